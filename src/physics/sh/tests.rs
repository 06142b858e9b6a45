//! Tests of the SH/ZH module. Every check pins a value derived independently of the code under test: closed
//! forms, exact quadrature of polynomials on the sphere, the addition theorem, or the HG Legendre moments.

use super::*;
use crate::physics::hg;

/// SplitMix64: a tiny deterministic generator for test inputs.
struct Rng(u64);

impl Rng {
    fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }

    /// Uniform in `[a, b)`.
    fn range(&mut self, a: f64, b: f64) -> f64 {
        a + (b - a) * (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64
    }

    /// Uniform unit direction.
    fn dir(&mut self) -> [f64; 3] {
        let z = self.range(-1.0, 1.0);
        let phi = self.range(0.0, TAU);
        let s = (1.0 - z * z).sqrt();
        [s * phi.cos(), s * phi.sin(), z]
    }

    fn vec(&mut self, n: usize) -> Vec<f64> {
        (0..n).map(|_| self.range(-1.0, 1.0)).collect()
    }
}

/// Product rule on the sphere: Gauss–Legendre in `cos θ` × uniform `φ`. Exact for polynomials in `(x, y, z)`
/// of degree `≤ min(2 n_mu − 1, n_phi − 1)`.
fn sphere_rule(n_mu: usize, n_phi: usize) -> Vec<([f64; 3], f64)> {
    let mut rule = Vec::new();
    for (mu, w) in gauss_legendre(n_mu) {
        let s = (1.0 - mu * mu).sqrt();
        for j in 0..n_phi {
            let phi = TAU * (j as f64 + 0.5) / n_phi as f64;
            rule.push(([s * phi.cos(), s * phi.sin(), mu], w * TAU / n_phi as f64));
        }
    }
    rule
}

fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

fn scaled(v: [f64; 3], s: f64) -> [f64; 3] {
    v.map(|c| c * s)
}

#[track_caller]
fn assert_close(got: f64, want: f64, tol: f64, what: &str) {
    assert!((got - want).abs() <= tol, "{what}: got {got:e}, want {want:e}, diff {:e} > {tol:e}", got - want);
}

/// A spread of axes: poles, equator, grazing (almost horizontal), almost polar, general.
const AXES: [[f64; 3]; 8] = [
    [0.0, 0.0, 1.0],
    [0.0, 0.0, -1.0],
    [1.0, 0.0, 0.0],
    [-1.0, 0.0, 0.0],
    [0.6, -0.8, 1e-9],
    [1e-8, 2e-8, -1.0],
    [0.3, -0.5, 0.8],
    [-2.0, 7.0, 0.5],
];

#[test]
fn gauss_legendre_matches_known_rules_and_integrates_monomials() {
    let r2 = gauss_legendre(2);
    assert_close(r2[0].0, 1.0 / 3f64.sqrt(), 2.3e-16, "n=2 node");
    assert_close(r2[1].0, -1.0 / 3f64.sqrt(), 2.3e-16, "n=2 node");
    assert_close(r2[0].1, 1.0, 1e-15, "n=2 weight");
    let r3 = gauss_legendre(3);
    assert_eq!(r3[1].0, 0.0);
    assert_close(r3[0].0, 0.6f64.sqrt(), 2.3e-16, "n=3 node");
    assert_close(r3[1].1, 8.0 / 9.0, 1e-15, "n=3 middle weight");
    assert_close(r3[2].1, 5.0 / 9.0, 1e-15, "n=3 outer weight");
    assert!(gauss_legendre(0).is_empty());
    for n in [1, 2, 5, 16, 64, 1000, MAX_NODES] {
        let rule = gauss_legendre(n);
        assert_eq!(rule.len(), n);
        assert!(rule.windows(2).all(|p| p[0].0 > p[1].0) && rule[0].0 < 1.0 && rule[n - 1].0 > -1.0);
        for k in 0..(2 * n).min(41) {
            let got: f64 = rule.iter().map(|&(x, w)| w * x.powi(k as i32)).sum();
            let want = if k % 2 == 0 { 2.0 / (k as f64 + 1.0) } else { 0.0 };
            assert_close(got, want, 2e-14, &format!("∫x^{k}, n = {n}"));
        }
    }
}

