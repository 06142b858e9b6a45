//! `voltab slurm`: a sharded compile as a Slurm job array plus a merge job that depends on it, and
//! for pipelines with lightmap bakes a second array of bake tiles plus its merge.
//!
//! Input: a pipeline, the shard count N, an output folder on storage every node sees, and optional
//! partition / time limit. Output: `<out>/slurm/compile.sbatch` (an array `0..N-1`, each task
//! `voltab compile --shard auto` into `<out>/shards/compile-<i>`), `<out>/slurm/merge.sbatch`
//! (`voltab merge` of those folders into `<out>`), and when the pipeline bakes lightmaps
//! `bake.sbatch` (each task `voltab run --shard auto --tables <out>` into `<out>/shards/bake-<i>`)
//! and `merge-bake.sbatch` (`voltab merge` of the bake shards: runs every stage into `<out>`). With
//! `submit` the jobs are submitted with `sbatch --parsable`, each held by `--dependency=afterok` on
//! the one before. A resubmission submits only the tasks whose shard folder has no finished manifest
//! for this pipeline (a task killed mid-way reuses its finished units) and cancels the still-pending
//! downstream jobs of the earlier submission (their dependency failed), so only missing work is redone.

use std::path::{Path, PathBuf};
use std::process::Command;

use super::{Job, MANIFEST, ShardError, ShardSpec, pipeline_key, read_manifest};
use crate::registry::ValidatedPipeline;
use crate::stages::{StageContext, StageDef};

/// What to write.
#[derive(Debug, Clone)]
pub struct SlurmOptions {
    /// Number of array tasks.
    pub shards: u32,
    /// `#SBATCH --partition`.
    pub partition: Option<String>,
    /// `#SBATCH --time`.
    pub time: Option<String>,
    /// The shared output folder.
    pub out: PathBuf,
    /// Scenes the pipeline is planned for (`--scene`).
    pub scenes: Vec<PathBuf>,
    /// CPUs per task (`#SBATCH --cpus-per-task`), if set.
    pub cpus_per_task: Option<u32>,
}

/// The scripts written and, when submitted, the job ids.
#[derive(Debug, Clone, serde::Serialize)]
pub struct SlurmJob {
    /// The table compile: its array and the merge of its shards into the output folder.
    pub compile: Phase,
    /// The lightmap bakes' tiles and their merge (which runs the stages), when the pipeline bakes.
    pub bake: Option<Phase>,
    /// Pending jobs of an earlier submission, cancelled (a job they depended on had failed).
    pub cancelled: Vec<String>,
}

/// One job array and the merge of its shards.
#[derive(Debug, Clone, serde::Serialize)]
pub struct Phase {
    /// The array script.
    pub array_script: PathBuf,
    /// The merge script.
    pub merge_script: PathBuf,
    /// Shard indices still to compute (all of them on a first submission).
    pub pending: Vec<u32>,
    /// Job id of the array (None when nothing was pending or not submitted).
    pub array_job: Option<String>,
    /// Job id of the merge.
    pub merge_job: Option<String>,
}

fn quote(p: &Path) -> String {
    let s = p.display().to_string();
    format!("'{}'", s.replace('\'', r"'\''"))
}

fn absolute(p: &Path) -> PathBuf {
    std::path::absolute(p).unwrap_or_else(|_| p.to_path_buf())
}

/// The compile shard folder of task `i`.
pub fn shard_dir(out: &Path, i: u32) -> PathBuf {
    job_dir(out, Job::Compile, i)
}

/// The shard folder of task `i` of `job`.
pub fn job_dir(out: &Path, job: Job, i: u32) -> PathBuf {
    let name = match job {
        Job::Compile => "compile",
        Job::Bake => "bake",
    };
    out.join("shards").join(format!("{name}-{i}"))
}

/// Indices whose compile shard folder holds no finished manifest of this pipeline.
pub fn pending_shards(p: &ValidatedPipeline, out: &Path, shards: u32) -> Vec<u32> {
    pending_of(out, Job::Compile, &pipeline_key(p), shards)
}

fn pending_of(out: &Path, job: Job, key: &str, shards: u32) -> Vec<u32> {
    (0..shards)
        .filter(|&i| {
            let d = job_dir(out, job, i);
            !(d.join(MANIFEST).is_file()
                && read_manifest(&d).is_ok_and(|m| {
                    m.job == job && m.pipeline_key == key && m.shard == ShardSpec { index: i, count: shards }
                }))
        })
        .collect()
}

