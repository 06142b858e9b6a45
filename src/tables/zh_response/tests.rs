//! Tests of the `ZhResponse` kind and its query API against independently derived values: the transport's
//! own interpolation law, the earlier `zh_transport::query` remapping, the random walk in real media
//! (absorption, g between slices, similarity), the analytic direct term and vacuum limit, full SH rotation
//! plus numerical quadrature for the Appendix A shading, and the extreme inputs of issue 3.

use std::sync::OnceLock;

use super::*;
use crate::physics::sh;
use crate::physics::zh_transport::tail;

/// A small table (g ∈ {0, 0.5}, 48 distances, 6 nodes per panel, B = 10), generated once.
fn small() -> &'static (ZhResponse, Generated, ZhResponseTable) {
    static T: OnceLock<(ZhResponse, Generated, ZhResponseTable)> = OnceLock::new();
    T.get_or_init(|| {
        let def = ZhResponse {
            emitters: EmitterProfile::AXIAL.to_vec(),
            g: GValues::List(vec![0.0, 0.5]),
            distance_bins: 48,
            quadrature_nodes: 6,
            element: Element::F64,
            ..ZhResponse::default()
        };
        assert!(def.validate().is_empty(), "{:?}", def.validate());
        let generated = def.generate(&[7; 32], &|_| {}).unwrap();
        let table = ZhResponseTable::from_arrays(&def, &generated.arrays, &generated.values).unwrap();
        (def, generated, table)
    })
}

/// The transport response of the small table's slice (profile, g index), rebuilt from the arrays.
fn response(profile: EmitterProfile, gi: usize) -> zh_transport::Response {
    let (def, generated, _) = small();
    let ei = def.emitters.iter().position(|e| *e == profile).unwrap();
    let ds = def.distance_axis().values_vec();
    let (nb, nd, n) = (def.bounces as usize, ds.len(), def.zh_order as usize);
    let k = def.arrays_per_emitter();
    let all = generated.values[k * ei + 1].to_f64();
    let per_g = &all[gi * nb * nd * n..(gi + 1) * nb * nd * n];
    let bounces =
        (0..nb).map(|b| (0..nd).map(|i| per_g[(b * nd + i) * n..(b * nd + i + 1) * n].to_vec()).collect()).collect();
    let direct = generated.values[k * ei].to_f64()[gi * nd..(gi + 1) * nd].to_vec();
    zh_transport::Response { kind: profile.transport().unwrap(), distances: ds, direct, bounces }
}

fn point(d: f64) -> Emitter {
    Emitter::Point { intensity: 1.0, position: [0.0, 0.0, d] }
}

fn directional(d: f64) -> Emitter {
    Emitter::Directional { irradiance: 1.0, toward_light: [0.0, 0.0, 1.0], depth: d }
}

fn receiver(cos_n: f64) -> Receiver {
    Receiver { position: [0.0; 3], normal: [(1.0 - cos_n * cos_n).max(0.0).sqrt(), 0.0, cos_n] }
}

/// No back-scatter shift, no tail, no similarity: the tabulated orders only.
const PLAIN: QueryOptions = QueryOptions { backscatter: false, tail: false, similarity: false, max_bounce: None };

/// The query's fast interpolation (precomputed logarithms and shapes, node-major) reproduces the
/// generator's law `Response::zh_at` below, on, between and beyond the nodes.
#[test]
fn fast_interpolation_reproduces_the_transport_law() {
    let (def, _, table) = small();
    let ds = def.distance_axis().values_vec();
    let mut probes = vec![1e-9, 1e-4, 200.0, 1e4];
    probes.extend(ds.iter().copied());
    probes.extend(ds.windows(2).map(|w| (w[0] * w[1]).sqrt()));
    for profile in EmitterProfile::AXIAL {
        let r = response(profile, 1);
        for &d in &probes {
            for b in 1..=10 {
                let want = r.zh_at(b, d);
                let mut got = vec![0.0; want.len()];
                table.accumulate(profile, 0.5, d, b..=b, 1.0, 1.0, &mut got).unwrap();
                for (l, (x, y)) in got.iter().zip(&want).enumerate() {
                    let scale = want[0].abs().max(1e-300);
                    assert!((x - y).abs() <= 1e-12 * scale, "{profile:?} b={b} d={d} l={l}: {x} vs {y}");
                }
            }
        }
    }
}

