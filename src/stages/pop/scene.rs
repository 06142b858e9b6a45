//! From an imported scene to POP inputs: the scene's global medium voxelised over the scene's
//! bounds, its directional lights, and its surfaces as an [`Occluder`].
//!
//! **Input → output.** [`Scene`] + BVH + a voxel resolution (+ an optional raw density volume that
//! multiplies the medium's density, the first heterogeneous input) → [`SceneMedia`]: directional lights
//! (rectilinear grids, Sec. 4) and point, spot and sphere lights (radial grids, Sec. 6; a sphere light
//! counts as a point of intensity `L π r²`, the scene convention for `treatAsPoint`); rect, disk and
//! emissive-mesh lights as instant-radiosity VPLs ([`area_vpls`]; with `vpls = 0` they are listed in
//! [`SceneMedia::skipped`], never silently dropped); and, with the BVH, VPLs for the light the surfaces
//! reflect ([`add_reflection_vpls`], from reflective shadow maps, [`super::rsm`]).

use glam::DVec3;

use super::radial_propagate::PointLight;
use crate::physics::medium::RgbMedium;
use crate::render::occluder::Occluder;
use crate::render::spot::SpotCone;
use crate::render::voxel::{DirectionalLight, VoxelMedium};
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
    /// The area lights and emissive meshes propagated as VPLs (their names in the scene).
    pub vpl_sources: Vec<String>,
    /// The VPLs standing for light reflected by the scene's surfaces, when added
    /// ([`add_reflection_vpls`]; they are among [`SceneMedia::points`]).
    pub reflection: Option<Reflection>,
}

impl SceneMedia {
    /// Index in [`SceneMedia::points`] of the first VPL of reflected light ([`add_reflection_vpls`]
    /// appends them last); `points.len()` when there are none.
    pub fn first_reflection_vpl(&self) -> usize {
        self.points.len() - self.reflection.as_ref().map_or(0, |r| r.vpls)
    }
}

/// What [`add_reflection_vpls`] added.
#[derive(Debug, Clone, serde::Serialize)]
pub struct Reflection {
    /// Reflective shadow maps rendered (one per primary light).
    pub maps: usize,
    /// Texels per side of each map.
    pub side: usize,
    /// VPLs added.
    pub vpls: usize,
    /// Flux the surfaces reflect per channel \[W\], the VPLs' total.
    pub flux: [f64; 3],
    /// Time to render the maps and place the VPLs \[ms\].
    pub ms: f64,
}

/// Adds `k` VPLs for the direct light the scene's surfaces reflect into the medium (elek2014 Sec. 6:
/// reflective shadow maps of every primary light — directional lights and point lights, area lights'
/// VPLs included — importance-sampled by reflected flux; [`super::rsm`]) to `media.points`, named
/// `surfaces vpl j`, each lifted off its surface like the area lights' VPLs. `k = 0` adds nothing and
/// leaves [`SceneMedia::reflection`] `None`.
pub fn add_reflection_vpls(media: &mut SceneMedia, scene: &Scene, bvh: &SceneBvh, k: usize, side: usize) {
    if k == 0 {
        return;
    }
    let t0 = std::time::Instant::now();
    let albedo = super::rsm::albedos(scene, bvh);
    let m = &media.medium;
    let mut maps: Vec<_> = media.lights.iter().map(|l| super::rsm::directional_rsm(&albedo, bvh, m, l, side)).collect();
    maps.extend(media.points.iter().map(|l| super::rsm::point_rsm(&albedo, bvh, m, l, side)));
    let lift = 1e-4 * (m.max - m.min).length();
    let vpls = super::rsm::sample_vpls(&maps, k, lift);
    media.reflection = Some(Reflection {
        maps: maps.len(),
        side,
        vpls: vpls.len(),
        flux: super::rsm::total_flux(&maps),
        ms: t0.elapsed().as_secs_f64() * 1e3,
    });
    for (j, p) in vpls.into_iter().enumerate() {
        media.points.push(p);
        media.point_names.push(format!("surfaces vpl {j}"));
    }
}

