//! A homogeneous medium inside a smooth dielectric boundary, lit by spherical emitters: the input
//! description the translucent renderer (`stages::translucent`, wang2018) and its brute-force
//! reference (`reference::translucent`) both read, so it lives on the render floor under both.
//!
//! **Input → output.** A scene and its BVH → the closed dielectric mesh bounding a medium and its index
//! of refraction ([`find_object`]), the scene's point and sphere lights as spherical [`Emitter`]s
//! ([`emitters`]), and the [`Setup`] bundling them with the medium's [`Material`].

use glam::DVec3;

use crate::scene::bvh::SceneBvh;
use crate::scene::{LightKind, Scene, Surface};

/// A homogeneous medium inside a smooth dielectric boundary, per RGB channel.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Material {
    /// Extinction coefficient `σ_t = 1/ℓ` \[1/m\], finite and > 0 per channel.
    pub sigma_t: [f64; 3],
    /// Single-scattering albedo `σ_s/σ_t` in \[0, 1\] per channel.
    pub albedo: [f64; 3],
    /// Henyey–Greenstein mean cosine shared by the channels, `|g| < 1`.
    pub g: f64,
    /// Index of refraction inside relative to outside (> 0; 1 is an index-matched boundary).
    pub ior: f64,
}

impl Material {
    /// A wang2018 Table 2 preset (`Oil`, `Wax`, `Milk`, `Skin`, `BumpySphere`) with its mean free paths
    /// multiplied by `mfp_scale` (scene metres per Table 2 length unit). `None` for an unknown name.
    pub fn preset(name: &str, mfp_scale: f64, ior: f64) -> Option<Material> {
        let m = crate::tables::ms_lobes::material(name)?;
        Some(Material { sigma_t: m.mfp.map(|l| 1.0 / (l * mfp_scale)), albedo: m.albedo, g: m.g, ior })
    }

    /// Scattering coefficient `σ_s` of channel `c`.
    pub fn sigma_s(&self, c: usize) -> f64 {
        self.albedo[c] * self.sigma_t[c]
    }

    /// Checks the ranges above; the message names the offending value.
    pub fn check(&self) -> Result<(), String> {
        for c in 0..3 {
            if !(self.sigma_t[c].is_finite() && self.sigma_t[c] > 0.0) {
                return Err(format!("sigma_t[{c}] = {} must be finite and > 0", self.sigma_t[c]));
            }
            if !(0.0..=1.0).contains(&self.albedo[c]) {
                return Err(format!("albedo[{c}] = {} must lie in [0, 1]", self.albedo[c]));
            }
        }
        if !(self.g.is_finite() && self.g.abs() < 1.0) {
            return Err(format!("g = {} must satisfy |g| < 1", self.g));
        }
        if !(self.ior.is_finite() && self.ior > 0.0) {
            return Err(format!("ior = {} must be finite and > 0", self.ior));
        }
        Ok(())
    }
}

/// A spherical emitter of uniform radiance (outward, all directions).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Emitter {
    /// Centre \[m\].
    pub center: DVec3,
    /// Radius \[m\], > 0.
    pub radius: f64,
    /// Radiance per channel \[W/(m²·sr)\].
    pub radiance: [f64; 3],
}

impl Emitter {
    /// Intensity `π r² L` \[W/sr\] the sphere radiates toward any far point (per channel).
    pub fn intensity(&self) -> [f64; 3] {
        let a = std::f64::consts::PI * self.radius * self.radius;
        self.radiance.map(|l| l * a)
    }

    /// Distance along the unit ray `o + t·d` to the sphere's front surface, if it is hit at `t > t_min`.
    pub fn intersect(&self, o: DVec3, d: DVec3, t_min: f64) -> Option<f64> {
        let oc = o - self.center;
        let b = oc.dot(d);
        let c = oc.length_squared() - self.radius * self.radius;
        let disc = b * b - c;
        if disc.is_nan() || disc < 0.0 {
            return None;
        }
        let s = disc.sqrt();
        // Stable roots: q = −b − sign(b)·s, t = q and c/q.
        let q = if b > 0.0 { -b - s } else { -b + s };
        let (t0, t1) = if q == 0.0 { (0.0, 0.0) } else { (q.min(c / q), q.max(c / q)) };
        [t0, t1].into_iter().find(|&t| t > t_min && t.is_finite())
    }
}

/// The scene's lights as emitters: point lights become spheres of radius `point_radius` with the same
/// intensity, sphere lights stay. Returns the emitters and, per light left out, a sentence saying why.
pub fn emitters(scene: &Scene, point_radius: f64) -> (Vec<Emitter>, Vec<String>) {
    let mut out = Vec::new();
    let mut skipped = Vec::new();
    for l in &scene.lights {
        match l.kind {
            LightKind::Point { position } => {
                let a = std::f64::consts::PI * point_radius * point_radius;
                out.push(Emitter {
                    center: DVec3::from_array(position),
                    radius: point_radius,
                    radiance: l.radiance.map(|i| i / a),
                });
            }
            LightKind::Sphere { center, radius } => out.push(Emitter {
                center: DVec3::from_array(center),
                radius,
                radiance: l.radiance,
            }),
            _ => skipped.push(format!(
                "light \"{}\" is left out: the translucent renderer and its reference take point and sphere lights only",
                l.name
            )),
        }
    }
    out.retain(|e| e.radius > 0.0 && e.radius.is_finite() && e.radiance.iter().any(|&v| v > 0.0));
    (out, skipped)
}

/// Everything the renderer and the reference read: the scene, its BVH, the translucent mesh, its
/// material (overriding the scene's medium) and the emitters.
#[derive(Debug, Clone, Copy)]
pub struct Setup<'a> {
    /// The imported scene.
    pub scene: &'a Scene,
    /// Its BVH (built over every mesh, the translucent one included).
    pub bvh: &'a SceneBvh,
    /// Index into `scene.meshes` of the closed dielectric mesh.
    pub object: usize,
    /// The medium inside it.
    pub material: Material,
    /// Lights.
    pub emitters: &'a [Emitter],
}

impl Setup<'_> {
    /// Diffuse reflectance (base colour) of the opaque mesh `mesh`, `[0; 3]` without a material.
    pub fn albedo_of(&self, mesh: usize) -> [f64; 3] {
        self.scene
            .meshes
            .get(mesh)
            .and_then(|m| m.material)
            .and_then(|i| self.scene.materials.get(i))
            .map(|m| m.base_color.map(|v| v.clamp(0.0, 1.0)))
            .unwrap_or([0.0; 3])
    }
}

/// The first closed dielectric mesh that bounds a medium, and its index of refraction.
pub fn find_object(scene: &Scene, bvh: &SceneBvh) -> Option<(usize, f64)> {
    (0..scene.meshes.len()).find_map(|i| {
        bvh.medium_bounded_by(i)?;
        let ior = match scene.materials.get(scene.meshes[i].material?)?.surface {
            Surface::Dielectric { ior } => ior,
            Surface::Opaque => return None,
        };
        Some((i, ior))
    })
}

#[cfg(test)]
mod tests;
