//! Table kinds (the compiler's back end): each kind turns a validated, resolved definition into the
//! arrays of one `.vtab` file, reports its own error estimate, and offers a ladder of quality budgets
//! and a reference for `voltab report`.
//!
//! Input: [`TableDef`] (resolved parameters; only the validator builds one inside a
//! [`crate::pipeline::ValidatedTable`]). Output: [`Generated`] — array descriptions, values and
//! run statistics. Invariant: generators never see unvalidated input and never emit NaN/Inf.
//!
//! Adding a kind: a module here with a `declare_params!` block, a variant in [`TableDecl`] and
//! [`TableDef`], and the match arms below.

pub mod kind;
pub mod ms_lobes;
pub mod phase_hg;
pub mod pop_preset;
pub mod zh_response;

pub use kind::TableKind;
use serde::{Deserialize, Serialize};

use crate::container::{ArrayDesc, ArrayValues};

/// A table entry as written in a pipeline file (kind + optional fields).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[non_exhaustive]
pub enum TableDecl {
    /// Henyey–Greenstein phase tables (phase value, cumulative, inverse CDF, ZH coefficients).
    PhaseHg(phase_hg::PhaseHgRaw),
    /// ZH impulse-response tables of dubouchet2019 (per emitter, g, bounce and distance).
    ZhResponse(zh_response::ZhResponseRaw),
    /// Multiple-scattering lobe tables of wang2018 (per albedo, g, ρ, z and lobe angle).
    MsLobes(ms_lobes::MsLobesRaw),
    /// Principal-Ordinates Propagation preset of elek2014 (ordinates, cell integrals, flow table, settings).
    PopPreset(pop_preset::PopPresetRaw),
}

/// A resolved table definition: every parameter present. Its canonical RON is hashed into the
/// content key.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[non_exhaustive]
pub enum TableDef {
    /// See [`phase_hg`].
    PhaseHg(phase_hg::PhaseHg),
    /// See [`zh_response`].
    ZhResponse(zh_response::ZhResponse),
    /// See [`ms_lobes`].
    MsLobes(ms_lobes::MsLobes),
    /// See [`pop_preset`].
    PopPreset(pop_preset::PopPreset),
}

/// A problem with one field's value, found by a kind's own validation.
#[derive(Debug, Clone, PartialEq)]
pub struct FieldIssue {
    /// Field name as written in RON.
    pub field: &'static str,
    /// What is wrong, with the value.
    pub message: String,
    /// Valid range and unit, or how to fix it.
    pub help: String,
}

/// Run statistics of one generation: never stored in the `.vtab` (the bytes must not depend on
/// them), written to the JSON sidecar and the report instead.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct GenStats {
    /// Samples or values that came out NaN/Inf and were discarded (Monte-Carlo kinds) — always
    /// reported, so a silent loss of samples is visible.
    pub nonfinite_discarded: u64,
    /// Number of random samples drawn (0 for closed-form kinds).
    pub samples: u64,
    /// Named error estimates against the kind's independent reference.
    pub errors: Vec<ErrorEstimate>,
}

/// One error estimate.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ErrorEstimate {
    /// What was measured, e.g. `phase_interp_max_rel`.
    pub name: String,
    /// The measured value.
    pub value: f64,
    /// How it was measured.
    pub how: String,
}

impl GenStats {
    /// The headline error (first estimate), for one-line summaries.
    pub fn headline(&self) -> Option<&ErrorEstimate> {
        self.errors.first()
    }
}

/// The output of a generator.
#[derive(Debug, Clone)]
pub struct Generated {
    /// One description per array.
    pub arrays: Vec<ArrayDesc>,
    /// Values, in the same order, row-major over the array's axes.
    pub values: Vec<ArrayValues>,
    /// Run statistics.
    pub stats: GenStats,
}

