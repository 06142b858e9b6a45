//! The consumer side of `MsLobes` (wang2018 Sec. 3.5.4 Eq. 7, Sec. 4.1): a loaded table (all of it, or
//! only the (α, g) slices some media need) and the look-ups a translucent-media renderer makes.
//!
//! **Input → output.** A `.vtab` and per colour channel a [`MediumChannel`] (albedo, σ_t, g), a beam
//! (origin, unit direction), a point `x` and a direction `ω` → the radiance scattered at `x` toward `ω`
//! per unit length per unit beam power by photons that scattered at least once before ([`LobeValue::total`])
//! and its exactly-two-events part ([`LobeValue::double`]); [`MsLobesTable::lobe`] answers the same in
//! the canonical medium (σ_t = 1) at cylindrical coordinates (ρ, z) and lobe angles.
//!
//! **Interpolation.** g linearly between slices (a g outside the tabulated range is refused, never
//! extrapolated); albedo linearly in `s = √(1 − α)` (the series `Σ α^k` behaves like `1/s²` globally,
//! but locally the field varies smoothly in `s`); `(ρ, z)` bilinearly between cell centres in the graded
//! coordinate (flat between the first centre and the axis / the grid edge); `θ` (and `φ`) linearly.
//!
//! **Outside the grid** the value at the nearest grid point is continued with the decay
//! `(r_b/r) e^{−κ(r − r_b)}`, `κ` the diffusion rate `√(3(1 − α)(1 − αg))` capped at the free-flight
//! rate 1 ([`crate::physics::lobe_transport::decay_rate`]; the double term uses 1): values always decay
//! outward, never grow or turn to garbage.
//!
//! **Scaling.** A medium with extinction `σ_t` is the canonical one with lengths divided by `σ_t`:
//! `S(x) = σ_t³ S_canonical(σ_t x)` (densities per unit volume scale as `σ_t³`, the radiance per unit
//! length as one more `σ_t` than the per-mfp value, the phase is unit-free).

use std::collections::{BTreeSet, HashMap};
use std::f64::consts::PI;
use std::path::Path;

use glam::DVec3;

use super::{LobeKind, MsLobes, MsLobesRaw};
use crate::container::{ArrayDesc, ArrayValues};
use crate::physics::lobe_transport::{GradedAxis, decay_rate};
use crate::tables::TableDef;

/// Failure to load an `MsLobes` table.
pub type LobesReadError = crate::tables::TableReadError;

/// A look-up the table cannot answer (the lobe twin of the ZH table's `QueryError`).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum LobeQueryError {
    /// An argument is out of its domain: not finite, a negative ρ, θ or φ outside [0, π], a zero vector,
    /// σ_t ≤ 0 or an albedo outside [0, 1].
    #[error("{0}")]
    Invalid(String),
    /// The albedo lies inside [0, 1] but outside the tabulated nodes.
    #[error("albedo = {albedo} is outside the table's albedo range [{min}, {max}]; add it (albedos or albedo_grid)")]
    AlbedoOutOfRange {
        /// Requested albedo.
        albedo: f64,
        /// Smallest tabulated albedo.
        min: f64,
        /// Largest tabulated albedo.
        max: f64,
    },
    /// The medium's g lies outside the tabulated slices.
    #[error("g = {g} is outside the table's g range [{min}, {max}]; add it to the table's g list")]
    GOutOfRange {
        /// Requested g.
        g: f64,
        /// Smallest tabulated g.
        min: f64,
        /// Largest tabulated g.
        max: f64,
    },
    /// The slices the query needs were not loaded (a table loaded for other media).
    #[error("{0} is not loaded")]
    NotLoaded(String),
    /// `σ_t³` times the canonical value overflows.
    #[error("sigma_t = {sigma_t} overflows the σ_t³ scaling of the lobe; use scene units nearer 1/σ_t")]
    Overflow {
        /// The medium's extinction.
        sigma_t: f64,
    },
}

/// One colour channel of a homogeneous medium, scene units.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MediumChannel {
    /// Single-scattering albedo in [0, 1].
    pub albedo: f64,
    /// Extinction coefficient σ_t = 1/ℓ (1/scene unit), finite, > 0.
    pub sigma_t: f64,
    /// HG mean cosine, within the table's g range.
    pub g: f64,
}

