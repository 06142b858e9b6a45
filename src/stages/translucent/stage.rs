//! `TranslucentRender`: scene + `MsLobes` table → wang2018 point-based renders of the scene's
//! translucent object with several materials, per-component images, and the error against the
//! brute-force reference.
//!
//! **Input.** A scene file (relative to the pipeline file) with a closed dielectric mesh bounding a
//! medium, point or sphere lights and a perspective camera; the id of a compiled `MsLobes` table whose
//! slices cover the materials (the planner keeps exactly those), and optionally `lobe_tables` tried
//! first: a material reads the first of them that holds its g and channel albedos as nodes (e.g. a
//! φ-resolved table for the strongly forward-scattering materials only; [`LobeTables`]).
//! **Phases.** Import → BVH → per material: light samples, trees and inner irradiance
//! ([`render::prepare`]) → the frame ([`render::render`]) → `<out>/<stage>/<material>.exr` (RGB =
//! the full image; layers `single`, `double`, `multiple`, `bounced`, `rest`), a PNG preview of the
//! image and of each component (wang2018 Fig. 12), and `summary.json`.
//!
//! **Materials.** Names from wang2018 Table 2 (`voltab materials`), their mean free paths times
//! `mfp_scale` metres, the object's index of refraction from the scene; `Scene` renders the scene's
//! own medium.
//!
//! **Check** (with `reference_samples > 0`): at `reference_width` pixels wide, the point-based frame and
//! the path-traced reference ([`reference::render`]) of the same view; `summary.json` holds the MSE over
//! the object's pixels (both images divided by the reference's mean object value, see [`compare`]),
//! with the reference's own noise removed and its floor stated, per component as well, and both run
//! times.

use std::path::{Path, PathBuf};
use std::time::Instant;

use serde::{Deserialize, Serialize};

use crate::reference::translucent::{self as reference, ReferenceOptions};
use crate::render::dielectric::{Emitter, Material, Setup, emitters, find_object};
use crate::render::{Image, RgbImage, ViewCamera};
use crate::report::noisy::NoiseCorrected;
use crate::report::plot::{Plot, Scale, Series, write_png};
use crate::scene::Scene;
use crate::scene::bvh::SceneBvh;
use crate::stages::BenchRow;
use crate::stages::translucent::compare::{self, Comparison};
use crate::stages::translucent::points::PointOptions;
use crate::stages::translucent::render::{self, RenderOptions};
use crate::stages::view::{self, ms};
use crate::stages::{StageContext, StageError, StageOutcome};
use crate::tables::FieldIssue;
use crate::tables::ms_lobes::MsLobesTable;

mod measure;

