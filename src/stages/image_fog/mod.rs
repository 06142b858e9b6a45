//! iser2018: analytic quasi-heterogeneous fog with hierarchical image-space filtering of multiple
//! scattering (Iser & Elek, CESCG 2018, after Elek et al. 2013).
//!
//! **Input → output.** An HDR colour image `L`, the distance buffer `D` (metres along each pixel's unit
//! ray, `∞` for sky), a [`ViewCamera`] and an analytic [`FogMedium`] → the fogged image
//! `L' = L_at + L'_sc` (Sec. 4.4) with its parts and per-phase timings ([`render`]).
//!
//! Pipeline (Fig. 4):
//! 1. [`prepare`] (Sec. 3.3, 4.1, module [`medium`]): per pixel the density integrals `P_i`, optical
//!    depths, `L_at = e^{−τ_t} L` and `L_sc = e^{−τ_a}(1 − e^{−τ_s}) L` per channel, and the spread
//!    `W` in pixels (Eq. 1 at the density-scaled length of Eq. 3, seen as an angle from the camera).
//! 2. MIP chains and level selection (Sec. 4.2–4.3, module [`filter`]).
//! 3. Compose `L' = L_at + L'_sc`.
//!
//! The gathering filter ([`gather`](fn@gather), module [`gather`](mod@gather)) is the filtering reference;
//! [`bench`](mod@bench) measures both on the bundled outdoor scene.
//!
//! **Attenuation-only baseline.** [`FogOutput::attenuated`] is `L_at = T·L` alone: the paper has no
//! in-scattering from light sources or ambient term (Sec. 6.2 leaves the ambient term to future
//! work), so attenuation-only fog is the same image with the scattered light dropped. Note
//! `L_at + L_sc = e^{−τ_a} L`: the method moves the scattered fraction around but never creates light.
//!
//! **Bright-pixel separation** (Sec. 4.3) is optional ([`FogOptions::separation`], off by default).
//!
//! **Robustness.** `D ≤ 0` or NaN means no fog on that pixel; `D = ∞` uses the integral to infinity
//! (`T = 0` in homogeneous fog, finite for fog thinning upward); non-finite colours are read as 0
//! (NaN, −∞) or `f32::MAX` (+∞); spreads beyond the last level read level `K`. No output is NaN/Inf
//! for finite inputs.

mod stage;
pub use stage::*;
#[cfg(feature = "gpu")]
pub mod gpu;
#[cfg(feature = "gpu")]
pub mod shaders;

pub mod bench;
pub mod filter;
pub mod gather;
pub mod medium;
#[cfg(test)]
mod tests;

use std::time::Instant;

use rayon::prelude::*;

use crate::render::{DistanceImage, Image, RgbImage, ViewCamera};
pub use medium::{FogComponent, FogMedium, PixelFog, spread_angle, spread_width};

/// How the fractional MIP level is chosen from the spread (see [`filter`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LevelRule {
    /// Blend the two levels whose blur variances bracket `W²` so the second moment is `W²` (default).
    VarianceMatched,
    /// The paper's `k = clamp(log2(W/c), 0, K)`, linear between levels.
    Paper,
}

/// Reconstruction from the MIP chain.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Interpolation {
    /// Linear between levels, bicubic (B-spline) within a level (the paper's recommended setting).
    LinearBicubic,
    /// Nearest level and nearest texel (ablation).
    Nearest,
}

/// How the spread-space chain `W^[k]` is built (see [`filter`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SpreadChain {
    /// Luminance-weighted 2×2 means (Elek et al., Sec. 4.3).
    LuminanceWeighted,
    /// The 4-tap Gaussian chain (the paper's density blurring, applied to `W`).
    Gaussian,
}

/// Bright-pixel separation (Sec. 4.3, optional): `M = smoothstep(T_y, T_y + ε_y, Y) · (1 −
/// smoothstep(T_w − ε_w, T_w, W))` selects bright pixels with a small spread; `L_ssc = M·L_sc` is
/// filtered by its own chain ([`filter::filter_separated`]) and `L_sc` keeps `(1 − M)·L_sc`.
/// (The paper thresholds the density `P`; the spread `W` is a monotone function of it per medium and
/// also covers sums of components.)
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Separation {
    /// Luminance threshold `T_y` of `L_sc` \[W/(m²·sr)\].
    pub luminance: f64,
    /// Luminance ramp width `ε_y`.
    pub luminance_width: f64,
    /// Spread threshold `T_w` \[pixels\]: pixels spreading less are separated.
    pub spread: f64,
    /// Spread ramp width `ε_w` \[pixels\].
    pub spread_width: f64,
}

impl Default for Separation {
    fn default() -> Self {
        Separation { luminance: 10.0, luminance_width: 10.0, spread: 8.0, spread_width: 4.0 }
    }
}

