//! Image files the stages write: linear float EXRs (lightmaps, with extra named layers) and 8-bit
//! sRGB PNG previews of HDR data.
//!
//! **Input → output.** `width × height` linear-RGB pixels (row-major, row 0 at the top, `[f32; 3]`
//! per pixel) → an OpenEXR file ([`write_exr_rgb`]: float32, ZIP16 scan lines, channels `R`, `G`, `B`
//! plus `<layer>.R`, `<layer>.G`, `<layer>.B` per extra layer) or a PNG preview ([`write_png_preview`]).
//! [`read_exr_rgb`] reads any single-part EXR back as named float channels (tests, the report).
//!
//! **Invariants.** Files are encoded in memory and published with [`crate::cache::write_atomic`], so
//! a path holds either its old contents or the complete new file. Non-finite values are never written
//! (the error names the first bad pixel). EXR stores channels sorted by name: read them by name.
//!
//! **Preview tone mapping** (`write_png_preview`): exposure `e = 0.8 / Y₉₉`, where `Y₉₉` is the
//! 99th-percentile (nearest rank) Rec. 709 luminance `0.2126 R + 0.7152 G + 0.0722 B` over the valid
//! pixels (`e = 1` when `Y₉₉ = 0`); each channel `x = e · max(c, 0)` then goes through [`shoulder`]
//! (identity below 0.6, a Reinhard curve from there that approaches 1, C¹ at the knee) and the sRGB
//! OETF ([`srgb_oetf`], IEC 61966-2-1), and is rounded to 8 bits. Invalid pixels show a dark 4-pixel
//! checker (values 24 and 40).

use std::collections::BTreeMap;
use std::io::Cursor;
use std::path::{Path, PathBuf};

use crate::cache::{CacheError, write_atomic};

pub use crate::render::color::REC709_LUMA;

/// Pre-shoulder value the 99th-percentile luminance is exposed to.
pub const PREVIEW_KEY: f64 = 0.8;

/// Where [`shoulder`] leaves the identity.
const SHOULDER_KNEE: f64 = 0.6;

/// Side of a square of the invalid-pixel checker \[pixels\].
const CHECKER: usize = 4;

/// Reading or writing an image failed.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum ImageError {
    /// A pixel buffer does not match the image size.
    #[error("{path}: {what} holds {len} pixels but the image is {width}×{height} = {expected}")]
    Size {
        /// Output file.
        path: PathBuf,
        /// Which buffer ("pixels", "layer \"direct\"", "valid mask").
        what: String,
        /// Its length.
        len: usize,
        /// Image width.
        width: usize,
        /// Image height.
        height: usize,
        /// `width · height`.
        expected: usize,
    },
    /// Zero or too large an image.
    #[error("{path}: cannot write a {width}×{height} image\n  = help: both sides must be in 1..={max}")]
    Dimensions {
        /// Output file.
        path: PathBuf,
        /// Width.
        width: usize,
        /// Height.
        height: usize,
        /// Largest side accepted.
        max: usize,
    },
    /// A value is NaN or infinite.
    #[error(
        "{path}: {what}: pixel (x {x}, y {y}) channel {channel} is {value}, refusing to write it\n  = help: the stage produced a non-finite value there; fix its input or clamp before writing"
    )]
    NonFinite {
        /// Output file.
        path: PathBuf,
        /// Which buffer.
        what: String,
        /// Column.
        x: usize,
        /// Row (0 at the top).
        y: usize,
        /// `R`, `G` or `B`.
        channel: char,
        /// The value.
        value: f32,
    },
    /// An extra EXR layer name is unusable.
    #[error(
        "{path}: EXR layer name \"{name}\" {reason}\n  = help: use a short unique name of ASCII letters, digits, '_' or '-', e.g. \"direct\""
    )]
    LayerName {
        /// Output file.
        path: PathBuf,
        /// The name.
        name: String,
        /// What is wrong with it.
        reason: &'static str,
    },
    /// The encoder failed.
    #[error("{path}: cannot encode the image: {message}")]
    Encode {
        /// Output file.
        path: PathBuf,
        /// Encoder message.
        message: String,
    },
    /// Publishing the file failed.
    #[error("{path}: cannot write the image: {source}")]
    Write {
        /// Output file.
        path: PathBuf,
        /// The failed atomic write.
        #[source]
        source: CacheError,
    },
    /// The file cannot be read.
    #[error("{path}: cannot read the image: {source}")]
    Read {
        /// Input file.
        path: PathBuf,
        /// Cause.
        #[source]
        source: std::io::Error,
    },
    /// The file is not a readable EXR (truncated, corrupt, deep, multi-part, …).
    #[error(
        "{path}: not a readable EXR image: {message}\n  = help: re-export it as a single-part scan-line or tiled OpenEXR file"
    )]
    Decode {
        /// Input file.
        path: PathBuf,
        /// Decoder message.
        message: String,
    },
}

