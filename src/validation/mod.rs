//! `voltab validate`: every stage of a pipeline judged against Mitsuba 3, an independent renderer that
//! shares none of voltab's code or simplifications (issue 30).
//!
//! **Input → output.** A validated pipeline with its tables compiled, a [`Quality`] and the stages to
//! check → per stage one or more [`Case`]s ([`cases`]: what the stage computes, evaluated by the stage's own code at
//! points or pixels the reference can evaluate too, and the scene as the reference must see it for that
//! quantity) → the scene exported for Mitsuba ([`crate::reference::mitsuba`]) and a request for the
//! Python harness (`python/mitsuba_ref`, which renders the same quantity from independent runs and
//! compares noise-corrected, [`python`]) → `validation.json` ([`Validation`]), `validation.md`, a
//! picture per stage (method | Mitsuba | difference for images; both per texel for lightmaps) and
//! `error_vs_time.png`.
//!
//! **How errors are stated.** Relative RMSE over all items and channels, normalised by the reference's
//! mean, with the reference's variance subtracted (E[(a − r)²] − Var(r), the variance from independent
//! runs); below the smallest error the comparison can resolve it reads "< floor X"; a 95 % interval
//! beside every number. A stage the harness cannot judge yet is listed with the reason, never left out.

pub mod cases;
pub mod python;
pub mod texels;

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use crate::cache::write_atomic;
use crate::report::plot::{self, Plot, Scale, Series};

/// How long the reference runs.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Quality {
    /// Low resolution and few texels, a few minutes for the default pipeline on two cores (CI).
    Quick,
    /// The stages' own resolution, more texels and paths (tens of minutes; opt-in).
    Full,
}

/// What the reference evaluates.
#[derive(Debug, Clone, Serialize)]
#[serde(tag = "kind", rename_all = "lowercase")]
pub enum Query {
    /// Irradiance \[W/m²\] at surface points (white Lambertian probes, the harness's module doc).
    Irradiance {
        /// Positions \[m\].
        points: Vec<[f64; 3]>,
        /// Unit normals.
        normals: Vec<[f64; 3]>,
        /// Paths per point and run.
        spp: u32,
        /// Mitsuba's max_depth (-1: all orders).
        max_depth: Vec<i32>,
    },
    /// The camera's image \[W/(m²·sr)\].
    Image {
        /// Width \[px\].
        width: u32,
        /// Height \[px\].
        height: u32,
        /// Paths per pixel and run.
        spp: u32,
        /// Mitsuba's max_depth (-1: all orders).
        max_depth: Vec<i32>,
        /// Subtract the image at this max_depth (light of exactly the orders between).
        #[serde(skip_serializing_if = "Option::is_none")]
        minus_depth: Option<i32>,
        /// Compare means over blocks of this many pixels square (a noisy reference resolves the error at
        /// that scale).
        #[serde(skip_serializing_if = "Option::is_none")]
        block: Option<u32>,
    },
}

/// One method's values at the query's items.
#[derive(Debug, Clone, Serialize)]
pub struct Method {
    /// Name in the report (e.g. the bake mode).
    pub name: String,
    /// RGB per item (pixels row-major).
    pub values: Vec<[f64; 3]>,
    /// The method's wall time for these values \[ms\].
    pub ms: f64,
    /// Variance of each value when the method is itself a Monte-Carlo estimate (an internal
    /// reference): the harness subtracts it too, so its error is not inflated by its own noise.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub variance: Option<Vec<[f64; 3]>>,
}

/// A stage made comparable.
#[derive(Debug)]
pub struct Case {
    /// Stage id.
    pub stage: String,
    /// Stage kind.
    pub kind: &'static str,
    /// The quantity compared, in words.
    pub quantity: String,
    /// The scene as the reference must see it for that quantity.
    pub scene: crate::scene::Scene,
    /// A second scene whose image is subtracted from the first's (same query, independent seeds).
    pub minus_scene: Option<crate::scene::Scene>,
    /// Export options (camera, raster).
    pub export: crate::reference::mitsuba::ExportOptions,
    /// What the reference evaluates.
    pub query: Query,
    /// The stage's values.
    pub methods: Vec<Method>,
    /// Known differences between what the stage and the reference compute (stated in the report).
    pub caveats: Vec<String>,
}