crate::declare_params! {
    /// Render a scene's translucent object with wang2018's point-based method (single, double, multiple and
    /// bounced scattering from light samples and an `MsLobes` table).
    raw TranslucentRenderRaw => resolved TranslucentRender, kind "TranslucentRender" {
        /// Scene file (.gltf, .glb, .usda, .usdc, .usd, .usdz), relative to the pipeline file.
        scene: String = String::new(), unit = "", range = "path to a scene file with a closed dielectric mesh bounding a medium";
        /// Id of the `MsLobes` table (its slices must cover the materials' albedos and g).
        table: String = String::new(), unit = "", range = "id of an MsLobes table in this pipeline";
        /// Further `MsLobes` tables tried before `table`, in order: a material reads the first that holds its g
        /// as a slice and its three channel albedos as nodes (e.g. a φ-resolved table for the strongly
        /// forward-scattering materials only); every other material reads `table`.
        lobe_tables: Vec<String> = Vec::new(), unit = "", range = "0 to 8 ids of MsLobes tables in this pipeline, each once, none equal to table";
        /// Index of the scene camera to render.
        camera: u32 = 0, unit = "", range = "0 to the scene's camera count - 1";
        /// Image width.
        width: u32 = 512, unit = "px", range = "1 to 8192";
        /// Image height.
        height: u32 = 512, unit = "px", range = "1 to 8192";
        /// Materials to render: wang2018 Table 2 names (Oil, Wax, Milk, Skin, BumpySphere) or Scene (the scene's own medium).
        materials: Vec<String> = vec!["Wax".into(), "Oil".into(), "Skin".into()], unit = "", range = "1 to 16 names, each once";
        /// Scene metres per Table 2 length unit (the presets' mean free paths are multiplied by it).
        mfp_scale: f64 = 0.01, unit = "m", range = "1e-6 to 1e6";
        /// Point lights are rendered as spheres of this radius with the same intensity (a path tracer cannot
        /// connect a point light through a smooth refractive boundary).
        light_radius: f64 = 0.02, unit = "m", range = "> 0 and ≤ 1e6";
        /// Blue-noise light samples on the object's surface (the paper's sweet spot is about 66 000).
        surface_samples: u32 = 16384, unit = "samples", range = "16 to 4000000";
        /// Volume samples per refracted light-ray segment.
        samples_per_ray: u32 = 8, unit = "samples", range = "1 to 256";
        /// Internal reflections followed on light paths.
        light_bounces: u32 = 2, unit = "reflections", range = "0 to 16";
        /// Internal reflections followed on camera paths.
        camera_bounces: u32 = 1, unit = "reflections", range = "0 to 16";
        /// Rays per surface sample gathering the scene's indirect diffuse light (0: none).
        indirect_rays: u32 = 16, unit = "rays", range = "0 to 4096";
        /// The object's light on the scene: its caustic and glow on opaque surfaces, from photons of the light
        /// rays that leave it (seen directly, through the object, and by the surface samples' indirect rays).
        object_light: bool = true, unit = "", range = "true or false";
        /// Phase-sampled rays per camera sample for the first scattering of the scene's light refracted in
        /// (0: from the surface samples' diffuse emission, wang2018 Eq. 8; 16 against 0: Oil MSE 7.8e-3 →
        /// 3.3e-3, Skin 2.5e-3 → 1.7e-3, Wax unchanged).
        scene_rays: u32 = 16, unit = "rays", range = "0 to 4096";
        /// Beams per surface sample, spread in azimuth at the median angle of the internally reflected
        /// light, for its later orders (0: along the inward normal; 4 against 0: Oil MSE 3.3e-3 → 2.5e-3,
        /// Skin 1.74e-3 → 1.63e-3, Wax 1.67e-3 → 1.42e-3).
        grazing_beams: u32 = 4, unit = "beams", range = "0 to 64";
        /// Points over a light tube's cross-section standing for a volume sample in double scattering (Eq. 6)
        /// near it (0: its centre alone, as in wang2018; 16 against 0: Wax MSE 1.45e-3 → 1.16e-3, its double
        /// scattering's own error 1.07e-4 → 1.3e-5, Skin 1.55e-3 → 1.43e-3, Oil unchanged).
        double_disk: u32 = 16, unit = "points", range = "0 to 1024";
        /// Camera samples k_max per segment of a ray reaching the object directly (Eq. 10).
        k_max: u32 = 16, unit = "samples", range = "1 to 4096";
        /// Rays per visible opaque pixel looking for the object's glow (diffuse bounce; 0: none).
        diffuse_rays: u32 = 0, unit = "rays", range = "0 to 4096";
        /// Camera samples per segment of a ray reaching the object after a diffuse bounce.
        diffuse_samples: u32 = 2, unit = "samples", range = "1 to 4096";
        /// Points per emitter for the direct light on opaque surfaces (soft shadows).
        light_samples: u32 = 4, unit = "samples", range = "1 to 65536";
        /// Algorithm 1: solid angle above which a node is always subdivided.
        epsilon1: f64 = 0.1, unit = "sr", range = "> 0, ≥ epsilon2";
        /// Algorithm 1: solid angle above which a node is subdivided where the phase function is large.
        epsilon2: f64 = 0.01, unit = "sr", range = "> 0, ≤ epsilon1";
        /// Solid angle above which a node is subdivided in the cuts for multiple and bounced scattering and the
        /// inner irradiance (1 sr: against 0.5 sr, 30 % less time and the same or lower MSE for Wax, Oil, Skin).
        epsilon_multiple: f64 = 1.0, unit = "sr", range = "> 0 and ≤ 4π";
        /// Solid angle above which a surface node is subdivided in the cut for the later orders of the
        /// boundary's light (its beams). 2 sr against 1 sr: bounced scattering 40 – 50 % faster, MSE Oil
        /// 2.50e-3 → 2.32e-3, Skin 1.63e-3 → 1.55e-3, Wax 1.42e-3 → 1.45e-3; from 2π on only the root is left.
        epsilon_beams: f64 = 2.0, unit = "sr", range = "> 0 and ≤ 4π";
        /// Single-scattering boxes are this many light-tube widths wide (density factor k_v = widen²).
        widen: f64 = 2.0, unit = "", range = "0.25 to 16";
        /// Clamp of the 1/r² of Eq. 6 and 8.
        clamp_mfp: f64 = 0.0625, unit = "mean free paths", range = "0 to 100";
        /// Two-step traversal with 2×2 sharing for single scattering (Sec. 4.3).
        two_step: bool = true, unit = "", range = "true or false";
        /// Half-space image beams for the table's infinite-medium responses (light that leaves near where it
        /// entered is not scattered back).
        boundary_image: bool = true, unit = "", range = "true or false";
        /// Most terms of the series of internal reflections of diffuse light (1: wang2018's single reflection).
        reflection_terms: u32 = 200, unit = "terms", range = "1 to 200";
        /// Multiple and bounced scattering at every n-th pixel and row, interpolated between (Sec. 5.1: 4).
        smooth_stride: u32 = 4, unit = "px", range = "1 to 64";
        /// Paths per pixel of the path-traced reference (0: no comparison).
        reference_samples: u32 = 0, unit = "paths", range = "0 to 1000000";
        /// Width of the comparison images (the height keeps the aspect ratio).
        reference_width: u32 = 96, unit = "px", range = "4 to 4096";
        /// Output folder name in the output directory; empty means the stage id.
        output: String = String::new(), unit = "", range = "plain folder name";
    }
}

