use super::*;

/// Chi-square over 64 equal bins for 2^16 draws: with 63 degrees of freedom the 99.9 % quantile
/// is 103.4, so a correct uniform stream fails this with probability 1e-3 (fixed keys: it
/// either always passes or always fails).
#[test]
fn uniform_passes_chi_square_in_each_dimension() {
    let k = StreamKey { table: 42, cell: 7 };
    for dim in 0..3 {
        let mut bins = [0u32; 64];
        let n = 1u64 << 16;
        for s in 0..n {
            let u = k.uniform(s, dim);
            assert!((0.0..1.0).contains(&u));
            bins[(u * 64.0) as usize] += 1;
        }
        let e = n as f64 / 64.0;
        let chi2: f64 = bins.iter().map(|&b| (f64::from(b) - e).powi(2) / e).sum();
        assert!(chi2 < 103.4, "dim {dim}: chi2 {chi2}");
    }
}

/// Neighbouring cells and samples must not be correlated: the mean product of adjacent draws of
/// independent U(0,1) is 1/4 with standard error ≈ 0.0011 at n = 2^16 (σ of a product ≈ 0.28).
#[test]
fn adjacent_streams_are_uncorrelated() {
    let n = 1u64 << 16;
    let a = StreamKey { table: 1, cell: 0 };
    let b = StreamKey { table: 1, cell: 1 };
    let mean_cells: f64 = (0..n).map(|s| a.uniform(s, 0) * b.uniform(s, 0)).sum::<f64>() / n as f64;
    let mean_samples: f64 = (0..n).map(|s| a.uniform(s, 0) * a.uniform(s + 1, 0)).sum::<f64>() / n as f64;
    let mean_dims: f64 = (0..n).map(|s| a.uniform(s, 0) * a.uniform(s, 1)).sum::<f64>() / n as f64;
    for m in [mean_cells, mean_samples, mean_dims] {
        assert!((m - 0.25).abs() < 0.0045, "mean product {m}");
    }
}

#[test]
fn sample_stream_equals_uniform() {
    let k = StreamKey { table: 0xdead_beef, cell: 3 };
    for s in [0u64, 1, 99, u64::MAX] {
        let st = k.sample(s);
        for d in [0u32, 1, 7, 4095] {
            assert_eq!(st.uniform(d).to_bits(), k.uniform(s, d).to_bits());
        }
    }
}

#[test]
fn is_a_pure_function_of_its_key() {
    let k = StreamKey::from_content_key(&[3u8; 32], 9);
    assert_eq!(k.uniform(123, 2).to_bits(), k.uniform(123, 2).to_bits());
    assert_ne!(k.uniform(123, 2).to_bits(), k.uniform(124, 2).to_bits());
}
