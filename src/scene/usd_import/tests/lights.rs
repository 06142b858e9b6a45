//! UsdLux lights and cameras: every conversion computed by hand from scene.md's formulas.

use std::f64::consts::PI;

use super::{assert_close, assert_warns, load};
use crate::scene::{Camera, Light, LightKind, Projection, Scene};

pub(super) const POINT_LIGHT: &str = r#"#usda 1.0
(
    metersPerUnit = 1
    upAxis = "Y"
)

def SphereLight "Bulb"
{
    float inputs:intensity = 683
    float inputs:radius = 0.1
    bool treatAsPoint = true
    double3 xformOp:translate = (1, 2, 3)
    uniform token[] xformOpOrder = ["xformOp:translate"]
}

def SphereLight "Normalized"
{
    float inputs:intensity = 683
    float inputs:radius = 0.05
    bool inputs:normalize = true
    bool treatAsPoint = true
    float3 xformOp:scale = (2, 2, 2)
    uniform token[] xformOpOrder = ["xformOp:scale"]
}
"#;

pub(super) const AREA_LIGHTS: &str = r#"#usda 1.0
(
    metersPerUnit = 1
    upAxis = "Y"
)

def SphereLight "Ball"
{
    float inputs:intensity = 683
    float inputs:exposure = 1
    color3f inputs:color = (1, 0.5, 0.25)
    float inputs:radius = 0.25
    double3 xformOp:translate = (0, 1, 0)
    uniform token[] xformOpOrder = ["xformOp:translate"]
}

def SphereLight "BallNormalized"
{
    float inputs:intensity = 683
    bool inputs:normalize = true
}

def RectLight "Panel"
{
    float inputs:intensity = 683
    float inputs:width = 2
    float inputs:height = 4
    bool inputs:normalize = true
    double3 xformOp:translate = (0, 3, 0)
    float xformOp:rotateX = 90
    float3 xformOp:scale = (2, 2, 2)
    uniform token[] xformOpOrder = ["xformOp:translate", "xformOp:rotateX", "xformOp:scale"]
}

def DiskLight "Disk"
{
    float inputs:intensity = 683
    bool inputs:normalize = true
}
"#;

pub(super) const DISTANT_LIGHTS: &str = r#"#usda 1.0
(
    metersPerUnit = 1
    upAxis = "Y"
)

def DistantLight "Sun"
{
    float inputs:intensity = 683
    float inputs:angle = 10
    float xformOp:rotateX = -90
    uniform token[] xformOpOrder = ["xformOp:rotateX"]
}

def DistantLight "SunNormalized"
{
    float inputs:intensity = 683
    float inputs:angle = 10
    bool inputs:normalize = true
}
"#;

pub(super) const DEFAULT_LIGHTS: &str = r#"#usda 1.0
(
    metersPerUnit = 1
    upAxis = "Y"
)

def SphereLight "Sphere"
{
}

def RectLight "Rect"
{
}

def DiskLight "Disk"
{
}

def DistantLight "Distant"
{
}
"#;

pub(super) const CAMERAS: &str = r#"#usda 1.0
(
    metersPerUnit = 1
    upAxis = "Y"
)

def Camera "Film"
{
    float focalLength = 35
    float verticalAperture = 24
    float horizontalAperture = 36
    float2 clippingRange = (0.1, 1000)
    double3 xformOp:translate = (1, 2, 3)
    float xformOp:rotateY = 90
    uniform token[] xformOpOrder = ["xformOp:translate", "xformOp:rotateY"]
}

def Camera "Default"
{
}

def Camera "Ortho"
{
    token projection = "orthographic"
    float horizontalAperture = 20
    float verticalAperture = 10
}
"#;

fn light<'a>(s: &'a Scene, name: &str) -> &'a Light {
    s.lights.iter().find(|l| l.name == name).unwrap_or_else(|| panic!("no light {name}"))
}

fn camera<'a>(s: &'a Scene, name: &str) -> &'a Camera {
    s.cameras.iter().find(|c| c.name == name).unwrap_or_else(|| panic!("no camera {name}"))
}

#[test]
fn treat_as_point_sphere_is_a_point_light_of_l_pi_r_squared() {
    let s = load("point", POINT_LIGHT);
    let bulb = light(&s, "/Bulb");
    assert_eq!(bulb.kind, LightKind::Point { position: [1.0, 2.0, 3.0] });
    // intensity 683 nits → L = 1; r = 0.1 → I = π · 0.01 W/sr (r is a float: 1e-7 relative).
    assert_close(bulb.radiance, [PI * 0.01; 3], 1e-7);
    // normalize: L / (4π r²) · π r² = L / 4, whatever the (world) radius.
    assert_close(light(&s, "/Normalized").radiance, [0.25; 3], 1e-12);
}

