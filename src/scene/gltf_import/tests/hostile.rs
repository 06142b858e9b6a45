//! Issue 37's glTF reproducers: buffer URIs that escape the document's folder or name devices,
//! byteLengths that disagree with the file, misaligned accessors and a glTF 3.0 asset are refused
//! with an error naming the file and the property, without reading more than the declared bytes.

use std::time::{Duration, Instant};

use serde_json::json;

use super::*;

/// The one-triangle document as `.gltf` whose buffer 0 has `uri` (and the true byteLength).
fn with_uri(dir: &Path, uri: &str) -> PathBuf {
    let d = one_triangle("t", json!({}), json!({}));
    let mut j = d.json_with_buffer(Some(uri.to_owned()));
    j["buffers"][0]["byteLength"] = json!(d.bin.len());
    let path = dir.join("scene.gltf");
    std::fs::write(&path, serde_json::to_string_pretty(&j).unwrap()).unwrap();
    path
}

#[test]
fn buffer_uris_naming_devices_or_escaping_the_folder_are_refused() {
    let root = tempfile::tempdir().unwrap();
    let dir = root.path().join("scene");
    std::fs::create_dir(&dir).unwrap();
    std::fs::write(root.path().join("outside.bin"), [0u8; 64]).unwrap();
    for (uri, says) in [
        ("/dev/urandom", "is an absolute path"),
        ("/dev/zero", "is an absolute path"),
        ("file:///dev/zero", "is an absolute path"),
        ("../outside.bin", "leads out of the document's folder"),
        ("a/../../outside.bin", "leads out of the document's folder"),
    ] {
        let path = with_uri(&dir, uri);
        let t = Instant::now();
        let e = error_text(import(&path));
        assert!(t.elapsed() < Duration::from_secs(2), "{uri}: {:?}", t.elapsed());
        assert!(e.contains("scene.gltf: buffers[0]") && e.contains(says), "{uri}: {e}");
    }
}

#[test]
fn a_fifo_or_device_inside_the_folder_is_not_read() {
    let dir = tempfile::tempdir().unwrap();
    let fifo = dir.path().join("data.bin");
    if !std::process::Command::new("mkfifo").arg(&fifo).status().is_ok_and(|s| s.success()) {
        return; // no mkfifo on this machine: the devices above cover the rule
    }
    let e = error_text(import(&with_uri(dir.path(), "data.bin")));
    assert!(e.contains("buffers[0]") && e.contains("not a regular file"), "{e}");
}

#[test]
fn buffer_file_larger_than_its_byte_length_is_refused() {
    let d = one_triangle("t", json!({}), json!({}));
    let dir = tempfile::tempdir().unwrap();
    let path = d.write_gltf_external(dir.path(), "scene");
    let mut bytes = d.bin.clone();
    bytes.extend_from_slice(&[0u8; 4]); // up to 3 bytes of padding are fine, 4 are not
    std::fs::write(dir.path().join("scene data.bin"), &bytes).unwrap();
    let e = error_text(import(&path));
    assert!(
        e.contains("buffers[0]") && e.contains(&format!("has {} bytes but the buffer's byteLength is", bytes.len())),
        "{e}"
    );
    bytes.truncate(d.bin.len() + 3);
    std::fs::write(dir.path().join("scene data.bin"), &bytes).unwrap();
    import(&path).expect("padding within 3 bytes");
}

#[test]
fn misaligned_accessor_offsets_are_refused() {
    let mut d = one_triangle("t", json!({}), json!({}));
    // Shift the position view by 2 bytes: its f32 data no longer starts on a 4-byte boundary.
    d.bin.splice(0..0, [0u8; 4]);
    d.json["bufferViews"][0]["byteOffset"] = json!(2);
    for v in d.json["bufferViews"].as_array_mut().unwrap().iter_mut().skip(1) {
        v["byteOffset"] = json!(v["byteOffset"].as_u64().unwrap() + 4);
    }
    let e = error_text(d.import());
    assert!(e.contains("accessors[0]") && e.contains("starts at byte 2") && e.contains("4-byte component"), "{e}");
}

#[test]
fn buffer_views_outside_the_declared_byte_length_are_refused() {
    let mut d = one_triangle("t", json!({}), json!({}));
    let len = d.bin.len();
    d.json["bufferViews"][0]["byteLength"] = json!(len + 4);
    let e = error_text(d.import());
    assert!(e.contains("bufferViews[0]") && e.contains("lies outside buffers[0]"), "{e}");
}

#[test]
fn assets_of_another_major_version_are_refused() {
    for (version, ok) in [("3.0", false), ("1.0", false), ("2", false), ("2.1", true)] {
        let mut d = one_triangle("t", json!({}), json!({}));
        d.json["asset"]["version"] = json!(version);
        let r = d.import();
        if ok {
            r.unwrap_or_else(|e| panic!("{version}: {e}"));
        } else {
            let e = error_text(r);
            assert!(e.contains("asset.version") && e.contains(&format!("\"{version}\" is not supported")), "{e}");
        }
    }
}

#[test]
fn documents_from_memory_refuse_external_buffers() {
    let d = one_triangle("t", json!({}), json!({}));
    let glb = d.glb_bytes();
    let scene = super::super::import_bytes(Path::new("mem.glb"), &glb).expect("GLB from memory");
    assert_eq!(scene.meshes.len(), 1);
    let j = d.json_with_buffer(Some("data.bin".into()));
    let e = error_text(super::super::import_bytes(Path::new("mem.gltf"), &serde_json::to_vec(&j).unwrap()));
    assert!(e.contains("mem.gltf: buffers[0]") && e.contains("read from memory"), "{e}");
}
