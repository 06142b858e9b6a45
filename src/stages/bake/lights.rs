//! The scene's lights as the bake connects to them.
//!
//! **Input → output.** [`Scene::lights`] → [`BakeLights`]: *delta* lights (point, spot, directional),
//! which a receiver connects to deterministically once per texel, and *area* lights (rect, disk, sphere,
//! emissive meshes), which are sampled: one light chosen in proportion to its power, one point on it
//! chosen uniformly by area. Each connection ends in a [`Source`], the emitter description the
//! dubouchet2019 tables are queried with (Sec. 5: point/directional tables for those emitters, the
//! differential-area table for area lights).
//!
//! **Conventions** (`docs/design/scene.md`): point and spot `radiance` is intensity \[W/sr\], directional
//! is irradiance \[W/m²\] on a surface facing it, area lights and emissive meshes are radiance
//! \[W/(m²·sr)\]. Spot cones use the glTF `KHR_lights_punctual` falloff: with
//! `t = clamp((cos θ − cos θ_outer) / max(10⁻³, cos θ_inner − cos θ_outer), 0, 1)`, the intensity is
//! scaled by `t²`. Rect and disk lights emit on the side of their normal only, spheres outward,
//! emissive triangles on their front (counter-clockwise) side. A directional light's angular size is
//! ignored (a delta direction).
//!
//! Positions, directions and normals are glam `DVec3` (converted from the scene's arrays here); colour
//! triples stay `[f64; 3]`.

use glam::DVec3;

use crate::render::color::luminance;
use crate::render::frame::frame;
use crate::render::spot::SpotCone;
use crate::scene::{LightKind, Mesh, Scene};

/// A point on an area light sampled by area: a differential patch.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Patch {
    /// Position \[m\].
    pub position: DVec3,
    /// Unit normal of the emitting side.
    pub normal: DVec3,
    /// Radiant intensity along the normal \[W/sr\] per channel: radiance × area ÷ probability of the
    /// sample (light choice × point choice), so averaging over samples is unbiased.
    pub intensity: [f64; 3],
}

/// What a receiver connects to.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Source {
    /// A point emitting `intensity` \[W/sr\] toward the receiver.
    Point {
        /// Position \[m\].
        position: DVec3,
        /// Intensity toward the receiver per channel.
        intensity: [f64; 3],
    },
    /// Parallel light arriving from `toward` (unit), `irradiance` \[W/m²\] on a surface facing it.
    Directional {
        /// Unit direction from the receiver to the light.
        toward: DVec3,
        /// Irradiance per channel.
        irradiance: [f64; 3],
    },
    /// A differential patch (an area-light sample, or a surface reflecting light).
    Patch(Patch),
}

/// A delta light.
#[derive(Debug, Clone, PartialEq)]
enum Delta {
    Point { position: DVec3, intensity: [f64; 3] },
    Spot { position: DVec3, cone: SpotCone, intensity: [f64; 3] },
    Directional { toward: DVec3, irradiance: [f64; 3] },
}

/// One sampleable area light.
#[derive(Debug, Clone, PartialEq)]
enum Shape {
    Rect {
        center: DVec3,
        half_u: DVec3,
        half_v: DVec3,
        normal: DVec3,
    },
    Disk {
        center: DVec3,
        normal: DVec3,
        radius: f64,
    },
    Sphere {
        center: DVec3,
        radius: f64,
    },
    /// Triangles (world positions, unit geometric normal) with their cumulative areas.
    Triangles {
        tris: Vec<WorldTriangle>,
        cdf: Vec<f64>,
    },
}

#[derive(Debug, Clone, PartialEq)]
struct Area {
    shape: Shape,
    area: f64,
    radiance: [f64; 3],
}

/// The lights of a scene, prepared for connections.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct BakeLights {
    deltas: Vec<Delta>,
    areas: Vec<Area>,
    /// Cumulative selection probabilities of `areas` (proportional to power).
    area_cdf: Vec<f64>,
}