#[test]
fn remapping_matches_the_transport_query_side() {
    // zh_transport::query is an earlier, separately written remapping (per-bounce lookups, no fast path).
    // Scene distances are chosen so that σ_t d lands on table nodes, where both interpolation laws are
    // exact: what is compared is the remapping alone.
    let (def, _, table) = small();
    let ds = def.distance_axis().values_vec();
    for profile in EmitterProfile::AXIAL {
        let r = response(profile, 1);
        for (sigma_s, sigma_a) in [(1.0, 0.0), (2.0, 0.5), (0.3, 3.0)] {
            for node in [ds[10], ds[25], ds[40]] {
                let dist = node / (sigma_s + sigma_a);
                for cos_n in [1.0, 0.3, -0.6] {
                    let m = HomogeneousMedium { sigma_s, sigma_a, g: 0.5 };
                    let want = r.irradiance_in(&m, 2.5, dist, cos_n).unwrap();
                    let emitter = match profile {
                        EmitterProfile::Point => Emitter::Point { intensity: 2.5, position: [0.0, 0.0, dist] },
                        _ => Emitter::Directional { irradiance: 2.5, toward_light: [0.0, 0.0, 1.0], depth: dist },
                    };
                    let got = table.irradiance(&m, &emitter, &receiver(cos_n), &PLAIN).unwrap();
                    for (name, x, y) in [
                        ("direct", got.direct, want.direct),
                        ("single", got.single, want.single),
                        ("multiple", got.multiple, want.multiple),
                    ] {
                        assert!(
                            (x - y).abs() <= 1e-9 * y.abs() + 1e-300,
                            "{profile:?} σ=({sigma_s},{sigma_a}) d={dist} cos={cos_n} {name}: {x} vs {y}"
                        );
                    }
                }
            }
        }
    }
}

#[test]
fn direct_term_is_analytic_and_vacuum_leaves_only_it() {
    let (_, _, table) = small();
    let m = HomogeneousMedium { sigma_s: 0.0, sigma_a: 0.7, g: 0.0 };
    let d = 1.9;
    let cos_n: f64 = 0.8;
    let p = table.irradiance(&m, &point(d), &receiver(cos_n), &QueryOptions::default()).unwrap();
    let want = (-0.7 * d).exp() * cos_n / (d * d);
    assert!((p.direct - want).abs() <= 1e-15 * want, "{} vs {want}", p.direct);
    assert_eq!((p.single, p.multiple, p.tail), (0.0, 0.0, 0.0));
    let s = table.irradiance(&m, &directional(d), &receiver(cos_n), &QueryOptions::default()).unwrap();
    let want = (-0.7 * d).exp() * cos_n;
    assert!((s.direct - want).abs() <= 1e-15 * want);
    assert_eq!(s.total, s.direct);
    // σ_s → 0: the scattered parts vanish linearly (single ∝ σ_s), nothing jumps.
    let tiny = |s: f64| {
        table.irradiance(&HomogeneousMedium { sigma_s: s, sigma_a: 0.7, g: 0.0 }, &point(d), &receiver(1.0), &PLAIN)
    };
    let (a, b) = (tiny(1e-6).unwrap().single, tiny(2e-6).unwrap().single);
    assert!(a > 0.0 && ((b / a) - 2.0).abs() < 1e-4, "{a} {b}");
}

