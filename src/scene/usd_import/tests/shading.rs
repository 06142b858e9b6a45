//! Material binding, UsdPreviewSurface, ND_anisotropic_vdf media and the global medium.

use super::{assert_close, assert_warns, load};
use crate::scene::{Boundary, Density, LightKind, Scene, Surface};

pub(super) const MATERIALS: &str = r#"#usda 1.0
(
    metersPerUnit = 1
    upAxis = "Y"
)

def Xform "World" (
    prepend apiSchemas = ["MaterialBindingAPI"]
)
{
    rel material:binding = </Looks/Red>

    def Mesh "Inherits"
    {
        uniform token subdivisionScheme = "none"
        int[] faceVertexCounts = [3]
        int[] faceVertexIndices = [0, 1, 2]
        point3f[] points = [(0, 0, 0), (1, 0, 0), (0, 1, 0)]
    }

    def Mesh "Direct" (
        prepend apiSchemas = ["MaterialBindingAPI"]
    )
    {
        rel material:binding = </Looks/Glass>
        uniform token subdivisionScheme = "none"
        int[] faceVertexCounts = [3]
        int[] faceVertexIndices = [0, 1, 2]
        point3f[] points = [(0, 0, 0), (1, 0, 0), (0, 1, 0)]
    }
}

def Xform "Strong" (
    prepend apiSchemas = ["MaterialBindingAPI"]
)
{
    rel material:binding = </Looks/Red> (
        bindMaterialAs = "strongerThanDescendants"
    )

    def Mesh "Overridden" (
        prepend apiSchemas = ["MaterialBindingAPI"]
    )
    {
        rel material:binding = </Looks/Glass>
        uniform token subdivisionScheme = "none"
        int[] faceVertexCounts = [3]
        int[] faceVertexIndices = [0, 1, 2]
        point3f[] points = [(0, 0, 0), (1, 0, 0), (0, 1, 0)]
    }
}

def Mesh "Unbound"
{
    uniform token subdivisionScheme = "none"
    int[] faceVertexCounts = [3]
    int[] faceVertexIndices = [0, 1, 2]
    point3f[] points = [(0, 0, 0), (1, 0, 0), (0, 1, 0)]
}

def Scope "Looks"
{
    def Material "Red"
    {
        token outputs:surface.connect = </Looks/Red/Surface.outputs:surface>

        def Shader "Surface"
        {
            uniform token info:id = "UsdPreviewSurface"
            color3f inputs:diffuseColor = (0.8, 0.1, 0.1)
            float inputs:roughness = 0.25
            color3f inputs:emissiveColor = (683, 341.5, 0)
            token outputs:surface
        }
    }

    def Material "Glass"
    {
        color3f inputs:tint = (0.2, 0.4, 0.6)
        token outputs:surface.connect = </Looks/Glass/Surface.outputs:surface>

        def Shader "Surface"
        {
            uniform token info:id = "UsdPreviewSurface"
            color3f inputs:diffuseColor.connect = </Looks/Glass.inputs:tint>
            float inputs:opacity = 0.5
            float inputs:ior = 1.33
            float inputs:roughness.connect = </Looks/Glass/Tex.outputs:r>
            token outputs:surface
        }

        def Shader "Tex"
        {
            uniform token info:id = "UsdUVTexture"
            asset inputs:file = @rough.png@
            float outputs:r
        }
    }
}
"#;

pub(super) const VDF_MEDIUM: &str = r#"#usda 1.0
(
    metersPerUnit = 0.01
    upAxis = "Y"
)

def Mesh "Box" (
    prepend apiSchemas = ["MaterialBindingAPI"]
)
{
    rel material:binding = </Looks/Fog>
    double3 xformOp:translate = (0, 500, 0)
    float3 xformOp:scale = (2, 2, 2)
    uniform token[] xformOpOrder = ["xformOp:translate", "xformOp:scale"]
    uniform token voltab:density = "exponentialHeight"
    float voltab:density:rho = 2
    float voltab:density:falloff = 0.5
    vector3f voltab:density:direction = (0, 1, 0)
    point3f voltab:density:offset = (0, 100, 0)
    uniform token subdivisionScheme = "none"
    int[] faceVertexCounts = [3]
    int[] faceVertexIndices = [0, 1, 2]
    point3f[] points = [(0, 0, 0), (100, 0, 0), (0, 100, 0)]
}

def Mesh "Cloud" (
    prepend apiSchemas = ["MaterialBindingAPI"]
)
{
    rel material:binding = </Looks/Mist>
    uniform token subdivisionScheme = "none"
    int[] faceVertexCounts = [3]
    int[] faceVertexIndices = [0, 1, 2]
    point3f[] points = [(0, 0, 0), (100, 0, 0), (0, 100, 0)]
}

