//! Stages (the consumers): each reads compiled tables — only the slices it needs — and writes
//! results (images, lightmaps, renders). `voltab run` runs them after compiling the tables.
//!
//! Input: a [`StageDef`] validated against the pipeline (its table references resolve to tables
//! of the right kind) and the output folder holding the compiled tables. Output: files in that
//! folder, listed in a [`StageOutcome`].

pub mod bake;
pub mod god_rays;
pub mod image_fog;
pub mod planning;
pub mod plot_phase;
pub mod pop;
pub mod translucent;
pub mod view;

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use crate::pipeline::kinds::{KindDoc, StageKind, StageKinds};
use crate::tables::{FieldIssue, TableDef};

/// The stages' own benchmarks, one per `voltab bench --suite` (`bake`, `effects`, `translucent`,
/// `pop`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum BenchFocus {
    /// Lightmap bakes.
    Bake,
    /// The real-time effects: god rays and image-space fog.
    Effects,
    /// Translucent media.
    Translucent,
    /// Principal-ordinates propagation.
    Pop,
}

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

/// A stage entry as written in a pipeline file.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[non_exhaustive]
pub enum StageDecl {
    /// Plots phase functions of a `PhaseHg` table to a PNG (log scale over angle).
    PlotPhase(plot_phase::PlotPhaseRaw),
    /// Bakes lightmaps and probes of a scene with volume-to-surface transport (dubouchet2019).
    BakeLightmaps(bake::BakeLightmapsRaw),
    /// Renders god rays (shadowed single scattering) of a scene with epipolar partial-sum trees (baran2010).
    EpipolarShadows(god_rays::EpipolarShadowsRaw),
    /// Applies image-space multiple-scattering fog to a view of a scene (iser2018).
    ImageFog(image_fog::ImageFogRaw),
    /// Renders a scene's translucent object with point-based light samples and an `MsLobes` table (wang2018).
    TranslucentRender(translucent::TranslucentRenderRaw),
    /// Renders a scene's global medium lit by directional lights with Principal-Ordinates Propagation (elek2014).
    PopRender(pop::PopRenderRaw),
}

/// A resolved stage definition.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[non_exhaustive]
pub enum StageDef {
    /// See [`plot_phase`].
    PlotPhase(plot_phase::PlotPhase),
    /// See [`bake`].
    BakeLightmaps(bake::BakeLightmaps),
    /// See [`god_rays`].
    EpipolarShadows(god_rays::EpipolarShadows),
    /// See [`image_fog`].
    ImageFog(image_fog::ImageFogStage),
    /// See [`translucent`].
    TranslucentRender(translucent::TranslucentRender),
    /// See [`pop`].
    PopRender(pop::PopRender),
}

/// Where a stage runs.
#[derive(Debug, Clone, Copy)]
pub struct StageContext<'a> {
    /// The output folder (compiled tables are read from it; results are written into it).
    pub out_dir: &'a Path,
    /// The folder of the pipeline file: relative paths in stage definitions (scenes) resolve against it.
    pub base_dir: &'a Path,
    /// Show progress bars (only on a terminal).
    pub progress: bool,
    /// Where the real-time effects (`PopRender`, `EpipolarShadows`, `ImageFog`) run; the other
    /// stages ignore it.
    pub device: &'a crate::render::gpu::Device,
    /// The run's imported scenes: a scene the planner or an earlier stage read is not imported again.
    pub scenes: &'a crate::scene::cache::SceneCache,
}

/// What a stage wrote.
#[derive(Debug, Clone, Default, Serialize, Deserialize)]
pub struct StageOutcome {
    /// Files written.
    pub outputs: Vec<PathBuf>,
    /// One line for the terminal.
    pub summary: String,
}

