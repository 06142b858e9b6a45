use crate::scene::{Light, LightKind, Scene, SceneFormat};
use std::path::Path;

#[test]
fn global_box_is_the_padded_bounds_of_lights_and_meshes() {
    let mut s = Scene::empty(Path::new("t.gltf"), SceneFormat::Gltf);
    assert_eq!(s.global_medium_bounds(), None);
    for p in [[0.0, 0.0, 0.0], [3.0, 4.0, 0.0]] {
        s.lights.push(Light { name: "p".into(), kind: LightKind::Point { position: p }, radiance: [1.0; 3] });
    }
    // Diagonal 5 m → padding 0.05 + 0.001 m on each side.
    let (lo, hi) = s.global_medium_bounds().unwrap();
    for (a, b) in lo.iter().zip([-0.051, -0.051, -0.051]) {
        assert!((a - b).abs() < 1e-12, "{lo:?}");
    }
    for (a, b) in hi.iter().zip([3.051, 4.051, 0.051]) {
        assert!((a - b).abs() < 1e-12, "{hi:?}");
    }
}
