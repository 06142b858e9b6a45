//! Voxel media and directional lights (elek2014 Sec. 3–4): the medium Principal-Ordinates
//! Propagation (`stages::pop`) propagates through and the grid Monte-Carlo reference
//! (`reference::grid_mc`) renders, so it lives on the render floor under both.
//!
//! **Input → output.** A world-space box, a density per voxel (piecewise constant, x fastest) and
//! per-channel coefficients at density 1 → point and cell queries of `σ_s`, `σ_a` and `g`. This is
//! the "medium volume (which exists independently of the propagation volumes)" of elek2014 Sec. 4:
//! the propagation grids sample it, and the Monte-Carlo reference (`crate::reference::grid_mc`)
//! reads the same voxels exactly. Scene media (homogeneous, exponential height fog) are voxelised
//! into one by [`VoxelMedium::from_fn`]; raw `f32` volumes are read by [`read_raw_density`].

use std::path::Path;

use glam::DVec3;

use crate::physics::medium::RgbMedium;

/// A box of voxels with one density each; outside the box the density is 0.
#[derive(Debug, Clone, PartialEq)]
pub struct VoxelMedium {
    /// Lower corner \[m\].
    pub min: DVec3,
    /// Upper corner \[m\].
    pub max: DVec3,
    /// Voxels along x, y, z (each ≥ 1).
    pub dims: [usize; 3],
    /// Density per voxel, index `x + dims[0]·(y + dims[1]·z)`; multiplies `sigma_s` and `sigma_a`.
    pub density: Vec<f32>,
    /// The coefficients at density 1, g in `[0, 1)` per channel (elek2014 does not propagate
    /// back-scattering media).
    pub coefficients: RgbMedium,
}

