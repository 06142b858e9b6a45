//! `EpipolarShadows`: scene → shadowed single scattering (god rays) by baran2010's epipolar
//! rectification and partial-sum trees, as EXR + PNG, with an optional brute-force comparison.
//!
//! **Input.** A scene file (relative to the pipeline file) with a perspective camera, a directional or
//! spot light and a homogeneous global medium (it fills the scene's padded bounds; the sun is
//! attenuated from where it enters them). **Phases.** Import → BVH → G-buffer of the camera
//! ([`view`]: vacuum colour and distance, voltab's own ray tracer) → light shadow map (rasterised,
//! [`epipolar::render_shadow_map`]) → [`epipolar::render`] (rectification into epipolar slices with the
//! sinh distribution, Sec. 8; Fenwick half-tree integration of the rank-N SVD factorisation of
//! `I(γ, β)`, Secs. 4–6; depth-mode prefiltering, Sec. 7; ray marching in the disc around the epipole;
//! unrectification) → composite `colour·T + in-scatter` → `<out>/<stage>/godrays.exr` (layers
//! `inscatter`, `transmittance`, `colour`) with PNG previews, and `summary.json` (time per phase; with
//! `reference_steps > 0` the relative RMSE of the in-scatter against the BVH shadow-ray marcher with that
//! many steps per ray and both methods' times; the marcher's in-scatter is written as `marcher.exr`).

use std::path::Path;
use std::time::Instant;

use serde::{Deserialize, Serialize};

use crate::render::gbuffer::GBuffer;
use crate::report::noisy::NoiseCorrected;
use crate::scene::Scene;
use crate::stages::BenchRow;
use crate::stages::god_rays::{
    self as epipolar, EpiLight, EpiMedium, EpipolarOptions, EpipolarOutput, EpipolarStats, ShadowMap,
};
use crate::stages::image_fog::GpuPhase;
use crate::stages::view::{self, ms};
use crate::stages::{StageContext, StageError, StageOutcome};
use crate::tables::FieldIssue;

crate::declare_params! {
    /// Render shadowed single scattering (god rays) of a scene with baran2010's epipolar partial-sum trees.
    raw EpipolarShadowsRaw => resolved EpipolarShadows, kind "EpipolarShadows" {
        /// Scene file (.gltf, .glb, .usda, .usdc, .usd, .usdz), relative to the pipeline file.
        scene: String = String::new(), unit = "", range = "path to a scene file";
        /// Index of the scene camera to render.
        camera: u32 = 0, unit = "", range = "0 to the scene's camera count - 1";
        /// Image width.
        width: u32 = 1280, unit = "px", range = "1 to 8192";
        /// Image height.
        height: u32 = 960, unit = "px", range = "1 to 8192";
        /// Paths per pixel of the vacuum colour buffer (direct light at the first hit).
        colour_samples: u32 = 16, unit = "paths", range = "1 to 65536";
        /// Shadow-map side.
        shadow_map: u32 = 2048, unit = "texels", range = "16 to 16384";
        /// SVD rank N of the factorised integrand I(γ, β) (baran2010 Sec. 6).
        rank: u32 = 4, unit = "", range = "1 to 8";
        /// Light-ray bins along γ per slice (the integration grid).
        gamma_bins: u32 = 2048, unit = "bins", range = "16 to 65536";
        /// Largest number of depth modes per γ bin (Sec. 7); 1 disables prefiltering.
        depth_modes: u32 = 4, unit = "", range = "1 to 4";
        /// Slice density relative to the half-pixel bound of Sec. 8 (1: slices one pixel apart at the edge).
        slice_density: f64 = 1.0, unit = "", range = "0.05 to 8";
        /// View-ray samples per pixel along an epipolar line.
        samples_per_pixel: f64 = 1.0, unit = "", range = "0.05 to 8";
        /// Steps per ray of a BVH shadow-ray marcher to compare against, run twice with independent
        /// jitter to measure its own noise (0: no comparison).
        reference_steps: u32 = 0, unit = "steps", range = "0 to 100000";
        /// Coloured light ("cookie"): an EXR (R, G, B multipliers), relative to the pipeline file, projected
        /// along the light over the shadow map's window (directional) or through the cone (spot); empty: white.
        light_texture: String = String::new(), unit = "", range = "empty or path to an EXR file";
        /// Output folder name in the output directory; empty means the stage id.
        output: String = String::new(), unit = "", range = "plain folder name";
    }
}

