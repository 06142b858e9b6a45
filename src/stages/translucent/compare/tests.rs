use super::*;

fn reference(values: Vec<[f64; 3]>, variance: Vec<[f64; 3]>, object: Vec<bool>, samples: u64) -> ReferenceImage {
    let n = values.len();
    ReferenceImage {
        width: n,
        height: 1,
        components: [vec![[0.0; 3]; n], values, vec![[0.0; 3]; n], vec![[0.0; 3]; n]],
        variance,
        object,
        paths: samples * n as u64,
        nonfinite: 0,
        seconds: 1.0,
    }
}

/// The normalisation is the reference's mean over the object, not its bright end: a percentile
/// of a noisy reference is inflated by the noise and made errors look up to 2.7× smaller (issue 30).
#[test]
fn scale_is_the_mean_of_object_values() {
    // 100 object pixels with values 1..=100 in every channel, one bright non-object pixel.
    let mut vals: Vec<[f64; 3]> = (1..=100).map(|i| [i as f64; 3]).collect();
    vals.push([1e6; 3]);
    let mut obj = vec![true; 100];
    obj.push(false);
    let r = reference(vals, vec![[0.0; 3]; 101], obj, 16);
    assert_eq!(scale_of(&r), 50.5);
    // A black object keeps the unit scale.
    let r = reference(vec![[0.0; 3]; 4], vec![[0.0; 3]; 4], vec![true; 4], 16);
    assert_eq!(scale_of(&r), 1.0);
}

/// Block means over the object's pixels: a full 4 × 4 block's mean has a sixteenth of a pixel's
/// variance, a block with one object pixel keeps that pixel's; blocks without one are left out.
#[test]
fn block_means_average_the_object_pixels_of_each_block() {
    // 8 × 4 pixels: the left block fully object, the right block only its pixel (4, 0).
    let (w, h) = (8, 4);
    let mask: Vec<bool> = (0..w * h).map(|i| (i % w) < 4 || i == 4).collect();
    let a: Vec<[f64; 3]> = (0..w * h).map(|i| [i as f64; 3]).collect();
    let r = vec![[1.0; 3]; w * h];
    let var = vec![[0.16; 3]; w * h];
    let (ba, br, bv) = block_means(&a, &r, &var, &mask, w);
    assert_eq!(ba.len(), 2);
    // Left block: columns 0..4 of rows 0..4, mean index (0+1+2+3)/4 + 8·(0+1+2+3)/4 = 1.5 + 12.
    assert_eq!(ba[0], [13.5; 3]);
    assert_eq!(ba[1], [4.0; 3]);
    assert_eq!(br, vec![[1.0; 3]; 2]);
    assert!((bv[0][0] - 0.01).abs() < 1e-15 && (bv[1][0] - 0.16).abs() < 1e-15, "{bv:?}");
}

#[test]
fn noise_is_removed_and_the_speedup_follows_the_reference_line() {
    // Reference: every object pixel 2.0 with variance of the mean 0.04 (per channel) at 16 paths.
    let n = 10;
    let r = reference(vec![[2.0; 3]; n], vec![[0.04; 3]; n], vec![true; n], 16);
    let frame = Frame {
        width: n,
        height: 1,
        single: vec![[2.2; 3]; n],
        double: vec![[0.0; 3]; n],
        multiple: vec![[0.0; 3]; n],
        bounced: vec![[0.0; 3]; n],
        rest: vec![[0.0; 3]; n],
        object: vec![true; n],
        times: Default::default(),
        stats: Default::default(),
    };
    let c = compare(&frame, 10.0, &r, 1000.0);
    // s = 2: MSE = (0.2/2)² = 0.01; noise = 0.04/4 = 0.01 → corrected 0 → below the floor.
    assert!((c.mse - 0.01).abs() < 1e-12);
    assert!((c.reference_noise - 0.01).abs() < 1e-12);
    assert!(c.lower_bound);
    // Floor over 30 channel values of variance 0.04: se0 = sqrt(2·0.04²/30), floor = sqrt(2 se0)/2;
    // the reference reaches MSE floor² with 16 · 0.01/floor² paths, the speed-up is its time / 10 ms.
    let e = c.error.unwrap();
    let se0 = (2.0 * 0.04f64.powi(2) / 30.0).sqrt();
    let floor = (2.0 * se0).sqrt() / 2.0;
    assert!(e.rel_rmse.is_none() && (e.floor - floor).abs() < 1e-12, "{e:?}");
    assert!((c.speedup - 1000.0 * 0.01 / (floor * floor) / 10.0).abs() < 1e-6, "{}", c.speedup);
    assert!((c.mse_components[0] - 0.01).abs() < 1e-12);
    // A frame off by 0.4 (MSE 0.04, corrected 0.03 = relative RMSE √0.03 ≈ 17 %, above the floor of
    // ≈ 7.2 %): the reference needs 16 · 0.01/0.03 paths.
    let far = Frame { single: vec![[2.4; 3]; n], ..frame };
    let c = compare(&far, 10.0, &r, 1000.0);
    assert!(!c.lower_bound && (c.mse_corrected - 0.03).abs() < 1e-12);
    assert!((c.error.unwrap().rel_rmse.unwrap() - 0.03f64.sqrt()).abs() < 1e-12);
    assert!((c.speedup - 1000.0 / 3.0 / 10.0).abs() < 1e-9);
}
