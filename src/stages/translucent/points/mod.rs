//! Surface and volume samples of wang2018's point-based renderer (Sec. 3.4.1 surface samples, Sec. 3.4.3
//! volume samples).
//!
//! **Input → output.** A [`Setup`] (scene, BVH, translucent mesh, material, spherical emitters) and
//! [`PointOptions`] → [`Points`]: blue-noise surface samples on the object's boundary with their direct
//! and one-bounce indirect irradiance from outside, and volume samples — intervals along the refracted
//! (and internally reflected) light rays, each with the flux entering it and the cross-section of its
//! light tube.
//!
//! - **Surface samples.** About `4N` area-uniform candidates on the world-space triangles (triangle by
//!   an area CDF, uniform barycentrics), reduced to `N` by weighted sample elimination (Yuksel 2015:
//!   weights `(1 − d̂/2r_max)^8` over a hash grid, a max-heap removes the most crowded candidate,
//!   `O(n log n)`). Each sample carries `area = total area / N`.
//! - **Light rays.** Per (surface sample, emitter) one ray from a uniformly jittered point of the disk the
//!   sphere emitter presents to the sample (its intensity toward the sample is [`Emitter::intensity`]).
//!   Irradiance `E = I·cos_i/D²`, entering flux `Φ = E·area·(1 − F)`, refracted by Snell's law.
//! - **Volume samples.** Along the refracted ray inside, `samples_per_ray` intervals per segment with the
//!   boundaries of wang2018 Eq. 10 for the smallest `σ_t`; at the exit facet the Fresnel-reflected part
//!   (all of it under total internal reflection) continues for up to `light_bounces` reflections.
//! - **Tube cross-section.** A flat facet lit by a point source at distance `D` refracts the ray pencil
//!   into an astigmatic pencil with virtual sources at `D_s = η·D` (sagittal) and
//!   `D_t = η·D·cos²θ_t/cos²θ_i` (tangential) behind the facet (Coddington's equations for a plane), so
//!   the cross-section at path length `t` inside is `A(t) = area·cos_t·(1 + t/D_s)(1 + t/D_t)`.
//!   Mirror reflection at a flat facet keeps the virtual distances, so `t` is the total depth since the
//!   entry even after internal reflections (exact for flat facets; an approximation where consecutive
//!   facets meet at an angle).
//! - **Indirect light.** Per surface sample `indirect_rays` stratified cosine-weighted rays; a hit on an
//!   opaque mesh of base colour `ρ` returns the radiance `ρ/π·Σ_e I_e·cos/d²` of its shadowed direct
//!   light (one bounce; the object occludes); `E = π·mean`.
//!
//! Mesh positions are already in world space (`Mesh::positions`, as the BVH uses them), so no
//! `to_world` transform is applied. Every random number is drawn from a [`StreamKey`] stream indexed by
//! the sample, and the samples run in parallel with results collected in order: the output is
//! bit-identical for any thread count.

use std::cmp::Ordering;
use std::collections::{BinaryHeap, HashMap};
use std::f64::consts::PI;
use std::time::Instant;

use glam::DVec3;
use rayon::prelude::*;

use super::object_light::{CAUSTIC_K, GLOW_K, ObjectLight, Photon, PhotonMap, glow_photon, land, receives};
use crate::physics::medium::{extinguished, free_flight};
use crate::physics::rng::StreamKey;
use crate::render::dielectric::{Emitter, Setup};
use crate::render::optics::{fresnel, reflect, refract};
use crate::scene::bvh::{Hit, Ray};

mod elimination;
#[cfg(test)]
mod tests;

use elimination::{surface_samples, world_triangles};

/// Options of [`generate`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PointOptions {
    /// Target number of surface samples `N` (the paper's sweet spot is about 66 K).
    pub surface_samples: usize,
    /// Volume samples (intervals) per straight light-ray segment inside the object.
    pub samples_per_ray: usize,
    /// A light ray is followed for at most this many mean free paths of the smallest `σ_t`.
    pub max_depth_mfp: f64,
    /// Internal reflections followed on a light path.
    pub light_bounces: u32,
    /// Cosine-weighted rays per surface sample for the scene's indirect diffuse light (0 = none).
    pub indirect_rays: u32,
    /// Seed of every random stream.
    pub seed: u64,
    /// Trace the light that leaves the object onto the scene's opaque surfaces (caustic and glow
    /// photon maps, [`super::object_light`]).
    pub object_light: bool,
}

