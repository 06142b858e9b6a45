//! Environment maps: a latitude–longitude HDR map of radiance, its exact texel solid angles and
//! moments, importance sampling of directions from it, and the maps the techniques use (a scene's
//! dome light, the bundled sky). POP turns a map into principal ordinates
//! (`stages::pop::environment`, elek2014 Sec. 5.1); the grid Monte-Carlo reference samples it
//! directly (`reference::grid_mc`).
//!
//! **Input → output.** Texels (read from an EXR, a dome light, or built from a function) → radiance
//! lookups by direction, texel directions, solid angles and first moments, and sampled directions
//! with their density.
//!
//! **Map convention.** Row 0 is the top. Texel `(col, row)` covers polar angles
//! `θ ∈ [π row/H, π (row+1)/H]` from `+Y` (up) and azimuths `φ ∈ [2π col/W, 2π (col+1)/W]`, with the
//! direction `ω = (sin θ sin φ, cos θ, −sin θ cos φ)`: the image centre column looks toward `+Z`, its
//! left edge toward `−Z`, a quarter across toward `+X`. A texel's solid angle is exact,
//! `ΔΩ = (2π/W)(cos θ₀ − cos θ₁)`, so `Σ ΔΩ = 4π` to rounding. `ω` is the direction *toward* the
//! environment (where light comes from).
//!
//! **Rotation.** A map may carry a world-from-map rotation ([`EnvMap::with_rotation`], e.g. a USD
//! `DomeLight`'s transform): the convention above then holds in the map's own frame, and every
//! direction ↔ texel function ([`EnvMap::texel_direction`], [`EnvMap::texel_of`], [`EnvMap::lookup`],
//! [`EnvMap::texel_moment`], [`EnvSampler::sample`], the ordinates) maps through it. Nothing is
//! resampled: the texels and their solid angles are unchanged, so the map's integral is exactly that of
//! the unrotated map. Any orthogonal matrix is accepted (a mirroring one shows the map mirrored).

use std::path::Path;

use glam::{DMat3, DVec3};
use rayon::prelude::*;

use crate::render::color::{Rgb, luminance};

/// Largest map side accepted (a 16k × 8k float map is 1.5 GiB as f64 RGB).
pub const MAX_SIDE: usize = 16_384;

/// Share of [`EnvSampler`]'s probability spread uniformly over the sphere.
const UNIFORM_SHARE: f64 = 0.1;

/// A latitude–longitude environment map of radiance \[W/(m² sr)\] (module doc for the convention).
#[derive(Debug, Clone, PartialEq)]
pub struct EnvMap {
    /// Texels per row (azimuth).
    pub width: usize,
    /// Rows (polar angle, top = up).
    pub height: usize,
    /// Radiance per texel, row-major from the top-left.
    pub radiance: Vec<Rgb>,
    /// World-from-map rotation (module doc); `None`: the map's frame is the world's.
    rotation: Option<DMat3>,
}

