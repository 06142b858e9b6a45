//! Henyey–Greenstein (HG) high-precision reference: what HG tables are judged against.
//!
//! **Input → output.** `μ`, `ξ`, `g` as `f64` (exact in double-double) → the HG phase,
//! the per-azimuth cumulative `F_hg` of elek2014 (Sec. 4.2, Eq. 2 context) and the inverse-CDF
//! sample, each rounded to `f64` from a ~106-bit double-double (`twofloat`) evaluation; the
//! Legendre moments `∫ f P_l dω` by numerical quadrature; and [`worst_errors_on_matrix`], the
//! worst error of `crate::physics::hg` against all of these on a fixed matrix of extreme inputs.
//!
//! **Invariant.** Results are independent of `crate::physics::hg` and, before the final
//! rounding to `f64`, accurate to well below one `f64` ulp (≲ 1e-18 relative for
//! `|g| ≤ 0.999999`, from the cancellation bounds below), so a measured difference is the
//! production code's error. They evaluate the *textbook closed forms* (the ones that cancel) in
//! different arithmetic, and leave them only where even ~106 bits would not absorb the
//! cancellation:
//! * `g == 0.0` exactly: the isotropic limits `1/(4π)`, `(1 + μ)/(4π)`, `2ξ − 1`;
//! * `0 < |g| < 1e-12`: second-order Taylor expansions in `g` (derived in the function docs;
//!   truncation `O(g³) < 1e-35` relative);
//! * `F_hg` with `|w| < 1e-12`, `w = 2g(1 + μ)/(1 + g)²`: the closed form cancels by a factor
//!   `~2/|w|`, which near `μ = −1` is large for *every* `g`, not only small ones
//!   (`μ = −1 + 1e-12`, `g = 1e-12` would lose 24 of ~32 digits); there the difference
//!   `s⁻¹ − 1/(1 + g)` is expanded as the binomial series of `(1 − w)^{−1/2} − 1`.
//!
//! Elsewhere the cancellation costs at most a factor `2/|w| ≤ 2e12` (`F_hg`), `1/|g| ≤ 1e12`
//! in absolute terms (sampler) and `1/(1 − |g|)² ≤ 1e12` (phase, `|g| ≤ 0.999999`): ≥ 60 of the
//! ~106 bits survive. All double-double quotients use the long division `dd_div` (not
//! twofloat's own, see there).
//!
//! The moment quadrature integrates in `y = ln(s²/(1 − g)²)` (for `|g| ≥ 1e-3`), which turns
//! the lobe of width `(1 − g)²` into the smooth weight `e^{−y/2}`, on composite 32-point
//! Gauss–Legendre panels (nodes by Newton iteration) equal in `θ`, so the oscillations of `P_l`
//! are resolved for any `l`; `P_l` comes from Reinsch's difference form of the recurrence,
//! which stays accurate near `μ = ±1` where the plain one does not, and sums are double-double.
//!
//! **Outside the domain.** As in `crate::physics::hg`: `μ`/`ξ` are clamped, an invalid `g`
//! (not finite or `|g| ≥ 1`) or a `NaN` argument gives `NaN`; nothing panics.

use std::sync::OnceLock;

use twofloat::TwoFloat;

use crate::physics::hg;

/// Double-double number (~106-bit mantissa).
type Dd = TwoFloat;

/// Below this `|g|` (and above 0) the Taylor expansions in `g` are used.
const TAYLOR_G_MAX: f64 = 1e-12;
/// Below this `|w|` the binomial series replaces the closed-form difference in `F_hg`.
const SERIES_W_MAX: f64 = 1e-12;
/// Number of terms of the binomial series (more than needed below `SERIES_W_MAX`; the series is
/// also checked against the closed form up to `|w| ~ 1e-2`, where 12 terms truncate at `|w|^13`).
const SERIES_TERMS: u32 = 12;
/// Below this `|g|` the moment quadrature integrates in `μ` directly.
const QUAD_G_SMALL: f64 = 1e-3;
/// Gauss–Legendre nodes per panel.
const GL_NODES: usize = 32;
/// Minimal number of equal-`θ` panels in the moment quadrature.
const QUAD_MIN_PANELS: u32 = 64;
/// Maximal panel width in the log variable `y`.
const QUAD_Y_STEP: f64 = 1.0;

/// The values of `g` of the extreme test matrix.
pub const G_MATRIX: [f64; 15] =
    [-0.999_999, -0.999, -0.9, -0.5, -1e-6, -1e-12, 0.0, 1e-12, 1e-8, 1e-6, 0.1, 0.5, 0.9, 0.999, 0.999_999];
/// The values of `μ` of the extreme test matrix.
pub const MU_MATRIX: [f64; 8] = [-1.0, -1.0 + 1e-12, -0.5, 0.0, 0.3, 1.0 - 1e-9, 1.0 - 1e-12, 1.0];
/// The values of `ξ` of the extreme test matrix (for the sampler).
pub const XI_MATRIX: [f64; 9] = [0.0, 1e-12, 1e-6, 0.25, 0.5, 0.75, 1.0 - 1e-6, 1.0 - 1e-12, 1.0];
/// The Legendre orders `l` at which moments are compared.
pub const MOMENT_ORDERS: [u32; 6] = [0, 1, 2, 5, 16, 64];

/// True when `g` is finite and `|g| < 1`.
fn g_is_valid(g: f64) -> bool {
    g.abs() < 1.0
}

/// `1/(4π)` in double-double.
fn inv_four_pi() -> Dd {
    twofloat::consts::FRAC_1_PI * 0.25
}

