//! glTF importer tests: small documents built here (base64 data-URI, external `.bin` or `.glb`
//! buffers assembled from f32/u32 bytes), written to a temporary folder and imported.

mod errors;
mod geometry;
mod hostile;
mod lights_cameras;
mod media;

use std::path::{Path, PathBuf};

use serde_json::{Value, json};

use super::import;
use crate::scene::{Scene, SceneError};

/// A glTF document under construction with one binary buffer.
pub(super) struct Doc {
    pub json: Value,
    pub bin: Vec<u8>,
}

/// One triangle in the z = 0 plane, counter-clockwise seen from +Z.
pub(super) const TRIANGLE: [[f32; 3]; 3] = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]];

/// A closed tetrahedron (outward winding), for media boundaries.
pub(super) const TETRA: ([[f32; 3]; 4], [u32; 12]) =
    ([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]], [0, 2, 1, 0, 1, 3, 0, 3, 2, 1, 2, 3]);

impl Doc {
    pub fn new() -> Doc {
        Doc { json: json!({ "asset": { "version": "2.0" } }), bin: Vec::new() }
    }

    /// Appends `value` to the top-level array `key`; returns its index.
    pub fn push(&mut self, key: &str, value: Value) -> usize {
        let arr = self.json.as_object_mut().unwrap().entry(key).or_insert_with(|| json!([]));
        let arr = arr.as_array_mut().unwrap();
        arr.push(value);
        arr.len() - 1
    }

    /// A buffer view over `bytes` (4-byte aligned in the buffer).
    pub fn view(&mut self, bytes: &[u8]) -> usize {
        while !self.bin.len().is_multiple_of(4) {
            self.bin.push(0);
        }
        let offset = self.bin.len();
        self.bin.extend_from_slice(bytes);
        self.push("bufferViews", json!({ "buffer": 0, "byteOffset": offset, "byteLength": bytes.len() }))
    }

    /// A float accessor of type `ty` (`"VEC3"`, `"VEC2"`, …); VEC3 ones get min/max.
    pub fn floats(&mut self, data: &[f32], ty: &str) -> usize {
        let n = match ty {
            "SCALAR" => 1,
            "VEC2" => 2,
            "VEC3" => 3,
            _ => 4,
        };
        let bytes: Vec<u8> = data.iter().flat_map(|x| x.to_le_bytes()).collect();
        let view = self.view(&bytes);
        let mut acc = json!({ "bufferView": view, "componentType": 5126, "count": data.len() / n, "type": ty });
        if n == 3 {
            let lo: Vec<f32> =
                (0..3).map(|c| data.iter().skip(c).step_by(3).fold(f32::INFINITY, |a, b| a.min(*b))).collect();
            let hi: Vec<f32> =
                (0..3).map(|c| data.iter().skip(c).step_by(3).fold(f32::NEG_INFINITY, |a, b| a.max(*b))).collect();
            // JSON has no NaN/Inf: fall back to 0 for test data that holds them.
            let fin = |v: Vec<f32>| v.into_iter().map(|x| if x.is_finite() { x } else { 0.0 }).collect::<Vec<_>>();
            acc["min"] = json!(fin(lo));
            acc["max"] = json!(fin(hi));
        }
        self.push("accessors", acc)
    }

    pub fn vec3s(&mut self, data: &[[f32; 3]]) -> usize {
        self.floats(&data.concat(), "VEC3")
    }

    /// A SCALAR UNSIGNED_INT accessor.
    pub fn u32s(&mut self, data: &[u32]) -> usize {
        let bytes: Vec<u8> = data.iter().flat_map(|x| x.to_le_bytes()).collect();
        let view = self.view(&bytes);
        self.push(
            "accessors",
            json!({ "bufferView": view, "componentType": 5125, "count": data.len(), "type": "SCALAR" }),
        )
    }

    /// A mesh with one primitive; `extra` is merged into the primitive (attributes merge too).
    pub fn mesh(&mut self, positions: &[[f32; 3]], indices: Option<&[u32]>, extra: Value) -> usize {
        let pos = self.vec3s(positions);
        let mut prim = json!({ "attributes": { "POSITION": pos } });
        if let Some(idx) = indices {
            prim["indices"] = json!(self.u32s(idx));
        }
        merge(&mut prim, extra);
        self.push("meshes", json!({ "primitives": [prim] }))
    }

