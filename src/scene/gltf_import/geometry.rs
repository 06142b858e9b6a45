//! One glTF mesh primitive at one node → a world-space voltab [`Mesh`].
//!
//! **Invariants.** Positions are finite and in metres, world space; every triangle index is below
//! the vertex count; normals are unit length and transformed with the inverse transpose of the
//! node's linear part; when that part mirrors (negative determinant) the winding is flipped so
//! triangles stay counter-clockwise seen from the side their normals point to.

use std::path::Path;

use glam::{DMat3, DMat4, DVec3};
use gltf::json;
use gltf::json::mesh::{Mode, Semantic};
use gltf::json::validation::Checked;

use super::accessor::Accessors;
use crate::scene::{Mesh, SceneError, SceneWarning};

/// What the importer knows about the primitive's place in the scene.
pub(super) struct Placement<'a> {
    pub file: &'a Path,
    /// Mesh name, `"<node name or index>/<primitive index>"`.
    pub name: String,
    /// Node-to-world transform.
    pub world: DMat4,
}

/// Builds the mesh, or `None` (with a warning) for primitives voltab does not import.
pub(super) fn primitive_mesh(
    at: &Placement<'_>,
    acc: &Accessors<'_>,
    prim: &json::mesh::Primitive,
    warnings: &mut Vec<SceneWarning>,
) -> Result<Option<Mesh>, SceneError> {
    let err = |message: String, help: &str| SceneError::at(at.file, format!("mesh \"{}\"", at.name), message, help);
    let mode = match prim.mode {
        Checked::Valid(m @ (Mode::Triangles | Mode::TriangleStrip | Mode::TriangleFan)) => m,
        Checked::Valid(other) => {
            warnings.push(SceneWarning {
                location: format!("mesh \"{}\"", at.name),
                message: format!("primitive mode {} skipped; voltab imports triangles only", mode_name(other)),
                help: "convert points and lines to triangles in the authoring tool if they should occlude or emit"
                    .into(),
            });
            return Ok(None);
        }
        Checked::Invalid => return Err(err("unknown primitive mode".into(), "use a glTF 2.0 mode (0-6)")),
    };
    let attribute = |s: Semantic| prim.attributes.get(&Checked::Valid(s)).map(|i| i.value());
    let Some(pos_index) = attribute(Semantic::Positions) else {
        return Err(err("the primitive has no POSITION attribute".into(), "every glTF primitive needs positions"));
    };
    let local = acc.vec3_f32(pos_index).map_err(|e| err(format!("POSITION: {e}"), "positions are VEC3 FLOAT"))?;
    if let Some((v, p)) = local.iter().enumerate().find(|(_, p)| p.iter().any(|c| !c.is_finite())) {
        return Err(err(
            format!("POSITION (accessors[{pos_index}]): vertex {v} is not finite: {p:?}"),
            "the exporter wrote NaN or infinite coordinates; fix the source mesh",
        ));
    }
    let n = local.len();
    let same_count = |semantic: &str, index: usize, count: usize| {
        if count == n {
            Ok(())
        } else {
            Err(err(
                format!("{semantic} (accessors[{index}]) has {count} elements but POSITION has {n}"),
                "all attributes of a primitive have one element per vertex",
            ))
        }
    };
    let normals = match attribute(Semantic::Normals) {
        Some(i) => {
            let v = acc.vec3_f32(i).map_err(|e| err(format!("NORMAL: {e}"), "normals are VEC3 FLOAT"))?;
            same_count("NORMAL", i, v.len())?;
            Some(v)
        }
        None => None,
    };
    let mut uvs = [None, None];
    for (set, slot) in uvs.iter_mut().enumerate() {
        if let Some(i) = attribute(Semantic::TexCoords(set as u32)) {
            let v = acc
                .vec2_texcoord(i)
                .map_err(|e| err(format!("TEXCOORD_{set}: {e}"), "texture coordinates are VEC2"))?;
            same_count(&format!("TEXCOORD_{set}"), i, v.len())?;
            *slot = Some(v);
        }
    }

    let Ok(n32) = u32::try_from(n) else {
        return Err(err(format!("{n} vertices; voltab meshes hold at most 2^32 - 1"), "split the mesh"));
    };
    let (indices, source) = match prim.indices {
        Some(i) => {
            let idx = acc
                .indices(i.value())
                .map_err(|e| err(format!("indices: {e}"), "indices are SCALAR unsigned integers"))?;
            if let Some((k, v)) = idx.iter().enumerate().find(|(_, v)| **v >= n32) {
                return Err(err(
                    format!(
                        "indices (accessors[{}]): index {v} at position {k} is out of range of the {n} vertices",
                        i.value()
                    ),
                    "the index buffer does not belong to this vertex buffer; re-export the mesh",
                ));
            }
            (idx, format!("indices (accessors[{}])", i.value()))
        }
        None => ((0..n32).collect(), format!("POSITION (accessors[{pos_index}]), non-indexed")),
    };
    let mut triangles = assemble(mode, &indices)
        .map_err(|e| err(format!("{source}: {e}"), "a TRIANGLES primitive has 3 indices per triangle"))?;

    // Transform to world space (f64), normals with the inverse transpose of the linear part.
    let linear = DMat3::from_mat4(at.world);
    let det = linear.determinant();
    let normal_matrix = linear.inverse().transpose();
    if !det.is_normal() || !normal_matrix.is_finite() {
        warnings.push(SceneWarning {
            location: format!("mesh \"{}\"", at.name),
            message: format!(
                "skipped: the node's transform is singular (determinant {det:e}), so the mesh has no area"
            ),
            help: "a zero scale hides an object; remove it from the scene if it should not be there".into(),
        });
        return Ok(None);
    }
    let world: Vec<DVec3> = local.iter().map(|p| at.world.transform_point3(DVec3::from(p.map(f64::from)))).collect();
    if let Some((v, p)) = world.iter().enumerate().find(|(_, p)| !p.as_vec3().is_finite()) {
        return Err(err(
            format!("POSITION (accessors[{pos_index}]): vertex {v} is not finite in world space: {p}"),
            "the node transforms overflow single precision",
        ));
    }
    if det < 0.0 {
        for t in &mut triangles {
            t.swap(1, 2);
        }
    }
    let face_normals = area_weighted_normals(&world, &triangles);
    let normals: Vec<[f32; 3]> = match &normals {
        Some(given) => given
            .iter()
            .zip(&face_normals)
            .map(|(nl, fallback)| {
                let nw = normal_matrix * DVec3::from(nl.map(f64::from));
                nw.try_normalize().unwrap_or(*fallback).as_vec3().to_array()
            })
            .collect(),
        None => face_normals.iter().map(|v| v.as_vec3().to_array()).collect(),
    };
    let [uv, lightmap_uv] = uvs;
    Ok(Some(Mesh {
        name: at.name.clone(),
        positions: world.iter().map(|p| p.as_vec3().to_array()).collect(),
        normals,
        uv,
        lightmap_uv,
        triangles,
        material: prim.material.map(|m| m.value()),
        medium: None,
        to_world: at.world.to_cols_array_2d(),
    }))
}

