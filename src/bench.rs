//! `voltab bench`: timings measured side by side in one process, printed as ratios (absolute
//! times only as context). Tests never assert wall-clock times; this command is where timing
//! claims are checked.
//!
//! Input: a validated pipeline. Output: a text table on stdout (and the same rows as JSON with
//! `--json`): cold compile vs no-op recompile, 1 vs N worker threads, and zstd levels 3/9/19 per table.

use std::time::Instant;

use serde::Serialize;

use crate::compile::{CompileError, CompileOptions, compile, encode_table};
use crate::container::ContainerError;
use crate::pipeline::{Limits, ValidatedPipeline};
use crate::tables::TableDef;

/// One measured comparison.
#[derive(Debug, Clone, Serialize)]
pub struct BenchRow {
    /// What is compared.
    pub what: String,
    /// Baseline, ms.
    pub baseline_ms: f64,
    /// Candidate, ms.
    pub candidate_ms: f64,
    /// baseline / candidate (> 1: candidate is faster).
    pub speedup: f64,
    /// Extra note (sizes).
    pub note: String,
}

/// Bench failure.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum BenchError {
    /// Compiling failed.
    #[error(transparent)]
    Compile(#[from] CompileError),
    /// Encoding failed.
    #[error(transparent)]
    Container(#[from] ContainerError),
    /// The scratch folder could not be made.
    #[error("cannot create a scratch folder: {0}")]
    Scratch(std::io::Error),
    /// A variant of a table did not validate.
    #[error("{0}")]
    Variant(String),
}

fn ms(t: Instant) -> f64 {
    t.elapsed().as_secs_f64() * 1e3
}

/// Median of `n` timed runs of `f`.
fn median_ms<E>(n: usize, mut f: impl FnMut() -> Result<(), E>) -> Result<f64, E> {
    let mut v = Vec::with_capacity(n);
    for _ in 0..n {
        let t = Instant::now();
        f()?;
        v.push(ms(t));
    }
    v.sort_by(f64::total_cmp);
    Ok(v[n / 2])
}

fn with_level(def: &TableDef, level: i32) -> TableDef {
    match def {
        TableDef::PhaseHg(p) => TableDef::PhaseHg(crate::tables::phase_hg::PhaseHg { zstd_level: level, ..p.clone() }),
    }
}

/// Runs the benchmarks.
pub fn run(p: &ValidatedPipeline) -> Result<Vec<BenchRow>, BenchError> {
    let scratch = tempfile::Builder::new().prefix("voltab-bench-").tempdir().map_err(BenchError::Scratch)?;
    let opts = |dir: &str, jobs| CompileOptions { out_dir: scratch.path().join(dir), jobs, ..Default::default() };
    let mut rows = Vec::new();

    let t = Instant::now();
    compile(p, &opts("cold", None))?;
    let cold = ms(t);
    let noop = median_ms(5, || compile(p, &opts("cold", None)).map(|_| ()))?;
    rows.push(BenchRow {
        what: "compile: cold vs up-to-date rerun".into(),
        baseline_ms: cold,
        candidate_ms: noop,
        speedup: cold / noop,
        note: format!("{} tables", p.tables().len()),
    });

    let threads = rayon::current_num_threads();
    let t = Instant::now();
    compile(p, &opts("j1", Some(1)))?;
    let one = ms(t);
    let t = Instant::now();
    compile(p, &opts("jn", Some(threads)))?;
    let many = ms(t);
    rows.push(BenchRow {
        what: format!("compile: 1 vs {threads} threads (cold)"),
        baseline_ms: one,
        candidate_ms: many,
        speedup: one / many,
        note: String::new(),
    });

    let limits = Limits::from_machine();
    for table in p.tables() {
        let generated = table.def().generate(table.key(), &|_| {}).map_err(|e| BenchError::Variant(e.to_string()))?;
        let mut sizes = Vec::new();
        let mut times = Vec::new();
        for level in [3, 9, 19] {
            let v = table.with_def(with_level(table.def(), level), &limits).map_err(BenchError::Variant)?;
            let mut bytes = 0;
            let t = median_ms(3, || {
                encode_table(&v, &generated).map(|e| {
                    bytes = e.bytes.len();
                })
            })?;
            sizes.push(bytes);
            times.push(t);
        }
        for (i, level) in [3, 19].into_iter().enumerate() {
            let k = if i == 0 { 0 } else { 2 };
            rows.push(BenchRow {
                what: format!("encode {}: zstd 9 vs {level}", table.id()),
                baseline_ms: times[1],
                candidate_ms: times[k],
                speedup: times[1] / times[k],
                note: format!("size {level}/9 = {:.3}", sizes[k] as f64 / sizes[1] as f64),
            });
        }
    }
    Ok(rows)
}

/// The rows as a text table.
pub fn render(rows: &[BenchRow]) -> String {
    let mut s =
        format!("{:<44} {:>12} {:>12} {:>9}  {}\n", "comparison", "baseline ms", "candidate ms", "speedup", "note");
    for r in rows {
        s.push_str(&format!(
            "{:<44} {:>12.2} {:>12.2} {:>8.2}x  {}\n",
            r.what, r.baseline_ms, r.candidate_ms, r.speedup, r.note
        ));
    }
    s
}