/// An environment map or dome light that cannot be built.
#[derive(Debug, thiserror::Error)]
pub enum EnvMapError {
    /// A side is 0 or above [`MAX_SIDE`].
    #[error("environment map is {width} × {height}; each side must be 1 to {MAX_SIDE}")]
    Size {
        /// Texels per row.
        width: usize,
        /// Rows.
        height: usize,
    },
    /// The texel count does not match the sides.
    #[error("environment map has {texels} texels, {width} × {height} needs {}", width * height)]
    Length {
        /// Texels given.
        texels: usize,
        /// Texels per row.
        width: usize,
        /// Rows.
        height: usize,
    },
    /// A texel's radiance is negative, NaN or infinite.
    #[error("environment texel (column {column}, row {row}) is {value:?}; radiance must be finite and non-negative")]
    Texel {
        /// Its column.
        column: usize,
        /// Its row.
        row: usize,
        /// Its radiance.
        value: Rgb,
    },
    /// A tint is negative, NaN or infinite.
    #[error("environment tint {0:?} must be finite and non-negative")]
    Tint(Rgb),
    /// A rotation matrix has a NaN or infinite entry.
    #[error("environment rotation {0:?} is not finite")]
    RotationNotFinite([f64; 9]),
    /// A matrix that is not a rotation.
    #[error("environment rotation {cols:?} is not orthogonal (|RᵀR − I| = {off:.3e}); give a pure rotation")]
    NotOrthogonal {
        /// The matrix, column by column.
        cols: [f64; 9],
        /// Largest entry of `|RᵀR − I|`.
        off: f64,
    },
    /// The dome's radiance scale is negative, NaN or infinite.
    #[error("the dome's radiance scale {0} must be finite and non-negative")]
    DomeScale(f64),
    /// The EXR file cannot be read.
    #[error(transparent)]
    Read(#[from] crate::image_io::ImageError),
    /// The EXR file has no `R`, `G`, `B` channels.
    #[error("{}: the environment map has no R, G, B channels (it has {channels:?})", path.display())]
    NoRgb {
        /// The file.
        path: std::path::PathBuf,
        /// The channels it has.
        channels: Vec<String>,
    },
    /// The EXR file's texels do not make a valid map.
    #[error("{}: {source}", path.display())]
    File {
        /// The file.
        path: std::path::PathBuf,
        /// What is wrong with its texels.
        source: Box<EnvMapError>,
    },
}

/// Largest deviation of `RᵀR` from the identity accepted as a rotation by [`EnvMap::with_rotation`].
const ORTHOGONALITY_TOLERANCE: f64 = 1e-9;

impl EnvMap {
    /// A map from its texels. Errors: a side outside `1..=`[`MAX_SIDE`], a wrong length, a negative,
    /// NaN or infinite radiance (naming the first texel).
    pub fn new(width: usize, height: usize, radiance: Vec<Rgb>) -> Result<Self, EnvMapError> {
        if !(1..=MAX_SIDE).contains(&width) || !(1..=MAX_SIDE).contains(&height) {
            return Err(EnvMapError::Size { width, height });
        }
        if radiance.len() != width * height {
            return Err(EnvMapError::Length { texels: radiance.len(), width, height });
        }
        if let Some(i) = radiance.iter().position(|v| v.iter().any(|c| !c.is_finite() || *c < 0.0)) {
            return Err(EnvMapError::Texel { column: i % width, row: i / width, value: radiance[i] });
        }
        Ok(Self { width, height, radiance, rotation: None })
    }

    /// A map of `width × height` texels all holding `radiance` (a uniform environment; any rotation
    /// leaves it unchanged).
    pub fn uniform(width: usize, height: usize, radiance: Rgb) -> Result<Self, EnvMapError> {
        // The sides are checked before the texels are allocated.
        let n = if (1..=MAX_SIDE).contains(&width) && (1..=MAX_SIDE).contains(&height) { width * height } else { 0 };
        Self::new(width, height, vec![radiance; n])
    }

    /// The map with every texel's radiance multiplied per channel by `tint` (finite, non-negative).
    pub fn tinted(mut self, tint: Rgb) -> Result<Self, EnvMapError> {
        if tint.iter().any(|c| !c.is_finite() || *c < 0.0) {
            return Err(EnvMapError::Tint(tint));
        }
        for v in &mut self.radiance {
            for c in 0..3 {
                v[c] *= tint[c];
            }
        }
        let rotation = self.rotation;
        Self::new(self.width, self.height, self.radiance).map(|m| Self { rotation, ..m })
    }

    /// The map placed in the world by `rotation` (world from map, column vectors; module doc), replacing
    /// any earlier rotation. Errors: a matrix that is not finite or not orthogonal (`|RᵀR − I|` above
    /// 1e-9). The identity is stored as no rotation, so an unrotated map behaves bit for bit as before.
    pub fn with_rotation(mut self, rotation: DMat3) -> Result<Self, EnvMapError> {
        let cols = rotation.to_cols_array();
        if cols.iter().any(|v| !v.is_finite()) {
            return Err(EnvMapError::RotationNotFinite(cols));
        }
        let gram = (rotation.transpose() * rotation - DMat3::IDENTITY).to_cols_array();
        let off = gram.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        if off > ORTHOGONALITY_TOLERANCE {
            return Err(EnvMapError::NotOrthogonal { cols, off });
        }
        self.rotation = (rotation != DMat3::IDENTITY).then_some(rotation);
        Ok(self)
    }

