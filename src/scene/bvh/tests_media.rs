//! Media along rays and optical thickness against analytic values and quadrature.

use super::procedural::{icosphere, scene};
use super::*;
use crate::physics::rng::StreamKey;
use crate::scene::fixtures::cuboid;
use crate::scene::{Boundary, Density, Medium};

fn medium(name: &str, sigma_t: [f64; 3], density: Density, boundary: Boundary) -> Medium {
    Medium { name: name.into(), sigma_s: sigma_t, sigma_a: [0.0; 3], g: [0.0; 3], density, boundary }
}

/// The unit cube [0, 1]³ bounding medium 0 (σ_t = 1), inside a global medium 1 (σ_t = 0.1).
fn cube_scene() -> Scene {
    let mut cube = cuboid("cube", [0.0; 3], [1.0; 3]);
    cube.medium = Some(0);
    let mut sc = scene(vec![cube]);
    sc.media = vec![
        medium("inside", [1.0; 3], Density::Homogeneous, Boundary::Mesh(0)),
        medium("air", [0.1; 3], Density::Homogeneous, Boundary::Global),
    ];
    sc
}

/// (t0, t1, medium) triples, for compact comparisons.
fn segs(bvh: &SceneBvh, sc: &Scene, o: [f64; 3], d: [f64; 3], t_max: f64) -> Vec<(f64, f64, Option<usize>)> {
    bvh.media_segments(sc, &Ray::new(o, d), t_max).iter().map(|s| (s.t0, s.t1, s.medium)).collect()
}

fn assert_segments(got: &[(f64, f64, Option<usize>)], want: &[(f64, f64, Option<usize>)], tol: f64) {
    assert_eq!(got.len(), want.len(), "got {got:?}, want {want:?}");
    for (g, w) in got.iter().zip(want) {
        let close = |a: f64, b: f64| a == b || (a - b).abs() <= tol;
        assert!(close(g.0, w.0) && close(g.1, w.1) && g.2 == w.2, "got {got:?}, want {want:?}");
    }
}

const INF: f64 = f64::INFINITY;

