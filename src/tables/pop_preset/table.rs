//! The consumer side of `PopPreset`: a loaded preset (resolved settings plus its four arrays) with
//! flow-table interpolation and the Eq. 10 switch iteration, and its error estimates against
//! independent references.
//!
//! Input: a `.vtab` file or in-memory generated arrays. Output: [`PopPresetTable`] (ordinates,
//! cell solid angles and mean cosines, `flow(a)` clamped to a ∈ [−1, 1]) and the sidecar's error
//! estimates: flow against the double-double cumulative of [`crate::reference::hg_hp`], the cell
//! integrals against a counter-based Monte-Carlo estimate with a brute-force nearest search.

use std::f64::consts::{FRAC_1_SQRT_2, PI};
use std::path::Path;

use glam::DVec3;
use rayon::prelude::*;

use super::ordinates::NearestDirection;
use super::{PopPreset, PopPresetRaw};
use crate::container::{ArrayDesc, ArrayValues};
use crate::physics::rng::StreamKey;
use crate::reference::hg_hp;
use crate::tables::{ErrorEstimate, TableDef, TableReadError};

/// Array names in the order the generator writes them.
pub const ARRAYS: [&str; 4] = ["ordinates", "ordinate_solid_angle", "ordinate_mean_cosine", "flow"];

/// Random directions used to check the stored cell mean cosines.
pub const MEAN_COSINE_CHECK_SAMPLES: u64 = 1 << 17;

/// Resolution of the polar angle of the covering-radius test grid (twice as many azimuths).
const COVERING_THETA_ROWS: usize = 512;

/// A loaded PopPreset table.
#[derive(Debug, Clone)]
pub struct PopPresetTable {
    /// The resolved preset settings (iterations, thresholds, grids, β, …) as stored in the file.
    pub def: PopPreset,
    ordinates: Vec<[f64; 3]>,
    solid_angles: Vec<f64>,
    mean_cosines: Vec<f64>,
    flow: Vec<[f64; 3]>,
}

impl PopPresetTable {
    /// Opens a `.vtab` holding a PopPreset table and loads all of it (a few kilobytes).
    pub fn open(path: &Path) -> Result<Self, TableReadError> {
        let layout = |m: String| TableReadError::Layout(format!("{}: {m}", path.display()));
        let container = |source| TableReadError::Container { path: path.to_path_buf(), source };
        let (mut r, def) =
            crate::tables::open_kind(path, (PopPresetRaw::KIND, super::KIND_SCHEMA_VERSION), container, layout)?;
        let TableDef::PopPreset(def) = def else {
            return Err(layout("its stored definition is not a readable PopPreset definition".into()));
        };
        let descs = r.header().arrays.clone();
        let values = (0..descs.len()).map(|i| r.read_array(i).map_err(container)).collect::<Result<Vec<_>, _>>()?;
        Self::from_arrays(&def, &descs, &values).map_err(layout)
    }

    /// Builds a table from in-memory arrays (as generated) and the definition they came from,
    /// checking that every shape matches the definition.
    pub fn from_arrays(def: &PopPreset, descs: &[ArrayDesc], values: &[ArrayValues]) -> Result<Self, String> {
        let names: Vec<&str> = descs.iter().map(|d| d.name.as_str()).collect();
        if names != ARRAYS || values.len() != ARRAYS.len() {
            return Err(format!("unexpected PopPreset arrays {names:?}; expected {ARRAYS:?}"));
        }
        let n = def.ordinates as u64;
        let bins = u64::from(def.a_bins);
        let want: [Vec<u64>; 4] = [vec![n, 3], vec![n], vec![n], vec![bins, 3]];
        for ((d, v), shape) in descs.iter().zip(values).zip(&want) {
            if d.shape() != *shape || v.len() as u64 != shape.iter().product::<u64>() {
                return Err(format!(
                    "PopPreset array {} has shape {:?} and {} values; its definition implies {shape:?}",
                    d.name,
                    d.shape(),
                    v.len()
                ));
            }
        }
        let a = &descs[3].axes[0];
        if bins < 2 || a.value(0) != -1.0 || a.value(bins - 1) != 1.0 {
            return Err("PopPreset flow table's anisotropy axis must run from -1 to 1 with at least 2 samples".into());
        }
        let triples = |v: &ArrayValues| v.to_f64().chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect::<Vec<_>>();
        Ok(Self {
            def: def.clone(),
            ordinates: triples(&values[0]),
            solid_angles: values[1].to_f64(),
            mean_cosines: values[2].to_f64(),
            flow: triples(&values[3]),
        })
    }

    /// The principal directions d_n (unit vectors, spherical Fibonacci order).
    pub fn ordinates(&self) -> &[[f64; 3]] {
        &self.ordinates
    }

    /// Solid angle Ω_n of each ordinate's Voronoi cell in sr (Σ = 4π).
    pub fn solid_angles(&self) -> &[f64] {
        &self.solid_angles
    }

