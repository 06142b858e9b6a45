//! `PopPreset`: the precomputed, tunable part of real-time Principal-Ordinates Propagation
//! (elek2014).
//!
//! Input: a validated [`PopPreset`] definition (ordinate count, propagation grid resolutions,
//! iteration limits and thresholds, prefiltering exponent, importance settings, flow-table resolution).
//! Output: four arrays (the scalar settings stay in the stored definition, see [`PopPresetTable::def`]):
//! - `ordinates[n, xyz]` — the N principal directions d_n (elek2014 Sec. 5), unit vectors from the
//!   spherical Fibonacci set `z_n = 1 − (2n + 1)/N`, `φ_n = 2π·frac(n/Φ²)`, Φ the golden ratio;
//! - `ordinate_solid_angle[n]` — the solid angle Ω_n of each ordinate's Voronoi cell in sr, Σ = 4π;
//! - `ordinate_mean_cosine[n]` — the prefiltered initial anisotropy of Sec. 5.1 as written there,
//!   `a_n = ∫_{Ω_n} d_n·ω dω / |Ω_n|` (mean cosine between d_n and the directions of its cell);
//! - `flow[a, side]` — for the lobe anisotropy `a` uniform in [−1, 1], the fractions
//!   `[front, side, back]` of an HG lobe reaching the cell in front, EACH of the four side cells and
//!   the cell behind (Sec. 4.2, Eqs. 2–3), from [`crate::physics::hg::pop_partition`].
//!
//! The settings cover the grid initialisation and propagation of Sec. 4.1–4.2, the prefiltering
//! exponent β of Sec. 5.1 (`a_n = (1 − w_n/N)^β` when ordinates come from importance-sampling an
//! environment map), the importance propagation of Sec. 5.2, the radial grids of point lights
//! (Sec. 6) and the switch to isotropic residuum propagation of Sec. 5.4 (Eqs. 9–10,
//! [`switch_iteration_raw`]). Cell integrals use a deterministic quadrature
//! ([`ordinates::cell_quadrature`]) and are judged against a counter-based Monte-Carlo estimate; the
//! flow table is judged against the double-double cumulative of [`crate::reference::hg_hp`].

pub mod ordinates;
mod table;
#[cfg(test)]
mod tests;

pub use table::{ARRAYS, MEAN_COSINE_CHECK_SAMPLES, PopPresetTable, flow_reference, lerp_flow};

use super::phase_hg::Element;
use super::{CheckError, FieldIssue, GenStats, GenerateError, Generated, Progress, to_element};
use crate::container::{ArrayDesc, Axis};
use crate::physics::hg;

/// Version of the array layout below.
pub const KIND_SCHEMA_VERSION: u32 = 1;
/// Version of the numerics; bump when values change so caches rebuild.
pub const GENERATOR_VERSION: &str = "pop_preset/1";

/// Most principal ordinates.
pub const MAX_ORDINATES: u32 = 4096;
/// Most bins on the anisotropy axis of the flow table.
pub const MAX_A_BINS: u32 = 65536;

