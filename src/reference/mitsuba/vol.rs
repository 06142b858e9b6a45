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
mod tests;
