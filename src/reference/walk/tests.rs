//! Tests of the random-walk reference against independently derived values: single scattering by
//! deterministic quadrature of the airlight integral (written here, sharing no code with the walk),
//! exact balance laws of the (truncated) transport process, exact zeros, the HG sampler against its
//! phase, thread-count determinism, the removal bound, extreme inputs and parameter validation.
//! Input: fixed configurations and seeds; output: pass/fail, with the agreements printed
//! (`cargo test -- --nocapture`).
//!
//! **Quadrature.** Point source, order 1: parametrise the ray `y = tω` from the receiver by the angle
//! `α` seen from the source (`t = t₀ + b tan α`, `b = d sin ψ`, `t₀ = d cos ψ`, `ψ = ∠(ω, l)`), which
//! turns `∫ dt e^{−σ_t(t + |y − s|)}/|y − s|²` into `(1/b) ∫ dα e^{−σ_t(t₀ + b tan(π/4 + α/2))}` with
//! scattering cosine `−sin α`; the `1/b` cancels the solid-angle `sin ψ`, the azimuth of
//! `max(0, n·ω)` is integrated in closed form, and `ψ`, `α` by adaptive Simpson. Directional,
//! order 1: `L₁(ω) = σ_s E₀ e^{−σ_t D} p(μ) ∫_0^{t_max} e^{−σ_t t (1 − μ)} dt`, `t_max = D/μ` for
//! `μ = l·ω > 0` (the ray leaves the medium) and `∞` otherwise.

use std::f64::consts::{FRAC_PI_2, FRAC_PI_4, PI};

use super::*;

const L: [f64; 3] = [2.0 / 3.0, -1.0 / 3.0, 2.0 / 3.0];

/// A unit vector perpendicular to `L`.
const L_PERP: [f64; 3] = [1.0 / std::f64::consts::SQRT_2, 0.0, -1.0 / std::f64::consts::SQRT_2];

/// HG phase, written out for the quadrature.
fn phase(g: f64, mu: f64) -> f64 {
    (1.0 - g * g) / (4.0 * PI * (1.0 + g * g - 2.0 * g * mu).powf(1.5))
}

/// A Simpson panel: end points and values at both ends and the middle, and its Simpson estimate.
#[derive(Clone, Copy)]
struct Panel {
    a: f64,
    b: f64,
    fa: f64,
    fm: f64,
    fb: f64,
    whole: f64,
}

impl Panel {
    fn new(f: &dyn Fn(f64) -> f64, a: f64, b: f64) -> Self {
        let (fa, fm, fb) = (f(a), f(0.5 * (a + b)), f(b));
        Self { a, b, fa, fm, fb, whole: (b - a) / 6.0 * (fa + 4.0 * fm + fb) }
    }

    /// Adaptive Simpson refinement to absolute tolerance `tol` (Richardson-corrected).
    fn refine(self, f: &dyn Fn(f64) -> f64, tol: f64, depth: u32) -> f64 {
        let m = 0.5 * (self.a + self.b);
        let (flm, frm) = (f(0.5 * (self.a + m)), f(0.5 * (m + self.b)));
        let left = Self {
            a: self.a,
            b: m,
            fa: self.fa,
            fm: flm,
            fb: self.fm,
            whole: (m - self.a) / 6.0 * (self.fa + 4.0 * flm + self.fm),
        };
        let right = Self {
            a: m,
            b: self.b,
            fa: self.fm,
            fm: frm,
            fb: self.fb,
            whole: (self.b - m) / 6.0 * (self.fm + 4.0 * frm + self.fb),
        };
        let delta = left.whole + right.whole - self.whole;
        if depth == 0 || delta.abs() <= 15.0 * tol {
            left.whole + right.whole + delta / 15.0
        } else {
            left.refine(f, 0.5 * tol, depth - 1) + right.refine(f, 0.5 * tol, depth - 1)
        }
    }
}

