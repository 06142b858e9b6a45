use super::*;
use crate::physics::medium::RgbMedium;
use crate::render::gpu::context::test_gpu;
use crate::scene::Scene;
use crate::scene::bvh::SceneBvh;
use image_fog::FogComponent;

/// Largest |a − b| / max(|b|, floor) over all channels.
fn max_rel(a: &[[f32; 3]], b: &[[f32; 3]], floor: f32) -> f64 {
    assert_eq!(a.len(), b.len());
    a.iter()
        .zip(b)
        .flat_map(|(x, y)| (0..3).map(move |c| ((x[c] - y[c]).abs() / y[c].abs().max(floor)) as f64))
        .fold(0.0, f64::max)
}

// The integrals in f32 on the device against f64-then-rounded on the CPU: e^{−τ} carries τ's
// absolute error, which grows with τ and, for height fog, with b·D times the f32 error of the
// ray's height cosine μ. Worst measured: 7.6e-6 for L_at and 7.8e-6 for the spread (the tilted
// height axis), 1.8e-7 for the image's relative RMSE (the outdoor frame); tolerances 5e-5, 5e-5
// and 1e-6. Each test prints its measured values.
const TOL_ATT: f64 = 5e-5;
const TOL_SPREAD: f64 = 5e-5;
const TOL_IMAGE: f64 = 1e-6;

/// (max relative error of L_at over channels, floor 1e-6 of the peak; max relative error of the
/// spread, floor 1e-3 px), GPU against CPU.
fn prepared_errors(gpu: &FogOutput, cpu: &FogOutput) -> (f64, f64) {
    assert!(finite(&gpu.attenuated) && gpu.spread.data.iter().all(|w| w.is_finite() && *w >= 0.0));
    let peak = cpu.attenuated.data.iter().flat_map(|p| p.iter()).fold(0.0f32, |m, &c| m.max(c));
    let e_att = max_rel(&gpu.attenuated.data, &cpu.attenuated.data, 1e-6 * peak.max(1e-30));
    let e_w = gpu
        .spread
        .data
        .iter()
        .zip(&cpu.spread.data)
        .map(|(&g, &c)| if g == c { 0.0 } else { ((g - c).abs() / c.abs().max(1e-3)) as f64 })
        .fold(0.0, f64::max);
    (e_att, e_w)
}

fn max_abs(a: &[f32], b: &[f32]) -> f64 {
    a.iter().zip(b).map(|(x, y)| (x - y).abs() as f64).fold(0.0, f64::max)
}

fn finite(img: &RgbImage) -> bool {
    img.data.iter().all(|p| p.iter().all(|c| c.is_finite()))
}

/// A deterministic image with structure at every scale and a few very bright pixels.
fn synthetic(w: usize, h: usize) -> (RgbImage, Image<f32>) {
    let mut img = Image::filled(w, h, [0.0f32; 3]);
    let mut spread = Image::filled(w, h, 0.0f32);
    for y in 0..h {
        for x in 0..w {
            let (u, v) = (x as f32 / w as f32, y as f32 / h as f32);
            let a = 1.0 + 0.5 * (17.0 * u).sin() * (11.0 * v).cos();
            let bright = if (x * 7 + y * 13) % 97 == 0 { 300.0 } else { 0.0 };
            img.data[y * w + x] = [a + bright, 0.8 * a + 0.2 * u, 1.2 - 0.3 * v + bright];
            spread.data[y * w + x] = if bright > 0.0 { 0.7 } else { 0.3 + 9.0 * u * v + 3.0 * (5.0 * u).sin().abs() };
        }
    }
    (img, spread)
}

/// GPU filter vs CPU filter: (max relative error of L'_sc, max level difference).
fn compare_filter(img: &RgbImage, spread: &Image<f32>, opts: &FogOptions) -> (f64, f64) {
    let (cpu, _, _) = filter::filter(img, spread, opts);
    let (gpu, times) = super::filter(test_gpu(), img, spread, opts).unwrap();
    assert!(times.iter().any(|t| t.phase == "fetch"));
    assert!(finite(&gpu.image));
    let peak = cpu.image.data.iter().flat_map(|p| p.iter()).fold(0.0f32, |m, &c| m.max(c.abs()));
    (max_rel(&gpu.image.data, &cpu.image.data, 1e-3 * peak.max(1e-30)), max_abs(&gpu.level.data, &cpu.level.data))
}

