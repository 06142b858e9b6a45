//! The command line's grammar: clap definitions of every `voltab` command and its options → the
//! values [`super::dispatch`] hands to the commands. `voltab help <command>` prints these docs.

use std::path::PathBuf;

use clap::{Parser, Subcommand};

#[derive(Parser)]
#[command(
    name = "voltab",
    version,
    about = "Compile participating-media tables from RON pipelines and run the stages that use them."
)]
pub struct Cli {
    // The command; none runs the main job (the default pipeline on the bundled scenes).
    #[command(subcommand)]
    pub command: Option<Command>,
}

#[derive(Subcommand)]
pub enum Command {
    /// Compile every table a pipeline declares, then run its stages.
    Run(RunArgs),
    /// Compile tables (incrementally: unchanged tables are not recomputed).
    Compile(CompileArgs),
    /// Merge the shard folders of a sharded compile into an output folder: the same bytes as
    /// `voltab compile` on one machine.
    Merge(MergeArgs),
    /// Write a Slurm job array that compiles a pipeline in N shards and a merge job that depends on it;
    /// with --submit, submit both (only the shards not yet finished) and print the job ids.
    Slurm(SlurmArgs),
    /// Print what voltab imported from a glTF or USD scene: counts, bounds, lights in voltab's units,
    /// media, cameras, materials and warnings.
    Scene(SceneArgs),
    /// For each table and slice of a pipeline, whether the scenes need it ("compile" or "skip", with the
    /// reason).
    Plan(PlanArgs),
    /// Validate a pipeline without compiling.
    Check(CheckArgs),
    /// Print a table's header, axes, chunks and compression.
    Inspect(InspectArgs),
    /// Check tables' integrity (non-zero exit on any problem).
    Verify(VerifyArgs),
    /// Compare two tables chunk by chunk (non-zero exit when outside tolerance).
    Diff(DiffArgs),
    /// Error against run time for every table (JSON, Markdown and PNG plots).
    Report(ReportArgs),
    /// Timings side by side as ratios: cold vs no-op compile, 1 vs N threads, zstd levels, ZH query throughput.
    Bench(BenchArgs),
    /// Evaluate a compiled table at one configuration.
    Eval {
        /// What to evaluate.
        #[command(subcommand)]
        what: EvalCommand,
    },
    /// Evaluate every formula on extreme inputs and print the matrix.
    Stability(StabilityArgs),
    /// Judge every stage of a pipeline against Mitsuba 3 (the independent reference renderer): writes
    /// validation.json, validation.md, a picture per stage and error_vs_time.png. Needs Python with
    /// `mitsuba` (.venv from scripts/test-all.sh, or VOLTAB_PYTHON).
    Validate(ValidateArgs),
    /// Write a scene as another renderer's scene (the independent references of issue 30).
    Export {
        #[command(subcommand)]
        what: ExportCommand,
    },
    /// Write or check `schemas/` (JSON Schema and reference page) from the code.
    Schema(SchemaArgs),
}

#[derive(clap::Args)]
pub struct RunArgs {
    /// Pipeline file.
    pub pipeline: PathBuf,
    /// Output folder.
    #[arg(long, default_value = "out")]
    pub out: PathBuf,
    /// Worker threads (default: all cores).
    #[arg(long)]
    pub jobs: Option<usize>,
    /// Print the summary as JSON on stdout.
    #[arg(long)]
    pub json: bool,
    /// Compile only what these scenes need (glTF or USD; see `voltab plan`).
    #[arg(long, num_args = 1..)]
    pub scene: Vec<PathBuf>,
    /// Where the real-time effects run: auto = the GPU when this build has the `gpu` feature
    /// and an adapter is found, else the CPU (the choice and the reason are printed).
    #[arg(long, value_enum, default_value_t = voltab::render::gpu::DeviceRequest::Auto)]
    pub device: voltab::render::gpu::DeviceRequest,
    /// Compute only shard I of N of the lightmap bakes' texel tiles into --out (a shard folder
    /// for `voltab merge`), reading the tables from --tables; `auto` as for `compile --shard`.
    #[arg(long, requires = "tables")]
    pub shard: Option<String>,
    /// With --shard: the folder holding the pipeline's compiled (merged) tables.
    #[arg(long, requires = "shard")]
    pub tables: Option<PathBuf>,
}

