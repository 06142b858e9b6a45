//! Reader: a `.vtab` file (path or bytes) → its header, chunk index and, on
//! demand, the decoded values of single slices or whole arrays.
//!
//! Invariant: a [`VtabReader`] only exists for input whose preamble, version,
//! meta checksum, header rules, chunk index, total length and end marker all
//! check out; every value it returns comes from a chunk whose CRC, decompressed
//! length and finiteness were verified. Malformed bytes of any kind yield a
//! [`ContainerError`]; lengths are checked before anything is allocated.

use std::borrow::Cow;
use std::fs::File;
use std::io::{Read, Seek, SeekFrom};
use std::path::{Path, PathBuf};

use super::error::ContainerError;
use super::format::{
    ArrayValues, ChunkEntry, END_MAGIC, ElementType, Header, PREAMBLE_LEN, Transform, decode_meta, parse_preamble,
};
use super::transform::{bytes_f32, bytes_f64, undelta, unshuffle};

/// Largest capacity reserved up front for one decompressed chunk; larger
/// chunks grow as real data arrives, so a forged length cannot force a huge allocation.
const MAX_RESERVE: u64 = 16 * 1024 * 1024;

/// Default largest decoded (and stored) size of one chunk: 256 MiB. The biggest slice any table
/// kind writes is far below it; a file declaring more is refused on open, before any of it is
/// read, so a small zstd bomb with an honest header cannot make the reader allocate gigabytes.
pub const DEFAULT_MAX_CHUNK_BYTES: u64 = 256 << 20;

/// Resource limits of a [`VtabReader`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ReadLimits {
    /// Largest raw or stored length of one chunk, in bytes. Reading a slice needs at most about
    /// three times this much memory (decompressed bytes, undone transform, decoded values).
    pub max_chunk_bytes: u64,
}

impl Default for ReadLimits {
    fn default() -> Self {
        Self { max_chunk_bytes: DEFAULT_MAX_CHUNK_BYTES }
    }
}

impl ReadLimits {
    /// The default limits, or `VOLTAB_MAX_CHUNK_BYTES` bytes per chunk when that variable holds a
    /// positive whole number.
    pub fn from_env() -> Self {
        let env = std::env::var("VOLTAB_MAX_CHUNK_BYTES").ok().and_then(|v| v.trim().parse::<u64>().ok());
        match env {
            Some(n) if n > 0 => Self { max_chunk_bytes: n },
            _ => Self::default(),
        }
    }
}

#[derive(Debug)]
enum Source {
    File { file: File, path: PathBuf },
    Bytes(Vec<u8>),
}

impl Source {
    fn path(&self) -> Option<&Path> {
        match self {
            Source::File { path, .. } => Some(path),
            Source::Bytes(_) => None,
        }
    }

    fn total_len(&self) -> Result<u64, ContainerError> {
        match self {
            Source::File { file, path } => {
                file.metadata().map(|m| m.len()).map_err(|e| ContainerError::io(Some(path), e))
            }
            Source::Bytes(b) => Ok(b.len() as u64),
        }
    }

    /// Reads `len` bytes at `offset`; the caller has checked the range against `total_len`.
    fn read_at(&mut self, offset: u64, len: u64) -> Result<Cow<'_, [u8]>, ContainerError> {
        let end = offset.checked_add(len);
        match self {
            Source::Bytes(b) => {
                let range = usize::try_from(offset).ok().zip(end.and_then(|e| usize::try_from(e).ok()));
                range
                    .and_then(|(s, e)| b.get(s..e))
                    .map(Cow::Borrowed)
                    .ok_or(ContainerError::Truncated { expected: end.unwrap_or(u64::MAX), found: b.len() as u64 })
            }
            Source::File { file, path } => {
                let n = usize::try_from(len)
                    .map_err(|_| ContainerError::Truncated { expected: end.unwrap_or(u64::MAX), found: 0 })?;
                let mut buf = vec![0u8; n];
                file.seek(SeekFrom::Start(offset))
                    .and_then(|_| file.read_exact(&mut buf))
                    .map_err(|e| ContainerError::io(Some(path), e))?;
                Ok(Cow::Owned(buf))
            }
        }
    }
}

