//! The spot light's cone, as `KHR_lights_punctual` defines it: one home for the bake, god rays and POP.
//!
//! **Input → output.** A cone axis and inner/outer half-angles \[rad\] → the relative intensity toward a
//! unit direction `w`: `t²` with `t = clamp((cos θ_w − cos θ_outer) / max(cos θ_inner − cos θ_outer,
//! 10⁻³), 0, 1)` — the extension's own implementation note, smooth in cosine between the cones, 1 inside
//! the inner cone and 0 outside the outer one. The `10⁻³` floor turns a hard-edged cone (inner = outer)
//! into a ramp `10⁻³` wide in cosine instead of a division by zero. The independent references
//! (`reference::volpath`, the Mitsuba export) write their own.

use glam::DVec3;

/// The floor on `cos θ_inner − cos θ_outer` (`KHR_lights_punctual`'s implementation note).
pub const MIN_COS_RANGE: f64 = 1e-3;

/// A spot light's cone.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SpotCone {
    /// Unit axis the spot shines along.
    pub axis: DVec3,
    /// `cos` of the outer cone half-angle.
    pub cos_outer: f64,
    /// `1 / max(cos θ_inner − cos θ_outer, 10⁻³)`.
    pub inv_range: f64,
}

impl SpotCone {
    /// The cone of a `KHR_lights_punctual` spot light shining along `direction` (any length), with inner
    /// and outer half-angles in radians (an inner angle past the outer one acts as a hard edge). `None`
    /// when `direction` has no finite direction or an angle is not finite.
    pub fn khr(direction: DVec3, inner_cone: f64, outer_cone: f64) -> Option<SpotCone> {
        let axis = direction.try_normalize()?;
        let (ci, co) = (inner_cone.cos(), outer_cone.cos());
        if !(ci.is_finite() && co.is_finite()) {
            return None;
        }
        Some(SpotCone { axis, cos_outer: co, inv_range: 1.0 / (ci - co).max(MIN_COS_RANGE) })
    }

    /// The linear ramp `t` toward unit direction `w` (the falloff is `t²`).
    pub fn ramp(&self, w: DVec3) -> f64 {
        ((self.axis.dot(w) - self.cos_outer) * self.inv_range).clamp(0.0, 1.0)
    }

    /// The relative intensity `t²` toward unit direction `w`.
    pub fn falloff(&self, w: DVec3) -> f64 {
        let t = self.ramp(w);
        t * t
    }
}

#[cfg(test)]
mod tests;
