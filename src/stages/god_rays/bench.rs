//! Error against run time and scaling of the epipolar method and the shadow-map ray marcher
//! (baran2010 Sec. 10: equal-quality speed-up, Fig. 12's log-log scaling).
//!
//! **Input → output.** A scene file (with a camera, a directional or spot light and a homogeneous
//! global medium) → a [`BenchReport`]: per thread count (1, 2) the (knob, ms, error) points of both
//! methods against a converged reference, the speed-up at equal error (log-log interpolation of the
//! marcher's curve), the per-phase milliseconds of the default setting, and the time-vs-resolution
//! slopes (least squares in log-log) for both methods, and the split of a whole frame (shadow map,
//! epipolar, composite) at 640×480 and 1280×720 on 2 threads.
//!
//! **Error metric.** Relative RMSE of the in-scattered image against the converged reference over all
//! pixels and channels: `sqrt(Σ (x − r)²) / sqrt(Σ r²)`. The reference is the BVH ray marcher (real
//! shadow rays, no shadow-map aliasing) with many steps, so both methods carry the shadow map's
//! discretisation error as a floor. Times exclude the depth map, shadow map and BVH (the paper's
//! methodology: only the scattering computation is timed).

use std::fmt;
use std::path::Path;
use std::time::Instant;

use super::{
    DistanceImage, EpiLight, EpiMedium, EpipolarOptions, EpipolarStats, RgbImage, ShadowMap, ViewCamera, march_bvh,
    march_shadow_map, render, render_shadow_map,
};
use crate::render::gbuffer::distance_image;
use crate::report::plot::{Plot, Scale, Series, write_png};
use crate::scene::Scene;
use crate::scene::bvh::SceneBvh;

/// One measured point.
#[derive(Debug, Clone, PartialEq)]
pub struct ErrorTimePoint {
    /// `"epipolar"` or `"raymarch"`.
    pub method: String,
    /// The knob setting, human readable.
    pub knob: String,
    /// Wall time \[ms\].
    pub ms: f64,
    /// Relative RMSE against the reference.
    pub error: f64,
}

/// Speed-up of the epipolar method at one of its settings.
#[derive(Debug, Clone, PartialEq)]
pub struct SpeedUp {
    /// The epipolar setting.
    pub knob: String,
    /// Its error.
    pub error: f64,
    /// Its time \[ms\].
    pub epi_ms: f64,
    /// The ray marcher's time at the same error (log-log interpolation) \[ms\].
    pub march_ms: f64,
    /// `march_ms / epi_ms`.
    pub speedup: f64,
    /// The error is below the marcher's best: its time is extrapolated along the power law through
    /// its two most accurate points.
    pub extrapolated: bool,
}

/// Measurements at one thread count.
#[derive(Debug, Clone, PartialEq)]
pub struct ThreadRun {
    /// Rayon threads.
    pub threads: usize,
    /// Points of both methods.
    pub points: Vec<ErrorTimePoint>,
    /// Speed-ups at equal error (epipolar settings whose error the marcher's curve brackets).
    pub speedups: Vec<SpeedUp>,
    /// Phases of the default epipolar setting.
    pub default_stats: EpipolarStats,
}

/// Time against resolution for one method.
#[derive(Debug, Clone, PartialEq)]
pub struct Scaling {
    /// Method name.
    pub method: String,
    /// `(scale factor k, ms)`: screen side, `γ` bins and marcher steps all ∝ `k`.
    pub points: Vec<(f64, f64)>,
    /// Least-squares slope of `log ms` against `log k` (paper: 1.94 tree, 2.83 ray marching).
    pub slope: f64,
}

/// Everything [`bench()`] measured.
#[derive(Debug, Clone, PartialEq)]
pub struct BenchReport {
    /// Raster size of the error-vs-time runs.
    pub width: usize,
    /// Raster height.
    pub height: usize,
    /// Shadow-map resolution.
    pub shadow_resolution: usize,
    /// Steps of the converged BVH reference.
    pub reference_steps: usize,
    /// Per thread count.
    pub runs: Vec<ThreadRun>,
    /// Scaling (single thread).
    pub scaling: Vec<Scaling>,
    /// Whole frames (2 threads): what a real-time frame costs at game resolutions.
    pub frames: Vec<FrameSplit>,
}

