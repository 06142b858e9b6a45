use super::encode;

#[test]
fn header_counts_and_little_endian_body() {
    let bytes = encode(&[[1.0, 2.0, 3.0]; 3], &[[0.0, 0.0, 1.0]; 3], &[[0, 1, 2]], true);
    let text = String::from_utf8_lossy(&bytes);
    assert!(text.starts_with("ply\nformat binary_little_endian 1.0\n"));
    assert!(text.contains("element vertex 3\n") && text.contains("element face 1\n"));
    let body = &bytes[text.find("end_header\n").unwrap() + "end_header\n".len()..];
    assert_eq!(body.len(), 3 * 24 + 13);
    assert_eq!(f32::from_le_bytes(body[0..4].try_into().unwrap()), 1.0);
    // Flipped: normal z negated, winding 0 2 1.
    assert_eq!(f32::from_le_bytes(body[20..24].try_into().unwrap()), -1.0);
    let face = &body[72..];
    assert_eq!(face[0], 3);
    let idx: Vec<i32> = (0..3).map(|k| i32::from_le_bytes(face[1 + 4 * k..5 + 4 * k].try_into().unwrap())).collect();
    assert_eq!(idx, [0, 2, 1]);
}
