//! On-disk vocabulary of the `.vtab` container: header/axis/chunk-index types
//! and the fixed preamble layout → the exact bytes and rules both the writer
//! and the reader follow.
//!
//! Layout (all integers little-endian, nothing is a raw struct dump):
//! `MAGIC[8] | major u16 | minor u16 | meta_len u64 | meta_crc32 u32 |
//! meta (bincode of (Header, Vec<ChunkEntry>)) | chunk payloads | END_MAGIC[8]`.
//! `meta_crc32` covers the `major`, `minor` and `meta_len` fields plus the meta
//! bytes, so a flipped version or length bit is caught like any other.
//!
//! Invariant established here: the preamble is parsed only after the magic
//! matched, the version is one this build reads and the meta length is below
//! [`MAX_META_LEN`]; meta bytes are decoded only after their checksum matched
//! and with a bincode allocation limit, and are handed on only after
//! `validate_header` and `validate_index` accepted them.

use serde::{Deserialize, Serialize};

use super::error::ContainerError;
use super::validate::{validate_header, validate_index};

/// Magic bytes every `.vtab` file starts with.
pub const MAGIC: [u8; 8] = *b"VTAB\x00\r\n\x1a";
/// Marker every `.vtab` file ends with.
pub const END_MAGIC: [u8; 8] = *b"VTABEND\x00";
/// Major format version written by this build; readers reject other majors.
pub const FORMAT_MAJOR: u16 = 1;
/// Minor format version written by this build; readers accept minors ≤ this.
pub const FORMAT_MINOR: u16 = 0;
/// Length of the fixed preamble before the meta bytes.
pub const PREAMBLE_LEN: u64 = 24;
/// Largest metadata block a reader accepts (64 MiB).
pub const MAX_META_LEN: u64 = 64 * 1024 * 1024;

/// bincode configuration used for the meta block (fixed-width little-endian ints).
pub(crate) fn bincode_config() -> impl bincode::config::Config {
    bincode::config::standard().with_fixed_int_encoding().with_little_endian()
}

/// Decodes the metadata block (untrusted bytes) with the encoding of [`bincode_config`] and a limit
/// on the bytes bincode may claim: a string or vector is allocated at its declared length before
/// its bytes are read, so the limit is the block's own length rounded up to a power of two (at
/// least 4 KiB, at most [`MAX_META_LEN`]). A genuine block claims exactly its length (fixed-size
/// integers, no `char`s), so it always fits; a forged length costs at most twice the block instead
/// of 64 MiB (found by the fuzz target's heap check: 6.7 MB for a 2 KB file).
fn decode_meta_block<T: serde::de::DeserializeOwned>(
    reader: &mut TrackedSlice<'_>,
) -> Result<T, bincode::error::DecodeError> {
    fn with<T: serde::de::DeserializeOwned, const L: usize>(
        r: &mut TrackedSlice<'_>,
    ) -> Result<T, bincode::error::DecodeError> {
        let config = bincode::config::standard().with_fixed_int_encoding().with_little_endian().with_limit::<L>();
        bincode::serde::decode_from_reader(r, config)
    }
    const _: () = assert!(MAX_META_LEN == 1 << 26);
    match reader.bytes.len().next_power_of_two().trailing_zeros() {
        0..=12 => with::<T, { 1 << 12 }>(reader),
        13 => with::<T, { 1 << 13 }>(reader),
        14 => with::<T, { 1 << 14 }>(reader),
        15 => with::<T, { 1 << 15 }>(reader),
        16 => with::<T, { 1 << 16 }>(reader),
        17 => with::<T, { 1 << 17 }>(reader),
        18 => with::<T, { 1 << 18 }>(reader),
        19 => with::<T, { 1 << 19 }>(reader),
        20 => with::<T, { 1 << 20 }>(reader),
        21 => with::<T, { 1 << 21 }>(reader),
        22 => with::<T, { 1 << 22 }>(reader),
        23 => with::<T, { 1 << 23 }>(reader),
        24 => with::<T, { 1 << 24 }>(reader),
        25 => with::<T, { 1 << 25 }>(reader),
        _ => with::<T, { MAX_META_LEN as usize }>(reader),
    }
}

