//! The export of hand-built scenes: what the XML says, which files are written, the manifest.

use super::build::spot_falloff_difference;
use super::*;
use crate::scene::{Density, Light, LightKind, Surface, fixtures};

fn xml_of(scene: &Scene) -> (String, Built) {
    let b = build(scene, &ExportOptions::default()).expect("builds");
    (b.xml.document(), b)
}

#[test]
fn fog_room_global_medium_box_floor_and_lights() {
    let scene = fixtures::fog_room();
    let (xml, b) = xml_of(&scene);
    let g = b.manifest.global_medium.as_ref().expect("global region");
    // Bounds: floor [0,4]×[−0.1,0]×[0,4], lamp up to y 3, bulb inside: diagonal √(16+9.61+16).
    let pad = 0.01 * (16.0f64 + 3.1 * 3.1 + 16.0).sqrt() + 1e-3;
    assert!((g.min[1] - (-0.1 - pad)).abs() < 1e-6 && (g.max[1] - (3.0 + pad)).abs() < 1e-6, "{g:?}");
    assert!(xml.contains("<shape type=\"cube\" id=\"global_medium_box\">"), "{xml}");
    assert!(xml.contains("<ref name=\"interior\" id=\"medium_0\"/>"));
    assert!(xml.contains("<medium id=\"medium_0\" type=\"homogeneous\">"));
    // σ_t = 0.11 as rgb 1 × scale 0.11 (Mitsuba's rgb must be ≤ 1), albedo 0.1/0.11.
    assert!(xml.contains("<rgb name=\"sigma_t\" value=\"1.0, 1.0, 1.0\"/>"));
    assert!(xml.contains(&format!("<float name=\"scale\" value=\"{}\"/>", xml::num(0.1 + 0.01))));
    assert!(xml.contains(&format!("<rgb name=\"albedo\" value=\"{0}, {0}, {0}\"/>", xml::num(0.1 / 0.11))));
    assert!(xml.contains("<point name=\"position\" x=\"2.0\" y=\"2.0\" z=\"2.0\"/>"));
    assert!(xml.contains("<rgb name=\"intensity\" value=\"1.0, 1.0, 1.0\"/>"));
    // The lamp mesh carries the emitter; the floor is two-sided diffuse 0.8.
    let lamp = b.manifest.shapes.iter().find(|s| s.name == "/Room/Lamp").unwrap();
    assert_eq!(lamp.emission, Some([5.0; 3]));
    assert!(xml.contains("<rgb name=\"reflectance\" value=\"0.8, 0.8, 0.8\"/>"));
    assert_eq!(b.files.iter().filter(|(f, _)| f.ends_with(".ply")).count(), 2);
}

#[test]
fn translucent_body_is_a_dielectric_holding_its_medium() {
    let (xml, b) = xml_of(&fixtures::translucent());
    let body = b.manifest.shapes.iter().find(|s| s.name == "Body").unwrap();
    assert_eq!(
        (body.bsdf.as_str(), body.interior.as_deref(), body.exterior.as_deref()),
        ("dielectric", Some("medium_0"), None)
    );
    assert!(xml.contains("<float name=\"int_ior\" value=\"1.5\"/>"));
    assert!(!body.flipped);
    assert!(b.manifest.global_medium.is_none());
}

#[test]
fn inward_medium_boundary_is_flipped_and_index_matched() {
    let mut s = fixtures::translucent();
    s.materials[0].surface = Surface::Dielectric { ior: 1.0 };
    for t in &mut s.meshes[0].triangles {
        t.swap(1, 2);
    }
    let (_, b) = xml_of(&s);
    let body = b.manifest.shapes.iter().find(|s| s.name == "Body").unwrap();
    assert!(body.flipped && body.bsdf == "null");
    assert!(b.manifest.warnings.iter().any(|w| w.location == "Body" && w.message.contains("inward")));
}