#[test]
fn appendix_a_shading_matches_full_sh_rotation_and_quadrature() {
    let (_, _, table) = small();
    let m = HomogeneousMedium { sigma_s: 0.8, sigma_a: 0.2, g: 0.25 };
    let e = Emitter::Point { intensity: 1.0, position: [0.3, -0.4, 1.1] };
    for normal in [[0.0, 0.0, 1.0], [0.6, 0.0, 0.8], [-0.3, 0.9, 0.1], [0.2, 0.1, -1.0]] {
        let r = Receiver { position: [0.1, 0.0, -0.2], normal };
        let irr = table.irradiance(&m, &e, &r, &PLAIN).unwrap();
        let rad = table.radiance(&m, &e, &r, &PLAIN).unwrap();
        let len = (normal[0] * normal[0] + normal[1] * normal[1] + normal[2] * normal[2]).sqrt();
        let n = normal.map(|c| c / len);
        let cosine = sh::zh_rotate(&sh::clamped_cosine_zh(table.order), n);
        let full = sh::sh_dot(&rad.sh, &cosine);
        // Numerical quadrature of the band-limited radiance times the clamped cosine.
        let order = table.order;
        let mut quad = 0.0;
        for (mu, wm) in sh::gauss_legendre(64) {
            for k in 0..128 {
                let phi = std::f64::consts::TAU * (k as f64 + 0.5) / 128.0;
                let s = (1.0 - mu * mu).sqrt();
                let w = [s * phi.cos(), s * phi.sin(), mu];
                let radiance: f64 = sh::sh_eval(order, w).iter().zip(&rad.sh).map(|(y, c)| y * c).sum();
                let c = (n[0] * w[0] + n[1] * w[1] + n[2] * w[2]).max(0.0);
                quad += wm * std::f64::consts::TAU / 128.0 * radiance * c;
            }
        }
        let parts = irr.single + irr.multiple;
        assert!((full - parts).abs() <= 1e-10 * parts.abs().max(1e-12), "{normal:?}: SH route {full} vs O(N) {parts}");
        assert!((quad - full).abs() <= 2e-3 * full.abs().max(1e-6), "{normal:?}: quadrature {quad} vs SH {full}");
    }
}

/// Walk in a real medium: σ_s = 1.5, σ_a = 0.5 (α = 0.75), scene distance 1 m (d_q = 2 mfp), facing
/// receiver. On a slice (g = 0, 0.5): single and orders 2..=10 within 3 % + 4σ (the small table has 48
/// distances). Halfway between slices 0.5 apart (g = 0.25) the linear g interpolation itself errs: measured
/// 0.1 % (point) and 5.5 % (directional, whose facing receiver sees back-scattered light, and HG's
/// back-scatter p(−1, g) is strongly convex in g); pinned at 8 %. Denser g lists shrink it quadratically.
#[test]
fn real_medium_with_absorption_and_g_interpolation_matches_the_walk() {
    let (_, _, table) = small();
    for (profile, e) in [(EmitterProfile::Point, point(1.0)), (EmitterProfile::Directional, directional(1.0))] {
        for g in [0.0, 0.25, 0.5] {
            let medium = walk::Medium { sigma_s: 1.5, sigma_a: 0.5, g };
            let em = match profile {
                EmitterProfile::Point => walk::Emitter::Point { intensity: 1.0, position: [0.0, 0.0, 1.0] },
                _ => walk::Emitter::Directional { irradiance: 1.0, toward_light: [0.0, 0.0, 1.0], depth: 1.0 },
            };
            let w = walk::irradiance(&em, &medium, [0.0, 0.0, 1.0], &walk::WalkConfig::new(1 << 17, 10, 11)).unwrap();
            let got = table
                .irradiance(&HomogeneousMedium { sigma_s: 1.5, sigma_a: 0.5, g }, &e, &receiver(1.0), &PLAIN)
                .unwrap();
            let single = w.orders[0];
            let multi: f64 = w.orders[1..].iter().map(|o| o.mean).sum();
            let multi_err: f64 = w.orders[1..].iter().map(|o| o.std_error * o.std_error).sum::<f64>().sqrt();
            println!(
                "{profile:?} g={g}: single {:.5} vs walk {:.5} ± {:.5}; multiple {:.5} vs {:.5} ± {:.5}",
                got.single, single.mean, single.std_error, got.multiple, multi, multi_err
            );
            let tol = if g == 0.25 { 0.08 } else { 0.03 };
            assert!((got.single - single.mean).abs() <= tol * single.mean + 4.0 * single.std_error);
            assert!((got.multiple - multi).abs() <= tol * multi + 4.0 * multi_err);
        }
    }
}

