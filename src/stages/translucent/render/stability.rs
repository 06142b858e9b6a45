//! The renderer's formulas on extreme inputs → rows of `voltab stability` (diffuse Fresnel,
//! extrapolation distance, share floors, scene rays over g → ±1, huge and vanishing σ_t, albedo 0).

use super::*;

/// Rows of `voltab stability` for the renderer's formulas on extreme inputs.
pub fn stability_rows() -> Vec<crate::stability::Row> {
    use crate::stability::{Expect, Row};
    let mut v = Vec::new();
    let kind = "translucent";
    // Diffuse Fresnel reflectance of an ior 1.5 interface: ≈ 0.092 from outside (Egan & Hilgeman's fit
    // gives 0.0919), and 1 − (1 − F_out)/η² from inside (reciprocity).
    let f_out = diffuse_fresnel(1.0, 1.5);
    v.push(Row {
        kind,
        formula: "F_dr outside",
        input: "η = 1.5".into(),
        value: f_out,
        expect: Expect::InRange(0.090, 0.094),
    });
    v.push(Row {
        kind,
        formula: "F_dr inside",
        input: "η = 1.5".into(),
        value: diffuse_fresnel(1.5, 1.0),
        expect: Expect::Close { to: 1.0 - (1.0 - f_out) / 2.25, rel: 2e-3 },
    });
    v.push(Row {
        kind,
        formula: "F_dr index-matched",
        input: "η = 1".into(),
        value: diffuse_fresnel(1.0, 1.0),
        expect: Expect::InRange(0.0, 1e-12),
    });
    v.push(Row {
        kind,
        formula: "Fresnel grazing",
        input: "cos θ = 0".into(),
        value: fresnel(0.0, 1.0, 1.5),
        expect: Expect::Close { to: 1.0, rel: 1e-12 },
    });
    v.push(Row {
        kind,
        formula: "Fresnel TIR",
        input: "inside, cos θ = 0.1".into(),
        value: fresnel(0.1, 1.5, 1.0),
        expect: Expect::Close { to: 1.0, rel: 0.0 },
    });
    // Camera-sample weights integrate the attenuation: Σ w = (1 − e^{−σ d})/σ for the reference channel.
    for (label, sigma, d) in
        [("σd = 1e-12", 1.0, 1e-12), ("σd = 1", 1.0, 1.0), ("σd = 1e6", 1.0, 1e6), ("σ = 1e9, d = 1", 1e9, 1.0)]
    {
        let m = Material { sigma_t: [sigma; 3], albedo: [1.0; 3], g: 0.0, ior: 1.5 };
        let s = Segment {
            pixel: 0,
            entry: DVec3::ZERO,
            normal: -DVec3::Z,
            dir: DVec3::Z,
            d_max: d,
            weight: [1.0; 3],
            samples: 16,
            primary: true,
        };
        let sum: f64 = camera_samples(&s, &m).iter().map(|x| x.1[0]).sum();
        let exact = -(-sigma * d).exp_m1() / sigma;
        v.push(Row {
            kind,
            formula: "Eq. 10 weights Σw",
            input: label.into(),
            value: sum,
            expect: Expect::Close { to: exact, rel: 1e-12 },
        });
    }
    // Channels with very different σ (oil: 1 : 4.2) keep finite weights deep in the object.
    let oil = Material { sigma_t: [10.3, 8.6, 36.5], albedo: [0.0042, 0.4535, 0.0995], g: 0.9, ior: 1.5 };
    let s = Segment {
        pixel: 0,
        entry: DVec3::ZERO,
        normal: -DVec3::Z,
        dir: DVec3::Z,
        d_max: 1e3,
        weight: [1.0; 3],
        samples: 16,
        primary: true,
    };
    let deepest = camera_samples(&s, &oil).last().map_or(f64::NAN, |x| x.1[2]);
    v.push(Row {
        kind,
        formula: "Eq. 10 weight, fastest channel",
        input: "oil, d = 1e3 m".into(),
        value: deepest,
        expect: Expect::InRange(0.0, 1.0),
    });
    v.push(Row {
        kind,
        formula: "Fresnel, index-matched",
        input: "grazing, cos θ = 0".into(),
        value: fresnel(0.0, 1.3, 1.3),
        expect: Expect::Close { to: 0.0, rel: 0.0 },
    });
    let profile = EmissionProfile { ior: 1.5, f_out: diffuse_fresnel(1.0, 1.5), f_in: diffuse_fresnel(1.5, 1.0) };
    v.push(Row {
        kind,
        formula: "emission profile (reflected)",
        input: "η = 1.5, grazing".into(),
        value: profile.factors(0.0).1,
        expect: Expect::Close { to: 1.0 / profile.f_in, rel: 1e-12 },
    });
    // The grazing beams' angle: inside the total-reflection cone `F = 1`, so where the median lies in
    // it, `m = √(F_dr,in/2)`; at η = 1 + 1e-6 the cone is 1.4e-3 wide and holds all but ~1e-7 of the
    // reflected flux.
    let steep = EmissionProfile { ior: 100.0, f_out: diffuse_fresnel(1.0, 100.0), f_in: diffuse_fresnel(100.0, 1.0) };
    v.push(Row {
        kind,
        formula: "grazing-beam median cos θ",
        input: "η = 100".into(),
        value: steep.grazing_median(),
        expect: Expect::Close { to: (steep.f_in / 2.0).sqrt(), rel: 1e-3 },
    });
    let eta = 1.0 + 1e-6;
    let thin = EmissionProfile { ior: eta, f_out: diffuse_fresnel(1.0, eta), f_in: diffuse_fresnel(eta, 1.0) };
    v.push(Row {
        kind,
        formula: "grazing-beam median cos θ",
        input: "η = 1 + 1e-6".into(),
        value: thin.grazing_median(),
        expect: Expect::InRange(0.0, (1.0 - 1.0 / (eta * eta)).sqrt()),
    });
    let stiff = Material { sigma_t: [1e-6, 1.0, 1e9], albedo: [1.0, 1.0, 0.0], g: 0.99, ior: 1.5 };
    v.push(Row {
        kind,
        formula: "z_b = 2/(3σ_t(1 − αg))",
        input: "σ_t = 1e-6, α = 1, g = 0.99".into(),
        value: extrapolation_distance(&stiff)[0],
        expect: Expect::Close { to: 2.0 / (3.0 * 1e-6 * 0.01), rel: 1e-9 },
    });
    v.push(Row {
        kind,
        formula: "solid angle",
        input: "inside the ball".into(),
        value: solid_angle(1.0, 0.0),
        expect: Expect::Close { to: 2.0 * PI, rel: 0.0 },
    });
    v.push(Row {
        kind,
        formula: "solid angle",
        input: "r/d = 1e-9".into(),
        value: solid_angle(1e-9, 1.0),
        expect: Expect::Close { to: PI * 1e-18, rel: 1e-6 },
    });
    v.extend(super::super::object_light::stability_rows());
    v.extend(scene_ray_rows());
    v
}