/// Failure inside a generator (after validation passed).
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum GenerateError {
    /// A value could not be represented (e.g. overflow to infinity after conversion to f32).
    #[error("{array}[{index}] evaluated to {value}, which cannot be stored; {help}")]
    NonFinite {
        /// Array name.
        array: String,
        /// Flat element index.
        index: u64,
        /// The offending value.
        value: f64,
        /// What to change.
        help: String,
    },
    /// The generated arrays do not have the kind's layout (a bug in the generator).
    #[error("generated arrays have an unexpected layout: {0}")]
    Layout(String),
    /// Checking the table against its reference failed.
    #[error("checking the table against its reference: {0}")]
    Check(#[from] CheckError),
}

/// Measuring a generated table against its independent reference failed ([`TableKind::estimate_errors`],
/// [`TableKind::report_measure`]).
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum CheckError {
    /// The generated arrays do not read back as a table of the kind (a bug in the generator).
    #[error("generated arrays have an unexpected layout: {0}")]
    Layout(String),
    /// The backward-walk reference of the lobe tables refused a probe.
    #[error("the backward-walk reference: {0}")]
    Adjoint(#[from] crate::reference::beam_adjoint::AdjointError),
    /// The random-walk reference of the ZH tables refused a probe.
    #[error("the random-walk reference: {0}")]
    Walk(#[from] crate::reference::walk::WalkError),
    /// A lobe table could not answer a probe.
    #[error("a lobe look-up: {0}")]
    Lobe(#[from] ms_lobes::LobeQueryError),
    /// A ZH table could not answer a probe.
    #[error("a ZH query: {0}")]
    Zh(#[from] zh_response::QueryError),
    /// A thread panicked while holding a cache of reference values.
    #[error("a cache of reference values was poisoned by a panicking thread")]
    CachePoisoned,
}

/// The seed of a table's random streams: the first 8 bytes of its content key, little-endian.
pub(crate) fn key_seed(key: &[u8; 32]) -> u64 {
    let [b0, b1, b2, b3, b4, b5, b6, b7, ..] = *key;
    u64::from_le_bytes([b0, b1, b2, b3, b4, b5, b6, b7])
}

/// Progress callback: called with a number of finished work units.
pub type Progress<'a> = &'a (dyn Fn(u64) + Sync);

impl TableDecl {
    /// Kind name as written in RON.
    pub fn kind(&self) -> &'static str {
        match self {
            TableDecl::PhaseHg(_) => phase_hg::PhaseHgRaw::KIND,
            TableDecl::ZhResponse(_) => zh_response::ZhResponseRaw::KIND,
            TableDecl::MsLobes(_) => ms_lobes::MsLobesRaw::KIND,
            TableDecl::PopPreset(_) => pop_preset::PopPresetRaw::KIND,
        }
    }

    /// All kind names, for "did you mean".
    pub const KINDS: &'static [&'static str] = &[
        phase_hg::PhaseHgRaw::KIND,
        zh_response::ZhResponseRaw::KIND,
        ms_lobes::MsLobesRaw::KIND,
        pop_preset::PopPresetRaw::KIND,
    ];

    /// Field names of this kind (without `id`/`preset`).
    pub fn field_names(&self) -> Vec<&'static str> {
        match self {
            TableDecl::PhaseHg(_) => phase_hg::PhaseHgRaw::FIELDS.iter().map(|f| f.name).collect(),
            TableDecl::ZhResponse(_) => zh_response::ZhResponseRaw::FIELDS.iter().map(|f| f.name).collect(),
            TableDecl::MsLobes(_) => ms_lobes::MsLobesRaw::FIELDS.iter().map(|f| f.name).collect(),
            TableDecl::PopPreset(_) => pop_preset::PopPresetRaw::FIELDS.iter().map(|f| f.name).collect(),
        }
    }

    /// The entry's `id`.
    pub fn id(&self) -> Option<&str> {
        match self {
            TableDecl::PhaseHg(r) => r.id.as_deref(),
            TableDecl::ZhResponse(r) => r.id.as_deref(),
            TableDecl::MsLobes(r) => r.id.as_deref(),
            TableDecl::PopPreset(r) => r.id.as_deref(),
        }
    }

    /// The entry's `preset`.
    pub fn preset(&self) -> Option<&str> {
        match self {
            TableDecl::PhaseHg(r) => r.preset.as_deref(),
            TableDecl::ZhResponse(r) => r.preset.as_deref(),
            TableDecl::MsLobes(r) => r.preset.as_deref(),
            TableDecl::PopPreset(r) => r.preset.as_deref(),
        }
    }

    /// Fields set explicitly (for locating errors).
    pub fn set_fields(&self) -> Vec<&'static str> {
        match self {
            TableDecl::PhaseHg(r) => r.set_fields(),
            TableDecl::ZhResponse(r) => r.set_fields(),
            TableDecl::MsLobes(r) => r.set_fields(),
            TableDecl::PopPreset(r) => r.set_fields(),
        }
    }

    /// `self` with unset fields taken from `base`; `None` if the kinds differ.
    pub fn merged_over(&self, base: &TableDecl) -> Option<TableDecl> {
        match (self, base) {
            (TableDecl::PhaseHg(a), TableDecl::PhaseHg(b)) => Some(TableDecl::PhaseHg(a.merged_over(b))),
            (TableDecl::ZhResponse(a), TableDecl::ZhResponse(b)) => Some(TableDecl::ZhResponse(a.merged_over(b))),
            (TableDecl::MsLobes(a), TableDecl::MsLobes(b)) => Some(TableDecl::MsLobes(a.merged_over(b))),
            (TableDecl::PopPreset(a), TableDecl::PopPreset(b)) => Some(TableDecl::PopPreset(a.merged_over(b))),
            _ => None,
        }
    }

    /// Fills defaults.
    pub fn resolve(&self) -> TableDef {
        match self {
            TableDecl::PhaseHg(r) => TableDef::PhaseHg(r.resolve()),
            TableDecl::ZhResponse(r) => TableDef::ZhResponse(r.resolve()),
            TableDecl::MsLobes(r) => TableDef::MsLobes(r.resolve()),
            TableDecl::PopPreset(r) => TableDef::PopPreset(r.resolve()),
        }
    }
}

impl TableDef {
    /// The kind behind the definition: every question about a table goes through this one match.
    pub fn kind_impl(&self) -> &dyn TableKind {
        match self {
            TableDef::PhaseHg(p) => p,
            TableDef::ZhResponse(p) => p,
            TableDef::MsLobes(p) => p,
            TableDef::PopPreset(p) => p,
        }
    }

    /// Kind name.
    pub fn kind(&self) -> &'static str {
        self.kind_impl().kind()
    }

    /// Content key: hash of (kind, kind schema version, generator version, container major, canonical
    /// definition). The cache files tables under it; random streams are keyed by it.
    pub fn content_key(&self) -> [u8; 32] {
        let k = self.kind_impl();
        let mut h = blake3::Hasher::new();
        h.update(b"voltab content key v1\0");
        h.update(k.kind().as_bytes());
        h.update(b"\0");
        h.update(&k.kind_schema_version().to_le_bytes());
        h.update(k.generator_version().as_bytes());
        h.update(b"\0");
        h.update(&crate::container::FORMAT_MAJOR.to_le_bytes());
        h.update(self.canonical_ron().as_bytes());
        *h.finalize().as_bytes()
    }

    /// Canonical RON text of the definition: part of the content key and stored in the header.
    pub fn canonical_ron(&self) -> String {
        // Serialising a plain struct of numbers, strings and enums cannot fail; fall back to Debug
        // (still deterministic) rather than panic if it ever did.
        ron::to_string(self).unwrap_or_else(|_| format!("{self:?}"))
    }
}

