use super::*;
use crate::physics::medium::RgbMedium;
use crate::render::gbuffer::distance_image;
use crate::render::gpu::context::test_gpu;
use crate::render::{RgbImage, rel_rmse};
use crate::scene::bvh::SceneBvh;
use crate::stages::god_rays::tests::{
    BOX, all_finite_nonneg, camera, dir_light, empty_bvh, medium, sphere_scene, spot_light,
};
use crate::stages::god_rays::{march_shadow_map, render_shadow_map};

pub(crate) struct Case {
    pub(crate) cam: ViewCamera,
    pub(crate) depth: DistanceImage,
    pub(crate) light: EpiLight,
    pub(crate) shadow: ShadowMap,
    pub(crate) medium: EpiMedium,
    pub(crate) opts: EpipolarOptions,
}

impl Case {
    pub(crate) fn new(bvh: &SceneBvh, cam: ViewCamera, light: EpiLight, medium: EpiMedium, res: usize) -> Case {
        let depth = distance_image(bvh, &cam);
        let shadow = render_shadow_map(bvh, &light, BOX, res);
        Case { cam, depth, light, shadow, medium, opts: EpipolarOptions::default() }
    }
    pub(crate) fn cpu(&self) -> EpipolarOutput {
        epipolar::render(&self.cam, &self.depth, &self.light, &self.shadow, &self.medium, &self.opts)
    }
    pub(crate) fn gpu_tuned(&self, budget: u64, block: Option<u32>) -> (EpipolarOutput, Vec<PassTime>) {
        render_chunked(
            test_gpu(),
            &self.cam,
            &self.depth,
            &self.light,
            &self.shadow,
            &self.medium,
            &self.opts,
            budget,
            block,
        )
        .unwrap()
    }
    pub(crate) fn gpu(&self) -> EpipolarOutput {
        render(test_gpu(), &self.cam, &self.depth, &self.light, &self.shadow, &self.medium, &self.opts)
            .unwrap_or_else(|e| panic!("{e}"))
            .0
    }
    fn marcher(&self, steps: usize) -> RgbImage {
        march_shadow_map(&self.cam, &self.depth, &self.light, &self.shadow, &self.medium, steps)
    }
}

/// Largest |a − b| relative to b's largest magnitude.
fn max_abs_rel(a: &RgbImage, b: &RgbImage) -> f64 {
    let scale = b.data.iter().flat_map(|p| p.iter()).fold(0.0f32, |m, &x| m.max(x.abs())).max(1e-30);
    a.data
        .iter()
        .zip(&b.data)
        .flat_map(|(x, y)| (0..3).map(move |c| f64::from((x[c] - y[c]).abs() / scale)))
        .fold(0.0, f64::max)
}

/// GPU against CPU: relative RMS of the in-scatter, largest transmittance difference.
fn compare(name: &str, case: &Case, tol: f64) -> (EpipolarOutput, EpipolarOutput) {
    let (cpu, gpu) = (case.cpu(), case.gpu());
    assert!(all_finite_nonneg(&gpu.inscatter) && all_finite_nonneg(&gpu.transmittance), "{name}: non-finite");
    let e = rel_rmse(&gpu.inscatter, &cpu.inscatter);
    let t = max_abs_rel(&gpu.transmittance, &cpu.transmittance);
    eprintln!(
        "{name}: in-scatter rel RMS {e:.2e}, transmittance max diff {t:.2e}, slices {} / {}",
        gpu.stats.slices, cpu.stats.slices
    );
    assert!(e <= tol, "{name}: GPU vs CPU in-scatter rel RMS {e}");
    assert!(t <= 1e-5, "{name}: transmittance differs by {t}");
    assert_eq!(gpu.stats.slices, cpu.stats.slices, "{name}: slice layout");
    assert_eq!(gpu.stats.samples, cpu.stats.samples, "{name}: samples");
    (cpu, gpu)
}

