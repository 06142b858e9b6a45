//! Hierarchy, transforms, winding, attributes, primitive modes and containers.

use serde_json::json;

use super::*;

fn world_f64(p: [f32; 3]) -> [f64; 3] {
    p.map(f64::from)
}

fn geometric_normal(m: &crate::scene::Mesh, t: [u32; 3]) -> glam::DVec3 {
    let [a, b, c] = t.map(|i| glam::DVec3::from(world_f64(m.positions[i as usize])));
    (b - a).cross(c - a)
}

#[test]
fn hierarchy_composes_matrix_translation_rotation_and_scale() {
    let mut d = Doc::new();
    let mesh = d.mesh(&TRIANGLE, Some(&[0, 1, 2]), json!({}));
    let child = d.node(json!({ "name": "child", "mesh": mesh, "translation": [1.0, 0.0, 0.0] }));
    let h = std::f32::consts::FRAC_1_SQRT_2;
    let parent = d.node(json!({
        "name": "parent", "children": [child],
        "translation": [1.0, 2.0, 3.0], "rotation": [0.0, h, 0.0, h], "scale": [2.0, 2.0, 2.0]
    }));
    // Column-major matrix translating by (0, 0, 10).
    let top = d.node(json!({ "name": "top", "children": [parent],
        "matrix": [1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 10.0, 1.0] }));
    d.scene(&[top]);
    let s = d.import().unwrap();
    assert_eq!(s.meshes.len(), 1);
    let m = &s.meshes[0];
    assert_eq!(m.name, "child/0");
    // By hand: q = p + (1,0,0); R_y(90°)(x,y,z) = (z, y, −x); ×2; + (1,2,3); + (0,0,10).
    // (0,0,0) → (1,0,0) → (0,0,−1) → (0,0,−2) → (1,2,1) → (1,2,11)
    // (1,0,0) → (2,0,0) → (0,0,−2) → (0,0,−4) → (1,2,−1) → (1,2,9)
    // (0,1,0) → (1,1,0) → (0,1,−1) → (0,2,−2) → (1,4,1) → (1,4,11)
    let want = [[1.0, 2.0, 11.0], [1.0, 2.0, 9.0], [1.0, 4.0, 11.0]];
    for (got, want) in m.positions.iter().zip(want) {
        assert_close3(world_f64(*got), want, 1e-5);
    }
    // The +Z face normal (computed, file has none) turns to +X under R_y(90°).
    for n in &m.normals {
        assert_close3(world_f64(*n), [1.0, 0.0, 0.0], 1e-6);
    }
    // to_world is column-major and maps the local origin to the first vertex.
    let to_world = glam::DMat4::from_cols_array_2d(&m.to_world);
    assert_close3(to_world.transform_point3(glam::DVec3::ZERO).to_array(), [1.0, 2.0, 11.0], 1e-9);
}

#[test]
fn normals_use_the_inverse_transpose_under_non_uniform_scale() {
    let s2 = std::f32::consts::FRAC_1_SQRT_2;
    // Triangle in the plane x + y = 1 with its normal (1,1,0)/√2 given per vertex.
    let pos = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 1.0, 1.0]];
    let mut d = Doc::new();
    let normals = d.vec3s(&[[s2, s2, 0.0]; 3]);
    let mesh = d.mesh(&pos, Some(&[0, 1, 2]), json!({ "attributes": { "NORMAL": normals } }));
    let n = d.node(json!({ "name": "squash", "mesh": mesh, "scale": [2.0, 1.0, 1.0] }));
    d.scene(&[n]);
    let s = d.import().unwrap();
    let m = &s.meshes[0];
    // World plane x/2 + y = 1: normal ∝ (1/2, 1, 0); A⁻ᵀ = diag(1/2, 1, 1) gives the same.
    let want = glam::DVec3::new(0.5, 1.0, 0.0).normalize().to_array();
    for n in &m.normals {
        assert_close3(world_f64(*n), want, 1e-6);
    }
    let g = geometric_normal(m, m.triangles[0]).normalize();
    assert!(g.dot(glam::DVec3::from(want)) > 0.999, "geometric {g} vs stored {want:?}");
}

