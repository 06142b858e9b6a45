//! One medium channel's lobes extracted from a loaded `MsLobes` table (wang2018 Sec. 4.1: "we
//! interpolate over α and g to extract the table corresponding to the current material").
//!
//! **Input → output.** An [`MsLobesTable`] and a [`MediumChannel`] (albedo, σ_t, g) → a [`LobeSlice`]
//! holding the g- and albedo-interpolated `total`, `E_2` and density arrays of that channel, so a
//! renderer's look-ups interpolate only in `(ρ, z, θ, φ)`. The slice answers
//! [`MsLobesTable::radiance`] and [`MsLobesTable::density`] with the same interpolation, outward decay and
//! clamping: the g/albedo blend is linear, so only the rounding differs (the blend happens once
//! instead of per look-up).

use super::table::{LobeQueryError, Located, beam_coordinates, scale_cubed};
use super::{LobeQuery, LobeValue, MediumChannel, MsLobesTable};
use crate::physics::lobe_transport::decay_rate;

/// A channel's lobes with the albedo and g interpolation done.
#[derive(Debug, Clone)]
pub struct LobeSlice<'a> {
    table: &'a MsLobesTable,
    medium: MediumChannel,
    /// `Σ w_g w_α total_{g,α}` `[z][ρ][θ][φ]`.
    total: Vec<f64>,
    /// `Σ w_g E_2,g` `[z][ρ][θ][φ]` (no albedo factor).
    e2: Vec<f64>,
    /// `Σ w_g w_α density_{g,α}` `[z][ρ]`.
    density: Vec<f64>,
    /// `total − α² E_2` (orders ≥ 3) `[z][ρ][θ][φ]`: inside the grid both parts are non-negative blends
    /// without decay, so their difference is one array.
    multiple: Vec<f64>,
    /// Outward decay rate of `total` and the density.
    kappa: f64,
    /// Outward decay rate of `E_2` (the free-flight rate).
    kappa_double: f64,
}

impl MsLobesTable {
    /// Extracts the lobes of one channel; refuses an albedo or g the table cannot answer and a bad σ_t.
    pub fn slice(&self, medium: &MediumChannel) -> Result<LobeSlice<'_>, LobeQueryError> {
        let st = medium.sigma_t;
        if !(st.is_finite() && st > 0.0) {
            return Err(LobeQueryError::Invalid(format!("sigma_t = {st} must be finite and > 0")));
        }
        let (gw, aw) = self.weights(medium.albedo, medium.g)?;
        let lobe_len = self.theta_bins * self.phi_nodes;
        let mut total: Vec<f64> = Vec::new();
        let mut density: Vec<f64> = Vec::new();
        let mut e2: Vec<f64> = Vec::new();
        let add = |acc: &mut Vec<f64>, v: &[f64], w: f64| {
            if acc.is_empty() {
                acc.resize(v.len(), 0.0);
            }
            for (a, x) in acc.iter_mut().zip(v) {
                *a += w * x;
            }
        };
        for &(gi, wg) in gw.iter().filter(|w| w.1 > 0.0) {
            let d = self.double.get(&gi).ok_or_else(|| self.not_loaded(gi, None))?;
            add(&mut e2, d, wg);
            for &(ai, wa) in aw.iter().filter(|w| w.1 > 0.0) {
                let missing = || self.not_loaded(gi, Some(ai));
                add(&mut total, self.total.get(&(gi, ai)).ok_or_else(missing)?, wg * wa);
                add(&mut density, self.density.get(&(gi, ai)).ok_or_else(missing)?, wg * wa);
            }
        }
        debug_assert!(total.len().is_multiple_of(lobe_len.max(1)));
        let a2 = medium.albedo * medium.albedo;
        let multiple = total.iter().zip(&e2).map(|(t, d)| t - a2 * d).collect();
        Ok(LobeSlice {
            table: self,
            medium: *medium,
            total,
            e2,
            density,
            multiple,
            kappa: decay_rate(medium.albedo, medium.g),
            kappa_double: decay_rate(0.0, 0.0),
        })
    }
}

