//! KHR_lights_punctual, emissive meshes and cameras.

use std::f32::consts::FRAC_1_SQRT_2 as H;

use serde_json::json;

use super::*;
use crate::scene::{LightKind, Projection};

#[test]
fn punctual_lights_convert_candela_and_lux_with_683_lm_per_w() {
    let mut d = Doc::new();
    let point = d.light(json!({ "type": "point", "intensity": 683.0, "color": [1.0, 0.5, 0.25] }));
    let sun = d.light(json!({ "type": "directional", "intensity": 1366.0 }));
    let spot = d.light(json!({ "type": "spot", "intensity": 2049.0, "range": 10.0,
        "spot": { "innerConeAngle": 0.2, "outerConeAngle": 0.5 } }));
    let nodes = [
        d.node(json!({ "name": "bulb", "translation": [1.0, 2.0, 3.0],
            "extensions": { "KHR_lights_punctual": { "light": point } } })),
        // −90° about X: the node's −Z turns to −Y (straight down).
        d.node(json!({ "name": "sun", "rotation": [-H, 0.0, 0.0, H],
            "extensions": { "KHR_lights_punctual": { "light": sun } } })),
        // +90° about Y: −Z turns to −X.
        d.node(json!({ "name": "spot", "translation": [0.0, 4.0, 0.0], "rotation": [0.0, H, 0.0, H],
            "extensions": { "KHR_lights_punctual": { "light": spot } } })),
    ];
    d.scene(&nodes);
    let s = d.import().unwrap();
    assert_eq!(s.lights.len(), 3);

    let l = &s.lights[0];
    assert_eq!(l.name, "bulb");
    assert_eq!(l.kind, LightKind::Point { position: [1.0, 2.0, 3.0] });
    assert_close3(l.radiance, [1.0, 0.5, 0.25], 1e-12); // 683 cd → 1 W/sr

    let LightKind::Directional { direction, angle } = s.lights[1].kind.clone() else { panic!("{:?}", s.lights[1]) };
    assert_close3(direction, [0.0, -1.0, 0.0], 1e-7);
    assert_eq!(angle, 0.0);
    assert_close3(s.lights[1].radiance, [2.0; 3], 1e-12); // 1366 lux → 2 W/m²

    let LightKind::Spot { position, direction, inner_cone, outer_cone } = s.lights[2].kind.clone() else {
        panic!("{:?}", s.lights[2])
    };
    assert_close3(position, [0.0, 4.0, 0.0], 1e-12);
    assert_close3(direction, [-1.0, 0.0, 0.0], 1e-7);
    assert_eq!((inner_cone, outer_cone), (f64::from(0.2f32), f64::from(0.5f32)));
    assert_close3(s.lights[2].radiance, [3.0; 3], 1e-12);
    let w = s.warnings.iter().find(|w| w.location == "node \"spot\"").expect("range warning");
    assert!(w.message.contains("range") && w.message.contains("inverse-square"), "{}", w.message);
}

#[test]
fn spot_cone_defaults_are_0_and_quarter_pi() {
    let mut d = Doc::new();
    let spot = d.light(json!({ "type": "spot", "spot": {} }));
    let n = d.node(json!({ "name": "s", "extensions": { "KHR_lights_punctual": { "light": spot } } }));
    d.scene(&[n]);
    let s = d.import().unwrap();
    let LightKind::Spot { inner_cone, outer_cone, direction, .. } = s.lights[0].kind.clone() else { panic!() };
    assert_eq!((inner_cone, outer_cone), (0.0, f64::from(std::f32::consts::FRAC_PI_4)));
    assert_eq!(direction, [0.0, 0.0, -1.0]);
    assert_close3(s.lights[0].radiance, [1.0 / 683.0; 3], 1e-15);
}

