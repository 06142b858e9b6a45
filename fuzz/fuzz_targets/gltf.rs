//! glTF importer from bytes (`.gltf` JSON or `.glb`), then the generic scene checks. External
//! buffer files are refused (the document is in memory), data URIs and GLB chunks are read. The
//! heap may grow by at most 4× the declared data: the input plus its buffers' `byteLength`s.
#![no_main]

#[path = "common/mem.rs"]
mod mem;

use std::path::Path;

use libfuzzer_sys::fuzz_target;

#[global_allocator]
static ALLOC: mem::Counting = mem::Counting;

fuzz_target!(|data: &[u8]| {
    let declared = (data.len() as u64).saturating_add(declared_buffers(data));
    let window = mem::start();
    if let Ok(mut scene) = voltab::scene::gltf_import::import_bytes(Path::new("fuzz.gltf"), data) {
        let _ = voltab::scene::check::check(&mut scene);
    }
    window.check("gltf", declared);
});

/// Σ `buffers[i].byteLength` of the document, read before the window opens with a parse that is
/// not the importer's: the JSON text itself, or a GLB's first chunk (bounds checked here, since
/// the `gltf` crate's own GLB splitter overflows on a header length below 12).
fn declared_buffers(data: &[u8]) -> u64 {
    let json = if data.starts_with(b"glTF") {
        let word = |at: usize| data.get(at..at + 4).map(|b| u32::from_le_bytes([b[0], b[1], b[2], b[3]]) as usize);
        match word(12) {
            Some(len) => data.get(20..20usize.saturating_add(len)).unwrap_or(&[]),
            None => &[],
        }
    } else {
        data
    };
    let Ok(root) = serde_json::from_slice::<serde_json::Value>(json) else { return 0 };
    let buffers = root.get("buffers").and_then(|b| b.as_array());
    buffers
        .into_iter()
        .flatten()
        .filter_map(|b| b.get("byteLength").and_then(|l| l.as_u64()))
        .fold(0u64, u64::saturating_add)
}
