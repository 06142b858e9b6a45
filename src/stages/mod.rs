//! Stages (the consumers): each reads compiled tables — only the slices it needs — and writes
//! results (images, lightmaps, renders). `voltab run` runs them after compiling the tables.
//!
//! Input: a [`StageDef`] validated against the pipeline (its table references resolve to tables
//! of the right kind) and the output folder holding the compiled tables. Output: files in that
//! folder, listed in a [`StageOutcome`].

pub mod bake;
pub mod god_rays;
pub mod image_fog;
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

impl StageKind for StageDef {
    fn kind(&self) -> &'static str {
        match self {
            StageDef::PlotPhase(_) => plot_phase::PlotPhaseRaw::KIND,
            StageDef::BakeLightmaps(_) => bake::BakeLightmapsRaw::KIND,
            StageDef::EpipolarShadows(_) => god_rays::EpipolarShadowsRaw::KIND,
            StageDef::ImageFog(_) => image_fog::ImageFogRaw::KIND,
            StageDef::TranslucentRender(_) => translucent::TranslucentRenderRaw::KIND,
            StageDef::PopRender(_) => pop::PopRenderRaw::KIND,
        }
    }
    fn table_refs(&self) -> Vec<(&'static str, String, &'static str)> {
        match self {
            StageDef::PlotPhase(p) => vec![("table", p.table.clone(), crate::tables::phase_hg::PhaseHgRaw::KIND)],
            StageDef::BakeLightmaps(b) => b
                .table_ref()
                .map(|t| ("table", t.to_string(), crate::tables::zh_response::ZhResponseRaw::KIND))
                .into_iter()
                .collect(),
            StageDef::TranslucentRender(t) => {
                let kind = crate::tables::ms_lobes::MsLobesRaw::KIND;
                let mut v = vec![("table", t.table.clone(), kind)];
                v.extend(t.lobe_tables.iter().map(|l| ("lobe_tables", l.clone(), kind)));
                v
            }
            StageDef::PopRender(p) => {
                vec![("table", p.table.clone(), crate::tables::pop_preset::PopPresetRaw::KIND)]
            }
            StageDef::EpipolarShadows(_) | StageDef::ImageFog(_) => Vec::new(),
        }
    }
    fn validate(&self) -> Vec<FieldIssue> {
        match self {
            StageDef::PlotPhase(p) => p.validate(),
            StageDef::BakeLightmaps(b) => b.validate(),
            StageDef::EpipolarShadows(e) => e.validate(),
            StageDef::ImageFog(f) => f.validate(),
            StageDef::TranslucentRender(t) => t.validate(),
            StageDef::PopRender(p) => p.validate(),
        }
    }
    fn check_tables(&self, id: &str, table: &dyn Fn(&str) -> Option<TableDef>) -> Vec<FieldIssue> {
        match self {
            StageDef::PlotPhase(p) => table(&p.table).and_then(|t| p.check_table(id, &t)).into_iter().collect(),
            _ => Vec::new(),
        }
    }
}

impl StageDef {
    /// Scene files the stage reads, resolved against `base_dir` (the pipeline's folder).
    pub fn scenes(&self, base_dir: &Path) -> Vec<PathBuf> {
        match self {
            StageDef::PlotPhase(_) => Vec::new(),
            StageDef::BakeLightmaps(b) => vec![b.scene_path(base_dir)],
            StageDef::EpipolarShadows(e) => vec![e.scene_path(base_dir)],
            StageDef::ImageFog(f) => vec![f.scene_path(base_dir)],
            StageDef::TranslucentRender(t) => vec![t.scene_path(base_dir)],
            StageDef::PopRender(p) => vec![p.scene_path(base_dir)],
        }
    }
    /// Error against run time for stages that have a reference (`voltab report --stages`): Markdown text,
    /// or `None` for stages without one.
    pub fn report(&self, id: &str, ctx: &StageContext, report_dir: &Path) -> Result<Option<String>, StageError> {
        match self {
            StageDef::PlotPhase(_) => Ok(None),
            StageDef::BakeLightmaps(b) => {
                let r = b.report(id, ctx, report_dir, &bake::report::LadderOptions::default())?;
                Ok(Some(bake::report::markdown(&r)))
            }
            StageDef::EpipolarShadows(e) => e.report(id, ctx, report_dir).map(Some),
            StageDef::ImageFog(f) => f.report(id, ctx, report_dir).map(Some),
            StageDef::TranslucentRender(t) => t.report(id, ctx, report_dir).map(Some),
            StageDef::PopRender(p) => p.report(id, ctx, report_dir).map(Some),
        }
    }

    /// The `voltab bench` focus whose run includes this stage's [`StageDef::bench`]; `None` for stages
    /// without a benchmark.
    pub fn bench_focus(&self) -> Option<BenchFocus> {
        match self {
            StageDef::PlotPhase(_) => None,
            StageDef::BakeLightmaps(_) => Some(BenchFocus::Bake),
            StageDef::EpipolarShadows(_) | StageDef::ImageFog(_) => Some(BenchFocus::Effects),
            StageDef::TranslucentRender(_) => Some(BenchFocus::Translucent),
            StageDef::PopRender(_) => Some(BenchFocus::Pop),
        }
    }

    /// `voltab bench --suite bake | effects | translucent | pop`: the stage's own benchmark, its text
    /// (empty for the bake, whose rows say it all) and rows; `None` for stages without one.
    pub fn bench(&self, id: &str, ctx: &StageContext) -> Result<Option<(String, Vec<BenchRow>)>, StageError> {
        match self {
            StageDef::PlotPhase(_) => Ok(None),
            StageDef::BakeLightmaps(b) => b.bench(id, ctx).map(|rows| Some((String::new(), rows))),
            StageDef::EpipolarShadows(e) => e.bench(id, ctx).map(Some),
            StageDef::ImageFog(f) => f.bench(id, ctx).map(Some),
            StageDef::TranslucentRender(t) => t.bench(id, ctx).map(Some),
            StageDef::PopRender(p) => p.bench(id, ctx).map(Some),
        }
    }

    /// `voltab bench --suite gpu`: the effect's frame on the CPU and on `ctx.device` side by side, with the
    /// GPU's per-pass times; `None` for stages without a GPU path.
    pub fn bench_gpu(
        &self,
        id: &str,
        ctx: &StageContext,
    ) -> Result<Option<(String, Vec<crate::stages::BenchRow>)>, StageError> {
        match self {
            StageDef::PopRender(p) => p.bench_gpu(id, ctx).map(Some),
            StageDef::EpipolarShadows(e) => e.bench_gpu(id, ctx).map(Some),
            _ => Ok(None),
        }
    }

    /// True for the real-time effects, which run on [`StageContext::device`].
    pub fn uses_device(&self) -> bool {
        matches!(self, StageDef::EpipolarShadows(_) | StageDef::ImageFog(_) | StageDef::PopRender(_))
    }

    /// Runs the stage on tables compiled into `ctx.out_dir`.
    pub fn run(&self, id: &str, ctx: &StageContext) -> Result<StageOutcome, StageError> {
        match self {
            StageDef::PlotPhase(p) => p.run(id, ctx.out_dir),
            StageDef::BakeLightmaps(b) => b.run(id, ctx),
            StageDef::EpipolarShadows(e) => e.run(id, ctx),
            StageDef::ImageFog(f) => f.run(id, ctx),
            StageDef::TranslucentRender(t) => t.run(id, ctx),
            StageDef::PopRender(p) => p.run(id, ctx),
        }
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
