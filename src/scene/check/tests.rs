use super::*;
use crate::scene::fixtures::{cube, medium, point_light};

/// A 1 m fog cube (σ_t = 1/m) with a 1 W/sr point light beside it.
fn scene() -> Scene {
    let mut box_mesh = cube("/World/FogBox", 1.0);
    box_mesh.medium = Some(0);
    let mut s = crate::scene::fixtures::empty("test.usda");
    s.meshes.push(box_mesh);
    s.lights.push(point_light("/World/Lamp", [2.0, 0.5, 0.5], 1.0));
    s.media.push(medium("/World/FogBox/Fog", 1.0, Boundary::Mesh(0)));
    s
}

fn error_of(mut s: Scene) -> SceneError {
    match check(&mut s) {
        Ok(()) => panic!("expected an error"),
        Err(e) => e,
    }
}

#[test]
fn a_closed_fog_box_passes_without_warnings() {
    let mut s = scene();
    check(&mut s).unwrap();
    assert!(s.warnings.is_empty(), "{:?}", s.warnings);
}

#[test]
fn an_open_or_miswound_boundary_is_an_error_naming_the_mesh() {
    let mut s = scene();
    s.meshes[0].triangles.truncate(10); // remove one face: 4 open edges
    let e = error_of(s);
    assert_eq!(e.location.as_deref(), Some("/World/FogBox"));
    assert!(e.message.contains("4 open (boundary) edges"), "{e}");

    let mut s = scene();
    s.meshes[0].triangles[0].swap(1, 2); // one triangle wound against its neighbours
    let e = error_of(s);
    assert!(e.message.contains("wound inconsistently"), "{e}");
    assert!(!e.message.contains(" 0 edges shared"), "{e}");
}

#[test]
fn split_vertices_are_welded_before_the_manifold_test() {
    // Duplicate every vertex per triangle (as glTF exporters do for flat normals): still closed.
    let mut s = scene();
    let m = &mut s.meshes[0];
    let mut positions = Vec::new();
    let mut triangles = Vec::new();
    for t in &m.triangles {
        let base = positions.len() as u32;
        positions.extend(t.iter().map(|&v| m.positions[v as usize]));
        triangles.push([base, base + 1, base + 2]);
    }
    m.normals = vec![[0.0, 1.0, 0.0]; positions.len()];
    m.positions = positions;
    m.triangles = triangles;
    check(&mut s).unwrap();
}

#[test]
fn degenerate_triangles_are_errors_on_boundaries_and_dropped_elsewhere() {
    let mut s = scene();
    s.meshes[0].triangles.push([0, 0, 1]);
    assert!(error_of(s).message.contains("degenerate triangle (triangle 12)"));

    let mut s = scene();
    let mut wall = cube("wall", 2.0);
    wall.triangles.push([0, 1, 1]);
    wall.triangles.push([0, 1, 3]); // 0, 1, 3 are not collinear: kept
    wall.positions.push([0.5, 0.0, 0.0]); // collinear with 0 and 1
    wall.normals.push([0.0, 1.0, 0.0]);
    wall.triangles.push([0, 1, 8]);
    s.meshes.push(wall);
    check(&mut s).unwrap();
    assert_eq!(s.meshes[1].triangles.len(), 13);
    assert_eq!(s.warnings.len(), 1);
    assert_eq!(s.warnings[0].location, "wall");
    assert!(s.warnings[0].message.starts_with("2 of 15 triangles"), "{:?}", s.warnings);
}