/// Options of the hierarchical filter.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FogOptions {
    /// Number of MIP levels `K` above level 0; `None`: down to 1×1.
    pub levels: Option<usize>,
    /// The scaling constant `c` of the paper's level rule (0.86).
    pub c: f64,
    /// Level selection.
    pub level_rule: LevelRule,
    /// Reconstruction.
    pub interpolation: Interpolation,
    /// Spread-space chain.
    pub spread_chain: SpreadChain,
    /// Re-select the level from the spread chain read at the pixel's own level (`k' = k(W^[k(W)])`).
    pub blur_level: bool,
    /// Mask small-spread pixels out of coarser levels (Sec. 4.3).
    pub masking: bool,
    /// Mask width `ε` (2 in the paper).
    pub mask_epsilon: f64,
    /// Filter the scattered light; `false`: `L'_sc = L_sc` (no spreading, for ablation).
    pub scattering: bool,
    /// Bright-pixel separation; `None` (default): off.
    pub separation: Option<Separation>,
}

impl Default for FogOptions {
    fn default() -> Self {
        FogOptions {
            levels: None,
            c: 0.86,
            level_rule: LevelRule::VarianceMatched,
            interpolation: Interpolation::LinearBicubic,
            spread_chain: SpreadChain::LuminanceWeighted,
            blur_level: true,
            masking: true,
            mask_epsilon: 2.0,
            scattering: true,
            separation: None,
        }
    }
}

/// Per-phase wall-clock times of one [`render`] \[ms\].
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct FogStats {
    /// Density integrals, `L_at`, `L_sc`, `W`.
    pub integrals_ms: f64,
    /// MIP chains.
    pub mip_ms: f64,
    /// Level selection, interpolation and compositing.
    pub filter_ms: f64,
}

impl FogStats {
    /// Sum of the phases.
    pub fn total_ms(&self) -> f64 {
        self.integrals_ms + self.mip_ms + self.filter_ms
    }
}

/// Result of [`render`].
#[derive(Debug, Clone)]
pub struct FogOutput {
    /// `L' = L_at + L'_sc`.
    pub image: RgbImage,
    /// Attenuation-only fog `L_at = T·L` (module doc).
    pub attenuated: RgbImage,
    /// The filtered multiple-scattering contribution `L'_sc`.
    pub scattered: RgbImage,
    /// Fractional MIP level read per pixel.
    pub level: Image<f32>,
    /// Spread `W` per pixel \[pixels\] (before clamping to the last level).
    pub spread: Image<f32>,
    /// Timings.
    pub stats: FogStats,
}

/// The per-pixel buffers of Sec. 4.1.
#[derive(Debug, Clone)]
pub struct Prepared {
    /// `L_at = e^{−τ_t} L`.
    pub attenuated: RgbImage,
    /// `L_sc = e^{−τ_a}(1 − e^{−τ_s}) L`.
    pub scattered: RgbImage,
    /// Spread `W` \[pixels\].
    pub spread: Image<f32>,
}

/// Focal length in pixels: `height / (2 tan(yfov/2))`.
pub fn focal_px(cam: &ViewCamera) -> f64 {
    cam.height as f64 / (2.0 * cam.tan_half_y)
}

fn sanitize(c: f32) -> f32 {
    if c.is_nan() { 0.0 } else { c.clamp(0.0, f32::MAX) }
}

/// Phase 1 (Sec. 3.3, 4.1): integrals, `L_at`, `L_sc` and `W` per pixel, rows in parallel.
/// `colour` and `distance` must have the camera's size (panics otherwise).
pub fn prepare(cam: &ViewCamera, colour: &RgbImage, distance: &DistanceImage, medium: &FogMedium) -> Prepared {
    let (w, h) = (cam.width, cam.height);
    assert!(colour.width == w && colour.height == h && distance.width == w && distance.height == h, "buffer sizes");
    let f = focal_px(cam);
    let mut att = Image::filled(w, h, [0.0f32; 3]);
    let mut sc = Image::filled(w, h, [0.0f32; 3]);
    let mut spread = Image::filled(w, h, 0.0f32);
    att.data.par_chunks_mut(w).zip(sc.data.par_chunks_mut(w)).zip(spread.data.par_chunks_mut(w)).enumerate().for_each(
        |(y, ((ra, rs), rw))| {
            for x in 0..w {
                let l = colour.data[y * w + x].map(sanitize);
                let d = distance.data[y * w + x] as f64;
                let pf = medium.pixel_fog(cam.position, cam.pixel_dir(x, y), d);
                let (t, s) = pf.weights();
                ra[x] = [0, 1, 2].map(|c| (t[c] * l[c] as f64) as f32);
                rs[x] = [0, 1, 2].map(|c| (s[c] * l[c] as f64) as f32);
                rw[x] = pf.spread_px(f);
            }
        },
    );
    Prepared { attenuated: att, scattered: sc, spread }
}

