//! Accessor data → typed vectors, every offset, stride and count checked first.
//!
//! The gltf crate's readers compute `count - 1`, slice buffers and `debug_assert!` strides without
//! checks, so a broken file can panic them; this reader returns an error naming the accessor
//! instead. It supports strided views, sparse accessors (with or without a base view) and the
//! normalized integer texture coordinates glTF 2.0 §3.7.2.1 allows.

use gltf::json;
use gltf::json::accessor::{ComponentType, Type};
use gltf::json::validation::Checked;

/// Elements per accessor beyond which a view-less (all-zero sparse) accessor is refused: the count
/// is not backed by bytes, so it could ask for any amount of memory.
const MAX_VIEWLESS_COUNT: u64 = 1 << 24;

/// An accessor, buffer view or buffer that cannot be read as declared (the message names it by its
/// index in the document).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum AccessorError {
    /// No such accessor.
    #[error("accessors[{0}] does not exist")]
    Missing(usize),
    /// A count that does not fit in memory addresses.
    #[error("accessors[{index}]: count {count} is too large")]
    CountTooLarge {
        /// The accessor.
        index: usize,
        /// Its count.
        count: u64,
    },
    /// A type or component type the glTF crate could not parse.
    #[error("accessors[{0}] has an unknown type or componentType")]
    UnknownType(usize),
    /// A type or component type this attribute does not take.
    #[error("accessors[{index}] is {ty} of {found}; expected {want} of {allowed}")]
    WrongType {
        /// The accessor.
        index: usize,
        /// Its type.
        ty: &'static str,
        /// Its component type (with "normalized").
        found: String,
        /// The type the attribute needs.
        want: &'static str,
        /// The component types the attribute takes.
        allowed: String,
    },
    /// A byte offset that does not fit in memory addresses.
    #[error("accessors[{0}]: byteOffset too large")]
    OffsetTooLarge(usize),
    /// The elements read past the end of their buffer view.
    #[error(
        "accessors[{index}] ({count} elements of {elem} bytes, stride {stride}, from byte {start}) reads past the end of bufferViews[{view}] ({len} bytes)"
    )]
    PastView {
        /// The accessor.
        index: usize,
        /// Its count.
        count: usize,
        /// Bytes per element.
        elem: usize,
        /// Bytes between elements.
        stride: usize,
        /// First byte read.
        start: usize,
        /// The buffer view.
        view: usize,
        /// The view's length.
        len: usize,
    },
    /// A sparse accessor without a buffer view whose count is not backed by bytes.
    #[error("accessors[{index}] has no bufferView and a count of {count} (more than {MAX_VIEWLESS_COUNT})")]
    Viewless {
        /// The accessor.
        index: usize,
        /// Its count.
        count: u64,
    },
    /// A sparse count that does not fit in memory addresses.
    #[error("accessors[{0}].sparse: count too large")]
    SparseCountTooLarge(usize),
    /// Sparse indices of a component type the glTF crate could not parse.
    #[error("accessors[{0}].sparse.indices has an unknown componentType")]
    SparseIndexType(usize),
    /// Sparse indices or values read past the end of their buffer view.
    #[error(
        "accessors[{index}].sparse.{what} ({count} elements of {size} bytes from byte {offset}) reads past the end of bufferViews[{view}] ({len} bytes)"
    )]
    SparsePastView {
        /// The accessor.
        index: usize,
        /// `"indices"` or `"values"`.
        what: &'static str,
        /// Sparse count.
        count: usize,
        /// Bytes per element.
        size: usize,
        /// First byte read.
        offset: u64,
        /// The buffer view.
        view: usize,
        /// The view's length.
        len: usize,
    },
    /// A sparse index beyond the accessor's count.
    #[error("accessors[{index}].sparse.indices[{k}] = {target} is out of range of the accessor's count")]
    SparseTarget {
        /// The accessor.
        index: usize,
        /// Position in the sparse index list.
        k: usize,
        /// The element it names.
        target: usize,
    },
    /// No such buffer view.
    #[error("bufferViews[{0}] does not exist")]
    NoView(usize),
    /// No such buffer.
    #[error("buffers[{0}] does not exist")]
    NoBuffer(usize),
    /// A buffer view outside its buffer.
    #[error(
        "bufferViews[{view}] (byteOffset {offset}, byteLength {length}) lies outside buffers[{buffer}] ({len} bytes)"
    )]
    ViewOutside {
        /// The buffer view.
        view: usize,
        /// Its byte offset.
        offset: u64,
        /// Its byte length.
        length: u64,
        /// Its buffer.
        buffer: usize,
        /// The buffer's length.
        len: usize,
    },
    /// A stride smaller than the element read.
    #[error("bufferViews[{view}] has byteStride {stride}, less than the {elem}-byte element read from it")]
    Stride {
        /// The buffer view.
        view: usize,
        /// Its stride.
        stride: usize,
        /// Bytes per element.
        elem: usize,
    },
}

