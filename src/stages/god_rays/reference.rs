//! Brute-force references: ray marchers of the single-scattering integral (baran2010 Sec. 2.1 and
//! Sec. 10, "a simple ray marcher that uses shadow maps for visibility queries"), plus one with real
//! shadow rays through the BVH.
//!
//! **Input → output.** Camera, depth image, light, visibility (a [`ShadowMap`] or a [`SceneBvh`]),
//! medium and a step count → the in-scatter image, the same quantity [`super::render`] computes (the
//! conventions are in the module doc of [`super`]).
//!
//! Each view ray's medium segment `[s0, d]` ([`super::view_segment`]) is split into `steps` equal strata; stratum `k` contributes
//! `V(x)·σ_s p(μ) L_in(x) · ∫_{stratum} e^{−σ_t s} ds` with `x` at a jittered position inside it. The
//! transmittance integral is exact, so the estimate is exact for a constant integrand (an unshadowed
//! untextured directional light) and converges as `O(steps⁻¹)` or faster otherwise. The jitter is
//! counter-based ([`StreamKey`] keyed by the pixel, sample = stratum, dimension = run): images are
//! identical for any thread count, and runs with different numbers are independent, which
//! [`mean_of_runs`] uses to measure the marcher's own noise.

use glam::DVec3;
use rayon::prelude::*;

use super::{
    DistanceImage, EpiLight, EpiMedium, Image, LightFrame, RgbImage, ShadowMap, ViewCamera, depth_at, exp_integral,
    modulation, view_segment,
};
use crate::physics::rng::StreamKey;
use crate::scene::bvh::SceneBvh;

/// Where visibility comes from.
#[derive(Debug, Clone, Copy)]
pub enum Visibility<'a> {
    /// Shadow-map lookups ([`ShadowMap::lit`]).
    ShadowMap(&'a ShadowMap),
    /// Shadow rays through the scene.
    Bvh(&'a SceneBvh),
}

/// Stream-key table word of the marchers' jitter.
pub(crate) const JITTER_TABLE: u64 = 0xba4a_2010_e919_0001;

/// Everything a marched pixel needs.
#[derive(Debug, Clone, Copy)]
pub struct MarchCtx<'a> {
    /// Camera.
    pub cam: &'a ViewCamera,
    /// Depth image of the camera.
    pub depth: &'a DistanceImage,
    /// Light.
    pub light: &'a EpiLight,
    /// Visibility.
    pub vis: Visibility<'a>,
    /// Medium (and the region it fills: where view rays start and end, where the light enters).
    pub medium: &'a EpiMedium,
    /// Light projection (texture coordinates).
    pub frame: &'a LightFrame,
    /// Strata per ray (at least 1).
    pub steps: usize,
    /// Jitter run: runs with different numbers draw independent jitter (0 by default).
    pub run: u32,
}