/// Adaptive Simpson on `[a, b]`, started on 16 panels, to relative tolerance `rel`.
fn integrate(f: &dyn Fn(f64) -> f64, a: f64, b: f64, rel: f64) -> f64 {
    if b <= a {
        return 0.0;
    }
    let panels = 16;
    let h = (b - a) / f64::from(panels);
    let pieces: Vec<Panel> =
        (0..panels).map(|i| Panel::new(f, a + h * f64::from(i), a + h * f64::from(i + 1))).collect();
    let scale = pieces.iter().map(|p| p.whole.abs()).sum::<f64>().max(1e-300);
    let tol = rel * scale / f64::from(panels);
    pieces.iter().map(|p| p.refine(f, tol, 40)).sum()
}

/// `∫_0^{2π} max(0, a + b cos φ) dφ` for `b ≥ 0`.
fn azimuthal(a: f64, b: f64) -> f64 {
    if b <= a.abs() {
        if a > 0.0 { 2.0 * PI * a } else { 0.0 }
    } else {
        let phi0 = (-a / b).acos();
        2.0 * (a * phi0 + b * (1.0 - (a / b).powi(2)).sqrt())
    }
}

/// Order-1 irradiance from a point source at distance `d` (cosine `cos_nl` between normal and `l`).
fn point_single(sigma_s: f64, sigma_t: f64, g: f64, intensity: f64, d: f64, cos_nl: f64) -> f64 {
    emitter_single(sigma_s, sigma_t, g, intensity, d, cos_nl, None)
}

/// Order-1 irradiance from an area emitter at distance `d` whose normal is `−l` (`facing = true`, it
/// faces the receiver) or `+l`: the point-source quadrature with the emission factor. Along the ray the
/// direction from the source to the scattering point is `v` with `l·v = sin(α − ψ)`, so the factor is
/// `max(0, ∓sin(α − ψ))` and the `α` range is split at `α = ψ` where it vanishes.
fn area_single(sigma_s: f64, sigma_t: f64, g: f64, intensity: f64, d: f64, cos_nl: f64, facing: bool) -> f64 {
    emitter_single(sigma_s, sigma_t, g, intensity, d, cos_nl, Some(facing))
}

/// The quadrature behind [`point_single`] (`area = None`) and [`area_single`] (`Some(facing)`).
fn emitter_single(sigma_s: f64, sigma_t: f64, g: f64, intensity: f64, d: f64, cos_nl: f64, area: Option<bool>) -> f64 {
    let sin_nl = (1.0 - cos_nl * cos_nl).max(0.0).sqrt();
    let outer = |psi: f64| {
        let c = azimuthal(cos_nl * psi.cos(), sin_nl * psi.sin());
        if c == 0.0 {
            return 0.0;
        }
        let (t0, b) = (d * psi.cos(), d * psi.sin());
        let inner = |alpha: f64| {
            let emission = match area {
                None => 1.0,
                Some(true) => (psi - alpha).sin().max(0.0),
                Some(false) => (alpha - psi).sin().max(0.0),
            };
            phase(g, -alpha.sin()) * (-sigma_t * (t0 + b * (FRAC_PI_4 + 0.5 * alpha).tan())).exp() * emission
        };
        let lo = -t0.atan2(b);
        let (a, z) = match area {
            None => (lo, FRAC_PI_2),
            Some(true) => (lo, psi.min(FRAC_PI_2)),
            Some(false) => (psi.max(lo), FRAC_PI_2),
        };
        c * integrate(&inner, a, z, 1e-9)
    };
    sigma_s * intensity / d * integrate(&outer, 0.0, PI, 1e-8)
}

/// Order-1 irradiance at depth `depth` below the boundary of a half-space lit along `−l`.
fn directional_single(sigma_s: f64, sigma_t: f64, g: f64, e0: f64, depth: f64, cos_nl: f64) -> f64 {
    let sin_nl = (1.0 - cos_nl * cos_nl).max(0.0).sqrt();
    let path = |mu: f64| {
        if mu <= 0.0 {
            1.0 / (sigma_t * (1.0 - mu))
        } else if mu >= 1.0 {
            depth
        } else {
            -(-sigma_t * depth * (1.0 - mu) / mu).exp_m1() / (sigma_t * (1.0 - mu))
        }
    };
    let outer = |psi: f64| {
        let mu = psi.cos();
        psi.sin() * azimuthal(cos_nl * mu, sin_nl * psi.sin()) * phase(g, mu) * path(mu)
    };
    sigma_s * e0 * (-sigma_t * depth).exp() * integrate(&outer, 0.0, PI, 1e-9)
}

