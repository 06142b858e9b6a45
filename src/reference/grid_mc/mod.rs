//! Monte-Carlo reference for Principal-Ordinates Propagation (POP, elek2014) on voxel media.
//!
//! **Input → output.** A [`VoxelMedium`] (axis-aligned box of voxels with piecewise-constant
//! density; `σ_s = density·sigma_s[c]`, `σ_a = density·sigma_a[c]`, HG `g[c]` per channel; vacuum
//! outside the box, no surfaces) lit by a [`DirectionalLight`] from outside, and either
//! - a [`TallySpec`] → ([`light_trace`]) a [`RadianceTally`]: per cell of a uniform tally grid over
//!   the box the fluence `∫ L dω` \[W/m²\], its uncollided part, and the radiance averaged over
//!   polar bins of the angle to an axis \[W/(m²·sr)\], each with a standard error; or
//! - a [`ViewCamera`](crate::render::ViewCamera) → ([`render`]) a [`ReferenceImage`]: per pixel the radiance reaching the eye
//!   \[W/(m²·sr)\] with the variance of its mean, its once-scattered part, and the exact
//!   transmittance of the box along the pixel-centre ray.
//!
//! It is the reference for elek2014 Fig. 12 (unit cube, `σ_s = 4 /m`, albedo 1, directional
//! light, `g ∈ {0, 0.7, 0.96}`: incident radiance distributions in the mid slice, from the
//! radiance tally) and for POP images (from [`render`]). It shares no code with the POP solver:
//! only the input types, the counter-based random streams ([`crate::physics::rng`]) and HG
//! sampling/evaluation ([`crate::physics::hg`], verified on its own).
//!
//! **Free flights and transmittance** are exact: the optical depth along a ray is a sum over the
//! voxels it crosses (a 3-D DDA; piecewise constant, so each piece is `σ·length`), a free flight
//! is drawn by inverting it exactly (`−ln(1−ξ)` walked off voxel by voxel), and a transmittance is
//! `exp(−σ_t ∫ density ds)`. No delta tracking, no majorants.
//!
//! **Light tracing** ([`light_trace`]). Photons start on the box's front faces (the faces with
//! `n·direction < 0`), a face chosen with probability `∝ |direction_i|·area_i` and a point uniform on
//! it: this is uniform over the box's projection onto the plane ⟂ the light, of area
//! `A⊥ = Σ_i |direction_i|·area_i`, so each photon carries `E_c·A⊥/photons` \[W\] in channel `c`.
//! Walks are *weighted*: flights are sampled ∝ `σ_t·T`, and at each collision the weight is
//! multiplied by the albedo `σ_s/σ_t` (absorption is never sampled) and a new direction is drawn
//! from HG about the current one. Below `1/16` of its starting weight a photon plays an unbiased
//! Russian roulette (survive with probability ½, weight doubled). Estimators:
//! - *uncollided* light: the expected track length, not a sampled one. Along the photon's entry
//!   ray every piece `[u, v]` inside one voxel and one tally cell adds
//!   `w·∫_u^v T(s) ds / V_k = w·T(u)(1 − e^{−σ_t(v−u)})/σ_t / V_k` exactly (the expectation of
//!   the track length given the entry point), so the uncollided fluence has no noise from flight
//!   sampling — only from where photons enter (none at all when every photon sees the same
//!   medium, e.g. a tally with one cell across the beam);
//! - *collided* light: the track-length estimator, every flight segment after a scattering event
//!   adds `w·ℓ/V_k` to the fluence of each tally cell `k` it crosses (clipped by a DDA over the
//!   tally grid) and `w·ℓ/(V_k·ΔΩ_b)` to the radiance of its direction's polar bin `b`.
//!
//! Both are unbiased: the first is the conditional expectation of the track-length estimator of the
//! first flight given its start, the second is the track-length estimator itself (the expected
//! weighted path length a walk spends in a cell is `∫_k φ dV` divided by the power the walk
//! carries), and weighting by the albedo and unbiased roulette keep every expectation. Walks stop when they leave the box (their weight is *escaped* energy) or after
//! `max_events` scattering events (flights after event `max_events` are still tallied; the weight
//! reaching collision `max_events + 1` is reported as truncated, and with it the transport is
//! biased low by at most that fraction). `max_events = 1` therefore tallies exactly the uncollided
//! plus the once-scattered light.
//!
//! **Standard errors** come from 64 batch means (fewer when there are fewer photons): photon `i`
//! of `N` belongs to batch `⌊64 i/N⌋`, each batch is traced sequentially in one task, and batches
//! are folded in index order (mean = sum of batch sums; Welford over batch means), so every
//! number is bit-identical for any rayon thread count.
//!
//! **Camera paths** ([`render`]). One pinhole ray through each pixel *centre*
//! ([`ViewCamera::pixel_dir`](crate::render::ViewCamera::pixel_dir); no jitter, so [`ReferenceImage::transmittance`] is the exact
//! transmittance along it). Each sample traces the ray into the box (black background; the
//! delta light is never seen directly), samples a collision ∝ `σ_t·T`, and at every collision does
//! next-event estimation toward the light:
//! `β·(σ_s/σ_t)·f_hg(light.direction·(−ω_path))·E_c·exp(−σ_t ∫ density ds)` to the box exit along
//! `−light.direction`, where `β` is the product of earlier albedos (and roulette factors) and
//! `ω_path` the direction the path travels (away from the eye); then `β *= σ_s/σ_t` and the next
//! direction is drawn from HG about `ω_path` (HG is symmetric, so this is the adjoint phase
//! sampling). The first collision's estimate is also [`ReferenceImage::single`]. Russian roulette
//! as for photons (below `β = 1/16`); paths stop after `max_events` collisions
//! ([`ReferenceImage::truncated_paths`] counts those that were cut with weight left). Each pixel's
//! samples are accumulated in order (Welford), pixels run in parallel: bit-identical for any thread
//! count.
//!
//! **Environment** ([`render_environment`]). The same camera paths lit by an
//! [`EnvMap`](crate::render::environment::EnvMap) instead of a directional light, with the opaque
//! surfaces of an [`Occluder`](crate::render::occluder::Occluder) (black: a path that reaches one
//! ends; the eye ray ends at the G-buffer's surface distance). Next-event estimation draws a direction
//! `w` from the map's importance sampler (density `p(w)` per steradian, positive everywhere) and adds
//! `β·(σ_s/σ_t)·f_hg(w·ω_path)·L(w)·V(w)·exp(−σ_t ∫ density ds)/p(w)`, `V` the occluder's visibility.
//! The eye ray's first collision is forced into its segment through the medium (drawn ∝ `σ_t·T` on
//! the segment, the weight multiplied by `1 − T` of the segment), so in thin media every path
//! contributes. Escaping paths add nothing (the background the eye sees directly is not scattered light), so the
//! estimate is unbiased with next-event estimation alone. Checked by the white furnace: albedo 1
//! under a uniform map `L`, scattered + `L·T` = `L` along every ray.
//!
//! **Channels.** Channels whose `(σ_s, σ_a, g)` are identical share one walk (its weight applies
//! to each of them with its own irradiance); otherwise one walk per distinct channel
//! ([`RadianceTally::walks`], [`ReferenceImage::walks`]). All walks of photon (or sample) `i`
//! use the same random numbers (common random numbers across channels).
//!
//! **Robustness.** No input panics. A light direction that is zero or not finite, non-finite
//! irradiance (that channel), a zero-sized tally grid, zero photons or samples give zeros; the
//! tally axis falls back to the light direction when it is zero or not finite; `theta_bins = 0`
//! gives an empty radiance tally. Non-finite contributions cannot arise from validated media and
//! finite irradiance: every factor is bounded (weights ≤ twice the start weight, transmittances ≤ 1,
//! `f_hg ≤ (1 + g)/(4π(1 − g)²)`, track lengths ≤ the box diagonal).
//!
//! **Limitations.** Pixel-centre rays only (the caller averages several cameras for a pixel
//! filter); surfaces only as black occluders of environment light; the light tracer's camera-free radiance tally averages over azimuth.