impl LobeSlice<'_> {
    /// The channel this slice answers for.
    pub fn medium(&self) -> &MediumChannel {
        &self.medium
    }

    /// The table's interpolation weights at canonical `(ρ, z, θ, φ)` for this channel.
    fn locate(&self, rho: f64, z: f64, theta: f64, phi: f64) -> Result<Located, LobeQueryError> {
        let m = &self.medium;
        self.table.locate(&LobeQuery { albedo: m.albedo, g: m.g, rho, z, theta, phi })
    }

    /// The canonical `total` (all orders ≥ 2) at located weights, with its outward decay.
    fn total_at(&self, at: &Located) -> f64 {
        let lobe_len = self.table.theta_bins * self.table.phi_nodes;
        (at.sample(&self.total, lobe_len) * at.decay(self.kappa)).max(0.0)
    }

    /// [`MsLobesTable::lobe`] at canonical `(ρ, z, θ, φ)` for this channel.
    pub fn lobe(&self, rho: f64, z: f64, theta: f64, phi: f64) -> Result<LobeValue, LobeQueryError> {
        let m = &self.medium;
        let at = self.locate(rho, z, theta, phi)?;
        let lobe_len = self.table.theta_bins * self.table.phi_nodes;
        let total = self.total_at(&at);
        let double = (m.albedo * m.albedo * (at.sample(&self.e2, lobe_len) * at.decay(self.kappa_double))).max(0.0);
        Ok(LobeValue { total, double })
    }

    /// [`MsLobesTable::radiance`] for this channel: the radiance scattered at `x` toward `omega` per
    /// unit length and per unit power of a beam leaving `beam.0` along `beam.1`.
    pub fn radiance(
        &self,
        beam: ([f64; 3], [f64; 3]),
        x: [f64; 3],
        omega: [f64; 3],
    ) -> Result<LobeValue, LobeQueryError> {
        let st = self.medium.sigma_t;
        let (rho, z, theta, phi) = beam_coordinates(self.table.lobe, st, beam, x, omega)?;
        scale_cubed(self.lobe(rho, z, theta, phi)?, st)
    }

    /// The `total` of [`Self::radiance`] alone (one array sampled instead of two).
    pub fn total_radiance(
        &self,
        beam: ([f64; 3], [f64; 3]),
        x: [f64; 3],
        omega: [f64; 3],
    ) -> Result<f64, LobeQueryError> {
        let st = self.medium.sigma_t;
        let (rho, z, theta, phi) = beam_coordinates(self.table.lobe, st, beam, x, omega)?;
        let total = self.total_at(&self.locate(rho, z, theta, phi)?);
        Ok(scale_cubed(LobeValue { total, double: 0.0 }, st)?.total)
    }

    /// `total − double` of [`Self::radiance`] (scattering orders ≥ 3) with one array look-up inside the
    /// grid (the same value up to rounding); beyond it the two parts decay at different rates and are
    /// looked up separately.
    pub fn multiple_radiance(
        &self,
        beam: ([f64; 3], [f64; 3]),
        x: [f64; 3],
        omega: [f64; 3],
    ) -> Result<f64, LobeQueryError> {
        let st = self.medium.sigma_t;
        let (rho, z, theta, phi) = beam_coordinates(self.table.lobe, st, beam, x, omega)?;
        let at = self.locate(rho, z, theta, phi)?;
        if at.decay(self.kappa) == 1.0 && at.decay(self.kappa_double) == 1.0 {
            let lobe_len = self.table.theta_bins * self.table.phi_nodes;
            let v = scale_cubed(LobeValue { total: at.sample(&self.multiple, lobe_len), double: 0.0 }, st)?;
            return Ok(v.total);
        }
        let v = scale_cubed(self.lobe(rho, z, theta, phi)?, st)?;
        Ok(v.total - v.double)
    }

    /// [`MsLobesTable::density`] at canonical `(ρ, z)` for this channel.
    pub fn density(&self, rho: f64, z: f64) -> Result<f64, LobeQueryError> {
        let at = self.locate(rho, z, 0.0, 0.0)?;
        Ok(at.sample_cells(&self.density) * at.decay(self.kappa))
    }
}
