//! `voltab report`: error against run time for every table of a pipeline.
//!
//! Input: a validated pipeline. For each table, its kind's ladder of quality budgets is generated
//! and encoded (timed), then measured against the kind's independent reference.
//! Output: `report.json` (rows: table, budget, ms, bytes, error per curve, plus a machine note),
//! `report.md`, and one log-log PNG of error against time per table. Plots are made from the rows.

pub mod noisy;
pub mod plot;

use std::path::{Path, PathBuf};
use std::time::Instant;

use serde::{Deserialize, Serialize};

use crate::cache::write_atomic;
use crate::compile::{encode_table, progress_bar};
use crate::pipeline::Limits;
use crate::registry::ValidatedPipeline;
use crate::tables::Generated;

/// One rung of one table's ladder.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Row {
    /// Budget label, e.g. `mu_bins=1024`.
    pub budget: String,
    /// Generation wall time (best of repeats), ms.
    pub generate_ms: f64,
    /// Encoding wall time (best of repeats), ms.
    pub encode_ms: f64,
    /// Encoded size.
    pub bytes: u64,
    /// raw / stored.
    pub compression_ratio: f64,
    /// Error per curve.
    pub errors: Vec<(String, f64)>,
    /// Worst error over curves.
    pub error_max: f64,
    /// NaN/Inf samples the generator discarded (always shown, so silent loss is visible).
    pub nonfinite_discarded: u64,
}

/// A table's results.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct TableReport {
    /// Table id.
    pub id: String,
    /// Kind.
    pub kind: String,
    /// What the error means.
    pub error_name: String,
    /// Rows, cheapest budget first.
    pub rows: Vec<Row>,
    /// The PNG plot.
    pub plot: PathBuf,
}

/// The whole report.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Report {
    /// voltab version.
    pub voltab_version: String,
    /// Machine the timings come from.
    pub machine: String,
    /// Pipeline file.
    pub pipeline: PathBuf,
    /// Per table.
    pub tables: Vec<TableReport>,
}

/// Report failure.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum ReportError {
    /// A rung could not be built or measured.
    #[error("table \"{id}\", {budget}: {message}")]
    Rung {
        /// Table id.
        id: String,
        /// Budget.
        budget: String,
        /// Why.
        message: String,
    },
    /// An output could not be written.
    #[error("cannot write {path}: {message}\n  = help: choose a writable folder with --out DIR")]
    Output {
        /// File.
        path: PathBuf,
        /// Why.
        message: String,
    },
}

fn machine_note() -> String {
    let cpu = std::fs::read_to_string("/proc/cpuinfo")
        .ok()
        .and_then(|s| {
            s.lines()
                .find(|l| l.starts_with("model name"))
                .and_then(|l| l.split(':').nth(1))
                .map(|s| s.trim().to_owned())
        })
        .unwrap_or_else(|| "unknown CPU".into());
    format!("{cpu}, {} threads, {} {}", rayon::current_num_threads(), std::env::consts::OS, std::env::consts::ARCH)
}

/// Times `f` as the best of up to 5 runs (stopping once 200 ms have been spent).
fn best_time<T>(mut f: impl FnMut() -> T) -> (T, f64) {
    let start = Instant::now();
    let t = Instant::now();
    let mut out = f();
    let mut best = t.elapsed().as_secs_f64();
    for _ in 0..4 {
        if start.elapsed().as_secs_f64() > 0.2 {
            break;
        }
        let t = Instant::now();
        out = f();
        best = best.min(t.elapsed().as_secs_f64());
    }
    (out, best * 1e3)
}

