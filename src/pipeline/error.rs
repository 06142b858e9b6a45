//! Diagnostics for pipeline files: every problem a person can cause in a RON pipeline becomes a
//! [`Diagnostic`] with a kind, a `file:line:column` location when one exists, a message and a hint
//! that says how to fix it. Rendered like a compiler error, never as a Rust debug dump.

use std::fmt;
use std::path::PathBuf;

/// A position in a pipeline file (1-based line and column).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Loc {
    /// File as the user named it (or as resolved from an include).
    pub file: PathBuf,
    /// 1-based line.
    pub line: usize,
    /// 1-based column, counted in characters.
    pub col: usize,
}

impl fmt::Display for Loc {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}:{}:{}", self.file.display(), self.line, self.col)
    }
}

/// What went wrong, for programs that react to it (tests, editors).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[non_exhaustive]
pub enum DiagnosticKind {
    /// A file could not be read.
    Io,
    /// The text is not valid RON.
    Syntax,
    /// A field name that this kind does not have.
    UnknownField,
    /// A table or stage kind that does not exist.
    UnknownKind,
    /// A value of the wrong type (e.g. a string where a number belongs).
    WrongType,
    /// A value outside its valid range (NaN, infinite, negative, |g| ≥ 1, empty lists, …).
    OutOfRange,
    /// A required field is missing.
    MissingField,
    /// Two entries share an id or name.
    DuplicateId,
    /// A reference (preset, table, include, override) names nothing.
    DanglingReference,
    /// Includes or presets refer to each other in a loop.
    Cycle,
    /// A table would need more memory than the machine has.
    TooLarge,
}

/// One user-facing problem.
#[derive(Debug, Clone, PartialEq)]
pub struct Diagnostic {
    /// Category.
    pub kind: DiagnosticKind,
    /// Where, when known.
    pub loc: Option<Loc>,
    /// What is wrong.
    pub message: String,
    /// How to fix it.
    pub help: Option<String>,
}

impl Diagnostic {
    /// A diagnostic without a hint.
    pub fn new(kind: DiagnosticKind, loc: Option<Loc>, message: impl Into<String>) -> Self {
        Self { kind, loc, message: message.into(), help: None }
    }

    /// Adds a hint.
    pub fn with_help(mut self, help: impl Into<String>) -> Self {
        self.help = Some(help.into());
        self
    }
}

impl fmt::Display for Diagnostic {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "error: {}", self.message)?;
        if let Some(loc) = &self.loc {
            write!(f, "\n  --> {loc}")?;
        }
        if let Some(help) = &self.help {
            write!(f, "\n  = help: {help}")?;
        }
        Ok(())
    }
}

/// All problems found in a pipeline (validation keeps going to report as many as it can).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub struct PipelineError {
    /// The problems, in file order where possible.
    pub diagnostics: Vec<Diagnostic>,
}

impl PipelineError {
    /// Wraps a single diagnostic.
    pub fn one(d: Diagnostic) -> Self {
        Self { diagnostics: vec![d] }
    }

    /// True if any diagnostic has this kind.
    pub fn has(&self, kind: DiagnosticKind) -> bool {
        self.diagnostics.iter().any(|d| d.kind == kind)
    }
}

impl fmt::Display for PipelineError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        for (i, d) in self.diagnostics.iter().enumerate() {
            if i > 0 {
                writeln!(f)?;
            }
            write!(f, "{d}")?;
        }
        if self.diagnostics.len() > 1 {
            write!(f, "\n{} problems found", self.diagnostics.len())?;
        }
        Ok(())
    }
}

/// Longest name (in bytes) compared for "did you mean": the string metrics are quadratic in the
/// length, and a name this long is not a typo of a field or table name.
pub const MAX_SUGGEST_LEN: usize = 64;

/// Most valid names listed in a hint; longer lists end with "… and N more".
pub const MAX_LISTED: usize = 24;

/// The closest candidate to `word` if it is plausibly a typo of it. Linear in the number of
/// candidates: names longer than [`MAX_SUGGEST_LEN`] are never compared.
pub fn did_you_mean<'a>(word: &str, candidates: impl IntoIterator<Item = &'a str>) -> Option<&'a str> {
    if word.len() > MAX_SUGGEST_LEN {
        return None;
    }
    let word_l = word.to_ascii_lowercase();
    // Jaro–Winkler catches shared prefixes ("mu_bin"), Damerau–Levenshtein catches transpositions
    // in short names ("fgo" for "fog").
    candidates
        .into_iter()
        .filter(|c| c.len() <= MAX_SUGGEST_LEN)
        .map(|c| {
            let c_l = c.to_ascii_lowercase();
            let score =
                strsim::jaro_winkler(&word_l, &c_l).max(strsim::normalized_damerau_levenshtein(&word_l, &c_l) + 0.15);
            (score, c)
        })
        .filter(|(score, _)| *score >= 0.8)
        .max_by(|a, b| a.0.total_cmp(&b.0))
        .map(|(_, c)| c)
}

/// "did you mean `x`? " + the list of valid names.
pub fn suggestion_help(word: &str, candidates: &[&str], what: &str) -> String {
    let list = if candidates.is_empty() {
        format!("there are no {what}s")
    } else if candidates.len() > MAX_LISTED {
        let more = candidates.len() - MAX_LISTED;
        format!("valid {what}s: {} … and {more} more", candidates[..MAX_LISTED].join(", "))
    } else {
        format!("valid {what}s: {}", candidates.join(", "))
    };
    match did_you_mean(word, candidates.iter().copied()) {
        Some(s) => format!("did you mean `{s}`? {list}"),
        None => list,
    }
}

#[cfg(test)]
mod tests;
