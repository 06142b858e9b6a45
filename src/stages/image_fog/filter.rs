//! Hierarchical spatially varying Gaussian filtering (iser2018 Sec. 4.2–4.3, after Elek et al. 2013).
//!
//! **Input → output.** A scattered image `L_sc` and a per-pixel spread `W` \[pixels\] → the filtered
//! image `L'_sc` (each pixel read from the MIP level whose blur matches its `W`) and the chosen
//! fractional level per pixel.
//!
//! - **MIP chain** (Sec. 4.2): `L^[k] = (M^[k] · L^[k−1]) * G`, down-sampled by 2, with the separable
//!   4-tap kernel `G = {0.13, 0.37, 0.37, 0.13}` and clamp-to-edge borders (weights sum to 1, so a
//!   constant image stays constant). Per axis a level-`k` texel spreads a level-0 impulse with variance
//!   `0.77·(4^k − 1)/3` pixels² (`0.77 = Σ w_i x_i²` of the taps at ±0.5, ±1.5).
//! - **Reconstruction** ("linear-bicubic"): cubic B-spline in space (the Sigg–Hadwiger filter the paper
//!   uses; adds `4^k/3` pixels²), linear between two levels. [`Interpolation::Nearest`] (ablation):
//!   nearest level, nearest texel (adds `4^k/12`).
//! - **Level selection**: [`LevelRule::VarianceMatched`] (default) picks the two levels whose total
//!   per-axis variances `V_a ≤ W² < V_{a+1}` bracket `W²` and blends them with weight
//!   `(W² − V_a)/(V_{a+1} − V_a)`, so the blur's second moment is exactly `W²`.
//!   [`LevelRule::Paper`] is the paper's `k = clamp(log2(W/c), 0, K)` with linear blending: with the
//!   B-spline reconstruction level `k` blurs by `sqrt(V_k) ≈ 0.77·2^k`, so with `c = 0.86` the blur is
//!   about `0.9 W` (the text's `W ≈ c·2^{k−1}` is one level off from its own formula; the formula is
//!   the one that fits). `W` beyond the last level clamps to level `K`.
//! - **Spread-space chain** (Sec. 4.3): `W^[k] = ((Y·W^[k−1]) * U)/(Y * U)` with the luminance `Y`.
//!   Here numerator and denominator are carried as separate chains through the colour chain's own
//!   4-tap kernel (instead of a 2×2 box `U`; `Y^[k]` is then exactly the luminance of the unmasked
//!   `L^[k]`) and are also interpolated separately when read, so wherever `L^[k]` holds light the
//!   spread of that light is known (with a box, or interpolating the ratio, texels next to a bright
//!   pixel's blurred light take the background's spread and read that light at the wrong level).
//!   Plain Gaussian mean of `W` where `Y = 0`. Or the Gaussian chain
//!   `W^[k] = W^[k−1] * G` ([`SpreadChain::Gaussian`], the paper's "density blurring" applied to `W`,
//!   a monotone function of `P`). With `blur_level` the level is re-selected from the chain read at the
//!   pixel's own level: `k' = k(W^[k(W)])`.
//! - **Masking** (Sec. 4.3): `M^[k] = smoothstep(σ_{k−1}/(1+ε), σ_{k−1}, W^[k−1])` with `σ_{k−1}` the
//!   blur of level `k−1` (`sqrt(V_{k−1})`): a pixel is fully present in every level it reads, and
//!   pixels with a small spread are kept out of coarser levels (less illumination leaking).

use rayon::prelude::*;

use super::{FogOptions, Interpolation, LevelRule, SpreadChain};
use crate::render::{Image, RgbImage};

/// The 4-tap kernel of Sec. 4.2.
pub const TAPS: [f32; 4] = [0.13, 0.37, 0.37, 0.13];

/// Per-axis variance \[level-(k−1) texels²\] one down-sampling step adds (`Σ w_i x_i²`).
pub fn tap_variance() -> f64 {
    let x = [-1.5, -0.5, 0.5, 1.5];
    (0..4).map(|i| TAPS[i] as f64 * x[i] * x[i]).sum()
}

