//! `PopRender`: scene + `PopPreset` table (+ an environment map) → elek2014 Principal-Ordinates
//! Propagation of the scene's global medium lit by its directional lights (Sec. 4), its point, spot and
//! sphere lights (radial grids, Sec. 6), its area lights and the light its surfaces reflect (VPLs from
//! the emitters and from reflective shadow maps, Sec. 6) and the environment's principal ordinates
//! (Sec. 5), ray-marched
//! into an EXR + PNG, with an optional comparison against brute-force volumetric path tracing.
//!
//! **Input.** A scene file (relative to the pipeline file) with a perspective camera, one global
//! medium (homogeneous or exponential height fog; optionally multiplied by a raw `f32` or EXR-slice
//! density volume spanning the scene's bounds), its lights and optionally an environment: the stage's
//! latitude–longitude EXR `environment` map or, when that field is empty, the scene's USD `DomeLight`
//! (its texture × intensity, rotated as the dome is; a uniform map without a texture; see
//! [`env_map::dome_map`]). When both are present the stage's map wins and `skipped` in
//! `summary.json` says the dome was overridden; an unreadable dome texture is an error naming the USD
//! file, the prim and the texture. The id of a compiled `PopPreset` table (grid, iterations, ε_L, ε_a,
//! residuum switch, flow table). **Phases** (elek2014 Fig. 14 names, in
//! `summary.json`): import → BVH → G-buffer → voxelisation → (environment: ordinates, Sec. 5.1) → per
//! directional light or ordinate: grid and medium downsampling, initialisation (Sec. 4.1), propagation
//! (Eqs. 2–8), isotropic residuum (Sec. 5.4, merged across the ordinates) → merge (Sec. 5.3) →
//! ray marching with joint-bilateral upsampling (Sec. 4.4) → `<out>/<stage>/pop.exr` (layers
//! `scattered`, `transmittance`, `colour`) with PNG previews and `summary.json`.
//!
//! **Check** (with `fig12_photons > 0`): elek2014 Fig. 12 with this stage's preset — the unit cube
//! (`σ_s = 4`, albedo 1, a directional light, `g` = 0, 0.7, 0.96) propagated by POP and light traced by
//! [`crate::reference::grid_mc`]: collided fluence and radiance distributions in the middle slice, and
//! images of the cube against the camera path tracer (`fig12_g*.png`, `summary.json`). The scene itself
//! is not path traced: voltab's path tracer fills space with the global medium without bound (so the
//! sun reaches nothing inside a closed room), while POP, like the paper, confines the medium to the
//! scene's bounds.

use std::path::Path;
use std::time::Instant;

use serde::{Deserialize, Serialize};

use crate::render::environment::{self as env_map, EnvMap};
use crate::render::{Image, RgbImage, ViewCamera};
use crate::report::noisy::NoiseCorrected;
use crate::scene::bvh::SceneBvh;
use crate::scene::{EnvironmentLight, Scene};
use crate::stages::pop::environment::{self, EnvOrdinate, OrdinateSet};
use crate::stages::pop::grid::Grid;
use crate::stages::pop::merge;
use crate::stages::pop::propagate::{self, FlowTable, Observer, PhaseTimes, Settings};
use crate::stages::pop::radial::RadialGrid;
use crate::stages::pop::radial_propagate;
use crate::stages::pop::render::{self, MarchOptions};
use crate::stages::pop::scene::{self as pop_scene, BvhOccluder, Environment, RawDensity, SceneMedia};
use crate::stages::view::{self, ms};
use crate::stages::{StageContext, StageError, StageOutcome};
use crate::tables::FieldIssue;
use crate::tables::pop_preset::PopPresetTable;

mod bench;
mod check;
mod frame;
mod report;

pub use check::FIG12_G;
use check::cube_settings;
use frame::*;
pub use frame::{compose, merge_dims, propagate_on, radial_settings, render_frame, settings_for};
pub use report::LadderPoint;