#[test]
fn directional_spheres_match_the_cpu_for_epipoles_on_and_off_screen() {
    let bvh = sphere_scene();
    let m = medium(0.06, 0.01, 0.6);
    // Measured: on screen 3.3e-5, behind 4.6e-6, at infinity 2.7e-3. With the epipole at infinity
    // the slices are parallel and the device's f32 slice angles and depth matches flip more
    // pixels between neighbouring slices than with a finite epipole.
    for (name, t, tol) in [
        ("on screen", [0.15, 0.1, -1.0], 2e-3),
        ("behind", [0.3, 0.9, 0.3], 2e-3),
        ("at infinity", [1.0, 0.3, 0.0], 4e-3),
    ] {
        let case = Case::new(&bvh, camera(96, 72), dir_light(t), m, 512);
        let (_, gpu) = compare(name, &case, tol);
        // And the GPU result is as close to the shadow-map marcher as the CPU test demands.
        let e = rel_rmse(&gpu.inscatter, &case.marcher(512));
        assert!(e < 0.03, "{name}: GPU vs marcher {e}");
    }
}

#[test]
fn spot_light_matches_the_cpu() {
    let bvh = sphere_scene();
    let case = Case::new(&bvh, camera(80, 60), spot_light(), medium(0.06, 0.02, 0.4), 512);
    compare("spot", &case, 2e-3);
}

#[test]
fn per_channel_sigma_and_a_textured_light_match_the_cpu() {
    let bvh = sphere_scene();
    let m = EpiMedium {
        coefficients: RgbMedium { sigma_s: [0.02, 0.05, 0.1], sigma_a: [0.01, 0.0, 0.02], g: [0.5; 3] },
        region: crate::stages::god_rays::tests::BOX,
    };
    let mut half = Image::filled(8, 8, [1.0f32, 0.6, 0.3]);
    for y in 0..8 {
        for x in 0..4 {
            half.data[y * 8 + x] = [0.0; 3];
        }
    }
    let EpiLight::Directional { direction, irradiance, .. } = dir_light([0.15, 0.1, -1.0]) else { unreachable!() };
    let plain = Case::new(&bvh, camera(64, 48), dir_light([0.15, 0.1, -1.0]), m, 256);
    compare("per-channel sigma", &plain, 2e-3);
    let light = EpiLight::Directional { direction, irradiance, texture: Some(half) };
    let textured = Case::new(&bvh, camera(64, 48), light, m, 256);
    compare("textured", &textured, 2e-3);
    // 3 channels × rank 9 = 27 lanes (a per-slice sweep would hold them all in one thread; the
    // per-lane sums have no such limit).
    let mut wide = plain;
    wide.opts.rank = 9;
    compare("rank 9", &wide, 2e-3);
}

#[test]
fn the_ring_is_marched_on_the_gpu_with_the_cpu_jitter() {
    let bvh = sphere_scene();
    let mut case = Case::new(&bvh, camera(64, 48), dir_light([0.15, 0.1, -1.0]), medium(0.06, 0.01, 0.6), 256);
    case.opts.ring_px = Some(14.0);
    case.opts.ring_steps = 16;
    let (cpu, gpu) = compare("ring", &case, 2e-3);
    assert_eq!(gpu.stats.ring_pixels, cpu.stats.ring_pixels);
    assert!(gpu.stats.ring_pixels > 500, "{}", gpu.stats.ring_pixels);
    // Only 16 jittered steps: a different jitter would differ by the stratum noise (≈ 1e-2).
    let (w, ep) = (case.cam.width, {
        let (s, _) = Setup::layout(&case.cam, &case.light, &case.opts);
        s.epipole
    });
    let mut worst = 0.0f32;
    for (i, (a, b)) in gpu.inscatter.data.iter().zip(&cpu.inscatter.data).enumerate() {
        let (x, y) = ((i % w) as f64 + 0.5, (i / w) as f64 + 0.5);
        if (x - ep[0]).hypot(y - ep[1]) < 13.0 {
            for c in 0..3 {
                worst = worst.max((a[c] - b[c]).abs() / b[c].abs().max(1e-12));
            }
        }
    }
    assert!(worst < 1e-3, "ring pixels differ by {worst}");
}

