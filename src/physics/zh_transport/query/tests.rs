use super::*;
use crate::physics::zh_transport::{ResponseConfig, compute};
use crate::reference::walk;

fn response(kind: EmitterKind, g: f64, bounces: usize) -> Response {
    let distances: Vec<f64> = (0..64).map(|i| 1e-3 * (32e3f64).powf(f64::from(i) / 63.0)).collect();
    let cfg = ResponseConfig { bounces, ..ResponseConfig::new(g, distances) };
    compute(kind, &cfg).unwrap()
}

/// The canonical medium with unit strength reproduces the canonical query exactly.
#[test]
fn canonical_medium_is_the_identity() {
    let r = response(EmitterKind::Point, 0.3, 3);
    let s = r.irradiance_in(&HomogeneousMedium { sigma_s: 1.0, sigma_a: 0.0, g: 0.3 }, 1.0, 1.7, 0.4).unwrap();
    let (d, single, multiple) = r.irradiance(1.7, 0.4);
    assert!((s.direct - d).abs() <= 1e-15 * d && (s.single - single).abs() <= 1e-15 * single);
    assert!((s.multiple - multiple).abs() <= 1e-14 * multiple);
}

/// σ-ratio remapping with absorption against the independent random walk in the real medium:
/// σ_s = 2/m, σ_a = 0.5/m, g = 0.5, emitter 0.6 m away (1.5 mean free paths).
#[test]
fn remapped_query_matches_the_walk_in_a_real_medium() {
    let medium = walk::Medium { sigma_s: 2.0, sigma_a: 0.5, g: 0.5 };
    for kind in [EmitterKind::Point, EmitterKind::Directional] {
        let r = response(kind, 0.5, 6);
        let emitter = match kind {
            EmitterKind::Point => walk::Emitter::Point { intensity: 3.0, position: [0.0, 0.0, 0.6] },
            EmitterKind::Directional => {
                walk::Emitter::Directional { irradiance: 3.0, toward_light: [0.0, 0.0, 1.0], depth: 0.6 }
            }
        };
        for cos_n in [1.0, 0.0] {
            let normal = [(1.0f64 - cos_n * cos_n).sqrt(), 0.0, cos_n];
            let w = walk::irradiance(&emitter, &medium, normal, &walk::WalkConfig::new(200_000, 6, 11)).unwrap();
            let q =
                r.irradiance_in(&HomogeneousMedium { sigma_s: 2.0, sigma_a: 0.5, g: 0.5 }, 3.0, 0.6, cos_n).unwrap();
            assert!((q.direct - w.direct).abs() <= 1e-12 * w.direct.max(1e-300), "{kind:?} direct");
            let single = w.orders[0];
            let err = (q.single - single.mean).abs();
            assert!(
                err <= 0.03 * single.mean && err <= 4.0 * single.std_error + 1e-3 * single.mean,
                "{kind:?} cos {cos_n}: single {} vs {single:?}",
                q.single
            );
            let multiple: f64 = w.orders[1..].iter().map(|o| o.mean).sum();
            let var: f64 = w.orders[1..].iter().map(|o| o.std_error * o.std_error).sum();
            let err = (q.multiple - multiple).abs();
            assert!(
                err <= 0.06 * multiple && err <= 4.0 * var.sqrt() + 0.01 * multiple,
                "{kind:?} cos {cos_n}: multiple {} vs {multiple} ± {}",
                q.multiple,
                var.sqrt()
            );
        }
    }
}

#[test]
fn limits_and_bad_input() {
    let r = response(EmitterKind::Point, 0.0, 2);
    // No scattering: only the attenuated direct term remains.
    let s = r.irradiance_in(&HomogeneousMedium { sigma_s: 0.0, sigma_a: 2.0, g: 0.0 }, 1.0, 0.5, 1.0).unwrap();
    assert_eq!((s.single, s.multiple), (0.0, 0.0));
    assert!((s.direct - 4.0 * (-1.0f64).exp()).abs() < 1e-15);
    // Vacuum: inverse-square law, nothing scattered.
    let s = r.irradiance_in(&HomogeneousMedium { sigma_s: 0.0, sigma_a: 0.0, g: 0.0 }, 2.0, 2.0, 0.5).unwrap();
    assert_eq!(s, Split { direct: 0.25, single: 0.0, multiple: 0.0 });
    // σ_a ≫ σ_s: everything finite, non-negative, and scattering tiny.
    let s = r.irradiance_in(&HomogeneousMedium { sigma_s: 1e-6, sigma_a: 1e3, g: 0.0 }, 1.0, 0.01, -0.3).unwrap();
    assert!(s.total().is_finite() && s.single >= 0.0 && s.multiple >= 0.0 && s.direct == 0.0);
    // Far beyond the table: exponential tail, finite and below the nearer value.
    let far = r.irradiance_in(&HomogeneousMedium { sigma_s: 1.0, sigma_a: 0.0, g: 0.0 }, 1.0, 500.0, 1.0).unwrap();
    let near = r.irradiance_in(&HomogeneousMedium { sigma_s: 1.0, sigma_a: 0.0, g: 0.0 }, 1.0, 30.0, 1.0).unwrap();
    assert!(far.total().is_finite() && far.total() <= near.total());
    for bad in [f64::NAN, -1.0, f64::INFINITY] {
        assert!(r.irradiance_in(&HomogeneousMedium { sigma_s: bad, sigma_a: 0.0, g: 0.0 }, 1.0, 1.0, 1.0).is_err());
        assert!(r.irradiance_in(&HomogeneousMedium { sigma_s: 1.0, sigma_a: 0.0, g: 0.0 }, 1.0, bad, 1.0).is_err());
    }
    let unit = HomogeneousMedium { sigma_s: 1.0, sigma_a: 0.0, g: 0.0 };
    assert_eq!(r.irradiance_in(&unit, 1.0, 0.0, 1.0), Err(SplitError::PointAtZero));
    let e = r.irradiance_in(&unit, 1.0, 1.0, f64::NAN).unwrap_err();
    assert_eq!(e.to_string(), "cos_n = NaN must be finite");
    let e = r.irradiance_in(&unit, -2.0, 1.0, 1.0).unwrap_err();
    assert_eq!(e.to_string(), "strength = -2 must be finite and >= 0");
    let e = r.irradiance_in(&HomogeneousMedium { g: 1.0, ..unit }, 1.0, 1.0, 1.0).unwrap_err();
    assert_eq!(e, SplitError::Medium(MediumError::G(1.0)));
}

/// Sec. 4.4: the effective coefficient reproduces the transmittance of piecewise media exactly.
#[test]
fn effective_sigma_is_exact_for_transmittance() {
    let segments = [(0.5, 2.0), (1.5, 0.1), (0.25, 8.0)];
    let eff = effective_sigma(&segments);
    let length: f64 = segments.iter().map(|s| s.0).sum();
    let product: f64 = segments.iter().map(|s| (-s.0 * s.1).exp()).product();
    assert!(((-eff * length).exp() - product).abs() < 1e-15);
    assert_eq!(effective_sigma(&[]), 0.0);
}
