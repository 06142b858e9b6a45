use super::*;

#[test]
fn domain_edges_are_accepted_and_everything_outside_is_named() {
    let m = HomogeneousMedium { sigma_s: 0.0, sigma_a: 0.0, g: 0.0 };
    assert_eq!(m.checked(), Ok((0.0, 0.0)));
    assert_eq!(m.albedo(), 0.0, "a vacuum has albedo 0, not NaN");
    let near_one = HomogeneousMedium { sigma_s: 1e300, sigma_a: 0.0, g: 1.0 - f64::EPSILON };
    assert_eq!(near_one.checked(), Ok((1e300, 0.0)));
    assert_eq!(near_one.albedo(), 1.0);
    for (bad, name) in [(f64::NAN, "sigma_s"), (-1e-300, "sigma_s"), (f64::INFINITY, "sigma_s")] {
        let e = HomogeneousMedium { sigma_s: bad, ..m }.checked().unwrap_err();
        assert!(matches!(e, MediumError::Coefficient { name: n, .. } if n == name), "{e}");
    }
    let e = HomogeneousMedium { sigma_a: -2.0, ..m }.checked().unwrap_err();
    assert_eq!(e.to_string(), "sigma_a = -2 must be finite and >= 0");
    for g in [1.0, -1.0, f64::NAN, f64::NEG_INFINITY] {
        assert!(matches!(HomogeneousMedium { g, ..m }.checked(), Err(MediumError::G(_))), "g = {g}");
    }
}

#[test]
fn albedo_and_extinction_are_the_remapping_of_sec_4_3() {
    // σ_s = 3, σ_a = 1: σ_t = 4, α = 3/4 exactly in binary floating point.
    let m = HomogeneousMedium { sigma_s: 3.0, sigma_a: 1.0, g: 0.5 };
    assert_eq!(m.sigma_t(), 4.0);
    assert_eq!(m.albedo(), 0.75);
    assert_eq!(HomogeneousMedium { sigma_s: 0.0, sigma_a: 5.0, g: 0.0 }.albedo(), 0.0);
    assert_eq!(HomogeneousMedium { sigma_s: 5.0, sigma_a: 0.0, g: -0.9 }.albedo(), 1.0);
}

#[test]
fn free_flight_inverts_the_extinguished_fraction_even_where_it_is_tiny() {
    // Analytic: extinguished(σ, L) = 1 − e^{−σL}; at σL = 1e-12 the naive 1 − exp(−x) keeps ~4 digits.
    for (sigma, length) in [(1e-12, 1.0), (2.0, 0.5), (1.0, 30.0), (1e3, 1e-3)] {
        let mass = extinguished(sigma, length);
        let x: f64 = sigma * length;
        let want = if x < 1e-6 { x - x * x / 2.0 } else { 1.0 - (-x).exp() };
        assert!((mass - want).abs() <= 4.0 * f64::EPSILON * want, "σL = {x}: {mass} vs {want}");
        // The inverse is conditioned by 1/(σ(1 − mass)): one ulp of `mass` near 1 moves t by ε/(σe^{−σL}).
        let back = free_flight(mass, sigma);
        let tol = 1e-12 * length + f64::EPSILON / (sigma * (1.0 - mass));
        assert!((back - length).abs() <= tol, "σL = {x}: {back} vs {length} ± {tol}");
    }
    // The median free flight is ln 2 / σ_t.
    assert!((free_flight(0.5, 4.0) - std::f64::consts::LN_2 / 4.0).abs() < 1e-16);
    // Edges: nothing extinguished over zero length; the whole beam at an infinite one.
    assert_eq!(extinguished(3.0, 0.0), 0.0);
    assert_eq!(extinguished(3.0, f64::INFINITY), 1.0);
    assert_eq!(free_flight(0.0, 3.0), 0.0);
    assert_eq!(free_flight(1.0, 3.0), f64::INFINITY);
    assert_eq!(free_flight(0.25, 0.0), f64::INFINITY);
}