crate::declare_params! {
    /// Principal-Ordinates Propagation preset (elek2014): principal ordinates with their cell solid
    /// angles and prefiltered anisotropies, the flow-partition table over lobe anisotropy, and the
    /// propagation settings (grids, iterations, thresholds) a real-time POP solver reads.
    raw PopPresetRaw => resolved PopPreset, kind "PopPreset" {
        /// Number N of principal ordinates (propagation directions) for environment lighting
        /// (elek2014 Sec. 5; the paper uses 64 or 125).
        ordinates: u32 = 64, unit = "directions", range = "1 to 4096";
        /// Rectilinear propagation grid resolution (x, y, z); a size of 1 along an axis is allowed
        /// (a slab or a column).
        grid: [u32; 3] = [20, 20, 20], unit = "cells per axis", range = "each 1 to 256";
        /// Point-light radial grid: octahedral angular resolution n (n x n directions) and number of
        /// radial shells (elek2014 Sec. 6).
        radial_grid: [u32; 2] = [16, 16], unit = "(directions per side, shells)", range = "n: 2 to 256, shells: 1 to 256";
        /// Anisotropic propagation iterations M per grid (elek2014 Sec. 4.2).
        iterations: u32 = 15, unit = "iterations", range = "1 to 10000";
        /// Switch to isotropic residuum propagation after m' iterations (elek2014 Sec. 5.4, Eq. 10).
        residuum: bool = true, unit = "", range = "true | false";
        /// Most isotropic residuum iterations after the switch.
        residuum_iterations: u32 = 200, unit = "iterations", range = "0 to 100000";
        /// Stop when an iteration's residual energy falls below eps_l times the initial energy
        /// (elek2014 Sec. 5.4, ε_L).
        eps_l: f64 = 1e-3, unit = "fraction of the initial energy", range = "0 < eps_l < 1";
        /// Anisotropy threshold ε_a below which radiance counts as isotropic (elek2014 Eqs. 9-10).
        eps_a: f64 = 0.1, unit = "dimensionless (mean cosine)", range = "0 < eps_a < 1";
        /// Prefiltering exponent β of elek2014 Sec. 5.1: an importance-sampled ordinate of importance
        /// w_n starts with anisotropy a_n = (1 - w_n/N)^β.
        beta: f64 = 1.0, unit = "dimensionless", range = "0 < beta <= 1000";
        /// Importance propagation from the camera before sampling the environment map (elek2014 Sec. 5.2).
        importance: bool = true, unit = "", range = "true | false";
        /// Resolution of the camera-aligned importance propagation grid (per axis).
        importance_grid: u32 = 16, unit = "cells per axis", range = "1 to 256";
        /// Resolution (width, height) of the directional importance map aligned with the environment map.
        importance_map: [u32; 2] = [32, 16], unit = "texels", range = "each 1 to 4096";
        /// Samples on the anisotropy axis a in [-1, 1] of the flow table.
        a_bins: u32 = 256, unit = "samples", range = "2 to 65536";
        /// Stored element type.
        element: Element = Element::F32, unit = "", range = "F32 | F64";
        /// zstd compression level.
        zstd_level: i32 = 9, unit = "", range = "1 to 19";
    }
}

fn check_u32(issues: &mut Vec<FieldIssue>, field: &'static str, what: &str, v: u32, lo: u32, hi: u32, unit: &str) {
    if !(lo..=hi).contains(&v) {
        issues.push(FieldIssue {
            field,
            message: format!("{field}{what} = {v} is out of range"),
            help: format!("{field}{what} must be between {lo} and {hi} {unit}"),
        });
    }
}

fn check_open_unit(issues: &mut Vec<FieldIssue>, field: &'static str, v: f64, example: &str) {
    if !(v > 0.0 && v < 1.0) {
        issues.push(FieldIssue {
            field,
            message: format!("{field} = {v} is outside (0, 1)"),
            help: format!("{field} must be strictly between 0 and 1, e.g. {field}: {example}"),
        });
    }
}

impl PopPreset {
    /// Range checks of every field.
    pub fn validate(&self) -> Vec<FieldIssue> {
        let mut issues = Vec::new();
        let i = &mut issues;
        check_u32(i, "ordinates", "", self.ordinates, 1, MAX_ORDINATES, "directions (64 or 125 are typical)");
        for (axis, v) in ["[0] (x)", "[1] (y)", "[2] (z)"].iter().zip(self.grid) {
            check_u32(i, "grid", axis, v, 1, 256, "cells");
        }
        check_u32(i, "radial_grid", "[0] (angular n)", self.radial_grid[0], 2, 256, "directions per side");
        check_u32(i, "radial_grid", "[1] (shells)", self.radial_grid[1], 1, 256, "shells");
        check_u32(i, "iterations", "", self.iterations, 1, 10_000, "iterations");
        check_u32(i, "residuum_iterations", "", self.residuum_iterations, 0, 100_000, "iterations");
        check_open_unit(i, "eps_l", self.eps_l, "1e-3");
        check_open_unit(i, "eps_a", self.eps_a, "0.1 (elek2014: around 0.1 or higher)");
        if !(self.beta > 0.0 && self.beta <= 1000.0) {
            i.push(FieldIssue {
                field: "beta",
                message: format!("beta = {} is outside (0, 1000]", self.beta),
                help: "beta must be > 0 and at most 1000 (1.0 maps importance linearly to anisotropy)".into(),
            });
        }
        check_u32(i, "importance_grid", "", self.importance_grid, 1, 256, "cells");
        check_u32(i, "importance_map", "[0] (width)", self.importance_map[0], 1, 4096, "texels");
        check_u32(i, "importance_map", "[1] (height)", self.importance_map[1], 1, 4096, "texels");
        check_u32(i, "a_bins", "", self.a_bins, 2, MAX_A_BINS, "samples (both ends a = -1 and a = 1 are stored)");
        if !(1..=19).contains(&self.zstd_level) {
            i.push(FieldIssue {
                field: "zstd_level",
                message: format!("zstd_level = {} is out of range", self.zstd_level),
                help: "zstd_level must be between 1 and 19 (9 is a good default)".into(),
            });
        }
        issues
    }

