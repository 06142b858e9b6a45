//! UsdLux lights and `UsdGeomCamera` → [`Light`] and [`Camera`] (`docs/design/scene.md`, "Lights"
//! and "Cameras"). openusd has no schema fallbacks, so USD's documented defaults are spelled out here.

use std::f64::consts::PI;

use glam::{DMat4, DVec3};
use openusd::sdf;

use super::Importer;
use super::values::{boolean, scalar, vec3};
use super::xform::normal_matrix;
use crate::scene::{Camera, LUMENS_PER_WATT, Light, LightKind, Projection, SceneError};

/// UsdLux fallbacks.
const INTENSITY: f64 = 1.0;
const EXPOSURE: f64 = 0.0;
const COLOR: [f64; 3] = [1.0; 3];
const SPHERE_RADIUS: f64 = 0.5;
const DISK_RADIUS: f64 = 0.5;
const RECT_SIZE: f64 = 1.0;
/// DistantLight `angle` fallback, in degrees.
const DISTANT_ANGLE_DEG: f64 = 0.53;

/// UsdGeomCamera fallbacks (apertures and focal length in tenths of a stage unit, i.e. mm for cm).
const FOCAL_LENGTH: f64 = 50.0;
const VERTICAL_APERTURE: f64 = 15.2908;
const HORIZONTAL_APERTURE: f64 = 20.955;
const CLIPPING_RANGE: [f64; 2] = [1.0, 1e6];

/// The radiance-like value of a UsdLux light: `intensity × 2^exposure × color / K`, with `normalize`.
pub(super) struct Emission {
    /// `L` per channel, in W/(m² sr).
    pub value: [f64; 3],
    /// `intensity × 2^exposure / K` (W/(m² sr) per unit colour), finite and >= 0.
    pub scale: f64,
    /// `inputs:color`.
    pub color: [f64; 3],
    /// `inputs:normalize`.
    pub normalize: bool,
}

/// `x > 0` (false for NaN): a light with `normalize` needs a positive area.
fn is_positive(x: f64) -> bool {
    x > 0.0
}

/// `v / |v|`, or `fallback` for a zero or non-finite vector.
fn unit(v: DVec3, fallback: DVec3) -> [f64; 3] {
    v.try_normalize().unwrap_or(fallback).to_array()
}

