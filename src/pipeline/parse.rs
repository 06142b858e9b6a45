//! Reading pipeline files: RON text → [`PipelineFile`] per file, following `include`s.
//!
//! Input: a path (on disk, or in the embedded default set). Output: [`Loaded`] — every file's
//! entries tagged with the file they came from, included files first.
//! Invariant: syntax, type and unknown-field errors leave here with `file:line:column` and a hint.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use super::error::{Diagnostic, DiagnosticKind as K, Loc, PipelineError, suggestion_help};
use super::kinds::StageKinds;
use super::locate::Masked;
use crate::tables::TableDecl;

/// One pipeline file as written, with stage entries of type `S` (the registry's stage kinds).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields, bound(deserialize = "S: Deserialize<'de>", serialize = "S: Serialize"))]
#[schemars(rename = "PipelineFile")]
pub struct PipelineFile<S> {
    /// Other pipeline files (paths relative to this file) whose presets, tables and stages are
    /// loaded first, e.g. a studio-wide base pipeline.
    #[serde(default)]
    pub include: Vec<String>,
    /// Named partial table definitions that tables start from with `preset: "name"`.
    #[serde(default)]
    pub presets: BTreeMap<String, TableDecl>,
    /// The tables to compile. Each needs a unique `id`.
    #[serde(default)]
    pub tables: Vec<TableDecl>,
    /// Field overrides for tables declared in included files, by table id.
    #[serde(default)]
    pub overrides: BTreeMap<String, TableDecl>,
    /// Consumers of the tables (run after compiling by `voltab run`).
    #[serde(default)]
    #[schemars(extend("default" = []))]
    pub stages: Vec<S>,
}

/// A source file kept for locating errors.
#[derive(Debug)]
pub struct SourceFile {
    /// Path as shown to the user.
    pub path: PathBuf,
    /// Searchable text.
    pub masked: Masked,
}

impl SourceFile {
    /// Location of a byte offset.
    pub fn loc(&self, offset: usize) -> Loc {
        let (line, col) = self.masked.line_col(offset);
        Loc { file: self.path.clone(), line, col }
    }
}

/// Where pipeline text comes from.
pub trait Sources {
    /// Reads a file.
    fn read(&self, path: &Path) -> std::io::Result<String>;
}

/// Files on disk.
pub struct Disk;

impl Sources for Disk {
    /// Reads a regular file of at most [`crate::cache::bounded::max_input_bytes`] bytes: a FIFO or
    /// device (`include: ["/dev/zero"]`) is refused rather than read forever. Text that is not UTF-8
    /// fails with a [`NotUtf8`] payload locating the first bad byte.
    fn read(&self, path: &Path) -> std::io::Result<String> {
        let bytes = crate::cache::bounded::read_regular(path, crate::cache::bounded::max_input_bytes())?;
        String::from_utf8(bytes).map_err(|e| {
            let valid = e.utf8_error().valid_up_to();
            let text = std::str::from_utf8(&e.as_bytes()[..valid]).unwrap_or("");
            let line = text.matches('\n').count() + 1;
            let col = text.rsplit('\n').next().map_or(0, |l| l.chars().count()) + 1;
            std::io::Error::new(std::io::ErrorKind::InvalidData, NotUtf8 { line, col, byte: valid })
        })
    }
}

/// The payload of the I/O error [`Disk`] returns for text that is not UTF-8: where the first
/// invalid byte is.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct NotUtf8 {
    /// 1-based line of the first invalid byte.
    pub line: usize,
    /// 1-based column (in characters) of the first invalid byte.
    pub col: usize,
    /// Byte offset of the first invalid byte.
    pub byte: usize,
}

impl std::fmt::Display for NotUtf8 {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "the text is not valid UTF-8 (first invalid byte at offset {})", self.byte)
    }
}

impl std::error::Error for NotUtf8 {}

/// The pipelines compiled into the binary (used when `voltab` runs without arguments outside a
/// checkout, so the README's main command works from anywhere).
pub struct Embedded;

/// (path, text) of the embedded pipelines.
pub const EMBEDDED: &[(&str, &str)] = &[
    ("pipelines/default.ron", include_str!("../../pipelines/default.ron")),
    ("pipelines/studio-base.ron", include_str!("../../pipelines/studio-base.ron")),
];

impl Sources for Embedded {
    fn read(&self, path: &Path) -> std::io::Result<String> {
        let norm = normalize(path);
        EMBEDDED
            .iter()
            .find(|(p, _)| Path::new(p) == norm)
            .map(|(_, t)| (*t).to_owned())
            .ok_or_else(|| std::io::Error::new(std::io::ErrorKind::NotFound, "not an embedded pipeline"))
    }
}

