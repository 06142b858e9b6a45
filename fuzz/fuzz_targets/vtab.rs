//! `.vtab` reader from bytes: preamble, header, index, every chunk (verify and read_array), and the
//! stored definition's validation (`check_known_kind`), under a 16 MiB per-chunk limit.
#![no_main]

use libfuzzer_sys::fuzz_target;
use voltab::container::{ReadLimits, VtabReader};

fuzz_target!(|data: &[u8]| {
    let limits = ReadLimits { max_chunk_bytes: 16 << 20 };
    let Ok(mut r) = VtabReader::from_bytes_with_limits(data.to_vec(), limits) else { return };
    let _ = voltab::tables::check_known_kind(r.header());
    let _ = r.verify();
    for a in 0..r.header().arrays.len() {
        let _ = r.read_array(a);
    }
});
