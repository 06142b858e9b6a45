//! Tests of the bounce-series tail closure: analytic limits, continuity, monotonicity, the tabulated
//! bounces the closure must predict, energy balance, and (ignored, release) the validation matrix against
//! the random walk.

use std::f64::consts::PI;
use std::sync::OnceLock;
use std::time::Instant;

use super::*;
use crate::physics::zh_transport::{ResponseConfig, compute};
use crate::reference::walk::{self, Emitter, Medium, WalkConfig};

fn log_spaced(n: usize, lo: f64, hi: f64) -> Vec<f64> {
    (0..n).map(|i| lo * (hi / lo).powf(i as f64 / (n - 1) as f64)).collect()
}

/// Small tables for the default (dev-profile) tests: 40 distances in `[1e-3, 64]`, 8 nodes per panel.
fn small(kind: EmitterKind, g: f64) -> &'static Response {
    static CELLS: [OnceLock<Response>; 4] = [OnceLock::new(), OnceLock::new(), OnceLock::new(), OnceLock::new()];
    assert!(g == 0.5 || g == -0.5, "small tables exist for g = ±0.5");
    let index = match (kind, g > 0.0) {
        (EmitterKind::Point, false) => 0,
        (EmitterKind::Point, true) => 1,
        (EmitterKind::Directional, false) => 2,
        (EmitterKind::Directional, true) => 3,
    };
    CELLS[index].get_or_init(|| {
        let cfg = ResponseConfig { mu_nodes: 8, t_nodes: 8, ..ResponseConfig::new(g, log_spaced(40, 1e-3, 64.0)) };
        compute(kind, &cfg).unwrap()
    })
}

/// Production-like table: 100 log-spaced distances in `[1e-3, 64]`, defaults otherwise (order 11, B = 10).
fn production(kind: EmitterKind, g: f64) -> &'static Response {
    static CELLS: [OnceLock<Response>; 6] =
        [OnceLock::new(), OnceLock::new(), OnceLock::new(), OnceLock::new(), OnceLock::new(), OnceLock::new()];
    let gi = [0.0, 0.5, -0.5].iter().position(|&x| x == g).expect("g in {0, 0.5, -0.5}");
    let index = 3 * usize::from(kind == EmitterKind::Directional) + gi;
    CELLS[index].get_or_init(|| compute(kind, &ResponseConfig::new(g, log_spaced(100, 1e-3, 64.0))).unwrap())
}

/// The same response with only the first `b` bounces.
fn truncated(r: &Response, b: usize) -> Response {
    Response { bounces: r.bounces[..b].to_vec(), ..r.clone() }
}

/// Canonical irradiance of bounces `1..=B` weighted by `α^b`.
fn series(r: &Response, albedo: f64, d: f64, cos_n: f64) -> f64 {
    (1..=r.bounces.len()).map(|b| albedo.powi(b as i32) * r.bounce_irradiance(b, d, cos_n)).sum()
}

/// Direct irradiance of the canonical emitter.
fn direct(kind: EmitterKind, d: f64, cos_n: f64) -> f64 {
    let unit = match kind {
        EmitterKind::Point => (-d).exp() / (d * d),
        EmitterKind::Directional => (-d).exp(),
    };
    unit * cos_n.max(0.0)
}

/// `E(+a) − E(−a)` of a ZH lobe: `2 Σ_{l odd} c_l A_l` with the clamped-cosine coefficients `A_l`.
fn net_flux(zh: &[f64]) -> f64 {
    let a = sh::clamped_cosine_zh(zh.len());
    zh.iter().zip(&a).enumerate().filter(|(l, _)| l % 2 == 1).map(|(_, (c, a))| 2.0 * c * a).sum()
}

