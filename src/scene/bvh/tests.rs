//! Hit queries against independent references: a brute-force loop over all triangles (the same
//! watertight test, so results must agree exactly) and an f64 Möller–Trumbore loop (agreement away
//! from edges), shadow rays against closest hits, batched against single queries on 1 and 3 threads.

use super::procedural::{icosphere, mesh, scene};
use super::triangle::{PreparedRay, Tri, intersect};
use super::*;
use crate::physics::rng::StreamKey;
use crate::scene::Mesh;

/// Uniform direction on the sphere from two uniforms.
fn sphere_dir(u: f64, v: f64) -> [f64; 3] {
    let z = 2.0 * u - 1.0;
    let phi = std::f64::consts::TAU * v;
    let s = (1.0 - z * z).max(0.0).sqrt();
    [s * phi.cos(), s * phi.sin(), z]
}

/// Rounds to f32 and back, so the BVH (which works in f32) and f64 references see the same ray.
fn f32_exact(v: [f64; 3]) -> [f64; 3] {
    v.map(|x| f64::from(x as f32))
}

/// Five meshes of random triangles in [−1, 1]³ (sizes 0.05–0.5), plus degenerate ones that must be
/// excluded: a repeated vertex, collinear vertices, a NaN vertex and an out-of-range index.
fn soup() -> Scene {
    let key = StreamKey { table: 0x50_0f, cell: 0 };
    let mut meshes = Vec::new();
    let mut n = 0u64;
    for m in 0..5 {
        let mut positions = Vec::new();
        let mut triangles = Vec::new();
        for _ in 0..60 {
            let s = key.sample(n);
            n += 1;
            let c = [0, 1, 2].map(|k| 2.0 * s.uniform(k) - 1.0);
            let size = 0.05 + 0.45 * s.uniform(3);
            let base = positions.len() as u32;
            for v in 0..3 {
                let d = sphere_dir(s.uniform(4 + 2 * v), s.uniform(5 + 2 * v));
                positions.push([0, 1, 2].map(|k| (c[k] + size * d[k]) as f32));
            }
            triangles.push([base, base + 1, base + 2]);
        }
        let base = positions.len() as u32;
        positions.extend([[0.125, 0.25, 0.5], [0.375, 0.5, 0.5], [0.625, 0.75, 0.5], [f32::NAN, 0.0, 0.0]]);
        triangles.extend([
            [base, base, base + 1],
            [base, base + 1, base + 2],
            [base, base + 3, base + 1],
            [base, base + 1, base + 99],
        ]);
        let normals = Vec::new(); // no vertex normals: the shading normal falls back to the geometric one
        meshes.push(mesh(&format!("soup{m}"), positions, normals, triangles));
    }
    scene(meshes)
}

/// Random rays: origins in [−1.5, 1.5]³, uniform directions (some axis-aligned, some of length ≠ 1),
/// every third one with a finite `t_max`.
fn rays(n: u64, cell: u64) -> Vec<Ray> {
    let key = StreamKey { table: 0x7a_75, cell };
    (0..n)
        .map(|i| {
            let s = key.sample(i);
            let o = f32_exact([0, 1, 2].map(|k| 3.0 * s.uniform(k) - 1.5));
            let mut d = sphere_dir(s.uniform(3), s.uniform(4));
            if i % 7 == 0 {
                // axis-aligned: exercises exactly zero direction components
                let a = (i / 7 % 3) as usize;
                d = [0.0; 3];
                d[a] = if i % 2 == 0 { 1.0 } else { -1.0 };
            }
            let scale = [1.0, 0.37, 5.0][(i % 3) as usize];
            let d = f32_exact(d.map(|x| x * scale));
            let t_max = if i % 3 == 0 { 0.5 + 2.0 * s.uniform(5) } else { f64::INFINITY };
            Ray { origin: o, direction: d, t_min: 0.0, t_max }
        })
        .collect()
}

