//! `BakeLightmaps`: scene + `ZhResponse` table → lightmaps (EXR + PNG), light probes and a JSON summary,
//! with volume-to-surface transport (dubouchet2019 Sec. 5–6).
//!
//! **Input.** A scene file (glTF or USD, path relative to the pipeline file) whose meshes carry lightmap
//! UVs, and the id of a compiled `ZhResponse` table (needed by [`BakeMode::Full`] when the scene has
//! media; only the emitter profiles and g slices the scene's lights and media need are decompressed).
//!
//! **Phases.** Import → BVH → atlas ([`atlas`]: one chart per lightmapped mesh, texels at texel centres
//! plus conservative edge texels) → for each requested mode, the irradiance of every texel by
//! [`transport`] (surface path tracing whose connections are weighted by the mode: vacuum, media
//! shadowing, or the ZH impulse responses) → dilation (so bilinear lookups do not bleed black at chart
//! edges) → `<out>/<stage>/lightmap_<mode>.exr` (linear float RGB irradiance \[W/m²\]) and `.png`
//! previews → optional probe grid (SH bands ≤ 2 of incident radiance, `probes.vtab`) → `summary.json`
//! (time per phase, samples, rays, texels/s, rays/s and the estimated noise per mode).
//!
//! **Lightmap content.** Irradiance `E` per texel (not outgoing radiance): a renderer multiplies by the
//! surface's albedo over π. Atlas layout: `summary.json` lists each chart's pixel rectangle; a mesh's
//! lightmap UV `(u, v)` maps to atlas pixel `(x + u·w, y + v·h)` (see [`atlas`]).

pub mod atlas;
pub mod lights;
mod probes;
pub mod report;
mod tiles;
pub mod transport;

pub use tiles::{TILE_TEXELS, TileBaker};

#[cfg(test)]
mod tests;

use std::path::{Path, PathBuf};
use std::time::Instant;

use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use super::{StageContext, StageError, StageOutcome};
use crate::report::noisy::NoiseCorrected;
use crate::scene::Scene;
use crate::scene::bvh::SceneBvh;
use crate::tables::FieldIssue;
use crate::tables::zh_response::{EmitterProfile, ZhResponseTable};
use transport::{Estimate, Transport, TransportOptions};

/// Which volume-to-surface effects a bake includes (dubouchet2019 Figs. 1 and 12).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize, schemars::JsonSchema)]
pub enum BakeMode {
    /// Surfaces only: media ignored.
    Surface,
    /// Surfaces with media shadowing: every connection attenuated by the media it crosses.
    Shadow,
    /// Attenuation plus single and multiple scattering from the ZH tables.
    Full,
}

impl BakeMode {
    /// Lower-case name used in file names.
    pub fn name(self) -> &'static str {
        match self {
            BakeMode::Surface => "surface",
            BakeMode::Shadow => "shadow",
            BakeMode::Full => "full",
        }
    }
}

crate::declare_params! {
    /// Bake lightmaps (and optionally light probes) of a scene with volume-to-surface transport.
    raw BakeLightmapsRaw => resolved BakeLightmaps, kind "BakeLightmaps" {
        /// Scene file (.gltf, .glb, .usda, .usdc, .usd, .usdz), relative to the pipeline file.
        scene: String = String::new(), unit = "", range = "path to a scene file";
        /// Id of the ZhResponse table (declared in this pipeline) the Full mode queries.
        table: String = String::new(), unit = "", range = "id of a ZhResponse table";
        /// Modes to bake, each to its own lightmap (Surface, Shadow, Full).
        modes: Vec<BakeMode> = vec![BakeMode::Full], unit = "", range = "non-empty list of Surface, Shadow, Full";
        /// Lightmap resolution: texels per metre along a surface.
        texels_per_metre: f64 = 8.0, unit = "1/m", range = "0.01 to 10000";
        /// Smallest chart side.
        min_size: u32 = 4, unit = "texels", range = "1 to max_size";
        /// Largest chart side.
        max_size: u32 = 256, unit = "texels", range = "min_size to 8192";
        /// Samples per texel (area-light points and bounce paths).
        samples: u32 = 128, unit = "samples", range = "1 to 1000000";
        /// Samples per texel on which the scattered light is queried from the table (the rest carry direct
        /// light only; the mean is unchanged). Scattered light is smooth, so a few suffice.
        scatter_samples: u32 = 32, unit = "samples", range = "1 to samples";
        /// Surface bounces of indirect light (0: direct light only).
        bounces: u32 = 5, unit = "bounces", range = "0 to 16";
        /// Apply dubouchet2019 Sec. 5.2 back-scatter compensation to the scattered light.
        backscatter: bool = true, unit = "", range = "true or false";
        /// Seed of the counter-based random streams.
        seed: u64 = 0, unit = "", range = "any";
        /// Probe grid over the scene bounds (nx, ny, nz); empty for no probes.
        probe_grid: Vec<u32> = Vec::new(), unit = "probes", range = "empty or three counts 1 to 256";
        /// Texels (a subset of the atlas) on which every mode is compared with the brute-force volumetric
        /// path tracer; 0 for no comparison. The errors go to summary.json.
        reference_texels: u32 = 0, unit = "texels", range = "0 to 100000";
        /// Paths per texel of that reference.
        reference_samples: u32 = 4096, unit = "paths", range = "1 to 10000000";
        /// Output folder name in the output directory; empty means the stage id.
        output: String = String::new(), unit = "", range = "plain folder name";
    }
}