/// A work unit's result before assembly (see [`TableKind::units`]): what a shard of a sharded compile
/// hands to the merge.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub enum UnitPart {
    /// The integer tallies of one photon batch of one g slice of an `MsLobes` table.
    MsLobesPhotons {
        /// The g slice.
        slice: usize,
        /// Its tallies.
        tally: crate::physics::lobe_transport::PhotonTally,
    },
    /// The references of an `MsLobes` table's sidecar check.
    MsLobesCheck(Vec<ms_lobes::CheckReference>),
    /// One (emitter, g slice) of a `ZhResponse` table.
    Zh(zh_response::ZhPart),
}

impl UnitPart {
    /// A unit of references for the sidecar check (its time is check time, not generation time).
    pub fn is_check(&self) -> bool {
        matches!(self, UnitPart::MsLobesCheck(_) | UnitPart::Zh(zh_response::ZhPart::Check(_)))
    }

    /// Adds `part` to the parts of one table gathered so far, summing the photon tallies of a slice as
    /// they arrive (a merge then holds one tally per slice, not one per unit). Integer sums: the order
    /// of arrival does not change a bit.
    pub fn absorb(parts: &mut Vec<UnitPart>, part: UnitPart) {
        if let UnitPart::MsLobesPhotons { slice, tally } = &part
            && let Some(UnitPart::MsLobesPhotons { tally: into, .. }) =
                parts.iter_mut().find(|p| matches!(p, UnitPart::MsLobesPhotons { slice: s, .. } if s == slice))
        {
            into.absorb(tally);
            return;
        }
        parts.push(part);
    }
}

