//! Translucent media with smooth refractive boundaries: wang2018's point-based renderer and its
//! brute-force reference.
//!
//! **Input → output.** A scene with a closed dielectric mesh bounding a homogeneous medium (or the mesh
//! with a wang2018 Table 2 material put in its place), the scene's lights as small spherical emitters,
//! a camera and an `MsLobes` table → an HDR image split into the components of wang2018 Eq. 9 (single,
//! double, multiple, bounced scattering inside the object, and the rest of the picture).
//!
//! - [`points`] (Sec. 3.4): blue-noise surface samples on the boundary with the scene's indirect
//!   diffuse light, and volume samples along the refracted light rays (Fresnel, internal reflections).
//! - [`octree`] (Sec. 3.4, 4.2, 4.3): the spatial hierarchy over volume and surface samples, its
//!   ray traversal (single scattering), its tree cuts (Algorithm 1) and the two-step traversal.
//! - [`render`] (Sec. 3.5, 5.1): camera rays, sample depths (Eq. 10) and the components (Eq. 5–9).
//! - [`lowres`] (Sec. 5.1): which segments' smooth components are interpolated from a downsampled
//!   grid of anchor pixels.
//! - [`surface_light`] (Sec. 3.5.5): the diffuse light the boundary sends into the object, with every
//!   internal reflection.
//! - [`object_light`] (beyond the paper): the caustic and glow the object throws on the opaque
//!   surfaces around it, as photon maps from the light rays that leave it.
//! - [`compare`]: MSE against the reference (normalisation stated there), error against run time.
//! - [`crate::reference::translucent`]: an independent volumetric path tracer for dielectric-bounded homogeneous media,
//!   split by the number of scattering events in the medium.
//! - [`crate::render::dielectric`]: what both read — the medium inside the boundary, the emitters
//!   and the [`Setup`](crate::render::dielectric::Setup).
//!
//! **Lights.** A smooth refractive boundary makes every path from a point light to a pinhole camera
//! through the medium with one scattering event a measure-zero set, so a path tracer renders a point-lit
//! translucent object black. Both the renderer and the reference therefore treat each point light of
//! intensity `I` as a sphere of radius `r` and radiance `I/(πr²)` (same power, same far field), and the
//! scene's sphere lights as they are. Other light kinds are left out and reported.
//!
//! **Radiometry.** Light entering the object is tracked as flux (W), so the `η²` radiance scaling at the
//! boundary never appears inside; radiance leaving the object toward the camera is scaled by
//! `(1 − F)/η²`, the inverse of how a camera path's importance enters.

mod stage;
pub use stage::*;

pub mod compare;
pub mod lowres;
pub mod object_light;
pub mod octree;
pub mod points;
pub mod render;
#[cfg(test)]
mod render_tests;
pub mod surface_light;