/// An environment map and how to split it into principal ordinates.
#[derive(Debug, Clone)]
pub struct Environment {
    /// The map (radiance, intensity applied).
    pub map: crate::render::environment::EnvMap,
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

/// `1/Φ` (Φ the golden ratio): the second coordinate of the Fibonacci lattice placing VPLs.
const INV_PHI: f64 = 0.618_033_988_749_894_8;

/// Instant-radiosity VPLs for an area light (elek2014 Sec. 6): `k` Lambertian point lights spread over a
/// rect, disk or emissive mesh, each standing for an equal share `A/k` of its area, so its intensity
/// along the normal is `L·A/k` and falls off as `max(0, n·w)`; each lifted `lift` off the surface along
/// its normal (so the emitter's own triangles do not shadow it). Placement is stratified: a rect or disk
/// takes the centres of an `m × m` grid (`m = ⌈√k⌉`, so `m²` VPLs; a disk through the concentric map), a
/// mesh the points `((i + ½)/k, frac(i/Φ))` of a Fibonacci lattice through its triangles' area
/// distribution. `None` for lights that are not area lights; an empty list for a degenerate emitter.
pub fn area_vpls(scene: &Scene, light: &crate::scene::Light, k: usize, lift: f64) -> Option<Vec<PointLight>> {
    let k = k.max(1);
    let vpl = |p: DVec3, n: DVec3, area_share: f64| PointLight {
        position: p + n * lift,
        intensity: light.radiance.map(|v| v * area_share),
        spot: None,
        normal: Some(n),
    };
    let m = (k as f64).sqrt().ceil() as usize;
    let cells = || (0..m * m).map(move |i| (((i % m) as f64 + 0.5) / m as f64, ((i / m) as f64 + 0.5) / m as f64));
    match &light.kind {
        LightKind::Rect { center, half_u, half_v, normal } => {
            let (c, u, v) = (DVec3::from_array(*center), DVec3::from_array(*half_u), DVec3::from_array(*half_v));
            let n = DVec3::from_array(*normal).try_normalize()?;
            let area = 4.0 * u.cross(v).length();
            Some(
                cells()
                    .map(|(a, b)| vpl(c + u * (2.0 * a - 1.0) + v * (2.0 * b - 1.0), n, area / (m * m) as f64))
                    .collect(),
            )
        }
        LightKind::Disk { center, normal, radius } => {
            let n = DVec3::from_array(*normal).try_normalize()?;
            let (t1, t2) = n.any_orthonormal_pair();
            let c = DVec3::from_array(*center);
            let area = std::f64::consts::PI * radius * radius;
            let concentric = |a: f64, b: f64| {
                let (x, y) = (2.0 * a - 1.0, 2.0 * b - 1.0);
                let (r, phi) = if x.abs() > y.abs() {
                    (x, std::f64::consts::FRAC_PI_4 * (y / x))
                } else {
                    (y, std::f64::consts::FRAC_PI_2 - std::f64::consts::FRAC_PI_4 * (x / y))
                };
                (t1 * phi.cos() + t2 * phi.sin()) * (r * radius)
            };
            Some(cells().map(|(a, b)| vpl(c + concentric(a, b), n, area / (m * m) as f64)).collect())
        }
        LightKind::EmissiveMesh { mesh } => {
            let mesh = scene.meshes.get(*mesh)?;
            let p = |i: u32| {
                let v = mesh.positions.get(i as usize).copied().unwrap_or([f32::NAN; 3]);
                DVec3::new(f64::from(v[0]), f64::from(v[1]), f64::from(v[2]))
            };
            let tris: Vec<(DVec3, DVec3, DVec3, f64)> = mesh
                .triangles
                .iter()
                .map(|t| (p(t[0]), p(t[1]), p(t[2])))
                .map(|(a, b, c)| (a, b, c, 0.5 * (b - a).cross(c - a).length()))
                .filter(|t| t.3.is_finite() && t.3 > 0.0)
                .collect();
            let total: f64 = tris.iter().map(|t| t.3).sum();
            if tris.is_empty() {
                return Some(Vec::new());
            }
            let mut out = Vec::with_capacity(k);
            let (mut t, mut below) = (0, 0.0);
            for i in 0..k {
                let u = (i as f64 + 0.5) / k as f64 * total;
                while t + 1 < tris.len() && below + tris[t].3 < u {
                    below += tris[t].3;
                    t += 1;
                }
                let (a, b, c, area) = tris[t];
                let su = ((u - below) / area).clamp(0.0, 1.0).sqrt();
                let v = (i as f64 * INV_PHI).fract();
                let point = a * (1.0 - su) + b * (su * (1.0 - v)) + c * (su * v);
                let n = (b - a).cross(c - a).normalize();
                out.push(vpl(point, n, total / k as f64));
            }
            Some(out)
        }
        _ => None,
    }
}

/// Voxelises the scene's global medium over the bounds of its meshes: `voxels` along the longest axis
/// (others in proportion), or the raw volume's grid when one is given. Area lights and emissive meshes
/// become `vpls` VPLs each ([`area_vpls`]; 0: they are skipped).
///
/// # Errors
/// A message with the fix when the scene has no global medium, more than one, a back-scattering
/// medium (`g < 0`, which POP does not propagate), no geometry to bound the medium, or no light POP
/// propagates and no `environment`.
pub fn scene_media(
    scene: &Scene,
    voxels: usize,
    raw: Option<&RawDensity>,
    environment: Option<Environment>,
    vpls: usize,
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
    let mut vpl_sources = Vec::new();
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
            LightKind::Point { position } => point(
                PointLight { position: DVec3::from_array(*position), intensity: l.radiance, spot: None, normal: None },
                &l.name,
            ),
            LightKind::Spot { position, direction, inner_cone, outer_cone } => {
                match SpotCone::khr(DVec3::from_array(*direction), *inner_cone, *outer_cone) {
                    Some(spot) => {
                        let p = PointLight {
                            position: DVec3::from_array(*position),
                            intensity: l.radiance,
                            spot: Some(spot),
                            normal: None,
                        };
                        point(p, &l.name)
                    }
                    None => Some(format!(
                        "light \"{}\": spot direction is zero or not finite, or a cone angle is not finite",
                        l.name
                    )),
                }
            }
            LightKind::Sphere { center, radius } => {
                let area = std::f64::consts::PI * radius * radius;
                let p = PointLight {
                    position: DVec3::from_array(*center),
                    intensity: l.radiance.map(|v| v * area),
                    spot: None,
                    normal: None,
                };
                point(p, &l.name)
            }
            _ if vpls == 0 => Some(format!(
                "light \"{}\": area lights and emissive surfaces become VPLs, and the stage's vpls is 0",
                l.name
            )),
            _ => match area_vpls(scene, l, vpls, 1e-4 * (hi - lo).length()) {
                Some(list) if !list.is_empty() => {
                    let mut skipped = None;
                    for (k, p) in list.into_iter().enumerate() {
                        skipped = skipped.or(point(p, &format!("{} vpl {k}", l.name)));
                    }
                    if skipped.is_none() {
                        vpl_sources.push(l.name.clone());
                    }
                    skipped
                }
                _ => Some(format!("light \"{}\": a degenerate area light (no area or no normal)", l.name)),
            },
        };
        skipped.extend(skip);
    }
    if lights.is_empty() && points.is_empty() && environment.is_none() {
        return Err(format!(
            "{file} has no directional, point, spot, sphere or area light (or vpls is 0) and the stage no \
             environment map; POP propagates light from those (add one)"
        ));
    }
    let coefficients = RgbMedium { g: m.g.map(|g| g.min(0.999_999)), ..m.coefficients() };
    let medium = match raw {
        Some(r) => {
            let size = (hi - lo) / DVec3::new(r.dims[0] as f64, r.dims[1] as f64, r.dims[2] as f64);
            let mut values = r.values.clone();
            for (n, v) in values.iter_mut().enumerate() {
                let c = [n % r.dims[0], (n / r.dims[0]) % r.dims[1], n / (r.dims[0] * r.dims[1])];
                let p = lo + size * DVec3::new(c[0] as f64 + 0.5, c[1] as f64 + 0.5, c[2] as f64 + 0.5);
                *v *= crate::reference::volpath::flight::density_at(&m.density, p) as f32;
            }
            VoxelMedium::new(lo, hi, r.dims, values, coefficients).map_err(|e| e.to_string())?
        }
        None => {
            let ext = hi - lo;
            let cell = ext.max_element() / voxels.max(1) as f64;
            let dims = [0, 1, 2].map(|a| ((ext[a] / cell).round() as usize).max(1));
            VoxelMedium::from_fn(lo, hi, dims, coefficients, |p| {
                crate::reference::volpath::flight::density_at(&m.density, p)
            })
            .map_err(|e| e.to_string())?
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
        vpl_sources,
        reflection: None,
    })
}

