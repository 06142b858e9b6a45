use super::*;
use crate::container::encode::{EncodeOptions, encode};
use crate::container::format::ArrayValues;
use crate::container::testutil::small_table;

fn reader(h: &Header, arrays: &[ArrayValues]) -> VtabReader {
    let enc = encode(h, arrays, &EncodeOptions::default()).expect("encode");
    VtabReader::from_bytes(enc.bytes).expect("open")
}

#[test]
fn identical_files_are_identical() {
    let (h, arrays) = small_table();
    let rep = diff(&mut reader(&h, &arrays), &mut reader(&h, &arrays)).expect("diff");
    assert!(rep.identical() && rep.within(0.0, 0.0));
    assert!(rep.header_differences.is_empty() && rep.notes.is_empty());
    assert_eq!(rep.chunks.len(), 3 + 6 + 2);
    assert!(rep.chunks.iter().all(|c| c.max_abs == 0.0 && c.max_rel == 0.0));
}

#[test]
fn a_perturbed_element_is_located() {
    let (h, arrays) = small_table();
    let mut changed = arrays.clone();
    // Array `a` is [3,4,5]: flat element 47 is slice 2, element 7 within the slice.
    let ArrayValues::F32(a) = &mut changed[0] else { panic!("f32") };
    let before = a[47];
    a[47] = before + 0.25;
    let expected_abs = f64::from(a[47]) - f64::from(before);
    let rep = diff(&mut reader(&h, &arrays), &mut reader(&h, &changed)).expect("diff");
    assert!(rep.header_differences.is_empty());
    assert!(!rep.identical());
    let hit: Vec<&ChunkDiff> = rep.chunks.iter().filter(|c| c.max_abs > 0.0).collect();
    assert_eq!(hit.len(), 1);
    let c = hit[0];
    assert_eq!((c.array.as_str(), c.slice, c.max_abs_index, c.max_rel_index), ("a", 2, 7, 7));
    assert_eq!(c.max_abs, expected_abs);
    let scale = f64::from(before).abs().max(f64::from(before + 0.25).abs());
    assert_eq!(c.max_rel, expected_abs / scale);
    assert!(rep.within(0.25, 0.0) && !rep.within(0.2, c.max_rel / 2.0) && rep.within(0.0, c.max_rel));
}

#[test]
fn relative_difference_handles_zeros() {
    let d = compare_values("x", 0, &[0.0, 0.0, 2.0, -1.0], &[0.0, 1e-3, 2.0, -3.0]);
    assert_eq!((d.max_abs, d.max_abs_index), (2.0, 3));
    assert_eq!((d.max_rel, d.max_rel_index), (1.0, 1)); // 1e-3 vs 0 → 1; index 3 is only 2/3
    let d = compare_values("x", 0, &[1.0, -1.0], &[-1.0, 1.0]);
    assert_eq!((d.max_rel, d.max_rel_index), (2.0, 0)); // a sign flip is 2, first occurrence
}

#[test]
fn header_differences_are_reported_and_shapes_gate_value_diffs() {
    let (h, arrays) = small_table();
    let mut h2 = h.clone();
    h2.kind = "other.kind".into();
    h2.generator_version = "voltab 9".into();
    h2.arrays[1].unit = "m".into();
    h2.arrays[2].axes[1].len = 8;
    h2.arrays[2].name = "c".into();
    let mut arrays2 = arrays.clone();
    arrays2[2] = ArrayValues::F32((0..16).map(|i| i as f32).collect());
    let rep = diff(&mut reader(&h, &arrays), &mut reader(&h2, &arrays2)).expect("diff");
    let joined = rep.header_differences.join("\n");
    assert!(joined.contains("kind `test.kind` vs `other.kind`"), "{joined}");
    assert!(joined.contains("array `b`: unit `1/m` vs `m`"), "{joined}");
    assert!(joined.contains("array `c`, axis 1: length 7 vs 8"), "{joined}");
    assert_eq!(rep.header_differences.len(), 3, "{joined}");
    assert_eq!(rep.notes, vec!["generator version `voltab-test 0.0.0` vs `voltab 9`".to_string()]);
    // `c` changed shape, so only `a` (3 slices) and `b` (6 slices) are compared.
    assert_eq!(rep.chunks.len(), 9);
    assert!(!rep.within(f64::INFINITY, f64::INFINITY));
}
