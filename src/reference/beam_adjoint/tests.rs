//! Tests of the beam adjoint reference against independently derived values: conservation of the
//! second scattering events (`∫∫ E_2 dω dV = 1`), a brute-force Simpson rule on a different
//! substitution, the isotropy of `E_2` at `g = 0`, a periodic trapezoid rule over the lobe azimuth,
//! an independent quadrature of `E_3` at `g = 0` (bipolar coordinates), exact identities of the
//! walk (order 2 alone, polynomial dependence on the albedo along fixed paths), thread-count
//! determinism, extreme inputs and validation. Input: fixed probes and seeds; output: pass/fail,
//! with the agreements printed (`cargo test -- --nocapture`).

use std::f64::consts::{PI, TAU};

use super::*;

/// HG phase written out for the brute-force rules (not the crate's implementation).
fn hg(mu: f64, g: f64) -> f64 {
    let s2 = 1.0 + g * g - 2.0 * g * mu;
    (1.0 - g * g) / (4.0 * PI * s2 * s2.sqrt())
}

/// Composite Simpson rule with `n` (even) intervals.
fn simpson(f: impl Fn(f64) -> f64, a: f64, b: f64, n: usize) -> f64 {
    let h = (b - a) / n as f64;
    let mut s = f(a) + f(b);
    for i in 1..n {
        s += if i % 2 == 1 { 4.0 } else { 2.0 } * f(a + h * i as f64);
    }
    s * h / 3.0
}

/// `E_2(P, ω)` by Simpson with 10⁶ intervals on `z_b = z + ρ sinh s` (then `r = ρ cosh s`,
/// `dz_b/r² = ds/(ρ cosh s)`, `z_b + r = z + ρ eˢ`, `ẑ·ŝ = −tanh s`), from `z_b = 0` to where
/// `z_b + r` exceeds `|P|` by 120.
fn e2_simpson(p: [f64; 3], omega: [f64; 3], g: f64) -> f64 {
    let rho = p[0].hypot(p[1]);
    let e = [p[0] / rho, p[1] / rho];
    let dist = rho.hypot(p[2]);
    let s0 = (-p[2] / rho).asinh();
    let s1 = ((dist - p[2] + 120.0) / rho).ln();
    let f = |s: f64| {
        let (sh, ch) = (s.sinh(), s.cosh());
        let (sin_psi, cos_psi) = (1.0 / ch, -sh / ch);
        let s_dot_w = sin_psi * (e[0] * omega[0] + e[1] * omega[1]) + cos_psi * omega[2];
        let exponent = p[2] + rho * s.exp();
        (-exponent).exp() * hg(cos_psi, g) * hg(s_dot_w, g) / (rho * ch)
    };
    simpson(f, s0, s1, 1_000_000)
}

fn unit(v: [f64; 3]) -> [f64; 3] {
    let n = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
    v.map(|c| c / n)
}

fn rel(a: f64, b: f64) -> f64 {
    (a - b).abs() / b.abs()
}

#[test]
fn gauss_legendre_rules_integrate_polynomials_exactly() {
    for n in [PSI_NODES, PHI_NODES] {
        let rule = gauss_legendre(n);
        for k in 0..2 * n {
            let exact = if k % 2 == 1 { 0.0 } else { 2.0 / (k as f64 + 1.0) };
            let got: f64 = rule.iter().map(|&(x, w)| w * x.powi(k as i32)).sum();
            assert!((got - exact).abs() < 1e-14, "n = {n}, x^{k}: {got} vs {exact}");
        }
    }
}

