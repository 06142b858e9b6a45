//! Rendering the accumulation grid (elek2014 Sec. 4.4).
//!
//! **Input → output.** The radiance a propagation scattered toward the eye (per cell, per unit
//! `σ_s`), the fine [`VoxelMedium`] and a camera → per pixel the in-scattered radiance and the
//! transmittance, by front-to-back emission–absorption ray marching. The coarse grid is upsampled at
//! every ray sample by a 3-D joint bilateral filter guided by the medium's density: the eight
//! trilinear weights of the surrounding cell centres are multiplied by
//! `exp(−½ ((ρ(x) − ρ̄_cell)/(σ_r ρ_max))²)`, so detail of the density field (finer than the grid)
//! carries into the solution. `σ_r = ∞` is plain trilinear interpolation.

use glam::DVec3;
use rayon::prelude::*;

use super::grid::Grid;

use crate::physics::medium::extinguished;
use crate::render::ViewCamera;
use crate::render::color::Rgb;
use crate::render::voxel::VoxelMedium;

/// Ray-marching settings.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MarchOptions {
    /// Step length as a fraction of the smaller of voxel and cell size (of the cell size when the
    /// density is uniform).
    pub step_fraction: f64,
    /// Range width `σ_r` of the bilateral weight relative to the largest density (`INFINITY`:
    /// trilinear).
    pub range_sigma: f64,
}

impl Default for MarchOptions {
    fn default() -> Self {
        Self { step_fraction: 0.5, range_sigma: 0.25 }
    }
}

/// A rendered frame: in-scattered radiance and transmittance per pixel (row-major).
#[derive(Debug, Clone)]
pub struct Frame {
    /// Pixels per row.
    pub width: usize,
    /// Rows.
    pub height: usize,
    /// In-scattered radiance \[W/(m² sr)\].
    pub radiance: Vec<Rgb>,
    /// Transmittance from the eye to the surface (or through the medium).
    pub transmittance: Vec<Rgb>,
}

/// `1/(σ_r ρ_max)`, the bilateral range scale of [`upsample`] (0: trilinear) for a range width `range`
/// relative to the medium's largest density (`INFINITY` or ≤ 0: trilinear).
pub fn range_scale(medium: &VoxelMedium, range: f64) -> f64 {
    let m = medium.max_density();
    if range.is_finite() && range > 0.0 && m > 0.0 { 1.0 / (range * m) } else { 0.0 }
}

/// The upsampled value of `toward_eye` at `p` (joint bilateral, see the module doc; `inv_range` from
/// [`range_scale`]).
pub fn upsample(grid: &Grid, toward_eye: &[Rgb], medium: &VoxelMedium, p: DVec3, inv_range: f64) -> Rgb {
    let t = grid.local(p) - DVec3::splat(0.5);
    let dims = grid.dims;
    let clampf = |v: f64, n: usize| v.clamp(0.0, (n - 1) as f64);
    let t = DVec3::new(clampf(t.x, dims[0]), clampf(t.y, dims[1]), clampf(t.z, dims[2]));
    let base = [t.x as usize, t.y as usize, t.z as usize];
    let f = t - DVec3::new(base[0] as f64, base[1] as f64, base[2] as f64);
    let rho = medium.density_at(p);
    let mut sum = [0.0; 3];
    let mut wsum = 0.0;
    let mut plain = [0.0; 3];
    for corner in 0..8 {
        let o = [corner & 1, (corner >> 1) & 1, (corner >> 2) & 1];
        let c =
            [(base[0] + o[0]).min(dims[0] - 1), (base[1] + o[1]).min(dims[1] - 1), (base[2] + o[2]).min(dims[2] - 1)];
        let w = (if o[0] == 1 { f.x } else { 1.0 - f.x })
            * (if o[1] == 1 { f.y } else { 1.0 - f.y })
            * (if o[2] == 1 { f.z } else { 1.0 - f.z });
        let i = grid.index(c);
        let z = (rho - grid.cells[i].density) * inv_range;
        let wr = w * (-0.5 * z * z).exp();
        for ch in 0..3 {
            sum[ch] += wr * toward_eye[i][ch];
            plain[ch] += w * toward_eye[i][ch];
        }
        wsum += wr;
    }
    if wsum > 1e-12 { sum.map(|v| v / wsum) } else { plain }
}

