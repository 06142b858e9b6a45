//! glTF materials → voltab [`Material`]s and the media `KHR_materials_volume` puts inside meshes.
//!
//! **Mapping** (docs/design/scene.md, "Materials and media"): `baseColorFactor` rgb → base colour,
//! `roughnessFactor` → roughness, `KHR_materials_transmission` factor > 0 → a dielectric with
//! `KHR_materials_ior` (default 1.5), `emissiveFactor × KHR_materials_emissive_strength` read as
//! nits / 683 → emitted radiance. On a transmissive material `KHR_materials_volume` gives the
//! extinction σ_t = −ln(attenuationColor)/attenuationDistance; the albedo and phase come from
//! `KHR_materials_volume_scatter` (draft), overridden field by field by `VOLTAB_participating_media`,
//! else α = 0 and g = 0 (Khronos' pure absorber).

use std::path::Path;

use serde::Deserialize;

use super::vendor::{self, DensitySpec};
use crate::scene::{LUMENS_PER_WATT, Material, Rgb, SceneError, SceneWarning, Surface};

/// Draft extension adding scattering to `KHR_materials_volume`.
pub(super) const VOLUME_SCATTER: &str = "KHR_materials_volume_scatter";

/// A material and the medium it puts inside closed meshes, if any.
pub(super) struct MaterialInfo {
    pub material: Material,
    pub volume: Option<VolumeSpec>,
}

/// Medium coefficients of a volume material (density still in the instancing node's frame).
#[derive(Debug, Clone)]
pub(super) struct VolumeSpec {
    /// [1/m]
    pub sigma_s: Rgb,
    /// [1/m]
    pub sigma_a: Rgb,
    pub g: Rgb,
    pub density: Option<DensitySpec>,
}

/// `KHR_materials_volume_scatter`, current draft (KhronosGroup/glTF PR 2453): `multiscatterColor`
/// and `scatterAnisotropy`; the 2020 draft called the colour `scatterAlbedo`.
#[derive(Debug, Default, Deserialize)]
#[serde(rename_all = "camelCase")]
struct VolumeScatter {
    #[serde(default)]
    multiscatter_color: Option<[f64; 3]>,
    #[serde(default)]
    scatter_albedo: Option<[f64; 3]>,
    #[serde(default)]
    scatter_anisotropy: Option<f64>,
}

/// Single-scattering albedo α from the multi-scatter albedo A (`KHR_materials_volume_scatter`,
/// after Kulla & Conty 2017): s = 4.09712 + 4.20863 A − √(9.59217 + 41.6808 A + 17.7126 A²),
/// α = 1 − s². The fit gives α ≈ 6·10⁻⁶ at A = 0 and α ≈ 1 − 3·10⁻¹¹ at A = 1; clamped to [0, 1].
pub(super) fn single_scatter_albedo(a: f64) -> f64 {
    let s = 4.09712 + 4.20863 * a - (9.59217 + 41.6808 * a + 17.7126 * a * a).sqrt();
    (1.0 - s * s).clamp(0.0, 1.0)
}

/// Reads `materials[index]`.
pub(super) fn read(
    file: &Path,
    index: usize,
    m: &gltf::Material<'_>,
    warnings: &mut Vec<SceneWarning>,
) -> Result<MaterialInfo, SceneError> {
    let name = m.name().map_or_else(|| format!("material {index}"), str::to_owned);
    let location = match m.name() {
        Some(n) => format!("material \"{n}\""),
        None => format!("materials[{index}]"),
    };
    let err = |message: String, help: &str| SceneError::at(file, &location, message, help);
    let pbr = m.pbr_metallic_roughness();
    let [r, g, b, _] = pbr.base_color_factor().map(f64::from);

    let strength = f64::from(m.emissive_strength().unwrap_or(1.0));
    let emission = m.emissive_factor().map(|e| f64::from(e) * strength / LUMENS_PER_WATT);
    if strength < 0.0 || emission.iter().any(|e| *e < 0.0) {
        return Err(err(
            format!("negative emission: emissiveFactor {:?} × emissive strength {strength}", m.emissive_factor()),
            "emissiveFactor components and KHR_materials_emissive_strength must be ≥ 0",
        ));
    }

    let transmission = m.transmission().map_or(0.0, |t| f64::from(t.transmission_factor()));
    let surface =
        if transmission > 0.0 { Surface::Dielectric { ior: m.ior().map_or(1.5, f64::from) } } else { Surface::Opaque };

    let textures = texture_slots(m);
    if !textures.is_empty() {
        warnings.push(SceneWarning {
            location: location.clone(),
            message: format!("textures ignored ({}); the constant factors are used", textures.join(", ")),
            help: "voltab reads material factors only; bake textures into factors if they matter for lighting".into(),
        });
    }

    let volume = read_volume(file, &location, m, transmission > 0.0, warnings)?;
    let material =
        Material { name, base_color: [r, g, b], emission, surface, roughness: f64::from(pbr.roughness_factor()) };
    Ok(MaterialInfo { material, volume })
}