#[test]
fn legendre_sequence_matches_closed_forms_and_hg() {
    for i in 0..=200 {
        let x = -1.0 + f64::from(i) * 0.01;
        let p: Vec<f64> = Legendre::new(x).take(5).collect();
        let x2 = x * x;
        let want =
            [1.0, x, 0.5 * (3.0 * x2 - 1.0), 0.5 * x * (5.0 * x2 - 3.0), (35.0 * x2 * x2 - 30.0 * x2 + 3.0) / 8.0];
        (0..5).for_each(|l| assert_close(p[l], want[l], 1e-15, &format!("P_{l}({x})")));
        for (l, p) in Legendre::new(x).take(MAX_ORDER).enumerate().step_by(7) {
            assert_close(p, hg::legendre_p(l as u32, x), 2e-15, &format!("P_{l}({x}) vs hg"));
        }
    }
    // The gap form at x = ±(1 − t) with a tiny t: P_l ≈ 1 − l(l+1) t/2 (to O(t²)).
    let t = 1e-12;
    for (l, p) in Legendre::with_gap(t, true).take(64).enumerate() {
        let sign = if l % 2 == 1 { -1.0 } else { 1.0 };
        assert_close(p, sign * (1.0 - (l * (l + 1)) as f64 * t / 2.0), 1e-19 * (l * l * l * l) as f64 + 2.3e-16, "gap");
    }
}

#[test]
fn basis_is_orthonormal_up_to_order_12() {
    let order = 12;
    let count = sh_count(order);
    // Products have degree ≤ 22: 24 nodes in cos θ (exact to degree 47) × 48 azimuths.
    let mut gram = vec![0.0; count * count];
    let mut y = vec![0.0; count];
    for (w_dir, w) in sphere_rule(24, 48) {
        sh_eval_into(order, w_dir, &mut y);
        for i in 0..count {
            for j in 0..count {
                gram[i * count + j] += w * y[i] * y[j];
            }
        }
    }
    let worst = (0..count * count)
        .map(|k| (gram[k] - if k / count == k % count { 1.0 } else { 0.0 }).abs())
        .fold(0.0, f64::max);
    eprintln!("orthonormality order 12: worst |<y_i,y_j> - δ_ij| = {worst:e}");
    assert!(worst < 1e-12, "{worst:e}");
}

#[test]
fn low_bands_match_closed_forms_with_condon_shortley_phase() {
    let c1 = (3.0 / FOUR_PI).sqrt();
    let c2 = (15.0 / FOUR_PI).sqrt();
    for d in [[0.0, 0.0, 1.0], [1.0, 2.0, -3.0], [-0.5, 0.1, 0.2], [0.0, -1.0, 0.0], [3e-5, 1e-7, -2.0]] {
        let y = sh_eval(3, d);
        let [x, yy, z] = unit_or_z(d);
        let want = [
            1.0 / (2.0 * PI.sqrt()),
            -c1 * yy,
            c1 * z,
            -c1 * x,
            c2 * x * yy,
            -c2 * yy * z,
            (5.0 / (16.0 * PI)).sqrt() * (3.0 * z * z - 1.0),
            -c2 * x * z,
            0.5 * c2 * (x * x - yy * yy),
        ];
        for (i, (&g, &w)) in y.iter().zip(&want).enumerate() {
            assert_close(g, w, 4.5e-16, &format!("y_{i}({d:?})"));
        }
    }
    // The sign convention itself: y_1^1 is negative towards +x, y_1^{-1} negative towards +y.
    assert!(sh_eval(2, [1.0, 0.0, 0.0])[3] < 0.0 && sh_eval(2, [0.0, 1.0, 0.0])[1] < 0.0);
}

#[test]
fn optimal_linear_direction_points_at_the_lobe() {
    // Project exp(3 ω·a) onto SH by quadrature (independent of zh_rotate); its first moment is along +a.
    let rule = sphere_rule(40, 80);
    for a in AXES {
        let a = unit_or_z(a);
        let mut sh = [0.0; 4];
        for &(w_dir, w) in &rule {
            let f = (3.0 * dot(w_dir, a)).exp();
            for (c, y) in sh.iter_mut().zip(sh_eval(2, w_dir)) {
                *c += w * f * y;
            }
        }
        let l = optimal_linear_direction(&sh).expect("non-zero band 1");
        for k in 0..3 {
            assert_close(l[k], a[k], 1e-13, &format!("l_opt of exp lobe about {a:?}"));
        }
        // A lobe with f_1 < 0 has its energy on the other side.
        let l = optimal_linear_direction(&zh_rotate(&[1.0, -0.5, 0.2], a)).expect("non-zero band 1");
        (0..3).for_each(|k| assert_close(l[k], -a[k], 1e-15, "l_opt of back lobe"));
    }
    assert_eq!(optimal_linear_direction(&[1.0, 0.0, 0.0]), None);
    assert_eq!(optimal_linear_direction(&[1.0, 0.0, 0.0, 0.0, 5.0]), None);
    assert_eq!(optimal_linear_direction(&[1.0, f64::NAN, 0.0, 1.0]), None);
    let tiny = optimal_linear_direction(&[0.0, 0.0, 0.0, -1e-310]).expect("subnormal band 1");
    assert_eq!(tiny, [1.0, 0.0, 0.0]);
}

