//! Opaque geometry as the volume techniques see it: a segment or ray either reaches its end or hits a
//! surface.
//!
//! **Input → output.** Two points (or an origin and a unit direction) → blocked or not, and the
//! distance to the first surface. POP's propagation grids (elek2014 Sec. 4: links that cross an opaque
//! surface carry nothing) and the grid Monte-Carlo reference ask the same question of a scene's
//! surfaces; [`NoOccluder`] answers it for free media.

use glam::DVec3;

/// Opaque geometry that blocks propagation (a scene's surfaces); [`NoOccluder`] for free media.
pub trait Occluder: Sync {
    /// True when the segment `a → b` hits a surface.
    fn segment_blocked(&self, a: DVec3, b: DVec3) -> bool;
    /// True when the ray from `origin` along unit `direction` hits a surface before leaving the
    /// scene (a shadow ray toward a distant light).
    fn ray_blocked(&self, origin: DVec3, direction: DVec3) -> bool;
    /// Distance from `origin` along unit `direction` to the first surface (`INFINITY` when none). The
    /// default narrows it down from [`Occluder::segment_blocked`] by bisection (to `1e-9` of the
    /// distance); scene occluders answer it with one closest-hit query.
    fn hit_distance(&self, origin: DVec3, direction: DVec3) -> f64 {
        if !self.ray_blocked(origin, direction) {
            return f64::INFINITY;
        }
        let mut hi = 1.0;
        while !self.segment_blocked(origin, origin + direction * hi) {
            hi *= 2.0;
            if !hi.is_finite() {
                return f64::INFINITY;
            }
        }
        let mut lo = 0.0;
        while hi - lo > 1e-9 * hi {
            let mid = 0.5 * (lo + hi);
            if self.segment_blocked(origin, origin + direction * mid) { hi = mid } else { lo = mid }
        }
        hi
    }
}

/// No surfaces: nothing is ever blocked.
#[derive(Debug, Clone, Copy, Default)]
pub struct NoOccluder;

impl Occluder for NoOccluder {
    fn segment_blocked(&self, _: DVec3, _: DVec3) -> bool {
        false
    }
    fn ray_blocked(&self, _: DVec3, _: DVec3) -> bool {
        false
    }
}