/// One stage kind's behaviour, implemented in the kind's own folder: its table references, range
/// checks, scenes, run, report ladder and benchmarks. [`StageDef`] dispatches to it through
/// [`StageDef::stage`] (one match), and so does the front end through [`StageKind`].
pub trait Stage: Sync {
    /// Kind name as written in RON.
    fn kind(&self) -> &'static str;
    /// (field, referenced table id, required table kind) for every table this stage reads.
    fn table_refs(&self) -> Vec<(&'static str, String, &'static str)> {
        Vec::new()
    }
    /// Range checks.
    fn validate(&self) -> Vec<FieldIssue>;
    /// Problems only the referenced tables' definitions reveal (see [`StageKind::check_tables`]).
    fn check_tables(&self, _id: &str, _table: &dyn Fn(&str) -> Option<TableDef>) -> Vec<FieldIssue> {
        Vec::new()
    }
    /// Scene files the stage reads, resolved against `base_dir` (the pipeline's folder).
    fn scenes(&self, _base_dir: &Path) -> Vec<PathBuf> {
        Vec::new()
    }
    /// Whether a run on the planned `scenes` needs the stage, given the tables the plan keeps, and its
    /// definition pruned to them ([`planning`]).
    fn plan(&self, scenes: &planning::PlannedScenes, kept: &planning::KeptTables) -> planning::StageDecision;
    /// The `MsLobes` materials the stage reads when its scene is planned: the plan keeps their slices
    /// like those of a scene's own translucent media. None by default.
    fn lobe_materials(&self, _scenes: &planning::PlannedScenes) -> Vec<String> {
        Vec::new()
    }
    /// Runs the stage on tables compiled into `ctx.out_dir`.
    fn run(&self, id: &str, ctx: &StageContext) -> Result<StageOutcome, StageError>;
    /// Error against run time for stages that have a reference (`voltab report --stages`): Markdown
    /// text, or `None` for stages without one.
    fn report(&self, _id: &str, _ctx: &StageContext, _report_dir: &Path) -> Result<Option<String>, StageError> {
        Ok(None)
    }
    /// The `voltab bench` suite whose run includes this stage's [`Stage::bench`]; `None` for stages
    /// without a benchmark.
    fn bench_focus(&self) -> Option<BenchFocus> {
        None
    }
    /// `voltab bench --suite bake | effects | translucent | pop`: the stage's own benchmark, its text
    /// and rows; `None` for stages without one.
    fn bench(&self, _id: &str, _ctx: &StageContext) -> Result<Option<(String, Vec<BenchRow>)>, StageError> {
        Ok(None)
    }
    /// `voltab bench --suite gpu`: the effect's frame on the CPU and on `ctx.device` side by side, with
    /// the GPU's per-pass times; `None` for stages without a GPU path.
    fn bench_gpu(&self, _id: &str, _ctx: &StageContext) -> Result<Option<(String, Vec<BenchRow>)>, StageError> {
        Ok(None)
    }
    /// True for the real-time effects, which run on [`StageContext::device`].
    fn uses_device(&self) -> bool {
        false
    }
}

/// A stage failed.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum StageError {
    /// Reading a table failed.
    #[error("stage \"{stage}\": cannot read table {path}: {message}")]
    Table {
        /// Stage id.
        stage: String,
        /// Table file.
        path: PathBuf,
        /// Why.
        message: String,
    },
    /// The stage's inputs are unusable (a missing or broken scene, a table that cannot answer).
    #[error("stage \"{stage}\": {message}\n  help: {help}")]
    Input {
        /// Stage id.
        stage: String,
        /// What is wrong.
        message: String,
        /// How to fix it.
        help: String,
    },
    /// Writing an output failed.
    #[error("stage \"{stage}\": cannot write {path}: {message}")]
    Output {
        /// Stage id.
        stage: String,
        /// Output file.
        path: PathBuf,
        /// Why.
        message: String,
    },
}

impl StageKinds for StageDecl {
    type Def = StageDef;
    const ENUM_NAME: &'static str = "StageDecl";
    fn kind(&self) -> &'static str {
        match self {
            StageDecl::PlotPhase(_) => plot_phase::PlotPhaseRaw::KIND,
            StageDecl::BakeLightmaps(_) => bake::BakeLightmapsRaw::KIND,
            StageDecl::EpipolarShadows(_) => god_rays::EpipolarShadowsRaw::KIND,
            StageDecl::ImageFog(_) => image_fog::ImageFogRaw::KIND,
            StageDecl::TranslucentRender(_) => translucent::TranslucentRenderRaw::KIND,
            StageDecl::PopRender(_) => pop::PopRenderRaw::KIND,
        }
    }
    fn id(&self) -> Option<&str> {
        match self {
            StageDecl::PlotPhase(r) => r.id.as_deref(),
            StageDecl::BakeLightmaps(r) => r.id.as_deref(),
            StageDecl::EpipolarShadows(r) => r.id.as_deref(),
            StageDecl::ImageFog(r) => r.id.as_deref(),
            StageDecl::TranslucentRender(r) => r.id.as_deref(),
            StageDecl::PopRender(r) => r.id.as_deref(),
        }
    }
    fn resolve(&self) -> StageDef {
        match self {
            StageDecl::PlotPhase(r) => StageDef::PlotPhase(r.resolve()),
            StageDecl::BakeLightmaps(r) => StageDef::BakeLightmaps(r.resolve()),
            StageDecl::EpipolarShadows(r) => StageDef::EpipolarShadows(r.resolve()),
            StageDecl::ImageFog(r) => StageDef::ImageFog(r.resolve()),
            StageDecl::TranslucentRender(r) => StageDef::TranslucentRender(r.resolve()),
            StageDecl::PopRender(r) => StageDef::PopRender(r.resolve()),
        }
    }
    fn docs() -> Vec<KindDoc> {
        use bake::{BakeLightmaps, BakeLightmapsRaw};
        use god_rays::{EpipolarShadows, EpipolarShadowsRaw};
        use image_fog::{ImageFogRaw, ImageFogStage};
        use plot_phase::{PlotPhase, PlotPhaseRaw};
        use pop::{PopRender, PopRenderRaw};
        use translucent::{TranslucentRender, TranslucentRenderRaw};
        vec![
            (
                PlotPhaseRaw::KIND,
                "Plots a PhaseHg table's phase functions (log scale over angle) to a PNG, loading only the g slices it plots.",
                PlotPhaseRaw::FIELDS,
                PlotPhase::defaults_json(),
            ),
            (BakeLightmapsRaw::KIND, BakeLightmapsRaw::ABOUT, BakeLightmapsRaw::FIELDS, BakeLightmaps::defaults_json()),
            (
                EpipolarShadowsRaw::KIND,
                EpipolarShadowsRaw::ABOUT,
                EpipolarShadowsRaw::FIELDS,
                EpipolarShadows::defaults_json(),
            ),
            (ImageFogRaw::KIND, ImageFogRaw::ABOUT, ImageFogRaw::FIELDS, ImageFogStage::defaults_json()),
            (
                TranslucentRenderRaw::KIND,
                TranslucentRenderRaw::ABOUT,
                TranslucentRenderRaw::FIELDS,
                TranslucentRender::defaults_json(),
            ),
            (PopRenderRaw::KIND, PopRenderRaw::ABOUT, PopRenderRaw::FIELDS, PopRender::defaults_json()),
        ]
    }
}

