//! The `voltab` command line. The only place that uses `anyhow`; everything else returns typed
//! errors. `voltab` with no arguments runs `pipelines/default.ron` into `out/`, pruned to what the
//! bundled scenes (`scenes/*.gltf`) need when run from a checkout.

use std::io::IsTerminal;
use std::path::{Path, PathBuf};
use std::process::ExitCode;

use anyhow::{Context, Result, bail};
use clap::{Parser, Subcommand};

use voltab::compile::{CompileOptions, compile, summary_line};
use voltab::container::{self, VtabReader};
use voltab::pipeline::{self, Disk, Embedded, Sources, ValidatedPipeline};

#[derive(Parser)]
#[command(
    name = "voltab",
    version,
    about = "Compile participating-media tables from RON pipelines and run the stages that use them."
)]
struct Cli {
    #[command(subcommand)]
    command: Option<Command>,
}

#[derive(Subcommand)]
enum Command {
    /// Compile every table a pipeline declares, then run its stages.
    Run {
        /// Pipeline file.
        pipeline: PathBuf,
        /// Output folder.
        #[arg(long, default_value = "out")]
        out: PathBuf,
        /// Worker threads (default: all cores).
        #[arg(long)]
        jobs: Option<usize>,
        /// Print the summary as JSON on stdout.
        #[arg(long)]
        json: bool,
        /// Compile only what these scenes need (glTF or USD; see `voltab plan`).
        #[arg(long, num_args = 1..)]
        scene: Vec<PathBuf>,
        /// Where the real-time effects run: auto = the GPU when this build has the `gpu` feature
        /// and an adapter is found, else the CPU (the choice and the reason are printed).
        #[arg(long, value_enum, default_value_t = voltab::render::gpu::DeviceRequest::Auto)]
        device: voltab::render::gpu::DeviceRequest,
        /// Compute only shard I of N of the lightmap bakes' texel tiles into --out (a shard folder
        /// for `voltab merge`), reading the tables from --tables; `auto` as for `compile --shard`.
        #[arg(long, requires = "tables")]
        shard: Option<String>,
        /// With --shard: the folder holding the pipeline's compiled (merged) tables.
        #[arg(long, requires = "shard")]
        tables: Option<PathBuf>,
    },
    /// Compile tables (incrementally: unchanged tables are not recomputed).
    Compile {
        /// Pipeline file.
        pipeline: PathBuf,
        /// Output folder.
        #[arg(long, default_value = "out")]
        out: PathBuf,
        /// Compile only these table ids.
        #[arg(long, num_args = 1..)]
        only: Vec<String>,
        /// Worker threads (default: all cores).
        #[arg(long)]
        jobs: Option<usize>,
        /// Print the summary as JSON on stdout.
        #[arg(long)]
        json: bool,
        /// Compile only the tables and slices these scenes need (glTF or USD; see `voltab plan`).
        #[arg(long, num_args = 1..)]
        scene: Vec<PathBuf>,
        /// Compute only shard I of N (`I/N`, 0-based) of the compile's work units into the shard folder
        /// --out; `auto` reads SLURM_ARRAY_TASK_ID (count: VOLTAB_SHARD_COUNT or SLURM_ARRAY_TASK_COUNT)
        /// or JOB_COMPLETION_INDEX (`auto/N`). `voltab merge` assembles the shards.
        #[arg(long)]
        shard: Option<String>,
    },
    /// Merge the shard folders of a sharded compile into an output folder: the same bytes as
    /// `voltab compile` on one machine.
    Merge {
        /// Shard folders (every shard of the job, once).
        #[arg(required = true)]
        shards: Vec<PathBuf>,
        /// Output folder.
        #[arg(long, default_value = "out")]
        out: PathBuf,
        /// The pipeline (default: the one the shards' manifest names).
        #[arg(long)]
        pipeline: Option<PathBuf>,
        /// Print the summary as JSON on stdout.
        #[arg(long)]
        json: bool,
        /// Bake shards: where the other stages' real-time effects run (as for `voltab run`).
        #[arg(long, value_enum, default_value_t = voltab::render::gpu::DeviceRequest::Auto)]
        device: voltab::render::gpu::DeviceRequest,
    },
    /// Write a Slurm job array that compiles a pipeline in N shards and a merge job that depends on it;
    /// with --submit, submit both (only the shards not yet finished) and print the job ids.
    Slurm {
        /// Pipeline file.
        pipeline: PathBuf,
        /// Number of shards (array tasks).
        #[arg(long)]
        shards: u32,
        /// Slurm partition.
        #[arg(long)]
        partition: Option<String>,
        /// Time limit per task (Slurm's format, e.g. 1:00:00).
        #[arg(long)]
        time: Option<String>,
        /// CPUs per task.
        #[arg(long)]
        cpus_per_task: Option<u32>,
        /// Output folder on storage every node sees (shards in <out>/shards, scripts in <out>/slurm).
        #[arg(long, default_value = "out")]
        out: PathBuf,
        /// Plan for these scenes (see `voltab plan`).
        #[arg(long, num_args = 1..)]
        scene: Vec<PathBuf>,
        /// Submit with sbatch and print the job ids.
        #[arg(long)]
        submit: bool,
    },
    /// Print what voltab imported from a glTF or USD scene: counts, bounds, lights in voltab's units,
    /// media, cameras, materials and warnings.
    Scene {
        /// Scene file (.gltf, .glb, .usd, .usda, .usdc, .usdz).
        file: PathBuf,
        /// Print JSON instead of text.
        #[arg(long)]
        json: bool,
    },
    /// For each table and slice of a pipeline, whether the scenes need it ("compile" or "skip", with the
    /// reason).
    Plan {
        /// Pipeline file.
        pipeline: PathBuf,
        /// Scene files (the plan covers what any of them needs).
        #[arg(long, num_args = 1.., required = true)]
        scene: Vec<PathBuf>,
        /// Print JSON instead of text.
        #[arg(long)]
        json: bool,
    },
    /// Validate a pipeline without compiling.
    Check {
        /// Pipeline file.
        pipeline: PathBuf,
        /// Print the root file as JSON (the form `schemas/pipeline.schema.json` describes).
        #[arg(long)]
        dump_json: bool,
    },
    /// Print a table's header, axes, chunks and compression.
    Inspect {
        /// Table file.
        file: PathBuf,
        /// Print every chunk.
        #[arg(long)]
        chunks: bool,
    },
    /// Check tables' integrity (non-zero exit on any problem).
    Verify {
        /// Table files.
        #[arg(required = true)]
        files: Vec<PathBuf>,
    },
    /// Compare two tables chunk by chunk (non-zero exit when outside tolerance).
    Diff {
        /// First table.
        a: PathBuf,
        /// Second table.
        b: PathBuf,
        /// Absolute tolerance.
        #[arg(long, default_value_t = 0.0)]
        abs_tol: f64,
        /// Relative tolerance.
        #[arg(long, default_value_t = 0.0)]
        rel_tol: f64,
    },
    /// Error against run time for every table (JSON, Markdown and PNG plots).
    Report {
        /// Pipeline file.
        pipeline: PathBuf,
        /// Output folder.
        #[arg(long, default_value = "report")]
        out: PathBuf,
        /// Only the stages' error-vs-time ladders (a lightmap bake against volumetric path tracing),
        /// skipping the tables' ladders. Tables the stages read are compiled into --tables first.
        #[arg(long)]
        stages: bool,
        /// Where the stages' tables are compiled (cached).
        #[arg(long, default_value = "out")]
        tables: PathBuf,
    },
    /// Timings side by side as ratios: cold vs no-op compile, 1 vs N threads, zstd levels, ZH query throughput.
    #[command(group(clap::ArgGroup::new("focus").args(["bake", "effects", "translucent", "pop", "gpu", "shards"])))]
    Bench {
        /// Pipeline file.
        #[arg(default_value = "pipelines/default.ron")]
        pipeline: PathBuf,
        /// Print the rows as JSON.
        #[arg(long)]
        json: bool,
        /// Only tables with these ids (all when absent).
        #[arg(long, num_args = 1..)]
        only: Vec<String>,
        /// Skip the whole-pipeline compile comparisons (cold vs up-to-date, 1 vs N threads), which compile
        /// the pipeline three times; keep the per-table rows (zstd levels, ZH query throughput).
        #[arg(long)]
        tables_only: bool,
        /// Also benchmark ray queries (BVH build; primary, incoherent and shadow rays; 1 vs N threads) on a
        /// procedural scene of at least TRIANGLES triangles (default 1048576).
        #[arg(long, value_name = "TRIANGLES", num_args = 0..=1, default_missing_value = "1048576")]
        rays: Option<usize>,
        /// Only the ray benchmark (no pipeline tables).
        #[arg(long)]
        rays_only: bool,
        /// Only the lightmap-bake benchmark of the pipeline's BakeLightmaps stages: texels/s and rays/s per
        /// mode, the Full/Surface overhead, and the speed-up over volumetric path tracing at equal error.
        #[arg(long)]
        bake: bool,
        /// Only the real-time effect benchmarks of the pipeline's EpipolarShadows and ImageFog stages: the
        /// epipolar speed-up over ray marching at equal error (1 and 2 threads), the time-vs-resolution
        /// slopes and the whole god-ray frame (shadow map + epipolar + composite) at 640×480 and 1280×720;
        /// fog frame times at 720p and 1080p and the speed-up over the gathering reference.
        #[arg(long)]
        effects: bool,
        /// Only the translucent-media benchmark of the pipeline's TranslucentRender stages: wang2018 Table 3's
        /// time split per material at the stage's size and at 512×512, memory, naive vs two-step
        /// traversal, and the speed-up over path tracing at equal MSE against the stage's reference and a
        /// 4096-path one (about 5 min for the default pipeline).
        #[arg(long)]
        translucent: bool,
        /// Only the POP benchmark of the pipeline's PopRender stages: the frame split into elek2014 Fig. 14's
        /// phases and the isotropic residuum's speed-up over anisotropic propagation to convergence.
        #[arg(long)]
        pop: bool,
        /// Only the GPU benchmark of the pipeline's real-time effects: each frame on the CPU and on the
        /// GPU side by side, with per-pass GPU times (timestamp queries where the adapter has them;
        /// on a software adapter such as lavapipe these are CPU times). Needs the `gpu` feature.
        #[arg(long)]
        gpu: bool,
        /// Where the bake's tables are compiled (cached).
        #[arg(long, default_value = "out")]
        tables: PathBuf,
        /// Only the scale-out benchmark: each table (--only, default the MsLobes tables) compiled whole
        /// vs as its work units one by one plus the merge; overhead, merge share, and the wall time
        /// projected on 1, 8, 64 and 512 nodes (and at wang2018's size for lobe tables).
        #[arg(long)]
        shards: bool,
    },
    /// Evaluate a compiled table at one configuration.
    Eval {
        /// What to evaluate.
        #[command(subcommand)]
        what: EvalCommand,
    },
    /// Evaluate every formula on extreme inputs and print the matrix.
    Stability {
        /// Print passing rows too.
        #[arg(long)]
        all: bool,
    },
    /// Judge every stage of a pipeline against Mitsuba 3 (the independent reference renderer): writes
    /// validation.json, validation.md, a picture per stage and error_vs_time.png. Needs Python with
    /// `mitsuba` (.venv from scripts/test-all.sh, or VOLTAB_PYTHON).
    Validate {
        /// Pipeline file.
        #[arg(default_value = "pipelines/default.ron")]
        pipeline: PathBuf,
        /// Only these stage ids (all when absent).
        #[arg(long, num_args = 1.., value_delimiter = ',')]
        stages: Vec<String>,
        /// quick: low resolution and few texels (minutes; CI); full: the stages' own size (opt-in, long).
        #[arg(long, value_enum, default_value = "quick")]
        quality: voltab::validation::Quality,
        /// Output folder.
        #[arg(long, default_value = "out/validate")]
        out: PathBuf,
        /// Where the pipeline's tables are compiled (cached).
        #[arg(long, default_value = "out")]
        tables: PathBuf,
    },
    /// Write a scene as another renderer's scene (the independent references of issue 30).
    Export {
        #[command(subcommand)]
        what: ExportCommand,
    },
    /// Write or check `schemas/` (JSON Schema and reference page) from the code.
    Schema {
        /// Folder to write into.
        #[arg(long, default_value = "schemas")]
        dir: PathBuf,
        /// Fail if the files differ instead of writing them.
        #[arg(long)]
        check: bool,
    },
}

