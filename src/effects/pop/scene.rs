//! From an imported scene to POP inputs: the scene's global medium voxelised over the scene's
//! bounds, its directional lights, and its surfaces as an [`Occluder`].
//!
//! **Input → output.** [`Scene`] + BVH + a voxel resolution (+ an optional raw density volume that
//! multiplies the medium's density, the first heterogeneous input) → [`SceneMedia`]. Point, spot and
//! area lights need elek2014's radial grids (Sec. 6), which voltab does not have yet: they are listed
//! in [`SceneMedia::skipped`], never silently dropped.

use glam::DVec3;

use super::grid::Occluder;
use super::medium::{DirectionalLight, VoxelMedium};
use crate::scene::bvh::SceneBvh;
use crate::scene::{Boundary, LightKind, Scene};

/// A scene's surfaces blocking light and propagation.
pub struct BvhOccluder<'a>(pub &'a SceneBvh);

impl Occluder for BvhOccluder<'_> {
    fn segment_blocked(&self, a: DVec3, b: DVec3) -> bool {
        let d = b - a;
        let len = d.length();
        len > 0.0 && self.0.occluded(a.to_array(), (d / len).to_array(), len)
    }
    fn ray_blocked(&self, origin: DVec3, direction: DVec3) -> bool {
        self.0.occluded(origin.to_array(), direction.to_array(), f64::INFINITY)
    }
}

/// What POP takes from a scene.
#[derive(Debug, Clone)]
pub struct SceneMedia {
    /// The global medium over the scene's bounds.
    pub medium: VoxelMedium,
    /// Its name in the scene.
    pub medium_name: String,
    /// The directional lights.
    pub lights: Vec<DirectionalLight>,
    /// Names of the directional lights.
    pub light_names: Vec<String>,
    /// Lights and media left out, with the reason.
    pub skipped: Vec<String>,
}

/// A raw density volume spanning the scene's bounds (x fastest), multiplying the medium's density.
#[derive(Debug, Clone)]
pub struct RawDensity {
    /// Voxels per axis.
    pub dims: [usize; 3],
    /// Densities.
    pub values: Vec<f32>,
}

/// Voxelises the scene's global medium over the bounds of its meshes: `voxels` along the longest axis
/// (others in proportion), or the raw volume's grid when one is given.
///
/// # Errors
/// A message with the fix when the scene has no global medium, more than one, a back-scattering
/// medium (`g < 0`, which POP does not propagate), no geometry to bound the medium, or no
/// directional light.
pub fn scene_media(scene: &Scene, voxels: usize, raw: Option<&RawDensity>) -> Result<SceneMedia, String> {
    let file = scene.source.display();
    let globals: Vec<_> = scene.media.iter().filter(|m| m.boundary == Boundary::Global).collect();
    let mut skipped: Vec<String> = scene
        .media
        .iter()
        .filter(|m| m.boundary != Boundary::Global)
        .map(|m| format!("medium \"{}\": bounded by a mesh; POP here propagates the global medium", m.name))
        .collect();
    let m = match globals.as_slice() {
        [m] => *m,
        [] => return Err(format!("{file} has no global medium; add global fog (VOLTAB_participating_media.global)")),
        many => {
            return Err(format!(
                "{file} has {} global media ({}); POP propagates one, merge them into one medium",
                many.len(),
                many.iter().map(|m| m.name.as_str()).collect::<Vec<_>>().join(", ")
            ));
        }
    };
    if m.g.iter().any(|g| *g < 0.0) {
        return Err(format!(
            "{file}: medium \"{}\" has g = {:?}; POP propagates forward-scattering media only (g ≥ 0)",
            m.name, m.g
        ));
    }
    let mut lo = DVec3::splat(f64::INFINITY);
    let mut hi = DVec3::splat(f64::NEG_INFINITY);
    for p in scene.meshes.iter().flat_map(|mesh| mesh.positions.iter()) {
        let p = DVec3::new(f64::from(p[0]), f64::from(p[1]), f64::from(p[2]));
        lo = lo.min(p);
        hi = hi.max(p);
    }
    if !(lo.is_finite() && hi.is_finite()) || (hi - lo).min_element() <= 0.0 {
        return Err(format!("{file} has no geometry with volume to bound the medium; add the room or ground meshes"));
    }
    let mut lights = Vec::new();
    let mut light_names = Vec::new();
    for l in &scene.lights {
        match &l.kind {
            LightKind::Directional { direction, .. } => {
                lights.push(DirectionalLight { direction: DVec3::from_array(*direction), irradiance: l.radiance });
                light_names.push(l.name.clone());
            }
            _ => skipped.push(format!(
                "light \"{}\": local lights need radial propagation grids (elek2014 Sec. 6), not implemented yet",
                l.name
            )),
        }
    }
    if lights.is_empty() {
        return Err(format!("{file} has no directional light; POP propagates light from directional lights here"));
    }
    let coefficients = (m.sigma_s, m.sigma_a, m.g.map(|g| g.min(0.999_999)));
    let medium = match raw {
        Some(r) => {
            let size = (hi - lo) / DVec3::new(r.dims[0] as f64, r.dims[1] as f64, r.dims[2] as f64);
            let mut values = r.values.clone();
            for (n, v) in values.iter_mut().enumerate() {
                let c = [n % r.dims[0], (n / r.dims[0]) % r.dims[1], n / (r.dims[0] * r.dims[1])];
                let p = lo + size * DVec3::new(c[0] as f64 + 0.5, c[1] as f64 + 0.5, c[2] as f64 + 0.5);
                *v *= crate::reference::volpath::flight::density_at(&m.density, p) as f32;
            }
            VoxelMedium::new(lo, hi, r.dims, values, coefficients)?
        }
        None => {
            let ext = hi - lo;
            let cell = ext.max_element() / voxels.max(1) as f64;
            let dims = [0, 1, 2].map(|a| ((ext[a] / cell).round() as usize).max(1));
            VoxelMedium::from_fn(lo, hi, dims, coefficients, |p| {
                crate::reference::volpath::flight::density_at(&m.density, p)
            })?
        }
    };
    Ok(SceneMedia { medium, medium_name: m.name.clone(), lights, light_names, skipped })
}