/// Double-double quotient `a / b`, by long division with double-double residuals
/// (`q = q₁ + q₂ + q₃`, relative error `~1e-32`).
///
/// Not `twofloat`'s `/`: in twofloat 0.8.4 `TwoFloat / TwoFloat` (and `recip`, `f64 / TwoFloat`)
/// forms the residual `1 − b_hi · (1/b_hi)` in plain `f64` without an FMA, so quotients are only
/// accurate to `~1.1e-16` relative — no better than `f64` (measured; see the tests).
/// `TwoFloat / f64` is accurate and is used where the divisor is an exact `f64`.
fn dd_div(a: Dd, b: Dd) -> Dd {
    let q1 = a.hi() / b.hi();
    let r = a - b * q1;
    let q2 = r.hi() / b.hi();
    let r = r - b * q2;
    let q3 = r.hi() / b.hi();
    Dd::new_add(q1, q2) + q3
}

/// `1 + g² − 2gμ` in double-double (`g²` and `gμ` are exact double-double products).
fn dist2_dd(mu: f64, g: f64) -> Dd {
    (1.0 + Dd::new_mul(g, g)) - 2.0 * Dd::new_mul(g, mu)
}

/// Reference HG phase `f(μ, g) = (1 − g²) / (4π (1 + g² − 2gμ)^{3/2})` [1/sr], textbook form in
/// double-double, rounded to `f64`.
///
/// For `0 < |g| < 1e-12` it uses `f = (1/4π)[1 + 3μg + (15μ² − 5)/2 · g²] + O(g³)` (the first
/// terms of `f = Σ (2l + 1)/(4π) g^l P_l(μ)`). `μ` is clamped; invalid `g` or `NaN` gives `NaN`.
pub fn phase_ref(mu: f64, g: f64) -> f64 {
    if !g_is_valid(g) || mu.is_nan() {
        return f64::NAN;
    }
    let mu = mu.clamp(-1.0, 1.0);
    let value = if g == 0.0 {
        inv_four_pi()
    } else if g.abs() < TAYLOR_G_MAX {
        phase_taylor(mu, g)
    } else {
        phase_closed(mu, g)
    };
    value.hi()
}

/// Textbook closed form of the phase.
fn phase_closed(mu: f64, g: f64) -> Dd {
    let s2 = dist2_dd(mu, g);
    dd_div((1.0 - Dd::new_mul(g, g)) * inv_four_pi(), s2 * s2.sqrt())
}

/// Second-order Taylor expansion of the phase in `g`.
fn phase_taylor(mu: f64, g: f64) -> Dd {
    let c2 = (15.0 * Dd::new_mul(mu, mu) - 5.0) * 0.5;
    inv_four_pi() * (1.0 + 3.0 * Dd::new_mul(mu, g) + c2 * Dd::new_mul(g, g))
}

/// Reference per-azimuth cumulative `F_hg(μ, g)` of elek2014 (Sec. 4.2, Eq. 2 context) [1/rad]:
/// the textbook `(1 − g²)/(4πg) · (s⁻¹ − 1/(1 + g))`, `s² = 1 + g² − 2gμ`, in double-double.
///
/// Special cases (see the module doc): `g == 0` → `(1 + μ)/(4π)`;
/// `0 < |g| < 1e-12` → `(1 + μ)/(4π) · [1 + (3/2)(μ − 1)g + (5/2)μ(μ − 1)g²] + O(g³)`
/// (integrate the Legendre series with `∫_{−1}^{μ} P_l = (P_{l+1} − P_{l−1})/(2l + 1)`; every
/// term carries the factor `1 + μ`, so the error is relative); and for
/// `|w| < 1e-12`, `w = 2g(1 + μ)/(1 + g)²`, the identity `s = (1 + g)√(1 − w)` gives
/// `F = (1 − g)/(4πg) · Σ_{k≥1} C(2k, k)/4^k · w^k`. `F(−1, g) = 0` exactly.
/// `μ` is clamped; invalid `g` or `NaN` gives `NaN`.
pub fn cdf_per_azimuth_ref(mu: f64, g: f64) -> f64 {
    if !g_is_valid(g) || mu.is_nan() {
        return f64::NAN;
    }
    let mu = mu.clamp(-1.0, 1.0);
    let value = if g == 0.0 {
        Dd::new_add(1.0, mu) * inv_four_pi()
    } else if g.abs() < TAYLOR_G_MAX {
        cdf_taylor(mu, g)
    } else if cdf_w(mu, g).abs() < SERIES_W_MAX {
        cdf_series(mu, g)
    } else {
        cdf_closed(mu, g)
    };
    value.hi()
}

/// Textbook closed form of `F_hg`.
fn cdf_closed(mu: f64, g: f64) -> Dd {
    let s = dist2_dd(mu, g).sqrt();
    let prefactor = (1.0 - Dd::new_mul(g, g)) * inv_four_pi() / g;
    let one = Dd::from(1.0);
    prefactor * (dd_div(one, s) - dd_div(one, Dd::new_add(1.0, g)))
}

/// `w = 2g(1 + μ)/(1 + g)²`, so that `s² = (1 + g)²(1 − w)` (`1 + μ` is exact in double-double).
fn cdf_w(mu: f64, g: f64) -> Dd {
    let one_plus_g = Dd::new_add(1.0, g);
    dd_div(2.0 * g * Dd::new_add(1.0, mu), one_plus_g * one_plus_g)
}

/// `F_hg = (1 − g)/(4πg) · ((1 − w)^{−1/2} − 1)` with the binomial series
/// `(1 − w)^{−1/2} − 1 = Σ_{k≥1} C(2k, k)/4^k · w^k` (term ratio `w (2k − 1)/(2k)`).
fn cdf_series(mu: f64, g: f64) -> Dd {
    let w = cdf_w(mu, g);
    let (mut term, mut sum) = (Dd::from(1.0), Dd::from(0.0));
    for k in 1..=SERIES_TERMS {
        let k = f64::from(k);
        term = term * w * (2.0 * k - 1.0) / (2.0 * k);
        sum += term;
    }
    Dd::new_sub(1.0, g) * inv_four_pi() / g * sum
}

