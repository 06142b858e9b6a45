//! The `PopRender` stage (elek2014) end to end through the binary on the bundled window room: the
//! image is the attenuated colour plus the propagated light, the Fig. 12 comparison lands in the
//! summary, and bad density input is refused clearly without writing the stage's outputs. On the bundled
//! fog room (a point light: radial grids, Sec. 6; its ceiling panel and the walls' reflected light as
//! VPLs) the scattered light is compared with path tracing.

mod common;

use common::{root, tempdir, text, voltab, write};

/// The noise-corrected error of `summary.reference` (`report::noisy::NoiseCorrected`).
#[derive(Debug)]
struct Measured {
    /// Before the reference's noise is removed.
    raw: f64,
    /// Upper end of the 95 % interval of the corrected error.
    upper: f64,
}

/// `reference` of a POP summary → (its error, the reference's noise, the total ratio). The corrected
/// error and its interval are consistent with the floor: a number only above it.
fn error_against_reference(r: &serde_json::Value) -> (Measured, f64, f64) {
    let e = &r["error"];
    let f = |k: &str| e[k].as_f64().unwrap_or_else(|| panic!("{k} in {e}"));
    let (floor, lo, hi) = (f("floor"), e["ci95"][0].as_f64().unwrap(), e["ci95"][1].as_f64().unwrap());
    if let Some(rel) = e["rel_rmse"].as_f64() {
        assert!(rel >= floor && lo <= rel && rel <= hi, "{e}");
    }
    (Measured { raw: f("raw_rel_rmse"), upper: hi }, f("reference_noise"), r["total_ratio"].as_f64().unwrap())
}

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
    // The translucent scene's medium is bounded by the wax sphere: the planner skips POP, saying why.
    let wax = root().join("scenes/translucent.gltf");
    let src = pipeline("").replace("window_room.gltf", "translucent.gltf");
    let p = write(d.path(), "wax.ron", &src);
    let o = voltab().args(["plan", p.to_str().unwrap(), "--scene", wax.to_str().unwrap()]).output().unwrap();
    let t = text(&o);
    assert!(t.contains("global medium"), "{t}");
}

#[test]
fn fog_room_point_light_against_path_tracing() {
    let d = tempdir();
    let src = format!(
        "(tables: [PopPreset(id: \"pop\", grid: (12, 12, 12), iterations: 15, a_bins: 64)],
          stages: [PopRender(id: \"fog\", scene: \"{}\", table: \"pop\", width: 48, height: 32,
                             colour_samples: 1, voxels: 32, reference_samples: 256, reference_width: 32,
                             vpls: 0, surface_vpls: 0)])",
        root().join("scenes/fog_room.gltf").display()
    );
    let p = write(d.path(), "fog.ron", &src);
    let out = d.path().join("out");
    let o = voltab().args(["run", p.to_str().unwrap(), "--out", out.to_str().unwrap()]).output().unwrap();
    assert!(o.status.success(), "{}", text(&o));
    let dir = out.join("fog");
    let sum: serde_json::Value = serde_json::from_slice(&std::fs::read(dir.join("summary.json")).unwrap()).unwrap();
    let light = &sum["lights"][0];
    assert_eq!((light["light"].as_str(), light["kind"].as_str()), (Some("bulb"), Some("point")));
    assert_eq!(light["grid"], serde_json::json!([16, 16, 16]));
    assert!(sum["skipped"][0].as_str().unwrap().contains("ceiling_panel"), "{sum}");
    for f in ["pop.exr", "pop_scattered.png", "reference_scattered.png", "reference_pop.png"] {
        assert!(dir.join(f).exists(), "{f}");
    }
    let r = &sum["reference"];
    let (e, noise, ratio) = error_against_reference(r);
    // Measured at 32 × 21, 256 paths per pixel, relative to the reference's mean: raw 0.217 against the
    // reference's noise 0.184; the noise-corrected error is below the floor 0.149 (95 % interval up to
    // 0.210), total ratio 1.024. (Relative to the reference's RMS instead of its mean this read "0.028
    // once the noise is removed", a number the comparison could not resolve.)
    assert!(e.upper < 0.3, "{e:?}");
    assert!(e.raw > noise * 0.9, "POP cannot be closer to the reference than its own noise: {e:?} vs {noise}");
    assert!((0.97..1.07).contains(&ratio), "total ratio {ratio}");
}

