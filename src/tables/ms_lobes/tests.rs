use super::*;
use crate::reference::beam_adjoint;

/// A table small enough for the dev profile: 16-mfp grid, 2^16 photons.
fn small_def(g: Vec<f64>, albedos: Vec<f64>) -> MsLobes {
    MsLobes {
        materials: Vec::new(),
        g,
        albedo_grid: 0,
        albedos,
        rho_max: 8.0,
        z_min: -4.0,
        z_max: 12.0,
        rho_bins: 40,
        z_bins: 64,
        theta_bins: 33,
        direction_bins: 64,
        photons: 1 << 16,
        max_order: 256,
        element: Element::F64,
        mantissa_bits: 0,
        ..MsLobes::default()
    }
}

fn build(def: &MsLobes, seed: u8) -> (Generated, MsLobesTable) {
    let def = &MsLobes { seed: u64::from(seed), ..def.clone() };
    let g = def.generate(&[seed; 32], &|_| {}).unwrap();
    let t = MsLobesTable::from_arrays(def, &g.arrays, &g.values).unwrap();
    (g, t)
}

/// The bundled presets are wang2018 Table 2, digit for digit.
#[test]
fn material_presets_are_table_2() {
    let names: Vec<&str> = materials().iter().map(|m| m.name.as_str()).collect();
    assert_eq!(names, ["Oil", "Wax", "Milk", "Skin", "BumpySphere"]);
    let milk = material("Milk").unwrap();
    assert_eq!(milk.albedo, [0.9999, 0.9997, 0.9991]);
    assert_eq!(milk.mfp, [0.8422, 0.7521, 0.6848]);
    assert_eq!(milk.g, 0.7);
    assert_eq!(material("Oil").unwrap().albedo[0], 0.0042);
    assert_eq!(material("Skin").unwrap().g, 0.0);
    assert!(material("milk").is_none());
}

/// The default definition covers every Table 2 material exactly (its g and channel albedos are
/// nodes), plus α = 0 and α = 1.
#[test]
fn default_covers_table_2() {
    let def = MsLobes::default();
    assert!(def.validate().is_empty(), "{:?}", def.validate());
    assert_eq!(def.g_values(), vec![0.0, 0.7, 0.8, 0.9]);
    let a = def.albedo_values();
    for m in materials() {
        for c in m.albedo {
            assert!(a.contains(&c), "{} albedo {c} missing", m.name);
        }
    }
    assert_eq!((a[0], a[a.len() - 1]), (0.0, 1.0));
}

#[test]
fn validation_names_the_field() {
    let bad = MsLobes { materials: vec!["Honey".into()], photons: 1 << 31, max_order: 4096, ..MsLobes::default() };
    let fields: Vec<&str> = bad.validate().iter().map(|i| i.field).collect();
    assert!(fields.contains(&"materials"), "{fields:?}");
    assert!(fields.contains(&"photons"), "{fields:?}");
    let bad = MsLobes { g: vec![0.995], albedos: vec![1.5], ..MsLobes::default() };
    let fields: Vec<&str> = bad.validate().iter().map(|i| i.field).collect();
    assert_eq!(fields, ["g", "albedos"]);
}

/// A coarse grid (cells of ~0.3–0.6 mfp near the probes) with 2^20 photons traced to order 4: enough
/// second collisions per cell for a ~2 % noise level.
fn double_def(g: Vec<f64>) -> MsLobes {
    MsLobes { rho_bins: 16, z_bins: 24, photons: 1 << 20, max_order: 4, ..small_def(g, vec![0.5]) }
}