/// Largest image side accepted by the writers (a 32k × 32k float RGB image is 12 GiB).
pub const MAX_SIDE: usize = 32_768;

/// A decoded EXR image: every channel of its (single) part as f32, row-major, row 0 at the top.
#[derive(Debug, Clone, PartialEq)]
pub struct ExrImage {
    /// Width \[pixels\].
    pub width: usize,
    /// Height \[pixels\].
    pub height: usize,
    /// Channel name (`R`, `direct.G`, …) → `width · height` samples (f16 and u32 channels converted).
    pub channels: BTreeMap<String, Vec<f32>>,
}

impl ExrImage {
    /// The RGB pixels of the main image (`layer = None`: channels `R`, `G`, `B`) or of an extra layer
    /// (`<layer>.R`, …); `None` when one of the three channels is missing.
    pub fn rgb(&self, layer: Option<&str>) -> Option<Vec<[f32; 3]>> {
        let name = |c: &str| match layer {
            Some(l) => format!("{l}.{c}"),
            None => c.to_string(),
        };
        let [r, g, b] = ["R", "G", "B"].map(|c| self.channels.get(&name(c)));
        let (r, g, b) = (r?, g?, b?);
        Some(r.iter().zip(g).zip(b).map(|((&r, &g), &b)| [r, g, b]).collect())
    }
}

/// Checks the image size and one buffer's length.
fn check_size(path: &Path, what: &str, len: usize, width: usize, height: usize) -> Result<(), ImageError> {
    if !(1..=MAX_SIDE).contains(&width) || !(1..=MAX_SIDE).contains(&height) {
        return Err(ImageError::Dimensions { path: path.to_path_buf(), width, height, max: MAX_SIDE });
    }
    if len != width * height {
        return Err(ImageError::Size {
            path: path.to_path_buf(),
            what: what.to_string(),
            len,
            width,
            height,
            expected: width * height,
        });
    }
    Ok(())
}

/// The first non-finite value of `pixels`, as an error.
fn check_finite(path: &Path, what: &str, width: usize, pixels: &[[f32; 3]]) -> Result<(), ImageError> {
    for (i, p) in pixels.iter().enumerate() {
        if let Some(c) = (0..3).find(|&c| !p[c].is_finite()) {
            return Err(ImageError::NonFinite {
                path: path.to_path_buf(),
                what: what.to_string(),
                x: i % width,
                y: i / width,
                channel: ['R', 'G', 'B'][c],
                value: p[c],
            });
        }
    }
    Ok(())
}

/// Why a layer name is rejected, if it is.
fn layer_name_problem(name: &str, earlier: &[(&str, &[[f32; 3]])]) -> Option<&'static str> {
    if name.is_empty() {
        Some("is empty")
    } else if name.len() > 200 {
        Some("is longer than 200 characters")
    } else if !name.chars().all(|c| c.is_ascii_alphanumeric() || matches!(c, '_' | '-')) {
        Some("contains characters other than ASCII letters, digits, '_' and '-'")
    } else if earlier.iter().any(|(n, _)| *n == name) {
        Some("is given twice")
    } else {
        None
    }
}