crate::declare_params! {
    /// Render a scene's global medium lit by its directional lights with elek2014's Principal-Ordinates
    /// Propagation, using a `PopPreset` table.
    raw PopRenderRaw => resolved PopRender, kind "PopRender" {
        /// Scene file (.gltf, .glb, .usda, .usdc, .usd, .usdz), relative to the pipeline file.
        scene: String = String::new(), unit = "", range = "path to a scene file";
        /// Id of the `PopPreset` table (grid, iterations, thresholds, flow table).
        table: String = String::new(), unit = "", range = "id of a PopPreset table in this pipeline";
        /// Index of the scene camera to render.
        camera: u32 = 0, unit = "", range = "0 to the scene's camera count - 1";
        /// Image width.
        width: u32 = 640, unit = "px", range = "1 to 8192";
        /// Image height.
        height: u32 = 480, unit = "px", range = "1 to 8192";
        /// Paths per pixel of the vacuum colour buffer (direct light at the first hit).
        colour_samples: u32 = 8, unit = "paths", range = "1 to 65536";
        /// Voxels of the scene medium along the scene's longest axis (the medium volume POP samples).
        voxels: u32 = 64, unit = "voxels", range = "1 to 1024";
        /// Raw little-endian f32 density volume (x fastest) spanning the scene's bounds, relative to the
        /// pipeline file, multiplying the medium's density; empty: none.
        density_raw: String = String::new(), unit = "", range = "empty or path to a .raw file";
        /// Folder of EXR images, one z slice of a density volume per file in file-name order (x = width,
        /// y = height with row 0 at the top, channel `density`, `Y`, `R` or `A`), spanning the scene's
        /// bounds and multiplying the medium's density, relative to the pipeline file; empty: none. Not
        /// with `density_raw`.
        density_slices: String = String::new(), unit = "", range = "empty or path to a folder of .exr slices";
        /// Voxels of `density_raw` along x, y, z.
        density_dims: [u32; 3] = [0, 0, 0], unit = "voxels", range = "each 1 to 1024 when density_raw is given";
        /// VPLs per area light or emissive mesh (instant radiosity, elek2014 Sec. 6): Lambertian point
        /// lights on radial grids, each an equal share of the emitter's area (rect and disk lights round
        /// up to a square number); 0 skips area lights.
        vpls: u32 = 4, unit = "VPLs per emitter", range = "0 to 256";
        /// VPLs for the direct light the scene's surfaces reflect into the medium (instant radiosity from
        /// reflective shadow maps of every light, elek2014 Sec. 6), placed over all maps in proportion
        /// to the reflected flux; 0: surfaces only occlude.
        surface_vpls: u32 = 32, unit = "VPLs", range = "0 to 1024";
        /// Texels per side of each light's reflective shadow map (used when surface_vpls > 0).
        rsm_size: u32 = 64, unit = "texels", range = "1 to 1024";
        /// Latitude-longitude HDR environment map (EXR with R, G, B; row 0 up, centre column toward +Z)
        /// lighting the medium through principal ordinates (elek2014 Sec. 5), relative to the pipeline
        /// file; it overrides the scene's DomeLight (noted in the summary's `skipped`). Empty: the scene's
        /// DomeLight if it has one (texture × its intensity, rotated with the dome), else none.
        environment: String = String::new(), unit = "", range = "empty or path to an .exr file";
        /// Multiplier of the environment map's radiance (not of a DomeLight's, which has its own intensity).
        environment_intensity: f64 = 1.0, unit = "", range = "0 to 1e6";
        /// Principal ordinates of the environment at most (0: the preset's `ordinates`).
        environment_ordinates: u32 = 0, unit = "directions", range = "0 to 4096";
        /// How the ordinates' directions are chosen: "importance" (sampled from the map's luminance,
        /// Sec. 5.1) or "fibonacci" (the preset's well-spread set).
        environment_set: String = String::from("importance"), unit = "", range = "importance | fibonacci";
        /// Range width of the joint-bilateral upsampling relative to the largest density (0: trilinear).
        range_sigma: f64 = 0.25, unit = "", range = "0 to 100";
        /// Photons of the elek2014 Fig. 12 comparison on the unit cube (σ_s = 4, albedo 1, g = 0, 0.7,
        /// 0.96) against Monte-Carlo light tracing, with this stage's preset (0: none).
        fig12_photons: u32 = 0, unit = "photons", range = "0 to 100000000";
        /// Width and height of the Fig. 12 cube images (POP against path tracing).
        fig12_size: u32 = 64, unit = "px", range = "4 to 1024";
        /// Paths per pixel of the path-traced cube images.
        fig12_samples: u32 = 64, unit = "paths", range = "1 to 100000";
        /// Paths per pixel of an independent path-traced image of the scattered light (the scene with
        /// black surfaces, the lights POP propagates and the medium confined to POP's box) that POP's
        /// scattered light is compared with (0: none).
        reference_samples: u32 = 0, unit = "paths", range = "0 to 100000";
        /// Width of the reference comparison (both images; the height follows the camera's aspect).
        reference_width: u32 = 64, unit = "px", range = "4 to 1024";
        /// Output folder name in the output directory; empty means the stage id.
        output: String = String::new(), unit = "", range = "plain folder name";
    }
}