#[test]
fn mirroring_transform_flips_winding_so_geometric_and_stored_normals_agree() {
    let mut d = Doc::new();
    let normals = d.vec3s(&[[0.0, 0.0, 1.0]; 3]);
    let mesh = d.mesh(&TRIANGLE, Some(&[0, 1, 2]), json!({ "attributes": { "NORMAL": normals } }));
    let mirrored = d.node(json!({ "name": "mirror", "mesh": mesh, "scale": [-1.0, 1.0, 1.0] }));
    let plain = d.node(json!({ "name": "plain", "mesh": mesh, "translation": [5.0, 0.0, 0.0] }));
    d.scene(&[mirrored, plain]);
    let s = d.import().unwrap();
    let (m, p) = (&s.meshes[0], &s.meshes[1]);
    assert_eq!((m.name.as_str(), p.name.as_str()), ("mirror/0", "plain/0"));
    assert_eq!(m.triangles, vec![[0, 2, 1]], "winding flipped under det < 0");
    assert_eq!(p.triangles, vec![[0, 1, 2]]);
    for mesh in [m, p] {
        let g = geometric_normal(mesh, mesh.triangles[0]);
        for n in &mesh.normals {
            assert!(g.dot(glam::DVec3::from(world_f64(*n))) > 0.0, "{}: geometric {g} vs stored {n:?}", mesh.name);
        }
    }
    // A mirror in x keeps a +Z normal +Z (inverse transpose of diag(−1,1,1) leaves z alone).
    assert_close3(world_f64(m.normals[0]), [0.0, 0.0, 1.0], 1e-9);
}

#[test]
fn non_indexed_primitives_get_sequential_indices_and_unnamed_nodes_their_index() {
    let mut d = Doc::new();
    let six = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [1.0, 0.0, 1.0], [0.0, 1.0, 1.0]];
    let mesh = d.mesh(&six, None, json!({}));
    let n = d.node(json!({ "mesh": mesh }));
    d.scene(&[n]);
    let s = d.import().unwrap();
    assert_eq!(s.meshes[0].name, "0/0");
    assert_eq!(s.meshes[0].triangles, vec![[0, 1, 2], [3, 4, 5]]);
}

#[test]
fn texcoords_map_to_uv_and_lightmap_uv_including_normalized_shorts() {
    let mut d = Doc::new();
    let uv0 = d.floats(&[0.0, 0.0, 1.0, 0.0, 0.0, 1.0], "VEC2");
    let shorts: Vec<u8> = [0u16, 65535, 32768, 0, 65535, 65535].iter().flat_map(|x| x.to_le_bytes()).collect();
    let view = d.view(&shorts);
    let uv1 = d.push(
        "accessors",
        json!({ "bufferView": view, "componentType": 5123, "normalized": true, "count": 3, "type": "VEC2" }),
    );
    let mesh = d.mesh(&TRIANGLE, Some(&[0, 1, 2]), json!({ "attributes": { "TEXCOORD_0": uv0, "TEXCOORD_1": uv1 } }));
    let n = d.node(json!({ "name": "uv", "mesh": mesh }));
    d.scene(&[n]);
    let s = d.import().unwrap();
    let m = &s.meshes[0];
    assert_eq!(m.uv.as_deref(), Some(&[[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]][..]));
    let lm = m.lightmap_uv.as_ref().unwrap();
    assert_eq!(lm[0], [0.0, 1.0]);
    assert!((lm[1][0] - 32768.0 / 65535.0).abs() < 1e-7 && lm[2] == [1.0, 1.0]);
}

#[test]
fn strips_and_fans_are_expanded_and_other_modes_skipped_with_a_warning() {
    let quad = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [1.0, 1.0, 0.0]];
    let mut d = Doc::new();
    let strip = d.mesh(&quad, Some(&[0, 1, 2, 3]), json!({ "mode": 5 }));
    let fan = d.mesh(&quad, Some(&[0, 1, 3, 2]), json!({ "mode": 6 }));
    let lines = d.mesh(&quad, Some(&[0, 1, 1, 3]), json!({ "mode": 1 }));
    let nodes: Vec<usize> = [("strip", strip), ("fan", fan), ("lines", lines)]
        .into_iter()
        .map(|(name, mesh)| d.node(json!({ "name": name, "mesh": mesh })))
        .collect();
    d.scene(&nodes);
    let s = d.import().unwrap();
    assert_eq!(s.meshes.len(), 2);
    // Strip: (0,1,2), then the odd triangle {v1, v3, v2}; both face +Z.
    assert_eq!(s.meshes[0].triangles, vec![[0, 1, 2], [1, 3, 2]]);
    // Fan: {v_{i+1}, v_{i+2}, v_0}.
    assert_eq!(s.meshes[1].triangles, vec![[1, 3, 0], [3, 2, 0]]);
    for m in &s.meshes {
        for t in &m.triangles {
            assert!(geometric_normal(m, *t).z > 0.0, "{}: {t:?} faces away", m.name);
        }
    }
    let w = s.warnings.iter().find(|w| w.location == "mesh \"lines/0\"").expect("warning for the LINES primitive");
    assert!(w.message.contains("LINES"), "{}", w.message);
}

