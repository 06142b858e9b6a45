//! Compilation as an asset-build step: incremental (content-keyed), deterministic across runs and
//! thread counts, safe under kill -9 and concurrent runs, and never trusting a corrupted output.

mod common;

use std::path::Path;
use std::process::Stdio;
use std::time::Duration;

use common::{tempdir, text, voltab, vtabs, write};
use voltab::compile::{CompileOptions, Status, compile};
use voltab::container::VtabReader;
use voltab::pipeline::Disk;
use voltab::registry::load_and_validate;

const PIPE: &str = "(tables: [
    PhaseHg(id: \"a\", g: [-0.5, 0.0, 0.5], mu_bins: 256, xi_bins: 256),
    PhaseHg(id: \"b\", g: [0.9], mu_bins: 128, xi_bins: 128, element: F64),
    PhaseHg(id: \"c\", g: (min: -0.9, max: 0.9, count: 7), mu_bins: 64, xi_bins: 64),
])";

fn compile_dir(pipeline: &Path, out: &Path, jobs: Option<usize>) -> Vec<(String, Status)> {
    let p = load_and_validate(pipeline, &Disk).unwrap();
    let s = compile(&p, &CompileOptions { out_dir: out.into(), jobs, ..Default::default() }).unwrap();
    s.tables.iter().map(|t| (t.id.clone(), t.status)).collect()
}

fn bytes(dir: &Path) -> Vec<(String, Vec<u8>)> {
    vtabs(dir)
        .into_iter()
        .map(|p| (p.file_name().unwrap().to_string_lossy().into_owned(), std::fs::read(&p).unwrap()))
        .collect()
}

#[test]
fn second_run_is_up_to_date_and_a_change_rebuilds_only_its_table() {
    let d = tempdir();
    let p = write(d.path(), "p.ron", PIPE);
    let out = d.path().join("out");
    let first = compile_dir(&p, &out, None);
    assert!(first.iter().all(|(_, s)| *s == Status::Compiled));
    let second = compile_dir(&p, &out, None);
    assert!(second.iter().all(|(_, s)| *s == Status::UpToDate), "{second:?}");
    // Change b only.
    write(d.path(), "p.ron", &PIPE.replace("mu_bins: 128", "mu_bins: 130"));
    let third = compile_dir(&p, &out, None);
    assert_eq!(third, [("a".into(), Status::UpToDate), ("b".into(), Status::Compiled), ("c".into(), Status::UpToDate)]);
    // Reverting restores the earlier b from the cache without recomputing.
    write(d.path(), "p.ron", PIPE);
    let fourth = compile_dir(&p, &out, None);
    assert_eq!(fourth[1], ("b".into(), Status::Restored));
    // A comment or reformatting does not change any key.
    write(d.path(), "p.ron", &format!("// a comment\n{}", PIPE.replace(", ", ",\n  ")));
    assert!(compile_dir(&p, &out, None).iter().all(|(_, s)| *s == Status::UpToDate));
}

#[test]
fn output_is_byte_identical_across_runs_and_thread_counts() {
    let d = tempdir();
    let p = write(d.path(), "p.ron", PIPE);
    compile_dir(&p, &d.path().join("j1"), Some(1));
    compile_dir(&p, &d.path().join("j2"), Some(2));
    compile_dir(&p, &d.path().join("j2again"), Some(2));
    let a = bytes(&d.path().join("j1"));
    assert_eq!(a.len(), 3);
    assert_eq!(a, bytes(&d.path().join("j2")));
    assert_eq!(a, bytes(&d.path().join("j2again")));
    // Through the binary with RAYON_NUM_THREADS, as a build system would run it.
    for threads in ["1", "2"] {
        let out = d.path().join(format!("env{threads}"));
        let o = voltab()
            .args(["compile", p.to_str().unwrap(), "--out", out.to_str().unwrap()])
            .env("RAYON_NUM_THREADS", threads)
            .output()
            .unwrap();
        assert!(o.status.success(), "{}", text(&o));
        assert_eq!(a, bytes(&out));
    }
}

#[test]
fn a_corrupted_output_is_rebuilt_not_trusted() {
    let d = tempdir();
    let p = write(d.path(), "p.ron", PIPE);
    let out = d.path().join("out");
    compile_dir(&p, &out, None);
    let clean = bytes(&out);
    let a = out.join("a.vtab");
    // Break the link to the cache entry first, then flip a payload byte in place.
    let mut b = std::fs::read(&a).unwrap();
    std::fs::remove_file(&a).unwrap();
    let n = b.len();
    b[n - 20] ^= 0x40;
    std::fs::write(&a, &b).unwrap();
    assert!(VtabReader::open(&a).and_then(|mut r| r.verify()).is_err());
    let again = compile_dir(&p, &out, None);
    assert_ne!(again[0].1, Status::UpToDate, "{again:?}");
    assert_eq!(clean, bytes(&out));
    // Truncated output, and a corrupted cache entry: both rebuilt.
    std::fs::remove_file(&a).unwrap();
    std::fs::write(&a, &clean[0].1[..100]).unwrap();
    for e in std::fs::read_dir(out.join(".voltab-cache")).unwrap().flatten() {
        let mut c = std::fs::read(e.path()).unwrap();
        std::fs::remove_file(e.path()).unwrap();
        let m = c.len() / 2;
        c[m] ^= 1;
        std::fs::write(e.path(), c).unwrap();
    }
    let again = compile_dir(&p, &out, None);
    assert_eq!(again[0].1, Status::Compiled, "{again:?}");
    assert_eq!(clean, bytes(&out));
}

/// A pipeline that takes a noticeable time, so kills land mid-compilation.
const SLOW: &str = "(tables: [
    PhaseHg(id: \"s1\", g: (min: -0.99, max: 0.99, count: 64), mu_bins: 65536, xi_bins: 65536, zstd_level: 15),
    PhaseHg(id: \"s2\", g: (min: -0.95, max: 0.95, count: 64), mu_bins: 65536, xi_bins: 65536, zstd_level: 15),
    PhaseHg(id: \"s3\", g: (min: -0.9, max: 0.9, count: 32), mu_bins: 32768, xi_bins: 32768, element: F64),
])";

fn all_outputs_verify(out: &Path) {
    for f in vtabs(out) {
        VtabReader::open(&f)
            .and_then(|mut r| r.verify())
            .unwrap_or_else(|e| panic!("{} is corrupt after kill: {e}", f.display()));
    }
    for e in std::fs::read_dir(out.join(".voltab-cache")).into_iter().flatten().flatten() {
        if e.path().extension().is_some_and(|x| x == "vtab") {
            VtabReader::open(&e.path())
                .and_then(|mut r| r.verify())
                .unwrap_or_else(|err| panic!("cache {} corrupt: {err}", e.path().display()));
        }
    }
}

#[test]
fn kill_9_at_any_moment_leaves_no_partial_table_and_the_next_run_recovers() {
    let d = tempdir();
    let p = write(d.path(), "slow.ron", SLOW);
    let reference = d.path().join("reference");
    let o = voltab().args(["compile", p.to_str().unwrap(), "--out", reference.to_str().unwrap()]).output().unwrap();
    assert!(o.status.success(), "{}", text(&o));
    let out = d.path().join("out");
    for delay_ms in [30u64, 150, 400, 900, 1600, 2600] {
        let mut child = voltab()
            .args(["compile", p.to_str().unwrap(), "--out", out.to_str().unwrap()])
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .unwrap();
        std::thread::sleep(Duration::from_millis(delay_ms));
        let _ = child.kill(); // SIGKILL
        let _ = child.wait();
        all_outputs_verify(&out);
    }
    let o = voltab().args(["compile", p.to_str().unwrap(), "--out", out.to_str().unwrap()]).output().unwrap();
    assert!(o.status.success(), "{}", text(&o));
    assert_eq!(bytes(&reference), bytes(&out));
    let leftovers: Vec<_> = std::fs::read_dir(&out)
        .unwrap()
        .flatten()
        .filter(|e| e.file_name().to_string_lossy().starts_with(".tmp-"))
        .collect();
    assert!(leftovers.is_empty(), "temporary files left: {leftovers:?}");
}

#[test]
fn concurrent_runs_on_one_folder_do_not_corrupt_each_other() {
    let d = tempdir();
    let p = write(d.path(), "p.ron", PIPE);
    let out = d.path().join("out");
    let spawn = || {
        voltab()
            .args(["compile", p.to_str().unwrap(), "--out", out.to_str().unwrap()])
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap()
    };
    let (a, b) = (spawn(), spawn());
    let (a, b) = (a.wait_with_output().unwrap(), b.wait_with_output().unwrap());
    assert!(a.status.success() && b.status.success(), "{}\n{}", text(&a), text(&b));
    all_outputs_verify(&out);
    let fresh = d.path().join("fresh");
    compile_dir(&p, &fresh, None);
    assert_eq!(bytes(&fresh), bytes(&out));
    // The run that waited found the tables up to date (or compiled them itself; never both half-way).
    let outs = format!("{}{}", text(&a), text(&b));
    assert_eq!(outs.matches("compiled  ").count() + outs.matches("up to date").count(), 6, "{outs}");
}

#[test]
fn unusable_output_folder_is_a_clear_error() {
    let d = tempdir();
    let p = write(d.path(), "p.ron", PIPE);
    let file = write(d.path(), "a-file", "x");
    let o =
        voltab().args(["compile", p.to_str().unwrap(), "--out", file.join("sub").to_str().unwrap()]).output().unwrap();
    assert_eq!(o.status.code(), Some(1));
    let s = text(&o);
    assert!(s.contains("is not usable") && s.contains("--out DIR") && !s.contains("panicked"), "{s}");
}

#[test]
fn only_selects_tables_and_unknown_ids_get_suggestions() {
    let d = tempdir();
    let p = write(d.path(), "p.ron", PIPE);
    let out = d.path().join("out");
    let o = voltab()
        .args(["compile", p.to_str().unwrap(), "--out", out.to_str().unwrap(), "--only", "b"])
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", text(&o));
    assert_eq!(vtabs(&out).len(), 1);
    let o = voltab()
        .args(["compile", p.to_str().unwrap(), "--out", out.to_str().unwrap(), "--only", "bb"])
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(1));
    assert!(text(&o).contains("did you mean `b`?"), "{}", text(&o));
}

#[test]
fn sidecar_reports_run_statistics_outside_the_table() {
    let d = tempdir();
    let p = write(d.path(), "p.ron", PIPE);
    let out = d.path().join("out");
    compile_dir(&p, &out, None);
    let s: serde_json::Value = serde_json::from_slice(&std::fs::read(out.join("a.vtab.json")).unwrap()).unwrap();
    assert_eq!(s["stats"]["nonfinite_discarded"], 0);
    assert_eq!(s["stats"]["samples"], 3 * 65536);
    let headline = &s["stats"]["errors"][0];
    assert_eq!(headline["name"], "phase_lookup_max_rel");
    assert!(s["compression_ratio"].as_f64().unwrap() > 1.0);
    // Timings live in the sidecar; the table file holds none (checked by byte identity above).
    assert!(s["generate_ms"].as_f64().unwrap() > 0.0);
}
