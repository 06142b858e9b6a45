//! Error estimates of a `ZhResponse` table (its sidecar and `voltab report`): a generated table →
//! single scattering and the sum of orders `≤ B` on a receiver facing the light, against the analog
//! photon walk of [`crate::reference::walk`] (dubouchet2019 Sec. 4–5), for up to three g slices.

use super::*;
use crate::reference::walk::WalkError;

/// Photons per walk run in the sidecar error estimate.
pub const SIDECAR_WALK_PHOTONS: u64 = 1 << 17;
/// Photons per walk run in the report's reference (computed once per configuration and cached).
pub const REPORT_WALK_PHOTONS: u64 = 1 << 20;
/// Albedo at which the walk runs; order `k` is rescaled by `α^{−k}` (exact: with `σ_t` fixed each
/// scattering event multiplies the photon weight by `α`), so photons die quickly and the estimate is
/// cheap, at the price of a larger variance at high orders.
pub const WALK_ALBEDO: f64 = 0.7;

/// The walk's conservative (α = 1) estimate of orders `1..=k_max` for a unit emitter in the canonical
/// medium, on a receiver facing the light: (direct, per-order means, per-order standard errors).
pub fn walk_reference(
    profile: EmitterProfile,
    g: f64,
    d: f64,
    k_max: usize,
    photons: u64,
    seed: u64,
) -> Result<(f64, Vec<f64>, Vec<f64>), WalkError> {
    let alpha = WALK_ALBEDO;
    let emitter = match profile {
        EmitterProfile::Point => walk::Emitter::Point { intensity: 1.0, position: [0.0, 0.0, d] },
        EmitterProfile::Directional => {
            walk::Emitter::Directional { irradiance: 1.0, toward_light: [0.0, 0.0, 1.0], depth: d }
        }
        // Patch facing the receiver (θ = 0).
        EmitterProfile::Area => {
            walk::Emitter::Area { intensity: 1.0, position: [0.0, 0.0, d], normal: [0.0, 0.0, -1.0] }
        }
    };
    let medium = walk::Medium { sigma_s: alpha, sigma_a: 1.0 - alpha, g };
    let r = walk::irradiance(&emitter, &medium, [0.0, 0.0, 1.0], &walk::WalkConfig::new(photons, k_max, seed))?;
    let scale = |k: usize| alpha.powi(-(k as i32));
    let means = r.orders.iter().enumerate().map(|(i, o)| o.mean * scale(i + 1)).collect();
    let errs = r.orders.iter().enumerate().map(|(i, o)| o.std_error * scale(i + 1)).collect();
    Ok((r.direct, means, errs))
}

/// Distances (mean free paths) at which the report compares against the walk (the range).
pub const REPORT_DISTANCES: [f64; 6] = [0.1, 0.5, 1.0, 2.0, 4.0, 8.0];

/// Cached report references keyed by (profile, g bits, d bits, bounces).
type RefCache = Mutex<HashMap<(EmitterProfile, u64, u64, usize), (f64, Vec<f64>, Vec<f64>)>>;

fn cached_reference(
    profile: EmitterProfile,
    g: f64,
    d: f64,
    k_max: usize,
) -> Result<(f64, Vec<f64>, Vec<f64>), CheckError> {
    static CACHE: OnceLock<RefCache> = OnceLock::new();
    let cache = CACHE.get_or_init(|| Mutex::new(HashMap::new()));
    let key = (profile, g.to_bits(), d.to_bits(), k_max);
    if let Some(v) = cache.lock().map_err(|_| CheckError::CachePoisoned)?.get(&key) {
        return Ok(v.clone());
    }
    let v = walk_reference(profile, g, d, k_max, REPORT_WALK_PHOTONS, 0x5eed_2019)?;
    cache.lock().map_err(|_| CheckError::CachePoisoned)?.insert(key, v.clone());
    Ok(v)
}

/// Relative errors of one table configuration against walk results: (single, total of orders ≤ B).
fn compare(
    table: &ZhResponseTable,
    profile: EmitterProfile,
    g: f64,
    d: f64,
    reference: &(f64, Vec<f64>, Vec<f64>),
) -> Result<(f64, f64), CheckError> {
    let medium = HomogeneousMedium { sigma_s: 1.0, sigma_a: 0.0, g };
    let opts = QueryOptions { backscatter: false, tail: false, similarity: false, max_bounce: None };
    let emitter = match profile {
        EmitterProfile::Point => Emitter::Point { intensity: 1.0, position: [0.0, 0.0, d] },
        EmitterProfile::Directional => {
            Emitter::Directional { irradiance: 1.0, toward_light: [0.0, 0.0, 1.0], depth: d }
        }
        EmitterProfile::Area => Emitter::Area { intensity: 1.0, position: [0.0, 0.0, d], normal: [0.0, 0.0, -1.0] },
    };
    let receiver = Receiver { position: [0.0; 3], normal: [0.0, 0.0, 1.0] };
    let got = table.irradiance(&medium, &emitter, &receiver, &opts)?;
    let (direct, means, _) = reference;
    let single_ref = means[0];
    let total_ref = direct + means.iter().sum::<f64>();
    let rel = |a: f64, b: f64| if b > 0.0 { (a - b).abs() / b } else { a.abs() };
    Ok((rel(got.single, single_ref), rel(got.direct + got.single + got.multiple, total_ref)))
}

impl ZhResponse {
    /// The g slices used for error estimates: first, middle and last (all when ≤ 3).
    fn probe_gs(&self) -> Vec<f64> {
        let gs = self.g.values();
        let n = gs.len();
        if n <= 3 { gs } else { vec![gs[0], gs[n / 2], gs[n - 1]] }
    }

