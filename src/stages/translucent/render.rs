//! The point-based renderer of wang2018 Sec. 3.5, 4.3, 4.4 and 5.1.
//!
//! **Input → output.** A [`Setup`], an `MsLobes` table holding the material's (α, g) slices, the
//! light samples of [`super::points`] and a camera → a [`Frame`]: per pixel the components of Eq. 9
//! (single, double, multiple, bounced scattering inside the object, and the rest of the picture), the
//! object mask, per-pass wall times (the paper's Table 3 columns) and counts.
//!
//! **Passes** (Sec. 4.4: rays first, scattering after):
//! 1. *Camera paths* (the "rest"): each pixel's ray is traced through the scene. At the object's
//!    boundary it splits deterministically into the Fresnel-reflected ray and the refracted ray; inside,
//!    the ray's segment up to the exit is stored in a segment buffer (with its throughput), and at the
//!    exit it splits again into the transmitted ray (seeing the scene behind) and, up to
//!    `camera_bounces` times, the internally reflected segment. Opaque surfaces are Lambertian and
//!    lit by the emitters directly (`light_samples` stratified points per emitter, shadow rays, the
//!    object occludes); an emitter hit directly or through specular events shows its radiance. A
//!    primary hit on an opaque surface also casts `diffuse_rays` cosine-distributed rays; those that
//!    reach the object store segments with `diffuse_samples` camera samples (Sec. 3.5.1: rays after
//!    diffuse bounces need fewer samples).
//! 2. *Single scattering* (Eq. 5): every volume sample whose oriented box a segment crosses adds
//!    `α p(d̂_v · ω) E_v (e^{−σ_t d_near} − e^{−σ_t d_far})`, `E_v` the light tube's irradiance at the box
//!    centre, `ω` the direction toward the camera. The box's cross-section is `widen²` tube
//!    cross-sections, so neighbouring boxes overlap `widen²` times on average and each contributes
//!    `1/widen²` of its irradiance: the density factor `k_v` of Eq. 4 is `widen²` here, with the tube's
//!    own spreading (exact for flat facets, [`super::points`]) accounting for focusing. Only the first
//!    `single_layer_mfp` mean free paths of a segment are searched (Sec. 4.4). Primary segments of
//!    2×2 pixel blocks share the first step of the two-step traversal (Sec. 4.3) when `two_step` is on.
//! 3. *Double and multiple scattering* at `k` camera samples per segment placed by Eq. 10 (midpoints of
//!    `k` intervals of equal attenuation mass, so the quadrature weights are equal): one tree cut over
//!    the volume samples (Algorithm 1) serves both. Double (Eq. 6):
//!    `σ_s² Λ_v e^{−σ_t r}/r² p(d̂_v·r̂) p(r̂·ω)`, `Λ_v = ∫Φ` the sample's track length; within
//!    `DISK_REACH` tube radii a sample is spread over `double_disk` equal-area points of its tube's
//!    cross-section (beyond wang2018: the tubes are wider than Wax's and Skin's mean free path, and
//!    the centre alone gave a speckled `1/r²` peak). Multiple (Eq. 7):
//!    the table's lobes of orders ≥ 3 (`total − double`) for the beam of each cut entry: a volume
//!    sample is the part of a beam between two points, so its response is exactly the beam from its
//!    start with its entering flux minus the beam from its end with its leaving flux; a node uses the
//!    flux-weighted starts and ends and the mean direction of its samples. The look-ups go to each
//!    channel's [`LobeSlice`], extracted from the table once per frame (Sec. 4.1). With
//!    `boundary_image`, each beam's negative image about the boundary plane where its light entered
//!    (moved out by [`extrapolation_distance`]) is subtracted: the table is an infinite medium.
//!    Multiple scattering is evaluated at anchor pixels every `smooth_stride` pixels and interpolated
//!    between ([`super::lowres`], Sec. 5.1's 4 × 4).
//! 4. *Bounced* (Eq. 8): the surface samples emit diffusely into the object what the scene's indirect
//!    light sends in (`(1 − F_dr,out)·E_indirect`) and what the surface reflects back from inside
//!    (`F_dr,in·E_inner`; `E_inner` is `φ/4` of the light scattered at least once, from the table's
//!    scattering-event density `σ_s φ`; `reflection_terms > 1` sums further internal reflections,
//!    [`super::surface_light`]); a tree cut over the surface samples gathers their first scattering
//!    `σ_s L_s A cos e^{−σ_t q}/q² p(q̂·ω)` and, beyond wang2018, the later orders of the same light: the
//!    table's response to beams from the node (flux `S A` from the samples minus what is left
//!    unscattered at their chords' ends, minus their images): the refracted scene light along the
//!    node's mean inward normal, the internally reflected light along `grazing_beams` beams spread in
//!    azimuth at its median angle (`cos θ = √(F_dr,in/2)` = 0.55 at η = 1.5: in a ball, light beyond the
//!    critical angle never comes nearer the centre than `R/η`). The emission is not Lambertian:
//!    refracted scene light fills the critical cone, reflected light leans to grazing angles
//!    ([`EmissionProfile`]). Same anchor pixels as multiple scattering.
//!    *Scene rays* (beyond wang2018, on by default): the first scattering of the scene's light refracted
//!    in is taken by `scene_rays` phase-sampled rays per camera sample instead of from the surface
//!    samples' diffuse emission — traced back to the boundary, out through it and to the lit surface
//!    behind (`Tracer::scene_first`). The diffuse model spreads the light that enters at a facet over
//!    the whole inner hemisphere; a forward-scattering medium shows instead what lies behind it along
//!    the view (Oil, g = 0.9: the top of the ball was half as bright as path tracing). The surface
//!    samples keep the internally reflected light's first scattering and every later order.
//!
//! **Singularities.** Eq. 6 and Eq. 8's `1/r²` use `max(r, clamp_mfp/σ_t)`; the bias is measured by
//! the tests (it vanishes as the samples get denser and the clamp smaller).
//!
//! **Determinism.** Only the diffuse rays and the scene rays draw random numbers, from counter-based
//! streams keyed by the pixel (diffuse rays) or by the segment and camera sample (scene rays);
//! segment results are summed into pixels in segment order, so frames are bit-identical for any
//! thread count.

use std::f64::consts::{FRAC_PI_4, PI};
use std::time::Instant;

use glam::DVec3;
use rayon::prelude::*;

use super::lowres::{self, Plan, SegmentShape};
use super::object_light::ObjectLight;
use super::octree::{CutEntry, Item, Octree};
use super::points::{PointOptions, Points, SurfaceSample, VolumeSample};
use super::{Material, Setup};
use crate::physics::hg::phase;
use crate::physics::rng::StreamKey;
use crate::render::ViewCamera;
use crate::render::optics::{fresnel, reflect, refract};
use crate::scene::bvh::Ray;
use crate::tables::ms_lobes::{LobeSlice, MediumChannel, MsLobesTable};

/// Quality knobs of the renderer (defaults near the paper's sweet spots where it gives them).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RenderOptions {
    /// Camera samples `k_max` per segment of a ray reaching the object directly or by specular events.
    pub k_max: usize,
    /// Camera samples per segment of a ray reaching the object after a diffuse bounce.
    pub diffuse_samples: usize,
    /// Cosine-distributed rays per primary opaque hit looking for the object's glow (0: none).
    pub diffuse_rays: u32,
    /// Stratified points per emitter for the direct light on opaque surfaces.
    pub light_samples: u32,
    /// Internal reflections followed on camera paths.
    pub camera_bounces: u32,
    /// Algorithm 1: subdivide a node whose solid angle exceeds this \[sr\] (the paper's sweet spot ≈ 0.1).
    pub epsilon1: f64,
    /// Solid angle \[sr\] above which a node is subdivided in the cuts for multiple and bounced
    /// scattering (smooth terms, so coarser than `epsilon1`).
    pub epsilon_multiple: f64,
    /// Solid angle \[sr\] above which a surface node is subdivided in the cut for the later orders of
    /// the boundary's light (its beams; smoother still than the first scattering, which uses
    /// `epsilon_multiple`). At or above 2π only the root is left.
    pub epsilon_beams: f64,
    /// Algorithm 1: below `epsilon1`, still subdivide above this solid angle where a phase value is large.
    pub epsilon2: f64,
    /// Algorithm 1: the phase value \[1/sr\] above which a node between `epsilon2` and `epsilon1` is
    /// subdivided (the paper's π/4).
    pub phase_threshold: f64,
    /// Single-scattering boxes are `widen` times the light tube's width (so `widen²` overlap on average).
    pub widen: f64,
    /// Single scattering is gathered over the first this-many mean free paths (smallest σ_t) of a segment.
    pub single_layer_mfp: f64,
    /// The `1/r²` of Eq. 6 and 8 is clamped at this many mean free paths.
    pub clamp_mfp: f64,
    /// Two-step traversal with 2×2 sharing for single scattering (Sec. 4.3).
    pub two_step: bool,
    /// Most terms of the series of internal reflections of diffuse light ([`super::surface_light`]);
    /// 1 is wang2018's single reflection; the series stops early once a term adds little.
    pub reflection_terms: usize,
    /// Half-space boundary for the table's infinite-medium responses: every beam (volume sample,
    /// surface sample) also has a negative image, mirrored about the boundary plane where its light
    /// entered or was last reflected and moved out by the extrapolation distance
    /// [`extrapolation_distance`], in multiple scattering, the later orders of the boundary's light
    /// and the inner irradiance of the surface samples. Without it light that leaves the object near
    /// where it entered is counted as if it scattered back (worst for g = 0).
    pub boundary_image: bool,
    /// Multiple and bounced scattering (smooth) are evaluated at every `smooth_stride`-th pixel and
    /// row and interpolated in between where the segments agree (wang2018 Sec. 5.1 uses 4);
    /// 1 evaluates every pixel.
    pub smooth_stride: usize,
    /// Phase-sampled rays per camera sample for the first scattering of the scene's light refracted in
    /// (the scene seen through the object and scattered once toward the camera); 0 takes it from the
    /// surface samples' emission instead (wang2018 Eq. 8).
    pub scene_rays: u32,
    /// Points over a light tube's cross-section that stand for a volume sample in double scattering
    /// (Eq. 6) within 3 tube radii of it (`DISK_REACH`; 0: its centre alone, as in wang2018).
    pub double_disk: u32,
    /// Beams, spread in azimuth, that carry the later orders of the internally reflected light each
    /// surface sample sends in, at the median polar angle of its `F(θ) cos θ` profile (grazing: in a
    /// sphere the light beyond the critical angle never comes nearer the centre than `R/η`); 0 sends
    /// it along the inward normal with the refracted scene light.
    pub grazing_beams: u32,
    /// Height above the leaves where the first step stops.
    pub stop_height: u8,
    /// Seed of the diffuse rays.
    pub seed: u64,
}

impl Default for RenderOptions {
    fn default() -> Self {
        RenderOptions {
            k_max: 16,
            diffuse_samples: 2,
            diffuse_rays: 0,
            light_samples: 4,
            camera_bounces: 1,
            epsilon1: 0.1,
            epsilon_multiple: 1.0,
            epsilon_beams: 2.0,
            epsilon2: 0.01,
            phase_threshold: FRAC_PI_4,
            widen: 2.0,
            single_layer_mfp: 8.0,
            clamp_mfp: 0.0625,
            two_step: true,
            reflection_terms: super::surface_light::SERIES_MAX,
            boundary_image: true,
            smooth_stride: 4,
            scene_rays: 16,
            grazing_beams: 4,
            double_disk: 16,
            stop_height: 3,
            seed: 0,
        }
    }
}

impl RenderOptions {
    /// Range checks; the message names the field.
    pub fn check(&self) -> Result<(), String> {
        if self.smooth_stride == 0 || self.smooth_stride > 64 {
            return Err(format!("smooth_stride = {} must lie in 1..=64", self.smooth_stride));
        }
        if self.reflection_terms == 0 {
            return Err("reflection_terms must be ≥ 1".into());
        }
        if self.k_max == 0 || self.k_max > 4096 {
            return Err(format!("k_max = {} must lie in 1..=4096", self.k_max));
        }
        if self.scene_rays > 4096 {
            return Err(format!("scene_rays = {} must lie in 0..=4096", self.scene_rays));
        }
        if self.double_disk > 1024 {
            return Err(format!("double_disk = {} must lie in 0..=1024", self.double_disk));
        }
        if self.grazing_beams > 64 {
            return Err(format!("grazing_beams = {} must lie in 0..=64", self.grazing_beams));
        }
        if self.diffuse_samples == 0 || self.diffuse_samples > 4096 {
            return Err(format!("diffuse_samples = {} must lie in 1..=4096", self.diffuse_samples));
        }
        for (name, v) in [
            ("epsilon1", self.epsilon1),
            ("epsilon2", self.epsilon2),
            ("epsilon_multiple", self.epsilon_multiple),
            ("epsilon_beams", self.epsilon_beams),
            ("widen", self.widen),
        ] {
            if !(v.is_finite() && v > 0.0) {
                return Err(format!("{name} = {v} must be finite and > 0"));
            }
        }
        if self.epsilon2 > self.epsilon1 {
            return Err(format!("epsilon2 = {} must not exceed epsilon1 = {}", self.epsilon2, self.epsilon1));
        }
        for (name, v) in [
            ("phase_threshold", self.phase_threshold),
            ("single_layer_mfp", self.single_layer_mfp),
            ("clamp_mfp", self.clamp_mfp),
        ] {
            if v.is_nan() || v < 0.0 {
                return Err(format!("{name} = {v} must be ≥ 0"));
            }
        }
        Ok(())
    }
}

