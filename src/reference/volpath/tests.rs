//! Tests of the volumetric path tracer against closed forms, conservation and the photon walk.

use std::f64::consts::PI;

use super::*;
use crate::reference::walk;
use crate::scene::bvh::{MediumSegment, Ray, optical_thickness};
use crate::scene::fixtures::{cuboid, empty, fog_room, point_light};
use crate::scene::{Boundary, Density, Light, LightKind, Material, Medium, Mesh, Surface};

fn opts(samples: u32) -> VolPathOptions {
    VolPathOptions {
        samples,
        max_depth: 64,
        rr_depth: 8,
        seed: 7,
        surface_bounces: u32::MAX,
        eye_surfaces: true,
        media: true,
    }
}

fn run(scene: &Scene, points: &[SurfacePoint], o: &VolPathOptions) -> Vec<Estimate> {
    let bvh = SceneBvh::build(scene);
    let (e, stats) = irradiance(scene, &bvh, points, o);
    assert_eq!(stats.nonfinite, 0);
    e
}

fn pt(position: [f64; 3], normal: [f64; 3]) -> SurfacePoint {
    SurfacePoint { position, normal }
}

pub(super) fn homogeneous(sigma_s: [f64; 3], sigma_a: [f64; 3], g: [f64; 3]) -> Medium {
    Medium { name: "Fog".into(), sigma_s, sigma_a, g, density: Density::Homogeneous, boundary: Boundary::Global }
}

pub(super) fn material(albedo: f64, emission: f64, surface: Surface) -> Material {
    Material { name: "M".into(), base_color: [albedo; 3], emission: [emission; 3], surface, roughness: 1.0 }
}

/// `|a − b| ≤ rel · |b|` per channel.
pub(super) fn close(a: [f64; 3], b: [f64; 3], rel: f64) -> bool {
    (0..3).all(|c| (a[c] - b[c]).abs() <= rel * b[c].abs())
}

/// Point light in vacuum above a grey floor, reflections off: only next-event estimation from the
/// receiver reaches the light, so `E = I cos θ / d²` exactly, with zero spread.
#[test]
fn point_light_in_vacuum_is_inverse_square() {
    let mut s = empty("point.usda");
    s.materials.push(material(0.5, 0.0, Surface::Opaque));
    let mut floor = cuboid("Floor", [-5.0, -0.1, -5.0], [5.0, 0.0, 5.0]);
    floor.material = Some(0);
    s.meshes.push(floor);
    let light = [0.3, 2.0, -0.2];
    s.lights.push(point_light("Bulb", light, 3.5));
    let tilt = 1.0 / 2f64.sqrt();
    let points = [
        pt([0.3, 0.0, -0.2], [0.0, 1.0, 0.0]),
        pt([1.5, 0.0, 0.7], [0.0, 1.0, 0.0]),
        pt([-2.0, 0.0, 1.0], [0.0, 1.0, 0.0]),
        pt([1.0, 0.5, 0.0], [-tilt, tilt, 0.0]),
        pt([1.0, 0.5, 0.0], [tilt, -tilt, 0.0]), // faces away: 0
    ];
    let e = run(&s, &points, &VolPathOptions { media: false, surface_bounces: 0, ..opts(16) });
    for (p, est) in points.iter().zip(&e) {
        let d: Vec<f64> = (0..3).map(|c| light[c] - p.position[c]).collect();
        let r2 = d.iter().map(|x| x * x).sum::<f64>();
        let cos = ((0..3).map(|c| d[c] * p.normal[c]).sum::<f64>() / r2.sqrt()).max(0.0);
        let exact = 3.5 * cos / r2;
        assert!(close(est.mean, [exact; 3], 1e-12), "{:?} vs {exact}", est.mean);
        assert_eq!(est.stderr, [0.0; 3]);
    }
}

