//! The `.vtab` tools as a person uses them: inspect, verify (truncation, flipped bytes, newer
//! versions), diff with tolerances. Exit codes and messages are part of the contract.

mod common;

use common::{run, tempdir, text, write};

fn compiled(dir: &std::path::Path) -> std::path::PathBuf {
    let p = write(
        dir,
        "p.ron",
        "(tables: [PhaseHg(id: \"t\", g: [-0.5, 0.0, 0.5], mu_bins: 128, xi_bins: 64, zh_order: 6)])",
    );
    let out = dir.join("out");
    let o = run(&["compile", p.to_str().unwrap(), "--out", out.to_str().unwrap()]);
    assert!(o.status.success(), "{}", text(&o));
    out.join("t.vtab")
}

#[test]
fn inspect_shows_header_axes_chunks_and_ratio() {
    let d = tempdir();
    let f = compiled(d.path());
    let o = run(&["inspect", f.to_str().unwrap(), "--chunks"]);
    assert!(o.status.success(), "{}", text(&o));
    let s = text(&o);
    for want in [
        "format          vtab 1.0",
        "kind            PhaseHg (layout v1)",
        "generator       phase_hg/1",
        "array 0: phase [3 x 128] F32",
        "axis mu",
        "axis g",
        "3 chunks",
        "slice     2:",
        "ratio",
    ] {
        assert!(s.contains(want), "missing {want:?} in\n{s}");
    }
}

#[test]
fn verify_detects_truncation_and_flipped_bytes() {
    let d = tempdir();
    let f = compiled(d.path());
    let o = run(&["verify", f.to_str().unwrap()]);
    assert!(o.status.success(), "{}", text(&o));
    let good = std::fs::read(&f).unwrap();

    let cut = d.path().join("cut.vtab");
    std::fs::write(&cut, &good[..good.len() - 100]).unwrap();
    let o = run(&["verify", cut.to_str().unwrap()]);
    assert_eq!(o.status.code(), Some(1));
    assert!(text(&o).contains("truncated"), "{}", text(&o));

    // Flip one byte in the middle of the payload: the message names the bad chunk.
    let mut flipped = good.clone();
    let at = good.len() - 200;
    flipped[at] ^= 0x10;
    let bad = d.path().join("flipped.vtab");
    std::fs::write(&bad, &flipped).unwrap();
    let o = run(&["verify", bad.to_str().unwrap(), f.to_str().unwrap()]);
    assert_eq!(o.status.code(), Some(1));
    let s = text(&o);
    assert!(s.contains("checksum") && s.contains("slice") && s.contains("1 of 2 files failed"), "{s}");
    assert!(!s.contains("panicked"));
}

#[test]
fn newer_major_version_is_refused_with_advice() {
    let d = tempdir();
    let f = compiled(d.path());
    let mut b = std::fs::read(&f).unwrap();
    b[8] = 2; // major version, little endian u16 after the 8-byte magic
    let newer = d.path().join("newer.vtab");
    std::fs::write(&newer, &b).unwrap();
    let o = run(&["inspect", newer.to_str().unwrap()]);
    assert_eq!(o.status.code(), Some(1));
    let s = text(&o);
    assert!(s.contains("2.0") && s.contains("1.0") && s.to_lowercase().contains("upgrade"), "{s}");
}

#[test]
fn not_a_table_and_missing_files_are_clear_errors() {
    let d = tempdir();
    let junk = write(d.path(), "junk.vtab", "hello, this is not a table at all");
    let o = run(&["verify", junk.to_str().unwrap()]);
    assert_eq!(o.status.code(), Some(1));
    assert!(text(&o).contains("not a .vtab file"), "{}", text(&o));
    let o = run(&["inspect", d.path().join("missing.vtab").to_str().unwrap()]);
    assert_eq!(o.status.code(), Some(1));
    assert!(text(&o).contains("missing.vtab"), "{}", text(&o));
}

#[test]
fn diff_reports_per_chunk_maxima_and_honours_tolerances() {
    let d = tempdir();
    let p = write(
        d.path(),
        "p.ron",
        "(tables: [PhaseHg(id: \"exact\", g: [0.5], mu_bins: 64, xi_bins: 64), PhaseHg(id: \"lossy\", g: [0.5], mu_bins: 64, xi_bins: 64, mantissa_bits: 12)])",
    );
    let out = d.path().join("out");
    assert!(run(&["compile", p.to_str().unwrap(), "--out", out.to_str().unwrap()]).status.success());
    let (a, b) = (out.join("exact.vtab"), out.join("lossy.vtab"));
    // Headers differ in the definition text, so even loose tolerances report a difference…
    let o = run(&["diff", a.to_str().unwrap(), b.to_str().unwrap(), "--rel-tol", "1"]);
    let s = text(&o);
    assert!(s.contains("phase") && s.contains("max rel"), "{s}");
    // …and the reported relative error respects the stated quantisation bound 2^-13.
    let max_rel = s
        .lines()
        .filter(|l| l.contains("max rel"))
        .filter_map(|l| l.split("max rel ").nth(1)?.split_whitespace().next()?.parse::<f64>().ok())
        .fold(0.0, f64::max);
    assert!(max_rel > 0.0 && max_rel <= 2f64.powi(-13), "{s}");
}

