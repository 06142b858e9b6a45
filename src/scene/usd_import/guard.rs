//! Containment of the USD parser: a layer path → the imported [`Scene`] read by a child process
//! (the same `voltab` binary, hidden subcommand [`CHILD_ARG`]) under a time limit, a memory limit
//! and a large stack, so that a hang, a stack overflow or an impossible allocation inside openusd
//! becomes a [`SceneError`] naming the file instead of taking the whole run down (issue 37: one
//! deleted `>` made openusd loop forever in `Path::parent`; a 26-byte deletion overflowed the stack
//! in its instancing code).
//!
//! Parent: spawns `/bin/sh -c 'ulimit -v <KiB>; exec <voltab> __usd-import-child <path>'` (the
//! shell sets the address-space limit, so no unsafe code is needed), reads the child's reply from
//! its stdout on a thread, and kills the child (by its id) when the time limit passes.
//! Child: imports on a thread with a 512 MiB stack and writes one bincode `Reply` to stdout.
//!
//! Limits: `VOLTAB_USD_TIME_LIMIT` (seconds, default 120), `VOLTAB_USD_MEMORY_LIMIT` (bytes, default
//! 8 GiB of address space). `VOLTAB_USD_GUARD=0` imports in-process (as does any binary other than
//! `voltab`, e.g. unit tests, which have no child subcommand).

use std::io::Read;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use serde::{Deserialize, Serialize};

use crate::scene::{Scene, SceneError};

/// The hidden first argument that makes `voltab` act as the import child.
pub const CHILD_ARG: &str = "__usd-import-child";

/// Stack of the child's import thread: deep but finite recursion in the parser fits. Public so
/// that the fuzz target imports on the same stack as the child does.
pub const CHILD_STACK: usize = 512 << 20;

/// What the child sends back.
#[derive(Serialize, Deserialize)]
enum Reply {
    Scene(Box<Scene>),
    Error { location: Option<String>, message: String, help: String },
}

fn env_u64(name: &str) -> Option<u64> {
    std::env::var(name).ok().and_then(|v| v.trim().parse::<u64>().ok()).filter(|&n| n > 0)
}

/// Time limit of one import.
pub fn time_limit() -> Duration {
    Duration::from_secs(env_u64("VOLTAB_USD_TIME_LIMIT").unwrap_or(120))
}

/// Address-space limit of the child, in bytes.
pub fn memory_limit() -> u64 {
    env_u64("VOLTAB_USD_MEMORY_LIMIT").unwrap_or(8 << 30)
}

/// The binary to run as the child, when guarding applies: the running executable if it is
/// `voltab` itself and `VOLTAB_USD_GUARD` is not `0`.
fn child_exe() -> Option<PathBuf> {
    if std::env::var("VOLTAB_USD_GUARD").is_ok_and(|v| v.trim() == "0") {
        return None;
    }
    let exe = std::env::current_exe().ok()?;
    (exe.file_stem().and_then(|s| s.to_str()) == Some(env!("CARGO_PKG_NAME"))).then_some(exe)
}

/// Imports `path` through a guarded child when possible (module doc), else with `in_process`.
pub fn import(path: &Path, in_process: impl FnOnce(&Path) -> Result<Scene, SceneError>) -> Result<Scene, SceneError> {
    match child_exe() {
        Some(exe) => import_in_child(&exe, path, time_limit(), memory_limit()),
        None => in_process(path),
    }
}

fn crashed(path: &Path, message: String) -> SceneError {
    SceneError::file(
        path,
        message,
        "the file is probably corrupt; re-export the layer with usd-core (e.g. `usdcat in.usda -o out.usda`) \
         and report the file",
    )
}

