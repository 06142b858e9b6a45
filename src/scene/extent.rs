//! Where an unbounded ([`Boundary::Global`](super::Boundary::Global)) medium ends: one model for every
//! consumer that needs a finite region (the Mitsuba export, and the bake and its references as they adopt
//! it, issue 31).
//!
//! **Model.** A global medium fills the axis-aligned box of the scene's bounds ([`Scene::bounds`]: every
//! mesh vertex and every positioned light) grown on each side by [`GLOBAL_PADDING_FRACTION`] of the
//! bounds' diagonal plus [`GLOBAL_PADDING_MIN`]; outside that box is vacuum. Light from directional lights
//! and the environment therefore enters the medium at the box's faces, and a closed room's walls lie
//! strictly inside the box (no face of the box coincides with scene geometry).

use super::Scene;

/// Padding of the global medium's box on each side, as a fraction of the scene bounds' diagonal.
pub const GLOBAL_PADDING_FRACTION: f64 = 0.01;

/// Padding added on each side on top of the fractional one \[m\] (keeps a flat scene's box non-degenerate).
pub const GLOBAL_PADDING_MIN: f64 = 1e-3;

impl Scene {
    /// The region a global medium fills (module doc): `(min, max)` corners in metres, `None` for a
    /// scene without geometry or positioned lights.
    pub fn global_medium_bounds(&self) -> Option<([f64; 3], [f64; 3])> {
        let (lo, hi) = self.bounds()?;
        let pad = GLOBAL_PADDING_FRACTION * self.diagonal() + GLOBAL_PADDING_MIN;
        Some((lo.map(|v| v - pad), hi.map(|v| v + pad)))
    }
}

#[cfg(test)]
mod tests;
