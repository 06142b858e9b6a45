//! Analytic checks of the light tracer and the camera path tracer.

#![allow(clippy::needless_range_loop)] // per-channel indices read more clearly in the checks

use std::f64::consts::{PI, TAU};

use glam::DVec3;

use super::*;
use crate::physics::hg::{cdf, phase, sample_mu};
use crate::physics::medium::RgbMedium;
use crate::render::ViewCamera;
use crate::render::voxel::unit_cube;

fn light(d: DVec3, e: [f64; 3]) -> DirectionalLight {
    DirectionalLight { direction: d.normalize(), irradiance: e }
}

fn lt(photons: u64, max_events: u32) -> LightTraceOptions {
    LightTraceOptions { photons, seed: 7, max_events }
}

fn rel(a: f64, b: f64) -> f64 {
    (a - b).abs() / b.abs().max(1e-300)
}

/// Solid angle of polar bin `b` of `n`.
fn solid_angle(b: usize, n: usize) -> f64 {
    TAU * ((b as f64 * PI / n as f64).cos() - ((b + 1) as f64 * PI / n as f64).cos())
}

/// Distance from `p` inside the unit cube along `w` to its boundary.
fn exit_unit_cube(p: DVec3, w: DVec3) -> f64 {
    let mut s = f64::INFINITY;
    for a in 0..3 {
        if w[a] > 0.0 {
            s = s.min((1.0 - p[a]) / w[a]);
        } else if w[a] < 0.0 {
            s = s.min(-p[a] / w[a]);
        }
    }
    s
}

/// Pure absorber, light along +x: every photon sees the same medium, so the tally is exact and
/// noise-free: the cell average of `E e^{−σ x}` is `E (e^{−σ x0} − e^{−σ x1})/(σ Δx)`, all of it in
/// polar bin 0 (axis = light direction). Chromatic `σ_a` runs one walk per channel.
#[test]
fn absorbing_slab_is_exact_and_noise_free() {
    let sa = [2.0, 0.5, 3.0];
    let e = [1.0, 2.0, 3.0];
    let m = unit_cube(RgbMedium { sigma_s: [0.0; 3], sigma_a: sa, g: [0.0; 3] });
    let spec = TallySpec { dims: [8, 1, 1], theta_bins: 4, axis: DVec3::X };
    let t = light_trace(&m, &light(DVec3::X, e), &spec, &lt(256, 100));
    assert_eq!(t.walks, 3);
    let sa0 = solid_angle(0, 4);
    for k in 0..8 {
        let (x0, x1) = (k as f64 / 8.0, (k + 1) as f64 / 8.0);
        for c in 0..3 {
            let s = sa[c];
            let want = e[c] * ((-s * x0).exp() - (-s * x1).exp()) / (s * (x1 - x0));
            assert!(rel(t.fluence[k][c], want) < 1e-9, "cell {k} ch {c}: {} vs {want}", t.fluence[k][c]);
            assert!(rel(t.uncollided_fluence[k][c], want) < 1e-9);
            assert!(t.fluence_std_err[k][c] < 1e-9 * want);
            assert!(rel(t.radiance[k * 4][c], want / sa0) < 1e-9);
            for b in 1..4 {
                assert_eq!(t.radiance[k * 4 + b][c], 0.0);
            }
        }
    }
    assert!(rel(t.injected[1], 2.0) < 1e-15);
    assert_eq!(t.truncated_fraction, 0.0);
}

