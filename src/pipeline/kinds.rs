//! What the front end knows about stage kinds: two traits, nothing more. The front end never
//! names a stage; the consumer layer implements [`StageKinds`] on its declaration enum and
//! [`StageKind`] on its resolved definition, and `crate::registry` hands them in as type
//! parameters (`parse::load::<S>`, `validate::validate::<S>`, `schema::json_schema::<S>`).
//!
//! Input: a stage entry as written in RON. Output: its kind, id, resolved definition, table
//! references and range problems — everything parsing, validation and the schema need.

use std::fmt::Debug;

use serde::Serialize;
use serde::de::DeserializeOwned;
use serde_json::Value;

use super::params::FieldDoc;
use crate::tables::{FieldIssue, TableDef};

/// (kind, what it is, fields, defaults) of one table or stage kind, for the schema.
pub type KindDoc = (&'static str, &'static str, &'static [FieldDoc], Vec<(&'static str, Value)>);

/// The stage entries a pipeline file may hold (an enum with one variant per kind).
pub trait StageKinds: Clone + Debug + PartialEq + Serialize + DeserializeOwned + schemars::JsonSchema {
    /// The resolved definition an entry becomes.
    type Def: StageKind;
    /// The enum's Rust name: RON names it as the context of an unknown-variant error.
    const ENUM_NAME: &'static str;
    /// Kind name as written in RON.
    fn kind(&self) -> &'static str;
    /// The entry's id.
    fn id(&self) -> Option<&str>;
    /// Fills defaults.
    fn resolve(&self) -> Self::Def;
    /// Every kind, documented for the schema and reference page.
    fn docs() -> Vec<KindDoc>;
}

/// A resolved stage definition, as validation sees it.
pub trait StageKind: Clone + Debug + PartialEq + Serialize + DeserializeOwned {
    /// Kind name.
    fn kind(&self) -> &'static str;
    /// (field, referenced table id, required table kind) for every table this stage reads.
    fn table_refs(&self) -> Vec<(&'static str, String, &'static str)>;
    /// Range checks.
    fn validate(&self) -> Vec<FieldIssue>;
    /// Problems only the definitions of the referenced tables reveal (a plotted g the table does not
    /// hold), found at `check` rather than when the stage opens the table. `table` looks a validated
    /// table up by id.
    fn check_tables(&self, id: &str, table: &dyn Fn(&str) -> Option<TableDef>) -> Vec<FieldIssue>;
}
