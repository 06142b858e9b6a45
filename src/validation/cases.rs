//! Each stage kind made comparable with Mitsuba: the stage's own code evaluates its output where the
//! reference can evaluate it too, and the scene is reduced to what that output claims to contain.
//!
//! **Input → output.** A stage definition, its [`StageContext`] (compiled tables) and a [`Quality`] →
//! a [`Case`] or the reason it cannot be judged yet ([`Prepared::NotCompared`]).
//!
//! - `BakeLightmaps` (dubouchet2019): irradiance at a subset of the atlas's texels (the subset the
//!   stage's own check uses), every mode at the stage's samples per texel, against Mitsuba's irradiance
//!   with all transport (surface bounces and every scattering order). Only the Full mode claims all of
//!   that light; Surface (media ignored) and Shadow (media only attenuate) are listed so the size of what
//!   they leave out is measured on the same texels.
//! - `ImageFog` (iser2018): the effect is a filter of an image, so it is fed Mitsuba's own vacuum image
//!   (the scene without media, same camera and raster) on voltab's distance buffer, and its fogged image
//!   is compared with Mitsuba's image of the scene with its fog (all transport); attenuation-only fog and
//!   no fog are listed on the same pixels, as the baselines issue 36 measures against.
//! - `PopRender` (elek2014): the medium's scattered radiance (layer `scattered`, the surfaces' reflected
//!   light switched off: `surface_vpls = 0`) against Mitsuba's image of the scene with black surfaces
//!   (and the stage's environment map) minus its image with every medium's scattering turned into
//!   absorption (same extinction, so emitters and sky seen through the medium cancel): exactly the light
//!   that scattered in the medium at least once.
//! - `TranslucentRender` (wang2018): per material, the full image against Mitsuba's image of the scene
//!   with that material's medium inside the object's dielectric boundary (all transport); point lights
//!   become the stage's spheres of `light_radius` with the same intensity, on both sides. The stage's own
//!   path tracer (`reference_samples`) is judged on the same pixels, its own per-pixel variance
//!   subtracted as well (`Method::variance`).
//! - `EpipolarShadows` (baran2010): the in-scattered radiance image (single scattering of the one light
//!   the stage uses, shadowed by the scene) against Mitsuba's image of the same camera with every surface
//!   black and only that light, max_depth 2 minus max_depth 1: exactly the light that scattered once in
//!   the medium, attenuated on both legs. The stage's own BVH marcher (`reference_steps`, the mean of
//!   two independently jittered runs) is judged on the same pixels, its noise from the two runs
//!   subtracted as well.

use std::path::Path;
use std::time::Instant;

use super::python::Harness;
use super::{Case, Method, Quality, Query, ValidateError};
use crate::reference::mitsuba::ExportOptions;
use crate::scene::{Material, Scene, Surface};
use crate::stages::god_rays::{EpiLight, EpipolarShadows};
use crate::stages::{StageContext, StageDef, StageError};

/// A stage made comparable, or why not.
#[derive(Debug)]
pub enum Prepared {
    /// Ready for the reference (one case per material for the translucent stage).
    Cases(Vec<Case>),
    /// Not judged (yet), and why.
    NotCompared(String),
}

/// The case of stage `id`; `dir` is the stage's validation folder (its own outputs at the validation's
/// size go to `dir/stage`; a stage whose input is another renderer's image gets it from `harness`).
pub fn prepare(
    id: &str,
    def: &StageDef,
    ctx: &StageContext,
    quality: Quality,
    dir: &Path,
    harness: &Harness,
) -> Result<Prepared, ValidateError> {
    Ok(match def {
        StageDef::BakeLightmaps(b) => Prepared::Cases(vec![bake(id, b, ctx, quality)?]),
        StageDef::EpipolarShadows(e) => Prepared::Cases(vec![god_rays(id, e, ctx, quality, &dir.join("stage"))?]),
        StageDef::ImageFog(f) => Prepared::Cases(vec![image_fog(id, f, ctx, quality, dir, harness)?]),
        StageDef::PlotPhase(_) => Prepared::NotCompared("plots a table; it renders no scene".into()),
        StageDef::TranslucentRender(t) => Prepared::Cases(translucent(id, t, ctx, quality, &dir.join("stage"))?),
        StageDef::PopRender(pop) => match pop_render(id, pop, ctx, quality, &dir.join("stage"))? {
            Some(case) => Prepared::Cases(vec![case]),
            None => Prepared::NotCompared(
                "its density volume (density_raw / density_slices) is not exported to Mitsuba yet; issue 33".into(),
            ),
        },
    })
}

