use super::*;

#[test]
fn devices_fifos_and_directories_are_refused_without_blocking() {
    for dev in ["/dev/zero", "/dev/urandom", "/dev/null"] {
        let e = read_regular(Path::new(dev), 1 << 20).expect_err(dev);
        assert!(e.to_string().contains("not a regular file"), "{dev}: {e}");
    }
    let dir = tempfile::tempdir().expect("tempdir");
    let e = read_regular(dir.path(), 1 << 20).expect_err("directory");
    assert!(e.to_string().contains("directory"), "{e}");
    let fifo = dir.path().join("fifo");
    let made = std::process::Command::new("mkfifo").arg(&fifo).status().is_ok_and(|s| s.success());
    if made {
        // Opening a FIFO for reading would block until a writer appears: must not be opened.
        let e = read_regular(&fifo, 1 << 20).expect_err("fifo");
        assert!(e.to_string().contains("not a regular file"), "{e}");
    }
}

#[test]
fn reads_are_bounded_by_the_limit_and_the_declared_length() {
    let dir = tempfile::tempdir().expect("tempdir");
    let p = dir.path().join("f.bin");
    std::fs::write(&p, [7u8; 100]).expect("write");
    assert_eq!(read_regular(&p, 100).expect("at the limit").len(), 100);
    let e = read_regular(&p, 99).expect_err("over the limit");
    assert!(e.to_string().contains("above the limit of 99"), "{e}");
    assert_eq!(read_regular_range(&p, 10, Some(20), 20).expect("range"), vec![7u8; 20]);
    let e = read_regular_range(&p, 90, Some(20), 1000).expect_err("past the end");
    assert_eq!(e.kind(), io::ErrorKind::UnexpectedEof, "{e}");
}