#[test]
fn cube_from_outside_inside_and_through_edges_and_vertices() {
    let sc = cube_scene();
    let bvh = SceneBvh::build(&sc);
    let (cube, air) = (Some(0), Some(1));
    let s = |o, d, t| segs(&bvh, &sc, o, d, t);
    // Through the middle of two faces, then from inside, with a finite and an infinite t_max.
    assert_segments(
        &s([0.5, 0.5, -1.0], [0.0, 0.0, 1.0], INF),
        &[(0.0, 1.0, air), (1.0, 2.0, cube), (2.0, INF, air)],
        0.0,
    );
    assert_segments(&s([0.5, 0.5, -1.0], [0.0, 0.0, 2.0], 0.75), &[(0.0, 0.5, air), (0.5, 0.75, cube)], 0.0);
    assert_segments(&s([0.25, 0.5, 0.5], [1.0, 0.0, 0.0], 5.0), &[(0.0, 0.75, cube), (0.75, 5.0, air)], 0.0);
    assert_segments(&s([0.25, 0.5, 0.5], [-1.0, 0.0, 0.0], INF), &[(0.0, 0.25, cube), (0.25, INF, air)], 0.0);
    // Through the faces' diagonals (shared edges of the two triangles of a face): counted once.
    for x in [0.125, 0.5, 0.875] {
        assert_segments(
            &s([x, x, -1.0], [0.0, 0.0, 1.0], 3.0),
            &[(0.0, 1.0, air), (1.0, 2.0, cube), (2.0, 3.0, air)],
            0.0,
        );
        assert_segments(
            &s([x, 2.0, x], [0.0, -1.0, 0.0], 3.0),
            &[(0.0, 1.0, air), (1.0, 2.0, cube), (2.0, 3.0, air)],
            0.0,
        );
    }
    // Through an edge (x = y = 0) into the cube and out through the opposite edge.
    assert_segments(
        &s([-1.0, -1.0, 0.5], [1.0, 1.0, 0.0], INF),
        &[(0.0, 1.0, air), (1.0, 2.0, cube), (2.0, INF, air)],
        1e-6,
    );
    // Through a vertex (the origin corner) along the diagonal, out through the opposite vertex.
    assert_segments(
        &s([-1.0, -1.0, -1.0], [1.0, 1.0, 1.0], INF),
        &[(0.0, 1.0, air), (1.0, 2.0, cube), (2.0, INF, air)],
        1e-6,
    );
    // Grazing an edge and a vertex from outside: the ray only touches the cube.
    assert_segments(&s([-1.0, 1.0, 0.5], [1.0, -1.0, 0.0], 3.0), &[(0.0, 3.0, air)], 0.0);
    assert_segments(&s([-1.0, 1.0, -1.0], [1.0, -1.0, 1.0], 3.0), &[(0.0, 3.0, air)], 0.0);
    // Grazing along faces: the rule moves an axis-aligned ray towards +kx, then +ky of its ray
    // frame, i.e. towards + on both other axes. In the planes z = 0 or y = 0 it is inside the cube,
    // in the planes z = 1 or y = 1 outside.
    let inside = [(0.0, 1.0, air), (1.0, 2.0, cube), (2.0, 3.0, air)];
    assert_segments(&s([-1.0, 0.5, 0.0], [1.0, 0.0, 0.0], 3.0), &inside, 0.0);
    assert_segments(&s([-1.0, 0.0, 0.5], [1.0, 0.0, 0.0], 3.0), &inside, 0.0);
    assert_segments(&s([-1.0, 0.0, 0.0], [1.0, 0.0, 0.0], 3.0), &inside, 0.0);
    assert_segments(&s([2.0, 0.5, 0.0], [-1.0, 0.0, 0.0], 3.0), &inside, 0.0);
    assert_segments(&s([-1.0, 0.5, 1.0], [1.0, 0.0, 0.0], 3.0), &[(0.0, 3.0, air)], 0.0);
    assert_segments(&s([-1.0, 1.0, 0.5], [1.0, 0.0, 0.0], 3.0), &[(0.0, 3.0, air)], 0.0);
    // Starting exactly on a face, going in or out.
    assert_segments(&s([0.5, 0.5, 0.0], [0.0, 0.0, 1.0], 2.0), &[(0.0, 1.0, cube), (1.0, 2.0, air)], 0.0);
    assert_segments(&s([0.5, 0.5, 0.0], [0.0, 0.0, -1.0], 2.0), &[(0.0, 2.0, air)], 0.0);
}

/// Random rays through the cube: the cube segment must match the f64 slab intersection, and a ray
/// starting inside must start in the cube; edges and vertices never flip the state for the rest of
/// the ray (the last segment is always air).
#[test]
fn cube_segments_match_slab_intersection_for_random_rays() {
    let sc = cube_scene();
    let bvh = SceneBvh::build(&sc);
    let key = StreamKey { table: 0xc0be, cell: 0 };
    for i in 0..2000u64 {
        let s = key.sample(i);
        let u = |k| s.uniform(k);
        let o = if i % 2 == 0 {
            [u(0), u(1), u(2)] // inside
        } else {
            [3.0 * u(0) - 1.0, 3.0 * u(1) - 1.0, 3.0 * u(2) - 1.0]
        }
        .map(|x| f64::from(x as f32));
        let z = 2.0 * u(3) - 1.0;
        let phi = std::f64::consts::TAU * u(4);
        let d = [(1.0 - z * z).sqrt() * phi.cos(), (1.0 - z * z).sqrt() * phi.sin(), z].map(|x| f64::from(x as f32));
        // Slab intersection in f64.
        let (mut t0, mut t1) = (0.0f64, INF);
        for c in 0..3 {
            let (a, b) = ((0.0 - o[c]) / d[c], (1.0 - o[c]) / d[c]);
            t0 = t0.max(a.min(b));
            t1 = t1.min(a.max(b));
        }
        let got = segs(&bvh, &sc, o, d, 10.0);
        let want: Vec<(f64, f64, Option<usize>)> = if t0 < t1 && t1 - t0 > 1e-4 {
            [(0.0, t0, Some(1)), (t0, t1, Some(0)), (t1, 10.0, Some(1))].into_iter().filter(|s| s.1 > s.0).collect()
        } else if t0 < t1 {
            continue; // a sliver through a corner: either outcome is consistent
        } else {
            vec![(0.0, 10.0, Some(1))]
        };
        assert_segments(&got, &want, 1e-5);
    }
}