/// How the sample positions of an [`Axis`] are laid out.
#[derive(Serialize, Deserialize, Clone, Copy, Debug, PartialEq, Eq)]
pub enum Spacing {
    /// Evenly spaced from `min` to `max`.
    Linear,
    /// Geometrically spaced from `min` to `max` (both > 0).
    Log,
    /// Positions listed explicitly in `values`.
    Explicit,
}

/// One axis of a table: a name, a unit and `len` sample positions.
#[derive(Serialize, Deserialize, Clone, Debug, PartialEq)]
pub struct Axis {
    /// Axis name (e.g. `"wavelength"`).
    pub name: String,
    /// Unit of the sample positions (e.g. `"nm"`).
    pub unit: String,
    /// How positions are laid out.
    pub spacing: Spacing,
    /// First position (for `Explicit`, the first listed value).
    pub min: f64,
    /// Last position (for `Explicit`, the last listed value).
    pub max: f64,
    /// Number of samples (≥ 1).
    pub len: u64,
    /// Explicit positions; non-empty only for [`Spacing::Explicit`].
    pub values: Vec<f64>,
}

impl Axis {
    /// A linearly spaced axis of `len` samples from `min` to `max`.
    pub fn linear(name: impl Into<String>, unit: impl Into<String>, min: f64, max: f64, len: u64) -> Self {
        Axis { name: name.into(), unit: unit.into(), spacing: Spacing::Linear, min, max, len, values: Vec::new() }
    }

    /// A geometrically spaced axis of `len` samples from `min` to `max` (both > 0).
    pub fn log(name: impl Into<String>, unit: impl Into<String>, min: f64, max: f64, len: u64) -> Self {
        Axis { name: name.into(), unit: unit.into(), spacing: Spacing::Log, min, max, len, values: Vec::new() }
    }

    /// An axis with explicitly listed sample positions.
    pub fn explicit(name: impl Into<String>, unit: impl Into<String>, values: Vec<f64>) -> Self {
        let min = values.first().copied().unwrap_or(0.0);
        let max = values.last().copied().unwrap_or(0.0);
        Axis {
            name: name.into(),
            unit: unit.into(),
            spacing: Spacing::Explicit,
            min,
            max,
            len: values.len() as u64,
            values,
        }
    }

    /// Position of sample `i`; the ends are exactly `min` and `max`.
    /// Returns NaN when `i >= len`.
    pub fn value(&self, i: u64) -> f64 {
        if i >= self.len {
            return f64::NAN;
        }
        match self.spacing {
            Spacing::Explicit => usize::try_from(i).ok().and_then(|i| self.values.get(i).copied()).unwrap_or(f64::NAN),
            _ if i == 0 => self.min,
            _ if i == self.len - 1 => self.max,
            Spacing::Linear => {
                let t = i as f64 / (self.len - 1) as f64;
                self.min * (1.0 - t) + self.max * t
            }
            Spacing::Log => {
                let t = i as f64 / (self.len - 1) as f64;
                self.min * (self.max / self.min).powf(t)
            }
        }
    }

    /// All sample positions, in order.
    pub fn values_vec(&self) -> Vec<f64> {
        match self.spacing {
            Spacing::Explicit => self.values.clone(),
            _ => (0..self.len).map(|i| self.value(i)).collect(),
        }
    }
}

/// Element type of an array.
#[derive(Serialize, Deserialize, Clone, Copy, Debug, PartialEq, Eq)]
pub enum ElementType {
    /// IEEE-754 binary32.
    F32,
    /// IEEE-754 binary64.
    F64,
}

