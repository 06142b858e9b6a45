//! Low-rank factorisation of the visibility-free integrand `I(γ, β) ≈ Σ_i Γ_i(γ)·B_i(β)` (baran2010
//! Sec. 6), shared by all slices.
//!
//! **Input → output.** The frame's `β` range and largest `γ`, the light geometry and the medium → per
//! kernel (one, or one per channel when `σ_t` differs between channels) `N` functions `Γ_i` on the
//! integration grid's `γ` bins and `B_i` at any `β`.
//!
//! The integrand per unit `γ` is `a(β)·K̃(γ, β)`:
//! - directional: `a = p(cos β)/sin β`, `K̃ = e^{−σ_t γ tan(β/2)}`: the view-ray attenuation
//!   `e^{−σ_t s}` (path length `s = γ/sin β`, `ds/dγ = 1/sin β`) times the light's attenuation from the
//!   eye's plane, `e^{σ_t s cos β}` (the per-light-ray rest `e^{−σ_t a_entry(γ)}` is applied outside,
//!   module doc of [`super`]); `s(1 − cos β) = γ tan(β/2)`;
//! - spot (Sec. 9, triangle eye–light–point with angles `β`, `γ`): `a = 1/(D sin β)`,
//!   `K̃ = p(cos(β+γ))·e^{−σ_t D (sin γ + sin β)/sin(β+γ)}` (0 for `β + γ ≥ π`), which is
//!   `p·e^{−σ_t(s+r)}·(ds/dγ)/r²` with `s = D sin γ/sin(β+γ)`, `r = D sin β/sin(β+γ)`.
//!
//! `a(β)` is kept exact and only `K̃` is factorised: `K̃` is bin-averaged over each `γ` bin (exactly for
//! directional lights, 2-point Gauss for spots, so a bin holds the integral over it even when the fog
//! decays within one bin), sampled on 128 `γ` nodes × 64 `β` nodes, decomposed by a one-sided Jacobi
//! SVD, truncated to rank `N`; `Γ_i` is extended to every bin exactly (`Γ_i(γ) = Σ_n K̃(γ, β_n)·V_ni/s_i`,
//! the Nyström extension of the left singular vectors) and `B_i = a(β)·s_i·V_i` is interpolated
//! linearly between the 64 `β` nodes (uniform in `ln tan(β/2)`). The light's strength, `σ_s`, texture
//! and (directional) entry attenuation are applied outside.

use rayon::prelude::*;

use super::rectify::{Geo, Setup};
use super::{EpiMedium, EpipolarOptions, exp_integral};

const GAMMA_NODES: usize = 128;
pub(crate) const BETA_NODES: usize = 64;

/// The factorisation of one frame.
#[derive(Debug, Clone, PartialEq)]
pub struct Factorization {
    /// Distinct kernels (1 when `σ_t` is grey, else 3).
    pub kernels: usize,
    /// Rank `N` actually used.
    pub rank: usize,
    /// Integration bins along `γ`.
    pub bins: usize,
    /// Bin width.
    pub dgamma: f64,
    /// `Γ[k][i][j]`, flattened `(k·rank + i)·bins + j`.
    pub gamma_fn: Vec<f64>,
    /// `ln tan(β/2)` at the ends of the `β` range.
    pub(crate) x_range: (f64, f64),
    /// `s_i·V[n][i]` flattened `(k·rank + i)·BETA_NODES + n`.
    pub(crate) bnode: Vec<f64>,
    geo: Geo,
    phase_g: EpiMedium,
    /// `s_N/s_0` of the first kernel (0 when the rank is complete).
    pub residual: f64,
}

impl Factorization {
    /// Factorises the frame's integrand.
    pub fn new(setup: &Setup, medium: &EpiMedium, opts: &EpipolarOptions) -> Factorization {
        Factorization::from_extent(setup.geo, setup.beta_range, setup.gamma_max, medium, opts)
    }

