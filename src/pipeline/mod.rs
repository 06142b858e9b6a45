//! The pipeline language (the compiler's front end): RON files declaring tables, presets,
//! overrides, includes and stages → a [`ValidatedPipeline`].
//!
//! Data flow: [`parse::load`] reads a file and its includes into typed, located entries;
//! [`validate::validate`] resolves presets/overrides, fills defaults, range-checks every field,
//! checks references and memory, and computes content keys. Only validation builds the
//! `Validated*` types the rest of voltab accepts.

pub mod error;
pub mod kinds;
pub mod locate;
pub mod params;
pub mod parse;
pub mod schema;
pub mod validate;

pub use error::{Diagnostic, DiagnosticKind, Loc, PipelineError};
pub use kinds::{KindDoc, StageKind, StageKinds};
pub use parse::{Disk, Embedded, PipelineFile, Sources};
pub use validate::{Limits, ValidatedPipeline, ValidatedStage, ValidatedTable, load_and_validate, validate};
