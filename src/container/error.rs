//! Error type of the `.vtab` container: every way writing or reading a table
//! can fail → one typed [`ContainerError`] variant with a human message.
//!
//! Invariant: no code path in `container` panics on malformed input; each
//! failure is reported as one of these variants instead.

use std::path::PathBuf;

use super::format::ElementType;

/// A `(major, minor)` format version pair.
pub type Version = (u16, u16);

/// Everything that can go wrong while encoding, opening, reading, verifying
/// or diffing a `.vtab` file.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum ContainerError {
    /// An operating-system I/O operation failed.
    #[error("I/O error{}: {source}", path_suffix(path))]
    Io {
        /// The file involved, when known.
        path: Option<PathBuf>,
        /// The underlying error.
        #[source]
        source: std::io::Error,
    },
    /// The file does not start with the `.vtab` magic bytes.
    #[error("not a .vtab file (bad magic bytes at the start)")]
    BadMagic,
    /// The file does not end with the `.vtab` end marker.
    #[error("corrupt .vtab file: the end marker is missing or damaged")]
    BadEndMagic,
    /// The file was written by a newer, incompatible major format version.
    #[error(
        "this .vtab file uses format version {}.{}, but this build of voltab only reads \
         format {}.x (up to {}.{}); upgrade voltab to read it",
        found.0, found.1, supported.0, supported.0, supported.1
    )]
    NewerMajor {
        /// Version found in the file.
        found: Version,
        /// Newest version this build reads.
        supported: Version,
    },
    /// The file was written by a newer minor format version than this build knows.
    #[error(
        "this .vtab file uses format version {}.{}, newer than the {}.{} this build of voltab \
         supports; upgrade voltab to read it",
        found.0, found.1, supported.0, supported.1
    )]
    NewerMinor {
        /// Version found in the file.
        found: Version,
        /// Newest version this build reads.
        supported: Version,
    },
    /// The file uses an old major format version that is no longer readable.
    #[error(
        "this .vtab file uses the old format version {}.{}, which this build of voltab \
         (format {}.{}) no longer reads; recompile the table",
        found.0, found.1, supported.0, supported.1
    )]
    UnsupportedOld {
        /// Version found in the file.
        found: Version,
        /// Newest version this build reads.
        supported: Version,
    },
    /// The metadata block's length field is larger than any sane header.
    #[error("corrupt .vtab header: metadata length {len} bytes exceeds the limit of {max} bytes")]
    HeaderTooLarge {
        /// Length claimed by the file.
        len: u64,
        /// Largest accepted length.
        max: u64,
    },
    /// The metadata block's checksum does not match its contents.
    #[error("corrupt .vtab header: checksum mismatch (stored {stored:#010x}, computed {computed:#010x})")]
    HeaderChecksum {
        /// Checksum stored in the file.
        stored: u32,
        /// Checksum computed from the bytes read.
        computed: u32,
    },
    /// The metadata block could not be decoded.
    #[error("corrupt .vtab header: {0}")]
    HeaderDecode(String),
    /// The header or chunk index is decodable but inconsistent, or a header
    /// given to the encoder breaks a container rule.
    #[error("invalid .vtab header: {0}")]
    InvalidHeader(String),
    /// The file is shorter than its header says.
    #[error("truncated .vtab file: expected {expected} bytes, found {found}")]
    Truncated {
        /// Length the file should have.
        expected: u64,
        /// Length actually present.
        found: u64,
    },
    /// The file has bytes after its end marker.
    #[error("corrupt .vtab file: {extra} unexpected trailing bytes after the end marker")]
    TrailingBytes {
        /// Number of surplus bytes.
        extra: u64,
    },
    /// The number of value arrays does not match the header.
    #[error("the header describes {expected} arrays but {found} were given")]
    ArrayCount {
        /// Arrays in the header.
        expected: usize,
        /// Arrays supplied.
        found: usize,
    },
    /// An array's values have a different element type than its description.
    #[error("array `{array}` is declared as {expected} but its values are {found}")]
    ElementTypeMismatch {
        /// Array name.
        array: String,
        /// Declared element type.
        expected: ElementType,
        /// Element type of the supplied values.
        found: ElementType,
    },
    /// An array's value count does not match the product of its axis lengths.
    #[error("array `{array}` has shape of {expected} elements but {found} values were given")]
    ShapeMismatch {
        /// Array name.
        array: String,
        /// Element count implied by the axes.
        expected: u64,
        /// Element count supplied.
        found: u64,
    },
    /// A value is NaN or infinite; such tables are never written.
    #[error("array `{array}` has the non-finite value {value} at element {index}")]
    NonFinite {
        /// Array name.
        array: String,
        /// Flat (row-major) element index, within the array when encoding and
        /// within the whole array when reading.
        index: u64,
        /// The offending value.
        value: f64,
    },
    /// The encoder options are invalid.
    #[error("invalid encode options: {0}")]
    InvalidOptions(String),
    /// Compressing a chunk or serializing the header failed.
    #[error("encoding failed: {0}")]
    Encode(String),
    /// An array index outside the header's arrays was requested.
    #[error("no array {index}: the file has {count} arrays")]
    NoSuchArray {
        /// Requested index.
        index: usize,
        /// Number of arrays.
        count: usize,
    },
    /// A slice index outside the array's outermost axis was requested.
    #[error("array `{array}` has no slice {slice}: it has {count} slices")]
    NoSuchSlice {
        /// Array name.
        array: String,
        /// Requested slice.
        slice: u64,
        /// Number of slices.
        count: u64,
    },
    /// A chunk's stored bytes do not match their checksum.
    #[error("corrupt .vtab file: checksum mismatch in array `{array}`, slice {slice}")]
    ChunkChecksum {
        /// Array name.
        array: String,
        /// Slice index.
        slice: u64,
    },
    /// A chunk's stored bytes could not be decompressed.
    #[error("corrupt .vtab file: cannot decompress array `{array}`, slice {slice}: {message}")]
    ChunkDecompress {
        /// Array name.
        array: String,
        /// Slice index.
        slice: u64,
        /// Decompressor message.
        message: String,
    },
    /// A chunk decompressed to a different length than recorded.
    #[error("corrupt .vtab file: array `{array}`, slice {slice} decompressed to {found} bytes, expected {expected}")]
    ChunkLength {
        /// Array name.
        array: String,
        /// Slice index.
        slice: u64,
        /// Recorded raw length.
        expected: u64,
        /// Length obtained (capped at `expected + 1`).
        found: u64,
    },
    /// A chunk declares more decoded (or stored) bytes than the reader's limit allows; refused
    /// before anything is read or allocated.
    #[error(
        "array `{array}`, slice {slice} declares {len} bytes, above this reader's limit of {limit} bytes \
         per chunk; if the table is genuine, raise the limit with VOLTAB_MAX_CHUNK_BYTES"
    )]
    ChunkTooLarge {
        /// Array name.
        array: String,
        /// Slice index.
        slice: u64,
        /// Declared length (the larger of raw and stored).
        len: u64,
        /// The limit in force.
        limit: u64,
    },
}

fn path_suffix(path: &Option<PathBuf>) -> String {
    match path {
        Some(p) => format!(" on `{}`", p.display()),
        None => String::new(),
    }
}

impl ContainerError {
    /// Wraps an I/O error, recording the path involved if any.
    pub(crate) fn io(path: Option<&std::path::Path>, source: std::io::Error) -> Self {
        ContainerError::Io { path: path.map(std::path::Path::to_path_buf), source }
    }
}

#[cfg(test)]
mod tests;
