//! Brute-force photon random-walk reference: the irradiance a receiver gets from a point, a
//! differential-area or a directional emitter in a homogeneous medium, split by the number of scattering events.
//!
//! **Input → output.** An [`Emitter`], a homogeneous [`Medium`] (σ_s, σ_a in 1/length,
//! Henyey–Greenstein `g`), the unit normal `n` of a receiver at the origin `x = 0` and a
//! [`WalkConfig`] → a [`WalkResult`]: `E_n = ∫ L(ω) max(0, n·ω) dω` (ω points from the receiver
//! toward where the light comes from) as the unscattered part (analytic), each order `k = 1..=K`
//! of scattering events, the tail `k > K` and the total, each scattered part with a standard error
//! from the spread of 32 batch means. This is what the dubouchet2019 (Sec. 4.2, 5.1) volume-to-point
//! impulse-response generators tabulate; the reference judges them.
//!
//! **Emitters.** *Point*: isotropic intensity `I` (W/sr) at `s = d·l` in an infinite medium; direct
//! part `I e^{−σ_t d} max(0, n·l)/d²`. *Directional*: the medium fills `{p : p·l ≤ D}`, vacuum above;
//! light travels along `−l` (normal incidence) with irradiance `E₀` at the boundary; direct part
//! `E₀ e^{−σ_t D} max(0, n·l)`. *Area*: a differential patch at `s = d·l` with unit normal `n_e` and
//! radiant intensity `I max(0, n_e·u)` in direction `u` (total power `πI`), infinite medium; direct part
//! `I max(0, −n_e·l) e^{−σ_t d} max(0, n·l)/d²`.
//!
//! **Walk.** Lengths are measured in mean free paths (`σ_t = 1` internally); a photon's position is
//! kept relative to the source (point) or as its depth below the boundary (half-space: lateral
//! coordinates do not matter), so it stays exact however far the receiver is. A photon leaves the
//! emitter (point and area: isotropic from `s`; directional: from the entry point `D·l` along `−l`) and flies
//! `Exp(1)` free paths, except that the first flight is drawn from the defensive mixture
//! `½ Exp(1) + ½ Exp(β)`, `β = 1/(1 + min(d, R_c))` (`D` for the half-space), with the weight
//! `e^{−t}/(½e^{−t} + ½βe^{−βt}) ≤ 2`: unbiased importance sampling that sends more photons past a
//! distant receiver. Every collision is a scattering event `k = 1, 2, …` carrying the survival
//! weight `w` (multiplied by the albedo `c = σ_s/σ_t` after the event; Russian roulette below
//! `w = 0.1` keeps the weight's expectation). At every event it scores `w c · K(y, u)` into bucket
//! `k` (or the tail), where `K` is a *symmetry-averaged next-event kernel*:
//!
//! * *Point.* The walk's law is invariant under rotations about `s`, so replacing a vertex
//!   `(y, u)` by `(R y, R u)` for a Haar-random rotation `R` about `s` leaves every expectation
//!   unchanged. The kernel is the point-detector term `p(u'·(−ω)) max(0, n·ω) e^{−r}/r²` of the
//!   rotated vertex, averaged over `R` by one importance sample: the rotated vertex `y'` is uniform
//!   on the sphere `|y' − s| = a` in Haar measure, and is drawn instead with density `∝ 1/r²`
//!   (`r = |y'|`, log-uniform on `[|a − d|, a + d]`, since `dA = 2π (a/d) r dr`), the spin about
//!   `y' − s` uniform. The weight is then `e^{−r} ln((a+d)/|a−d|)/(2ad)`: the `1/r²` cancels
//!   exactly, no ball or cut-off is needed, and nothing is biased. The kernel is at most
//!   `p_max ln((a+d)/|a−d|)/(2ad)`, singular only logarithmically at `a = d`, and the vertex density
//!   in `a` is bounded there, so the second moment is finite (a plain point detector's diverges).
//! * *Area.* The cosine emission breaks the rotation symmetry about `s`, so the photons are emitted
//!   *isotropically* (the point walk, same law) and the emission profile enters as a weight: the area
//!   emitter's expectation is `πI σ_t² E_iso[4 max(0, n_e·u₀) K(y, u)]` (`u₀` the emission direction;
//!   `E_iso[4 max(0, n_e·u₀)] = 1`). The isotropic walk's law *is* invariant under every rotation `R`
//!   about `s` when `u₀` is rotated along with the vertex, so the point kernel's averaging applies to
//!   the whole path: with the rotated vertex `y'` sampled as above, `R` is completed by mapping a fixed
//!   unit vector `p̂ ⊥ (y − s)` to a uniformly spun `p̂' ⊥ (y' − s)` (Haar measure conditioned on the
//!   image of `(y − s)/a`), and the score is `p(Ru·(−ω)) max(0, n·ω) e^{−r}/r² · 4 max(0, n_e·Ru₀)`
//!   with the same importance weight. Unbiased for the same reason as the point kernel; the extra
//!   factor is at most 4, so the second moment stays finite. The variance grows where little of the
//!   rotated emission faces `n_e` (e.g. patches facing away), never the bias.
//! * *Directional.* Medium and beam are invariant under translations parallel to the boundary, so
//!   the irradiance at `x` from the uniform beam equals `E₀ ∫ dA(x')` of the irradiance from one
//!   unit-power pencil entering at `D·l`, over receivers `x'` on the plane `P₀ = {p·l = 0}`. Every
//!   photon starts at `D·l`, and a vertex at height `h = y·l` scores that plane integral: with
//!   `dA/r² = dω/|μ|`, `μ = l·ω`, and `t = |h|/|μ|` (free paths to `P₀` along `ω`), it is
//!   `∫ dφ ∫_{|h|}^∞ p max(0, n·ω) e^{−t}/t dt`, estimated with one `(t, φ)` sample: `t` from a mixture
//!   that is log-uniform on `[|h|, 1]` and `1 + Exp(1)` beyond (or `|h| + Exp(1)` if `|h| ≥ 1`), so
//!   the sample weight is at most `ln(1/|h|) + 1/e`: unbiased, finite second moment.
//!
//! **Termination and its bias.** Roulette is unbiased. A photon is removed (its weight added to
//! [`WalkResult::truncated_weight`]) when a collision lies farther than `R_c = far_mfp` free paths
//! from the emitter (point `s`; boundary plane) *and* from every receiver point of the averaged
//! kernel (the sphere `|y − s| = d`, point and area; the plane `P₀`). A removed photon's contributions to orders
//! `k ≤ K` need at most `K` further exponential lengths (flights and the attenuated connection) to
//! span `R_c`; the attenuation those paths carry, relative to unremoved ones, is at most
//! [`WalkResult::order_truncation_bound`] `= P[Poisson(R_c) ≤ K]` (`< 2e-15` for the default
//! `R_c = 40 + 2K`). The tail and the total lose what removed photons would still have sent: in an
//! absorbing medium this decays like `e^{−R_c/L_diff}` (`L_diff` the diffusion length), but for
//! `c = 1` only like `1/R_c` (a 3-D walk returns from distance `ρ` with probability `~1/ρ`; in the
//! half-space every deep photon comes back), so there tail and total are those of the *truncated
//! process*, in which removal is a perfect absorber beyond `R_c` (for `d, D ≤ 2R_c` the removal
//! region is the convex complement of a ball or half-space, which straight flights and connections
//! never re-enter). That process obeys exact balance laws (tested): net outward flux
//! `E_{+l} − E_{−l} = I/d²` around a conservative point source (nothing is removed inside the
//! sphere), and net downward flux `E_{+l} − E_{−l} = E₀ · truncated_weight` in a conservative
//! half-space (`→ 0` as `R_c → ∞`: all light is eventually reflected).
//!
//! **Measure-zero deviations** (probability `≲ 2⁻⁵³` per event): a vertex exactly at `s` scores 0;
//! at `a = d` exactly the log span uses `|a − d| = 2⁻⁶⁰ d`; at `|h| < 1e-300` the plane kernel starts
//! at `t = 1e-300`. HG sampling is the inverse CDF, with `μ = v + 1.5 g (1 − v²)`, `v = 2ξ − 1`
//! (exact at `g = 0`, error `O(g²) < 1e-12`) when `|g| < 1e-6`, where the closed form cancels.
//!
//! **Independent of** every table generator and of `crate::physics::hg` (own HG phase and sampler,
//! own geometry, on glam's `DVec3`); it shares only `crate::physics::rng`. Streams are keyed by `(seed, photon index)`
//! with a running draw counter, batches are traced sequentially and reduced in batch order, so the
//! result is bit-identical for any rayon thread count.