/// One method's error against Mitsuba.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct MethodResult {
    /// Method name.
    pub name: String,
    /// The method's time \[ms\].
    pub ms: f64,
    /// Noise-corrected relative RMSE; `None` below the floor or when it could not be computed.
    pub rel_rmse: Option<f64>,
    /// 95 % interval of the relative RMSE.
    pub ci95: Option<[f64; 2]>,
    /// Smallest error the comparison resolves.
    pub floor: Option<f64>,
    /// The relative RMSE before the reference's noise is subtracted.
    pub raw_rel_rmse: Option<f64>,
    /// Mean of the method's values over items and channels.
    pub method_mean: f64,
    /// Mean of the reference's values.
    pub reference_mean: Option<f64>,
    /// The report's wording ("0.123 (floor 0.004)", "< floor 0.004") or why there is no number.
    pub text: String,
}

/// One stage's validation.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct StageResult {
    /// Stage id.
    pub stage: String,
    /// Stage kind.
    pub kind: String,
    /// Compared quantity; empty when not compared.
    pub quantity: String,
    /// Why the stage was not compared (`None`: compared).
    pub not_compared: Option<String>,
    /// Known differences between the two computations.
    pub caveats: Vec<String>,
    /// Items compared (texels or pixels).
    pub items: usize,
    /// Mitsuba variant used.
    pub variant: String,
    /// Reference paths per item (spp × runs).
    pub reference_paths: u64,
    /// Independent reference runs (the variance comes from them).
    pub reference_runs: u32,
    /// Reference wall time \[s\].
    pub reference_s: f64,
    /// The stage's methods.
    pub methods: Vec<MethodResult>,
    /// Files written for this stage (pictures, the export, the harness's result).
    pub files: Vec<PathBuf>,
}

/// `validation.json`.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Validation {
    /// Pipeline file.
    pub pipeline: PathBuf,
    /// Quality.
    pub quality: Quality,
    /// Per stage.
    pub stages: Vec<StageResult>,
}

