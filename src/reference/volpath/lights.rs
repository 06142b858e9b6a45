//! Next-event sampling of every light kind in voltab's radiometric convention.
//!
//! **Input → output.** A [`Scene`]'s lights → [`PreparedLight`]s; per prepared light and shading
//! point a [`LightSample`]: the unit direction to a point on the light, its distance, and the
//! incident value `L/p` (radiance over the solid-angle pdf, or for delta lights the irradiance a
//! surface facing the light receives), plus the solid-angle pdf when an unidirectional path can also
//! hit the light (emissive meshes, for the MIS weights in `path.rs`).
//!
//! **Conventions.** Point: intensity `I` \[W/sr\], `I/max(d², D_MIN²)` with [`D_MIN`] = 1e-4 m (a
//! receiver touching the light stays finite; the clamp changes nothing at `d ≥ 0.1 mm`). Spot: the
//! KHR_lights_punctual falloff, `I · clamp((cos θ − cos θ_o)/(cos θ_i − cos θ_o), 0, 1)²`, with the
//! denominator floored at 1e-3 as in that specification. Directional: irradiance `E` \[W/m²\] from
//! the delta direction `−direction` (a non-zero `angle` is ignored). Rect and disk: one-sided, emit
//! along `normal`, sampled uniformly by area. Sphere: emits outward, sampled uniformly in the cone
//! it subtends (nothing reaches a point inside it). Emissive mesh: triangles emit on their front
//! (counter-clockwise, geometric-normal) side, a triangle chosen with probability ∝ area, a point
//! uniform in it.

use glam::DVec3;

use crate::reference::frame::frame;
use crate::scene::{LightKind, Scene};

/// Smallest distance a point light's `1/d²` is evaluated at \[m\].
pub const D_MIN: f64 = 1e-4;

/// Geometry of one prepared light.
#[derive(Debug, Clone)]
enum Shape {
    Point { pos: DVec3 },
    Spot { pos: DVec3, axis: DVec3, cos_outer: f64, inv_range: f64 },
    Directional { to_light: DVec3 },
    Rect { center: DVec3, half_u: DVec3, half_v: DVec3, normal: DVec3, area: f64 },
    Disk { center: DVec3, normal: DVec3, t1: DVec3, t2: DVec3, radius: f64, area: f64 },
    Sphere { center: DVec3, radius: f64 },
    Mesh { tris: Vec<[DVec3; 3]>, cdf: Vec<f64>, area: f64 },
}

/// A light ready for sampling.
#[derive(Debug, Clone)]
pub struct PreparedLight {
    shape: Shape,
    /// Intensity, irradiance or radiance per channel (see the module doc).
    pub radiance: [f64; 3],
    /// Index into [`Scene::meshes`] for an emissive mesh.
    pub mesh: Option<usize>,
}

/// One next-event sample.
#[derive(Debug, Clone, Copy)]
pub struct LightSample {
    /// Unit direction from the shading point to the light.
    pub dir: DVec3,
    /// Distance to the sampled point (`+∞` for a directional light).
    pub dist: f64,
    /// Whether the sampled point lies on scene geometry (the shadow ray must stop short of it).
    pub on_surface: bool,
    /// `L/p` per channel: the sample's contribution before the phase/BSDF factor and transmittance.
    pub value: [f64; 3],
    /// Solid-angle pdf when an unidirectional path can hit the light too (emissive meshes).
    pub pdf: Option<f64>,
}

/// A unit vector, or `None` for a zero or non-finite one.
pub fn unit(v: [f64; 3]) -> Option<DVec3> {
    let v = DVec3::from_array(v);
    let m = v.abs().max_element();
    if !(m > 0.0 && m.is_finite()) {
        return None;
    }
    let s = v / m;
    Some(s / s.length())
}

impl PreparedLight {
    /// Every light of `scene` with non-zero, finite power and usable geometry.
    pub fn prepare_all(scene: &Scene) -> Vec<PreparedLight> {
        scene.lights.iter().filter_map(|l| Self::prepare(scene, &l.kind, l.radiance)).collect()
    }