#[test]
fn zh_rotate_reconstructs_the_rotated_lobe() {
    let mut rng = Rng(1);
    for order in [1, 2, 5, 16, 32] {
        let f = rng.vec(order);
        let scale: f64 = f.iter().enumerate().map(|(l, c)| c.abs() * zh_norm(l)).sum();
        for axis in AXES {
            let h = zh_rotate(&f, axis);
            assert_eq!(h.len(), order * order);
            for _ in 0..20 {
                let w = rng.dir();
                let got = sh_dot(&h, &sh_eval(order, w));
                let want = zh_eval(&f, dot(w, unit_or_z(axis)));
                assert_close(got, want, 1e-13 * scale, &format!("order {order}, axis {axis:?}"));
            }
        }
    }
    // Against the projection by (exact) quadrature of the rotated function: degree ≤ 14.
    let order = 8;
    let f = rng.vec(order);
    let rule = sphere_rule(16, 32);
    for axis in AXES {
        let mut proj = vec![0.0; order * order];
        for &(w_dir, w) in &rule {
            let g = zh_eval(&f, dot(w_dir, unit_or_z(axis)));
            proj.iter_mut().zip(sh_eval(order, w_dir)).for_each(|(c, y)| *c += w * g * y);
        }
        let h = zh_rotate(&f, axis);
        (0..order * order).for_each(|i| assert_close(h[i], proj[i], 1e-14, &format!("h_{i}, axis {axis:?}")));
    }
}

#[test]
fn zh_project_about_round_trips_and_obeys_funk_hecke() {
    let mut rng = Rng(2);
    let rule = sphere_rule(16, 32);
    for order in [1, 3, 8, 16] {
        let f = rng.vec(order);
        for a in AXES {
            let back = zh_project_about(&zh_rotate(&f, a), a);
            (0..order).for_each(|l| assert_close(back[l], f[l], 1e-14, &format!("round trip l={l}, {a:?}")));
            // About another axis b: c_l = ∫ f(ω·a) y_l^0(ω·b) dω = f_l P_l(a·b) (Funk–Hecke).
            let b = rng.dir();
            let c = zh_project_about(&zh_rotate(&f, a), b);
            let cos_ab = dot(unit_or_z(a), b);
            for l in 0..order {
                assert_close(c[l], f[l] * hg::legendre_p(l as u32, cos_ab), 1e-14, "Funk-Hecke");
            }
            if order == 8 {
                let mut quad = vec![0.0; order];
                for &(w_dir, w) in &rule {
                    let g = zh_eval(&f, dot(w_dir, unit_or_z(a)));
                    let yb = zh_basis(order, dot(w_dir, b));
                    quad.iter_mut().zip(yb).for_each(|(q, y)| *q += w * g * y);
                }
                (0..order).for_each(|l| assert_close(c[l], quad[l], 1e-14, "projection vs quadrature"));
            }
        }
    }
    // A general (non-zonal) SH function, and a trailing partial band that is ignored.
    let mut sh = rng.vec(36 + 5);
    let axis = [0.2, -0.9, 0.4];
    let c = zh_project_about(&sh, axis);
    sh.truncate(36);
    assert_eq!(c.len(), 6);
    for (l, &cl) in c.iter().enumerate() {
        let quad: f64 = rule
            .iter()
            .map(|&(w_dir, w)| w * sh_dot(&sh, &sh_eval(6, w_dir)) * zh_basis(6, dot(w_dir, unit_or_z(axis)))[l])
            .sum();
        assert_close(cl, quad, 1e-14, "general function");
    }
}

