use super::*;

fn sample(start: DVec3, direction: DVec3, plane_point: DVec3, plane_normal: DVec3) -> VolumeSample {
    VolumeSample {
        start,
        direction,
        length: 0.5,
        flux: [1.0; 3],
        area: 1e-4,
        surface: 0,
        bounce: 0,
        depth: 0.0,
        plane_point,
        plane_normal,
        tan_entry: 0.0,
    }
}

/// The image beam of a sample is its interval mirrored about its boundary plane and moved out by
/// `2 z_b` (derived by hand: medium z > 0, outward normal −z); a node's image is the flux-weighted
/// mean of its samples' images even when their planes differ.
#[test]
fn image_beams_mirror_about_each_samples_plane() {
    let sigma = [0.0; 3]; // no attenuation: start and end carry the same weight
    let d = DVec3::new(0.6, 0.0, 0.8);
    let a = VolAgg::of_sample(&sample(DVec3::new(0.0, 0.0, 0.5), d, DVec3::ZERO, -DVec3::Z), sigma);
    let (s, e, dir) = a.image(0.25);
    assert!((s - DVec3::new(0.0, 0.0, -1.0)).length() < 1e-12, "{s}");
    assert!((e - DVec3::new(0.3, 0.0, -1.4)).length() < 1e-12, "{e}");
    assert!((dir - DVec3::new(0.6, 0.0, -0.8)).length() < 1e-12, "{dir}");
    // A second sample under the plane x = 1 (outward +x), starting 0.2 inside it, along −x.
    let b = VolAgg::of_sample(&sample(DVec3::new(0.8, 0.0, 2.0), -DVec3::X, DVec3::X, DVec3::X), sigma);
    let (s2, ..) = b.image(0.25);
    assert!((s2 - DVec3::new(1.7, 0.0, 2.0)).length() < 1e-12, "{s2}");
    let (sm, ..) = VolAgg::merge(&[a, b]).image(0.25);
    assert!((sm - 0.5 * (s + s2)).length() < 1e-12, "{sm}");
}

/// The median of the internally reflected flux lies inside the total-reflection cone at η = 1.5,
/// where `F = 1`, so `∫₀^m μ dμ = F_dr,in/4` gives `m = √(F_dr,in/2)`; without an interface the
/// Lambertian median `1/√2`. The grazing directions sit at that cosine and spread evenly.
#[test]
fn grazing_median_and_directions() {
    let f_in = diffuse_fresnel(1.5, 1.0);
    let p = EmissionProfile { ior: 1.5, f_out: diffuse_fresnel(1.0, 1.5), f_in };
    let m = p.grazing_median();
    assert!(m < (1.0f64 - 1.0 / 2.25).sqrt());
    assert!((m - (f_in / 2.0).sqrt()).abs() < 1e-4, "{m} vs {}", (f_in / 2.0).sqrt());
    let matched = EmissionProfile { ior: 1.0, f_out: 0.0, f_in: 0.0 };
    assert_eq!(matched.grazing_median(), std::f64::consts::FRAC_1_SQRT_2);
    let n = DVec3::new(0.2, -0.9, 0.4).normalize();
    let dirs: Vec<DVec3> = grazing_dirs(n, m, 4).collect();
    for d in &dirs {
        assert!((d.length() - 1.0).abs() < 1e-12 && (d.dot(n) - m).abs() < 1e-12);
    }
    let sum: DVec3 = dirs.iter().copied().sum();
    assert!((sum - n * (4.0 * m)).length() < 1e-12, "{sum}");
}