#[test]
fn outdoor_frame_matches_the_cpu_per_output_and_per_level() {
    // The stage's frame (pipelines/default.ron: outdoor_fog, camera 0, colour_samples 8), at
    // 480×270 instead of 1280×720 to keep the debug-build path tracing of the colour buffer short.
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes/outdoor.gltf");
    let scene = Scene::load(&path).unwrap();
    let bvh = SceneBvh::build(&scene);
    let cam = crate::render::ViewCamera::from_scene(&scene.cameras[0], 480, 270).unwrap();
    let g = crate::render::gbuffer::render(
        &scene,
        &bvh,
        &cam,
        &crate::render::gbuffer::ColourOptions { samples: 8, bounces: 0, seed: 0 },
    );
    let medium = FogMedium::from_scene(&scene).unwrap();
    let opts = FogOptions::default();
    let cpu = image_fog::render(&cam, &g.colour, &g.distance, &medium, &opts);
    let (gpu, times) = render(test_gpu(), &cam, &g.colour, &g.distance, &medium, &opts).unwrap();
    for t in &times {
        println!("outdoor 480×270 {}: {:.3} ms over {} passes", t.phase, t.seconds * 1e3, t.passes);
    }
    let rel = |a: &RgbImage, b: &RgbImage| crate::render::rel_rmse(a, b);
    let (e_img, e_sc, e_lvl) =
        (rel(&gpu.image, &cpu.image), rel(&gpu.scattered, &cpu.scattered), max_abs(&gpu.level.data, &cpu.level.data));
    println!("outdoor: rel RMSE image {e_img:.3e}, scattered {e_sc:.3e}; max level diff {e_lvl:.3e}");
    let (e_att, e_w) = prepared_errors(&gpu, &cpu);
    println!("outdoor integrals: max rel L_at {e_att:.3e}, spread {e_w:.3e}");
    assert!(e_att < TOL_ATT && e_w < TOL_SPREAD, "{e_att} {e_w}");
    // f32 on both sides, same tap order; FMA contraction and f32 (vs f64-then-rounded) B-spline
    // weights, variances and masks give ulp-level differences (measured 7.8e-8 scattered, 1.1e-8 image,
    // levels 4.8e-7): tolerances 5e-7 and 2e-6.
    assert!(e_sc < 5e-7 && e_img < 5e-7, "{e_sc} {e_img}");
    assert!(e_lvl < 2e-6, "{e_lvl}");
    assert!(finite(&gpu.image) && gpu.scattered.data.iter().any(|p| p[0] > 0.0));
    // Per level of the MIP chain, against the CPU's build_chain of the same L_sc.
    let k = filter::level_count(480, 270, &opts);
    let v = filter::level_variances(k, opts.interpolation);
    let p = image_fog::prepare(&cam, &g.colour, &g.distance, &medium);
    let cpu_chain = filter::build_chain(&p.scattered, &filter::clamp_spread(&p.spread, &v), &opts);
    let src = Level0::Host { l: &p.scattered, spread: &p.spread, attenuated: None };
    let r = run(test_gpu(), src, &opts, true).unwrap();
    let chain = r.chain.unwrap();
    assert_eq!(chain.len(), k + 1);
    for (lv, (rgb, sp)) in cpu_chain.levels.iter().zip(&chain) {
        let wh = (lv.width, lv.height);
        let er = rel(
            &Image { width: wh.0, height: wh.1, data: rgb.clone() },
            &Image { width: wh.0, height: wh.1, data: lv.rgb.clone() },
        );
        let es = rel(
            &Image { width: wh.0, height: wh.1, data: sp.clone() },
            &Image { width: wh.0, height: wh.1, data: lv.spread.clone() },
        );
        println!("level {}×{}: rel RMSE colour {er:.3e}, spread chain {es:.3e}", wh.0, wh.1);
        // Each level adds one 16-tap f32 sum (FMA vs separate rounding) and an f32 mask; the error grows
        // with the level (measured 0 up to 4×3, 3.3e-8 at 2×2, 2.0e-6 at 1×1): ≤ 1e-5.
        assert!(er < 1e-5 && es < 1e-5, "level {wh:?}: {er} {es}");
    }
}

