//! `ZhResponse`: zonal-harmonic impulse-response tables of dubouchet2019 Sec. 4–5 (Eqs. 14–15, the
//! bounce recursion of Sec. 5.1), the table the lightmap baker consumes.
//!
//! **Input → output.** A validated [`ZhResponse`] definition (emitter profiles, HG g list, bounce count
//! `B`, ZH order `N`, distance axis, quadrature size) → per emitter profile `p` three arrays, each
//! chunked per g slice so a consumer decompresses only the g it needs:
//! - `{p}_direct[g, d]` — the unscattered irradiance per unit `max(0, n·a)` of a unit emitter in the
//!   canonical medium: `e^{−d}/d²` (point), `e^{−D}` (directional). Stored as irradiance, never as a lobe
//!   (the point emitter's direct light is a delta);
//! - `{p}_zh[g, b, d, l]` — ZH coefficients (about the light axis `a`) of the radiance arriving after
//!   exactly `b = 1..=B` scattering events, so a consumer can pick orders and weight them by `α^b`;
//! - `{p}_zh_sum[g, d, l]` — their sum over `b`, the single combined table of Sec. 5.1 (conservative media).
//!
//! - `{p}_tail[g, albedo, d, l]` (with `tail_closure`) — the ZH (`l = 0, 1`) of all orders `b > B`,
//!   `Σ_{b>B} α^b c^{(b)}`, on the albedo axis [`TAIL_ALBEDOS`] (P1/diffusion closure sourced by bounce `B`,
//!   [`crate::physics::zh_transport::tail`]), so albedo-1 media in thick regions are not silently dark.
//!
//! **Canonical medium and units.** `σ_s = 1`, `σ_a = 0`, lengths in mean free paths. A point emitter has
//! intensity 1 W/sr at distance `d`; a directional emitter delivers irradiance 1 W/m² at the boundary of
//! the half-space medium, the receiver lying `D` below it. The receiver irradiance is
//! `E = ∫ L(ω) max(0, n·ω) dω`. Everything physical (σ-ratio remapping, albedo weights, g interpolation,
//! similarity, back-scatter shift) happens at query time in [`ZhResponseTable`]; the transport itself is
//! [`crate::physics::zh_transport`] (deterministic quadrature; derivations in its module doc and in
//! `docs/design/zh-response.md`).
//!
//! **Errors.** [`ZhResponse::estimate_errors`] judges the tables against the independent random walk
//! [`crate::reference::walk`] (single scattering and the sum of orders `≤ B` on a receiver facing the
//! light); the report ladder varies the distance resolution and the quadrature size.

mod errors;
mod table;
#[cfg(test)]
mod tests;

use std::collections::HashMap;
use std::sync::{Mutex, OnceLock};

use serde::{Deserialize, Serialize};

pub use errors::{REPORT_DISTANCES, REPORT_WALK_PHOTONS, SIDECAR_WALK_PHOTONS, WALK_ALBEDO, walk_reference};
pub use table::{
    Emitter, Irradiance, QueryError, QueryOptions, Radiance, Receiver, ZhReadError, ZhResponseTable, array_names,
};

use super::phase_hg::{Element, GValues};
use super::{CheckError, ErrorEstimate, FieldIssue, GenStats, GenerateError, Generated, Progress, to_element};
use crate::container::{ArrayDesc, Axis};
use crate::physics::medium::HomogeneousMedium;
use crate::physics::zh_transport::{self, EmitterKind, ResponseConfig, tail};
use crate::reference::walk;

/// Version of the array layout below.
pub const KIND_SCHEMA_VERSION: u32 = 1;
/// Version of the numerics; bump when values change so caches rebuild.
pub const GENERATOR_VERSION: &str = "zh_response/1";

/// Most g slices one table may hold.
pub const MAX_G: usize = 64;
/// Largest `|g|` accepted (an order-11 ZH cannot represent sharper lobes anyway).
pub const MAX_ABS_G: f64 = 0.99;
/// Highest ZH order `N`.
pub const MAX_ORDER: u32 = 32;
/// Most bounces `B`.
pub const MAX_BOUNCES: u32 = 64;

/// Albedo nodes of the tail arrays: dense toward 1, where the tail grows fastest.
pub const TAIL_ALBEDOS: [f64; 12] = [0.0, 0.3, 0.5, 0.7, 0.8, 0.9, 0.95, 0.98, 0.99, 0.995, 0.999, 1.0];

/// Which canonical emitter a set of arrays is for (dubouchet2019 Fig. 4).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize, schemars::JsonSchema)]
pub enum EmitterProfile {
    /// Isotropic point light, intensity 1 W/sr, infinite medium; axis = distance to the light.
    Point,
    /// Collimated light of irradiance 1 W/m² entering a half-space; axis = depth below the boundary.
    Directional,
    /// Differential cosine-weighted patch (intensity 1 W/sr along its normal), infinite medium; axes =
    /// distance and the angle θ between the patch normal and the direction from the patch to the receiver.
    Area,
}