#[test]
fn domain_sweep_is_finite_and_physical() {
    for kind in [EmitterKind::Point, EmitterKind::Directional] {
        let r = small(kind, 0.5);
        for albedo in [0.0, 1e-300, 0.3, 0.9, 1.0, 2.0, -1.0, f64::NAN] {
            for d in [1e-150, 1e-3, 0.7, 64.0, 300.0, 1e5, f64::INFINITY, f64::NAN, -1.0] {
                let [c0, c1] = tail_at(r, 0.5, albedo, d);
                assert!(c0.is_finite() && c1.is_finite() && c0 >= 0.0, "{kind:?} {albedo} {d}: {c0} {c1}");
                assert!(c1.abs() <= 3f64.sqrt() * c0 * (1.0 + 1e-12), "{kind:?} {albedo} {d}: {c0} {c1}");
                if albedo.is_nan() || albedo <= 0.0 {
                    assert_eq!([c0, c1], [0.0, 0.0], "α = {albedo} must give no tail");
                }
            }
        }
    }
}

/// [`tail_table`] is [`tail_at`] on the table's distances, and the energy ratio has its limits: 0 without
/// scattering, growing with `d` at `α = 1` (the truncated series dies like `e^{−d}`, the tail like `1/d`).
#[test]
fn table_matches_pointwise_and_energy_ratio() {
    for kind in [EmitterKind::Point, EmitterKind::Directional] {
        let r = small(kind, -0.5);
        let albedos = [0.0, 0.5, 0.97, 1.0];
        let table = tail_table(r, -0.5, &albedos);
        assert_eq!((table.len(), table[0].len()), (4, r.distances.len()));
        for (row, &a) in table.iter().zip(&albedos) {
            for (c, &d) in row.iter().zip(&r.distances).step_by(7) {
                assert_eq!(*c, tail_at(r, -0.5, a, d), "{kind:?} α {a} d {d}");
            }
        }
        assert_eq!(tail_energy_ratio(r, -0.5, 0.0, 1.0), 0.0);
        let ratios: Vec<f64> = [0.1, 1.0, 4.0, 8.0].iter().map(|&d| tail_energy_ratio(r, -0.5, 1.0, d)).collect();
        assert!(ratios.windows(2).all(|w| w[1] > w[0]) && ratios[0] > 0.0 && ratios[3] > 100.0, "{ratios:?}");
    }
}

/// `D`, `μ` against the transport dispersion relation and their limits.
#[test]
fn diffusion_constants() {
    for g in [-0.5, 0.0, 0.5, 0.9] {
        let one = diffusion(g, 1.0);
        assert!((one.coefficient - 1.0 / (3.0 * (1.0 - g))).abs() < 1e-15 && one.decay == 0.0);
        let near = diffusion(g, 1.0 - 1e-12);
        assert!((near.coefficient / one.coefficient - 1.0).abs() < 1e-9 && near.decay < 1e-5, "{near:?}");
        for albedo in [0.5, 0.9, 0.99, 0.999_999] {
            let p = diffusion(g, albedo);
            // σ_a/D = ν², ν = (1 − αg) ν', α' artanh(ν')/ν' = 1.
            assert!((p.decay * p.decay * p.coefficient - (1.0 - albedo)).abs() < 1e-13);
            let nu = p.decay / (1.0 - albedo * g);
            let a_sim = albedo * (1.0 - g) / (1.0 - albedo * g);
            assert!(nu < 1.0 && (a_sim * nu.atanh() / nu - 1.0).abs() < 1e-6, "g {g} α {albedo}: ν' {nu}");
        }
    }
    // Tabulated root (isotropic, α = 0.9): ν = 0.5254295.
    assert!((diffusion(0.0, 0.9).decay - 0.525_429_5).abs() < 1e-6, "{:?}", diffusion(0.0, 0.9));
}

