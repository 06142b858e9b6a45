use super::*;

#[test]
fn falloff_is_one_inside_the_inner_cone_zero_outside_the_outer_and_khr_between() {
    let c = SpotCone::khr(DVec3::new(0.0, 0.0, -2.0), 0.2, 0.5).unwrap();
    assert_eq!(c.axis, DVec3::NEG_Z);
    let at = |theta: f64| c.falloff(DVec3::new(theta.sin(), 0.0, -theta.cos()));
    assert_eq!(at(0.0), 1.0);
    assert_eq!(at(0.19), 1.0);
    assert_eq!(at(0.51), 0.0);
    assert_eq!(at(std::f64::consts::PI), 0.0);
    // Between the cones: ((cos θ − cos 0.5) / (cos 0.2 − cos 0.5))², written out.
    let want = ((0.35f64.cos() - 0.5f64.cos()) / (0.2f64.cos() - 0.5f64.cos())).powi(2);
    assert!((at(0.35) - want).abs() < 1e-12, "{} vs {want}", at(0.35));
}

#[test]
fn a_hard_edged_cone_ramps_over_the_floor_and_bad_input_has_no_cone() {
    let c = SpotCone::khr(DVec3::X, 0.4, 0.4).unwrap();
    assert_eq!(c.inv_range, 1.0 / MIN_COS_RANGE);
    let w = |theta: f64| DVec3::new(theta.cos(), theta.sin(), 0.0);
    assert_eq!(c.falloff(w(0.39)), 1.0, "10⁻³ in cosine is ~0.0026 rad at 0.4 rad");
    assert_eq!(c.falloff(w(0.4)), 0.0);
    assert!(c.falloff(w(0.399)).is_finite());
    assert_eq!(SpotCone::khr(DVec3::ZERO, 0.1, 0.2), None);
    assert_eq!(SpotCone::khr(DVec3::splat(f64::NAN), 0.1, 0.2), None);
    assert_eq!(SpotCone::khr(DVec3::Y, f64::INFINITY, 0.2), None);
}
