use super::*;

/// A crate file with the given TOC offset and sections `(name, start, size)`, padded to `len`.
fn crate_bytes(toc: u64, sections: &[(&str, u64, u64)], len: usize) -> Vec<u8> {
    let mut b = b"PXR-USDC".to_vec();
    b.extend_from_slice(&[0, 8, 0, 0, 0, 0, 0, 0]);
    b.extend_from_slice(&toc.to_le_bytes());
    b.resize(len, 0);
    let t = toc as usize;
    if t >= 32 && t + 8 <= len {
        b[t..t + 8].copy_from_slice(&(sections.len() as u64).to_le_bytes());
        for (k, (name, start, size)) in sections.iter().enumerate() {
            let at = t + 8 + k * 32;
            if at + 32 > len {
                break;
            }
            b[at..at + name.len()].copy_from_slice(name.as_bytes());
            b[at + 16..at + 24].copy_from_slice(&start.to_le_bytes());
            b[at + 24..at + 32].copy_from_slice(&size.to_le_bytes());
        }
    }
    b
}

#[test]
fn malformed_paths_are_found_outside_strings_assets_and_comments() {
    let ok = "#usda 1.0 <not a path in a comment>\ndef X \"A\" (doc = \"a <b c> d\" doc = \"\"\"<x\n>\"\"\")\n{\n\
              asset t = @tex.<UDIM>.exr@\n/* <x y> */ rel r = </A/B.c[/D].e>\n    rel v = </A{v=s}B>\n}\n";
    assert_eq!(malformed_path(ok), None);
    // A `>` gone missing: the path runs into the next line.
    let missing = "#usda 1.0\ndef X \"A\" {\n    rel r = </World/Lo\"\n    rel q = </B>\n}\n";
    let (line, column, what) = malformed_path(missing).expect("malformed");
    assert_eq!((line, column), (3, 13), "{what}");
    assert!(what.starts_with("'\"' in `</World/Lo"), "{what}");
}

#[test]
fn attribute_names_and_self_parented_paths() {
    for ok in ["xformOp:translate", "xformOp:rotateXYZ:tilt", "_a:b1", "größe"] {
        assert!(is_attribute_name(ok), "{ok}");
    }
    for bad in ["xformOp:ttoken[] xformOpOrder = [", "", "a::b", "1a", "xformOp:", "a b"] {
        assert!(!is_attribute_name(bad), "{bad}");
    }
    let p = |s: &str| openusd::sdf::Path::new(s).expect("openusd accepts any path text");
    assert!(ancestry_terminates(&p("/World/Looks/Mat.outputs:surface")));
    assert!(ancestry_terminates(&p("/A{v=s}B")));
    // Ends with `}` but has no `{`: openusd gives the path itself as its parent.
    assert!(!ancestry_terminates(&p("/World/a}")));
}

#[test]
fn crate_failures_name_the_broken_part() {
    let at = |b: &[u8], m: &str| crate_failure(b, m);
    assert_eq!(at(b"PXR-USDC", "x").as_deref(), Some("bytes 0–32 (crate bootstrap; the file has 8)"));
    let mut bad_magic = crate_bytes(40, &[], 100);
    bad_magic[3] = b'?';
    assert_eq!(at(&bad_magic, "x").as_deref(), Some("bytes 0–8 (crate magic)"));
    let good = crate_bytes(100, &[("TOKENS", 32, 40), ("PATHS", 72, 20)], 200);
    assert_eq!(at(&good, "Usd crate version mismatch").as_deref(), Some("bytes 8–11 (crate version 0.8.0)"));
    assert_eq!(
        at(&crate_bytes(500, &[], 200), "Invalid TOC offset").as_deref(),
        Some("bytes 16–24 (TOC offset 500, past the end of the 200-byte file)")
    );
    assert_eq!(at(&crate_bytes(0, &[], 200), "x").as_deref(), Some("bytes 16–24 (TOC offset 0)"));
    assert_eq!(at(&crate_bytes(100, &[], 200), "x").as_deref(), Some("bytes 100–108 (TOC of 0 sections)"));
    let past = crate_bytes(100, &[("TOKENS", 32, 40), ("PATHS", 72, 500)], 200);
    assert_eq!(at(&past, "x").as_deref(), Some("bytes 140–172 (TOC entry of section `PATHS`: 72–572, past the end)"));
    // Layout intact: the section openusd's message names, else no location.
    assert_eq!(at(&good, "Failed to parse TOKENS section").as_deref(), Some("bytes 32–72 (section `TOKENS`)"));
    assert_eq!(at(&good, "Unable to read pod").as_deref(), None);
}
