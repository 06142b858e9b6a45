//! Writer: `(Header, [ArrayValues], EncodeOptions)` → the complete bytes of a
//! `.vtab` file plus compression statistics.
//!
//! Invariant: the output is a pure function of the inputs (no clocks, no
//! randomness, `zstd::bulk` at a fixed level, deterministic transform choice),
//! and it is only produced for a valid header whose arrays match their
//! descriptions and contain finite values only — a table with NaN/Inf is never
//! written.

use rayon::prelude::*;

use super::error::ContainerError;
use super::format::{
    ArrayValues, ChunkEntry, END_MAGIC, ElementType, Header, MAX_META_LEN, Transform, bincode_config, encode_preamble,
};
use super::transform::{delta, f32_bytes, f64_bytes, quantize_f32, quantize_f64, shuffle};
use super::validate::{validate_header, validate_index};

/// Options of the writer.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct EncodeOptions {
    /// zstd compression level (default 9).
    pub zstd_level: i32,
}

impl Default for EncodeOptions {
    fn default() -> Self {
        EncodeOptions { zstd_level: 9 }
    }
}

/// Size statistics of one encoded array.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct ArrayStats {
    /// Array name.
    pub name: String,
    /// Bytes of the decoded elements.
    pub raw_bytes: u64,
    /// Bytes stored in the payload.
    pub stored_bytes: u64,
}

/// Size statistics of an encoded file's payload.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct EncodeStats {
    /// Bytes of all decoded elements.
    pub raw_bytes: u64,
    /// Bytes of all stored chunks.
    pub stored_bytes: u64,
    /// Per-array breakdown, in header order.
    pub per_array: Vec<ArrayStats>,
}

impl EncodeStats {
    /// Compression ratio of the whole payload: raw bytes / stored bytes
    /// (1.0 for an empty payload).
    pub fn ratio(&self) -> f64 {
        if self.stored_bytes == 0 { 1.0 } else { self.raw_bytes as f64 / self.stored_bytes as f64 }
    }
}

/// An encoded `.vtab` file.
#[derive(Clone, Debug, PartialEq)]
pub struct Encoded {
    /// The complete file contents.
    pub bytes: Vec<u8>,
    /// Size statistics.
    pub stats: EncodeStats,
}

fn zstd(data: &[u8], level: i32) -> Result<Vec<u8>, ContainerError> {
    zstd::bulk::compress(data, level).map_err(|e| ContainerError::Encode(format!("zstd: {e}")))
}

/// Encodes one chunk's raw little-endian bytes: tries `Shuffle` and
/// `DeltaShuffle` (rows of `row_len` elements), keeps the smaller compressed
/// result (ties → `Shuffle`), or stores the bytes verbatim (`None`) when
/// compression would not shrink them.
pub(crate) fn encode_chunk(
    raw: &[u8],
    element: ElementType,
    row_len: usize,
    level: i32,
) -> Result<(Transform, Vec<u8>), ContainerError> {
    let shuffled = zstd(&shuffle(raw, element), level)?;
    let deltaed = zstd(&shuffle(&delta(raw, element, row_len), element), level)?;
    let (transform, best) = if deltaed.len() < shuffled.len() {
        (Transform::DeltaShuffle, deltaed)
    } else {
        (Transform::Shuffle, shuffled)
    };
    if best.len() >= raw.len() { Ok((Transform::None, raw.to_vec())) } else { Ok((transform, best)) }
}

fn first_non_finite(values: &ArrayValues) -> Option<(u64, f64)> {
    match values {
        ArrayValues::F32(v) => {
            v.iter().enumerate().find(|(_, x)| !x.is_finite()).map(|(i, &x)| (i as u64, f64::from(x)))
        }
        ArrayValues::F64(v) => v.iter().enumerate().find(|(_, x)| !x.is_finite()).map(|(i, &x)| (i as u64, x)),
    }
}

fn to_usize(n: u64, what: &str) -> Result<usize, ContainerError> {
    usize::try_from(n).map_err(|_| ContainerError::InvalidHeader(format!("{what} does not fit in memory")))
}

/// Lays out a file from a header, a chunk index and a payload exactly as the writer does (preamble,
/// checksummed meta block, payload, end marker) **without** checking any of them: for tests,
/// fuzzing and tools that need well-framed but lying files (e.g. a zstd bomb with an honest
/// header). Readers must refuse what [`encode`] would never write.
pub fn assemble_unchecked(header: &Header, chunks: &[ChunkEntry], payload: &[u8]) -> Vec<u8> {
    let meta = bincode::serde::encode_to_vec((header, chunks), bincode_config()).unwrap_or_default();
    let mut out = encode_preamble(&meta);
    out.extend_from_slice(&meta);
    out.extend_from_slice(payload);
    out.extend_from_slice(&END_MAGIC);
    out
}

