//! The wgpu device every GPU pass runs on.
//!
//! **Input → output.** Nothing (the system's Vulkan adapters) → a [`Gpu`]: one device and queue,
//! storage buffers made from and read back into slices, compute [`Kernel`]s made from the validated
//! `.wgsl` sources, and [`Gpu::run`], which records a list of [`Pass`]es into one command buffer,
//! submits it, waits, and returns each pass's time.
//!
//! **Conventions shared by every shader.** Kernels are one-dimensional with `@workgroup_size(64)`;
//! a pass over `n` items dispatches `⌈n/64⌉` workgroups folded into a 2-D grid whose x extent stays
//! within the adapter's `max_compute_workgroups_per_dimension` (65 535 by default), so any `n` up to
//! 2³² fits one dispatch; the shader recovers its item as `gid.x + gid.y · num_workgroups.x · 64`
//! and returns when it is `≥ n`. Bindings are group 0, binding `i` = the `i`-th buffer handed to
//! [`Gpu::bind`]; parameters travel in a uniform buffer of 32-bit words (floats as their bits).
//!
//! **Errors.** wgpu reports validation errors and device loss through callbacks; [`Gpu`] collects
//! them and every call that submits work returns them as a [`GpuError`] instead of panicking.

use std::sync::{Arc, Mutex};
use std::time::Instant;

use wgpu::util::DeviceExt;

use super::shaders::Shader;

/// Threads per workgroup of every kernel.
pub const WORKGROUP: u32 = 64;

/// What can go wrong on the GPU.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum GpuError {
    /// No adapter (no Vulkan driver, or none that wgpu accepts).
    #[error("no GPU adapter found ({0})")]
    NoAdapter(String),
    /// The adapter refused to create a device.
    #[error("the adapter {adapter} refused a device: {message}")]
    Device {
        /// Adapter name.
        adapter: String,
        /// Why.
        message: String,
    },
    /// A shader failed naga's validation.
    #[error("shader {name}: {message}")]
    Shader {
        /// The shader file.
        name: String,
        /// The rendered diagnostic.
        message: String,
    },
    /// wgpu reported a validation error or lost the device while running a pass.
    #[error("GPU error during {during}: {message}")]
    Runtime {
        /// The pass or transfer.
        during: String,
        /// wgpu's message.
        message: String,
    },
    /// The input does not fit the adapter (a buffer above its limit).
    #[error("{0}")]
    Limit(String),
}

/// A compute pipeline and its entry point.
#[derive(Debug)]
pub struct Kernel {
    pipeline: wgpu::ComputePipeline,
    name: String,
}

/// One dispatch of a kernel over `items` work items.
#[derive(Debug, Clone, Copy)]
pub struct Pass<'a> {
    /// The phase it is timed under (several passes may share one; their times add up).
    pub phase: &'a str,
    /// The kernel.
    pub kernel: &'a Kernel,
    /// Its bindings.
    pub bind: &'a wgpu::BindGroup,
    /// Work items (one thread each).
    pub items: u32,
}

pub use super::PassTime;

/// The device, its queue and what was learnt of the adapter.
pub struct Gpu {
    device: wgpu::Device,
    queue: wgpu::Queue,
    info: wgpu::AdapterInfo,
    timestamps: bool,
    max_groups: u32,
    max_buffer: u64,
    errors: Arc<Mutex<Vec<String>>>,
}

impl std::fmt::Debug for Gpu {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Gpu").field("adapter", &self.describe()).finish()
    }
}