/// The exactly-two-events lobes agree with the deterministic beam quadrature of
/// `reference::beam_adjoint` (no shared code), averaged over the same cell; the tolerance is 4σ of the
/// table's noise (the spread of two independent keys) plus 1.5 % for the direction-bin kernel.
#[test]
fn double_matches_beam_quadrature() {
    let def = double_def(vec![0.0, 0.7]);
    let (_, a) = build(&def, 1);
    let (_, b) = build(&def, 9);
    let mut worst = 0.0f64;
    for g in [0.0, 0.7] {
        for (rho, z) in [(1.0, 2.0), (2.0, 0.5), (1.5, -1.0), (3.0, 5.0)] {
            for theta in [0.0, 1.0, 2.0, std::f64::consts::PI] {
                let ((rc, zc), want) =
                    cell_average(&def, rho, z, &|r, zz| beam_adjoint::double_symmetric(r, zz, theta, g)).unwrap();
                let q = LobeQuery { albedo: 0.5, g, rho: rc, z: zc, theta, phi: 0.0 };
                let (x, y) = (a.double_lobe(&q).unwrap(), b.double_lobe(&q).unwrap());
                let with_albedo = a.lobe(&q).unwrap().double;
                assert!((with_albedo - 0.25 * x).abs() <= 1e-15 * x);
                let got = 0.5 * (x + y);
                let sigma = 0.5 * (x - y).abs();
                worst = worst.max((got - want).abs() / want);
                assert!(
                    (got - want).abs() < 4.0 * sigma + 0.015 * want,
                    "g {g} cell ({rc:.3}, {zc:.3}) theta {theta}: {got} ± {sigma} vs {want}"
                );
            }
        }
    }
    eprintln!("worst E_2 relative error {worst:.4}");
}

/// Totals (all orders ≥ 2, incl. the closure) agree with the backward random walk within the combined
/// noise: the table's noise from two independent keys, the reference's from its own standard error.
#[test]
fn total_matches_backward_walk() {
    let def = small_def(vec![0.7], vec![0.8, 0.95]);
    let (_, a) = build(&def, 2);
    let (_, b) = build(&def, 3);
    for albedo in [0.8, 0.95] {
        for (rho, z, theta) in [(1.0, 2.0, 1.2), (2.5, 1.0, 0.4)] {
            let cfg = beam_adjoint::AdjointConfig { samples: 4000, max_order: 256, seed: 99 };
            let r = beam_adjoint::total_symmetric(rho, z, theta, 0.7, albedo, &cfg).unwrap();
            let q = LobeQuery { albedo, g: 0.7, rho, z, theta, phi: 0.0 };
            let (x, y) = (a.lobe(&q).unwrap().total, b.lobe(&q).unwrap().total);
            let table = 0.5 * (x + y);
            let table_se = 0.5 * (x - y).abs();
            let sigma = (table_se * table_se + r.std_error * r.std_error).sqrt();
            // 4σ (with the table's two-sample spread as its σ) plus 3 % for the cell average.
            assert!(
                (table - r.mean).abs() < 4.0 * sigma + 0.03 * r.mean,
                "α {albedo} ({rho}, {z}, θ {theta}): table {table} ± {table_se} vs walk {} ± {}",
                r.mean,
                r.std_error
            );
        }
    }
}

/// The full lobe resolves the azimuth: its `E_2` at (θ, φ) matches the pointwise quadrature with ω
/// built in each point's local frame, averaged over the cell (this pins the frame convention: φ = 0
/// toward `ê₁`). Tolerance as in `double_matches_beam_quadrature`, plus 3 % for the coarser (μ', φ') bins.
#[test]
fn full_lobe_matches_pointwise_quadrature() {
    let def = MsLobes { lobe: LobeKind::Full, phi_bins: 13, direction_bins: 32, ..double_def(vec![0.7]) };
    let (_, a) = build(&def, 4);
    let (_, b) = build(&def, 10);
    for (theta, phi) in [(0.6, 0.0), (0.6, std::f64::consts::PI), (1.4, 1.0), (2.4, 2.5)] {
        let ((rc, zc), want) = cell_average(&def, 1.5, 1.0, &|r, zz| {
            let p = [r, 0.0, zz];
            let (ax, e1, e2) = crate::physics::lobe_transport::lobe_frame(p.into());
            let (st, ct) = (f64::sin(theta), f64::cos(theta));
            let w: [f64; 3] =
                std::array::from_fn(|i| ct * ax[i] + st * (f64::cos(phi) * e1[i] + f64::sin(phi) * e2[i]));
            beam_adjoint::e2(p, w, 0.7)
        })
        .unwrap();
        let q = LobeQuery { albedo: 0.5, g: 0.7, rho: rc, z: zc, theta, phi };
        let (x, y) = (a.double_lobe(&q).unwrap(), b.double_lobe(&q).unwrap());
        let (got, sigma) = (0.5 * (x + y), 0.5 * (x - y).abs());
        assert!((got - want).abs() < 4.0 * sigma + 0.045 * want, "θ {theta} φ {phi}: {got} ± {sigma} vs {want}");
    }
}