mod photon;
#[cfg(test)]
mod tests;

use glam::DVec3;
use rayon::prelude::*;

use crate::physics::rng::StreamKey;
use photon::{Geometry, Problem, Tally};

/// Number of batches whose spread gives the standard errors.
pub const BATCHES: u64 = 32;

/// A light source; positions and depths in the same length unit as `1/σ`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Emitter {
    /// Isotropic point source in an infinite medium.
    Point {
        /// Radiant intensity `I` (W/sr), in `[0, 1e100]`.
        intensity: f64,
        /// Source position `s` relative to the receiver, `|s|` in `[1e-100, 1e100]`.
        position: [f64; 3],
    },
    /// Differential area (cosine-weighted) emitter in an infinite medium: radiant intensity
    /// `intensity · max(0, normal·ω)` in direction `ω` (total power `π · intensity`).
    Area {
        /// Radiant intensity along the patch normal (W/sr), in `[0, 1e100]`.
        intensity: f64,
        /// Patch position `s` relative to the receiver, `|s|` in `[1e-100, 1e100]`.
        position: [f64; 3],
        /// Patch normal `n_e` (any finite non-zero vector; normalised).
        normal: [f64; 3],
    },
    /// Collimated light entering the half-space medium `{p : p·l ≤ depth}` at normal incidence.
    Directional {
        /// Irradiance `E₀` (W/m²) on a plane perpendicular to the beam at the boundary, in `[0, 1e100]`.
        irradiance: f64,
        /// Direction `l` toward the light (any finite non-zero vector; normalised).
        toward_light: [f64; 3],
        /// Depth `D` of the receiver below the boundary, in `[0, 1e100]`.
        depth: f64,
    },
}

