//! A stage's side of planning: each stage kind says, in its own folder, whether a run needs it.
//!
//! **Input → output.** The run's planned scenes ([`PlannedScenes`]) and the definitions of the tables
//! the plan keeps → a [`StageDecision`]: run (with the definition pruned to what was kept, and why) or
//! skip (and why). `crate::plan` asks every stage through [`super::Stage::plan`] and turns the answers
//! into its report; it no longer matches on the stage kinds. The user's rule "leave out what a given
//! scene does not need" applies here: an effect runs only on a planned scene that holds what it renders.

use std::path::{Path, PathBuf};

use super::StageDef;
use crate::scene::Scene;
use crate::tables::TableDef;

/// The scenes a run plans for, and the pipeline's folder their stage paths are relative to.
#[derive(Debug, Clone, Copy)]
pub struct PlannedScenes<'a> {
    /// The pipeline file's folder.
    pub base: &'a Path,
    /// The planned scenes.
    pub scenes: &'a [&'a Scene],
}

impl<'a> PlannedScenes<'a> {
    /// The planned scene a stage names by `path` (relative to the pipeline's folder): the same file
    /// after canonicalising both, or the same path when either cannot be canonicalised.
    pub fn find(&self, path: &str) -> Option<&'a Scene> {
        let path: PathBuf = self.base.join(path);
        let same = |a: &Path| match (a.canonicalize(), path.canonicalize()) {
            (Ok(x), Ok(y)) => x == y,
            _ => a == path,
        };
        self.scenes.iter().copied().find(|sc| same(&sc.source))
    }
}

/// What a stage decides for a run.
#[derive(Debug, Clone)]
pub enum StageDecision {
    /// The stage runs with `def` (its definition, pruned to the tables the plan keeps).
    Run {
        /// Why, for the plan's report.
        reason: String,
        /// The definition to run (boxed: a definition is large, a skip is a line of text).
        def: Box<StageDef>,
    },
    /// The stage is left out.
    Skip {
        /// Why, for the plan's report.
        reason: String,
    },
}

/// Two g values closer than this are the same node (the plan's slice matching and `PlotPhase`'s g list).
pub const ON_NODE: f64 = 1e-12;

/// The tables a plan keeps: the (pruned) definition of each compiled table, `None` for a skipped one.
pub type KeptTables<'a> = dyn Fn(&str) -> Option<&'a TableDef> + 'a;

/// A stage that reads table `table` is skipped when the plan skips that table.
pub fn table_skipped(table: &str) -> StageDecision {
    StageDecision::Skip { reason: format!("its table {table} is skipped") }
}

/// The decision of a real-time effect or renderer drawing `effect` on `scene`: skipped when the scene is
/// not planned or `lacks` names what it is missing; otherwise run with `def` as declared.
pub fn effect(
    def: StageDef,
    effect: &str,
    scene: &str,
    scenes: &PlannedScenes,
    lacks: impl Fn(&Scene) -> Option<&'static str>,
) -> StageDecision {
    match scenes.find(scene) {
        None => StageDecision::Skip { reason: format!("its scene {scene} is not among the planned scenes") },
        Some(sc) => match lacks(sc) {
            Some(what) => StageDecision::Skip { reason: format!("{scene} has no {what}") },
            None => StageDecision::Run { reason: format!("renders {effect} of {scene}"), def: Box::new(def) },
        },
    }
}
