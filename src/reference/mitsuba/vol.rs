//! Mitsuba's binary grid-volume format (`.vol`, version 3) for `gridvolume`: bytes `VOL`, version 3,
//! int32 encoding 1 (float32), int32 resolution x, y, z, int32 channel count, six float32 bounds
//! (min xyz, max xyz), then float32 values with x fastest, then y, then z, channels interleaved. All
//! little-endian. Mitsuba places the grid with the `gridvolume`'s `to_world` (the unit cube → the box),
//! and treats value `i` as the sample at the centre of cell `i` (trilinear between centres, clamped in the
//! outer half cells); [`sample_cell_centres`] follows that.

/// A grid of `channels` values per cell over an axis-aligned box.
#[derive(Debug, Clone, PartialEq)]
pub struct Grid {
    /// Cells along x, y, z.
    pub resolution: [usize; 3],
    /// Values per cell.
    pub channels: usize,
    /// Box corners \[m\].
    pub bounds: ([f64; 3], [f64; 3]),
    /// `resolution[0]·resolution[1]·resolution[2]·channels` values, x fastest.
    pub data: Vec<f32>,
}

/// Fills a grid over `bounds` with `f(cell centre)` (`channels` values).
pub fn sample_cell_centres(
    bounds: ([f64; 3], [f64; 3]),
    resolution: [usize; 3],
    channels: usize,
    f: impl Fn([f64; 3]) -> Vec<f64>,
) -> Grid {
    let (lo, hi) = bounds;
    let mut data = Vec::with_capacity(resolution.iter().product::<usize>() * channels);
    let centre = |k: usize, i: usize| lo[k] + (i as f64 + 0.5) / resolution[k] as f64 * (hi[k] - lo[k]);
    for z in 0..resolution[2] {
        for y in 0..resolution[1] {
            for x in 0..resolution[0] {
                let v = f([centre(0, x), centre(1, y), centre(2, z)]);
                debug_assert_eq!(v.len(), channels);
                data.extend(v.iter().map(|&c| c as f32));
            }
        }
    }
    Grid { resolution, channels, bounds, data }
}

/// The `.vol` bytes of `grid`.
pub fn encode(grid: &Grid) -> Vec<u8> {
    let mut out = Vec::with_capacity(48 + grid.data.len() * 4);
    out.extend_from_slice(b"VOL");
    out.push(3);
    out.extend_from_slice(&1i32.to_le_bytes());
    for r in grid.resolution {
        out.extend_from_slice(&(r as i32).to_le_bytes());
    }
    out.extend_from_slice(&(grid.channels as i32).to_le_bytes());
    for v in grid.bounds.0.iter().chain(&grid.bounds.1) {
        out.extend_from_slice(&(*v as f32).to_le_bytes());
    }
    for v in &grid.data {
        out.extend_from_slice(&v.to_le_bytes());
    }
    out
}

#[cfg(test)]
mod tests {
    use super::{encode, sample_cell_centres};

    #[test]
    fn header_layout_and_x_fastest_cell_centres() {
        let g = sample_cell_centres(([0.0; 3], [2.0, 4.0, 1.0]), [2, 2, 1], 1, |p| vec![p[0] + 10.0 * p[1]]);
        // Centres x ∈ {0.5, 1.5}, y ∈ {1, 3}.
        assert_eq!(g.data, vec![10.5, 11.5, 30.5, 31.5]);
        let b = encode(&g);
        assert_eq!(&b[..4], b"VOL\x03");
        let int = |o: usize| i32::from_le_bytes(b[o..o + 4].try_into().unwrap());
        assert_eq!([int(4), int(8), int(12), int(16), int(20)], [1, 2, 2, 1, 1]);
        let f = |o: usize| f32::from_le_bytes(b[o..o + 4].try_into().unwrap());
        assert_eq!([f(24), f(36), f(40), f(44)], [0.0, 2.0, 4.0, 1.0]);
        assert_eq!(b.len(), 48 + 16);
        assert_eq!(f(48 + 4), 11.5);
    }
}