/// Opens `path` for reading if it is a regular file. A FIFO or device has no length to check
/// against the header: it is refused instead of blocking or being read forever.
fn open_regular(path: &Path) -> Result<File, ContainerError> {
    // Checked before opening too: opening a FIFO for reading blocks until a writer appears.
    crate::cache::bounded::check_regular(path, u64::MAX).map_err(|e| ContainerError::io(Some(path), e))?;
    let file = File::open(path).map_err(|e| ContainerError::io(Some(path), e))?;
    let meta = file.metadata().map_err(|e| ContainerError::io(Some(path), e))?;
    if !meta.is_file() {
        let e = std::io::Error::new(std::io::ErrorKind::InvalidInput, "not a regular file");
        return Err(ContainerError::io(Some(path), e));
    }
    Ok(file)
}

/// Parsed front matter: header, index, version and where the payload lies.
struct Front {
    header: Header,
    chunks: Vec<ChunkEntry>,
    version: (u16, u16),
    payload_start: u64,
    payload_len: u64,
}

fn read_front(source: &mut Source, total: u64) -> Result<Front, ContainerError> {
    let pre = source.read_at(0, total.min(PREAMBLE_LEN))?;
    let pre = parse_preamble(&pre)?;
    let payload_start = PREAMBLE_LEN + pre.meta_len; // meta_len ≤ MAX_META_LEN: no overflow
    if total < payload_start {
        let expected = payload_start + END_MAGIC.len() as u64;
        return Err(ContainerError::Truncated { expected, found: total });
    }
    let meta = source.read_at(PREAMBLE_LEN, pre.meta_len)?;
    let (header, chunks, payload_len) = decode_meta(&pre, &meta)?;
    Ok(Front { header, chunks, version: pre.version, payload_start, payload_len })
}

/// Summary of a successful [`VtabReader::verify`].
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct VerifyReport {
    /// Number of arrays.
    pub arrays: usize,
    /// Number of chunks checked.
    pub chunks: u64,
    /// Bytes of all decoded elements.
    pub raw_bytes: u64,
    /// Bytes of all stored chunks.
    pub stored_bytes: u64,
}

impl std::fmt::Display for VerifyReport {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "{} arrays, {} chunks, {} bytes raw in {} stored",
            self.arrays, self.chunks, self.raw_bytes, self.stored_bytes
        )
    }
}

/// Random-access reader of one `.vtab` file.
#[derive(Debug)]
pub struct VtabReader {
    source: Source,
    header: Header,
    chunks: Vec<ChunkEntry>,
    /// Index into `chunks` of each array's first slice.
    first_chunk: Vec<usize>,
    version: (u16, u16),
    payload_start: u64,
    payload_len: u64,
}

/// Reads only the preamble and header of a `.vtab` file (no length or payload checks).
pub fn read_header(path: &Path) -> Result<(Header, (u16, u16)), ContainerError> {
    let file = open_regular(path)?;
    let mut source = Source::File { file, path: path.to_path_buf() };
    let total = source.total_len()?;
    let front = read_front(&mut source, total)?;
    Ok((front.header, front.version))
}

impl VtabReader {
    /// Opens a file, reading only its preamble, header and end marker, with
    /// [`ReadLimits::from_env`].
    pub fn open(path: &Path) -> Result<Self, ContainerError> {
        Self::open_with_limits(path, ReadLimits::from_env())
    }

    /// [`Self::open`] with explicit limits.
    pub fn open_with_limits(path: &Path, limits: ReadLimits) -> Result<Self, ContainerError> {
        let file = open_regular(path)?;
        Self::init(Source::File { file, path: path.to_path_buf() }, limits)
    }

    /// Reads a `.vtab` file held in memory, with [`ReadLimits::from_env`].
    pub fn from_bytes(bytes: Vec<u8>) -> Result<Self, ContainerError> {
        Self::from_bytes_with_limits(bytes, ReadLimits::from_env())
    }

    /// [`Self::from_bytes`] with explicit limits.
    pub fn from_bytes_with_limits(bytes: Vec<u8>, limits: ReadLimits) -> Result<Self, ContainerError> {
        Self::init(Source::Bytes(bytes), limits)
    }

