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

mod materials;
mod slice;
mod table;
#[cfg(test)]
mod tests;

use serde::{Deserialize, Serialize};

pub use materials::{Material, material, materials};
pub use slice::LobeSlice;
pub use table::{LobeQuery, LobeValue, LobesReadError, MediumChannel, MsLobesTable};

use super::phase_hg::Element;
use super::{ErrorEstimate, FieldIssue, GenStats, GenerateError, Generated, Progress, to_element};
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
        StreamKey::from_content_key(&crate::cache::content_key(&super::TableDef::MsLobes(one)), 0)
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
    /// against about 30 µs per photon walked (`voltab bench --shards`, Table 2 grid); at one photon
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

/// Points `(ρ, z)` at which the sidecar reports the closure's share of the density.
pub const REMAINDER_POINTS: [(f64, f64); 4] = [(1.0, 2.0), (5.0, 5.0), (10.0, 10.0), (20.0, 20.0)];

/// Probe points `(ρ, z)` of the error estimates, in mean free paths (kept inside the grid).
pub const PROBES: [(f64, f64); 3] = [(1.0, 2.0), (2.0, 0.5), (1.5, -1.0)];
/// Lobe angles of the `E_2` probes.
pub const PROBE_THETAS: [f64; 3] = [0.0, std::f64::consts::FRAC_PI_2, std::f64::consts::PI];
/// Backward-walk samples per probe in the sidecar.
pub const SIDECAR_ADJOINT_SAMPLES: u64 = 4096;
/// Backward-walk samples per probe in the report's reference (cached per configuration).
pub const REPORT_ADJOINT_SAMPLES: u64 = 16384;
/// Albedo at which totals are compared (the nearest stored node is used, so no albedo interpolation
/// enters the comparison): orders die out by `k ≈ 120`, so the backward walk stays cheap.
pub const PROBE_ALBEDO: f64 = 0.8;

/// The probe points that lie inside a definition's grid.
fn probes(def: &MsLobes) -> Vec<(f64, f64)> {
    PROBES.into_iter().filter(|&(r, z)| r <= def.rho_max && z >= def.z_min && z <= def.z_max).collect()
}

/// The g slices used for error estimates: first and last (one when equal).
fn probe_gs(def: &MsLobes) -> Vec<f64> {
    let gs = def.g_values();
    match (gs.first(), gs.last()) {
        (Some(a), Some(b)) if a != b => vec![*a, *b],
        (Some(a), _) => vec![*a],
        _ => Vec::new(),
    }
}

/// The stored albedo node nearest [`PROBE_ALBEDO`].
fn probe_albedo(def: &MsLobes) -> f64 {
    def.albedo_values()
        .into_iter()
        .min_by(|a, b| (a - PROBE_ALBEDO).abs().total_cmp(&(b - PROBE_ALBEDO).abs()))
        .unwrap_or(PROBE_ALBEDO)
}

/// Worst relative error of `E_2` against the deterministic quadrature over the probes, and the
/// worst relative error / z-score of the totals against the backward walk.
#[derive(Debug, Clone, Copy, Default)]
struct Comparison {
    double_rel: f64,
    /// Fewest second collisions expected in a probe's cell (its E_2 noise is ~1/√hits).
    double_hits: f64,
    total_rel: f64,
    total_z: f64,
    ref_rel_noise: f64,
}

type AdjointRef = (f64, f64);