#[test]
fn clamped_cosine_matches_closed_forms_and_quadrature() {
    let a = clamped_cosine_zh(MAX_ORDER + 10);
    assert_eq!(a.len(), MAX_ORDER);
    assert_close(a[0], PI.sqrt() / 2.0, 2.3e-16 * a[0], "A_0");
    assert_close(a[1], (PI / 3.0).sqrt(), 2.3e-16 * a[1], "A_1");
    assert_close(a[2], (5.0 * PI).sqrt() / 8.0, 2.3e-16 * a[2], "A_2");
    assert_close(a[4], -PI.sqrt() / 16.0, 4.5e-16 * a[2], "A_4");
    assert!(a.iter().skip(3).step_by(2).all(|&v| v == 0.0), "odd l ≥ 3 vanish");
    assert!(a.iter().all(|v| v.is_finite()));
    // 2π ∫_0^1 μ y_l^0(μ) dμ with 32 Gauss nodes mapped to [0, 1] (exact to degree 63).
    let rule = gauss_legendre(32);
    let mut worst: f64 = 0.0;
    for (l, &al) in a.iter().enumerate().take(32) {
        let quad: f64 = rule
            .iter()
            .map(|&(x, w)| {
                let mu = 0.5 * (x + 1.0);
                TAU * 0.5 * w * mu * zh_norm(l) * hg::legendre_p(l as u32, mu)
            })
            .sum();
        worst = worst.max((al - quad).abs());
        assert_close(al, quad, 3e-15, &format!("A_{l} vs quadrature"));
    }
    eprintln!("clamped cosine l ≤ 31: worst |A_l - quadrature| = {worst:e}");
    // RH01's factorial form Â_l = 2π (−1)^{l/2−1} l! / ((l+2)(l−1) 2^l ((l/2)!)²), A_l = Â_l sqrt((2l+1)/(4π)).
    let fact = |n: usize| (1..=n).map(|k| k as f64).product::<f64>();
    for l in (2..=30).step_by(2) {
        let sign = if (l / 2) % 2 == 0 { -1.0 } else { 1.0 };
        let hat = TAU * sign * fact(l) / ((l + 2) as f64 * (l - 1) as f64 * 2f64.powi(l as i32) * fact(l / 2).powi(2));
        assert_close(a[l], hat * zh_norm(l), 1e-14 * a[l].abs(), &format!("A_{l} vs RH01"));
    }
}

#[test]
fn zh_double_product_matches_quadrature_and_the_full_sh_route() {
    let mut rng = Rng(3);
    // Integrand degree ≤ 30: 18 nodes in cos θ × 36 azimuths is exact.
    let rule = sphere_rule(18, 36);
    let mut worst: f64 = 0.0;
    for order in 1..=16 {
        let (a, b) = (rng.vec(order), rng.vec(order + 3));
        let r = rng.dir();
        let ortho = unit_or_z([r[1], -r[0], 0.0]);
        let pairs = [(r, r), (r, scaled(r, -1.0)), (r, ortho), (rng.dir(), rng.dir()), (AXES[0], AXES[1])];
        for (axis_a, axis_b) in pairs {
            let got = zh_double_product(&a, axis_a, &b, axis_b);
            let bt = &b[..order];
            let quad: f64 = rule
                .iter()
                .map(|&(w_dir, w)| w * zh_eval(&a, dot(w_dir, axis_a)) * zh_eval(bt, dot(w_dir, axis_b)))
                .sum();
            let scale: f64 = a.iter().zip(&b).map(|(x, y)| (x * y).abs()).sum();
            worst = worst.max((got - quad).abs() / scale);
            assert_close(got, quad, 1e-10 * scale, &format!("order {order} vs quadrature"));
            let full = sh_dot(&zh_rotate(&a, axis_a), &zh_rotate(&b, axis_b));
            assert_close(got, full, 1e-13 * scale, &format!("order {order} vs full SH"));
        }
    }
    eprintln!("zh_double_product orders 1..=16: worst |got - quadrature| / Σ|a_l b_l| = {worst:e}");
}