    fn init(mut source: Source, limits: ReadLimits) -> Result<Self, ContainerError> {
        let total = source.total_len()?;
        let front = read_front(&mut source, total)?;
        let expected = front
            .payload_start
            .checked_add(front.payload_len)
            .and_then(|n| n.checked_add(END_MAGIC.len() as u64))
            .ok_or_else(|| ContainerError::InvalidHeader("payload length overflows".into()))?;
        if total < expected {
            return Err(ContainerError::Truncated { expected, found: total });
        }
        if total > expected {
            return Err(ContainerError::TrailingBytes { extra: total - expected });
        }
        // validate_index proved the entries are array-major and match the header's arrays.
        if let Some(c) = front.chunks.iter().find(|c| c.raw_len.max(c.stored_len) > limits.max_chunk_bytes) {
            let array = front.header.arrays.get(c.array as usize).map_or_else(String::new, |d| d.name.clone());
            return Err(ContainerError::ChunkTooLarge {
                array,
                slice: c.slice,
                len: c.raw_len.max(c.stored_len),
                limit: limits.max_chunk_bytes,
            });
        }
        let mut first_chunk = Vec::with_capacity(front.header.arrays.len());
        let mut next = 0usize;
        for desc in &front.header.arrays {
            first_chunk.push(next);
            // validate_index proved the slice counts sum to chunks.len().
            next = next.saturating_add(usize::try_from(desc.slice_count()).unwrap_or(usize::MAX));
        }
        let mut reader = VtabReader {
            source,
            header: front.header,
            chunks: front.chunks,
            first_chunk,
            version: front.version,
            payload_start: front.payload_start,
            payload_len: front.payload_len,
        };
        reader.check_end_magic()?;
        Ok(reader)
    }

    fn check_end_magic(&mut self) -> Result<(), ContainerError> {
        let at = self.payload_start + self.payload_len; // checked in init
        let tail = self.source.read_at(at, END_MAGIC.len() as u64)?;
        if *tail != END_MAGIC { Err(ContainerError::BadEndMagic) } else { Ok(()) }
    }

    /// The table header.
    pub fn header(&self) -> &Header {
        &self.header
    }

    /// Format version `(major, minor)` found in the file.
    pub fn version(&self) -> (u16, u16) {
        self.version
    }

    /// The chunk index, array-major and slice-ascending.
    pub fn chunks(&self) -> &[ChunkEntry] {
        &self.chunks
    }

    /// Index of the array called `name`, if any.
    pub fn find_array(&self, name: &str) -> Option<usize> {
        self.header.arrays.iter().position(|a| a.name == name)
    }

    /// Reads, checks and decodes one slice (one index of the outermost axis) of an array.
    pub fn read_slice(&mut self, array: usize, slice: u64) -> Result<ArrayValues, ContainerError> {
        let count = self.header.arrays.len();
        let desc = self.header.arrays.get(array).ok_or(ContainerError::NoSuchArray { index: array, count })?;
        let name = || desc.name.clone();
        if slice >= desc.slice_count() {
            return Err(ContainerError::NoSuchSlice { array: name(), slice, count: desc.slice_count() });
        }
        let entry = usize::try_from(slice)
            .ok()
            .and_then(|s| self.first_chunk.get(array).and_then(|f| f.checked_add(s)))
            .and_then(|i| self.chunks.get(i))
            .ok_or_else(|| ContainerError::InvalidHeader(format!("no index entry for {array}/{slice}")))?;
        let offset = self
            .payload_start
            .checked_add(entry.offset)
            .ok_or_else(|| ContainerError::InvalidHeader("chunk offset overflows".into()))?;
        let stored = self.source.read_at(offset, entry.stored_len)?;
        if crc32fast::hash(&stored) != entry.crc32 {
            return Err(ContainerError::ChunkChecksum { array: name(), slice });
        }
        let raw =
            match entry.transform {
                Transform::None => stored.into_owned(),
                Transform::Shuffle | Transform::DeltaShuffle => {
                    let decompressed = decompress(&stored, entry.raw_len).map_err(|e| {
                        ContainerError::ChunkDecompress { array: name(), slice, message: e.to_string() }
                    })?;
                    if decompressed.len() as u64 != entry.raw_len {
                        return Err(ContainerError::ChunkLength {
                            array: name(),
                            slice,
                            expected: entry.raw_len,
                            found: decompressed.len() as u64,
                        });
                    }
                    let plain = unshuffle(&decompressed, desc.element);
                    if entry.transform == Transform::DeltaShuffle {
                        let row_len = usize::try_from(desc.row_len()).unwrap_or(usize::MAX);
                        undelta(&plain, desc.element, row_len)
                    } else {
                        plain
                    }
                }
            };
        let values = match desc.element {
            ElementType::F32 => ArrayValues::F32(bytes_f32(&raw)),
            ElementType::F64 => ArrayValues::F64(bytes_f64(&raw)),
        };
        // Checked in place: a copy to f64 would double the memory of a large f32 chunk.
        let bad = match &values {
            ArrayValues::F32(v) => v.iter().position(|x| !x.is_finite()).map(|i| (i, f64::from(v[i]))),
            ArrayValues::F64(v) => v.iter().position(|x| !x.is_finite()).map(|i| (i, v[i])),
        };
        if let Some((i, value)) = bad {
            let base = slice.saturating_mul(desc.slice_len().unwrap_or(0));
            return Err(ContainerError::NonFinite { array: name(), index: base.saturating_add(i as u64), value });
        }
        Ok(values)
    }