impl MarchCtx<'_> {
    /// `σ_s p(μ) L_in(x)` per channel for view direction `v` (unshadowed).
    fn incident(&self, x: DVec3, v: DVec3) -> [f64; 3] {
        let m = modulation(self.light, self.frame, x);
        let sig_s = self.medium.sigma_s_clean();
        let strength = self.light.strength().map(|c| if c.is_finite() { c.max(0.0) } else { 0.0 });
        match self.light {
            EpiLight::Directional { direction, .. } => {
                let l = DVec3::from_array(*direction).try_normalize().unwrap_or(DVec3::NEG_Y);
                let p = self.medium.phase(-l.dot(v));
                let u = self.depth_to_light(x, -l);
                let st = self.medium.sigma_t();
                [0, 1, 2].map(|c| sig_s[c] * p * strength[c] * m[c] * (-st[c] * u).exp())
            }
            EpiLight::Spot { position, .. } => {
                let wv = x - DVec3::from_array(*position);
                let r = wv.length();
                if r <= 1e-12 {
                    return [0.0; 3];
                }
                let p = self.medium.phase(-(wv / r).dot(v));
                let st = self.medium.sigma_t();
                [0, 1, 2].map(|c| sig_s[c] * p * strength[c] * m[c] * (-st[c] * r).exp() / (r * r))
            }
        }
    }

    /// How far the light has travelled inside the medium's box to reach `x` (inside it) along `-toward`:
    /// the distance from `x` to the box's face in the direction `toward` of the light.
    fn depth_to_light(&self, x: DVec3, toward: DVec3) -> f64 {
        let (lo, hi) = self.medium.region;
        let mut u = f64::INFINITY;
        for a in 0..3 {
            let face = if toward[a] > 0.0 { hi[a] } else { lo[a] };
            if toward[a] != 0.0 {
                u = u.min(((face - x[a]) / toward[a]).max(0.0));
            }
        }
        if u.is_finite() { u } else { 0.0 }
    }

    fn visible(&self, x: DVec3) -> bool {
        match self.vis {
            Visibility::ShadowMap(s) => s.lit(x),
            Visibility::Bvh(b) => match self.light {
                EpiLight::Directional { direction, .. } => {
                    let l = DVec3::from_array(*direction);
                    !b.occluded(x.to_array(), (-l).to_array(), f64::INFINITY)
                }
                EpiLight::Spot { position, .. } => {
                    let d = DVec3::from_array(*position) - x;
                    !b.occluded(x.to_array(), d.to_array(), 1.0)
                }
            },
        }
    }

    /// The in-scatter of pixel `(x, y)`.
    pub fn pixel(&self, x: usize, y: usize) -> [f32; 3] {
        let v = self.cam.pixel_dir(x, y);
        let (s0, d) = view_segment(self.cam.position, v, depth_at(self.depth, x, y), self.medium.region);
        let n = self.steps.max(1);
        if d <= s0 {
            return [0.0; 3];
        }
        let key = StreamKey { table: JITTER_TABLE, cell: (y * self.cam.width + x) as u64 };
        let st = self.medium.sigma_t();
        let dt = (d - s0) / n as f64;
        let mut acc = [0.0f64; 3];
        for k in 0..n {
            let a = s0 + k as f64 * dt;
            let b = if k + 1 == n { d } else { a + dt };
            let t = a + key.uniform(k as u64, self.run) * (b - a);
            let p = self.cam.position + t * v;
            let inc = self.incident(p, v);
            if inc.iter().all(|&c| c <= 0.0) || !self.visible(p) {
                continue;
            }
            for c in 0..3 {
                acc[c] += inc[c] * exp_integral(st[c], a, b);
            }
        }
        acc.map(|c| if c.is_finite() && c > 0.0 { c as f32 } else { 0.0 })
    }

    /// The whole image, rows in parallel.
    pub fn image(&self) -> RgbImage {
        let (w, h) = (self.cam.width, self.cam.height);
        let mut img = Image::filled(w, h, [0.0f32; 3]);
        img.data.par_chunks_mut(w).enumerate().for_each(|(y, row)| {
            for (x, px) in row.iter_mut().enumerate() {
                *px = self.pixel(x, y);
            }
        });
        img
    }
}

/// Shadow-mapped ray marcher with `steps_per_ray` jittered strata per pixel (the paper's brute force).
pub fn march_shadow_map(
    cam: &ViewCamera,
    depth: &DistanceImage,
    light: &EpiLight,
    shadow: &ShadowMap,
    medium: &EpiMedium,
    steps_per_ray: usize,
) -> RgbImage {
    MarchCtx {
        cam,
        depth,
        light,
        vis: Visibility::ShadowMap(shadow),
        medium,
        frame: &shadow.frame,
        steps: steps_per_ray,
        run: 0,
    }
    .image()
}

/// Ray marcher casting a real shadow ray through `bvh` at every step (no shadow-map aliasing);
/// `bounds` are the scene bounds (the window the light texture is projected over, as in
/// [`super::render_shadow_map`]); `run` picks the jitter (runs with different numbers are independent).
#[allow(clippy::too_many_arguments)]
pub fn march_bvh(
    cam: &ViewCamera,
    depth: &DistanceImage,
    light: &EpiLight,
    bvh: &SceneBvh,
    medium: &EpiMedium,
    bounds: ([f64; 3], [f64; 3]),
    steps_per_ray: usize,
    run: u32,
) -> RgbImage {
    let frame = LightFrame::new(light, bounds);
    MarchCtx { cam, depth, light, vis: Visibility::Bvh(bvh), medium, frame: &frame, steps: steps_per_ray, run }.image()
}

/// Two independently jittered marcher images `a`, `b` → their mean and the variance of each pixel's
/// mean, estimated as `(a − b)²/4` per channel. One degree of freedom per pixel: unbiased, so its mean
/// over many pixels is a fair noise level (a floor built from it is conservative by `3^{1/4}`, since
/// `E[(a − b)⁴] = 3 E[(a − b)²]²` for Gaussian noise).
pub fn mean_of_runs(a: &RgbImage, b: &RgbImage) -> (RgbImage, Vec<[f64; 3]>) {
    let mut mean = a.clone();
    let mut variance = Vec::with_capacity(a.data.len());
    for ((m, x), y) in mean.data.iter_mut().zip(&a.data).zip(&b.data) {
        let (x, y) = (x.map(f64::from), y.map(f64::from));
        *m = std::array::from_fn(|c| (0.5 * (x[c] + y[c])) as f32);
        variance.push(std::array::from_fn(|c| 0.25 * (x[c] - y[c]).powi(2)));
    }
    (mean, variance)
}