#[test]
fn sparse_accessor_overrides_listed_vertices() {
    let mut d = Doc::new();
    let base = d.vec3s(&TRIANGLE);
    let idx_view = d.view(&2u32.to_le_bytes());
    let val_view = d.view(&[5.0f32, 6.0, 7.0].iter().flat_map(|x| x.to_le_bytes()).collect::<Vec<_>>());
    let base_view = d.json["accessors"][base]["bufferView"].clone();
    let pos = d.push(
        "accessors",
        json!({ "bufferView": base_view, "componentType": 5126, "count": 3, "type": "VEC3",
                "min": [0, 0, 0], "max": [5, 6, 7],
                "sparse": { "count": 1, "indices": { "bufferView": idx_view, "componentType": 5125 },
                            "values": { "bufferView": val_view } } }),
    );
    let mesh = d.push("meshes", json!({ "primitives": [{ "attributes": { "POSITION": pos } }] }));
    let n = d.node(json!({ "name": "sparse", "mesh": mesh }));
    d.scene(&[n]);
    let s = d.import().unwrap();
    assert_eq!(s.meshes[0].positions, vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [5.0, 6.0, 7.0]]);
}

#[test]
fn default_scene_is_used_and_without_scenes_every_root_node() {
    let mut d = Doc::new();
    let mesh = d.mesh(&TRIANGLE, Some(&[0, 1, 2]), json!({}));
    let a = d.node(json!({ "name": "a", "mesh": mesh }));
    let b = d.node(json!({ "name": "b", "mesh": mesh }));
    let c = d.node(json!({ "name": "c", "mesh": mesh, "children": [b] }));
    d.push("scenes", json!({ "nodes": [a] }));
    d.push("scenes", json!({ "nodes": [c] }));
    d.json["scene"] = json!(1);
    let names = |s: Scene| s.meshes.into_iter().map(|m| m.name).collect::<Vec<_>>();
    assert_eq!(names(d.import().unwrap()), ["c/0", "b/0"]);
    d.json.as_object_mut().unwrap().remove("scene");
    assert_eq!(names(d.import().unwrap()), ["a/0"], "scene 0 without a default");
    d.json.as_object_mut().unwrap().remove("scenes");
    assert_eq!(names(d.import().unwrap()), ["a/0", "c/0", "b/0"], "all root nodes without scenes");
}

#[test]
fn glb_and_external_bin_read_the_same_as_data_uris() {
    let d = one_triangle("t", json!({ "translation": [0.0, 1.0, 0.0] }), json!({}));
    let dir = tempfile::tempdir().unwrap();
    let from = |p: PathBuf| import(&p).unwrap().meshes[0].positions.clone();
    let want = from(d.write_gltf(dir.path(), "a"));
    assert_eq!(want[2], [0.0, 2.0, 0.0]);
    assert_eq!(from(d.write_glb(dir.path(), "b")), want);
    assert_eq!(from(d.write_gltf_external(dir.path(), "c")), want);
}

#[test]
fn textures_are_warned_about_and_images_never_read() {
    let mut d = one_triangle("t", json!({}), json!({ "material": 0 }));
    d.material(json!({ "name": "painted", "pbrMetallicRoughness": { "baseColorTexture": { "index": 0 },
        "baseColorFactor": [0.5, 0.25, 1.0, 1.0], "roughnessFactor": 0.3 } }));
    d.push("textures", json!({ "source": 0 }));
    // The image file does not exist: reading it would fail the import.
    d.push("images", json!({ "uri": "missing.png" }));
    let s = d.import().unwrap();
    assert_eq!(s.materials[0].base_color, [0.5, 0.25, 1.0]);
    assert!(close(s.materials[0].roughness, 0.3, 1e-7));
    assert_eq!(s.meshes[0].material, Some(0));
    let w = s.warnings.iter().find(|w| w.location == "material \"painted\"").expect("texture warning");
    assert!(w.message.contains("baseColorTexture"), "{}", w.message);
}
