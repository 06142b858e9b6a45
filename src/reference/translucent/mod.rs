//! Brute-force volumetric path tracer for a homogeneous medium inside a smooth dielectric mesh: the
//! independent ground truth the point-based renderer ([`crate::stages::translucent::render`]) is judged against.
//!
//! **Input → output.** A [`Setup`] (scene, BVH, translucent mesh, its [`crate::render::dielectric::Material`], spherical
//! [`Emitter`]s), a [`ViewCamera`] and [`ReferenceOptions`] → a [`ReferenceImage`]: per pixel the mean
//! radiance \[W/(m²·sr)\] split by the number of scattering events in the medium (none, one, two, three
//! or more), the variance of the mean of the total, and whether the pixel sees the object first. It
//! shares no transport code with `points`, `octree` or `render`.
//!
//! **Camera rays.** Pinhole rays from `camera.position` through pixel centres
//! ([`ViewCamera::pixel_dir`]), no pixel filter. A camera inside the object starts in the medium (decided
//! by the facing of the first hit on the object along the pixel's ray).
//!
//! **Surfaces.** The object mesh is a smooth dielectric with its geometric normal (`front_face` = the
//! path enters): reflect with probability `F` ([`fresnel`], total internal reflection included), else
//! refract ([`refract`]). Radiance convention: a camera path crossing from index `η_i` into `η_t` has
//! its throughput multiplied by `(η_i/η_t)²` (radiance of the traced direction scales by `η²`), so on a
//! path that enters and leaves the factors cancel and an emitter seen straight through a slab without a
//! medium shows `L (1 − F₁)(1 − F₂)` per transmission pair. Every other mesh is opaque Lambertian with
//! albedo [`Setup::albedo_of`]: next-event estimation to every emitter (uniform in the cone the sphere
//! subtends, shadow ray with [`crate::scene::bvh::SceneBvh::occluded_ray`]: every mesh, the object
//! included, occludes, so shadow rays never cross the refractive boundary), then a cosine-sampled
//! bounce. A Lambertian vertex inside the medium (an opaque mesh within the object) does no next-event
//! estimation; its bounce gathers the emitters it meets instead.
//!
//! **Emitters** are not geometry: they never occlude and paths pass through them. A flight gathers the
//! radiance of every emitter whose front surface it reaches before its end (origin outside the sphere),
//! unless the flight leaves a Lambertian vertex that did next-event estimation (no specular event or
//! medium vertex in between), which already counted those paths. Flights leaving the object after a
//! medium vertex do gather: no next-event estimation crosses a refractive boundary.
//!
//! **Medium** (homogeneous, `σ_t`, albedo per channel, HG `g` from [`crate::physics::hg`]). Free flights
//! by one-sample spectral MIS: a hero channel `h` is picked uniformly and a distance sampled with
//! `σ_t,h`; channel `k` is weighted `T_k σ_t,k / mean_j(T_j σ_t,j)` at a collision (times the
//! scattering albedo `α_k`) and `T_k / mean_j T_j` where the flight passes an emitter or reaches the
//! boundary (ratios formed relative to the smallest optical depth, so they never overflow or divide 0
//! by 0). A medium with albedo 0 in every channel is crossed deterministically with weight `T_k` (no
//! free-flight sampling: nothing scatters). At a collision the path continues in an HG-sampled
//! direction (weight 1) and, with probability `guide`, also makes a *guided connection*: a direction from
//! a uniform cone about a light-guided direction toward one emitter, picked with probability
//! ∝ `mean intensity / d²`; the guided direction aims at the point where the straight line toward the
//! emitter's centre leaves the object, refracts the direction from there to the centre into the medium,
//! and repeats this fixed point [`GUIDE_ITERATIONS`] times (an emitter inside the object, or a line
//! blocked by another mesh, keeps the straight direction); the half-angle is [`CONE_MARGIN`] times the
//! emitter's apparent angular radius over the unfolded path length, clamped to
//! \[[`CONE_MIN`], [`CONE_MAX`]\] rad. The connection gathers every emitter on its flight inside (exact
//! transmittance `T_k`) and, through the transmitted branch `(1 − F) η²` of the boundary it reaches,
//! on the flight outside. The HG continuation gathers the same paths (emitters met before any further
//! event, or after exactly one refraction out of the object); both are weighted by the balance
//! heuristic with the exact densities `phase(ω)` and `guide · p_guide(ω)` (`p_guide` the mixture of
//! every emitter's cone), so the estimate is unbiased whatever the guide directions are. Emitters whose
//! sphere contains the vertex have no cone. This replaces a one-sample mixture of the continuation
//! direction, whose weights `phase/pdf_mix ≤ 1/(1 − guide)` multiply along deep multiple-scattering
//! paths and raise the variance geometrically with the number of vertices. `guide` is clamped to
//! \[0, 0.99\], NaN to 0; 0 is plain HG path tracing.
//!
//! **Components.** Each path counts its medium collisions; a contribution gathered after `n` of them is
//! added to component `min(n, 3)` (0: reflections, see-through and the rest of the scene; 1 single;
//! 2 double; 3 multiple).
//!
//! **Termination.** At most `max_events` vertices (surface events and collisions) per path; the flight
//! leaving the last one still gathers. Russian roulette from the 9th vertex on with survival
//! `min(1, max_c β_c)` (throughput relative to the camera's 1).
//!
//! **Not modelled.** Other media of the scene (fog, other bounded media) are ignored (vacuum outside the
//! object); the scene's emissive meshes and non-spherical lights are not emitters here (only
//! [`Setup::emitters`]); nothing is emitted at infinity.
//!
//! **Determinism and robustness.** Path `s` of pixel `i` draws from
//! `StreamKey { table: hash(seed), cell: i }.sample(s)` only; rows run in parallel (rayon) and each
//! pixel's paths are accumulated in order, so images are bit-identical for any thread count. A path
//! whose contribution is not finite is dropped and counted in [`ReferenceImage::nonfinite`]; a pixel
//! whose ray has a non-finite or zero origin or direction gets 0 and all its paths count as non-finite.
//! An invalid material ([`crate::render::dielectric::Material::check`]) gives an image of zeros with every path counted as
//! non-finite. Invalid emitters (non-finite, radius ≤ 0, negative radiance) are ignored.

