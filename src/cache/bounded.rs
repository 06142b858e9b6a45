//! Bounded reads of user-named files: a path and a byte limit → the file's bytes, or an error
//! that says why the file was refused.
//!
//! Invariant: only regular files are opened (a FIFO, `/dev/zero`, `/dev/urandom`, a socket or a
//! directory is refused from its metadata, before `open` could block), and never more than
//! `limit` bytes are read, even from a file that grows while it is read (issue 37).

use std::fs::File;
use std::io::{self, Read};
use std::path::Path;

/// Default largest pipeline or scene side file: 256 MiB (`VOLTAB_MAX_INPUT_BYTES` overrides).
pub const DEFAULT_MAX_INPUT_BYTES: u64 = 256 << 20;

/// The input-size limit: `VOLTAB_MAX_INPUT_BYTES` when it holds a positive whole number, else
/// [`DEFAULT_MAX_INPUT_BYTES`].
pub fn max_input_bytes() -> u64 {
    match std::env::var("VOLTAB_MAX_INPUT_BYTES").ok().and_then(|v| v.trim().parse::<u64>().ok()) {
        Some(n) if n > 0 => n,
        _ => DEFAULT_MAX_INPUT_BYTES,
    }
}

fn refuse(msg: String) -> io::Error {
    io::Error::new(io::ErrorKind::InvalidInput, msg)
}

/// Checks that `path` names a regular file of at most `limit` bytes, without opening it.
pub fn check_regular(path: &Path, limit: u64) -> io::Result<u64> {
    let meta = std::fs::metadata(path)?;
    if meta.is_dir() {
        return Err(refuse("it is a directory, not a file".into()));
    }
    if !meta.is_file() {
        return Err(refuse("it is not a regular file (a device, FIFO or socket), so it has no size to check".into()));
    }
    if meta.len() > limit {
        return Err(refuse(format!(
            "it has {} bytes, above the limit of {limit} bytes (raise it with VOLTAB_MAX_INPUT_BYTES)",
            meta.len()
        )));
    }
    Ok(meta.len())
}

/// Reads a whole regular file of at most `limit` bytes.
pub fn read_regular(path: &Path, limit: u64) -> io::Result<Vec<u8>> {
    read_regular_range(path, 0, None, limit)
}

/// Reads `len` bytes at `offset` of a regular file (to the end when `len` is `None`), reading at
/// most `limit` bytes. Fails if the file is shorter than `offset + len`.
pub fn read_regular_range(path: &Path, offset: u64, len: Option<u64>, limit: u64) -> io::Result<Vec<u8>> {
    use std::io::{Seek, SeekFrom};
    let size = check_regular(path, u64::MAX)?;
    let want = len.unwrap_or(size.saturating_sub(offset));
    if want > limit {
        return Err(refuse(format!(
            "{want} bytes would be read, above the limit of {limit} bytes (raise it with VOLTAB_MAX_INPUT_BYTES)"
        )));
    }
    let mut file = File::open(path)?;
    if !file.metadata()?.is_file() {
        return Err(refuse("it stopped being a regular file while it was opened".into()));
    }
    file.seek(SeekFrom::Start(offset))?;
    let mut buf = Vec::with_capacity(usize::try_from(want).unwrap_or(0));
    file.take(want.saturating_add(u64::from(len.is_none()))).read_to_end(&mut buf)?;
    if (buf.len() as u64) < want {
        return Err(io::Error::new(
            io::ErrorKind::UnexpectedEof,
            format!("the file has {} bytes from offset {offset}, {want} are needed", buf.len()),
        ));
    }
    if buf.len() as u64 > want {
        return Err(refuse("the file grew while it was read".into()));
    }
    Ok(buf)
}

#[cfg(test)]
mod tests;
