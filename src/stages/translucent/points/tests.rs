use super::elimination::*;
use super::*;
use crate::render::dielectric::Material;
use crate::scene::bvh::{SceneBvh, procedural};
use crate::scene::fixtures::cuboid;
use crate::scene::{Material as SceneMaterial, Scene, Surface};

fn mat(sigma: [f64; 3], ior: f64) -> Material {
    Material { sigma_t: sigma, albedo: [0.9; 3], g: 0.0, ior }
}

fn emitter(center: DVec3, radius: f64, intensity: [f64; 3]) -> Emitter {
    let a = PI * radius * radius;
    Emitter { center, radius, radiance: intensity.map(|i| i / a) }
}

fn opaque(rho: [f64; 3]) -> SceneMaterial {
    SceneMaterial {
        name: "ground".into(),
        base_color: rho,
        emission: [0.0; 3],
        surface: Surface::Opaque,
        roughness: 1.0,
    }
}

fn opts(n: usize) -> PointOptions {
    PointOptions { surface_samples: n, indirect_rays: 0, ..PointOptions::default() }
}

fn run(scene: &Scene, m: Material, emitters: &[Emitter], o: &PointOptions) -> Points {
    let bvh = SceneBvh::build(scene);
    let setup = Setup { scene, bvh: &bvh, object: 0, material: m, emitters };
    generate(&setup, o).unwrap()
}

#[test]
fn cube_samples_cover_the_area_on_the_faces() {
    let s = procedural::scene(vec![cuboid("c", [-0.5, -0.25, 0.0], [0.5, 0.25, 2.0])]);
    let p = run(&s, mat([1.0; 3], 1.5), &[], &opts(3000));
    assert_eq!(p.surface.len(), 3000);
    // 2(1·0.5 + 1·2 + 0.5·2) = 7 m².
    let total: f64 = p.surface.iter().map(|x| x.area).sum();
    assert!((total - 7.0).abs() < 1e-9, "{total}");
    for x in &p.surface {
        // The normal is the axis of the face the point lies on, pointing away from the centre.
        let a = x.normal.abs().max_element();
        assert!((a - 1.0).abs() < 1e-12);
        let k = (0..3).find(|&k| x.normal[k].abs() > 0.5).unwrap();
        let face = [(-0.5, 0.5), (-0.25, 0.25), (0.0, 2.0)][k];
        let want = if x.normal[k] > 0.0 { face.1 } else { face.0 };
        assert!((x.position[k] - want).abs() < 1e-6, "{x:?}");
    }
    // Per face, the count follows the area (1 m² ↔ 3000/7 samples) within 5 %.
    let top = p.surface.iter().filter(|x| x.normal.z > 0.5).count() as f64;
    assert!((top - 0.5 / 7.0 * 3000.0).abs() < 0.05 * 3000.0 * 0.5 / 7.0 + 3.0, "{top}");
}

#[test]
fn samples_are_well_spaced() {
    let sphere = procedural::icosphere("s", [0.0; 3], 1.0, 4);
    let s = procedural::scene(vec![sphere]);
    let n = 2000;
    let p = run(&s, mat([1.0; 3], 1.5), &[], &opts(n));
    let area: f64 = p.surface.iter().map(|x| x.area).sum();
    let r_max = (area / (2.0 * 3f64.sqrt() * n as f64)).sqrt();
    let min_dist = |pts: &[DVec3]| {
        let mut m = f64::INFINITY;
        for i in 0..pts.len() {
            for j in 0..i {
                m = m.min(pts[i].distance(pts[j]));
            }
        }
        m
    };
    let blue: Vec<DVec3> = p.surface.iter().map(|x| x.position).collect();
    let tris = world_triangles(&s.meshes[0]);
    let white: Vec<DVec3> = area_uniform(&tris, n, 1).into_iter().map(|c| c.0).collect();
    // 2·r_max is the largest possible minimum distance (hexagonal packing of n points on the area).
    let d_max = 2.0 * r_max;
    let (b, w) = (min_dist(&blue), min_dist(&white));
    assert!(b >= 0.5 * d_max, "blue-noise minimum distance {b} vs packing distance {d_max}");
    assert!(w < 0.5 * d_max, "white noise minimum distance {w} vs packing distance {d_max}");
}

