//! Every diagnostic a user can trigger in a pipeline file, checked on its rendered text: kind,
//! `file:line:column`, and the hint. Also the positive paths of presets, includes and overrides.

mod common;

use std::path::Path;

use common::{tempdir, text, write};
use voltab::pipeline::{DiagnosticKind as K, Disk, Limits, PipelineError};
use voltab::registry::load_and_validate;
use voltab::registry::{load, validate};
use voltab::tables::TableDef;
use voltab::tables::phase_hg::GValues;

fn check(dir: &Path, text: &str) -> Result<voltab::registry::ValidatedPipeline, PipelineError> {
    let p = write(dir, "p.ron", text);
    load_and_validate(&p, &Disk)
}

fn err(text: &str) -> (PipelineError, String) {
    let d = tempdir();
    let e = check(d.path(), text).expect_err("pipeline should be rejected");
    let s = e.to_string();
    assert!(!s.contains("Error {") && !s.contains("SpannedError"), "debug dump leaked: {s}");
    (e, s)
}

#[test]
fn malformed_ron_names_line_and_column() {
    let (e, s) = err("(\n  tables: [\n    PhaseHg(id: \"a\" g: [0.5]),\n  ],\n)");
    assert!(e.has(K::Syntax), "{s}");
    assert!(s.contains("p.ron:3:"), "{s}");
}

#[test]
fn unknown_field_suggests_the_right_one() {
    let (e, s) = err("(tables: [PhaseHg(id: \"a\", mu_bin: 64)])");
    assert!(e.has(K::UnknownField), "{s}");
    assert!(s.contains("unknown field `mu_bin` in a PhaseHg entry"), "{s}");
    assert!(s.contains("did you mean `mu_bins`?"), "{s}");
    assert!(s.contains("p.ron:1:28"), "{s}");
}

#[test]
fn unknown_top_level_field_is_reported() {
    let (e, s) = err("(tabels: [])");
    assert!(e.has(K::UnknownField), "{s}");
    assert!(s.contains("did you mean `tables`?"), "{s}");
}

#[test]
fn unknown_kind_suggests_known_kinds() {
    let (e, s) = err("(tables: [PhaseHG(id: \"a\")])");
    assert!(e.has(K::UnknownKind), "{s}");
    assert!(s.contains("unknown table kind `PhaseHG`") && s.contains("did you mean `PhaseHg`?"), "{s}");
}

#[test]
fn wrong_type_is_reported_with_location() {
    let (e, s) = err("(tables: [\n PhaseHg(id: \"a\", mu_bins: \"many\"),\n])");
    assert!(e.has(K::WrongType), "{s}");
    assert!(s.contains("p.ron:2:"), "{s}");
    let (e, s) = err("(tables: [PhaseHg(id: \"a\", mu_bins: -3)])");
    assert!(e.has(K::WrongType), "{s}");
    assert!(s.contains("`-3` does not fit") && s.contains("non-negative whole number"), "{s}");
    let (e, s) = err("(tables: [PhaseHg(id: \"a\", g: \"forward\")])");
    assert!(e.has(K::WrongType), "{s}");
    assert!(s.contains("write g as a list"), "{s}");
}

#[test]
fn g_outside_open_interval_is_out_of_range() {
    for bad in ["1.0", "-1.0", "1.5", "NaN", "inf", "-inf"] {
        let (e, s) = err(&format!("(tables: [\n  PhaseHg(id: \"a\",\n    g: [{bad}]),\n])"));
        assert!(e.has(K::OutOfRange), "{bad}: {s}");
        assert!(s.contains("outside (-1, 1)") && s.contains("-1 < g < 1"), "{bad}: {s}");
        assert!(s.contains("p.ron:3:5"), "{bad}: {s}");
    }
}

