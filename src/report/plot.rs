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
//! The file is written atomically: the image is rendered into memory,
//! encoded to a temporary file in the destination directory, flushed to disk
//! and renamed over the destination, so an interrupted run never leaves a
//! partial PNG at `path` (at worst a stray hidden `.*.tmp.png` file).

use std::ffi::OsString;
use std::fs::{self, File, OpenOptions};
use std::io;
use std::path::{Path, PathBuf};
use std::sync::OnceLock;
use std::sync::atomic::{AtomicU64, Ordering};

use plotters::coord::Shift;
use plotters::coord::ranged1d::{KeyPointHint, NoDefaultFormatting, ValueFormatter};
use plotters::element::ComposedElement;
use plotters::prelude::*;
use plotters::style::{FontStyle, register_font};

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

/// Why a plot could not be written. Every message names the destination.
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
    /// Encoding the PNG into the temporary file failed.
    #[error(
        "cannot write plot to {}: encoding PNG into {} failed: {message}",
        path.display(),
        temp.display()
    )]
    Encode {
        /// The destination asked for.
        path: PathBuf,
        /// The temporary file being written.
        temp: PathBuf,
        /// The encoder's description of the failure.
        message: String,
    },
    /// A file-system operation failed.
    #[error("cannot write plot to {}: {action}: {source}", path.display())]
    Io {
        /// The destination asked for.
        path: PathBuf,
        /// What was being done, naming the file involved.
        action: String,
        /// The underlying error.
        #[source]
        source: io::Error,
    },
}

/// Draws `plot` and writes it as a PNG at `path`, replacing any existing file.
///
/// The image is rendered in memory, encoded into a hidden temporary file in
/// the same directory, flushed, and renamed onto `path`, so `path` either
/// keeps its old contents or gets the complete new image. The file is PNG
/// whatever the extension of `path`. Returns how many points were drawn and
/// skipped; see the module docs for which points are skipped and for how
/// a plot without drawable points is handled.
pub fn write_png(path: &Path, plot: &Plot) -> Result<PlotOutcome, PlotError> {
    let file_name = path.file_name().ok_or_else(|| PlotError::InvalidPath { path: path.to_path_buf() })?;
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

    let dir = match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
        _ => PathBuf::from("."),
    };
    let temp = TempFile::create(&dir, file_name).map_err(|(temp, source)| PlotError::Io {
        path: path.to_path_buf(),
        action: format!("creating temporary file {}", temp.display()),
        source,
    })?;

    encode_png(&temp.path, &pixels, width, height).map_err(|message| PlotError::Encode {
        path: path.to_path_buf(),
        temp: temp.path.clone(),
        message,
    })?;
    // Opened for writing: Windows refuses to flush a read-only handle.
    OpenOptions::new().write(true).open(&temp.path).and_then(|f| f.sync_all()).map_err(|source| PlotError::Io {
        path: path.to_path_buf(),
        action: format!("flushing temporary file {}", temp.path.display()),
        source,
    })?;
    fs::rename(&temp.path, path).map_err(|source| PlotError::Io {
        path: path.to_path_buf(),
        action: format!("renaming temporary file {} onto it", temp.path.display()),
        source,
    })?;
    temp.disarm();
    // Make the rename itself durable where directories can be opened and
    // synced (Unix). Failure here does not undo a completed rename.
    if let Ok(d) = File::open(&dir) {
        let _ = d.sync_all();
    }
    Ok(outcome)
}

// ---------------------------------------------------------------------------
// Temporary file handling

/// A temporary file that is removed on drop unless disarmed.
struct TempFile {
    path: PathBuf,
    armed: bool,
}

impl TempFile {
    /// Creates (exclusively) a fresh hidden `.png` file in `dir` for `name`.
    /// The `.png` extension is what plotters' encoder keys the format on.
    fn create(dir: &Path, name: &std::ffi::OsStr) -> Result<TempFile, (PathBuf, io::Error)> {
        static COUNTER: AtomicU64 = AtomicU64::new(0);
        let mut attempt = 0;
        loop {
            let n = COUNTER.fetch_add(1, Ordering::Relaxed);
            let mut temp_name = OsString::from(".");
            temp_name.push(name);
            temp_name.push(format!(".{}-{n}.tmp.png", std::process::id()));
            let path = dir.join(temp_name);
            match OpenOptions::new().write(true).create_new(true).open(&path) {
                Ok(_) => return Ok(TempFile { path, armed: true }),
                Err(e) if e.kind() == io::ErrorKind::AlreadyExists && attempt < 16 => {
                    attempt += 1;
                }
                Err(e) => return Err((path, e)),
            }
        }
    }

    /// Keeps the file: it has been renamed into place.
    fn disarm(mut self) {
        self.armed = false;
    }
}

impl Drop for TempFile {
    fn drop(&mut self) {
        if self.armed {
            let _ = fs::remove_file(&self.path);
        }
    }
}

/// Encodes an RGB8 pixel buffer as a PNG file at `temp` with plotters'
/// bitmap encoder (the `image` crate). Returns the encoder's message on
/// failure.
fn encode_png(temp: &Path, pixels: &[u8], width: u32, height: u32) -> Result<(), String> {
    let mut backend = BitMapBackend::new(temp, (width, height));
    backend.blit_bitmap((0, 0), (width, height), pixels).map_err(|e| e.to_string())?;
    backend.present().map_err(|e| e.to_string())
}

// ---------------------------------------------------------------------------
// Fonts

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

// ---------------------------------------------------------------------------
// Rendering

/// Why rendering failed, before a path is attached.
#[derive(Debug)]
enum RenderError {
    /// The data cannot be placed on an axis.
    Range(String),
    /// Plotters reported a drawing failure.
    Draw(String),
}

/// Converts a plotters drawing error into a [`RenderError`].
fn draw_err<E: std::error::Error + Send + Sync>(e: DrawingAreaErrorKind<E>) -> RenderError {
    RenderError::Draw(e.to_string())
}

/// Series colours: the Okabe–Ito palette (minus yellow) plus two extras,
/// all readable on white.
const PALETTE: [RGBColor; 8] = [
    RGBColor(0, 114, 178),
    RGBColor(213, 94, 0),
    RGBColor(0, 158, 115),
    RGBColor(204, 121, 167),
    RGBColor(230, 159, 0),
    RGBColor(86, 180, 233),
    RGBColor(40, 40, 40),
    RGBColor(120, 70, 160),
];

/// Marker shapes, cycled at a different period than colours so that
/// colour + shape stays distinct for the first 40 series.
#[derive(Debug, Clone, Copy)]
enum Shape {
    Circle,
    Square,
    TriangleUp,
    Diamond,
    TriangleDown,
}

