//! Atlas layout, rasterization and dilation, pinned against hand-derived values.

use std::path::Path;

use super::*;
use crate::scene::fixtures;
use crate::scene::{Scene, SceneFormat};

const IDENTITY: [[f64; 4]; 4] =
    [[1.0, 0.0, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0], [0.0, 0.0, 0.0, 1.0]];

/// A mesh in the y = 0 plane facing +Y with world `(x, 0, z)` per vertex and the given lightmap UVs.
fn flat_mesh(name: &str, xz: &[[f32; 2]], uv: &[[f32; 2]], triangles: Vec<[u32; 3]>) -> Mesh {
    Mesh {
        name: name.into(),
        positions: xz.iter().map(|p| [p[0], 0.0, p[1]]).collect(),
        normals: vec![[0.0, 1.0, 0.0]; xz.len()],
        uv: None,
        lightmap_uv: Some(uv.to_vec()),
        triangles,
        material: None,
        medium: None,
        to_world: IDENTITY,
    }
}

/// An `sx × sz` rectangle from the origin, UVs mapping x → u and z → v linearly onto `[u0, u1] × [v0, v1]`.
/// Triangles `[0, 2, 1]`, `[0, 3, 2]` are counter-clockwise seen from +Y.
fn quad(name: &str, sx: f32, sz: f32, u: [f32; 2], v: [f32; 2]) -> Mesh {
    let xz = [[0.0, 0.0], [sx, 0.0], [sx, sz], [0.0, sz]];
    let uv = [[u[0], v[0]], [u[1], v[0]], [u[1], v[1]], [u[0], v[1]]];
    flat_mesh(name, &xz, &uv, vec![[0, 2, 1], [0, 3, 2]])
}

fn scene(meshes: Vec<Mesh>) -> Scene {
    let mut s = Scene::empty(Path::new("test.gltf"), SceneFormat::Gltf);
    s.meshes = meshes;
    s
}

fn opts(tpm: f64, padding: u32) -> AtlasOptions {
    AtlasOptions { texels_per_metre: tpm, min_size: 1, max_size: 1024, padding }
}

#[test]
fn unit_quad_at_4_texels_per_metre_gives_4x4_centred_texels() {
    let s = scene(vec![quad("floor", 1.0, 1.0, [0.0, 1.0], [0.0, 1.0])]);
    let a = build(&s, &opts(4.0, 0)).expect("atlas");
    assert_eq!(a.charts, vec![Chart { mesh: 0, x: 0, y: 0, width: 4, height: 4 }]);
    assert_eq!((a.width, a.height), (4, 4));
    assert_eq!(a.texels.len(), 16);
    for (n, t) in a.texels.iter().enumerate() {
        let (i, j) = (n % 4, n / 4);
        assert_eq!(t.pixel as usize, n);
        assert!(t.inside);
        // Texel (i, j) centre = UV ((i + ½)/4, (j + ½)/4) = world (x, 0, z) with x = u, z = v.
        let want = [(i as f64 + 0.5) / 4.0, 0.0, (j as f64 + 0.5) / 4.0];
        assert_eq!(t.position, want, "texel ({i}, {j})");
        assert_eq!(t.normal, [0.0, 1.0, 0.0]);
        assert_eq!(t.geometric_normal, [0.0, 1.0, 0.0]);
        // The diagonal u = v is shared. Triangle [0, 2, 1] covers u > v; triangle [0, 3, 2] covers
        // v > u and, by the tie-break (its diagonal edge 0 → 2 points down), the diagonal itself.
        assert_eq!(t.triangle, usize::from(j >= i), "texel ({i}, {j})");
    }
    assert_eq!(a.texels.iter().filter(|t| t.triangle == 0).count(), 6);
    assert_eq!(a.inside_texels(), 16);
    assert_eq!(a.fill_ratio(), 1.0);
    assert!(a.skipped.is_empty() && a.warnings.is_empty());
}

