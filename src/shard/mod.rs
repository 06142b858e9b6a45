//! Scale-out: a compile split into deterministic work units over N shards, and a merge that writes the
//! bytes one machine writes; lightmap bakes split into texel tiles the same way ([`bake`]).
//!
//! Input: a [`ValidatedPipeline`] and a [`ShardSpec`] (`--shard I/N`, or `auto` from Slurm's or
//! Kubernetes' job-array variables). Output: a self-describing shard folder — `shard.json` (the
//! [`Manifest`]: voltab version, pipeline content key, the job's whole unit list, and per part its
//! blake3) plus one `.part` file per work unit — and, from [`merge`], the tables of the pipeline in an
//! output folder, published through [`crate::cache::OutputDir`] exactly as `voltab compile` publishes them.
//!
//! Work units follow the axes the generators key their random streams on
//! ([`TableKind::units`](crate::tables::TableKind::units)): an `MsLobes` table splits into photon
//! batches (`MsLobes::unit_photons`, 2^18 or more on fine grids) per g slice (integer tallies, summed in the merge) plus one unit per
//! check reference, a `ZhResponse` table into its (emitter, g) responses plus its walk references,
//! and every other table is one unit. A unit computes the same bits wherever it runs, and
//! [`TableKind::assemble`](crate::tables::TableKind::assemble) is the code `voltab compile` itself runs
//! after computing every unit in one process, so a merged table is byte-identical to a local one
//! (tested in `tests/shard.rs`).
//! Units are spread by longest-processing-time-first over the shards from their declared work
//! ([`assign`]), so the split is a pure function of (pipeline, N).
//!
//! Failure model: a part file appears atomically and carries its own blake3, so a task killed mid-way
//! leaves finished units that a rerun reuses (no-ops) and no manifest; the manifest is written last, so
//! a shard folder without one is unfinished. [`merge`] checks every shard (version, pipeline key,
//! duplicates, coverage, every part's digest) before it publishes anything, and names the shard and the
//! units it lacks.

pub mod bake;
pub mod bench;
pub mod slurm;

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::time::Instant;

use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::cache::{CacheError, OutputDir, write_atomic};
use crate::compile::{CompileError, Sidecar, Status, TableResult, build_table};
use crate::pipeline::ValidatedTable;
use crate::registry::ValidatedPipeline;
use crate::tables::{GenerateError, UnitPart};

/// The manifest's file name inside a shard folder.
pub const MANIFEST: &str = "shard.json";
/// Format version of the manifest and part files.
const FORMAT: u32 = 1;
/// First bytes of a part file.
const PART_MAGIC: &[u8; 8] = b"VTPART1\0";

/// Which shard of how many this process computes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct ShardSpec {
    /// 0-based index.
    pub index: u32,
    /// Number of shards.
    pub count: u32,
}

