//! `ImageFog`: scene → iser2018 image-space quasi-heterogeneous fog (analytic density integrals,
//! hierarchical MIP filtering of multiple scattering) as EXR + PNG, with optional comparisons against
//! the gathering filter and against brute-force volumetric path tracing.
//!
//! **Input.** A scene file (relative to the pipeline file) with a perspective camera and global media
//! (homogeneous or exponential height fog, summed). **Phases.** Import → BVH → G-buffer of the camera
//! ([`view`]: vacuum colour and distance) → [`image_fog::render`] (per-pixel density
//! integrals P and spread W, Secs. 3.3 and Eqs. 1, 3; attenuated and scattered images, Sec. 4.1; MIP
//! chain of the scattered image with the 4-tap Gaussian and level selection, Sec. 4.2; spread-space
//! chain, masking, Sec. 4.3) → `<out>/<stage>/fog.exr` (layers `attenuated`, `scattered`) with PNG
//! previews and `summary.json`.
//!
//! **Checks** (in `summary.json`). With `gather_pixels > 0`, the scattered image against the gathering
//! reference (spatially varying Gaussian) on a stratified grid of that many pixels, and the gather's
//! full-frame time extrapolated per pixel. With `reference_samples > 0`, the physics: at
//! `reference_width` pixels wide, a vacuum image and a fogged image are both path traced
//! ([`volpath::radiance`](crate::reference::volpath::radiance): multiple scattering, surfaces with the same `reference_depth`), the effect is
//! applied to the vacuum image, and the errors of the attenuation-only fog, of the full effect and of
//! no fog at all against the path-traced fog are reported — how much closer multiple scattering gets —
//! relative to the path-traced image's mean with its noise removed and its floor stated
//! ([`NoiseCorrected`]).

use std::path::Path;
use std::time::Instant;

use serde::{Deserialize, Serialize};

use crate::render::Image;
use crate::render::gbuffer::GBuffer;
use crate::report::noisy::NoiseCorrected;
use crate::report::plot::{Plot, Scale, Series, write_png};
use crate::scene::Scene;
use crate::scene::bvh::SceneBvh;
use crate::stages::BenchRow;
use crate::stages::image_fog::{self, FogMedium, FogOptions, LevelRule};
use crate::stages::view::{self, View, ViewFields, ms};
use crate::stages::{StageContext, StageError, StageOutcome};
use crate::tables::FieldIssue;

crate::declare_params! {
    /// Apply iser2018 image-space multiple-scattering fog to a camera view of a scene.
    raw ImageFogRaw => resolved ImageFogStage, kind "ImageFog" {
        /// Scene file (.gltf, .glb, .usda, .usdc, .usd, .usdz), relative to the pipeline file.
        scene: String = String::new(), unit = "", range = "path to a scene file";
        /// Index of the scene camera to render.
        camera: u32 = 0, unit = "", range = "0 to the scene's camera count - 1";
        /// Image width.
        width: u32 = 1280, unit = "px", range = "1 to 8192";
        /// Image height.
        height: u32 = 720, unit = "px", range = "1 to 8192";
        /// Paths per pixel of the vacuum colour buffer (direct light at the first hit).
        colour_samples: u32 = 16, unit = "paths", range = "1 to 65536";
        /// MIP levels above level 0 (0: down to 1×1).
        levels: u32 = 0, unit = "levels", range = "0 to 16";
        /// Use the paper's level rule k = log2(W/c) instead of variance matching.
        paper_levels: bool = false, unit = "", range = "true or false";
        /// Mask small-spread pixels out of coarser levels (Sec. 4.3).
        masking: bool = true, unit = "", range = "true or false";
        /// Pixels (a stratified grid) on which the filter is compared with the gathering reference (0: none).
        gather_pixels: u32 = 0, unit = "px", range = "0 to 1000000";
        /// Paths per pixel of the path-traced physics comparison (0: none).
        reference_samples: u32 = 0, unit = "paths", range = "0 to 1000000";
        /// Width of the path-traced comparison's images (height keeps the aspect ratio).
        reference_width: u32 = 160, unit = "px", range = "4 to 4096";
        /// Most path vertices (surface bounces and medium collisions) of the path-traced comparison.
        reference_depth: u32 = 16, unit = "vertices", range = "1 to 256";
        /// Colour buffer from another renderer (EXR with R, G, B: linear radiance), relative to the pipeline
        /// file; empty: voltab renders it. Needs distance_exr; the scene still gives the camera and fog.
        colour_exr: String = String::new(), unit = "", range = "empty or path to an EXR file";
        /// Distance buffer from another renderer (EXR; channel Z, depth, distance, R or Y, the first present),
        /// same size as colour_exr; infinite or huge values are sky.
        distance_exr: String = String::new(), unit = "", range = "empty or path to an EXR file";
        /// The distance EXR holds view-space depth along the camera axis (a z-buffer) rather than distance
        /// along each pixel's ray; it is converted with the camera.
        depth_is_z: bool = false, unit = "", range = "true or false";
        /// Output folder name in the output directory; empty means the stage id.
        output: String = String::new(), unit = "", range = "plain folder name";
    }
}