/// What the merge of a split table's units gives: the table and its error estimates.
#[derive(Debug, Clone)]
pub struct Assembled {
    /// The table, as [`TableKind::generate`] makes it.
    pub generated: Generated,
    /// Wall time of [`TableKind::estimate_errors`] on it \[ms\] (its references came from a unit).
    pub check_ms: f64,
}

/// Failure to load a table for a consumer (every kind's reader).
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum TableReadError {
    /// The container is unreadable.
    #[error("{}: {source}", path.display())]
    Container {
        /// The file.
        path: std::path::PathBuf,
        /// Why.
        source: crate::container::ContainerError,
    },
    /// The file is a valid container but not a table of the kind this build can use, or the requested
    /// slices are outside it.
    #[error("{0}")]
    Layout(String),
}

/// The common start of every kind's reader: opens `path`, checks that it holds a `kind` table whose
/// layout version this build reads (`supported`), and parses its stored definition (the caller matches
/// the variant it expects). Errors go through the caller's `container` and `layout` constructors.
pub fn open_kind<E>(
    path: &std::path::Path,
    expected: (&str, u32),
    container: impl Fn(crate::container::ContainerError) -> E,
    layout: impl Fn(String) -> E,
) -> Result<(crate::container::VtabReader, TableDef), E> {
    let r = crate::container::VtabReader::open(path).map_err(container)?;
    check_kind(r, expected, layout)
}

/// [`open_kind`] on an already open reader (e.g. one made from bytes).
pub fn check_kind<E>(
    r: crate::container::VtabReader,
    (kind, supported): (&str, u32),
    layout: impl Fn(String) -> E,
) -> Result<(crate::container::VtabReader, TableDef), E> {
    let h = r.header();
    if h.kind != kind {
        return Err(layout(format!("holds a {} table, not {kind}", h.kind)));
    }
    if h.kind_schema_version > supported {
        return Err(layout(format!(
            "uses {kind} layout version {}, this voltab reads up to {supported}; upgrade voltab",
            h.kind_schema_version
        )));
    }
    let def = stored_definition(h, kind).map_err(|e| layout(e.to_string()))?;
    Ok((r, def))
}

