//! One (emitter, g) slice of a `ZhResponse` table made ready for queries (dubouchet2019 Sec. 4): the
//! file's coefficients `[b][d][l]` → node-major `[d][b][l]` blocks with the log-linear interpolation
//! law of `zh_transport::Response::zh_at` and the tail closure precomputed.

use super::*;

/// Where a canonical distance falls on the axis.
#[derive(Debug, Clone, Copy)]
pub(super) enum Loc {
    /// Below the first node: per-bounce power law (point) or constant (directional).
    Below { ratio: f64 },
    /// Beyond the last node: the last node times `decay = e^{−Δd}`; `d` the distance.
    Above { decay: f64, d: f64 },
    /// Between nodes `i` and `i + 1` at `λ` (linear in `ln d`), `d` the distance.
    Between { i: usize, lambda: f64, d: f64 },
}

/// One (emitter, g) slice in node-major layout `[d][b][l]`, so one query reads two contiguous blocks,
/// with what the interpolation law of `zh_transport::Response::zh_at` needs precomputed.
#[derive(Debug, Clone)]
pub(super) struct Slice {
    pub(super) profile: EmitterProfile,
    pub(super) gi: usize,
    /// Raw coefficients, flat `[d][b][l]`.
    pub(super) raw: Vec<f64>,
    /// `c_l / c_0`, flat `[d][b][l]` (0 where `c_0 ≤ 0`).
    pub(super) shape: Vec<f64>,
    /// `ln c_0` per `[d][b]` (NaN where `c_0 ≤ 0`).
    pub(super) log_c0: Vec<f64>,
    /// Per bounce: power-law exponent below the first node (point tables), in `[−1, 0]`.
    pub(super) k_low: Vec<f64>,
    /// Tail closure `[albedo][d][l = 0, 1]` on [`super::TAIL_ALBEDOS`] (empty without one).
    pub(super) tail: Vec<f64>,
    /// Diffusion decay `ν` of the tail population per albedo node (`tail::diffusion`).
    pub(super) tail_nu: Vec<f64>,
    /// `ln c_0` of every tail entry `[albedo][d]` (NaN where `c_0 ≤ 0`), computed once at load.
    pub(super) tail_log_c0: Vec<f64>,
}

impl Slice {
    /// `values` in file layout `[b][d][l]`.
    pub(super) fn new(
        profile: EmitterProfile,
        gi: usize,
        values: &[f64],
        ds: &[f64],
        bounces: usize,
        order: usize,
    ) -> Self {
        let nd = ds.len();
        let mut raw = vec![0.0; values.len()];
        let mut shape = vec![0.0; values.len()];
        let mut log_c0 = vec![f64::NAN; nd * bounces];
        for b in 0..bounces {
            for i in 0..nd {
                let src = &values[(b * nd + i) * order..(b * nd + i + 1) * order];
                let dst = (i * bounces + b) * order;
                raw[dst..dst + order].copy_from_slice(src);
                if src[0] > 0.0 {
                    log_c0[i * bounces + b] = src[0].ln();
                    for (o, c) in shape[dst..dst + order].iter_mut().zip(src) {
                        *o = c / src[0];
                    }
                }
            }
        }
        let point = profile == EmitterProfile::Point;
        let k_low = (0..bounces)
            .map(|b| {
                let (c0, c1) = (values[b * nd * order], values[(b * nd + 1) * order]);
                if point && nd > 1 && c0 > 0.0 && c1 > 0.0 {
                    ((c0 / c1).ln() / (ds[0] / ds[1]).ln()).clamp(-1.0, 0.0)
                } else {
                    0.0
                }
            })
            .collect();
        Self { profile, gi, raw, shape, log_c0, k_low, tail: Vec::new(), tail_nu: Vec::new(), tail_log_c0: Vec::new() }
    }