    /// Peak memory: f64 arrays, their stored copies and compressed output (≤ raw), plus the
    /// per-chunk quadrature accumulators (16 bytes per ordinate per chunk) and the search index.
    pub fn estimated_bytes(&self) -> u128 {
        let n = u128::from(self.ordinates);
        let raw = 5 * n + 3 * u128::from(self.a_bins);
        let chunks = u128::from(ordinates::quadrature_chunks(ordinates::quadrature_samples(self.ordinates as usize)));
        raw * (8 + 8 + 8) + chunks * n * 16 + n * 48
    }

    /// One unit per quadrature chunk, plus one for the flow table.
    pub fn work_units(&self) -> u64 {
        ordinates::quadrature_chunks(ordinates::quadrature_samples(self.ordinates as usize)) + 1
    }

    /// The anisotropy `a_j = −1 + 2j/(a_bins − 1)` of flow row `j` (exactly −1, 1 at the ends).
    pub fn a_value(&self, j: u32) -> f64 {
        -1.0 + 2.0 * f64::from(j) / f64::from(self.a_bins.max(2) - 1)
    }

    /// The flow table as generated (before conversion to the element type): row `j` is
    /// [`hg::pop_partition`] at [`Self::a_value`]`(j)`, `[front, side (each of four), back]`.
    pub fn flow_table(&self) -> Vec<[f64; 3]> {
        (0..self.a_bins).map(|j| hg::pop_partition(self.a_value(j))).collect()
    }

    fn descs(&self) -> Vec<ArrayDesc> {
        let n = u64::from(self.ordinates);
        let ord = Axis::linear("n", "ordinate index", 0.0, (n - 1) as f64, n);
        let xyz = Axis::linear("xyz", "component (x, y, z)", 0.0, 2.0, 3);
        let a = Axis::linear("a", "mean cosine of the lobe", -1.0, 1.0, u64::from(self.a_bins));
        let side = Axis::linear("side", "front, each side, back", 0.0, 2.0, 3);
        let d = |name: &str, description: &str, unit: &str, axes: Vec<Axis>| ArrayDesc {
            name: name.into(),
            description: description.into(),
            unit: unit.into(),
            element: self.element.into(),
            axes,
            quantization: None,
        };
        vec![
            d(
                "ordinates",
                "principal directions d_n: spherical Fibonacci z = 1 - (2n+1)/N, phi = 2 pi frac(n / golden ratio^2)",
                "unit vector",
                vec![ord.clone(), xyz],
            ),
            d(
                "ordinate_solid_angle",
                "solid angle of each ordinate's Voronoi cell (sum 4 pi)",
                "sr",
                vec![ord.clone()],
            ),
            d(
                "ordinate_mean_cosine",
                "prefiltered initial anisotropy a_n = mean of d_n . w over the ordinate's cell (elek2014 Sec. 5.1)",
                "",
                vec![ord],
            ),
            d(
                "flow",
                "fraction of an HG lobe of mean cosine a reaching the front cell, EACH of the 4 side cells, the back cell (elek2014 Eqs. 2-3)",
                "",
                vec![a, side],
            ),
        ]
    }

    /// Runs the generator (quadrature parallel over fixed chunks merged in order: thread-count
    /// independent).
    pub fn generate(&self, _key: &[u8; 32], progress: Progress<'_>) -> Result<Generated, GenerateError> {
        let descs = self.descs();
        let dirs = ordinates::fibonacci_directions(self.ordinates as usize);
        let samples = ordinates::quadrature_samples(dirs.len());
        let cells = ordinates::cell_quadrature(&dirs, samples, progress);
        let flow = self.flow_table();
        progress(1);
        let help = "this is a bug in the PopPreset generator; please report the pipeline";
        let flat = [
            dirs.iter().flatten().copied().collect(),
            cells.solid_angle,
            cells.mean_cosine,
            flow.iter().flatten().copied().collect::<Vec<f64>>(),
        ];
        let values = descs.iter().zip(flat).map(|(d, v)| to_element(d, v, help)).collect::<Result<Vec<_>, _>>()?;
        let stats = GenStats { nonfinite_discarded: 0, samples: 0, errors: Vec::new() };
        Ok(Generated { arrays: descs, values, stats })
    }