/// The three receiver normals: facing the light, orthogonal to it, facing away.
fn normals() -> [([f64; 3], f64); 3] {
    [(L, 1.0), (L_PERP, 0.0), (L.map(|c| -c), -1.0)]
}

/// Asserts agreement within 4 standard errors and 3 %, and returns the difference in standard errors.
fn check(label: &str, mc: OrderEstimate, exact: f64) -> f64 {
    let z = (mc.mean - exact) / mc.std_error;
    let rel = (mc.mean - exact) / exact;
    eprintln!(
        "{label}: walk {:.6e} ± {:.2} %, quadrature {exact:.6e}, diff {:+.2} % = {z:+.2} SE",
        mc.mean,
        100.0 * mc.std_error / mc.mean,
        100.0 * rel
    );
    assert!(z.abs() < 4.0 && rel.abs() < 0.03, "{label}: {mc:?} vs {exact}");
    z
}

/// Order-1 estimate with a standard error of about 0.6 % or less: a 200 000-photon pilot run, then,
/// if its error is larger, a run sized from it (at most 4 million photons).
fn order_one(emitter: &Emitter, medium: &Medium, normal: [f64; 3], seed: u64) -> OrderEstimate {
    let pilot = 200_000;
    let r = irradiance(emitter, medium, normal, &WalkConfig::new(pilot, 1, seed)).unwrap();
    assert_eq!(r.nonfinite_discarded, 0);
    let rel = r.orders[0].std_error / r.orders[0].mean;
    if rel <= 0.006 {
        return r.orders[0];
    }
    let photons = ((pilot as f64 * (rel / 0.006).powi(2)) as u64).min(4_000_000);
    let r = irradiance(emitter, medium, normal, &WalkConfig::new(photons, 1, seed + 1)).unwrap();
    assert_eq!(r.nonfinite_discarded, 0);
    r.orders[0]
}

/// Single scattering from a point source (σ_t = 2/length, albedo 1/4) against quadrature, for
/// distances `d_mfp` (free paths) and the three normals.
fn point_single_scattering(g: f64, distances: &[f64]) {
    let medium = Medium { sigma_s: 0.5, sigma_a: 1.5, g };
    for &d_mfp in distances {
        let d = d_mfp / 2.0;
        let emitter = Emitter::Point { intensity: 3.0, position: L.map(|c| c * d) };
        for (n, cos_nl) in normals() {
            let exact = point_single(0.5, 2.0, g, 3.0, d, cos_nl);
            check(&format!("point g={g} d={d_mfp} mfp n·l={cos_nl}"), order_one(&emitter, &medium, n, 11), exact);
        }
    }
}

#[test]
fn point_single_scattering_isotropic_near_matches_quadrature() {
    point_single_scattering(0.0, &[0.1, 1.0]);
}

#[test]
fn point_single_scattering_isotropic_far_matches_quadrature() {
    point_single_scattering(0.0, &[4.0]);
}

#[test]
fn point_single_scattering_forward_hg_near_matches_quadrature() {
    point_single_scattering(0.5, &[0.1, 1.0]);
}

#[test]
fn point_single_scattering_forward_hg_far_matches_quadrature() {
    point_single_scattering(0.5, &[4.0]);
}

#[test]
fn point_single_scattering_backward_hg_near_matches_quadrature() {
    point_single_scattering(-0.5, &[0.1, 1.0]);
}

#[test]
fn point_single_scattering_backward_hg_far_matches_quadrature() {
    point_single_scattering(-0.5, &[4.0]);
}

