//! Measured on 64×1024 f32 tables (x ∈ [0,5] outer, y ∈ [0,2π] inner), zstd
//! level 9 (zstd 1.5.7), payload ratio raw/stored:
//!
//! | table                     | plain zstd | Shuffle | DeltaShuffle |
//! |---------------------------|-----------:|--------:|-------------:|
//! | exp(-x)·cos(y)            |      1.458 |   1.406 |        2.037 |
//! | exp(-(1+x)·y/3) (monotone)|      1.071 |   1.556 |        2.604 |
//! | 1-exp(-(1+x)·y)           |      1.857 |   2.904 |        4.465 |
//! | ln(1+x·y)                 |      1.141 |   1.604 |        2.888 |
//! | exp(-x)·cos(y), 12 bits   |      1.697 |   2.453 |        6.579 |
//! | monotone, 12 bits         |      1.389 |   3.019 |       10.107 |
//!
//! Shuffle alone does not beat plain zstd on the oscillating cos table;
//! DeltaShuffle wins everywhere, and the encoder picks it for every chunk.

use super::*;
use crate::container::format::{Axis, Quantization};
use crate::container::reader::VtabReader;
use crate::container::testutil::{desc, header, small_table};

fn smooth(f: impl Fn(f64, f64) -> f64) -> (Header, Vec<ArrayValues>) {
    let h = header(vec![desc(
        "t",
        ElementType::F32,
        vec![Axis::linear("x", "", 0.0, 5.0, 64), Axis::linear("y", "rad", 0.0, std::f64::consts::TAU, 1024)],
    )]);
    let axes = &h.arrays[0].axes;
    let v = (0..64).flat_map(|i| (0..1024).map(move |j| (i, j)));
    let v = v.map(|(i, j)| f(axes[0].value(i), axes[1].value(j)) as f32).collect();
    (h, vec![ArrayValues::F32(v)])
}

/// Payload sizes of (plain zstd, Shuffle, DeltaShuffle) over all slices.
fn sizes(values: &[f32]) -> (f64, f64, f64) {
    let mut s = (0.0, 0.0, 0.0);
    for row in values.chunks(1024) {
        let raw = f32_bytes(row);
        let sh = shuffle(&raw, ElementType::F32);
        s.0 += zstd(&raw, 9).map_or(f64::NAN, |c| c.len() as f64);
        s.1 += zstd(&sh, 9).map_or(f64::NAN, |c| c.len() as f64);
        let de = shuffle(&delta(&raw, ElementType::F32, 1024), ElementType::F32);
        s.2 += zstd(&de, 9).map_or(f64::NAN, |c| c.len() as f64);
    }
    s
}

#[test]
fn delta_shuffle_beats_shuffle_beats_plain_on_monotone_table() {
    let (h, arrays) = smooth(|x, y| (-(1.0 + x) * y / 3.0).exp());
    let ArrayValues::F32(v) = &arrays[0] else { panic!("f32 fixture") };
    let raw = (v.len() * 4) as f64;
    let (plain, sh, de) = sizes(v);
    let (r_plain, r_sh, r_de) = (raw / plain, raw / sh, raw / de);
    assert!(r_plain < 1.15, "plain {r_plain}"); // measured 1.071
    assert!(r_sh > 1.45 && r_sh > 1.35 * r_plain, "shuffle {r_sh} vs plain {r_plain}"); // 1.556
    assert!(r_de > 2.45 && r_de > 1.5 * r_sh, "delta {r_de} vs shuffle {r_sh}"); // 2.604

    let enc = encode(&h, &arrays, &EncodeOptions::default()).expect("encode");
    assert_eq!(enc.stats.raw_bytes, 64 * 1024 * 4);
    assert_eq!(enc.stats.stored_bytes as f64, de, "encoder keeps the smaller candidate");
    assert!((enc.stats.ratio() - r_de).abs() < 1e-12);
    let reader = VtabReader::from_bytes(enc.bytes).expect("open");
    assert!(reader.chunks().iter().all(|c| c.transform == Transform::DeltaShuffle));
}

#[test]
fn delta_shuffle_wins_on_oscillating_table_and_with_quantization() {
    let (mut h, arrays) = smooth(|x, y| (-x).exp() * y.cos());
    let ArrayValues::F32(v) = &arrays[0] else { panic!("f32 fixture") };
    let raw = (v.len() * 4) as f64;
    let (plain, _, de) = sizes(v);
    assert!(raw / de > 1.9 && plain / de > 1.3, "delta {} plain {}", raw / de, raw / plain); // 2.037 vs 1.458
    h.arrays[0].quantization = Some(Quantization::new(12));
    let enc = encode(&h, &arrays, &EncodeOptions::default()).expect("encode");
    assert!(enc.stats.ratio() > 6.0, "quantized ratio {}", enc.stats.ratio()); // measured 6.579
}

