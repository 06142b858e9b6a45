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
//! - `EpipolarShadows` (baran2010): the in-scattered radiance image (single scattering of the one light
//!   the stage uses, shadowed by the scene) against Mitsuba's image of the same camera with every surface
//!   black and only that light, max_depth 2 minus max_depth 1: exactly the light that scattered once in
//!   the medium, attenuated on both legs.

use std::path::Path;
use std::time::Instant;

use super::{Case, Method, Quality, Query, ValidateError};
use crate::reference::mitsuba::ExportOptions;
use crate::scene::{Material, Scene, Surface};
use crate::stages::god_rays::{EpiLight, EpipolarShadows};
use crate::stages::{StageContext, StageDef, StageError};

/// A stage made comparable, or why not.
#[derive(Debug)]
pub enum Prepared {
    /// Ready for the reference.
    Case(Box<Case>),
    /// Not judged (yet), and why.
    NotCompared(String),
}

/// The case of stage `id`; `scratch` is a folder for the stage's own outputs at the validation's size.
pub fn prepare(
    id: &str,
    def: &StageDef,
    ctx: &StageContext,
    quality: Quality,
    scratch: &Path,
) -> Result<Prepared, ValidateError> {
    Ok(match def {
        StageDef::BakeLightmaps(b) => Prepared::Case(Box::new(bake(id, b, ctx, quality)?)),
        StageDef::EpipolarShadows(e) => Prepared::Case(Box::new(god_rays(id, e, ctx, quality, scratch)?)),
        StageDef::PlotPhase(_) => Prepared::NotCompared("plots a table; it renders no scene".into()),
        StageDef::ImageFog(_) => Prepared::NotCompared(
            "no Mitsuba comparison yet (the fog's in-scattered light of the height-fog grid; issue 36)".into(),
        ),
        StageDef::TranslucentRender(_) => Prepared::NotCompared(
            "no Mitsuba comparison yet (the object as a dielectric boundary around each material; issue 34)".into(),
        ),
        StageDef::PopRender(_) => Prepared::NotCompared(
            "no Mitsuba comparison yet (the medium's scattered light of the stage's view; issue 33)".into(),
        ),
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
        .map(|(mode, values, ms)| Method { name: mode.name().into(), values: values.clone(), ms: *ms })
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
        scene: check.scene,
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
    let (width, height, spp) = match quality {
        Quality::Quick => {
            let w = stage.width.min(160);
            (w, ((f64::from(stage.height) * f64::from(w) / f64::from(stage.width)).round() as u32).max(1), 1024)
        }
        Quality::Full => (stage.width, stage.height, 4096),
    };
    let mut small = stage.clone();
    small.width = width;
    small.height = height;
    small.reference_steps = 0;
    small.output = String::new();
    std::fs::create_dir_all(scratch).map_err(|e| StageError::Output {
        stage: id.into(),
        path: scratch.into(),
        message: e.to_string(),
    })?;
    let sctx = StageContext { out_dir: scratch, ..*ctx };
    let t0 = Instant::now();
    small.run(id, &sctx)?;
    let wall_ms = t0.elapsed().as_secs_f64() * 1e3;
    let dir = scratch.join(id);
    let exr = dir.join("godrays.exr");
    let img = crate::image_io::read_exr_rgb(&exr).map_err(|e| fail(e.to_string()))?;
    let inscatter = img.rgb(Some("inscatter")).ok_or_else(|| fail(format!("{}: no inscatter layer", exr.display())))?;
    // The epipolar method's own time (shadow map and G-buffer excluded, as the stage reports it).
    let summary: serde_json::Value =
        std::fs::read(dir.join("summary.json")).ok().and_then(|b| serde_json::from_slice(&b).ok()).unwrap_or_default();
    let ms = summary["phases_ms"][6].as_f64().unwrap_or(wall_ms);

    let mut scene = Scene::load(&stage.scene_path(ctx.base_dir)).map_err(|e| fail(e.to_string()))?;
    let camera = scene
        .cameras
        .get(stage.camera as usize)
        .map(|c| c.name.clone())
        .ok_or_else(|| fail(format!("camera {} does not exist", stage.camera)))?;
    let mut caveats = single_scattering_view(&mut scene).map_err(fail)?;
    if !stage.light_texture.is_empty() {
        caveats.push("the light texture (cookie) is not exported: the reference's light is white".into());
    }
    if quality == Quality::Quick && (width, height) != (stage.width, stage.height) {
        caveats.push(format!(
            "the stage runs at {width}×{height} here (declared {}×{}) so the reference stays quick",
            stage.width, stage.height
        ));
    }
    Ok(Case {
        stage: id.into(),
        kind: "EpipolarShadows",
        quantity: "in-scattered radiance image (single scattering)".into(),
        scene,
        export: ExportOptions { camera: Some(camera), width, height: Some(height), spp, texels: 0 },
        query: Query::Image { width, height, spp, max_depth: vec![2], minus_depth: Some(1) },
        methods: vec![Method {
            name: "epipolar".into(),
            values: inscatter.iter().map(|p| p.map(f64::from)).collect(),
            ms,
        }],
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
    let black = scene.materials.len();
    scene.materials.push(Material {
        name: "voltab_validate_black".into(),
        base_color: [0.0; 3],
        emission: [0.0; 3],
        surface: Surface::Opaque,
        roughness: 1.0,
    });
    for m in &mut scene.materials {
        m.emission = [0.0; 3];
    }
    let mut dielectric = 0;
    for mesh in &mut scene.meshes {
        match mesh.material.map(|k| scene.materials[k].surface) {
            Some(Surface::Dielectric { .. }) => dielectric += 1,
            _ => mesh.material = Some(black),
        }
    }
    if dielectric > 0 {
        caveats.push(format!("{dielectric} dielectric mesh(es) are kept as such in the reference"));
    }
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