#[test]
fn zh_irradiance_known_values() {
    let normals = [[0.0, 0.0, 1.0], [0.0, 0.0, -1.0], [1.0, 2.0, 3.0], [0.6, -0.8, 1e-12]];
    // Uniform radiance 1: f_0 = 2√π, E = π for every normal, also with zero-padded higher bands.
    for n in normals {
        let mut iso = vec![0.0; 11];
        iso[0] = 2.0 * PI.sqrt();
        assert_close(zh_irradiance(&iso[..1], [0.3, 0.1, 0.2], n), PI, 4.5e-16, "isotropic, order 1");
        assert_close(zh_irradiance(&iso, [0.3, 0.1, 0.2], n), PI, 4.5e-16, "isotropic, order 11");
    }
    // L = 1 + ω·a: E = π ± 2π/3 aligned / opposite, π for a normal orthogonal to a.
    let lin = zh_project_fn(2, |mu| 1.0 + mu, 4);
    assert_close(lin[1], (4.0 * PI / 3.0).sqrt(), 1e-15, "linear lobe f_1");
    let a = unit_or_z([0.3, -0.5, 0.8]);
    let perp = unit_or_z([0.5, 0.3, 0.0]);
    assert_close(zh_irradiance(&lin, a, a), 5.0 * PI / 3.0, 2e-15, "linear, aligned");
    assert_close(zh_irradiance(&lin, a, scaled(a, -1.0)), PI / 3.0, 2e-15, "linear, opposite");
    assert_close(zh_irradiance(&lin, a, perp), PI, 2e-15, "linear, orthogonal");
    // L = (ω·a)², normal at angle γ from a: E = π/4 sin²γ + π/2 cos²γ (hemisphere moments of x², z²).
    let quad = zh_project_fn(11, |mu| mu * mu, 8);
    for gamma in [0.0, 0.4, PI / 2.0, 2.0, PI] {
        let n = [gamma.sin(), 0.0, gamma.cos()];
        let want = PI / 4.0 * gamma.sin().powi(2) + PI / 2.0 * gamma.cos().powi(2);
        assert_close(zh_irradiance(&quad, [0.0, 0.0, 1.0], n), want, 2e-15, &format!("quadratic, γ = {gamma}"));
    }
    // Directional light (delta lobe f_l = y_l^0(1)): E is the truncated clamped-cosine series at a·n, which
    // tends to max(0, a·n); at order 32 the truncation error is below 3e-3 away from the kink.
    let delta: Vec<f64> = (0..32).map(zh_norm).collect();
    let big_a = clamped_cosine_zh(32);
    for c in [0.9_f64, 0.5, -0.5, -1.0, 1.0] {
        let n = [(1.0 - c * c).sqrt(), 0.0, c];
        let e = zh_irradiance(&delta, [0.0, 0.0, 1.0], n);
        assert_close(e, zh_eval(&big_a, c), 1e-14, "delta vs series");
        assert_close(e, c.max(0.0), 3e-3, &format!("delta vs max(0, cos), cos = {c}"));
    }
    // Grazing normals: against quadrature of L(ω) · (truncated clamped cosine)(n·ω), degree ≤ 20.
    let mut rng = Rng(4);
    let f = rng.vec(11);
    let a11 = clamped_cosine_zh(11);
    let rule = sphere_rule(16, 32);
    let axis = unit_or_z([0.2, 0.1, 1.0]);
    for eps in [1e-3, -1e-7, 0.0] {
        let t = unit_or_z([1.0, 0.0, -0.2]);
        let n = unit_or_z([t[0] + eps * axis[0], t[1] + eps * axis[1], t[2] + eps * axis[2]]);
        let want: f64 =
            rule.iter().map(|&(w_dir, w)| w * zh_eval(&f, dot(w_dir, axis)) * zh_eval(&a11, dot(w_dir, n))).sum();
        assert_close(zh_irradiance(&f, axis, n), want, 1e-14, &format!("grazing, eps = {eps}"));
    }
}

#[test]
fn zh_project_fn_matches_hg_moments_and_polynomials() {
    for g in [0.5, -0.3, 0.0] {
        let got = zh_project_fn(12, |mu| hg::phase(mu, g), 200);
        (0..12).for_each(|l| assert_close(got[l], hg::zh_coefficient(l as u32, g), 1e-15, "HG moment"));
    }
    // μ³ = (2 P_3 + 3 P_1)/5: f_1 = 2π √(3/4π) · 2/5, f_3 = 2π √(7/4π) · 4/35; 4 nodes are exact (degree 6).
    let got = zh_project_fn(5, |mu| mu.powi(3), 4);
    let want = [0.0, TAU * zh_norm(1) * 0.4, 0.0, TAU * zh_norm(3) * 4.0 / 35.0, 0.0];
    (0..5).for_each(|l| assert_close(got[l], want[l], 1e-15, "μ³"));
    assert_eq!(zh_project_fn(3, |_| 1.0, 0), vec![0.0; 3]);
    assert!(zh_project_fn(0, |_| 1.0, 10).is_empty());
}

