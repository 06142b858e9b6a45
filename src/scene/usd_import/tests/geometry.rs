//! Units, axes, transforms, triangulation, winding, primvars, traversal rules.

use super::{assert_close, assert_warns, f64s, load, warnings_at};
use crate::scene::{LightKind, Scene};

pub(super) const CM_SCALE: &str = r#"#usda 1.0
(
    metersPerUnit = 0.01
    upAxis = "Y"
)

def Xform "World"
{
    double3 xformOp:translate = (0, 200, 0)
    uniform token[] xformOpOrder = ["xformOp:translate"]

    def Mesh "Tri"
    {
        uniform token subdivisionScheme = "none"
        int[] faceVertexCounts = [3]
        int[] faceVertexIndices = [0, 1, 2]
        point3f[] points = [(0, 0, 0), (100, 0, 0), (0, 100, 0)]
    }

    def SphereLight "Bulb"
    {
        float inputs:intensity = 683
        float inputs:radius = 10
        bool treatAsPoint = true
    }

    def Camera "Cam"
    {
        float2 clippingRange = (10, 10000)
    }
}
"#;

pub(super) const NO_UNITS: &str = r#"#usda 1.0
(
    upAxis = "Y"
)

def Mesh "Tri"
{
    uniform token subdivisionScheme = "none"
    int[] faceVertexCounts = [3]
    int[] faceVertexIndices = [0, 1, 2]
    point3f[] points = [(0, 0, 0), (100, 0, 0), (0, 100, 0)]
}
"#;

pub(super) const Z_UP: &str = r#"#usda 1.0
(
    metersPerUnit = 1
    upAxis = "Z"
)

def Mesh "Tri"
{
    uniform token subdivisionScheme = "none"
    int[] faceVertexCounts = [3]
    int[] faceVertexIndices = [0, 1, 2]
    point3f[] points = [(1, 2, 3), (0, 0, 0), (1, 0, 0)]
}

def DistantLight "Sun"
{
}
"#;

pub(super) const NESTED_XFORMS: &str = r#"#usda 1.0
(
    metersPerUnit = 1
    upAxis = "Y"
)

def Xform "Parent"
{
    double3 xformOp:translate = (10, 0, 0)
    float xformOp:rotateZ = 90
    float3 xformOp:scale = (2, 2, 2)
    uniform token[] xformOpOrder = ["xformOp:translate", "xformOp:rotateZ", "xformOp:scale"]

    def Xform "Child"
    {
        quatf xformOp:orient = (0.70710677, 0.70710677, 0, 0)
        matrix4d xformOp:transform = ( (1, 0, 0, 0), (0, 1, 0, 0), (0, 0, 1, 0), (0, 0, 1, 1) )
        uniform token[] xformOpOrder = ["xformOp:orient", "xformOp:transform"]

        def Mesh "Tri"
        {
            double3 xformOp:translate = (0, 1, 0)
            uniform token[] xformOpOrder = ["xformOp:translate"]
            uniform token subdivisionScheme = "none"
            int[] faceVertexCounts = [3]
            int[] faceVertexIndices = [0, 1, 2]
            point3f[] points = [(1, 0, 0), (0, 0, 0), (0, 0, 1)]
        }
    }

    def Mesh "Euler"
    {
        float3 xformOp:rotateXYZ = (90, 0, 90)
        uniform token[] xformOpOrder = ["xformOp:rotateXYZ"]
        uniform token subdivisionScheme = "none"
        int[] faceVertexCounts = [3]
        int[] faceVertexIndices = [0, 1, 2]
        point3f[] points = [(0, 1, 0), (0, 0, 0), (1, 0, 0)]
    }

    def Mesh "Reset"
    {
        double3 xformOp:translate = (0, 0, 5)
        uniform token[] xformOpOrder = ["!resetXformStack!", "xformOp:translate"]
        uniform token subdivisionScheme = "none"
        int[] faceVertexCounts = [3]
        int[] faceVertexIndices = [0, 1, 2]
        point3f[] points = [(0, 0, 0), (1, 0, 0), (0, 1, 0)]
    }

    def Mesh "Inverted"
    {
        double3 xformOp:translate = (0, 0, 5)
        uniform token[] xformOpOrder = ["!invert!xformOp:translate"]
        uniform token subdivisionScheme = "none"
        int[] faceVertexCounts = [3]
        int[] faceVertexIndices = [0, 1, 2]
        point3f[] points = [(0, 0, 0), (1, 0, 0), (0, 1, 0)]
    }
}
"#;

