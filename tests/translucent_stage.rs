//! The `TranslucentRender` stage (wang2018) end to end through the binary on the bundled wax-sphere
//! scene: the planner keeps the lobe slices of the stage's materials, the EXR holds the components and
//! their sum, the summary compares with path tracing, and bad input is refused clearly.

mod common;

use common::{root, tempdir, text, voltab, write};

fn pipeline(materials: &str, extra: &str) -> String {
    format!(
        "(tables: [MsLobes(id: \"lobes\", materials: [\"Wax\", \"Oil\"], albedo_grid: 0, photons: 16384, rho_bins: 24,
                          z_bins: 40, theta_bins: 9, max_order: 128)],
          stages: [TranslucentRender(id: \"tr\", scene: \"{}\", table: \"lobes\", width: 24, height: 24,
                                     materials: {materials}, surface_samples: 256, k_max: 4,
                                     reference_samples: 32, reference_width: 16{extra})])",
        root().join("scenes/translucent.gltf").display()
    )
}

/// Wax and Oil (g 0.8 and 0.9) on the bundled sphere, whose own medium has g 0.7: the planner keeps the
/// stage's slices, the render's layers add up to its image, and the summary holds the comparison.
#[test]
fn translucent_stage_renders_components_and_compares_with_path_tracing() {
    let d = tempdir();
    let (out, s) = run_and_read(d.path(), "out", &pipeline("[\"Wax\", \"Oil\"]", ""));
    let dir = out.join("tr");
    for name in ["Wax", "Oil"] {
        let exr = voltab::image_io::read_exr_rgb(&dir.join(format!("{name}.exr"))).unwrap();
        assert_eq!((exr.width, exr.height), (24, 24));
        let total = exr.rgb(None).unwrap();
        let layers: Vec<Vec<[f32; 3]>> = ["single", "double", "multiple", "bounced", "rest"]
            .iter()
            .map(|l| exr.rgb(Some(l)).unwrap_or_else(|| panic!("layer {l}")))
            .collect();
        for i in 0..total.len() {
            for c in 0..3 {
                let s: f32 = layers.iter().map(|l| l[i][c]).sum();
                assert!((total[i][c] - s).abs() <= 1e-5 * s.abs().max(1e-6), "{name} pixel {i}");
            }
        }
        // The object scatters light (a lit sphere fills the middle of the view).
        let single: f32 = layers[0].iter().map(|p| p[0]).sum();
        assert!(single > 0.0, "{name}: no single scattering");
        for layer in ["single", "double", "multiple", "bounced"] {
            assert!(dir.join(format!("{name}_{layer}.png")).exists());
        }
    }
    let m = s["materials"].as_array().unwrap();
    assert_eq!(m.len(), 2);
    for e in m {
        let c = &e["comparison"];
        assert!(c["object_pixels"].as_u64().unwrap() > 20);
        let (mse, noise) = (c["mse"].as_f64().unwrap(), c["reference_noise"].as_f64().unwrap());
        assert!(mse.is_finite() && noise > 0.0);
        assert!((c["mse_corrected"].as_f64().unwrap() - (mse - noise).max(0.0)).abs() < 1e-12);
        // The relative error is the same MSE against the reference's mean (`report::noisy`): above its
        // floor its square is the corrected MSE divided by the squared mean over the scale.
        let (pe, pb) = (&c["error"], &c["block_error"]);
        if let Some(rel) = pe["rel_rmse"].as_f64() {
            let want = c["mse_corrected"].as_f64().unwrap()
                * (c["scale"].as_f64().unwrap() / pe["norm"].as_f64().unwrap()).powi(2);
            assert!((rel * rel - want).abs() <= 1e-9 * want.max(1e-30), "{c}");
        }
        // Block means (4 × 4 px) carry less noise per item: the reference resolves a smaller error there.
        assert!(pb["reference_noise"].as_f64().unwrap() < pe["reference_noise"].as_f64().unwrap(), "{c}");
        // Pre-processing, four passes, total.
        let t: Vec<f64> = e["times_ms"].as_array().unwrap().iter().map(|x| x.as_f64().unwrap()).collect();
        assert!((t[0] + t[1] + t[2] + t[3] + t[4] - t[5]).abs() < 1e-6 * t[5]);
        assert_eq!(e["failed_lookups"].as_u64(), Some(0));
    }
}

/// An unknown material, a missing table id and a scene without a translucent object are refused with
/// the field and the fix, before anything is written.
#[test]
fn translucent_stage_input_errors_are_clear() {
    let d = tempdir();
    let p = write(d.path(), "bad.ron", &pipeline("[\"Jelly\"]", ""));
    let o = voltab().args(["check", p.to_str().unwrap()]).output().unwrap();
    assert_eq!(o.status.code(), Some(1), "{}", text(&o));
    let t = text(&o);
    assert!(t.contains("unknown material \"Jelly\"") && t.contains("BumpySphere"), "{t}");

    let p = write(d.path(), "bad2.ron", &pipeline("[\"Wax\"]", ", widen: -1.0"));
    let o = voltab().args(["check", p.to_str().unwrap()]).output().unwrap();
    assert_eq!(o.status.code(), Some(1));
    assert!(text(&o).contains("widen"), "{}", text(&o));

    // The fog room has no refractive object: the planner skips the stage and says why.
    let fog = root().join("scenes/fog_room.gltf");
    let src = pipeline("[\"Wax\"]", "").replace("translucent.gltf", "fog_room.gltf");
    let p = write(d.path(), "fog.ron", &src);
    let o = voltab().args(["plan", p.to_str().unwrap(), "--scene", fog.to_str().unwrap()]).output().unwrap();
    let t = text(&o);
    assert!(t.contains("closed dielectric mesh"), "{t}");
}

