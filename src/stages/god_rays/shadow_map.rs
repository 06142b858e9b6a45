//! Light-space shadow maps (baran2010 Sec. 2.2, "a shadow map from the light"; Sec. 9 for spot
//! lights), rasterised ([`render_shadow_map`]) or ray traced ([`trace_shadow_map`], the independent
//! check of the rasteriser and its old implementation).
//!
//! **Input → output.** A [`SceneBvh`], an [`EpiLight`], the scene bounds and a resolution → a
//! [`ShadowMap`]: per texel the distance from the light's near plane (directional, orthographic
//! window fitted to the bounds) or from the light's position (spot, perspective frustum over the
//! outer cone) to the first surface along the texel centre's ray, `f32::INFINITY` where that ray
//! escapes. Lookups are nearest-texel; [`ShadowMap::lit`] is the visibility every shadow-map method
//! uses.
//!
//! **Rasteriser.** Each triangle the BVH holds is projected into texel space (a spot's triangles first
//! clipped to the half-space in front of the light), binned into bands of rows, and per band (in
//! parallel) every texel centre inside it (edge functions in `f64`, edges inclusive so shared edges
//! leave no gaps) takes the depth of the triangle's plane along the texel's ray if it is nearer. The
//! depth is the same ray–plane distance the tracer finds, so both maps agree to rounding except at
//! texel centres lying on a triangle's edge.

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

/// Renders the shadow map of `light` over `scene_bounds` at `resolution²` texels (at least 1) by
/// rasterising the triangles of `bvh` (module doc), on the current rayon pool. Deterministic: the
/// nearest depth per texel does not depend on the order triangles are drawn in.
pub fn render_shadow_map(
    bvh: &SceneBvh,
    light: &EpiLight,
    scene_bounds: ([f64; 3], [f64; 3]),
    resolution: usize,
) -> ShadowMap {
    let n = resolution.max(1);
    let frame = LightFrame::new(light, scene_bounds);
    let tris: Vec<Projected> = bvh.triangles().flat_map(|t| frame.project(t, n)).collect();
    // Bands of rows, each drawn by one task from the triangles overlapping it.
    let band = BAND_ROWS.min(n);
    let bands = n.div_ceil(band);
    let mut binned: Vec<Vec<u32>> = vec![Vec::new(); bands];
    for (k, t) in tris.iter().enumerate() {
        let last = (t.rows.1 / band).min(bands - 1);
        for list in &mut binned[t.rows.0 / band..=last] {
            list.push(k as u32);
        }
    }
    let mut depth = vec![f32::INFINITY; n * n];
    depth.par_chunks_mut(band * n).zip(binned.par_iter()).enumerate().for_each(|(b, (rows, list))| {
        let j0 = b * band;
        for &k in list {
            tris[k as usize].draw(&frame, n, j0, rows);
        }
    });
    shadow_map(frame, depth, n, scene_bounds)
}

/// Rows per rasterisation task.
const BAND_ROWS: usize = 32;

/// The shadow map of [`render_shadow_map`] by casting one ray per texel centre through `bvh` (the
/// tracer the rasteriser replaced: its independent check, and the fallback view of what a texel sees).
pub fn trace_shadow_map(
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
    shadow_map(frame, depth, n, scene_bounds)
}

fn shadow_map(frame: LightFrame, depth: Vec<f32>, n: usize, scene_bounds: ([f64; 3], [f64; 3])) -> ShadowMap {
    let diag = (DVec3::from_array(scene_bounds.1) - DVec3::from_array(scene_bounds.0)).length();
    let bias = if diag.is_finite() { 1e-4 * diag } else { 1e-4 };
    ShadowMap { resolution: n, depth, frame, bounds: scene_bounds, bias }
}

/// One triangle (or a piece of one clipped in front of a spot) in texel space: vertices `(X, Y)` with
/// texel `(i, j)`'s centre at `(i + ½, j + ½)`, its plane, and the rows it may cover.
#[derive(Debug, Clone, Copy)]
struct Projected {
    xy: [[f64; 3]; 2],
    /// A point of the plane and its unit normal (world space).
    p0: DVec3,
    normal: DVec3,
    /// First and last row whose centre may be covered.
    rows: (usize, usize),
}

impl LightFrame {
    /// Texel-space position of `p` in an `n × n` map (`None` behind a spot's near plane).
    fn texel_xy(&self, p: DVec3, n: usize) -> Option<[f64; 2]> {
        let nf = n as f64;
        match *self {
            LightFrame::Ortho { origin, ax_u, ax_v, extent, .. } => {
                let q = p - origin;
                Some([q.dot(ax_u) / extent[0] * nf, q.dot(ax_v) / extent[1] * nf])
            }
            LightFrame::Persp { pos, fwd, right, up, tan_half } => {
                let q = p - pos;
                let z = q.dot(fwd);
                (z > 0.0).then(|| {
                    let (sx, sy) = (q.dot(right) / (z * tan_half), q.dot(up) / (z * tan_half));
                    [(sx + 1.0) * 0.5 * nf, (1.0 - sy) * 0.5 * nf]
                })
            }
        }
    }

