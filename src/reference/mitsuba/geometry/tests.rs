use super::*;
use crate::scene::fixtures;

#[test]
fn unit_cube_volume_and_containment() {
    let cube = fixtures::cube("c", 1.0);
    assert!((signed_volume(&cube) - 1.0).abs() < 1e-6, "{}", signed_volume(&cube));
    assert!(contains(&cube, [0.5, 0.5, 0.5]));
    assert!(contains(&cube, [0.01, 0.99, 0.5]));
    assert!(!contains(&cube, [1.01, 0.5, 0.5]));
    assert!(!contains(&cube, [-0.5, 0.5, 0.5]));
}

#[test]
fn frames_are_right_handed() {
    for n in [[0.0, 0.0, 1.0], [1.0, 0.0, 0.0], unit([1.0, -2.0, 0.5]).unwrap()] {
        let (t, b) = frame(n);
        let c = cross(t, b);
        assert!((0..3).all(|k| (c[k] - n[k]).abs() < 1e-12), "{n:?}");
        assert!(dot(t, n).abs() < 1e-12 && dot(b, n).abs() < 1e-12);
    }
}