use std::f64::consts::PI;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Instant;

use glam::DVec3;
use rayon::prelude::*;

use crate::physics::hg;
use crate::physics::rng::{Draws, StreamKey};
use crate::reference::frame::frame;
use crate::render::ViewCamera;
use crate::render::dielectric::{Emitter, Material, Setup};
use crate::render::optics::{fresnel, reflect, refract};
use crate::scene::bvh::{Hit, Ray};

/// Fixed-point iterations of the light-guided direction through the refractive boundary.
pub const GUIDE_ITERATIONS: usize = 3;
/// Guide cone half-angle as a multiple of the emitter's apparent angular radius. A curved boundary
/// magnifies the emitter seen from inside, and what the cone misses only the HG continuation finds
/// (fireflies): on the bundled sphere at 2 × 1024 paths the variance of the mean was, for margins 2 / 4 / 8,
/// Wax 5.1e-2 / 2.0e-2 / 2.6e-2 and Skin 4.7e-3 / 2.2e-3 / 6.4e-3 (normalised; Oil 4.6e-2 for 2 and 4).
pub const CONE_MARGIN: f64 = 4.0;
/// Smallest guide cone half-angle \[rad\].
pub const CONE_MIN: f64 = 0.01;
/// Largest guide cone half-angle \[rad\].
pub const CONE_MAX: f64 = 0.5;
/// Vertices before Russian roulette starts.
const RR_START: u32 = 8;

/// How much to trace.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ReferenceOptions {
    /// Paths per pixel.
    pub samples: u32,
    /// Cap on vertices (surface events and medium collisions) per path.
    pub max_events: u32,
    /// Probability of a guided connection at a medium vertex (module doc), in \[0, 0.99\].
    pub guide: f64,
    /// Seed, hashed into the stream key.
    pub seed: u64,
}

impl Default for ReferenceOptions {
    fn default() -> Self {
        ReferenceOptions { samples: 64, max_events: 10_000, guide: 0.5, seed: 0 }
    }
}

