//! The references' own Gauss–Legendre rule: `n` → nodes and weights on `[−1, 1]` by Newton's method on
//! the three-term recurrence. Kept apart from `physics::sh::gauss_legendre` (the methods' rule) so that
//! a reference shares no code with what it judges; used by `beam_adjoint` and the references' tests.

use std::f64::consts::PI;

/// `n`-point Gauss–Legendre rule on `[−1, 1]` as `(node, weight)`: Newton's method on `P_n` from
/// the asymptotic guesses `cos(π(i + 3/4)/(n + 1/2))`, weights `2/((1 − x²) P_n'(x)²)`.
pub fn gauss_legendre(n: usize) -> Vec<(f64, f64)> {
    (0..n)
        .map(|i| {
            let mut x = (PI * (i as f64 + 0.75) / (n as f64 + 0.5)).cos();
            for _ in 0..100 {
                let (p, dp) = legendre_with_derivative(n, x);
                let step = p / dp;
                x -= step;
                if step.abs() <= 1e-16 {
                    break;
                }
            }
            let (_, dp) = legendre_with_derivative(n, x);
            (x, 2.0 / ((1.0 - x * x) * dp * dp))
        })
        .collect()
}

/// `(P_n(x), P_n'(x))` by the three-term recurrence, for `|x| < 1`.
fn legendre_with_derivative(n: usize, x: f64) -> (f64, f64) {
    let (mut prev, mut cur) = (1.0, x);
    for k in 1..n {
        let k = k as f64;
        let next = ((2.0 * k + 1.0) * x * cur - k * prev) / (k + 1.0);
        prev = cur;
        cur = next;
    }
    (cur, n as f64 * (x * cur - prev) / (x * x - 1.0))
}
