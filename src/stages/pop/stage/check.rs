//! `PopRender`'s checks: the stage's view → POP's scattered light against independent volumetric path
//! tracing of the same view ([`PopRender::reference`]); and elek2014 Fig. 12 with the stage's preset —
//! the unit cube propagated by POP against light tracing and camera path tracing ([`FIG12_G`]).

use super::*;

impl PopRender {
    /// POP's scattered light against path tracing of the same view at `reference_width` (module doc of
    /// [`pop_scene::scattering_reference_scene`]); writes `reference_scattered.png` and
    /// `reference_pop.png` beside the stage's image.
    pub(super) fn reference(
        &self,
        id: &str,
        ctx: &StageContext,
        table: &PopPresetTable,
        media: &SceneMedia,
        dir: &Path,
        outputs: &mut Vec<std::path::PathBuf>,
    ) -> Result<Option<ReferenceComparison>, StageError> {
        if self.reference_samples == 0 {
            return Ok(None);
        }
        let fields = self.fields();
        let w = self.reference_width as usize;
        let h = ((w as f64 * self.height as f64 / self.width as f64).round() as usize).max(1);
        let v = fields.load(id, ctx, Some((w, h)))?;
        let distance: Vec<f64> = v.gbuffer.distance.data.iter().map(|&d| f64::from(d)).collect();
        let fail = |message: String| StageError::Input { stage: id.into(), message, help: "check the scene".into() };
        let cam = &v.gbuffer.camera;
        let t0 = Instant::now();
        let frame =
            render_frame(media, &v.bvh, table, cam, &distance, self.range_sigma, &crate::render::gpu::Device::Cpu)
                .map_err(fail)?;
        let pop_ms = ms(t0);
        let c =
            compare_with_reference(&v.scene, media, cam, &frame.scattered, self.reference_samples).map_err(|e| {
                StageError::Input {
                    stage: id.into(),
                    message: format!("the path-traced reference cannot judge POP: {e}"),
                    help: "aim the camera at the lit medium, or set reference_samples: 0 to skip the check".into(),
                }
            })?;
        for (name, img) in [("reference_scattered.png", &c.1), ("reference_pop.png", &frame.scattered)] {
            let png = dir.join(name);
            crate::image_io::write_png_preview(&png, w, h, &img.data, None).map_err(|e| StageError::Output {
                stage: id.into(),
                path: png.clone(),
                message: e.to_string(),
            })?;
            outputs.push(png);
        }
        Ok(Some(ReferenceComparison { ms: [pop_ms, c.0.ms[1]], ..c.0 }))
    }
}

/// Path-traces `scene`'s scattered light as POP sees it ([`pop_scene::scattering_reference_scene`]) from
/// `cam` with `samples` paths per pixel and compares `pop` with it; returns the comparison (POP time 0)
/// and the reference image, or why the reference cannot judge (it is black where compared). The
/// environment's part (when the stage has one) comes from
/// [`crate::reference::grid_mc::render_environment`] on POP's voxel medium with the scene's surfaces as
/// black occluders, and is added to the lights' part (the scattered light is linear in the sources;
/// the two estimates are independent, so their variances add).
pub fn compare_with_reference(
    scene: &Scene,
    media: &SceneMedia,
    cam: &ViewCamera,
    pop: &RgbImage,
    samples: u32,
) -> Result<(ReferenceComparison, RgbImage), String> {
    let t0 = Instant::now();
    let n = cam.width * cam.height;
    let mut mean = vec![[0.0f64; 3]; n];
    let mut variance = vec![[0.0f64; 3]; n];
    // The scene's own surfaces (occluders of the environment, and where the camera sees an emitter).
    let scene_bvh = (media.environment.is_some() || !media.vpl_sources.is_empty()).then(|| SceneBvh::build(scene));
    if !media.lights.is_empty() || !media.points.is_empty() {
        let ref_scene = pop_scene::scattering_reference_scene(scene, media);
        let bvh = SceneBvh::build(&ref_scene);
        let opts = crate::reference::volpath::VolPathOptions {
            samples,
            max_depth: 256,
            rr_depth: 4,
            seed: 0x5eed,
            surface_bounces: pop_scene::reference_bounces(media),
            eye_surfaces: false,
            media: true,
        };
        for (i, (m, se)) in view::path_trace_pixels_with(&ref_scene, &bvh, cam, &opts).into_iter().enumerate() {
            mean[i] = m.map(|v| if v.is_finite() { v } else { 0.0 });
            variance[i] = se.map(|v| if v.is_finite() { v * v } else { 0.0 });
        }
    }
    if let (Some(env), Some(bvh)) = (&media.environment, &scene_bvh) {
        let opts = crate::reference::grid_mc::CameraOptions { samples, seed: 0xe7e, max_events: 100_000 };
        let r =
            crate::reference::grid_mc::render_environment(&media.medium, &env.map, &BvhOccluder(bvh), cam, None, &opts);
        for ((m, v), (s, var)) in mean.iter_mut().zip(&r.radiance).zip(variance.iter_mut().zip(&r.variance)) {
            for c in 0..3 {
                m[c] += v[c];
                s[c] += var[c];
            }
        }
    }
    let ref_ms = ms(t0);
    // Pixels that see a VPL emitter directly hold its radiance in the reference: both images leave them out.
    let masked = match &scene_bvh {
        Some(bvh) if !media.vpl_sources.is_empty() => pop_scene::sees_vpl_emitter(scene, bvh, media, cam),
        _ => vec![false; n],
    };
    let keep = |v: [f64; 3], m: bool| if m { [0.0; 3] } else { v };
    let img = Image {
        width: cam.width,
        height: cam.height,
        data: mean.iter().zip(&masked).map(|(v, &m)| keep(*v, m).map(|x| x as f32)).collect(),
    };
    let pop_kept = Image {
        width: pop.width,
        height: pop.height,
        data: pop.data.iter().zip(&masked).map(|(v, &m)| if m { [0.0; 3] } else { *v }).collect(),
    };
    let pop = &pop_kept;
    let compared: Vec<bool> = masked.iter().map(|m| !m).collect();
    let pop_f64: Vec<[f64; 3]> = pop.data.iter().map(|p| p.map(f64::from)).collect();
    let error = NoiseCorrected::of_rgb_masked(&pop_f64, &mean, &variance, &compared)?;
    let sum = |i: &RgbImage| i.data.iter().map(|c| c.iter().map(|&v| f64::from(v)).sum::<f64>()).sum::<f64>();
    let r = sum(&img);
    let c = ReferenceComparison {
        size: [cam.width, cam.height],
        samples,
        error,
        total_ratio: if r > 0.0 { sum(pop) / r } else { 0.0 },
        ms: [0.0, ref_ms],
    };
    Ok((c, img))
}

