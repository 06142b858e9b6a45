//! Principal ordinates of elek2014 Sec. 5: a deterministic, well-spread set of unit directions
//! (spherical Fibonacci points), an exact nearest-ordinate search, and the quadrature of each
//! ordinate's Voronoi cell Ω_n (its solid angle and the mean cosine a_n of Sec. 5.1).
//!
//! Input: a direction count N (or any direction set). Output: directions, per-cell solid angle (sr)
//! and mean cosine. Invariant: every result is a pure function of its inputs (no randomness, fixed
//! chunking and merge order), so tables are byte-identical for any thread count.

use glam::DVec3;
use rayon::prelude::*;

/// `1/Φ²` with `Φ = (1 + √5)/2` the golden ratio: `2π/Φ²` is the golden angle.
const INV_PHI_SQUARED: f64 = 0.381_966_011_250_105_15;

/// Samples per quadrature chunk (the unit of parallel work and of the fixed merge order).
const CHUNK: u64 = 1 << 16;

/// Direction `i` of the `n`-point spherical Fibonacci set:
/// `z_i = 1 − (2i + 1)/n`, `φ_i = 2π · frac(i/Φ²)`, `(x, y, z) = (r cos φ_i, r sin φ_i, z_i)` with
/// `r = √((1 − z_i)(1 + z_i))`. The points lie at the centres of `n` equal-area zones in z, rotated
/// by the golden angle, so no two share a zone and none sits on a pole.
pub fn fibonacci_direction(i: u64, n: u64) -> [f64; 3] {
    let z = 1.0 - (2 * i + 1) as f64 / n as f64;
    let r = ((1.0 - z) * (1.0 + z)).max(0.0).sqrt();
    let phi = std::f64::consts::TAU * (i as f64 * INV_PHI_SQUARED).fract();
    [r * phi.cos(), r * phi.sin(), z]
}

/// The `n`-point spherical Fibonacci set (see [`fibonacci_direction`]).
pub fn fibonacci_directions(n: usize) -> Vec<[f64; 3]> {
    (0..n as u64).map(|i| fibonacci_direction(i, n as u64)).collect()
}

/// Exact nearest-direction search over a direction set, by a sweep in z.
///
/// The geodesic angle between two unit vectors bounds the difference of their z components
/// (`|cos θ₁ − cos θ₂| ≤ |θ₁ − θ₂|`), so once the z gap to the next candidate exceeds the best
/// angle found, no later candidate on that side can be nearer. Ties go to the lower index.
#[derive(Debug, Clone)]
pub struct NearestDirection {
    /// (z, original index), ascending in z.
    by_z: Vec<(f64, usize)>,
    dirs: Vec<DVec3>,
}

impl NearestDirection {
    /// Indexes a direction set (unit vectors).
    pub fn new(dirs: &[[f64; 3]]) -> Self {
        let mut by_z: Vec<(f64, usize)> = dirs.iter().enumerate().map(|(i, d)| (d[2], i)).collect();
        by_z.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
        Self { by_z, dirs: dirs.iter().map(|&d| DVec3::from_array(d)).collect() }
    }

    /// Index of the direction nearest to `w` (a unit vector) and the cosine of the angle to it;
    /// `None` for an empty set.
    pub fn nearest(&self, w: [f64; 3]) -> Option<(usize, f64)> {
        let n = self.by_z.len();
        let wv = DVec3::from_array(w);
        let p = self.by_z.partition_point(|e| e.0 < w[2]);
        let (mut lo, mut hi) = (p, p); // candidates: lo − 1 downwards, hi upwards
        let mut best: Option<(usize, f64)> = None;
        let mut bound = f64::INFINITY; // angle to the best so far (+ rounding margin)
        loop {
            let gap_lo = if lo > 0 { w[2] - self.by_z[lo - 1].0 } else { f64::INFINITY };
            let gap_hi = if hi < n { self.by_z[hi].0 - w[2] } else { f64::INFINITY };
            let can_lo = lo > 0 && gap_lo <= bound;
            let can_hi = hi < n && gap_hi <= bound;
            let j = if can_lo && (!can_hi || gap_lo <= gap_hi) {
                lo -= 1;
                self.by_z[lo].1
            } else if can_hi {
                hi += 1;
                self.by_z[hi - 1].1
            } else {
                break;
            };
            let c = self.dirs[j].dot(wv);
            let better = match best {
                None => true,
                Some((bi, bc)) => c > bc || (c == bc && j < bi),
            };
            if better {
                best = Some((j, c));
                bound = c.clamp(-1.0, 1.0).acos() + 1e-12;
            }
        }
        best
    }
}

/// Per-cell results of [`cell_quadrature`].
#[derive(Debug, Clone, PartialEq)]
pub struct CellQuadrature {
    /// Solid angle Ω_n of each direction's Voronoi cell in sr; sums to 4π.
    pub solid_angle: Vec<f64>,
    /// Mean cosine `∫_{Ω_n} d_n·ω dω / |Ω_n|` between each direction and its cell (elek2014
    /// Sec. 5.1); 0 for a cell that received no sample.
    pub mean_cosine: Vec<f64>,
    /// Quadrature samples used.
    pub samples: u64,
}

/// Number of quadrature samples for `n` ordinates: 4096 per cell, at least 2^20, at most 2^24.
/// A cell then holds ≥ 4096 samples up to N = 4096; the boundary discretisation error of a cell's
/// solid angle is well below 1 % (measured against 8x the samples: ≤ 0.08 % at N = 64, ≤ 0.25 %
/// at N = 125; mean cosines within 2e-5; see the tests).
pub fn quadrature_samples(n: usize) -> u64 {
    (4096 * n as u64).clamp(1 << 20, 1 << 24)
}

/// Solid angle and mean cosine of the Voronoi cell of every direction in `dirs`, by assigning the
/// `samples` points of a spherical Fibonacci set (equal weights 4π/samples) to their nearest
/// direction. Deterministic: integer counts, and cosine sums merged in a fixed chunk order.
pub fn cell_quadrature(dirs: &[[f64; 3]], samples: u64, progress: &(dyn Fn(u64) + Sync)) -> CellQuadrature {
    let n = dirs.len();
    let search = NearestDirection::new(dirs);
    let chunks: Vec<(Vec<u64>, Vec<f64>)> = (0..samples.div_ceil(CHUNK))
        .into_par_iter()
        .map(|c| {
            let mut count = vec![0u64; n];
            let mut sum_cos = vec![0.0f64; n];
            for i in c * CHUNK..((c + 1) * CHUNK).min(samples) {
                let w = fibonacci_direction(i, samples);
                if let Some((j, cos)) = search.nearest(w) {
                    count[j] += 1;
                    sum_cos[j] += cos;
                }
            }
            progress(1);
            (count, sum_cos)
        })
        .collect();
    let mut count = vec![0u64; n];
    let mut sum_cos = vec![0.0f64; n];
    for (c, s) in &chunks {
        count.iter_mut().zip(c).for_each(|(acc, x)| *acc += x);
        sum_cos.iter_mut().zip(s).for_each(|(acc, x)| *acc += x);
    }
    let weight = 4.0 * std::f64::consts::PI / samples as f64;
    CellQuadrature {
        solid_angle: count.iter().map(|&c| c as f64 * weight).collect(),
        mean_cosine: count.iter().zip(&sum_cos).map(|(&c, &s)| if c > 0 { s / c as f64 } else { 0.0 }).collect(),
        samples,
    }
}

/// Work units [`cell_quadrature`] reports for `samples` samples.
pub fn quadrature_chunks(samples: u64) -> u64 {
    samples.div_ceil(CHUNK)
}