/// Writes a linear float32 RGB OpenEXR (ZIP16 scan lines) with channels `R`, `G`, `B` for `pixels`
/// and `<name>.R`, `<name>.G`, `<name>.B` for each extra layer, atomically.
///
/// Every buffer holds `width · height` pixels, row-major from the top-left corner. Errors: a wrong
/// length, a side outside `1..=`[`MAX_SIDE`], a bad or repeated layer name, a NaN or infinity (naming
/// the first one), an encoder or file-system failure; each names `path`.
pub fn write_exr_rgb(
    path: &Path,
    width: usize,
    height: usize,
    pixels: &[[f32; 3]],
    layers: &[(&str, &[[f32; 3]])],
) -> Result<(), ImageError> {
    use exr::prelude::{AnyChannel, AnyChannels, Encoding, FlatSamples, Image, Layer, LayerAttributes, SmallVec};
    use exr::prelude::{Text, WritableImage};

    check_size(path, "pixels", pixels.len(), width, height)?;
    check_finite(path, "pixels", width, pixels)?;
    for (k, (name, data)) in layers.iter().enumerate() {
        if let Some(reason) = layer_name_problem(name, &layers[..k]) {
            return Err(ImageError::LayerName { path: path.to_path_buf(), name: name.to_string(), reason });
        }
        let what = format!("layer \"{name}\"");
        check_size(path, &what, data.len(), width, height)?;
        check_finite(path, &what, width, data)?;
    }

    let mut list: SmallVec<[AnyChannel<FlatSamples>; 4]> = SmallVec::new();
    let named = std::iter::once(("", pixels)).chain(layers.iter().copied());
    for (layer, data) in named {
        for (c, letter) in ["R", "G", "B"].iter().enumerate() {
            let name = if layer.is_empty() { letter.to_string() } else { format!("{layer}.{letter}") };
            // The name was checked to be ASCII above, so this cannot fail.
            let text = Text::new_or_none(&name).ok_or_else(|| ImageError::LayerName {
                path: path.to_path_buf(),
                name: name.clone(),
                reason: "is not ASCII",
            })?;
            list.push(AnyChannel::new(text, FlatSamples::F32(data.iter().map(|p| p[c]).collect())));
        }
    }
    let layer =
        Layer::new((width, height), LayerAttributes::default(), Encoding::SMALL_LOSSLESS, AnyChannels::sort(list));
    let mut bytes = Vec::new();
    Image::from_layer(layer)
        .write()
        .to_buffered(Cursor::new(&mut bytes))
        .map_err(|e| ImageError::Encode { path: path.to_path_buf(), message: e.to_string() })?;
    write_atomic(path, &bytes).map_err(|source| ImageError::Write { path: path.to_path_buf(), source })
}

/// Reads every channel of a single-part, flat (not deep) EXR file as f32 (the largest resolution
/// level of a mip-mapped file). Errors name `path`: missing file, truncated or corrupt data, a deep or
/// multi-part file.
pub fn read_exr_rgb(path: &Path) -> Result<ExrImage, ImageError> {
    use exr::prelude::{ReadChannels, ReadLayers, read};

    let bytes = std::fs::read(path).map_err(|source| ImageError::Read { path: path.to_path_buf(), source })?;
    let decode = |message: String| ImageError::Decode { path: path.to_path_buf(), message };
    let image = read()
        .no_deep_data()
        .largest_resolution_level()
        .all_channels()
        .all_layers()
        .all_attributes()
        .non_parallel()
        .from_buffered(Cursor::new(bytes))
        .map_err(|e| decode(e.to_string()))?;
    let [layer] = image.layer_data.as_slice() else {
        return Err(decode(format!("it has {} parts; voltab reads single-part files", image.layer_data.len())));
    };
    let (width, height) = (layer.size.0, layer.size.1);
    let mut channels = BTreeMap::new();
    for ch in &layer.channel_data.list {
        channels.insert(ch.name.to_string(), ch.sample_data.values_as_f32().collect::<Vec<f32>>());
    }
    Ok(ExrImage { width, height, channels })
}

/// The sRGB opto-electronic transfer function (IEC 61966-2-1): linear `x ∈ [0, 1]` → encoded value
/// (inputs outside are clamped).
pub fn srgb_oetf(x: f64) -> f64 {
    let x = x.clamp(0.0, 1.0);
    if x <= 0.003_130_8 { 12.92 * x } else { 1.055 * x.powf(1.0 / 2.4) - 0.055 }
}

