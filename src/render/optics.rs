//! Smooth dielectric interfaces: Fresnel reflectance, refraction and mirror reflection (one home for
//! the optics every technique and reference uses).
//!
//! **Input → output.** Directions, normals, cosines and indices of refraction → reflectance in
//! \[0, 1\] and refracted/reflected unit directions. Total internal reflection gives reflectance 1 and
//! no refracted direction; index-matched interfaces reflect nothing.

use glam::DVec3;

/// Unpolarised Fresnel reflectance of a smooth interface for light arriving with `cos_i = |cos θ_i|`
/// from the side of index `eta_i` toward index `eta_t`; 1 under total internal reflection.
pub fn fresnel(cos_i: f64, eta_i: f64, eta_t: f64) -> f64 {
    if eta_i == eta_t {
        return 0.0; // index-matched: no interface (and no 0/0 at grazing incidence)
    }
    let cos_i = cos_i.clamp(0.0, 1.0);
    let sin2_t = (eta_i / eta_t).powi(2) * (1.0 - cos_i * cos_i);
    if sin2_t >= 1.0 {
        return 1.0;
    }
    fresnel_cos(cos_i, (1.0 - sin2_t).sqrt(), eta_i, eta_t)
}

/// Unpolarised Fresnel reflectance of a smooth dielectric interface from the cosines of the incident
/// and transmitted angles and the indices of both sides; 1 where the ratios are not finite (both
/// cosines 0).
pub fn fresnel_cos(cos_i: f64, cos_t: f64, eta_i: f64, eta_t: f64) -> f64 {
    let rs = (eta_i * cos_i - eta_t * cos_t) / (eta_i * cos_i + eta_t * cos_t);
    let rp = (eta_t * cos_i - eta_i * cos_t) / (eta_t * cos_i + eta_i * cos_t);
    let f = 0.5 * (rs * rs + rp * rp);
    if f.is_finite() { f.clamp(0.0, 1.0) } else { 1.0 }
}

/// Refracts the unit direction `d` at a surface with unit normal `n` (either orientation) going from
/// index `eta_i` to `eta_t`; `None` under total internal reflection.
pub fn refract(d: DVec3, n: DVec3, eta_i: f64, eta_t: f64) -> Option<DVec3> {
    let n = if d.dot(n) > 0.0 { -n } else { n };
    let cos_i = (-d.dot(n)).clamp(0.0, 1.0);
    let eta = eta_i / eta_t;
    let sin2_t = eta * eta * (1.0 - cos_i * cos_i);
    if sin2_t >= 1.0 {
        return None;
    }
    let cos_t = (1.0 - sin2_t).sqrt();
    Some((eta * d + (eta * cos_i - cos_t) * n).normalize())
}

/// Mirror reflection of `d` about the plane with normal `n`.
pub fn reflect(d: DVec3, n: DVec3) -> DVec3 {
    d - 2.0 * d.dot(n) * n
}

#[cfg(test)]
mod tests;
