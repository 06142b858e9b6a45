//! `UsdGeomMesh` → [`Mesh`]: topology checks, fan triangulation, primvars expanded to one value per
//! output vertex (faceVarying and uniform data split vertices), world-space positions and normals.

use glam::{DMat4, DVec3};
use openusd::sdf;

use super::Importer;
use super::values::{Interp, Primvar, int_array, vec2_array, vec3_array};
use super::xform::normal_matrix;
use crate::scene::{Mesh, SceneError};

/// Per-output-vertex source of an attribute.
enum Src<const N: usize> {
    /// One value per point.
    PerPoint(Vec<[f32; N]>),
    /// One value per face-vertex (corner).
    PerCorner(Vec<[f32; N]>),
}

impl<const N: usize> Src<N> {
    fn get(&self, point: usize, corner: usize) -> [f32; N] {
        match self {
            Src::PerPoint(v) => v[point],
            Src::PerCorner(v) => v[corner],
        }
    }

    fn per_corner(&self) -> bool {
        matches!(self, Src::PerCorner(_))
    }
}

/// Face topology after validation.
pub(super) struct Topology {
    /// Number of points.
    pub n_points: usize,
    /// faceVertexIndices (validated: in range).
    pub indices: Vec<u32>,
    /// faceVertexCounts (validated: each >= 3, summing to `indices.len()`).
    pub counts: Vec<u32>,
    /// Triangles over corner (face-vertex) ids, hole faces skipped, final winding.
    pub triangles: Vec<[u32; 3]>,
}

/// Validates the topology and fan-triangulates every face that is not a hole (`flip` reverses the
/// winding). Errors are messages with help, for the caller to attach the prim.
pub(super) fn triangulate(
    counts: &[i64],
    indices: &[i64],
    n_points: usize,
    holes: &[i64],
    flip: bool,
) -> Result<Topology, (String, String)> {
    let total: i128 = counts.iter().map(|&c| i128::from(c)).sum();
    if total != indices.len() as i128 {
        return Err((
            format!("faceVertexCounts sum to {total} but faceVertexIndices has {} entries", indices.len()),
            "the counts must sum to the number of face-vertex indices".into(),
        ));
    }
    if let Some((f, c)) = counts.iter().enumerate().find(|&(_, &c)| c < 3) {
        return Err((
            format!("face {f} has {c} vertices"),
            "every face needs at least 3 vertices: remove degenerate faces before export".into(),
        ));
    }
    if indices.len() > u32::MAX as usize || n_points > u32::MAX as usize {
        return Err(("the mesh has more than 2^32 face-vertices or points".into(), "split the mesh".into()));
    }
    if let Some((i, v)) = indices.iter().enumerate().find(|&(_, &v)| v < 0 || v as u64 >= n_points as u64) {
        return Err((
            format!("faceVertexIndices[{i}] = {v} is out of range for {n_points} points"),
            "every face-vertex index must name a point (0 .. points.size - 1)".into(),
        ));
    }
    let mut is_hole = vec![false; counts.len()];
    for &h in holes {
        if let Some(slot) = usize::try_from(h).ok().and_then(|h| is_hole.get_mut(h)) {
            *slot = true;
        }
    }
    let n_tris: usize = counts.iter().map(|&c| c as usize - 2).sum();
    let mut triangles = Vec::with_capacity(n_tris);
    let mut base = 0u32;
    for (f, &c) in counts.iter().enumerate() {
        let c = c as u32;
        if !is_hole[f] {
            for j in 1..c - 1 {
                let (b, d) = (base + j, base + j + 1);
                triangles.push(if flip { [base, d, b] } else { [base, b, d] });
            }
        }
        base += c;
    }
    Ok(Topology {
        n_points,
        indices: indices.iter().map(|&v| v as u32).collect(),
        counts: counts.iter().map(|&c| c as u32).collect(),
        triangles,
    })
}

