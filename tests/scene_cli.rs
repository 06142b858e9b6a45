//! `voltab scene`, `voltab plan` and `voltab compile --scene` on the bundled scenes, through the binary.

mod common;

use std::path::{Path, PathBuf};

use common::{root, run, tempdir, text, voltab, write};

fn scene(name: &str) -> PathBuf {
    root().join("scenes").join(name)
}

fn json(args: &[&str]) -> serde_json::Value {
    let o = run(args);
    assert!(o.status.success(), "{}", text(&o));
    serde_json::from_slice(&o.stdout).unwrap_or_else(|e| panic!("{e}: {}", text(&o)))
}

fn path(p: &Path) -> &str {
    p.to_str().unwrap()
}

/// A pipeline with one small table of each kind (fast to compile in a debug build).
const SMALL: &str = r#"(
    tables: [
        PhaseHg(id: "hg", g: (min: -0.9, max: 0.9, count: 19), mu_bins: 64, xi_bins: 64, zh_order: 8),
        ZhResponse(id: "zh", g: [-0.5, 0.0, 0.5], bounces: 3, zh_order: 4, distance_bins: 48, quadrature_nodes: 4,
            theta_bins: 3),
        MsLobes(id: "lobes", materials: [], g: [0.0, 0.7, 0.9], albedo_grid: 5, albedos: [0.99],
            rho_bins: 16, z_bins: 24, theta_bins: 9, direction_bins: 16, photons: 4096, max_order: 64),
    ],
)"#;

fn decisions(plan: &serde_json::Value) -> Vec<(String, String)> {
    plan["tables"]
        .as_array()
        .unwrap()
        .iter()
        .map(|t| (t["id"].as_str().unwrap().to_string(), t["decision"].as_str().unwrap().to_string()))
        .collect()
}

#[test]
fn the_fog_room_and_the_translucent_scene_get_different_plans() {
    let d = tempdir();
    let p = write(d.path(), "small.ron", SMALL);
    let fog = json(&["plan", path(&p), "--scene", path(&scene("fog_room.gltf")), "--json"]);
    let wax = json(&["plan", path(&p), "--scene", path(&scene("translucent.usda")), "--json"]);
    let s = |v: &[(&str, &str)]| v.iter().map(|(a, b)| (a.to_string(), b.to_string())).collect::<Vec<_>>();
    assert_eq!(decisions(&fog), s(&[("hg", "compile"), ("zh", "compile"), ("lobes", "skip")]));
    assert_eq!(decisions(&wax), s(&[("hg", "compile"), ("zh", "skip"), ("lobes", "compile")]));
    // Every item names its slice and gives a reason.
    for t in fog["tables"].as_array().unwrap() {
        for i in t["items"].as_array().unwrap() {
            assert!(!i["reason"].as_str().unwrap().is_empty(), "{i}");
        }
    }
    // The text form names skipped slices with their reason.
    let o = run(&["plan", path(&p), "--scene", path(&scene("fog_room.usda"))]);
    assert!(o.status.success(), "{}", text(&o));
    let t = text(&o);
    assert!(t.contains("skip     table lobes [MsLobes]: no refractive translucent objects in the scene"), "{t}");
    assert!(t.contains("unused: scene media have g = 0.3"), "{t}");
}

/// `compile --scene` writes a subset of the full tables, and a consumer reading the pruned tables gets the
/// same answers as from the full ones.
#[test]
fn compiling_for_a_scene_prunes_and_lookups_do_not_change() {
    let d = tempdir();
    let p = write(d.path(), "small.ron", SMALL);
    let (full, pruned) = (d.path().join("full"), d.path().join("pruned"));
    let o = run(&["compile", path(&p), "--out", path(&full)]);
    assert!(o.status.success(), "{}", text(&o));
    let o = run(&["compile", path(&p), "--out", path(&pruned), "--scene", path(&scene("translucent.gltf"))]);
    assert!(o.status.success(), "{}", text(&o));
    let names = |dir: &Path| -> Vec<String> {
        common::vtabs(dir).iter().map(|f| f.file_name().unwrap().to_string_lossy().into_owned()).collect()
    };
    assert_eq!(names(&full), ["hg.vtab", "lobes.vtab", "zh.vtab"]);
    assert_eq!(names(&pruned), ["hg.vtab", "lobes.vtab"]);
    for t in ["hg.vtab", "lobes.vtab"] {
        let (a, b) = (std::fs::metadata(full.join(t)).unwrap().len(), std::fs::metadata(pruned.join(t)).unwrap().len());
        assert!(b < a, "{t}: pruned {b} bytes, full {a}");
    }
    let summary = json(&["scene", path(&scene("translucent.gltf")), "--json"]);
    let medium = &summary["media"][0];
    let g = medium["g"][0].as_f64().unwrap();
    for albedo in medium["albedo"].as_array().unwrap().iter().map(|a| a.as_f64().unwrap()) {
        for (rho, z, theta) in [("0.5", "1", "20"), ("3", "6", "90"), ("2", "-1", "170")] {
            let q = |dir: &Path| {
                json(&[
                    "eval",
                    "lobes",
                    "--table",
                    path(&dir.join("lobes.vtab")),
                    "--albedo",
                    &albedo.to_string(),
                    "--g",
                    &g.to_string(),
                    "--rho",
                    rho,
                    "--z",
                    z,
                    "--theta",
                    theta,
                    "--json",
                ])
            };
            assert_eq!(q(&full), q(&pruned), "albedo {albedo} at ({rho}, {z}, {theta}°)");
        }
    }
}

#[test]
fn scene_errors_name_the_file_and_exit_non_zero() {
    let d = tempdir();
    let missing = d.path().join("nope.gltf");
    let o = run(&["scene", path(&missing)]);
    assert!(!o.status.success());
    assert!(text(&o).contains("nope.gltf"), "{}", text(&o));
    let odd = write(d.path(), "scene.obj", "v 0 0 0\n");
    let o = run(&["scene", path(&odd)]);
    assert!(!o.status.success());
    assert!(text(&o).contains("unknown scene format \"obj\""), "{}", text(&o));
    // A pipeline with a broken scene writes nothing.
    let p = write(d.path(), "small.ron", SMALL);
    let out = d.path().join("out");
    let o = voltab().args(["compile", path(&p), "--out", path(&out), "--scene", path(&missing)]).output().unwrap();
    assert!(!o.status.success());
    assert!(!out.join("hg.vtab").exists());
    assert!(!text(&o).contains("panicked"), "{}", text(&o));
}
