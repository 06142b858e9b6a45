//! iser2018 image-space fog on the GPU: the hierarchical filter of the scattered light (MIP chain,
//! level selection, reconstruction) and the final compose as compute passes.
//!
//! **Input → output.** The same inputs as [`image_fog::render`] (colour and distance buffers, camera,
//! analytic [`FogMedium`], [`FogOptions`]) → the same [`FogOutput`] (final, attenuated and filtered
//! scattered images, level and spread per pixel), plus the GPU time of each phase; and
//! [`filter()`], shaped like [`image_fog::filter::filter`] (`L_sc` + spread → `L'_sc` + levels).
//!
//! **Paper.** iser2018 Sec. 4.2 (MIP chain with the 4-tap kernel `{0.13, 0.37, 0.37, 0.13}`, level
//! from the spread), Sec. 4.3 (masking, luminance-weighted spread chain, level re-selection from the
//! blurred spread), Sec. 4.4 (compose `L' = L_at + L'_sc`).
//!
//! **Passes.** In one submission: `fog_integrals.wgsl` (per pixel: the density integrals of every
//! component, `L_at`, `L_sc` and the spread `W`, written straight into level 0 of both chains; the
//! CPU twin is [`image_fog::prepare`], whose stable forms it keeps in f32: Eq. 4 with the
//! exponential at the denser end and `φ(y) = −expm1(−y)/y`, log-space re-forming when a product
//! leaves f32's normal range, `D = ∞`, and ∞ carried as `f32::MAX`), `fog_downsample.wgsl` once per
//! level `k = 1..=K` (masked 4-tap down-sampling of the colour chain and of the `(Y·W, Y, W)` spread
//! chain, both chains in one buffer each), `fog_fetch.wgsl` (per pixel: level selection,
//! re-selection from the spread chain, B-spline reconstruction within a level, linear between
//! levels) and `fog_compose.wgsl`. The host only forms the per-camera constants of each component
//! (`h₀`, `a₀`, `ln ρ'`) in f64.
//! Supported: every [`FogOptions`] except [`Interpolation::Nearest`] and
//! [`FogOptions::separation`], which return [`GpuError::Limit`] naming the option (the caller runs
//! the CPU path and says so).
//!
//! **Precision.** The integrals are f32 on the device and f64 on the CPU (differences measured up
//! to 7.8e-6 relative, growing with the optical depth). Both sides filter in f32 with the same tap order (rows weighted horizontally, then
//! combined vertically); the GPU may contract multiply-adds (FMA) and computes the B-spline weights,
//! level variances and smoothstep masks in f32 where the CPU uses f64 then rounds. Level selection,
//! masks and blends are continuous in their inputs, so these ulp-level differences stay ulp-level in
//! the output (the tests state the measured errors and their tolerances).

use super::shaders;
use crate::render::gpu::context::{Gpu, GpuError, Pass, PassTime, Words};
use crate::render::{DistanceImage, Image, RgbImage, ViewCamera};
use crate::scene::Density;
use crate::stages::image_fog::filter::{self, Filtered};
use crate::stages::image_fog::{
    self, FogMedium, FogOptions, FogOutput, FogStats, Interpolation, LevelRule, SpreadChain,
};

fn vec4s(v: &[[f32; 3]]) -> Vec<[f32; 4]> {
    v.iter().map(|c| [c[0], c[1], c[2], 0.0]).collect()
}

fn rgbs(v: &[[f32; 4]]) -> Vec<[f32; 3]> {
    v.iter().map(|c| [c[0], c[1], c[2]]).collect()
}

/// The options the GPU path does not port, as a [`GpuError::Limit`] naming the option.
pub fn check_options(opts: &FogOptions) -> Result<(), GpuError> {
    if opts.separation.is_some() {
        return Err(GpuError::Limit(
            "image fog: bright-pixel separation (FogOptions::separation) runs on the CPU only".into(),
        ));
    }
    if opts.interpolation == Interpolation::Nearest {
        return Err(GpuError::Limit(
            "image fog: nearest-level reconstruction (Interpolation::Nearest) runs on the CPU only".into(),
        ));
    }
    Ok(())
}

/// One level of the chains read back: colour and `(Y·W, Y, W)` per texel.
type ChainLevel = (Vec<[f32; 3]>, Vec<[f32; 3]>);

/// A filtered frame and, on request, the chain read back per level (`(rgb, spread)` per level).
struct GpuFiltered {
    filtered: Filtered,
    image: Option<RgbImage>,
    /// `L_at` and the spread \[pixels\] from the integrals pass ([`Level0::Frame`]).
    prepared: Option<(RgbImage, Image<f32>)>,
    /// Read only by the per-level test (`read_chain = true`).
    #[cfg_attr(not(test), allow(dead_code))]
    chain: Option<Vec<ChainLevel>>,
    times: Vec<PassTime>,
}

/// Where level 0 of the chains comes from.
enum Level0<'a> {
    /// Host images: `L_sc`, its spread \[pixels\] and, for the compose, `L_at`.
    Host { l: &'a RgbImage, spread: &'a Image<f32>, attenuated: Option<&'a RgbImage> },
    /// `fog_integrals.wgsl` from the frame's colour and distance buffers (`no_spread`: level 0
    /// everywhere, the `scattering = false` ablation).
    Frame {
        cam: &'a ViewCamera,
        colour: &'a RgbImage,
        distance: &'a DistanceImage,
        medium: &'a FogMedium,
        no_spread: bool,
    },
}

