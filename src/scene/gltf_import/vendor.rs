//! voltab's vendor glTF extension `VOLTAB_participating_media`: what Khronos lacks for media.
//!
//! **Input → output.** The extension's raw JSON (on a material, or at the document root) → typed
//! values, with unknown fields and wrong types rejected naming the field. The same types generate
//! `schemas/VOLTAB_participating_media.schema.json` ([`schema`]), so the schema cannot drift from
//! what the importer accepts.
//!
//! - Material level: `scatteringAlbedo` and `anisotropy` split the extinction that
//!   `KHR_materials_volume` gives (σ_t = −ln(attenuationColor)/attenuationDistance) into σ_s and
//!   σ_a; `density` makes the medium heterogeneous.
//! - Root level: `global` is a medium filling all space outside closed media.

use std::borrow::Cow;

use schemars::{JsonSchema, Schema, SchemaGenerator, json_schema};
use serde::de::{DeserializeOwned, Error as _};
use serde::{Deserialize, Deserializer};
use serde_json::{Map, Value, json};

/// The extension's name.
pub(crate) const EXTENSION: &str = "VOLTAB_participating_media";

/// `materials[i].extensions.VOLTAB_participating_media`: scattering of the medium that
/// `KHR_materials_volume` puts inside every closed mesh using this (transmissive) material.
/// Overrides `KHR_materials_volume_scatter` field by field.
#[derive(Debug, Default, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields, rename_all = "camelCase")]
#[schemars(title = "Material-level VOLTAB_participating_media")]
pub(crate) struct MaterialMedium {
    /// Single-scattering albedo α = σ_s/σ_t per linear-RGB channel (dimensionless, 0 to 1; default
    /// [0, 0, 0], a pure absorber as in KHR_materials_volume). σ_s = α·σ_t and σ_a = (1 − α)·σ_t,
    /// where σ_t [1/m] = −ln(attenuationColor)/attenuationDistance comes from KHR_materials_volume.
    #[serde(default)]
    #[schemars(schema_with = "rgb_albedo", extend("x-unit" = "1 (dimensionless)", "default" = [0.0, 0.0, 0.0]))]
    pub scattering_albedo: Option<[f64; 3]>,
    /// Henyey-Greenstein mean cosine g of the phase function, one number for all channels or
    /// [r, g, b] (dimensionless, −1 < g < 1; default 0, isotropic).
    #[schemars(extend("x-unit" = "1 (dimensionless)", "default" = 0.0))]
    pub anisotropy: Option<Anisotropy>,
    /// Spatial density multiplying σ_s and σ_a (default: homogeneous, 1). Given in the local frame
    /// of the node instancing the mesh (offset as a point, direction as a plane normal), so the fog
    /// moves with the object; for nodes without scale that frame is metres.
    pub density: Option<DensitySpec>,
}

/// Root `extensions.VOLTAB_participating_media`: scene-wide media.
#[derive(Debug, Default, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields, rename_all = "camelCase")]
#[schemars(title = "Root-level VOLTAB_participating_media")]
pub(crate) struct RootMedia {
    /// The medium filling all space outside closed media (an atmosphere or room fog); at most one.
    pub global: Option<GlobalMedium>,
}

/// A homogeneous or height-varying medium everywhere outside closed media (world space).
#[derive(Debug, Default, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields, rename_all = "camelCase")]
pub(crate) struct GlobalMedium {
    /// Scattering coefficient σ_s per linear-RGB channel at density 1 [1/m], ≥ 0; default [0, 0, 0].
    #[serde(default)]
    #[schemars(schema_with = "rgb_coefficient", extend("x-unit" = "1/m", "default" = [0.0, 0.0, 0.0]))]
    pub sigma_s: Option<[f64; 3]>,
    /// Absorption coefficient σ_a per linear-RGB channel at density 1 [1/m], ≥ 0; default [0, 0, 0].
    #[serde(default)]
    #[schemars(schema_with = "rgb_coefficient", extend("x-unit" = "1/m", "default" = [0.0, 0.0, 0.0]))]
    pub sigma_a: Option<[f64; 3]>,
    /// Henyey-Greenstein mean cosine g, one number or [r, g, b] (−1 < g < 1; default 0).
    #[schemars(extend("x-unit" = "1 (dimensionless)", "default" = 0.0))]
    pub anisotropy: Option<Anisotropy>,
    /// Spatial density multiplying σ_s and σ_a, in world space (default: homogeneous, 1).
    pub density: Option<DensitySpec>,
}

