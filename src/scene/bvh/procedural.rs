//! Procedural geometry for tests and benchmarks: closed icospheres and a large field of spheres on a
//! terrain.
//!
//! **Input → output.** Centre, radius and subdivision level → a closed, welded [`Mesh`] with outward
//! counter-clockwise triangles (the importers' convention); a triangle budget → a [`Scene`] of at
//! least that many triangles. Everything is a pure function of the arguments.

use std::collections::HashMap;
use std::path::PathBuf;

use glam::DVec3;

use crate::physics::rng::StreamKey;
use crate::scene::{Mesh, Scene, SceneFormat};

const IDENTITY: [[f64; 4]; 4] =
    [[1.0, 0.0, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0], [0.0, 0.0, 0.0, 1.0]];

/// A mesh with no material or medium and an identity transform.
pub fn mesh(name: &str, positions: Vec<[f32; 3]>, normals: Vec<[f32; 3]>, triangles: Vec<[u32; 3]>) -> Mesh {
    Mesh {
        name: name.into(),
        positions,
        normals,
        uv: None,
        lightmap_uv: None,
        triangles,
        material: None,
        medium: None,
        to_world: IDENTITY,
    }
}

/// A scene holding `meshes` (no lights, cameras or media), "read" from `<procedural>`.
pub fn scene(meshes: Vec<Mesh>) -> Scene {
    Scene {
        source: PathBuf::from("<procedural>"),
        format: SceneFormat::Gltf,
        meshes,
        materials: Vec::new(),
        lights: Vec::new(),
        cameras: Vec::new(),
        media: Vec::new(),
        environment: None,
        warnings: Vec::new(),
    }
}

/// Unit icosphere: `20·4^subdivisions` triangles, vertices on the unit sphere, outward winding.
fn unit_icosphere(subdivisions: u32) -> (Vec<DVec3>, Vec<[u32; 3]>) {
    let p = (1.0 + 5f64.sqrt()) / 2.0;
    let mut verts: Vec<DVec3> = [
        [-1.0, p, 0.0],
        [1.0, p, 0.0],
        [-1.0, -p, 0.0],
        [1.0, -p, 0.0],
        [0.0, -1.0, p],
        [0.0, 1.0, p],
        [0.0, -1.0, -p],
        [0.0, 1.0, -p],
        [p, 0.0, -1.0],
        [p, 0.0, 1.0],
        [-p, 0.0, -1.0],
        [-p, 0.0, 1.0],
    ]
    .iter()
    .map(|&v| {
        let v = DVec3::from_array(v);
        v / v.length()
    })
    .collect();
    let mut faces: Vec<[u32; 3]> = vec![
        [0, 11, 5],
        [0, 5, 1],
        [0, 1, 7],
        [0, 7, 10],
        [0, 10, 11],
        [1, 5, 9],
        [5, 11, 4],
        [11, 10, 2],
        [10, 7, 6],
        [7, 1, 8],
        [3, 9, 4],
        [3, 4, 2],
        [3, 2, 6],
        [3, 6, 8],
        [3, 8, 9],
        [4, 9, 5],
        [2, 4, 11],
        [6, 2, 10],
        [8, 6, 7],
        [9, 8, 1],
    ];
    for _ in 0..subdivisions {
        let mut mid: HashMap<(u32, u32), u32> = HashMap::new();
        let mut midpoint = |a: u32, b: u32, verts: &mut Vec<DVec3>| {
            *mid.entry((a.min(b), a.max(b))).or_insert_with(|| {
                let v = verts[a as usize] + verts[b as usize];
                verts.push(v / v.length());
                (verts.len() - 1) as u32
            })
        };
        let mut next = Vec::with_capacity(faces.len() * 4);
        for [a, b, c] in faces {
            let (ab, bc, ca) = (midpoint(a, b, &mut verts), midpoint(b, c, &mut verts), midpoint(c, a, &mut verts));
            next.extend([[a, ab, ca], [b, bc, ab], [c, ca, bc], [ab, bc, ca]]);
        }
        faces = next;
    }
    (verts, faces)
}

/// A closed icosphere of `20·4^subdivisions` triangles: shared (welded) vertices on the sphere of
/// `radius` about `center`, unit outward normals, counter-clockwise seen from outside.
pub fn icosphere(name: &str, center: [f64; 3], radius: f64, subdivisions: u32) -> Mesh {
    let (verts, faces) = unit_icosphere(subdivisions);
    let center = DVec3::from_array(center);
    let positions = verts.iter().map(|&v| (center + radius * v).as_vec3().to_array()).collect();
    let normals = verts.iter().map(|v| v.as_vec3().to_array()).collect();
    mesh(name, positions, normals, faces)
}

/// A height-field terrain of `n × n` quads (`2n²` triangles) over `[−half, half]²` in x/z, facing +y.
pub fn terrain(name: &str, n: usize, half: f64, amplitude: f64) -> Mesh {
    let n = n.max(1);
    let height = |x: f64, z: f64| amplitude * ((0.7 * x).sin() * (0.45 * z).cos() + 0.3 * (1.9 * x + 1.3 * z).sin());
    let mut positions = Vec::with_capacity((n + 1) * (n + 1));
    for j in 0..=n {
        for i in 0..=n {
            let x = -half + 2.0 * half * i as f64 / n as f64;
            let z = -half + 2.0 * half * j as f64 / n as f64;
            positions.push([x as f32, height(x, z) as f32, z as f32]);
        }
    }
    let idx = |i: usize, j: usize| (j * (n + 1) + i) as u32;
    let mut triangles = Vec::with_capacity(2 * n * n);
    for j in 0..n {
        for i in 0..n {
            // Counter-clockwise seen from +y (x right, z towards the viewer).
            triangles.push([idx(i, j), idx(i, j + 1), idx(i + 1, j + 1)]);
            triangles.push([idx(i, j), idx(i + 1, j + 1), idx(i + 1, j)]);
        }
    }
    let normals = vec![[0.0, 1.0, 0.0]; positions.len()];
    mesh(name, positions, normals, triangles)
}

/// A benchmark scene of at least `min_triangles` triangles: a terrain holding about an eighth of them
/// under a square grid of icospheres (level 5, 20 480 triangles each, for budgets of 320 k and more)
/// with radii in [0.6, 1] on a 2.5 m pitch.
pub fn sphere_field(min_triangles: usize) -> Scene {
    let target = min_triangles.max(20);
    let level = (0..=5u32).rev().find(|&l| 20 * 4usize.pow(l) * 16 <= target).unwrap_or(0);
    let per_sphere = 20 * 4usize.pow(level);
    let n_terrain = ((target as f64 / 16.0).sqrt() as usize).max(1);
    let terrain_tris = 2 * n_terrain * n_terrain;
    let spheres = target.saturating_sub(terrain_tris).div_ceil(per_sphere).max(1);
    let side = (spheres as f64).sqrt().ceil() as usize;
    let pitch = 2.5;
    let half = 0.5 * pitch * side as f64 + 1.0;
    let mut meshes = vec![terrain("terrain", n_terrain, half, 0.3)];
    let key = StreamKey { table: 0x0b7e_5eed, cell: 0 };
    for s in 0..spheres {
        let (i, j) = (s % side, s / side);
        let r = 0.6 + 0.4 * key.uniform(s as u64, 0);
        let x = -half + 1.0 + pitch * (i as f64 + 0.5);
        let z = -half + 1.0 + pitch * (j as f64 + 0.5);
        meshes.push(icosphere(&format!("sphere{s}"), [x, 0.6 + r, z], r, level));
    }
    scene(meshes)
}