    /// Factorises the integrand over `β ∈ beta_range`, `γ ∈ [0, gamma_max]` (what [`Factorization::new`]
    /// reads off a [`Setup`]; the GPU path measures `gamma_max` on the device).
    pub fn from_extent(
        geo: Geo,
        beta_range: (f64, f64),
        gamma_max: f64,
        medium: &EpiMedium,
        opts: &EpipolarOptions,
    ) -> Factorization {
        let st = medium.sigma_t();
        let grey = st[0] == st[1] && st[1] == st[2];
        let kernels = if grey { 1 } else { 3 };
        let bins = opts.gamma_bins.clamp(2, 1 << 20);
        let gmax = if gamma_max.is_finite() && gamma_max > 0.0 { gamma_max } else { 1e-6 };
        let dgamma = gmax / bins as f64;
        let (mut beta_lo, mut beta_hi) = beta_range;
        if !(beta_lo.is_finite() && beta_hi.is_finite() && beta_hi > beta_lo) {
            beta_lo = 1e-3;
            beta_hi = beta_lo + 1e-3;
        }
        let rank = opts.rank.clamp(1, BETA_NODES);
        let (x_lo, x_hi) = (beta_param(beta_lo), beta_param(beta_hi));
        let bnodes: Vec<f64> = (0..BETA_NODES)
            .map(|n| beta_from_param(x_lo + (x_hi - x_lo) * n as f64 / (BETA_NODES - 1) as f64))
            .collect();
        let gnodes: Vec<usize> =
            (0..GAMMA_NODES).map(|m| ((m * (bins - 1)) as f64 / (GAMMA_NODES - 1) as f64).round() as usize).collect();
        let mut gamma_fn = vec![0.0; kernels * rank * bins];
        let mut bnode = vec![0.0; kernels * rank * BETA_NODES];
        let mut residual = 0.0;
        for k in 0..kernels {
            let sig = st[k];
            let kt = |j: usize, beta: f64| kernel_bin(geo, medium, sig, (j as f64 + 0.5) * dgamma, dgamma, beta);
            // Column-major matrix: column n = β node, row m = γ node.
            let mut a: Vec<f64> = Vec::with_capacity(GAMMA_NODES * BETA_NODES);
            for &b in &bnodes {
                for &j in &gnodes {
                    a.push(kt(j, b));
                }
            }
            let (s, v) = jacobi_svd(&mut a, GAMMA_NODES, BETA_NODES);
            if k == 0 {
                residual = if rank < BETA_NODES && s[0] > 0.0 { s[rank] / s[0] } else { 0.0 };
            }
            for i in 0..rank {
                for n in 0..BETA_NODES {
                    bnode[(k * rank + i) * BETA_NODES + n] = s[i] * v[n * BETA_NODES + i];
                }
            }
            let inv: Vec<f64> =
                (0..rank).map(|i| if s[i] > 1e-300 && s[i] > 1e-14 * s[0] { 1.0 / s[i] } else { 0.0 }).collect();
            let cols: Vec<Vec<f64>> = (0..bins)
                .into_par_iter()
                .map(|j| {
                    let kv: Vec<f64> = bnodes.iter().map(|&b| kt(j, b)).collect();
                    (0..rank)
                        .map(|i| (0..BETA_NODES).map(|n| kv[n] * v[n * BETA_NODES + i]).sum::<f64>() * inv[i])
                        .collect()
                })
                .collect();
            for (j, c) in cols.iter().enumerate() {
                for i in 0..rank {
                    gamma_fn[(k * rank + i) * bins + j] = c[i];
                }
            }
        }
        Factorization {
            kernels,
            rank,
            bins,
            dgamma,
            gamma_fn,
            x_range: (x_lo, x_hi),
            bnode,
            geo,
            phase_g: *medium,
            residual,
        }
    }

    /// `B_i(β)` of every kernel `k` and term `i` into `out[k·rank + i]` (including the exact factor
    /// `a(β)`).
    pub fn b_all(&self, beta: f64, out: &mut [f64]) {
        let (x_lo, x_hi) = (self.x_range.0, self.x_range.1);
        let pos =
            ((beta_param(beta) - x_lo) / (x_hi - x_lo) * (BETA_NODES - 1) as f64).clamp(0.0, (BETA_NODES - 1) as f64);
        let n0 = (pos.floor() as usize).min(BETA_NODES - 2);
        let f = pos - n0 as f64;
        let a = beta_factor(self.geo, &self.phase_g, beta);
        for (ki, o) in out.iter_mut().enumerate().take(self.kernels * self.rank) {
            let row = &self.bnode[ki * BETA_NODES..];
            *o = ((1.0 - f) * row[n0] + f * row[n0 + 1]) * a;
        }
    }
}

/// The `β` node parameter `ln tan(β/2)`: nodes uniform in it crowd towards the epipole and the
/// anti-epipole, where `K̃` varies fastest.
fn beta_param(beta: f64) -> f64 {
    (0.5 * beta.clamp(1e-9, std::f64::consts::PI - 1e-9)).tan().ln()
}

