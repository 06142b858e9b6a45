//! UsdLux `DomeLight` and `DomeLight_1` → the scene's [`EnvironmentLight`] (`docs/design/scene.md`,
//! "Environment").
//!
//! **Orientation** (UsdLux, quoting OpenEXR's latitude–longitude convention): in the dome's own frame,
//! the image's top row is latitude +π/2 (the dome's +Y, its "top pole"), the left edge longitude +π, and
//! the direction of latitude φ and longitude λ is `(cos φ sin λ, sin φ, cos φ cos λ)`, so longitude 0 (the
//! centre column) looks toward +Z and longitude π/2 (a quarter across) toward +X. That is exactly
//! `render::environment`'s map convention, so the dome's frame needs no fixed re-mapping: the map's
//! world rotation is the prim's world transform (scale and translation removed: a dome is infinitely far
//! away), with USD's stage frame (metres, Z-up → Y-up) applied like everywhere else. `DomeLight` keeps
//! its pole on its own +Y whatever the stage's `upAxis`; `DomeLight_1`'s `poleAxis` first turns the dome
//! by +90° about X (its +Y onto +Z) when it is `"Z"`, or when it is `"scene"` (the fallback) on a Z-up
//! stage — as usdImaging's `domeOffset` does.
//!
//! **Radiance**: `intensity · 2^exposure · color / 683` per unit texel value, the conversion of every
//! UsdLux light ([`super::lights`]); `normalize` has no area to divide by and is ignored (with a warning).
//! `inputs:texture:format` `"latlong"` and `"automatic"` (read as latlong) are supported; other formats
//! drop the dome with a warning. Without a texture the dome is a uniform environment.
//!
//! **Texture path**: the asset path resolved by openusd against the layer that authors the strongest
//! opinion (an absolute path is stored); a texture that does not exist is kept (stages that light with
//! the dome fail naming it) and warned about. A second dome is skipped with a warning naming the first.

use std::path::{Path, PathBuf};

use glam::{DMat3, DMat4, DVec3};
use openusd::sdf::{self, Value};

use super::Importer;
use crate::scene::{EnvironmentLight, SceneError};

/// Formats read as latitude–longitude maps.
const LATLONG_FORMATS: [&str; 2] = ["latlong", "automatic"];

/// `+90°` about X: the dome's +Y (pole) onto +Z, its +Z onto −Y (usdImaging's Z-up `domeOffset`).
const POLE_TO_Z: DMat3 = DMat3::from_cols(DVec3::X, DVec3::Z, DVec3::NEG_Y);

/// Largest deviation of a unit-determinant linear part from a rotation that is not warned about.
const SHEAR_TOLERANCE: f64 = 1e-6;

/// How a dome's linear transform turns into a rotation.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) enum DomeRotation {
    /// A rotation (possibly mirroring) up to a uniform scale: `(rotation, mirrored)`.
    Exact(DMat3, bool),
    /// Non-uniform scale or shear: the nearest orthogonal matrix (polar factor), and whether it mirrors.
    Nearest(DMat3, bool),
    /// Singular or not finite: no direction mapping.
    Singular,
}

/// The orthogonal part of `l` (its polar decomposition `l = Q·S`, `S` symmetric positive definite).
/// Newton's iteration `Q ← (Q + Q⁻ᵀ)/2` from `l / |det l|^{1/3}` converges quadratically for any
/// non-singular matrix; a rotation up to uniform scale comes back to rounding.
pub(super) fn dome_rotation(l: DMat3) -> DomeRotation {
    let det = l.determinant();
    if !(det.is_finite() && det.abs() > 1e-300) || l.to_cols_array().iter().any(|v| !v.is_finite()) {
        return DomeRotation::Singular;
    }
    let mut q = l * (1.0 / det.abs().cbrt());
    let off =
        |m: DMat3| (m.transpose() * m - DMat3::IDENTITY).to_cols_array().iter().fold(0.0f64, |a, v| a.max(v.abs()));
    let exact = off(q) <= SHEAR_TOLERANCE;
    for _ in 0..100 {
        let next = (q + q.inverse().transpose()) * 0.5;
        let change = (next - q).to_cols_array().iter().fold(0.0f64, |a, v| a.max(v.abs()));
        q = next;
        if change <= 1e-15 {
            break;
        }
    }
    let mirrored = det < 0.0;
    if exact { DomeRotation::Exact(q, mirrored) } else { DomeRotation::Nearest(q, mirrored) }
}

