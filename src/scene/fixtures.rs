//! Small hand-built scenes for unit tests (no importer involved).

use super::{Boundary, Density, Light, LightKind, Material, Medium, Mesh, Scene, SceneFormat, Surface};

/// An axis-aligned box from `lo` to `hi`, 8 shared vertices, 12 outward (counter-clockwise) triangles.
pub fn cuboid(name: &str, lo: [f32; 3], hi: [f32; 3]) -> Mesh {
    let positions: Vec<[f32; 3]> =
        (0..8).map(|i| [0, 1, 2].map(|c| if i >> c & 1 == 1 { hi[c] } else { lo[c] })).collect();
    let quads = [[0, 2, 3, 1], [4, 5, 7, 6], [0, 1, 5, 4], [2, 6, 7, 3], [0, 4, 6, 2], [1, 3, 7, 5]];
    let triangles = quads.iter().flat_map(|q| [[q[0], q[1], q[2]], [q[0], q[2], q[3]]]).collect();
    Mesh {
        name: name.into(),
        normals: vec![[0.0, 1.0, 0.0]; 8],
        positions,
        uv: None,
        lightmap_uv: None,
        triangles,
        material: None,
        medium: None,
        to_world: [[1.0, 0.0, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0], [0.0, 0.0, 0.0, 1.0]],
    }
}

/// The unit cube [0, s]³.
pub fn cube(name: &str, s: f32) -> Mesh {
    cuboid(name, [0.0; 3], [s; 3])
}

/// A homogeneous medium with the same σ_s on every channel, σ_a = 0 and g = 0.5.
pub fn medium(name: &str, sigma: f64, boundary: Boundary) -> Medium {
    Medium {
        name: name.into(),
        sigma_s: [sigma; 3],
        sigma_a: [0.0; 3],
        g: [0.5; 3],
        density: Density::Homogeneous,
        boundary,
    }
}

/// An empty scene "read" from `file`.
pub fn empty(file: &str) -> Scene {
    Scene::empty(std::path::Path::new(file), SceneFormat::Usd)
}

/// A point light of intensity `i` W/sr.
pub fn point_light(name: &str, position: [f64; 3], i: f64) -> Light {
    Light { name: name.into(), kind: LightKind::Point { position }, radiance: [i; 3] }
}

/// A 4 m room (opaque floor) filled with global fog (σ_s 0.1 /m, σ_a 0.01 /m, g 0.3), lit by a point
/// light and an emissive ceiling quad (as a one-triangle-pair mesh).
pub fn fog_room() -> Scene {
    let mut s = empty("fog_room.usda");
    s.materials.push(Material {
        name: "Floor".into(),
        base_color: [0.8; 3],
        emission: [0.0; 3],
        surface: Surface::Opaque,
        roughness: 0.5,
    });
    let mut floor = cuboid("/Room/Floor", [0.0, -0.1, 0.0], [4.0, 0.0, 4.0]);
    floor.material = Some(0);
    s.meshes.push(floor);
    s.meshes.push(cuboid("/Room/Lamp", [1.5, 2.9, 1.5], [2.5, 3.0, 2.5]));
    s.lights.push(point_light("/Room/Bulb", [2.0, 2.0, 2.0], 1.0));
    s.lights.push(Light { name: "/Room/Lamp".into(), kind: LightKind::EmissiveMesh { mesh: 1 }, radiance: [5.0; 3] });
    s.media.push(Medium {
        name: "/Room/Fog".into(),
        sigma_s: [0.1; 3],
        sigma_a: [0.01; 3],
        g: [0.3; 3],
        density: Density::Homogeneous,
        boundary: Boundary::Global,
    });
    s
}

/// A 0.2 m wax-like cube with a refractive (ior 1.5) boundary, per-channel albedo, g 0.7, on a floor, lit by
/// a point light.
pub fn translucent() -> Scene {
    let mut s = empty("translucent.gltf");
    s.materials.push(Material {
        name: "Wax".into(),
        base_color: [1.0; 3],
        emission: [0.0; 3],
        surface: Surface::Dielectric { ior: 1.5 },
        roughness: 0.0,
    });
    let mut body = cube("Body", 0.2);
    body.material = Some(0);
    body.medium = Some(0);
    s.meshes.push(body);
    s.meshes.push(cuboid("Floor", [-1.0, -0.01, -1.0], [1.0, 0.0, 1.0]));
    s.lights.push(point_light("Bulb", [0.5, 0.5, 0.5], 0.5));
    s.media.push(Medium {
        name: "Wax".into(),
        sigma_s: [990.0, 950.0, 900.0],
        sigma_a: [10.0, 50.0, 100.0],
        g: [0.7; 3],
        density: Density::Homogeneous,
        boundary: Boundary::Mesh(0),
    });
    s
}
