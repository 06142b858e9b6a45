//! `PhaseHg`: Henyey–Greenstein phase-function tables.
//!
//! Input: a validated [`PhaseHg`] definition (list or grid of g, μ and ξ resolutions, ZH order).
//! Output: five arrays, each chunked per g slice so a consumer loads only the g it needs:
//! - `phase[g, μ]` — f(μ, g) in 1/sr (normalised over the sphere);
//! - `cdf_per_azimuth[g, μ]` — F_hg(μ, g) of elek2014 (Eq. 2 context, READING-NOTES.md), in 1/rad,
//!   the per-unit-azimuth cumulative that POP's flux partition (elek2014 Eq. 2–3) integrates;
//! - `inv_cdf[g, ξ]` — μ(ξ, g), the inverse of the CDF 2π·F, for importance sampling;
//! - `zh[g, l]` — zonal-harmonic coefficients sqrt((2l+1)/4π)·g^l (dubouchet2019 Eq. 13 convention);
//! - `legendre[g, l]` — Legendre moments ∫ f P_l dω = g^l.
//!
//! Values are evaluated in f64 with the cancellation-free forms of [`crate::physics::hg`] and judged
//! against the double-double closed forms and quadrature of [`crate::reference::hg_hp`].

use rayon::prelude::*;
use serde::{Deserialize, Serialize};

mod table;

pub use table::{ARRAYS, PhaseHgReadError, PhaseHgTable, SAMPLER_CHECK_SAMPLES, lerp_on};

use super::{CheckError, FieldIssue, GenStats, GenerateError, Generated, Progress, to_element};
use crate::container::{ArrayDesc, ArrayValues, Axis, ElementType, Quantization};
use crate::physics::hg;

/// Version of the array layout below.
pub const KIND_SCHEMA_VERSION: u32 = 1;
/// Version of the numerics; bump when values change so caches rebuild.
pub const GENERATOR_VERSION: &str = "phase_hg/1";

/// Most g values one table may hold.
pub const MAX_G: usize = 4096;
/// Most bins on the μ or ξ axis.
pub const MAX_BINS: u32 = 1 << 24;
/// Highest ZH order.
pub const MAX_ZH_ORDER: u32 = 4096;

/// Which g values to tabulate.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(untagged, deny_unknown_fields)]
pub enum GValues {
    /// Explicit list, strictly increasing: `[-0.5, 0.0, 0.5]`.
    List(Vec<f64>),
    /// `count` evenly spaced values from `min` to `max` inclusive, each rounded to 15 significant
    /// digits: `(min: -0.9, max: 0.9, count: 19)`.
    Grid {
        /// First value.
        min: f64,
        /// Last value.
        max: f64,
        /// Number of values (1 means just `min`, which must then equal `max`).
        count: u32,
    },
}

impl GValues {
    /// The values in table order.
    pub fn values(&self) -> Vec<f64> {
        match self {
            GValues::List(v) => v.clone(),
            GValues::Grid { min, max, count } => match *count {
                0 => Vec::new(),
                1 => vec![*min],
                n => (0..n)
                    .map(|i| {
                        let t = f64::from(i) / f64::from(n - 1);
                        round_15_digits(min * (1.0 - t) + max * t)
                    })
                    .collect(),
            },
        }
    }
}

/// The double nearest to `x` written with 15 significant digits: grid points land on the decimal
/// values a person expects (−0.9 … 0.9 in 19 steps gives exactly −0.8, not −0.7999999999999999).
fn round_15_digits(x: f64) -> f64 {
    format!("{x:.14e}").parse().unwrap_or(x)
}

/// Spacing of the μ = cos θ axis.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, schemars::JsonSchema)]
pub enum MuSpacing {
    /// Uniform in μ from −1 to 1.
    Linear,
    /// Uniform in θ from π to 0 (μ = −cos(πi/(n−1))): cells shrink quadratically towards μ = ±1,
    /// where strongly forward or backward lobes (|g| → 1) live.
    UniformAngle,
}

/// Stored element type.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, schemars::JsonSchema)]
pub enum Element {
    /// 32-bit IEEE float (what GPUs sample).
    F32,
    /// 64-bit IEEE float.
    F64,
}

impl From<Element> for ElementType {
    fn from(e: Element) -> Self {
        match e {
            Element::F32 => ElementType::F32,
            Element::F64 => ElementType::F64,
        }
    }
}