impl ElementType {
    /// Size of one element in bytes.
    pub fn size_bytes(self) -> u64 {
        match self {
            ElementType::F32 => 4,
            ElementType::F64 => 8,
        }
    }

    /// Number of explicit mantissa bits of the type (23 or 52).
    pub fn mantissa_bits(self) -> u8 {
        match self {
            ElementType::F32 => 23,
            ElementType::F64 => 52,
        }
    }
}

impl std::fmt::Display for ElementType {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            ElementType::F32 => "f32",
            ElementType::F64 => "f64",
        })
    }
}

/// Lossy mantissa rounding applied before encoding.
#[derive(Serialize, Deserialize, Clone, Debug, PartialEq)]
pub struct Quantization {
    /// Explicit mantissa bits kept (1..=23 for f32, 1..=52 for f64).
    pub mantissa_bits: u8,
    /// Guaranteed bound on |decoded − input| / |input|: `2^-(mantissa_bits+1)`.
    pub max_rel_error: f64,
}

impl Quantization {
    /// Quantization keeping `mantissa_bits` bits, with the matching error bound.
    pub fn new(mantissa_bits: u8) -> Self {
        Quantization { mantissa_bits, max_rel_error: (-(f64::from(mantissa_bits) + 1.0)).exp2() }
    }
}

/// Description of one named n-dimensional array.
#[derive(Serialize, Deserialize, Clone, Debug, PartialEq)]
pub struct ArrayDesc {
    /// Unique array name.
    pub name: String,
    /// Human description.
    pub description: String,
    /// Unit of the values.
    pub unit: String,
    /// Element type.
    pub element: ElementType,
    /// Axes, outermost first; `axes[0]` is the chunk (slice) axis.
    pub axes: Vec<Axis>,
    /// Lossy quantization applied when encoding, if any.
    pub quantization: Option<Quantization>,
}

impl ArrayDesc {
    /// Axis lengths, outermost first.
    pub fn shape(&self) -> Vec<u64> {
        self.axes.iter().map(|a| a.len).collect()
    }

    /// Number of slices (= chunks) — the length of the outermost axis.
    pub fn slice_count(&self) -> u64 {
        self.axes.first().map_or(0, |a| a.len)
    }

    /// Elements per slice (product of all but the outermost axis), or `None` on overflow.
    pub fn slice_len(&self) -> Option<u64> {
        self.axes.iter().skip(1).try_fold(1u64, |acc, a| acc.checked_mul(a.len))
    }

    /// Total element count, or `None` on overflow.
    pub fn element_count(&self) -> Option<u64> {
        self.slice_len()?.checked_mul(self.slice_count())
    }

    /// Length of one innermost row inside a slice (1 for a 1-D array).
    pub fn row_len(&self) -> u64 {
        if self.axes.len() > 1 { self.axes.last().map_or(1, |a| a.len) } else { 1 }
    }
}

/// The table-level header of a `.vtab` file.
#[derive(Serialize, Deserialize, Clone, Debug, PartialEq)]
pub struct Header {
    /// Table kind identifier.
    pub kind: String,
    /// Schema version of that kind.
    pub kind_schema_version: u32,
    /// Version of the generator that compiled the table.
    pub generator_version: String,
    /// The table definition, as RON text.
    pub definition_ron: String,
    /// Content-addressing key of the definition.
    pub content_key: [u8; 32],
    /// The arrays stored in the file, in payload order.
    pub arrays: Vec<ArrayDesc>,
}

/// Reversible byte transform applied to a chunk before storage.
#[derive(Serialize, Deserialize, Clone, Copy, Debug, PartialEq, Eq)]
pub enum Transform {
    /// Stored verbatim: raw little-endian elements, not compressed
    /// (`stored_len == raw_len`); used when compression would not shrink the chunk.
    None,
    /// Byte-plane transposition, then zstd.
    Shuffle,
    /// Wrapping bit-pattern delta along the innermost row, then shuffle, then zstd.
    DeltaShuffle,
}

