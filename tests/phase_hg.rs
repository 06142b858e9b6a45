//! PhaseHg tables judged by invariants derived independently of the generator: normalisation,
//! consistency of the stored cumulative with the integral of the stored phase, sample-vs-pdf
//! consistency (chi-square) of the stored inverse CDF, Legendre moments against quadrature of the
//! stored phase, and node accuracy against the double-double reference at extreme g.

use voltab::physics::hg;
use voltab::reference::hg_hp;
use voltab::tables::phase_hg::{Element, GValues, MuSpacing, PhaseHg, PhaseHgTable};

fn table(g: &[f64], bins: u32, spacing: MuSpacing, element: Element) -> PhaseHgTable {
    let def = PhaseHg {
        g: GValues::List(g.to_vec()),
        mu_bins: bins,
        xi_bins: bins,
        mu_spacing: spacing,
        element,
        ..PhaseHg::default()
    };
    let gn = def.generate(&[7; 32], &|_| {}).unwrap();
    PhaseHgTable::from_arrays(&gn.arrays, &gn.values).unwrap()
}

/// ∫ f dω = 2π ∫ f dμ = 1: trapezoid over the stored nodes; for g ≤ 0.5 the lobe is smooth and
/// 4097 linear nodes integrate it to ~1e-6 (trapezoid error ~ h² f''/12).
#[test]
fn stored_phase_is_normalised() {
    let gs = [-0.5, 0.0, 0.3, 0.5];
    let t = table(&gs, 4097, MuSpacing::Linear, Element::F64);
    for (gi, g) in gs.iter().enumerate() {
        let n = 4097;
        let h = 2.0 / (n - 1) as f64;
        let mut s = 0.0;
        for i in 0..n {
            let mu = -1.0 + h * i as f64;
            let w = if i == 0 || i == n - 1 { 0.5 } else { 1.0 };
            s += w * t.phase_lerp(gi, mu).unwrap();
        }
        let total = 2.0 * std::f64::consts::PI * s * h;
        assert!((total - 1.0).abs() < 2e-6, "g = {g}: ∫f dω = {total}");
    }
}

/// F_hg(μ) − F_hg(μ') = ∫_{μ'}^{μ} f dμ: Simpson on the analytic phase between stored nodes.
#[test]
fn stored_cumulative_matches_integral_of_phase() {
    let gs = [-0.9, 0.0, 0.7];
    let t = table(&gs, 257, MuSpacing::Linear, Element::F64);
    for (gi, &g) in gs.iter().enumerate() {
        for k in 0..256 {
            let (a, b) = (-1.0 + 2.0 * k as f64 / 256.0, -1.0 + 2.0 * (k + 1) as f64 / 256.0);
            let m = 1024;
            let h = (b - a) / m as f64;
            let simpson: f64 = (0..=m)
                .map(|i| {
                    let w = if i == 0 || i == m {
                        1.0
                    } else if i % 2 == 1 {
                        4.0
                    } else {
                        2.0
                    };
                    w * hg::phase(a + h * i as f64, g)
                })
                .sum::<f64>()
                * h
                / 3.0;
            let diff = t.cdf_per_azimuth_lerp(gi, b).unwrap() - t.cdf_per_azimuth_lerp(gi, a).unwrap();
            assert!((diff - simpson).abs() <= 1e-12 + 1e-9 * simpson, "g {g} cell {k}: {diff} vs {simpson}");
        }
    }
}

/// Chi-square of the stored inverse CDF as a sampler: 2^16 stratified ξ mapped through the table
/// and binned into 32 bins of equal probability under the exact CDF. With linear interpolation on
/// 4096 ξ nodes the bias is far below the statistical noise; stratification makes counts nearly
/// exact, so even a loose 31-dof bound (99.9 %: 61.1) is a strong test.
#[test]
fn stored_inverse_cdf_samples_the_phase_function() {
    let gs = [-0.9, 0.0, 0.5, 0.99];
    let t = table(&gs, 4096, MuSpacing::Linear, Element::F32);
    for (gi, &g) in gs.iter().enumerate() {
        let n = 1 << 16;
        let mut bins = [0u32; 32];
        for k in 0..n {
            let xi = (k as f64 + 0.5) / n as f64;
            let mu = t.sample_mu_lerp(gi, xi).unwrap();
            let c = hg::cdf(mu, g);
            bins[((c * 32.0) as usize).min(31)] += 1;
        }
        let e = n as f64 / 32.0;
        let chi2: f64 = bins.iter().map(|&b| (f64::from(b) - e).powi(2) / e).sum();
        assert!(chi2 < 61.1, "g = {g}: chi2 = {chi2}, bins {bins:?}");
    }
}

/// The stored Legendre moments equal the moments of the stored phase (quadrature in double-double
/// reference code), and the ZH coefficients carry the documented normalisation.
#[test]
fn legendre_and_zh_coefficients_match_quadrature() {
    let gs = [-0.999, -0.3, 0.0, 0.8, 0.999];
    let t = table(&gs, 64, MuSpacing::Linear, Element::F64);
    for (gi, &g) in gs.iter().enumerate() {
        let zh = t.zh(gi).unwrap();
        assert_eq!(zh.len(), 33);
        for l in [0u32, 1, 2, 7, 32] {
            let q = hg_hp::legendre_moment_quadrature(l, g);
            let norm = ((2 * l + 1) as f64 / (4.0 * std::f64::consts::PI)).sqrt();
            assert!((zh[l as usize] / norm - q).abs() < 1e-12, "g {g} l {l}: {} vs {q}", zh[l as usize] / norm);
        }
    }
}

