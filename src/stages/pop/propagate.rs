//! Principal-ordinates propagation on one light-aligned grid (elek2014 Secs. 4.1–4.3, 5.4).
//!
//! **Input → output.** A [`Grid`], a [`DirectionalLight`], the flow table of a POP preset and the
//! iteration settings → per cell the uncollided fluence, the collided fluence, and what an observer
//! needs: the radiance scattered toward an eye (Eqs. 7–8, convolved with the phase function) or the
//! incident radiance binned by the angle from `d` (elek2014 Fig. 12).
//!
//! **Scheme.** Each cell holds a magnitude `L_i` (the fluence `∫ L dω` of its lobe) and an
//! anisotropy `a_i`: `L(x_i, ω) = L_i f_hg(ω·d, a_i)` (Sec. 4). One iteration gathers, for every
//! cell, the six neighbours' flows `ΔL = L_src · T_src→dst · P(a_src)` (Eq. 2 with the Eq. 3
//! partition, [`crate::physics::hg::pop_partition`] tabulated by the preset) and anisotropies
//! `a_src · g^{σ̄_s t}` (Eq. 4), combined by Eqs. 5–6. Every cell's energy moves on each iteration,
//! so the steady-state field is the sum of the iterates; `Σ_i L_i` never increases (the partition
//! sums to 1 and `T ≤ 1`).
//!
//! **Initialisation (Sec. 4.1), made exact for the uncollided light.** The paper fills every cell
//! with the attenuated incident radiance `L_in T_i` at `a = 1` and propagates it. Summing iterates
//! of that field counts the direct beam once per cell it has crossed (a vacuum cell `k` cells deep
//! would accumulate `k · L_in`). voltab keeps the transmittance sweep but splits it: the uncollided
//! beam `E · T_i` stays a Dirac lobe evaluated exactly (no propagation, no false scattering), and
//! each cell is seeded with the light that scatters in it for the first time,
//! `S_i = E T_in (σ_s/σ_t)(1 − e^{−σ_t Δz})`, with the single-scattering anisotropy `a = g` (the
//! once-scattered lobe about `d` is exactly HG(g)). The seed is counted at half weight in the sum
//! (light scattered inside a cell crosses on average half of it there).
//!
//! **Isotropic residuum (Sec. 5.4).** When `m'` (Eq. 10) is below the iteration budget `M`, after
//! `m'` anisotropic iterations the remaining energy is propagated with `a = 0` (fixed partition, no
//! anisotropy bookkeeping) until it falls below `ε_L` of the seeded energy. Otherwise `M` anisotropic
//! iterations run and what is left is reported, not turned isotropic.

use std::time::Instant;

use glam::DVec3;
use rayon::prelude::*;

use super::grid::Grid;

use crate::render::occluder::Occluder;

use crate::physics::hg;
use crate::physics::medium::extinguished;
use crate::render::color::Rgb;
use crate::render::voxel::DirectionalLight;

/// The Eq. 2–3 partition tabulated on a uniform anisotropy axis `a ∈ [−1, 1]` (a POP preset's
/// `flow` array), linearly interpolated.
#[derive(Debug, Clone, PartialEq)]
pub struct FlowTable {
    rows: Vec<[f64; 3]>,
}

impl FlowTable {
    /// The exact partition at `bins` nodes (≥ 2).
    pub fn exact(bins: usize) -> Self {
        let bins = bins.max(2);
        Self { rows: (0..bins).map(|j| hg::pop_partition(-1.0 + 2.0 * j as f64 / (bins - 1) as f64)).collect() }
    }

    /// A table read from a preset.
    ///
    /// # Errors
    /// Fewer than 2 rows, or a row that is negative, non-finite or does not sum to 1 within 1e-4.
    pub fn from_rows(rows: Vec<[f64; 3]>) -> Result<Self, String> {
        if rows.len() < 2 {
            return Err(format!("the flow table has {} rows; it needs at least 2", rows.len()));
        }
        for (j, r) in rows.iter().enumerate() {
            let sum = r[0] + 4.0 * r[1] + r[2];
            if r.iter().any(|v| !v.is_finite() || *v < 0.0) || (sum - 1.0).abs() > 1e-4 {
                return Err(format!("flow row {j} = {r:?} is not a partition (front + 4·side + back = {sum})"));
            }
        }
        Ok(Self { rows })
    }

    /// Number of nodes on the anisotropy axis.
    pub fn len(&self) -> usize {
        self.rows.len()
    }

    /// True when the table has no rows (never: both constructors require ≥ 2).
    pub fn is_empty(&self) -> bool {
        self.rows.is_empty()
    }