    pub fn node(&mut self, node: Value) -> usize {
        self.push("nodes", node)
    }

    pub fn material(&mut self, m: Value) -> usize {
        self.push("materials", m)
    }

    /// A scene with these root nodes, made the default.
    pub fn scene(&mut self, roots: &[usize]) -> usize {
        let s = self.push("scenes", json!({ "nodes": roots }));
        self.json["scene"] = json!(s);
        s
    }

    /// Adds a `KHR_lights_punctual` light; returns its index.
    pub fn light(&mut self, light: Value) -> usize {
        let ext = self.json.as_object_mut().unwrap().entry("extensions").or_insert_with(|| json!({}));
        let lights =
            ext.as_object_mut().unwrap().entry("KHR_lights_punctual").or_insert_with(|| json!({ "lights": [] }));
        let arr = lights["lights"].as_array_mut().unwrap();
        arr.push(light);
        arr.len() - 1
    }

    /// The JSON with buffer 0 pointing at `uri` (`None`: the GLB BIN chunk).
    fn json_with_buffer(&self, uri: Option<String>) -> Value {
        let mut j = self.json.clone();
        if !self.bin.is_empty() {
            let mut b = json!({ "byteLength": self.bin.len() });
            if let Some(uri) = uri {
                b["uri"] = json!(uri);
            }
            j["buffers"] = json!([b]);
        }
        j
    }

    /// `name.gltf` with the buffer as a base64 data URI.
    pub fn write_gltf(&self, dir: &Path, name: &str) -> PathBuf {
        let uri = format!("data:application/octet-stream;base64,{}", base64(&self.bin));
        let path = dir.join(format!("{name}.gltf"));
        std::fs::write(&path, serde_json::to_string_pretty(&self.json_with_buffer(Some(uri))).unwrap()).unwrap();
        path
    }

    /// `name.gltf` plus `name data.bin` (a space, to exercise percent-decoding of the URI).
    pub fn write_gltf_external(&self, dir: &Path, name: &str) -> PathBuf {
        std::fs::write(dir.join(format!("{name} data.bin")), &self.bin).unwrap();
        let path = dir.join(format!("{name}.gltf"));
        let j = self.json_with_buffer(Some(format!("{name}%20data.bin")));
        std::fs::write(&path, serde_json::to_string_pretty(&j).unwrap()).unwrap();
        path
    }

    /// `name.glb`: header, JSON chunk (space padded), BIN chunk (zero padded).
    pub fn write_glb(&self, dir: &Path, name: &str) -> PathBuf {
        let path = dir.join(format!("{name}.glb"));
        std::fs::write(&path, self.glb_bytes()).unwrap();
        path
    }

    pub fn glb_bytes(&self) -> Vec<u8> {
        let mut json = serde_json::to_vec(&self.json_with_buffer(None)).unwrap();
        while !json.len().is_multiple_of(4) {
            json.push(b' ');
        }
        let mut bin = self.bin.clone();
        while !bin.len().is_multiple_of(4) {
            bin.push(0);
        }
        let total = 12 + 8 + json.len() + if bin.is_empty() { 0 } else { 8 + bin.len() };
        let mut out = Vec::new();
        out.extend_from_slice(b"glTF");
        out.extend_from_slice(&2u32.to_le_bytes());
        out.extend_from_slice(&(total as u32).to_le_bytes());
        out.extend_from_slice(&(json.len() as u32).to_le_bytes());
        out.extend_from_slice(b"JSON");
        out.extend_from_slice(&json);
        if !bin.is_empty() {
            out.extend_from_slice(&(bin.len() as u32).to_le_bytes());
            out.extend_from_slice(b"BIN\0");
            out.extend_from_slice(&bin);
        }
        out
    }

    /// Writes the document as `.gltf` into a fresh temporary folder and imports it.
    pub fn import(&self) -> Result<Scene, SceneError> {
        let dir = tempfile::tempdir().unwrap();
        import(&self.write_gltf(dir.path(), "scene"))
    }
}