/// One material's results in `summary.json`.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct MaterialSummary {
    /// Material name.
    pub material: String,
    /// Id of the `MsLobes` table it read (`lobe_tables` or `table`).
    pub table: String,
    /// σ_t per channel \[1/m\].
    pub sigma_t: [f64; 3],
    /// Albedo per channel.
    pub albedo: [f64; 3],
    /// HG g.
    pub g: f64,
    /// Surface samples, volume samples.
    pub samples: [usize; 2],
    /// The paper's Table 3 columns \[ms\]: pre-processing, single, double + multiple, bounced, rest, total.
    pub times_ms: [f64; 6],
    /// Bytes of samples, trees and aggregates.
    pub memory_bytes: usize,
    /// Mean tree-cut size per camera sample.
    pub mean_cut: f64,
    /// Table look-ups that failed (counted as 0).
    pub failed_lookups: u64,
    /// Against the path-traced reference.
    pub comparison: Option<Comparison>,
}

/// What `summary.json` holds.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct TranslucentSummary {
    /// Scene file.
    pub scene: String,
    /// Image size.
    pub size: [usize; 2],
    /// Lights left out, with why.
    pub skipped_lights: Vec<String>,
    /// Per material.
    pub materials: Vec<MaterialSummary>,
}

impl TranslucentRender {
    fn fields(&self) -> view::ViewFields<'_> {
        view::ViewFields {
            scene: &self.scene,
            camera: self.camera,
            width: self.width,
            height: self.height,
            colour_samples: self.light_samples,
            output: &self.output,
        }
    }

    /// The scene file resolved against the pipeline's folder.
    pub fn scene_path(&self, base_dir: &Path) -> PathBuf {
        self.fields().scene_path(base_dir)
    }

    /// What `scene` lacks for this stage (the planner leaves the stage out then): a refractive object
    /// bounding a medium, or a point or sphere light.
    pub fn lacks(&self, scene: &Scene) -> Option<&'static str> {
        let bvh = crate::scene::bvh::SceneBvh::build(scene);
        if crate::render::dielectric::find_object(scene, &bvh).is_none() {
            Some("closed dielectric mesh bounding a medium")
        } else if crate::render::dielectric::emitters(scene, self.light_radius).0.is_empty() {
            Some("point or sphere light")
        } else {
            None
        }
    }

    /// Range checks.
    pub fn validate(&self) -> Vec<FieldIssue> {
        let mut v = self.fields().validate();
        let mut issue = |field: &'static str, message: String, help: &str| {
            v.push(FieldIssue { field, message, help: help.into() });
        };
        if self.table.is_empty() {
            issue("table", "table is empty".into(), "give the id of an MsLobes table, e.g. table: \"ms_lobes_table2\"");
        }
        if self.lobe_tables.len() > MAX_LOBE_TABLES {
            issue(
                "lobe_tables",
                format!("{} lobe tables", self.lobe_tables.len()),
                &format!("list at most {MAX_LOBE_TABLES} tables"),
            );
        }
        for (i, t) in self.lobe_tables.iter().enumerate() {
            if *t == self.table || self.lobe_tables[..i].contains(t) {
                issue(
                    "lobe_tables",
                    format!("table \"{t}\" is listed twice (lobe_tables and table included)"),
                    "list each table once; `table` is always tried last",
                );
            }
        }
        if self.materials.is_empty() || self.materials.len() > 16 {
            issue("materials", format!("{} materials", self.materials.len()), "give 1 to 16 material names");
        }
        for (i, m) in self.materials.iter().enumerate() {
            if m != "Scene" && crate::tables::ms_lobes::material(m).is_none() {
                let names: Vec<&str> = crate::tables::ms_lobes::materials().iter().map(|m| m.name.as_str()).collect();
                issue("materials", format!("unknown material \"{m}\""), &format!("use one of {names:?} or Scene"));
            }
            if self.materials[..i].contains(m) {
                issue("materials", format!("material \"{m}\" is listed twice"), "list each material once");
            }
        }
        let range = |field: &'static str, x: f64, lo: f64, hi: f64, open_lo: bool| -> Option<FieldIssue> {
            let ok = x.is_finite() && x <= hi && if open_lo { x > lo } else { x >= lo };
            (!ok).then(|| FieldIssue {
                field,
                message: format!("{field} = {x}"),
                help: format!("use a value in {}{lo}, {hi}]", if open_lo { "(" } else { "[" }),
            })
        };
        v.extend(range("mfp_scale", self.mfp_scale, 1e-6, 1e6, false));
        v.extend(range("light_radius", self.light_radius, 0.0, 1e6, true));
        v.extend(range("epsilon1", self.epsilon1, 0.0, 4.0 * std::f64::consts::PI, true));
        v.extend(range("epsilon2", self.epsilon2, 0.0, self.epsilon1.max(0.0), true));
        v.extend(range("epsilon_multiple", self.epsilon_multiple, 0.0, 4.0 * std::f64::consts::PI, true));
        v.extend(range("epsilon_beams", self.epsilon_beams, 0.0, 4.0 * std::f64::consts::PI, true));
        v.extend(range("widen", self.widen, 0.25, 16.0, false));
        v.extend(range("clamp_mfp", self.clamp_mfp, 0.0, 100.0, false));
        for (field, x, lo, hi) in [
            ("surface_samples", self.surface_samples, 16, 4_000_000),
            ("samples_per_ray", self.samples_per_ray, 1, 256),
            ("light_bounces", self.light_bounces, 0, 16),
            ("camera_bounces", self.camera_bounces, 0, 16),
            ("indirect_rays", self.indirect_rays, 0, 4096),
            ("scene_rays", self.scene_rays, 0, 4096),
            ("grazing_beams", self.grazing_beams, 0, 64),
            ("double_disk", self.double_disk, 0, 1024),
            ("k_max", self.k_max, 1, 4096),
            ("diffuse_rays", self.diffuse_rays, 0, 4096),
            ("diffuse_samples", self.diffuse_samples, 1, 4096),
            ("reference_samples", self.reference_samples, 0, 1_000_000),
            ("reference_width", self.reference_width, 4, 4096),
            ("reflection_terms", self.reflection_terms, 1, 200),
            ("smooth_stride", self.smooth_stride, 1, 64),
        ] {
            if !(lo..=hi).contains(&x) {
                v.push(FieldIssue { field, message: format!("{field} = {x}"), help: format!("use {lo} to {hi}") });
            }
        }
        v
    }

    /// The light-sample knobs.
    pub fn point_options(&self) -> PointOptions {
        PointOptions {
            surface_samples: self.surface_samples as usize,
            samples_per_ray: self.samples_per_ray as usize,
            light_bounces: self.light_bounces,
            indirect_rays: self.indirect_rays,
            object_light: self.object_light,
            ..PointOptions::default()
        }
    }

    /// The renderer's knobs.
    pub fn render_options(&self) -> RenderOptions {
        RenderOptions {
            k_max: self.k_max as usize,
            diffuse_samples: self.diffuse_samples as usize,
            diffuse_rays: self.diffuse_rays,
            light_samples: self.light_samples,
            camera_bounces: self.camera_bounces,
            epsilon1: self.epsilon1,
            epsilon2: self.epsilon2,
            epsilon_multiple: self.epsilon_multiple,
            epsilon_beams: self.epsilon_beams,
            widen: self.widen,
            clamp_mfp: self.clamp_mfp,
            two_step: self.two_step,
            boundary_image: self.boundary_image,
            reflection_terms: self.reflection_terms as usize,
            smooth_stride: self.smooth_stride as usize,
            scene_rays: self.scene_rays,
            grazing_beams: self.grazing_beams,
            double_disk: self.double_disk,
            ..RenderOptions::default()
        }
    }

    /// Each material's (channel albedos, g) as the lobe tables see it (`scene` gives `Scene`'s medium;
    /// a `Scene` material without one is left out).
    fn material_media(&self, scene: Option<&Scene>) -> Vec<([f64; 3], f64)> {
        let mut out = Vec::new();
        for name in &self.materials {
            if let Some(m) = crate::tables::ms_lobes::material(name) {
                out.push((m.albedo, m.g));
            } else if let Some(med) = scene.and_then(|s| scene_medium(s, 1.0)) {
                // The index of refraction does not enter the table: any value does here.
                out.push((med.albedo, med.g));
            }
        }
        out
    }

    /// Runs the stage.
    pub fn run(&self, id: &str, ctx: &StageContext) -> Result<StageOutcome, StageError> {
        let fields = self.fields();
        let dir = fields.out_dir(id, ctx)?;
        let loaded = self.load(id, ctx)?;
        let cam = fields.camera(id, &loaded.scene, &fields.scene_path(ctx.base_dir), None)?;
        let tables = self.open_tables(id, ctx, &loaded.scene)?;
        let mut outputs = Vec::new();
        let mut summaries = Vec::new();
        for name in &self.materials {
            let material = loaded.material(id, name, self.mfp_scale)?;
            let (table_id, table) = tables.for_material(&material);
            let setup = loaded.setup(material);
            let fail = material_error(id, name);
            let (frame, prep) = self.render_frame(&setup, table, &cam, ctx.progress).map_err(fail)?;
            outputs.extend(write_frame(id, &dir, name, &frame)?);
            let comparison = if self.reference_samples > 0 {
                let (c, files) = self.compare(id, &dir, name, &setup, table, &cam)?;
                outputs.extend(files);
                Some(c)
            } else {
                None
            };
            let t = frame.times;
            summaries.push(MaterialSummary {
                material: name.clone(),
                table: table_id.to_string(),
                sigma_t: material.sigma_t,
                albedo: material.albedo,
                g: material.g,
                samples: [prep.points.surface.len(), prep.points.volume.len()],
                times_ms: [
                    prep.preprocess_ms,
                    t.single_ms,
                    t.double_multiple_ms,
                    t.bounced_ms,
                    t.rest_ms,
                    prep.preprocess_ms + t.single_ms + t.double_multiple_ms + t.bounced_ms + t.rest_ms,
                ],
                memory_bytes: prep.memory_bytes,
                mean_cut: frame.stats.mean_cut,
                failed_lookups: frame.stats.failed_lookups,
                comparison,
            });
        }
        let summary = TranslucentSummary {
            scene: fields.scene_path(ctx.base_dir).display().to_string(),
            size: [cam.width, cam.height],
            skipped_lights: loaded.skipped.clone(),
            materials: summaries,
        };
        outputs.push(view::write_json(id, &dir.join("summary.json"), &summary)?);
        let parts: Vec<String> = summary
            .materials
            .iter()
            .map(|m| {
                let mut s = format!("{} {:.1} s", m.material, m.times_ms[5] / 1e3);
                if let Some(c) = &m.comparison {
                    s.push_str(&format!(" (vs path tracing: {})", c.describe()));
                }
                s
            })
            .collect();
        Ok(StageOutcome {
            outputs,
            summary: format!("{}×{}: {} → {}", cam.width, cam.height, parts.join(", "), dir.display()),
        })
    }

    /// Pre-processing and the frame.
    pub fn render_frame(
        &self,
        setup: &Setup,
        table: &MsLobesTable,
        cam: &ViewCamera,
        progress: bool,
    ) -> Result<(render::Frame, render::Prepared), String> {
        let prep = render::prepare(setup, table, &self.point_options(), &self.render_options())?;
        let bar = crate::compile::progress_bar(
            progress,
            cam.height as u64,
            format!("translucent frame {}×{}: rows", cam.width, cam.height),
        );
        let frame = render::render(setup, table, &prep, cam, &self.render_options(), &|n| bar.inc(n))?;
        bar.finish_and_clear();
        Ok((frame, prep))
    }

    fn compare(
        &self,
        id: &str,
        dir: &Path,
        name: &str,
        setup: &Setup,
        table: &MsLobesTable,
        cam: &ViewCamera,
    ) -> Result<(Comparison, Vec<PathBuf>), StageError> {
        let w = self.reference_width as usize;
        let h = ((w as f64) * cam.height as f64 / cam.width as f64).round().max(1.0) as usize;
        let small = ViewCamera { width: w, height: h, ..*cam };
        let fail = material_error(id, name);
        let t0 = Instant::now();
        let (frame, prep) = self.render_frame(setup, table, &small, false).map_err(fail)?;
        let point_ms = ms(t0);
        let _ = prep;
        let opts = ReferenceOptions { samples: self.reference_samples, ..ReferenceOptions::default() };
        let t0 = Instant::now();
        let reference = reference::render(setup, &small, &opts, &|_| {});
        let reference_ms = ms(t0);
        let c = compare::compare(&frame, point_ms, &reference, reference_ms);
        let img =
            |v: &[[f64; 3]]| RgbImage { width: w, height: h, data: v.iter().map(|p| p.map(|x| x as f32)).collect() };
        let files = view::write_image(
            id,
            dir,
            &format!("{name}_reference"),
            &img(&reference.total()),
            &[("point_based", &img(&frame.total())), ("variance", &img(&reference.variance))],
        )?;
        Ok((c, files))
    }

    fn load(&self, id: &str, ctx: &StageContext) -> Result<Loaded, StageError> {
        let fail = |message: String, help: &str| StageError::Input { stage: id.into(), message, help: help.into() };
        let path = self.scene_path(ctx.base_dir);
        let scene = ctx.scenes.load(&path).map_err(|e| fail(e.to_string(), "fix the scene file or the scene field"))?;
        let bvh = SceneBvh::build(&scene);
        let (object, ior) = find_object(&scene, &bvh).ok_or_else(|| {
            fail(
                format!("{} has no closed dielectric mesh bounding a medium", path.display()),
                "give the object a refractive material (glTF KHR_materials_transmission + ior, USD opacity 0 + ior) and a medium",
            )
        })?;
        let (emitters, skipped) = emitters(&scene, self.light_radius);
        if emitters.is_empty() {
            return Err(fail(
                format!("{} has no point or sphere light", path.display()),
                "add a point light or a sphere light to the scene",
            ));
        }
        Ok(Loaded { scene, bvh, object, ior, emitters, skipped })
    }

    /// `lobe_tables` in order, then `table`, each loaded with the slices of the materials that read it
    /// (a lobe table that holds none of them is not kept).
    fn open_tables(&self, id: &str, ctx: &StageContext, scene: &Scene) -> Result<LobeTables, StageError> {
        let open = |table: &str, needs: &[(f64, f64)]| {
            let path = ctx.out_dir.join(format!("{table}.vtab"));
            MsLobesTable::open(&path, Some(needs)).map_err(|e| StageError::Table {
                stage: id.into(),
                path,
                message: format!("{e} (the materials need (albedo, g) = {needs:?})"),
            })
        };
        let pairs = |media: &[([f64; 3], f64)]| -> Vec<(f64, f64)> {
            media.iter().flat_map(|(a, g)| a.map(|x| (x, *g))).collect()
        };
        let mut left = self.material_media(Some(scene));
        let mut tables = Vec::new();
        for t in &self.lobe_tables {
            // The layout alone (no slices) says which materials the table holds.
            let layout = open(t, &[])?;
            let held: Vec<([f64; 3], f64)> = left.iter().filter(|(a, g)| layout.holds(a, *g)).copied().collect();
            if held.is_empty() {
                continue;
            }
            left.retain(|(a, g)| !layout.holds(a, *g));
            tables.push((t.clone(), open(t, &pairs(&held))?));
        }
        tables.push((self.table.clone(), open(&self.table, &pairs(&left))?));
        Ok(LobeTables { tables })
    }
}

