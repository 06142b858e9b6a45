//! The scene model every importer fills and every downstream stage reads: triangle meshes in world
//! space, materials, lights in one radiometric convention, cameras and participating media.
//!
//! **Input → output.** A glTF 2.0 file ([`gltf_import`]) or a USD layer ([`usd_import`]) → a [`Scene`],
//! checked by [`check`] (broken geometry and media are errors naming the node or prim; unit mistakes are
//! warnings). [`bvh`] builds ray queries over it and [`crate::plan`] turns it into "these tables and
//! slices". The conventions below are the contract between the two importers; `docs/design/scene.md`
//! gives the full mapping from each format.
//!
//! **World.** Right-handed, +Y up, lengths in metres. USD stages are scaled by `metersPerUnit` and
//! Z-up stages rotated to Y-up; glTF is already in this frame.
//!
//! **Lights** (one convention, radiometric, per linear-RGB channel; photometric inputs divide by
//! [`LUMENS_PER_WATT`] = 683 lm/W):
//! - point and spot: radiant intensity `I` \[W/sr\] (glTF candela / 683; UsdLux treatAsPoint sphere:
//!   `L·πr²`);
//! - directional: irradiance `E` \[W/m²\] on a surface facing the light (glTF lux / 683; UsdLux distant:
//!   `L` × the solid angle of its `angle`, or `L` itself with `normalize`);
//! - rectangle, disk, sphere and emissive meshes: emitted radiance `L` \[W/(m²·sr)\] (UsdLux nits / 683,
//!   divided by the world-space area with `normalize`; glTF emissive × emissive strength read as nits);
//! - the environment ([`EnvironmentLight`], USD `DomeLight`): radiance `L(ω)` \[W/(m²·sr)\] arriving from
//!   direction `ω`, the texture's value (1 without a texture) × `color` × `scale`, where `scale` is
//!   UsdLux's `intensity · 2^exposure` nits / 683 like every other UsdLux light.
//!
//! **Media.** Coefficients `σ_s`, `σ_a` in 1/m and HG `g`, per channel, scaled by a [`Density`]
//! (homogeneous, or iser2018's exponential height fog `ρ(x) = ρ'·e^{−b⟨x−o, n⟩}`). A medium fills a
//! closed mesh ([`Boundary::Mesh`], whose surface may be refractive) or all space outside closed media
//! ([`Boundary::Global`]).

pub mod bvh;
pub mod cache;
pub mod check;
pub mod extent;
#[cfg(test)]
pub(crate) mod fixtures;
pub mod gltf_import;
pub mod summary;
pub mod usd_import;

use std::fmt;
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use crate::physics::medium::RgbMedium;

/// Luminous efficacy used to turn photometric inputs into voltab's radiometric units \[lm/W\].
pub const LUMENS_PER_WATT: f64 = 683.0;

/// An RGB triple (linear, per channel).
pub type Rgb = [f64; 3];

/// Which format a scene came from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum SceneFormat {
    /// glTF 2.0 (`.gltf` or `.glb`).
    Gltf,
    /// USD (`.usda`, `.usdc`, `.usd`, `.usdz`).
    Usd,
}

/// An imported scene in world space.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Scene {
    /// The file it was read from.
    pub source: PathBuf,
    /// Its format.
    pub format: SceneFormat,
    /// Triangle meshes, world space.
    pub meshes: Vec<Mesh>,
    /// Materials referenced by meshes.
    pub materials: Vec<Material>,
    /// Lights (emissive meshes included, as [`LightKind::EmissiveMesh`]).
    pub lights: Vec<Light>,
    /// Cameras.
    pub cameras: Vec<Camera>,
    /// Participating media.
    pub media: Vec<Medium>,
    /// The distant environment (USD `DomeLight`; glTF has none).
    #[serde(default)]
    pub environment: Option<EnvironmentLight>,
    /// What the importer or the checks noticed but could still import.
    pub warnings: Vec<SceneWarning>,
}