fn compare(
    def: &MsLobes,
    table: &MsLobesTable,
    reference: &dyn Fn(f64, f64, f64, f64, f64) -> Result<AdjointRef, String>,
) -> Result<Comparison, String> {
    use crate::reference::beam_adjoint;
    let mut c = Comparison { double_hits: f64::INFINITY, ..Comparison::default() };
    let albedo = probe_albedo(def);
    for g in probe_gs(def) {
        for (rho, z) in probes(def) {
            // E_2 at the centre of the probe's cell against the cell average of the quadrature: what an
            // exact table holds there (no interpolation bias; the Monte-Carlo noise remains).
            for theta in PROBE_THETAS {
                let ((rc, zc), want) =
                    cell_average(def, rho, z, &|r, zz| beam_adjoint::double_symmetric(r, zz, theta, g))?;
                let got = table.double_lobe(&LobeQuery { albedo, g, rho: rc, z: zc, theta, phi: 0.0 })?;
                c.double_rel = c.double_rel.max((got - want).abs() / want);
            }
            c.double_hits = c.double_hits.min(expected_second_collisions(def, table, g, rho, z)?);
            // Totals only where the backward walk's heavy tail is tame (|g| <= 0.7: at g = 0.9 its
            // scores near the beam axis make seeds disagree by 2x).
            if g.abs() > 0.7 {
                continue;
            }
            let theta = std::f64::consts::FRAC_PI_2;
            let (mean, se) = reference(rho, z, theta, g, albedo)?;
            let got = table.lobe(&LobeQuery { albedo, g, rho, z, theta, phi: 0.0 })?.total;
            c.total_rel = c.total_rel.max((got - mean).abs() / mean);
            c.total_z = c.total_z.max((got - mean).abs() / se.max(f64::MIN_POSITIVE));
            c.ref_rel_noise = c.ref_rel_noise.max(se / mean);
        }
    }
    Ok(c)
}

/// Second collisions the walk is expected to tally in the cell holding `(rho, z)`: `ψ_2 V N`, with `ψ_2`
/// the table's own `E_2` integrated over directions (trapezoid over its θ nodes).
fn expected_second_collisions(def: &MsLobes, table: &MsLobesTable, g: f64, rho: f64, z: f64) -> Result<f64, String> {
    let (ra, za) = (def.rho_axis(), def.z_axis());
    let (ir, iz) = match (ra.cell(rho), za.cell(z)) {
        (Some(a), Some(b)) => (a, b),
        _ => return Err(format!("({rho}, {z}) is outside the grid")),
    };
    let (r0, r1) = (ra.edge(ir), ra.edge(ir + 1));
    let volume = std::f64::consts::PI * (r1 * r1 - r0 * r0) * (za.edge(iz + 1) - za.edge(iz));
    let n = def.theta_bins as usize;
    let h = std::f64::consts::PI / (n - 1) as f64;
    let mut psi = 0.0;
    for i in 0..n {
        let theta = h * i as f64;
        let w = if i == 0 || i == n - 1 { 0.5 } else { 1.0 };
        let q = LobeQuery { albedo: 0.5, g, rho: ra.center(ir), z: za.center(iz), theta, phi: 0.0 };
        psi += w * h * 2.0 * std::f64::consts::PI * theta.sin() * table.double_lobe(&q)?;
    }
    Ok(psi * volume * def.photons as f64)
}

/// The cell of `def`'s grid holding `(rho, z)`: its centre and the 3×3 Gauss average of `f(ρ, z)` over
/// its volume (weight ρ) — what an exact table stores in that cell.
pub fn cell_average(
    def: &MsLobes,
    rho: f64,
    z: f64,
    f: &dyn Fn(f64, f64) -> Result<f64, String>,
) -> Result<((f64, f64), f64), String> {
    let (ra, za) = (def.rho_axis(), def.z_axis());
    let (ir, iz) = match (ra.cell(rho), za.cell(z)) {
        (Some(a), Some(b)) => (a, b),
        _ => return Err(format!("({rho}, {z}) is outside the grid")),
    };
    let (r0, r1, z0, z1) = (ra.edge(ir), ra.edge(ir + 1), za.edge(iz), za.edge(iz + 1));
    let gl = crate::physics::sh::gauss_legendre(3);
    let (mut acc, mut wsum) = (0.0, 0.0);
    for &(x, wx) in &gl {
        let r = 0.5 * (r0 + r1) + 0.5 * (r1 - r0) * x;
        for &(y, wy) in &gl {
            let zz = 0.5 * (z0 + z1) + 0.5 * (z1 - z0) * y;
            acc += wx * wy * r * f(r, zz)?;
            wsum += wx * wy * r;
        }
    }
    Ok(((ra.center(ir), za.center(iz)), acc / wsum))
}