fn bake(
    id: &str,
    stage: &crate::stages::bake::BakeLightmaps,
    ctx: &StageContext,
    quality: Quality,
) -> Result<Case, ValidateError> {
    let (texels, spp) = match quality {
        Quality::Quick => (64, 256),
        Quality::Full => (256, 1024),
    };
    let check = stage.texel_check(id, ctx, texels)?;
    let methods = check
        .modes
        .iter()
        .map(|(mode, values, ms)| Method { name: mode.name().into(), values: values.clone(), ms: *ms, variance: None })
        .collect();
    let caveats = vec![format!(
        "only the Full mode claims all of Mitsuba's light; Surface leaves the media out and Shadow lets them \
         only attenuate (dubouchet2019 Figs. 1, 12), so their errors measure what they leave out. {} samples \
         per texel.",
        stage.samples
    )];
    Ok(Case {
        stage: id.into(),
        kind: "BakeLightmaps",
        quantity: "irradiance at lightmap texels, all transport".into(),
        query: Query::Irradiance {
            points: check.points.iter().map(|p| p.position).collect(),
            normals: check.points.iter().map(|p| p.normal).collect(),
            spp,
            max_depth: vec![-1],
        },
        scene: std::sync::Arc::unwrap_or_clone(check.scene),
        minus_scene: None,
        export: ExportOptions::default(),
        methods,
        caveats,
    })
}

fn god_rays(
    id: &str,
    stage: &EpipolarShadows,
    ctx: &StageContext,
    quality: Quality,
    scratch: &Path,
) -> Result<Case, ValidateError> {
    let fail = |message: String| StageError::Input { stage: id.into(), message, help: "fix the stage's scene".into() };
    let (width, height, spp) = view(stage.width, stage.height, quality, 160, 1024);
    let mut small = stage.clone();
    small.width = width;
    small.height = height;
    // The stage's own reference (its BVH marcher) runs too, so Mitsuba judges it as well (issue 30:
    // a simplification the method and its internal reference share shows up here).
    small.reference_steps = stage.reference_steps;
    small.output = String::new();
    scratch_with_tables(id, ctx, scratch, &[])?;
    let sctx = StageContext { out_dir: scratch, ..*ctx };
    let t0 = Instant::now();
    small.run(id, &sctx)?;
    let wall_ms = t0.elapsed().as_secs_f64() * 1e3;
    let dir = scratch.join(id);
    let exr = dir.join("godrays.exr");
    let img = crate::image_io::read_exr_rgb(&exr).map_err(|e| fail(e.to_string()))?;
    let inscatter = img.rgb(Some("inscatter")).ok_or_else(|| fail(format!("{}: no inscatter layer", exr.display())))?;
    // The epipolar method's own time (shadow map and G-buffer excluded, as the stage reports it).
    let summary = read_summary(&dir);
    let ms = summary["phases_ms"][6].as_f64().unwrap_or(wall_ms);

    let (mut scene, camera) = scene_and_camera(id, &stage.scene_path(ctx.base_dir), stage.camera)?;
    let mut methods = vec![Method {
        name: "epipolar".into(),
        values: inscatter.iter().map(|p| p.map(f64::from)).collect(),
        ms,
        variance: None,
    }];
    if stage.reference_steps > 0 {
        let exr = dir.join("marcher.exr");
        let img = crate::image_io::read_exr_rgb(&exr).map_err(|e| fail(e.to_string()))?;
        let values = img.rgb(None).ok_or_else(|| fail(format!("{}: no R, G, B", exr.display())))?;
        let variance =
            img.rgb(Some("variance")).ok_or_else(|| fail(format!("{}: no variance layer", exr.display())))?;
        methods.push(Method {
            name: format!("internal reference ({}-step BVH marcher, mean of 2 runs)", stage.reference_steps),
            values: values.iter().map(|p| p.map(f64::from)).collect(),
            ms: summary["reference"]["ms"].as_f64().unwrap_or(0.0),
            variance: Some(variance.iter().map(|p| p.map(f64::from)).collect()),
        });
    }
    let mut caveats = single_scattering_view(&mut scene).map_err(fail)?;
    if !stage.light_texture.is_empty() {
        caveats.push("the light texture (cookie) is not exported: the reference's light is white".into());
    }
    caveats.extend(size_caveat((width, height), (stage.width, stage.height)));
    Ok(Case {
        stage: id.into(),
        kind: "EpipolarShadows",
        quantity: "in-scattered radiance image (single scattering)".into(),
        scene,
        minus_scene: None,
        export: ExportOptions { camera: Some(camera), width, height: Some(height), spp },
        query: Query::Image { width, height, spp, max_depth: vec![2], minus_depth: Some(1), block: None },
        methods,
        caveats,
    })
}

