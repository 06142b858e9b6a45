//! The `PopRender` stage lit by a USD `DomeLight` (the scene's environment), through the binary on the
//! bundled window room: a dome renders exactly what the same map given as the stage's `environment` field
//! renders (both with a texture and as a uniform dome), the stage's field overrides a dome and says so in
//! `skipped`, and a dome texture that is missing or not an EXR is an error naming the USD file, the prim
//! and the texture.

mod common;

use std::path::{Path, PathBuf};

use common::{root, tempdir, text, voltab, write};

/// A root layer over the bundled window room (same units and axes) with `extra` prims.
fn layer(extra: &str) -> String {
    format!(
        "#usda 1.0\n(\n    metersPerUnit = 1\n    upAxis = \"Y\"\n    subLayers = [@{}@]\n)\n\n{extra}",
        root().join("scenes/window_room.usda").display()
    )
}

/// The bundled sky at 341.5 nits × 2^1 = 683 nits = 1 W/(m² sr) per texel unit: the stage's
/// `environment_intensity: 1` in voltab's radiometric units.
const TEXTURED_DOME: &str = "def DomeLight \"Sky\"\n{\n    float inputs:intensity = 341.5\n    \
                             float inputs:exposure = 1\n    asset inputs:texture:file = @textures/sky.exr@\n}\n";

/// A uniform dome of 341.5 nits = 0.5 W/(m² sr) (an exact binary fraction, as in a float EXR).
const UNIFORM_DOME: &str = "def DomeLight \"Sky\"\n{\n    float inputs:intensity = 341.5\n}\n";

/// Runs the stage on `scene` with `extra` fields; returns the process output and the stage's folder.
fn run(dir: &Path, name: &str, scene: &Path, extra: &str) -> (std::process::Output, PathBuf) {
    let src = format!(
        "(tables: [PopPreset(id: \"pop\", grid: (10, 10, 10), iterations: 10, a_bins: 64)],
          stages: [PopRender(id: \"pop_stage\", scene: \"{}\", table: \"pop\", width: 32, height: 24,
                             colour_samples: 1, voxels: 20, surface_vpls: 0, environment_ordinates: 8{extra})])",
        scene.display()
    );
    let p = write(dir, &format!("{name}.ron"), &src);
    let out = dir.join(name);
    let o = voltab().args(["run", p.to_str().unwrap(), "--out", out.to_str().unwrap()]).output().unwrap();
    (o, out.join("pop_stage"))
}

/// The stage's image layers (final, scattered) and its summary.
fn results(dir: &Path) -> (Vec<[f32; 3]>, Vec<[f32; 3]>, serde_json::Value) {
    let exr = voltab::image_io::read_exr_rgb(&dir.join("pop.exr")).unwrap();
    let sum = serde_json::from_slice(&std::fs::read(dir.join("summary.json")).unwrap()).unwrap();
    (exr.rgb(None).unwrap(), exr.rgb(Some("scattered")).unwrap(), sum)
}