/// A voxel medium that cannot be built, or a density volume that cannot be read (file errors name the
/// file or folder).
#[derive(Debug, thiserror::Error)]
pub enum VoxelError {
    /// The box is empty, inverted or not finite.
    #[error("the medium box {min} – {max} is empty or not finite; give max > min on every axis")]
    Box {
        /// Lower corner.
        min: DVec3,
        /// Upper corner.
        max: DVec3,
    },
    /// An axis without voxels.
    #[error("voxel dimensions {0:?} contain 0; every axis needs at least one voxel")]
    ZeroDims([usize; 3]),
    /// The density count does not match the dimensions.
    #[error("{got} densities for {dims:?} voxels; the volume needs {} (x fastest, then y, then z)", voxel_count(*dims))]
    Count {
        /// Densities given.
        got: usize,
        /// Voxels per axis.
        dims: [usize; 3],
    },
    /// A negative, NaN or infinite density.
    #[error("voxel {voxel} has density {value}; densities must be finite and ≥ 0")]
    Density {
        /// Flat voxel index.
        voxel: usize,
        /// Its density.
        value: f32,
    },
    /// A negative, NaN or infinite coefficient.
    #[error("channel {channel}: σ_s = {sigma_s}, σ_a = {sigma_a}; coefficients must be finite and ≥ 0 (1/m)")]
    Coefficient {
        /// Colour channel.
        channel: usize,
        /// Its scattering coefficient.
        sigma_s: f64,
        /// Its absorption coefficient.
        sigma_a: f64,
    },
    /// g outside `[0, 1)`.
    #[error("channel {channel}: g = {g}; POP propagates forward-scattering media, g in [0, 1)")]
    G {
        /// Colour channel.
        channel: usize,
        /// Its HG mean cosine.
        g: f64,
    },
    /// A file or folder that cannot be read.
    #[error("{}: cannot read the {what}: {source}", path.display())]
    Io {
        /// The file or folder.
        path: std::path::PathBuf,
        /// `"density volume"` or `"slice folder"`.
        what: &'static str,
        /// The cause.
        source: std::io::Error,
    },
    /// A raw volume of the wrong size.
    #[error("{}: {bytes} bytes, but {dims:?} voxels of little-endian f32 need {}; check `dims` or the file", path.display(), voxel_count(*dims).saturating_mul(4))]
    RawSize {
        /// The file.
        path: std::path::PathBuf,
        /// Its size.
        bytes: u64,
        /// Voxels per axis.
        dims: [usize; 3],
    },
    /// A device, pipe or folder where a raw volume file belongs.
    #[error("{}: not a regular file; give density_raw a file of little-endian f32 densities", .0.display())]
    NotAFile(std::path::PathBuf),
    /// A slice folder without `.exr` files.
    #[error("{}: no .exr slices in the folder; put one EXR per z slice there", .0.display())]
    NoSlices(std::path::PathBuf),
    /// More slices than [`MAX_SLICE_VOXELS`].
    #[error("{}: {count} slices; at most {MAX_SLICE_VOXELS}", path.display())]
    TooManySlices {
        /// The folder.
        path: std::path::PathBuf,
        /// Its slice count.
        count: usize,
    },
    /// A slice that cannot be decoded.
    #[error(transparent)]
    Image(#[from] crate::image_io::ImageError),
    /// A slice without a density channel.
    #[error("{}: no density channel (looked for density, Y, R, A; the file has {channels:?})", path.display())]
    NoChannel {
        /// The slice.
        path: std::path::PathBuf,
        /// Its channels.
        channels: Vec<String>,
    },
    /// A slice larger than [`MAX_SLICE_VOXELS`] on a side.
    #[error("{}: {width} × {height} pixels; slices may be at most {MAX_SLICE_VOXELS} on a side", path.display())]
    SliceTooLarge {
        /// The slice.
        path: std::path::PathBuf,
        /// Its width.
        width: usize,
        /// Its height.
        height: usize,
    },
    /// A slice whose size differs from the first one's.
    #[error("{}: {width} × {height} pixels, but {} is {} × {}; every slice must have the same size", path.display(), first.display(), first_size[0], first_size[1])]
    SliceSize {
        /// The slice.
        path: std::path::PathBuf,
        /// Its width.
        width: usize,
        /// Its height.
        height: usize,
        /// The first slice.
        first: std::path::PathBuf,
        /// The first slice's width and height.
        first_size: [usize; 2],
    },
    /// A negative, NaN or infinite density in a slice.
    #[error("{}: channel {channel} at pixel ({x}, {row}) is {value}; densities must be finite and ≥ 0", path.display())]
    Pixel {
        /// The slice.
        path: std::path::PathBuf,
        /// The channel read.
        channel: &'static str,
        /// Column.
        x: usize,
        /// Image row (0 at the top).
        row: usize,
        /// The value.
        value: f32,
    },
}

/// A distant light: parallel radiance along one direction (elek2014 Sec. 4).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DirectionalLight {
    /// Unit direction the light travels to.
    pub direction: DVec3,
    /// Irradiance on a surface facing the light \[W/m²\] per channel.
    pub irradiance: [f64; 3],
}

impl VoxelMedium {
    /// Checks and builds a medium.
    ///
    /// # Errors
    /// A message naming the problem and the fix: an empty or inverted box, a zero dimension, a
    /// density count that does not match `dims`, a negative or non-finite density or coefficient,
    /// or `g ∉ [0, 1)`.
    pub fn new(
        min: DVec3,
        max: DVec3,
        dims: [usize; 3],
        density: Vec<f32>,
        coefficients: RgbMedium,
    ) -> Result<Self, VoxelError> {
        let RgbMedium { sigma_s, sigma_a, g } = coefficients;
        if !(min.is_finite() && max.is_finite()) || (max - min).min_element() <= 0.0 {
            return Err(VoxelError::Box { min, max });
        }
        if dims.contains(&0) {
            return Err(VoxelError::ZeroDims(dims));
        }
        let n = dims[0].checked_mul(dims[1]).and_then(|v| v.checked_mul(dims[2]));
        if n != Some(density.len()) {
            return Err(VoxelError::Count { got: density.len(), dims });
        }
        if let Some((voxel, &value)) = density.iter().enumerate().find(|(_, d)| !(d.is_finite() && **d >= 0.0)) {
            return Err(VoxelError::Density { voxel, value });
        }
        for channel in 0..3 {
            let (s, a) = (sigma_s[channel], sigma_a[channel]);
            if !(s.is_finite() && s >= 0.0 && a.is_finite() && a >= 0.0) {
                return Err(VoxelError::Coefficient { channel, sigma_s: s, sigma_a: a });
            }
            if !(g[channel].is_finite() && (0.0..1.0).contains(&g[channel])) {
                return Err(VoxelError::G { channel, g: g[channel] });
            }
        }
        Ok(Self { min, max, dims, density, coefficients })
    }

