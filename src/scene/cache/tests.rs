use super::*;

fn scenes_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes")
}

#[test]
fn a_scene_is_imported_once_however_its_path_is_spelt() {
    let cache = SceneCache::default();
    let a = cache.load(&scenes_dir().join("fog_room.gltf")).unwrap();
    let b = cache.load(&scenes_dir().join("../scenes/./fog_room.gltf")).unwrap();
    assert!(Arc::ptr_eq(&a, &b));
    assert_eq!(cache.len(), 1);
    let c = cache.load(&scenes_dir().join("window_room.gltf")).unwrap();
    assert!(!Arc::ptr_eq(&a, &c));
    assert_eq!(cache.len(), 2);
    // The shared scene is the one a direct import gives.
    let direct = Scene::load(&scenes_dir().join("fog_room.gltf")).unwrap();
    assert_eq!(a.meshes.len(), direct.meshes.len());
    assert_eq!(a.triangle_count(), direct.triangle_count());
    assert_eq!(a.bounds(), direct.bounds());
}

#[test]
fn a_broken_scene_is_reported_to_every_reader_and_not_kept() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("broken.gltf");
    std::fs::write(&path, b"{ not json").unwrap();
    let cache = SceneCache::default();
    for _ in 0..2 {
        let e = cache.load(&path).expect_err("broken glTF").to_string();
        assert!(e.contains("broken.gltf"), "{e}");
    }
    assert!(cache.is_empty());
    let missing = cache.load(&dir.path().join("missing.gltf")).expect_err("missing file").to_string();
    assert!(missing.contains("missing.gltf"), "{missing}");
    assert!(cache.is_empty());
}
