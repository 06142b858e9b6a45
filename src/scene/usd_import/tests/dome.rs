//! UsdLux `DomeLight` / `DomeLight_1` → `Scene::environment`: units computed by hand from UsdLux's
//! `intensity · 2^exposure · color` over 683 lm/W, asset paths resolved against the authoring layer, the
//! orientation from the UsdLux text (OpenEXR's latitude–longitude map, `poleAxis`), and every dome that
//! cannot be used warned about by prim.

use std::f64::consts::PI;
use std::path::{Path, PathBuf};

use glam::DVec3;

use super::{assert_close, assert_warns, load, warnings_at, write};
use crate::render::environment::dome_map;
use crate::scene::usd_import::import;
use crate::scene::{EnvironmentLight, Scene};
use crate::stages::pop::environment::{self, OrdinateSet};

pub(super) const DOME_TEXTURED: &str = r#"#usda 1.0
(
    metersPerUnit = 1
    upAxis = "Y"
)

def DomeLight "Sky"
{
    float inputs:intensity = 2
    float inputs:exposure = 3
    color3f inputs:color = (1, 0.5, 0.25)
    asset inputs:texture:file = @textures/dome_sky.exr@
    token inputs:texture:format = "latlong"
}
"#;

pub(super) const DOME_UNIFORM: &str = r#"#usda 1.0
(
    metersPerUnit = 0.01
    upAxis = "Y"
)

def Xform "Rig"
{
    double3 xformOp:translate = (100, 200, 300)
    float3 xformOp:scale = (3, 3, 3)
    uniform token[] xformOpOrder = ["xformOp:translate", "xformOp:scale"]

    def DomeLight "Sky"
    {
        float xformOp:rotateY = 90
        uniform token[] xformOpOrder = ["xformOp:rotateY"]
    }
}
"#;

pub(super) const DOME_1_Z_UP: &str = r#"#usda 1.0
(
    metersPerUnit = 1
    upAxis = "Z"
)

def DomeLight_1 "Sky"
{
}
"#;

pub(super) const DOME_Z_UP: &str = r#"#usda 1.0
(
    metersPerUnit = 1
    upAxis = "Z"
)

def DomeLight "Sky"
{
}
"#;

pub(super) const DOME_POLE_Z: &str = r#"#usda 1.0
(
    metersPerUnit = 1
    upAxis = "Y"
)

def DomeLight_1 "Sky"
{
    uniform token poleAxis = "Z"
}
"#;

pub(super) const DOME_FORMATS: &str = r#"#usda 1.0
(
    metersPerUnit = 1
    upAxis = "Y"
)

def DomeLight "Ball"
{
    asset inputs:texture:file = @dome_sky.exr@
    token inputs:texture:format = "mirroredBall"
}

def DomeLight "Angular"
{
    asset inputs:texture:file = @dome_sky.exr@
    token inputs:texture:format = "angular"
}

def DomeLight "Cross"
{
    asset inputs:texture:file = @dome_sky.exr@
    token inputs:texture:format = "cubeMapVerticalCross"
}
"#;

pub(super) const TWO_DOMES: &str = r#"#usda 1.0
(
    metersPerUnit = 1
    upAxis = "Y"
)

def DomeLight "SkyA"
{
    float inputs:intensity = 683
}

def DomeLight_1 "SkyB"
{
}

def DomeLight "SkyC"
{
}
"#;

pub(super) const DOME_EXTRAS: &str = r#"#usda 1.0
(
    metersPerUnit = 1
    upAxis = "Y"
)

def DomeLight "Sky"
{
    bool inputs:normalize = true
    uniform token poleAxis = "Z"
    rel portals = </Portal>
    float xformOp:rotateY = 90
    float3 xformOp:scale = (1, 2, 1)
    uniform token[] xformOpOrder = ["xformOp:rotateY", "xformOp:scale"]
}

def PortalLight "Portal"
{
}
"#;