/// Nested spheres (radius 2 around radius 1, concentric), the outer listed after the inner, in a
/// global medium: every crossing order, from outside, between and inside.
#[test]
fn nested_spheres() {
    let mut inner = icosphere("inner", [0.0; 3], 1.0, 3);
    let mut outer = icosphere("outer", [0.0; 3], 2.0, 3);
    inner.medium = Some(1);
    outer.medium = Some(0);
    let mut sc = scene(vec![inner, outer]);
    sc.media = vec![
        medium("outer", [1.0; 3], Density::Homogeneous, Boundary::Mesh(1)),
        medium("inner", [2.0; 3], Density::Homogeneous, Boundary::Mesh(0)),
        medium("air", [0.5; 3], Density::Homogeneous, Boundary::Global),
    ];
    let bvh = SceneBvh::build(&sc);
    let (out, inn, air) = (Some(0), Some(1), Some(2));
    // The level-3 tessellation lies up to ≈ 0.004 r inside the sphere (more along oblique rays).
    let tol = 0.02;
    let key = StreamKey { table: 0x5feb, cell: 0 };
    for i in 0..200 {
        let s = key.sample(i);
        let z = 2.0 * s.uniform(0) - 1.0;
        let phi = std::f64::consts::TAU * s.uniform(1);
        let d = [(1.0 - z * z).sqrt() * phi.cos(), (1.0 - z * z).sqrt() * phi.sin(), z];
        let at = |r: f64| d.map(|x| -r * x);
        // From outside through the centre.
        assert_segments(
            &segs(&bvh, &sc, at(4.0), d, INF),
            &[(0.0, 2.0, air), (2.0, 3.0, out), (3.0, 5.0, inn), (5.0, 6.0, out), (6.0, INF, air)],
            tol,
        );
        // From between the spheres, through the inner one.
        assert_segments(
            &segs(&bvh, &sc, at(1.5), d, 10.0),
            &[(0.0, 0.5, out), (0.5, 2.5, inn), (2.5, 3.5, out), (3.5, 10.0, air)],
            tol,
        );
        // From inside the inner sphere (the innermost medium must be found from the hits ahead).
        assert_segments(&segs(&bvh, &sc, at(0.5), d, INF), &[(0.0, 1.5, inn), (1.5, 2.5, out), (2.5, INF, air)], tol);
        // From between, missing the inner sphere: offset perpendicular to d by 1.5.
        let perp = unit_normal(DVec3::from_array(d).cross(DVec3::new(0.3, 0.5, 0.8))).unwrap();
        let o = [0, 1, 2].map(|c| 1.5 * perp[c] - 1.0 * d[c]);
        let exit = 1.0 + (4.0f64 - 2.25).sqrt();
        assert_segments(&segs(&bvh, &sc, o, d, INF), &[(0.0, exit, out), (exit, INF, air)], tol);
    }
}