#[derive(Subcommand)]
enum ExportCommand {
    /// Mitsuba 3: `scene.xml`, binary PLY meshes, `.vol` grid volumes and `export.json` (what became what,
    /// units, the region the global medium fills, approximations); see `voltab::reference::mitsuba`.
    Mitsuba {
        /// Scene file (.gltf, .glb, .usd, .usda, .usdc, .usdz).
        file: PathBuf,
        /// Output folder (created; earlier files replaced).
        #[arg(long)]
        out: PathBuf,
        /// Camera to export as the sensor (default: the scene's first).
        #[arg(long)]
        camera: Option<String>,
        /// Default image width [px].
        #[arg(long, default_value_t = 256)]
        width: u32,
        /// Default image height [px] (default: from the camera's aspect ratio).
        #[arg(long)]
        height: Option<u32>,
        /// Default samples per pixel.
        #[arg(long, default_value_t = 64)]
        spp: u32,
        /// Also write texels.json: this many of the lightmap bake's texels with its Surface and Shadow
        /// irradiance and voltab's internal reference there (0: none).
        #[arg(long, default_value_t = 0)]
        texels: usize,
    },
}

#[derive(Subcommand)]
enum EvalCommand {
    /// Irradiance from a ZhResponse table on a receiver at --distance from the light (point, area) or below
    /// the medium boundary (directional), its normal at --normal-angle from the direction toward the light.
    Zh(EvalZh),
    /// The stored multiple-scattering lobe of an MsLobes table at (rho, z) around the canonical beam
    /// (sigma_t = 1, lengths in mean free paths), theta from the axis beam origin -> P (symmetric lobe:
    /// averaged over the azimuth about that axis).
    Lobes(EvalLobes),
}