/// The full method: `L' = L_at + L'_sc` (module doc) with per-phase timings.
pub fn render(
    cam: &ViewCamera,
    colour: &RgbImage,
    distance: &DistanceImage,
    medium: &FogMedium,
    opts: &FogOptions,
) -> FogOutput {
    let t0 = Instant::now();
    let p = prepare(cam, colour, distance, medium);
    let integrals_ms = t0.elapsed().as_secs_f64() * 1e3;
    let (filtered, mip_ms, fetch_ms) = if opts.scattering {
        match &opts.separation {
            None => filter::filter(&p.scattered, &p.spread, opts),
            Some(sep) => filter_with_separation(&p.scattered, &p.spread, sep, opts),
        }
    } else {
        let level = Image::filled(cam.width, cam.height, 0.0f32);
        (filter::Filtered { image: p.scattered.clone(), level }, 0.0, 0.0)
    };
    let t2 = Instant::now();
    let image = Image {
        width: cam.width,
        height: cam.height,
        data: p
            .attenuated
            .data
            .par_iter()
            .zip(filtered.image.data.par_iter())
            .map(|(a, s)| [0, 1, 2].map(|c| (a[c] + s[c]).min(f32::MAX)))
            .collect(),
    };
    let filter_ms = fetch_ms + t2.elapsed().as_secs_f64() * 1e3;
    FogOutput {
        image,
        attenuated: p.attenuated,
        scattered: filtered.image,
        level: filtered.level,
        spread: p.spread,
        stats: FogStats { integrals_ms, mip_ms, filter_ms },
    }
}

/// Splits `l_sc` into the separated bright pixels and the rest, filters both and adds them
/// (`L'_sc + L'_ssc`); the level image is the one of the non-separated part.
pub fn filter_with_separation(
    l_sc: &RgbImage,
    spread: &Image<f32>,
    sep: &Separation,
    opts: &FogOptions,
) -> (filter::Filtered, f64, f64) {
    let smooth = |e0: f64, e1: f64, x: f64| {
        let t = if e1 > e0 {
            ((x - e0) / (e1 - e0)).clamp(0.0, 1.0)
        } else if x >= e1 {
            1.0
        } else {
            0.0
        };
        t * t * (3.0 - 2.0 * t)
    };
    let t0 = Instant::now();
    let mask: Vec<f32> = l_sc
        .data
        .par_iter()
        .zip(spread.data.par_iter())
        .map(|(c, &w)| {
            let y = crate::render::color::luminance([c[0] as f64, c[1] as f64, c[2] as f64]);
            let m = smooth(sep.luminance, sep.luminance + sep.luminance_width, y)
                * (1.0 - smooth(sep.spread - sep.spread_width, sep.spread, w as f64));
            m as f32
        })
        .collect();
    let split = |keep: bool| Image {
        width: l_sc.width,
        height: l_sc.height,
        data: l_sc
            .data
            .iter()
            .zip(&mask)
            .map(|(c, &m)| {
                let k = if keep { m } else { 1.0 - m };
                c.map(|v| v * k)
            })
            .collect(),
    };
    let (bright, rest) = (split(true), split(false));
    let split_ms = t0.elapsed().as_secs_f64() * 1e3;
    let (a, chain_a, fetch_a) = filter::filter(&rest, spread, opts);
    if mask.iter().all(|&m| m == 0.0) {
        return (a, chain_a + split_ms, fetch_a);
    }
    let (b, chain_b, fetch_b) = filter::filter_separated(&bright, spread, opts);
    let image = Image {
        width: l_sc.width,
        height: l_sc.height,
        data: a
            .image
            .data
            .iter()
            .zip(&b.image.data)
            .map(|(x, y)| [0, 1, 2].map(|c| (x[c] + y[c]).min(f32::MAX)))
            .collect(),
    };
    (filter::Filtered { image, level: a.level }, split_ms + chain_a + chain_b, fetch_a + fetch_b)
}

/// The gathering reference (module [`gather`](mod@gather)): the scattered image `L'_sc` filtered with a
/// per-source Gaussian of width `W` (clamped to the last level's blur of `opts`), for the whole image
/// or only `region = (x0, y0, x1, y1)` (half-open; other pixels are 0). Compare with
/// [`FogOutput::scattered`].
pub fn gather(
    cam: &ViewCamera,
    colour: &RgbImage,
    distance: &DistanceImage,
    medium: &FogMedium,
    opts: &FogOptions,
    region: Option<(usize, usize, usize, usize)>,
) -> RgbImage {
    let p = prepare(cam, colour, distance, medium);
    gather::gather_image(&p.scattered, &p.spread, spread_cap(cam.width, cam.height, opts), region)
}

/// The largest spread the hierarchical filter honours for this size: `sqrt(V_K)` \[pixels\].
pub fn spread_cap(width: usize, height: usize, opts: &FogOptions) -> f64 {
    let k = filter::level_count(width, height, opts);
    filter::level_variances(k, opts.interpolation)[k].sqrt()
}