/// Homogeneous medium.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Medium {
    /// Scattering coefficient σ_s (1/length), in `[0, 1e100]`.
    pub sigma_s: f64,
    /// Absorption coefficient σ_a (1/length), in `[0, 1e100]`.
    pub sigma_a: f64,
    /// Henyey–Greenstein asymmetry `g`, in the open interval `(−1, 1)`.
    pub g: f64,
}

/// How much to trace.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct WalkConfig {
    /// Photons to trace, in `[64, 2^48]`.
    pub photons: u64,
    /// Highest order `K` reported separately, in `[0, 1000]`; higher orders go to the tail.
    pub max_order: usize,
    /// Seed of the random streams.
    pub seed: u64,
    /// Removal distance `R_c` in mean free paths, in `[1, 1e4]` (see the module doc).
    pub far_mfp: f64,
}

impl WalkConfig {
    /// Configuration with the default removal distance `R_c = 40 + 2K` free paths.
    pub fn new(photons: u64, max_order: usize, seed: u64) -> Self {
        Self { photons, max_order, seed, far_mfp: 40.0 + 2.0 * max_order as f64 }
    }
}

/// A Monte-Carlo estimate.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct OrderEstimate {
    /// Estimated value.
    pub mean: f64,
    /// Standard error of `mean`, from the spread of the batch means.
    pub std_error: f64,
}

/// Irradiance split by scattering order.
#[derive(Debug, Clone, PartialEq)]
pub struct WalkResult {
    /// Unscattered part (analytic, exact).
    pub direct: f64,
    /// Orders `k = 1..=K` (`orders[k − 1]`).
    pub orders: Vec<OrderEstimate>,
    /// All orders `k > K` together.
    pub tail: OrderEstimate,
    /// `direct` + every order + tail.
    pub total: OrderEstimate,
    /// Mean photon weight removed by the `R_c` rule (a fraction of the emitted power).
    pub truncated_weight: OrderEstimate,
    /// `P[Poisson(R_c) ≤ K]`: bound on the relative attenuation of the paths the removal drops
    /// from orders `k ≤ K` (see the module doc).
    pub order_truncation_bound: f64,
    /// Photons traced (0 when `σ_s = 0`: nothing scatters).
    pub photons: u64,
    /// Non-finite scores (and photons whose position became non-finite) discarded; each is counted.
    pub nonfinite_discarded: u64,
}