/// One MIP level: colour and spread chain.
#[derive(Debug, Clone)]
pub struct MipLevel {
    /// Texels per row.
    pub width: usize,
    /// Rows.
    pub height: usize,
    /// `L^[k]`, row-major.
    pub rgb: Vec<[f32; 3]>,
    /// Spread chain per texel: `(Y·W, Y, W)` through the 4-tap chain; `W^[k] = (Y·W)/Y`, or the plain
    /// `W` where `Y = 0` ([`spread_of`]). `Y` is level 0's luminance (or 1 for the Gaussian chain).
    pub spread: Vec<[f32; 3]>,
}

/// The MIP chains of one frame and the per-axis blur variance of each level.
#[derive(Debug, Clone)]
pub struct MipChain {
    /// Levels `0..=K` (level 0 is the input).
    pub levels: Vec<MipLevel>,
    /// `V_k` \[pixels²\]: per-axis variance of an impulse read back from level `k` (`V_0 = 0`).
    pub variances: Vec<f64>,
}

/// Filtered image and the chosen level per pixel.
#[derive(Debug, Clone)]
pub struct Filtered {
    /// `L'_sc`.
    pub image: RgbImage,
    /// Fractional level per pixel.
    pub level: Image<f32>,
}

/// `K` for an image: the level where the chain reaches 1×1 (`⌈log2 max(w, h)⌉`), or `opts.levels`
/// when smaller.
pub fn level_count(width: usize, height: usize, opts: &FogOptions) -> usize {
    let side = width.max(height).max(1);
    let mut k = 0;
    while (1usize << k) < side {
        k += 1;
    }
    opts.levels.map_or(k, |l| l.min(k))
}

/// `V_0..=V_K` for the reconstruction in `opts` (see the module doc).
pub fn level_variances(k_max: usize, interpolation: Interpolation) -> Vec<f64> {
    let tv = tap_variance();
    let recon = match interpolation {
        Interpolation::LinearBicubic => 1.0 / 3.0,
        Interpolation::Nearest => 1.0 / 12.0,
    };
    (0..=k_max)
        .map(|k| {
            if k == 0 {
                0.0
            } else {
                let p = 4f64.powi(k as i32);
                tv * (p - 1.0) / 3.0 + recon * p
            }
        })
        .collect()
}

/// Fractional level for spread `w` \[pixels\]: `(a, f)` = read level `a` with weight `1 − f` and
/// `a + 1` with weight `f` (`f = 0` at `a = K`).
pub fn select_level(w: f32, variances: &[f64], opts: &FogOptions) -> (usize, f32) {
    let k_max = variances.len() - 1;
    let w = if w.is_nan() { 0.0 } else { w.max(0.0) as f64 };
    if w == 0.0 || k_max == 0 {
        return (0, 0.0);
    }
    let (a, f) = match opts.level_rule {
        LevelRule::VarianceMatched => {
            let w2 = w * w;
            if w2 >= variances[k_max] {
                (k_max, 0.0)
            } else {
                let a = variances.iter().rposition(|&v| v <= w2).unwrap_or(0);
                (a, (w2 - variances[a]) / (variances[a + 1] - variances[a]))
            }
        }
        LevelRule::Paper => {
            let l = (w / opts.c).log2().clamp(0.0, k_max as f64);
            let a = (l.floor() as usize).min(k_max);
            (a, if a == k_max { 0.0 } else { l - a as f64 })
        }
    };
    match opts.interpolation {
        Interpolation::LinearBicubic => (a, f as f32),
        Interpolation::Nearest => {
            if f >= 0.5 && a < k_max {
                (a + 1, 0.0)
            } else {
                (a, 0.0)
            }
        }
    }
}

