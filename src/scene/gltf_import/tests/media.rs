//! KHR_materials_volume (+ _scatter draft) and VOLTAB_participating_media.

use serde_json::{Value, json};

use super::*;
use crate::scene::{Boundary, Density, Surface};

/// A tetrahedron node `name` using material 0 = a transmissive volume with `extensions` added.
fn volume_doc(name: &str, node_extra: Value, extensions: Value) -> Doc {
    let mut d = Doc::new();
    let mesh = d.mesh(&TETRA.0, Some(&TETRA.1), json!({ "material": 0 }));
    let mut node = json!({ "name": name, "mesh": mesh });
    merge(&mut node, node_extra);
    let n = d.node(node);
    d.scene(&[n]);
    let mut ext = json!({
        "KHR_materials_transmission": { "transmissionFactor": 1.0 },
        "KHR_materials_ior": { "ior": 1.0 },
        "KHR_materials_volume": { "attenuationColor": [0.5, 0.25, 1.0], "attenuationDistance": 2.0 }
    });
    merge(&mut ext, extensions);
    d.material(json!({ "name": "fog", "extensions": ext }));
    d
}

const LN2: f64 = std::f64::consts::LN_2;

#[test]
fn attenuation_gives_sigma_t_minus_ln_c_over_d_as_pure_absorption() {
    let s = volume_doc("box", json!({}), json!({})).import().unwrap();
    assert_eq!(s.materials[0].surface, Surface::Dielectric { ior: 1.0 });
    assert_eq!(s.media.len(), 1);
    let m = &s.media[0];
    assert_eq!(m.name, "fog");
    assert_eq!(m.boundary, Boundary::Mesh(0));
    assert_eq!(s.meshes[0].medium, Some(0));
    // σ_t = −ln(c)/d: −ln(0.5)/2, −ln(0.25)/2, −ln(1)/2.
    assert_close3(m.sigma_a, [LN2 / 2.0, LN2, 0.0], 1e-12);
    assert_eq!(m.sigma_s, [0.0; 3]);
    assert_eq!(m.g, [0.0; 3]);
    assert_eq!(m.density, Density::Homogeneous);
}

#[test]
fn infinite_attenuation_distance_means_no_extinction_and_default_ior_is_1_5() {
    let mut d = volume_doc("box", json!({}), json!({}));
    // Absent properties take their defaults (attenuationDistance +∞, ior 1.5).
    let ext = d.json["materials"][0]["extensions"].as_object_mut().unwrap();
    ext.remove("KHR_materials_ior");
    ext["KHR_materials_volume"].as_object_mut().unwrap().remove("attenuationDistance");
    let s = d.import().unwrap();
    assert_eq!(s.materials[0].surface, Surface::Dielectric { ior: 1.5 });
    assert_eq!(s.media[0].sigma_t(), [0.0; 3]);
}

#[test]
fn volume_scatter_inverts_the_multiscatter_albedo() {
    let d = volume_doc(
        "box",
        json!({}),
        json!({
            "KHR_materials_volume": { "attenuationColor": [0.5, 0.5, 0.5] },
            "KHR_materials_volume_scatter": { "multiscatterColor": [0.0, 1.0, 0.5], "scatterAnisotropy": 0.3 }
        }),
    );
    let s = d.import().unwrap();
    let m = &s.media[0];
    let alpha = m.albedo();
    // A = 0: s = 4.09712 − √9.59217 = 0.999997, α = 1 − s² ≈ 6e-6 ≈ 0.
    assert!(close(alpha[0], 0.0, 1e-5), "{alpha:?}");
    // A = 1: s = 8.30575 − √68.98557 ≈ −5e-6, α ≈ 1.
    assert!(close(alpha[1], 1.0, 1e-9), "{alpha:?}");
    // A = 0.5 by hand: s = 6.201435 − √34.86072 = 6.201435 − 5.9042966 = 0.2971384, α = 1 − 0.0882912 = 0.9117088.
    assert!(close(alpha[2], 0.911_708_8, 1e-6), "{alpha:?}");
    assert_close3(m.sigma_t(), [LN2 / 2.0; 3], 1e-12);
    assert!(close(m.sigma_s[2], 0.911_708_8 * LN2 / 2.0, 1e-6));
    assert_close3(m.g, [0.3; 3], 1e-12);
}

