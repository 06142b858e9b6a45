use super::*;
use crate::scene::fixtures;

#[test]
fn unit_cube_volume_and_containment() {
    let cube = fixtures::cube("c", 1.0);
    assert!((signed_volume(&cube) - 1.0).abs() < 1e-6, "{}", signed_volume(&cube));
    assert!(contains(&cube, DVec3::new(0.5, 0.5, 0.5)));
    assert!(contains(&cube, DVec3::new(0.01, 0.99, 0.5)));
    assert!(!contains(&cube, DVec3::new(1.01, 0.5, 0.5)));
    assert!(!contains(&cube, DVec3::new(-0.5, 0.5, 0.5)));
}

#[test]
fn frames_are_right_handed() {
    for n in [DVec3::Z, DVec3::X, unit(DVec3::new(1.0, -2.0, 0.5)).unwrap()] {
        let (t, b) = frame(n);
        assert!((t.cross(b) - n).abs().max_element() < 1e-12, "{n:?}");
        assert!(t.dot(n).abs() < 1e-12 && b.dot(n).abs() < 1e-12);
    }
}