fn smoothstep(e0: f64, e1: f64, x: f64) -> f64 {
    if e1 <= e0 {
        return if x >= e1 { 1.0 } else { 0.0 };
    }
    let t = ((x - e0) / (e1 - e0)).clamp(0.0, 1.0);
    t * t * (3.0 - 2.0 * t)
}

/// Clamp-to-edge 4-tap down-sampling of a `w × h` buffer of `N` floats per texel.
fn downsample<const N: usize>(src: &[[f32; N]], w: usize, h: usize) -> (Vec<[f32; N]>, usize, usize) {
    let nw = w.div_ceil(2).max(1);
    let nh = h.div_ceil(2).max(1);
    let clamp = |i: isize, n: usize| i.clamp(0, n as isize - 1) as usize;
    // Horizontal pass: w → nw, h rows.
    let mut tmp = vec![[0.0f32; N]; nw * h];
    tmp.par_chunks_mut(nw).enumerate().for_each(|(y, row)| {
        let s = &src[y * w..(y + 1) * w];
        for (i, out) in row.iter_mut().enumerate() {
            let mut acc = [0.0f32; N];
            for (t, &wt) in TAPS.iter().enumerate() {
                let v = s[clamp(2 * i as isize - 1 + t as isize, w)];
                for c in 0..N {
                    acc[c] += wt * v[c];
                }
            }
            *out = acc;
        }
    });
    // Vertical pass: h → nh.
    let mut dst = vec![[0.0f32; N]; nw * nh];
    dst.par_chunks_mut(nw).enumerate().for_each(|(j, row)| {
        let rows = [0, 1, 2, 3].map(|t| clamp(2 * j as isize - 1 + t as isize, h));
        for (i, out) in row.iter_mut().enumerate() {
            let mut acc = [0.0f32; N];
            for (t, &wt) in TAPS.iter().enumerate() {
                let v = tmp[rows[t] * nw + i];
                for c in 0..N {
                    acc[c] += wt * v[c];
                }
            }
            *out = acc;
        }
    });
    (dst, nw, nh)
}

/// `W` from a spread-chain texel `(Y·W, Y, W)`: the luminance-weighted mean, or the plain mean where
/// no light is.
pub fn spread_of(v: [f32; 3]) -> f32 {
    if v[1] > 0.0 && (v[0] / v[1]).is_finite() { v[0] / v[1] } else { v[2] }
}

/// Builds `L^[0..K]` and `W^[0..K]` (module doc). `spread` must be finite and `≥ 0` (the caller
/// clamps it to the last level's blur).
pub fn build_chain(l: &RgbImage, spread: &Image<f32>, opts: &FogOptions) -> MipChain {
    let k_max = level_count(l.width, l.height, opts);
    let variances = level_variances(k_max, opts.interpolation);
    let s0: Vec<[f32; 3]> = l
        .data
        .par_iter()
        .zip(spread.data.par_iter())
        .map(|(c, &s)| {
            let y = match opts.spread_chain {
                SpreadChain::LuminanceWeighted => crate::render::color::luminance_f32(*c).max(0.0),
                SpreadChain::Gaussian => 1.0,
            };
            [y * s, y, s]
        })
        .collect();
    let mut levels = vec![MipLevel { width: l.width, height: l.height, rgb: l.data.clone(), spread: s0 }];
    for k in 1..=k_max {
        let prev = &levels[k - 1];
        let (w, h) = (prev.width, prev.height);
        // Masked colour (Sec. 4.3 masking).
        let hi = variances[k - 1].sqrt();
        let lo = hi / (1.0 + opts.mask_epsilon.max(0.0));
        let masked: Vec<[f32; 3]>;
        let src: &[[f32; 3]] = if opts.masking && hi > 0.0 {
            masked = prev
                .rgb
                .par_iter()
                .zip(prev.spread.par_iter())
                .map(|(c, &s)| {
                    let m = smoothstep(lo, hi, spread_of(s) as f64) as f32;
                    [c[0] * m, c[1] * m, c[2] * m]
                })
                .collect();
            &masked
        } else {
            &prev.rgb
        };
        let (rgb, nw, nh) = downsample(src, w, h);
        let spread = downsample(&prev.spread, w, h).0;
        levels.push(MipLevel { width: nw, height: nh, rgb, spread });
    }
    MipChain { levels, variances }
}

