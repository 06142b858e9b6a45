//! Error of the point-based renderer against the path-traced reference, and error against run time
//! (wang2018 Sec. 6, Table 3, Fig. 23–24).
//!
//! **Input → output.** A point-based [`Frame`] and a [`ReferenceImage`] of the same view (with their
//! run times) → a [`Comparison`]; a quality ladder of both methods → [`Curve`]s of (ms, MSE).
//!
//! **Image normalisation.** Both images are divided by `s`, the mean of the reference's object-pixel
//! channel values: a converged statistic of the reference (its noise averages out over the object),
//! unlike its maximum or a percentile, which noise inflates and which would make every error look
//! smaller (issue 30). wang2018 reports MSE of displayed pictures without stating the scale. The MSE is
//! the mean of `(x − r)²/s²` over the object's pixels (where the primary ray hits the object first) and
//! the three channels.
//!
//! **Reference noise.** The reference's MSE against the truth at `n` paths per pixel is its mean
//! per-pixel variance of the mean, `v/n`; it is subtracted from the measured MSE (`mse_corrected`, the
//! expected MSE against the noise-free image). [`NoiseCorrected`] states the same error as a relative
//! RMSE with its floor (the smallest error the comparison tells from zero) and 95 % interval; below the
//! floor the report reads "< floor X". The reference's MSE-vs-time line: at equal MSE `e` the reference
//! needs `n_e = v₁/e` paths per pixel (`v₁` = per-path variance), i.e. `reference_ms · n_e / n`. When
//! the point-based error is below the floor the speed-up is a lower bound (`e` = the floor's square).
//!
//! **Block scale.** A few hundred paths per pixel leave the reference's per-pixel noise above the error
//! (a point light seen through a refractive boundary is reached by chance only), so the error is also
//! stated over means of [`BLOCK`] × [`BLOCK`]-pixel blocks (the object's pixels in each block; the
//! variance of a block mean is the sum of its pixels' variances over the count squared), the scale
//! `voltab validate` compares at: 16× less noise per item and 16× fewer items, so a floor half as large
//! for even noise and lower still when a few pixels hold most of it (measured on the default pipeline:
//! Wax 112 → 36 %, Oil 78 → 21 %, Skin 19 → 13 %).

use serde::{Deserialize, Serialize};

use super::render::Frame;
use crate::reference::translucent::ReferenceImage;
use crate::report::noisy::NoiseCorrected;

/// The point-based frame against the reference.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Comparison {
    /// Image size.
    pub size: [usize; 2],
    /// Object pixels compared.
    pub object_pixels: usize,
    /// Reference paths per pixel.
    pub samples: u32,
    /// Normalisation `s` \[W/(m²·sr)\] (module doc).
    pub scale: f64,
    /// MSE of the full image over the object's pixels (normalised).
    pub mse: f64,
    /// The reference's own noise in the same units (mean variance of its mean).
    pub reference_noise: f64,
    /// `max(mse − reference_noise, 0)`.
    pub mse_corrected: f64,
    /// The same error as a noise-corrected relative RMSE with its floor and interval (`None` when the
    /// reference is black on the object).
    pub error: Option<NoiseCorrected>,
    /// The same over [`BLOCK`] × [`BLOCK`]-pixel block means of the object's pixels (module doc).
    pub block_error: Option<NoiseCorrected>,
    /// Per component against the reference's paths with the same number of medium events: single vs
    /// one, double vs two, multiple + bounced vs three or more, rest vs none (normalised MSE, noise not
    /// removed).
    pub mse_components: [f64; 4],
    /// Point-based time (pre-processing and frame) \[ms\].
    pub point_ms: f64,
    /// Reference time \[ms\].
    pub reference_ms: f64,
    /// Reference time to reach `mse_corrected` \[ms\].
    pub equal_mse_reference_ms: f64,
    /// `equal_mse_reference_ms / point_ms`.
    pub speedup: f64,
    /// The point-based error is below the floor: the speed-up is a lower bound.
    pub lower_bound: bool,
}

/// RGB values per item.
type Rgbs = Vec<[f64; 3]>;

/// Side of the blocks of the block-scale error \[px\].
pub const BLOCK: usize = 4;

/// Means over `BLOCK` × `BLOCK` blocks of the masked pixels of a `width`-wide image: (method, reference,
/// variance of the reference's block mean) per block holding at least one masked pixel.
fn block_means(a: &[[f64; 3]], r: &[[f64; 3]], var: &[[f64; 3]], mask: &[bool], width: usize) -> (Rgbs, Rgbs, Rgbs) {
    let height = mask.len() / width.max(1);
    let (bw, bh) = (width.div_ceil(BLOCK), height.div_ceil(BLOCK));
    let mut acc = vec![([0.0; 3], [0.0; 3], [0.0; 3], 0usize); bw * bh];
    for (i, _) in mask.iter().enumerate().filter(|(_, m)| **m) {
        let b = &mut acc[(i / width / BLOCK) * bw + (i % width) / BLOCK];
        for c in 0..3 {
            b.0[c] += a[i][c];
            b.1[c] += r[i][c];
            b.2[c] += var[i][c];
        }
        b.3 += 1;
    }
    let kept: Vec<_> = acc.into_iter().filter(|b| b.3 > 0).collect();
    let k = |b: &([f64; 3], [f64; 3], [f64; 3], usize)| b.3 as f64;
    (
        kept.iter().map(|b| b.0.map(|x| x / k(b))).collect(),
        kept.iter().map(|b| b.1.map(|x| x / k(b))).collect(),
        kept.iter().map(|b| b.2.map(|x| x / (k(b) * k(b)))).collect(),
    )
}