#[test]
fn empty_and_unsorted_axes_are_rejected() {
    let (e, s) = err("(tables: [PhaseHg(id: \"a\", g: [])])");
    assert!(e.has(K::OutOfRange) && s.contains("between 1 and 4096 g values"), "{s}");
    let (_, s) = err("(tables: [PhaseHg(id: \"a\", g: [0.5, 0.5])])");
    assert!(s.contains("strictly increasing"), "{s}");
    // Regression: validation used to expand the grid before checking its count (32 GB here).
    let (e, s) = err("(tables: [PhaseHg(id: \"a\", g: (min: -0.5, max: 0.5, count: 4000000000))])");
    assert!(e.has(K::OutOfRange) && s.contains("count must be between 1 and 4096"), "{s}");
    let (_, s) = err("(tables: [PhaseHg(id: \"a\", g: (min: 0.5, max: -0.5, count: 3))])");
    assert!(s.contains("inconsistent"), "{s}");
    for bins in ["0", "1", "16777217"] {
        let (e, s) = err(&format!("(tables: [PhaseHg(id: \"a\", mu_bins: {bins})])"));
        assert!(e.has(K::OutOfRange) && s.contains("between 2 and 16777216 samples"), "{s}");
    }
    let (_, s) = err("(tables: [PhaseHg(id: \"a\", element: F32, mantissa_bits: 30)])");
    assert!(s.contains("exceeds the 23 bits of F32"), "{s}");
}

#[test]
fn absurd_sizes_are_refused_before_allocating() {
    let d = tempdir();
    let p = write(
        d.path(),
        "p.ron",
        "(tables: [PhaseHg(id: \"huge\", g: (min: -0.9, max: 0.9, count: 4096), mu_bins: 16777216, xi_bins: 16777216)])",
    );
    let e = validate(&p, load(&p, &Disk).unwrap(), &Limits { memory_bytes: 24 << 30 }).unwrap_err();
    let s = e.to_string();
    assert!(e.has(K::TooLarge), "{s}");
    // 4096 g × (2·2^24 + 2^24 + 2·33) values × 24 bytes ≈ 4.5 TiB
    assert!(s.contains("would need 4.5 TiB") && s.contains("limit on this machine is 24.0 GiB"), "{s}");
}

#[test]
fn missing_files_are_reported() {
    let d = tempdir();
    let e = load_and_validate(&d.path().join("nope.ron"), &Disk).unwrap_err();
    assert!(e.has(K::Io) && e.to_string().contains("cannot read pipeline") && e.to_string().contains("nope.ron"));
    let (e, s) = err("(\n  include: [\"missing-base.ron\"],\n)");
    assert!(e.has(K::Io), "{s}");
    assert!(s.contains("cannot read included pipeline") && s.contains("p.ron:2:13"), "{s}");
}

#[test]
fn duplicate_ids_name_both_places() {
    let (e, s) = err("(tables: [\n  PhaseHg(id: \"a\"),\n  PhaseHg(id: \"a\", g: [0.1]),\n])");
    assert!(e.has(K::DuplicateId), "{s}");
    assert!(s.contains("p.ron:3:11") && s.contains("first at") && s.contains("p.ron:2:11"), "{s}");
}

#[test]
fn dangling_references_suggest_names() {
    let (e, s) = err("(presets: {\"fine\": PhaseHg(mu_bins: 4096)}, tables: [PhaseHg(id: \"a\", preset: \"fien\")])");
    assert!(e.has(K::DanglingReference) && s.contains("did you mean `fine`?"), "{s}");
    let (e, s) = err("(tables: [PhaseHg(id: \"hg\")], overrides: {\"hgg\": PhaseHg(mu_bins: 64)})");
    assert!(e.has(K::DanglingReference) && s.contains("did you mean `hg`?"), "{s}");
    let (e, s) = err("(tables: [PhaseHg(id: \"hg\")], stages: [PlotPhase(id: \"p\", table: \"gh\")])");
    assert!(e.has(K::DanglingReference) && s.contains("reads table \"gh\""), "{s}");
    let (e, s) = err("(stages: [PlotPhase(id: \"p\")])");
    assert!(e.has(K::MissingField) && s.contains("needs `table`"), "{s}");
}