/// The filter against the gathering reference.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct GatherCheck {
    /// Pixels gathered.
    pub pixels: usize,
    /// Gather time for them \[ms\].
    pub ms: f64,
    /// Full-frame gather time extrapolated per pixel \[ms\].
    pub frame_ms: f64,
    /// Relative RMSE of the hierarchical scattered image against the gather on those pixels.
    pub rel_rmse: f64,
    /// Extrapolated gather frame time / hierarchical frame time.
    pub speedup: f64,
}

/// The effect against path-traced fog.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct PhysicsCheck {
    /// Image size compared.
    pub size: [usize; 2],
    /// Paths per pixel.
    pub samples: u32,
    /// Path-tracing time (vacuum + fog) \[ms\].
    pub ms: f64,
    /// Attenuation-only fog against the path-traced fog (each error holds the reference's noise).
    pub attenuation_only: NoiseCorrected,
    /// The full effect against it.
    pub effect: NoiseCorrected,
    /// The vacuum image (no fog at all) against it.
    pub no_fog: NoiseCorrected,
}

/// What `summary.json` holds.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct FogSummary {
    /// Scene file.
    pub scene: String,
    /// Image size.
    pub size: [usize; 2],
    /// Import, BVH, distance buffer, colour buffer \[ms\].
    pub setup_ms: [f64; 4],
    /// Effect phases \[ms\]: integrals, MIP chain, filter + compose, total.
    pub phases_ms: [f64; 4],
    /// Filter against gather.
    pub gather: Option<GatherCheck>,
    /// Effect against path tracing.
    pub physics: Option<PhysicsCheck>,
    /// Where the effect ran: `"cpu"` or `"gpu"` (integrals, filter and compose alike).
    #[serde(default)]
    pub device: String,
    /// GPU time per phase (`mip chain`, `fetch`, `compose`) when they ran on the GPU.
    #[serde(default)]
    pub gpu_phases: Vec<GpuPhase>,
    /// Why the CPU path ran although a GPU was selected (an option the GPU path does not port).
    #[serde(default)]
    pub device_note: Option<String>,
}

/// GPU time of one phase of the effect.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct GpuPhase {
    /// The phase.
    pub phase: String,
    /// Milliseconds, summed over its passes.
    pub ms: f64,
    /// Passes.
    pub passes: usize,
}

crate::stages::view::impl_view_fields!(ImageFogStage);