impl EmitterProfile {
    /// Prefix of this profile's array names.
    pub fn prefix(self) -> &'static str {
        match self {
            EmitterProfile::Point => "point",
            EmitterProfile::Directional => "directional",
            EmitterProfile::Area => "area",
        }
    }

    /// The transport module's emitter for the axially symmetric profiles (`None` for `Area`).
    pub fn transport(self) -> Option<EmitterKind> {
        match self {
            EmitterProfile::Point => Some(EmitterKind::Point),
            EmitterProfile::Directional => Some(EmitterKind::Directional),
            EmitterProfile::Area => None,
        }
    }

    /// The axially symmetric profiles (one ZH lobe about the light axis per bounce).
    pub const AXIAL: [EmitterProfile; 2] = [EmitterProfile::Point, EmitterProfile::Directional];
    /// All profiles.
    pub const ALL: [EmitterProfile; 3] = [EmitterProfile::Point, EmitterProfile::Directional, EmitterProfile::Area];
}

/// Spacing of the distance axis.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, schemars::JsonSchema)]
pub enum DistanceSpacing {
    /// Geometric: the same relative resolution near the light (single scattering ~1/d) and far away.
    Log,
    /// Uniform in distance.
    Linear,
}

crate::declare_params! {
    /// ZH impulse-response tables (dubouchet2019 Sec. 4–5): per emitter profile and HG g, the ZH
    /// coefficients of the incident radiance after each bounce, their sum, and the direct term.
    raw ZhResponseRaw => resolved ZhResponse, kind "ZhResponse" {
        /// Emitter profiles to tabulate, each at most once: `[Point, Directional]`.
        emitters: Vec<EmitterProfile> = EmitterProfile::ALL.to_vec(), unit = "", range = "1 to 3 distinct of Point | Directional | Area";
        /// HG mean cosines of the slices: a strictly increasing list or a grid `(min, max, count)`.
        /// Queries interpolate between slices and refuse g outside the tabulated range.
        g: GValues = GValues::List(vec![-0.5, 0.0, 0.5]), unit = "dimensionless (mean cosine)", range = "each |g| <= 0.99; 1 to 64 values, strictly increasing";
        /// Scattering orders tabulated separately (b = 1 … bounces); orders beyond go to the tail closure.
        bounces: u32 = 10, unit = "scattering events", range = "1 to 64";
        /// ZH coefficients per lobe (bands l = 0 … zh_order − 1).
        zh_order: u32 = 11, unit = "bands", range = "1 to 32";
        /// Samples on the distance (point) / depth (directional) axis.
        distance_bins: u32 = 256, unit = "samples", range = "4 to 4096";
        /// First distance sample.
        distance_min: f64 = 1e-3, unit = "mean free paths", range = "1e-6 to 1, below distance_max";
        /// Last distance sample; beyond it lookups decay as e^{-Δd} (never clamped upward).
        distance_max: f64 = 64.0, unit = "mean free paths", range = "1 to 1000";
        /// Spacing of the distance axis: `Log` or `Linear`.
        distance_spacing: DistanceSpacing = DistanceSpacing::Log, unit = "", range = "Log | Linear";
        /// Area emitter: samples of the patch angle θ, uniform in [0, π].
        theta_bins: u32 = 8, unit = "samples", range = "2 to 64";
        /// Gauss nodes per panel of the graded quadrature, in both the receiver angle and along rays
        /// (12 changes bounce 1 by < 1e-6 and bounce 2 by < 1e-4 of c_0 when doubled). The area emitter's
        /// 3-D rule uses half of it per panel in ψ and along rays and 5/6 of it in azimuth.
        quadrature_nodes: u32 = 12, unit = "nodes per panel", range = "2 to 64";
        /// Back-scatter compensation of Sec. 5.2: scattered light is looked up for a receiver shifted
        /// this far along its normal (the direct term is not); 0 switches it off.
        backscatter_shift: f64 = 0.125, unit = "mean free paths", range = "0 (off) to 1";
        /// Tabulate the closure of the bounce series beyond `bounces` (orders b > B as a diffusion-
        /// transported population sourced by bounce B) on a 12-node albedo axis; queries add it.
        tail_closure: bool = true, unit = "", range = "true | false";
        /// Stored element type.
        element: Element = Element::F32, unit = "", range = "F32 | F64";
        /// zstd compression level.
        zstd_level: i32 = 9, unit = "", range = "1 to 19";
    }
}

