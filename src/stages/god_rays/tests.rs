//! Tests of the epipolar effect against independently derived values: exact Fenwick sums, the
//! closed-form unshadowed in-scatter, an analytically lit interval behind a half-plane occluder, the
//! half-pixel slice bound, agreement with the ray marchers, extreme geometry and media, textured
//! light and thread-count determinism.

use glam::DVec3;

use super::bench::{bench, rel_rmse};
use super::tree::FenwickTree;
use super::*;
use crate::physics::medium::RgbMedium;
use crate::physics::rng::StreamKey;
use crate::render::gbuffer::distance_image;
use crate::scene::bvh::{SceneBvh, procedural};

pub(crate) const BOX: ([f64; 3], [f64; 3]) = ([-20.0; 3], [20.0; 3]);

pub(crate) fn medium(s: f64, a: f64, g: f64) -> EpiMedium {
    EpiMedium { coefficients: RgbMedium::grey(s, a, g), region: BOX }
}

/// `∫_a^b e^{−σ (s + u(s))} ds` exactly, for the view ray `eye + s·v` inside `region` and `u(s)` the
/// distance from `eye + s·v` to the region's face in the direction `t` (towards the light): the
/// minimum over the axes of linear functions of `s`, so the integral is a sum of exponential pieces
/// split where the minimising axis changes. Derived here, independently of the method's split into
/// `e^{−σ γ tan(β/2)}·e^{−σ a_entry}`.
fn box_attenuated_integral(
    eye: DVec3,
    v: DVec3,
    t: DVec3,
    region: ([f64; 3], [f64; 3]),
    sigma: f64,
    a: f64,
    b: f64,
) -> f64 {
    if b <= a {
        return 0.0;
    }
    // u(s) = min_k (A_k − s·B_k) over the axes the light direction is not parallel to.
    let lines: Vec<(f64, f64)> = (0..3)
        .filter(|&k| t[k] != 0.0)
        .map(|k| {
            let face = if t[k] > 0.0 { region.1[k] } else { region.0[k] };
            ((face - eye[k]) / t[k], v[k] / t[k])
        })
        .collect();
    let mut cuts = vec![a, b];
    for i in 0..lines.len() {
        for j in i + 1..lines.len() {
            let db = lines[i].1 - lines[j].1;
            if db != 0.0 {
                let s = (lines[i].0 - lines[j].0) / db;
                if s > a && s < b {
                    cuts.push(s);
                }
            }
        }
    }
    cuts.sort_by(f64::total_cmp);
    let mut sum = 0.0;
    for w in cuts.windows(2) {
        let (lo, hi) = (w[0], w[1]);
        let mid = 0.5 * (lo + hi);
        let &(ak, bk) = lines.iter().min_by(|x, y| (x.0 - mid * x.1).total_cmp(&(y.0 - mid * y.1))).unwrap();
        // e^{−σ(s + A − sB)} on [lo, hi]: rate k = σ(1 − B), of either sign.
        let k = sigma * (1.0 - bk);
        let e0 = -sigma * (lo + ak - lo * bk);
        let x = k * (hi - lo);
        sum += if x.abs() < 1e-12 { e0.exp() * (hi - lo) } else { e0.exp() * -(-x).exp_m1() / k };
    }
    sum
}

pub(crate) fn dir_light(t_toward: [f64; 3]) -> EpiLight {
    let l = -DVec3::from_array(t_toward).normalize();
    EpiLight::Directional { direction: l.to_array(), irradiance: [2.0, 3.0, 4.0], texture: None }
}

/// A spot light above the sphere scene, pointing away from the eye (the camera is outside the cone).
pub(crate) fn spot_light() -> EpiLight {
    EpiLight::Spot {
        position: [1.0, 6.0, -16.0],
        direction: DVec3::new(0.2, -1.0, -0.3).normalize().to_array(),
        inner_cone: 0.5,
        outer_cone: 0.8,
        intensity: [300.0, 200.0, 100.0],
        texture: None,
    }
}

fn quad(name: &str, y: f32, x0: f32, x1: f32, z0: f32, z1: f32) -> crate::scene::Mesh {
    procedural::mesh(
        name,
        vec![[x0, y, z0], [x1, y, z0], [x1, y, z1], [x0, y, z1]],
        vec![[0.0, -1.0, 0.0]; 4],
        vec![[0, 1, 2], [0, 2, 3]],
    )
}