/// Vacuum: the fluence is `E` in every cell, the power leaving equals the power entering
/// `E·A⊥` (A⊥ of a 2×1×1 box).
#[test]
fn vacuum_fluence_is_the_irradiance() {
    let m = VoxelMedium::new(
        DVec3::ZERO,
        DVec3::new(2.0, 1.0, 1.0),
        [2, 2, 2],
        vec![0.0; 8],
        RgbMedium::grey(1.0, 1.0, 0.5),
    )
    .unwrap();
    let e = [1.5, 1.0, 0.5];
    // Along an axis with one cell across the beam: exact.
    let spec = TallySpec { dims: [5, 1, 1], theta_bins: 3, axis: DVec3::X };
    let t = light_trace(&m, &light(DVec3::X, e), &spec, &lt(100, 10));
    for f in &t.fluence {
        for c in 0..3 {
            assert!(rel(f[c], e[c]) < 1e-12, "{f:?}");
        }
    }
    // Along the diagonal on a 3×3×3 tally: E within 4 standard errors.
    let d = DVec3::new(1.0, 1.0, 1.0).normalize();
    let spec = TallySpec { dims: [3, 3, 3], theta_bins: 2, axis: DVec3::Z };
    let t = light_trace(&m, &light(d, e), &spec, &lt(20_000, 10));
    let a_perp = (1.0 + 2.0 + 2.0) / 3f64.sqrt();
    for c in 0..3 {
        assert!(rel(t.injected[c], e[c] * a_perp) < 1e-14);
        assert!(rel(t.escaped[c], t.injected[c]) < 1e-12);
    }
    for (k, (f, s)) in t.fluence.iter().zip(&t.fluence_std_err).enumerate() {
        for c in 0..3 {
            assert!(s[c] > 0.0 && (f[c] - e[c]).abs() < 4.0 * s[c] + 1e-12, "cell {k}: {f:?} ± {s:?}");
        }
    }
}

/// Albedo 1, g = 0: every photon leaves (weights never change), so the escaped power equals the
/// injected power to rounding; the uncollided fluence is exact (expected-value estimator); the
/// radiance bins integrate to the fluence.
#[test]
fn albedo_one_conserves_energy_and_uncollided_is_exact() {
    let m = unit_cube(RgbMedium::grey(4.0, 0.0, 0.0));
    let spec = TallySpec { dims: [4, 1, 1], theta_bins: 6, axis: DVec3::X };
    let t = light_trace(&m, &light(DVec3::X, [1.0; 3]), &spec, &lt(4000, 100_000));
    assert_eq!(t.walks, 1);
    assert_eq!(t.truncated_fraction, 0.0);
    for c in 0..3 {
        assert!(rel(t.escaped[c], t.injected[c]) < 1e-12, "{:?} vs {:?}", t.escaped, t.injected);
        assert_eq!(t.absorbed[c], 0.0);
    }
    for k in 0..4 {
        let (x0, x1) = (k as f64 / 4.0, (k + 1) as f64 / 4.0);
        let want = ((-4.0 * x0).exp() - (-4.0 * x1).exp()) / (4.0 * 0.25);
        assert!(rel(t.uncollided_fluence[k][0], want) < 1e-9);
        assert!(t.fluence[k][0] > want);
        let sum: f64 = (0..6).map(|b| t.radiance[k * 6 + b][0] * solid_angle(b, 6)).sum();
        assert!(rel(sum, t.fluence[k][0]) < 1e-12);
    }
}

/// Heterogeneous (4×3×2 voxels), absorbing and scattering, oblique light: the power
/// absorbed scored at collisions equals `σ_a ∫ φ dV` from the track-length fluence (two different
/// estimators of the same quantity), and absorbed + escaped = injected, within 4 standard errors.
#[test]
fn absorption_from_collisions_matches_track_length_fluence() {
    let m = VoxelMedium::from_fn(DVec3::ZERO, DVec3::ONE, [4, 3, 2], RgbMedium::grey(2.0, 1.0, 0.5), |p| {
        0.5 + p.x + p.y * p.z
    })
    .unwrap();
    let l = light(DVec3::new(0.4, -0.7, 0.3), [1.0; 3]);
    // A tally equal to the voxels, so σ_a is constant in each tally cell.
    let spec = TallySpec { dims: m.dims, theta_bins: 1, axis: DVec3::Y };
    let t2 = light_trace(&m, &l, &spec, &lt(40_000, 10_000));
    let v = 1.0 / 24.0;
    let mut track = 0.0;
    let mut track_se = 0.0;
    for (i, (f, s)) in t2.fluence.iter().zip(&t2.fluence_std_err).enumerate() {
        let rho = f64::from(m.density[i]);
        track += 1.0 * rho * f[0] * v;
        track_se += 1.0 * rho * s[0] * v;
    }
    let tol = 4.0 * (track_se + t2.absorbed_std_err[0]);
    assert!((track - t2.absorbed[0]).abs() < tol, "{track} vs {} ± {tol}", t2.absorbed[0]);
    let balance = t2.absorbed[0] + t2.escaped[0] - t2.injected[0];
    assert!(balance.abs() < 4.0 * (t2.absorbed_std_err[0] + t2.escaped_std_err[0]) + 1e-12, "{balance}");
    assert!(t2.truncated_fraction == 0.0);
}

