//! Compilation (the plan executed): validated tables → `.vtab` files in an output folder.
//!
//! Input: a [`ValidatedPipeline`] and [`CompileOptions`]. Output: one `.vtab` + JSON sidecar per
//! selected table and a [`CompileSummary`]. Tables whose content key is already present and
//! verified are "up to date"; keys found in the cache are restored; the rest are generated in
//! parallel (rayon), encoded, and published atomically through [`crate::cache::OutputDir`].
//! Invariant: the `.vtab` bytes depend only on (definition, generator version) — timings and
//! sample counts go to the sidecar, never into the table.

use std::io::IsTerminal;
use std::path::{Path, PathBuf};
use std::time::Instant;

use indicatif::{MultiProgress, ProgressBar, ProgressDrawTarget, ProgressStyle};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::cache::{CacheError, OutputDir, hex};
use crate::container::{self, ContainerError, EncodeOptions, Header};
use crate::pipeline::ValidatedTable;
use crate::pipeline::error::suggestion_help;
use crate::registry::ValidatedPipeline;
use crate::tables::{GenStats, GenerateError, Generated, TableDef};

/// How to compile.
#[derive(Debug, Clone, Default)]
pub struct CompileOptions {
    /// Output folder.
    pub out_dir: PathBuf,
    /// Table ids to compile (empty: all).
    pub only: Vec<String>,
    /// Worker threads (None: rayon's default, i.e. `RAYON_NUM_THREADS` or the core count).
    pub jobs: Option<usize>,
    /// Draw a progress bar (only ever on a terminal).
    pub progress: bool,
}

/// What happened to one table.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum Status {
    /// Generated now.
    Compiled,
    /// Already present with the same key.
    UpToDate,
    /// Taken from the cache (same key compiled earlier).
    Restored,
}

/// JSON sidecar written beside each table: run statistics that must not live inside the table.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Sidecar {
    /// Table id.
    pub id: String,
    /// Kind.
    pub kind: String,
    /// Content key (hex).
    pub content_key: String,
    /// Generator version.
    pub generator_version: String,
    /// Uncompressed payload bytes.
    pub raw_bytes: u64,
    /// Stored payload bytes.
    pub stored_bytes: u64,
    /// File size.
    pub file_bytes: u64,
    /// raw / stored.
    pub compression_ratio: f64,
    /// Per array: (name, raw bytes, stored bytes).
    pub arrays: Vec<(String, u64, u64)>,
    /// Wall time of generation.
    pub generate_ms: f64,
    /// Wall time of encoding (transforms + zstd).
    pub encode_ms: f64,
    /// Wall time of measuring the error estimates against the reference.
    #[serde(default)]
    pub check_ms: f64,
    /// Generator statistics and error estimates.
    pub stats: GenStats,
}

/// Result for one table.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct TableResult {
    /// Table id.
    pub id: String,
    /// What happened.
    pub status: Status,
    /// Output file.
    pub path: PathBuf,
    /// Sidecar data (from this run or the one that compiled it).
    pub sidecar: Sidecar,
}

/// Result of a compile run.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct CompileSummary {
    /// Per table, in pipeline order.
    pub tables: Vec<TableResult>,
    /// Total wall time.
    pub total_ms: f64,
    /// Temporary files of killed runs removed at start.
    pub stale_removed: usize,
}

/// Compilation failed.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum CompileError {
    /// `--only` named an unknown table.
    #[error("--only {id}: no such table in {pipeline}\n  = help: {help}")]
    UnknownOnly {
        /// The id.
        id: String,
        /// Pipeline file.
        pipeline: PathBuf,
        /// Suggestions.
        help: String,
    },
    /// Output folder problem.
    #[error(transparent)]
    Cache(#[from] CacheError),
    /// A generator failed.
    #[error("table \"{id}\": {source}")]
    Generate {
        /// Table id.
        id: String,
        /// Cause.
        source: GenerateError,
    },
    /// Encoding failed (e.g. a non-finite value reached the container: never written).
    #[error("table \"{id}\": {source}")]
    Encode {
        /// Table id.
        id: String,
        /// Cause.
        source: ContainerError,
    },
    /// The worker pool could not start.
    #[error("cannot start {jobs} worker threads: {message}")]
    Threads {
        /// Requested threads.
        jobs: usize,
        /// Cause.
        message: String,
    },
}

/// Encodes a generated table into `.vtab` bytes.
pub fn encode_table(t: &ValidatedTable, g: &Generated) -> Result<container::Encoded, ContainerError> {
    let def = t.def();
    let header = Header {
        kind: def.kind().to_owned(),
        kind_schema_version: def.kind_impl().kind_schema_version(),
        generator_version: def.kind_impl().generator_version().to_owned(),
        definition_ron: def.canonical_ron(),
        content_key: *t.key(),
        arrays: g.arrays.clone(),
    };
    container::encode(&header, &g.values, &EncodeOptions { zstd_level: zstd_level(def) })
}

