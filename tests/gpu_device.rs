//! `voltab run --device gpu` end to end (issue 10): the real-time effect stages run on the GPU
//! adapter (lavapipe in CI), say which adapter they chose, record the device and per-pass GPU times
//! in their summaries, and give the images the CPU gives within f32 tolerance. Built only with the
//! `gpu` feature (`cargo test --features gpu`, what `scripts/test-all.sh` runs).
#![cfg(feature = "gpu")]

mod common;

use std::path::Path;

use common::{root, tempdir, text, voltab, write};

fn pipeline() -> String {
    format!(
        "(tables: [PopPreset(id: \"pop\", grid: (12, 12, 12), iterations: 12, a_bins: 64)],
          stages: [PopRender(id: \"pop_stage\", scene: \"{}\", table: \"pop\", width: 40, height: 30,
                             colour_samples: 1, voxels: 24, fig12_photons: 0)])",
        root().join("scenes/window_room.gltf").display()
    )
}

fn run(p: &Path, out: &Path, device: &str) -> String {
    let o = voltab()
        .args(["run", p.to_str().unwrap(), "--out", out.to_str().unwrap(), "--device", device])
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", text(&o));
    text(&o)
}

fn summary(dir: &Path) -> serde_json::Value {
    serde_json::from_slice(&std::fs::read(dir.join("summary.json")).unwrap()).unwrap()
}

/// Relative RMS of the GPU image `gpu` against the CPU image `cpu`, which must not be black.
fn rel_rms(gpu: &[[f32; 3]], cpu: &[[f32; 3]], what: &str) -> f64 {
    let (mut num, mut den) = (0.0f64, 0.0f64);
    for (a, b) in gpu.iter().zip(cpu) {
        for k in 0..3 {
            num += f64::from(a[k] - b[k]).powi(2);
            den += f64::from(b[k]).powi(2);
        }
    }
    assert!(den > 0.0, "the CPU frame has {what}");
    (num / den).sqrt()
}

#[test]
fn pop_stage_on_the_gpu_matches_the_cpu_and_reports_its_adapter() {
    let d = tempdir();
    let p = write(d.path(), "pop.ron", &pipeline());
    let (cpu_out, gpu_out) = (d.path().join("cpu"), d.path().join("gpu"));
    let said = run(&p, &cpu_out, "cpu");
    assert!(said.contains("device: cpu (asked for with --device cpu)"), "{said}");
    let said = run(&p, &gpu_out, "gpu");
    assert!(said.contains("device: gpu ("), "the chosen adapter is named: {said}");

    let (c, g) = (summary(&cpu_out.join("pop_stage")), summary(&gpu_out.join("pop_stage")));
    assert_eq!(c["lights"][0]["device"], "cpu");
    assert_eq!(g["lights"][0]["device"], "gpu");
    assert_eq!(c["lights"][0]["gpu_passes"], serde_json::json!([]));
    let phases: Vec<&str> =
        g["lights"][0]["gpu_passes"].as_array().unwrap().iter().map(|p| p["phase"].as_str().unwrap()).collect();
    assert!(phases.contains(&"propagation") && phases.contains(&"accumulation"), "{phases:?}");
    for key in ["anisotropic_iterations", "isotropic_iterations"] {
        assert_eq!(c["lights"][0][key], g["lights"][0][key], "{key}");
    }

    // The scattered light: f32 propagation on the GPU against f64 on the CPU, then the same ray
    // march; measured ~1e-6 relative RMS, pinned at 1e-5.
    let read = |out: &Path| voltab::image_io::read_exr_rgb(&out.join("pop_stage/pop.exr")).unwrap();
    let (ce, ge) = (read(&cpu_out), read(&gpu_out));
    let (cs, gs) = (ce.rgb(Some("scattered")).unwrap(), ge.rgb(Some("scattered")).unwrap());
    let rel = rel_rms(&gs, &cs, "scattered light");
    assert!(rel < 1e-5, "GPU vs CPU scattered light: relative RMS {rel:.2e}");
    // Transmittance does not depend on the propagation at all.
    assert_eq!(ce.rgb(Some("transmittance")).unwrap(), ge.rgb(Some("transmittance")).unwrap());
}

#[test]
fn device_auto_names_its_choice() {
    let d = tempdir();
    let p = write(d.path(), "pop.ron", &pipeline());
    let said = run(&p, &d.path().join("out"), "auto");
    // With the gpu feature and lavapipe installed (CI), auto takes the GPU; either way it says so.
    assert!(said.contains("device: gpu (") || said.contains("device: cpu (no GPU adapter"), "{said}");
}

#[test]
fn god_rays_on_the_gpu_match_the_cpu_and_record_their_passes() {
    let d = tempdir();
    let p = write(
        d.path(),
        "rays.ron",
        &format!(
            "(stages: [EpipolarShadows(id: \"rays\", scene: \"{}\", width: 96, height: 72, colour_samples: 1,
                                      shadow_map: 512, reference_steps: 0)])",
            root().join("scenes/window_room.gltf").display()
        ),
    );
    let (cpu_out, gpu_out) = (d.path().join("cpu"), d.path().join("gpu"));
    run(&p, &cpu_out, "cpu");
    let said = run(&p, &gpu_out, "gpu");
    assert!(said.contains("epipolar") && said.contains(" on gpu"), "{said}");
    let (c, g) = (summary(&cpu_out.join("rays")), summary(&gpu_out.join("rays")));
    assert_eq!(c["device"], "cpu");
    assert_eq!(g["device"], "gpu");
    assert_eq!(c["slices"], g["slices"], "the same slice layout");
    let phases: Vec<&str> = g["gpu_phases"].as_array().unwrap().iter().map(|p| p["phase"].as_str().unwrap()).collect();
    let integrate = ["integrate: quantise", "integrate: block bases", "integrate: sums", "integrate: combine"];
    for phase in ["rectify", "prefilter"].into_iter().chain(integrate).chain(["unrectify"]) {
        assert!(phases.contains(&phase), "{phase} missing from {phases:?}");
    }
    // f32 on the device against f64 on the CPU; measured 8.7e-5 relative RMS on the window grid's
    // hard shadow edges, pinned at 1e-3.
    let read = |out: &Path| voltab::image_io::read_exr_rgb(&out.join("rays/godrays.exr")).unwrap();
    let (ce, ge) = (read(&cpu_out), read(&gpu_out));
    let (cs, gs) = (ce.rgb(Some("inscatter")).unwrap(), ge.rgb(Some("inscatter")).unwrap());
    let rel = rel_rms(&gs, &cs, "in-scattered light");
    eprintln!("god rays GPU vs CPU in-scatter: relative RMS {rel:.2e}");
    assert!(rel < 1e-3, "GPU vs CPU in-scatter: relative RMS {rel:.2e}");
}