/// A stage with a φ-resolved Wax table in `lobe_tables`: `stage` is the TranslucentRender body after
/// its id and scene.
fn two_table_pipeline(stage: &str) -> String {
    format!(
        "(tables: [MsLobes(id: \"lobes\", materials: [\"Wax\", \"Oil\"], albedo_grid: 0, photons: 16384, rho_bins: 24,
                          z_bins: 40, theta_bins: 9, max_order: 128),
                   MsLobes(id: \"wax_full\", materials: [\"Wax\"], albedo_grid: 0, lobe: Full, phi_bins: 5,
                          photons: 16384, rho_bins: 24, z_bins: 40, theta_bins: 9, max_order: 128)],
          stages: [TranslucentRender(id: \"tr\", scene: \"{}\", width: 16, height: 16, surface_samples: 256,
                                     k_max: 4, {stage})])",
        root().join("scenes/translucent.gltf").display()
    )
}

/// Runs pipeline `src` (written as `<name>.ron`) on the bundled scene into `<dir>/<name>`: that folder
/// and stage `tr`'s summary.
fn run_and_read(dir: &std::path::Path, name: &str, src: &str) -> (std::path::PathBuf, serde_json::Value) {
    let p = write(dir, &format!("{name}.ron"), src);
    let out = dir.join(name);
    let scene = root().join("scenes/translucent.gltf");
    let o = voltab()
        .args(["run", p.to_str().unwrap(), "--out", out.to_str().unwrap(), "--scene", scene.to_str().unwrap()])
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", text(&o));
    let s = serde_json::from_slice(&std::fs::read(out.join("tr/summary.json")).unwrap()).unwrap();
    (out, s)
}

/// Each material reads the first of `lobe_tables` that holds it exactly, else `table`: Wax renders
/// bit-for-bit as with `table: "wax_full"`, Oil as with `lobe_tables` absent; a lobe table holding none
/// of the materials is skipped by the planner and the stage runs without it.
#[test]
fn lobe_tables_serve_the_materials_they_hold() {
    let d = tempdir();
    let (out, s) = run_and_read(
        d.path(),
        "both",
        &two_table_pipeline("table: \"lobes\", lobe_tables: [\"wax_full\"], materials: [\"Wax\", \"Oil\"]"),
    );
    let read: Vec<(&str, &str)> = s["materials"]
        .as_array()
        .unwrap()
        .iter()
        .map(|m| (m["material"].as_str().unwrap(), m["table"].as_str().unwrap()))
        .collect();
    assert_eq!(read, [("Wax", "wax_full"), ("Oil", "lobes")]);
    let image = |out: &std::path::Path, name: &str| std::fs::read(out.join(format!("tr/{name}.exr"))).unwrap();
    let (wax_alone, _) =
        run_and_read(d.path(), "wax", &two_table_pipeline("table: \"wax_full\", materials: [\"Wax\"]"));
    assert!(image(&out, "Wax") == image(&wax_alone, "Wax"), "Wax did not read the φ-resolved table");
    // ... which renders Wax differently from the symmetric one (so the comparison above can fail).
    let (wax_symmetric, _) =
        run_and_read(d.path(), "wax_sym", &two_table_pipeline("table: \"lobes\", materials: [\"Wax\"]"));
    assert!(image(&wax_symmetric, "Wax") != image(&wax_alone, "Wax"));
    let (oil_alone, _) = run_and_read(d.path(), "oil", &two_table_pipeline("table: \"lobes\", materials: [\"Oil\"]"));
    assert!(image(&out, "Oil") == image(&oil_alone, "Oil"), "Oil did not read the symmetric table");
    // Oil only: the Wax table brackets nothing the scene or the stage needs, so it is not compiled.
    let (oil_only, s) = run_and_read(
        d.path(),
        "oil_only",
        &two_table_pipeline("table: \"lobes\", lobe_tables: [\"wax_full\"], materials: [\"Oil\"]"),
    );
    assert_eq!(s["materials"][0]["table"].as_str(), Some("lobes"));
    assert!(!oil_only.join("wax_full.vtab").exists());
    assert!(image(&oil_only, "Oil") == image(&oil_alone, "Oil"));

    // Listing `table` again, or a table twice, is refused with the field named.
    let p = write(
        d.path(),
        "twice.ron",
        &two_table_pipeline("table: \"lobes\", lobe_tables: [\"wax_full\", \"lobes\"], materials: [\"Wax\"]"),
    );
    let o = voltab().args(["check", p.to_str().unwrap()]).output().unwrap();
    assert_eq!(o.status.code(), Some(1));
    assert!(text(&o).contains("lobe_tables") && text(&o).contains("listed twice"), "{}", text(&o));
}
