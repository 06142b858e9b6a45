use super::*;
use crate::reference::volpath::{self, CameraRay, VolPathOptions};
use crate::scene::bvh::SceneBvh;
use crate::scene::bvh::procedural::icosphere;
use crate::scene::fixtures::{cuboid, empty};
use crate::scene::{Boundary, Density, Light, LightKind, Medium, Scene, Surface};

fn scene_of(meshes: Vec<crate::scene::Mesh>) -> Scene {
    let mut s = empty("translucent_reference.usda");
    s.meshes = meshes;
    s
}

fn mat(sigma_t: [f64; 3], albedo: [f64; 3], g: f64, ior: f64) -> Material {
    Material { sigma_t, albedo, g, ior }
}

fn opts(samples: u32, guide: f64, seed: u64) -> ReferenceOptions {
    ReferenceOptions { samples, guide, seed, ..ReferenceOptions::default() }
}

fn run(s: &Scene, m: Material, em: &[Emitter], cam: &ViewCamera, o: &ReferenceOptions) -> ReferenceImage {
    let bvh = SceneBvh::build(s);
    let setup = Setup { scene: s, bvh: &bvh, object: 0, material: m, emitters: em };
    render(&setup, cam, o, &|_| {})
}

fn cam1(eye: [f64; 3], forward: [f64; 3]) -> ViewCamera {
    ViewCamera::new(eye, forward, [0.0, 1.0, 0.0], 0.5, 1, 1).unwrap()
}

/// Gauss–Legendre nodes and weights on [a, b] (the references' own rule, mapped).
fn gauss_legendre(n: usize, a: f64, b: f64) -> Vec<(f64, f64)> {
    crate::reference::quadrature::gauss_legendre(n)
        .into_iter()
        .map(|(x, w)| (0.5 * (a + b) + 0.5 * (b - a) * x, 0.5 * (b - a) * w))
        .collect()
}

/// Index-matched pure absorber: an emitter seen through a 1 m slab shows `L e^{−σ_t ℓ}` exactly (the
/// medium is crossed deterministically at albedo 0), `ℓ = 1/|d_x|`.
#[test]
fn absorber_index_matched_is_exact_transmittance() {
    let s = scene_of(vec![cuboid("Slab", [1.0, -5.0, -5.0], [2.0, 5.0, 5.0])]);
    let sigma = [0.3, 0.7, 1.9];
    let le = [1.0, 2.0, 3.0];
    let m = mat(sigma, [0.0; 3], 0.0, 1.0);
    for (dir, tol) in [([1.0, 0.0, 0.0], 1e-9), ([6.0, 0.3, -0.2], 1e-6)] {
        let d = DVec3::from_array(dir).normalize();
        let em = [Emitter { center: d * (6.0 / d.x), radius: 0.5, radiance: le }];
        let img = run(&s, m, &em, &cam1([0.0; 3], dir), &opts(8, 0.5, 1));
        let chord = 1.0 / d.x;
        let got = img.components[0][0];
        for c in 0..3 {
            let exact = le[c] * (-sigma[c] * chord).exp();
            eprintln!("absorber dir {dir:?} c{c}: {} vs {exact}", got[c]);
            assert!((got[c] - exact).abs() <= tol * exact, "{} vs {exact}", got[c]);
        }
        assert_eq!(img.variance[0], [0.0; 3]);
        assert!(img.object[0]);
        assert_eq!((img.paths, img.nonfinite), (8, 0));
        assert!(img.components[1..].iter().all(|c| c[0] == [0.0; 3]));
    }
}

/// Refractive absorbing slab at normal incidence: all internal reflections,
/// `L (1 − F)² e^{−τ} / (1 − F² e^{−2τ})` with `F = 0.04`.
#[test]
fn refractive_slab_follows_the_fresnel_series() {
    let s = scene_of(vec![cuboid("Slab", [1.0, -50.0, -50.0], [1.1, 50.0, 50.0])]);
    let sigma = [0.5, 1.0, 3.0];
    let le = [1.0, 2.0, 3.0];
    let em = [Emitter { center: DVec3::new(6.0, 0.0, 0.0), radius: 0.5, radiance: le }];
    let img = run(&s, mat(sigma, [0.0; 3], 0.0, 1.5), &em, &cam1([0.0; 3], [1.0, 0.0, 0.0]), &opts(20_000, 0.5, 2));
    let f = 0.04f64;
    for c in 0..3 {
        let t = (-sigma[c] * 0.1).exp();
        let exact = le[c] * (1.0 - f).powi(2) * t / (1.0 - f * f * t * t);
        let got = img.components[0][0][c];
        let z = (got - exact) / img.variance[0][c].sqrt();
        eprintln!("slab c{c}: {got} ± {} vs {exact} (z {z:.2})", img.variance[0][c].sqrt());
        assert!(z.abs() < 4.5 && (got - exact).abs() < 0.01 * exact, "{got} vs {exact}");
    }
}

