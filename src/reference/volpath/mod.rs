//! Brute-force volumetric path tracer: surface irradiance and camera-ray radiance with full
//! volume-to-surface transport.
//!
//! **Input → output.** A [`Scene`](crate::scene::Scene), its [`SceneBvh`](crate::scene::bvh::SceneBvh) and [`VolPathOptions`](crate::reference::volpath::VolPathOptions), and either
//! - [`SurfacePoint`](crate::reference::volpath::SurfacePoint)s → ([`irradiance`](crate::reference::volpath::irradiance)) per point an [`Estimate`](crate::reference::volpath::Estimate) of the irradiance
//!   `E(x) = ∫_{H²} L_i(x, ω) cos θ dω` \[W/m²\] per RGB channel (the quantity dubouchet2019's
//!   lightmap stores), or
//! - [`CameraRay`](crate::reference::volpath::CameraRay)s → ([`radiance`](crate::reference::volpath::radiance)) per ray an [`Estimate`](crate::reference::volpath::Estimate) of the radiance `L(o, −d)`
//!   \[W/(m²·sr)\] arriving at the origin `o` against the direction `d`,
//!
//! each with its standard error, and [`VolPathStats`](crate::reference::volpath::VolPathStats). It is the reference the lightmap bake
//! (issue 6) and the translucent renderer (issue 7) are judged against, and shares no transport code
//! with them.
//!
//! **What it implements** (details in the submodules):
//! - `path`: unidirectional path tracing from the receiver or the eye with next-event estimation to
//!   every light at every vertex (receiver, Lambertian surfaces, medium collisions) plus equiangular
//!   sampling of point and spot lights along every leg through a medium, HG phase sampling
//!   ([`crate::physics::hg`]), cosine-sampled bounces, emissive meshes gathered both by next-event
//!   estimation and by unidirectional hits with balance-heuristic MIS, hero-channel spectral MIS for
//!   chromatic media, smooth Fresnel dielectrics, index-matched boundaries passed through, Russian
//!   roulette; both entry points run the same path loop, only vertex 0 differs;
//! - `flight`: free-flight sampling by exact analytic inversion of the optical depth (homogeneous and
//!   iser2018 exponential height fog), exact shadow-ray transmittance
//!   ([`crate::scene::bvh::optical_thickness`]);
//! - `lights`: next-event sampling of every light kind in the scene's radiometric convention, and
//!   ray intersection of the analytic area lights.
//!
//! **Camera rays.** The path starts at the ray's origin along its direction (the first leg is given,
//! not sampled; the eye gathers nothing itself). Along that leg the medium is traced as on every
//! other leg (free flight, equiangular samples of point/spot lights with MIS, hero-channel MIS); its
//! first event — a Lambertian hit, a medium collision or a dielectric interface — is vertex 1 and is
//! treated as the receiver of [`irradiance`](crate::reference::volpath::irradiance) would be treated at vertex 0 (so `max_depth` and `rr_depth`
//! count the same events after it). What the ray sees directly:
//! - the front side of an emissive mesh: its radiance, attenuated by the media before it;
//! - the emitting side of a rect or disk light, or a sphere light from outside: its radiance times
//!   the transmittance to it, gathered by a deterministic connection (analytic lights are not
//!   geometry: they do not occlude, and the ray continues through them). The same holds after every
//!   specular (Fresnel) event, where no next-event sample can produce the path; on legs leaving a
//!   diffuse or medium vertex they are reached by next-event estimation alone;
//! - nothing where it escapes (no sky, no environment: radiance 0); point, spot and directional lights
//!   are never seen directly (delta lights), only their effect on surfaces and media.
//!
//! What each option means for a camera ray:
//! - `max_depth = 0`: the first event only gathers. With `media = false` this is classic direct
//!   lighting at the first surface hit: its emission (emissive meshes, as above) plus next-event
//!   estimation to every light (MIS-paired with emissive meshes hit by one cosine-sampled ray) —
//!   an HDR colour G-buffer without fog. With `media = true` the same picture with fog: attenuation
//!   along the ray and single scattering of every light along it, with the surface behind lit
//!   through the fog (shadow-ray transmittance). `max_depth = n` adds `n` further events (diffuse
//!   bounces, multiple scattering, specular events: a dielectric slab needs two), so large values
//!   with `media = true` give fog with single and multiple scattering and global illumination.
//! - `surface_bounces = 0`: the surfaces the camera ray itself meets (its first Lambertian hit,
//!   also behind index-matched boundaries and Fresnel interfaces on that first flight) are still
//!   shaded; light reflected or transmitted by any later surface is ignored. `surface_bounces = n`
//!   lets `n` later Lambertian reflections through (`u32::MAX`: all).
//! - `eye_surfaces = false`: that first Lambertian hit absorbs instead of being shaded: the image is
//!   the light scattered by the media toward the eye (plus emitters seen directly), e.g. what a
//!   volumetric effect adds on top of a surface renderer.
//! - `media = false`: media are ignored (vacuum), as for irradiance.
//! - Russian roulette survival is measured against a throughput of 1 (not `π` as at a receiver).
//!
//! **Determinism.** Path `s` of point (or ray) `i` draws its numbers from
//! `StreamKey { table: hash(seed), cell: i }.sample(s)` only, points run in parallel and each point's
//! samples are accumulated in order, so results are bit-identical for any rayon thread count.
//!
//! **Robustness.** A point with a zero or non-finite normal or position, and a camera ray with a zero
//! or non-finite origin or direction, get 0 (and trace no paths). Lights of zero power are skipped.
//! A point light's `1/d²` is clamped at `d = 1e-4 m` ([`lights::D_MIN`](crate::reference::volpath::lights::D_MIN)). A ray escaping into
//! an unbounded medium ends (its transmittance to infinity is 0 unless the fog thins out; nothing is
//! emitted at infinity). Non-finite path samples are dropped and counted in
//! [`VolPathStats::nonfinite`](crate::reference::volpath::VolPathStats::nonfinite) (never averaged in).
//!
//! **Limitations.** Point and spot lights are sampled from media both at free-flight collisions and
//! equiangularly along every leg (Kulla & Fajardo 2012, balance heuristic), which removes their
//! `1/r²` singularity; next-event samples of the analytic area lights (rect, disk, sphere) from a
//! collision very close to the light keep a heavy tail (finite mean, standard errors optimistic
//! there); emissive meshes have MIS and no such tail. Surfaces are Lambertian with the geometric
//! normal (roughness, shading normals and textures ignored); directional lights with `angle > 0` are
//! treated as delta directions. Next-event rays do not cross refractive (`ior ≠ 1`) boundaries. Camera
//! rays are pinhole rays: no lens, no pixel filter (the caller integrates over a pixel if it wants).