/// Tail grows with the albedo and is continuous in `α` and `d` (also where `d` crosses a breakpoint).
#[test]
fn monotone_in_albedo_and_continuous() {
    for kind in [EmitterKind::Point, EmitterKind::Directional] {
        for g in [-0.5, 0.5] {
            let r = small(kind, g);
            for d in [0.05, 1.0, 6.0, 40.0] {
                let mut last = 0.0;
                for i in 0..=100 {
                    let c0 = tail_at(r, g, f64::from(i) / 100.0, d)[0];
                    assert!(c0 >= last, "{kind:?} g {g} d {d} α {}: {c0} < {last}", f64::from(i) / 100.0);
                    last = c0;
                }
                let at_one = tail_at(r, g, 1.0, d);
                // μ ∝ √(1 − α): the approach to α = 1 is continuous with a square-root slope.
                let below = tail_at(r, g, 1.0 - 1e-14, d);
                for (x, y) in at_one.iter().zip(&below) {
                    assert!((x - y).abs() <= 1e-5 * at_one[0], "{kind:?} α → 1: {at_one:?} {below:?}");
                }
            }
            // 1.024 and 2.048 are fixed breakpoints, 1.024 + 0.125 = 1.149 makes d − 1/8 cross one.
            for d in [1.024, 2.048, 1.149, 0.125] {
                let lo = tail_at(r, g, 0.95, d * (1.0 - 1e-9));
                let hi = tail_at(r, g, 0.95, d * (1.0 + 1e-9));
                for (x, y) in lo.iter().zip(&hi) {
                    assert!((x - y).abs() <= 1e-7 * lo[0], "{kind:?} g {g} d {d}: {lo:?} {hi:?}");
                }
            }
        }
    }
}

/// The closure of a table truncated at `B = 7` must predict the bounces 8..=10 the recursion computed:
/// `T_7 ≈ Σ_{b=8}^{10} α^b c^{(b)} + T_10` (an independent check of the model against the deterministic
/// transport, at a lower `B` than production, where the closure is less accurate), and the tail shrinks as
/// `B` grows. Measured worst relative errors (small tables): `c_0` 6.0 % at `α = 1`, 17 % at `α = 0.9`
/// (both near a point light, `g = 0.5`, `d ≤ 1`); `c_1` 2.2 % at `α = 1`, 7.4 % at `α = 0.9`.
#[test]
fn closure_predicts_the_tabulated_bounces() {
    let mut worst = [[0.0f64; 2]; 2];
    for kind in [EmitterKind::Point, EmitterKind::Directional] {
        for g in [-0.5, 0.5] {
            let full = small(kind, g);
            let short = truncated(full, 7);
            for (ai, albedo) in [1.0, 0.9].into_iter().enumerate() {
                for d in [0.3, 1.0, 3.0, 8.0] {
                    let t7 = tail_at(&short, g, albedo, d);
                    let t10 = tail_at(full, g, albedo, d);
                    if albedo < 1.0 {
                        assert!(t10[0] < t7[0], "{kind:?} g {g} α {albedo} d {d}");
                    }
                    let mut expect = t10;
                    for b in 8..=10 {
                        let c = full.zh_at(b, d);
                        expect[0] += albedo.powi(b as i32) * c[0];
                        expect[1] += albedo.powi(b as i32) * c[1];
                    }
                    let tols = [[0.07, 0.03], [0.2, 0.09]][ai];
                    for (l, ((got, want), tol)) in t7.iter().zip(&expect).zip(tols).enumerate() {
                        let err = got / want - 1.0;
                        worst[ai][l] = worst[ai][l].max(err.abs());
                        assert!(err.abs() < tol, "{kind:?} g {g} α {albedo} d {d} l {l}: {err:+.4}");
                    }
                }
            }
        }
    }
    eprintln!("closure from B = 7 vs recursion + closure from B = 10, worst [α = 1, α = 0.9][c0, c1]: {worst:.4?}");
}

/// `B → ∞`: the tail vanishes, strictly decreasing in `B` (`B = 4, 7, 10`). (From `B ≤ 2` the closure is
/// too crude near a point light to be ordered: P1 transport of nearly unscattered light, whose dipole
/// source can even drive `Φ` to the clamp at 0 for `B = 1`.)
#[test]
fn tail_vanishes_as_b_grows() {
    for kind in [EmitterKind::Point, EmitterKind::Directional] {
        let full = small(kind, 0.5);
        for (albedo, d) in [(0.9, 1.0), (0.95, 0.3)] {
            let tails: Vec<f64> = [4, 7, 10].iter().map(|&b| tail_at(&truncated(full, b), 0.5, albedo, d)[0]).collect();
            assert!(tails.windows(2).all(|w| w[1] < w[0]), "{kind:?} α {albedo}: {tails:?}");
            assert!(tails[2] < 0.6 * tails[0], "{kind:?} α {albedo}: {tails:?}");
        }
    }
}