/// iser2018's exponential height fog: ρ(x) = rho · exp(−falloff · ⟨x − offset, direction⟩),
/// multiplying σ_s and σ_a.
#[derive(Debug, Clone, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields, rename_all = "camelCase")]
pub(crate) struct DensitySpec {
    /// The density profile.
    #[serde(rename = "type")]
    pub kind: DensityKind,
    /// Density ρ' on the reference plane through `offset` (dimensionless multiplier, ≥ 0).
    #[schemars(range(min = 0.0), extend("x-unit" = "1 (dimensionless)"))]
    pub rho: f64,
    /// Falloff b along `direction` [1/m]: the density drops by e every 1/b metres (negative: rises).
    #[schemars(extend("x-unit" = "1/m"))]
    pub falloff: f64,
    /// Direction n the density decreases along ("up"); normalised on import, must be nonzero.
    /// Default [0, 1, 0] (+Y, glTF's up).
    #[serde(default)]
    #[schemars(schema_with = "vec3", extend("x-unit" = "1 (direction)", "default" = [0.0, 1.0, 0.0]))]
    pub direction: Option<[f64; 3]>,
    /// A point o on the reference plane [m]; default [0, 0, 0].
    #[serde(default)]
    #[schemars(schema_with = "vec3", extend("x-unit" = "m", "default" = [0.0, 0.0, 0.0]))]
    pub offset: Option<[f64; 3]>,
}

/// Density profiles.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize, JsonSchema)]
#[serde(rename_all = "camelCase")]
pub(crate) enum DensityKind {
    /// ρ(x) = rho · exp(−falloff · ⟨x − offset, direction⟩) (iser2018).
    ExponentialHeight,
}

/// HG g: one number for all channels or one per channel.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Anisotropy(pub [f64; 3]);

impl<'de> Deserialize<'de> for Anisotropy {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        let v = Value::deserialize(d)?;
        let g = match &v {
            Value::Number(n) => n.as_f64().map(|g| [g; 3]),
            Value::Array(a) if a.len() == 3 => match (a[0].as_f64(), a[1].as_f64(), a[2].as_f64()) {
                (Some(r), Some(g), Some(b)) => Some([r, g, b]),
                _ => None,
            },
            _ => None,
        };
        g.map(Anisotropy)
            .ok_or_else(|| D::Error::custom(format!("expected a number or an array of 3 numbers, found {v}")))
    }
}

impl JsonSchema for Anisotropy {
    fn schema_name() -> Cow<'static, str> {
        "Anisotropy".into()
    }

    fn json_schema(_: &mut SchemaGenerator) -> Schema {
        json_schema!({
            "description": "Henyey-Greenstein mean cosine g (dimensionless, -1 < g < 1): one number for all channels or [r, g, b].",
            "anyOf": [
                { "type": "number", "exclusiveMinimum": -1.0, "exclusiveMaximum": 1.0 },
                {
                    "type": "array",
                    "items": { "type": "number", "exclusiveMinimum": -1.0, "exclusiveMaximum": 1.0 },
                    "minItems": 3,
                    "maxItems": 3
                }
            ]
        })
    }
}

fn rgb_schema(item: Value) -> Schema {
    json_schema!({ "type": "array", "items": item, "minItems": 3, "maxItems": 3 })
}

fn rgb_albedo(_: &mut SchemaGenerator) -> Schema {
    rgb_schema(json!({ "type": "number", "minimum": 0.0, "maximum": 1.0 }))
}