impl StageDef {
    /// The stage behind the definition: every question about a stage goes through this one match.
    pub fn stage(&self) -> &dyn Stage {
        match self {
            StageDef::PlotPhase(s) => s,
            StageDef::BakeLightmaps(s) => s,
            StageDef::EpipolarShadows(s) => s,
            StageDef::ImageFog(s) => s,
            StageDef::TranslucentRender(s) => s,
            StageDef::PopRender(s) => s,
        }
    }
}

impl StageKind for StageDef {
    fn kind(&self) -> &'static str {
        self.stage().kind()
    }
    fn table_refs(&self) -> Vec<(&'static str, String, &'static str)> {
        self.stage().table_refs()
    }
    fn validate(&self) -> Vec<FieldIssue> {
        self.stage().validate()
    }
    fn check_tables(&self, id: &str, table: &dyn Fn(&str) -> Option<TableDef>) -> Vec<FieldIssue> {
        self.stage().check_tables(id, table)
    }
}

/// What an effect stage's frame ran on: the output, the device's name, the GPU time per phase, and
/// why the CPU ran although a GPU was selected.
pub(crate) type DeviceRun<T> = (T, &'static str, Vec<image_fog::GpuPhase>, Option<String>);

/// An effect's GPU `result` as a [`DeviceRun`]: its phases on success; on a device limit (an input
/// the GPU path refuses) the CPU frame from `cpu`, with the limit in the note; any other device error
/// as a stage error naming `effect`.
#[cfg(feature = "gpu")]
pub(crate) fn device_run<T>(
    id: &str,
    ctx: &StageContext,
    effect: &str,
    result: Result<(T, Vec<crate::render::gpu::PassTime>), crate::render::gpu::GpuError>,
    cpu: impl FnOnce() -> T,
) -> Result<DeviceRun<T>, StageError> {
    match result {
        Ok((out, times)) => {
            let phases = times
                .into_iter()
                .map(|t| image_fog::GpuPhase { phase: t.phase, ms: t.seconds * 1e3, passes: t.passes })
                .collect();
            Ok((out, ctx.device.name(), phases, None))
        }
        Err(crate::render::gpu::GpuError::Limit(why)) => {
            Ok((cpu(), "cpu", Vec::new(), Some(format!("GPU selected but the CPU path ran: {why}"))))
        }
        Err(e) => Err(StageError::Input {
            stage: id.into(),
            message: format!("GPU {effect} failed: {e}"),
            help: "run with --device cpu".into(),
        }),
    }
}

/// Checks an output file name: a plain name (no folders) with the given extension.
pub fn check_output_name(field: &'static str, name: &str, ext: &str) -> Option<FieldIssue> {
    let ok = name.is_empty()
        || (name.ends_with(ext)
            && !name.starts_with('.')
            && name.chars().all(|c| c.is_ascii_alphanumeric() || matches!(c, '_' | '-' | '.')));
    (!ok).then(|| FieldIssue {
        field,
        message: format!("{field} = \"{name}\" is not a plain {ext} file name"),
        help: format!(
            "use a name like \"phase{ext}\" (letters, digits, '_', '-', '.'); it is written into the output folder"
        ),
    })
}