impl Importer<'_> {
    /// A UsdLux input, read as `inputs:<name>` or (pre-2021 UsdLux) `<name>`.
    fn lux_f64(&mut self, prim: &sdf::Path, name: &str, fallback: f64) -> Result<f64, SceneError> {
        let prefixed = format!("inputs:{name}");
        Ok(self.first_of(prim, &[&prefixed, name], scalar, "a number")?.unwrap_or(fallback))
    }

    /// A UsdLux size input that must be finite and >= 0.
    fn lux_size(&mut self, prim: &sdf::Path, name: &str, fallback: f64) -> Result<f64, SceneError> {
        let v = self.lux_f64(prim, name, fallback)?;
        if !(v.is_finite() && v >= 0.0) {
            return Err(self.err(
                prim,
                format!("inputs:{name} = {v}"),
                format!("inputs:{name} must be finite and >= 0"),
            ));
        }
        Ok(v)
    }

    /// The LightAPI inputs common to every light.
    pub(super) fn emission(&mut self, prim: &sdf::Path) -> Result<Emission, SceneError> {
        let intensity = self.lux_f64(prim, "intensity", INTENSITY)?;
        let exposure = self.lux_f64(prim, "exposure", EXPOSURE)?;
        let color = self.first_of(prim, &["inputs:color", "color"], vec3, "a color3f")?.unwrap_or(COLOR);
        let normalize = self.first_of(prim, &["inputs:normalize", "normalize"], boolean, "a bool")?.unwrap_or(false);
        if self.first_of(prim, &["inputs:enableColorTemperature", "enableColorTemperature"], boolean, "a bool")?
            == Some(true)
        {
            self.warn(
                prim.as_str(),
                "enableColorTemperature is not supported; the light's colour ignores its temperature".into(),
                "bake the blackbody colour into inputs:color and disable enableColorTemperature",
            );
        }
        // nits → W/(m² sr): L = intensity · 2^exposure · color / K.
        let value = color.map(|c| intensity * exposure.exp2() * c / LUMENS_PER_WATT);
        let scale = intensity * exposure.exp2() / LUMENS_PER_WATT;
        let bad = |v: f64| !v.is_finite() || v < 0.0;
        if value.iter().any(|&v| bad(v)) || bad(scale) || color.iter().any(|&c| bad(c)) {
            return Err(self.err(
                prim,
                format!(
                    "light value intensity {intensity} × 2^{exposure} × color {color:?} = {value:?} is negative or \
                     not finite"
                ),
                "light intensity, exposure-scaled, and colour must be finite and >= 0",
            ));
        }
        Ok(Emission { value, scale, color, normalize })
    }

    /// Warns about light features voltab does not read (ShapingAPI, light filters, and textures unless
    /// `reads_texture`: a DomeLight's texture is read).
    pub(super) fn light_extras(&mut self, prim: &sdf::Path, reads_texture: bool) -> Result<(), SceneError> {
        let p = self.stage.prim(prim.clone());
        let apis = p.api_schemas().map_err(|e| self.usd_err(prim, "apiSchemas", e))?;
        if apis.iter().any(|a| a.as_str() == "ShapingAPI") {
            self.warn(
                prim.as_str(),
                "ShapingAPI (spot cone, focus, IES profile) is not read; the light emits unshaped".into(),
                "voltab reads UsdLux spot cones only through glTF spot lights for now",
            );
        }
        let rel = prim.append_property("light:filters").map_err(|e| self.usd_err(prim, "light:filters", e))?;
        let filters = self.stage.relationship(rel).targets().map_err(|e| self.usd_err(prim, "light:filters", e))?;
        if !filters.is_empty() {
            self.warn(
                prim.as_str(),
                format!("light filters are not supported; {} filter(s) ignored", filters.len()),
                "remove light:filters or bake their effect into the light",
            );
        }
        if !reads_texture && self.value(prim, "inputs:texture:file")?.is_some() {
            self.warn(
                prim.as_str(),
                "light textures (inputs:texture:file) are not read; the light emits its uniform colour".into(),
                "remove the texture or bake its average into inputs:color",
            );
        }
        Ok(())
    }

    /// World-space radius of a sphere of local radius `r` under `m`, warning on non-uniform scale.
    fn sphere_radius(&mut self, prim: &sdf::Path, m: &DMat4, r: f64) -> f64 {
        let cols = [m.x_axis, m.y_axis, m.z_axis].map(|c| c.truncate().length());
        let (lo, hi) = (cols.iter().copied().fold(f64::INFINITY, f64::min), cols.iter().copied().fold(0.0, f64::max));
        if hi > lo * (1.0 + 1e-6) {
            self.warn(
                prim.as_str(),
                format!("non-uniform scale {cols:?} on a sphere light; its radius uses the geometric mean scale"),
                "scale sphere lights uniformly",
            );
        }
        r * (cols[0] * cols[1] * cols[2]).cbrt()
    }

    /// Converts a SphereLight, RectLight, DiskLight or DistantLight (`ty`) with world matrix `m`.
    pub(super) fn read_light(&mut self, prim: &sdf::Path, ty: &str, m: &DMat4) -> Result<(), SceneError> {
        let em = self.emission(prim)?;
        self.light_extras(prim, false)?;
        let center = m.transform_point3(DVec3::ZERO).to_array();
        // Emitting side: local −Z; plane normals go through the inverse transpose.
        let local_n = DVec3::NEG_Z;
        let plane_normal = |fallback| unit(normal_matrix(m).map_or(fallback, |nm| nm * local_n), fallback);
        let area_err = |imp: &Self, what: &str| {
            imp.err(prim, format!("normalize is on but the light's {what} is zero"), "give the light a non-zero size")
        };
        let (kind, radiance) = match ty {
            "SphereLight" => {
                let r_local = self.lux_size(prim, "radius", SPHERE_RADIUS)?;
                let r = self.sphere_radius(prim, m, r_local);
                let treat_as_point = self.bool_attr(prim, "treatAsPoint")?.unwrap_or(false);
                let area = 4.0 * PI * r * r;
                if em.normalize && !is_positive(area) {
                    return Err(area_err(self, "radius"));
                }
                let l = em.value.map(|v| if em.normalize { v / area } else { v });
                if treat_as_point {
                    // A sphere of radiance L seen from afar has intensity L·πr² (scene.md, Lights).
                    (LightKind::Point { position: center }, l.map(|v| v * PI * r * r))
                } else {
                    (LightKind::Sphere { center, radius: r }, l)
                }
            }
            "RectLight" => {
                let w = self.lux_size(prim, "width", RECT_SIZE)?;
                let h = self.lux_size(prim, "height", RECT_SIZE)?;
                let half_u = m.transform_vector3(DVec3::X * (w / 2.0));
                let half_v = m.transform_vector3(DVec3::Y * (h / 2.0));
                let area = 4.0 * half_u.cross(half_v).length();
                if em.normalize && !is_positive(area) {
                    return Err(area_err(self, "width × height"));
                }
                let normal = plane_normal(DVec3::NEG_Z);
                let l = em.value.map(|v| if em.normalize { v / area } else { v });
                (LightKind::Rect { center, half_u: half_u.to_array(), half_v: half_v.to_array(), normal }, l)
            }
            "DiskLight" => {
                let r_local = self.lux_size(prim, "radius", DISK_RADIUS)?;
                let (ax, ay) = (m.transform_vector3(DVec3::X), m.transform_vector3(DVec3::Y));
                let (lx, ly) = (ax.length(), ay.length());
                if (lx - ly).abs() > 1e-6 * lx.max(ly) || ax.dot(ay).abs() > 1e-6 * lx * ly {
                    self.warn(
                        prim.as_str(),
                        "non-uniform or sheared scale in the disk's plane; its radius keeps the disk's area".into(),
                        "scale disk lights uniformly",
                    );
                }
                let r = r_local * ax.cross(ay).length().sqrt();
                let area = PI * r * r;
                if em.normalize && !is_positive(area) {
                    return Err(area_err(self, "radius"));
                }
                let normal = plane_normal(DVec3::NEG_Z);
                (
                    LightKind::Disk { center, normal, radius: r },
                    em.value.map(|v| if em.normalize { v / area } else { v }),
                )
            }
            _ => {
                // DistantLight: E = L × solid angle of a cone of half-angle angle/2, or L with normalize.
                let angle_deg = self.lux_size(prim, "angle", DISTANT_ANGLE_DEG)?;
                let angle = angle_deg.to_radians();
                let solid = 2.0 * PI * (1.0 - (angle / 2.0).cos());
                let direction = unit(m.transform_vector3(local_n), DVec3::NEG_Y);
                let e = em.value.map(|v| if em.normalize { v } else { v * solid });
                (LightKind::Directional { direction, angle }, e)
            }
        };
        self.scene.lights.push(Light { name: prim.as_str().to_owned(), kind, radiance });
        Ok(())
    }

    /// Converts a `UsdGeomCamera` with world matrix `m`.
    pub(super) fn read_camera(&mut self, prim: &sdf::Path, m: &DMat4) -> Result<(), SceneError> {
        let positive = |imp: &mut Self, name: &str, fallback: f64| -> Result<f64, SceneError> {
            let v = imp.f64_attr(prim, name)?.unwrap_or(fallback);
            if !(v.is_finite() && v > 0.0) {
                return Err(imp.err(prim, format!("{name} = {v}"), format!("{name} must be a positive number")));
            }
            Ok(v)
        };
        let focal = positive(self, "focalLength", FOCAL_LENGTH)?;
        let vert = positive(self, "verticalAperture", VERTICAL_APERTURE)?;
        let horiz = positive(self, "horizontalAperture", HORIZONTAL_APERTURE)?;
        let clip = self.vec2_attr(prim, "clippingRange")?.unwrap_or(CLIPPING_RANGE);
        if !(clip[0] >= 0.0 && clip[1] > clip[0]) {
            return Err(self.err(
                prim,
                format!("clippingRange = {clip:?}"),
                "clippingRange is (near, far) with 0 <= near < far",
            ));
        }
        for name in ["horizontalApertureOffset", "verticalApertureOffset"] {
            if self.f64_attr(prim, name)?.is_some_and(|v| v != 0.0) {
                self.warn(
                    prim.as_str(),
                    format!("{name} (off-axis projection) is not supported; the camera is read as centred"),
                    "bake the lens shift into the camera transform",
                );
            }
        }
        let mpu = self.frame.mpu;
        let projection = match self.token_attr(prim, "projection")?.as_deref() {
            None | Some("perspective") => {
                Projection::Perspective { yfov: 2.0 * (vert / (2.0 * focal)).atan(), aspect: Some(horiz / vert) }
            }
            // Apertures are in tenths of a stage unit (USD's convention).
            Some("orthographic") => {
                Projection::Orthographic { xmag: horiz / 2.0 * 0.1 * mpu, ymag: vert / 2.0 * 0.1 * mpu }
            }
            Some(other) => {
                return Err(self.err(
                    prim,
                    format!("projection = \"{other}\""),
                    "projection is \"perspective\" (the fallback) or \"orthographic\"",
                ));
            }
        };
        let forward = DVec3::from(unit(m.transform_vector3(DVec3::NEG_Z), DVec3::NEG_Z));
        let up_raw = m.transform_vector3(DVec3::Y);
        let up = unit(up_raw - forward * up_raw.dot(forward), forward.any_orthonormal_vector());
        self.scene.cameras.push(Camera {
            name: prim.as_str().to_owned(),
            position: m.transform_point3(DVec3::ZERO).to_array(),
            forward: forward.to_array(),
            up,
            projection,
            znear: clip[0] * mpu,
            zfar: clip[1].is_finite().then_some(clip[1] * mpu),
        });
        Ok(())
    }
}
