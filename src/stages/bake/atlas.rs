//! Lightmap atlas: a [`Scene`]'s lightmap UVs → one atlas image layout and the world-space sample
//! (position, normals) behind every covered texel, plus [`dilate`] to fill chart borders after baking.
//!
//! **Input → output.** `(&Scene, &AtlasOptions)` → [`Atlas`]: one square [`Chart`] per lightmapped mesh
//! (its whole `[0, 1]²` lightmap-UV square), shelf-packed with `padding` free texels on every side, and
//! a [`Texel`] per covered pixel, ordered by pixel index. Meshes that get no chart are listed in
//! [`Atlas::skipped`] with the reason.
//!
//! **Which meshes.** A mesh with `lightmap_uv` (glTF `TEXCOORD_1`, USD `primvars:st1`) that bounds no
//! medium (neither [`Mesh::medium`] nor a [`Boundary::Mesh`] names it, the rule of
//! [`SceneBvh::medium_bounded_by`](crate::scene::bvh::SceneBvh::medium_bounded_by)) and has at least one
//! triangle of non-zero area both in world space and in lightmap UV. UVs must be finite and inside
//! `[0, 1]`; values at most [`UV_TOLERANCE`] outside are clamped with a warning, anything further is an
//! error naming the mesh (voltab does not re-unwrap).
//!
//! **Chart size.** With `A` the mesh's world area \[m²\] and `a` its lightmap-UV area (fraction of the
//! unit square), one UV unit spans `√(A/a)` metres, so the side is `⌈√(A/a) · texels_per_metre⌉`
//! clamped to `[min_size, max_size]` (clamping is reported in [`Atlas::warnings`]).
//!
//! **Texel ↔ UV.** UVs follow the glTF convention (`docs/design/scene.md`: origin at the image's
//! top-left, v down). Texel `(i, j)` of a chart of side `S` (column `i`, row `j` from the top) has its
//! centre at lightmap UV `((i + ½)/S, (j + ½)/S)` and is atlas pixel `(chart.x + i, chart.y + j)`. A
//! renderer maps a mesh UV into the atlas with [`Atlas::uv_scale_offset`].
//!
//! **Rasterization.** UVs are scaled to chart pixels and snapped to 1/256 pixel (the sub-pixel precision
//! of D3D11-class rasterizers), so edge functions are exact integers. A texel centre strictly inside a
//! triangle belongs to it; a centre exactly on an edge belongs to the triangle whose edge, walked in
//! the triangle's positively oriented order, points down (+v) or exactly left (−u). The two triangles
//! sharing an edge walk it in opposite directions, so each centre of a closed UV island belongs to
//! exactly one triangle. Those texels are `inside`, sampled at the centre by barycentric
//! interpolation (f64). A conservative pass then adds the texels a triangle overlaps with positive area
//! but whose centre no triangle holds (`inside = false`), sampled at the point of the nearest
//! overlapping triangle closest to the centre (in UV space), so bilinear lookups at chart edges read
//! baked values. If UV triangles overlap, the lowest triangle index keeps the texel (and a warning
//! counts them).

use std::path::PathBuf;

use glam::DVec3;
use rayon::prelude::*;

use crate::scene::{Boundary, Mesh, Scene, SceneWarning};

/// How far outside `[0, 1]` a lightmap UV may lie and still be clamped (rounding in exporters).
pub const UV_TOLERANCE: f32 = 1e-3;

/// Largest atlas side \[texels\] (the 2D texture limit of D3D11-class GPUs).
pub const MAX_ATLAS_SIDE: u32 = 16_384;

/// Sub-pixel bits of the snapped UV grid.
const SUBPIXEL_BITS: u32 = 8;
const ONE: i64 = 1 << SUBPIXEL_BITS;

/// Layout settings.
#[derive(Debug, Clone, PartialEq)]
pub struct AtlasOptions {
    /// World-space texel density \[texels/m\].
    pub texels_per_metre: f64,
    /// Smallest chart side \[texels\].
    pub min_size: u32,
    /// Largest chart side \[texels\].
    pub max_size: u32,
    /// Free texels around every chart (room for dilation and bilinear filtering).
    pub padding: u32,
}