/// A walk argument outside its valid range.
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
pub enum WalkError {
    /// A scalar outside `[lo, hi]` (or NaN).
    #[error("{name} = {value} is out of range: valid range is [{lo:e}, {hi:e}]")]
    Range {
        /// The argument.
        name: &'static str,
        /// Its value.
        value: f64,
        /// Smallest accepted value.
        lo: f64,
        /// Largest accepted value.
        hi: f64,
    },
    /// A vector with a non-finite component or a length outside `[lo, hi]`.
    #[error("{name} = {value:?} is out of range: valid range is finite components with length in [{lo:e}, {hi:e}]")]
    Vector {
        /// The argument.
        name: &'static str,
        /// Its value.
        value: [f64; 3],
        /// Smallest accepted length.
        lo: f64,
        /// Largest accepted length.
        hi: f64,
    },
    /// `|g| ≥ 1` or NaN.
    #[error("medium.g = {0} is out of range: valid range is the open interval (-1, 1)")]
    G(f64),
    /// A photon count outside `[64, 2^48]`.
    #[error("cfg.photons = {0} is out of range: valid range is [64, 2^48]")]
    Photons(u64),
    /// More than 1000 scattering orders.
    #[error("cfg.max_order = {0} is out of range: valid range is [0, 1000]")]
    MaxOrder(usize),
}

/// Irradiance at the origin with receiver normal `normal` (any finite non-zero vector; normalised),
/// split by scattering order. Errors name the offending parameter and its valid range.
pub fn irradiance(
    emitter: &Emitter,
    medium: &Medium,
    normal: [f64; 3],
    cfg: &WalkConfig,
) -> Result<WalkResult, WalkError> {
    let sigma_s = in_range("medium.sigma_s", medium.sigma_s, 0.0, 1e100)?;
    let sigma_a = in_range("medium.sigma_a", medium.sigma_a, 0.0, 1e100)?;
    if medium.g.is_nan() || medium.g.abs() >= 1.0 {
        return Err(WalkError::G(medium.g));
    }
    let n = unit("normal", DVec3::from_array(normal), 1e-150, 1e150)?;
    if !(64..=1u64 << 48).contains(&cfg.photons) {
        return Err(WalkError::Photons(cfg.photons));
    }
    if cfg.max_order > 1000 {
        return Err(WalkError::MaxOrder(cfg.max_order));
    }
    let far = in_range("cfg.far_mfp", cfg.far_mfp, 1.0, 1e4)?;
    let sigma_t = sigma_s + sigma_a;
    let (geometry, direct, scale) = match *emitter {
        Emitter::Point { intensity, position } => {
            let intensity = in_range("emitter.intensity", intensity, 0.0, 1e100)?;
            let position = DVec3::from_array(position);
            let dist = norm3("emitter.position", position, 1e-100, 1e100)?;
            let l = position / dist;
            let direct = intensity * (-sigma_t * dist).exp() * n.dot(l).max(0.0) / (dist * dist);
            (
                Geometry::Point { d: sigma_t * dist, l },
                direct,
                4.0 * std::f64::consts::PI * intensity * sigma_t * sigma_t,
            )
        }
        Emitter::Area { intensity, position, normal } => {
            let intensity = in_range("emitter.intensity", intensity, 0.0, 1e100)?;
            let position = DVec3::from_array(position);
            let dist = norm3("emitter.position", position, 1e-100, 1e100)?;
            let ne = unit("emitter.normal", DVec3::from_array(normal), 1e-150, 1e150)?;
            let l = position / dist;
            let facing = (-ne.dot(l)).max(0.0);
            let direct = intensity * facing * (-sigma_t * dist).exp() * n.dot(l).max(0.0) / (dist * dist);
            (Geometry::Area { d: sigma_t * dist, l, ne }, direct, std::f64::consts::PI * intensity * sigma_t * sigma_t)
        }
        Emitter::Directional { irradiance, toward_light, depth } => {
            let e0 = in_range("emitter.irradiance", irradiance, 0.0, 1e100)?;
            let l = unit("emitter.toward_light", DVec3::from_array(toward_light), 1e-150, 1e150)?;
            let depth = in_range("emitter.depth", depth, 0.0, 1e100)?;
            let direct = e0 * (-sigma_t * depth).exp() * n.dot(l).max(0.0);
            (Geometry::Slab { depth: sigma_t * depth, l }, direct, e0)
        }
    };
    let k_max = cfg.max_order;
    let bound = poisson_cdf(far, k_max);
    let zero = OrderEstimate { mean: 0.0, std_error: 0.0 };
    if sigma_s == 0.0 {
        return Ok(WalkResult {
            direct,
            orders: vec![zero; k_max],
            tail: zero,
            total: OrderEstimate { mean: direct, std_error: 0.0 },
            truncated_weight: zero,
            order_truncation_bound: bound,
            photons: 0,
            nonfinite_discarded: 0,
        });
    }
    let problem = Problem::new(geometry, sigma_s / sigma_t, medium.g, n, k_max, far);
    let per = cfg.photons / BATCHES;
    let extra = cfg.photons % BATCHES;
    let batches: Vec<(u64, Tally)> = (0..BATCHES)
        .into_par_iter()
        .map(|b| {
            let start = b * per + b.min(extra);
            let count = per + u64::from(b < extra);
            let mut tally = Tally::new(k_max + 1);
            for i in start..start + count {
                photon::trace(&problem, StreamKey { table: cfg.seed, cell: i }, &mut tally);
            }
            (count, tally)
        })
        .collect();
    let counts: Vec<u64> = batches.iter().map(|(c, _)| *c).collect();
    let bucket = |j: usize| -> Vec<f64> { batches.iter().map(|(_, t)| scale * t.sums[j]).collect() };
    let orders = (0..k_max).map(|j| estimate(&bucket(j), &counts, 0.0)).collect();
    let tail = estimate(&bucket(k_max), &counts, 0.0);
    let totals: Vec<f64> = batches.iter().map(|(_, t)| scale * t.sums.iter().sum::<f64>()).collect();
    let truncated: Vec<f64> = batches.iter().map(|(_, t)| t.truncated).collect();
    Ok(WalkResult {
        direct,
        orders,
        tail,
        total: estimate(&totals, &counts, direct),
        truncated_weight: estimate(&truncated, &counts, 0.0),
        order_truncation_bound: bound,
        photons: cfg.photons,
        nonfinite_discarded: batches.iter().map(|(_, t)| t.nonfinite).sum(),
    })
}

