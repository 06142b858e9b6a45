//! The registry: voltab's stage kinds bound to the kind-agnostic layers below them.
//!
//! Input: the stage kinds ([`StageDecl`] as written, [`StageDef`] resolved) and every kind's
//! stability rows. Output: the front end instantiated for them — [`load`], [`validate`],
//! [`load_and_validate`] → [`ValidatedPipeline`], the [`json_schema`] and [`reference_markdown`]
//! pages — and the whole extreme-input matrix ([`stability_rows`]).
//!
//! The front end (`pipeline`), the table kinds (`tables`), the container and the cache never import
//! a consumer: they take the stage kinds as a type parameter ([`crate::pipeline::StageKinds`]) and
//! this module, at the top of the import graph, supplies it. Adding a stage kind touches its folder,
//! the two enums in [`crate::stages`] and nothing below them.

use std::path::Path;

use crate::pipeline::{self, Limits, PipelineError, Sources};
use crate::stability::Row;
use crate::stages::{StageDecl, StageDef};

/// One pipeline file as written, with voltab's stage kinds.
pub type PipelineFile = pipeline::PipelineFile<StageDecl>;
/// A pipeline's entries as loaded (before validation).
pub type Loaded = pipeline::parse::Loaded<StageDecl>;
/// A validated pipeline of voltab's stage kinds.
pub type ValidatedPipeline = pipeline::ValidatedPipeline<StageDef>;
/// A validated stage of one of voltab's stage kinds.
pub type ValidatedStage = pipeline::ValidatedStage<StageDef>;

/// Loads `path` and everything it includes.
pub fn load(path: &Path, sources: &dyn Sources) -> Result<Loaded, PipelineError> {
    pipeline::parse::load::<StageDecl>(path, sources)
}

/// Validates loaded entries.
pub fn validate(root: &Path, loaded: Loaded, limits: &Limits) -> Result<ValidatedPipeline, PipelineError> {
    pipeline::validate::validate(root, loaded, limits)
}

/// Loads and validates a pipeline file with the machine's limits.
pub fn load_and_validate(path: &Path, sources: &dyn Sources) -> Result<ValidatedPipeline, PipelineError> {
    pipeline::validate::load_and_validate::<StageDecl>(path, sources)
}

/// JSON Schema of a pipeline file (`schemas/pipeline.schema.json`).
pub fn json_schema() -> serde_json::Value {
    pipeline::schema::json_schema::<StageDecl>()
}

/// The human reference page (`schemas/reference.md`).
pub fn reference_markdown() -> String {
    pipeline::schema::reference_markdown::<StageDecl>()
}

/// Every stability row of every table kind and technique (`voltab stability`, `tests/stability.rs`).
pub fn stability_rows() -> Vec<Row> {
    let mut v = Vec::new();
    v.extend(crate::tables::phase_hg::stability_rows());
    v.extend(crate::tables::zh_response::stability_rows());
    v.extend(crate::tables::ms_lobes::stability_rows());
    v.extend(crate::tables::pop_preset::stability_rows());
    v.extend(crate::stages::pop::radial::stability_rows());
    v.extend(crate::stages::image_fog::medium::stability_rows());
    v.extend(crate::stages::translucent::render::stability_rows());
    v
}
