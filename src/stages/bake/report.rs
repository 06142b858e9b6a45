//! Error against run time of the lightmap bake: the ZH-table bake and the brute-force volumetric path
//! tracer ([`crate::reference::volpath`]), both measured against a converged reference on the same texels.
//!
//! **Input → output.** A `BakeLightmaps` definition (its scene, atlas settings and modes), the loaded table
//! and a [`LadderOptions`] → [`BakeReport`]: rows (method, samples, wall time, relative RMSE), the speed-up
//! of the bake over the reference at equal error, and a log-log PNG of error against time.
//!
//! **Error.** Relative RMSE over the texel subset and the three channels against the converged
//! reference, relative to its mean, with its noise removed and its floor stated ([`NoiseCorrected`]):
//! a rung below the floor is entered at the floor and marked, never as a smaller number. The subset is
//! every k-th `inside` texel of the atlas (same texels for every method), so run times are for those
//! texels only; both methods trace on the same thread pool.
//!
//! **Speed-up at equal error.** The bake's error at a rung is looked up on the reference's curve, which is
//! interpolated log-log between rungs (Monte-Carlo error falls like `t^{-1/2}`); beyond the last rung it is
//! extrapolated with that slope, and the row says so.

use std::path::Path;
use std::time::Instant;

use serde::{Deserialize, Serialize};

use super::transport::{Transport, TransportOptions};
use super::{BakeLightmaps, BakeMode, TexelPoint, atlas, bake_points};
use crate::reference::volpath::{self, SurfacePoint, VolPathOptions};
use crate::report::noisy::NoiseCorrected;
use crate::scene::Scene;
use crate::scene::bvh::SceneBvh;
use crate::tables::zh_response::ZhResponseTable;

/// What the ladder measures.
#[derive(Debug, Clone, PartialEq)]
pub struct LadderOptions {
    /// Texels in the subset.
    pub texels: usize,
    /// Paths per texel of the converged reference.
    pub converged_samples: u32,
    /// Reference rungs (paths per texel).
    pub reference_samples: Vec<u32>,
    /// Bake rungs (samples per texel, Full mode).
    pub bake_samples: Vec<u32>,
}

impl Default for LadderOptions {
    fn default() -> Self {
        LadderOptions {
            texels: 256,
            converged_samples: 8192,
            reference_samples: vec![4, 16, 64, 256, 1024],
            bake_samples: vec![1, 4, 16, 64, 256],
        }
    }
}

/// One measurement.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct LadderRow {
    /// `reference`, or the bake mode.
    pub method: String,
    /// Samples per texel.
    pub samples: u32,
    /// Wall time over the subset \[ms\].
    pub ms: f64,
    /// Relative RMSE against the converged reference, its noise removed (the floor when below it).
    pub rel_rmse: f64,
    /// The error is below the converged reference's floor: `rel_rmse` is the floor, an upper bound.
    pub below_floor: bool,
    /// For bake rows: reference time needed for the same error \[ms\] (log-log interpolated).
    pub reference_ms_at_equal_error: Option<f64>,
    /// `reference_ms_at_equal_error / ms` (a lower bound when `below_floor`).
    pub speedup: Option<f64>,
    /// The reference time was extrapolated beyond the ladder.
    pub extrapolated: bool,
}

/// The ladder of one bake stage.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct BakeReport {
    /// Stage id.
    pub stage: String,
    /// Texels measured.
    pub texels: usize,
    /// Converged reference: samples, time \[ms\] and its own mean relative standard error.
    pub converged: (u32, f64, f64),
    /// The smallest relative RMSE the converged reference resolves.
    pub floor: f64,
    /// Rows.
    pub rows: Vec<LadderRow>,
}

/// The measured texels of `atlas`: every k-th inside texel, `count` of them at most.
pub fn subset(atlas: &atlas::Atlas, count: usize) -> Vec<TexelPoint> {
    let inside: Vec<&atlas::Texel> = atlas.texels.iter().filter(|t| t.inside).collect();
    let step = inside.len().div_ceil(count.max(1)).max(1);
    inside
        .iter()
        .step_by(step)
        .map(|t| TexelPoint {
            position: t.position,
            normal: t.normal,
            geometric_normal: t.geometric_normal,
            cell: u64::from(t.pixel),
        })
        .collect()
}

/// Relative RMSE of `a` against `r` over all channels.
pub fn rel_rmse(a: &[[f64; 3]], r: &[[f64; 3]]) -> f64 {
    let (mut num, mut den) = (0.0, 0.0);
    for (x, y) in a.iter().zip(r) {
        for c in 0..3 {
            num += (x[c] - y[c]).powi(2);
            den += y[c] * y[c];
        }
    }
    if den > 0.0 { (num / den).sqrt() } else { 0.0 }
}

