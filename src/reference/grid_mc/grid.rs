//! Geometry of the reference: ray–box clipping, a 3-D DDA over a uniform grid (voxels or tally
//! cells), exact density integrals and exact free-flight inversion along a ray.

use glam::DVec3;

use crate::reference::frame::frame;
use crate::render::voxel::VoxelMedium;

/// A uniform grid of `dims` cells of size `size` from `min` (voxels or tally cells).
#[derive(Debug, Clone, Copy)]
pub(super) struct Grid {
    pub min: DVec3,
    pub max: DVec3,
    pub size: DVec3,
    pub dims: [usize; 3],
}

impl Grid {
    /// The grid of `dims` cells over the box `min`–`max`.
    pub fn new(min: DVec3, max: DVec3, dims: [usize; 3]) -> Self {
        let size = (max - min) / DVec3::new(dims[0] as f64, dims[1] as f64, dims[2] as f64);
        Grid { min, max, size, dims }
    }

    /// Linear index of cell `c` (x fastest).
    #[inline]
    pub fn index(&self, c: [usize; 3]) -> usize {
        c[0] + self.dims[0] * (c[1] + self.dims[1] * c[2])
    }

    /// Volume of one cell \[m³\].
    pub fn cell_volume(&self) -> f64 {
        self.size.x * self.size.y * self.size.z
    }

    /// Walks the cells the ray `o + t d` crosses for `t ∈ [t0, t1]` (which must lie in the grid's
    /// box up to rounding), in order, calling `f(cell index, a, b)` for every piece `[a, b]` of
    /// positive length; `f` returns `false` to stop. The cell of the first piece is found from the
    /// point at `t0` (clamped into the grid); a point rounded onto the wrong side of a plane gives
    /// a zero-length piece that is skipped, so rounding never moves more than `~ε·t` of length.
    pub fn walk(&self, o: DVec3, d: DVec3, t0: f64, t1: f64, mut f: impl FnMut(usize, f64, f64) -> bool) {
        if t1.partial_cmp(&t0) != Some(std::cmp::Ordering::Greater) || !o.is_finite() || !d.is_finite() {
            return;
        }
        let p = o + d * t0;
        let mut cell = [0i64; 3];
        let mut t_next = [f64::INFINITY; 3];
        let mut step = [0i64; 3];
        for a in 0..3 {
            let n = self.dims[a] as i64;
            let u = (p[a] - self.min[a]) / self.size[a];
            let mut c = (u.floor() as i64).clamp(0, n - 1);
            // On a plane while moving down: the cell below is the one the ray enters.
            if d[a] < 0.0 && c > 0 && u <= c as f64 {
                c -= 1;
            }
            cell[a] = c;
            if d[a] > 0.0 {
                step[a] = 1;
                t_next[a] = (self.min[a] + (c + 1) as f64 * self.size[a] - o[a]) / d[a];
            } else if d[a] < 0.0 {
                step[a] = -1;
                t_next[a] = (self.min[a] + c as f64 * self.size[a] - o[a]) / d[a];
            }
        }
        let mut t = t0;
        let limit = self.dims.iter().sum::<usize>() + 8;
        for _ in 0..limit {
            let a = if t_next[0] <= t_next[1] && t_next[0] <= t_next[2] {
                0
            } else if t_next[1] <= t_next[2] {
                1
            } else {
                2
            };
            let end = t_next[a].min(t1);
            if end > t {
                let idx = self.index([cell[0] as usize, cell[1] as usize, cell[2] as usize]);
                if !f(idx, t, end) {
                    return;
                }
                t = end;
            }
            if t_next[a] >= t1 {
                return;
            }
            cell[a] += step[a];
            if cell[a] < 0 || cell[a] >= self.dims[a] as i64 {
                return;
            }
            let plane = if step[a] > 0 { cell[a] + 1 } else { cell[a] };
            t_next[a] = (self.min[a] + plane as f64 * self.size[a] - o[a]) / d[a];
        }
    }
}

/// The parameter interval `[t0, t1]`, `t0 ≥ t_min`, of the ray `o + t d` inside the box
/// `min`–`max`; `None` when the ray misses it or only grazes it (zero length).
pub(super) fn clip(min: DVec3, max: DVec3, o: DVec3, d: DVec3, t_min: f64) -> Option<(f64, f64)> {
    let (mut t0, mut t1) = (t_min, f64::INFINITY);
    for a in 0..3 {
        if d[a] == 0.0 {
            if o[a] < min[a] || o[a] > max[a] {
                return None;
            }
        } else {
            let inv = 1.0 / d[a];
            let (mut n, mut f) = ((min[a] - o[a]) * inv, (max[a] - o[a]) * inv);
            if n > f {
                std::mem::swap(&mut n, &mut f);
            }
            t0 = t0.max(n);
            t1 = t1.min(f);
        }
    }
    (t1 > t0 && t0.is_finite() && t1.is_finite()).then_some((t0, t1))
}

/// The medium's voxels as a [`Grid`] plus their densities.
pub(super) struct Voxels<'a> {
    pub grid: Grid,
    pub density: &'a [f32],
}

impl<'a> Voxels<'a> {
    pub fn new(m: &'a VoxelMedium) -> Self {
        Voxels { grid: Grid::new(m.min, m.max, m.dims), density: &m.density }
    }

    /// `[t0, t1]` of the ray inside the medium box (`t0 ≥ t_min`).
    pub fn clip(&self, o: DVec3, d: DVec3, t_min: f64) -> Option<(f64, f64)> {
        clip(self.grid.min, self.grid.max, o, d, t_min)
    }

    /// `∫ density ds` along `o + t d`, `t ∈ [t0, t1]` (exact for piecewise-constant voxels).
    pub fn density_integral(&self, o: DVec3, d: DVec3, t0: f64, t1: f64) -> f64 {
        let mut sum = 0.0;
        self.grid.walk(o, d, t0, t1, |i, a, b| {
            sum += f64::from(self.density[i]) * (b - a);
            true
        });
        sum
    }

    /// `∫ density ds` from `o` along `d` to where the ray leaves the box (0 outside it).
    pub fn density_to_exit(&self, o: DVec3, d: DVec3) -> f64 {
        self.clip(o, d, 0.0).map_or(0.0, |(t0, t1)| self.density_integral(o, d, t0, t1))
    }

    /// The `t ∈ [t0, t1]` at which `∫_{t0}^{t} density ds` reaches `target` (exact inversion,
    /// voxel by voxel), `None` if the ray reaches `t1` first.
    pub fn invert(&self, o: DVec3, d: DVec3, t0: f64, t1: f64, target: f64) -> Option<f64> {
        if !target.is_finite() {
            return None;
        }
        let mut acc = 0.0;
        let mut hit = None;
        self.grid.walk(o, d, t0, t1, |i, a, b| {
            let rho = f64::from(self.density[i]);
            let piece = rho * (b - a);
            if rho > 0.0 && acc + piece >= target {
                hit = Some((a + (target - acc) / rho).clamp(a, b));
                return false;
            }
            acc += piece;
            true
        });
        hit
    }
}

/// The direction at cosine `mu` and azimuth `2π·u` about the unit vector `d`.
pub(super) fn rotate(d: DVec3, mu: f64, u: f64) -> DVec3 {
    let (t, b) = frame(d);
    let s = (1.0 - mu * mu).max(0.0).sqrt();
    let phi = std::f64::consts::TAU * u;
    let w = d * mu + (t * phi.cos() + b * phi.sin()) * s;
    w.try_normalize().unwrap_or(d)
}