/// Irradiance at distance `h` on the axis of a parallel rectangle of half-sides `a`, `b` and radiance `L`.
/// The rectangle splits into four `a × b` rectangles with a corner on the axis; for one of them the
/// contour integral of the projected solid angle (Lambert) gives
/// `π F = ½ [X/√(1+X²) atan(Y/√(1+X²)) + Y/√(1+Y²) atan(X/√(1+Y²))]`, `X = a/h`, `Y = b/h`, so
/// `E = 4 L π F`. Check: `a, b → ∞` gives `E → π L`.
pub(super) fn rect_on_axis(l: f64, a: f64, b: f64, h: f64) -> f64 {
    let (x, y) = (a / h, b / h);
    let (sx, sy) = ((1.0 + x * x).sqrt(), (1.0 + y * y).sqrt());
    2.0 * l * (x / sx * (y / sx).atan() + y / sy * (x / sy).atan())
}

#[test]
fn rect_light_in_vacuum_matches_form_factor() {
    assert!((rect_on_axis(1.0, 1e9, 1e9, 1.0) - PI).abs() < 1e-6);
    // Independent midpoint quadrature of ∫ L cos θ cos θ' / r² dA = ∫ L h² / r⁴ dA.
    let (l, a, b, h) = (2.0, 0.6, 0.3, 0.8);
    let n = 2000;
    let mut quad = 0.0;
    for i in 0..n {
        for j in 0..n {
            let x = -a + 2.0 * a * (i as f64 + 0.5) / n as f64;
            let y = -b + 2.0 * b * (j as f64 + 0.5) / n as f64;
            let r2 = x * x + y * y + h * h;
            quad += l * h * h / (r2 * r2);
        }
    }
    quad *= 4.0 * a * b / (n * n) as f64;
    let exact = rect_on_axis(l, a, b, h);
    assert!((quad - exact).abs() < 1e-6 * exact, "quadrature {quad} vs closed form {exact}");

    let mut s = empty("rect.usda");
    s.lights.push(Light {
        name: "Panel".into(),
        kind: LightKind::Rect {
            center: [0.0, h, 0.0],
            half_u: [a, 0.0, 0.0],
            half_v: [0.0, 0.0, b],
            normal: [0.0, -1.0, 0.0],
        },
        radiance: [l; 3],
    });
    let e = run(&s, &[pt([0.0; 3], [0.0, 1.0, 0.0])], &VolPathOptions { media: false, ..opts(100_000) })[0];
    eprintln!("rect: {:?} ± {:?} vs {exact}", e.mean, e.stderr);
    for c in 0..3 {
        assert!((e.mean[c] - exact).abs() < 3.0 * e.stderr[c] && (e.mean[c] - exact).abs() < 0.01 * exact);
    }
    // Seen from behind (one-sided light): nothing.
    let back = run(&s, &[pt([0.0, 2.0 * h, 0.0], [0.0, -1.0, 0.0])], &opts(64))[0];
    assert_eq!(back.mean, [0.0; 3]);
}

/// A pure absorber filling all space: `E = I e^{−σ_a d} cos θ / d²` exactly (bounce paths are absorbed
/// at their first collision, which scatters nothing).
#[test]
fn pure_absorber_attenuates_exponentially() {
    let mut s = empty("absorb.usda");
    let sigma_a = [0.3, 0.7, 1.9];
    s.media.push(homogeneous([0.0; 3], sigma_a, [0.5; 3]));
    let light = [0.0, 1.7, 0.4];
    s.lights.push(point_light("Bulb", light, 2.0));
    let points = [pt([0.0; 3], [0.0, 1.0, 0.0]), pt([0.5, -0.3, 0.2], [0.6, 0.8, 0.0])];
    let e = run(&s, &points, &opts(32));
    for (p, est) in points.iter().zip(&e) {
        let d: Vec<f64> = (0..3).map(|c| light[c] - p.position[c]).collect();
        let r = d.iter().map(|x| x * x).sum::<f64>().sqrt();
        let cos = (0..3).map(|c| d[c] * p.normal[c]).sum::<f64>() / r;
        let exact = sigma_a.map(|sa| 2.0 * (-sa * r).exp() * cos / (r * r));
        assert!(close(est.mean, exact, 1e-12), "{:?} vs {exact:?}", est.mean);
    }
}

