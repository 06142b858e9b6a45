//! The `PopRender` stage (elek2014) end to end through the binary on the bundled window room: the
//! image is the attenuated colour plus the propagated light, the Fig. 12 comparison lands in the
//! summary, the planner leaves POP out for a scene without a directional light, and bad density input
//! is refused clearly without writing the stage's outputs.

mod common;

use common::{root, tempdir, text, voltab, write};

fn pipeline(extra: &str) -> String {
    format!(
        "(tables: [PopPreset(id: \"pop\", grid: (12, 12, 12), iterations: 12, a_bins: 64)],
          stages: [PopRender(id: \"pop_stage\", scene: \"{}\", table: \"pop\", width: 40, height: 30,
                             colour_samples: 1, voxels: 24, fig12_photons: 20000, fig12_size: 12,
                             fig12_samples: 4{extra})])",
        root().join("scenes/window_room.gltf").display()
    )
}

#[test]
fn pop_stage_composes_the_image_and_reports_fig12() {
    let d = tempdir();
    let p = write(d.path(), "pop.ron", &pipeline(""));
    let out = d.path().join("out");
    let o = voltab().args(["run", p.to_str().unwrap(), "--out", out.to_str().unwrap()]).output().unwrap();
    assert!(o.status.success(), "{}", text(&o));
    let dir = out.join("pop_stage");
    let exr = voltab::image_io::read_exr_rgb(&dir.join("pop.exr")).unwrap();
    assert_eq!((exr.width, exr.height), (40, 30));
    let image = exr.rgb(None).unwrap();
    let colour = exr.rgb(Some("colour")).unwrap();
    let t = exr.rgb(Some("transmittance")).unwrap();
    let s = exr.rgb(Some("scattered")).unwrap();
    let mut lit = 0;
    for i in 0..image.len() {
        for c in 0..3 {
            let want = colour[i][c] * t[i][c] + s[i][c];
            assert!((image[i][c] - want).abs() <= 1e-5 * want.abs().max(1e-6), "pixel {i}");
            // The fog dims every view ray a little and never brightens the surface behind it.
            assert!(t[i][c] > 0.0 && t[i][c] <= 1.0, "transmittance {}", t[i][c]);
        }
        lit += usize::from(s[i][1] > 0.0);
    }
    assert!(lit > image.len() / 2, "sunlit fog should scatter into most pixels: {lit}");
    for f in
        ["pop.png", "pop_scattered.png", "fig12_g0.70_radiance.png", "fig12_g0.96_pop.png", "fig12_g0.00_reference.png"]
    {
        assert!(dir.join(f).exists(), "{f}");
    }
    let sum: serde_json::Value = serde_json::from_slice(&std::fs::read(dir.join("summary.json")).unwrap()).unwrap();
    let light = &sum["lights"][0];
    assert_eq!(light["light"], "sun");
    assert_eq!(light["grid"], serde_json::json!([12, 12, 12]));
    let runs = light["anisotropic_iterations"].as_u64().unwrap() + light["isotropic_iterations"].as_u64().unwrap();
    assert!((1..=12 + 200).contains(&runs));
    let residual = light["residual_energy"].as_f64().unwrap();
    assert!((0.0..=1.0).contains(&residual));
    let rows = sum["fig12"].as_array().unwrap();
    assert_eq!(rows.len(), 3);
    for r in rows {
        let e = r["slice"]["collided_error"].as_f64().unwrap();
        assert!(e.is_finite() && e > 0.0, "{e}");
        assert_eq!(r["slice"]["slice"].as_array().unwrap().len(), 16 * 16);
    }
}

#[test]
fn pop_stage_input_errors_are_clear() {
    let d = tempdir();
    // A raw density volume that does not exist: the stage names the file and writes nothing.
    let p = write(d.path(), "raw.ron", &pipeline(", density_raw: \"smoke.raw\", density_dims: (4, 4, 4)"));
    let out = d.path().join("out");
    let o = voltab().args(["run", p.to_str().unwrap(), "--out", out.to_str().unwrap()]).output().unwrap();
    assert_ne!(o.status.code(), Some(0));
    assert!(text(&o).contains("smoke.raw"), "{}", text(&o));
    assert!(!out.join("pop_stage").join("pop.exr").exists());
    // The wrong size: the message says how many bytes the dims need.
    std::fs::write(d.path().join("smoke.raw"), vec![0u8; 100]).unwrap();
    let o = voltab().args(["run", p.to_str().unwrap(), "--out", out.to_str().unwrap()]).output().unwrap();
    assert_ne!(o.status.code(), Some(0));
    assert!(text(&o).contains("256"), "{}", text(&o));
    // density_raw without dims is refused by `check`, naming the field.
    let p = write(d.path(), "dims.ron", &pipeline(", density_raw: \"smoke.raw\""));
    let o = voltab().args(["check", p.to_str().unwrap()]).output().unwrap();
    assert_eq!(o.status.code(), Some(1));
    assert!(text(&o).contains("density_dims"), "{}", text(&o));
    // The fog room has no directional light: the planner skips the stage and its table, saying why.
    let fog = root().join("scenes/fog_room.gltf");
    let src = pipeline("").replace("window_room.gltf", "fog_room.gltf");
    let p = write(d.path(), "fog.ron", &src);
    let o = voltab().args(["plan", p.to_str().unwrap(), "--scene", fog.to_str().unwrap()]).output().unwrap();
    let t = text(&o);
    assert!(t.contains("directional light"), "{t}");
}