#[derive(clap::Args)]
#[command(allow_negative_numbers = true)]
struct EvalLobes {
    /// A compiled MsLobes table (.vtab).
    #[arg(long)]
    table: PathBuf,
    /// Single-scattering albedo in [0, 1].
    #[arg(long)]
    albedo: f64,
    /// HG mean cosine, within the table's g range.
    #[arg(long, default_value_t = 0.0)]
    g: f64,
    /// Distance from the beam axis (mean free paths).
    #[arg(long)]
    rho: f64,
    /// Depth along the beam from its origin (mean free paths; negative behind it).
    #[arg(long)]
    z: f64,
    /// Angle between the outgoing direction and the axis from the beam origin to the point (degrees).
    #[arg(long)]
    theta: f64,
    /// Full-lobe tables: azimuth about that axis from the plane of the beam (degrees, 0 to 180).
    #[arg(long, default_value_t = 0.0)]
    phi: f64,
    /// Print JSON (keys: total, double).
    #[arg(long)]
    json: bool,
}

#[derive(clap::Args)]
#[command(allow_negative_numbers = true)]
struct EvalZh {
    /// A compiled ZhResponse table (.vtab).
    #[arg(long)]
    table: PathBuf,
    /// Emitter profile.
    #[arg(long, value_enum)]
    emitter: EvalEmitter,
    /// Point: intensity (W/sr). Area: intensity along the patch normal (W/sr). Directional: irradiance at
    /// the medium boundary (W/m^2).
    #[arg(long, default_value_t = 1.0)]
    intensity: f64,
    /// Distance to the point light, or depth below the boundary toward the directional light (m).
    #[arg(long)]
    distance: f64,
    /// Angle between the receiver normal and the direction toward the light (degrees).
    #[arg(long, default_value_t = 0.0)]
    normal_angle: f64,
    /// Area emitter: angle between the patch normal and the direction from the patch to the receiver
    /// (degrees; 0 = facing the receiver, > 90 = facing away).
    #[arg(long, default_value_t = 0.0)]
    patch_angle: f64,
    /// Scattering coefficient (1/m).
    #[arg(long)]
    sigma_s: f64,
    /// Absorption coefficient (1/m).
    #[arg(long, default_value_t = 0.0)]
    sigma_a: f64,
    /// HG mean cosine, within the table's g range.
    #[arg(long, default_value_t = 0.0)]
    g: f64,
    /// Apply the table's back-scatter shift (dubouchet2019 Sec. 5.2; a surface heuristic, off for a
    /// receiver inside the medium).
    #[arg(long)]
    backscatter: bool,
    /// Leave out the tail closure (orders beyond the table's B).
    #[arg(long)]
    no_tail: bool,
    /// Similarity relation (1 - g) sigma_s, g = 0 for the multiple-scattering orders.
    #[arg(long)]
    similarity: bool,
    /// Highest scattering order summed (default: all the table holds).
    #[arg(long)]
    max_bounce: Option<usize>,
    /// Print JSON (keys: direct, single, multiple, tail, total).
    #[arg(long)]
    json: bool,
}