pub mod flight;
pub mod lights;
mod path;

#[cfg(test)]
mod tests;
#[cfg(test)]
mod tests_camera;

use std::time::Instant;

use glam::DVec3;
use rayon::prelude::*;

use crate::physics::rng::StreamKey;
use crate::scene::Scene;
use crate::scene::bvh::SceneBvh;

/// A surface point whose irradiance is wanted.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SurfacePoint {
    /// Position \[m\], world space.
    pub position: [f64; 3],
    /// Unit normal on the side light arrives on (normalised again here).
    pub normal: [f64; 3],
}

/// A camera ray: the radiance arriving at `origin` from direction `−direction` is wanted.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CameraRay {
    /// Eye position \[m\], world space.
    pub origin: [f64; 3],
    /// Unit viewing direction, pointing away from the eye into the scene (normalised again here).
    pub direction: [f64; 3],
}

/// How much to trace and which transport to include.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct VolPathOptions {
    /// Paths per point or camera ray.
    pub samples: u32,
    /// Most vertices (medium collisions, diffuse bounces, specular events) per path after the receiver,
    /// or after a camera ray's first event (0: direct lighting there; module doc, "Camera rays").
    pub max_depth: u32,
    /// Vertex index from which Russian roulette applies (counted like `max_depth`).
    pub rr_depth: u32,
    /// Seed, hashed into the stream key.
    pub seed: u64,
    /// Most Lambertian reflections per path after vertex 0, not counting the surface a camera ray itself
    /// meets: `u32::MAX` all, `0` light reflected or transmitted by surfaces is ignored (emitters and
    /// media only). Once used up, flights end at the next surface after gathering its emission.
    pub surface_bounces: u32,
    /// `false`: the Lambertian surface a camera ray itself meets absorbs (the path ends there, its
    /// emission still gathered), so the image holds the light the media scatter toward the eye and
    /// what emitters show directly; `true`: it is shaded. Irrelevant for receivers.
    pub eye_surfaces: bool,
    /// `false`: media are ignored (vacuum).
    pub media: bool,
}

impl Default for VolPathOptions {
    fn default() -> Self {
        VolPathOptions {
            samples: 1024,
            max_depth: 64,
            rr_depth: 8,
            seed: 0,
            surface_bounces: u32::MAX,
            eye_surfaces: true,
            media: true,
        }
    }
}

/// Irradiance \[W/m²\] or radiance \[W/(m²·sr)\] per channel and the standard error of that mean.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Estimate {
    /// Mean over paths.
    pub mean: [f64; 3],
    /// Standard error of the mean (sample standard deviation / √n).
    pub stderr: [f64; 3],
}