/// Second-order Taylor expansion of `F_hg` in `g`.
fn cdf_taylor(mu: f64, g: f64) -> Dd {
    let mu_minus_1 = Dd::new_sub(mu, 1.0);
    let bracket = 1.0 + 1.5 * g * mu_minus_1 + 2.5 * Dd::new_mul(g, g) * mu * mu_minus_1;
    Dd::new_add(1.0, mu) * inv_four_pi() * bracket
}

/// Reference inverse-CDF sample `μ(ξ, g)` with `P(M ≤ μ) = ξ`: the textbook
/// `μ = (1 + g² − ((1 − g²)/(1 − g + 2gξ))²) / (2g)` in double-double.
///
/// `g == 0` → `2ξ − 1`; `0 < |g| < 1e-12` →
/// `μ = (2ξ − 1) + 6ξ(1 − ξ) g + 8ξ(1 − ξ)(1 − 2ξ) g² + O(g³)` (invert the Taylor series of
/// [`cdf_per_azimuth_ref`] order by order). `ξ` is clamped to `[0, 1]`, the result to `[−1, 1]`;
/// invalid `g` or `NaN` gives `NaN`.
pub fn sample_mu_ref(xi: f64, g: f64) -> f64 {
    if !g_is_valid(g) || xi.is_nan() {
        return f64::NAN;
    }
    let xi = xi.clamp(0.0, 1.0);
    let mu = if g == 0.0 {
        Dd::new_sub(2.0 * xi, 1.0)
    } else if g.abs() < TAYLOR_G_MAX {
        sample_taylor(xi, g)
    } else {
        sample_closed(xi, g)
    };
    mu.hi().clamp(-1.0, 1.0)
}

/// Textbook closed-form inverse CDF.
fn sample_closed(xi: f64, g: f64) -> Dd {
    let d = Dd::new_sub(1.0, g) + 2.0 * Dd::new_mul(g, xi);
    let x = dd_div(1.0 - Dd::new_mul(g, g), d);
    ((1.0 + Dd::new_mul(g, g)) - x * x) / (2.0 * g)
}

/// Second-order Taylor expansion of the inverse CDF in `g`.
fn sample_taylor(xi: f64, g: f64) -> Dd {
    let xx = Dd::from(xi) * Dd::new_sub(1.0, xi);
    let c2 = 8.0 * xx * Dd::new_sub(1.0, 2.0 * xi);
    Dd::new_sub(2.0 * xi, 1.0) + 6.0 * xx * g + c2 * Dd::new_mul(g, g)
}

/// Gauss–Legendre nodes and weights on `[−1, 1]`, by Newton iteration on `P_n`.
fn gauss_legendre() -> &'static ([f64; GL_NODES], [f64; GL_NODES]) {
    static RULE: OnceLock<([f64; GL_NODES], [f64; GL_NODES])> = OnceLock::new();
    RULE.get_or_init(|| {
        let n = GL_NODES as f64;
        let mut nodes = [0.0; GL_NODES];
        let mut weights = [0.0; GL_NODES];
        for (i, (x_out, w_out)) in nodes.iter_mut().zip(weights.iter_mut()).enumerate() {
            // Standard initial guess cos(π(i + 3/4)/(n + 1/2)) for the i-th largest root, then Newton.
            let mut x = (std::f64::consts::PI * (i as f64 + 0.75) / (n + 0.5)).cos();
            let mut dp = 1.0;
            for _ in 0..100 {
                let (mut p_prev, mut p) = (1.0, x);
                for k in 1..GL_NODES {
                    let k = k as f64;
                    let next = ((2.0 * k + 1.0) * x * p - k * p_prev) / (k + 1.0);
                    p_prev = p;
                    p = next;
                }
                dp = n * (x * p - p_prev) / (x * x - 1.0);
                let dx = p / dp;
                x -= dx;
                if dx.abs() <= 1e-17 {
                    break;
                }
            }
            *x_out = x;
            *w_out = 2.0 / ((1.0 - x * x) * dp * dp);
        }
        (nodes, weights)
    })
}

/// `P_l(1 − t_i)` for a batch of `t_i ∈ [0, 2]` (the distance of `x` from 1, exact from the
/// integration variable), evaluated from the nearer end of `[−1, 1]` with
/// `P_l(−x) = (−1)^l P_l(x)`, by Reinsch's difference form of the Legendre recurrence:
/// `D_{k+1} = k/(k + 1) · D_k − (2k + 1)/(k + 1) · u P_k`, `P_{k+1} = P_k + D_{k+1}`,
/// `u = min(t, 2 − t)`. The plain recurrence loses `~l² ε/8` near `x = ±1` (2e-10 at
/// `l = 4096`); this form stays at `≤ 3e-15` (measured against a double-double recurrence).
/// The batch runs the nodes of one panel in lock-step so their independent chains overlap.
fn legendre_batch(l: u32, t: &[f64; GL_NODES]) -> [f64; GL_NODES] {
    let odd = !l.is_multiple_of(2);
    let mut u = [0.0; GL_NODES];
    let mut sign = [1.0; GL_NODES];
    for i in 0..GL_NODES {
        if t[i] <= 1.0 {
            u[i] = t[i];
        } else {
            u[i] = (2.0 - t[i]).max(0.0);
            sign[i] = if odd { -1.0 } else { 1.0 };
        }
    }
    let mut p = [1.0; GL_NODES];
    if l == 0 {
        return p;
    }
    let mut d = [0.0; GL_NODES];
    for i in 0..GL_NODES {
        p[i] = 1.0 - u[i];
        d[i] = -u[i];
    }
    for k in 1..l {
        let k = f64::from(k);
        let (a, b) = ((2.0 * k + 1.0) / (k + 1.0), k / (k + 1.0));
        for i in 0..GL_NODES {
            d[i] = b * d[i] - a * u[i] * p[i];
            p[i] += d[i];
        }
    }
    for i in 0..GL_NODES {
        p[i] *= sign[i];
    }
    p
}

