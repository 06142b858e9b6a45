use super::*;

#[test]
fn pixel_rays_project_back_to_their_pixels() {
    let cam = ViewCamera::new([1.0, 2.0, 3.0], [0.3, -0.2, -1.0], [0.0, 1.0, 0.0], 0.9, 64, 48).unwrap();
    for &(x, y) in &[(0.5, 0.5), (63.5, 47.5), (20.25, 31.75)] {
        let d = cam.ray_dir(x, y);
        assert!((d.length() - 1.0).abs() < 1e-12);
        let (q, front) = cam.project_dir(d).unwrap();
        assert!(front);
        assert!((q[0] - x).abs() < 1e-9 && (q[1] - y).abs() < 1e-9, "{q:?} vs ({x}, {y})");
        let (q2, _) = cam.project_point(cam.position + 7.0 * d).unwrap();
        assert!((q2[0] - x).abs() < 1e-9 && (q2[1] - y).abs() < 1e-9);
    }
    // The image centre looks along `forward`; the top edge is yfov/2 above it.
    let c = cam.ray_dir(32.0, 24.0);
    assert!((c - cam.forward).length() < 1e-12);
    let top = cam.ray_dir(32.0, 0.0);
    assert!((top.dot(cam.forward).acos() - 0.45).abs() < 1e-12);
    // A direction behind the camera projects with `front = false`; one across the view axis not at all.
    assert!(!cam.project_dir(-cam.forward).unwrap().1);
    assert!(cam.project_dir(cam.right).is_none());
}

#[test]
fn degenerate_cameras_are_rejected() {
    assert!(ViewCamera::new([0.0; 3], [0.0, 0.0, 0.0], [0.0, 1.0, 0.0], 1.0, 8, 8).is_none());
    assert!(ViewCamera::new([0.0; 3], [0.0, 1.0, 0.0], [0.0, 2.0, 0.0], 1.0, 8, 8).is_none());
    assert!(ViewCamera::new([0.0; 3], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0], 0.0, 8, 8).is_none());
    assert!(ViewCamera::new([f64::NAN, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0], 1.0, 8, 8).is_none());
    assert!(ViewCamera::new([0.0; 3], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0], 1.0, 0, 8).is_none());
}
