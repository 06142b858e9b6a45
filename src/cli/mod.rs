//! The `voltab` binary's commands: a parsed [`args::Command`] → library calls, printed results and an
//! exit code. The only place that uses `anyhow`; the library returns typed errors. `voltab` with no
//! arguments runs `pipelines/default.ron` into `out/`, pruned to what the bundled scenes
//! (`scenes/*.gltf`) need when run from a checkout.
//!
//! One file per group of commands: [`build`] (run, compile, merge, slurm), [`tables`] (check, plan,
//! scene, inspect, verify, diff, eval, schema), [`measure`] (report, bench, stability, validate,
//! export); the helpers they share (loading and planning a pipeline, the stages' device) live here.

pub mod args;
mod build;
mod measure;
mod tables;

use std::io::IsTerminal;
use std::path::{Path, PathBuf};
use std::process::ExitCode;

use anyhow::{Context, Result, bail};

use args::*;
use voltab::compile::{CompileOptions, compile, summary_line};
use voltab::container::{self, VtabReader};
use voltab::pipeline::{self, Disk, Embedded, Sources, StageKind};
use voltab::registry::ValidatedPipeline;
use voltab::scene::cache::SceneCache;

/// Runs a command (`None`: the main job, the default pipeline on the bundled scenes).
pub fn dispatch(cmd: Option<Command>) -> Result<ExitCode> {
    let cmd = cmd.unwrap_or_else(|| {
        Command::Run(RunArgs {
            pipeline: "pipelines/default.ron".into(),
            out: "out".into(),
            jobs: None,
            json: false,
            scene: bundled_scenes(),
            device: voltab::render::gpu::DeviceRequest::Auto,
            shard: None,
            tables: None,
        })
    });
    match cmd {
        Command::Run(a) => build::run(a),
        Command::Compile(a) => build::compile(a),
        Command::Merge(a) => build::merge(a),
        Command::Slurm(a) => build::slurm(a),
        Command::Scene(a) => tables::scene(a),
        Command::Plan(a) => tables::plan(a),
        Command::Check(a) => tables::check(a),
        Command::Inspect(a) => tables::inspect(&a.file, a.chunks).map(|()| ExitCode::SUCCESS),
        Command::Verify(a) => tables::verify(a),
        Command::Diff(a) => tables::diff(a),
        Command::Eval { what: EvalCommand::Zh(a) } => tables::eval_zh(&a).map(|()| ExitCode::SUCCESS),
        Command::Eval { what: EvalCommand::Lobes(a) } => tables::eval_lobes(&a).map(|()| ExitCode::SUCCESS),
        Command::Schema(a) => tables::schema(a),
        Command::Report(a) => measure::report(a),
        Command::Bench(a) => measure::bench(a),
        Command::Stability(a) => measure::stability(a),
        Command::Validate(a) => {
            let progress = progress();
            measure::validate(&a.pipeline, &a.stages, a.quality, &a.out, &a.tables, progress)
                .map(|()| ExitCode::SUCCESS)
        }
        Command::Export { what } => measure::export(what),
    }
}

/// Whether to show progress: on a terminal only.
fn progress() -> bool {
    std::io::stderr().is_terminal()
}

pub(super) fn load(path: &Path) -> Result<ValidatedPipeline> {
    let sources: &dyn Sources = if !path.exists()
        && pipeline::parse::EMBEDDED.iter().any(|(p, _)| Path::new(p) == pipeline::parse::normalize(path))
    {
        eprintln!("note: {} not found here; using the copy built into voltab", path.display());
        &Embedded
    } else {
        &Disk
    };
    // Diagnostics are complete messages; print them as they are.
    voltab::registry::load_and_validate(path, sources).map_err(|e| anyhow::anyhow!("{e}"))
}

/// The bundled scenes (`scenes/*.gltf`, sorted) when run from a checkout: the main job compiles what they
/// need. Outside a checkout there are none and the whole default pipeline is compiled.
pub(super) fn bundled_scenes() -> Vec<PathBuf> {
    let mut v: Vec<PathBuf> = std::fs::read_dir("scenes")
        .map(|d| d.flatten().map(|e| e.path()).filter(|p| p.extension().is_some_and(|e| e == "gltf")).collect())
        .unwrap_or_default();
    v.sort();
    if !v.is_empty() {
        let names: Vec<String> = v.iter().map(|p| p.display().to_string()).collect();
        eprintln!("note: compiling what the bundled scenes need: {}", names.join(", "));
    }
    v
}