#[derive(Clone, Copy, clap::ValueEnum)]
enum EvalEmitter {
    Point,
    Directional,
    Area,
}

fn eval_zh(a: &EvalZh) -> Result<()> {
    use voltab::tables::zh_response::{Emitter, EmitterProfile, Medium, QueryOptions, Receiver, ZhResponseTable};
    let profile = match a.emitter {
        EvalEmitter::Point => EmitterProfile::Point,
        EvalEmitter::Directional => EmitterProfile::Directional,
        EvalEmitter::Area => EmitterProfile::Area,
    };
    let table = ZhResponseTable::open(&a.table, Some(&[profile]), Some(&[a.g])).map_err(|e| anyhow::anyhow!("{e}"))?;
    let theta = a.normal_angle.to_radians();
    let receiver = Receiver { position: [0.0; 3], normal: [theta.sin(), 0.0, theta.cos()] };
    let emitter = match a.emitter {
        EvalEmitter::Point => Emitter::Point { intensity: a.intensity, position: [0.0, 0.0, a.distance] },
        EvalEmitter::Directional => {
            Emitter::Directional { irradiance: a.intensity, toward_light: [0.0, 0.0, 1.0], depth: a.distance }
        }
        EvalEmitter::Area => {
            let t = a.patch_angle.to_radians();
            Emitter::Area { intensity: a.intensity, position: [0.0, 0.0, a.distance], normal: [t.sin(), 0.0, -t.cos()] }
        }
    };
    if !(a.distance.is_finite() && a.distance >= 0.0) {
        bail!("--distance {} must be finite and >= 0 (metres)", a.distance);
    }
    let medium = Medium { sigma_s: a.sigma_s, sigma_a: a.sigma_a, g: a.g };
    let opts = QueryOptions {
        backscatter: a.backscatter,
        tail: !a.no_tail,
        similarity: a.similarity,
        max_bounce: a.max_bounce,
    };
    let r = table
        .irradiance(&medium, &emitter, &receiver, &opts)
        .map_err(|e| anyhow::anyhow!("{}: {e}", a.table.display()))?;
    if a.json {
        println!("{}", serde_json::to_string_pretty(&r)?);
    } else {
        println!("direct    {:.6e} W/m^2", r.direct);
        println!("single    {:.6e} W/m^2", r.single);
        println!("multiple  {:.6e} W/m^2  (b >= 2, of which tail b > {}: {:.6e})", r.multiple, table.bounces, r.tail);
        println!("total     {:.6e} W/m^2", r.total);
    }
    Ok(())
}

fn eval_lobes(a: &EvalLobes) -> Result<()> {
    use voltab::tables::ms_lobes::{LobeQuery, MsLobesTable};
    let table = MsLobesTable::open(&a.table, Some(&[(a.albedo, a.g)])).map_err(|e| anyhow::anyhow!("{e}"))?;
    let q = LobeQuery {
        albedo: a.albedo,
        g: a.g,
        rho: a.rho,
        z: a.z,
        theta: a.theta.to_radians(),
        phi: a.phi.to_radians(),
    };
    let v = table.lobe(&q).map_err(|e| anyhow::anyhow!("{}: {e}", a.table.display()))?;
    if a.json {
        println!("{}", serde_json::json!({ "total": v.total, "double": v.double }));
    } else {
        println!("total   {:.6e} 1/(mfp sr)  (all paths with >= 2 scattering events)", v.total);
        println!("double  {:.6e} 1/(mfp sr)  (exactly 2 scattering events)", v.double);
    }
    Ok(())
}

fn main() -> ExitCode {
    if let Some(code) = voltab::scene::usd_import::guarded_child_main() {
        return code; // the hidden USD import child (scene::usd_import::guard)
    }
    let cli = Cli::parse();
    match dispatch(cli.command) {
        Ok(code) => code,
        Err(e) => {
            eprintln!("{e:#}");
            ExitCode::FAILURE
        }
    }
}

fn load(path: &Path) -> Result<ValidatedPipeline> {
    let sources: &dyn Sources = if !path.exists()
        && pipeline::parse::EMBEDDED.iter().any(|(p, _)| Path::new(p) == pipeline::parse::normalize(path))
    {
        eprintln!("note: {} not found here; using the copy built into voltab", path.display());
        &Embedded
    } else {
        &Disk
    };
    // Diagnostics are complete messages; print them as they are.
    pipeline::load_and_validate(path, sources).map_err(|e| anyhow::anyhow!("{e}"))
}