/// The rendered image, split by scattering order.
#[derive(Debug, Clone, PartialEq)]
pub struct ReferenceImage {
    /// Pixels per row.
    pub width: usize,
    /// Rows.
    pub height: usize,
    /// Per component, per pixel mean radiance \[W/(m²·sr)\]: index 0 = paths with no scattering event in
    /// the medium (reflections, see-through, the rest of the scene), 1 = exactly one (single), 2 = exactly
    /// two (double), 3 = three or more (multiple).
    pub components: [Vec<[f64; 3]>; 4],
    /// Per pixel variance of the mean of the total (sample variance / n) per channel.
    pub variance: Vec<[f64; 3]>,
    /// Whether the pixel's primary ray hits the translucent object first.
    pub object: Vec<bool>,
    /// Paths traced.
    pub paths: u64,
    /// Paths dropped (non-finite contribution, invalid ray or material).
    pub nonfinite: u64,
    /// Wall time \[s\].
    pub seconds: f64,
}

impl ReferenceImage {
    /// Sum of the four components per pixel.
    pub fn total(&self) -> Vec<[f64; 3]> {
        (0..self.width * self.height)
            .map(|i| {
                let mut t = [0.0; 3];
                for comp in &self.components {
                    if let Some(v) = comp.get(i) {
                        for c in 0..3 {
                            t[c] += v[c];
                        }
                    }
                }
                t
            })
            .collect()
    }
}

/// The stream-key table word for `seed` (SplitMix64 finaliser).
fn seed_hash(seed: u64) -> u64 {
    let mut z = seed.wrapping_add(0x9e37_79b9_7f4a_7c15) ^ 0x7472_616e_736c_7563; // "translucent"
    z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    z ^ (z >> 31)
}

/// Renders `camera`'s view of `setup` (module doc). `progress(rows done)` is called after each row, possibly
/// from worker threads. Runs on the current rayon pool.
pub fn render(
    setup: &Setup,
    camera: &ViewCamera,
    opts: &ReferenceOptions,
    progress: &(dyn Fn(u64) + Sync),
) -> ReferenceImage {
    let start = Instant::now();
    let (w, h) = (camera.width, camera.height);
    let n = w.saturating_mul(h);
    let mut img = ReferenceImage {
        width: w,
        height: h,
        components: std::array::from_fn(|_| vec![[0.0; 3]; n]),
        variance: vec![[0.0; 3]; n],
        object: vec![false; n],
        paths: 0,
        nonfinite: 0,
        seconds: 0.0,
    };
    if setup.material.check().is_err() {
        img.nonfinite = n as u64 * u64::from(opts.samples);
        progress(h as u64);
        img.seconds = start.elapsed().as_secs_f64();
        return img;
    }
    let tracer = Tracer::new(setup, opts);
    let table = seed_hash(opts.seed);
    let done = AtomicU64::new(0);
    let rows: Vec<Vec<PixelResult>> = (0..h)
        .into_par_iter()
        .map(|y| {
            let row = (0..w)
                .map(|x| {
                    let key = StreamKey { table, cell: (y * w + x) as u64 };
                    tracer.pixel(camera.position, camera.pixel_dir(x, y), key, opts.samples)
                })
                .collect();
            progress(done.fetch_add(1, Ordering::Relaxed) + 1);
            row
        })
        .collect();
    for (i, p) in rows.into_iter().flatten().enumerate() {
        for (k, comp) in img.components.iter_mut().enumerate() {
            comp[i] = p.components[k];
        }
        img.variance[i] = p.variance;
        img.object[i] = p.object;
        img.paths += p.paths;
        img.nonfinite += p.nonfinite;
    }
    img.seconds = start.elapsed().as_secs_f64();
    img
}

/// One pixel's estimate.
#[derive(Debug, Clone, Copy, Default)]
struct PixelResult {
    components: [[f64; 3]; 4],
    variance: [f64; 3],
    object: bool,
    paths: u64,
    nonfinite: u64,
}

/// A guide cone of one emitter at one medium vertex.
#[derive(Debug, Clone, Copy)]
struct Cone {
    /// Selection probability among the cones.
    prob: f64,
    axis: DVec3,
    cos_max: f64,
    /// `1 / (2π (1 − cos_max))`.
    pdf: f64,
}

/// The state of one camera path.
struct PathState {
    o: DVec3,
    d: DVec3,
    beta: [f64; 3],
    inside: bool,
    scatters: u32,
    /// The current flight leaves a Lambertian vertex that did next-event estimation.
    nee_done: bool,
    /// Surface the current flight starts on (skipped by the next closest-hit query).
    last: Option<(usize, usize)>,
    t_min: f64,
    /// Where the gathers of the current flights stand in the MIS pair with the guided connections.
    mis: Mis,
    out: [[f64; 3]; 4],
}