    /// The world-from-map rotation (the identity for an unrotated map).
    pub fn rotation(&self) -> DMat3 {
        self.rotation.unwrap_or(DMat3::IDENTITY)
    }

    /// A direction in the map's frame → world.
    pub(crate) fn to_world(&self, d: DVec3) -> DVec3 {
        self.rotation.map_or(d, |r| r * d)
    }

    /// A world direction → the map's frame (the transpose undoes an orthogonal matrix).
    fn to_map(&self, w: DVec3) -> DVec3 {
        self.rotation.map_or(w, |r| r.transpose() * w)
    }

    /// A map whose texels hold `f` at their centre directions.
    pub fn from_fn(width: usize, height: usize, f: impl Fn(DVec3) -> Rgb + Sync) -> Result<Self, EnvMapError> {
        let dirs: Vec<DVec3> = (0..width * height)
            .map(|i| direction((i % width) as f64 + 0.5, (i / width) as f64 + 0.5, width, height))
            .collect();
        Self::new(width, height, dirs.par_iter().map(|&d| f(d)).collect())
    }

    /// Reads the `R`, `G`, `B` channels of an EXR file, scaled by `intensity`. Errors name the file.
    pub fn read_exr(path: &Path, intensity: f64) -> Result<Self, EnvMapError> {
        let image = crate::image_io::read_exr_rgb(path)?;
        let rgb = image.rgb(None).ok_or_else(|| EnvMapError::NoRgb {
            path: path.to_path_buf(),
            channels: image.channels.keys().cloned().collect(),
        })?;
        let radiance = rgb.iter().map(|p| p.map(|c| f64::from(c) * intensity)).collect();
        Self::new(image.width, image.height, radiance)
            .map_err(|e| EnvMapError::File { path: path.to_path_buf(), source: Box::new(e) })
    }

    /// Centre direction of texel `(col, row)`.
    pub fn texel_direction(&self, col: usize, row: usize) -> DVec3 {
        self.to_world(direction(col as f64 + 0.5, row as f64 + 0.5, self.width, self.height))
    }

    /// Exact solid angle of a texel in `row` \[sr\].
    pub fn texel_solid_angle(&self, row: usize) -> f64 {
        let h = self.height as f64;
        let (t0, t1) = (std::f64::consts::PI * row as f64 / h, std::f64::consts::PI * (row + 1) as f64 / h);
        std::f64::consts::TAU / self.width as f64 * (t0.cos() - t1.cos())
    }

    /// `∫ ω dω` over texel `(col, row)` (exact): its length over the solid angle is the mean cosine of
    /// the texel's directions about their mean direction (→ 1 for small texels, 0 for a 1 × 1 map).
    pub fn texel_moment(&self, col: usize, row: usize) -> DVec3 {
        let (h, w) = (self.height as f64, self.width as f64);
        let (t0, t1) = (std::f64::consts::PI * row as f64 / h, std::f64::consts::PI * (row + 1) as f64 / h);
        let (p0, p1) = (std::f64::consts::TAU * col as f64 / w, std::f64::consts::TAU * (col + 1) as f64 / w);
        // ∫ sin²θ dθ and ∫ cos θ sin θ dθ over the row; ∫ (sin φ, −cos φ) dφ over the column.
        let s2 = 0.5 * (t1 - t0) - 0.25 * ((2.0 * t1).sin() - (2.0 * t0).sin());
        let cs = 0.5 * (t1.sin().powi(2) - t0.sin().powi(2));
        let dphi = p1 - p0;
        // A rotation is linear: the integral of the rotated directions is the rotated integral.
        self.to_world(DVec3::new(s2 * (p0.cos() - p1.cos()), dphi * cs, -s2 * (p1.sin() - p0.sin())))
    }

    /// The texel containing unit direction `w` (toward the environment, world frame).
    pub fn texel_of(&self, w: DVec3) -> (usize, usize) {
        let w = self.to_map(w);
        let theta = w.y.clamp(-1.0, 1.0).acos();
        let mut phi = w.x.atan2(-w.z);
        if phi < 0.0 {
            phi += std::f64::consts::TAU;
        }
        let col = ((phi / std::f64::consts::TAU * self.width as f64) as usize).min(self.width - 1);
        let row = ((theta / std::f64::consts::PI * self.height as f64) as usize).min(self.height - 1);
        (col, row)
    }