/// Point light in an infinite scattering medium against `reference::walk` (an analog photon walk with
/// its own sampling and kernels): orders 0..=K with `max_depth = K`, within 4 combined standard errors
/// (the walk's per-order errors added linearly: a conservative bound for correlated orders).
#[test]
fn scattering_point_light_matches_photon_walk() {
    const K: usize = 5;
    let d = 1.2;
    for (g, albedo) in [(0.0, 1.0), (0.7, 1.0), (0.0, 0.5), (0.7, 0.5)] {
        let (ss, sa) = (albedo, 1.0 - albedo); // σ_t = 1 /m
        let mut s = empty("walk.usda");
        s.media.push(homogeneous([ss; 3], [sa; 3], [g; 3]));
        s.lights.push(point_light("Bulb", [0.0, d, 0.0], 1.0));
        let normals = [[0.0, 1.0, 0.0], [1.0, 0.0, 0.0]];
        let points: Vec<SurfacePoint> = normals.iter().map(|&n| pt([0.0; 3], n)).collect();
        let o = VolPathOptions { max_depth: K as u32, rr_depth: K as u32, ..opts(30_000) };
        let t0 = std::time::Instant::now();
        let mine = run(&s, &points, &o);
        eprintln!("volpath {:?}", t0.elapsed());
        for (n, e) in normals.iter().zip(&mine) {
            let medium = walk::Medium { sigma_s: ss, sigma_a: sa, g };
            let emitter = walk::Emitter::Point { intensity: 1.0, position: [0.0, d, 0.0] };
            let t0 = std::time::Instant::now();
            // R_c = 25 mfp: orders ≤ K lose at most P[Poisson(25) ≤ 5] ≈ 1e-6 relative.
            let cfg = walk::WalkConfig { far_mfp: 25.0, ..walk::WalkConfig::new(100_000, K, 11) };
            let w = walk::irradiance(&emitter, &medium, *n, &cfg).unwrap();
            assert!(w.order_truncation_bound < 2e-6);
            eprintln!("walk {:?}", t0.elapsed());
            let reference = w.direct + w.orders.iter().map(|o| o.mean).sum::<f64>();
            let ref_se: f64 = w.orders.iter().map(|o| o.std_error).sum();
            let se = (ref_se * ref_se + e.stderr[0] * e.stderr[0]).sqrt();
            eprintln!(
                "g {g} albedo {albedo} n {n:?}: volpath {:.6} ± {:.6}, walk {reference:.6} ± {ref_se:.6} (direct {:.6})",
                e.mean[0], e.stderr[0], w.direct
            );
            assert!((e.mean[0] - reference).abs() < 4.0 * se, "{} vs {reference} (se {se})", e.mean[0]);
            assert_eq!(e.mean[0].to_bits(), e.mean[1].to_bits(), "achromatic channels differ");
        }
    }
}

/// The unit cube with black, inward-facing walls emitting `l`, filled with a chromatic non-absorbing
/// global medium (σ_s 0.5, 2, 4 /m; g 0, 0.5, −0.3).
pub(super) fn furnace_box(l: f64) -> Scene {
    let mut s = empty("furnace.usda");
    s.materials.push(material(0.0, l, Surface::Opaque));
    let mut bx: Mesh = cuboid("Box", [0.0; 3], [1.0, 1.0, 1.0]);
    for t in &mut bx.triangles {
        t.swap(1, 2); // inward-facing (counter-clockwise seen from inside)
    }
    bx.material = Some(0);
    s.meshes.push(bx);
    s.lights.push(Light { name: "Box".into(), kind: LightKind::EmissiveMesh { mesh: 0 }, radiance: [l; 3] });
    s.media.push(homogeneous([0.5, 2.0, 4.0], [0.0; 3], [0.0, 0.5, -0.3]));
    s
}

/// Closed box whose inside walls are black (albedo 0) and emit `L` inward, filled with a
/// non-absorbing medium: the radiance field is uniform, `L` everywhere in every direction (scattering
/// with albedo 1 maps a uniform field onto itself), so every wall point receives `E = π L` exactly.
#[test]
fn emissive_box_with_conservative_medium_is_a_furnace() {
    let l = 1.5;
    let s = furnace_box(l);
    let points = [pt([0.5, 0.0, 0.5], [0.0, 1.0, 0.0]), pt([0.0, 0.3, 0.8], [1.0, 0.0, 0.0])];
    let exact = PI * l;
    for media in [false, true] {
        let e = run(&s, &points, &VolPathOptions { media, ..opts(100_000) });
        for est in &e {
            eprintln!("furnace media {media}: {:?} ± {:?} vs {exact}", est.mean, est.stderr);
            for c in 0..3 {
                let err = (est.mean[c] - exact).abs();
                assert!(err < 3.0 * est.stderr[c].max(1e-12) && err < 0.01 * exact, "{c}: {}", est.mean[c]);
            }
        }
    }
}

