use super::*;

#[test]
fn shuffle_layout_is_byte_planes() {
    let bytes: Vec<u8> = (0u8..8).collect(); // two f32: [0,1,2,3], [4,5,6,7]
    assert_eq!(shuffle(&bytes, ElementType::F32), vec![0, 4, 1, 5, 2, 6, 3, 7]);
    assert_eq!(unshuffle(&[0, 4, 1, 5, 2, 6, 3, 7], ElementType::F32), bytes);
}

#[test]
fn shuffle_and_delta_round_trip_any_bytes() {
    let bytes: Vec<u8> = (0u32..240).map(|i| (i.wrapping_mul(2_654_435_761) >> 13) as u8).collect();
    for el in [ElementType::F32, ElementType::F64] {
        assert_eq!(unshuffle(&shuffle(&bytes, el), el), bytes);
        for row in [1, 3, 5, 30] {
            assert_eq!(undelta(&delta(&bytes, el, row), el, row), bytes);
        }
    }
    // Odd lengths (never produced by the writer) still do not panic.
    let _ = unshuffle(&bytes[..7], ElementType::F64);
    let _ = undelta(&bytes[..13], ElementType::F32, 2);
}

#[test]
fn delta_is_wrapping_bit_difference_per_row() {
    let vals = [1.0f32, 2.0, 0.5, 4.0];
    let d = bytes_f32(&delta(&f32_bytes(&vals), ElementType::F32, 2));
    let bits: Vec<u32> = d.iter().map(|v| v.to_bits()).collect();
    assert_eq!(bits[0], 1.0f32.to_bits());
    assert_eq!(bits[1], 2.0f32.to_bits().wrapping_sub(1.0f32.to_bits()));
    assert_eq!(bits[2], 0.5f32.to_bits()); // new row starts fresh
    assert_eq!(bits[3], 4.0f32.to_bits().wrapping_sub(0.5f32.to_bits()));
}

#[test]
fn rounding_is_nearest_even() {
    // 1 + 2^-23 with 22 kept bits: exact tie between 1 and 1 + 2^-22 → even (1).
    let mut v = [f32::from_bits(0x3F80_0001), f32::from_bits(0x3F80_0003)];
    quantize_f32(&mut v, 22);
    assert_eq!(v[0].to_bits(), 0x3F80_0000);
    assert_eq!(v[1].to_bits(), 0x3F80_0004);
    // 1 kept bit: 1.75 = 1.11b ties 1.5/2.0 → 2.0 (even); 1.25 ties 1.0/1.5 → 1.0;
    // 1.3 rounds to nearest (1.5); negative values mirror.
    let mut v = [1.75f64, 1.25, 1.3, -1.75];
    quantize_f64(&mut v, 1);
    assert_eq!(v, [2.0, 1.0, 1.5, -2.0]);
    // Overflowing rounding keeps the value; subnormals are untouched.
    let mut w = [f32::MAX, f32::from_bits(1)];
    quantize_f32(&mut w, 3);
    assert_eq!(w, [f32::MAX, f32::from_bits(1)]);
}
