//! Quadrature rules of the response generator: a composite rule graded geometrically toward both ends
//! of an interval, built from the crate's Gauss–Legendre rule ([`crate::physics::sh::gauss_legendre`]).
//!
//! The graded rule returns every node as its distance to *both* ends, each formed without cancellation,
//! because the integrands of the parent module are evaluated through `sin`/`tan` of those distances near
//! their end points (where `b − x` computed from `x` would lose every digit).

/// Ratio between the lengths of consecutive panels of the graded rule.
pub(super) const GRADING: f64 = 0.125;

/// Number of geometric refinement levels toward each end (smallest panel `8⁻⁷ ≈ 4.8e-7` of a half).
pub(super) const LEVELS: i32 = 7;

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
/// carrying the `base` rule (a [`crate::physics::sh::gauss_legendre`] rule). Integrates smooth functions with boundary layers
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