    /// Node `j`'s `[front, side, back]` (at `a = −1 + 2j/(len − 1)`).
    pub fn row(&self, j: usize) -> [f64; 3] {
        self.rows[j]
    }

    /// `[front, side, back]` at anisotropy `a` (clamped to `[−1, 1]`), linearly interpolated as the
    /// preset's reader does ([`crate::tables::pop_preset::lerp_flow`]).
    #[inline]
    pub fn lookup(&self, a: f64) -> [f64; 3] {
        crate::tables::pop_preset::lerp_flow(&self.rows, a)
    }
}

/// Iteration settings (from a POP preset and Eq. 10).
#[derive(Debug, Clone, PartialEq)]
pub struct Settings {
    /// Anisotropic iterations at most (`M`).
    pub iterations: usize,
    /// Switch to the isotropic residuum after `switch_iteration` anisotropic iterations, when that is
    /// fewer than `iterations`.
    pub residuum: bool,
    /// `m'` of Eq. 10.
    pub switch_iteration: usize,
    /// Isotropic iterations at most.
    pub residuum_iterations: usize,
    /// Stop when an iterate's energy falls below `eps_l` times the seeded energy.
    pub eps_l: f64,
}

/// What the accumulation grid records (Sec. 4.3).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Observer {
    /// Radiance scattered toward this eye position per unit `σ_s` (Eqs. 7–8).
    Eye(DVec3),
    /// Incident radiance averaged over `n` bins of the angle `θ ∈ [0, π]` from `d` (Fig. 12).
    ThetaBins(usize),
}

/// Wall-clock seconds per phase (elek2014 Fig. 14 names).
#[derive(Debug, Clone, Copy, Default, PartialEq, serde::Serialize)]
pub struct PhaseTimes {
    /// Transmittance sweep and seeding.
    pub initialisation: f64,
    /// Anisotropic iterations (Eqs. 2–6).
    pub propagation: f64,
    /// Isotropic residuum iterations.
    pub residuum: f64,
    /// Accumulation (Eqs. 7–8), inside the two above.
    pub accumulation: f64,
}

/// The converged (or stopped) propagation.
#[derive(Debug, Clone)]
pub struct Propagation {
    /// Uncollided fluence `E · V · T` at cell centres (a Dirac lobe along `d`).
    pub uncollided: Vec<Rgb>,
    /// Collided fluence `Σ_m L^m` per cell.
    pub fluence: Vec<Rgb>,
    /// [`Observer::Eye`]: radiance scattered toward the eye per unit `σ_s`, uncollided light
    /// included (`E T f_hg(u, g) + Σ_m L^m f_hg(u, a^m g)`); empty otherwise.
    pub toward_eye: Vec<Rgb>,
    /// [`Observer::ThetaBins`]: collided incident radiance `[cell · bins + b]`; empty otherwise.
    pub bins: Vec<Rgb>,
    /// Number of θ bins (0 for an eye).
    pub theta_bins: usize,
    /// Anisotropic iterations run.
    pub anisotropic_iterations: usize,
    /// Isotropic residuum iterations run.
    pub isotropic_iterations: usize,
    /// `Σ_cells Σ_channels L` of the seed and of every iterate (non-increasing).
    pub energy: Vec<f64>,
    /// Times per phase.
    pub times: PhaseTimes,
    /// The last iterate `L^m` (already accumulated): where a merged isotropic residuum on another grid
    /// continues ([`isotropic_residuum`]). Empty from the GPU.
    pub last: Vec<Rgb>,
}

struct Accumulator<'a> {
    grid: &'a Grid,
    observer: Observer,
    /// Per cell `d · (eye − x)/|eye − x|`.
    u: Vec<f64>,
    toward_eye: Vec<Rgb>,
    bins: Vec<Rgb>,
    fluence: Vec<Rgb>,
    seconds: f64,
}

impl<'a> Accumulator<'a> {
    fn new(grid: &'a Grid, observer: Observer) -> Self {
        let n = grid.len();
        let d = grid.axes[2];
        let (u, toward_eye, bins) = match observer {
            Observer::Eye(eye) => (
                (0..n).map(|i| (eye - grid.center(grid.coords(i))).normalize_or_zero().dot(d)).collect(),
                vec![[0.0; 3]; n],
                Vec::new(),
            ),
            Observer::ThetaBins(b) => (Vec::new(), Vec::new(), vec![[0.0; 3]; n * b.max(1)]),
        };
        Self { grid, observer, u, toward_eye, bins, fluence: vec![[0.0; 3]; n], seconds: 0.0 }
    }

