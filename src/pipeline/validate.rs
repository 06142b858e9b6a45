//! Validation: [`Loaded`] entries → [`ValidatedPipeline`], the only way to obtain the validated
//! types generators and stages accept (naga's `ModuleInfo` idea: validation produces a proof).
//!
//! Checks: ids present, well-formed and unique; presets and overrides resolve (no dangling names,
//! no cycles, same kind); every field in range (per kind); stage references name tables of the
//! right kind; every table fits in memory. All problems are collected and reported together.

use std::collections::{BTreeMap, BTreeSet, HashMap};
use std::path::{Path, PathBuf};

use super::error::{Diagnostic, DiagnosticKind as K, Loc, PipelineError, suggestion_help};
use super::kinds::{StageKind, StageKinds};
use super::parse::{Loaded, Sources, load};
use crate::tables::{TableDecl, TableDef};

/// Resource limits applied during validation.
#[derive(Debug, Clone, Copy)]
pub struct Limits {
    /// Largest peak memory a single table may need.
    pub memory_bytes: u128,
}

impl Limits {
    /// 80 % of physical memory (from /proc/meminfo; 8 GiB if unknown), or `VOLTAB_MEMORY_LIMIT`
    /// bytes when that variable is set.
    pub fn from_machine() -> Self {
        if let Some(v) = std::env::var("VOLTAB_MEMORY_LIMIT").ok().and_then(|v| v.trim().parse::<u128>().ok()) {
            return Self { memory_bytes: v };
        }
        let total_kib = std::fs::read_to_string("/proc/meminfo").ok().and_then(|s| {
            s.lines()
                .find(|l| l.starts_with("MemTotal:"))
                .and_then(|l| l.split_whitespace().nth(1))
                .and_then(|n| n.parse::<u128>().ok())
        });
        Self { memory_bytes: total_kib.map_or(8 << 30, |k| k * 1024 * 8 / 10) }
    }
}

/// A table that passed validation.
#[derive(Debug, Clone)]
pub struct ValidatedTable {
    id: String,
    def: TableDef,
    loc: Option<Loc>,
    key: [u8; 32],
}

impl ValidatedTable {
    /// Unique id (safe as a file name).
    pub fn id(&self) -> &str {
        &self.id
    }
    /// Resolved definition.
    pub fn def(&self) -> &TableDef {
        &self.def
    }
    /// Where it was declared.
    pub fn loc(&self) -> Option<&Loc> {
        self.loc.as_ref()
    }
    /// Content key: hash of (canonical definition, kind schema version, generator version, container major).
    pub fn key(&self) -> &[u8; 32] {
        &self.key
    }
}

/// A stage that passed validation (`D`: the registry's resolved stage definition).
#[derive(Debug, Clone)]
pub struct ValidatedStage<D> {
    id: String,
    def: D,
}

impl<D: StageKind> ValidatedStage<D> {
    /// Unique id.
    pub fn id(&self) -> &str {
        &self.id
    }
    /// Resolved definition.
    pub fn def(&self) -> &D {
        &self.def
    }
    /// The same stage with another definition, revalidated.
    pub fn with_def(&self, def: D) -> Result<Self, String> {
        if let Some(i) = def.validate().first() {
            return Err(format!("{}: {}", i.message, i.help));
        }
        Ok(Self { id: self.id.clone(), def })
    }
}

/// A whole pipeline that passed validation (`D`: the registry's resolved stage definition).
#[derive(Debug, Clone)]
pub struct ValidatedPipeline<D> {
    path: PathBuf,
    tables: Vec<ValidatedTable>,
    stages: Vec<ValidatedStage<D>>,
}

impl<D: StageKind> ValidatedPipeline<D> {
    /// The root pipeline file.
    pub fn path(&self) -> &Path {
        &self.path
    }
    /// Tables in declaration order (included files first).
    pub fn tables(&self) -> &[ValidatedTable] {
        &self.tables
    }
    /// Stages in declaration order.
    pub fn stages(&self) -> &[ValidatedStage<D>] {
        &self.stages
    }
    /// A table by id.
    pub fn table(&self, id: &str) -> Option<&ValidatedTable> {
        self.tables.iter().find(|t| t.id == id)
    }

    /// A pipeline of the given tables only (used by `voltab report` for its quality ladders).
    pub fn with_tables(&self, tables: Vec<ValidatedTable>) -> Self {
        Self { path: self.path.clone(), tables, stages: Vec::new() }
    }

