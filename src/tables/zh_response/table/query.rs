//! The query API of a `ZhResponse` table (dubouchet2019 Sec. 4–5): a medium, an emitter and a
//! receiver in → irradiance (direct, single, multiple, tail) or the scattered radiance as ZH/SH out,
//! and the errors of a query the table cannot answer.

use super::*;
use crate::physics::medium::MediumError;

/// A query the table cannot answer.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum QueryError {
    /// An argument is out of its domain.
    #[error("{0}")]
    Invalid(String),
    /// The medium's coefficients are outside their domain.
    #[error(transparent)]
    Medium(#[from] MediumError),
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
    /// The table (or the loaded part) lacks what the query needs.
    #[error("{0}")]
    NotLoaded(String),
}

/// A light, scene units.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Emitter {
    /// Isotropic point light.
    Point {
        /// Radiant intensity (W/sr), finite, ≥ 0.
        intensity: f64,
        /// Position (m).
        position: [f64; 3],
    },
    /// Collimated light entering the medium through a boundary plane perpendicular to the beam.
    Directional {
        /// Irradiance at the boundary on a plane perpendicular to the beam (W/m²), finite, ≥ 0.
        irradiance: f64,
        /// Direction toward the light (any finite non-zero vector).
        toward_light: [f64; 3],
        /// Distance from the receiver to the boundary along `toward_light` (m), finite, ≥ 0.
        depth: f64,
    },
    /// Differential cosine-weighted patch (an area light element, or a surface reflecting light).
    Area {
        /// Radiant intensity along the patch normal (W/sr); `intensity · max(0, normal·u)` toward `u`.
        intensity: f64,
        /// Position (m).
        position: [f64; 3],
        /// Patch normal (any finite non-zero vector).
        normal: [f64; 3],
    },
}

impl Emitter {
    pub(super) fn profile(&self) -> EmitterProfile {
        match self {
            Emitter::Point { .. } => EmitterProfile::Point,
            Emitter::Directional { .. } => EmitterProfile::Directional,
            Emitter::Area { .. } => EmitterProfile::Area,
        }
    }
}

/// A receiving surface point.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Receiver {
    /// Position (m).
    pub position: [f64; 3],
    /// Surface normal (any finite non-zero vector).
    pub normal: [f64; 3],
}

/// Switches of a query.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct QueryOptions {
    /// Apply the table's back-scatter shift (Sec. 5.2) to the scattered orders: a heuristic for
    /// receivers on surfaces, off by default (a receiver inside the medium needs no compensation).
    pub backscatter: bool,
    /// Add the tail closure (orders `> B`) when the table has one.
    pub tail: bool,
    /// Similarity relation `(1 − g) σ_s`, `g = 0` for the orders `b ≥ 2`.
    pub similarity: bool,
    /// Highest order summed (`None`: all `B`); orders above it are dropped (and so is the tail).
    pub max_bounce: Option<usize>,
}

impl Default for QueryOptions {
    fn default() -> Self {
        Self { backscatter: false, tail: true, similarity: false, max_bounce: None }
    }
}

/// Irradiance on a receiver (W/m²) by scattering order.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct Irradiance {
    /// Unscattered light.
    pub direct: f64,
    /// Exactly one scattering event.
    pub single: f64,
    /// Two or more events: orders `2..=B` plus the tail.
    pub multiple: f64,
    /// The part of `multiple` from orders beyond `B` (tail closure; 0 when off or not tabulated).
    pub tail: f64,
    /// Sum of the parts.
    pub total: f64,
}

/// The scattered incident radiance at a receiver.
#[derive(Debug, Clone, PartialEq)]
pub struct Radiance {
    /// ZH coefficients (`N`) about `axis`.
    pub zh: Vec<f64>,
    /// Unit axis of the lobe (toward the light, from the possibly shifted receiver).
    pub axis: [f64; 3],
    /// The lobe rotated to world real SH (`N²` coefficients, Eq. 13).
    pub sh: Vec<f64>,
}