/// A mesh's `[0, 1]²` lightmap-UV square placed in the atlas (padding excluded).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Chart {
    /// Index into [`Scene::meshes`].
    pub mesh: usize,
    /// Left column of the chart \[texels\].
    pub x: u32,
    /// Top row of the chart \[texels\].
    pub y: u32,
    /// Width \[texels\].
    pub width: u32,
    /// Height \[texels\] (charts are square).
    pub height: u32,
}

/// The surface point behind one atlas pixel.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Texel {
    /// Pixel index `y · atlas width + x`.
    pub pixel: u32,
    /// Index into [`Scene::meshes`].
    pub mesh: usize,
    /// Triangle within the mesh.
    pub triangle: usize,
    /// World position \[m\].
    pub position: [f64; 3],
    /// Unit shading normal: the interpolated vertex normal, negated if it points away from
    /// `geometric_normal`; the geometric normal where the mesh has no usable normals.
    pub normal: [f64; 3],
    /// Unit face normal (counter-clockwise winding).
    pub geometric_normal: [f64; 3],
    /// The texel centre lies in the triangle (false: a conservative edge texel sampled at the
    /// triangle's point closest to its centre).
    pub inside: bool,
}

/// A mesh without a chart, and why.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct SkippedMesh {
    /// Index into [`Scene::meshes`].
    pub mesh: usize,
    /// Mesh name.
    pub name: String,
    /// Why it has no chart.
    pub reason: String,
}

/// The atlas layout and its texels.
#[derive(Debug, Clone, PartialEq)]
pub struct Atlas {
    /// Width \[texels\] (a power of two).
    pub width: u32,
    /// Height \[texels\] (the packed height).
    pub height: u32,
    /// Padding around each chart \[texels\], as requested.
    pub padding: u32,
    /// One chart per lightmapped mesh, in packing order.
    pub charts: Vec<Chart>,
    /// Covered pixels, ordered by pixel index, at most one per pixel.
    pub texels: Vec<Texel>,
    /// Meshes without a chart.
    pub skipped: Vec<SkippedMesh>,
    /// Clamped UVs, clamped chart sizes, overlapping or collapsed UV triangles.
    pub warnings: Vec<SceneWarning>,
}

/// The atlas cannot be built or used.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum AtlasError {
    /// Bad options.
    #[error("lightmap atlas: {message}\n  = help: {help}")]
    Options {
        /// What is wrong.
        message: String,
        /// How to fix it.
        help: String,
    },
    /// A mesh's lightmap data is unusable.
    #[error("{scene}: mesh \"{mesh}\": {message}\n  = help: {help}")]
    Mesh {
        /// Scene file.
        scene: PathBuf,
        /// Mesh name.
        mesh: String,
        /// What is wrong.
        message: String,
        /// How to fix it.
        help: String,
    },
    /// No mesh qualifies for a chart.
    #[error("{scene}: no mesh can be lightmapped:{}\n  = help: give the surfaces to bake a second UV set (glTF TEXCOORD_1, USD primvars:st1) in your DCC tool", list(.skipped))]
    NothingToBake {
        /// Scene file.
        scene: PathBuf,
        /// Every mesh and why it was left out.
        skipped: Vec<SkippedMesh>,
    },
    /// The packed atlas exceeds [`MAX_ATLAS_SIDE`].
    #[error(
        "{scene}: the lightmap atlas would be {width}×{height} texels, above the {max}×{max} limit\n  = help: lower texels_per_metre or max_size"
    )]
    TooLarge {
        /// Scene file.
        scene: PathBuf,
        /// Packed width.
        width: u64,
        /// Packed height.
        height: u64,
        /// [`MAX_ATLAS_SIDE`].
        max: u32,
    },
    /// A pixel buffer does not match the atlas.
    #[error(
        "lightmap atlas: the pixel buffer holds {len} pixels but the atlas is {width}×{height}\n  = help: allocate width · height pixels for the atlas"
    )]
    Buffer {
        /// Buffer length.
        len: usize,
        /// Atlas width.
        width: u32,
        /// Atlas height.
        height: u32,
    },
}