/// On a ball of radius R every chord at `cos θ = μ` from the inward normal is `2Rμ`, so a sample's
/// grazing beams end `2Rμ` away with `e^{−σ_t 2Rμ}` of their flux left; the normal beam carries the
/// refracted scene light and the grazing beams the rest of the exitance (all of it on the normal
/// beam without them).
#[test]
fn grazing_beams_follow_the_chords_of_a_ball() {
    let scene = super::super::object_light::ball_over_ground(0.05);
    let bvh = crate::scene::bvh::SceneBvh::build(&scene);
    let (c, radius) = (DVec3::new(0.0, 0.15, 0.0), 0.1);
    let material = Material { sigma_t: [5.0, 10.0, 20.0], albedo: [0.9, 0.5, 0.2], g: 0.7, ior: 1.5 };
    let setup = Setup { scene: &scene, bvh: &bvh, object: 0, material, emitters: &[] };
    let f_out = diffuse_fresnel(1.0, 1.5);
    let mu = EmissionProfile { ior: 1.5, f_out, f_in: diffuse_fresnel(1.5, 1.0) }.grazing_median();
    let ex = [3.0, 2.0, 1.0];
    for out in [DVec3::X, DVec3::new(0.3, 0.8, -0.5), DVec3::new(-0.6, -0.7, 0.2)] {
        let out = out.normalize();
        let hit = bvh.closest_hit(&Ray::new(c.to_array(), out.to_array())).unwrap();
        let s = SurfaceSample {
            position: c + out * hit.t,
            normal: DVec3::from_array(hit.geometric_normal),
            area: 1e-4,
            triangle: hit.triangle as u32,
            direct: [0.0; 3],
            indirect: [0.5, 1.0, 4.0], // (1 − F_dr,out) E: below `ex` in R and G, capped in B
        };
        let a = surface_item(&setup, &s, ex, 0.2, f_out, (4, mu));
        let len = a.graze_len / a.w;
        assert!((len - 2.0 * radius * mu).abs() < 0.01 * 2.0 * radius * mu, "{len}");
        for (ch, &e) in ex.iter().enumerate() {
            let s_ext = ((1.0 - f_out) * s.indirect[ch]).min(e);
            assert!((a.flux0[ch] - s_ext * s.area).abs() < 1e-15);
            assert!((a.flux0[ch] + a.graze0[ch] - e * s.area).abs() < 1e-15);
            let left = (-material.sigma_t[ch] * 2.0 * radius * mu).exp() * a.graze0[ch];
            assert!((a.graze1[ch] - left).abs() <= 0.01 * left, "channel {ch}");
        }
        assert_eq!(a.graze0[2], 0.0); // the scene light alone exceeds the exitance in B
        let plain = surface_item(&setup, &s, ex, 0.2, f_out, (0, mu));
        assert_eq!((plain.graze0, plain.graze_len), ([0.0; 3], 0.0));
        for (f, e) in plain.flux0.iter().zip(ex) {
            assert!((f - e * s.area).abs() < 1e-15);
        }
    }
}

/// Eq. 6 near a volume sample averages `1/r²` over its tube's disk: on the disk's axis at height
/// `h` that average is `ln(1 + a²/h²)/a²` (σ → 0, g = 0 so both phase values are `1/4π`); with
/// `double_disk: 0`, and beyond `DISK_REACH` radii, the centre's `1/h²`.
#[test]
fn double_scattering_spreads_a_sample_over_its_tube() {
    let scene = super::super::object_light::ball_over_ground(0.05);
    let bvh = crate::scene::bvh::SceneBvh::build(&scene);
    let sigma = 1e-3;
    let material = Material { sigma_t: [sigma; 3], albedo: [1.0; 3], g: 0.0, ior: 1.0 };
    let setup = Setup { scene: &scene, bvh: &bvh, object: 0, material, emitters: &[] };
    let a = 0.01;
    let mut v = sample(DVec3::ZERO, DVec3::Z, DVec3::ZERO, -DVec3::Z);
    v.length = 1e-4;
    v.area = PI * a * a;
    let items = [Item { position: v.center(), bounds: v.obb(2.0).aabb() }];
    let tree = Octree::build(&items, 8, 24);
    let vol_items = [VolAgg::of_sample(&v, material.sigma_t)];
    let agg = tree
        .bottom_up(|ids| VolAgg::merge(&ids.iter().map(|&i| vol_items[i as usize]).collect::<Vec<_>>()), VolAgg::merge);
    let lam = vol_items[0].lam[0];
    let scale = sigma * sigma * lam / (16.0 * PI * PI); // σ_s² Λ p p
    let at = |n: u32, h: f64| {
        let opts = RenderOptions { double_disk: n, clamp_mfp: 0.0, ..RenderOptions::default() };
        let eval = Evaluator::new(&setup, &[], &opts, (&tree, &agg, &vol_items));
        eval.double(v.center() + DVec3::Z * h, DVec3::X, &mut Vec::new()).0[1] / scale
    };
    let h = 0.5 * a;
    let want = (1.0 + a * a / (h * h)).ln() / (a * a);
    let got = at(4096, h);
    assert!((got - want).abs() < 2e-3 * want, "{got} vs {want}");
    assert!((at(0, h) - 1.0 / (h * h)).abs() < 1e-4 / (h * h));
    let far = 3.5 * a;
    assert!((at(4096, far) - 1.0 / (far * far)).abs() < 1e-4 / (far * far));
}