fn zstd_level(def: &TableDef) -> i32 {
    match def {
        TableDef::PhaseHg(p) => p.zstd_level,
        TableDef::ZhResponse(p) => p.zstd_level,
        TableDef::MsLobes(p) => p.zstd_level,
        TableDef::PopPreset(p) => p.zstd_level,
    }
}

/// Generates and encodes one table, returning the bytes and its sidecar.
pub fn build_table(t: &ValidatedTable, progress: &(dyn Fn(u64) + Sync)) -> Result<(Vec<u8>, Sidecar), CompileError> {
    let t0 = Instant::now();
    let generated = t
        .def()
        .kind_impl()
        .generate(t.key(), progress)
        .map_err(|source| CompileError::Generate { id: t.id().into(), source })?;
    let generate_ms = t0.elapsed().as_secs_f64() * 1e3;
    let t_check = Instant::now();
    let mut generated = generated;
    generated.stats = t
        .def()
        .kind_impl()
        .estimate_errors(&generated, t.key())
        .map_err(|e| CompileError::Generate { id: t.id().into(), source: GenerateError::Check(e) })?;
    let check_ms = t_check.elapsed().as_secs_f64() * 1e3;
    // Progress: generation reports its own units; checking and encoding count as much again each.
    progress(t.def().kind_impl().work_units());
    let (bytes, mut sidecar) = encode_with_sidecar(t, &generated)?;
    progress(t.def().kind_impl().work_units());
    sidecar.generate_ms = generate_ms;
    sidecar.check_ms = check_ms;
    Ok((bytes, sidecar))
}

/// A generated and judged table encoded: the bytes and the sidecar (`generate_ms` and `check_ms` left 0
/// for the caller). A sharded compile's merge runs this on a table assembled from its units, so its
/// bytes are those of [`build_table`].
pub fn encode_with_sidecar(t: &ValidatedTable, generated: &Generated) -> Result<(Vec<u8>, Sidecar), CompileError> {
    let t1 = Instant::now();
    let enc = encode_table(t, generated).map_err(|source| CompileError::Encode { id: t.id().into(), source })?;
    let encode_ms = t1.elapsed().as_secs_f64() * 1e3;
    let s = &enc.stats;
    let sidecar = Sidecar {
        id: t.id().into(),
        kind: t.def().kind().into(),
        content_key: hex(t.key()),
        generator_version: t.def().kind_impl().generator_version().into(),
        raw_bytes: s.raw_bytes,
        stored_bytes: s.stored_bytes,
        file_bytes: enc.bytes.len() as u64,
        compression_ratio: s.ratio(),
        arrays: s.per_array.iter().map(|a| (a.name.clone(), a.raw_bytes, a.stored_bytes)).collect(),
        generate_ms: 0.0,
        encode_ms,
        check_ms: 0.0,
        stats: generated.stats.clone(),
    };
    Ok((enc.bytes, sidecar))
}

/// Compiles the selected tables of `p`.
pub fn compile(p: &ValidatedPipeline, opts: &CompileOptions) -> Result<CompileSummary, CompileError> {
    let t0 = Instant::now();
    let selected: Vec<&ValidatedTable> = if opts.only.is_empty() {
        p.tables().iter().collect()
    } else {
        let ids: Vec<&str> = p.tables().iter().map(ValidatedTable::id).collect();
        opts.only
            .iter()
            .map(|id| {
                p.table(id).ok_or_else(|| CompileError::UnknownOnly {
                    id: id.clone(),
                    pipeline: p.path().to_path_buf(),
                    help: suggestion_help(id, &ids, "table id"),
                })
            })
            .collect::<Result<_, _>>()?
    };
    let out = OutputDir::open(&opts.out_dir, || {
        eprintln!("waiting for another voltab run that is using {}", opts.out_dir.display());
    })?;

    // Cheap checks first (serially): up to date or restorable from the cache.
    let mut results: Vec<Option<TableResult>> = Vec::with_capacity(selected.len());
    for t in &selected {
        let status = if out.is_up_to_date(t.id(), t.key()) {
            Some(Status::UpToDate)
        } else if out.restore(t.id(), t.key())? {
            Some(Status::Restored)
        } else {
            None
        };
        results.push(match status {
            Some(status) => Some(TableResult {
                id: t.id().into(),
                status,
                path: out.table_path(t.id()),
                sidecar: read_sidecar(&out.sidecar_path(t.id()), t)?,
            }),
            None => None,
        });
    }

    let todo: Vec<usize> = (0..selected.len()).filter(|&i| results[i].is_none()).collect();
    let lines = TableLines::new(opts.progress && !todo.is_empty());
    let run = || -> Vec<(usize, Result<TableResult, CompileError>)> {
        todo.par_iter()
            .map(|&i| {
                let t = selected[i];
                let bar = lines.start(t);
                let t1 = Instant::now();
                let r = build_table(t, &|n| bar.inc(n)).and_then(|(bytes, sidecar)| {
                    let json = serde_json::to_vec_pretty(&sidecar).unwrap_or_default();
                    out.store(t.id(), t.key(), &bytes, &json)?;
                    Ok(TableResult {
                        id: t.id().into(),
                        status: Status::Compiled,
                        path: out.table_path(t.id()),
                        sidecar,
                    })
                });
                lines.finish(&bar, t, t1, r.is_ok());
                (i, r)
            })
            .collect()
    };
    let built = match opts.jobs {
        Some(jobs) => rayon::ThreadPoolBuilder::new()
            .num_threads(jobs)
            .build()
            .map_err(|e| CompileError::Threads { jobs, message: e.to_string() })?
            .install(run),
        None => run(),
    };
    for (i, r) in built {
        results[i] = Some(r?);
    }
    Ok(CompileSummary {
        tables: results.into_iter().flatten().collect(),
        total_ms: t0.elapsed().as_secs_f64() * 1e3,
        stale_removed: out.stale_removed,
    })
}