/// Per-mode results in the summary.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct ModeSummary {
    /// Mode.
    pub mode: BakeMode,
    /// Trace time \[ms\].
    pub trace_ms: f64,
    /// Dilation + writing \[ms\].
    pub write_ms: f64,
    /// Texels baked.
    pub texels: usize,
    /// Samples per texel.
    pub samples: u32,
    /// Rays traced.
    pub rays: u64,
    /// Texels per second of trace time.
    pub texels_per_s: f64,
    /// Rays per second of trace time.
    pub rays_per_s: f64,
    /// Median over texels of the estimate's relative standard error.
    pub noise_median: f64,
    /// 90th percentile of the same.
    pub noise_p90: f64,
    /// Mean irradiance over texels per channel \[W/m²\].
    pub mean_irradiance: [f64; 3],
    /// EXR written.
    pub exr: PathBuf,
    /// A few texels as written to the EXR, for interchange checks: (x, y, RGB as f32).
    pub texel_samples: Vec<(u32, u32, [f32; 3])>,
}

/// The bake's modes against the brute-force reference on a subset of texels.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct ReferenceCheck {
    /// Texels compared.
    pub texels: usize,
    /// Paths per texel of the reference.
    pub samples: u32,
    /// Reference time \[ms\].
    pub ms: f64,
    /// Mean relative standard error of the reference itself.
    pub reference_rel_stderr: f64,
    /// Each mode against the reference, relative to its mean, its noise removed, with its floor.
    pub errors: Vec<(BakeMode, NoiseCorrected)>,
    /// Each mode's mean luminance over the texels divided by the reference's (the bias).
    pub mean_ratio: Vec<(BakeMode, f64)>,
}

/// What `summary.json` holds.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct BakeSummary {
    /// Scene file.
    pub scene: PathBuf,
    /// Import time \[ms\].
    pub import_ms: f64,
    /// BVH build \[ms\].
    pub bvh_ms: f64,
    /// Table load \[ms\] (0 when not needed).
    pub table_ms: f64,
    /// Atlas layout and rasterisation \[ms\].
    pub atlas_ms: f64,
    /// Atlas size.
    pub atlas_size: [u32; 2],
    /// Charts: (mesh name, x, y, width, height).
    pub charts: Vec<(String, u32, u32, u32, u32)>,
    /// Meshes without a chart and why.
    pub skipped: Vec<(String, String)>,
    /// Per mode.
    pub modes: Vec<ModeSummary>,
    /// Comparison with the volumetric path tracer on a texel subset (when `reference_texels > 0`).
    pub reference: Option<ReferenceCheck>,
    /// Probe time \[ms\] and count.
    pub probes_ms: f64,
    /// Number of probes.
    pub probes: usize,
}