/// Writes the two scripts (and the log folder) for `p`, and with `submit` submits them.
pub fn write_and_submit(
    p: &ValidatedPipeline,
    voltab: &Path,
    opts: &SlurmOptions,
    submit: bool,
) -> Result<SlurmJob, ShardError> {
    let err = |message: String, help: &str| ShardError::Spec { message, help: help.into() };
    if opts.shards == 0 || opts.shards > 1_000_000 {
        return Err(err(format!("--shards {}", opts.shards), "use 1 … 1000000 shards"));
    }
    let out = absolute(&opts.out);
    let dir = out.join("slurm");
    let logs = dir.join("logs");
    std::fs::create_dir_all(&logs).map_err(|e| {
        err(format!("cannot create {}: {e}", logs.display()), "choose a writable --out on shared storage")
    })?;
    let voltab = absolute(voltab);
    let pipeline = absolute(p.path());
    let scenes: String = if opts.scenes.is_empty() {
        String::new()
    } else {
        format!(" --scene {}", opts.scenes.iter().map(|s| quote(&absolute(s))).collect::<Vec<_>>().join(" "))
    };
    let mut head = String::new();
    if let Some(part) = &opts.partition {
        head.push_str(&format!("#SBATCH --partition={part}\n"));
    }
    if let Some(t) = &opts.time {
        head.push_str(&format!("#SBATCH --time={t}\n"));
    }
    if let Some(c) = opts.cpus_per_task {
        head.push_str(&format!("#SBATCH --cpus-per-task={c}\n"));
    }
    let n = opts.shards;
    let array_script = dir.join("compile.sbatch");
    let array = format!(
        "#!/bin/bash\n\
         # Written by `voltab slurm`: shard $SLURM_ARRAY_TASK_ID of {n} of compiling {pipeline}.\n\
         # Submit with: sbatch --array=0-{last} {script}\n\
         #SBATCH --job-name=voltab-compile\n\
         #SBATCH --output={logs}/compile-%a.log\n\
         {head}\
         set -euo pipefail\n\
         export VOLTAB_SHARD_COUNT={n}\n\
         exec {voltab} compile {pipe}{scenes} --shard auto --out {out_q}/shards/compile-\"$SLURM_ARRAY_TASK_ID\"\n",
        pipeline = pipeline.display(),
        last = n - 1,
        script = array_script.display(),
        logs = logs.display(),
        voltab = quote(&voltab),
        pipe = quote(&pipeline),
        out_q = quote(&out),
    );
    let merge_script = dir.join("merge.sbatch");
    let merge = merge_job_script(Job::Compile, n, &out, &logs, &head, &voltab);
    let write = |path: &Path, text: &str| -> Result<(), ShardError> {
        crate::cache::write_atomic(path, text.as_bytes())?;
        #[cfg(unix)]
        {
            use std::os::unix::fs::PermissionsExt;
            let _ = std::fs::set_permissions(path, std::fs::Permissions::from_mode(0o755));
        }
        Ok(())
    };
    write(&array_script, &array)?;
    write(&merge_script, &merge)?;
    let pending = pending_shards(p, &out, n);
    // The bake phase: tiles of the pipeline's lightmap bakes, read from the merged tables.
    let bake = if p.stages().iter().any(|s| matches!(s.def(), StageDef::BakeLightmaps(_))) {
        let base = p.path().parent().map(Path::to_path_buf).unwrap_or_default();
        let device = crate::render::gpu::Device::Cpu;
        let scene_cache = crate::scene::cache::SceneCache::default();
        let ctx =
            StageContext { out_dir: &out, base_dir: &base, progress: false, device: &device, scenes: &scene_cache };
        let (_, key) = super::bake::bake_units(p, &ctx)?;
        let bake_script = dir.join("bake.sbatch");
        let bake_array = format!(
            "#!/bin/bash\n\
             # Written by `voltab slurm`: bake shard $SLURM_ARRAY_TASK_ID of {n} of {pipeline}'s lightmaps,\n\
             # after the tables are merged into {out}.\n\
             #SBATCH --job-name=voltab-bake\n\
             #SBATCH --output={logs}/bake-%a.log\n\
             {head}\
             set -euo pipefail\n\
             export VOLTAB_SHARD_COUNT={n}\n\
             exec {voltab} run {pipe}{scenes} --shard auto --tables {out_q} --out {out_q}/shards/bake-\"$SLURM_ARRAY_TASK_ID\"\n",
            pipeline = pipeline.display(),
            out = out.display(),
            logs = logs.display(),
            voltab = quote(&voltab),
            pipe = quote(&pipeline),
            out_q = quote(&out),
        );
        let merge_bake_script = dir.join("merge-bake.sbatch");
        let merge_bake = merge_job_script(Job::Bake, n, &out, &logs, &head, &voltab);
        write(&bake_script, &bake_array)?;
        write(&merge_bake_script, &merge_bake)?;
        Some(Phase {
            array_script: bake_script,
            merge_script: merge_bake_script,
            pending: pending_of(&out, Job::Bake, &key, n),
            array_job: None,
            merge_job: None,
        })
    } else {
        None
    };
    let mut job = SlurmJob {
        compile: Phase { array_script, merge_script, pending: pending.clone(), array_job: None, merge_job: None },
        bake,
        cancelled: Vec::new(),
    };
    if !submit {
        return Ok(job);
    }
    // Jobs left pending by an earlier submission wait forever on a failed dependency (afterok can no
    // longer be satisfied): cancel them while they are still pending, and submit new ones.
    let jobids_file = dir.join("jobs.pending");
    let earlier = std::fs::read_to_string(&jobids_file)
        .or_else(|_| std::fs::read_to_string(dir.join("merge.jobid")))
        .unwrap_or_default();
    for old in earlier.split_whitespace().filter(|id| id.chars().all(|c| c.is_ascii_digit())) {
        let pending = Command::new("squeue")
            .args(["-h", "-t", "PENDING", "-o", "%i", "-j", old])
            .output()
            .is_ok_and(|o| o.status.success() && !String::from_utf8_lossy(&o.stdout).trim().is_empty());
        if pending {
            let _ = Command::new("scancel").arg(old).status();
            job.cancelled.push(old.to_string());
        }
    }
    let after =
        |id: &Option<String>| -> Vec<String> { id.iter().map(|id| format!("--dependency=afterok:{id}")).collect() };
    let array_list =
        |pending: &[u32]| format!("--array={}", pending.iter().map(u32::to_string).collect::<Vec<_>>().join(","));
    let array_job =
        if pending.is_empty() { None } else { Some(sbatch(&[array_list(&pending)], &job.compile.array_script)?) };
    let merge_job = sbatch(&after(&array_job), &job.compile.merge_script)?;
    let mut downstream = vec![merge_job.clone()];
    if let Some(b) = job.bake.as_mut() {
        let merge = Some(merge_job.clone());
        let bake_array = if b.pending.is_empty() {
            None
        } else {
            let mut args = after(&merge);
            args.push(array_list(&b.pending));
            Some(sbatch(&args, &b.array_script)?)
        };
        let bake_merge = sbatch(&after(if bake_array.is_some() { &bake_array } else { &merge }), &b.merge_script)?;
        downstream.extend(bake_array.iter().cloned());
        downstream.push(bake_merge.clone());
        b.array_job = bake_array;
        b.merge_job = Some(bake_merge);
    }
    crate::cache::write_atomic(&jobids_file, format!("{}\n", downstream.join(" ")).as_bytes())?;
    job.compile.merge_job = Some(merge_job);
    job.compile.array_job = array_job;
    Ok(job)
}