/// Thin cube (σ_s L = 0.01, albedo 1, g = 0.7), light along +x, one tally cell (the cube), 8 polar
/// bins about +x, `max_events = 1`: the collided radiance per bin is the once-scattered light,
/// `E σ_s/(V ΔΩ_b) ∫_V dV' e^{−σ x'} ∫_{bin} f_hg(ω) (1 − e^{−σ s(x', ω)})/σ dω` with `s` the
/// distance to the cube's boundary (the out-going transmittance is included). Computed here by
/// a midpoint rule in `(x', y', z', ξ, φ)` with `μ = HG⁻¹(ξ)` over each bin's range of `ξ`
/// (20³·16·32 nodes per bin; halving that moved the bins by ≤ 1.1 %, so the rule is allowed 0.5 %
/// on top of 4 standard errors; with 16 M photons every bin agreed within 1.9 standard errors).
#[test]
fn thin_medium_once_scattered_radiance_matches_quadrature() {
    let (sigma, g) = (0.01, 0.7);
    let m = unit_cube(RgbMedium::grey(sigma, 0.0, g));
    let bins = 8;
    let spec = TallySpec { dims: [1, 1, 1], theta_bins: bins, axis: DVec3::X };
    let t = light_trace(&m, &light(DVec3::X, [1.0; 3]), &spec, &lt(4_000_000, 1));
    assert!(t.truncated_fraction > 0.0 && t.truncated_fraction < 2e-4);
    let np = 20;
    let (nxi, nphi) = (16, 32);
    let mut total = 0.0;
    for b in 0..bins {
        let mu_hi = (b as f64 * PI / bins as f64).cos();
        let mu_lo = ((b + 1) as f64 * PI / bins as f64).cos();
        let (x_lo, x_hi) = (cdf(mu_lo, g), cdf(mu_hi, g));
        let mut sum = 0.0;
        for ix in 0..nxi {
            let mu = sample_mu(x_lo + (ix as f64 + 0.5) / nxi as f64 * (x_hi - x_lo), g);
            let s = (1.0 - mu * mu).max(0.0).sqrt();
            for ip in 0..nphi {
                let phi = TAU * (ip as f64 + 0.5) / nphi as f64;
                let w = DVec3::new(mu, s * phi.cos(), s * phi.sin());
                for i in 0..np {
                    for j in 0..np {
                        for k in 0..np {
                            let p = (DVec3::new(i as f64, j as f64, k as f64) + 0.5) / np as f64;
                            let len = exit_unit_cube(p, w);
                            sum += (-sigma * p.x).exp() * (-(-sigma * len).exp_m1()) / sigma;
                        }
                    }
                }
            }
        }
        let integral = sum / (nxi * nphi * np * np * np) as f64 * (x_hi - x_lo);
        let want = sigma * integral / solid_angle(b, bins);
        total += want * solid_angle(b, bins);
        let mut got = t.radiance[b][0];
        if b == 0 {
            got -= t.uncollided_fluence[0][0] / solid_angle(0, bins);
        }
        let se = t.radiance_std_err[b][0];
        assert!((got - want).abs() < 4.0 * se + 5e-3 * want, "bin {b}: {got} vs {want} ± {se}");
    }
    let collided = t.fluence[0][0] - t.uncollided_fluence[0][0];
    assert!((collided - total).abs() < 4.0 * t.fluence_std_err[0][0] + 5e-3 * total, "{collided} vs {total}");
    // Uncollided: the cube average of e^{−σ x}.
    assert!(rel(t.uncollided_fluence[0][0], -(-sigma).exp_m1() / sigma) < 1e-10);
}