fn list(skipped: &[SkippedMesh]) -> String {
    if skipped.is_empty() {
        return " the scene has no meshes".into();
    }
    skipped.iter().map(|s| format!("\n  - \"{}\": {}", s.name, s.reason)).collect()
}

impl Atlas {
    /// `(scale, offset)` mapping a mesh's lightmap UV into atlas UV (`[0, 1]²` over the whole atlas,
    /// v down): `atlas_uv = uv · scale + offset`.
    pub fn uv_scale_offset(&self, chart: &Chart) -> ([f64; 2], [f64; 2]) {
        let (w, h) = (f64::from(self.width), f64::from(self.height));
        ([f64::from(chart.width) / w, f64::from(chart.height) / h], [f64::from(chart.x) / w, f64::from(chart.y) / h])
    }

    /// Fraction of the atlas covered by charts (padding excluded).
    pub fn fill_ratio(&self) -> f64 {
        let charts: u64 = self.charts.iter().map(|c| u64::from(c.width) * u64::from(c.height)).sum();
        charts as f64 / (f64::from(self.width) * f64::from(self.height))
    }

    /// Number of `inside` texels.
    pub fn inside_texels(&self) -> usize {
        self.texels.iter().filter(|t| t.inside).count()
    }
}

/// A mesh that gets a chart: its usable triangles and clamped UVs.
struct Chartable {
    mesh: usize,
    side: u32,
    uv: Vec<[f64; 2]>,
    triangles: Vec<usize>,
}

fn check_options(o: &AtlasOptions) -> Result<(), AtlasError> {
    let bad = |message: String, help: &str| Err(AtlasError::Options { message, help: help.into() });
    if !(o.texels_per_metre.is_finite() && o.texels_per_metre > 0.0) {
        return bad(format!("texels_per_metre = {}", o.texels_per_metre), "give a positive density, e.g. 16 texels/m");
    }
    if o.min_size == 0 || o.min_size > o.max_size || o.max_size > MAX_ATLAS_SIDE {
        return bad(
            format!("chart sizes min_size = {}, max_size = {}", o.min_size, o.max_size),
            &format!("need 1 <= min_size <= max_size <= {MAX_ATLAS_SIDE}"),
        );
    }
    if o.padding > MAX_ATLAS_SIDE / 4 {
        return bad(format!("padding = {}", o.padding), "padding is a few texels (2 to 4 is usual)");
    }
    Ok(())
}