/// Eq. 6 spreads a volume sample over its tube's disk within this many tube radii of its centre;
/// beyond, the disk and its centre differ by under about `1/(2·3²)` in `1/r²`.
const DISK_REACH: f64 = 3.0;
/// `π (3 − √5)`: successive points of a Vogel spiral.
const GOLDEN_ANGLE: f64 = 2.399_963_229_728_653;

/// `x` mirrored about the plane through `q` with unit normal `n`.
fn mirror_about(x: DVec3, q: DVec3, n: DVec3) -> DVec3 {
    x - 2.0 * (x - q).dot(n) * n
}

/// Aggregate of volume samples (a tree node or one sample).
#[derive(Debug, Clone, Copy, Default)]
struct VolAgg {
    /// Track length `∫Φ ds` per channel \[W·m\].
    lam: [f64; 3],
    /// Flux entering the samples' intervals, per channel \[W\].
    phi0: [f64; 3],
    /// Flux leaving them.
    phi1: [f64; 3],
    /// Track-length-weighted centre (divided through after merging).
    center: DVec3,
    /// Entering-flux-weighted start.
    start: DVec3,
    /// Leaving-flux-weighted end.
    end: DVec3,
    /// Sum of track-length-weighted directions (its length over the weight is the directions' spread).
    dir_sum: DVec3,
    /// Track-length-weighted light-tube cross-section \[m²·W·m\] (divided by `w_lam` when read).
    tube: f64,
    /// Scalar weights of the centroids.
    w_lam: f64,
    w0: f64,
    w1: f64,
    /// Bounds of the samples' interval end points (the extent the cuts judge).
    lo: DVec3,
    hi: DVec3,
    /// Image beams (`boundary_image`): entering-flux-weighted start mirrored about its sample's
    /// boundary plane, and the weighted outward normals (the shift by `2 z_b` is per channel).
    istart: DVec3,
    inormal0: DVec3,
    /// Leaving-flux-weighted mirrored end and normals.
    iend: DVec3,
    inormal1: DVec3,
    /// Track-length-weighted mirrored directions.
    idir_sum: DVec3,
}

impl VolAgg {
    fn of_sample(v: &VolumeSample, sigma_t: [f64; 3]) -> Self {
        let lam = v.track_length(sigma_t);
        let phi1: [f64; 3] = std::array::from_fn(|c| v.flux[c] * (-sigma_t[c] * v.length).exp());
        let (w_lam, w0, w1) = (lam.iter().sum::<f64>(), v.flux.iter().sum::<f64>(), phi1.iter().sum::<f64>());
        VolAgg {
            lam,
            phi0: v.flux,
            phi1,
            center: v.center() * w_lam,
            start: v.start * w0,
            end: v.end() * w1,
            dir_sum: v.direction * w_lam,
            tube: v.area * w_lam,
            w_lam,
            w0,
            w1,
            lo: v.start.min(v.end()),
            hi: v.start.max(v.end()),
            istart: mirror_about(v.start, v.plane_point, v.plane_normal) * w0,
            inormal0: v.plane_normal * w0,
            iend: mirror_about(v.end(), v.plane_point, v.plane_normal) * w1,
            inormal1: v.plane_normal * w1,
            idir_sum: mirror_about(v.direction, DVec3::ZERO, v.plane_normal) * w_lam,
        }
    }

    fn merge(parts: &[VolAgg]) -> Self {
        let mut a = VolAgg { lo: DVec3::INFINITY, hi: DVec3::NEG_INFINITY, ..VolAgg::default() };
        for p in parts {
            a.lo = a.lo.min(p.lo);
            a.hi = a.hi.max(p.hi);
            for c in 0..3 {
                a.lam[c] += p.lam[c];
                a.phi0[c] += p.phi0[c];
                a.phi1[c] += p.phi1[c];
            }
            a.center += p.center;
            a.start += p.start;
            a.end += p.end;
            a.dir_sum += p.dir_sum;
            a.tube += p.tube;
            a.istart += p.istart;
            a.inormal0 += p.inormal0;
            a.iend += p.iend;
            a.inormal1 += p.inormal1;
            a.idir_sum += p.idir_sum;
            a.w_lam += p.w_lam;
            a.w0 += p.w0;
            a.w1 += p.w1;
        }
        a
    }

    /// Half the diagonal of the end points' bounds (0 when empty).
    fn radius(&self) -> f64 {
        if self.lo.x <= self.hi.x { 0.5 * (self.hi - self.lo).length() } else { 0.0 }
    }

    /// The image beam of channel `c` (extrapolation distance `z_b`): (start, end, unit direction).
    fn image(&self, z_b: f64) -> (DVec3, DVec3, DVec3) {
        let div = |v: DVec3, w: f64| if w > 0.0 { v / w } else { v };
        let dir = self.idir_sum.try_normalize().unwrap_or(-DVec3::Z);
        let start = div(self.istart, self.w0) + 2.0 * z_b * div(self.inormal0, self.w0);
        let end = div(self.iend, self.w1) + 2.0 * z_b * div(self.inormal1, self.w1);
        (start, end, dir)
    }

    /// The weighted sums divided through: (centre, start, end, unit mean direction).
    fn points(&self) -> (DVec3, DVec3, DVec3, DVec3) {
        let div = |v: DVec3, w: f64| if w > 0.0 { v / w } else { v };
        let dir = self.dir_sum.try_normalize().unwrap_or(DVec3::Z);
        (div(self.center, self.w_lam), div(self.start, self.w0), div(self.end, self.w1), dir)
    }
}

/// Aggregate of surface samples.
#[derive(Debug, Clone, Copy, Default)]
struct SurfAgg {
    /// `Σ S_ext A/π` per channel \[W/sr\]: the scene's indirect light refracted in (its radiance
    /// inside follows the transmitted cone, [`Prepared::emission_profile`]).
    power_ext: [f64; 3],
    /// `Σ S_int A/π`: the internally reflected light (its radiance follows `F(θ)`).
    power_int: [f64; 3],
    /// Flux `Σ S A` emitted into the object along the inward normal, per channel \[W\] (all of it when
    /// [`RenderOptions::grazing_beams`] is 0, else the refracted scene light's).
    flux0: [f64; 3],
    /// The part of it left unscattered at the chord's end, `Σ S A e^{−σ_t d}`.
    flux1: [f64; 3],
    /// Flux of the internally reflected light sent along the grazing beams (0 without them).
    graze0: [f64; 3],
    /// The part of it left unscattered at the grazing chords' ends.
    graze1: [f64; 3],
    /// Power-weighted mean length of the grazing chords.
    graze_len: f64,
    /// Power-weighted position.
    pos: DVec3,
    /// Power-weighted chord end.
    end: DVec3,
    /// Sum of power-weighted inward normals.
    normal: DVec3,
    w: f64,
}

impl SurfAgg {
    fn merge(parts: &[SurfAgg]) -> Self {
        let mut a = SurfAgg::default();
        for p in parts {
            for c in 0..3 {
                a.power_ext[c] += p.power_ext[c];
                a.power_int[c] += p.power_int[c];
                a.flux0[c] += p.flux0[c];
                a.flux1[c] += p.flux1[c];
                a.graze0[c] += p.graze0[c];
                a.graze1[c] += p.graze1[c];
            }
            a.graze_len += p.graze_len;
            a.pos += p.pos;
            a.end += p.end;
            a.normal += p.normal;
            a.w += p.w;
        }
        a
    }
}

/// One surface sample as an emitter into the object (exitance `ex`, chord `d` along the inward
/// normal): its first-scattering powers split into the refracted scene light and the internal
/// reflections, the normal beam's flux and, with `graze.0` grazing beams at `cos θ = graze.1`, the
/// internally reflected flux, what is left of it at the grazing chords' ends and their mean length.
fn surface_item(setup: &Setup, s: &SurfaceSample, ex: [f64; 3], d: f64, f_out: f64, graze: (u32, f64)) -> SurfAgg {
    let sigma_t = setup.material.sigma_t;
    let s_ext: [f64; 3] = std::array::from_fn(|c| ((1.0 - f_out) * s.indirect[c]).min(ex[c]));
    let s_int: [f64; 3] = std::array::from_fn(|c| (ex[c] - s_ext[c]).max(0.0));
    let power_ext: [f64; 3] = std::array::from_fn(|c| s_ext[c] / PI * s.area);
    let power_int: [f64; 3] = std::array::from_fn(|c| s_int[c] / PI * s.area);
    let normal_share: [f64; 3] = if graze.0 > 0 { s_ext } else { ex };
    let flux0: [f64; 3] = std::array::from_fn(|c| normal_share[c] * s.area);
    let flux1: [f64; 3] = std::array::from_fn(|c| flux0[c] * (-sigma_t[c] * d).exp());
    let end = if d.is_finite() { s.position - s.normal * d } else { s.position };
    let w = ex.iter().sum::<f64>() * s.area;
    let (mut graze0, mut graze1, mut graze_len) = ([0.0; 3], [0.0; 3], 0.0);
    if graze.0 > 0 {
        // A ray that hits nothing (an open mesh) counts as a chord of length 0: nothing scatters.
        let chords: Vec<f64> = grazing_dirs(-s.normal, graze.1, graze.0)
            .map(|dir| Some(super::surface_light::chord(setup, s, dir)).filter(|q| q.is_finite()).unwrap_or(0.0))
            .collect();
        let n = chords.len() as f64;
        for c in 0..3 {
            graze0[c] = s_int[c] * s.area;
            graze1[c] = chords.iter().map(|&q| (-sigma_t[c] * q).exp()).sum::<f64>() * graze0[c] / n;
        }
        graze_len = chords.iter().sum::<f64>() / n * w;
    }
    SurfAgg {
        power_ext,
        power_int,
        flux0,
        flux1,
        graze0,
        graze1,
        graze_len,
        pos: s.position * w,
        end: end * w,
        normal: -s.normal * w,
        w,
    }
}

/// Radiance profile of the light the boundary sends into the object, relative to a Lambertian
/// emitter of the same exitance (both integrate to 1 against `cos θ dω/π` over the inner hemisphere):
/// the scene's diffuse light refracted in fills the cone inside the critical angle,
/// `(1 − F(θ)) η² / (1 − F_dr,out)`; the internally reflected light goes mostly to grazing angles,
/// `F(θ) / F_dr,in` (wang2018 Eq. 8 takes both as Lambertian). `θ` is measured from the inward normal.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EmissionProfile {
    /// Index of refraction inside relative to outside.
    pub ior: f64,
    /// `F_dr,out`: diffuse Fresnel reflectance for light arriving from outside.
    pub f_out: f64,
    /// `F_dr,in`: the same from inside.
    pub f_in: f64,
}

impl EmissionProfile {
    /// (refracted, reflected) factors at `cos θ = mu`.
    pub fn factors(&self, mu: f64) -> (f64, f64) {
        let f = fresnel(mu, self.ior, 1.0);
        let ext = if self.f_out < 1.0 { (1.0 - f) * self.ior * self.ior / (1.0 - self.f_out) } else { 0.0 };
        let int = if self.f_in > 0.0 { f / self.f_in } else { 0.0 };
        (ext, int)
    }

    /// Median `cos θ` of the internally reflected light's flux, whose density in `μ = cos θ` is
    /// `∝ F(μ) μ` (2048-point midpoint rule, linear within the cell); without reflection
    /// (`F_dr,in = 0`) the Lambertian median `1/√2`.
    pub fn grazing_median(&self) -> f64 {
        let n = 2048;
        let dens: Vec<f64> = (0..n)
            .map(|i| {
                let mu = (i as f64 + 0.5) / n as f64;
                fresnel(mu, self.ior, 1.0) * mu
            })
            .collect();
        let total: f64 = dens.iter().sum();
        if total <= 0.0 {
            return std::f64::consts::FRAC_1_SQRT_2;
        }
        let mut acc = 0.0;
        for (i, d) in dens.iter().enumerate() {
            if acc + d >= 0.5 * total {
                return (i as f64 + (0.5 * total - acc) / d) / n as f64;
            }
            acc += d;
        }
        1.0
    }
}

/// `k` unit directions at `cos θ = mu` from the unit axis `n`, evenly spread in azimuth about it
/// (azimuth 0 along the first tangent of `frame_of(n)`).
fn grazing_dirs(n: DVec3, mu: f64, k: u32) -> impl Iterator<Item = DVec3> {
    let (t1, t2) = frame_of(n);
    let sin = (1.0 - mu * mu).max(0.0).sqrt();
    (0..k).map(move |i| {
        let phi = 2.0 * PI * i as f64 / k as f64;
        n * mu + (t1 * phi.cos() + t2 * phi.sin()) * sin
    })
}