#[test]
fn shared_edge_centres_are_assigned_once_in_a_fan() {
    // A square split into four triangles around its centre; UV = world, chart 8×8 at 8 texels/m.
    // Centres on the two diagonals are shared by two triangles each.
    let xz = [[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0], [0.5, 0.5]];
    let tris = vec![[4, 1, 0], [4, 2, 1], [4, 3, 2], [4, 0, 3]];
    let s = scene(vec![flat_mesh("fan", &xz, &xz, tris)]);
    let a = build(&s, &opts(8.0, 0)).expect("atlas");
    assert_eq!(a.charts[0].width, 8);
    // Every one of the 64 centres exactly once (texels are unique per pixel by construction; all
    // inside, none left to the conservative pass).
    assert_eq!(a.texels.len(), 64);
    assert_eq!(a.inside_texels(), 64);
    assert!(a.warnings.is_empty(), "{:?}", a.warnings);
}

#[test]
fn inside_texel_area_approximates_the_mesh_area() {
    // A 2 m × 3 m rectangle (A = 6 m²) using UVs [0.1, 0.9] × [0.2, 0.7] (a = 0.4): one UV unit spans
    // √15 m, so at 10 texels/m the chart side is ⌈38.73⌉ = 39 and a texel stands for 15 / 39² m².
    let s = scene(vec![quad("wall", 2.0, 3.0, [0.1, 0.9], [0.2, 0.7])]);
    let a = build(&s, &opts(10.0, 2)).expect("atlas");
    assert_eq!(a.charts[0].width, 39);
    // In chart pixels the rectangle spans u ∈ [3.9, 35.1], v ∈ [7.8, 27.3]: centres i + ½ for
    // i = 4..=34 (31 columns) and j = 8..=26 (19 rows) → 589 inside texels, i.e. 589 · 15 / 1521 =
    // 5.809 m² (−3.2 %: the rectangle is 31.2 × 19.5 texels, counted as 31 × 19).
    assert_eq!(a.inside_texels(), 589);
    let estimate = a.inside_texels() as f64 * 15.0 / (39.0 * 39.0);
    assert!((estimate - 6.0).abs() / 6.0 < 0.035, "area estimate {estimate}");
    // Conservative texels ring the rectangle, sampled on its border.
    assert!(a.texels.iter().any(|t| !t.inside));
    for t in &a.texels {
        let inside = |x: f64, hi: f64| (-1e-12..=hi + 1e-12).contains(&x);
        assert!(inside(t.position[0], 2.0) && inside(t.position[2], 3.0), "{t:?}");
    }
}

#[test]
fn conservative_texels_sample_the_closest_point() {
    // UV triangle (0, 0), (0.875, 0), (0, 0.875) on a 4×4 chart: pixel corners (0,0), (3.5,0), (0,3.5).
    // Centres with i + j ≤ 2 are inside (6); texels with i + j = 3 overlap the hypotenuse x + y = 3.5
    // but their centres (sum 4) lie outside: the closest point moves each centre by −0.25 on both axes.
    let xz = [[0.0, 0.0], [0.875, 0.0], [0.0, 0.875]];
    let s = scene(vec![flat_mesh("tri", &xz, &xz, vec![[0, 2, 1]])]);
    let mut o = opts(4.0, 0);
    o.min_size = 4; // A/a = 1 → ⌈4 · 1⌉ = 4
    let a = build(&s, &o).expect("atlas");
    assert_eq!(a.charts[0].width, 4);
    assert_eq!(a.inside_texels(), 6);
    assert_eq!(a.texels.len(), 10);
    let at = |i: u32, j: u32| a.texels.iter().find(|t| t.pixel == j * a.width + i).expect("texel");
    for (i, j) in [(3, 0), (2, 1), (1, 2), (0, 3)] {
        let t = at(i, j);
        assert!(!t.inside);
        let want = [(i as f64 + 0.25) / 4.0, 0.0, (j as f64 + 0.25) / 4.0];
        for c in 0..3 {
            assert!((t.position[c] - want[c]).abs() < 1e-12, "({i}, {j}): {:?} vs {want:?}", t.position);
        }
    }
    assert_eq!(at(1, 1).position, [0.375, 0.0, 0.375]);
}

