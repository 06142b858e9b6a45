//! Building: `voltab run | compile | merge | slurm` → compiled tables and stage outputs, on one machine
//! or as shards of a farm job (issue 38) and their merge.

use super::*;

/// `voltab run`: compiles the pipeline's tables, then runs its stages; with `--shard`, computes one
/// shard of the lightmap bakes' tiles from tables compiled into `--tables`.
pub fn run(a: RunArgs) -> Result<ExitCode> {
    let RunArgs { pipeline, out, jobs, json, scene, device, shard, tables } = a;
    let progress = progress();
    let cache = SceneCache::default();
    if let (Some(shard), Some(tables)) = (shard, tables) {
        let spec = voltab::shard::ShardSpec::parse(&shard, &|k| std::env::var(k).ok())?;
        let p = planned(load(&pipeline)?, &scene, true, &cache)?;
        let base = base_dir(&p);
        let cpu_device = voltab::render::gpu::Device::Cpu;
        let ctx = voltab::stages::StageContext {
            out_dir: &tables,
            base_dir: &base,
            progress,
            device: &cpu_device,
            scenes: &cache,
        };
        let run = || voltab::shard::bake::bake_shard(&p, &scene, spec, &ctx, &out);
        let s = match jobs {
            Some(j) => rayon::ThreadPoolBuilder::new().num_threads(j).build()?.install(run)?,
            None => run()?,
        };
        print_shard("bake shard", "tiles", &s, json)?;
        return Ok(ExitCode::SUCCESS);
    }
    let p = planned(load(&pipeline)?, &scene, json, &cache)?;
    let summary =
        voltab::compile::compile(&p, &CompileOptions { out_dir: out.clone(), only: Vec::new(), jobs, progress })?;
    let mut stage_results = Vec::new();
    let base = base_dir(&p);
    let device = stage_device(&p, device)?;
    let ctx =
        voltab::stages::StageContext { out_dir: &out, base_dir: &base, progress, device: &device, scenes: &cache };
    for s in p.stages() {
        let missing: Vec<PathBuf> = s.def().stage().scenes(&base).into_iter().filter(|f| !f.exists()).collect();
        if !missing.is_empty() && !pipeline.exists() {
            // The built-in default pipeline outside a checkout: its bundled scenes are not here.
            eprintln!(
                "note: stage {} skipped: {} not found (run from a voltab checkout)",
                s.id(),
                missing[0].display()
            );
            continue;
        }
        stage_results.push((s.id().to_owned(), s.def().stage().run(s.id(), &ctx)?));
    }
    if json {
        println!(
            "{}",
            serde_json::to_string_pretty(&serde_json::json!({ "compile": summary, "stages": stage_results }))?
        );
    } else {
        for t in &summary.tables {
            println!("{}", summary_line(t));
        }
        for (id, r) in &stage_results {
            println!("stage      {id:<20} {}", r.summary);
        }
        println!(
            "{} tables, {} stages in {:.0} ms → {}",
            summary.tables.len(),
            stage_results.len(),
            summary.total_ms,
            out.display()
        );
    }
    Ok(ExitCode::SUCCESS)
}

/// `voltab compile`: compiles the pipeline's tables (incrementally); with `--shard`, one shard of its
/// work units into a shard folder.
pub fn compile(a: CompileArgs) -> Result<ExitCode> {
    let CompileArgs { pipeline, out, only, jobs, json, scene, shard } = a;
    let progress = progress();
    let cache = SceneCache::default();
    if let Some(shard) = shard {
        if !only.is_empty() {
            anyhow::bail!(
                "--only and --shard cannot be combined\n  = help: a sharded compile covers the whole pipeline; drop --only"
            );
        }
        let spec = voltab::shard::ShardSpec::parse(&shard, &|k| std::env::var(k).ok())?;
        let p = planned(load(&pipeline)?, &scene, true, &cache)?;
        let s = voltab::shard::compile_shard(&p, &scene, spec, &out, jobs, progress)?;
        print_shard("shard", "units", &s, json)?;
        return Ok(ExitCode::SUCCESS);
    }
    let p = planned(load(&pipeline)?, &scene, json, &cache)?;
    let summary = voltab::compile::compile(&p, &CompileOptions { out_dir: out.clone(), only, jobs, progress })?;
    if json {
        println!("{}", serde_json::to_string_pretty(&summary)?);
    } else {
        if summary.stale_removed > 0 {
            println!("removed {} temporary files left by an interrupted run", summary.stale_removed);
        }
        for t in &summary.tables {
            println!("{}", summary_line(t));
        }
        println!("{} tables in {:.0} ms → {}", summary.tables.len(), summary.total_ms, out.display());
    }
    Ok(ExitCode::SUCCESS)
}

