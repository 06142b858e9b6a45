//! One colour channel of a homogeneous participating medium: the coefficients every table query and
//! method takes.
//!
//! **Input → output.** Scattering and absorption coefficients σ_s, σ_a (1/m) and the HG mean cosine g
//! → a checked [`HomogeneousMedium`], its extinction σ_t = σ_s + σ_a and single-scattering albedo
//! α = σ_s/σ_t (the canonical-medium remapping of dubouchet2019 Sec. 4.3: lengths in mean free paths
//! of the real medium turn it into the tabulated σ_t = 1 medium with albedo α); an extinction and a
//! length → the extinguished fraction 1 − e^{−σ_t L} ([`extinguished`]) and its inverse, the
//! free-flight distance ([`free_flight`]) that samples e^{−σ_t t} (truncated to [0, L] when the
//! fraction drawn is below `extinguished(σ_t, L)`): the distance sampling of wang2018's light and
//! camera samples (Sec. 4.1) and of the lobe generator's walks (Sec. 5.2).
//!
//! Per colour channel the same coefficients form an [`RgbMedium`]: the coefficients of the voxel media
//! of POP (`render::voxel`), of the god rays' box (`stages::god_rays`) and of the analytic fog
//! components (`stages::image_fog`), each adding only its own density representation.
//!
//! The ZH response tables (`tables::zh_response`), their generator's own query
//! (`physics::zh_transport::query`) and the lightmap bake (`stages::bake`, the effective medium along a
//! segment, dubouchet2019 Sec. 4.4) all read this one description. Scene media (per-channel, with a
//! density field and a boundary) are `scene::Medium`; the path-tracing references keep their own
//! (`reference::walk::Medium`) so that they share no code with the methods they judge.

/// A medium's coefficients are outside their domain.
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
pub enum MediumError {
    /// σ_s or σ_a is negative, NaN or infinite.
    #[error("{name} = {value} must be finite and >= 0")]
    Coefficient {
        /// `"sigma_s"` or `"sigma_a"`.
        name: &'static str,
        /// The value given.
        value: f64,
    },
    /// g is NaN or `|g| ≥ 1`.
    #[error("g = {0} must lie in (-1, 1)")]
    G(f64),
}

/// One channel of a homogeneous medium (or the effective coefficients along a segment), scene units.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HomogeneousMedium {
    /// Scattering coefficient σ_s (1/m), finite, ≥ 0.
    pub sigma_s: f64,
    /// Absorption coefficient σ_a (1/m), finite, ≥ 0.
    pub sigma_a: f64,
    /// HG mean cosine, in (−1, 1).
    pub g: f64,
}

impl HomogeneousMedium {
    /// `(σ_s, σ_a)` when both are finite and ≥ 0 and g lies in (−1, 1).
    ///
    /// # Errors
    /// The first coefficient outside its domain, σ_s before σ_a before g.
    pub fn checked(&self) -> Result<(f64, f64), MediumError> {
        for (name, value) in [("sigma_s", self.sigma_s), ("sigma_a", self.sigma_a)] {
            if !(value.is_finite() && value >= 0.0) {
                return Err(MediumError::Coefficient { name, value });
            }
        }
        if !(self.g.is_finite() && self.g.abs() < 1.0) {
            return Err(MediumError::G(self.g));
        }
        Ok((self.sigma_s, self.sigma_a))
    }

    /// Extinction σ_t = σ_s + σ_a (1/m).
    pub fn sigma_t(&self) -> f64 {
        self.sigma_s + self.sigma_a
    }

    /// Single-scattering albedo σ_s/σ_t; 0 for a medium that neither scatters nor absorbs.
    pub fn albedo(&self) -> f64 {
        let sigma_t = self.sigma_t();
        if sigma_t > 0.0 { self.sigma_s / sigma_t } else { 0.0 }
    }
}

/// A homogeneous medium per colour channel (R, G, B) at density 1, scene units. Methods whose
/// factorisation shares one phase function across channels (baran2010's god rays, iser2018's fog) read
/// the channel mean [`RgbMedium::mean_g`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RgbMedium {
    /// Scattering coefficient σ_s (1/m) per channel.
    pub sigma_s: [f64; 3],
    /// Absorption coefficient σ_a (1/m) per channel.
    pub sigma_a: [f64; 3],
    /// HG mean cosine per channel.
    pub g: [f64; 3],
}

impl RgbMedium {
    /// The same coefficients in every channel.
    pub fn grey(sigma_s: f64, sigma_a: f64, g: f64) -> Self {
        Self { sigma_s: [sigma_s; 3], sigma_a: [sigma_a; 3], g: [g; 3] }
    }

    /// Channel `c` (0, 1 or 2).
    pub fn channel(&self, c: usize) -> HomogeneousMedium {
        HomogeneousMedium { sigma_s: self.sigma_s[c], sigma_a: self.sigma_a[c], g: self.g[c] }
    }

    /// Extinction σ_t = σ_s + σ_a per channel (1/m).
    pub fn sigma_t(&self) -> [f64; 3] {
        [0, 1, 2].map(|c| self.sigma_s[c] + self.sigma_a[c])
    }

    /// The channel mean of g, `(g_R + g_G + g_B)/3`.
    pub fn mean_g(&self) -> f64 {
        (self.g[0] + self.g[1] + self.g[2]) / 3.0
    }
}

/// The fraction of a beam extinguished over `length`, `1 − e^{−σ_t·length}`, without cancellation
/// for small `σ_t·length`. In `[0, 1]` for `σ_t, length ≥ 0`; NaN only for NaN input.
pub fn extinguished(sigma_t: f64, length: f64) -> f64 {
    -(-sigma_t * length).exp_m1()
}

/// The distance at which the extinguished fraction reaches `mass`, `−ln(1 − mass)/σ_t`: the inverse of
/// [`extinguished`]. A `mass` uniform in `[0, 1)` samples the free flight `σ_t e^{−σ_t t}`; uniform in
/// `[0, extinguished(σ_t, L))` it samples the flight truncated to `[0, L]`. `+∞` at `mass = 1` or
/// `σ_t = 0` with `mass > 0`.
pub fn free_flight(mass: f64, sigma_t: f64) -> f64 {
    -(-mass).ln_1p() / sigma_t
}

#[cfg(test)]
mod tests;
