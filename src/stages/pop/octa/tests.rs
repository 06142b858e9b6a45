use super::*;

#[test]
fn round_trip_and_poles() {
    for k in 0..2000 {
        let z = 1.0 - 2.0 * (k as f64 + 0.5) / 2000.0;
        let phi = 2.399_963_229_728_653 * k as f64;
        let s = (1.0 - z * z).sqrt();
        let d = DVec3::new(s * phi.cos(), s * phi.sin(), z);
        let back = decode(encode(d));
        assert!((back - d).length() < 1e-12, "{d} → {back}");
    }
    for d in [DVec3::X, -DVec3::X, DVec3::Y, -DVec3::Y, DVec3::Z, -DVec3::Z] {
        assert!((decode(encode(d)) - d).length() < 1e-15, "{d}");
    }
    assert_eq!(encode(DVec3::ZERO), DVec2::splat(0.5));
    assert_eq!(encode(DVec3::NAN), DVec2::splat(0.5));
}

#[test]
fn cells_have_equal_solid_angle() {
    // Monte-Carlo-free check: a fine uniform sampling of the sphere by the Fibonacci lattice falls into
    // the 4 × 4 cells in equal shares (equal-area map), within the lattice's discrepancy.
    let n = 4;
    let total = 200_000;
    let mut count = vec![0usize; n * n];
    for k in 0..total {
        let z = 1.0 - 2.0 * (k as f64 + 0.5) / total as f64;
        let phi = 2.399_963_229_728_653 * k as f64;
        let s = (1.0 - z * z).sqrt();
        let (i, j) = cell_of(DVec3::new(s * phi.cos(), s * phi.sin(), z), n);
        count[i + n * j] += 1;
    }
    let want = total as f64 / (n * n) as f64;
    for c in count {
        assert!((c as f64 - want).abs() < 2e-3 * want, "{c} vs {want}");
    }
}

#[test]
fn folds_glue_the_same_directions() {
    let n = 8;
    // Just outside the right edge at height y equals just inside at −y.
    for j in 0..n {
        let (a, b) = wrap(n as i64, j as i64, n);
        assert_eq!((a, b), (n - 1, n - 1 - j));
        let inside = decode(DVec2::new(1.0 - 1e-9, (j as f64 + 0.5) / n as f64));
        let mirrored = decode(DVec2::new(1.0 - 1e-9, (b as f64 + 0.5) / n as f64));
        assert!((inside - mirrored).length() < 1e-6);
    }
    assert_eq!(wrap(-1, 2, n), (0, 5));
    assert_eq!(wrap(3, -1, n), (4, 0));
    assert_eq!(wrap(3, n as i64, n), (4, 7));
    assert_eq!(wrap(2, 3, n), (2, 3));
    // Antipodes pair up.
    for i in 0..n {
        for j in 0..n {
            let (a, b) = antipode(i, j, n);
            assert_eq!(antipode(a, b, n), (i, j));
            assert!((cell_centre(a, b, n) + cell_centre(i, j, n)).length() < 1e-9);
        }
    }
}