/// Most `lobe_tables` of a stage.
const MAX_LOBE_TABLES: usize = 8;

/// A stage's lobe tables with their ids: `lobe_tables` that hold one of its materials, in order, then
/// `table`.
pub struct LobeTables {
    tables: Vec<(String, MsLobesTable)>,
}

impl LobeTables {
    /// The table `m` reads and its id: the first that holds its g and channel albedos exactly, else the
    /// stage's `table` (the last).
    pub fn for_material(&self, m: &Material) -> (&str, &MsLobesTable) {
        let last = self.tables.len() - 1;
        let (id, t) = self.tables[..last].iter().find(|(_, t)| t.holds(&m.albedo, m.g)).unwrap_or(&self.tables[last]);
        (id, t)
    }
}

/// The error of rendering material `name` (the renderer's message, with the fix).
fn material_error<'a>(id: &'a str, name: &'a str) -> impl Fn(String) -> StageError + Copy + 'a {
    move |message| StageError::Input {
        stage: id.into(),
        message: format!("material {name}: {message}"),
        help: "check the material and the table's g and albedo coverage (voltab plan)".into(),
    }
}

/// The medium inside the scene's translucent object with the object's index of refraction `ior` (the
/// channels' mean g: the renderer takes one g).
fn scene_medium(scene: &Scene, ior: f64) -> Option<Material> {
    let m = scene.media.iter().find(|m| matches!(m.boundary, crate::scene::Boundary::Mesh(_)))?;
    Some(Material { sigma_t: m.sigma_t(), albedo: m.albedo(), g: m.g.iter().sum::<f64>() / 3.0, ior })
}