/// Builds the atlas of `scene` (module doc). Errors: bad options, a lightmapped mesh with broken
/// indices or UVs, no mesh to lightmap, an atlas above [`MAX_ATLAS_SIDE`].
pub fn build(scene: &Scene, opts: &AtlasOptions) -> Result<Atlas, AtlasError> {
    check_options(opts)?;
    let n = scene.meshes.len();
    let mut bounded: Vec<Option<usize>> = scene.meshes.iter().map(|m| m.medium).collect();
    for (i, md) in scene.media.iter().enumerate() {
        if let Boundary::Mesh(j) = md.boundary
            && let Some(slot @ None) = bounded.get_mut(j)
        {
            *slot = Some(i);
        }
    }
    let (mut skipped, mut warnings, mut chartable) = (Vec::new(), Vec::new(), Vec::new());
    for (mi, mesh) in scene.meshes.iter().enumerate() {
        let skip = |reason: String| SkippedMesh { mesh: mi, name: mesh.name.clone(), reason };
        if let Some(md) = bounded[mi] {
            let name = scene.media.get(md).map_or("?", |m| m.name.as_str());
            skipped.push(skip(format!(
                "bounds the participating medium \"{name}\"; medium boundaries get no lightmap (light in media comes from the volume tables)"
            )));
            continue;
        }
        match prepare_mesh(scene, mi, opts, &mut warnings)? {
            Ok(c) => chartable.push(c),
            Err(reason) => skipped.push(skip(reason)),
        }
    }
    debug_assert_eq!(chartable.len() + skipped.len(), n);
    if chartable.is_empty() {
        return Err(AtlasError::NothingToBake { scene: scene.source.clone(), skipped });
    }
    let (width, height, charts) = pack(&chartable, opts.padding).ok_or_else(|| AtlasError::TooLarge {
        scene: scene.source.clone(),
        width: shelf_width(&chartable, opts.padding),
        height: shelf_height(&chartable, opts.padding),
        max: MAX_ATLAS_SIDE,
    })?;
    let per_chart: Vec<(Vec<Texel>, usize)> = charts
        .par_iter()
        .map(|&(ci, chart)| rasterize(&scene.meshes[chartable[ci].mesh], &chartable[ci], &chart, width))
        .collect();
    let charts: Vec<Chart> = charts.into_iter().map(|(_, c)| c).collect();
    let mut texels = Vec::new();
    for ((t, overlapped), chart) in per_chart.into_iter().zip(&charts) {
        if overlapped > 0 {
            warnings.push(SceneWarning {
                location: scene.meshes[chart.mesh].name.clone(),
                message: format!("{overlapped} lightmap texels are covered by more than one triangle (overlapping lightmap UVs); the lowest triangle keeps them"),
                help: "lightmap UVs must not overlap: re-pack the second UV set without overlaps".into(),
            });
        }
        texels.extend(t);
    }
    texels.sort_by_key(|t| t.pixel);
    Ok(Atlas { width, height, padding: opts.padding, charts, texels, skipped, warnings })
}

/// Checks a mesh's lightmap data: `Ok(Ok(_))` gets a chart, `Ok(Err(reason))` is skipped.
fn prepare_mesh(
    scene: &Scene,
    mi: usize,
    opts: &AtlasOptions,
    warnings: &mut Vec<SceneWarning>,
) -> Result<Result<Chartable, String>, AtlasError> {
    let mesh = &scene.meshes[mi];
    let err = |message: String, help: &str| AtlasError::Mesh {
        scene: scene.source.clone(),
        mesh: mesh.name.clone(),
        message,
        help: help.into(),
    };
    let Some(raw_uv) = &mesh.lightmap_uv else {
        return Ok(Err("has no lightmap UVs (glTF TEXCOORD_1 / USD primvars:st1); add one in your DCC tool's UV unwrap — voltab does not unwrap by hand".into()));
    };
    let nv = mesh.positions.len();
    if raw_uv.len() != nv {
        return Err(err(format!("{} lightmap UVs for {nv} vertices", raw_uv.len()), "give one lightmap UV per vertex"));
    }
    if let Some((ti, t)) = mesh.triangles.iter().enumerate().find(|(_, t)| t.iter().any(|&v| v as usize >= nv)) {
        return Err(err(format!("triangle {ti} {t:?} indexes past the {nv} vertices"), "fix the index buffer"));
    }
    if let Some((vi, p)) = mesh.positions.iter().enumerate().find(|(_, p)| p.iter().any(|x| !x.is_finite())) {
        return Err(err(format!("vertex {vi} position {p:?} is not finite"), "fix or remove the vertex"));
    }
    let mut clamped = 0usize;
    let mut uv = Vec::with_capacity(nv);
    for (vi, t) in raw_uv.iter().enumerate() {
        if t.iter().any(|x| !x.is_finite() || !(-UV_TOLERANCE..=1.0 + UV_TOLERANCE).contains(x)) {
            return Err(err(
                format!("lightmap UV of vertex {vi} is {t:?}, outside [0, 1]"),
                "lightmap UVs must lie in the unit square (no tiling, no UDIMs): re-pack the second UV set into 0..1",
            ));
        }
        clamped += usize::from(t.iter().any(|x| !(0.0..=1.0).contains(x)));
        uv.push(t.map(|x| f64::from(x.clamp(0.0, 1.0))));
    }
    if clamped > 0 {
        warnings.push(SceneWarning {
            location: mesh.name.clone(),
            message: format!("{clamped} lightmap UVs lie up to {UV_TOLERANCE} outside [0, 1] and were clamped"),
            help: "re-pack the second UV set strictly inside 0..1".into(),
        });
    }
    let (mut area, mut uv_area, mut collapsed) = (0.0f64, 0.0f64, 0usize);
    let mut triangles = Vec::new();
    for (ti, t) in mesh.triangles.iter().enumerate() {
        let p = t.map(|v| DVec3::from(mesh.positions[v as usize].map(f64::from)));
        let world = 0.5 * (p[1] - p[0]).cross(p[2] - p[0]).length();
        let q = t.map(|v| uv[v as usize]);
        let flat = 0.5 * ((q[1][0] - q[0][0]) * (q[2][1] - q[0][1]) - (q[1][1] - q[0][1]) * (q[2][0] - q[0][0])).abs();
        if world > 0.0 && flat > 0.0 {
            area += world;
            uv_area += flat;
            triangles.push(ti);
        } else if world > 0.0 {
            collapsed += 1;
        }
    }
    if collapsed > 0 {
        warnings.push(SceneWarning {
            location: mesh.name.clone(),
            message: format!("{collapsed} triangles have zero lightmap-UV area and get no texels"),
            help: "give every face room in the second UV set".into(),
        });
    }
    if triangles.is_empty() {
        return Ok(Err("has no triangle with non-zero area both in world space and in its lightmap UVs".into()));
    }
    let wanted = ((area / uv_area).sqrt() * opts.texels_per_metre).ceil();
    let side = wanted.clamp(f64::from(opts.min_size), f64::from(opts.max_size)) as u32;
    if wanted > f64::from(opts.max_size) {
        warnings.push(SceneWarning {
            location: mesh.name.clone(),
            message: format!(
                "the chart needs {wanted} texels a side at {} texels/m; clamped to max_size = {}",
                opts.texels_per_metre, opts.max_size
            ),
            help: "raise max_size or accept the lower density on this mesh".into(),
        });
    }
    Ok(Ok(Chartable { mesh: mi, side, uv, triangles }))
}

