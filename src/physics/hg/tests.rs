#[test]
fn pop_partition_sums_to_one_and_has_exact_limits() {
    for &a in &[-1.0, -0.999_999, -0.5, -1e-12, 0.0, 1e-12, 0.3, 0.9, 0.99, 0.999_999, 1.0] {
        let [f, s, b] = pop_partition(a);
        assert!((f + 4.0 * s + b - 1.0).abs() < 4e-16, "a = {a}");
        assert!(f >= 0.0 && s >= 0.0 && b >= 0.0);
    }
    // Isotropic: solid-angle fractions of the cones, 2π(1 − cos π/4)/4π each.
    let cone = (1.0 - std::f64::consts::FRAC_1_SQRT_2) / 2.0;
    let [f, s, b] = pop_partition(0.0);
    assert!((f - cone).abs() < 1e-16 && (b - cone).abs() < 1e-16);
    assert!((s - std::f64::consts::FRAC_1_SQRT_2 / 4.0).abs() < 1e-16);
    assert_eq!(pop_partition(1.0), [1.0, 0.0, 0.0]);
    assert_eq!(pop_partition(-1.0), [0.0, 0.0, 1.0]);
    // Mirror symmetry and the a → 1 limit: the back cone of HG(a) holds
    // (1 − a)²(1 + a)·(…) → 0 quadratically; front → 1 continuously.
    let [f1, _, b1] = pop_partition(0.7);
    let [f2, _, b2] = pop_partition(-0.7);
    assert!((f1 - b2).abs() < 1e-15 && (b1 - f2).abs() < 1e-15);
    assert!(pop_partition(0.999_999)[0] > 0.999_99);
    assert!(pop_partition(f64::NAN)[0].is_nan());
}

use super::*;

/// The sampler form given in the design brief (valid for `g ≥ 0`):
/// `μ = [−(1 − g)² + (1 + g²)(2ξ(1 − g) + 2gξ²)] / D²`. Used only to confirm the identity.
fn brief_sample_form(xi: f64, g: f64) -> f64 {
    let d = 1.0 - g + 2.0 * g * xi;
    (-(1.0 - g) * (1.0 - g) + (1.0 + g * g) * (2.0 * xi * (1.0 - g) + 2.0 * g * xi * xi)) / (d * d)
}

#[test]
fn invalid_g_gives_nan_and_an_error_without_panicking() {
    for g in [1.0, -1.0, 1.5, -7.0, f64::INFINITY, f64::NEG_INFINITY, f64::NAN] {
        assert!(validate_g(g).is_err(), "{g}");
        assert!(phase(0.3, g).is_nan());
        assert!(cdf(0.3, g).is_nan());
        assert!(cdf_per_azimuth(0.3, g).is_nan());
        assert!(sample_mu(0.3, g).is_nan());
        assert!(legendre_moment(3, g).is_nan());
        assert!(zh_coefficient(3, g).is_nan());
    }
    for g in [0.0, -0.0, 0.5, -0.999_999_999, 1e-300, f64::MIN_POSITIVE] {
        assert!(validate_g(g).is_ok(), "{g}");
    }
    assert!(validate_g(2.0).unwrap_err().contains("got 2"));
}

#[test]
fn out_of_range_arguments_are_clamped_and_nan_propagates() {
    for g in [-0.7, 0.0, 0.3] {
        assert_eq!(phase(3.0, g), phase(1.0, g));
        assert_eq!(phase(-f64::INFINITY, g), phase(-1.0, g));
        assert_eq!(cdf(2.0, g), 1.0);
        assert_eq!(cdf(-2.0, g), 0.0);
        assert_eq!(sample_mu(-0.5, g), -1.0);
        assert_eq!(sample_mu(f64::INFINITY, g), 1.0);
        assert!(phase(f64::NAN, g).is_nan());
        assert!(cdf(f64::NAN, g).is_nan());
        assert!(sample_mu(f64::NAN, g).is_nan());
    }
    assert!(legendre_p(3, f64::NAN).is_nan());
    // Far outside [−1, 1] the polynomial overflows (to ±∞, then inf − inf = NaN) without
    // panicking.
    assert!(!legendre_p(200, 1e10).is_finite());
}