/// Recursively merges object `b` into `a`.
pub(super) fn merge(a: &mut Value, b: Value) {
    match (a, b) {
        (Value::Object(a), Value::Object(b)) => {
            for (k, v) in b {
                merge(a.entry(k).or_insert(Value::Null), v);
            }
        }
        (a, b) => *a = b,
    }
}

/// Standard base64 with padding.
pub(super) fn base64(bytes: &[u8]) -> String {
    const A: &[u8; 64] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    let mut s = String::new();
    for c in bytes.chunks(3) {
        let n =
            (u32::from(c[0]) << 16) | (u32::from(*c.get(1).unwrap_or(&0)) << 8) | u32::from(*c.get(2).unwrap_or(&0));
        for k in 0..4 {
            if k <= c.len() {
                s.push(A[(n >> (18 - 6 * k) & 63) as usize] as char);
            } else {
                s.push('=');
            }
        }
    }
    s
}

/// A document with one node `name` carrying a one-triangle mesh with `prim_extra`.
pub(super) fn one_triangle(name: &str, node_extra: Value, prim_extra: Value) -> Doc {
    let mut d = Doc::new();
    let mesh = d.mesh(&TRIANGLE, Some(&[0, 1, 2]), prim_extra);
    let mut node = json!({ "name": name, "mesh": mesh });
    merge(&mut node, node_extra);
    let n = d.node(node);
    d.scene(&[n]);
    d
}

pub(super) fn close(a: f64, b: f64, tol: f64) -> bool {
    (a - b).abs() <= tol
}

pub(super) fn assert_close3(got: [f64; 3], want: [f64; 3], tol: f64) {
    assert!((0..3).all(|c| close(got[c], want[c], tol)), "got {got:?}, want {want:?}");
}

/// Rendered error text (location and message), for assertions on what it names.
pub(super) fn error_text(r: Result<Scene, SceneError>) -> String {
    match r {
        Ok(s) => panic!("expected an error, imported {} meshes", s.meshes.len()),
        Err(e) => e.to_string(),
    }
}

#[test]
fn committed_vendor_schema_matches_the_code() {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("schemas/VOLTAB_participating_media.schema.json");
    let want = format!("{}\n", serde_json::to_string_pretty(&super::vendor_schema()).unwrap());
    if std::env::var_os("VOLTAB_BLESS").is_some() {
        std::fs::write(&path, &want).unwrap();
    }
    assert!(
        std::fs::read_to_string(&path).ok().as_deref() == Some(want.as_str()),
        "schemas/VOLTAB_participating_media.schema.json is out of date: regenerate it with\n  VOLTAB_BLESS=1 cargo test --lib committed_vendor_schema"
    );
}

#[test]
fn vendor_schema_describes_both_levels_and_refuses_unknown_fields() {
    let s = super::vendor_schema();
    assert_eq!(s["$schema"], "https://json-schema.org/draft/2020-12/schema");
    let defs = &s["$defs"];
    for (def, fields) in [
        ("MaterialMedium", &["scatteringAlbedo", "anisotropy", "density"][..]),
        ("RootMedia", &["global"][..]),
        ("GlobalMedium", &["sigmaS", "sigmaA", "anisotropy", "density"][..]),
        ("DensitySpec", &["type", "rho", "falloff", "direction", "offset"][..]),
    ] {
        assert_eq!(defs[def]["additionalProperties"], false, "{def}");
        for f in fields {
            let p = &defs[def]["properties"][f];
            assert!(p.is_object(), "{def}.{f} missing");
            assert!(p.get("description").is_some() || p.get("$ref").is_some(), "{def}.{f} lacks a description: {p}");
        }
    }
    assert_eq!(defs["GlobalMedium"]["properties"]["sigmaS"]["x-unit"], "1/m");
    assert_eq!(defs["DensitySpec"]["properties"]["falloff"]["x-unit"], "1/m");
    assert_eq!(defs["DensitySpec"]["properties"]["offset"]["x-unit"], "m");
    assert_eq!(s["anyOf"].as_array().map(Vec::len), Some(2));
}
