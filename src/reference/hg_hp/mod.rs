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
mod tests;