/// The comparison with the brute-force marcher.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct GodRaysCheck {
    /// Steps per ray of the BVH shadow-ray marcher.
    pub steps: u32,
    /// Its time (two independent runs, averaged) \[ms\].
    pub ms: f64,
    /// The epipolar in-scatter against it (over pixels and channels, relative to its mean), the
    /// marcher's jitter noise (from its two runs) removed, with its floor.
    pub error: NoiseCorrected,
    /// One marcher run's time / epipolar time.
    pub speedup: f64,
}

/// What `summary.json` holds.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct GodRaysSummary {
    /// Scene file.
    pub scene: String,
    /// Image size.
    pub size: [usize; 2],
    /// Import, BVH, distance buffer, colour buffer, shadow map \[ms\].
    pub setup_ms: [f64; 5],
    /// Epipolar phases \[ms\]: rectify, factorise, prefilter, integrate, ring march, unrectify, total.
    pub phases_ms: [f64; 7],
    /// Epipolar slices and view samples.
    pub slices: usize,
    /// View-ray samples.
    pub samples: usize,
    /// Pixels marched around the epipole.
    pub ring_pixels: usize,
    /// Pixels marched at silhouettes no slice sample matches.
    #[serde(default)]
    pub edge_pixels: usize,
    /// Pixels marched because their slices need a light gain above `MAX_LIGHT_GAIN` or the camera is
    /// outside the fog's box.
    #[serde(default)]
    pub gain_pixels: usize,
    /// The box the fog fills (`min`, `max` corners) \[m\]; the sun is attenuated from where it enters it.
    #[serde(default)]
    pub fog_region: [[f64; 3]; 2],
    /// Relative residual of the rank-N SVD of I(γ, β).
    pub svd_residual: f64,
    /// Mean in-scattered radiance per channel \[W/(m²·sr)\].
    pub mean_inscatter: [f64; 3],
    /// Comparison with the marcher.
    pub reference: Option<GodRaysCheck>,
    /// Where the effect ran: `"cpu"` or `"gpu"` (the shadow map, slice layout and SVD always run on
    /// the CPU).
    #[serde(default)]
    pub device: String,
    /// GPU time per phase (`rectify`, `prefilter`, `integrate`, `unrectify`) when it ran on the GPU.
    #[serde(default)]
    pub gpu_phases: Vec<GpuPhase>,
    /// Why the CPU path ran although a GPU was selected (a limit of the device path).
    #[serde(default)]
    pub device_note: Option<String>,
}

crate::stages::view::impl_view_fields!(EpipolarShadows);