/// Both emission profiles carry exactly the exitance (`2∫ k(μ) μ dμ = 1`, midpoint rule), the
/// refracted light stays inside the critical cone, and an index-matched boundary is Lambertian.
#[test]
fn emission_profiles_conserve_the_exitance() {
    let p = EmissionProfile { ior: 1.5, f_out: diffuse_fresnel(1.0, 1.5), f_in: diffuse_fresnel(1.5, 1.0) };
    let n = 200_000;
    let (mut ext, mut int) = (0.0, 0.0);
    for i in 0..n {
        let mu = (i as f64 + 0.5) / n as f64;
        let (a, b) = p.factors(mu);
        ext += 2.0 * a * mu / n as f64;
        int += 2.0 * b * mu / n as f64;
    }
    assert!((ext - 1.0).abs() < 1e-4 && (int - 1.0).abs() < 1e-4, "{ext} {int}");
    // sin θ_c = 1/1.5: just outside the cone nothing is refracted in, everything is reflected.
    let mu_c = (1.0 - 1.0 / 2.25f64).sqrt();
    assert_eq!(p.factors(mu_c - 1e-6).0, 0.0);
    assert!((p.factors(mu_c - 1e-6).1 - 1.0 / p.f_in).abs() < 1e-12);
    // At normal incidence F = 0.04: (1 − 0.04)·2.25/(1 − F_dr,out).
    assert!((p.factors(1.0).0 - 0.96 * 2.25 / (1.0 - p.f_out)).abs() < 1e-12);
    let m = EmissionProfile { ior: 1.0, f_out: 0.0, f_in: 0.0 };
    for mu in [0.0, 0.3, 1.0] {
        assert_eq!(m.factors(mu), (1.0, 0.0));
    }
}

/// `z_b = 2/(3σ_t(1 − αg))`; the multiple-scattering floor keeps a channel at `α²/(1 − α) ≥ 0.02`.
#[test]
fn extrapolation_distance_and_multiple_floor() {
    let m = Material { sigma_t: [10.0, 10.0, 4.0], albedo: [1.0, 0.5, 0.0], g: 0.8, ior: 1.5 };
    let z = extrapolation_distance(&m);
    for (got, want) in z.iter().zip([2.0 / 6.0, 2.0 / 18.0, 2.0 / 12.0]) {
        assert!((got - want).abs() < 1e-15, "{got} vs {want}");
    }
    // Oil (wang2018 Table 2): red and blue are left out, green kept.
    assert_eq!([0.0042, 0.4535, 0.0995].map(multiple_needed), [false, true, false]);
    assert!(multiple_needed(1.0) && !multiple_needed(0.0));
    // The floor's crossing: α² = 0.02 (1 − α) at α = (−0.02 + √(0.0004 + 0.08))/2.
    let a = (-0.02 + (0.0004f64 + 0.08).sqrt()) / 2.0;
    assert!(multiple_needed(a + 1e-9) && !multiple_needed(a - 1e-9));
    // The inner irradiance drops only oil's red; its crossing α = 0.02 (1 − α) at α = 0.02/1.02.
    assert_eq!([0.0042, 0.4535, 0.0995].map(inner_needed), [false, true, true]);
    assert!(inner_needed(1.0) && !inner_needed(0.0));
    let a = 0.02 / 1.02;
    assert!(inner_needed(a + 1e-9) && !inner_needed(a - 1e-9));
}