/// A scene whose only triangle lies far outside every test view: nothing shadows the view volume.
pub(crate) fn empty_bvh() -> SceneBvh {
    let tri = procedural::mesh(
        "speck",
        // Below and behind the eye: for every test light its shadow column leaves the box at once.
        vec![[0.0, -19.5, 19.5], [0.5, -19.5, 19.5], [0.0, -19.5, 19.0]],
        vec![[0.0, 0.0, 1.0]; 3],
        vec![[0, 1, 2]],
    );
    SceneBvh::build(&procedural::scene(vec![tri]))
}

pub(crate) fn camera(w: usize, h: usize) -> ViewCamera {
    ViewCamera::new([0.0; 3], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0], 1.0, w, h).unwrap()
}

/// Closed form of the unshadowed directional in-scatter of each pixel (light entering the medium's box).
fn analytic(cam: &ViewCamera, depth: &DistanceImage, light: &EpiLight, m: &EpiMedium) -> RgbImage {
    let EpiLight::Directional { direction, irradiance, .. } = light else { unreachable!() };
    let l = DVec3::from_array(*direction);
    let mut img = Image::filled(cam.width, cam.height, [0.0f32; 3]);
    for y in 0..cam.height {
        for x in 0..cam.width {
            let v = cam.pixel_dir(x, y);
            let (s0, d) = view_segment(cam.position, v, depth.at(x, y), m.region);
            let st = m.sigma_t();
            let p = m.phase(-l.dot(v));
            img.data[y * cam.width + x] = [0, 1, 2].map(|c| {
                let i = box_attenuated_integral(cam.position, v, -l, m.region, st[c], s0, d);
                (m.coefficients.sigma_s[c] * p * irradiance[c] * i) as f32
            });
        }
    }
    img
}

fn max_rel(a: &RgbImage, r: &RgbImage) -> f64 {
    a.data
        .iter()
        .zip(&r.data)
        .flat_map(|(x, y)| (0..3).map(move |c| ((x[c] - y[c]).abs() / y[c].abs().max(1e-30)) as f64))
        .fold(0.0, f64::max)
}

pub(crate) fn all_finite_nonneg(img: &RgbImage) -> bool {
    img.data.iter().all(|p| p.iter().all(|c| c.is_finite() && *c >= 0.0))
}

#[test]
fn fenwick_sums_are_exact_after_thousands_of_updates() {
    let key = StreamKey { table: 7, cell: 1 };
    let n = 1500;
    let lanes = 3;
    // Values spanning 12 decades, like Γ(γ)·Δγ in dense fog.
    let vals: Vec<f64> = (0..n * lanes).map(|i| 10f64.powf(-12.0 * key.uniform(i as u64, 0)) * 3.7).collect();
    let mut tree = FenwickTree::new(&vals, lanes);
    let mut cur: Vec<i64> = (0..n * lanes).map(|i| tree.leaf_int(i / lanes, i % lanes)).collect();
    // Quantisation: each leaf equals its value to 2⁻⁵⁰ of the lane's largest value.
    for i in 0..n * lanes {
        let back = cur[i] as f64 / tree.scale(i % lanes);
        assert!((back - vals[i]).abs() <= 3.7 * 2f64.powi(-49), "{back} vs {}", vals[i]);
    }
    let mut ints = vec![0i64; lanes];
    let mut scratch = Vec::new();
    let original = cur.clone();
    for step in 0..6000u64 {
        let k = (key.uniform(step, 1) * n as f64) as usize;
        match step % 3 {
            0 => tree.zero(k),
            1 => {
                let w = key.uniform(step, 2);
                tree.remove_fraction(k, &original[k * lanes..(k + 1) * lanes], w * 0.25, false, &mut scratch);
                // Keep the brute-force copy in step by reading the leaf back (checked below).
            }
            _ => {
                let delta: Vec<i64> = (0..lanes).map(|l| original[k * lanes + l] / 3).collect();
                tree.add_int(k, &delta);
            }
        }
        for l in 0..lanes {
            cur[k * lanes + l] = tree.leaf_int(k, l);
        }
        if step % 7 == 0 {
            let q = (key.uniform(step, 3) * (n + 1) as f64) as usize;
            tree.prefix_int(q, &mut ints);
            for l in 0..lanes {
                let brute: i64 = (0..q).map(|i| cur[i * lanes + l]).sum();
                assert_eq!(ints[l], brute, "step {step} q {q} lane {l}");
            }
        }
    }
    // Zero everything: every prefix sum is exactly 0 — no residue, no negative values.
    for k in 0..n {
        tree.zero(k);
    }
    for q in 0..=n {
        tree.prefix_int(q, &mut ints);
        assert!(ints.iter().all(|&s| s == 0), "q {q}: {ints:?}");
    }
    // The fractional query is the lerp of the two neighbouring prefix sums.
    let t2 = FenwickTree::new(&[1.0, 2.0, 4.0, 8.0], 1);
    let mut out = [0.0];
    t2.prefix_frac(2.25, &mut [0], &mut out);
    assert!((out[0] - (3.0 + 0.25 * 4.0)).abs() < 1e-12);
}