#[test]
fn direct_irradiance_matches_inverse_square_law_with_shadow() {
    // Sphere of radius 0.5 at the origin, a near-point emitter at z = 3, an opaque square at
    // z = 1.5 over x ∈ [0, 0.3], y ∈ [−0.3, 0.3] shadowing part of the lit cap.
    let mut quad = procedural::mesh(
        "q",
        vec![[0.0, -0.3, 1.5], [0.3, -0.3, 1.5], [0.3, 0.3, 1.5], [0.0, 0.3, 1.5]],
        vec![[0.0, 0.0, 1.0]; 4],
        vec![[0, 1, 2], [0, 2, 3]],
    );
    quad.material = Some(0);
    let mut s = procedural::scene(vec![procedural::icosphere("s", [0.0; 3], 0.5, 3), quad]);
    s.materials.push(opaque([0.5; 3]));
    let c = DVec3::new(0.0, 0.0, 3.0);
    let i = [1.0, 2.0, 3.0];
    let p = run(&s, mat([1.0; 3], 1.5), &[emitter(c, 1e-10, i)], &opts(1500));
    let (mut lit, mut shadowed) = (0, 0);
    for x in &p.surface {
        let v = c - x.position;
        let cos = x.normal.dot(v.normalize());
        // Crossing of the segment with z = 1.5 (away from the square's edges by 1e-3).
        let t = (1.5 - x.position.z) / v.z;
        let q = x.position + v * t;
        let margin = [q.x, 0.3 - q.x, 0.3 - q.y, q.y + 0.3].into_iter().fold(f64::INFINITY, f64::min);
        if margin.abs() < 1e-3 || cos.abs() < 0.05 {
            continue;
        }
        let blocked = (0.0..1.0).contains(&t) && margin > 0.0;
        for (k, ik) in i.iter().enumerate() {
            let want = if cos > 0.0 && !blocked { ik * cos / v.length_squared() } else { 0.0 };
            assert!((x.direct[k] - want).abs() <= 1e-5 * want + 1e-15, "{:?}: {} vs {want}", x.position, x.direct[k]);
        }
        if cos > 0.0 {
            if blocked { shadowed += 1 } else { lit += 1 }
        }
    }
    assert!(lit > 100 && shadowed > 20, "lit {lit}, shadowed {shadowed}");
}

#[test]
fn index_matched_flux_and_tube_growth() {
    let s = procedural::scene(vec![procedural::icosphere("s", [0.0; 3], 0.5, 3)]);
    let c = DVec3::new(1.0, 2.0, 4.0);
    let sigma = [0.5, 1.0, 2.0];
    let p = run(&s, mat(sigma, 1.0), &[emitter(c, 1e-10, [3.0; 3])], &opts(500));
    let mut checked = 0;
    for v in &p.volume {
        let x = &p.surface[v.surface as usize];
        let d = c.distance(x.position);
        let l = (c - x.position) / d;
        let cos = x.normal.dot(l);
        // No bending, no reflection at η = 1.
        assert!((v.direction + l).length() < 1e-6);
        assert_eq!(v.bounce, 0);
        // Flux: E·area·e^{−σ t} exactly (F = 0), E = I cos/D² as recorded.
        for (k, sk) in sigma.iter().enumerate() {
            let want = x.direct[k] * x.area * (-sk * v.depth).exp();
            assert!((v.flux[k] - want).abs() <= 1e-12 * want, "{} vs {want}", v.flux[k]);
        }
        // Tube: area·cos·(1 + t/D)² at the midpoint depth.
        let t = v.depth + 0.5 * v.length;
        let want = x.area * cos * (1.0 + t / d).powi(2);
        assert!((v.area - want).abs() <= 1e-6 * want, "{} vs {want}", v.area);
        checked += 1;
    }
    assert!(checked > 500);
    assert!(p.stats.light_rays > 100);
}

fn slab_ctx<'a>(setup: &'a Setup<'a>, bounces: u32) -> LightCtx<'a> {
    LightCtx {
        setup,
        eta: setup.material.ior,
        sigma_t: setup.material.sigma_t,
        sigma_min: setup.material.sigma_t.iter().copied().fold(f64::INFINITY, f64::min),
        budget: 1e3,
        samples_per_ray: 5,
        light_bounces: bounces,
        eps: 1e-6,
        object_light: false,
    }
}