/// The normalisation `s` of the module doc: the mean of the reference's finite object-pixel channel
/// values (1 when the object is black or absent).
pub fn scale_of(reference: &ReferenceImage) -> f64 {
    let (sum, n) = reference
        .total()
        .iter()
        .zip(&reference.object)
        .filter(|(_, o)| **o)
        .flat_map(|(p, _)| p.iter().copied())
        .filter(|x| x.is_finite())
        .fold((0.0, 0usize), |(s, n), x| (s + x, n + 1));
    let s = if n > 0 { sum / n as f64 } else { 0.0 };
    if s > 0.0 { s } else { 1.0 }
}

/// Normalised MSE of `a` against `b` over the masked pixels.
fn mse(a: &[[f64; 3]], b: &[[f64; 3]], mask: &[bool], scale: f64) -> f64 {
    let (mut sum, mut n) = (0.0, 0usize);
    for ((x, y), m) in a.iter().zip(b).zip(mask) {
        if *m {
            for c in 0..3 {
                let d = (x[c] - y[c]) / scale;
                sum += d * d;
            }
            n += 3;
        }
    }
    if n == 0 { 0.0 } else { sum / n as f64 }
}

/// Mean normalised variance of the reference's mean over the masked pixels.
pub fn noise(reference: &ReferenceImage, mask: &[bool], scale: f64) -> f64 {
    let (mut sum, mut n) = (0.0, 0usize);
    for (v, m) in reference.variance.iter().zip(mask) {
        if *m {
            sum += v.iter().sum::<f64>() / (scale * scale);
            n += 3;
        }
    }
    if n == 0 { 0.0 } else { sum / n as f64 }
}

/// Compares a frame with the reference of the same view (module doc).
pub fn compare(frame: &Frame, point_ms: f64, reference: &ReferenceImage, reference_ms: f64) -> Comparison {
    let scale = scale_of(reference);
    let mask = &reference.object;
    let measured = mse(&frame.total(), &reference.total(), mask, scale);
    let ref_noise = noise(reference, mask, scale);
    let corrected = (measured - ref_noise).max(0.0);
    let multiple: Vec<[f64; 3]> =
        frame.multiple.iter().zip(&frame.bounced).map(|(m, b)| std::array::from_fn(|c| m[c] + b[c])).collect();
    let c = &reference.components;
    let mse_components = [
        mse(&frame.single, &c[1], mask, scale),
        mse(&frame.double, &c[2], mask, scale),
        mse(&multiple, &c[3], mask, scale),
        mse(&frame.rest, &c[0], mask, scale),
    ];
    let samples = (reference.paths / (reference.width * reference.height).max(1) as u64).max(1) as u32;
    let (total, ref_total) = (frame.total(), reference.total());
    let error = NoiseCorrected::of_rgb_masked(&total, &ref_total, &reference.variance, mask).ok();
    let (ba, br, bv) = block_means(&total, &ref_total, &reference.variance, mask, reference.width);
    let block_error = NoiseCorrected::of_rgb(&ba, &br, &bv).ok();
    // Per-path variance v₁ = noise · n; paths needed for MSE e: v₁/e, with e no smaller than the floor's
    // square (below it only a lower bound is claimed).
    let per_path = ref_noise * samples as f64;
    let lower_bound = error.is_none_or(|e| e.below_floor());
    let target = match error {
        Some(e) if lower_bound => e.floor * e.floor,
        _ => corrected,
    };
    let n_eq = if target > 0.0 { per_path / target } else { samples as f64 };
    let equal_ms = reference_ms * n_eq / samples as f64;
    Comparison {
        size: [reference.width, reference.height],
        object_pixels: mask.iter().filter(|m| **m).count(),
        samples,
        scale,
        mse: measured,
        reference_noise: ref_noise,
        mse_corrected: corrected,
        error,
        block_error,
        mse_components,
        point_ms,
        reference_ms,
        equal_mse_reference_ms: equal_ms,
        speedup: equal_ms / point_ms.max(1e-9),
        lower_bound,
    }
}

impl Comparison {
    /// Report wording: the relative RMSE with its interval and floor (or "< floor X"), the reference's
    /// noise, and the speed-up at equal MSE ("≥" when the error is below the floor).
    pub fn describe(&self) -> String {
        let err = self.error.map_or_else(|| "the reference is black on the object".into(), |e| e.percent());
        let blocks =
            self.block_error.map_or_else(String::new, |e| format!(" ({BLOCK}×{BLOCK} blocks: {})", e.percent()));
        format!(
            "relative RMSE {err}{blocks}, reference noise {:.1} % ({} paths/px), {}{}× faster at equal MSE",
            100.0 * self.reference_noise.sqrt(),
            self.samples,
            if self.lower_bound { "≥ " } else { "" },
            match self.speedup {
                x if x >= 10.0 => format!("{x:.0}"),
                x if x >= 1.0 => format!("{x:.1}"),
                x => format!("{x:.2}"),
            }
        )
    }
}

/// One method's error against run time.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Curve {
    /// Method and material.
    pub name: String,
    /// (setting, ms, normalised MSE against the converged reference with its noise removed, below the
    /// floor: then the MSE is the floor's square, an upper bound).
    pub points: Vec<(String, f64, f64, bool)>,
}

#[cfg(test)]
mod tests;