crate::declare_params! {
    /// Henyey–Greenstein phase tables: phase value, per-azimuth cumulative, inverse CDF, ZH and
    /// Legendre coefficients, one chunk per g.
    raw PhaseHgRaw => resolved PhaseHg, kind "PhaseHg" {
        /// HG mean cosines: a strictly increasing list `[-0.5, 0.0, 0.5]` or a grid
        /// `(min: -0.9, max: 0.9, count: 19)`.
        g: GValues = GValues::List(vec![-0.9, -0.5, 0.0, 0.5, 0.9]), unit = "dimensionless (mean cosine)", range = "each finite with |g| < 1; 1 to 4096 values";
        /// Number of samples on the μ = cos θ axis (phase and cumulative arrays).
        mu_bins: u32 = 1024, unit = "samples", range = "2 to 16777216";
        /// Spacing of the μ axis: `Linear` or `UniformAngle` (denser near μ = ±1).
        mu_spacing: MuSpacing = MuSpacing::Linear, unit = "", range = "Linear | UniformAngle";
        /// Number of samples on the ξ ∈ [0, 1] axis of the inverse CDF.
        xi_bins: u32 = 1024, unit = "samples", range = "2 to 16777216";
        /// Highest zonal-harmonic / Legendre order l stored (l = 0 … zh_order).
        zh_order: u32 = 32, unit = "order", range = "0 to 4096";
        /// Stored element type.
        element: Element = Element::F32, unit = "", range = "F32 | F64";
        /// Lossy storage: keep this many mantissa bits (relative error ≤ 2^-(bits+1), stated in the
        /// header); 0 stores values exactly.
        mantissa_bits: u8 = 0, unit = "bits", range = "0 (lossless), or 1 to 23 for F32, 1 to 52 for F64";
        /// zstd compression level.
        zstd_level: i32 = 9, unit = "", range = "1 to 19";
    }
}

fn check_bins(issues: &mut Vec<FieldIssue>, field: &'static str, v: u32) {
    if !(2..=MAX_BINS).contains(&v) {
        issues.push(FieldIssue {
            field,
            message: format!("{field} = {v} is out of range"),
            help: format!("{field} must be between 2 and {MAX_BINS} samples"),
        });
    }
}

impl PhaseHg {
    /// Range checks of every field.
    pub fn validate(&self) -> Vec<FieldIssue> {
        let mut issues = Vec::new();
        let g_help = "each g must be finite with -1 < g < 1 (HG is singular at |g| = 1); e.g. g: [-0.999, 0.0, 0.999]";
        match &self.g {
            GValues::List(v) => {
                if v.is_empty() || v.len() > MAX_G {
                    issues.push(FieldIssue {
                        field: "g",
                        message: format!("g has {} values", v.len()),
                        help: format!("give between 1 and {MAX_G} g values"),
                    });
                }
                for w in v.windows(2) {
                    if w[0] >= w[1] {
                        issues.push(FieldIssue {
                            field: "g",
                            message: format!(
                                "g values must be strictly increasing, but {} is followed by {}",
                                w[0], w[1]
                            ),
                            help: "sort the list and remove duplicates".into(),
                        });
                        break;
                    }
                }
            }
            GValues::Grid { min, max, count } => {
                if *count == 0 || *count as usize > MAX_G {
                    issues.push(FieldIssue {
                        field: "g",
                        message: format!("g grid count = {count}"),
                        help: format!("count must be between 1 and {MAX_G}"),
                    });
                }
                if min.partial_cmp(max) == Some(std::cmp::Ordering::Greater)
                    || min.is_nan()
                    || max.is_nan()
                    || (*count == 1 && min != max)
                    || (*count > 1 && min == max)
                {
                    issues.push(FieldIssue {
                        field: "g",
                        message: format!("g grid (min: {min}, max: {max}, count: {count}) is empty or inconsistent"),
                        help: "need min < max for count > 1, and min == max for count == 1".into(),
                    });
                }
            }
        }
        // Only expand a grid whose size passed the check above (a count of 4e9 must not allocate).
        let expandable = match &self.g {
            GValues::List(_) => true,
            GValues::Grid { count, .. } => *count as usize <= MAX_G,
        };
        let values = if expandable { self.g.values() } else { Vec::new() };
        if let Some(bad) = values.into_iter().find(|g| hg::validate_g(*g).is_err()) {
            issues.push(FieldIssue {
                field: "g",
                message: format!("g = {bad} is outside (-1, 1)"),
                help: g_help.into(),
            });
        }
        check_bins(&mut issues, "mu_bins", self.mu_bins);
        check_bins(&mut issues, "xi_bins", self.xi_bins);
        if self.zh_order > MAX_ZH_ORDER {
            issues.push(FieldIssue {
                field: "zh_order",
                message: format!("zh_order = {} is out of range", self.zh_order),
                help: format!("zh_order must be between 0 and {MAX_ZH_ORDER}"),
            });
        }
        let max_bits = match self.element {
            Element::F32 => 23,
            Element::F64 => 52,
        };
        if self.mantissa_bits > max_bits {
            issues.push(FieldIssue {
                field: "mantissa_bits",
                message: format!(
                    "mantissa_bits = {} exceeds the {max_bits} bits of {:?}",
                    self.mantissa_bits, self.element
                ),
                help: format!("use 0 (lossless) or 1 to {max_bits}"),
            });
        }
        if !(1..=19).contains(&self.zstd_level) {
            issues.push(FieldIssue {
                field: "zstd_level",
                message: format!("zstd_level = {} is out of range", self.zstd_level),
                help: "zstd_level must be between 1 and 19 (9 is a good default; 19 is ~100x slower for ~1 % smaller files)".into(),
            });
        }
        issues
    }