/// Mean per photon of batch sums `sums` (batch sizes `counts`) plus `offset`, with the standard error
/// `sqrt(B/(B−1) Σ_b (n_b/N)² (m_b − m)²)` of the batch means `m_b` (summed relative to the largest
/// `|m_b|`, so it does not overflow for results near `f64::MAX`).
fn estimate(sums: &[f64], counts: &[u64], offset: f64) -> OrderEstimate {
    let n = counts.iter().sum::<u64>() as f64;
    let mean = sums.iter().sum::<f64>() / n;
    let batch_means: Vec<f64> = sums.iter().zip(counts).map(|(&s, &c)| s / c as f64).collect();
    let unit = batch_means.iter().fold(0.0f64, |m, x| m.max(x.abs()));
    let b = sums.len() as f64;
    let spread: f64 = if unit > 0.0 {
        batch_means.iter().zip(counts).map(|(&m, &c)| (c as f64 / n * (m / unit - mean / unit)).powi(2)).sum()
    } else {
        0.0
    };
    OrderEstimate { mean: mean + offset, std_error: unit * (b / (b - 1.0) * spread).sqrt() }
}

/// `P[Poisson(tau) ≤ k]`, summed in log space (no underflow of `e^{−tau}` for large `tau`).
fn poisson_cdf(tau: f64, k: usize) -> f64 {
    let mut log_fact = 0.0;
    let mut sum = 0.0;
    for i in 0..=k {
        if i > 0 {
            log_fact += (i as f64).ln();
        }
        sum += (-tau + i as f64 * tau.ln() - log_fact).exp();
    }
    sum.min(1.0)
}

/// `v` if it lies in `[lo, hi]`, else an error naming `name` and the range.
fn in_range(name: &'static str, v: f64, lo: f64, hi: f64) -> Result<f64, WalkError> {
    if (lo..=hi).contains(&v) { Ok(v) } else { Err(WalkError::Range { name, value: v, lo, hi }) }
}

/// Euclidean norm of a finite vector if it lies in `[lo, hi]`, else an error naming `name`.
fn norm3(name: &'static str, v: DVec3, lo: f64, hi: f64) -> Result<f64, WalkError> {
    let len = v.length();
    if v.is_finite() && (lo..=hi).contains(&len) {
        Ok(len)
    } else {
        Err(WalkError::Vector { name, value: v.to_array(), lo, hi })
    }
}

/// `v` normalised (divided by its length), if finite with length in `[lo, hi]`, else an error naming `name`.
fn unit(name: &'static str, v: DVec3, lo: f64, hi: f64) -> Result<DVec3, WalkError> {
    let len = norm3(name, v, lo, hi)?;
    Ok(v / len)
}