/// A look-up in the canonical medium (σ_t = 1, lengths in mean free paths).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LobeQuery {
    /// Albedo in [0, 1].
    pub albedo: f64,
    /// HG g within the table's range.
    pub g: f64,
    /// Distance from the beam axis, ≥ 0.
    pub rho: f64,
    /// Depth along the beam from its origin (negative behind it).
    pub z: f64,
    /// Angle between ω and the axis origin → P, in [0, π].
    pub theta: f64,
    /// Azimuth of ω about that axis in [0, π] (full-lobe tables; ignored by symmetric ones, which hold
    /// the azimuthal average).
    pub phi: f64,
}

/// The scattered radiance per unit length per unit beam power.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct LobeValue {
    /// All paths with at least two scattering events (`Σ_{k≥2} α^k E_k`).
    pub total: f64,
    /// Exactly two scattering events (`α² E_2`), included in `total`.
    pub double: f64,
}

/// A loaded `MsLobes` table.
#[derive(Debug, Clone)]
pub struct MsLobesTable {
    gs: Vec<f64>,
    albedos: Vec<f64>,
    /// `√(1 − α)` of the albedo nodes in reverse order (increasing), the albedo interpolation axis.
    s_nodes: Vec<f64>,
    rho: GradedAxis,
    z: GradedAxis,
    /// The grid's outer edges `(ρ_max, z_min, z_max)` (computed once; every look-up clamps to them).
    edges: (f64, f64, f64),
    pub(super) theta_bins: usize,
    pub(super) phi_nodes: usize,
    pub(super) lobe: LobeKind,
    /// `(g index, albedo index)` → `[z][ρ][θ][φ]`.
    pub(super) total: HashMap<(usize, usize), Vec<f64>>,
    /// `(g index, albedo index)` → `[z][ρ]`.
    pub(super) density: HashMap<(usize, usize), Vec<f64>>,
    /// g index → `E_2` `[z][ρ][θ][φ]`.
    pub(super) double: HashMap<usize, Vec<f64>>,
    /// `[g][k − 1]`.
    inside: Vec<Vec<f64>>,
}

/// Interpolation weights of one query point (at most four spatial and four angular nodes; unused
/// entries carry weight 0 and are skipped).
pub(super) struct Located {
    r: f64,
    r_b: f64,
    spatial: [(usize, f64); 4],
    angular: [(usize, f64); 4],
}

impl Located {
    /// Weighted sum over the cells and lobe nodes of one slice (`lobe_len` values per cell).
    pub(super) fn sample(&self, v: &[f64], lobe_len: usize) -> f64 {
        let mut acc = 0.0;
        for &(cell, wc) in self.spatial.iter().filter(|w| w.1 > 0.0) {
            for &(o, wo) in self.angular.iter().filter(|w| w.1 > 0.0) {
                acc += wc * wo * v[cell * lobe_len + o];
            }
        }
        acc
    }

    /// Weighted sum over the cells of a `[z][ρ]` array.
    pub(super) fn sample_cells(&self, v: &[f64]) -> f64 {
        self.spatial.iter().filter(|w| w.1 > 0.0).map(|&(c, w)| w * v[c]).sum::<f64>()
    }

    /// `(r_b/r) e^{−κ(r − r_b)}` beyond the grid, 1 inside.
    pub(super) fn decay(&self, kappa: f64) -> f64 {
        if self.r > self.r_b && self.r_b > 0.0 {
            (self.r_b / self.r) * (-kappa * (self.r - self.r_b)).exp()
        } else {
            1.0
        }
    }
}

/// Linear interpolation weights over an increasing node list; `None` outside `[first, last]`.
fn bracket(nodes: &[f64], x: f64) -> Option<[(usize, f64); 2]> {
    let n = nodes.len();
    let (first, last) = (*nodes.first()?, *nodes.last()?);
    let tol = 1e-12 * (1.0 + last.abs().max(first.abs()));
    if !(x >= first - tol && x <= last + tol) {
        return None;
    }
    if n == 1 {
        return Some([(0, 1.0), (0, 0.0)]);
    }
    let x = x.clamp(first, last);
    let i = nodes.partition_point(|&v| v <= x).clamp(1, n - 1) - 1;
    let f = if nodes[i + 1] > nodes[i] { (x - nodes[i]) / (nodes[i + 1] - nodes[i]) } else { 0.0 };
    Some([(i, 1.0 - f), (i + 1, f)])
}