def Scope "Looks"
{
    def Material "Fog"
    {
        token outputs:volume.connect = </Looks/Fog/Vdf.outputs:out>

        def Shader "Vdf"
        {
            uniform token info:id = "ND_anisotropic_vdf"
            vector3f inputs:absorption = (0.01, 0.02, 0.03)
            vector3f inputs:scattering = (0.05, 0.05, 0.05)
            float inputs:anisotropy = 0.3
            token outputs:out
        }
    }

    def Material "Mist"
    {
        token outputs:surface.connect = </Looks/Mist/Surface.outputs:surface>
        token outputs:mtlx:volume.connect = </Looks/Mist/Vdf.outputs:out>

        def Shader "Surface"
        {
            uniform token info:id = "UsdPreviewSurface"
            token outputs:surface
        }

        def Shader "Vdf"
        {
            uniform token info:id = "ND_anisotropic_vdf"
            vector3f inputs:scattering = (0.1, 0.1, 0.1)
            token outputs:out
        }
    }
}
"#;

pub(super) const GLOBAL_MEDIUM: &str = r#"#usda 1.0
(
    metersPerUnit = 0.5
    upAxis = "Z"
)

def Xform "Fog"
{
    uniform token voltab:medium = "global"
    color3f voltab:sigmaS = (0.1, 0.2, 0.3)
    color3f voltab:sigmaA = (0.05, 0.05, 0.05)
    float voltab:anisotropy = 0.5
    uniform token voltab:density = "exponentialHeight"
    float voltab:density:rho = 1.5
    float voltab:density:falloff = 2
    vector3f voltab:density:direction = (0, 0, 1)
    point3f voltab:density:offset = (0, 0, 10)
    double3 xformOp:translate = (100, 100, 100)
    uniform token[] xformOpOrder = ["xformOp:translate"]
}
"#;

pub(super) const SUBSETS: &str = r#"#usda 1.0
(
    metersPerUnit = 1
    upAxis = "Y"
)

def Mesh "Cube" (
    prepend apiSchemas = ["MaterialBindingAPI"]
)
{
    rel material:binding = </Looks/Plain>
    rel material:binding:collection:Hero = [</Cube.collection:hero>, </Looks/Plain>]
    uniform token subdivisionScheme = "none"
    int[] faceVertexCounts = [3, 3]
    int[] faceVertexIndices = [0, 1, 2, 0, 2, 3]
    point3f[] points = [(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0)]

    def GeomSubset "Top" (
        prepend apiSchemas = ["MaterialBindingAPI"]
    )
    {
        uniform token elementType = "face"
        uniform token familyName = "materialBind"
        int[] indices = [0]
        rel material:binding = </Looks/Plain>
    }
}

def Scope "Looks"
{
    def Material "Plain"
    {
    }
}
"#;

fn material_of<'a>(s: &'a Scene, mesh: &str) -> &'a crate::scene::Material {
    let m = s.meshes.iter().find(|m| m.name == mesh).unwrap_or_else(|| panic!("no mesh {mesh}"));
    &s.materials[m.material.unwrap_or_else(|| panic!("{mesh} has no material"))]
}

#[test]
fn bindings_resolve_direct_inherited_and_stronger_than_descendants() {
    let s = load("mats", MATERIALS);
    assert_eq!(material_of(&s, "/World/Inherits").name, "/Looks/Red");
    assert_eq!(material_of(&s, "/World/Direct").name, "/Looks/Glass");
    assert_eq!(material_of(&s, "/Strong/Overridden").name, "/Looks/Red");
    assert_eq!(s.meshes.iter().find(|m| m.name == "/Unbound").map(|m| m.material), Some(None));
    assert_eq!(s.materials.len(), 2, "each material is converted once");
}

