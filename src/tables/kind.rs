//! The table-kind trait: what the compiler, the cache, the sharded compile and the report ask of a
//! table kind, implemented in each kind's own folder.
//!
//! Input: a resolved definition of one kind. Output: its versions, range checks, memory and work
//! estimates, the generator, the split into work units for a sharded compile (kinds that split), the
//! error estimates against the kind's independent reference and the report ladder. [`TableDef`]
//! reaches the implementation through [`TableDef::kind_impl`], the one match over the kinds.

use super::{Assembled, CheckError, GenStats, GenerateError, Generated, Progress, TableDef, UnitPart};
use crate::tables::FieldIssue;

/// One table kind's behaviour.
pub trait TableKind: Sync {
    /// Kind name as written in RON.
    fn kind(&self) -> &'static str;
    /// Version of this kind's array layout; a reader of the kind checks it.
    fn kind_schema_version(&self) -> u32;
    /// Version of the generator's numerics; bumping it invalidates cached tables of this kind.
    fn generator_version(&self) -> &'static str;
    /// Range checks of every field.
    fn validate(&self) -> Vec<FieldIssue>;
    /// Bytes the generator will hold in memory at its peak (checked before allocating).
    fn estimated_bytes(&self) -> u128;
    /// Work units reported through the progress callback.
    fn work_units(&self) -> u64;
    /// What one of [`TableKind::work_units`] is, for progress lines.
    fn work_unit_name(&self) -> &'static str;
    /// Runs the generator. `key` is the content key (seeds random streams).
    fn generate(&self, key: &[u8; 32], progress: Progress<'_>) -> Result<Generated, GenerateError>;
    /// Measures a generated table against the kind's independent reference.
    fn estimate_errors(&self, generated: &Generated, key: &[u8; 32]) -> Result<GenStats, CheckError>;
    /// Quality budgets for `voltab report`, cheapest first: (label, definition).
    fn report_ladder(&self) -> Vec<(String, TableDef)>;
    /// What the report's error axis means for this kind.
    fn report_error_name(&self) -> &'static str;
    /// Error per curve (e.g. per g) of a generated table, for the report.
    fn report_measure(&self, generated: &Generated) -> Result<Vec<(String, f64)>, CheckError>;

    /// How many independent work units the generator splits into, for a sharded compile
    /// (`crate::shard`); 1 for kinds that take seconds, not hours (the whole table is one unit).
    fn units(&self) -> usize {
        1
    }
    /// Computes work unit `unit` of a table with more than one ([`TableKind::units`]).
    fn generate_unit(&self, _key: &[u8; 32], _unit: usize, _progress: Progress<'_>) -> Result<UnitPart, GenerateError> {
        Err(GenerateError::Layout(format!("a {} table is one work unit: generate it whole", self.kind())))
    }
    /// The table and its error estimates from all its work units, in unit order: the same bits as
    /// [`TableKind::generate`] followed by [`TableKind::estimate_errors`].
    fn assemble(&self, _key: &[u8; 32], _parts: Vec<UnitPart>) -> Result<Assembled, GenerateError> {
        Err(GenerateError::Layout(format!("a {} table is one work unit: generate it whole", self.kind())))
    }
}