#[test]
fn total_internal_reflection_at_a_cube_side_by_hand() {
    // Unit cube, η = 1.5. A ray enters the top face at (0.3, 0.5, 0) from 80° incidence:
    // sin θ_t = sin 80°/1.5, it reaches the side x = −0.5 before the bottom, where the angle of
    // incidence (90° − θ_t = 48.96°) exceeds the critical 41.81°: total reflection; then it meets
    // the bottom at θ_t and is partly transmitted.
    let s = procedural::scene(vec![cuboid("c", [-0.5; 3], [0.5; 3])]);
    let bvh = SceneBvh::build(&s);
    let sigma = [0.3, 0.6, 0.9];
    let setup = Setup { scene: &s, bvh: &bvh, object: 0, material: mat(sigma, 1.5), emitters: &[] };
    let ctx = slab_ctx(&setup, 1);
    let th = 80f64.to_radians();
    let l = DVec3::new(th.sin(), th.cos(), 0.0);
    let dir = refract(-l, DVec3::Y, 1.0, 1.5).unwrap();
    let (st, ct) = (th.sin() / 1.5, (1.0 - (th.sin() / 1.5).powi(2)).sqrt());
    assert!((dir - DVec3::new(-st, -ct, 0.0)).length() < 1e-12);
    let phi = [1.0, 2.0, 4.0];
    let ray = Entering {
        point: DVec3::new(0.3, 0.5, 0.0),
        normal: DVec3::Y,
        dir,
        flux: phi,
        tube: Tube { area_cos: 1.0, d_s: 1.0, d_t: 1.0 },
        surface: 7,
    };
    let mut out = Vec::new();
    let b = trace(&ctx, &ray, &mut out, &mut Vec::new());
    let s1 = 0.8 / st; // to x = −0.5
    let y1 = 0.5 - s1 * ct;
    let s2 = (y1 + 0.5) / ct; // then to y = −0.5
    assert!(y1 > -0.5);
    assert_eq!(b.tir, 1);
    let len = |k: u8| out.iter().filter(|v| v.bounce == k).map(|v| v.length).sum::<f64>();
    assert!((len(0) - s1).abs() < 1e-5, "{} vs {s1}", len(0));
    assert!((len(1) - s2).abs() < 1e-5, "{} vs {s2}", len(1));
    let first1 = out.iter().find(|v| v.bounce == 1).unwrap();
    let f_bottom = fresnel(ct, 1.5, 1.0);
    for k in 0..3 {
        // All of Φ(s1) is reflected; at the bottom (1 − F) leaves and F is cut by the bounce limit.
        assert!((first1.flux[k] - phi[k] * (-sigma[k] * s1).exp()).abs() < 1e-5 * phi[k]);
        let at_bottom = phi[k] * (-sigma[k] * (s1 + s2)).exp();
        assert!((b.transmitted[k] - (1.0 - f_bottom) * at_bottom).abs() < 1e-5 * phi[k]);
        assert!((b.lost[k] - f_bottom * at_bottom).abs() < 1e-5 * phi[k]);
    }
    assert!(out.iter().all(|v| v.surface == 7));
}

/// Σ over a ray's intervals of (flux in − flux out) + transmitted + cut-off flux = entering flux.
fn assert_conserved(ctx: &LightCtx, ray: &Entering) -> RayBudget {
    let mut out = Vec::new();
    let b = trace(ctx, ray, &mut out, &mut Vec::new());
    for k in 0..3 {
        let absorbed: f64 = out.iter().map(|v| -v.flux[k] * (-ctx.sigma_t[k] * v.length).exp_m1()).sum();
        let total = absorbed + b.transmitted[k] + b.lost[k];
        assert!((total - ray.flux[k]).abs() <= 1e-12 * ray.flux[k], "channel {k}: {total} vs {}", ray.flux[k]);
    }
    b
}

