//! `voltab eval zh` end to end: a compiled ZhResponse table queried through the binary agrees with the
//! library query and the analytic direct term; bad tables and arguments are clear errors.

mod common;

use std::sync::OnceLock;

use common::{tempdir, text, voltab};
use voltab::physics::medium::HomogeneousMedium;
use voltab::tables::zh_response::{Emitter, QueryOptions, Receiver, ZhResponseTable};

/// A small table compiled once through the binary: (kept temp dir, table path).
fn compiled() -> &'static (tempfile::TempDir, std::path::PathBuf) {
    static T: OnceLock<(tempfile::TempDir, std::path::PathBuf)> = OnceLock::new();
    T.get_or_init(|| {
        common::compile_pipeline(
            "zh.ron",
            "(tables: [ZhResponse(id: \"zh\", g: [-0.5, 0.0, 0.5], bounces: 4, distance_bins: 24, quadrature_nodes: 4), PhaseHg(id: \"hg\", g: [0.0])])",
            "zh",
        )
    })
}

fn eval(args: &[&str]) -> std::process::Output {
    eval_table(&compiled().1, args)
}

/// `voltab eval zh --table <table> <args>`.
fn eval_table(table: &std::path::Path, args: &[&str]) -> std::process::Output {
    voltab().args(["eval", "zh", "--table", table.to_str().unwrap()]).args(args).output().unwrap()
}

fn json(o: &std::process::Output) -> serde_json::Value {
    assert!(o.status.success(), "{}", text(o));
    serde_json::from_slice(&o.stdout).unwrap()
}

#[test]
fn point_and_directional_match_the_library_and_the_analytic_direct_term() {
    let (_, path) = compiled();
    let table = ZhResponseTable::open(path, None, None).unwrap();
    for (emitter, make) in [
        ("point", (|d: f64| Emitter::Point { intensity: 3.0, position: [0.0, 0.0, d] }) as fn(f64) -> Emitter),
        ("directional", |d: f64| Emitter::Directional { irradiance: 3.0, toward_light: [0.0, 0.0, 1.0], depth: d }),
    ] {
        for (deg, dist, s, a, g) in
            [(0.0, 1.5, 0.8, 0.2, 0.25), (70.0, 0.3, 2.0, 0.0, -0.5), (180.0, 4.0, 1.0, 1.0, 0.0)]
        {
            let o = eval(&[
                "--emitter",
                emitter,
                "--intensity",
                "3",
                "--distance",
                &dist.to_string(),
                "--normal-angle",
                &deg.to_string(),
                "--sigma-s",
                &s.to_string(),
                "--sigma-a",
                &a.to_string(),
                "--g",
                &g.to_string(),
                "--json",
            ]);
            let v = json(&o);
            let th = f64::to_radians(deg);
            let r = Receiver { position: [0.0; 3], normal: [th.sin(), 0.0, th.cos()] };
            let want = table
                .irradiance(&HomogeneousMedium { sigma_s: s, sigma_a: a, g }, &make(dist), &r, &QueryOptions::default())
                .unwrap();
            for (k, w) in
                [("direct", want.direct), ("single", want.single), ("multiple", want.multiple), ("total", want.total)]
            {
                let got = v[k].as_f64().unwrap();
                assert!((got - w).abs() <= 1e-12 * w.abs().max(1e-300), "{emitter} {deg}° {k}: {got} vs {w}");
            }
            let geometric = if emitter == "point" { 1.0 / (dist * dist) } else { 1.0 };
            let direct = 3.0 * (-(s + a) * dist).exp() * th.cos().max(0.0) * geometric;
            let got = v["direct"].as_f64().unwrap();
            assert!((got - direct).abs() <= 1e-12 * direct.max(1e-300), "{emitter} direct {got} vs {direct}");
            assert!(v["single"].as_f64().unwrap() > 0.0 && v["multiple"].as_f64().unwrap() > 0.0);
        }
    }
    // The area emitter: a patch 1.2 m away tilted 30° from facing the receiver.
    let o = eval(&[
        "--emitter",
        "area",
        "--distance",
        "1.2",
        "--patch-angle",
        "30",
        "--sigma-s",
        "0.9",
        "--g",
        "0.5",
        "--json",
    ]);
    let v = json(&o);
    let t = 30f64.to_radians();
    let e = Emitter::Area { intensity: 1.0, position: [0.0, 0.0, 1.2], normal: [t.sin(), 0.0, -t.cos()] };
    let r = Receiver { position: [0.0; 3], normal: [0.0, 0.0, 1.0] };
    let want = table
        .irradiance(&HomogeneousMedium { sigma_s: 0.9, sigma_a: 0.0, g: 0.5 }, &e, &r, &QueryOptions::default())
        .unwrap();
    assert!((v["total"].as_f64().unwrap() - want.total).abs() <= 1e-12 * want.total);
    let direct = t.cos() * (-0.9f64 * 1.2).exp() / (1.2 * 1.2);
    assert!((v["direct"].as_f64().unwrap() - direct).abs() <= 1e-12 * direct);
    assert!(v["single"].as_f64().unwrap() > 0.0 && v["tail"].as_f64().unwrap() == 0.0);
    // Human-readable output names the parts.
    let o = eval(&["--emitter", "point", "--distance", "1", "--sigma-s", "1"]);
    assert!(o.status.success(), "{}", text(&o));
    for k in ["direct", "single", "multiple", "total", "W/m^2"] {
        assert!(text(&o).contains(k), "{}", text(&o));
    }
}