impl ImageFogStage {
    /// Range checks.
    pub fn validate(&self) -> Vec<FieldIssue> {
        let mut v = self.fields().validate();
        let mut issue = |field: &'static str, message: String, help: &str| {
            v.push(FieldIssue { field, message, help: help.into() });
        };
        if self.levels > 16 {
            issue("levels", format!("levels = {}", self.levels), "use 0 (automatic) to 16");
        }
        if self.gather_pixels > 1_000_000 {
            issue("gather_pixels", format!("gather_pixels = {}", self.gather_pixels), "use 0 to 1000000");
        }
        if self.reference_samples > 1_000_000 {
            issue("reference_samples", format!("reference_samples = {}", self.reference_samples), "use 0 to 1000000");
        }
        if !(4..=4096).contains(&self.reference_width) {
            issue("reference_width", format!("reference_width = {}", self.reference_width), "use 4 to 4096");
        }
        if self.colour_exr.is_empty() != self.distance_exr.is_empty() {
            issue(
                "colour_exr",
                "colour_exr and distance_exr must be given together".into(),
                "give both EXR files of the other renderer, or neither (voltab renders the buffers)",
            );
        }
        if !(1..=256).contains(&self.reference_depth) {
            issue("reference_depth", format!("reference_depth = {}", self.reference_depth), "use 1 to 256");
        }
        v
    }

    /// The effect's knobs.
    pub fn options(&self) -> FogOptions {
        FogOptions {
            levels: (self.levels > 0).then_some(self.levels as usize),
            level_rule: if self.paper_levels { LevelRule::Paper } else { LevelRule::VarianceMatched },
            masking: self.masking,
            ..FogOptions::default()
        }
    }

    fn medium(id: &str, scene: &Scene) -> Result<FogMedium, StageError> {
        FogMedium::from_scene(scene).ok_or_else(|| StageError::Input {
            stage: id.into(),
            message: format!("{} has no global medium", scene.source.display()),
            help: "add global fog (homogeneous or exponential height fog) to the scene".into(),
        })
    }

    /// Runs the stage.
    pub fn run(&self, id: &str, ctx: &StageContext) -> Result<StageOutcome, StageError> {
        let fields = self.fields();
        let dir = fields.out_dir(id, ctx)?;
        let v = if self.colour_exr.is_empty() { fields.load(id, ctx, None)? } else { self.load_exr(id, ctx)? };
        let medium = Self::medium(id, &v.scene)?;
        let g = &v.gbuffer;
        let opts = self.options();
        let t0 = Instant::now();
        let (out, device, gpu_phases, device_note) = self.render_on_device(id, ctx, g, &medium, &opts)?;
        let total_ms = ms(t0);
        let mut outputs = view::write_image(
            id,
            &dir,
            "fog",
            &out.image,
            &[("attenuated", &out.attenuated), ("scattered", &out.scattered), ("colour", &g.colour)],
        )?;
        for (name, img) in [("fog_attenuated", &out.attenuated), ("fog_scattered", &out.scattered)] {
            let png = dir.join(format!("{name}.png"));
            crate::image_io::write_png_preview(&png, img.width, img.height, &img.data, None)
                .map_err(|e| StageError::Output { stage: id.into(), path: png.clone(), message: e.to_string() })?;
            outputs.push(png);
        }
        let gather = (self.gather_pixels > 0).then(|| {
            let (w, h) = (g.camera.width, g.camera.height);
            let pixels = stratified(w, h, self.gather_pixels as usize);
            let t0 = Instant::now();
            let p = image_fog::prepare(&g.camera, &g.colour, &g.distance, &medium);
            let cap = image_fog::spread_cap(w, h, &opts);
            let truth = image_fog::gather::gather_pixels(&p.scattered, &p.spread, cap, &pixels);
            let gather_ms = ms(t0);
            let mine: Vec<[f32; 3]> = pixels.iter().map(|&(x, y)| out.scattered.at(x, y)).collect();
            let frame_ms = gather_ms / pixels.len() as f64 * (w * h) as f64;
            GatherCheck {
                pixels: pixels.len(),
                ms: gather_ms,
                frame_ms,
                rel_rmse: crate::render::rel_rmse(
                    &Image { width: mine.len(), height: 1, data: mine },
                    &Image { width: truth.len(), height: 1, data: truth },
                ),
                speedup: frame_ms / total_ms.max(1e-9),
            }
        });
        let physics =
            if self.reference_samples > 0 { Some(self.physics(id, &v.scene, &v.bvh, &medium)?) } else { None };
        let s = &out.stats;
        let summary = FogSummary {
            scene: fields.scene_path(ctx.base_dir).display().to_string(),
            size: [g.camera.width, g.camera.height],
            setup_ms: [v.import_ms, v.bvh_ms, g.distance_ms, g.colour_ms],
            phases_ms: [s.integrals_ms, s.mip_ms, s.filter_ms, s.total_ms()],
            gather,
            physics,
            device: device.to_string(),
            gpu_phases,
            device_note,
        };
        outputs.push(view::write_json(id, &dir.join("summary.json"), &summary)?);
        let mut line =
            format!("{}×{}, fog {:.0} ms on {}", g.camera.width, g.camera.height, s.total_ms(), summary.device);
        if let Some(note) = &summary.device_note {
            line.push_str(&format!(" ({note})"));
        }
        if let Some(c) = &summary.gather {
            line.push_str(&format!(
                "; vs gathering on {} px: error {:.2} %, {:.0}× faster",
                c.pixels,
                100.0 * c.rel_rmse,
                c.speedup
            ));
        }
        if let Some(c) = &summary.physics {
            line.push_str(&format!(
                "; vs path tracing at {}×{} ({} paths/px, noise {:.1} %): attenuation only {}, with scattering {}",
                c.size[0],
                c.size[1],
                c.samples,
                100.0 * c.effect.reference_noise,
                c.attenuation_only.percent(),
                c.effect.percent()
            ));
        }
        Ok(StageOutcome { outputs, summary: format!("{line} → {}", dir.display()) })
    }

    /// The effect on the selected device: the GPU filter and compose ([`crate::stages::image_fog::gpu::render`]) when
    /// the run has a GPU, else (or for options the GPU path does not port, said in the note) the CPU.
    fn render_on_device(
        &self,
        id: &str,
        ctx: &StageContext,
        g: &GBuffer,
        medium: &FogMedium,
        opts: &FogOptions,
    ) -> Result<crate::stages::DeviceRun<image_fog::FogOutput>, StageError> {
        #[cfg(feature = "gpu")]
        if let Some(gpu) = ctx.device.gpu() {
            let result = crate::stages::image_fog::gpu::render(gpu, &g.camera, &g.colour, &g.distance, medium, opts);
            return crate::stages::device_run(id, ctx, "image fog", result, || {
                image_fog::render(&g.camera, &g.colour, &g.distance, medium, opts)
            });
        }
        #[cfg(not(feature = "gpu"))]
        let _ = id;
        Ok((image_fog::render(&g.camera, &g.colour, &g.distance, medium, opts), ctx.device.name(), Vec::new(), None))
    }

    /// The scene (camera, fog) with colour and distance buffers read from another renderer's EXR files.
    /// `voltab validate`: the effect applied to a colour image from another renderer (at its size), on
    /// voltab's distance buffer of the stage's camera at that size. Returns the output and the fog's
    /// time \[ms\] (integrals, MIP chain, filter; the distance buffer excluded).
    pub fn apply_to_colour(
        &self,
        id: &str,
        ctx: &StageContext,
        colour: &crate::render::RgbImage,
    ) -> Result<(image_fog::FogOutput, f64), StageError> {
        let mut fields = self.fields();
        fields.colour_samples = 1;
        let v = fields.load(id, ctx, Some((colour.width, colour.height)))?;
        let medium = Self::medium(id, &v.scene)?;
        let t0 = Instant::now();
        let out = image_fog::render(&v.gbuffer.camera, colour, &v.gbuffer.distance, &medium, &self.options());
        Ok((out, ms(t0)))
    }

    fn load_exr(&self, id: &str, ctx: &StageContext) -> Result<View, StageError> {
        let fail = |message: String, help: &str| StageError::Input { stage: id.into(), message, help: help.into() };
        let t0 = Instant::now();
        let read = |name: &str| {
            let path = ctx.base_dir.join(name);
            crate::image_io::read_exr_rgb(&path)
                .map_err(|e| {
                    fail(e.to_string(), "give a readable single-part EXR file (path relative to the pipeline file)")
                })
                .map(|img| (path, img))
        };
        let (cpath, cimg) = read(&self.colour_exr)?;
        let (dpath, dimg) = read(&self.distance_exr)?;
        if (cimg.width, cimg.height) != (dimg.width, dimg.height) {
            return Err(fail(
                format!(
                    "{} is {}×{} but {} is {}×{}",
                    cpath.display(),
                    cimg.width,
                    cimg.height,
                    dpath.display(),
                    dimg.width,
                    dimg.height
                ),
                "render both buffers at the same size",
            ));
        }
        let colour = cimg.rgb(None).ok_or_else(|| {
            fail(format!("{} has no R, G, B channels", cpath.display()), "write the colour as channels R, G, B")
        })?;
        let names = ["Z", "depth", "distance", "R", "Y"];
        let dist = names.iter().find_map(|n| dimg.channels.get(*n)).ok_or_else(|| {
            fail(
                format!(
                    "{} has none of the channels {names:?} (it has {:?})",
                    dpath.display(),
                    dimg.channels.keys().collect::<Vec<_>>()
                ),
                "write the distance as channel Z (or depth, distance, R, Y)",
            )
        })?;
        let (w, h) = (cimg.width, cimg.height);
        for (i, c) in colour.iter().enumerate() {
            if c.iter().any(|x| !x.is_finite() || *x < 0.0) {
                return Err(fail(
                    format!("{}: pixel ({}, {}) is {c:?}", cpath.display(), i % w, i / w),
                    "colours must be finite and non-negative linear radiance",
                ));
            }
        }
        let path = self.fields().scene_path(ctx.base_dir);
        let t1 = Instant::now();
        let scene = ctx.scenes.load(&path).map_err(|e| fail(e.to_string(), "fix the scene file or the scene field"))?;
        let import_ms = ms(t1);
        let t1 = Instant::now();
        let bvh = SceneBvh::build(&scene);
        let bvh_ms = ms(t1);
        let camera = self.fields().camera(id, &scene, &path, Some((w, h)))?;
        let mut distance = Image::filled(w, h, f32::INFINITY);
        for (i, &d) in dist.iter().enumerate() {
            if d.is_nan() || d < 0.0 {
                return Err(fail(
                    format!("{}: pixel ({}, {}) has distance {d}", dpath.display(), i % w, i / w),
                    "distances must be non-negative (infinite or huge for sky)",
                ));
            }
            // A z-buffer value is the depth along the view axis: the ray's distance is z / cos.
            let cos = if self.depth_is_z { camera.pixel_dir(i % w, i / w).dot(camera.forward) } else { 1.0 };
            distance.data[i] = if d >= 1e30 { f32::INFINITY } else { (f64::from(d) / cos) as f32 };
        }
        let gbuffer = GBuffer {
            camera,
            colour: Image { width: w, height: h, data: colour },
            distance,
            distance_ms: ms(t0),
            colour_ms: 0.0,
        };
        Ok(View { scene, bvh, gbuffer, import_ms, bvh_ms })
    }

    /// The filter's error against the gathering reference at this stage's size, for several filter
    /// settings, with the G-buffer colour of the scene: rows (label, frame ms, relative RMSE) and the
    /// gather's extrapolated frame time.
    fn settings_vs_gather(&self, id: &str, ctx: &StageContext) -> Result<image_fog::bench::BenchReport, StageError> {
        let fields = ViewFields { colour_samples: self.colour_samples.min(4), ..self.fields() };
        let v = fields.load(id, ctx, None)?;
        let medium = Self::medium(id, &v.scene)?;
        let g = &v.gbuffer;
        let frames = [image_fog::bench::Frame { cam: g.camera, colour: &g.colour, distance: &g.distance }];
        let cfg = image_fog::bench::BenchConfig { runs: 3, gather_grid: Some((16, 9)) };
        image_fog::bench::bench_frames(&frames, &medium, &cfg).map_err(|e| StageError::Input {
            stage: id.into(),
            message: e,
            help: "fix the stage's inputs".into(),
        })
    }

    /// `voltab report --stages`: the hierarchical filter's error against the gathering reference and its
    /// frame time for several settings (`<id>-fog.md`, `<id>-fog-error-vs-time.png` in `report_dir`).
    pub fn report(&self, id: &str, ctx: &StageContext, report_dir: &Path) -> Result<String, StageError> {
        let out =
            |path: &Path, message: String| StageError::Output { stage: id.into(), path: path.to_path_buf(), message };
        let r = self.settings_vs_gather(id, ctx)?;
        std::fs::create_dir_all(report_dir).map_err(|e| out(report_dir, e.to_string()))?;
        let series: Vec<Series> =
            r.errors.iter().map(|e| Series { name: e.label.clone(), points: vec![(e.frame_ms, e.rel_rmse)] }).collect();
        let png = report_dir.join(format!("{id}-fog-error-vs-time.png"));
        let plot = Plot {
            title: &format!("{id}: image-space fog, error vs gathering against frame time"),
            x_label: "frame time [ms]",
            y_label: "relative RMSE of scattered light vs gather",
            x_scale: Scale::Log10,
            y_scale: Scale::Log10,
            series: &series,
            width: 1024,
            height: 720,
        };
        write_png(&png, &plot).map_err(|e| out(&png, e.to_string()))?;
        let mut md = format!(
            "## {id}: image-space fog (iser2018), {}×{}\n\nRelative RMSE of the filtered scattered light against the gathering filter on {} stratified pixels; the gather would take {:.0} s for the whole frame ({}), {:.0}× the hierarchical filter.\n\n| setting | frame ms | rel. RMSE |\n|---|---:|---:|\n",
            self.width,
            self.height,
            r.gather.pixels,
            r.gather.frame_seconds,
            if r.gather.full { "measured" } else { "extrapolated per pixel" },
            r.gather.speedup
        );
        for e in &r.errors {
            md.push_str(&format!("| {} | {:.1} | {:.4} |\n", e.label, e.frame_ms, e.rel_rmse));
        }
        let md_path = report_dir.join(format!("{id}-fog.md"));
        crate::cache::write_atomic(&md_path, md.as_bytes()).map_err(|e| out(&md_path, e.to_string()))?;
        Ok(md)
    }

    /// `voltab bench --suite effects`: frame time and phases at 1280×720 and 1920×1080 (G-buffer colour of the
    /// scene, 2 paths per pixel) on the current rayon pool, and the gathering reference at 1080p on a
    /// stratified pixel subset, extrapolated per pixel.
    pub fn bench(&self, id: &str, ctx: &StageContext) -> Result<(String, Vec<BenchRow>), StageError> {
        let fields = ViewFields { colour_samples: 2, ..self.fields() };
        let mut views = Vec::new();
        for size in [(1280, 720), (1920, 1080)] {
            views.push(fields.load(id, ctx, Some(size))?);
        }
        let medium = Self::medium(id, &views[0].scene)?;
        let frames: Vec<image_fog::bench::Frame<'_>> = views
            .iter()
            .map(|v| image_fog::bench::Frame {
                cam: v.gbuffer.camera,
                colour: &v.gbuffer.colour,
                distance: &v.gbuffer.distance,
            })
            .collect();
        let cfg = image_fog::bench::BenchConfig { runs: 7, gather_grid: Some((8, 6)) };
        let r = image_fog::bench::bench_frames(&frames, &medium, &cfg).map_err(|e| StageError::Input {
            stage: id.into(),
            message: e,
            help: "fix the stage's inputs".into(),
        })?;
        let f = r.frames.last().map_or(f64::NAN, |f| f.median_ms);
        let rows = vec![BenchRow {
            what: format!(
                "fog {id}: gathering reference vs hierarchical filter at {}×{}",
                r.gather.width, r.gather.height
            ),
            baseline_ms: r.gather.frame_seconds * 1e3,
            candidate_ms: f,
            speedup: r.gather.speedup,
            note: format!(
                "gather {} on {} pixels; filter error vs gather {:.3}",
                if r.gather.full { "measured" } else { "extrapolated per pixel" },
                r.gather.pixels,
                r.errors.first().map_or(f64::NAN, |e| e.rel_rmse)
            ),
        }];
        Ok((r.to_string(), rows))
    }

    /// The physics comparison (module doc).
    fn physics(&self, id: &str, scene: &Scene, bvh: &SceneBvh, medium: &FogMedium) -> Result<PhysicsCheck, StageError> {
        let w = self.reference_width as usize;
        let h = ((w as f64 * self.height as f64 / self.width as f64).round() as usize).max(1);
        let path = Path::new(&self.scene);
        let cam = self.fields().camera(id, scene, path, Some((w, h)))?;
        let t0 = Instant::now();
        let trace = |media| view::path_trace(scene, bvh, &cam, self.reference_samples, self.reference_depth, media);
        let vacuum = trace(false).0;
        let (fog, variance) = trace(true);
        let pt_ms = ms(t0);
        let distance = crate::render::gbuffer::distance_image(bvh, &cam);
        let out = image_fog::render(&cam, &vacuum, &distance, medium, &self.options());
        let truth: Vec<[f64; 3]> = fog.data.iter().map(|p| p.map(f64::from)).collect();
        let judge = |img: &crate::render::RgbImage| {
            let a: Vec<[f64; 3]> = img.data.iter().map(|p| p.map(f64::from)).collect();
            NoiseCorrected::of_rgb(&a, &truth, &variance).map_err(|e| StageError::Input {
                stage: id.into(),
                message: format!("the path-traced fog cannot judge the effect: {e}"),
                help: "aim the camera at lit surfaces, or set reference_samples: 0 to skip the check".into(),
            })
        };
        Ok(PhysicsCheck {
            size: [w, h],
            samples: self.reference_samples,
            ms: pt_ms,
            attenuation_only: judge(&out.attenuated)?,
            effect: judge(&out.image)?,
            no_fog: judge(&vacuum)?,
        })
    }
}

