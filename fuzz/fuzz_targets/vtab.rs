//! `.vtab` reader from bytes: preamble, header, index, every chunk (verify and read_array), and the
//! stored definition's validation (`check_known_kind`), under a 16 MiB per-chunk limit. The heap may
//! grow by at most 4× the declared data (the input plus every chunk's declared raw size).
#![no_main]

#[path = "common/mem.rs"]
mod mem;

use libfuzzer_sys::fuzz_target;
use voltab::container::{ReadLimits, VtabReader};

#[global_allocator]
static ALLOC: mem::Counting = mem::Counting;

fuzz_target!(|data: &[u8]| {
    let window = mem::start();
    let mut declared = data.len() as u64;
    let limits = ReadLimits { max_chunk_bytes: 16 << 20 };
    if let Ok(mut r) = VtabReader::from_bytes_with_limits(data.to_vec(), limits) {
        declared = declared.saturating_add(r.chunks().iter().fold(0u64, |s, c| s.saturating_add(c.raw_len)));
        let _ = voltab::tables::check_known_kind(r.header());
        let _ = r.verify();
        for a in 0..r.header().arrays.len() {
            let _ = r.read_array(a);
        }
    }
    window.check("vtab", declared);
});
