//! Tests of camera-ray radiance ([`radiance`]) against closed forms, quadrature and conservation.

use std::f64::consts::PI;

use super::tests::{close, furnace_box, homogeneous, material, rect_on_axis};
use super::*;
use crate::scene::fixtures::{cuboid, empty, fog_room, point_light};
use crate::scene::{Boundary, Light, LightKind, Material, Medium, Surface};

fn opts(samples: u32, max_depth: u32, media: bool) -> VolPathOptions {
    VolPathOptions { samples, max_depth, rr_depth: 8, seed: 11, surface_bounces: u32::MAX, eye_surfaces: true, media }
}

/// A ray from `eye` towards `target` (direction deliberately left unnormalised).
fn ray(eye: [f64; 3], target: [f64; 3]) -> CameraRay {
    CameraRay { origin: eye, direction: [0, 1, 2].map(|c| target[c] - eye[c]) }
}

fn run(scene: &Scene, rays: &[CameraRay], o: &VolPathOptions) -> Vec<Estimate> {
    let bvh = SceneBvh::build(scene);
    let (e, stats) = radiance(scene, &bvh, rays, o);
    assert_eq!(stats.nonfinite, 0);
    e
}

/// `|mean − exact| < k · stderr` and `< rel · exact` on every channel.
fn within(e: &Estimate, exact: [f64; 3], k: f64, rel: f64, what: &str) {
    eprintln!("{what}: {:?} ± {:?} vs {exact:?}", e.mean, e.stderr);
    for (c, &x) in exact.iter().enumerate() {
        let err = (e.mean[c] - x).abs();
        assert!(err < k * e.stderr[c].max(1e-15) && err < rel * x, "{what} channel {c}: {} vs {x}", e.mean[c]);
    }
}

fn rect(center: [f64; 3], half_u: [f64; 3], half_v: [f64; 3], normal: [f64; 3], l: [f64; 3]) -> Light {
    Light { name: "Rect".into(), kind: LightKind::Rect { center, half_u, half_v, normal }, radiance: l }
}

/// Vacuum, `max_depth = 0`: a Lambert floor (albedo `k`) lit by a point light `I` is seen with radiance
/// `k/π · I cos θ / d²` (one deterministic next-event sample, zero spread), with or without
/// `surface_bounces`; a ray that escapes or sees the unlit underside gives 0.
#[test]
fn lambert_floor_under_point_light_is_exact_direct_lighting() {
    let mut s = empty("cam_point.usda");
    let k = [0.2, 0.5, 0.9];
    s.materials.push(Material { base_color: k, ..material(0.0, 0.0, Surface::Opaque) });
    let mut floor = cuboid("Floor", [-5.0, -0.1, -5.0], [5.0, 0.0, 5.0]);
    floor.material = Some(0);
    s.meshes.push(floor);
    let light = [0.3, 2.0, -0.2];
    s.lights.push(point_light("Bulb", light, 3.5));
    let views =
        [([1.0, 1.0, 2.0], [0.3, 0.0, -0.2]), ([-1.5, 0.5, 0.0], [1.5, 0.0, 0.7]), ([0.0, 3.0, 0.0], [-2.0, 0.0, 1.0])];
    let mut rays: Vec<CameraRay> = views.iter().map(|&(e, t)| ray(e, t)).collect();
    rays.push(ray([0.0, 1.0, 0.0], [0.5, 2.0, 0.0])); // looks up: escapes
    rays.push(ray([0.0, -1.0, 0.0], [0.2, -0.1, 0.3])); // sees the underside, which the light misses
    for surface_bounces in [u32::MAX, 0] {
        let e = run(&s, &rays, &VolPathOptions { surface_bounces, ..opts(16, 0, false) });
        for (&(_, target), est) in views.iter().zip(&e) {
            let d = DVec3::from_array(light) - DVec3::from_array(target);
            let r = d.length();
            let exact = k.map(|kc| kc / PI * 3.5 * (d.y / r) / (r * r));
            // 1e-6: the hit point comes from the BVH at f32 precision.
            assert!(close(est.mean, exact, 1e-6), "{:?} vs {exact:?}", est.mean);
            assert_eq!(est.stderr, [0.0; 3]);
        }
        assert_eq!(e[3].mean, [0.0; 3]);
        assert_eq!(e[4].mean, [0.0; 3]);
    }
}