pub(super) const POLYGONS: &str = r#"#usda 1.0
(
    metersPerUnit = 1
    upAxis = "Y"
)

def Mesh "Right"
{
    uniform token subdivisionScheme = "none"
    int[] faceVertexCounts = [4, 5]
    int[] faceVertexIndices = [0, 1, 2, 3, 4, 5, 6, 7, 8]
    point3f[] points = [(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0), (2, 0, 0), (3, 0, 0), (3.5, 1, 0), (2.5, 2, 0), (1.5, 1, 0)]
}

def Mesh "Left"
{
    uniform token subdivisionScheme = "none"
    uniform token orientation = "leftHanded"
    int[] faceVertexCounts = [4, 5]
    int[] faceVertexIndices = [0, 1, 2, 3, 4, 5, 6, 7, 8]
    point3f[] points = [(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0), (2, 0, 0), (3, 0, 0), (3.5, 1, 0), (2.5, 2, 0), (1.5, 1, 0)]
}

def Mesh "Mirrored"
{
    float3 xformOp:scale = (-1, 1, 1)
    uniform token[] xformOpOrder = ["xformOp:scale"]
    uniform token subdivisionScheme = "none"
    int[] faceVertexCounts = [4, 5]
    int[] faceVertexIndices = [0, 1, 2, 3, 4, 5, 6, 7, 8]
    point3f[] points = [(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0), (2, 0, 0), (3, 0, 0), (3.5, 1, 0), (2.5, 2, 0), (1.5, 1, 0)]
}

def Mesh "Holes"
{
    uniform token subdivisionScheme = "none"
    int[] holeIndices = [0]
    int[] faceVertexCounts = [4, 5]
    int[] faceVertexIndices = [0, 1, 2, 3, 4, 5, 6, 7, 8]
    point3f[] points = [(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0), (2, 0, 0), (3, 0, 0), (3.5, 1, 0), (2.5, 2, 0), (1.5, 1, 0)]
}
"#;

pub(super) const INDEXED_ST: &str = r#"#usda 1.0
(
    metersPerUnit = 1
    upAxis = "Y"
)

def Mesh "Quad"
{
    uniform token subdivisionScheme = "none"
    int[] faceVertexCounts = [4]
    int[] faceVertexIndices = [0, 1, 2, 3]
    point3f[] points = [(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0)]
    texCoord2f[] primvars:st = [(0, 0), (1, 0), (1, 1), (0, 1)] (
        interpolation = "vertex"
    )
    int[] primvars:st:indices = [2, 3, 0, 1]
    texCoord2f[] primvars:lightmapUV = [(0.5, 0.5), (0.25, 0.5), (0.25, 0.25), (0.5, 0.25)] (
        interpolation = "vertex"
    )
}

def Mesh "Both"
{
    uniform token subdivisionScheme = "none"
    int[] faceVertexCounts = [4]
    int[] faceVertexIndices = [0, 1, 2, 3]
    point3f[] points = [(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0)]
    texCoord2f[] primvars:st1 = [(0.75, 0.25)] (
        interpolation = "constant"
    )
    texCoord2f[] primvars:lightmapUV = [(0.5, 0.5), (0.25, 0.5), (0.25, 0.25), (0.5, 0.25)] (
        interpolation = "vertex"
    )
}
"#;

