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
use crate::physics::hg::phase;
use crate::physics::medium::{extinguished, free_flight};
use crate::physics::rng::StreamKey;
use crate::render::ViewCamera;
use crate::render::dielectric::{Material, Setup};
use crate::render::optics::{fresnel, reflect, refract};
use crate::scene::bvh::Ray;
use crate::tables::ms_lobes::{LobeQueryError, LobeSlice, MediumChannel, MsLobesTable};

mod aggregate;
mod evaluate;
mod stability;
#[cfg(test)]
mod tests;
mod tracer;

pub use aggregate::EmissionProfile;
use aggregate::{DISK_REACH, GOLDEN_ANGLE, SurfAgg, VolAgg, grazing_dirs, mirror_about, surface_item};
use evaluate::{Evaluator, bounced_at, single_pass};
pub use stability::stability_rows;
use tracer::{Tracer, frame_of};

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
fn slices<'t>(table: &'t MsLobesTable, ch: &[MediumChannel; 3]) -> Result<Vec<LobeSlice<'t>>, LobeQueryError> {
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
    let slices = slices(table, &ch).map_err(|e| e.to_string())?;
    let eval = Evaluator::new(setup, &slices, opts, (&vol_tree, &vol_agg, &vol_items));
    let inner_irradiance: Vec<[f64; 3]> = points
        .surface
        .par_iter()
        .map(|s| eval.inner_irradiance(s))
        .collect::<Result<Vec<_>, _>>()
        .map_err(|e| e.to_string())?;

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
    )
    .map_err(|e| e.to_string())?;
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
    let slices = slices(table, &ch).map_err(|e| e.to_string())?;
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
    let mass = extinguished(sr, s.d_max);
    if mass.is_nan() || mass <= 0.0 {
        return Vec::new();
    }
    (0..k)
        .map(|i| {
            let u = (i as f64 + 0.5) / k as f64 * mass;
            let d = free_flight(u, sr);
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