/// `e2` against a brute-force Simpson rule on a different substitution, at sharp (`g = 0.9, 0.95`),
/// backward (`g = −0.5`), near-axis (`ρ = 1e-4`), far (`ρ = 20`) and off-plane probes.
#[test]
fn e2_matches_brute_force_simpson() {
    let cases: [([f64; 3], [f64; 3], f64); 7] = [
        ([1.0, 0.0, 1.0], unit([0.3, 0.4, 0.8]), 0.9),
        ([1e-4, 0.0, 1.0], [0.6, 0.0, 0.8], 0.95),
        ([2.0, 0.0, 0.5], [0.0, 0.0, 1.0], 0.95),
        ([0.3, 0.0, -2.0], unit([-0.48, 0.6, 0.64]), -0.5),
        ([20.0, 0.0, 3.0], unit([1.0, 0.1, 0.2]), 0.9),
        ([0.6, 0.8, 1.5], unit([-0.2, 0.9, -0.1]), 0.7),
        ([0.05, -0.02, 4.0], unit([0.01, 0.0, 1.0]), 0.95),
    ];
    let mut worst = 0.0f64;
    for (p, w, g) in cases {
        let got = e2(p, w, g).unwrap();
        let want = e2_simpson(p, w, g);
        let r = rel(got, want);
        println!("P = {p:?}, g = {g}: e2 = {got:.12e}, Simpson = {want:.12e}, rel {r:.2e}");
        worst = worst.max(r);
        assert!(r < 1e-6, "P = {p:?}, ω = {w:?}, g = {g}: {got} vs {want}");
    }
    println!("worst relative difference {worst:.2e}");
}

/// A wider matrix against the same Simpson rule: probes drawn at random with `ρ ∈ [1e-4, 2e1]`
/// (log-uniform), `z ∈ [−5, 10]`, any azimuth and direction, `|g| ≤ 0.99`.
#[test]
fn e2_matches_brute_force_simpson_on_a_random_matrix() {
    let k = StreamKey { table: 5, cell: 5 };
    let mut worst = 0.0f64;
    for i in 0..24u64 {
        let u = |d: u32| k.uniform(i, d);
        let rho = 10f64.powf(-4.0 + 5.3 * u(0));
        let azimuth = TAU * u(2);
        let p = [rho * azimuth.cos(), rho * azimuth.sin(), -5.0 + 15.0 * u(1)];
        let w = unit([u(3) - 0.5, u(4) - 0.5, u(5) - 0.5]);
        let g = 0.99 * (2.0 * u(6) - 1.0);
        let (got, want) = (e2(p, w, g).unwrap(), e2_simpson(p, w, g));
        let r = rel(got, want);
        worst = worst.max(r);
        assert!(r < 1e-6, "P = {p:?}, ω = {w:?}, g = {g}: {got} vs {want}");
    }
    println!("random matrix: worst relative difference {worst:.2e}");
}

/// Conservation: every photon of the non-absorbing medium scatters a second time exactly once, so
/// the collision density of second events integrates to 1 over space. `∫ E_2 dω` is the `ψ`
/// quadrature with the last phase integrated out ([`e2_angle_integrated`]); the outer integral
/// `2π ∫ ρ dρ ∫ dz` uses 8-point Gauss–Legendre panels graded geometrically (ratio 4) toward
/// `ρ = 0` and `z = 0` from `1e-6`, then widening to `|P| = 50` (`ρ ∫ dz` stays finite on the
/// axis: the line singularity is `~1/ρ`).
#[test]
fn second_events_integrate_to_one() {
    let rule = gauss_legendre(8);
    let nodes = |breaks: &[f64]| -> Vec<(f64, f64)> {
        breaks
            .windows(2)
            .flat_map(|ab| {
                let (mid, half) = (0.5 * (ab[0] + ab[1]), 0.5 * (ab[1] - ab[0]));
                rule.iter().map(move |&(x, w)| (mid + half * x, half * w))
            })
            .collect()
    };
    let mut graded: Vec<f64> = (0..10).map(|k| 1e-6 * 4f64.powi(k)).collect();
    graded.extend([0.5, 1.0, 1.5, 2.0, 3.0, 4.0, 5.5, 7.0, 9.0, 11.0, 14.0, 17.0, 21.0, 26.0, 32.0, 40.0, 50.0]);
    let mut rho_breaks = vec![0.0];
    rho_breaks.extend(&graded);
    let mut z_breaks: Vec<f64> = graded.iter().rev().map(|x| -x).collect();
    z_breaks.push(0.0);
    z_breaks.extend(&graded);
    let (rho_nodes, z_nodes) = (nodes(&rho_breaks), nodes(&z_breaks));
    for g in [0.0, 0.7, -0.5] {
        let total: f64 = rho_nodes
            .par_iter()
            .map(|&(rho, wr)| {
                let col: f64 = z_nodes.iter().map(|&(z, wz)| wz * e2_angle_integrated(rho, z, g).unwrap()).sum();
                wr * rho * col
            })
            .collect::<Vec<f64>>()
            .iter()
            .sum::<f64>()
            * TAU;
        println!("g = {g}: ∫∫ E_2 dω dV = {total:.10} (deviation {:.1e})", total - 1.0);
        assert!((total - 1.0).abs() < 1e-4, "g = {g}: {total}");
    }
}