/// Single scattering from an area emitter facing the receiver (`n_e = −l`) and facing away (`n_e = l`),
/// σ_t = 2/length, albedo 1/4, against quadrature for distances `d_mfp` and the three normals.
fn area_single_scattering(g: f64, distances: &[f64]) {
    let medium = Medium { sigma_s: 0.5, sigma_a: 1.5, g };
    for &d_mfp in distances {
        let d = d_mfp / 2.0;
        for facing in [true, false] {
            let normal = if facing { L.map(|c| -c) } else { L };
            let emitter = Emitter::Area { intensity: 3.0, position: L.map(|c| c * d), normal };
            for (n, cos_nl) in normals() {
                let exact = area_single(0.5, 2.0, g, 3.0, d, cos_nl, facing);
                let label = format!("area g={g} d={d_mfp} mfp facing={facing} n·l={cos_nl}");
                if exact == 0.0 {
                    // Facing away from each other: no once-scattered light can reach the receiver's
                    // hemisphere, and the rotated vertices never score either.
                    let r = irradiance(&emitter, &medium, n, &WalkConfig::new(20_000, 1, 21)).unwrap();
                    assert_eq!(r.orders[0].mean, 0.0, "{label}");
                    continue;
                }
                check(&label, order_one(&emitter, &medium, n, 21), exact);
            }
        }
    }
}

#[test]
fn area_single_scattering_isotropic_matches_quadrature() {
    area_single_scattering(0.0, &[0.1, 1.0, 4.0]);
}

#[test]
fn area_single_scattering_forward_hg_matches_quadrature() {
    area_single_scattering(0.5, &[0.1, 1.0, 4.0]);
}

#[test]
fn area_single_scattering_backward_hg_matches_quadrature() {
    area_single_scattering(-0.5, &[0.1, 1.0, 4.0]);
}

/// All orders at a general patch angle, from linearity and mirror symmetry: `Area(n) − Area(−n)` is the
/// dipole source `I n·u`, linear in `n`; with `n_θ = cos θ (−l) + sin θ p` (`p ⊥ l`) and a receiver
/// normal perpendicular to `p`, the mirror across the plane `⊥ p` (it fixes the source, the receiver and
/// its normal) makes the `p` dipole's response vanish, so
/// `Area(n_θ) − Area(−n_θ) = cos θ (Area(−l) − Area(l))` order by order. The left side exercises the
/// rotation-averaged kernel at a general angle; the right side only at `θ = 0, π` (checked above
/// against quadrature). Also checks `Area(p) = Area(−p)` for such receivers.
#[test]
fn area_general_angle_obeys_dipole_linearity() {
    let medium = Medium { sigma_s: 1.0, sigma_a: 0.25, g: 0.4 };
    let theta = PI / 3.0;
    let d = 0.8;
    let n_theta: [f64; 3] = std::array::from_fn(|i| -theta.cos() * L[i] + theta.sin() * L_PERP[i]);
    let cfg = WalkConfig::new(400_000, 3, 77);
    // Receiver normals perpendicular to L_PERP: facing the light and halfway to L × L_PERP.
    let side =
        [L[1] * L_PERP[2] - L[2] * L_PERP[1], L[2] * L_PERP[0] - L[0] * L_PERP[2], L[0] * L_PERP[1] - L[1] * L_PERP[0]];
    for normal in [L, std::array::from_fn(|i| L[i] + side[i])] {
        let run = |ne: [f64; 3], seed: u64| {
            let emitter = Emitter::Area { intensity: 2.0, position: L.map(|c| c * d), normal: ne };
            irradiance(&emitter, &medium, normal, &WalkConfig { seed, ..cfg }).unwrap()
        };
        let (plus, minus) = (run(n_theta, 1), run(n_theta.map(|c| -c), 2));
        let (toward, away) = (run(L.map(|c| -c), 3), run(L, 4));
        let (p_plus, p_minus) = (run(L_PERP, 5), run(L_PERP.map(|c| -c), 6));
        let parts = |r: &WalkResult| -> Vec<OrderEstimate> { r.orders.iter().copied().chain([r.total]).collect() };
        for (k, (((a, b), (c, e)), (f, h))) in parts(&plus)
            .into_iter()
            .zip(parts(&minus))
            .zip(parts(&toward).into_iter().zip(parts(&away)))
            .zip(parts(&p_plus).into_iter().zip(parts(&p_minus)))
            .enumerate()
        {
            let lhs = a.mean - b.mean;
            let rhs = theta.cos() * (c.mean - e.mean);
            let se =
                (a.std_error.powi(2) + b.std_error.powi(2) + 0.25 * (c.std_error.powi(2) + e.std_error.powi(2))).sqrt();
            eprintln!("dipole part {k}: {lhs:.5e} vs {rhs:.5e} ({:+.2} SE)", (lhs - rhs) / se);
            assert!((lhs - rhs).abs() < 4.0 * se, "part {k}: {lhs} vs {rhs} ± {se}");
            let se = (f.std_error.powi(2) + h.std_error.powi(2)).sqrt();
            eprintln!("mirror part {k}: {:.5e} vs {:.5e} ({:+.2} SE)", f.mean, h.mean, (f.mean - h.mean) / se);
            assert!((f.mean - h.mean).abs() < 4.0 * se && f.mean > 0.0, "mirror part {k}: {f:?} vs {h:?}");
        }
        // The direct part obeys the same identity exactly.
        let lhs = plus.direct - minus.direct;
        assert!((lhs - theta.cos() * (toward.direct - away.direct)).abs() <= 1e-15 * toward.direct);
    }
}

