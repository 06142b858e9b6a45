//! Errors against a noisy reference that cannot flatter (issue 30): the one statistic every stage's
//! internal comparison reports, the same one `voltab validate`'s harness computes against Mitsuba
//! (`python/mitsuba_ref/compare.py`).
//!
//! **Input → output.** A method's values `a`, the reference's means `r` and the variance of each mean
//! `var_r` (per item: pixel, texel or point, channels flattened) → a [`NoiseCorrected`] error with its
//! floor, 95 % interval and report wording.
//!
//! **The statistic.** `E[(a − r)²] = (a − r_true)² + Var(r)`, so the raw MSE overstates the error by
//! the reference's noise; the corrected MSE is `mean((a − r)²) − mean(var_r)`. Everything is relative to
//! the reference's converged mean level `norm = mean(r)` (never its maximum or a percentile, which noise
//! inflates). The floor is the smallest relative RMSE the comparison tells from zero: with no error,
//! each item's `(a − r)²` is squared Gaussian noise of variance `2 var_r²`, so the corrected MSE of an
//! exact method scatters by `se0 = sqrt(mean(2 var_r²)/n)` and the floor is `sqrt(2 se0)/norm`. Below
//! it the report reads "< floor X", never a smaller number. The 95 % interval takes each item's
//! variance `2 var_r² + 4 d² var_r` with `d² = max((a − r)² − var_r, 0)`.

use serde::{Deserialize, Serialize};

/// A method's error against a noisy reference (module doc).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct NoiseCorrected {
    /// Noise-corrected relative RMSE; `None` below the floor.
    pub rel_rmse: Option<f64>,
    /// Smallest relative RMSE the comparison resolves.
    pub floor: f64,
    /// 95 % interval of the relative RMSE.
    pub ci95: [f64; 2],
    /// Relative RMSE before the reference's noise is removed.
    pub raw_rel_rmse: f64,
    /// The reference's own noise as a relative RMS, `sqrt(mean(var_r))/norm`.
    pub reference_noise: f64,
    /// `mean(r)`, the normalisation.
    pub norm: f64,
    /// Items × channels compared.
    pub n: usize,
}

impl NoiseCorrected {
    /// The error of `a` against `r` whose means have variances `var_r` (flattened, equal lengths).
    ///
    /// # Errors
    /// Lengths differ, nothing is compared, a value is not finite, or the reference's mean is not
    /// positive (an error relative to an empty reference judges nothing).
    pub fn of(a: &[f64], r: &[f64], var_r: &[f64]) -> Result<Self, String> {
        if a.len() != r.len() || r.len() != var_r.len() {
            return Err(format!("lengths differ: method {}, reference {}, variance {}", a.len(), r.len(), var_r.len()));
        }
        if a.is_empty() {
            return Err("nothing to compare".into());
        }
        if let Some(i) = (0..a.len()).find(|&i| !(a[i].is_finite() && r[i].is_finite() && var_r[i].is_finite())) {
            return Err(format!(
                "value {i} is not finite (method {}, reference {}, variance {})",
                a[i], r[i], var_r[i]
            ));
        }
        let n = a.len();
        let mean = |f: &dyn Fn(usize) -> f64| (0..n).map(f).sum::<f64>() / n as f64;
        let norm = mean(&|i| r[i]);
        if norm <= 0.0 {
            return Err(format!("the reference's mean {norm} is not positive"));
        }
        let raw = mean(&|i| (a[i] - r[i]).powi(2));
        let noise = mean(&|i| var_r[i]);
        let corrected = raw - noise;
        let se0 = (mean(&|i| 2.0 * var_r[i] * var_r[i]) / n as f64).sqrt();
        let floor = (2.0 * se0).sqrt() / norm;
        let rel = corrected.max(0.0).sqrt() / norm;
        let spread: f64 = (0..n)
            .map(|i| {
                let d2 = ((a[i] - r[i]).powi(2) - var_r[i]).max(0.0);
                2.0 * var_r[i] * var_r[i] + 4.0 * d2 * var_r[i]
            })
            .sum();
        let se = spread.sqrt() / n as f64;
        let bound = |x: f64| x.max(0.0).sqrt() / norm;
        Ok(Self {
            rel_rmse: (rel >= floor).then_some(rel),
            floor,
            ci95: [bound(corrected - 1.96 * se), bound(corrected + 1.96 * se)],
            raw_rel_rmse: raw.sqrt() / norm,
            reference_noise: noise.sqrt() / norm,
            norm,
            n,
        })
    }

    /// [`Self::of`] for RGB items.
    ///
    /// # Errors
    /// As [`Self::of`].
    pub fn of_rgb(a: &[[f64; 3]], r: &[[f64; 3]], var_r: &[[f64; 3]]) -> Result<Self, String> {
        let flat = |x: &[[f64; 3]]| x.iter().flatten().copied().collect::<Vec<f64>>();
        Self::of(&flat(a), &flat(r), &flat(var_r))
    }

    /// [`Self::of_rgb`] over the items where `mask` is true (all three slices are as long as `mask`).
    ///
    /// # Errors
    /// As [`Self::of`].
    pub fn of_rgb_masked(a: &[[f64; 3]], r: &[[f64; 3]], var_r: &[[f64; 3]], mask: &[bool]) -> Result<Self, String> {
        if a.len() != mask.len() {
            return Err(format!("lengths differ: method {}, mask {}", a.len(), mask.len()));
        }
        let kept = |x: &[[f64; 3]]| x.iter().zip(mask).filter(|(_, m)| **m).map(|(p, _)| *p).collect::<Vec<_>>();
        Self::of_rgb(&kept(a), &kept(r), &kept(var_r))
    }

    /// The error is below the floor (`rel_rmse` is `None`).
    pub fn below_floor(&self) -> bool {
        self.rel_rmse.is_none()
    }

    /// The noise-corrected relative RMSE, or the floor when below it (the largest error the comparison
    /// cannot rule out there: an upper bound).
    pub fn rel_or_floor(&self) -> f64 {
        self.rel_rmse.unwrap_or(self.floor)
    }

    /// `rel_or_floor²`: the relative MSE, or the smallest MSE the comparison can claim.
    pub fn mse_or_floor(&self) -> f64 {
        self.rel_or_floor().powi(2)
    }

    /// Report wording in per cent: "12.3 % [11.9, 12.8] (floor 0.4 %)" or "< floor 0.4 %".
    pub fn percent(&self) -> String {
        match self.rel_rmse {
            Some(e) => format!(
                "{} [{}, {}] (floor {} %)",
                pct(e) + " %",
                pct(self.ci95[0]),
                pct(self.ci95[1]),
                pct(self.floor)
            ),
            None => format!("< floor {} %", pct(self.floor)),
        }
    }
}

/// A fraction in per cent with two significant figures (one decimal at least).
fn pct(x: f64) -> String {
    let p = 100.0 * x;
    if p == 0.0 {
        "0".into()
    } else if p >= 10.0 {
        format!("{p:.0}")
    } else if p >= 0.1 {
        format!("{p:.1}")
    } else {
        format!("{p:.2}")
    }
}

#[cfg(test)]
mod tests;