#[test]
fn chunked_integration_equals_one_chunk() {
    let bvh = sphere_scene();
    let case = Case::new(&bvh, camera(64, 48), dir_light([0.15, 0.1, -1.0]), medium(0.06, 0.01, 0.6), 256);
    let (one, _) = case.gpu_tuned(CHUNK_BUDGET, None);
    // A few slices per chunk.
    let (many, times) = case.gpu_tuned(7 * 200_000, None);
    assert!(times.iter().any(|t| t.phase == "integrate: sums" && t.passes > 10), "{times:?}");
    assert!(one.inscatter == many.inscatter && one.transmittance == many.transmittance);
}

/// The integration blocks only regroup exact integer sums, so every block size gives the same
/// bits: one sample per block (every sample from its own base), the default √S, and one block
/// per slice (every sample walks the slice's whole list of changed bins). The spheres' shadows put
/// depth modes inside the slices, so the blocks have something to regroup.
#[test]
fn every_integration_block_size_gives_the_same_bits() {
    let bvh = sphere_scene();
    let case = Case::new(&bvh, camera(64, 48), dir_light([0.15, 0.1, -1.0]), medium(0.06, 0.01, 0.6), 256);
    let (default, _) = case.gpu_tuned(CHUNK_BUDGET, None);
    for block in [1, 7, 100_000] {
        let (other, _) = case.gpu_tuned(CHUNK_BUDGET, Some(block));
        assert!(other.inscatter == default.inscatter, "block {block}");
    }
}

#[test]
fn extreme_media_sizes_and_phases_stay_finite_and_match() {
    let bvh = empty_bvh();
    // σ = 0: exactly nothing.
    let zero = Case::new(&bvh, camera(64, 48), dir_light([0.1, 0.05, -1.0]), medium(0.0, 0.0, 0.5), 32);
    let out = zero.gpu();
    assert!(out.inscatter.data.iter().all(|p| *p == [0.0; 3]));
    assert!(out.transmittance.data.iter().all(|p| *p == [1.0; 3]));
    // Very dense fog: the light would need a gain of e^{σ_t·(40 m)} behind the eye's plane, which the
    // device path refuses (the stage then runs the CPU path, which ray marches those slices).
    let dense = Case::new(&bvh, camera(64, 48), dir_light([0.1, 0.05, -1.0]), medium(2e4, 1e4, 0.5), 32);
    match render(test_gpu(), &dense.cam, &dense.depth, &dense.light, &dense.shadow, &dense.medium, &dense.opts) {
        Err(GpuError::Limit(m)) => assert!(m.contains("optically thick"), "{m}"),
        other => panic!("dense fog must be refused, got {:?}", other.map(|o| o.0.stats)),
    }
    // Optically thin fog, fog 4 mean free paths across the box, g at ±0.999 and 0.
    for (name, m, tol) in [
        ("tiny sigma", medium(1e-9, 0.0, 0.5), 2e-3),
        ("thick", medium(0.08, 0.02, 0.5), 2e-3),
        ("g 0.999", medium(0.05, 0.0, 0.999), 5e-3),
        ("g -0.999", medium(0.05, 0.0, -0.999), 2e-3),
        ("g 0", medium(0.05, 0.0, 0.0), 2e-3),
    ] {
        let case = Case::new(&bvh, camera(64, 48), dir_light([0.1, 0.05, -1.0]), m, 32);
        compare(name, &case, tol);
    }
    // Odd and degenerate raster sizes.
    let bvh = sphere_scene();
    for (w, h) in [(1, 1), (3, 97), (131, 7)] {
        let case = Case::new(&bvh, camera(w, h), dir_light([0.15, 0.1, -1.0]), medium(0.06, 0.01, 0.6), 128);
        compare(&format!("{w}×{h}"), &case, 2e-3);
    }
}
