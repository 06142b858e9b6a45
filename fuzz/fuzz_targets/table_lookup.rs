//! Table look-ups from bytes: the first byte picks ZhResponse or MsLobes, the rest is a `.vtab`
//! opened as that kind (stored-definition validation, layout checks), then queried at a few points
//! in and out of range. Errors are fine; panics are not, nor a heap growing beyond 4× the declared
//! data (the input plus every chunk's declared raw size).
#![no_main]

#[path = "common/mem.rs"]
mod mem;

use std::path::Path;

use libfuzzer_sys::fuzz_target;
use voltab::container::{ReadLimits, VtabReader};
use voltab::physics::medium::HomogeneousMedium;
use voltab::tables::ms_lobes::{LobeQuery, MsLobesTable};
use voltab::tables::zh_response::{Emitter, QueryOptions, Receiver, ZhResponseTable};

#[global_allocator]
static ALLOC: mem::Counting = mem::Counting;

fuzz_target!(|data: &[u8]| {
    let window = mem::start();
    let mut declared = data.len() as u64;
    look_up(data, &mut declared);
    window.check("table_lookup", declared);
});

fn look_up(data: &[u8], declared: &mut u64) {
    let Some((&which, bytes)) = data.split_first() else { return };
    let limits = ReadLimits { max_chunk_bytes: 16 << 20 };
    let Ok(r) = VtabReader::from_bytes_with_limits(bytes.to_vec(), limits) else { return };
    *declared = declared.saturating_add(r.chunks().iter().fold(0u64, |s, c| s.saturating_add(c.raw_len)));
    let name = Path::new("fuzz.vtab");
    if which % 2 == 0 {
        let Ok(t) = ZhResponseTable::from_reader(r, name, None, None) else { return };
        let receiver = Receiver { position: [0.0, 0.0, 1.0], normal: [0.0, 0.0, -1.0] };
        for g in [-0.95, 0.0, 0.3, 0.95] {
            let medium = HomogeneousMedium { sigma_s: 1.0, sigma_a: 0.1, g };
            let emitters = [
                Emitter::Point { intensity: 1.0, position: [0.0, 0.0, 0.0] },
                Emitter::Directional { irradiance: 1.0, toward_light: [0.0, 0.0, -1.0], depth: 2.0 },
                Emitter::Area { intensity: 1.0, position: [0.0, 0.0, 0.0], normal: [0.0, 0.0, 1.0] },
            ];
            for e in &emitters {
                let _ = t.irradiance(&medium, e, &receiver, &QueryOptions::default());
                let _ = t.radiance(&medium, e, &receiver, &QueryOptions::default());
            }
        }
    } else {
        let Ok(t) = MsLobesTable::from_reader(r, name, None) else { return };
        for (albedo, g, rho, z) in
            [(0.5, 0.0, 0.5, 1.0), (1.0, 0.8, 3.0, -1.0), (0.9, 0.99, 1e9, 1e9), (0.0, -0.5, 0.0, 0.0)]
        {
            let q = LobeQuery { albedo, g, rho, z, theta: 1.0, phi: 0.5 };
            let _ = t.lobe(&q);
            let _ = t.double_lobe(&q);
            let _ = t.density(albedo, g, rho, z);
        }
    }
}