#[test]
fn ids_must_be_file_name_safe() {
    let (e, s) = err("(tables: [PhaseHg(id: \"../escape\")])");
    assert!(e.has(K::OutOfRange) && s.contains("not a valid id"), "{s}");
    let (e, _) = err("(tables: [PhaseHg(g: [0.5])])");
    assert!(e.has(K::MissingField));
}

#[test]
fn cycles_are_reported() {
    let d = tempdir();
    write(d.path(), "a.ron", "(include: [\"b.ron\"])");
    write(d.path(), "b.ron", "(include: [\"a.ron\"])");
    let e = load_and_validate(&d.path().join("a.ron"), &Disk).unwrap_err();
    assert!(e.has(K::Cycle) && e.to_string().contains("include cycle"), "{e}");
    let (e, s) = err(
        "(presets: {\"x\": PhaseHg(preset: \"y\"), \"y\": PhaseHg(preset: \"x\")}, tables: [PhaseHg(id: \"a\", preset: \"x\")])",
    );
    assert!(e.has(K::Cycle) && s.contains("preset cycle"), "{s}");
}

#[test]
fn several_problems_are_reported_together() {
    let (e, s) = err("(tables: [PhaseHg(id: \"a\", g: [2.0]), PhaseHg(id: \"b\", mu_bins: 1)])");
    assert_eq!(e.diagnostics.len(), 2, "{s}");
    assert!(s.ends_with("2 problems found"), "{s}");
}

fn phase(p: &voltab::registry::ValidatedPipeline, id: &str) -> voltab::tables::phase_hg::PhaseHg {
    match p.table(id).unwrap().def() {
        TableDef::PhaseHg(h) => h.clone(),
        #[allow(unreachable_patterns)]
        _ => panic!("not PhaseHg"),
    }
}

#[test]
fn presets_chain_includes_load_and_overrides_apply() {
    let d = tempdir();
    write(
        d.path(),
        "base/studio.ron",
        "(presets: {\"coarse\": PhaseHg(mu_bins: 64, zh_order: 4), \"coarse_f64\": PhaseHg(preset: \"coarse\", element: F64)}, tables: [PhaseHg(id: \"studio\", preset: \"coarse\")])",
    );
    let p = write(
        d.path(),
        "project.ron",
        "(include: [\"base/studio.ron\"], tables: [PhaseHg(id: \"mine\", preset: \"coarse_f64\", zh_order: 8)], overrides: {\"studio\": PhaseHg(xi_bins: 32)})",
    );
    let v = load_and_validate(&p, &Disk).unwrap();
    let ids: Vec<&str> = v.tables().iter().map(|t| t.id()).collect();
    assert_eq!(ids, ["studio", "mine"]);
    let mine = phase(&v, "mine");
    assert_eq!((mine.mu_bins, mine.zh_order, mine.element), (64, 8, voltab::tables::phase_hg::Element::F64));
    assert_eq!(mine.xi_bins, 1024, "unset fields take the documented default");
    let studio = phase(&v, "studio");
    assert_eq!((studio.mu_bins, studio.zh_order, studio.xi_bins), (64, 4, 32));
    assert_eq!(studio.g, GValues::List(vec![-0.9, -0.5, 0.0, 0.5, 0.9]));
}

#[test]
fn the_bundled_pipelines_validate() {
    let v = load_and_validate(&common::root().join("pipelines/default.ron"), &Disk).unwrap();
    assert_eq!(v.tables().len(), 7);
    assert_eq!(phase(&v, "hg_dubouchet").zh_order, 16, "override from default.ron applies to the included table");
    assert_eq!(v.stages().len(), 8);
}