/// Per pixel of `cam`: whether its centre ray sees the emitting side of an area light POP propagates as
/// VPLs before any other surface. The path tracer shows such an emitter's own radiance there, which is
/// not scattered light, so the comparison leaves those pixels out.
pub fn sees_vpl_emitter(
    scene: &Scene,
    bvh: &SceneBvh,
    media: &SceneMedia,
    cam: &crate::render::ViewCamera,
) -> Vec<bool> {
    let sources: Vec<&crate::scene::Light> =
        scene.lights.iter().filter(|l| media.vpl_sources.contains(&l.name)).collect();
    (0..cam.width * cam.height)
        .map(|i| {
            let d = cam.pixel_dir(i % cam.width, i / cam.width);
            let o = cam.position;
            let hit = bvh.closest_hit(&crate::scene::bvh::Ray::new(o.to_array(), d.to_array()));
            let t_surface = hit.map_or(f64::INFINITY, |h| h.t);
            sources.iter().any(|l| match l.kind {
                LightKind::EmissiveMesh { mesh } => {
                    hit.is_some_and(|h| h.mesh == mesh && DVec3::from_array(h.geometric_normal).dot(d) < 0.0)
                }
                LightKind::Rect { center, half_u, half_v, normal } => {
                    let (c, u, v, n) = (
                        DVec3::from_array(center),
                        DVec3::from_array(half_u),
                        DVec3::from_array(half_v),
                        DVec3::from_array(normal),
                    );
                    plane_hit(o, d, c, n, t_surface).is_some_and(|p| {
                        (p - c).dot(u).abs() <= u.length_squared() && (p - c).dot(v).abs() <= v.length_squared()
                    })
                }
                LightKind::Disk { center, normal, radius } => {
                    let c = DVec3::from_array(center);
                    plane_hit(o, d, c, DVec3::from_array(normal), t_surface).is_some_and(|p| (p - c).length() <= radius)
                }
                _ => false,
            })
        })
        .collect()
}

