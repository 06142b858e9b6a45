//! Tests of the USD importer. Every `.usda` snippet lives in [`SNIPPETS`] (so one test can check
//! them all with usd-core, whose parser is stricter than openusd's); expected values are computed by
//! hand in each test from the formulas in `docs/design/scene.md`.

mod dome;
mod errors;
mod geometry;
mod interchange;
mod lights;
mod shading;

use std::path::{Path, PathBuf};
use std::process::Command;

use tempfile::TempDir;

use super::import;
use crate::scene::{Scene, SceneError, SceneWarning};

/// Every snippet by name, for the usd-core validation test.
pub(super) const SNIPPETS: &[(&str, &str)] = &[
    ("cm_scale", geometry::CM_SCALE),
    ("no_units", geometry::NO_UNITS),
    ("z_up", geometry::Z_UP),
    ("nested_xforms", geometry::NESTED_XFORMS),
    ("polygons", geometry::POLYGONS),
    ("indexed_st", geometry::INDEXED_ST),
    ("face_varying", geometry::FACE_VARYING),
    ("uniform_normals", geometry::UNIFORM_NORMALS),
    ("skipped_prims", geometry::SKIPPED_PRIMS),
    ("instances", geometry::INSTANCES),
    ("time_samples", geometry::TIME_SAMPLES),
    ("point_light", lights::POINT_LIGHT),
    ("area_lights", lights::AREA_LIGHTS),
    ("distant_lights", lights::DISTANT_LIGHTS),
    ("default_lights", lights::DEFAULT_LIGHTS),
    ("cameras", lights::CAMERAS),
    ("materials", shading::MATERIALS),
    ("vdf_medium", shading::VDF_MEDIUM),
    ("global_medium", shading::GLOBAL_MEDIUM),
    ("subsets", shading::SUBSETS),
    ("unsupported", errors::UNSUPPORTED),
    ("missing_reference", errors::MISSING_REFERENCE),
    ("bad_counts", errors::BAD_COUNTS),
    ("short_face", errors::SHORT_FACE),
    ("index_range", errors::INDEX_RANGE),
    ("nan_point", errors::NAN_POINT),
    ("negative_light", errors::NEGATIVE_LIGHT),
    ("two_globals", errors::TWO_GLOBALS),
    ("dome_textured", dome::DOME_TEXTURED),
    ("dome_uniform", dome::DOME_UNIFORM),
    ("dome_1_z_up", dome::DOME_1_Z_UP),
    ("dome_z_up", dome::DOME_Z_UP),
    ("dome_pole_z", dome::DOME_POLE_Z),
    ("dome_formats", dome::DOME_FORMATS),
    ("two_domes", dome::TWO_DOMES),
    ("dome_extras", dome::DOME_EXTRAS),
    ("dome_degenerate", dome::DOME_DEGENERATE),
    ("dome_oriented", dome::DOME_ORIENTED),
];

/// A snippet written to a temporary folder (kept alive with the path).
pub(super) struct Written {
    _dir: TempDir,
    pub path: PathBuf,
}

/// Writes `text` as `<name>.usda` in a fresh temporary folder.
pub(super) fn write(name: &str, text: &str) -> Written {
    let dir = tempfile::tempdir().expect("temp dir");
    let path = dir.path().join(format!("{name}.usda"));
    std::fs::write(&path, text).expect("write snippet");
    Written { _dir: dir, path }
}

/// Imports a snippet that must load.
pub(super) fn load(name: &str, text: &str) -> Scene {
    let w = write(name, text);
    import(&w.path).unwrap_or_else(|e| panic!("{name} failed to import: {e}"))
}

/// Imports a snippet that must fail.
pub(super) fn load_err(name: &str, text: &str) -> SceneError {
    let w = write(name, text);
    match import(&w.path) {
        Ok(_) => panic!("{name} imported but should fail"),
        Err(e) => e,
    }
}

/// The warnings located at `location`.
pub(super) fn warnings_at<'a>(scene: &'a Scene, location: &str) -> Vec<&'a SceneWarning> {
    scene.warnings.iter().filter(|w| w.location == location).collect()
}

/// Asserts one warning at `location` whose message contains `needle`.
#[track_caller]
pub(super) fn assert_warns(scene: &Scene, location: &str, needle: &str) {
    assert!(
        warnings_at(scene, location).iter().any(|w| w.message.contains(needle)),
        "no warning at {location} containing {needle:?}; warnings: {:#?}",
        scene.warnings
    );
}

/// Asserts `|a − b| <= tol · max(1, |b|)` component-wise.
#[track_caller]
pub(super) fn assert_close<const N: usize>(a: [f64; N], b: [f64; N], tol: f64) {
    for i in 0..N {
        assert!((a[i] - b[i]).abs() <= tol * b[i].abs().max(1.0), "component {i}: got {a:?}, expected {b:?}");
    }
}

/// `[f32; 3]` → `[f64; 3]`.
pub(super) fn f64s(p: [f32; 3]) -> [f64; 3] {
    p.map(f64::from)
}

/// The Python interpreter with usd-core (`pxr`), if this machine has one: `$VOLTAB_PYTHON`, the
/// crate's `.venv`, or `python3` on PATH.
pub(super) fn pxr_python() -> Option<PathBuf> {
    let venv = Path::new(env!("CARGO_MANIFEST_DIR")).join(".venv/bin/python");
    let candidates = [std::env::var_os("VOLTAB_PYTHON").map(PathBuf::from), Some(venv), Some("python3".into())];
    candidates
        .into_iter()
        .flatten()
        .find(|py| Command::new(py).args(["-c", "import pxr.Usd"]).output().is_ok_and(|o| o.status.success()))
}

/// Runs `script` with usd-core's Python and `args`; panics with its stderr on failure.
pub(super) fn run_python(py: &Path, script: &str, args: &[&Path]) {
    let out = Command::new(py)
        .arg("-c")
        .arg(script)
        .args(args)
        .env("USD_WRITE_NEW_USDC_FILES_AS_VERSION", "0.8.0")
        .output()
        .expect("run python");
    assert!(out.status.success(), "python failed:\n{}", String::from_utf8_lossy(&out.stderr));
}

/// usd-core opens every snippet without errors (openusd's parser is more lenient, so a snippet that
/// only openusd accepts would test nothing real).
#[test]
fn snippets_are_valid_usd_for_usd_core() {
    let Some(py) = pxr_python() else {
        eprintln!("SKIPPED: no Python with usd-core (pxr); set VOLTAB_PYTHON or create .venv with usd-core");
        return;
    };
    let dir = tempfile::tempdir().expect("temp dir");
    for (name, text) in SNIPPETS {
        std::fs::write(dir.path().join(format!("{name}.usda")), text).expect("write");
    }
    let script = r#"
import pathlib, sys
from pxr import Sdf, Usd
bad = []
for f in sorted(pathlib.Path(sys.argv[1]).glob("*.usda")):
    layer = Sdf.Layer.FindOrOpen(str(f))
    if layer is None or Usd.Stage.Open(layer) is None:
        bad.append(f.name)
if bad:
    sys.exit("usd-core rejects: " + ", ".join(bad))
"#;
    run_python(&py, script, &[dir.path()]);
}