#[test]
fn light_rays_conserve_flux() {
    let s = procedural::scene(vec![procedural::icosphere("s", [0.0; 3], 0.5, 3)]);
    let bvh = SceneBvh::build(&s);
    for (sigma, bounces) in [([2.0, 5.0, 10.0], 3), ([1e-3, 0.1, 1.0], 8), ([40.0, 80.0, 160.0], 0)] {
        let setup = Setup { scene: &s, bvh: &bvh, object: 0, material: mat(sigma, 1.5), emitters: &[] };
        let ctx = LightCtx { budget: 2.0, ..slab_ctx(&setup, bounces) };
        let key = StreamKey { table: 5, cell: 0 };
        let mut reflected = 0;
        for r in 0..40u64 {
            let u = DVec3::new(key.uniform(r, 0), key.uniform(r, 1), key.uniform(r, 2)) * 2.0 - 1.0;
            let Some(h) = bvh.closest_hit(&Ray::new((u.normalize() * 3.0).to_array(), (-u).to_array())) else {
                continue;
            };
            let n = DVec3::from_array(h.geometric_normal);
            let p = u.normalize() * 3.0 - u * h.t;
            let l = (u + DVec3::new(0.3, 0.0, 0.0)).normalize();
            let Some(dir) = refract(-l, n, 1.0, 1.5).filter(|_| n.dot(l) > 0.0) else { continue };
            let ray = Entering {
                point: p,
                normal: n,
                dir,
                flux: [1.0, 0.5, 2.0],
                tube: Tube { area_cos: 1.0, d_s: 1.0, d_t: 1.0 },
                surface: 0,
            };
            let b = assert_conserved(&ctx, &ray);
            reflected += usize::from(b.lost.iter().any(|&x| x > 0.0));
        }
        assert!(reflected > 0);
    }
}

#[test]
fn thin_and_opaque_media_stay_finite() {
    let s = procedural::scene(vec![procedural::icosphere("s", [0.0; 3], 0.5, 2)]);
    let e = [emitter(DVec3::new(0.5, 1.0, 3.0), 0.05, [2.0; 3])];
    for sigma in [1e-9, 1e6] {
        let p = run(&s, mat([sigma; 3], 1.5), &e, &opts(400));
        assert!(!p.volume.is_empty());
        for v in &p.volume {
            let ok = v.start.is_finite()
                && v.length.is_finite()
                && v.length > 0.0
                && v.area.is_finite()
                && v.area > 0.0
                && v.flux.iter().chain(&v.track_length([sigma; 3])).all(|x| x.is_finite() && *x >= 0.0);
            assert!(ok, "{v:?}");
        }
        assert!(p.stats.lost_flux_fraction.is_finite());
        if sigma > 1.0 {
            // Every ray is cut at 8 mean free paths: e^{−8} of the entering flux is left.
            assert!((p.stats.lost_flux_fraction - (-8f64).exp()).abs() < 1e-9, "{}", p.stats.lost_flux_fraction);
            assert!(p.volume.iter().all(|v| v.depth + v.length <= 8e-6 * (1.0 + 1e-9)));
        }
    }
}

#[test]
fn total_internal_reflection_is_counted_at_grazing_light() {
    let s = procedural::scene(vec![cuboid("c", [-0.5; 3], [0.5; 3])]);
    let m = mat([0.1; 3], 1.5);
    // Light from 84° off the top normal: rays through the top meet a side beyond the critical angle.
    let grazing = run(&s, m, &[emitter(DVec3::new(-20.0, 2.6, 0.0), 0.01, [1.0; 3])], &opts(600));
    assert!(grazing.stats.total_internal_reflections > 20, "{:?}", grazing.stats);
    assert!(grazing.volume.iter().any(|v| v.bounce > 0));
    // Light from straight above and far (rays within 5e-5 rad of vertical): rays meet the bottom and
    // top at near-normal incidence, never totally reflected. (A near source would totally reflect the
    // few rays entering within a ray divergence × path length of the top's edges off the sides.)
    let above = run(&s, m, &[emitter(DVec3::new(0.0, 1e4, 0.0), 0.01, [1.0; 3])], &opts(600));
    assert_eq!(above.stats.total_internal_reflections, 0);
    assert!(above.stats.light_rays > 50);
}