impl BakeLightmaps {
    /// Range checks.
    pub fn validate(&self) -> Vec<FieldIssue> {
        let mut v = Vec::new();
        let mut issue = |field: &'static str, message: String, help: &str| {
            v.push(FieldIssue { field, message, help: help.into() });
        };
        if self.scene.is_empty() {
            issue("scene", "scene is empty".into(), "give the scene file, e.g. scene: \"../scenes/fog_room.gltf\"");
        }
        if self.modes.is_empty() {
            issue("modes", "modes is empty".into(), "list at least one of Surface, Shadow, Full");
        }
        let mut seen = Vec::new();
        for m in &self.modes {
            if seen.contains(m) {
                issue("modes", format!("mode {m:?} is listed twice"), "list each mode once");
            }
            seen.push(*m);
        }
        if self.modes.contains(&BakeMode::Full) && self.table.is_empty() {
            issue("table", "mode Full needs a table".into(), "set table to the id of a ZhResponse table");
        }
        if !(self.texels_per_metre.is_finite() && (0.01..=10_000.0).contains(&self.texels_per_metre)) {
            issue("texels_per_metre", format!("texels_per_metre = {}", self.texels_per_metre), "use 0.01 to 10000");
        }
        if !(1..=8192).contains(&self.max_size) || self.min_size < 1 || self.min_size > self.max_size {
            issue(
                "max_size",
                format!("min_size = {}, max_size = {}", self.min_size, self.max_size),
                "use 1 <= min_size <= max_size <= 8192",
            );
        }
        if !(1..=1_000_000).contains(&self.samples) {
            issue("samples", format!("samples = {}", self.samples), "use 1 to 1000000");
        }
        if self.scatter_samples < 1 || self.scatter_samples > self.samples {
            issue("scatter_samples", format!("scatter_samples = {}", self.scatter_samples), "use 1 to samples");
        }
        if self.bounces > 16 {
            issue("bounces", format!("bounces = {}", self.bounces), "use 0 to 16");
        }
        if !(self.probe_grid.is_empty()
            || (self.probe_grid.len() == 3 && self.probe_grid.iter().all(|n| (1..=256).contains(n))))
        {
            issue("probe_grid", format!("probe_grid = {:?}", self.probe_grid), "give [] or three counts from 1 to 256");
        }
        let plain = |s: &str| s.chars().all(|c| c.is_ascii_alphanumeric() || matches!(c, '_' | '-' | '.'));
        if !self.output.is_empty() && (!plain(&self.output) || self.output.starts_with('.')) {
            issue(
                "output",
                format!("output = \"{}\" is not a plain folder name", self.output),
                "use letters, digits, '_', '-', '.'",
            );
        }
        v
    }

    /// The table ids this stage reads (only when a mode needs one).
    pub fn table_ref(&self) -> Option<&str> {
        (self.modes.contains(&BakeMode::Full) && !self.table.is_empty()).then_some(self.table.as_str())
    }

    /// The scene file resolved against the pipeline's folder.
    pub fn scene_path(&self, base_dir: &Path) -> PathBuf {
        base_dir.join(&self.scene)
    }

    /// Runs the bake.
    pub fn run(&self, id: &str, ctx: &StageContext) -> Result<StageOutcome, StageError> {
        self.run_with(id, ctx, None)
    }

    /// The imported scene and the texel count of its atlas: what a farm bake splits into
    /// [`TILE_TEXELS`]-texel tiles per mode.
    pub fn scene_and_texels(&self, id: &str, ctx: &StageContext) -> Result<(std::sync::Arc<Scene>, usize), StageError> {
        let fail = |message: String, help: &str| StageError::Input { stage: id.into(), message, help: help.into() };
        let scene = ctx
            .scenes
            .load(&self.scene_path(ctx.base_dir))
            .map_err(|e| fail(e.to_string(), "fix the scene file or the scene field"))?;
        let atlas = atlas::build(&scene, &self.atlas_options())
            .map_err(|e| fail(e.to_string(), "add lightmap UVs to the scene's meshes"))?;
        let texels = atlas.texels.len();
        Ok((scene, texels))
    }

    /// The bake prepared once (scene, BVH, table slices, atlas) for computing its tiles.
    pub fn tile_baker(&self, id: &str, ctx: &StageContext) -> Result<TileBaker<'_>, StageError> {
        Ok(TileBaker { stage: self, id: id.to_string(), prepared: self.prepare(id, ctx)? })
    }

    /// Runs the bake; with `given`, each mode's estimates (per mode in `self.modes` order, with the
    /// time they took \[ms\]) come from a farm's tiles instead of being traced here.
    pub fn run_with(
        &self,
        id: &str,
        ctx: &StageContext,
        given: Option<&[(Vec<transport::Estimate>, f64)]>,
    ) -> Result<StageOutcome, StageError> {
        let fail = |message: String, help: &str| StageError::Input { stage: id.into(), message, help: help.into() };
        let out_name = if self.output.is_empty() { id.to_string() } else { self.output.clone() };
        let dir = ctx.out_dir.join(&out_name);
        std::fs::create_dir_all(&dir).map_err(|e| StageError::Output {
            stage: id.into(),
            path: dir.clone(),
            message: e.to_string(),
        })?;
        let Prepared { scene, bvh, table, atlas, points, import_ms, bvh_ms, table_ms, atlas_ms } =
            self.prepare(id, ctx)?;
        let scene_path = self.scene_path(ctx.base_dir);
        let mut outputs = Vec::new();
        let mut modes = Vec::new();
        let check_points = report::subset(&atlas, self.reference_texels as usize);
        let mut check_modes: Vec<(BakeMode, Vec<[f64; 3]>)> = Vec::new();
        for (mi, &mode) in self.modes.iter().enumerate() {
            let (est, trace_ms) = match given {
                Some(given) => {
                    let Some((est, ms)) = given.get(mi) else {
                        return Err(fail(format!("no estimates for mode {}", mode.name()), "report this bug"));
                    };
                    if est.len() != points.len() {
                        return Err(fail(
                            format!("{} estimates for {} texels in mode {}", est.len(), points.len(), mode.name()),
                            "rerun the bake tiles for this scene",
                        ));
                    }
                    (est.clone(), *ms)
                }
                None => {
                    let opts = self.transport_options(mode);
                    let tr = Transport::new(&scene, &bvh, table.as_ref(), opts)
                        .map_err(|e| fail(e.to_string(), "check the table"))?;
                    let t0 = Instant::now();
                    let est = bake_points(&tr, &points, ctx.progress, &format!("{id} {}", mode.name()))
                        .map_err(|e| fail(e.to_string(), "check the table's g range against the scene's media"))?;
                    (est, ms(t0))
                }
            };
            if self.reference_texels > 0 {
                let by_cell: std::collections::HashMap<u64, [f64; 3]> =
                    points.iter().zip(&est).map(|(p, e)| (p.cell, e.irradiance)).collect();
                check_modes.push((mode, check_points.iter().map(|p| by_cell[&p.cell]).collect()));
            }
            let t0 = Instant::now();
            let (w, h) = (atlas.width as usize, atlas.height as usize);
            let mut pixels = vec![[0.0f32; 3]; w * h];
            for (t, e) in atlas.texels.iter().zip(&est) {
                pixels[t.pixel as usize] = e.irradiance.map(|c| c as f32);
            }
            atlas::dilate(&atlas, &mut pixels, 4).map_err(|e| fail(e.to_string(), "report this bug"))?;
            let exr = dir.join(format!("lightmap_{}.exr", mode.name()));
            let png = exr.with_extension("png");
            let io = |path: &Path, e: crate::image_io::ImageError| StageError::Output {
                stage: id.into(),
                path: path.to_path_buf(),
                message: e.to_string(),
            };
            crate::image_io::write_exr_rgb(&exr, w, h, &pixels, &[]).map_err(|e| io(&exr, e))?;
            crate::image_io::write_png_preview(&png, w, h, &pixels, None).map_err(|e| io(&png, e))?;
            let write_ms = ms(t0);
            let rays: u64 = est.iter().map(|e| e.rays).sum();
            let mut noise: Vec<f64> = est.iter().map(|e| e.rel_stderr).collect();
            noise.sort_by(f64::total_cmp);
            let pct = |q: f64| noise.get(((noise.len() as f64 - 1.0) * q).round() as usize).copied().unwrap_or(0.0);
            let n = est.len().max(1) as f64;
            let mean_irradiance = [0, 1, 2].map(|c| est.iter().map(|e| e.irradiance[c]).sum::<f64>() / n);
            let secs = (trace_ms / 1e3).max(1e-9);
            modes.push(ModeSummary {
                mode,
                trace_ms,
                write_ms,
                texels: est.len(),
                samples: self.samples,
                rays,
                texels_per_s: est.len() as f64 / secs,
                rays_per_s: rays as f64 / secs,
                noise_median: pct(0.5),
                noise_p90: pct(0.9),
                mean_irradiance,
                exr: exr.clone(),
                texel_samples: atlas
                    .texels
                    .iter()
                    .step_by((atlas.texels.len() / 32).max(1))
                    .map(|t| (t.pixel % atlas.width, t.pixel / atlas.width, pixels[t.pixel as usize]))
                    .collect(),
            });
            outputs.push(exr);
            outputs.push(png);
        }
        let reference = (self.reference_texels > 0)
            .then(|| {
                let truth = report::reference(&scene, &bvh, &check_points, self.reference_samples, self.seed ^ 0x5eed);
                let errors = check_modes
                    .iter()
                    .map(|(m, e)| {
                        NoiseCorrected::of_rgb(e, &truth.mean, &truth.variance).map(|x| (*m, x)).map_err(|e| {
                            fail(
                                format!("the path-traced reference cannot judge the bake: {e}"),
                                "light the baked surfaces, or set reference_texels: 0 to skip the check",
                            )
                        })
                    })
                    .collect::<Result<Vec<_>, _>>()?;
                Ok(ReferenceCheck {
                    texels: check_points.len(),
                    samples: self.reference_samples,
                    ms: truth.ms,
                    reference_rel_stderr: truth.rel_stderr,
                    errors,
                    mean_ratio: check_modes
                        .iter()
                        .map(|(m, e)| (*m, report::mean_luminance(e) / report::mean_luminance(&truth.mean)))
                        .collect(),
                })
            })
            .transpose()?;
        let t0 = Instant::now();
        let probes = self.bake_probes(id, &scene, &bvh, table.as_ref(), &dir, &mut outputs)?;
        let probes_ms = if probes > 0 { ms(t0) } else { 0.0 };
        let summary = BakeSummary {
            scene: scene_path,
            import_ms,
            bvh_ms,
            table_ms,
            atlas_ms,
            atlas_size: [atlas.width, atlas.height],
            charts: atlas
                .charts
                .iter()
                .map(|c| (scene.meshes[c.mesh].name.clone(), c.x, c.y, c.width, c.height))
                .collect(),
            skipped: atlas.skipped.iter().map(|s| (s.name.clone(), s.reason.clone())).collect(),
            modes,
            reference,
            probes_ms,
            probes,
        };
        let json_path = dir.join("summary.json");
        let json = serde_json::to_vec_pretty(&summary).map_err(|e| fail(e.to_string(), "report this bug"))?;
        crate::cache::write_atomic(&json_path, &json).map_err(|e| StageError::Output {
            stage: id.into(),
            path: json_path.clone(),
            message: e.to_string(),
        })?;
        outputs.push(json_path);
        let line = summary
            .modes
            .iter()
            .map(|m| {
                format!(
                    "{} {:.0} ms ({:.0} texels/s, noise {:.1} %)",
                    m.mode.name(),
                    m.trace_ms,
                    m.texels_per_s,
                    100.0 * m.noise_median
                )
            })
            .collect::<Vec<_>>()
            .join(", ");
        let check = summary.reference.as_ref().map_or(String::new(), |r| {
            let errs: Vec<String> = r.errors.iter().map(|(m, e)| format!("{} {}", m.name(), e.percent())).collect();
            let noise = r.errors.first().map_or(0.0, |e| e.1.reference_noise);
            format!(
                "; vs path tracing on {} texels ({} paths, noise {:.1} %): {}",
                r.texels,
                r.samples,
                100.0 * noise,
                errs.join(", ")
            )
        });
        Ok(StageOutcome {
            outputs,
            summary: format!(
                "{} texels in a {}×{} atlas: {line}{}{check} → {}",
                atlas.texels.len(),
                atlas.width,
                atlas.height,
                if probes > 0 { format!(", {probes} probes") } else { String::new() },
                dir.display()
            ),
        })
    }

    /// `voltab report` for this stage: the error-against-time ladder of [`report::ladder`] written into
    /// `report_dir` as `<id>-lightmap.json`, `.md` and a PNG plot. Tables are read from `ctx.out_dir`.
    pub fn report(
        &self,
        id: &str,
        ctx: &StageContext,
        report_dir: &Path,
        opts: &report::LadderOptions,
    ) -> Result<report::BakeReport, StageError> {
        let fail =
            |message: String| StageError::Input { stage: id.into(), message, help: "fix the stage's inputs".into() };
        let out =
            |path: &Path, message: String| StageError::Output { stage: id.into(), path: path.to_path_buf(), message };
        let Prepared { scene, bvh, table, atlas, .. } = self.prepare(id, ctx)?;
        let say = |m: &str| {
            if ctx.progress {
                eprintln!("{m}");
            }
        };
        let r = report::ladder(id, &scene, &bvh, table.as_ref(), self, &atlas, opts, &say).map_err(fail)?;
        std::fs::create_dir_all(report_dir).map_err(|e| out(report_dir, e.to_string()))?;
        let json = report_dir.join(format!("{id}-lightmap.json"));
        let bytes = serde_json::to_vec_pretty(&r).map_err(|e| out(&json, e.to_string()))?;
        crate::cache::write_atomic(&json, &bytes).map_err(|e| out(&json, e.to_string()))?;
        let md = report_dir.join(format!("{id}-lightmap.md"));
        crate::cache::write_atomic(&md, report::markdown(&r).as_bytes()).map_err(|e| out(&md, e.to_string()))?;
        report::plot(&r, report_dir).map_err(|e| out(report_dir, e))?;
        Ok(r)
    }

    /// `voltab validate`: every mode of this stage at `count` texels of its atlas (the subset its own
    /// reference check uses), at the stage's samples per texel, with the time of each mode. The scene is
    /// returned too, so the caller judges the texels against an independent renderer on the same import.
    pub fn texel_check(&self, id: &str, ctx: &StageContext, count: usize) -> Result<TexelCheck, StageError> {
        let fail = |message: String| StageError::Input { stage: id.into(), message, help: "check the table".into() };
        let Prepared { scene, bvh, table, atlas, .. } = self.prepare(id, ctx)?;
        let points = report::subset(&atlas, count);
        let mut modes = Vec::new();
        for &mode in &self.modes {
            let (irradiance, ms) =
                report::bake(&scene, &bvh, table.as_ref(), self, mode, self.samples, &points).map_err(fail)?;
            modes.push((mode, irradiance, ms));
        }
        Ok(TexelCheck { scene, points, modes })
    }

    /// `voltab bench --suite bake`: every mode over the whole atlas at this stage's quality (texels/s, rays/s,
    /// overhead of Shadow and Full over Surface measured in one run), and the speed-up of the Full bake
    /// over the brute-force reference at equal error on a 256-texel subset (the [`report::ladder`]).
    pub fn bench(&self, id: &str, ctx: &StageContext) -> Result<Vec<crate::stages::BenchRow>, StageError> {
        let fail =
            |message: String| StageError::Input { stage: id.into(), message, help: "fix the stage's inputs".into() };
        let Prepared { scene, bvh, table, atlas, points, .. } = self.prepare(id, ctx)?;
        let mut timed = Vec::new();
        for mode in [BakeMode::Surface, BakeMode::Shadow, BakeMode::Full] {
            let tr = Transport::new(&scene, &bvh, table.as_ref(), self.transport_options(mode))
                .map_err(|e| fail(e.to_string()))?;
            let t0 = Instant::now();
            let est = bake_points(&tr, &points, ctx.progress, mode.name()).map_err(|e| fail(e.to_string()))?;
            let ms = ms(t0);
            let rays: u64 = est.iter().map(|e| e.rays).sum();
            timed.push((mode, ms, rays));
        }
        let (_, surface_ms, _) = timed[0];
        let mut rows: Vec<crate::stages::BenchRow> = timed
            .iter()
            .skip(1)
            .map(|(mode, t, rays)| crate::stages::BenchRow {
                what: format!(
                    "bake {id}: {} vs Surface ({} texels, {} samples)",
                    mode.name(),
                    points.len(),
                    self.samples
                ),
                baseline_ms: surface_ms,
                candidate_ms: *t,
                speedup: surface_ms / t,
                note: format!(
                    "overhead {:+.0} %; {:.0} texels/s, {:.2} Mrays/s (Surface {:.0} texels/s, {:.2} Mrays/s)",
                    100.0 * (t / surface_ms - 1.0),
                    points.len() as f64 / (t / 1e3),
                    *rays as f64 / (t / 1e3) / 1e6,
                    points.len() as f64 / (surface_ms / 1e3),
                    timed[0].2 as f64 / (surface_ms / 1e3) / 1e6
                ),
            })
            .collect();
        let ladder_opts =
            report::LadderOptions { bake_samples: vec![self.samples], ..report::LadderOptions::default() };
        let say = |m: &str| {
            if ctx.progress {
                eprintln!("{m}");
            }
        };
        let r = report::ladder(id, &scene, &bvh, table.as_ref(), self, &atlas, &ladder_opts, &say).map_err(fail)?;
        if let Some(row) = r.rows.iter().find(|x| x.method == "full") {
            rows.push(crate::stages::BenchRow {
                what: format!("bake {id}: volumetric path tracing vs Full at equal error ({} texels)", r.texels),
                baseline_ms: row.reference_ms_at_equal_error.unwrap_or(f64::NAN),
                candidate_ms: row.ms,
                speedup: row.speedup.unwrap_or(f64::NAN),
                note: format!(
                    "relative RMSE {}{:.4} vs a {}-path reference (floor {:.4}){}",
                    if row.below_floor { "< " } else { "" },
                    row.rel_rmse,
                    r.converged.0,
                    r.floor,
                    if row.extrapolated { "; reference time extrapolated (t^-1/2)" } else { "" }
                ),
            });
        }
        Ok(rows)
    }

    /// Imports the scene, builds its BVH, opens the table (when needed) and lays out the atlas, timing each.
    fn prepare(&self, id: &str, ctx: &StageContext) -> Result<Prepared, StageError> {
        let fail = |message: String, help: &str| StageError::Input { stage: id.into(), message, help: help.into() };
        let t0 = Instant::now();
        let scene = ctx
            .scenes
            .load(&self.scene_path(ctx.base_dir))
            .map_err(|e| fail(e.to_string(), "fix the scene file or the scene field"))?;
        let import_ms = ms(t0);
        let t0 = Instant::now();
        let bvh = SceneBvh::build(&scene);
        let bvh_ms = ms(t0);
        let t0 = Instant::now();
        let table = self.open_table(id, ctx, &scene)?;
        let table_ms = if table.is_some() { ms(t0) } else { 0.0 };
        let t0 = Instant::now();
        let atlas = atlas::build(&scene, &self.atlas_options())
            .map_err(|e| fail(e.to_string(), "add lightmap UVs to the scene's meshes"))?;
        let points = atlas
            .texels
            .iter()
            .map(|t| TexelPoint {
                position: t.position,
                normal: t.normal,
                geometric_normal: t.geometric_normal,
                cell: u64::from(t.pixel),
            })
            .collect();
        let atlas_ms = ms(t0);
        Ok(Prepared { scene, bvh, table, atlas, points, import_ms, bvh_ms, table_ms, atlas_ms })
    }

    fn atlas_options(&self) -> atlas::AtlasOptions {
        atlas::AtlasOptions {
            texels_per_metre: self.texels_per_metre,
            min_size: self.min_size,
            max_size: self.max_size,
            padding: 2,
        }
    }

    /// The transport options of `mode`.
    pub fn transport_options(&self, mode: BakeMode) -> TransportOptions {
        TransportOptions {
            mode,
            samples: self.samples,
            scatter_samples: self.scatter_samples,
            bounces: self.bounces,
            backscatter: self.backscatter,
            seed: self.seed,
        }
    }

    /// Opens the table when a Full bake of a scene with media needs it (only the profiles of the scene's
    /// light kinds and the g slices of its media).
    fn open_table(&self, id: &str, ctx: &StageContext, scene: &Scene) -> Result<Option<ZhResponseTable>, StageError> {
        let has_media = scene.media.iter().any(|m| m.sigma_s.iter().any(|&s| s > 0.0));
        let Some(table_id) = self.table_ref() else { return Ok(None) };
        if !has_media {
            return Ok(None);
        }
        let mut profiles = vec![EmitterProfile::Area];
        for l in &scene.lights {
            let p = match l.kind {
                crate::scene::LightKind::Point { .. } | crate::scene::LightKind::Spot { .. } => EmitterProfile::Point,
                crate::scene::LightKind::Directional { .. } => EmitterProfile::Directional,
                _ => EmitterProfile::Area,
            };
            if !profiles.contains(&p) {
                profiles.push(p);
            }
        }
        profiles.sort();
        let gs: Vec<f64> = scene.media.iter().flat_map(|m| m.g).collect();
        let path = ctx.out_dir.join(format!("{table_id}.vtab"));
        ZhResponseTable::open(&path, Some(&profiles), Some(&gs)).map(Some).map_err(|e| StageError::Table {
            stage: id.into(),
            path,
            message: format!("{e} (the scene's media have g = {gs:?})"),
        })
    }
}

