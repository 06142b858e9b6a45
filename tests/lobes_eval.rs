//! `voltab eval lobes` end to end: an MsLobes table compiled through the binary, queried through the
//! binary, agrees with the library look-up and with exact relations of the lobes (albedo scaling of the
//! double term, isotropy at g = 0, nothing scattered at albedo 0); bad arguments are clear errors.

mod common;

use std::sync::OnceLock;

use common::{tempdir, text, voltab};
use voltab::tables::ms_lobes::{LobeQuery, MsLobesTable};

/// A small table compiled once through the binary: (kept temp dir, table path).
fn compiled() -> &'static (tempfile::TempDir, std::path::PathBuf) {
    static T: OnceLock<(tempfile::TempDir, std::path::PathBuf)> = OnceLock::new();
    T.get_or_init(|| {
        common::compile_pipeline(
            "lobes.ron",
            "(tables: [MsLobes(id: \"lobes\", materials: [\"Skin\"], g: [0.9], albedo_grid: 3, rho_max: 8.0, \
             z_min: -4.0, z_max: 12.0, rho_bins: 16, z_bins: 24, theta_bins: 17, direction_bins: 16, \
             photons: 16384, max_order: 64)])",
            "lobes",
        )
    })
}

fn eval(args: &[&str]) -> std::process::Output {
    voltab().args(["eval", "lobes", "--table", compiled().1.to_str().unwrap()]).args(args).output().unwrap()
}

fn json(o: &std::process::Output) -> (f64, f64) {
    assert!(o.status.success(), "{}", text(o));
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    (v["total"].as_f64().unwrap(), v["double"].as_f64().unwrap())
}

#[test]
fn eval_matches_the_library_and_exact_relations() {
    let at = |albedo: &str, g: &str, theta: &str| {
        json(&eval(&["--albedo", albedo, "--g", g, "--rho", "1.3", "--z", "-0.7", "--theta", theta, "--json"]))
    };
    let table = MsLobesTable::open(&compiled().1, None).unwrap();
    let q = LobeQuery { albedo: 0.838, g: 0.45, rho: 1.3, z: -0.7, theta: 60f64.to_radians(), phi: 0.0 };
    let lib = table.lobe(&q).unwrap();
    let (total, double) = at("0.838", "0.45", "60");
    // (serde_json's default float parsing may differ from the printed value in the last bit.)
    assert!((total - lib.total).abs() <= 1e-15 * total && (double - lib.double).abs() <= 1e-15 * double);
    assert!(total > double && double > 0.0, "{total} {double}");
    // The double term is α² E_2: the ratio between two albedos is exactly the ratio of their squares.
    let (_, d2) = at("0.6778", "0.45", "60");
    assert!((double / d2 - (0.838f64 / 0.6778).powi(2)).abs() < 1e-12, "{double} {d2}");
    // g = 0: the last scattering is isotropic, so the lobe does not depend on θ.
    let (t0, d0) = at("0.9584", "0", "0");
    let (t1, d1) = at("0.9584", "0", "180");
    assert!((t0 - t1).abs() <= 1e-6 * t0 && (d0 - d1).abs() <= 1e-6 * d0, "{t0} {t1} {d0} {d1}");
    // Albedo 0 scatters nothing.
    assert_eq!(at("0", "0.9", "30"), (0.0, 0.0));
}

#[test]
fn eval_refuses_what_the_table_cannot_answer() {
    let o = eval(&["--albedo", "0.5", "--g", "0.95", "--rho", "1", "--z", "1", "--theta", "10"]);
    assert_eq!(o.status.code(), Some(1));
    assert!(text(&o).contains("g = 0.95 is outside the table's g range [0, 0.9]"), "{}", text(&o));
    let o = eval(&["--albedo", "1.5", "--g", "0.5", "--rho", "1", "--z", "1", "--theta", "10"]);
    assert_eq!(o.status.code(), Some(1));
    assert!(text(&o).contains("albedo = 1.5"), "{}", text(&o));
    let o = eval(&["--albedo", "0.5", "--g", "0.5", "--rho", "1", "--z", "1", "--theta", "200"]);
    assert_eq!(o.status.code(), Some(1));
    assert!(text(&o).contains("theta"), "{}", text(&o));
    let d = tempdir();
    let bad = d.path().join("bad.vtab");
    std::fs::write(&bad, b"not a table").unwrap();
    let o = voltab()
        .args(["eval", "lobes", "--table", bad.to_str().unwrap(), "--albedo", "0.5", "--rho", "1", "--z", "1"])
        .args(["--theta", "0"])
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(1));
    assert!(text(&o).contains("bad.vtab"), "{}", text(&o));
}
