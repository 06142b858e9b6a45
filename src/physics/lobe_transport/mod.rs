//! Multiple-scattering lobes of a pencil beam (wang2018 Sec. 3.5.4, 4.1, 5.2): the Monte-Carlo
//! generator behind the `MsLobes` table kind.
//!
//! **Input → output.** A [`LobeConfig`] (HG `g`, albedo nodes, the `(ρ, z)` grid, lobe directions,
//! photon count, highest traced order `K`) and a content key → a [`LobeResponse`]: per grid cell and
//! lobe direction `ω` the radiance scattered at `P` toward `ω` per unit length and per unit beam power,
//! `S(P, ω) = Σ_{k ≥ 2} α^k E_k(P, ω)` for every albedo node at once, the exactly-two-events part `E_2`
//! (albedo-free: a consumer multiplies by `α²`), the angle-integrated density, and the fraction of the
//! order-`k` collisions that landed inside the grid.
//!
//! **Canonical problem.** A unit-power beam leaves the origin along `+z` in an infinite medium with
//! `σ_t = 1` (lengths in mean free paths). `E_k(P, ω)` is the radiance the photons at their `k`-th
//! scattering event add per unit length at `P` toward `ω` in the non-absorbing medium (`σ_s = 1`):
//! `E_k(P, ω) = ψ_k(P) · ∫ f_k(ω' | P) p(ω'·ω) dω'`, with `ψ_k` the density of `k`-th collisions and
//! `f_k` the distribution of the direction they arrive along. With albedo `α` a photon reaches its
//! `k`-th collision with weight `α^{k−1}` and scatters with probability `α`, so the physical source is
//! `Σ α^k E_k`. The single-scattering term `k = 1` is a line singularity on the axis and is left to the
//! renderer (it is analytic).
//!
//! **One walk per g (wang2018 Sec. 5.2, made α-free).** With `σ_t` fixed the positions of the
//! `k`-th collision do not depend on `α`; only the weight does. Photons walk in the non-absorbing
//! medium and every collision `k ≥ 2` inside the grid is tallied once per albedo node with weight
//! `α_j^k`, so one walk gives the whole albedo axis. Tallies are histograms of the incoming direction
//! `μ' = â·ω'` (and its folded azimuth for the full lobe) per cell, `â = P/|P|` the lobe axis of
//! wang2018 Sec. 4.1; the lobe follows from one matrix product with the phase function averaged over
//! each direction bin ([`kernel`]) — exact for the symmetric lobe, because the azimuthal average
//! about `â` of `p(ω'·ω)` depends on `ω'` only through `μ'`.
//!
//! **Determinism.** Tallies are integers (fixed point, `2^scale_bits` per unit weight), so their sum
//! is the same for any partition of the photons and any thread count; random numbers come from
//! [`crate::physics::rng::StreamKey`] keyed by (table, g slice) and the photon index.
//!
//! **Orders beyond `K`** (`α → 1`). Photons are traced to their `K`-th collision; orders `k > K` are
//! added analytically as the Gaussian (central-limit) density of the `k`-th collision position with the
//! exact mean and mean-square displacement of the walk, isotropic in direction ([`remainder`]). The
//! energy left to it is `α^{K+1}/(1 − α)` of `α²/(1 − α)` (all of it at `α = 1` is spread over a
//! region of radius `~√(2K/(1−g))`, so inside the grid it is a small, smooth share; the sidecar
//! reports it).

mod closure;
#[cfg(test)]
mod tests;

use std::f64::consts::PI;
use std::sync::atomic::{AtomicU64, Ordering};

use glam::DVec3;

pub use closure::{collision_moments, decay_rate, remainder};

use crate::physics::hg;
use crate::physics::medium::free_flight;
use crate::physics::rng::StreamKey;

/// Fraction of the graded mapping that is linear (the rest is quadratic): cells near the origin are
/// `LINEAR_PART` times the uniform width, cells at the far end `2 − LINEAR_PART` times.
pub const LINEAR_PART: f64 = 0.25;