/// An `asset` (or string) attribute's authored and resolved paths.
fn asset(v: &Value) -> Option<sdf::AssetPath> {
    match v {
        Value::AssetPath(a) => Some(a.clone()),
        Value::String(s) => Some(sdf::AssetPath::new(s.clone())),
        Value::Token(t) => Some(sdf::AssetPath::new(t.as_str())),
        _ => None,
    }
}

/// `p` made absolute against the working directory (openusd's identifiers already are).
fn absolute(p: PathBuf) -> PathBuf {
    if p.is_absolute() { p } else { std::env::current_dir().map_or(p.clone(), |d| d.join(&p)) }
}

impl Importer<'_> {
    /// Converts a `DomeLight` or `DomeLight_1` (`ty`) with voltab world matrix `m` (module doc).
    pub(super) fn read_dome(&mut self, prim: &sdf::Path, ty: &str, m: &DMat4) -> Result<(), SceneError> {
        let loc = prim.as_str();
        if let Some(first) = &self.scene.environment {
            let msg =
                format!("a second dome light; only the first ({}) lights the scene, this one is skipped", first.name);
            self.warn(loc, msg, "keep one DomeLight (combine their textures into one map)");
            return Ok(());
        }
        let em = self.emission(prim)?;
        self.light_extras(prim, true)?;
        if em.normalize {
            self.warn(
                loc,
                "normalize has no effect on a dome light (it has no area); it is ignored".into(),
                "remove inputs:normalize from the DomeLight",
            );
        }
        let rel = prim.append_property("portals").map_err(|e| self.usd_err(prim, "portals", e))?;
        let portals = self.stage.relationship(rel).targets().map_err(|e| self.usd_err(prim, "portals", e))?;
        if !portals.is_empty() {
            self.warn(
                loc,
                format!(
                    "portals are not supported; {} portal(s) ignored, the dome lights from every direction",
                    portals.len()
                ),
                "remove the portals relationship, or block the dome with geometry",
            );
        }
        let Some(rotation) = self.dome_orientation(prim, ty, m)? else { return Ok(()) };
        let texture = match self.dome_texture(prim)? {
            Texture::None => None,
            Texture::File(path) => Some(path),
            Texture::Unusable => return Ok(()),
        };
        self.scene.environment = Some(EnvironmentLight {
            name: loc.to_owned(),
            texture,
            scale: em.scale,
            color: em.color,
            rotation: [rotation.x_axis.to_array(), rotation.y_axis.to_array(), rotation.z_axis.to_array()],
        });
        Ok(())
    }

    /// The dome's world-from-map rotation: the pole offset of `DomeLight_1`, then the prim's world
    /// matrix `m` reduced to its orthogonal part. `None` (after a warning) for a singular transform.
    fn dome_orientation(&mut self, prim: &sdf::Path, ty: &str, m: &DMat4) -> Result<Option<DMat3>, SceneError> {
        let loc = prim.as_str();
        let pole = self.token_attr(prim, "poleAxis")?;
        let offset = if ty == "DomeLight" {
            if let Some(p) = &pole {
                self.warn(
                    loc,
                    format!("poleAxis = \"{p}\" is a DomeLight_1 attribute; a DomeLight keeps its pole on its +Y"),
                    "make the prim a DomeLight_1, or rotate the DomeLight with an xformOp",
                );
            }
            DMat3::IDENTITY
        } else {
            let z_up = self.frame.up == DVec3::Z;
            match pole.as_deref() {
                None | Some("scene") if z_up => POLE_TO_Z,
                None | Some("scene" | "Y") => DMat3::IDENTITY,
                Some("Z") => POLE_TO_Z,
                Some(other) => {
                    self.warn(
                        loc,
                        format!("poleAxis = \"{other}\" is not a UsdLux value; read as \"scene\""),
                        "use poleAxis \"scene\", \"Y\" or \"Z\"",
                    );
                    if z_up { POLE_TO_Z } else { DMat3::IDENTITY }
                }
            }
        };
        let linear = DMat3::from_mat4(*m) * offset;
        let (rotation, mirrored) = match dome_rotation(linear) {
            DomeRotation::Exact(r, mirrored) => (r, mirrored),
            DomeRotation::Nearest(r, mirrored) => {
                self.warn(
                    loc,
                    "non-uniform scale or shear on a dome light; only its rotation (the nearest one) orients the map"
                        .into(),
                    "transform dome lights by rotations only (uniform scale and translation do not matter)",
                );
                (r, mirrored)
            }
            DomeRotation::Singular => {
                self.warn(
                    loc,
                    "the dome light's transform is singular (a zero scale); the dome is skipped".into(),
                    "give the DomeLight a non-singular transform (rotations only matter)",
                );
                return Ok(None);
            }
        };
        if mirrored {
            self.warn(
                loc,
                "the dome light's transform mirrors (negative determinant); the map is seen mirrored".into(),
                "use a rotation without negative scale unless the mirror is intended",
            );
        }
        Ok(Some(rotation))
    }

    /// The dome's texture (module doc): none, an absolute file path, or unusable (warned; dome skipped).
    fn dome_texture(&mut self, prim: &sdf::Path) -> Result<Texture, SceneError> {
        let loc = prim.as_str();
        let names = ["inputs:texture:file", "texture:file"];
        let Some((name, a)) = self.first_asset(prim, &names)? else { return Ok(Texture::None) };
        if a.asset_path().is_empty() {
            return Ok(Texture::None);
        }
        let format =
            self.first_of(prim, &["inputs:texture:format", "texture:format"], super::values::token, "a token")?;
        if let Some(f) = format.as_deref().filter(|f| !LATLONG_FORMATS.contains(f)) {
            self.warn(
                loc,
                format!("texture format \"{f}\" is not supported (only latlong); the dome light is skipped"),
                "convert the texture to a latitude-longitude (equirectangular) map and set inputs:texture:format = \
                 \"latlong\"",
            );
            return Ok(Texture::Unusable);
        }
        let path = match a.resolved_path() {
            Some(r) => PathBuf::from(r),
            None => {
                // openusd resolves default values only; a time-sampled path is anchored here.
                let anchored = self.anchor(prim, name, a.asset_path())?;
                if anchored.is_file() {
                    return Ok(Texture::File(anchored));
                }
                self.warn(
                    loc,
                    format!(
                        "{name} = @{}@ does not resolve to a file (looked for {}); stages lit by the dome will fail",
                        a.as_str(),
                        anchored.display()
                    ),
                    "fix the asset path: a relative path is relative to the layer that authors it",
                );
                anchored
            }
        };
        let text = path.to_string_lossy();
        if text.ends_with(']') && text.to_ascii_lowercase().contains(".usdz[") {
            self.warn(
                loc,
                format!(
                    "the dome texture {} is packaged inside a .usdz; voltab reads textures from files only, the \
                         dome light is skipped",
                    path.display()
                ),
                "unpack the texture next to the layer and reference it with a relative asset path",
            );
            return Ok(Texture::Unusable);
        }
        Ok(Texture::File(absolute(path)))
    }

    /// The first authored of `names` as an asset path, with the name it came from.
    fn first_asset(
        &mut self,
        prim: &sdf::Path,
        names: &[&'static str],
    ) -> Result<Option<(&'static str, sdf::AssetPath)>, SceneError> {
        for &name in names {
            if let Some(a) = self.typed(prim, name, asset, "an asset path (asset, e.g. @sky.exr@)")? {
                return Ok(Some((name, a)));
            }
        }
        Ok(None)
    }

    /// Where a relative asset path `authored` of attribute `name` points: next to the layer holding the
    /// attribute's strongest opinion (the root layer when openusd cannot say).
    fn anchor(&mut self, prim: &sdf::Path, name: &str, authored: &str) -> Result<PathBuf, SceneError> {
        if Path::new(authored).is_absolute() {
            return Ok(PathBuf::from(authored));
        }
        let attr = prim.append_property(name).map_err(|e| self.usd_err(prim, name, e))?;
        let stack = self.stage.attribute(attr).property_stack().map_err(|e| self.usd_err(prim, name, e))?;
        let layer = stack.first().map_or_else(|| self.file.to_path_buf(), |(layer, _)| PathBuf::from(layer));
        let dir = layer.parent().map(Path::to_path_buf).unwrap_or_default();
        Ok(absolute(dir.join(authored)))
    }
}

/// A dome's texture.
enum Texture {
    /// No texture: a uniform dome.
    None,
    /// An absolute path (the file may be missing: warned).
    File(PathBuf),
    /// A texture voltab cannot read (warned): the dome is skipped.
    Unusable,
}