impl Gpu {
    /// Opens the first high-performance adapter wgpu finds (Vulkan), with timestamp queries when the
    /// adapter has them and the adapter's own limits.
    ///
    /// # Errors
    /// [`GpuError::NoAdapter`] or [`GpuError::Device`].
    pub fn new() -> Result<Self, GpuError> {
        let instance = wgpu::Instance::new(wgpu::InstanceDescriptor::new_without_display_handle_from_env());
        let adapter = pollster::block_on(instance.request_adapter(&wgpu::RequestAdapterOptions {
            power_preference: wgpu::PowerPreference::HighPerformance,
            ..Default::default()
        }))
        .map_err(|e| GpuError::NoAdapter(e.to_string()))?;
        let info = adapter.get_info();
        let timestamps = adapter.features().contains(wgpu::Features::TIMESTAMP_QUERY);
        let required_features = if timestamps { wgpu::Features::TIMESTAMP_QUERY } else { wgpu::Features::empty() };
        let limits = adapter.limits();
        let (device, queue) = pollster::block_on(adapter.request_device(&wgpu::DeviceDescriptor {
            label: Some("voltab"),
            required_features,
            required_limits: limits.clone(),
            experimental_features: wgpu::ExperimentalFeatures::disabled(),
            memory_hints: wgpu::MemoryHints::Performance,
            trace: wgpu::Trace::Off,
        }))
        .map_err(|e| GpuError::Device { adapter: info.name.clone(), message: e.to_string() })?;
        let errors = Arc::new(Mutex::new(Vec::new()));
        let sink = errors.clone();
        device.on_uncaptured_error(Arc::new(move |e: wgpu::Error| {
            if let Ok(mut v) = sink.lock() {
                v.push(e.to_string());
            }
        }));
        let lost = errors.clone();
        device.set_device_lost_callback(move |reason, message| {
            if let Ok(mut v) = lost.lock() {
                v.push(format!("device lost ({reason:?}): {message}"));
            }
        });
        Ok(Gpu {
            device,
            queue,
            timestamps,
            max_groups: limits.max_compute_workgroups_per_dimension.max(1),
            max_buffer: limits.max_storage_buffer_binding_size.min(limits.max_buffer_size),
            info,
            errors,
        })
    }

    /// Adapter name, backend, device type and whether passes are timed by timestamp queries.
    pub fn describe(&self) -> String {
        format!(
            "{} [{:?}, {:?}{}], pass times from {}",
            self.info.name,
            self.info.backend,
            self.info.device_type,
            if self.is_software() { ", software rasteriser: times are CPU times" } else { "" },
            if self.timestamps { "timestamp queries" } else { "wall-clock waits" }
        )
    }

    /// True for a CPU adapter (lavapipe / llvmpipe): its pass times are not a GPU's.
    pub fn is_software(&self) -> bool {
        self.info.device_type == wgpu::DeviceType::Cpu
    }

    /// True when pass times come from timestamp queries.
    pub fn has_timestamps(&self) -> bool {
        self.timestamps
    }

    /// Workgroups allowed along one dispatch dimension.
    pub fn max_workgroups_per_dimension(&self) -> u32 {
        self.max_groups
    }