#[test]
fn unknown_kinds_and_newer_layouts_are_refused_by_verify() {
    use voltab::container::{ArrayDesc, ArrayValues, Axis, ElementType, EncodeOptions, Header, encode};
    let d = tempdir();
    let make = |kind: &str, layout: u32| {
        let header = Header {
            kind: kind.into(),
            kind_schema_version: layout,
            generator_version: "test/1".into(),
            definition_ron: "()".into(),
            content_key: [0; 32],
            arrays: vec![ArrayDesc {
                name: "a".into(),
                description: String::new(),
                unit: String::new(),
                element: ElementType::F32,
                axes: vec![Axis::linear("x", "", 0.0, 1.0, 4)],
                quantization: None,
            }],
        };
        let bytes =
            encode(&header, &[ArrayValues::F32(vec![1.0, 2.0, 3.0, 4.0])], &EncodeOptions::default()).unwrap().bytes;
        let p = d.path().join(format!("{kind}-{layout}.vtab"));
        std::fs::write(&p, bytes).unwrap();
        p
    };
    let o = run(&["verify", make("FutureKind", 1).to_str().unwrap()]);
    assert_eq!(o.status.code(), Some(1));
    assert!(
        text(&o).contains("unknown table kind `FutureKind`") && text(&o).contains("upgrade voltab"),
        "{}",
        text(&o)
    );
    let o = run(&["verify", make("PhaseHg", 99).to_str().unwrap()]);
    assert_eq!(o.status.code(), Some(1));
    assert!(text(&o).contains("layout version 99 is newer"), "{}", text(&o));
    // inspect still shows the header of a table it cannot consume, with a warning.
    let o = run(&["inspect", make("FutureKind", 1).to_str().unwrap()]);
    assert!(o.status.success() && text(&o).contains("warning         unknown table kind"), "{}", text(&o));
}

/// Regression: a container-valid file of kind PhaseHg with a 1-sample μ axis made lookups index out of
/// bounds; it must be refused with a message instead.
#[test]
fn a_well_formed_but_unusable_phase_hg_file_is_refused_without_panicking() {
    use voltab::container::{ArrayDesc, ArrayValues, Axis, ElementType, EncodeOptions, Header, encode};
    use voltab::tables::phase_hg::{ARRAYS, PhaseHgTable};
    let d = tempdir();
    let desc = |name: &str, second: Axis| ArrayDesc {
        name: name.into(),
        description: String::new(),
        unit: String::new(),
        element: ElementType::F64,
        axes: vec![Axis::explicit("g", "", vec![0.5]), second],
        quantization: None,
    };
    let one = Axis::explicit("mu", "", vec![0.0]);
    let arrays: Vec<ArrayDesc> = ARRAYS.iter().map(|n| desc(n, one.clone())).collect();
    let header = Header {
        kind: "PhaseHg".into(),
        kind_schema_version: 1,
        generator_version: "hostile/1".into(),
        definition_ron: "()".into(),
        content_key: [0; 32],
        arrays,
    };
    let values: Vec<ArrayValues> = (0..5).map(|_| ArrayValues::F64(vec![1.0])).collect();
    let p = d.path().join("bad.vtab");
    std::fs::write(&p, encode(&header, &values, &EncodeOptions::default()).unwrap().bytes).unwrap();
    // Its stored definition is checked first (issue 37)…
    let e = PhaseHgTable::open(&p, None).unwrap_err().to_string();
    assert!(e.contains("bad.vtab") && e.contains("stored definition is not a readable PhaseHg definition"), "{e}");
    // …and with a valid definition the arrays themselves are still checked.
    let def = voltab::tables::phase_hg::PhaseHg {
        g: voltab::tables::phase_hg::GValues::List(vec![0.5]),
        ..Default::default()
    };
    let header = Header { definition_ron: voltab::tables::TableDef::PhaseHg(def).canonical_ron(), ..header };
    std::fs::write(&p, encode(&header, &values, &EncodeOptions::default()).unwrap().bytes).unwrap();
    let e = PhaseHgTable::open(&p, None).unwrap_err().to_string();
    assert!(e.contains("unusable for lookups"), "{e}");
}
