//! Finding things in pipeline source text: after typed deserialisation the spans are gone, so
//! validation errors (out-of-range values, duplicate ids, dangling references) are located by
//! searching the source for the entry and field they concern, with comments and string contents
//! masked so a match inside a comment is never reported.

/// Source text with comments and string contents blanked out (same byte offsets), for searching,
/// plus every string literal's decoded value (escapes such as `"h\u{67}"` and raw strings
/// `r#"…"#` resolved), so an entry is found by the value RON gave it, not by its spelling.
///
/// Every lookup is linear in the size of what it returns or scans (an entry, a line), never in the
/// whole file: validating 8,000 tables must not search the file 8,000 times (issue 37).
#[derive(Debug)]
pub struct Masked {
    text: String,
    masked: Vec<u8>,
    /// Byte offset of the start of each line.
    line_starts: Vec<usize>,
    /// Whether each line is pure ASCII (its column is then a byte difference).
    line_ascii: Vec<bool>,
    /// (start, end) byte range of every string literal (quotes included), in file order.
    strings: Vec<(usize, usize)>,
    /// Decoded value → indices into `strings`, in file order.
    by_value: std::collections::HashMap<String, Vec<usize>>,
}

impl Masked {
    /// Masks `//` and `/* */` comments (nested block comments as RON allows) and string contents.
    pub fn new(text: &str) -> Self {
        let b = text.as_bytes();
        let mut m = b.to_vec();
        let mut strings = Vec::new();
        let mut by_value: std::collections::HashMap<String, Vec<usize>> = std::collections::HashMap::new();
        let mut i = 0;
        while i < b.len() {
            if let Some((end, value)) = string_literal(b, i) {
                for c in &mut m[i + 1..end.saturating_sub(1).max(i + 1)] {
                    if *c != b'\n' {
                        *c = b' ';
                    }
                }
                by_value.entry(value).or_default().push(strings.len());
                strings.push((i, end));
                i = end;
            } else if b[i] == b'/' && b.get(i + 1) == Some(&b'/') {
                while i < b.len() && b[i] != b'\n' {
                    m[i] = b' ';
                    i += 1;
                }
            } else if b[i] == b'/' && b.get(i + 1) == Some(&b'*') {
                let mut depth = 0usize;
                while i < b.len() {
                    if b[i] == b'/' && b.get(i + 1) == Some(&b'*') {
                        depth += 1;
                        m[i] = b' ';
                        m[i + 1] = b' ';
                        i += 2;
                    } else if b[i] == b'*' && b.get(i + 1) == Some(&b'/') {
                        depth = depth.saturating_sub(1);
                        m[i] = b' ';
                        m[i + 1] = b' ';
                        i += 2;
                        if depth == 0 {
                            break;
                        }
                    } else {
                        if b[i] != b'\n' {
                            m[i] = b' ';
                        }
                        i += 1;
                    }
                }
            } else if let Some(n) = ron_only_whitespace(&b[i..]) {
                // White space to RON but not to `u8::is_ascii_whitespace` (vertical tab, NEL, the
                // direction marks and line/paragraph separators): blanked so `id:\x0B"x"` is found.
                m[i..i + n].fill(b' ');
                i += n;
            } else {
                i += 1;
            }
        }
        let mut line_starts = vec![0];
        line_starts.extend(b.iter().enumerate().filter(|(_, c)| **c == b'\n').map(|(i, _)| i + 1));
        let line_ascii = line_starts
            .iter()
            .enumerate()
            .map(|(k, &s)| b[s..line_starts.get(k + 1).copied().unwrap_or(b.len())].is_ascii())
            .collect();
        Self { text: text.to_owned(), masked: m, line_starts, line_ascii, strings, by_value }
    }

    /// 1-based (line, column) of a byte offset.
    pub fn line_col(&self, offset: usize) -> (usize, usize) {
        let offset = offset.min(self.text.len());
        let line = self.line_starts.partition_point(|&s| s <= offset).max(1);
        let start = self.line_starts[line - 1];
        let col = if self.line_ascii[line - 1] {
            offset - start
        } else {
            self.text.get(start..offset).map_or(offset - start, |l| l.chars().count())
        };
        (line, col + 1)
    }

    /// Offset of `key` followed by optional white space and `:` and then `"value"`, i.e. `id: "x"`.
    pub fn find_key_string(&self, key: &str, value: &str, from: usize) -> Option<usize> {
        self.find_key_strings(key, value, from).into_iter().next()
    }

    /// Offsets of every `key: "value"` at or after `from`, in order.
    pub fn find_key_strings(&self, key: &str, value: &str, from: usize) -> Vec<usize> {
        let mut out = Vec::new();
        for p in self.literals(value, from) {
            let mut before = trim_back(&self.masked[..p]);
            // RON also accepts the option spelled out: `id: Some("x")`, and even `id: Some"x"`.
            if let Some(b) = before.strip_suffix(b"(") {
                before = trim_back(b);
            }
            if let Some(b) = before.strip_suffix(b"Some")
                && ident_boundary(b, b.len())
            {
                before = trim_back(b);
            }
            if let Some(before) = before.strip_suffix(b":") {
                let before = trim_back(before);
                if before.ends_with(key.as_bytes()) && ident_boundary(before, before.len() - key.len()) {
                    out.push(before.len() - key.len());
                }
            }
        }
        out
    }

