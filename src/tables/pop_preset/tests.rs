//! PopPreset tests: each pins a value derived independently of the generator.

use std::f64::consts::{FRAC_1_SQRT_2, PI};

use glam::DVec3;

use super::ordinates::{cell_quadrature, fibonacci_directions, quadrature_samples};
use super::*;
use crate::container::{EncodeOptions, Header, encode};
use crate::tables::TableDef;

fn generated(def: &PopPreset) -> Generated {
    def.generate(&[7; 32], &|_| {}).unwrap()
}

fn table(def: &PopPreset) -> PopPresetTable {
    let g = generated(def);
    PopPresetTable::from_arrays(def, &g.arrays, &g.values).unwrap()
}

#[test]
fn isotropic_flow_row_is_the_solid_angle_fractions_of_the_cones() {
    // a = 0 is row 2 of 5; front/back cones of half-angle π/4 hold (1 − cos π/4)/2 of the sphere
    // each, the four side wedges share the rest: cos(π/4)/4 each.
    let def = PopPreset { a_bins: 5, element: Element::F64, ..PopPreset::default() };
    let t = table(&def);
    let cone = (1.0 - FRAC_1_SQRT_2) / 2.0;
    let [f, s, b] = t.flow_rows()[2];
    assert!((f - cone).abs() < 1e-15 && (b - cone).abs() < 1e-15, "{f} {b}");
    assert!((s - FRAC_1_SQRT_2 / 4.0).abs() < 1e-15, "{s}");
    let [f, s, b] = t.flow(0.0);
    assert!((f - cone).abs() < 1e-15 && (s - FRAC_1_SQRT_2 / 4.0).abs() < 1e-15 && (b - cone).abs() < 1e-15);
}

#[test]
fn flow_at_the_dirac_ends_and_clamping_and_nan() {
    let t = table(&PopPreset { a_bins: 16, ..PopPreset::default() });
    assert_eq!(t.flow(1.0), [1.0, 0.0, 0.0]);
    assert_eq!(t.flow(7.0), [1.0, 0.0, 0.0]);
    assert_eq!(t.flow(-1.0), [0.0, 0.0, 1.0]);
    assert_eq!(t.flow(-3.0), [0.0, 0.0, 1.0]);
    assert!(t.flow(f64::NAN).iter().all(|v| v.is_nan()));
}

#[test]
fn flow_interpolation_converges_against_the_double_double_reference() {
    // Linear interpolation: halving the spacing should cut the error ~4x (smooth partition).
    let e =
        |bins| table(&PopPreset { a_bins: bins, element: Element::F64, ..PopPreset::default() }).flow_interp_error();
    let (coarse, fine) = (e(65), e(129));
    assert!(fine < coarse / 3.0 && fine < 2e-3, "{coarse} {fine}");
    // The reference agrees with pop_partition itself to rounding (two independent derivations).
    for a in [-0.999_999, -0.3, 1e-12, 0.5, 0.999_999] {
        let (r, p) = (flow_reference(a), hg::pop_partition(a));
        assert!((0..3).all(|k| (r[k] - p[k]).abs() < 1e-14), "a = {a}: {r:?} {p:?}");
    }
}

#[test]
fn solid_angles_sum_to_four_pi_and_cells_are_nearly_equal() {
    for n in [1u32, 7, 64, 125] {
        let t = table(&PopPreset { ordinates: n, element: Element::F64, ..PopPreset::default() });
        let sum: f64 = t.solid_angles().iter().sum();
        assert!((sum / (4.0 * PI) - 1.0).abs() < 1e-9, "N = {n}: {sum}");
        assert!(t.ordinates().iter().all(|&d| (DVec3::from_array(d).length_squared() - 1.0).abs() < 1e-15));
    }
}

#[test]
fn two_antipodal_directions_split_the_sphere_into_hemispheres_of_mean_cosine_one_half() {
    // ±z: each cell is a hemisphere, Ω = 2π, mean cosine ∫cos θ dω / 2π = 1/2 exactly.
    let q = cell_quadrature(&[[0.0, 0.0, 1.0], [0.0, 0.0, -1.0]], 1 << 20, &|_| {});
    for (omega, a) in q.solid_angle.iter().zip(&q.mean_cosine) {
        assert!((omega - 2.0 * PI).abs() < 1e-12, "{:?}", q.solid_angle);
        assert!((a - 0.5).abs() < 1e-9, "{:?}", q.mean_cosine);
    }
}