/// Names of the texture slots the material fills.
fn texture_slots(m: &gltf::Material<'_>) -> Vec<&'static str> {
    let pbr = m.pbr_metallic_roughness();
    let slots = [
        ("baseColorTexture", pbr.base_color_texture().is_some()),
        ("metallicRoughnessTexture", pbr.metallic_roughness_texture().is_some()),
        ("normalTexture", m.normal_texture().is_some()),
        ("occlusionTexture", m.occlusion_texture().is_some()),
        ("emissiveTexture", m.emissive_texture().is_some()),
        ("transmissionTexture", m.transmission().is_some_and(|t| t.transmission_texture().is_some())),
        ("thicknessTexture", m.volume().is_some_and(|v| v.thickness_texture().is_some())),
    ];
    slots.into_iter().filter_map(|(n, has)| has.then_some(n)).collect()
}

/// The medium a material puts inside meshes (`None`: no volume, or the volume is ignored).
fn read_volume(
    file: &Path,
    location: &str,
    m: &gltf::Material<'_>,
    transmissive: bool,
    warnings: &mut Vec<SceneWarning>,
) -> Result<Option<VolumeSpec>, SceneError> {
    let err = |message: String, help: &str| SceneError::at(file, location, message, help);
    // Parse (and so validate) the vendor extension even where it ends up unused.
    let vendor = match m.extension_value(vendor::EXTENSION) {
        Some(v) => Some(vendor::parse_material(v).map_err(|e| {
            err(format!("{}: {e}", vendor::EXTENSION), "see schemas/VOLTAB_participating_media.schema.json")
        })?),
        None => None,
    };
    let scatter = match m.extension_value(VOLUME_SCATTER) {
        Some(v) => Some(vendor::parse_named::<VolumeScatter>(v, "").map_err(|e| {
            err(
                format!("{VOLUME_SCATTER}: {e}"),
                "multiscatterColor is [r, g, b] in [0, 1], scatterAnisotropy a number in (-1, 1)",
            )
        })?),
        None => None,
    };
    let Some(volume) = m.volume() else {
        if vendor.is_some() || scatter.is_some() {
            warnings.push(SceneWarning {
                location: location.to_owned(),
                message: format!(
                    "{}/{VOLUME_SCATTER} ignored: the material has no KHR_materials_volume",
                    vendor::EXTENSION
                ),
                help: "a medium needs KHR_materials_volume (its attenuation gives the extinction)".into(),
            });
        }
        return Ok(None);
    };
    if !transmissive {
        warnings.push(SceneWarning {
            location: location.to_owned(),
            message: "KHR_materials_volume ignored: the material is not transmissive".into(),
            help:
                "add KHR_materials_transmission with transmissionFactor > 0 (ior 1 for an index-matched fog boundary)"
                    .into(),
        });
        return Ok(None);
    }

    let distance = f64::from(volume.attenuation_distance());
    let color = volume.attenuation_color().map(f64::from);
    if distance.is_nan() || distance <= 0.0 || color.iter().any(|c| c.is_nan() || *c <= 0.0) {
        return Err(err(
            format!(
                "KHR_materials_volume: attenuationColor {color:?} and attenuationDistance {distance} give no finite extinction"
            ),
            "attenuationDistance must be > 0 and attenuationColor components > 0 (1 means no attenuation)",
        ));
    }
    // KHR_materials_volume: σ_t = −ln(c)/d; d = +∞ (the default) or c = 1 means no attenuation.
    let sigma_t = color.map(|c| if distance.is_infinite() || c == 1.0 { 0.0 } else { -c.ln() / distance });

    let mut albedo = [0.0; 3];
    let mut g = [0.0; 3];
    if let Some(s) = &scatter {
        let a = match (s.multiscatter_color, s.scatter_albedo) {
            (Some(a), _) => Some(a),
            (None, Some(a)) => {
                warnings.push(SceneWarning {
                    location: location.to_owned(),
                    message: format!(
                        "{VOLUME_SCATTER}: `scatterAlbedo` is the 2020 draft's name; read as multiscatterColor"
                    ),
                    help: "rename it to multiscatterColor (current draft)".into(),
                });
                Some(a)
            }
            (None, None) => None,
        };
        if let Some(a) = a {
            if a.iter().any(|x| !(0.0..=1.0).contains(x)) {
                return Err(err(
                    format!("{VOLUME_SCATTER}: multiscatterColor {a:?} is outside [0, 1]"),
                    "it is an albedo",
                ));
            }
            albedo = a.map(single_scatter_albedo);
        }
        if let Some(s) = s.scatter_anisotropy {
            g = [s; 3];
        }
    }
    let mut density = None;
    if let Some(v) = vendor {
        albedo = v.scattering_albedo.unwrap_or(albedo);
        g = v.anisotropy.map_or(g, |a| a.0);
        density = v.density;
    }
    Ok(Some(VolumeSpec {
        sigma_s: [0, 1, 2].map(|c| albedo[c] * sigma_t[c]),
        sigma_a: [0, 1, 2].map(|c| (1.0 - albedo[c]) * sigma_t[c]),
        g,
        density,
    }))
}