/// Lexically normalises `a/./b/../c` to `a/c` (no file system access); a path that normalises
/// to nothing (`.`, `a/..`) becomes `.`, so messages never show an empty path.
pub fn normalize(p: &Path) -> PathBuf {
    let out = normalize_components(p);
    if out.as_os_str().is_empty() { PathBuf::from(".") } else { out }
}

fn normalize_components(p: &Path) -> PathBuf {
    let mut out = PathBuf::new();
    for c in p.components() {
        match c {
            std::path::Component::CurDir => {}
            std::path::Component::ParentDir => {
                if !out.pop() {
                    out.push("..");
                }
            }
            other => out.push(other),
        }
    }
    out
}

/// All entries of a pipeline and its includes, each tagged with its file index.
#[derive(Debug)]
pub struct Loaded<S> {
    /// Source files, in load order.
    pub files: Vec<SourceFile>,
    /// (name, decl, file).
    pub presets: Vec<(String, TableDecl, usize)>,
    /// (decl, file).
    pub tables: Vec<(TableDecl, usize)>,
    /// (table id, decl, file).
    pub overrides: Vec<(String, TableDecl, usize)>,
    /// (decl, file).
    pub stages: Vec<(S, usize)>,
}

fn ron_options() -> ron::Options {
    ron::Options::default().with_default_extension(
        ron::extensions::Extensions::IMPLICIT_SOME | ron::extensions::Extensions::UNWRAP_VARIANT_NEWTYPES,
    )
}

/// Loads `path` and everything it includes.
pub fn load<S: StageKinds>(path: &Path, sources: &dyn Sources) -> Result<Loaded<S>, PipelineError> {
    let mut loaded = Loaded {
        files: Vec::new(),
        presets: Vec::new(),
        tables: Vec::new(),
        overrides: Vec::new(),
        stages: Vec::new(),
    };
    let mut stack = Vec::new();
    load_into(&normalize(path), None, sources, &mut loaded, &mut stack)?;
    Ok(loaded)
}

fn load_into<S: StageKinds>(
    path: &Path,
    included_from: Option<Loc>,
    sources: &dyn Sources,
    out: &mut Loaded<S>,
    stack: &mut Vec<PathBuf>,
) -> Result<(), PipelineError> {
    if stack.iter().any(|p| p == path) {
        let chain: Vec<String> =
            stack.iter().chain(std::iter::once(&path.to_path_buf())).map(|p| p.display().to_string()).collect();
        return Err(PipelineError::one(
            Diagnostic::new(K::Cycle, included_from, format!("include cycle: {}", chain.join(" → ")))
                .with_help("remove one of the includes so the files form a tree"),
        ));
    }
    if out.files.iter().any(|f| f.path == path) {
        return Ok(()); // already loaded through another include (diamond): load once
    }
    let text = sources.read(path).map_err(|e| PipelineError::one(read_diagnostic(path, included_from.clone(), &e)))?;
    let file: PipelineFile<S> =
        ron_options().from_str(&text).map_err(|e| PipelineError::one(ron_diagnostic(path, &text, &e, S::ENUM_NAME)))?;
    let masked = Masked::new(&text);
    let this = SourceFile { path: path.to_path_buf(), masked };
    stack.push(path.to_path_buf());
    let dir = path.parent().map(Path::to_path_buf).unwrap_or_default();
    for inc in &file.include {
        let at = this.masked.find_string(inc, 0).map(|o| this.loc(o));
        load_into(&normalize(&dir.join(inc)), at, sources, out, stack)?;
    }
    stack.pop();
    let idx = out.files.len();
    out.files.push(this);
    out.presets.extend(file.presets.into_iter().map(|(n, d)| (n, d, idx)));
    out.tables.extend(file.tables.into_iter().map(|d| (d, idx)));
    out.overrides.extend(file.overrides.into_iter().map(|(n, d)| (n, d, idx)));
    out.stages.extend(file.stages.into_iter().map(|d| (d, idx)));
    Ok(())
}

/// Why a pipeline file could not be read, located at the bad byte for non-UTF-8 text and at the
/// `include` entry otherwise, with a hint that fits the cause (not always "permissions").
fn read_diagnostic(path: &Path, included_from: Option<Loc>, e: &std::io::Error) -> Diagnostic {
    let what = if included_from.is_some() { "included pipeline" } else { "pipeline" };
    if let Some(bad) = e.get_ref().and_then(|r| r.downcast_ref::<NotUtf8>()) {
        let loc = Loc { file: path.to_path_buf(), line: bad.line, col: bad.col };
        return Diagnostic::new(K::Io, Some(loc), format!("cannot read {what} {}: {bad}", path.display()))
            .with_help("pipeline files are UTF-8 text; re-save the file as UTF-8");
    }
    let help = match e.kind() {
        std::io::ErrorKind::NotFound => "check the path (includes are relative to the including file)",
        std::io::ErrorKind::PermissionDenied => "check the file's permissions",
        std::io::ErrorKind::InvalidInput => "name a regular pipeline file (.ron) no larger than the limit",
        _ => "check the path (includes are relative to the including file) and its permissions",
    };
    Diagnostic::new(K::Io, included_from, format!("cannot read {what} {}: {e}", path.display())).with_help(help)
}