#[test]
fn fibonacci_two_points_give_hemisphere_cells_about_their_bisector() {
    // N = 2 Fibonacci points are z = ±1/2 (not antipodal). Any two unit vectors split the sphere by
    // their bisecting great circle: Ω = 2π each, and the cell of d0 is the hemisphere about
    // c = (d0 − d1)/|d0 − d1|, whose mean direction is c/2, so a_0 = d0·c/2 = |d0 − d1|/4.
    let d = fibonacci_directions(2);
    assert!((d[0][2] - 0.5).abs() < 1e-15 && (d[1][2] + 0.5).abs() < 1e-15);
    let expect = (DVec3::from_array(d[0]) - DVec3::from_array(d[1])).length() / 4.0;
    let t = table(&PopPreset { ordinates: 2, element: Element::F64, ..PopPreset::default() });
    for (omega, a) in t.solid_angles().iter().zip(t.mean_cosines()) {
        assert!((omega / (2.0 * PI) - 1.0).abs() < 1e-4, "{:?}", t.solid_angles());
        assert!((a - expect).abs() < 1e-4, "{:?} vs {expect}", t.mean_cosines());
    }
}

#[test]
fn one_ordinate_owns_the_whole_sphere_with_mean_cosine_zero() {
    let t = table(&PopPreset { ordinates: 1, element: Element::F64, ..PopPreset::default() });
    assert!((t.solid_angles()[0] - 4.0 * PI).abs() < 1e-12);
    assert!(t.mean_cosines()[0].abs() < 1e-5, "{}", t.mean_cosines()[0]);
}

#[test]
fn cell_quadrature_is_within_half_a_percent_of_an_8x_finer_one() {
    // The per-cell quadrature error (brief: < 1 %) judged against the same integral with 8x the
    // samples; the search behind both is checked against brute force separately.
    for n in [64usize, 125] {
        let dirs = fibonacci_directions(n);
        let q = cell_quadrature(&dirs, quadrature_samples(n), &|_| {});
        let fine = cell_quadrature(&dirs, 8 * quadrature_samples(n), &|_| {});
        for j in 0..n {
            let rel = (q.solid_angle[j] / fine.solid_angle[j] - 1.0).abs();
            assert!(rel < 5e-3, "N = {n}, cell {j}: {rel}");
            let diff = (q.mean_cosine[j] - fine.mean_cosine[j]).abs();
            assert!(diff < 5e-5, "N = {n}, cell {j}: {diff}");
        }
    }
}

#[test]
fn sweep_search_agrees_with_brute_force() {
    for n in [1usize, 2, 3, 64, 500] {
        let dirs = fibonacci_directions(n);
        let s = ordinates::NearestDirection::new(&dirs);
        let stream = crate::physics::rng::StreamKey { table: 3, cell: n as u64 };
        for k in 0..2000 {
            let z = 1.0 - 2.0 * stream.uniform(k, 0);
            let phi = 2.0 * PI * stream.uniform(k, 1);
            let r = (1.0 - z * z).max(0.0).sqrt();
            let w = DVec3::new(r * phi.cos(), r * phi.sin(), z);
            let dot = |a: usize| DVec3::from_array(dirs[a]).dot(w);
            let brute = (0..n).max_by(|&a, &b| dot(a).total_cmp(&dot(b)).then(b.cmp(&a))).unwrap();
            assert_eq!(s.nearest(w.to_array()).unwrap().0, brute, "N = {n}, sample {k}");
        }
    }
}

#[test]
fn switch_iteration_matches_a_hand_calculation() {
    // ln(0.1)/ln(0.9)/0.25 = 21.854…/0.25 = 87.42 → 88.
    assert_eq!(switch_iteration_raw(0.1, 1.0, 0.9, 0.25, 1.0, 10), Some(88));
    assert_eq!(switch_iteration_raw(0.1, 1.0, 0.9, 0.5, 0.5, 100), Some(100), "at least the grid length");
    let p = PopPreset { iterations: 200, ..PopPreset::default() };
    assert_eq!(p.switch_iteration(1.0, 0.9, 0.25, 1.0, 10), 88);
    assert_eq!(p.switch_iteration(1.0, -0.9, 0.25, 1.0, 10), 88, "g enters by magnitude");
    assert_eq!(PopPreset::default().switch_iteration(1.0, 0.9, 0.25, 1.0, 10), 15, "capped at iterations");
    // Extremes.
    assert_eq!(p.switch_iteration(1.0, 0.0, 0.25, 1.0, 20), 20, "g = 0: isotropic after one scattering");
    assert_eq!(p.switch_iteration(0.05, 0.9, 0.25, 1.0, 20), 20, "a_max <= eps_a");
    assert_eq!(p.switch_iteration(1.0, 0.9, 0.0, 1.0, 20), 200, "no scattering: never switches");
    assert_eq!(p.switch_iteration(1.0, 1.0, 0.25, 1.0, 20), 200, "g = 1: never switches");
    assert_eq!(p.switch_iteration(1.0, 1.0 - 1e-16, 0.25, 1.0, 20), 200);
    assert_eq!(p.switch_iteration(f64::NAN, 0.9, 0.25, 1.0, 20), 200);
    assert_eq!(switch_iteration_raw(0.1, 1.0, 0.9, 1e-300, 1.0, 20), None);
    let off = PopPreset { residuum: false, ..p };
    assert_eq!(off.switch_iteration(1.0, 0.0, 0.25, 1.0, 20), 200, "residuum off");
}