/// MIS state of the flights since the last vertex (module doc, "Medium").
#[derive(Debug, Clone, Copy)]
enum Mis {
    /// Gathers count fully (no guided connection can produce them).
    One,
    /// The path left the medium vertex `x` (arriving along `d_in`) along `w` by HG sampling and has had
    /// no event since (`exited = false`) or exactly one refraction out of the object (`exited = true`).
    /// `weight` caches `phase / (phase + guide · p_guide)` once computed.
    Pending { x: DVec3, d_in: DVec3, w: DVec3, exited: bool, weight: Option<f64> },
}

impl PathState {
    fn add(&mut self, v: [f64; 3]) {
        let slot = &mut self.out[self.scatters.min(3) as usize];
        for c in 0..3 {
            slot[c] += v[c];
        }
    }
}

/// Prepared, read-only rendering context.
struct Tracer<'a> {
    setup: &'a Setup<'a>,
    mat: Material,
    emitters: Vec<Emitter>,
    guide: f64,
    max_events: u32,
    /// Some channel scatters (otherwise media are crossed with their transmittance).
    scattering: bool,
}

/// Self-intersection guard \[m\] at point `p`.
fn eps(p: DVec3) -> f64 {
    1e-6 * p.abs().max_element().max(1.0)
}

/// The unit direction with cosine `mu` to the unit `axis` and azimuth `phi`.
fn around(axis: DVec3, mu: f64, phi: f64) -> DVec3 {
    let (t, b) = frame(axis);
    let s = (1.0 - mu * mu).max(0.0).sqrt();
    (mu * axis + s * (phi.cos() * t + phi.sin() * b)).normalize()
}

/// A uniform direction in the cone of `1 − cos θ_max = one_minus_cos` about `axis`.
fn sample_cone(axis: DVec3, one_minus_cos: f64, u: f64, v: f64) -> DVec3 {
    around(axis, 1.0 - u * one_minus_cos, 2.0 * PI * v)
}

impl<'a> Tracer<'a> {
    fn new(setup: &'a Setup<'a>, opts: &ReferenceOptions) -> Self {
        let emitters = setup
            .emitters
            .iter()
            .filter(|e| {
                e.center.is_finite()
                    && e.radius > 0.0
                    && e.radius.is_finite()
                    && e.radiance.iter().all(|&l| l >= 0.0 && l.is_finite())
                    && e.radiance.iter().any(|&l| l > 0.0)
            })
            .copied()
            .collect();
        let guide = if opts.guide.is_nan() { 0.0 } else { opts.guide.clamp(0.0, 0.99) };
        Tracer {
            setup,
            mat: setup.material,
            emitters,
            guide,
            max_events: opts.max_events,
            scattering: setup.material.albedo.iter().any(|&a| a > 0.0),
        }
    }

    /// Closest hit along `o + t d`, `t > t_min`, skipping the surface the ray starts on.
    fn closest(&self, o: DVec3, d: DVec3, t_min: f64, last: Option<(usize, usize)>) -> Option<Hit> {
        let mut ray = Ray { origin: o.to_array(), direction: d.to_array(), t_min, t_max: f64::INFINITY };
        for _ in 0..4 {
            let h = self.setup.bvh.closest_hit(&ray)?;
            if Some((h.mesh, h.triangle)) != last {
                return Some(h);
            }
            ray.t_min = h.t;
        }
        None
    }

    /// The pixel's primary ray: whether the object is the first thing it meets (before any emitter),
    /// and whether the camera is inside the object.
    fn classify(&self, o: DVec3, d: DVec3) -> (bool, bool) {
        let first = self.closest(o, d, 0.0, None);
        let t_first = first.map_or(f64::INFINITY, |h| h.t);
        let emitter_first = self
            .emitters
            .iter()
            .any(|e| (o - e.center).length() > e.radius && e.intersect(o, d, 0.0).is_some_and(|t| t < t_first));
        let object = first.is_some_and(|h| h.mesh == self.setup.object) && !emitter_first;
        // Walk the hits along the ray to the first one on the object: leaving it means we start inside.
        let mut t_min = 0.0;
        let mut inside = false;
        for _ in 0..1024 {
            let ray = Ray { origin: o.to_array(), direction: d.to_array(), t_min, t_max: f64::INFINITY };
            let Some(h) = self.setup.bvh.closest_hit(&ray) else { break };
            if h.mesh == self.setup.object {
                inside = !h.front_face;
                break;
            }
            if h.t.is_nan() || h.t <= t_min {
                break;
            }
            t_min = h.t;
        }
        (object, inside)
    }

