use super::*;
use crate::container::encode::{EncodeOptions, encode};
use crate::container::format::{Axis, FORMAT_MAJOR, FORMAT_MINOR, MAX_META_LEN};
use crate::container::testutil::{desc, header, small_table, temp_path};

fn small_bytes() -> Vec<u8> {
    let (h, arrays) = small_table();
    encode(&h, &arrays, &EncodeOptions::default()).expect("encode").bytes
}

fn bits(v: &ArrayValues) -> Vec<u64> {
    match v {
        ArrayValues::F32(v) => v.iter().map(|x| u64::from(x.to_bits())).collect(),
        ArrayValues::F64(v) => v.iter().map(|x| x.to_bits()).collect(),
    }
}

fn slice_of(v: &ArrayValues, start: usize, len: usize) -> ArrayValues {
    match v {
        ArrayValues::F32(v) => ArrayValues::F32(v[start..start + len].to_vec()),
        ArrayValues::F64(v) => ArrayValues::F64(v[start..start + len].to_vec()),
    }
}

/// A table exercising all three transforms: a smooth f64 3-D array
/// (DeltaShuffle), a f32 array of randomly chosen small integers (Shuffle)
/// and a tiny noisy f32 array (None).
fn mixed_table() -> (crate::container::format::Header, Vec<ArrayValues>) {
    let h = header(vec![
        desc(
            "smooth",
            ElementType::F64,
            vec![
                Axis::linear("a", "", 0.0, 1.0, 4),
                Axis::log("b", "", 1.0, 100.0, 8),
                Axis::linear("c", "", 0.0, 1.0, 256),
            ],
        ),
        desc(
            "levels",
            ElementType::F32,
            vec![Axis::linear("i", "", 0.0, 1.0, 2), Axis::linear("j", "", 0.0, 1.0, 512)],
        ),
        desc("tiny", ElementType::F32, vec![Axis::linear("k", "", 0.0, 1.0, 3), Axis::linear("l", "", 0.0, 1.0, 2)]),
    ]);
    let smooth = (0..4 * 8 * 256).map(|n| ((n / 256) as f64 * 0.3).exp() * ((n % 256) as f64 / 40.0).sin()).collect();
    let noise = crate::container::testutil::noise(1024, 5);
    let levels = noise.iter().map(|b| (b % 4) as f32).collect();
    let tiny = noise.iter().take(6).map(|b| f32::from_bits((*b as u32 >> 9) | 0x3F80_0000)).collect();
    (h, vec![ArrayValues::F64(smooth), ArrayValues::F32(levels), ArrayValues::F32(tiny)])
}

#[test]
fn round_trip_is_bit_exact_for_every_slice_shape_and_transform() {
    for (h, arrays) in [small_table(), mixed_table()] {
        let enc = encode(&h, &arrays, &EncodeOptions::default()).expect("encode");
        let path = temp_path(&format!("roundtrip-{}", h.arrays[0].name));
        std::fs::write(&path, &enc.bytes).expect("write");
        let from_file = VtabReader::open(&path);
        let (h2, version) = read_header(&path).expect("read_header");
        let _ = std::fs::remove_file(&path);
        assert_eq!((h2, version), (h.clone(), (FORMAT_MAJOR, FORMAT_MINOR)));
        for mut r in [from_file.expect("open"), VtabReader::from_bytes(enc.bytes.clone()).expect("from_bytes")] {
            assert_eq!(r.header(), &h);
            assert_eq!(r.version(), (1, 0));
            let total_slices: u64 = h.arrays.iter().map(|d| d.slice_count()).sum();
            assert_eq!(r.chunks().len() as u64, total_slices);
            for (ai, (desc, values)) in h.arrays.iter().zip(&arrays).enumerate() {
                let whole = r.read_array(ai).expect("read_array");
                assert_eq!(bits(&whole), bits(values), "array {}", desc.name);
                let n = desc.slice_len().expect("small") as usize;
                // Read slices in reverse to show each read is independent.
                for s in (0..desc.slice_count()).rev() {
                    let got = r.read_slice(ai, s).expect("read_slice");
                    assert_eq!(bits(&got), bits(&slice_of(values, s as usize * n, n)), "{}/{s}", desc.name);
                }
            }
            let rep = r.verify().expect("verify");
            assert_eq!(rep.chunks, total_slices);
        }
    }
    let (h, arrays) = mixed_table();
    let enc = encode(&h, &arrays, &EncodeOptions::default()).expect("encode");
    let r = VtabReader::from_bytes(enc.bytes).expect("open");
    let used: Vec<Transform> = r.chunks().iter().map(|c| c.transform).collect();
    assert!(used[..4].iter().all(|t| *t == Transform::DeltaShuffle), "{used:?}");
    assert!(used[4..6].iter().all(|t| *t == Transform::Shuffle), "{used:?}");
    assert!(used[6..].iter().all(|t| *t == Transform::None), "{used:?}");
}