impl Default for PointOptions {
    fn default() -> Self {
        PointOptions {
            surface_samples: 16_384,
            samples_per_ray: 8,
            max_depth_mfp: 8.0,
            light_bounces: 2,
            indirect_rays: 16,
            seed: 0,
            object_light: true,
        }
    }
}

/// A point on the object's boundary.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SurfaceSample {
    /// World position \[m\].
    pub position: DVec3,
    /// Outward unit geometric normal of its triangle.
    pub normal: DVec3,
    /// Area it represents \[m²\]: the object's area over the number of samples.
    pub area: f64,
    /// Index into the object mesh's triangles.
    pub triangle: u32,
    /// Irradiance \[W/m²\] from the emitters arriving from outside (shadowed), per channel.
    pub direct: [f64; 3],
    /// Irradiance \[W/m²\] arriving from outside from the scene's opaque diffuse surfaces lit by the
    /// emitters (one bounce), per channel.
    pub indirect: [f64; 3],
}

/// An interval `[start, start + length·direction]` of a refracted light ray inside the object.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct VolumeSample {
    /// Start of the interval \[m\].
    pub start: DVec3,
    /// Unit direction of the light.
    pub direction: DVec3,
    /// Length \[m\] (> 0).
    pub length: f64,
    /// Flux \[W\] entering the interval at `start`, per channel.
    pub flux: [f64; 3],
    /// Cross-section \[m²\] of the light tube at the interval's midpoint.
    pub area: f64,
    /// Surface sample the light ray entered through.
    pub surface: u32,
    /// Internal reflections before this interval.
    pub bounce: u8,
    /// Path length \[m\] inside the object from the entry point to `start`.
    pub depth: f64,
    /// The boundary point the light last crossed or was reflected at (the plane of its image beam).
    pub plane_point: DVec3,
    /// Unit outward normal there.
    pub plane_normal: DVec3,
    /// For an interval starting on the boundary, `tan θ` of the angle between the light and the
    /// inward normal (0 otherwise): its box reaches back across the boundary (see [`Self::obb`]).
    pub tan_entry: f64,
}

impl VolumeSample {
    /// Midpoint of the interval.
    pub fn center(&self) -> DVec3 {
        self.start + 0.5 * self.length * self.direction
    }

    /// End point of the interval.
    pub fn end(&self) -> DVec3 {
        self.start + self.length * self.direction
    }

    /// Track length of the flux over the interval, `∫_0^L Φ e^{−σ s} ds = Φ·(1 − e^{−σL})/σ` per channel
    /// \[W·m\] (`Φ·L` for `σ = 0`), evaluated with `expm1` so it is exact as `σL → 0` and `σL → ∞`.
    pub fn track_length(&self, sigma_t: [f64; 3]) -> [f64; 3] {
        std::array::from_fn(|c| {
            let (s, l) = (sigma_t[c], self.length);
            if s > 0.0 && s * l > 0.0 { self.flux[c] * extinguished(s, l) / s } else { self.flux[c] * l }
        })
    }

    /// Oriented box around the interval: first axis the direction, a square cross-section of side
    /// `widen·sqrt(area)` in a deterministic frame, axially the interval `[0, L]`. An interval that
    /// starts on the boundary with the light at angle θ to the normal has its start face tilted
    /// against the boundary, so a wedge of the medium up to `w tan θ` (half-width `w`) behind the face
    /// would be covered by fewer boxes than elsewhere and lose single scattering; such a box reaches
    /// back `w tan θ` (at most `4w`) to cover it.
    pub fn obb(&self, widen: f64) -> Obb {
        let a = self.direction.try_normalize().unwrap_or(DVec3::X);
        let (u, v) = a.any_orthonormal_pair();
        let w = 0.5 * widen * self.area.max(0.0).sqrt();
        let back = if self.tan_entry > 0.0 { (w * self.tan_entry).min(4.0 * w) } else { 0.0 };
        Obb { center: self.center() - 0.5 * back * a, axes: [a, u, v], half: [0.5 * (self.length + back), w, w] }
    }
}

/// An oriented box.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Obb {
    /// Centre \[m\].
    pub center: DVec3,
    /// Orthonormal axes.
    pub axes: [DVec3; 3],
    /// Half extents along the axes \[m\].
    pub half: [f64; 3],
}

