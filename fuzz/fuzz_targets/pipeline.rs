//! Pipeline front end from memory: RON text → load (parse, includes) → validate. Any outcome but a
//! panic, abort or hang is fine; every diagnostic must name the file and carry a location
//! (`file:line:column`), and the heap may grow by at most 4× the text's size.
#![no_main]

#[path = "common/mem.rs"]
mod mem;

use std::path::Path;

use libfuzzer_sys::fuzz_target;
use voltab::pipeline::{Limits, Sources};
use voltab::registry::{load, validate};

#[global_allocator]
static ALLOC: mem::Counting = mem::Counting;

/// One in-memory file; includes of anything else are "not found".
struct Mem<'a>(&'a str);

impl Sources for Mem<'_> {
    fn read(&self, path: &Path) -> std::io::Result<String> {
        if path == Path::new("fuzz.ron") {
            Ok(self.0.to_owned())
        } else {
            Err(std::io::Error::new(std::io::ErrorKind::NotFound, "not in the fuzz input"))
        }
    }
}

fuzz_target!(|data: &[u8]| {
    let Ok(text) = std::str::from_utf8(data) else { return };
    let window = mem::start();
    let path = Path::new("fuzz.ron");
    let limits = Limits { memory_bytes: 1 << 30 };
    let result = load(path, &Mem(text)).and_then(|l| validate(path, l, &limits));
    if let Err(e) = result {
        for d in &e.diagnostics {
            let shown = d.to_string();
            assert!(shown.contains("fuzz.ron"), "a diagnostic lost its file: {shown}");
            assert!(d.loc.is_some(), "a diagnostic has no location: {shown}");
        }
    }
    window.check("pipeline", data.len() as u64);
});
