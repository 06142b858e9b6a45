//! Helpers shared by the integration tests.
#![allow(dead_code)]

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

/// A fresh temporary folder (deleted on drop).
pub fn tempdir() -> tempfile::TempDir {
    tempfile::Builder::new().prefix("voltab-test-").tempdir().expect("temp dir")
}

/// Writes `text` to `dir/name` and returns the path.
pub fn write(dir: &Path, name: &str, text: &str) -> PathBuf {
    let p = dir.join(name);
    if let Some(parent) = p.parent() {
        std::fs::create_dir_all(parent).expect("mkdir");
    }
    std::fs::write(&p, text).expect("write");
    p
}

/// The voltab binary built for this test run.
pub fn voltab() -> Command {
    Command::new(env!("CARGO_BIN_EXE_voltab"))
}

/// Runs voltab with args, returning output.
pub fn run(args: &[&str]) -> Output {
    voltab().args(args).output().expect("spawn voltab")
}

/// stdout + stderr as one string.
pub fn text(o: &Output) -> String {
    format!("{}{}", String::from_utf8_lossy(&o.stdout), String::from_utf8_lossy(&o.stderr))
}

/// Compiles `pipeline` (written as `file` in a fresh temp folder) through the binary and returns the
/// kept folder and the path of table `id`.
pub fn compile_pipeline(file: &str, pipeline: &str, id: &str) -> (tempfile::TempDir, PathBuf) {
    let d = tempdir();
    let p = write(d.path(), file, pipeline);
    let out = d.path().join("out");
    let o = voltab().args(["compile", p.to_str().unwrap(), "--out", out.to_str().unwrap()]).output().unwrap();
    assert!(o.status.success(), "{}", text(&o));
    (d, out.join(format!("{id}.vtab")))
}

/// The repository root.
pub fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// Every `.vtab` file in a folder (not the cache), sorted.
pub fn vtabs(dir: &Path) -> Vec<PathBuf> {
    let mut v: Vec<PathBuf> = std::fs::read_dir(dir)
        .expect("read_dir")
        .flatten()
        .map(|e| e.path())
        .filter(|p| p.extension().is_some_and(|e| e == "vtab"))
        .collect();
    v.sort();
    v
}