/// A graded axis: `x(u) = s · sign(u) · (a|u| + (1 − a)u²)` with `u` uniform over the bins, fine near
/// the origin (the beam start), coarse far away where the field is smooth.
#[derive(Debug, Clone, PartialEq)]
pub struct GradedAxis {
    /// Scale `s` (the largest `|x|` of the axis).
    pub scale: f64,
    /// `u` at the lower edge.
    pub u_lo: f64,
    /// `u` at the upper edge.
    pub u_hi: f64,
    /// Number of cells.
    pub bins: usize,
}

impl GradedAxis {
    /// An axis over `[lo, hi]` (`lo ≤ 0 < hi`, or `lo = 0` for ρ) with `bins` cells.
    pub fn new(lo: f64, hi: f64, bins: usize) -> Self {
        let scale = lo.abs().max(hi.abs());
        let u_lo = -inverse_unit(-lo / scale);
        let u_hi = inverse_unit(hi / scale);
        GradedAxis { scale, u_lo, u_hi, bins }
    }

    fn du(&self) -> f64 {
        (self.u_hi - self.u_lo) / self.bins as f64
    }

    /// Position of the mapping at `u`.
    pub fn x_of_u(&self, u: f64) -> f64 {
        let v = u.abs();
        self.scale * u.signum() * (LINEAR_PART * v + (1.0 - LINEAR_PART) * v * v)
    }

    /// Edge `i` (`0 ..= bins`).
    pub fn edge(&self, i: usize) -> f64 {
        self.x_of_u(self.u_lo + self.du() * i as f64)
    }

    /// Centre of cell `i` (the mapping at the cell's middle `u`).
    pub fn center(&self, i: usize) -> f64 {
        self.x_of_u(self.u_lo + self.du() * (i as f64 + 0.5))
    }

    /// All cell centres.
    pub fn centers(&self) -> Vec<f64> {
        (0..self.bins).map(|i| self.center(i)).collect()
    }

    /// Continuous cell coordinate of `x`: cell `i` spans `[i, i + 1)`; outside the axis the value is
    /// below 0 or at least `bins`.
    pub fn coordinate(&self, x: f64) -> f64 {
        let u = x.signum() * inverse_unit(x.abs() / self.scale);
        (u - self.u_lo) / self.du()
    }

    /// Cell containing `x`, if any.
    pub fn cell(&self, x: f64) -> Option<usize> {
        let c = self.coordinate(x);
        if c >= 0.0 && c < self.bins as f64 { Some((c as usize).min(self.bins - 1)) } else { None }
    }
}

/// Inverse of `v ↦ a v + (1 − a) v²` on `v ≥ 0` (without cancellation: the rationalised root).
fn inverse_unit(x: f64) -> f64 {
    let (a, b) = (LINEAR_PART, 1.0 - LINEAR_PART);
    // v = (−a + √(a² + 4bx)) / (2b) = 2x / (a + √(a² + 4bx)).
    2.0 * x / (a + (a * a + 4.0 * b * x).sqrt())
}

/// Which lobe is tallied.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LobeShape {
    /// Symmetric about `â = P/|P|` (wang2018 Sec. 4.1): lobe nodes in `θ` only.
    Symmetric,
    /// Full lobe in the local frame: `θ` from `â` and azimuth `φ ∈ [0, π]` from `ê₁` (the direction in
    /// the plane of `â` and the beam axis, perpendicular to `â`, pointing away from the beam's side);
    /// the lobe is mirror-symmetric in `φ`.
    Full {
        /// Output azimuth nodes over `[0, π]` (and input azimuth bins).
        phi_bins: usize,
    },
}

/// Everything the generator needs for one g slice.
#[derive(Debug, Clone, PartialEq)]
pub struct LobeConfig {
    /// HG mean cosine.
    pub g: f64,
    /// Albedo nodes.
    pub albedos: Vec<f64>,
    /// Radial axis (from 0).
    pub rho: GradedAxis,
    /// Axial axis (through 0).
    pub z: GradedAxis,
    /// Lobe polar nodes over `[0, π]` (inclusive).
    pub theta_nodes: usize,
    /// Histogram bins of the incoming direction cosine `μ' ∈ [−1, 1]`.
    pub direction_bins: usize,
    /// Symmetric or full lobe.
    pub shape: LobeShape,
    /// Photons traced.
    pub photons: u64,
    /// Highest collision order traced (`K`); higher orders come from [`remainder`].
    pub max_order: usize,
    /// Random stream key of this slice.
    pub stream: StreamKey,
}

