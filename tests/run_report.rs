//! The main job and the report, end to end through the binary.

mod common;

use common::{tempdir, text, voltab, write};

/// `voltab` with no arguments is the README's main command: outside a checkout it uses the
/// pipelines built into the binary, compiles every table and runs every stage. It compiles the full
/// default pipeline (ZH tables at the paper's size: minutes), so it runs in release, opt-in:
/// `cargo test --release --test run_report -- --ignored` (scripts/test-all.sh does).
#[test]
#[ignore = "compiles the full default pipeline; run in release with --ignored (scripts/test-all.sh does)"]
fn no_arguments_runs_the_embedded_default_pipeline() {
    let d = tempdir();
    let o = voltab().current_dir(d.path()).output().unwrap();
    assert!(o.status.success(), "{}", text(&o));
    assert!(text(&o).contains("using the copy built into voltab"), "{}", text(&o));
    let out = d.path().join("out");
    let tables: Vec<String> =
        common::vtabs(&out).iter().map(|p| p.file_name().unwrap().to_string_lossy().into_owned()).collect();
    assert_eq!(
        tables,
        [
            "hg_dubouchet.vtab",
            "hg_extreme.vtab",
            "hg_grid.vtab",
            "ms_lobes_table2.vtab",
            "ms_lobes_wax_full.vtab",
            "pop_realtime.vtab",
            "zh_dubouchet.vtab"
        ]
    );
    for png in ["hg_extreme_plot.png", "hg_grid_plot.png"] {
        let img = image::open(out.join(png)).unwrap();
        assert_eq!((img.width(), img.height()), (1024, 720));
    }
    // The embedded copy is the committed file: compiling pipelines/default.ron into the same folder finds
    // every table up to date (same content keys) and leaves the bytes alone.
    let before: Vec<Vec<u8>> = tables.iter().map(|t| std::fs::read(out.join(t)).unwrap()).collect();
    let o = voltab()
        .args(["compile", common::root().join("pipelines/default.ron").to_str().unwrap(), "--json", "--out"])
        .arg(&out)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", text(&o));
    let summary: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    let statuses: Vec<&str> =
        summary["tables"].as_array().unwrap().iter().map(|t| t["status"].as_str().unwrap()).collect();
    assert_eq!(statuses, vec!["UpToDate"; tables.len()], "{summary}");
    for (t, b) in tables.iter().zip(&before) {
        assert_eq!(&std::fs::read(out.join(t)).unwrap(), b, "{t}");
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

/// Runs `voltab report` on a one-table pipeline; returns the temp dir, the report folder and the rows.
fn report_rows(name: &str, pipeline: &str) -> (tempfile::TempDir, std::path::PathBuf, Vec<serde_json::Value>) {
    let d = tempdir();
    let p = write(d.path(), name, pipeline);
    let out = d.path().join("report");
    let o = voltab().args(["report", p.to_str().unwrap(), "--out", out.to_str().unwrap()]).output().unwrap();
    assert!(o.status.success(), "{}", text(&o));
    let r: serde_json::Value = serde_json::from_slice(&std::fs::read(out.join("report.json")).unwrap()).unwrap();
    let rows = r["tables"][0]["rows"].as_array().unwrap().clone();
    (d, out, rows)
}

/// The ZH tables' error against run time: the ladder from 1/16 of the table's distance resolution and
/// quadrature size up to the table's own converges toward the random walk. Walk references of 2^20
/// photons make this slow in the dev profile, so it runs in release with the other opt-in end-to-end
/// tests (`cargo test --release --test run_report -- --ignored`).
#[test]
#[ignore = "walk references of 2^20 photons; run in release with --ignored (scripts/test-all.sh does)"]
fn report_plots_zh_error_against_time() {
    let (_d, out, rows) = report_rows(
        "zh.ron",
        "(tables: [ZhResponse(id: \"zh\", g: [0.0], emitters: [Point, Directional], bounces: 4, distance_bins: 64, quadrature_nodes: 8)])",
    );
    let budgets: Vec<&str> = rows.iter().map(|r| r["budget"].as_str().unwrap()).collect();
    assert_eq!(
        budgets,
        [
            "distance_bins=4,nodes=2",
            "distance_bins=8,nodes=2",
            "distance_bins=16,nodes=4",
            "distance_bins=32,nodes=5",
            "distance_bins=64,nodes=8"
        ]
    );
    let curves: Vec<&str> = rows[0]["errors"].as_array().unwrap().iter().map(|c| c[0].as_str().unwrap()).collect();
    assert_eq!(curves, ["point single", "point orders <= B", "directional single", "directional orders <= B"]);
    let err = |i: usize| rows[i]["error_max"].as_f64().unwrap();
    // The cheapest rung is off by tens of percent; the table's own settings are within the 2 % single-
    // scattering target of issue 3 (walk noise at 2^20 photons: ~0.3 %).
    assert!(err(0) > 0.1 && err(4) < 0.02 && err(4) < err(0) / 10.0, "{} → {}", err(0), err(4));
    let img = image::open(out.join("zh-error-vs-time.png")).unwrap();
    assert_eq!((img.width(), img.height()), (1024, 720));
}

/// The lobe tables' error against run time: photons from 1/64 of the table's count up to it. The E_2
/// error against the beam quadrature is Monte-Carlo noise, so it falls like 1/√photons (8× over the
/// ladder); totals are compared with the backward walk (16384 samples, g ≤ 0.7). Cells of ~0.33 mfp near
/// the probes keep the bilinear interpolation of the totals within a few per cent (on cells of 0.5 mfp
/// the worst probe was 11.9 % off; on cells of 0.25 mfp the E_2 noise of the sparsest probe cell reached 19 %).
#[test]
#[ignore = "backward-walk references of 16384 samples; run in release with --ignored (scripts/test-all.sh does)"]
fn report_plots_lobe_error_against_time() {
    let (_d, out, rows) = report_rows(
        "lobes.ron",
        "(tables: [MsLobes(id: \"lobes\", materials: [], g: [0.0, 0.7], albedo_grid: 0, albedos: [0.8], \
         rho_max: 8.0, z_min: -4.0, z_max: 12.0, rho_bins: 24, z_bins: 36, direction_bins: 32, \
         photons: 1048576, max_order: 64)])",
    );
    let budgets: Vec<&str> = rows.iter().map(|r| r["budget"].as_str().unwrap()).collect();
    assert_eq!(budgets, ["photons=16384", "photons=65536", "photons=262144", "photons=1048576"]);
    let curve = |i: usize, name: &str| {
        rows[i]["errors"].as_array().unwrap().iter().find(|c| c[0] == name).unwrap()[1].as_f64().unwrap()
    };
    let (first, last) = (curve(0, "double (E_2) vs quadrature"), curve(3, "double (E_2) vs quadrature"));
    // 1/√N noise: 8× from the first rung to the last; allow for the worst probe's own fluctuation.
    assert!(last < first / 3.0 && last < 0.1, "E_2 error {first} → {last}");
    // The backward walk's scores are heavy-tailed (∝ 1/ρ near the beam): at these probes two seeds of
    // 20000 samples differed by 13 % (g = 0, (1.5, −1)), and its reported σ understates the spread
    // ~1.65×. The worst of six comparisons measured 11.9 % (0.5-mfp cells) and 14.1 % (0.33-mfp cells).
    let total = curve(3, "total vs backward walk");
    assert!(total < 0.2, "total error at the table's own photon count {total}");
    let img = image::open(out.join("lobes-error-vs-time.png")).unwrap();
    assert_eq!((img.width(), img.height()), (1024, 720));
}