    fn prepare(scene: &Scene, kind: &LightKind, radiance: [f64; 3]) -> Option<PreparedLight> {
        let radiance = radiance.map(|x| if x.is_finite() && x > 0.0 { x } else { 0.0 });
        if radiance.iter().all(|&x| x == 0.0) {
            return None;
        }
        let p = |a: [f64; 3]| Some(DVec3::from_array(a)).filter(|v| v.is_finite());
        let mut mesh = None;
        let shape = match kind {
            LightKind::Point { position } => Shape::Point { pos: p(*position)? },
            LightKind::Spot { position, direction, inner_cone, outer_cone } => {
                let (ci, co) = (inner_cone.cos(), outer_cone.cos());
                if !(ci.is_finite() && co.is_finite()) {
                    return None;
                }
                Shape::Spot {
                    pos: p(*position)?,
                    axis: unit(*direction)?,
                    cos_outer: co,
                    inv_range: 1.0 / (ci - co).max(1e-3),
                }
            }
            LightKind::Directional { direction, .. } => Shape::Directional { to_light: -unit(*direction)? },
            LightKind::Rect { center, half_u, half_v, normal } => {
                let (hu, hv) = (p(*half_u)?, p(*half_v)?);
                let area = 4.0 * hu.cross(hv).length();
                if !(area > 0.0 && area.is_finite()) {
                    return None;
                }
                Shape::Rect { center: p(*center)?, half_u: hu, half_v: hv, normal: unit(*normal)?, area }
            }
            LightKind::Disk { center, normal, radius } => {
                let n = unit(*normal)?;
                let area = std::f64::consts::PI * radius * radius;
                if !(area > 0.0 && area.is_finite()) {
                    return None;
                }
                let (t1, t2) = frame(n);
                Shape::Disk { center: p(*center)?, normal: n, t1, t2, radius: *radius, area }
            }
            LightKind::Sphere { center, radius } => {
                if !(*radius > 0.0 && radius.is_finite()) {
                    return None;
                }
                Shape::Sphere { center: p(*center)?, radius: *radius }
            }
            LightKind::EmissiveMesh { mesh: mi } => {
                let m = scene.meshes.get(*mi)?;
                mesh = Some(*mi);
                let mut tris = Vec::with_capacity(m.triangles.len());
                let mut cdf = Vec::with_capacity(m.triangles.len());
                let mut area = 0.0;
                for t in &m.triangles {
                    let v = t.map(|i| m.positions.get(i as usize).map(|q| DVec3::from_array(q.map(f64::from))));
                    let (Some(a), Some(b), Some(c)) = (v[0], v[1], v[2]) else { continue };
                    let ar = 0.5 * (b - a).cross(c - a).length();
                    if !(ar > 0.0 && ar.is_finite()) {
                        continue;
                    }
                    area += ar;
                    tris.push([a, b, c]);
                    cdf.push(area);
                }
                if !(area > 0.0 && area.is_finite()) {
                    return None;
                }
                Shape::Mesh { tris, cdf, area }
            }
        };
        Some(PreparedLight { shape, radiance, mesh })
    }

    /// Position of a point or spot light (the lights whose next-event samples from a medium are
    /// singular at the light: `path.rs` adds equiangular sampling for them).
    pub fn position(&self) -> Option<DVec3> {
        match &self.shape {
            Shape::Point { pos } | Shape::Spot { pos, .. } => Some(*pos),
            _ => None,
        }
    }

    /// Distance `t > 0` at which the ray `o + t·d` (unit `d`) meets the emitting side of an analytic
    /// area light: the front (`⟨d, normal⟩ < 0`) of a rect (the parallelogram `center + a·half_u +
    /// b·half_v`, `|a|, |b| ≤ 1`) or disk, or the outside of a sphere from a ray starting outside it.
    /// `None` for every other kind (delta lights cannot be hit; emissive meshes are scene geometry).
    pub fn hit_distance(&self, o: DVec3, d: DVec3) -> Option<f64> {
        // The plane through `c` with normal `m`, met from the emitting side of `side`: distance and
        // the point met relative to `c`.
        let plane = |c: DVec3, m: DVec3, side: DVec3| -> Option<(f64, DVec3)> {
            if d.dot(side).is_nan() || d.dot(side) >= 0.0 {
                return None;
            }
            let t = (c - o).dot(m) / d.dot(m);
            (t > 0.0 && t.is_finite()).then(|| (t, o + t * d - c))
        };
        let t = match &self.shape {
            Shape::Rect { center, half_u, half_v, normal, .. } => {
                // The parallelogram's own plane; `normal` only decides the emitting side.
                let m = half_u.cross(*half_v);
                let (t, q) = plane(*center, m, *normal)?;
                let mm = m.length_squared();
                let (a, b) = (q.cross(*half_v).dot(m) / mm, half_u.cross(q).dot(m) / mm);
                (a.abs() <= 1.0 && b.abs() <= 1.0).then_some(t)?
            }
            Shape::Disk { center, normal, radius, .. } => {
                let (t, q) = plane(*center, *normal, *normal)?;
                (q.length_squared() <= radius * radius).then_some(t)?
            }
            Shape::Sphere { center, radius } => {
                let rel = *center - o;
                let b = rel.dot(d);
                let c2 = rel.length_squared();
                if c2 <= radius * radius || b <= 0.0 {
                    return None;
                }
                let disc = radius * radius - (c2 - b * b);
                if disc.is_nan() || disc < 0.0 {
                    return None;
                }
                // Nearer root without cancellation: t = (c² − r²)/(b + √disc).
                (c2 - radius * radius) / (b + disc.sqrt())
            }
            _ => return None,
        };
        (t > 0.0 && t.is_finite()).then_some(t)
    }