impl Obb {
    /// Entry and exit parameters `t` of the line `origin + t·dir` (unclipped: either may be negative),
    /// `None` when the line misses the box or the input is not finite.
    pub fn hit(&self, origin: DVec3, dir: DVec3) -> Option<(f64, f64)> {
        let rel = origin - self.center;
        let (mut t0, mut t1) = (f64::NEG_INFINITY, f64::INFINITY);
        for (axis, &h) in self.axes.iter().zip(&self.half) {
            let (o, d) = (rel.dot(*axis), dir.dot(*axis));
            if !(o.is_finite() && d.is_finite()) {
                return None;
            }
            if d == 0.0 {
                if o.abs() > h {
                    return None;
                }
            } else {
                let (a, b) = ((-h - o) / d, (h - o) / d);
                t0 = t0.max(a.min(b));
                t1 = t1.min(a.max(b));
            }
        }
        (t0 <= t1).then_some((t0, t1))
    }

    /// Axis-aligned bounds (min, max).
    pub fn aabb(&self) -> (DVec3, DVec3) {
        let e =
            self.axes[0].abs() * self.half[0] + self.axes[1].abs() * self.half[1] + self.axes[2].abs() * self.half[2];
        (self.center - e, self.center + e)
    }
}

/// Counts and timings of [`generate`].
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct PointStats {
    /// Wall time of the surface sampling \[ms\].
    pub surface_ms: f64,
    /// Wall time of the light rays and volume samples \[ms\].
    pub volume_ms: f64,
    /// Wall time of the indirect irradiance \[ms\].
    pub indirect_ms: f64,
    /// Wall time of the object's caustic and glow photons \[ms\].
    pub photon_ms: f64,
    /// Light rays that entered the object.
    pub light_rays: u64,
    /// Total internal reflections met at exit facets.
    pub total_internal_reflections: u64,
    /// Flux \[W\] that entered the object, per channel.
    pub entered_flux: [f64; 3],
    /// Flux still inside when a ray was cut (depth budget, bounce limit, reflected flux below 1e-4 of
    /// the entering flux, or a ray leaving the object's mesh unexpectedly), over the entered flux
    /// (channel sums).
    pub lost_flux_fraction: f64,
}

/// The output of [`generate`].
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Points {
    /// Surface samples.
    pub surface: Vec<SurfaceSample>,
    /// Volume samples, grouped by surface sample, then emitter, then along the ray.
    pub volume: Vec<VolumeSample>,
    /// The object's light on the scene (empty unless [`PointOptions::object_light`]).
    pub object_light: ObjectLight,
    /// Counts and timings.
    pub stats: PointStats,
}

/// Stream cells of the three random uses.
const CELL_CANDIDATES: u64 = 0x5eed_0001;
const CELL_EMITTER: u64 = 0x5eed_0002;
const CELL_INDIRECT: u64 = 0x5eed_0003;
const CELL_GLOW: u64 = 0x5eed_0004;