/// Reads accessors of one document.
pub(super) struct Accessors<'a> {
    pub root: &'a json::Root,
    pub buffers: &'a [Vec<u8>],
}

/// Bytes of one element → value.
type Decode<'f, T> = &'f dyn Fn(&[u8]) -> T;

impl Accessors<'_> {
    /// Number of elements `accessors[index]` declares.
    pub fn count(&self, index: usize) -> Result<usize, AccessorError> {
        let a = self.root.accessors.get(index).ok_or(AccessorError::Missing(index))?;
        usize::try_from(a.count.0).map_err(|_| AccessorError::CountTooLarge { index, count: a.count.0 })
    }

    /// `VEC3` of `FLOAT` (POSITION, NORMAL).
    pub fn vec3_f32(&self, index: usize) -> Result<Vec<[f32; 3]>, AccessorError> {
        let ct = self.expect(index, Type::Vec3, &[ComponentType::F32], false)?;
        self.elements(index, 12, &|b| [0, 1, 2].map(|k| component(&b[4 * k..], ct, false)))
    }

    /// `VEC2` of `FLOAT`, or of normalized `UNSIGNED_BYTE`/`UNSIGNED_SHORT` (TEXCOORD_n).
    pub fn vec2_texcoord(&self, index: usize) -> Result<Vec<[f32; 2]>, AccessorError> {
        let ct = self.expect(index, Type::Vec2, &[ComponentType::F32, ComponentType::U8, ComponentType::U16], true)?;
        let size = component_size(ct);
        self.elements(index, 2 * size, &|b| [0, 1].map(|k| component(&b[size * k..], ct, true)))
    }

    /// `SCALAR` of `UNSIGNED_BYTE`/`UNSIGNED_SHORT`/`UNSIGNED_INT` (primitive indices).
    pub fn indices(&self, index: usize) -> Result<Vec<u32>, AccessorError> {
        let ct =
            self.expect(index, Type::Scalar, &[ComponentType::U8, ComponentType::U16, ComponentType::U32], false)?;
        self.elements(index, component_size(ct), &|b| unsigned(b, ct))
    }

    /// Checks the accessor's type and component type; returns the component type.
    fn expect(
        &self,
        index: usize,
        want: Type,
        allowed: &[ComponentType],
        int_needs_normalized: bool,
    ) -> Result<ComponentType, AccessorError> {
        let a = self.root.accessors.get(index).ok_or(AccessorError::Missing(index))?;
        let (Checked::Valid(ty), Checked::Valid(ct)) = (&a.type_, &a.component_type) else {
            return Err(AccessorError::UnknownType(index));
        };
        let ct = ct.0;
        let ok_ct = allowed.contains(&ct) && (!int_needs_normalized || ct == ComponentType::F32 || a.normalized);
        if *ty != want || !ok_ct {
            let names: Vec<String> = allowed
                .iter()
                .map(|c| match (c, int_needs_normalized) {
                    (ComponentType::F32, _) | (_, false) => component_name(*c).to_owned(),
                    (_, true) => format!("normalized {}", component_name(*c)),
                })
                .collect();
            let found = format!("{}{}", if a.normalized { "normalized " } else { "" }, component_name(ct));
            return Err(AccessorError::WrongType {
                index,
                ty: type_name(*ty),
                found,
                want: type_name(want),
                allowed: names.join(" or "),
            });
        }
        Ok(ct)
    }

    /// Decodes every element of `accessors[index]` (`elem` bytes each), sparse substitution included.
    fn elements<T: Copy + Default>(
        &self,
        index: usize,
        elem: usize,
        decode: Decode<'_, T>,
    ) -> Result<Vec<T>, AccessorError> {
        let a = self.root.accessors.get(index).ok_or(AccessorError::Missing(index))?;
        let count = self.count(index)?;
        let mut out = match a.buffer_view {
            Some(view) => {
                let (data, stride) = self.view(view.value(), elem, false)?;
                let start = a.byte_offset.map_or(0, |o| o.0);
                let start = usize::try_from(start).map_err(|_| AccessorError::OffsetTooLarge(index))?;
                let end = count.checked_sub(1).map(|last| {
                    last.checked_mul(stride).and_then(|x| x.checked_add(start)).and_then(|x| x.checked_add(elem))
                });
                match end {
                    Some(Some(end)) if end <= data.len() => {}
                    None if start <= data.len() => {}
                    _ => {
                        return Err(AccessorError::PastView {
                            index,
                            count,
                            elem,
                            stride,
                            start,
                            view: view.value(),
                            len: data.len(),
                        });
                    }
                }
                (0..count).map(|k| decode(&data[start + k * stride..start + k * stride + elem])).collect()
            }
            None => {
                if a.count.0 > MAX_VIEWLESS_COUNT {
                    return Err(AccessorError::Viewless { index, count: a.count.0 });
                }
                vec![T::default(); count]
            }
        };
        if let Some(sparse) = &a.sparse {
            self.apply_sparse(index, sparse, elem, decode, &mut out)?;
        }
        Ok(out)
    }

    /// Overwrites the elements a sparse accessor lists (glTF 2.0 §3.6.2.3).
    fn apply_sparse<T>(
        &self,
        index: usize,
        sparse: &json::accessor::sparse::Sparse,
        elem: usize,
        decode: Decode<'_, T>,
        out: &mut [T],
    ) -> Result<(), AccessorError> {
        let n = usize::try_from(sparse.count.0).map_err(|_| AccessorError::SparseCountTooLarge(index))?;
        let Checked::Valid(ict) = &sparse.indices.component_type else {
            return Err(AccessorError::SparseIndexType(index));
        };
        let isize = component_size(ict.0);
        let slice = |view: usize, offset: u64, size: usize, what: &'static str| -> Result<&[u8], AccessorError> {
            let (data, _) = self.view(view, size, true)?;
            let start = usize::try_from(offset).ok();
            let end = start.and_then(|s| n.checked_mul(size).and_then(|x| x.checked_add(s)));
            match (start, end) {
                (Some(s), Some(e)) if e <= data.len() => Ok(&data[s..e]),
                _ => Err(AccessorError::SparsePastView { index, what, count: n, size, offset, view, len: data.len() }),
            }
        };
        let indices = slice(sparse.indices.buffer_view.value(), sparse.indices.byte_offset.0, isize, "indices")?;
        let values = slice(sparse.values.buffer_view.value(), sparse.values.byte_offset.0, elem, "values")?;
        for k in 0..n {
            let target = unsigned(&indices[k * isize..], ict.0) as usize;
            let slot = out.get_mut(target).ok_or(AccessorError::SparseTarget { index, k, target })?;
            *slot = decode(&values[k * elem..(k + 1) * elem]);
        }
        Ok(())
    }

    /// The bytes of `bufferViews[view]` and its stride (tightly packed when absent or 0).
    fn view(&self, view: usize, elem: usize, sparse: bool) -> Result<(&[u8], usize), AccessorError> {
        let v = self.root.buffer_views.get(view).ok_or(AccessorError::NoView(view))?;
        let buffer = self.buffers.get(v.buffer.value()).ok_or(AccessorError::NoBuffer(v.buffer.value()))?;
        let start = usize::try_from(v.byte_offset.map_or(0, |o| o.0)).ok();
        let end = start.and_then(|s| usize::try_from(v.byte_length.0).ok().and_then(|l| s.checked_add(l)));
        let data = match (start, end) {
            (Some(s), Some(e)) if e <= buffer.len() => &buffer[s..e],
            _ => {
                return Err(AccessorError::ViewOutside {
                    view,
                    offset: v.byte_offset.map_or(0, |o| o.0),
                    length: v.byte_length.0,
                    buffer: v.buffer.value(),
                    len: buffer.len(),
                });
            }
        };
        let stride = match v.byte_stride {
            Some(s) if s.0 > 0 && !sparse => s.0,
            _ => elem,
        };
        if stride < elem {
            return Err(AccessorError::Stride { view, stride, elem });
        }
        Ok((data, stride))
    }
}