/// Conservation: `E(+a) − E(−a)` of direct + bounces `1..=B` + tail equals `1/d²` around a conservative
/// point source, and 0 (all light is eventually reflected) in a conservative half-space.
#[test]
fn energy_balance() {
    for g in [-0.5, 0.5] {
        let r = small(EmitterKind::Point, g);
        for d in [0.5, 2.0, 8.0] {
            let (with, without) = point_balance(r, g, d);
            eprintln!("small table, point g {g} d {d}: {with:.5} (without tail {without:.5})");
            assert!((with - 1.0).abs() < ENERGY_TOLERANCE, "point g {g} d {d}: {with} (without tail {without})");
        }
        let r = small(EmitterKind::Directional, g);
        for d in [0.5, 2.0, 8.0] {
            let (with, without) = slab_balance(r, g, d);
            eprintln!("small table, slab g {g} d {d}: {with:+.5} (without tail {without:+.5})");
            assert!(with.abs() < ENERGY_TOLERANCE, "slab g {g} d {d}: {with} (without tail {without})");
        }
    }
}

/// The small tables (8 nodes per panel, 40 distances) measure at worst 1.7 % (point, `g = 0.5`, `d = 8`)
/// and 2.5 % (half-space, `g = 0.5`, `d = 0.5`); the production-like tables of `validation_matrix` 0.28 %
/// and 0.42 % (pinned there at 0.6 %). The residual is the table's own error (orders `≤ 10`), which the
/// tail inherits through its source.
const ENERGY_TOLERANCE: f64 = 0.035;

/// `(E(+a) − E(−a)) d²` with and without the tail (point, `α = 1`).
fn point_balance(r: &Response, g: f64, d: f64) -> (f64, f64) {
    let orders: f64 = (1..=r.bounces.len()).map(|b| net_flux(&r.zh_at(b, d))).sum();
    let without = (-d).exp() / (d * d) + orders;
    let with = without + net_flux(&tail_at(r, g, 1.0, d));
    (with * d * d, without * d * d)
}

/// `E(+a) − E(−a)` with and without the tail, relative to `E(+a)` (directional, `α = 1`).
fn slab_balance(r: &Response, g: f64, d: f64) -> (f64, f64) {
    let orders: f64 = (1..=r.bounces.len()).map(|b| net_flux(&r.zh_at(b, d))).sum();
    let tail = tail_at(r, g, 1.0, d);
    let without = (-d).exp() + orders;
    let facing = direct(EmitterKind::Directional, d, 1.0) + series(r, 1.0, d, 1.0) + tail_irradiance(tail, 1.0);
    ((without + net_flux(&tail)) / facing, without / facing)
}