/// Hero-channel spectral MIS in a chromatic medium against tracing each channel's coefficients as an
/// achromatic medium (4 combined standard errors).
#[test]
fn chromatic_medium_matches_per_channel_tracing() {
    let build = |sigma_s: [f64; 3], sigma_a: [f64; 3], g: [f64; 3]| {
        let mut s = empty("chroma.usda");
        s.materials.push(material(0.6, 0.0, Surface::Opaque));
        let mut floor = cuboid("Floor", [-3.0, -0.1, -3.0], [3.0, 0.0, 3.0]);
        floor.material = Some(0);
        s.meshes.push(floor);
        s.lights.push(point_light("Bulb", [0.0, 1.0, 0.0], 1.0));
        s.media.push(homogeneous(sigma_s, sigma_a, g));
        s
    };
    let (ss, sa, g) = ([0.3, 1.0, 2.5], [0.2, 0.1, 0.0], [0.0, 0.4, 0.7]);
    let points = [pt([0.4, 0.0, 0.0], [0.0, 1.0, 0.0])];
    let o = opts(20_000);
    let t0 = std::time::Instant::now();
    let chroma = run(&build(ss, sa, g), &points, &o)[0];
    eprintln!("chroma {:?}", t0.elapsed());
    for c in 0..3 {
        let single = run(&build([ss[c]; 3], [sa[c]; 3], [g[c]; 3]), &points, &o)[0];
        let se = (chroma.stderr[c].powi(2) + single.stderr[c].powi(2)).sqrt();
        eprintln!(
            "channel {c}: hero MIS {:.6} ± {:.6}, per-channel {:.6}",
            chroma.mean[c], chroma.stderr[c], single.mean[c]
        );
        assert!((chroma.mean[c] - single.mean[c]).abs() < 4.0 * se);
    }
}

#[test]
fn results_do_not_depend_on_thread_count() {
    let s = fog_room();
    let bvh = SceneBvh::build(&s);
    let points: Vec<SurfacePoint> = (0..6).map(|i| pt([0.5 + 0.5 * i as f64, 0.0, 1.7], [0.0, 1.0, 0.0])).collect();
    let o = opts(200);
    let bits = |threads: usize| {
        let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
        let (e, stats) = pool.install(|| irradiance(&s, &bvh, &points, &o));
        let mut v: Vec<u64> = e.iter().flat_map(|x| x.mean.iter().chain(&x.stderr).map(|f| f.to_bits())).collect();
        v.push(stats.rays);
        v
    };
    assert_eq!(bits(1), bits(2));
}

/// A medium with σ = 0 changes nothing: the same paths as in vacuum (same draws), equal to rounding.
#[test]
fn zero_sigma_medium_equals_vacuum() {
    let mut s = fog_room();
    s.media[0].sigma_s = [0.0; 3];
    s.media[0].sigma_a = [0.0; 3];
    let points = [pt([1.0, 0.0, 1.0], [0.0, 1.0, 0.0]), pt([3.0, 0.0, 2.5], [0.0, 1.0, 0.0])];
    let with = run(&s, &points, &opts(500));
    let without = run(&s, &points, &VolPathOptions { media: false, ..opts(500) });
    for (a, b) in with.iter().zip(&without) {
        assert!(close(a.mean, b.mean, 1e-12), "{:?} vs {:?}", a.mean, b.mean);
        assert!(a.mean[0] > 0.0);
    }
}