crate::stages::view::impl_view_fields!(PopRender);

/// One light's propagation.
#[derive(Debug, Clone, Serialize)]
pub struct LightRun {
    /// Light name.
    pub light: String,
    /// `"directional"` (rectilinear grid, elek2014 Sec. 4), `"environment"` (one ordinate of the
    /// environment map on its rectilinear grid, Sec. 5) or `"point"` (radial grid, Sec. 6; spot and sphere
    /// lights too).
    pub kind: &'static str,
    /// Grid cells: (lateral, lateral, along the light), or for a radial grid (octahedral n, n, shells).
    pub grid: [usize; 3],
    /// Cell size \[m\]; for a radial grid the innermost shell's outer radius, the outermost's, and the
    /// angular cell size \[rad\].
    pub cell: [f64; 3],
    /// Eq. 10's switch iteration `m'`.
    pub switch_iteration: usize,
    /// Anisotropic iterations run.
    pub anisotropic_iterations: usize,
    /// Isotropic residuum iterations run.
    pub isotropic_iterations: usize,
    /// Energy left after the last iteration, relative to the seeded energy.
    pub residual_energy: f64,
    /// Grid build and medium downsampling \[ms\].
    pub grid_ms: f64,
    /// Phase times \[ms\] (on the GPU: initialisation on the CPU, the iterations' GPU times).
    pub phases_ms: PhaseMs,
    /// Merging this radial grid into the medium-aligned render grid \[ms\] (0 for directional lights).
    pub merge_ms: f64,
    /// `"cpu"` or `"gpu"`: where the iterations ran.
    pub device: &'static str,
    /// GPU time per pass kind (empty on the CPU).
    pub gpu_passes: Vec<crate::render::gpu::PassTime>,
}

/// [`PhaseTimes`] in milliseconds.
#[derive(Debug, Clone, Copy, Serialize, Deserialize)]
pub struct PhaseMs {
    /// Initialisation sweep.
    pub initialisation: f64,
    /// Anisotropic propagation (accumulation included).
    pub propagation: f64,
    /// Isotropic residuum (accumulation included).
    pub residuum: f64,
    /// Accumulation alone.
    pub accumulation: f64,
}

impl From<PhaseTimes> for PhaseMs {
    fn from(t: PhaseTimes) -> Self {
        Self {
            initialisation: t.initialisation * 1e3,
            propagation: t.propagation * 1e3,
            residuum: t.residuum * 1e3,
            accumulation: t.accumulation * 1e3,
        }
    }
}

/// One `g` of the Fig. 12 comparison.
#[derive(Debug, Clone, Serialize)]
pub struct Fig12Row {
    /// Phase mean cosine.
    pub g: f64,
    /// Mid-slice errors, iterations and times.
    pub slice: crate::stages::pop::fig12::SliceComparison,
    /// POP's cube image against path tracing, noise removed, with its floor.
    pub image: NoiseCorrected,
    /// POP (propagation + ray march) and path-tracing times for the image \[ms\].
    pub image_ms: [f64; 2],
}