/// Builds the surface and volume samples of `setup` (see the module doc).
pub fn generate(setup: &Setup, opts: &PointOptions) -> Result<Points, String> {
    setup.material.check()?;
    check_options(opts)?;
    for (i, e) in setup.emitters.iter().enumerate() {
        if !(e.center.is_finite() && e.radius.is_finite() && e.radius > 0.0) {
            return Err(format!(
                "emitter {i}: centre {:?} and radius {} must be finite (radius > 0)",
                e.center, e.radius
            ));
        }
        if e.radiance.iter().any(|v| !(v.is_finite() && *v >= 0.0)) {
            return Err(format!("emitter {i}: radiance {:?} must be finite and ≥ 0", e.radiance));
        }
    }
    let mesh =
        setup.scene.meshes.get(setup.object).ok_or_else(|| {
            format!("object mesh {} does not exist ({} meshes)", setup.object, setup.scene.meshes.len())
        })?;
    let tris = world_triangles(mesh);
    let total_area: f64 = tris.iter().map(|t| t.area).sum();
    if !(total_area > 0.0 && total_area.is_finite()) {
        return Err(format!("object mesh \"{}\" has no triangle of finite, non-zero area", mesh.name));
    }
    let (lo, hi) =
        tris.iter().flat_map(|t| t.v).fold((DVec3::INFINITY, DVec3::NEG_INFINITY), |(a, b), p| (a.min(p), b.max(p)));
    let scale = (hi - lo).length().max(lo.abs().max_element()).max(hi.abs().max_element());
    let eps = 1e-5 * scale;

    let t0 = Instant::now();
    let samples = surface_samples(&tris, total_area, opts.surface_samples, opts.seed);
    let area = total_area / samples.len() as f64;
    let surface_ms = ms(t0);

    let sigma_min = setup.material.sigma_t.iter().copied().fold(f64::INFINITY, f64::min);
    let ctx = LightCtx {
        setup,
        eta: setup.material.ior,
        sigma_t: setup.material.sigma_t,
        sigma_min,
        budget: opts.max_depth_mfp / sigma_min,
        samples_per_ray: opts.samples_per_ray,
        light_bounces: opts.light_bounces,
        eps,
        object_light: opts.object_light,
    };
    let t1 = Instant::now();
    let lit: Vec<SampleLight> = samples
        .par_iter()
        .enumerate()
        .map(|(i, &(p, ti))| light_sample(&ctx, i as u32, p, tris[ti].normal, area, opts.seed))
        .collect();
    let volume_ms = ms(t1);

    // The object's light on the scene: photons of the transmitted and the scattered light.
    let t3 = Instant::now();
    let mut object_light = ObjectLight::default();
    if opts.object_light {
        let glow: Vec<Vec<Photon>> = lit
            .par_iter()
            .enumerate()
            .map(|(i, l)| {
                let key = StreamKey { table: opts.seed, cell: CELL_GLOW ^ ((i as u64) << 20) };
                l.volume
                    .iter()
                    .enumerate()
                    .filter_map(|(j, v)| glow_photon(setup, v, key.sample(j as u64), eps))
                    .collect()
            })
            .collect();
        let r_max = 0.25 * (hi - lo).length();
        let caustic = lit.iter().flat_map(|l| l.caustic.iter().copied()).collect();
        object_light = ObjectLight {
            caustic: PhotonMap::build(caustic, CAUSTIC_K, r_max),
            glow: PhotonMap::build(glow.into_iter().flatten().collect(), GLOW_K, r_max),
        };
    }
    let photon_ms = ms(t3);

    let t2 = Instant::now();
    let indirect: Vec<[f64; 3]> = samples
        .par_iter()
        .enumerate()
        .map(|(i, &(p, ti))| indirect_irradiance(&ctx, &object_light, i as u64, p, tris[ti].normal, opts))
        .collect();
    let indirect_ms = ms(t2);

    let mut stats = PointStats { surface_ms, volume_ms, indirect_ms, photon_ms, ..PointStats::default() };
    let mut lost = [0.0; 3];
    let mut surface = Vec::with_capacity(samples.len());
    let mut volume = Vec::with_capacity(lit.iter().map(|l| l.volume.len()).sum());
    for (((p, ti), l), ind) in samples.iter().zip(lit).zip(indirect) {
        surface.push(SurfaceSample {
            position: *p,
            normal: tris[*ti].normal,
            area,
            triangle: tris[*ti].index,
            direct: l.direct,
            indirect: ind,
        });
        volume.extend(l.volume);
        stats.light_rays += l.rays;
        stats.total_internal_reflections += l.tir;
        for (c, lost_c) in lost.iter_mut().enumerate() {
            stats.entered_flux[c] += l.entered[c];
            *lost_c += l.lost[c];
        }
    }
    let entered: f64 = stats.entered_flux.iter().sum();
    stats.lost_flux_fraction = if entered > 0.0 { lost.iter().sum::<f64>() / entered } else { 0.0 };
    Ok(Points { surface, volume, object_light, stats })
}

fn ms(t: Instant) -> f64 {
    t.elapsed().as_secs_f64() * 1e3
}