impl ShardSpec {
    /// Parses `I/N`, `auto` or `auto/N`. `auto` reads Slurm's `SLURM_ARRAY_TASK_ID` (the count from
    /// `VOLTAB_SHARD_COUNT`, else `SLURM_ARRAY_TASK_COUNT`) or Kubernetes' `JOB_COMPLETION_INDEX` (the
    /// count from `/N`, else `VOLTAB_SHARD_COUNT`); `env` looks a variable up.
    pub fn parse(text: &str, env: &dyn Fn(&str) -> Option<String>) -> Result<Self, ShardError> {
        let bad = |message: String, help: &str| ShardError::Spec { message, help: help.into() };
        let num = |s: &str, what: &str| -> Result<u32, ShardError> {
            s.trim().parse::<u32>().map_err(|_| {
                bad(format!("{what} \"{s}\" is not a whole number"), "write --shard I/N, e.g. --shard 0/4")
            })
        };
        let (index, count) = if let Some(rest) = text.strip_prefix("auto") {
            let count_arg = match rest.strip_prefix('/') {
                Some(n) => Some(num(n, "the shard count")?),
                None if rest.is_empty() => None,
                None => return Err(bad(format!("--shard {text}"), "write --shard auto or --shard auto/N")),
            };
            let from_env = |name: &str| env(name).filter(|v| !v.trim().is_empty());
            let count_env = || -> Result<Option<u32>, ShardError> {
                from_env("VOLTAB_SHARD_COUNT").map(|v| num(&v, "VOLTAB_SHARD_COUNT")).transpose()
            };
            if let Some(id) = from_env("SLURM_ARRAY_TASK_ID") {
                let count = match (count_arg, count_env()?) {
                    (Some(n), _) | (None, Some(n)) => n,
                    (None, None) => match from_env("SLURM_ARRAY_TASK_COUNT") {
                        Some(c) => num(&c, "SLURM_ARRAY_TASK_COUNT")?,
                        None => {
                            return Err(bad(
                                "SLURM_ARRAY_TASK_ID is set but not the shard count".into(),
                                "set VOLTAB_SHARD_COUNT or write --shard auto/N",
                            ));
                        }
                    },
                };
                (num(&id, "SLURM_ARRAY_TASK_ID")?, count)
            } else if let Some(id) = from_env("JOB_COMPLETION_INDEX") {
                let Some(count) = count_arg.or(count_env()?) else {
                    return Err(bad(
                        "JOB_COMPLETION_INDEX is set but not the shard count".into(),
                        "write --shard auto/N (N = the Job's completions) or set VOLTAB_SHARD_COUNT",
                    ));
                };
                (num(&id, "JOB_COMPLETION_INDEX")?, count)
            } else {
                return Err(bad(
                    "--shard auto: neither SLURM_ARRAY_TASK_ID nor JOB_COMPLETION_INDEX is set".into(),
                    "run inside a Slurm job array or an indexed Kubernetes Job, or write --shard I/N",
                ));
            }
        } else {
            let Some((i, n)) = text.split_once('/') else {
                return Err(bad(format!("--shard {text}"), "write --shard I/N (0 <= I < N), e.g. --shard 0/4"));
            };
            (num(i, "the shard index")?, num(n, "the shard count")?)
        };
        if count == 0 || index >= count {
            return Err(bad(
                format!("shard {index} of {count} does not exist"),
                "the index is 0-based and below the count: --shard 0/4 … --shard 3/4",
            ));
        }
        if count > 1_000_000 {
            return Err(bad(format!("{count} shards"), "use at most 1000000 shards"));
        }
        Ok(Self { index, count })
    }
}

impl std::fmt::Display for ShardSpec {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}/{}", self.index, self.count)
    }
}

/// One work unit of a compile.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Unit {
    /// Stable name: `<table id>` or `<table id>#<unit>`.
    pub name: String,
    /// Index of the table in the pipeline.
    pub table: usize,
    /// The unit of a split table; `None` for a whole table.
    pub part: Option<usize>,
    /// Declared work (the generator's progress units), for balancing.
    pub cost: u64,
}

/// The work units of compiling `p`, in pipeline order.
pub fn compile_units(p: &ValidatedPipeline) -> Vec<Unit> {
    let mut units = Vec::new();
    for (ti, t) in p.tables().iter().enumerate() {
        let n = t.def().kind_impl().units();
        let work = t.def().kind_impl().work_units().max(1);
        if n <= 1 {
            units.push(Unit { name: t.id().to_string(), table: ti, part: None, cost: work });
        } else {
            for u in 0..n {
                units.push(Unit { name: format!("{}#{u}", t.id()), table: ti, part: Some(u), cost: work / n as u64 });
            }
        }
    }
    units
}

/// The shard of each unit: longest declared work first, each to the least-loaded shard (ties to the
/// lower index) — a pure function of the units and the count.
pub fn assign(units: &[Unit], count: u32) -> Vec<u32> {
    let mut order: Vec<usize> = (0..units.len()).collect();
    order.sort_by(|&a, &b| units[b].cost.cmp(&units[a].cost).then(a.cmp(&b)));
    let mut load = vec![0u128; count.max(1) as usize];
    let mut shard = vec![0u32; units.len()];
    for i in order {
        let (best, _) = load.iter().enumerate().min_by(|a, b| a.1.cmp(b.1).then(a.0.cmp(&b.0))).unwrap_or((0, &0));
        shard[i] = best as u32;
        load[best] += u128::from(units[i].cost.max(1));
    }
    shard
}

/// Content key of a pipeline's compile: the voltab version and every table's (id, content key) in
/// order. Shards of one job share it; a shard of another pipeline or generator version does not.
pub fn pipeline_key(p: &ValidatedPipeline) -> String {
    let mut h = blake3::Hasher::new();
    h.update(b"voltab shard key v1\0");
    h.update(env!("CARGO_PKG_VERSION").as_bytes());
    for t in p.tables() {
        h.update(b"\0");
        h.update(t.id().as_bytes());
        h.update(b"\0");
        h.update(t.key());
    }
    h.finalize().to_hex().to_string()
}