/// What `summary.json` holds.
#[derive(Debug, Clone, Serialize)]
pub struct PopSummary {
    /// Scene file.
    pub scene: String,
    /// Image size.
    pub size: [usize; 2],
    /// The medium and its voxels.
    pub medium: String,
    /// Voxels of the medium volume.
    pub voxels: [usize; 3],
    /// Import, BVH, G-buffer, voxelisation \[ms\].
    pub setup_ms: [f64; 4],
    /// Per light.
    pub lights: Vec<LightRun>,
    /// Ray marching \[ms\].
    pub ray_march_ms: f64,
    /// Lights and media left out.
    pub skipped: Vec<String>,
    /// elek2014 Fig. 12 against Monte-Carlo light tracing.
    pub fig12: Vec<Fig12Row>,
    /// POP's scattered light against path tracing of the same view (`reference_samples > 0`).
    pub reference: Option<ReferenceComparison>,
    /// The environment lighting (the `environment` map, or the scene's DomeLight).
    pub environment: Option<EnvSummary>,
    /// The VPLs of the surfaces' reflected light (when `surface_vpls > 0`): maps, VPLs, flux, time.
    pub reflection: Option<pop_scene::Reflection>,
}

/// POP's scattered light against an independent path-traced image of it.
#[derive(Debug, Clone, Serialize)]
pub struct ReferenceComparison {
    /// Image size of both.
    pub size: [usize; 2],
    /// Paths per pixel of the reference.
    pub samples: u32,
    /// POP's scattered light against it over the pixels and channels compared, relative to the
    /// reference's mean, its noise removed, with its floor, interval, the raw error and the noise.
    pub error: NoiseCorrected,
    /// Ratio of POP's summed scattered light to the reference's (energy bias).
    pub total_ratio: f64,
    /// POP frame (all phases) and path-tracing times \[ms\].
    pub ms: [f64; 2],
}

/// A rendered POP frame (no G-buffer colour).
pub struct PopFrame {
    /// Scattered light of all lights.
    pub scattered: RgbImage,
    /// Transmittance to the surface.
    pub transmittance: RgbImage,
    /// Per light.
    pub lights: Vec<LightRun>,
    /// Ray marching \[ms\].
    pub march_ms: f64,
    /// The environment's ordinates and their phases (when the stage has an environment map).
    pub environment: Option<EnvSummary>,
}

/// The environment lighting of a frame (elek2014 Sec. 5).
#[derive(Debug, Clone, Serialize)]
pub struct EnvSummary {
    /// Map file (the stage's `environment`), or `DomeLight <prim> (<texture>)`.
    pub map: String,
    /// Map size.
    pub size: [usize; 2],
    /// `∫ L dω` of the map per channel \[W/m²\].
    pub integral: [f64; 3],
    /// The ordinates propagated (direction of travel, irradiance, initial anisotropy, cell solid angle).
    pub ordinates: Vec<EnvOrdinate>,
    /// Whether the ordinates were placed with the camera's importance (Sec. 5.2; the preset's
    /// `importance`, with `environment_set: "importance"`).
    pub importance: bool,
    /// Importance propagation and its projection onto the directions (Fig. 14 "importance") \[ms\].
    pub importance_ms: f64,
    /// Choosing the ordinates (Fig. 14 "ordinates") \[ms\].
    pub ordinates_ms: f64,
    /// Merging the ordinates' accumulation grids into the medium-aligned grid (Sec. 5.3) \[ms\].
    pub merge_ms: f64,
}

