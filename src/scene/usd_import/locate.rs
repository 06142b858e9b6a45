//! Where a layer that openusd cannot open goes wrong: a layer path and openusd's error (which
//! carries no position) → "line L, column C" in a text layer, or the byte range of the part of a
//! binary crate file (`.usdc`) that is broken. Used only on failure, in the guarded child like the
//! first parse (issue 37: every error names the file and a location). Before the layer is opened,
//! a text layer's path literals are checked (`refuse_malformed_paths`): openusd can loop forever
//! on a malformed one.
//!
//! Crate layout, as openusd 0.6 reads it (`usdc/reader.rs`): a 32-byte bootstrap (magic
//! `PXR-USDC`, version bytes major/minor/patch, table-of-contents offset as a little-endian u64,
//! 8 reserved bytes); at that offset the TOC: a u64 section count (1..64) and per section a
//! 16-byte NUL-padded name, a u64 start and a u64 size.

use std::path::Path;

use crate::scene::SceneError;

/// The location of the failure to open the layer at `path`, whose openusd error text is
/// `message`; `None` when the file cannot be read again or the failure has no place in it.
pub(super) fn layer_failure(path: &Path, message: &str) -> Option<String> {
    let ext = path.extension().and_then(|e| e.to_str()).map(str::to_ascii_lowercase);
    let bytes = crate::cache::bounded::read_regular(path, crate::cache::bounded::max_input_bytes()).ok()?;
    let crate_file = bytes.starts_with(b"PXR-USDC");
    match ext.as_deref() {
        Some("usda") => text_failure(bytes),
        Some("usd") if !crate_file && !bytes.starts_with(b"PK") => text_failure(bytes),
        Some("usdc" | "usd") => crate_failure(&bytes, message),
        _ => None,
    }
}

/// Refuses a text layer with a malformed path literal ([`malformed_path`]) before openusd sees it.
pub(super) fn refuse_malformed_paths(path: &Path) -> Result<(), SceneError> {
    let ext = path.extension().and_then(|e| e.to_str()).map(str::to_ascii_lowercase);
    if !matches!(ext.as_deref(), Some("usda" | "usd")) {
        return Ok(());
    }
    let Ok(bytes) = crate::cache::bounded::read_regular(path, crate::cache::bounded::max_input_bytes()) else {
        return Ok(()); // openusd reports the unreadable file
    };
    let Ok(text) = std::str::from_utf8(&bytes) else { return Ok(()) };
    if !text.starts_with("#usda") {
        return Ok(());
    }
    match malformed_path(text) {
        None => Ok(()),
        Some((line, column, what)) => Err(SceneError::at(
            path,
            format!("line {line}, column {column}"),
            format!("malformed path: {what}"),
            "a path literal runs from `<` to the next `>`; close it (e.g. `</World/Looks/Mat>`)",
        )),
    }
}

/// Where a text layer stops parsing. Before the first token (an empty file, a missing `#usda`
/// magic) that is line 1, column 1; in a file that is not UTF-8, its first bad byte. `None` when
/// the layer parses (the error was elsewhere: a sublayer, a reference, composition).
fn text_failure(bytes: Vec<u8>) -> Option<String> {
    let text = match String::from_utf8(bytes) {
        Ok(text) => text,
        Err(e) => {
            let good = &e.as_bytes()[..e.utf8_error().valid_up_to()];
            // Valid UTF-8 up to here, so the line and column count characters.
            let good = std::str::from_utf8(good).ok()?;
            let line = good.matches('\n').count() + 1;
            let column = good.rsplit('\n').next().map_or(0, |l| l.chars().count()) + 1;
            return Some(format!("line {line}, column {column} (byte {}: not UTF-8)", good.len()));
        }
    };
    let mut parser = openusd::usda::parser::Parser::new(&text);
    if parser.parse().is_ok() {
        return None;
    }
    Some(match parser.last_error_highlight() {
        Some(at) => format!("line {}, column {}", at.line, at.column),
        None => "line 1, column 1".to_owned(),
    })
}