impl ZhResponse {
    /// Range checks of every field.
    pub fn validate(&self) -> Vec<FieldIssue> {
        let mut issues = Vec::new();
        let mut issue = |field: &'static str, message: String, help: String| {
            issues.push(FieldIssue { field, message, help });
        };
        if self.emitters.is_empty() {
            issue("emitters", "emitters is empty".into(), "list at least one of Point, Directional".into());
        }
        let mut seen = std::collections::BTreeSet::new();
        for e in &self.emitters {
            if !seen.insert(*e) {
                issue("emitters", format!("{e:?} is listed twice"), "list each emitter profile once".into());
            }
        }
        let count_ok = match &self.g {
            GValues::List(v) => !v.is_empty() && v.len() <= MAX_G,
            GValues::Grid { count, .. } => (1..=MAX_G).contains(&(*count as usize)),
        };
        if !count_ok {
            issue("g", "the g list is empty or too long".into(), format!("give between 1 and {MAX_G} g values"));
        } else {
            let gs = self.g.values();
            if let Some(bad) = gs.iter().find(|g| !(g.is_finite() && g.abs() <= MAX_ABS_G)) {
                issue(
                    "g",
                    format!("g = {bad} is out of range"),
                    format!(
                        "each g must satisfy |g| <= {MAX_ABS_G} (order-{} ZH cannot resolve sharper lobes)",
                        self.zh_order
                    ),
                );
            }
            if gs.windows(2).any(|w| w[0] >= w[1]) || gs.iter().any(|g| g.is_nan()) {
                issue("g", "g values must be strictly increasing".into(), "sort the list and remove duplicates".into());
            }
        }
        if !(1..=MAX_BOUNCES).contains(&self.bounces) {
            issue("bounces", format!("bounces = {} is out of range", self.bounces), format!("use 1 to {MAX_BOUNCES}"));
        }
        if !(1..=MAX_ORDER).contains(&self.zh_order) {
            issue("zh_order", format!("zh_order = {} is out of range", self.zh_order), format!("use 1 to {MAX_ORDER}"));
        }
        if !(4..=4096).contains(&self.distance_bins) {
            issue(
                "distance_bins",
                format!("distance_bins = {} is out of range", self.distance_bins),
                "use 4 to 4096".into(),
            );
        }
        if !(1e-6..=1.0).contains(&self.distance_min) {
            issue(
                "distance_min",
                format!("distance_min = {} is out of range", self.distance_min),
                "use 1e-6 to 1 mean free paths".into(),
            );
        }
        if !(1.0..=1000.0).contains(&self.distance_max) {
            issue(
                "distance_max",
                format!("distance_max = {} is out of range", self.distance_max),
                "use 1 to 1000 mean free paths".into(),
            );
        }
        if self.distance_min >= self.distance_max {
            issue(
                "distance_min",
                format!("distance_min = {} is not below distance_max = {}", self.distance_min, self.distance_max),
                "distance_min must be smaller than distance_max".into(),
            );
        }
        if !(2..=64).contains(&self.theta_bins) {
            issue("theta_bins", format!("theta_bins = {} is out of range", self.theta_bins), "use 2 to 64".into());
        }
        if !(2..=64).contains(&self.quadrature_nodes) {
            issue(
                "quadrature_nodes",
                format!("quadrature_nodes = {} is out of range", self.quadrature_nodes),
                "use 2 to 64 Gauss nodes per panel (12 is converged to ~1e-4)".into(),
            );
        }
        if !(0.0..=1.0).contains(&self.backscatter_shift) {
            issue(
                "backscatter_shift",
                format!("backscatter_shift = {} is out of range", self.backscatter_shift),
                "use 0 (off) to 1 mean free path; the paper uses 0.125".into(),
            );
        }
        if !(1..=19).contains(&self.zstd_level) {
            issue("zstd_level", format!("zstd_level = {} is out of range", self.zstd_level), "use 1 to 19".into());
        }
        issues
    }

    /// Arrays per axially symmetric emitter profile: direct, zh, zh_sum, and tail when `tail_closure`
    /// (the area profile has direct, zh and axis).
    pub fn arrays_per_emitter(&self) -> usize {
        3 + usize::from(self.tail_closure)
    }

    /// The patch angles of the area emitter (radians, uniform in `[0, π]`).
    pub fn thetas(&self) -> Vec<f64> {
        let n = self.theta_bins.max(2);
        (0..n).map(|j| std::f64::consts::PI * f64::from(j) / f64::from(n - 1)).collect()
    }

    pub(crate) fn area_config(&self, g: f64) -> zh_transport::area::AreaConfig {
        let mut cfg = zh_transport::area::AreaConfig::new(g, self.distance_axis().values_vec(), self.thetas());
        cfg.order = self.zh_order as usize;
        cfg.bounces = self.bounces as usize;
        let q = self.quadrature_nodes as usize;
        cfg.psi_nodes = (q / 2).max(1);
        cfg.t_nodes = (q / 2).max(1);
        cfg.phi_nodes = (5 * q / 6).max(1);
        cfg
    }

    fn n_g(&self) -> u128 {
        match &self.g {
            GValues::List(v) => v.len() as u128,
            GValues::Grid { count, .. } => u128::from(*count),
        }
    }

    /// Peak memory: the f64 responses of one slice while computing, plus every stored value three
    /// times (f64 working copy, element copy, compressed output bounded by raw).
    pub fn estimated_bytes(&self) -> u128 {
        let lobes = u128::from(self.bounces) + 1 + if self.tail_closure { TAIL_ALBEDOS.len() as u128 } else { 0 };
        let area = self.emitters.contains(&EmitterProfile::Area);
        let axial = self.emitters.len() as u128 - u128::from(area);
        let lobe_bytes = u128::from(self.distance_bins) * u128::from(self.zh_order + 1);
        let per_g = axial * lobes * lobe_bytes + u128::from(area) * lobes * lobe_bytes * u128::from(self.theta_bins);
        self.n_g() * per_g * 24 + per_g * 8
    }

    /// One unit per bounce of every (g, axial emitter) response; an area response counts as 8 axial
    /// ones (its 3-D quadrature), reported when it finishes.
    pub fn work_units(&self) -> u64 {
        (self.n_g() as u64) * self.emitters.iter().map(|e| self.units_of(*e)).sum::<u64>()
    }

    fn units_of(&self, e: EmitterProfile) -> u64 {
        match e {
            EmitterProfile::Area => 8 * u64::from(self.bounces),
            _ => u64::from(self.bounces),
        }
    }

    /// The distance axis (its values are exactly the distances the transport is computed at).
    pub fn distance_axis(&self) -> Axis {
        let n = u64::from(self.distance_bins);
        match self.distance_spacing {
            DistanceSpacing::Log => Axis::log("d", "mean free paths", self.distance_min, self.distance_max, n),
            DistanceSpacing::Linear => Axis::linear("d", "mean free paths", self.distance_min, self.distance_max, n),
        }
    }

    fn transport_config(&self, g: f64) -> ResponseConfig {
        let mut cfg = ResponseConfig::new(g, self.distance_axis().values_vec());
        cfg.order = self.zh_order as usize;
        cfg.bounces = self.bounces as usize;
        cfg.mu_nodes = self.quadrature_nodes as usize;
        cfg.t_nodes = self.quadrature_nodes as usize;
        cfg
    }

    fn descs(&self) -> Vec<ArrayDesc> {
        let g_axis = Axis::explicit("g", "", self.g.values());
        let b_axis = Axis::linear("b", "scattering events", 1.0, f64::from(self.bounces), u64::from(self.bounces));
        let d_axis = self.distance_axis();
        let l_axis =
            Axis::linear("l", "band", 0.0, f64::from(self.zh_order.saturating_sub(1)), u64::from(self.zh_order));
        let desc = |name: String, description: String, unit: &str, axes: Vec<Axis>| ArrayDesc {
            name,
            description,
            unit: unit.into(),
            element: self.element.into(),
            axes,
            quantization: None,
        };
        let mut out = Vec::new();
        for e in &self.emitters {
            let p = e.prefix();
            if *e == EmitterProfile::Area {
                let t_axis = Axis::explicit("theta", "rad", self.thetas());
                out.push(desc(
                    "area_direct".into(),
                    "unscattered irradiance per unit max(0, n.a) of a unit area emitter, canonical medium: e^-d/d^2 max(0, cos theta)".into(),
                    "W/m^2",
                    vec![g_axis.clone(), d_axis.clone(), t_axis.clone()],
                ));
                out.push(desc(
                    "area_zh".into(),
                    "ZH coefficients about the best-fit axis (area_axis) of the radiance after exactly b scattering events (area emitter)".into(),
                    "W/(m^2 sr)",
                    vec![g_axis.clone(), b_axis.clone(), d_axis.clone(), t_axis.clone(), l_axis.clone()],
                ));
                out.push(desc(
                    "area_axis".into(),
                    "angle of the best-fit ZH axis (Brent) from the light axis toward the patch normal's tangential part".into(),
                    "rad",
                    vec![g_axis.clone(), b_axis.clone(), d_axis.clone(), t_axis],
                ));
                continue;
            }
            let direct = match e {
                EmitterProfile::Area => "e^-d/d^2 max(0, cos theta)",
                EmitterProfile::Point => "e^-d/d^2",
                EmitterProfile::Directional => "e^-D",
            };
            out.push(desc(
                format!("{p}_direct"),
                format!(
                    "unscattered irradiance per unit max(0, n.a) of a unit {p} emitter, canonical medium: {direct}"
                ),
                "W/m^2",
                vec![g_axis.clone(), d_axis.clone()],
            ));
            out.push(desc(
                format!("{p}_zh"),
                format!("ZH coefficients about the light axis of the radiance after exactly b scattering events ({p} emitter)"),
                "W/(m^2 sr)",
                vec![g_axis.clone(), b_axis.clone(), d_axis.clone(), l_axis.clone()],
            ));
            out.push(desc(
                format!("{p}_zh_sum"),
                format!("sum over b = 1..B of {p}_zh: the combined table of dubouchet2019 Sec. 5.1 (albedo 1)"),
                "W/(m^2 sr)",
                vec![g_axis.clone(), d_axis.clone(), l_axis.clone()],
            ));
            if self.tail_closure {
                out.push(desc(
                    format!("{p}_tail"),
                    format!(
                        "ZH coefficients (l = 0, 1) about the light axis of all orders b > B weighted by albedo^b ({p} emitter; P1 closure)"
                    ),
                    "W/(m^2 sr)",
                    vec![
                        g_axis.clone(),
                        Axis::explicit("albedo", "", TAIL_ALBEDOS.to_vec()),
                        d_axis.clone(),
                        Axis::linear("l", "band", 0.0, 1.0, 2),
                    ],
                ));
            }
        }
        out
    }

    /// Runs the generator: per g slice and emitter the bounce recursion of
    /// [`zh_transport::compute_with_progress`] (parallel over distances, collected in order: the bytes
    /// do not depend on the thread count).
    pub fn generate(&self, _key: &[u8; 32], progress: Progress<'_>) -> Result<Generated, GenerateError> {
        let parts = (0..self.unit_count()).map(|u| self.generate_unit(u, progress)).collect::<Result<Vec<_>, _>>()?;
        self.assemble(parts)
    }

    /// Work units of a sharded compile (`crate::shard`): one per (emitter, g slice), emitter-major.
    pub fn unit_count(&self) -> usize {
        self.emitters.len() * self.g.values().len()
    }

    /// [`ZhResponse::generate_unit`] and, as unit [`ZhResponse::unit_count`], the check's references.
    pub fn shard_unit(&self, unit: usize, key: &[u8; 32], progress: Progress<'_>) -> Result<ZhPart, GenerateError> {
        if unit == self.unit_count() {
            return self.check_references(key).map(ZhPart::Check).map_err(GenerateError::Check);
        }
        self.generate_unit(unit, progress)
    }

    /// The transport of one (emitter, g slice) ([`ZhResponse::unit_count`]): deterministic quadrature,
    /// the same bits wherever it runs.
    pub fn generate_unit(&self, unit: usize, progress: Progress<'_>) -> Result<ZhPart, GenerateError> {
        let gs = self.g.values();
        let (Some(e), Some(&g)) = (self.emitters.get(unit / gs.len().max(1)), gs.get(unit % gs.len().max(1))) else {
            return Err(GenerateError::Layout(format!("work unit {unit} out of range ({})", self.unit_count())));
        };
        match e.transport() {
            Some(kind) => zh_transport::compute_with_progress(kind, &self.transport_config(g), &|| progress(1))
                .map(ZhPart::Response)
                .map_err(|m| GenerateError::Layout(format!("{} transport for g = {g}: {m}", e.prefix()))),
            None => {
                let r = zh_transport::area::compute(&self.area_config(g))
                    .map_err(|m| GenerateError::Layout(format!("area transport for g = {g}: {m}")))?;
                progress(self.units_of(EmitterProfile::Area));
                let (mut zh, mut axis) = (Vec::new(), Vec::new());
                for rows in &r.bounces {
                    for row in rows {
                        for entry in row {
                            zh.extend_from_slice(&entry.zh);
                            axis.push(entry.theta_fit);
                        }
                    }
                }
                Ok(ZhPart::Area { direct: r.direct.iter().flatten().copied().collect(), zh, axis })
            }
        }
    }

    /// The table from its units in unit order: what [`ZhResponse::generate`] does after the transport.
    pub fn assemble(&self, parts: Vec<ZhPart>) -> Result<Generated, GenerateError> {
        if parts.len() != self.unit_count() {
            return Err(GenerateError::Layout(format!(
                "{} units given for a table of {}",
                parts.len(),
                self.unit_count()
            )));
        }
        let descs = self.descs();
        let gs = self.g.values();
        let help = "a ZH coefficient overflowed the element type; use element: F64";
        let mut values = Vec::with_capacity(descs.len());
        let mut discarded = 0u64;
        let mut tail_energy = Vec::new();
        let mut at = 0;
        let mut parts = parts.into_iter();
        for e in &self.emitters {
            let mine: Vec<ZhPart> = parts.by_ref().take(gs.len()).collect();
            let Some(kind) = e.transport() else {
                let (mut direct, mut zh, mut axis) = (Vec::new(), Vec::new(), Vec::new());
                for part in mine {
                    let ZhPart::Area { direct: d, zh: z, axis: a } = part else {
                        return Err(GenerateError::Layout("an area emitter's unit holds a point response".into()));
                    };
                    direct.extend(d);
                    zh.extend(z);
                    axis.extend(a);
                }
                for v in [&mut direct, &mut zh, &mut axis] {
                    for x in v.iter_mut().filter(|x| !x.is_finite()) {
                        *x = 0.0;
                        discarded += 1;
                    }
                }
                values.push(to_element(&descs[at], direct, help)?);
                values.push(to_element(&descs[at + 1], zh, help)?);
                values.push(to_element(&descs[at + 2], axis, help)?);
                at += 3;
                continue;
            };
            let mut per_g = Vec::with_capacity(gs.len());
            for part in mine {
                match part {
                    ZhPart::Response(r) if r.kind == kind => per_g.push(r),
                    _ => {
                        return Err(GenerateError::Layout(format!(
                            "a {} unit holds another emitter's response",
                            e.prefix()
                        )));
                    }
                }
            }
            let direct: Vec<f64> = per_g.iter().flat_map(|r| r.direct.iter().copied()).collect();
            let mut zh = Vec::new();
            let mut sum = Vec::new();
            for r in &per_g {
                for rows in &r.bounces {
                    for row in rows {
                        zh.extend_from_slice(row);
                    }
                }
                for i in 0..r.distances.len() {
                    for l in 0..self.zh_order as usize {
                        sum.push(r.bounces.iter().map(|rows| rows[i][l]).sum::<f64>());
                    }
                }
            }
            for v in [&mut zh, &mut sum] {
                for x in v.iter_mut().filter(|x| !x.is_finite()) {
                    *x = 0.0;
                    discarded += 1;
                }
            }
            let k = self.arrays_per_emitter();
            values.push(to_element(&descs[at], direct, help)?);
            values.push(to_element(&descs[at + 1], zh, help)?);
            values.push(to_element(&descs[at + 2], sum, help)?);
            if self.tail_closure {
                let mut tail = Vec::new();
                for (r, &g) in per_g.iter().zip(&gs) {
                    for per_albedo in tail::tail_table(r, g, &TAIL_ALBEDOS) {
                        for c in per_albedo {
                            tail.extend_from_slice(&c);
                        }
                    }
                }
                for x in tail.iter_mut().filter(|x| !x.is_finite()) {
                    *x = 0.0;
                    discarded += 1;
                }
                values.push(to_element(&descs[at + 3], tail, help)?);
                for (r, &g) in per_g.iter().zip(&gs) {
                    for d in TAIL_REPORT_DISTANCES {
                        tail_energy.push((*e, g, d, tail::tail_energy_ratio(r, g, 1.0, d)));
                    }
                }
            }
            at += k;
        }
        let errors = tail_energy_estimates(&tail_energy);
        let stats = GenStats { nonfinite_discarded: discarded, samples: 0, errors };
        Ok(Generated { arrays: descs, values, stats })
    }
}