    /// The compute pipeline of `entry` in `shader` (validated by naga first, so a broken shader is an
    /// error naming the file and line, not a wgpu panic).
    ///
    /// # Errors
    /// [`GpuError::Shader`] or [`GpuError::Runtime`] (pipeline creation refused).
    pub fn kernel(&self, shader: &Shader, entry: &str) -> Result<Kernel, GpuError> {
        shader.validate().map_err(|message| GpuError::Shader { name: shader.name.to_string(), message })?;
        let module = self.device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some(shader.name),
            source: wgpu::ShaderSource::Wgsl(shader.source.into()),
        });
        let pipeline = self.device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
            label: Some(entry),
            layout: None,
            module: &module,
            entry_point: Some(entry),
            compilation_options: wgpu::PipelineCompilationOptions::default(),
            cache: None,
        });
        self.check(&format!("creating {}::{entry}", shader.name))?;
        Ok(Kernel { pipeline, name: format!("{}::{entry}", shader.name) })
    }

    fn check_size(&self, label: &str, bytes: u64) -> Result<u64, GpuError> {
        if bytes > self.max_buffer {
            return Err(GpuError::Limit(format!(
                "buffer {label} needs {bytes} bytes; the adapter binds at most {} (use a smaller grid or image)",
                self.max_buffer
            )));
        }
        // Zero-sized bindings are invalid: an empty input still gets one word.
        Ok(bytes.max(4).next_multiple_of(4))
    }

    /// A storage buffer holding `data` (readable back, writable by shaders).
    ///
    /// # Errors
    /// [`GpuError::Limit`] when it exceeds the adapter's binding size.
    pub fn buffer_from<T: bytemuck::Pod>(&self, label: &str, data: &[T]) -> Result<wgpu::Buffer, GpuError> {
        let bytes: &[u8] = bytemuck::cast_slice(data);
        let size = self.check_size(label, bytes.len() as u64)?;
        let usage = wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC | wgpu::BufferUsages::COPY_DST;
        if bytes.len() as u64 == size {
            Ok(self.device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some(label),
                contents: bytes,
                usage,
            }))
        } else {
            let mut padded = bytes.to_vec();
            padded.resize(size as usize, 0);
            Ok(self.device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some(label),
                contents: &padded,
                usage,
            }))
        }
    }

    /// A zero-filled storage buffer of `bytes` bytes.
    ///
    /// # Errors
    /// [`GpuError::Limit`] when it exceeds the adapter's binding size.
    pub fn buffer_zeroed(&self, label: &str, bytes: u64) -> Result<wgpu::Buffer, GpuError> {
        let size = self.check_size(label, bytes)?;
        Ok(self.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some(label),
            size,
            usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        }))
    }

    /// A uniform buffer of 32-bit words (pad structs to 16 bytes in the shader as WGSL requires).
    pub fn uniform(&self, label: &str, words: &[u32]) -> wgpu::Buffer {
        let mut w = words.to_vec();
        w.resize(words.len().max(4).next_multiple_of(4), 0);
        self.device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some(label),
            contents: bytemuck::cast_slice(&w),
            usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
        })
    }

    /// Overwrites the start of `buffer` with `data`.
    pub fn write<T: bytemuck::Pod>(&self, buffer: &wgpu::Buffer, data: &[T]) {
        self.queue.write_buffer(buffer, 0, bytemuck::cast_slice(data));
    }

    /// Binds `buffers` to group 0 of `kernel`, binding `i` = `buffers[i]`.
    pub fn bind(&self, kernel: &Kernel, buffers: &[&wgpu::Buffer]) -> wgpu::BindGroup {
        let entries: Vec<wgpu::BindGroupEntry> = buffers
            .iter()
            .enumerate()
            .map(|(i, b)| wgpu::BindGroupEntry { binding: i as u32, resource: b.as_entire_binding() })
            .collect();
        self.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some(&kernel.name),
            layout: &kernel.pipeline.get_bind_group_layout(0),
            entries: &entries,
        })
    }

    /// Binds `buffers` to group 0 of `kernel` at the given binding numbers (for kernels whose shader
    /// declares bindings the entry point does not use, which wgpu leaves out of its layout).
    pub fn bind_at(&self, kernel: &Kernel, buffers: &[(u32, &wgpu::Buffer)]) -> wgpu::BindGroup {
        let entries: Vec<wgpu::BindGroupEntry> = buffers
            .iter()
            .map(|&(binding, b)| wgpu::BindGroupEntry { binding, resource: b.as_entire_binding() })
            .collect();
        self.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some(&kernel.name),
            layout: &kernel.pipeline.get_bind_group_layout(0),
            entries: &entries,
        })
    }

    /// The largest storage buffer the adapter binds \[bytes\].
    pub fn max_binding(&self) -> u64 {
        self.max_buffer
    }

    /// The 2-D workgroup grid of a pass over `items` items (see the module doc).
    pub fn groups(&self, items: u32) -> (u32, u32) {
        let groups = items.div_ceil(WORKGROUP).max(1);
        let x = groups.min(self.max_groups);
        (x, groups.div_ceil(x))
    }

    /// Records `passes` in order into one command buffer, submits it, waits for it, and returns the
    /// time of each phase (in first-seen order).
    ///
    /// # Errors
    /// [`GpuError::Runtime`] with wgpu's message when a pass was invalid or the device was lost.
    pub fn run(&self, passes: &[Pass]) -> Result<Vec<PassTime>, GpuError> {
        // Timestamp queries: two per pass, in batches the query set can hold.
        const BATCH: usize = 1024;
        let mut times: Vec<PassTime> = Vec::new();
        let mut add = |phase: &str, seconds: f64| match times.iter_mut().find(|t| t.phase == phase) {
            Some(t) => {
                t.seconds += seconds;
                t.passes += 1;
            }
            None => times.push(PassTime { phase: phase.to_string(), seconds, passes: 1 }),
        };
        for batch in passes.chunks(BATCH) {
            if self.timestamps {
                let ticks = self.run_timed(batch)?;
                let period = self.queue.get_timestamp_period() as f64 * 1e-9;
                for (p, t) in batch.iter().zip(ticks.chunks(2)) {
                    add(p.phase, t[1].saturating_sub(t[0]) as f64 * period);
                }
            } else {
                for p in batch {
                    let start = Instant::now();
                    self.submit(std::slice::from_ref(p), None)?;
                    add(p.phase, start.elapsed().as_secs_f64());
                }
            }
        }
        Ok(times)
    }

    fn run_timed(&self, passes: &[Pass]) -> Result<Vec<u64>, GpuError> {
        let count = (2 * passes.len()) as u32;
        let set = self.device.create_query_set(&wgpu::QuerySetDescriptor {
            label: Some("pass times"),
            ty: wgpu::QueryType::Timestamp,
            count,
        });
        let bytes = count as u64 * 8;
        let resolve = self.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("timestamps"),
            size: bytes,
            usage: wgpu::BufferUsages::QUERY_RESOLVE | wgpu::BufferUsages::COPY_SRC,
            mapped_at_creation: false,
        });
        self.submit(passes, Some((&set, &resolve)))?;
        let raw = self.read_bytes(&resolve, bytes, "timestamps")?;
        Ok(bytemuck::cast_slice::<u8, u64>(&raw).to_vec())
    }

    fn submit(&self, passes: &[Pass], timing: Option<(&wgpu::QuerySet, &wgpu::Buffer)>) -> Result<(), GpuError> {
        let mut encoder = self.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("voltab") });
        for (i, p) in passes.iter().enumerate() {
            let timestamp_writes = timing.map(|(set, _)| wgpu::ComputePassTimestampWrites {
                query_set: set,
                beginning_of_pass_write_index: Some(2 * i as u32),
                end_of_pass_write_index: Some(2 * i as u32 + 1),
            });
            let mut pass = encoder
                .begin_compute_pass(&wgpu::ComputePassDescriptor { label: Some(&p.kernel.name), timestamp_writes });
            pass.set_pipeline(&p.kernel.pipeline);
            pass.set_bind_group(0, p.bind, &[]);
            let (x, y) = self.groups(p.items);
            pass.dispatch_workgroups(x, y, 1);
        }
        if let Some((set, buffer)) = timing {
            encoder.resolve_query_set(set, 0..2 * passes.len() as u32, buffer, 0);
        }
        self.queue.submit([encoder.finish()]);
        self.wait("submitting passes")?;
        let during = passes.first().map(|p| p.kernel.name.clone()).unwrap_or_default();
        self.check(&during)
    }

    fn wait(&self, during: &str) -> Result<(), GpuError> {
        self.device
            .poll(wgpu::PollType::wait_indefinitely())
            .map(|_| ())
            .map_err(|e| GpuError::Runtime { during: during.to_string(), message: e.to_string() })
    }

    /// Returns (and clears) the errors wgpu reported since the last check.
    fn check(&self, during: &str) -> Result<(), GpuError> {
        let mut errors = self.errors.lock().unwrap_or_else(|p| p.into_inner());
        if errors.is_empty() {
            return Ok(());
        }
        let message = errors.join("\n");
        errors.clear();
        Err(GpuError::Runtime { during: during.to_string(), message })
    }

    /// Reads the first `count` elements of `buffer` back.
    ///
    /// # Errors
    /// [`GpuError::Runtime`] when the copy or the mapping fails.
    pub fn read<T: bytemuck::Pod>(&self, buffer: &wgpu::Buffer, count: usize) -> Result<Vec<T>, GpuError> {
        let bytes = (count * std::mem::size_of::<T>()) as u64;
        if bytes == 0 {
            return Ok(Vec::new());
        }
        let raw = self.read_bytes(buffer, bytes, "reading a result")?;
        Ok(bytemuck::pod_collect_to_vec(&raw))
    }

    fn read_bytes(&self, buffer: &wgpu::Buffer, bytes: u64, during: &str) -> Result<Vec<u8>, GpuError> {
        let size = bytes.next_multiple_of(wgpu::COPY_BUFFER_ALIGNMENT);
        let staging = self.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("readback"),
            size,
            usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let mut encoder =
            self.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("readback") });
        encoder.copy_buffer_to_buffer(buffer, 0, &staging, 0, size);
        self.queue.submit([encoder.finish()]);
        let slice = staging.slice(..);
        let (tx, rx) = std::sync::mpsc::channel();
        slice.map_async(wgpu::MapMode::Read, move |r| {
            let _ = tx.send(r);
        });
        self.wait(during)?;
        self.check(during)?;
        // When several threads share the device (the test harness), another thread's poll may be
        // the one that runs this callback, after this thread's poll has returned: wait for it.
        match rx.recv_timeout(std::time::Duration::from_secs(120)) {
            Ok(Ok(())) => {}
            Ok(Err(e)) => return Err(GpuError::Runtime { during: during.to_string(), message: e.to_string() }),
            Err(_) => {
                return Err(GpuError::Runtime {
                    during: during.to_string(),
                    message: "the buffer was never mapped".into(),
                });
            }
        }
        let view = slice
            .get_mapped_range()
            .map_err(|e| GpuError::Runtime { during: during.to_string(), message: e.to_string() })?;
        let out = view[..bytes as usize].to_vec();
        drop(view);
        staging.unmap();
        Ok(out)
    }
}