/// Albedo interpolation variable.
fn s_of(albedo: f64) -> f64 {
    (1.0 - albedo).max(0.0).sqrt()
}

impl MsLobesTable {
    /// Loads a table; with `needs` = the (albedo, g) pairs of the media to render, only the slices
    /// bracketing them are decompressed.
    pub fn open(path: &Path, needs: Option<&[(f64, f64)]>) -> Result<Self, LobesReadError> {
        let r = crate::container::VtabReader::open(path)
            .map_err(|source| LobesReadError::Container { path: path.to_path_buf(), source })?;
        Self::from_reader(r, path, needs)
    }

    /// [`Self::open`] on an open reader (e.g. made from bytes); `path` names it in messages.
    pub fn from_reader(
        r: crate::container::VtabReader,
        path: &Path,
        needs: Option<&[(f64, f64)]>,
    ) -> Result<Self, LobesReadError> {
        let layout = |m: String| LobesReadError::Layout(format!("{}: {m}", path.display()));
        let container = |source| LobesReadError::Container { path: path.to_path_buf(), source };
        let (mut r, def) = crate::tables::check_kind(r, (MsLobesRaw::KIND, super::KIND_SCHEMA_VERSION), layout)?;
        let TableDef::MsLobes(def) = def else {
            return Err(layout("its stored definition is not a readable MsLobes definition".into()));
        };
        let h = r.header().clone();
        let mut table = Self::from_arrays(&def, &h.arrays, &[]).map_err(layout)?;
        let mut want: BTreeSet<(usize, usize)> = BTreeSet::new();
        match needs {
            None => {
                for gi in 0..table.gs.len() {
                    want.extend((0..table.albedos.len()).map(|ai| (gi, ai)));
                }
            }
            Some(list) => {
                for &(albedo, g) in list {
                    let (gw, aw) = table.weights(albedo, g).map_err(|e| layout(e.to_string()))?;
                    for (gi, wg) in gw {
                        for &(ai, wa) in &aw {
                            if wg > 0.0 && wa > 0.0 {
                                want.insert((gi, ai));
                            }
                        }
                    }
                }
            }
        }
        let index = |name: &str| {
            h.arrays.iter().position(|a| a.name == name).ok_or_else(|| layout(format!("lacks the {name} array")))
        };
        let (di, ii) = (index("double")?, index("inside")?);
        let gis: BTreeSet<usize> = want.iter().map(|w| w.0).collect();
        for &gi in &gis {
            table.double.insert(gi, r.read_slice(di, gi as u64).map_err(container)?.to_f64());
        }
        let inside = r.read_array(ii).map_err(container)?.to_f64();
        let k = def.max_order as usize;
        table.inside = inside.chunks(k.max(1)).map(<[f64]>::to_vec).collect();
        for &(gi, ai) in &want {
            let t = index(&format!("total_g{gi}"))?;
            let d = index(&format!("density_g{gi}"))?;
            table.total.insert((gi, ai), r.read_slice(t, ai as u64).map_err(container)?.to_f64());
            table.density.insert((gi, ai), r.read_slice(d, ai as u64).map_err(container)?.to_f64());
        }
        table.check_sizes().map_err(layout)?;
        Ok(table)
    }

