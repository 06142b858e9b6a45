//! baran2010 epipolar god rays on the GPU: depth rectification, the partial-sum integration over
//! each slice and unrectification as compute passes.
//!
//! **Input → output.** The same inputs as [`epipolar::render`] (camera, distance image, light,
//! shadow map, homogeneous medium, [`EpipolarOptions`]) → the same [`EpipolarOutput`] (in-scatter,
//! view transmittance, stats), plus the GPU time of each phase.
//!
//! **Paper.** Sec. 3 (rectification, `epi_rectify.wgsl`), Sec. 7 (shadow-map rectification into depth
//! modes, `epi_prefilter.wgsl`), Secs. 4–6 (partial sums of the rank-`N` factorised integrand:
//! `epi_quantise.wgsl` quantises each slice's leaves, `epi_integrate.wgsl` sums the visible leaves
//! below each view ray's `γ_end` and combines them with `B_i(β)`), Sec. 3/6 (unrectification, and ray
//! marching in the ring around the epipole, `epi_unrectify.wgsl`); Sec. 9 for spot lights.
//!
//! **Integration, and how it differs from the paper's sweep.** The CPU (and the paper) sweep each
//! slice's `β` samples in order in one thread, updating a Fenwick tree as depth modes are passed:
//! `O(log bins)` per sample, but one long sequential loop per slice. The device cuts each slice's
//! samples into blocks of about √S (`integration_blocks`): one pass evaluates every bin's visible
//! leaf at each block's first sample and prefix-sums it, and lists the bins with a depth mode inside
//! the block; each (sample, lane) thread then takes its block's prefix sum at its `γ_end` bin and
//! subtracts what the listed bins below it lose between the block's start and its own `β`. Work per
//! lane is `O(S/T·bins + S·modes·T/S)` for blocks of `T` (balanced near `T = √S`), with no thread
//! depending on another. The leaves are the same integers the CPU's tree holds and integer sums are
//! exact in any order, so both give the same partial sums up to the f32 rounding of the leaves, and
//! every block size gives the same bits (a test). A second reason: lavapipe (Mesa 22.3, the CI's
//! device) silently ends a loop nest after 65 535 iterations in total, which a per-slice sweep
//! exceeds by far; every pass here keeps each thread's loops below that (measured: a sweep lost the
//! lanes past the first few on 12-lane slices).
//!
//! **Split.** The CPU lays out the slices ([`Setup::layout`], Sec. 8: a few hundred directions from
//! the epipole's position) and factorises the kernel by SVD ([`Factorization::from_extent`]: a
//! 128×64 Jacobi SVD per channel kernel, once per frame), which needs the largest rectified depth,
//! read back from the rectification pass (one word per slice). Everything per sample, per bin and
//! per pixel runs on the device. Slices are integrated in chunks whose scratch (events, leaves, lane
//! sums) fits the adapter's binding limit, so any image size runs.
//!
//! **Precision.** f32 throughout (the CPU uses f64), and the leaves are i32 with a per-lane scale
//! keeping a slice's sum below 2³⁰ (the CPU: i64 below 2⁶²), so a bin is quantised to about
//! 2³⁰/bins levels of its lane's largest value. Discrete decisions (which texel a point falls in,
//! which view ray a blocker terminates, whether a sample's depth matches a pixel's) can flip where
//! f32 and f64 straddle a boundary; such pixels differ by the local contrast of the effect. The tests
//! state the measured differences and their tolerances.

use std::time::Instant;

use glam::DVec3;

use super::shaders;
use crate::physics::rng::StreamKey;
use crate::render::gpu::context::{Gpu, GpuError, Pass, PassTime, Words};
use crate::render::spot::SpotCone;
use crate::render::{DistanceImage, Image, ViewCamera};
use crate::stages::god_rays::factor::{BETA_NODES, Factorization};
use crate::stages::god_rays::rectify::{Geo, Setup, SliceLayout};
use crate::stages::god_rays::{
    self as epipolar, EpiLight, EpiMedium, EpipolarOptions, EpipolarOutput, EpipolarStats, LightFrame, ShadowMap,
};

/// β samples per integration block and blocks per slice for slices of at most `max_beta` samples:
/// blocks of about √`max_beta` samples (at least 16) balance `epi_integrate.wgsl`'s two costs, the
/// per-block prefix sums over every bin and the per-sample walk over the block's changed bins.
fn integration_blocks(max_beta: u32) -> [u32; 2] {
    let block = (f64::from(max_beta).sqrt().ceil() as u32).max(16);
    [block, max_beta.div_ceil(block).max(1)]
}