fn adjoint(
    samples: u64,
    seed: u64,
    max_order: usize,
) -> impl Fn(f64, f64, f64, f64, f64) -> Result<AdjointRef, String> {
    move |rho, z, theta, g, albedo| {
        let cfg = crate::reference::beam_adjoint::AdjointConfig { samples, max_order, seed };
        let e = crate::reference::beam_adjoint::total_symmetric(rho, z, theta, g, albedo, &cfg)?;
        Ok((e.mean, e.std_error))
    }
}

/// Cached report references keyed by (ρ, z, θ, g, α, max_order) bits.
type RefCache = std::sync::Mutex<std::collections::HashMap<[u64; 6], AdjointRef>>;

fn cached_adjoint(max_order: usize) -> impl Fn(f64, f64, f64, f64, f64) -> Result<AdjointRef, String> {
    static CACHE: std::sync::OnceLock<RefCache> = std::sync::OnceLock::new();
    move |rho, z, theta, g, albedo| {
        let cache = CACHE.get_or_init(Default::default);
        let key = [rho.to_bits(), z.to_bits(), theta.to_bits(), g.to_bits(), albedo.to_bits(), max_order as u64];
        if let Some(v) = cache.lock().map_err(|_| "reference cache poisoned".to_string())?.get(&key) {
            return Ok(*v);
        }
        let v = adjoint(REPORT_ADJOINT_SAMPLES, 0x3a6e_2018, max_order)(rho, z, theta, g, albedo)?;
        cache.lock().map_err(|_| "reference cache poisoned".to_string())?.insert(key, v);
        Ok(v)
    }
}

/// `∫ density dV` over the grid for albedo node `ai` of g slice `gi`, and `Σ_{k=2}^{K} α^k · inside_k`
/// (what the integer tallies put inside), for the conservation check.
pub fn conservation(def: &MsLobes, table: &MsLobesTable, gi: usize, ai: usize) -> Result<(f64, f64), String> {
    let (rho, z) = (def.rho_axis(), def.z_axis());
    let albedo = def.albedo_values()[ai];
    let g = def.g_values()[gi];
    let mut integral = 0.0;
    for iz in 0..z.bins {
        for ir in 0..rho.bins {
            let (r0, r1) = (rho.edge(ir), rho.edge(ir + 1));
            let volume = std::f64::consts::PI * (r1 * r1 - r0 * r0) * (z.edge(iz + 1) - z.edge(iz));
            let closure = lobe_transport::remainder(albedo, g, def.max_order as usize, rho.center(ir), z.center(iz));
            let d = table.density(albedo, g, rho.center(ir), z.center(iz))?;
            integral += (d - closure) * volume;
        }
    }
    let tallied: f64 = (2..=def.max_order as usize)
        .map(|k| albedo.powi(k as i32) * table.inside_fraction(gi, k).unwrap_or(f64::NAN))
        .sum();
    Ok((integral, tallied))
}

impl MsLobes {
    /// Error estimates (sidecar): `E_2` against the deterministic quadrature and totals against the
    /// backward walk of [`crate::reference::beam_adjoint`] at [`PROBES`], for the first and last g slices;
    /// conservation at the largest albedo node ≤ 0.5; the closure's share (from the generator).
    pub fn estimate_errors(&self, generated: &Generated, key: &[u8; 32]) -> Result<GenStats, String> {
        self.estimate_errors_with(generated, key, &[])
    }

    /// The backward-walk references [`MsLobes::estimate_errors`] compares the table with, computed in
    /// parallel: a work unit of its own in a sharded compile (it needs the definition only, not the
    /// table). Each value is keyed by the bits of its (ρ, z, θ, g, α).
    pub fn check_references(&self, key: &[u8; 32]) -> Result<Vec<CheckReference>, String> {
        use rayon::prelude::*;
        let seed = u64::from_le_bytes(key[..8].try_into().map_err(|_| "short key".to_string())?);
        let albedo = probe_albedo(self);
        let theta = std::f64::consts::FRAC_PI_2;
        let points: Vec<[f64; 5]> = probe_gs(self)
            .into_iter()
            .filter(|g| g.abs() <= 0.7)
            .flat_map(|g| probes(self).into_iter().map(move |(rho, z)| [rho, z, theta, g, albedo]))
            .collect();
        let reference = adjoint(SIDECAR_ADJOINT_SAMPLES, seed, 400);
        points
            .par_iter()
            .map(|q| Ok(CheckReference { at: q.map(f64::to_bits), value: reference(q[0], q[1], q[2], q[3], q[4])? }))
            .collect()
    }