/// What a shard task computed: table units (`voltab compile --shard`) or bake tiles
/// (`voltab run --shard`, [`bake`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Job {
    /// Work units of the pipeline's tables.
    #[default]
    Compile,
    /// Texel tiles of the pipeline's lightmap bakes.
    Bake,
}

/// `shard.json`: what a shard folder holds.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Manifest {
    /// Format version.
    pub format: u32,
    /// What the shard computed (absent in compile shards written before bake tiles existed).
    #[serde(default)]
    pub job: Job,
    /// The voltab that wrote it.
    pub voltab_version: String,
    /// The pipeline file (as given on the command line).
    pub pipeline: PathBuf,
    /// The scenes the pipeline was planned for (`--scene`).
    pub scenes: Vec<PathBuf>,
    /// [`pipeline_key`].
    pub pipeline_key: String,
    /// This shard.
    pub shard: ShardSpec,
    /// Every unit of the job, in order (the same list in every shard).
    pub units: Vec<String>,
    /// The units this shard computed.
    pub parts: Vec<PartEntry>,
}

/// One computed unit.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PartEntry {
    /// Unit name.
    pub unit: String,
    /// File name inside the shard folder.
    pub file: String,
    /// blake3 of the whole file.
    pub blake3: String,
    /// File size.
    pub bytes: u64,
    /// Wall time of computing it \[ms\] (0 when reused from an earlier attempt).
    pub ms: f64,
}

impl PartEntry {
    /// The entry of unit `unit` written as `file` with `bytes`, computed in `ms`.
    fn of(unit: &str, file: &str, bytes: &[u8], ms: f64) -> Self {
        PartEntry {
            unit: unit.to_string(),
            file: file.to_string(),
            blake3: blake3::hash(bytes).to_hex().to_string(),
            bytes: bytes.len() as u64,
            ms,
        }
    }
}

/// What a part file carries.
#[derive(Debug, Serialize, Deserialize)]
enum Payload {
    /// A whole table: its `.vtab` bytes and JSON sidecar.
    Table { vtab: Vec<u8>, sidecar: Vec<u8> },
    /// One unit of a split table and its generation time.
    Unit { part: UnitPart, ms: f64 },
    /// One tile of a bake: its texels' estimates and the time they took.
    Texels { estimates: Vec<crate::stages::bake::transport::Estimate>, ms: f64 },
}

