//! The consumer side of `PhaseHg`: a loaded table (all or some g slices) with interpolating
//! lookups, and its error estimates against the double-double reference.
//!
//! Input: a `.vtab` file (only the wanted g slices are decompressed) or in-memory generated arrays.
//! Output: `phase_lerp`, `cdf_per_azimuth_lerp`, `sample_mu_lerp`, `zh` per g, and the error
//! estimates written to the sidecar. Lookups clamp μ and ξ to their axis ranges.

use super::{KIND_SCHEMA_VERSION, PhaseHgRaw};
use crate::container::{ArrayDesc, ArrayValues};
use crate::physics::rng::StreamKey;
use crate::reference::hg_hp;
use crate::tables::ErrorEstimate;

/// Random samples per g used to check the stored inverse CDF as a sampler.
pub const SAMPLER_CHECK_SAMPLES: u64 = 1 << 16;

/// Probe points (off-grid) at which lookups are compared with the reference.
fn probe_mus(n: usize) -> Vec<f64> {
    // Half uniform in μ, half uniform in angle, at irrational offsets so no probe lies on a node.
    let phi = 0.618_033_988_749_894_9;
    let mut v: Vec<f64> = (0..n)
        .flat_map(|i| {
            let t = (i as f64 + phi) / n as f64;
            [2.0 * t - 1.0, -(std::f64::consts::PI * t).cos()]
        })
        .collect();
    v.sort_by(f64::total_cmp);
    v
}

/// A loaded PhaseHg table (all or some g slices), with interpolating lookups.
#[derive(Debug, Clone)]
pub struct PhaseHgTable {
    /// The g value of every slice in the file.
    pub g: Vec<f64>,
    mu: Vec<f64>,
    xi_bins: usize,
    /// Loaded slices: (g index, arrays in file order as f64).
    slices: Vec<(usize, [Vec<f64>; 5])>,
}

/// Array names in the order the generator writes them.
pub const ARRAYS: [&str; 5] = ["phase", "cdf_per_azimuth", "inv_cdf", "zh", "legendre"];

/// Failure to load a PhaseHg table.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum PhaseHgReadError {
    /// The container is unreadable.
    #[error(transparent)]
    Container(#[from] crate::container::ContainerError),
    /// The file is a valid container but not a PhaseHg table this build understands.
    #[error("{0}")]
    Layout(String),
}

impl PhaseHgTable {
    /// Opens a `.vtab` and loads only the slices whose g is in `wanted` (all when `None`); g values
    /// match within 1e-9 so grid values can be named as written (`-0.5` for -0.49999999999999994).
    /// A wanted g that the table lacks is an error naming the available values.
    pub fn open(path: &std::path::Path, wanted: Option<&[f64]>) -> Result<Self, PhaseHgReadError> {
        let mut r = crate::container::VtabReader::open(path)?;
        let h = r.header().clone();
        if h.kind != PhaseHgRaw::KIND {
            return Err(PhaseHgReadError::Layout(format!("{} holds a {} table, not PhaseHg", path.display(), h.kind)));
        }
        if h.kind_schema_version > KIND_SCHEMA_VERSION {
            return Err(PhaseHgReadError::Layout(format!(
                "{} uses PhaseHg layout version {}, this voltab reads up to {KIND_SCHEMA_VERSION}; upgrade voltab",
                path.display(),
                h.kind_schema_version
            )));
        }
        crate::tables::stored_definition(&h, PhaseHgRaw::KIND)
            .map_err(|m| PhaseHgReadError::Layout(format!("{}: {m}", path.display())))?;
        let mut empty = Self::from_arrays(&h.arrays, &[]).map_err(PhaseHgReadError::Layout)?;
        let idx: Vec<usize> = match wanted {
            None => (0..empty.g.len()).collect(),
            Some(w) => w
                .iter()
                .map(|g| {
                    empty.g.iter().position(|x| (x - g).abs() <= 1e-9).ok_or_else(|| {
                        PhaseHgReadError::Layout(format!(
                            "g = {g} is not in {}; it holds g = {:?}",
                            path.display(),
                            empty.g
                        ))
                    })
                })
                .collect::<Result<_, _>>()?,
        };
        for gi in idx {
            let mut arrays: [Vec<f64>; 5] = Default::default();
            for (a, slot) in arrays.iter_mut().enumerate() {
                *slot = r.read_slice(a, gi as u64)?.to_f64();
            }
            empty.slices.push((gi, arrays));
        }
        Ok(empty)
    }

