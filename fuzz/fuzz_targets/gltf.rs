//! glTF importer from bytes (`.gltf` JSON or `.glb`), then the generic scene checks. External
//! buffer files are refused (the document is in memory), data URIs and GLB chunks are read.
#![no_main]

use std::path::Path;

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    if let Ok(mut scene) = voltab::scene::gltf_import::import_bytes(Path::new("fuzz.gltf"), data) {
        let _ = voltab::scene::check::check(&mut scene);
    }
});