fn check_options(o: &PointOptions) -> Result<(), String> {
    if !(1..=1 << 24).contains(&o.surface_samples) {
        return Err(format!("surface_samples = {} must lie in [1, 2^24]", o.surface_samples));
    }
    if !(1..=4096).contains(&o.samples_per_ray) {
        return Err(format!("samples_per_ray = {} must lie in [1, 4096]", o.samples_per_ray));
    }
    if !(o.max_depth_mfp.is_finite() && o.max_depth_mfp > 0.0) {
        return Err(format!("max_depth_mfp = {} must be finite and > 0", o.max_depth_mfp));
    }
    if o.light_bounces > 255 {
        return Err(format!("light_bounces = {} must be at most 255", o.light_bounces));
    }
    if o.indirect_rays > 1 << 20 {
        return Err(format!("indirect_rays = {} must be at most 2^20", o.indirect_rays));
    }
    Ok(())
}

/// What the light rays need, shared by all samples.
struct LightCtx<'a> {
    setup: &'a Setup<'a>,
    eta: f64,
    sigma_t: [f64; 3],
    sigma_min: f64,
    /// Path-length budget inside \[m\].
    budget: f64,
    samples_per_ray: usize,
    light_bounces: u32,
    /// Ray offset from surfaces \[m\].
    eps: f64,
    /// Land the transmitted flux of exit facets as caustic photons.
    object_light: bool,
}

/// The light tube of one ray: `A(t) = area_cos·(1 + t/d_s)(1 + t/d_t)`.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Tube {
    area_cos: f64,
    d_s: f64,
    d_t: f64,
}

impl Tube {
    fn at(&self, t: f64) -> f64 {
        self.area_cos * (1.0 + t / self.d_s) * (1.0 + t / self.d_t)
    }
}

/// A light ray entering the object.
#[derive(Debug, Clone, Copy)]
struct Entering {
    /// Entry point on the boundary.
    point: DVec3,
    /// Outward normal there.
    normal: DVec3,
    /// Refracted unit direction (pointing inside).
    dir: DVec3,
    /// Flux after Fresnel transmission.
    flux: [f64; 3],
    tube: Tube,
    surface: u32,
}

/// Where the flux of one light ray went.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
struct RayBudget {
    /// Transmitted out through exit facets (not followed).
    transmitted: [f64; 3],
    /// Still inside when the ray was cut.
    lost: [f64; 3],
    /// Total internal reflections met.
    tir: u64,
}

fn max3(a: [f64; 3]) -> f64 {
    a[0].max(a[1]).max(a[2])
}

/// Follows one refracted light ray inside the object, appending its intervals to `out`.
fn trace(ctx: &LightCtx, ray: &Entering, out: &mut Vec<VolumeSample>, caustic: &mut Vec<Photon>) -> RayBudget {
    let bvh = ctx.setup.bvh;
    let mut res = RayBudget::default();
    let mut origin = ray.point - ray.normal * ctx.eps;
    let mut dir = ray.dir;
    let mut flux = ray.flux;
    let entering = max3(ray.flux);
    let mut depth = 0.0;
    let mut bounce: u32 = 0;
    let mut plane = (ray.point, ray.normal);
    loop {
        let remaining = ctx.budget - depth;
        let hit = bvh.closest_hit(&Ray::new(origin.to_array(), dir.to_array()));
        // The ray must leave through the object's boundary from inside; anything else ends it.
        let (t_exit, facet): (f64, Option<Hit>) = match hit {
            Some(h) if h.mesh == ctx.setup.object && !h.front_face => (h.t, Some(h)),
            Some(h) => (h.t, None),
            None => (f64::INFINITY, None),
        };
        let s = t_exit.min(remaining).max(0.0);
        place_intervals(ctx, ray, &Segment { origin, dir, flux, s, depth, bounce, plane }, out);
        let at_s: [f64; 3] = std::array::from_fn(|c| flux[c] * (-ctx.sigma_t[c] * s).exp());
        let Some(h) = facet.filter(|_| t_exit <= remaining) else {
            (0..3).for_each(|c| res.lost[c] += at_s[c]);
            return res;
        };
        depth += s;
        let n = DVec3::from_array(h.geometric_normal);
        let f = fresnel(dir.dot(n).abs(), ctx.eta, 1.0);
        if f >= 1.0 {
            res.tir += 1;
        }
        let reflected = at_s.map(|x| f * x);
        (0..3).for_each(|c| res.transmitted[c] += at_s[c] - reflected[c]);
        if ctx.object_light
            && f < 1.0
            && let Some(out_dir) = refract(dir, n, ctx.eta, 1.0)
        {
            let exit = origin + dir * t_exit;
            let gone: [f64; 3] = std::array::from_fn(|c| at_s[c] - reflected[c]);
            caustic.extend(land(ctx.setup, exit + n * ctx.eps, out_dir, gone));
        }
        if bounce >= ctx.light_bounces || max3(reflected).is_nan() || max3(reflected) <= 1e-4 * entering {
            (0..3).for_each(|c| res.lost[c] += reflected[c]);
            return res;
        }
        let exit = origin + dir * t_exit;
        dir = reflect(dir, n).normalize();
        origin = exit - n * ctx.eps;
        plane = (exit, n);
        flux = reflected;
        bounce += 1;
    }
}