/// Light samples organised for rendering: what the paper recomputes when the light or the material
/// changes, and keeps while only the camera moves.
#[derive(Debug)]
pub struct Prepared {
    /// The light samples.
    pub points: Points,
    vol_tree: Octree,
    vol_agg: Vec<VolAgg>,
    vol_items: Vec<VolAgg>,
    surf_tree: Octree,
    surf_agg: Vec<SurfAgg>,
    surf_items: Vec<SurfAgg>,
    /// Per surface sample, the irradiance reaching it from inside the object from the volume samples
    /// \[W/m²\].
    pub inner_irradiance: Vec<[f64; 3]>,
    /// Per surface sample, the exitance it emits diffusely into the object \[W/m²\] (indirect light and
    /// every internal reflection, [`super::surface_light`]).
    pub exitance: Vec<[f64; 3]>,
    /// Angular profile of the surface samples' emission: the index of refraction and `F_dr,out`,
    /// `F_dr,in` ([`EmissionProfile`]).
    pub emission_profile: EmissionProfile,
    /// Median `cos θ` of the internally reflected light ([`EmissionProfile::grazing_median`]).
    pub grazing_mu: f64,
    /// Terms of the internal-reflection series summed.
    pub reflection_terms: usize,
    /// Wall time of [`super::points::generate`], the trees and the inner irradiance \[ms\].
    pub preprocess_ms: f64,
    /// Bytes held by the samples, trees and aggregates.
    pub memory_bytes: usize,
}

/// Hemispherical average of the Fresnel reflectance for diffuse light arriving from the side of index
/// `eta_i` (`2∫₀¹ F(μ) μ dμ`, 2048-point midpoint rule).
pub fn diffuse_fresnel(eta_i: f64, eta_t: f64) -> f64 {
    let n = 2048;
    (0..n)
        .map(|i| {
            let mu = (i as f64 + 0.5) / n as f64;
            2.0 * fresnel(mu, eta_i, eta_t) * mu / n as f64
        })
        .sum()
}

/// Per-channel media of the material for the table's look-ups.
fn channels(m: &Material) -> [MediumChannel; 3] {
    std::array::from_fn(|c| MediumChannel { albedo: m.albedo[c], sigma_t: m.sigma_t[c], g: m.g })
}

/// The table's lobes of each channel, extracted once (wang2018 Sec. 4.1).
fn slices<'t>(table: &'t MsLobesTable, ch: &[MediumChannel; 3]) -> Result<Vec<LobeSlice<'t>>, String> {
    ch.iter().map(|m| table.slice(m)).collect()
}

/// Light samples, trees and the inner irradiance of the surface samples (everything that depends on
/// the lights and the material but not on the camera).
pub fn prepare(
    setup: &Setup,
    table: &MsLobesTable,
    points_opts: &PointOptions,
    opts: &RenderOptions,
) -> Result<Prepared, String> {
    setup.material.check()?;
    opts.check()?;
    let t0 = Instant::now();
    let points = super::points::generate(setup, points_opts)?;
    let m = setup.material;
    let sigma_t = m.sigma_t;

    let items: Vec<Item> =
        points.volume.iter().map(|v| Item { position: v.center(), bounds: v.obb(opts.widen).aabb() }).collect();
    let vol_tree = Octree::build(&items, 8, 24);
    let vol_items: Vec<VolAgg> = points.volume.iter().map(|v| VolAgg::of_sample(v, sigma_t)).collect();
    let vol_agg = vol_tree
        .bottom_up(|ids| VolAgg::merge(&ids.iter().map(|&i| vol_items[i as usize]).collect::<Vec<_>>()), VolAgg::merge);

    // Inner irradiance of every surface sample: single-scattered light of the volume samples plus the
    // table's collision density of orders ≥ 2 (φ/4 of an isotropic field).
    let ch = channels(&m);
    let slices = slices(table, &ch)?;
    let eval = Evaluator::new(setup, &slices, opts, (&vol_tree, &vol_agg, &vol_items));
    let inner_irradiance: Vec<[f64; 3]> =
        points.surface.par_iter().map(|s| eval.inner_irradiance(s)).collect::<Result<Vec<_>, String>>()?;

    // Surface samples as diffuse emitters into the object, with the series of internal reflections.
    let (f_out, f_in) = (diffuse_fresnel(1.0, m.ior), diffuse_fresnel(m.ior, 1.0));
    let sitems: Vec<Item> =
        points.surface.iter().map(|s| Item { position: s.position, bounds: (s.position, s.position) }).collect();
    let surf_tree = Octree::build(&sitems, 8, 24);
    let clamp: [f64; 3] = std::array::from_fn(|c| opts.clamp_mfp / sigma_t[c]);
    let emission = super::surface_light::emission(
        setup,
        &points.surface,
        &surf_tree,
        &slices,
        &inner_irradiance,
        (f_out, f_in),
        opts.epsilon_multiple,
        clamp,
        opts.reflection_terms,
    )?;
    let profile = EmissionProfile { ior: m.ior, f_out, f_in };
    let mu_graze = profile.grazing_median();
    let n_graze = if f_in > 0.0 { opts.grazing_beams } else { 0 };
    let surf_items: Vec<SurfAgg> = points
        .surface
        .par_iter()
        .zip(&emission.exitance)
        .zip(&emission.chord)
        .map(|((s, ex), &d)| surface_item(setup, s, *ex, d, f_out, (n_graze, mu_graze)))
        .collect();
    let surf_agg = surf_tree.bottom_up(
        |ids| SurfAgg::merge(&ids.iter().map(|&i| surf_items[i as usize]).collect::<Vec<_>>()),
        SurfAgg::merge,
    );

    let memory_bytes = points.volume.len() * std::mem::size_of::<VolumeSample>()
        + points.surface.len() * std::mem::size_of::<SurfaceSample>()
        + (vol_agg.len() + vol_items.len()) * std::mem::size_of::<VolAgg>()
        + (surf_agg.len() + surf_items.len()) * std::mem::size_of::<SurfAgg>()
        + (vol_tree.nodes.len() + surf_tree.nodes.len()) * std::mem::size_of::<super::octree::Node>()
        + (vol_tree.items.len() + surf_tree.items.len()) * 4
        + inner_irradiance.len() * 24
        + emission.exitance.len() * 32
        + points.object_light.memory_bytes();
    Ok(Prepared {
        points,
        vol_tree,
        vol_agg,
        vol_items,
        surf_tree,
        surf_agg,
        surf_items,
        inner_irradiance,
        exitance: emission.exitance,
        reflection_terms: emission.terms,
        emission_profile: profile,
        grazing_mu: mu_graze,
        preprocess_ms: t0.elapsed().as_secs_f64() * 1e3,
        memory_bytes,
    })
}

/// One stretch of a camera path inside the object.
#[derive(Debug, Clone, Copy)]
struct Segment {
    pixel: u32,
    entry: DVec3,
    /// Unit outward normal of the boundary at `entry` (the plane of the image beams).
    normal: DVec3,
    /// Unit propagation direction (away from the camera).
    dir: DVec3,
    d_max: f64,
    /// Camera-path throughput at the entry (Fresnel, `1/η²` and earlier attenuation included).
    weight: [f64; 3],
    samples: u32,
    /// Reached directly through one refraction (eligible for 2×2 sharing).
    primary: bool,
}

/// Per segment: double, multiple, cut entries, failed look-ups, camera samples, and per channel the
/// sum of the camera-sample weights (`≈ ∫₀^{d_max} e^{−σ_c t} dt`, what [`super::lowres`]
/// normalises by).
type SegmentDm = ([f64; 3], [f64; 3], usize, u64, u64, [f64; 3]);
/// Per group of segments: (segment, single scattering) and nodes tested.
type GroupSingle = (Vec<(usize, [f64; 3])>, usize);

/// Wall times of the passes \[ms\] (the paper's Table 3 columns without pre-processing).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct PassTimes {
    /// Camera paths and the rest of the picture.
    pub rest_ms: f64,
    /// Single scattering.
    pub single_ms: f64,
    /// Double and multiple scattering.
    pub double_multiple_ms: f64,
    /// Bounced multiple scattering.
    pub bounced_ms: f64,
}

/// Counts of one frame.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct FrameStats {
    /// Segments inside the object.
    pub segments: usize,
    /// Camera samples `P_k`.
    pub camera_samples: u64,
    /// Mean entries of the volume-sample cuts.
    pub mean_cut: f64,
    /// Mean octree nodes tested per segment for single scattering.
    pub mean_single_nodes: f64,
    /// Table look-ups that failed (a point the table cannot answer) and were counted as 0.
    pub failed_lookups: u64,
    /// Segments whose multiple and bounced scattering were interpolated ([`super::lowres`]).
    pub interpolated: usize,
}

/// A rendered frame, per component and pixel, linear RGB radiance \[W/(m²·sr)\].
#[derive(Debug, Clone)]
pub struct Frame {
    /// Pixels per row.
    pub width: usize,
    /// Rows.
    pub height: usize,
    /// Single scattering (Eq. 5).
    pub single: Vec<[f64; 3]>,
    /// Double scattering (Eq. 6).
    pub double: Vec<[f64; 3]>,
    /// Multiple scattering (Eq. 7).
    pub multiple: Vec<[f64; 3]>,
    /// Bounced multiple scattering (Eq. 8).
    pub bounced: Vec<[f64; 3]>,
    /// Everything else: reflections, what is seen through the object, the rest of the scene.
    pub rest: Vec<[f64; 3]>,
    /// The pixel's primary ray hits the object first.
    pub object: Vec<bool>,
    /// Pass times.
    pub times: PassTimes,
    /// Counts.
    pub stats: FrameStats,
}

impl Frame {
    /// The full image (Eq. 9 plus the rest).
    pub fn total(&self) -> Vec<[f64; 3]> {
        (0..self.single.len())
            .map(|i| {
                std::array::from_fn(|c| {
                    self.single[i][c] + self.double[i][c] + self.multiple[i][c] + self.bounced[i][c] + self.rest[i][c]
                })
            })
            .collect()
    }
}

struct Evaluator<'a> {
    setup: &'a Setup<'a>,
    /// Per channel, the table's lobes.
    slices: &'a [LobeSlice<'a>],
    opts: &'a RenderOptions,
    ch: [MediumChannel; 3],
    vol_tree: &'a Octree,
    vol_agg: &'a [VolAgg],
    vol_items: &'a [VolAgg],
    /// Extrapolation distance per channel when `boundary_image` is on.
    z_b: Option<[f64; 3]>,
}

/// A channel's multiple scattering (orders ≥ 3) is left out when, in an infinite medium, it would
/// carry less than this share of its single scattering: `Σ_{k≥3} α^k / α = α²/(1 − α)` (oil's red
/// and blue channels, α = 0.0042 and 0.0995: 1.8e-5 and 1.1e-2).
pub const MULTIPLE_SHARE_FLOOR: f64 = 0.02;

/// Whether multiple scattering of a channel with albedo `albedo` is evaluated
/// ([`MULTIPLE_SHARE_FLOOR`]).
pub fn multiple_needed(albedo: f64) -> bool {
    above_floor(albedo, |a| a * a / (1.0 - a))
}

/// A channel of albedo `albedo` is kept when it scatters at all and `share(albedo)` (its share of the
/// channel's single scattering, for α < 1) reaches [`MULTIPLE_SHARE_FLOOR`]; α = 1 always is.
fn above_floor(albedo: f64, share: impl Fn(f64) -> f64) -> bool {
    albedo > 0.0 && (albedo >= 1.0 || share(albedo) >= MULTIPLE_SHARE_FLOOR)
}

/// Whether the inner irradiance of a channel with albedo `albedo` is evaluated: the boundary re-emits
/// it into the object, where it shows only after one more scattering, so it carries at most
/// `Σ_{k≥2} α^k / α = α/(1 − α)` of the channel's single scattering; below [`MULTIPLE_SHARE_FLOOR`]
/// it is left out (oil's red channel, α = 0.0042: 4.2e-3).
pub fn inner_needed(albedo: f64) -> bool {
    above_floor(albedo, |a| a / (1.0 - a))
}

/// Diffusion's extrapolation distance of an index-matched boundary, `z_b = 2D` per channel with
/// `D = 1/(3σ_t')` and the reduced extinction `σ_t' = σ_t (1 − α g)` (the partial-current boundary
/// condition with `A = 1`: the internal reflections are not folded into `A` because the surface
/// samples re-emit them explicitly, `F_dr,in E_inner`).
pub fn extrapolation_distance(m: &Material) -> [f64; 3] {
    std::array::from_fn(|c| 2.0 / (3.0 * m.sigma_t[c] * (1.0 - m.albedo[c] * m.g)))
}