#[test]
fn bad_tables_and_arguments_are_clear_errors() {
    let (_, path) = compiled();
    let o = eval(&["--emitter", "point", "--distance", "1", "--sigma-s", "1", "--g", "0.7"]);
    assert!(!o.status.success());
    assert!(text(&o).contains("g = 0.7 is outside the table's g range [-0.5, 0.5]"), "{}", text(&o));
    assert!(text(&o).contains("zh.vtab"), "{}", text(&o));
    let o = eval(&["--emitter", "point", "--distance", "-1", "--sigma-s", "1"]);
    assert!(!o.status.success() && text(&o).contains("--distance"), "{}", text(&o));
    let o = eval(&["--emitter", "point", "--distance", "1", "--sigma-s", "-2"]);
    assert!(!o.status.success() && text(&o).contains("sigma_s"), "{}", text(&o));
    let o = eval(&["--emitter", "point", "--distance", "0", "--sigma-s", "1"]);
    assert!(!o.status.success() && text(&o).contains("at the point light"), "{}", text(&o));
    // A PhaseHg table, a missing file and a truncated copy.
    let hg = path.with_file_name("hg.vtab");
    let o = eval_table(&hg, &["--emitter", "point", "--distance", "1", "--sigma-s", "1"]);
    assert!(!o.status.success() && text(&o).contains("holds a PhaseHg table, not ZhResponse"), "{}", text(&o));
    let d = tempdir();
    let missing = d.path().join("nope.vtab");
    let o = eval_table(&missing, &["--emitter", "point", "--distance", "1", "--sigma-s", "1"]);
    assert!(!o.status.success() && text(&o).contains("nope.vtab"), "{}", text(&o));
    let bytes = std::fs::read(path).unwrap();
    let cut = d.path().join("cut.vtab");
    std::fs::write(&cut, &bytes[..bytes.len() / 2]).unwrap();
    let o = eval_table(&cut, &["--emitter", "directional", "--distance", "1", "--sigma-s", "1"]);
    assert!(!o.status.success(), "{}", text(&o));
    assert!(!text(&o).contains("panicked"), "{}", text(&o));
    assert!(text(&o).contains("cut.vtab") && text(&o).to_lowercase().contains("truncated"), "{}", text(&o));
}

#[test]
fn only_the_needed_g_slices_are_loaded() {
    let (_, path) = compiled();
    // g = 0.25 needs the slices 0 and 0.5 (and 0 for similarity); -0.5 is not loaded.
    let t = ZhResponseTable::open(path, None, Some(&[0.25])).unwrap();
    let r = Receiver { position: [0.0; 3], normal: [0.0, 0.0, 1.0] };
    let e = Emitter::Point { intensity: 1.0, position: [0.0, 0.0, 1.0] };
    assert!(
        t.irradiance(&HomogeneousMedium { sigma_s: 1.0, sigma_a: 0.0, g: 0.25 }, &e, &r, &QueryOptions::default())
            .is_ok()
    );
    let err = t
        .irradiance(&HomogeneousMedium { sigma_s: 1.0, sigma_a: 0.0, g: -0.25 }, &e, &r, &QueryOptions::default())
        .unwrap_err();
    assert!(err.to_string().contains("not loaded"), "{err}");
}