/// All triangles of the scene that the BVH keeps, with their global ids (mesh-major).
fn all_tris(scene: &Scene) -> Vec<(Tri, usize, usize)> {
    let mut out = Vec::new();
    let mut gid = 0u32;
    for (mi, m) in scene.meshes.iter().enumerate() {
        for (ti, t) in m.triangles.iter().enumerate() {
            if let Some(v) = triangle_vertices(&m.positions, t) {
                out.push((Tri { v, gid }, mi, ti));
            }
            gid += 1;
        }
    }
    out
}

/// Brute force with the same watertight test and tie-break: (t, mesh, triangle, front).
fn brute_closest(tris: &[(Tri, usize, usize)], ray: &Ray) -> Option<(f64, usize, usize, bool)> {
    let q = Query::new(ray.origin, ray.direction, ray.t_min, ray.t_max)?;
    let mut best: Option<(f32, u32, usize, usize, bool)> = None;
    for (tri, m, t) in tris {
        if let Some(h) = intersect(tri, &q.pr)
            && q.in_range(h.t)
            && best.is_none_or(|b| (h.t, tri.gid) < (b.0, b.1))
        {
            best = Some((h.t, tri.gid, *m, *t, h.front));
        }
    }
    best.map(|b| (f64::from(b.0) / q.unit, b.2, b.3, b.4))
}

/// f64 Möller–Trumbore: (t, barycentrics (b0, b1, b2)) of the line through the triangle's plane.
fn mt64(v: [[f32; 3]; 3], o: [f64; 3], d: [f64; 3]) -> Option<(f64, [f64; 3])> {
    let p = v.map(|x| DVec3::from_array(x.map(f64::from)));
    let (o, d) = (DVec3::from_array(o), DVec3::from_array(d));
    let e1 = p[1] - p[0];
    let e2 = p[2] - p[0];
    let pv = d.cross(e2);
    let det = e1.dot(pv);
    if det.abs() < 1e-14 {
        return None;
    }
    let tv = o - p[0];
    let u = tv.dot(pv) / det;
    let qv = tv.cross(e1);
    let v = d.dot(qv) / det;
    let t = e2.dot(qv) / det;
    Some((t, [1.0 - u - v, u, v]))
}

#[test]
fn closest_hit_equals_brute_force_over_all_triangles() {
    let sc = soup();
    let bvh = SceneBvh::build(&sc);
    assert_eq!(bvh.stats().excluded, 5 * 4, "four degenerate triangles per mesh are left out");
    assert_eq!(bvh.stats().triangles, 5 * 60);
    let tris = all_tris(&sc);
    let mut hits = 0;
    for r in rays(3000, 1) {
        let got = bvh.closest_hit(&r);
        let want = brute_closest(&tris, &r);
        assert_eq!(got.map(|h| (h.t, h.mesh, h.triangle, h.front_face)), want, "ray {r:?}");
        hits += usize::from(got.is_some());
    }
    // Not a vacuous comparison: a good share of the rays hit something.
    assert!(hits > 600, "{hits} hits");
}