/// Mean and standard error over pixels (independent batches) of one component.
fn batch(img: &ReferenceImage, comp: usize) -> ([f64; 3], [f64; 3]) {
    let v = &img.components[comp];
    let n = v.len() as f64;
    let mean = [0, 1, 2].map(|c| v.iter().map(|x| x[c]).sum::<f64>() / n);
    let se = [0, 1, 2].map(|c| (v.iter().map(|x| (x[c] - mean[c]).powi(2)).sum::<f64>() / ((n - 1.0) * n)).sqrt());
    (mean, se)
}

/// Single scattering in an index-matched box against deterministic quadrature: along the camera
/// ray (Gauss–Legendre in depth) and over the emitter's cone (Gauss–Legendre in cos θ, trapezoid in
/// φ), `σ_s T_cam phase L T_light` with exact box chords.
#[test]
fn single_scattering_matches_quadrature() {
    let (lo, hi) = ([1.0, -0.5, -0.5], [2.0, 0.5, 0.5]);
    let s = scene_of(vec![cuboid("Box", lo.map(|v| v as f32), hi.map(|v| v as f32))]);
    let sigma = [0.3, 0.6, 1.2];
    let albedo = [0.9, 0.7, 0.5];
    let g = 0.3;
    let le = [100.0; 3];
    let e = Emitter { center: DVec3::new(1.5, 5.0, 0.0), radius: 0.05, radiance: le };
    // 16 pixels of a 1e-9 rad field of view: 16 independent batches of one ray.
    let cam = ViewCamera::new([0.0; 3], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], 1e-9, 4, 4).unwrap();
    let img = run(&s, mat(sigma, albedo, g, 1.0), &[e], &cam, &opts(2500, 0.5, 3));
    let (mean, se) = batch(&img, 1);
    // Exit distance from x along w through the box.
    let exit = |x: DVec3, w: DVec3| {
        (0..3)
            .map(|k| {
                if w[k] > 0.0 {
                    (hi[k] - x[k]) / w[k]
                } else if w[k] < 0.0 {
                    (lo[k] - x[k]) / w[k]
                } else {
                    f64::INFINITY
                }
            })
            .fold(f64::INFINITY, f64::min)
    };
    let mut exact = [0.0; 3];
    for (sd, ws) in gauss_legendre(32, 0.0, 1.0) {
        let x = DVec3::new(1.0 + sd, 0.0, 0.0);
        let to_c = e.center - x;
        let d2 = to_c.length_squared();
        let cos_max = (1.0 - e.radius * e.radius / d2).sqrt();
        let axis = to_c.normalize();
        let nphi = 16;
        for (mu, wm) in gauss_legendre(8, cos_max, 1.0) {
            for j in 0..nphi {
                let w = around(axis, mu, 2.0 * PI * j as f64 / nphi as f64);
                let ph = hg::phase(w.x, g);
                let l = exit(x, w);
                for c in 0..3 {
                    exact[c] += ws
                        * wm
                        * (2.0 * PI / nphi as f64)
                        * sigma[c]
                        * albedo[c]
                        * (-sigma[c] * (sd + l)).exp()
                        * ph
                        * le[c];
                }
            }
        }
    }
    for c in 0..3 {
        let z = (mean[c] - exact[c]) / se[c];
        eprintln!("single c{c}: {} ± {} vs {} (z {z:.2})", mean[c], se[c], exact[c]);
        assert!(z.abs() < 4.5, "single scattering c{c}: {} vs {}", mean[c], exact[c]);
    }
    assert!(img.components[0].iter().all(|v| *v == [0.0; 3]));
}

