//! Axis ranges, ticks and tick labels.
//!
//! Input: the span of the drawable data along one axis, in plot space
//! (the value itself on a linear axis, its log10 on a log axis; `None` when
//! no point is drawable), the axis [`Scale`] and a target tick count.
//! Output: an [`Axis`] — the padded range, labelled ticks, their labels and
//! unlabelled minor grid positions — which is also the plotters coordinate
//! the chart is built on, so plotters draws exactly these ticks and labels.

use plotters::coord::ranged1d::{KeyPointHint, NoDefaultFormatting, ValueFormatter};
use plotters::prelude::Ranged;

use super::Scale;

/// Maps a data value into plot space for `scale`, or `None` when the value
/// cannot be shown on that axis.
pub(super) fn to_plot_space(scale: Scale, v: f64) -> Option<f64> {
    match scale {
        Scale::Linear => v.is_finite().then_some(v),
        Scale::Log10 => (v.is_finite() && v > 0.0).then(|| v.log10()),
    }
}

/// One axis, in plot space (log10 of the data on a log axis).
#[derive(Debug, Clone, PartialEq)]
pub(super) struct Axis {
    /// Lower end of the axis, in plot space.
    pub(super) lo: f64,
    /// Upper end of the axis, in plot space.
    pub(super) hi: f64,
    /// Labelled tick positions, ascending.
    pub(super) ticks: Vec<f64>,
    /// Label of each tick.
    pub(super) labels: Vec<String>,
    /// Unlabelled minor grid positions.
    pub(super) minor: Vec<f64>,
}

impl Axis {
    /// Label of the tick at `v` (an exact tick value handed back by plotters).
    fn label(&self, v: f64) -> String {
        self.ticks
            .iter()
            .position(|t| t.to_bits() == v.to_bits())
            .and_then(|i| self.labels.get(i).cloned())
            .unwrap_or_else(|| format!("{v}"))
    }
}

/// The axis is its own plotters coordinate: it maps plot-space values
/// linearly onto pixels and hands plotters our ticks and labels.
impl Ranged for Axis {
    type FormatOption = NoDefaultFormatting;
    type ValueType = f64;

    fn map(&self, value: &f64, limit: (i32, i32)) -> i32 {
        let frac = (*value - self.lo) / (self.hi - self.lo);
        let pixels = f64::from(limit.1) - f64::from(limit.0);
        // `as` saturates (and maps NaN to 0), so this cannot overflow.
        (f64::from(limit.0) + pixels * frac).round() as i32
    }

    fn key_points<Hint: KeyPointHint>(&self, hint: Hint) -> Vec<f64> {
        if hint.weight().allow_light_points() { self.minor.clone() } else { self.ticks.clone() }
    }

    fn range(&self) -> std::ops::Range<f64> {
        self.lo..self.hi
    }
}

impl ValueFormatter<f64> for Axis {
    fn format(value: &f64) -> String {
        format!("{value}")
    }

    fn format_ext(&self, value: &f64) -> String {
        self.label(*value)
    }
}

/// Builds an axis for the data span `data` (plot space, `None` when there
/// is no drawable point), aiming at about `target` labelled ticks.
pub(super) fn build_axis(scale: Scale, data: Option<(f64, f64)>, target: usize) -> Result<Axis, String> {
    match scale {
        Scale::Linear => linear_axis(data, target),
        Scale::Log10 => Ok(log_axis(data, target)),
    }
}

/// A linear axis over `data` (0–1 when `None`), widened when degenerate
/// and padded by 5 % each side. Fails when the padded span overflows.
fn linear_axis(data: Option<(f64, f64)>, target: usize) -> Result<Axis, String> {
    let (mut lo, mut hi) = data.unwrap_or((0.0, 1.0));
    let magnitude = lo.abs().max(hi.abs());
    if hi - lo <= magnitude * 1e-12 {
        let half = if magnitude > 0.0 { magnitude * 0.1 } else { 1.0 };
        lo -= half;
        hi += half;
    }
    let pad = 0.05 * (hi - lo);
    lo -= pad;
    hi += pad;
    if !(lo.is_finite() && hi.is_finite() && (hi - lo).is_finite()) {
        return Err(format!("values up to {magnitude:e} are too large for a linear axis"));
    }
    let (ticks, labels) = linear_ticks(lo, hi, target);
    Ok(Axis { lo, hi, ticks, labels, minor: Vec::new() })
}