#[test]
fn unshadowed_directional_matches_closed_form_for_every_epipole() {
    let bvh = empty_bvh();
    let cam = camera(96, 72);
    let depth = distance_image(&bvh, &cam);
    let m = medium(0.05, 0.01, 0.5);
    // Epipole on screen, near the right edge (just outside), far off screen, behind the camera (light
    // behind), and at infinity (view rays parallel to light rays in the image plane).
    let cases: [(&str, [f64; 3]); 5] = [
        ("on", [0.1, 0.05, -1.0]),
        ("near", [0.6, 0.1, -0.85]),
        ("off", [-1.0, 0.2, -0.3]),
        ("behind", [0.2, 0.3, 0.9]),
        ("infinity", [1.0, 0.3, 0.0]),
    ];
    for (name, t) in cases {
        let light = dir_light(t);
        let shadow = render_shadow_map(&bvh, &light, BOX, 64);
        let want = analytic(&cam, &depth, &light, &m);
        let out = render(&cam, &depth, &light, &shadow, &m, &EpipolarOptions::default());
        // Rank 4 (the paper's N): the truncated SVD leaves ≤ 4 % near the epipole; rank 8 converges.
        let (e, mx) = (rel_rmse(&out.inscatter, &want), max_rel(&out.inscatter, &want));
        assert!(e < 0.01 && mx < 0.04, "{name}: rel RMSE {e}, max rel {mx}, stats {:?}", out.stats);
        let opts8 = EpipolarOptions { rank: 8, ..Default::default() };
        let out8 = render(&cam, &depth, &light, &shadow, &m, &opts8);
        let (e8, mx8) = (rel_rmse(&out8.inscatter, &want), max_rel(&out8.inscatter, &want));
        assert!(e8 < 0.004 && mx8 < 0.025, "{name} rank 8: rel RMSE {e8}, max rel {mx8}");
        // Transmittance is exp(−σ_t d) exactly.
        let v = cam.pixel_dir(10, 20);
        let (_, d) = view_segment(cam.position, v, depth.at(10, 20), BOX);
        assert!((f64::from(out.transmittance.at(10, 20)[0]) - (-0.06 * d).exp()).abs() < 1e-6);
        // The marchers converge on it (exact stratum transmittance; the light's attenuation varies by
        // well under 1 % across one of 256 strata).
        let sm = march_shadow_map(&cam, &depth, &light, &shadow, &m, 256);
        let bm = march_bvh(&cam, &depth, &light, &bvh, &m, BOX, 256, 0);
        let (es, eb) = (max_rel(&sm, &want), max_rel(&bm, &want));
        assert!(es < 2e-3 && eb < 2e-3, "{name}: marchers {es} {eb}");
    }
}

#[test]
fn slices_keep_every_pixel_within_half_a_pixel() {
    let bvh = empty_bvh();
    let cam = camera(80, 60);
    let depth = distance_image(&bvh, &cam);
    for t in [[0.1, 0.05, -1.0], [0.6, 0.1, -0.85], [-1.0, 0.2, -0.3], [0.0, 0.0, -1.0]] {
        let light = dir_light(t);
        let opts = EpipolarOptions { ring_px: Some(0.0), ..Default::default() };
        let s = rectify::Setup::new(&cam, &depth, &light, BOX, &opts);
        let dirs: Vec<[f64; 2]> = s
            .slices
            .iter()
            .map(|sl| {
                let (c, sn) = (sl.angle.cos(), sl.angle.sin());
                [s.ref_dir[0] * c - s.ref_dir[1] * sn, s.ref_dir[0] * sn + s.ref_dir[1] * c]
            })
            .collect();
        let mut worst = 0.0f64;
        for y in 0..cam.height {
            for x in 0..cam.width {
                let q = [x as f64 + 0.5 - s.epipole[0], y as f64 + 0.5 - s.epipole[1]];
                let best = dirs
                    .iter()
                    .filter(|d| d[0] * q[0] + d[1] * q[1] >= 0.0)
                    .map(|d| (d[0] * q[1] - d[1] * q[0]).abs())
                    .fold(f64::INFINITY, f64::min);
                worst = worst.max(best);
            }
        }
        assert!(worst <= 0.5 + 1e-9, "{t:?}: a pixel is {worst} px from the nearest slice");
        // Fewer slices than one per perimeter pixel (the sinh distribution's saving).
        assert!(s.slices.len() <= 2 * (cam.width + cam.height) + 8, "{}", s.slices.len());
    }
}

