//! Ray queries over a [`Scene`]: closest hit, shadow (any-hit) rays, and the media a ray passes
//! through with their optical thickness.
//!
//! **Input → output.** A [`Scene`] (meshes in world space) → a [`SceneBvh`] (obvhs compressed wide BVH
//! over every triangle, and a second one over the boundaries of closed media) → per [`Ray`]: the
//! closest [`Hit`], whether a segment is occluded, the [`MediumSegment`]s along it, and per channel
//! the optical thickness `τ = ∫σ_t` and the effective extinction `τ / length` — the per-path σ that
//! dubouchet2019 Sec. 4.4 feeds its tables in heterogeneous media. Exponential height fog is
//! integrated in closed form (iser2018 Eq. 4).
//!
//! **Invariants.**
//! - Watertight: a ray crossing a closed mesh through an edge or a vertex is counted exactly once
//!   (the rule is in `bvh/triangle.rs`); media along a ray are therefore consistent from end to end.
//! - Results are a pure function of the scene and the ray: equal distances are resolved by the lower
//!   (mesh, triangle) index, box culling is conservative (`bvh/traverse.rs`), and the batched queries
//!   return exactly what the single ones do, for any thread count.
//! - Bad input never panics: rays with a zero, infinite or NaN direction or origin miss everything;
//!   triangles with out-of-range indices, non-finite or coincident-in-f64 (zero-area) vertices are left
//!   out of the BVH and counted in [`BuildStats::excluded`].
//!
//! Geometry is intersected in f32, the precision of [`Mesh::positions`](super::Mesh); a ray's origin is
//! rounded to f32 and its direction rescaled by a power of two (exact), so `t` is reported in units of
//! the given direction's length. Direction components below 2⁻⁶⁰ of the largest are flushed to zero.

mod media;
pub mod procedural;
mod traverse;
mod triangle;

#[cfg(test)]
mod tests;
#[cfg(test)]
mod tests_media;

use std::time::Instant;

use glam::DVec3;
use rayon::prelude::*;

use super::{Scene, Surface};
pub use media::{MediumSegment, effective_sigma, exponential_density_integral, optical_thickness};
use traverse::{Accel, NodeRay};
use triangle::{PreparedRay, Tri, intersect};

/// A ray `origin + t·direction`, `t ∈ (t_min, t_max]`, in world space (metres).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Ray {
    /// Origin (metres).
    pub origin: [f64; 3],
    /// Direction (need not be unit; `t` is measured in its length).
    pub direction: [f64; 3],
    /// Hits at `t <= t_min` are ignored.
    pub t_min: f64,
    /// Hits at `t > t_max` are ignored (`+∞` allowed).
    pub t_max: f64,
}

impl Ray {
    /// A ray over `t ∈ (0, +∞]`.
    pub fn new(origin: [f64; 3], direction: [f64; 3]) -> Self {
        Ray { origin, direction, t_min: 0.0, t_max: f64::INFINITY }
    }
}

/// How light meets a surface ([`SceneBvh::surface_response`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum SurfaceResponse {
    /// Lambertian reflector with this albedo per channel: the material's base colour (non-finite or
    /// negative values as 0), 0.8 grey without a material. Textures and roughness are not read.
    Lambert([f64; 3]),
    /// Index-matched boundary: light passes unbent (an `ior = 1` dielectric, or a mesh bounding a medium
    /// without a material).
    PassThrough,
    /// Smooth dielectric interface with this index of refraction.
    Dielectric(f64),
}

/// The closest intersection of a ray with the scene's triangles.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Hit {
    /// Ray parameter of the hit (distance in units of the direction's length).
    pub t: f64,
    /// Index into [`Scene::meshes`].
    pub mesh: usize,
    /// Index into that mesh's [`triangles`](super::Mesh::triangles).
    pub triangle: usize,
    /// Barycentric weights `(u, v)` of the triangle's vertices 1 and 2 (vertex 0 has `1 − u − v`).
    pub barycentric: [f64; 2],
    /// Unit normal of the triangle's plane, on the side its counter-clockwise winding faces.
    pub geometric_normal: [f64; 3],
    /// Vertex normals interpolated with the barycentrics and normalised (the geometric normal when the
    /// mesh has no usable vertex normals).
    pub shading_normal: [f64; 3],
    /// The ray arrives from the side the geometric normal points to (`⟨direction, n_g⟩ < 0`, decided by
    /// the same arithmetic that found the hit): it is entering a closed mesh.
    pub front_face: bool,
}