    /// [`MsLobes::estimate_errors`] with references already computed ([`MsLobes::check_references`]);
    /// any it lacks are computed here. The same numbers either way.
    pub fn estimate_errors_with(
        &self,
        generated: &Generated,
        key: &[u8; 32],
        known: &[CheckReference],
    ) -> Result<GenStats, String> {
        let table = MsLobesTable::from_arrays(self, &generated.arrays, &generated.values)?;
        let seed = u64::from_le_bytes(key[..8].try_into().map_err(|_| "short key".to_string())?);
        let compute = adjoint(SIDECAR_ADJOINT_SAMPLES, seed, 400);
        let reference = |rho: f64, z: f64, theta: f64, g: f64, albedo: f64| {
            let at = [rho, z, theta, g, albedo].map(f64::to_bits);
            match known.iter().find(|r| r.at == at) {
                Some(r) => Ok(r.value),
                None => compute(rho, z, theta, g, albedo),
            }
        };
        let c = compare(self, &table, &reference)?;
        let where_ =
            format!("(rho, z) in {:?} mfp, g {:?}, albedo node {}", probes(self), probe_gs(self), probe_albedo(self));
        let mut errors = vec![
            ErrorEstimate {
                name: "double_max_rel_vs_quadrature".into(),
                value: c.double_rel,
                how: format!(
                    "E_2 lobes at theta 0, pi/2, pi at the centres of the probes' cells vs the cell average of reference::beam_adjoint::double_symmetric (Monte-Carlo noise included), {where_}"
                ),
            },
            ErrorEstimate {
                name: "double_probe_min_second_collisions".into(),
                value: c.double_hits,
                how: "fewest second collisions the walk tallied (expected) in a probe's cell: the E_2 comparison's noise is ~1/sqrt of it (not an error)".into(),
            },
            ErrorEstimate {
                name: "total_max_rel_vs_backward_walk".into(),
                value: c.total_rel,
                how: format!(
                    "total lobe at theta pi/2 vs reference::beam_adjoint::total_symmetric ({SIDECAR_ADJOINT_SAMPLES} samples; g slices with |g| <= 0.7 only), {where_}"
                ),
            },
            ErrorEstimate {
                name: "total_max_z_vs_backward_walk".into(),
                value: c.total_z,
                how: "largest |table - reference| / reference standard error (table noise not included)".into(),
            },
            ErrorEstimate {
                name: "backward_walk_rel_std_error".into(),
                value: c.ref_rel_noise,
                how: "largest relative standard error of the backward-walk reference (its noise floor)".into(),
            },
        ];
        let albedos = self.albedo_values();
        if let Some(ai) = albedos.iter().rposition(|&a| a <= 0.5 && a > 0.0) {
            let a = albedos[ai];
            let mut worst = 0.0f64;
            let mut worst_law = 0.0f64;
            for gi in 0..self.g_values().len() {
                let (integral, tallied) = conservation(self, &table, gi, ai)?;
                worst = worst.max((integral / tallied - 1.0).abs());
                worst_law = worst_law.max((integral / (a * a / (1.0 - a)) - 1.0).abs());
            }
            errors.push(ErrorEstimate {
                name: "conservation_density_vs_tallied".into(),
                value: worst,
                how: format!(
                    "albedo {a}: |∫density dV / Σ_k α^k inside_k − 1| over the g slices (stored, quantised values)"
                ),
            });
            errors.push(ErrorEstimate {
                name: "conservation_vs_alpha2_over_1_minus_alpha".into(),
                value: worst_law,
                how: format!(
                    "albedo {a}: |∫density dV / (α²/(1−α)) − 1|: collisions of order >= 2 per photon (includes the share outside the grid)"
                ),
            });
        }
        if self.lobe == LobeKind::Full {
            let albedo = probe_albedo(self);
            let mut worst = 0.0f64;
            for g in probe_gs(self) {
                for (rho, z) in probes(self) {
                    worst = worst.max(symmetry_error(&table, albedo, g, rho, z)?.1);
                }
            }
            errors.push(ErrorEstimate {
                name: "symmetric_lobe_max_rel".into(),
                value: worst,
                how: format!(
                    "largest integral |L(theta, phi) - azimuthal mean| domega / integral L domega: the error a Symmetric table of the same walk makes (wang2018 Fig. 8), {where_}"
                ),
            });
        }
        errors.extend(generated.stats.errors.iter().cloned());
        Ok(GenStats {
            nonfinite_discarded: generated.stats.nonfinite_discarded,
            samples: generated.stats.samples,
            errors,
        })
    }