#[test]
fn preview_surface_inputs_map_to_the_material_and_emission_to_a_light() {
    let s = load("mats", MATERIALS);
    let red = material_of(&s, "/World/Inherits");
    assert_close(red.base_color, [0.8, 0.1, 0.1], 1e-7);
    assert_close([red.roughness], [0.25], 0.0);
    assert_eq!(red.surface, Surface::Opaque);
    // emissiveColor in nits / 683.
    assert_close(red.emission, [1.0, 0.5, 0.0], 1e-12);
    let emitters: Vec<_> = s.lights.iter().filter(|l| matches!(l.kind, LightKind::EmissiveMesh { .. })).collect();
    let names: Vec<&str> = emitters.iter().map(|l| l.name.as_str()).collect();
    assert_eq!(names, ["/World/Inherits", "/Strong/Overridden"]);
    let LightKind::EmissiveMesh { mesh } = emitters[0].kind else { unreachable!() };
    assert_eq!(s.meshes[mesh].name, "/World/Inherits");
    assert_close(emitters[0].radiance, [1.0, 0.5, 0.0], 1e-12);

    let glass = material_of(&s, "/World/Direct");
    // diffuseColor through the material interface input; opacity < 1 → dielectric with its ior.
    assert_close(glass.base_color, [0.2, 0.4, 0.6], 1e-7);
    assert!(matches!(glass.surface, Surface::Dielectric { ior } if (ior - 1.33).abs() < 1e-6));
    // roughness is driven by a texture: fallback 0.5 and a warning naming the material.
    assert_close([glass.roughness], [0.5], 0.0);
    assert_warns(
        &s,
        "/Looks/Glass",
        "inputs:roughness of </Looks/Glass/Surface> is driven by </Looks/Glass/Tex.outputs:r>",
    );
}

#[test]
fn collection_and_subset_bindings_and_shaderless_materials_warn() {
    let s = load("subsets", SUBSETS);
    assert_warns(&s, "/Cube", "collection-based material bindings are not supported");
    assert_warns(&s, "/Cube/Top", "per-face material bindings (GeomSubset) are not supported");
    assert_warns(&s, "/Looks/Plain", "no surface shader");
    // The direct binding still applies, with UsdPreviewSurface fallbacks.
    let m = material_of(&s, "/Cube");
    assert_eq!((m.base_color, m.roughness, m.emission, m.surface), ([0.18; 3], 0.5, [0.0; 3], Surface::Opaque));
}

#[test]
fn anisotropic_vdf_medium_is_per_metre_with_mesh_density() {
    let s = load("vdf", VDF_MEDIUM);
    assert_eq!(s.media.len(), 2);
    let fog = &s.media[0];
    assert_eq!((fog.name.as_str(), fog.boundary), ("/Looks/Fog", Boundary::Mesh(0)));
    assert_eq!(s.meshes[0].medium, Some(0));
    // Per centimetre → per metre: × 100.
    assert_close(fog.sigma_a, [1.0, 2.0, 3.0], 1e-6);
    assert_close(fog.sigma_s, [5.0; 3], 1e-6);
    assert_close(fog.g, [0.3; 3], 1e-7);
    // Offset (0,100,0) → ×2 → +(0,500,0) → ×0.01 m = (0,7,0); falloff 0.5 per local unit of
    // 2 × 0.01 m = 25 per metre.
    let Density::ExponentialHeight { rho, falloff, direction, offset } = fog.density.clone() else {
        panic!("{:?}", fog.density)
    };
    assert_close([rho, falloff], [2.0, 25.0], 1e-12);
    assert_close(direction, [0.0, 1.0, 0.0], 1e-12);
    assert_close(offset, [0.0, 7.0, 0.0], 1e-12);
    // A volume-only material is an index-matched boundary.
    assert_eq!(s.materials[0].surface, Surface::Dielectric { ior: 1.0 });

    let mist = &s.media[1];
    assert_eq!((mist.boundary, mist.density.clone()), (Boundary::Mesh(1), Density::Homogeneous));
    assert_close(mist.sigma_s, [10.0; 3], 1e-6);
    assert_eq!((mist.sigma_a, mist.g), ([0.0; 3], [0.0; 3]), "MaterialX fallbacks are 0");
    assert_warns(&s, "/Looks/Mist", "opaque surface");
}

#[test]
fn global_medium_is_per_metre_with_stage_frame_density() {
    let s = load("global", GLOBAL_MEDIUM);
    assert_eq!(s.media.len(), 1);
    let m = &s.media[0];
    assert_eq!((m.name.as_str(), m.boundary), ("/Fog", Boundary::Global));
    // metersPerUnit 0.5: coefficients × 2.
    assert_close(m.sigma_s, [0.2, 0.4, 0.6], 1e-6);
    assert_close(m.sigma_a, [0.1; 3], 1e-6);
    assert_close(m.g, [0.5; 3], 0.0);
    // Z-up stage: direction (0,0,1) → +Y; offset (0,0,10) units = (0,0,5) m → (0,5,0); falloff 2/unit = 4/m.
    // The prim's own translate does not move the global medium.
    assert_eq!(
        m.density,
        Density::ExponentialHeight { rho: 1.5, falloff: 4.0, direction: [0.0, 1.0, 0.0], offset: [0.0, 5.0, 0.0] }
    );
}