#[test]
fn closest_hit_agrees_with_f64_moller_trumbore_away_from_edges() {
    let sc = soup();
    let bvh = SceneBvh::build(&sc);
    let tris = all_tris(&sc);
    let (mut compared, mut ambiguous) = (0, 0);
    for r in rays(3000, 2) {
        // Candidates: triangles hit in f64 or missed by less than 1e-4 in a barycentric.
        let mut cand: Vec<(f64, f64, usize, usize)> = tris
            .iter()
            .filter_map(|(tri, m, t)| {
                let (tt, b) = mt64(tri.v, r.origin, r.direction)?;
                let min_b = b[0].min(b[1]).min(b[2]);
                (tt > 0.0 && tt <= r.t_max && min_b > -1e-4).then_some((tt, min_b, *m, *t))
            })
            .collect();
        cand.sort_by(|a, b| a.0.total_cmp(&b.0));
        let got = bvh.closest_hit(&r);
        let first_sure = cand.iter().position(|c| c.1 >= 1e-4);
        // Ambiguous when an edge-near candidate comes before the first sure hit or ties with it.
        let is_ambiguous = match first_sure {
            Some(i) => {
                cand[..i].iter().any(|c| c.1 > -1e-4)
                    || cand.get(i + 1).is_some_and(|c| c.0 <= cand[i].0 * (1.0 + 1e-5))
                    || (r.t_max - cand[i].0).abs() < 1e-5
            }
            None => !cand.is_empty(),
        };
        if is_ambiguous {
            ambiguous += 1;
            continue;
        }
        compared += 1;
        match (got, first_sure.map(|i| cand[i])) {
            (None, None) => {}
            (Some(h), Some(c)) => {
                assert_eq!((h.mesh, h.triangle), (c.2, c.3), "ray {r:?}");
                assert!((h.t - c.0).abs() <= 1e-5 * (1.0 + c.0), "t {} vs {}", h.t, c.0);
            }
            (g, w) => panic!("ray {r:?}: bvh {g:?}, f64 reference {w:?}"),
        }
    }
    assert!(ambiguous * 20 < compared, "{ambiguous} ambiguous of {compared}");
}

#[test]
fn hit_fields_are_consistent() {
    let sc = soup();
    let bvh = SceneBvh::build(&sc);
    let mut checked = 0;
    for r in rays(2000, 3) {
        let Some(h) = bvh.closest_hit(&r) else { continue };
        let m = &sc.meshes[h.mesh];
        let p = m.triangles[h.triangle].map(|i| m.positions[i as usize].map(f64::from));
        let [u, v] = h.barycentric;
        assert!(u >= 0.0 && v >= 0.0 && u + v <= 1.0 + 1e-6, "{:?}", h.barycentric);
        let x = [0, 1, 2].map(|c| (1.0 - u - v) * p[0][c] + u * p[1][c] + v * p[2][c]);
        let y = [0, 1, 2].map(|c| r.origin[c] + h.t * r.direction[c]);
        for c in 0..3 {
            assert!((x[c] - y[c]).abs() < 1e-5, "point {x:?} vs {y:?}");
        }
        let pv = p.map(DVec3::from_array);
        let n = unit_normal((pv[1] - pv[0]).cross(pv[2] - pv[0])).unwrap();
        assert!((0..3).all(|c| (n[c] - h.geometric_normal[c]).abs() < 1e-9));
        assert_eq!(h.shading_normal, h.geometric_normal, "the soup has no vertex normals");
        let cos = n[0] * r.direction[0] + n[1] * r.direction[1] + n[2] * r.direction[2];
        let len = r.direction.iter().map(|x| x * x).sum::<f64>().sqrt();
        if cos.abs() > 1e-3 * len {
            assert_eq!(h.front_face, cos < 0.0, "front_face must be the sign of <d, n_g>");
            checked += 1;
        }
    }
    assert!(checked > 300);
}

#[test]
fn occluded_agrees_with_closest_hit() {
    let sc = soup();
    let bvh = SceneBvh::build(&sc);
    let key = StreamKey { table: 0x0cc1, cell: 0 };
    let (mut blocked, mut clear) = (0, 0);
    for (i, r) in rays(3000, 4).into_iter().enumerate() {
        let t_max = 0.05 + 3.0 * key.uniform(i as u64, 0);
        let nearest = bvh.closest_hit(&Ray { t_max: f64::INFINITY, ..r });
        let expect = nearest.is_some_and(|h| h.t < t_max);
        assert_eq!(bvh.occluded(r.origin, r.direction, t_max), expect, "ray {r:?} t_max {t_max}");
        if expect {
            blocked += 1
        } else {
            clear += 1
        }
        // A shadow ray ending exactly at the hit is not blocked by it (t_max itself is excluded)
        // unless something else lies strictly in front.
        if let Some(h) = nearest {
            assert!(!bvh.occluded(r.origin, r.direction, h.t), "ray {r:?}");
        }
    }
    assert!(blocked > 300 && clear > 300, "{blocked} blocked, {clear} clear");
}