mod camera;
mod grid;
mod light;

#[cfg(test)]
mod tests;

use glam::DVec3;

pub use camera::{render, render_environment};
pub use light::light_trace;

use crate::render::voxel::{DirectionalLight, VoxelMedium};

/// The tally grid and polar bins of [`light_trace`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TallySpec {
    /// Tally cells along x, y, z: a uniform grid over the medium box (independent of the voxels).
    pub dims: [usize; 3],
    /// Polar bins of the angle `θ ∈ [0, π]` between a photon's travel direction and `axis`, uniform in
    /// `θ` (bin `b` covers solid angle `2π(cos θ_b − cos θ_{b+1})`; azimuth is averaged).
    pub theta_bins: usize,
    /// Axis of the polar bins (normalised here; the light direction if zero or not finite).
    pub axis: DVec3,
}

/// How many photons [`light_trace`] follows.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LightTraceOptions {
    /// Photons (per walk; module doc, "Channels").
    pub photons: u64,
    /// Seed, hashed into the stream key.
    pub seed: u64,
    /// Most scattering events per photon; weight reaching event `max_events + 1` is truncated.
    pub max_events: u32,
}

/// Fluence and radiance per tally cell from [`light_trace`] (module doc for the estimators).
#[derive(Debug, Clone, PartialEq)]
pub struct RadianceTally {
    /// Tally cells along x, y, z (cell index `x + dims[0]·(y + dims[1]·z)`).
    pub dims: [usize; 3],
    /// Polar bins per cell.
    pub theta_bins: usize,
    /// Per cell: `∫ L dω` over the sphere, averaged over the cell \[W/m²\].
    pub fluence: Vec<[f64; 3]>,
    /// Standard error of `fluence` (64 batch means).
    pub fluence_std_err: Vec<[f64; 3]>,
    /// The part of `fluence` that never scattered (expected-track-length estimator).
    pub uncollided_fluence: Vec<[f64; 3]>,
    /// `[cell · theta_bins + bin]`: radiance averaged over the cell and the bin's solid angle
    /// \[W/(m²·sr)\] (uncollided light included).
    pub radiance: Vec<[f64; 3]>,
    /// Standard error of `radiance`.
    pub radiance_std_err: Vec<[f64; 3]>,
    /// Photons traced per walk.
    pub photons: u64,
    /// Distinct walks (channel groups with identical coefficients).
    pub walks: u32,
    /// Wall time \[s\].
    pub seconds: f64,
    /// Energy cut off by `max_events`, as a fraction of the energy entering the box (all channels).
    pub truncated_fraction: f64,
    /// Power entering the box, `E_c·A⊥` \[W\].
    pub injected: [f64; 3],
    /// Power leaving the box (weights of escaping photons) \[W\].
    pub escaped: [f64; 3],
    /// Standard error of `escaped`.
    pub escaped_std_err: [f64; 3],
    /// Power absorbed, scored at collisions as `w·(1 − albedo)` \[W\].
    pub absorbed: [f64; 3],
    /// Standard error of `absorbed`.
    pub absorbed_std_err: [f64; 3],
}

