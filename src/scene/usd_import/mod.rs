//! USD importer: a `.usda`, `.usdc`, `.usd` or `.usdz` layer → a [`Scene`] in voltab's conventions,
//! read with the pure-Rust `openusd` crate. The mapping is the contract in `docs/design/scene.md`.
//!
//! **Input → output.** The composed stage (sublayers, references, payloads, variant selections,
//! internal references and instancing, all resolved by openusd) → world-space triangle meshes,
//! materials, lights in voltab's radiometric convention, cameras and media, plus a
//! [`SceneWarning`] for everything read approximately or not at all. The generic checks (manifold
//! media, unit sanity, degenerate triangles) are not done here but in [`super::check`].
//!
//! **Supported.**
//! - Stage metadata: `metersPerUnit` (unauthored: USD's 0.01, with a warning naming the layer) and
//!   `upAxis` (`"Z"` stages are rotated −90° about X to +Y up).
//! - Transforms: every ancestor's xformOps composed through openusd's `local_to_parent_transform`
//!   (translate, scale, rotate in any axis order, orient, transform, `!invert!`,
//!   `!resetXformStack!`).
//! - `UsdGeomMesh`: points, faceVertexCounts/Indices fan-triangulated, holeIndices, orientation
//!   `leftHanded` (and mirroring transforms) flip the winding, normals (`primvars:normals` over
//!   `normals`), primvars `st` → `uv` and `st1` or `lightmapUV` → `lightmap_uv` (as authored, no V
//!   flip); constant, uniform, vertex/varying and faceVarying data, indexed or not; uniform and
//!   faceVarying data split vertices (corners with equal point and bit-identical values share a
//!   vertex). Missing normals are computed area-weighted from the faces.
//! - UsdLux `SphereLight` (`treatAsPoint` → point light), `RectLight`, `DiskLight`, `DistantLight`,
//!   with USD's fallbacks hard-coded (openusd has none) and `normalize`; the pre-2021 un-prefixed
//!   input names are accepted too.
//! - UsdLux `DomeLight` and `DomeLight_1` (`poleAxis`) → [`Scene::environment`](super::Scene): a
//!   latitude–longitude texture (`inputs:texture:format` `latlong` or `automatic`; the asset path
//!   resolved against the layer that authors it) or none (uniform), `intensity · 2^exposure · color / 683`
//!   per texel value, and the prim's rotation (scale and translation do not matter for a dome). The
//!   first dome wins; `dome.rs` derives the orientation.
//! - `UsdGeomCamera` (perspective and orthographic).
//! - UsdShade: `material:binding` (direct, on the prim or inherited, `strongerThanDescendants`,
//!   `material:binding:full` before all-purpose), `UsdPreviewSurface` (diffuseColor, emissiveColor →
//!   emissive-mesh light, roughness, opacity < 1 → dielectric with `ior`), constant values reached
//!   through NodeGraph/Material interface connections, and media from a MaterialX
//!   `ND_anisotropic_vdf` on `outputs:volume` / `outputs:mtlx:volume`.
//! - voltab's own attributes: `voltab:medium = "global"` with `voltab:sigmaS/sigmaA/anisotropy`, and
//!   `voltab:density*` (exponential height fog) on the global prim or a medium mesh; the density's
//!   offset and direction go through the mesh's world transform, and through the stage frame only
//!   (units and up axis, not the prim's xformOps) for the global prim.
//!
//! **Read with a warning naming the prim.** Composition errors (e.g. a missing referenced file);
//! time-sampled attributes (the first sample is read, else the default); subdivision surfaces
//! (`subdivisionScheme` other than `"none"`, including USD's unauthored catmullClark: the control cage
//! is read); SkelRoot meshes (rest pose); textures and shading nodes driving inputs; colour
//! temperature; non-uniformly scaled sphere and disk lights; dome lights with non-uniform scale, shear or
//! a mirroring transform (their nearest orthogonal matrix), `normalize` or portals (ignored), and dome
//! textures that do not resolve to a file (kept; stages lit by the dome fail naming it).
//!
//! **Skipped with a warning naming the prim.** `PointInstancer` (and its subtree), `Skeleton`,
//! `SkelAnimation`, `BlendShape`, `CylinderLight`, `GeometryLight`, `PortalLight`, plugin lights and
//! light filters, dome lights after the first, dome lights whose texture format is not latlong
//! (`mirroredBall`, `angular`, `cubeMapVerticalCross`), whose texture is packaged inside a `.usdz` or
//! whose transform is singular, `ShapingAPI` (spot cones), gprims other than `Mesh` (`Sphere`, `Cube`,
//! `Cylinder`, `Cone`, `Capsule`, `Plane`, `Points`, curves, patches, `TetMesh`), `Volume` fields,
//! per-face `GeomSubset` material bindings and collection bindings.
//!
//! **Skipped silently (intended by the author).** Inactive prims, `class` and `over`-only prims,
//! prims with `visibility = "invisible"` and their subtrees, and `purpose` `guide` or `proxy`
//! subtrees (a final render shows `default` and `render`).
//!
//! **Errors** ([`SceneError`] naming the file and prim): a missing or unparsable file, topology that
//! does not add up (counts vs indices, faces with fewer than 3 vertices, indices out of range),
//! non-finite points, negative or non-finite light values, invalid camera parameters, a second
//! global medium. The importer never panics on bad input; a panic inside openusd is caught and
//! reported as an error. openusd itself can hang (a deleted `>` in a relationship path loops in
//! `Path::parent`), overflow its stack (instancing) or request an impossible allocation (array
//! lengths of a corrupt `.usdc`): the `voltab` binary therefore parses every layer in a guarded
//! child process ([`guard`]: time limit, memory limit, large stack), so those become errors naming
//! the file. A layer openusd cannot open is located by `locate`: line and column in a text layer,
//! the broken part's byte range in a crate file.
//!
//! openusd's `Stage` is not `Send`; everything is converted on the calling thread into voltab's
//! own structs.