/// About `n` pixel centres on a stratified grid over a `w × h` image (at least one).
fn stratified(w: usize, h: usize, n: usize) -> Vec<(usize, usize)> {
    let aspect = w as f64 / h as f64;
    let ny = ((n as f64 / aspect).sqrt().round() as usize).clamp(1, h);
    let nx = (n / ny).clamp(1, w);
    image_fog::gather::grid_pixels(w, h, nx, ny)
}

impl crate::stages::Stage for ImageFogStage {
    fn kind(&self) -> &'static str {
        ImageFogRaw::KIND
    }
    fn validate(&self) -> Vec<FieldIssue> {
        ImageFogStage::validate(self)
    }
    fn scenes(&self, base_dir: &Path) -> Vec<std::path::PathBuf> {
        vec![self.scene_path(base_dir)]
    }
    fn plan(
        &self,
        scenes: &crate::stages::planning::PlannedScenes,
        _kept: &crate::stages::planning::KeptTables,
    ) -> crate::stages::planning::StageDecision {
        let def = crate::stages::StageDef::ImageFog(self.clone());
        crate::stages::planning::effect(def, "image-space fog", &self.scene, scenes, |sc| {
            super::FogMedium::from_scene(sc).is_none().then_some("global medium")
        })
    }
    fn run(&self, id: &str, ctx: &StageContext) -> Result<StageOutcome, StageError> {
        ImageFogStage::run(self, id, ctx)
    }
    fn report(&self, id: &str, ctx: &StageContext, report_dir: &Path) -> Result<Option<String>, StageError> {
        ImageFogStage::report(self, id, ctx, report_dir).map(Some)
    }
    fn bench_focus(&self) -> Option<crate::stages::BenchFocus> {
        Some(crate::stages::BenchFocus::Effects)
    }
    fn bench(&self, id: &str, ctx: &StageContext) -> Result<Option<(String, Vec<BenchRow>)>, StageError> {
        ImageFogStage::bench(self, id, ctx).map(Some)
    }
    fn uses_device(&self) -> bool {
        true
    }
}
