//! The gathering filter: the filtering reference of iser2018 Sec. 4.2 (Fig. 5f).
//!
//! **Input → output.** The scattered image `L_sc` and the per-pixel spread `W` \[pixels\] (the same
//! buffers the hierarchical filter reads, see [`super::prepare`]) → for each requested pixel `x`
//! `L'_sc(x) = Σ_y L_sc(y) · g_{W(y)}(x − y)`: every source pixel spreads its radiance with its own
//! normalised Gaussian (energy-conserving splatting, evaluated by gathering).
//!
//! Conventions, chosen so the comparison isolates the filtering approximation:
//! - `W(y)` is clamped to the blur of the last MIP level `sqrt(V_K)` (the hierarchical filter cannot
//!   blur wider either);
//! - sources outside the image are its clamp-to-edge extension (the MIP chain's border rule), so a
//!   constant image stays constant;
//! - `g_W` is the discrete Gaussian `e^{−|d|²/(2W²)}` normalised over the whole lattice
//!   (`Z = (Σ_i e^{−i²/(2W²)})²`, by Poisson summation for `W ≥ 0.5`) and truncated at `|d_x|, |d_y| ≤
//!   ⌈4W⌉` (the mass lost is below 2e-4); `W = 0` is a delta.
//!
//! Cost: `O((8 W_max)²)` per pixel, which is why the benchmark times a subset of pixels.

use rayon::prelude::*;

use crate::render::{Image, RgbImage};

/// `Σ_{i∈ℤ} e^{−i²/(2W²)}` (1-D lattice normalisation of the discrete Gaussian).
pub fn lattice_norm(w: f64) -> f64 {
    if w.is_nan() || w <= 0.0 {
        return 1.0;
    }
    if w >= 0.5 {
        // Poisson summation: √(2π) W (1 + 2 Σ_m e^{−2π² m² W²}); m ≤ 3 is exact to f64 for W ≥ 0.5.
        let s: f64 = (1..=3).map(|m| (-2.0 * std::f64::consts::PI.powi(2) * (m * m) as f64 * w * w).exp()).sum();
        (2.0 * std::f64::consts::PI).sqrt() * w * (1.0 + 2.0 * s)
    } else {
        let a = 1.0 / (2.0 * w * w);
        1.0 + 2.0 * (1..=8).map(|i| (-a * (i * i) as f64).exp()).sum::<f64>()
    }
}

/// Gathers `L'_sc` at `pixels` (module doc). `spread_cap` is the largest spread honoured (`sqrt(V_K)`).
pub fn gather_pixels(
    l_sc: &RgbImage,
    spread: &Image<f32>,
    spread_cap: f64,
    pixels: &[(usize, usize)],
) -> Vec<[f32; 3]> {
    let (w, h) = (l_sc.width, l_sc.height);
    // Per source: 1/(2W²), 1/Z², truncation radius.
    struct Src {
        a: f64,
        inv_z: f64,
        r: i64,
    }
    let src: Vec<Src> = spread
        .data
        .par_iter()
        .map(|&s| {
            let s = if s.is_nan() { 0.0 } else { (s as f64).clamp(0.0, spread_cap) };
            if s == 0.0 {
                Src { a: 0.0, inv_z: 1.0, r: 0 }
            } else {
                let z = lattice_norm(s);
                Src { a: 1.0 / (2.0 * s * s), inv_z: 1.0 / (z * z), r: (4.0 * s).ceil() as i64 }
            }
        })
        .collect();
    let r_max = src.iter().map(|s| s.r).max().unwrap_or(0);
    let clamp = |i: i64, n: usize| i.clamp(0, n as i64 - 1) as usize;
    pixels
        .par_iter()
        .map(|&(x, y)| {
            let (x, y) = (x as i64, y as i64);
            let mut acc = [0.0f64; 3];
            for sy in (y - r_max)..=(y + r_max) {
                let cy = clamp(sy, h);
                let dy = sy - y;
                for sx in (x - r_max)..=(x + r_max) {
                    let idx = cy * w + clamp(sx, w);
                    let s = &src[idx];
                    let dx = sx - x;
                    if dx.abs() > s.r || dy.abs() > s.r {
                        continue;
                    }
                    let c = l_sc.data[idx];
                    if c == [0.0; 3] {
                        continue;
                    }
                    let g = if s.r == 0 { 1.0 } else { (-(dx * dx + dy * dy) as f64 * s.a).exp() * s.inv_z };
                    for k in 0..3 {
                        acc[k] += g * c[k] as f64;
                    }
                }
            }
            acc.map(|v| v as f32)
        })
        .collect()
}

/// Gathers the whole image, or only `region = (x0, y0, x1, y1)` (half-open, clipped to the image);
/// pixels outside the region are 0.
pub fn gather_image(
    l_sc: &RgbImage,
    spread: &Image<f32>,
    spread_cap: f64,
    region: Option<(usize, usize, usize, usize)>,
) -> RgbImage {
    let (x0, y0, x1, y1) = region.unwrap_or((0, 0, l_sc.width, l_sc.height));
    let (x1, y1) = (x1.min(l_sc.width), y1.min(l_sc.height));
    let pixels: Vec<(usize, usize)> = (y0..y1).flat_map(|y| (x0..x1).map(move |x| (x, y))).collect();
    let vals = gather_pixels(l_sc, spread, spread_cap, &pixels);
    let mut out = Image::filled(l_sc.width, l_sc.height, [0.0f32; 3]);
    for (&(x, y), v) in pixels.iter().zip(vals) {
        out.data[y * l_sc.width + x] = v;
    }
    out
}

/// Pixel centres of an `nx × ny` stratified grid over a `w × h` image (cell centres, rounded down).
pub fn grid_pixels(w: usize, h: usize, nx: usize, ny: usize) -> Vec<(usize, usize)> {
    (0..ny).flat_map(|j| (0..nx).map(move |i| ((2 * i + 1) * w / (2 * nx), (2 * j + 1) * h / (2 * ny)))).collect()
}