    fn n_g(&self) -> u128 {
        match &self.g {
            GValues::List(v) => v.len() as u128,
            GValues::Grid { count, .. } => u128::from(*count),
        }
    }

    /// Peak memory: f64 working arrays plus stored copies plus compressed output (bounded by raw).
    pub fn estimated_bytes(&self) -> u128 {
        let per_g = 2 * u128::from(self.mu_bins) + u128::from(self.xi_bins) + 2 * (u128::from(self.zh_order) + 1);
        // f64 working set + element copy + compressed chunks (≤ raw) + μ/ξ axis values.
        self.n_g() * per_g * (8 + 8 + 8) + 8 * u128::from(self.mu_bins)
    }

    /// One unit per g slice.
    pub fn work_units(&self) -> u64 {
        self.n_g() as u64
    }

    /// The μ axis.
    pub fn mu_axis(&self) -> Axis {
        let n = self.mu_bins;
        match self.mu_spacing {
            MuSpacing::Linear => Axis::linear("mu", "cos(theta)", -1.0, 1.0, u64::from(n)),
            MuSpacing::UniformAngle => {
                let last = f64::from(n - 1);
                let v = (0..n).map(|i| -(std::f64::consts::PI * f64::from(i) / last).cos()).collect();
                Axis::explicit("mu", "cos(theta)", v)
            }
        }
    }

    fn quantization(&self) -> Option<Quantization> {
        (self.mantissa_bits > 0).then(|| Quantization {
            mantissa_bits: self.mantissa_bits,
            max_rel_error: 2f64.powi(-(i32::from(self.mantissa_bits) + 1)),
        })
    }

    fn descs(&self) -> Vec<ArrayDesc> {
        let g_axis = Axis::explicit("g", "", self.g.values());
        let mu = self.mu_axis();
        let xi = Axis::linear("xi", "", 0.0, 1.0, u64::from(self.xi_bins));
        let l = Axis::linear("l", "order", 0.0, f64::from(self.zh_order), u64::from(self.zh_order) + 1);
        let d = |name: &str, description: &str, unit: &str, axis: &Axis| ArrayDesc {
            name: name.into(),
            description: description.into(),
            unit: unit.into(),
            element: self.element.into(),
            axes: vec![g_axis.clone(), axis.clone()],
            quantization: self.quantization(),
        };
        vec![
            d("phase", "HG phase function f(mu, g), normalised over the sphere", "1/sr", &mu),
            d("cdf_per_azimuth", "F_hg(mu, g) = integral of f from -1 to mu per unit azimuth (elek2014)", "1/rad", &mu),
            d("inv_cdf", "mu(xi, g): inverse of the CDF 2*pi*F_hg, for importance sampling", "cos(theta)", &xi),
            d("zh", "zonal-harmonic coefficients sqrt((2l+1)/(4 pi)) g^l", "1/sr^0.5", &l),
            d("legendre", "Legendre moments g^l of f", "", &l),
        ]
    }

