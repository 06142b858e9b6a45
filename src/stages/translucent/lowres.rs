//! Lower-rate evaluation of the smooth components (wang2018 Sec. 5.1: multiple scattering is computed
//! on a 4 × 4 downsampled image and interpolated).
//!
//! **Input → output.** The camera segments of a frame (pixel, order within the pixel, kind, length,
//! direction, boundary normal) and a stride `s` → per segment a [`Plan`]: evaluate it directly, or
//! interpolate it bilinearly from the segments of the same order in the four surrounding anchor
//! pixels. Anchor pixels are every `s`-th column and row plus the last column and row, so every pixel
//! lies in a cell of anchors.
//!
//! **What is interpolated.** A segment's component is an integral `∫₀^d e^{−σ t} L(t) dt` over its
//! camera samples, so it grows with the segment's length; the plan interpolates the attenuation-
//! weighted mean radiance (the integral divided by its quadrature weights' sum) and the caller
//! multiplies it back by the segment's own sum.
//!
//! **Edges.** A segment is interpolated only when every anchor segment it draws on has the same kind
//! (reached directly or not, same number of camera samples), a direction within
//! [`MAX_DIR_ANGLE_COS`], a boundary normal within [`MAX_NORMAL_COS`] and a length within a factor
//! [`MAX_LENGTH_RATIO`]; otherwise (silhouettes, internal reflections that diverge, the ground seen
//! beside the object) it is evaluated directly.

use glam::DVec3;

/// Anchor and interpolated segments must have directions with at least this cosine (≈ 26°).
pub const MAX_DIR_ANGLE_COS: f64 = 0.9;
/// ... boundary normals with at least this cosine (≈ 37°).
pub const MAX_NORMAL_COS: f64 = 0.8;
/// ... lengths within this factor of each other.
pub const MAX_LENGTH_RATIO: f64 = 2.0;

/// What the planner needs to know of a segment.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SegmentShape {
    /// Pixel index `x + y·width`.
    pub pixel: u32,
    /// Reached directly through one refraction.
    pub primary: bool,
    /// Camera samples.
    pub samples: u32,
    /// Length inside the object.
    pub d_max: f64,
    /// Unit direction.
    pub dir: DVec3,
    /// Unit outward boundary normal at the entry.
    pub normal: DVec3,
}

/// How a segment's smooth components are obtained.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Plan {
    /// Evaluated at the segment's own camera samples.
    Direct,
    /// Bilinear weights over up to four directly evaluated segments (indices), weights summing to 1.
    Interp([(u32, f64); 4]),
}

fn compatible(a: &SegmentShape, b: &SegmentShape) -> bool {
    a.primary == b.primary
        && a.samples == b.samples
        && a.dir.dot(b.dir) >= MAX_DIR_ANGLE_COS
        && a.normal.dot(b.normal) >= MAX_NORMAL_COS
        && a.d_max <= MAX_LENGTH_RATIO * b.d_max
        && b.d_max <= MAX_LENGTH_RATIO * a.d_max
}

/// The anchor coordinates at or below and at or above `x` on an axis of `n` pixels.
fn bracket(x: usize, n: usize, stride: usize) -> (usize, usize) {
    if is_anchor(x, n, stride) {
        return (x, x);
    }
    let lo = x - x % stride;
    (lo, (lo + stride).min(n - 1))
}

fn is_anchor(x: usize, n: usize, stride: usize) -> bool {
    x.is_multiple_of(stride) || x == n - 1
}

/// Plans every segment. `segments` are in pixel order (a pixel's segments contiguous, in tracing
/// order); `stride` 1 evaluates everything directly.
pub fn plan(width: usize, height: usize, stride: usize, segments: &[SegmentShape]) -> Vec<Plan> {
    let mut out = vec![Plan::Direct; segments.len()];
    if stride <= 1 || width == 0 || height == 0 {
        return out;
    }
    // First segment of each pixel and its count.
    let mut first = vec![(0u32, 0u32); width * height];
    for (i, s) in segments.iter().enumerate() {
        let e = &mut first[s.pixel as usize];
        if e.1 == 0 {
            e.0 = i as u32;
        }
        e.1 += 1;
    }
    for (i, s) in segments.iter().enumerate() {
        let px = s.pixel as usize;
        let (x, y) = (px % width, px / width);
        if is_anchor(x, width, stride) && is_anchor(y, height, stride) {
            continue;
        }
        let order = i as u32 - first[px].0;
        let (x0, x1) = bracket(x, width, stride);
        let (y0, y1) = bracket(y, height, stride);
        let fx = if x1 > x0 { (x - x0) as f64 / (x1 - x0) as f64 } else { 0.0 };
        let fy = if y1 > y0 { (y - y0) as f64 / (y1 - y0) as f64 } else { 0.0 };
        let corners = [
            (x0, y0, (1.0 - fx) * (1.0 - fy)),
            (x1, y0, fx * (1.0 - fy)),
            (x0, y1, (1.0 - fx) * fy),
            (x1, y1, fx * fy),
        ];
        let mut taps = [(0u32, 0.0); 4];
        let mut ok = true;
        for (k, &(cx, cy, w)) in corners.iter().enumerate() {
            if w <= 0.0 {
                continue;
            }
            let (f, n) = first[cx + cy * width];
            let j = f + order;
            if order >= n || !compatible(s, &segments[j as usize]) {
                ok = false;
                break;
            }
            taps[k] = (j, w);
        }
        if ok {
            out[i] = Plan::Interp(taps);
        }
    }
    out
}

#[cfg(test)]
mod tests;