/// The cost of one whole god-ray frame on 2 threads (best of 3): the shadow map (rasterised, at the
/// bench's resolution), the epipolar in-scatter (default settings) and the composite over a colour
/// image; the camera's distance buffer is the engine's G-buffer input, timed beside it, not in the total.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FrameSplit {
    /// Raster size.
    pub width: usize,
    /// Raster height.
    pub height: usize,
    /// Shadow map \[ms\].
    pub shadow_ms: f64,
    /// Epipolar in-scatter and transmittance \[ms\].
    pub epipolar_ms: f64,
    /// Composite `colour · T + inscatter` \[ms\].
    pub composite_ms: f64,
    /// Shadow map + epipolar + composite \[ms\].
    pub total_ms: f64,
    /// The camera's distance buffer, ray traced by voltab (an engine rasterises it) \[ms\].
    pub gbuffer_ms: f64,
}

/// [`FrameSplit`] of `inp`'s scene at `width × height` with a `shadow_res²` shadow map, on the
/// current rayon pool.
pub fn frame_split(inp: &Inputs, width: usize, height: usize, shadow_res: usize) -> FrameSplit {
    let best = |f: &mut dyn FnMut() -> f64| (0..3).map(|_| f()).fold(f64::INFINITY, f64::min);
    let mut cam = inp.cam;
    cam.width = width;
    cam.height = height;
    let timed = |f: &mut dyn FnMut()| {
        let t = Instant::now();
        f();
        t.elapsed().as_secs_f64() * 1e3
    };
    let mut depth = None;
    let gbuffer_ms = best(&mut || timed(&mut || depth = Some(distance_image(&inp.bvh, &cam))));
    let depth = depth.unwrap_or_else(|| distance_image(&inp.bvh, &cam));
    let mut shadow = None;
    let shadow_ms =
        best(&mut || timed(&mut || shadow = Some(render_shadow_map(&inp.bvh, &inp.light, inp.bounds, shadow_res))));
    let shadow = shadow.unwrap_or_else(|| render_shadow_map(&inp.bvh, &inp.light, inp.bounds, shadow_res));
    let opts = EpipolarOptions::default();
    let mut out = None;
    let epipolar_ms =
        best(&mut || timed(&mut || out = Some(render(&cam, &depth, &inp.light, &shadow, &inp.medium, &opts))));
    let out = out.unwrap_or_else(|| render(&cam, &depth, &inp.light, &shadow, &inp.medium, &opts));
    let colour = crate::render::Image::filled(width, height, [0.5f32; 3]);
    let composite_ms = best(&mut || {
        timed(&mut || {
            std::hint::black_box(super::composite(&colour, &out));
        })
    });
    FrameSplit {
        width,
        height,
        shadow_ms,
        epipolar_ms,
        composite_ms,
        total_ms: shadow_ms + epipolar_ms + composite_ms,
        gbuffer_ms,
    }
}

/// The inputs of one measurement: scene products that are not timed.
pub struct Inputs {
    /// Camera.
    pub cam: ViewCamera,
    /// Depth image.
    pub depth: DistanceImage,
    /// Light.
    pub light: EpiLight,
    /// Medium.
    pub medium: EpiMedium,
    /// Shadow map.
    pub shadow: ShadowMap,
    /// BVH.
    pub bvh: SceneBvh,
    /// Scene bounds.
    pub bounds: ([f64; 3], [f64; 3]),
}

impl Inputs {
    /// Camera (the scene's first), light, medium, depth image and shadow map of `scene`.
    pub fn new(scene: &Scene, width: usize, height: usize, shadow_res: usize) -> Result<Inputs, String> {
        let camera = scene.cameras.first().ok_or("the scene has no camera")?;
        let cam = ViewCamera::from_scene(camera, width, height)
            .ok_or("the scene's camera is not a usable perspective camera")?;
        let light = EpiLight::from_scene(scene).ok_or("the scene has no directional or spot light")?;
        let medium = EpiMedium::from_scene(scene).ok_or_else(|| EpiMedium::refusal(scene))?;
        let bounds = scene.bounds().ok_or("the scene is empty")?;
        let bvh = SceneBvh::build(scene);
        let depth = distance_image(&bvh, &cam);
        let shadow = render_shadow_map(&bvh, &light, bounds, shadow_res);
        Ok(Inputs { cam, depth, light, medium, shadow, bvh, bounds })
    }