/// What every use of a bake stage (run, report, bench) starts from.
struct Prepared {
    scene: std::sync::Arc<Scene>,
    bvh: SceneBvh,
    table: Option<ZhResponseTable>,
    atlas: atlas::Atlas,
    /// One receiver per atlas texel.
    points: Vec<TexelPoint>,
    import_ms: f64,
    bvh_ms: f64,
    table_ms: f64,
    atlas_ms: f64,
}

/// The bake at a subset of its texels ([`BakeLightmaps::texel_check`]).
#[derive(Debug)]
pub struct TexelCheck {
    /// The imported scene the bake read.
    pub scene: std::sync::Arc<Scene>,
    /// The texels.
    pub points: Vec<TexelPoint>,
    /// Per mode: irradiance per texel \[W/m²\], RGB, and the wall time \[ms\].
    pub modes: Vec<(BakeMode, Vec<[f64; 3]>, f64)>,
}

/// A receiver of the bake.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TexelPoint {
    /// Position \[m\].
    pub position: [f64; 3],
    /// Unit shading normal.
    pub normal: [f64; 3],
    /// Unit geometric normal (same side).
    pub geometric_normal: [f64; 3],
    /// Random-stream cell (the atlas pixel).
    pub cell: u64,
}

/// The irradiance of every point, in parallel (any thread count gives the same bits), with a progress bar
/// on a terminal.
pub fn bake_points(
    tr: &Transport,
    points: &[TexelPoint],
    progress: bool,
    label: &str,
) -> Result<Vec<Estimate>, transport::TransportError> {
    let bar = crate::compile::progress_bar(progress, points.len() as u64, format!("bake {label}: texels"));
    let out: Result<Vec<Vec<Estimate>>, _> = points
        .par_chunks(64)
        .map(|chunk| {
            let r: Result<Vec<Estimate>, _> =
                chunk.iter().map(|p| tr.receiver(p.position, p.normal, p.geometric_normal, p.cell)).collect();
            bar.inc(chunk.len() as u64);
            r
        })
        .collect();
    bar.finish_and_clear();
    Ok(out?.into_iter().flatten().collect())
}