fn run_in_pool<T: Send>(threads: usize, f: impl FnOnce() -> T + Send) -> T {
    rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap().install(f)
}

#[test]
fn results_do_not_depend_on_the_thread_count() {
    let m = VoxelMedium::from_fn(
        DVec3::ZERO,
        DVec3::ONE,
        [3, 3, 3],
        RgbMedium { sigma_s: [4.0, 4.0, 2.0], sigma_a: [0.1; 3], g: [0.7, 0.7, 0.3] },
        |p| p.x + 0.2,
    )
    .unwrap();
    let l = light(DVec3::new(1.0, 0.3, -0.2), [1.0, 2.0, 3.0]);
    let spec = TallySpec { dims: [4, 4, 4], theta_bins: 5, axis: DVec3::X };
    let go = || {
        let mut t = light_trace(&m, &l, &spec, &lt(3000, 1000));
        t.seconds = 0.0;
        t
    };
    let (a, b) = (run_in_pool(1, go), run_in_pool(2, go));
    assert_eq!(a.walks, 2);
    assert!(a == b);
    let cam = ViewCamera::new([0.5, 0.5, -1.5], [0.0, 0.0, 1.0], [0.0, 1.0, 0.0], 0.8, 6, 5).unwrap();
    let opts = CameraOptions { samples: 20, seed: 3, max_events: 100 };
    let go = || {
        let mut r = render(&m, &l, &cam, &opts);
        r.seconds = 0.0;
        r
    };
    let (a, b) = (run_in_pool(1, go), run_in_pool(2, go));
    assert!(a == b);
    assert!(a.radiance.iter().any(|p| p[0] > 0.0));
}

/// Distance from `p` along `w` to the unit cube's boundary, 0 outside.
fn chord(p: DVec3, w: DVec3) -> f64 {
    grid::clip(DVec3::ZERO, DVec3::ONE, p, w, 0.0).map_or(0.0, |(a, b)| b - a)
}

/// Thin-ish homogeneous cube seen head-on: the once-scattered radiance per pixel equals
/// `∫ σ_s f_hg(l·(−d)) E T_light(x(t)) e^{−σ_t (t − t0)} dt` along the pixel-centre ray (midpoint
/// rule, 4000 nodes), within 4 standard errors; transmittance exact; `max_events = 1` gives
/// radiance = single.
#[test]
fn camera_single_scattering_matches_quadrature() {
    let (ss, sa, g) = (0.5, 0.25, 0.7);
    let m = unit_cube(RgbMedium::grey(ss, sa, g));
    let st = ss + sa;
    let l = light(DVec3::new(0.3, -0.2, -1.0), [1.0, 2.0, 0.5]);
    let cam = ViewCamera::new([0.5, 0.5, -2.0], [0.0, 0.0, 1.0], [0.0, 1.0, 0.0], 0.4, 5, 5).unwrap();
    let r = render(&m, &l, &cam, &CameraOptions { samples: 2000, seed: 11, max_events: 64 });
    let r1 = render(&m, &l, &cam, &CameraOptions { samples: 2000, seed: 11, max_events: 1 });
    let mut worst: f64 = 0.0;
    for y in 0..5 {
        for x in 0..5 {
            let i = x + 5 * y;
            let d = cam.pixel_dir(x, y);
            let (t0, t1) = grid::clip(DVec3::ZERO, DVec3::ONE, cam.position, d, 0.0).unwrap();
            let n = 4000;
            let h = (t1 - t0) / n as f64;
            let f = phase(l.direction.dot(-d), g);
            let mut sum = 0.0;
            for k in 0..n {
                let t = t0 + (k as f64 + 0.5) * h;
                let p = cam.position + d * t;
                sum += ss * f * (-st * chord(p, -l.direction)).exp() * (-st * (t - t0)).exp() * h;
            }
            for c in 0..3 {
                let want = sum * l.irradiance[c];
                let se = r.single_variance[i][c].sqrt();
                worst = worst.max((r.single[i][c] - want).abs() / se);
                assert!((r.single[i][c] - want).abs() < 4.0 * se, "pixel {i}: {} vs {want} ± {se}", r.single[i][c]);
                assert!(rel(r.transmittance[i][c], (-st * (t1 - t0)).exp()) < 1e-12);
                assert_eq!(r1.radiance[i][c], r1.single[i][c]);
                assert!(r.radiance[i][c] > r.single[i][c]);
            }
        }
    }
    assert!(worst > 0.0);
}

