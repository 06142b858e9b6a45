//! glTF 2.0 importer: a `.gltf` (external `.bin` files or base64 data URIs) or `.glb` file → a
//! [`Scene`] per docs/design/scene.md.
//!
//! **Pipeline.** `container` reads the file, checks `extensionsRequired`, validates the JSON with
//! the gltf crate and loads the buffers (never images). `material` maps every material (and the
//! medium a volume material puts inside meshes, with `vendor`'s `VOLTAB_participating_media`).
//! Then the node hierarchy of the default scene (else scene 0, else every root node) is walked
//! with transforms composed in f64: each mesh primitive becomes a world-space mesh (`geometry`,
//! reading data through the bounds-checked `accessor`), `KHR_lights_punctual` lights and cameras
//! are placed, emissive materials turn their meshes into [`LightKind::EmissiveMesh`] lights and
//! volume materials give their meshes a [`Medium`] bounded by the mesh.
//!
//! **Units.** glTF is already right-handed, +Y up, metres. Photometric light inputs are divided by
//! K = 683 lm/W: point and spot candela → W/sr, directional lux → W/m², emissive nits → W/(m²·sr).
//!
//! **Not here.** Manifold media boundaries, degenerate triangles and unit sanity are checked for
//! both importers by [`crate::scene::check`].

mod accessor;
mod container;
mod geometry;
mod material;
mod vendor;

#[cfg(test)]
mod tests;

use std::path::Path;

use glam::{DMat4, DQuat, DVec3};
use gltf::json;
use gltf::json::validation::Checked;

use self::accessor::Accessors;
use self::geometry::Placement;
use self::material::MaterialInfo;
use self::vendor::{DensityKind, DensitySpec};
use super::{
    Boundary, Camera, Density, LUMENS_PER_WATT, Light, LightKind, Medium, Projection, Scene, SceneError, SceneFormat,
    SceneWarning,
};

/// JSON Schema of the vendor extension `VOLTAB_participating_media`
/// (`schemas/VOLTAB_participating_media.schema.json`).
pub fn vendor_schema() -> serde_json::Value {
    vendor::schema()
}

/// Reads a `.gltf` or `.glb` file into a scene (not yet checked: [`Scene::load`] runs the checks).
pub fn import(path: &Path) -> Result<Scene, SceneError> {
    convert(path, container::load(path)?)
}

/// Reads a `.gltf` or `.glb` document held in memory (`path` names it in messages). Buffers must be
/// embedded (GLB BIN chunk or data URIs): a buffer naming a file is an error.
pub fn import_bytes(path: &Path, bytes: &[u8]) -> Result<Scene, SceneError> {
    convert(path, container::load_bytes(path, bytes, None)?)
}

fn convert(path: &Path, loaded: container::Loaded) -> Result<Scene, SceneError> {
    let root = loaded.doc.as_json();
    let mut im = Importer {
        file: path,
        root,
        acc: Accessors { root, buffers: &loaded.buffers },
        materials: Vec::new(),
        scene: Scene::empty(path, SceneFormat::Gltf),
    };
    for (i, m) in loaded.doc.materials().enumerate() {
        let info = material::read(path, i, &m, &mut im.scene.warnings)?;
        im.scene.materials.push(info.material.clone());
        im.materials.push(info);
    }
    im.global_medium()?;
    im.walk()?;
    Ok(im.scene)
}

/// State of one import.
struct Importer<'a> {
    file: &'a Path,
    root: &'a json::Root,
    acc: Accessors<'a>,
    /// Per glTF material (same order as `scene.materials`).
    materials: Vec<MaterialInfo>,
    scene: Scene,
}