/// The fog components as `fog_integrals.wgsl`'s `Component` rows, with the per-camera constants
/// (`h₀`, `a₀ = −b h₀`, `ln ρ'`, channel means) formed in f64 (the CPU twin's branches: a zero
/// falloff is `ρ'·D`, a degenerate axis or `ρ' ≤ 0` gives `P = 0`, an infinite `a₀ > 0` gives ∞).
fn component_rows(medium: &FogMedium, eye: glam::DVec3) -> Vec<[f32; 16]> {
    medium
        .components
        .iter()
        .map(|c| {
            let mean = |v: [f64; 3]| (v[0] + v[1] + v[2]) / 3.0;
            let (kind, axis, expo) = match &c.density {
                Density::Homogeneous => (0.0, [0.0; 3], [0.0, 0.0, 0.0, 1.0]),
                Density::ExponentialHeight { rho, falloff, direction, offset } => {
                    let n = glam::DVec3::from_array(*direction);
                    let len = n.length();
                    if !(len > 0.0 && len.is_finite()) {
                        (2.0, [0.0; 3], [0.0; 4])
                    } else if *falloff == 0.0 {
                        (0.0, [0.0; 3], [0.0, 0.0, 0.0, *rho])
                    } else {
                        let n = n / len;
                        let a0 = -falloff * (eye - glam::DVec3::from_array(*offset)).dot(n);
                        let positive_rho = *rho > 0.0;
                        let kind = if !positive_rho || a0 == f64::NEG_INFINITY || a0.is_nan() {
                            2.0
                        } else if a0 == f64::INFINITY {
                            3.0
                        } else {
                            1.0
                        };
                        (kind, n.to_array(), [a0, *falloff, rho.ln(), *rho])
                    }
                }
            };
            let f = |x: f64| x as f32;
            [
                f(c.sigma_s[0]),
                f(c.sigma_s[1]),
                f(c.sigma_s[2]),
                f(mean(c.sigma_s) * (1.0 - c.g).max(0.0)),
                f(c.sigma_a[0]),
                f(c.sigma_a[1]),
                f(c.sigma_a[2]),
                f(mean(c.sigma_a)),
                f(axis[0]),
                f(axis[1]),
                f(axis[2]),
                kind,
                f(expo[0]),
                f(expo[1]),
                f(expo[2]),
                f(expo[3]),
            ]
        })
        .collect()
}

/// Buffers written by the integrals pass: `L_at` and the unclamped spread per pixel.
struct FrameOut {
    attenuated: wgpu::Buffer,
    width: wgpu::Buffer,
    bind: wgpu::BindGroup,
}