/// An index-matched closed medium with σ = 0 between a point light and the receiver is invisible
/// (rays and shadow rays pass its boundary): `E = I/d²` exactly.
#[test]
fn index_matched_boundary_is_transparent() {
    let mut s = empty("matched.usda");
    let mut bx = cuboid("Box", [-0.5, 0.5, -0.5], [0.5, 1.5, 0.5]);
    bx.medium = Some(0);
    s.meshes.push(bx);
    s.media.push(Medium { boundary: Boundary::Mesh(0), ..homogeneous([0.0; 3], [0.0; 3], [0.0; 3]) });
    s.lights.push(point_light("Bulb", [0.0, 2.0, 0.0], 1.0));
    let e = run(&s, &[pt([0.0; 3], [0.0, 1.0, 0.0])], &opts(16))[0];
    assert!(close(e.mean, [0.25; 3], 1e-12), "{:?}", e.mean);
    // The same box made absorbing: E = I e^{−σ_a·1 m}/d².
    s.media[0].sigma_a = [0.5; 3];
    let e = run(&s, &[pt([0.0; 3], [0.0, 1.0, 0.0])], &opts(16))[0];
    assert!(close(e.mean, [0.25 * (-0.5f64).exp(); 3], 1e-6), "{:?}", e.mean);
}

/// Receivers touching a point light, and degenerate points, give finite values (0 where undefined).
#[test]
fn degenerate_receivers_stay_finite() {
    let s = fog_room();
    let bulb = [2.0, 2.0, 2.0];
    let points = [
        pt(bulb, [0.0, 1.0, 0.0]),
        pt([2.0, 2.0 - 1e-9, 2.0], [0.0, 1.0, 0.0]),
        pt([1.0, 0.0, 1.0], [0.0, 0.0, 0.0]),
        pt([1.0, 0.0, 1.0], [f64::NAN, 1.0, 0.0]),
        pt([f64::NAN, 0.0, 1.0], [0.0, 1.0, 0.0]),
    ];
    let e = run(&s, &points, &opts(64));
    for est in &e {
        assert!(est.mean.iter().chain(&est.stderr).all(|x| x.is_finite()), "{est:?}");
    }
    // At 1 nm below the bulb the clamped 1/d² bounds the direct part by I / D_MIN² = 1e8.
    assert!(e[1].mean[0] > 1e7 && e[1].mean[0] < 1.1e8, "{:?}", e[1].mean);
    for est in &e[2..] {
        assert_eq!(est.mean, [0.0; 3]);
    }
}

/// Free flights in exponential height fog: with stratified uniforms `ξ_i = (i + ½)/N` the sampled
/// distances are exact quantiles, so their empirical CDF must match `1 − e^{−τ(t)}` (τ from
/// `optical_thickness`, closed form) to within `1/N` everywhere; and each inversion must reproduce its
/// target depth.
#[test]
fn exponential_fog_free_flights_follow_transmittance() {
    let fog = Medium {
        density: Density::ExponentialHeight {
            rho: 2.0,
            falloff: 0.8,
            direction: [0.0, 1.0, 0.0],
            offset: [0.0, 0.5, 0.0],
        },
        ..homogeneous([0.4; 3], [0.1, 0.3, 0.6], [0.0; 3])
    };
    let mut s = empty("fog.usda");
    s.media.push(fog);
    for dir in [[0.0, 1.0, 0.0], [0.6, -0.8, 0.0], [1.0, 0.0, 0.0], [0.0, 0.6, 0.8]] {
        let ray = Ray::new([0.2, 1.0, -0.3], dir);
        let t_end = 6.0;
        let segs = [MediumSegment { t0: 0.0, t1: t_end, medium: Some(0) }];
        for hero in 0..3 {
            let n = 4000;
            let mut ts: Vec<f64> = (0..n)
                .filter_map(|i| {
                    let xi = (i as f64 + 0.5) / n as f64;
                    let f = flight::fly(&s, &ray, &segs, hero, xi);
                    let c = f.collision?;
                    // The optical depth at the collision is the target −ln(1 − ξ).
                    assert!((f.tau[hero] + (-xi).ln_1p()).abs() < 1e-9 * (1.0 + f.tau[hero]));
                    Some(c.t)
                })
                .collect();
            ts.sort_by(f64::total_cmp);
            for (k, &t) in ts.iter().enumerate().step_by(97) {
                let part = [MediumSegment { t0: 0.0, t1: t, medium: Some(0) }];
                let cdf = -(-optical_thickness(&s, &part, &ray)[hero]).exp_m1();
                let emp = (k as f64 + 0.5) / n as f64;
                assert!((cdf - emp).abs() < 1.0 / n as f64, "dir {dir:?} hero {hero}: {cdf} vs {emp}");
            }
            // Escape fraction = transmittance of the whole segment.
            let escaped = (n - ts.len()) as f64 / n as f64;
            let t_all = (-optical_thickness(&s, &segs, &ray)[hero]).exp();
            assert!((escaped - t_all).abs() <= 1.0 / n as f64, "{escaped} vs {t_all}");
        }
    }
}

