//! Finding things in pipeline source text: after typed deserialisation the spans are gone, so
//! validation errors (out-of-range values, duplicate ids, dangling references) are located by
//! searching the source for the entry and field they concern, with comments and string contents
//! masked so a match inside a comment is never reported.

/// Source text with comments blanked out (same byte offsets), for searching.
#[derive(Debug)]
pub struct Masked {
    text: String,
    masked: Vec<u8>,
}

impl Masked {
    /// Masks `//` and `/* */` comments (nested block comments as RON allows).
    pub fn new(text: &str) -> Self {
        let b = text.as_bytes();
        let mut m = b.to_vec();
        let mut i = 0;
        let mut in_str = false;
        while i < b.len() {
            if in_str {
                if b[i] == b'\\' {
                    i += 2;
                    continue;
                }
                if b[i] == b'"' {
                    in_str = false;
                }
                i += 1;
            } else if b[i] == b'"' {
                in_str = true;
                i += 1;
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
            } else {
                i += 1;
            }
        }
        Self { text: text.to_owned(), masked: m }
    }

    /// 1-based (line, column) of a byte offset.
    pub fn line_col(&self, offset: usize) -> (usize, usize) {
        let upto = &self.text[..offset.min(self.text.len())];
        let line = upto.matches('\n').count() + 1;
        let col = upto.rsplit('\n').next().map_or(0, |l| l.chars().count()) + 1;
        (line, col)
    }

    /// Offset of `key` followed by optional white space and `:` and then `"value"`, i.e. `id: "x"`.
    pub fn find_key_string(&self, key: &str, value: &str, from: usize) -> Option<usize> {
        self.find_key_strings(key, value, from).into_iter().next()
    }

    /// Offsets of every `key: "value"` at or after `from`, in order.
    pub fn find_key_strings(&self, key: &str, value: &str, from: usize) -> Vec<usize> {
        let needle = format!("\"{value}\"");
        let mut out = Vec::new();
        let mut start = from;
        while let Some(p) = find(&self.masked, needle.as_bytes(), start) {
            let before = trim_back(&self.masked[..p]);
            if let Some(before) = before.strip_suffix(b":") {
                let before = trim_back(before);
                if before.ends_with(key.as_bytes()) && ident_boundary(before, before.len() - key.len()) {
                    out.push(before.len() - key.len());
                }
            }
            start = p + 1;
        }
        out
    }

    /// Offset of a map key `"name"` followed by `:` (preset and override names).
    pub fn find_map_key(&self, name: &str, from: usize) -> Option<usize> {
        let needle = format!("\"{name}\"");
        let mut start = from;
        while let Some(p) = find(&self.masked, needle.as_bytes(), start) {
            let after = &self.masked[p + needle.len()..];
            let rest = after.iter().position(|c| !c.is_ascii_whitespace());
            if rest.is_some_and(|r| after[r] == b':') {
                return Some(p);
            }
            start = p + 1;
        }
        None
    }

    /// Offset of field `name:` at or after `from` (the first one, which lies inside the entry that
    /// starts at `from` as long as that entry sets the field).
    pub fn find_field(&self, name: &str, from: usize) -> Option<usize> {
        let mut start = from;
        while let Some(p) = find(&self.masked, name.as_bytes(), start) {
            let after = &self.masked[p + name.len()..];
            let colon = after.iter().position(|c| !c.is_ascii_whitespace()).is_some_and(|r| after[r] == b':');
            if colon && ident_boundary(&self.masked, p) && !is_ident(after.first().copied()) {
                return Some(p);
            }
            start = p + 1;
        }
        None
    }

    /// Offset of the first occurrence of a plain string literal `"s"`.
    pub fn find_string(&self, s: &str, from: usize) -> Option<usize> {
        find(&self.masked, format!("\"{s}\"").as_bytes(), from)
    }
}

fn is_ident(c: Option<u8>) -> bool {
    c.is_some_and(|c| c.is_ascii_alphanumeric() || c == b'_')
}

fn ident_boundary(b: &[u8], p: usize) -> bool {
    p == 0 || !is_ident(b.get(p - 1).copied())
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
mod tests {
    use super::*;

    #[test]
    fn skips_comments_and_finds_fields() {
        let src = "// id: \"hg\" in a comment\n(tables: [\n  PhaseHg(id: \"hg\", /* mu_bins: 3 */ mu_bins: 0),\n])";
        let m = Masked::new(src);
        let e = m.find_key_string("id", "hg", 0).unwrap();
        assert_eq!(m.line_col(e), (3, 11));
        let f = m.find_field("mu_bins", e).unwrap();
        assert_eq!(m.line_col(f), (3, 38));
    }

    #[test]
    fn field_match_respects_identifier_boundaries() {
        let m = Masked::new("(xmu_bins: 1, mu_bins_x: 2, mu_bins : 3)");
        let f = m.find_field("mu_bins", 0).unwrap();
        assert_eq!(m.line_col(f), (1, 29));
    }
}
