//! `MsLobes`: the 5-D multiple-scattering lobe tables of wang2018 Sec. 3.5.4, 4.1 and 5.2 — the
//! precomputed material response the translucent-media renderer consumes.
//!
//! **Input → output.** A validated [`MsLobes`] definition (material presets and/or g and albedo nodes,
//! the `(ρ, z)` grid, lobe directions, photons, traced orders) → per g slice `i`:
//! - `total_g{i}[albedo, z, ρ, θ(, φ)]` — the radiance scattered at `P = (ρ, z)` toward `ω` per mean free
//!   path and per unit beam power by photons that had already scattered at least once,
//!   `Σ_{k≥2} α^k E_k(P, ω)` (orders beyond `max_order` from the central-limit closure), chunked per
//!   albedo so a consumer decompresses only the (α, g) slices it needs;
//! - `density_g{i}[albedo, z, ρ]` — its integral over directions (`Σ α^k ψ_k`, collisions per mfp³);
//!
//! and for all g slices `double[g, z, ρ, θ(, φ)]` — `E_2`, the exactly-two-events part without its
//! `α²` (so a renderer can swap it for its own double scattering, wang2018 Eq. 6), and
//! `inside[g, k]` — the fraction of the order-`k` collisions inside the grid (the conservation check).
//! `θ` is measured from the lobe axis `â = P/|P|` (symmetric lobe, Sec. 4.1: the value is the average
//! over the azimuth about `â`); with `lobe: Full` a second angle `φ ∈ [0, π]` about `â` from the plane
//! of the beam ([`crate::physics::lobe_transport::lobe_frame`]).
//!
//! **Canonical medium and units.** `σ_t = 1`, lengths in mean free paths, a unit-power pencil beam from
//! the origin along `+z`; values in `1/(mfp · sr)` of radiance per unit length per watt. A medium with
//! extinction `σ_t` scales positions by `σ_t` and values by `σ_t³` ([`MsLobesTable::radiance`]).
//!
//! **Generator.** [`crate::physics::lobe_transport`]: one non-absorbing random walk per g gives every
//! albedo (collision-order weights `α^k`), integer tallies (bit-identical for any thread count), the
//! lobe from the incoming-direction histogram by one phase-kernel product. **Compression.** The graded
//! grid is the adaptive part (cells `0.25×` the uniform width at the beam start, `1.75×` far away, where
//! the field is smooth); values keep `mantissa_bits` bits (below the Monte-Carlo noise), which makes
//! the noise digits compressible, then byte shuffle + zstd; empty space (zero cells) costs nothing.
//!
//! **Errors.** [`MsLobes::estimate_errors`] compares the `E_2` lobes with the deterministic quadrature
//! of [`crate::reference::beam_adjoint`] and the totals with its backward random walk, both sharing
//! no code with the generator, and checks conservation (`Σ α^k` collisions per photon).

mod errors;
mod materials;
mod slice;
mod table;
#[cfg(test)]
mod tests;

use serde::{Deserialize, Serialize};

pub use errors::{
    PROBE_ALBEDO, PROBE_THETAS, PROBES, REMAINDER_POINTS, REPORT_ADJOINT_SAMPLES, SIDECAR_ADJOINT_SAMPLES,
    cell_average, conservation, symmetry_error,
};
pub use materials::{Material, material, materials};
pub use slice::LobeSlice;
pub use table::{LobeQuery, LobeQueryError, LobeValue, LobesReadError, MediumChannel, MsLobesTable};

use super::phase_hg::Element;
use super::{CheckError, ErrorEstimate, FieldIssue, GenStats, GenerateError, Generated, Progress, to_element};
use crate::container::{ArrayDesc, Axis, Quantization};
use crate::physics::lobe_transport::{self, GradedAxis, LobeConfig, LobeShape};
use crate::physics::rng::StreamKey;

/// Version of the array layout below.
pub const KIND_SCHEMA_VERSION: u32 = 1;
/// Version of the numerics; bump when values change so caches rebuild.
pub const GENERATOR_VERSION: &str = "ms_lobes/2";

/// Most g slices (each needs its own walk).
pub const MAX_G: usize = 32;
/// Most albedo nodes (each is a tally channel of every collision).
pub const MAX_ALBEDOS: usize = 64;
/// Largest `|g|`.
pub const MAX_ABS_G: f64 = 0.99;

