//! Orders beyond the traced ones: the density of the `k`-th collision for large `k` by the central
//! limit theorem, summed over `k > K` with albedo weights.
//!
//! **Input → output.** `(α, g, K, ρ, z)` → `Σ_{k>K} α^k ψ_k(ρ, z)` [1/mfp³], with `ψ_k` the Gaussian
//! whose mean and mean-square displacement are the walk's exact moments ([`collision_moments`]). The
//! sum over `k` is an integral (Euler–Maclaurin, the terms vary on a scale `~K`) on the substitution
//! `k = (K + ½)/w²`, which maps the `k^{−3/2}` tail of `α = 1` to a bounded integrand on `w ∈ (0, 1]`.

use std::f64::consts::PI;

/// Mean `z` and per-coordinate variance of the position of the `k`-th collision of a photon leaving
/// the origin along `+z` (σ_t = 1, HG `g`): flights are exponential (`E ℓ = 1`, `E ℓ² = 2`) and the
/// direction after `j` scatterings has mean `g^j ẑ` with `E[ω_i·ω_j] = g^{|i−j|}`, so
/// `E X = (1 − g^k)/(1 − g) ẑ` and `E|X|² = 2k + 2 Σ_{d=1}^{k−1} (k − d) g^d`. The variance is the
/// mean-square about the mean, split evenly over the three coordinates (exact as `k → ∞`).
pub fn collision_moments(g: f64, k: f64) -> (f64, f64) {
    // g^k for real k ≥ 0 (g < 0: |g|^k with the sign of an integer k; the closure only needs large k,
    // where |g|^k is negligible anyway).
    let gk = if g == 0.0 { 0.0 } else { g.abs().powf(k) * if g < 0.0 && (k as i64) % 2 == 1 { -1.0 } else { 1.0 } };
    let omg = 1.0 - g;
    let mean = (1.0 - gk) / omg;
    // Σ_{d=1}^{k−1} (k − d) g^d = [g k (1 − g) − g (1 − g^k)] / (1 − g)².
    let s = if g == 0.0 { 0.0 } else { (g * k * omg - g * (1.0 - gk)) / (omg * omg) };
    let msd = 2.0 * k + 2.0 * s;
    let var = ((msd - mean * mean) / 3.0).max(1e-300);
    (mean, var)
}

/// Gauss–Legendre panels of the `w` integral.
const PANELS: usize = 8;

/// `Σ_{k>K} α^k ψ_k(ρ, z)` with `ψ_k` the Gaussian of [`collision_moments`] [1/mfp³]. Zero for
/// `α = 0`; finite at `α = 1` (the `k^{−3/2}` tail converges).
pub fn remainder(albedo: f64, g: f64, max_order: usize, rho: f64, z: f64) -> f64 {
    if albedo.is_nan() || albedo <= 0.0 {
        return 0.0;
    }
    let k0 = max_order as f64 + 0.5;
    let ln_a = albedo.ln();
    static NODES: std::sync::OnceLock<Vec<(f64, f64)>> = std::sync::OnceLock::new();
    let nodes = NODES.get_or_init(|| crate::physics::sh::gauss_legendre(16));
    let mut sum = 0.0;
    for p in 0..PANELS {
        let (lo, hi) = (p as f64 / PANELS as f64, (p + 1) as f64 / PANELS as f64);
        for &(x, w) in nodes {
            let wv = lo + (hi - lo) * 0.5 * (x + 1.0);
            if wv <= 0.0 {
                continue;
            }
            let k = k0 / (wv * wv);
            let (mean, var) = collision_moments(g, k);
            let r2 = rho * rho + (z - mean) * (z - mean);
            let log_term = k * ln_a - 1.5 * (2.0 * PI * var).ln() - r2 / (2.0 * var);
            let jac = 2.0 * k0 / (wv * wv * wv);
            sum += 0.5 * (hi - lo) * w * jac * log_term.exp();
        }
    }
    if sum.is_finite() { sum } else { 0.0 }
}

/// Spatial decay rate used beyond the grid: the diffusion rate `√(3(1 − α)(1 − αg))` of the fluence
/// (`e^{−κ r}/r`), never faster than the unscattered flight's `e^{−r}`.
pub fn decay_rate(albedo: f64, g: f64) -> f64 {
    (3.0 * (1.0 - albedo).max(0.0) * (1.0 - albedo * g).max(0.0)).sqrt().min(1.0)
}
