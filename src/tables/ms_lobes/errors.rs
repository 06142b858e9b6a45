//! Error estimates of an `MsLobes` table (its sidecar and `voltab report`): a generated table →
//! its `E_2` lobes against the deterministic quadrature and its totals against the backward walk of
//! [`crate::reference::beam_adjoint`] at fixed probes, conservation of the collision count, and the
//! symmetric-lobe approximation's error (wang2018 Sec. 4.1, Fig. 8).

use super::*;
use crate::reference::beam_adjoint::AdjointError;

/// Points `(ρ, z)` at which the sidecar reports the closure's share of the density.
pub const REMAINDER_POINTS: [(f64, f64); 4] = [(1.0, 2.0), (5.0, 5.0), (10.0, 10.0), (20.0, 20.0)];

/// Probe points `(ρ, z)` of the error estimates, in mean free paths (kept inside the grid).
pub const PROBES: [(f64, f64); 3] = [(1.0, 2.0), (2.0, 0.5), (1.5, -1.0)];
/// Lobe angles of the `E_2` probes.
pub const PROBE_THETAS: [f64; 3] = [0.0, std::f64::consts::FRAC_PI_2, std::f64::consts::PI];
/// Backward-walk samples per probe in the sidecar.
pub const SIDECAR_ADJOINT_SAMPLES: u64 = 4096;
/// Backward-walk samples per probe in the report's reference (cached per configuration).
pub const REPORT_ADJOINT_SAMPLES: u64 = 16384;
/// Albedo at which totals are compared (the nearest stored node is used, so no albedo interpolation
/// enters the comparison): orders die out by `k ≈ 120`, so the backward walk stays cheap.
pub const PROBE_ALBEDO: f64 = 0.8;

/// The probe points that lie inside a definition's grid.
pub(super) fn probes(def: &MsLobes) -> Vec<(f64, f64)> {
    PROBES.into_iter().filter(|&(r, z)| r <= def.rho_max && z >= def.z_min && z <= def.z_max).collect()
}

/// The g slices used for error estimates: first and last (one when equal).
pub(super) fn probe_gs(def: &MsLobes) -> Vec<f64> {
    let gs = def.g_values();
    match (gs.first(), gs.last()) {
        (Some(a), Some(b)) if a != b => vec![*a, *b],
        (Some(a), _) => vec![*a],
        _ => Vec::new(),
    }
}

/// The stored albedo node nearest [`PROBE_ALBEDO`].
pub(super) fn probe_albedo(def: &MsLobes) -> f64 {
    def.albedo_values()
        .into_iter()
        .min_by(|a, b| (a - PROBE_ALBEDO).abs().total_cmp(&(b - PROBE_ALBEDO).abs()))
        .unwrap_or(PROBE_ALBEDO)
}

/// Worst relative error of `E_2` against the deterministic quadrature over the probes, and the
/// worst relative error / z-score of the totals against the backward walk.
#[derive(Debug, Clone, Copy, Default)]
pub(super) struct Comparison {
    double_rel: f64,
    /// Fewest second collisions expected in a probe's cell (its E_2 noise is ~1/√hits).
    double_hits: f64,
    total_rel: f64,
    total_z: f64,
    ref_rel_noise: f64,
}

type AdjointRef = (f64, f64);