/// Runs the child and turns its outcome into a result.
pub fn import_in_child(exe: &Path, path: &Path, limit: Duration, memory: u64) -> Result<Scene, SceneError> {
    let script = format!("ulimit -v {} 2>/dev/null; exec \"$0\" {CHILD_ARG} \"$1\"", memory / 1024);
    let mut child = Command::new("/bin/sh")
        .arg("-c")
        .arg(script)
        .arg(exe)
        .arg(path)
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .map_err(|e| crashed(path, format!("cannot start the guarded USD reader: {e}")))?;
    let mut stdout = child.stdout.take().ok_or_else(|| crashed(path, "no pipe to the USD reader".into()))?;
    let mut stderr = child.stderr.take().ok_or_else(|| crashed(path, "no pipe to the USD reader".into()))?;
    let out = std::thread::spawn(move || {
        let mut buf = Vec::new();
        let _ = stdout.read_to_end(&mut buf);
        buf
    });
    let err = std::thread::spawn(move || {
        let mut buf = Vec::new();
        let _ = (&mut stderr).take(64 * 1024).read_to_end(&mut buf);
        let _ = std::io::copy(&mut stderr, &mut std::io::sink());
        buf
    });
    let start = Instant::now();
    let status = loop {
        match child.try_wait() {
            Ok(Some(status)) => break status,
            Ok(None) if start.elapsed() >= limit => {
                let _ = child.kill();
                let _ = child.wait();
                return Err(crashed(
                    path,
                    format!(
                        "the USD reader (openusd) did not finish within {limit:?} and was stopped (raise the \
                         limit with VOLTAB_USD_TIME_LIMIT, in seconds, if the layer is genuinely this slow)"
                    ),
                ));
            }
            Ok(None) => std::thread::sleep(Duration::from_millis(5)),
            Err(e) => return Err(crashed(path, format!("lost the guarded USD reader: {e}"))),
        }
    };
    let bytes = out.join().unwrap_or_default();
    let stderr = err.join().unwrap_or_default();
    let decoded = bincode::serde::decode_from_slice::<Reply, _>(&bytes, bincode::config::standard());
    match decoded {
        Ok((Reply::Scene(scene), _)) if status.success() => Ok(*scene),
        Ok((Reply::Error { location, message, help }, _)) => {
            Err(SceneError { file: path.to_path_buf(), location, message, help })
        }
        _ => {
            let text = String::from_utf8_lossy(&stderr);
            let last = text.lines().rev().find(|l| !l.trim().is_empty()).unwrap_or("").trim();
            let how = match status.code() {
                Some(code) => format!("exited with status {code}"),
                None => "was killed by a signal".to_owned(),
            };
            let what = if text.contains("overflowed its stack") {
                "overflowed its stack".to_owned()
            } else if text.contains("memory allocation") {
                format!("ran out of its {} MiB memory limit (VOLTAB_USD_MEMORY_LIMIT)", memory >> 20)
            } else if last.is_empty() {
                how
            } else {
                format!("{how}: {last}")
            };
            Err(crashed(path, format!("the USD reader (openusd) crashed on this file: it {what}")))
        }
    }
}

/// The child's side: if the process was started as the import child, imports the layer named by
/// the next argument with `in_process`, writes the reply to stdout and returns the exit code.
pub fn child_main(
    args: &[std::ffi::OsString],
    in_process: fn(&Path) -> Result<Scene, SceneError>,
) -> Option<std::process::ExitCode> {
    if args.get(1).is_none_or(|a| a != CHILD_ARG) {
        return None;
    }
    let Some(path) = args.get(2).map(PathBuf::from) else {
        eprintln!("{CHILD_ARG}: missing the layer path");
        return Some(std::process::ExitCode::from(2));
    };
    let worker = std::thread::Builder::new().stack_size(CHILD_STACK).spawn(move || in_process(&path));
    let result = match worker {
        Ok(handle) => handle.join(),
        Err(e) => {
            eprintln!("{CHILD_ARG}: cannot start the import thread: {e}");
            return Some(std::process::ExitCode::from(2));
        }
    };
    let reply = match result {
        Ok(Ok(scene)) => Reply::Scene(Box::new(scene)),
        Ok(Err(e)) => Reply::Error { location: e.location, message: e.message, help: e.help },
        Err(_) => return Some(std::process::ExitCode::from(3)), // panics are caught inside; not reached
    };
    let mut stdout = std::io::stdout().lock();
    match bincode::serde::encode_into_std_write(&reply, &mut stdout, bincode::config::standard()) {
        Ok(_) => Some(std::process::ExitCode::SUCCESS),
        Err(e) => {
            eprintln!("{CHILD_ARG}: cannot send the scene: {e}");
            Some(std::process::ExitCode::from(2))
        }
    }
}

#[cfg(test)]
mod tests;
