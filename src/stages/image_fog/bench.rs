//! Benchmark of the hierarchical filter against the gathering reference (iser2018 Sec. 5, Table 1).
//!
//! **Input → output.** A fog scene (default `scenes/outdoor.gltf`) → a [`BenchReport`]: frame time
//! (median of several runs) and per-phase times at 1280×720 and 1920×1080 with the caller's rayon
//! pool, the gathering reference's time (per-pixel time on a stratified pixel subset, extrapolated to
//! the full frame) and the speed-up at the larger size, and the error of the hierarchical filter
//! against the gather at several option settings (error against time).
//!
//! The distance buffer is ray traced from the scene's first camera; the colour image is, for now, a
//! deterministic synthetic HDR image ([`synthetic_colour`]); [`bench_frames`] takes any colour image.
//!
//! Error metric: relative RMSE of the scattered image `L'_sc` over the sampled pixels and the three
//! channels, `sqrt(Σ (h − g)² / Σ g²)`, hierarchical `h` against gather `g`.

use std::fmt;
use std::path::Path;
use std::time::Instant;

use super::{
    DistanceImage, FogMedium, FogOptions, FogStats, Interpolation, LevelRule, RgbImage, ViewCamera, gather, prepare,
    render, spread_cap,
};
use crate::render::Image;

/// Timing of the hierarchical filter at one resolution.
#[derive(Debug, Clone)]
pub struct FrameRow {
    /// Image size.
    pub width: usize,
    /// Image size.
    pub height: usize,
    /// Number of timed runs.
    pub runs: usize,
    /// Median total frame time \[ms\].
    pub median_ms: f64,
    /// Median of each phase \[ms\] over the same runs.
    pub phases: FogStats,
}

/// The gathering reference at the largest resolution.
#[derive(Debug, Clone)]
pub struct GatherRow {
    /// Image size.
    pub width: usize,
    /// Image size.
    pub height: usize,
    /// Pixels gathered (a stratified grid).
    pub pixels: usize,
    /// Wall time for those pixels \[s\].
    pub seconds: f64,
    /// Whether the whole frame was gathered (otherwise the full time is extrapolated per pixel).
    pub full: bool,
    /// Full-frame time \[s\] (measured or extrapolated).
    pub frame_seconds: f64,
    /// `frame_seconds` / the hierarchical median frame time at the same size.
    pub speedup: f64,
}

/// Error against time for one option setting.
#[derive(Debug, Clone)]
pub struct ErrorRow {
    /// What was changed from the defaults.
    pub label: String,
    /// Median frame time \[ms\] at the gather's size.
    pub frame_ms: f64,
    /// Relative RMSE of `L'_sc` against the gather (module doc).
    pub rel_rmse: f64,
}

/// The benchmark's results.
#[derive(Debug, Clone)]
pub struct BenchReport {
    /// Per resolution.
    pub frames: Vec<FrameRow>,
    /// The reference.
    pub gather: GatherRow,
    /// Error against time.
    pub errors: Vec<ErrorRow>,
    /// Threads in the rayon pool.
    pub threads: usize,
}

impl fmt::Display for BenchReport {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        writeln!(f, "iser2018 image-space fog ({} threads)", self.threads)?;
        writeln!(
            f,
            "{:>11} {:>5} {:>10} {:>12} {:>9} {:>14}",
            "size", "runs", "frame ms", "integrals ms", "MIP ms", "filter+comp ms"
        )?;
        for r in &self.frames {
            writeln!(
                f,
                "{:>11} {:>5} {:>10.2} {:>12.2} {:>9.2} {:>14.2}",
                format!("{}x{}", r.width, r.height),
                r.runs,
                r.median_ms,
                r.phases.integrals_ms,
                r.phases.mip_ms,
                r.phases.filter_ms
            )?;
        }
        let g = &self.gather;
        writeln!(
            f,
            "gather reference at {}x{}: {} pixels in {:.2} s -> full frame {:.1} s ({}); speed-up of the hierarchical filter {:.0}x",
            g.width,
            g.height,
            g.pixels,
            g.seconds,
            g.frame_seconds,
            if g.full { "measured" } else { "extrapolated per pixel from a stratified subset" },
            g.speedup
        )?;
        writeln!(f, "error of L'_sc vs gather (relative RMSE over the gathered pixels, RGB):")?;
        for e in &self.errors {
            writeln!(f, "  {:<44} {:>9.2} ms  rel. RMSE {:.4}", e.label, e.frame_ms, e.rel_rmse)?;
        }
        Ok(())
    }
}