/// Words of a uniform block: `u32`s as they are, `f32`s as their bits.
#[derive(Debug, Clone, Default)]
pub struct Words(pub Vec<u32>);

impl Words {
    /// Appends an unsigned integer.
    pub fn u(mut self, v: u32) -> Self {
        self.0.push(v);
        self
    }
    /// Appends a float.
    pub fn f(mut self, v: f32) -> Self {
        self.0.push(v.to_bits());
        self
    }
    /// Pads with zeros to a multiple of 4 words (16 bytes, a WGSL `vec4` boundary).
    pub fn pad(mut self) -> Self {
        while !self.0.len().is_multiple_of(4) {
            self.0.push(0);
        }
        self
    }
}

/// The device the tests share (one per test binary). Panics with an install hint when there is no
/// adapter: the GPU tests fail on a machine without Vulkan rather than pass by skipping.
#[cfg(test)]
pub fn test_gpu() -> &'static Gpu {
    static GPU: std::sync::OnceLock<Gpu> = std::sync::OnceLock::new();
    GPU.get_or_init(|| {
        Gpu::new().unwrap_or_else(|e| {
            panic!("{e}: the GPU tests need a Vulkan adapter (without a GPU: apt-get install mesa-vulkan-drivers libvulkan1)")
        })
    })
}