pub(super) const DOME_DEGENERATE: &str = r#"#usda 1.0
(
    metersPerUnit = 1
    upAxis = "Y"
)

def DomeLight "Flat"
{
    float3 xformOp:scale = (1, 0, 1)
    uniform token[] xformOpOrder = ["xformOp:scale"]
}

def DomeLight "Mirror"
{
    float3 xformOp:scale = (-2, 2, 2)
    uniform token[] xformOpOrder = ["xformOp:scale"]
}
"#;

pub(super) const DOME_ORIENTED: &str = r#"#usda 1.0
(
    metersPerUnit = 1
    upAxis = "Y"
)

def DomeLight "Sky"
{
    float inputs:intensity = 683
    asset inputs:texture:file = @dome_sky.exr@
    float xformOp:rotateY = 90
    uniform token[] xformOpOrder = ["xformOp:rotateY"]
}
"#;

/// Snippets that name a texture (`dome_sky.exr` next to the layer or in `textures/`).
pub(super) const TEXTURED: [&str; 3] = ["dome_textured", "dome_formats", "dome_oriented"];

/// Writes a `w × h` RGB EXR whose texel `i` (row-major from the top-left) holds `f(i)`.
fn write_exr(path: &Path, w: usize, h: usize, f: impl Fn(usize) -> [f32; 3]) {
    std::fs::create_dir_all(path.parent().expect("parent")).expect("mkdir");
    let px: Vec<[f32; 3]> = (0..w * h).map(f).collect();
    crate::image_io::write_exr_rgb(path, w, h, &px, &[]).expect("write exr");
}

fn dome(s: &Scene) -> &EnvironmentLight {
    s.environment.as_ref().unwrap_or_else(|| panic!("no environment; warnings: {:#?}", s.warnings))
}

/// The rotation's columns (world images of the map's X, Y, Z).
fn cols(e: &EnvironmentLight) -> [[f64; 3]; 3] {
    e.rotation
}

#[track_caller]
fn assert_rotation(e: &EnvironmentLight, want: [[f64; 3]; 3], tol: f64) {
    for (j, (g, w)) in cols(e).iter().zip(&want).enumerate() {
        for k in 0..3 {
            assert!((g[k] - w[k]).abs() <= tol, "column {j}: got {:?}, expected {want:?}", e.rotation);
        }
    }
}

const IDENTITY: [[f64; 3]; 3] = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
/// USD `rotateY = 90` (column vectors): +X → −Z, +Y → +Y, +Z → +X.
const RY90: [[f64; 3]; 3] = [[0.0, 0.0, -1.0], [0.0, 1.0, 0.0], [1.0, 0.0, 0.0]];

#[test]
fn dome_radiance_is_intensity_times_two_to_the_exposure_times_colour_over_683() {
    let w = write("dome_textured", DOME_TEXTURED);
    let dir = w.path.parent().expect("dir").to_path_buf();
    let texture = dir.join("textures/dome_sky.exr");
    write_exr(&texture, 4, 2, |_| [1.0; 3]);
    let s = import(&w.path).expect("import");
    let e = dome(&s);
    assert_eq!(e.name, "/Sky");
    // 2 · 2³ / 683 nits → W/(m² sr) per unit texel, tinted (1, 0.5, 0.25).
    assert_close([e.scale], [16.0 / 683.0], 1e-15);
    assert_eq!(e.color, [1.0, 0.5, 0.25]);
    assert_close(e.multiplier(), [16.0 / 683.0, 8.0 / 683.0, 4.0 / 683.0], 1e-15);
    assert_eq!(e.texture.as_deref(), Some(texture.as_path()), "relative to the layer, absolute");
    assert_rotation(e, IDENTITY, 0.0);
    assert!(warnings_at(&s, "/Sky").is_empty(), "{:#?}", s.warnings);
    assert!(s.lights.is_empty(), "a dome is not a scene light");
}

