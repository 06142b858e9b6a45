//! Colour: Rec. 709 luminance, the one weighting of linear RGB every technique uses (importance of
//! lights and texels, luminance-weighted spreads, errors and exposure).
//!
//! **Input → output.** A linear RGB triple → its relative luminance `Y = 0.2126 R + 0.7152 G + 0.0722 B`
//! (ITU-R BT.709-6 Item 3.3), summed left to right.

/// Per-channel values (linear RGB, or a per-channel coefficient).
pub type Rgb = [f64; 3];

/// Rec. 709 / sRGB luminance weights (ITU-R BT.709-6 Item 3.3).
pub const REC709_LUMA: [f64; 3] = [0.2126, 0.7152, 0.0722];

/// Relative luminance of a linear RGB triple.
pub fn luminance(c: [f64; 3]) -> f64 {
    REC709_LUMA[0] * c[0] + REC709_LUMA[1] * c[1] + REC709_LUMA[2] * c[2]
}

/// [`luminance`] in single precision (weights rounded once from their decimal values to f32).
pub fn luminance_f32(c: [f32; 3]) -> f32 {
    0.2126 * c[0] + 0.7152 * c[1] + 0.0722 * c[2]
}

#[cfg(test)]
mod tests;
