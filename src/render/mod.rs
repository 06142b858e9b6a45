//! The render floor: what every technique's stage stands on — image and camera types, the G-buffer,
//! colour, optics, voxel media, occluders and the GPU context.
//!
//! **Input → output.** A scene and a camera → per-pixel buffers (an HDR colour image, the distance
//! along each pixel's view ray: [`gbuffer`]), which the techniques in `crate::stages` turn into their
//! images; or EXR files of another renderer in their place.
//!
//! - [`gbuffer`]: scene + camera → distance and vacuum colour buffers.
//! - [`color`]: Rec. 709 luminance (one home) and the per-channel [`color::Rgb`] triple.
//! - [`dielectric`]: a medium inside a smooth dielectric boundary, spherical emitters and the setup the
//!   translucent renderer and its reference read.
//! - [`environment`]: latitude–longitude environment maps, their sampling, the dome and the bundled sky.
//! - [`frame`]: the methods' orthonormal frame (Duff et al. 2017).
//! - [`voxel`]: voxel media and directional lights (POP and its grid Monte-Carlo reference).
//! - [`occluder`]: opaque geometry as a segment/ray blocking query (POP and its reference).
//! - [`spot`]: the `KHR_lights_punctual` spot cone and its falloff (one home).
//! - [`optics`]: Fresnel reflectance, refraction, reflection at smooth dielectric interfaces (one home).
//! - [`gpu`]: device choice, wgpu context, shader validation (the passes live with their techniques).
//!
//! Conventions shared by every effect: pixel `(x, y)` has its centre at `(x + ½, y + ½)`, `y` grows
//! downwards, images are row-major (`data[y · width + x]`), distances are metres along the unit view ray
//! (`f32::INFINITY` for sky pixels), colours are linear RGB radiance \[W/(m²·sr)\].

pub mod color;
pub mod dielectric;
pub mod environment;
pub mod frame;
pub mod gbuffer;
pub mod gpu;
pub mod occluder;
pub mod optics;
pub mod spot;
pub mod voxel;

use glam::DVec3;

/// A row-major image of `T`.
#[derive(Debug, Clone, PartialEq)]
pub struct Image<T> {
    /// Pixels per row.
    pub width: usize,
    /// Rows.
    pub height: usize,
    /// `width · height` pixels, row-major.
    pub data: Vec<T>,
}

impl<T: Clone> Image<T> {
    /// An image filled with `value`.
    pub fn filled(width: usize, height: usize, value: T) -> Self {
        Image { width, height, data: vec![value; width * height] }
    }
}

impl<T: Copy> Image<T> {
    /// Pixel `(x, y)`; panics when out of range (callers iterate over the image's own size).
    pub fn at(&self, x: usize, y: usize) -> T {
        self.data[y * self.width + x]
    }
}

/// Linear RGB radiance image.
pub type RgbImage = Image<[f32; 3]>;
/// Distance along each pixel's unit view ray \[m\] (`f32::INFINITY` where the ray hits nothing).
pub type DistanceImage = Image<f32>;

/// A pinhole camera with an image raster: maps pixels to world-space rays and back.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ViewCamera {
    /// Eye position \[m\].
    pub position: DVec3,
    /// Unit viewing direction.
    pub forward: DVec3,
    /// Unit vector to the right of the image.
    pub right: DVec3,
    /// Unit vector to the top of the image.
    pub up: DVec3,
    /// `tan(yfov / 2)`.
    pub tan_half_y: f64,
    /// Pixels per row.
    pub width: usize,
    /// Rows.
    pub height: usize,
}