#[test]
fn extreme_inputs_are_finite_non_negative_and_continuous() {
    let (_, _, table) = small();
    let ok =
        |x: &Irradiance| [x.direct, x.single, x.multiple, x.tail, x.total].iter().all(|v| v.is_finite() && *v >= 0.0);
    let media = [
        HomogeneousMedium { sigma_s: 1.0, sigma_a: 0.0, g: 0.5 }, // albedo exactly 1
        HomogeneousMedium { sigma_s: 1e-3, sigma_a: 1e3, g: 0.0 }, // σ_a ≫ σ_s
        HomogeneousMedium { sigma_s: 1e-12, sigma_a: 0.0, g: 0.25 }, // σ_s → 0
        HomogeneousMedium { sigma_s: 1e4, sigma_a: 0.0, g: 0.5 }, // very thick
        HomogeneousMedium { sigma_s: 1.0, sigma_a: 0.0, g: 0.5 - 1e-12 }, // at a slice boundary
    ];
    for m in media {
        for d in [1e-12, 1e-6, 0.01, 1.0, 50.0, 1e3, 1e12] {
            for cos_n in [1.0, 1e-9, 0.0, -1e-9, -1.0] {
                for opts in [PLAIN, QueryOptions { backscatter: true, similarity: true, ..QueryOptions::default() }] {
                    for e in [point(d), directional(d)] {
                        let x = table.irradiance(&m, &e, &receiver(cos_n), &opts).unwrap();
                        assert!(ok(&x), "{m:?} d={d} cos={cos_n} {opts:?} {e:?}: {x:?}");
                    }
                }
            }
        }
    }
    // Beyond the table (64 mfp): decays, never clamps upward.
    let m = HomogeneousMedium { sigma_s: 1.0, sigma_a: 0.0, g: 0.0 };
    let at = |d: f64| table.irradiance(&m, &point(d), &receiver(1.0), &PLAIN).unwrap().single;
    assert!(at(70.0) < at(64.0) && at(100.0) < at(70.0) && at(1e3) == 0.0);
    // Continuous in d across nodes and the last node, and in g across the slice boundary.
    let ds = small().0.distance_axis().values_vec();
    for &node in ds.iter().step_by(7).chain([ds[ds.len() - 1]].iter()) {
        let (a, b) = (at(node * (1.0 - 1e-9)), at(node * (1.0 + 1e-9)));
        assert!((a - b).abs() <= 1e-6 * a.max(1e-300), "jump at d = {node}: {a} vs {b}");
    }
    let gq = |g: f64| {
        table
            .irradiance(&HomogeneousMedium { sigma_s: 1.0, sigma_a: 0.0, g }, &point(1.0), &receiver(1.0), &PLAIN)
            .unwrap()
            .single
    };
    assert!((gq(0.5 - 1e-10) - gq(0.5)).abs() <= 1e-8 * gq(0.5));
    // Receiver inside the back-scatter shift (closer to the light than ε = 0.125 mfp): finite, continuous.
    let bs = QueryOptions { backscatter: true, ..PLAIN };
    let near = |d: f64| table.irradiance(&m, &point(d), &receiver(1.0), &bs).unwrap();
    for d in [0.2, 0.125, 0.1, 0.0625] {
        let (a, b) = (near(d).single, near(d * (1.0 + 1e-9)).single);
        assert!(a.is_finite() && (a - b).abs() <= 1e-6 * a, "d = {d}: {a} vs {b}");
    }
    // Back-scatter shift changes only the scattered parts.
    let (x, y) = (near(1.0), table.irradiance(&m, &point(1.0), &receiver(1.0), &PLAIN).unwrap());
    assert_eq!(x.direct, y.direct);
    assert!(x.single > y.single, "a receiver shifted toward the light sees more scattered light");
}