/// For stage ladders and benchmarks: the pipeline planned for the scenes its stages read, with those tables
/// compiled into `tables` (cached); `None` when no stage reads a scene.
pub(super) fn compiled_for_stages(
    pipeline: &Path,
    tables: &Path,
    progress: bool,
    cache: &SceneCache,
) -> Result<Option<ValidatedPipeline>> {
    let p = load(pipeline)?;
    let scenes: Vec<PathBuf> = p.stages().iter().flat_map(|s| s.def().stage().scenes(&base_dir(&p))).collect();
    if scenes.is_empty() {
        return Ok(None);
    }
    let p = planned(p, &scenes, true, cache)?;
    compile(&p, &CompileOptions { out_dir: tables.to_path_buf(), only: Vec::new(), jobs: None, progress })?;
    Ok(Some(p))
}

/// Where the stages of `p` run: the device is opened only when a stage can use it, and the choice
/// is said once.
pub(super) fn stage_device(
    p: &ValidatedPipeline,
    request: voltab::render::gpu::DeviceRequest,
) -> Result<voltab::render::gpu::Device> {
    if p.stages().iter().any(|s| s.def().stage().uses_device()) {
        let (d, message) = voltab::render::gpu::select(request).map_err(|e| anyhow::anyhow!(e))?;
        eprintln!("{message}");
        Ok(d)
    } else {
        Ok(voltab::render::gpu::Device::Cpu)
    }
}

/// The folder relative stage paths resolve against: the pipeline file's.
pub(super) fn base_dir(p: &ValidatedPipeline) -> PathBuf {
    p.path().parent().map(Path::to_path_buf).unwrap_or_default()
}

/// Whether two paths name the same file (by canonical path when both exist).
pub(super) fn same_file(a: &Path, b: &Path) -> bool {
    match (a.canonicalize(), b.canonicalize()) {
        (Ok(x), Ok(y)) => x == y,
        _ => a == b,
    }
}

/// Imports a scene; its warnings go to stderr.
pub(super) fn load_scene(path: &Path) -> Result<voltab::scene::Scene> {
    // Scene errors are complete messages (file, node/prim, fix).
    voltab::scene::Scene::load(path).map_err(|e| anyhow::anyhow!("{e}"))
}

/// The pipeline pruned to what `scenes` need (unchanged when there are none); the plan goes to stderr.
///
/// The scenes that stages read (a bake's scene) are planned for too, so the tables they need are kept.
pub(super) fn planned(
    p: ValidatedPipeline,
    scenes: &[PathBuf],
    quiet: bool,
    cache: &SceneCache,
) -> Result<ValidatedPipeline> {
    if scenes.is_empty() {
        return Ok(p);
    }
    let mut scenes = scenes.to_vec();
    for s in p.stages() {
        for f in s.def().stage().scenes(&base_dir(&p)) {
            // The built-in default pipeline outside a checkout names scenes that are not here.
            let embedded_elsewhere = !f.exists() && !p.path().exists();
            if !embedded_elsewhere && !scenes.iter().any(|g| same_file(g, &f)) {
                scenes.push(f);
            }
        }
    }
    // Imported into the run's cache: the stages that read these scenes do not import them again.
    let loaded =
        scenes.iter().map(|f| cache.load(f).map_err(|e| anyhow::anyhow!("{e}"))).collect::<Result<Vec<_>>>()?;
    for s in &loaded {
        for w in &s.warnings {
            eprintln!("warning: {}: {}: {}\n  help: {}", s.source.display(), w.location, w.message, w.help);
        }
    }
    let plan = voltab::plan::Plan::new(&p, &loaded);
    if !quiet {
        eprint!("{}", plan.text());
    }
    if plan.has_missing() {
        eprintln!("warning: the scenes need slices this pipeline does not declare (MISSING above)");
    }
    plan.pruned_pipeline(&p, &pipeline::Limits::from_machine())
        .map_err(|e| anyhow::anyhow!("{}: {e}", p.path().display()))
}
