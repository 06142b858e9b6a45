use super::*;

/// The rendered text of every error a user can trigger with a bad file or table.
#[test]
fn messages_render_for_humans() {
    let cases: Vec<(ContainerError, &str)> = vec![
        (ContainerError::BadMagic, "not a .vtab file (bad magic bytes at the start)"),
        (
            ContainerError::NewerMajor { found: (2, 0), supported: (1, 0) },
            "this .vtab file uses format version 2.0, but this build of voltab only reads format 1.x \
             (up to 1.0); upgrade voltab to read it",
        ),
        (
            ContainerError::NewerMinor { found: (1, 3), supported: (1, 0) },
            "this .vtab file uses format version 1.3, newer than the 1.0 this build of voltab supports; \
             upgrade voltab to read it",
        ),
        (
            ContainerError::UnsupportedOld { found: (0, 9), supported: (1, 0) },
            "this .vtab file uses the old format version 0.9, which this build of voltab (format 1.0) \
             no longer reads; recompile the table",
        ),
        (
            ContainerError::Truncated { expected: 1018, found: 1000 },
            "truncated .vtab file: expected 1018 bytes, found 1000",
        ),
        (
            ContainerError::TrailingBytes { extra: 3 },
            "corrupt .vtab file: 3 unexpected trailing bytes after the end marker",
        ),
        (
            ContainerError::HeaderChecksum { stored: 0xDEAD_BEEF, computed: 0x0000_0001 },
            "corrupt .vtab header: checksum mismatch (stored 0xdeadbeef, computed 0x00000001)",
        ),
        (
            ContainerError::ChunkChecksum { array: "phase".into(), slice: 4 },
            "corrupt .vtab file: checksum mismatch in array `phase`, slice 4",
        ),
        (
            ContainerError::NonFinite { array: "phase".into(), index: 17, value: f64::NAN },
            "array `phase` has the non-finite value NaN at element 17",
        ),
        (
            ContainerError::ElementTypeMismatch {
                array: "zh".into(),
                expected: ElementType::F32,
                found: ElementType::F64,
            },
            "array `zh` is declared as f32 but its values are f64",
        ),
        (
            ContainerError::Io {
                path: Some(PathBuf::from("/tmp/x.vtab")),
                source: std::io::Error::new(std::io::ErrorKind::NotFound, "No such file or directory"),
            },
            "I/O error on `/tmp/x.vtab`: No such file or directory",
        ),
    ];
    for (err, text) in cases {
        assert_eq!(err.to_string(), text);
    }
}