/// One straight piece of a light ray inside: from `origin` along `dir` over `[0, s]`, entered with
/// `flux` at total depth `depth` after `bounce` reflections.
#[derive(Debug, Clone, Copy)]
struct Segment {
    origin: DVec3,
    dir: DVec3,
    flux: [f64; 3],
    s: f64,
    depth: f64,
    bounce: u32,
    /// Boundary point the segment starts from and its unit outward normal.
    plane: (DVec3, DVec3),
}

/// Intervals of wang2018 Eq. 10 over `[0, s]` of one straight segment:
/// `t_k = −ln(1 − k(1 − e^{−σ s})/n)/σ` with `σ` the smallest `σ_t`.
fn place_intervals(ctx: &LightCtx, ray: &Entering, seg: &Segment, out: &mut Vec<VolumeSample>) {
    let Segment { origin, dir, flux, s, depth, bounce, plane } = *seg;
    if !(s > 0.0 && s.is_finite()) {
        return;
    }
    let sigma = ctx.sigma_min;
    let n = ctx.samples_per_ray;
    let a = extinguished(sigma, s);
    let mut prev = 0.0f64;
    for k in 1..=n {
        let t = if k == n { s } else { free_flight(k as f64 * a / n as f64, sigma).clamp(prev, s) };
        if t > prev {
            out.push(VolumeSample {
                start: origin + dir * prev,
                direction: dir,
                length: t - prev,
                flux: std::array::from_fn(|c| flux[c] * (-ctx.sigma_t[c] * prev).exp()),
                area: ray.tube.at(depth + 0.5 * (prev + t)),
                surface: ray.surface,
                bounce: bounce.min(255) as u8,
                depth: depth + prev,
                plane_point: plane.0,
                plane_normal: plane.1,
                tan_entry: if prev == 0.0 { tan_to(dir, plane.1) } else { 0.0 },
            });
        }
        prev = t;
    }
}

/// `tan θ` of the angle between unit `dir` and the line of unit normal `n` (0 for a degenerate input).
fn tan_to(dir: DVec3, n: DVec3) -> f64 {
    let c = dir.dot(n).abs().min(1.0);
    let t = (1.0 - c * c).sqrt() / c;
    if t.is_finite() { t } else { 0.0 }
}

/// Per surface sample: direct irradiance, volume samples and flux accounting.
#[derive(Debug, Default)]
struct SampleLight {
    direct: [f64; 3],
    volume: Vec<VolumeSample>,
    caustic: Vec<Photon>,
    rays: u64,
    tir: u64,
    entered: [f64; 3],
    lost: [f64; 3],
}

/// The light ray from emitter `e` to the surface point `x` (normal `n`, area `area`), if it is lit:
/// (irradiance, entering ray).
fn light_ray(
    ctx: &LightCtx,
    e: &Emitter,
    jitter: (f64, f64),
    x: DVec3,
    n: DVec3,
    area: f64,
) -> Option<([f64; 3], Option<Entering>)> {
    let to_x = x - e.center;
    let dc = to_x.length();
    if dc.is_nan() || dc <= e.radius {
        return None;
    }
    let (a, b) = (to_x / dc).any_orthonormal_pair();
    let (r, phi) = (e.radius * jitter.0.sqrt(), 2.0 * PI * jitter.1);
    let y = e.center + r * (phi.cos() * a + phi.sin() * b);
    let v = y - x;
    let d = v.length();
    let l = v / d;
    let cos_i = n.dot(l);
    if cos_i.is_nan() || cos_i <= 0.0 {
        return None;
    }
    let o = x + n * ctx.eps;
    if ctx.setup.bvh.occluded(o.to_array(), (y - o).to_array(), 1.0) {
        return None;
    }
    let irr = e.intensity().map(|i| i * cos_i / (d * d));
    let t = 1.0 - fresnel(cos_i, 1.0, ctx.eta);
    let entering = refract(-l, n, 1.0, ctx.eta).map(|dt| {
        let cos_t = dt.dot(n).abs();
        let d_s = ctx.eta * d;
        let d_t = (ctx.eta * d * cos_t * cos_t / (cos_i * cos_i)).max(f64::MIN_POSITIVE);
        Entering {
            point: x,
            normal: n,
            dir: dt,
            flux: irr.map(|e| e * area * t),
            tube: Tube { area_cos: area * cos_t, d_s, d_t },
            surface: 0,
        }
    });
    Some((irr, entering))
}

