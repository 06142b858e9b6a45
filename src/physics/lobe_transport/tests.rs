use super::*;

fn small(g: f64, albedos: Vec<f64>, photons: u64, max_order: usize) -> LobeConfig {
    LobeConfig {
        g,
        albedos,
        rho: GradedAxis::new(0.0, 24.0, 24),
        z: GradedAxis::new(-16.0, 32.0, 32),
        theta_nodes: 17,
        direction_bins: 16,
        shape: LobeShape::Symmetric,
        photons,
        max_order,
        stream: StreamKey { table: 11, cell: 0 },
    }
}

/// The mapping and its inverse agree at every edge, and the edges span the requested extents.
#[test]
fn graded_axis_round_trips() {
    for (lo, hi, n) in [(0.0, 32.0, 96), (-16.0, 48.0, 160), (-5.0, 1.0, 7)] {
        let a = GradedAxis::new(lo, hi, n);
        assert!((a.edge(0) - lo).abs() < 1e-12 * hi.abs().max(1.0), "{} vs {lo}", a.edge(0));
        assert!((a.edge(n) - hi).abs() < 1e-12 * hi.abs().max(1.0), "{} vs {hi}", a.edge(n));
        for i in 0..=n {
            assert!((a.coordinate(a.edge(i)) - i as f64).abs() < 1e-9, "edge {i}");
        }
        for i in 0..n {
            assert_eq!(a.cell(a.center(i)), Some(i));
            assert!(a.edge(i + 1) > a.edge(i));
        }
        assert_eq!(a.cell(hi + 1e-9), None);
    }
}

/// The closed-form moments equal the brute-force double sums over flight pairs.
#[test]
fn collision_moments_match_direct_sums() {
    for g in [-0.6f64, 0.0, 0.3, 0.9] {
        for k in [1usize, 2, 5, 40] {
            let mean: f64 = (0..k).map(|j| g.powi(j as i32)).sum();
            // E|X|² = Σ_i Σ_j E[ℓ_i ℓ_j] g^{|i−j|}, E[ℓ²] = 2, E[ℓ_i ℓ_j] = 1 (i ≠ j).
            let mut msd = 0.0;
            for i in 0..k {
                for j in 0..k {
                    msd += if i == j { 2.0 } else { g.powi((i as i32 - j as i32).abs()) };
                }
            }
            let (m, v) = collision_moments(g, k as f64);
            assert!((m - mean).abs() < 1e-12 * mean.abs().max(1.0), "g {g} k {k}: mean {m} vs {mean}");
            let want = (msd - mean * mean) / 3.0;
            assert!((v - want).abs() < 1e-10 * want.max(1.0), "g {g} k {k}: var {v} vs {want}");
        }
    }
}

/// The Euler–Maclaurin integral of the remainder equals the brute-force sum of the Gaussian terms
/// (10^6 orders, then the integral of the rest) at α = 1 and α = 0.999.
#[test]
fn remainder_integral_matches_direct_sum() {
    let gauss = |albedo: f64, g: f64, k: f64, rho: f64, z: f64| {
        let (m, v) = collision_moments(g, k);
        albedo.powf(k) * (2.0 * PI * v).powf(-1.5) * (-(rho * rho + (z - m) * (z - m)) / (2.0 * v)).exp()
    };
    for (albedo, g, rho, z) in [(1.0, 0.5, 3.0, 4.0), (0.999, 0.0, 10.0, -2.0), (1.0, 0.9, 0.0, 30.0)] {
        let k_max = 300usize;
        let far = 1_000_000usize;
        let direct: f64 = (k_max + 1..=far).map(|k| gauss(albedo, g, k as f64, rho, z)).sum::<f64>()
            + remainder(albedo, g, far, rho, z);
        let got = remainder(albedo, g, k_max, rho, z);
        assert!((got / direct - 1.0).abs() < 1e-4, "α {albedo} g {g}: {got} vs {direct}");
    }
    assert_eq!(remainder(0.0, 0.3, 10, 1.0, 1.0), 0.0);
}