/// The exact integral of `e^{−σ (s + u(s))}` (view and light attenuation, the light entering the box
/// `region`) over the part of the view ray `[0, d]` from the origin lit past a half-plane occluder
/// `{y = 2, x ≥ 0}` under light `l` (travel direction, `l_y < 0`).
fn half_plane_integral(v: DVec3, l: DVec3, d: f64, sigma: f64, region: ([f64; 3], [f64; 3])) -> f64 {
    let exp_integral = |sigma: f64, a: f64, b: f64| box_attenuated_integral(DVec3::ZERO, v, -l, region, sigma, a, b);
    // Below the plane, a point p is shadowed iff the ray p − s·l reaches y = 2 at x ≥ 0:
    // x_hit(t) = t·v_x + (2 − t·v_y)·l_x/l_y, linear in t.
    let (a0, a1) = (2.0 * l.x / l.y, v.x - v.y * l.x / l.y);
    let ty = if v.y > 0.0 { 2.0 / v.y } else { f64::INFINITY };
    let below_end = ty.min(d);
    let mut lit = 0.0;
    // Lit below where a0 + a1 t < 0.
    let (lo, hi) = if a1.abs() < 1e-15 {
        if a0 < 0.0 { (0.0, below_end) } else { (0.0, 0.0) }
    } else {
        let r = -a0 / a1;
        if a1 > 0.0 { (0.0, r.min(below_end)) } else { (r.max(0.0), below_end) }
    };
    if hi > lo {
        lit += exp_integral(sigma, lo, hi);
    }
    if d > ty {
        lit += exp_integral(sigma, ty, d);
    }
    lit
}

#[test]
fn half_plane_shadow_matches_the_analytic_lit_interval() {
    // x ≤ 45 and z ≥ −60 cover every hit of a light ray from a point inside the bounds (|·| ≤ 45).
    let plane = quad("half", 2.0, 0.0, 45.0, -60.0, 45.0);
    let bvh = SceneBvh::build(&procedural::scene(vec![plane]));
    let cam = ViewCamera::new([0.0; 3], [0.6, 0.35, -1.0], [0.0, 1.0, 0.0], 1.1, 96, 72).unwrap();
    let depth = distance_image(&bvh, &cam);
    let l = DVec3::new(0.45, -1.0, -0.3).normalize();
    let light = EpiLight::Directional { direction: l.to_array(), irradiance: [1.0; 3], texture: None };
    let bounds = ([-45.0; 3], [45.0; 3]);
    let m = EpiMedium { region: bounds, ..medium(0.08, 0.02, 0.3) };
    let mut want = Image::filled(cam.width, cam.height, [0.0f32; 3]);
    for y in 0..cam.height {
        for x in 0..cam.width {
            let v = cam.pixel_dir(x, y);
            let (_, d) = view_segment(cam.position, v, depth.at(x, y), bounds);
            let val = m.coefficients.sigma_s[0] * m.phase(-l.dot(v)) * half_plane_integral(v, l, d, 0.1, bounds);
            want.data[y * cam.width + x] = [val as f32; 3];
        }
    }
    let shadow = render_shadow_map(&bvh, &light, bounds, 2048);
    let bm = march_bvh(&cam, &depth, &light, &bvh, &m, bounds, 256, 0);
    let sm = march_shadow_map(&cam, &depth, &light, &shadow, &m, 256);
    let out = render(&cam, &depth, &light, &shadow, &m, &EpipolarOptions::default());
    let (eb, es, ee) = (rel_rmse(&bm, &want), rel_rmse(&sm, &want), rel_rmse(&out.inscatter, &want));
    assert!(eb < 0.01, "BVH marcher {eb}");
    assert!(es < 0.03, "shadow-map marcher {es}");
    assert!(ee < 0.035, "epipolar {ee} ({:?})", out.stats);
}

pub(crate) fn sphere_scene() -> SceneBvh {
    let mut meshes = Vec::new();
    for (i, c) in [[-3.0, 1.0, -9.0], [2.0, -1.0, -12.0], [0.5, 2.5, -7.0], [-1.0, -2.0, -15.0]].iter().enumerate() {
        meshes.push(procedural::icosphere(&format!("s{i}"), *c, 1.2, 2));
    }
    meshes.push(quad("floor", -4.0, -20.0, 20.0, -20.0, 5.0));
    SceneBvh::build(&procedural::scene(meshes))
}