mod dome;
pub mod guard;
mod lights;
mod locate;
mod mesh;
mod shade;
mod values;
mod xform;

#[cfg(test)]
mod tests;

use std::collections::{BTreeMap, HashMap, HashSet};
use std::panic::{AssertUnwindSafe, catch_unwind};
use std::path::Path;

use glam::DMat4;
use openusd::sdf;
use openusd::usd::{PrimPredicate, Stage};

use self::shade::MaterialInfo;
use self::xform::Frame;
use super::{Boundary, Density, Light, LightKind, Medium, Scene, SceneError, SceneFormat, SceneWarning};

/// Reads the USD layer at `path` (`.usda`, `.usdc`, `.usd`, `.usdz`) into a [`Scene`] (module doc),
/// in a guarded child process when running as the `voltab` binary ([`guard`]): a hang or crash
/// of the parser becomes an error naming the file.
pub fn import(path: &Path) -> Result<Scene, SceneError> {
    guard::import(path, import_in_process)
}

/// For `main`: when this process was started as the guarded import child, runs it and returns its
/// exit code.
pub fn guarded_child_main() -> Option<std::process::ExitCode> {
    let args: Vec<std::ffi::OsString> = std::env::args_os().collect();
    guard::child_main(&args, import_in_process)
}

/// [`import`] in this process (panics inside openusd are caught; hangs and stack overflows are not).
pub fn import_in_process(path: &Path) -> Result<Scene, SceneError> {
    match catch_unwind(AssertUnwindSafe(|| import_stage(path))) {
        Ok(result) => result,
        Err(panic) => {
            let what = panic
                .downcast_ref::<String>()
                .map(String::as_str)
                .or_else(|| panic.downcast_ref::<&str>().copied())
                .unwrap_or("(no message)");
            Err(SceneError::file(
                path,
                format!("the USD reader (openusd) failed on this file: {what}"),
                "re-export the layer with usd-core (e.g. `usdcat in.usd -o out.usda`) and report the file",
            ))
        }
    }
}

