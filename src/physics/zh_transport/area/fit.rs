//! The best-fit axis of a bounce's radiance (dubouchet2019 Sec. 4.2, Fig. 5): the full SH vector of
//! one `(d, θ)` cell → the ZH lobe about the axis in the `xz`-plane that keeps the most energy.
//!
//! **Input → output.** SH coefficients (order `N`, mirror-symmetric about the `xz`-plane) → an
//! [`AreaEntry`]: the axis angle `theta_fit ∈ (−π/2, π/2]` from the light axis, the ZH coefficients
//! about it and the relative L² error of the fit. The energy `J(ϑ) = Σ_l c_l(u(ϑ))²` is scanned at
//! [`FIT_SCAN`] angles per period (plus the light axis and the optimal linear direction), bracketed
//! around the best sample and refined by Brent's method ([`brent_max`]). An axis is a line, so angles
//! are kept in one half turn and interpolation picks the nearer representative ([`antipode_nearest`]).

use std::f64::consts::{FRAC_PI_2, PI};

use super::AreaEntry;
use crate::physics::sh;

/// Number of equally spaced angles per period scanned before Brent's method.
pub const FIT_SCAN: usize = 48;

/// `J(ϑ) = Σ_l c_l(u(ϑ))²` for `u = (sin ϑ, 0, cos ϑ)`.
pub(super) fn fit_energy(sh_coeffs: &[f64], angle: f64) -> f64 {
    let (s, c) = angle.sin_cos();
    sh::zh_project_about(sh_coeffs, [s, 0.0, c]).iter().map(|x| x * x).sum()
}

/// Best-fit ZH of the SH vector `coeffs` (mirror-symmetric about the `xz`-plane): scan, bracket,
/// Brent (module doc).
pub(super) fn fit_axis(coeffs: &[f64], order: usize) -> AreaEntry {
    let norm2: f64 = coeffs.iter().map(|x| x * x).sum();
    let mut candidates: Vec<f64> = (0..FIT_SCAN).map(|k| -FRAC_PI_2 + PI * k as f64 / FIT_SCAN as f64).collect();
    candidates.push(0.0);
    if let Some(dir) = sh::optimal_linear_direction(coeffs) {
        candidates.push(wrap_half_turn(dir[0].atan2(dir[2])));
    }
    candidates.sort_by(f64::total_cmp);
    candidates.dedup();
    let values: Vec<f64> = candidates.iter().map(|&a| fit_energy(coeffs, a)).collect();
    let best = (0..candidates.len()).fold(0, |b, k| if values[k] > values[b] { k } else { b });
    let angle = if order < 2 || norm2 == 0.0 {
        0.0
    } else {
        // Neighbours in the periodic list (period π).
        let n = candidates.len();
        let left = if best == 0 { candidates[n - 1] - PI } else { candidates[best - 1] };
        let right = if best + 1 == n { candidates[0] + PI } else { candidates[best + 1] };
        let (a, _) = brent_max(|x| fit_energy(coeffs, x), left, candidates[best], right, 1e-10, 100);
        wrap_half_turn(a)
    };
    let zh = sh::zh_project_about(coeffs, [angle.sin(), 0.0, angle.cos()]);
    let energy: f64 = zh.iter().map(|x| x * x).sum();
    let fit_error = if norm2 > 0.0 { (norm2 - energy).max(0.0).sqrt() / norm2.sqrt() } else { 0.0 };
    AreaEntry { zh, theta_fit: angle, fit_error }
}

/// `(f1 ± π, true)` when that representative of the axis line at angle `f1` is nearer to `f0` than `f1`
/// (the stored angles differ by more than `π/2`), else `(f1, false)`.
pub(super) fn antipode_nearest(f0: f64, f1: f64) -> (f64, bool) {
    if f1 - f0 > FRAC_PI_2 {
        (f1 - PI, true)
    } else if f0 - f1 > FRAC_PI_2 {
        (f1 + PI, true)
    } else {
        (f1, false)
    }
}

/// The angle `x + kπ` in `(−π/2, π/2]`.
pub(super) fn wrap_half_turn(x: f64) -> f64 {
    let mut y = x.rem_euclid(PI);
    if y > FRAC_PI_2 {
        y -= PI;
    }
    y
}

/// Brent's method for the maximum of `f` on `[lo, hi]`, starting from `mid` (with `f(mid)` not below the
/// ends, so a maximum is bracketed): each step fits a parabola through the three best points so far and
/// takes its vertex when it lies inside the bracket and moves less than half the step before last,
/// otherwise a golden-section step into the larger part of the bracket; it stops when the bracket is
/// within `2·tol` (plus a relative `1e-12`) of the best point. Returns `(argmax, max)` after at most
/// `max_iter` steps (Brent 1973, "Algorithms for minimization without derivatives", ch. 5).
pub fn brent_max(f: impl Fn(f64) -> f64, lo: f64, mid: f64, hi: f64, tol: f64, max_iter: usize) -> (f64, f64) {
    const GOLD: f64 = 0.381_966_011_250_105_1; // (3 − √5)/2
    let (mut a, mut b) = (lo.min(hi), lo.max(hi));
    // x: best so far; w: second best; v: previous w. Work on −f (minimisation).
    let (mut x, mut w, mut v) = (mid, mid, mid);
    let mut fx = -f(x);
    let (mut fw, mut fv) = (fx, fx);
    let (mut step, mut prev_step) = (0.0f64, 0.0f64);
    for _ in 0..max_iter {
        let m = 0.5 * (a + b);
        let tol1 = tol + 1e-12 * x.abs();
        let tol2 = 2.0 * tol1;
        if (x - m).abs() <= tol2 - 0.5 * (b - a) {
            break;
        }
        let mut golden = true;
        if prev_step.abs() > tol1 {
            // Parabola through (v, fv), (w, fw), (x, fx).
            let r = (x - w) * (fx - fv);
            let q0 = (x - v) * (fx - fw);
            let mut p = (x - v) * q0 - (x - w) * r;
            let mut q = 2.0 * (q0 - r);
            if q > 0.0 {
                p = -p;
            }
            q = q.abs();
            let older = prev_step;
            if p.abs() < (0.5 * q * older).abs() && p > q * (a - x) && p < q * (b - x) {
                prev_step = step;
                step = p / q;
                let u = x + step;
                if u - a < tol2 || b - u < tol2 {
                    step = if x < m { tol1 } else { -tol1 };
                }
                golden = false;
            }
        }
        if golden {
            prev_step = if x < m { b - x } else { a - x };
            step = GOLD * prev_step;
        }
        let u = if step.abs() >= tol1 { x + step } else { x + tol1.copysign(step) };
        let fu = -f(u);
        if fu <= fx {
            if u < x {
                b = x;
            } else {
                a = x;
            }
            (v, fv) = (w, fw);
            (w, fw) = (x, fx);
            (x, fx) = (u, fu);
        } else {
            if u < x {
                a = u;
            } else {
                b = u;
            }
            if fu <= fw || w == x {
                (v, fv) = (w, fw);
                (w, fw) = (u, fu);
            } else if fu <= fv || v == x || v == w {
                (v, fv) = (u, fu);
            }
        }
    }
    (x, -fx)
}