/// Where the ray `o + t d` meets the front side (facing `n`) of the plane through `c`, before `t_max`.
fn plane_hit(o: DVec3, d: DVec3, c: DVec3, n: DVec3, t_max: f64) -> Option<DVec3> {
    let dn = d.dot(n);
    if dn >= 0.0 {
        return None;
    }
    let t = (c - o).dot(n) / dn;
    (t > 0.0 && t < t_max).then(|| o + d * t)
}

/// The surface reflections the path-traced reference of [`scattering_reference_scene`] lets through:
/// one when POP propagates the surfaces' reflected light as VPLs ([`add_reflection_vpls`]), else none.
pub fn reference_bounces(media: &SceneMedia) -> u32 {
    u32::from(media.reflection.as_ref().is_some_and(|r| r.vpls > 0))
}

/// The scene an independent path tracer must render to give exactly what POP's `scattered` layer
/// holds: the light the medium scatters toward the eye from the lights POP propagates, attenuated on the
/// way. Surfaces keep their albedo but emit nothing (the tracer is run with `eye_surfaces = false`, so
/// the surfaces the eye sees absorb, and `surface_bounces` 0, or 1 when POP propagates reflected light
/// as VPLs: [`reference_bounces`]), lights POP skips are removed, and the global medium is confined to POP's medium box: it becomes the medium of a closed,
/// index-matched box mesh (no material, so rays pass its faces unbent) `1e-6` of the box diagonal larger
/// than the box, so its faces never coincide with the walls they enclose. voltab's path tracer fills all
/// space with a global medium; the box keeps fog outside the scene's bounds (e.g. in front of an open
/// wall, between the camera and the room) out of the reference, as POP keeps it out.
pub fn scattering_reference_scene(scene: &Scene, media: &SceneMedia) -> Scene {
    let mut s = scene.clone();
    // Emissive meshes POP propagates as VPLs keep their emission; every other surface is dark.
    let emitting: Vec<usize> = s
        .lights
        .iter()
        .filter(|l| media.vpl_sources.contains(&l.name))
        .filter_map(|l| match l.kind {
            LightKind::EmissiveMesh { mesh } => s.meshes.get(mesh).and_then(|m| m.material),
            _ => None,
        })
        .collect();
    for (i, m) in s.materials.iter_mut().enumerate() {
        if !emitting.contains(&i) {
            m.emission = [0.0; 3];
        }
    }
    let names: Vec<&String> = media.light_names.iter().chain(&media.point_names).collect();
    s.lights.retain(|l| {
        media.vpl_sources.contains(&l.name)
            || (names.contains(&&l.name) && !matches!(l.kind, LightKind::EmissiveMesh { .. }))
    });
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

/// What a scene lacks for POP (`PopRender` and its `PopPreset` table): a global medium that scatters
/// forward (`g ≥ 0`), or a directional, point, spot or sphere light (rectilinear and radial grids) or a
/// dome light (environment ordinates).
pub fn lacks(sc: &Scene) -> Option<&'static str> {
    let media = sc.media.iter().filter(|m| m.boundary == Boundary::Global).collect::<Vec<_>>();
    if media.len() != 1 || media[0].g.iter().any(|g| *g < 0.0) {
        Some("single forward-scattering global medium")
    } else if sc.environment.is_none()
        && !sc.lights.iter().any(|l| {
            matches!(
                l.kind,
                LightKind::Directional { .. }
                    | LightKind::Point { .. }
                    | LightKind::Spot { .. }
                    | LightKind::Sphere { .. }
            )
        })
    {
        Some("directional, point, spot, sphere or dome light")
    } else {
        None
    }
}