fn padded(c: &Chartable, padding: u32) -> u64 {
    u64::from(c.side) + 2 * u64::from(padding)
}

/// The atlas width: the smallest power of two ≥ √(total padded area) and ≥ the widest padded chart.
fn shelf_width(charts: &[Chartable], padding: u32) -> u64 {
    let total: u64 = charts.iter().map(|c| padded(c, padding).pow(2)).sum();
    let widest = charts.iter().map(|c| padded(c, padding)).max().unwrap_or(1);
    ((total as f64).sqrt().ceil() as u64).max(widest).next_power_of_two()
}

/// Shelf packing order: tallest padded chart first, mesh index breaking ties (deterministic).
fn order(charts: &[Chartable], padding: u32) -> Vec<usize> {
    let mut v: Vec<usize> = (0..charts.len()).collect();
    v.sort_by_key(|&i| (std::cmp::Reverse(padded(&charts[i], padding)), charts[i].mesh));
    v
}

/// Places charts on shelves of width `shelf_width`; returns (index into `charts`, x, y) of each padded
/// box and the height.
fn shelves(charts: &[Chartable], padding: u32) -> (Vec<(usize, u64, u64)>, u64) {
    let w = shelf_width(charts, padding);
    let (mut x, mut y, mut shelf) = (0u64, 0u64, 0u64);
    let mut placed = Vec::with_capacity(charts.len());
    for ci in order(charts, padding) {
        let s = padded(&charts[ci], padding);
        if x + s > w {
            (x, y, shelf) = (0, y + shelf, 0);
        }
        placed.push((ci, x, y));
        x += s;
        shelf = shelf.max(s);
    }
    (placed, y + shelf)
}

fn shelf_height(charts: &[Chartable], padding: u32) -> u64 {
    shelves(charts, padding).1
}

/// Packed charts, each with its index into the chartable list.
type Packed = Vec<(usize, Chart)>;