    /// A table from generated arrays (all slices), or only its layout when `values` is empty.
    pub fn from_arrays(def: &MsLobes, descs: &[ArrayDesc], values: &[ArrayValues]) -> Result<Self, String> {
        let want: Vec<String> = def.descs().into_iter().map(|d| d.name).collect();
        let names: Vec<&str> = descs.iter().map(|d| d.name.as_str()).collect();
        if names != want {
            return Err(format!("unexpected MsLobes arrays {names:?}; expected {want:?}"));
        }
        for (d, e) in descs.iter().zip(def.descs()) {
            if d.shape() != e.shape() {
                return Err(format!("array {} has shape {:?}, expected {:?}", d.name, d.shape(), e.shape()));
            }
        }
        let mut table = MsLobesTable {
            gs: def.g_values(),
            albedos: def.albedo_values(),
            s_nodes: def.albedo_values().iter().rev().map(|&a| s_of(a)).collect(),
            rho: def.rho_axis(),
            z: def.z_axis(),
            edges: {
                let (r, z) = (def.rho_axis(), def.z_axis());
                (r.edge(r.bins), z.edge(0), z.edge(z.bins))
            },
            theta_bins: def.theta_bins as usize,
            phi_nodes: def.phi_nodes(),
            lobe: def.lobe,
            total: HashMap::new(),
            density: HashMap::new(),
            double: HashMap::new(),
            inside: Vec::new(),
        };
        if values.is_empty() {
            return Ok(table);
        }
        if values.len() != descs.len() {
            return Err(format!("{} arrays of values for {} descriptions", values.len(), descs.len()));
        }
        let ng = table.gs.len();
        let na = table.albedos.len();
        let cells = table.rho.bins * table.z.bins;
        let lobe_len = cells * table.theta_bins * table.phi_nodes;
        for gi in 0..ng {
            let t = values[2 * gi].to_f64();
            let d = values[2 * gi + 1].to_f64();
            for ai in 0..na {
                table.total.insert((gi, ai), t.get(ai * lobe_len..(ai + 1) * lobe_len).unwrap_or(&[]).to_vec());
                table.density.insert((gi, ai), d.get(ai * cells..(ai + 1) * cells).unwrap_or(&[]).to_vec());
            }
        }
        let double = values[2 * ng].to_f64();
        for gi in 0..ng {
            table.double.insert(gi, double.get(gi * lobe_len..(gi + 1) * lobe_len).unwrap_or(&[]).to_vec());
        }
        let k = def.max_order as usize;
        table.inside = values[2 * ng + 1].to_f64().chunks(k.max(1)).map(<[f64]>::to_vec).collect();
        table.check_sizes()?;
        Ok(table)
    }

    fn check_sizes(&self) -> Result<(), String> {
        let cells = self.rho.bins * self.z.bins;
        let lobe_len = cells * self.theta_bins * self.phi_nodes;
        let ok = self.total.values().all(|v| v.len() == lobe_len)
            && self.double.values().all(|v| v.len() == lobe_len)
            && self.density.values().all(|v| v.len() == cells);
        if ok { Ok(()) } else { Err("a slice has the wrong number of values".into()) }
    }

    /// The g slices.
    pub fn g_values(&self) -> &[f64] {
        &self.gs
    }

    /// The albedo nodes.
    pub fn albedo_values(&self) -> &[f64] {
        &self.albedos
    }

    /// Whether `g` is a g slice and every channel albedo an albedo node (to the definition's merge
    /// tolerance, [`super::NODE_TOLERANCE`]): a medium this table looks up without interpolating.
    pub fn holds(&self, albedo: &[f64], g: f64) -> bool {
        let node = |nodes: &[f64], x: f64| nodes.iter().any(|&v| (v - x).abs() <= super::NODE_TOLERANCE);
        node(&self.gs, g) && albedo.iter().all(|&a| node(&self.albedos, a))
    }

    /// Fraction of the order-`k` collisions inside the grid for g slice `gi` (`k ≥ 1`).
    pub fn inside_fraction(&self, gi: usize, k: usize) -> Option<f64> {
        self.inside.get(gi)?.get(k.checked_sub(1)?).copied()
    }

    /// Lobe nodes per cell: (θ nodes, φ nodes; 1 for a symmetric table).
    pub fn lobe_nodes(&self) -> (usize, usize) {
        (self.theta_bins, self.phi_nodes)
    }

    /// Number of (g, albedo) slices loaded.
    pub fn loaded_slices(&self) -> usize {
        self.total.len()
    }