#[test]
fn batched_queries_equal_single_ones_on_any_thread_count() {
    let sc = soup();
    let rs = rays(4000, 5);
    let run = |threads: usize| {
        let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().expect("pool");
        pool.install(|| {
            let bvh = SceneBvh::build(&sc);
            (bvh.closest_hits(&rs), bvh.occluded_batch(&rs), bvh)
        })
    };
    let (hits1, occ1, bvh1) = run(1);
    let (hits3, occ3, _) = run(3);
    assert_eq!(hits1, hits3);
    assert_eq!(occ1, occ3);
    for (i, r) in rs.iter().enumerate() {
        assert_eq!(hits1[i], bvh1.closest_hit(r));
        assert_eq!(occ1[i], bvh1.occluded_ray(r));
    }
}

#[test]
fn invalid_rays_and_scenes_miss_without_panicking() {
    let sc = soup();
    let bvh = SceneBvh::build(&sc);
    let o = [-1.5, 0.0, 0.0];
    for d in [[0.0; 3], [f64::NAN, 1.0, 0.0], [f64::INFINITY, 0.0, 0.0], [1e-320, 0.0, 0.0]] {
        let r = Ray::new(o, d);
        if d[0] == 1e-320 {
            // A subnormal but non-zero direction is valid: it is rescaled exactly.
            assert_eq!(
                bvh.closest_hit(&r).map(|h| h.mesh),
                bvh.closest_hit(&Ray::new(o, [1.0, 0.0, 0.0])).map(|h| h.mesh)
            );
            continue;
        }
        assert_eq!(bvh.closest_hit(&r), None, "{d:?}");
        assert!(!bvh.occluded(o, d, 10.0));
        assert!(bvh.media_segments(&sc, &r, 10.0).is_empty());
    }
    for origin in [[f64::NAN, 0.0, 0.0], [1e300, 0.0, 0.0]] {
        assert_eq!(bvh.closest_hit(&Ray::new(origin, [1.0, 0.0, 0.0])), None);
    }
    let r = Ray::new(o, [1.0, 0.0, 0.0]);
    for (t_min, t_max) in [(0.0, f64::NAN), (f64::NAN, 1.0), (2.0, 1.0), (1.0, 1.0)] {
        assert_eq!(bvh.closest_hit(&Ray { t_min, t_max, ..r }), None);
        assert!(!bvh.occluded_ray(&Ray { t_min, t_max, ..r }));
    }
    // Empty scene, and a scene whose only triangle has zero area.
    let empty = SceneBvh::build(&scene(Vec::new()));
    assert_eq!(empty.closest_hit(&r), None);
    assert!(!empty.occluded(o, [1.0, 0.0, 0.0], f64::INFINITY));
    let flat = mesh("flat", vec![[0.0, -1.0, -1.0], [0.0, 1.0, 1.0], [0.0, 0.0, 0.0]], Vec::new(), vec![[0, 1, 2]]);
    let flat = SceneBvh::build(&scene(vec![flat]));
    assert_eq!((flat.stats().triangles, flat.stats().excluded), (0, 1));
    assert_eq!(flat.closest_hit(&r), None);
}