/// Mean luminance of `a`.
pub fn mean_luminance(a: &[[f64; 3]]) -> f64 {
    a.iter().map(|c| super::transport::luminance(*c)).sum::<f64>() / a.len().max(1) as f64
}

/// The path-traced irradiance of texels.
pub struct Reference {
    /// Irradiance per texel \[W/m²\].
    pub mean: Vec<[f64; 3]>,
    /// Variance of each mean.
    pub variance: Vec<[f64; 3]>,
    /// Mean relative standard error (luminance).
    pub rel_stderr: f64,
    /// Time \[ms\].
    pub ms: f64,
}

/// Runs the reference on `points`.
pub fn reference(scene: &Scene, bvh: &SceneBvh, points: &[TexelPoint], samples: u32, seed: u64) -> Reference {
    let sp: Vec<SurfacePoint> =
        points.iter().map(|p| SurfacePoint { position: p.position, normal: p.normal }).collect();
    let opts = VolPathOptions {
        samples,
        max_depth: 64,
        rr_depth: 4,
        seed,
        surface_bounces: u32::MAX,
        eye_surfaces: true,
        media: true,
    };
    let t0 = Instant::now();
    let (est, _) = volpath::irradiance(scene, bvh, &sp, &opts);
    let ms = t0.elapsed().as_secs_f64() * 1e3;
    let rel: f64 = est
        .iter()
        .map(|e| {
            let m = super::transport::luminance(e.mean);
            if m > 0.0 { super::transport::luminance(e.stderr) / m } else { 0.0 }
        })
        .sum::<f64>()
        / est.len().max(1) as f64;
    Reference {
        mean: est.iter().map(|e| e.mean).collect(),
        variance: est.iter().map(|e| e.stderr.map(|s| s * s)).collect(),
        rel_stderr: rel,
        ms,
    }
}

/// Bakes `points` in `mode` at `samples` (scatter samples scaled like the stage's default ratio): (irradiance, ms).
pub fn bake(
    scene: &Scene,
    bvh: &SceneBvh,
    table: Option<&ZhResponseTable>,
    def: &BakeLightmaps,
    mode: BakeMode,
    samples: u32,
    points: &[TexelPoint],
) -> Result<(Vec<[f64; 3]>, f64), String> {
    let ratio = f64::from(def.scatter_samples) / f64::from(def.samples.max(1));
    let scatter = ((f64::from(samples) * ratio).round() as u32).clamp(1, samples);
    let opts = TransportOptions { samples, scatter_samples: scatter, ..def.transport_options(mode) };
    let t0 = Instant::now();
    let tr = Transport::new(scene, bvh, table, opts).map_err(|e| e.to_string())?;
    let est = bake_points(&tr, points, false, "").map_err(|e| e.to_string())?;
    Ok((est.iter().map(|e| e.irradiance).collect(), t0.elapsed().as_secs_f64() * 1e3))
}

/// Reference time at error `e` on the reference rows' curve (sorted by time), and whether extrapolated.
fn time_at_error(rows: &[(f64, f64)], e: f64) -> Option<(f64, bool)> {
    let pts: Vec<(f64, f64)> = rows.iter().filter(|(t, err)| *t > 0.0 && *err > 0.0).copied().collect();
    if pts.is_empty() || e.is_nan() || e <= 0.0 {
        return None;
    }
    for w in pts.windows(2) {
        let ((t0, e0), (t1, e1)) = (w[0], w[1]);
        if (e <= e0 && e >= e1) || (e >= e0 && e <= e1) {
            if e0 == e1 {
                return Some((t0, false));
            }
            let f = (e.ln() - e0.ln()) / (e1.ln() - e0.ln());
            return Some(((t0.ln() + f * (t1.ln() - t0.ln())).exp(), false));
        }
    }
    // Beyond the ladder: the t^{-1/2} law from the nearest end.
    let (t, err) = if e < pts[pts.len() - 1].1 { pts[pts.len() - 1] } else { pts[0] };
    Some((t * (err / e).powi(2), true))
}