    /// The same inputs at another raster size.
    pub fn resized(&self, width: usize, height: usize) -> Inputs {
        let mut cam = self.cam;
        cam.width = width;
        cam.height = height;
        let depth = distance_image(&self.bvh, &cam);
        Inputs {
            cam,
            depth,
            light: self.light.clone(),
            medium: self.medium,
            shadow: self.shadow.clone(),
            bvh: self.bvh.clone(),
            bounds: self.bounds,
        }
    }

    /// The converged reference: BVH marcher with `steps` per ray.
    pub fn reference(&self, steps: usize) -> RgbImage {
        march_bvh(&self.cam, &self.depth, &self.light, &self.bvh, &self.medium, self.bounds, steps, 0)
    }
}

pub use crate::render::rel_rmse;

/// Epipolar knob ladder: (slice density, samples per pixel, γ bins).
fn epi_ladder(quick: bool) -> Vec<(f64, f64, usize)> {
    if quick {
        vec![(0.5, 0.5, 128), (1.0, 1.0, 512)]
    } else {
        vec![(0.25, 0.25, 256), (0.5, 0.5, 512), (1.0, 1.0, 1024), (1.0, 1.0, 2048), (2.0, 2.0, 4096)]
    }
}

fn march_ladder(quick: bool) -> Vec<usize> {
    if quick { vec![4, 16] } else { vec![2, 4, 8, 16, 32, 64, 128] }
}

/// The error-vs-time points of both methods on `inp` against `reference`, on the current rayon pool,
/// plus the phases of the default setting.
pub fn measure(inp: &Inputs, reference: &RgbImage, quick: bool) -> (Vec<ErrorTimePoint>, EpipolarStats) {
    let mut pts = Vec::new();
    let mut default_stats = EpipolarStats::default();
    for (dens, spp, bins) in epi_ladder(quick) {
        let opts =
            EpipolarOptions { slice_density: dens, samples_per_pixel: spp, gamma_bins: bins, ..Default::default() };
        let t = Instant::now();
        let out = render(&inp.cam, &inp.depth, &inp.light, &inp.shadow, &inp.medium, &opts);
        let ms = t.elapsed().as_secs_f64() * 1e3;
        if bins == 2048 || (quick && bins == 512) {
            default_stats = out.stats;
        }
        pts.push(ErrorTimePoint {
            method: "epipolar".into(),
            knob: format!("slices×{dens} β/px {spp} bins {bins}"),
            ms,
            error: rel_rmse(&out.inscatter, reference),
        });
    }
    for steps in march_ladder(quick) {
        let t = Instant::now();
        let img = march_shadow_map(&inp.cam, &inp.depth, &inp.light, &inp.shadow, &inp.medium, steps);
        let ms = t.elapsed().as_secs_f64() * 1e3;
        pts.push(ErrorTimePoint {
            method: "raymarch".into(),
            knob: format!("{steps} steps"),
            ms,
            error: rel_rmse(&img, reference),
        });
    }
    (pts, default_stats)
}

/// Error-vs-time points of both methods on `scene` at `width × height` (current rayon pool), for
/// `voltab report`: shadow map 2048² (256² when `quick`), reference = BVH marcher with 256 steps (64).
pub fn error_vs_time(scene: &Scene, width: usize, height: usize, quick: bool) -> Result<Vec<ErrorTimePoint>, String> {
    let inp = Inputs::new(scene, width, height, if quick { 256 } else { 2048 })?;
    let reference = inp.reference(if quick { 64 } else { 256 });
    Ok(measure(&inp, &reference, quick).0)
}