    /// Builds a table from in-memory arrays (as generated), checking the layout.
    pub fn from_arrays(descs: &[ArrayDesc], values: &[ArrayValues]) -> Result<Self, String> {
        let names: Vec<&str> = descs.iter().map(|d| d.name.as_str()).collect();
        if names != ARRAYS || descs.iter().any(|d| d.axes.len() != 2) {
            return Err(format!("unexpected PhaseHg arrays {names:?}; expected {ARRAYS:?} over (g, ·)"));
        }
        // A file can be well-formed as a container yet not a usable PhaseHg table (written by a buggy
        // or hostile tool): check everything the lookups rely on, so they can index without panicking.
        let g = descs[0].axes[0].values_vec();
        let mu = descs[0].axes[1].values_vec();
        let xi_bins = descs[2].axes[1].len as usize;
        if descs.iter().any(|d| d.axes[0] != descs[0].axes[0]) || descs[1].axes[1] != descs[0].axes[1] {
            return Err("PhaseHg arrays disagree on their g or mu axes".into());
        }
        if descs[3].axes[1] != descs[4].axes[1] {
            return Err("PhaseHg zh and legendre arrays disagree on their l axis".into());
        }
        if mu.len() < 2 || xi_bins < 2 || !mu.windows(2).all(|w| w[0] < w[1]) {
            return Err(format!(
                "PhaseHg axes unusable for lookups: {} mu values (need >= 2, strictly increasing), {xi_bins} xi values (need >= 2)",
                mu.len()
            ));
        }
        let mut t = Self { g, mu, xi_bins, slices: Vec::new() };
        if !values.is_empty() {
            let flat: Vec<Vec<f64>> = values.iter().map(ArrayValues::to_f64).collect();
            for gi in 0..t.g.len() {
                let mut arrays: [Vec<f64>; 5] = Default::default();
                for (a, slot) in arrays.iter_mut().enumerate() {
                    let n = descs[a].axes[1].len as usize;
                    *slot = flat[a].get(gi * n..(gi + 1) * n).ok_or("array shorter than its axes")?.to_vec();
                }
                t.slices.push((gi, arrays));
            }
        }
        Ok(t)
    }

    fn slice(&self, gi: usize) -> Option<&[Vec<f64>; 5]> {
        self.slices.iter().find(|(i, _)| *i == gi).map(|(_, s)| s)
    }

    /// Indexes of the loaded g slices.
    pub fn loaded(&self) -> Vec<usize> {
        self.slices.iter().map(|(i, _)| *i).collect()
    }

    /// Phase value at μ (clamped to [−1, 1]) by linear interpolation; `None` if slice `gi` is not loaded.
    pub fn phase_lerp(&self, gi: usize, mu: f64) -> Option<f64> {
        self.slice(gi).map(|s| lerp_on(&self.mu, &s[0], mu))
    }

    /// F_hg at μ (clamped) by linear interpolation.
    pub fn cdf_per_azimuth_lerp(&self, gi: usize, mu: f64) -> Option<f64> {
        self.slice(gi).map(|s| lerp_on(&self.mu, &s[1], mu))
    }

    /// Importance sample: μ for ξ ∈ [0, 1] (clamped) by linear interpolation of the inverse CDF.
    pub fn sample_mu_lerp(&self, gi: usize, xi: f64) -> Option<f64> {
        let s = self.slice(gi)?;
        let t = xi.clamp(0.0, 1.0) * (self.xi_bins - 1) as f64;
        let i = (t.floor() as usize).min(self.xi_bins.saturating_sub(2));
        let f = t - i as f64;
        Some(s[2][i] * (1.0 - f) + s[2][i + 1] * f)
    }

    /// ZH coefficients l = 0 … order.
    pub fn zh(&self, gi: usize) -> Option<&[f64]> {
        self.slice(gi).map(|s| s[3].as_slice())
    }

    /// Worst relative error of `phase_lerp` against the double-double reference at off-grid probes.
    pub fn phase_lookup_error(&self, gi: usize, probes: usize) -> Option<f64> {
        let g = *self.g.get(gi)?;
        let s = self.slice(gi)?;
        Some(
            probe_mus(probes)
                .into_iter()
                .map(|m| rel(lerp_on(&self.mu, &s[0], m), hg_hp::phase_ref(m, g)))
                .fold(0.0, f64::max),
        )
    }