#[test]
fn vendor_extension_sets_albedo_anisotropy_and_density_in_the_node_frame() {
    let d = volume_doc(
        "box",
        json!({ "translation": [0.0, 3.0, 0.0], "scale": [2.0, 2.0, 2.0] }),
        json!({ "VOLTAB_participating_media": {
            "scatteringAlbedo": [0.9, 0.8, 0.7], "anisotropy": [0.1, 0.2, 0.3],
            "density": { "type": "exponentialHeight", "rho": 2.0, "falloff": 0.5, "direction": [0.0, 2.0, 0.0], "offset": [0.0, 1.0, 0.0] }
        } }),
    );
    let s = d.import().unwrap();
    let m = &s.media[0];
    let st = [LN2 / 2.0, LN2, 0.0];
    assert_close3(m.sigma_s, [0.9 * st[0], 0.8 * st[1], 0.0], 1e-12);
    assert_close3(m.sigma_a, [0.1 * st[0], 0.2 * st[1], 0.0], 1e-12);
    assert_eq!(m.g, [0.1, 0.2, 0.3]);
    // Node M = T(0,3,0)·S(2): offset → M·(0,1,0) = (0,5,0); direction → A⁻ᵀ(0,1,0) = (0,½,0), so the
    // falloff per world metre halves (0.5 → 0.25): ρ is the same at the same material point.
    let Density::ExponentialHeight { rho, falloff, direction, offset } = m.density.clone() else { panic!() };
    assert_eq!(rho, 2.0);
    assert!(close(falloff, 0.25, 1e-12), "{falloff}");
    assert_close3(direction, [0.0, 1.0, 0.0], 1e-12);
    assert_close3(offset, [0.0, 5.0, 0.0], 1e-12);
}

#[test]
fn vendor_extension_overrides_volume_scatter_field_by_field() {
    let d = volume_doc(
        "box",
        json!({}),
        json!({
            "KHR_materials_volume_scatter": { "multiscatterColor": [1.0, 1.0, 1.0], "scatterAnisotropy": 0.3 },
            "VOLTAB_participating_media": { "anisotropy": -0.5 }
        }),
    );
    let m = &d.import().unwrap().media[0];
    assert_eq!(m.g, [-0.5; 3], "anisotropy from the vendor extension");
    assert!(m.albedo().iter().take(2).all(|a| close(*a, 1.0, 1e-9)), "albedo from volume_scatter: {:?}", m.albedo());
}

#[test]
fn global_medium_comes_from_the_root_extension() {
    let mut d = one_triangle("floor", json!({}), json!({}));
    d.json["extensions"] = json!({ "VOLTAB_participating_media": { "global": {
        "sigmaS": [0.1, 0.2, 0.3], "sigmaA": [0.01, 0.02, 0.03], "anisotropy": 0.7,
        "density": { "type": "exponentialHeight", "rho": 1.5, "falloff": 0.1, "direction": [0.0, 0.0, 3.0] }
    } } });
    let s = d.import().unwrap();
    assert_eq!(s.media.len(), 1);
    let g = &s.media[0];
    assert_eq!(g.boundary, Boundary::Global);
    assert_eq!((g.sigma_s, g.sigma_a, g.g), ([0.1, 0.2, 0.3], [0.01, 0.02, 0.03], [0.7; 3]));
    assert_eq!(
        g.density,
        Density::ExponentialHeight { rho: 1.5, falloff: 0.1, direction: [0.0, 0.0, 1.0], offset: [0.0; 3] }
    );
}

#[test]
fn volume_on_an_opaque_material_is_ignored_with_a_warning() {
    let mut d = volume_doc("box", json!({}), json!({}));
    d.json["materials"][0]["extensions"].as_object_mut().unwrap().remove("KHR_materials_transmission");
    let s = d.import().unwrap();
    assert!(s.media.is_empty() && s.meshes[0].medium.is_none());
    assert_eq!(s.materials[0].surface, Surface::Opaque);
    assert!(s.warnings.iter().any(|w| w.location == "material \"fog\"" && w.message.contains("not transmissive")));
}

