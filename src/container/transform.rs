//! Chunk codecs: float values ↔ little-endian bytes, mantissa quantization,
//! byte shuffle and row-wise bit-pattern delta → reversible byte streams.
//!
//! Invariant: for every byte buffer `b` whose length is a multiple of the
//! element size, `unshuffle(shuffle(b)) == b` and `undelta(delta(b)) == b`
//! bit-for-bit; quantization changes each finite normal value by a relative
//! amount ≤ `2^-(mantissa_bits+1)` and leaves zeros, subnormals and values
//! whose rounding would overflow untouched. Nothing here panics on any input.

use super::format::ElementType;

/// Rounds the explicit mantissa of an IEEE bit pattern to `keep` bits
/// (round-to-nearest, ties-to-even on the bit pattern).
/// `mant` is the type's explicit mantissa width, `exp_bits` its exponent width.
fn round_bits(bits: u64, mant: u32, exp_bits: u32, keep: u32) -> u64 {
    if keep >= mant {
        return bits;
    }
    let exp_mask = (1u64 << exp_bits) - 1;
    let exp = (bits >> mant) & exp_mask;
    if exp == 0 || exp == exp_mask {
        // Zero, subnormal (kept exact so the relative bound holds) or non-finite.
        return bits;
    }
    let drop = mant - keep;
    let low_mask = (1u64 << drop) - 1;
    let lsb = (bits >> drop) & 1;
    let rounded = (bits + (low_mask >> 1) + lsb) & !low_mask;
    if (rounded >> mant) & exp_mask == exp_mask {
        // Rounding carried into the infinity pattern: keep the value exact instead.
        return bits;
    }
    rounded
}

/// Quantizes f32 values in place to `keep` explicit mantissa bits.
pub(crate) fn quantize_f32(values: &mut [f32], keep: u8) {
    for v in values {
        *v = f32::from_bits(round_bits(u64::from(v.to_bits()), 23, 8, u32::from(keep)) as u32);
    }
}

/// Quantizes f64 values in place to `keep` explicit mantissa bits.
pub(crate) fn quantize_f64(values: &mut [f64], keep: u8) {
    for v in values {
        *v = f64::from_bits(round_bits(v.to_bits(), 52, 11, u32::from(keep)));
    }
}

/// Little-endian bytes of f32 values.
pub(crate) fn f32_bytes(values: &[f32]) -> Vec<u8> {
    values.iter().flat_map(|v| v.to_le_bytes()).collect()
}

/// Little-endian bytes of f64 values.
pub(crate) fn f64_bytes(values: &[f64]) -> Vec<u8> {
    values.iter().flat_map(|v| v.to_le_bytes()).collect()
}

/// f32 values from little-endian bytes (a trailing partial element is ignored;
/// callers check lengths first).
pub(crate) fn bytes_f32(bytes: &[u8]) -> Vec<f32> {
    bytes.as_chunks::<4>().0.iter().map(|c| f32::from_le_bytes(*c)).collect()
}

/// f64 values from little-endian bytes (a trailing partial element is ignored;
/// callers check lengths first).
pub(crate) fn bytes_f64(bytes: &[u8]) -> Vec<f64> {
    bytes.as_chunks::<8>().0.iter().map(|c| f64::from_le_bytes(*c)).collect()
}

fn shuffle_n<const N: usize>(bytes: &[u8]) -> Vec<u8> {
    let (elems, rest) = bytes.as_chunks::<N>();
    let mut out = Vec::with_capacity(bytes.len());
    for k in 0..N {
        out.extend(elems.iter().map(|e| e[k]));
    }
    out.extend_from_slice(rest);
    out
}

fn unshuffle_n<const N: usize>(bytes: &[u8]) -> Vec<u8> {
    let n = bytes.len() / N;
    let mut out = vec![0u8; bytes.len()];
    let (elems, rest) = out.as_chunks_mut::<N>();
    for (k, plane) in bytes.chunks_exact(n.max(1)).take(N).enumerate() {
        for (e, &b) in elems.iter_mut().zip(plane) {
            if let Some(slot) = e.get_mut(k) {
                *slot = b;
            }
        }
    }
    let tail = bytes.get(n * N..).unwrap_or(&[]);
    for (d, &s) in rest.iter_mut().zip(tail) {
        *d = s;
    }
    out
}

/// Byte-plane transposition: byte 0 of every element, then byte 1, ….
pub(crate) fn shuffle(bytes: &[u8], element: ElementType) -> Vec<u8> {
    match element {
        ElementType::F32 => shuffle_n::<4>(bytes),
        ElementType::F64 => shuffle_n::<8>(bytes),
    }
}

/// Inverse of [`shuffle`].
pub(crate) fn unshuffle(bytes: &[u8], element: ElementType) -> Vec<u8> {
    match element {
        ElementType::F32 => unshuffle_n::<4>(bytes),
        ElementType::F64 => unshuffle_n::<8>(bytes),
    }
}

fn word<const N: usize>(e: &[u8; N]) -> u64 {
    e.iter().rev().fold(0u64, |acc, &b| (acc << 8) | u64::from(b))
}

fn put_word<const N: usize>(e: &mut [u8; N], w: u64) {
    for (k, slot) in e.iter_mut().enumerate() {
        *slot = (w >> (8 * k)) as u8;
    }
}

/// Applies `step(prev, cur) -> new` along each row of `row_len` elements,
/// where `prev` is the previous element's original (`forward`) or reconstructed value.
fn rowwise<const N: usize>(bytes: &[u8], row_len: usize, forward: bool) -> Vec<u8> {
    let mut out = bytes.to_vec();
    let (elems, _) = out.as_chunks_mut::<N>();
    for row in elems.chunks_mut(row_len.max(1)) {
        let mut prev: Option<u64> = None;
        for e in row {
            let cur = word(e);
            match prev {
                None => prev = Some(cur),
                Some(p) if forward => {
                    put_word(e, cur.wrapping_sub(p));
                    prev = Some(cur);
                }
                Some(p) => {
                    let value = cur.wrapping_add(p);
                    put_word(e, value);
                    // Re-read so the running value wraps at the element width.
                    prev = Some(word(e));
                }
            }
        }
    }
    out
}

/// Replaces each element's bit pattern by the wrapping difference from the
/// previous element in its row of `row_len` elements (the first is kept).
pub(crate) fn delta(bytes: &[u8], element: ElementType, row_len: usize) -> Vec<u8> {
    match element {
        ElementType::F32 => rowwise::<4>(bytes, row_len, true),
        ElementType::F64 => rowwise::<8>(bytes, row_len, true),
    }
}

/// Inverse of [`delta`].
pub(crate) fn undelta(bytes: &[u8], element: ElementType, row_len: usize) -> Vec<u8> {
    match element {
        ElementType::F32 => rowwise::<4>(bytes, row_len, false),
        ElementType::F64 => rowwise::<8>(bytes, row_len, false),
    }
}

#[cfg(test)]
mod tests;