impl ViewCamera {
    /// A camera at `position` looking along `forward` with `up` as the image's upward hint, vertical
    /// field of view `yfov` \[rad\]. `None` when the vectors are degenerate (zero, parallel, non-finite),
    /// `yfov ∉ (0, π)` or the raster is empty.
    pub fn new(
        position: [f64; 3],
        forward: [f64; 3],
        up: [f64; 3],
        yfov: f64,
        width: usize,
        height: usize,
    ) -> Option<Self> {
        let p = DVec3::from_array(position);
        let f = DVec3::from_array(forward).try_normalize()?;
        let r = f.cross(DVec3::from_array(up)).try_normalize()?;
        let u = r.cross(f);
        if !(p.is_finite() && yfov > 0.0 && yfov < std::f64::consts::PI) || width == 0 || height == 0 {
            return None;
        }
        Some(ViewCamera { position: p, forward: f, right: r, up: u, tan_half_y: (0.5 * yfov).tan(), width, height })
    }

    /// A camera from a scene camera (perspective only; the raster's aspect ratio is `width / height`).
    pub fn from_scene(camera: &crate::scene::Camera, width: usize, height: usize) -> Option<Self> {
        match camera.projection {
            crate::scene::Projection::Perspective { yfov, .. } => {
                Self::new(camera.position, camera.forward, camera.up, yfov, width, height)
            }
            crate::scene::Projection::Orthographic { .. } => None,
        }
    }

    /// `width / height`.
    pub fn aspect(&self) -> f64 {
        self.width as f64 / self.height as f64
    }

    /// Unit world-space direction through raster position `(x, y)` (pixel units, `y` down; pixel
    /// centres at half-integers).
    pub fn ray_dir(&self, x: f64, y: f64) -> DVec3 {
        let sx = (2.0 * x / self.width as f64 - 1.0) * self.tan_half_y * self.aspect();
        let sy = (1.0 - 2.0 * y / self.height as f64) * self.tan_half_y;
        (self.forward + sx * self.right + sy * self.up).normalize()
    }

    /// Unit direction through the centre of pixel `(x, y)`.
    pub fn pixel_dir(&self, x: usize, y: usize) -> DVec3 {
        self.ray_dir(x as f64 + 0.5, y as f64 + 0.5)
    }

    /// Raster position of the direction `d` seen from the eye (its vanishing point), and whether it
    /// lies in front of the camera (`⟨d, forward⟩ > 0`). `None` when `d` is perpendicular to the view
    /// axis (the point is at infinity on the image plane). Used for epipoles of lights.
    pub fn project_dir(&self, d: DVec3) -> Option<([f64; 2], bool)> {
        let z = d.dot(self.forward);
        if z.abs() < 1e-12 * d.length() || !d.is_finite() {
            return None;
        }
        let sx = d.dot(self.right) / z / (self.tan_half_y * self.aspect());
        let sy = d.dot(self.up) / z / self.tan_half_y;
        Some(([(sx + 1.0) * 0.5 * self.width as f64, (1.0 - sy) * 0.5 * self.height as f64], z > 0.0))
    }

    /// Raster position of world point `p` and whether it lies in front of the eye; `None` when `p` is on
    /// the eye's plane.
    pub fn project_point(&self, p: DVec3) -> Option<([f64; 2], bool)> {
        self.project_dir(p - self.position)
    }
}

/// Relative RMSE of `img` against `reference` over pixels and channels (`sqrt(Σ(x−r)²)/sqrt(Σr²)`); `∞` for
/// mismatching sizes, 0 when both are zero.
pub fn rel_rmse(img: &RgbImage, reference: &RgbImage) -> f64 {
    if img.data.len() != reference.data.len() {
        return f64::INFINITY;
    }
    let (mut num, mut den) = (0.0f64, 0.0f64);
    for (a, r) in img.data.iter().zip(&reference.data) {
        for c in 0..3 {
            let (x, y) = (f64::from(a[c]), f64::from(r[c]));
            num += (x - y) * (x - y);
            den += y * y;
        }
    }
    if den > 0.0 {
        (num / den).sqrt()
    } else if num > 0.0 {
        f64::INFINITY
    } else {
        0.0
    }
}

#[cfg(test)]
mod tests;