#[test]
fn global_medium_and_vacuum() {
    let mut sc = scene(vec![cuboid("wall", [0.0; 3], [1.0; 3])]); // not a medium boundary
    let bvh = SceneBvh::build(&sc);
    assert_eq!(bvh.stats().boundary_triangles, 0);
    assert_segments(&segs(&bvh, &sc, [0.5, 0.5, -1.0], [0.0, 0.0, 1.0], 4.0), &[(0.0, 4.0, None)], 0.0);
    sc.media = vec![medium("fog", [0.2; 3], Density::Homogeneous, Boundary::Global)];
    assert_segments(&segs(&bvh, &sc, [0.5, 0.5, -1.0], [0.0, 0.0, 1.0], INF), &[(0.0, INF, Some(0))], 0.0);
    for t_max in [0.0, -1.0, f64::NAN] {
        assert!(segs(&bvh, &sc, [0.0; 3], [1.0, 0.0, 0.0], t_max).is_empty());
    }
    // A medium boundary without a global medium: vacuum outside.
    let mut cube = cuboid("cube", [0.0; 3], [1.0; 3]);
    cube.medium = Some(0);
    let mut sc = scene(vec![cube]);
    sc.media = vec![medium("inside", [1.0; 3], Density::Homogeneous, Boundary::Mesh(0))];
    let bvh = SceneBvh::build(&sc);
    assert_segments(
        &segs(&bvh, &sc, [0.5, 0.5, -1.0], [0.0, 0.0, 1.0], 3.0),
        &[(0.0, 1.0, None), (1.0, 2.0, Some(0)), (2.0, 3.0, None)],
        0.0,
    );
}

#[test]
fn optical_thickness_of_a_homogeneous_slab_is_exact() {
    let mut slab = cuboid("slab", [-10.0, 0.0, -10.0], [10.0, 1.0, 10.0]);
    slab.medium = Some(0);
    let mut sc = scene(vec![slab]);
    sc.media = vec![medium("slab", [0.5, 1.0, 2.0], Density::Homogeneous, Boundary::Mesh(0))];
    let bvh = SceneBvh::build(&sc);
    // A direction of length 2: t is in units of it, τ in metres.
    let ray = Ray::new([0.0, -1.0, 0.0], [0.0, 2.0, 0.0]);
    let s = bvh.media_segments(&sc, &ray, INF);
    assert_eq!(optical_thickness(&sc, &s, &ray), [0.5, 1.0, 2.0]);
    // Oblique, 45°: path length √2 through the 1 m slab.
    let ray = Ray::new([0.0, -1.0, 0.0], [1.0, 1.0, 0.0]);
    let s = bvh.media_segments(&sc, &ray, INF);
    let tau = optical_thickness(&sc, &s, &ray);
    for (c, want) in [0.5, 1.0, 2.0].into_iter().enumerate() {
        assert!((tau[c] - want * 2f64.sqrt()).abs() < 1e-6, "{tau:?}");
    }
    // Effective σ over 3 m of which √2 m in the slab, along a unit direction.
    let u = Ray::new([0.0, -1.0, 0.0], [0.5f64.sqrt(), 0.5f64.sqrt(), 0.0]);
    let s = bvh.media_segments(&sc, &u, 3.0);
    let sig = effective_sigma(&sc, &s, &u);
    for (c, want) in [0.5, 1.0, 2.0].into_iter().enumerate() {
        assert!((sig[c] - want * 2f64.sqrt() / 3.0).abs() < 1e-6, "{sig:?}");
    }
    // Inside the slab, homogeneous: σ_eff = σ_t exactly; unbounded: the far density (vacuum: 0).
    let r = Ray::new([0.0, 0.5, 0.0], [1.0, 0.0, 0.0]);
    assert_eq!(effective_sigma(&sc, &bvh.media_segments(&sc, &r, 4.0), &r), [0.5, 1.0, 2.0]);
    assert_eq!(effective_sigma(&sc, &bvh.media_segments(&sc, &ray, INF), &ray), [0.0; 3]);
}