    /// Evaluates every array for one g.
    fn slice(&self, g: f64, mu: &[f64]) -> [Vec<f64>; 5] {
        let xi_last = f64::from(self.xi_bins - 1);
        [
            mu.iter().map(|&m| hg::phase(m, g)).collect(),
            mu.iter().map(|&m| hg::cdf_per_azimuth(m, g)).collect(),
            (0..self.xi_bins).map(|j| hg::sample_mu(f64::from(j) / xi_last, g)).collect(),
            (0..=self.zh_order).map(|l| hg::zh_coefficient(l, g)).collect(),
            (0..=self.zh_order).map(|l| hg::legendre_moment(l, g)).collect(),
        ]
    }

    /// Runs the generator (parallel over g, merged in g order: thread-count independent).
    pub fn generate(&self, _key: &[u8; 32], progress: Progress<'_>) -> Result<Generated, GenerateError> {
        let descs = self.descs();
        let gs = self.g.values();
        let mu = descs[0].axes[1].values_vec();
        let slices: Vec<[Vec<f64>; 5]> = gs
            .par_iter()
            .map(|&g| {
                let s = self.slice(g, &mu);
                progress(1);
                s
            })
            .collect();
        let help = "this is a bug in the PhaseHg generator; please report the pipeline";
        let mut values = Vec::with_capacity(5);
        for (a, desc) in descs.iter().enumerate() {
            let flat: Vec<f64> = slices.iter().flat_map(|s| s[a].iter().copied()).collect();
            values.push(to_element(desc, flat, help)?);
        }
        let stats = GenStats { nonfinite_discarded: 0, samples: 0, errors: Vec::new() };
        Ok(Generated { arrays: descs, values, stats })
    }
}

impl PhaseHg {
    /// Error estimates of a generated table against the independent reference (sidecar, report).
    pub fn estimate_errors(&self, generated: &Generated, key: &[u8; 32]) -> Result<GenStats, CheckError> {
        let table = PhaseHgTable::from_arrays(&generated.arrays, &generated.values).map_err(CheckError::Layout)?;
        Ok(GenStats {
            nonfinite_discarded: generated.stats.nonfinite_discarded,
            samples: SAMPLER_CHECK_SAMPLES * table.g.len() as u64,
            errors: table.error_estimates(key),
        })
    }

    /// Quality budgets for `voltab report`: μ and ξ resolution from 16 to 16384 samples.
    pub fn report_ladder(&self) -> Vec<(String, PhaseHg)> {
        (4..=14)
            .map(|k| {
                let n = 1u32 << k;
                (format!("mu_bins={n}"), PhaseHg { mu_bins: n, xi_bins: n, ..self.clone() })
            })
            .collect()
    }

    /// Error of each g slice's phase lookups (for the report's curves).
    pub fn report_measure(&self, generated: &Generated) -> Result<Vec<(String, f64)>, CheckError> {
        let table = PhaseHgTable::from_arrays(&generated.arrays, &generated.values).map_err(CheckError::Layout)?;
        let errors: Vec<f64> =
            (0..table.g.len()).map(|gi| table.phase_lookup_error(gi, 2048).unwrap_or(f64::INFINITY)).collect();
        let mut curves = vec![("worst over all g".to_owned(), errors.iter().copied().fold(0.0, f64::max))];
        // At most 7 individual g curves (evenly spread over the table) keep the plot readable.
        let n = errors.len();
        let shown: std::collections::BTreeSet<usize> =
            if n <= 7 { (0..n).collect() } else { (0..7).map(|k| k * (n - 1) / 6).collect() };
        curves.extend(shown.into_iter().map(|gi| (format!("g = {}", table.g[gi]), errors[gi])));
        Ok(curves)
    }
}

/// Extreme inputs of the HG formulas, for [`crate::stability`].
pub const EXTREME_G: [f64; 11] = [-0.999_999, -0.999, -0.5, -1e-8, -1e-300, 0.0, 1e-300, 1e-8, 0.5, 0.999, 0.999_999];