/// Expands a primvar to one value per point or per corner; `Err` says why it does not fit the mesh.
fn expand<const N: usize>(pv: &Primvar<N>, topo: &Topology) -> Result<Src<N>, String> {
    let values: Vec<[f32; N]> = match &pv.indices {
        None => pv.values.iter().map(|v| v.map(|x| x as f32)).collect(),
        Some(idx) => {
            let mut out = Vec::with_capacity(idx.len());
            for (i, &k) in idx.iter().enumerate() {
                let v = usize::try_from(k)
                    .ok()
                    .and_then(|k| pv.values.get(k))
                    .ok_or_else(|| format!("its indices[{i}] = {k} is out of range for {} values", pv.values.len()))?;
                out.push(v.map(|x| x as f32));
            }
            out
        }
    };
    let n_corners = topo.indices.len();
    let (want, what) = match pv.interp {
        Interp::Constant => (1, "constant (1 value)"),
        Interp::Uniform => (topo.counts.len(), "uniform (one per face)"),
        Interp::Vertex => (topo.n_points, "vertex (one per point)"),
        Interp::FaceVarying => (n_corners, "faceVarying (one per face-vertex)"),
    };
    if values.len() != want {
        return Err(format!("it is {what} but has {} values for {want} elements", values.len()));
    }
    Ok(match pv.interp {
        Interp::Constant => Src::PerPoint(vec![values[0]; topo.n_points]),
        Interp::Vertex => Src::PerPoint(values),
        Interp::FaceVarying => Src::PerCorner(values),
        Interp::Uniform => Src::PerCorner(
            topo.counts.iter().zip(&values).flat_map(|(&c, v)| std::iter::repeat_n(*v, c as usize)).collect(),
        ),
    })
}

/// Area-weighted unit normals per point from world positions and (final-winding) point triangles;
/// points touched by no triangle of positive area get +Y.
fn face_normals(positions: &[[f32; 3]], triangles: &[[u32; 3]]) -> Vec<[f32; 3]> {
    let mut acc = vec![DVec3::ZERO; positions.len()];
    let p = |i: u32| DVec3::from(positions[i as usize].map(f64::from));
    for t in triangles {
        let n = (p(t[1]) - p(t[0])).cross(p(t[2]) - p(t[0]));
        for &v in t {
            acc[v as usize] += n;
        }
    }
    acc.iter().map(|n| n.try_normalize().unwrap_or(DVec3::Y).as_vec3().to_array()).collect()
}