/// Bands `l ≥ 2` of the tail. The closure keeps `l ≤ 1`; a proxy for what it drops is the tail beyond
/// `B = 7` as the table itself knows it, `Σ_{b=8}^{10} c^{(b)} + T_10` (α = 1): its bands `l ≥ 2` change its
/// irradiance by at most `BAND_SHARE` of its facing irradiance over `d ∈ [0.1, 8]` and all three normals
/// (worst where `d` is largest: the order-8..10 light there is still forward-peaked). Orders beyond 10 are
/// more isotropic still (each scattering multiplies `c_l` by `g^l`, and more of them are diffusive).
#[test]
fn higher_bands_are_small() {
    let mut share: f64 = 0.0;
    for kind in [EmitterKind::Point, EmitterKind::Directional] {
        for g in [-0.5, 0.5] {
            let r = small(kind, g);
            for d in log_spaced(12, 0.1, 8.0) {
                let t = tail_at(r, g, 1.0, d);
                let mut lobe = vec![0.0; 11];
                for b in 8..=10 {
                    for (acc, c) in lobe.iter_mut().zip(r.zh_at(b, d)) {
                        *acc += c;
                    }
                }
                lobe[0] += t[0];
                lobe[1] += t[1];
                let facing = sh::zh_irradiance(&lobe, [0.0, 0.0, 1.0], [0.0, 0.0, 1.0]);
                for cos_n in [1.0, 0.0, -1.0] {
                    let n = [(1.0f64 - cos_n * cos_n).sqrt(), 0.0, cos_n];
                    let all = sh::zh_irradiance(&lobe, [0.0, 0.0, 1.0], n);
                    let p1 = sh::zh_irradiance(&lobe[..2], [0.0, 0.0, 1.0], n);
                    share = share.max((all - p1).abs() / facing);
                }
            }
        }
    }
    eprintln!("bands l >= 2 of the B = 7 tail proxy: at most {share:.4} of its facing irradiance");
    assert!(share < BAND_SHARE, "{share}");
}

/// Measured 0.0195 (see `higher_bands_are_small`), pinned with margin.
const BAND_SHARE: f64 = 0.03;

/// One walk case in the dev profile: tail irradiance at `α = 0.9`, `g = 0.5`, `d = 2` on the facing normal.
#[test]
fn matches_the_walk_in_one_absorbing_case() {
    let g = 0.5;
    let r = small(EmitterKind::Point, g);
    let w = walk_tail(EmitterKind::Point, g, 0.9, 2.0, 1.0, 40_000, 60.0);
    let t = tail_irradiance(tail_at(r, g, 0.9, 2.0), 1.0);
    let err = t / w.mean - 1.0;
    assert!(err.abs() < 0.1 && (t - w.mean).abs() < 0.05 * w.mean + 4.0 * w.std_error, "{t} vs {w:?}");
}

fn walk_run(kind: EmitterKind, g: f64, albedo: f64, d: f64, cos_n: f64, photons: u64, far: f64) -> walk::WalkResult {
    let emitter = match kind {
        EmitterKind::Point => Emitter::Point { intensity: 1.0, position: [0.0, 0.0, d] },
        EmitterKind::Directional => Emitter::Directional { irradiance: 1.0, toward_light: [0.0, 0.0, 1.0], depth: d },
    };
    let medium = Medium { sigma_s: albedo, sigma_a: 1.0 - albedo, g };
    let normal = [(1.0f64 - cos_n * cos_n).max(0.0).sqrt(), 0.0, cos_n];
    let cfg = WalkConfig { far_mfp: far, ..WalkConfig::new(photons, 10, 7) };
    walk::irradiance(&emitter, &medium, normal, &cfg).unwrap()
}

fn walk_tail(
    kind: EmitterKind,
    g: f64,
    albedo: f64,
    d: f64,
    cos_n: f64,
    photons: u64,
    far: f64,
) -> walk::OrderEstimate {
    walk_run(kind, g, albedo, d, cos_n, photons, far).tail
}

