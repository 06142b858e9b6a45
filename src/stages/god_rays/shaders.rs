//! The WGSL sources of the epipolar god rays (baran2010) GPU passes, one `.wgsl` file per pass under `shaders/` beside
//! this file, compiled into the binary with `include_str!` and validated by naga before wgpu sees
//! them ([`Shader`]). Each file's header comment documents its bindings.

use crate::render::gpu::shaders::Shader;

/// The folder of these shader files, relative to the crate root (for diagnostics).
const DIR: &str = "src/stages/god_rays/shaders";

/// Epipolar god rays: the declarations all `epi_*` passes share (parameters, camera, shadow-map and
/// light functions). Prepended to each pass's source: WGSL has no include.
pub const EPI_COMMON: Shader =
    Shader { dir: DIR, name: "epi_common.wgsl", source: include_str!("shaders/epi_common.wgsl") };
/// Epipolar: depth rectification per slice sample (baran2010 Sec. 3, Sec. 9).
pub const EPI_RECTIFY: Shader = Shader {
    dir: DIR,
    name: "epi_rectify.wgsl",
    source: concat!(include_str!("shaders/epi_common.wgsl"), include_str!("shaders/epi_rectify.wgsl")),
};
/// Epipolar: rectified shadow map, depth modes and light modulation per (slice, γ bin) (Secs. 6–7).
pub const EPI_PREFILTER: Shader = Shader {
    dir: DIR,
    name: "epi_prefilter.wgsl",
    source: concat!(include_str!("shaders/epi_common.wgsl"), include_str!("shaders/epi_prefilter.wgsl")),
};
/// Epipolar: per-lane scale and integer leaves of each slice's integrand (Sec. 6).
pub const EPI_QUANTISE: Shader = Shader {
    dir: DIR,
    name: "epi_quantise.wgsl",
    source: concat!(include_str!("shaders/epi_common.wgsl"), include_str!("shaders/epi_quantise.wgsl")),
};
/// Epipolar: in-scatter per view ray from the partial sums of the visible leaves (Secs. 4–7).
pub const EPI_INTEGRATE: Shader = Shader {
    dir: DIR,
    name: "epi_integrate.wgsl",
    source: concat!(include_str!("shaders/epi_common.wgsl"), include_str!("shaders/epi_integrate.wgsl")),
};
/// Epipolar: unrectification, transmittance and the ray-marched ring (Secs. 3, 6).
pub const EPI_UNRECTIFY: Shader = Shader {
    dir: DIR,
    name: "epi_unrectify.wgsl",
    source: concat!(include_str!("shaders/epi_common.wgsl"), include_str!("shaders/epi_unrectify.wgsl")),
};

/// Every shader of this technique, for validation.
pub const ALL: &[Shader] = &[EPI_COMMON, EPI_RECTIFY, EPI_PREFILTER, EPI_QUANTISE, EPI_INTEGRATE, EPI_UNRECTIFY];