impl Importer<'_> {
    /// Reads a primvar and expands it, warning (and ignoring it) when it does not fit the topology.
    fn expanded<const N: usize>(
        &mut self,
        prim: &sdf::Path,
        name: &str,
        conv: fn(&openusd::sdf::Value) -> Option<Vec<[f64; N]>>,
        default_interp: Interp,
        topo: &Topology,
        map: impl Fn([f64; N]) -> [f64; N],
    ) -> Result<Option<Src<N>>, SceneError> {
        let Some(mut pv) = self.primvar(prim, name, conv, default_interp)? else {
            return Ok(None);
        };
        for v in &mut pv.values {
            *v = map(*v);
        }
        match expand(&pv, topo) {
            Ok(src) => Ok(Some(src)),
            Err(why) => {
                self.warn(
                    prim.as_str(),
                    format!("`{name}` is ignored: {why}"),
                    "author one value per element of its interpolation (see UsdGeomPrimvar)",
                );
                Ok(None)
            }
        }
    }

    /// Converts the mesh at `prim` with world matrix `to_world`; `None` (after a warning) for a mesh
    /// without faces.
    pub(super) fn read_mesh(&mut self, prim: &sdf::Path, to_world: &DMat4) -> Result<Option<Mesh>, SceneError> {
        let points = self.typed(prim, "points", vec3_array, "point3f[]")?.unwrap_or_default();
        let counts = self.typed(prim, "faceVertexCounts", int_array, "int[]")?.unwrap_or_default();
        let indices = self.typed(prim, "faceVertexIndices", int_array, "int[]")?.unwrap_or_default();
        let holes = self.typed(prim, "holeIndices", int_array, "int[]")?.unwrap_or_default();
        if let Some((i, p)) = points.iter().enumerate().find(|(_, p)| p.iter().any(|x| !x.is_finite())) {
            return Err(self.err(
                prim,
                format!("point {i} is not finite: {p:?}"),
                "fix or remove the point (NaN or infinite coordinates)",
            ));
        }
        let scheme = self.token_attr(prim, "subdivisionScheme")?;
        if scheme.as_deref() != Some("none") {
            let scheme = scheme.unwrap_or_else(|| "catmullClark (USD's fallback)".into());
            self.warn(
                prim.as_str(),
                format!("subdivisionScheme is {scheme}; voltab reads the control cage without subdividing"),
                "author `uniform token subdivisionScheme = \"none\"` for polygonal meshes, or subdivide before export",
            );
        }
        if counts.is_empty() || points.is_empty() {
            self.warn(
                prim.as_str(),
                "the mesh has no faces or no points; it is skipped".into(),
                "author points, faceVertexCounts and faceVertexIndices",
            );
            return Ok(None);
        }
        let left = match self.token_attr(prim, "orientation")?.as_deref() {
            None | Some("rightHanded") => false,
            Some("leftHanded") => true,
            Some(other) => {
                return Err(self.err(
                    prim,
                    format!("orientation = \"{other}\""),
                    "orientation is \"rightHanded\" (the fallback) or \"leftHanded\"",
                ));
            }
        };
        // A mirroring transform reverses the winding seen in world space.
        let mirrored = glam::DMat3::from_mat4(*to_world).determinant() < 0.0;
        let topo = triangulate(&counts, &indices, points.len(), &holes, left != mirrored)
            .map_err(|(msg, help)| self.err(prim, msg, help))?;
        drop((counts, indices, holes));

        let nm = normal_matrix(to_world);
        let to_normal = |n: [f64; 3]| match nm {
            Some(nm) => (nm * DVec3::from(n)).try_normalize().map_or([0.0; 3], |v| v.to_array()),
            None => [0.0; 3],
        };
        // `primvars:normals` wins over `normals` (UsdGeomPointBased).
        let normals = match self.expanded(prim, "primvars:normals", vec3_array, Interp::Constant, &topo, to_normal)? {
            Some(n) => Some(n),
            None => self.expanded(prim, "normals", vec3_array, Interp::Vertex, &topo, to_normal)?,
        };
        // voltab's UVs follow glTF (origin top left, v down); USD's st has its origin bottom left.
        let flip_v = |v: [f64; 2]| [v[0], 1.0 - v[1]];
        let uv = self.expanded(prim, "primvars:st", vec2_array, Interp::Constant, &topo, flip_v)?;
        let lightmap = match self.expanded(prim, "primvars:st1", vec2_array, Interp::Constant, &topo, flip_v)? {
            Some(s) => Some(s),
            None => self.expanded(prim, "primvars:lightmapUV", vec2_array, Interp::Constant, &topo, flip_v)?,
        };

        let world: Vec<[f32; 3]> =
            points.iter().map(|p| to_world.transform_point3(DVec3::from(*p)).as_vec3().to_array()).collect();
        drop(points);
        let split = normals.as_ref().is_some_and(Src::per_corner)
            || uv.as_ref().is_some_and(Src::per_corner)
            || lightmap.as_ref().is_some_and(Src::per_corner);
        let verts = if split {
            Vertices::welded(&topo, normals.as_ref(), uv.as_ref(), lightmap.as_ref())
        } else {
            Vertices::per_point(&topo)
        };
        // Computed normals fill in where the file has none (or a degenerate one).
        let authored = normals.as_ref().map(|s| verts.gather(s));
        let computed = authored.as_ref().is_none_or(|n| n.contains(&[0.0; 3])).then(|| {
            let point_tris: Vec<[u32; 3]> =
                verts.triangles.iter().map(|t| t.map(|v| verts.point[v as usize])).collect();
            face_normals(&world, &point_tris)
        });
        let normals = (0..verts.point.len())
            .map(|v| match (&authored, &computed) {
                (Some(n), _) if n[v] != [0.0; 3] => n[v],
                (_, Some(c)) => c[verts.point[v] as usize],
                _ => [0.0, 1.0, 0.0],
            })
            .collect();
        Ok(Some(Mesh {
            name: prim.as_str().to_owned(),
            positions: verts.point.iter().map(|&p| world[p as usize]).collect(),
            normals,
            uv: uv.as_ref().map(|s| verts.gather(s)),
            lightmap_uv: lightmap.as_ref().map(|s| verts.gather(s)),
            triangles: verts.triangles,
            material: None,
            medium: None,
            to_world: to_world.to_cols_array_2d(),
        }))
    }
}