#[test]
fn odd_sizes_and_option_variants_match_the_cpu() {
    let mut worst = (0.0f64, 0.0f64);
    for (w, h) in [(1, 1), (3, 5), (333, 77), (2, 1), (1, 40)] {
        let (img, spread) = synthetic(w, h);
        for opts in [
            FogOptions::default(),
            FogOptions { masking: false, blur_level: false, ..FogOptions::default() },
            FogOptions { level_rule: LevelRule::Paper, spread_chain: SpreadChain::Gaussian, ..FogOptions::default() },
            FogOptions { levels: Some(2), mask_epsilon: 0.0, ..FogOptions::default() },
        ] {
            let (e, l) = compare_filter(&img, &spread, &opts);
            println!(
                "{w}×{h} {:?}/{:?} masking {}: max rel {e:.3e}, level {l:.3e}",
                opts.level_rule, opts.spread_chain, opts.masking
            );
            worst = (worst.0.max(e), worst.1.max(l));
        }
    }
    println!("odd sizes: worst max relative error {:.3e}, worst level difference {:.3e}", worst.0, worst.1);
    // Per pixel (relative to max(|cpu|, 1e-3 · peak)): f32 ulp differences amplified by the
    // bright pixels' cancellation in blends; measured 1.6e-6 (levels 4.8e-7): tolerances 1e-5, 2e-6.
    assert!(worst.0 < 1e-5 && worst.1 < 2e-6, "{worst:?}");
}

#[test]
fn constant_stays_constant_and_zero_stays_zero() {
    let (w, h) = (50, 31);
    let img = Image::filled(w, h, [2.0f32, 1.0, 0.5]);
    let ramp =
        Image { width: w, height: h, data: (0..w * h).map(|i| 0.4 * (i % w) as f32 + 0.1 * (i / w) as f32).collect() };
    let (f, _) =
        super::filter(test_gpu(), &img, &ramp, &FogOptions { masking: false, ..FogOptions::default() }).unwrap();
    for p in &f.image.data {
        for c in 0..3 {
            // Taps sum to 1 in f32 (≈ 1 ± 6e-8 per level): ≤ 2e-6 relative, as on the CPU.
            assert!((p[c] - img.data[0][c]).abs() < 2e-6 * img.data[0][c], "{p:?}");
        }
    }
    let zero = Image::filled(37, 23, [0.0f32; 3]);
    let (f, _) = super::filter(test_gpu(), &zero, &Image::filled(37, 23, 4.0f32), &FogOptions::default()).unwrap();
    assert!(f.image.data.iter().all(|p| *p == [0.0; 3]));
    // Zero spread: level 0 is the input, bit for bit.
    let (img2, _) = synthetic(37, 23);
    let (f, _) = super::filter(test_gpu(), &img2, &Image::filled(37, 23, 0.0f32), &FogOptions::default()).unwrap();
    assert_eq!(f.image, img2);
    assert!(f.level.data.iter().all(|&l| l == 0.0));
}

#[test]
fn a_frame_beyond_one_dispatch_dimension_matches_the_cpu() {
    // 2600×1700 = 4.42 M pixels > 65535·64 = 4.19 M: the fetch and compose passes fold their
    // dispatch into 2-D (wid.y > 0), and level 1 (1300×850) needs only one row.
    let (w, h) = (2600, 1700);
    assert!(w * h > 65535 * 64);
    let (img, spread) = synthetic(w, h);
    let (e, l) = compare_filter(&img, &spread, &FogOptions::default());
    println!("2600×1700: max rel {e:.3e}, level {l:.3e}");
    // Measured 1.1e-6 (levels 7.2e-7), same f32 ulp argument as the odd sizes.
    assert!(e < 1e-5 && l < 2e-6, "{e} {l}");
}