/// Walk tail and total of the *infinite* process. At `α = 1` the walk removes photons beyond `R_c`
/// (module doc of `reference::walk`); the removal is undone with its diffusion-theory correction: point —
/// the removed sphere `|y − s| > R_c + d` lowers the fluence by the constant `P/(4πD R')`,
/// `R' = R_c + d + z_b` (irradiance `φ/4` on every normal, the current is fixed by Gauss's law);
/// half-space — the measured removed weight `w` is the net downward flux, the fluence is lowered by
/// `w (z + z_b)/D`, so `E_{±a}` gain `δφ/4 ∓ w/2`.
fn walk_infinite(
    kind: EmitterKind,
    g: f64,
    albedo: f64,
    d: f64,
    cos_n: f64,
    photons: u64,
    far: f64,
) -> (f64, f64, f64, f64) {
    // Optional cache of walk runs (a file named by TAIL_WALK_CACHE), so that the matrix can be re-printed.
    let key = format!("{kind:?} {g} {albedo} {d} {cos_n} {photons} {far}");
    let cache = std::env::var("TAIL_WALK_CACHE").ok();
    let cached = cache.as_ref().and_then(|path| {
        let text = std::fs::read_to_string(path).ok()?;
        let line = text.lines().find(|l| l.starts_with(&format!("{key}:")))?;
        let v: Vec<f64> = line.split(':').nth(1)?.split_whitespace().filter_map(|x| x.parse().ok()).collect();
        (v.len() == 5).then(|| (v[0], v[1], v[2], v[3], v[4]))
    });
    let (tail, tail_se, total, total_se, removed) = cached.unwrap_or_else(|| {
        let w = walk_run(kind, g, albedo, d, cos_n, photons, far);
        let v = (w.tail.mean, w.tail.std_error, w.total.mean, w.total.std_error, w.truncated_weight.mean);
        if let Some(path) = &cache {
            use std::io::Write;
            let mut f = std::fs::OpenOptions::new().create(true).append(true).open(path).unwrap();
            writeln!(f, "{key}: {} {} {} {} {}", v.0, v.1, v.2, v.3, v.4).unwrap();
        }
        v
    });
    let correction = if albedo < 1.0 {
        0.0
    } else {
        let p = diffusion(g, 1.0);
        match kind {
            EmitterKind::Point => 4.0 * PI / (4.0 * PI * p.coefficient * (far + d + p.extrapolation)) / 4.0,
            EmitterKind::Directional => removed * (d + p.extrapolation) / p.coefficient / 4.0 - 0.5 * removed * cos_n,
        }
    };
    (tail + correction, tail_se, total + correction, total_se)
}

/// Photons and removal distance of a validation run: enough for ~1 % standard errors where affordable.
fn walk_budget(kind: EmitterKind, albedo: f64, scale: f64) -> (u64, f64) {
    let (photons, far) = match (kind, albedo < 1.0) {
        (_, true) => (40_000.0, 60.0),
        (EmitterKind::Point, false) => (20_000.0, 40.0),
        (EmitterKind::Directional, false) => (40_000.0, 100.0),
    };
    ((photons * scale) as u64, far)
}

/// Validation matrix against the random walk (release, ~13 minutes on 2 cores):
/// `cargo test --release --lib tail -- --ignored --nocapture`. Optional environment: `TAIL_WALK_CACHE=<file>`
/// stores the walk results and reuses them on the next run; `TAIL_PHOTON_SCALE=<x>` scales the photon counts.
/// Asserts the key number (total irradiance at `α = 1` within 5 % of the walk; measured 3.9 %) and the
/// production energy balance (within 0.6 %; measured 0.28 % point, 0.42 % half-space).
/// Prints tail and total irradiance of the production-like table + closure against the walk for both
/// emitters, `g ∈ {0, ±0.5}`, `α ∈ {1, 0.99, 0.9}`, `d ∈ {0.5, 1, 2, 4, 8}`, normals facing / orthogonal /
/// away, then the energy balance, the energy the tail adds and the cost of a production tail table.
#[test]
#[ignore]
fn validation_matrix() {
    let scale: f64 = std::env::var("TAIL_PHOTON_SCALE").ok().and_then(|s| s.parse().ok()).unwrap_or(1.0);
    let mut worst_total_alpha1: f64 = 0.0;
    let mut worst_tail: f64 = 0.0;
    eprintln!(
        "kind        g     α     d   cos | walk tail ± se      closure   err    | walk total   table total err    (no tail)"
    );
    for kind in [EmitterKind::Point, EmitterKind::Directional] {
        for g in [0.0, 0.5, -0.5] {
            let r = production(kind, g);
            for albedo in [1.0, 0.99, 0.9] {
                for d in [0.5, 1.0, 2.0, 4.0, 8.0] {
                    for cos_n in [1.0, 0.0, -1.0] {
                        let (photons, far) = walk_budget(kind, albedo, scale);
                        let (wt, wse, wtot, _) = walk_infinite(kind, g, albedo, d, cos_n, photons, far);
                        let t = tail_irradiance(tail_at(r, g, albedo, d), cos_n);
                        let base = direct(kind, d, cos_n) + series(r, albedo, d, cos_n);
                        let total = base + t;
                        let (et, etot, e0) = (t / wt - 1.0, total / wtot - 1.0, base / wtot - 1.0);
                        worst_tail = worst_tail.max(et.abs());
                        if albedo == 1.0 {
                            worst_total_alpha1 = worst_total_alpha1.max(etot.abs());
                        }
                        eprintln!(
                            "{kind:11?} {g:+.1} {albedo:5.2} {d:4.1} {cos_n:+.0} | {wt:.4e} ± {:5.2}% {t:.4e} {:+6.2}% | {wtot:.4e} {total:.4e} {:+6.2}% ({:+6.2}%)",
                            100.0 * wse / wt.abs(),
                            100.0 * et,
                            100.0 * etot,
                            100.0 * e0
                        );
                    }
                }
            }
        }
    }
    eprintln!("worst |tail error| {worst_tail:.4}, worst |total error| at α = 1: {worst_total_alpha1:.4}");
    // Measured 3.9 % (walk standard errors ~1–2 %); the downstream target is 5 %.
    assert!(worst_total_alpha1 < 0.05, "total irradiance at α = 1 off by {worst_total_alpha1}");
    production_report();
}

