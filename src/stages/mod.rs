//! Stages (the consumers): each reads compiled tables — only the slices it needs — and writes
//! results (images, lightmaps, renders). `voltab run` runs them after compiling the tables.
//!
//! Input: a [`StageDef`] validated against the pipeline (its table references resolve to tables
//! of the right kind) and the output folder holding the compiled tables. Output: files in that
//! folder, listed in a [`StageOutcome`].

pub mod plot_phase;

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use crate::tables::FieldIssue;

/// A stage entry as written in a pipeline file.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[non_exhaustive]
pub enum StageDecl {
    /// Plots phase functions of a `PhaseHg` table to a PNG (log scale over angle).
    PlotPhase(plot_phase::PlotPhaseRaw),
}

/// A resolved stage definition.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[non_exhaustive]
pub enum StageDef {
    /// See [`plot_phase`].
    PlotPhase(plot_phase::PlotPhase),
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

impl StageDecl {
    /// Kind name as written in RON.
    pub fn kind(&self) -> &'static str {
        match self {
            StageDecl::PlotPhase(_) => plot_phase::PlotPhaseRaw::KIND,
        }
    }
    /// The entry's id.
    pub fn id(&self) -> Option<&str> {
        match self {
            StageDecl::PlotPhase(r) => r.id.as_deref(),
        }
    }
    /// Fills defaults.
    pub fn resolve(&self) -> StageDef {
        match self {
            StageDecl::PlotPhase(r) => StageDef::PlotPhase(r.resolve()),
        }
    }
}

impl StageDef {
    /// Kind name.
    pub fn kind(&self) -> &'static str {
        match self {
            StageDef::PlotPhase(_) => plot_phase::PlotPhaseRaw::KIND,
        }
    }
    /// (field, referenced table id, required table kind) for every table this stage reads.
    pub fn table_refs(&self) -> Vec<(&'static str, String, &'static str)> {
        match self {
            StageDef::PlotPhase(p) => vec![("table", p.table.clone(), crate::tables::phase_hg::PhaseHgRaw::KIND)],
        }
    }
    /// Range checks.
    pub fn validate(&self) -> Vec<FieldIssue> {
        match self {
            StageDef::PlotPhase(p) => p.validate(),
        }
    }
    /// Runs the stage on tables compiled into `out_dir`.
    pub fn run(&self, id: &str, out_dir: &Path) -> Result<StageOutcome, StageError> {
        match self {
            StageDef::PlotPhase(p) => p.run(id, out_dir),
        }
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