#[test]
fn charts_do_not_overlap_including_padding() {
    let meshes: Vec<Mesh> = [1.0f32, 2.5, 0.5, 3.0, 1.0, 0.25, 2.0]
        .iter()
        .enumerate()
        .map(|(k, &size)| quad(&format!("q{k}"), size, size, [0.0, 1.0], [0.0, 1.0]))
        .collect();
    let s = scene(meshes);
    let p = 3;
    let a = build(&s, &opts(8.0, p)).expect("atlas");
    assert_eq!(a, build(&s, &opts(8.0, p)).expect("again"), "deterministic");
    assert_eq!(a.charts.len(), 7);
    // Sides ⌈8 · size⌉: 8, 20, 4, 24, 8, 2, 16; padded +6: 14, 26, 10, 30, 14, 8, 22 → total area
    // 196 + 676 + 100 + 900 + 196 + 64 + 484 = 2616, √ = 51.1 → width 64.
    assert_eq!(a.width, 64);
    let mut sides: Vec<u32> = a.charts.iter().map(|c| c.width).collect();
    sides.sort_unstable();
    assert_eq!(sides, [2, 4, 8, 8, 16, 20, 24]);
    let boxes: Vec<[u32; 4]> =
        a.charts.iter().map(|c| [c.x - p, c.y - p, c.x + c.width + p, c.y + c.height + p]).collect();
    for (k, b) in boxes.iter().enumerate() {
        assert!(b[2] <= a.width && b[3] <= a.height, "{b:?}");
        for o in &boxes[k + 1..] {
            let apart = b[2] <= o[0] || o[2] <= b[0] || b[3] <= o[1] || o[3] <= b[1];
            assert!(apart, "{b:?} overlaps {o:?}");
        }
    }
    // Every texel lies inside its own mesh's chart.
    for t in &a.texels {
        let c = a.charts.iter().find(|c| c.mesh == t.mesh).expect("chart");
        let (x, y) = (t.pixel % a.width, t.pixel / a.width);
        assert!((c.x..c.x + c.width).contains(&x) && (c.y..c.y + c.height).contains(&y));
    }
    assert!(a.texels.windows(2).all(|w| w[0].pixel < w[1].pixel), "ordered, one per pixel");
}

#[test]
fn skipped_meshes_are_reported_and_nothing_to_bake_is_an_error() {
    let mut no_uv = quad("no_uv", 1.0, 1.0, [0.0, 1.0], [0.0, 1.0]);
    no_uv.lightmap_uv = None;
    let mut fog_box = fixtures::cube("fog_box", 1.0);
    fog_box.lightmap_uv = Some(vec![[0.5, 0.5]; 8]);
    let collapsed = quad("collapsed", 1.0, 1.0, [0.3, 0.3], [0.0, 1.0]); // zero UV width
    let mut s = scene(vec![no_uv, fog_box, collapsed, quad("ok", 1.0, 1.0, [0.0, 1.0], [0.0, 1.0])]);
    s.media.push(fixtures::medium("fog", 0.5, Boundary::Mesh(1)));
    let a = build(&s, &opts(4.0, 1)).expect("atlas");
    assert_eq!(a.charts.len(), 1);
    assert_eq!(a.charts[0].mesh, 3);
    let reasons: Vec<(usize, &str)> = a.skipped.iter().map(|k| (k.mesh, k.reason.as_str())).collect();
    assert_eq!(reasons.len(), 3);
    assert!(reasons[0].0 == 0 && reasons[0].1.contains("has no lightmap UVs (glTF TEXCOORD_1"), "{reasons:?}");
    assert!(reasons[1].0 == 1 && reasons[1].1.contains("bounds the participating medium \"fog\""), "{reasons:?}");
    assert!(reasons[2].0 == 2 && reasons[2].1.contains("no triangle with non-zero area"), "{reasons:?}");
    assert!(a.warnings.iter().any(|w| w.location == "collapsed" && w.message.contains("2 triangles")));

    s.meshes.pop();
    let msg = build(&s, &opts(4.0, 1)).expect_err("nothing").to_string();
    assert!(msg.contains("test.gltf: no mesh can be lightmapped"), "{msg}");
    for name in ["\"no_uv\"", "\"fog_box\"", "\"collapsed\""] {
        assert!(msg.contains(name), "{msg}");
    }
}

