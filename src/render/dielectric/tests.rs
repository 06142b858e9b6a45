use super::*;

#[test]
fn emitter_intersection_and_intensity() {
    let e = Emitter { center: DVec3::new(0.0, 0.0, 5.0), radius: 1.0, radiance: [2.0; 3] };
    assert!((e.intersect(DVec3::ZERO, DVec3::Z, 0.0).unwrap() - 4.0).abs() < 1e-12);
    assert!(e.intersect(DVec3::ZERO, -DVec3::Z, 0.0).is_none());
    assert!((e.intersect(DVec3::new(0.0, 0.0, 5.0), DVec3::Z, 0.0).unwrap() - 1.0).abs() < 1e-12);
    assert!((e.intensity()[0] - 2.0 * std::f64::consts::PI).abs() < 1e-12);
}

#[test]
fn presets_scale_mean_free_paths() {
    let wax = Material::preset("Wax", 0.01, 1.5).unwrap();
    assert!((wax.sigma_t[0] - 1.0 / 0.006536).abs() < 1e-9);
    assert!(wax.check().is_ok());
    assert!(Material::preset("Jelly", 1.0, 1.5).is_none());
}