#[test]
fn addition_theorem_holds_at_orders_32_and_max() {
    // Reference P_l(±(1 − t)): near the poles, where rounding of the cosine would be amplified by l(l+1)/2, the
    // series P_l(1 − t) = Σ_k (−1)^k C(l,k) C(l+k,k) (t/2)^k with t from the cross product; else hg::legendre_p.
    let reference = |l: usize, a: [f64; 3], b: [f64; 3]| {
        let c = dot(a, b);
        let cr = [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]];
        let t = dot(cr, cr) / (1.0 + c.abs());
        if (l * l) as f64 * t >= 1.0 {
            return hg::legendre_p(l as u32, c);
        }
        let (mut term, mut sum) = (1.0, 1.0);
        for k in 0..l {
            term *= -(((l - k) * (l + k + 1)) as f64) / ((k + 1) * (k + 1)) as f64 * t / 2.0;
            sum += term;
        }
        if c < 0.0 && l % 2 == 1 { -sum } else { sum }
    };
    let dirs = [[1e-3, 0.0, 1.0], [0.0, 0.0, -1.0], [1.0, 1e-9, 0.0], [0.3, -0.5, 0.8], [-0.7, 0.2, -0.1]];
    for order in [32, MAX_ORDER] {
        let ys: Vec<Vec<f64>> = dirs.iter().map(|&d| sh_eval(order, d)).collect();
        let mut worst: f64 = 0.0;
        for (i, a) in dirs.iter().enumerate() {
            for (j, b) in dirs.iter().enumerate().skip(i) {
                for l in 0..order {
                    let band = l * l..(l + 1) * (l + 1);
                    let sum: f64 = ys[i][band.clone()].iter().zip(&ys[j][band]).map(|(p, q)| p * q).sum();
                    let norm = (2 * l + 1) as f64 / FOUR_PI;
                    let want = if i == j { norm } else { norm * reference(l, unit_or_z(*a), unit_or_z(*b)) };
                    worst = worst.max((sum - want).abs() / norm);
                }
            }
        }
        eprintln!("addition theorem order {order}: worst relative error {worst:e}");
        // At MAX_ORDER the m ≥ 1 columns near the pole inherit the ~ε rounding of cos θ times ~l² (module doc).
        assert!(worst < if order == 32 { 1e-14 } else { 3e-11 }, "order {order}: {worst:e}");
    }
}