/// What [`SceneBvh::build`] did.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct BuildStats {
    /// Triangles in the BVH.
    pub triangles: usize,
    /// Of those, triangles of meshes bounding a medium (also in the boundary BVH).
    pub boundary_triangles: usize,
    /// Triangles left out: indices out of range, non-finite or zero-area vertices, or beyond 2³²−2.
    pub excluded: usize,
    /// Nodes of the two BVHs.
    pub nodes: usize,
    /// Wall time of the whole build (gathering triangles, both BVHs), milliseconds.
    pub build_ms: f64,
    /// Worker threads of the rayon pool it ran on.
    pub threads: usize,
}

/// Per mesh, what a hit needs to report its shading normal.
#[derive(Debug, Clone, Default)]
struct MeshShading {
    /// Vertex normals (empty when unusable: count differs from the positions').
    normals: Vec<[f32; 3]>,
    /// Triangles (vertex indices; empty when the normals are).
    triangles: Vec<[u32; 3]>,
}

/// Ray-query acceleration structures over one [`Scene`].
#[derive(Debug, Clone)]
pub struct SceneBvh {
    all: Accel,
    boundary: Accel,
    /// Global index of each mesh's first triangle (mesh-major), plus the total.
    offsets: Vec<u64>,
    shading: Vec<MeshShading>,
    /// Per mesh, the medium it bounds (validated index into `Scene::media`).
    bounds_medium: Vec<Option<usize>>,
    stats: BuildStats,
}

/// A ray converted to the internal frame.
struct Query {
    pr: PreparedRay,
    node: NodeRay,
    /// The internal direction is `direction / unit` (a power of two), so `t_user = t_internal / unit`.
    unit: f64,
    /// Internal range.
    t_min: f64,
    t_max: f64,
    /// Internal `t_max` for box culling (rounded up to f32).
    node_t_max: f32,
}

impl Query {
    /// `None` for a non-finite origin, a zero or non-finite direction, or an empty or NaN range.
    fn new(origin: [f64; 3], direction: [f64; 3], t_min: f64, t_max: f64) -> Option<Query> {
        let m = direction.iter().fold(0.0f64, |m, x| m.max(x.abs()));
        let valid_range = t_max > t_min; // false for NaN
        if !(m > 0.0 && m.is_finite()) || direction.iter().any(|x| x.is_nan()) || t_min.is_nan() || !valid_range {
            return None;
        }
        // The power of two with m / unit in [1, 2) (read from the bits, subnormals included): the
        // rescaling is exact.
        let bits = m.to_bits();
        let unit = if bits >> 52 > 0 {
            f64::from_bits(bits >> 52 << 52)
        } else {
            f64::from_bits(1u64 << (63 - bits.leading_zeros()))
        };
        let flush = 2f64.powi(-60);
        let d = direction.map(|x| {
            let s = x / unit;
            if s.abs() < flush { 0.0f32 } else { s as f32 }
        });
        let o = origin.map(|x| x as f32);
        if o.iter().any(|x| !x.is_finite()) {
            return None;
        }
        let pr = PreparedRay::new(o, d);
        let (t_min, t_max) = (t_min * unit, t_max * unit);
        let node_t_min = if t_min.is_finite() { (t_min as f32).next_down() } else { f32::NEG_INFINITY };
        let node_t_max = if t_max.is_finite() { (t_max as f32).next_up() } else { f32::INFINITY };
        Some(Query { node: NodeRay::new(&pr, node_t_min), pr, unit, t_min, t_max, node_t_max })
    }

    #[inline(always)]
    fn in_range(&self, t: f32) -> bool {
        let t = f64::from(t);
        t > self.t_min && t <= self.t_max
    }
}