/// Sharding failed.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum ShardError {
    /// A bad `--shard` argument.
    #[error("{message}\n  = help: {help}")]
    Spec {
        /// What is wrong.
        message: String,
        /// The fix.
        help: String,
    },
    /// A shard folder cannot be merged.
    #[error("{path}: {message}\n  = help: {help}")]
    Shard {
        /// The shard folder.
        path: PathBuf,
        /// What is wrong.
        message: String,
        /// The fix.
        help: String,
    },
    /// The shards do not cover the job.
    #[error("{message}\n  = help: {help}")]
    Coverage {
        /// Which shards lack which units.
        message: String,
        /// The fix.
        help: String,
    },
    /// Compiling a unit failed.
    #[error(transparent)]
    Compile(#[from] CompileError),
    /// Output folder problem.
    #[error(transparent)]
    Cache(#[from] CacheError),
}

/// What [`compile_shard`] or [`bake::bake_shard`] did.
#[derive(Debug, Clone, Serialize)]
pub struct ShardSummary {
    /// The shard.
    pub shard: ShardSpec,
    /// Units of the whole job.
    pub units_total: usize,
    /// Units computed now (name, ms).
    pub computed: Vec<(String, f64)>,
    /// Units reused from an earlier attempt of this shard.
    pub reused: Vec<String>,
    /// Wall time \[ms\].
    pub total_ms: f64,
    /// The folder.
    pub dir: PathBuf,
}

fn part_file(t: &ValidatedTable, unit: &Unit) -> String {
    let mut h = blake3::Hasher::new();
    h.update(t.key());
    h.update(&(unit.part.map_or(u64::MAX, |u| u as u64)).to_le_bytes());
    format!("{}.part", &h.finalize().to_hex()[..32])
}

fn encode_part(payload: &Payload) -> Vec<u8> {
    let body = bincode::serde::encode_to_vec(payload, bincode::config::standard()).unwrap_or_default();
    let mut bytes = Vec::with_capacity(body.len() + 40);
    bytes.extend_from_slice(PART_MAGIC);
    bytes.extend_from_slice(&body);
    bytes.extend_from_slice(blake3::hash(&body).as_bytes());
    bytes
}

fn decode_part(bytes: &[u8]) -> Result<Payload, String> {
    if bytes.len() < PART_MAGIC.len() + 32 || !bytes.starts_with(PART_MAGIC) {
        return Err("not a voltab part file (truncated or foreign)".into());
    }
    let (body, digest) = bytes[PART_MAGIC.len()..].split_at(bytes.len() - PART_MAGIC.len() - 32);
    if blake3::hash(body).as_bytes() != digest {
        return Err("its checksum does not match its contents (corrupt)".into());
    }
    let limit = bincode::config::standard().with_limit::<{ 1 << 40 }>();
    bincode::serde::decode_from_slice::<Payload, _>(body, limit)
        .map(|(p, _)| p)
        .map_err(|e| format!("cannot decode it: {e}"))
}

/// A part file already written by an earlier attempt of this shard, if complete and intact.
fn reusable(path: &Path, limit: u64) -> Option<Vec<u8>> {
    let bytes = crate::cache::bounded::read_regular(path, limit).ok()?;
    decode_part(&bytes).ok().map(|_| bytes)
}

/// Upper bound of a part file's size for a table (its generator's peak memory, plus slack).
fn part_limit(t: &ValidatedTable) -> u64 {
    u64::try_from(t.def().kind_impl().estimated_bytes().saturating_mul(2)).unwrap_or(u64::MAX).saturating_add(64 << 20)
}

/// Computes shard `spec` of compiling `p` into the shard folder `dir`. Units finished by an earlier
/// attempt (their part files intact) are not recomputed; the manifest is written last.
pub fn compile_shard(
    p: &ValidatedPipeline,
    scenes: &[PathBuf],
    spec: ShardSpec,
    dir: &Path,
    jobs: Option<usize>,
    progress: bool,
) -> Result<ShardSummary, ShardError> {
    let t0 = Instant::now();
    let out = OutputDir::open(dir, || {
        eprintln!("waiting for another voltab run that is using {}", dir.display());
    })?;
    let units = compile_units(p);
    let owner = assign(&units, spec.count);
    let mine: Vec<&Unit> = units.iter().zip(&owner).filter(|(_, s)| **s == spec.index).map(|(u, _)| u).collect();
    let total: u64 = mine.iter().map(|u| u.cost).sum();
    let bar = crate::compile::progress_bar(
        progress,
        total,
        format!("shard {}/{}: work (cost units)", spec.index, spec.count),
    );
    let work = |u: &Unit| -> Result<(PartEntry, bool), ShardError> {
        let t = &p.tables()[u.table];
        let file = part_file(t, u);
        let path = dir.join(&file);
        let entry = |bytes: &[u8], ms: f64| PartEntry::of(&u.name, &file, bytes, ms);
        if let Some(bytes) = reusable(&path, part_limit(t)) {
            bar.inc(u.cost);
            return Ok((entry(&bytes, 0.0), true));
        }
        let t1 = Instant::now();
        let payload = match u.part {
            None => {
                let (vtab, sidecar) = build_table(t, &|_| {})?;
                let json = serde_json::to_vec_pretty(&sidecar).unwrap_or_default();
                Payload::Table { vtab, sidecar: json }
            }
            Some(k) => {
                let part = t
                    .def()
                    .kind_impl()
                    .generate_unit(t.key(), k, &|_| {})
                    .map_err(|source| CompileError::Generate { id: t.id().into(), source })?;
                Payload::Unit { part, ms: t1.elapsed().as_secs_f64() * 1e3 }
            }
        };
        let ms = t1.elapsed().as_secs_f64() * 1e3;
        let bytes = encode_part(&payload);
        write_atomic(&path, &bytes)?;
        bar.inc(u.cost);
        Ok((entry(&bytes, ms), false))
    };
    let run = || mine.par_iter().map(|u| work(u)).collect::<Vec<_>>();
    let results = match jobs {
        Some(j) => rayon::ThreadPoolBuilder::new()
            .num_threads(j)
            .build()
            .map_err(|e| CompileError::Threads { jobs: j, message: e.to_string() })?
            .install(run),
        None => run(),
    };
    bar.finish_and_clear();
    let mut parts = Vec::new();
    let (mut computed, mut reused) = (Vec::new(), Vec::new());
    for r in results {
        let (e, was_reused) = r?;
        if was_reused {
            reused.push(e.unit.clone());
        } else {
            computed.push((e.unit.clone(), e.ms));
        }
        parts.push(e);
    }
    let finished = Finished { job: Job::Compile, key: pipeline_key(p), units: &units, parts, computed, reused };
    finished.write(p, scenes, spec, out.path(), t0)
}

/// A shard task's finished work, before its manifest is written.
struct Finished<'a> {
    job: Job,
    key: String,
    units: &'a [Unit],
    parts: Vec<PartEntry>,
    computed: Vec<(String, f64)>,
    reused: Vec<String>,
}

