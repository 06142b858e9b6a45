//! The rectilinear propagation grid of elek2014 Sec. 4 aligned with a directional light.
//!
//! **Input → output.** A [`VoxelMedium`], the light's direction `d` and a resolution → a box of cells
//! whose third axis is `d` (Fig. 2, top), spanning the whole medium, with per cell the medium
//! averaged over the cell (the MIP-style downsampling of Sec. 4.2 when the grid is coarser than the
//! voxels, a box filter of `s³` sub-samples) and per link between neighbouring cells the two factors
//! of Eqs. 2 and 4 that do not depend on the radiance: the absorption-only transmittance `T_src→dst`
//! (averaged `σ_a`, centre distance) and the anisotropy decay `g^{σ̄_s t}`. Links that cross an opaque
//! surface ([`Occluder`]) carry nothing.

use glam::DVec3;
use rayon::prelude::*;

use crate::render::color::Rgb;
use crate::render::occluder::Occluder;
use crate::render::voxel::VoxelMedium;

/// The medium averaged over one propagation cell.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Cell {
    /// Mean scattering coefficient \[1/m\].
    pub sigma_s: Rgb,
    /// Mean absorption coefficient \[1/m\].
    pub sigma_a: Rgb,
    /// Mean density (the guide of the joint-bilateral upsampling, Sec. 4.4).
    pub density: f64,
}

impl Cell {
    /// The cell of `medium` at mean `density`.
    pub fn at_density(medium: &VoxelMedium, density: f64) -> Self {
        Cell {
            sigma_s: medium.coefficients.sigma_s.map(|v| v * density),
            sigma_a: medium.coefficients.sigma_a.map(|v| v * density),
            density,
        }
    }

    /// The mean over channels of `σ_s` and of `g`, and of the cells with medium: what Eq. 10's switch
    /// reads (`(0, ḡ)` when no cell has medium).
    pub fn means(cells: &[Cell], g: Rgb) -> (f64, f64) {
        let occupied: Vec<f64> = cells
            .iter()
            .filter(|c| c.density > 0.0)
            .map(|c| (c.sigma_s[0] + c.sigma_s[1] + c.sigma_s[2]) / 3.0)
            .collect();
        let sigma_s = if occupied.is_empty() { 0.0 } else { occupied.iter().sum::<f64>() / occupied.len() as f64 };
        (sigma_s, (g[0] + g[1] + g[2]) / 3.0)
    }
}

/// A propagation grid aligned with a light direction.
#[derive(Debug, Clone)]
pub struct Grid {
    /// Grid origin (corner of cell 0) \[m\].
    pub origin: DVec3,
    /// Unit axes: `axes[2]` is the light direction `d`, `axes[0..2]` span the plane ⟂ `d`.
    pub axes: [DVec3; 3],
    /// Cells along each axis.
    pub dims: [usize; 3],
    /// Cell size along each axis \[m\].
    pub size: [f64; 3],
    /// The averaged medium per cell, index `i + dims[0]·(j + dims[1]·k)`.
    pub cells: Vec<Cell>,
    /// HG mean cosine per channel (the medium's; uniform over the volume).
    pub g: Rgb,
    /// Per cell and positive axis `a`, the link to the next cell along `a`:
    /// absorption transmittance per channel (0 when blocked or at the border).
    pub link_transmittance: Vec<[Rgb; 3]>,
    /// Per cell and positive axis, the anisotropy decay `g^{σ̄_s t}` per channel (Eq. 4).
    pub link_decay: Vec<[Rgb; 3]>,
}

impl Grid {
    /// Builds the grid: `d` (unit, the way light travels), `dims` (lateral, lateral, along `d`).
    ///
    /// # Errors
    /// A message when `d` is not a finite non-zero vector or a dimension is 0.
    pub fn new(medium: &VoxelMedium, d: DVec3, dims: [usize; 3], occluder: &dyn Occluder) -> Result<Self, String> {
        let d = d.try_normalize().ok_or_else(|| format!("light direction {d} is zero or not finite"))?;
        if dims.contains(&0) {
            return Err(format!("propagation grid {dims:?} has a zero dimension; every axis needs ≥ 1 cell"));
        }
        let (u, v) = crate::render::frame::frame(d);
        let axes = [u, v, d];
        // The oriented box enclosing the medium box's corners.
        let mut lo = DVec3::splat(f64::INFINITY);
        let mut hi = DVec3::splat(f64::NEG_INFINITY);
        for c in 0..8 {
            let p = DVec3::new(
                if c & 1 == 0 { medium.min.x } else { medium.max.x },
                if c & 2 == 0 { medium.min.y } else { medium.max.y },
                if c & 4 == 0 { medium.min.z } else { medium.max.z },
            );
            let q = DVec3::new(p.dot(axes[0]), p.dot(axes[1]), p.dot(axes[2]));
            lo = lo.min(q);
            hi = hi.max(q);
        }
        let ext = hi - lo;
        let size = [ext.x / dims[0] as f64, ext.y / dims[1] as f64, ext.z / dims[2] as f64];
        let origin = axes[0] * lo.x + axes[1] * lo.y + axes[2] * lo.z;
        let mut grid = Grid {
            origin,
            axes,
            dims,
            size,
            cells: Vec::new(),
            g: medium.coefficients.g,
            link_transmittance: Vec::new(),
            link_decay: Vec::new(),
        };
        grid.cells = grid.sample_medium(medium);
        grid.build_links(occluder);
        Ok(grid)
    }

