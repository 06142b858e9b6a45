//! The GPU floor of the real-time techniques: device choice and the `wgpu` context their WGSL compute
//! passes (in `stages/<technique>/gpu.rs`) run on.
//!
//! **Input → output.** The same inputs as the CPU effects (a POP grid and flow table, an epipolar
//! frame's rectified slices, an image-fog frame's scattered image and spread) → the same outputs,
//! computed by one compute pipeline per pass, with per-pass GPU times (timestamp queries where the
//! adapter has them, else the wall time of each submitted pass).
//!
//! | module | pass | paper |
//! |---|---|---|
//! | [`context`] | adapter and device, buffers, chunked dispatch, timing, error capture | — |
//! | [`shaders`] | the shader type and its naga validation; the `.wgsl` sources live in `src/stages/<technique>/shaders/` | — |
//! | `stages::god_rays::gpu` | god rays: depth rectification, shadow-map depth modes, per-slice Fenwick sweep (one thread per slice), unrectification with the ring march; slice layout and SVD on the CPU | baran2010 Secs. 3–9 |
//! | `stages::image_fog::gpu` | image-space fog: per-pixel density integrals, `L_at`, `L_sc` and spread; MIP chain (masked 4-tap, colour + spread chains), level selection and B-spline fetch, compose | iser2018 Secs. 3.3, 4.1–4.4 |
//! | `stages::pop::gpu` | POP gathering iteration (Eqs. 2–6) and accumulation toward the eye (Eqs. 7–8) | elek2014 Secs. 4.2–4.3, 5.4 |
//!
//! The CPU implementations in `crate::stages` are the ground truth: every GPU pass has a test
//! that runs it on the bundled scenes and compares it with the CPU result within a stated
//! tolerance (f32 on the GPU against the CPU's f64 or f32, and a different summation order).
//!
//! Device selection ([`DeviceRequest`]) is compiled in every build so the command line can say
//! why a GPU is not used; everything that touches `wgpu` is behind the cargo feature `gpu`
//! (`cargo build --release --features gpu`). Without an adapter (no Vulkan driver), `auto` falls
//! back to the CPU and says why; `gpu` is an error naming the fix.

#[cfg(feature = "gpu")]
pub mod context;
#[cfg(feature = "gpu")]
pub mod shaders;

#[cfg(feature = "gpu")]
pub use context::{Gpu, GpuError};

use serde::{Deserialize, Serialize};

/// GPU time of one phase of a frame (written into stage summaries; empty on the CPU).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PassTime {
    /// The phase name.
    pub phase: String,
    /// Seconds, summed over the phase's passes.
    pub seconds: f64,
    /// Passes summed.
    pub passes: usize,
}

/// Where the real-time effects run, as asked on the command line (`--device`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize, clap::ValueEnum)]
#[serde(rename_all = "lowercase")]
pub enum DeviceRequest {
    /// The GPU when this build has the `gpu` feature and an adapter is found, else the CPU.
    #[default]
    Auto,
    /// Always the CPU implementations (the ground truth).
    Cpu,
    /// The GPU; an error when it cannot be had.
    Gpu,
}

/// The device the effects run on, once chosen.
#[derive(Debug, Clone)]
pub enum Device {
    /// The CPU implementations.
    Cpu,
    /// A wgpu device (shared by every stage of a run).
    #[cfg(feature = "gpu")]
    Gpu(std::sync::Arc<context::Gpu>),
}

impl Device {
    /// `"cpu"` or `"gpu"`, as written into stage summaries.
    pub fn name(&self) -> &'static str {
        match self {
            Device::Cpu => "cpu",
            #[cfg(feature = "gpu")]
            Device::Gpu(_) => "gpu",
        }
    }

    /// The GPU, when this is one.
    #[cfg(feature = "gpu")]
    pub fn gpu(&self) -> Option<&context::Gpu> {
        match self {
            Device::Gpu(g) => Some(g),
            Device::Cpu => None,
        }
    }
}

/// Chooses the device for `request`: the device and a one-line message saying which adapter was
/// chosen or why none was (printed by the command line).
///
/// # Errors
/// `--device gpu` when this build has no `gpu` feature or no adapter can be had; the message names
/// the fix.
pub fn select(request: DeviceRequest) -> Result<(Device, String), String> {
    match request {
        DeviceRequest::Cpu => Ok((Device::Cpu, "device: cpu (asked for with --device cpu)".to_string())),
        DeviceRequest::Auto | DeviceRequest::Gpu => select_gpu(request),
    }
}

#[cfg(not(feature = "gpu"))]
fn select_gpu(request: DeviceRequest) -> Result<(Device, String), String> {
    let why = "this voltab was built without the `gpu` cargo feature";
    match request {
        DeviceRequest::Gpu => Err(format!(
            "--device gpu: {why}\n  help: rebuild with `cargo build --release --features gpu`, or use --device cpu"
        )),
        _ => Ok((Device::Cpu, format!("device: cpu ({why}; rebuild with --features gpu for the GPU path)"))),
    }
}

#[cfg(feature = "gpu")]
fn select_gpu(request: DeviceRequest) -> Result<(Device, String), String> {
    match context::Gpu::new() {
        Ok(gpu) => {
            let msg = format!("device: gpu ({})", gpu.describe());
            Ok((Device::Gpu(std::sync::Arc::new(gpu)), msg))
        }
        Err(e) if request == DeviceRequest::Gpu => Err(format!(
            "--device gpu: {e}\n  help: install a Vulkan driver (on Debian without a GPU: `apt-get install \
             mesa-vulkan-drivers libvulkan1`), or use --device cpu"
        )),
        Err(e) => Ok((Device::Cpu, format!("device: cpu (no GPU adapter: {e})"))),
    }
}