impl BakeLights {
    /// Prepares `scene`'s lights. Lights with zero power, degenerate shapes or non-finite values are left
    /// out (the scene checks have already warned about them).
    pub fn new(scene: &Scene) -> BakeLights {
        let mut out = BakeLights::default();
        for light in &scene.lights {
            let rgb = light.radiance;
            if !rgb.iter().all(|c| c.is_finite() && *c >= 0.0) || rgb.iter().all(|&c| c == 0.0) {
                continue;
            }
            match &light.kind {
                LightKind::Point { position } => {
                    out.deltas.push(Delta::Point { position: DVec3::from_array(*position), intensity: rgb });
                }
                LightKind::Spot { position, direction, inner_cone, outer_cone } => {
                    let Some(cone) = SpotCone::khr(DVec3::from_array(*direction), *inner_cone, *outer_cone) else {
                        continue;
                    };
                    let position = DVec3::from_array(*position);
                    out.deltas.push(Delta::Spot { position, cone, intensity: rgb });
                }
                LightKind::Directional { direction, .. } => {
                    let Some(d) = unit(DVec3::from_array(*direction)) else { continue };
                    out.deltas.push(Delta::Directional { toward: -d, irradiance: rgb });
                }
                LightKind::Rect { center, half_u, half_v, normal } => {
                    let (half_u, half_v) = (DVec3::from_array(*half_u), DVec3::from_array(*half_v));
                    let area = 4.0 * half_u.cross(half_v).length();
                    if let Some(n) = unit(DVec3::from_array(*normal)) {
                        let center = DVec3::from_array(*center);
                        out.push_area(Shape::Rect { center, half_u, half_v, normal: n }, area, rgb);
                    }
                }
                LightKind::Disk { center, normal, radius } => {
                    if let Some(n) = unit(DVec3::from_array(*normal)) {
                        let area = std::f64::consts::PI * radius * radius;
                        let center = DVec3::from_array(*center);
                        out.push_area(Shape::Disk { center, normal: n, radius: *radius }, area, rgb);
                    }
                }
                LightKind::Sphere { center, radius } => {
                    let area = 4.0 * std::f64::consts::PI * radius * radius;
                    out.push_area(Shape::Sphere { center: DVec3::from_array(*center), radius: *radius }, area, rgb);
                }
                LightKind::EmissiveMesh { mesh } => {
                    if let Some(m) = scene.meshes.get(*mesh) {
                        let (tris, cdf) = triangles(m);
                        let area = cdf.last().copied().unwrap_or(0.0);
                        out.push_area(Shape::Triangles { tris, cdf }, area, rgb);
                    }
                }
            }
        }
        let total: f64 = out.areas.iter().map(power).sum();
        let mut acc = 0.0;
        out.area_cdf = out
            .areas
            .iter()
            .map(|a| {
                acc += power(a) / total;
                acc
            })
            .collect();
        if let Some(last) = out.area_cdf.last_mut() {
            *last = 1.0;
        }
        out
    }

    fn push_area(&mut self, shape: Shape, area: f64, radiance: [f64; 3]) {
        if area.is_finite() && area > 0.0 {
            self.areas.push(Area { shape, area, radiance });
        }
    }

    /// Whether there are area lights to sample.
    pub fn has_area(&self) -> bool {
        !self.areas.is_empty()
    }

    /// Number of delta lights.
    pub fn delta_count(&self) -> usize {
        self.deltas.len()
    }

    /// The delta lights as seen from `x`: point and spot lights as [`Source::Point`] (spot falloff
    /// applied toward `x`; lights whose intensity toward `x` is 0 are left out), directional lights as
    /// [`Source::Directional`].
    pub fn deltas_toward(&self, x: DVec3, out: &mut Vec<Source>) {
        out.clear();
        for d in &self.deltas {
            match d {
                Delta::Point { position, intensity } => {
                    out.push(Source::Point { position: *position, intensity: *intensity });
                }
                Delta::Spot { position, cone, intensity } => {
                    let Some(to_x) = unit(x - *position) else { continue };
                    let t = cone.ramp(to_x);
                    if t > 0.0 {
                        out.push(Source::Point { position: *position, intensity: intensity.map(|c| c * t * t) });
                    }
                }
                Delta::Directional { toward, irradiance } => {
                    out.push(Source::Directional { toward: *toward, irradiance: *irradiance });
                }
            }
        }
    }