#[test]
fn extreme_inputs_stay_finite_and_match_the_cpu() {
    // The CPU suite's spreads beyond the last level (1e30, ∞, NaN), with levels = 3.
    let (w, h) = (40, 30);
    let (img, _) = synthetic(w, h);
    let mut spread = Image::filled(w, h, 1e30f32);
    spread.data[7] = f32::INFINITY;
    spread.data[8] = f32::NAN;
    let opts = FogOptions { levels: Some(3), ..FogOptions::default() };
    let (e, l) = compare_filter(&img, &spread, &opts);
    // Every pixel reads level 3 (pixel 8: level 0) on both sides; colours agree to f32 ulps.
    assert!(e < 1e-5 && l == 0.0, "{e} {l}");
    // Camera inside dense fog (σ_s = 40, with and without absorption), sky and D = 0 pixels,
    // grazing rays of an exponential fog, and σ = 0: render GPU vs CPU, finite.
    let cam = ViewCamera::new([0.0, 1.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0], 0.9, 48, 32).unwrap();
    let (img, _) = synthetic(48, 32);
    let mut dist = Image { width: 48, height: 32, data: (0..48 * 32).map(|i| 1.0 + (i % 13) as f32).collect() };
    dist.data[3] = f32::INFINITY;
    dist.data[4] = 0.0;
    dist.data[5] = f32::NAN;
    let homog =
        |s: f64, a: f64| FogComponent { coefficients: RgbMedium::grey(s, a, 0.7), density: Density::Homogeneous };
    let grazing = FogComponent {
        coefficients: RgbMedium { sigma_s: [0.02, 0.022, 0.025], sigma_a: [0.001; 3], g: [0.5; 3] },
        density: Density::ExponentialHeight {
            rho: 0.8,
            falloff: 0.05,
            direction: [0.0, 1.0, 0.0],
            offset: [0.0, 1.0, 0.0],
        },
    };
    for m in [vec![homog(40.0, 0.0)], vec![homog(40.0, 5.0)], vec![homog(0.0, 0.0)], vec![grazing]] {
        let medium = FogMedium { components: m };
        let cpu = image_fog::render(&cam, &img, &dist, &medium, &FogOptions::default());
        let (gpu, _) = render(test_gpu(), &cam, &img, &dist, &medium, &FogOptions::default()).unwrap();
        assert!(finite(&gpu.image) && finite(&gpu.scattered));
        let e = crate::render::rel_rmse(&gpu.image, &cpu.image);
        let (e_att, e_w) = prepared_errors(&gpu, &cpu);
        println!("extreme medium: rel RMSE {e:.3e}, max rel L_at {e_att:.3e}, spread {e_w:.3e}");
        assert!(e < TOL_IMAGE && e_att < TOL_ATT && e_w < TOL_SPREAD, "{e} {e_att} {e_w}");
    }
    // No scattering: L' = L_at + L_sc at level 0.
    let medium = FogMedium { components: vec![homog(1.0, 0.1)] };
    let o = FogOptions { scattering: false, ..FogOptions::default() };
    let cpu = image_fog::render(&cam, &img, &dist, &medium, &o);
    let (gpu, _) = render(test_gpu(), &cam, &img, &dist, &medium, &o).unwrap();
    let e = crate::render::rel_rmse(&gpu.image, &cpu.image);
    println!("no scattering: rel RMSE {e:.3e}");
    assert!(e < TOL_IMAGE && gpu.level.data.iter().all(|&l| l == 0.0), "{e}");
}