/// Composite Gauss–Legendre quadrature of `h(v) · P_l(1 − t(v))` over the panels between
/// consecutive sorted `breaks`, where `node(v) = (h(v), t(v))`; accumulated in double-double.
fn legendre_quadrature(breaks: &[f64], l: u32, node: impl Fn(f64) -> (f64, f64)) -> f64 {
    let (nodes, weights) = gauss_legendre();
    let mut acc = Dd::from(0.0);
    let mut scaled = [0.0; GL_NODES];
    let mut t = [0.0; GL_NODES];
    for pair in breaks.windows(2) {
        let (mid, half) = (0.5 * (pair[0] + pair[1]), 0.5 * (pair[1] - pair[0]));
        if half <= 0.0 {
            continue;
        }
        for i in 0..GL_NODES {
            let (h, ti) = node(mid + half * nodes[i]);
            scaled[i] = weights[i] * half * h;
            t[i] = ti;
        }
        let p = legendre_batch(l, &t);
        for i in 0..GL_NODES {
            acc += scaled[i] * p[i];
        }
    }
    acc.hi()
}

/// Panel edges `t_j = 1 − cos θ_j = 2 sin²(θ_j/2)` for `K` equal steps in `θ ∈ [0, π]`
/// (ascending, `t_0 = 0`, `t_K = 2`). `P_l(cos θ)` has its `l` zeros about evenly spaced in
/// `θ`, so `K = max(64, ⌈l/8⌉)` keeps at most ~8 zeros in a 32-node panel. (Measured for
/// `l ≤ 4096`: the results do not change beyond rounding between `⌈l/4⌉` and `⌈l/16⌉`.)
fn theta_panel_edges(l: u32) -> Vec<f64> {
    let panels = QUAD_MIN_PANELS.max(l.div_ceil(8));
    (0..=panels)
        .map(|j| {
            let half_theta = 0.5 * std::f64::consts::PI * f64::from(j) / f64::from(panels);
            let s = half_theta.sin();
            2.0 * s * s
        })
        .collect()
}

/// `2π ∫ f P_l dμ` integrated directly in `μ` (for `|g| < 1e-3`, where `f` is nearly flat).
fn moment_in_mu(l: u32, g: f64) -> f64 {
    let mut breaks: Vec<f64> = theta_panel_edges(l).iter().map(|t| 1.0 - t).collect();
    breaks.reverse();
    legendre_quadrature(&breaks, l, |mu| {
        let s2 = 1.0 + g * g - 2.0 * g * mu;
        ((1.0 - g * g) / (2.0 * s2 * s2.sqrt()), 1.0 - mu)
    })
}

/// `2π ∫ f P_l dμ` for `g ∈ [1e-3, 1)` in the variable `y = ln(s²/(1 − g)²) ∈ [0, Y]`.
///
/// With `c = (1 − g)²/(2g)`: `1 − μ = c·(e^y − 1)` (no cancellation near the peak `μ = 1`),
/// `2π f |dμ| = (1 + g)/(4g) · e^{−y/2} dy`, and `Y = ln(1 + 2/c)` (`μ = −1`). Panels: width
/// `≤ 1` in `y` (the peak region, where `y` is logarithmic in `1 − μ`) plus the images of the
/// equal-`θ` panels of [`theta_panel_edges`] (the oscillations of `P_l`).
fn moment_in_log_s2(l: u32, g: f64) -> f64 {
    let omg = 1.0 - g;
    let c = omg * omg / (2.0 * g);
    let y_of_t = |t: f64| (t / c).ln_1p();
    let y_max = y_of_t(2.0);
    let mut breaks: Vec<f64> = theta_panel_edges(l).into_iter().map(y_of_t).collect();
    let mut y = 0.0;
    while y < y_max {
        breaks.push(y);
        y += QUAD_Y_STEP;
    }
    breaks.push(y_max);
    breaks.retain(|&b| b <= y_max);
    breaks.sort_by(f64::total_cmp);
    breaks.dedup();
    let integral = legendre_quadrature(&breaks, l, |y| ((-0.5 * y).exp(), (c * y.exp_m1()).min(2.0)));
    (1.0 + g) / (4.0 * g) * integral
}

/// Legendre moment `∫ f(μ, g) P_l(μ) dω = 2π ∫ f P_l dμ` by numerical quadrature, *not* via
/// `g^l` (it is the check of `crate::physics::hg::legendre_moment`).
///
/// Absolute error `≤ 7e-16` measured for `l ≤ 4096` and `|g| ≤ 0.999999` (against `g^l` in
/// double-double; the tests require `≤ 1e-12` for the moments and `≤ 1e-14` for the
/// normalisation `l = 0`). Cost `O(l²)`: ~0.1 s at `l = 4096` in a dev build, sub-millisecond
/// for `l ≤ 64`. `g < 0` uses `moment(l, −g) = (−1)^l moment(l, g)`; `|g| < 1e-3` integrates
/// in `μ`, larger `|g|` in `y = ln(s²/(1 − g)²)` (see the module doc), both on panels equal in
/// `θ`. Invalid `g` gives `NaN`.
pub fn legendre_moment_quadrature(l: u32, g: f64) -> f64 {
    if !g_is_valid(g) {
        return f64::NAN;
    }
    if g < 0.0 {
        let m = legendre_moment_quadrature(l, -g);
        return if l.is_multiple_of(2) { m } else { -m };
    }
    if g < QUAD_G_SMALL { moment_in_mu(l, g) } else { moment_in_log_s2(l, g) }
}

/// Worst errors of `crate::physics::hg` against this reference on the extreme matrix
/// ([`G_MATRIX`] × [`MU_MATRIX`], [`G_MATRIX`] × [`XI_MATRIX`], [`G_MATRIX`] ×
/// [`MOMENT_ORDERS`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HgErrorSummary {
    /// Max relative error of `hg::phase` vs [`phase_ref`].
    pub phase_rel: f64,
    /// Max relative error of `hg::cdf_per_azimuth` vs [`cdf_per_azimuth_ref`].
    pub cdf_rel: f64,
    /// Max absolute error of `hg::sample_mu` vs [`sample_mu_ref`].
    pub sample_abs: f64,
    /// Max absolute error of `hg::legendre_moment` vs [`legendre_moment_quadrature`].
    pub moment_abs: f64,
}