/// Vacuum, `max_depth = 0`: a floor point below a parallel rect light (on its axis) is seen with
/// `k/π · E` (`E` the closed-form form factor of `tests::rect_on_axis`), also from above through the
/// rect's non-emitting back; looking up into the rect's front shows its radiance `L` exactly.
#[test]
fn floor_under_rect_light_and_the_rect_itself() {
    let (l, a, b, h, k) = (2.0, 0.6, 0.3, 0.8, 0.5);
    let mut s = empty("cam_rect.usda");
    s.materials.push(material(k, 0.0, Surface::Opaque));
    let mut floor = cuboid("Floor", [-5.0, -0.1, -5.0], [5.0, 0.0, 5.0]);
    floor.material = Some(0);
    s.meshes.push(floor);
    s.lights.push(rect([0.0, h, 0.0], [a, 0.0, 0.0], [0.0, 0.0, b], [0.0, -1.0, 0.0], [l; 3]));
    let rays = [
        ray([0.7, 0.3, 0.4], [0.0; 3]),
        ray([0.0, 2.0 * h, 0.0], [0.0; 3]),
        ray([0.1, 0.2, -0.1], [0.1, 1.0, -0.1]),
        ray([0.1, 0.2, -0.1], [0.1 + 2.0 * a, 1.0, -0.1]), // passes beside the rect
    ];
    let e = run(&s, &rays, &opts(60_000, 0, false));
    let lit = k / PI * rect_on_axis(l, a, b, h);
    within(&e[0], [lit; 3], 3.0, 0.01, "floor under rect");
    within(&e[1], [lit; 3], 3.0, 0.01, "floor seen through the rect's back");
    assert!(close(e[2].mean, [l; 3], 1e-12) && e[2].stderr == [0.0; 3], "{:?}", e[2]);
    assert_eq!(e[3].mean, [0.0; 3]);
}

/// A camera in vacuum looks through a bounded, index-matched, purely absorbing slab (1 m thick along
/// x) at an emissive mesh and at rect, disk and sphere lights: each shows `L_c e^{−σ_a,c ℓ}` with
/// `ℓ = 1 m / |d_x|` the path length in the slab (the analytic lights exactly, to the f32 precision of
/// the slab's geometry: they are gathered by a deterministic connection along the ray). From behind, rect and disk show nothing; from inside the
/// sphere neither.
#[test]
fn emitters_seen_through_an_absorbing_slab() {
    let sigma_a = [0.3, 0.7, 1.9];
    let le = [1.0, 2.0, 3.0];
    let mut s = empty("cam_slab.usda");
    s.materials.push(material(0.0, 1.0, Surface::Opaque));
    let mut slab = cuboid("Slab", [1.0, -5.0, -5.0], [2.0, 5.0, 5.0]);
    slab.medium = Some(0);
    s.meshes.push(slab);
    s.media.push(Medium { boundary: Boundary::Mesh(0), ..homogeneous([0.0; 3], sigma_a, [0.0; 3]) });
    let mut lamp = cuboid("Lamp", [6.0, -2.5, -0.5], [7.0, -1.5, 0.5]);
    lamp.material = Some(0);
    s.meshes.push(lamp);
    s.lights.push(Light { name: "Lamp".into(), kind: LightKind::EmissiveMesh { mesh: 1 }, radiance: le });
    s.lights.push(rect([6.0, 0.0, -2.0], [0.0, 0.5, 0.0], [0.0, 0.0, 0.5], [-1.0, 0.0, 0.0], le));
    s.lights.push(Light {
        name: "Disk".into(),
        kind: LightKind::Disk { center: [6.0, 0.0, 2.0], normal: [-1.0, 0.0, 0.0], radius: 0.5 },
        radiance: le,
    });
    s.lights.push(Light {
        name: "Ball".into(),
        kind: LightKind::Sphere { center: [6.0, 2.0, 0.0], radius: 0.5 },
        radiance: le,
    });
    let targets = [[6.0, -2.0, 0.1], [6.0, 0.2, -2.1], [6.0, -0.1, 2.2], [6.0, 2.0, 0.0], [5.6, 1.9, 0.1]];
    let eye = [0.0, 0.0, 0.0];
    let mut rays: Vec<CameraRay> = targets.iter().map(|&t| ray(eye, t)).collect();
    rays.push(ray([10.0, 0.0, -2.0], [6.0, 0.0, -2.0])); // rect from behind
    rays.push(ray([10.0, 0.0, 2.0], [6.0, 0.0, 2.0])); // disk from behind
    rays.push(ray([6.0, 2.0, 0.0], [6.0, 2.0, 5.0])); // from inside the sphere
    let e = run(&s, &rays, &opts(20_000, 8, true));
    for (i, t) in targets.iter().enumerate() {
        let len = DVec3::from_array(*t).length() / t[0]; // 1 m of slab along x
        let exact = [0, 1, 2].map(|c| le[c] * (-sigma_a[c] * len).exp());
        if i == 0 {
            // The emissive mesh is met by the free flight (escape probability T_h): a noisy estimate.
            within(&e[0], exact, 4.0, 0.03, "emissive mesh through slab");
        } else {
            assert!(close(e[i].mean, exact, 1e-6), "target {i}: {:?} vs {exact:?}", e[i].mean);
        }
    }
    for est in &e[targets.len()..] {
        assert_eq!(est.mean, [0.0; 3]);
    }
}