    /// Offset of a map key `"name"` followed by `:` (preset and override names).
    pub fn find_map_key(&self, name: &str, from: usize) -> Option<usize> {
        self.literals(name, from).find(|&p| {
            let end = self.literal_end(p);
            let after = &self.masked[end..];
            let rest = after.iter().position(|c| !c.is_ascii_whitespace());
            rest.is_some_and(|r| after[r] == b':')
        })
    }

    /// Offset of field `name:` at or after `from`, inside the entry that contains `from` (the
    /// search stops at the parenthesis that closes it, so a field the entry does not set is never
    /// reported at another entry's).
    pub fn find_field(&self, name: &str, from: usize) -> Option<usize> {
        let end = self.entry_end(from);
        let hay = self.masked.get(..end)?;
        let mut start = from;
        while let Some(p) = find(hay, name.as_bytes(), start) {
            let after = &hay[p + name.len()..];
            let colon = after.iter().position(|c| !c.is_ascii_whitespace()).is_some_and(|r| after[r] == b':');
            if colon && ident_boundary(hay, p) && !is_ident(after.first().copied()) {
                return Some(p);
            }
            start = p + 1;
        }
        None
    }

    /// Offset of the first string literal at or after `from` whose value is `s`.
    pub fn find_string(&self, s: &str, from: usize) -> Option<usize> {
        self.literals(s, from).next()
    }

    /// Offset of the `index`-th (0-based) entry of the list given as field `list` (e.g. the third
    /// table of `tables: [...]`), for entries that have no id to be found by.
    pub fn find_list_entry(&self, list: &str, index: usize) -> Option<usize> {
        let field = self.find_field(list, 0)?;
        let open = field + self.masked[field..].iter().position(|&c| c == b'[')?;
        let mut depth = 0usize;
        let mut seen = 0usize;
        let mut expect_entry = true;
        let mut i = open + 1;
        while i < self.masked.len() {
            let c = self.masked[i];
            if depth == 0 && expect_entry && !c.is_ascii_whitespace() && c != b']' && c != b',' {
                if seen == index {
                    return Some(i);
                }
                seen += 1;
                expect_entry = false;
            }
            match c {
                b'"' => {
                    i = self.literal_end(i);
                    continue;
                }
                b'(' | b'[' | b'{' => depth += 1,
                b')' | b']' | b'}' if depth == 0 => return None,
                b')' | b']' | b'}' => depth -= 1,
                b',' if depth == 0 => expect_entry = true,
                _ => {}
            }
            i += 1;
        }
        None
    }

    /// End (exclusive) of the innermost bracketed entry containing `from`: the offset of the
    /// bracket that closes it, or the end of the text.
    fn entry_end(&self, from: usize) -> usize {
        let mut depth = 0usize;
        let mut i = from;
        while i < self.masked.len() {
            match self.masked[i] {
                b'"' => {
                    i = self.literal_end(i);
                    continue;
                }
                b'(' | b'[' | b'{' => depth += 1,
                b')' | b']' | b'}' if depth == 0 => return i,
                b')' | b']' | b'}' => depth -= 1,
                _ => {}
            }
            i += 1;
        }
        self.masked.len()
    }

    /// Start offsets of the literals with value `value` at or after `from`.
    fn literals(&self, value: &str, from: usize) -> impl Iterator<Item = usize> + '_ {
        self.by_value.get(value).into_iter().flatten().map(|&k| self.strings[k].0).filter(move |&p| p >= from)
    }

    /// End (exclusive) of the literal whose opening quote (or `r` of a raw string) is at `start`;
    /// `start + 1` if no literal starts there.
    fn literal_end(&self, start: usize) -> usize {
        let k = self.strings.partition_point(|&(s, _)| s < start);
        match self.strings.get(k) {
            Some(&(s, e)) if s == start => e,
            // The quote of a raw string sits after its `r#…`: find the literal containing it.
            _ => match k.checked_sub(1).and_then(|k| self.strings.get(k)) {
                Some(&(s, e)) if s < start && start < e => e,
                _ => start + 1,
            },
        }
    }
}

