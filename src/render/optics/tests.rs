use super::*;

#[test]
fn fresnel_limits() {
    // Normal incidence: ((n1 − n2)/(n1 + n2))² = 0.04 for 1 → 1.5.
    assert!((fresnel(1.0, 1.0, 1.5) - 0.04).abs() < 1e-12);
    assert!((fresnel(1.0, 1.5, 1.0) - 0.04).abs() < 1e-12);
    // Grazing: total reflection; index matched: none.
    assert!((fresnel(0.0, 1.0, 1.5) - 1.0).abs() < 1e-12);
    assert!(fresnel(0.3, 1.3, 1.3) < 1e-15);
    // Beyond the critical angle asin(1/1.5) from inside.
    let cos_c = (1.0 - 1.0 / 2.25f64).sqrt();
    assert_eq!(fresnel(cos_c - 1e-6, 1.5, 1.0), 1.0);
    assert!(fresnel(cos_c + 1e-3, 1.5, 1.0) < 1.0);
}

#[test]
fn refraction_obeys_snell_and_reversibility() {
    let n = DVec3::Z;
    let d = DVec3::new(0.6, 0.0, -0.8);
    let t = refract(d, n, 1.0, 1.5).unwrap();
    let (sin_i, sin_t) = (d.x.abs(), t.x.abs());
    assert!((sin_i - 1.5 * sin_t).abs() < 1e-12);
    let back = refract(-t, n, 1.5, 1.0).unwrap();
    assert!((back + d).length() < 1e-12);
    assert!(refract(DVec3::new(0.9, 0.0, 0.43589).normalize(), n, 1.5, 1.0).is_none());
}

#[test]
fn the_cosine_form_is_1_where_both_cosines_vanish() {
    assert_eq!(fresnel_cos(0.0, 0.0, 1.0, 1.5), 1.0);
    // Normal incidence through the cosine form: 0.04 for 1 → 1.5.
    assert!((fresnel_cos(1.0, 1.0, 1.0, 1.5) - 0.04).abs() < 1e-12);
}