/// Henyey–Greenstein phase function (written out here, independent of `physics::hg`).
fn hg_phase(mu: f64, g: f64) -> f64 {
    (1.0 - g * g) / (4.0 * PI * (1.0 + g * g - 2.0 * g * mu).powf(1.5))
}

/// Single scattering of a point light (intensity `i` at `light`) into the ray `o + t d` in an infinite
/// homogeneous medium (`σ_s`, `σ_t`, `g`): `∫₀^T e^{−σ_t t} σ_s p(⟨d, ω_l⟩) I e^{−σ_t r}/r² dt` by
/// composite Simpson with 400 000 intervals.
fn single_scatter(o: [f64; 3], d: [f64; 3], light: [f64; 3], i: f64, medium: (f64, f64, f64), t_max: f64) -> f64 {
    let (ss, st, g) = medium;
    let (o, d, light) = (DVec3::from_array(o), DVec3::from_array(d), DVec3::from_array(light));
    let f = |t: f64| {
        let v = light - (o + t * d);
        let r = v.length();
        let mu = v.dot(d) / r;
        (-st * t).exp() * ss * hg_phase(mu, g) * i * (-st * r).exp() / (r * r)
    };
    let n = 400_000;
    let h = t_max / n as f64;
    let mut sum = f(0.0) + f(t_max);
    for j in 1..n {
        sum += f(j as f64 * h) * if j % 2 == 1 { 4.0 } else { 2.0 };
    }
    sum * h / 3.0
}