/// Speed-ups at equal error: for each epipolar point, the marcher's time at that error by
/// piecewise-linear interpolation of `log ms` against `log error` (marcher points sorted by time); an
/// error below the marcher's best is extrapolated along the power law through the marcher's two most
/// accurate points (flagged [`SpeedUp::extrapolated`]; only when that law still decreases).
pub fn speedups(points: &[ErrorTimePoint]) -> Vec<SpeedUp> {
    let mut rm: Vec<&ErrorTimePoint> =
        points.iter().filter(|p| p.method == "raymarch" && p.error > 0.0 && p.error.is_finite()).collect();
    rm.sort_by(|a, b| a.ms.total_cmp(&b.ms));
    let interp = |a: &ErrorTimePoint, b: &ErrorTimePoint, e: f64| {
        let f = (e.ln() - a.error.ln()) / (b.error.ln() - a.error.ln());
        (a.ms.ln() + f * (b.ms.ln() - a.ms.ln())).exp()
    };
    let mut out = Vec::new();
    for e in points.iter().filter(|p| p.method == "epipolar" && p.error > 0.0 && p.error.is_finite()) {
        let mut found = None;
        for w in rm.windows(2) {
            let (a, b) = (w[0], w[1]);
            let (hi, lo) = (a.error.max(b.error), a.error.min(b.error));
            if e.error <= hi && e.error >= lo && hi > lo {
                found = Some((interp(a, b, e.error), false));
                break;
            }
        }
        if found.is_none()
            && let [.., a, b] = rm.as_slice()
            && e.error < b.error
            && b.error < a.error
        {
            found = Some((interp(a, b, e.error), true));
        }
        if let Some((ms, extrapolated)) = found {
            out.push(SpeedUp {
                knob: e.knob.clone(),
                error: e.error,
                epi_ms: e.ms,
                march_ms: ms,
                speedup: ms / e.ms,
                extrapolated,
            });
        }
    }
    out
}

/// Least-squares slope of `ln y` against `ln x`.
pub fn loglog_slope(pts: &[(f64, f64)]) -> f64 {
    let v: Vec<(f64, f64)> = pts.iter().filter(|p| p.0 > 0.0 && p.1 > 0.0).map(|p| (p.0.ln(), p.1.ln())).collect();
    let n = v.len() as f64;
    if v.len() < 2 {
        return f64::NAN;
    }
    let (mx, my) = (v.iter().map(|p| p.0).sum::<f64>() / n, v.iter().map(|p| p.1).sum::<f64>() / n);
    let sxy: f64 = v.iter().map(|p| (p.0 - mx) * (p.1 - my)).sum();
    let sxx: f64 = v.iter().map(|p| (p.0 - mx) * (p.0 - mx)).sum();
    if sxx > 0.0 { sxy / sxx } else { f64::NAN }
}

/// Runs the whole benchmark on the scene at `scene_path` (module doc): 1280×960 (160×120 when
/// `quick`), 1 and 2 threads, scaling over 4 resolutions on 1 thread.
pub fn bench(scene_path: &Path, quick: bool) -> Result<BenchReport, String> {
    let scene = Scene::load(scene_path).map_err(|e| e.to_string())?;
    let (w, h) = if quick { (160, 120) } else { (1280, 960) };
    let shadow_res = if quick { 256 } else { 2048 };
    let reference_steps = if quick { 48 } else { 192 };
    let inp = Inputs::new(&scene, w, h, shadow_res)?;
    let reference = inp.reference(reference_steps);
    let mut runs = Vec::new();
    for threads in [1usize, 2] {
        let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().map_err(|e| e.to_string())?;
        let (points, default_stats) = pool.install(|| measure(&inp, &reference, quick));
        let speedups = speedups(&points);
        runs.push(ThreadRun { threads, points, speedups, default_stats });
    }
    // Scaling: side, γ bins and steps ∝ k (the paper scales s, r and d together).
    let pool = rayon::ThreadPoolBuilder::new().num_threads(1).build().map_err(|e| e.to_string())?;
    let ks: [f64; 4] = [0.25, 0.5, 0.75, 1.0];
    let (mut epi, mut rm) = (Vec::new(), Vec::new());
    for &k in &ks {
        let (sw, sh) = (((w as f64 * k).round() as usize).max(8), ((h as f64 * k).round() as usize).max(6));
        let small = inp.resized(sw, sh);
        let bins = ((2048.0 * k).round() as usize).max(16);
        let steps = ((128.0 * k).round() as usize).max(2);
        let opts = EpipolarOptions { gamma_bins: bins, ..Default::default() };
        let (te, tm) = pool.install(|| {
            let t = Instant::now();
            let _ = render(&small.cam, &small.depth, &small.light, &small.shadow, &small.medium, &opts);
            let te = t.elapsed().as_secs_f64() * 1e3;
            let t = Instant::now();
            let _ = march_shadow_map(&small.cam, &small.depth, &small.light, &small.shadow, &small.medium, steps);
            (te, t.elapsed().as_secs_f64() * 1e3)
        });
        epi.push((k, te));
        rm.push((k, tm));
    }
    let scaling = vec![
        Scaling { method: "epipolar".into(), slope: loglog_slope(&epi), points: epi },
        Scaling { method: "raymarch".into(), slope: loglog_slope(&rm), points: rm },
    ];
    let pool = rayon::ThreadPoolBuilder::new().num_threads(2).build().map_err(|e| e.to_string())?;
    let sizes: &[(usize, usize)] = if quick { &[(160, 120)] } else { &[(640, 480), (1280, 720)] };
    let frames = pool.install(|| sizes.iter().map(|&(fw, fh)| frame_split(&inp, fw, fh, shadow_res)).collect());
    Ok(BenchReport { width: w, height: h, shadow_resolution: shadow_res, reference_steps, runs, scaling, frames })
}