/// Ties [`e2`] (with its last phase) to the conservation test: its integral over all directions
/// (64 Gauss–Legendre cosines about `ẑ` × 128 periodic-trapezoid azimuths) equals the angle-integrated form.
#[test]
fn e2_integrates_over_directions_to_the_angle_integrated_form() {
    let rule = gauss_legendre(64);
    for (p, g) in [([0.7, 0.0, 1.2], 0.7), ([0.4, 0.3, -0.5], -0.4)] {
        let mut sum = 0.0;
        for &(mu, w) in &rule {
            let s = ((1.0 - mu) * (1.0 + mu)).sqrt();
            for j in 0..128 {
                let phi = TAU * j as f64 / 128.0;
                sum += w * (TAU / 128.0) * e2(p, [s * phi.cos(), s * phi.sin(), mu], g).unwrap();
            }
        }
        let want = e2_angle_integrated(p[0].hypot(p[1]), p[2], g).unwrap();
        println!("P = {p:?}, g = {g}: ∫ e2 dω = {sum:.12e}, angle-integrated {want:.12e}, rel {:.1e}", rel(sum, want));
        assert!(rel(sum, want) < 1e-7);
    }
}

/// At `g = 0` the last phase is `1/4π`: `E_2` does not depend on `ω`, and neither does the lobe.
#[test]
fn isotropic_scattering_makes_e2_direction_independent() {
    let p = [0.8, 0.0, 0.6];
    let a = e2(p, [0.0, 0.0, 1.0], 0.0).unwrap();
    let b = e2(p, unit([-0.3, 0.9, -0.2]), 0.0).unwrap();
    assert!(rel(a, b) < 1e-12, "{a} vs {b}");
    for theta in [0.0, 1.1, PI] {
        let d = double_symmetric(0.8, 0.6, theta, 0.0).unwrap();
        assert!(rel(d, a) < 1e-12, "theta = {theta}: {d} vs {a}");
    }
}

/// The adaptive `φ` quadrature against the periodic trapezoid rule over the full circle (spectrally
/// accurate for the smooth periodic integrand), at sharp forward and backward lobes.
#[test]
fn double_symmetric_matches_periodic_trapezoid() {
    for (rho, z, theta, g) in [(1.0, 1.5, 0.8, 0.9), (0.3, -0.4, 2.5, -0.9), (2.0, 0.2, 1.6, 0.95)] {
        let lobe = Lobe::new(rho, z, theta);
        let n = 2048;
        let trap = (0..n)
            .map(|j| e2([rho, 0.0, z], lobe.direction(TAU * j as f64 / n as f64).to_array(), g).unwrap())
            .sum::<f64>()
            / n as f64;
        let got = double_symmetric(rho, z, theta, g).unwrap();
        println!(
            "ρ = {rho}, z = {z}, θ = {theta}, g = {g}: {got:.12e} vs trapezoid {trap:.12e}, rel {:.1e}",
            rel(got, trap)
        );
        assert!(rel(got, trap) < 1e-7);
    }
}

