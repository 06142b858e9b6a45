use super::*;
use crate::physics::rng::StreamKey;

/// An exact method against a noisy reference: the raw error is the noise, the corrected one is
/// below the floor, and the report says so instead of a smaller number.
#[test]
fn an_exact_method_reads_below_the_floor() {
    let n = 4000;
    let sigma = 0.1;
    let truth: Vec<f64> = (0..n).map(|i| 1.0 + 0.5 * ((i as f64) * 0.01).sin()).collect();
    let r: Vec<f64> = (0..n).map(|i| truth[i] + sigma * gauss(7, i as u64)).collect();
    let e = NoiseCorrected::of(&truth, &r, &vec![sigma * sigma; n]).unwrap();
    assert_eq!(e.rel_rmse, None, "{e:?}");
    assert!(e.percent().starts_with("< floor "), "{}", e.percent());
    // raw ≈ σ/mean(r); floor = sqrt(2·sqrt(2σ⁴/n))/mean(r) = σ·(8/n)^{1/4}/mean(r).
    assert!((e.raw_rel_rmse - sigma / e.norm).abs() < 0.005, "{e:?}");
    assert!((e.floor - sigma * (8.0 / n as f64).powf(0.25) / e.norm).abs() < 1e-12, "{e:?}");
    assert!((e.reference_noise - sigma / e.norm).abs() < 1e-12);
}

/// A method 5 % off everywhere, reference noise 10 % per item: the raw error (≈ 11.2 %) would
/// flatter nothing but overstates; the corrected one recovers 5 % inside its interval.
#[test]
fn a_biased_method_is_recovered_under_the_noise() {
    let n = 20_000;
    let sigma = 0.1;
    let a = vec![1.05; n];
    let r: Vec<f64> = (0..n).map(|i| 1.0 + sigma * gauss(11, i as u64)).collect();
    let e = NoiseCorrected::of(&a, &r, &vec![sigma * sigma; n]).unwrap();
    let rel = e.rel_rmse.expect("above the floor");
    assert!((rel - 0.05).abs() < 0.005, "{e:?}");
    assert!(e.ci95[0] <= 0.05 && 0.05 <= e.ci95[1], "{e:?}");
    assert!((e.raw_rel_rmse - (0.05f64.powi(2) + 0.01).sqrt()).abs() < 0.003, "{e:?}");
    assert!(e.percent().starts_with("5.0 % ["), "{}", e.percent());
}

/// Normalised by the mean, not by a bright outlier: one pixel 100× brighter changes the norm by
/// its share of the mean only.
#[test]
fn the_norm_is_the_mean() {
    let mut r = vec![1.0; 99];
    r.push(100.0);
    let a: Vec<f64> = r.iter().map(|x| x * 1.1).collect();
    let e = NoiseCorrected::of(&a, &r, &vec![0.0; 100]).unwrap();
    assert!((e.norm - 1.99).abs() < 1e-12);
    // Σ(0.1 r)²/n = (99·0.01 + 100)/100; relative to the mean 1.99.
    let want = ((99.0 * 0.01 + 100.0) / 100.0f64).sqrt() / 1.99;
    assert!((e.rel_rmse.unwrap() - want).abs() < 1e-12);
    assert_eq!(e.floor, 0.0);
}

/// The masked form compares exactly the kept items; a mask of another length is refused.
#[test]
fn masked_items_are_the_kept_ones() {
    let a = [[1.0; 3], [50.0; 3], [2.0; 3]];
    let r = [[1.5; 3], [1.0; 3], [2.5; 3]];
    let v = [[0.01; 3]; 3];
    let m = NoiseCorrected::of_rgb_masked(&a, &r, &v, &[true, false, true]).unwrap();
    assert_eq!(m, NoiseCorrected::of_rgb(&[a[0], a[2]], &[r[0], r[2]], &[v[0], v[2]]).unwrap());
    // Above the floor (a 0.5 offset against noise 0.1): the number itself.
    assert!(!m.below_floor() && m.rel_or_floor() == m.rel_rmse.unwrap());
    assert!(NoiseCorrected::of_rgb_masked(&a, &r, &v, &[true]).unwrap_err().contains("mask"));
}

#[test]
fn bad_input_is_refused() {
    assert!(NoiseCorrected::of(&[1.0], &[1.0, 2.0], &[0.0, 0.0]).unwrap_err().contains("lengths differ"));
    assert!(NoiseCorrected::of(&[], &[], &[]).is_err());
    assert!(NoiseCorrected::of(&[1.0], &[0.0], &[0.0]).unwrap_err().contains("not positive"));
    assert!(NoiseCorrected::of(&[f64::NAN], &[1.0], &[0.0]).unwrap_err().contains("not finite"));
}

/// A standard normal draw from the counter-based stream `(key, i)` (Box–Muller).
fn gauss(key: u64, i: u64) -> f64 {
    let s = StreamKey { table: key, cell: i };
    let (u1, u2) = (s.uniform(0, 0).max(1e-300), s.uniform(0, 1));
    (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
}