/// Scene rays at the centre of an index-matched ball over a ground lit by a small lamp: the ground
/// seen through the ball and scattered once toward `w`, `σ_s ∫ p(ω·w) L_in(ω) dω`, against a
/// product quadrature over directions written here with analytic geometry (every straight line
/// from the centre leaves the ball after `R`; the ground's radiance is `ρ/π I cos/d²` where the ball
/// does not shadow it).
#[test]
fn scene_rays_match_quadrature_through_an_index_matched_ball() {
    let scene = super::super::object_light::ball_over_ground(0.05);
    let bvh = crate::scene::bvh::SceneBvh::build(&scene);
    let (c, radius, rho) = (DVec3::new(0.0, 0.15, 0.0), 0.1, 0.5);
    let (r, i) = (0.002, 2.0);
    let lamp_at = DVec3::new(0.5, 0.7, 0.2);
    let lamp = [crate::render::dielectric::Emitter { center: lamp_at, radius: r, radiance: [i / (PI * r * r); 3] }];
    let material = Material { sigma_t: [5.0, 10.0, 20.0], albedo: [0.9, 0.5, 0.2], g: 0.7, ior: 1.0 };
    let setup = Setup { scene: &scene, bvh: &bvh, object: 0, material, emitters: &lamp };
    let light = ObjectLight::default();
    let opts = RenderOptions { scene_rays: 4096, ..RenderOptions::default() };
    let tracer = Tracer { setup: &setup, opts: &opts, light: &light };
    let w = DVec3::new(0.3, 1.0, 0.2).normalize();
    let got = tracer.scene_first(c, w, StreamKey { table: 7, cell: 0 }, 0);

    // Does the segment a → b cross the ball (radius slightly inside the facets' vertices)?
    let blocked = |a: DVec3, b: DVec3| {
        let d = b - a;
        let t = ((c - a).dot(d) / d.length_squared()).clamp(0.0, 1.0);
        (a + d * t).distance(c) < radius
    };
    let hg = |mu: f64, g: f64| (1.0 - g * g) / (4.0 * PI * (1.0 + g * g - 2.0 * g * mu).powf(1.5));
    // Travel directions ω with ω.y > 0 (light from the ground below): Gauss–Legendre in ω.y,
    // midpoint rule in azimuth.
    let (nu, nphi) = (400, 800);
    let nodes = crate::physics::sh::gauss_legendre(nu);
    let mut want = [0.0; 3];
    for &(x, wx) in &nodes {
        let uy = 0.5 * (x + 1.0);
        let s = (1.0 - uy * uy).sqrt();
        for k in 0..nphi {
            let phi = 2.0 * PI * (k as f64 + 0.5) / nphi as f64;
            let omega = DVec3::new(s * phi.cos(), uy, s * phi.sin());
            let exit = c - omega * radius;
            let q = exit - omega * (exit.y / omega.y);
            if q.x.abs() > 1.0 || q.z.abs() > 1.0 || blocked(q, lamp_at) {
                continue;
            }
            let d = lamp_at - q;
            let l_out = rho / PI * i * (d.y / d.length()) / d.length_squared();
            let dw = 0.5 * wx * 2.0 * PI / nphi as f64;
            for (ch, x) in want.iter_mut().enumerate() {
                let l_in = l_out * (-material.sigma_t[ch] * radius).exp();
                *x += material.albedo[ch] * material.sigma_t[ch] * hg(omega.dot(w), material.g) * l_in * dw;
            }
        }
    }
    for ch in 0..3 {
        assert!((got[ch] - want[ch]).abs() < 0.01 * want[ch], "channel {ch}: {} vs {}", got[ch], want[ch]);
    }
    // Off: the surface samples carry this light instead.
    let off = RenderOptions { scene_rays: 0, ..RenderOptions::default() };
    let tracer = Tracer { setup: &setup, opts: &off, light: &light };
    assert_eq!(tracer.scene_first(c, w, StreamKey { table: 7, cell: 0 }, 0), [0.0; 3]);
}
