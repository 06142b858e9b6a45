//! UsdShade → [`Material`] and [`Medium`]: `material:binding` resolution, `UsdPreviewSurface`
//! inputs, MaterialX `ND_anisotropic_vdf` volumes, and voltab's `voltab:medium` / `voltab:density*`
//! attributes (`docs/design/scene.md`, "Materials and media").

use glam::{DMat4, DVec3};
use openusd::sdf::{self, Value};

use super::Importer;
use super::values::{scalar, token, vec3};
use super::xform::normal_matrix;
use crate::scene::{Boundary, Density, LUMENS_PER_WATT, Material, Medium, Rgb, SceneError, Surface};

/// UsdPreviewSurface fallbacks.
const DIFFUSE: f64 = 0.18;
const ROUGHNESS: f64 = 0.5;
const OPACITY: f64 = 1.0;
const IOR: f64 = 1.5;
/// Connection hops followed through NodeGraph / Material interfaces before giving up (cycles).
const MAX_HOPS: usize = 16;

/// Medium coefficients of a material's volume, in 1/m.
#[derive(Debug, Clone)]
pub(super) struct VolumeParams {
    pub sigma_s: Rgb,
    pub sigma_a: Rgb,
    pub g: Rgb,
}

/// A converted material.
#[derive(Debug, Clone)]
pub(super) struct MaterialInfo {
    /// Index into `Scene::materials`.
    pub index: usize,
    /// The medium its `outputs:volume` describes.
    pub volume: Option<VolumeParams>,
}