/// The scene reduced to what the god-ray stage lights it with: only the light it uses (the first
/// directional or spot light), no environment, no emissive surfaces, every opaque surface black (it
/// occludes but reflects nothing). Returns the caveats: what else the stage does not model.
fn single_scattering_view(scene: &mut Scene) -> Result<Vec<String>, String> {
    let mut probe = scene.clone();
    let keep = scene
        .lights
        .iter()
        .position(|l| {
            probe.lights = vec![l.clone()];
            EpiLight::from_scene(&probe).is_some()
        })
        .ok_or_else(|| format!("{} has no directional or spot light", scene.source.display()))?;
    let mut caveats = Vec::new();
    let dropped = scene.lights.len() - 1 + usize::from(scene.environment.is_some());
    if dropped > 0 {
        caveats.push(format!(
            "{dropped} other light(s) of the scene are left out of both sides: the stage renders light {:?} only",
            scene.lights[keep].name
        ));
    }
    scene.lights = vec![scene.lights[keep].clone()];
    scene.environment = None;
    for m in &mut scene.materials {
        m.emission = [0.0; 3];
    }
    caveats.extend(black_surfaces(scene));
    let other_media = scene
        .media
        .iter()
        .filter(|m| m.boundary != crate::scene::Boundary::Global || m.density != crate::scene::Density::Homogeneous)
        .count();
    if other_media > 0 {
        caveats
            .push(format!("{other_media} medium/media besides the homogeneous global one are in the reference only"));
    }
    Ok(caveats)
}

/// Raster and reference paths per pixel of an image stage at `quality`: quick keeps at most `quick_width`
/// pixels across (same aspect) and `quick_spp` paths per run; full, the declared raster and 4× the paths.
fn view(width: u32, height: u32, quality: Quality, quick_width: u32, quick_spp: u32) -> (u32, u32, u32) {
    let (w, h) = raster(width, height, quality, quick_width);
    (w, h, if quality == Quality::Quick { quick_spp } else { 4 * quick_spp })
}

/// The raster of an image stage at `quality`: quick keeps at most `quick_width` pixels across (same aspect).
fn raster(width: u32, height: u32, quality: Quality, quick_width: u32) -> (u32, u32) {
    match quality {
        Quality::Quick => {
            let w = width.min(quick_width);
            (w, ((f64::from(height) * f64::from(w) / f64::from(width)).round() as u32).max(1))
        }
        Quality::Full => (width, height),
    }
}