/// σ_t scaling: a medium with σ_t = 2 is the canonical one at doubled coordinates with values × 8; the
/// beam frame may point anywhere.
#[test]
fn radiance_scales_with_sigma_t_and_rotates_with_the_beam() {
    let def = small_def(vec![0.0, 0.7], vec![0.5, 0.9]);
    let (_, t) = build(&def, 5);
    let m = MediumChannel { albedo: 0.9, sigma_t: 2.0, g: 0.35 };
    // Beam along +x from (1, 1, 1); point 0.75 ahead and 0.5 off the axis (along +y).
    let beam = ([1.0, 1.0, 1.0], [3.0, 0.0, 0.0]);
    let x = [1.75, 1.5, 1.0];
    let omega = [0.0, 1.0, 0.0];
    let got = t.radiance(&m, beam, x, omega).unwrap();
    let p = [0.75f64, 0.5];
    let r = (p[0] * p[0] + p[1] * p[1]).sqrt();
    let theta = (p[1] / r).acos();
    let q = LobeQuery { albedo: 0.9, g: 0.35, rho: 2.0 * p[1], z: 2.0 * p[0], theta, phi: 0.0 };
    let want = t.lobe(&q).unwrap();
    assert!((got.total - 8.0 * want.total).abs() <= 1e-12 * got.total, "{got:?} vs {want:?}");
    assert!((got.double - 8.0 * want.double).abs() <= 1e-12 * got.double);
}

/// Albedo interpolation is exact at nodes and stays between them; g outside the slices and albedo
/// outside the nodes are refused with the fix named.
#[test]
fn interpolation_and_refusals() {
    let def = small_def(vec![0.0, 0.7], vec![0.5, 0.9]);
    let (_, t) = build(&def, 6);
    let at = |albedo| t.lobe(&LobeQuery { albedo, g: 0.7, rho: 1.0, z: 1.0, theta: 1.0, phi: 0.0 }).unwrap().total;
    let (lo, hi, mid) = (at(0.5), at(0.9), at(0.75));
    assert!(lo < mid && mid < hi, "{lo} {mid} {hi}");
    let e = t.lobe(&LobeQuery { albedo: 0.9, g: 0.8, rho: 1.0, z: 1.0, theta: 1.0, phi: 0.0 }).unwrap_err();
    assert_eq!(e, LobeQueryError::GOutOfRange { g: 0.8, min: 0.0, max: 0.7 });
    assert!(e.to_string().contains("g list"), "{e}");
    let e = t.lobe(&LobeQuery { albedo: 0.95, g: 0.0, rho: 1.0, z: 1.0, theta: 1.0, phi: 0.0 }).unwrap_err();
    assert_eq!(e, LobeQueryError::AlbedoOutOfRange { albedo: 0.95, min: 0.5, max: 0.9 });
    assert!(e.to_string().contains("albedo_grid"), "{e}");
    let e = t.lobe(&LobeQuery { albedo: 1.5, g: 0.0, rho: 1.0, z: 1.0, theta: 1.0, phi: 0.0 }).unwrap_err();
    assert!(matches!(e, LobeQueryError::Invalid(_)) && e.to_string().contains("outside [0, 1]"), "{e}");
}

/// Beyond the grid values decay monotonically outward (never grow, never NaN), and at α = 1 (no
/// absorption) more slowly than at α = 0.5.
#[test]
fn decays_outside_the_grid() {
    let def = small_def(vec![0.0], vec![0.5, 1.0]);
    let (_, t) = build(&def, 7);
    for albedo in [0.5, 1.0] {
        let mut last = f64::INFINITY;
        for s in [1.0, 1.5, 3.0, 10.0, 1e3, 1e200] {
            let v = t.lobe(&LobeQuery { albedo, g: 0.0, rho: 8.0 * s, z: 12.0 * s, theta: 0.5, phi: 0.0 }).unwrap();
            assert!(v.total.is_finite() && v.total >= 0.0 && v.total <= last, "α {albedo} s {s}: {v:?}");
            last = v.total;
        }
    }
    let f = |albedo| {
        let q = |s: f64| LobeQuery { albedo, g: 0.0, rho: 8.0 * s, z: 12.0 * s, theta: 0.5, phi: 0.0 };
        t.lobe(&q(2.0)).unwrap().total / t.lobe(&q(1.0)).unwrap().total
    };
    assert!(f(1.0) > f(0.5), "{} vs {}", f(1.0), f(0.5));
}

