//! Unsupported constructs (warnings naming the prim) and errors naming the file and prim.

use std::path::Path;

use super::{assert_warns, load, load_err};
use crate::scene::{LightKind, SceneError};

pub(super) const UNSUPPORTED: &str = r#"#usda 1.0
(
    metersPerUnit = 1
    upAxis = "Y"
)

def Sphere "Ball"
{
}

def BasisCurves "Hair"
{
}

def PointInstancer "Scatter"
{
    def Mesh "Proto"
    {
        uniform token subdivisionScheme = "none"
        int[] faceVertexCounts = [3]
        int[] faceVertexIndices = [0, 1, 2]
        point3f[] points = [(0, 0, 0), (1, 0, 0), (0, 1, 0)]
    }
}

def DomeLight "Sky"
{
}

def CylinderLight "Tube"
{
}

def SphereLight "Spot" (
    prepend apiSchemas = ["ShapingAPI"]
)
{
    float inputs:shaping:cone:angle = 30
    bool inputs:enableColorTemperature = true
    float inputs:colorTemperature = 3000
}

def Skeleton "Skel"
{
}

def Mesh "Glow" (
    prepend apiSchemas = ["MeshLightAPI"]
)
{
    uniform token subdivisionScheme = "none"
    int[] faceVertexCounts = [3]
    int[] faceVertexIndices = [0, 1, 2]
    point3f[] points = [(0, 0, 0), (1, 0, 0), (0, 1, 0)]
}

def RectLight "Window"
{
    asset inputs:texture:file = @rough.png@
}
"#;

pub(super) const MISSING_REFERENCE: &str = r#"#usda 1.0
(
    metersPerUnit = 1
    upAxis = "Y"
)

def Xform "Ref" (
    prepend references = @./missing_asset.usda@
)
{
}

def Mesh "Still"
{
    uniform token subdivisionScheme = "none"
    int[] faceVertexCounts = [3]
    int[] faceVertexIndices = [0, 1, 2]
    point3f[] points = [(0, 0, 0), (1, 0, 0), (0, 1, 0)]
}
"#;

pub(super) const BAD_COUNTS: &str = r#"#usda 1.0
(
    metersPerUnit = 1
    upAxis = "Y"
)

def Xform "World"
{
    def Mesh "Bad"
    {
        int[] faceVertexCounts = [3, 3]
        int[] faceVertexIndices = [0, 1, 2, 0, 1]
        point3f[] points = [(0, 0, 0), (1, 0, 0), (0, 1, 0)]
    }
}
"#;

pub(super) const SHORT_FACE: &str = r#"#usda 1.0
(
    metersPerUnit = 1
    upAxis = "Y"
)

def Mesh "Short"
{
    int[] faceVertexCounts = [3, 2]
    int[] faceVertexIndices = [0, 1, 2, 0, 1]
    point3f[] points = [(0, 0, 0), (1, 0, 0), (0, 1, 0)]
}
"#;

pub(super) const INDEX_RANGE: &str = r#"#usda 1.0
(
    metersPerUnit = 1
    upAxis = "Y"
)

def Mesh "Range"
{
    int[] faceVertexCounts = [3]
    int[] faceVertexIndices = [0, 1, 7]
    point3f[] points = [(0, 0, 0), (1, 0, 0), (0, 1, 0)]
}
"#;

pub(super) const NAN_POINT: &str = r#"#usda 1.0
(
    metersPerUnit = 1
    upAxis = "Y"
)

def Mesh "Nan"
{
    int[] faceVertexCounts = [3]
    int[] faceVertexIndices = [0, 1, 2]
    point3f[] points = [(0, 0, 0), (nan, 0, 0), (0, 1, 0)]
}
"#;

pub(super) const NEGATIVE_LIGHT: &str = r#"#usda 1.0
(
    metersPerUnit = 1
    upAxis = "Y"
)

def RectLight "Dark"
{
    float inputs:intensity = 10
    color3f inputs:color = (1, -0.5, 1)
}
"#;

pub(super) const TWO_GLOBALS: &str = r#"#usda 1.0
(
    metersPerUnit = 1
    upAxis = "Y"
)

def Scope "FogA"
{
    uniform token voltab:medium = "global"
}

def Scope "FogB"
{
    uniform token voltab:medium = "global"
}
"#;

#[test]
fn unsupported_prims_warn_naming_the_prim() {
    let s = load("unsupported", UNSUPPORTED);
    assert_warns(&s, "/Ball", "Sphere prims are not supported");
    assert_warns(&s, "/Hair", "BasisCurves prims are not supported");
    assert_warns(&s, "/Scatter", "PointInstancer is not supported");
    // A DomeLight is read (the scene's environment; `dome.rs` tests it): nothing to warn about here.
    assert!(super::warnings_at(&s, "/Sky").is_empty(), "{:#?}", s.warnings);
    assert_eq!(s.environment.as_ref().map(|e| e.name.as_str()), Some("/Sky"));
    assert_warns(&s, "/Tube", "CylinderLight is not supported");
    assert_warns(&s, "/Skel", "UsdSkel Skeleton is not supported");
    assert_warns(&s, "/Glow", "mesh lights (MeshLightAPI/LightAPI on a Mesh) are not supported");
    assert_warns(&s, "/Window", "light textures (inputs:texture:file) are not read");
    let meshes: Vec<&str> = s.meshes.iter().map(|m| m.name.as_str()).collect();
    assert_eq!(meshes, ["/Glow"], "the instancer's prototype is not imported on its own");
    let lights: Vec<&str> = s.lights.iter().map(|l| l.name.as_str()).collect();
    assert_eq!(lights, ["/Spot", "/Window"]);
    assert!(matches!(s.lights[0].kind, LightKind::Sphere { .. }));
}

