use super::*;

#[test]
fn axis_positions() {
    let lin = Axis::linear("x", "m", -1.0, 3.0, 5);
    assert_eq!(lin.values_vec(), vec![-1.0, 0.0, 1.0, 2.0, 3.0]);
    let log = Axis::log("l", "nm", 1.0, 1000.0, 4);
    let v = log.values_vec();
    assert_eq!((v[0], v[3]), (1.0, 1000.0));
    assert!((v[1] - 10.0).abs() < 1e-12 && (v[2] - 100.0).abs() < 1e-10, "{v:?}");
    let ex = Axis::explicit("g", "", vec![0.5, 0.75, 2.0]);
    assert_eq!((ex.len, ex.min, ex.max, ex.value(1)), (3, 0.5, 2.0, 0.75));
    assert!(ex.value(3).is_nan() && lin.value(5).is_nan());
    assert_eq!(Axis::linear("one", "", 4.0, 4.0, 1).values_vec(), vec![4.0]);
    assert_eq!((ElementType::F32.size_bytes(), ElementType::F64.size_bytes()), (4, 8));
    assert_eq!(Quantization::new(10).max_rel_error, 1.0 / 2048.0);
}

#[test]
fn preamble_layout_is_explicit_little_endian() {
    let meta = [7u8; 300];
    let p = encode_preamble(&meta);
    assert_eq!(p.len() as u64, PREAMBLE_LEN);
    assert_eq!(&p[..8], b"VTAB\x00\r\n\x1a");
    assert_eq!(&p[8..12], &[1, 0, 0, 0]);
    assert_eq!(&p[12..20], &[44, 1, 0, 0, 0, 0, 0, 0]);
    let pre = parse_preamble(&p).expect("parse");
    assert_eq!((pre.version, pre.meta_len, pre.meta_crc), ((1, 0), 300, meta_crc(1, 0, &meta)));
    assert!(matches!(parse_preamble(&p[..5]), Err(ContainerError::Truncated { expected: 24, found: 5 })));
    assert!(matches!(parse_preamble(b"VTAX"), Err(ContainerError::BadMagic)));
}