#[test]
fn bad_queries_are_errors_naming_the_problem() {
    let (_, _, table) = small();
    let m = HomogeneousMedium { sigma_s: 1.0, sigma_a: 0.0, g: 0.0 };
    let err =
        |m: HomogeneousMedium, e: Emitter, r: Receiver| table.irradiance(&m, &e, &r, &PLAIN).unwrap_err().to_string();
    assert!(
        err(HomogeneousMedium { g: 0.7, ..m }, point(1.0), receiver(1.0))
            .contains("outside the table's g range [0, 0.5]")
    );
    assert!(err(HomogeneousMedium { g: -0.1, ..m }, point(1.0), receiver(1.0)).contains("g range"));
    assert!(err(HomogeneousMedium { sigma_s: -1.0, ..m }, point(1.0), receiver(1.0)).contains("sigma_s"));
    assert!(err(HomogeneousMedium { sigma_a: f64::NAN, ..m }, point(1.0), receiver(1.0)).contains("sigma_a"));
    assert!(err(m, point(0.0), receiver(1.0)).contains("at the point light"));
    assert!(err(m, point(1.0), Receiver { position: [0.0; 3], normal: [0.0; 3] }).contains("normal"));
    let e = Emitter::Directional { irradiance: 1.0, toward_light: [0.0; 3], depth: 1.0 };
    assert!(err(m, e, receiver(1.0)).contains("toward_light"));
    let e = Emitter::Point { intensity: f64::INFINITY, position: [0.0, 0.0, 1.0] };
    assert!(err(m, e, receiver(1.0)).contains("intensity"));
}

#[test]
fn validation_names_each_bad_field() {
    let bad = ZhResponse {
        emitters: vec![EmitterProfile::Point, EmitterProfile::Point],
        g: GValues::List(vec![0.5, 0.0, 0.995]),
        bounces: 0,
        zh_order: 40,
        distance_bins: 2,
        distance_min: 2.0,
        distance_max: 0.5,
        quadrature_nodes: 1,
        backscatter_shift: -0.1,
        zstd_level: 30,
        ..ZhResponse::default()
    };
    let fields: Vec<&str> = bad.validate().iter().map(|i| i.field).collect();
    for f in [
        "emitters",
        "g",
        "bounces",
        "zh_order",
        "distance_bins",
        "distance_min",
        "distance_max",
        "quadrature_nodes",
        "backscatter_shift",
        "zstd_level",
    ] {
        assert!(fields.contains(&f), "{f} not reported: {fields:?}");
    }
    assert!(ZhResponse::default().validate().is_empty());
}

#[test]
fn generation_is_thread_count_independent() {
    let def = ZhResponse {
        g: GValues::List(vec![0.3]),
        distance_bins: 8,
        quadrature_nodes: 3,
        bounces: 3,
        ..ZhResponse::default()
    };
    let run = |threads| {
        let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
        pool.install(|| def.generate(&[1; 32], &|_| {}).unwrap().values)
    };
    assert_eq!(run(1), run(3));
}

/// The tail through the query equals `zh_transport::tail::tail_at` on albedo and distance nodes (what was
/// tabulated) and stays within the measured interpolation error between them, relative to the whole
/// scattered fluence (orders ≤ B plus tail) a query adds it to: between albedo nodes (`tail/α^{B+1}`
/// blended in `√(1 − α)`): measured 1.2 %; between the distance nodes of this coarse 48-node axis
/// (`e^{νd} c_0` geometric): measured 0.8 %. Pinned at 2.5 % and 1.5 %.
#[test]
fn tail_query_reproduces_the_closure() {
    let (def, _, table) = small();
    let ds = def.distance_axis().values_vec();
    let mut worst = [0.0f64; 2];
    for profile in EmitterProfile::AXIAL {
        let r = response(profile, 1);
        // Up to 8 mean free paths (issue 3's range); far beyond, the tail's decay e^{−ν(α)d} makes the
        // relative α-interpolation error grow, on values below e^{−40}.
        for (i, &d) in ds.iter().enumerate().filter(|(_, d)| **d <= 8.0) {
            for (k, &alpha) in TAIL_ALBEDOS.iter().enumerate() {
                let want = tail::tail_at(&r, 0.5, alpha, d);
                let mut got = [0.0; 2];
                table.accumulate_tail(profile, 0.5, d, alpha, 1.0, &mut got).unwrap();
                for l in 0..2 {
                    assert!((got[l] - want[l]).abs() <= 1e-12 * want[0].max(1e-300), "{profile:?} d={d} α={alpha}");
                }
                // Between albedo nodes and between distance nodes.
                if k + 1 < TAIL_ALBEDOS.len() && i + 1 < ds.len() {
                    for (which, a, dd) in
                        [(0, 0.5 * (alpha + TAIL_ALBEDOS[k + 1]), d), (1, alpha, (d * ds[i + 1]).sqrt())]
                    {
                        let want = tail::tail_at(&r, 0.5, a, dd);
                        let mut got = [0.0; 2];
                        table.accumulate_tail(profile, 0.5, dd, a, 1.0, &mut got).unwrap();
                        // Relative to the whole scattered fluence (orders ≤ B plus tail): what a query sees.
                        let truncated: f64 = (1..=10).map(|b| a.powi(b) * r.zh_at(b as usize, dd)[0]).sum();
                        let whole = want[0] + truncated;
                        if whole > 1e-200 {
                            worst[which] = worst[which].max((got[0] - want[0]).abs() / whole);
                        }
                    }
                }
            }
        }
    }
    println!("tail interpolation: worst {:.3e} between albedo nodes, {:.3e} between distances", worst[0], worst[1]);
    assert!(worst[0] < 0.025 && worst[1] < 0.015, "{worst:?}");
}