/// `voltab merge`: the shard folders of a sharded compile (or bake) → the same bytes as one machine's.
pub fn merge(a: MergeArgs) -> Result<ExitCode> {
    let progress = progress();
    let cache = SceneCache::default();
    let MergeArgs { shards, out, pipeline, json, device } = a;
    let first = voltab::shard::read_manifest(&shards[0])?;
    let path = pipeline.unwrap_or_else(|| first.pipeline.clone());
    let p = planned(load(&path)?, &first.scenes, true, &cache)?;
    if first.job == voltab::shard::Job::Bake {
        let base = base_dir(&p);
        let device = stage_device(&p, device)?;
        let ctx =
            voltab::stages::StageContext { out_dir: &out, base_dir: &base, progress, device: &device, scenes: &cache };
        let results = voltab::shard::bake::merge_bake(&p, &shards, &ctx)?;
        if json {
            println!("{}", serde_json::to_string_pretty(&serde_json::json!({ "stages": results }))?);
        } else {
            for (id, r) in &results {
                println!("stage      {id:<20} {}", r.summary);
            }
            println!("{} stages from {} bake shards → {}", results.len(), shards.len(), out.display());
        }
        return Ok(ExitCode::SUCCESS);
    }
    let s = voltab::shard::merge(&p, &shards, &out)?;
    if json {
        println!("{}", serde_json::to_string_pretty(&s)?);
    } else {
        for t in &s.tables {
            println!("{}", summary_line(t));
        }
        println!(
            "{} tables from {} shards (checked in {:.0} ms, published in {:.0} ms) → {}",
            s.tables.len(),
            s.shards,
            s.check_ms,
            s.publish_ms,
            out.display()
        );
    }
    Ok(ExitCode::SUCCESS)
}

/// `voltab slurm`: writes (and with `--submit` submits) the Slurm array and merge jobs.
pub fn slurm(a: SlurmArgs) -> Result<ExitCode> {
    let SlurmArgs { pipeline, shards, partition, time, cpus_per_task, out, scene, submit } = a;
    let p = planned(load(&pipeline)?, &scene, true, &SceneCache::default())?;
    let exe = std::env::current_exe()?;
    let opts = voltab::shard::slurm::SlurmOptions { shards, partition, time, out, scenes: scene, cpus_per_task };
    let job = voltab::shard::slurm::write_and_submit(&p, &exe, &opts, submit)?;
    let phases = std::iter::once(("", &job.compile)).chain(job.bake.as_ref().map(|b| ("bake ", b)));
    for (_, ph) in phases.clone() {
        println!("wrote {} and {}", ph.array_script.display(), ph.merge_script.display());
    }
    if submit {
        for id in &job.cancelled {
            println!("cancelled the pending job {id} of the earlier submission");
        }
        for (kind, ph) in phases {
            match &ph.array_job {
                Some(id) => println!(
                    "submitted {kind}array job {id} ({} of {shards} {kind}shards pending: {:?})",
                    ph.pending.len(),
                    ph.pending
                ),
                None => println!("all {shards} {kind}shards are finished: only the {kind}merge is submitted"),
            }
            if let Some(id) = &ph.merge_job {
                println!("submitted {kind}merge job {id}");
            }
        }
    } else {
        println!(
            "submit with: jid=$(sbatch --parsable --array=0-{} {}) && mid=$(sbatch --parsable --dependency=afterok:$jid {})",
            shards.saturating_sub(1),
            job.compile.array_script.display(),
            job.compile.merge_script.display()
        );
        if let Some(b) = &job.bake {
            println!(
                "  then: bid=$(sbatch --parsable --dependency=afterok:$mid --array=0-{} {}) && sbatch --dependency=afterok:$bid {}",
                shards.saturating_sub(1),
                b.array_script.display(),
                b.merge_script.display()
            );
        }
    }
    Ok(ExitCode::SUCCESS)
}

/// What a shard task did: one line, or JSON.
fn print_shard(what: &str, units: &str, s: &voltab::shard::ShardSummary, json: bool) -> Result<()> {
    if json {
        println!("{}", serde_json::to_string_pretty(s)?);
    } else {
        println!(
            "{what} {}: {} of {} {units} computed, {} reused from an earlier attempt, in {:.0} ms → {}",
            s.shard,
            s.computed.len(),
            s.units_total,
            s.reused.len(),
            s.total_ms,
            s.dir.display()
        );
    }
    Ok(())
}