    fn pixel(&self, o: DVec3, d: DVec3, key: StreamKey, samples: u32) -> PixelResult {
        let mut r = PixelResult::default();
        let d = d.try_normalize().filter(|_| o.is_finite());
        let Some(d) = d else {
            r.nonfinite = u64::from(samples);
            return r;
        };
        let (object, inside) = self.classify(o, d);
        r.object = object;
        let mut sums = [[0.0; 3]; 4];
        let (mut n, mut mean, mut m2) = (0u64, [0.0; 3], [0.0; 3]);
        let mut scratch = Vec::with_capacity(self.emitters.len());
        for s in 0..samples {
            r.paths += 1;
            let mut draws = Draws::new(key.sample(u64::from(s)));
            let c = self.trace(o, d, inside, &mut draws, &mut scratch);
            if c.iter().flatten().any(|v| !v.is_finite()) {
                r.nonfinite += 1;
                continue;
            }
            n += 1;
            let nf = n as f64;
            for k in 0..4 {
                for ch in 0..3 {
                    sums[k][ch] += c[k][ch];
                }
            }
            for ch in 0..3 {
                let x = c[0][ch] + c[1][ch] + c[2][ch] + c[3][ch];
                let delta = x - mean[ch];
                mean[ch] += delta / nf;
                m2[ch] += delta * (x - mean[ch]);
            }
        }
        if n > 0 {
            let nf = n as f64;
            r.components = sums.map(|s| s.map(|v| v / nf));
            if n > 1 {
                r.variance = m2.map(|m| m.max(0.0) / ((nf - 1.0) * nf));
            }
        }
        r
    }

    /// One camera path from `o` along `d`; contributions per component.
    fn trace(&self, o: DVec3, d: DVec3, inside: bool, draws: &mut Draws, scratch: &mut Vec<Cone>) -> [[f64; 3]; 4] {
        let mut st = PathState {
            o,
            d,
            beta: [1.0; 3],
            inside,
            scatters: 0,
            nee_done: false,
            last: None,
            t_min: 0.0,
            mis: Mis::One,
            out: [[0.0; 3]; 4],
        };
        let mut events = 0u32;
        loop {
            let hit = self.closest(st.o, st.d, st.t_min, st.last);
            let t_hit = hit.map_or(f64::INFINITY, |h| h.t);
            let collision = if st.inside {
                self.medium_flight(&mut st, t_hit, draws)
            } else {
                if !st.nee_done {
                    self.gather(&mut st, t_hit, |_| [1.0; 3]);
                }
                None
            };
            if collision.is_none() && hit.is_none() {
                break; // escaped (or an open mesh let the path out of the medium)
            }
            if st.beta.iter().all(|&b| b <= 0.0) || events >= self.max_events {
                break;
            }
            events += 1;
            if events > RR_START {
                let q = st.beta.iter().fold(0.0f64, |m, &b| m.max(b)).min(1.0);
                if q <= 0.0 || draws.draw() >= q {
                    break;
                }
                st.beta = st.beta.map(|b| b / q);
            }
            if let Some(t) = collision {
                let x = st.o + t * st.d;
                st.scatters += 1;
                if self.guide > 0.0 && draws.draw() < self.guide {
                    self.connect(&mut st, x, draws, scratch);
                }
                let (u, v) = (draws.draw(), draws.draw());
                let w = around(st.d, hg::sample_mu(u, self.mat.g), 2.0 * PI * v);
                if !w.is_finite() {
                    break;
                }
                st.mis = if self.guide > 0.0 {
                    Mis::Pending { x, d_in: st.d, w, exited: false, weight: None }
                } else {
                    Mis::One
                };
                st.o = x;
                st.d = w;
                st.last = None;
                st.t_min = 0.0;
                st.nee_done = false;
                continue;
            }
            let Some(h) = hit else { break };
            let p = st.o + h.t * st.d;
            let n = DVec3::from_array(h.geometric_normal);
            if h.mesh == self.setup.object {
                let ior = self.mat.ior;
                let (eta_i, eta_t) = if h.front_face { (1.0, ior) } else { (ior, 1.0) };
                let f = fresnel(st.d.dot(n).abs(), eta_i, eta_t);
                let refracted = if draws.draw() < f { None } else { refract(st.d, n, eta_i, eta_t) };
                match refracted {
                    Some(t) => {
                        let s = (eta_i / eta_t) * (eta_i / eta_t);
                        st.beta = st.beta.map(|b| b * s);
                        st.d = t;
                        st.inside = h.front_face;
                        st.mis = match st.mis {
                            Mis::Pending { exited: false, x, d_in, w, weight } if !h.front_face => {
                                Mis::Pending { x, d_in, w, exited: true, weight }
                            }
                            _ => Mis::One,
                        };
                    }
                    None => {
                        st.d = reflect(st.d, n).normalize();
                        st.inside = !h.front_face;
                        st.mis = Mis::One;
                    }
                }
                st.nee_done = false;
            } else {
                st.mis = Mis::One;
                let k = self.setup.albedo_of(h.mesh);
                let side = if st.d.dot(n) < 0.0 { n } else { -n };
                if st.inside {
                    st.nee_done = false;
                } else {
                    self.next_event(&mut st, p, side, k, draws);
                    st.nee_done = true;
                }
                let (u, v) = (draws.draw(), draws.draw());
                let mu = u.sqrt();
                st.d = around(side, mu, 2.0 * PI * v);
                st.beta = [0, 1, 2].map(|c| st.beta[c] * k[c]);
            }
            st.o = p;
            st.last = Some((h.mesh, h.triangle));
            st.t_min = eps(p);
        }
        st.out
    }