/// Every kernel column (one direction bin) integrates to 1 over the output sphere: the phase function
/// is normalised. With 65 θ nodes the trapezoid rule in θ is accurate to ~1e-3 at g = 0.3.
#[test]
fn kernel_columns_are_normalised() {
    let mut cfg = small(0.3, vec![0.5], 1024, 4);
    cfg.theta_nodes = 65;
    let k = kernel(&cfg);
    let nb = cfg.bins();
    let h = PI / (cfg.theta_nodes - 1) as f64;
    for b in 0..nb {
        let mut s = 0.0;
        for i in 0..cfg.theta_nodes {
            let w = if i == 0 || i == cfg.theta_nodes - 1 { 0.5 } else { 1.0 };
            s += w * h * 2.0 * PI * theta_node(i, cfg.theta_nodes).sin() * k[i * nb + b];
        }
        assert!((s - 1.0).abs() < 2e-3, "bin {b}: {s}");
    }
    // g = 0: every entry is exactly 1/4π.
    let cfg0 = small(0.0, vec![0.5], 1024, 4);
    for v in kernel(&cfg0) {
        assert!((v - 1.0 / (4.0 * PI)).abs() < 1e-12, "{v}");
    }
}

/// Conservation: photons of order k ≥ 2 scatter α^k times on average, so Σ_k α^k collisions per photon
/// integrate (density × cell volume) to α²/(1 − α) when the grid holds nearly every collision (α = 0.3:
/// orders that can leave a 16-mfp grid weigh < 1e-9). The tallies are exact integers, so the identity
/// holds to rounding, not to Monte-Carlo noise.
#[test]
fn density_integrates_to_expected_scattering_events() {
    let cfg = small(0.6, vec![0.0, 0.3, 0.5], 8192, 64);
    let r = compute(&cfg, &|_| {}).unwrap();
    for (ai, &a) in cfg.albedos.iter().enumerate() {
        let mut integral = 0.0;
        for iz in 0..cfg.z.bins {
            for ir in 0..cfg.rho.bins {
                let (r0, r1) = (cfg.rho.edge(ir), cfg.rho.edge(ir + 1));
                let v = PI * (r1 * r1 - r0 * r0) * (cfg.z.edge(iz + 1) - cfg.z.edge(iz));
                integral += r.density[ai][iz * cfg.rho.bins + ir] * v;
            }
        }
        let want = if a == 0.0 { 0.0 } else { a * a / (1.0 - a) };
        let inside: f64 = (2..=cfg.max_order).map(|k| a.powi(k as i32) * r.inside[k - 1]).sum();
        assert!((integral - want).abs() <= 2e-5 * want, "α {a}: {integral} vs {want}");
        assert!((integral - inside).abs() <= 1e-7 * want.max(1e-300), "α {a}: {integral} vs tallied {inside}");
    }
    assert_eq!(r.events, cfg.photons * cfg.max_order as u64);
}

/// The tallies are integers: one worker or two give bit-identical lobes.
#[test]
fn result_does_not_depend_on_thread_count() {
    let cfg = small(0.8, vec![0.9, 1.0], 3 * BATCH + 17, 32);
    let run = |n| {
        let pool = rayon::ThreadPoolBuilder::new().num_threads(n).build().unwrap();
        pool.install(|| compute(&cfg, &|_| {}).unwrap())
    };
    let (a, b) = (run(1), run(2));
    let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
    assert_eq!(bits(&a.double), bits(&b.double));
    for (x, y) in a.total.iter().zip(&b.total) {
        assert_eq!(bits(x), bits(y));
    }
}

/// The symmetric lobe is the azimuthal average of the full lobe (same tallies, same kernel), so the
/// full table averaged over φ reproduces the symmetric one.
#[test]
fn full_lobe_averages_to_symmetric() {
    let mut sym = small(0.7, vec![0.9], 4096, 16);
    sym.direction_bins = 32;
    let mut full = sym.clone();
    full.shape = LobeShape::Full { phi_bins: 9 };
    let (a, b) = (compute(&sym, &|_| {}).unwrap(), compute(&full, &|_| {}).unwrap());
    let nt = sym.theta_nodes;
    let np = 9;
    let mut worst = 0.0f64;
    let mut scale = 0.0f64;
    for cell in 0..sym.cells() {
        for i in 1..nt - 1 {
            // Trapezoid over φ ∈ [0, π] of the mirror-symmetric lobe = average over the circle.
            let row = &b.total[0][(cell * nt + i) * np..(cell * nt + i + 1) * np];
            let avg =
                (0..np).map(|m| if m == 0 || m == np - 1 { 0.5 } else { 1.0 } * row[m]).sum::<f64>() / (np - 1) as f64;
            let s = a.total[0][cell * nt + i];
            worst = worst.max((avg - s).abs());
            scale = scale.max(s);
        }
    }
    // The φ-trapezoid on 9 nodes is the only difference (bins coarser than the lobe's azimuthal
    // structure): a few per cent of the largest value at most.
    assert!(worst <= 0.05 * scale, "worst {worst} of {scale}");
}