impl super::Stage for BakeLightmaps {
    fn kind(&self) -> &'static str {
        BakeLightmapsRaw::KIND
    }
    fn table_refs(&self) -> Vec<(&'static str, String, &'static str)> {
        let kind = crate::tables::zh_response::ZhResponseRaw::KIND;
        self.table_ref().map(|t| ("table", t.to_string(), kind)).into_iter().collect()
    }
    fn validate(&self) -> Vec<FieldIssue> {
        BakeLightmaps::validate(self)
    }
    fn scenes(&self, base_dir: &Path) -> Vec<PathBuf> {
        vec![self.scene_path(base_dir)]
    }
    fn plan(
        &self,
        _scenes: &super::planning::PlannedScenes,
        kept: &super::planning::KeptTables,
    ) -> super::planning::StageDecision {
        match self.table_ref() {
            Some(t) if kept(t).is_none() => super::planning::table_skipped(t),
            _ => super::planning::StageDecision::Run {
                reason: format!("bakes {}", self.scene),
                def: Box::new(super::StageDef::BakeLightmaps(self.clone())),
            },
        }
    }
    fn run(&self, id: &str, ctx: &StageContext) -> Result<StageOutcome, StageError> {
        BakeLightmaps::run(self, id, ctx)
    }
    fn report(&self, id: &str, ctx: &StageContext, report_dir: &Path) -> Result<Option<String>, StageError> {
        let r = BakeLightmaps::report(self, id, ctx, report_dir, &report::LadderOptions::default())?;
        Ok(Some(report::markdown(&r)))
    }
    fn bench_focus(&self) -> Option<super::BenchFocus> {
        Some(super::BenchFocus::Bake)
    }
    /// The bake's rows say it all: its text is empty.
    fn bench(&self, id: &str, ctx: &StageContext) -> Result<Option<(String, Vec<super::BenchRow>)>, StageError> {
        BakeLightmaps::bench(self, id, ctx).map(|rows| Some((String::new(), rows)))
    }
}

fn ms(t0: Instant) -> f64 {
    t0.elapsed().as_secs_f64() * 1e3
}