/// (width, height, charts) or `None` when a side exceeds [`MAX_ATLAS_SIDE`].
fn pack(charts: &[Chartable], padding: u32) -> Option<(u32, u32, Packed)> {
    let w = shelf_width(charts, padding);
    let (placed, h) = shelves(charts, padding);
    if w > u64::from(MAX_ATLAS_SIDE) || h > u64::from(MAX_ATLAS_SIDE) {
        return None;
    }
    let out = placed
        .into_iter()
        .map(|(ci, x, y)| {
            let (mesh, s) = (charts[ci].mesh, charts[ci].side);
            (ci, Chart { mesh, x: x as u32 + padding, y: y as u32 + padding, width: s, height: s })
        })
        .collect();
    Some((w as u32, h as u32, out))
}

/// A triangle in snapped chart pixels, positively oriented; `idx` are its vertices in that order.
struct Tri {
    q: [[i64; 2]; 3],
    idx: [usize; 3],
    /// Twice the (positive) area in snapped units².
    d: i64,
    ti: usize,
}

/// Edge function of `a → b` at `p`: positive on the interior side of a positively oriented triangle.
fn edge(a: [i64; 2], b: [i64; 2], p: [i64; 2]) -> i64 {
    (b[0] - a[0]) * (p[1] - a[1]) - (b[1] - a[1]) * (p[0] - a[0])
}

/// The tie-break: an edge owns the centres on it when it points down (+v) or exactly left (−u).
fn owns_ties(a: [i64; 2], b: [i64; 2]) -> bool {
    let d = [b[0] - a[0], b[1] - a[1]];
    d[1] > 0 || (d[1] == 0 && d[0] < 0)
}

impl Tri {
    fn new(mesh: &Mesh, uv: &[[f64; 2]], ti: usize, side: u32) -> Option<Tri> {
        let t = mesh.triangles[ti].map(|v| v as usize);
        let scale = f64::from(side) * ONE as f64;
        let snap = |v: usize| uv[v].map(|x| (x * scale).round() as i64);
        let (mut idx, mut q) = (t, t.map(snap));
        let mut d = edge(q[0], q[1], q[2]);
        if d < 0 {
            idx.swap(1, 2);
            q.swap(1, 2);
            d = -d;
        }
        (d > 0).then_some(Tri { q, idx, d, ti })
    }

    fn edges(&self) -> [([i64; 2], [i64; 2]); 3] {
        [(self.q[1], self.q[2]), (self.q[2], self.q[0]), (self.q[0], self.q[1])]
    }

    /// Barycentric weights of `idx` at `p` if the centre `p` belongs to this triangle.
    fn contains(&self, p: [i64; 2]) -> Option<[f64; 3]> {
        let mut w = [0i64; 3];
        for (k, (a, b)) in self.edges().into_iter().enumerate() {
            let e = edge(a, b, p);
            if e < 0 || (e == 0 && !owns_ties(a, b)) {
                return None;
            }
            w[k] = e;
        }
        Some(w.map(|e| e as f64 / self.d as f64))
    }

    /// Whether the texel `[i, i+1] × [j, j+1]` and the triangle overlap with positive area (2D
    /// separating axes: the texel's sides and the triangle's edges).
    fn overlaps(&self, i: i64, j: i64) -> bool {
        let (x0, y0, x1, y1) = (i * ONE, j * ONE, (i + 1) * ONE, (j + 1) * ONE);
        let (xs, ys) = (self.q.map(|p| p[0]), self.q.map(|p| p[1]));
        if xs.iter().max() <= Some(&x0) || xs.iter().min() >= Some(&x1) {
            return false;
        }
        if ys.iter().max() <= Some(&y0) || ys.iter().min() >= Some(&y1) {
            return false;
        }
        let corners = [[x0, y0], [x1, y0], [x0, y1], [x1, y1]];
        self.edges().iter().all(|&(a, b)| corners.iter().any(|&c| edge(a, b, c) > 0))
    }

