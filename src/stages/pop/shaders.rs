//! The WGSL sources of the POP (elek2014) GPU passes, one `.wgsl` file per pass under `shaders/` beside
//! this file, compiled into the binary with `include_str!` and validated by naga before wgpu sees
//! them ([`Shader`]). Each file's header comment documents its bindings.

use crate::render::gpu::shaders::Shader;

/// The folder of these shader files, relative to the crate root (for diagnostics).
const DIR: &str = "src/stages/pop/shaders";

/// POP: one gathering iteration (elek2014 Eqs. 2–6) and the iterate's energy per workgroup.
pub const POP_STEP: Shader = Shader { dir: DIR, name: "pop_step.wgsl", source: include_str!("shaders/pop_step.wgsl") };
/// POP: the stopping rule (energy below `ε_L` of the seed), decided on the GPU.
pub const POP_ENERGY: Shader =
    Shader { dir: DIR, name: "pop_energy.wgsl", source: include_str!("shaders/pop_energy.wgsl") };
/// POP: accumulation toward the eye (Eqs. 7–8) and of the collided fluence.
pub const POP_ACCUMULATE: Shader =
    Shader { dir: DIR, name: "pop_accumulate.wgsl", source: include_str!("shaders/pop_accumulate.wgsl") };

/// Every shader of this technique, for validation.
pub const ALL: &[Shader] = &[POP_STEP, POP_ENERGY, POP_ACCUMULATE];