/// With `K = 2` the walk scores `α² E_2(P, ω)` at the sampled lobe azimuths only: at `g = 0` every
/// score is the same number, so the mean is `α²` times the lobe exactly; at `θ = 0` every `ω` is
/// `â`; at `g = 0.7` it agrees with the quadrature within its standard error.
#[test]
fn walk_of_order_two_is_the_double_term() {
    let cfg = AdjointConfig { samples: 1000, max_order: 2, seed: 3 };
    let (rho, z, alpha) = (0.7, 0.9, 0.8);
    let est = total_symmetric(rho, z, 1.2, 0.0, alpha, &cfg).unwrap();
    let want = alpha * alpha * double_symmetric(rho, z, 1.2, 0.0).unwrap();
    assert!(rel(est.mean, want) < 1e-12, "{} vs {want}", est.mean);
    let axis = unit([rho, 0.0, z]);
    let est = total_symmetric(rho, z, 0.0, 0.7, alpha, &cfg).unwrap();
    let want = alpha * alpha * e2([rho, 0.0, z], axis, 0.7).unwrap();
    assert!(rel(est.mean, want) < 1e-12, "θ = 0: {} vs {want}", est.mean);
    let cfg = AdjointConfig { samples: 4000, ..cfg };
    let est = total_symmetric(rho, z, 1.2, 0.7, alpha, &cfg).unwrap();
    let want = alpha * alpha * double_symmetric(rho, z, 1.2, 0.7).unwrap();
    let sigmas = (est.mean - want) / est.std_error;
    println!("g = 0.7: walk {:.6e} ± {:.1e}, quadrature {want:.6e} ({sigmas:.2} σ)", est.mean, est.std_error);
    assert!(sigmas.abs() < 4.0 && est.std_error < 0.05 * want);
}

/// `E_3(P) = (4π)^{−3} ∫_0^∞ dz_b e^{−z_b} K(|P − b|)` at `g = 0` (every phase `1/4π`), with the
/// self-convolution of the flight kernel `K(d) = ∫ dV e^{−r₁}e^{−r₂}/(r₁² r₂²)` in bipolar
/// coordinates (`dV = 2π r₁ r₂ dr₁ dr₂/d`, then `s = r₁ + r₂`, `t = r₁ − r₂`):
/// `K(d) = (4π/d) ∫_d^∞ e^{−s} ln((s + d)/(s − d)) ds/s`. Simpson rules on `s = d + eᵛ` and on
/// `z_b = z + ρ sinh u` (where `d = ρ cosh u`).
fn e3_isotropic(rho: f64, z: f64) -> f64 {
    let kernel = |d: f64| {
        let f = |v: f64| {
            let x = v.exp();
            (-(d + x)).exp() * ((2.0 * d + x) / x).ln() / (d + x) * x
        };
        4.0 * PI / d * simpson(f, (1e-14f64).ln(), 60f64.ln(), 4000)
    };
    let f = |u: f64| {
        let d = rho * u.cosh();
        (-(z + rho * u.sinh())).exp() * kernel(d) * d
    };
    let u0 = (-z / rho).asinh();
    let u1 = ((60.0 + z.abs()) / rho).asinh();
    simpson(f, u0, u1, 1200) / (4.0 * PI).powi(3)
}

/// The walk's third-order scores against the independent `E_3` quadrature: `E_3` alone is the
/// difference of the `K = 3` and `K = 2` runs at `α = 1` on the same paths; 16 seeds give its spread.
#[test]
fn walk_third_order_matches_independent_quadrature() {
    for (rho, z) in [(0.5, 1.0), (1.5, -0.5)] {
        let want = e3_isotropic(rho, z);
        let seeds = 16;
        let parts: Vec<f64> = (0..seeds)
            .map(|seed| {
                let cfg = AdjointConfig { samples: 6000, max_order: 3, seed };
                let three = total_symmetric(rho, z, 0.9, 0.0, 1.0, &cfg).unwrap().mean;
                let two = total_symmetric(rho, z, 0.9, 0.0, 1.0, &AdjointConfig { max_order: 2, ..cfg }).unwrap().mean;
                three - two
            })
            .collect();
        let mean = parts.iter().sum::<f64>() / seeds as f64;
        let var = parts.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (seeds as f64 - 1.0);
        let err = (var / seeds as f64).sqrt();
        println!(
            "ρ = {rho}, z = {z}: E_3 walk {mean:.6e} ± {err:.1e}, quadrature {want:.6e} ({:.2} σ)",
            (mean - want) / err
        );
        assert!((mean - want).abs() < 4.0 * err && err < 0.03 * want);
    }
}