    /// Squared distance from `p` to the triangle and barycentric weights of the closest point.
    fn closest(&self, p: [i64; 2]) -> (f64, [f64; 3]) {
        if self.edges().iter().all(|&(a, b)| edge(a, b, p) >= 0) {
            let w = self.edges().map(|(a, b)| edge(a, b, p) as f64 / self.d as f64);
            return (0.0, w);
        }
        let f = |v: [i64; 2]| v.map(|x| x as f64);
        let pf = f(p);
        let mut best = (f64::INFINITY, [0.0; 3]);
        // Edge k runs from vertex (k+1)%3 to (k+2)%3 (opposite vertex k).
        for k in 0..3 {
            let (a, b) = (f(self.q[(k + 1) % 3]), f(self.q[(k + 2) % 3]));
            let ab = [b[0] - a[0], b[1] - a[1]];
            let t =
                (((pf[0] - a[0]) * ab[0] + (pf[1] - a[1]) * ab[1]) / (ab[0] * ab[0] + ab[1] * ab[1])).clamp(0.0, 1.0);
            let c = [a[0] + t * ab[0], a[1] + t * ab[1]];
            let d2 = (c[0] - pf[0]).powi(2) + (c[1] - pf[1]).powi(2);
            if d2 < best.0 {
                let mut w = [0.0; 3];
                w[(k + 1) % 3] = 1.0 - t;
                w[(k + 2) % 3] = t;
                best = (d2, w);
            }
        }
        (best.0 / (ONE * ONE) as f64, best.1)
    }

    /// Texel index range `[lo, hi)` per axis touched by the triangle's bounds, clipped to the chart.
    fn texel_bounds(&self, side: u32) -> [(i64, i64); 2] {
        [0, 1].map(|a| {
            let lo = self.q.iter().map(|p| p[a]).min().unwrap_or(0).div_euclid(ONE);
            let hi = (self.q.iter().map(|p| p[a]).max().unwrap_or(0) + ONE - 1).div_euclid(ONE);
            (lo.max(0), hi.min(i64::from(side)))
        })
    }
}

/// Per texel of a chart: the owning triangle (index into the `tris` list), the weights and whether
/// the centre is inside; `dist` is the conservative candidate's squared distance.
#[derive(Clone, Copy)]
struct Slot {
    tri: u32,
    w: [f64; 3],
    inside: bool,
    dist: f64,
}

const EMPTY: u32 = u32::MAX;

/// The texels of one chart and the number of centres claimed by more than one triangle.
fn rasterize(mesh: &Mesh, c: &Chartable, chart: &Chart, atlas_width: u32) -> (Vec<Texel>, usize) {
    let s = c.side as usize;
    let tris: Vec<Tri> = c.triangles.iter().filter_map(|&ti| Tri::new(mesh, &c.uv, ti, c.side)).collect();
    let mut slots = vec![Slot { tri: EMPTY, w: [0.0; 3], inside: false, dist: f64::INFINITY }; s * s];
    let mut overlapped = 0usize;
    let centre = |i: i64, j: i64| [i * ONE + ONE / 2, j * ONE + ONE / 2];
    for (k, t) in tris.iter().enumerate() {
        let [(i0, i1), (j0, j1)] = t.texel_bounds(c.side);
        for j in j0..j1 {
            for i in i0..i1 {
                if let Some(w) = t.contains(centre(i, j)) {
                    let slot = &mut slots[j as usize * s + i as usize];
                    if slot.tri == EMPTY {
                        *slot = Slot { tri: k as u32, w, inside: true, dist: 0.0 };
                    } else {
                        overlapped += 1;
                    }
                }
            }
        }
    }
    for (k, t) in tris.iter().enumerate() {
        let [(i0, i1), (j0, j1)] = t.texel_bounds(c.side);
        for j in j0..j1 {
            for i in i0..i1 {
                let slot = &mut slots[j as usize * s + i as usize];
                if slot.inside || !t.overlaps(i, j) {
                    continue;
                }
                let (d2, w) = t.closest(centre(i, j));
                if d2 < slot.dist {
                    *slot = Slot { tri: k as u32, w, inside: false, dist: d2 };
                }
            }
        }
    }
    let mut out = Vec::new();
    for (n, slot) in slots.iter().enumerate() {
        if slot.tri == EMPTY {
            continue;
        }
        let t = &tris[slot.tri as usize];
        let (i, j) = ((n % s) as u32, (n / s) as u32);
        let pixel = (chart.y + j) * atlas_width + chart.x + i;
        out.push(sample(mesh, t, slot, pixel, c.mesh));
    }
    (out, overlapped)
}