/// Lobe representation.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, schemars::JsonSchema)]
pub enum LobeKind {
    /// Symmetric about the axis from the beam origin to `P` (wang2018 Sec. 4.1): `θ` only.
    Symmetric,
    /// Full lobe in the local frame: `θ` and the azimuth `φ ∈ [0, π]` (`phi_bins` nodes), for offline
    /// quality and for measuring the symmetric approximation.
    Full,
}

crate::declare_params! {
    /// Multiple-scattering lobe tables (wang2018): per HG g and albedo, the radiance scattered at points
    /// around a pencil beam by photons that scattered at least once before, as lobes over directions.
    raw MsLobesRaw => resolved MsLobes, kind "MsLobes" {
        /// Material presets to cover (wang2018 Table 2: Oil, Wax, Milk, Skin, BumpySphere): their g join the
        /// g slices and their per-channel albedos join the albedo nodes, so the materials are looked up exactly.
        materials: Vec<String> = vec!["Oil".into(), "Wax".into(), "Milk".into(), "Skin".into(), "BumpySphere".into()], unit = "", range = "names from `voltab materials` (case-sensitive), each once";
        /// Further g slices besides the materials' (queries interpolate linearly between slices).
        g: Vec<f64> = Vec::new(), unit = "dimensionless (mean cosine)", range = "each |g| <= 0.99; at most 32 slices in all";
        /// Albedo nodes uniform in s = √(1 − α) from α = 0 to α = 1 (inclusive), added to the materials'
        /// albedos; 0 adds none. Queries interpolate linearly in s (the sum Σα^k is smooth in s, not in α).
        albedo_grid: u32 = 9, unit = "nodes", range = "0, or 2 to 64";
        /// Further albedo nodes.
        albedos: Vec<f64> = Vec::new(), unit = "", range = "each in [0, 1]; at most 64 nodes in all";
        /// Radial extent of the grid (distance from the beam axis).
        rho_max: f64 = 32.0, unit = "mean free paths", range = "0.5 to 1000";
        /// Axial extent behind the beam start (negative).
        z_min: f64 = -16.0, unit = "mean free paths", range = "-1000 to -0.5";
        /// Axial extent ahead of the beam start.
        z_max: f64 = 48.0, unit = "mean free paths", range = "0.5 to 1000";
        /// Radial cells (graded: 0.25× the uniform width at the axis, 1.75× at rho_max).
        rho_bins: u32 = 96, unit = "cells", range = "2 to 4096";
        /// Axial cells (graded away from the beam start in both directions).
        z_bins: u32 = 160, unit = "cells", range = "2 to 4096";
        /// Lobe nodes in θ, uniform over [0, π] inclusive (angle between ω and the axis origin → P).
        theta_bins: u32 = 33, unit = "nodes", range = "3 to 256";
        /// Lobe representation: `Symmetric` (wang2018's GPU table) or `Full` (adds φ).
        lobe: LobeKind = LobeKind::Symmetric, unit = "", range = "Symmetric | Full";
        /// Full lobe only: azimuth nodes over [0, π] (the lobe is mirror-symmetric in φ).
        phi_bins: u32 = 19, unit = "nodes", range = "2 to 64";
        /// Histogram bins of the incoming direction cosine μ' per cell (the lobe is the phase function
        /// averaged over each bin, weighted by the bin's tally).
        direction_bins: u32 = 64, unit = "bins", range = "4 to 1024";
        /// Photons traced per g slice.
        photons: u64 = 1 << 19, unit = "photons", range = "1024 to 2^32, photons × max_order <= 2^40";
        /// Highest collision order traced; orders beyond are the central-limit closure (isotropic).
        max_order: u32 = 512, unit = "collisions", range = "4 to 65536";
        /// Stored element type.
        element: Element = Element::F32, unit = "", range = "F32 | F64";
        /// Mantissa bits kept (relative rounding ≤ 2^-(bits+1)); 0 stores values exactly. 10 bits
        /// (5e-4) is well below the Monte-Carlo noise of a cell.
        mantissa_bits: u8 = 10, unit = "bits", range = "0 (lossless), or 1 to 23 for F32, 1 to 52 for F64";
        /// zstd compression level.
        zstd_level: i32 = 9, unit = "", range = "1 to 19";
        /// Random seed: another value draws an independent table (e.g. to measure the Monte-Carlo noise).
        /// Each g slice's photons depend only on the seed and the slice's own walk parameters, so a table
        /// pruned to fewer g slices or albedo nodes holds exactly the same numbers for the slices it keeps.
        seed: u64 = 0, unit = "", range = "any";
    }
}