    /// Tail `[c_0, c_1]` at albedo node `j` and located distance: `e^{ν d} c_0` geometric in `ln d` where
    /// positive at both nodes (else linear), the ratio `c_1/c_0` linear (`ν` the node's diffusion decay:
    /// exact for the far field `d^k e^{−ν d}`); held constant below the axis; beyond it the diffusion decay
    /// `e^{−ν Δd}` (point: times `d_last/d`), which never adds energy.
    pub(super) fn tail_at_node(&self, j: usize, loc: Loc, ds: &[f64]) -> [f64; 2] {
        let nd = ds.len();
        let at = |i: usize| {
            let k = (j * nd + i) * 2;
            [self.tail[k], self.tail[k + 1]]
        };
        match loc {
            Loc::Below { .. } => at(0),
            Loc::Above { d, .. } => {
                let last = at(nd - 1);
                let nu = self.tail_nu[j];
                let mut f = (-nu * (d - ds[nd - 1])).exp();
                if self.profile == EmitterProfile::Point {
                    f *= ds[nd - 1] / d;
                }
                if !f.is_finite() {
                    f = 0.0;
                }
                [last[0] * f, last[1] * f]
            }
            Loc::Between { i, lambda, d } => {
                let (a, b) = (at(i), at(i + 1));
                if a[0] > 0.0 && b[0] > 0.0 {
                    let nu = self.tail_nu[j];
                    let (la, lb) = (self.tail_log_c0[j * nd + i], self.tail_log_c0[j * nd + i + 1]);
                    let log_c0 = (1.0 - lambda) * (la + nu * (ds[i] - d)) + lambda * (lb + nu * (ds[i + 1] - d));
                    let c0 = log_c0.exp();
                    [c0, c0 * ((1.0 - lambda) * a[1] / a[0] + lambda * b[1] / b[0])]
                } else {
                    blend(a, b, lambda)
                }
            }
        }
    }

    /// `acc += weight · Σ_{b ∈ orders} α^b c_b(d)` at the located distance, with the law of
    /// `Response::zh_at`: `ln(e^{d} c_0)` and the shape `c_l/c_0` linear in `λ`, a linear fallback in
    /// `c · e^{d}` (point: `c · d e^{d}`) where `c_0 ≤ 0` at either node.
    #[allow(clippy::too_many_arguments)]
    pub(super) fn accumulate(
        &self,
        loc: Loc,
        ds: &[f64],
        (bounces, order): (usize, usize),
        orders: std::ops::RangeInclusive<usize>,
        alpha: f64,
        weight: f64,
        acc: &mut [f64],
    ) {
        let nd = ds.len();
        let at = |i: usize, b: usize| (i * bounces + b - 1) * order;
        let mut ab = weight * alpha.powi(*orders.start() as i32);
        for b in orders {
            if ab == 0.0 {
                break;
            }
            match loc {
                Loc::Below { ratio } => {
                    let k = self.k_low[b - 1];
                    let w = if k != 0.0 { ab * ratio.powf(k) } else { ab };
                    for (a, c) in acc.iter_mut().zip(&self.raw[at(0, b)..at(0, b) + order]) {
                        *a += w * c;
                    }
                }
                Loc::Above { decay, .. } => {
                    for (a, c) in acc.iter_mut().zip(&self.raw[at(nd - 1, b)..at(nd - 1, b) + order]) {
                        *a += ab * decay * c;
                    }
                }
                Loc::Between { i, lambda, d } => {
                    let (l0, l1) = (self.log_c0[i * bounces + b - 1], self.log_c0[(i + 1) * bounces + b - 1]);
                    let (j0, j1) = (at(i, b), at(i + 1, b));
                    if !l0.is_nan() && !l1.is_nan() {
                        let log_c0 = (1.0 - lambda) * (l0 + (ds[i] - d)) + lambda * (l1 + (ds[i + 1] - d));
                        let c0 = ab * log_c0.exp();
                        let (w0, w1) = (c0 * (1.0 - lambda), c0 * lambda);
                        let (s0, s1) = (&self.shape[j0..j0 + order], &self.shape[j1..j1 + order]);
                        for ((a, x), y) in acc.iter_mut().zip(s0).zip(s1) {
                            *a += w0 * x + w1 * y;
                        }
                    } else {
                        let (d0, d1) = (ds[i], ds[i + 1]);
                        let (mut w0, mut w1) = ((1.0 - lambda) * (-(d - d0)).exp(), lambda * (d1 - d).min(700.0).exp());
                        if self.profile == EmitterProfile::Point {
                            w0 *= d0 / d;
                            w1 *= d1 / d;
                        }
                        let (r0, r1) = (&self.raw[j0..j0 + order], &self.raw[j1..j1 + order]);
                        for ((a, c0), c1) in acc.iter_mut().zip(r0).zip(r1) {
                            let second = if *c1 == 0.0 { 0.0 } else { w1 * c1 };
                            *a += ab * (w0 * c0 + second);
                        }
                    }
                }
            }
            ab *= alpha;
        }
    }
}