#[test]
fn epipolar_agrees_with_the_shadow_map_marcher_on_spheres() {
    let bvh = sphere_scene();
    let cam = camera(96, 72);
    let depth = distance_image(&bvh, &cam);
    let m = medium(0.06, 0.01, 0.6);
    for (name, t) in [("on screen", [0.15, 0.1, -1.0]), ("behind", [0.3, 0.9, 0.3])] {
        let light = dir_light(t);
        let shadow = render_shadow_map(&bvh, &light, BOX, 512);
        let sm = march_shadow_map(&cam, &depth, &light, &shadow, &m, 512);
        let out = render(&cam, &depth, &light, &shadow, &m, &EpipolarOptions::default());
        let e = rel_rmse(&out.inscatter, &sm);
        assert!(e < 0.03, "{name}: {e}");
        // The shadows matter here: the unshadowed closed form is far from both.
        let free = analytic(&cam, &depth, &light, &m);
        assert!(rel_rmse(&free, &sm) > 0.03, "{name}: scene casts too little shadow ({})", rel_rmse(&free, &sm));
    }
}

#[test]
fn spot_light_agrees_with_the_marcher() {
    let bvh = sphere_scene();
    let cam = camera(80, 60);
    let depth = distance_image(&bvh, &cam);
    let m = medium(0.06, 0.02, 0.4);
    let light = spot_light();
    let shadow = render_shadow_map(&bvh, &light, BOX, 512);
    let sm = march_shadow_map(&cam, &depth, &light, &shadow, &m, 2048);
    let out = render(&cam, &depth, &light, &shadow, &m, &EpipolarOptions::default());
    let e = rel_rmse(&out.inscatter, &sm);
    assert!(e < 0.04, "spot: {e} ({:?})", out.stats);
    assert!(all_finite_nonneg(&out.inscatter));
}

#[test]
fn vanishing_and_extremely_dense_media_stay_finite() {
    let bvh = empty_bvh();
    let cam = camera(64, 48);
    let depth = distance_image(&bvh, &cam);
    let light = dir_light([0.1, 0.05, -1.0]);
    let shadow = render_shadow_map(&bvh, &light, BOX, 32);
    // σ = 0: nothing scatters, nothing is absorbed.
    let zero = render(&cam, &depth, &light, &shadow, &medium(0.0, 0.0, 0.5), &EpipolarOptions::default());
    assert!(zero.inscatter.data.iter().all(|p| *p == [0.0; 3]));
    assert!(zero.transmittance.data.iter().all(|p| *p == [1.0; 3]));
    // σ → 0: in-scatter → σ_s p E d (bounded by it), no NaN.
    let tiny = medium(1e-9, 0.0, 0.5);
    let out = render(&cam, &depth, &light, &shadow, &tiny, &EpipolarOptions::default());
    let want = analytic(&cam, &depth, &light, &tiny);
    assert!(all_finite_nonneg(&out.inscatter) && rel_rmse(&out.inscatter, &want) < 0.01);
    // σ_t d ≫ 700: T underflows to 0, in-scatter → σ_s p E / σ_t.
    let dense = medium(2e4, 1e4, 0.5);
    let out = render(&cam, &depth, &light, &shadow, &dense, &EpipolarOptions::default());
    assert!(out.transmittance.data.iter().all(|p| *p == [0.0; 3]));
    let want = analytic(&cam, &depth, &light, &dense);
    assert!(all_finite_nonneg(&out.inscatter));
    let e = rel_rmse(&out.inscatter, &want);
    assert!(e < 0.01, "dense fog: {e}");
    let sm = march_shadow_map(&cam, &depth, &light, &shadow, &dense, 4);
    assert!(max_rel(&sm, &want) < 1e-5);
}

