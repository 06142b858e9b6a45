//! `voltab validate`'s failures are clear and leave no report behind: an unknown stage id is named with
//! the valid ones; a missing Mitsuba harness names the interpreter and how to make one. (The comparison
//! itself runs in `tests/python/test_validate.py`, which has Mitsuba.)

mod common;

use common::{text, write};

fn pipeline(dir: &std::path::Path) -> std::path::PathBuf {
    let scene = common::root().join("scenes/window_room.gltf");
    write(
        dir,
        "p.ron",
        &format!(
            "(stages: [EpipolarShadows(id: \"god\", scene: \"{}\", width: 32, height: 24, colour_samples: 1, \
             shadow_map: 256)])",
            scene.display()
        ),
    )
}

#[test]
fn unknown_stage_is_named_with_the_valid_ids() {
    let d = common::tempdir();
    let p = pipeline(d.path());
    let out = d.path().join("report");
    let o = common::voltab()
        .args(["validate", p.to_str().unwrap(), "--stages", "godd", "--out", out.to_str().unwrap(), "--tables"])
        .arg(d.path().join("tables"))
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(1), "{}", text(&o));
    let t = text(&o);
    assert!(t.contains("no stage \"godd\"") && t.contains("stages: god"), "{t}");
    assert!(!out.join("validation.json").exists());
}

#[test]
fn missing_harness_is_a_clear_error_and_writes_no_report() {
    let d = common::tempdir();
    let p = pipeline(d.path());
    let out = d.path().join("report");
    let o = common::voltab()
        .args(["validate", p.to_str().unwrap(), "--out", out.to_str().unwrap(), "--tables"])
        .arg(d.path().join("tables"))
        .env("VOLTAB_PYTHON", d.path().join("no-such-python"))
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(1), "{}", text(&o));
    let t = text(&o);
    assert!(t.contains("the Mitsuba harness failed") && t.contains("no-such-python"), "{t}");
    assert!(t.contains("help:") && t.contains("VOLTAB_PYTHON"), "{t}");
    assert!(!t.contains("panicked"), "{t}");
    assert!(!out.join("validation.json").exists());
}