impl LobeConfig {
    /// Output lobe nodes per cell.
    pub fn lobe_len(&self) -> usize {
        self.theta_nodes * self.phi_nodes()
    }

    /// Output azimuth nodes (1 for the symmetric lobe).
    pub fn phi_nodes(&self) -> usize {
        match self.shape {
            LobeShape::Symmetric => 1,
            LobeShape::Full { phi_bins } => phi_bins,
        }
    }

    /// Histogram bins per cell.
    pub fn bins(&self) -> usize {
        self.direction_bins * self.phi_nodes()
    }

    /// Cells of the grid.
    pub fn cells(&self) -> usize {
        self.rho.bins * self.z.bins
    }

    /// Fixed-point scale: the largest per-bin sum (every collision of every photon in one bin)
    /// stays below 2^63.
    pub fn scale_bits(&self) -> i32 {
        let events = (self.photons as f64 * self.max_order as f64).max(1.0);
        (63 - events.log2().ceil() as i32).clamp(16, 48)
    }

    /// Checks the configuration (the table kind validates user input; this guards the module API).
    pub fn check(&self) -> Result<(), String> {
        hg::validate_g(self.g)?;
        if self.albedos.iter().any(|a| !(0.0..=1.0).contains(a)) {
            return Err(format!("albedos must lie in [0, 1], got {:?}", self.albedos));
        }
        if self.rho.bins == 0 || self.z.bins == 0 || self.theta_nodes < 2 || self.direction_bins == 0 {
            return Err("the grid needs at least one cell, two θ nodes and one direction bin".into());
        }
        if !(self.rho.scale > 0.0 && self.z.scale > 0.0 && self.rho.scale.is_finite() && self.z.scale.is_finite()) {
            return Err("the grid extents must be positive and finite".into());
        }
        if self.max_order < 2 || self.photons == 0 {
            return Err("trace at least one photon to order 2".into());
        }
        if let LobeShape::Full { phi_bins } = self.shape
            && phi_bins < 2
        {
            return Err("the full lobe needs at least two azimuth nodes".into());
        }
        Ok(())
    }
}

/// What one g slice produces; lobe values in canonical units `1/(mfp · sr)` per unit beam power
/// (radiance added per mean free path), density in `1/mfp³`.
#[derive(Debug, Clone)]
pub struct LobeResponse {
    /// `E_2` lobes, `[z][ρ][θ][φ]` flattened.
    pub double: Vec<f64>,
    /// Per albedo node: `Σ_{k≥2} α^k E_k` lobes incl. the remainder, `[z][ρ][θ][φ]`.
    pub total: Vec<Vec<f64>>,
    /// Per albedo node: angle-integrated `Σ_{k≥2} α^k ψ_k` incl. the remainder, `[z][ρ]`.
    pub density: Vec<Vec<f64>>,
    /// Per albedo node: the part of `density` that the remainder closure added, `[z][ρ]`.
    pub remainder_density: Vec<Vec<f64>>,
    /// Fraction of the order-`k` collisions inside the grid, `k = 1 ..= K` (index `k − 1`).
    pub inside: Vec<f64>,
    /// Collisions simulated (all orders, inside and outside the grid).
    pub events: u64,
    /// Random walks that produced a non-finite position or direction and were dropped.
    pub nonfinite_discarded: u64,
}

/// Photons per batch of work (a batch is the unit of progress and of work stealing).
pub const BATCH: u64 = 4096;