/// A log10 axis over `data` (plot-space exponents; 1–10 when `None`),
/// widened when degenerate and padded by a fraction of a decade.
pub(super) fn log_axis(data: Option<(f64, f64)>, target: usize) -> Axis {
    let (mut lo, mut hi) = data.unwrap_or((0.0, 1.0));
    if hi - lo < 1e-9 {
        lo -= 0.5;
        hi += 0.5;
    }
    let pad = (0.05 * (hi - lo)).max(0.1);
    lo -= pad;
    hi += pad;

    // Plot-space values lie within about -324..309, so these fit in i32.
    let first = lo.ceil() as i32;
    let last = hi.floor() as i32;
    let decades = (last - first + 1).max(0) as usize;
    let mut ticks = Vec::new();
    let mut labels = Vec::new();
    let mut minor = Vec::new();

    if decades >= 2 {
        // Label every `stride`-th decade (a round number of decades), with
        // unlabelled grid lines every `minor_stride` decades in between, or
        // at 2..9 within each decade when every decade is labelled.
        const STRIDES: [(i32, i32); 12] = [
            (1, 1),
            (2, 1),
            (3, 1),
            (5, 1),
            (10, 2),
            (20, 5),
            (25, 5),
            (50, 10),
            (100, 20),
            (200, 50),
            (250, 50),
            (500, 100),
        ];
        let (stride, minor_stride) = STRIDES
            .iter()
            .copied()
            .find(|&(stride, _)| decades.div_ceil(stride as usize) <= target.max(2))
            .unwrap_or((1000, 200));
        for k in first..=last {
            if k.rem_euclid(stride) == 0 {
                ticks.push(f64::from(k));
                labels.push(format!("1e{k}"));
            } else if k.rem_euclid(minor_stride) == 0 {
                minor.push(f64::from(k));
            }
        }
        if stride == 1 {
            for k in (first - 1)..=last {
                for m in 2..=9 {
                    let t = f64::from(k) + f64::from(m).log10();
                    if (lo..=hi).contains(&t) {
                        minor.push(t);
                    }
                }
            }
        }
    } else {
        // Under two decades: ticks at 1..9 (or 1, 2, 5) times a power of
        // ten, labelled plainly for moderate exponents ("0.02", "300") and
        // as "2e-5" otherwise.
        let candidates = |ms: &[u32]| -> Vec<(f64, String)> {
            let mut out = Vec::new();
            for k in (lo.floor() as i32)..=(hi.ceil() as i32) {
                for &m in ms {
                    let t = f64::from(k) + f64::from(m).log10();
                    if (lo..=hi).contains(&t) {
                        let label = if (-3..=4).contains(&k) {
                            let decimals = (-k).max(0) as usize;
                            format!("{:.decimals$}", f64::from(m) * 10f64.powi(k))
                        } else {
                            format!("{m}e{k}")
                        };
                        out.push((t, label));
                    }
                }
            }
            out
        };
        let mut chosen = candidates(&[1, 2, 3, 4, 5, 6, 7, 8, 9]);
        if chosen.len() > target.max(2) {
            chosen = candidates(&[1, 2, 5]);
        }
        if chosen.len() < 3 {
            // A narrow range: nice linear values, placed on the log axis.
            let (vs, ls) = linear_ticks(10f64.powf(lo), 10f64.powf(hi), target);
            let linear: Vec<(f64, String)> =
                vs.into_iter().zip(ls).filter(|(v, _)| *v > 0.0).map(|(v, l)| (v.log10(), l)).collect();
            if linear.len() > chosen.len() {
                chosen = linear;
            }
        }
        for (t, l) in chosen {
            ticks.push(t);
            labels.push(l);
        }
    }
    Axis { lo, hi, ticks, labels, minor }
}

/// Nice ticks (1, 2 or 5 × 10^k steps) within `lo..=hi`, at most about
/// `target`, with their labels.
pub(super) fn linear_ticks(lo: f64, hi: f64, target: usize) -> (Vec<f64>, Vec<String>) {
    let span = hi - lo;
    let raw = span / target.max(1) as f64;
    if !(raw.is_finite() && raw > 0.0) {
        return (Vec::new(), Vec::new());
    }
    let magnitude = 10f64.powf(raw.log10().floor());
    let norm = raw / magnitude;
    let step = if norm <= 1.0 {
        1.0
    } else if norm <= 2.0 {
        2.0
    } else if norm <= 5.0 {
        5.0
    } else {
        10.0
    } * magnitude;
    if !(step.is_finite() && step > 0.0) {
        return (Vec::new(), Vec::new());
    }
    let first = (lo / step).ceil();
    let last = (hi / step).floor();
    // Guard against precision loss far from zero: at most 100 ticks.
    if !(first.is_finite() && last.is_finite()) || last - first > 100.0 || last < first {
        return (Vec::new(), Vec::new());
    }
    let biggest = lo.abs().max(hi.abs());
    let step_exp = step.log10().floor() as i32;
    let scientific = biggest >= 1e6 || (step < 1e-3 && biggest < 1e-2) || step < 1e-5;
    let mut ticks = Vec::new();
    let mut labels = Vec::new();
    let mut k = first;
    while k <= last {
        let mut v = k * step;
        if v.abs() < step * 1e-9 {
            v = 0.0;
        }
        ticks.push(v);
        labels.push(format_linear(v, step_exp, biggest, scientific));
        k += 1.0;
    }
    (ticks, labels)
}

/// Formats a linear tick value `v` for ticks spaced `10^step_exp`-ish apart.
fn format_linear(v: f64, step_exp: i32, biggest: f64, scientific: bool) -> String {
    if v == 0.0 {
        return "0".to_string();
    }
    if scientific {
        let lead = biggest.log10().floor() as i32;
        let digits = lead.saturating_sub(step_exp).clamp(0, 15) as usize;
        let s = format!("{v:.digits$e}");
        match s.split_once('e') {
            Some((mantissa, exp)) => {
                let mantissa = if mantissa.contains('.') {
                    mantissa.trim_end_matches('0').trim_end_matches('.')
                } else {
                    mantissa
                };
                format!("{mantissa}e{exp}")
            }
            None => s,
        }
    } else {
        let decimals = (-step_exp).clamp(0, 15) as usize;
        format!("{v:.decimals$}")
    }
}
