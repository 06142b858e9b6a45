//! Light-space shadow maps rendered with voltab's own ray tracer (baran2010 Sec. 2.2, "a shadow map
//! from the light"; Sec. 9 for spot lights).
//!
//! **Input → output.** A [`SceneBvh`], an [`EpiLight`], the scene bounds and a resolution → a
//! [`ShadowMap`]: per texel the distance from the light's near plane (directional, orthographic
//! window fitted to the bounds) or from the light's position (spot, perspective frustum over the
//! outer cone) to the first surface, `f32::INFINITY` where the texel's ray escapes. Lookups are
//! nearest-texel; [`ShadowMap::lit`] is the visibility every shadow-map method uses.

use glam::DVec3;
use rayon::prelude::*;

use super::EpiLight;
use crate::scene::bvh::{Ray, SceneBvh};

/// The light's projection: where a world point falls in the shadow map and its depth there.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum LightFrame {
    /// Parallel projection along `dir` (directional light).
    Ortho {
        /// Corner of the window on the near plane \[m\].
        origin: DVec3,
        /// First window axis (unit, ⟂ `dir`).
        ax_u: DVec3,
        /// Second window axis (unit, ⟂ `dir`, `ax_u`).
        ax_v: DVec3,
        /// Light travel direction (unit).
        dir: DVec3,
        /// Window size along `ax_u`, `ax_v` \[m\].
        extent: [f64; 2],
    },
    /// Central projection from `pos` (spot light), square frustum of half-angle `atan(tan_half)`.
    Persp {
        /// Light position \[m\].
        pos: DVec3,
        /// Cone axis (unit).
        fwd: DVec3,
        /// Image-right axis (unit).
        right: DVec3,
        /// Image-up axis (unit).
        up: DVec3,
        /// Tangent of the frustum's half-angle.
        tan_half: f64,
    },
}

fn perpendicular_basis(d: DVec3) -> (DVec3, DVec3) {
    let hint = if d.y.abs() < 0.9 { DVec3::Y } else { DVec3::X };
    let u = d.cross(hint).normalize();
    (u, u.cross(d))
}

impl LightFrame {
    /// The frame of `light` fitted to `bounds` (orthographic window over the projected box for a
    /// directional light; the outer cone, clamped to 80°, for a spot light). Degenerate directions
    /// fall back to −Y.
    pub fn new(light: &EpiLight, bounds: ([f64; 3], [f64; 3])) -> LightFrame {
        match light {
            EpiLight::Directional { direction, .. } => {
                let dir = DVec3::from_array(*direction).try_normalize().unwrap_or(DVec3::NEG_Y);
                let (ax_u, ax_v) = perpendicular_basis(dir);
                let (mut lo, mut hi) = ([f64::INFINITY; 3], [f64::NEG_INFINITY; 3]);
                for c in 0..8 {
                    let p = DVec3::new(
                        if c & 1 == 1 { bounds.1[0] } else { bounds.0[0] },
                        if c & 2 == 2 { bounds.1[1] } else { bounds.0[1] },
                        if c & 4 == 4 { bounds.1[2] } else { bounds.0[2] },
                    );
                    let q = [p.dot(ax_u), p.dot(ax_v), p.dot(dir)];
                    for k in 0..3 {
                        lo[k] = lo[k].min(q[k]);
                        hi[k] = hi[k].max(q[k]);
                    }
                }
                let size = (0..3).map(|k| hi[k] - lo[k]).fold(0.0f64, f64::max).max(1e-6);
                let margin = 1e-3 * size;
                let origin = (lo[0] - margin) * ax_u + (lo[1] - margin) * ax_v + (lo[2] - margin) * dir;
                let extent = [hi[0] - lo[0] + 2.0 * margin, hi[1] - lo[1] + 2.0 * margin];
                LightFrame::Ortho { origin, ax_u, ax_v, dir, extent }
            }
            EpiLight::Spot { position, direction, outer_cone, .. } => {
                let fwd = DVec3::from_array(*direction).try_normalize().unwrap_or(DVec3::NEG_Y);
                let (right, up) = perpendicular_basis(fwd);
                let half = if outer_cone.is_finite() { outer_cone.clamp(1e-3, 80f64.to_radians()) } else { 0.5 };
                LightFrame::Persp { pos: DVec3::from_array(*position), fwd, right, up, tan_half: half.tan() }
            }
        }
    }

