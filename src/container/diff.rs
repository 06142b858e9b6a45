//! Table comparison: two open `.vtab` readers → a [`DiffReport`] listing header
//! mismatches and, per slice of every same-named, same-shaped array, the
//! largest absolute and relative element differences and where they occur.
//!
//! Invariant: a header difference is reported for anything that changes the
//! meaning of the values (kind, schema version, array set, units, element
//! types, quantization, axes); values are compared only for arrays present in
//! both files with equal shapes, matched by name, slice by slice.

use super::error::ContainerError;
use super::format::{ArrayDesc, Axis, Header};
use super::reader::VtabReader;

/// Largest differences found in one slice of one array.
#[derive(Clone, Debug, PartialEq)]
pub struct ChunkDiff {
    /// Array name.
    pub array: String,
    /// Slice index along the outermost axis.
    pub slice: u64,
    /// Largest |a − b|.
    pub max_abs: f64,
    /// Flat row-major element index within the slice where `max_abs` first occurs.
    pub max_abs_index: u64,
    /// Largest |a − b| / max(|a|, |b|) (0 where both are 0).
    pub max_rel: f64,
    /// Flat row-major element index within the slice where `max_rel` first occurs.
    pub max_rel_index: u64,
}

/// Result of [`diff`].
#[derive(Clone, Debug, PartialEq, Default)]
pub struct DiffReport {
    /// Mismatches in the headers that change the meaning of the table.
    pub header_differences: Vec<String>,
    /// Informational differences (generator version, definition text,
    /// content key, descriptions) that do not affect [`DiffReport::within`].
    pub notes: Vec<String>,
    /// Per-slice value differences of the arrays that could be compared.
    pub chunks: Vec<ChunkDiff>,
}

impl DiffReport {
    /// True iff there are no header differences and every chunk has
    /// `max_abs <= abs_tol` or `max_rel <= rel_tol`.
    pub fn within(&self, abs_tol: f64, rel_tol: f64) -> bool {
        self.header_differences.is_empty() && self.chunks.iter().all(|c| c.max_abs <= abs_tol || c.max_rel <= rel_tol)
    }

    /// True iff there are no header differences and all compared values are equal.
    pub fn identical(&self) -> bool {
        self.within(0.0, 0.0)
    }
}

fn compare_axis(out: &mut Vec<String>, array: &str, k: usize, a: &Axis, b: &Axis) {
    let at = format!("array `{array}`, axis {k}");
    if a.name != b.name {
        out.push(format!("{at}: name `{}` vs `{}`", a.name, b.name));
    }
    if a.unit != b.unit {
        out.push(format!("{at}: unit `{}` vs `{}`", a.unit, b.unit));
    }
    if a.spacing != b.spacing {
        out.push(format!("{at}: spacing {:?} vs {:?}", a.spacing, b.spacing));
    }
    if a.len != b.len {
        out.push(format!("{at}: length {} vs {}", a.len, b.len));
    }
    if a.min.to_bits() != b.min.to_bits() || a.max.to_bits() != b.max.to_bits() {
        out.push(format!("{at}: range [{}, {}] vs [{}, {}]", a.min, a.max, b.min, b.max));
    }
    if a.len == b.len && a.values != b.values {
        out.push(format!("{at}: explicit sample positions differ"));
    }
}

fn compare_array(out: &mut Vec<String>, notes: &mut Vec<String>, a: &ArrayDesc, b: &ArrayDesc) {
    let name = &a.name;
    if a.unit != b.unit {
        out.push(format!("array `{name}`: unit `{}` vs `{}`", a.unit, b.unit));
    }
    if a.element != b.element {
        out.push(format!("array `{name}`: element type {} vs {}", a.element, b.element));
    }
    if a.quantization != b.quantization {
        out.push(format!("array `{name}`: quantization {:?} vs {:?}", a.quantization, b.quantization));
    }
    if a.description != b.description {
        notes.push(format!("array `{name}`: descriptions differ"));
    }
    if a.axes.len() != b.axes.len() {
        out.push(format!("array `{name}`: {} axes vs {}", a.axes.len(), b.axes.len()));
    }
    for (k, (x, y)) in a.axes.iter().zip(&b.axes).enumerate() {
        compare_axis(out, name, k, x, y);
    }
}

/// Header differences and notes between two headers.
fn compare_headers(a: &Header, b: &Header) -> (Vec<String>, Vec<String>) {
    let mut out = Vec::new();
    let mut notes = Vec::new();
    if a.kind != b.kind {
        out.push(format!("kind `{}` vs `{}`", a.kind, b.kind));
    }
    if a.kind_schema_version != b.kind_schema_version {
        out.push(format!("kind schema version {} vs {}", a.kind_schema_version, b.kind_schema_version));
    }
    if a.generator_version != b.generator_version {
        notes.push(format!("generator version `{}` vs `{}`", a.generator_version, b.generator_version));
    }
    if a.definition_ron != b.definition_ron {
        notes.push("definition text differs".into());
    }
    if a.content_key != b.content_key {
        notes.push("content key differs".into());
    }
    for x in &a.arrays {
        match b.arrays.iter().find(|y| y.name == x.name) {
            Some(y) => compare_array(&mut out, &mut notes, x, y),
            None => out.push(format!("array `{}` only in the first file", x.name)),
        }
    }
    for y in b.arrays.iter().filter(|y| !a.arrays.iter().any(|x| x.name == y.name)) {
        out.push(format!("array `{}` only in the second file", y.name));
    }
    (out, notes)
}

/// Largest absolute and relative differences between two equally long value lists.
pub(crate) fn compare_values(array: &str, slice: u64, a: &[f64], b: &[f64]) -> ChunkDiff {
    let mut d =
        ChunkDiff { array: array.to_string(), slice, max_abs: 0.0, max_abs_index: 0, max_rel: 0.0, max_rel_index: 0 };
    for (i, (&x, &y)) in a.iter().zip(b).enumerate() {
        let abs = (x - y).abs();
        let scale = x.abs().max(y.abs());
        let rel = if scale == 0.0 { 0.0 } else { abs / scale };
        if abs > d.max_abs {
            d.max_abs = abs;
            d.max_abs_index = i as u64;
        }
        if rel > d.max_rel {
            d.max_rel = rel;
            d.max_rel_index = i as u64;
        }
    }
    d
}

/// Compares two tables: headers first, then the values of every array that
/// exists in both with the same shape, slice by slice.
pub fn diff(a: &mut VtabReader, b: &mut VtabReader) -> Result<DiffReport, ContainerError> {
    let (header_differences, notes) = compare_headers(a.header(), b.header());
    let mut chunks = Vec::new();
    let pairs: Vec<(usize, usize, String, u64)> = a
        .header()
        .arrays
        .iter()
        .enumerate()
        .filter_map(|(ia, x)| {
            let ib = b.find_array(&x.name)?;
            let y = b.header().arrays.get(ib)?;
            (x.shape() == y.shape()).then(|| (ia, ib, x.name.clone(), x.slice_count()))
        })
        .collect();
    for (ia, ib, name, slices) in pairs {
        for slice in 0..slices {
            let va = a.read_slice(ia, slice)?.to_f64();
            let vb = b.read_slice(ib, slice)?.to_f64();
            chunks.push(compare_values(&name, slice, &va, &vb));
        }
    }
    Ok(DiffReport { header_differences, notes, chunks })
}

#[cfg(test)]
mod tests;