const SHAPES: [Shape; 5] = [Shape::Circle, Shape::Square, Shape::TriangleUp, Shape::Diamond, Shape::TriangleDown];

/// A marker, optionally with a line through it: a circle or a polygon
/// (whichever is unused is transparent or empty) on a short path, all in
/// pixel offsets from the anchor point. One concrete type serves every
/// shape because plotters' boxed `DynElement` would need a `'static`
/// backend, which one drawing into a borrowed buffer is not.
type Glyph<C, DB> = ComposedElement<
    C,
    DB,
    PathElement<(i32, i32)>,
    ComposedElement<(i32, i32), DB, Circle<(i32, i32), u32>, Polygon<(i32, i32)>>,
>;

/// Builds a marker of `shape` and half-size `r` pixels centred on `at`,
/// optionally with a horizontal line of `(half_length, width)` pixels
/// through it (used for legend entries).
fn glyph<DB: DrawingBackend, C>(
    at: C,
    shape: Shape,
    r: i32,
    colour: RGBColor,
    line: Option<(i32, u32)>,
) -> Glyph<C, DB> {
    let path = match line {
        Some((half, width)) => PathElement::new(vec![(-half, 0), (half, 0)], colour.stroke_width(width)),
        None => PathElement::new(Vec::new(), colour),
    };
    let fill = colour.filled();
    let s = r + 1;
    let (circle_style, vertices) = match shape {
        Shape::Circle => (fill, Vec::new()),
        Shape::Square => (TRANSPARENT.filled(), vec![(-r, -r), (r, -r), (r, r), (-r, r)]),
        Shape::TriangleUp => (TRANSPARENT.filled(), vec![(0, -s), (s, s - 1), (-s, s - 1)]),
        Shape::Diamond => (TRANSPARENT.filled(), vec![(0, -s), (s, 0), (0, s), (-s, 0)]),
        Shape::TriangleDown => (TRANSPARENT.filled(), vec![(0, s), (s, 1 - s), (-s, 1 - s)]),
    };
    EmptyElement::at(at) + path + Circle::new((0, 0), r.max(1) as u32, circle_style) + Polygon::new(vertices, fill)
}

/// Maps a data value into plot space for `scale`, or `None` when the value
/// cannot be shown on that axis.
fn to_plot_space(scale: Scale, v: f64) -> Option<f64> {
    match scale {
        Scale::Linear => v.is_finite().then_some(v),
        Scale::Log10 => (v.is_finite() && v > 0.0).then(|| v.log10()),
    }
}

/// One axis, in plot space (log10 of the data on a log axis).
#[derive(Debug, Clone, PartialEq)]
struct Axis {
    lo: f64,
    hi: f64,
    /// Labelled tick positions, ascending.
    ticks: Vec<f64>,
    /// Label of each tick.
    labels: Vec<String>,
    /// Unlabelled minor grid positions.
    minor: Vec<f64>,
}

impl Axis {
    /// Label of the tick at `v` (an exact tick value handed back by plotters).
    fn label(&self, v: f64) -> String {
        self.ticks
            .iter()
            .position(|t| t.to_bits() == v.to_bits())
            .and_then(|i| self.labels.get(i).cloned())
            .unwrap_or_else(|| format!("{v}"))
    }
}

/// The axis is its own plotters coordinate: it maps plot-space values
/// linearly onto pixels and hands plotters our ticks and labels.
impl Ranged for Axis {
    type FormatOption = NoDefaultFormatting;
    type ValueType = f64;

    fn map(&self, value: &f64, limit: (i32, i32)) -> i32 {
        let frac = (*value - self.lo) / (self.hi - self.lo);
        let pixels = f64::from(limit.1) - f64::from(limit.0);
        // `as` saturates (and maps NaN to 0), so this cannot overflow.
        (f64::from(limit.0) + pixels * frac).round() as i32
    }

    fn key_points<Hint: KeyPointHint>(&self, hint: Hint) -> Vec<f64> {
        if hint.weight().allow_light_points() { self.minor.clone() } else { self.ticks.clone() }
    }

    fn range(&self) -> std::ops::Range<f64> {
        self.lo..self.hi
    }
}

impl ValueFormatter<f64> for Axis {
    fn format(value: &f64) -> String {
        format!("{value}")
    }

    fn format_ext(&self, value: &f64) -> String {
        self.label(*value)
    }
}

/// Builds an axis for the data span `data` (plot space, `None` when there
/// is no drawable point), aiming at about `target` labelled ticks.
fn build_axis(scale: Scale, data: Option<(f64, f64)>, target: usize) -> Result<Axis, String> {
    match scale {
        Scale::Linear => linear_axis(data, target),
        Scale::Log10 => Ok(log_axis(data, target)),
    }
}

fn linear_axis(data: Option<(f64, f64)>, target: usize) -> Result<Axis, String> {
    let (mut lo, mut hi) = data.unwrap_or((0.0, 1.0));
    let magnitude = lo.abs().max(hi.abs());
    if hi - lo <= magnitude * 1e-12 {
        let half = if magnitude > 0.0 { magnitude * 0.1 } else { 1.0 };
        lo -= half;
        hi += half;
    }
    let pad = 0.05 * (hi - lo);
    lo -= pad;
    hi += pad;
    if !(lo.is_finite() && hi.is_finite() && (hi - lo).is_finite()) {
        return Err(format!("values up to {magnitude:e} are too large for a linear axis"));
    }
    let (ticks, labels) = linear_ticks(lo, hi, target);
    Ok(Axis { lo, hi, ticks, labels, minor: Vec::new() })
}

