//! Test fixtures: parameters → small headers, value arrays and hand-assembled
//! `.vtab` byte images shared by the container's unit tests.
//!
//! Invariant: fixtures are deterministic (no randomness, no clocks), so every
//! test that uses them pins the same bytes on every run.

use super::format::{ArrayDesc, ArrayValues, Axis, ChunkEntry, ElementType, Header};

/// An array description without quantization.
pub fn desc(name: &str, element: ElementType, axes: Vec<Axis>) -> ArrayDesc {
    ArrayDesc {
        name: name.into(),
        description: format!("test array {name}"),
        unit: "1/m".into(),
        element,
        axes,
        quantization: None,
    }
}

/// A header around the given arrays.
pub fn header(arrays: Vec<ArrayDesc>) -> Header {
    Header {
        kind: "test.kind".into(),
        kind_schema_version: 3,
        generator_version: "voltab-test 0.0.0".into(),
        definition_ron: "(kind: \"test.kind\")".into(),
        content_key: *blake3::hash(b"test definition").as_bytes(),
        arrays,
    }
}

/// Deterministic pseudo-random 64-bit values (splitmix64).
pub fn noise(n: usize, seed: u64) -> Vec<u64> {
    let mut s = seed;
    (0..n)
        .map(|_| {
            s = s.wrapping_add(0x9E37_79B9_7F4A_7C15);
            let mut z = s;
            z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
            z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
            z ^ (z >> 31)
        })
        .collect()
}

/// A small three-array table: 3-D f32 `a` [3,4,5], 1-D f64 `b` [6], 2-D f32 `c` [2,7].
/// Values include -0.0, a subnormal and extreme magnitudes.
pub fn small_table() -> (Header, Vec<ArrayValues>) {
    let h = header(vec![
        desc(
            "a",
            ElementType::F32,
            vec![
                Axis::linear("x", "m", 0.0, 1.0, 3),
                Axis::log("lambda", "nm", 300.0, 900.0, 4),
                Axis::explicit("g", "", vec![-0.9, -0.5, 0.0, 0.5, 0.9]),
            ],
        ),
        desc("b", ElementType::F64, vec![Axis::linear("t", "K", 100.0, 600.0, 6)]),
        desc("c", ElementType::F32, vec![Axis::linear("u", "", 0.0, 1.0, 2), Axis::linear("v", "", 0.0, 1.0, 7)]),
    ]);
    let mut a: Vec<f32> = (0..60).map(|i| (i as f32 * 0.37).sin() * 10.0 + 1.0).collect();
    a[0] = -0.0;
    a[1] = f32::from_bits(1);
    a[2] = f32::MAX;
    a[3] = -f32::MIN_POSITIVE;
    let b = vec![1.0e-300, -2.5, 3.0e300, 0.0, 7.0, std::f64::consts::PI];
    let c: Vec<f32> = (0..14).map(|i| i as f32 * 0.5).collect();
    (h, vec![ArrayValues::F32(a), ArrayValues::F64(b), ArrayValues::F32(c)])
}

/// Assembles a file from a header, an index and a payload, exactly as the
/// writer lays it out (used to forge files with valid checksums).
pub fn assemble(header: &Header, chunks: &[ChunkEntry], payload: &[u8]) -> Vec<u8> {
    super::encode::assemble_unchecked(header, chunks, payload)
}

/// A unique scratch path in the system temp directory.
pub fn temp_path(tag: &str) -> std::path::PathBuf {
    std::env::temp_dir().join(format!("voltab-container-{}-{tag}.vtab", std::process::id()))
}