/// Index entry locating one chunk (one slice of one array) in the payload.
#[derive(Serialize, Deserialize, Clone, Debug, PartialEq)]
pub struct ChunkEntry {
    /// Index into [`Header::arrays`].
    pub array: u32,
    /// Index along the array's outermost axis.
    pub slice: u64,
    /// Byte offset from the start of the payload.
    pub offset: u64,
    /// Bytes stored in the file.
    pub stored_len: u64,
    /// Bytes of the decoded little-endian elements.
    pub raw_len: u64,
    /// Transform to undo after decompression.
    pub transform: Transform,
    /// CRC-32 of the stored bytes.
    pub crc32: u32,
}

/// Values of one array, flat in row-major order.
#[derive(Serialize, Deserialize, Clone, Debug, PartialEq)]
pub enum ArrayValues {
    /// binary32 values.
    F32(Vec<f32>),
    /// binary64 values.
    F64(Vec<f64>),
}

impl ArrayValues {
    /// Number of elements.
    pub fn len(&self) -> usize {
        match self {
            ArrayValues::F32(v) => v.len(),
            ArrayValues::F64(v) => v.len(),
        }
    }

    /// True when there are no elements.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The values widened to f64.
    pub fn to_f64(&self) -> Vec<f64> {
        match self {
            ArrayValues::F32(v) => v.iter().map(|&x| f64::from(x)).collect(),
            ArrayValues::F64(v) => v.clone(),
        }
    }

    /// Element type of the values.
    pub fn element_type(&self) -> ElementType {
        match self {
            ArrayValues::F32(_) => ElementType::F32,
            ArrayValues::F64(_) => ElementType::F64,
        }
    }
}

/// Encodes the 24-byte preamble for a meta block of `meta` bytes.
pub(crate) fn encode_preamble(meta: &[u8]) -> Vec<u8> {
    let mut out = Vec::with_capacity(PREAMBLE_LEN as usize);
    out.extend_from_slice(&MAGIC);
    out.extend_from_slice(&FORMAT_MAJOR.to_le_bytes());
    out.extend_from_slice(&FORMAT_MINOR.to_le_bytes());
    out.extend_from_slice(&(meta.len() as u64).to_le_bytes());
    out.extend_from_slice(&meta_crc(FORMAT_MAJOR, FORMAT_MINOR, meta).to_le_bytes());
    out
}

/// The meta checksum: CRC-32 over `major`, `minor`, `meta_len` (LE) and the meta bytes.
pub(crate) fn meta_crc(major: u16, minor: u16, meta: &[u8]) -> u32 {
    let mut h = crc32fast::Hasher::new();
    h.update(&major.to_le_bytes());
    h.update(&minor.to_le_bytes());
    h.update(&(meta.len() as u64).to_le_bytes());
    h.update(meta);
    h.finalize()
}

/// Fields of a parsed preamble.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Preamble {
    pub version: (u16, u16),
    pub meta_len: u64,
    pub meta_crc: u32,
}

/// Parses and checks the fixed preamble: magic, version policy, meta length limit.
/// `bytes` may be shorter than the preamble (→ `BadMagic` or `Truncated`).
pub(crate) fn parse_preamble(bytes: &[u8]) -> Result<Preamble, ContainerError> {
    let magic_seen = bytes.get(..MAGIC.len()).unwrap_or(bytes);
    if !MAGIC.starts_with(magic_seen) {
        return Err(ContainerError::BadMagic);
    }
    let too_short = || ContainerError::Truncated { expected: PREAMBLE_LEN, found: bytes.len() as u64 };
    let field = |at: usize, n: usize| bytes.get(at..at + n).ok_or_else(too_short);
    let u16_at = |at| field(at, 2).map(|b| b.iter().rev().fold(0u16, |acc, &x| (acc << 8) | u16::from(x)));
    let major = u16_at(8)?;
    let minor = u16_at(10)?;
    let meta_len = field(12, 8)?.iter().rev().fold(0u64, |acc, &x| (acc << 8) | u64::from(x));
    let meta_crc = field(20, 4)?.iter().rev().fold(0u32, |acc, &x| (acc << 8) | u32::from(x));
    let found = (major, minor);
    let supported = (FORMAT_MAJOR, FORMAT_MINOR);
    if major > FORMAT_MAJOR {
        return Err(ContainerError::NewerMajor { found, supported });
    }
    if major < FORMAT_MAJOR {
        return Err(ContainerError::UnsupportedOld { found, supported });
    }
    if minor > FORMAT_MINOR {
        return Err(ContainerError::NewerMinor { found, supported });
    }
    if meta_len > MAX_META_LEN {
        return Err(ContainerError::HeaderTooLarge { len: meta_len, max: MAX_META_LEN });
    }
    Ok(Preamble { version: found, meta_len, meta_crc })
}