    /// A pipeline of the given tables and stages (used by the scene planner for pruned pipelines).
    pub fn with_parts(&self, tables: Vec<ValidatedTable>, stages: Vec<ValidatedStage<D>>) -> Self {
        Self { path: self.path.clone(), tables, stages }
    }
}

impl ValidatedTable {
    /// The same table with another definition of the same kind, revalidated (used by report ladders).
    pub fn with_def(&self, def: TableDef, limits: &Limits) -> Result<Self, String> {
        if let Some(i) = def.kind_impl().validate().first() {
            return Err(format!("{}: {}", i.message, i.help));
        }
        if def.kind_impl().estimated_bytes() > limits.memory_bytes {
            return Err(format!("needs {} bytes", def.kind_impl().estimated_bytes()));
        }
        let key = def.content_key();
        Ok(Self { id: self.id.clone(), def, loc: self.loc.clone(), key })
    }
}

/// Loads and validates a pipeline file with the machine's limits.
pub fn load_and_validate<S: StageKinds>(
    path: &Path,
    sources: &dyn Sources,
) -> Result<ValidatedPipeline<S::Def>, PipelineError> {
    validate(path, load::<S>(path, sources)?, &Limits::from_machine())
}

/// Ids are used as file names: keep them portable and free of path separators.
fn valid_id(id: &str) -> bool {
    !id.is_empty()
        && id.len() <= 128
        && !id.starts_with('.')
        && id.chars().all(|c| c.is_ascii_alphanumeric() || matches!(c, '_' | '-' | '.'))
}