/// The watertight test alone: a ray through the shared diagonal of a quad, or through the centre of
/// a fan of triangles, hits exactly one of them, from both sides and with every axis as dominant.
#[test]
fn shared_edges_and_vertices_are_owned_by_exactly_one_triangle() {
    // A regular fan of 7 triangles around the origin in the plane z = 0 and a quad split along x = y.
    let fan: Vec<Tri> = (0..7)
        .map(|i| {
            let a = |k: u32| {
                let phi = std::f64::consts::TAU * f64::from(k % 7) / 7.0;
                [phi.cos() as f32, phi.sin() as f32, 0.0]
            };
            Tri { v: [[0.0; 3], a(i), a(i + 1)], gid: i }
        })
        .collect();
    let quad = [
        Tri { v: [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 1.0, 0.0]], gid: 0 },
        Tri { v: [[0.0, 0.0, 0.0], [1.0, 1.0, 0.0], [0.0, 1.0, 0.0]], gid: 1 },
    ];
    let count = |tris: &[Tri], o: [f32; 3], d: [f32; 3]| {
        let r = PreparedRay::new(o, d);
        tris.iter().filter(|t| intersect(t, &r).is_some_and(|h| h.t > 0.0)).count()
    };
    for dz in [1.0f32, -1.0] {
        let z = -dz;
        for (dx, dy) in [(0.0, 0.0), (0.5, 0.25), (-0.25, 0.5), (1.7, 0.3)] {
            // Dominant axis z, and (for the last one) x.
            assert_eq!(count(&fan, [-dx, -dy, z], [dx, dy, dz]), 1, "fan centre, d = ({dx}, {dy}, {dz})");
            for s in [0.25f32, 0.5, 0.75] {
                assert_eq!(count(&quad, [s - dx, s - dy, z], [dx, dy, dz]), 1, "diagonal at {s}");
            }
            // The quad's corner (0, 0) is a silhouette vertex of the quad: owned by at most one.
            assert!(count(&quad, [-dx, -dy, z], [dx, dy, dz]) <= 1);
        }
    }
}

/// A closed mesh: every directed edge's reverse appears exactly once, and every face normal points
/// away from the centre.
fn assert_closed_outward(m: &Mesh, center: [f64; 3]) {
    let mut edges = std::collections::HashMap::new();
    for t in &m.triangles {
        for k in 0..3 {
            *edges.entry((t[k], t[(k + 1) % 3])).or_insert(0) += 1;
        }
        let p = t.map(|i| m.positions[i as usize].map(f64::from));
        let pv = p.map(DVec3::from_array);
        let n = (pv[1] - pv[0]).cross(pv[2] - pv[0]);
        let g = [0, 1, 2].map(|c| (p[0][c] + p[1][c] + p[2][c]) / 3.0 - center[c]);
        assert!(n[0] * g[0] + n[1] * g[1] + n[2] * g[2] > 0.0, "{}: inward face {t:?}", m.name);
    }
    for (&(a, b), &n) in &edges {
        assert_eq!((n, edges.get(&(b, a)).copied()), (1, Some(1)), "{}: edge {a}-{b}", m.name);
    }
}

#[test]
fn procedural_meshes_are_closed_and_outward() {
    for level in 0..3 {
        let m = icosphere("s", [0.5, -1.0, 2.0], 1.5, level);
        assert_eq!(m.triangles.len(), 20 * 4usize.pow(level));
        assert_closed_outward(&m, [0.5, -1.0, 2.0]);
    }
    let field = procedural::sphere_field(30_000);
    assert!(field.triangle_count() >= 30_000, "{}", field.triangle_count());
    for m in &field.meshes[1..] {
        let c = m.positions.iter().fold([0.0; 3], |a, p| [0, 1, 2].map(|k| a[k] + f64::from(p[k])));
        assert_closed_outward(m, c.map(|x| x / m.positions.len() as f64));
    }
}