pub(super) fn compare(
    def: &MsLobes,
    table: &MsLobesTable,
    reference: &dyn Fn(f64, f64, f64, f64, f64) -> Result<AdjointRef, CheckError>,
) -> Result<Comparison, CheckError> {
    use crate::reference::beam_adjoint;
    let mut c = Comparison { double_hits: f64::INFINITY, ..Comparison::default() };
    let albedo = probe_albedo(def);
    for g in probe_gs(def) {
        for (rho, z) in probes(def) {
            // E_2 at the centre of the probe's cell against the cell average of the quadrature: what an
            // exact table holds there (no interpolation bias; the Monte-Carlo noise remains).
            for theta in PROBE_THETAS {
                let ((rc, zc), want) =
                    cell_average(def, rho, z, &|r, zz| beam_adjoint::double_symmetric(r, zz, theta, g))?;
                let got = table.double_lobe(&LobeQuery { albedo, g, rho: rc, z: zc, theta, phi: 0.0 })?;
                c.double_rel = c.double_rel.max((got - want).abs() / want);
            }
            c.double_hits = c.double_hits.min(expected_second_collisions(def, table, g, rho, z)?);
            // Totals only where the backward walk's heavy tail is tame (|g| <= 0.7: at g = 0.9 its
            // scores near the beam axis make seeds disagree by 2x).
            if g.abs() > 0.7 {
                continue;
            }
            let theta = std::f64::consts::FRAC_PI_2;
            let (mean, se) = reference(rho, z, theta, g, albedo)?;
            let got = table.lobe(&LobeQuery { albedo, g, rho, z, theta, phi: 0.0 })?.total;
            c.total_rel = c.total_rel.max((got - mean).abs() / mean);
            c.total_z = c.total_z.max((got - mean).abs() / se.max(f64::MIN_POSITIVE));
            c.ref_rel_noise = c.ref_rel_noise.max(se / mean);
        }
    }
    Ok(c)
}

/// Second collisions the walk is expected to tally in the cell holding `(rho, z)`: `ψ_2 V N`, with `ψ_2`
/// the table's own `E_2` integrated over directions (trapezoid over its θ nodes).
pub(super) fn expected_second_collisions(
    def: &MsLobes,
    table: &MsLobesTable,
    g: f64,
    rho: f64,
    z: f64,
) -> Result<f64, LobeQueryError> {
    let (ra, za) = (def.rho_axis(), def.z_axis());
    let (ir, iz) = match (ra.cell(rho), za.cell(z)) {
        (Some(a), Some(b)) => (a, b),
        _ => return Err(LobeQueryError::Invalid(format!("({rho}, {z}) is outside the grid"))),
    };
    let (r0, r1) = (ra.edge(ir), ra.edge(ir + 1));
    let volume = std::f64::consts::PI * (r1 * r1 - r0 * r0) * (za.edge(iz + 1) - za.edge(iz));
    let n = def.theta_bins as usize;
    let h = std::f64::consts::PI / (n - 1) as f64;
    let mut psi = 0.0;
    for i in 0..n {
        let theta = h * i as f64;
        let w = if i == 0 || i == n - 1 { 0.5 } else { 1.0 };
        let q = LobeQuery { albedo: 0.5, g, rho: ra.center(ir), z: za.center(iz), theta, phi: 0.0 };
        psi += w * h * 2.0 * std::f64::consts::PI * theta.sin() * table.double_lobe(&q)?;
    }
    Ok(psi * volume * def.photons as f64)
}

/// The cell of `def`'s grid holding `(rho, z)`: its centre and the 3×3 Gauss average of `f(ρ, z)` over
/// its volume (weight ρ) — what an exact table stores in that cell.
pub fn cell_average(
    def: &MsLobes,
    rho: f64,
    z: f64,
    f: &dyn Fn(f64, f64) -> Result<f64, AdjointError>,
) -> Result<((f64, f64), f64), CheckError> {
    let (ra, za) = (def.rho_axis(), def.z_axis());
    let (ir, iz) = match (ra.cell(rho), za.cell(z)) {
        (Some(a), Some(b)) => (a, b),
        _ => return Err(LobeQueryError::Invalid(format!("({rho}, {z}) is outside the grid")).into()),
    };
    let (r0, r1, z0, z1) = (ra.edge(ir), ra.edge(ir + 1), za.edge(iz), za.edge(iz + 1));
    let gl = crate::physics::sh::gauss_legendre(3);
    let (mut acc, mut wsum) = (0.0, 0.0);
    for &(x, wx) in &gl {
        let r = 0.5 * (r0 + r1) + 0.5 * (r1 - r0) * x;
        for &(y, wy) in &gl {
            let zz = 0.5 * (z0 + z1) + 0.5 * (z1 - z0) * y;
            acc += wx * wy * r * f(r, zz)?;
            wsum += wx * wy * r;
        }
    }
    Ok(((ra.center(ir), za.center(iz)), acc / wsum))
}