/// Integer tallies of one worker.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
struct Tally {
    /// `[cell][bin][channel]`, channels = albedo nodes in descending order, then `E_2` ([`increments`]).
    hist: Vec<u64>,
    /// Collisions inside the grid per order (index `k − 1`).
    inside: Vec<u64>,
    events: u64,
    dropped: u64,
    /// Tally events not yet applied: `(cell · bins + bin) << ORDER_BITS | k`. Applying them in
    /// sorted order turns random writes into the histogram (the walk's bottleneck: one cache miss
    /// per collision) into a sequential sweep.
    #[serde(skip)]
    pending: Vec<u64>,
    #[serde(skip)]
    scratch: Vec<u64>,
}

/// Bits of the collision order in a pending tally key (`max_order ≤ 65536 < 2^17`).
const ORDER_BITS: u32 = 17;
/// Pending tally events per worker before they are sorted and applied.
const PENDING: usize = 1 << 21;

impl Tally {
    fn new(cfg: &LobeConfig) -> Self {
        let channels = 1 + cfg.albedos.len();
        Tally {
            hist: vec![0; cfg.cells() * cfg.bins() * channels],
            inside: vec![0; cfg.max_order],
            events: 0,
            dropped: 0,
            pending: Vec::with_capacity(PENDING),
            scratch: Vec::new(),
        }
    }

    /// Sorts the pending events by histogram slot (LSD radix on the slot bits) and applies them.
    fn flush(&mut self, inc: &[Vec<u64>], slots: usize, channels: usize) {
        let slot_bits = usize::BITS - slots.max(1).leading_zeros();
        let passes = slot_bits.div_ceil(8);
        self.scratch.resize(self.pending.len(), 0);
        for pass in 0..passes {
            let shift = ORDER_BITS + 8 * pass;
            let mut count = [0usize; 257];
            for &key in &self.pending {
                count[((key >> shift) & 0xff) as usize + 1] += 1;
            }
            for i in 0..256 {
                count[i + 1] += count[i];
            }
            for &key in &self.pending {
                let d = ((key >> shift) & 0xff) as usize;
                self.scratch[count[d]] = key;
                count[d] += 1;
            }
            std::mem::swap(&mut self.pending, &mut self.scratch);
        }
        for &key in &self.pending {
            let slot = (key >> ORDER_BITS) as usize;
            let row = &inc[(key & ((1 << ORDER_BITS) - 1)) as usize - 1];
            let at = slot * channels;
            for (h, w) in self.hist[at..at + row.len()].iter_mut().zip(row) {
                *h = h.wrapping_add(*w);
            }
        }
        self.pending.clear();
    }

    fn add(&mut self, other: &Tally) {
        for (a, b) in self.hist.iter_mut().zip(&other.hist) {
            *a = a.wrapping_add(*b);
        }
        for (a, b) in self.inside.iter_mut().zip(&other.inside) {
            *a += b;
        }
        self.events += other.events;
        self.dropped += other.dropped;
    }
}

/// Fixed-point increments `round(α^k · 2^scale)` per order `k` (index `k − 1`) over the tally
/// channels: the albedo nodes in *descending* order, then `E_2` (weight 1 at `k = 2` only). Each row
/// is cut after its last non-zero entry (`α^k` underflows the fixed point first for the smallest
/// albedos, so the live channels are a prefix): deep orders touch only the albedos near 1.
fn increments(cfg: &LobeConfig) -> Vec<Vec<u64>> {
    let scale = f64::from(cfg.scale_bits()).exp2();
    (1..=cfg.max_order)
        .map(|k| {
            let mut row: Vec<u64> =
                cfg.albedos.iter().rev().map(|&a| (a.powi(k as i32) * scale).round() as u64).collect();
            row.push(if k == 2 { scale as u64 } else { 0 });
            while row.last() == Some(&0) {
                row.pop();
            }
            row
        })
        .collect()
}

