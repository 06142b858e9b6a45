//! The same scene from `.usda`, `.usdc` (written by usd-core) and `.usdz`; import time of a large mesh.

use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Instant;

use super::{SNIPPETS, pxr_python, run_python};
use crate::scene::Scene;
use crate::scene::usd_import::import;

/// `usdcat` on PATH or in the crate's `.venv`.
fn usdcat() -> Option<PathBuf> {
    let venv = Path::new(env!("CARGO_MANIFEST_DIR")).join(".venv/bin/usdcat");
    [PathBuf::from("usdcat"), venv]
        .into_iter()
        .find(|c| Command::new(c).arg("--help").output().is_ok_and(|o| o.status.success()))
}

/// The scene as JSON with the source path blanked (it differs between the copies by design), also
/// where a warning names the layer.
fn canonical(mut s: Scene) -> serde_json::Value {
    let layer = s.source.display().to_string();
    for w in &mut s.warnings {
        if w.location == layer {
            w.location = "<layer>".into();
        }
    }
    s.source = PathBuf::new();
    serde_json::to_value(&s).expect("scene serialises")
}

/// Every snippet that imports, converted to `.usdc` (usdcat, else usd-core's Python) and packaged as
/// `.usdz` (usd-core), gives exactly the scene the `.usda` gives.
#[test]
fn usdc_and_usdz_written_by_usd_core_give_the_same_scene() {
    let (cat, py) = (usdcat(), pxr_python());
    if cat.is_none() && py.is_none() {
        eprintln!("SKIPPED: neither usdcat nor a Python with usd-core (pxr) is available to write .usdc files");
        return;
    }
    let dir = tempfile::tempdir().expect("temp dir");
    // The texture a material names must exist for usdz packaging (voltab does not read it); so must the
    // dome textures (which voltab reads from files only: packaged, they are warned about instead).
    std::fs::write(dir.path().join("rough.png"), b"\x89PNG\r\n\x1a\n").expect("write");
    for tex in ["dome_sky.exr", "textures/dome_sky.exr"] {
        let path = dir.path().join(tex);
        std::fs::create_dir_all(path.parent().expect("parent")).expect("mkdir");
        crate::image_io::write_exr_rgb(&path, 2, 1, &[[1.0; 3]; 2], &[]).expect("write exr");
    }
    let mut cases = Vec::new();
    for (name, text) in SNIPPETS {
        let usda = dir.path().join(format!("{name}.usda"));
        std::fs::write(&usda, text).expect("write");
        if let Ok(scene) = import(&usda) {
            cases.push((*name, usda, canonical(scene)));
        }
    }
    let usdas: Vec<&Path> = cases.iter().map(|(_, p, _)| p.as_path()).collect();
    match &cat {
        Some(cat) => {
            for usda in &usdas {
                let out = Command::new(cat)
                    .arg(usda)
                    .arg("-o")
                    .arg(usda.with_extension("usdc"))
                    .env("USD_WRITE_NEW_USDC_FILES_AS_VERSION", "0.8.0")
                    .output()
                    .expect("run usdcat");
                assert!(out.status.success(), "usdcat failed: {}", String::from_utf8_lossy(&out.stderr));
            }
        }
        None => {
            let script = "import sys\nfrom pxr import Sdf\nfor f in sys.argv[1:]:\n    \
                          assert Sdf.Layer.FindOrOpen(f).Export(f[:-1] + 'c')";
            run_python(py.as_deref().expect("python"), script, &usdas);
        }
    }
    // A package cannot hold a reference to a missing file: that snippet has no .usdz.
    let packaged: Vec<&Path> =
        cases.iter().filter(|(name, ..)| *name != "missing_reference").map(|(_, p, _)| p.as_path()).collect();
    if let Some(py) = &py {
        let script = "import sys\nfrom pxr import UsdUtils\nfor f in sys.argv[1:]:\n    \
                      assert UsdUtils.CreateNewUsdzPackage(f[:-1] + 'c', f[:-1] + 'z')";
        run_python(py, script, &packaged);
    }
    for (name, usda, expected) in &cases {
        let got = canonical(import(&usda.with_extension("usdc")).unwrap_or_else(|e| panic!("{name}.usdc: {e}")));
        assert_eq!(&got, expected, "{name}: .usdc differs from .usda");
        // `.usd` may hold either encoding.
        for (from, to) in [("usdc", "bin.usd"), ("usda", "text.usd")] {
            let copy = usda.with_extension(to);
            std::fs::copy(usda.with_extension(from), &copy).expect("copy");
            let got = canonical(import(&copy).unwrap_or_else(|e| panic!("{name}.{to}: {e}")));
            assert_eq!(&got, expected, "{name}: .{to} differs from .usda");
        }
        if py.is_some() && *name != "missing_reference" {
            let scene = import(&usda.with_extension("usdz")).unwrap_or_else(|e| panic!("{name}.usdz: {e}"));
            if super::dome::TEXTURED.contains(name) && expected["environment"] != serde_json::Value::Null {
                // The package holds the dome's texture: voltab skips the dome, saying why.
                assert!(scene.environment.is_none(), "{name}.usdz: {:?}", scene.environment);
                assert!(
                    scene.warnings.iter().any(|w| w.message.contains("packaged inside a .usdz")),
                    "{name}.usdz: {:#?}",
                    scene.warnings
                );
                continue;
            }
            assert_eq!(&canonical(scene), expected, "{name}: .usdz differs from .usda");
        }
    }
    assert!(cases.len() >= 15, "only {} snippets compared", cases.len());
}

