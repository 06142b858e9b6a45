//! Golden tables: `tables/golden/golden.ron` recompiled and compared byte for byte with the committed
//! `.vtab` files (and with `voltab diff` for a readable report when they differ).
//! Re-bless deliberately with `VOLTAB_BLESS=1 cargo test --test golden`.
//!
//! Also the frozen fixture of container version 1.0 (`tests/fixtures/vtab-1.0/`), which is never
//! regenerated: every later voltab must keep decoding it to the same values.

mod common;

use std::path::Path;

use voltab::compile::{CompileOptions, compile};
use voltab::container::{self, VtabReader};
use voltab::physics::hg;
use voltab::pipeline::Disk;
use voltab::registry::load_and_validate;
use voltab::tables::phase_hg::PhaseHgTable;

#[test]
fn golden_tables_are_reproduced_byte_for_byte() {
    let golden = common::root().join("tables/golden");
    let d = common::tempdir();
    let p = load_and_validate(&golden.join("golden.ron"), &Disk).unwrap();
    compile(&p, &CompileOptions { out_dir: d.path().into(), ..Default::default() }).unwrap();
    let bless = std::env::var_os("VOLTAB_BLESS").is_some();
    let mut failures = Vec::new();
    for t in p.tables() {
        let fresh = d.path().join(format!("{}.vtab", t.id()));
        let committed = golden.join(format!("{}.vtab", t.id()));
        if bless {
            std::fs::copy(&fresh, &committed).unwrap();
            continue;
        }
        if std::fs::read(&fresh).unwrap() != std::fs::read(&committed).unwrap_or_default() {
            let report = match (VtabReader::open(&fresh), VtabReader::open(&committed)) {
                (Ok(mut a), Ok(mut b)) => format!("{:#?}", container::diff(&mut a, &mut b)),
                (_, Err(e)) => format!("committed file unreadable: {e}"),
                (Err(e), _) => format!("fresh file unreadable: {e}"),
            };
            failures.push(format!("{}: bytes differ\n{report}", t.id()));
        }
    }
    assert!(
        failures.is_empty(),
        "{}\nIf the change is intended: VOLTAB_BLESS=1 cargo test --test golden",
        failures.join("\n")
    );
}

#[test]
fn voltab_diff_agrees_with_the_golden_comparison() {
    let golden = common::root().join("tables/golden/golden_hg_f32.vtab");
    let o = common::run(&["diff", golden.to_str().unwrap(), golden.to_str().unwrap()]);
    assert!(o.status.success() && common::text(&o).contains("identical values"), "{}", common::text(&o));
    let other = common::root().join("tables/golden/golden_hg_quantised.vtab");
    let o = common::run(&["diff", golden.to_str().unwrap(), other.to_str().unwrap()]);
    assert_eq!(o.status.code(), Some(1), "{}", common::text(&o));
    assert!(common::text(&o).contains("header:"), "{}", common::text(&o));
}

fn fixture() -> std::path::PathBuf {
    common::root().join("tests/fixtures/vtab-1.0/phase_hg.vtab")
}

/// Frozen bytes written by voltab 0.1 (container 1.0, PhaseHg layout 1); values checked against the
/// HG formulas, not against a re-generation, so a decoder change cannot hide behind a re-bless.
#[test]
fn frozen_v1_0_fixture_still_decodes() {
    let mut r = VtabReader::open(&fixture()).unwrap();
    assert_eq!(r.version(), (1, 0));
    r.verify().unwrap();
    assert_eq!(r.header().kind, "PhaseHg");
    let t = PhaseHgTable::open(&fixture(), None).unwrap();
    assert_eq!(t.g, [-0.9, 0.0, 0.5, 0.999]);
    for (gi, &g) in t.g.iter().enumerate() {
        for mu in [-1.0, -0.5, 0.0, 0.5, 1.0] {
            // mu = ±1, ±0.5, 0 are nodes of the 33-node linear axis, so lookups return stored f32 nodes.
            let stored = t.phase_lerp(gi, mu).unwrap();
            let exact = hg::phase(mu, g);
            assert!((stored - exact).abs() <= 6e-8 * exact, "g {g} mu {mu}: {stored} vs {exact}");
        }
    }
}

#[test]
fn fixture_is_not_regenerated() {
    // The fixture equals the golden table it was copied from at freeze time; if the golden is
    // re-blessed, the fixture must stay as it is (compare against its frozen hash).
    let bytes = std::fs::read(fixture()).unwrap();
    let hash = blake3::hash(&bytes).to_hex().to_string();
    let frozen = std::fs::read_to_string(fixture().with_extension("blake3")).unwrap();
    assert_eq!(hash, frozen.trim(), "tests/fixtures are frozen: never rewrite them");
    assert!(Path::new(&fixture()).exists());
}