#[test]
fn per_channel_sigma_and_textured_light() {
    let bvh = sphere_scene();
    let cam = camera(64, 48);
    let depth = distance_image(&bvh, &cam);
    let m = EpiMedium {
        coefficients: RgbMedium { sigma_s: [0.02, 0.05, 0.1], sigma_a: [0.01, 0.0, 0.02], g: [0.5; 3] },
        region: BOX,
    };
    let plain = dir_light([0.15, 0.1, -1.0]);
    let shadow = render_shadow_map(&bvh, &plain, BOX, 256);
    let base = render(&cam, &depth, &plain, &shadow, &m, &EpipolarOptions::default());
    let sm = march_shadow_map(&cam, &depth, &plain, &shadow, &m, 256);
    assert!(rel_rmse(&base.inscatter, &sm) < 0.03, "per-channel σ: {}", rel_rmse(&base.inscatter, &sm));
    // A uniform texture scales each channel by its colour.
    let tint = [0.5f32, 2.0, 1.25];
    let EpiLight::Directional { direction, irradiance, .. } = plain.clone() else { unreachable!() };
    let textured = EpiLight::Directional { direction, irradiance, texture: Some(Image::filled(4, 4, tint)) };
    let out = render(&cam, &depth, &textured, &shadow, &m, &EpipolarOptions::default());
    for (a, b) in out.inscatter.data.iter().zip(&base.inscatter.data) {
        for c in 0..3 {
            assert!((a[c] - tint[c] * b[c]).abs() <= 1e-4 * (tint[c] * b[c]).abs() + 1e-12, "{a:?} vs {b:?}");
        }
    }
    // A half-black texture: agrees with the marcher reading the same texture.
    let mut half = Image::filled(8, 8, [1.0f32, 0.6, 0.3]);
    for y in 0..8 {
        for x in 0..4 {
            half.data[y * 8 + x] = [0.0; 3];
        }
    }
    let textured = EpiLight::Directional { direction, irradiance, texture: Some(half) };
    let out = render(&cam, &depth, &textured, &shadow, &m, &EpipolarOptions::default());
    let sm = march_shadow_map(&cam, &depth, &textured, &shadow, &m, 256);
    let e = rel_rmse(&out.inscatter, &sm);
    // The texture's sharp edge is resolved to a pixel by both methods, differently at 64 × 48.
    assert!(e < 0.08, "half texture: {e}");
    assert!(rel_rmse(&base.inscatter, &sm) > 0.2, "the texture must matter");
}

#[test]
fn results_are_identical_for_one_and_two_threads() {
    let bvh = sphere_scene();
    let cam = camera(64, 48);
    let depth = distance_image(&bvh, &cam);
    let m = medium(0.06, 0.01, 0.6);
    let light = dir_light([0.15, 0.1, -1.0]);
    let run = |n: usize| {
        let pool = rayon::ThreadPoolBuilder::new().num_threads(n).build().unwrap();
        pool.install(|| {
            let shadow = render_shadow_map(&bvh, &light, BOX, 128);
            let out = render(&cam, &depth, &light, &shadow, &m, &EpipolarOptions::default());
            let sm = march_shadow_map(&cam, &depth, &light, &shadow, &m, 16);
            let bm = march_bvh(&cam, &depth, &light, &bvh, &m, BOX, 8, 0);
            (shadow, out.inscatter, out.transmittance, sm, bm)
        })
    };
    assert!(run(1) == run(2));
}

#[test]
fn quick_bench_on_the_window_room() {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes/window_room.gltf");
    let report = bench(&path, true).unwrap();
    assert_eq!(report.runs.len(), 2);
    for run in &report.runs {
        let err = |m: &str, k: &str| run.points.iter().find(|p| p.method == m && p.knob.starts_with(k)).unwrap().error;
        // More marcher steps converge towards the reference; the epipolar default is close to it.
        assert!(err("raymarch", "16") < err("raymarch", "4"), "{report}");
        let epi = run.points.iter().filter(|p| p.method == "epipolar").map(|p| p.error).fold(f64::INFINITY, f64::min);
        assert!(epi < 0.1, "{report}");
        assert!(run.default_stats.slices > 0 && run.default_stats.samples > 0);
    }
    // Identical images at 1 and 2 threads → identical errors.
    let e1: Vec<f64> = report.runs[0].points.iter().map(|p| p.error).collect();
    let e2: Vec<f64> = report.runs[1].points.iter().map(|p| p.error).collect();
    assert_eq!(e1, e2);
    assert!(report.scaling.iter().all(|s| s.slope.is_finite()));
    // The whole-frame split adds up and is printed.
    assert_eq!(report.frames.len(), 1);
    let fr = report.frames[0];
    assert_eq!(fr.total_ms, fr.shadow_ms + fr.epipolar_ms + fr.composite_ms);
    assert!(fr.shadow_ms > 0.0 && fr.epipolar_ms > 0.0 && fr.gbuffer_ms > 0.0, "{fr:?}");
    assert!(report.to_string().contains("whole frame"));
    // Equal-error interpolation on a known power law: error = 1/steps, time = steps ms.
    let pts: Vec<bench::ErrorTimePoint> = [(4.0, 0.25), (16.0, 0.0625), (64.0, 1.0 / 64.0)]
        .iter()
        .map(|&(ms, error)| bench::ErrorTimePoint { method: "raymarch".into(), knob: String::new(), ms, error })
        .chain([(2.0, 1.0 / 32.0), (1.0, 1.0 / 128.0)].map(|(ms, error)| bench::ErrorTimePoint {
            method: "epipolar".into(),
            knob: String::new(),
            ms,
            error,
        }))
        .collect();
    let sp = bench::speedups(&pts);
    assert!((sp[0].march_ms - 32.0).abs() < 1e-9 && !sp[0].extrapolated);
    assert!((sp[1].speedup - 128.0).abs() < 1e-9 && sp[1].extrapolated);
    let text = report.to_string();
    assert!(text.contains("relative RMSE"));
}