#[test]
fn zero_length_and_degenerate_segments_add_nothing() {
    let sc = cube_scene();
    let ray = Ray::new([0.0; 3], [1.0, 0.0, 0.0]);
    let zero = [MediumSegment { t0: 0.5, t1: 0.5, medium: Some(0) }];
    assert_eq!(optical_thickness(&sc, &zero, &ray), [0.0; 3]);
    assert_eq!(effective_sigma(&sc, &zero, &ray), [0.0; 3]);
    assert_eq!(effective_sigma(&sc, &[], &ray), [0.0; 3]);
    let odd = [
        MediumSegment { t0: 1.0, t1: 0.5, medium: Some(0) },
        MediumSegment { t0: f64::NAN, t1: 1.0, medium: Some(0) },
        MediumSegment { t0: 0.0, t1: 1.0, medium: Some(7) },
    ];
    assert_eq!(optical_thickness(&sc, &odd, &ray), [0.0; 3]);
    let zero_dir = Ray::new([0.0; 3], [0.0; 3]);
    assert_eq!(optical_thickness(&sc, &[MediumSegment { t0: 0.0, t1: 1.0, medium: Some(0) }], &zero_dir), [0.0; 3]);
}

/// Composite Simpson's rule with `n` (even) intervals.
fn simpson(f: impl Fn(f64) -> f64, a: f64, b: f64, n: usize) -> f64 {
    let h = (b - a) / n as f64;
    let mut s = f(a) + f(b);
    for i in 1..n {
        s += f(a + h * i as f64) * if i % 2 == 1 { 4.0 } else { 2.0 };
    }
    s * h / 3.0
}

#[test]
fn exponential_fog_integral_matches_quadrature() {
    let n = 100_000;
    for mu in [0.0, 1e-12, -1e-12, 0.3, -0.3, 1.0] {
        for (rho, b, h0) in [(1.0, 0.5, 0.0), (0.02, 2.0, -1.5), (3.0, 0.01, 40.0)] {
            for bd in [0.0, 1e-9, 0.1, 1.0, 30.0, 1e3] {
                let d = if bd == 0.0 { 2.0 } else { bd / b };
                let got = exponential_density_integral(rho, b, h0, mu, d);
                let want = simpson(|s| rho * (-b * (h0 + s * mu)).exp(), 0.0, d, n);
                assert!(got.is_finite(), "mu {mu} b {b} D {d}: {got}");
                assert!((got - want).abs() <= 1e-9 * want, "mu {mu} rho {rho} b {b} h0 {h0} D {d}: {got} vs {want}");
            }
        }
    }
}

#[test]
fn exponential_fog_integral_is_finite_or_infinite_never_nan() {
    // A huge exponent with a tiny ρ': e^{1000}·1e-300 fits in f64 although e^{1000} does not.
    let (rho, b, h0, mu, d) = (1e-300, 1.0, -1000.0, 0.3, 1e3);
    let got = exponential_density_integral(rho, b, h0, mu, d);
    let want = simpson(|s| (rho.ln() - b * (h0 + s * mu)).exp(), 0.0, d, 100_000);
    assert!(got.is_finite() && (got - want).abs() <= 1e-9 * want, "{got} vs {want}");
    // μ = 0: ρ' e^{−b h₀} D exactly where it fits, +∞ where the true value overflows f64.
    assert!(
        (exponential_density_integral(1e-300, 1.0, -800.0, 0.0, 1.0) / (800.0 - 300.0 * 10f64.ln()).exp() - 1.0).abs()
            < 1e-12
    );
    assert_eq!(exponential_density_integral(1.0, 1.0, -800.0, 0.0, 1.0), INF);
    assert_eq!(exponential_density_integral(1.0, 1.0, 0.0, -1.0, 1e3), INF); // e^{1000}
    // Unbounded: finite when the density falls along the ray, +∞ otherwise.
    assert!((exponential_density_integral(2.0, 0.5, 1.0, 0.25, INF) - 2.0 * (-0.5f64).exp() / 0.125).abs() < 1e-15);
    assert_eq!(exponential_density_integral(2.0, 0.5, 1.0, 0.0, INF), INF);
    assert_eq!(exponential_density_integral(2.0, 0.5, 1.0, -0.25, INF), INF);
    for rho in [0.0, 1e-300, 1.0, 1e300] {
        for b in [-10.0, 0.0, 1e-3, 1.0, 1e3] {
            for h0 in [-1e3, 0.0, 1e3] {
                for mu in [-1.0, -1e-12, 0.0, 1e-12, 1.0] {
                    for d in [0.0, 1e-300, 1.0, 1e300, INF] {
                        let p = exponential_density_integral(rho, b, h0, mu, d);
                        assert!(p >= 0.0, "rho {rho} b {b} h0 {h0} mu {mu} D {d}: {p}");
                    }
                }
            }
        }
    }
}