fn rgb_coefficient(_: &mut SchemaGenerator) -> Schema {
    rgb_schema(json!({ "type": "number", "minimum": 0.0 }))
}

fn vec3(_: &mut SchemaGenerator) -> Schema {
    rgb_schema(json!({ "type": "number" }))
}

/// Parses the material-level object; errors name the field (`density.falloff`, …).
pub(crate) fn parse_material(value: &Value) -> Result<MaterialMedium, String> {
    if let Some(d) = value.get("density") {
        parse_named::<DensitySpec>(d, "density.")?.check("density.")?;
    }
    let m: MaterialMedium = parse_named(value, "")?;
    if let Some(a) = m.scattering_albedo
        && a.iter().any(|x| !(0.0..=1.0).contains(x))
    {
        return Err(format!("field `scatteringAlbedo`: {a:?} is outside [0, 1] (a single-scattering albedo)"));
    }
    Ok(m)
}

/// Parses the root-level object; errors name the field (`global.sigmaS`, …).
pub(crate) fn parse_root(value: &Value) -> Result<RootMedia, String> {
    if let Some(g) = value.get("global") {
        if let Some(d) = g.get("density") {
            parse_named::<DensitySpec>(d, "global.density.")?.check("global.density.")?;
        }
        parse_named::<GlobalMedium>(g, "global.")?;
    }
    parse_named(value, "")
}

impl DensitySpec {
    /// Range checks serde cannot express.
    fn check(&self, prefix: &str) -> Result<(), String> {
        if self.rho < 0.0 {
            return Err(format!("field `{prefix}rho`: {} is negative (a density multiplier is ≥ 0)", self.rho));
        }
        if self.direction.is_some_and(|d| d.iter().all(|c| *c == 0.0)) {
            return Err(format!("field `{prefix}direction`: [0, 0, 0] is not a direction"));
        }
        Ok(())
    }
}

/// Deserializes `value` as `T`. serde's messages for a wrong type do not say which field it was,
/// so each field is first tried alone (a one-entry object; `T`'s fields are optional or their
/// absence is ignored here) and the first that fails is named with `prefix`.
pub(super) fn parse_named<T: DeserializeOwned>(value: &Value, prefix: &str) -> Result<T, String> {
    let Value::Object(map) = value else {
        let at = prefix.strip_suffix('.').map_or(String::new(), |p| format!("field `{p}`: "));
        return Err(format!("{at}expected an object, found {value}"));
    };
    for (key, field) in map {
        let alone = Value::Object(Map::from_iter([(key.clone(), field.clone())]));
        if let Err(e) = serde_json::from_value::<T>(alone) {
            let text = e.to_string();
            if !text.starts_with("missing field") {
                return Err(format!("field `{prefix}{key}`: {text}"));
            }
        }
    }
    serde_json::from_value(value.clone()).map_err(|e| match prefix.strip_suffix('.') {
        Some(p) => format!("field `{p}`: {e}"),
        None => e.to_string(),
    })
}

/// JSON Schema (draft 2020-12) of the extension: the material-level or the root-level object.
pub fn schema() -> Value {
    let mut generator = schemars::generate::SchemaSettings::draft2020_12().into_generator();
    let material = generator.subschema_for::<MaterialMedium>();
    let root = generator.subschema_for::<RootMedia>();
    let defs = generator.take_definitions(true);
    json!({
        "$schema": "https://json-schema.org/draft/2020-12/schema",
        "title": EXTENSION,
        "description": "voltab's vendor glTF 2.0 extension for participating media (docs/design/scene.md). On a material (next to KHR_materials_volume and KHR_materials_transmission) it gives the scattering albedo, the HG anisotropy and a density field of the medium inside meshes using that material; at the document root, `global` is a medium filling all space outside closed media. Units: coefficients in 1/m, lengths in metres. Generated from the importer's types (src/scene/gltf_import/vendor.rs); do not edit.",
        "anyOf": [material, root],
        "$defs": defs,
    })
}