/// The metadata block as a bincode reader that knows how far decoding got, so that a decode
/// failure names its byte.
struct TrackedSlice<'a> {
    bytes: &'a [u8],
    at: usize,
}

impl bincode::de::read::Reader for TrackedSlice<'_> {
    fn read(&mut self, out: &mut [u8]) -> Result<(), bincode::error::DecodeError> {
        let Some(src) = self.at.checked_add(out.len()).and_then(|end| self.bytes.get(self.at..end)) else {
            let additional = self.at.saturating_add(out.len()) - self.bytes.len();
            self.at = self.bytes.len();
            return Err(bincode::error::DecodeError::UnexpectedEnd { additional });
        };
        out.copy_from_slice(src);
        self.at += out.len();
        Ok(())
    }
}

/// A bincode decode failure in words, at file byte `PREAMBLE_LEN + at` (bincode's own `Display`
/// is its `Debug`).
fn decode_failure(e: &bincode::error::DecodeError, at: usize) -> String {
    use bincode::error::DecodeError as D;
    let what = match e {
        D::UnexpectedEnd { additional } => format!("the metadata ends {additional} bytes early"),
        D::LimitExceeded => "a declared length runs past the end of the metadata".to_owned(),
        D::Utf8 { .. } => "a name or text field is not valid UTF-8".to_owned(),
        D::UnexpectedVariant { type_name, found, .. } => format!("tag {found} is not a valid `{type_name}`"),
        D::InvalidBooleanValue(v) => format!("{v} is not a boolean (0 or 1)"),
        D::InvalidCharEncoding(_) => "a character is not valid UTF-8".to_owned(),
        D::OtherString(m) => m.clone(),
        other => format!("{other:?}"),
    };
    format!("at byte {} (metadata byte {at}): {what}", PREAMBLE_LEN as usize + at)
}

/// Checks the meta checksum, decodes `(Header, Vec<ChunkEntry>)` and validates both.
/// Returns the header, the chunk index and the payload length.
pub(crate) fn decode_meta(pre: &Preamble, meta: &[u8]) -> Result<(Header, Vec<ChunkEntry>, u64), ContainerError> {
    let computed = meta_crc(pre.version.0, pre.version.1, meta);
    if computed != pre.meta_crc {
        return Err(ContainerError::HeaderChecksum { stored: pre.meta_crc, computed });
    }
    let mut reader = TrackedSlice { bytes: meta, at: 0 };
    let (header, chunks): (Header, Vec<ChunkEntry>) =
        decode_meta_block(&mut reader).map_err(|e| ContainerError::HeaderDecode(decode_failure(&e, reader.at)))?;
    if reader.at != meta.len() {
        return Err(ContainerError::HeaderDecode(format!(
            "{} unused bytes after the header, from byte {}",
            meta.len() - reader.at,
            PREAMBLE_LEN as usize + reader.at
        )));
    }
    validate_header(&header)?;
    let payload_len = validate_index(&header, &chunks)?;
    Ok((header, chunks, payload_len))
}

#[cfg(test)]
mod tests;