#[test]
fn exr_slice_density_renders_as_the_same_raw_volume() {
    // One 6 × 5 × 4 density volume written as raw f32 and as four EXR slices (row 0 = top = largest y):
    // the two stages must give bit-identical images.
    let d = tempdir();
    let (w, h, n) = (6usize, 5usize, 4usize);
    let density = |x: usize, y: usize, z: usize| 0.2 + ((x * 7 + y * 3 + z * 5) % 11) as f32 * 0.15;
    let mut raw = Vec::new();
    for z in 0..n {
        for y in 0..h {
            for x in 0..w {
                raw.extend_from_slice(&density(x, y, z).to_le_bytes());
            }
        }
        let px: Vec<[f32; 3]> = (0..w * h).map(|i| [density(i % w, h - 1 - i / w, z), 0.0, 0.0]).collect();
        std::fs::create_dir_all(d.path().join("slices")).unwrap();
        voltab::image_io::write_exr_rgb(&d.path().join(format!("slices/z{z:02}.exr")), w, h, &px, &[]).unwrap();
    }
    std::fs::write(d.path().join("smoke.raw"), raw).unwrap();
    let run = |extra: &str, name: &str| {
        let src = pipeline(extra).replace("fig12_photons: 20000", "fig12_photons: 0");
        let p = write(d.path(), &format!("{name}.ron"), &src);
        let out = d.path().join(name);
        let o = voltab().args(["run", p.to_str().unwrap(), "--out", out.to_str().unwrap()]).output().unwrap();
        assert!(o.status.success(), "{}", text(&o));
        let exr = voltab::image_io::read_exr_rgb(&out.join("pop_stage/pop.exr")).unwrap();
        exr.rgb(Some("scattered")).unwrap()
    };
    let a = run(", density_raw: \"smoke.raw\", density_dims: (6, 5, 4)", "raw");
    let b = run(", density_slices: \"slices\"", "slices");
    assert_eq!(a, b);
    assert!(a.iter().any(|p| p[1] > 0.0));
    // Both at once is refused by `check`, naming the field.
    let p = write(
        d.path(),
        "both.ron",
        &pipeline(", density_raw: \"smoke.raw\", density_dims: (6, 5, 4), density_slices: \"slices\""),
    );
    let o = voltab().args(["check", p.to_str().unwrap()]).output().unwrap();
    assert_eq!(o.status.code(), Some(1));
    assert!(text(&o).contains("density_slices"), "{}", text(&o));
}

#[test]
fn window_room_under_the_bundled_sky() {
    // The sun plus the bundled sky through the window: the sky's ordinates carry its whole integral, and
    // the scattered light is compared with path tracing (the environment part from grid_mc).
    let d = tempdir();
    let sky = root().join("scenes/sky.exr");
    let extra = format!(
        ", environment: \"{}\", environment_intensity: 10, environment_ordinates: 16, reference_samples: 64, reference_width: 16",
        sky.display()
    );
    let src = pipeline(&extra).replace("fig12_photons: 20000", "fig12_photons: 0");
    let p = write(d.path(), "sky.ron", &src);
    let out = d.path().join("out");
    let o = voltab().args(["run", p.to_str().unwrap(), "--out", out.to_str().unwrap()]).output().unwrap();
    assert!(o.status.success(), "{}", text(&o));
    let sum: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out.join("pop_stage/summary.json")).unwrap()).unwrap();
    let env = &sum["environment"];
    // The preset's importance propagation placed the ordinates (Sec. 5.2).
    assert_eq!(env["importance"], serde_json::json!(true));
    let ords = env["ordinates"].as_array().unwrap();
    assert!(!ords.is_empty() && ords.len() <= 16, "{}", ords.len());
    let integral = env["integral"][1].as_f64().unwrap();
    let parts: f64 = ords.iter().map(|o| o["irradiance"][1].as_f64().unwrap()).sum();
    assert!((parts - integral).abs() < 1e-9 * integral, "{parts} vs {integral}");
    // 10 × the bundled sky's green integral, 2π(0.65 − 0.33·2/3) + 2π·0.09 (its golden test).
    let want = 10.0 * std::f64::consts::TAU * (0.65 - 0.22 + 0.09);
    assert!((integral - want).abs() < 2e-3 * want, "{integral} vs {want}");
    let kinds: Vec<&str> = sum["lights"].as_array().unwrap().iter().map(|l| l["kind"].as_str().unwrap()).collect();
    assert_eq!(kinds.iter().filter(|k| **k == "environment").count(), ords.len());
    assert_eq!(kinds.iter().filter(|k| **k == "directional").count(), 1);
    let r = &sum["reference"];
    // Measured at 16 × 12, 64 paths per pixel: 0.54 [0.33, 0.69] (floor 0.37), total ×1.199 (issue 33).
    let (e, _, ratio) = error_against_reference(r);
    assert!(e.upper < 0.8 && ratio > 0.5 && ratio < 2.0, "{r}");
}