/// The integrals pass on the CPU suite's stiff media: a density integral beyond f32 (e^300, the
/// log-space branch and a saturated P), a falloff of 1e-12 (the homogeneous limit), a zero
/// falloff (P = ρ'D), ρ' = 0 and a degenerate height axis (P = 0), a camera 10⁶ m from the
/// origin (h₀ formed on the host), and the last five summed; distances from 0 to 10⁴ m, ∞ and NaN,
/// with rays across the horizon (μ → 0).
#[test]
fn stiff_fog_integrals_stay_finite_and_match_the_cpu() {
    let (w, h) = (48, 32);
    let (img, _) = synthetic(w, h);
    let mut dist = Image { width: w, height: h, data: (0..w * h).map(|i| 10f32.powi((i % 5) as i32)).collect() };
    dist.data[1] = f32::INFINITY;
    dist.data[2] = 0.0;
    dist.data[3] = f32::NAN;
    for i in (7..w * h).step_by(11) {
        dist.data[i] = f32::INFINITY;
    }
    let height = |rho: f64, falloff: f64, direction: [f64; 3], offset: [f64; 3]| FogComponent {
        coefficients: RgbMedium { sigma_s: [0.02, 0.022, 0.025], sigma_a: [0.001; 3], g: [0.5; 3] },
        density: Density::ExponentialHeight { rho, falloff, direction, offset },
    };
    let up = [0.0, 1.0, 0.0];
    let stiff = [
        ("e^300 at the eye", height(1.0, 1.0, up, [0.0, 301.7, 0.0])),
        ("falloff 1e-12", height(0.8, 1e-12, up, [0.0; 3])),
        ("zero falloff", height(0.5, 0.0, up, [0.0; 3])),
        ("rho 0", height(0.0, 0.05, up, [0.0; 3])),
        ("degenerate axis", height(0.8, 0.05, [0.0; 3], [0.0; 3])),
        ("tilted axis", height(0.8, 0.05, [0.3, 1.0, 0.2], [5.0, -2.0, 1.0])),
    ];
    // Summed without the first, which alone blacks out every pixel.
    let all: Vec<FogComponent> = stiff.iter().skip(1).map(|(_, c)| c.clone()).collect();
    let cases = stiff.iter().map(|(n, c)| (*n, vec![c.clone()])).chain([("all summed", all)]);
    for (name, components) in cases {
        for eye in [[0.0, 1.7, 0.0], [1e6, 1.7, -1e6]] {
            let cam = ViewCamera::new(eye, [0.0, 0.05, -1.0], up, 0.9, w, h).unwrap();
            let medium = FogMedium { components: components.clone() };
            let cpu = image_fog::render(&cam, &img, &dist, &medium, &FogOptions::default());
            let (gpu, _) = render(test_gpu(), &cam, &img, &dist, &medium, &FogOptions::default()).unwrap();
            assert!(finite(&gpu.image) && finite(&gpu.scattered), "{name}");
            let e = crate::render::rel_rmse(&gpu.image, &cpu.image);
            let (e_att, e_w) = prepared_errors(&gpu, &cpu);
            println!("{name}, eye {eye:?}: rel RMSE {e:.3e}, max rel L_at {e_att:.3e}, spread {e_w:.3e}");
            assert!(e < TOL_IMAGE && e_att < TOL_ATT && e_w < TOL_SPREAD, "{name}: {e} {e_att} {e_w}");
        }
    }
}

#[test]
fn an_all_sky_frame_matches_the_cpu() {
    // Every pixel D = ∞ in the outdoor scene's height fog (finite P upward, +∞ at and below the
    // horizon): the camera looks across the horizon, so both kinds of sky pixel occur.
    let cam = ViewCamera::new([0.0, 1.7, 0.0], [0.0, 0.1, -1.0], [0.0, 1.0, 0.0], 0.8, 64, 40).unwrap();
    let (img, _) = synthetic(64, 40);
    let dist = Image::filled(64, 40, f32::INFINITY);
    let medium = FogMedium {
        components: vec![FogComponent {
            coefficients: RgbMedium { sigma_s: [0.02, 0.022, 0.025], sigma_a: [0.001; 3], g: [0.5; 3] },
            density: Density::ExponentialHeight {
                rho: 0.8,
                falloff: 0.05,
                direction: [0.0, 1.0, 0.0],
                offset: [0.0; 3],
            },
        }],
    };
    let cpu = image_fog::render(&cam, &img, &dist, &medium, &FogOptions::default());
    let (gpu, _) = render(test_gpu(), &cam, &img, &dist, &medium, &FogOptions::default()).unwrap();
    assert!(finite(&gpu.image) && finite(&gpu.scattered));
    assert!(cpu.attenuated.data.iter().any(|p| p[0] == 0.0) && cpu.attenuated.data.iter().any(|p| p[0] > 0.0));
    let e = crate::render::rel_rmse(&gpu.image, &cpu.image);
    let (e_att, e_w) = prepared_errors(&gpu, &cpu);
    println!("all sky: rel RMSE {e:.3e}, max rel L_at {e_att:.3e}, spread {e_w:.3e}");
    assert!(e < TOL_IMAGE && e_att < TOL_ATT && e_w < TOL_SPREAD, "{e} {e_att} {e_w}");
}

#[test]
fn options_not_ported_are_limit_errors_naming_them() {
    let (img, spread) = synthetic(8, 8);
    let sep = FogOptions { separation: Some(Default::default()), ..FogOptions::default() };
    let near = FogOptions { interpolation: Interpolation::Nearest, ..FogOptions::default() };
    for (o, name) in [(sep, "separation"), (near, "Nearest")] {
        match super::filter(test_gpu(), &img, &spread, &o) {
            Err(GpuError::Limit(m)) => assert!(m.contains(name), "{m}"),
            other => panic!("{name}: {other:?}"),
        }
    }
}
