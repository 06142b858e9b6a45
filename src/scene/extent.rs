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
mod tests {
    use crate::scene::{Light, LightKind, Scene, SceneFormat};
    use std::path::Path;

    #[test]
    fn global_box_is_the_padded_bounds_of_lights_and_meshes() {
        let mut s = Scene::empty(Path::new("t.gltf"), SceneFormat::Gltf);
        assert_eq!(s.global_medium_bounds(), None);
        for p in [[0.0, 0.0, 0.0], [3.0, 4.0, 0.0]] {
            s.lights.push(Light { name: "p".into(), kind: LightKind::Point { position: p }, radiance: [1.0; 3] });
        }
        // Diagonal 5 m → padding 0.05 + 0.001 m on each side.
        let (lo, hi) = s.global_medium_bounds().unwrap();
        for (a, b) in lo.iter().zip([-0.051, -0.051, -0.051]) {
            assert!((a - b).abs() < 1e-12, "{lo:?}");
        }
        for (a, b) in hi.iter().zip([3.051, 4.051, 0.051]) {
            assert!((a - b).abs() < 1e-12, "{hi:?}");
        }
    }
}