fn component_size(ct: ComponentType) -> usize {
    match ct {
        ComponentType::I8 | ComponentType::U8 => 1,
        ComponentType::I16 | ComponentType::U16 => 2,
        ComponentType::U32 | ComponentType::F32 => 4,
    }
}

/// One component at the start of `b` (which holds at least its size), normalized if asked
/// (glTF 2.0 §3.11: unsigned c / max, signed max(c / max, −1)).
fn component(b: &[u8], ct: ComponentType, normalized: bool) -> f32 {
    let (value, max) = match ct {
        ComponentType::F32 => return f32::from_le_bytes([b[0], b[1], b[2], b[3]]),
        ComponentType::U8 => (f32::from(b[0]), 255.0),
        ComponentType::I8 => (f32::from(b[0] as i8), 127.0),
        ComponentType::U16 => (f32::from(u16::from_le_bytes([b[0], b[1]])), 65535.0),
        ComponentType::I16 => (f32::from(i16::from_le_bytes([b[0], b[1]])), 32767.0),
        ComponentType::U32 => (u32::from_le_bytes([b[0], b[1], b[2], b[3]]) as f32, u32::MAX as f32),
    };
    if normalized { (value / max).max(-1.0) } else { value }
}

/// An unsigned integer component at the start of `b`.
fn unsigned(b: &[u8], ct: ComponentType) -> u32 {
    match ct {
        ComponentType::U8 | ComponentType::I8 => u32::from(b[0]),
        ComponentType::U16 | ComponentType::I16 => u32::from(u16::from_le_bytes([b[0], b[1]])),
        ComponentType::U32 | ComponentType::F32 => u32::from_le_bytes([b[0], b[1], b[2], b[3]]),
    }
}

fn component_name(ct: ComponentType) -> &'static str {
    match ct {
        ComponentType::I8 => "BYTE",
        ComponentType::U8 => "UNSIGNED_BYTE",
        ComponentType::I16 => "SHORT",
        ComponentType::U16 => "UNSIGNED_SHORT",
        ComponentType::U32 => "UNSIGNED_INT",
        ComponentType::F32 => "FLOAT",
    }
}

fn type_name(t: Type) -> &'static str {
    match t {
        Type::Scalar => "SCALAR",
        Type::Vec2 => "VEC2",
        Type::Vec3 => "VEC3",
        Type::Vec4 => "VEC4",
        Type::Mat2 => "MAT2",
        Type::Mat3 => "MAT3",
        Type::Mat4 => "MAT4",
    }
}