/// Triangles of a TRIANGLES, TRIANGLE_STRIP or TRIANGLE_FAN index list (glTF 2.0 §3.7.2.1).
fn assemble(mode: Mode, s: &[u32]) -> Result<Vec<[u32; 3]>, String> {
    let windows = s.len().saturating_sub(2);
    Ok(match mode {
        Mode::Triangles => {
            if !s.len().is_multiple_of(3) {
                return Err(format!("{} indices, not a multiple of 3", s.len()));
            }
            s.chunks_exact(3).map(|t| [t[0], t[1], t[2]]).collect()
        }
        // p_i = {v_i, v_{i+(1+i%2)}, v_{i+(2−i%2)}}; repeated indices (strip stitching) are dropped.
        Mode::TriangleStrip => (0..windows)
            .map(|i| if i % 2 == 0 { [s[i], s[i + 1], s[i + 2]] } else { [s[i], s[i + 2], s[i + 1]] })
            .filter(|t| t[0] != t[1] && t[1] != t[2] && t[0] != t[2])
            .collect(),
        // p_i = {v_{i+1}, v_{i+2}, v_0}.
        Mode::TriangleFan => (0..windows).map(|i| [s[i + 1], s[i + 2], s[0]]).collect(),
        _ => Vec::new(),
    })
}

/// Unit vertex normals: the sum of adjacent face normals weighted by face area (+Y where no
/// triangle with area touches the vertex).
fn area_weighted_normals(p: &[DVec3], triangles: &[[u32; 3]]) -> Vec<DVec3> {
    let mut sum = vec![DVec3::ZERO; p.len()];
    for t in triangles {
        let [a, b, c] = t.map(|i| i as usize);
        // |cross| = 2 × area, so the unnormalised cross product is already area-weighted.
        let n = (p[b] - p[a]).cross(p[c] - p[a]);
        for v in [a, b, c] {
            sum[v] += n;
        }
    }
    sum.into_iter().map(|n| n.try_normalize().unwrap_or(DVec3::Y)).collect()
}

fn mode_name(mode: Mode) -> &'static str {
    match mode {
        Mode::Points => "POINTS",
        Mode::Lines => "LINES",
        Mode::LineLoop => "LINE_LOOP",
        Mode::LineStrip => "LINE_STRIP",
        Mode::Triangles => "TRIANGLES",
        Mode::TriangleStrip => "TRIANGLE_STRIP",
        Mode::TriangleFan => "TRIANGLE_FAN",
    }
}