fn image_fog(
    id: &str,
    stage: &crate::stages::image_fog::ImageFogStage,
    ctx: &StageContext,
    quality: Quality,
    dir: &Path,
    harness: &Harness,
) -> Result<Case, ValidateError> {
    let fail = |message: String| StageError::Input { stage: id.into(), message, help: "fix the stage's scene".into() };
    if !stage.colour_exr.is_empty() {
        return Err(fail("the stage reads its colour from colour_exr: validate it on a scene it renders".into()).into());
    }
    let (width, height) = raster(stage.width, stage.height, quality, 160);
    let (vacuum_spp, spp) = match quality {
        Quality::Quick => (1024, 256),
        Quality::Full => (4096, 1024),
    };
    let (scene, camera) = scene_and_camera(id, &stage.scene_path(ctx.base_dir), stage.camera)?;
    let export = ExportOptions { camera: Some(camera), width, height: Some(height), spp };
    // Mitsuba's vacuum image: the colour buffer the effect filters.
    let mut vacuum = scene.clone();
    vacuum.media.clear();
    for m in &mut vacuum.meshes {
        m.medium = None;
    }
    let vdir = dir.join("vacuum");
    crate::reference::mitsuba::export(&vacuum, &export, &vdir.join("mitsuba"))
        .map_err(|source| ValidateError::Export { stage: id.into(), source })?;
    let request = serde_json::json!({
        "export": "mitsuba", "out": "vacuum.json", "variant": "auto", "runs": 4, "seed": 100,
        "queries": [{"kind": "image", "name": "vacuum", "width": width, "height": height, "spp": vacuum_spp,
                     "max_depth": [-1]}],
    });
    let reply = harness.run(&vdir, "request.json", &request)?;
    let file = reply.queries.first().and_then(|q| q.files.first()).ok_or_else(|| {
        super::python::PythonError::Reply { path: vdir.join("vacuum.json"), message: "no vacuum image".into() }
    })?;
    let img = crate::image_io::read_exr_rgb(&vdir.join(file)).map_err(|e| fail(e.to_string()))?;
    let data = img.rgb(None).ok_or_else(|| fail(format!("{file}: no R, G, B")))?;
    let colour = crate::render::Image { width: img.width, height: img.height, data };
    let (out, ms) = stage.apply_to_colour(id, ctx, &colour)?;
    let values = |im: &crate::render::RgbImage| im.data.iter().map(|p| p.map(f64::from)).collect::<Vec<_>>();
    let mut caveats = vec![format!(
        "the effect filters Mitsuba's vacuum image ({vacuum_spp}×4 paths per pixel; its own noise is not \
         subtracted) on voltab's distance buffer"
    )];
    caveats.extend(size_caveat((width, height), (stage.width, stage.height)));
    Ok(Case {
        stage: id.into(),
        kind: "ImageFog",
        quantity: "fogged image (all transport), 4×4-pixel blocks".into(),
        scene,
        minus_scene: None,
        export,
        query: Query::Image { width, height, spp, max_depth: vec![-1], minus_depth: None, block: Some(4) },
        methods: vec![
            Method { name: "fog".into(), values: values(&out.image), ms, variance: None },
            Method { name: "attenuation only".into(), values: values(&out.attenuated), ms, variance: None },
            Method { name: "no fog".into(), values: values(&colour), ms: 0.0, variance: None },
        ],
        caveats,
    })
}

