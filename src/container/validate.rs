//! Container rules: a [`Header`] (and its chunk index) → `Ok` or a typed
//! [`ContainerError::InvalidHeader`] naming the broken rule.
//!
//! Invariant: a header that passes [`validate_header`] has at least one
//! uniquely named array (at most `u32::MAX`), every array has ≥ 1 axis of
//! length ≥ 1 with finite, well-formed positions, its element count and byte
//! size fit in `u64`, and its quantization (if any) is legal for its element
//! type; a chunk index that passes [`validate_index`] lists exactly one entry
//! per slice, array-major and slice-ascending, with contiguous offsets from 0,
//! raw lengths matching the shape, and `None` chunks stored uncompressed.
//! Both run on the writer's input and on every file the reader opens.

use super::error::ContainerError;
use super::format::{ArrayDesc, Axis, ChunkEntry, Header, Quantization, Spacing, Transform};

fn invalid(msg: String) -> ContainerError {
    ContainerError::InvalidHeader(msg)
}

fn validate_axis(array: &str, k: usize, axis: &Axis) -> Result<(), ContainerError> {
    let what = format!("array `{array}`, axis {k} (`{}`)", axis.name);
    if axis.len == 0 {
        return Err(invalid(format!("{what} has length 0")));
    }
    if !axis.min.is_finite() || !axis.max.is_finite() {
        return Err(invalid(format!("{what} has a non-finite range")));
    }
    match axis.spacing {
        Spacing::Explicit => {
            if axis.values.len() as u64 != axis.len {
                return Err(invalid(format!("{what}: len {} but {} explicit values", axis.len, axis.values.len())));
            }
            if axis.values.iter().any(|v| !v.is_finite()) {
                return Err(invalid(format!("{what} has a non-finite explicit value")));
            }
        }
        Spacing::Linear | Spacing::Log => {
            if !axis.values.is_empty() {
                return Err(invalid(format!("{what}: explicit values given for a computed axis")));
            }
            if axis.spacing == Spacing::Log && (axis.min <= 0.0 || axis.max <= 0.0) {
                return Err(invalid(format!("{what}: log axis needs min > 0 and max > 0")));
            }
        }
    }
    Ok(())
}

fn validate_array(desc: &ArrayDesc) -> Result<(), ContainerError> {
    let name = &desc.name;
    if desc.axes.is_empty() {
        return Err(invalid(format!("array `{name}` has no axes")));
    }
    for (k, axis) in desc.axes.iter().enumerate() {
        validate_axis(name, k, axis)?;
    }
    let count = desc.element_count().ok_or_else(|| invalid(format!("array `{name}`: element count overflows")))?;
    if count.checked_mul(desc.element.size_bytes()).is_none() {
        return Err(invalid(format!("array `{name}`: byte size overflows")));
    }
    if let Some(q) = &desc.quantization {
        let max_bits = desc.element.mantissa_bits();
        if q.mantissa_bits == 0 || q.mantissa_bits > max_bits {
            return Err(invalid(format!(
                "array `{name}`: {} mantissa bits is outside 1..={max_bits} for {}",
                q.mantissa_bits, desc.element
            )));
        }
        if q.max_rel_error != Quantization::new(q.mantissa_bits).max_rel_error {
            return Err(invalid(format!("array `{name}`: max_rel_error must be 2^-(mantissa_bits+1)")));
        }
    }
    Ok(())
}

/// Checks the container rules on a header (see the module invariant).
pub fn validate_header(header: &Header) -> Result<(), ContainerError> {
    if header.arrays.is_empty() {
        return Err(invalid("a .vtab file needs at least one array".into()));
    }
    if u32::try_from(header.arrays.len()).is_err() {
        return Err(invalid("too many arrays".into()));
    }
    // A set, not a scan of the earlier names: 40,000 arrays took 5.7 s quadratically (issue 37).
    let mut names = std::collections::HashSet::with_capacity(header.arrays.len());
    for desc in &header.arrays {
        if !names.insert(desc.name.as_str()) {
            return Err(invalid(format!("duplicate array name `{}`", desc.name)));
        }
        validate_array(desc)?;
    }
    Ok(())
}

/// Checks that `chunks` is exactly the canonical index for a valid `header`
/// (one entry per slice, array-major, contiguous offsets from 0, raw lengths
/// matching the shapes) and returns the total payload length.
pub fn validate_index(header: &Header, chunks: &[ChunkEntry]) -> Result<u64, ContainerError> {
    let expected = header
        .arrays
        .iter()
        .try_fold(0u64, |acc, d| acc.checked_add(d.slice_count()))
        .ok_or_else(|| invalid("slice count overflows".into()))?;
    if expected != chunks.len() as u64 {
        return Err(invalid(format!("chunk index has {} entries, the arrays need {expected}", chunks.len())));
    }
    let mut entries = chunks.iter();
    let mut offset = 0u64;
    for (ai, desc) in header.arrays.iter().enumerate() {
        let raw_len = desc
            .slice_len()
            .and_then(|n| n.checked_mul(desc.element.size_bytes()))
            .ok_or_else(|| invalid(format!("array `{}`: slice size overflows", desc.name)))?;
        for slice in 0..desc.slice_count() {
            let e = entries.next().ok_or_else(|| invalid("chunk index too short".into()))?;
            let here = format!("chunk {ai}/{slice}");
            if e.array as usize != ai || e.slice != slice {
                return Err(invalid(format!("{here}: entry names {}/{} (out of order)", e.array, e.slice)));
            }
            if e.offset != offset {
                return Err(invalid(format!("{here}: offset {} but expected {offset}", e.offset)));
            }
            if e.raw_len != raw_len {
                return Err(invalid(format!("{here}: raw length {} but the shape needs {raw_len}", e.raw_len)));
            }
            if e.transform == Transform::None && e.stored_len != e.raw_len {
                return Err(invalid(format!("{here}: uncompressed chunk with stored length ≠ raw length")));
            }
            offset = offset.checked_add(e.stored_len).ok_or_else(|| invalid("payload length overflows".into()))?;
        }
    }
    Ok(offset)
}

#[cfg(test)]
mod tests;