/// Two g or albedo values this close are one node (merged in the definition, matched by
/// [`MsLobesTable::holds`]).
pub const NODE_TOLERANCE: f64 = 1e-12;

fn sorted_union(mut v: Vec<f64>) -> Vec<f64> {
    v.sort_by(f64::total_cmp);
    v.dedup_by(|a, b| (*a - *b).abs() <= NODE_TOLERANCE);
    v
}

impl MsLobes {
    /// The g slices: the materials' g and `g`, sorted, duplicates merged.
    pub fn g_values(&self) -> Vec<f64> {
        let mut v = self.g.clone();
        v.extend(self.materials.iter().filter_map(|m| material(m).map(|m| m.g)));
        sorted_union(v)
    }

    /// The albedo nodes: the grid, the materials' channel albedos and `albedos`, sorted, merged.
    pub fn albedo_values(&self) -> Vec<f64> {
        let mut v = self.albedos.clone();
        let n = self.albedo_grid;
        if n >= 2 {
            v.extend((0..n).map(|i| {
                let s = f64::from(i) / f64::from(n - 1);
                1.0 - s * s
            }));
        }
        v.extend(self.materials.iter().filter_map(|m| material(m)).flat_map(|m| m.albedo));
        sorted_union(v)
    }

    /// Range checks of every field.
    pub fn validate(&self) -> Vec<FieldIssue> {
        let mut issues = Vec::new();
        let mut issue = |field: &'static str, message: String, help: String| {
            issues.push(FieldIssue { field, message, help });
        };
        let known: Vec<&str> = materials().iter().map(|m| m.name.as_str()).collect();
        let mut seen = std::collections::BTreeSet::new();
        for m in &self.materials {
            if material(m).is_none() {
                issue("materials", format!("unknown material `{m}`"), format!("use one of {}", known.join(", ")));
            }
            if !seen.insert(m) {
                issue("materials", format!("`{m}` is listed twice"), "list each material once".into());
            }
        }
        if let Some(bad) = self.g.iter().find(|g| !(g.is_finite() && g.abs() <= MAX_ABS_G)) {
            issue("g", format!("g = {bad} is out of range"), format!("each g must satisfy |g| <= {MAX_ABS_G}"));
        }
        let ng = self.g_values().len();
        if ng == 0 || ng > MAX_G {
            issue("g", format!("{ng} g slices"), format!("give 1 to {MAX_G} g values (materials and g together)"));
        }
        if self.albedo_grid == 1 || self.albedo_grid > MAX_ALBEDOS as u32 {
            issue(
                "albedo_grid",
                format!("albedo_grid = {} is out of range", self.albedo_grid),
                "use 0 (none) or 2 to 64 nodes".into(),
            );
        }
        if let Some(bad) = self.albedos.iter().find(|a| !(0.0..=1.0).contains(*a)) {
            issue("albedos", format!("albedo {bad} is out of range"), "each albedo must lie in [0, 1]".into());
        }
        // Expand the grid only once its size passed the check above: albedo_grid = 4294967295 must be
        // refused, not allocated (issue 37).
        let grid_ok = self.albedo_grid as usize <= MAX_ALBEDOS;
        let na = if grid_ok { self.albedo_values().len() } else { 0 };
        if grid_ok && (na == 0 || na > MAX_ALBEDOS) {
            issue(
                "albedos",
                format!("{na} albedo nodes"),
                format!("give 1 to {MAX_ALBEDOS} albedo nodes (grid, materials and albedos together)"),
            );
        }
        for (field, v, lo, hi) in [
            ("rho_max", self.rho_max, 0.5, 1000.0),
            ("z_min", self.z_min, -1000.0, -0.5),
            ("z_max", self.z_max, 0.5, 1000.0),
        ] {
            if !(lo..=hi).contains(&v) {
                issue(field, format!("{field} = {v} is out of range"), format!("use {lo} to {hi} mean free paths"));
            }
        }
        for (field, v, lo, hi) in [
            ("rho_bins", self.rho_bins, 2, 4096),
            ("z_bins", self.z_bins, 2, 4096),
            ("theta_bins", self.theta_bins, 3, 256),
            ("phi_bins", self.phi_bins, 2, 64),
            ("direction_bins", self.direction_bins, 4, 1024),
            ("max_order", self.max_order, 4, 65536),
        ] {
            if !(lo..=hi).contains(&v) {
                issue(field, format!("{field} = {v} is out of range"), format!("use {lo} to {hi}"));
            }
        }
        if !(1024..=1u64 << 32).contains(&self.photons) {
            issue("photons", format!("photons = {} is out of range", self.photons), "use 1024 to 2^32".into());
        } else if u128::from(self.photons) * u128::from(self.max_order) > 1u128 << 40 {
            issue(
                "photons",
                format!("photons × max_order = {} exceeds 2^40", u128::from(self.photons) * u128::from(self.max_order)),
                "the integer tallies need photons × max_order <= 2^40; lower one of them".into(),
            );
        }
        let max_bits = match self.element {
            Element::F32 => 23,
            Element::F64 => 52,
        };
        if self.mantissa_bits > max_bits {
            issue(
                "mantissa_bits",
                format!("mantissa_bits = {} exceeds the {max_bits} bits of {:?}", self.mantissa_bits, self.element),
                format!("use 0 (lossless) or 1 to {max_bits}"),
            );
        }
        if !(1..=19).contains(&self.zstd_level) {
            issue("zstd_level", format!("zstd_level = {} is out of range", self.zstd_level), "use 1 to 19".into());
        }
        issues
    }

    /// The radial axis of the grid.
    pub fn rho_axis(&self) -> GradedAxis {
        GradedAxis::new(0.0, self.rho_max, self.rho_bins as usize)
    }

    /// The axial axis of the grid.
    pub fn z_axis(&self) -> GradedAxis {
        GradedAxis::new(self.z_min, self.z_max, self.z_bins as usize)
    }

    /// Output azimuth nodes (1 for the symmetric lobe).
    pub fn phi_nodes(&self) -> usize {
        match self.lobe {
            LobeKind::Symmetric => 1,
            LobeKind::Full => self.phi_bins as usize,
        }
    }

    fn cells(&self) -> u128 {
        u128::from(self.rho_bins) * u128::from(self.z_bins)
    }

    /// Peak memory: integer tallies per worker plus their sum, the f64 response of one slice, and every
    /// stored value three times (f64, element copy, compressed output bounded by raw).
    pub fn estimated_bytes(&self) -> u128 {
        let channels = 1 + self.albedo_values().len() as u128;
        let bins = u128::from(self.direction_bins) * self.phi_nodes() as u128;
        let workers = rayon::current_num_threads().max(1) as u128 + 1;
        let tally = self.cells() * bins * channels * 8 * workers;
        let lobe = u128::from(self.theta_bins) * self.phi_nodes() as u128;
        let per_g = self.cells() * (lobe + 1) * channels;
        tally + per_g * 8 + self.g_values().len() as u128 * per_g * 24
    }

    /// One unit per photon of every g slice.
    pub fn work_units(&self) -> u64 {
        self.photons * self.g_values().len() as u64
    }

    /// The random stream of the g slice `g`: keyed by the parameters its walk depends on (the seed, g,
    /// photons, orders, grid, lobe shape), not by the other slices, the albedo nodes or the encoding.
    pub fn slice_stream(&self, g: f64) -> StreamKey {
        let one = MsLobes {
            materials: Vec::new(),
            g: vec![g],
            albedo_grid: 0,
            albedos: Vec::new(),
            element: Element::F64,
            mantissa_bits: 0,
            zstd_level: 1,
            ..self.clone()
        };
        StreamKey::from_content_key(&super::TableDef::MsLobes(one).content_key(), 0)
    }

    /// The generator configuration of g slice `gi`.
    pub fn lobe_config(&self, gi: usize, g: f64, key: &[u8; 32]) -> LobeConfig {
        LobeConfig {
            g,
            albedos: self.albedo_values(),
            rho: self.rho_axis(),
            z: self.z_axis(),
            theta_nodes: self.theta_bins as usize,
            direction_bins: self.direction_bins as usize,
            shape: match self.lobe {
                LobeKind::Symmetric => LobeShape::Symmetric,
                LobeKind::Full => LobeShape::Full { phi_bins: self.phi_bins as usize },
            },
            photons: self.photons,
            max_order: self.max_order as usize,
            stream: StreamKey::from_content_key(key, gi as u64),
        }
    }

    fn quantization(&self) -> Option<Quantization> {
        (self.mantissa_bits > 0).then(|| Quantization::new(self.mantissa_bits))
    }

    /// Array descriptions, in file order.
    pub fn descs(&self) -> Vec<ArrayDesc> {
        let gs = self.g_values();
        let g_axis = Axis::explicit("g", "", gs.clone());
        let a_axis = Axis::explicit("albedo", "", self.albedo_values());
        let z_axis = Axis::explicit("z", "mean free paths (cell centre)", self.z_axis().centers());
        let r_axis = Axis::explicit("rho", "mean free paths (cell centre)", self.rho_axis().centers());
        let t_axis = Axis::linear("theta", "rad", 0.0, std::f64::consts::PI, u64::from(self.theta_bins));
        let mut lobe_axes = vec![z_axis.clone(), r_axis.clone(), t_axis];
        if self.lobe == LobeKind::Full {
            lobe_axes.push(Axis::linear("phi", "rad", 0.0, std::f64::consts::PI, u64::from(self.phi_bins)));
        }
        let desc = |name: String, description: String, unit: &str, axes: Vec<Axis>, q: Option<Quantization>| {
            ArrayDesc { name, description, unit: unit.into(), element: self.element.into(), axes, quantization: q }
        };
        let mut out = Vec::new();
        for (i, g) in gs.iter().enumerate() {
            out.push(desc(
                format!("total_g{i}"),
                format!("g = {g}: sum over k >= 2 of albedo^k E_k, the radiance scattered at (rho, z) toward (theta, phi) per mfp per unit beam power (orders > max_order: central-limit closure)"),
                "1/(mfp sr)",
                [vec![a_axis.clone()], lobe_axes.clone()].concat(),
                self.quantization(),
            ));
            out.push(desc(
                format!("density_g{i}"),
                format!("g = {g}: sum over k >= 2 of albedo^k psi_k, the scattering-event density (total integrated over directions)"),
                "1/mfp^3",
                vec![a_axis.clone(), z_axis.clone(), r_axis.clone()],
                self.quantization(),
            ));
        }
        out.push(desc(
            "double".into(),
            "E_2: radiance scattered by photons at their second scattering event, without the albedo^2 factor".into(),
            "1/(mfp sr)",
            [vec![g_axis.clone()], lobe_axes].concat(),
            self.quantization(),
        ));
        out.push(ArrayDesc {
            name: "inside".into(),
            description: "fraction of the order-k collisions inside the grid (k = 1 .. max_order)".into(),
            unit: "".into(),
            element: crate::container::ElementType::F64,
            axes: vec![
                g_axis,
                Axis::linear("k", "collisions", 1.0, f64::from(self.max_order), u64::from(self.max_order)),
            ],
            quantization: None,
        });
        out
    }

    /// Runs the generator: one walk per g slice (parallel over photon batches; integer tallies make the
    /// bytes independent of the thread count).
    pub fn generate(&self, key: &[u8; 32], progress: Progress<'_>) -> Result<Generated, GenerateError> {
        let parts = (0..self.g_values().len())
            .map(|gi| self.generate_slice(gi, key, progress))
            .collect::<Result<Vec<_>, _>>()?;
        self.assemble(parts)
    }

    /// The walk of g slice `gi` alone. Its random stream is keyed by the slice
    /// ([`MsLobes::slice_stream`]) and each photon has its own counter-based stream, so a slice — or a
    /// range of its photons ([`MsLobes::generate_batch`]) — computed on another machine is the same to
    /// the bit.
    pub fn generate_slice(
        &self,
        gi: usize,
        key: &[u8; 32],
        progress: Progress<'_>,
    ) -> Result<SlicePart, GenerateError> {
        let (g, cfg) = self.slice_config(gi, key)?;
        let t = lobe_transport::tally(&cfg, 0..cfg.photons, progress)
            .map_err(|m| GenerateError::Layout(format!("lobe walk for g = {g}: {m}")))?;
        self.slice_from_tallies(gi, key, &[t])
    }

    /// Photons per work unit of a sharded compile: [`MIN_UNIT_PHOTONS`], or more on fine grids. A
    /// unit's part file holds the slice's whole integer tally (8 bytes per (cell, direction bin,
    /// channel)) whatever its photon count, and writing plus reading it costs about 3 ns per byte
    /// against about 30 µs per photon walked (`voltab bench --suite shards`, Table 2 grid); at one photon
    /// per [`TALLY_BYTES_PER_PHOTON`] tally bytes the part files stay near 1 % of the walk. A power
    /// of two, a function of the grid alone: the split, and with it every byte, depends only on the
    /// pipeline.
    pub fn unit_photons(&self) -> u64 {
        let channels = 1 + self.albedo_values().len() as u64;
        let phi = match self.lobe {
            LobeKind::Symmetric => 1,
            LobeKind::Full => u64::from(self.phi_bins),
        };
        let tally_bytes =
            8 * u64::from(self.rho_bins) * u64::from(self.z_bins) * u64::from(self.direction_bins) * phi * channels;
        tally_bytes.div_ceil(TALLY_BYTES_PER_PHOTON).next_power_of_two().max(MIN_UNIT_PHOTONS)
    }

    /// How many photon batches of [`MsLobes::unit_photons`] a slice's walk splits into (work units of a
    /// sharded compile).
    pub fn photon_units(&self) -> usize {
        self.photons.div_ceil(self.unit_photons()).max(1) as usize
    }

    /// The integer tallies of photon batch `batch` of g slice `gi`: a work unit of a sharded compile.
    pub fn generate_batch(
        &self,
        gi: usize,
        batch: usize,
        key: &[u8; 32],
        progress: Progress<'_>,
    ) -> Result<lobe_transport::PhotonTally, GenerateError> {
        let (g, cfg) = self.slice_config(gi, key)?;
        let unit = self.unit_photons();
        let start = batch as u64 * unit;
        if start >= cfg.photons {
            return Err(GenerateError::Layout(format!("photon batch {batch} out of range ({})", self.photon_units())));
        }
        let end = (start + unit).min(cfg.photons);
        lobe_transport::tally(&cfg, start..end, progress)
            .map_err(|m| GenerateError::Layout(format!("lobe walk for g = {g}: {m}")))
    }

    fn slice_config(&self, gi: usize, key: &[u8; 32]) -> Result<(f64, LobeConfig), GenerateError> {
        let gs = self.g_values();
        let Some(&g) = gs.get(gi) else {
            return Err(GenerateError::Layout(format!("g slice {gi} out of range (the table has {})", gs.len())));
        };
        let mut cfg = self.lobe_config(gi, g, key);
        cfg.stream = self.slice_stream(g);
        Ok((g, cfg))
    }

    /// Slice `gi` from the tallies of a partition of its photons (any order; integer sums).
    pub fn slice_from_tallies(
        &self,
        gi: usize,
        key: &[u8; 32],
        tallies: &[lobe_transport::PhotonTally],
    ) -> Result<SlicePart, GenerateError> {
        let (g, cfg) = self.slice_config(gi, key)?;
        let (rho_axis, z_axis) = (self.rho_axis(), self.z_axis());
        let r = lobe_transport::finish_tallies(&cfg, tallies)
            .map_err(|m| GenerateError::Layout(format!("lobe walk for g = {g}: {m}")))?;
        // Share of the density the closure contributes, at REMAINDER_POINTS, for the largest albedo node.
        let mut remainder_share = vec![0.0f64; REMAINDER_POINTS.len()];
        if let (Some(rem), Some(dens)) = (r.remainder_density.last(), r.density.last()) {
            for (share, &(rho, z)) in remainder_share.iter_mut().zip(&REMAINDER_POINTS) {
                if let (Some(ir), Some(iz)) = (rho_axis.cell(rho), z_axis.cell(z)) {
                    let c = iz * rho_axis.bins + ir;
                    if dens[c] > 0.0 {
                        *share = share.max(rem[c] / dens[c]);
                    }
                }
            }
        }
        Ok(SlicePart {
            total: r.total.into_iter().flatten().collect(),
            density: r.density.into_iter().flatten().collect(),
            double: r.double,
            inside: r.inside,
            remainder_share,
            events: r.events,
            dropped: r.nonfinite_discarded,
        })
    }

    /// The table from its g slices, in slice order (what [`MsLobes::generate`] does after the walks).
    pub fn assemble(&self, parts: Vec<SlicePart>) -> Result<Generated, GenerateError> {
        let descs = self.descs();
        let gs = self.g_values();
        if parts.len() != gs.len() {
            return Err(GenerateError::Layout(format!("{} g slices given for a table of {}", parts.len(), gs.len())));
        }
        let help = "a lobe value overflowed the element type; use element: F64";
        let mut values = Vec::with_capacity(descs.len());
        let (mut double, mut inside) = (Vec::new(), Vec::new());
        let (mut events, mut dropped) = (0u64, 0u64);
        let mut remainder_share = vec![0.0f64; REMAINDER_POINTS.len()];
        for (gi, part) in parts.into_iter().enumerate() {
            events += part.events;
            dropped += part.dropped;
            for (share, s) in remainder_share.iter_mut().zip(&part.remainder_share) {
                *share = share.max(*s);
            }
            values.push(to_element(&descs[2 * gi], part.total, help)?);
            values.push(to_element(&descs[2 * gi + 1], part.density, help)?);
            double.extend(part.double);
            inside.extend(part.inside);
        }
        values.push(to_element(&descs[2 * gs.len()], double, help)?);
        values.push(to_element(&descs[2 * gs.len() + 1], inside, help)?);
        let top = self.albedo_values().last().copied().unwrap_or(0.0);
        let mut errors: Vec<ErrorEstimate> = REMAINDER_POINTS
            .iter()
            .zip(&remainder_share)
            .map(|(&(rho, z), &v)| ErrorEstimate {
                name: format!("remainder_share_rho{rho}_z{z}"),
                value: v,
                how: format!(
                    "share of the density at (rho, z) = ({rho}, {z}) mfp contributed by the closure of orders > {} (albedo {top}, largest over the g slices); not an error",
                    self.max_order
                ),
            })
            .collect();
        errors.push(ErrorEstimate {
            name: "remainder_energy_fraction".into(),
            value: if top > 0.0 { top.powi(self.max_order as i32 - 1) } else { 0.0 },
            how: format!(
                "albedo {top}: the fraction alpha^(K-1) of all scattering events of order >= 2 that lie beyond K = {} (everywhere, mostly far outside the grid)",
                self.max_order
            ),
        });
        let stats = GenStats { nonfinite_discarded: dropped, samples: events, errors };
        Ok(Generated { arrays: descs, values, stats })
    }
}