#[test]
fn isotropic_limit_is_exact() {
    let inv4pi = 1.0 / (4.0 * PI);
    for mu in [-1.0, -0.25, 0.0, 0.5, 1.0] {
        assert_eq!(phase(mu, 0.0), inv4pi);
        assert!((cdf(mu, 0.0) - 0.5 * (1.0 + mu)).abs() <= f64::EPSILON);
    }
    for xi in [0.0, 0.125, 0.5, 0.875, 1.0] {
        assert_eq!(sample_mu(xi, 0.0), 2.0 * xi - 1.0);
    }
}

#[test]
fn endpoints_are_exact() {
    for g in [-0.999_999, -0.5, -1e-9, 0.0, 1e-9, 0.5, 0.999_999] {
        assert_eq!(cdf(-1.0, g), 0.0);
        assert_eq!(cdf(1.0, g), 1.0);
        assert_eq!(cdf_per_azimuth(1.0, g), 1.0 / TAU);
        assert_eq!(sample_mu(0.0, g), -1.0);
        assert_eq!(sample_mu(1.0, g), 1.0);
    }
}

#[test]
fn mirror_symmetries_hold_to_rounding() {
    for g in [-0.95, -0.3, 0.2, 0.9] {
        for mu in [-1.0, -0.6, 0.0, 0.4, 0.999] {
            let a = phase(mu, g);
            assert!((a - phase(-mu, -g)).abs() <= 4.0 * f64::EPSILON * a);
            assert!((cdf(mu, g) + cdf(-mu, -g) - 1.0).abs() <= 4.0 * f64::EPSILON);
        }
        for xi in [0.0, 0.25, 0.5, 0.625, 1.0] {
            let s = sample_mu(xi, g) + sample_mu(1.0 - xi, -g);
            assert!(s.abs() <= 4.0 * f64::EPSILON, "{xi} {g} {s}");
        }
    }
}

#[test]
fn sampler_agrees_with_the_brief_numerator_form_where_that_is_stable() {
    // The brief's form cancels only where μ ≈ 0 in absolute terms (fine) and for g < 0 near
    // ξ = 1; for g ≥ 0 both are few-ulp accurate in absolute terms.
    for g in [0.0, 1e-8, 0.1, 0.5, 0.9, 0.999_999] {
        for i in 0..=64 {
            let xi = f64::from(i) / 64.0;
            let d = (sample_mu(xi, g) - brief_sample_form(xi, g)).abs();
            assert!(d <= 1e-15, "g={g} xi={xi} diff={d}");
        }
    }
}

#[test]
fn legendre_p_matches_closed_forms() {
    for x in [-1.0, -0.3, 0.0, 0.7, 1.0] {
        assert_eq!(legendre_p(0, x), 1.0);
        assert_eq!(legendre_p(1, x), x);
        let p2 = 0.5 * (3.0 * x * x - 1.0);
        let p3 = 0.5 * (5.0 * x * x * x - 3.0 * x);
        assert!((legendre_p(2, x) - p2).abs() < 1e-15);
        assert!((legendre_p(3, x) - p3).abs() < 1e-15);
    }
    for l in [0, 1, 7, 64, 1000] {
        assert!((legendre_p(l, 1.0) - 1.0).abs() < 1e-12);
        let sign = if l % 2 == 0 { 1.0 } else { -1.0 };
        assert!((legendre_p(l, -1.0) - sign).abs() < 1e-12);
    }
}

#[test]
fn moments_and_zh_coefficients() {
    assert_eq!(legendre_moment(0, 0.0), 1.0);
    assert_eq!(legendre_moment(0, -0.9), 1.0);
    assert_eq!(legendre_moment(3, -0.5), -0.125);
    assert!((legendre_moment(64, 0.9) - 0.9f64.powi(64)).abs() < 1e-16);
    assert_eq!(legendre_moment(u32::MAX, 0.5), 0.0);
    assert!((zh_coefficient(0, 0.3) - 1.0 / (2.0 * PI.sqrt())).abs() < 1e-16);
    let expect = (3.0 / (4.0 * PI)).sqrt() * 0.3;
    assert!((zh_coefficient(1, 0.3) - expect).abs() < 1e-16);
}
