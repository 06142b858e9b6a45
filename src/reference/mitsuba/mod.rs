//! `voltab export mitsuba`: the imported [`Scene`] as a Mitsuba 3 scene, so that an independent renderer
//! sees exactly what voltab's stages see (issue 30). The renders and comparisons live in the Python
//! harness `python/mitsuba_ref/`.
//!
//! **Input → output.** A checked [`Scene`] (world space, metres, voltab's radiometric units) and
//! [`ExportOptions`] → a folder with `scene.xml` (Mitsuba 3 XML, format 3.0.0), `meshes/*.ply` (binary,
//! world space), `volumes/*.vol` (Mitsuba grid volumes, for exponential height fog) and `export.json`
//! ([`Manifest`]: what became what, the unit conventions, the region the global medium fills, warnings for
//! what Mitsuba cannot represent exactly). Every file is written to a temporary name and renamed, and
//! `export.json` is written last. (`voltab export --texels N` adds `texels.json`, the bake's own texels,
//! from `crate::validation::texels`: the bake is a method, so the reference never runs it.)
//!
//! **Mapping** (units carry over unchanged; voltab's and Mitsuba's conventions coincide):
//! - point: `point` `intensity` = voltab intensity \[W/sr\]; directional: `directional` `irradiance` \[W/m²\]
//!   and `direction` = the direction light travels; spot: `spot` with `cutoff_angle` = outer cone,
//!   `beam_width` = inner cone (Mitsuba's falloff is linear in angle between them, voltab's is KHR's
//!   `t²` in cosine: the largest difference is a warning in `export.json`);
//! - rect, disk, sphere lights: `rectangle`/`disk`/`sphere` shapes with an `area` emitter of the light's
//!   radiance and a `null` BSDF (voltab's analytic area lights never occlude); emissive meshes: an `area`
//!   emitter on the mesh's own shape; the environment: `constant` or `envmap` (Mitsuba's lat-long
//!   convention equals voltab's: row 0 toward the map's +Y, centre column toward +Z, a quarter across
//!   toward +X) with `to_world` = the dome's rotation;
//! - surfaces: opaque → two-sided Lambertian with `base_color` (no material: 0.8 grey, as voltab's
//!   references; roughness ignored); dielectric with `ior ≠ 1` → smooth `dielectric` (`int_ior` = ior,
//!   `ext_ior` = 1); `ior = 1`, or a medium boundary without a material → `null` (index-matched);
//! - media: `homogeneous` (`sigma_t` · `scale` = σ_s + σ_a, normalised so each rgb channel is ≤ 1 as Mitsuba requires; `albedo` = σ_s/σ_t per channel, HG `g`) or, for
//!   exponential height fog, `heterogeneous` with a 3-channel `gridvolume` of σ_t·ρ(x) sampled at cell
//!   centres finely along the fog's direction (relative interpolation error ≤ [`GRID_TOLERANCE`]² / 8 per
//!   cell); a closed medium mesh gets `interior` = its medium and `exterior` = the medium around it;
//! - the global medium fills [`Scene::global_medium_bounds`] (the one model of where it ends, see
//!   [`crate::scene::extent`]): a `cube` shape with a `null` BSDF and that medium inside;
//! - the camera: `perspective` with `fov_axis = y`, `fov` = yfov, `to_world` = look-at(position,
//!   position + forward, up); Mitsuba's look-at puts `up × forward` on the image's left, i.e. `forward ×
//!   up` on its right, as voltab's camera; a camera inside a medium gets that medium.
//!
//! Parameters the harness sets at load time: `spp`, `width`, `height`, `max_depth`, `rr_depth`.

mod build;
mod geometry;
pub mod ply;
pub mod vol;
pub mod xml;

#[cfg(test)]
mod tests;

use std::path::{Path, PathBuf};

use serde::Serialize;

use crate::scene::Scene;

pub use build::{Built, build};

/// Largest `b·Δ` (falloff × cell size projected on the fog's direction) the height-fog grids allow.
pub const GRID_TOLERANCE: f64 = 0.05;

/// Largest number of cells of one grid volume (a warning names the medium when the tolerance would need more).
pub const GRID_MAX_CELLS: usize = 1 << 22;

/// What to export.
#[derive(Debug, Clone, PartialEq)]
pub struct ExportOptions {
    /// Camera name; `None`: the scene's first camera.
    pub camera: Option<String>,
    /// Default image width \[px\] (the harness may override it).
    pub width: u32,
    /// Default image height \[px\]; `None`: from the camera's aspect ratio (4:3 when it has none).
    pub height: Option<u32>,
    /// Default samples per pixel.
    pub spp: u32,
}

impl Default for ExportOptions {
    fn default() -> Self {
        ExportOptions { camera: None, width: 256, height: None, spp: 64 }
    }
}

/// An export failed.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum ExportError {
    /// A file could not be written.
    #[error("{}: {message}\n  help: check that the output folder is writable and the disk is not full", path.display())]
    Io {
        /// The file or folder.
        path: PathBuf,
        /// The operating system's message.
        message: String,
    },
    /// `--camera` names no camera of the scene.
    #[error("{}: no camera named \"{name}\"\n  help: the scene's cameras are: {}", scene.display(), if available.is_empty() { "(none)".to_string() } else { available.join(", ") })]
    UnknownCamera {
        /// The scene file.
        scene: PathBuf,
        /// The requested name.
        name: String,
        /// The cameras the scene has.
        available: Vec<String>,
    },
}

