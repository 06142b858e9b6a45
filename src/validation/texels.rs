//! The lightmap bake's own texels, for judging the bake against Mitsuba at exactly the points it bakes
//! (issue 30 for issue 31's targets). It runs the bake (a method), so it lives in the validation layer
//! above the stages, not in `reference::mitsuba`, which only exports the scene.
//!
//! **Input → output.** A scene with lightmap UVs and a texel count → [`TexelSet`] (`texels.json` beside the
//! export): every k-th inside texel of the bake's atlas at its default density (the subset the stage's own
//! report uses), its position and normal, the bake's irradiance in the modes that need no table (Surface,
//! Shadow) with their times, and voltab's internal reference (`reference::volpath`, full volumetric
//! transport) with per-texel standard errors. The Full mode needs a compiled `ZhResponse` table and is not
//! part of this set. The harness evaluates Mitsuba's irradiance at the same (position, normal) pairs.

use serde::Serialize;

use crate::reference::volpath::{self, SurfacePoint, VolPathOptions};
use crate::scene::Scene;
use crate::scene::bvh::SceneBvh;
use crate::stages::bake::{BakeLightmaps, BakeMode, atlas, report};

/// Bake samples per texel for the table-free modes.
pub const BAKE_SAMPLES: u32 = 128;

/// Paths per texel of the internal reference.
pub const REFERENCE_SAMPLES: u32 = 1024;

/// One bake mode at the texels.
#[derive(Debug, Clone, Serialize)]
pub struct ModeIrradiance {
    /// `surface` or `shadow`.
    pub mode: String,
    /// Irradiance per texel \[W/m²\], RGB.
    pub irradiance: Vec<[f64; 3]>,
    /// Samples per texel.
    pub samples: u32,
    /// Wall time \[ms\].
    pub ms: f64,
}

/// The internal reference at the texels.
#[derive(Debug, Clone, Serialize)]
pub struct InternalReference {
    /// Mean irradiance per texel \[W/m²\].
    pub mean: Vec<[f64; 3]>,
    /// Standard error of each mean.
    pub stderr: Vec<[f64; 3]>,
    /// Paths per texel.
    pub samples: u32,
    /// Wall time \[ms\].
    pub ms: f64,
}

/// `texels.json`.
#[derive(Debug, Clone, Serialize)]
pub struct TexelSet {
    /// Texel positions \[m\].
    pub positions: Vec<[f64; 3]>,
    /// Unit shading normals (the side the bake gathers on).
    pub normals: Vec<[f64; 3]>,
    /// The bake's table-free modes.
    pub modes: Vec<ModeIrradiance>,
    /// voltab's volumetric path tracer.
    pub internal_reference: InternalReference,
}

/// The bake's texel subset of `scene` (at most `count`), baked and referenced (module doc).
pub fn texels(scene: &Scene, count: usize) -> Result<TexelSet, String> {
    let def = BakeLightmaps { samples: BAKE_SAMPLES, ..BakeLightmaps::default() };
    let opts = atlas::AtlasOptions {
        texels_per_metre: def.texels_per_metre,
        min_size: def.min_size,
        max_size: def.max_size,
        padding: 2,
    };
    let atlas = atlas::build(scene, &opts)
        .map_err(|e| format!("{}: {e} (the texel export needs lightmap UVs)", scene.source.display()))?;
    let points = report::subset(&atlas, count);
    if points.is_empty() {
        return Err(format!("{}: the bake's atlas has no texels (no mesh with lightmap UVs)", scene.source.display()));
    }
    let bvh = SceneBvh::build(scene);
    let mut modes = Vec::new();
    for mode in [BakeMode::Surface, BakeMode::Shadow] {
        let (irradiance, ms) = report::bake(scene, &bvh, None, &def, mode, BAKE_SAMPLES, &points)?;
        modes.push(ModeIrradiance { mode: mode.name().into(), irradiance, samples: BAKE_SAMPLES, ms });
    }
    let sp: Vec<SurfacePoint> =
        points.iter().map(|p| SurfacePoint { position: p.position, normal: p.normal }).collect();
    let vopts = VolPathOptions {
        samples: REFERENCE_SAMPLES,
        max_depth: 64,
        rr_depth: 4,
        seed: 1,
        surface_bounces: u32::MAX,
        eye_surfaces: true,
        media: true,
    };
    let t0 = std::time::Instant::now();
    let (est, _) = volpath::irradiance(scene, &bvh, &sp, &vopts);
    let internal_reference = InternalReference {
        mean: est.iter().map(|e| e.mean).collect(),
        stderr: est.iter().map(|e| e.stderr).collect(),
        samples: REFERENCE_SAMPLES,
        ms: t0.elapsed().as_secs_f64() * 1e3,
    };
    Ok(TexelSet {
        positions: points.iter().map(|p| p.position).collect(),
        normals: points.iter().map(|p| p.normal).collect(),
        modes,
        internal_reference,
    })
}