#[test]
fn height_fog_grid_resolves_the_falloff_and_samples_cell_centres() {
    let mut s = fixtures::fog_room();
    s.media[0].density =
        Density::ExponentialHeight { rho: 2.0, falloff: 1.5, direction: [0.0, 1.0, 0.0], offset: [0.0; 3] };
    let (xml, b) = xml_of(&s);
    let m = &b.manifest.media[0];
    assert_eq!(m.mitsuba_type, "heterogeneous");
    let grid = m.grid.as_ref().unwrap();
    assert_eq!((grid.resolution[0], grid.resolution[2]), (2, 2));
    let h = grid.max[1] - grid.min[1];
    assert_eq!(grid.resolution[1], (1.5 * h / GRID_TOLERANCE).ceil() as usize);
    assert!(grid.max_relative_interpolation_error <= GRID_TOLERANCE.powi(2) / 8.0 + 1e-12);
    assert!(xml.contains("<string name=\"filename\" value=\"volumes/medium_0.vol\"/>"));
    let (_, bytes) = b.files.iter().find(|(f, _)| f == "volumes/medium_0.vol").unwrap();
    // First cell (x 0, y 0, z 0), red: σ_t · 2 e^{−1.5 y_centre}.
    let y0 = grid.min[1] + 0.5 * h / grid.resolution[1] as f64;
    let v = f32::from_le_bytes(bytes[48..52].try_into().unwrap());
    let want = 0.11 * 2.0 * (-1.5 * y0).exp();
    assert!((f64::from(v) - want).abs() < 1e-6 * want, "{v} vs {want}");
}

#[test]
fn spot_falloff_difference_is_zero_for_a_hard_cone_and_named_otherwise() {
    // Independent dense scan of |KHR t² in cosine − Mitsuba linear in angle| for inner 0.2, outer 0.6.
    let (ci, co) = (0.2f64.cos(), 0.6f64.cos());
    let want = (0..=100_000)
        .map(|k| 0.2 + 0.4 * f64::from(k) / 1e5)
        .map(|th: f64| (((th.cos() - co) / (ci - co)).powi(2) - (0.6 - th) / 0.4).abs())
        .fold(0.0, f64::max);
    let d = spot_falloff_difference(0.2, 0.6);
    assert!((d - want).abs() < 1e-3 && d > 0.05, "{d} vs {want}");
    // voltab's hard cone keeps KHR's 10⁻³ cosine ramp, Mitsuba's is a step: the difference is bounded by 1.
    assert!(spot_falloff_difference(0.5, 0.5) <= 1.0);
    let mut s = fixtures::fog_room();
    s.lights.push(Light {
        name: "Spot".into(),
        kind: LightKind::Spot { position: [1.0; 3], direction: [0.0, -1.0, 0.0], inner_cone: 0.2, outer_cone: 0.6 },
        radiance: [3.0; 3],
    });
    let (xml, b) = xml_of(&s);
    assert!(xml.contains("<emitter type=\"spot\">"));
    assert!(b.manifest.warnings.iter().any(|w| w.location == "Spot" && w.message.contains("falloff")));
}

#[test]
fn unknown_camera_names_the_available_ones() {
    let s = fixtures::fog_room();
    let e = build(&s, &ExportOptions { camera: Some("Cam".into()), ..ExportOptions::default() }).unwrap_err();
    assert_eq!(e.to_string(), "fog_room.usda: no camera named \"Cam\"\n  help: the scene's cameras are: (none)");
}

#[test]
fn export_writes_every_file_and_the_manifest_last() {
    let dir = tempfile::tempdir().unwrap();
    let m = export(&fixtures::fog_room(), &ExportOptions::default(), dir.path()).unwrap();
    for f in ["scene.xml", "export.json", "meshes/mesh_0.ply", "meshes/mesh_1.ply"] {
        assert!(dir.path().join(f).is_file(), "{f}");
    }
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.path().join("export.json")).unwrap()).unwrap();
    assert_eq!(json["global_medium"]["id"], "medium_0");
    assert_eq!(m.shapes.len(), 3);
    let leftovers: Vec<_> = std::fs::read_dir(dir.path())
        .unwrap()
        .filter_map(|e| e.ok())
        .filter(|e| e.file_name().to_string_lossy().starts_with(".tmp"))
        .collect();
    assert!(leftovers.is_empty());
}