#[test]
fn extreme_inputs_give_documented_finite_results() {
    let all_finite = |v: &[f64]| v.iter().all(|x| x.is_finite());
    // Order 0 and 1.
    assert!(sh_eval(0, [1.0, 0.0, 0.0]).is_empty() && zh_basis(0, 0.3).is_empty());
    assert!(zh_rotate(&[], [1.0, 0.0, 0.0]).is_empty() && zh_project_about(&[1.0, 2.0], [0.0; 3]).len() == 1);
    assert!(clamped_cosine_zh(0).is_empty());
    assert_eq!((zh_eval(&[], 0.5), zh_double_product(&[], [1.0; 3], &[1.0], [0.0; 3])), (0.0, 0.0));
    assert_eq!(zh_irradiance(&[], [1.0; 3], [1.0; 3]), 0.0);
    for d in [[0.0; 3], [f64::NAN, 0.0, 1.0], [5.0, -1.0, 2.0]] {
        assert_eq!(sh_eval(1, d), vec![Y00]);
    }
    // Poles: the m ≠ 0 functions vanish exactly, the zonal ones are y_l^0(±1); no NaN.
    for (pole, c) in [([0.0, 0.0, 3.0], 1.0), ([0.0, 0.0, -1e-200], -1.0)] {
        let y = sh_eval(32, pole);
        let zonal = zh_basis(32, c);
        for l in 0..32usize {
            for m in -(l as i64)..=(l as i64) {
                let v = y[(l * (l + 1)).wrapping_add_signed(m as isize)];
                let want = if m == 0 { zonal[l] } else { 0.0 };
                assert_close(v, want, 1e-14 * zonal[0].abs().max(1.0), "pole");
            }
        }
    }
    // Non-normalised axes give the results of the unit axis; zero / NaN vectors act as +z; infinities win.
    let mut rng = Rng(5);
    let f = rng.vec(11);
    for d in AXES {
        let y = sh_eval(32, d);
        for s in [1e-300, 1e300, 1e-310] {
            let ys = sh_eval(32, scaled(d, s));
            assert!(all_finite(&ys));
            let tol = if s < 1e-307 { 1e-3 } else { 1e-14 };
            (0..y.len()).for_each(|i| assert_close(ys[i], y[i], tol * y[0].max(1.0), "scaled direction"));
            let e = zh_irradiance(&f, scaled(d, s), [0.1, 0.2, 0.3]);
            assert_close(e, zh_irradiance(&f, d, [0.1, 0.2, 0.3]), tol, "scaled axis");
        }
    }
    let z = sh_eval(8, [0.0, 0.0, 1.0]);
    for d in [[0.0; 3], [f64::NAN; 3], [1.0, f64::NAN, 0.0]] {
        assert_eq!(sh_eval(8, d), z);
        assert_eq!(zh_irradiance(&f, d, [0.0, 0.0, 1.0]), zh_irradiance(&f, [0.0, 0.0, 1.0], [0.0, 0.0, 1.0]));
    }
    assert_eq!(sh_eval(8, [f64::INFINITY, 5.0, 0.0]), sh_eval(8, [1.0, 0.0, 0.0]));
    assert_eq!(sh_eval(8, [f64::INFINITY, 5.0, -f64::INFINITY]), sh_eval(8, [1.0, 0.0, -1.0]));
    // Normal antiparallel to the axis: E = Σ f_l A_l (−1)^l.
    let a11 = clamped_cosine_zh(11);
    let want: f64 = (0..11).map(|l| f[l] * a11[l] * if l % 2 == 0 { 1.0 } else { -1.0 }).sum();
    for d in AXES {
        assert_close(zh_irradiance(&f, d, scaled(d, -3.0)), want, 1e-14, "antiparallel normal");
    }
    // Cosines a rounding error outside [−1, 1] are clamped.
    assert_eq!(zh_basis(32, 1.0 + 1e-15), zh_basis(32, 1.0));
    assert_eq!(zh_eval(&f, -1.0 - 4e-16), zh_eval(&f, -1.0));
    let par = [0.1, 0.2, 0.3];
    let want: f64 = f.iter().map(|x| x * x).sum();
    assert_close(zh_double_product(&f, par, &f, scaled(par, 3.0)), want, 1e-14, "parallel axes");
    // Orders above MAX_ORDER are clamped; short buffers get the complete bands that fit, the rest zeroed.
    assert_eq!(sh_eval(MAX_ORDER + 3, [1.0, 2.0, 3.0]).len(), MAX_ORDER * MAX_ORDER);
    assert_eq!(zh_basis(usize::MAX, 0.2).len(), MAX_ORDER);
    let mut buf = [7.0; 10];
    sh_eval_into(4, [1.0, 2.0, 3.0], &mut buf);
    assert_eq!(buf[..9], sh_eval(3, [1.0, 2.0, 3.0])[..]);
    assert_eq!(buf[9], 0.0);
    assert_eq!(sh_count(usize::MAX), usize::MAX);
    // Every combination of extreme components gives finite results and a unit direction.
    let values = [0.0, 1e-320, -1e-300, f64::MIN_POSITIVE, 1.0, -3.5, 1e300, -f64::MAX, f64::MAX];
    let f = rng.vec(6);
    for &x in &values {
        for &y in &values {
            for &z in &values {
                let d = [x, y, z];
                let u = unit_or_z(d);
                assert_close(dot(u, u), 1.0, 4.5e-16, &format!("|unit({d:?})|"));
                assert!(all_finite(&sh_eval(6, d)) && all_finite(&zh_rotate(&f, d)), "{d:?}");
                assert!(all_finite(&zh_project_about(&sh_eval(6, d), d)), "{d:?}");
                let e = [zh_irradiance(&f, d, [z, x, y]), zh_double_product(&f, d, &f, [y, -z, x])];
                assert!(all_finite(&e), "{d:?}");
            }
        }
    }
    assert!(all_finite(&zh_rotate(&rng.vec(32), [0.0, 0.0, -1.0])));
}