#[test]
fn area_lights_convert_exposure_color_and_normalize() {
    let s = load("area", AREA_LIGHTS);
    let ball = light(&s, "/Ball");
    assert_eq!(ball.kind, LightKind::Sphere { center: [0.0, 1.0, 0.0], radius: 0.25 });
    // 683 · 2^1 · color / 683: exposure 1 doubles.
    assert_close(ball.radiance, [2.0, 1.0, 0.5], 1e-12);
    // Fallback radius 0.5: L / (4π · 0.25) = 1/π.
    assert_close(light(&s, "/BallNormalized").radiance, [1.0 / PI; 3], 1e-12);

    let panel = light(&s, "/Panel");
    let LightKind::Rect { center, half_u, half_v, normal } = panel.kind else { panic!("{panel:?}") };
    // Scale 2 then rotateX 90°: half extents (2,0,0) and Rx·(0,4,0) = (0,0,4); −Z → +Y.
    assert_close(center, [0.0, 3.0, 0.0], 1e-12);
    assert_close(half_u, [2.0, 0.0, 0.0], 1e-12);
    assert_close(half_v, [0.0, 0.0, 4.0], 1e-12);
    assert_close(normal, [0.0, 1.0, 0.0], 1e-12);
    // World area (2·2)·(4·2) = 32.
    assert_close(panel.radiance, [1.0 / 32.0; 3], 1e-12);

    let disk = light(&s, "/Disk");
    assert_eq!(disk.kind, LightKind::Disk { center: [0.0; 3], normal: [0.0, 0.0, -1.0], radius: 0.5 });
    // L / (π · 0.25).
    assert_close(disk.radiance, [4.0 / PI; 3], 1e-12);
}

#[test]
fn distant_light_irradiance_is_l_times_the_cone_solid_angle() {
    let s = load("distant", DISTANT_LIGHTS);
    let sun = light(&s, "/Sun");
    let angle = 10f64.to_radians();
    let LightKind::Directional { direction, angle: a } = sun.kind else { panic!("{sun:?}") };
    assert_close(direction, [0.0, -1.0, 0.0], 1e-12);
    assert_close([a], [angle], 1e-12);
    // E = L · 2π(1 − cos(angle/2)), L = 1.
    assert_close(sun.radiance, [2.0 * PI * (1.0 - (angle / 2.0).cos()); 3], 1e-12);
    // normalize: E = L.
    assert_close(light(&s, "/SunNormalized").radiance, [1.0; 3], 1e-12);
}

#[test]
fn unauthored_light_inputs_use_usd_fallbacks() {
    let s = load("defaults", DEFAULT_LIGHTS);
    let l = 1.0 / 683.0;
    assert_eq!(light(&s, "/Sphere").kind, LightKind::Sphere { center: [0.0; 3], radius: 0.5 });
    assert_close(light(&s, "/Sphere").radiance, [l; 3], 1e-12);
    let rect = light(&s, "/Rect");
    assert_eq!(
        rect.kind,
        LightKind::Rect {
            center: [0.0; 3],
            half_u: [0.5, 0.0, 0.0],
            half_v: [0.0, 0.5, 0.0],
            normal: [0.0, 0.0, -1.0]
        }
    );
    assert_close(rect.radiance, [l; 3], 1e-12);
    assert_eq!(light(&s, "/Disk").kind, LightKind::Disk { center: [0.0; 3], normal: [0.0, 0.0, -1.0], radius: 0.5 });
    assert_close(light(&s, "/Disk").radiance, [l; 3], 1e-12);
    let sun = light(&s, "/Distant");
    let angle = 0.53f64.to_radians();
    assert_eq!(sun.kind, LightKind::Directional { direction: [0.0, 0.0, -1.0], angle });
    assert_close(sun.radiance, [l * 2.0 * PI * (1.0 - (angle / 2.0).cos()); 3], 1e-12);
    assert!(s.warnings.is_empty(), "{:#?}", s.warnings);
}

#[test]
fn cameras_follow_the_aperture_formulas_and_fallbacks() {
    let s = load("cams", CAMERAS);
    let film = camera(&s, "/Film");
    assert_eq!(film.projection, Projection::Perspective { yfov: 2.0 * (24.0f64 / 70.0).atan(), aspect: Some(1.5) });
    assert_close(film.position, [1.0, 2.0, 3.0], 1e-12);
    // rotateY 90°: −Z → −X; up stays +Y.
    assert_close(film.forward, [-1.0, 0.0, 0.0], 1e-12);
    assert_close(film.up, [0.0, 1.0, 0.0], 1e-12);
    assert_close([film.znear, film.zfar.unwrap_or(0.0)], [0.1, 1000.0], 1e-7);

    let def = camera(&s, "/Default");
    let yfov = 2.0 * (15.2908f64 / 100.0).atan();
    assert_eq!(def.projection, Projection::Perspective { yfov, aspect: Some(20.955 / 15.2908) });
    assert_eq!((def.znear, def.zfar), (1.0, Some(1e6)));
    assert_close(def.forward, [0.0, 0.0, -1.0], 0.0);

    // Apertures in tenths of a stage unit: half extents 20/2·0.1 and 10/2·0.1.
    let Projection::Orthographic { xmag, ymag } = camera(&s, "/Ortho").projection else { panic!("not orthographic") };
    assert_close([xmag, ymag], [1.0, 0.5], 1e-12);
}

#[test]
fn shaping_api_and_color_temperature_warn() {
    let s = load("spot", super::errors::UNSUPPORTED);
    assert_warns(&s, "/Spot", "ShapingAPI");
    assert_warns(&s, "/Spot", "enableColorTemperature");
    assert!(matches!(light(&s, "/Spot").kind, LightKind::Sphere { .. }), "the light itself is still read");
}