/// Throughput on the fog room fixture: `cargo test --lib reference::volpath -- --ignored --nocapture`.
#[test]
#[ignore]
fn fog_room_throughput() {
    let s = fog_room();
    let bvh = SceneBvh::build(&s);
    let points: Vec<SurfacePoint> =
        (0..64).map(|i| pt([0.25 + 0.5 * (i % 8) as f64, 0.0, 0.25 + 0.5 * (i / 8) as f64], [0.0, 1.0, 0.0])).collect();
    let (e, stats) = irradiance(&s, &bvh, &points, &opts(2000));
    let rate = stats.paths as f64 / (stats.ms * 1e-3);
    eprintln!(
        "fog room: {} paths, {} rays in {:.0} ms on {} threads: {rate:.0} paths/s, {:.1} rays/path; E(centre) {:?} ± {:?}",
        stats.paths,
        stats.rays,
        stats.ms,
        rayon::current_num_threads(),
        stats.rays as f64 / stats.paths as f64,
        e[27].mean,
        e[27].stderr
    );
    assert!(rate > 0.0 && e.iter().all(|x| x.mean[0].is_finite()));
}

/// `surface_bounces = 1` in vacuum between a floor and a ceiling (albedo `k`, 6 m × 6 m, 1 m apart), a
/// point light `I` at height `a`: the irradiance at the floor's centre is the direct `I/a²` plus one
/// reflection off the ceiling, `∫ k/π · I (h−a)/d³ · h²/r⁴ dA` over the ceiling (`d`, `r` the distances
/// of a ceiling point to the light and to the receiver), by a 1200² midpoint rule (smooth integrand).
/// `surface_bounces = 0` gives the direct term exactly; all bounces (floor–ceiling–floor) give more.
#[test]
fn surface_bounces_counts_reflections() {
    let (k, h, a, i, half) = (0.7, 1.0, 0.5, 1.0, 3.0);
    let mut s = empty("bounces.usda");
    s.materials.push(material(k, 0.0, Surface::Opaque));
    for (name, lo, hi) in [("Floor", -0.1f32, 0.0f32), ("Ceiling", 1.0, 1.1)] {
        let mut m = cuboid(name, [-3.0, lo, -3.0], [3.0, hi, 3.0]);
        m.material = Some(0);
        s.meshes.push(m);
    }
    s.lights.push(point_light("Bulb", [0.0, a, 0.0], i));
    let receiver = [pt([0.0, 0.0, 0.0], [0.0, 1.0, 0.0])];
    let direct = i / (a * a);
    let n = 1200;
    let du = 2.0 * half / n as f64;
    let mut bounce = 0.0;
    for y in 0..n {
        for x in 0..n {
            let (u, v) = (-half + (x as f64 + 0.5) * du, -half + (y as f64 + 0.5) * du);
            let rho2 = u * u + v * v;
            let d = (rho2 + (h - a) * (h - a)).sqrt();
            let r2 = rho2 + h * h;
            bounce += k / PI * i * (h - a) / (d * d * d) * h * h / (r2 * r2) * du * du;
        }
    }
    let zero = run(&s, &receiver, &VolPathOptions { media: false, surface_bounces: 0, ..opts(64) });
    assert!(close(zero[0].mean, [direct; 3], 1e-12), "{:?} vs {direct}", zero[0].mean);
    let one = run(&s, &receiver, &VolPathOptions { media: false, surface_bounces: 1, ..opts(40_000) });
    let exact = direct + bounce;
    for c in 0..3 {
        let dev = (one[0].mean[c] - exact).abs();
        assert!(dev <= 4.0 * one[0].stderr[c] && dev <= 0.01 * exact, "{:?} vs {exact} (bounce {bounce})", one[0]);
    }
    let all = run(&s, &receiver, &VolPathOptions { media: false, ..opts(40_000) });
    assert!(all[0].mean[0] > one[0].mean[0] + 5.0 * (all[0].stderr[0] + one[0].stderr[0]), "{:?}", all[0]);
}