/// End to end: a global exponential fog along a ray, segments from the BVH (none: all fog), τ per
/// channel against quadrature of the density at the ray's points.
#[test]
fn optical_thickness_of_height_fog_along_a_ray() {
    let n = [0.0, 1.0, 0.0];
    let fog =
        Density::ExponentialHeight { rho: 0.7, falloff: 0.8, direction: n.map(|x| 2.0 * x), offset: [0.0, 1.0, 0.0] };
    let mut sc = scene(Vec::new());
    sc.media = vec![medium("fog", [0.1, 0.2, 0.4], fog.clone(), Boundary::Global)];
    let bvh = SceneBvh::build(&sc);
    for d in [[1.0, 0.0, 0.0], [3.0, -1.0, 0.5], [0.0, 2.0, 0.0], [1.0, 1e-12, 0.0]] {
        let ray = Ray::new([0.5, 3.0, -2.0], d);
        let t_max = 2.0;
        let s = bvh.media_segments(&sc, &ray, t_max);
        assert_eq!(s, vec![MediumSegment { t0: 0.0, t1: t_max, medium: Some(0) }]);
        let tau = optical_thickness(&sc, &s, &ray);
        let len = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
        let rho = |t: f64| 0.7 * (-0.8 * (ray.origin[1] + t * d[1] - 1.0)).exp();
        let p = simpson(rho, 0.0, t_max, 100_000) * len;
        for (c, sigma) in [0.1, 0.2, 0.4].into_iter().enumerate() {
            assert!((tau[c] - sigma * p).abs() <= 1e-10 * sigma * p, "d {d:?}: {tau:?} vs {}", sigma * p);
        }
        let sig = effective_sigma(&sc, &s, &ray);
        assert!((sig[1] - tau[1] / (t_max * len)).abs() <= 1e-15 * sig[1]);
    }
    // Unbounded rays: upwards the fog thins out (finite τ, σ_eff → 0), downwards τ = ∞.
    let up = Ray::new([0.0, 1.0, 0.0], [0.0, 1.0, 0.0]);
    let s = bvh.media_segments(&sc, &up, INF);
    let tau = optical_thickness(&sc, &s, &up);
    assert!((tau[0] - 0.1 * 0.7 / 0.8).abs() < 1e-15, "{tau:?}");
    assert_eq!(effective_sigma(&sc, &s, &up), [0.0; 3]);
    let down = Ray::new([0.0, 1.0, 0.0], [0.0, -1.0, 0.0]);
    assert_eq!(optical_thickness(&sc, &bvh.media_segments(&sc, &down, INF), &down), [INF; 3]);
    let level = Ray::new([0.0, 1.0, 0.0], [1.0, 0.0, 0.0]);
    let sig = effective_sigma(&sc, &bvh.media_segments(&sc, &level, INF), &level);
    assert!((sig[2] - 0.4 * 0.7).abs() < 1e-15, "{sig:?}");
}