/// Solid angle of a ball of radius `radius` seen from distance `dist` (capped at 2π inside it).
pub(super) fn solid_angle(radius: f64, dist: f64) -> f64 {
    if dist <= radius {
        return 2.0 * PI;
    }
    let s2 = (radius / dist).powi(2);
    // 2π(1 − √(1 − s²)) without the cancellation for small s.
    2.0 * PI * s2 / (1.0 + (1.0 - s2).max(0.0).sqrt())
}

fn half_diagonal(b: &(DVec3, DVec3)) -> f64 {
    0.5 * (b.1 - b.0).length()
}

impl<'a> Evaluator<'a> {
    fn new(
        setup: &'a Setup<'a>,
        slices: &'a [LobeSlice<'a>],
        opts: &'a RenderOptions,
        (vol_tree, vol_agg, vol_items): (&'a Octree, &'a [VolAgg], &'a [VolAgg]),
    ) -> Self {
        let m = setup.material;
        Evaluator {
            setup,
            slices,
            opts,
            ch: channels(&m),
            vol_tree,
            vol_agg,
            vol_items,
            z_b: opts.boundary_image.then(|| extrapolation_distance(&m)),
        }
    }

    fn sigma(&self, c: usize) -> f64 {
        self.ch[c].sigma_t
    }

    fn clamp_r(&self, r: f64, c: usize) -> f64 {
        r.max(self.opts.clamp_mfp / self.sigma(c))
    }

    /// Algorithm 1 for a volume-sample node seen from `p` with the camera direction `w`.
    fn refine(&self, node: u32, p: DVec3, w: DVec3) -> bool {
        let n = &self.vol_tree.nodes[node as usize];
        let (center, _, _, dir) = self.vol_agg[node as usize].points();
        let u = p - center;
        let dist = u.length();
        let radius = self.vol_agg[node as usize].radius();
        if n.is_leaf() {
            // A leaf splits into its samples only around the point itself.
            return dist < radius;
        }
        let omega = solid_angle(radius, dist);
        if omega > self.opts.epsilon1 {
            return true;
        }
        if omega > self.opts.epsilon2 {
            let uh = u / dist;
            let g = self.ch[0].g;
            return phase(uh.dot(w), g) > self.opts.phase_threshold
                || phase(dir.dot(uh), g) > self.opts.phase_threshold;
        }
        false
    }

    /// Double scattering (Eq. 6) at `p` toward `w` over the Algorithm 1 cut, per channel, radiance per
    /// unit length; also the number of cut entries.
    fn double(&self, p: DVec3, w: DVec3, cut: &mut Vec<CutEntry>) -> ([f64; 3], usize) {
        cut.clear();
        if self.vol_tree.nodes.is_empty() {
            return ([0.0; 3], 0);
        }
        self.vol_tree.cut(&[0], |n| self.refine(n, p, w), cut);
        let mut dbl = [0.0; 3];
        let g = self.ch[0].g;
        let n_disk = self.opts.double_disk as usize;
        // Eq. 6 for light of track length `weight · Λ` scattered at `p − qv` (travel direction `dir`).
        let add = |dbl: &mut [f64; 3], qv: DVec3, lam: &[f64; 3], dir: DVec3, weight: f64| {
            let rq = qv.length();
            if rq <= 0.0 {
                return;
            }
            let qh = qv / rq;
            let pp = phase(dir.dot(qh), g) * phase(qh.dot(w), g);
            for (c, dc) in dbl.iter_mut().enumerate() {
                let ss = self.ch[c].albedo * self.sigma(c);
                let rc = self.clamp_r(rq, c);
                *dc += ss * ss * lam[c] * weight * (-self.sigma(c) * rq).exp() / (rc * rc) * pp;
            }
        };
        for e in cut.iter() {
            let a = self.entry(e);
            let (center, _, _, dir) = a.points();
            let rv = p - center;
            let r = rv.length();
            if r <= 0.0 {
                continue;
            }
            let a2 = if a.w_lam > 0.0 { a.tube / a.w_lam / PI } else { 0.0 };
            if n_disk > 0 && r * r < DISK_REACH * DISK_REACH * a2 {
                // Near its tube the sample's light is spread over the tube's cross-section, not
                // concentrated at its centre: average Eq. 6 over `n_disk` equal-area points of that
                // disk (a Vogel spiral), so the sum keeps the sample's power.
                let (t1, t2) = frame_of(dir.try_normalize().unwrap_or(DVec3::Z));
                let radius = a2.sqrt();
                let share = 1.0 / n_disk as f64;
                for k in 0..n_disk {
                    let rr = radius * ((k as f64 + 0.5) * share).sqrt();
                    let ang = k as f64 * GOLDEN_ANGLE;
                    add(&mut dbl, p - (center + (t1 * ang.cos() + t2 * ang.sin()) * rr), &a.lam, dir, share);
                }
            } else {
                add(&mut dbl, rv, &a.lam, dir, 1.0);
            }
        }
        (dbl, cut.len())
    }

    /// Multiple scattering (Eq. 7, orders ≥ 3) at `p` toward `w` over the coarser solid-angle cut at
    /// `epsilon_multiple` (smooth and costly: four table look-ups per entry and channel, eight with the
    /// image beams); also the number of cut entries and failed look-ups.
    fn multiple(&self, p: DVec3, w: DVec3, cut: &mut Vec<CutEntry>) -> ([f64; 3], usize, u64) {
        let (mut mul, mut failed) = ([0.0; 3], 0u64);
        if self.vol_tree.nodes.is_empty() {
            return (mul, 0, 0);
        }
        let needed = self.ch.map(|ch| multiple_needed(ch.albedo));
        cut.clear();
        self.coarse_cut(p, cut);
        for e in cut.iter() {
            let a = self.entry(e);
            let (_, start, end, dir) = a.points();
            for (c, mc) in mul.iter_mut().enumerate() {
                if !needed[c] || a.phi0[c] <= 0.0 {
                    continue;
                }
                let look = |origin: DVec3, dir: DVec3| {
                    self.slices[c].multiple_radiance((origin.to_array(), dir.to_array()), p.to_array(), w.to_array())
                };
                let (v0, v1) = match (look(start, dir), look(end, dir)) {
                    (Ok(v0), Ok(v1)) => (v0, v1),
                    _ => {
                        failed += 1;
                        continue;
                    }
                };
                let real = (a.phi0[c] * v0 - a.phi1[c] * v1).max(0.0);
                let image = match self.z_b {
                    Some(z) => {
                        let (is, ie, id) = a.image(z[c]);
                        match (look(is, id), look(ie, id)) {
                            (Ok(u0), Ok(u1)) => (a.phi0[c] * u0 - a.phi1[c] * u1).max(0.0),
                            _ => {
                                failed += 1;
                                0.0
                            }
                        }
                    }
                    None => 0.0,
                };
                *mc += (real - image).max(0.0);
            }
        }
        (mul, cut.len(), failed)
    }

    fn entry(&self, e: &CutEntry) -> &VolAgg {
        match *e {
            CutEntry::Node(n) => &self.vol_agg[n as usize],
            CutEntry::Item(i) => &self.vol_items[i as usize],
        }
    }

    /// The solid-angle-only cut at `epsilon_multiple` seen from `p`.
    fn coarse_cut(&self, p: DVec3, cut: &mut Vec<CutEntry>) {
        self.vol_tree.cut(
            &[0],
            |n| {
                let node = &self.vol_tree.nodes[n as usize];
                let (center, ..) = self.vol_agg[n as usize].points();
                let (radius, dist) = (self.vol_agg[n as usize].radius(), (p - center).length());
                if node.is_leaf() { dist < radius } else { solid_angle(radius, dist) > self.opts.epsilon_multiple }
            },
            cut,
        );
    }

    /// Irradiance reaching a surface sample from inside from the volume samples: the irradiance `φ/4`
    /// of an isotropic field whose fluence `φ` is that of the light scattered at least once (the table's
    /// scattering-event density of orders ≥ 2 is `σ_s φ`).
    fn inner_irradiance(&self, s: &SurfaceSample) -> Result<[f64; 3], String> {
        let mut out = [0.0; 3];
        if self.vol_tree.nodes.is_empty() {
            return Ok(out);
        }
        let p = s.position;
        let mut cut = Vec::new();
        self.coarse_cut(p, &mut cut);
        for e in &cut {
            let a = self.entry(e);
            let (_, start, end, dir) = a.points();
            for (c, o) in out.iter_mut().enumerate() {
                if !inner_needed(self.ch[c].albedo) {
                    continue;
                }
                let st = self.sigma(c);
                let ss = self.ch[c].albedo * st;
                let fluence = |origin: DVec3, dir: DVec3| -> Result<f64, String> {
                    let v = p - origin;
                    let z = v.dot(dir);
                    let rho = (v - z * dir).length();
                    // Scattering-event density per unit volume per watt: σ_t³ D(σ_t x) = σ_s φ.
                    Ok(self.slices[c].density(st * rho, st * z)? * st * st * st / ss)
                };
                let m = (a.phi0[c] * fluence(start, dir)? - a.phi1[c] * fluence(end, dir)?).max(0.0);
                let image = match self.z_b {
                    Some(z) => {
                        let (is, ie, id) = a.image(z[c]);
                        (a.phi0[c] * fluence(is, id)? - a.phi1[c] * fluence(ie, id)?).max(0.0)
                    }
                    None => 0.0,
                };
                *o += 0.25 * (m - image).max(0.0);
            }
        }
        Ok(out)
    }
}

/// Renders a frame (the passes of the module doc).
pub fn render(
    setup: &Setup,
    table: &MsLobesTable,
    prepared: &Prepared,
    camera: &ViewCamera,
    opts: &RenderOptions,
    progress: &(dyn Fn(u64) + Sync),
) -> Result<Frame, String> {
    opts.check()?;
    setup.material.check()?;
    let (w, h) = (camera.width, camera.height);
    let n = w * h;
    let m = setup.material;
    let ch = channels(&m);
    let slices = slices(table, &ch)?;
    let eval = Evaluator::new(setup, &slices, opts, (&prepared.vol_tree, &prepared.vol_agg, &prepared.vol_items));

    // Pass 1: camera paths.
    let t = Instant::now();
    let tracer = Tracer { setup, opts, light: &prepared.points.object_light };
    let per_pixel: Vec<(Vec<Segment>, [f64; 3], bool)> = (0..n)
        .into_par_iter()
        .map(|i| {
            let (x, y) = (i % w, i / w);
            let mut segs = Vec::new();
            let mut rest = [0.0; 3];
            let dir = camera.pixel_dir(x, y);
            let object = tracer.primary(i as u32, camera.position, dir, &mut segs, &mut rest);
            if x == w - 1 {
                progress(1);
            }
            (segs, rest, object)
        })
        .collect();
    let mut segments = Vec::new();
    let mut rest = vec![[0.0; 3]; n];
    let mut object = vec![false; n];
    for (i, (s, r, o)) in per_pixel.into_iter().enumerate() {
        segments.extend(s);
        rest[i] = r;
        object[i] = o;
    }
    let rest_ms = t.elapsed().as_secs_f64() * 1e3;

    // Pass 2: single scattering.
    let t = Instant::now();
    let (single_per_seg, single_nodes) = single_pass(&eval, prepared, &segments, w);
    let single_ms = t.elapsed().as_secs_f64() * 1e3;

    // Pass 3: double scattering at every segment, multiple scattering at the directly planned ones
    // (the rest is interpolated below, [`super::lowres`]).
    let t = Instant::now();
    let shapes: Vec<SegmentShape> = segments
        .iter()
        .map(|s| SegmentShape {
            pixel: s.pixel,
            primary: s.primary,
            samples: s.samples,
            d_max: s.d_max,
            dir: s.dir,
            normal: s.normal,
        })
        .collect();
    let plan = lowres::plan(w, h, opts.smooth_stride, &shapes);
    let dm: Vec<SegmentDm> = segments
        .par_iter()
        .zip(&plan)
        .map_init(Vec::new, |cut, (s, plan)| {
            let (mut dbl, mut mul, mut entries, mut failed, mut norm) = ([0.0; 3], [0.0; 3], 0usize, 0u64, [0.0; 3]);
            let wc = -s.dir;
            for (d, wts) in camera_samples(s, &m) {
                let p = s.entry + d * s.dir;
                let (a, e) = eval.double(p, wc, cut);
                entries += e;
                let b = if *plan == Plan::Direct {
                    let (b, e, f) = eval.multiple(p, wc, cut);
                    entries += e;
                    failed += f;
                    b
                } else {
                    [0.0; 3]
                };
                for (c, w) in wts.iter().enumerate() {
                    dbl[c] += w * a[c];
                    mul[c] += w * b[c];
                    norm[c] += w;
                }
            }
            (dbl, mul, entries, failed, s.samples as u64, norm)
        })
        .collect();
    let mut mul_per_seg: Vec<[f64; 3]> = dm.iter().map(|x| x.1).collect();
    let norms: Vec<[f64; 3]> = dm.iter().map(|x| x.5).collect();
    interpolate(&plan, &norms, &mut mul_per_seg);
    let double_multiple_ms = t.elapsed().as_secs_f64() * 1e3;

    // Pass 4: bounced, at the directly planned segments, then interpolated.
    let t = Instant::now();
    let mut bounced_per_seg: Vec<[f64; 3]> = segments
        .par_iter()
        .zip(&plan)
        .enumerate()
        .map_init(Vec::new, |cut, (k, (s, plan))| {
            let mut out = [0.0; 3];
            if *plan != Plan::Direct {
                return out;
            }
            let key = StreamKey { table: opts.seed ^ 0x5ce7_e0a7_b0c1_a5e5, cell: k as u64 };
            for (j, (d, wts)) in camera_samples(s, &m).into_iter().enumerate() {
                let p = s.entry + d * s.dir;
                let b = bounced_at(&eval, prepared, p, -s.dir, cut);
                let f = tracer.scene_first(p, -s.dir, key, j as u64);
                for c in 0..3 {
                    out[c] += wts[c] * (b[c] + f[c]);
                }
            }
            out
        })
        .collect();
    interpolate(&plan, &norms, &mut bounced_per_seg);
    let bounced_ms = t.elapsed().as_secs_f64() * 1e3;
    let interpolated = plan.iter().filter(|p| **p != Plan::Direct).count();

    let mut frame = Frame {
        width: w,
        height: h,
        single: vec![[0.0; 3]; n],
        double: vec![[0.0; 3]; n],
        multiple: vec![[0.0; 3]; n],
        bounced: vec![[0.0; 3]; n],
        rest,
        object,
        times: PassTimes { rest_ms, single_ms, double_multiple_ms, bounced_ms },
        stats: FrameStats { segments: segments.len(), interpolated, ..Default::default() },
    };
    let mut entries = 0usize;
    for (k, s) in segments.iter().enumerate() {
        let px = s.pixel as usize;
        let (dbl, _, e, f, cs, _) = dm[k];
        let mul = mul_per_seg[k];
        entries += e;
        frame.stats.failed_lookups += f;
        frame.stats.camera_samples += cs;
        for c in 0..3 {
            let wgt = s.weight[c];
            frame.single[px][c] += wgt * single_per_seg[k][c];
            frame.double[px][c] += wgt * dbl[c];
            frame.multiple[px][c] += wgt * mul[c];
            frame.bounced[px][c] += wgt * bounced_per_seg[k][c];
        }
    }
    frame.stats.mean_cut = entries as f64 / (frame.stats.camera_samples.max(1) as f64);
    frame.stats.mean_single_nodes = single_nodes as f64 / segments.len().max(1) as f64;
    for v in [&mut frame.single, &mut frame.double, &mut frame.multiple, &mut frame.bounced, &mut frame.rest] {
        for px in v.iter_mut() {
            for x in px.iter_mut() {
                if !x.is_finite() {
                    *x = 0.0;
                }
            }
        }
    }
    Ok(frame)
}