/// `max_depth = 0` in a chromatic infinite medium with a point light off the ray is exactly single
/// scattering (free-flight collisions and equiangular samples, MIS, hero-channel MIS): against
/// quadrature on `[0, 80/σ_t]` per channel within 4 standard errors and 2 %. The Simpson rule itself
/// is checked against the closed form for `g = 0` without extinction, the ray starting at the foot of
/// the light's perpendicular (distance `D`): `∫₀^T σ_s I/(4π (D² + t²)) dt = σ_s I atan(T/D)/(4π D)`.
#[test]
fn single_scattering_matches_quadrature() {
    let (ss, sa, g) = ([0.3, 0.6, 0.9], [0.2, 0.1, 0.05], [0.0, 0.5, -0.3]);
    let (light, i) = ([1.0, 0.6, 0.0], 2.0);
    let check = single_scatter([1.0, 0.0, 0.0], [0.0, 0.0, 1.0], light, i, (0.5, 0.0, 0.0), 50.0);
    let closed = 0.5 * i * (50.0f64 / 0.6).atan() / (4.0 * PI * 0.6);
    assert!((check - closed).abs() < 1e-10 * closed, "Simpson {check} vs {closed}");

    let mut s = empty("cam_single.usda");
    s.media.push(homogeneous(ss, sa, g));
    s.lights.push(point_light("Bulb", light, i));
    let dirs = [[1.0, 0.0, 0.0], [-1.0, 0.0, 0.0], [0.6, 0.0, 0.8]];
    let rays: Vec<CameraRay> = dirs.iter().map(|&d| CameraRay { origin: [0.0; 3], direction: d }).collect();
    let e = run(&s, &rays, &opts(100_000, 0, true));
    for (d, est) in dirs.iter().zip(&e) {
        let exact = [0, 1, 2].map(|c| {
            let st = ss[c] + sa[c];
            single_scatter([0.0; 3], *d, light, i, (ss[c], st, g[c]), 80.0 / st)
        });
        within(est, exact, 4.0, 0.02, &format!("single scattering along {d:?}"));
    }
}

/// A closed box whose black inside walls emit `L`, filled with a chromatic non-absorbing medium: the
/// radiance field is uniform, so every camera ray inside sees `L` (without media exactly; with
/// multiple scattering within 3 standard errors and 1 %).
#[test]
fn camera_inside_emissive_box_is_a_furnace() {
    let l = 1.5;
    let s = furnace_box(l);
    let rays = [
        ray([0.5, 0.5, 0.5], [0.5, 1.0, 0.5]),
        ray([0.5, 0.5, 0.5], [0.0, 0.1, 0.2]),
        ray([0.2, 0.7, 0.9], [0.9, 0.3, 0.1]),
    ];
    let exact = run(&s, &rays, &opts(16, 256, false));
    for est in &exact {
        assert!(close(est.mean, [l; 3], 1e-12) && est.stderr == [0.0; 3], "{est:?}");
    }
    let e = run(&s, &rays, &opts(200_000, 256, true));
    for est in &e {
        within(est, [l; 3], 3.0, 0.01, "furnace");
    }
}

/// A camera looks at normal incidence through a glass slab (ior 1.5, Fresnel `F = 0.04`) at a rect
/// light of radiance `L`: the depth budget decides how many interface events a path may have, so
/// `max_depth` 0 (the far interface would be vertex 2) shows 0, 1 shows the two transmissions
/// `L (1 − F)²` and a large budget all internal reflections, `L (1 − F)²/(1 − F²) = L (1 − F)/(1 + F)`.
#[test]
fn rect_light_through_glass_follows_fresnel_and_depth_budget() {
    let le = [1.0, 2.0, 3.0];
    let mut s = empty("cam_glass.usda");
    s.materials.push(material(0.0, 0.0, Surface::Dielectric { ior: 1.5 }));
    let mut glass = cuboid("Glass", [1.0, -5.0, -5.0], [2.0, 5.0, 5.0]);
    glass.material = Some(0);
    s.meshes.push(glass);
    s.lights.push(rect([4.0, 0.0, 0.0], [0.0, 0.5, 0.0], [0.0, 0.0, 0.5], [-1.0, 0.0, 0.0], le));
    let rays = [CameraRay { origin: [0.0; 3], direction: [1.0, 0.0, 0.0] }];
    let f = 0.04f64;
    assert_eq!(run(&s, &rays, &opts(2000, 0, false))[0].mean, [0.0; 3]);
    let one = run(&s, &rays, &opts(20_000, 1, false))[0];
    within(&one, le.map(|x| x * (1.0 - f).powi(2)), 4.0, 0.01, "glass, max_depth 1");
    let all = run(&s, &rays, &opts(20_000, 64, false))[0];
    within(&all, le.map(|x| x * (1.0 - f) / (1.0 + f)), 4.0, 0.01, "glass, all orders");
}