    /// Error estimates of a generated table against the independent references (sidecar, report).
    pub fn estimate_errors(&self, generated: &Generated, key: &[u8; 32]) -> Result<GenStats, CheckError> {
        let table =
            PopPresetTable::from_arrays(self, &generated.arrays, &generated.values).map_err(CheckError::Layout)?;
        Ok(GenStats {
            nonfinite_discarded: generated.stats.nonfinite_discarded,
            samples: MEAN_COSINE_CHECK_SAMPLES,
            errors: table.error_estimates(key),
        })
    }

    /// Quality budgets for `voltab report`: flow-table resolution a_bins = 8, 32, 128, 512.
    pub fn report_ladder(&self) -> Vec<(String, PopPreset)> {
        [8, 32, 128, 512]
            .into_iter()
            .map(|n| (format!("a_bins={n}"), PopPreset { a_bins: n, ..self.clone() }))
            .collect()
    }

    /// Error of the flow table's interpolation (one curve), for the report.
    pub fn report_measure(&self, generated: &Generated) -> Result<Vec<(String, f64)>, CheckError> {
        let table =
            PopPresetTable::from_arrays(self, &generated.arrays, &generated.values).map_err(CheckError::Layout)?;
        Ok(vec![("flow interpolation, worst over a".to_owned(), table.flow_interp_error())])
    }

    /// Eq. 10 for this preset (see [`switch_iteration_raw`]): the iteration after which propagation
    /// switches to isotropic residuum propagation, capped at [`Self::iterations`]. A return value
    /// equal to `iterations` means the anisotropic phase runs to its cap without switching early;
    /// with `residuum: false` it is always `iterations`.
    pub fn switch_iteration(&self, a_max: f64, g: f64, sigma_s_mean: f64, dx: f64, grid_len: usize) -> usize {
        let cap = self.iterations as usize;
        if !self.residuum {
            return cap;
        }
        switch_iteration_raw(self.eps_a, a_max, g, sigma_s_mean, dx, grid_len).map_or(cap, |m| m.min(cap))
    }
}

/// elek2014 Eq. 10: the iteration m' after which the anisotropy `a_max · |g|^(σ̄_s m Δx)` of the
/// most anisotropic radiance (Eq. 9, HG self-convolution) has fallen below `eps_a`:
/// `m' = ⌈(ln ε_a − ln a_max)/(ln |g|) · 1/(σ̄_s Δx)⌉`, and at least `grid_len` (the grid resolution
/// along the propagation direction, so light from the first row of cells reaches the whole volume —
/// the paper's advice).
///
/// `a_max` and `g` enter by magnitude. Extremes: `|a_max| ≤ eps_a` (already isotropic) or `g = 0`
/// (any scattering removes all anisotropy) give `Some(grid_len)`; `|g| ≥ 1`, `σ̄_s Δx ≤ 0` (no
/// scattering per step), a NaN input, or an m' beyond 2^53 give `None`: the radiance never becomes
/// isotropic, so propagation never switches.
pub fn switch_iteration_raw(
    eps_a: f64,
    a_max: f64,
    g: f64,
    sigma_s_mean: f64,
    dx: f64,
    grid_len: usize,
) -> Option<usize> {
    let (a, g, step) = (a_max.abs(), g.abs(), sigma_s_mean * dx);
    if eps_a.is_nan() || a.is_nan() || g.is_nan() || step.is_nan() {
        return None;
    }
    if a <= eps_a {
        return Some(grid_len);
    }
    if g >= 1.0 || step <= 0.0 || eps_a <= 0.0 {
        return None;
    }
    if g == 0.0 {
        return Some(grid_len);
    }
    // Both logarithms are negative-or-ordered: ln ε_a − ln a < 0 and ln g < 0, so m' > 0.
    let m = (eps_a.ln() - a.ln()) / g.ln() / step;
    if !(m.is_finite() && m < 9.007_199_254_740_992e15) {
        return None;
    }
    Some((m.ceil() as usize).max(grid_len))
}

/// Anisotropies of the stability rows for the flow table.
pub const EXTREME_A: [f64; 6] = [-1.0, -0.999_999, 0.0, 1e-12, 0.999_999, 1.0];