/// Camera-sample depths of a segment (Eq. 10 at interval midpoints of equal attenuation mass for the
/// smallest σ_t) and their per-channel quadrature weights, which include the attenuation from the entry:
/// `Σ_k w_k f(d_k) ≈ ∫₀^{d_max} e^{−σ_c s} f(s) ds`.
fn camera_samples(s: &Segment, m: &Material) -> Vec<(f64, [f64; 3])> {
    let k = s.samples.max(1) as usize;
    let sr = m.sigma_t.iter().copied().fold(f64::INFINITY, f64::min);
    let mass = -(-sr * s.d_max).exp_m1(); // 1 − e^{−σ d_max}
    if mass.is_nan() || mass <= 0.0 {
        return Vec::new();
    }
    (0..k)
        .map(|i| {
            let u = (i as f64 + 0.5) / k as f64 * mass;
            let d = -(-u).ln_1p() / sr;
            // Interval width around d for this mass: (mass/k) / (σ_r e^{−σ_r d}).
            let base = mass / k as f64 / sr;
            let wts = std::array::from_fn(|c| base * (-(m.sigma_t[c] - sr) * d).exp());
            (d, wts)
        })
        .collect()
}

/// Fills the interpolated segments of `values` from the direct ones: the weight-normalised means of
/// the taps, times the segment's own weight sum ([`super::lowres`]).
fn interpolate(plan: &[Plan], norms: &[[f64; 3]], values: &mut [[f64; 3]]) {
    for (i, p) in plan.iter().enumerate() {
        let Plan::Interp(taps) = p else { continue };
        let mut v = [0.0; 3];
        for &(j, wt) in taps {
            if wt <= 0.0 {
                continue;
            }
            let (j, wt) = (j as usize, wt);
            for c in 0..3 {
                if norms[j][c] > 0.0 {
                    v[c] += wt * values[j][c] / norms[j][c];
                }
            }
        }
        values[i] = std::array::from_fn(|c| v[c] * norms[i][c]);
    }
}

/// Bounced scattering (Eq. 8) at `p` toward `w`: a tree cut over the surface samples.
fn bounced_at(eval: &Evaluator, prep: &Prepared, p: DVec3, w: DVec3, cut: &mut Vec<CutEntry>) -> [f64; 3] {
    let mut out = [0.0; 3];
    let tree = &prep.surf_tree;
    if tree.nodes.is_empty() {
        return out;
    }
    let g = eval.ch[0].g;
    let cut_at = |eps: f64, cut: &mut Vec<CutEntry>| {
        cut.clear();
        tree.cut(
            &[0],
            |n| {
                let a = &prep.surf_agg[n as usize];
                let pos = if a.w > 0.0 {
                    a.pos / a.w
                } else {
                    0.5 * (tree.nodes[n as usize].bounds.0 + tree.nodes[n as usize].bounds.1)
                };
                let node = &tree.nodes[n as usize];
                let (radius, dist) = (half_diagonal(&node.bounds), (p - pos).length());
                if node.is_leaf() { dist < radius } else { solid_angle(radius, dist) > eps }
            },
            cut,
        );
    };
    // A cut entry with power: its aggregate, power-weighted position and mean inward normal (shorter
    // than 1 where the normals spread).
    let entry = |e: &CutEntry| {
        let a = match *e {
            CutEntry::Node(n) => &prep.surf_agg[n as usize],
            CutEntry::Item(i) => &prep.surf_items[i as usize],
        };
        (a.w > 0.0).then(|| (a, a.pos / a.w, a.normal / a.w))
    };
    cut_at(eval.opts.epsilon_multiple, cut);
    for (a, pos, nrm) in cut.iter().filter_map(entry) {
        let q = p - pos;
        let r = q.length();
        if r <= 0.0 {
            continue;
        }
        let qh = q / r;
        let cos = nrm.dot(qh).max(0.0);
        if cos > 0.0 {
            let (k_ext, k_int) = prep.emission_profile.factors(cos / nrm.length());
            let ph = phase(qh.dot(w), g);
            for (c, o) in out.iter_mut().enumerate() {
                let rc = eval.clamp_r(r, c);
                // With scene rays the refracted scene light's first scattering is theirs.
                let ext = if eval.opts.scene_rays == 0 { a.power_ext[c] } else { 0.0 };
                let power = ext * k_ext + a.power_int[c] * k_int;
                *o += eval.ch[c].albedo * eval.sigma(c) * power * cos * ph * (-eval.sigma(c) * r).exp() / (rc * rc);
            }
        }
    }
    if eval.opts.epsilon_beams != eval.opts.epsilon_multiple {
        cut_at(eval.opts.epsilon_beams, cut);
    }
    let n_graze = eval.opts.grazing_beams as usize;
    let mut graze_dirs = [DVec3::ZERO; 64]; // grazing_beams ≤ 64 (RenderOptions::check)
    for (a, pos, nrm) in cut.iter().filter_map(entry) {
        // Orders ≥ 2 of the emitted light: the table's response to beams from the samples' positions
        // with their flux minus from the chords' ends with what is left there. The refracted scene
        // light goes along the mean inward normal; the internally reflected light along
        // `grazing_beams` beams at its median angle (or with the rest when there are none).
        let Some(dir) = nrm.try_normalize() else { continue };
        let end = a.end / a.w;
        let graze = &mut graze_dirs[..n_graze];
        for (slot, d) in graze.iter_mut().zip(grazing_dirs(dir, prep.grazing_mu, n_graze as u32)) {
            *slot = d;
        }
        let graze = &*graze;
        for (c, o) in out.iter_mut().enumerate() {
            // Left out where all orders ≥ 2 are under 2 % of the first (as for the inner irradiance).
            if !inner_needed(eval.ch[c].albedo) || a.flux0[c] + a.graze0[c] <= 0.0 {
                continue;
            }
            let look = |origin: DVec3, d: DVec3| {
                eval.slices[c].total_radiance((origin.to_array(), d.to_array()), p.to_array(), w.to_array())
            };
            // Beam from `pos` along `d` with flux `f0`, ending at `end` with `f1`, minus its image about
            // the sample's own plane (through `pos`, normal `dir`), moved out by `2 z_b`.
            let beam = |end: DVec3, d: DVec3, f0: f64, f1: f64| {
                let one = |pos: DVec3, end: DVec3, d: DVec3| {
                    let v0 = look(pos, d).unwrap_or(0.0);
                    // What is left at the end is skipped once it is a millionth of the start (thick
                    // media): its response is at most that share of the beam's own near field.
                    let v1 = if f1 > 1e-6 * f0 { look(end, d).unwrap_or(0.0) } else { 0.0 };
                    (f0 * v0 - f1 * v1).max(0.0)
                };
                let real = one(pos, end, d);
                let image = eval.z_b.map_or(0.0, |z| {
                    let out = -dir * (2.0 * z[c]);
                    one(pos + out, mirror_about(end, pos, dir) + out, d - 2.0 * d.dot(dir) * dir)
                });
                (real - image).max(0.0)
            };
            if a.flux0[c] > 0.0 {
                *o += beam(end, dir, a.flux0[c], a.flux1[c]);
            }
            if n_graze > 0 && a.graze0[c] > 0.0 {
                let len = a.graze_len / a.w;
                let (f0, f1) = (a.graze0[c] / n_graze as f64, a.graze1[c] / n_graze as f64);
                for &d in graze {
                    *o += beam(pos + d * len, d, f0, f1);
                }
            }
        }
    }
    out
}

/// Single scattering per segment (Eq. 5), with the two-step traversal for primary 2×2 blocks; also the
/// total number of nodes tested.
fn single_pass(eval: &Evaluator, prep: &Prepared, segments: &[Segment], width: usize) -> (Vec<[f64; 3]>, usize) {
    let tree = &prep.vol_tree;
    let m = eval.setup.material;
    let sr = m.sigma_t.iter().copied().fold(f64::INFINITY, f64::min);
    let layer = eval.opts.single_layer_mfp / sr;
    // Group segments: primary segments by 2×2 pixel block (when two_step), every other one alone.
    let mut groups: Vec<Vec<usize>> = Vec::new();
    if eval.opts.two_step {
        let mut by_block: std::collections::BTreeMap<(usize, usize), Vec<usize>> = std::collections::BTreeMap::new();
        for (k, s) in segments.iter().enumerate() {
            if s.primary {
                let px = s.pixel as usize;
                by_block.entry(((px % width) / 2, (px / width) / 2)).or_default().push(k);
            } else {
                groups.push(vec![k]);
            }
        }
        groups.extend(by_block.into_values());
    } else {
        groups.extend((0..segments.len()).map(|k| vec![k]));
    }
    let results: Vec<GroupSingle> = groups
        .par_iter()
        .map(|grp| {
            let rays: Vec<(DVec3, DVec3, f64)> =
                grp.iter().map(|&k| (segments[k].entry, segments[k].dir, segments[k].d_max.min(layer))).collect();
            let mut roots = vec![0u32];
            let mut tested = 0;
            if tree.nodes.is_empty() {
                return (grp.iter().map(|&k| (k, [0.0; 3])).collect(), 0);
            }
            if eval.opts.two_step && grp.len() > 1 {
                roots.clear();
                tested += tree.ray_frontier(&rays, eval.opts.stop_height, &mut roots);
            }
            let out = grp
                .iter()
                .zip(&rays)
                .map(|(&k, &(o, d, tmax))| {
                    let mut acc = [0.0; 3];
                    let wcam = -d;
                    tested += tree.ray_items(&roots, o, d, tmax, |it| {
                        let v = &prep.points.volume[it as usize];
                        let obb = v.obb(eval.opts.widen);
                        let Some((a, b)) = obb.hit(o, d) else { return };
                        let (a, b) = (a.max(0.0), b.min(tmax));
                        if b <= a {
                            return;
                        }
                        let area = v.area * eval.opts.widen * eval.opts.widen;
                        if area.is_nan() || area <= 0.0 {
                            return;
                        }
                        let ph = phase(v.direction.dot(wcam), m.g);
                        for (c, x) in acc.iter_mut().enumerate() {
                            let st = m.sigma_t[c];
                            let e = v.flux[c] * (-0.5 * st * v.length).exp() / area;
                            // e^{−σa} − e^{−σb} = e^{−σa}(1 − e^{−σ(b−a)}), stable for thin boxes.
                            let dt = (-st * a).exp() * -(-st * (b - a)).exp_m1();
                            *x += m.albedo[c] * ph * e * dt;
                        }
                    });
                    (k, acc)
                })
                .collect();
            (out, tested)
        })
        .collect();
    let mut per_seg = vec![[0.0; 3]; segments.len()];
    let mut tested = 0;
    for (list, t) in results {
        tested += t;
        for (k, v) in list {
            per_seg[k] = v;
        }
    }
    (per_seg, tested)
}