#[test]
fn camera_outside_a_bounded_fog_box_matches_the_closed_form() {
    // A fog box in front of the camera (which stands in clear air): view rays integrate only their
    // segment inside the box, and the light enters the box at its faces.
    let bvh = empty_bvh();
    let cam = camera(48, 36);
    let depth = distance_image(&bvh, &cam);
    let m = EpiMedium { region: ([-4.0, -3.0, -14.0], [4.0, 3.0, -6.0]), ..medium(0.15, 0.05, 0.4) };
    let light = dir_light([0.3, 0.8, 0.2]);
    let shadow = render_shadow_map(&bvh, &light, BOX, 64);
    let want = analytic(&cam, &depth, &light, &m);
    let out = render(&cam, &depth, &light, &shadow, &m, &EpipolarOptions::default());
    // Every pixel is ray marched (128 strata) when the eye is outside the region.
    assert_eq!(out.stats.gain_pixels, cam.width * cam.height, "{:?}", out.stats);
    let e = rel_rmse(&out.inscatter, &want);
    assert!(e < 2e-3, "camera outside: {e}");
    // Pixels whose rays miss the box see no fog and full transmittance.
    let corner = cam.pixel_dir(0, 0);
    assert_eq!(view_segment(cam.position, corner, f32::INFINITY, m.region), (0.0, 0.0));
    assert_eq!(out.inscatter.at(0, 0), [0.0; 3]);
    assert_eq!(out.transmittance.at(0, 0), [1.0; 3]);
}

#[test]
fn thick_fog_behind_the_eye_is_marched_and_matches_the_closed_form() {
    // 12 mean free paths across a box the eye stands near the back of, light from behind and the
    // side: light rays that enter through the side face far in front of the eye (behind the eye's
    // plane as seen from the light) would need gains far above MAX_LIGHT_GAIN, so those slices are
    // marched; the rest stay epipolar.
    let bvh = empty_bvh();
    let cam = camera(48, 36);
    let depth = distance_image(&bvh, &cam);
    let m = EpiMedium { region: ([-20.0, -20.0, -40.0], [20.0, 20.0, 2.0]), ..medium(0.25, 0.05, 0.5) };
    let light = dir_light([0.3, 0.2, 0.93]);
    let shadow = render_shadow_map(&bvh, &light, BOX, 64);
    let want = analytic(&cam, &depth, &light, &m);
    let out = render(&cam, &depth, &light, &shadow, &m, &EpipolarOptions::default());
    assert!(out.stats.gain_slices > 0 && out.stats.gain_pixels > 0, "{:?}", out.stats);
    assert!(out.stats.gain_slices < out.stats.slices, "{:?}", out.stats);
    assert!(all_finite_nonneg(&out.inscatter));
    let e = rel_rmse(&out.inscatter, &want);
    assert!(e < 0.01, "thick fog: {e} ({:?})", out.stats);
}

#[test]
fn light_entry_is_the_distance_to_the_box_towards_the_light() {
    let m = medium(0.1, 0.0, 0.0);
    let up = DVec3::Y;
    // From the centre straight up to the face y = 20; from outside below, the far (upper) face.
    assert_eq!(m.light_entry(DVec3::ZERO, up), Some(20.0));
    assert_eq!(m.light_entry(DVec3::new(0.0, -30.0, 0.0), up), Some(50.0));
    // A line that misses the box.
    assert_eq!(m.light_entry(DVec3::new(30.0, 0.0, 0.0), up), None);
    // Attenuation e^{−σ_t a}, a gain for a < 0, never NaN.
    assert!((m.light_attenuation(20.0)[0] - (-2.0f64).exp()).abs() < 1e-15);
    assert!((m.light_attenuation(-10.0)[1] - 1f64.exp()).abs() < 1e-12);
    assert_eq!(medium(1e300, 1e300, 0.0).light_attenuation(-1e10), [0.0; 3]);
}