    /// Radiance arriving from unit direction `w` (nearest texel).
    pub fn lookup(&self, w: DVec3) -> Rgb {
        let (c, r) = self.texel_of(w);
        self.radiance[r * self.width + c]
    }

    /// `∫ L dω` over the sphere per channel (the irradiance a sphere's cross-section receives per unit
    /// area, times 4: the scalar fluence in empty space) \[W/m²\].
    pub fn integral(&self) -> Rgb {
        let mut sum = [0.0; 3];
        for row in 0..self.height {
            let omega = self.texel_solid_angle(row);
            for v in &self.radiance[row * self.width..(row + 1) * self.width] {
                for c in 0..3 {
                    sum[c] += v[c] * omega;
                }
            }
        }
        sum
    }
}

/// Direction at fractional texel coordinates (`x ∈ [0, W]`, `y ∈ [0, H]`).
pub(crate) fn direction(x: f64, y: f64, width: usize, height: usize) -> DVec3 {
    let theta = std::f64::consts::PI * y / height as f64;
    let phi = std::f64::consts::TAU * x / width as f64;
    let (st, ct) = theta.sin_cos();
    let (sp, cp) = phi.sin_cos();
    DVec3::new(st * sp, ct, -st * cp)
}

/// Importance sampling of directions from an [`EnvMap`]: a texel with probability
/// `∝ (1 − s) Y_t ΔΩ_t / Σ Y ΔΩ + s ΔΩ_t/4π` (`s` = 10 %: a uniform share, so every direction has a
/// positive density), then a direction uniform in solid angle inside the texel. The density per
/// steradian is `p_t/ΔΩ_t`.
#[derive(Debug, Clone)]
pub struct EnvSampler {
    /// Cumulative texel probabilities (row-major), last = 1.
    cdf: Vec<f64>,
    /// Texel probabilities.
    p: Vec<f64>,
    width: usize,
    height: usize,
    /// The map's world-from-map rotation.
    rotation: Option<DMat3>,
}

impl EnvSampler {
    /// The sampler of `env`.
    pub fn new(env: &EnvMap) -> Self {
        Self::with_importance(env, None)
    }

    /// The sampler of `env` with each texel's weight multiplied by a directional importance map (any
    /// size, the same latitude–longitude convention, read at the texel's centre direction; elek2014
    /// Sec. 5.2).
    pub fn with_importance(env: &EnvMap, importance: Option<&EnvMap>) -> Self {
        let (w, h) = (env.width, env.height);
        let weights: Vec<f64> = (0..w * h)
            .map(|i| {
                let imp = importance.map_or(1.0, |m| m.lookup(env.texel_direction(i % w, i / w))[0].max(0.0));
                luminance(env.radiance[i]).max(0.0) * env.texel_solid_angle(i / w) * imp
            })
            .collect();
        let total: f64 = weights.iter().sum();
        let four_pi = 4.0 * std::f64::consts::PI;
        let share = if total > 0.0 { UNIFORM_SHARE } else { 1.0 };
        let p: Vec<f64> = weights
            .iter()
            .enumerate()
            .map(|(i, &wt)| {
                let lum = if total > 0.0 { wt / total } else { 0.0 };
                (1.0 - share) * lum + share * env.texel_solid_angle(i / w) / four_pi
            })
            .collect();
        let mut cdf = Vec::with_capacity(p.len());
        let mut acc = 0.0;
        for v in &p {
            acc += v;
            cdf.push(acc);
        }
        let last = acc;
        for v in &mut cdf {
            *v /= last;
        }
        Self { cdf, p: p.iter().map(|v| v / last).collect(), width: w, height: h, rotation: env.rotation }
    }