/// Parametric interval of the ray inside the box, if any.
fn clip(min: DVec3, max: DVec3, o: DVec3, d: DVec3) -> Option<(f64, f64)> {
    let inv = d.recip();
    let t0 = (min - o) * inv;
    let t1 = (max - o) * inv;
    let lo = t0.min(t1);
    let hi = t0.max(t1);
    // NaN (0 · ∞ when the origin lies on a slab plane of an axis-parallel ray) must not widen the
    // interval: f64::max/min ignore NaN.
    let enter = lo.x.max(lo.y).max(lo.z).max(0.0);
    let exit = hi.x.min(hi.y).min(hi.z);
    (exit > enter).then_some((enter, exit))
}

/// A source of light scattered toward the eye that the ray marcher evaluates per step instead of reading
/// it from a grid (a point light's single scattering, whose `1/r²` no grid resolves).
pub trait StepSource: Sync {
    /// Over the step from `a` to `b` (the eye lies behind `a`), `∫ J(s) e^{−σ_t s} ds` per channel: the
    /// radiance `J` scattered toward the eye per unit `σ_s` \[W/(m² sr) per 1/m\], weighted by the
    /// transmittance from `a` with the step's extinction `sigma_t` \[1/m\].
    fn step_integral(&self, a: DVec3, b: DVec3, sigma_t: Rgb) -> Rgb;
}

/// Ray-marches every pixel. `surface_distance` (per pixel, `INFINITY` when the ray escapes) stops the
/// march at the first surface.
pub fn march(
    grid: &Grid,
    toward_eye: &[Rgb],
    medium: &VoxelMedium,
    camera: &ViewCamera,
    surface_distance: Option<&[f64]>,
    opts: &MarchOptions,
) -> Frame {
    march_with(grid, toward_eye, medium, camera, surface_distance, opts, &[])
}

/// [`march`] with extra per-step sources added to the upsampled grid value.
pub fn march_with(
    grid: &Grid,
    toward_eye: &[Rgb],
    medium: &VoxelMedium,
    camera: &ViewCamera,
    surface_distance: Option<&[f64]>,
    opts: &MarchOptions,
    sources: &[&dyn StepSource],
) -> Frame {
    // Steps resolve the finer of voxels and cells; a uniform density has no voxel detail to resolve.
    let cell = grid.size.iter().copied().fold(f64::INFINITY, f64::min);
    let uniform = medium.density.windows(2).all(|w| w[0] == w[1]);
    let step = opts.step_fraction.max(1e-3) * if uniform { cell } else { medium.voxel_size().min_element().min(cell) };
    let (w, h) = (camera.width, camera.height);
    let inv_range = range_scale(medium, opts.range_sigma);
    let pixels: Vec<(Rgb, Rgb)> = (0..w * h)
        .into_par_iter()
        .map(|n| {
            let (x, y) = (n % w, n / w);
            let dir = camera.pixel_dir(x, y);
            let far = surface_distance.map_or(f64::INFINITY, |s| s[n]);
            let mut radiance = [0.0; 3];
            let mut trans = [1.0; 3];
            let Some((t0, t1)) = clip(medium.min, medium.max, camera.position, dir) else {
                return (radiance, trans);
            };
            let t1 = t1.min(far);
            if t1 <= t0 {
                return (radiance, trans);
            }
            let steps = ((t1 - t0) / step).ceil().max(1.0) as usize;
            let dt = (t1 - t0) / steps as f64;
            for s in 0..steps {
                let p = camera.position + dir * (t0 + (s as f64 + 0.5) * dt);
                let rho = medium.density_at(p);
                if rho <= 0.0 {
                    continue;
                }
                let j = upsample(grid, toward_eye, medium, p, inv_range);
                let mut extra = [0.0; 3];
                if !sources.is_empty() {
                    let a = camera.position + dir * (t0 + s as f64 * dt);
                    let b = camera.position + dir * (t0 + (s + 1) as f64 * dt);
                    let sigma_t =
                        [0, 1, 2].map(|c| rho * (medium.coefficients.sigma_s[c] + medium.coefficients.sigma_a[c]));
                    for src in sources {
                        let e = src.step_integral(a, b, sigma_t);
                        for c in 0..3 {
                            extra[c] += e[c];
                        }
                    }
                }
                for c in 0..3 {
                    let ss = rho * medium.coefficients.sigma_s[c];
                    let st = ss + rho * medium.coefficients.sigma_a[c];
                    if st <= 0.0 {
                        continue;
                    }
                    // ∫ T σ_s J over the step for constant coefficients, without cancellation.
                    let absorbed = extinguished(st, dt);
                    radiance[c] += trans[c] * (absorbed * (ss / st) * j[c] + ss * extra[c]);
                    trans[c] *= 1.0 - absorbed;
                }
            }
            (radiance, trans)
        })
        .collect();
    let (radiance, transmittance) = pixels.into_iter().unzip();
    Frame { width: w, height: h, radiance, transmittance }
}