    /// Prefiltered initial anisotropy a_n of each ordinate (elek2014 Sec. 5.1): the mean cosine
    /// between d_n and the directions of its cell.
    pub fn mean_cosines(&self) -> &[f64] {
        &self.mean_cosines
    }

    /// The stored flow rows `[front, side (each of four), back]` at `a_j = −1 + 2j/(a_bins − 1)`.
    pub fn flow_rows(&self) -> &[[f64; 3]] {
        &self.flow
    }

    /// `[front, side (each of four), back]` fractions of an HG lobe with mean cosine `a` (elek2014
    /// Eqs. 2–3) by linear interpolation in the table; `a` is clamped to [−1, 1], NaN gives NaNs.
    pub fn flow(&self, a: f64) -> [f64; 3] {
        lerp_flow(&self.flow, a)
    }

    /// Eq. 10 switch iteration with this preset's ε_a, `iterations` and `residuum`
    /// (see [`PopPreset::switch_iteration`]).
    pub fn switch_iteration(&self, a_max: f64, g: f64, sigma_s_mean: f64, dx: f64, grid_len: usize) -> usize {
        self.def.switch_iteration(a_max, g, sigma_s_mean, dx, grid_len)
    }

    /// Max absolute error of [`Self::flow`] against [`flow_reference`] at the bin midpoints, 4096
    /// off-grid anisotropies and anisotropies next to and at ±1 and 0.
    pub fn flow_interp_error(&self) -> f64 {
        let bins = self.flow.len();
        let mut probes: Vec<f64> = (0..bins - 1).map(|j| -1.0 + (2.0 * j as f64 + 1.0) / (bins - 1) as f64).collect();
        let golden = 0.618_033_988_749_894_9;
        probes.extend((0..4096).map(|i| 2.0 * ((i as f64 + golden) / 4096.0) - 1.0));
        for e in [1e-3, 1e-6, 1e-9, 1e-12] {
            probes.extend([1.0 - e, e - 1.0, e, -e]);
        }
        probes.extend([-1.0, 0.0, 1.0]);
        probes
            .par_iter()
            .map(|&a| {
                let (t, r) = (self.flow(a), flow_reference(a));
                (0..3).map(|k| (t[k] - r[k]).abs()).fold(0.0, f64::max)
            })
            .reduce(|| 0.0, f64::max)
    }

    /// The error estimates written to the sidecar; the first is the headline.
    pub fn error_estimates(&self, key: &[u8; 32]) -> Vec<ErrorEstimate> {
        let sum_dev = self.flow.iter().map(|[f, s, b]| (f + 4.0 * s + b - 1.0).abs()).fold(0.0, f64::max);
        let n = self.ordinates.len() as f64;
        let cell = 4.0 * PI / n;
        let omega_dev = self.solid_angles.iter().map(|o| (o / cell - 1.0).abs()).fold(0.0, f64::max);
        let (mc_dev, mc_se) = self.mean_cosine_mc_check(key);
        let e = |name: &str, value: f64, how: String| ErrorEstimate { name: name.into(), value, how };
        vec![
            e(
                "flow_interp_max_abs",
                self.flow_interp_error(),
                "max absolute error of linearly interpolated [front, side, back] at the bin midpoints, 4096 off-grid a and a = ±(1 - 1e-3 ... 1e-12), ±1e-3 ... ±1e-12, -1, 0, 1, vs 2 pi (F(1) - F(cos pi/4)), pi/2 (F(cos pi/4) - F(-cos pi/4)), 2 pi F(-cos pi/4) with the double-double F_hg of reference::hg_hp (includes element rounding)".into(),
            ),
            e(
                "flow_sum_max_dev",
                sum_dev,
                "max |front + 4 side + back - 1| over the stored flow rows (after conversion to the element type)".into(),
            ),
            e(
                "ordinate_covering_deg",
                covering_radius_deg(&self.ordinates),
                format!(
                    "covering radius of the ordinates in degrees: max over a {COVERING_THETA_ROWS} x {} cell-centred grid of test directions (uniform in polar angle and azimuth) of the angle to the nearest ordinate; underestimates by at most {:.2} deg",
                    2 * COVERING_THETA_ROWS,
                    180.0 / COVERING_THETA_ROWS as f64 * FRAC_1_SQRT_2
                ),
            ),
            e(
                "ordinate_solid_angle_max_rel_dev",
                omega_dev,
                "max |Omega_n / (4 pi / N) - 1| over the stored cell solid angles (how unequal the cells are)".into(),
            ),
            e(
                "mean_cosine_check",
                mc_dev,
                format!(
                    "max |a_n - a_n(MC)| over cells, a_n(MC) = mean of d_n . w over {MEAN_COSINE_CHECK_SAMPLES} counter-based uniform random directions assigned to their nearest ordinate by brute force; largest per-cell MC standard error {mc_se:.2e}"
                ),
            ),
        ]
    }