/// Rows of the stability matrix for `MsLobes`: a small table at g ∈ {−0.9, 0, 0.9, 0.99} and albedos
/// {0, 1e-6, 0.5, 0.999, 1}, queried on the beam axis, at the origin, far outside the grid and behind
/// the beam, at θ = 0 and π: every value finite and non-negative, far values no larger than at the
/// grid's edge, and albedo 0 exactly 0.
pub fn stability_rows() -> Vec<crate::stability::Row> {
    use crate::stability::{Expect, Row};
    let row = |formula, input: String, value, expect| Row { kind: "MsLobes", formula, input, value, expect };
    let def = MsLobes {
        materials: Vec::new(),
        g: vec![-0.9, 0.0, 0.9, 0.99],
        albedo_grid: 0,
        albedos: vec![0.0, 1e-6, 0.5, 0.999, 1.0],
        rho_max: 4.0,
        z_min: -2.0,
        z_max: 6.0,
        rho_bins: 6,
        z_bins: 8,
        theta_bins: 9,
        direction_bins: 8,
        photons: 2048,
        max_order: 64,
        element: Element::F64,
        ..MsLobes::default()
    };
    let table = match def
        .generate(&[7; 32], &|_| {})
        .map_err(|e| e.to_string())
        .and_then(|g| MsLobesTable::from_arrays(&def, &g.arrays, &g.values))
    {
        Ok(t) => t,
        Err(e) => return vec![row("generate", format!("small table: {e}"), f64::NAN, Expect::Finite)],
    };
    let mut v = Vec::new();
    let points = [("on axis", 0.0, 1.0), ("origin", 0.0, 0.0), ("far outside", 1e3, 1e3), ("far behind", 0.0, -1e300)];
    for albedo in [0.0, 1e-6, 0.5, 0.999, 1.0] {
        for g in [-0.9, 0.0, 0.9, 0.99] {
            let edge = table
                .lobe(&LobeQuery { albedo, g, rho: 4.0, z: 6.0, theta: 0.0, phi: 0.0 })
                .map_or(f64::NAN, |x| x.total);
            for (name, rho, z) in points {
                for theta in [0.0, std::f64::consts::PI] {
                    let value = match table.lobe(&LobeQuery { albedo, g, rho, z, theta, phi: 0.0 }) {
                        Ok(x) if x.total >= 0.0 && x.double >= 0.0 && x.double.is_finite() => x.total,
                        _ => f64::NAN,
                    };
                    let expect = if albedo == 0.0 {
                        Expect::Close { to: 0.0, rel: 0.0 }
                    } else if name == "far outside" && theta == 0.0 {
                        Expect::InRange(0.0, edge)
                    } else {
                        Expect::InRange(0.0, f64::MAX)
                    };
                    v.push(row(
                        "lobe total",
                        format!("albedo={albedo}, g={g}, {name}, theta={theta:.3}"),
                        value,
                        expect,
                    ));
                }
            }
        }
    }
    v
}