/// Scene rays ([`Tracer::scene_first`]) on the ball over a lit ground: strongly forward and backward
/// scattering, an optically huge and a vanishing medium, a camera sample on the boundary, and albedo 0.
/// Each value lies in `[0, σ_s η² L_max]`, `L_max` the brightest ground radiance (below the lamp).
fn scene_ray_rows() -> Vec<crate::stability::Row> {
    use crate::stability::{Expect, Row};
    let scene = super::super::object_light::ball_over_ground(0.05);
    let bvh = crate::scene::bvh::SceneBvh::build(&scene);
    let (r, i) = (0.005, 1.0);
    let lamp = [crate::render::dielectric::Emitter {
        center: DVec3::new(0.3, 0.8, 0.0),
        radius: r,
        radiance: [i / (PI * r * r); 3],
    }];
    let l_max = 0.5 / PI * i / (0.8 * 0.8);
    let light = ObjectLight::default();
    let opts = RenderOptions { scene_rays: 64, ..RenderOptions::default() };
    let centre = DVec3::new(0.0, 0.15, 0.0);
    // (input, σ_t, albedo, g, camera sample)
    type Case = (&'static str, [f64; 3], [f64; 3], f64, DVec3);
    let cases: [Case; 5] = [
        ("g = 0.99, α = 1", [10.0; 3], [1.0; 3], 0.99, centre),
        ("g = −0.99, σ_t = 1e4 /m", [1e4; 3], [1.0; 3], -0.99, centre),
        ("g = 0, σ_t = 1e-3 /m", [1e-3; 3], [1.0; 3], 0.0, centre),
        ("g = 0.9, on the boundary", [10.0; 3], [1.0; 3], 0.9, DVec3::new(0.0, 0.05, 0.0)),
        ("albedo 0", [10.0; 3], [0.0; 3], 0.7, centre),
    ];
    let mut v = Vec::new();
    for (input, sigma_t, albedo, g, p) in cases {
        let material = Material { sigma_t, albedo, g, ior: 1.5 };
        let setup = Setup { scene: &scene, bvh: &bvh, object: 0, material, emitters: &lamp };
        let tracer = Tracer { setup: &setup, opts: &opts, light: &light };
        let f = tracer.scene_first(p, DVec3::Y, StreamKey { table: 1, cell: 2 }, 0);
        let bound = albedo[0] * sigma_t[0] * 1.5 * 1.5 * l_max;
        let expect = if bound > 0.0 { Expect::InRange(0.0, bound) } else { Expect::Close { to: 0.0, rel: 0.0 } };
        v.push(Row {
            kind: "translucent",
            formula: "scene rays (first scattering)",
            input: input.into(),
            value: f[0],
            expect,
        });
    }
    v
}