/// Energy balance, energy the tail adds and cost, on the production-like tables (part of the validation
/// run; prints only).
fn production_report() {
    for g in [0.0, 0.5, -0.5] {
        let r = production(EmitterKind::Point, g);
        for d in [0.5, 2.0, 8.0] {
            let (with, without) = point_balance(r, g, d);
            assert!((with - 1.0).abs() < 0.006, "point g {g} d {d}: {with}");
            eprintln!("point balance g {g:+.1} d {d}: (E_out − E_in) d² = {with:.5} with tail, {without:.5} without");
        }
        let r = production(EmitterKind::Directional, g);
        for d in [0.5, 2.0, 8.0] {
            let (with, without) = slab_balance(r, g, d);
            assert!(with.abs() < 0.006, "slab g {g} d {d}: {with}");
            eprintln!(
                "slab balance g {g:+.1} d {d}: (E_down − E_up)/E_down = {with:+.5} with tail, {without:+.5} without"
            );
        }
    }
    for kind in [EmitterKind::Point, EmitterKind::Directional] {
        for g in [0.0, 0.5, -0.5] {
            let r = production(kind, g);
            for albedo in [1.0, 0.99, 0.9, 0.5] {
                let ratios: Vec<String> = [0.1, 0.5, 1.0, 2.0, 4.0, 8.0, 16.0]
                    .iter()
                    .map(|&d| format!("{:.3}", tail_energy_ratio(r, g, albedo, d)))
                    .collect();
                eprintln!(
                    "tail fluence / series fluence {kind:?} g {g:+.1} α {albedo}: d 0.1..16 = {}",
                    ratios.join(" ")
                );
            }
        }
    }
    // Cost of a production tail table: 256 distances, 12 albedos (the 256-distance response is the 100-node
    // table resampled, which has the same lookup cost).
    let albedos: Vec<f64> = (0..12).map(|i| 1.0 - 0.5f64.powi(i)).collect();
    for kind in [EmitterKind::Point, EmitterKind::Directional] {
        let r = production(kind, 0.5);
        let distances = log_spaced(256, 1e-3, 64.0);
        let bounces = (1..=10).map(|b| distances.iter().map(|&d| r.zh_at(b, d)).collect()).collect();
        let big = Response { kind, distances: distances.clone(), direct: r.direct.clone(), bounces };
        let t0 = Instant::now();
        let table = tail_table(&big, 0.5, &albedos);
        let elapsed = t0.elapsed();
        assert!(table.iter().flatten().all(|c| c[0].is_finite() && c[1].is_finite()));
        eprintln!("tail_table {kind:?}: 256 distances x 12 albedos in {elapsed:.2?}");
    }
}