/// Single scattering in the half-space (σ_t = 2/length, albedo 1/4) against quadrature, for
/// `D ∈ {0.1, 1, 4}` free paths and the three normals.
fn directional_single_scattering(g: f64) {
    let medium = Medium { sigma_s: 0.5, sigma_a: 1.5, g };
    for d_mfp in [0.1, 1.0, 4.0] {
        let emitter = Emitter::Directional { irradiance: 2.0, toward_light: L, depth: d_mfp / 2.0 };
        for (n, cos_nl) in normals() {
            let exact = directional_single(0.5, 2.0, g, 2.0, d_mfp / 2.0, cos_nl);
            check(&format!("directional g={g} D={d_mfp} mfp n·l={cos_nl}"), order_one(&emitter, &medium, n, 5), exact);
        }
    }
}

#[test]
fn directional_single_scattering_isotropic_matches_quadrature() {
    directional_single_scattering(0.0);
}

#[test]
fn directional_single_scattering_forward_hg_matches_quadrature() {
    directional_single_scattering(0.5);
}

#[test]
fn directional_single_scattering_backward_hg_matches_quadrature() {
    directional_single_scattering(-0.5);
}

/// Without scattering every scattered order is exactly zero and the total is the direct part.
#[test]
fn no_scattering_gives_exact_zeros() {
    let medium = Medium { sigma_s: 0.0, sigma_a: 0.7, g: 0.3 };
    for emitter in [
        Emitter::Point { intensity: 2.0, position: [0.0, 0.0, 1.5] },
        Emitter::Directional { irradiance: 2.0, toward_light: [0.0, 0.0, 1.0], depth: 1.5 },
        Emitter::Area { intensity: 2.0, position: [0.0, 0.0, 1.5], normal: [0.0, 0.6, -0.8] },
    ] {
        let r = irradiance(&emitter, &medium, [0.0, 0.6, 0.8], &WalkConfig::new(1000, 4, 1)).unwrap();
        assert!(r.orders.iter().chain([&r.tail]).all(|o| o.mean == 0.0 && o.std_error == 0.0));
        assert_eq!(r.total.mean, r.direct);
        let expected = match emitter {
            Emitter::Point { .. } => 2.0 * (-0.7f64 * 1.5).exp() * 0.8 / 2.25,
            Emitter::Directional { .. } => 2.0 * (-0.7f64 * 1.5).exp() * 0.8,
            Emitter::Area { .. } => 2.0 * 0.8 * (-0.7f64 * 1.5).exp() * 0.8 / 2.25,
        };
        assert!((r.direct - expected).abs() <= 1e-15 * expected);
    }
}