/// Scratch the slice chunks may use in all \[bytes\].
const CHUNK_BUDGET: u64 = 192 << 20;

fn f3(v: DVec3) -> [f32; 3] {
    v.as_vec3().to_array()
}

fn word4(w: Words, xyz: [f32; 3], last: f32) -> Words {
    w.f(xyz[0]).f(xyz[1]).f(xyz[2]).f(last)
}

/// The frame's fixed parameters: everything in `EpiParams` but the chunk words.
struct Frame {
    head: Words,
    n0: [u32; 4],
    n1: [u32; 4],
    tex_size: [u32; 2],
    samples: u32,
    key: u64,
    max_beta: u32,
    /// β samples per integration block, and blocks per slice (`epi_integrate.wgsl`).
    block: [u32; 2],
}

impl Frame {
    fn uniform(&self, gpu: &Gpu, label: &str, first: u32, count: u32) -> wgpu::Buffer {
        let mut w = self.head.clone();
        for v in self.n0.iter().chain(&self.n1) {
            w = w.u(*v);
        }
        w = w.u(self.tex_size[0]).u(self.tex_size[1]).u(first).u(self.samples);
        w = w.u(count).u(0).u(self.key as u32).u((self.key >> 32) as u32);
        w = w.u(self.max_beta).u(self.block[0]).u(self.block[1]).pad();
        gpu.uniform(label, &w.0)
    }
}

/// The head of `EpiParams` (camera, light, shadow frame, bounds, medium, epipole) in words.
fn head_words(
    cam: &ViewCamera,
    setup: &Setup,
    light: &EpiLight,
    shadow: &ShadowMap,
    medium: &EpiMedium,
    dgamma: f64,
    x_range: (f64, f64),
) -> Words {
    let mut w = Words::default();
    let aspect = cam.width as f64 / cam.height.max(1) as f64;
    w = word4(w, f3(cam.position), cam.tan_half_y as f32);
    w = word4(w, f3(cam.forward), aspect as f32);
    w = word4(w, f3(cam.right), cam.width as f32);
    w = word4(w, f3(cam.up), cam.height as f32);
    let (kind, pos, dist) = match setup.geo {
        Geo::Directional { .. } => (0.0, DVec3::ZERO, 1.0),
        Geo::Spot { pos, dist, .. } => (1.0, pos, dist),
    };
    w = word4(w, f3(setup.geo.toward()), kind);
    w = word4(w, f3(pos), dist as f32);
    // A spot without a cone (degenerate axis or angles) lights nothing, as on the CPU: cos_outer 2.
    let cone = match light {
        EpiLight::Directional { direction, .. } => {
            SpotCone { axis: DVec3::from_array(*direction), cos_outer: 0.0, inv_range: 1.0 }
        }
        EpiLight::Spot { .. } => {
            light.cone().unwrap_or(SpotCone { axis: DVec3::NEG_Y, cos_outer: 2.0, inv_range: 1.0 })
        }
    };
    w = word4(w, f3(cone.axis), cone.inv_range as f32);
    let strength = light.strength().map(|c| if c.is_finite() { c.max(0.0) as f32 } else { 0.0 });
    w = word4(w, strength, cone.cos_outer as f32);
    match shadow.frame {
        LightFrame::Ortho { origin, ax_u, ax_v, dir, extent } => {
            w = word4(w, f3(origin), 0.0);
            w = word4(w, f3(ax_u), extent[0] as f32);
            w = word4(w, f3(ax_v), extent[1] as f32);
            w = word4(w, f3(dir), shadow.bias as f32);
        }
        LightFrame::Persp { pos, fwd, right, up, tan_half } => {
            w = word4(w, f3(pos), 1.0);
            w = word4(w, f3(right), tan_half as f32);
            w = word4(w, f3(up), 0.0);
            w = word4(w, f3(fwd), shadow.bias as f32);
        }
    }
    let tex = if light.texture().is_some_and(|t| t.width > 0 && t.height > 0) { 1.0 } else { 0.0 };
    w = word4(w, medium.region.0.map(|x| x as f32), shadow.resolution as f32);
    w = word4(w, medium.region.1.map(|x| x as f32), tex);
    let g = medium.phase_g();
    w = word4(w, medium.sigma_s_clean().map(|x| x as f32), g as f32);
    w = word4(w, medium.sigma_t().map(|x| x as f32), dgamma as f32);
    w = w.f(setup.epipole[0] as f32).f(setup.epipole[1] as f32).f(setup.ref_dir[0] as f32).f(setup.ref_dir[1] as f32);
    w.f(setup.ring as f32).f(x_range.0 as f32).f(x_range.1 as f32).f(if setup.inside { 1.0 } else { 0.0 })
}