    /// Gathers every emitter whose front surface the flight `st.o + t st.d`, `t < t_end`, reaches, with
    /// the per-channel weight `w(t)`.
    fn gather(&self, st: &mut PathState, t_end: f64, w: impl Fn(f64) -> [f64; 3]) {
        let mut mis = None;
        for e in &self.emitters {
            if (st.o - e.center).length() <= e.radius {
                continue;
            }
            if let Some(t) = e.intersect(st.o, st.d, 0.0).filter(|&t| t < t_end) {
                let wt = w(t);
                let m = *mis.get_or_insert_with(|| self.mis_weight(&mut st.mis));
                let v = [0, 1, 2].map(|c| st.beta[c] * wt[c] * e.radiance[c] * m);
                st.add(v);
            }
        }
    }

    /// Per-channel weights `x_k e^{−(τ_k − τ_min)} / mean_j(x_j e^{−(τ_j − τ_min)})` at distance `t`.
    fn mis_ratio(&self, t: f64, x: [f64; 3]) -> [f64; 3] {
        let tau = self.mat.sigma_t.map(|s| s * t);
        let m = tau[0].min(tau[1]).min(tau[2]);
        let r = [0, 1, 2].map(|c| x[c] * (-(tau[c] - m)).exp());
        let mean = (r[0] + r[1] + r[2]) / 3.0;
        if mean > 0.0 { r.map(|v| v / mean) } else { [0.0; 3] }
    }

    /// A flight inside the medium up to the boundary at `t_hit`: gathers emitters on the way, updates the
    /// throughput, and returns the collision distance if one was sampled.
    fn medium_flight(&self, st: &mut PathState, t_hit: f64, draws: &mut Draws) -> Option<f64> {
        let sigma = self.mat.sigma_t;
        if !self.scattering {
            let gather = !st.nee_done;
            if gather {
                self.gather(st, t_hit, |t| sigma.map(|s| (-s * t).exp()));
            }
            st.beta = [0, 1, 2].map(|c| st.beta[c] * (-sigma[c] * t_hit).exp());
            return None;
        }
        let hero = ((draws.draw() * 3.0) as usize).min(2);
        let xi = draws.draw();
        let t_c = -(1.0 - xi).ln() / sigma[hero];
        let collided = t_c < t_hit;
        let t_end = if collided { t_c } else { t_hit };
        if !st.nee_done {
            self.gather(st, t_end, |t| self.mis_ratio(t, [1.0; 3]));
        }
        if collided {
            let w = self.mis_ratio(t_c, sigma);
            st.beta = [0, 1, 2].map(|c| st.beta[c] * w[c] * self.mat.albedo[c]);
            Some(t_c)
        } else {
            if t_hit.is_finite() {
                let w = self.mis_ratio(t_hit, [1.0; 3]);
                st.beta = [0, 1, 2].map(|c| st.beta[c] * w[c]);
            }
            None
        }
    }