/// World position and normals at the weights of `slot` on triangle `t`.
fn sample(mesh: &Mesh, t: &Tri, slot: &Slot, pixel: u32, mi: usize) -> Texel {
    let pos = |v: usize| DVec3::from(mesh.positions[v].map(f64::from));
    let mut position = DVec3::ZERO;
    for k in 0..3 {
        position += pos(t.idx[k]) * slot.w[k];
    }
    let tv = mesh.triangles[t.ti].map(|v| v as usize);
    let geometric = (pos(tv[1]) - pos(tv[0])).cross(pos(tv[2]) - pos(tv[0])).try_normalize().unwrap_or(DVec3::Y);
    let shading = (mesh.normals.len() == mesh.positions.len())
        .then(|| {
            let mut n = DVec3::ZERO;
            for k in 0..3 {
                n += DVec3::from(mesh.normals[t.idx[k]].map(f64::from)) * slot.w[k];
            }
            n.try_normalize()
        })
        .flatten()
        .map_or(geometric, |n| if n.dot(geometric) < 0.0 { n * -1.0 } else { n });
    Texel {
        pixel,
        mesh: mi,
        triangle: t.ti,
        position: position.to_array(),
        normal: shading.to_array(),
        geometric_normal: geometric.to_array(),
        inside: slot.inside,
    }
}

/// Fills the pixels without a texel inside each chart and its padding ring, `iterations` rings deep:
/// each pass sets every still-empty pixel that has filled 8-neighbours in the same chart box to their
/// mean (all pixels of a pass read the previous pass, so the result does not depend on scan order).
/// Pixels outside every chart box are never written, and neighbours in another chart's box are never
/// read. Returns how many pixels were filled; errors if `pixels` is not `width · height` long.
pub fn dilate(atlas: &Atlas, pixels: &mut [[f32; 3]], iterations: u32) -> Result<usize, AtlasError> {
    let (w, h) = (atlas.width as usize, atlas.height as usize);
    if pixels.len() != w * h {
        return Err(AtlasError::Buffer { len: pixels.len(), width: atlas.width, height: atlas.height });
    }
    let mut has = vec![false; w * h];
    for t in &atlas.texels {
        if let Some(f) = has.get_mut(t.pixel as usize) {
            *f = true;
        }
    }
    let p = atlas.padding as usize;
    let mut filled = 0usize;
    for c in &atlas.charts {
        let (x0, y0) = ((c.x as usize).saturating_sub(p), (c.y as usize).saturating_sub(p));
        let (x1, y1) = (((c.x + c.width) as usize + p).min(w), ((c.y + c.height) as usize + p).min(h));
        for _ in 0..iterations {
            let mut updates = Vec::new();
            for y in y0..y1 {
                for x in x0..x1 {
                    if has[y * w + x] {
                        continue;
                    }
                    let (mut sum, mut count) = ([0.0f64; 3], 0u32);
                    for ny in y.saturating_sub(1).max(y0)..(y + 2).min(y1) {
                        for nx in x.saturating_sub(1).max(x0)..(x + 2).min(x1) {
                            if has[ny * w + nx] {
                                count += 1;
                                for (s, v) in sum.iter_mut().zip(pixels[ny * w + nx]) {
                                    *s += f64::from(v);
                                }
                            }
                        }
                    }
                    if count > 0 {
                        updates.push((y * w + x, sum.map(|s| (s / f64::from(count)) as f32)));
                    }
                }
            }
            if updates.is_empty() {
                break;
            }
            filled += updates.len();
            for (i, v) in updates {
                pixels[i] = v;
                has[i] = true;
            }
        }
    }
    Ok(filled)
}

#[cfg(test)]
mod tests;