/// On fixed paths the walk's estimate is a polynomial in the albedo, `T(α) = Σ_k α^k Ê_k`: with
/// `K = 3`, `T/α² − Ê_2 = α Ê_3` (ratio exactly 2 between `α = 0.1` and `0.05`); with `K = 4`,
/// `(T/α² − Ê_2)/α = Ê_3 + α Ê_4` is linear; with `K = 200` the ratio is
/// `2 (1 + 0.1 q)/(1 + 0.05 q)`, `q = Ê_4/Ê_3`, up to `O(α²)`.
#[test]
fn walk_scales_with_the_albedo_order_by_order() {
    let (rho, z, theta, g) = (0.6, 0.8, 0.7, 0.6);
    let cfg = |max_order| AdjointConfig { samples: 400, max_order, seed: 11 };
    let t = |alpha: f64, k: usize| total_symmetric(rho, z, theta, g, alpha, &cfg(k)).unwrap().mean;
    let e2_hat = t(1.0, 2);
    let d = |alpha: f64, k: usize| t(alpha, k) / (alpha * alpha) - e2_hat;
    let r3 = d(0.1, 3) / d(0.05, 3);
    assert!((r3 - 2.0).abs() < 1e-10, "K = 3: ratio {r3}");
    let lin = |alpha: f64| d(alpha, 4) / alpha;
    let (l1, l2, l3) = (lin(0.1), lin(0.05), lin(0.025));
    let r4 = (l1 - l2) / (l2 - l3);
    assert!((r4 - 2.0).abs() < 1e-6, "K = 4: second difference ratio {r4}");
    let e4_hat = (l1 - l2) / 0.05;
    let e3_hat = l2 - 0.05 * e4_hat;
    let q = e4_hat / e3_hat;
    let r = d(0.1, 200) / d(0.05, 200);
    let expected = 2.0 * (1.0 + 0.1 * q) / (1.0 + 0.05 * q);
    println!("Ê_3 = {e3_hat:.4e}, Ê_4 = {e4_hat:.4e}; K = 200 ratio {r:.6} vs {expected:.6} to first order");
    assert!(e3_hat > 0.0 && e4_hat > 0.0);
    assert!((r - expected).abs() < 0.01 * q.max(1.0).powi(2), "ratio {r} vs {expected}");
}

#[test]
fn walk_is_bit_identical_for_any_thread_count() {
    let cfg = AdjointConfig { samples: 600, max_order: 40, seed: 17 };
    let run = |threads| {
        let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
        pool.install(|| total_symmetric(1.3, 0.4, 0.5, 0.8, 0.9, &cfg).unwrap())
    };
    let (one, two) = (run(1), run(2));
    assert_eq!(one.mean.to_bits(), two.mean.to_bits());
    assert_eq!(one.std_error.to_bits(), two.std_error.to_bits());
}

#[test]
fn turn_keeps_unit_length_and_the_scattering_cosine() {
    for d in [[0.0, 0.0, 1.0], [0.0, 0.0, -1.0], unit([1e-9, 0.0, -1.0]), unit([0.3, -0.5, 0.8]), [1.0, 0.0, 0.0]] {
        let d = DVec3::from_array(d);
        for (mu, az) in [(0.3, 0.0), (-0.99, 2.0), (1.0, 1.0), (-1.0, 4.0), (0.0, 5.5)] {
            let v = turn(d, mu, az);
            let w = turn(d, mu, az + 0.5 * PI);
            assert!((v.length() - 1.0).abs() < 1e-15);
            assert!((v.dot(d) - mu).abs() < 1e-14, "d = {d:?}, mu = {mu}");
            let perp = |x: DVec3| x - mu * d;
            assert!(perp(v).dot(perp(w)).abs() < 1e-14);
        }
    }
}