/// Distances (mean free paths) at which the sidecar reports the energy the tail adds.
pub const TAIL_REPORT_DISTANCES: [f64; 3] = [1.0, 4.0, 8.0];

/// "How much energy the tail adds" (issue 3): per emitter and distance, the largest ratio over the g
/// slices of the tail's fluence to that of the truncated series at albedo 1.
fn tail_energy_estimates(rows: &[(EmitterProfile, f64, f64, f64)]) -> Vec<ErrorEstimate> {
    let mut out = Vec::new();
    for profile in EmitterProfile::ALL {
        for d in TAIL_REPORT_DISTANCES {
            let worst = rows.iter().filter(|r| r.0 == profile && r.2 == d).map(|r| r.3).fold(f64::NAN, f64::max);
            if worst.is_nan() {
                continue;
            }
            out.push(ErrorEstimate {
                name: format!("tail_energy_ratio_{}_d{d}_albedo1", profile.prefix()),
                value: worst,
                how: "fluence of the tail closure / fluence of orders 1..=B at albedo 1 (largest over the g slices); \
                      the energy the closure adds, not an error"
                    .into(),
            });
        }
    }
    out
}

/// Rows of the stability matrix for `ZhResponse`: a small table at the extreme g = ±0.95 queried in
/// extreme media (albedo exactly 1, σ_a ≫ σ_s, σ_s → 0, very thick), at extreme distances (next to the
/// light, beyond the table, astronomically far) and on facing, grazing and back-facing receivers, with and
/// without similarity and back-scatter shift: every part finite and non-negative; vacuum leaves exactly
/// the analytic direct term.
pub fn stability_rows() -> Vec<crate::stability::Row> {
    use crate::stability::{Expect, Row};
    let row = |formula, input: String, value, expect| Row { kind: "ZhResponse", formula, input, value, expect };
    let def = ZhResponse {
        g: GValues::List(vec![-0.95, 0.0, 0.95]),
        bounces: 4,
        distance_bins: 16,
        quadrature_nodes: 3,
        element: Element::F64,
        ..ZhResponse::default()
    };
    let table = match def
        .generate(&[0; 32], &|_| {})
        .map_err(|e| e.to_string())
        .and_then(|g| ZhResponseTable::from_arrays(&def, &g.arrays, &g.values))
    {
        Ok(t) => t,
        Err(e) => return vec![row("generate", format!("g = ±0.95 table: {e}"), f64::NAN, Expect::Finite)],
    };
    let media = [
        ("albedo 1", 1.0, 0.0),
        ("sigma_a >> sigma_s", 1e-3, 1e3),
        ("sigma_s -> 0", 1e-300, 1.0),
        ("very thick", 1e6, 0.0),
    ];
    let mut v = Vec::new();
    for profile in EmitterProfile::ALL {
        for (name, sigma_s, sigma_a) in media {
            for g in [-0.95, 0.95 - 1e-12] {
                for d in [1e-150, 1e-9, 1.0, 1e3, 1e300] {
                    for cos_n in [1.0f64, 0.0, -1.0] {
                        let emitter = match profile {
                            EmitterProfile::Point => Emitter::Point { intensity: 1.0, position: [0.0, 0.0, d] },
                            EmitterProfile::Directional => {
                                Emitter::Directional { irradiance: 1.0, toward_light: [0.0, 0.0, 1.0], depth: d }
                            }
                            EmitterProfile::Area => {
                                Emitter::Area { intensity: 1.0, position: [0.0, 0.0, d], normal: [0.6, 0.0, -0.8] }
                            }
                        };
                        let s = (1.0 - cos_n * cos_n).sqrt();
                        let receiver = Receiver { position: [0.0; 3], normal: [s, 0.0, cos_n] };
                        let opts = if cos_n == 0.0 {
                            QueryOptions { similarity: true, backscatter: true, ..QueryOptions::default() }
                        } else {
                            QueryOptions::default()
                        };
                        let medium = HomogeneousMedium { sigma_s, sigma_a, g };
                        let value = match table.irradiance(&medium, &emitter, &receiver, &opts) {
                            Ok(x) if [x.direct, x.single, x.multiple, x.tail].iter().all(|p| *p >= 0.0) => x.total,
                            _ => f64::NAN,
                        };
                        v.push(row(
                            "irradiance total",
                            format!("{}, {name}, g={g}, d={d:e}, cos_n={cos_n}", profile.prefix()),
                            value,
                            Expect::InRange(0.0, f64::MAX),
                        ));
                    }
                }
            }
        }
        // Closer than 1e-154 to a point light the direct term overflows f64 (and at 1e-300 the distance itself
        // squares to 0): an explicit error, never Inf.
        if profile == EmitterProfile::Point {
            let emitter = Emitter::Point { intensity: 1.0, position: [0.0, 0.0, 1e-300] };
            let receiver = Receiver { position: [0.0; 3], normal: [0.0, 0.0, 1.0] };
            let medium = HomogeneousMedium { sigma_s: 1.0, sigma_a: 0.0, g: 0.0 };
            let value = match table.irradiance(&medium, &emitter, &receiver, &QueryOptions::default()) {
                Err(QueryError::Invalid(m)) if m.contains("overflowed") || m.contains("at the point light") => 1.0,
                _ => f64::NAN,
            };
            v.push(row("overflow is an error", "point, d=1e-300".into(), value, Expect::Close { to: 1.0, rel: 0.0 }));
        }
        // Vacuum: exactly the analytic direct term.
        let (d, cos_n) = (0.7f64, 0.6f64);
        let emitter = match profile {
            EmitterProfile::Point => Emitter::Point { intensity: 1.0, position: [0.0, 0.0, d] },
            EmitterProfile::Directional => {
                Emitter::Directional { irradiance: 1.0, toward_light: [0.0, 0.0, 1.0], depth: d }
            }
            EmitterProfile::Area => Emitter::Area { intensity: 1.0, position: [0.0, 0.0, d], normal: [0.6, 0.0, -0.8] },
        };
        let want = match profile {
            EmitterProfile::Point => (-0.5 * d).exp() * cos_n / (d * d),
            EmitterProfile::Directional => (-0.5 * d).exp() * cos_n,
            EmitterProfile::Area => 0.8 * (-0.5 * d).exp() * cos_n / (d * d),
        };
        let receiver = Receiver { position: [0.0; 3], normal: [0.8, 0.0, cos_n] };
        let medium = HomogeneousMedium { sigma_s: 0.0, sigma_a: 0.5, g: 0.0 };
        let value =
            table.irradiance(&medium, &emitter, &receiver, &QueryOptions::default()).map_or(f64::NAN, |x| x.total);
        v.push(row(
            "vacuum = direct",
            format!("{}, sigma_s=0", profile.prefix()),
            value,
            Expect::Close { to: want, rel: 1e-14 },
        ));
    }
    v
}