    /// Adds `weight · L` with anisotropies `a` (per channel).
    fn add(&mut self, l: &[Rgb], a: &[Rgb], weight: f64) {
        let start = Instant::now();
        let g = self.grid.g;
        for (f, v) in self.fluence.iter_mut().zip(l) {
            for c in 0..3 {
                f[c] += weight * v[c];
            }
        }
        match self.observer {
            Observer::Eye(_) => {
                self.toward_eye.par_iter_mut().enumerate().for_each(|(i, t)| {
                    for c in 0..3 {
                        if l[i][c] > 0.0 {
                            t[c] += weight * l[i][c] * hg::phase(self.u[i], a[i][c] * g[c]);
                        }
                    }
                });
            }
            Observer::ThetaBins(nb) => {
                let nb = nb.max(1);
                let edges: Vec<f64> = (0..=nb).map(|b| (std::f64::consts::PI * b as f64 / nb as f64).cos()).collect();
                self.bins.par_chunks_mut(nb).enumerate().for_each(|(i, cell)| {
                    for c in 0..3 {
                        if l[i][c] <= 0.0 {
                            continue;
                        }
                        for (b, out) in cell.iter_mut().enumerate() {
                            let (hi, lo) = (edges[b], edges[b + 1]);
                            let omega = std::f64::consts::TAU * (hi - lo);
                            let frac = lobe_fraction(a[i][c], lo, hi);
                            out[c] += weight * l[i][c] * frac / omega;
                        }
                    }
                });
            }
        }
        self.seconds += start.elapsed().as_secs_f64();
    }
}

/// Fraction of an HG lobe of anisotropy `a ∈ [−1, 1]` with `cos θ ∈ [lo, hi]`.
fn lobe_fraction(a: f64, lo: f64, hi: f64) -> f64 {
    if a >= 1.0 {
        return if hi >= 1.0 { 1.0 } else { 0.0 };
    }
    if a <= -1.0 {
        return if lo <= -1.0 { 1.0 } else { 0.0 };
    }
    (hg::cdf(hi, a) - hg::cdf(lo, a)).max(0.0)
}

/// Runs the propagation of a directional light (a Dirac lobe).
pub fn propagate(
    grid: &Grid,
    light: &DirectionalLight,
    occluder: &dyn Occluder,
    flow: &FlowTable,
    settings: &Settings,
    observer: Observer,
) -> Propagation {
    propagate_lobe(grid, light, 1.0, occluder, flow, settings, observer)
}

/// Runs the propagation of a distant light whose incident radiance is an HG lobe of anisotropy
/// `spread ∈ [0, 1]` about its direction (elek2014 Sec. 5.1: an environment ordinate's prefiltered
/// initial anisotropy; `1` is a directional light). The uncollided light still travels along the
/// grid's axis (the sweep of Sec. 4.1); what the lobe changes is how it scatters: by HG
/// self-convolution, light of anisotropy `spread` scattered once has anisotropy `spread · g`, so the
/// seeds start there and the uncollided light scatters toward the eye with `f_hg(u, spread · g)`.
pub fn propagate_lobe(
    grid: &Grid,
    light: &DirectionalLight,
    spread: f64,
    occluder: &dyn Occluder,
    flow: &FlowTable,
    settings: &Settings,
    observer: Observer,
) -> Propagation {
    let start = Instant::now();
    let (uncollided, seed) = initialise(grid, light, occluder);
    let mut acc = Accumulator::new(grid, observer);
    let spread = if spread.is_finite() { spread.clamp(0.0, 1.0) } else { 1.0 };
    // `g · 1.0 == g` exactly, so a directional light keeps its former bits.
    let g = grid.g.map(|v| v * spread);
    let a0: Vec<Rgb> = vec![g; grid.len()];
    let init_seconds = start.elapsed().as_secs_f64();

    // The uncollided lobe: toward the eye it scatters with the phase convolved with the lobe.
    if let Observer::Eye(_) = observer {
        for (i, t) in acc.toward_eye.iter_mut().enumerate() {
            for c in 0..3 {
                t[c] += uncollided[i][c] * hg::phase(acc.u[i], g[c]);
            }
        }
    }
    acc.add(&seed, &a0, 0.5);
    let total = |l: &[Rgb]| l.iter().map(|v| v[0] + v[1] + v[2]).sum::<f64>();
    let seeded = total(&seed);
    let mut energy = vec![seeded];
    let stop = settings.eps_l * seeded;

    let prop_start = Instant::now();
    let mut l = seed;
    let mut a = a0;
    // The residuum takes over only where Eq. 10 says the anisotropy has decayed within the budget
    // (m' < M); otherwise the lobes are still directional after M iterations and stay so.
    let residuum = settings.residuum && settings.switch_iteration < settings.iterations;
    let anisotropic_cap = if residuum { settings.switch_iteration } else { settings.iterations };
    let mut anisotropic_iterations = 0;
    while anisotropic_iterations < anisotropic_cap && *energy.last().unwrap_or(&0.0) > stop {
        let (nl, na) = step(grid, flow, &l, Some(&a));
        l = nl;
        a = na;
        acc.add(&l, &a, 1.0);
        energy.push(total(&l));
        anisotropic_iterations += 1;
    }
    let propagation = prop_start.elapsed().as_secs_f64();

    let res_start = Instant::now();
    let mut isotropic_iterations = 0;
    if residuum {
        let zero = vec![[0.0; 3]; grid.len()];
        while isotropic_iterations < settings.residuum_iterations && *energy.last().unwrap_or(&0.0) > stop {
            l = step(grid, flow, &l, None).0;
            acc.add(&l, &zero, 1.0);
            energy.push(total(&l));
            isotropic_iterations += 1;
        }
    }
    let residuum = res_start.elapsed().as_secs_f64();
    let theta_bins = match observer {
        Observer::ThetaBins(b) => b.max(1),
        Observer::Eye(_) => 0,
    };
    Propagation {
        uncollided,
        fluence: acc.fluence,
        toward_eye: acc.toward_eye,
        bins: acc.bins,
        theta_bins,
        anisotropic_iterations,
        isotropic_iterations,
        energy,
        times: PhaseTimes { initialisation: init_seconds, propagation, residuum, accumulation: acc.seconds },
        last: l,
    }
}