/// Turns a RON error into a diagnostic with a location and a hint (`stage_enum`: the Rust name of
/// the stage-entry enum, which RON names in an unknown-variant error).
fn ron_diagnostic(path: &Path, text: &str, e: &ron::error::SpannedError, stage_enum: &str) -> Diagnostic {
    use ron::error::Error as E;
    let loc = Some(Loc { file: path.to_path_buf(), line: e.span.start.line, col: e.span.start.col });
    match &e.code {
        E::NoSuchStructField { expected, found, outer } => {
            let names: Vec<&str> = expected.to_vec();
            let ctx = outer.as_deref().map(describe_outer).unwrap_or_default();
            Diagnostic::new(K::UnknownField, loc, format!("unknown field `{found}`{ctx}"))
                .with_help(suggestion_help(found, &names, "field"))
        }
        E::NoSuchEnumVariant { expected, found, outer } => {
            let names: Vec<&str> = expected.to_vec();
            let (kind, what) = match outer.as_deref() {
                Some("TableDecl") => (K::UnknownKind, "table kind"),
                Some(o) if o == stage_enum => (K::UnknownKind, "stage kind"),
                _ => (K::WrongType, "value"),
            };
            Diagnostic::new(kind, loc, format!("unknown {what} `{found}`"))
                .with_help(suggestion_help(found, &names, what))
        }
        E::MissingStructField { field, outer } => {
            let ctx = outer.as_deref().map(describe_outer).unwrap_or_default();
            Diagnostic::new(K::MissingField, loc, format!("missing field `{field}`{ctx}"))
        }
        E::DuplicateStructField { field, .. } => {
            Diagnostic::new(K::DuplicateId, loc, format!("field `{field}` is given twice"))
                .with_help("keep one of them")
        }
        E::InvalidValueForType { expected, found } => {
            let mut d = Diagnostic::new(K::WrongType, loc, format!("expected {expected}, found {found}"));
            if expected.contains("u32") || expected.contains("u8") || expected.contains("i32") {
                d = d.with_help("this field takes a whole number in the range given in schemas/reference.md");
            }
            d
        }
        E::Message(m) if m.contains("untagged enum GValues") => {
            Diagnostic::new(K::WrongType, loc, "g must be a list or a grid")
                .with_help("write g as a list `[-0.5, 0.0, 0.5]` or a grid `(min: -0.9, max: 0.9, count: 19)`")
        }
        E::ExpectedInteger
        | E::ExpectedFloat
        | E::ExpectedString
        | E::ExpectedBoolean
        | E::ExpectedArray
        | E::ExpectedMap
        | E::ExpectedStructLike
        | E::ExpectedUnit
        | E::ExpectedChar
        | E::ExpectedIdentifier => Diagnostic::new(K::WrongType, loc, format!("wrong type of value: {}", e.code))
            .with_help("see schemas/reference.md for each field's type and valid range"),
        E::IntegerOutOfBounds => {
            let token = span_text(text, e);
            Diagnostic::new(K::WrongType, loc, format!("`{token}` does not fit this field's integer type"))
                .with_help("this field takes a non-negative whole number; see schemas/reference.md for its valid range")
        }
        other => Diagnostic::new(K::Syntax, loc, format!("invalid RON: {other}"))
            .with_help("see pipelines/default.ron for the layout of a pipeline file"),
    }
}

/// The source text an error's span covers (on its first line).
fn span_text(text: &str, e: &ron::error::SpannedError) -> String {
    let line = text.lines().nth(e.span.start.line.saturating_sub(1)).unwrap_or("");
    let mut start = e.span.start.col.saturating_sub(1);
    // ron's span of a negative literal starts after the sign.
    if start > 0 && line.chars().nth(start - 1) == Some('-') {
        start -= 1;
    }
    let end = if e.span.end.line == e.span.start.line { e.span.end.col.saturating_sub(1) } else { usize::MAX };
    line.chars().skip(start).take(end.saturating_sub(start)).collect::<String>().trim().to_owned()
}

fn describe_outer(outer: &str) -> String {
    match outer {
        "PipelineFile" => " at the top level of the pipeline".to_owned(),
        o => format!(" in a {} entry", o.trim_end_matches("Raw")),
    }
}
