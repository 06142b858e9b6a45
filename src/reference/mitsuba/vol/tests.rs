use super::{encode, sample_cell_centres};

#[test]
fn header_layout_and_x_fastest_cell_centres() {
    let g = sample_cell_centres(([0.0; 3], [2.0, 4.0, 1.0]), [2, 2, 1], 1, |p| vec![p[0] + 10.0 * p[1]]);
    // Centres x ∈ {0.5, 1.5}, y ∈ {1, 3}.
    assert_eq!(g.data, vec![10.5, 11.5, 30.5, 31.5]);
    let b = encode(&g);
    assert_eq!(&b[..4], b"VOL\x03");
    let int = |o: usize| i32::from_le_bytes(b[o..o + 4].try_into().unwrap());
    assert_eq!([int(4), int(8), int(12), int(16), int(20)], [1, 2, 2, 1, 1]);
    let f = |o: usize| f32::from_le_bytes(b[o..o + 4].try_into().unwrap());
    assert_eq!([f(24), f(36), f(40), f(44)], [0.0, 2.0, 4.0, 1.0]);
    assert_eq!(b.len(), 48 + 16);
    assert_eq!(f(48 + 4), 11.5);
}