/// The local lobe frame at `p` (wang2018 Sec. 4.1): axis `â = p/|p|` (`+z` at the origin) and `ê₁`
/// perpendicular to it in the plane of `â` and the beam axis, pointing away from the beam's side
/// (`ê₁ = (z ρ̂ − ρ ẑ)/r`); `ê₂ = â × ê₁`. On the axis `ê₁ = x̂`.
pub fn lobe_frame(p: DVec3) -> (DVec3, DVec3, DVec3) {
    let r = p.length();
    let rho = (p.x * p.x + p.y * p.y).sqrt();
    if r.is_nan() || r <= 0.0 {
        return (DVec3::Z, DVec3::X, DVec3::Y);
    }
    let a = p / r;
    let e1 = if rho > 0.0 {
        let (rho_x, rho_y) = (p.x / rho, p.y / rho);
        DVec3::new((p.z * rho_x) / r, (p.z * rho_y) / r, -rho / r)
    } else {
        // On the axis every perpendicular is equivalent.
        DVec3::X
    };
    (a, e1, a.cross(e1))
}

/// Runs the walk for one g slice (parallel over batches of [`BATCH`] photons; `progress` is called
/// with the number of photons of every finished batch).
pub fn compute(cfg: &LobeConfig, progress: &(dyn Fn(u64) + Sync)) -> Result<LobeResponse, String> {
    let t = tally(cfg, 0..cfg.photons, progress)?;
    Ok(finish(cfg, &t.0))
}

/// The integer tallies of photons `range` of a g slice: a work unit of a sharded compile. Every photon
/// draws from its own counter-based stream and tallies are integers, so the tallies of any partition
/// of `0..photons`, summed ([`finish_tallies`]), are those of [`compute`] to the bit.
pub fn tally(
    cfg: &LobeConfig,
    range: std::ops::Range<u64>,
    progress: &(dyn Fn(u64) + Sync),
) -> Result<PhotonTally, String> {
    cfg.check()?;
    if range.end > cfg.photons || range.start > range.end {
        return Err(format!("photons {range:?} outside 0..{}", cfg.photons));
    }
    let inc = increments(cfg);
    let batches = (range.end - range.start).div_ceil(BATCH);
    let next = AtomicU64::new(0);
    let workers = rayon::current_num_threads().max(1);
    let results = std::sync::Mutex::new(Vec::with_capacity(workers));
    rayon::scope(|s| {
        for _ in 0..workers {
            let (next, inc, results, range) = (&next, &inc, &results, &range);
            s.spawn(move |_| {
                let mut t = Tally::new(cfg);
                loop {
                    let b = next.fetch_add(1, Ordering::Relaxed);
                    if b >= batches {
                        break;
                    }
                    let start = range.start + b * BATCH;
                    let end = (start + BATCH).min(range.end);
                    for photon in start..end {
                        walk(cfg, photon, &mut t);
                        if t.pending.len() + cfg.max_order > PENDING {
                            t.flush(inc, cfg.cells() * cfg.bins(), 1 + cfg.albedos.len());
                        }
                    }
                    progress(end - start);
                }
                t.flush(inc, cfg.cells() * cfg.bins(), 1 + cfg.albedos.len());
                // Integer tallies: the order in which workers hand them in does not matter.
                if let Ok(mut r) = results.lock() {
                    r.push(t);
                }
            });
        }
    });
    let tallies = results.into_inner().map_err(|_| "a lobe worker panicked".to_string())?;
    if tallies.len() != workers {
        return Err("a lobe worker panicked".into());
    }
    let mut total = Tally::new(cfg);
    for t in &tallies {
        total.add(t);
    }
    total.pending = Vec::new();
    Ok(PhotonTally(total))
}

/// The lobes of a g slice from the tallies of a partition of its photons (any order).
pub fn finish_tallies(cfg: &LobeConfig, parts: &[PhotonTally]) -> Result<LobeResponse, String> {
    let mut total = Tally::new(cfg);
    total.pending = Vec::new();
    for p in parts {
        if p.0.hist.len() != total.hist.len() || p.0.inside.len() != total.inside.len() {
            return Err("photon tallies of another grid".into());
        }
        total.add(&p.0);
    }
    Ok(finish(cfg, &total))
}

/// Integer tallies of a range of photons ([`tally`]); serialisable, so a shard can hand them over.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct PhotonTally(Tally);