    /// Total emitting area of an emissive mesh \[m²\] (`None` for other kinds).
    pub fn mesh_area(&self) -> Option<f64> {
        match &self.shape {
            Shape::Mesh { area, .. } => Some(*area),
            _ => None,
        }
    }

    /// A next-event sample from point `x` with the uniforms `u`, `v` (`None`: no light reaches `x`).
    pub fn sample(&self, x: DVec3, u: f64, v: f64) -> Option<LightSample> {
        let delta = |to: DVec3, scale: f64| -> Option<LightSample> {
            let d = to - x;
            let dist = d.length();
            let dir = unit(d.to_array())?;
            let inv = 1.0 / (dist * dist).max(D_MIN * D_MIN);
            Some(LightSample { dir, dist, on_surface: false, value: self.radiance.map(|r| r * scale * inv), pdf: None })
        };
        // An area sample at `q` with emitting normal `n` (one-sided) and area pdf `1/area`.
        let area_sample = |q: DVec3, n: DVec3, area: f64, on_surface: bool, mis: bool| -> Option<LightSample> {
            let d = q - x;
            let dist = d.length();
            let dir = unit(d.to_array())?;
            let cos_l = -n.dot(dir);
            if cos_l.is_nan() || cos_l <= 0.0 {
                return None;
            }
            let pdf = dist * dist / (area * cos_l);
            if !(pdf > 0.0 && pdf.is_finite()) {
                return None;
            }
            let value = self.radiance.map(|r| r / pdf);
            Some(LightSample { dir, dist, on_surface, value, pdf: mis.then_some(pdf) })
        };
        match &self.shape {
            Shape::Point { pos } => delta(*pos, 1.0),
            Shape::Spot { pos, axis, cos_outer, inv_range } => {
                let dir = unit((x - *pos).to_array())?;
                let f = ((axis.dot(dir) - cos_outer) * inv_range).clamp(0.0, 1.0);
                if f == 0.0 {
                    return None;
                }
                delta(*pos, f * f)
            }
            Shape::Directional { to_light } => Some(LightSample {
                dir: *to_light,
                dist: f64::INFINITY,
                on_surface: false,
                value: self.radiance,
                pdf: None,
            }),
            Shape::Rect { center, half_u, half_v, normal, area } => {
                let q = *center + (2.0 * u - 1.0) * *half_u + (2.0 * v - 1.0) * *half_v;
                area_sample(q, *normal, *area, false, false)
            }
            Shape::Disk { center, normal, t1, t2, radius, area } => {
                let (r, phi) = (radius * u.sqrt(), std::f64::consts::TAU * v);
                let q = *center + r * (phi.cos() * *t1 + phi.sin() * *t2);
                area_sample(q, *normal, *area, false, false)
            }
            Shape::Sphere { center, radius } => self.sample_sphere(x, *center, *radius, u, v),
            Shape::Mesh { tris, cdf, area } => {
                let target = u * area;
                let i = cdf.partition_point(|&c| c <= target).min(tris.len() - 1);
                let lo = if i == 0 { 0.0 } else { cdf[i - 1] };
                // Reuse the remainder of `u` within the chosen triangle's bin as a fresh uniform.
                let w = ((target - lo) / (cdf[i] - lo)).clamp(0.0, 1.0);
                let [a, b, c] = tris[i];
                let s = w.sqrt();
                let q = a * (1.0 - s) + b * (s * (1.0 - v)) + c * (s * v);
                let n = unit((b - a).cross(c - a).to_array())?;
                area_sample(q, n, *area, true, true)
            }
        }
    }

    /// Uniform direction in the cone subtended by an outward-emitting sphere.
    fn sample_sphere(&self, x: DVec3, center: DVec3, radius: f64, u: f64, v: f64) -> Option<LightSample> {
        let d = center - x;
        let dc = d.length();
        if dc.is_nan() || dc <= radius {
            return None;
        }
        let axis = d / dc;
        let s2 = (radius / dc).powi(2); // sin²θ_max
        let one_minus_cos_max = s2 / (1.0 + (1.0 - s2).sqrt());
        let solid = std::f64::consts::TAU * one_minus_cos_max;
        let one_minus_cos = u * one_minus_cos_max;
        let cos = 1.0 - one_minus_cos;
        let sin = (one_minus_cos * (2.0 - one_minus_cos)).max(0.0).sqrt();
        let phi = std::f64::consts::TAU * v;
        let (t1, t2) = frame(axis);
        let dir = cos * axis + sin * (phi.cos() * t1 + phi.sin() * t2);
        // Nearer intersection with the sphere: t = dc·cos − sqrt(r² − dc²·sin²).
        let disc = (radius * radius - dc * dc * sin * sin).max(0.0);
        let dist = (dc * cos - disc.sqrt()).max(0.0);
        Some(LightSample { dir, dist, on_surface: false, value: self.radiance.map(|r| r * solid), pdf: None })
    }
}