/// A distant environment lighting the scene from every direction (USD `DomeLight`, `DomeLight_1`): the
/// radiance arriving from world direction `ω` is `texel(ω) · color · scale` \[W/(m²·sr)\] per channel,
/// `texel` read from a latitude–longitude texture (OpenEXR's convention in the map's frame: row 0 toward
/// the map's +Y, the centre column toward its +Z, a quarter across toward its +X; the same as
/// `render::environment`), or 1 without a texture (a uniform environment).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct EnvironmentLight {
    /// Prim path; every diagnostic uses it.
    pub name: String,
    /// Absolute path of the latitude–longitude texture (USD asset paths resolved against the layer that
    /// authors them); `None`: a uniform environment.
    pub texture: Option<PathBuf>,
    /// Radiance per unit texel value \[W/(m²·sr)\]: `intensity · 2^exposure / 683`.
    pub scale: f64,
    /// Linear RGB tint (`inputs:color`).
    pub color: Rgb,
    /// World-from-map rotation (orthogonal; column-major: `rotation[j]` is the world direction of the
    /// map's axis `j`), from the prim's world transform with scale and translation removed.
    pub rotation: [[f64; 3]; 3],
}

impl EnvironmentLight {
    /// `color · scale` per channel: the radiance of a uniform environment, or what multiplies each texel.
    pub fn multiplier(&self) -> Rgb {
        self.color.map(|c| c * self.scale)
    }
}

/// A triangle mesh, transformed to world space.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Mesh {
    /// Node name (glTF) or prim path (USD); every diagnostic uses it.
    pub name: String,
    /// Vertex positions in metres, world space.
    pub positions: Vec<[f32; 3]>,
    /// Unit vertex normals, world space (computed from faces when the file has none).
    pub normals: Vec<[f32; 3]>,
    /// Material UVs (glTF `TEXCOORD_0`, USD `primvars:st`).
    pub uv: Option<Vec<[f32; 2]>>,
    /// Lightmap UVs (glTF `TEXCOORD_1`, USD `primvars:st1` or `primvars:lightmapUV`).
    pub lightmap_uv: Option<Vec<[f32; 2]>>,
    /// Triangles (counter-clockwise seen from the side the normals point to).
    pub triangles: Vec<[u32; 3]>,
    /// Index into [`Scene::materials`].
    pub material: Option<usize>,
    /// Index into [`Scene::media`] of the medium this closed mesh bounds.
    pub medium: Option<usize>,
    /// Object-to-world matrix (column-major, metres), as composed from the node/prim hierarchy.
    pub to_world: [[f64; 4]; 4],
}

/// How light crosses a surface.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub enum Surface {
    /// Opaque diffuse/glossy reflector.
    Opaque,
    /// Smooth or rough dielectric interface with this index of refraction (light refracts into the
    /// medium the mesh bounds); `ior == 1` is an index-matched boundary (light passes unbent).
    Dielectric {
        /// Index of refraction inside relative to outside.
        ior: f64,
    },
}

/// A surface material.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Material {
    /// Material name (glTF) or prim path (USD).
    pub name: String,
    /// Diffuse reflectance (glTF baseColorFactor, USD diffuseColor).
    pub base_color: Rgb,
    /// Emitted radiance \[W/(m²·sr)\], see the module doc.
    pub emission: Rgb,
    /// Opaque or dielectric.
    pub surface: Surface,
    /// Perceptual roughness in [0, 1].
    pub roughness: f64,
}

/// Kinds of light and their geometry (world space, metres, unit directions).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub enum LightKind {
    /// Isotropic point light; `radiance` holds intensity \[W/sr\].
    Point {
        /// Position.
        position: [f64; 3],
    },
    /// Spot light; `radiance` holds on-axis intensity \[W/sr\].
    Spot {
        /// Position.
        position: [f64; 3],
        /// Direction the light shines to.
        direction: [f64; 3],
        /// Full-intensity cone half-angle \[rad\].
        inner_cone: f64,
        /// Cut-off cone half-angle \[rad\].
        outer_cone: f64,
    },
    /// Distant light; `radiance` holds irradiance \[W/m²\] on a surface facing it.
    Directional {
        /// Direction the light travels to.
        direction: [f64; 3],
        /// Angular diameter of the source \[rad\] (0 for glTF).
        angle: f64,
    },
    /// One-sided rectangle emitting along `normal`; `radiance` holds radiance.
    Rect {
        /// Centre.
        center: [f64; 3],
        /// Half-extent vector along the first side.
        half_u: [f64; 3],
        /// Half-extent vector along the second side.
        half_v: [f64; 3],
        /// Emitting side.
        normal: [f64; 3],
    },
    /// One-sided disk emitting along `normal`; `radiance` holds radiance.
    Disk {
        /// Centre.
        center: [f64; 3],
        /// Emitting side.
        normal: [f64; 3],
        /// Radius.
        radius: f64,
    },
    /// Sphere emitting outward; `radiance` holds radiance.
    Sphere {
        /// Centre.
        center: [f64; 3],
        /// Radius.
        radius: f64,
    },
    /// An emissive mesh; `radiance` holds radiance (its material's emission).
    EmissiveMesh {
        /// Index into [`Scene::meshes`].
        mesh: usize,
    },
}