#[test]
fn camera_results_do_not_depend_on_thread_count() {
    let s = fog_room();
    let bvh = SceneBvh::build(&s);
    let rays: Vec<CameraRay> =
        (0..6).map(|i| ray([2.0, 1.2, -0.5], [0.4 + 0.6 * i as f64, 0.3 * (i % 3) as f64, 3.0])).collect();
    let o = opts(200, 64, true);
    let bits = |threads: usize| {
        let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
        let (e, stats) = pool.install(|| radiance(&s, &bvh, &rays, &o));
        assert!(e.iter().all(|x| x.mean[0] > 0.0), "{e:?}");
        let mut v: Vec<u64> = e.iter().flat_map(|x| x.mean.iter().chain(&x.stderr).map(|f| f.to_bits())).collect();
        v.push(stats.rays);
        v
    };
    assert_eq!(bits(1), bits(2));
}

/// Non-finite or zero rays give 0 without paths; rays starting at the point light stay finite.
#[test]
fn degenerate_camera_rays_give_zero() {
    let s = fog_room();
    let bvh = SceneBvh::build(&s);
    let rays = [
        CameraRay { origin: [f64::NAN, 1.0, 1.0], direction: [0.0, -1.0, 0.0] },
        CameraRay { origin: [1.0, f64::INFINITY, 1.0], direction: [0.0, -1.0, 0.0] },
        CameraRay { origin: [1.0, 1.0, 1.0], direction: [0.0, f64::NEG_INFINITY, 0.0] },
        CameraRay { origin: [1.0, 1.0, 1.0], direction: [0.0; 3] },
        CameraRay { origin: [2.0, 2.0, 2.0], direction: [0.0, -1.0, 0.0] },
    ];
    let o = opts(64, 64, true);
    let (e, stats) = radiance(&s, &bvh, &rays, &o);
    assert_eq!(stats.nonfinite, 0);
    assert_eq!(stats.paths, 64);
    for est in &e[..4] {
        assert_eq!((est.mean, est.stderr), ([0.0; 3], [0.0; 3]));
    }
    assert!(e[4].mean.iter().chain(&e[4].stderr).all(|x| x.is_finite()) && e[4].mean[0] > 0.0, "{:?}", e[4]);
}

/// `eye_surfaces = false`, `max_depth = 0`: a camera ray through a homogeneous medium down onto a lit
/// floor sees exactly the medium's single scattering of the point light up to the floor (quadrature on
/// `[0, 2]`, within 4 standard errors and 2 %), and no floor; with `eye_surfaces = true` the lit floor
/// adds its attenuated radiance `k/π · I cos θ e^{−σ_t (d + 2)}/d² ` (`d` light–floor distance).
#[test]
fn eye_surfaces_off_leaves_only_the_media() {
    let (ss, sa, g, k, i) = (0.3, 0.1, 0.4, 0.6, 2.0);
    let light = [1.0, 0.6, 0.0];
    let mut s = empty("cam_eye_surfaces.usda");
    s.media.push(homogeneous([ss; 3], [sa; 3], [g; 3]));
    s.materials.push(material(k, 0.0, Surface::Opaque));
    let mut floor = cuboid("Floor", [-5.0, -2.1, -5.0], [5.0, -2.0, 5.0]);
    floor.material = Some(0);
    s.meshes.push(floor);
    s.lights.push(point_light("Bulb", light, i));
    let rays = [CameraRay { origin: [0.0; 3], direction: [0.0, -1.0, 0.0] }];
    let off = run(&s, &rays, &VolPathOptions { eye_surfaces: false, ..opts(100_000, 0, true) });
    let single = single_scatter([0.0; 3], [0.0, -1.0, 0.0], light, i, (ss, ss + sa, g), 2.0);
    within(&off[0], [single; 3], 4.0, 0.02, "eye surfaces off");
    let on = run(&s, &rays, &opts(100_000, 0, true));
    let d = (DVec3::from_array(light) - DVec3::new(0.0, -2.0, 0.0)).length();
    let floor_term = k / PI * i * (2.6 / d) * (-(ss + sa) * (d + 2.0)).exp() / (d * d);
    within(&on[0], [single + floor_term; 3], 4.0, 0.02, "eye surfaces on");
}