/// The bundled scenes (`scenes/*.gltf`, sorted) when run from a checkout: the main job compiles what they
/// need. Outside a checkout there are none and the whole default pipeline is compiled.
fn bundled_scenes() -> Vec<PathBuf> {
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
fn compiled_for_stages(pipeline: &Path, tables: &Path, progress: bool) -> Result<Option<ValidatedPipeline>> {
    let p = load(pipeline)?;
    let scenes: Vec<PathBuf> = p.stages().iter().flat_map(|s| s.def().scenes(&base_dir(&p))).collect();
    if scenes.is_empty() {
        return Ok(None);
    }
    let p = planned(p, &scenes, true)?;
    compile(&p, &CompileOptions { out_dir: tables.to_path_buf(), only: Vec::new(), jobs: None, progress })?;
    Ok(Some(p))
}

/// Where the stages of `p` run: the device is opened only when a stage can use it, and the choice
/// is said once.
fn stage_device(
    p: &ValidatedPipeline,
    request: voltab::render::gpu::DeviceRequest,
) -> Result<voltab::render::gpu::Device> {
    if p.stages().iter().any(|s| s.def().uses_device()) {
        let (d, message) = voltab::render::gpu::select(request).map_err(|e| anyhow::anyhow!(e))?;
        eprintln!("{message}");
        Ok(d)
    } else {
        Ok(voltab::render::gpu::Device::Cpu)
    }
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

/// The folder relative stage paths resolve against: the pipeline file's.
fn base_dir(p: &ValidatedPipeline) -> PathBuf {
    p.path().parent().map(Path::to_path_buf).unwrap_or_default()
}

/// Whether two paths name the same file (by canonical path when both exist).
fn same_file(a: &Path, b: &Path) -> bool {
    match (a.canonicalize(), b.canonicalize()) {
        (Ok(x), Ok(y)) => x == y,
        _ => a == b,
    }
}

/// Imports a scene; its warnings go to stderr.
fn load_scene(path: &Path) -> Result<voltab::scene::Scene> {
    // Scene errors are complete messages (file, node/prim, fix).
    voltab::scene::Scene::load(path).map_err(|e| anyhow::anyhow!("{e}"))
}

/// The pipeline pruned to what `scenes` need (unchanged when there are none); the plan goes to stderr.
///
/// The scenes that stages read (a bake's scene) are planned for too, so the tables they need are kept.
fn planned(p: ValidatedPipeline, scenes: &[PathBuf], quiet: bool) -> Result<ValidatedPipeline> {
    if scenes.is_empty() {
        return Ok(p);
    }
    let mut scenes = scenes.to_vec();
    for s in p.stages() {
        for f in s.def().scenes(&base_dir(&p)) {
            // The built-in default pipeline outside a checkout names scenes that are not here.
            let embedded_elsewhere = !f.exists() && !p.path().exists();
            if !embedded_elsewhere && !scenes.iter().any(|g| same_file(g, &f)) {
                scenes.push(f);
            }
        }
    }
    let loaded = scenes.iter().map(|f| load_scene(f)).collect::<Result<Vec<_>>>()?;
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

/// `voltab validate`: each selected stage made comparable, judged by Mitsuba, written as a report.
fn validate(
    pipeline: &Path,
    only: &[String],
    quality: voltab::validation::Quality,
    out: &Path,
    tables: &Path,
    progress: bool,
) -> Result<()> {
    use voltab::validation::{self, Validation, cases};
    let p = compiled_for_stages(pipeline, tables, progress)?
        .ok_or_else(|| anyhow::anyhow!("{}: no stage reads a scene; nothing to validate", pipeline.display()))?;
    if let Some(bad) = only.iter().find(|id| !p.stages().iter().any(|s| s.id() == id.as_str())) {
        let ids: Vec<&str> = p.stages().iter().map(|s| s.id()).collect();
        bail!("{}: no stage \"{bad}\" (stages: {})", pipeline.display(), ids.join(", "));
    }
    let base = base_dir(&p);
    let device = voltab::render::gpu::Device::Cpu;
    let ctx = voltab::stages::StageContext { out_dir: tables, base_dir: &base, progress, device: &device };
    let harness = validation::python::Harness::locate();
    let mut results = Vec::new();
    for s in p.stages().iter().filter(|s| only.is_empty() || only.iter().any(|id| id == s.id())) {
        let dir = out.join(s.id());
        eprintln!("validate   {:<20} {}", s.id(), s.def().kind());
        let rows = match cases::prepare(s.id(), s.def(), &ctx, quality, &dir, &harness)? {
            cases::Prepared::Cases(cases) => {
                let many = cases.len() > 1;
                let mut rows = Vec::new();
                for case in &cases {
                    let sub = if many { dir.join(case.stage.rsplit('/').next().unwrap_or("")) } else { dir.clone() };
                    rows.push(validation::judge(case, &sub, &harness)?);
                }
                rows
            }
            cases::Prepared::NotCompared(why) => vec![validation::not_compared(s.id(), s.def().kind(), &why)],
        };
        for r in rows {
            for m in &r.methods {
                println!(
                    "validate   {:<20} {:<10} {} ({:.0} ms; Mitsuba {:.0} s)",
                    r.stage, m.name, m.text, m.ms, r.reference_s
                );
            }
            if let Some(why) = &r.not_compared {
                println!("validate   {:<20} not compared: {why}", r.stage);
            }
            results.push(r);
        }
    }
    let v = Validation { pipeline: pipeline.to_path_buf(), quality, stages: results };
    let files = validation::write(&v, out)?;
    print!("{}", validation::markdown(&v));
    println!("wrote {}", files.iter().map(|f| f.display().to_string()).collect::<Vec<_>>().join(", "));
    Ok(())
}

fn dispatch(cmd: Option<Command>) -> Result<ExitCode> {
    let progress = std::io::stderr().is_terminal();
    let cmd = cmd.unwrap_or_else(|| Command::Run {
        pipeline: "pipelines/default.ron".into(),
        out: "out".into(),
        jobs: None,
        json: false,
        scene: bundled_scenes(),
        device: voltab::render::gpu::DeviceRequest::Auto,
        shard: None,
        tables: None,
    });
    let cpu_device = voltab::render::gpu::Device::Cpu;
    match cmd {
        Command::Run { pipeline, out, json, scene, shard: Some(shard), tables: Some(tables), jobs, .. } => {
            let spec = voltab::shard::ShardSpec::parse(&shard, &|k| std::env::var(k).ok())?;
            let p = planned(load(&pipeline)?, &scene, true)?;
            let base = base_dir(&p);
            let ctx = voltab::stages::StageContext { out_dir: &tables, base_dir: &base, progress, device: &cpu_device };
            let run = || voltab::shard::bake::bake_shard(&p, &scene, spec, &ctx, &out);
            let s = match jobs {
                Some(j) => rayon::ThreadPoolBuilder::new().num_threads(j).build()?.install(run)?,
                None => run()?,
            };
            print_shard("bake shard", "tiles", &s, json)?;
        }
        Command::Run { pipeline, out, jobs, json, scene, device, .. } => {
            let p = planned(load(&pipeline)?, &scene, json)?;
            let summary = compile(&p, &CompileOptions { out_dir: out.clone(), only: Vec::new(), jobs, progress })?;
            let mut stage_results = Vec::new();
            let base = base_dir(&p);
            let device = stage_device(&p, device)?;
            let ctx = voltab::stages::StageContext { out_dir: &out, base_dir: &base, progress, device: &device };
            for s in p.stages() {
                let missing: Vec<PathBuf> = s.def().scenes(&base).into_iter().filter(|f| !f.exists()).collect();
                if !missing.is_empty() && !pipeline.exists() {
                    // The built-in default pipeline outside a checkout: its bundled scenes are not here.
                    eprintln!(
                        "note: stage {} skipped: {} not found (run from a voltab checkout)",
                        s.id(),
                        missing[0].display()
                    );
                    continue;
                }
                stage_results.push((s.id().to_owned(), s.def().run(s.id(), &ctx)?));
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
        }
        Command::Compile { pipeline, out, jobs, json, scene, shard: Some(shard), only } => {
            if !only.is_empty() {
                anyhow::bail!(
                    "--only and --shard cannot be combined\n  = help: a sharded compile covers the whole pipeline; drop --only"
                );
            }
            let spec = voltab::shard::ShardSpec::parse(&shard, &|k| std::env::var(k).ok())?;
            let p = planned(load(&pipeline)?, &scene, true)?;
            let s = voltab::shard::compile_shard(&p, &scene, spec, &out, jobs, progress)?;
            print_shard("shard", "units", &s, json)?;
        }
        Command::Merge { shards, out, pipeline, json, device } => {
            let first = voltab::shard::read_manifest(&shards[0])?;
            let path = pipeline.unwrap_or_else(|| first.pipeline.clone());
            let p = planned(load(&path)?, &first.scenes, true)?;
            if first.job == voltab::shard::Job::Bake {
                let base = base_dir(&p);
                let device = stage_device(&p, device)?;
                let ctx = voltab::stages::StageContext { out_dir: &out, base_dir: &base, progress, device: &device };
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
        }
        Command::Slurm { pipeline, shards, partition, time, cpus_per_task, out, scene, submit } => {
            let p = planned(load(&pipeline)?, &scene, true)?;
            let exe = std::env::current_exe()?;
            let opts =
                voltab::shard::slurm::SlurmOptions { shards, partition, time, out, scenes: scene, cpus_per_task };
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
        }
        Command::Compile { pipeline, out, only, jobs, json, scene, shard: None } => {
            let p = planned(load(&pipeline)?, &scene, json)?;
            let summary = compile(&p, &CompileOptions { out_dir: out.clone(), only, jobs, progress })?;
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
        }
        Command::Scene { file, json } => {
            let scene = load_scene(&file)?;
            let summary = voltab::scene::summary::SceneSummary::of(&scene);
            if json {
                println!("{}", serde_json::to_string_pretty(&summary)?);
            } else {
                print!("{}", summary.text());
            }
        }
        Command::Plan { pipeline, scene, json } => {
            let p = load(&pipeline)?;
            let scenes = scene.iter().map(|f| load_scene(f)).collect::<Result<Vec<_>>>()?;
            let plan = voltab::plan::Plan::new(&p, &scenes);
            if json {
                println!("{}", serde_json::to_string_pretty(&plan)?);
            } else {
                print!("{}", plan.text());
            }
        }
        Command::Check { pipeline, dump_json } => {
            let p = load(&pipeline)?;
            if dump_json {
                let text =
                    if pipeline.exists() { std::fs::read_to_string(&pipeline)? } else { Embedded.read(&pipeline)? };
                let file: pipeline::PipelineFile = ron::Options::default()
                    .with_default_extension(
                        ron::extensions::Extensions::IMPLICIT_SOME
                            | ron::extensions::Extensions::UNWRAP_VARIANT_NEWTYPES,
                    )
                    .from_str(&text)?;
                println!("{}", serde_json::to_string_pretty(&file)?);
            } else {
                println!("{}: ok ({} tables, {} stages)", pipeline.display(), p.tables().len(), p.stages().len());
                for t in p.tables() {
                    println!(
                        "  table {:<20} {:<10} key {}",
                        t.id(),
                        t.def().kind(),
                        &voltab::cache::hex(t.key())[..16]
                    );
                }
                for s in p.stages() {
                    println!("  stage {:<20} {}", s.id(), s.def().kind());
                }
            }
        }
        Command::Inspect { file, chunks } => inspect(&file, chunks)?,
        Command::Verify { files } => {
            let mut bad = 0;
            for f in &files {
                let checked = VtabReader::open(f).map_err(|e| e.to_string()).and_then(|mut r| {
                    let rep = r.verify().map_err(|e| e.to_string())?;
                    voltab::tables::check_known_kind(r.header())?;
                    Ok(rep)
                });
                match checked {
                    Ok(rep) => println!("ok   {} ({rep})", f.display()),
                    Err(e) => {
                        bad += 1;
                        println!("BAD  {}: {e}", f.display());
                    }
                }
            }
            if bad > 0 {
                bail!("{bad} of {} files failed verification", files.len());
            }
        }
        Command::Diff { a, b, abs_tol, rel_tol } => {
            let mut ra = VtabReader::open(&a).with_context(|| format!("reading {}", a.display()))?;
            let mut rb = VtabReader::open(&b).with_context(|| format!("reading {}", b.display()))?;
            let d = container::diff(&mut ra, &mut rb)?;
            for h in &d.header_differences {
                println!("header: {h}");
            }
            for c in &d.chunks {
                println!(
                    "{:<16} slice {:>5}  max abs {:.3e} at {:>7}  max rel {:.3e} at {:>7}",
                    c.array, c.slice, c.max_abs, c.max_abs_index, c.max_rel, c.max_rel_index
                );
            }
            if d.identical() {
                println!("identical values");
            } else if d.within(abs_tol, rel_tol) {
                println!("within tolerance (abs {abs_tol:e}, rel {rel_tol:e})");
            } else {
                println!("DIFFERENT beyond tolerance (abs {abs_tol:e}, rel {rel_tol:e})");
                return Ok(ExitCode::FAILURE);
            }
        }
        Command::Report { pipeline, out, stages, tables } => {
            if !stages {
                let p = load(&pipeline)?;
                let r = voltab::report::run(&p, &out, progress)?;
                print!("{}", voltab::report::markdown(&r));
                println!("wrote {}/report.json, report.md and {} plots", out.display(), r.tables.len());
            }
            if let Some(p) = compiled_for_stages(&pipeline, &tables, progress)? {
                let base = base_dir(&p);
                let ctx =
                    voltab::stages::StageContext { out_dir: &tables, base_dir: &base, progress, device: &cpu_device };
                for s in p.stages() {
                    if let Some(md) = s.def().report(s.id(), &ctx, &out)? {
                        print!("{md}");
                        println!(
                            "wrote {}/{}-* (Markdown, JSON where available, error-vs-time plot)",
                            out.display(),
                            s.id()
                        );
                    }
                }
            }
        }
        Command::Bench {
            pipeline,
            json,
            only,
            tables_only,
            rays,
            rays_only,
            bake,
            effects,
            translucent,
            pop,
            gpu,
            tables,
            shards,
        } => {
            let mut rows = Vec::new();
            if shards {
                let p = load(&pipeline)?;
                let is_stage = |o: &String| p.stages().iter().any(|s| s.id() == o.as_str());
                let (stage_only, table_only): (Vec<String>, Vec<String>) = only.iter().cloned().partition(is_stage);
                let say = |m: &str| {
                    if progress {
                        eprintln!("{m}");
                    }
                };
                // Prints a measurement's text (unless --json) and keeps its rows.
                let mut keep = |(text, r): (String, Vec<_>)| {
                    if !json {
                        print!("{text}");
                    }
                    rows.extend(r);
                };
                if only.is_empty() || !table_only.is_empty() {
                    keep(voltab::shard::bench::run(&p, &table_only, &say).map_err(|e| anyhow::anyhow!(e))?);
                }
                // The lightmap bakes as tiles (their tables compiled into --tables first).
                if (only.is_empty() || !stage_only.is_empty())
                    && let Some(p) = compiled_for_stages(&pipeline, &tables, progress)?
                {
                    let base = base_dir(&p);
                    let ctx = voltab::stages::StageContext {
                        out_dir: &tables,
                        base_dir: &base,
                        progress: false,
                        device: &cpu_device,
                    };
                    keep(voltab::shard::bench::bake(&p, &ctx, &stage_only, &say).map_err(|e| anyhow::anyhow!(e))?);
                }
            } else if gpu || bake || translucent || pop || effects {
                // The stages' own benchmarks; effects need no tables, the others compile theirs first.
                use voltab::stages::BenchFocus;
                let focus = [
                    (bake, BenchFocus::Bake),
                    (translucent, BenchFocus::Translucent),
                    (pop, BenchFocus::Pop),
                    (effects, BenchFocus::Effects),
                ]
                .into_iter()
                .find_map(|(on, f)| on.then_some(f));
                let device = if gpu {
                    let (device, message) = voltab::render::gpu::select(voltab::render::gpu::DeviceRequest::Gpu)
                        .map_err(|e| anyhow::anyhow!(e))?;
                    eprintln!("{message}");
                    device
                } else {
                    cpu_device
                };
                let p =
                    if effects { Some(load(&pipeline)?) } else { compiled_for_stages(&pipeline, &tables, progress)? };
                if let Some(p) = p {
                    let base = base_dir(&p);
                    let ctx =
                        voltab::stages::StageContext { out_dir: &tables, base_dir: &base, progress, device: &device };
                    for s in p.stages() {
                        let measured = if gpu {
                            s.def().bench_gpu(s.id(), &ctx)?
                        } else if focus.is_some() && s.def().bench_focus() == focus {
                            s.def().bench(s.id(), &ctx)?
                        } else {
                            None
                        };
                        if let Some((text, r)) = measured {
                            if !json && !text.is_empty() {
                                println!("{text}");
                            }
                            rows.extend(r);
                        }
                    }
                }
            } else if !rays_only {
                let p = load(&pipeline)?;
                rows = voltab::bench::run(&p, &voltab::bench::BenchOptions { only, tables_only })?;
            }
            if rays.is_some() || rays_only {
                rows.extend(voltab::bench::ray_rows(rays.unwrap_or(voltab::bench::RAY_BENCH_TRIANGLES))?);
            }
            if json {
                println!("{}", serde_json::to_string_pretty(&rows)?);
            } else {
                print!("{}", voltab::bench::render(&rows));
            }
        }
        Command::Eval { what: EvalCommand::Zh(a) } => eval_zh(&a)?,
        Command::Eval { what: EvalCommand::Lobes(a) } => eval_lobes(&a)?,
        Command::Export { what: ExportCommand::Mitsuba { file, out, camera, width, height, spp, texels } } => {
            let scene = load_scene(&file)?;
            let options = voltab::reference::mitsuba::ExportOptions { camera, width, height, spp, texels };
            let m = voltab::reference::mitsuba::export(&scene, &options, &out).map_err(|e| anyhow::anyhow!("{e}"))?;
            println!(
                "wrote {} ({} shapes, {} media, {} lights)",
                out.join(&m.scene_xml).display(),
                m.shapes.len(),
                m.media.len(),
                m.lights.len()
            );
            for w in &m.warnings {
                eprintln!("warning: {}: {}", w.location, w.message);
            }
        }
        Command::Stability { all } => {
            let rows = voltab::stability::rows();
            let failed = rows.iter().filter(|r| !r.ok()).count();
            for r in rows.iter().filter(|r| all || !r.ok()) {
                println!("{r}");
            }
            println!("{} passed, {failed} failed", rows.len() - failed);
            if failed > 0 {
                return Ok(ExitCode::FAILURE);
            }
        }
        Command::Validate { pipeline, stages, quality, out, tables } => {
            validate(&pipeline, &stages, quality, &out, &tables, progress)?;
        }
        Command::Schema { dir, check } => {
            let files = [
                (
                    "pipeline.schema.json",
                    format!("{}\n", serde_json::to_string_pretty(&pipeline::schema::json_schema())?),
                ),
                ("reference.md", pipeline::schema::reference_markdown()),
                (
                    "VOLTAB_participating_media.schema.json",
                    format!("{}\n", serde_json::to_string_pretty(&voltab::scene::gltf_import::vendor_schema())?),
                ),
            ];
            let mut stale = Vec::new();
            for (name, text) in &files {
                let path = dir.join(name);
                if check {
                    if std::fs::read_to_string(&path).ok().as_deref() != Some(text.as_str()) {
                        stale.push(path.display().to_string());
                    }
                } else {
                    std::fs::create_dir_all(&dir)?;
                    voltab::cache::write_atomic(&path, text.as_bytes())?;
                    println!("wrote {}", path.display());
                }
            }
            if !stale.is_empty() {
                bail!("out of date: {} — run `cargo run -- schema` to regenerate", stale.join(", "));
            }
        }
    }
    Ok(ExitCode::SUCCESS)
}

fn inspect(file: &Path, all_chunks: bool) -> Result<()> {
    let r = VtabReader::open(file).with_context(|| format!("reading {}", file.display()))?;
    let h = r.header();
    let (major, minor) = r.version();
    println!("file            {}", file.display());
    println!("format          vtab {major}.{minor}");
    println!("kind            {} (layout v{})", h.kind, h.kind_schema_version);
    if let Err(e) = voltab::tables::check_known_kind(h) {
        println!("warning         {e}");
    }
    println!("generator       {}", h.generator_version);
    println!("content key     {}", voltab::cache::hex(&h.content_key));
    println!("definition      {}", h.definition_ron);
    for (ai, a) in h.arrays.iter().enumerate() {
        let shape: Vec<String> = a.axes.iter().map(|x| x.len.to_string()).collect();
        println!(
            "array {ai}: {} [{}] {:?}, unit {:?} — {}",
            a.name,
            shape.join(" x "),
            a.element,
            a.unit,
            a.description
        );
        if let Some(q) = &a.quantization {
            println!("    quantised to {} mantissa bits: max relative error {:.3e}", q.mantissa_bits, q.max_rel_error);
        }
        for x in &a.axes {
            println!(
                "    axis {:<6} {:>8} values {:?} from {} to {} {}",
                x.name, x.len, x.spacing, x.min, x.max, x.unit
            );
        }
        let chunks: Vec<_> = r.chunks().iter().filter(|c| c.array as usize == ai).collect();
        let raw: u64 = chunks.iter().map(|c| c.raw_len).sum();
        let stored: u64 = chunks.iter().map(|c| c.stored_len).sum();
        println!(
            "    {} chunks, {raw} bytes raw → {stored} stored, ratio {:.2}",
            chunks.len(),
            raw as f64 / stored.max(1) as f64
        );
        for c in chunks.iter().take(if all_chunks { usize::MAX } else { 0 }) {
            println!(
                "      slice {:>5}: {:>9} → {:>9} bytes ({:?}, crc {:08x})",
                c.slice, c.raw_len, c.stored_len, c.transform, c.crc32
            );
        }
    }
    let raw: u64 = r.chunks().iter().map(|c| c.raw_len).sum();
    let stored: u64 = r.chunks().iter().map(|c| c.stored_len).sum();
    println!("total           {raw} bytes raw → {stored} stored, ratio {:.2}", raw as f64 / stored.max(1) as f64);
    Ok(())
}