/// A light in voltab's radiometric convention (module doc).
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Light {
    /// Node name or prim path.
    pub name: String,
    /// Geometry.
    pub kind: LightKind,
    /// Per channel: intensity \[W/sr\] (point, spot), irradiance \[W/m²\] (directional) or radiance
    /// \[W/(m²·sr)\] (area lights, emissive meshes).
    pub radiance: Rgb,
}

/// Camera projection.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub enum Projection {
    /// Pinhole camera.
    Perspective {
        /// Vertical field of view \[rad\].
        yfov: f64,
        /// Width / height, when the file gives it.
        aspect: Option<f64>,
    },
    /// Parallel projection.
    Orthographic {
        /// Half-width of the view \[m\].
        xmag: f64,
        /// Half-height of the view \[m\].
        ymag: f64,
    },
}

/// A camera (looks along `forward`, world space).
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Camera {
    /// Node name or prim path.
    pub name: String,
    /// Eye position.
    pub position: [f64; 3],
    /// Unit viewing direction.
    pub forward: [f64; 3],
    /// Unit up vector (orthogonal to `forward`).
    pub up: [f64; 3],
    /// Projection.
    pub projection: Projection,
    /// Near clipping distance \[m\].
    pub znear: f64,
    /// Far clipping distance \[m\] (None: infinite).
    pub zfar: Option<f64>,
}

/// Spatial variation of a medium's density (multiplies `σ_s` and `σ_a`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub enum Density {
    /// Constant 1.
    Homogeneous,
    /// iser2018's exponential height fog: `ρ(x) = rho · exp(−falloff · ⟨x − offset, direction⟩)`.
    ExponentialHeight {
        /// Density `ρ'` at the offset plane.
        rho: f64,
        /// Falloff `b` \[1/m\].
        falloff: f64,
        /// Unit direction `n` the density decreases along ("up").
        direction: [f64; 3],
        /// Point `o` on the reference plane \[m\].
        offset: [f64; 3],
    },
}

/// Where a medium is.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum Boundary {
    /// Inside this closed mesh (index into [`Scene::meshes`]).
    Mesh(usize),
    /// Everywhere outside the closed media: an atmosphere or room fog.
    Global,
}

/// A participating medium.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Medium {
    /// Material name, node name or prim path it came from.
    pub name: String,
    /// Scattering coefficient \[1/m\] per channel at density 1.
    pub sigma_s: Rgb,
    /// Absorption coefficient \[1/m\] per channel at density 1.
    pub sigma_a: Rgb,
    /// HG mean cosine per channel.
    pub g: Rgb,
    /// Density field.
    pub density: Density,
    /// Where it is.
    pub boundary: Boundary,
}

/// Something the importer or the checks noticed; the scene still loaded.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SceneWarning {
    /// Node name, prim path or material the warning is about.
    pub location: String,
    /// What is wrong.
    pub message: String,
    /// What to do about it.
    pub help: String,
}

/// A scene could not be imported.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub struct SceneError {
    /// The file.
    pub file: PathBuf,
    /// Node name, prim path or JSON pointer, when the problem has one.
    pub location: Option<String>,
    /// What is wrong.
    pub message: String,
    /// How to fix it.
    pub help: String,
}

impl fmt::Display for SceneError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}", self.file.display())?;
        if let Some(loc) = &self.location {
            write!(f, ": {loc}")?;
        }
        write!(f, ": {}", self.message)?;
        if !self.help.is_empty() {
            write!(f, "\n  help: {}", self.help)?;
        }
        Ok(())
    }
}

impl SceneError {
    /// An error at `location` in `file`.
    pub fn at(file: &Path, location: impl Into<String>, message: impl Into<String>, help: impl Into<String>) -> Self {
        SceneError {
            file: file.to_path_buf(),
            location: Some(location.into()),
            message: message.into(),
            help: help.into(),
        }
    }

    /// An error about the whole file.
    pub fn file(file: &Path, message: impl Into<String>, help: impl Into<String>) -> Self {
        SceneError { file: file.to_path_buf(), location: None, message: message.into(), help: help.into() }
    }
}