impl SceneBvh {
    /// Builds the BVHs over every triangle of every mesh, on the current rayon pool (the build time
    /// is in [`SceneBvh::stats`]).
    pub fn build(scene: &Scene) -> SceneBvh {
        let start = Instant::now();
        let media = scene.media.len();
        let mut bounds_medium: Vec<Option<usize>> =
            scene.meshes.iter().map(|m| m.medium.filter(|&i| i < media)).collect();
        for (i, md) in scene.media.iter().enumerate() {
            if let super::Boundary::Mesh(j) = md.boundary
                && let Some(slot @ None) = bounds_medium.get_mut(j)
            {
                *slot = Some(i);
            }
        }
        let mut offsets = Vec::with_capacity(scene.meshes.len() + 1);
        let mut all = Vec::with_capacity(scene.triangle_count());
        let mut boundary = Vec::new();
        let mut excluded = 0usize;
        let mut gid: u64 = 0;
        for (mi, mesh) in scene.meshes.iter().enumerate() {
            offsets.push(gid);
            for t in &mesh.triangles {
                let id = gid;
                gid += 1;
                let Some(v) = triangle_vertices(&mesh.positions, t) else {
                    excluded += 1;
                    continue;
                };
                // Global ids must fit u32 (obvhs indexes primitives with u32; u32::MAX is its "invalid").
                if id >= u64::from(u32::MAX) {
                    excluded += 1;
                    continue;
                }
                let tri = Tri { v, gid: id as u32 };
                all.push(tri);
                if bounds_medium[mi].is_some() {
                    boundary.push(tri);
                }
            }
        }
        offsets.push(gid);
        let (triangles, boundary_triangles) = (all.len(), boundary.len());
        let (all, boundary) = rayon::join(|| Accel::build(all), || Accel::build(boundary));
        let shading = scene
            .meshes
            .iter()
            .map(|m| {
                if m.normals.len() == m.positions.len() {
                    MeshShading { normals: m.normals.clone(), triangles: m.triangles.clone() }
                } else {
                    MeshShading::default()
                }
            })
            .collect();
        let stats = BuildStats {
            triangles,
            boundary_triangles,
            excluded,
            nodes: all.nodes() + boundary.nodes(),
            build_ms: start.elapsed().as_secs_f64() * 1e3,
            threads: rayon::current_num_threads(),
        };
        SceneBvh { all, boundary, offsets, shading, bounds_medium, stats }
    }

