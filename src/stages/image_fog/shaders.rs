//! The WGSL sources of the image-space fog (iser2018) GPU passes, one `.wgsl` file per pass under `shaders/` beside
//! this file, compiled into the binary with `include_str!` and validated by naga before wgpu sees
//! them ([`Shader`]). Each file's header comment documents its bindings.

use crate::render::gpu::shaders::Shader;

/// The folder of these shader files, relative to the crate root (for diagnostics).
const DIR: &str = "src/stages/image_fog/shaders";

/// Image fog: one masked 4-tap MIP level of the colour and spread chains (iser2018 Secs. 4.2-4.3).
pub const FOG_DOWNSAMPLE: Shader =
    Shader { dir: DIR, name: "fog_downsample.wgsl", source: include_str!("shaders/fog_downsample.wgsl") };
/// Image fog: per-pixel density integrals, `L_at`, `L_sc` and spread into MIP level 0 (Secs. 3.3, 4.1).
pub const FOG_INTEGRALS: Shader =
    Shader { dir: DIR, name: "fog_integrals.wgsl", source: include_str!("shaders/fog_integrals.wgsl") };
/// Image fog: per-pixel level selection and B-spline/linear reconstruction (Secs. 4.2-4.3).
pub const FOG_FETCH: Shader =
    Shader { dir: DIR, name: "fog_fetch.wgsl", source: include_str!("shaders/fog_fetch.wgsl") };
/// Image fog: compose L' = L_at + L'_sc (Sec. 4.4).
pub const FOG_COMPOSE: Shader =
    Shader { dir: DIR, name: "fog_compose.wgsl", source: include_str!("shaders/fog_compose.wgsl") };

/// Every shader of this technique, for validation.
pub const ALL: &[Shader] = &[FOG_DOWNSAMPLE, FOG_INTEGRALS, FOG_FETCH, FOG_COMPOSE];