#[derive(clap::Args)]
pub struct CompileArgs {
    /// Pipeline file.
    pub pipeline: PathBuf,
    /// Output folder.
    #[arg(long, default_value = "out")]
    pub out: PathBuf,
    /// Compile only these table ids.
    #[arg(long, num_args = 1..)]
    pub only: Vec<String>,
    /// Worker threads (default: all cores).
    #[arg(long)]
    pub jobs: Option<usize>,
    /// Print the summary as JSON on stdout.
    #[arg(long)]
    pub json: bool,
    /// Compile only the tables and slices these scenes need (glTF or USD; see `voltab plan`).
    #[arg(long, num_args = 1..)]
    pub scene: Vec<PathBuf>,
    /// Compute only shard I of N (`I/N`, 0-based) of the compile's work units into the shard folder
    /// --out; `auto` reads SLURM_ARRAY_TASK_ID (count: VOLTAB_SHARD_COUNT or SLURM_ARRAY_TASK_COUNT)
    /// or JOB_COMPLETION_INDEX (`auto/N`). `voltab merge` assembles the shards.
    #[arg(long)]
    pub shard: Option<String>,
}

#[derive(clap::Args)]
pub struct MergeArgs {
    /// Shard folders (every shard of the job, once).
    #[arg(required = true)]
    pub shards: Vec<PathBuf>,
    /// Output folder.
    #[arg(long, default_value = "out")]
    pub out: PathBuf,
    /// The pipeline (default: the one the shards' manifest names).
    #[arg(long)]
    pub pipeline: Option<PathBuf>,
    /// Print the summary as JSON on stdout.
    #[arg(long)]
    pub json: bool,
    /// Bake shards: where the other stages' real-time effects run (as for `voltab run`).
    #[arg(long, value_enum, default_value_t = voltab::render::gpu::DeviceRequest::Auto)]
    pub device: voltab::render::gpu::DeviceRequest,
}

#[derive(clap::Args)]
pub struct SlurmArgs {
    /// Pipeline file.
    pub pipeline: PathBuf,
    /// Number of shards (array tasks).
    #[arg(long)]
    pub shards: u32,
    /// Slurm partition.
    #[arg(long)]
    pub partition: Option<String>,
    /// Time limit per task (Slurm's format, e.g. 1:00:00).
    #[arg(long)]
    pub time: Option<String>,
    /// CPUs per task.
    #[arg(long)]
    pub cpus_per_task: Option<u32>,
    /// Output folder on storage every node sees (shards in <out>/shards, scripts in <out>/slurm).
    #[arg(long, default_value = "out")]
    pub out: PathBuf,
    /// Plan for these scenes (see `voltab plan`).
    #[arg(long, num_args = 1..)]
    pub scene: Vec<PathBuf>,
    /// Submit with sbatch and print the job ids.
    #[arg(long)]
    pub submit: bool,
}

#[derive(clap::Args)]
pub struct SceneArgs {
    /// Scene file (.gltf, .glb, .usd, .usda, .usdc, .usdz).
    pub file: PathBuf,
    /// Print JSON instead of text.
    #[arg(long)]
    pub json: bool,
}

#[derive(clap::Args)]
pub struct PlanArgs {
    /// Pipeline file.
    pub pipeline: PathBuf,
    /// Scene files (the plan covers what any of them needs).
    #[arg(long, num_args = 1.., required = true)]
    pub scene: Vec<PathBuf>,
    /// Print JSON instead of text.
    #[arg(long)]
    pub json: bool,
}

#[derive(clap::Args)]
pub struct CheckArgs {
    /// Pipeline file.
    pub pipeline: PathBuf,
    /// Print the root file as JSON (the form `schemas/pipeline.schema.json` describes).
    #[arg(long)]
    pub dump_json: bool,
}

#[derive(clap::Args)]
pub struct InspectArgs {
    /// Table file.
    pub file: PathBuf,
    /// Print every chunk.
    #[arg(long)]
    pub chunks: bool,
}

#[derive(clap::Args)]
pub struct VerifyArgs {
    /// Table files.
    #[arg(required = true)]
    pub files: Vec<PathBuf>,
}