/// Runs the report into `out_dir`.
pub fn run(p: &ValidatedPipeline, out_dir: &Path, progress: bool) -> Result<Report, ReportError> {
    let out_err = |path: &Path, e: &dyn std::fmt::Display| ReportError::Output {
        path: path.to_path_buf(),
        message: e.to_string(),
    };
    std::fs::create_dir_all(out_dir).map_err(|e| out_err(out_dir, &e))?;
    let limits = Limits::from_machine();
    let rungs: u64 = p.tables().iter().map(|t| t.def().kind_impl().report_ladder().len() as u64).sum();
    let bar = progress_bar(progress, rungs, "report: ladder rungs");
    let mut tables = Vec::new();
    for t in p.tables() {
        let mut rows = Vec::new();
        for (budget, def) in t.def().kind_impl().report_ladder() {
            let rung_err = |message: String| ReportError::Rung { id: t.id().into(), budget: budget.clone(), message };
            let vt = t.with_def(def, &limits).map_err(rung_err)?;
            let (generated, generate_ms) = best_time(|| vt.def().kind_impl().generate(vt.key(), &|_| {}));
            let generated: Generated = generated.map_err(|e| rung_err(e.to_string()))?;
            let (enc, encode_ms) = best_time(|| encode_table(&vt, &generated));
            let enc = enc.map_err(|e| rung_err(e.to_string()))?;
            let errors = vt.def().kind_impl().report_measure(&generated).map_err(|e| rung_err(e.to_string()))?;
            let error_max = errors.iter().map(|e| e.1).fold(0.0, f64::max);
            rows.push(Row {
                budget,
                generate_ms,
                encode_ms,
                bytes: enc.bytes.len() as u64,
                compression_ratio: enc.stats.ratio(),
                errors,
                error_max,
                nonfinite_discarded: generated.stats.nonfinite_discarded,
            });
            bar.inc(1);
        }
        let plot_path = out_dir.join(format!("{}-error-vs-time.png", t.id()));
        write_plot(&plot_path, t.id(), t.def().kind_impl().report_error_name(), &rows)
            .map_err(|e| out_err(&plot_path, &e))?;
        tables.push(TableReport {
            id: t.id().into(),
            kind: t.def().kind().into(),
            error_name: t.def().kind_impl().report_error_name().into(),
            rows,
            plot: plot_path,
        });
    }
    bar.finish_and_clear();
    let report = Report {
        voltab_version: env!("CARGO_PKG_VERSION").into(),
        machine: machine_note(),
        pipeline: p.path().to_path_buf(),
        tables,
    };
    let json_path = out_dir.join("report.json");
    let json = serde_json::to_vec_pretty(&report).map_err(|e| out_err(&json_path, &e))?;
    write_atomic(&json_path, &json).map_err(|e| out_err(&json_path, &e))?;
    let md_path = out_dir.join("report.md");
    write_atomic(&md_path, markdown(&report).as_bytes()).map_err(|e| out_err(&md_path, &e))?;
    Ok(report)
}

fn write_plot(path: &Path, id: &str, error_name: &str, rows: &[Row]) -> Result<(), plot::PlotError> {
    let names: Vec<String> = rows.first().map(|r| r.errors.iter().map(|e| e.0.clone()).collect()).unwrap_or_default();
    let series: Vec<plot::Series> = names
        .iter()
        .enumerate()
        .map(|(i, name)| plot::Series {
            name: name.clone(),
            points: rows.iter().filter_map(|r| r.errors.get(i).map(|e| (r.generate_ms + r.encode_ms, e.1))).collect(),
        })
        .collect();
    let title = format!("{id}: error vs run time");
    let y_label = format!("error ({error_name})");
    let y_label = if y_label.len() > 60 { "max relative error".to_owned() } else { y_label };
    plot::write_png(
        path,
        &plot::Plot {
            title: &title,
            x_label: "generate + encode time (ms)",
            y_label: &y_label,
            x_scale: plot::Scale::Log10,
            y_scale: plot::Scale::Log10,
            series: &series,
            width: 1024,
            height: 720,
        },
    )
    .map(|_| ())
}

/// The Markdown summary.
pub fn markdown(r: &Report) -> String {
    let mut s = format!(
        "# voltab report\n\nPipeline `{}`, voltab {}, machine: {}.\n\n",
        r.pipeline.display(),
        r.voltab_version,
        r.machine
    );
    for t in &r.tables {
        s.push_str(&format!(
            "## `{}` ({})\n\nError: {}. Plot: `{}`.\n\n",
            t.id,
            t.kind,
            t.error_name,
            t.plot.file_name().map_or_else(String::new, |f| f.to_string_lossy().into_owned())
        ));
        s.push_str(
            "| budget | generate ms | encode ms | bytes | ratio | NaN/Inf discarded | worst error |\n|---|---:|---:|---:|---:|---:|---:|\n",
        );
        for row in &t.rows {
            s.push_str(&format!(
                "| {} | {:.3} | {:.3} | {} | {:.2} | {} | {:.3e} |\n",
                row.budget,
                row.generate_ms,
                row.encode_ms,
                row.bytes,
                row.compression_ratio,
                row.nonfinite_discarded,
                row.error_max
            ));
        }
        s.push('\n');
    }
    s
}