    /// Quality budgets for `voltab report`: photons from 1/64 of the table's count up to it.
    pub fn report_ladder(&self) -> Vec<(String, MsLobes)> {
        [64u64, 16, 4, 1]
            .into_iter()
            .map(|div| (self.photons / div).max(1024))
            .collect::<std::collections::BTreeSet<_>>()
            .into_iter()
            .map(|photons| (format!("photons={photons}"), MsLobes { photons, ..self.clone() }))
            .collect()
    }

    /// Curves of the report: `E_2` against the quadrature, totals against the cached backward walk.
    pub fn report_measure(&self, generated: &Generated) -> Result<Vec<(String, f64)>, String> {
        let table = MsLobesTable::from_arrays(self, &generated.arrays, &generated.values)?;
        let c = compare(self, &table, &cached_adjoint(400))?;
        Ok(vec![("double (E_2) vs quadrature".into(), c.double_rel), ("total vs backward walk".into(), c.total_rel)])
    }
}

/// The error of the symmetric-lobe approximation (wang2018 Sec. 4.1, Fig. 8) at canonical `(ρ, z)`, from a
/// `Full` table, with `L̄(θ)` the azimuthal average (what a symmetric table stores): (largest
/// `|L(θ, φ) − L̄(θ)|` over the lobe nodes relative to the lobe's maximum, `∫|L − L̄| dω / ∫ L dω`, angle
/// of the full lobe's peak from the symmetry axis in degrees).
pub fn symmetry_error(table: &MsLobesTable, albedo: f64, g: f64, rho: f64, z: f64) -> Result<(f64, f64, f64), String> {
    let (nt, np) = table.lobe_nodes();
    if np < 2 {
        return Err("the symmetric-lobe error needs a Full lobe table".into());
    }
    let node = |i: usize, n: usize| std::f64::consts::PI * i as f64 / (n - 1) as f64;
    let trapezoid = |i: usize, n: usize| if i == 0 || i == n - 1 { 0.5 } else { 1.0 };
    let mut worst = 0.0f64;
    let (mut l1_diff, mut l1) = (0.0f64, 0.0f64);
    let (mut peak, mut peak_theta) = (0.0f64, 0.0);
    for i in 0..nt {
        let theta = node(i, nt);
        let lobe: Vec<f64> = (0..np)
            .map(|m| table.lobe(&LobeQuery { albedo, g, rho, z, theta, phi: node(m, np) }).map(|v| v.total))
            .collect::<Result<_, _>>()?;
        // Trapezoid over φ ∈ [0, π] of the mirror-symmetric lobe = its average over the circle.
        let avg = lobe.iter().enumerate().map(|(m, v)| trapezoid(m, np) * v).sum::<f64>() / (np - 1) as f64;
        let w_theta = trapezoid(i, nt) * theta.sin();
        for (m, &v) in lobe.iter().enumerate() {
            worst = worst.max((v - avg).abs());
            l1_diff += w_theta * trapezoid(m, np) * (v - avg).abs();
            l1 += w_theta * trapezoid(m, np) * v;
            if v > peak {
                peak = v;
                peak_theta = theta;
            }
        }
    }
    if peak > 0.0 { Ok((worst / peak, l1_diff / l1, peak_theta.to_degrees())) } else { Ok((0.0, 0.0, 0.0)) }
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