/// The whole ladder.
#[allow(clippy::too_many_arguments)]
pub fn ladder(
    id: &str,
    scene: &Scene,
    bvh: &SceneBvh,
    table: Option<&ZhResponseTable>,
    def: &BakeLightmaps,
    atlas: &atlas::Atlas,
    opts: &LadderOptions,
    progress: &dyn Fn(&str),
) -> Result<BakeReport, String> {
    let points = subset(atlas, opts.texels);
    progress(&format!("{id}: converged reference, {} texels × {} paths", points.len(), opts.converged_samples));
    let truth = reference(scene, bvh, &points, opts.converged_samples, 0x5eed_0001);
    let judge = |e: &[[f64; 3]]| {
        NoiseCorrected::of_rgb(e, &truth.mean, &truth.variance)
            .map_err(|e| format!("the converged reference cannot judge: {e}"))
    };
    let mut rows = Vec::new();
    let mut ref_curve = Vec::new();
    let floor = judge(&truth.mean)?.floor;
    for &s in &opts.reference_samples {
        progress(&format!("{id}: reference at {s} paths"));
        let r = reference(scene, bvh, &points, s, 0x5eed_0002);
        let err = judge(&r.mean)?;
        let ms = r.ms;
        ref_curve.push((ms, err.rel_or_floor()));
        rows.push(LadderRow {
            method: "reference".into(),
            samples: s,
            ms,
            rel_rmse: err.rel_or_floor(),
            below_floor: err.below_floor(),
            reference_ms_at_equal_error: None,
            speedup: None,
            extrapolated: false,
        });
    }
    ref_curve.sort_by(|a, b| a.0.total_cmp(&b.0));
    let push_bake = |mode: BakeMode, s: u32, rows: &mut Vec<LadderRow>| -> Result<(), String> {
        progress(&format!("{id}: bake {} at {s} samples", mode.name()));
        let (e, ms) = bake(scene, bvh, table, def, mode, s, &points)?;
        let judged = judge(&e)?;
        let err = judged.rel_or_floor();
        let at = time_at_error(&ref_curve, err);
        rows.push(LadderRow {
            method: mode.name().into(),
            samples: s,
            ms,
            rel_rmse: err,
            below_floor: judged.below_floor(),
            reference_ms_at_equal_error: at.map(|a| a.0),
            speedup: at.map(|a| a.0 / ms.max(1e-6)),
            extrapolated: at.is_some_and(|a| a.1),
        });
        Ok(())
    };
    for &s in &opts.bake_samples {
        push_bake(BakeMode::Full, s, &mut rows)?;
    }
    for mode in [BakeMode::Surface, BakeMode::Shadow] {
        push_bake(mode, def.samples, &mut rows)?;
    }
    Ok(BakeReport {
        stage: id.into(),
        texels: points.len(),
        converged: (opts.converged_samples, truth.ms, truth.rel_stderr),
        floor,
        rows,
    })
}

/// Writes `<stage>-lightmap-error-vs-time.png` into `dir`.
pub fn plot(r: &BakeReport, dir: &Path) -> Result<std::path::PathBuf, String> {
    use crate::report::plot::{Plot, Scale, Series, write_png};
    let series_of = |method: &str, name: &str| Series {
        name: name.into(),
        points: r.rows.iter().filter(|x| x.method == method).map(|x| (x.ms, x.rel_rmse)).collect(),
    };
    let series = vec![
        series_of("reference", "volumetric path tracing (reference)"),
        series_of("full", "ZH-table bake, Full"),
        series_of("surface", "surface only"),
        series_of("shadow", "media shadowing only"),
    ];
    let title = format!("{}: lightmap error against run time ({} texels)", r.stage, r.texels);
    let path = dir.join(format!("{}-lightmap-error-vs-time.png", r.stage));
    write_png(
        &path,
        &Plot {
            title: &title,
            x_label: "wall time (ms)",
            y_label: "relative RMSE vs converged reference",
            x_scale: Scale::Log10,
            y_scale: Scale::Log10,
            series: &series,
            width: 1024,
            height: 720,
        },
    )
    .map_err(|e| e.to_string())?;
    Ok(path)
}

/// Markdown table of the rows.
pub fn markdown(r: &BakeReport) -> String {
    let mut s = format!(
        "## {}: lightmap error against run time\n\n{} texels; converged reference {} paths/texel in {:.0} ms (its mean relative standard error {:.2} %). Errors relative to its mean with its noise removed; \"< X\": below the floor X it resolves.\n\n| method | samples | ms | rel. RMSE | reference ms at equal error | speed-up |\n|---|---|---|---|---|---|\n",
        r.stage,
        r.texels,
        r.converged.0,
        r.converged.1,
        100.0 * r.converged.2
    );
    for x in &r.rows {
        let eq = x
            .reference_ms_at_equal_error
            .map_or("—".into(), |t| format!("{t:.0}{}", if x.extrapolated { " (extrapolated)" } else { "" }));
        // Below the floor the bake's error is at most the floor, so the reference's time to match it is
        // at least the time at the floor: the speed-up is a lower bound.
        let ge = if x.below_floor { "≥ " } else { "" };
        let sp = x.speedup.map_or("—".into(), |v| format!("{ge}{v:.1}×"));
        let lt = if x.below_floor { "< " } else { "" };
        s += &format!("| {} | {} | {:.1} | {lt}{:.4} | {eq} | {sp} |\n", x.method, x.samples, x.ms, x.rel_rmse);
    }
    s
}