fn run(gpu: &Gpu, src: Level0<'_>, opts: &FogOptions, read_chain: bool) -> Result<GpuFiltered, GpuError> {
    check_options(opts)?;
    let (w, h) = match &src {
        Level0::Host { l, spread, attenuated } => {
            let (w, h) = (l.width, l.height);
            if spread.width != w || spread.height != h || attenuated.is_some_and(|a| a.width != w || a.height != h) {
                return Err(GpuError::Limit(format!(
                    "image fog: buffer sizes differ from the {w}×{h} scattered image"
                )));
            }
            (w, h)
        }
        Level0::Frame { cam, colour, distance, .. } => {
            let (w, h) = (cam.width, cam.height);
            if colour.width != w || colour.height != h || distance.width != w || distance.height != h {
                return Err(GpuError::Limit(format!("image fog: the colour and distance buffers are not {w}×{h}")));
            }
            (w, h)
        }
    };
    let n = w * h;
    let count = u32::try_from(n).map_err(|_| GpuError::Limit(format!("{n} pixels exceed the GPU path's 2³² limit")))?;
    let k_max = filter::level_count(w, h, opts);
    let variances = filter::level_variances(k_max, opts.interpolation);
    let mut dims = vec![(w, h, 0usize)];
    let mut total = n;
    for _ in 1..=k_max {
        let (pw, ph, _) = dims[dims.len() - 1];
        let (nw, nh) = (pw.div_ceil(2).max(1), ph.div_ceil(2).max(1));
        dims.push((nw, nh, total));
        total += nw * nh;
    }
    let luminance_weighted = opts.spread_chain == SpreadChain::LuminanceWeighted;
    let (rgb, sp, host_att, integrals) = match src {
        Level0::Host { l, spread, attenuated } => {
            // Level 0 of both chains on the host (an upload of the inputs): colour, and (Y·W, Y, W).
            let spread = filter::clamp_spread(spread, &variances);
            let mut rgb0 = vec4s(&l.data);
            rgb0.resize(total, [0.0; 4]);
            let mut s0: Vec<[f32; 4]> = l
                .data
                .iter()
                .zip(&spread.data)
                .map(|(c, &s)| {
                    let y = if luminance_weighted { crate::render::color::luminance_f32(*c).max(0.0) } else { 1.0 };
                    [y * s, y, s, 0.0]
                })
                .collect();
            s0.resize(total, [0.0; 4]);
            let rgb = gpu.buffer_from("fog chain rgb", &rgb0)?;
            let sp = gpu.buffer_from("fog chain spread", &s0)?;
            let att = match attenuated {
                Some(a) => Some(gpu.buffer_from("fog attenuated", &vec4s(&a.data))?),
                None => None,
            };
            (rgb, sp, att, None)
        }
        Level0::Frame { cam, colour, distance, medium, no_spread } => {
            let rgb = gpu.buffer_zeroed("fog chain rgb", total as u64 * 16)?;
            let sp = gpu.buffer_zeroed("fog chain spread", total as u64 * 16)?;
            // Inputs sanitised as the CPU's prepare does (NaN → 0, clamped to [0, f32::MAX]); D = ∞ → −1.
            let clean = |c: f32| if c.is_nan() { 0.0 } else { c.clamp(0.0, f32::MAX) };
            let col: Vec<[f32; 4]> = colour.data.iter().map(|c| [clean(c[0]), clean(c[1]), clean(c[2]), 0.0]).collect();
            let dist: Vec<f32> = distance
                .data
                .iter()
                .map(|&d| {
                    if d.is_nan() || d <= 0.0 {
                        0.0
                    } else if d.is_infinite() {
                        -1.0
                    } else {
                        d
                    }
                })
                .collect();
            let mut rows = component_rows(medium, cam.position);
            let ncomp = rows.len() as u32;
            if rows.is_empty() {
                rows.push([0.0; 16]);
            }
            let comps = gpu.buffer_from("fog components", &rows)?;
            let col_buf = gpu.buffer_from("fog colour", &col)?;
            let dist_buf = gpu.buffer_from("fog distance", &dist)?;
            drop((col, dist));
            let attenuated = gpu.buffer_zeroed("fog attenuated", n as u64 * 16)?;
            let width = gpu.buffer_zeroed("fog spread", n as u64 * 4)?;
            let cap = 2.0 * variances.last().copied().unwrap_or(0.0).sqrt();
            let aspect = w as f64 / h.max(1) as f64;
            let v3 = |v: glam::DVec3, x: f64, words: Words| words.f(v.x as f32).f(v.y as f32).f(v.z as f32).f(x as f32);
            let mut words = v3(cam.forward, cam.tan_half_y, Words::default());
            words = v3(cam.right, aspect, words);
            words = v3(cam.up, image_fog::focal_px(cam), words);
            words = words.u(w as u32).u(h as u32).u(count).u(ncomp);
            words =
                words.f(cap as f32).f(f32::from(u8::from(luminance_weighted))).f(f32::from(u8::from(no_spread))).f(0.0);
            let p = gpu.uniform("fog integrals", &words.0);
            let kernel = gpu.kernel(&shaders::FOG_INTEGRALS, "main")?;
            let bind = gpu.bind(&kernel, &[&p, &comps, &col_buf, &dist_buf, &attenuated, &rgb, &sp, &width]);
            (rgb, sp, None, Some((FrameOut { attenuated, width, bind }, kernel)))
        }
    };
    let down_k = gpu.kernel(&shaders::FOG_DOWNSAMPLE, "main")?;
    let fetch_k = gpu.kernel(&shaders::FOG_FETCH, "main")?;
    let compose_k = gpu.kernel(&shaders::FOG_COMPOSE, "main")?;
    let mut down_binds = Vec::new();
    for k in 1..=k_max {
        let (pw, ph, po) = dims[k - 1];
        let (nw, nh, no) = dims[k];
        let hi = variances[k - 1].sqrt();
        let lo = hi / (1.0 + opts.mask_epsilon.max(0.0));
        let masking = opts.masking && hi > 0.0;
        let p = gpu.uniform(
            "fog downsample",
            &Words::default()
                .u(po as u32)
                .u(no as u32)
                .u(pw as u32)
                .u(ph as u32)
                .u(nw as u32)
                .u((nw * nh) as u32)
                .u(masking as u32)
                .u(0)
                .f(lo as f32)
                .f(hi as f32)
                .pad()
                .0,
        );
        down_binds.push(((nw * nh) as u32, gpu.bind(&down_k, &[&p, &rgb, &sp])));
    }
    let level_rows: Vec<[u32; 4]> = dims
        .iter()
        .zip(&variances)
        .map(|(&(lw, lh, off), &v)| [off as u32, lw as u32, lh as u32, (v as f32).to_bits()])
        .collect();
    let levels = gpu.buffer_from("fog levels", &level_rows)?;
    let fetch_p = gpu.uniform(
        "fog fetch",
        &Words::default()
            .u(w as u32)
            .u(h as u32)
            .u(count)
            .u(k_max as u32)
            .u(opts.blur_level as u32)
            .u((opts.level_rule == LevelRule::Paper) as u32)
            .f(opts.c as f32)
            .u(0)
            .0,
    );
    let scattered = gpu.buffer_zeroed("fog scattered", n as u64 * 16)?;
    let level = gpu.buffer_zeroed("fog level", n as u64 * 4)?;
    let fetch_b = gpu.bind(&fetch_k, &[&fetch_p, &levels, &rgb, &sp, &scattered, &level]);
    let mut passes: Vec<Pass> = down_binds
        .iter()
        .map(|(items, b)| Pass { phase: "mip chain", kernel: &down_k, bind: b, items: *items })
        .collect();
    passes.push(Pass { phase: "fetch", kernel: &fetch_k, bind: &fetch_b, items: count });
    let att = host_att.as_ref().or(integrals.as_ref().map(|(f, _)| &f.attenuated));
    let compose = match att {
        Some(att) => {
            let image = gpu.buffer_zeroed("fog image", n as u64 * 16)?;
            let p = gpu.uniform("fog compose", &Words::default().u(count).pad().0);
            let b = gpu.bind(&compose_k, &[&p, att, &scattered, &image]);
            Some((image, b))
        }
        None => None,
    };
    if let Some((_, b)) = &compose {
        passes.push(Pass { phase: "compose", kernel: &compose_k, bind: b, items: count });
    }
    if let Some((f, kernel)) = &integrals {
        passes.insert(0, Pass { phase: "integrals", kernel, bind: &f.bind, items: count });
    }
    let times = gpu.run(&passes)?;
    let image = match &compose {
        Some((buf, _)) => Some(Image { width: w, height: h, data: rgbs(&gpu.read::<[f32; 4]>(buf, n)?) }),
        None => None,
    };
    let prepared = match &integrals {
        Some((f, _)) => Some((
            Image { width: w, height: h, data: rgbs(&gpu.read::<[f32; 4]>(&f.attenuated, n)?) },
            Image { width: w, height: h, data: gpu.read::<f32>(&f.width, n)? },
        )),
        None => None,
    };
    let filtered = Filtered {
        image: Image { width: w, height: h, data: rgbs(&gpu.read::<[f32; 4]>(&scattered, n)?) },
        level: Image { width: w, height: h, data: gpu.read::<f32>(&level, n)? },
    };
    let chain = if read_chain {
        let all_rgb = rgbs(&gpu.read::<[f32; 4]>(&rgb, total)?);
        let all_sp = rgbs(&gpu.read::<[f32; 4]>(&sp, total)?);
        Some(
            dims.iter()
                .map(|&(lw, lh, off)| (all_rgb[off..off + lw * lh].to_vec(), all_sp[off..off + lw * lh].to_vec()))
                .collect(),
        )
    } else {
        None
    };
    Ok(GpuFiltered { filtered, image, prepared, chain, times })
}