fn light_sample(ctx: &LightCtx, i: u32, x: DVec3, n: DVec3, area: f64, seed: u64) -> SampleLight {
    let mut out = SampleLight::default();
    for (ei, e) in ctx.setup.emitters.iter().enumerate() {
        let s = StreamKey { table: seed, cell: CELL_EMITTER ^ ((ei as u64) << 32) }.sample(u64::from(i));
        let Some((irr, entering)) = light_ray(ctx, e, (s.uniform(0), s.uniform(1)), x, n, area) else { continue };
        (0..3).for_each(|c| out.direct[c] += irr[c]);
        let Some(mut ray) = entering else { continue };
        if max3(ray.flux) <= 0.0 {
            continue;
        }
        ray.surface = i;
        out.rays += 1;
        (0..3).for_each(|c| out.entered[c] += ray.flux[c]);
        let b = trace(ctx, &ray, &mut out.volume, &mut out.caustic);
        out.tir += b.tir;
        (0..3).for_each(|c| out.lost[c] += b.lost[c]);
    }
    out
}

/// One-bounce diffuse irradiance at `x` (outward normal `n`) from the scene's opaque meshes.
fn indirect_irradiance(
    ctx: &LightCtx,
    object_light: &ObjectLight,
    i: u64,
    x: DVec3,
    n: DVec3,
    opts: &PointOptions,
) -> [f64; 3] {
    let k = opts.indirect_rays;
    if k == 0 || ctx.setup.emitters.is_empty() {
        return [0.0; 3];
    }
    let setup = ctx.setup;
    let (t1, t2) = n.any_orthonormal_pair();
    let s = StreamKey { table: opts.seed, cell: CELL_INDIRECT }.sample(i);
    let (j1, j2) = (s.uniform(0), s.uniform(1));
    let golden = 0.5 * (5f64.sqrt() - 1.0);
    let o = x + n * ctx.eps;
    let mut sum = [0.0; 3];
    for j in 0..k {
        // Jittered strata in cos²θ, a rank-1 lattice in φ (one random shift per sample).
        let u1 = (f64::from(j) + j1) / f64::from(k);
        let u2 = (f64::from(j) * golden + j2).fract();
        let (r, phi) = (u1.sqrt(), 2.0 * PI * u2);
        let d = t1 * (r * phi.cos()) + t2 * (r * phi.sin()) + n * (1.0 - u1).max(0.0).sqrt();
        let Some(h) = setup.bvh.closest_hit(&Ray::new(o.to_array(), d.to_array())) else { continue };
        if !receives(setup, h.mesh) {
            continue;
        }
        let rho = setup.albedo_of(h.mesh);
        let mut nh = DVec3::from_array(h.geometric_normal);
        if nh.dot(d) > 0.0 {
            nh = -nh;
        }
        let p = o + d * h.t;
        let po = p + nh * ctx.eps;
        let e_obj = object_light.irradiance(p, nh, true);
        (0..3).for_each(|ch| sum[ch] += rho[ch] / PI * e_obj[ch]);
        for e in setup.emitters {
            let v = e.center - po;
            let de = v.length();
            if de.is_nan() || de <= e.radius {
                continue;
            }
            let le = v / de;
            let c = nh.dot(le);
            if c.is_nan() || c <= 0.0 || setup.bvh.occluded(po.to_array(), le.to_array(), de - e.radius) {
                continue;
            }
            let i_e = e.intensity();
            (0..3).for_each(|ch| sum[ch] += rho[ch] / PI * i_e[ch] * c / (de * de));
        }
    }
    sum.map(|v| PI * v / f64::from(k))
}
