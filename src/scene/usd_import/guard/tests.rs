use super::*;

/// A stand-in for the child: a shell script doing `body`.
fn fake_child(dir: &Path, body: &str) -> PathBuf {
    use std::os::unix::fs::PermissionsExt;
    let p = dir.join("fake-voltab");
    std::fs::write(&p, format!("#!/bin/sh\n{body}\n")).expect("write");
    std::fs::set_permissions(&p, std::fs::Permissions::from_mode(0o755)).expect("chmod");
    p
}

fn run(body: &str, limit: Duration) -> (String, Duration) {
    let dir = tempfile::tempdir().expect("tempdir");
    let exe = fake_child(dir.path(), body);
    let t = Instant::now();
    let e = import_in_child(&exe, Path::new("scenes/broken.usda"), limit, 1 << 30).expect_err("no scene");
    (e.to_string(), t.elapsed())
}

/// Issue 37: a hang inside openusd (`Path::parent` looping) hung the whole run.
#[test]
fn a_hanging_reader_is_stopped_at_the_time_limit() {
    let (e, took) = run("exec sleep 30", Duration::from_millis(500));
    assert!(e.starts_with("scenes/broken.usda: the USD reader (openusd) did not finish within 500ms"), "{e}");
    assert!(took < Duration::from_secs(5), "{took:?}");
}

/// Issue 37: a stack overflow in openusd's instancing code aborted the process (SIGABRT).
#[test]
fn a_stack_overflow_or_signal_is_reported_naming_the_file() {
    let (e, _) = run("echo \"thread 'x' has overflowed its stack\" >&2; kill -ABRT $$", Duration::from_secs(10));
    assert!(
        e.starts_with("scenes/broken.usda: the USD reader (openusd) crashed on this file: it overflowed its stack"),
        "{e}"
    );
    let (e, _) = run("kill -SEGV $$", Duration::from_secs(10));
    assert!(e.contains("crashed on this file: it was killed by a signal"), "{e}");
    let (e, _) = run("echo 'memory allocation of 99999 bytes failed' >&2; exit 134", Duration::from_secs(10));
    assert!(e.contains("ran out of its 1024 MiB memory limit"), "{e}");
}

/// An importer error travels back with its location and hint; garbage on the pipe is a crash.
#[test]
fn replies_are_decoded_and_garbage_is_refused() {
    let (e, _) = run("echo garbage", Duration::from_secs(10));
    assert!(e.contains("crashed on this file: it exited with status 0"), "{e}");
    let reply = Reply::Error { location: Some("/World/Mesh".into()), message: "bad mesh".into(), help: "fix".into() };
    let bytes = bincode::serde::encode_to_vec(&reply, bincode::config::standard()).expect("encode");
    let dir = tempfile::tempdir().expect("tempdir");
    let wire = dir.path().join("reply.bin");
    std::fs::write(&wire, bytes).expect("write");
    let exe = fake_child(dir.path(), &format!("cat '{}'", wire.display()));
    let e = import_in_child(&exe, Path::new("a.usda"), Duration::from_secs(10), 1 << 30).expect_err("error reply");
    assert_eq!((e.location.as_deref(), e.message.as_str(), e.help.as_str()), (Some("/World/Mesh"), "bad mesh", "fix"));
}