#[test]
fn extreme_inputs_give_errors_or_finite_values() {
    let cfg = AdjointConfig { samples: 64, max_order: 20, seed: 1 };
    assert!(e2([0.0, 0.0, 1.0], [0.0, 0.0, 1.0], 0.5).is_err());
    assert!(double_symmetric(0.0, 1.0, 0.3, 0.5).is_err());
    assert!(total_symmetric(0.0, 1.0, 0.3, 0.5, 0.9, &cfg).is_err());
    assert!(total_symmetric(0.0, 0.0, 0.3, 0.5, 0.9, &cfg).is_err());
    let near = e2([AXIS_MIN, 0.0, 1.0], [0.0, 0.0, 1.0], 0.5).unwrap();
    assert!(near.is_finite() && near > 0.0);
    for v in [
        e2([200.0, 0.0, 0.0], [1.0, 0.0, 0.0], 0.5).unwrap(),
        e2([1.0, 0.0, 1e6], [0.0, 0.0, 1.0], 0.5).unwrap(),
        double_symmetric(200.0, -30.0, 1.0, 0.9).unwrap(),
        total_symmetric(200.0, 5.0, 1.0, 0.9, 1.0, &cfg).unwrap().mean,
    ] {
        assert!(v.is_finite() && v >= 0.0, "{v}");
    }
    for theta in [0.0, PI] {
        assert!(double_symmetric(0.5, 0.5, theta, 0.8).unwrap().is_finite());
        assert!(total_symmetric(0.5, 0.5, theta, 0.8, 0.9, &cfg).unwrap().mean.is_finite());
    }
    for g in [0.99, -0.99] {
        let v = e2([0.3, 0.0, 0.7], unit([0.2, 0.1, 0.9]), g).unwrap();
        assert!(v.is_finite() && v > 0.0);
        let d = double_symmetric(0.3, 0.7, 0.4, g).unwrap();
        assert!(d.is_finite() && d > 0.0);
        assert!(total_symmetric(0.3, 0.7, 0.4, g, 0.9, &cfg).unwrap().mean.is_finite());
    }
    let zero = total_symmetric(0.5, 0.5, 0.5, 0.5, 0.0, &cfg).unwrap();
    assert_eq!((zero.mean, zero.std_error), (0.0, 0.0));
    let one = total_symmetric(0.5, 0.5, 0.5, 0.5, 1.0, &cfg).unwrap();
    assert!(one.mean.is_finite() && one.mean > 0.0 && one.std_error.is_finite());
}

#[test]
fn invalid_parameters_are_rejected() {
    let cfg = AdjointConfig { samples: 8, max_order: 4, seed: 0 };
    let z = [0.0, 0.0, 1.0];
    assert!(e2([f64::NAN, 0.0, 1.0], z, 0.5).is_err());
    assert!(e2([1.0, 0.0, f64::INFINITY], z, 0.5).is_err());
    assert!(e2([1.0, 0.0, 1.0], [0.0, 0.0, 1.0 + 1e-8], 0.5).is_err());
    assert!(e2([1.0, 0.0, 1.0], [0.0, 0.0, 1.0 + 1e-10], 0.5).is_ok());
    for g in [1.0, -1.0, f64::NAN] {
        assert!(e2([1.0, 0.0, 1.0], z, g).is_err());
        assert!(double_symmetric(1.0, 1.0, 0.5, g).is_err());
        assert!(total_symmetric(1.0, 1.0, 0.5, g, 0.5, &cfg).is_err());
    }
    for theta in [-1e-9, PI + 1e-9, f64::NAN] {
        assert!(double_symmetric(1.0, 1.0, theta, 0.5).is_err());
        assert!(total_symmetric(1.0, 1.0, theta, 0.5, 0.5, &cfg).is_err());
    }
    for albedo in [-0.1, 1.1, f64::NAN] {
        assert!(total_symmetric(1.0, 1.0, 0.5, 0.5, albedo, &cfg).is_err());
    }
    assert!(total_symmetric(-1.0, 1.0, 0.5, 0.5, 0.5, &cfg).is_err());
    assert!(total_symmetric(f64::NAN, 1.0, 0.5, 0.5, 0.5, &cfg).is_err());
    assert!(total_symmetric(1.0, 1.0, 0.5, 0.5, 0.5, &AdjointConfig { samples: 1, ..cfg }).is_err());
    assert!(total_symmetric(1.0, 1.0, 0.5, 0.5, 0.5, &AdjointConfig { max_order: 1, ..cfg }).is_err());
    assert!(total_symmetric(1.0, 1.0, 0.5, 0.5, 0.5, &AdjointConfig { max_order: MAX_ORDER + 1, ..cfg }).is_err());
}