/// Encodes a table into the bytes of a `.vtab` file.
///
/// Fails with a typed error if the options or header are invalid, if the
/// arrays do not match the header (count, element type, length), or if any
/// value is NaN or infinite ([`ContainerError::NonFinite`]).
pub fn encode(header: &Header, arrays: &[ArrayValues], opts: &EncodeOptions) -> Result<Encoded, ContainerError> {
    let levels = zstd::compression_level_range();
    if !levels.contains(&opts.zstd_level) {
        return Err(ContainerError::InvalidOptions(format!(
            "zstd level {} is outside {}..={}",
            opts.zstd_level,
            levels.start(),
            levels.end()
        )));
    }
    validate_header(header)?;
    if arrays.len() != header.arrays.len() {
        return Err(ContainerError::ArrayCount { expected: header.arrays.len(), found: arrays.len() });
    }
    for (desc, values) in header.arrays.iter().zip(arrays) {
        if values.element_type() != desc.element {
            return Err(ContainerError::ElementTypeMismatch {
                array: desc.name.clone(),
                expected: desc.element,
                found: values.element_type(),
            });
        }
        // validate_header guarantees the element count does not overflow.
        let expected = desc.element_count().unwrap_or(u64::MAX);
        if values.len() as u64 != expected {
            return Err(ContainerError::ShapeMismatch {
                array: desc.name.clone(),
                expected,
                found: values.len() as u64,
            });
        }
        if let Some((index, value)) = first_non_finite(values) {
            return Err(ContainerError::NonFinite { array: desc.name.clone(), index, value });
        }
    }

    let mut chunks = Vec::new();
    let mut payload = Vec::new();
    let mut per_array = Vec::with_capacity(arrays.len());
    for (ai, (desc, values)) in header.arrays.iter().zip(arrays).enumerate() {
        let slice_len = to_usize(desc.slice_len().unwrap_or(u64::MAX), "slice")?;
        let row_len = to_usize(desc.row_len(), "row")?;
        let keep = desc.quantization.as_ref().map(|q| q.mantissa_bits);
        let raws: Vec<Vec<u8>> = match values {
            ArrayValues::F32(v) => v
                .chunks(slice_len)
                .map(|c| {
                    let mut c = c.to_vec();
                    if let Some(k) = keep {
                        quantize_f32(&mut c, k);
                    }
                    f32_bytes(&c)
                })
                .collect(),
            ArrayValues::F64(v) => v
                .chunks(slice_len)
                .map(|c| {
                    let mut c = c.to_vec();
                    if let Some(k) = keep {
                        quantize_f64(&mut c, k);
                    }
                    f64_bytes(&c)
                })
                .collect(),
        };
        let mut stats = ArrayStats { name: desc.name.clone(), raw_bytes: 0, stored_bytes: 0 };
        // Chunks compress independently, in parallel; collecting in slice order keeps the bytes
        // independent of the thread count.
        let encoded: Vec<Result<(Transform, Vec<u8>), ContainerError>> =
            raws.par_iter().map(|raw| encode_chunk(raw, desc.element, row_len, opts.zstd_level)).collect();
        for (slice, (raw, enc)) in raws.iter().zip(encoded).enumerate() {
            let (transform, stored) = enc?;
            chunks.push(ChunkEntry {
                array: ai as u32, // validate_header bounds the array count by u32
                slice: slice as u64,
                offset: payload.len() as u64,
                stored_len: stored.len() as u64,
                raw_len: raw.len() as u64,
                transform,
                crc32: crc32fast::hash(&stored),
            });
            stats.raw_bytes += raw.len() as u64;
            stats.stored_bytes += stored.len() as u64;
            payload.extend_from_slice(&stored);
        }
        per_array.push(stats);
    }
    // Self-check: the writer must emit exactly what the reader will accept.
    validate_index(header, &chunks)?;

    let meta = bincode::serde::encode_to_vec((header, &chunks), bincode_config())
        .map_err(|e| ContainerError::Encode(format!("header serialization: {e}")))?;
    if meta.len() as u64 > MAX_META_LEN {
        return Err(ContainerError::HeaderTooLarge { len: meta.len() as u64, max: MAX_META_LEN });
    }
    let mut bytes = encode_preamble(&meta);
    bytes.reserve(meta.len() + payload.len() + END_MAGIC.len());
    bytes.extend_from_slice(&meta);
    bytes.extend_from_slice(&payload);
    bytes.extend_from_slice(&END_MAGIC);
    let stats = EncodeStats {
        raw_bytes: per_array.iter().map(|a| a.raw_bytes).sum(),
        stored_bytes: payload.len() as u64,
        per_array,
    };
    Ok(Encoded { bytes, stats })
}

#[cfg(test)]
mod tests;
