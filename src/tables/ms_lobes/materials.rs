//! Material presets of wang2018 Table 2 (per-channel albedo α, mean free path ℓ, HG g), read from the
//! bundled RON file `materials.ron` beside this module.
//!
//! **Input → output.** A material name → its [`Material`]; the renderer passes each channel's `α` and
//! `σ_t = 1/ℓ` to [`super::MsLobesTable::radiance`].

use std::sync::OnceLock;

use serde::Deserialize;

/// One translucent material, per colour channel (R, G, B).
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Material {
    /// Preset name.
    pub name: String,
    /// Single-scattering albedo per channel.
    pub albedo: [f64; 3],
    /// Mean free path `ℓ = 1/σ_t` per channel (the paper's scene units).
    pub mfp: [f64; 3],
    /// HG mean cosine (shared by the channels).
    pub g: f64,
}

const SOURCE: &str = include_str!("materials.ron");

/// All presets, in file order. The bundled file is checked by a test; should it ever fail to parse,
/// the list is empty and every name is reported unknown (never a panic).
pub fn materials() -> &'static [Material] {
    static LIST: OnceLock<Vec<Material>> = OnceLock::new();
    LIST.get_or_init(|| ron::from_str::<Vec<Material>>(SOURCE).unwrap_or_default())
}

/// The preset called `name` (case-sensitive).
pub fn material(name: &str) -> Option<&'static Material> {
    materials().iter().find(|m| m.name == name)
}