    /// The error estimates written to the sidecar; the first is the headline.
    pub fn error_estimates(&self, key: &[u8; 32]) -> Vec<ErrorEstimate> {
        let mut phase_interp = 0.0f64;
        let mut phase_node = 0.0f64;
        let mut cdf_node = 0.0f64;
        let mut inv_abs = 0.0f64;
        let mut zh_abs = 0.0f64;
        let mut sampler = 0.0f64;
        let xi_last = (self.xi_bins - 1) as f64;
        for (gi, s) in &self.slices {
            let g = self.g[*gi];
            phase_interp = phase_interp.max(self.phase_lookup_error(*gi, 2048).unwrap_or(f64::INFINITY));
            for i in strided(self.mu.len(), 4096) {
                phase_node = phase_node.max(rel(s[0][i], hg_hp::phase_ref(self.mu[i], g)));
                cdf_node = cdf_node.max(rel(s[1][i], hg_hp::cdf_per_azimuth_ref(self.mu[i], g)));
            }
            for j in strided(self.xi_bins, 4096) {
                inv_abs = inv_abs.max((s[2][j] - hg_hp::sample_mu_ref(j as f64 / xi_last, g)).abs());
            }
            // ZH coefficients l = 0..=zh_order (just l = 0 at zh_order 0): probe the ones stored.
            let order = s[4].len().saturating_sub(1);
            for l in [0, 1, 2, order / 2, order].into_iter().filter(|&l| l <= order) {
                let reference = hg_hp::legendre_moment_quadrature(l as u32, g);
                zh_abs = zh_abs.max((s[4][l] - reference).abs());
            }
            // The stored inverse CDF used as a sampler must reproduce the mean cosine g = ∫ μ f dω.
            let stream = StreamKey::from_content_key(key, *gi as u64);
            let mean = (0..SAMPLER_CHECK_SAMPLES)
                .map(|k| self.sample_mu_lerp(*gi, stream.uniform(k, 0)).unwrap_or(f64::NAN))
                .sum::<f64>()
                / SAMPLER_CHECK_SAMPLES as f64;
            sampler = sampler.max((mean - g).abs());
        }
        let e = |name: &str, value: f64, how: &str| ErrorEstimate { name: name.into(), value, how: how.into() };
        vec![
            e(
                "phase_lookup_max_rel",
                phase_interp,
                "max relative error of linearly interpolated phase at 4096 off-grid mu probes vs double-double closed form",
            ),
            e(
                "phase_node_max_rel",
                phase_node,
                "max relative error of stored phase nodes vs double-double closed form (includes element rounding)",
            ),
            e("cdf_node_max_rel", cdf_node, "max relative error of stored F_hg nodes vs double-double closed form"),
            e(
                "inv_cdf_node_max_abs",
                inv_abs,
                "max absolute error in mu of stored inverse-CDF nodes vs double-double closed form",
            ),
            e(
                "legendre_max_abs",
                zh_abs,
                "max absolute error of Legendre moments (l = 0, 1, 2, L/2, L) vs numerical quadrature",
            ),
            e(
                "sampler_mean_cosine_abs",
                sampler,
                "|E[mu] - g| sampling the stored inverse CDF with 65536 counter-based random numbers (MC noise ~ 0.002 for g = 0)",
            ),
        ]
    }
}

fn rel(a: f64, reference: f64) -> f64 {
    if a == reference { 0.0 } else { (a - reference).abs() / reference.abs().max(f64::MIN_POSITIVE) }
}

/// Up to `max` indexes spread over 0..n, always including the first and last.
fn strided(n: usize, max: usize) -> impl Iterator<Item = usize> {
    let step = n.div_ceil(max).max(1);
    (0..n).step_by(step).chain(std::iter::once(n - 1))
}

/// Linear interpolation of `ys` on a sorted axis `xs` at x (clamped to the axis range); NaN when
/// `xs` is empty or `ys` is shorter than `xs`.
pub fn lerp_on(xs: &[f64], ys: &[f64], x: f64) -> f64 {
    let n = xs.len();
    if n == 0 || ys.len() < n {
        return f64::NAN; // documented: no data to interpolate
    }
    if n == 1 {
        return ys[0];
    }
    let x = x.clamp(xs[0], xs[n - 1]);
    let i = xs.partition_point(|&v| v <= x).clamp(1, n - 1) - 1;
    let (x0, x1) = (xs[i], xs[i + 1]);
    let t = if x1 > x0 { (x - x0) / (x1 - x0) } else { 0.0 };
    ys[i] * (1.0 - t) + ys[i + 1] * t
}