/// A deterministic HDR colour image for a distance buffer: a sky gradient where `D = ∞`, a shaded
/// checker on surfaces, and a few bright lamp discs (radiance 200) at fixed image fractions.
pub fn synthetic_colour(distance: &DistanceImage) -> RgbImage {
    let (w, h) = (distance.width, distance.height);
    let lamps = [(0.22, 0.55), (0.4, 0.62), (0.61, 0.5), (0.78, 0.66), (0.5, 0.3)];
    let radius = (h as f64 / 150.0).max(1.0);
    let mut img = Image::filled(w, h, [0.0f32; 3]);
    for y in 0..h {
        for x in 0..w {
            let d = distance.data[y * w + x] as f64;
            let v = y as f64 / h as f64;
            let mut c = if d.is_finite() {
                let check = ((x * 16 / w) + (y * 9 / h)) % 2;
                let a = if check == 0 { 0.25 } else { 0.6 };
                let s = 1.0 / (1.0 + d / 150.0);
                [a * s, a * 0.9 * s, a * 0.75 * s]
            } else {
                [0.5 + 0.5 * v, 0.65 + 0.4 * v, 1.0 + 0.2 * v]
            };
            for &(lx, ly) in &lamps {
                let dx = x as f64 + 0.5 - lx * w as f64;
                let dy = y as f64 + 0.5 - ly * h as f64;
                if dx * dx + dy * dy <= radius * radius {
                    c = [200.0, 120.0, 60.0];
                }
            }
            img.data[y * w + x] = c.map(|v| v as f32);
        }
    }
    img
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    let n = v.len();
    if n % 2 == 1 { v[n / 2] } else { 0.5 * (v[n / 2 - 1] + v[n / 2]) }
}

/// What [`bench_frames`] measures.
#[derive(Debug, Clone)]
pub struct BenchConfig {
    /// Timed runs per setting (median reported).
    pub runs: usize,
    /// Pixels gathered per axis (a stratified grid); `None`: the whole frame.
    pub gather_grid: Option<(usize, usize)>,
}

/// Median frame time and phases of `render` with `opts`.
fn time_render(
    cam: &ViewCamera,
    colour: &RgbImage,
    distance: &DistanceImage,
    medium: &FogMedium,
    opts: &FogOptions,
    runs: usize,
) -> (FrameRow, RgbImage) {
    let mut totals = Vec::new();
    let mut phases = [Vec::new(), Vec::new(), Vec::new()];
    let mut last = None;
    for _ in 0..runs.max(1) {
        let t = Instant::now();
        let out = render(cam, colour, distance, medium, opts);
        totals.push(t.elapsed().as_secs_f64() * 1e3);
        phases[0].push(out.stats.integrals_ms);
        phases[1].push(out.stats.mip_ms);
        phases[2].push(out.stats.filter_ms);
        last = Some(out.scattered);
    }
    let [a, b, c] = phases;
    let row = FrameRow {
        width: cam.width,
        height: cam.height,
        runs: totals.len(),
        median_ms: median(totals),
        phases: FogStats { integrals_ms: median(a), mip_ms: median(b), filter_ms: median(c) },
    };
    (row, last.unwrap_or_else(|| Image::filled(cam.width, cam.height, [0.0; 3])))
}

/// Inputs of one resolution.
pub struct Frame<'a> {
    /// Camera with the frame's raster.
    pub cam: ViewCamera,
    /// HDR colour.
    pub colour: &'a RgbImage,
    /// Distances.
    pub distance: &'a DistanceImage,
}