/// Camera-path tracing of pass 1.
struct Tracer<'a> {
    setup: &'a Setup<'a>,
    opts: &'a RenderOptions,
    /// The object's caustic and glow on opaque surfaces.
    light: &'a ObjectLight,
}

/// Offset of secondary rays from surfaces \[m\].
const EPS: f64 = 1e-6;
/// Throughput below which a camera path is dropped.
const MIN_WEIGHT: f64 = 1e-6;

impl Tracer<'_> {
    /// Traces a pixel's primary ray; returns whether it hits the object first.
    fn primary(&self, pixel: u32, o: DVec3, d: DVec3, segs: &mut Vec<Segment>, rest: &mut [f64; 3]) -> bool {
        let hit = self.setup.bvh.closest_hit(&Ray::new(o.to_array(), d.to_array()));
        let object = hit.is_some_and(|h| h.mesh == self.setup.object)
            && !self.emitter_before(o, d, hit.map(|h| h.t).unwrap_or(f64::INFINITY));
        self.trace(pixel, o, d, [1.0; 3], 0, true, segs, rest);
        object
    }

    fn emitter_before(&self, o: DVec3, d: DVec3, t_max: f64) -> bool {
        self.setup.emitters.iter().any(|e| e.intersect(o, d, 0.0).is_some_and(|t| t < t_max))
    }

    /// Radiance of emitters hit by the ray before `t_max` (the closest one).
    fn emitter_radiance(&self, o: DVec3, d: DVec3, t_max: f64) -> Option<[f64; 3]> {
        let mut best: Option<(f64, [f64; 3])> = None;
        for e in self.setup.emitters {
            if let Some(t) = e.intersect(o, d, 0.0)
                && t < t_max
                && best.is_none_or(|b| t < b.0)
            {
                best = Some((t, e.radiance));
            }
        }
        best.map(|b| b.1)
    }

    #[allow(clippy::too_many_arguments)]
    fn trace(
        &self,
        pixel: u32,
        o: DVec3,
        d: DVec3,
        thr: [f64; 3],
        depth: u32,
        primary: bool,
        segs: &mut Vec<Segment>,
        rest: &mut [f64; 3],
    ) {
        if thr.iter().all(|&t| t < MIN_WEIGHT) || depth > 8 {
            return;
        }
        let hit = self.setup.bvh.closest_hit(&Ray {
            origin: o.to_array(),
            direction: d.to_array(),
            t_min: 0.0,
            t_max: f64::INFINITY,
        });
        let t_hit = hit.map(|h| h.t).unwrap_or(f64::INFINITY);
        if let Some(l) = self.emitter_radiance(o, d, t_hit) {
            for c in 0..3 {
                rest[c] += thr[c] * l[c];
            }
            return;
        }
        let Some(h) = hit else { return };
        let p = o + h.t * d;
        let n = DVec3::from_array(h.geometric_normal);
        if h.mesh == self.setup.object {
            let eta = self.setup.material.ior;
            if !h.front_face {
                // A camera path meeting the object from inside (camera inside): treat as an exit.
                return;
            }
            let cos_i = d.dot(n).abs();
            let f = fresnel(cos_i, 1.0, eta);
            if f > 0.0 {
                let r = reflect(d, n);
                self.trace(pixel, p + n * EPS, r, thr.map(|t| t * f), depth + 1, false, segs, rest);
            }
            if let Some(tdir) = refract(d, n, 1.0, eta) {
                let w = thr.map(|t| t * (1.0 - f) / (eta * eta));
                self.inside(
                    pixel,
                    p - n * EPS,
                    n,
                    tdir,
                    w,
                    self.opts.camera_bounces,
                    depth,
                    primary,
                    self.opts.k_max,
                    segs,
                    rest,
                );
            }
            return;
        }
        // Opaque Lambertian surface: direct light from the emitters.
        let nf = if n.dot(d) > 0.0 { -n } else { n };
        let rho = self.setup.albedo_of(h.mesh);
        let direct = self.direct(p + nf * EPS, nf, pixel);
        // The object's light on the surface; its glow is gathered by the diffuse rays instead when
        // they are on.
        let object = self.light.irradiance(p, nf, !(primary && self.opts.diffuse_rays > 0));
        for c in 0..3 {
            rest[c] += thr[c] * rho[c] / PI * (direct[c] + object[c]);
        }
        if primary && self.opts.diffuse_rays > 0 && rho.iter().any(|&r| r > 0.0) {
            let key = StreamKey { table: self.opts.seed ^ 0x7a3c_0de5_1bad_5eed, cell: pixel as u64 };
            let nrays = self.opts.diffuse_rays;
            let (t1, t2) = frame_of(nf);
            for s in 0..nrays {
                let (u1, u2) = (key.uniform(s as u64, 0), key.uniform(s as u64, 1));
                let r = u1.sqrt();
                let phi = 2.0 * PI * u2;
                let dir = (t1 * (r * phi.cos()) + t2 * (r * phi.sin()) + nf * (1.0 - u1).max(0.0).sqrt()).normalize();
                let q = p + nf * EPS;
                let Some(h2) = self.setup.bvh.closest_hit(&Ray::new(q.to_array(), dir.to_array())) else { continue };
                if h2.mesh != self.setup.object || !h2.front_face {
                    continue;
                }
                let n2 = DVec3::from_array(h2.geometric_normal);
                let eta = self.setup.material.ior;
                let f = fresnel(dir.dot(n2).abs(), 1.0, eta);
                let Some(tdir) = refract(dir, n2, 1.0, eta) else { continue };
                // Cosine-weighted estimator: L = ρ/π ∫ L_i cos dω ≈ (ρ/N) Σ L_i.
                let w: [f64; 3] = std::array::from_fn(|c| thr[c] * rho[c] / nrays as f64 * (1.0 - f) / (eta * eta));
                let entry = q + h2.t * dir - n2 * EPS;
                let mut ignored = [0.0; 3];
                self.inside(
                    pixel,
                    entry,
                    n2,
                    tdir,
                    w,
                    0,
                    depth + 1,
                    false,
                    self.opts.diffuse_samples,
                    segs,
                    &mut ignored,
                );
            }
        }
    }

    /// A camera path inside the object from `entry` along `d` (unit): stores the segment, then follows
    /// the transmitted ray out and, with bounces left, the internally reflected one.
    #[allow(clippy::too_many_arguments)]
    fn inside(
        &self,
        pixel: u32,
        entry: DVec3,
        n_out: DVec3,
        d: DVec3,
        w: [f64; 3],
        bounces: u32,
        depth: u32,
        primary: bool,
        samples: usize,
        segs: &mut Vec<Segment>,
        rest: &mut [f64; 3],
    ) {
        if w.iter().all(|&t| t < MIN_WEIGHT) {
            return;
        }
        let Some(h) = self.setup.bvh.closest_hit(&Ray::new(entry.to_array(), d.to_array())) else { return };
        let d_max = h.t;
        if !(d_max > 0.0 && d_max.is_finite()) {
            return;
        }
        segs.push(Segment { pixel, entry, normal: n_out, dir: d, d_max, weight: w, samples: samples as u32, primary });
        if h.mesh != self.setup.object {
            return;
        }
        let m = self.setup.material;
        let att: [f64; 3] = std::array::from_fn(|c| w[c] * (-m.sigma_t[c] * d_max).exp());
        let exit = entry + d * d_max;
        let n = DVec3::from_array(h.geometric_normal);
        let f = fresnel(d.dot(n).abs(), m.ior, 1.0);
        if let Some(out) = refract(d, n, m.ior, 1.0) {
            let nout = if n.dot(out) > 0.0 { n } else { -n };
            let wt = att.map(|a| a * (1.0 - f) * m.ior * m.ior);
            self.trace(pixel, exit + nout * EPS, out, wt, depth + 1, false, segs, rest);
        }
        if bounces > 0 && f > 0.0 {
            let r = reflect(d, n);
            let nin = if n.dot(r) > 0.0 { n } else { -n };
            self.inside(
                pixel,
                exit + nin * EPS,
                -nin,
                r,
                att.map(|a| a * f),
                bounces - 1,
                depth + 1,
                false,
                samples,
                segs,
                rest,
            );
        }
    }

    /// First scattering toward `w` at `p` inside the object of the scene's light refracted in, per unit
    /// length, `σ_s ∫ p(ω·w) L_in(ω) dω`: `scene_rays` travel directions `ω` drawn from the phase
    /// function about `w` (stratified in its CDF, a rank-1 lattice in azimuth; weight 1), each traced
    /// back to the boundary, out through it (`(1 − F) η²`, none under total internal reflection) and to
    /// the first opaque surface, whose radiance is its direct light and the object's caustic and glow.
    /// Emitters seen this way are left out (the volume samples carry the lamp's light), as are rays that
    /// meet the object again. `key` and `sample` (the camera sample) pick the random stream.
    fn scene_first(&self, p: DVec3, w: DVec3, key: StreamKey, sample: u64) -> [f64; 3] {
        let n = self.opts.scene_rays;
        let m = self.setup.material;
        let mut sum = [0.0; 3];
        if n == 0 || m.albedo.iter().all(|&a| a <= 0.0) {
            return sum;
        }
        let bvh = self.setup.bvh;
        let (j1, j2) = (key.uniform(sample, 0), key.uniform(sample, 1));
        let golden = 0.5 * (5f64.sqrt() - 1.0);
        let (t1, t2) = frame_of(w);
        for j in 0..n {
            let u1 = (f64::from(j) + j1) / f64::from(n);
            let phi = 2.0 * PI * (f64::from(j) * golden + j2).fract();
            let mu = crate::physics::hg::sample_mu(u1, m.g);
            let s = (1.0 - mu * mu).max(0.0).sqrt();
            // The light travels along `travel`; it comes from `−travel`.
            let travel = (w * mu + t1 * (s * phi.cos()) + t2 * (s * phi.sin())).normalize();
            let back = -travel;
            let Some(h) = bvh.closest_hit(&Ray::new(p.to_array(), back.to_array())) else { continue };
            if h.mesh != self.setup.object || h.front_face {
                continue;
            }
            let nrm = DVec3::from_array(h.geometric_normal);
            let Some(out) = refract(back, nrm, m.ior, 1.0) else { continue };
            let f = fresnel(back.dot(nrm).abs(), m.ior, 1.0);
            let exit = p + back * h.t;
            let nout = if nrm.dot(out) > 0.0 { nrm } else { -nrm };
            let o = exit + nout * EPS;
            let Some(h2) = bvh.closest_hit(&Ray::new(o.to_array(), out.to_array())) else { continue };
            if h2.mesh == self.setup.object || self.emitter_before(o, out, h2.t) {
                continue;
            }
            let q = o + out * h2.t;
            let mut nq = DVec3::from_array(h2.geometric_normal);
            if nq.dot(out) > 0.0 {
                nq = -nq;
            }
            let rho = self.setup.albedo_of(h2.mesh);
            if rho.iter().all(|&r| r <= 0.0) {
                continue;
            }
            let e = self.direct(q + nq * EPS, nq, u32::MAX);
            let obj = self.light.irradiance(q, nq, true);
            for c in 0..3 {
                let l_out = rho[c] / PI * (e[c] + obj[c]);
                sum[c] += l_out * (1.0 - f) * m.ior * m.ior * (-m.sigma_t[c] * h.t).exp();
            }
        }
        std::array::from_fn(|c| m.albedo[c] * m.sigma_t[c] * sum[c] / f64::from(n))
    }

    /// Irradiance from the emitters at a point with unit normal `n` (stratified points on each
    /// emitter's disk facing the point, shadow rays).
    fn direct(&self, p: DVec3, n: DVec3, pixel: u32) -> [f64; 3] {
        let mut e = [0.0; 3];
        let ns = self.opts.light_samples.max(1);
        let side = (ns as f64).sqrt().ceil() as u32;
        let key = StreamKey { table: self.opts.seed ^ 0x51_9a7e_11e5, cell: pixel as u64 };
        for (li, em) in self.setup.emitters.iter().enumerate() {
            let to_c = em.center - p;
            let dist_c = to_c.length();
            if dist_c <= em.radius {
                continue;
            }
            let axis = to_c / dist_c;
            let (t1, t2) = frame_of(axis);
            let inten = em.intensity();
            for s in 0..ns {
                let (i, j) = (s % side, s / side);
                let su = (i as f64 + key.uniform(s as u64 + 1024 * li as u64, 0)) / side as f64;
                let sv = (j as f64 + key.uniform(s as u64 + 1024 * li as u64, 1)) / side as f64;
                let (r, phi) = (em.radius * su.sqrt(), 2.0 * PI * sv);
                let y = em.center + t1 * (r * phi.cos()) + t2 * (r * phi.sin());
                let l = y - p;
                let dist = l.length();
                let lh = l / dist;
                let cos = n.dot(lh);
                if cos <= 0.0 || self.setup.bvh.occluded(p.to_array(), lh.to_array(), dist - EPS) {
                    continue;
                }
                for c in 0..3 {
                    e[c] += inten[c] * cos / (dist * dist) / ns as f64;
                }
            }
        }
        e
    }
}

