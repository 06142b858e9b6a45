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
                f(c.coefficients.sigma_s[0]),
                f(c.coefficients.sigma_s[1]),
                f(c.coefficients.sigma_s[2]),
                f(mean(c.coefficients.sigma_s) * (1.0 - c.coefficients.mean_g()).max(0.0)),
                f(c.coefficients.sigma_a[0]),
                f(c.coefficients.sigma_a[1]),
                f(c.coefficients.sigma_a[2]),
                f(mean(c.coefficients.sigma_a)),
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
mod tests;