    /// Next-event estimation from the Lambertian point `p` (unit normal `side` toward the arriving path,
    /// albedo `k`) to every emitter: one direction uniform in the cone the sphere subtends, shadow ray
    /// against every mesh.
    fn next_event(&self, st: &mut PathState, p: DVec3, side: DVec3, k: [f64; 3], draws: &mut Draws) {
        let origin = p + side * eps(p);
        for e in &self.emitters {
            let (u, v) = (draws.draw(), draws.draw());
            let to_c = e.center - origin;
            let d2 = to_c.length_squared();
            let r2 = e.radius * e.radius;
            if !d2.is_finite() || d2 <= r2 {
                continue;
            }
            let s2 = r2 / d2;
            let cos_max = (1.0 - s2).sqrt();
            let one_minus = s2 / (1.0 + cos_max);
            let axis = to_c / d2.sqrt();
            let w = sample_cone(axis, one_minus, u, v);
            let cos = w.dot(side);
            if cos.is_nan() || cos <= 0.0 {
                continue;
            }
            let Some(t) = e.intersect(origin, w, 0.0) else { continue };
            if self.setup.bvh.occluded(origin.to_array(), w.to_array(), t) {
                continue;
            }
            let inv_pdf = 2.0 * PI * one_minus;
            let val = [0, 1, 2].map(|c| st.beta[c] * k[c] / PI * cos * e.radiance[c] * inv_pdf);
            st.add(val);
        }
    }

    /// The guide cones of every emitter at the medium point `x`, selection probabilities normalised
    /// (empty when no emitter has one).
    fn cones(&self, x: DVec3, cones: &mut Vec<Cone>) {
        cones.clear();
        cones.extend(self.emitters.iter().filter_map(|e| self.guide_cone(x, e)));
        let total: f64 = cones.iter().map(|c| c.prob).sum();
        if total > 0.0 && total.is_finite() {
            for c in cones.iter_mut() {
                c.prob /= total;
            }
        } else {
            cones.clear();
        }
    }

    /// Density of the guided connection's direction `w` \[1/sr\].
    fn guide_pdf(cones: &[Cone], w: DVec3) -> f64 {
        cones.iter().filter(|c| w.dot(c.axis) >= c.cos_max).map(|c| c.prob * c.pdf).sum()
    }

    /// The balance-heuristic weight of the HG continuation's gathers in a `Pending` state (cached).
    fn mis_weight(&self, mis: &mut Mis) -> f64 {
        match mis {
            Mis::One => 1.0,
            Mis::Pending { weight: Some(m), .. } => *m,
            Mis::Pending { x, d_in, w, weight, .. } => {
                let mut cones = Vec::with_capacity(self.emitters.len());
                self.cones(*x, &mut cones);
                let phase = hg::phase(d_in.dot(*w), self.mat.g);
                let pg = self.guide * Self::guide_pdf(&cones, *w);
                let m = if phase > 0.0 { phase / (phase + pg) } else { 0.0 };
                *weight = Some(m);
                m
            }
        }
    }