impl PhotonTally {
    /// Adds another range's tallies (integer sums: any order gives the same bits).
    pub fn absorb(&mut self, other: &PhotonTally) {
        self.0.add(&other.0);
    }
}

/// One photon: `K` collisions in the non-absorbing medium, tallying orders `≥ 2` inside the grid.
fn walk(cfg: &LobeConfig, photon: u64, t: &mut Tally) {
    let bins = cfg.bins();
    let rng = cfg.stream.sample(photon);
    let (mut p, mut d) = (DVec3::ZERO, DVec3::Z);
    let phi_bins = cfg.phi_nodes();
    let nbins = cfg.direction_bins as f64;
    for k in 1..=cfg.max_order {
        let dim = 3 * (k as u32 - 1);
        let step = free_flight(rng.uniform(dim), 1.0);
        p += step * d;
        if k >= 2 {
            let rho2 = p.x * p.x + p.y * p.y;
            let rho = rho2.sqrt();
            if let (Some(iz), Some(ir)) = (cfg.z.cell(p.z), cfg.rho.cell(rho)) {
                t.inside[k - 1] += 1;
                let r = (rho2 + p.z * p.z).sqrt();
                // μ' = â·ω' with â = p/r (the beam direction at the origin itself).
                let mu = if r > 0.0 { (p.dot(d) / r).clamp(-1.0, 1.0) } else { d.z };
                let jm = ((direction_coordinate(mu) * nbins) as usize).min(cfg.direction_bins - 1);
                let jp = if phi_bins > 1 {
                    let (_, e1, e2) = lobe_frame(p);
                    let phi = d.dot(e2).abs().atan2(d.dot(e1));
                    ((phi / PI * phi_bins as f64) as usize).min(phi_bins - 1)
                } else {
                    0
                };
                let cell = iz * cfg.rho.bins + ir;
                let slot = (cell * bins + jm * phi_bins + jp) as u64;
                t.pending.push(slot << ORDER_BITS | k as u64);
            }
        } else {
            t.inside[0] += u64::from(cfg.z.cell(p.z).is_some());
        }
        // Scatter about d: cosine μ from HG, azimuth uniform, in the frame built from d alone.
        let mu = hg::sample_mu(rng.uniform(dim + 1), cfg.g);
        let (sp, cp) = (2.0 * PI * rng.uniform(dim + 2)).sin_cos();
        let s = (1.0 - mu * mu).max(0.0).sqrt();
        d = if d.z.abs() < 0.999_99 {
            let q = (1.0 - d.z * d.z).sqrt();
            DVec3::new(
                mu * d.x + s * (d.x * d.z * cp - d.y * sp) / q,
                mu * d.y + s * (d.y * d.z * cp + d.x * sp) / q,
                mu * d.z - s * cp * q,
            )
        } else {
            let sign = d.z.signum();
            DVec3::new(s * cp, s * sp, sign * mu)
        };
        d /= d.length();
    }
    t.events += cfg.max_order as u64;
    if !p.is_finite() {
        t.dropped += 1;
    }
}