    /// Interpolation weights over g slices and albedo nodes.
    #[allow(clippy::type_complexity)]
    pub(super) fn weights(
        &self,
        albedo: f64,
        g: f64,
    ) -> Result<(Vec<(usize, f64)>, Vec<(usize, f64)>), LobeQueryError> {
        if !(0.0..=1.0).contains(&albedo) {
            return Err(LobeQueryError::Invalid(format!("albedo = {albedo} is outside [0, 1]")));
        }
        let gw = self.g_weights(g)?;
        // Nodes in s = √(1 − α) increase as α decreases: bracket on the reversed list.
        let n = self.albedos.len();
        let aw = bracket(&self.s_nodes, s_of(albedo)).ok_or_else(|| LobeQueryError::AlbedoOutOfRange {
            albedo,
            min: self.albedos.first().copied().unwrap_or(f64::NAN),
            max: self.albedos.last().copied().unwrap_or(f64::NAN),
        })?;
        Ok((gw, aw.into_iter().map(|(i, w)| (n - 1 - i, w)).collect()))
    }

    /// Interpolation weights over the g slices.
    fn g_weights(&self, g: f64) -> Result<Vec<(usize, f64)>, LobeQueryError> {
        let gw = bracket(&self.gs, g).ok_or_else(|| LobeQueryError::GOutOfRange {
            g,
            min: self.gs.first().copied().unwrap_or(f64::NAN),
            max: self.gs.last().copied().unwrap_or(f64::NAN),
        })?;
        Ok(gw.into_iter().collect())
    }

    /// The error for a missing `(g, albedo)` slice (or the `E_2` of a g slice, `ai = None`).
    pub(super) fn not_loaded(&self, gi: usize, ai: Option<usize>) -> LobeQueryError {
        LobeQueryError::NotLoaded(match ai {
            Some(ai) => format!("slice (albedo {}, g {})", self.albedos[ai], self.gs[gi]),
            None => format!("g slice {}", self.gs[gi]),
        })
    }

    /// The stored lobes at a canonical point (σ_t = 1): `total` = `Σ_{k≥2} α^k E_k`, `double` = `α² E_2`.
    pub fn lobe(&self, q: &LobeQuery) -> Result<LobeValue, LobeQueryError> {
        let (gw, aw) = self.weights(q.albedo, q.g)?;
        let at = self.locate(q)?;
        let mut out = LobeValue { total: 0.0, double: q.albedo * q.albedo * self.e2_at(&gw, &at)? };
        for &(gi, wg) in gw.iter().filter(|w| w.1 > 0.0) {
            for &(ai, wa) in aw.iter().filter(|w| w.1 > 0.0) {
                let t = self.total.get(&(gi, ai)).ok_or_else(|| self.not_loaded(gi, Some(ai)))?;
                out.total += wg * wa * at.sample(t, self.theta_bins * self.phi_nodes);
            }
        }
        out.total *= at.decay(decay_rate(q.albedo, q.g));
        // Interpolating in albedo can leave a sliver of double above total when the two nodes differ a
        // lot; both are non-negative by construction.
        out.total = out.total.max(0.0);
        out.double = out.double.max(0.0);
        Ok(out)
    }

    /// `E_2` alone (no albedo factor) at a canonical point; `q.albedo` is ignored.
    pub fn double_lobe(&self, q: &LobeQuery) -> Result<f64, LobeQueryError> {
        let gw = self.g_weights(q.g)?;
        let at = self.locate(q)?;
        self.e2_at(&gw, &at)
    }

    fn e2_at(&self, gw: &[(usize, f64)], at: &Located) -> Result<f64, LobeQueryError> {
        let mut acc = 0.0;
        for &(gi, wg) in gw.iter().filter(|w| w.1 > 0.0) {
            let e2 = self.double.get(&gi).ok_or_else(|| self.not_loaded(gi, None))?;
            acc += wg * at.sample(e2, self.theta_bins * self.phi_nodes);
        }
        Ok(acc * at.decay(decay_rate(0.0, 0.0)))
    }