#[test]
fn bad_uvs_and_options_are_errors_naming_the_mesh() {
    let s = scene(vec![quad("tiled", 1.0, 1.0, [0.0, 2.0], [0.0, 1.0])]);
    let msg = build(&s, &opts(4.0, 1)).expect_err("outside").to_string();
    assert!(msg.contains("mesh \"tiled\": lightmap UV of vertex 1 is [2.0, 0.0], outside [0, 1]"), "{msg}");
    let s = scene(vec![quad("nan", 1.0, 1.0, [0.0, f32::NAN], [0.0, 1.0])]);
    assert!(build(&s, &opts(4.0, 1)).expect_err("nan").to_string().contains("mesh \"nan\""));
    // Within the tolerance: clamped with a warning.
    let s = scene(vec![quad("rounded", 1.0, 1.0, [-0.0005, 1.0005], [0.0, 1.0])]);
    let a = build(&s, &opts(4.0, 1)).expect("clamped");
    assert!(a.warnings.iter().any(|w| w.location == "rounded" && w.message.contains("4 lightmap UVs")));
    for bad in [
        AtlasOptions { texels_per_metre: 0.0, ..opts(1.0, 1) },
        AtlasOptions { texels_per_metre: f64::NAN, ..opts(1.0, 1) },
        AtlasOptions { min_size: 0, ..opts(1.0, 1) },
        AtlasOptions { min_size: 64, max_size: 32, ..opts(1.0, 1) },
    ] {
        assert!(build(&s, &bad).expect_err("options").to_string().starts_with("lightmap atlas: "));
    }
    // A chart clamped to max_size is reported.
    let s = scene(vec![quad("big", 100.0, 100.0, [0.0, 1.0], [0.0, 1.0])]);
    let a = build(&s, &AtlasOptions { max_size: 64, ..opts(16.0, 1) }).expect("clamped chart");
    assert_eq!(a.charts[0].width, 64);
    assert!(a.warnings[0].message.contains("needs 1600 texels a side"), "{:?}", a.warnings);
}

/// A hand-made atlas: `charts` with the given texel pixels.
fn manual(width: u32, height: u32, padding: u32, charts: Vec<Chart>, pixels: &[u32]) -> Atlas {
    let texels = pixels
        .iter()
        .map(|&pixel| Texel {
            pixel,
            mesh: 0,
            triangle: 0,
            position: [0.0; 3],
            normal: [0.0, 1.0, 0.0],
            geometric_normal: [0.0, 1.0, 0.0],
            inside: true,
        })
        .collect();
    Atlas { width, height, padding, charts, texels, skipped: vec![], warnings: vec![] }
}

#[test]
fn dilation_fills_the_padding_ring_with_neighbour_means() {
    // 4×4 atlas, one 2×2 chart at (1, 1), padding 1; baked values 1, 2 / 3, 4 (grey).
    let a = manual(4, 4, 1, vec![Chart { mesh: 0, x: 1, y: 1, width: 2, height: 2 }], &[5, 6, 9, 10]);
    let mut px = vec![[0.0f32; 3]; 16];
    for (p, v) in [(5, 1.0), (6, 2.0), (9, 3.0), (10, 4.0)] {
        px[p] = [v; 3];
    }
    let filled = dilate(&a, &mut px, 1).expect("dilate");
    assert_eq!(filled, 12);
    let g: Vec<f32> = px.iter().map(|p| p[0]).collect();
    // By hand: corner (0,0) sees only (1,1) = 1; edge (1,0) sees (1,1), (2,1) → 1.5; (0,1) sees
    // (1,1), (1,2) → 2; and so on around the ring.
    #[rustfmt::skip]
    let want = [
        1.0, 1.5, 1.5, 2.0,
        2.0, 1.0, 2.0, 3.0,
        2.0, 3.0, 4.0, 3.0,
        3.0, 3.5, 3.5, 4.0,
    ];
    assert_eq!(g, want);
    // Dilation starts from the texels again each call: repeating it fills the same 12 pixels with the
    // same values (no further rings exist inside this chart box).
    assert_eq!(dilate(&a, &mut px, 3).expect("again"), 12);
    assert_eq!(px.iter().map(|p| p[0]).collect::<Vec<f32>>(), want);
    let mut short = vec![[0.0f32; 3]; 15];
    assert!(dilate(&a, &mut short, 1).expect_err("length").to_string().contains("holds 15 pixels"));
}

