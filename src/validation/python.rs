//! The Python side of `voltab validate`: finds an interpreter with Mitsuba 3 and the harness
//! `python/mitsuba_ref`, runs a request in a folder and reads the harness's reply.
//!
//! **Input → output.** A request (JSON, the format of `python/mitsuba_ref/harness.py`) → `request.json` in
//! the case's folder (atomically) → `python -m mitsuba_ref request.json` → [`Reply`] read from the
//! `out` file the request names.
//!
//! The interpreter is `$VOLTAB_PYTHON`, else `.venv/bin/python` in the working folder (what
//! `scripts/test-all.sh` creates), else `python3`; the harness's folder is `$VOLTAB_PYTHONPATH`, else
//! `python/` in the working folder, else the `python/` folder of the source tree this binary was built
//! from.

use std::path::{Path, PathBuf};
use std::process::Command;

use serde::Deserialize;

use crate::cache::write_atomic;

/// The harness could not run or answered nonsense.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum PythonError {
    /// The interpreter could not be started or the harness failed.
    #[error(
        "the Mitsuba harness failed ({python} -m mitsuba_ref {}): {message}\n  help: create the Python \
         environment with `scripts/test-all.sh` (it makes .venv with mitsuba), or point VOLTAB_PYTHON at a \
         Python that has `mitsuba` and VOLTAB_PYTHONPATH at voltab's python/ folder",
        request.display()
    )]
    Run {
        /// Interpreter.
        python: String,
        /// Request file.
        request: PathBuf,
        /// What went wrong (the harness's last lines of stderr).
        message: String,
    },
    /// The reply is unreadable.
    #[error("{}: {message}\n  help: this is a harness bug; rerun with the request file to reproduce", path.display())]
    Reply {
        /// Reply file.
        path: PathBuf,
        /// Why.
        message: String,
    },
}

/// Where the harness runs.
#[derive(Debug, Clone)]
pub struct Harness {
    /// Interpreter.
    pub python: PathBuf,
    /// Folder holding the `mitsuba_ref` package.
    pub python_path: PathBuf,
}

impl Harness {
    /// The interpreter and harness folder (module doc).
    pub fn locate() -> Harness {
        let python = std::env::var_os("VOLTAB_PYTHON").map(PathBuf::from).unwrap_or_else(|| {
            let venv = PathBuf::from(".venv/bin/python");
            if venv.exists() { venv } else { PathBuf::from("python3") }
        });
        let python_path = std::env::var_os("VOLTAB_PYTHONPATH").map(PathBuf::from).unwrap_or_else(|| {
            let here = PathBuf::from("python");
            if here.join("mitsuba_ref").is_dir() { here } else { Path::new(env!("CARGO_MANIFEST_DIR")).join("python") }
        });
        // The harness runs in each case's folder: relative paths are made absolute first (a bare
        // interpreter name is left to the search path).
        let abs = |p: PathBuf| std::path::absolute(&p).unwrap_or(p);
        let python = if python.components().count() > 1 { abs(python) } else { python };
        Harness { python, python_path: abs(python_path) }
    }

    /// Writes `request` to `dir/name`, runs it, reads the reply.
    pub fn run(&self, dir: &Path, name: &str, request: &serde_json::Value) -> Result<Reply, PythonError> {
        let path = dir.join(name);
        let fail = |message: String| PythonError::Run {
            python: self.python.display().to_string(),
            request: path.clone(),
            message,
        };
        let text = serde_json::to_vec_pretty(request).expect("a JSON value serialises");
        write_atomic(&path, &text).map_err(|e| fail(e.to_string()))?;
        let output = Command::new(&self.python)
            .arg("-m")
            .arg("mitsuba_ref")
            .arg(name)
            .current_dir(dir)
            .env("PYTHONPATH", &self.python_path)
            .stdin(std::process::Stdio::null())
            .output()
            .map_err(|e| fail(format!("cannot start it: {e}")))?;
        if !output.status.success() {
            let err = String::from_utf8_lossy(&output.stderr);
            let tail: Vec<&str> = err.lines().rev().take(12).collect();
            let tail: Vec<&str> = tail.into_iter().rev().collect();
            return Err(fail(format!("{}\n{}", output.status, tail.join("\n"))));
        }
        let out = request["out"].as_str().unwrap_or("result.json");
        let reply_path = dir.join(out);
        let bad = |message: String| PythonError::Reply { path: reply_path.clone(), message };
        let bytes = std::fs::read(&reply_path).map_err(|e| bad(e.to_string()))?;
        serde_json::from_slice(&bytes).map_err(|e| bad(e.to_string()))
    }
}

/// The harness's result file.
#[derive(Debug, Clone, Deserialize)]
pub struct Reply {
    /// Mitsuba variant used.
    pub variant: String,
    /// Per query and max_depth.
    pub queries: Vec<QueryResult>,
}

/// One query at one max_depth.
#[derive(Debug, Clone, Deserialize)]
pub struct QueryResult {
    /// Query name.
    pub name: String,
    /// Wall time \[s\].
    pub seconds: f64,
    /// Reference mean per item (irradiance and radiance queries).
    #[serde(default)]
    pub mean: Vec<[f64; 3]>,
    /// Files written (images: mean and variance EXR).
    #[serde(default)]
    pub files: Vec<String>,
    /// The methods' errors.
    #[serde(default)]
    pub comparisons: Vec<Comparison>,
}

/// One method against the reference (`mitsuba_ref.compare.noise_corrected`).
#[derive(Debug, Clone, Deserialize)]
pub struct Comparison {
    /// Method name.
    pub method: Option<String>,
    /// Noise-corrected relative RMSE (`None` below the floor).
    pub rel_rmse: Option<f64>,
    /// 95 % interval.
    #[serde(default)]
    pub ci95: Option<[f64; 2]>,
    /// Floor.
    pub floor: Option<f64>,
    /// Before noise correction.
    pub raw_rel_rmse: Option<f64>,
    /// The reference's mean.
    pub norm: Option<f64>,
    /// Wording.
    pub text: Option<String>,
    /// Why no comparison.
    pub error: Option<String>,
}