    /// Reads and decodes a whole array (all slices, in order).
    pub fn read_array(&mut self, array: usize) -> Result<ArrayValues, ContainerError> {
        let count = self.header.arrays.len();
        let desc = self.header.arrays.get(array).ok_or(ContainerError::NoSuchArray { index: array, count })?;
        let slices = desc.slice_count();
        let mut out = match desc.element {
            ElementType::F32 => ArrayValues::F32(Vec::new()),
            ElementType::F64 => ArrayValues::F64(Vec::new()),
        };
        for slice in 0..slices {
            match (&mut out, self.read_slice(array, slice)?) {
                (ArrayValues::F32(all), ArrayValues::F32(part)) => all.extend(part),
                (ArrayValues::F64(all), ArrayValues::F64(part)) => all.extend(part),
                _ => {
                    return Err(ContainerError::InvalidHeader("element type changed between slices".into()));
                }
            }
        }
        Ok(out)
    }

    /// Checks every chunk (CRC, decompression, length, finite values), the
    /// file length and the end marker.
    pub fn verify(&mut self) -> Result<VerifyReport, ContainerError> {
        let expected = self.payload_start + self.payload_len + END_MAGIC.len() as u64; // checked in init
        let total = self.source.total_len()?;
        if total < expected {
            return Err(ContainerError::Truncated { expected, found: total });
        }
        if total > expected {
            return Err(ContainerError::TrailingBytes { extra: total - expected });
        }
        for array in 0..self.header.arrays.len() {
            for slice in 0..self.header.arrays.get(array).map_or(0, |d| d.slice_count()) {
                self.read_slice(array, slice)?;
            }
        }
        self.check_end_magic()?;
        Ok(VerifyReport {
            arrays: self.header.arrays.len(),
            chunks: self.chunks.len() as u64,
            raw_bytes: self.chunks.iter().fold(0u64, |acc, c| acc.saturating_add(c.raw_len)),
            stored_bytes: self.payload_len,
        })
    }

    /// The path this reader was opened from, if any.
    pub fn path(&self) -> Option<&Path> {
        self.source.path()
    }
}

/// Decompresses one zstd chunk, stopping one byte past `raw_len` so a forged
/// or corrupt stream cannot grow the output beyond what the index promises.
fn decompress(stored: &[u8], raw_len: u64) -> std::io::Result<Vec<u8>> {
    let decoder = zstd::stream::read::Decoder::with_buffer(stored)?;
    let mut out = Vec::with_capacity(usize::try_from(raw_len.min(MAX_RESERVE)).unwrap_or(0));
    decoder.take(raw_len.saturating_add(1)).read_to_end(&mut out)?;
    Ok(out)
}

#[cfg(test)]
mod tests;