/// The smallest ZH order the range allows (`zh_order: 0`, a table that keeps only l = 0): the one
/// stored coefficient is Y₀₀ = 1/√(4π) for every g (the phase integrates to one), and the error
/// report probes only the orders stored (it indexed l = 1, 2 past the end before).
#[test]
fn zh_order_zero_stores_y00_and_reports_its_errors() {
    let def = PhaseHg {
        g: GValues::List(vec![-0.99, 0.0, 0.99]),
        mu_bins: 64,
        xi_bins: 64,
        zh_order: 0,
        element: Element::F64,
        ..PhaseHg::default()
    };
    let gn = def.generate(&[7; 32], &|_| {}).unwrap();
    let t = PhaseHgTable::from_arrays(&gn.arrays, &gn.values).unwrap();
    for gi in 0..3 {
        let zh = t.zh(gi).unwrap();
        assert_eq!(zh.len(), 1);
        assert!((zh[0] - 1.0 / (4.0 * std::f64::consts::PI).sqrt()).abs() < 1e-15, "{zh:?}");
    }
    let errors = t.error_estimates(&[7; 32]);
    let legendre = errors.iter().find(|e| e.name.contains("legendre")).expect("a Legendre-moment estimate");
    assert!(legendre.value < 1e-12, "{legendre:?}");
    assert!(errors.iter().all(|e| e.value.is_finite()), "{errors:?}");
}

/// Node accuracy at the extremes: F64 tables within 1e-13 of the double-double closed forms,
/// F32 tables within f32 rounding (2^-24 ≈ 6e-8).
#[test]
fn nodes_are_accurate_at_extreme_g() {
    let gs = [-0.999_999, -0.999, -1e-9, 0.0, 1e-9, 0.999, 0.999_999];
    for (element, tol) in [(Element::F64, 1e-13), (Element::F32, 6.0e-8)] {
        let def = PhaseHg {
            g: GValues::List(gs.to_vec()),
            mu_bins: 512,
            xi_bins: 512,
            mu_spacing: MuSpacing::UniformAngle,
            element,
            ..PhaseHg::default()
        };
        let gn = def.generate(&[1; 32], &|_| {}).unwrap();
        let stats = def.estimate_errors(&gn, &[1; 32]).unwrap();
        let get = |n: &str| stats.errors.iter().find(|e| e.name == n).unwrap().value;
        assert!(get("phase_node_max_rel") <= tol, "{element:?}: phase {:e}", get("phase_node_max_rel"));
        assert!(get("cdf_node_max_rel") <= tol, "{element:?}: cdf {:e}", get("cdf_node_max_rel"));
        assert!(get("inv_cdf_node_max_abs") <= tol, "{element:?}: inv {:e}", get("inv_cdf_node_max_abs"));
        assert!(get("legendre_max_abs") <= tol.max(1e-12), "{element:?}: legendre {:e}", get("legendre_max_abs"));
        // Sampler check: |E[μ] − g| within 4σ of the Monte-Carlo noise (σ ≤ sqrt(1/3)/256 ≈ 0.0023).
        assert!(get("sampler_mean_cosine_abs") < 0.009, "{element:?}: sampler {:e}", get("sampler_mean_cosine_abs"));
    }
}

/// Interpolated lookups converge: halving the cell size cuts the error of a smooth lobe by ~4
/// (linear interpolation is second order).
#[test]
fn lookup_error_converges_at_second_order() {
    let e = |bins| table(&[0.5], bins, MuSpacing::Linear, Element::F64).phase_lookup_error(0, 2048).unwrap();
    let (coarse, fine) = (e(256), e(512));
    let order = (coarse / fine).log2();
    assert!((1.8..2.2).contains(&order), "observed order {order} ({coarse:e} → {fine:e})");
}

#[test]
fn uniform_angle_spacing_resolves_peaked_lobes_better() {
    let lin = table(&[0.99], 1024, MuSpacing::Linear, Element::F64).phase_lookup_error(0, 2048).unwrap();
    let ang = table(&[0.99], 1024, MuSpacing::UniformAngle, Element::F64).phase_lookup_error(0, 2048).unwrap();
    assert!(ang < lin / 10.0, "uniform-angle {ang:e} vs linear {lin:e}");
}

/// Regression: grid g values came out as -0.7999999999999999, which showed in plot legends and
/// made `PlotPhase(g: [-0.8])` depend on float noise.
#[test]
fn grid_values_land_on_the_decimals_a_person_wrote() {
    let g = GValues::Grid { min: -0.9, max: 0.9, count: 19 }.values();
    assert_eq!(g.len(), 19);
    assert_eq!(g[1], -0.8);
    assert_eq!(g[9], 0.0);
    assert_eq!(g[12], 0.3);
    assert_eq!(g[18], 0.9);
    assert!(g.windows(2).all(|w| w[0] < w[1]));
}