impl EpipolarShadows {
    /// Range checks.
    pub fn validate(&self) -> Vec<FieldIssue> {
        let mut v = self.fields().validate();
        let mut issue = |field: &'static str, message: String, help: &str| {
            v.push(FieldIssue { field, message, help: help.into() });
        };
        if !(16..=16_384).contains(&self.shadow_map) {
            issue("shadow_map", format!("shadow_map = {}", self.shadow_map), "use 16 to 16384 texels");
        }
        if !(1..=8).contains(&self.rank) {
            issue("rank", format!("rank = {}", self.rank), "use 1 to 8 (the paper uses 4)");
        }
        if !(16..=65_536).contains(&self.gamma_bins) {
            issue("gamma_bins", format!("gamma_bins = {}", self.gamma_bins), "use 16 to 65536 (the paper: 2048–4096)");
        }
        if !(1..=4).contains(&self.depth_modes) {
            issue("depth_modes", format!("depth_modes = {}", self.depth_modes), "use 1 to 4");
        }
        for (field, x) in [("slice_density", self.slice_density), ("samples_per_pixel", self.samples_per_pixel)] {
            if !(x.is_finite() && (0.05..=8.0).contains(&x)) {
                issue(field, format!("{field} = {x}"), "use 0.05 to 8");
            }
        }
        if self.reference_steps > 100_000 {
            issue("reference_steps", format!("reference_steps = {}", self.reference_steps), "use 0 to 100000");
        }
        v
    }

    /// The effect's knobs.
    pub fn options(&self) -> EpipolarOptions {
        EpipolarOptions {
            slice_density: self.slice_density,
            samples_per_pixel: self.samples_per_pixel,
            gamma_bins: self.gamma_bins as usize,
            rank: self.rank as usize,
            depth_modes: self.depth_modes as usize,
            ..EpipolarOptions::default()
        }
    }

    /// The scene's light and medium, or an error saying what the scene lacks.
    fn light_and_medium(id: &str, scene: &Scene) -> Result<(EpiLight, EpiMedium), StageError> {
        let fail = |message: String, help: &str| StageError::Input { stage: id.into(), message, help: help.into() };
        let light = EpiLight::from_scene(scene).ok_or_else(|| {
            fail(
                format!("{} has no directional or spot light", scene.source.display()),
                "add a directional (sun) or spot light to the scene",
            )
        })?;
        let medium = EpiMedium::from_scene(scene).ok_or_else(|| {
            fail(
                EpiMedium::refusal(scene),
                "give the scene a homogeneous global medium (room or atmosphere fog, density Homogeneous)",
            )
        })?;
        Ok((light, medium))
    }

    /// The light texture: finite, non-negative RGB multipliers.
    fn texture(&self, id: &str, ctx: &StageContext) -> Result<crate::render::RgbImage, StageError> {
        let fail = |message: String, help: &str| StageError::Input { stage: id.into(), message, help: help.into() };
        let path = ctx.base_dir.join(&self.light_texture);
        let img = crate::image_io::read_exr_rgb(&path).map_err(|e| {
            fail(e.to_string(), "give a readable EXR file for light_texture (relative to the pipeline file)")
        })?;
        let data = img.rgb(None).ok_or_else(|| {
            fail(format!("{} has no R, G, B channels", path.display()), "write the texture as channels R, G, B")
        })?;
        if let Some(i) = data.iter().position(|c| c.iter().any(|x| !x.is_finite() || *x < 0.0)) {
            return Err(fail(
                format!("{}: pixel ({}, {}) is {:?}", path.display(), i % img.width, i / img.width, data[i]),
                "light texture values must be finite and non-negative",
            ));
        }
        Ok(crate::render::Image { width: img.width, height: img.height, data })
    }

    /// Runs the stage.
    pub fn run(&self, id: &str, ctx: &StageContext) -> Result<StageOutcome, StageError> {
        let fields = self.fields();
        let dir = fields.out_dir(id, ctx)?;
        let v = fields.load(id, ctx, None)?;
        let (mut light, medium) = Self::light_and_medium(id, &v.scene)?;
        if !self.light_texture.is_empty() {
            let tex = self.texture(id, ctx)?;
            match &mut light {
                EpiLight::Directional { texture, .. } | EpiLight::Spot { texture, .. } => *texture = Some(tex),
            }
        }
        let bounds = v.scene.bounds().ok_or_else(|| StageError::Input {
            stage: id.into(),
            message: format!("{} has no geometry", v.scene.source.display()),
            help: "add meshes to the scene".into(),
        })?;
        let t0 = Instant::now();
        let shadow = epipolar::render_shadow_map(&v.bvh, &light, bounds, self.shadow_map as usize);
        let shadow_ms = ms(t0);
        let g = &v.gbuffer;
        let (out, device, gpu_phases, device_note) = self.render_on_device(id, ctx, g, &light, &shadow, &medium)?;
        let image = epipolar::composite(&g.colour, &out);
        let mut outputs = view::write_image(
            id,
            &dir,
            "godrays",
            &image,
            &[("inscatter", &out.inscatter), ("transmittance", &out.transmittance), ("colour", &g.colour)],
        )?;
        let png = dir.join("inscatter.png");
        crate::image_io::write_png_preview(&png, image.width, image.height, &out.inscatter.data, None)
            .map_err(|e| StageError::Output { stage: id.into(), path: png.clone(), message: e.to_string() })?;
        outputs.push(png);
        let reference = (self.reference_steps > 0).then(|| {
            let t0 = Instant::now();
            let run = |r| {
                let steps = self.reference_steps as usize;
                epipolar::march_bvh(&g.camera, &g.distance, &light, &v.bvh, &medium, bounds, steps, r)
            };
            let truth = epipolar::mean_of_runs(&run(0), &run(1));
            let ref_ms = ms(t0);
            (truth, ref_ms)
        });
        if let Some(((truth, variance), _)) = &reference {
            // The marcher's image and the variance of each pixel beside the method's, for comparisons
            // elsewhere (`voltab validate`).
            let var = crate::render::Image {
                width: truth.width,
                height: truth.height,
                data: variance.iter().map(|v| v.map(|x| x as f32)).collect(),
            };
            outputs.extend(view::write_image(id, &dir, "marcher", truth, &[("variance", &var)])?);
        }
        let reference = reference
            .map(|((truth, variance), ref_ms)| -> Result<GodRaysCheck, StageError> {
                let f = |img: &crate::render::RgbImage| -> Vec<[f64; 3]> {
                    img.data.iter().map(|p| p.map(f64::from)).collect()
                };
                let error = NoiseCorrected::of_rgb(&f(&out.inscatter), &f(&truth), &variance).map_err(|e| {
                    StageError::Input {
                        stage: id.into(),
                        message: format!("the BVH marcher cannot judge the god rays: {e}"),
                        help: "aim the camera at the lit fog, or set reference_steps: 0 to skip the check".into(),
                    }
                })?;
                Ok(GodRaysCheck {
                    steps: self.reference_steps,
                    ms: ref_ms,
                    error,
                    speedup: 0.5 * ref_ms / out.stats.total_ms.max(1e-9),
                })
            })
            .transpose()?;
        let s: &EpipolarStats = &out.stats;
        let n = out.inscatter.data.len().max(1) as f64;
        let summary = GodRaysSummary {
            scene: fields.scene_path(ctx.base_dir).display().to_string(),
            size: [image.width, image.height],
            setup_ms: [v.import_ms, v.bvh_ms, g.distance_ms, g.colour_ms, shadow_ms],
            phases_ms: [
                s.rectify_ms,
                s.factorize_ms,
                s.prefilter_ms,
                s.integrate_ms,
                s.ring_ms,
                s.unrectify_ms,
                s.total_ms,
            ],
            slices: s.slices,
            samples: s.samples,
            ring_pixels: s.ring_pixels,
            edge_pixels: s.edge_pixels,
            gain_pixels: s.gain_pixels,
            fog_region: [medium.region.0, medium.region.1],
            svd_residual: s.svd_residual,
            mean_inscatter: [0, 1, 2].map(|c| out.inscatter.data.iter().map(|p| f64::from(p[c])).sum::<f64>() / n),
            reference,
            device: device.to_string(),
            gpu_phases,
            device_note,
        };
        outputs.push(view::write_json(id, &dir.join("summary.json"), &summary)?);
        let check = summary.reference.as_ref().map_or(String::new(), |r| {
            format!(
                "; vs {}-step BVH marcher (jitter noise {:.2} %): {}, {:.0}× faster",
                r.steps,
                100.0 * r.error.reference_noise,
                r.error.percent(),
                r.speedup
            )
        });
        let note = summary.device_note.as_ref().map_or(String::new(), |n| format!(" ({n})"));
        Ok(StageOutcome {
            outputs,
            summary: format!(
                "{}×{}, {} slices, epipolar {:.0} ms on {}{note}{check} → {}",
                image.width,
                image.height,
                s.slices,
                s.total_ms,
                summary.device,
                dir.display()
            ),
        })
    }

    /// `voltab bench --suite gpu`: the stage's frame on the CPU and on `ctx.device` side by side (median of
    /// 3 each, shadow map excluded: both share it), the GPU time of every phase, and how far the
    /// device's in-scatter is from the CPU's.
    pub fn bench_gpu(&self, id: &str, ctx: &StageContext) -> Result<(String, Vec<BenchRow>), StageError> {
        let fields = self.fields();
        let v = fields.load(id, ctx, None)?;
        let (light, medium) = Self::light_and_medium(id, &v.scene)?;
        let bounds = v.scene.bounds().ok_or_else(|| StageError::Input {
            stage: id.into(),
            message: format!("{} has no geometry", v.scene.source.display()),
            help: "add meshes to the scene".into(),
        })?;
        let shadow = epipolar::render_shadow_map(&v.bvh, &light, bounds, self.shadow_map as usize);
        let g = &v.gbuffer;
        let opts = self.options();
        let median = |mut x: Vec<f64>| {
            x.sort_by(f64::total_cmp);
            x[x.len() / 2]
        };
        let cpu: Vec<EpipolarOutput> =
            (0..3).map(|_| epipolar::render(&g.camera, &g.distance, &light, &shadow, &medium, &opts)).collect();
        let mut dev = Vec::new();
        for _ in 0..3 {
            dev.push(self.render_on_device(id, ctx, g, &light, &shadow, &medium)?);
        }
        let cpu_ms = median(cpu.iter().map(|o| o.stats.total_ms).collect());
        let dev_ms = median(dev.iter().map(|d| d.0.stats.total_ms).collect());
        let diff = crate::render::rel_rmse(&dev[0].0.inscatter, &cpu[0].inscatter);
        let mut text = format!(
            "Epipolar god rays on {} ({}×{}, {} slices): CPU {cpu_ms:.1} ms, {} {dev_ms:.1} ms ({:.2}×); in-scatter differs by {diff:.2e} (rel. RMS)\n",
            fields.scene_path(ctx.base_dir).display(),
            g.camera.width,
            g.camera.height,
            cpu[0].stats.slices,
            dev[0].1,
            cpu_ms / dev_ms.max(1e-9),
        );
        if let Some(note) = &dev[0].3 {
            text.push_str(&format!("  ({note})\n"));
        }
        if !dev[0].2.is_empty() {
            text.push_str("GPU phases (first frame):\n");
            for p in &dev[0].2 {
                text.push_str(&format!("  {:<24} {:>3} passes {:>9.3} ms\n", p.phase, p.passes, p.ms));
            }
        }
        let rows = vec![BenchRow {
            what: format!("{id}: epipolar frame, CPU vs {}", dev[0].1),
            baseline_ms: cpu_ms,
            candidate_ms: dev_ms,
            speedup: cpu_ms / dev_ms.max(1e-9),
            note: format!("in-scatter differs by {diff:.2e} (rel. RMS)"),
        }];
        Ok((text, rows))
    }

    /// The effect on the selected device: [`crate::stages::god_rays::gpu::render`] when the run has a GPU,
    /// else (or when the device path refuses the input, said in the note) [`epipolar::render`].
    fn render_on_device(
        &self,
        id: &str,
        ctx: &StageContext,
        g: &GBuffer,
        light: &EpiLight,
        shadow: &ShadowMap,
        medium: &EpiMedium,
    ) -> Result<crate::stages::DeviceRun<EpipolarOutput>, StageError> {
        let opts = self.options();
        #[cfg(feature = "gpu")]
        if let Some(gpu) = ctx.device.gpu() {
            let result =
                crate::stages::god_rays::gpu::render(gpu, &g.camera, &g.distance, light, shadow, medium, &opts);
            return crate::stages::device_run(id, ctx, "epipolar god rays", result, || {
                epipolar::render(&g.camera, &g.distance, light, shadow, medium, &opts)
            });
        }
        #[cfg(not(feature = "gpu"))]
        let _ = id;
        Ok((
            epipolar::render(&g.camera, &g.distance, light, shadow, medium, &opts),
            ctx.device.name(),
            Vec::new(),
            None,
        ))
    }

    /// `voltab bench --suite effects`: [`epipolar::bench::bench`] on this stage's scene (1280×960, 1 and 2
    /// threads, error against time of both methods, speed-up at equal error, time-vs-resolution slopes).
    pub fn bench(&self, id: &str, ctx: &StageContext) -> Result<(String, Vec<BenchRow>), StageError> {
        let r = epipolar::bench::bench(&self.scene_path(ctx.base_dir), false).map_err(|e| StageError::Input {
            stage: id.into(),
            message: e,
            help: "fix the stage's inputs".into(),
        })?;
        let rows = r
            .runs
            .iter()
            .flat_map(|run| {
                run.speedups.iter().map(move |s| BenchRow {
                    what: format!("god rays {id}: ray marcher vs epipolar at equal error, {} thread(s)", run.threads),
                    baseline_ms: s.march_ms,
                    candidate_ms: s.epi_ms,
                    speedup: s.speedup,
                    note: format!(
                        "{} at error {:.4}{}",
                        s.knob,
                        s.error,
                        if s.extrapolated { "; marcher time extrapolated (power law)" } else { "" }
                    ),
                })
            })
            .collect();
        Ok((r.to_string(), rows))
    }

    /// `voltab report --stages`: error against time of the epipolar method and the shadow-map marcher
    /// against a converged BVH marcher at this stage's size, as `<id>-godrays.md` and
    /// `<id>-godrays-error-vs-time.png` in `report_dir`. Returns the Markdown.
    pub fn report(&self, id: &str, ctx: &StageContext, report_dir: &Path) -> Result<String, StageError> {
        let out =
            |path: &Path, message: String| StageError::Output { stage: id.into(), path: path.to_path_buf(), message };
        let fields = self.fields();
        let path = fields.scene_path(ctx.base_dir);
        let scene = ctx.scenes.load(&path).map_err(|e| StageError::Input {
            stage: id.into(),
            message: e.to_string(),
            help: "fix the scene file or the scene field".into(),
        })?;
        let points = epipolar::bench::error_vs_time(&scene, self.width as usize, self.height as usize, false)
            .map_err(|e| StageError::Input { stage: id.into(), message: e, help: "fix the stage's inputs".into() })?;
        std::fs::create_dir_all(report_dir).map_err(|e| out(report_dir, e.to_string()))?;
        let png = report_dir.join(format!("{id}-godrays-error-vs-time.png"));
        epipolar::bench::write_error_plot(&points, &format!("{id}: god rays, error vs time"), &png)
            .map_err(|e| out(&png, e))?;
        let mut md = format!(
            "## {id}: epipolar god rays (baran2010) vs ray marching, {}×{}\n\nRelative RMSE of the in-scatter against a converged BVH shadow-ray marcher.\n\n| method | setting | ms | rel. RMSE |\n|---|---|---:|---:|\n",
            self.width, self.height
        );
        for p in &points {
            md.push_str(&format!("| {} | {} | {:.1} | {:.4} |\n", p.method, p.knob, p.ms, p.error));
        }
        md.push('\n');
        for s in epipolar::bench::speedups(&points) {
            md.push_str(&format!(
                "- epipolar {} (error {:.4}, {:.1} ms): ray marching needs {:.1} ms for that error → {:.1}×\n",
                s.knob, s.error, s.epi_ms, s.march_ms, s.speedup
            ));
        }
        let md_path = report_dir.join(format!("{id}-godrays.md"));
        crate::cache::write_atomic(&md_path, md.as_bytes()).map_err(|e| out(&md_path, e.to_string()))?;
        Ok(md)
    }
}

