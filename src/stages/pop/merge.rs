//! Merging point lights' radial accumulation grids into one medium-aligned grid (elek2014 Sec. 5.3,
//! applied to the radial grids of Sec. 6) and rendering them.
//!
//! **Input → output.** Radial grids with their collided radiance toward the eye per unit `σ_s`, a
//! medium-aligned [`Grid`] (elek2014 uses double the propagation grids' resolution, "since these are
//! oriented arbitrarily in space") → that grid's per-cell value: the sum over lights of each radial
//! field resampled ([`RadialGrid::sample`]) at `2³` points inside the cell and averaged (a box filter, so
//! the small cells around a light are not point-sampled). The ray marcher then reads one grid for all
//! point lights, upsampled by the joint bilateral filter of Sec. 4.4, and adds each light's uncollided
//! single scattering per step ([`PointDirect`]).

use rayon::prelude::*;

use super::grid::Grid;

use super::radial::RadialGrid;
use super::radial_propagate::{PointDirect, RadialPropagation};
use super::render::{self, Frame, MarchOptions, StepSource};
use crate::render::ViewCamera;
use crate::render::color::Rgb;
use crate::render::voxel::VoxelMedium;

/// Sums the radial fields into `target`'s cells (module doc).
pub fn merge(target: &Grid, sources: &[(&RadialGrid, &[Rgb])]) -> Vec<Rgb> {
    box_filter(target, |p| {
        let mut sum = [0.0; 3];
        for (grid, field) in sources {
            let v = grid.sample(field, p);
            for ch in 0..3 {
                sum[ch] += v[ch];
            }
        }
        sum
    })
}

/// Sums rectilinear fields (environment ordinates' accumulation grids, each aligned with its own
/// ordinate) into `target`'s cells: each field read trilinearly between cell centres (clamped at the
/// faces, as [`render::upsample`] without the range weight) at the same `2³` points per cell.
pub fn merge_rectilinear(target: &Grid, sources: &[(&Grid, &[Rgb])]) -> Vec<Rgb> {
    box_filter(target, |p| {
        let mut sum = [0.0; 3];
        for (grid, field) in sources {
            let v = trilinear(grid, field, p);
            for ch in 0..3 {
                sum[ch] += v[ch];
            }
        }
        sum
    })
}

/// `field` (one value per cell of `grid`) interpolated trilinearly at world point `p`.
fn trilinear(grid: &Grid, field: &[Rgb], p: glam::DVec3) -> Rgb {
    let t = grid.local(p) - glam::DVec3::splat(0.5);
    let mut base = [0usize; 3];
    let mut f = [0.0f64; 3];
    for a in 0..3 {
        let v = t[a].clamp(0.0, (grid.dims[a] - 1) as f64);
        base[a] = (v as usize).min(grid.dims[a].saturating_sub(2));
        f[a] = v - base[a] as f64;
    }
    let mut out = [0.0; 3];
    for corner in 0..8 {
        let o = [corner & 1, (corner >> 1) & 1, (corner >> 2) & 1];
        let c = [0, 1, 2].map(|a| (base[a] + o[a]).min(grid.dims[a] - 1));
        let w: f64 = (0..3).map(|a| if o[a] == 1 { f[a] } else { 1.0 - f[a] }).product();
        if w == 0.0 {
            continue;
        }
        let v = field[grid.index(c)];
        for ch in 0..3 {
            out[ch] += w * v[ch];
        }
    }
    out
}

/// `target`'s cells: the mean of `f` at `2³` points inside each cell (a box filter).
fn box_filter(target: &Grid, f: impl Fn(glam::DVec3) -> Rgb + Sync) -> Vec<Rgb> {
    (0..target.len())
        .into_par_iter()
        .map(|n| {
            let c = target.coords(n);
            let mut sum = [0.0; 3];
            for corner in 0..8 {
                let t = glam::DVec3::new(
                    c[0] as f64 + 0.25 + 0.5 * (corner & 1) as f64,
                    c[1] as f64 + 0.25 + 0.5 * ((corner >> 1) & 1) as f64,
                    c[2] as f64 + 0.25 + 0.5 * ((corner >> 2) & 1) as f64,
                );
                let v = f(target.world(t));
                for ch in 0..3 {
                    sum[ch] += v[ch] / 8.0;
                }
            }
            sum
        })
        .collect()
}

/// Ray-marches the merged grid plus every light's uncollided single scattering.
pub fn march_points(
    merged: &Grid,
    merged_toward_eye: &[Rgb],
    lights: &[(&RadialGrid, &RadialPropagation)],
    medium: &VoxelMedium,
    camera: &ViewCamera,
    surface_distance: Option<&[f64]>,
    opts: &MarchOptions,
) -> Frame {
    let uniform = medium.density.windows(2).all(|w| w[0] == w[1]);
    let directs: Vec<PointDirect<'_>> =
        lights.iter().map(|(grid, p)| PointDirect { init: &p.init, grid, medium, uniform }).collect();
    let sources: Vec<&dyn StepSource> = directs.iter().map(|d| d as &dyn StepSource).collect();
    render::march_with(merged, merged_toward_eye, medium, camera, surface_distance, opts, &sources)
}