pub(super) fn adjoint(
    samples: u64,
    seed: u64,
    max_order: usize,
) -> impl Fn(f64, f64, f64, f64, f64) -> Result<AdjointRef, CheckError> {
    move |rho, z, theta, g, albedo| {
        let cfg = crate::reference::beam_adjoint::AdjointConfig { samples, max_order, seed };
        let e = crate::reference::beam_adjoint::total_symmetric(rho, z, theta, g, albedo, &cfg)?;
        Ok((e.mean, e.std_error))
    }
}

/// Cached report references keyed by (ρ, z, θ, g, α, max_order) bits.
type RefCache = std::sync::Mutex<std::collections::HashMap<[u64; 6], AdjointRef>>;

pub(super) fn cached_adjoint(max_order: usize) -> impl Fn(f64, f64, f64, f64, f64) -> Result<AdjointRef, CheckError> {
    static CACHE: std::sync::OnceLock<RefCache> = std::sync::OnceLock::new();
    move |rho, z, theta, g, albedo| {
        let cache = CACHE.get_or_init(Default::default);
        let key = [rho.to_bits(), z.to_bits(), theta.to_bits(), g.to_bits(), albedo.to_bits(), max_order as u64];
        if let Some(v) = cache.lock().map_err(|_| CheckError::CachePoisoned)?.get(&key) {
            return Ok(*v);
        }
        let v = adjoint(REPORT_ADJOINT_SAMPLES, 0x3a6e_2018, max_order)(rho, z, theta, g, albedo)?;
        cache.lock().map_err(|_| CheckError::CachePoisoned)?.insert(key, v);
        Ok(v)
    }
}

/// `∫ density dV` over the grid for albedo node `ai` of g slice `gi`, and `Σ_{k=2}^{K} α^k · inside_k`
/// (what the integer tallies put inside), for the conservation check.
pub fn conservation(def: &MsLobes, table: &MsLobesTable, gi: usize, ai: usize) -> Result<(f64, f64), LobeQueryError> {
    let (rho, z) = (def.rho_axis(), def.z_axis());
    let albedo = def.albedo_values()[ai];
    let g = def.g_values()[gi];
    let mut integral = 0.0;
    for iz in 0..z.bins {
        for ir in 0..rho.bins {
            let (r0, r1) = (rho.edge(ir), rho.edge(ir + 1));
            let volume = std::f64::consts::PI * (r1 * r1 - r0 * r0) * (z.edge(iz + 1) - z.edge(iz));
            let closure = lobe_transport::remainder(albedo, g, def.max_order as usize, rho.center(ir), z.center(iz));
            let d = table.density(albedo, g, rho.center(ir), z.center(iz))?;
            integral += (d - closure) * volume;
        }
    }
    let tallied: f64 = (2..=def.max_order as usize)
        .map(|k| albedo.powi(k as i32) * table.inside_fraction(gi, k).unwrap_or(f64::NAN))
        .sum();
    Ok((integral, tallied))
}

impl MsLobes {
    /// Error estimates (sidecar): `E_2` against the deterministic quadrature and totals against the
    /// backward walk of [`crate::reference::beam_adjoint`] at [`PROBES`], for the first and last g slices;
    /// conservation at the largest albedo node ≤ 0.5; the closure's share (from the generator).
    pub fn estimate_errors(&self, generated: &Generated, key: &[u8; 32]) -> Result<GenStats, CheckError> {
        self.estimate_errors_with(generated, key, &[])
    }

    /// The backward-walk references [`MsLobes::estimate_errors`] compares the table with, computed in
    /// parallel: a work unit of its own in a sharded compile (it needs the definition only, not the
    /// table). Each value is keyed by the bits of its (ρ, z, θ, g, α).
    pub fn check_references(&self, key: &[u8; 32]) -> Result<Vec<CheckReference>, CheckError> {
        use rayon::prelude::*;
        let seed = super::super::key_seed(key);
        let albedo = probe_albedo(self);
        let theta = std::f64::consts::FRAC_PI_2;
        let points: Vec<[f64; 5]> = probe_gs(self)
            .into_iter()
            .filter(|g| g.abs() <= 0.7)
            .flat_map(|g| probes(self).into_iter().map(move |(rho, z)| [rho, z, theta, g, albedo]))
            .collect();
        let reference = adjoint(SIDECAR_ADJOINT_SAMPLES, seed, 400);
        points
            .par_iter()
            .map(|q| Ok(CheckReference { at: q.map(f64::to_bits), value: reference(q[0], q[1], q[2], q[3], q[4])? }))
            .collect()
    }