/// Reads an existing sidecar; a missing or unreadable one is rebuilt from the table header.
fn read_sidecar(path: &Path, t: &ValidatedTable) -> Result<Sidecar, CompileError> {
    let parsed = std::fs::read(path).ok().and_then(|b| serde_json::from_slice::<Sidecar>(&b).ok());
    Ok(parsed.unwrap_or_else(|| Sidecar {
        id: t.id().into(),
        kind: t.def().kind().into(),
        content_key: hex(t.key()),
        generator_version: t.def().kind_impl().generator_version().into(),
        raw_bytes: 0,
        stored_bytes: 0,
        file_bytes: 0,
        compression_ratio: 0.0,
        arrays: Vec::new(),
        generate_ms: 0.0,
        encode_ms: 0.0,
        check_ms: 0.0,
        stats: GenStats::default(),
    }))
}

/// One progress line per table being compiled on a terminal (id, kind, work units done of its
/// total in its own unit, rate, ETA); a finished table's line gives way to one line saying so.
/// Nothing is drawn off a terminal.
struct TableLines {
    multi: MultiProgress,
    style: Option<ProgressStyle>,
}

impl TableLines {
    fn new(show: bool) -> Self {
        let show = show && std::io::stderr().is_terminal();
        let target = if show { ProgressDrawTarget::stderr() } else { ProgressDrawTarget::hidden() };
        let style = ProgressStyle::with_template(
            "{spinner} {prefix:<20} {msg} [{elapsed_precise}] {wide_bar} {percent:>3}% {per_sec} ETA {eta}",
        )
        .ok();
        TableLines { multi: MultiProgress::with_draw_target(target), style }
    }

    /// The line of table `t`: its generation reports `work_units` and its encoding and check one
    /// more share each ([`build_table`]), hence a length of three shares.
    fn start(&self, t: &ValidatedTable) -> ProgressBar {
        let units = t.def().kind_impl().work_units();
        let bar = self.multi.add(ProgressBar::new(3 * units));
        if let Some(style) = &self.style {
            bar.set_style(style.clone());
        }
        bar.set_prefix(t.id().to_string());
        bar.set_message(format!("{} ({} {})", t.def().kind(), units, t.def().kind_impl().work_unit_name()));
        bar
    }

    /// Replaces the line of table `t` by one summary line.
    fn finish(&self, bar: &ProgressBar, t: &ValidatedTable, started: Instant, ok: bool) {
        bar.finish_and_clear();
        self.multi.remove(bar);
        let what = if ok { "generated" } else { "failed" };
        let secs = started.elapsed().as_secs_f64();
        // A hidden display prints nothing; a broken terminal only loses the line.
        let _ = self.multi.println(format!("{what:<10} {:<20} {:<10} in {secs:.1} s", t.id(), t.def().kind()));
    }
}

/// A progress bar labelled `label` (what it counts) on stderr when `show` and stderr is a terminal;
/// hidden otherwise.
pub fn progress_bar(show: bool, total: u64, label: impl Into<std::borrow::Cow<'static, str>>) -> ProgressBar {
    if !show || !std::io::stderr().is_terminal() {
        return ProgressBar::with_draw_target(Some(total), ProgressDrawTarget::hidden());
    }
    let bar = ProgressBar::new(total).with_message(label);
    if let Ok(style) =
        ProgressStyle::with_template("{spinner} {msg} [{elapsed_precise}] {wide_bar} {pos}/{len} {per_sec} ETA {eta}")
    {
        bar.set_style(style);
    }
    bar
}

/// One line per table for the terminal.
pub fn summary_line(r: &TableResult) -> String {
    let s = &r.sidecar;
    let status = match r.status {
        Status::Compiled => "compiled  ",
        Status::UpToDate => "up to date",
        Status::Restored => "restored  ",
    };
    let err = s.stats.headline().map_or_else(String::new, |e| format!("  {} {:.2e}", e.name, e.value));
    let time = match r.status {
        Status::Compiled => format!("{:>8.1} ms", s.generate_ms + s.encode_ms),
        _ => format!("{:>11}", ""),
    };
    format!(
        "{status} {:<20} {:<10} {:>10}  ratio {:>5.2}  {time}{err}",
        r.id,
        s.kind,
        crate::pipeline::validate::human_bytes(u128::from(s.file_bytes)),
        s.compression_ratio,
    )
}
