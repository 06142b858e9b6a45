//! Line plots rendered to PNG files.
//!
//! Input: a [`Plot`] — title, axis labels, a linear or log10 scale per axis,
//! and any number of named [`Series`] of `(x, y)` points. Output: a PNG image
//! of `width × height` pixels written atomically to a path by [`write_png`],
//! plus a [`PlotOutcome`] counting the points drawn and the points skipped.
//!
//! What is drawn: the title, both axes with their labels and tick labels
//! (log axes get decade ticks labelled like `1e-3`), a line plus markers per
//! series in distinct colours and marker shapes, and a legend naming the
//! series (placed in the plot corner with the fewest points; as many entries
//! as fit, the rest summarised as `+N more`; long names shortened with `…`).
//! Axis ranges come from the finite data with a small margin (a fraction of
//! a decade on log axes); a degenerate range (a single point, or all values
//! equal) is widened.
//!
//! Points are never reordered: each series is drawn in the order given. A
//! point is skipped (and counted in [`PlotOutcome::points_skipped`]) when
//! either coordinate is NaN or infinite, or is zero or negative on a log
//! axis; the line of a series is broken where a point was skipped.
//!
//! A plot with no series, empty series, or only skipped points is not an
//! error: it is written as a valid PNG with the title, axes, ticks and
//! (when there are series) the legend, over a default range (0–1 on a
//! linear axis, 1–10 on a log axis). Errors are returned, never panics, for
//! a bad size or path, data whose linear span overflows `f64`, and drawing,
//! encoding or file-system failures.
//!
//! Text uses the DejaVu Sans font embedded through the `dejavu` crate, which
//! is registered with plotters as the `sans-serif` family on first use, so
//! no system font is needed. Rendering is deterministic: the same input
//! gives the same PNG bytes.
//!
//! The image is rendered into an in-memory RGB buffer, encoded to PNG in
//! memory with the `image` crate, and written with
//! [`crate::cache::write_atomic`] (temporary file in the destination
//! folder, fsync, rename), so an interrupted run never leaves a partial PNG
//! at `path`.
//!
//! Layout: this file holds the public API and the file writing; `axis`
//! computes axis ranges, ticks and labels; `render` draws into the pixel
//! buffer.

use std::path::{Path, PathBuf};
use std::sync::OnceLock;

use image::ImageEncoder;
use image::codecs::png::PngEncoder;
use plotters::style::{FontStyle, register_font};

use crate::cache::{CacheError, write_atomic};

use render::{RenderError, render_rgb};

mod axis;
mod render;
#[cfg(test)]
mod tests;

/// Smallest accepted image side, in pixels.
pub const MIN_SIDE: u32 = 200;
/// Largest accepted image side, in pixels.
pub const MAX_SIDE: u32 = 8192;

/// How an axis maps data values to positions.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Scale {
    /// Evenly spaced values.
    #[default]
    Linear,
    /// Evenly spaced decades; only values above zero can be shown.
    Log10,
}

/// One named line of `(x, y)` points, drawn in the order given.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Series {
    /// Name shown in the legend.
    pub name: String,
    /// Data points as `(x, y)`.
    pub points: Vec<(f64, f64)>,
}

/// Everything needed to draw one plot.
#[derive(Debug, Clone, Copy)]
pub struct Plot<'a> {
    /// Title drawn above the plot area (nothing is drawn when empty).
    pub title: &'a str,
    /// Label of the horizontal axis.
    pub x_label: &'a str,
    /// Label of the vertical axis.
    pub y_label: &'a str,
    /// Scale of the horizontal axis.
    pub x_scale: Scale,
    /// Scale of the vertical axis.
    pub y_scale: Scale,
    /// The series to draw, each in its own colour and marker shape.
    pub series: &'a [Series],
    /// Image width in pixels, within [`MIN_SIDE`]`..=`[`MAX_SIDE`].
    pub width: u32,
    /// Image height in pixels, within [`MIN_SIDE`]`..=`[`MAX_SIDE`].
    pub height: u32,
}

/// What [`write_png`] drew.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct PlotOutcome {
    /// Points drawn, over all series.
    pub points_drawn: usize,
    /// Points left out, over all series: a NaN or infinite coordinate, or a
    /// coordinate that is zero or negative on a log axis.
    pub points_skipped: usize,
}