impl Medium {
    /// The coefficients at density 1, without the density field and the boundary.
    pub fn coefficients(&self) -> RgbMedium {
        RgbMedium { sigma_s: self.sigma_s, sigma_a: self.sigma_a, g: self.g }
    }

    /// Extinction `σ_s + σ_a` per channel at density 1.
    pub fn sigma_t(&self) -> Rgb {
        self.coefficients().sigma_t()
    }

    /// Single-scattering albedo per channel (0 where `σ_t = 0`).
    pub fn albedo(&self) -> Rgb {
        [0, 1, 2].map(|c| self.coefficients().channel(c).albedo())
    }
}

impl Density {
    /// Largest density over an axis-aligned box (the scene bounds; `None`: the density at the offset
    /// plane). An exponential is monotone along its direction, so a corner of the box holds its maximum.
    pub fn max_over(&self, bounds: Option<([f64; 3], [f64; 3])>) -> f64 {
        match self {
            Density::Homogeneous => 1.0,
            Density::ExponentialHeight { rho, falloff, direction, offset } => {
                let Some((lo, hi)) = bounds else { return *rho };
                let len = direction.iter().map(|x| x * x).sum::<f64>().sqrt().max(f64::MIN_POSITIVE);
                (0..8)
                    .map(|c| {
                        let p = [0, 1, 2].map(|k| if c >> k & 1 == 1 { hi[k] } else { lo[k] });
                        let h: f64 = (0..3).map(|k| (p[k] - offset[k]) * direction[k] / len).sum();
                        rho * (-falloff * h).exp()
                    })
                    .fold(0.0, f64::max)
            }
        }
    }
}

impl Scene {
    /// An empty scene read from `source` (importers fill it).
    pub fn empty(source: &Path, format: SceneFormat) -> Scene {
        Scene {
            source: source.to_path_buf(),
            format,
            meshes: Vec::new(),
            materials: Vec::new(),
            lights: Vec::new(),
            cameras: Vec::new(),
            media: Vec::new(),
            environment: None,
            warnings: Vec::new(),
        }
    }

    /// Reads a scene, choosing the importer by extension (`.gltf`/`.glb` or `.usd`/`.usda`/`.usdc`/
    /// `.usdz`), then runs [`check::check`]. Warnings land in [`Scene::warnings`].
    pub fn load(path: &Path) -> Result<Scene, SceneError> {
        let ext = path.extension().and_then(|e| e.to_str()).unwrap_or("").to_ascii_lowercase();
        let mut scene = match ext.as_str() {
            "gltf" | "glb" => gltf_import::import(path)?,
            "usd" | "usda" | "usdc" | "usdz" => usd_import::import(path)?,
            _ => {
                return Err(SceneError::file(
                    path,
                    format!("unknown scene format \"{ext}\""),
                    "give a glTF 2.0 file (.gltf, .glb) or a USD layer (.usd, .usda, .usdc, .usdz)",
                ));
            }
        };
        check::check(&mut scene)?;
        Ok(scene)
    }

    /// Number of triangles over all meshes.
    pub fn triangle_count(&self) -> usize {
        self.meshes.iter().map(|m| m.triangles.len()).sum()
    }

    /// Axis-aligned bounds of all mesh vertices and positioned lights, `None` for an empty scene.
    pub fn bounds(&self) -> Option<([f64; 3], [f64; 3])> {
        let mut lo = [f64::INFINITY; 3];
        let mut hi = [f64::NEG_INFINITY; 3];
        let mut add = |p: [f64; 3]| {
            for c in 0..3 {
                lo[c] = lo[c].min(p[c]);
                hi[c] = hi[c].max(p[c]);
            }
        };
        for m in &self.meshes {
            for p in &m.positions {
                add(p.map(f64::from));
            }
        }
        for l in &self.lights {
            match &l.kind {
                LightKind::Point { position } | LightKind::Spot { position, .. } => add(*position),
                LightKind::Rect { center, .. } | LightKind::Disk { center, .. } | LightKind::Sphere { center, .. } => {
                    add(*center)
                }
                LightKind::Directional { .. } | LightKind::EmissiveMesh { .. } => {}
            }
        }
        lo[0].is_finite().then_some((lo, hi))
    }

    /// Length of the bounds' diagonal \[m\] (0 for an empty scene).
    pub fn diagonal(&self) -> f64 {
        self.bounds().map_or(0.0, |(lo, hi)| ((0..3).map(|c| (hi[c] - lo[c]).powi(2)).sum::<f64>()).sqrt())
    }
}