#[test]
fn broken_values_are_errors_naming_the_node() {
    let mut s = scene();
    s.meshes[0].positions[3][1] = f32::NAN;
    let e = error_of(s);
    assert_eq!(e.location.as_deref(), Some("/World/FogBox"));
    assert!(e.message.contains("vertex 3 is not finite"), "{e}");

    let mut s = scene();
    s.meshes[0].triangles[5][2] = 8;
    assert!(error_of(s).message.contains("triangle 5 indexes vertex 8 but the mesh has 8 vertices"));

    let mut s = scene();
    s.lights[0].radiance[1] = -0.5;
    let e = error_of(s);
    assert_eq!(e.location.as_deref(), Some("/World/Lamp"));
    assert!(e.message.contains("negative light intensity"), "{e}");

    let mut s = scene();
    s.media[0].g = [0.5, 1.0, 0.5];
    assert!(error_of(s).message.contains("|g| < 1"));

    let mut s = scene();
    s.media[0].sigma_a[2] = -1.0;
    assert!(error_of(s).message.contains("sigma_a"));

    let mut s = scene();
    s.media.push(medium("Air", 0.01, Boundary::Global));
    s.media.push(medium("Haze", 0.01, Boundary::Global));
    let e = error_of(s);
    assert_eq!(e.location.as_deref(), Some("Haze"));
    assert!(e.message.contains("the first is Air"), "{e}");
}

#[test]
fn unit_mistakes_are_warned_with_the_likely_cause() {
    // σ_t = 2e6 /m: the mean free path is 0.5 µm.
    let mut s = scene();
    s.media[0].sigma_s = [2e6; 3];
    check(&mut s).unwrap();
    assert_eq!(s.warnings.len(), 1);
    assert!(s.warnings[0].message.contains("opaque within a micron"), "{:?}", s.warnings);

    // The diagonal spans (0,0,0)..(2,1,1): √6 m. σ_t = 1e-4 /m gives 2.4e-4 < 1e-3 across it.
    let mut s = scene();
    s.media[0].sigma_s = [1e-4; 3];
    check(&mut s).unwrap();
    assert!(s.warnings[0].message.contains("invisible across a thousand"), "{:?}", s.warnings);
    // 1e-3 /m gives 2.4e-3: no warning.
    let mut s = scene();
    s.media[0].sigma_s = [1e-3; 3];
    check(&mut s).unwrap();
    assert!(s.warnings.is_empty());

    // A 1 W/sr point at half the diagonal (√6/2 m) gives 2/3 W/m²; 1e6 W/sr gives 6.7e5 > 1e5.
    let mut s = scene();
    s.lights[0].radiance = [1e6, 0.0, 0.0];
    check(&mut s).unwrap();
    assert_eq!(s.warnings[0].location, "/World/Lamp");
    assert!(s.warnings[0].message.contains("6.667e5"), "{:?}", s.warnings);
    assert!(s.warnings[0].help.contains("683"));
    // 1e-5 W/sr gives 6.7e-6 < 1e-5.
    let mut s = scene();
    s.lights[0].radiance = [1e-5; 3];
    check(&mut s).unwrap();
    assert!(s.warnings[0].help.contains("far too dark"), "{:?}", s.warnings);
}

#[test]
fn exponential_fog_is_judged_at_its_densest_corner() {
    // ρ(x) = 1e-6·e^{−10·(y − 1)}: at y = 0 (the floor) the density is 1e-6·e^{10} = 0.022, so with
    // σ = 1 /m the thickness across √6 m is 0.054: no warning, although ρ' alone would give 2.4e-6.
    let mut s = scene();
    s.media[0].density =
        Density::ExponentialHeight { rho: 1e-6, falloff: 10.0, direction: [0.0, 1.0, 0.0], offset: [0.0, 1.0, 0.0] };
    check(&mut s).unwrap();
    assert!(s.warnings.is_empty(), "{:?}", s.warnings);
    let Density::ExponentialHeight { rho, .. } = &mut s.media[0].density else { unreachable!() };
    *rho = 1e-9; // now 2.2e-5 · √6 = 5.4e-5 < 1e-3
    check(&mut s).unwrap();
    assert!(s.warnings[0].message.contains("invisible"), "{:?}", s.warnings);

    s.media[0].density =
        Density::ExponentialHeight { rho: 1.0, falloff: 1.0, direction: [0.0, 0.0, 0.0], offset: [0.0; 3] };
    assert!(error_of(s).message.contains("exponential density"));
}