/// elek2014 Sec. 5.4 with several grids: once every ordinate's lobes are nearly isotropic, their
/// remaining light `l0` (the ordinates' last iterates resampled onto `grid`, already accumulated there)
/// continues as isotropic iterations on this one grid, at most `max_iterations` and until an iterate's
/// energy falls below `stop`. Returns the accumulation toward `eye` (`L f_hg(u, 0) = L/4π` per iterate)
/// and the fluence of these iterations only; `uncollided` is zero.
pub fn isotropic_residuum(
    grid: &Grid,
    flow: &FlowTable,
    l0: Vec<Rgb>,
    max_iterations: usize,
    stop: f64,
    eye: DVec3,
) -> Propagation {
    let start = Instant::now();
    let mut acc = Accumulator::new(grid, Observer::Eye(eye));
    let total = |l: &[Rgb]| l.iter().map(|v| v[0] + v[1] + v[2]).sum::<f64>();
    let zero = vec![[0.0; 3]; grid.len()];
    let mut energy = vec![total(&l0)];
    let mut l = l0;
    let mut isotropic_iterations = 0;
    while isotropic_iterations < max_iterations && *energy.last().unwrap_or(&0.0) > stop {
        l = step(grid, flow, &l, None).0;
        acc.add(&l, &zero, 1.0);
        energy.push(total(&l));
        isotropic_iterations += 1;
    }
    Propagation {
        uncollided: zero,
        fluence: acc.fluence,
        toward_eye: acc.toward_eye,
        bins: Vec::new(),
        theta_bins: 0,
        anisotropic_iterations: 0,
        isotropic_iterations,
        energy,
        times: PhaseTimes {
            initialisation: 0.0,
            propagation: 0.0,
            residuum: start.elapsed().as_secs_f64(),
            accumulation: acc.seconds,
        },
        last: l,
    }
}