    /// A grid aligned with the medium's box (axes x, y, z) holding only the averaged medium, no links:
    /// the single medium-aligned grid that radial grids are merged into (elek2014 Sec. 5.3) for rendering.
    ///
    /// # Errors
    /// A message when a dimension is 0.
    pub fn medium_aligned(medium: &VoxelMedium, dims: [usize; 3]) -> Result<Self, String> {
        if dims.contains(&0) {
            return Err(format!("merge grid {dims:?} has a zero dimension; every axis needs ≥ 1 cell"));
        }
        let ext = medium.max - medium.min;
        let mut grid = Grid {
            origin: medium.min,
            axes: [DVec3::X, DVec3::Y, DVec3::Z],
            dims,
            size: [ext.x / dims[0] as f64, ext.y / dims[1] as f64, ext.z / dims[2] as f64],
            cells: Vec::new(),
            g: medium.coefficients.g,
            link_transmittance: Vec::new(),
            link_decay: Vec::new(),
        };
        grid.cells = grid.sample_medium(medium);
        Ok(grid)
    }

    /// Number of cells.
    pub fn len(&self) -> usize {
        self.cells.len()
    }

    /// True when the grid has no cells (never, after [`Grid::new`]).
    pub fn is_empty(&self) -> bool {
        self.cells.is_empty()
    }

    /// Flat index of cell `(i, j, k)`.
    #[inline]
    pub fn index(&self, c: [usize; 3]) -> usize {
        c[0] + self.dims[0] * (c[1] + self.dims[1] * c[2])
    }

    /// Cell coordinates of flat index `n`.
    #[inline]
    pub fn coords(&self, n: usize) -> [usize; 3] {
        [n % self.dims[0], (n / self.dims[0]) % self.dims[1], n / (self.dims[0] * self.dims[1])]
    }

    /// World position of grid coordinates `t` (in cells; cell centres at `i + 0.5`).
    pub fn world(&self, t: DVec3) -> DVec3 {
        self.origin
            + self.axes[0] * (t.x * self.size[0])
            + self.axes[1] * (t.y * self.size[1])
            + self.axes[2] * (t.z * self.size[2])
    }

    /// Centre of cell `c`.
    pub fn center(&self, c: [usize; 3]) -> DVec3 {
        self.world(DVec3::new(c[0] as f64 + 0.5, c[1] as f64 + 0.5, c[2] as f64 + 0.5))
    }

    /// Continuous grid coordinates (in cells) of a world point.
    pub fn local(&self, p: DVec3) -> DVec3 {
        let q = p - self.origin;
        DVec3::new(
            q.dot(self.axes[0]) / self.size[0],
            q.dot(self.axes[1]) / self.size[1],
            q.dot(self.axes[2]) / self.size[2],
        )
    }

    /// Averages the medium over each cell with `s³` sub-samples, `s` chosen so sub-samples are no
    /// farther apart than half a voxel (at most 8 per axis).
    fn sample_medium(&self, medium: &VoxelMedium) -> Vec<Cell> {
        let voxel = medium.voxel_size().min_element();
        let s = self.size.iter().map(|&c| ((2.0 * c / voxel).ceil() as usize).clamp(1, 8)).max().unwrap_or(1);
        let inv = 1.0 / (s * s * s) as f64;
        (0..self.dims.iter().product::<usize>())
            .into_par_iter()
            .map(|n| {
                let c = self.coords(n);
                let mut density = 0.0;
                for a in 0..s {
                    for b in 0..s {
                        for e in 0..s {
                            let t = DVec3::new(
                                c[0] as f64 + (a as f64 + 0.5) / s as f64,
                                c[1] as f64 + (b as f64 + 0.5) / s as f64,
                                c[2] as f64 + (e as f64 + 0.5) / s as f64,
                            );
                            density += medium.density_at(self.world(t));
                        }
                    }
                }
                density *= inv;
                Cell::at_density(medium, density)
            })
            .collect()
    }

    /// The link factors of Eqs. 2 and 4 toward the next cell along each positive axis.
    fn build_links(&mut self, occluder: &dyn Occluder) {
        let g = self.g;
        let links: Vec<([Rgb; 3], [Rgb; 3])> = (0..self.len())
            .into_par_iter()
            .map(|n| {
                let c = self.coords(n);
                let mut t = [[0.0; 3]; 3];
                let mut decay = [[0.0; 3]; 3];
                for axis in 0..3 {
                    if c[axis] + 1 >= self.dims[axis] {
                        continue;
                    }
                    let mut nb = c;
                    nb[axis] += 1;
                    let (a, b) = (&self.cells[n], &self.cells[self.index(nb)]);
                    if occluder.segment_blocked(self.center(c), self.center(nb)) {
                        continue;
                    }
                    let dist = self.size[axis];
                    for ch in 0..3 {
                        t[axis][ch] = (-0.5 * (a.sigma_a[ch] + b.sigma_a[ch]) * dist).exp();
                        decay[axis][ch] = anisotropy_decay(g[ch], 0.5 * (a.sigma_s[ch] + b.sigma_s[ch]) * dist);
                    }
                }
                (t, decay)
            })
            .collect();
        self.link_transmittance = links.iter().map(|l| l.0).collect();
        self.link_decay = links.iter().map(|l| l.1).collect();
    }
}

/// Eq. 4's decay factor `g^{τ_s}` after a scattering optical depth `τ_s = σ̄_s t`: 1 in a
/// non-scattering stretch (also for `g = 0`, where `0⁰ = 1`), 0 for `g = 0` and `τ_s > 0` (one
/// scattering forgets the direction). Computed as `exp(τ_s ln g)`, which is finite for every `g ∈
/// [0, 1)` and `τ_s ≥ 0`.
pub fn anisotropy_decay(g: f64, tau_s: f64) -> f64 {
    if tau_s <= 0.0 {
        1.0
    } else if g <= 0.0 {
        0.0
    } else {
        (tau_s * g.ln()).exp()
    }
}