#[test]
fn fog_room_ceiling_panel_as_vpls_against_path_tracing() {
    // The emissive ceiling panel as 4 Lambertian VPLs (instant radiosity, elek2014 Sec. 6) beside the
    // bulb; the path tracer keeps the panel's emission, and the pixels that see the panel itself are left
    // out of the comparison.
    let d = tempdir();
    let src = format!(
        "(tables: [PopPreset(id: \"pop\", grid: (12, 12, 12), iterations: 15, a_bins: 64)],
          stages: [PopRender(id: \"fog\", scene: \"{}\", table: \"pop\", width: 48, height: 32,
                             colour_samples: 1, voxels: 32, reference_samples: 256, reference_width: 32,
                             vpls: 4, surface_vpls: 0)])",
        root().join("scenes/fog_room.gltf").display()
    );
    let p = write(d.path(), "fog.ron", &src);
    let out = d.path().join("out");
    let o = voltab().args(["run", p.to_str().unwrap(), "--out", out.to_str().unwrap()]).output().unwrap();
    assert!(o.status.success(), "{}", text(&o));
    let sum: serde_json::Value = serde_json::from_slice(&std::fs::read(out.join("fog/summary.json")).unwrap()).unwrap();
    assert_eq!(sum["skipped"].as_array().unwrap().len(), 0, "{sum}");
    let names: Vec<&str> = sum["lights"].as_array().unwrap().iter().map(|l| l["light"].as_str().unwrap()).collect();
    assert_eq!(names.iter().filter(|n| n.contains("ceiling_panel") && n.contains("vpl")).count(), 4, "{names:?}");
    let r = &sum["reference"];
    let (e, noise, ratio) = error_against_reference(r);
    // Measured at 32 × 21, 256 paths per pixel, relative to the reference's mean: raw 0.700 against the
    // reference's noise 0.626, below the floor 0.453 (95 % interval up to 0.595), total ratio 1.037.
    // Without the panel's emission in the reference the ratio was ×8.8, with the panel seen directly
    // left in ×0.23: the ratio pins the VPLs' power.
    assert!(e.upper < 0.7, "{e:?}");
    assert!(e.raw > noise * 0.9, "POP cannot be closer to the reference than its own noise: {e:?} vs {noise}");
    assert!((0.95..1.15).contains(&ratio), "total ratio {ratio}");
}

#[test]
fn fog_room_surface_reflections_as_vpls_against_path_tracing() {
    // The bulb and the ceiling panel light the walls; 32 VPLs drawn from the lights' reflective shadow
    // maps (elek2014 Sec. 6) carry the walls' reflected light into the fog. The path tracer keeps the
    // walls' albedo for exactly one reflection (the walls the eye sees absorb); without the VPLs POP
    // misses that light.
    let run = |surface_vpls: u32| {
        let d = tempdir();
        let src = format!(
            "(tables: [PopPreset(id: \"pop\", grid: (12, 12, 12), iterations: 15, a_bins: 64)],
              stages: [PopRender(id: \"fog\", scene: \"{}\", table: \"pop\", width: 48, height: 32,
                                 colour_samples: 1, voxels: 32, reference_samples: 256, reference_width: 32,
                                 vpls: 4, surface_vpls: {surface_vpls})])",
            root().join("scenes/fog_room.gltf").display()
        );
        let p = write(d.path(), "fog.ron", &src);
        let out = d.path().join("out");
        let o = voltab().args(["run", p.to_str().unwrap(), "--out", out.to_str().unwrap()]).output().unwrap();
        assert!(o.status.success(), "{}", text(&o));
        let sum: serde_json::Value =
            serde_json::from_slice(&std::fs::read(out.join("fog/summary.json")).unwrap()).unwrap();
        let exr = voltab::image_io::read_exr_rgb(&out.join("fog/pop.exr")).unwrap();
        let total: f64 = exr.rgb(Some("scattered")).unwrap().iter().flatten().map(|&v| f64::from(v)).sum();
        (sum, total)
    };
    let (sum, with) = run(32);
    let refl = &sum["reflection"];
    assert_eq!((refl["maps"].as_u64(), refl["vpls"].as_u64(), refl["side"].as_u64()), (Some(5), Some(32), Some(64)));
    let names: Vec<&str> = sum["lights"].as_array().unwrap().iter().map(|l| l["light"].as_str().unwrap()).collect();
    assert_eq!(names.iter().filter(|n| n.starts_with("surfaces vpl")).count(), 32, "{names:?}");
    let r = &sum["reference"];
    let (e, noise, ratio) = error_against_reference(r);
    // Measured at 32 × 21, 256 paths per pixel, relative to the reference's mean: raw 0.574 against the
    // reference's noise 0.487, below the floor 0.334 (95 % interval up to 0.493), total ratio 0.991.
    assert!(e.upper < 0.6, "{e:?}");
    assert!(e.raw > noise * 0.9, "POP cannot be closer to the reference than its own noise: {e:?} vs {noise}");
    assert!((0.93..1.07).contains(&ratio), "total ratio {ratio}");
    // The VPLs add a third to POP's scattered light (measured ×1.329), so POP without them would sit
    // near ×0.75 of this reference: the ratio above pins their power.
    let (sum0, without) = run(0);
    assert!(sum0["reflection"].is_null());
    assert!((1.2..1.5).contains(&(with / without)), "with / without reflections {}", with / without);
}