impl PopRender {
    /// Range checks.
    pub fn validate(&self) -> Vec<FieldIssue> {
        let mut v = self.fields().validate();
        let mut issue = |field: &'static str, message: String, help: &str| {
            v.push(FieldIssue { field, message, help: help.into() });
        };
        if self.table.is_empty() {
            issue("table", "table is empty".into(), "give the id of a PopPreset table, e.g. table: \"pop_realtime\"");
        }
        if !(1..=1024).contains(&self.voxels) {
            issue("voxels", format!("voxels = {}", self.voxels), "use 1 to 1024");
        }
        if !self.density_raw.is_empty() && self.density_dims.iter().any(|d| !(1..=1024).contains(d)) {
            issue(
                "density_dims",
                format!("density_dims = {:?} with density_raw = \"{}\"", self.density_dims, self.density_raw),
                "give the raw volume's voxels per axis, each 1 to 1024",
            );
        }
        if !self.density_raw.is_empty() && !self.density_slices.is_empty() {
            issue(
                "density_slices",
                format!("both density_raw = \"{}\" and density_slices = \"{}\"", self.density_raw, self.density_slices),
                "give one density volume: a raw file or a folder of EXR slices",
            );
        }
        if !(self.environment_intensity.is_finite() && (0.0..=1e6).contains(&self.environment_intensity)) {
            issue(
                "environment_intensity",
                format!("environment_intensity = {}", self.environment_intensity),
                "use 0 to 1e6 (1 keeps the map's radiance)",
            );
        }
        if self.surface_vpls > 1024 {
            issue(
                "surface_vpls",
                format!("surface_vpls = {}", self.surface_vpls),
                "use 0 (surfaces only occlude) to 1024 VPLs",
            );
        }
        if !(1..=1024).contains(&self.rsm_size) {
            issue("rsm_size", format!("rsm_size = {}", self.rsm_size), "use 1 to 1024 texels per side");
        }
        if self.vpls > 256 {
            issue("vpls", format!("vpls = {}", self.vpls), "use 0 (skip area lights) to 256 VPLs per emitter");
        }
        if self.environment_ordinates > 4096 {
            issue(
                "environment_ordinates",
                format!("environment_ordinates = {}", self.environment_ordinates),
                "use 0 (the preset's count) to 4096",
            );
        }
        if self.ordinate_set().is_none() {
            issue(
                "environment_set",
                format!("environment_set = \"{}\"", self.environment_set),
                "use \"importance\" or \"fibonacci\"",
            );
        }
        if !(self.range_sigma.is_finite() && (0.0..=100.0).contains(&self.range_sigma)) {
            issue("range_sigma", format!("range_sigma = {}", self.range_sigma), "use 0 (trilinear) to 100");
        }
        if self.fig12_photons > 100_000_000 {
            issue("fig12_photons", format!("fig12_photons = {}", self.fig12_photons), "use 0 (none) to 100000000");
        }
        if !(4..=1024).contains(&self.fig12_size) {
            issue("fig12_size", format!("fig12_size = {}", self.fig12_size), "use 4 to 1024");
        }
        if self.reference_samples > 100_000 {
            issue(
                "reference_samples",
                format!("reference_samples = {}", self.reference_samples),
                "use 0 (no comparison) to 100000",
            );
        }
        if !(4..=1024).contains(&self.reference_width) {
            issue("reference_width", format!("reference_width = {}", self.reference_width), "use 4 to 1024");
        }
        if !(1..=100_000).contains(&self.fig12_samples) {
            issue("fig12_samples", format!("fig12_samples = {}", self.fig12_samples), "use 1 to 100000");
        }
        v
    }

    fn open_table(&self, id: &str, ctx: &StageContext) -> Result<PopPresetTable, StageError> {
        let path = ctx.out_dir.join(format!("{}.vtab", self.table));
        PopPresetTable::open(&path).map_err(|e| StageError::Table { stage: id.into(), path, message: e.to_string() })
    }

    /// The scene's media for POP (voxelised, with the raw or EXR-slice density when given), with the
    /// VPLs of the surfaces' reflected light when `surface_vpls > 0`.
    pub fn media(&self, id: &str, ctx: &StageContext, scene: &Scene, bvh: &SceneBvh) -> Result<SceneMedia, StageError> {
        let fail = |message: String| StageError::Input {
            stage: id.into(),
            message,
            help: "fix the scene's medium and lights, or the stage's density_raw / density_dims".into(),
        };
        let raw = if !self.density_slices.is_empty() {
            let (dims, values) = crate::render::voxel::read_exr_slices(&ctx.base_dir.join(&self.density_slices))
                .map_err(|e| StageError::Input {
                    stage: id.into(),
                    message: e.to_string(),
                    help: "give density_slices a folder of EXR images, one z slice per file in name order".into(),
                })?;
            Some(RawDensity { dims, values })
        } else if self.density_raw.is_empty() {
            None
        } else {
            let dims = self.density_dims.map(|d| d as usize);
            let values = crate::render::voxel::read_raw_density(&ctx.base_dir.join(&self.density_raw), dims)
                .map_err(|e| fail(e.to_string()))?;
            Some(RawDensity { dims, values })
        };
        let ordinates = self.environment_ordinates as usize;
        let set = self.ordinate_set().unwrap_or(OrdinateSet::Importance);
        let mut overridden = None;
        let environment = if !self.environment.is_empty() {
            let path = ctx.base_dir.join(&self.environment);
            let map = EnvMap::read_exr(&path, self.environment_intensity).map_err(|e| StageError::Input {
                stage: id.into(),
                message: e.to_string(),
                help: "give environment a latitude-longitude RGB EXR map, relative to the pipeline file".into(),
            })?;
            // The stage's map wins over the scene's dome, and says so in `skipped`.
            overridden = scene.environment.as_ref().map(|dome| {
                format!(
                    "DomeLight {}: overridden by the stage's environment map {} (leave environment empty to light \
                     with the dome)",
                    dome.name, self.environment
                )
            });
            Some(Environment { map, name: self.environment.clone(), ordinates, set })
        } else if let Some(dome) = &scene.environment {
            let map = dome_environment(id, scene, dome)?;
            let what = dome.texture.as_ref().map_or("uniform".to_string(), |t| t.display().to_string());
            Some(Environment { map, name: format!("DomeLight {} ({what})", dome.name), ordinates, set })
        } else {
            None
        };
        let mut media =
            pop_scene::scene_media(scene, self.voxels as usize, raw.as_ref(), environment, self.vpls as usize)
                .map_err(fail)?;
        pop_scene::add_reflection_vpls(&mut media, scene, bvh, self.surface_vpls as usize, self.rsm_size as usize);
        media.skipped.extend(overridden);
        Ok(media)
    }

    /// The ordinate set named by `environment_set`.
    fn ordinate_set(&self) -> Option<OrdinateSet> {
        match self.environment_set.as_str() {
            "importance" => Some(OrdinateSet::Importance),
            "fibonacci" => Some(OrdinateSet::Fibonacci),
            _ => None,
        }
    }

    /// Runs the stage.
    pub fn run(&self, id: &str, ctx: &StageContext) -> Result<StageOutcome, StageError> {
        let fields = self.fields();
        let dir = fields.out_dir(id, ctx)?;
        let table = self.open_table(id, ctx)?;
        let v = fields.load(id, ctx, None)?;
        let t0 = Instant::now();
        let media = self.media(id, ctx, &v.scene, &v.bvh)?;
        // The reflective shadow maps are timed on their own (`reflection` in the summary).
        let voxel_ms = ms(t0) - media.reflection.as_ref().map_or(0.0, |r| r.ms);
        let g = &v.gbuffer;
        let distance: Vec<f64> = g.distance.data.iter().map(|&d| f64::from(d)).collect();
        let fail = |message: String| StageError::Input { stage: id.into(), message, help: "check the scene".into() };
        let frame =
            render_frame(&media, &v.bvh, &table, &g.camera, &distance, self.range_sigma, ctx.device).map_err(fail)?;
        let image = compose(&g.colour, &frame, true);
        let mut outputs = view::write_image(
            id,
            &dir,
            "pop",
            &image,
            &[("scattered", &frame.scattered), ("transmittance", &frame.transmittance), ("colour", &g.colour)],
        )?;
        let png = dir.join("pop_scattered.png");
        crate::image_io::write_png_preview(
            &png,
            frame.scattered.width,
            frame.scattered.height,
            &frame.scattered.data,
            None,
        )
        .map_err(|e| StageError::Output { stage: id.into(), path: png.clone(), message: e.to_string() })?;
        outputs.push(png);
        let fig12 = self.fig12(id, &dir, &table, &mut outputs)?;
        let summary = PopSummary {
            scene: fields.scene_path(ctx.base_dir).display().to_string(),
            size: [g.camera.width, g.camera.height],
            medium: media.medium_name.clone(),
            voxels: media.medium.dims,
            setup_ms: [v.import_ms, v.bvh_ms, g.distance_ms + g.colour_ms, voxel_ms],
            lights: frame.lights.clone(),
            ray_march_ms: frame.march_ms,
            skipped: media.skipped.clone(),
            fig12,
            reference: self.reference(id, ctx, &table, &media, &dir, &mut outputs)?,
            environment: frame.environment.clone(),
            reflection: media.reflection.clone(),
        };
        outputs.push(view::write_json(id, &dir.join("summary.json"), &summary)?);
        let prop_ms: f64 = frame.lights.iter().map(|l| l.phases_ms.propagation + l.phases_ms.residuum).sum();
        let mut line = format!(
            "{}×{}, {} light(s), propagation {prop_ms:.0} ms, ray march {:.0} ms",
            g.camera.width,
            g.camera.height,
            frame.lights.len(),
            frame.march_ms
        );
        if let Some(r) = &summary.reference {
            line.push_str(&format!(
                "; vs path tracing at {}×{} ({} paths/px, noise {:.1} %): scattered light {} off, total ×{:.3}",
                r.size[0],
                r.size[1],
                r.samples,
                100.0 * r.error.reference_noise,
                r.error.percent(),
                r.total_ratio
            ));
        }
        for r in &summary.fig12 {
            line.push_str(&format!(
                "; Fig. 12 g {}: collided fluence {} (light tracer's noise {:.1} %), image {} off",
                r.g,
                r.slice.collided.percent(),
                100.0 * r.slice.collided.reference_noise,
                r.image.percent()
            ));
        }
        Ok(StageOutcome { outputs, summary: format!("{line} → {}", dir.display()) })
    }
}