/// Times the frames, gathers at the last (largest) frame and compares option settings there.
pub fn bench_frames(frames: &[Frame<'_>], medium: &FogMedium, cfg: &BenchConfig) -> Result<BenchReport, String> {
    let last = frames.last().ok_or("no frames")?;
    let defaults = FogOptions::default();
    let mut rows = Vec::new();
    for fr in frames {
        rows.push(time_render(&fr.cam, fr.colour, fr.distance, medium, &defaults, cfg.runs).0);
    }
    let (w, h) = (last.cam.width, last.cam.height);
    let pixels: Vec<(usize, usize)> = match cfg.gather_grid {
        None => (0..h).flat_map(|y| (0..w).map(move |x| (x, y))).collect(),
        Some((nx, ny)) => gather::grid_pixels(w, h, nx, ny),
    };
    let t = Instant::now();
    let p = prepare(&last.cam, last.colour, last.distance, medium);
    let reference = gather::gather_pixels(&p.scattered, &p.spread, spread_cap(w, h, &defaults), &pixels);
    let seconds = t.elapsed().as_secs_f64();
    let full = pixels.len() == w * h;
    let frame_seconds = if full { seconds } else { seconds / pixels.len() as f64 * (w * h) as f64 };
    let base_ms = rows.last().map_or(f64::NAN, |r| r.median_ms);
    let gather_row = GatherRow {
        width: w,
        height: h,
        pixels: pixels.len(),
        seconds,
        full,
        frame_seconds,
        speedup: frame_seconds * 1e3 / base_ms,
    };
    let settings: Vec<(&str, FogOptions)> = vec![
        ("defaults (variance-matched, B-spline, masking)", defaults),
        ("no masking, no level blur (naive MIP)", FogOptions { masking: false, blur_level: false, ..defaults }),
        ("paper level rule k = log2(W/c)", FogOptions { level_rule: LevelRule::Paper, ..defaults }),
        ("nearest level + texel", FogOptions { interpolation: Interpolation::Nearest, ..defaults }),
        ("Gaussian spread chain (density blur)", FogOptions { spread_chain: super::SpreadChain::Gaussian, ..defaults }),
        (
            "bright-pixel separation (default thresholds)",
            FogOptions { separation: Some(Default::default()), ..defaults },
        ),
    ];
    let mut errors = Vec::new();
    for (label, o) in settings {
        let (row, sc) = time_render(&last.cam, last.colour, last.distance, medium, &o, cfg.runs);
        let (mut num, mut den) = (0.0f64, 0.0f64);
        for (&(x, y), g) in pixels.iter().zip(&reference) {
            let v = sc.data[y * w + x];
            for c in 0..3 {
                num += (v[c] as f64 - g[c] as f64).powi(2);
                den += (g[c] as f64).powi(2);
            }
        }
        errors.push(ErrorRow {
            label: label.to_string(),
            frame_ms: row.median_ms,
            rel_rmse: (num / den.max(f64::MIN_POSITIVE)).sqrt(),
        });
    }
    Ok(BenchReport { frames: rows, gather: gather_row, errors, threads: rayon::current_num_threads() })
}

/// Runs the benchmark on `scene_path` (its first camera and global fog) at 1280×720 and 1920×1080
/// (`quick`: 160×90 and 240×135, fewer runs, for tests) with the caller's rayon pool.
pub fn bench(scene_path: &Path, quick: bool) -> Result<BenchReport, String> {
    let scene = crate::scene::Scene::load(scene_path).map_err(|e| e.to_string())?;
    let medium = FogMedium::from_scene(&scene).ok_or_else(|| format!("{}: no global medium", scene_path.display()))?;
    let camera = scene.cameras.first().ok_or_else(|| format!("{}: no camera", scene_path.display()))?;
    let bvh = crate::scene::bvh::SceneBvh::build(&scene);
    let sizes: &[(usize, usize)] = if quick { &[(160, 90), (240, 135)] } else { &[(1280, 720), (1920, 1080)] };
    let mut inputs = Vec::new();
    for &(w, h) in sizes {
        let cam = ViewCamera::from_scene(camera, w, h).ok_or("the scene camera is not a valid perspective camera")?;
        let distance = crate::render::gbuffer::distance_image(&bvh, &cam);
        let colour = synthetic_colour(&distance);
        inputs.push((cam, colour, distance));
    }
    let frames: Vec<Frame<'_>> =
        inputs.iter().map(|(cam, colour, distance)| Frame { cam: *cam, colour, distance }).collect();
    let cfg = if quick {
        BenchConfig { runs: 2, gather_grid: Some((6, 4)) }
    } else {
        BenchConfig { runs: 7, gather_grid: Some((8, 6)) }
    };
    bench_frames(&frames, &medium, &cfg)
}