impl Importer<'_> {
    /// The material bound to `prim` (its own `material:binding` or the closest ancestor's, unless an
    /// ancestor binds `strongerThanDescendants`; `material:binding:full` before all-purpose bindings).
    pub(super) fn bound_material(&mut self, prim: &sdf::Path) -> Result<Option<sdf::Path>, SceneError> {
        for rel_name in ["material:binding:full", "material:binding"] {
            let mut winner = None;
            for p in prim.ancestors_below_root() {
                self.check_collection_bindings(&p)?;
                let rel = p.append_property(rel_name).map_err(|e| self.usd_err(prim, rel_name, e))?;
                let targets =
                    self.stage.relationship(rel.clone()).targets().map_err(|e| self.usd_err(&p, rel_name, e))?;
                let Some(target) = targets.into_iter().next() else { continue };
                // Relationship metadata reads through the attribute handle (openusd's field query).
                let strength = self.stage.attribute(rel).get_metadata::<Value>("bindMaterialAs");
                let stronger = strength.map_err(|e| self.usd_err(&p, rel_name, e))?.as_ref().and_then(token).as_deref()
                    == Some("strongerThanDescendants");
                if winner.is_none() || stronger {
                    winner = Some(target);
                }
            }
            if winner.is_some() {
                return Ok(winner);
            }
        }
        Ok(None)
    }

    /// Warns (once per prim) about collection-based bindings on `prim`, which voltab does not resolve.
    fn check_collection_bindings(&mut self, prim: &sdf::Path) -> Result<(), SceneError> {
        if !self.binding_checked.insert(prim.clone()) {
            return Ok(());
        }
        let names = self.stage.prim(prim.clone()).property_names().map_err(|e| self.usd_err(prim, "properties", e))?;
        if names.iter().any(|n| n.as_str().starts_with("material:binding:collection:")) {
            self.warn(
                prim.as_str(),
                "collection-based material bindings are not supported; only direct material:binding is read".into(),
                "bind materials directly on the meshes (or their ancestors) with material:binding",
            );
        }
        Ok(())
    }

    /// The material at `path` converted once (cached); `None` (after a warning) when the target is not
    /// a Material prim.
    pub(super) fn material(&mut self, path: &sdf::Path, user: &sdf::Path) -> Result<Option<MaterialInfo>, SceneError> {
        if let Some(info) = self.materials.get(path) {
            return Ok(info.clone());
        }
        let ty = self.stage.prim(path.clone()).type_name().map_err(|e| self.usd_err(path, "typeName", e))?;
        let info = if ty.as_ref().map(|t| t.as_str()) == Some("Material") {
            Some(self.convert_material(path)?)
        } else {
            self.warn(
                user.as_str(),
                format!("material:binding targets <{path}>, which is not a Material prim; the binding is ignored"),
                "bind a `def Material` prim (check the target path and that the material's layer is loaded)",
            );
            None
        };
        self.materials.insert(path.clone(), info.clone());
        Ok(info)
    }

    /// Follows connections from attribute `attr` through NodeGraph and Material interface attributes;
    /// returns the final attribute path. Stops at an output of a Shader.
    fn follow(&mut self, mut attr: sdf::Path) -> Result<sdf::Path, SceneError> {
        for _ in 0..MAX_HOPS {
            let owner = attr.prim_path();
            let conns =
                self.stage.attribute(attr.clone()).connections().map_err(|e| self.usd_err(&owner, "connections", e))?;
            let Some(src) = conns.into_iter().next() else { return Ok(attr) };
            let src_prim = src.prim_path();
            let ty =
                self.stage.prim(src_prim.clone()).type_name().map_err(|e| self.usd_err(&src_prim, "typeName", e))?;
            attr = src;
            if ty.as_ref().map(|t| t.as_str()) == Some("Shader") && attr.property_suffix().starts_with(".outputs:") {
                return Ok(attr);
            }
        }
        Err(self.err(&attr.prim_path(), "a shading connection loops".into(), "remove the connection cycle"))
    }

    /// The Shader prim driving material terminal `output` (e.g. `outputs:surface`), if connected.
    fn terminal_shader(&mut self, material: &sdf::Path, output: &str) -> Result<Option<sdf::Path>, SceneError> {
        let attr = material.append_property(output).map_err(|e| self.usd_err(material, output, e))?;
        let end = self.follow(attr.clone())?;
        Ok((end != attr && end.property_suffix().starts_with(".outputs:")).then(|| end.prim_path()))
    }

    /// `info:id` of a shader prim.
    fn shader_id(&mut self, shader: &sdf::Path) -> Result<Option<String>, SceneError> {
        self.token_attr(shader, "info:id")
    }

    /// A shader input's constant value: the value at the end of its connections through interfaces;
    /// an input driven by another shader's output (a texture, a node) warns and falls back to the value
    /// authored on the input itself.
    fn input(&mut self, shader: &sdf::Path, material: &sdf::Path, name: &str) -> Result<Option<Value>, SceneError> {
        let attr = shader.append_property(format!("inputs:{name}")).map_err(|e| self.usd_err(shader, name, e))?;
        let end = self.follow(attr.clone())?;
        if end.property_suffix().starts_with(".outputs:") {
            self.warn(
                material.as_str(),
                format!(
                    "inputs:{name} of <{shader}> is driven by <{end}>; textures and shading nodes are not evaluated"
                ),
                "voltab uses the input's own authored value or the fallback; author a constant to control it",
            );
            return self.value(shader, &format!("inputs:{name}"));
        }
        self.value(&end.prim_path(), end.property_suffix().trim_start_matches('.'))
    }

    /// A numeric shader input.
    fn input_f64(&mut self, shader: &sdf::Path, material: &sdf::Path, name: &str) -> Result<Option<f64>, SceneError> {
        match self.input(shader, material, name)? {
            None => Ok(None),
            Some(v) => scalar(&v).map(Some).ok_or_else(|| self.input_type_err(shader, name, &v, "a float")),
        }
    }

    /// A 3-vector shader input (a scalar is broadcast).
    fn input_rgb(&mut self, shader: &sdf::Path, material: &sdf::Path, name: &str) -> Result<Option<Rgb>, SceneError> {
        match self.input(shader, material, name)? {
            None => Ok(None),
            Some(v) => vec3(&v)
                .or_else(|| scalar(&v).map(|s| [s; 3]))
                .map(Some)
                .ok_or_else(|| self.input_type_err(shader, name, &v, "a color3f or vector3f")),
        }
    }

    fn input_type_err(&self, shader: &sdf::Path, name: &str, v: &Value, expected: &str) -> SceneError {
        self.err(
            shader,
            format!("inputs:{name} holds a {} value, expected {expected}", super::values::type_of(v)),
            format!("author inputs:{name} as {expected}"),
        )
    }

    /// Converts the Material prim at `path` and appends it to the scene.
    fn convert_material(&mut self, path: &sdf::Path) -> Result<MaterialInfo, SceneError> {
        let mut material = Material {
            name: path.as_str().to_owned(),
            base_color: [DIFFUSE; 3],
            emission: [0.0; 3],
            surface: Surface::Opaque,
            roughness: ROUGHNESS,
        };
        let mut surface = self.terminal_shader(path, "outputs:surface")?;
        if surface.is_none() {
            surface = self.terminal_shader(path, "outputs:mtlx:surface")?;
        }
        let volume = self.read_volume(path)?;
        match &surface {
            Some(shader) if self.shader_id(shader)?.as_deref() == Some("UsdPreviewSurface") => {
                self.preview_surface(shader, path, &mut material)?;
            }
            Some(shader) => {
                let id = self.shader_id(shader)?.unwrap_or_else(|| "(no info:id)".into());
                self.warn(
                    path.as_str(),
                    format!("surface shader <{shader}> is {id}, not UsdPreviewSurface; the material uses fallbacks"),
                    "add a UsdPreviewSurface network on outputs:surface (the universal render context)",
                );
            }
            None if volume.is_some() => {
                // A volume-only material: an index-matched boundary (light enters the medium unbent).
                material.surface = Surface::Dielectric { ior: 1.0 };
            }
            None => self.warn(
                path.as_str(),
                "the material has no surface shader connected to outputs:surface; it uses UsdPreviewSurface fallbacks"
                    .into(),
                "connect a UsdPreviewSurface to the material's outputs:surface",
            ),
        }
        if volume.is_some() && material.surface == Surface::Opaque {
            self.warn(
                path.as_str(),
                "the material has a volume but an opaque surface (opacity 1): light cannot enter the medium".into(),
                "set inputs:opacity < 1 (and inputs:ior = 1 for an index-matched boundary) on its UsdPreviewSurface",
            );
        }
        let index = self.scene.materials.len();
        self.scene.materials.push(material);
        Ok(MaterialInfo { index, volume })
    }

    /// Reads UsdPreviewSurface inputs into `m`.
    fn preview_surface(&mut self, shader: &sdf::Path, mat: &sdf::Path, m: &mut Material) -> Result<(), SceneError> {
        if let Some(c) = self.input_rgb(shader, mat, "diffuseColor")? {
            m.base_color = c;
        }
        if let Some(e) = self.input_rgb(shader, mat, "emissiveColor")? {
            // emissiveColor is read as nits (scene.md): L = emissive / K.
            m.emission = e.map(|v| v / LUMENS_PER_WATT);
        }
        if let Some(r) = self.input_f64(shader, mat, "roughness")? {
            m.roughness = r.clamp(0.0, 1.0);
        }
        let opacity = self.input_f64(shader, mat, "opacity")?.unwrap_or(OPACITY);
        if opacity < 1.0 {
            let ior = self.input_f64(shader, mat, "ior")?.unwrap_or(IOR);
            if !(ior.is_finite() && ior > 0.0) {
                return Err(self.err(shader, format!("inputs:ior = {ior}"), "inputs:ior must be a positive number"));
            }
            m.surface = Surface::Dielectric { ior };
        }
        Ok(())
    }

    /// The medium of the material's `outputs:volume` (or `outputs:mtlx:volume`), per metre.
    fn read_volume(&mut self, material: &sdf::Path) -> Result<Option<VolumeParams>, SceneError> {
        let mut shader = self.terminal_shader(material, "outputs:volume")?;
        if shader.is_none() {
            shader = self.terminal_shader(material, "outputs:mtlx:volume")?;
        }
        let Some(shader) = shader else { return Ok(None) };
        let id = self.shader_id(&shader)?;
        if id.as_deref() != Some("ND_anisotropic_vdf") {
            self.warn(
                material.as_str(),
                format!(
                    "volume shader <{shader}> is {}; only ND_anisotropic_vdf is read, the volume is ignored",
                    id.unwrap_or_else(|| "(no info:id)".into())
                ),
                "drive outputs:volume with a MaterialX ND_anisotropic_vdf (absorption, scattering, anisotropy)",
            );
            return Ok(None);
        }
        // Coefficients are authored per stage unit: 1/unit ÷ (m/unit) = 1/m.
        let mpu = self.frame.mpu;
        let sigma_a = self.input_rgb(&shader, material, "absorption")?.unwrap_or([0.0; 3]).map(|v| v / mpu);
        let sigma_s = self.input_rgb(&shader, material, "scattering")?.unwrap_or([0.0; 3]).map(|v| v / mpu);
        let g = self.input_f64(&shader, material, "anisotropy")?.unwrap_or(0.0);
        Ok(Some(VolumeParams { sigma_s, sigma_a, g: [g; 3] }))
    }

    /// `voltab:density*` on `prim`, with `m` mapping the prim's coordinates to world (the prim's world
    /// matrix for meshes, the stage frame for the global medium).
    pub(super) fn density(&mut self, prim: &sdf::Path, m: &DMat4) -> Result<Option<Density>, SceneError> {
        let Some(kind) = self.token_attr(prim, "voltab:density")? else { return Ok(None) };
        match kind.as_str() {
            "homogeneous" => Ok(Some(Density::Homogeneous)),
            "exponentialHeight" => {
                let rho = self.f64_attr(prim, "voltab:density:rho")?.unwrap_or(1.0);
                let falloff = self.f64_attr(prim, "voltab:density:falloff")?.unwrap_or(0.0);
                let up = self.frame.up.to_array();
                let dir = self.vec3_attr(prim, "voltab:density:direction")?.unwrap_or(up);
                let offset = self.vec3_attr(prim, "voltab:density:offset")?.unwrap_or([0.0; 3]);
                let Some(dir) = DVec3::from(dir).try_normalize() else {
                    return Err(self.err(
                        prim,
                        format!("voltab:density:direction = {dir:?} is not a non-zero finite vector"),
                        "author the direction the density decreases along, e.g. (0, 1, 0)",
                    ));
                };
                // ⟨x_l − o_l, n_l⟩ = ⟨x − o, M^{−T} n_l⟩: the world normal is M^{−T} n_l and its length
                // rescales the falloff (for a uniform scale s: falloff / s, i.e. 1/unit → 1/m).
                let Some(nm) = normal_matrix(m) else {
                    return Err(self.err(prim, "the prim's transform is singular".into(), "fix its xformOps"));
                };
                let n_world = nm * dir;
                Ok(Some(Density::ExponentialHeight {
                    rho,
                    falloff: falloff * n_world.length(),
                    direction: n_world.normalize().to_array(),
                    offset: m.transform_point3(DVec3::from(offset)).to_array(),
                }))
            }
            other => {
                self.warn(
                    prim.as_str(),
                    format!("voltab:density = \"{other}\" is unknown; the medium is read as homogeneous"),
                    "use \"homogeneous\" or \"exponentialHeight\"",
                );
                Ok(Some(Density::Homogeneous))
            }
        }
    }

    /// A prim with `voltab:medium = "global"` → the global medium (a second one is an error).
    pub(super) fn global_medium(&mut self, prim: &sdf::Path) -> Result<(), SceneError> {
        match self.token_attr(prim, "voltab:medium")?.as_deref() {
            None => return Ok(()),
            Some("global") => {}
            Some(other) => {
                self.warn(
                    prim.as_str(),
                    format!("voltab:medium = \"{other}\" is unknown; the prim is not a medium"),
                    "use voltab:medium = \"global\" for the global medium; media in meshes come from materials",
                );
                return Ok(());
            }
        }
        if let Some(first) = &self.global_medium {
            return Err(self.err(
                prim,
                format!("a second global medium (the first is {first})"),
                "keep one prim with voltab:medium = \"global\"; put local fog inside closed meshes",
            ));
        }
        let mpu = self.frame.mpu;
        let rgb = |imp: &mut Self, name: &str| -> Result<Rgb, SceneError> {
            let v = imp.typed(prim, name, |v| vec3(v).or_else(|| scalar(v).map(|s| [s; 3])), "a color3f")?;
            Ok(v.unwrap_or([0.0; 3]))
        };
        let sigma_s = rgb(self, "voltab:sigmaS")?.map(|v| v / mpu);
        let sigma_a = rgb(self, "voltab:sigmaA")?.map(|v| v / mpu);
        let g = rgb(self, "voltab:anisotropy")?;
        let frame = self.frame.matrix;
        let density = self.density(prim, &frame)?.unwrap_or(Density::Homogeneous);
        self.global_medium = Some(prim.as_str().to_owned());
        self.scene.media.push(Medium {
            name: prim.as_str().to_owned(),
            sigma_s,
            sigma_a,
            g,
            density,
            boundary: Boundary::Global,
        });
        Ok(())
    }
}