    /// Checks a query's coordinates and finds its interpolation weights.
    pub(super) fn locate(&self, q: &LobeQuery) -> Result<Located, LobeQueryError> {
        for (name, v) in [("rho", q.rho), ("z", q.z), ("theta", q.theta), ("phi", q.phi), ("albedo", q.albedo)] {
            if !v.is_finite() {
                return Err(LobeQueryError::Invalid(format!("{name} = {v} is not finite")));
            }
        }
        if q.rho < 0.0 {
            return Err(LobeQueryError::Invalid(format!("rho = {} is negative", q.rho)));
        }
        if !(0.0..=PI).contains(&q.theta) || !(0.0..=PI).contains(&q.phi) {
            return Err(LobeQueryError::Invalid(format!("theta = {} and phi = {} must lie in [0, π]", q.theta, q.phi)));
        }
        // Nearest grid point and the outward decay.
        let rho_b = q.rho.min(self.edges.0);
        let z_b = q.z.clamp(self.edges.1, self.edges.2);
        Ok(Located {
            r: (q.rho * q.rho + q.z * q.z).sqrt(),
            r_b: (rho_b * rho_b + z_b * z_b).sqrt(),
            spatial: self.spatial_weights(rho_b, z_b),
            angular: self.angular_weights(q.theta, q.phi),
        })
    }

    /// Bilinear weights over cell centres (flat beyond the first / last centre).
    fn spatial_weights(&self, rho: f64, z: f64) -> [(usize, f64); 4] {
        let axis_w = |axis: &GradedAxis, x: f64| -> [(usize, f64); 2] {
            let c = (axis.coordinate(x) - 0.5).clamp(0.0, (axis.bins - 1) as f64);
            let i = (c as usize).min(axis.bins.saturating_sub(2)); // c ≥ 0: truncation is floor
            let f = (c - i as f64).clamp(0.0, 1.0);
            if axis.bins == 1 { [(0, 1.0), (0, 0.0)] } else { [(i, 1.0 - f), (i + 1, f)] }
        };
        let (wr, wz) = (axis_w(&self.rho, rho), axis_w(&self.z, z));
        let mut out = [(0, 0.0); 4];
        for (k, (iz, a)) in wz.into_iter().enumerate() {
            for (l, (ir, b)) in wr.into_iter().enumerate() {
                out[2 * k + l] = (iz * self.rho.bins + ir, a * b);
            }
        }
        out
    }

    /// Linear weights over θ (and φ) nodes, as offsets within a cell's lobe.
    fn angular_weights(&self, theta: f64, phi: f64) -> [(usize, f64); 4] {
        let lin = |x: f64, n: usize| -> [(usize, f64); 2] {
            let c = (x / PI * (n - 1) as f64).clamp(0.0, (n - 1) as f64);
            let i = (c as usize).min(n - 2); // c ≥ 0: truncation is floor
            let f = c - i as f64;
            [(i, 1.0 - f), (i + 1, f)]
        };
        let wt = lin(theta, self.theta_bins);
        if self.lobe == LobeKind::Symmetric || self.phi_nodes < 2 {
            return [wt[0], wt[1], (0, 0.0), (0, 0.0)];
        }
        let wp = lin(phi, self.phi_nodes);
        let mut out = [(0, 0.0); 4];
        for (k, (it, a)) in wt.into_iter().enumerate() {
            for (l, (ip, b)) in wp.into_iter().enumerate() {
                out[2 * k + l] = (it * self.phi_nodes + ip, a * b);
            }
        }
        out
    }

    /// The radiance scattered at `x` toward `omega` per unit length and per unit power of a beam
    /// leaving `origin` along `direction`, in a medium channel (wang2018 Eq. 7 for one volume sample):
    /// the canonical lobe at `(σ_t ρ, σ_t z)` times `σ_t³`.
    pub fn radiance(
        &self,
        medium: &MediumChannel,
        beam: ([f64; 3], [f64; 3]),
        x: [f64; 3],
        omega: [f64; 3],
    ) -> Result<LobeValue, LobeQueryError> {
        let (rho, z, theta, phi) = beam_coordinates(self.lobe, medium.sigma_t, beam, x, omega)?;
        let q = LobeQuery { albedo: medium.albedo, g: medium.g, rho, z, theta, phi };
        scale_cubed(self.lobe(&q)?, medium.sigma_t)
    }