/// Why a plot could not be written. Every message names the destination
/// (for [`PlotError::Io`], through the wrapped [`CacheError`]).
#[derive(thiserror::Error, Debug)]
pub enum PlotError {
    /// The destination has no file name (such as `/` or `..`).
    #[error("cannot write plot to {}: the path does not name a file", path.display())]
    InvalidPath {
        /// The destination asked for.
        path: PathBuf,
    },
    /// Width or height is outside [`MIN_SIDE`]`..=`[`MAX_SIDE`].
    #[error(
        "cannot write plot to {}: image size {width}x{height} is outside the supported \
         {MIN_SIDE}..={MAX_SIDE} pixels per side",
        path.display()
    )]
    InvalidSize {
        /// The destination asked for.
        path: PathBuf,
        /// Width asked for.
        width: u32,
        /// Height asked for.
        height: u32,
    },
    /// The data cannot be placed on an axis (e.g. values so large that the
    /// axis span overflows).
    #[error("cannot write plot to {}: {reason}", path.display())]
    InvalidRange {
        /// The destination asked for.
        path: PathBuf,
        /// What is wrong with the data.
        reason: String,
    },
    /// The embedded DejaVu Sans font could not be registered with plotters.
    #[error(
        "cannot write plot to {}: the embedded DejaVu Sans font could not be loaded",
        path.display()
    )]
    Font {
        /// The destination asked for.
        path: PathBuf,
    },
    /// Plotters failed while drawing into the in-memory image.
    #[error("cannot write plot to {}: drawing failed: {message}", path.display())]
    Draw {
        /// The destination asked for.
        path: PathBuf,
        /// Plotters' description of the failure.
        message: String,
    },
    /// Encoding the rendered pixels as PNG (in memory) failed.
    #[error("cannot write plot to {}: PNG encoding failed: {message}", path.display())]
    Encode {
        /// The destination asked for.
        path: PathBuf,
        /// The encoder's description of the failure.
        message: String,
    },
    /// Writing the file failed (creating, writing, flushing or renaming the
    /// temporary file next to the destination). The message of `source`
    /// names the file.
    #[error("plot not written: {source}")]
    Io {
        /// The destination asked for.
        path: PathBuf,
        /// The failed atomic write.
        #[source]
        source: CacheError,
    },
}

/// Draws `plot` and writes it as a PNG at `path`, replacing any existing file.
///
/// The image is rendered and PNG-encoded in memory, then written with
/// [`write_atomic`], so `path` either keeps its old contents or gets the
/// complete new image. The file is PNG whatever the extension of `path`.
/// Returns how many points were drawn and skipped; see the module docs for
/// which points are skipped and for how a plot without drawable points is
/// handled.
pub fn write_png(path: &Path, plot: &Plot) -> Result<PlotOutcome, PlotError> {
    if path.file_name().is_none() {
        return Err(PlotError::InvalidPath { path: path.to_path_buf() });
    }
    let (width, height) = (plot.width, plot.height);
    if !(MIN_SIDE..=MAX_SIDE).contains(&width) || !(MIN_SIDE..=MAX_SIDE).contains(&height) {
        return Err(PlotError::InvalidSize { path: path.to_path_buf(), width, height });
    }
    if !ensure_font() {
        return Err(PlotError::Font { path: path.to_path_buf() });
    }

    let (pixels, outcome) = render_rgb(plot).map_err(|e| match e {
        RenderError::Range(reason) => PlotError::InvalidRange { path: path.to_path_buf(), reason },
        RenderError::Draw(message) => PlotError::Draw { path: path.to_path_buf(), message },
    })?;
    let png = encode_png(&pixels, width, height)
        .map_err(|message| PlotError::Encode { path: path.to_path_buf(), message })?;
    write_atomic(path, &png).map_err(|source| PlotError::Io { path: path.to_path_buf(), source })?;
    Ok(outcome)
}

/// Encodes an RGB8 pixel buffer of `width × height` as PNG bytes (default
/// compression and adaptive filtering, no timestamp: deterministic).
/// Returns the encoder's message on failure.
fn encode_png(pixels: &[u8], width: u32, height: u32) -> Result<Vec<u8>, String> {
    // The encoder panics on a length mismatch; report it as an error instead.
    let expected = u64::from(width) * u64::from(height) * 3;
    if pixels.len() as u64 != expected {
        return Err(format!("pixel buffer holds {} bytes, expected {expected}", pixels.len()));
    }
    let mut png = Vec::new();
    PngEncoder::new(&mut png).write_image(pixels, width, height, image::ColorType::Rgb8).map_err(|e| e.to_string())?;
    Ok(png)
}

/// Registers the embedded DejaVu Sans as plotters' `sans-serif` family,
/// once per process. Returns whether it is available.
fn ensure_font() -> bool {
    static REGISTERED: OnceLock<bool> = OnceLock::new();
    *REGISTERED.get_or_init(|| {
        let regular = register_font("sans-serif", FontStyle::Normal, dejavu::sans::regular());
        let bold = register_font("sans-serif", FontStyle::Bold, dejavu::sans::bold());
        regular.is_ok() && bold.is_ok()
    })
}