/// A wax-like ball (icosphere, ior 1.5) under a large sphere light, rendered by this module and by
/// `reference::volpath` from the same scene: totals agree within both standard errors.
#[test]
fn agrees_with_volpath() {
    let sigma_t = [4.0, 6.0, 8.0];
    let albedo = [0.8, 0.6, 0.9];
    let g = 0.3;
    let mut s = empty("translucent_vs_volpath.usda");
    s.materials.push(crate::scene::Material {
        name: "Glass".into(),
        base_color: [1.0; 3],
        emission: [0.0; 3],
        surface: Surface::Dielectric { ior: 1.5 },
        roughness: 0.0,
    });
    let mut ball = icosphere("Ball", [0.0; 3], 0.5, 3);
    ball.material = Some(0);
    ball.medium = Some(0);
    s.meshes.push(ball);
    s.media.push(Medium {
        name: "Wax".into(),
        sigma_s: [0, 1, 2].map(|c| albedo[c] * sigma_t[c]),
        sigma_a: [0, 1, 2].map(|c| (1.0 - albedo[c]) * sigma_t[c]),
        g: [g; 3],
        density: Density::Homogeneous,
        boundary: Boundary::Mesh(0),
    });
    s.lights.push(Light {
        name: "Ball light".into(),
        kind: LightKind::Sphere { center: [0.0, 3.0, 1.0], radius: 1.0 },
        radiance: [1.0, 2.0, 3.0],
    });
    let bvh = SceneBvh::build(&s);
    let (object, ior) = crate::render::dielectric::find_object(&s, &bvh).unwrap();
    let md = &s.media[0];
    let m = Material {
        sigma_t: [0, 1, 2].map(|c| md.sigma_s[c] + md.sigma_a[c]),
        albedo: [0, 1, 2].map(|c| md.sigma_s[c] / (md.sigma_s[c] + md.sigma_a[c])),
        g: md.g[0],
        ior,
    };
    let (em, skipped) = crate::render::dielectric::emitters(&s, 0.02);
    assert!(skipped.is_empty() && em.len() == 1);
    let cam = ViewCamera::new([0.0, 0.0, 3.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0], 0.1, 3, 1).unwrap();
    let setup = Setup { scene: &s, bvh: &bvh, object, material: m, emitters: &em };
    let img = render(&setup, &cam, &opts(40_000, 0.5, 4), &|_| {});
    let rays: Vec<CameraRay> = (0..3)
        .map(|x| CameraRay { origin: cam.position.to_array(), direction: cam.pixel_dir(x, 0).to_array() })
        .collect();
    let vo = VolPathOptions {
        samples: 40_000,
        max_depth: 1000,
        rr_depth: 8,
        seed: 5,
        surface_bounces: u32::MAX,
        eye_surfaces: true,
        media: true,
    };
    let (est, stats) = volpath::radiance(&s, &bvh, &rays, &vo);
    assert_eq!(stats.nonfinite, 0);
    let total = img.total();
    for (x, tx) in total.iter().enumerate() {
        assert!(img.object[x]);
        for (c, &tc) in tx.iter().enumerate() {
            let se = (img.variance[x][c] + est[x].stderr[c].powi(2)).sqrt();
            let z = (tc - est[x].mean[c]) / se;
            eprintln!(
                "pixel {x} c{c}: {} ± {} vs volpath {} ± {} (z {z:.2})",
                total[x][c],
                img.variance[x][c].sqrt(),
                est[x].mean[c],
                est[x].stderr[c]
            );
            assert!(z.abs() < 4.5);
        }
    }
}

/// A refractive scattering cube lit by a small emitter: guided and unguided (HG only) estimates
/// agree, and guiding has a clearly smaller variance.
#[test]
fn guiding_is_unbiased_and_reduces_variance() {
    let s = scene_of(vec![cuboid("Cube", [-0.25; 3], [0.25; 3])]);
    let m = mat([8.0; 3], [0.9, 0.8, 0.7], 0.3, 1.5);
    let em = [Emitter { center: DVec3::new(0.3, 1.5, 0.4), radius: 0.2, radiance: [10.0; 3] }];
    let cam = cam1([0.0, 0.0, 2.0], [0.0, 0.0, -1.0]);
    let guided = run(&s, m, &em, &cam, &opts(6000, 0.5, 6));
    let plain = run(&s, m, &em, &cam, &opts(6000, 0.0, 7));
    let (a, b) = (guided.total()[0], plain.total()[0]);
    let mut ratio = [0.0; 3];
    for c in 0..3 {
        let (va, vb) = (guided.variance[0][c], plain.variance[0][c]);
        let z = (a[c] - b[c]) / (va + vb).sqrt();
        ratio[c] = vb / va;
        eprintln!(
            "guided {} ± {} vs HG {} ± {} (z {z:.2}), variance ratio {:.1}",
            a[c],
            va.sqrt(),
            b[c],
            vb.sqrt(),
            ratio[c]
        );
        assert!(z.abs() < 4.5);
        assert!(ratio[c] > 2.0, "variance ratio {}", ratio[c]);
    }
}

