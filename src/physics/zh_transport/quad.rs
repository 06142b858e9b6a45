//! Quadrature rules of the response generator: Gauss–Legendre on `[−1, 1]` (Newton iteration on the
//! three-term recurrence) and a composite rule graded geometrically toward both ends of an interval.
//!
//! The graded rule returns every node as its distance to *both* ends, each formed without cancellation,
//! because the integrands of the parent module are evaluated through `sin`/`tan` of those distances near
//! their end points (where `b − x` computed from `x` would lose every digit).

/// Ratio between the lengths of consecutive panels of the graded rule.
pub(super) const GRADING: f64 = 0.125;

/// Number of geometric refinement levels toward each end (smallest panel `8⁻⁷ ≈ 4.8e-7` of a half).
pub(super) const LEVELS: i32 = 7;

/// `n`-point Gauss–Legendre rule on `[−1, 1]` as `(node, weight)`, nodes ascending. `n = 0` gives no nodes.
pub(super) fn gauss_legendre(n: usize) -> Vec<(f64, f64)> {
    let nf = n as f64;
    let mut rule: Vec<(f64, f64)> = (0..n)
        .map(|i| {
            // Tricomi's initial guess, then Newton on P_n.
            let mut x = (std::f64::consts::PI * (i as f64 + 0.75) / (nf + 0.5)).cos();
            let mut dp = 1.0;
            for _ in 0..100 {
                let (p, d) = legendre_with_derivative(n, x);
                dp = d;
                let step = p / d;
                x -= step;
                if step.abs() < 1e-16 {
                    break;
                }
            }
            let (_, d) = legendre_with_derivative(n, x);
            if d.is_finite() {
                dp = d;
            }
            (x, 2.0 / ((1.0 - x * x) * dp * dp))
        })
        .collect();
    rule.sort_by(|a, b| a.0.total_cmp(&b.0));
    rule
}

/// `(P_n(x), P_n'(x))` by the three-term recurrence; requires `|x| < 1` for the derivative.
fn legendre_with_derivative(n: usize, x: f64) -> (f64, f64) {
    let (mut p0, mut p1) = (1.0, x);
    if n == 0 {
        return (1.0, 0.0);
    }
    for k in 1..n {
        let kf = k as f64;
        let p2 = ((2.0 * kf + 1.0) * x * p1 - kf * p0) / (kf + 1.0);
        (p0, p1) = (p1, p2);
    }
    let nf = n as f64;
    (p1, nf * (x * p1 - p0) / (x * x - 1.0))
}

/// A node of a graded rule on `[a, b]`: distances `lo = x − a` and `hi = b − x` (both accurate) and weight.
#[derive(Debug, Clone, Copy)]
pub(super) struct Node {
    /// Distance to the lower end.
    pub lo: f64,
    /// Distance to the upper end.
    pub hi: f64,
    /// Quadrature weight.
    pub w: f64,
}

/// Composite Gauss–Legendre rule on an interval of length `len ≥ 0`, graded toward both ends: each half
/// is split into panels whose lengths shrink by [`GRADING`] toward its end ([`LEVELS`] times), each panel
/// carrying the `base` rule (a [`gauss_legendre`] rule). Integrates smooth functions with boundary layers
/// (exponential cut-offs, peaked phase functions, integrable end singularities) of any width down to
/// `~len · 8⁻⁷`.
pub(super) fn graded(len: f64, base: &[(f64, f64)]) -> Vec<Node> {
    let half = 0.5 * len;
    let mut out = Vec::with_capacity(2 * base.len() * (LEVELS as usize + 1));
    let mut upper = half;
    for level in 0..=LEVELS {
        let lower = if level == LEVELS { 0.0 } else { half * GRADING.powi(level + 1) };
        let (mid, rad) = (0.5 * (upper + lower), 0.5 * (upper - lower));
        for &(x, w) in base {
            let u = mid + rad * x;
            let weight = rad * w;
            out.push(Node { lo: u, hi: len - u, w: weight });
            out.push(Node { lo: len - u, hi: u, w: weight });
        }
        upper = lower;
    }
    out
}