#[test]
fn rasterised_shadow_maps_equal_the_traced_ones() {
    // The rasteriser against the BVH tracer, texel by texel: directional (epipole on screen and light
    // from behind), a spot light whose frustum crosses geometry beside and behind it, and the window
    // room's sun (its wall with a grid of holes).
    let spheres = sphere_scene();
    let room_scene =
        crate::scene::Scene::load(&std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes/window_room.gltf"))
            .unwrap();
    let room = SceneBvh::build(&room_scene);
    let sun = EpiLight::from_scene(&room_scene).unwrap();
    let room_bounds = room_scene.bounds().unwrap();
    for (name, bvh, light, bounds, res) in [
        ("front", &spheres, dir_light([0.15, 0.1, -1.0]), BOX, 512),
        ("behind", &spheres, dir_light([0.3, 0.9, 0.3]), BOX, 300),
        ("spot", &spheres, spot_light(), BOX, 256),
        ("window room", &room, sun, room_bounds, 1024),
    ] {
        let (r, t) = (render_shadow_map(bvh, &light, bounds, res), trace_shadow_map(bvh, &light, bounds, res));
        assert_eq!((r.frame, r.bias, r.bounds), (t.frame, t.bias, t.bounds));
        let (mut differ, mut hit, mut worst) = (0usize, 0usize, 0.0f64);
        for (a, b) in r.depth.iter().zip(&t.depth) {
            match (a.is_finite(), b.is_finite()) {
                (true, true) => {
                    hit += 1;
                    // Relative to the bounds' diagonal: the depth bias is 10⁻⁴ of it.
                    let rel = f64::from((a - b).abs()) / (r.bias * 1e4);
                    if rel > 1e-4 {
                        differ += 1;
                    } else {
                        worst = worst.max(rel);
                    }
                }
                (false, false) => {}
                _ => differ += 1,
            }
        }
        let n = r.depth.len();
        assert!(hit > n / 20, "{name}: only {hit} texels see geometry");
        assert!(differ * 2000 <= n, "{name}: {differ} of {n} texels differ");
        assert!(worst < 1e-5, "{name}: depth differs by {worst} of the diagonal");
    }
}

#[test]
fn media_the_god_rays_cannot_take_are_named_with_the_reason() {
    use crate::scene::{Boundary, Density, Medium};
    let mut scene = procedural::scene(vec![quad("floor", 0.0, -1.0, 1.0, -1.0, 1.0)]);
    assert!(EpiMedium::refusal(&scene).contains("no participating medium"));
    let fog = |name: &str, density, boundary| Medium {
        name: name.into(),
        sigma_s: [0.1; 3],
        sigma_a: [0.0; 3],
        g: [0.3; 3],
        density,
        boundary,
    };
    let height = Density::ExponentialHeight { rho: 1.0, falloff: 0.5, direction: [0.0, 1.0, 0.0], offset: [0.0; 3] };
    scene.media = vec![fog("haze", height, Boundary::Global), fog("volume", Density::Homogeneous, Boundary::Mesh(0))];
    assert!(EpiMedium::from_scene(&scene).is_none());
    let why = EpiMedium::refusal(&scene);
    assert!(why.contains("\"haze\"") && why.contains("height") && why.contains("ImageFog"), "{why}");
    assert!(why.contains("\"volume\"") && why.contains("bounded by mesh 0"), "{why}");
    // A homogeneous global medium is taken, over the scene's padded bounds.
    scene.media.push(fog("room", Density::Homogeneous, Boundary::Global));
    let m = EpiMedium::from_scene(&scene).unwrap();
    assert_eq!(Some(m.region), scene.global_medium_bounds());
}

#[test]
fn a_zero_thickness_fog_box_scatters_nothing() {
    let bvh = empty_bvh();
    let cam = camera(32, 24);
    let depth = distance_image(&bvh, &cam);
    let light = dir_light([0.1, 0.6, -0.4]);
    let shadow = render_shadow_map(&bvh, &light, BOX, 64);
    // A slab of zero thickness across the view: every view ray crosses it in a single point.
    let m = EpiMedium { region: ([-20.0, -20.0, -8.0], [20.0, 20.0, -8.0]), ..medium(0.5, 0.1, 0.5) };
    let out = render(&cam, &depth, &light, &shadow, &m, &EpipolarOptions::default());
    assert!(out.inscatter.data.iter().all(|p| *p == [0.0; 3]));
    assert!(out.transmittance.data.iter().all(|p| *p == [1.0; 3]));
}