pub(super) const FACE_VARYING: &str = r#"#usda 1.0
(
    metersPerUnit = 1
    upAxis = "Y"
)

def Mesh "Split"
{
    uniform token subdivisionScheme = "none"
    int[] faceVertexCounts = [3, 3]
    int[] faceVertexIndices = [0, 1, 2, 0, 2, 3]
    point3f[] points = [(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0)]
    texCoord2f[] primvars:st = [(0, 0), (1, 0), (1, 1), (0, 1), (0.5, 0.5)] (
        interpolation = "faceVarying"
    )
    int[] primvars:st:indices = [0, 1, 2, 0, 4, 3]
}
"#;

pub(super) const UNIFORM_NORMALS: &str = r#"#usda 1.0
(
    metersPerUnit = 1
    upAxis = "Y"
)

def Mesh "Fold"
{
    float xformOp:rotateX = 90
    float3 xformOp:scale = (2, 1, 1)
    uniform token[] xformOpOrder = ["xformOp:rotateX", "xformOp:scale"]
    uniform token subdivisionScheme = "none"
    int[] faceVertexCounts = [3, 3]
    int[] faceVertexIndices = [0, 1, 2, 0, 3, 1]
    point3f[] points = [(0, 0, 0), (1, 0, 0), (0, 1, 0), (0, 0, 1)]
    normal3f[] normals = [(0, 0, 1), (0.70710677, 0.70710677, 0)] (
        interpolation = "uniform"
    )
}
"#;

pub(super) const SKIPPED_PRIMS: &str = r#"#usda 1.0
(
    metersPerUnit = 1
    upAxis = "Y"
)

def Mesh "Hidden"
{
    token visibility = "invisible"
    uniform token subdivisionScheme = "none"
    int[] faceVertexCounts = [3]
    int[] faceVertexIndices = [0, 1, 2]
    point3f[] points = [(0, 0, 0), (1, 0, 0), (0, 1, 0)]
}

def Xform "HiddenParent"
{
    token visibility = "invisible"

    def Mesh "Child"
    {
        uniform token subdivisionScheme = "none"
        int[] faceVertexCounts = [3]
        int[] faceVertexIndices = [0, 1, 2]
        point3f[] points = [(0, 0, 0), (1, 0, 0), (0, 1, 0)]
    }
}

def Mesh "Inactive" (
    active = false
)
{
    uniform token subdivisionScheme = "none"
    int[] faceVertexCounts = [3]
    int[] faceVertexIndices = [0, 1, 2]
    point3f[] points = [(0, 0, 0), (1, 0, 0), (0, 1, 0)]
}

def Mesh "Guide"
{
    uniform token purpose = "guide"
    uniform token subdivisionScheme = "none"
    int[] faceVertexCounts = [3]
    int[] faceVertexIndices = [0, 1, 2]
    point3f[] points = [(0, 0, 0), (1, 0, 0), (0, 1, 0)]
}

def Xform "ProxyParent"
{
    uniform token purpose = "proxy"

    def Mesh "Child"
    {
        uniform token subdivisionScheme = "none"
        int[] faceVertexCounts = [3]
        int[] faceVertexIndices = [0, 1, 2]
        point3f[] points = [(0, 0, 0), (1, 0, 0), (0, 1, 0)]
    }
}

def Mesh "Visible"
{
    uniform token subdivisionScheme = "none"
    int[] faceVertexCounts = [3]
    int[] faceVertexIndices = [0, 1, 2]
    point3f[] points = [(0, 0, 0), (1, 0, 0), (0, 1, 0)]
}

def Mesh "Subdiv"
{
    int[] faceVertexCounts = [3]
    int[] faceVertexIndices = [0, 1, 2]
    point3f[] points = [(0, 0, 0), (1, 0, 0), (0, 1, 0)]
}

def Mesh "Loop"
{
    uniform token subdivisionScheme = "loop"
    int[] faceVertexCounts = [3]
    int[] faceVertexIndices = [0, 1, 2]
    point3f[] points = [(0, 0, 0), (1, 0, 0), (0, 1, 0)]
}
"#;