/// Rows of the stability matrix for PhaseHg.
pub fn stability_rows() -> Vec<crate::stability::Row> {
    use crate::stability::{Expect, Row};
    use std::f64::consts::PI;
    let row = |formula, input: String, value, expect| Row { kind: "PhaseHg", formula, input, value, expect };
    let mus = [-1.0, -1.0 + 1e-12, 0.0, 1.0 - 1e-12, 1.0];
    let xis = [0.0, 1e-12, 0.5, 1.0 - 1e-12, 1.0];
    let mut v = Vec::new();
    for g in EXTREME_G {
        for mu in mus {
            v.push(row("phase", format!("mu={mu}, g={g}"), hg::phase(mu, g), Expect::Positive));
            v.push(row(
                "cdf_per_azimuth",
                format!("mu={mu}, g={g}"),
                hg::cdf_per_azimuth(mu, g),
                Expect::InRange(0.0, 0.5 / PI),
            ));
        }
        v.push(row("cdf(mu=1)", format!("g={g}"), hg::cdf(1.0, g), Expect::Close { to: 1.0, rel: 1e-14 }));
        v.push(row("cdf(mu=-1)", format!("g={g}"), hg::cdf(-1.0, g), Expect::InRange(0.0, 0.0)));
        v.push(row(
            "F continuity at g->0",
            format!("mu=0.3, g={g}"),
            hg::cdf_per_azimuth(0.3, g),
            if g.abs() < 1e-6 { Expect::Close { to: 1.3 / (4.0 * PI), rel: 1e-7 } } else { Expect::Finite },
        ));
        for xi in xis {
            v.push(row("sample_mu", format!("xi={xi}, g={g}"), hg::sample_mu(xi, g), Expect::InRange(-1.0, 1.0)));
        }
        v.push(row("sample_mu(0)", format!("g={g}"), hg::sample_mu(0.0, g), Expect::Close { to: -1.0, rel: 1e-15 }));
        v.push(row("sample_mu(1)", format!("g={g}"), hg::sample_mu(1.0, g), Expect::Close { to: 1.0, rel: 1e-15 }));
        v.push(row("zh_coefficient", format!("l=4096, g={g}"), hg::zh_coefficient(4096, g), Expect::Finite));
        v.push(row(
            "legendre_moment",
            format!("l=0, g={g}"),
            hg::legendre_moment(0, g),
            Expect::Close { to: 1.0, rel: 0.0 },
        ));
    }
    // Whole generated tables at the extremes, both element types: every stored value finite.
    for element in [Element::F32, Element::F64] {
        let def =
            PhaseHg { g: GValues::List(EXTREME_G.to_vec()), mu_bins: 64, xi_bins: 64, element, ..PhaseHg::default() };
        let worst = match def.generate(&[0; 32], &|_| {}) {
            Ok(gn) => gn
                .values
                .iter()
                .flat_map(ArrayValues::to_f64)
                .fold(0.0f64, |m, x| if x.is_finite() { m.max(x.abs()) } else { f64::NAN }),
            Err(_) => f64::NAN,
        };
        v.push(row("generate: max |value|", format!("{element:?}, g = extremes"), worst, Expect::Positive));
    }
    v
}

impl super::TableKind for PhaseHg {
    fn kind(&self) -> &'static str {
        PhaseHgRaw::KIND
    }
    fn kind_schema_version(&self) -> u32 {
        KIND_SCHEMA_VERSION
    }
    fn generator_version(&self) -> &'static str {
        GENERATOR_VERSION
    }
    fn validate(&self) -> Vec<FieldIssue> {
        PhaseHg::validate(self)
    }
    fn estimated_bytes(&self) -> u128 {
        PhaseHg::estimated_bytes(self)
    }
    fn work_units(&self) -> u64 {
        PhaseHg::work_units(self)
    }
    fn work_unit_name(&self) -> &'static str {
        "g slices"
    }
    fn generate(
        &self,
        key: &[u8; 32],
        progress: super::Progress<'_>,
    ) -> Result<super::Generated, super::GenerateError> {
        PhaseHg::generate(self, key, progress)
    }
    fn estimate_errors(&self, generated: &super::Generated, key: &[u8; 32]) -> Result<super::GenStats, CheckError> {
        PhaseHg::estimate_errors(self, generated, key)
    }
    fn report_ladder(&self) -> Vec<(String, super::TableDef)> {
        PhaseHg::report_ladder(self).into_iter().map(|(l, d)| (l, super::TableDef::PhaseHg(d))).collect()
    }
    fn report_error_name(&self) -> &'static str {
        "max relative error of interpolated phase lookups vs double-double reference"
    }
    fn report_measure(&self, generated: &super::Generated) -> Result<Vec<(String, f64)>, CheckError> {
        PhaseHg::report_measure(self, generated)
    }
}