/// Import time of a 500k-quad grid written as `.usdc` by usd-core (run with `--ignored`, ideally in
/// release: `cargo test --release --lib usd_import -- --ignored --nocapture`).
#[test]
#[ignore = "timing: generates a 500k-quad .usdc with usd-core"]
fn large_usdc_mesh_import_time() {
    let Some(py) = pxr_python() else {
        eprintln!("SKIPPED: no Python with usd-core (pxr)");
        return;
    };
    let dir = tempfile::tempdir().expect("temp dir");
    let path = dir.path().join("grid.usdc");
    let script = r#"
import sys
import numpy as np
from pxr import Sdf, Usd, UsdGeom, Vt
n = 708  # 708² = 501,264 quads
stage = Usd.Stage.CreateNew(sys.argv[1])
stage.SetMetadata("metersPerUnit", 1.0)
mesh = UsdGeom.Mesh.Define(stage, "/Grid")
mesh.CreateSubdivisionSchemeAttr("none")
xs = np.linspace(0.0, 1.0, n + 1, dtype=np.float32)
gx, gz = np.meshgrid(xs, xs)
pts = np.stack([gx.ravel(), np.zeros(gx.size, np.float32), gz.ravel()], axis=1)
mesh.CreatePointsAttr(Vt.Vec3fArray.FromNumpy(pts))
i = np.arange(n)
a = (i[:, None] * (n + 1) + i[None, :]).ravel()
quads = np.stack([a, a + n + 1, a + n + 2, a + 1], axis=1).astype(np.int32)
mesh.CreateFaceVertexCountsAttr(Vt.IntArray.FromNumpy(np.full(n * n, 4, np.int32)))
mesh.CreateFaceVertexIndicesAttr(Vt.IntArray.FromNumpy(quads.ravel()))
st = UsdGeom.PrimvarsAPI(mesh).CreatePrimvar("st", Sdf.ValueTypeNames.TexCoord2fArray, UsdGeom.Tokens.faceVarying)
uv = np.stack([pts[:, 0], pts[:, 2]], axis=1)[quads.ravel()]
st.Set(Vt.Vec2fArray.FromNumpy(uv.astype(np.float32)))
stage.GetRootLayer().Save()
"#;
    run_python(&py, script, &[&path]);
    let t = Instant::now();
    let scene = import(&path).expect("import grid");
    let secs = t.elapsed().as_secs_f64();
    let m = &scene.meshes[0];
    assert_eq!(m.triangles.len(), 2 * 708 * 708);
    assert_eq!(m.positions.len(), 709 * 709, "faceVarying st with equal values per point welds back");
    eprintln!(
        "USD import of a {}-quad .usdc grid ({} triangles, faceVarying st): {secs:.3} s ({} build)",
        708 * 708,
        m.triangles.len(),
        if cfg!(debug_assertions) { "debug" } else { "release" }
    );
}