#[test]
fn version_policy() {
    let bytes = small_bytes();
    let with_version = |major: u16, minor: u16| {
        let mut f = bytes.clone();
        f[8..10].copy_from_slice(&major.to_le_bytes());
        f[10..12].copy_from_slice(&minor.to_le_bytes());
        VtabReader::from_bytes(f)
    };
    let e = with_version(2, 0).expect_err("newer major");
    assert!(matches!(e, ContainerError::NewerMajor { found: (2, 0), supported: (1, 0) }), "{e:?}");
    let msg = e.to_string();
    assert!(msg.contains("2.0") && msg.contains("1.0") && msg.contains("upgrade voltab"), "{msg}");
    let e = with_version(1, 1).expect_err("newer minor");
    assert!(matches!(e, ContainerError::NewerMinor { found: (1, 1), supported: (1, 0) }), "{e:?}");
    assert!(e.to_string().contains("1.1") && e.to_string().contains("1.0"));
    let e = with_version(0, 7).expect_err("old major");
    assert!(matches!(e, ContainerError::UnsupportedOld { found: (0, 7), .. }), "{e:?}");
}

#[test]
fn framing_errors_are_typed() {
    let bytes = small_bytes();
    let mut f = bytes.clone();
    f.extend_from_slice(b"xyz");
    assert!(matches!(VtabReader::from_bytes(f), Err(ContainerError::TrailingBytes { extra: 3 })));
    let mut f = bytes.clone();
    f[0] = b'X';
    let e = VtabReader::from_bytes(f).expect_err("bad magic");
    assert!(matches!(e, ContainerError::BadMagic) && e.to_string().contains("not a .vtab file"));
    assert!(matches!(VtabReader::from_bytes(b"PK\x03\x04".to_vec()), Err(ContainerError::BadMagic)));
    let mut f = bytes.clone();
    f[12..20].copy_from_slice(&(1u64 << 40).to_le_bytes());
    let e = VtabReader::from_bytes(f);
    assert!(matches!(e, Err(ContainerError::HeaderTooLarge { len, max: MAX_META_LEN }) if len == 1 << 40), "{e:?}");
    let mut f = bytes.clone();
    f[30] ^= 0x10;
    assert!(matches!(VtabReader::from_bytes(f), Err(ContainerError::HeaderChecksum { .. })));
    let mut f = bytes.clone();
    let n = f.len();
    f[n - 3] = b'?';
    assert!(matches!(VtabReader::from_bytes(f), Err(ContainerError::BadEndMagic)));
    let missing = temp_path("does-not-exist");
    let e = VtabReader::open(&missing).expect_err("missing file");
    assert!(matches!(&e, ContainerError::Io { path: Some(p), .. } if *p == missing));
    assert!(e.to_string().contains("does-not-exist"));
}

#[test]
fn out_of_range_requests_are_typed() {
    let mut r = VtabReader::from_bytes(small_bytes()).expect("open");
    assert!(matches!(r.read_slice(3, 0), Err(ContainerError::NoSuchArray { index: 3, count: 3 })));
    assert!(matches!(r.read_array(9), Err(ContainerError::NoSuchArray { index: 9, count: 3 })));
    let e = r.read_slice(1, 6);
    assert!(matches!(&e, Err(ContainerError::NoSuchSlice { array, slice: 6, count: 6 }) if array == "b"), "{e:?}");
    assert_eq!(r.find_array("c"), Some(2));
}