    /// Every triangle the BVH intersects (world-space vertices, metres), in BVH slot order: what a
    /// rasteriser needs to draw the same occluders the ray queries see.
    pub fn triangles(&self) -> impl Iterator<Item = [[f32; 3]; 3]> + '_ {
        self.all.tris.iter().map(|t| t.v)
    }

    /// Counts and timing of the build.
    pub fn stats(&self) -> BuildStats {
        self.stats
    }

    /// The medium mesh `mesh` bounds (from [`Mesh::medium`](super::Mesh::medium), else a medium whose
    /// boundary is [`Boundary::Mesh`](super::Boundary::Mesh) of it), as recorded at build time.
    pub fn medium_bounded_by(&self, mesh: usize) -> Option<usize> {
        self.bounds_medium.get(mesh).copied().flatten()
    }

    /// How light meets mesh `mesh`'s surface: the one reading of its material that every transport code
    /// shares. `scene` must be the scene this BVH was built from.
    pub fn surface_response(&self, scene: &Scene, mesh: usize) -> SurfaceResponse {
        let mat = scene.meshes.get(mesh).and_then(|m| m.material).and_then(|j| scene.materials.get(j));
        match mat.map(|x| x.surface) {
            Some(Surface::Dielectric { ior: 1.0 }) => SurfaceResponse::PassThrough,
            Some(Surface::Dielectric { ior }) if ior.is_finite() && ior > 0.0 => SurfaceResponse::Dielectric(ior),
            None if self.medium_bounded_by(mesh).is_some() => SurfaceResponse::PassThrough,
            _ => SurfaceResponse::Lambert(
                mat.map_or([0.8; 3], |x| x.base_color).map(|a| if a.is_finite() { a.max(0.0) } else { 0.0 }),
            ),
        }
    }

    /// (mesh, triangle within mesh) of a global triangle id.
    fn locate(&self, gid: u32) -> (usize, usize) {
        let g = u64::from(gid);
        let mesh = self.offsets.partition_point(|&o| o <= g).saturating_sub(1);
        (mesh, (g - self.offsets[mesh]) as usize)
    }

    /// The closest hit with `t ∈ (t_min, t_max]`; among hits at exactly the same `t`, the lowest
    /// (mesh, triangle). `None` on a miss or an invalid ray.
    pub fn closest_hit(&self, ray: &Ray) -> Option<Hit> {
        let q = Query::new(ray.origin, ray.direction, ray.t_min, ray.t_max)?;
        let tris = &self.all.tris;
        let mut best: Option<(triangle::TriHit, usize)> = None;
        self.all.traverse(&q.node, q.node_t_max, |slot, t_max| {
            if let Some(h) = intersect(&tris[slot], &q.pr)
                && q.in_range(h.t)
            {
                let better = match best {
                    None => true,
                    Some((b, bs)) => h.t < b.t || (h.t == b.t && tris[slot].gid < tris[bs].gid),
                };
                if better {
                    best = Some((h, slot));
                    *t_max = h.t;
                }
            }
            false
        });
        let (h, slot) = best?;
        Some(self.finish_hit(&q, &h, &tris[slot]))
    }

    fn finish_hit(&self, q: &Query, h: &triangle::TriHit, tri: &Tri) -> Hit {
        let (mesh, triangle) = self.locate(tri.gid);
        let v = tri.v.map(|p| DVec3::from_array(p.map(f64::from)));
        let geometric_normal = unit_normal((v[1] - v[0]).cross(v[2] - v[0])).unwrap_or(DVec3::Z);
        let (b1, b2) = (f64::from(h.b1), f64::from(h.b2));
        let b0 = 1.0 - b1 - b2;
        let shading_normal = self
            .shading
            .get(mesh)
            .filter(|s| !s.normals.is_empty())
            .and_then(|s| s.triangles.get(triangle).map(|t| (s, t)))
            .and_then(|(s, t)| {
                let n = t.map(|i| s.normals.get(i as usize).map(|n| DVec3::from_array(n.map(f64::from))));
                let (n0, n1, n2) = (n[0]?, n[1]?, n[2]?);
                unit_normal(b0 * n0 + b1 * n1 + b2 * n2)
            })
            .unwrap_or(geometric_normal);
        Hit {
            t: f64::from(h.t) / q.unit,
            mesh,
            triangle,
            barycentric: [b1, b2],
            geometric_normal: geometric_normal.to_array(),
            shading_normal: shading_normal.to_array(),
            front_face: h.front,
        }
    }

    /// Whether anything is hit at `t ∈ (0, t_max)` (`t_max` itself excluded, so a shadow ray aimed at a
    /// light's surface is not blocked by it). Stops at the first hit found. `false` for an invalid ray.
    pub fn occluded(&self, origin: [f64; 3], direction: [f64; 3], t_max: f64) -> bool {
        self.occluded_ray(&Ray { origin, direction, t_min: 0.0, t_max })
    }

    /// [`SceneBvh::occluded`] over `t ∈ (ray.t_min, ray.t_max)`.
    pub fn occluded_ray(&self, ray: &Ray) -> bool {
        let Some(q) = Query::new(ray.origin, ray.direction, ray.t_min, ray.t_max) else { return false };
        let tris = &self.all.tris;
        let mut hit = false;
        self.all.traverse(&q.node, q.node_t_max, |slot, _| {
            hit = intersect(&tris[slot], &q.pr).is_some_and(|h| {
                let t = f64::from(h.t);
                t > q.t_min && t < q.t_max
            });
            hit
        });
        hit
    }

    /// [`SceneBvh::closest_hit`] for each ray, in parallel on the current rayon pool (same results,
    /// in order, for any thread count).
    pub fn closest_hits(&self, rays: &[Ray]) -> Vec<Option<Hit>> {
        rays.par_iter().with_min_len(256).map(|r| self.closest_hit(r)).collect()
    }

    /// [`SceneBvh::occluded_ray`] for each ray, in parallel on the current rayon pool.
    pub fn occluded_batch(&self, rays: &[Ray]) -> Vec<bool> {
        rays.par_iter().with_min_len(256).map(|r| self.occluded_ray(r)).collect()
    }
}

/// The three vertices of `t` if its indices are in range, they are finite and the triangle has
/// non-zero area in f64 (the products of f32 differences are then nearly exact).
fn triangle_vertices(positions: &[[f32; 3]], t: &[u32; 3]) -> Option<[[f32; 3]; 3]> {
    let v = [positions.get(t[0] as usize)?, positions.get(t[1] as usize)?, positions.get(t[2] as usize)?];
    if v.iter().any(|p| p.iter().any(|x| !x.is_finite())) {
        return None;
    }
    let p = v.map(|p| DVec3::from_array(p.map(f64::from)));
    let n = (p[1] - p[0]).cross(p[2] - p[0]);
    (n != DVec3::ZERO && n.is_finite()).then_some([*v[0], *v[1], *v[2]])
}

/// `v / |v|`, divided by the largest component first so tiny (f32-subnormal) normals do not underflow
/// when squared; `None` for a zero or non-finite `v`. (Not glam's `normalize`: that multiplies by the
/// reciprocal length, which rounds differently.)
fn unit_normal(v: DVec3) -> Option<DVec3> {
    let m = 0.0f64.max(v.x.abs()).max(v.y.abs()).max(v.z.abs());
    if !(m > 0.0 && m.is_finite()) {
        return None;
    }
    let s = v / m;
    Some(s / s.length())
}