/// Total irradiance with the tail against the walk's all-order total in an almost conservative medium
/// (α = 0.99: the walk's removal bias ~e^{−R_c/L_diff} is negligible) 4 mean free paths from a point
/// light, where orders beyond B = 10 carry most of the light: without the tail the table is far too dark,
/// with it within 5 % + 4σ (issue 3's total target).
#[test]
fn tail_closes_the_total_in_a_thick_medium() {
    let (_, _, table) = small();
    let sigma_s = 0.99;
    let medium = walk::Medium { sigma_s, sigma_a: 0.01, g: 0.0 };
    let em = walk::Emitter::Point { intensity: 1.0, position: [0.0, 0.0, 4.0] };
    let w = walk::irradiance(&em, &medium, [0.0, 0.0, 1.0], &walk::WalkConfig::new(1 << 14, 10, 3)).unwrap();
    let m = HomogeneousMedium { sigma_s, sigma_a: 0.01, g: 0.0 };
    let with = table.irradiance(&m, &point(4.0), &receiver(1.0), &QueryOptions::default()).unwrap();
    let without = table.irradiance(&m, &point(4.0), &receiver(1.0), &PLAIN).unwrap();
    println!(
        "d = 4 mfp, α = 0.99: walk {:.5} ± {:.5} (orders > 10: {:.5}); table {:.5} with tail ({:.5}), {:.5} without",
        w.total.mean, w.total.std_error, w.tail.mean, with.total, with.tail, without.total
    );
    assert!(without.total < 0.7 * w.total.mean, "the truncated series alone must be visibly dark");
    assert!((with.total - w.total.mean).abs() <= 0.05 * w.total.mean + 4.0 * w.total.std_error);
    assert!((with.tail - w.tail.mean).abs() <= 0.15 * w.tail.mean + 4.0 * w.tail.std_error);
}