/// A loaded scene with its translucent object and emitters.
pub struct Loaded {
    /// The scene.
    pub scene: std::sync::Arc<Scene>,
    /// Its BVH.
    pub bvh: SceneBvh,
    /// The translucent mesh.
    pub object: usize,
    /// Its index of refraction.
    pub ior: f64,
    /// Lights as emitters.
    pub emitters: Vec<Emitter>,
    /// Lights left out.
    pub skipped: Vec<String>,
}

impl Loaded {
    /// The material called `name` (a preset, or `Scene`).
    pub fn material(&self, id: &str, name: &str, mfp_scale: f64) -> Result<Material, StageError> {
        let m = if name == "Scene" {
            scene_medium(&self.scene, self.ior)
        } else {
            Material::preset(name, mfp_scale, self.ior)
        };
        let m = m.ok_or_else(|| StageError::Input {
            stage: id.into(),
            message: format!("material \"{name}\" is unknown or the scene has no medium for it"),
            help: "use a wang2018 Table 2 name (voltab materials) or Scene with a scene medium".into(),
        })?;
        m.check().map_err(|e| StageError::Input {
            stage: id.into(),
            message: format!("material {name}: {e}"),
            help: "check mfp_scale and the scene's medium".into(),
        })?;
        Ok(m)
    }