#[test]
fn cli_reports_errors_without_panicking() {
    let d = tempdir();
    let p = write(d.path(), "bad.ron", "(tables: [PhaseHg(id: \"a\", mu_bin: 64)])");
    let o = common::run(&["check", p.to_str().unwrap()]);
    assert_eq!(o.status.code(), Some(1));
    let s = common::text(&o);
    assert!(
        s.contains("error: unknown field `mu_bin`") && s.contains("bad.ron:1:28") && !s.contains("panicked"),
        "{s}"
    );
    let o = common::run(&["compile", p.to_str().unwrap(), "--out", d.path().join("out").to_str().unwrap()]);
    assert_eq!(o.status.code(), Some(1));
    assert!(!d.path().join("out").exists(), "an invalid pipeline must not create outputs");
}

#[test]
fn bake_stage_errors_name_the_field_or_the_file() {
    let d = tempdir();
    // Out-of-range parameters are rejected before anything runs, naming the field and the fix.
    let p = write(
        d.path(),
        "bad.ron",
        "(tables: [ZhResponse(id: \"zh\")], stages: [BakeLightmaps(id: \"b\", scene: \"x.gltf\", table: \"zh\", samples: 0, modes: [])])",
    );
    let o = common::run(&["check", p.to_str().unwrap()]);
    assert_eq!(o.status.code(), Some(1));
    let t = text(&o);
    assert!(t.contains("samples") && t.contains("modes"), "{t}");
    // Full without a table is refused at validation, too.
    let p = write(d.path(), "notable.ron", "(stages: [BakeLightmaps(id: \"b\", scene: \"x.gltf\")])");
    let o = common::run(&["check", p.to_str().unwrap()]);
    assert_eq!(o.status.code(), Some(1));
    assert!(text(&o).contains("mode Full needs a table"), "{}", text(&o));
    // A missing scene fails the run with the path in the message and leaves no lightmap behind.
    let p = write(
        d.path(),
        "missing.ron",
        "(stages: [BakeLightmaps(id: \"b\", scene: \"nowhere.gltf\", modes: [Surface])])",
    );
    let out = d.path().join("out");
    let o = common::run(&["run", p.to_str().unwrap(), "--out", out.to_str().unwrap()]);
    assert_eq!(o.status.code(), Some(1));
    assert!(text(&o).contains("nowhere.gltf") && !text(&o).contains("panicked"), "{}", text(&o));
    assert!(!out.join("b").join("lightmap_surface.exr").exists());
}

#[test]
fn pop_environment_errors_name_the_field_or_the_file() {
    let d = tempdir();
    let scene = Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes/window_room.gltf");
    let stage = |env: &str, set: &str| {
        format!(
            "(tables: [PopPreset(id: \"pop\", ordinates: 8, grid: (4, 4, 4))], stages: [PopRender(id: \"p\", \
             scene: \"{}\", table: \"pop\", width: 8, height: 6, colour_samples: 1, environment: \"{env}\", \
             environment_set: \"{set}\")])",
            scene.display()
        )
    };
    // An unknown ordinate set is refused at validation, naming the field and the choices.
    let p = write(d.path(), "set.ron", &stage("sky.exr", "random"));
    let o = common::run(&["check", p.to_str().unwrap()]);
    assert_eq!(o.status.code(), Some(1));
    let t = text(&o);
    assert!(t.contains("environment_set") && t.contains("fibonacci"), "{t}");
    // A missing map and a corrupt one fail the run naming the file, and leave no image behind.
    std::fs::write(d.path().join("corrupt.exr"), b"v/1\x01 not an exr").unwrap();
    for (name, says) in [("missing.exr", "missing.exr"), ("corrupt.exr", "not a readable EXR")] {
        let p = write(d.path(), "env.ron", &stage(name, "importance"));
        let out = d.path().join(format!("out-{name}"));
        let o = common::run(&["run", p.to_str().unwrap(), "--out", out.to_str().unwrap()]);
        assert_eq!(o.status.code(), Some(1), "{name}");
        let t = text(&o);
        assert!(t.contains(name) && t.contains(says) && !t.contains("panicked"), "{t}");
        assert!(!out.join("p").join("pop.exr").exists());
    }
}