/// Validation failed (not: a stage missed its target, which is a result).
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum ValidateError {
    /// A stage could not compute its values.
    #[error(transparent)]
    Stage(#[from] crate::stages::StageError),
    /// The export failed.
    #[error("stage \"{stage}\": {source}")]
    Export {
        /// Stage id.
        stage: String,
        /// Why.
        source: crate::reference::mitsuba::ExportError,
    },
    /// The harness failed or could not be started.
    #[error(transparent)]
    Python(#[from] python::PythonError),
    /// Writing a result failed.
    #[error("cannot write {}: {message}\n  help: check that the output folder is writable", path.display())]
    Output {
        /// File.
        path: PathBuf,
        /// Why.
        message: String,
    },
}

fn output_error(path: &Path, e: impl std::fmt::Display) -> ValidateError {
    ValidateError::Output { path: path.to_path_buf(), message: e.to_string() }
}

/// Runs the reference for one case in `dir` (export, request, harness) and writes its pictures.
pub fn judge(case: &Case, dir: &Path, harness: &python::Harness) -> Result<StageResult, ValidateError> {
    std::fs::create_dir_all(dir).map_err(|e| output_error(dir, e))?;
    let export_dir = dir.join("mitsuba");
    crate::reference::mitsuba::export(&case.scene, &case.export, &export_dir)
        .map_err(|source| ValidateError::Export { stage: case.stage.clone(), source })?;
    let runs = 4;
    if let Some(minus) = &case.minus_scene {
        crate::reference::mitsuba::export(minus, &case.export, &dir.join("mitsuba_minus"))
            .map_err(|source| ValidateError::Export { stage: case.stage.clone(), source })?;
    }
    let mut query = serde_json::to_value(&case.query).expect("the query serialises");
    if case.minus_scene.is_some() {
        query["minus_export"] = "mitsuba_minus".into();
    }
    query["name"] = slug(&case.stage).into();
    query["methods"] = case
        .methods
        .iter()
        .map(|m| match &m.variance {
            Some(v) => serde_json::json!({"name": m.name, "values": m.values, "variance": v}),
            None => serde_json::json!({"name": m.name, "values": m.values}),
        })
        .collect();
    let request = serde_json::json!({
        "export": "mitsuba", "out": "reference.json", "variant": "auto", "runs": runs, "seed": 0,
        "queries": [query],
    });
    let reply = harness.run(dir, "request.json", &request)?;
    let entry = reply.queries.first().ok_or_else(|| python::PythonError::Reply {
        path: dir.join("reference.json"),
        message: "no query result".into(),
    })?;
    let (spp, items) = match &case.query {
        Query::Irradiance { spp, points, .. } => (*spp, points.len()),
        Query::Image { spp, width, height, block, .. } => {
            let b = block.unwrap_or(1).max(1);
            (*spp, ((*width / b) * (*height / b)) as usize)
        }
    };
    let mut methods = Vec::new();
    for m in &case.methods {
        let c = entry.comparisons.iter().find(|c| c.method.as_deref() == Some(m.name.as_str()));
        methods.push(method_result(m, c));
    }
    let mut files = vec![export_dir, dir.join("reference.json")];
    files.extend(pictures(case, dir, entry)?);
    Ok(StageResult {
        stage: case.stage.clone(),
        kind: case.kind.into(),
        quantity: case.quantity.clone(),
        not_compared: None,
        caveats: case.caveats.clone(),
        items,
        variant: reply.variant.clone(),
        reference_paths: u64::from(spp) * runs as u64,
        reference_runs: runs,
        reference_s: reply.queries.iter().map(|q| q.seconds).sum(),
        methods,
        files,
    })
}

fn method_result(m: &Method, c: Option<&python::Comparison>) -> MethodResult {
    let n = (m.values.len() * 3).max(1) as f64;
    let method_mean = m.values.iter().flatten().sum::<f64>() / n;
    let Some(c) = c else {
        return MethodResult {
            name: m.name.clone(),
            ms: m.ms,
            rel_rmse: None,
            ci95: None,
            floor: None,
            raw_rel_rmse: None,
            method_mean,
            reference_mean: None,
            text: "no comparison returned".into(),
        };
    };
    MethodResult {
        name: m.name.clone(),
        ms: m.ms,
        rel_rmse: c.rel_rmse,
        ci95: c.ci95,
        floor: c.floor,
        raw_rel_rmse: c.raw_rel_rmse,
        method_mean,
        reference_mean: c.norm,
        text: c.error.clone().unwrap_or_else(|| c.text.clone().unwrap_or_default()),
    }
}

/// Method | reference | |difference| for images (one exposure for all three); for texels a plot of both
/// per texel, sorted by the reference's luminance.
fn pictures(case: &Case, dir: &Path, entry: &python::QueryResult) -> Result<Vec<PathBuf>, ValidateError> {
    let mut files = Vec::new();
    match &case.query {
        Query::Image { width, height, .. } => {
            let Some(mean_file) = entry.files.first() else { return Ok(files) };
            let path = dir.join(mean_file);
            let img = crate::image_io::read_exr_rgb(&path).map_err(|e| output_error(&path, e))?;
            let reference = img.rgb(None).unwrap_or_default();
            let (w, h) = (*width as usize, *height as usize);
            if img.width != w || img.height != h || reference.len() != w * h {
                return Ok(files);
            }
            for m in &case.methods {
                let mut strip = vec![[0.0f32; 3]; 3 * w * h];
                for y in 0..h {
                    for x in 0..w {
                        let a = m.values[y * w + x].map(|v| v as f32);
                        let r = reference[y * w + x];
                        strip[y * 3 * w + x] = a;
                        strip[y * 3 * w + w + x] = r;
                        strip[y * 3 * w + 2 * w + x] = [0, 1, 2].map(|c| (a[c] - r[c]).abs());
                    }
                }
                let png = dir.join(format!("{}_vs_mitsuba.png", slug(&m.name)));
                crate::image_io::write_png_preview(&png, 3 * w, h, &strip, None).map_err(|e| output_error(&png, e))?;
                files.push(png);
            }
        }
        Query::Irradiance { .. } => {
            let luma = |v: &[f64; 3]| crate::render::color::luminance(*v);
            let reference: Vec<f64> = entry.mean.iter().map(luma).collect();
            let mut order: Vec<usize> = (0..reference.len()).collect();
            order.sort_by(|&a, &b| reference[a].total_cmp(&reference[b]));
            let mut series = vec![Series {
                name: "Mitsuba".into(),
                points: order.iter().enumerate().map(|(k, &i)| (k as f64, reference[i])).collect(),
            }];
            for m in &case.methods {
                series.push(Series {
                    name: m.name.clone(),
                    points: order.iter().enumerate().map(|(k, &i)| (k as f64, luma(&m.values[i]))).collect(),
                });
            }
            let png = dir.join("texels_vs_mitsuba.png");
            let title = format!("{}: irradiance per texel against Mitsuba", case.stage);
            let p = Plot {
                title: &title,
                x_label: "texel (sorted by Mitsuba's irradiance)",
                y_label: "irradiance luminance [W/m²]",
                x_scale: Scale::Linear,
                y_scale: Scale::Log10,
                series: &series,
                width: 900,
                height: 600,
            };
            plot::write_png(&png, &p).map_err(|e| output_error(&png, e))?;
            files.push(png);
        }
    }
    Ok(files)
}

fn slug(s: &str) -> String {
    s.chars().map(|c| if c.is_ascii_alphanumeric() { c.to_ascii_lowercase() } else { '_' }).collect()
}

/// A stage listed without a comparison, and why.
pub fn not_compared(stage: &str, kind: &str, reason: &str) -> StageResult {
    StageResult {
        stage: stage.into(),
        kind: kind.into(),
        quantity: String::new(),
        not_compared: Some(reason.into()),
        caveats: Vec::new(),
        items: 0,
        variant: String::new(),
        reference_paths: 0,
        reference_runs: 0,
        reference_s: 0.0,
        methods: Vec::new(),
        files: Vec::new(),
    }
}

/// The Markdown table of `validation.md`.
pub fn markdown(v: &Validation) -> String {
    let mut s = format!(
        "# Validation against Mitsuba 3: {} ({:?})\n\n\
         Error: noise-corrected relative RMSE over all items and RGB channels (reference variance from \
         independent runs subtracted), relative to the reference's mean; \"< floor X\": below what the \
         comparison resolves. 95 % interval in brackets.\n\n\
         | stage | method | quantity | error vs Mitsuba [95 % CI] | noise floor | raw error | mean / Mitsuba's | \
         method time | reference (paths/item, time) |\n|---|---|---|---|---|---|---|---|---|\n",
        v.pipeline.display(),
        v.quality
    );
    for st in &v.stages {
        if let Some(why) = &st.not_compared {
            s.push_str(&format!("| {} | — | not compared | {why} | | | | | |\n", st.stage));
            continue;
        }
        for m in &st.methods {
            let err = match (m.rel_rmse, m.ci95) {
                (Some(e), Some([lo, hi])) => format!("{:.1} % [{:.1}, {:.1}]", 100.0 * e, 100.0 * lo, 100.0 * hi),
                (Some(e), None) => format!("{:.1} %", 100.0 * e),
                // Below the floor: the floor in the table's unit (per cent), as the floor column states it.
                (None, _) => m.floor.map_or_else(|| m.text.clone(), |f| format!("< floor {:.1} %", 100.0 * f)),
            };
            let pct = |x: Option<f64>| x.map_or("—".into(), |x| format!("{:.2} %", 100.0 * x));
            s.push_str(&format!(
                "| {} | {} | {} ({} items) | {err} | {} | {} | {} | {:.0} ms | {} ({}×{} runs), {:.0} s |\n",
                st.stage,
                m.name,
                st.quantity,
                st.items,
                pct(m.floor),
                pct(m.raw_rel_rmse),
                m.reference_mean.map_or("—".into(), |r| format!("{:.3}", m.method_mean / r)),
                m.ms,
                st.variant,
                st.reference_paths / u64::from(st.reference_runs.max(1)),
                st.reference_runs,
                st.reference_s
            ));
        }
    }
    let caveats: Vec<String> =
        v.stages.iter().flat_map(|st| st.caveats.iter().map(move |c| format!("- **{}**: {c}\n", st.stage))).collect();
    if !caveats.is_empty() {
        s.push_str("\nWhat the two sides compute differently (known, stated rather than hidden):\n\n");
        s.extend(caveats);
    }
    s
}

/// Writes `validation.json`, `validation.md` and `error_vs_time.png` into `dir`.
pub fn write(v: &Validation, dir: &Path) -> Result<Vec<PathBuf>, ValidateError> {
    std::fs::create_dir_all(dir).map_err(|e| output_error(dir, e))?;
    let json = dir.join("validation.json");
    let bytes = serde_json::to_vec_pretty(v).map_err(|e| output_error(&json, e))?;
    write_atomic(&json, &bytes).map_err(|e| output_error(&json, e))?;
    let md = dir.join("validation.md");
    write_atomic(&md, markdown(v).as_bytes()).map_err(|e| output_error(&md, e))?;
    let series: Vec<Series> = v
        .stages
        .iter()
        .flat_map(|st| {
            st.methods.iter().filter_map(move |m| {
                let e = m.rel_rmse.or(m.floor)?;
                Some(Series { name: format!("{} {}", st.stage, m.name), points: vec![(m.ms.max(1e-3), e)] })
            })
        })
        .collect();
    let png = dir.join("error_vs_time.png");
    let p = Plot {
        title: "Error against Mitsuba vs the stage's time (floor where below it)",
        x_label: "method time [ms]",
        y_label: "relative RMSE",
        x_scale: Scale::Log10,
        y_scale: Scale::Log10,
        series: &series,
        width: 1000,
        height: 640,
    };
    plot::write_png(&png, &p).map_err(|e| output_error(&png, e))?;
    Ok(vec![json, md, png])
}

#[cfg(test)]
mod tests;
