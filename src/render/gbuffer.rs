//! Camera G-buffers rendered by voltab's own ray tracer, so the screen-space effects run on any
//! imported scene.
//!
//! **Input → output.** A [`Scene`], its [`SceneBvh`] and a [`ViewCamera`] → per pixel the distance to
//! the first surface along the pixel-centre ray ([`distance_image`]) and the radiance reaching the eye
//! with the media removed ([`render`]), which the effects then attenuate and scatter. Both buffers use
//! the same pixel-centre rays (no anti-aliasing), so every colour pixel belongs to its distance.

use std::time::Instant;

use rayon::prelude::*;

use super::{DistanceImage, Image, RgbImage, ViewCamera};
use crate::reference::volpath::{self, CameraRay, VolPathOptions};
use crate::scene::Scene;
use crate::scene::bvh::{Ray, SceneBvh};

/// Distance \[m\] along each pixel-centre unit ray to the closest triangle (`f32::INFINITY` when the
/// ray escapes), rows in parallel.
pub fn distance_image(bvh: &SceneBvh, cam: &ViewCamera) -> DistanceImage {
    let mut img = Image::filled(cam.width, cam.height, f32::INFINITY);
    img.data.par_chunks_mut(cam.width).enumerate().for_each(|(y, row)| {
        for (x, px) in row.iter_mut().enumerate() {
            let d = cam.pixel_dir(x, y);
            let ray = Ray::new(cam.position.to_array(), d.to_array());
            if let Some(h) = bvh.closest_hit(&ray) {
                *px = h.t as f32;
            }
        }
    });
    img
}

/// How the colour buffer is rendered.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ColourOptions {
    /// Paths per pixel (through the pixel centre, like the distance buffer).
    pub samples: u32,
    /// Surface bounces after the first hit (0: emission plus direct light).
    pub bounces: u32,
    /// Seed of the counter-based streams.
    pub seed: u64,
}

impl Default for ColourOptions {
    fn default() -> Self {
        ColourOptions { samples: 16, bounces: 0, seed: 0 }
    }
}

/// A camera view's buffers: what the screen-space effects take as input.
#[derive(Debug, Clone)]
pub struct GBuffer {
    /// The camera.
    pub camera: ViewCamera,
    /// Radiance reaching the eye with the media removed \[W/(m²·sr)\].
    pub colour: RgbImage,
    /// Distance to the first surface \[m\].
    pub distance: DistanceImage,
    /// Time for the distance buffer \[ms\].
    pub distance_ms: f64,
    /// Time for the colour buffer \[ms\].
    pub colour_ms: f64,
}

/// Renders the distance buffer and the vacuum colour buffer of `cam` (the colour by
/// [`volpath::radiance`] with media off: emission plus light from
/// every light kind with shadow rays, and `bounces` diffuse bounces). Media are left to the effects.
pub fn render(scene: &Scene, bvh: &SceneBvh, cam: &ViewCamera, opts: &ColourOptions) -> GBuffer {
    let t0 = Instant::now();
    let distance = distance_image(bvh, cam);
    let distance_ms = t0.elapsed().as_secs_f64() * 1e3;
    let t0 = Instant::now();
    let rays: Vec<CameraRay> = (0..cam.height)
        .flat_map(|y| (0..cam.width).map(move |x| (x, y)))
        .map(|(x, y)| CameraRay { origin: cam.position.to_array(), direction: cam.pixel_dir(x, y).to_array() })
        .collect();
    let vp = VolPathOptions {
        samples: opts.samples.max(1),
        max_depth: opts.bounces,
        rr_depth: opts.bounces.max(1),
        seed: opts.seed,
        surface_bounces: u32::MAX,
        eye_surfaces: true,
        media: false,
    };
    let (est, _) = volpath::radiance(scene, bvh, &rays, &vp);
    let colour = Image {
        width: cam.width,
        height: cam.height,
        data: est.iter().map(|e| e.mean.map(|c| if c.is_finite() { c.max(0.0) as f32 } else { 0.0 })).collect(),
    };
    GBuffer { camera: *cam, colour, distance, distance_ms, colour_ms: t0.elapsed().as_secs_f64() * 1e3 }
}