/// Net outward flux around a conservative isotropic point source: `E_{+l} − E_{−l} = I/R²` over all
/// orders (the normal `+l` faces the source and collects outward-travelling light). Removal only
/// happens outside the sphere, so this holds exactly for the truncated process too.
#[test]
fn conservative_point_source_net_flux_is_emitted_power() {
    let medium = Medium { sigma_s: 1.0, sigma_a: 0.0, g: 0.0 };
    for radius in [0.5, 1.0] {
        let emitter = Emitter::Point { intensity: 2.0, position: L.map(|c| c * radius) };
        let cfg = |seed| WalkConfig { photons: 120_000, max_order: 4, seed, far_mfp: 6.0 };
        let out = irradiance(&emitter, &medium, L, &cfg(1)).unwrap();
        let inward = irradiance(&emitter, &medium, L.map(|c| -c), &cfg(2)).unwrap();
        let net = out.total.mean - inward.total.mean;
        let se = out.total.std_error.hypot(inward.total.std_error);
        let exact = 2.0 / (radius * radius);
        eprintln!("R = {radius}: net {net:.5} ± {se:.5} vs {exact} (direct {:.4})", out.direct);
        assert!((net - exact).abs() < 4.0 * se, "R = {radius}: {net} ± {se} vs {exact}");
        assert!(se < 0.01 * exact);
    }
}

/// Conservative half-space: the net downward flux `E_{+l} − E_{−l}` equals the power absorbed below
/// the receiver plane. Untruncated that is 0 (all light is eventually reflected); with removal
/// beyond `R_c` it is exactly `E₀ ·` the removed weight, which falls as `R_c` grows.
#[test]
fn conservative_half_space_net_flux_is_removed_power() {
    let medium = Medium { sigma_s: 2.0, sigma_a: 0.0, g: 0.5 };
    let emitter = Emitter::Directional { irradiance: 1.5, toward_light: L, depth: 0.5 };
    let mut removed = Vec::new();
    for far_mfp in [4.0, 16.0] {
        let cfg = |seed| WalkConfig { photons: 100_000, max_order: 3, seed, far_mfp };
        let down = irradiance(&emitter, &medium, L, &cfg(1)).unwrap();
        let up = irradiance(&emitter, &medium, L.map(|c| -c), &cfg(2)).unwrap();
        let lost = irradiance(&emitter, &medium, L, &cfg(3)).unwrap().truncated_weight;
        let net = down.total.mean - up.total.mean;
        let se = down.total.std_error.hypot(up.total.std_error).hypot(1.5 * lost.std_error);
        eprintln!("R_c = {far_mfp}: net {net:.5} vs E0·removed {:.5} ± {se:.5}", 1.5 * lost.mean);
        assert!((net - 1.5 * lost.mean).abs() < 4.0 * se);
        assert!(se < 0.01 * down.total.mean);
        removed.push(lost.mean);
    }
    assert!(removed[1] < 0.5 * removed[0], "{removed:?}");
}

/// Bit-identical results for rayon pools of 1 and 2 threads.
#[test]
fn results_do_not_depend_on_thread_count() {
    let medium = Medium { sigma_s: 1.0, sigma_a: 0.2, g: 0.3 };
    for emitter in [
        Emitter::Point { intensity: 1.0, position: [0.3, 0.4, 1.2] },
        Emitter::Directional { irradiance: 1.0, toward_light: [0.0, 0.6, 0.8], depth: 0.7 },
        Emitter::Area { intensity: 1.0, position: [0.3, 0.4, 1.2], normal: [1.0, 0.0, -0.5] },
    ] {
        let run = |threads| {
            let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
            pool.install(|| irradiance(&emitter, &medium, [0.0, 0.0, 1.0], &WalkConfig::new(20_000, 3, 99)).unwrap())
        };
        let (a, b) = (run(1), run(2));
        let bits = |r: &WalkResult| -> Vec<u64> {
            let mut v: Vec<u64> = r.orders.iter().flat_map(|o| [o.mean.to_bits(), o.std_error.to_bits()]).collect();
            for o in [r.tail, r.total, r.truncated_weight] {
                v.extend([o.mean.to_bits(), o.std_error.to_bits()]);
            }
            v.extend([r.direct.to_bits(), r.nonfinite_discarded, r.photons]);
            v
        };
        assert_eq!(bits(&a), bits(&b));
        assert!(a.orders[0].mean > 0.0);
    }
}

