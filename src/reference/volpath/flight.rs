//! Free-flight sampling and transmittance along a ray through the media of a scene.
//!
//! **Input → output.** A unit-direction ray, its [`MediumSegment`]s (from
//! [`SceneBvh::media_segments`](crate::scene::bvh::SceneBvh::media_segments)), a tracking channel
//! and a uniform → a [`Flight`]: the first collision (distance, medium, per-channel `σ_s`, `σ_t` there)
//! or none before the end of the segments, and the per-channel optical depth `τ` from the origin to
//! where the flight stopped.
//!
//! **Method: exact analytic inversion** of the tracking channel's optical depth (no majorant, no
//! null collisions). The target depth is `τ* = −ln(1 − ξ)`; segments are walked in order, each
//! one's depth `τ_seg` taken from [`optical_thickness`] (closed form, homogeneous and iser2018 Eq. 4).
//! Within the segment that holds `τ*` the distance solves `τ(s) = τ*`: homogeneous `s = τ*/σ`;
//! exponential height fog `τ(s) = A (1 − e^{−ks})/k` (`A = σ_t ρ(start)`, `k = b⟨ω, n⟩`), so
//! `s = (τ*/A) · (−ln(1 − x)/x)` with `x = τ* k / A` (`→ τ*/A` as `x → 0`, no cancellation; for
//! `k > 0` and `x ≥ 1` the thinning fog cannot supply `τ*`: no collision in that segment). A
//! segment whose start density underflows to 0 is treated as empty.

use glam::DVec3;

use crate::scene::bvh::{MediumSegment, Ray, optical_thickness};
use crate::scene::{Density, Medium, Scene};

/// Where a free flight stopped.
#[derive(Debug, Clone, Copy)]
pub struct Flight {
    /// The collision: ray distance, medium index, and per channel `σ_s`, `σ_t` \[1/m\] there.
    pub collision: Option<Collision>,
    /// Per-channel optical depth from the origin to the collision or to the end of the segments.
    pub tau: [f64; 3],
}

/// A sampled collision.
#[derive(Debug, Clone, Copy)]
pub struct Collision {
    /// Distance along the (unit-direction) ray \[m\].
    pub t: f64,
    /// Index into [`Scene::media`].
    pub medium: usize,
    /// Scattering coefficient times density, per channel \[1/m\].
    pub sigma_s: [f64; 3],
    /// Extinction coefficient times density, per channel \[1/m\].
    pub sigma_t: [f64; 3],
}

/// Density `ρ(x)` of a medium.
pub fn density_at(density: &Density, x: DVec3) -> f64 {
    match density {
        Density::Homogeneous => 1.0,
        Density::ExponentialHeight { rho, falloff, direction, offset } => {
            let Some(n) = super::lights::unit(*direction) else { return 0.0 };
            let h = (x - DVec3::from_array(*offset)).dot(n);
            let v = rho * (-falloff * h).exp();
            if v.is_finite() { v } else { 0.0 }
        }
    }
}

/// Distance `s` into a segment starting at `start` (direction `dir`, unit) at which the optical depth of
/// extinction `sigma` in `medium` reaches `target`; `None` when it never does (a thinning fog).
pub fn invert_depth(medium: &Medium, sigma: f64, start: DVec3, dir: DVec3, target: f64) -> Option<f64> {
    let a = sigma * density_at(&medium.density, start);
    if a.is_nan() || a <= 0.0 {
        return None;
    }
    if a == f64::INFINITY {
        return Some(0.0);
    }
    let k = match &medium.density {
        Density::Homogeneous => 0.0,
        Density::ExponentialHeight { falloff, direction, .. } => {
            super::lights::unit(*direction).map_or(0.0, |n| falloff * dir.dot(n))
        }
    };
    let x = target * k / a;
    if x.is_nan() || x >= 1.0 {
        return None;
    }
    let ratio = if x.abs() < 1e-12 { 1.0 + 0.5 * x } else { -(-x).ln_1p() / x };
    let s = target / a * ratio;
    s.is_finite().then_some(s)
}

/// Samples a free flight along `ray` (unit direction) over `segments` with channel `hero` and the
/// uniform `xi`.
pub fn fly(scene: &Scene, ray: &Ray, segments: &[MediumSegment], hero: usize, xi: f64) -> Flight {
    let mut remaining = -(-xi).ln_1p(); // τ* = −ln(1 − ξ)
    let mut tau = [0.0; 3];
    for seg in segments {
        let Some(medium) = seg.medium.and_then(|i| scene.media.get(i)) else { continue };
        let seg_tau = optical_thickness(scene, std::slice::from_ref(seg), ray);
        if seg_tau[hero] < remaining {
            remaining -= seg_tau[hero];
            for c in 0..3 {
                tau[c] += seg_tau[c];
            }
            continue;
        }
        let origin = DVec3::from_array(ray.origin);
        let dir = DVec3::from_array(ray.direction);
        let start = origin + seg.t0 * dir;
        let sigma_t = medium.sigma_t();
        let Some(s) = invert_depth(medium, sigma_t[hero], start, dir, remaining) else {
            // Only reachable when rounding puts τ* just at the segment's end: pass it.
            remaining = (remaining - seg_tau[hero]).max(0.0);
            for c in 0..3 {
                tau[c] += seg_tau[c];
            }
            continue;
        };
        let t = (seg.t0 + s).min(seg.t1);
        let part = MediumSegment { t0: seg.t0, t1: t, medium: seg.medium };
        let part_tau = optical_thickness(scene, std::slice::from_ref(&part), ray);
        for c in 0..3 {
            tau[c] += part_tau[c];
        }
        let rho = density_at(&medium.density, origin + t * dir);
        let collision = Collision {
            t,
            medium: seg.medium.unwrap_or(0),
            sigma_s: medium.sigma_s.map(|s| s * rho),
            sigma_t: sigma_t.map(|s| s * rho),
        };
        return Flight { collision: Some(collision), tau };
    }
    Flight { collision: None, tau }
}

/// Per-channel optical depth of `segments` along `ray`.
pub fn depth(scene: &Scene, ray: &Ray, segments: &[MediumSegment]) -> [f64; 3] {
    optical_thickness(scene, segments, ray)
}