#[test]
fn untextured_dome_is_uniform_with_usd_fallbacks_and_only_its_rotation_counts() {
    let s = load("dome_uniform", DOME_UNIFORM);
    let e = dome(&s);
    assert_eq!((e.name.as_str(), e.texture.as_ref()), ("/Rig/Sky", None));
    // intensity 1, exposure 0, colour 1 (UsdLux fallbacks): 1/683 W/(m² sr) in every direction.
    assert_close(e.multiplier(), [1.0 / 683.0; 3], 1e-15);
    // Centimetres, the parent's translation and uniform scale 3 do not matter: rotateY(90°) alone.
    assert_rotation(e, RY90, 1e-12);
    assert!(warnings_at(&s, "/Rig/Sky").is_empty(), "{:#?}", s.warnings);
    // The uniform map of that dome holds 4π/683 W/m² of fluence whatever the rotation.
    let map = dome_map(e).expect("uniform map");
    assert_close(map.integral(), [4.0 * PI / 683.0; 3], 1e-12);
}

#[test]
fn pole_axis_follows_usd_imaging_dome_offset() {
    // DomeLight_1 on a Z-up stage (poleAxis "scene"): the pole on stage +Z = voltab's +Y; the image
    // centre (dome +Z, turned to stage −Y) is voltab's +Z: no rotation at all.
    assert_rotation(dome(&load("dome_1_z_up", DOME_1_Z_UP)), IDENTITY, 1e-15);
    // A plain DomeLight keeps its pole on stage +Y, which a Z-up stage turns to voltab's −Z; its
    // centre (stage +Z) points up.
    let plain = [[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]];
    assert_rotation(dome(&load("dome_z_up", DOME_Z_UP)), plain, 1e-15);
    // poleAxis "Z" on a Y-up stage: +90° about X, pole to +Z, centre to −Y.
    let pole_z = [[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]];
    assert_rotation(dome(&load("dome_pole_z", DOME_POLE_Z)), pole_z, 1e-15);
}

#[test]
fn unsupported_texture_formats_drop_the_dome_with_a_warning() {
    let s = load("dome_formats", DOME_FORMATS);
    for (prim, format) in [("/Ball", "mirroredBall"), ("/Angular", "angular"), ("/Cross", "cubeMapVerticalCross")] {
        assert_warns(&s, prim, &format!("texture format \"{format}\" is not supported (only latlong)"));
    }
    assert!(s.environment.is_none());
}

#[test]
fn a_second_dome_is_skipped_naming_the_first() {
    let s = load("two_domes", TWO_DOMES);
    let e = dome(&s);
    assert_eq!(e.name, "/SkyA");
    assert_close(e.multiplier(), [1.0; 3], 1e-15);
    for other in ["/SkyB", "/SkyC"] {
        assert_warns(&s, other, "a second dome light; only the first (/SkyA) lights the scene");
    }
}

#[test]
fn dome_extras_are_warned_and_non_rotations_reduced_to_the_nearest_rotation() {
    let s = load("dome_extras", DOME_EXTRAS);
    for needle in [
        "normalize has no effect on a dome light",
        "poleAxis = \"Z\" is a DomeLight_1 attribute",
        "portals are not supported; 1 portal(s) ignored",
        "non-uniform scale or shear on a dome light",
    ] {
        assert_warns(&s, "/Sky", needle);
    }
    // rotateY(90°) · scale(1, 2, 1): the polar factor is the rotation itself.
    assert_rotation(dome(&s), RY90, 1e-12);
    // A singular dome is skipped and the next one lights the scene; a mirror is kept and warned about.
    let s = load("dome_degenerate", DOME_DEGENERATE);
    assert_warns(&s, "/Flat", "transform is singular");
    assert_warns(&s, "/Mirror", "mirrors (negative determinant)");
    let e = dome(&s);
    assert_eq!(e.name, "/Mirror");
    assert_rotation(e, [[-1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]], 1e-15);
}