#[derive(clap::Args)]
pub struct DiffArgs {
    /// First table.
    pub a: PathBuf,
    /// Second table.
    pub b: PathBuf,
    /// Absolute tolerance.
    #[arg(long, default_value_t = 0.0)]
    pub abs_tol: f64,
    /// Relative tolerance.
    #[arg(long, default_value_t = 0.0)]
    pub rel_tol: f64,
}

#[derive(clap::Args)]
pub struct ReportArgs {
    /// Pipeline file.
    pub pipeline: PathBuf,
    /// Output folder.
    #[arg(long, default_value = "report")]
    pub out: PathBuf,
    /// Only the stages' error-vs-time ladders (a lightmap bake against volumetric path tracing),
    /// skipping the tables' ladders. Tables the stages read are compiled into --tables first.
    #[arg(long)]
    pub stages: bool,
    /// Where the stages' tables are compiled (cached).
    #[arg(long, default_value = "out")]
    pub tables: PathBuf,
}

#[derive(clap::Args)]
pub struct BenchArgs {
    /// Pipeline file.
    #[arg(default_value = "pipelines/default.ron")]
    pub pipeline: PathBuf,
    /// Which benchmark to run.
    #[arg(long, value_enum, default_value_t = Suite::Tables)]
    pub suite: Suite,
    /// Print the rows as JSON.
    #[arg(long)]
    pub json: bool,
    /// Only tables with these ids (all when absent); with `--suite shards`, tables or bake stages.
    #[arg(long, num_args = 1..)]
    pub only: Vec<String>,
    /// Skip the whole-pipeline compile comparisons (cold vs up-to-date, 1 vs N threads), which compile
    /// the pipeline three times; keep the per-table rows (zstd levels, ZH query throughput).
    #[arg(long)]
    pub tables_only: bool,
    /// Ray queries on a procedural scene of at least TRIANGLES triangles (default 1048576): with the
    /// tables suite, also run the ray benchmark; with `--suite rays`, its size.
    #[arg(long, value_name = "TRIANGLES", num_args = 0..=1, default_missing_value = "1048576")]
    pub rays: Option<usize>,
    /// Where the stages' tables are compiled (cached).
    #[arg(long, default_value = "out")]
    pub tables: PathBuf,
}

/// The benchmark suites of `voltab bench --suite`.
#[derive(Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Suite {
    /// The pipeline's tables: cold vs no-op compile, 1 vs N threads, zstd levels, ZH query throughput.
    Tables,
    /// Ray queries (BVH build; primary, incoherent and shadow rays; 1 vs N threads) on a procedural
    /// scene (no pipeline tables).
    Rays,
    /// The BakeLightmaps stages: texels/s and rays/s per mode, the Full/Surface overhead, and the
    /// speed-up over volumetric path tracing at equal error.
    Bake,
    /// The EpipolarShadows and ImageFog stages: the epipolar speed-up over ray marching at equal error
    /// (1 and 2 threads), the time-vs-resolution slopes and the whole god-ray frame at 640×480 and
    /// 1280×720; fog frame times at 720p and 1080p and the speed-up over the gathering reference.
    Effects,
    /// The TranslucentRender stages: wang2018 Table 3's time split per material at the stage's size and
    /// at 512×512, memory, naive vs two-step traversal, and the speed-up over path tracing at equal MSE
    /// (about 5 min for the default pipeline).
    Translucent,
    /// The PopRender stages: the frame split into elek2014 Fig. 14's phases and the isotropic
    /// residuum's speed-up over anisotropic propagation to convergence.
    Pop,
    /// The real-time effects on the CPU and on the GPU side by side, with per-pass GPU times
    /// (timestamp queries where the adapter has them; CPU times on lavapipe). Needs the `gpu` feature.
    Gpu,
    /// Scale-out: each table (--only, default the MsLobes tables) compiled whole vs as its work units
    /// plus the merge, and the bakes as tiles; overhead, merge share, and the wall time projected on 1,
    /// 8, 64 and 512 nodes (and at wang2018's size for lobe tables).
    Shards,
}

#[derive(clap::Args)]
pub struct StabilityArgs {
    /// Print passing rows too.
    #[arg(long)]
    pub all: bool,
}