/// Something exported approximately or left out.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ExportWarning {
    /// Light, mesh, medium or camera name.
    pub location: String,
    /// What differs from voltab's scene.
    pub message: String,
}

/// The region a global medium fills.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct GlobalRegion {
    /// Index into the scene's media.
    pub medium: usize,
    /// Mitsuba id of the medium.
    pub id: String,
    /// Box corner \[m\].
    pub min: [f64; 3],
    /// Box corner \[m\].
    pub max: [f64; 3],
    /// The model, in words.
    pub model: String,
}

/// One exported medium.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct MediumEntry {
    /// Scene name.
    pub name: String,
    /// Mitsuba id.
    pub id: String,
    /// `homogeneous` or `heterogeneous`.
    pub mitsuba_type: String,
    /// `global` or the bounding mesh's name.
    pub boundary: String,
    /// The grid volume file (heterogeneous media).
    pub grid: Option<GridEntry>,
}

/// A grid volume written for a medium.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct GridEntry {
    /// Path relative to the export folder.
    pub file: String,
    /// Cells along x, y, z.
    pub resolution: [usize; 3],
    /// Box corner \[m\].
    pub min: [f64; 3],
    /// Box corner \[m\].
    pub max: [f64; 3],
    /// Bound on the relative error of trilinear interpolation of the exponential between cell centres.
    pub max_relative_interpolation_error: f64,
}

/// One exported shape.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ShapeEntry {
    /// Mitsuba id.
    pub id: String,
    /// Mesh or light name in the scene.
    pub name: String,
    /// PLY file relative to the export folder (meshes), `None` for analytic shapes.
    pub file: Option<String>,
    /// BSDF written (`diffuse`, `dielectric`, `null`).
    pub bsdf: String,
    /// Interior medium id.
    pub interior: Option<String>,
    /// Exterior medium id.
    pub exterior: Option<String>,
    /// Emitted radiance \[W/(m²·sr)\] of an `area` emitter on it.
    pub emission: Option<[f64; 3]>,
    /// Whether winding and normals were reversed (a medium boundary oriented inward).
    pub flipped: bool,
}

/// One exported light.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct LightEntry {
    /// Scene name.
    pub name: String,
    /// voltab kind.
    pub kind: String,
    /// Mitsuba plugin.
    pub mitsuba: String,
}

/// The exported camera.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct CameraEntry {
    /// Scene name.
    pub name: String,
    /// Default width \[px\].
    pub width: u32,
    /// Default height \[px\].
    pub height: u32,
    /// Vertical field of view \[deg\].
    pub fov_y_deg: f64,
    /// Medium the camera sits in (id).
    pub medium: Option<String>,
}

/// `export.json`: what was exported and how.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Manifest {
    /// Always `voltab-mitsuba-export`.
    pub format: String,
    /// Version of this layout.
    pub version: u32,
    /// The scene file.
    pub source: PathBuf,
    /// The Mitsuba scene, relative to the export folder.
    pub scene_xml: String,
    /// Unit conventions, by quantity.
    pub units: Vec<(String, String)>,
    /// The global medium's region, when the scene has a global medium.
    pub global_medium: Option<GlobalRegion>,
    /// The camera, when the scene has one.
    pub camera: Option<CameraEntry>,
    /// Shapes.
    pub shapes: Vec<ShapeEntry>,
    /// Media.
    pub media: Vec<MediumEntry>,
    /// Lights.
    pub lights: Vec<LightEntry>,
    /// Approximations and omissions.
    pub warnings: Vec<ExportWarning>,
}

/// Exports `scene` into `out` (created when missing; files of an earlier export are replaced).
pub fn export(scene: &Scene, options: &ExportOptions, out: &Path) -> Result<Manifest, ExportError> {
    let built = build(scene, options)?;
    for (rel, bytes) in &built.files {
        write_atomic(&out.join(rel), bytes)?;
    }
    write_atomic(&out.join(&built.manifest.scene_xml), built.xml.document().as_bytes())?;
    let json = serde_json::to_string_pretty(&built.manifest).expect("the manifest serialises");
    write_atomic(&out.join("export.json"), format!("{json}\n").as_bytes())?;
    Ok(built.manifest)
}

/// Creates `path`'s folder, then writes it through the project's one atomic writer
/// ([`crate::cache::write_atomic`]: temp file, fsync, rename).
fn write_atomic(path: &Path, bytes: &[u8]) -> Result<(), ExportError> {
    let dir = path.parent().unwrap_or(Path::new("."));
    std::fs::create_dir_all(dir).map_err(|e| ExportError::Io { path: dir.to_path_buf(), message: e.to_string() })?;
    crate::cache::write_atomic(path, bytes).map_err(|e| match e {
        crate::cache::CacheError::Io { source, .. } => {
            ExportError::Io { path: path.to_path_buf(), message: source.to_string() }
        }
        other => ExportError::Io { path: path.to_path_buf(), message: other.to_string() },
    })
}