    /// The pieces of triangle `v` to draw into an `n × n` map: the triangle itself, or for a spot light
    /// its part in front of the light (clipped at a near distance; up to two triangles), nothing when it
    /// is edge-on, behind the light, or off the map.
    fn project(&self, v: [[f32; 3]; 3], n: usize) -> Vec<Projected> {
        let p = v.map(|a| DVec3::from_array(a.map(f64::from)));
        let Some(normal) = (p[1] - p[0]).cross(p[2] - p[0]).try_normalize() else { return Vec::new() };
        let polygon: Vec<DVec3> = match *self {
            LightFrame::Ortho { .. } => p.to_vec(),
            LightFrame::Persp { pos, fwd, .. } => {
                let size = p.iter().map(|q| (*q - pos).length()).fold(0.0f64, f64::max);
                clip_front(&p, pos, fwd, 1e-9 * size.max(1e-9))
            }
        };
        let xy: Vec<[f64; 2]> = polygon.iter().filter_map(|&q| self.texel_xy(q, n)).collect();
        if xy.len() != polygon.len() || xy.len() < 3 {
            return Vec::new();
        }
        (1..xy.len() - 1)
            .filter_map(|k| {
                let t = [xy[0], xy[k], xy[k + 1]];
                let (lo, hi) =
                    t.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), q| (a.min(q[1]), b.max(q[1])));
                let (r0, r1) = ((lo - 0.5).ceil(), (hi - 0.5).floor());
                if !(r0 <= r1 && r1 >= 0.0 && r0 < n as f64) {
                    return None;
                }
                Some(Projected {
                    xy: [[t[0][0], t[1][0], t[2][0]], [t[0][1], t[1][1], t[2][1]]],
                    p0: p[0],
                    normal,
                    rows: (r0.max(0.0) as usize, (r1 as usize).min(n - 1)),
                })
            })
            .collect()
    }
}

/// The part of the polygon `p` with `(q − pos)·fwd ≥ near` (Sutherland–Hodgman against one plane).
fn clip_front(p: &[DVec3], pos: DVec3, fwd: DVec3, near: f64) -> Vec<DVec3> {
    let dist = |q: DVec3| (q - pos).dot(fwd) - near;
    let mut out = Vec::with_capacity(4);
    for k in 0..p.len() {
        let (a, b) = (p[k], p[(k + 1) % p.len()]);
        let (da, db) = (dist(a), dist(b));
        if da >= 0.0 {
            out.push(a);
        }
        if (da >= 0.0) != (db >= 0.0) {
            out.push(a + (b - a) * (da / (da - db)));
        }
    }
    out
}

impl Projected {
    /// Draws the triangle into `rows` (the map's rows `j0..`, `n` texels each), keeping the nearer depth:
    /// per row the span of texel centres inside all three edges (inclusive) is solved for directly, and
    /// the depth along the texel rays is affine in the texel centre (orthographic) or the plane distance
    /// over the ray's cosine (perspective).
    fn draw(&self, frame: &LightFrame, n: usize, j0: usize, rows: &mut [f32]) {
        let [x, y] = self.xy;
        let area = (x[1] - x[0]) * (y[2] - y[0]) - (y[1] - y[0]) * (x[2] - x[0]);
        if area == 0.0 || !area.is_finite() {
            return;
        }
        let s = area.signum();
        // Edge k: s·((x_l − x_k)(cy − y_k) − (y_l − y_k)(cx − x_k)) = a·cx + b·cy + c ≥ 0.
        let edges: [[f64; 3]; 3] = [0, 1, 2].map(|k| {
            let l = (k + 1) % 3;
            let (a, b) = (-s * (y[l] - y[k]), s * (x[l] - x[k]));
            [a, b, -(a * x[k] + b * y[k])]
        });
        let nf = n as f64;
        // Depth along texel (cx, cy)'s ray.
        enum Depth {
            Affine([f64; 3]),
            Persp { k: f64, d0: DVec3, dx: DVec3, dy: DVec3 },
        }
        let depth = match *frame {
            LightFrame::Ortho { origin, ax_u, ax_v, dir, extent } => {
                let den = self.normal.dot(dir);
                if den == 0.0 {
                    return;
                }
                let base = self.normal.dot(self.p0 - origin) / den;
                let gx = -extent[0] / nf * self.normal.dot(ax_u) / den;
                let gy = -extent[1] / nf * self.normal.dot(ax_v) / den;
                Depth::Affine([gx, gy, base])
            }
            LightFrame::Persp { pos, fwd, right, up, tan_half } => Depth::Persp {
                k: self.normal.dot(self.p0 - pos),
                d0: fwd - tan_half * right + tan_half * up,
                dx: 2.0 * tan_half / nf * right,
                dy: -2.0 * tan_half / nf * up,
            },
        };
        let j_end = j0 + rows.len() / n;
        for j in self.rows.0.max(j0)..=self.rows.1.min(j_end.saturating_sub(1)) {
            let cy = j as f64 + 0.5;
            let (mut lo, mut hi) = (0.5f64, nf - 0.5);
            for e in &edges {
                let r = e[1] * cy + e[2];
                if e[0] > 0.0 {
                    lo = lo.max(-r / e[0]);
                } else if e[0] < 0.0 {
                    hi = hi.min(-r / e[0]);
                } else if r < 0.0 {
                    hi = f64::NEG_INFINITY;
                }
            }
            if hi < lo || hi.is_nan() || lo.is_nan() {
                continue;
            }
            let (i0, i1) = ((lo - 0.5).ceil().max(0.0) as usize, ((hi - 0.5).floor().min(nf - 1.0)) as usize);
            let row = &mut rows[(j - j0) * n..(j - j0 + 1) * n];
            for (i, px) in row.iter_mut().enumerate().take(i1.min(n - 1) + 1).skip(i0) {
                let cx = i as f64 + 0.5;
                let t = match depth {
                    Depth::Affine(g) => g[0] * cx + g[1] * cy + g[2],
                    Depth::Persp { k, d0, dx, dy } => {
                        let d = d0 + cx * dx + cy * dy;
                        let den = self.normal.dot(d);
                        if den == 0.0 {
                            continue;
                        }
                        k * d.length() / den
                    }
                };
                if t > 0.0 && t.is_finite() {
                    let t = t as f32;
                    if t < *px {
                        *px = t;
                    }
                }
            }
        }
    }
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