/// The string literal starting at `i` (a `"…"` with escapes, or a raw `r"…"` / `r#"…"#`):
/// its end (exclusive) and decoded value. An unterminated literal runs to the end of the text.
fn string_literal(b: &[u8], i: usize) -> Option<(usize, String)> {
    if b[i] == b'r' && (i == 0 || !is_ident(Some(b[i - 1]))) {
        let hashes = b[i + 1..].iter().take_while(|&&c| c == b'#').count();
        if b.get(i + 1 + hashes) != Some(&b'"') {
            return None;
        }
        let body = i + 2 + hashes;
        let mut j = body;
        while j < b.len() {
            if b[j] == b'"' && b[j + 1..].iter().take(hashes).filter(|&&c| c == b'#').count() == hashes {
                let value = String::from_utf8_lossy(&b[body..j]).into_owned();
                return Some(((j + 1 + hashes).min(b.len()), value));
            }
            j += 1;
        }
        return Some((b.len(), String::from_utf8_lossy(&b[body..]).into_owned()));
    }
    if b[i] != b'"' {
        return None;
    }
    let mut out = Vec::new();
    let mut j = i + 1;
    while j < b.len() {
        match b[j] {
            b'"' => return Some((j + 1, String::from_utf8_lossy(&out).into_owned())),
            b'\\' => {
                let (len, decoded) = unescape(&b[j + 1..]);
                out.extend_from_slice(decoded.as_bytes());
                j += 1 + len;
            }
            c => {
                out.push(c);
                j += 1;
            }
        }
    }
    Some((b.len(), String::from_utf8_lossy(&out).into_owned()))
}

/// One escape after a backslash: (bytes consumed, decoded text). Unknown escapes decode to
/// themselves (RON rejects them before any lookup happens).
fn unescape(b: &[u8]) -> (usize, String) {
    let simple = |c: char| (1, c.to_string());
    match b.first() {
        Some(b'n') => simple('\n'),
        Some(b't') => simple('\t'),
        Some(b'r') => simple('\r'),
        Some(b'0') => simple('\0'),
        Some(b'u') if b.get(1) == Some(&b'{') => {
            let close = b.iter().take(12).position(|&c| c == b'}');
            let ch = close.and_then(|c| {
                let hex = std::str::from_utf8(&b[2..c]).ok()?;
                char::from_u32(u32::from_str_radix(hex, 16).ok()?)
            });
            match (close, ch) {
                (Some(c), Some(ch)) => (c + 1, ch.to_string()),
                _ => (1, "u".into()),
            }
        }
        Some(b'u') if b.len() >= 5 => {
            let ch = std::str::from_utf8(&b[1..5])
                .ok()
                .and_then(|h| u32::from_str_radix(h, 16).ok())
                .and_then(char::from_u32);
            ch.map_or((1, "u".into()), |ch| (5, ch.to_string()))
        }
        // A line continuation: `\` at the end of a line skips the line break and the white space
        // after it (ron's `consume_string_continuation`).
        Some(b'\n') => (continuation(b, 1), String::new()),
        Some(b'\r') if b.get(1) == Some(&b'\n') => (continuation(b, 2), String::new()),
        // `\xHH`: an ASCII byte, or the first of up to four `\xHH` that spell one UTF-8 character.
        Some(b'x') => {
            let byte = |at: usize| {
                let hex = std::str::from_utf8(b.get(at + 1..at + 3)?).ok()?;
                u8::from_str_radix(hex, 16).ok()
            };
            let mut bytes = Vec::with_capacity(4);
            let mut len = 0;
            while let Some(c) = byte(len) {
                bytes.push(c);
                len += 3;
                if let Ok(ch) = std::str::from_utf8(&bytes) {
                    return (len, ch.to_owned());
                }
                if bytes.len() == 4 || b.get(len..len + 2) != Some(b"\\x") {
                    break;
                }
                len += 1;
            }
            (1, "x".into())
        }
        Some(&c) if c.is_ascii() => simple(char::from(c)),
        Some(_) | None => (0, String::new()),
    }
}

/// Bytes consumed by a line continuation whose line break is `b[..n]`: the break and the spaces,
/// tabs and line breaks after it.
fn continuation(b: &[u8], n: usize) -> usize {
    n + b[n..].iter().take_while(|c| matches!(c, b' ' | b'\t' | b'\n' | b'\r')).count()
}

fn is_ident(c: Option<u8>) -> bool {
    c.is_some_and(|c| c.is_ascii_alphanumeric() || c == b'_')
}

fn ident_boundary(b: &[u8], p: usize) -> bool {
    p == 0 || !is_ident(b.get(p - 1).copied())
}

/// Byte length of a character at the start of `b` that RON's parser skips as white space but
/// `u8::is_ascii_whitespace` does not (ron's `is_whitespace_char`: `\x0B`, U+0085, U+200E, U+200F,
/// U+2028, U+2029), or `None`.
fn ron_only_whitespace(b: &[u8]) -> Option<usize> {
    match b {
        [0x0B, ..] => Some(1),
        [0xC2, 0x85, ..] => Some(2),
        [0xE2, 0x80, 0x8E | 0x8F | 0xA8 | 0xA9, ..] => Some(3),
        _ => None,
    }
}

fn trim_back(b: &[u8]) -> &[u8] {
    let end = b.iter().rposition(|c| !c.is_ascii_whitespace()).map_or(0, |e| e + 1);
    &b[..end]
}

fn find(hay: &[u8], needle: &[u8], from: usize) -> Option<usize> {
    if needle.is_empty() || from >= hay.len() {
        return None;
    }
    hay[from..].windows(needle.len()).position(|w| w == needle).map(|p| p + from)
}

#[cfg(test)]
mod tests;