#[test]
fn volume_required_is_accepted_and_moved_to_used() {
    // Regression: the gltf crate rejects KHR_materials_volume in extensionsRequired.
    let mut d = volume_doc("box", json!({}), json!({}));
    let all = [
        "KHR_materials_volume",
        "KHR_materials_transmission",
        "KHR_materials_ior",
        "KHR_materials_volume_scatter",
        "VOLTAB_participating_media",
    ];
    d.json["extensionsRequired"] = json!(all);
    d.json["extensionsUsed"] = json!(["KHR_materials_transmission"]);
    let s = d.import().unwrap();
    assert_eq!(s.media.len(), 1);
    let dir = tempfile::tempdir().unwrap();
    assert_eq!(import(&d.write_glb(dir.path(), "v")).unwrap().media.len(), 1, "same through a .glb");
}

#[test]
fn vendor_extension_errors_name_the_material_and_the_field() {
    let cases = [
        (json!({ "scatteringAlbdo": [0.5, 0.5, 0.5] }), "scatteringAlbdo", "unknown field"),
        (json!({ "anisotropy": "high" }), "`anisotropy`", "a number or an array of 3 numbers"),
        (json!({ "scatteringAlbedo": [0.5, 0.5] }), "`scatteringAlbedo`", "invalid length"),
        (json!({ "scatteringAlbedo": [0.5, 0.5, 1.5] }), "`scatteringAlbedo`", "outside [0, 1]"),
        (
            json!({ "density": { "type": "exponentialHeight", "rho": 1.0, "falloff": "fast" } }),
            "`density.falloff`",
            "invalid type",
        ),
        (json!({ "density": { "type": "linear", "rho": 1.0, "falloff": 1.0 } }), "`density.type`", "unknown variant"),
        (json!({ "density": { "type": "exponentialHeight", "falloff": 1.0 } }), "`density`", "missing field `rho`"),
        (
            json!({ "density": { "type": "exponentialHeight", "rho": 1.0, "falloff": 1.0, "direction": [0, 0, 0] } }),
            "`density.direction`",
            "not a direction",
        ),
    ];
    for (ext, field, what) in cases {
        let d = volume_doc("box", json!({}), json!({ "VOLTAB_participating_media": ext }));
        let e = error_text(d.import());
        assert!(e.contains("material \"fog\"") && e.contains(field) && e.contains(what), "{e}");
    }
}

#[test]
fn root_vendor_extension_errors_name_root_extensions_and_the_field() {
    for (ext, field) in [
        (json!({ "global": { "sigmaT": [1.0, 1.0, 1.0] } }), "`global.sigmaT`"),
        (json!({ "global": { "sigmaS": "thick" } }), "`global.sigmaS`"),
        (
            json!({ "global": { "density": { "type": "exponentialHeight", "rho": -1.0, "falloff": 1.0 } } }),
            "`global.density.rho`",
        ),
        (json!({ "globals": {} }), "`globals`"),
        (json!([1, 2]), "expected an object"),
    ] {
        let mut d = one_triangle("floor", json!({}), json!({}));
        d.json["extensions"] = json!({ "VOLTAB_participating_media": ext });
        let e = error_text(d.import());
        assert!(e.contains("root extensions") && e.contains("VOLTAB_participating_media") && e.contains(field), "{e}");
    }
}

#[test]
fn volume_scatter_errors_name_the_field_and_the_old_draft_name_is_read_with_a_warning() {
    let d = volume_doc("box", json!({}), json!({ "KHR_materials_volume_scatter": { "multiscatterColor": "red" } }));
    let e = error_text(d.import());
    assert!(
        e.contains("material \"fog\"") && e.contains("KHR_materials_volume_scatter: field `multiscatterColor`"),
        "{e}"
    );

    let d =
        volume_doc("box", json!({}), json!({ "KHR_materials_volume_scatter": { "scatterAlbedo": [1.0, 1.0, 1.0] } }));
    let s = d.import().unwrap();
    assert!(close(s.media[0].albedo()[0], 1.0, 1e-9));
    assert!(s.warnings.iter().any(|w| w.message.contains("scatterAlbedo")));
}