/// Histograms → lobes: normalise per photon and cell volume, apply the kernel, add the remainder.
fn finish(cfg: &LobeConfig, t: &Tally) -> LobeResponse {
    use rayon::prelude::*;
    let na = cfg.albedos.len();
    let channels = 1 + na;
    let bins = cfg.bins();
    let lobe_len = cfg.lobe_len();
    let k = kernel(cfg);
    let unit = (-f64::from(cfg.scale_bits())).exp2() / cfg.photons as f64;
    let iso = 1.0 / (4.0 * PI);
    let nr = cfg.rho.bins;
    // One z row per task (each cell is independent; rows are collected in order, so the result does
    // not depend on the thread count): (E_2 lobes, per albedo: lobes, density, closure density).
    type Row = (Vec<f64>, Vec<Vec<f64>>, Vec<Vec<f64>>, Vec<Vec<f64>>);
    let rows: Vec<Row> = (0..cfg.z.bins)
        .into_par_iter()
        .map(|iz| {
            let (z0, z1) = (cfg.z.edge(iz), cfg.z.edge(iz + 1));
            let mut double = vec![0.0; nr * lobe_len];
            let mut total = vec![vec![0.0; nr * lobe_len]; na];
            let mut density = vec![vec![0.0; nr]; na];
            let mut rem_density = vec![vec![0.0; nr]; na];
            let mut h = vec![0.0; bins];
            for ir in 0..nr {
                let (r0, r1) = (cfg.rho.edge(ir), cfg.rho.edge(ir + 1));
                let volume = PI * (r1 * r1 - r0 * r0) * (z1 - z0);
                let cell = iz * nr + ir;
                let (rc, zc) = (cfg.rho.center(ir), cfg.z.center(iz));
                for ch in 0..channels {
                    let mut sum = 0.0;
                    for (j, hj) in h.iter_mut().enumerate() {
                        *hj = t.hist[(cell * bins + j) * channels + ch] as f64 * unit / volume;
                        sum += *hj;
                    }
                    // Channels: albedo nodes in descending order, then E_2.
                    let albedo_index = (ch < na).then(|| na - 1 - ch);
                    let out = match albedo_index {
                        None => &mut double[ir * lobe_len..(ir + 1) * lobe_len],
                        Some(ai) => &mut total[ai][ir * lobe_len..(ir + 1) * lobe_len],
                    };
                    if sum > 0.0 {
                        for (o, v) in out.iter_mut().enumerate() {
                            let row = &k[o * bins..(o + 1) * bins];
                            *v = row.iter().zip(&h).map(|(a, b)| a * b).sum();
                        }
                    }
                    if let Some(ai) = albedo_index {
                        let rem = remainder(cfg.albedos[ai], cfg.g, cfg.max_order, rc, zc);
                        for v in out.iter_mut() {
                            *v += rem * iso;
                        }
                        density[ai][ir] = sum + rem;
                        rem_density[ai][ir] = rem;
                    }
                }
            }
            (double, total, density, rem_density)
        })
        .collect();
    let mut out = LobeResponse {
        double: Vec::with_capacity(cfg.cells() * lobe_len),
        total: vec![Vec::with_capacity(cfg.cells() * lobe_len); na],
        density: vec![Vec::with_capacity(cfg.cells()); na],
        remainder_density: vec![Vec::with_capacity(cfg.cells()); na],
        inside: t.inside.iter().map(|&c| c as f64 / cfg.photons as f64).collect(),
        events: t.events,
        nonfinite_discarded: t.dropped,
    };
    for (double, total, density, rem) in rows {
        out.double.extend(double);
        for ai in 0..na {
            out.total[ai].extend_from_slice(&total[ai]);
            out.density[ai].extend_from_slice(&density[ai]);
            out.remainder_density[ai].extend_from_slice(&rem[ai]);
        }
    }
    out
}

/// Coordinate of the direction bins, `x(μ') = ½ + ½ sign(μ')(1 − √(1 − |μ'|))` ∈ [0, 1]: linear in μ'
/// near μ' = 0 and linear in the angle near the poles, where the incoming directions of low orders
/// crowd (bins uniform in μ' would be ~14° wide at the poles with 64 bins, as wide as a g = 0.7 lobe).
pub fn direction_coordinate(mu: f64) -> f64 {
    let m = mu.clamp(-1.0, 1.0);
    0.5 + 0.5 * m.signum() * (1.0 - (1.0 - m.abs()).sqrt())
}

/// Inverse of [`direction_coordinate`]: `(μ', dμ'/dx)`.
pub fn direction_inverse(x: f64) -> (f64, f64) {
    let t = 2.0 * x.clamp(0.0, 1.0) - 1.0;
    let v = t.abs();
    (t.signum() * (1.0 - (1.0 - v) * (1.0 - v)), 4.0 * (1.0 - v))
}

/// Polar angle of lobe node `i` (uniform over `[0, π]`).
pub fn theta_node(i: usize, n: usize) -> f64 {
    PI * i as f64 / (n.max(2) - 1) as f64
}

