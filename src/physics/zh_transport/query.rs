//! The query side of the responses (dubouchet2019 Sec. 4.3–4.4): canonical tables (σ_s = 1, σ_a = 0,
//! lengths in mean free paths) → irradiance in a real homogeneous medium, split into direct, single and
//! multiple scattering.
//!
//! Input: a [`Response`], a [`HomogeneousMedium`] in scene units (1/m; its `g` is the one the response
//! was computed for), the emitter strength (intensity in W/sr
//! for a point emitter, irradiance in W/m² at the boundary for a directional one), the distance (or
//! boundary depth) in metres and the cosine between the receiver normal and the light axis.
//! Derivation (Sec. 4.3 with absorption): measuring lengths in mean free paths of the real medium,
//! x = σ_t x', turns it into the canonical medium with albedo α = σ_s/σ_t. A path with b scattering
//! events then carries α^b (one factor per event, the "per-bounce weights (σ_s/σ_t)^b" of Sec. 5.1), the
//! table is read at d_q = σ_t d', and a point emitter's 1/r² in scaled lengths brings σ_t² (the σ_r² of
//! Sec. 4.3); directional entries are unscaled. The direct term is evaluated analytically in scene units.
//! Heterogeneous media enter through [`effective_sigma`] (Sec. 4.4): the length-weighted mean
//! coefficient along the connecting segment, which is exact for the direct term.

use super::{EmitterKind, Response};
use crate::physics::medium::{HomogeneousMedium, MediumError};
use crate::physics::sh;

/// Irradiance at a receiver split by scattering order (W/m²).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Split {
    /// Unscattered light.
    pub direct: f64,
    /// Exactly one scattering event.
    pub single: f64,
    /// Two to B events.
    pub multiple: f64,
}

impl Split {
    /// direct + single + multiple.
    pub fn total(&self) -> f64 {
        self.direct + self.single + self.multiple
    }
}

/// Effective extinction-like coefficient of a ray crossing segments `(length, σ)`: Σ σ_i d_i / Σ d_i
/// (dubouchet2019 Sec. 4.4). Zero for a zero-length ray.
pub fn effective_sigma(segments: &[(f64, f64)]) -> f64 {
    let length: f64 = segments.iter().map(|s| s.0).sum();
    if length > 0.0 { segments.iter().map(|s| s.0 * s.1).sum::<f64>() / length } else { 0.0 }
}

/// A query argument outside its domain.
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
pub enum SplitError {
    /// The medium's coefficients.
    #[error(transparent)]
    Medium(#[from] MediumError),
    /// `strength`, `distance` or `cos_n` is NaN, infinite or (for the first two) negative.
    #[error("{name} = {value} must be finite{}", if *.name == "cos_n" { "" } else { " and >= 0" })]
    Argument {
        /// The argument's name.
        name: &'static str,
        /// The value given.
        value: f64,
    },
    /// A point emitter on the receiver.
    #[error("a point emitter at distance 0 has no defined irradiance")]
    PointAtZero,
}

fn finite_non_negative(name: &'static str, value: f64) -> Result<f64, SplitError> {
    if value.is_finite() && value >= 0.0 { Ok(value) } else { Err(SplitError::Argument { name, value }) }
}

impl Response {
    /// Irradiance of bounce `b ≥ 1` in canonical units at canonical distance `d` for a receiver whose
    /// normal makes cosine `cos_n` with the light axis (order-N ZH · clamped cosine, Appendix A).
    pub fn bounce_irradiance(&self, b: usize, d: f64, cos_n: f64) -> f64 {
        let c = if cos_n.is_nan() { 0.0 } else { cos_n.clamp(-1.0, 1.0) };
        let normal = [(1.0 - c * c).max(0.0).sqrt(), 0.0, c];
        sh::zh_irradiance(&self.zh_at(b, d), [0.0, 0.0, 1.0], normal).max(0.0)
    }

    /// Irradiance in a real medium (see the module doc). `strength` is the point emitter's intensity
    /// (W/sr) or the directional emitter's boundary irradiance (W/m²); `distance` is the emitter
    /// distance or boundary depth in metres.
    ///
    /// # Errors
    /// The medium or argument outside its domain, or a point emitter at distance 0.
    pub fn irradiance_in(
        &self,
        medium: &HomogeneousMedium,
        strength: f64,
        distance: f64,
        cos_n: f64,
    ) -> Result<Split, SplitError> {
        let (sigma_s, _) = medium.checked()?;
        let strength = finite_non_negative("strength", strength)?;
        let distance = finite_non_negative("distance", distance)?;
        if !cos_n.is_finite() {
            return Err(SplitError::Argument { name: "cos_n", value: cos_n });
        }
        let cos = cos_n.clamp(-1.0, 1.0);
        let sigma_t = medium.sigma_t();
        let dq = sigma_t * distance;
        let geometric = match self.kind {
            EmitterKind::Point if distance == 0.0 => {
                return Err(SplitError::PointAtZero);
            }
            EmitterKind::Point => strength / (distance * distance),
            EmitterKind::Directional => strength,
        };
        let direct = geometric * (-dq).exp() * cos.max(0.0);
        if sigma_s == 0.0 || self.bounces.is_empty() {
            return Ok(Split { direct, single: 0.0, multiple: 0.0 });
        }
        let albedo = medium.albedo();
        let scale = strength
            * match self.kind {
                EmitterKind::Point => sigma_t * sigma_t,
                EmitterKind::Directional => 1.0,
            };
        let single = scale * albedo * self.bounce_irradiance(1, dq, cos);
        let mut weight = albedo;
        let mut multiple = 0.0;
        for b in 2..=self.bounces.len() {
            weight *= albedo;
            if weight == 0.0 {
                break;
            }
            multiple += scale * weight * self.bounce_irradiance(b, dq, cos);
        }
        Ok(Split { direct, single, multiple })
    }
}

#[cfg(test)]
mod tests;