pub(super) const INSTANCES: &str = r#"#usda 1.0
(
    metersPerUnit = 1
    upAxis = "Y"
)

class "Proto"
{
    def Mesh "Tri"
    {
        uniform token subdivisionScheme = "none"
        int[] faceVertexCounts = [3]
        int[] faceVertexIndices = [0, 1, 2]
        point3f[] points = [(0, 0, 0), (1, 0, 0), (0, 1, 0)]
    }
}

def Xform "A" (
    instanceable = true
    references = </Proto>
)
{
    double3 xformOp:translate = (5, 0, 0)
    uniform token[] xformOpOrder = ["xformOp:translate"]
}

def Xform "B" (
    instanceable = true
    references = </Proto>
)
{
    double3 xformOp:translate = (0, 5, 0)
    uniform token[] xformOpOrder = ["xformOp:translate"]
}
"#;

pub(super) const TIME_SAMPLES: &str = r#"#usda 1.0
(
    metersPerUnit = 1
    upAxis = "Y"
)

def Mesh "Moving"
{
    double3 xformOp:translate.timeSamples = {
        1: (1, 0, 0),
        10: (5, 0, 0),
    }
    uniform token[] xformOpOrder = ["xformOp:translate"]
    uniform token subdivisionScheme = "none"
    int[] faceVertexCounts = [3]
    int[] faceVertexIndices = [0, 1, 2]
    point3f[] points = [(0, 0, 0), (1, 0, 0), (0, 1, 0)]
}

def SphereLight "Blink"
{
    float inputs:intensity.timeSamples = {
        0: 1366,
        5: 0,
    }
}
"#;

fn mesh<'a>(scene: &'a Scene, name: &str) -> &'a crate::scene::Mesh {
    scene.meshes.iter().find(|m| m.name == name).unwrap_or_else(|| panic!("no mesh {name}"))
}

fn positions(scene: &Scene, name: &str) -> Vec<[f64; 3]> {
    mesh(scene, name).positions.iter().map(|&p| f64s(p)).collect()
}

#[track_caller]
fn assert_points(got: &[[f64; 3]], expected: &[[f64; 3]]) {
    assert_eq!(got.len(), expected.len(), "got {got:?}");
    for (g, e) in got.iter().zip(expected) {
        assert_close(*g, *e, 1e-6);
    }
}

#[test]
fn meters_per_unit_scales_lengths() {
    let s = load("cm", CM_SCALE);
    // 100 cm points under a 200 cm translation → metres.
    assert_points(&positions(&s, "/World/Tri"), &[[0.0, 2.0, 0.0], [1.0, 2.0, 0.0], [0.0, 3.0, 0.0]]);
    let m = mesh(&s, "/World/Tri").to_world;
    assert_close([m[0][0], m[1][1], m[2][2], m[3][1]], [0.01, 0.01, 0.01, 2.0], 1e-12);
    // treatAsPoint radius 10 cm = 0.1 m: I = L·πr² = 1 · π · 0.01.
    let bulb = &s.lights[0];
    assert_eq!(bulb.kind, LightKind::Point { position: [0.0, 2.0, 0.0] });
    assert_close(bulb.radiance, [std::f64::consts::PI * 0.01; 3], 1e-7);
    let cam = &s.cameras[0];
    assert_close([cam.znear, cam.zfar.unwrap_or(0.0)], [0.1, 100.0], 1e-12);
    assert!(s.warnings.iter().all(|w| !w.message.contains("metersPerUnit")), "{:#?}", s.warnings);
}

#[test]
fn unauthored_meters_per_unit_is_centimetres_with_a_warning() {
    let w = super::write("nounits", NO_UNITS);
    let s = super::import(&w.path).expect("import");
    assert_points(&positions(&s, "/Tri"), &[[0.0; 3], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]);
    assert_warns(&s, &w.path.display().to_string(), "does not author metersPerUnit");
}