/// The preview's highlight shoulder: identity up to the knee 0.6, then `k + (1−k)·t/(t + 1−k)` with
/// `t = x − k` (a Reinhard curve scaled to approach 1, with slope 1 at the knee). Negative inputs → 0.
pub fn shoulder(x: f64) -> f64 {
    let k = SHOULDER_KNEE;
    if x <= 0.0 {
        0.0
    } else if x <= k {
        x
    } else {
        let t = x - k;
        k + (1.0 - k) * t / (t + (1.0 - k))
    }
}

/// Exposure mapping the 99th-percentile (nearest rank) Rec. 709 luminance of the valid pixels to
/// [`PREVIEW_KEY`]; 1 when there are no valid pixels or that luminance is 0. Negative channels count
/// as 0.
pub fn preview_exposure(pixels: &[[f32; 3]], valid: Option<&[bool]>) -> f64 {
    let mut lum: Vec<f64> = pixels
        .iter()
        .enumerate()
        .filter(|(i, _)| valid.is_none_or(|v| v.get(*i).copied().unwrap_or(false)))
        .map(|(_, p)| (0..3).map(|c| REC709_LUMA[c] * f64::from(p[c]).max(0.0)).sum::<f64>())
        .filter(|y| y.is_finite())
        .collect();
    if lum.is_empty() {
        return 1.0;
    }
    lum.sort_by(f64::total_cmp);
    // Nearest rank: the smallest value with at least 99 % of the samples at or below it.
    let rank = (0.99 * lum.len() as f64).ceil() as usize;
    let y99 = lum[rank.clamp(1, lum.len()) - 1];
    if y99 > 0.0 { PREVIEW_KEY / y99 } else { 1.0 }
}

/// Writes an 8-bit sRGB PNG preview of linear HDR `pixels` (module doc: exposure, shoulder, OETF),
/// atomically, and returns the exposure used. Pixels whose `valid` entry is false are drawn as a dark
/// checker and ignored by the exposure; their values may be anything. Errors name `path`: wrong
/// lengths, a side outside `1..=`[`MAX_SIDE`], a non-finite valid pixel, encoder or file failures.
pub fn write_png_preview(
    path: &Path,
    width: usize,
    height: usize,
    pixels: &[[f32; 3]],
    valid: Option<&[bool]>,
) -> Result<f64, ImageError> {
    use image::ImageEncoder;
    use image::codecs::png::PngEncoder;

    check_size(path, "pixels", pixels.len(), width, height)?;
    if let Some(v) = valid {
        check_size(path, "valid mask", v.len(), width, height)?;
    }
    let is_valid = |i: usize| valid.is_none_or(|v| v[i]);
    if let Some(i) = (0..pixels.len()).find(|&i| is_valid(i) && pixels[i].iter().any(|x| !x.is_finite())) {
        let c = (0..3).find(|&c| !pixels[i][c].is_finite()).unwrap_or(0);
        return Err(ImageError::NonFinite {
            path: path.to_path_buf(),
            what: "pixels".to_string(),
            x: i % width,
            y: i / width,
            channel: ['R', 'G', 'B'][c],
            value: pixels[i][c],
        });
    }
    let exposure = preview_exposure(pixels, valid);
    let mut rgb8 = Vec::with_capacity(pixels.len() * 3);
    for (i, p) in pixels.iter().enumerate() {
        if is_valid(i) {
            for &c in p {
                let v = srgb_oetf(shoulder(exposure * f64::from(c)));
                rgb8.push((v * 255.0).round() as u8);
            }
        } else {
            let (x, y) = (i % width, i / width);
            let dark = if (x / CHECKER + y / CHECKER).is_multiple_of(2) { 24 } else { 40 };
            rgb8.extend_from_slice(&[dark; 3]);
        }
    }
    let mut png = Vec::new();
    let (w, h) = (width as u32, height as u32);
    PngEncoder::new(&mut png)
        .write_image(&rgb8, w, h, image::ColorType::Rgb8)
        .map_err(|e| ImageError::Encode { path: path.to_path_buf(), message: e.to_string() })?;
    write_atomic(path, &png).map_err(|source| ImageError::Write { path: path.to_path_buf(), source })?;
    Ok(exposure)
}

#[cfg(test)]
mod tests;