/// A table file whose header this build cannot trust or read.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum StoredTableError {
    /// The stored definition does not parse as the kind's definition.
    #[error("its stored definition is not a readable {0} definition")]
    Unreadable(String),
    /// The stored definition is of another kind than the header says.
    #[error("its stored definition is a {found} definition, not {kind}")]
    WrongKind {
        /// The definition's kind.
        found: &'static str,
        /// The header's kind.
        kind: String,
    },
    /// The stored definition breaks a range rule of its kind.
    #[error("its stored definition is invalid: {message} (field `{field}`; {help})")]
    Invalid {
        /// What is wrong.
        message: String,
        /// The field.
        field: &'static str,
        /// The fix.
        help: String,
    },
    /// Reading the table would need more memory than this machine allows.
    #[error("its stored definition would need {bytes} bytes of memory, above this machine's limit of {limit}")]
    TooLarge {
        /// Bytes needed.
        bytes: u128,
        /// This machine's limit.
        limit: u128,
    },
    /// A kind this build does not know.
    #[error("unknown table kind `{kind}`: voltab {} reads {}; upgrade voltab to use this table", env!("CARGO_PKG_VERSION"), TableDecl::KINDS.join(", "))]
    UnknownKind {
        /// The file's kind.
        kind: String,
    },
    /// A layout newer than this build reads.
    #[error("{kind} layout version {version} is newer than the {supported} this voltab {} reads; upgrade voltab", env!("CARGO_PKG_VERSION"))]
    NewerLayout {
        /// The kind.
        kind: String,
        /// The file's layout version.
        version: u32,
        /// The newest this build reads.
        supported: u32,
    },
}

/// Parses a table header's stored definition and validates it exactly as a pipeline's table is
/// validated (same [`TableKind::validate`], same memory estimate): a file whose definition was
/// edited (`z_min > z_max`, `g: [NaN]`, `rho_max: 0`, …) is refused with the first broken rule
/// instead of reaching a reader that trusts it (issue 37).
pub fn stored_definition(h: &crate::container::Header, kind: &str) -> Result<TableDef, StoredTableError> {
    let def = ron::from_str::<TableDef>(&h.definition_ron).map_err(|_| StoredTableError::Unreadable(kind.into()))?;
    if def.kind() != kind {
        return Err(StoredTableError::WrongKind { found: def.kind(), kind: kind.into() });
    }
    if let Some(i) = def.kind_impl().validate().first() {
        return Err(StoredTableError::Invalid { message: i.message.clone(), field: i.field, help: i.help.clone() });
    }
    let limit = crate::pipeline::Limits::from_machine().memory_bytes;
    let bytes = def.kind_impl().estimated_bytes();
    if bytes > limit {
        return Err(StoredTableError::TooLarge { bytes, limit });
    }
    Ok(def)
}

/// Checks that a table's kind and layout version are ones this build can consume.
pub fn check_known_kind(h: &crate::container::Header) -> Result<(), StoredTableError> {
    let supported = match h.kind.as_str() {
        k if k == phase_hg::PhaseHgRaw::KIND => phase_hg::KIND_SCHEMA_VERSION,
        k if k == zh_response::ZhResponseRaw::KIND => zh_response::KIND_SCHEMA_VERSION,
        k if k == ms_lobes::MsLobesRaw::KIND => ms_lobes::KIND_SCHEMA_VERSION,
        k if k == pop_preset::PopPresetRaw::KIND => pop_preset::KIND_SCHEMA_VERSION,
        other => return Err(StoredTableError::UnknownKind { kind: other.into() }),
    };
    if h.kind_schema_version > supported {
        return Err(StoredTableError::NewerLayout { kind: h.kind.clone(), version: h.kind_schema_version, supported });
    }
    stored_definition(h, &h.kind).map(|_| ())
}

/// Converts f64 values to the array's element type, refusing non-finite results.
pub fn to_element(desc: &ArrayDesc, values: Vec<f64>, help: &str) -> Result<ArrayValues, GenerateError> {
    use crate::container::ElementType;
    let bad = |index: usize, value: f64| GenerateError::NonFinite {
        array: desc.name.clone(),
        index: index as u64,
        value,
        help: help.to_owned(),
    };
    match desc.element {
        ElementType::F64 => {
            if let Some((i, v)) = values.iter().enumerate().find(|(_, v)| !v.is_finite()) {
                return Err(bad(i, *v));
            }
            Ok(ArrayValues::F64(values))
        }
        ElementType::F32 => {
            let out: Vec<f32> = values.iter().map(|&v| v as f32).collect();
            if let Some((i, _)) = out.iter().enumerate().find(|(_, v)| !v.is_finite()) {
                return Err(bad(i, values[i]));
            }
            Ok(ArrayValues::F32(out))
        }
    }
}