/// Rows of the stability matrix for PopPreset.
pub fn stability_rows() -> Vec<crate::stability::Row> {
    use crate::stability::{Expect, Row};
    use std::f64::consts::PI;
    let row = |formula, input: String, value, expect| Row { kind: "PopPreset", formula, input, value, expect };
    let mut v = Vec::new();
    for a in EXTREME_A {
        let [f, s, b] = hg::pop_partition(a);
        v.push(row("flow front", format!("a={a}"), f, Expect::InRange(0.0, 1.0)));
        v.push(row("flow side (each)", format!("a={a}"), s, Expect::InRange(0.0, 0.25)));
        v.push(row("flow back", format!("a={a}"), b, Expect::InRange(0.0, 1.0)));
        v.push(row("flow front+4side+back", format!("a={a}"), f + 4.0 * s + b, Expect::Close { to: 1.0, rel: 1e-14 }));
    }
    for n in [1usize, 2, 3] {
        let dirs = ordinates::fibonacci_directions(n);
        let cells = ordinates::cell_quadrature(&dirs, ordinates::quadrature_samples(n), &|_| {});
        let covering = table::covering_radius_deg(&dirs);
        v.push(row("ordinate covering radius [deg]", format!("N={n}"), covering, Expect::InRange(0.0, 180.0)));
        v.push(row(
            "sum of cell solid angles",
            format!("N={n}"),
            cells.solid_angle.iter().sum(),
            Expect::Close { to: 4.0 * PI, rel: 1e-12 },
        ));
        let worst = cells.mean_cosine.iter().fold(0.0f64, |m, a| if a.is_finite() { m.max(a.abs()) } else { f64::NAN });
        v.push(row("max |cell mean cosine|", format!("N={n}"), worst, Expect::InRange(0.0, 1.0)));
    }
    let slab = PopPreset { grid: [1, 256, 1], ..PopPreset::default() };
    v.push(row("validate: issues", "grid=[1, 256, 1]".into(), slab.validate().len() as f64, Expect::InRange(0.0, 0.0)));
    let p = PopPreset { iterations: 100, ..PopPreset::default() };
    let (lo, hi) = (20.0, 100.0);
    let cases: [(&str, f64, f64, f64); 5] = [
        ("a=1, g=0, sigma dx=0.25", 1.0, 0.0, 0.25),
        ("a=0.05 <= eps_a, g=0.9", 0.05, 0.9, 0.25),
        ("a=1, g=0.9, sigma dx=0", 1.0, 0.9, 0.0),
        ("a=1, g=1-1e-16, sigma dx=0.25", 1.0, 1.0 - 1e-16, 0.25),
        ("a=1, g=0.9, sigma dx=1e-300", 1.0, 0.9, 1e-300),
    ];
    for (input, a, g, step) in cases {
        let m = p.switch_iteration(a, g, step, 1.0, 20) as f64;
        v.push(row("switch_iteration (grid 20, M 100)", input.into(), m, Expect::InRange(lo, hi)));
    }
    v
}

impl super::TableKind for PopPreset {
    fn kind(&self) -> &'static str {
        PopPresetRaw::KIND
    }
    fn kind_schema_version(&self) -> u32 {
        KIND_SCHEMA_VERSION
    }
    fn generator_version(&self) -> &'static str {
        GENERATOR_VERSION
    }
    fn validate(&self) -> Vec<FieldIssue> {
        PopPreset::validate(self)
    }
    fn estimated_bytes(&self) -> u128 {
        PopPreset::estimated_bytes(self)
    }
    fn work_units(&self) -> u64 {
        PopPreset::work_units(self)
    }
    fn work_unit_name(&self) -> &'static str {
        "quadrature chunks"
    }
    fn generate(
        &self,
        key: &[u8; 32],
        progress: super::Progress<'_>,
    ) -> Result<super::Generated, super::GenerateError> {
        PopPreset::generate(self, key, progress)
    }
    fn estimate_errors(&self, generated: &super::Generated, key: &[u8; 32]) -> Result<super::GenStats, CheckError> {
        PopPreset::estimate_errors(self, generated, key)
    }
    fn report_ladder(&self) -> Vec<(String, super::TableDef)> {
        PopPreset::report_ladder(self).into_iter().map(|(l, d)| (l, super::TableDef::PopPreset(d))).collect()
    }
    fn report_error_name(&self) -> &'static str {
        "max absolute error of the interpolated flow fractions [front, side, back] vs the double-double HG cumulative"
    }
    fn report_measure(&self, generated: &super::Generated) -> Result<Vec<(String, f64)>, CheckError> {
        PopPreset::report_measure(self, generated)
    }
}