impl Finished<'_> {
    /// Writes the manifest (last: a folder without one is unfinished) and says what the task did.
    fn write(
        self,
        p: &ValidatedPipeline,
        scenes: &[PathBuf],
        spec: ShardSpec,
        dir: &Path,
        t0: Instant,
    ) -> Result<ShardSummary, ShardError> {
        let manifest = Manifest {
            format: FORMAT,
            job: self.job,
            voltab_version: env!("CARGO_PKG_VERSION").into(),
            pipeline: p.path().to_path_buf(),
            scenes: scenes.to_vec(),
            pipeline_key: self.key,
            shard: spec,
            units: self.units.iter().map(|u| u.name.clone()).collect(),
            parts: self.parts,
        };
        let json = serde_json::to_vec_pretty(&manifest).unwrap_or_default();
        write_atomic(&dir.join(MANIFEST), &json)?;
        Ok(ShardSummary {
            shard: spec,
            units_total: self.units.len(),
            computed: self.computed,
            reused: self.reused,
            total_ms: t0.elapsed().as_secs_f64() * 1e3,
            dir: dir.to_path_buf(),
        })
    }
}

/// Reads a shard folder's manifest (without checking it against a pipeline).
pub fn read_manifest(dir: &Path) -> Result<Manifest, ShardError> {
    let shard_err = |message: String, help: &str| ShardError::Shard { path: dir.into(), message, help: help.into() };
    if !dir.is_dir() {
        return Err(shard_err(
            "no such shard folder".into(),
            "give the folders the shard tasks wrote (--out of `voltab compile --shard`)",
        ));
    }
    let path = dir.join(MANIFEST);
    let bytes = match crate::cache::bounded::read_regular(&path, 64 << 20) {
        Ok(b) => b,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
            return Err(shard_err(
                format!("no {MANIFEST}: this shard's task did not finish"),
                "rerun its task (`voltab compile|run <pipeline> --shard I/N --out <this folder>`, or resubmit the Slurm array task): finished units are reused",
            ));
        }
        Err(e) => return Err(shard_err(format!("cannot read {MANIFEST}: {e}"), "check the folder's permissions")),
    };
    serde_json::from_slice::<Manifest>(&bytes).map_err(|e| {
        shard_err(
            format!("{MANIFEST} is not a voltab shard manifest: {e}"),
            "rerun this shard's task into an empty folder",
        )
    })
}

/// What [`merge`] did.
#[derive(Debug, Clone, Serialize)]
pub struct MergeSummary {
    /// Per table, in pipeline order.
    pub tables: Vec<TableResult>,
    /// Shards merged.
    pub shards: usize,
    /// Wall time of checking the shards \[ms\].
    pub check_ms: f64,
    /// Wall time of assembling, checking and encoding split tables and publishing \[ms\].
    pub publish_ms: f64,
}