impl Importer<'_> {
    /// `node "name"` or `nodes[i]`, for diagnostics.
    fn node_location(&self, i: usize) -> String {
        match self.root.nodes.get(i).and_then(|n| n.name.as_deref()) {
            Some(name) => format!("node \"{name}\""),
            None => format!("nodes[{i}]"),
        }
    }

    /// The node's name, or its index when it has none (mesh, light and camera names).
    fn node_label(&self, i: usize) -> String {
        self.root.nodes.get(i).and_then(|n| n.name.clone()).unwrap_or_else(|| i.to_string())
    }

    fn error(&self, node: usize, message: impl Into<String>, help: impl Into<String>) -> SceneError {
        SceneError::at(self.file, self.node_location(node), message, help)
    }

    fn warn(&mut self, location: String, message: impl Into<String>, help: impl Into<String>) {
        self.scene.warnings.push(SceneWarning { location, message: message.into(), help: help.into() });
    }

    /// Root `extensions.VOLTAB_participating_media.global` → a [`Boundary::Global`] medium.
    fn global_medium(&mut self) -> Result<(), SceneError> {
        let Some(value) = self.root.extensions.as_ref().and_then(|e| e.others.get(vendor::EXTENSION)) else {
            return Ok(());
        };
        let parsed = vendor::parse_root(value).map_err(|e| {
            SceneError::at(
                self.file,
                "root extensions",
                format!("{}: {e}", vendor::EXTENSION),
                "see schemas/VOLTAB_participating_media.schema.json",
            )
        })?;
        if let Some(g) = parsed.global {
            self.scene.media.push(Medium {
                name: "global".into(),
                sigma_s: g.sigma_s.unwrap_or_default(),
                sigma_a: g.sigma_a.unwrap_or_default(),
                g: g.anisotropy.map_or([0.0; 3], |a| a.0),
                density: g.density.as_ref().map_or(Density::Homogeneous, |d| density_in_world(d, &DMat4::IDENTITY)),
                boundary: Boundary::Global,
            });
        }
        Ok(())
    }

    /// Root nodes to import: the default scene's, else scene 0's, else every node without a parent.
    /// Also rejects nodes with two parents and scene roots that have a parent (glTF 2.0 §3.5.3:
    /// nodes form disjoint strict trees), which also rules out cycles.
    fn roots(&self) -> Result<Vec<usize>, SceneError> {
        let mut parent: Vec<Option<usize>> = vec![None; self.root.nodes.len()];
        for (p, node) in self.root.nodes.iter().enumerate() {
            for c in node.children.iter().flatten().map(|c| c.value()) {
                if let Some(first) = parent[c].replace(p) {
                    return Err(self.error(
                        c,
                        format!(
                            "the node is a child of both {} and {}",
                            self.node_location(first),
                            self.node_location(p)
                        ),
                        "glTF node hierarchies are trees: each node has at most one parent (instance meshes instead)",
                    ));
                }
            }
        }
        let scene = self.root.scene.map(|s| s.value()).or((!self.root.scenes.is_empty()).then_some(0));
        let Some(scene) = scene else {
            return Ok((0..parent.len()).filter(|&i| parent[i].is_none()).collect());
        };
        let roots: Vec<usize> = self.root.scenes[scene].nodes.iter().map(|n| n.value()).collect();
        if let Some(&r) = roots.iter().find(|&&r| parent[r].is_some()) {
            return Err(self.error(
                r,
                format!("listed as a root of scenes[{scene}] but it is a child of another node (a cycle or a broken hierarchy)"),
                "scene.nodes lists root nodes only",
            ));
        }
        Ok(roots)
    }

    /// Depth-first walk (pre-order, children in file order) composing transforms.
    fn walk(&mut self) -> Result<(), SceneError> {
        let mut stack: Vec<(usize, DMat4)> = self.roots()?.into_iter().rev().map(|r| (r, DMat4::IDENTITY)).collect();
        while let Some((i, parent)) = stack.pop() {
            let world = parent * self.local_transform(i)?;
            self.visit(i, &world)?;
            let node = &self.root.nodes[i];
            stack.extend(node.children.iter().flatten().rev().map(|c| (c.value(), world)));
        }
        Ok(())
    }

    /// The node's `matrix` (column-major) or `T·R·S`, in f64.
    fn local_transform(&self, i: usize) -> Result<DMat4, SceneError> {
        let node = &self.root.nodes[i];
        let m = match node.matrix {
            Some(m) => DMat4::from_cols_array(&m.map(f64::from)),
            None => {
                let t = node.translation.unwrap_or([0.0; 3]).map(f64::from);
                let [x, y, z, w] = node.rotation.map_or([0.0, 0.0, 0.0, 1.0], |r| r.0).map(f64::from);
                let s = node.scale.unwrap_or([1.0; 3]).map(f64::from);
                let q = DQuat::from_xyzw(x, y, z, w);
                let len = q.length();
                if !(len > 0.0 && len.is_finite()) {
                    return Err(self.error(
                        i,
                        format!("rotation {:?} is not a rotation quaternion", [x, y, z, w]),
                        "use a unit quaternion [x, y, z, w]",
                    ));
                }
                DMat4::from_scale_rotation_translation(DVec3::from(s), q / len, DVec3::from(t))
            }
        };
        if !m.is_finite() {
            return Err(self.error(i, "the node's transform is not finite", "fix the node's matrix or TRS"));
        }
        Ok(m)
    }

    /// Imports what a node carries.
    fn visit(&mut self, i: usize, world: &DMat4) -> Result<(), SceneError> {
        let node = &self.root.nodes[i];
        if let Some(mesh) = node.mesh {
            if node.skin.is_some() {
                self.warn(self.node_location(i), "skin ignored: the mesh is imported in its bind pose at the node", "");
            }
            self.mesh(i, mesh.value(), world)?;
        }
        if let Some(camera) = node.camera {
            self.camera(i, camera.value(), world)?;
        }
        if let Some(light) = node.extensions.as_ref().and_then(|e| e.khr_lights_punctual.as_ref()) {
            self.light(i, light.light.value(), world)?;
        }
        Ok(())
    }

    /// Every primitive of `meshes[m]` at node `i`; their emission and media.
    fn mesh(&mut self, i: usize, m: usize, world: &DMat4) -> Result<(), SceneError> {
        let root = self.root;
        let mesh = &root.meshes[m];
        for (p, prim) in mesh.primitives.iter().enumerate() {
            let at = Placement { file: self.file, name: format!("{}/{p}", self.node_label(i)), world: *world };
            if prim.targets.as_ref().is_some_and(|t| !t.is_empty()) {
                self.warn(format!("mesh \"{}\"", at.name), "morph targets ignored: the base shape is imported", "");
            }
            let Some(mut out) = geometry::primitive_mesh(&at, &self.acc, prim, &mut self.scene.warnings)? else {
                continue;
            };
            let index = self.scene.meshes.len();
            if let Some(info) = out.material.and_then(|k| self.materials.get(k)) {
                let emission = info.material.emission;
                if emission.iter().any(|e| *e > 0.0) {
                    self.scene.lights.push(Light {
                        name: out.name.clone(),
                        kind: LightKind::EmissiveMesh { mesh: index },
                        radiance: emission,
                    });
                }
                if let Some(v) = &info.volume {
                    out.medium = Some(self.scene.media.len());
                    self.scene.media.push(Medium {
                        name: info.material.name.clone(),
                        sigma_s: v.sigma_s,
                        sigma_a: v.sigma_a,
                        g: v.g,
                        density: v.density.as_ref().map_or(Density::Homogeneous, |d| density_in_world(d, world)),
                        boundary: Boundary::Mesh(index),
                    });
                }
            }
            self.scene.meshes.push(out);
        }
        Ok(())
    }

    /// `KHR_lights_punctual` light `l` at node `i` (docs/design/scene.md light table).
    fn light(&mut self, i: usize, l: usize, world: &DMat4) -> Result<(), SceneError> {
        let root = self.root;
        let Some(light) =
            root.extensions.as_ref().and_then(|e| e.khr_lights_punctual.as_ref()).and_then(|x| x.lights.get(l))
        else {
            return Err(self.error(i, format!("KHR_lights_punctual light {l} does not exist"), "fix the light index"));
        };
        let intensity = f64::from(light.intensity);
        let color = light.color.map(f64::from);
        if intensity.is_nan() || intensity < 0.0 || color.iter().any(|c| c.is_nan() || *c < 0.0) {
            return Err(self.error(
                i,
                format!("light {l}: negative intensity {intensity} or color {color:?}"),
                "KHR_lights_punctual intensity and color are ≥ 0",
            ));
        }
        if let Some(range) = light.range {
            self.warn(
                self.node_location(i),
                format!("light {l}: range {range} m ignored; voltab uses physical inverse-square falloff"),
                "remove `range` if the light should reach everything (as it does physically)",
            );
        }
        let position = world.transform_point3(DVec3::ZERO).to_array();
        let direction = world.transform_vector3(DVec3::NEG_Z).try_normalize();
        let Some(direction) = direction.map(|d| d.to_array()) else {
            return Err(self.error(i, "the light's node transform collapses its −Z axis", "use a nonzero scale"));
        };
        use json::extensions::scene::khr_lights_punctual::Type;
        let kind = match (&light.type_, &light.spot) {
            (Checked::Valid(Type::Point), _) => LightKind::Point { position },
            (Checked::Valid(Type::Directional), _) => LightKind::Directional { direction, angle: 0.0 },
            (Checked::Valid(Type::Spot), spot) => {
                let (inner, outer) = spot.as_ref().map_or((0.0, std::f64::consts::FRAC_PI_4), |s| {
                    (f64::from(s.inner_cone_angle), f64::from(s.outer_cone_angle))
                });
                if !(0.0 <= inner && inner <= outer && outer > 0.0 && outer <= std::f64::consts::FRAC_PI_2) {
                    return Err(self.error(
                        i,
                        format!("light {l}: spot cone angles inner {inner} and outer {outer} rad are invalid"),
                        "KHR_lights_punctual needs 0 ≤ innerConeAngle ≤ outerConeAngle ≤ π/2 and outerConeAngle > 0",
                    ));
                }
                LightKind::Spot { position, direction, inner_cone: inner, outer_cone: outer }
            }
            (Checked::Invalid, _) => return Err(self.error(i, format!("light {l} has an unknown type"), "")),
        };
        // Point/spot: candela → W/sr; directional: lux → W/m² (divide by K = 683 lm/W).
        let radiance = color.map(|c| c * intensity / LUMENS_PER_WATT);
        self.scene.lights.push(Light { name: self.node_label(i), kind, radiance });
        Ok(())
    }

    /// `cameras[c]` at node `i`: looks along the node's −Z with +Y up.
    fn camera(&mut self, i: usize, c: usize, world: &DMat4) -> Result<(), SceneError> {
        let cam = &self.root.cameras[c];
        let bad = |what: String| self.error(i, format!("cameras[{c}]: {what}"), "see glTF 2.0 §5.12-5.14");
        use json::camera::Type;
        let (projection, znear, zfar) = match (&cam.type_, &cam.perspective, &cam.orthographic) {
            (Checked::Valid(Type::Perspective), Some(p), _) => {
                let yfov = f64::from(p.yfov);
                if !(yfov > 0.0 && yfov < std::f64::consts::PI) {
                    return Err(bad(format!("yfov {yfov} rad is outside (0, π)")));
                }
                let aspect = p.aspect_ratio.map(f64::from);
                if aspect.is_some_and(|a| a.is_nan() || a <= 0.0) {
                    return Err(bad(format!("aspectRatio {aspect:?} is not positive")));
                }
                (Projection::Perspective { yfov, aspect }, p.znear, p.zfar)
            }
            (Checked::Valid(Type::Orthographic), _, Some(o)) => {
                (Projection::Orthographic { xmag: f64::from(o.xmag), ymag: f64::from(o.ymag) }, o.znear, Some(o.zfar))
            }
            _ => return Err(bad("the type and the projection object given do not match".into())),
        };
        let (znear, zfar) = (f64::from(znear), zfar.map(f64::from));
        if znear.is_nan() || znear < 0.0 || zfar.is_some_and(|f| f.is_nan() || f <= znear) {
            return Err(bad(format!("clipping range znear {znear}, zfar {zfar:?} is invalid")));
        }
        let forward = world.transform_vector3(DVec3::NEG_Z).try_normalize();
        let up = world.transform_vector3(DVec3::Y);
        // Gram-Schmidt: up loses its component along forward (shear or non-uniform scale).
        let frame = forward.and_then(|f| (up - up.dot(f) * f).try_normalize().map(|u| (f, u)));
        let Some((forward, up)) = frame else {
            return Err(self.error(
                i,
                "the camera's node transform is degenerate (no −Z/+Y frame)",
                "use a nonzero scale",
            ));
        };
        self.scene.cameras.push(Camera {
            name: self.node_label(i),
            position: world.transform_point3(DVec3::ZERO).to_array(),
            forward: forward.to_array(),
            up: up.to_array(),
            projection,
            znear,
            zfar,
        });
        Ok(())
    }
}

/// A vendor density field given in the frame of `to_world` → world space. With x_l = M⁻¹x and
/// linear part A: ⟨x_l − o, n⟩ = ⟨x − M o, A⁻ᵀ n⟩, so the offset maps as a point, the direction
/// like a normal, and the falloff scales by |A⁻ᵀ n| (for rigid transforms: unchanged).
fn density_in_world(d: &DensitySpec, to_world: &DMat4) -> Density {
    let DensityKind::ExponentialHeight = d.kind;
    let n = DVec3::from(d.direction.unwrap_or([0.0, 1.0, 0.0])).normalize_or(DVec3::Y);
    let o = DVec3::from(d.offset.unwrap_or([0.0; 3]));
    let nw = glam::DMat3::from_mat4(*to_world).inverse().transpose() * n;
    let len = nw.length();
    let (direction, scale) = if len > 0.0 && len.is_finite() { (nw / len, len) } else { (n, 1.0) };
    Density::ExponentialHeight {
        rho: d.rho,
        falloff: d.falloff * scale,
        direction: direction.to_array(),
        offset: to_world.transform_point3(o).to_array(),
    }
}