    /// One area-light sample from uniforms `u` (light choice, two for the point); `None` without area
    /// lights.
    pub fn sample_area(&self, u: [f64; 3]) -> Option<Patch> {
        let i = self.area_cdf.iter().position(|&c| u[0] < c).unwrap_or(self.areas.len().checked_sub(1)?);
        let a = &self.areas[i];
        let p_choice = self.area_cdf[i] - if i == 0 { 0.0 } else { self.area_cdf[i - 1] };
        if p_choice <= 0.0 {
            return None;
        }
        let (position, normal) = match &a.shape {
            Shape::Rect { center, half_u, half_v, normal } => {
                let (s, t) = (2.0 * u[1] - 1.0, 2.0 * u[2] - 1.0);
                (*center + s * *half_u + t * *half_v, *normal)
            }
            Shape::Disk { center, normal, radius } => {
                let (e1, e2) = frame(*normal);
                let r = radius * u[1].sqrt();
                let phi = 2.0 * std::f64::consts::PI * u[2];
                let (a1, a2) = (r * phi.cos(), r * phi.sin());
                (*center + a1 * e1 + a2 * e2, *normal)
            }
            Shape::Sphere { center, radius } => {
                let z = 1.0 - 2.0 * u[1];
                let s = (1.0 - z * z).max(0.0).sqrt();
                let phi = 2.0 * std::f64::consts::PI * u[2];
                let n = DVec3::new(s * phi.cos(), s * phi.sin(), z);
                (*center + *radius * n, n)
            }
            Shape::Triangles { tris, cdf } => {
                let total = *cdf.last()?;
                // Reuse u[0]'s position within the chosen light's interval for the triangle choice.
                let lo = if i == 0 { 0.0 } else { self.area_cdf[i - 1] };
                let v = ((u[0] - lo) / p_choice).clamp(0.0, 1.0) * total;
                let k = cdf.partition_point(|&c| c <= v).min(tris.len() - 1);
                let (p, n) = &tris[k];
                let su = u[1].sqrt();
                let (b1, b2) = (1.0 - su, u[2] * su);
                (p[0] + b1 * (p[1] - p[0]) + b2 * (p[2] - p[0]), *n)
            }
        };
        let w = a.area / p_choice;
        Some(Patch { position, normal, intensity: a.radiance.map(|l| l * w) })
    }
}

fn power(a: &Area) -> f64 {
    a.area * luminance(a.radiance)
}

/// A world triangle and its unit geometric normal.
type WorldTriangle = ([DVec3; 3], DVec3);

/// World triangles of `m` with unit geometric normals (degenerate ones left out) and cumulative areas.
fn triangles(m: &Mesh) -> (Vec<WorldTriangle>, Vec<f64>) {
    let mut tris = Vec::new();
    let mut cdf = Vec::new();
    let mut acc = 0.0;
    for t in &m.triangles {
        let Some(p) = t
            .iter()
            .map(|&i| m.positions.get(i as usize).map(|v| DVec3::from_array(v.map(f64::from))))
            .collect::<Option<Vec<_>>>()
        else {
            continue;
        };
        let c = (p[1] - p[0]).cross(p[2] - p[0]);
        let (Some(n), area) = (unit(c), 0.5 * c.length()) else { continue };
        acc += area;
        tris.push(([p[0], p[1], p[2]], n));
        cdf.push(acc);
    }
    (tris, cdf)
}

/// `a / |a|`, or `None` for a zero or non-finite vector. (Not glam's `try_normalize`, which multiplies
/// by the reciprocal length and so rounds differently.)
pub(super) fn unit(a: DVec3) -> Option<DVec3> {
    let n = a.length();
    (n > 0.0 && n.is_finite()).then(|| a / n)
}