/// Merges the shard folders `dirs` of compiling `p` into `out`: checks every shard first (format and
/// voltab version, pipeline key, one folder per shard index, every unit present once, every part's
/// digest), then publishes each table atomically through the output folder's cache.
pub fn merge(p: &ValidatedPipeline, dirs: &[PathBuf], out_dir: &Path) -> Result<MergeSummary, ShardError> {
    let t0 = Instant::now();
    let units = compile_units(p);
    let checked = check_shards(Job::Compile, &pipeline_key(p), &units, dirs)?;
    let read_part = |u: &Unit| checked.read(u);
    let check_ms = t0.elapsed().as_secs_f64() * 1e3;
    let t1 = Instant::now();
    let out = OutputDir::open(out_dir, || {
        eprintln!("waiting for another voltab run that is using {}", out_dir.display());
    })?;
    let mut results = Vec::new();
    for (ti, t) in p.tables().iter().enumerate() {
        let idx: Vec<usize> = (0..units.len()).filter(|&i| units[i].table == ti).collect();
        let status = if out.is_up_to_date(t.id(), t.key()) {
            Status::UpToDate
        } else {
            let (vtab, sidecar) = if let [i] = idx[..]
                && units[i].part.is_none()
            {
                match read_part(&units[i])? {
                    Payload::Table { vtab, sidecar } => (vtab, sidecar),
                    Payload::Unit { .. } | Payload::Texels { .. } => return Err(mismatch(t)),
                }
            } else {
                let mut parts = Vec::with_capacity(idx.len());
                let (mut generate_ms, mut check_ms) = (0.0, 0.0);
                for &i in &idx {
                    match read_part(&units[i])? {
                        Payload::Unit { part, ms } => {
                            *(if part.is_check() { &mut check_ms } else { &mut generate_ms }) += ms;
                            UnitPart::absorb(&mut parts, part);
                        }
                        Payload::Table { .. } | Payload::Texels { .. } => return Err(mismatch(t)),
                    }
                }
                assemble_table(t, parts, generate_ms, check_ms)?
            };
            out.store(t.id(), t.key(), &vtab, &sidecar)?;
            Status::Compiled
        };
        let sidecar = std::fs::read(out.sidecar_path(t.id()))
            .ok()
            .and_then(|b| serde_json::from_slice::<Sidecar>(&b).ok())
            .ok_or_else(|| CacheError::Io {
                path: out.sidecar_path(t.id()),
                source: std::io::Error::other("sidecar missing after publishing"),
            })?;
        results.push(TableResult { id: t.id().into(), status, path: out.table_path(t.id()), sidecar });
    }
    Ok(MergeSummary { tables: results, shards: checked.shards, check_ms, publish_ms: t1.elapsed().as_secs_f64() * 1e3 })
}

/// Shard folders checked against a job: every unit's part located, read and its digest verified.
struct Checked {
    shards: usize,
    have: BTreeMap<String, (PathBuf, PartEntry)>,
}

impl Checked {
    /// Reads and decodes unit `u`'s part (its digest checked again: the file may have changed).
    fn read(&self, u: &Unit) -> Result<Payload, ShardError> {
        let Some((d, e)) = self.have.get(u.name.as_str()) else {
            return Err(ShardError::Coverage {
                message: format!("no shard holds unit {}", u.name),
                help: "rerun the shard tasks and give all their folders to the merge".into(),
            });
        };
        let bad = |message: String| ShardError::Shard {
            path: d.clone(),
            message: format!("unit {}: {}: {message}", u.name, e.file),
            help: "rerun this shard's task (a corrupt part is recomputed)".into(),
        };
        if e.file.contains('/') || e.file.contains('\\') || e.file.starts_with('.') {
            return Err(bad("not a file name inside the shard folder".into()));
        }
        let bytes =
            crate::cache::bounded::read_regular(&d.join(&e.file), e.bytes).map_err(|err| bad(err.to_string()))?;
        if blake3::hash(&bytes).to_hex().as_str() != e.blake3 {
            return Err(bad("its blake3 does not match the manifest (corrupt)".into()));
        }
        decode_part(&bytes).map_err(bad)
    }
}