    /// (max |a_n − MC estimate|, largest per-cell MC standard error).
    fn mean_cosine_mc_check(&self, key: &[u8; 32]) -> (f64, f64) {
        let n = self.ordinates.len();
        let stream = StreamKey::from_content_key(key, 0);
        let chunk = 4096u64;
        let parts: Vec<Vec<(u64, f64, f64)>> = (0..MEAN_COSINE_CHECK_SAMPLES.div_ceil(chunk))
            .into_par_iter()
            .map(|c| {
                let mut acc = vec![(0u64, 0.0f64, 0.0f64); n];
                for k in c * chunk..((c + 1) * chunk).min(MEAN_COSINE_CHECK_SAMPLES) {
                    let s = stream.sample(k);
                    let z = 1.0 - 2.0 * s.uniform(0);
                    let r = ((1.0 - z) * (1.0 + z)).max(0.0).sqrt();
                    let phi = 2.0 * PI * s.uniform(1);
                    let w = DVec3::new(r * phi.cos(), r * phi.sin(), z);
                    // Brute force: shares no code with the generator's sweep search.
                    let (mut best, mut best_cos) = (0, f64::NEG_INFINITY);
                    for (j, d) in self.ordinates.iter().enumerate() {
                        let c = DVec3::from_array(*d).dot(w);
                        if c > best_cos {
                            (best, best_cos) = (j, c);
                        }
                    }
                    let a = &mut acc[best];
                    *a = (a.0 + 1, a.1 + best_cos, a.2 + best_cos * best_cos);
                }
                acc
            })
            .collect();
        let (mut dev, mut se) = (0.0f64, 0.0f64);
        for (j, &stored) in self.mean_cosines.iter().enumerate() {
            let (mut m, mut s, mut s2) = (0u64, 0.0, 0.0);
            for p in &parts {
                (m, s, s2) = (m + p[j].0, s + p[j].1, s2 + p[j].2);
            }
            if m < 2 {
                continue;
            }
            let mf = m as f64;
            let mean = s / mf;
            let var = ((s2 - s * mean) / (mf - 1.0)).max(0.0);
            dev = dev.max((stored - mean).abs());
            se = se.max((var / mf).sqrt());
        }
        (dev, se)
    }
}

/// Linear interpolation of flow rows sampled uniformly on a ∈ [−1, 1] (first row a = −1, last
/// a = 1); `a` is clamped, NaN (or fewer than two rows) gives NaNs.
pub fn lerp_flow(rows: &[[f64; 3]], a: f64) -> [f64; 3] {
    let n = rows.len();
    if a.is_nan() || n < 2 {
        return [f64::NAN; 3];
    }
    let t = (a.clamp(-1.0, 1.0) + 1.0) * 0.5 * (n - 1) as f64;
    let i = (t.floor() as usize).min(n - 2);
    let f = t - i as f64;
    let (r0, r1) = (rows[i], rows[i + 1]);
    [0, 1, 2].map(|k| r0[k] * (1.0 - f) + r1[k] * f)
}

/// Independent reference of the flow partition (elek2014 Eqs. 2–3) from the double-double
/// per-azimuth cumulative `F = `[`hg_hp::cdf_per_azimuth_ref`]: front `2π (F(1) − F(cos π/4))`,
/// each side `π/2 · (F(cos π/4) − F(−cos π/4))`, back `2π F(−cos π/4)`; `a = ±1` are the Dirac lobes
/// `[1, 0, 0]`, `[0, 0, 1]`; `a` is clamped, NaN gives NaNs.
pub fn flow_reference(a: f64) -> [f64; 3] {
    if a.is_nan() {
        return [f64::NAN; 3];
    }
    if a >= 1.0 {
        return [1.0, 0.0, 0.0];
    }
    if a <= -1.0 {
        return [0.0, 0.0, 1.0];
    }
    let f = |mu: f64| hg_hp::cdf_per_azimuth_ref(mu, a);
    let (c, top) = (FRAC_1_SQRT_2, f(1.0));
    let (fc, fm) = (f(c), f(-c));
    [2.0 * PI * (top - fc), 0.5 * PI * (fc - fm), 2.0 * PI * fm]
}

/// Covering radius in degrees of a direction set: the largest angle from a test direction (centres
/// of a grid uniform in polar angle and azimuth) to its nearest direction.
pub fn covering_radius_deg(dirs: &[[f64; 3]]) -> f64 {
    let search = NearestDirection::new(dirs);
    let rows = COVERING_THETA_ROWS;
    let cols = 2 * rows;
    let worst_cos = (0..rows)
        .into_par_iter()
        .map(|i| {
            let theta = PI * (i as f64 + 0.5) / rows as f64;
            let (st, ct) = theta.sin_cos();
            (0..cols)
                .map(|k| {
                    let phi = 2.0 * PI * (k as f64 + 0.5) / cols as f64;
                    let w = [st * phi.cos(), st * phi.sin(), ct];
                    search.nearest(w).map_or(-1.0, |(_, c)| c)
                })
                .fold(1.0, f64::min)
        })
        .reduce(|| 1.0, f64::min);
    worst_cos.clamp(-1.0, 1.0).acos().to_degrees()
}