impl crate::stages::Stage for PopRender {
    fn kind(&self) -> &'static str {
        PopRenderRaw::KIND
    }
    fn table_refs(&self) -> Vec<(&'static str, String, &'static str)> {
        vec![("table", self.table.clone(), crate::tables::pop_preset::PopPresetRaw::KIND)]
    }
    fn validate(&self) -> Vec<FieldIssue> {
        PopRender::validate(self)
    }
    fn scenes(&self, base_dir: &Path) -> Vec<std::path::PathBuf> {
        vec![self.scene_path(base_dir)]
    }
    fn plan(
        &self,
        scenes: &crate::stages::planning::PlannedScenes,
        kept: &crate::stages::planning::KeptTables,
    ) -> crate::stages::planning::StageDecision {
        if kept(&self.table).is_none() {
            return crate::stages::planning::table_skipped(&self.table);
        }
        let def = crate::stages::StageDef::PopRender(self.clone());
        crate::stages::planning::effect(
            def,
            "principal-ordinates propagation",
            &self.scene,
            scenes,
            super::scene::lacks,
        )
    }
    fn run(&self, id: &str, ctx: &StageContext) -> Result<StageOutcome, StageError> {
        PopRender::run(self, id, ctx)
    }
    fn report(&self, id: &str, ctx: &StageContext, report_dir: &Path) -> Result<Option<String>, StageError> {
        PopRender::report(self, id, ctx, report_dir).map(Some)
    }
    fn bench_focus(&self) -> Option<crate::stages::BenchFocus> {
        Some(crate::stages::BenchFocus::Pop)
    }
    fn bench(
        &self,
        id: &str,
        ctx: &StageContext,
    ) -> Result<Option<(String, Vec<crate::stages::BenchRow>)>, StageError> {
        PopRender::bench(self, id, ctx).map(Some)
    }
    fn bench_gpu(
        &self,
        id: &str,
        ctx: &StageContext,
    ) -> Result<Option<(String, Vec<crate::stages::BenchRow>)>, StageError> {
        PopRender::bench_gpu(self, id, ctx).map(Some)
    }
    fn uses_device(&self) -> bool {
        true
    }
}