#[test]
fn texture_paths_resolve_against_the_layer_that_authors_them() {
    // The dome lives in a sublayer one folder down: `@dome_sky.exr@` is next to that layer, not next to
    // the root layer (where a decoy of the same name sits).
    let d = tempfile::tempdir().expect("temp dir");
    let root = d.path().join("root.usda");
    let layer = |texture: &str| {
        format!("#usda 1.0\n\ndef DomeLight \"Sky\"\n{{\n    asset inputs:texture:file = @{texture}@\n}}\n")
    };
    std::fs::create_dir_all(d.path().join("layers")).expect("mkdir");
    std::fs::write(d.path().join("layers/sky.usda"), layer("dome_sky.exr")).expect("write");
    std::fs::write(d.path().join("layers/lost.usda"), layer("missing.exr")).expect("write");
    write_exr(&d.path().join("layers/dome_sky.exr"), 4, 2, |_| [1.0; 3]);
    write_exr(&d.path().join("dome_sky.exr"), 4, 2, |_| [9.0; 3]);
    let stage = |sub: &str| {
        format!("#usda 1.0\n(\n    metersPerUnit = 1\n    upAxis = \"Y\"\n    subLayers = [@layers/{sub}@]\n)\n")
    };
    std::fs::write(&root, stage("sky.usda")).expect("write");
    let s = import(&root).expect("import");
    assert_eq!(dome(&s).texture, Some(d.path().join("layers/dome_sky.exr")));
    assert!(warnings_at(&s, "/Sky").is_empty(), "{:#?}", s.warnings);
    // A texture that does not exist: kept at the path it would have (for the stage's error) and warned.
    std::fs::write(&root, stage("lost.usda")).expect("write");
    let s = import(&root).expect("import");
    let want: PathBuf = d.path().join("layers/missing.exr");
    assert_eq!(dome(&s).texture.as_ref(), Some(&want));
    assert_warns(&s, "/Sky", &format!("does not resolve to a file (looked for {})", want.display()));
}

#[test]
fn a_bright_texel_lands_where_the_usda_rotation_puts_it() {
    // The texel at column 40, row 10 of a 64 × 32 map looks, by the OpenEXR text UsdLux quotes, toward
    // latitude 11π/64 and longitude −17π/64; the dome's rotateY(90°) takes (x, y, z) to (z, y, −x):
    // (cos(11π/64) cos(17π/64), sin(11π/64), cos(11π/64) sin(17π/64)) in the world.
    let w = write("dome_oriented", DOME_ORIENTED);
    let texture = w.path.parent().expect("dir").join("dome_sky.exr");
    write_exr(&texture, 64, 32, |i| if i == 10 * 64 + 40 { [1000.0; 3] } else { [0.0; 3] });
    let s = import(&w.path).expect("import");
    let map = dome_map(dome(&s)).expect("dome map");
    let (lat, lon) = (11.0 * PI / 64.0, 17.0 * PI / 64.0);
    let want = DVec3::new(lat.cos() * lon.cos(), lat.sin(), lat.cos() * lon.sin());
    assert!((map.texel_direction(40, 10) - want).length() < 1e-12);
    // intensity 683 nits = 1 W/(m² sr) per unit texel.
    assert_eq!(map.lookup(want), [1000.0; 3]);
    let ords = environment::ordinates(&map, 8, OrdinateSet::Importance);
    let bright = ords.iter().max_by(|a, b| a.irradiance[1].total_cmp(&b.irradiance[1])).expect("ordinates");
    let angle = (-DVec3::from(bright.direction)).angle_between(want);
    assert!(angle < 1e-3, "the light arrives {angle} rad away from the spec's direction");
    // The energy is the texel's: 1000 × (2π/64)(cos(10π/32) − cos(11π/32)), whatever the rotation.
    let omega = 2.0 * PI / 64.0 * ((10.0 * PI / 32.0).cos() - (11.0 * PI / 32.0).cos());
    assert_close(map.integral(), [1000.0 * omega; 3], 1e-12);
}