/// Two unit vectors completing `n` to an orthonormal frame.
fn frame_of(n: DVec3) -> (DVec3, DVec3) {
    let a = if n.x.abs() < 0.9 { DVec3::X } else { DVec3::Y };
    let t1 = n.cross(a).normalize();
    (t1, n.cross(t1))
}

/// Rows of `voltab stability` for the renderer's formulas on extreme inputs.
pub fn stability_rows() -> Vec<crate::stability::Row> {
    use crate::stability::{Expect, Row};
    let mut v = Vec::new();
    let kind = "translucent";
    // Diffuse Fresnel reflectance of an ior 1.5 interface: ≈ 0.092 from outside (Egan & Hilgeman's fit
    // gives 0.0919), and 1 − (1 − F_out)/η² from inside (reciprocity).
    let f_out = diffuse_fresnel(1.0, 1.5);
    v.push(Row {
        kind,
        formula: "F_dr outside",
        input: "η = 1.5".into(),
        value: f_out,
        expect: Expect::InRange(0.090, 0.094),
    });
    v.push(Row {
        kind,
        formula: "F_dr inside",
        input: "η = 1.5".into(),
        value: diffuse_fresnel(1.5, 1.0),
        expect: Expect::Close { to: 1.0 - (1.0 - f_out) / 2.25, rel: 2e-3 },
    });
    v.push(Row {
        kind,
        formula: "F_dr index-matched",
        input: "η = 1".into(),
        value: diffuse_fresnel(1.0, 1.0),
        expect: Expect::InRange(0.0, 1e-12),
    });
    v.push(Row {
        kind,
        formula: "Fresnel grazing",
        input: "cos θ = 0".into(),
        value: fresnel(0.0, 1.0, 1.5),
        expect: Expect::Close { to: 1.0, rel: 1e-12 },
    });
    v.push(Row {
        kind,
        formula: "Fresnel TIR",
        input: "inside, cos θ = 0.1".into(),
        value: fresnel(0.1, 1.5, 1.0),
        expect: Expect::Close { to: 1.0, rel: 0.0 },
    });
    // Camera-sample weights integrate the attenuation: Σ w = (1 − e^{−σ d})/σ for the reference channel.
    for (label, sigma, d) in
        [("σd = 1e-12", 1.0, 1e-12), ("σd = 1", 1.0, 1.0), ("σd = 1e6", 1.0, 1e6), ("σ = 1e9, d = 1", 1e9, 1.0)]
    {
        let m = Material { sigma_t: [sigma; 3], albedo: [1.0; 3], g: 0.0, ior: 1.5 };
        let s = Segment {
            pixel: 0,
            entry: DVec3::ZERO,
            normal: -DVec3::Z,
            dir: DVec3::Z,
            d_max: d,
            weight: [1.0; 3],
            samples: 16,
            primary: true,
        };
        let sum: f64 = camera_samples(&s, &m).iter().map(|x| x.1[0]).sum();
        let exact = -(-sigma * d).exp_m1() / sigma;
        v.push(Row {
            kind,
            formula: "Eq. 10 weights Σw",
            input: label.into(),
            value: sum,
            expect: Expect::Close { to: exact, rel: 1e-12 },
        });
    }
    // Channels with very different σ (oil: 1 : 4.2) keep finite weights deep in the object.
    let oil = Material { sigma_t: [10.3, 8.6, 36.5], albedo: [0.0042, 0.4535, 0.0995], g: 0.9, ior: 1.5 };
    let s = Segment {
        pixel: 0,
        entry: DVec3::ZERO,
        normal: -DVec3::Z,
        dir: DVec3::Z,
        d_max: 1e3,
        weight: [1.0; 3],
        samples: 16,
        primary: true,
    };
    let deepest = camera_samples(&s, &oil).last().map_or(f64::NAN, |x| x.1[2]);
    v.push(Row {
        kind,
        formula: "Eq. 10 weight, fastest channel",
        input: "oil, d = 1e3 m".into(),
        value: deepest,
        expect: Expect::InRange(0.0, 1.0),
    });
    v.push(Row {
        kind,
        formula: "Fresnel, index-matched",
        input: "grazing, cos θ = 0".into(),
        value: fresnel(0.0, 1.3, 1.3),
        expect: Expect::Close { to: 0.0, rel: 0.0 },
    });
    let profile = EmissionProfile { ior: 1.5, f_out: diffuse_fresnel(1.0, 1.5), f_in: diffuse_fresnel(1.5, 1.0) };
    v.push(Row {
        kind,
        formula: "emission profile (reflected)",
        input: "η = 1.5, grazing".into(),
        value: profile.factors(0.0).1,
        expect: Expect::Close { to: 1.0 / profile.f_in, rel: 1e-12 },
    });
    // The grazing beams' angle: inside the total-reflection cone `F = 1`, so where the median lies in
    // it, `m = √(F_dr,in/2)`; at η = 1 + 1e-6 the cone is 1.4e-3 wide and holds all but ~1e-7 of the
    // reflected flux.
    let steep = EmissionProfile { ior: 100.0, f_out: diffuse_fresnel(1.0, 100.0), f_in: diffuse_fresnel(100.0, 1.0) };
    v.push(Row {
        kind,
        formula: "grazing-beam median cos θ",
        input: "η = 100".into(),
        value: steep.grazing_median(),
        expect: Expect::Close { to: (steep.f_in / 2.0).sqrt(), rel: 1e-3 },
    });
    let eta = 1.0 + 1e-6;
    let thin = EmissionProfile { ior: eta, f_out: diffuse_fresnel(1.0, eta), f_in: diffuse_fresnel(eta, 1.0) };
    v.push(Row {
        kind,
        formula: "grazing-beam median cos θ",
        input: "η = 1 + 1e-6".into(),
        value: thin.grazing_median(),
        expect: Expect::InRange(0.0, (1.0 - 1.0 / (eta * eta)).sqrt()),
    });
    let stiff = Material { sigma_t: [1e-6, 1.0, 1e9], albedo: [1.0, 1.0, 0.0], g: 0.99, ior: 1.5 };
    v.push(Row {
        kind,
        formula: "z_b = 2/(3σ_t(1 − αg))",
        input: "σ_t = 1e-6, α = 1, g = 0.99".into(),
        value: extrapolation_distance(&stiff)[0],
        expect: Expect::Close { to: 2.0 / (3.0 * 1e-6 * 0.01), rel: 1e-9 },
    });
    v.push(Row {
        kind,
        formula: "solid angle",
        input: "inside the ball".into(),
        value: solid_angle(1.0, 0.0),
        expect: Expect::Close { to: 2.0 * PI, rel: 0.0 },
    });
    v.push(Row {
        kind,
        formula: "solid angle",
        input: "r/d = 1e-9".into(),
        value: solid_angle(1e-9, 1.0),
        expect: Expect::Close { to: PI * 1e-18, rel: 1e-6 },
    });
    v.extend(super::object_light::stability_rows());
    v.extend(scene_ray_rows());
    v
}

