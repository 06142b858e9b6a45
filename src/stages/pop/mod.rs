//! Principal-Ordinates Propagation (elek2014): real-time multiple scattering in heterogeneous,
//! strongly anisotropic media.
//!
//! **Input → output.** A voxel medium (or a scene medium voxelised into one), a directional light,
//! opaque surfaces and a POP preset (`tables::pop_preset`: flow table, iteration counts,
//! thresholds) → a light-aligned propagation grid ([`grid`]), its propagated radiance
//! ([`propagate`]) and a ray-marched image ([`render`]).
//!
//! | module | paper |
//! |---|---|
//! | [`crate::render::voxel`] | the medium volume of Sec. 4 (voxels, per-channel `σ_s`, `σ_a`, `g`) |
//! | [`grid`] | Sec. 4 grid aligned with `d`, Sec. 4.2 medium downsampling, link factors of Eqs. 2 and 4 |
//! | [`propagate`] | Sec. 4.1 sweep, Eqs. 2–6 iterations, Eqs. 7–8 accumulation, Sec. 5.4 residuum |
//! | [`render`] | Sec. 4.4 joint-bilateral upsampling and front-to-back ray marching |
//! | [`environment`] | Secs. 5.1, 5.3, 5.4: environment maps → ordinates with prefiltered lobes, merged grids and residuum |
//! | [`rsm`] | Sec. 6 instant radiosity: reflective shadow maps of the primary lights → VPLs for the surfaces' reflected light |
//!
//! Where voltab departs from the paper (the exact uncollided beam and first-scattering seed instead
//! of propagating `L_in T_i` from every cell; the phase convolution in the accumulation) is stated in
//! [`propagate`] and in `docs/design/pop.md`.

mod stage;
pub use stage::*;
#[cfg(feature = "gpu")]
pub mod gpu;
#[cfg(feature = "gpu")]
pub mod shaders;

pub mod environment;
pub mod fig12;
pub mod grid;
pub mod merge;
pub mod octa;
pub mod propagate;
pub mod radial;
pub mod radial_propagate;
pub mod render;
pub mod rsm;
pub mod scene;

#[cfg(test)]
mod tests;
#[cfg(test)]
mod tests_env;
#[cfg(test)]
mod tests_env_rotation;
#[cfg(test)]
mod tests_radial;