/// The fewest photons in a work unit of a sharded compile ([`MsLobes::unit_photons`]).
pub const MIN_UNIT_PHOTONS: u64 = 1 << 18;

/// Tally bytes per photon of a work unit at most ([`MsLobes::unit_photons`]).
pub const TALLY_BYTES_PER_PHOTON: u64 = 64;

/// One g slice of an [`MsLobes`] table before assembly.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SlicePart {
    /// Lobes of all orders >= 2 per albedo node, flat `[albedo, z, rho, theta(, phi)]`.
    pub total: Vec<f64>,
    /// Densities per albedo node, flat `[albedo, z, rho]`.
    pub density: Vec<f64>,
    /// E_2 without albedo², flat `[z, rho, theta(, phi)]`.
    pub double: Vec<f64>,
    /// Per-order inside fractions.
    pub inside: Vec<f64>,
    /// Closure share at the report points (largest albedo node).
    pub remainder_share: Vec<f64>,
    /// Scattering events simulated.
    pub events: u64,
    /// Non-finite contributions discarded.
    pub dropped: u64,
}

/// One backward-walk reference value of the sidecar check ([`MsLobes::check_references`]).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CheckReference {
    /// Bits of (ρ, z, θ, g, α).
    pub at: [u64; 5],
    /// (mean, standard error).
    pub value: (f64, f64),
}