/// Distances for the device: `< 0` where nothing was hit (infinite or NaN), negatives clamped to 0.
fn device_depth(depth: &DistanceImage, w: usize, h: usize) -> Vec<f32> {
    (0..w * h)
        .map(|i| {
            let d = epipolar::depth_at(depth, i % w, i / w);
            if d.is_finite() { d.max(0.0) } else { -1.0 }
        })
        .collect()
}

/// Renders the in-scatter and transmittance like [`epipolar::render`], on `gpu`.
///
/// # Errors
/// [`GpuError::Limit`] when one slice's scratch exceeds the adapter's binding size or
/// `ring_steps` exceeds 65 535; [`GpuError::Runtime`] on a device error.
pub fn render(
    gpu: &Gpu,
    cam: &ViewCamera,
    depth: &DistanceImage,
    light: &EpiLight,
    shadow: &ShadowMap,
    medium: &EpiMedium,
    opts: &EpipolarOptions,
) -> Result<(EpipolarOutput, Vec<PassTime>), GpuError> {
    render_chunked(gpu, cam, depth, light, shadow, medium, opts, CHUNK_BUDGET, None)
}

/// [`render`] with at most `budget` bytes of per-chunk scratch (at least one slice per chunk) and,
/// when given, `block` β samples per integration block instead of [`integration_blocks`]' choice.
#[allow(clippy::too_many_arguments)]
fn render_chunked(
    gpu: &Gpu,
    cam: &ViewCamera,
    depth: &DistanceImage,
    light: &EpiLight,
    shadow: &ShadowMap,
    medium: &EpiMedium,
    opts: &EpipolarOptions,
    budget: u64,
    block: Option<u32>,
) -> Result<(EpipolarOutput, Vec<PassTime>), GpuError> {
    let start = Instant::now();
    let mut stats = EpipolarStats::default();
    let (w, h) = (cam.width, cam.height);
    let rank = opts.rank.clamp(1, BETA_NODES);
    let st = medium.sigma_t();
    let kernels = if st[0] == st[1] && st[1] == st[2] { 1 } else { 3 };
    let ch = if kernels == 3 || light.texture().is_some() { 3 } else { 1 };

    if opts.ring_steps > 65_535 {
        return Err(GpuError::Limit(format!(
            "epipolar: ring_steps = {} exceeds the 65 535 loop iterations a device thread may run (lavapipe ends longer loops silently); use at most 65 535",
            opts.ring_steps
        )));
    }

    // The device path integrates every slice by the tree: it refuses what the CPU path ray marches
    // (an eye outside the medium's region; a light gain above MAX_LIGHT_GAIN, bounded here by the
    // region's corner furthest behind the eye's plane along the direction to the light).
    if !medium.contains(cam.position) {
        return Err(GpuError::Limit(
            "epipolar: the camera is outside the fog's region (the CPU path ray marches that case)".into(),
        ));
    }
    if let Geo::Directional { t } = Geo::new(cam.position, light) {
        let (lo, hi) = medium.region;
        let behind = (0..8)
            .map(|c| DVec3::new([lo, hi][c & 1][0], [lo, hi][(c >> 1) & 1][1], [lo, hi][(c >> 2) & 1][2]))
            .map(|p| (p - cam.position).dot(t))
            .fold(0.0f64, f64::min);
        let gain = st.iter().fold(1.0f64, |g, &s| g.max((-s * behind).exp()));
        if gain > epipolar::MAX_LIGHT_GAIN {
            return Err(GpuError::Limit(format!(
                "epipolar: the fog is optically thick behind the eye's plane (light gain up to {gain:.3e} > {}; the CPU path ray marches those slices)",
                epipolar::MAX_LIGHT_GAIN
            )));
        }
    }

    // 1. Slice layout (CPU), rectification (GPU).
    let t0 = Instant::now();
    let (mut setup, layout) = Setup::layout(cam, light, opts);
    let layout_ms = ms(t0);
    let nslices = layout.len();
    let mut offs = vec![0u32; nslices + 1];
    for (k, l) in layout.iter().enumerate() {
        offs[k + 1] = offs[k] + l.n as u32;
    }
    let samples = offs[nslices];
    let max_beta = layout.iter().map(|l| l.n).max().unwrap_or(0) as u32;
    stats.slices = nslices;
    stats.samples = samples as usize;
    let slice_words: Vec<[f32; 4]> = layout
        .iter()
        .flat_map(|l: &SliceLayout| {
            let u = f3(l.u);
            [[u[0], u[1], u[2], l.beta_lo as f32], [l.beta_hi as f32, 0.0, 0.0, 0.0]]
        })
        .collect();
    let angles: Vec<f32> = layout.iter().map(|l| l.angle as f32).collect();

    let shadow_buf = gpu.buffer_from(
        "epi shadow",
        &shadow.depth.iter().map(|&d| if d.is_finite() { d } else { -1.0 }).collect::<Vec<f32>>(),
    )?;
    let tex_data: Vec<[f32; 4]> = match light.texture().filter(|t| t.width > 0 && t.height > 0) {
        Some(t) => t
            .data
            .iter()
            .map(|c| c.map(|x| if x.is_finite() && x > 0.0 { x } else { 0.0 }))
            .map(|c| [c[0], c[1], c[2], 0.0])
            .collect(),
        None => vec![[1.0; 4]],
    };
    let tex_size =
        light.texture().filter(|t| t.width > 0 && t.height > 0).map_or([1, 1], |t| [t.width as u32, t.height as u32]);
    let tex_buf = gpu.buffer_from("epi texture", &tex_data)?;
    let slices_buf = gpu.buffer_from("epi slices", &slice_words)?;
    let offs_buf = gpu.buffer_from("epi offsets", &offs)?;
    let angles_buf = gpu.buffer_from("epi angles", &angles)?;
    let depth_buf = gpu.buffer_from("epi depth", &device_depth(depth, w, h))?;
    let sample_bytes = u64::from(samples) * 4;
    let betas_buf = gpu.buffer_zeroed("epi betas", sample_bytes)?;
    let gend_buf = gpu.buffer_zeroed("epi gamma_end", sample_bytes)?;
    let cots_buf = gpu.buffer_zeroed("epi cot beta", sample_bytes)?;
    let gmax_buf = gpu.buffer_zeroed("epi slice gamma max", nslices as u64 * 4)?;

    let key = StreamKey { table: crate::stages::god_rays::reference::JITTER_TABLE, cell: 0 }.table_word();
    let sub = if opts.depth_modes > 1 { 4 } else { 1 };
    let mut frame = Frame {
        head: head_words(cam, &setup, light, shadow, medium, 0.0, (0.0, 1.0)),
        n0: [nslices as u32, 0, rank as u32, kernels as u32],
        n1: [sub, opts.depth_modes.max(1) as u32, opts.ring_steps.max(1) as u32, ch as u32],
        tex_size,
        samples,
        key,
        max_beta,
        block: match block {
            Some(b) => [b.max(1), max_beta.div_ceil(b.max(1)).max(1)],
            None => integration_blocks(max_beta),
        },
    };
    let rectify = gpu.kernel(&shaders::EPI_RECTIFY, "main")?;
    let p0 = frame.uniform(gpu, "epi rectify params", 0, 0);
    let bind = gpu.bind_at(
        &rectify,
        &[
            (0, &p0),
            (3, &slices_buf),
            (4, &offs_buf),
            (5, &depth_buf),
            (6, &betas_buf),
            (7, &gend_buf),
            (8, &cots_buf),
            (9, &gmax_buf),
        ],
    );
    let mut times = gpu.run(&[Pass { phase: "rectify", kernel: &rectify, bind: &bind, items: samples }])?;
    let slice_gmax: Vec<f32> = gpu.read::<u32>(&gmax_buf, nslices)?.into_iter().map(f32::from_bits).collect();
    setup.gamma_max = slice_gmax.iter().fold(0.0f64, |m, &g| m.max(f64::from(g)));

    // 2. Factorisation (CPU).
    let t1 = Instant::now();
    let fac = Factorization::from_extent(setup.geo, setup.beta_range, setup.gamma_max, medium, opts);
    stats.factorize_ms = ms(t1);
    stats.svd_residual = fac.residual;
    let bins = fac.bins;
    let nbins: Vec<u32> = slice_gmax
        .iter()
        .map(|&g| ((((f64::from(g) / fac.dgamma).ceil() as usize) + 1).clamp(1, bins)) as u32)
        .collect();
    frame.head = head_words(cam, &setup, light, shadow, medium, fac.dgamma, fac.x_range);
    frame.n0[1] = bins as u32;
    let nbins_buf = gpu.buffer_from("epi bins per slice", &nbins)?;
    let gfn: Vec<f32> = fac.gamma_fn.iter().map(|&x| x as f32).collect();
    let bnode: Vec<f32> = fac.bnode.iter().map(|&x| x as f32).collect();
    let gfn_buf = gpu.buffer_from("epi Gamma_i", &gfn)?;
    let bnode_buf = gpu.buffer_from("epi B_i nodes", &bnode)?;

    // 3. Chunks of slices: prefilter, quantise, integrate.
    let lanes = (ch * rank) as u64;
    let bins64 = bins as u64;
    // Per slice: events, modulation, leaf prefix sums, scales, per-lane sample sums, and per block
    // the prefix sums at its start and its bins with a depth mode [bytes].
    let nblk = u64::from(frame.block[1]);
    let per_slice = [
        bins64 * 16,
        bins64 * 16,
        bins64 * lanes * 4,
        lanes * 4,
        u64::from(max_beta) * lanes * 4,
        nblk * bins64 * lanes * 4,
        nblk * (bins64 + 1) * 4,
    ];
    let largest = per_slice.iter().copied().max().unwrap_or(1).max(1);
    if largest > gpu.max_binding() {
        return Err(GpuError::Limit(format!(
            "epipolar: one slice's scratch needs {largest} bytes; the adapter binds at most {} (use fewer gamma_bins)",
            gpu.max_binding()
        )));
    }
    let total: u64 = per_slice.iter().sum();
    let chunk = ((budget / total).min(gpu.max_binding() / largest) as usize).clamp(1, nslices.max(1));
    let c64 = chunk as u64;
    let events_buf = gpu.buffer_zeroed("epi events", c64 * per_slice[0])?;
    let modul_buf = gpu.buffer_zeroed("epi modulation", c64 * per_slice[1])?;
    let cum_buf = gpu.buffer_zeroed("epi leaf prefix sums", c64 * per_slice[2])?;
    let scales_buf = gpu.buffer_zeroed("epi lane scales", c64 * per_slice[3])?;
    let lsum_buf = gpu.buffer_zeroed("epi lane sums", c64 * per_slice[4])?;
    let base_buf = gpu.buffer_zeroed("epi block prefix sums", c64 * per_slice[5])?;
    let listed_buf = gpu.buffer_zeroed("epi block bins with a depth mode", c64 * per_slice[6])?;
    let values_buf = gpu.buffer_zeroed("epi values", u64::from(samples) * 16)?;
    let prefilter = gpu.kernel(&shaders::EPI_PREFILTER, "main")?;
    let quantise = gpu.kernel(&shaders::EPI_QUANTISE, "main")?;
    let bases = gpu.kernel(&shaders::EPI_INTEGRATE, "bases")?;
    let sums = gpu.kernel(&shaders::EPI_INTEGRATE, "sums")?;
    let combine = gpu.kernel(&shaders::EPI_INTEGRATE, "combine")?;
    let unrectify = gpu.kernel(&shaders::EPI_UNRECTIFY, "main")?;
    let mut uniforms = Vec::new();
    for first in (0..nslices).step_by(chunk) {
        let count = chunk.min(nslices - first);
        uniforms.push((frame.uniform(gpu, "epi chunk params", first as u32, count as u32), count));
    }
    let mut binds = Vec::new();
    for (p, count) in &uniforms {
        let pre = gpu.bind_at(
            &prefilter,
            &[
                (0, p),
                (1, &shadow_buf),
                (2, &tex_buf),
                (3, &slices_buf),
                (4, &offs_buf),
                (5, &cots_buf),
                (6, &nbins_buf),
                (7, &events_buf),
                (8, &modul_buf),
            ],
        );
        let quant = gpu.bind_at(
            &quantise,
            &[(0, p), (7, &nbins_buf), (9, &modul_buf), (10, &gfn_buf), (12, &scales_buf), (13, &cum_buf)],
        );
        let base = gpu.bind_at(
            &bases,
            &[
                (0, p),
                (4, &offs_buf),
                (7, &nbins_buf),
                (8, &events_buf),
                (13, &cum_buf),
                (15, &listed_buf),
                (17, &base_buf),
            ],
        );
        let sum = gpu.bind_at(
            &sums,
            &[
                (0, p),
                (4, &offs_buf),
                (6, &gend_buf),
                (7, &nbins_buf),
                (8, &events_buf),
                (13, &cum_buf),
                (14, &lsum_buf),
                (15, &listed_buf),
                (17, &base_buf),
            ],
        );
        let comb = gpu.bind_at(
            &combine,
            &[
                (0, p),
                (4, &offs_buf),
                (5, &betas_buf),
                (11, &bnode_buf),
                (12, &scales_buf),
                (14, &lsum_buf),
                (16, &values_buf),
            ],
        );
        binds.push((pre, quant, base, sum, comb, *count as u32));
    }

    // 4. Unrectification with the ring march.
    let pixels = (w * h) as u32;
    let inscat_buf = gpu.buffer_zeroed("epi inscatter", u64::from(pixels) * 16)?;
    let trans_buf = gpu.buffer_zeroed("epi transmittance", u64::from(pixels) * 16)?;
    let counts_buf = gpu.buffer_zeroed("epi marched pixels", 8)?;
    let pu = frame.uniform(gpu, "epi unrectify params", 0, 0);
    let ubind = gpu.bind_at(
        &unrectify,
        &[
            (0, &pu),
            (1, &shadow_buf),
            (2, &tex_buf),
            (3, &angles_buf),
            (4, &offs_buf),
            (5, &depth_buf),
            (6, &betas_buf),
            (7, &gend_buf),
            (8, &values_buf),
            (9, &inscat_buf),
            (10, &trans_buf),
            (11, &counts_buf),
        ],
    );
    let mut passes = Vec::new();
    let lanes32 = lanes as u32;
    for (pre, quant, base, sum, comb, count) in &binds {
        passes.push(Pass { phase: "prefilter", kernel: &prefilter, bind: pre, items: count * bins as u32 });
        passes.push(Pass { phase: "integrate: quantise", kernel: &quantise, bind: quant, items: count * lanes32 });
        passes.push(Pass {
            phase: "integrate: block bases",
            kernel: &bases,
            bind: base,
            items: count * frame.block[1] * lanes32,
        });
        passes.push(Pass { phase: "integrate: sums", kernel: &sums, bind: sum, items: count * max_beta * lanes32 });
        passes.push(Pass { phase: "integrate: combine", kernel: &combine, bind: comb, items: count * max_beta });
    }
    passes.push(Pass { phase: "unrectify", kernel: &unrectify, bind: &ubind, items: pixels });
    times.extend(gpu.run(&passes)?);
    let inscatter: Vec<[f32; 4]> = gpu.read(&inscat_buf, pixels as usize)?;
    let transmittance: Vec<[f32; 4]> = gpu.read(&trans_buf, pixels as usize)?;
    let counts: Vec<u32> = gpu.read(&counts_buf, 2)?;

    // A phase and its sub-passes ("integrate: sums").
    let phase_ms = |name: &str| {
        times
            .iter()
            .filter(|t| t.phase.strip_prefix(name).is_some_and(|rest| rest.is_empty() || rest.starts_with(':')))
            .map(|t| t.seconds * 1e3)
            .sum::<f64>()
    };
    stats.rectify_ms = layout_ms + phase_ms("rectify");
    stats.prefilter_ms = phase_ms("prefilter");
    stats.integrate_ms = phase_ms("integrate");
    stats.unrectify_ms = phase_ms("unrectify");
    stats.ring_pixels = counts[0] as usize;
    stats.edge_pixels = counts[1] as usize;
    stats.total_ms = ms(start);
    let rgb =
        |v: Vec<[f32; 4]>| Image { width: w, height: h, data: v.into_iter().map(|c| [c[0], c[1], c[2]]).collect() };
    Ok((EpipolarOutput { inscatter: rgb(inscatter), transmittance: rgb(transmittance), stats }, times))
}

fn ms(t: Instant) -> f64 {
    t.elapsed().as_secs_f64() * 1e3
}

#[cfg(test)]
mod tests;