    /// Window coordinates `uv ∈ [0, 1)²` of `p` and its depth (distance along the light from the near
    /// plane, or from the spot's position); `None` outside the window or behind the spot.
    pub fn uv_depth(&self, p: DVec3) -> Option<([f64; 2], f64)> {
        let (uv, z) = match *self {
            LightFrame::Ortho { origin, ax_u, ax_v, dir, extent } => {
                let q = p - origin;
                ([q.dot(ax_u) / extent[0], q.dot(ax_v) / extent[1]], q.dot(dir))
            }
            LightFrame::Persp { pos, fwd, right, up, tan_half } => {
                let q = p - pos;
                let z = q.dot(fwd);
                if z <= 0.0 {
                    return None;
                }
                let sx = q.dot(right) / (z * tan_half);
                let sy = q.dot(up) / (z * tan_half);
                ([(sx + 1.0) * 0.5, (1.0 - sy) * 0.5], q.length())
            }
        };
        (uv[0] >= 0.0 && uv[0] < 1.0 && uv[1] >= 0.0 && uv[1] < 1.0 && z.is_finite()).then_some((uv, z))
    }

    /// Window coordinates of `p` without the window check (`None` only behind a spot light): where a
    /// light texture is sampled (clamped to its edges).
    pub fn uv(&self, p: DVec3) -> Option<[f64; 2]> {
        match *self {
            LightFrame::Ortho { origin, ax_u, ax_v, extent, .. } => {
                let q = p - origin;
                Some([q.dot(ax_u) / extent[0], q.dot(ax_v) / extent[1]])
            }
            LightFrame::Persp { pos, fwd, right, up, tan_half } => {
                let q = p - pos;
                let z = q.dot(fwd);
                (z > 0.0)
                    .then(|| [(q.dot(right) / (z * tan_half) + 1.0) * 0.5, (1.0 - q.dot(up) / (z * tan_half)) * 0.5])
            }
        }
    }

    /// Ray of texel `(i, j)` of an `n × n` map: origin and unit direction; depth is measured in `t`.
    fn texel_ray(&self, i: usize, j: usize, n: usize) -> (DVec3, DVec3) {
        let (a, b) = ((i as f64 + 0.5) / n as f64, (j as f64 + 0.5) / n as f64);
        match *self {
            LightFrame::Ortho { origin, ax_u, ax_v, dir, extent } => {
                (origin + a * extent[0] * ax_u + b * extent[1] * ax_v, dir)
            }
            LightFrame::Persp { pos, fwd, right, up, tan_half } => {
                let d = fwd + (2.0 * a - 1.0) * tan_half * right + (1.0 - 2.0 * b) * tan_half * up;
                (pos, d.normalize())
            }
        }
    }
}

/// A light-space depth map (module doc).
#[derive(Debug, Clone, PartialEq)]
pub struct ShadowMap {
    /// Texels per side.
    pub resolution: usize,
    /// `resolution²` blocker depths, row-major (`v` rows), `f32::INFINITY` where nothing is hit.
    pub depth: Vec<f32>,
    /// The projection.
    pub frame: LightFrame,
    /// The scene bounds it was fitted to (also where escaping view rays end).
    pub bounds: ([f64; 3], [f64; 3]),
    /// Depth bias \[m\]: a point is lit when its depth is below the texel's blocker depth plus this
    /// (10⁻⁴ of the bounds' diagonal; volume samples need little bias).
    pub bias: f64,
}

/// Renders the shadow map of `light` over `scene_bounds` at `resolution²` texels (at least 1) on the
/// current rayon pool.
pub fn render_shadow_map(
    bvh: &SceneBvh,
    light: &EpiLight,
    scene_bounds: ([f64; 3], [f64; 3]),
    resolution: usize,
) -> ShadowMap {
    let n = resolution.max(1);
    let frame = LightFrame::new(light, scene_bounds);
    let mut depth = vec![f32::INFINITY; n * n];
    depth.par_chunks_mut(n).enumerate().for_each(|(j, row)| {
        for (i, px) in row.iter_mut().enumerate() {
            let (o, d) = frame.texel_ray(i, j, n);
            if let Some(h) = bvh.closest_hit(&Ray::new(o.to_array(), d.to_array())) {
                *px = h.t as f32;
            }
        }
    });
    let diag = (DVec3::from_array(scene_bounds.1) - DVec3::from_array(scene_bounds.0)).length();
    let bias = if diag.is_finite() { 1e-4 * diag } else { 1e-4 };
    ShadowMap { resolution: n, depth, frame, bounds: scene_bounds, bias }
}

impl ShadowMap {
    /// Blocker depth of the texel `p` falls in and `p`'s own depth; `None` outside the window.
    pub fn blocker_and_depth(&self, p: DVec3) -> Option<(f64, f64)> {
        let (uv, z) = self.frame.uv_depth(p)?;
        let n = self.resolution;
        let i = ((uv[0] * n as f64) as usize).min(n - 1);
        let j = ((uv[1] * n as f64) as usize).min(n - 1);
        Some((f64::from(self.depth[j * n + i]), z))
    }

    /// Whether `p` sees the light (outside the map's window: lit — nothing there casts shadows).
    pub fn lit(&self, p: DVec3) -> bool {
        match self.blocker_and_depth(p) {
            Some((b, z)) => z < b + self.bias,
            None => true,
        }
    }
}