    /// The guided connection from the medium vertex `x` (path state after the collision, `st.d` the
    /// arriving direction), made with probability `guide`: a direction from the guide cones, the exact
    /// transmittance to the boundary, the transmitted branch `(1 − F) η²` of the first boundary, and
    /// every emitter met on the way inside or on the flight after the refraction out, weighted
    /// `phase / (phase + guide · p_guide)` (balance heuristic against the HG continuation).
    fn connect(&self, st: &mut PathState, x: DVec3, draws: &mut Draws, cones: &mut Vec<Cone>) {
        let (u0, u1, u2) = (draws.draw(), draws.draw(), draws.draw());
        self.cones(x, cones);
        if cones.is_empty() {
            return;
        }
        let mut pick = cones[cones.len() - 1];
        let mut acc = 0.0;
        for c in cones.iter() {
            acc += c.prob;
            if u0 < acc {
                pick = *c;
                break;
            }
        }
        let w = sample_cone(pick.axis, 1.0 - pick.cos_max, u1, u2);
        let pg = Self::guide_pdf(cones, w);
        let phase = hg::phase(st.d.dot(w), self.mat.g);
        if !(pg > 0.0 && phase > 0.0 && w.is_finite()) {
            return;
        }
        // Made with probability `guide`: (phase/(guide·pg)) · guide·pg/(phase + guide·pg).
        let f = phase / (phase + self.guide * pg);
        let sigma = self.mat.sigma_t;
        let beta = st.beta.map(|b| b * f);
        let hit = self.closest(x, w, 0.0, None);
        let t_b = hit.map_or(f64::INFINITY, |h| h.t);
        let mut add = [0.0; 3];
        for e in &self.emitters {
            if (x - e.center).length() <= e.radius {
                continue;
            }
            if let Some(t) = e.intersect(x, w, 0.0).filter(|&t| t < t_b) {
                for c in 0..3 {
                    add[c] += beta[c] * (-sigma[c] * t).exp() * e.radiance[c];
                }
            }
        }
        if let Some(h) = hit.filter(|h| h.mesh == self.setup.object && !h.front_face) {
            let p = x + h.t * w;
            let n = DVec3::from_array(h.geometric_normal);
            let ior = self.mat.ior;
            let fr = fresnel(w.dot(n).abs(), ior, 1.0);
            if let Some(out) = refract(w, n, ior, 1.0).filter(|_| fr < 1.0) {
                let scale = (1.0 - fr) * ior * ior;
                let t_next = self.closest(p, out, eps(p), Some((h.mesh, h.triangle))).map_or(f64::INFINITY, |g| g.t);
                for e in &self.emitters {
                    if (p - e.center).length() <= e.radius {
                        continue;
                    }
                    if e.intersect(p, out, 0.0).is_some_and(|t| t < t_next) {
                        for c in 0..3 {
                            add[c] += beta[c] * (-sigma[c] * h.t).exp() * scale * e.radiance[c];
                        }
                    }
                }
            }
        }
        st.add(add);
    }

    /// The guide cone toward emitter `e` from the medium point `x` (module doc), with its unnormalised
    /// selection weight; `None` when `x` lies inside the emitter.
    fn guide_cone(&self, x: DVec3, e: &Emitter) -> Option<Cone> {
        let to_c = e.center - x;
        let dist = to_c.length();
        if !dist.is_finite() || dist <= e.radius {
            return None;
        }
        let mut w = to_c / dist;
        let mut length = dist;
        for _ in 0..GUIDE_ITERATIONS {
            let ray = Ray { origin: x.to_array(), direction: w.to_array(), t_min: 0.0, t_max: f64::INFINITY };
            let Some(h) = self.setup.bvh.closest_hit(&ray) else { break };
            if h.mesh != self.setup.object || h.front_face {
                break;
            }
            if e.intersect(x, w, 0.0).is_some_and(|t| t < h.t) {
                break; // the emitter lies inside the object along this line
            }
            let p = x + h.t * w;
            let n = DVec3::from_array(h.geometric_normal);
            let Some(u) = (e.center - p).try_normalize() else { break };
            if u.dot(n) <= 0.0 {
                break; // the centre is behind the exit plane: no refraction leads there
            }
            let Some(t_in) = refract(-u, n, 1.0, self.mat.ior) else { break };
            let nw = -t_in;
            if !nw.is_finite() {
                break;
            }
            length = h.t + (e.center - p).length();
            w = nw;
        }
        let half = (CONE_MARGIN * (e.radius / length).min(1.0).asin()).clamp(CONE_MIN, CONE_MAX);
        let one_minus = 2.0 * (0.5 * half).sin().powi(2);
        let cos_max = 1.0 - one_minus;
        let intensity = e.intensity();
        let weight = (intensity[0] + intensity[1] + intensity[2]) / (3.0 * dist * dist);
        Some(Cone { prob: weight, axis: w, cos_max, pdf: 1.0 / (2.0 * PI * one_minus) })
    }
}

#[cfg(test)]
mod tests;