#[test]
fn black_where_nothing_scatters_or_the_ray_misses() {
    let l = light(DVec3::new(0.2, -1.0, 0.1), [1.0; 3]);
    let cam = ViewCamera::new([0.5, 0.5, -2.0], [0.0, 0.0, 1.0], [0.0, 1.0, 0.0], 1.2, 8, 6).unwrap();
    let opts = CameraOptions { samples: 50, seed: 1, max_events: 64 };
    // Albedo 0.
    let r = render(&unit_cube(RgbMedium::grey(0.0, 3.0, 0.5)), &l, &cam, &opts);
    assert!(r.radiance.iter().chain(&r.single).chain(&r.variance).all(|p| *p == [0.0; 3]));
    assert!(r.transmittance.iter().any(|p| p[0] < 0.1));
    // Density 0.
    let m0 = VoxelMedium::new(DVec3::ZERO, DVec3::ONE, [1, 1, 1], vec![0.0], RgbMedium::grey(5.0, 1.0, 0.5)).unwrap();
    let r = render(&m0, &l, &cam, &opts);
    assert!(r.radiance.iter().all(|p| *p == [0.0; 3]));
    assert!(r.transmittance.iter().all(|p| *p == [1.0; 3]));
    // Scattering medium: pixels whose ray misses the box are black with transmittance 1.
    let r = render(&unit_cube(RgbMedium::grey(2.0, 0.0, 0.5)), &l, &cam, &opts);
    let mut missed = 0;
    for y in 0..6 {
        for x in 0..8 {
            let i = x + 8 * y;
            if grid::clip(DVec3::ZERO, DVec3::ONE, cam.position, cam.pixel_dir(x, y), 0.0).is_none() {
                missed += 1;
                assert_eq!(r.radiance[i], [0.0; 3]);
                assert_eq!(r.transmittance[i], [1.0; 3]);
            } else {
                assert!(r.radiance[i][0] > 0.0);
            }
        }
    }
    assert!(missed > 0);
    // No usable light: black, transmittance still exact.
    let dark = DirectionalLight { direction: DVec3::ZERO, irradiance: [1.0; 3] };
    let r = render(&unit_cube(RgbMedium::grey(2.0, 0.0, 0.5)), &dark, &cam, &opts);
    assert!(r.radiance.iter().all(|p| *p == [0.0; 3]));
    let t = light_trace(
        &unit_cube(RgbMedium::grey(2.0, 0.0, 0.5)),
        &dark,
        &TallySpec { dims: [2, 2, 2], theta_bins: 2, axis: DVec3::X },
        &lt(100, 10),
    );
    assert!(t.fluence.iter().all(|p| *p == [0.0; 3]));
}

fn all_finite(v: &[[f64; 3]]) -> bool {
    v.iter().all(|p| p.iter().all(|x| x.is_finite()))
}