/// One (emitter, g slice) of a [`ZhResponse`] table before assembly: a work unit of a sharded compile.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub enum ZhPart {
    /// A point or directional emitter's response.
    Response(zh_transport::Response),
    /// The walk references of the sidecar check ([`ZhResponse::check_references`]).
    Check(Vec<WalkReference>),
    /// An area emitter's flattened arrays for one g slice.
    Area {
        /// `direct[d, θ]`.
        direct: Vec<f64>,
        /// `zh[b, d, θ, l]`.
        zh: Vec<f64>,
        /// `axis[b, d, θ]`.
        axis: Vec<f64>,
    },
}

/// One walk reference of the ZH sidecar check: (direct, per-order means, per-order standard errors).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct WalkReference {
    /// Emitter.
    pub profile: EmitterProfile,
    /// Bits of g.
    pub g: u64,
    /// Bits of the distance.
    pub d: u64,
    /// What [`walk_reference`] returned.
    pub value: (f64, Vec<f64>, Vec<f64>),
}

impl super::TableKind for ZhResponse {
    fn kind(&self) -> &'static str {
        ZhResponseRaw::KIND
    }
    fn kind_schema_version(&self) -> u32 {
        KIND_SCHEMA_VERSION
    }
    fn generator_version(&self) -> &'static str {
        GENERATOR_VERSION
    }
    fn validate(&self) -> Vec<FieldIssue> {
        ZhResponse::validate(self)
    }
    fn estimated_bytes(&self) -> u128 {
        ZhResponse::estimated_bytes(self)
    }
    fn work_units(&self) -> u64 {
        ZhResponse::work_units(self)
    }
    fn work_unit_name(&self) -> &'static str {
        "bounce responses"
    }
    fn generate(
        &self,
        key: &[u8; 32],
        progress: super::Progress<'_>,
    ) -> Result<super::Generated, super::GenerateError> {
        ZhResponse::generate(self, key, progress)
    }
    fn estimate_errors(&self, generated: &super::Generated, key: &[u8; 32]) -> Result<super::GenStats, CheckError> {
        ZhResponse::estimate_errors(self, generated, key)
    }
    fn report_ladder(&self) -> Vec<(String, super::TableDef)> {
        ZhResponse::report_ladder(self).into_iter().map(|(l, d)| (l, super::TableDef::ZhResponse(d))).collect()
    }
    fn report_error_name(&self) -> &'static str {
        "max relative error of the irradiance on a receiver facing the light vs the random-walk reference"
    }
    fn report_measure(&self, generated: &super::Generated) -> Result<Vec<(String, f64)>, CheckError> {
        ZhResponse::report_measure(self, generated)
    }

    /// One unit per (emitter, g slice) and one for the references of the sidecar check.
    fn units(&self) -> usize {
        self.unit_count() + 1
    }
    fn generate_unit(
        &self,
        key: &[u8; 32],
        unit: usize,
        progress: super::Progress<'_>,
    ) -> Result<super::UnitPart, super::GenerateError> {
        self.shard_unit(unit, key, progress).map(super::UnitPart::Zh)
    }
    fn assemble(&self, key: &[u8; 32], parts: Vec<super::UnitPart>) -> Result<super::Assembled, super::GenerateError> {
        let (mut zh, mut refs) = (Vec::new(), Vec::new());
        for part in parts {
            match part {
                super::UnitPart::Zh(ZhPart::Check(r)) => refs.extend(r),
                super::UnitPart::Zh(z) => zh.push(z),
                _ => return Err(super::GenerateError::Layout("a lobe unit given to a ZH table".into())),
            }
        }
        let mut generated = ZhResponse::assemble(self, zh)?;
        let t0 = std::time::Instant::now();
        generated.stats = self.estimate_errors_with(&generated, key, &refs)?;
        Ok(super::Assembled { generated, check_ms: t0.elapsed().as_secs_f64() * 1e3 })
    }
}