/// The direction-bin kernel: `K[o][b]` = the HG phase `p(ω_o·ω')` averaged over the incoming
/// directions `ω'` of histogram bin `b` (both mirror images of its azimuth range), and for the
/// symmetric lobe over the azimuth of the outgoing `ω_o` about `â` as well. Row-major `[o][b]`.
pub fn kernel(cfg: &LobeConfig) -> Vec<f64> {
    use rayon::prelude::*;
    let gl_mu = crate::physics::sh::gauss_legendre(8);
    let nb = cfg.bins();
    let n_phi = cfg.phi_nodes();
    let mut out = vec![0.0; cfg.lobe_len() * nb];
    // Sub-nodes of each direction bin: (μ', weight) with weights ∝ dμ'/dx (uniform in solid angle
    // within the bin), summing to 1.
    let dx = 1.0 / cfg.direction_bins as f64;
    let sub: Vec<Vec<(f64, f64)>> = (0..cfg.direction_bins)
        .map(|j| {
            let nodes: Vec<(f64, f64)> = gl_mu
                .iter()
                .map(|&(x, w)| {
                    let xv = dx * (j as f64 + 0.5 * (x + 1.0));
                    let (mu, jac) = direction_inverse(xv);
                    (mu, w * jac)
                })
                .collect();
            let total: f64 = nodes.iter().map(|n| n.1).sum();
            nodes.into_iter().map(|(mu, w)| (mu, w / total)).collect()
        })
        .collect();
    match cfg.shape {
        LobeShape::Symmetric => {
            // Relative azimuth quadrature: periodic trapezoid on [0, π] (the integrand is even).
            let m = 1024usize;
            let cos_phi: Vec<f64> = (0..=m).map(|q| (PI * q as f64 / m as f64).cos()).collect();
            let rows: Vec<Vec<f64>> = (0..cfg.theta_nodes)
                .into_par_iter()
                .map(|i| {
                    let th = theta_node(i, cfg.theta_nodes);
                    let (ct, st) = (th.cos(), th.sin());
                    (0..cfg.direction_bins)
                        .map(|j| {
                            let mut acc = 0.0;
                            for &(mu, w) in &sub[j] {
                                let s = (1.0 - mu * mu).max(0.0).sqrt();
                                let mut avg = 0.0;
                                for (q, c) in cos_phi.iter().enumerate() {
                                    let wq = if q == 0 || q == m { 0.5 } else { 1.0 };
                                    avg += wq * hg::phase(ct * mu + st * s * c, cfg.g);
                                }
                                acc += w * avg / m as f64;
                            }
                            acc
                        })
                        .collect()
                })
                .collect();
            for (i, row) in rows.into_iter().enumerate() {
                out[i * nb..i * nb + row.len()].copy_from_slice(&row);
            }
        }
        LobeShape::Full { phi_bins } => {
            let gl_phi = crate::physics::sh::gauss_legendre(6);
            let dphi = PI / phi_bins as f64;
            for i in 0..cfg.theta_nodes {
                let th = theta_node(i, cfg.theta_nodes);
                let (ct, st) = (th.cos(), th.sin());
                for m_out in 0..n_phi {
                    let phi_o = PI * m_out as f64 / (n_phi - 1) as f64;
                    let o = i * n_phi + m_out;
                    for j in 0..cfg.direction_bins {
                        for q in 0..phi_bins {
                            let mut acc = 0.0;
                            for &(mu, w) in &sub[j] {
                                let s = (1.0 - mu * mu).max(0.0).sqrt();
                                for &(y, v) in &gl_phi {
                                    let phi = dphi * (q as f64 + 0.5 * (y + 1.0));
                                    let a = hg::phase(ct * mu + st * s * (phi_o - phi).cos(), cfg.g);
                                    let b = hg::phase(ct * mu + st * s * (phi_o + phi).cos(), cfg.g);
                                    acc += 0.5 * w * v * 0.5 * (a + b);
                                }
                            }
                            out[o * nb + j * phi_bins + q] = acc;
                        }
                    }
                }
            }
        }
    }
    out
}
