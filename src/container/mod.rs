//! The `.vtab` table container: a compiled table (header + named n-dimensional
//! f32/f64 arrays) → one self-describing, checksummed file whose arrays are
//! split into independently loadable, transformed and zstd-compressed slices
//! (one chunk per index of each array's outermost axis), and back.
//!
//! Invariant: [`encode()`] only writes valid, finite tables, deterministically;
//! [`VtabReader`] only hands out values from chunks whose checksums, lengths
//! and finiteness were verified, and turns every malformed input into a typed
//! [`ContainerError`] — never a panic and never silently different values.
//!
//! Submodules: [`format`](mod@format) (types, layout), [`validate`] (rules), `transform` (byte
//! codecs), [`encode`](mod@encode) (writer), [`reader`], [`diff`](mod@diff).

pub mod diff;
pub mod encode;
pub mod error;
pub mod format;
pub mod reader;
mod transform;
pub mod validate;

#[cfg(test)]
mod robustness;
#[cfg(test)]
mod testutil;

pub use diff::{ChunkDiff, DiffReport, diff};
pub use encode::{ArrayStats, EncodeOptions, EncodeStats, Encoded, assemble_unchecked, encode};
pub use error::{ContainerError, Version};
pub use format::{
    ArrayDesc, ArrayValues, Axis, ChunkEntry, END_MAGIC, ElementType, FORMAT_MAJOR, FORMAT_MINOR, Header, MAGIC,
    MAX_META_LEN, Quantization, Spacing, Transform,
};
pub use reader::{DEFAULT_MAX_CHUNK_BYTES, ReadLimits, VerifyReport, VtabReader, read_header};
pub use validate::{validate_header, validate_index};
