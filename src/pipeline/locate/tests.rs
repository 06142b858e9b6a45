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

/// Found by fuzzing (issue 37): `id: Some"x"` parses, and its errors lost their location.
#[test]
fn ids_written_as_explicit_options_are_found() {
    let m = Masked::new("(tables: [A(id: Some(\"a\")), B(id: Some\"b\"), C(id: XSome\"c\")])");
    assert_eq!(m.find_key_string("id", "a", 0).map(|o| m.line_col(o)), Some((1, 13)));
    assert_eq!(m.find_key_string("id", "b", 0).map(|o| m.line_col(o)), Some((1, 31)));
    assert_eq!(m.find_key_string("id", "c", 0), None);
}

/// Found by the long fuzz run (fuzz/artifacts/pipeline/crash-3869b6f7…): a `\` at the end of a
/// line continues the string without the break and the indentation, and `\xC3\xA9` is one
/// character (é), as RON decodes them; the locator kept the break and read two Latin-1 letters.
#[test]
fn escapes_decode_as_ron_decodes_them() {
    #[derive(serde::Deserialize)]
    struct T {
        a: String,
        b: String,
        c: String,
    }
    let src = "(a: \"ab\\\n   \n\tcd\", b: \"ab\\\r\n  cd\", c: \"caf\\xC3\\xA9\\x21\")";
    let t: T = ron::from_str(src).expect("RON decodes it");
    assert_eq!((t.a.as_str(), t.b.as_str(), t.c.as_str()), ("abcd", "abcd", "café!"));
    let m = Masked::new(src);
    assert_eq!(m.find_key_string("a", &t.a, 0), Some(1));
    assert_eq!(m.find_key_string("b", &t.b, 0), src.find("b:"));
    assert_eq!(m.find_key_string("c", &t.c, 0), src.find("c:"));
}

#[test]
fn field_match_respects_identifier_boundaries() {
    let m = Masked::new("(xmu_bins: 1, mu_bins_x: 2, mu_bins : 3)");
    let f = m.find_field("mu_bins", 0).unwrap();
    assert_eq!(m.line_col(f), (1, 29));
}