/// The first path literal `<…>` of a text layer that cannot be a path, as (line, column, what is
/// wrong), found by scanning the tokens the way openusd's lexer does (strings, asset paths and
/// comments skipped; a path runs from `<` to the next `>`). A path never holds white space,
/// quotes, parentheses, commas, `<`, `@`, `#` or `;`; one that does is almost always a `>` gone
/// missing, and openusd, handed such a path, can loop forever walking its ancestors
/// (`Path::parent`; every USD hang the fuzzer found, 13 of 13) — so it is refused, located, before
/// the layer is opened.
pub(super) fn malformed_path(text: &str) -> Option<(usize, usize, String)> {
    let b = text.as_bytes();
    let skip_quoted = |i: usize, q: &[u8]| -> usize {
        // A string or asset path opening at i with delimiter q: the offset after its end.
        let mut j = i + q.len();
        while j < b.len() {
            if q.len() == 1 && b[j] == b'\\' && q[0] != b'@' {
                j += 2;
                continue;
            }
            if b[j..].starts_with(q) {
                return j + q.len();
            }
            j += 1;
        }
        b.len()
    };
    let mut i = 0;
    while i < b.len() {
        let rest = &b[i..];
        i = match rest[0] {
            b'"' if rest.starts_with(b"\"\"\"") => skip_quoted(i, b"\"\"\""),
            b'\'' if rest.starts_with(b"\'\'\'") => skip_quoted(i, b"\'\'\'"),
            b'@' if rest.starts_with(b"@@@") => skip_quoted(i, b"@@@"),
            q @ (b'"' | b'\'' | b'@') => skip_quoted(i, &[q]),
            b'#' => i + rest.iter().position(|&c| c == b'\n' || c == b'\r').unwrap_or(rest.len()),
            b'/' if rest.starts_with(b"/*") => {
                i + 2 + rest[2..].windows(2).position(|w| w == b"*/").map_or(rest.len() - 2, |p| p + 2)
            }
            b'<' => {
                let body = &rest[1..rest.iter().position(|&c| c == b'>').unwrap_or(rest.len())];
                if let Some(bad) = body.iter().find(|c| b" \t\r\n\x0c\"'(),<@#;".contains(c)) {
                    let before = &text[..i];
                    let line = before.matches('\n').count() + 1;
                    let column = before.rsplit('\n').next().map_or(0, |l| l.chars().count()) + 1;
                    let shown: String = String::from_utf8_lossy(body).chars().take(48).collect();
                    return Some((line, column, format!("{:?} in `<{}…`", char::from(*bad), shown.escape_debug())));
                }
                i + 2 + body.len()
            }
            _ => i + 1,
        };
    }
    None
}

/// Whether `name` can name an attribute: identifiers joined by `:` (`xformOp:rotateXYZ:tilt`).
/// openusd builds a property path from any string it is handed, and a name such as
/// `xformOp:t[] x = [` gives a path whose ancestors it walks forever.
pub(super) fn is_attribute_name(name: &str) -> bool {
    name.split(':').all(|part| {
        let mut c = part.chars();
        c.next().is_some_and(|first| first == '_' || first.is_alphabetic())
            && c.all(|ch| ch == '_' || ch.is_alphanumeric())
    })
}

/// Whether walking `path`'s parents ends: each step must shorten it. A prim name holding a brace
/// or bracket (only a broken layer has one) gives a path that is its own parent in openusd.
pub(super) fn ancestry_terminates(path: &openusd::sdf::Path) -> bool {
    let mut p = path.clone();
    for _ in 0..=path.as_str().len() {
        match p.parent() {
            None => return true,
            Some(q) if q.as_str().len() < p.as_str().len() => p = q,
            Some(_) => return false,
        }
    }
    false
}

/// Length of the crate bootstrap openusd reads.
const BOOTSTRAP: u64 = 32;
/// Length of one TOC entry: name[16], start, size.
const SECTION: u64 = 32;

/// The first part of a crate file that breaks its layout, or the section openusd's `message`
/// names when the layout holds and the failure is inside a section's data.
fn crate_failure(b: &[u8], message: &str) -> Option<String> {
    let len = b.len() as u64;
    if len < BOOTSTRAP {
        return Some(format!("bytes 0–{BOOTSTRAP} (crate bootstrap; the file has {len})"));
    }
    if !b.starts_with(b"PXR-USDC") {
        return Some("bytes 0–8 (crate magic)".to_owned());
    }
    if message.contains("version") {
        return Some(format!("bytes 8–11 (crate version {}.{}.{})", b[8], b[9], b[10]));
    }
    let u64_at = |at: u64| -> Option<u64> {
        let at = usize::try_from(at).ok()?;
        let w = b.get(at..at.checked_add(8)?)?;
        Some(u64::from_le_bytes(w.try_into().ok()?))
    };
    let toc = u64_at(16)?;
    if toc == 0 {
        return Some("bytes 16–24 (TOC offset 0)".to_owned());
    }
    let Some(count) = u64_at(toc) else {
        return Some(format!("bytes 16–24 (TOC offset {toc}, past the end of the {len}-byte file)"));
    };
    let toc_end = (toc + 8).saturating_add(count.saturating_mul(SECTION));
    if count == 0 || count >= 64 || toc_end > len {
        return Some(format!("bytes {toc}–{} (TOC of {count} sections)", toc_end.min(len)));
    }
    let mut named = None;
    for k in 0..count {
        let at = toc + 8 + k * SECTION;
        let name = &b[at as usize..(at + 16) as usize];
        let name = String::from_utf8_lossy(name.split(|&c| c == 0).next().unwrap_or(name)).into_owned();
        let (start, size) = (u64_at(at + 16)?, u64_at(at + 24)?);
        let end = start.saturating_add(size);
        if end > len {
            return Some(format!(
                "bytes {at}–{} (TOC entry of section `{name}`: {start}–{end}, past the end)",
                at + SECTION
            ));
        }
        if named.is_none() && !name.is_empty() && message.to_ascii_uppercase().contains(&name) {
            named = Some(format!("bytes {start}–{end} (section `{name}`)"));
        }
    }
    named
}

#[cfg(test)]
mod tests;
