//! From an imported scene to POP inputs: the scene's global medium voxelised over the scene's
//! bounds, its directional lights, and its surfaces as an [`Occluder`].
//!
//! **Input → output.** [`Scene`] + BVH + a voxel resolution (+ an optional raw density volume that
//! multiplies the medium's density, the first heterogeneous input) → [`SceneMedia`]: directional lights
//! (rectilinear grids, Sec. 4) and point, spot and sphere lights (radial grids, Sec. 6; a sphere light
//! counts as a point of intensity `L π r²`, the scene convention for `treatAsPoint`). Rect, disk and
//! emissive-mesh lights would need elek2014's instant-radiosity VPLs, which voltab does not have: they
//! are listed in [`SceneMedia::skipped`], never silently dropped.

use glam::DVec3;

use super::grid::Occluder;
use super::medium::{DirectionalLight, VoxelMedium};
use super::radial_propagate::{PointLight, Spot};
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
    fn hit_distance(&self, origin: DVec3, direction: DVec3) -> f64 {
        let ray = crate::scene::bvh::Ray::new(origin.to_array(), direction.to_array());
        self.0.closest_hit(&ray).map_or(f64::INFINITY, |h| h.t * direction.length())
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
    /// The point, spot and sphere lights.
    pub points: Vec<PointLight>,
    /// Their names.
    pub point_names: Vec<String>,
    /// Lights and media left out, with the reason.
    pub skipped: Vec<String>,
    /// Environment lighting (elek2014 Sec. 5), when the stage gives a map.
    pub environment: Option<Environment>,
}

/// An environment map and how to split it into principal ordinates.
#[derive(Debug, Clone)]
pub struct Environment {
    /// The map (radiance, intensity applied).
    pub map: super::environment::EnvMap,
    /// Name for summaries (the file).
    pub name: String,
    /// Ordinates at most.
    pub ordinates: usize,
    /// How their directions are chosen.
    pub set: super::environment::OrdinateSet,
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
/// medium (`g < 0`, which POP does not propagate), no geometry to bound the medium, or no directional,
/// point, spot or sphere light and no `environment`.
pub fn scene_media(
    scene: &Scene,
    voxels: usize,
    raw: Option<&RawDensity>,
    environment: Option<Environment>,
) -> Result<SceneMedia, String> {
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
    let mut points = Vec::new();
    let mut point_names = Vec::new();
    let mut point = |p: PointLight, name: &str| {
        if p.position.is_finite() && p.intensity.iter().all(|v| v.is_finite() && *v >= 0.0) {
            points.push(p);
            point_names.push(name.to_string());
            None
        } else {
            Some(format!("light \"{name}\": position or intensity is not finite and ≥ 0"))
        }
    };
    for l in &scene.lights {
        let skip = match &l.kind {
            LightKind::Directional { direction, .. } => {
                lights.push(DirectionalLight { direction: DVec3::from_array(*direction), irradiance: l.radiance });
                light_names.push(l.name.clone());
                None
            }
            LightKind::Point { position } => {
                point(PointLight { position: DVec3::from_array(*position), intensity: l.radiance, spot: None }, &l.name)
            }
            LightKind::Spot { position, direction, inner_cone, outer_cone } => {
                match DVec3::from_array(*direction).try_normalize() {
                    Some(axis) => {
                        let (ci, co) = (inner_cone.cos(), outer_cone.cos());
                        let spot = Spot { axis, cos_outer: co, inv_range: 1.0 / (ci - co).max(1e-3) };
                        let p = PointLight {
                            position: DVec3::from_array(*position),
                            intensity: l.radiance,
                            spot: Some(spot),
                        };
                        point(p, &l.name)
                    }
                    None => Some(format!("light \"{}\": spot direction is zero or not finite", l.name)),
                }
            }
            LightKind::Sphere { center, radius } => {
                let area = std::f64::consts::PI * radius * radius;
                let p = PointLight {
                    position: DVec3::from_array(*center),
                    intensity: l.radiance.map(|v| v * area),
                    spot: None,
                };
                point(p, &l.name)
            }
            _ => Some(format!(
                "light \"{}\": area lights and emissive surfaces need instant-radiosity VPLs (elek2014 Sec. 6), not implemented",
                l.name
            )),
        };
        skipped.extend(skip);
    }
    if lights.is_empty() && points.is_empty() && environment.is_none() {
        return Err(format!(
            "{file} has no directional, point, spot or sphere light and the stage no environment map; POP \
             propagates light from those (add one)"
        ));
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
    Ok(SceneMedia {
        medium,
        medium_name: m.name.clone(),
        lights,
        light_names,
        points,
        point_names,
        skipped,
        environment,
    })
}

/// The scene an independent path tracer must render to give exactly what POP's `scattered` layer
/// holds: the light the medium scatters toward the eye from the lights POP propagates, attenuated on the
/// way. Surfaces become black absorbers (POP's surfaces only occlude) with no emission, lights POP skips
/// are removed, and the global medium is confined to POP's medium box: it becomes the medium of a closed,
/// index-matched box mesh (no material, so rays pass its faces unbent) `1e-6` of the box diagonal larger
/// than the box, so its faces never coincide with the walls they enclose. voltab's path tracer fills all
/// space with a global medium; the box keeps fog outside the scene's bounds (e.g. in front of an open
/// wall, between the camera and the room) out of the reference, as POP keeps it out.
pub fn scattering_reference_scene(scene: &Scene, media: &SceneMedia) -> Scene {
    let mut s = scene.clone();
    for m in &mut s.materials {
        m.base_color = [0.0; 3];
        m.emission = [0.0; 3];
    }
    let names: Vec<&String> = media.light_names.iter().chain(&media.point_names).collect();
    s.lights.retain(|l| names.contains(&&l.name) && !matches!(l.kind, LightKind::EmissiveMesh { .. }));
    let margin = 1e-6 * (media.medium.max - media.medium.min).length();
    let (lo, hi) = (media.medium.min - DVec3::splat(margin), media.medium.max + DVec3::splat(margin));
    let corner = |c: usize| {
        [
            if c & 1 == 0 { lo.x } else { hi.x } as f32,
            if c & 2 == 0 { lo.y } else { hi.y } as f32,
            if c & 4 == 0 { lo.z } else { hi.z } as f32,
        ]
    };
    let positions: Vec<[f32; 3]> = (0..8).map(corner).collect();
    // Counter-clockwise seen from outside (outward normals).
    let triangles: Vec<[u32; 3]> = vec![
        [0, 2, 3],
        [0, 3, 1], // −z
        [4, 5, 7],
        [4, 7, 6], // +z
        [0, 1, 5],
        [0, 5, 4], // −y
        [2, 6, 7],
        [2, 7, 3], // +y
        [0, 4, 6],
        [0, 6, 2], // −x
        [1, 3, 7],
        [1, 7, 5], // +x
    ];
    let medium_index = s.media.iter().position(|m| m.name == media.medium_name && m.boundary == Boundary::Global);
    if let Some(i) = medium_index {
        let mesh_index = s.meshes.len();
        s.meshes.push(crate::scene::Mesh {
            name: "pop_medium_box".into(),
            normals: Vec::new(),
            positions,
            uv: None,
            lightmap_uv: None,
            triangles,
            material: None,
            medium: Some(i),
            to_world: [[1.0, 0.0, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0], [0.0, 0.0, 0.0, 1.0]],
        });
        s.media[i].boundary = Boundary::Mesh(mesh_index);
    }
    s
}