fn log_axis(data: Option<(f64, f64)>, target: usize) -> Axis {
    let (mut lo, mut hi) = data.unwrap_or((0.0, 1.0));
    if hi - lo < 1e-9 {
        lo -= 0.5;
        hi += 0.5;
    }
    let pad = (0.05 * (hi - lo)).max(0.1);
    lo -= pad;
    hi += pad;

    // Plot-space values lie within about -324..309, so these fit in i32.
    let first = lo.ceil() as i32;
    let last = hi.floor() as i32;
    let decades = (last - first + 1).max(0) as usize;
    let mut ticks = Vec::new();
    let mut labels = Vec::new();
    let mut minor = Vec::new();

    if decades >= 2 {
        // Label every `stride`-th decade (a round number of decades), with
        // unlabelled grid lines every `minor_stride` decades in between, or
        // at 2..9 within each decade when every decade is labelled.
        const STRIDES: [(i32, i32); 12] = [
            (1, 1),
            (2, 1),
            (3, 1),
            (5, 1),
            (10, 2),
            (20, 5),
            (25, 5),
            (50, 10),
            (100, 20),
            (200, 50),
            (250, 50),
            (500, 100),
        ];
        let (stride, minor_stride) = STRIDES
            .iter()
            .copied()
            .find(|&(stride, _)| decades.div_ceil(stride as usize) <= target.max(2))
            .unwrap_or((1000, 200));
        for k in first..=last {
            if k.rem_euclid(stride) == 0 {
                ticks.push(f64::from(k));
                labels.push(format!("1e{k}"));
            } else if k.rem_euclid(minor_stride) == 0 {
                minor.push(f64::from(k));
            }
        }
        if stride == 1 {
            for k in (first - 1)..=last {
                for m in 2..=9 {
                    let t = f64::from(k) + f64::from(m).log10();
                    if (lo..=hi).contains(&t) {
                        minor.push(t);
                    }
                }
            }
        }
    } else {
        // Under two decades: ticks at 1..9 (or 1, 2, 5) times a power of
        // ten, labelled plainly for moderate exponents ("0.02", "300") and
        // as "2e-5" otherwise.
        let candidates = |ms: &[u32]| -> Vec<(f64, String)> {
            let mut out = Vec::new();
            for k in (lo.floor() as i32)..=(hi.ceil() as i32) {
                for &m in ms {
                    let t = f64::from(k) + f64::from(m).log10();
                    if (lo..=hi).contains(&t) {
                        let label = if (-3..=4).contains(&k) {
                            let decimals = (-k).max(0) as usize;
                            format!("{:.decimals$}", f64::from(m) * 10f64.powi(k))
                        } else {
                            format!("{m}e{k}")
                        };
                        out.push((t, label));
                    }
                }
            }
            out
        };
        let mut chosen = candidates(&[1, 2, 3, 4, 5, 6, 7, 8, 9]);
        if chosen.len() > target.max(2) {
            chosen = candidates(&[1, 2, 5]);
        }
        if chosen.len() < 3 {
            // A narrow range: nice linear values, placed on the log axis.
            let (vs, ls) = linear_ticks(10f64.powf(lo), 10f64.powf(hi), target);
            let linear: Vec<(f64, String)> =
                vs.into_iter().zip(ls).filter(|(v, _)| *v > 0.0).map(|(v, l)| (v.log10(), l)).collect();
            if linear.len() > chosen.len() {
                chosen = linear;
            }
        }
        for (t, l) in chosen {
            ticks.push(t);
            labels.push(l);
        }
    }
    Axis { lo, hi, ticks, labels, minor }
}

/// Nice ticks (1, 2 or 5 × 10^k steps) within `lo..=hi`, at most about
/// `target`, with their labels.
fn linear_ticks(lo: f64, hi: f64, target: usize) -> (Vec<f64>, Vec<String>) {
    let span = hi - lo;
    let raw = span / target.max(1) as f64;
    if !(raw.is_finite() && raw > 0.0) {
        return (Vec::new(), Vec::new());
    }
    let magnitude = 10f64.powf(raw.log10().floor());
    let norm = raw / magnitude;
    let step = if norm <= 1.0 {
        1.0
    } else if norm <= 2.0 {
        2.0
    } else if norm <= 5.0 {
        5.0
    } else {
        10.0
    } * magnitude;
    if !(step.is_finite() && step > 0.0) {
        return (Vec::new(), Vec::new());
    }
    let first = (lo / step).ceil();
    let last = (hi / step).floor();
    // Guard against precision loss far from zero: at most 100 ticks.
    if !(first.is_finite() && last.is_finite()) || last - first > 100.0 || last < first {
        return (Vec::new(), Vec::new());
    }
    let biggest = lo.abs().max(hi.abs());
    let step_exp = step.log10().floor() as i32;
    let scientific = biggest >= 1e6 || (step < 1e-3 && biggest < 1e-2) || step < 1e-5;
    let mut ticks = Vec::new();
    let mut labels = Vec::new();
    let mut k = first;
    while k <= last {
        let mut v = k * step;
        if v.abs() < step * 1e-9 {
            v = 0.0;
        }
        ticks.push(v);
        labels.push(format_linear(v, step_exp, biggest, scientific));
        k += 1.0;
    }
    (ticks, labels)
}

/// Formats a linear tick value `v` for ticks spaced `10^step_exp`-ish apart.
fn format_linear(v: f64, step_exp: i32, biggest: f64, scientific: bool) -> String {
    if v == 0.0 {
        return "0".to_string();
    }
    if scientific {
        let lead = biggest.log10().floor() as i32;
        let digits = lead.saturating_sub(step_exp).clamp(0, 15) as usize;
        let s = format!("{v:.digits$e}");
        match s.split_once('e') {
            Some((mantissa, exp)) => {
                let mantissa = if mantissa.contains('.') {
                    mantissa.trim_end_matches('0').trim_end_matches('.')
                } else {
                    mantissa
                };
                format!("{mantissa}e{exp}")
            }
            None => s,
        }
    } else {
        let decimals = (-step_exp).clamp(0, 15) as usize;
        format!("{v:.decimals$}")
    }
}

/// Which legend corner overlaps the fewest points (`pts` in 0..1 plot
/// fractions), preferring upper right, upper left, lower right, lower left.
fn legend_corner(pts: &[(f64, f64)]) -> SeriesLabelPosition {
    let corners = [
        (SeriesLabelPosition::UpperRight, true, true),
        (SeriesLabelPosition::UpperLeft, false, true),
        (SeriesLabelPosition::LowerRight, true, false),
        (SeriesLabelPosition::LowerLeft, false, false),
    ];
    let mut best = (usize::MAX, SeriesLabelPosition::UpperRight);
    for (pos, right, upper) in corners {
        let count = pts
            .iter()
            .filter(|&&(u, v)| {
                let in_x = if right { u >= 0.55 } else { u <= 0.45 };
                let in_y = if upper { v >= 0.6 } else { v <= 0.4 };
                in_x && in_y
            })
            .count();
        if count < best.0 {
            best = (count, pos);
        }
    }
    best.1
}

/// `text` on one line (control characters become spaces), shortened with
/// a trailing `…` until it is at most `max_w` pixels wide in `style`.
fn fit_text<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    text: &str,
    style: &TextStyle,
    max_w: f64,
) -> Result<String, RenderError> {
    let mut chars: Vec<char> = text.chars().take(200).map(|c| if c.is_control() { ' ' } else { c }).collect();
    let mut candidate: String = chars.iter().collect();
    let truncated = chars.len() < text.chars().count();
    if truncated {
        candidate.push('…');
    }
    loop {
        let (w, _) = area.estimate_text_size(&candidate, style).map_err(draw_err)?;
        if f64::from(w) <= max_w || chars.is_empty() {
            return Ok(candidate);
        }
        chars.pop();
        candidate = chars.iter().collect();
        candidate.push('…');
    }
}