#[test]
fn z_up_stage_is_rotated_to_y_up() {
    let s = load("zup", Z_UP);
    // Rx(−90°): (x, y, z) → (x, z, −y).
    assert_points(&positions(&s, "/Tri"), &[[1.0, 3.0, -2.0], [0.0; 3], [1.0, 0.0, 0.0]]);
    // The sun's local −Z is the stage's down, world −Y.
    let LightKind::Directional { direction, .. } = s.lights[0].kind else { panic!("{:?}", s.lights[0]) };
    assert_close(direction, [0.0, -1.0, 0.0], 1e-12);
}

#[test]
fn nested_xform_ops_compose_to_world() {
    let s = load("xforms", NESTED_XFORMS);
    // Worked by hand in the order USD applies ops (last listed first): mesh translate, child matrix
    // (+Z), orient 90° about X, parent scale 2, rotateZ 90°, translate (10, 0, 0).
    assert_points(&positions(&s, "/Parent/Child/Tri"), &[[12.0, 2.0, 2.0], [12.0, 0.0, 2.0], [14.0, 0.0, 2.0]]);
    // rotateXYZ applies X then Y then Z: (0,1,0) → (0,0,1); (1,0,0) → (0,1,0); then the parent.
    assert_points(&positions(&s, "/Parent/Euler"), &[[10.0, 0.0, 2.0], [10.0, 0.0, 0.0], [8.0, 0.0, 0.0]]);
    // !resetXformStack! ignores the parent.
    assert_points(&positions(&s, "/Parent/Reset"), &[[0.0, 0.0, 5.0], [1.0, 0.0, 5.0], [0.0, 1.0, 5.0]]);
    // !invert! translates by −5 in the parent's (scaled, rotated) frame.
    assert_points(&positions(&s, "/Parent/Inverted"), &[[10.0, 0.0, -10.0], [10.0, 2.0, -10.0], [8.0, 0.0, -10.0]]);
}

#[test]
fn polygons_are_fan_triangulated_with_winding_from_orientation_and_mirroring() {
    let s = load("polys", POLYGONS);
    let right = [[0, 1, 2], [0, 2, 3], [4, 5, 6], [4, 6, 7], [4, 7, 8]];
    let left = right.map(|[a, b, c]| [a, c, b]);
    assert_eq!(mesh(&s, "/Right").triangles, right, "quad → 2, pentagon → 3 triangles");
    assert_eq!(mesh(&s, "/Left").triangles, left);
    assert_eq!(mesh(&s, "/Mirrored").triangles, left, "a negative-determinant transform flips the winding");
    assert_eq!(mesh(&s, "/Holes").triangles, right[2..]);
    // Computed normals follow the final winding: +Z, −Z for leftHanded, +Z again after mirroring.
    for (name, n) in [("/Right", [0.0, 0.0, 1.0]), ("/Left", [0.0, 0.0, -1.0]), ("/Mirrored", [0.0, 0.0, 1.0])] {
        for v in [0, 2, 4, 6] {
            assert_close(f64s(mesh(&s, name).normals[v]), n, 1e-6);
        }
    }
}

#[test]
fn indexed_st_is_expanded_and_lightmap_uvs_are_read() {
    let s = load("st", INDEXED_ST);
    let q = mesh(&s, "/Quad");
    assert_eq!(q.uv.as_deref(), Some(&[[1.0, 0.0], [0.0, 0.0], [0.0, 1.0], [1.0, 1.0]][..]));
    assert_eq!(q.lightmap_uv.as_deref(), Some(&[[0.5, 0.5], [0.25, 0.5], [0.25, 0.75], [0.5, 0.75]][..]));
    assert_eq!(q.positions.len(), 4, "vertex primvars do not split vertices");
    // primvars:st1 wins over primvars:lightmapUV; constant → every vertex.
    assert_eq!(mesh(&s, "/Both").lightmap_uv.as_deref(), Some(&[[0.75, 0.75]; 4][..]));
    assert_eq!(mesh(&s, "/Both").uv, None);
}