/// Loading only what the media need: one (α, g) pair between two nodes of one g slice loads two
/// slices, and the values equal the fully loaded table's.
#[test]
fn open_loads_only_the_needed_slices() {
    let def = MsLobes { element: Element::F32, mantissa_bits: 10, ..small_def(vec![0.0, 0.7], vec![0.5, 0.9, 1.0]) };
    let g = def.generate(&[8; 32], &|_| {}).unwrap();
    let header = crate::container::Header {
        kind: "MsLobes".into(),
        kind_schema_version: KIND_SCHEMA_VERSION,
        generator_version: GENERATOR_VERSION.into(),
        definition_ron: TableDef::MsLobes(def.clone()).canonical_ron(),
        content_key: [8; 32],
        arrays: g.arrays.clone(),
    };
    let enc = crate::container::encode(&header, &g.values, &crate::container::EncodeOptions { zstd_level: 3 }).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("lobes.vtab");
    std::fs::write(&path, &enc.bytes).unwrap();
    let part = MsLobesTable::open(&path, Some(&[(0.95, 0.7)])).unwrap();
    assert_eq!(part.loaded_slices(), 2);
    let all = MsLobesTable::open(&path, None).unwrap();
    assert_eq!(all.loaded_slices(), 6);
    let q = LobeQuery { albedo: 0.95, g: 0.7, rho: 0.7, z: 2.0, theta: 0.3, phi: 0.0 };
    assert_eq!(part.lobe(&q).unwrap(), all.lobe(&q).unwrap());
    let e = part.lobe(&LobeQuery { g: 0.0, ..q }).unwrap_err();
    assert!(matches!(e, LobeQueryError::NotLoaded(_)) && e.to_string().contains("is not loaded"), "{e}");
}

use crate::tables::TableDef;

/// A channel's extracted slice answers like the table (same interpolation; only the order of the
/// g/albedo blend differs, so within rounding) inside the grid, outside it and behind the beam, and
/// refuses what the table refuses.
#[test]
fn slice_matches_the_table() {
    let def = small_def(vec![0.0, 0.7], vec![0.5, 0.9]);
    let (_, t) = build(&def, 9);
    let m = MediumChannel { albedo: 0.8, sigma_t: 3.0, g: 0.4 };
    let s = t.slice(&m).unwrap();
    let mut checked = 0;
    for (i, x) in [[0.1, 0.2, 0.3], [2.0, -1.0, 0.5], [-0.4, 0.05, 0.0], [30.0, 2.0, -7.0], [0.0, 0.0, 1e-9]]
        .into_iter()
        .enumerate()
    {
        let beam = ([0.0, 0.0, 0.0], [0.3, -0.2, 0.9]);
        let omega = [0.2 + 0.1 * i as f64, 0.7, -0.4];
        let (a, b) = (t.radiance(&m, beam, x, omega).unwrap(), s.radiance(beam, x, omega).unwrap());
        for (u, v) in [(a.total, b.total), (a.double, b.double)] {
            assert!((u - v).abs() <= 1e-12 * u.abs().max(1e-300), "{x:?}: {a:?} vs {b:?}");
        }
        let mult = s.multiple_radiance(beam, x, omega).unwrap();
        assert!((mult - (a.total - a.double)).abs() <= 1e-12 * a.total.max(1e-300), "{x:?}: {mult} vs {a:?}");
        let (rho, z) = (0.5 + i as f64, 3.0 - 2.0 * i as f64);
        let (u, v) = (t.density(m.albedo, m.g, rho, z).unwrap(), s.density(rho, z).unwrap());
        assert!((u - v).abs() <= 1e-12 * u.abs(), "density at ({rho}, {z}): {u} vs {v}");
        assert!(u > 0.0);
        checked += 1;
    }
    assert_eq!(checked, 5);
    assert!(s.radiance(([0.0; 3], [0.0; 3]), [1.0; 3], [0.0, 0.0, 1.0]).is_err());
    assert!(s.density(f64::NAN, 1.0).is_err());
    assert!(matches!(t.slice(&MediumChannel { albedo: 0.95, ..m }), Err(LobeQueryError::AlbedoOutOfRange { .. })));
    assert!(matches!(t.slice(&MediumChannel { g: 0.8, ..m }), Err(LobeQueryError::GOutOfRange { .. })));
    assert!(matches!(t.slice(&MediumChannel { sigma_t: 0.0, ..m }), Err(LobeQueryError::Invalid(_))));
}