    /// A homogeneous box (one voxel of density 1).
    ///
    /// # Errors
    /// As [`VoxelMedium::new`].
    pub fn homogeneous(min: DVec3, max: DVec3, coefficients: RgbMedium) -> Result<Self, VoxelError> {
        Self::new(min, max, [1, 1, 1], vec![1.0], coefficients)
    }

    /// Voxelises a density function sampled at voxel centres.
    ///
    /// # Errors
    /// As [`VoxelMedium::new`] (a negative or non-finite sample is reported with its voxel).
    pub fn from_fn(
        min: DVec3,
        max: DVec3,
        dims: [usize; 3],
        coefficients: RgbMedium,
        density: impl Fn(DVec3) -> f64,
    ) -> Result<Self, VoxelError> {
        let size = (max - min) / DVec3::new(dims[0] as f64, dims[1] as f64, dims[2] as f64);
        let mut values = Vec::with_capacity(dims.iter().product());
        for z in 0..dims[2] {
            for y in 0..dims[1] {
                for x in 0..dims[0] {
                    let p = min + size * DVec3::new(x as f64 + 0.5, y as f64 + 0.5, z as f64 + 0.5);
                    values.push(density(p) as f32);
                }
            }
        }
        Self::new(min, max, dims, values, coefficients)
    }

    /// Size of one voxel \[m\].
    pub fn voxel_size(&self) -> DVec3 {
        (self.max - self.min) / DVec3::new(self.dims[0] as f64, self.dims[1] as f64, self.dims[2] as f64)
    }

    /// The voxel containing `p`, `None` outside the box (the upper faces belong to the last voxel).
    pub fn voxel_of(&self, p: DVec3) -> Option<[usize; 3]> {
        if !(p.cmpge(self.min).all() && p.cmple(self.max).all()) {
            return None;
        }
        let t = (p - self.min) / self.voxel_size();
        let f = |v: f64, n: usize| (v.max(0.0) as usize).min(n - 1);
        Some([f(t.x, self.dims[0]), f(t.y, self.dims[1]), f(t.z, self.dims[2])])
    }

    /// Density of voxel `v`.
    pub fn voxel_density(&self, v: [usize; 3]) -> f64 {
        f64::from(self.density[v[0] + self.dims[0] * (v[1] + self.dims[1] * v[2])])
    }

    /// Density at `p` (piecewise constant per voxel, 0 outside the box).
    pub fn density_at(&self, p: DVec3) -> f64 {
        self.voxel_of(p).map_or(0.0, |v| self.voxel_density(v))
    }

    /// The largest voxel density (a majorant for delta tracking).
    pub fn max_density(&self) -> f64 {
        self.density.iter().fold(0.0_f64, |m, &d| m.max(f64::from(d)))
    }
}

/// Test fixture: the homogeneous unit cube `[0, 1]³` (one voxel of density 1) with `coefficients`.
#[cfg(test)]
pub(crate) fn unit_cube(coefficients: RgbMedium) -> VoxelMedium {
    VoxelMedium::homogeneous(DVec3::ZERO, DVec3::ONE, coefficients).expect("fixture coefficients are valid")
}

