//! The main job and the report, end to end through the binary.

mod common;

use common::{tempdir, text, voltab, write};

/// `voltab` with no arguments is the README's main command: outside a checkout it uses the
/// pipelines built into the binary, compiles every table and runs every stage.
#[test]
fn no_arguments_runs_the_embedded_default_pipeline() {
    let d = tempdir();
    let o = voltab().current_dir(d.path()).output().unwrap();
    assert!(o.status.success(), "{}", text(&o));
    assert!(text(&o).contains("using the copy built into voltab"), "{}", text(&o));
    let out = d.path().join("out");
    let tables: Vec<String> =
        common::vtabs(&out).iter().map(|p| p.file_name().unwrap().to_string_lossy().into_owned()).collect();
    assert_eq!(tables, ["hg_dubouchet.vtab", "hg_extreme.vtab", "hg_grid.vtab"]);
    for png in ["hg_extreme_plot.png", "hg_grid_plot.png"] {
        let img = image::open(out.join(png)).unwrap();
        assert_eq!((img.width(), img.height()), (1024, 720));
    }
    // The embedded copy is the committed file: same tables as compiling pipelines/default.ron.
    let o = voltab()
        .args(["compile", common::root().join("pipelines/default.ron").to_str().unwrap(), "--out"])
        .arg(d.path().join("direct"))
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", text(&o));
    for t in &tables {
        assert_eq!(std::fs::read(out.join(t)).unwrap(), std::fs::read(d.path().join("direct").join(t)).unwrap(), "{t}");
    }
}

#[test]
fn report_writes_json_markdown_and_a_plot_with_converging_errors() {
    let d = tempdir();
    let p = write(d.path(), "p.ron", "(tables: [PhaseHg(id: \"hg\", g: [0.0, 0.5], zh_order: 4)])");
    let out = d.path().join("report");
    let o = voltab().args(["report", p.to_str().unwrap(), "--out", out.to_str().unwrap()]).output().unwrap();
    assert!(o.status.success(), "{}", text(&o));
    let r: serde_json::Value = serde_json::from_slice(&std::fs::read(out.join("report.json")).unwrap()).unwrap();
    let rows = r["tables"][0]["rows"].as_array().unwrap();
    assert_eq!(rows.len(), 11, "budgets mu_bins = 16 … 16384");
    let err = |i: usize| rows[i]["error_max"].as_f64().unwrap();
    // Linear interpolation is second order: 10 halvings of the cell size divide the error of the
    // smooth g = 0.5 lobe by ~4^10 until f32 rounding (~6e-8) takes over.
    assert!(err(0) > 1e-2 && err(10) < 1e-6 && err(10) < err(0) / 1e4, "{} → {}", err(0), err(10));
    assert_eq!(rows[0]["nonfinite_discarded"], 0);
    assert!(rows.iter().all(|r| r["generate_ms"].as_f64().unwrap() > 0.0));
    let md = std::fs::read_to_string(out.join("report.md")).unwrap();
    assert!(md.contains("| mu_bins=1024 |") && md.contains("hg-error-vs-time.png"), "{md}");
    let img = image::open(out.join("hg-error-vs-time.png")).unwrap();
    assert_eq!((img.width(), img.height()), (1024, 720));
}