impl crate::stages::Stage for EpipolarShadows {
    fn kind(&self) -> &'static str {
        EpipolarShadowsRaw::KIND
    }
    fn validate(&self) -> Vec<FieldIssue> {
        EpipolarShadows::validate(self)
    }
    fn scenes(&self, base_dir: &Path) -> Vec<std::path::PathBuf> {
        vec![self.scene_path(base_dir)]
    }
    fn plan(
        &self,
        scenes: &crate::stages::planning::PlannedScenes,
        _kept: &crate::stages::planning::KeptTables,
    ) -> crate::stages::planning::StageDecision {
        let def = crate::stages::StageDef::EpipolarShadows(self.clone());
        crate::stages::planning::effect(def, "god rays", &self.scene, scenes, |sc| {
            if super::EpiLight::from_scene(sc).is_none() {
                Some("directional or spot light")
            } else if super::EpiMedium::from_scene(sc).is_none() {
                Some("homogeneous global medium")
            } else {
                None
            }
        })
    }
    fn run(&self, id: &str, ctx: &StageContext) -> Result<StageOutcome, StageError> {
        EpipolarShadows::run(self, id, ctx)
    }
    fn report(&self, id: &str, ctx: &StageContext, report_dir: &Path) -> Result<Option<String>, StageError> {
        EpipolarShadows::report(self, id, ctx, report_dir).map(Some)
    }
    fn bench_focus(&self) -> Option<crate::stages::BenchFocus> {
        Some(crate::stages::BenchFocus::Effects)
    }
    fn bench(&self, id: &str, ctx: &StageContext) -> Result<Option<(String, Vec<BenchRow>)>, StageError> {
        EpipolarShadows::bench(self, id, ctx).map(Some)
    }
    fn bench_gpu(&self, id: &str, ctx: &StageContext) -> Result<Option<(String, Vec<BenchRow>)>, StageError> {
        EpipolarShadows::bench_gpu(self, id, ctx).map(Some)
    }
    fn uses_device(&self) -> bool {
        true
    }
}