/// Scene rays ([`Tracer::scene_first`]) on the ball over a lit ground: strongly forward and backward
/// scattering, an optically huge and a vanishing medium, a camera sample on the boundary, and albedo 0.
/// Each value lies in `[0, σ_s η² L_max]`, `L_max` the brightest ground radiance (below the lamp).
fn scene_ray_rows() -> Vec<crate::stability::Row> {
    use crate::stability::{Expect, Row};
    let scene = super::object_light::ball_over_ground(0.05);
    let bvh = crate::scene::bvh::SceneBvh::build(&scene);
    let (r, i) = (0.005, 1.0);
    let lamp = [super::Emitter { center: DVec3::new(0.3, 0.8, 0.0), radius: r, radiance: [i / (PI * r * r); 3] }];
    let l_max = 0.5 / PI * i / (0.8 * 0.8);
    let light = ObjectLight::default();
    let opts = RenderOptions { scene_rays: 64, ..RenderOptions::default() };
    let centre = DVec3::new(0.0, 0.15, 0.0);
    // (input, σ_t, albedo, g, camera sample)
    type Case = (&'static str, [f64; 3], [f64; 3], f64, DVec3);
    let cases: [Case; 5] = [
        ("g = 0.99, α = 1", [10.0; 3], [1.0; 3], 0.99, centre),
        ("g = −0.99, σ_t = 1e4 /m", [1e4; 3], [1.0; 3], -0.99, centre),
        ("g = 0, σ_t = 1e-3 /m", [1e-3; 3], [1.0; 3], 0.0, centre),
        ("g = 0.9, on the boundary", [10.0; 3], [1.0; 3], 0.9, DVec3::new(0.0, 0.05, 0.0)),
        ("albedo 0", [10.0; 3], [0.0; 3], 0.7, centre),
    ];
    let mut v = Vec::new();
    for (input, sigma_t, albedo, g, p) in cases {
        let material = Material { sigma_t, albedo, g, ior: 1.5 };
        let setup = Setup { scene: &scene, bvh: &bvh, object: 0, material, emitters: &lamp };
        let tracer = Tracer { setup: &setup, opts: &opts, light: &light };
        let f = tracer.scene_first(p, DVec3::Y, StreamKey { table: 1, cell: 2 }, 0);
        let bound = albedo[0] * sigma_t[0] * 1.5 * 1.5 * l_max;
        let expect = if bound > 0.0 { Expect::InRange(0.0, bound) } else { Expect::Close { to: 0.0, rel: 0.0 } };
        v.push(Row {
            kind: "translucent",
            formula: "scene rays (first scattering)",
            input: input.into(),
            value: f[0],
            expect,
        });
    }
    v
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample(start: DVec3, direction: DVec3, plane_point: DVec3, plane_normal: DVec3) -> VolumeSample {
        VolumeSample {
            start,
            direction,
            length: 0.5,
            flux: [1.0; 3],
            area: 1e-4,
            surface: 0,
            bounce: 0,
            depth: 0.0,
            plane_point,
            plane_normal,
            tan_entry: 0.0,
        }
    }

    /// The image beam of a sample is its interval mirrored about its boundary plane and moved out by
    /// `2 z_b` (derived by hand: medium z > 0, outward normal −z); a node's image is the flux-weighted
    /// mean of its samples' images even when their planes differ.
    #[test]
    fn image_beams_mirror_about_each_samples_plane() {
        let sigma = [0.0; 3]; // no attenuation: start and end carry the same weight
        let d = DVec3::new(0.6, 0.0, 0.8);
        let a = VolAgg::of_sample(&sample(DVec3::new(0.0, 0.0, 0.5), d, DVec3::ZERO, -DVec3::Z), sigma);
        let (s, e, dir) = a.image(0.25);
        assert!((s - DVec3::new(0.0, 0.0, -1.0)).length() < 1e-12, "{s}");
        assert!((e - DVec3::new(0.3, 0.0, -1.4)).length() < 1e-12, "{e}");
        assert!((dir - DVec3::new(0.6, 0.0, -0.8)).length() < 1e-12, "{dir}");
        // A second sample under the plane x = 1 (outward +x), starting 0.2 inside it, along −x.
        let b = VolAgg::of_sample(&sample(DVec3::new(0.8, 0.0, 2.0), -DVec3::X, DVec3::X, DVec3::X), sigma);
        let (s2, ..) = b.image(0.25);
        assert!((s2 - DVec3::new(1.7, 0.0, 2.0)).length() < 1e-12, "{s2}");
        let (sm, ..) = VolAgg::merge(&[a, b]).image(0.25);
        assert!((sm - 0.5 * (s + s2)).length() < 1e-12, "{sm}");
    }

    /// The median of the internally reflected flux lies inside the total-reflection cone at η = 1.5,
    /// where `F = 1`, so `∫₀^m μ dμ = F_dr,in/4` gives `m = √(F_dr,in/2)`; without an interface the
    /// Lambertian median `1/√2`. The grazing directions sit at that cosine and spread evenly.
    #[test]
    fn grazing_median_and_directions() {
        let f_in = diffuse_fresnel(1.5, 1.0);
        let p = EmissionProfile { ior: 1.5, f_out: diffuse_fresnel(1.0, 1.5), f_in };
        let m = p.grazing_median();
        assert!(m < (1.0f64 - 1.0 / 2.25).sqrt());
        assert!((m - (f_in / 2.0).sqrt()).abs() < 1e-4, "{m} vs {}", (f_in / 2.0).sqrt());
        let matched = EmissionProfile { ior: 1.0, f_out: 0.0, f_in: 0.0 };
        assert_eq!(matched.grazing_median(), std::f64::consts::FRAC_1_SQRT_2);
        let n = DVec3::new(0.2, -0.9, 0.4).normalize();
        let dirs: Vec<DVec3> = grazing_dirs(n, m, 4).collect();
        for d in &dirs {
            assert!((d.length() - 1.0).abs() < 1e-12 && (d.dot(n) - m).abs() < 1e-12);
        }
        let sum: DVec3 = dirs.iter().copied().sum();
        assert!((sum - n * (4.0 * m)).length() < 1e-12, "{sum}");
    }

    /// On a ball of radius R every chord at `cos θ = μ` from the inward normal is `2Rμ`, so a sample's
    /// grazing beams end `2Rμ` away with `e^{−σ_t 2Rμ}` of their flux left; the normal beam carries the
    /// refracted scene light and the grazing beams the rest of the exitance (all of it on the normal
    /// beam without them).
    #[test]
    fn grazing_beams_follow_the_chords_of_a_ball() {
        let scene = super::super::object_light::ball_over_ground(0.05);
        let bvh = crate::scene::bvh::SceneBvh::build(&scene);
        let (c, radius) = (DVec3::new(0.0, 0.15, 0.0), 0.1);
        let material = Material { sigma_t: [5.0, 10.0, 20.0], albedo: [0.9, 0.5, 0.2], g: 0.7, ior: 1.5 };
        let setup = Setup { scene: &scene, bvh: &bvh, object: 0, material, emitters: &[] };
        let f_out = diffuse_fresnel(1.0, 1.5);
        let mu = EmissionProfile { ior: 1.5, f_out, f_in: diffuse_fresnel(1.5, 1.0) }.grazing_median();
        let ex = [3.0, 2.0, 1.0];
        for out in [DVec3::X, DVec3::new(0.3, 0.8, -0.5), DVec3::new(-0.6, -0.7, 0.2)] {
            let out = out.normalize();
            let hit = bvh.closest_hit(&Ray::new(c.to_array(), out.to_array())).unwrap();
            let s = SurfaceSample {
                position: c + out * hit.t,
                normal: DVec3::from_array(hit.geometric_normal),
                area: 1e-4,
                triangle: hit.triangle as u32,
                direct: [0.0; 3],
                indirect: [0.5, 1.0, 4.0], // (1 − F_dr,out) E: below `ex` in R and G, capped in B
            };
            let a = surface_item(&setup, &s, ex, 0.2, f_out, (4, mu));
            let len = a.graze_len / a.w;
            assert!((len - 2.0 * radius * mu).abs() < 0.01 * 2.0 * radius * mu, "{len}");
            for (ch, &e) in ex.iter().enumerate() {
                let s_ext = ((1.0 - f_out) * s.indirect[ch]).min(e);
                assert!((a.flux0[ch] - s_ext * s.area).abs() < 1e-15);
                assert!((a.flux0[ch] + a.graze0[ch] - e * s.area).abs() < 1e-15);
                let left = (-material.sigma_t[ch] * 2.0 * radius * mu).exp() * a.graze0[ch];
                assert!((a.graze1[ch] - left).abs() <= 0.01 * left, "channel {ch}");
            }
            assert_eq!(a.graze0[2], 0.0); // the scene light alone exceeds the exitance in B
            let plain = surface_item(&setup, &s, ex, 0.2, f_out, (0, mu));
            assert_eq!((plain.graze0, plain.graze_len), ([0.0; 3], 0.0));
            for (f, e) in plain.flux0.iter().zip(ex) {
                assert!((f - e * s.area).abs() < 1e-15);
            }
        }
    }

    /// Eq. 6 near a volume sample averages `1/r²` over its tube's disk: on the disk's axis at height
    /// `h` that average is `ln(1 + a²/h²)/a²` (σ → 0, g = 0 so both phase values are `1/4π`); with
    /// `double_disk: 0`, and beyond `DISK_REACH` radii, the centre's `1/h²`.
    #[test]
    fn double_scattering_spreads_a_sample_over_its_tube() {
        let scene = super::super::object_light::ball_over_ground(0.05);
        let bvh = crate::scene::bvh::SceneBvh::build(&scene);
        let sigma = 1e-3;
        let material = Material { sigma_t: [sigma; 3], albedo: [1.0; 3], g: 0.0, ior: 1.0 };
        let setup = Setup { scene: &scene, bvh: &bvh, object: 0, material, emitters: &[] };
        let a = 0.01;
        let mut v = sample(DVec3::ZERO, DVec3::Z, DVec3::ZERO, -DVec3::Z);
        v.length = 1e-4;
        v.area = PI * a * a;
        let items = [Item { position: v.center(), bounds: v.obb(2.0).aabb() }];
        let tree = Octree::build(&items, 8, 24);
        let vol_items = [VolAgg::of_sample(&v, material.sigma_t)];
        let agg = tree.bottom_up(
            |ids| VolAgg::merge(&ids.iter().map(|&i| vol_items[i as usize]).collect::<Vec<_>>()),
            VolAgg::merge,
        );
        let lam = vol_items[0].lam[0];
        let scale = sigma * sigma * lam / (16.0 * PI * PI); // σ_s² Λ p p
        let at = |n: u32, h: f64| {
            let opts = RenderOptions { double_disk: n, clamp_mfp: 0.0, ..RenderOptions::default() };
            let eval = Evaluator::new(&setup, &[], &opts, (&tree, &agg, &vol_items));
            eval.double(v.center() + DVec3::Z * h, DVec3::X, &mut Vec::new()).0[1] / scale
        };
        let h = 0.5 * a;
        let want = (1.0 + a * a / (h * h)).ln() / (a * a);
        let got = at(4096, h);
        assert!((got - want).abs() < 2e-3 * want, "{got} vs {want}");
        assert!((at(0, h) - 1.0 / (h * h)).abs() < 1e-4 / (h * h));
        let far = 3.5 * a;
        assert!((at(4096, far) - 1.0 / (far * far)).abs() < 1e-4 / (far * far));
    }

    /// Both emission profiles carry exactly the exitance (`2∫ k(μ) μ dμ = 1`, midpoint rule), the
    /// refracted light stays inside the critical cone, and an index-matched boundary is Lambertian.
    #[test]
    fn emission_profiles_conserve_the_exitance() {
        let p = EmissionProfile { ior: 1.5, f_out: diffuse_fresnel(1.0, 1.5), f_in: diffuse_fresnel(1.5, 1.0) };
        let n = 200_000;
        let (mut ext, mut int) = (0.0, 0.0);
        for i in 0..n {
            let mu = (i as f64 + 0.5) / n as f64;
            let (a, b) = p.factors(mu);
            ext += 2.0 * a * mu / n as f64;
            int += 2.0 * b * mu / n as f64;
        }
        assert!((ext - 1.0).abs() < 1e-4 && (int - 1.0).abs() < 1e-4, "{ext} {int}");
        // sin θ_c = 1/1.5: just outside the cone nothing is refracted in, everything is reflected.
        let mu_c = (1.0 - 1.0 / 2.25f64).sqrt();
        assert_eq!(p.factors(mu_c - 1e-6).0, 0.0);
        assert!((p.factors(mu_c - 1e-6).1 - 1.0 / p.f_in).abs() < 1e-12);
        // At normal incidence F = 0.04: (1 − 0.04)·2.25/(1 − F_dr,out).
        assert!((p.factors(1.0).0 - 0.96 * 2.25 / (1.0 - p.f_out)).abs() < 1e-12);
        let m = EmissionProfile { ior: 1.0, f_out: 0.0, f_in: 0.0 };
        for mu in [0.0, 0.3, 1.0] {
            assert_eq!(m.factors(mu), (1.0, 0.0));
        }
    }

    /// `z_b = 2/(3σ_t(1 − αg))`; the multiple-scattering floor keeps a channel at `α²/(1 − α) ≥ 0.02`.
    #[test]
    fn extrapolation_distance_and_multiple_floor() {
        let m = Material { sigma_t: [10.0, 10.0, 4.0], albedo: [1.0, 0.5, 0.0], g: 0.8, ior: 1.5 };
        let z = extrapolation_distance(&m);
        for (got, want) in z.iter().zip([2.0 / 6.0, 2.0 / 18.0, 2.0 / 12.0]) {
            assert!((got - want).abs() < 1e-15, "{got} vs {want}");
        }
        // Oil (wang2018 Table 2): red and blue are left out, green kept.
        assert_eq!([0.0042, 0.4535, 0.0995].map(multiple_needed), [false, true, false]);
        assert!(multiple_needed(1.0) && !multiple_needed(0.0));
        // The floor's crossing: α² = 0.02 (1 − α) at α = (−0.02 + √(0.0004 + 0.08))/2.
        let a = (-0.02 + (0.0004f64 + 0.08).sqrt()) / 2.0;
        assert!(multiple_needed(a + 1e-9) && !multiple_needed(a - 1e-9));
        // The inner irradiance drops only oil's red; its crossing α = 0.02 (1 − α) at α = 0.02/1.02.
        assert_eq!([0.0042, 0.4535, 0.0995].map(inner_needed), [false, true, true]);
        assert!(inner_needed(1.0) && !inner_needed(0.0));
        let a = 0.02 / 1.02;
        assert!(inner_needed(a + 1e-9) && !inner_needed(a - 1e-9));
    }

    /// Scene rays at the centre of an index-matched ball over a ground lit by a small lamp: the ground
    /// seen through the ball and scattered once toward `w`, `σ_s ∫ p(ω·w) L_in(ω) dω`, against a
    /// product quadrature over directions written here with analytic geometry (every straight line
    /// from the centre leaves the ball after `R`; the ground's radiance is `ρ/π I cos/d²` where the ball
    /// does not shadow it).
    #[test]
    fn scene_rays_match_quadrature_through_an_index_matched_ball() {
        let scene = super::super::object_light::ball_over_ground(0.05);
        let bvh = crate::scene::bvh::SceneBvh::build(&scene);
        let (c, radius, rho) = (DVec3::new(0.0, 0.15, 0.0), 0.1, 0.5);
        let (r, i) = (0.002, 2.0);
        let lamp_at = DVec3::new(0.5, 0.7, 0.2);
        let lamp = [super::super::Emitter { center: lamp_at, radius: r, radiance: [i / (PI * r * r); 3] }];
        let material = Material { sigma_t: [5.0, 10.0, 20.0], albedo: [0.9, 0.5, 0.2], g: 0.7, ior: 1.0 };
        let setup = Setup { scene: &scene, bvh: &bvh, object: 0, material, emitters: &lamp };
        let light = ObjectLight::default();
        let opts = RenderOptions { scene_rays: 4096, ..RenderOptions::default() };
        let tracer = Tracer { setup: &setup, opts: &opts, light: &light };
        let w = DVec3::new(0.3, 1.0, 0.2).normalize();
        let got = tracer.scene_first(c, w, StreamKey { table: 7, cell: 0 }, 0);

        // Does the segment a → b cross the ball (radius slightly inside the facets' vertices)?
        let blocked = |a: DVec3, b: DVec3| {
            let d = b - a;
            let t = ((c - a).dot(d) / d.length_squared()).clamp(0.0, 1.0);
            (a + d * t).distance(c) < radius
        };
        let hg = |mu: f64, g: f64| (1.0 - g * g) / (4.0 * PI * (1.0 + g * g - 2.0 * g * mu).powf(1.5));
        // Travel directions ω with ω.y > 0 (light from the ground below): Gauss–Legendre in ω.y,
        // midpoint rule in azimuth.
        let (nu, nphi) = (400, 800);
        let nodes = crate::physics::sh::gauss_legendre(nu);
        let mut want = [0.0; 3];
        for &(x, wx) in &nodes {
            let uy = 0.5 * (x + 1.0);
            let s = (1.0 - uy * uy).sqrt();
            for k in 0..nphi {
                let phi = 2.0 * PI * (k as f64 + 0.5) / nphi as f64;
                let omega = DVec3::new(s * phi.cos(), uy, s * phi.sin());
                let exit = c - omega * radius;
                let q = exit - omega * (exit.y / omega.y);
                if q.x.abs() > 1.0 || q.z.abs() > 1.0 || blocked(q, lamp_at) {
                    continue;
                }
                let d = lamp_at - q;
                let l_out = rho / PI * i * (d.y / d.length()) / d.length_squared();
                let dw = 0.5 * wx * 2.0 * PI / nphi as f64;
                for (ch, x) in want.iter_mut().enumerate() {
                    let l_in = l_out * (-material.sigma_t[ch] * radius).exp();
                    *x += material.albedo[ch] * material.sigma_t[ch] * hg(omega.dot(w), material.g) * l_in * dw;
                }
            }
        }
        for ch in 0..3 {
            assert!((got[ch] - want[ch]).abs() < 0.01 * want[ch], "channel {ch}: {} vs {}", got[ch], want[ch]);
        }
        // Off: the surface samples carry this light instead.
        let off = RenderOptions { scene_rays: 0, ..RenderOptions::default() };
        let tracer = Tracer { setup: &setup, opts: &off, light: &light };
        assert_eq!(tracer.scene_first(c, w, StreamKey { table: 7, cell: 0 }, 0), [0.0; 3]);
    }
}