    /// [`MsLobes::estimate_errors`] with references already computed ([`MsLobes::check_references`]);
    /// any it lacks are computed here. The same numbers either way.
    pub fn estimate_errors_with(
        &self,
        generated: &Generated,
        key: &[u8; 32],
        known: &[CheckReference],
    ) -> Result<GenStats, CheckError> {
        let table =
            MsLobesTable::from_arrays(self, &generated.arrays, &generated.values).map_err(CheckError::Layout)?;
        let seed = super::super::key_seed(key);
        let compute = adjoint(SIDECAR_ADJOINT_SAMPLES, seed, 400);
        let reference = |rho: f64, z: f64, theta: f64, g: f64, albedo: f64| {
            let at = [rho, z, theta, g, albedo].map(f64::to_bits);
            match known.iter().find(|r| r.at == at) {
                Some(r) => Ok(r.value),
                None => compute(rho, z, theta, g, albedo),
            }
        };
        let c = compare(self, &table, &reference)?;
        let where_ =
            format!("(rho, z) in {:?} mfp, g {:?}, albedo node {}", probes(self), probe_gs(self), probe_albedo(self));
        let mut errors = vec![
            ErrorEstimate {
                name: "double_max_rel_vs_quadrature".into(),
                value: c.double_rel,
                how: format!(
                    "E_2 lobes at theta 0, pi/2, pi at the centres of the probes' cells vs the cell average of reference::beam_adjoint::double_symmetric (Monte-Carlo noise included), {where_}"
                ),
            },
            ErrorEstimate {
                name: "double_probe_min_second_collisions".into(),
                value: c.double_hits,
                how: "fewest second collisions the walk tallied (expected) in a probe's cell: the E_2 comparison's noise is ~1/sqrt of it (not an error)".into(),
            },
            ErrorEstimate {
                name: "total_max_rel_vs_backward_walk".into(),
                value: c.total_rel,
                how: format!(
                    "total lobe at theta pi/2 vs reference::beam_adjoint::total_symmetric ({SIDECAR_ADJOINT_SAMPLES} samples; g slices with |g| <= 0.7 only), {where_}"
                ),
            },
            ErrorEstimate {
                name: "total_max_z_vs_backward_walk".into(),
                value: c.total_z,
                how: "largest |table - reference| / reference standard error (table noise not included)".into(),
            },
            ErrorEstimate {
                name: "backward_walk_rel_std_error".into(),
                value: c.ref_rel_noise,
                how: "largest relative standard error of the backward-walk reference (its noise floor)".into(),
            },
        ];
        let albedos = self.albedo_values();
        if let Some(ai) = albedos.iter().rposition(|&a| a <= 0.5 && a > 0.0) {
            let a = albedos[ai];
            let mut worst = 0.0f64;
            let mut worst_law = 0.0f64;
            for gi in 0..self.g_values().len() {
                let (integral, tallied) = conservation(self, &table, gi, ai)?;
                worst = worst.max((integral / tallied - 1.0).abs());
                worst_law = worst_law.max((integral / (a * a / (1.0 - a)) - 1.0).abs());
            }
            errors.push(ErrorEstimate {
                name: "conservation_density_vs_tallied".into(),
                value: worst,
                how: format!(
                    "albedo {a}: |∫density dV / Σ_k α^k inside_k − 1| over the g slices (stored, quantised values)"
                ),
            });
            errors.push(ErrorEstimate {
                name: "conservation_vs_alpha2_over_1_minus_alpha".into(),
                value: worst_law,
                how: format!(
                    "albedo {a}: |∫density dV / (α²/(1−α)) − 1|: collisions of order >= 2 per photon (includes the share outside the grid)"
                ),
            });
        }
        if self.lobe == LobeKind::Full {
            let albedo = probe_albedo(self);
            let mut worst = 0.0f64;
            for g in probe_gs(self) {
                for (rho, z) in probes(self) {
                    worst = worst.max(symmetry_error(&table, albedo, g, rho, z)?.1);
                }
            }
            errors.push(ErrorEstimate {
                name: "symmetric_lobe_max_rel".into(),
                value: worst,
                how: format!(
                    "largest integral |L(theta, phi) - azimuthal mean| domega / integral L domega: the error a Symmetric table of the same walk makes (wang2018 Fig. 8), {where_}"
                ),
            });
        }
        errors.extend(generated.stats.errors.iter().cloned());
        Ok(GenStats {
            nonfinite_discarded: generated.stats.nonfinite_discarded,
            samples: generated.stats.samples,
            errors,
        })
    }