#[test]
fn validation_names_the_field() {
    let field = |p: PopPreset| p.validate().into_iter().map(|i| (i.field, i.message)).collect::<Vec<_>>();
    let v = field(PopPreset { a_bins: 1, ..PopPreset::default() });
    assert_eq!(v.len(), 1);
    assert_eq!(v[0], ("a_bins", "a_bins = 1 is out of range".to_owned()));
    let v = field(PopPreset { eps_a: 0.0, ..PopPreset::default() });
    assert_eq!(v, [("eps_a", "eps_a = 0 is outside (0, 1)".to_owned())]);
    let v = field(PopPreset { grid: [20, 0, 20], ..PopPreset::default() });
    assert_eq!(v, [("grid", "grid[1] (y) = 0 is out of range".to_owned())]);
    assert!(field(PopPreset { grid: [1, 1, 1], ..PopPreset::default() }).is_empty());
    assert!(field(PopPreset { eps_l: f64::NAN, ..PopPreset::default() })[0].0 == "eps_l");
    assert!(field(PopPreset { beta: 0.0, ..PopPreset::default() })[0].0 == "beta");
    assert!(field(PopPreset { ordinates: 4097, ..PopPreset::default() })[0].0 == "ordinates");
    assert!(field(PopPreset::default()).is_empty());
}

#[test]
fn a_file_round_trip_gives_identical_arrays_and_generation_is_deterministic() {
    let def = PopPreset { ordinates: 27, a_bins: 33, ..PopPreset::default() };
    let (g1, g2) = (generated(&def), generated(&def));
    let td = TableDef::PopPreset(def.clone());
    let header = Header {
        kind: td.kind().to_owned(),
        kind_schema_version: td.kind_impl().kind_schema_version(),
        generator_version: td.kind_impl().generator_version().to_owned(),
        definition_ron: td.canonical_ron(),
        content_key: [7; 32],
        arrays: g1.arrays.clone(),
    };
    let bytes = encode(&header, &g1.values, &EncodeOptions { zstd_level: def.zstd_level }).unwrap().bytes;
    let bytes2 = encode(&header, &g2.values, &EncodeOptions { zstd_level: def.zstd_level }).unwrap().bytes;
    assert_eq!(bytes, bytes2, "two generations are byte-equal");
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("pop.vtab");
    std::fs::write(&path, &bytes).unwrap();
    let read = PopPresetTable::open(&path).unwrap();
    let mem = PopPresetTable::from_arrays(&def, &g1.arrays, &g1.values).unwrap();
    assert_eq!(read.def, def);
    assert_eq!(read.ordinates(), mem.ordinates());
    assert_eq!(read.solid_angles(), mem.solid_angles());
    assert_eq!(read.mean_cosines(), mem.mean_cosines());
    assert_eq!(read.flow_rows(), mem.flow_rows());
    assert_eq!(read.switch_iteration(1.0, 0.9, 0.25, 1.0, 10), 15);
}

#[test]
fn error_estimates_are_small_for_the_realtime_preset() {
    let def = PopPreset::default();
    let g = generated(&def);
    let stats = def.estimate_errors(&g, &[7; 32]).unwrap();
    let get = |n: &str| stats.errors.iter().find(|e| e.name == n).unwrap().value;
    assert_eq!(stats.errors[0].name, "flow_interp_max_abs");
    assert!(get("flow_interp_max_abs") < 1e-3, "{stats:?}");
    assert!(get("flow_sum_max_dev") < 1e-6, "{stats:?}");
    // 64 Fibonacci points: cells of 11 deg mean radius; covering radius a bit above that.
    let cov = get("ordinate_covering_deg");
    assert!(cov > 11.0 && cov < 20.0, "{cov}");
    assert!(get("ordinate_solid_angle_max_rel_dev") < 0.1, "{stats:?}");
    assert!(get("mean_cosine_check") < 5e-3, "{stats:?}");
}