    /// The renderer's view of the scene with `material` in the object.
    pub fn setup(&self, material: Material) -> Setup<'_> {
        Setup { scene: &self.scene, bvh: &self.bvh, object: self.object, material, emitters: &self.emitters }
    }
}

/// Writes `<name>.exr` (RGB = full image, component layers), its PNG and one PNG per component.
fn write_frame(id: &str, dir: &Path, name: &str, f: &render::Frame) -> Result<Vec<PathBuf>, StageError> {
    let img = |v: &[[f64; 3]]| Image {
        width: f.width,
        height: f.height,
        data: v.iter().map(|p| p.map(|x| x as f32)).collect::<Vec<[f32; 3]>>(),
    };
    let layers = [
        ("single", img(&f.single)),
        ("double", img(&f.double)),
        ("multiple", img(&f.multiple)),
        ("bounced", img(&f.bounced)),
        ("rest", img(&f.rest)),
    ];
    let refs: Vec<(&str, &RgbImage)> = layers.iter().map(|(n, i)| (*n, i)).collect();
    let mut out = view::write_image(id, dir, name, &img(&f.total()), &refs)?;
    for (layer, image) in &layers[..4] {
        let png = dir.join(format!("{name}_{layer}.png"));
        crate::image_io::write_png_preview(&png, image.width, image.height, &image.data, None)
            .map_err(|e| StageError::Output { stage: id.into(), path: png.clone(), message: e.to_string() })?;
        out.push(png);
    }
    Ok(out)
}