/// `|x − r| / |r|`, with `0` when both are equal (including both zero) and `∞` for `r = 0 ≠ x`.
fn rel_err(x: f64, r: f64) -> f64 {
    if x == r { 0.0 } else { (x - r).abs() / r.abs() }
}

/// Measures [`HgErrorSummary`] on the extreme matrix (a few milliseconds; used by the CLI
/// report and the tests). A `NaN` anywhere makes the corresponding field `NaN`.
pub fn worst_errors_on_matrix() -> HgErrorSummary {
    let worst = |acc: f64, e: f64| {
        if e.is_nan() || acc.is_nan() { f64::NAN } else { acc.max(e) }
    };
    let mut s = HgErrorSummary { phase_rel: 0.0, cdf_rel: 0.0, sample_abs: 0.0, moment_abs: 0.0 };
    for g in G_MATRIX {
        for mu in MU_MATRIX {
            s.phase_rel = worst(s.phase_rel, rel_err(hg::phase(mu, g), phase_ref(mu, g)));
            let f = hg::cdf_per_azimuth(mu, g);
            s.cdf_rel = worst(s.cdf_rel, rel_err(f, cdf_per_azimuth_ref(mu, g)));
        }
        for xi in XI_MATRIX {
            let e = (hg::sample_mu(xi, g) - sample_mu_ref(xi, g)).abs();
            s.sample_abs = worst(s.sample_abs, e);
        }
        for l in MOMENT_ORDERS {
            let e = (hg::legendre_moment(l, g) - legendre_moment_quadrature(l, g)).abs();
            s.moment_abs = worst(s.moment_abs, e);
        }
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Relative difference of two double-double values.
    fn dd_rel(a: Dd, b: Dd) -> f64 {
        ((a - b).hi() / b.hi()).abs()
    }

    /// Deterministic xorshift64 stream of uniforms in `[0, 1)`.
    fn uniforms(mut state: u64) -> impl FnMut() -> f64 {
        move || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            (state >> 11) as f64 / (1u64 << 53) as f64
        }
    }

    /// Dense `μ` grid: uniform plus geometric clustering at both ends, sorted.
    fn dense_mu_grid() -> Vec<f64> {
        let mut mus: Vec<f64> = (0..=4000).map(|i| -1.0 + f64::from(i) / 2000.0).collect();
        for k in 0..600 {
            let d = 10f64.powf(-16.0 + 15.0 * f64::from(k) / 600.0);
            mus.extend([1.0 - d, -1.0 + d]);
        }
        mus.sort_by(f64::total_cmp);
        mus
    }

    /// The matrix `g` values plus a few more strong and moderate ones.
    fn dense_g_list() -> Vec<f64> {
        let mut gs = G_MATRIX.to_vec();
        gs.extend([0.99, -0.99, 0.3, -0.3, 0.999_999_9, -0.999_999_9, 5e-324, -1e-300]);
        gs
    }

    #[test]
    fn production_values_on_the_matrix_are_finite_positive_in_range_and_monotone() {
        for g in G_MATRIX {
            let mut prev_cdf = 0.0;
            for mu in MU_MATRIX {
                let f = hg::phase(mu, g);
                assert!(f.is_finite() && f > 0.0, "phase({mu}, {g}) = {f}");
                let c = hg::cdf(mu, g);
                assert!((0.0..=1.0).contains(&c), "cdf({mu}, {g}) = {c}");
                assert!(c >= prev_cdf, "cdf not monotone at mu={mu}, g={g}");
                assert!(hg::cdf_per_azimuth(mu, g).is_finite());
                prev_cdf = c;
            }
            let mut prev_mu = -1.0;
            for xi in XI_MATRIX {
                let m = hg::sample_mu(xi, g);
                assert!((-1.0..=1.0).contains(&m), "sample_mu({xi}, {g}) = {m}");
                assert!(m >= prev_mu, "sample_mu not monotone at xi={xi}, g={g}");
                prev_mu = m;
            }
            for l in MOMENT_ORDERS {
                assert!(hg::legendre_moment(l, g).is_finite());
                assert!(hg::zh_coefficient(l, g).is_finite());
            }
        }
    }

    #[test]
    fn cdf_and_sampler_are_monotone_on_dense_grids_including_near_one() {
        // Pins the complement evaluation: computing P(M ≤ μ) directly near 1 (e.g. g = −0.999999,
        // μ → 1, where the density is ~1e-7) lets rounding noise of a few ulps(1) reverse order.
        let mus = dense_mu_grid();
        for g in dense_g_list() {
            let mut prev = (0.0, -1.0);
            for &mu in &mus {
                let c = hg::cdf(mu, g);
                let m = hg::sample_mu(0.5 * (1.0 + mu), g);
                assert!(c >= prev.0, "cdf decreases at mu={mu}, g={g}");
                assert!(m >= prev.1, "sample_mu decreases at xi={}, g={g}", 0.5 * (1.0 + mu));
                prev = (c, m);
            }
        }
    }

    #[test]
    fn phase_matches_reference_to_1e13_relative() {
        // Measured worst on the matrix: 5.6e-16 (g = 0.999, μ = 0.3); on a dense grid of ~1200 g
        // (log-spaced to 1e-15 from 0 and from ±1) × 800 μ: 7.9e-16.
        let mut worst: f64 = 0.0;
        for g in G_MATRIX {
            for mu in MU_MATRIX {
                worst = worst.max(rel_err(hg::phase(mu, g), phase_ref(mu, g)));
            }
        }
        assert!(worst <= 1e-13, "worst relative error {worst:e}");
    }

    #[test]
    fn cdf_per_azimuth_matches_reference_to_1e13_relative() {
        // Measured worst on the matrix: 3.2e-16 (g = 1e-8, μ = −1 + 1e-12); dense grid: 6.9e-16.
        // (With twofloat's own division in the reference this read 1.3e-15: the reference, not
        // the production code, was the less accurate side — see `dd_div`.)
        let mut worst: f64 = 0.0;
        for g in G_MATRIX {
            for mu in MU_MATRIX {
                worst = worst.max(rel_err(hg::cdf_per_azimuth(mu, g), cdf_per_azimuth_ref(mu, g)));
                let c = hg::cdf(mu, g);
                let c_ref = std::f64::consts::TAU * cdf_per_azimuth_ref(mu, g);
                assert!((c - c_ref).abs() <= 1e-15, "cdf({mu}, {g}): {c} vs {c_ref}");
            }
        }
        assert!(worst <= 1e-13, "worst relative error {worst:e}");
    }

    #[test]
    fn sample_mu_matches_reference_to_1e13_absolute() {
        // Measured worst on the matrix: 1.7e-16 (g = 0.1, ξ = 0.5); dense grid: 5.1e-16.
        let mut worst: f64 = 0.0;
        for g in G_MATRIX {
            for xi in XI_MATRIX {
                worst = worst.max((hg::sample_mu(xi, g) - sample_mu_ref(xi, g)).abs());
            }
        }
        assert!(worst <= 1e-13, "worst absolute error {worst:e}");
    }

    #[test]
    fn legendre_moments_match_quadrature_to_1e12_absolute() {
        // Measured worst on the matrix: 6.7e-16 (g = 1e-8, l = 0); over 170 g values in
        // [−0.999999, 0.999999] and l ≤ 64: 7.8e-16.
        let mut worst: f64 = 0.0;
        for g in G_MATRIX {
            for l in MOMENT_ORDERS {
                let e = (hg::legendre_moment(l, g) - legendre_moment_quadrature(l, g)).abs();
                worst = worst.max(e);
            }
        }
        assert!(worst <= 1e-12, "worst absolute error {worst:e}");
        // ZH coefficients are the same moments times the y_l^0 normalisation.
        let zh = hg::zh_coefficient(5, 0.7);
        let q = (11.0 / (4.0 * std::f64::consts::PI)).sqrt() * legendre_moment_quadrature(5, 0.7);
        assert!((zh - q).abs() <= 1e-14);
    }

    #[test]
    fn legendre_moments_match_quadrature_at_high_orders() {
        // Tables may store up to l = 4096. Measured worst: 6.7e-16. Before the fixes this read
        // 4.7e-12 (plain Legendre recurrence in the quadrature) and 4e-14 (g^l by binary
        // powering in production).
        for l in [512, 4096] {
            for g in [-0.999_999, 0.5, 0.9999, 0.999_999] {
                let e = (hg::legendre_moment(l, g) - legendre_moment_quadrature(l, g)).abs();
                assert!(e <= 1e-14, "l = {l}, g = {g}: {e:e}");
            }
        }
    }

    #[test]
    fn phase_is_normalised_over_the_sphere() {
        for g in dense_g_list() {
            let norm = legendre_moment_quadrature(0, g);
            assert!((norm - 1.0).abs() <= 1e-14, "∫ f dω = {norm} for g = {g}");
        }
    }

    #[test]
    fn worst_error_summary_is_within_the_tested_bounds() {
        let s = worst_errors_on_matrix();
        assert!(s.phase_rel <= 1e-13 && s.cdf_rel <= 1e-13, "{s:?}");
        assert!(s.sample_abs <= 1e-13 && s.moment_abs <= 1e-12, "{s:?}");
    }

    #[test]
    fn g_to_zero_is_continuous() {
        let ulp = |x: f64| f64::EPSILON * x.abs().max(f64::MIN_POSITIVE);
        for g in [1e-300, -1e-300, 5e-324, -5e-324] {
            for mu in MU_MATRIX {
                let (a, b) = (hg::cdf_per_azimuth(mu, g), hg::cdf_per_azimuth(mu, 0.0));
                assert!((a - b).abs() <= ulp(b), "F({mu}, {g}) = {a} vs F({mu}, 0) = {b}");
                assert!((hg::phase(mu, g) - hg::phase(mu, 0.0)).abs() <= ulp(hg::phase(mu, 0.0)));
                let (ra, rb) = (cdf_per_azimuth_ref(mu, g), cdf_per_azimuth_ref(mu, 0.0));
                assert!((ra - rb).abs() <= ulp(rb));
            }
            for xi in XI_MATRIX {
                let (a, b) = (hg::sample_mu(xi, g), hg::sample_mu(xi, 0.0));
                assert!((a - b).abs() <= f64::EPSILON, "mu({xi}, {g}) = {a} vs {b}");
                assert!((sample_mu_ref(xi, g) - sample_mu_ref(xi, 0.0)).abs() <= f64::EPSILON);
            }
        }
    }

    #[test]
    fn naive_closed_form_cancels_where_the_stable_form_does_not() {
        // elek2014's closed form in plain f64 at g = 1e-10 (measured): 8.3e-8 relative error at
        // μ = 0.3 (≈ u/g · O(0.1)), and 100 % at μ = −1 + 1e-12 (it returns 0). The sampler's
        // textbook inverse is off by 3.3e-8 absolute. The stable forms stay at rounding level.
        let pi = std::f64::consts::PI;
        let naive_f = |mu: f64, g: f64| {
            (1.0 - g * g) / (4.0 * pi * g) * (1.0 / (1.0 + g * g - 2.0 * g * mu).sqrt() - 1.0 / (1.0 + g))
        };
        let naive_mu = |xi: f64, g: f64| {
            let x = (1.0 - g * g) / (1.0 - g + 2.0 * g * xi);
            (1.0 + g * g - x * x) / (2.0 * g)
        };
        let g = 1e-10;
        for (mu, naive_at_least) in [(0.3, 1e-8), (-1.0 + 1e-12, 0.5)] {
            let r = cdf_per_azimuth_ref(mu, g);
            assert!(rel_err(naive_f(mu, g), r) > naive_at_least);
            assert!(rel_err(hg::cdf_per_azimuth(mu, g), r) <= 1e-15);
        }
        let r = sample_mu_ref(0.3, g);
        assert!((naive_mu(0.3, g) - r).abs() > 1e-8);
        assert!((hg::sample_mu(0.3, g) - r).abs() <= 1e-15);
    }

    #[test]
    fn sampler_inverts_the_cdf_to_one_ulp_of_mu() {
        // |cdf(sample_mu(ξ)) − ξ| itself can be large where the CDF is steeper than f64 can
        // resolve: g = −0.9999999, ξ = 0.0055 maps to 1 + μ ≈ 5.5e-17 < ulp(−1), i.e. μ = −1,
        // cdf = 0. The real invariant: ξ lies between the CDF at the neighbours of μ.
        let mut xis: Vec<f64> = (0..=4000).map(|i| f64::from(i) / 4000.0).collect();
        for k in 0..400 {
            let d = 10f64.powf(-16.0 + 15.0 * f64::from(k) / 400.0);
            xis.extend([d, 1.0 - d]);
        }
        for g in dense_g_list() {
            for &xi in &xis {
                let m = hg::sample_mu(xi, g);
                let lo = hg::cdf(m.next_down(), g) - 1e-15;
                let hi = hg::cdf(m.next_up(), g) + 1e-15;
                assert!(lo <= xi && xi <= hi, "g={g} xi={xi} mu={m}");
            }
        }
    }

    #[test]
    fn chi_square_of_sampler_against_cdf_is_pinned() {
        // 4096 van der Corput points shifted to the cell midpoints, (j + ½)/4096: no point lies
        // within 2/81920 of a bin edge k/20 (20j + 10 − 4096k ≡ 2 mod 4 ≠ 0), far more than the
        // ~1e-15 round-trip error, so binning cdf(sample_mu(ξ)) into 20 equal-probability bins
        // must reproduce the binning of ξ exactly: 16 bins of 205 and 4 of 204, χ² = 0.015625
        // (χ²₁₉ at p = 0.001 would be 43.8).
        const N: u32 = 4096;
        const BINS: usize = 20;
        let expected = f64::from(N) / BINS as f64;
        for g in [-0.9, 0.0, 0.5, 0.99] {
            let (mut counts, mut counts_xi) = ([0u32; BINS], [0u32; BINS]);
            for i in 0..N {
                let xi = (f64::from(i.reverse_bits()) + 0.5 * f64::from(1u32 << 20)) / 2f64.powi(32);
                let p = hg::cdf(hg::sample_mu(xi, g), g);
                counts[((p * BINS as f64) as usize).min(BINS - 1)] += 1;
                counts_xi[((xi * BINS as f64) as usize).min(BINS - 1)] += 1;
            }
            assert_eq!(counts, counts_xi, "g = {g}");
            assert!(counts.iter().all(|&c| c == 204 || c == 205), "{counts:?}");
            let chi2: f64 = counts.iter().map(|&c| (f64::from(c) - expected).powi(2) / expected).sum();
            assert!((chi2 - 0.015625).abs() < 1e-12, "chi2 = {chi2} for g = {g}");
        }
    }

    #[test]
    fn chi_square_of_sampler_with_pseudo_random_points_is_plausible() {
        // Fixed xorshift stream, 100 000 points: the statistic is that of uniform variates binned
        // (mean 19); deterministic, so it either passes forever or never. Bound: χ²₁₉(0.999) = 43.8.
        const N: u32 = 100_000;
        const BINS: usize = 20;
        for g in [-0.9, 0.0, 0.5, 0.99] {
            let mut next = uniforms(0x9E37_79B9_7F4A_7C15);
            let mut counts = [0u32; BINS];
            for _ in 0..N {
                let p = hg::cdf(hg::sample_mu(next(), g), g);
                counts[((p * BINS as f64) as usize).min(BINS - 1)] += 1;
            }
            let expected = f64::from(N) / BINS as f64;
            let chi2: f64 = counts.iter().map(|&c| (f64::from(c) - expected).powi(2) / expected).sum();
            assert!(chi2 < 43.8, "chi2 = {chi2} for g = {g}");
        }
    }

    #[test]
    fn reference_taylor_coefficients_match_the_closed_forms() {
        // At |g| = 1e-6 the O(g³) truncation is ~1e-17 and the closed forms lose only 6 of ~32
        // digits; a wrong second-order coefficient would show as ~g² = 1e-12.
        for g in [1e-6, -1e-6] {
            for mu in [-1.0 + 1e-3, -0.5, 0.0, 0.3, 0.9, 1.0] {
                assert!(dd_rel(phase_taylor(mu, g), phase_closed(mu, g)) < 1e-15);
                assert!(dd_rel(cdf_taylor(mu, g), cdf_closed(mu, g)) < 1e-15, "{mu} {g}");
            }
            for xi in [1e-3, 0.1, 0.25, 0.5, 0.8, 1.0] {
                assert!((sample_taylor(xi, g) - sample_closed(xi, g)).hi().abs() < 1e-15);
            }
        }
    }

    #[test]
    fn reference_is_continuous_across_the_taylor_switch() {
        for g in [TAYLOR_G_MAX, -TAYLOR_G_MAX] {
            let inside = if g > 0.0 { g.next_down() } else { g.next_up() };
            for mu in MU_MATRIX {
                assert!(rel_err(phase_ref(mu, inside), phase_ref(mu, g)) <= 2.0 * f64::EPSILON);
                let (a, b) = (cdf_per_azimuth_ref(mu, inside), cdf_per_azimuth_ref(mu, g));
                assert!(rel_err(a, b) <= 2.0 * f64::EPSILON, "{mu}: {a} vs {b}");
            }
            for xi in XI_MATRIX {
                assert!((sample_mu_ref(xi, inside) - sample_mu_ref(xi, g)).abs() <= f64::EPSILON);
            }
        }
    }

    #[test]
    fn reference_series_branch_matches_the_closed_form_where_both_are_accurate() {
        // The closed form loses a factor ~2/|w| of ~1e-31; 12 series terms truncate at |w|^13.
        // 1e-6 ≤ |w| ≤ 1.3e-2: both are good to ≲ 1e-24, so this checks the series itself.
        for g in [0.5, -0.5, 0.999, 0.01] {
            for one_plus_mu in [1e-4, 3e-4, 1e-3, 3e-3] {
                let mu = -1.0 + one_plus_mu;
                let w = cdf_w(mu, g).hi().abs();
                assert!((1e-6..=1.3e-2).contains(&w), "w = {w}");
                assert!(dd_rel(cdf_series(mu, g), cdf_closed(mu, g)) < 1e-20, "{g} {mu} w={w}");
            }
        }
        // Around the switch |w| = 1e-12 the closed form is still good to ~1e-18.
        for (g, one_plus_mu) in [(0.5, 1e-12), (0.5, 2.25e-12), (0.5, 1e-11), (-0.5, 2.5e-13)] {
            let mu = -1.0 + one_plus_mu;
            let w = cdf_w(mu, g).hi().abs();
            assert!((2e-13..=5e-12).contains(&w), "w = {w}");
            assert!(dd_rel(cdf_series(mu, g), cdf_closed(mu, g)) < 1e-17, "{g} {mu} w={w}");
        }
    }

    #[test]
    fn dd_div_is_double_double_accurate_unlike_twofloat_division() {
        // twofloat 0.8.4's `TwoFloat / TwoFloat` measured here: ~1.1e-16 worst relative residual.
        let mut next = uniforms(0x0123_4567_89AB_CDEF);
        let mut worst: f64 = 0.0;
        for _ in 0..20_000 {
            let a = Dd::new_add(0.5 + next(), 1e-17 * next());
            let b = Dd::new_add(0.5 + next(), 1e-17 * next());
            let q = dd_div(a, b);
            worst = worst.max(((a - q * b).hi() / a.hi()).abs());
        }
        assert!(worst < 1e-30, "dd_div residual {worst:e}");
    }

    #[test]
    fn gauss_legendre_rule_integrates_degree_63_exactly() {
        for k in 0..64 {
            let exact = if k % 2 == 0 { 2.0 / f64::from(k + 1) } else { 0.0 };
            let got = legendre_quadrature(&[-1.0, 1.0], 0, |x| (x.powi(k), 0.0));
            assert!((got - exact).abs() <= 1e-15, "x^{k}: {got} vs {exact}");
        }
    }

    #[test]
    fn legendre_evaluations_match_a_double_double_recurrence() {
        // Plain recurrence in double-double (division by an exact f64 is accurate in twofloat),
        // at `x` given exactly as a double-double (the batch takes `t = 1 − x`, which `f64` `x`
        // could not represent near 1).
        let legendre_dd = |l: u32, x: Dd| {
            let (mut prev, mut cur) = (Dd::from(1.0), x);
            for k in 1..l.max(1) {
                let k = f64::from(k);
                let next = ((2.0 * k + 1.0) * x * cur - k * prev) / (k + 1.0);
                prev = cur;
                cur = next;
            }
            if l == 0 { 1.0 } else { cur.hi() }
        };
        let plain = |l: u32, x: f64| {
            let (mut prev, mut cur) = (1.0, x);
            for k in 1..l {
                let k = f64::from(k);
                let next = ((2.0 * k + 1.0) * x * cur - k * prev) / (k + 1.0);
                prev = cur;
                cur = next;
            }
            cur
        };
        let ts = [0.0, 1e-12, 1e-8, 1e-6, 1e-5, 1e-4, 1e-3, 0.003, 0.01, 0.05, 0.2, 0.5, 0.9, 1.0];
        let mut batch_t = [0.0; GL_NODES];
        for (i, &t) in ts.iter().enumerate() {
            batch_t[i] = t;
            batch_t[GL_NODES - 1 - i] = 2.0 - t;
        }
        // Measured worst: 2.9e-15 (l = 4096).
        for l in [0, 1, 2, 5, 16, 64, 512, 4096] {
            let batch = legendre_batch(l, &batch_t);
            for (i, &t) in batch_t.iter().enumerate() {
                let exact = legendre_dd(l, Dd::new_sub(1.0, t));
                assert!((batch[i] - exact).abs() <= 1e-14, "ref P_{l}(1 - {t})");
                let x = 1.0 - t;
                let exact = legendre_dd(l, Dd::from(x));
                assert!((hg::legendre_p(l, x) - exact).abs() <= 1e-14, "hg P_{l}({x})");
            }
        }
        // What the difference form fixes: the plain f64 recurrence near x = 1 at l = 4096
        // (measured 2.2e-12 on these points, 2.5e-10 on a dense grid of t ∈ (0, 0.05]).
        let worst_plain =
            ts.iter().map(|&t| (plain(4096, 1.0 - t) - legendre_dd(4096, Dd::from(1.0 - t))).abs()).fold(0.0, f64::max);
        assert!(worst_plain > 1e-12, "{worst_plain:e}");
    }

    #[test]
    fn reference_invalid_inputs_give_nan() {
        for g in [1.0, -1.0, 2.0, f64::NAN, f64::INFINITY] {
            assert!(phase_ref(0.0, g).is_nan());
            assert!(cdf_per_azimuth_ref(0.0, g).is_nan());
            assert!(sample_mu_ref(0.5, g).is_nan());
            assert!(legendre_moment_quadrature(2, g).is_nan());
        }
        assert!(phase_ref(f64::NAN, 0.5).is_nan());
        assert!(cdf_per_azimuth_ref(f64::NAN, 0.5).is_nan());
        assert!(sample_mu_ref(f64::NAN, 0.5).is_nan());
        assert_eq!(cdf_per_azimuth_ref(7.0, 0.5), cdf_per_azimuth_ref(1.0, 0.5));
        assert_eq!(sample_mu_ref(-3.0, 0.5), -1.0);
    }
}