/// What a run did.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct VolPathStats {
    /// Paths traced.
    pub paths: u64,
    /// BVH queries (closest hits, shadow rays, media-segment queries).
    pub rays: u64,
    /// Non-finite path samples dropped.
    pub nonfinite: u64,
    /// Wall time \[ms\].
    pub ms: f64,
}

/// Per-channel running mean and sum of squared deviations (Welford), accumulated in sample order.
#[derive(Debug, Clone, Copy, Default)]
struct Running {
    n: u64,
    mean: [f64; 3],
    m2: [f64; 3],
}

impl Running {
    fn push(&mut self, x: [f64; 3]) {
        self.n += 1;
        let n = self.n as f64;
        for (c, &xc) in x.iter().enumerate() {
            let d = xc - self.mean[c];
            self.mean[c] += d / n;
            self.m2[c] += d * (xc - self.mean[c]);
        }
    }

    fn estimate(&self) -> Estimate {
        let n = self.n as f64;
        let stderr = if self.n > 1 { self.m2.map(|m| (m.max(0.0) / ((n - 1.0) * n)).sqrt()) } else { [0.0; 3] };
        Estimate { mean: self.mean, stderr }
    }
}

/// The stream-key table word for `seed` (SplitMix64 finaliser, so nearby seeds give unrelated streams).
fn seed_hash(seed: u64) -> u64 {
    let mut z = seed.wrapping_add(0x9e37_79b9_7f4a_7c15) ^ 0x766f_6c70_6174_6872; // "volpathr"
    z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    z ^ (z >> 31)
}

/// Irradiance at each point (module doc), in parallel over points on the current rayon pool.
/// `scene` must be the scene `bvh` was built from.
pub fn irradiance(
    scene: &Scene,
    bvh: &SceneBvh,
    points: &[SurfacePoint],
    opts: &VolPathOptions,
) -> (Vec<Estimate>, VolPathStats) {
    estimate_all(scene, bvh, points, opts, |pt| {
        let x = DVec3::from_array(pt.position);
        let n = lights::unit(pt.normal)?;
        x.is_finite().then_some(path::Start::Receiver { x, n })
    })
}

/// Radiance \[W/(m²·sr)\] per channel arriving at each ray's origin from `−direction` (module doc,
/// "Camera rays"), in parallel over rays on the current rayon pool. Ray `i` uses the stream key
/// `(hash(seed), i)` exactly as point `i` of [`irradiance`]. `scene` must be the scene `bvh` was built
/// from.
pub fn radiance(
    scene: &Scene,
    bvh: &SceneBvh,
    rays: &[CameraRay],
    opts: &VolPathOptions,
) -> (Vec<Estimate>, VolPathStats) {
    estimate_all(scene, bvh, rays, opts, |r| {
        let origin = DVec3::from_array(r.origin);
        let dir = lights::unit(r.direction)?;
        origin.is_finite().then_some(path::Start::Camera { origin, dir })
    })
}

/// The estimator shared by both entry points: `opts.samples` paths from `start(item)` per item (an
/// estimate of 0 with no paths when it gives `None`), non-finite samples dropped and counted.
fn estimate_all<T: Sync>(
    scene: &Scene,
    bvh: &SceneBvh,
    items: &[T],
    opts: &VolPathOptions,
    start: impl Fn(&T) -> Option<path::Start> + Sync,
) -> (Vec<Estimate>, VolPathStats) {
    let start_time = Instant::now();
    let ctx = path::Context::new(scene, bvh, opts);
    let table = seed_hash(opts.seed);
    let per_item: Vec<(Estimate, u64, u64, u64)> = items
        .par_iter()
        .enumerate()
        .map(|(i, item)| {
            let key = StreamKey { table, cell: i as u64 };
            let Some(from) = start(item) else {
                return (Estimate { mean: [0.0; 3], stderr: [0.0; 3] }, 0, 0, 0);
            };
            let mut acc = Running::default();
            let (mut rays, mut bad) = (0u64, 0u64);
            for s in 0..opts.samples {
                let v = ctx.trace(from, key.sample(u64::from(s)), &mut rays);
                if v.iter().all(|c| c.is_finite()) {
                    acc.push(v);
                } else {
                    bad += 1;
                    acc.push([0.0; 3]);
                }
            }
            (acc.estimate(), u64::from(opts.samples), rays, bad)
        })
        .collect();
    let mut stats = VolPathStats::default();
    let estimates = per_item
        .into_iter()
        .map(|(e, p, r, b)| {
            stats.paths += p;
            stats.rays += r;
            stats.nonfinite += b;
            e
        })
        .collect();
    stats.ms = start_time.elapsed().as_secs_f64() * 1e3;
    (estimates, stats)
}