#[test]
fn face_varying_uvs_split_vertices() {
    let s = load("fv", FACE_VARYING);
    let m = mesh(&s, "/Split");
    // (UVs below are as authored; voltab stores (s, 1 − t).) Corner 3 (point 0, uv (0,0)) welds with corner 0; corner 4 (point 2, uv (0.5,0.5)) splits from
    // corner 2 (point 2, uv (1,1)): 6 corners → 5 vertices.
    assert_eq!(m.triangles, [[0, 1, 2], [0, 3, 4]]);
    assert_points(
        &positions(&s, "/Split"),
        &[[0.0; 3], [1.0, 0.0, 0.0], [1.0, 1.0, 0.0], [1.0, 1.0, 0.0], [0.0, 1.0, 0.0]],
    );
    assert_eq!(m.uv.as_deref(), Some(&[[0.0, 1.0], [1.0, 1.0], [1.0, 0.0], [0.5, 0.5], [0.0, 0.0]][..]));
    assert_eq!(m.normals.len(), 5);
    assert_close(f64s(m.normals[3]), [0.0, 0.0, 1.0], 1e-6);
}

#[test]
fn uniform_normals_split_vertices_and_use_the_inverse_transpose() {
    let s = load("normals", UNIFORM_NORMALS);
    let m = mesh(&s, "/Fold");
    assert_eq!(m.triangles, [[0, 1, 2], [3, 4, 5]], "each face gets its own corners");
    // World = Rx(90°)·diag(2,1,1); normals map by Rx(90°)·diag(1/2,1,1):
    // (0,0,1) → (0,−1,0); (1,1,0)/√2 → (1/2,1,0) → Rx → (1/2,0,1), normalised (1,0,2)/√5.
    let s5 = 5f64.sqrt();
    for v in 0..3 {
        assert_close(f64s(m.normals[v]), [0.0, -1.0, 0.0], 1e-6);
        assert_close(f64s(m.normals[v + 3]), [1.0 / s5, 0.0, 2.0 / s5], 1e-6);
    }
}

#[test]
fn invisible_inactive_guide_and_proxy_prims_are_skipped_and_subdivision_warns() {
    let s = load("skip", SKIPPED_PRIMS);
    let names: Vec<&str> = s.meshes.iter().map(|m| m.name.as_str()).collect();
    assert_eq!(names, ["/Visible", "/Subdiv", "/Loop"]);
    assert_warns(&s, "/Subdiv", "catmullClark (USD's fallback)");
    assert_warns(&s, "/Loop", "subdivisionScheme is loop");
    assert!(warnings_at(&s, "/Visible").is_empty());
}

#[test]
fn instanceable_references_import_every_instance() {
    let s = load("inst", INSTANCES);
    assert_points(&positions(&s, "/A/Tri"), &[[5.0, 0.0, 0.0], [6.0, 0.0, 0.0], [5.0, 1.0, 0.0]]);
    assert_points(&positions(&s, "/B/Tri"), &[[0.0, 5.0, 0.0], [1.0, 5.0, 0.0], [0.0, 6.0, 0.0]]);
    assert_eq!(s.meshes.len(), 2, "the class prototype itself is not geometry");
}

#[test]
fn time_samples_read_the_first_sample_with_a_warning() {
    let s = load("time", TIME_SAMPLES);
    assert_points(&positions(&s, "/Moving"), &[[1.0, 0.0, 0.0], [2.0, 0.0, 0.0], [1.0, 1.0, 0.0]]);
    assert_warns(&s, "/Moving", "xformOp:translate (2 samples)");
    // First intensity sample 1366 nits → L = 2 W/(m² sr).
    assert_close(s.lights[0].radiance, [2.0; 3], 1e-12);
    assert_warns(&s, "/Blink", "inputs:intensity (2 samples)");
}