/// Per-axis reconstruction taps of one level: for each output coordinate, 4 texel indices and weights.
struct AxisTaps {
    idx: Vec<[u32; 4]>,
    wt: Vec<[f32; 4]>,
}

fn axis_taps(n_out: usize, n_level: usize, k: usize, interpolation: Interpolation) -> AxisTaps {
    let scale = (1u64 << k) as f64;
    let mut idx = Vec::with_capacity(n_out);
    let mut wt = Vec::with_capacity(n_out);
    let clamp = |i: i64| i.clamp(0, n_level as i64 - 1) as u32;
    for x in 0..n_out {
        let u = (x as f64 + 0.5) / scale - 0.5;
        match interpolation {
            Interpolation::LinearBicubic => {
                let i = u.floor();
                let t = u - i;
                let i = i as i64;
                let t2 = t * t;
                let t3 = t2 * t;
                let w0 = (1.0 - t).powi(3) / 6.0;
                let w1 = (3.0 * t3 - 6.0 * t2 + 4.0) / 6.0;
                let w2 = (-3.0 * t3 + 3.0 * t2 + 3.0 * t + 1.0) / 6.0;
                let w3 = t3 / 6.0;
                idx.push([clamp(i - 1), clamp(i), clamp(i + 1), clamp(i + 2)]);
                wt.push([w0 as f32, w1 as f32, w2 as f32, w3 as f32]);
            }
            Interpolation::Nearest => {
                let i = clamp((x >> k) as i64);
                idx.push([i; 4]);
                wt.push([1.0, 0.0, 0.0, 0.0]);
            }
        }
    }
    AxisTaps { idx, wt }
}

/// Reads a level at output pixel `(x, y)` through the separable taps.
fn sample<const N: usize>(
    data: &[[f32; N]],
    width: usize,
    tx: &AxisTaps,
    ty: &AxisTaps,
    x: usize,
    y: usize,
) -> [f32; N] {
    let mut acc = [0.0f32; N];
    let (xi, xw) = (&tx.idx[x], &tx.wt[x]);
    for (&yi, &yw) in ty.idx[y].iter().zip(ty.wt[y].iter()) {
        if yw == 0.0 {
            continue;
        }
        let row = &data[yi as usize * width..];
        let mut r = [0.0f32; N];
        for (&xi, &xw) in xi.iter().zip(xw.iter()) {
            let v = row[xi as usize];
            for c in 0..N {
                r[c] += xw * v[c];
            }
        }
        for c in 0..N {
            acc[c] += yw * r[c];
        }
    }
    acc
}

/// Clamps spreads to `[0, 2·σ_K]` (NaN → 0): beyond the last level every spread reads level `K`.
pub fn clamp_spread(spread: &Image<f32>, variances: &[f64]) -> Image<f32> {
    let cap = (2.0 * variances.last().copied().unwrap_or(0.0).sqrt()) as f32;
    Image {
        width: spread.width,
        height: spread.height,
        data: spread.data.iter().map(|&s| if s.is_nan() { 0.0 } else { s.clamp(0.0, cap) }).collect(),
    }
}