/// [`image_fog::filter::filter`] on the GPU: `L_sc` and spreads \[pixels\] → `L'_sc` and levels, with
/// the GPU time of the `mip chain` and `fetch` phases.
///
/// # Errors
/// [`GpuError::Limit`] for an option the GPU path does not port ([`check_options`]), mismatched
/// sizes or an image too large for the adapter; [`GpuError::Runtime`] when a pass fails.
pub fn filter(
    gpu: &Gpu,
    l: &RgbImage,
    spread: &Image<f32>,
    opts: &FogOptions,
) -> Result<(Filtered, Vec<PassTime>), GpuError> {
    let r = run(gpu, Level0::Host { l, spread, attenuated: None }, opts, false)?;
    Ok((r.filtered, r.times))
}

/// [`image_fog::render`] on the GPU: the integrals, the filter and the compose in one submission.
/// `stats` holds the GPU phase times (integrals; MIP chain; fetch + compose).
///
/// # Errors
/// As [`filter()`]; also [`GpuError::Limit`] when the buffers do not have the camera's size.
pub fn render(
    gpu: &Gpu,
    cam: &ViewCamera,
    colour: &RgbImage,
    distance: &DistanceImage,
    medium: &FogMedium,
    opts: &FogOptions,
) -> Result<(FogOutput, Vec<PassTime>), GpuError> {
    check_options(opts)?;
    // Without spreading (the CPU's ablation) L'_sc = L_sc at level 0.
    let o = if opts.scattering { *opts } else { FogOptions { levels: Some(0), ..*opts } };
    let src = Level0::Frame { cam, colour, distance, medium, no_spread: !opts.scattering };
    let r = run(gpu, src, &o, false)?;
    let times = r.times;
    let ms = |phases: &[&str]| {
        1e3 * times.iter().filter(|t| phases.contains(&t.phase.as_str())).map(|t| t.seconds).sum::<f64>()
    };
    let stats =
        FogStats { integrals_ms: ms(&["integrals"]), mip_ms: ms(&["mip chain"]), filter_ms: ms(&["fetch", "compose"]) };
    let missing = |what: &str| GpuError::Runtime { during: "image fog".into(), message: format!("no {what}") };
    let image = r.image.ok_or_else(|| missing("composed image"))?;
    let (attenuated, spread) = r.prepared.ok_or_else(|| missing("integrals"))?;
    Ok((FogOutput { image, attenuated, scattered: r.filtered.image, level: r.filtered.level, spread, stats }, times))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::render::gpu::context::test_gpu;
    use crate::scene::Scene;
    use crate::scene::bvh::SceneBvh;
    use image_fog::FogComponent;

    /// Largest |a − b| / max(|b|, floor) over all channels.
    fn max_rel(a: &[[f32; 3]], b: &[[f32; 3]], floor: f32) -> f64 {
        assert_eq!(a.len(), b.len());
        a.iter()
            .zip(b)
            .flat_map(|(x, y)| (0..3).map(move |c| ((x[c] - y[c]).abs() / y[c].abs().max(floor)) as f64))
            .fold(0.0, f64::max)
    }

    // The integrals in f32 on the device against f64-then-rounded on the CPU: e^{−τ} carries τ's
    // absolute error, which grows with τ and, for height fog, with b·D times the f32 error of the
    // ray's height cosine μ. Worst measured: 7.6e-6 for L_at and 7.8e-6 for the spread (the tilted
    // height axis), 1.8e-7 for the image's relative RMSE (the outdoor frame); tolerances 5e-5, 5e-5
    // and 1e-6. Each test prints its measured values.
    const TOL_ATT: f64 = 5e-5;
    const TOL_SPREAD: f64 = 5e-5;
    const TOL_IMAGE: f64 = 1e-6;

    /// (max relative error of L_at over channels, floor 1e-6 of the peak; max relative error of the
    /// spread, floor 1e-3 px), GPU against CPU.
    fn prepared_errors(gpu: &FogOutput, cpu: &FogOutput) -> (f64, f64) {
        assert!(finite(&gpu.attenuated) && gpu.spread.data.iter().all(|w| w.is_finite() && *w >= 0.0));
        let peak = cpu.attenuated.data.iter().flat_map(|p| p.iter()).fold(0.0f32, |m, &c| m.max(c));
        let e_att = max_rel(&gpu.attenuated.data, &cpu.attenuated.data, 1e-6 * peak.max(1e-30));
        let e_w = gpu
            .spread
            .data
            .iter()
            .zip(&cpu.spread.data)
            .map(|(&g, &c)| if g == c { 0.0 } else { ((g - c).abs() / c.abs().max(1e-3)) as f64 })
            .fold(0.0, f64::max);
        (e_att, e_w)
    }

    fn max_abs(a: &[f32], b: &[f32]) -> f64 {
        a.iter().zip(b).map(|(x, y)| (x - y).abs() as f64).fold(0.0, f64::max)
    }

    fn finite(img: &RgbImage) -> bool {
        img.data.iter().all(|p| p.iter().all(|c| c.is_finite()))
    }

    /// A deterministic image with structure at every scale and a few very bright pixels.
    fn synthetic(w: usize, h: usize) -> (RgbImage, Image<f32>) {
        let mut img = Image::filled(w, h, [0.0f32; 3]);
        let mut spread = Image::filled(w, h, 0.0f32);
        for y in 0..h {
            for x in 0..w {
                let (u, v) = (x as f32 / w as f32, y as f32 / h as f32);
                let a = 1.0 + 0.5 * (17.0 * u).sin() * (11.0 * v).cos();
                let bright = if (x * 7 + y * 13) % 97 == 0 { 300.0 } else { 0.0 };
                img.data[y * w + x] = [a + bright, 0.8 * a + 0.2 * u, 1.2 - 0.3 * v + bright];
                spread.data[y * w + x] =
                    if bright > 0.0 { 0.7 } else { 0.3 + 9.0 * u * v + 3.0 * (5.0 * u).sin().abs() };
            }
        }
        (img, spread)
    }

    /// GPU filter vs CPU filter: (max relative error of L'_sc, max level difference).
    fn compare_filter(img: &RgbImage, spread: &Image<f32>, opts: &FogOptions) -> (f64, f64) {
        let (cpu, _, _) = filter::filter(img, spread, opts);
        let (gpu, times) = super::filter(test_gpu(), img, spread, opts).unwrap();
        assert!(times.iter().any(|t| t.phase == "fetch"));
        assert!(finite(&gpu.image));
        let peak = cpu.image.data.iter().flat_map(|p| p.iter()).fold(0.0f32, |m, &c| m.max(c.abs()));
        (max_rel(&gpu.image.data, &cpu.image.data, 1e-3 * peak.max(1e-30)), max_abs(&gpu.level.data, &cpu.level.data))
    }

    #[test]
    fn outdoor_frame_matches_the_cpu_per_output_and_per_level() {
        // The stage's frame (pipelines/default.ron: outdoor_fog, camera 0, colour_samples 8), at
        // 480×270 instead of 1280×720 to keep the debug-build path tracing of the colour buffer short.
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes/outdoor.gltf");
        let scene = Scene::load(&path).unwrap();
        let bvh = SceneBvh::build(&scene);
        let cam = crate::render::ViewCamera::from_scene(&scene.cameras[0], 480, 270).unwrap();
        let g = crate::render::gbuffer::render(
            &scene,
            &bvh,
            &cam,
            &crate::render::gbuffer::ColourOptions { samples: 8, bounces: 0, seed: 0 },
        );
        let medium = FogMedium::from_scene(&scene).unwrap();
        let opts = FogOptions::default();
        let cpu = image_fog::render(&cam, &g.colour, &g.distance, &medium, &opts);
        let (gpu, times) = render(test_gpu(), &cam, &g.colour, &g.distance, &medium, &opts).unwrap();
        for t in &times {
            println!("outdoor 480×270 {}: {:.3} ms over {} passes", t.phase, t.seconds * 1e3, t.passes);
        }
        let rel = |a: &RgbImage, b: &RgbImage| crate::render::rel_rmse(a, b);
        let (e_img, e_sc, e_lvl) = (
            rel(&gpu.image, &cpu.image),
            rel(&gpu.scattered, &cpu.scattered),
            max_abs(&gpu.level.data, &cpu.level.data),
        );
        println!("outdoor: rel RMSE image {e_img:.3e}, scattered {e_sc:.3e}; max level diff {e_lvl:.3e}");
        let (e_att, e_w) = prepared_errors(&gpu, &cpu);
        println!("outdoor integrals: max rel L_at {e_att:.3e}, spread {e_w:.3e}");
        assert!(e_att < TOL_ATT && e_w < TOL_SPREAD, "{e_att} {e_w}");
        // f32 on both sides, same tap order; FMA contraction and f32 (vs f64-then-rounded) B-spline
        // weights, variances and masks give ulp-level differences (measured 7.8e-8 scattered, 1.1e-8 image,
        // levels 4.8e-7): tolerances 5e-7 and 2e-6.
        assert!(e_sc < 5e-7 && e_img < 5e-7, "{e_sc} {e_img}");
        assert!(e_lvl < 2e-6, "{e_lvl}");
        assert!(finite(&gpu.image) && gpu.scattered.data.iter().any(|p| p[0] > 0.0));
        // Per level of the MIP chain, against the CPU's build_chain of the same L_sc.
        let k = filter::level_count(480, 270, &opts);
        let v = filter::level_variances(k, opts.interpolation);
        let p = image_fog::prepare(&cam, &g.colour, &g.distance, &medium);
        let cpu_chain = filter::build_chain(&p.scattered, &filter::clamp_spread(&p.spread, &v), &opts);
        let src = Level0::Host { l: &p.scattered, spread: &p.spread, attenuated: None };
        let r = run(test_gpu(), src, &opts, true).unwrap();
        let chain = r.chain.unwrap();
        assert_eq!(chain.len(), k + 1);
        for (lv, (rgb, sp)) in cpu_chain.levels.iter().zip(&chain) {
            let wh = (lv.width, lv.height);
            let er = rel(
                &Image { width: wh.0, height: wh.1, data: rgb.clone() },
                &Image { width: wh.0, height: wh.1, data: lv.rgb.clone() },
            );
            let es = rel(
                &Image { width: wh.0, height: wh.1, data: sp.clone() },
                &Image { width: wh.0, height: wh.1, data: lv.spread.clone() },
            );
            println!("level {}×{}: rel RMSE colour {er:.3e}, spread chain {es:.3e}", wh.0, wh.1);
            // Each level adds one 16-tap f32 sum (FMA vs separate rounding) and an f32 mask; the error grows
            // with the level (measured 0 up to 4×3, 3.3e-8 at 2×2, 2.0e-6 at 1×1): ≤ 1e-5.
            assert!(er < 1e-5 && es < 1e-5, "level {wh:?}: {er} {es}");
        }
    }

    #[test]
    fn odd_sizes_and_option_variants_match_the_cpu() {
        let mut worst = (0.0f64, 0.0f64);
        for (w, h) in [(1, 1), (3, 5), (333, 77), (2, 1), (1, 40)] {
            let (img, spread) = synthetic(w, h);
            for opts in [
                FogOptions::default(),
                FogOptions { masking: false, blur_level: false, ..FogOptions::default() },
                FogOptions {
                    level_rule: LevelRule::Paper,
                    spread_chain: SpreadChain::Gaussian,
                    ..FogOptions::default()
                },
                FogOptions { levels: Some(2), mask_epsilon: 0.0, ..FogOptions::default() },
            ] {
                let (e, l) = compare_filter(&img, &spread, &opts);
                println!(
                    "{w}×{h} {:?}/{:?} masking {}: max rel {e:.3e}, level {l:.3e}",
                    opts.level_rule, opts.spread_chain, opts.masking
                );
                worst = (worst.0.max(e), worst.1.max(l));
            }
        }
        println!("odd sizes: worst max relative error {:.3e}, worst level difference {:.3e}", worst.0, worst.1);
        // Per pixel (relative to max(|cpu|, 1e-3 · peak)): f32 ulp differences amplified by the
        // bright pixels' cancellation in blends; measured 1.6e-6 (levels 4.8e-7): tolerances 1e-5, 2e-6.
        assert!(worst.0 < 1e-5 && worst.1 < 2e-6, "{worst:?}");
    }

    #[test]
    fn constant_stays_constant_and_zero_stays_zero() {
        let (w, h) = (50, 31);
        let img = Image::filled(w, h, [2.0f32, 1.0, 0.5]);
        let ramp = Image {
            width: w,
            height: h,
            data: (0..w * h).map(|i| 0.4 * (i % w) as f32 + 0.1 * (i / w) as f32).collect(),
        };
        let (f, _) =
            super::filter(test_gpu(), &img, &ramp, &FogOptions { masking: false, ..FogOptions::default() }).unwrap();
        for p in &f.image.data {
            for c in 0..3 {
                // Taps sum to 1 in f32 (≈ 1 ± 6e-8 per level): ≤ 2e-6 relative, as on the CPU.
                assert!((p[c] - img.data[0][c]).abs() < 2e-6 * img.data[0][c], "{p:?}");
            }
        }
        let zero = Image::filled(37, 23, [0.0f32; 3]);
        let (f, _) = super::filter(test_gpu(), &zero, &Image::filled(37, 23, 4.0f32), &FogOptions::default()).unwrap();
        assert!(f.image.data.iter().all(|p| *p == [0.0; 3]));
        // Zero spread: level 0 is the input, bit for bit.
        let (img2, _) = synthetic(37, 23);
        let (f, _) = super::filter(test_gpu(), &img2, &Image::filled(37, 23, 0.0f32), &FogOptions::default()).unwrap();
        assert_eq!(f.image, img2);
        assert!(f.level.data.iter().all(|&l| l == 0.0));
    }

    #[test]
    fn a_frame_beyond_one_dispatch_dimension_matches_the_cpu() {
        // 2600×1700 = 4.42 M pixels > 65535·64 = 4.19 M: the fetch and compose passes fold their
        // dispatch into 2-D (wid.y > 0), and level 1 (1300×850) needs only one row.
        let (w, h) = (2600, 1700);
        assert!(w * h > 65535 * 64);
        let (img, spread) = synthetic(w, h);
        let (e, l) = compare_filter(&img, &spread, &FogOptions::default());
        println!("2600×1700: max rel {e:.3e}, level {l:.3e}");
        // Measured 1.1e-6 (levels 7.2e-7), same f32 ulp argument as the odd sizes.
        assert!(e < 1e-5 && l < 2e-6, "{e} {l}");
    }

    #[test]
    fn extreme_inputs_stay_finite_and_match_the_cpu() {
        // The CPU suite's spreads beyond the last level (1e30, ∞, NaN), with levels = 3.
        let (w, h) = (40, 30);
        let (img, _) = synthetic(w, h);
        let mut spread = Image::filled(w, h, 1e30f32);
        spread.data[7] = f32::INFINITY;
        spread.data[8] = f32::NAN;
        let opts = FogOptions { levels: Some(3), ..FogOptions::default() };
        let (e, l) = compare_filter(&img, &spread, &opts);
        // Every pixel reads level 3 (pixel 8: level 0) on both sides; colours agree to f32 ulps.
        assert!(e < 1e-5 && l == 0.0, "{e} {l}");
        // Camera inside dense fog (σ_s = 40, with and without absorption), sky and D = 0 pixels,
        // grazing rays of an exponential fog, and σ = 0: render GPU vs CPU, finite.
        let cam = ViewCamera::new([0.0, 1.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0], 0.9, 48, 32).unwrap();
        let (img, _) = synthetic(48, 32);
        let mut dist = Image { width: 48, height: 32, data: (0..48 * 32).map(|i| 1.0 + (i % 13) as f32).collect() };
        dist.data[3] = f32::INFINITY;
        dist.data[4] = 0.0;
        dist.data[5] = f32::NAN;
        let homog =
            |s: f64, a: f64| FogComponent { sigma_s: [s; 3], sigma_a: [a; 3], g: 0.7, density: Density::Homogeneous };
        let grazing = FogComponent {
            sigma_s: [0.02, 0.022, 0.025],
            sigma_a: [0.001; 3],
            g: 0.5,
            density: Density::ExponentialHeight {
                rho: 0.8,
                falloff: 0.05,
                direction: [0.0, 1.0, 0.0],
                offset: [0.0, 1.0, 0.0],
            },
        };
        for m in [vec![homog(40.0, 0.0)], vec![homog(40.0, 5.0)], vec![homog(0.0, 0.0)], vec![grazing]] {
            let medium = FogMedium { components: m };
            let cpu = image_fog::render(&cam, &img, &dist, &medium, &FogOptions::default());
            let (gpu, _) = render(test_gpu(), &cam, &img, &dist, &medium, &FogOptions::default()).unwrap();
            assert!(finite(&gpu.image) && finite(&gpu.scattered));
            let e = crate::render::rel_rmse(&gpu.image, &cpu.image);
            let (e_att, e_w) = prepared_errors(&gpu, &cpu);
            println!("extreme medium: rel RMSE {e:.3e}, max rel L_at {e_att:.3e}, spread {e_w:.3e}");
            assert!(e < TOL_IMAGE && e_att < TOL_ATT && e_w < TOL_SPREAD, "{e} {e_att} {e_w}");
        }
        // No scattering: L' = L_at + L_sc at level 0.
        let medium = FogMedium { components: vec![homog(1.0, 0.1)] };
        let o = FogOptions { scattering: false, ..FogOptions::default() };
        let cpu = image_fog::render(&cam, &img, &dist, &medium, &o);
        let (gpu, _) = render(test_gpu(), &cam, &img, &dist, &medium, &o).unwrap();
        let e = crate::render::rel_rmse(&gpu.image, &cpu.image);
        println!("no scattering: rel RMSE {e:.3e}");
        assert!(e < TOL_IMAGE && gpu.level.data.iter().all(|&l| l == 0.0), "{e}");
    }

    /// The integrals pass on the CPU suite's stiff media: a density integral beyond f32 (e^300, the
    /// log-space branch and a saturated P), a falloff of 1e-12 (the homogeneous limit), a zero
    /// falloff (P = ρ'D), ρ' = 0 and a degenerate height axis (P = 0), a camera 10⁶ m from the
    /// origin (h₀ formed on the host), and the last five summed; distances from 0 to 10⁴ m, ∞ and NaN,
    /// with rays across the horizon (μ → 0).
    #[test]
    fn stiff_fog_integrals_stay_finite_and_match_the_cpu() {
        let (w, h) = (48, 32);
        let (img, _) = synthetic(w, h);
        let mut dist = Image { width: w, height: h, data: (0..w * h).map(|i| 10f32.powi((i % 5) as i32)).collect() };
        dist.data[1] = f32::INFINITY;
        dist.data[2] = 0.0;
        dist.data[3] = f32::NAN;
        for i in (7..w * h).step_by(11) {
            dist.data[i] = f32::INFINITY;
        }
        let height = |rho: f64, falloff: f64, direction: [f64; 3], offset: [f64; 3]| FogComponent {
            sigma_s: [0.02, 0.022, 0.025],
            sigma_a: [0.001; 3],
            g: 0.5,
            density: Density::ExponentialHeight { rho, falloff, direction, offset },
        };
        let up = [0.0, 1.0, 0.0];
        let stiff = [
            ("e^300 at the eye", height(1.0, 1.0, up, [0.0, 301.7, 0.0])),
            ("falloff 1e-12", height(0.8, 1e-12, up, [0.0; 3])),
            ("zero falloff", height(0.5, 0.0, up, [0.0; 3])),
            ("rho 0", height(0.0, 0.05, up, [0.0; 3])),
            ("degenerate axis", height(0.8, 0.05, [0.0; 3], [0.0; 3])),
            ("tilted axis", height(0.8, 0.05, [0.3, 1.0, 0.2], [5.0, -2.0, 1.0])),
        ];
        // Summed without the first, which alone blacks out every pixel.
        let all: Vec<FogComponent> = stiff.iter().skip(1).map(|(_, c)| c.clone()).collect();
        let cases = stiff.iter().map(|(n, c)| (*n, vec![c.clone()])).chain([("all summed", all)]);
        for (name, components) in cases {
            for eye in [[0.0, 1.7, 0.0], [1e6, 1.7, -1e6]] {
                let cam = ViewCamera::new(eye, [0.0, 0.05, -1.0], up, 0.9, w, h).unwrap();
                let medium = FogMedium { components: components.clone() };
                let cpu = image_fog::render(&cam, &img, &dist, &medium, &FogOptions::default());
                let (gpu, _) = render(test_gpu(), &cam, &img, &dist, &medium, &FogOptions::default()).unwrap();
                assert!(finite(&gpu.image) && finite(&gpu.scattered), "{name}");
                let e = crate::render::rel_rmse(&gpu.image, &cpu.image);
                let (e_att, e_w) = prepared_errors(&gpu, &cpu);
                println!("{name}, eye {eye:?}: rel RMSE {e:.3e}, max rel L_at {e_att:.3e}, spread {e_w:.3e}");
                assert!(e < TOL_IMAGE && e_att < TOL_ATT && e_w < TOL_SPREAD, "{name}: {e} {e_att} {e_w}");
            }
        }
    }

    #[test]
    fn an_all_sky_frame_matches_the_cpu() {
        // Every pixel D = ∞ in the outdoor scene's height fog (finite P upward, +∞ at and below the
        // horizon): the camera looks across the horizon, so both kinds of sky pixel occur.
        let cam = ViewCamera::new([0.0, 1.7, 0.0], [0.0, 0.1, -1.0], [0.0, 1.0, 0.0], 0.8, 64, 40).unwrap();
        let (img, _) = synthetic(64, 40);
        let dist = Image::filled(64, 40, f32::INFINITY);
        let medium = FogMedium {
            components: vec![FogComponent {
                sigma_s: [0.02, 0.022, 0.025],
                sigma_a: [0.001; 3],
                g: 0.5,
                density: Density::ExponentialHeight {
                    rho: 0.8,
                    falloff: 0.05,
                    direction: [0.0, 1.0, 0.0],
                    offset: [0.0; 3],
                },
            }],
        };
        let cpu = image_fog::render(&cam, &img, &dist, &medium, &FogOptions::default());
        let (gpu, _) = render(test_gpu(), &cam, &img, &dist, &medium, &FogOptions::default()).unwrap();
        assert!(finite(&gpu.image) && finite(&gpu.scattered));
        assert!(cpu.attenuated.data.iter().any(|p| p[0] == 0.0) && cpu.attenuated.data.iter().any(|p| p[0] > 0.0));
        let e = crate::render::rel_rmse(&gpu.image, &cpu.image);
        let (e_att, e_w) = prepared_errors(&gpu, &cpu);
        println!("all sky: rel RMSE {e:.3e}, max rel L_at {e_att:.3e}, spread {e_w:.3e}");
        assert!(e < TOL_IMAGE && e_att < TOL_ATT && e_w < TOL_SPREAD, "{e} {e_att} {e_w}");
    }

    #[test]
    fn options_not_ported_are_limit_errors_naming_them() {
        let (img, spread) = synthetic(8, 8);
        let sep = FogOptions { separation: Some(Default::default()), ..FogOptions::default() };
        let near = FogOptions { interpolation: Interpolation::Nearest, ..FogOptions::default() };
        for (o, name) in [(sep, "separation"), (near, "Nearest")] {
            match super::filter(test_gpu(), &img, &spread, &o) {
                Err(GpuError::Limit(m)) => assert!(m.contains(name), "{m}"),
                other => panic!("{name}: {other:?}"),
            }
        }
    }
}