#[derive(clap::Args)]
pub struct ValidateArgs {
    /// Pipeline file.
    #[arg(default_value = "pipelines/default.ron")]
    pub pipeline: PathBuf,
    /// Only these stage ids (all when absent).
    #[arg(long, num_args = 1.., value_delimiter = ',')]
    pub stages: Vec<String>,
    /// quick: low resolution and few texels (minutes; CI); full: the stages' own size (opt-in, long).
    #[arg(long, value_enum, default_value = "quick")]
    pub quality: voltab::validation::Quality,
    /// Output folder.
    #[arg(long, default_value = "out/validate")]
    pub out: PathBuf,
    /// Where the pipeline's tables are compiled (cached).
    #[arg(long, default_value = "out")]
    pub tables: PathBuf,
}

#[derive(clap::Args)]
pub struct SchemaArgs {
    /// Folder to write into.
    #[arg(long, default_value = "schemas")]
    pub dir: PathBuf,
    /// Fail if the files differ instead of writing them.
    #[arg(long)]
    pub check: bool,
}

#[derive(Subcommand)]
pub enum ExportCommand {
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
pub enum EvalCommand {
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
pub struct EvalLobes {
    /// A compiled MsLobes table (.vtab).
    #[arg(long)]
    pub table: PathBuf,
    /// Single-scattering albedo in [0, 1].
    #[arg(long)]
    pub albedo: f64,
    /// HG mean cosine, within the table's g range.
    #[arg(long, default_value_t = 0.0)]
    pub g: f64,
    /// Distance from the beam axis (mean free paths).
    #[arg(long)]
    pub rho: f64,
    /// Depth along the beam from its origin (mean free paths; negative behind it).
    #[arg(long)]
    pub z: f64,
    /// Angle between the outgoing direction and the axis from the beam origin to the point (degrees).
    #[arg(long)]
    pub theta: f64,
    /// Full-lobe tables: azimuth about that axis from the plane of the beam (degrees, 0 to 180).
    #[arg(long, default_value_t = 0.0)]
    pub phi: f64,
    /// Print JSON (keys: total, double).
    #[arg(long)]
    pub json: bool,
}

#[derive(clap::Args)]
#[command(allow_negative_numbers = true)]
pub struct EvalZh {
    /// A compiled ZhResponse table (.vtab).
    #[arg(long)]
    pub table: PathBuf,
    /// Emitter profile.
    #[arg(long, value_enum)]
    pub emitter: EvalEmitter,
    /// Point: intensity (W/sr). Area: intensity along the patch normal (W/sr). Directional: irradiance at
    /// the medium boundary (W/m^2).
    #[arg(long, default_value_t = 1.0)]
    pub intensity: f64,
    /// Distance to the point light, or depth below the boundary toward the directional light (m).
    #[arg(long)]
    pub distance: f64,
    /// Angle between the receiver normal and the direction toward the light (degrees).
    #[arg(long, default_value_t = 0.0)]
    pub normal_angle: f64,
    /// Area emitter: angle between the patch normal and the direction from the patch to the receiver
    /// (degrees; 0 = facing the receiver, > 90 = facing away).
    #[arg(long, default_value_t = 0.0)]
    pub patch_angle: f64,
    /// Scattering coefficient (1/m).
    #[arg(long)]
    pub sigma_s: f64,
    /// Absorption coefficient (1/m).
    #[arg(long, default_value_t = 0.0)]
    pub sigma_a: f64,
    /// HG mean cosine, within the table's g range.
    #[arg(long, default_value_t = 0.0)]
    pub g: f64,
    /// Apply the table's back-scatter shift (dubouchet2019 Sec. 5.2; a surface heuristic, off for a
    /// receiver inside the medium).
    #[arg(long)]
    pub backscatter: bool,
    /// Leave out the tail closure (orders beyond the table's B).
    #[arg(long)]
    pub no_tail: bool,
    /// Similarity relation (1 - g) sigma_s, g = 0 for the multiple-scattering orders.
    #[arg(long)]
    pub similarity: bool,
    /// Highest scattering order summed (default: all the table holds).
    #[arg(long)]
    pub max_bounce: Option<usize>,
    /// Print JSON (keys: direct, single, multiple, tail, total).
    #[arg(long)]
    pub json: bool,
}

#[derive(Clone, Copy, clap::ValueEnum)]
pub enum EvalEmitter {
    Point,
    Directional,
    Area,
}