fn all_finite(img: &ReferenceImage) -> bool {
    img.components.iter().flatten().chain(&img.variance).flatten().all(|v| v.is_finite() && *v >= 0.0)
}

/// A cube (mesh 0) on a grey floor (mesh 1, albedo 0.5).
fn cube_on_floor() -> Scene {
    let mut floor = cuboid("Floor", [-2.0, -0.4, -2.0], [2.0, -0.3, 2.0]);
    floor.material = Some(0);
    let mut s = scene_of(vec![cuboid("Cube", [-0.25; 3], [0.25; 3]), floor]);
    s.materials.push(crate::scene::Material {
        name: "Grey".into(),
        base_color: [0.5; 3],
        emission: [0.0; 3],
        surface: Surface::Opaque,
        roughness: 1.0,
    });
    s
}

/// Extreme materials and geometry: finite, non-negative values, no dropped paths.
#[test]
fn extremes_stay_finite() {
    let s = cube_on_floor();
    let em = [Emitter { center: DVec3::new(0.3, 1.5, 0.4), radius: 0.2, radiance: [10.0; 3] }];
    let inner = [Emitter { center: DVec3::new(0.05, 0.0, 0.0), radius: 0.05, radiance: [10.0; 3] }];
    let cam = ViewCamera::new([0.0, 0.0, 2.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0], 0.4, 3, 2).unwrap();
    let grazing = cam1([-1.0, 0.25, 2.0], [0.0, 0.0, -1.0]);
    let inside = ViewCamera::new([0.0, 0.05, 0.1], [0.3, 0.1, -1.0], [0.0, 1.0, 0.0], 1.0, 2, 2).unwrap();
    let o = ReferenceOptions { samples: 8, max_events: 200, guide: 0.5, seed: 8 };
    let base = mat([8.0; 3], [0.9; 3], 0.3, 1.5);
    let cases: Vec<(&str, Material, &[Emitter], &ViewCamera)> = vec![
        ("albedo 0", Material { albedo: [0.0; 3], ..base }, &em, &cam),
        ("albedo 1", Material { albedo: [1.0; 3], ..base }, &em, &cam),
        ("g 0", Material { g: 0.0, ..base }, &em, &cam),
        ("g 0.99", Material { g: 0.99, ..base }, &em, &cam),
        ("g -0.99", Material { g: -0.99, ..base }, &em, &cam),
        ("sigma 1e-6", Material { sigma_t: [1e-6; 3], ..base }, &em, &cam),
        ("sigma 1e6", Material { sigma_t: [1e6, 1e6, 1.0], albedo: [1.0; 3], ..base }, &em, &cam),
        ("grazing", base, &em, &grazing),
        ("camera inside", base, &em, &inside),
        ("emitter inside", base, &inner, &cam),
        ("emitter inside, camera inside", base, &inner, &inside),
        ("no emitters", base, &[], &cam),
        ("index matched", Material { ior: 1.0, ..base }, &em, &cam),
    ];
    for (what, m, e, c) in cases {
        let img = run(&s, m, e, c, &o);
        let t = img.total();
        eprintln!("{what}: {:?}", t);
        assert!(all_finite(&img) && img.nonfinite == 0, "{what}");
        if e.is_empty() {
            assert!(t.iter().flatten().all(|&v| v == 0.0));
        }
    }
    // The inside camera sees the inner emitter (attenuated) and the emitter outside lights the inside.
    let img = run(&s, base, &inner, &inside, &o);
    assert!(img.total().iter().any(|v| v[0] > 0.0));
    // Invalid inputs: a NaN camera and a bad material give zeros, counted.
    let mut bad = cam;
    bad.forward = DVec3::NAN;
    let img = run(&s, base, &em, &bad, &o);
    assert_eq!(img.nonfinite, 6 * 8);
    assert!(img.total().iter().flatten().all(|&v| v == 0.0));
    let img = run(&s, Material { sigma_t: [f64::NAN; 3], ..base }, &em, &cam, &o);
    assert_eq!((img.paths, img.nonfinite), (0, 6 * 8));
    let img = run(&s, base, &em, &cam, &ReferenceOptions { guide: f64::NAN, ..o });
    assert!(all_finite(&img));
}

