use super::*;
use crate::container::format::ElementType;
use crate::container::testutil::{desc, header};

#[test]
fn header_rules() {
    let ok = |arrays| validate_header(&header(arrays));
    let lin = || Axis::linear("x", "", 0.0, 1.0, 2);
    assert!(ok(vec![desc("a", ElementType::F32, vec![lin()])]).is_ok());
    let mut q = desc("a", ElementType::F32, vec![lin()]);
    for (bits, good) in [(0u8, false), (1, true), (23, true), (24, false)] {
        q.quantization = Some(Quantization::new(bits));
        assert_eq!(ok(vec![q.clone()]).is_ok(), good, "f32 with {bits} bits");
    }
    q.element = ElementType::F64;
    q.quantization = Some(Quantization::new(52));
    assert!(ok(vec![q.clone()]).is_ok());
    // The bound is an exact power of two however a caller computes it.
    for m in 1..=52u8 {
        let q2 = Quantization { mantissa_bits: m, max_rel_error: 2f64.powi(-(i32::from(m) + 1)) };
        assert_eq!(q2, Quantization::new(m));
    }
    q.quantization = Some(Quantization { mantissa_bits: 8, max_rel_error: 0.1 });
    assert!(ok(vec![q]).is_err());
    let bad: Vec<Vec<ArrayDesc>> = vec![
        vec![],
        vec![desc("a", ElementType::F32, vec![])],
        vec![desc("a", ElementType::F32, vec![lin()]), desc("a", ElementType::F64, vec![lin()])],
        vec![desc("a", ElementType::F32, vec![Axis::linear("x", "", 0.0, 1.0, 0)])],
        vec![desc("a", ElementType::F32, vec![Axis::log("x", "", 0.0, 1.0, 3)])],
        vec![desc("a", ElementType::F32, vec![Axis::linear("x", "", 0.0, f64::NAN, 3)])],
        vec![desc("a", ElementType::F32, vec![Axis { len: 4, ..Axis::explicit("x", "", vec![1.0, 2.0]) }])],
        vec![desc("a", ElementType::F64, vec![Axis::linear("x", "", 0.0, 1.0, 1 << 61)])],
    ];
    for arrays in bad {
        let e = ok(arrays.clone());
        assert!(matches!(e, Err(ContainerError::InvalidHeader(_))), "{arrays:?} → {e:?}");
    }
}