/// Validates loaded entries.
pub fn validate<S: StageKinds>(
    root: &Path,
    l: Loaded<S>,
    limits: &Limits,
) -> Result<ValidatedPipeline<S::Def>, PipelineError> {
    let mut diags = Vec::new();
    let entry_loc =
        |file: usize, id: &str| l.files[file].masked.find_key_string("id", id, 0).map(|o| l.files[file].loc(o));
    let field_loc = |file: usize, id: &str, field: &str| {
        let f = &l.files[file];
        let start = f.masked.find_key_string("id", id, 0)?;
        f.masked.find_field(field, start).map(|o| f.loc(o))
    };

    // Presets: unique names.
    let mut presets: BTreeMap<&str, (&TableDecl, usize)> = BTreeMap::new();
    for (name, decl, file) in &l.presets {
        let loc = l.files[*file].masked.find_map_key(name, 0).map(|o| l.files[*file].loc(o));
        if let Some((_, first)) = presets.get(name.as_str()) {
            diags.push(
                Diagnostic::new(
                    K::DuplicateId,
                    loc,
                    format!("preset \"{name}\" is defined twice (also in {})", l.files[*first].path.display()),
                )
                .with_help("give the new preset another name and start it from the old one with preset: \"…\""),
            );
            continue;
        }
        if decl.id().is_some() {
            diags.push(
                Diagnostic::new(K::WrongType, loc, format!("preset \"{name}\" has an id"))
                    .with_help("presets are not tables: remove `id`"),
            );
        }
        presets.insert(name, (decl, *file));
    }
    let preset_names: Vec<&str> = presets.keys().copied().collect();

    // Tables: ids present, well-formed, unique.
    let mut tables: Vec<(String, TableDecl, usize)> = Vec::new();
    let mut seen: BTreeMap<String, usize> = BTreeMap::new();
    // Position of each entry within its own file's `tables: [...]`, to locate entries without an id.
    let mut per_file = vec![0usize; l.files.len()];
    for (decl, file) in &l.tables {
        let nth = per_file[*file];
        per_file[*file] += 1;
        let Some(id) = decl.id() else {
            let f = &l.files[*file];
            diags.push(
                Diagnostic::new(
                    K::MissingField,
                    f.masked.find_list_entry("tables", nth).map(|o| f.loc(o)),
                    format!("table #{} ({}) in {} has no id", nth + 1, decl.kind(), f.path.display()),
                )
                .with_help("add id: \"a_name\" to the entry"),
            );
            continue;
        };
        if !valid_id(id) {
            diags.push(
                Diagnostic::new(K::OutOfRange, entry_loc(*file, id), format!("table id \"{id}\" is not a valid id"))
                    .with_help("ids are file names: use 1-128 letters, digits, '_', '-' or '.', not starting with '.'"),
            );
            continue;
        }
        if let Some(first) = seen.get(id) {
            let first_loc =
                entry_loc(*first, id).map_or_else(|| l.files[*first].path.display().to_string(), |x| x.to_string());
            // The duplicate is the second occurrence: search after the first one in the same file.
            let f = &l.files[*file];
            let dup_loc = if *first == *file {
                f.masked.find_key_strings("id", id, 0).get(1).map(|&o| f.loc(o))
            } else {
                entry_loc(*file, id)
            };
            diags.push(
                Diagnostic::new(
                    K::DuplicateId,
                    dup_loc,
                    format!("table id \"{id}\" is used twice (first at {first_loc})"),
                )
                .with_help(
                    "rename one of them; to change an included table, use `overrides: { \"id\": Kind(field: …) }`",
                ),
            );
            continue;
        }
        seen.insert(id.to_owned(), *file);
        tables.push((id.to_owned(), decl.clone(), *file));
    }

    // Overrides: apply to included tables (found through a map: linear in the number of entries).
    let table_index: HashMap<String, usize> = tables.iter().enumerate().map(|(k, t)| (t.0.clone(), k)).collect();
    for (id, over, file) in &l.overrides {
        let f = &l.files[*file];
        let loc = f.masked.find_map_key(id, 0).map(|o| f.loc(o));
        let Some(t) = table_index.get(id).map(|&k| &mut tables[k]) else {
            let ids: Vec<&str> = seen.keys().map(String::as_str).collect();
            diags.push(
                Diagnostic::new(
                    K::DanglingReference,
                    loc,
                    format!("override for table \"{id}\", which is not declared"),
                )
                .with_help(suggestion_help(id, &ids, "table id")),
            );
            continue;
        };
        match over.merged_over(&t.1) {
            Some(merged) => t.1 = merged,
            None => diags.push(
                Diagnostic::new(
                    K::WrongType,
                    loc,
                    format!("override of \"{id}\" is a {}, but the table is a {}", over.kind(), t.1.kind()),
                )
                .with_help("an override must use the table's own kind"),
            ),
        }
    }

    // Presets (with chains), defaults, ranges, memory.
    let mut out = Vec::new();
    for (id, decl, file) in &tables {
        let mut current = decl.clone();
        let mut chain: Vec<String> = Vec::new();
        let mut ok = true;
        while let Some(p) = current.preset().map(str::to_owned) {
            let loc = field_loc(*file, id, "preset");
            if chain.contains(&p) {
                diags.push(
                    Diagnostic::new(K::Cycle, loc, format!("preset cycle: {} → {p}", chain.join(" → ")))
                        .with_help("presets must not refer back to themselves"),
                );
                ok = false;
                break;
            }
            let Some((base, _)) = presets.get(p.as_str()) else {
                diags.push(
                    Diagnostic::new(
                        K::DanglingReference,
                        loc,
                        format!("table \"{id}\" uses preset \"{p}\", which is not defined"),
                    )
                    .with_help(suggestion_help(&p, &preset_names, "preset")),
                );
                ok = false;
                break;
            };
            chain.push(p.clone());
            // Keep the base's own preset link so chains continue.
            let next_preset = base.preset().map(str::to_owned);
            match current.merged_over(base) {
                Some(mut m) => {
                    set_preset(&mut m, next_preset);
                    current = m;
                }
                None => {
                    diags.push(
                        Diagnostic::new(
                            K::WrongType,
                            loc,
                            format!("table \"{id}\" is a {} but preset \"{p}\" is a {}", decl.kind(), base.kind()),
                        )
                        .with_help("a table can only use a preset of its own kind"),
                    );
                    ok = false;
                    break;
                }
            }
        }
        if !ok {
            continue;
        }
        let def = current.resolve();
        let issues = def.kind_impl().validate();
        for i in &issues {
            diags.push(
                Diagnostic::new(
                    K::OutOfRange,
                    field_loc(*file, id, i.field).or_else(|| entry_loc(*file, id)),
                    format!("table \"{id}\" ({}): {}", def.kind(), i.message),
                )
                .with_help(i.help.clone()),
            );
        }
        if !issues.is_empty() {
            continue;
        }
        let bytes = def.kind_impl().estimated_bytes();
        if bytes > limits.memory_bytes {
            diags.push(
                Diagnostic::new(
                    K::TooLarge,
                    entry_loc(*file, id),
                    format!(
                        "table \"{id}\" would need {} of memory; the limit on this machine is {}",
                        human_bytes(bytes),
                        human_bytes(limits.memory_bytes)
                    ),
                )
                .with_help("reduce its resolution (bins, orders, number of g values)"),
            );
            continue;
        }
        let key = def.content_key();
        out.push(ValidatedTable { id: id.clone(), def, loc: entry_loc(*file, id), key });
    }

    // Stages.
    let mut stage_ids = BTreeSet::new();
    let mut stages = Vec::new();
    let validated: HashMap<&str, &ValidatedTable> = out.iter().map(|t| (t.id.as_str(), t)).collect();
    let mut per_file = vec![0usize; l.files.len()];
    for (decl, file) in &l.stages {
        let nth = per_file[*file];
        per_file[*file] += 1;
        let Some(id) = decl.id() else {
            let f = &l.files[*file];
            diags.push(
                Diagnostic::new(
                    K::MissingField,
                    f.masked.find_list_entry("stages", nth).map(|o| f.loc(o)),
                    format!("a {} stage in {} has no id", decl.kind(), l.files[*file].path.display()),
                )
                .with_help("add id: \"a_name\""),
            );
            continue;
        };
        let loc = entry_loc(*file, id);
        if !valid_id(id) || !stage_ids.insert(id.to_owned()) {
            diags.push(
                Diagnostic::new(K::DuplicateId, loc, format!("stage id \"{id}\" is invalid or used twice"))
                    .with_help("stage ids are unique file-name-safe names"),
            );
            continue;
        }
        let def = decl.resolve();
        let mut bad = false;
        for (field, table_id, kind) in def.table_refs() {
            let floc = field_loc(*file, id, field).or_else(|| loc.clone());
            match validated.get(table_id.as_str()).copied() {
                None if table_id.is_empty() => {
                    diags.push(
                        Diagnostic::new(K::MissingField, floc, format!("stage \"{id}\" needs `{field}`"))
                            .with_help(format!("name a {kind} table of this pipeline")),
                    );
                    bad = true;
                }
                None => {
                    let ids: Vec<&str> = seen.keys().map(String::as_str).collect();
                    diags.push(
                        Diagnostic::new(
                            K::DanglingReference,
                            floc,
                            format!("stage \"{id}\" reads table \"{table_id}\", which is not declared"),
                        )
                        .with_help(suggestion_help(&table_id, &ids, "table id")),
                    );
                    bad = true;
                }
                Some(t) if t.def.kind() != kind => {
                    diags.push(Diagnostic::new(
                        K::WrongType,
                        floc,
                        format!("stage \"{id}\" needs a {kind} table, but \"{table_id}\" is a {}", t.def.kind()),
                    ));
                    bad = true;
                }
                Some(_) => {}
            }
        }
        for i in def.check_tables(id, &|t| validated.get(t).map(|t| t.def.clone())) {
            diags.push(
                Diagnostic::new(K::DanglingReference, field_loc(*file, id, i.field).or_else(|| loc.clone()), i.message)
                    .with_help(i.help),
            );
            bad = true;
        }
        for i in def.validate() {
            diags.push(
                Diagnostic::new(
                    K::OutOfRange,
                    field_loc(*file, id, i.field).or_else(|| loc.clone()),
                    format!("stage \"{id}\": {}", i.message),
                )
                .with_help(i.help),
            );
            bad = true;
        }
        if !bad {
            stages.push(ValidatedStage { id: id.to_owned(), def });
        }
    }

    if diags.is_empty() {
        Ok(ValidatedPipeline { path: root.to_path_buf(), tables: out, stages })
    } else {
        Err(PipelineError { diagnostics: diags })
    }
}

fn set_preset(d: &mut TableDecl, p: Option<String>) {
    match d {
        TableDecl::PhaseHg(r) => r.preset = p,
        TableDecl::ZhResponse(r) => r.preset = p,
        TableDecl::MsLobes(r) => r.preset = p,
        TableDecl::PopPreset(r) => r.preset = p,
    }
}

/// "1.5 GiB".
pub fn human_bytes(b: u128) -> String {
    let units = ["B", "KiB", "MiB", "GiB", "TiB", "PiB", "EiB"];
    let mut v = b as f64;
    let mut u = 0;
    while v >= 1024.0 && u + 1 < units.len() {
        v /= 1024.0;
        u += 1;
    }
    if u == 0 { format!("{b} B") } else { format!("{v:.1} {}", units[u]) }
}