/// Similarity `(1 − g) σ_s, g = 0` for the orders ≥ 2 (and the tail) against the walk with the true
/// g = 0.5: a diffusion-regime relation. Deep in an almost conservative medium (α = 0.99, 6 mean free
/// paths from a point light) it comes within 10 % of the walk's all-order total (measured −8.2 %, where
/// the exact-g table with the tail is −2.2 %); in a thin, absorbing
/// configuration (d = 2 mfp, α = 0.75, orders 2..=10) it is far off — measured −52 %, which is why it is
/// an option and off by default.
#[test]
fn similarity_relation_holds_where_light_is_diffuse() {
    let (_, _, table) = small();
    let g = 0.5;
    let m = HomogeneousMedium { sigma_s: 0.99, sigma_a: 0.01, g };
    let em = walk::Emitter::Point { intensity: 1.0, position: [0.0, 0.0, 6.0] };
    let medium = walk::Medium { sigma_s: 0.99, sigma_a: 0.01, g };
    let w = walk::irradiance(&em, &medium, [0.0, 0.0, 1.0], &walk::WalkConfig::new(1 << 14, 10, 9)).unwrap();
    let sim = QueryOptions { similarity: true, ..QueryOptions::default() };
    let got = table.irradiance(&m, &point(6.0), &receiver(1.0), &sim).unwrap();
    let exact = table.irradiance(&m, &point(6.0), &receiver(1.0), &QueryOptions::default()).unwrap();
    println!(
        "similarity, d = 6, α = 0.99, g = 0.5: {:.5} vs walk {:.5} ± {:.5}; exact-g table {:.5}",
        got.total, w.total.mean, w.total.std_error, exact.total
    );
    assert!((got.total - w.total.mean).abs() <= 0.10 * w.total.mean);
    assert!((exact.total - w.total.mean).abs() <= 0.05 * w.total.mean + 4.0 * w.total.std_error);
    assert_eq!(got.single, exact.single, "single scattering always uses the true g");
    // Thin and absorbing: the documented failure of the relation.
    let m = HomogeneousMedium { sigma_s: 1.5, sigma_a: 0.5, g };
    let opts = QueryOptions { similarity: true, ..PLAIN };
    let thin = table.irradiance(&m, &point(1.0), &receiver(1.0), &opts).unwrap().multiple;
    let exact = table.irradiance(&m, &point(1.0), &receiver(1.0), &PLAIN).unwrap().multiple;
    println!("similarity thin: {thin:.5} vs exact-g {exact:.5}");
    assert!(thin < 0.6 * exact, "the relation underestimates thin media strongly ({thin} vs {exact})");
}

/// A small area-emitter table (g ∈ {0, 0.5}, 32 distances, 8 angles, B = 4, 6 nodes per panel).
fn small_area() -> &'static (ZhResponse, ZhResponseTable, Vec<zh_transport::area::AreaResponse>) {
    static T: OnceLock<(ZhResponse, ZhResponseTable, Vec<zh_transport::area::AreaResponse>)> = OnceLock::new();
    T.get_or_init(|| {
        let def = ZhResponse {
            emitters: vec![EmitterProfile::Area],
            g: GValues::List(vec![0.0, 0.5]),
            bounces: 4,
            distance_bins: 32,
            quadrature_nodes: 6,
            element: Element::F64,
            ..ZhResponse::default()
        };
        let generated = def.generate(&[3; 32], &|_| {}).unwrap();
        let table = ZhResponseTable::from_arrays(&def, &generated.arrays, &generated.values).unwrap();
        let direct = zh_transport::area::compute(&def.area_config(0.5)).unwrap();
        (def, table, vec![direct])
    })
}