#[test]
fn indirect_irradiance_from_a_lit_ground_matches_quadrature() {
    // A small sphere 1 m above a 100 m × 100 m ground of albedo ρ lit by a near-point emitter at
    // (3, 2, 0). The ground's radiance is ρ/π·I·2/d³; the irradiance at the lowest sample is
    // ∫ L cos_x cos_p / r² dA over the ground (the sphere's own shadow on the ground is ~2e-4 of it).
    let rho = [0.8, 0.4, 0.2];
    let mut ground = procedural::mesh(
        "g",
        vec![[-50.0, 0.0, -50.0], [50.0, 0.0, -50.0], [50.0, 0.0, 50.0], [-50.0, 0.0, 50.0]],
        vec![[0.0, 1.0, 0.0]; 4],
        vec![[0, 2, 1], [0, 3, 2]],
    );
    ground.material = Some(0);
    let mut s = procedural::scene(vec![procedural::icosphere("s", [0.0, 1.0, 0.0], 0.05, 2), ground]);
    s.materials.push(opaque(rho));
    let c = DVec3::new(3.0, 2.0, 0.0);
    let i = 5.0;
    let o = PointOptions { surface_samples: 24, indirect_rays: 4096, ..PointOptions::default() };
    let p = run(&s, mat([1.0; 3], 1.5), &[emitter(c, 1e-4, [i; 3])], &o);
    // The lowest sample and the one whose normal is closest to horizontal.
    let low = p.surface.iter().min_by(|a, b| a.normal.y.total_cmp(&b.normal.y)).unwrap();
    let side = p.surface.iter().min_by(|a, b| a.normal.y.abs().total_cmp(&b.normal.y.abs())).unwrap();
    assert!(low.normal.y < -0.8 && side.normal.y.abs() < 0.3);
    for (x, tol) in [(low, 0.02), (side, 0.03)] {
        // Graded midpoint rule, p = 50·u³ per axis.
        let m = 1000;
        let mut e = 0.0;
        for a in 0..m {
            let ua = -1.0 + (a as f64 + 0.5) * 2.0 / m as f64;
            let (px, jx) = (50.0 * ua.powi(3), 150.0 * ua * ua * 2.0 / m as f64);
            for b in 0..m {
                let ub = -1.0 + (b as f64 + 0.5) * 2.0 / m as f64;
                let (pz, jz) = (50.0 * ub.powi(3), 150.0 * ub * ub * 2.0 / m as f64);
                let q = DVec3::new(px, 0.0, pz);
                let de = c.distance(q);
                let radiance = i * 2.0 / de.powi(3) / PI;
                let r = q - x.position;
                let cos_x = x.normal.dot(r);
                if cos_x > 0.0 {
                    e += radiance * cos_x * x.position.y / r.length_squared().powi(2) * jx * jz;
                }
            }
        }
        for (k, rk) in rho.iter().enumerate() {
            let want = rk * e;
            assert!(
                (x.indirect[k] - want).abs() < tol * want,
                "n {}: channel {k}: {} vs {want}",
                x.normal,
                x.indirect[k]
            );
        }
    }
}