/// How many camera paths [`render`] traces.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CameraOptions {
    /// Paths per pixel (per walk).
    pub samples: u32,
    /// Seed, hashed into the stream key.
    pub seed: u64,
    /// Most collisions (next-event vertices) per path.
    pub max_events: u32,
}

/// A rendered reference image from [`render`].
#[derive(Debug, Clone, PartialEq)]
pub struct ReferenceImage {
    /// Pixels per row.
    pub width: usize,
    /// Rows.
    pub height: usize,
    /// Row-major radiance reaching the eye, mean over samples \[W/(m²·sr)\].
    pub radiance: Vec<[f64; 3]>,
    /// Variance of that mean per pixel (sample variance / samples).
    pub variance: Vec<[f64; 3]>,
    /// The once-scattered part of `radiance` (mean).
    pub single: Vec<[f64; 3]>,
    /// Variance of the mean of `single`.
    pub single_variance: Vec<[f64; 3]>,
    /// Exact transmittance of the box along the pixel-centre ray (1 where it misses).
    pub transmittance: Vec<[f64; 3]>,
    /// Wall time \[s\].
    pub seconds: f64,
    /// Samples per pixel.
    pub samples: u32,
    /// Distinct walks (channel groups with identical coefficients).
    pub walks: u32,
    /// Paths cut by `max_events` with weight left (summed over walks).
    pub truncated_paths: u64,
}