/// The Fig. 12 settings of a preset on an `n³` cube grid (Eq. 10's switch with the cube's `σ_s`).
pub(super) fn cube_settings(table: &PopPresetTable, g: f64, n: usize) -> (Settings, FlowTable) {
    preset_settings(table, g, crate::stages::pop::fig12::SIGMA_S, 1.0 / n as f64, n)
}

/// The Fig. 12 values of `g`.
pub const FIG12_G: [f64; 3] = [0.0, 0.7, 0.96];

impl PopRender {
    /// elek2014 Fig. 12 with this stage's preset on a 16³ grid (module doc): per `g`, the mid-slice
    /// comparison, a plot of the collided radiance against the angle from the light in three cells on the
    /// slice's centre line (`fig12_g<g>_radiance.png`), and POP's and the path tracer's cube images
    /// (`fig12_g<g>_pop.png`, `fig12_g<g>_reference.png`).
    pub(super) fn fig12(
        &self,
        id: &str,
        dir: &Path,
        table: &PopPresetTable,
        outputs: &mut Vec<std::path::PathBuf>,
    ) -> Result<Vec<Fig12Row>, StageError> {
        use crate::stages::pop::fig12;
        if self.fig12_photons == 0 {
            return Ok(Vec::new());
        }
        let fail = |message: String| StageError::Input { stage: id.into(), message, help: "check the preset".into() };
        let out =
            |path: &Path, message: String| StageError::Output { stage: id.into(), path: path.to_path_buf(), message };
        let n = 16;
        let mut rows = Vec::new();
        for g in FIG12_G {
            let (settings, flow) = cube_settings(table, g, n);
            let opts =
                fig12::SliceOptions { cells: n, theta_bins: 18, photons: u64::from(self.fig12_photons), seed: 12 };
            let slice = fig12::compare_slice(g, &flow, &settings, &opts).map_err(fail)?;
            let size = self.fig12_size as usize;
            let img = fig12::compare_image(g, &flow, &settings, n, [size, size], self.fig12_samples).map_err(fail)?;
            let tag = format!("{g:.2}");
            // Radiance against θ in three cells along the light, on the slice's centre line.
            let mut series = Vec::new();
            let centre = slice
                .slice
                .iter()
                .map(|c| c.z)
                .fold(f64::NAN, |m, z| if (z - 0.5).abs() < (m - 0.5).abs() || m.is_nan() { z } else { m });
            for depth in [0.25, 0.5, 0.75] {
                let Some(cell) = slice
                    .slice
                    .iter()
                    .filter(|c| c.z == centre)
                    .min_by(|a, b| (a.x - depth).abs().total_cmp(&(b.x - depth).abs()))
                else {
                    continue;
                };
                let nb = cell.pop_bins.len();
                let theta = |b: usize| 180.0 * (b as f64 + 0.5) / nb as f64;
                let pts = |v: &[f64]| -> Vec<(f64, f64)> {
                    v.iter().enumerate().map(|(b, &r)| (theta(b), r.max(1e-6))).collect()
                };
                series.push(crate::report::plot::Series {
                    name: format!("POP x = {:.2}", cell.x),
                    points: pts(&cell.pop_bins),
                });
                series.push(crate::report::plot::Series {
                    name: format!("light tracing x = {:.2}", cell.x),
                    points: pts(&cell.mc_bins),
                });
            }
            let png = dir.join(format!("fig12_g{tag}_radiance.png"));
            let plot = crate::report::plot::Plot {
                title: &format!("elek2014 Fig. 12, g = {g}: collided radiance in the mid slice"),
                x_label: "angle from the light direction [deg]",
                y_label: "collided radiance [W/(m² sr)] per unit irradiance",
                x_scale: crate::report::plot::Scale::Linear,
                y_scale: crate::report::plot::Scale::Log10,
                series: &series,
                width: 1024,
                height: 720,
            };
            crate::report::plot::write_png(&png, &plot).map_err(|e| out(&png, e.to_string()))?;
            outputs.push(png);
            for (name, data) in [("pop", &img.pop), ("reference", &img.reference)] {
                let png = dir.join(format!("fig12_g{tag}_{name}.png"));
                let px: Vec<[f32; 3]> = data.iter().map(|c| c.map(|v| v as f32)).collect();
                crate::image_io::write_png_preview(&png, size, size, &px, None)
                    .map_err(|e| out(&png, e.to_string()))?;
                outputs.push(png);
            }
            rows.push(Fig12Row { g, slice, image: img.error, image_ms: [img.pop_ms, img.reference_ms] });
        }
        Ok(rows)
    }
}