/// Sec. 4.1 sweep along `d`: the uncollided fluence at cell centres and the first-scattering seed.
pub(crate) fn initialise(grid: &Grid, light: &DirectionalLight, occluder: &dyn Occluder) -> (Vec<Rgb>, Vec<Rgb>) {
    let n = grid.len();
    let mut uncollided = vec![[0.0; 3]; n];
    let mut seed = vec![[0.0; 3]; n];
    let dz = grid.size[2];
    let d = grid.axes[2];
    let columns: Vec<(usize, Vec<(Rgb, Rgb)>)> = (0..grid.dims[0] * grid.dims[1])
        .into_par_iter()
        .map(|col| {
            let (i, j) = (col % grid.dims[0], col / grid.dims[0]);
            let mut t_in = [1.0; 3];
            let mut out = Vec::with_capacity(grid.dims[2]);
            for k in 0..grid.dims[2] {
                let cell = &grid.cells[grid.index([i, j, k])];
                let visible = !occluder.ray_blocked(grid.center([i, j, k]), -d);
                let mut u = [0.0; 3];
                let mut s = [0.0; 3];
                for c in 0..3 {
                    let st = cell.sigma_s[c] + cell.sigma_a[c];
                    if visible {
                        let e = light.irradiance[c] * t_in[c];
                        u[c] = e * (-0.5 * st * dz).exp();
                        // (σ_s/σ_t)(1 − e^{−σ_t Δz}) without cancellation for small σ_t Δz.
                        s[c] = if st > 0.0 { e * cell.sigma_s[c] * extinguished(st, dz) / st } else { 0.0 };
                    }
                    t_in[c] *= (-st * dz).exp();
                }
                out.push((u, s));
            }
            (col, out)
        })
        .collect();
    for (col, out) in columns {
        let (i, j) = (col % grid.dims[0], col / grid.dims[0]);
        for (k, (u, s)) in out.into_iter().enumerate() {
            let idx = grid.index([i, j, k]);
            uncollided[idx] = u;
            seed[idx] = s;
        }
    }
    (uncollided, seed)
}

/// Every source cell's flow partition for one iteration, `[channel][front, side, back]` (Eq. 2 at the
/// cell's anisotropy); empty for the isotropic residuum (`a = None`), which uses `flow.lookup(0)`.
pub(crate) fn partitions(flow: &FlowTable, a: Option<&[Rgb]>) -> Vec<[[f64; 3]; 3]> {
    match a {
        Some(a) => a.par_iter().map(|v| [flow.lookup(v[0]), flow.lookup(v[1]), flow.lookup(v[2])]).collect(),
        None => Vec::new(),
    }
}

/// One cell's gather (Eqs. 4–6), shared by the rectilinear and the radial grids: what flows in over
/// `links` — (source cell, part index front/side/back, link transmittance, link decay) — from the
/// field `l`, and the new anisotropy, the flow-weighted mean of the sources' decayed `a` (0 for the
/// isotropic residuum, `a = None`, whose partition is `iso`).
pub(crate) fn gather(
    links: impl IntoIterator<Item = (usize, usize, Rgb, Rgb)>,
    l: &[Rgb],
    parts: &[[[f64; 3]; 3]],
    iso: [f64; 3],
    a: Option<&[Rgb]>,
) -> (Rgb, Rgb) {
    let mut sum_l = [0.0; 3];
    let mut sum_la = [0.0; 3];
    for (src, part, t, decay) in links {
        for ch in 0..3 {
            let ls = l[src][ch];
            if ls <= 0.0 || t[ch] <= 0.0 {
                continue;
            }
            let frac = match a {
                Some(_) => parts[src][ch][part],
                None => iso[part],
            };
            let dl = ls * t[ch] * frac;
            sum_l[ch] += dl;
            if let Some(a) = a {
                sum_la[ch] += dl * a[src][ch] * decay[ch];
            }
        }
    }
    let mut na = [0.0; 3];
    if a.is_some() {
        for ch in 0..3 {
            if sum_l[ch] > 0.0 {
                na[ch] = (sum_la[ch] / sum_l[ch]).clamp(-1.0, 1.0);
            }
        }
    }
    (sum_l, na)
}

/// One gathering iteration (Eqs. 2–6). `a = None`: isotropic residuum (all lobes `a = 0`).
fn step(grid: &Grid, flow: &FlowTable, l: &[Rgb], a: Option<&[Rgb]>) -> (Vec<Rgb>, Vec<Rgb>) {
    let iso = flow.lookup(0.0);
    let parts = partitions(flow, a);
    let dims = grid.dims;
    let out: Vec<(Rgb, Rgb)> = (0..grid.len())
        .into_par_iter()
        .map(|n| {
            let c = grid.coords(n);
            let links = (0..3).flat_map(|axis| [-1i64, 1].map(|dir| (axis, dir))).filter_map(|(axis, dir)| {
                let nb = c[axis] as i64 + dir;
                if nb < 0 || nb >= dims[axis] as i64 {
                    return None;
                }
                let mut sc = c;
                sc[axis] = nb as usize;
                let src = grid.index(sc);
                // The link is stored at the lower cell of the pair.
                let link = if dir < 0 { src } else { n };
                // Part index: flow along +d from a src behind (dir < 0) is "front".
                let part = match (axis, dir) {
                    (2, -1) => 0,
                    (2, _) => 2,
                    _ => 1,
                };
                Some((src, part, grid.link_transmittance[link][axis], grid.link_decay[link][axis]))
            });
            gather(links, l, &parts, iso, a)
        })
        .collect();
    out.into_iter().unzip()
}