/// A quality setting of the point-based renderer in the error-against-time ladder.
#[derive(Debug, Clone, Copy)]
struct Quality {
    surface_samples: u32,
    k_max: u32,
    epsilon1: f64,
}

impl crate::stages::Stage for TranslucentRender {
    fn kind(&self) -> &'static str {
        TranslucentRenderRaw::KIND
    }
    fn table_refs(&self) -> Vec<(&'static str, String, &'static str)> {
        let kind = crate::tables::ms_lobes::MsLobesRaw::KIND;
        let mut v = vec![("table", self.table.clone(), kind)];
        v.extend(self.lobe_tables.iter().map(|l| ("lobe_tables", l.clone(), kind)));
        v
    }
    fn validate(&self) -> Vec<FieldIssue> {
        TranslucentRender::validate(self)
    }
    fn scenes(&self, base_dir: &Path) -> Vec<PathBuf> {
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
        // A lobe table the plan skips brackets none of the stage's materials, so holds none of them: the
        // stage reads `table` for those and must not open a file this run did not write.
        let mut def = self.clone();
        def.lobe_tables.retain(|l| kept(l).is_some());
        let def = crate::stages::StageDef::TranslucentRender(def);
        crate::stages::planning::effect(def, "translucent media", &self.scene, scenes, |sc| self.lacks(sc))
    }
    fn lobe_materials(&self, scenes: &crate::stages::planning::PlannedScenes) -> Vec<String> {
        if scenes.find(&self.scene).is_none() {
            return Vec::new();
        }
        self.materials.iter().filter(|m| m.as_str() != "Scene").cloned().collect()
    }
    fn run(&self, id: &str, ctx: &StageContext) -> Result<StageOutcome, StageError> {
        TranslucentRender::run(self, id, ctx)
    }
    fn report(&self, id: &str, ctx: &StageContext, report_dir: &Path) -> Result<Option<String>, StageError> {
        TranslucentRender::report(self, id, ctx, report_dir).map(Some)
    }
    fn bench_focus(&self) -> Option<crate::stages::BenchFocus> {
        Some(crate::stages::BenchFocus::Translucent)
    }
    fn bench(&self, id: &str, ctx: &StageContext) -> Result<Option<(String, Vec<BenchRow>)>, StageError> {
        TranslucentRender::bench(self, id, ctx).map(Some)
    }
}