#[test]
fn sphere_hits_have_outward_normals() {
    let sc = scene(vec![icosphere("ball", [0.0, 0.0, 0.0], 1.0, 3)]);
    let bvh = SceneBvh::build(&sc);
    let key = StreamKey { table: 0xba11, cell: 0 };
    for i in 0..500 {
        let s = key.sample(i);
        let dir = sphere_dir(s.uniform(0), s.uniform(1));
        // From outside towards a random point inside, and from the centre outwards.
        let target = sphere_dir(s.uniform(2), s.uniform(3)).map(|x| 0.5 * s.uniform(4) * x);
        let o = dir.map(|x| 3.0 * x);
        let h = bvh.closest_hit(&Ray::new(o, [0, 1, 2].map(|c| target[c] - o[c]))).expect("hits the ball");
        assert!(h.front_face);
        let p = [0, 1, 2].map(|c| o[c] + h.t * (target[c] - o[c]));
        let r = (p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt();
        assert!((r - 1.0).abs() < 5e-3, "|p| = {r}");
        let cos_s = (0..3).map(|c| h.shading_normal[c] * p[c] / r).sum::<f64>();
        let cos_g = (0..3).map(|c| h.geometric_normal[c] * p[c] / r).sum::<f64>();
        assert!(cos_s > 0.999 && cos_g > 0.99, "{cos_s} {cos_g}");
        let out = bvh.closest_hit(&Ray::new([0.0; 3], dir)).expect("hits from inside");
        assert!(!out.front_face && (out.t - 1.0).abs() < 5e-3);
    }
}

/// Regression for obvhs's own box test, which clamps the entry distance to 1e-4 and treats direction
/// components below f32::EPSILON as slope ±1.19e-7: a hit a micron ahead, and a ray running parallel
/// to a box face just inside it towards a triangle 90 m away, must both be found.
#[test]
fn hits_close_to_the_origin_and_along_box_faces_are_not_culled() {
    let sc = soup();
    let bvh = SceneBvh::build(&sc);
    let key = StreamKey { table: 0x0e05, cell: 0 };
    for (mi, m) in sc.meshes.iter().enumerate() {
        for ti in (0..60).step_by(7) {
            let p = m.triangles[ti].map(|i| m.positions[i as usize].map(f64::from));
            let s = key.sample((mi * 100 + ti) as u64);
            let target = [0, 1, 2].map(|c| (p[0][c] + p[1][c] + p[2][c]) / 3.0);
            let d = sphere_dir(s.uniform(0), s.uniform(1));
            let o = [0, 1, 2].map(|c| target[c] - 1e-6 * d[c]);
            let h = bvh.closest_hit(&Ray::new(o, d)).expect("a micron ahead");
            assert!(h.t < 2e-6, "t = {} for a hit a micron ahead", h.t);
        }
    }
    // A unit triangle standing in the plane x = 90 (y, z in [0, 1]) and a long floor.
    let wall = mesh("wall", vec![[90.0, 0.0, 0.0], [90.0, 1.0, 0.0], [90.0, 0.0, 1.0]], Vec::new(), vec![[0, 1, 2]]);
    let floor =
        mesh("floor", vec![[0.0, -1.0, -1.0], [100.0, -1.0, -1.0], [0.0, -1.0, 2.0]], Vec::new(), vec![[0, 1, 2]]);
    let bvh = SceneBvh::build(&scene(vec![wall, floor]));
    // Starting 2⁻¹⁶ m in front of a small wall (its leaf box is flat in x): inside obvhs's 1e-4 clamp.
    let small = mesh("small", vec![[0.75, 0.0, 0.0], [0.75, 0.5, 0.0], [0.75, 0.0, 0.5]], Vec::new(), vec![[0, 1, 2]]);
    let base = mesh("base", vec![[0.0, -0.5, 0.0], [1.0, -0.5, 0.0], [0.0, -0.5, 1.0]], Vec::new(), vec![[0, 1, 2]]);
    let near = SceneBvh::build(&scene(vec![small, base]));
    let h = near.closest_hit(&Ray::new([0.75 - 2f64.powi(-16), 0.125, 0.125], [1.0, 0.0, 0.0])).expect("just ahead");
    assert_eq!((h.mesh, h.t), (0, 2f64.powi(-16)));
    let y = 1.0 - 2f64.powi(-20);
    for dy in [0.0, 1e-12, -1e-12] {
        let h =
            bvh.closest_hit(&Ray::new([0.0, y, 2f64.powi(-21)], [1.0, dy, 0.0])).expect("parallel to the box's top");
        assert_eq!(h.mesh, 0);
        assert!((h.t - 90.0).abs() < 1e-4);
    }
}