/// Checks the shard folders `dirs` of a `job` with content key `key` and work units `units`:
/// format and voltab version, job, key, one folder per shard index, every unit present once, every
/// part's digest. Nothing is published before this passes.
fn check_shards(job: Job, key: &str, units: &[Unit], dirs: &[PathBuf]) -> Result<Checked, ShardError> {
    if dirs.is_empty() {
        return Err(ShardError::Coverage {
            message: "no shard folders given".into(),
            help: "voltab merge SHARD_DIR… --out DIR".into(),
        });
    }
    let names: Vec<String> = units.iter().map(|u| u.name.clone()).collect();
    let mut manifests = Vec::with_capacity(dirs.len());
    for d in dirs {
        let m = read_manifest(d)?;
        let shard_err = |message: String, help: &str| ShardError::Shard { path: d.clone(), message, help: help.into() };
        if m.format != FORMAT || m.voltab_version != env!("CARGO_PKG_VERSION") {
            return Err(shard_err(
                format!(
                    "written by voltab {} (format {}); this is voltab {} (format {FORMAT})",
                    m.voltab_version,
                    m.format,
                    env!("CARGO_PKG_VERSION")
                ),
                "rerun the shard tasks with the same voltab as the merge",
            ));
        }
        if m.job != job {
            let what = |j: Job| match j {
                Job::Compile => "compile shards (`voltab compile --shard`)",
                Job::Bake => "bake shards (`voltab run --shard`)",
            };
            return Err(shard_err(
                format!("one of the {}, but the merge's first folder is one of the {}", what(m.job), what(job)),
                "merge the compile shards into the output folder first, then the bake shards in a second `voltab merge`",
            ));
        }
        if m.pipeline_key != key || m.units != names {
            return Err(shard_err(
                format!(
                    "stale: computed for another version of the pipeline or its generators (shard key {}…, this pipeline {}…)",
                    &m.pipeline_key[..m.pipeline_key.len().min(12)],
                    &key[..12]
                ),
                "rerun the shard tasks for this pipeline (a Slurm resubmission reruns only what changed)",
            ));
        }
        manifests.push((d.clone(), m));
    }
    let count = manifests[0].1.shard.count;
    let mut by_index: BTreeMap<u32, &PathBuf> = BTreeMap::new();
    for (d, m) in &manifests {
        if m.shard.count != count {
            return Err(ShardError::Shard {
                path: d.clone(),
                message: format!("shard {} is of a {}-way split, the others of {count}", m.shard, m.shard.count),
                help: "merge the shards of one job".into(),
            });
        }
        if let Some(other) = by_index.insert(m.shard.index, d) {
            return Err(ShardError::Shard {
                path: d.clone(),
                message: format!("duplicate: {} is shard {} too", other.display(), m.shard),
                help: "give each shard folder once".into(),
            });
        }
    }
    let owner = assign(units, count);
    let mut have: BTreeMap<String, (PathBuf, PartEntry)> = BTreeMap::new();
    for (d, m) in &manifests {
        for e in &m.parts {
            have.insert(e.unit.clone(), (d.clone(), e.clone()));
        }
    }
    let mut lacking: BTreeMap<u32, Vec<&str>> = BTreeMap::new();
    for (u, s) in units.iter().zip(&owner) {
        if !have.contains_key(u.name.as_str()) {
            lacking.entry(*s).or_default().push(&u.name);
        }
    }
    if !lacking.is_empty() {
        let lines: Vec<String> = lacking
            .iter()
            .map(|(s, us)| {
                let state = if by_index.contains_key(s) { "holds an incomplete unit list" } else { "is missing" };
                format!("shard {s}/{count} {state}; it lacks: {}", us.join(", "))
            })
            .collect();
        return Err(ShardError::Coverage {
            message: lines.join("\n"),
            help: "rerun those shards' tasks (`--shard I/N`) and give their folders to the merge".into(),
        });
    }
    // Every part read and checked before anything is published (one at a time: parts can be large).
    let checked = Checked { shards: manifests.len(), have };
    for u in units {
        checked.read(u)?;
    }
    Ok(checked)
}

fn mismatch(t: &ValidatedTable) -> ShardError {
    ShardError::Coverage {
        message: format!("table \"{}\": the shards' parts do not match its work units", t.id()),
        help: "rerun the shard tasks with the same voltab as the merge".into(),
    }
}

/// A split table from its units: assembled, judged and encoded by the code `voltab compile` runs.
fn assemble_table(
    t: &ValidatedTable,
    parts: Vec<UnitPart>,
    generate_ms: f64,
    check_ms: f64,
) -> Result<(Vec<u8>, Vec<u8>), ShardError> {
    let fail = |source: GenerateError| CompileError::Generate { id: t.id().into(), source };
    let a = t.def().kind_impl().assemble(t.key(), parts).map_err(fail)?;
    let (bytes, mut sidecar) = crate::compile::encode_with_sidecar(t, &a.generated)?;
    sidecar.generate_ms = generate_ms;
    sidecar.check_ms = check_ms + a.check_ms;
    let json = serde_json::to_vec_pretty(&sidecar).unwrap_or_default();
    Ok((bytes, json))
}