/// The area query in an arbitrary world frame (patch and receiver anywhere, σ_s = 1, σ_a = 0, g on a slice)
/// reproduces the generator's own canonical evaluation `AreaResponse::irradiance` at the node distances:
/// the frame mapping (light axis, the patch normal's tangential direction, the fitted axis) is right.
#[test]
fn area_query_matches_the_canonical_response_in_any_frame() {
    let (def, table, canon) = small_area();
    let ds = def.distance_axis().values_vec();
    let resp = &canon[0];
    let m = HomogeneousMedium { sigma_s: 1.0, sigma_a: 0.0, g: 0.5 };
    let x = [0.3, -1.2, 0.7];
    for &d in &[ds[5], ds[15], ds[25]] {
        for (dir, ne) in [
            ([0.0, 0.0, 1.0], [0.0, 0.0, -1.0]),
            ([0.6, 0.0, 0.8], [-0.2, 0.9, -0.3]),
            ([-0.48, 0.6, 0.64], [0.1, 0.2, 0.9]),
        ] {
            let p = [x[0] + d * dir[0], x[1] + d * dir[1], x[2] + d * dir[2]];
            for n in [[0.0, 0.0, 1.0], [0.36, 0.48, 0.8], [-0.6, 0.0, -0.8], [0.0, 1.0, 0.0]] {
                let e = Emitter::Area { intensity: 1.0, position: p, normal: ne };
                let got = table.irradiance(&m, &e, &Receiver { position: x, normal: n }, &PLAIN).unwrap();
                // Canonical frame: z = toward the patch, x = tangential part of the patch normal.
                let l = (ne[0] * ne[0] + ne[1] * ne[1] + ne[2] * ne[2]).sqrt();
                let ne = ne.map(|c| c / l);
                let cos_t = -(ne[0] * dir[0] + ne[1] * dir[1] + ne[2] * dir[2]);
                let t = [ne[0] + cos_t * dir[0], ne[1] + cos_t * dir[1], ne[2] + cos_t * dir[2]];
                let tl = (t[0] * t[0] + t[1] * t[1] + t[2] * t[2]).sqrt();
                // Along the axis the patch normal has no tangential part: any perpendicular (here +x) will do.
                let ex = if tl > 1e-12 { t.map(|c| c / tl) } else { [1.0, 0.0, 0.0] };
                let ey =
                    [dir[1] * ex[2] - dir[2] * ex[1], dir[2] * ex[0] - dir[0] * ex[2], dir[0] * ex[1] - dir[1] * ex[0]];
                let dotp = |a: [f64; 3], b: [f64; 3]| a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
                let nc = [dotp(n, ex), dotp(n, ey), dotp(n, dir)];
                let (direct, single, multiple) = resp.irradiance(d, cos_t.clamp(-1.0, 1.0).acos(), nc);
                let (direct, multiple_4) = (direct, multiple);
                for (name, a, b) in [
                    ("direct", got.direct, direct),
                    ("single", got.single, single),
                    ("multiple", got.multiple, multiple_4),
                ] {
                    assert!((a - b).abs() <= 1e-9 * b.abs() + 1e-14, "d={d} dir={dir:?} n={n:?} {name}: {a} vs {b}");
                }
            }
        }
    }
}

/// The area emitter in a real medium (σ_s = 1.5, σ_a = 0.5, 1 m from the receiver: 2 mean free paths)
/// against the walk's area emitter: the patch facing the receiver and tilted by 60° (a node: θ = 3π/7 is
/// the nearest, so 60° reads between nodes), facing receiver. Single within 5 % + 4σ (on this small
/// table; the generator's own single scattering is within 2 % at production size); orders 2..=4 within
/// 15 % (the recursion's bias through the 8-node angle interpolation, measured +2…+20 % per order).
#[test]
fn area_emitter_in_a_real_medium_matches_the_walk() {
    let (_, table, _) = small_area();
    for (theta, g) in [(0.0f64, 0.0), (std::f64::consts::FRAC_PI_3, 0.5)] {
        let ne = [theta.sin(), 0.0, -theta.cos()];
        let em = walk::Emitter::Area { intensity: 1.0, position: [0.0, 0.0, 1.0], normal: ne };
        let medium = walk::Medium { sigma_s: 1.5, sigma_a: 0.5, g };
        let w = walk::irradiance(&em, &medium, [0.0, 0.0, 1.0], &walk::WalkConfig::new(1 << 17, 4, 21)).unwrap();
        let e = Emitter::Area { intensity: 1.0, position: [0.0, 0.0, 1.0], normal: ne };
        let got =
            table.irradiance(&HomogeneousMedium { sigma_s: 1.5, sigma_a: 0.5, g }, &e, &receiver(1.0), &PLAIN).unwrap();
        let single = w.orders[0];
        let multi: f64 = w.orders[1..].iter().map(|o| o.mean).sum();
        println!(
            "area θ={theta:.3} g={g}: direct {:.5} vs {:.5}; single {:.5} vs walk {:.5} ± {:.5}; orders 2-4 {:.5} vs {:.5}",
            got.direct, w.direct, got.single, single.mean, single.std_error, got.multiple, multi
        );
        assert!((got.direct - w.direct).abs() <= 1e-12 * w.direct);
        assert!((got.single - single.mean).abs() <= 0.05 * single.mean + 4.0 * single.std_error);
        assert!((got.multiple - multi).abs() <= 0.15 * multi);
    }
}