/// Out-of-range parameters give errors naming the parameter and its range.
#[test]
fn bad_parameters_are_rejected_by_name() {
    let medium = Medium { sigma_s: 1.0, sigma_a: 0.1, g: 0.2 };
    let point = Emitter::Point { intensity: 1.0, position: [0.0, 0.0, 1.0] };
    let cfg = WalkConfig::new(1000, 3, 1);
    let cases: Vec<(&str, Result<WalkResult, WalkError>)> = vec![
        ("medium.g", irradiance(&point, &Medium { g: 1.0, ..medium }, [0.0, 0.0, 1.0], &cfg)),
        ("medium.g", irradiance(&point, &Medium { g: f64::NAN, ..medium }, [0.0, 0.0, 1.0], &cfg)),
        ("medium.sigma_s", irradiance(&point, &Medium { sigma_s: -1.0, ..medium }, [0.0, 0.0, 1.0], &cfg)),
        ("medium.sigma_a", irradiance(&point, &Medium { sigma_a: -0.1, ..medium }, [0.0, 0.0, 1.0], &cfg)),
        (
            "emitter.position",
            irradiance(&Emitter::Point { intensity: 1.0, position: [0.0; 3] }, &medium, [0.0, 0.0, 1.0], &cfg),
        ),
        (
            "emitter.intensity",
            irradiance(&Emitter::Point { intensity: -1.0, position: [1.0, 0.0, 0.0] }, &medium, [0.0, 0.0, 1.0], &cfg),
        ),
        ("normal", irradiance(&point, &medium, [0.0; 3], &cfg)),
        (
            "emitter.normal",
            irradiance(
                &Emitter::Area { intensity: 1.0, position: [1.0, 0.0, 0.0], normal: [0.0, f64::NAN, 1.0] },
                &medium,
                [0.0, 0.0, 1.0],
                &cfg,
            ),
        ),
        (
            "emitter.position",
            irradiance(
                &Emitter::Area { intensity: 1.0, position: [0.0; 3], normal: [0.0, 0.0, 1.0] },
                &medium,
                [0.0, 0.0, 1.0],
                &cfg,
            ),
        ),
        (
            "emitter.intensity",
            irradiance(
                &Emitter::Area { intensity: f64::INFINITY, position: [1.0, 0.0, 0.0], normal: [0.0, 0.0, 1.0] },
                &medium,
                [0.0, 0.0, 1.0],
                &cfg,
            ),
        ),
        ("normal", irradiance(&point, &medium, [f64::INFINITY, 0.0, 0.0], &cfg)),
        (
            "emitter.toward_light",
            irradiance(
                &Emitter::Directional { irradiance: 1.0, toward_light: [0.0; 3], depth: 1.0 },
                &medium,
                [0.0, 0.0, 1.0],
                &cfg,
            ),
        ),
        (
            "emitter.depth",
            irradiance(
                &Emitter::Directional { irradiance: 1.0, toward_light: [0.0, 0.0, 1.0], depth: -1.0 },
                &medium,
                [0.0, 0.0, 1.0],
                &cfg,
            ),
        ),
        ("cfg.photons", irradiance(&point, &medium, [0.0, 0.0, 1.0], &WalkConfig { photons: 10, ..cfg })),
        ("cfg.max_order", irradiance(&point, &medium, [0.0, 0.0, 1.0], &WalkConfig { max_order: 5000, ..cfg })),
        ("cfg.far_mfp", irradiance(&point, &medium, [0.0, 0.0, 1.0], &WalkConfig { far_mfp: 0.5, ..cfg })),
    ];
    for (name, result) in cases {
        let err = result.expect_err(name).to_string();
        assert!(err.starts_with(name) && err.contains("valid range"), "{name}: {err}");
    }
}