impl super::TableKind for MsLobes {
    fn kind(&self) -> &'static str {
        MsLobesRaw::KIND
    }
    fn kind_schema_version(&self) -> u32 {
        KIND_SCHEMA_VERSION
    }
    fn generator_version(&self) -> &'static str {
        GENERATOR_VERSION
    }
    fn validate(&self) -> Vec<FieldIssue> {
        MsLobes::validate(self)
    }
    fn estimated_bytes(&self) -> u128 {
        MsLobes::estimated_bytes(self)
    }
    fn work_units(&self) -> u64 {
        MsLobes::work_units(self)
    }
    fn work_unit_name(&self) -> &'static str {
        "photons"
    }
    fn generate(
        &self,
        key: &[u8; 32],
        progress: super::Progress<'_>,
    ) -> Result<super::Generated, super::GenerateError> {
        MsLobes::generate(self, key, progress)
    }
    fn estimate_errors(&self, generated: &super::Generated, key: &[u8; 32]) -> Result<super::GenStats, CheckError> {
        MsLobes::estimate_errors(self, generated, key)
    }
    fn report_ladder(&self) -> Vec<(String, super::TableDef)> {
        MsLobes::report_ladder(self).into_iter().map(|(l, d)| (l, super::TableDef::MsLobes(d))).collect()
    }
    fn report_error_name(&self) -> &'static str {
        "max relative error of the lobes vs the beam quadrature (E_2) and the backward-walk reference (total)"
    }
    fn report_measure(&self, generated: &super::Generated) -> Result<Vec<(String, f64)>, CheckError> {
        MsLobes::report_measure(self, generated)
    }

    /// Its g slices' photon batches (each its own random stream) and one unit for the references of
    /// its check.
    fn units(&self) -> usize {
        self.g_values().len() * self.photon_units() + 1
    }
    fn generate_unit(
        &self,
        key: &[u8; 32],
        unit: usize,
        progress: super::Progress<'_>,
    ) -> Result<super::UnitPart, super::GenerateError> {
        if unit == self.g_values().len() * self.photon_units() {
            return self.check_references(key).map(super::UnitPart::MsLobesCheck).map_err(super::GenerateError::Check);
        }
        let (slice, batch) = (unit / self.photon_units(), unit % self.photon_units());
        self.generate_batch(slice, batch, key, progress).map(|tally| super::UnitPart::MsLobesPhotons { slice, tally })
    }
    fn assemble(&self, key: &[u8; 32], parts: Vec<super::UnitPart>) -> Result<super::Assembled, super::GenerateError> {
        let n = self.g_values().len();
        let (mut tallies, mut refs) = (vec![Vec::new(); n], Vec::new());
        for part in parts {
            match part {
                super::UnitPart::MsLobesPhotons { slice, tally } if slice < n => tallies[slice].push(tally),
                super::UnitPart::MsLobesCheck(r) => refs.extend(r),
                _ => return Err(super::GenerateError::Layout("a unit of another table given to a lobe table".into())),
            }
        }
        let slices = tallies
            .iter()
            .enumerate()
            .map(|(gi, t)| self.slice_from_tallies(gi, key, t))
            .collect::<Result<Vec<_>, _>>()?;
        let mut generated = MsLobes::assemble(self, slices)?;
        let t0 = std::time::Instant::now();
        generated.stats = self.estimate_errors_with(&generated, key, &refs)?;
        Ok(super::Assembled { generated, check_ms: t0.elapsed().as_secs_f64() * 1e3 })
    }
}