/// The importer's state while it walks the stage.
struct Importer<'a> {
    /// The root layer (every error names it).
    file: &'a Path,
    /// The composed stage.
    stage: Stage,
    /// Stage units and axes.
    frame: Frame,
    /// The scene being built (warnings included).
    scene: Scene,
    /// Converted materials by prim path (`None`: the binding target is not a Material).
    materials: HashMap<sdf::Path, Option<MaterialInfo>>,
    /// Path of the global medium prim, once seen.
    global_medium: Option<String>,
    /// Time-sampled attributes read, per prim: (attribute, number of samples).
    time_sampled: BTreeMap<String, Vec<(String, usize)>>,
    /// Prims already checked for collection-based material bindings.
    binding_checked: HashSet<sdf::Path>,
}

/// What the traversal does below a prim.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Flow {
    /// Visit the children.
    Descend,
    /// Skip the subtree.
    Prune,
}

/// Per visited prim: its stage-space world matrix and its effective purpose.
#[derive(Debug, Clone)]
struct Node {
    world: DMat4,
    purpose: Option<String>,
}

/// Gprims other than Mesh (skipped with a warning).
const OTHER_GPRIMS: [&str; 14] = [
    "Sphere",
    "Cube",
    "Cylinder",
    "Cylinder_1",
    "Cone",
    "Capsule",
    "Capsule_1",
    "Plane",
    "Points",
    "BasisCurves",
    "NurbsCurves",
    "HermiteCurves",
    "NurbsPatch",
    "TetMesh",
];

/// Lights voltab has no model for (skipped with a warning).
const OTHER_LIGHTS: [&str; 4] = ["CylinderLight", "GeometryLight", "PortalLight", "PluginLight"];

fn import_stage(path: &Path) -> Result<Scene, SceneError> {
    if !path.is_file() {
        let msg = if path.exists() { "is not a file" } else { "does not exist" };
        return Err(SceneError::file(path, format!("the USD file {msg}"), "check the path"));
    }
    let Some(path_str) = path.to_str() else {
        return Err(SceneError::file(path, "the path is not valid UTF-8", "rename the file or a parent folder"));
    };
    locate::refuse_malformed_paths(path)?;
    let stage = Stage::open(path_str).map_err(|e| {
        let message = format!("cannot open the USD layer: {e:#}");
        let help = "check that the file is a valid .usda/.usdc/.usdz (e.g. open it with usd-core's usdcat)";
        match locate::layer_failure(path, &message) {
            Some(at) => SceneError::at(path, at, message, help),
            None => SceneError::file(path, message, help),
        }
    })?;
    let mut imp = Importer {
        file: path,
        stage,
        frame: Frame::new(1.0, false),
        scene: Scene::empty(path, SceneFormat::Usd),
        materials: HashMap::new(),
        global_medium: None,
        time_sampled: BTreeMap::new(),
        binding_checked: HashSet::new(),
    };
    imp.frame = imp.read_frame()?;
    imp.traverse()?;
    imp.finish();
    Ok(imp.scene)
}

