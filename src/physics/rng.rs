//! Counter-based random streams: a random number is a pure function of
//! (stream key, cell index, sample index, dimension), never the state of a shared generator.
//! This is what makes Monte-Carlo tables byte-identical for any thread count or schedule: whichever
//! thread computes cell c, sample s draws the same numbers.
//!
//! Input: 64-bit keys. Output: uniform `f64` in [0, 1) with 53 random bits.
//! The mixing is the SplitMix64 finaliser (Steele, Lea & Flood 2014) applied to a chained combination
//! of the key words; each word passes through a full avalanche before the next is folded in.

/// Identifies one random stream: typically (table content key, cell index).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct StreamKey {
    /// Derived from the table's content key (see [`StreamKey::from_content_key`]).
    pub table: u64,
    /// Cell (or slice) within the table.
    pub cell: u64,
}

impl StreamKey {
    /// Stream for `cell` of the table whose content key is `key`.
    pub fn from_content_key(key: &[u8; 32], cell: u64) -> Self {
        let mut w = [0u8; 8];
        w.copy_from_slice(&key[..8]);
        Self { table: u64::from_le_bytes(w), cell }
    }

    /// The table's word as every stream folds it in first (`mix(table ^ IV)`), for GPU kernels that
    /// rebuild [`StreamKey::uniform`] from it.
    #[cfg_attr(not(feature = "gpu"), allow(dead_code))]
    pub(crate) fn table_word(&self) -> u64 {
        mix(self.table ^ 0x6a09_e667_f3bc_c909)
    }

    /// Uniform value in [0, 1) for sample `sample`, dimension `dim` of this stream.
    #[inline]
    pub fn uniform(&self, sample: u64, dim: u32) -> f64 {
        let h = mix(mix(mix(self.table ^ 0x6a09_e667_f3bc_c909) ^ self.cell) ^ sample.rotate_left(17) ^ u64::from(dim));
        (h >> 11) as f64 * (1.0 / (1u64 << 53) as f64)
    }

    /// The stream of one sample with the key words folded in once: `self.sample(s).uniform(d)` is
    /// bit-identical to `self.uniform(s, d)` at a third of the cost (for walks that draw many
    /// dimensions of one sample).
    #[inline]
    pub fn sample(&self, sample: u64) -> SampleStream {
        SampleStream { h: mix(mix(self.table ^ 0x6a09_e667_f3bc_c909) ^ self.cell) ^ sample.rotate_left(17) }
    }
}

/// The random numbers of one sample of a [`StreamKey`] (see [`StreamKey::sample`]).
#[derive(Debug, Clone, Copy)]
pub struct SampleStream {
    h: u64,
}

impl SampleStream {
    /// Uniform value in [0, 1) for dimension `dim`.
    #[inline]
    pub fn uniform(&self, dim: u32) -> f64 {
        (mix(self.h ^ u64::from(dim)) >> 11) as f64 * (1.0 / (1u64 << 53) as f64)
    }
}

/// The dimensions of one [`SampleStream`] drawn in order: a Monte-Carlo path's random numbers.
#[derive(Debug, Clone, Copy)]
pub struct Draws {
    stream: SampleStream,
    dim: u32,
}

impl Draws {
    /// Starts at dimension 0.
    pub fn new(stream: SampleStream) -> Self {
        Draws { stream, dim: 0 }
    }

    /// The next dimension's uniform value in [0, 1).
    #[inline]
    pub fn draw(&mut self) -> f64 {
        let u = self.stream.uniform(self.dim);
        self.dim = self.dim.wrapping_add(1);
        u
    }
}

/// SplitMix64 finaliser: a bijection on u64 with full avalanche.
#[inline]
fn mix(mut z: u64) -> u64 {
    z = z.wrapping_add(0x9e37_79b9_7f4a_7c15);
    z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    z ^ (z >> 31)
}

#[cfg(test)]
mod tests;