/// Reads the chain per pixel (module doc). With `spread_level = Some(k)` the level is selected from the
/// spread chain read at level `k` (clamped to `K`) instead of the pixel's own spread (the fetch of the
/// separated bright pixels, Sec. 4.3: `k' = k(P_ssc^[k_ssc])`).
pub fn fetch(chain: &MipChain, opts: &FogOptions, spread_level: Option<usize>) -> Filtered {
    let l0 = &chain.levels[0];
    let (w, h) = (l0.width, l0.height);
    let taps: Vec<(AxisTaps, AxisTaps)> = chain
        .levels
        .iter()
        .enumerate()
        .map(|(k, lv)| (axis_taps(w, lv.width, k, opts.interpolation), axis_taps(h, lv.height, k, opts.interpolation)))
        .collect();
    let read_spread = |k: usize, x: usize, y: usize| -> f32 {
        if k == 0 {
            return l0.spread[y * w + x][2];
        }
        let lv = &chain.levels[k];
        spread_of(sample(&lv.spread, lv.width, &taps[k].0, &taps[k].1, x, y))
    };
    let mut image = Image::filled(w, h, [0.0f32; 3]);
    let mut level = Image::filled(w, h, 0.0f32);
    image.data.par_chunks_mut(w).zip(level.data.par_chunks_mut(w)).enumerate().for_each(|(y, (row, lrow))| {
        for x in 0..w {
            let mut s = match spread_level {
                Some(k) => read_spread(k.min(chain.levels.len() - 1), x, y),
                None => l0.spread[y * w + x][2],
            };
            let (mut a, mut f) = select_level(s, &chain.variances, opts);
            if spread_level.is_none() && opts.blur_level && (a > 0 || f > 0.0) {
                let s_a = read_spread(a, x, y);
                s = if f > 0.0 { (1.0 - f) * s_a + f * read_spread(a + 1, x, y) } else { s_a };
                (a, f) = select_level(s, &chain.variances, opts);
            }
            let read = |k: usize| -> [f32; 3] {
                if k == 0 {
                    l0.rgb[y * w + x]
                } else {
                    let lv = &chain.levels[k];
                    let v = sample(&lv.rgb, lv.width, &taps[k].0, &taps[k].1, x, y);
                    v.map(|c| c.max(0.0))
                }
            };
            let va = read(a);
            row[x] = if f > 0.0 {
                let vb = read(a + 1);
                [0, 1, 2].map(|c| (1.0 - f) * va[c] + f * vb[c])
            } else {
                va
            };
            lrow[x] = a as f32 + f;
        }
    });
    Filtered { image, level }
}

/// The hierarchical filter on its own: `L_sc` and spreads \[pixels\] → `L'_sc` and levels. A spread of
/// 0 everywhere returns `l` exactly (level 0 is the input). Returns the chain and fetch times \[ms\].
pub fn filter(l: &RgbImage, spread: &Image<f32>, opts: &FogOptions) -> (Filtered, f64, f64) {
    let t0 = std::time::Instant::now();
    let k_max = level_count(l.width, l.height, opts);
    let variances = level_variances(k_max, opts.interpolation);
    let spread = clamp_spread(spread, &variances);
    let chain = build_chain(l, &spread, opts);
    let chain_ms = t0.elapsed().as_secs_f64() * 1e3;
    let t1 = std::time::Instant::now();
    let out = fetch(&chain, opts, None);
    (out, chain_ms, t1.elapsed().as_secs_f64() * 1e3)
}

/// The filter of the separated bright pixels (Sec. 4.3 "radiance separation"): a Gaussian chain
/// without masking, a luminance-weighted spread chain, and every pixel's level selected from that
/// chain read at level `k_ssc = ⌊0.7 K⌉`. Returns the filtered image and the chain and fetch times \[ms\].
pub fn filter_separated(l: &RgbImage, spread: &Image<f32>, opts: &FogOptions) -> (Filtered, f64, f64) {
    let t0 = std::time::Instant::now();
    let o = FogOptions { masking: false, spread_chain: SpreadChain::LuminanceWeighted, ..*opts };
    let k_max = level_count(l.width, l.height, &o);
    let variances = level_variances(k_max, o.interpolation);
    let spread = clamp_spread(spread, &variances);
    let chain = build_chain(l, &spread, &o);
    let chain_ms = t0.elapsed().as_secs_f64() * 1e3;
    let t1 = std::time::Instant::now();
    let k_ssc = (0.7 * k_max as f64).round() as usize;
    let out = fetch(&chain, &o, Some(k_ssc));
    (out, chain_ms, t1.elapsed().as_secs_f64() * 1e3)
}