#[test]
fn dilation_fills_gaps_over_iterations_and_never_crosses_charts() {
    // 8×3 atlas, padding 0: chart A = columns 0..4, chart B = columns 4..8, rows 0..3. A has one
    // baked texel at (0, 1) = 8; B has one at (7, 1) = 100.
    let charts =
        vec![Chart { mesh: 0, x: 0, y: 0, width: 4, height: 3 }, Chart { mesh: 1, x: 4, y: 0, width: 4, height: 3 }];
    let a = manual(8, 3, 0, charts, &[8, 15]);
    let mut px = vec![[0.0f32; 3]; 24];
    px[8] = [8.0; 3];
    px[15] = [100.0; 3];
    // One pass fills the 5 neighbours of each baked texel: (x 1, y 0) but not (x 2, y 0).
    assert_eq!(dilate(&a, &mut px, 1).expect("one pass"), 2 * 5);
    assert_eq!(px[1][0], 8.0);
    assert_eq!(px[2][0], 0.0);
    // Dilation restarts from the texels: 10 passes fill all 11 empty pixels of each chart.
    assert_eq!(dilate(&a, &mut px, 10).expect("rest"), 2 * 11);
    for (i, p) in px.iter().enumerate() {
        let want = if i % 8 < 4 { 8.0 } else { 100.0 };
        assert_eq!(p[0], want, "pixel {i}: a constant chart dilates to that constant, never mixing charts");
    }
}

#[test]
fn bundled_fog_room_charts_every_lightmapped_mesh() {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes/fog_room.gltf");
    let s = Scene::load(&path).expect("fog_room loads");
    let o = AtlasOptions { texels_per_metre: 16.0, min_size: 4, max_size: 1024, padding: 2 };
    let a = build(&s, &o).expect("atlas");
    let lightmapped: Vec<usize> = (0..s.meshes.len())
        .filter(|&i| {
            s.meshes[i].lightmap_uv.is_some()
                && s.meshes[i].medium.is_none()
                && !s.media.iter().any(|m| m.boundary == Boundary::Mesh(i))
        })
        .collect();
    let mut charted: Vec<usize> = a.charts.iter().map(|c| c.mesh).collect();
    charted.sort_unstable();
    assert_eq!(charted, lightmapped);
    assert_eq!(a.charts.len() + a.skipped.len(), s.meshes.len());
    // Each mesh's inside texels, scaled by its chart's world area per texel, approximate its area.
    for c in &a.charts {
        let m = &s.meshes[c.mesh];
        let (mut area, mut uv_area) = (0.0, 0.0);
        for t in &m.triangles {
            let p = t.map(|v| glam::DVec3::from(m.positions[v as usize].map(f64::from)));
            area += 0.5 * (p[1] - p[0]).cross(p[2] - p[0]).length();
            let q = t.map(|v| m.lightmap_uv.as_ref().expect("uv")[v as usize].map(f64::from));
            uv_area +=
                0.5 * ((q[1][0] - q[0][0]) * (q[2][1] - q[0][1]) - (q[1][1] - q[0][1]) * (q[2][0] - q[0][0])).abs();
        }
        let n = a.texels.iter().filter(|t| t.inside && t.mesh == c.mesh).count() as f64;
        let all = a.texels.iter().filter(|t| t.mesh == c.mesh).count() as f64;
        let texels_per_uv = f64::from(c.width * c.height);
        // The texels overlapping the triangles cover them: their count bounds the UV area in texels.
        assert!(
            all >= uv_area * texels_per_uv,
            "{}: {all} texels for {} texels of UV area",
            m.name,
            uv_area * texels_per_uv
        );
        // Centre counting on an island of w × h texels is off by at most (w + h + 1) / (w h); the boxes'
        // islands are about 13 × 20 texels at 16 texels/m, so up to 13 %.
        let estimate = n * (area / uv_area) / texels_per_uv;
        println!("  {}: chart {}², area {area:.3} m², inside-texel estimate {estimate:.3} m²", m.name, c.width);
        assert!((estimate - area).abs() / area < 0.13, "{}: {estimate} vs {area}", m.name);
    }
    println!(
        "fog_room @16/m: atlas {}x{}, {} charts, {} texels ({} inside), fill ratio {:.3}, texel coverage {:.3}",
        a.width,
        a.height,
        a.charts.len(),
        a.texels.len(),
        a.inside_texels(),
        a.fill_ratio(),
        a.texels.len() as f64 / (f64::from(a.width) * f64::from(a.height))
    );
}
