//! USD importer from bytes: the input is written to a `.usda` (or, when it starts with the crate
//! magic `PXR-USDC`, a `.usdc`) file and imported in this process (the guarded child is what
//! contains openusd's own hangs in `voltab`; here they show up as libFuzzer timeouts), then checked.
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let ext = if data.starts_with(b"PXR-USDC") { "usdc" } else { "usda" };
    let Ok(dir) = tempfile::tempdir() else { return };
    let path = dir.path().join(format!("fuzz.{ext}"));
    if std::fs::write(&path, data).is_err() {
        return;
    }
    if let Ok(mut scene) = voltab::scene::usd_import::import_in_process(&path) {
        let _ = voltab::scene::check::check(&mut scene);
    }
});