fn beta_from_param(x: f64) -> f64 {
    2.0 * x.exp().atan()
}

/// `a(β)` (module doc).
pub fn beta_factor(geo: Geo, medium: &EpiMedium, beta: f64) -> f64 {
    let sb = beta.sin().max(1e-12);
    match geo {
        Geo::Directional { .. } => medium.phase(beta.cos()) / sb,
        Geo::Spot { dist, .. } => 1.0 / (dist * sb),
    }
}

/// `K̃` averaged over the bin `[g − w/2, g + w/2]` (clipped at 0) for extinction `sigma`.
pub fn kernel_bin(geo: Geo, medium: &EpiMedium, sigma: f64, g: f64, w: f64, beta: f64) -> f64 {
    let lo = (g - 0.5 * w).max(0.0);
    let hi = g + 0.5 * w;
    if hi <= lo {
        return 0.0;
    }
    match geo {
        Geo::Directional { .. } => {
            let c = sigma * (0.5 * beta.clamp(0.0, std::f64::consts::PI - 1e-12)).tan();
            exp_integral(c, lo, hi) / (hi - lo)
        }
        Geo::Spot { dist, .. } => {
            let (m, r) = (0.5 * (lo + hi), 0.5 * (hi - lo) / 3f64.sqrt());
            0.5 * (spot_kernel(dist, medium, sigma, m - r, beta) + spot_kernel(dist, medium, sigma, m + r, beta))
        }
    }
}

fn spot_kernel(dist: f64, medium: &EpiMedium, sigma: f64, gamma: f64, beta: f64) -> f64 {
    let sum = beta + gamma;
    if sum >= std::f64::consts::PI {
        return 0.0;
    }
    let ssum = sum.sin();
    if ssum <= 0.0 {
        return 0.0;
    }
    let path = dist * (gamma.sin() + beta.sin()) / ssum;
    let v = medium.phase(sum.cos()) * (-sigma * path).exp();
    if v.is_finite() { v } else { 0.0 }
}

/// One-sided Jacobi SVD of the column-major `m × n` matrix `a` (overwritten): singular values
/// (descending) and `V` (`n × n`, row-major `v[row·n + col]`, columns sorted like the values).
pub fn jacobi_svd(a: &mut [f64], m: usize, n: usize) -> (Vec<f64>, Vec<f64>) {
    let mut v = vec![0.0; n * n];
    for i in 0..n {
        v[i * n + i] = 1.0;
    }
    for _sweep in 0..60 {
        let mut rotated = false;
        for p in 0..n {
            for q in p + 1..n {
                let (mut alpha, mut beta, mut gamma) = (0.0, 0.0, 0.0);
                for r in 0..m {
                    let (x, y) = (a[p * m + r], a[q * m + r]);
                    alpha += x * x;
                    beta += y * y;
                    gamma += x * y;
                }
                if gamma == 0.0 || gamma.abs() <= 1e-15 * (alpha * beta).sqrt() {
                    continue;
                }
                rotated = true;
                let zeta = (beta - alpha) / (2.0 * gamma);
                let t = zeta.signum() / (zeta.abs() + (1.0 + zeta * zeta).sqrt());
                let c = 1.0 / (1.0 + t * t).sqrt();
                let s = c * t;
                for r in 0..m {
                    let (x, y) = (a[p * m + r], a[q * m + r]);
                    a[p * m + r] = c * x - s * y;
                    a[q * m + r] = s * x + c * y;
                }
                for r in 0..n {
                    let (x, y) = (v[r * n + p], v[r * n + q]);
                    v[r * n + p] = c * x - s * y;
                    v[r * n + q] = s * x + c * y;
                }
            }
        }
        if !rotated {
            break;
        }
    }
    let norms: Vec<f64> = (0..n).map(|p| (0..m).map(|r| a[p * m + r] * a[p * m + r]).sum::<f64>().sqrt()).collect();
    let mut order: Vec<usize> = (0..n).collect();
    order.sort_by(|&x, &y| norms[y].total_cmp(&norms[x]));
    let s: Vec<f64> = order.iter().map(|&i| norms[i]).collect();
    let mut vs = vec![0.0; n * n];
    for r in 0..n {
        for (c, &o) in order.iter().enumerate() {
            vs[r * n + c] = v[r * n + o];
        }
    }
    (s, vs)
}