/// Reads a raw little-endian `f32` density volume of `dims` voxels (x fastest).
///
/// # Errors
/// Naming the file: missing or unreadable, not a regular file, or a size that is not `4 · x · y · z`
/// bytes (checked before reading).
pub fn read_raw_density(path: &Path, dims: [usize; 3]) -> Result<Vec<f32>, VoxelError> {
    let io = |source| VoxelError::Io { path: path.to_path_buf(), what: "density volume", source };
    let wrong_size = |bytes: u64| VoxelError::RawSize { path: path.to_path_buf(), bytes, dims };
    // The size is checked before anything is read, so a device or a huge file is never slurped.
    let meta = std::fs::metadata(path).map_err(io)?;
    if !meta.is_file() {
        return Err(VoxelError::NotAFile(path.to_path_buf()));
    }
    if u128::from(meta.len()) != voxel_count(dims).saturating_mul(4) {
        return Err(wrong_size(meta.len()));
    }
    let bytes = std::fs::read(path).map_err(io)?;
    if voxel_count(dims).saturating_mul(4) != bytes.len() as u128 {
        return Err(wrong_size(bytes.len() as u64));
    }
    Ok(bytes.chunks_exact(4).map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]])).collect())
}

/// Voxels of a volume of `dims`, without overflow (saturating far beyond any real volume).
fn voxel_count(dims: [usize; 3]) -> u128 {
    dims.iter().fold(1u128, |n, &d| n.saturating_mul(d as u128))
}

/// Largest slice count and slice side of an EXR-slice volume.
pub const MAX_SLICE_VOXELS: usize = 1024;

/// Reads a density volume stored as a folder of EXR images, one z slice per file in file-name order
/// (`slice_000.exr`, `slice_001.exr`, … — every `.exr` in the folder). Each slice's width is x and its
/// height y, with image row 0 at the *top*, i.e. the largest y (so a slice looks as it does in an image
/// viewer with y up). The density is the first channel present of `density`, `Y`, `R`, `A`. Returns the
/// voxels per axis and the densities, x fastest.
///
/// # Errors
/// A message naming the folder or the file: unreadable folder, no `.exr` in it, more than 1024 slices,
/// an undecodable file, a slice without any of the channels, slices of different sizes or larger than
/// 1024, and a negative, NaN or infinite density (with its pixel).
pub fn read_exr_slices(dir: &Path) -> Result<([usize; 3], Vec<f32>), VoxelError> {
    let entries = std::fs::read_dir(dir).map_err(|source| VoxelError::Io {
        path: dir.to_path_buf(),
        what: "slice folder",
        source,
    })?;
    let mut files: Vec<std::path::PathBuf> = entries
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|x| x.eq_ignore_ascii_case("exr")))
        .collect();
    files.sort();
    if files.is_empty() {
        return Err(VoxelError::NoSlices(dir.to_path_buf()));
    }
    if files.len() > MAX_SLICE_VOXELS {
        return Err(VoxelError::TooManySlices { path: dir.to_path_buf(), count: files.len() });
    }
    let mut dims = [0usize, 0, files.len()];
    let mut values = Vec::new();
    for (z, file) in files.iter().enumerate() {
        let image = crate::image_io::read_exr_rgb(file)?;
        let Some((name, data)) =
            ["density", "Y", "R", "A"].iter().find_map(|c| image.channels.get(*c).map(|d| (*c, d)))
        else {
            return Err(VoxelError::NoChannel {
                path: file.clone(),
                channels: image.channels.keys().cloned().collect(),
            });
        };
        if z == 0 {
            dims[0] = image.width;
            dims[1] = image.height;
            if image.width > MAX_SLICE_VOXELS || image.height > MAX_SLICE_VOXELS {
                return Err(VoxelError::SliceTooLarge { path: file.clone(), width: image.width, height: image.height });
            }
            values.reserve(dims[0] * dims[1] * dims[2]);
        } else if [image.width, image.height] != [dims[0], dims[1]] {
            return Err(VoxelError::SliceSize {
                path: file.clone(),
                width: image.width,
                height: image.height,
                first: files[0].clone(),
                first_size: [dims[0], dims[1]],
            });
        }
        for y in 0..dims[1] {
            let row = dims[1] - 1 - y;
            for x in 0..dims[0] {
                let v = data[row * dims[0] + x];
                if !(v.is_finite() && v >= 0.0) {
                    return Err(VoxelError::Pixel { path: file.clone(), channel: name, x, row, value: v });
                }
                values.push(v);
            }
        }
    }
    Ok((dims, values))
}

#[cfg(test)]
mod tests;