    /// The angle-integrated density `Σ_{k≥2} α^k ψ_k` at canonical `(ρ, z)` (interpolated like [`Self::lobe`]).
    pub fn density(&self, albedo: f64, g: f64, rho: f64, z: f64) -> Result<f64, LobeQueryError> {
        let (gw, aw) = self.weights(albedo, g)?;
        let rho_b = rho.min(self.edges.0);
        let z_b = z.clamp(self.edges.1, self.edges.2);
        let (r, r_b) = ((rho * rho + z * z).sqrt(), (rho_b * rho_b + z_b * z_b).sqrt());
        let spatial = self.spatial_weights(rho_b, z_b);
        let mut acc = 0.0;
        for &(gi, wg) in gw.iter().filter(|w| w.1 > 0.0) {
            for &(ai, wa) in aw.iter().filter(|w| w.1 > 0.0) {
                let v = self.density.get(&(gi, ai)).ok_or_else(|| self.not_loaded(gi, Some(ai)))?;
                acc += wg * wa * spatial.iter().filter(|w| w.1 > 0.0).map(|&(c, w)| w * v[c]).sum::<f64>();
            }
        }
        let decay = if r > r_b && r_b > 0.0 { (r_b / r) * (-decay_rate(albedo, g) * (r - r_b)).exp() } else { 1.0 };
        Ok(acc * decay)
    }
}

/// The canonical look-up coordinates `(σ_t ρ, σ_t z, θ, φ)` of the point `x` and direction `omega`
/// relative to a beam (origin, direction) in a medium of extinction `sigma_t` (φ is 0 for symmetric
/// lobes). Refuses non-finite or zero vectors and a bad `sigma_t`.
pub(super) fn beam_coordinates(
    lobe: LobeKind,
    sigma_t: f64,
    beam: ([f64; 3], [f64; 3]),
    x: [f64; 3],
    omega: [f64; 3],
) -> Result<(f64, f64, f64, f64), LobeQueryError> {
    let (origin, direction) = beam;
    let st = sigma_t;
    if !(st.is_finite() && st > 0.0) {
        return Err(LobeQueryError::Invalid(format!("sigma_t = {st} must be finite and > 0")));
    }
    let unit = |v: [f64; 3], name: &str| -> Result<DVec3, LobeQueryError> {
        let v = DVec3::from_array(v);
        let n = v.length();
        if !(n.is_finite() && n > 0.0) {
            return Err(LobeQueryError::Invalid(format!("{name} must be a finite non-zero vector")));
        }
        Ok(v / n)
    };
    let d = unit(direction, "the beam direction")?;
    let w = unit(omega, "omega")?;
    let p = DVec3::from_array(x) - DVec3::from_array(origin);
    if !p.is_finite() {
        return Err(LobeQueryError::Invalid("the point and the beam origin must be finite".into()));
    }
    let z = p.dot(d);
    let perp = p - z * d;
    let rho = perp.length();
    let r = p.length();
    let (a, e1) = if r > 0.0 {
        let a = p / r;
        // φ's reference direction only matters to a φ-resolved lobe.
        let e1 = if lobe != LobeKind::Full {
            DVec3::ZERO
        } else if rho > 0.0 {
            let rh = perp / rho;
            (z * rh - rho * d) / r
        } else {
            crate::physics::lobe_transport::lobe_frame(DVec3::Z).1
        };
        (a, e1)
    } else {
        (d, DVec3::ZERO)
    };
    let theta = a.dot(w).clamp(-1.0, 1.0).acos();
    let phi = if lobe == LobeKind::Full && e1.dot(e1) > 0.0 {
        let e2 = a.cross(e1);
        w.dot(e2).abs().atan2(w.dot(e1))
    } else {
        0.0
    };
    Ok((st * rho, st * z, theta, phi))
}

/// A canonical lobe value scaled to a medium of extinction `sigma_t` (`× σ_t³`); refuses an overflow.
pub(super) fn scale_cubed(v: LobeValue, sigma_t: f64) -> Result<LobeValue, LobeQueryError> {
    let s3 = sigma_t * sigma_t * sigma_t;
    let scale = |x: f64| if x == 0.0 { 0.0 } else { x * s3 };
    let out = LobeValue { total: scale(v.total), double: scale(v.double) };
    if out.total.is_finite() && out.double.is_finite() { Ok(out) } else { Err(LobeQueryError::Overflow { sigma_t }) }
}
