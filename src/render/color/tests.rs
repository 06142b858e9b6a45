use super::*;

#[test]
fn weights_sum_to_one_so_white_keeps_its_value() {
    assert!((luminance([1.0; 3]) - 1.0).abs() < 1e-15);
    assert!((luminance_f32([1.0; 3]) - 1.0).abs() < 1e-6);
    assert_eq!(luminance([0.0, 1.0, 0.0]), 0.7152);
    assert_eq!(luminance_f32([0.0, 0.0, 2.0]), 0.1444);
}
