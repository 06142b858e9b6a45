//! USD importer from bytes: the input is written to a `.usda` (or, when it starts with the crate
//! magic `PXR-USDC`, a `.usdc`) file and imported in this process (the guarded child is what
//! contains openusd's own hangs in `voltab`; here they show up as libFuzzer timeouts), then checked.
//! The heap may grow by at most 4× the input's size.
#![no_main]

#[path = "common/mem.rs"]
mod mem;

use libfuzzer_sys::fuzz_target;

#[global_allocator]
static ALLOC: mem::Counting = mem::Counting;

fuzz_target!(|data: &[u8]| {
    let ext = if data.starts_with(b"PXR-USDC") { "usdc" } else { "usda" };
    let Ok(dir) = tempfile::tempdir() else { return };
    let path = dir.path().join(format!("fuzz.{ext}"));
    if std::fs::write(&path, data).is_err() {
        return;
    }
    let window = mem::start();
    // On a thread with the guarded child's stack, as `voltab` imports, so a deep but finite
    // recursion that `voltab` survives is not a crash here. An unbounded one still overflows: a
    // plain SIGSEGV under libFuzzer (no artifact), whose input stays in `dir`, never removed then.
    let import =
        std::thread::Builder::new().stack_size(voltab::scene::usd_import::guard::CHILD_STACK).spawn(move || {
            if let Ok(mut scene) = voltab::scene::usd_import::import_in_process(&path) {
                let _ = voltab::scene::check::check(&mut scene);
            }
            drop(dir);
        });
    if let Ok(handle) = import {
        if let Err(panic) = handle.join() {
            std::panic::resume_unwind(panic);
        }
    }
    window.check("usd", data.len() as u64);
});