/// Extreme media, lights and cameras: nothing non-finite; a very thick medium is cut by
/// `max_events` and says so.
#[test]
fn extreme_inputs_stay_finite() {
    let diag = DVec3::new(1.0, 1.0, 1.0);
    let media = [
        unit_cube(RgbMedium::grey(1.0, 0.1, 0.999)),
        unit_cube(RgbMedium::grey(1e4, 0.0, 0.5)),
        unit_cube(RgbMedium::grey(0.0, 0.0, 0.0)),
        VoxelMedium::from_fn(DVec3::ZERO, DVec3::ONE, [5, 4, 3], RgbMedium::grey(3.0, 0.0, 0.96), |p| {
            if p.x < 0.5 { 0.0 } else { 2.0 }
        })
        .unwrap(),
    ];
    let lights = [light(DVec3::X, [1.0; 3]), light(-DVec3::Z, [1.0; 3]), light(diag, [1.0; 3]), light(-diag, [1.0; 3])];
    let inside = ViewCamera::new([0.5, 0.4, 0.6], [0.3, 0.2, 1.0], [0.0, 1.0, 0.0], 2.0, 4, 3).unwrap();
    let corner = ViewCamera::new([0.0, 0.0, 0.0], [1.0, 1.0, 1.0], [0.0, 1.0, 0.0], 0.5, 3, 3).unwrap();
    let spec = TallySpec { dims: [3, 3, 3], theta_bins: 4, axis: DVec3::new(0.0, 0.0, 0.0) };
    for (mi, m) in media.iter().enumerate() {
        for l in &lights {
            let t = light_trace(m, l, &spec, &lt(200, 40));
            assert!(all_finite(&t.fluence) && all_finite(&t.radiance) && all_finite(&t.fluence_std_err));
            assert!(t.truncated_fraction.is_finite());
            if mi == 1 {
                assert!(t.truncated_fraction > 0.1, "{}", t.truncated_fraction);
            }
            for cam in [&inside, &corner] {
                let r = render(m, l, cam, &CameraOptions { samples: 8, seed: 2, max_events: 40 });
                assert!(all_finite(&r.radiance) && all_finite(&r.variance) && all_finite(&r.transmittance));
                if mi == 1 {
                    assert!(r.truncated_paths > 0);
                }
            }
        }
    }
    // Degenerate requests: empty outputs or zeros, no panic.
    let m = &media[0];
    let l = &lights[0];
    let t = light_trace(m, l, &TallySpec { dims: [0, 2, 2], theta_bins: 4, axis: DVec3::X }, &lt(100, 10));
    assert!(t.fluence.is_empty() && t.radiance.is_empty());
    let t = light_trace(m, l, &TallySpec { dims: [2, 2, 2], theta_bins: 0, axis: DVec3::X }, &lt(100, 10));
    assert!(t.radiance.is_empty() && t.fluence.iter().all(|p| p[0] > 0.0));
    let t = light_trace(m, l, &TallySpec { dims: [2, 2, 2], theta_bins: 3, axis: DVec3::NAN }, &lt(0, 10));
    assert!(t.fluence.iter().all(|p| *p == [0.0; 3]));
    let r = render(m, l, &inside, &CameraOptions { samples: 0, seed: 0, max_events: 0 });
    assert!(r.radiance.iter().all(|p| *p == [0.0; 3]));
}

/// Throughput on the elek2014 Fig. 12 cube (σ_s = 4 /m, albedo 1, g = 0.7): run with
/// `cargo test --release --lib grid_mc::tests::fig12_timing -- --ignored --nocapture`.
#[test]
#[ignore]
fn fig12_timing() {
    let m = unit_cube(RgbMedium::grey(4.0, 0.0, 0.7));
    let l = light(DVec3::new(0.0, -1.0, 0.0), [1.0; 3]);
    let spec = TallySpec { dims: [32, 32, 32], theta_bins: 32, axis: DVec3::new(0.0, -1.0, 0.0) };
    let t = light_trace(&m, &l, &spec, &lt(1_000_000, 100_000));
    eprintln!(
        "light_trace: {:.0} photons/s ({} walks, truncated {})",
        t.photons as f64 / t.seconds,
        t.walks,
        t.truncated_fraction
    );
    let cam = ViewCamera::new([0.5, 0.5, -2.0], [0.0, 0.0, 1.0], [0.0, 1.0, 0.0], 0.6, 64, 64).unwrap();
    let r = render(&m, &l, &cam, &CameraOptions { samples: 64, seed: 1, max_events: 100_000 });
    eprintln!("render: {:.0} samples/s", (64 * 64 * 64) as f64 / r.seconds);
}