#[test]
fn a_dome_renders_exactly_as_its_map_given_to_the_stage() {
    let d = tempdir();
    std::fs::create_dir_all(d.path().join("textures")).unwrap();
    std::fs::copy(root().join("scenes/sky.exr"), d.path().join("textures/sky.exr")).unwrap();
    let dome = write(d.path(), "dome.usda", &layer(TEXTURED_DOME));
    let plain = write(d.path(), "plain.usda", &layer(""));

    let (o, dir) = run(d.path(), "dome", &dome, "");
    assert!(o.status.success(), "{}", text(&o));
    let (dome_img, dome_scattered, dome_sum) = results(&dir);
    let env = &dome_sum["environment"];
    let map = env["map"].as_str().unwrap();
    assert!(map.starts_with("DomeLight /Sky (") && map.ends_with("textures/sky.exr)"), "{map}");
    // The bundled sky's green integral, 2π(0.65 − 0.33·2/3) + 2π·0.09 (its golden test), × 1 W/(m² sr).
    let want = std::f64::consts::TAU * (0.65 - 0.22 + 0.09);
    let integral = env["integral"][1].as_f64().unwrap();
    assert!((integral - want).abs() < 2e-3 * want, "{integral} vs {want}");
    assert!(dome_scattered.iter().any(|p| p[1] > 0.0));

    // The same scene without the dome, the same map through the stage's field at intensity 1.
    let field = ", environment: \"textures/sky.exr\", environment_intensity: 1";
    let (o, dir) = run(d.path(), "field", &plain, field);
    assert!(o.status.success(), "{}", text(&o));
    let (field_img, field_scattered, field_sum) = results(&dir);
    assert_eq!(dome_scattered, field_scattered, "scattered light differs");
    assert_eq!(dome_img, field_img, "final image differs");
    assert_eq!(dome_sum["environment"]["ordinates"], field_sum["environment"]["ordinates"]);

    // Both at once: the stage's field wins, the summary says the dome was overridden.
    let (o, dir) = run(d.path(), "both", &dome, field);
    assert!(o.status.success(), "{}", text(&o));
    let (_, both_scattered, both_sum) = results(&dir);
    assert_eq!(both_scattered, field_scattered);
    let skipped: Vec<&str> = both_sum["skipped"].as_array().unwrap().iter().map(|s| s.as_str().unwrap()).collect();
    assert!(
        skipped
            .iter()
            .any(|s| s.starts_with("DomeLight /Sky: overridden by the stage's environment map textures/sky.exr")),
        "{skipped:?}"
    );
    assert_eq!(both_sum["environment"]["map"], "textures/sky.exr");
    assert!(!dome_sum["skipped"].to_string().contains("overridden"), "{}", dome_sum["skipped"]);
}

#[test]
fn a_uniform_dome_renders_as_a_uniform_map_given_to_the_stage() {
    let d = tempdir();
    // The uniform dome's map is 64 × 32 texels of 0.5 W/(m² sr) (`UNIFORM_DOME_SIZE`).
    let px = vec![[0.5f32; 3]; 64 * 32];
    voltab::image_io::write_exr_rgb(&d.path().join("half.exr"), 64, 32, &px, &[]).unwrap();
    let dome = write(d.path(), "dome.usda", &layer(UNIFORM_DOME));
    let plain = write(d.path(), "plain.usda", &layer(""));
    let (o, dir) = run(d.path(), "dome", &dome, "");
    assert!(o.status.success(), "{}", text(&o));
    let (_, dome_scattered, dome_sum) = results(&dir);
    assert_eq!(dome_sum["environment"]["map"], "DomeLight /Sky (uniform)");
    // 4π × 0.5 W/m².
    let integral = dome_sum["environment"]["integral"][0].as_f64().unwrap();
    assert!((integral - 2.0 * std::f64::consts::PI).abs() < 1e-12, "{integral}");
    let (o, dir) = run(d.path(), "field", &plain, ", environment: \"half.exr\"");
    assert!(o.status.success(), "{}", text(&o));
    assert_eq!(dome_scattered, results(&dir).1);
}

#[test]
fn an_unreadable_dome_texture_names_the_file_the_prim_and_the_texture() {
    let d = tempdir();
    let dome = write(d.path(), "dome.usda", &layer(TEXTURED_DOME));
    let texture = d.path().join("textures/sky.exr");
    // Missing, then not an EXR at all.
    for (case, bytes) in [("missing", None), ("corrupt", Some(b"not an exr".as_slice()))] {
        if let Some(b) = bytes {
            write(d.path(), "textures/sky.exr", std::str::from_utf8(b).unwrap());
        }
        let (o, dir) = run(d.path(), case, &dome, "");
        assert_ne!(o.status.code(), Some(0), "{case}");
        let t = text(&o);
        for needle in [
            format!(
                "{}: DomeLight /Sky: cannot light the medium with its texture {}",
                dome.display(),
                texture.display()
            ),
            "inputs:texture:file".to_string(),
            "help:".to_string(),
        ] {
            assert!(t.contains(&needle), "{case}: no {needle:?} in\n{t}");
        }
        for bad in ["panicked", "RUST_BACKTRACE"] {
            assert!(!t.contains(bad), "{case}: {t}");
        }
        assert!(!dir.join("pop.exr").exists(), "{case}");
    }
}