/// Writes the error-vs-time plot (log-log, one series per method) of `points` to `path`.
pub fn write_error_plot(points: &[ErrorTimePoint], title: &str, path: &Path) -> Result<(), String> {
    let series: Vec<Series> = ["epipolar", "raymarch"]
        .iter()
        .map(|m| Series {
            name: (*m).to_string(),
            points: points.iter().filter(|p| p.method == *m).map(|p| (p.ms, p.error)).collect(),
        })
        .collect();
    let plot = Plot {
        title,
        x_label: "time [ms]",
        y_label: "relative RMSE of in-scatter",
        x_scale: Scale::Log10,
        y_scale: Scale::Log10,
        series: &series,
        width: 900,
        height: 600,
    };
    write_png(path, &plot).map(|_| ()).map_err(|e| e.to_string())
}

impl fmt::Display for BenchReport {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        writeln!(f, "baran2010 epipolar volumetric shadows vs shadow-map ray marcher, {}×{}", self.width, self.height)?;
        writeln!(
            f,
            "error metric: relative RMSE of the in-scattered image against the BVH ray marcher with {} steps \
             (sqrt(Σ(x−r)²)/sqrt(Σr²) over pixels and channels); shadow map {}²; times exclude depth/shadow maps",
            self.reference_steps, self.shadow_resolution
        )?;
        for run in &self.runs {
            writeln!(f, "\n[{} thread(s)]", run.threads)?;
            for p in &run.points {
                writeln!(f, "  {:<9} {:<32} {:>10.1} ms  error {:.4}", p.method, p.knob, p.ms, p.error)?;
            }
            let s = &run.default_stats;
            writeln!(
                f,
                "  default phases: rectify {:.1} ms, factorise {:.1} ms, prefilter {:.1} ms, integrate {:.1} ms, \
                 ring+edges {:.1} ms ({} + {} px), unrectify {:.1} ms, total {:.1} ms; {} slices, {} β samples, SVD residual {:.3}",
                s.rectify_ms,
                s.factorize_ms,
                s.prefilter_ms,
                s.integrate_ms,
                s.ring_ms,
                s.ring_pixels,
                s.edge_pixels,
                s.unrectify_ms,
                s.total_ms,
                s.slices,
                s.samples,
                s.svd_residual
            )?;
            if run.speedups.is_empty() {
                writeln!(
                    f,
                    "  speed-up at equal error: none (the marcher's curve does not reach the epipolar errors)"
                )?;
            }
            for s in &run.speedups {
                writeln!(
                    f,
                    "  equal error {:.4}: epipolar {:.1} ms ({}) vs ray marcher {:.1} ms{} → {:.1}×",
                    s.error,
                    s.epi_ms,
                    s.knob,
                    s.march_ms,
                    if s.extrapolated { " (extrapolated)" } else { "" },
                    s.speedup
                )?;
            }
        }
        writeln!(f, "\nwhole frame (2 threads, best of 3; shadow map {}² rasterised):", self.shadow_resolution)?;
        for fr in &self.frames {
            writeln!(
                f,
                "  {}×{}: shadow map {:.1} ms + epipolar {:.1} ms + composite {:.1} ms = {:.1} ms \
                 (camera distance buffer, the engine's G-buffer, ray traced here: {:.1} ms)",
                fr.width, fr.height, fr.shadow_ms, fr.epipolar_ms, fr.composite_ms, fr.total_ms, fr.gbuffer_ms
            )?;
        }
        writeln!(f, "\nscaling (1 thread; side, γ bins and steps ∝ k):")?;
        for s in &self.scaling {
            let pts: Vec<String> = s.points.iter().map(|(k, ms)| format!("k={k}: {ms:.1} ms")).collect();
            writeln!(f, "  {:<9} slope {:.2}  [{}]", s.method, s.slope, pts.join(", "))?;
        }
        Ok(())
    }
}