#[test]
fn missing_reference_is_a_warning_naming_the_prim() {
    let s = load("missingref", MISSING_REFERENCE);
    assert_warns(&s, "/Ref", "missing_asset.usda");
    assert_eq!(s.meshes.len(), 1, "the rest of the stage still loads");
}

#[track_caller]
fn assert_error(e: &SceneError, file_stem: &str, location: Option<&str>, needle: &str) {
    assert_eq!(e.file.file_stem().and_then(|s| s.to_str()), Some(file_stem), "{e}");
    assert_eq!(e.location.as_deref(), location, "{e}");
    assert!(e.message.contains(needle), "message {:?} lacks {needle:?}", e.message);
    assert!(!e.help.is_empty(), "{e}");
}

#[test]
fn topology_errors_name_the_prim() {
    let e = load_err("counts", BAD_COUNTS);
    assert_error(&e, "counts", Some("/World/Bad"), "faceVertexCounts sum to 6 but faceVertexIndices has 5 entries");
    let e = load_err("short", SHORT_FACE);
    assert_error(&e, "short", Some("/Short"), "face 1 has 2 vertices");
    let e = load_err("range", INDEX_RANGE);
    assert_error(&e, "range", Some("/Range"), "faceVertexIndices[2] = 7 is out of range for 3 points");
    let e = load_err("nan", NAN_POINT);
    assert_error(&e, "nan", Some("/Nan"), "point 1 is not finite");
}

#[test]
fn negative_light_and_second_global_medium_are_errors() {
    let e = load_err("dark", NEGATIVE_LIGHT);
    assert_error(&e, "dark", Some("/Dark"), "is negative");
    let e = load_err("globals", TWO_GLOBALS);
    assert_error(&e, "globals", Some("/FogB"), "a second global medium (the first is /FogA)");
    // The rendered diagnostic carries file, prim, message and help.
    let text = e.to_string();
    assert!(text.contains("globals.usda: /FogB: a second global medium") && text.contains("help: keep one"), "{text}");
}

#[test]
fn missing_and_unparsable_files_are_errors_naming_the_file() {
    let e = super::import(Path::new("/nonexistent/voltab/scene.usda")).expect_err("missing file");
    assert_error(&e, "scene", None, "does not exist");
    let e = load_err("garbage", "#usda 1.0\ndef Mesh \"M\" {\n    int[] faceVertexCounts = [3\n");
    // openusd's own message has no position; the importer re-parses the text layer for it: the
    // input ends after the `3` of line 3 (4 spaces + `int[] faceVertexCounts = [` = 30 characters).
    assert_error(&e, "garbage", Some("line 3, column 31"), "cannot open the USD layer");
    // A text layer must open with the `#usda` magic: the parser stops at its very first character.
    let e = load_err("notusd", "this is not a USD file\n");
    assert_error(&e, "notusd", Some("line 1, column 1"), "cannot open the USD layer");
    // An empty layer: no token was read, so the position is the start of the file.
    let e = load_err("empty", "");
    assert_error(&e, "empty", Some("line 1, column 1"), "cannot open the USD layer");
    // Not UTF-8: the first bad byte, 0xFF after `#usda 1.0\nde` (10 + 2 bytes), is line 2, column 3.
    let dir = tempfile::tempdir().expect("temp dir");
    let path = dir.path().join("latin1.usda");
    std::fs::write(&path, b"#usda 1.0\nde\xFFf Xform \"A\" {}\n").expect("write");
    let e = super::import(&path).expect_err("not UTF-8");
    assert_eq!(e.location.as_deref(), Some("line 2, column 3 (byte 12: not UTF-8)"), "{e}");
    // A zero `metersPerUnit` is located at the layer metadata.
    let e = load_err("zero_mpu", "#usda 1.0\n(\n    metersPerUnit = 0\n)\ndef Xform \"A\" {}\n");
    assert_error(&e, "zero_mpu", Some("layer metadata `metersPerUnit`"), "is not a positive number");
}

/// Regression: `openusd_panics.usdc` (a usd-core `.usdc` with one byte flipped) makes openusd 0.6's
/// crate reader panic (index out of bounds in `read_token_vec`); the importer turns that into an error
/// naming the file instead of unwinding into the caller.
#[test]
fn a_usdc_that_makes_openusd_panic_is_an_error_naming_the_file() {
    let dir = tempfile::tempdir().expect("temp dir");
    let path = dir.path().join("corrupt.usdc");
    std::fs::write(&path, include_bytes!("openusd_panics.usdc")).expect("write");
    let e = super::import(&path).expect_err("a corrupted crate file must not import");
    assert_eq!((e.file.as_path(), e.location.as_deref()), (path.as_path(), None), "{e}");
    assert!(!e.help.is_empty(), "{e}");
}