fn pop_render(
    id: &str,
    stage: &crate::stages::pop::PopRender,
    ctx: &StageContext,
    quality: Quality,
    scratch: &Path,
) -> Result<Option<Case>, ValidateError> {
    let fail = |message: String| StageError::Input { stage: id.into(), message, help: "fix the stage's scene".into() };
    if !stage.density_raw.is_empty() || !stage.density_slices.is_empty() {
        return Ok(None);
    }
    let (width, height, spp) = view(stage.width, stage.height, quality, 160, 1024);
    let mut small = stage.clone();
    small.width = width;
    small.height = height;
    small.reference_samples = 0;
    small.fig12_photons = 0;
    small.surface_vpls = 0;
    small.output = String::new();
    scratch_with_tables(id, ctx, scratch, std::slice::from_ref(&stage.table))?;
    let sctx = StageContext { out_dir: scratch, ..*ctx };
    small.run(id, &sctx)?;
    let dir = scratch.join(id);
    let exr = dir.join("pop.exr");
    let img = crate::image_io::read_exr_rgb(&exr).map_err(|e| fail(e.to_string()))?;
    let scattered = img.rgb(Some("scattered")).ok_or_else(|| fail(format!("{}: no scattered layer", exr.display())))?;
    // The frame's time: every light's grid, propagation phases and merge, and the ray marching.
    let summary = read_summary(&dir);
    let f = |v: &serde_json::Value| v.as_f64().unwrap_or(0.0);
    let lights_ms: f64 = summary["lights"].as_array().map_or(0.0, |ls| {
        ls.iter()
            .map(|l| {
                let p = &l["phases_ms"];
                f(&l["grid_ms"])
                    + f(&p["initialisation"])
                    + f(&p["propagation"])
                    + f(&p["residuum"])
                    + f(&p["accumulation"])
                    + f(&l["merge_ms"])
            })
            .sum()
    });
    let ms = lights_ms + f(&summary["ray_march_ms"]);

    let (mut scene, camera) = scene_and_camera(id, &stage.scene_path(ctx.base_dir), stage.camera)?;
    // Surfaces black on both sides: otherwise Mitsuba's difference would also hold the surfaces lit by
    // the medium's scattered light, which is not light the medium scatters toward the camera.
    let mut caveats = vec![
        "surfaces reflect nothing on both sides (black in Mitsuba, surface_vpls = 0 in the stage): this judges \
         the medium's propagation of the lights (Secs. 4-6), not the reflected-light VPLs"
            .to_string(),
    ];
    caveats.extend(black_surfaces(&mut scene));
    if !stage.environment.is_empty() {
        scene.environment = Some(crate::scene::EnvironmentLight {
            name: format!("the stage's environment {}", stage.environment),
            texture: Some({
                let p = ctx.base_dir.join(&stage.environment);
                std::path::absolute(&p).unwrap_or(p)
            }),
            scale: stage.environment_intensity,
            color: [1.0; 3],
            rotation: [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
        });
    }
    let mut absorbing = scene.clone();
    for m in &mut absorbing.media {
        m.sigma_a = [0, 1, 2].map(|c| m.sigma_a[c] + m.sigma_s[c]);
        m.sigma_s = [0.0; 3];
    }
    caveats.extend(size_caveat((width, height), (stage.width, stage.height)));
    Ok(Some(Case {
        stage: id.into(),
        kind: "PopRender",
        quantity: "light scattered in the medium (all orders), 4×4-pixel blocks".into(),
        scene,
        minus_scene: Some(absorbing),
        export: ExportOptions { camera: Some(camera), width, height: Some(height), spp },
        query: Query::Image { width, height, spp, max_depth: vec![-1], minus_depth: None, block: Some(4) },
        methods: vec![Method {
            name: "pop".into(),
            values: scattered.iter().map(|p| p.map(f64::from)).collect(),
            ms,
            variance: None,
        }],
        caveats,
    }))
}

/// The folder a stage clone writes into, holding (hard links to, else copies of) the compiled tables it
/// reads: a stage reads its tables from its output folder.
fn scratch_with_tables(id: &str, ctx: &StageContext, scratch: &Path, tables: &[String]) -> Result<(), StageError> {
    let err = |path: &Path, e: std::io::Error| StageError::Output {
        stage: id.into(),
        path: path.to_path_buf(),
        message: e.to_string(),
    };
    std::fs::create_dir_all(scratch).map_err(|e| err(scratch, e))?;
    for t in tables {
        let name = format!("{t}.vtab");
        let (from, to) = (ctx.out_dir.join(&name), scratch.join(&name));
        let _ = std::fs::remove_file(&to);
        if std::fs::hard_link(&from, &to).is_err() {
            std::fs::copy(&from, &to).map_err(|e| err(&from, e))?;
        }
    }
    Ok(())
}

/// Every opaque surface black (it occludes, reflects nothing); dielectrics are kept. Returns a caveat
/// when there are dielectrics.
fn black_surfaces(scene: &mut Scene) -> Option<String> {
    let black = scene.materials.len();
    scene.materials.push(Material {
        name: "voltab_validate_black".into(),
        base_color: [0.0; 3],
        emission: [0.0; 3],
        surface: Surface::Opaque,
        roughness: 1.0,
    });
    let mut dielectric = 0;
    for mesh in &mut scene.meshes {
        match mesh.material.map(|k| scene.materials[k].surface) {
            Some(Surface::Dielectric { .. }) => dielectric += 1,
            _ => mesh.material = Some(black),
        }
    }
    (dielectric > 0).then(|| format!("{dielectric} dielectric mesh(es) are kept as such in the reference"))
}

fn translucent(
    id: &str,
    stage: &crate::stages::translucent::TranslucentRender,
    ctx: &StageContext,
    quality: Quality,
    scratch: &Path,
) -> Result<Vec<Case>, ValidateError> {
    use crate::scene::LightKind;
    let fail = |message: String| StageError::Input { stage: id.into(), message, help: "fix the stage's scene".into() };
    let (width, height, spp) = view(stage.width, stage.height, quality, 48, 2048);
    let mut small = stage.clone();
    small.width = width;
    small.height = height;
    // The stage's own path tracer runs too (at the same raster), so Mitsuba judges it as well.
    small.reference_samples = stage.reference_samples;
    small.reference_width = width;
    small.output = String::new();
    let mut tables = vec![stage.table.clone()];
    tables.extend(stage.lobe_tables.iter().cloned());
    scratch_with_tables(id, ctx, scratch, &tables)?;
    let sctx = StageContext { out_dir: scratch, ..*ctx };
    small.run(id, &sctx)?;
    let dir = scratch.join(id);
    let summary = read_summary(&dir);
    let (mut scene, camera) = scene_and_camera(id, &stage.scene_path(ctx.base_dir), stage.camera)?;
    let r = stage.light_radius;
    for l in &mut scene.lights {
        if let LightKind::Point { position } = l.kind {
            l.kind = LightKind::Sphere { center: position, radius: r };
            // A sphere of uniform radiance L has intensity π r² L toward every direction.
            l.radiance = l.radiance.map(|i| i / (std::f64::consts::PI * r * r));
        }
    }
    let object = scene
        .media
        .iter()
        .position(|m| matches!(m.boundary, crate::scene::Boundary::Mesh(_)))
        .ok_or_else(|| fail("the scene has no medium bounded by a mesh".into()))?;
    let mut caveats = Vec::new();
    if let Some(skipped) = summary["skipped_lights"].as_array().filter(|a| !a.is_empty()) {
        caveats.push(format!("lights the stage leaves out are in the reference: {skipped:?}"));
    }
    caveats.extend(size_caveat((width, height), (stage.width, stage.height)));
    let mut cases = Vec::new();
    for (k, name) in stage.materials.iter().enumerate() {
        let m = &summary["materials"][k];
        let f3 = |v: &serde_json::Value| [0, 1, 2].map(|c| v[c].as_f64().unwrap_or(0.0));
        let (sigma_t, albedo, g) = (f3(&m["sigma_t"]), f3(&m["albedo"]), m["g"].as_f64().unwrap_or(0.0));
        let ms = m["times_ms"][5].as_f64().unwrap_or(0.0);
        let exr = dir.join(format!("{name}.exr"));
        let img = crate::image_io::read_exr_rgb(&exr).map_err(|e| fail(e.to_string()))?;
        let values = img.rgb(None).ok_or_else(|| fail(format!("{}: no R, G, B", exr.display())))?;
        let mut methods = vec![Method {
            name: "point-based".into(),
            values: values.iter().map(|p| p.map(f64::from)).collect(),
            ms,
            variance: None,
        }];
        if stage.reference_samples > 0 {
            let exr = dir.join(format!("{name}_reference.exr"));
            let img = crate::image_io::read_exr_rgb(&exr).map_err(|e| fail(e.to_string()))?;
            let values = img.rgb(None).ok_or_else(|| fail(format!("{}: no R, G, B", exr.display())))?;
            let variance =
                img.rgb(Some("variance")).ok_or_else(|| fail(format!("{}: no variance layer", exr.display())))?;
            methods.push(Method {
                name: format!("internal reference (path tracer, {} paths)", stage.reference_samples),
                values: values.iter().map(|p| p.map(f64::from)).collect(),
                ms: m["comparison"]["reference_ms"].as_f64().unwrap_or(0.0),
                variance: Some(variance.iter().map(|p| p.map(f64::from)).collect()),
            });
        }
        let mut sc = scene.clone();
        let med = &mut sc.media[object];
        med.sigma_s = [0, 1, 2].map(|c| sigma_t[c] * albedo[c]);
        med.sigma_a = [0, 1, 2].map(|c| sigma_t[c] * (1.0 - albedo[c]));
        med.g = [g; 3];
        med.density = crate::scene::Density::Homogeneous;
        cases.push(Case {
            stage: format!("{id}/{name}"),
            kind: "TranslucentRender",
            quantity: format!("image of the object in {name} (all transport), 4×4-pixel blocks"),
            scene: sc,
            minus_scene: None,
            export: ExportOptions { camera: Some(camera.clone()), width, height: Some(height), spp },
            query: Query::Image { width, height, spp, max_depth: vec![-1], minus_depth: None, block: Some(4) },
            methods,
            caveats: caveats.clone(),
        });
    }
    Ok(cases)
}

/// The stage's summary.json in `dir` (`null` when missing: the fields read from it fall back).
fn read_summary(dir: &Path) -> serde_json::Value {
    std::fs::read(dir.join("summary.json")).ok().and_then(|b| serde_json::from_slice(&b).ok()).unwrap_or_default()
}

/// The stage's scene and the name of its camera (the export's sensor).
fn scene_and_camera(id: &str, path: &Path, camera: u32) -> Result<(Scene, String), StageError> {
    let fail = |message: String| StageError::Input { stage: id.into(), message, help: "fix the stage's scene".into() };
    let scene = Scene::load(path).map_err(|e| fail(e.to_string()))?;
    let name = scene
        .cameras
        .get(camera as usize)
        .map(|c| c.name.clone())
        .ok_or_else(|| fail(format!("{}: camera {camera} does not exist", path.display())))?;
    Ok((scene, name))
}

/// Said when the stage runs smaller here than it is declared.
fn size_caveat(here: (u32, u32), declared: (u32, u32)) -> Option<String> {
    (here != declared).then(|| {
        format!(
            "the stage runs at {}×{} here (declared {}×{}) so the reference stays quick",
            here.0, here.1, declared.0, declared.1
        )
    })
}