    /// A direction for the uniform numbers `(u1, u2, u3)` in `[0, 1)` and its density per steradian.
    pub fn sample(&self, u1: f64, u2: f64, u3: f64) -> (DVec3, f64) {
        let t = self.cdf.partition_point(|&c| c <= u1).min(self.cdf.len() - 1);
        let (col, row) = (t % self.width, t / self.width);
        let h = self.height as f64;
        let (c0, c1) =
            ((std::f64::consts::PI * row as f64 / h).cos(), (std::f64::consts::PI * (row + 1) as f64 / h).cos());
        // Uniform in solid angle: cos θ uniform between the row's edges, φ uniform in the column.
        let ct = c0 + (c1 - c0) * u2;
        let st = (1.0 - ct * ct).max(0.0).sqrt();
        let phi = std::f64::consts::TAU * (col as f64 + u3) / self.width as f64;
        let (sp, cp) = phi.sin_cos();
        let omega = std::f64::consts::TAU / self.width as f64 * (c0 - c1);
        let d = DVec3::new(st * sp, ct, -st * cp);
        // Rotations keep solid angles: the density per steradian is the map frame's.
        (self.rotation.map_or(d, |r| r * d), self.p[t] / omega)
    }

    /// The texel index of lattice point `(u1, u2)` (for ordinate placement).
    pub(crate) fn texel(&self, u1: f64) -> usize {
        self.cdf.partition_point(|&c| c <= u1).min(self.cdf.len() - 1)
    }
}

/// A sky for the bundled scenes and the tests: a horizon-to-zenith gradient above (`√up` blend from a pale
/// horizon to a deeper zenith blue), a dim ground below and, when given, a sun disk `(toward the sun,
/// angular radius, radiance)`. Relative units (the bundled `scenes/sky.exr` is this without a sun at
/// 128 × 64; the pipeline scales it with `environment_intensity`). Pure function of its arguments.
pub fn procedural_sky(w: DVec3, sun: Option<(DVec3, f64, Rgb)>) -> Rgb {
    if let Some((dir, radius, radiance)) = sun
        && w.dot(dir) >= radius.cos()
    {
        return radiance;
    }
    if w.y >= 0.0 {
        let t = w.y.sqrt();
        [0.55 + (0.18 - 0.55) * t, 0.65 + (0.32 - 0.65) * t, 0.80 + (0.62 - 0.80) * t]
    } else {
        [0.10, 0.09, 0.08]
    }
}

/// Size of the map standing for a dome light without a texture (uniform radiance): enough texels for
/// the importance-sampled ordinates to spread over the sphere (one ordinate per texel).
pub const UNIFORM_DOME_SIZE: [usize; 2] = [64, 32];

/// The environment map of a scene's dome light ([`crate::scene::EnvironmentLight`]): its
/// latitude–longitude EXR texture × `scale` × `color`, or a uniform [`UNIFORM_DOME_SIZE`] map of
/// `color · scale` without a texture, placed by the dome's rotation (the dome's frame uses this module's
/// convention, so no re-mapping is needed). Errors: the texture's read error (naming the file), or an
/// invalid scale, colour or rotation.
pub fn dome_map(dome: &crate::scene::EnvironmentLight) -> Result<EnvMap, EnvMapError> {
    if !(dome.scale.is_finite() && dome.scale >= 0.0) {
        return Err(EnvMapError::DomeScale(dome.scale));
    }
    let map = match &dome.texture {
        Some(path) => EnvMap::read_exr(path, dome.scale)?.tinted(dome.color)?,
        None => {
            let [w, h] = UNIFORM_DOME_SIZE;
            EnvMap::uniform(w, h, dome.multiplier())?
        }
    };
    map.with_rotation(DMat3::from_cols_array_2d(&dome.rotation))
}

/// The bundled sky map's size.
pub const BUNDLED_SKY_SIZE: [usize; 2] = [128, 64];

/// The bundled sky map (`scenes/sky.exr`): [`procedural_sky`] without a sun at [`BUNDLED_SKY_SIZE`].
pub fn bundled_sky() -> EnvMap {
    let [w, h] = BUNDLED_SKY_SIZE;
    // Cannot fail: the sizes are in range and the values finite and non-negative.
    EnvMap::from_fn(w, h, |d| procedural_sky(d, None)).expect("the bundled sky is a valid map")
}