/// The sampler draws the phase it claims: mean cosine `g`, and the fraction of samples below each
/// of a few cosines matches the quadrature of the phase; the phase integrates to 1.
#[test]
fn hg_sampler_and_phase_are_consistent() {
    for g in [-0.9, -0.5, -1e-7, 0.0, 3e-7, 0.5, 0.9] {
        let norm = integrate(&|mu| 2.0 * PI * photon::hg_phase(g, mu), -1.0, 1.0, 1e-12);
        assert!((norm - 1.0).abs() < 1e-9, "g = {g}: {norm}");
        let n = 200_000;
        let samples: Vec<f64> = (0..n).map(|i| photon::hg_sample(g, (f64::from(i) + 0.5) / f64::from(n))).collect();
        let mean = samples.iter().sum::<f64>() / f64::from(n);
        assert!((mean - g).abs() < 1e-4, "g = {g}: mean cosine {mean}");
        for cut in [-0.5, 0.0, 0.7] {
            let below = samples.iter().filter(|&&m| m < cut).count() as f64 / f64::from(n);
            let cdf = integrate(&|mu| 2.0 * PI * photon::hg_phase(g, mu), -1.0, cut, 1e-12);
            assert!((below - cdf).abs() < 1e-4, "g = {g}, cut {cut}: {below} vs {cdf}");
        }
    }
}

/// The removal bound quoted in the module doc holds for the default `R_c = 40 + 2K`.
#[test]
fn default_removal_bound_is_negligible() {
    for k in [0, 1, 10, 30, 100, 1000] {
        let bound = poisson_cdf(WalkConfig::new(64, k, 0).far_mfp, k);
        assert!(bound < 2e-15, "K = {k}: {bound}");
    }
    assert!((poisson_cdf(2.0, 1) - 3.0 * (-2.0f64).exp()).abs() < 1e-16);
}

/// Extreme but valid inputs: no panic, finite results, nothing discarded.
#[test]
fn extreme_inputs_stay_finite() {
    let media = [
        Medium { sigma_s: 1.0, sigma_a: 0.0, g: 0.999_999 },
        Medium { sigma_s: 1.0, sigma_a: 0.0, g: -0.999_999 },
        Medium { sigma_s: 1e-100, sigma_a: 1e100, g: 5e-7 },
        Medium { sigma_s: 1e100, sigma_a: 0.0, g: -5e-7 },
        Medium { sigma_s: 1e-100, sigma_a: 0.0, g: 0.3 },
    ];
    let emitters = [
        Emitter::Point { intensity: 1e100, position: [1e-100, 0.0, 0.0] },
        Emitter::Point { intensity: 1.0, position: [0.0, -1e100, 0.0] },
        Emitter::Point { intensity: 0.0, position: [0.3, 0.0, 0.0] },
        Emitter::Directional { irradiance: 1e100, toward_light: [1e-150, 0.0, 0.0], depth: 0.0 },
        Emitter::Directional { irradiance: 1.0, toward_light: [0.0, 0.0, -3.0], depth: 1e100 },
        Emitter::Directional { irradiance: 1.0, toward_light: [0.0, 0.0, 1.0], depth: 1e-100 },
        Emitter::Area { intensity: 1e100, position: [1e-100, 0.0, 0.0], normal: [-1.0, 0.0, 0.0] },
        Emitter::Area { intensity: 1.0, position: [0.0, 1e100, 0.0], normal: [0.0, 1e-150, 0.0] },
        Emitter::Area { intensity: 1.0, position: [0.0, 0.0, 0.5], normal: [1.0, 0.0, 0.0] },
    ];
    for medium in &media {
        for emitter in &emitters {
            for normal in [[1.0, 0.0, 0.0], [0.0, 1e-150, 0.0], [-1.0, 1.0, 1.0]] {
                let cfg = WalkConfig { photons: 64, max_order: 2, seed: 3, far_mfp: 3.0 };
                let r = irradiance(emitter, medium, normal, &cfg).unwrap();
                let all = r.orders.iter().chain([&r.tail, &r.total, &r.truncated_weight]);
                assert!(
                    r.direct.is_finite() && all.clone().all(|o| o.mean.is_finite() && o.std_error.is_finite()),
                    "{emitter:?} {medium:?}: {r:?}"
                );
                assert_eq!(r.nonfinite_discarded, 0, "{emitter:?} {medium:?}");
            }
        }
    }
    let r = irradiance(
        &emitters[0],
        &media[0],
        [1.0, 0.0, 0.0],
        &WalkConfig { photons: 64, max_order: 0, seed: 1, far_mfp: 1.0 },
    );
    assert!(r.unwrap().orders.is_empty());
}