    /// Quality budgets for `voltab report`: photons from 1/64 of the table's count up to it.
    pub fn report_ladder(&self) -> Vec<(String, MsLobes)> {
        [64u64, 16, 4, 1]
            .into_iter()
            .map(|div| (self.photons / div).max(1024))
            .collect::<std::collections::BTreeSet<_>>()
            .into_iter()
            .map(|photons| (format!("photons={photons}"), MsLobes { photons, ..self.clone() }))
            .collect()
    }

    /// Curves of the report: `E_2` against the quadrature, totals against the cached backward walk.
    pub fn report_measure(&self, generated: &Generated) -> Result<Vec<(String, f64)>, CheckError> {
        let table =
            MsLobesTable::from_arrays(self, &generated.arrays, &generated.values).map_err(CheckError::Layout)?;
        let c = compare(self, &table, &cached_adjoint(400))?;
        Ok(vec![("double (E_2) vs quadrature".into(), c.double_rel), ("total vs backward walk".into(), c.total_rel)])
    }
}

/// The error of the symmetric-lobe approximation (wang2018 Sec. 4.1, Fig. 8) at canonical `(ρ, z)`, from a
/// `Full` table, with `L̄(θ)` the azimuthal average (what a symmetric table stores): (largest
/// `|L(θ, φ) − L̄(θ)|` over the lobe nodes relative to the lobe's maximum, `∫|L − L̄| dω / ∫ L dω`, angle
/// of the full lobe's peak from the symmetry axis in degrees).
pub fn symmetry_error(
    table: &MsLobesTable,
    albedo: f64,
    g: f64,
    rho: f64,
    z: f64,
) -> Result<(f64, f64, f64), LobeQueryError> {
    let (nt, np) = table.lobe_nodes();
    if np < 2 {
        return Err(LobeQueryError::Invalid("the symmetric-lobe error needs a Full lobe table".into()));
    }
    let node = |i: usize, n: usize| std::f64::consts::PI * i as f64 / (n - 1) as f64;
    let trapezoid = |i: usize, n: usize| if i == 0 || i == n - 1 { 0.5 } else { 1.0 };
    let mut worst = 0.0f64;
    let (mut l1_diff, mut l1) = (0.0f64, 0.0f64);
    let (mut peak, mut peak_theta) = (0.0f64, 0.0);
    for i in 0..nt {
        let theta = node(i, nt);
        let lobe: Vec<f64> = (0..np)
            .map(|m| table.lobe(&LobeQuery { albedo, g, rho, z, theta, phi: node(m, np) }).map(|v| v.total))
            .collect::<Result<_, _>>()?;
        // Trapezoid over φ ∈ [0, π] of the mirror-symmetric lobe = its average over the circle.
        let avg = lobe.iter().enumerate().map(|(m, v)| trapezoid(m, np) * v).sum::<f64>() / (np - 1) as f64;
        let w_theta = trapezoid(i, nt) * theta.sin();
        for (m, &v) in lobe.iter().enumerate() {
            worst = worst.max((v - avg).abs());
            l1_diff += w_theta * trapezoid(m, np) * (v - avg).abs();
            l1 += w_theta * trapezoid(m, np) * v;
            if v > peak {
                peak = v;
                peak_theta = theta;
            }
        }
    }
    if peak > 0.0 { Ok((worst / peak, l1_diff / l1, peak_theta.to_degrees())) } else { Ok((0.0, 0.0, 0.0)) }
}