/// The merge job of `job`'s `n` shards into `out`.
fn merge_job_script(job: Job, n: u32, out: &Path, logs: &Path, head: &str, voltab: &Path) -> String {
    let (what, name) = match job {
        Job::Compile => ("merges the {n} shards", "merge"),
        Job::Bake => ("merges the {n} bake shards and runs the stages", "merge-bake"),
    };
    let shards: Vec<String> = (0..n).map(|i| quote(&job_dir(out, job, i))).collect();
    format!(
        "#!/bin/bash\n\
         # Written by `voltab slurm`: {what} into {out}.\n\
         #SBATCH --job-name=voltab-{name}\n\
         #SBATCH --output={logs}/{name}.log\n\
         {head}\
         set -euo pipefail\n\
         exec {voltab} merge {shards} --out {out_q}\n",
        what = what.replace("{n}", &n.to_string()),
        out = out.display(),
        logs = logs.display(),
        voltab = quote(voltab),
        shards = shards.join(" "),
        out_q = quote(out),
    )
}

/// `sbatch --parsable ARGS SCRIPT` → the job id.
fn sbatch(args: &[String], script: &Path) -> Result<String, ShardError> {
    let output =
        Command::new("sbatch").arg("--parsable").args(args).arg(script).output().map_err(|e| ShardError::Spec {
            message: format!("cannot run sbatch: {e}"),
            help: "run on a Slurm submit host (sbatch on PATH), or submit the scripts by hand".into(),
        })?;
    if !output.status.success() {
        return Err(ShardError::Spec {
            message: format!("sbatch {} failed: {}", script.display(), String::from_utf8_lossy(&output.stderr).trim()),
            help: "check the partition and time limit (--partition, --time) and that slurmctld is up (sinfo)".into(),
        });
    }
    let text = String::from_utf8_lossy(&output.stdout);
    // --parsable prints "<id>" or "<id>;<cluster>".
    let id = text.trim().split(';').next().unwrap_or("").to_string();
    if id.is_empty() || !id.chars().all(|c| c.is_ascii_digit() || c == '_') {
        return Err(ShardError::Spec {
            message: format!("sbatch printed no job id: {text:?}"),
            help: "check the Slurm installation (sbatch --parsable)".into(),
        });
    }
    Ok(id)
}