impl Importer<'_> {
    /// An error at `prim`.
    fn err(&self, prim: &sdf::Path, message: String, help: impl Into<String>) -> SceneError {
        SceneError::at(self.file, prim.as_str(), message, help)
    }

    /// openusd failed to answer a query about `what` on `prim`.
    fn usd_err(&self, prim: &sdf::Path, what: &str, e: impl std::fmt::Display) -> SceneError {
        self.err(
            prim,
            format!("openusd cannot read `{what}`: {e:#}"),
            "the layer may be malformed; check it with usd-core (usdchecker or usdcat)",
        )
    }

    /// Records a warning.
    fn warn(&mut self, location: &str, message: String, help: &str) {
        self.scene.warnings.push(SceneWarning { location: location.to_owned(), message, help: help.to_owned() });
    }

    /// Remembers that attribute `name` of `prim` has time samples (warned once per prim at the end).
    fn note_time_samples(&mut self, prim: &sdf::Path, name: &str, samples: usize) {
        let list = self.time_sampled.entry(prim.as_str().to_owned()).or_default();
        if !list.iter().any(|(n, _)| n == name) {
            list.push((name.to_owned(), samples));
        }
    }

    /// Walks the composed stage depth-first (parents before children) and converts each prim.
    fn traverse(&mut self) -> Result<(), SceneError> {
        let mut paths = Vec::new();
        // Instance proxies are visited so instanced geometry is imported like any other.
        self.stage.traverse(PrimPredicate::DEFAULT_PROXIES, |p| paths.push(p.clone())).map_err(|e| {
            SceneError::file(self.file, format!("cannot traverse the stage: {e:#}"), "re-export the layer")
        })?;
        let mut nodes: HashMap<sdf::Path, Node> = HashMap::new();
        nodes.insert(sdf::Path::abs_root(), Node { world: DMat4::IDENTITY, purpose: None });
        for path in paths {
            if !locate::ancestry_terminates(&path) {
                return Err(self.err(
                    &path,
                    "the prim's name is not a valid prim name (openusd cannot walk its ancestors)".into(),
                    "name prims with identifiers (letters, digits, '_')",
                ));
            }
            // A parent missing from `nodes` was skipped: so is its subtree.
            let Some(parent) = path.parent().and_then(|p| nodes.get(&p)).cloned() else { continue };
            if self.token_attr(&path, "visibility")?.as_deref() == Some("invisible") {
                continue;
            }
            let purpose = self.token_attr(&path, "purpose")?.or(parent.purpose);
            if matches!(purpose.as_deref(), Some("guide" | "proxy")) {
                continue;
            }
            let prim = self.stage.prim(path.clone());
            let ty = prim.type_name().map_err(|e| self.usd_err(&path, "typeName", e))?;
            let ty = ty.as_ref().map_or("", |t| t.as_str()).to_owned();
            let (local, resets) = self.local_transform(&prim)?;
            let world = if resets { local } else { parent.world * local };
            if self.visit(&path, &ty, &(self.frame.matrix * world))? == Flow::Descend {
                nodes.insert(path, Node { world, purpose });
            }
        }
        Ok(())
    }

    /// Converts one prim of type `ty` with voltab world matrix `m`.
    fn visit(&mut self, path: &sdf::Path, ty: &str, m: &DMat4) -> Result<Flow, SceneError> {
        let loc = path.as_str();
        match ty {
            "Mesh" => self.add_mesh(path, m)?,
            "Camera" => self.read_camera(path, m)?,
            "SphereLight" | "RectLight" | "DiskLight" | "DistantLight" => self.read_light(path, ty, m)?,
            "DomeLight" | "DomeLight_1" => self.read_dome(path, ty, m)?,
            _ if OTHER_LIGHTS.contains(&ty) => self.warn(
                loc,
                format!("{ty} is not supported; the light is skipped"),
                "voltab reads SphereLight, RectLight, DiskLight, DistantLight and DomeLight (and emissive meshes)",
            ),
            "LightFilter" | "PluginLightFilter" => {
                self.warn(loc, format!("{ty} is not supported; it is ignored"), "bake the filter into the light")
            }
            "PointInstancer" => {
                self.warn(
                    loc,
                    "UsdGeomPointInstancer is not supported; its instances (and its subtree) are skipped".into(),
                    "make the instances real prims before export (e.g. instanceable references instead)",
                );
                return Ok(Flow::Prune);
            }
            "SkelRoot" => self.warn(
                loc,
                "UsdSkel is not supported; meshes below this SkelRoot are read in their rest pose".into(),
                "bake the skinned pose into the mesh points before export",
            ),
            "Skeleton" | "SkelAnimation" | "BlendShape" => {
                self.warn(loc, format!("UsdSkel {ty} is not supported; it is ignored"), "bake skinning before export")
            }
            _ if OTHER_GPRIMS.contains(&ty) => self.warn(
                loc,
                format!("{ty} prims are not supported (only Mesh); it is skipped"),
                "convert it to a Mesh (tessellate it) before export",
            ),
            "Volume" | "OpenVDBAsset" | "Field3DAsset" => self.warn(
                loc,
                format!("{ty} (volume fields) is not supported; it is skipped"),
                "describe media with an ND_anisotropic_vdf material on a closed mesh or voltab:medium = \"global\"",
            ),
            "GeomSubset" => self.geom_subset(path)?,
            _ => {}
        }
        self.global_medium(path)?;
        Ok(Flow::Descend)
    }

    /// Warns about per-face material bindings, which are not supported.
    fn geom_subset(&mut self, path: &sdf::Path) -> Result<(), SceneError> {
        let rel = path.append_property("material:binding").map_err(|e| self.usd_err(path, "material:binding", e))?;
        let targets = self.stage.relationship(rel).targets().map_err(|e| self.usd_err(path, "material:binding", e))?;
        if !targets.is_empty() {
            self.warn(
                path.as_str(),
                "per-face material bindings (GeomSubset) are not supported; the faces use the mesh's material".into(),
                "split the mesh by material before export",
            );
        }
        Ok(())
    }

    /// Converts a mesh and attaches its material, medium and emission.
    fn add_mesh(&mut self, path: &sdf::Path, m: &DMat4) -> Result<(), SceneError> {
        let Some(mut mesh) = self.read_mesh(path, m)? else { return Ok(()) };
        let apis = self.stage.prim(path.clone()).api_schemas().map_err(|e| self.usd_err(path, "apiSchemas", e))?;
        if apis.iter().any(|a| matches!(a.as_str(), "MeshLightAPI" | "LightAPI" | "VolumeLightAPI")) {
            self.warn(
                path.as_str(),
                "mesh lights (MeshLightAPI/LightAPI on a Mesh) are not supported; the mesh is read as geometry".into(),
                "make the mesh emissive with a UsdPreviewSurface emissiveColor instead",
            );
        }
        let index = self.scene.meshes.len();
        let info = match self.bound_material(path)? {
            Some(target) => self.material(&target, path)?,
            None => None,
        };
        let density = self.density(path, m)?;
        if let Some(info) = &info {
            mesh.material = Some(info.index);
            if let Some(vol) = &info.volume {
                mesh.medium = Some(self.scene.media.len());
                self.scene.media.push(Medium {
                    name: self.scene.materials[info.index].name.clone(),
                    sigma_s: vol.sigma_s,
                    sigma_a: vol.sigma_a,
                    g: vol.g,
                    density: density.clone().unwrap_or(Density::Homogeneous),
                    boundary: Boundary::Mesh(index),
                });
            }
            let emission = self.scene.materials[info.index].emission;
            if emission.iter().any(|&e| e > 0.0) {
                self.scene.lights.push(Light {
                    name: path.as_str().to_owned(),
                    kind: LightKind::EmissiveMesh { mesh: index },
                    radiance: emission,
                });
            }
        }
        if density.is_some() && mesh.medium.is_none() {
            self.warn(
                path.as_str(),
                "voltab:density is authored on a mesh that bounds no medium; it is ignored".into(),
                "bind a material whose outputs:volume is an ND_anisotropic_vdf",
            );
        }
        self.scene.meshes.push(mesh);
        Ok(())
    }

    /// Turns composition errors and time-sampled attributes into warnings.
    fn finish(&mut self) {
        for e in self.stage.composition_errors() {
            let location = composition_site(&e).unwrap_or_else(|| self.file.display().to_string());
            self.warn(
                &location,
                format!("composition error: {e}"),
                "check the asset path (relative to the layer that authors it) and the target prim; the arc is skipped",
            );
        }
        for (prim, attrs) in std::mem::take(&mut self.time_sampled) {
            let list: Vec<String> = attrs.iter().map(|(a, n)| format!("{a} ({n} samples)")).collect();
            self.warn(
                &prim,
                format!("time-sampled attributes read at their first sample: {}", list.join(", ")),
                "voltab imports one frame; author default values (or bake the frame you want)",
            );
        }
    }
}

/// The prim a composition error is about, when it names one.
fn composition_site(e: &openusd::pcp::Error) -> Option<String> {
    use openusd::pcp::Error as E;
    match e {
        E::UnresolvedLayer { site_path, .. }
        | E::MalformedLayer { site_path, .. }
        | E::MutedAssetPath { site_path, .. }
        | E::InvalidPrimPath { site_path, .. }
        | E::UnresolvedPrimPath { site_path, .. }
        | E::MissingDefaultPrim { site_path, .. }
        | E::InvalidDefaultPrim { site_path, .. }
        | E::InvalidExpression { site_path, .. } => Some(site_path.as_str().to_owned()),
        _ => None,
    }
}