/// Renders `plot` into a fresh RGB8 buffer of `width × height × 3` bytes.
/// The font must already be registered.
fn render_rgb(plot: &Plot) -> Result<(Vec<u8>, PlotOutcome), RenderError> {
    let (width, height) = (plot.width, plot.height);
    let len = (width as usize)
        .checked_mul(height as usize)
        .and_then(|n| n.checked_mul(3))
        .ok_or_else(|| RenderError::Range(format!("image size {width}x{height} too large")))?;
    let mut buf = vec![255u8; len];

    // Map points into plot space; split each series into unbroken runs.
    let mut outcome = PlotOutcome::default();
    let mut runs: Vec<Vec<Vec<(f64, f64)>>> = Vec::with_capacity(plot.series.len());
    let mut x_span: Option<(f64, f64)> = None;
    let mut y_span: Option<(f64, f64)> = None;
    let widen = |span: &mut Option<(f64, f64)>, v: f64| {
        *span = Some(match *span {
            Some((lo, hi)) => (lo.min(v), hi.max(v)),
            None => (v, v),
        });
    };
    for series in plot.series {
        let mut series_runs = vec![Vec::new()];
        for &(x, y) in &series.points {
            match (to_plot_space(plot.x_scale, x), to_plot_space(plot.y_scale, y)) {
                (Some(px), Some(py)) => {
                    outcome.points_drawn += 1;
                    widen(&mut x_span, px);
                    widen(&mut y_span, py);
                    if let Some(run) = series_runs.last_mut() {
                        run.push((px, py));
                    }
                }
                _ => {
                    outcome.points_skipped += 1;
                    if series_runs.last().is_some_and(|r| !r.is_empty()) {
                        series_runs.push(Vec::new());
                    }
                }
            }
        }
        series_runs.retain(|r| !r.is_empty());
        runs.push(series_runs);
    }

    let s = (f64::from(width.min(height)) / 600.0).clamp(0.5, 4.0);
    let px = |v: f64| (v * s).round().max(1.0);
    // Font sizes are even pixel counts: plotters' ab_glyph text path
    // truncates `size / 2 + glyph_top` to whole pixels, which puts glyphs
    // such as `.` and `-` a pixel off the baseline at odd sizes.
    let font_px = |v: f64| ((v * s / 2.0).round() * 2.0).max(8.0);
    let x_target = ((f64::from(width) / (110.0 * s)) as usize).clamp(2, 10);
    let y_target = ((f64::from(height) / (70.0 * s)) as usize).clamp(2, 10);
    let x_axis = build_axis(plot.x_scale, x_span, x_target).map_err(RenderError::Range)?;
    let y_axis = build_axis(plot.y_scale, y_span, y_target).map_err(RenderError::Range)?;

    {
        let root: DrawingArea<BitMapBackend, Shift> =
            BitMapBackend::with_buffer(&mut buf, (width, height)).into_drawing_area();
        root.fill(&WHITE).map_err(draw_err)?;

        let (title_px, desc_px, tick_px) = (font_px(22.0), font_px(16.0), font_px(14.0));
        let title_font = ("sans-serif", title_px).into_font();
        let desc_font = ("sans-serif", desc_px).into_font();
        let tick_font = ("sans-serif", tick_px).into_font();
        let legend_font = ("sans-serif", font_px(14.0)).into_font();

        let tick_style = TextStyle::from(tick_font.clone());
        let mut widest = 0u32;
        for label in &y_axis.labels {
            let (w, _) = root.estimate_text_size(label, &tick_style).map_err(draw_err)?;
            widest = widest.max(w);
        }
        let y_area = f64::from(widest) + desc_px * 1.3 + px(18.0);
        let x_area = tick_px * 1.3 + desc_px * 1.3 + px(18.0);

        let mut builder = ChartBuilder::on(&root);
        builder.margin(px(12.0)).margin_right(px(20.0)).x_label_area_size(x_area).y_label_area_size(y_area);
        if !plot.title.is_empty() {
            builder.caption(plot.title, title_font);
        }
        let mut chart = builder.build_cartesian_2d(x_axis.clone(), y_axis.clone()).map_err(draw_err)?;

        chart
            .configure_mesh()
            .x_desc(plot.x_label)
            .y_desc(plot.y_label)
            .label_style(tick_font)
            .axis_desc_style(desc_font)
            .bold_line_style(BLACK.mix(0.18))
            .light_line_style(BLACK.mix(0.06))
            .axis_style(BLACK.stroke_width(px(1.0) as u32))
            .set_all_tick_mark_size(px(5.0) as u32)
            .draw()
            .map_err(draw_err)?;

        // Legend: as many entries as fit the plot area's height (the rest
        // summarised as "+N more"), names shortened to fit 45% of its width.
        let legend_style = TextStyle::from(legend_font.clone());
        let legend_margin = px(8.0);
        let legend_glyph_area = px(30.0);
        let (area_w, area_h) = chart.plotting_area().dim_in_pixel();
        let entry_h = legend_font.get_size() * 1.25;
        let fit = ((f64::from(area_h) - 2.0 * legend_margin - 4.0) / entry_h).max(0.0) as usize;
        let labelled = if plot.series.len() <= fit { plot.series.len() } else { fit.saturating_sub(1) };
        let max_name_w = (0.45 * f64::from(area_w) - legend_glyph_area - 2.0 * legend_margin).max(0.0);

        let line_width = px(2.0) as u32;
        let marker = px(3.5) as i32;
        let legend_half = px(11.0) as i32;
        for (i, (series, series_runs)) in plot.series.iter().zip(&runs).enumerate() {
            let colour = PALETTE[i % PALETTE.len()];
            let shape = SHAPES[i % SHAPES.len()];
            for run in series_runs {
                chart
                    .draw_series(std::iter::once(PathElement::new(run.clone(), colour.stroke_width(line_width))))
                    .map_err(draw_err)?;
            }
            let points = series_runs.iter().flatten().copied();
            let anno = chart.draw_series(points.map(|p| glyph(p, shape, marker, colour, None))).map_err(draw_err)?;
            if i < labelled {
                let name = fit_text(&root, &series.name, &legend_style, max_name_w)?;
                anno.label(name).legend(move |c| glyph(c, shape, marker, colour, Some((legend_half, line_width))));
            }
        }
        let hidden = plot.series.len() - labelled;
        if hidden > 0 && fit > 0 {
            chart
                .draw_series(std::iter::empty::<PathElement<(f64, f64)>>())
                .map_err(draw_err)?
                .label(format!("+{hidden} more"));
        }

        if fit > 0 && !plot.series.is_empty() {
            let fractions: Vec<(f64, f64)> = runs
                .iter()
                .flatten()
                .flatten()
                .map(|&(x, y)| ((x - x_axis.lo) / (x_axis.hi - x_axis.lo), (y - y_axis.lo) / (y_axis.hi - y_axis.lo)))
                .collect();
            chart
                .configure_series_labels()
                .position(legend_corner(&fractions))
                .margin(legend_margin)
                .legend_area_size(legend_glyph_area)
                .label_font(legend_font)
                .background_style(WHITE.mix(0.9))
                .border_style(BLACK.mix(0.5))
                .draw()
                .map_err(draw_err)?;
        }
        root.present().map_err(draw_err)?;
    }
    Ok((buf, outcome))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tempdir(tag: &str) -> PathBuf {
        let dir = std::env::temp_dir().join(format!("voltab-plot-test-{}-{tag}", std::process::id()));
        let _ = fs::remove_dir_all(&dir);
        fs::create_dir_all(&dir).expect("create test dir");
        dir
    }

    fn sample_series() -> Vec<Series> {
        (0..3)
            .map(|s| Series {
                name: format!("order {}", s + 1),
                points: (0..12)
                    .map(|i| {
                        let t = 10f64.powf(-3.0 + 0.25 * f64::from(i));
                        (t, 0.5 * t.powi(s + 1))
                    })
                    .collect(),
            })
            .collect()
    }

    fn plot_of(series: &[Series], x: Scale, y: Scale) -> Plot<'_> {
        Plot {
            title: "Error vs time step",
            x_label: "dt [s]",
            y_label: "max abs error",
            x_scale: x,
            y_scale: y,
            series,
            width: 640,
            height: 480,
        }
    }

    #[test]
    fn writes_png_of_requested_size() {
        let dir = tempdir("size");
        let series = sample_series();
        let mut plot = plot_of(&series, Scale::Log10, Scale::Log10);
        plot.width = 500;
        plot.height = 333;
        let path = dir.join("a.png");
        let outcome = write_png(&path, &plot).expect("write");
        assert_eq!(outcome.points_drawn, 36);
        assert_eq!(outcome.points_skipped, 0);
        let img = png::decode(&fs::read(&path).expect("read")).expect("decode");
        assert_eq!((img.width, img.height), (500, 333));
        assert_eq!(img.rgb.len(), 500 * 333 * 3);
        // Only the PNG remains: the temporary file was renamed away.
        let names: Vec<_> = fs::read_dir(&dir).expect("list").flatten().collect();
        assert_eq!(names.len(), 1);
        let _ = fs::remove_dir_all(&dir);
    }

    #[test]
    fn decoded_pixels_match_render_and_show_data() {
        let dir = tempdir("pixels");
        let series = sample_series();
        let plot = plot_of(&series, Scale::Log10, Scale::Log10);
        let path = dir.join("p.png");
        write_png(&path, &plot).expect("write");
        let img = png::decode(&fs::read(&path).expect("read")).expect("decode");
        let (rendered, _) = render_rgb(&plot).map_err(|e| format!("{e:?}")).expect("render");
        assert!(img.rgb == rendered, "PNG decodes to the rendered pixels");

        // Saturated (series-coloured) pixels inside the central plot area.
        let (w, h) = (img.width as usize, img.height as usize);
        let mut coloured = 0;
        for y in h / 5..h * 4 / 5 {
            for x in w / 5..w * 4 / 5 {
                let p = &img.rgb[(y * w + x) * 3..(y * w + x) * 3 + 3];
                let max = p.iter().max().copied().unwrap_or(0);
                let min = p.iter().min().copied().unwrap_or(0);
                if max - min > 60 {
                    coloured += 1;
                }
            }
        }
        assert!(coloured > 200, "only {coloured} coloured pixels");
        let _ = fs::remove_dir_all(&dir);
    }

    #[test]
    fn output_is_deterministic() {
        let dir = tempdir("det");
        let series = sample_series();
        let plot = plot_of(&series, Scale::Log10, Scale::Linear);
        let a = dir.join("a.png");
        let b = dir.join("b.png");
        write_png(&a, &plot).expect("write a");
        write_png(&b, &plot).expect("write b");
        write_png(&a, &plot).expect("overwrite a");
        let bytes_a = fs::read(&a).expect("read a");
        assert!(bytes_a == fs::read(&b).expect("read b"));
        assert!(bytes_a.starts_with(b"\x89PNG\r\n\x1a\n"));
        let _ = fs::remove_dir_all(&dir);
    }

    #[test]
    fn empty_and_all_invalid_give_axes_only_png() {
        let dir = tempdir("empty");
        let bad = [
            Series { name: "empty".into(), points: vec![] },
            Series {
                name: "invalid".into(),
                points: vec![
                    (f64::NAN, 1.0),
                    (1.0, f64::INFINITY),
                    (0.0, 1.0),
                    (1.0, -2.0),
                    (f64::NEG_INFINITY, f64::NAN),
                ],
            },
        ];
        for (name, series, scale) in [
            ("none.png", &[][..], Scale::Linear),
            ("none_log.png", &[][..], Scale::Log10),
            ("bad.png", &bad[..], Scale::Log10),
        ] {
            let path = dir.join(name);
            let outcome = write_png(&path, &plot_of(series, scale, scale)).expect(name);
            let expected_skipped = if series.is_empty() { 0 } else { 5 };
            assert_eq!(outcome, PlotOutcome { points_drawn: 0, points_skipped: expected_skipped });
            let img = png::decode(&fs::read(&path).expect("read")).expect("decode");
            assert_eq!((img.width, img.height), (640, 480));
            // Axes and text are drawn: some dark pixels.
            assert!(img.rgb.chunks(3).any(|p| p.iter().all(|&c| c < 64)));
        }
        let _ = fs::remove_dir_all(&dir);
    }

    #[test]
    fn log_axis_skips_nonpositive_and_counts_them() {
        let dir = tempdir("skip");
        let series = vec![Series {
            name: "s".into(),
            points: vec![(1.0, 1.0), (2.0, 0.0), (3.0, -1.0), (4.0, 1e-3), (f64::NAN, 2.0)],
        }];
        let log = write_png(&dir.join("l.png"), &plot_of(&series, Scale::Linear, Scale::Log10)).expect("log");
        assert_eq!(log, PlotOutcome { points_drawn: 2, points_skipped: 3 });
        let lin = write_png(&dir.join("n.png"), &plot_of(&series, Scale::Linear, Scale::Linear)).expect("linear");
        assert_eq!(lin, PlotOutcome { points_drawn: 4, points_skipped: 1 });
        let _ = fs::remove_dir_all(&dir);
    }

    #[test]
    fn degenerate_and_extreme_ranges_do_not_fail() {
        let dir = tempdir("degenerate");
        let cases: Vec<Vec<(f64, f64)>> = vec![
            vec![(1.0, 1.0)],
            vec![(0.0, 0.0)],
            vec![(5.0, 3.0), (5.0, 3.0)],
            vec![(1e-300, 1e300), (1e300, 1e-300)],
            vec![(1e16, 1.0), (1e16 + 2.0, 1.0 + 1e-15)],
            vec![(3.1, 3.2), (3.3, 3.4)],
            vec![(f64::MIN_POSITIVE, 1.0), (f64::MAX, 2.0)],
            vec![(-1e-9, 1e-9), (1e-9, -1e-9)],
        ];
        for (i, points) in cases.into_iter().enumerate() {
            let series = vec![Series { name: format!("case {i}"), points }];
            for (x, y) in [(Scale::Linear, Scale::Linear), (Scale::Log10, Scale::Log10), (Scale::Linear, Scale::Log10)]
            {
                let mut plot = plot_of(&series, x, y);
                plot.width = MIN_SIDE;
                plot.height = MIN_SIDE;
                let path = dir.join(format!("c{i}.png"));
                match write_png(&path, &plot) {
                    Ok(outcome) => {
                        assert_eq!(outcome.points_drawn + outcome.points_skipped, series[0].points.len());
                    }
                    // Only f64::MAX on a linear axis overflows the padded span.
                    Err(PlotError::InvalidRange { .. }) if i == 6 && x == Scale::Linear => {}
                    Err(e) => panic!("case {i}: {e}"),
                }
            }
        }
        let _ = fs::remove_dir_all(&dir);
    }

    #[test]
    fn overflowing_linear_span_is_a_clear_error() {
        let dir = tempdir("overflow");
        let series = vec![Series { name: "huge".into(), points: vec![(-f64::MAX, 0.0), (f64::MAX, 1.0)] }];
        let path = dir.join("o.png");
        let err = write_png(&path, &plot_of(&series, Scale::Linear, Scale::Linear)).expect_err("overflow");
        assert!(matches!(err, PlotError::InvalidRange { .. }), "{err}");
        assert!(err.to_string().contains("o.png"), "{err}");
        assert!(!path.exists());
        let _ = fs::remove_dir_all(&dir);
    }

    #[test]
    fn many_series_and_sizes() {
        let dir = tempdir("many");
        let series: Vec<Series> = (0..12)
            .map(|i| Series {
                name: format!("s{i}"),
                points: (0..5).map(|j| (f64::from(j), f64::from(i * j))).collect(),
            })
            .collect();
        for (w, h) in [(MIN_SIDE, MIN_SIDE), (1200, 300), (300, 900), (1600, 1200)] {
            let mut plot = plot_of(&series, Scale::Linear, Scale::Linear);
            plot.width = w;
            plot.height = h;
            let path = dir.join("m.png");
            let outcome = write_png(&path, &plot).expect("write");
            assert_eq!(outcome.points_drawn, 60);
            let img = png::decode(&fs::read(&path).expect("read")).expect("decode");
            assert_eq!((img.width, img.height), (w, h));
        }
        let _ = fs::remove_dir_all(&dir);
    }

    #[test]
    fn rejects_bad_size_and_path() {
        let series = sample_series();
        let mut plot = plot_of(&series, Scale::Linear, Scale::Linear);
        plot.width = 0;
        let err = write_png(Path::new("x.png"), &plot).expect_err("zero width");
        assert!(matches!(err, PlotError::InvalidSize { .. }));
        assert!(err.to_string().contains("x.png"));
        plot.width = MAX_SIDE + 1;
        assert!(matches!(write_png(Path::new("x.png"), &plot), Err(PlotError::InvalidSize { .. })));
        plot.width = 640;
        assert!(matches!(write_png(Path::new("/"), &plot), Err(PlotError::InvalidPath { .. })));
    }

    #[test]
    fn unwritable_directory_is_an_error() {
        let dir = tempdir("unwritable");
        let series = sample_series();
        let plot = plot_of(&series, Scale::Log10, Scale::Log10);
        // A directory that does not exist.
        let missing = dir.join("no/such/dir/p.png");
        let err = write_png(&missing, &plot).expect_err("missing dir");
        assert!(matches!(err, PlotError::Io { .. }), "{err}");
        assert!(err.to_string().contains("p.png"), "{err}");
        // A regular file used as the directory.
        let file = dir.join("file");
        fs::write(&file, b"x").expect("write file");
        let err = write_png(&file.join("p.png"), &plot).expect_err("file as dir");
        assert!(matches!(err, PlotError::Io { .. }), "{err}");
        // The destination is an existing directory: the rename fails and
        // the temporary file is cleaned up.
        let target = dir.join("target.png");
        fs::create_dir(&target).expect("mkdir");
        fs::write(target.join("keep"), b"x").expect("write keep");
        let err = write_png(&target, &plot).expect_err("dir as target");
        assert!(matches!(err, PlotError::Io { .. }), "{err}");
        let leftovers: Vec<_> = fs::read_dir(&dir)
            .expect("list")
            .flatten()
            .filter(|e| e.file_name().to_string_lossy().contains(".tmp"))
            .collect();
        assert!(leftovers.is_empty(), "{leftovers:?}");
        let _ = fs::remove_dir_all(&dir);
    }

    #[cfg(unix)]
    #[test]
    fn read_only_directory_is_an_error() {
        use std::os::unix::fs::PermissionsExt;
        let dir = tempdir("readonly");
        let ro = dir.join("ro");
        fs::create_dir(&ro).expect("mkdir");
        fs::set_permissions(&ro, fs::Permissions::from_mode(0o555)).expect("chmod");
        // Root ignores directory permissions; only check when they apply.
        let probe = ro.join("probe");
        let enforced = fs::write(&probe, b"x").is_err();
        let _ = fs::remove_file(&probe);
        if enforced {
            let series = sample_series();
            let err = write_png(&ro.join("p.png"), &plot_of(&series, Scale::Linear, Scale::Linear))
                .expect_err("read-only dir");
            assert!(matches!(err, PlotError::Io { .. }), "{err}");
        }
        let _ = fs::set_permissions(&ro, fs::Permissions::from_mode(0o755));
        let _ = fs::remove_dir_all(&dir);
    }

    #[test]
    fn log_ticks_are_decades() {
        let axis = log_axis(Some((-3.0, 0.0)), 6);
        assert_eq!(axis.labels, ["1e-3", "1e-2", "1e-1", "1e0"]);
        assert_eq!(axis.ticks, [-3.0, -2.0, -1.0, 0.0]);
        assert!(axis.lo < -3.0 && axis.lo > -3.5 && axis.hi > 0.0 && axis.hi < 0.5);
        assert!(!axis.minor.is_empty());
        let wide = log_axis(Some((-30.0, 30.0)), 6);
        assert!(wide.ticks.len() <= 8 && wide.ticks.len() >= 2, "{:?}", wide.labels);
        assert!(wide.labels.iter().all(|l| l.starts_with("1e")));
        let (strides, labels): (Vec<f64>, Vec<&str>) =
            (wide.ticks.windows(2).map(|w| w[1] - w[0]).collect(), wide.labels.iter().map(String::as_str).collect());
        assert!(strides.iter().all(|&d| d == 10.0 || d == 20.0), "{labels:?}");
        let narrow = log_axis(Some((0.3, 0.7)), 6);
        assert_eq!(narrow.labels, ["2", "3", "4", "5", "6"]);
        let tiny = log_axis(Some((-5.5, -5.0)), 6);
        assert!(tiny.labels.len() >= 3 && tiny.labels.iter().all(|l| l.contains("e-")), "{:?}", tiny.labels);
        let very_narrow = log_axis(Some((0.50, 0.51)), 6);
        assert!(very_narrow.ticks.len() >= 3, "{:?}", very_narrow.labels);
        for axis in [&axis, &wide, &narrow, &tiny, &very_narrow] {
            assert!(axis.ticks.windows(2).all(|w| w[0] < w[1]));
            assert!(axis.ticks.iter().all(|t| (axis.lo..=axis.hi).contains(t)));
            assert_eq!(axis.ticks.len(), axis.labels.len());
        }
    }

    #[test]
    fn legend_fits_many_series_and_odd_names() {
        let dir = tempdir("legend");
        let series: Vec<Series> = (0..40)
            .map(|i| Series {
                name: format!("series\twith a very long name that cannot fit {i}\n"),
                points: vec![(1.0, f64::from(i) + 1.0), (2.0, f64::from(i) + 2.0)],
            })
            .collect();
        for n in [1, 3, 40] {
            let plot = plot_of(&series[..n], Scale::Log10, Scale::Log10);
            let outcome = write_png(&dir.join("l.png"), &plot).expect("write");
            assert_eq!(outcome.points_drawn, 2 * n);
        }
        let _ = fs::remove_dir_all(&dir);
    }

    #[test]
    fn linear_ticks_are_nice() {
        let (ticks, labels) = linear_ticks(-0.05, 1.05, 6);
        assert_eq!(ticks, [0.0, 0.2, 0.4, 0.6000000000000001, 0.8, 1.0]);
        assert_eq!(labels, ["0", "0.2", "0.4", "0.6", "0.8", "1.0"]);
        let (_, labels) = linear_ticks(0.0, 3e7, 4);
        assert_eq!(labels, ["0", "1e7", "2e7", "3e7"]);
        let (_, labels) = linear_ticks(-2.0, 2.0, 4);
        assert_eq!(labels, ["-2", "-1", "0", "1", "2"]);
    }

    /// A small PNG decoder for the tests (8-bit RGB, non-interlaced), with
    /// its own inflate: the crate has no PNG decoding dependency.
    mod png {
        pub struct Image {
            pub width: u32,
            pub height: u32,
            pub rgb: Vec<u8>,
        }

        fn be32(b: &[u8]) -> u32 {
            u32::from_be_bytes([b[0], b[1], b[2], b[3]])
        }

        fn crc32(data: &[u8]) -> u32 {
            let mut crc = !0u32;
            for &byte in data {
                crc ^= u32::from(byte);
                for _ in 0..8 {
                    crc = if crc & 1 != 0 { (crc >> 1) ^ 0xEDB8_8320 } else { crc >> 1 };
                }
            }
            !crc
        }

        pub fn decode(bytes: &[u8]) -> Result<Image, String> {
            let rest = bytes.strip_prefix(b"\x89PNG\r\n\x1a\n").ok_or("bad signature")?;
            let mut pos = 0;
            let (mut width, mut height) = (0, 0);
            let mut idat = Vec::new();
            let mut seen_end = false;
            while pos + 12 <= rest.len() {
                let len = be32(&rest[pos..]) as usize;
                let kind = &rest[pos + 4..pos + 8];
                let data = rest.get(pos + 8..pos + 8 + len).ok_or("truncated chunk")?;
                let crc = rest.get(pos + 8 + len..pos + 12 + len).ok_or("truncated crc")?;
                if crc32(&rest[pos + 4..pos + 8 + len]) != be32(crc) {
                    return Err("bad chunk crc".into());
                }
                match kind {
                    b"IHDR" => {
                        width = be32(data);
                        height = be32(&data[4..]);
                        if data[8..13] != [8, 2, 0, 0, 0] {
                            return Err(format!("unsupported IHDR {:?}", &data[8..13]));
                        }
                    }
                    b"IDAT" => idat.extend_from_slice(data),
                    b"IEND" => seen_end = true,
                    _ => {}
                }
                pos += 12 + len;
            }
            if !seen_end {
                return Err("no IEND".into());
            }
            let raw = zlib(&idat)?;
            let stride = width as usize * 3;
            if raw.len() != height as usize * (stride + 1) {
                return Err(format!("decoded {} bytes", raw.len()));
            }
            let mut rgb = vec![0u8; stride * height as usize];
            for y in 0..height as usize {
                let filter = raw[y * (stride + 1)];
                let line = &raw[y * (stride + 1) + 1..(y + 1) * (stride + 1)];
                for x in 0..stride {
                    let a = if x >= 3 { rgb[y * stride + x - 3] } else { 0 };
                    let b = if y > 0 { rgb[(y - 1) * stride + x] } else { 0 };
                    let c = if x >= 3 && y > 0 { rgb[(y - 1) * stride + x - 3] } else { 0 };
                    let pred = match filter {
                        0 => 0,
                        1 => a,
                        2 => b,
                        3 => ((u16::from(a) + u16::from(b)) / 2) as u8,
                        4 => {
                            let p = i16::from(a) + i16::from(b) - i16::from(c);
                            let (pa, pb, pc) =
                                ((p - i16::from(a)).abs(), (p - i16::from(b)).abs(), (p - i16::from(c)).abs());
                            if pa <= pb && pa <= pc {
                                a
                            } else if pb <= pc {
                                b
                            } else {
                                c
                            }
                        }
                        f => return Err(format!("bad filter {f}")),
                    };
                    rgb[y * stride + x] = line[x].wrapping_add(pred);
                }
            }
            Ok(Image { width, height, rgb })
        }

        struct Bits<'a> {
            data: &'a [u8],
            pos: usize,
            bit: u32,
        }

        impl Bits<'_> {
            fn bits(&mut self, n: u32) -> Result<u32, String> {
                let mut v = 0;
                for i in 0..n {
                    let byte = *self.data.get(self.pos).ok_or("inflate: out of data")?;
                    v |= u32::from((byte >> self.bit) & 1) << i;
                    self.bit += 1;
                    if self.bit == 8 {
                        self.bit = 0;
                        self.pos += 1;
                    }
                }
                Ok(v)
            }
        }

        /// Canonical Huffman table: code counts per length and symbols.
        struct Huffman {
            counts: [u16; 16],
            symbols: Vec<u16>,
        }

        impl Huffman {
            fn new(lengths: &[u8]) -> Huffman {
                let mut counts = [0u16; 16];
                for &l in lengths {
                    counts[l as usize] += 1;
                }
                counts[0] = 0;
                let mut offsets = [0u16; 16];
                for l in 1..15 {
                    offsets[l + 1] = offsets[l] + counts[l];
                }
                let mut symbols = vec![0u16; lengths.len()];
                for (sym, &l) in lengths.iter().enumerate() {
                    if l != 0 {
                        symbols[offsets[l as usize] as usize] = sym as u16;
                        offsets[l as usize] += 1;
                    }
                }
                Huffman { counts, symbols }
            }

            fn decode(&self, bits: &mut Bits) -> Result<u16, String> {
                let (mut code, mut first, mut index) = (0i32, 0i32, 0i32);
                for len in 1..16 {
                    code |= bits.bits(1)? as i32;
                    let count = i32::from(self.counts[len]);
                    if code - count < first {
                        return Ok(self.symbols[(index + code - first) as usize]);
                    }
                    index += count;
                    first = (first + count) << 1;
                    code <<= 1;
                }
                Err("inflate: bad code".into())
            }
        }

        const LEN_BASE: [u16; 29] = [
            3, 4, 5, 6, 7, 8, 9, 10, 11, 13, 15, 17, 19, 23, 27, 31, 35, 43, 51, 59, 67, 83, 99, 115, 131, 163, 195,
            227, 258,
        ];
        const LEN_EXTRA: [u8; 29] =
            [0, 0, 0, 0, 0, 0, 0, 0, 1, 1, 1, 1, 2, 2, 2, 2, 3, 3, 3, 3, 4, 4, 4, 4, 5, 5, 5, 5, 0];
        const DIST_BASE: [u16; 30] = [
            1, 2, 3, 4, 5, 7, 9, 13, 17, 25, 33, 49, 65, 97, 129, 193, 257, 385, 513, 769, 1025, 1537, 2049, 3073,
            4097, 6145, 8193, 12289, 16385, 24577,
        ];
        const DIST_EXTRA: [u8; 30] =
            [0, 0, 0, 0, 1, 1, 2, 2, 3, 3, 4, 4, 5, 5, 6, 6, 7, 7, 8, 8, 9, 9, 10, 10, 11, 11, 12, 12, 13, 13];

        fn zlib(data: &[u8]) -> Result<Vec<u8>, String> {
            if data.len() < 6 || data[0] & 0x0f != 8 {
                return Err("zlib: bad header".into());
            }
            let mut bits = Bits { data: &data[2..], pos: 0, bit: 0 };
            let mut out = Vec::new();
            loop {
                let last = bits.bits(1)?;
                match bits.bits(2)? {
                    0 => {
                        if bits.bit != 0 {
                            bits.bit = 0;
                            bits.pos += 1;
                        }
                        let p = bits.pos;
                        let hdr = bits.data.get(p..p + 4).ok_or("stored: truncated")?;
                        let len = usize::from(u16::from_le_bytes([hdr[0], hdr[1]]));
                        let block = bits.data.get(p + 4..p + 4 + len).ok_or("stored: truncated")?;
                        out.extend_from_slice(block);
                        bits.pos = p + 4 + len;
                    }
                    1 => {
                        let mut lengths = [0u8; 288];
                        lengths[..144].fill(8);
                        lengths[144..256].fill(9);
                        lengths[256..280].fill(7);
                        lengths[280..].fill(8);
                        let lit = Huffman::new(&lengths);
                        let dist = Huffman::new(&[5u8; 30]);
                        block(&mut bits, &lit, &dist, &mut out)?;
                    }
                    2 => {
                        let nlen = bits.bits(5)? as usize + 257;
                        let ndist = bits.bits(5)? as usize + 1;
                        let ncode = bits.bits(4)? as usize + 4;
                        const ORDER: [usize; 19] = [16, 17, 18, 0, 8, 7, 9, 6, 10, 5, 11, 4, 12, 3, 13, 2, 14, 1, 15];
                        let mut cl = [0u8; 19];
                        for &i in &ORDER[..ncode] {
                            cl[i] = bits.bits(3)? as u8;
                        }
                        let clh = Huffman::new(&cl);
                        let mut lengths = Vec::with_capacity(nlen + ndist);
                        while lengths.len() < nlen + ndist {
                            let sym = clh.decode(&mut bits)?;
                            match sym {
                                0..=15 => lengths.push(sym as u8),
                                16 => {
                                    let prev = *lengths.last().ok_or("repeat with no previous")?;
                                    let n = 3 + bits.bits(2)?;
                                    lengths.extend(std::iter::repeat_n(prev, n as usize));
                                }
                                17 => {
                                    let n = 3 + bits.bits(3)?;
                                    lengths.extend(std::iter::repeat_n(0, n as usize));
                                }
                                _ => {
                                    let n = 11 + bits.bits(7)?;
                                    lengths.extend(std::iter::repeat_n(0, n as usize));
                                }
                            }
                        }
                        let lit = Huffman::new(&lengths[..nlen]);
                        let dist = Huffman::new(&lengths[nlen..nlen + ndist]);
                        block(&mut bits, &lit, &dist, &mut out)?;
                    }
                    _ => return Err("inflate: bad block type".into()),
                }
                if last == 1 {
                    return Ok(out);
                }
            }
        }

        fn block(bits: &mut Bits, lit: &Huffman, dist: &Huffman, out: &mut Vec<u8>) -> Result<(), String> {
            loop {
                let sym = lit.decode(bits)? as usize;
                if sym < 256 {
                    out.push(sym as u8);
                } else if sym == 256 {
                    return Ok(());
                } else {
                    let i = sym - 257;
                    let len =
                        *LEN_BASE.get(i).ok_or("bad length")? as usize + bits.bits(u32::from(LEN_EXTRA[i]))? as usize;
                    let d = dist.decode(bits)? as usize;
                    let back = *DIST_BASE.get(d).ok_or("bad distance")? as usize
                        + bits.bits(u32::from(DIST_EXTRA[d]))? as usize;
                    let start = out.len().checked_sub(back).ok_or("distance too far")?;
                    for k in 0..len {
                        let b = out[start + k];
                        out.push(b);
                    }
                }
            }
        }
    }
}