#[test]
fn incompressible_chunks_are_stored_verbatim() {
    let bits = crate::container::testutil::noise(256, 7);
    // Random mantissas with a fixed sign/exponent: finite but incompressible.
    let v: Vec<f64> = bits.iter().map(|b| f64::from_bits((b >> 12) | 0x3FF0_0000_0000_0000)).collect();
    let h = header(vec![desc("n", ElementType::F64, vec![Axis::linear("i", "", 0.0, 1.0, 256)])]);
    let enc = encode(&h, &[ArrayValues::F64(v.clone())], &EncodeOptions::default()).expect("encode");
    assert_eq!(enc.stats.stored_bytes, 256 * 8);
    let mut r = VtabReader::from_bytes(enc.bytes).expect("open");
    assert!(r.chunks().iter().all(|c| c.transform == Transform::None && c.stored_len == 8));
    assert_eq!(r.read_array(0).expect("read"), ArrayValues::F64(v));
}

#[test]
fn encoding_is_deterministic() {
    let (h, arrays) = small_table();
    let a = encode(&h, &arrays, &EncodeOptions::default()).expect("encode");
    let b = encode(&h.clone(), &arrays.clone(), &EncodeOptions::default()).expect("encode");
    assert_eq!(a, b);
    assert_eq!(blake3::hash(&a.bytes), blake3::hash(&b.bytes));
    let c = encode(&h, &arrays, &EncodeOptions { zstd_level: 1 }).expect("encode");
    assert_eq!(c.stats.raw_bytes, a.stats.raw_bytes);
    assert_eq!(a.stats.raw_bytes, 60 * 4 + 6 * 8 + 14 * 4);
    assert_eq!(a.stats.per_array.iter().map(|s| s.raw_bytes).collect::<Vec<_>>(), vec![240, 48, 56]);
}

#[test]
fn non_finite_values_are_never_written() {
    let (h, arrays) = small_table();
    for (which, bad, index) in [(0usize, f64::NAN, 17usize), (1, f64::INFINITY, 4), (2, f64::NEG_INFINITY, 0)] {
        let mut arrays = arrays.clone();
        match &mut arrays[which] {
            ArrayValues::F32(v) => v[index] = bad as f32,
            ArrayValues::F64(v) => v[index] = bad,
        }
        match encode(&h, &arrays, &EncodeOptions::default()) {
            Err(ContainerError::NonFinite { array, index: i, value }) => {
                assert_eq!(array, h.arrays[which].name);
                assert_eq!(i, index as u64);
                assert_eq!(value.is_nan(), bad.is_nan());
                assert!(value.is_nan() || value == bad);
            }
            other => panic!("expected NonFinite, got {other:?}"),
        }
    }
}

#[test]
fn inputs_not_matching_the_header_are_rejected() {
    let (h, arrays) = small_table();
    let opts = EncodeOptions::default();
    let e = encode(&h, &arrays[..2], &opts);
    assert!(matches!(e, Err(ContainerError::ArrayCount { expected: 3, found: 2 })), "{e:?}");
    let mut wrong = arrays.clone();
    wrong[1] = ArrayValues::F32(vec![0.0; 6]);
    let e = encode(&h, &wrong, &opts);
    assert!(matches!(e, Err(ContainerError::ElementTypeMismatch { .. })), "{e:?}");
    wrong[1] = ArrayValues::F64(vec![0.0; 5]);
    let e = encode(&h, &wrong, &opts);
    assert!(matches!(e, Err(ContainerError::ShapeMismatch { expected: 6, found: 5, .. })), "{e:?}");
    let e = encode(&h, &arrays, &EncodeOptions { zstd_level: 99 });
    assert!(matches!(e, Err(ContainerError::InvalidOptions(_))), "{e:?}");
    let mut huge = h.clone();
    huge.arrays[1].axes = vec![Axis::linear("t", "", 0.0, 1.0, u64::MAX / 2); 3];
    let e = encode(&huge, &arrays, &opts);
    assert!(matches!(e, Err(ContainerError::InvalidHeader(_))), "{e:?}");
}

#[test]
fn quantization_error_is_within_bound_and_23_bits_is_lossless() {
    let bits = crate::container::testutil::noise(4096, 11);
    // Normal f32 values spanning many binades, both signs.
    let v: Vec<f32> = bits
        .iter()
        .map(|b| f32::from_bits(((*b as u32) & 0x807F_FFFF) | ((((b >> 32) as u32 % 200) + 28) << 23)))
        .collect();
    let mut h = header(vec![desc("q", ElementType::F32, vec![Axis::linear("i", "", 0.0, 1.0, 4096)])]);
    for m in [1u8, 4, 10, 16, 22, 23] {
        h.arrays[0].quantization = Some(Quantization::new(m));
        let enc = encode(&h, &[ArrayValues::F32(v.clone())], &EncodeOptions::default()).expect("encode");
        let out = VtabReader::from_bytes(enc.bytes).and_then(|mut r| r.read_array(0)).expect("read");
        let ArrayValues::F32(out) = out else { panic!("f32") };
        let bound = (-(f64::from(m) + 1.0)).exp2();
        let mut worst = 0.0f64;
        for (a, b) in v.iter().zip(&out) {
            worst = worst.max(((f64::from(*a) - f64::from(*b)) / f64::from(*a)).abs());
        }
        assert!(worst <= bound, "m={m}: worst {worst} > {bound}");
        if m == 23 {
            assert!(v.iter().zip(&out).all(|(a, b)| a.to_bits() == b.to_bits()));
        } else {
            assert!(worst > bound / 2.0, "m={m}: bound should be nearly attained, worst {worst}");
        }
    }
}