#[test]
fn emissive_material_makes_its_meshes_emissive_lights_with_strength_in_nits() {
    let mut d = one_triangle("glow", json!({}), json!({ "material": 0 }));
    d.material(json!({ "name": "lamp", "emissiveFactor": [1.0, 0.5, 0.0],
        "extensions": { "KHR_materials_emissive_strength": { "emissiveStrength": 6.83 } } }));
    // A second mesh without the material stays a plain mesh.
    let plain = d.mesh(&TRIANGLE, Some(&[0, 1, 2]), json!({}));
    let n = d.node(json!({ "name": "plain", "mesh": plain }));
    d.json["scenes"][0]["nodes"] = json!([n, 0]);
    let s = d.import().unwrap();
    assert_eq!(s.meshes.iter().map(|m| m.name.as_str()).collect::<Vec<_>>(), ["plain/0", "glow/0"]);
    let want = [0.01, 0.005, 0.0]; // [1, 0.5, 0] × 6.83 nits / 683
    assert_close3(s.materials[0].emission, want, 1e-8);
    assert_eq!(s.lights.len(), 1);
    assert_eq!(s.lights[0].name, "glow/0");
    assert_eq!(s.lights[0].kind, LightKind::EmissiveMesh { mesh: 1 });
    assert_eq!(s.lights[0].radiance, s.materials[0].emission);
}

#[test]
fn emissive_factor_without_strength_is_read_as_nits() {
    let mut d = one_triangle("glow", json!({}), json!({ "material": 0 }));
    d.material(json!({ "emissiveFactor": [1.0, 1.0, 1.0] }));
    let s = d.import().unwrap();
    assert_close3(s.lights[0].radiance, [1.0 / 683.0; 3], 1e-15);
    assert_eq!(s.materials[0].name, "material 0");
}

#[test]
fn cameras_keep_projection_and_look_along_node_minus_z_with_plus_y_up() {
    let mut d = Doc::new();
    let persp = d.push(
        "cameras",
        json!({ "type": "perspective",
        "perspective": { "yfov": 0.8, "aspectRatio": 1.5, "znear": 0.1, "zfar": 100.0 } }),
    );
    let ortho = d.push(
        "cameras",
        json!({ "type": "orthographic",
        "orthographic": { "xmag": 2.0, "ymag": 1.0, "znear": 0.01, "zfar": 50.0 } }),
    );
    let inf = d.push("cameras", json!({ "type": "perspective", "perspective": { "yfov": 1.0, "znear": 0.5 } }));
    let nodes = [
        d.node(json!({ "name": "eye", "camera": persp, "translation": [0.0, 1.0, 5.0], "rotation": [0.0, H, 0.0, H] })),
        d.node(json!({ "name": "top", "camera": ortho, "rotation": [-H, 0.0, 0.0, H] })),
        d.node(json!({ "name": "far", "camera": inf })),
    ];
    d.scene(&nodes);
    let s = d.import().unwrap();
    let c = &s.cameras[0];
    assert_eq!(c.name, "eye");
    assert_eq!(c.projection, Projection::Perspective { yfov: f64::from(0.8f32), aspect: Some(1.5) });
    assert_eq!((c.znear, c.zfar), (f64::from(0.1f32), Some(100.0)));
    assert_close3(c.position, [0.0, 1.0, 5.0], 1e-12);
    assert_close3(c.forward, [-1.0, 0.0, 0.0], 1e-7);
    assert_close3(c.up, [0.0, 1.0, 0.0], 1e-7);

    let o = &s.cameras[1];
    assert_eq!(o.projection, Projection::Orthographic { xmag: 2.0, ymag: 1.0 });
    assert_eq!(o.zfar, Some(50.0));
    assert_close3(o.forward, [0.0, -1.0, 0.0], 1e-7);
    assert_close3(o.up, [0.0, 0.0, -1.0], 1e-7);

    assert_eq!(s.cameras[2].zfar, None, "no zfar: infinite projection");
    assert_eq!(s.cameras[2].projection, Projection::Perspective { yfov: 1.0, aspect: None });
}

#[test]
fn camera_up_is_orthonormalised_under_shear() {
    let mut d = Doc::new();
    let cam = d.push("cameras", json!({ "type": "perspective", "perspective": { "yfov": 1.0, "znear": 0.1 } }));
    // Column-major: +Y maps to (0, 1, 1) (sheared towards +Z), −Z stays −Z.
    let n = d.node(json!({ "name": "shear", "camera": cam,
        "matrix": [1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0] }));
    d.scene(&[n]);
    let c = &d.import().unwrap().cameras[0];
    assert_close3(c.forward, [0.0, 0.0, -1.0], 1e-12);
    assert_close3(c.up, [0.0, 1.0, 0.0], 1e-12);
}