/// The output vertices of a mesh.
struct Vertices {
    /// The point each vertex is at.
    point: Vec<u32>,
    /// A face-vertex (corner) each vertex came from (empty when vertices are the points).
    corner: Vec<u32>,
    /// Triangles over vertices.
    triangles: Vec<[u32; 3]>,
}

impl Vertices {
    /// One vertex per point (every attribute is per point).
    fn per_point(topo: &Topology) -> Vertices {
        let triangles = topo.triangles.iter().map(|t| t.map(|c| topo.indices[c as usize])).collect();
        Vertices { point: (0..topo.n_points as u32).collect(), corner: Vec::new(), triangles }
    }

    /// Corners welded into vertices: two corners share a vertex when they use the same point and
    /// bit-identical per-corner attribute values. Only corners of triangulated faces become vertices;
    /// vertices are numbered in first-use order.
    fn welded(topo: &Topology, normals: Option<&Src<3>>, uv: Option<&Src<2>>, lightmap: Option<&Src<2>>) -> Vertices {
        fn bits<const N: usize>(src: Option<&Src<N>>, corner: usize, out: &mut [u32]) {
            if let Some(Src::PerCorner(v)) = src {
                for (o, x) in out.iter_mut().zip(v[corner]) {
                    *o = x.to_bits();
                }
            }
        }
        const NONE: u32 = u32::MAX;
        // Per point, a chain of its vertices (head → next → …) with their attribute bits: a point has
        // few distinct corner values, so a linear scan of its chain beats hashing every corner.
        let mut head = vec![NONE; topo.n_points];
        let (mut next, mut keys): (Vec<u32>, Vec<CornerKey>) = (Vec::new(), Vec::new());
        let mut corner_vertex = vec![NONE; topo.indices.len()];
        let (mut point, mut corner) = (Vec::new(), Vec::new());
        let mut triangles = Vec::with_capacity(topo.triangles.len());
        for t in &topo.triangles {
            let mut out = [0u32; 3];
            for (k, &c) in t.iter().enumerate() {
                let c = c as usize;
                if corner_vertex[c] == NONE {
                    let p = topo.indices[c];
                    let mut key = [0u32; 7];
                    bits(normals, c, &mut key[0..3]);
                    bits(uv, c, &mut key[3..5]);
                    bits(lightmap, c, &mut key[5..7]);
                    let mut v = head[p as usize];
                    while v != NONE && keys[v as usize] != key {
                        v = next[v as usize];
                    }
                    if v == NONE {
                        v = point.len() as u32;
                        point.push(p);
                        corner.push(c as u32);
                        keys.push(key);
                        next.push(head[p as usize]);
                        head[p as usize] = v;
                    }
                    corner_vertex[c] = v;
                }
                out[k] = corner_vertex[c];
            }
            triangles.push(out);
        }
        Vertices { point, corner, triangles }
    }

    /// An attribute's value at every vertex.
    fn gather<const N: usize>(&self, src: &Src<N>) -> Vec<[f32; N]> {
        let corner = |v: usize| self.corner.get(v).copied().unwrap_or(0) as usize;
        (0..self.point.len()).map(|v| src.get(self.point[v] as usize, corner(v))).collect()
    }
}

/// Bit pattern of a corner's per-corner normal, uv and lightmap uv (per-point ones contribute zeros).
type CornerKey = [u32; 7];