/// One walk: the scalar coefficients at density 1 shared by the channels in `mask`.
#[derive(Debug, Clone, Copy)]
struct Walk {
    sigma_s: f64,
    sigma_t: f64,
    g: f64,
    /// Irradiance per channel for the channels of this walk, 0 for the others.
    e: [f64; 3],
}

impl Walk {
    /// `σ_s/σ_t` (0 when `σ_t = 0`, where no collision happens anyway).
    fn albedo(&self) -> f64 {
        if self.sigma_t > 0.0 { self.sigma_s / self.sigma_t } else { 0.0 }
    }
}

/// Groups channels with identical `(σ_s, σ_a, g)` into walks; non-finite irradiance counts as 0.
fn walks(medium: &VoxelMedium, light: &DirectionalLight) -> Vec<Walk> {
    let mut out: Vec<(usize, Walk)> = Vec::new();
    for c in 0..3 {
        let e = if light.irradiance[c].is_finite() { light.irradiance[c] } else { 0.0 };
        let key = medium.coefficients.channel(c);
        if let Some((_, w)) = out.iter_mut().find(|(k, _)| medium.coefficients.channel(*k) == key) {
            w.e[c] = e;
        } else {
            let mut ev = [0.0; 3];
            ev[c] = e;
            let w = Walk { sigma_s: key.sigma_s, sigma_t: key.sigma_s + key.sigma_a, g: key.g, e: ev };
            out.push((c, w));
        }
    }
    out.into_iter().map(|(_, w)| w).collect()
}

/// The stream-key table word for `seed` (SplitMix64 finaliser with a module-specific constant).
fn seed_hash(seed: u64, salt: u64) -> u64 {
    let mut z = seed.wrapping_add(0x9e37_79b9_7f4a_7c15) ^ salt;
    z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    z ^ (z >> 31)
}

/// The unit light direction, `None` if zero or not finite.
fn light_dir(light: &DirectionalLight) -> Option<DVec3> {
    if light.direction.is_finite() { light.direction.try_normalize() } else { None }
}

/// Per-entry running mean and sum of squared deviations over batch means (Welford).
#[derive(Debug, Clone, Default)]
struct Welford {
    n: u64,
    mean: Vec<[f64; 3]>,
    m2: Vec<[f64; 3]>,
}

impl Welford {
    fn new(len: usize) -> Self {
        Welford { n: 0, mean: vec![[0.0; 3]; len], m2: vec![[0.0; 3]; len] }
    }

    /// Adds one batch estimate (`scale · values`).
    fn push(&mut self, values: &[[f64; 3]], scale: f64) {
        self.n += 1;
        let n = self.n as f64;
        for ((m, q), v) in self.mean.iter_mut().zip(self.m2.iter_mut()).zip(values) {
            for c in 0..3 {
                let x = v[c] * scale;
                let d = x - m[c];
                m[c] += d / n;
                q[c] += d * (x - m[c]);
            }
        }
    }

    /// Standard errors of the mean of the batch estimates.
    fn std_err(&self) -> Vec<[f64; 3]> {
        let n = self.n as f64;
        self.m2
            .iter()
            .map(|q| if self.n > 1 { q.map(|v| (v.max(0.0) / (n * (n - 1.0))).sqrt()) } else { [0.0; 3] })
            .collect()
    }
}

/// An unbiased Russian roulette below `w_ref/16`: survive with probability ½ at twice the weight.
fn roulette(w: f64, w_ref: f64, xi: f64) -> Option<f64> {
    if w >= w_ref / 16.0 {
        Some(w)
    } else if xi < 0.5 {
        Some(2.0 * w)
    } else {
        None
    }
}