#[test]
fn bit_identical_for_any_thread_count() {
    let s = cube_on_floor();
    let em = [Emitter { center: DVec3::new(0.3, 1.5, 0.4), radius: 0.2, radiance: [10.0; 3] }];
    let cam = ViewCamera::new([0.0, 0.3, 2.0], [0.0, -0.1, -1.0], [0.0, 1.0, 0.0], 0.5, 4, 3).unwrap();
    let m = mat([8.0, 10.0, 12.0], [0.9, 0.8, 0.95], 0.3, 1.5);
    let bits = |threads: usize| {
        let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
        let img = pool.install(|| run(&s, m, &em, &cam, &opts(24, 0.5, 9)));
        assert!(img.total().iter().any(|v| v[0] > 0.0));
        let mut v: Vec<u64> =
            img.components.iter().flatten().chain(&img.variance).flatten().map(|x| x.to_bits()).collect();
        v.extend(img.object.iter().map(|&b| u64::from(b)));
        v.push(img.paths);
        v
    };
    assert_eq!(bits(1), bits(2));
}

/// Timing on the bundled scene (Wax, Oil, Skin at 0.01 m per Table 2 unit, 96×64, 64 paths per
/// pixel): paths per second and the relative standard error over the object's pixels. Slow in debug.
#[test]
#[ignore = "timing run on the bundled scene (minutes in debug)"]
fn bundled_scene_timing() {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes/translucent.gltf");
    let scene = Scene::load(&path).unwrap();
    let bvh = SceneBvh::build(&scene);
    let (object, _) = crate::render::dielectric::find_object(&scene, &bvh).unwrap();
    let (em, _) = crate::render::dielectric::emitters(&scene, 0.02);
    let cam = ViewCamera::from_scene(&scene.cameras[0], 96, 64).unwrap();
    let spp: u32 = std::env::var("VOLTAB_REF_SPP").ok().and_then(|v| v.parse().ok()).unwrap_or(64);
    for name in ["Wax", "Oil", "Skin"] {
        let m = Material::preset(name, 0.01, 1.5).unwrap();
        let setup = Setup { scene: &scene, bvh: &bvh, object, material: m, emitters: &em };
        let img = render(&setup, &cam, &ReferenceOptions { samples: spp, ..ReferenceOptions::default() }, &|_| {});
        let t = img.total();
        let (mut sum, mut var, mut n) = (0.0, 0.0, 0usize);
        let mut rel: Vec<f64> = Vec::new();
        for (i, ti) in t.iter().enumerate() {
            if img.object[i] {
                let l = (ti[0] + ti[1] + ti[2]) / 3.0;
                let v = (img.variance[i][0] + img.variance[i][1] + img.variance[i][2]) / 9.0;
                sum += l;
                var += v;
                n += 1;
                if l > 0.0 {
                    rel.push(v.sqrt() / l);
                }
            }
        }
        rel.sort_by(f64::total_cmp);
        let comps: Vec<f64> = (0..4)
            .map(|k| {
                img.components[k]
                    .iter()
                    .zip(&img.object)
                    .filter(|(_, o)| **o)
                    .map(|(v, _)| v[0] + v[1] + v[2])
                    .sum::<f64>()
            })
            .collect();
        eprintln!(
            "{name}: {} paths in {:.2} s = {:.0} paths/s ({:.2} us/path); object pixels {n}; aggregate rel. stderr {:.4}; median per-pixel rel. stderr {:.4}; component sums {comps:?}; nonfinite {}",
            img.paths,
            img.seconds,
            img.paths as f64 / img.seconds,
            1e6 * img.seconds / img.paths as f64,
            var.sqrt() / sum,
            rel.get(rel.len() / 2).copied().unwrap_or(f64::NAN),
            img.nonfinite
        );
    }
}