    /// Error estimates against the walk (sidecar): single scattering and the sum of orders `≤ B` on a
    /// facing receiver at d ∈ {0.5, 2} mean free paths, per emitter, for up to three g slices.
    pub fn estimate_errors(&self, generated: &Generated, key: &[u8; 32]) -> Result<GenStats, CheckError> {
        self.estimate_errors_with(generated, key, &[])
    }

    /// The walk references [`ZhResponse::estimate_errors`] compares with, computed in parallel: a work
    /// unit of a sharded compile (they need the definition only). Keyed by (emitter, g bits, d bits).
    pub fn check_references(&self, key: &[u8; 32]) -> Result<Vec<WalkReference>, CheckError> {
        use rayon::prelude::*;
        let seed = super::super::key_seed(key);
        let cases: Vec<(EmitterProfile, f64, f64)> = self
            .emitters
            .iter()
            .flat_map(|&p| self.probe_gs().into_iter().flat_map(move |g| [0.5, 2.0].map(|d| (p, g, d))))
            .collect();
        cases
            .par_iter()
            .map(|&(profile, g, d)| {
                let value = walk_reference(profile, g, d, self.bounces as usize, SIDECAR_WALK_PHOTONS, seed)?;
                Ok(WalkReference { profile, g: g.to_bits(), d: d.to_bits(), value })
            })
            .collect()
    }

    /// [`ZhResponse::estimate_errors`] with walk references already computed; missing ones are computed.
    pub fn estimate_errors_with(
        &self,
        generated: &Generated,
        key: &[u8; 32],
        known: &[WalkReference],
    ) -> Result<GenStats, CheckError> {
        let table =
            ZhResponseTable::from_arrays(self, &generated.arrays, &generated.values).map_err(CheckError::Layout)?;
        let seed = super::super::key_seed(key);
        let mut noise = 0.0f64;
        let mut photons = 0u64;
        let mut errors = Vec::new();
        let how = format!(
            "facing receiver (area: patch facing it), d in {{0.5, 2}} mfp, g {:?}, vs reference::walk ({SIDECAR_WALK_PHOTONS} photons per case)",
            self.probe_gs()
        );
        for &profile in &self.emitters {
            let (mut single, mut total) = (0.0f64, 0.0f64);
            for g in self.probe_gs() {
                for d in [0.5, 2.0] {
                    let reference = match known
                        .iter()
                        .find(|r| r.profile == profile && r.g == g.to_bits() && r.d == f64::to_bits(d))
                    {
                        Some(r) => r.value.clone(),
                        None => walk_reference(profile, g, d, self.bounces as usize, SIDECAR_WALK_PHOTONS, seed)?,
                    };
                    photons += SIDECAR_WALK_PHOTONS;
                    let (s, t) = compare(&table, profile, g, d, &reference)?;
                    single = single.max(s);
                    total = total.max(t);
                    noise = noise.max(reference.2[0] / reference.1[0]);
                }
            }
            let p = profile.prefix();
            errors.push(ErrorEstimate { name: format!("{p}_single_max_rel_vs_walk"), value: single, how: how.clone() });
            errors.push(ErrorEstimate {
                name: format!("{p}_orders_le_b_max_rel_vs_walk"),
                value: total,
                how: how.clone(),
            });
        }
        errors.push(ErrorEstimate {
            name: "walk_single_rel_std_error".into(),
            value: noise,
            how: "largest relative standard error of the walk's single-scattering estimate (noise floor)".into(),
        });
        errors.extend(generated.stats.errors.iter().cloned());
        Ok(GenStats { nonfinite_discarded: generated.stats.nonfinite_discarded, samples: photons, errors })
    }

    /// Quality budgets for `voltab report`: distance resolution and quadrature size together, from 1/16
    /// of the table's own settings up to them (at least 4 distances and 2 nodes per panel).
    pub fn report_ladder(&self) -> Vec<(String, ZhResponse)> {
        let (n, q) = (self.distance_bins, self.quadrature_nodes);
        [(n / 16, q / 4), (n / 8, q / 3), (n / 4, q / 2), (n / 2, 2 * q / 3), (n, q)]
            .into_iter()
            .map(|(bins, nodes)| (bins.max(4), nodes.max(2)))
            .collect::<std::collections::BTreeSet<_>>()
            .into_iter()
            .map(|(bins, nodes)| {
                (
                    format!("distance_bins={bins},nodes={nodes}"),
                    ZhResponse { distance_bins: bins, quadrature_nodes: nodes, ..self.clone() },
                )
            })
            .collect()
    }

    /// Per emitter: the worst relative error of single scattering and of the orders `≤ B` against the
    /// walk ([`REPORT_WALK_PHOTONS`] photons), over the probe g slices and [`REPORT_DISTANCES`].
    pub fn report_measure(&self, generated: &Generated) -> Result<Vec<(String, f64)>, CheckError> {
        let table =
            ZhResponseTable::from_arrays(self, &generated.arrays, &generated.values).map_err(CheckError::Layout)?;
        let mut curves = Vec::new();
        for &profile in &self.emitters {
            let (mut single, mut total) = (0.0f64, 0.0f64);
            for g in self.probe_gs() {
                for d in REPORT_DISTANCES {
                    let reference = cached_reference(profile, g, d, self.bounces as usize)?;
                    let (s, t) = compare(&table, profile, g, d, &reference)?;
                    single = single.max(s);
                    total = total.max(t);
                }
            }
            curves.push((format!("{} single", profile.prefix()), single));
            curves.push((format!("{} orders <= B", profile.prefix()), total));
        }
        Ok(curves)
    }
}