#[test]
fn obb_and_track_length() {
    let v = VolumeSample {
        start: DVec3::new(1.0, 0.0, 0.0),
        direction: DVec3::Z,
        length: 2.0,
        flux: [1.0, 2.0, 3.0],
        area: 0.04,
        surface: 0,
        bounce: 0,
        depth: 0.0,
        plane_point: DVec3::new(1.0, 0.0, 0.0),
        plane_normal: -DVec3::Z,
        tan_entry: 0.0,
    };
    assert_eq!(v.center(), DVec3::new(1.0, 0.0, 1.0));
    assert_eq!(v.end(), DVec3::new(1.0, 0.0, 2.0));
    // ∫_0^2 Φ e^{−s} ds = Φ (1 − e^{−2}); σ → 0 gives Φ L; σ → ∞ gives Φ/σ.
    let t = v.track_length([1.0, 1e-300, 1e300]);
    assert!((t[0] - (1.0 - (-2f64).exp())).abs() < 1e-15);
    assert!((t[1] - 4.0).abs() < 1e-15);
    assert!((t[2] - 3e-300).abs() < 1e-312);
    let b = v.obb(1.0);
    // Cross-section side sqrt(0.04) = 0.2: a ray along x through the centre spans [−0.1, 0.1] about it.
    let (t0, t1) = b.hit(DVec3::new(0.0, 0.0, 1.0), DVec3::X).unwrap();
    let w = (b.axes[1].x.abs() + b.axes[2].x.abs()) * 0.1;
    assert!((t0 - (1.0 - w)).abs() < 1e-12 && (t1 - (1.0 + w)).abs() < 1e-12, "{t0} {t1}");
    assert!(b.hit(DVec3::new(0.0, 0.0, 3.5), DVec3::X).is_none());
    let (t0, t1) = b.hit(DVec3::new(1.0, 0.0, -1.0), DVec3::Z).unwrap();
    assert!((t0 - 1.0).abs() < 1e-12 && (t1 - 3.0).abs() < 1e-12);
    let (lo, hi) = b.aabb();
    assert!((lo.z - 0.0).abs() < 1e-12 && (hi.z - 2.0).abs() < 1e-12);
    assert!(lo.x <= 0.9 + 1e-12 && hi.x >= 1.1 - 1e-12 && hi.x - lo.x <= 0.2 * 2f64.sqrt() + 1e-12);
    // Starting on the boundary at tan θ = 0.5, half-width 0.1: the box reaches back 0.05; at
    // grazing tan θ = 100 the reach stops at 4 half-widths (0.4). The end face stays put.
    for (tan_entry, back) in [(0.5, 0.05), (100.0, 0.4)] {
        let (t0, t1) = VolumeSample { tan_entry, ..v }.obb(1.0).hit(DVec3::new(1.0, 0.0, -1.0), DVec3::Z).unwrap();
        assert!((t0 - (1.0 - back)).abs() < 1e-12 && (t1 - 3.0).abs() < 1e-12, "{tan_entry}: {t0} {t1}");
    }
}

#[test]
fn bad_input_is_an_error_and_output_is_deterministic() {
    let s = procedural::scene(vec![procedural::icosphere("s", [0.0; 3], 0.5, 2)]);
    let bvh = SceneBvh::build(&s);
    let e = [emitter(DVec3::new(0.0, 0.0, 3.0), 0.05, [1.0; 3])];
    let setup = Setup { scene: &s, bvh: &bvh, object: 0, material: mat([1.0; 3], 1.5), emitters: &e };
    assert!(generate(&Setup { object: 3, ..setup }, &opts(10)).is_err());
    assert!(generate(&Setup { material: mat([-1.0; 3], 1.5), ..setup }, &opts(10)).is_err());
    assert!(generate(&setup, &opts(0)).is_err());
    assert!(generate(&setup, &PointOptions { max_depth_mfp: f64::NAN, ..opts(10) }).is_err());
    let bad = [Emitter { radius: f64::NAN, ..e[0] }];
    assert!(generate(&Setup { emitters: &bad, ..setup }, &opts(10)).is_err());
    let o = PointOptions { surface_samples: 300, indirect_rays: 4, ..PointOptions::default() };
    let a = generate(&setup, &o).unwrap();
    let pool = rayon::ThreadPoolBuilder::new().num_threads(1).build().unwrap();
    let b = pool.install(|| generate(&setup, &o).unwrap());
    assert_eq!(a.surface, b.surface);
    assert_eq!(a.volume, b.volume);
    assert_eq!(a.stats.entered_flux, b.stats.entered_flux);
}

#[test]
#[ignore = "timing on the bundled scene; run with --ignored --nocapture"]
fn bundled_scene_timing() {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes/translucent.gltf");
    let scene = Scene::load(&path).unwrap();
    let bvh = SceneBvh::build(&scene);
    let (object, _) = crate::render::dielectric::find_object(&scene, &bvh).unwrap();
    let (em, _) = crate::render::dielectric::emitters(&scene, 0.02);
    let setup = Setup {
        scene: &scene,
        bvh: &bvh,
        object,
        material: Material::preset("Wax", 0.01, 1.5).unwrap(),
        emitters: &em,
    };
    let t = Instant::now();
    let p = generate(&setup, &PointOptions::default()).unwrap();
    println!(
        "emitters {}, surface {}, volume {}, total {:.0} ms, stats {:?}",
        em.len(),
        p.surface.len(),
        p.volume.len(),
        ms(t),
        p.stats
    );
}
