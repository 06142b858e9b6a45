//! One volumetric path from a receiver or an eye: the estimator behind [`super::irradiance`] and
//! [`super::radiance`].
//!
//! **Input → output.** A [`Start`] — a receiver (point, unit normal) or a camera ray (origin, unit
//! direction) — and a [`SampleStream`] → one sample per channel of the irradiance
//! `E = ∫ L_i cos θ dω` at the receiver, or of the radiance arriving along the camera ray (unbiased;
//! the mean over paths is the estimate). Both run the same loop ([`Context::trace`]); only vertex 0
//! differs.
//!
//! **Estimator.** A receiver is vertex 0 with "BSDF" `cos θ` (cosine sampling, weight `π`); an eye is
//! vertex 0 that gathers nothing and whose direction is given (probability 1 for every channel). At
//! every other vertex — a Lambertian surface point (albedo `k`, BSDF `k/π`), a collision in a
//! medium (HG phase) — and at a receiver: next-event estimation to every light, then a direction from
//! the BSDF or phase function and a free flight (`flight.rs`) to the next collision or surface.
//! Emission is gathered two ways: next-event samples, and unidirectional hits on the front side of
//! emissive meshes (the only emitters that are geometry). Both are combined with the balance
//! heuristic, and the same heuristic handles chromatic media (hero-channel spectral MIS): the
//! tracking channel `h` is drawn uniformly per path and every technique's pdf is kept per channel, so
//! a path `x̄` ending with technique `t` contributes `f(x̄) / (⅓ Σ_c Σ_t' p_{c,t'}(x̄))` (the
//! per-channel ratios `r_u`, `r_l` below are these pdfs divided by the hero's, renormalised at every
//! vertex so they never overflow). The unidirectional pdf of an emitter hit includes the free-flight
//! escape probability `T_c` of the last segment; the next-event pdf is the light's solid-angle pdf; a
//! hit on the eye's own ray or after a specular event has no next-event partner. Delta lights are
//! gathered by next-event estimation alone. The analytic area lights (rect, disk, sphere) are not
//! geometry (never occlude, never end a flight): they are gathered by next-event estimation from
//! diffuse and medium vertices, and on flights no next-event sample can produce (the eye's ray, after
//! a specular event) by a deterministic connection to where the flight's line meets their emitting
//! side (`β_c L_c T_c / mean r`, [`Context::see_area_lights`]); each path to them is thus counted by
//! exactly one technique. For point and spot lights, next-event estimation at a leg's free-flight
//! collision is balanced against a second estimate of the same single-collision integral from a
//! distance sampled equiangularly along the leg (Kulla & Fajardo 2012, pdf
//! `D/((θ_b − θ_a)(D² + (t − Δ)²))`), which cancels the `1/r²` of collisions near the light.
//! Transmittance of shadow rays is exact ([`crate::scene::bvh::optical_thickness`]).
//!
//! **Surfaces.** Lambertian with the material's `base_color` (no material: 0.8 grey), two-sided, with
//! the geometric normal. Index-matched boundaries (a mesh bounding a medium whose material is missing
//! or a dielectric with `ior = 1`, and any `ior = 1` dielectric) are invisible: rays and shadow rays
//! continue from the hit. Refractive dielectrics are smooth Fresnel interfaces (reflect with
//! probability `F`, else refract by Snell's law, total internal reflection included; radiance scales
//! by `(η_from/η_to)²` when a traced ray crosses). Next-event rays cannot cross them: lights outside a
//! refractive boundary reach its inside only through unidirectional paths ending on emissive meshes
//! or analytic area lights (point, spot and directional lights do not light the inside at all).
//!
//! **Termination.** Vertices are indexed from 0 (receiver or eye); each straight flight may produce
//! the next index, each specular event takes one. `max_depth` counts vertices after the receiver, or
//! after a camera ray's first event (which is vertex 1, so the limit is `max_depth + 1` there): a
//! vertex up to the limit gathers by next-event estimation and scatters on; the flight leaving the
//! last one still gathers emission (so the MIS pair is complete) but produces no vertex, takes no
//! specular event and samples no equiangular distances. Russian roulette from vertex `rr_depth` on
//! (`rr_depth + 1` for camera rays), with survival `min(1, max_c w_c/u)`, `u` the throughput of an
//! unabsorbed path (`π` at a receiver, 1 from an eye). Once `surface_bounces` Lambertian vertices have
//! been made (the eye's own hit not counted), flights end at surfaces after gathering their emission,
//! except the eye's own flight; with `eye_surfaces` off that flight ends at its Lambertian hit.

use std::f64::consts::PI;

use glam::DVec3;

use super::VolPathOptions;
use super::flight::{self, Flight};
use super::lights::{LightSample, PreparedLight};
use crate::physics::hg;
use crate::physics::rng::{Draws, SampleStream};
use crate::reference::frame::frame;
use crate::render::optics::fresnel_cos;
use crate::scene::Scene;
use crate::scene::bvh::{Hit, MediumSegment, Ray, SceneBvh, SurfaceResponse as SurfaceKind};

/// Everything a path needs about the scene, prepared once.
pub struct Context<'a> {
    scene: &'a Scene,
    bvh: &'a SceneBvh,
    opts: &'a VolPathOptions,
    lights: Vec<PreparedLight>,
    kinds: Vec<SurfaceKind>,
    /// Per mesh, the prepared emissive-mesh lights it carries.
    emitters: Vec<Vec<usize>>,
    any_pass_through: bool,
    media: bool,
    /// Length scale of the scene \[m\] for ray-origin offsets.
    scale: f64,
}

/// Where a path starts.
#[derive(Debug, Clone, Copy)]
pub enum Start {
    /// An irradiance receiver: position and unit normal (vertex 0, "BSDF" `cos θ`).
    Receiver { x: DVec3, n: DVec3 },
    /// A camera ray: origin and unit direction (vertex 0 is the eye, which gathers nothing itself).
    Camera { origin: DVec3, dir: DVec3 },
}

/// Vertex-index limits of one path (see "Termination" in the module doc).
#[derive(Debug, Clone, Copy)]
struct Budget {
    /// Highest index of a vertex that gathers by next-event estimation and scatters on.
    max: u32,
    /// Index from which Russian roulette applies.
    rr: u32,
    /// Whether vertex 0 is an eye: its flight meets surfaces even when `surface_bounces` is off.
    camera: bool,
    /// Throughput scale of a path with nothing absorbed: `π` from a receiver (its `cos θ` "BSDF" has
    /// cosine-sampling weight `π`), 1 from an eye; Russian roulette survival is `max_c w_c` over it.
    unit: f64,
}

/// A vertex where light is gathered and a direction sampled.
#[derive(Debug, Clone, Copy)]
enum Vertex {
    /// The eye of a camera ray: origin and the given unit direction (no gathering, no sampling).
    Camera { o: DVec3, d: DVec3 },
    /// Receiver or Lambertian point: position, ray origin (offset along the side normal), side
    /// normal, `k` (BSDF `k/π`).
    Surface { p: DVec3, o: DVec3, n: DVec3, k: [f64; 3] },
    /// Collision in a medium: position, direction the path arrived along, HG `g` per channel, and the
    /// leg it was sampled on (for the equiangular MIS weights).
    Medium { p: DVec3, d_in: DVec3, g: [f64; 3], leg: Leg },
}

/// A straight flight: origin, unit direction, end, and per channel the factor turning an equiangular
/// pdf at the collision into a ratio comparable with `r_u` there (`r_dir / (σ_t,h T_h)`).
#[derive(Debug, Clone, Copy)]
struct Leg {
    origin: DVec3,
    dir: DVec3,
    t_end: f64,
    scale: [f64; 3],
}

impl Leg {
    /// Equiangular pdf (Kulla & Fajardo 2012) of distance `t ∈ [0, t_end)` for a light at `light`:
    /// `D / ((θ_b − θ_a)(D² + (t − Δ)²))`; 0 when the leg passes through the light (`D ≈ 0`).
    fn pdf(&self, light: DVec3, t: f64) -> f64 {
        let Some((delta, d, span)) = self.angles(light) else { return 0.0 };
        d / (span.1 - span.0) / (d * d + (t - delta) * (t - delta))
    }

    /// `(Δ, D, (θ_a, θ_b))` of the leg relative to `light`.
    fn angles(&self, light: DVec3) -> Option<(f64, f64, (f64, f64))> {
        let rel = light - self.origin;
        let delta = rel.dot(self.dir);
        let d = (rel - delta * self.dir).length();
        if d.is_nan() || d <= 1e-12 * (1.0 + rel.length()) || !d.is_finite() {
            return None;
        }
        let ta = (-delta).atan2(d);
        let tb = if self.t_end.is_finite() { (self.t_end - delta).atan2(d) } else { std::f64::consts::FRAC_PI_2 };
        (tb > ta).then_some((delta, d, (ta, tb)))
    }

    /// An equiangular distance for uniform `xi`.
    fn sample(&self, light: DVec3, xi: f64) -> Option<f64> {
        let (delta, d, (ta, tb)) = self.angles(light)?;
        let t = delta + d * (ta + xi * (tb - ta)).tan();
        (t.is_finite() && t >= 0.0).then(|| if self.t_end.is_finite() { t.min(self.t_end) } else { t })
    }
}

/// Per-channel path state (see the module doc).
struct State {
    hero: usize,
    /// Throughput over the hero's pdf.
    beta: [f64; 3],
    /// Unidirectional pdfs per channel over the hero's.
    r_u: [f64; 3],
    /// Lambertian reflections so far, not counting the surface the eye's own flight meets.
    reflections: u32,
}

impl State {
    /// Weight of a contribution whose techniques' pdf ratios sum to `denom` per channel.
    fn mean(r: [f64; 3]) -> f64 {
        (r[0] + r[1] + r[2]) / 3.0
    }

    /// Rescales `beta` and `r_u` by the same factor so that `max r_u = 1`; returns the divisor.
    fn renormalise(&mut self) -> f64 {
        let m = self.r_u.iter().fold(0.0f64, |m, &x| m.max(x));
        if m > 0.0 && m.is_finite() {
            self.r_u = self.r_u.map(|x| x / m);
            self.beta = self.beta.map(|x| x / m);
            m
        } else {
            1.0
        }
    }
}

/// `exp(x)` capped so that products with zero stay zero (never `∞`).
fn exp_capped(x: f64) -> f64 {
    x.min(700.0).exp()
}

fn hg_phase(mu: f64, g: f64) -> f64 {
    hg::phase(mu, g.clamp(-0.999_999, 0.999_999))
}

impl<'a> Context<'a> {
    /// Prepares lights and surface kinds.
    pub fn new(scene: &'a Scene, bvh: &'a SceneBvh, opts: &'a VolPathOptions) -> Self {
        let lights = PreparedLight::prepare_all(scene);
        let mut emitters = vec![Vec::new(); scene.meshes.len()];
        for (i, l) in lights.iter().enumerate() {
            if let Some(m) = l.mesh {
                emitters[m].push(i);
            }
        }
        let kinds: Vec<SurfaceKind> = (0..scene.meshes.len()).map(|i| bvh.surface_response(scene, i)).collect();
        let any_pass_through = kinds.iter().any(|k| matches!(k, SurfaceKind::PassThrough));
        let scale = scene.diagonal();
        let scale = if scale.is_finite() { scale } else { 0.0 };
        Context {
            scene,
            bvh,
            opts,
            lights,
            kinds,
            emitters,
            any_pass_through,
            media: opts.media && !scene.media.is_empty(),
            scale,
        }
    }

    /// Ray-origin offset at `p` \[m\]: a few hundred f32 ulps of the coordinates and the scene size.
    fn eps(&self, p: DVec3) -> f64 {
        1e-5 * (p.abs().max_element() + 0.01 * self.scale) + 1e-9
    }

    /// Closest hit that is not an index-matched boundary.
    fn closest(&self, ray: &Ray, rays: &mut u64) -> Option<Hit> {
        let mut r = *ray;
        loop {
            *rays += 1;
            let h = self.bvh.closest_hit(&r)?;
            if !matches!(self.kinds.get(h.mesh), Some(SurfaceKind::PassThrough)) {
                return Some(h);
            }
            if h.t.is_nan() || h.t <= r.t_min {
                return None;
            }
            r.t_min = h.t;
        }
    }

    /// Per-channel transmittance from `p` along unit `dir` over `dist` (`∞` allowed), `None` when
    /// geometry other than index-matched boundaries blocks the ray from the offset origin `o` along
    /// `shadow_dir` before `t_block`.
    #[allow(clippy::too_many_arguments)]
    fn transmittance(
        &self,
        o: DVec3,
        p: DVec3,
        dir: DVec3,
        shadow_dir: DVec3,
        dist: f64,
        t_block: f64,
        rays: &mut u64,
    ) -> Option<[f64; 3]> {
        let ray = Ray { origin: o.to_array(), direction: shadow_dir.to_array(), t_min: 0.0, t_max: t_block };
        if t_block > 0.0 {
            if self.any_pass_through {
                if self.closest(&ray, rays).is_some_and(|h| h.t < t_block) {
                    return None;
                }
            } else {
                *rays += 1;
                if self.bvh.occluded_ray(&ray) {
                    return None;
                }
            }
        }
        if !self.media {
            return Some([1.0; 3]);
        }
        *rays += 1;
        let ray = Ray { origin: p.to_array(), direction: dir.to_array(), ..ray };
        let segs = self.bvh.media_segments(self.scene, &ray, dist);
        Some(flight::depth(self.scene, &ray, &segs).map(|t| (-t).exp()))
    }

    /// One path's sample from `start`: irradiance at a receiver, or radiance arriving along a camera
    /// ray (module doc). Both share this loop; only vertex 0 differs.
    pub fn trace(&self, start: Start, stream: SampleStream, rays: &mut u64) -> [f64; 3] {
        let mut draws = Draws::new(stream);
        let hero = ((draws.draw() * 3.0) as usize).min(2);
        let mut st = State { hero, beta: [1.0; 3], r_u: [1.0; 3], reflections: 0 };
        let mut out = [0.0; 3];
        // A camera path's vertex 0 is the eye, so its user-facing vertex indices start at 1.
        let (mut vertex, camera) = match start {
            Start::Receiver { x, n } => (Vertex::Surface { p: x, o: x + n * self.eps(x), n, k: [PI; 3] }, false),
            Start::Camera { origin, dir } => (Vertex::Camera { o: origin, d: dir }, true),
        };
        let off = u32::from(camera);
        let budget = Budget {
            max: self.opts.max_depth.saturating_add(off),
            rr: self.opts.rr_depth.saturating_add(off),
            camera,
            unit: if camera { 1.0 } else { PI },
        };
        let mut depth = 0u32;
        loop {
            self.next_event(&vertex, &st, &mut draws, &mut out, rays);
            // Direction sampling: throughput and per-channel pdf ratios.
            let (u1, u2) = (draws.draw(), draws.draw());
            let r_prefix = st.r_u;
            let (origin, dir, p_dir_hero) = match vertex {
                // The given ray: probability 1 for every channel, and no light sample can produce it.
                Vertex::Camera { o, d } => (o, d, f64::INFINITY),
                Vertex::Surface { o, n, k, .. } => {
                    let (t1, t2) = frame(n);
                    let r = u1.sqrt();
                    let phi = std::f64::consts::TAU * u2;
                    let cz = (1.0 - u1).max(0.0).sqrt();
                    let dir = (r * phi.cos() * t1 + r * phi.sin() * t2 + cz * n).normalize();
                    st.beta = [0, 1, 2].map(|c| st.beta[c] * k[c]);
                    (o, dir, cz / PI)
                }
                Vertex::Medium { p, d_in, g, .. } => {
                    let mu = hg::sample_mu(u1, g[hero].clamp(-0.999_999, 0.999_999));
                    let (t1, t2) = frame(d_in);
                    let phi = std::f64::consts::TAU * u2;
                    let sin = (1.0 - mu * mu).max(0.0).sqrt();
                    let dir = (mu * d_in + sin * (phi.cos() * t1 + phi.sin() * t2)).normalize();
                    let mu = d_in.dot(dir);
                    let ph = g.map(|gc| hg_phase(mu, gc));
                    let h = ph[hero];
                    if !(h > 0.0 && h.is_finite()) {
                        return out;
                    }
                    st.beta = [0, 1, 2].map(|c| st.beta[c] * ph[c] / h);
                    st.r_u = [0, 1, 2].map(|c| st.r_u[c] * ph[c] / h);
                    (p, dir, h)
                }
            };
            if p_dir_hero.is_nan() || p_dir_hero <= 0.0 || st.beta.iter().all(|&b| b == 0.0) {
                return out;
            }
            // Russian roulette on the MIS-weighted throughput.
            let xi_rr = draws.draw();
            if depth >= budget.rr {
                let w = st.beta.iter().fold(0.0f64, |m, &b| m.max(b)) / State::mean(st.r_u);
                let q = (w / budget.unit).min(1.0);
                if q.is_nan() || q <= 0.0 || xi_rr >= q {
                    return out;
                }
                st.beta = st.beta.map(|b| b / q);
            }
            // Next-event pdf ratios of the coming emitter hit (per unit light pdf, before escape).
            let r_l = r_prefix.map(|r| r / p_dir_hero);
            let leg = Leg { origin, dir, t_end: f64::INFINITY, scale: st.r_u };
            match self.flight(leg, &mut st, r_l, budget, &mut draws, &mut out, &mut depth, rays) {
                Some(v) => vertex = v,
                None => return out,
            }
            if st.beta.iter().all(|&b| b == 0.0) {
                return out;
            }
            let m = st.renormalise();
            if let Vertex::Medium { leg, .. } = &mut vertex {
                leg.scale = leg.scale.map(|x| x / m);
            }
        }
    }

    /// Next-event estimation to every light from `vertex`.
    fn next_event(&self, vertex: &Vertex, st: &State, draws: &mut Draws, out: &mut [f64; 3], rays: &mut u64) {
        let (p, o) = match *vertex {
            Vertex::Camera { .. } => return, // the eye gathers only along its given ray
            Vertex::Surface { p, o, .. } => (p, o),
            Vertex::Medium { p, .. } => (p, p),
        };
        for light in &self.lights {
            let (u, v) = (draws.draw(), draws.draw());
            let Some(s) = light.sample(p, u, v) else { continue };
            if s.value.iter().all(|&x| x.is_nan() || x <= 0.0) {
                continue;
            }
            // BSDF or phase value per channel and the unidirectional pdf per channel.
            let (f, p_dir) = match *vertex {
                Vertex::Surface { n, k, .. } => {
                    let cos = n.dot(s.dir);
                    if cos.is_nan() || cos <= 0.0 {
                        continue;
                    }
                    (k.map(|kc| kc / PI * cos), [cos / PI; 3])
                }
                Vertex::Medium { d_in, g, .. } => {
                    let mu = d_in.dot(s.dir);
                    let ph = g.map(|gc| hg_phase(mu, gc));
                    (ph, ph)
                }
                Vertex::Camera { .. } => return,
            };
            if f.iter().all(|&x| x.is_nan() || x <= 0.0) {
                continue;
            }
            // A target on geometry: aim the shadow ray from the offset origin and stop short of it.
            let (shadow_dir, block) = if s.on_surface {
                let q = p + s.dir * s.dist;
                let d = q - o;
                let len = d.length();
                (d / len, len * (1.0 - 1e-7) - self.eps(q))
            } else {
                (s.dir, s.dist)
            };
            let Some(tr) = self.transmittance(o, p, s.dir, shadow_dir, s.dist, block, rays) else { continue };
            let LightSample { value, pdf, .. } = s;
            let denom = match (pdf, vertex, light.position()) {
                (Some(pl), _, _) => State::mean([0, 1, 2].map(|c| st.r_u[c] * (1.0 + p_dir[c] * tr[c] / pl))),
                (None, Vertex::Medium { leg, .. }, Some(lp)) => {
                    // Balance against the equiangular sample of the same leg (see `equiangular`).
                    let pe = leg.pdf(lp, (p - leg.origin).dot(leg.dir));
                    State::mean([0, 1, 2].map(|c| st.r_u[c] + leg.scale[c] * pe))
                }
                (None, _, _) => State::mean(st.r_u),
            };
            for (c, o) in out.iter_mut().enumerate() {
                let add = st.beta[c] * f[c] * tr[c] * value[c] / denom;
                if add > 0.0 {
                    *o += add;
                }
            }
        }
    }

    /// Flies from `origin` along `dir` through index-matched boundaries and specular events; gathers
    /// emitter hits; returns the next diffuse or medium vertex, or `None` when the path ends (also
    /// when that vertex's index would exceed `budget.max`: it has then only gathered emission).
    #[allow(clippy::too_many_arguments)]
    fn flight(
        &self,
        leg: Leg,
        st: &mut State,
        mut r_l: [f64; 3],
        budget: Budget,
        draws: &mut Draws,
        out: &mut [f64; 3],
        depth: &mut u32,
        rays: &mut u64,
    ) -> Option<Vertex> {
        let (mut origin, mut dir) = (leg.origin, leg.dir);
        // The eye's own flight meets surfaces whatever `surface_bounces` says: they are what it sees.
        let eye_flight = budget.camera && *depth == 0;
        let surfaces = st.reflections < self.opts.surface_bounces || eye_flight;
        *depth += 1;
        loop {
            // `*depth` is the index of the vertex this straight flight may produce.
            let last = *depth > budget.max;
            let ray = Ray { origin: origin.to_array(), direction: dir.to_array(), t_min: 0.0, t_max: f64::INFINITY };
            let hit = self.closest(&ray, rays);
            let t_end = hit.map_or(f64::INFINITY, |h| h.t);
            let xi = draws.draw();
            let segs: Vec<MediumSegment> = if self.media {
                *rays += 1;
                self.bvh.media_segments(self.scene, &ray, t_end)
            } else {
                Vec::new()
            };
            let Flight { collision, tau } = flight::fly(self.scene, &ray, &segs, st.hero, xi);
            let h = st.hero;
            let leg = Leg { origin, dir, t_end, scale: st.r_u };
            if !last {
                self.equiangular(&leg, &segs, st, draws, out, rays);
            }
            if r_l.iter().all(|&r| r == 0.0) {
                // No light sample can produce this flight (the eye's ray, or after a specular event).
                self.see_area_lights(&leg, &segs, st, out);
            }
            if let Some(c) = collision {
                let sh = c.sigma_t[h];
                if !(sh > 0.0 && sh.is_finite()) {
                    return None;
                }
                let ratio = |k: usize| exp_capped(tau[h] - tau[k]);
                let th_inv = exp_capped(tau[h]);
                st.beta = [0, 1, 2].map(|k| st.beta[k] * c.sigma_s[k] * ratio(k) / sh);
                st.r_u = [0, 1, 2].map(|k| st.r_u[k] * c.sigma_t[k] * ratio(k) / sh);
                let g = self.scene.media[c.medium].g;
                let leg = Leg { scale: leg.scale.map(|r| r * th_inv / sh), ..leg };
                return (!last).then_some(Vertex::Medium { p: origin + c.t * dir, d_in: dir, g, leg });
            }
            // Escaped the media up to the hit (or to infinity): weight T_c / T_h.
            let ratio = |k: usize| exp_capped(tau[h] - tau[k]);
            st.beta = [0, 1, 2].map(|k| st.beta[k] * ratio(k));
            st.r_u = [0, 1, 2].map(|k| st.r_u[k] * ratio(k));
            let inv_th = exp_capped(tau[h]);
            r_l = r_l.map(|r| r * inv_th);
            let hit = hit?;
            let p = origin + hit.t * dir;
            let ng = DVec3::from_array(hit.geometric_normal);
            if hit.front_face {
                self.gather_emission(&hit, dir, ng, st, r_l, out);
            }
            if !surfaces {
                return None;
            }
            let side = if dir.dot(ng) < 0.0 { ng } else { -ng };
            match self.kinds[hit.mesh] {
                SurfaceKind::Lambert(k) => {
                    if eye_flight {
                        if !self.opts.eye_surfaces {
                            return None;
                        }
                    } else {
                        st.reflections += 1;
                    }
                    return (!last).then_some(Vertex::Surface { p, o: p + side * self.eps(p), n: side, k });
                }
                SurfaceKind::PassThrough => return None, // `closest` never reports these
                SurfaceKind::Dielectric(_) if last => return None,
                SurfaceKind::Dielectric(ior) => {
                    *depth += 1;
                    let (eta_from, eta_to) = if hit.front_face { (1.0, ior) } else { (ior, 1.0) };
                    let xi = draws.draw();
                    let cos_i = -dir.dot(side);
                    let eta = eta_from / eta_to;
                    let sin2_t = eta * eta * (1.0 - cos_i * cos_i).max(0.0);
                    let fresnel =
                        if sin2_t >= 1.0 { 1.0 } else { fresnel_cos(cos_i, (1.0 - sin2_t).sqrt(), eta_from, eta_to) };
                    if xi < fresnel {
                        dir = (dir + 2.0 * cos_i * side).normalize();
                        origin = p + side * self.eps(p);
                    } else {
                        let cos_t = (1.0 - sin2_t).sqrt();
                        dir = (eta * dir + (eta * cos_i - cos_t) * side).normalize();
                        origin = p - side * self.eps(p);
                        let scale = eta * eta;
                        st.beta = st.beta.map(|b| b * scale);
                    }
                    // A specular vertex: next-event estimation cannot produce the coming hit.
                    r_l = [0.0; 3];
                }
            }
        }
    }

    /// Equiangular next-event estimation to each point and spot light along one leg: a distance `t`
    /// with pdf `p_e(t)` ([`Leg::pdf`]), next-event estimation from the point there, balanced against
    /// the same next-event estimate at the leg's free-flight collision (pdf `σ_t,c T_c` per channel).
    /// Removes the `1/r²` singularity of collisions near the light.
    fn equiangular(
        &self,
        leg: &Leg,
        segs: &[MediumSegment],
        st: &State,
        draws: &mut Draws,
        out: &mut [f64; 3],
        rays: &mut u64,
    ) {
        for light in &self.lights {
            let xi = draws.draw();
            let (u, v) = (draws.draw(), draws.draw());
            let Some(lp) = light.position().filter(|_| !segs.is_empty()) else { continue };
            let Some(t) = leg.sample(lp, xi) else { continue };
            let pe = leg.pdf(lp, t);
            let Some(seg) = segs.iter().find(|s| s.t0 <= t && t < s.t1) else { continue };
            let Some(medium) = seg.medium.and_then(|i| self.scene.media.get(i)) else { continue };
            let x = leg.origin + t * leg.dir;
            let rho = flight::density_at(&medium.density, x);
            let tau = self.depth_to(leg, segs, t);
            let Some(s) = light.sample(x, u, v) else { continue };
            let mu = leg.dir.dot(s.dir);
            let f = medium.g.map(|g| hg_phase(mu, g));
            let Some(tr) = self.transmittance(x, x, s.dir, s.dir, s.dist, s.dist, rays) else { continue };
            let trans = tau.map(|x| (-x).exp());
            let denom = State::mean([0, 1, 2].map(|c| leg.scale[c] * (medium.sigma_t()[c] * rho * trans[c] + pe)));
            for (c, o) in out.iter_mut().enumerate() {
                let add = st.beta[c] * medium.sigma_s[c] * rho * trans[c] * f[c] * tr[c] * s.value[c] / denom;
                if add > 0.0 {
                    *o += add;
                }
            }
        }
    }

    /// Per-channel optical depth along `leg` from its origin to distance `t` (`segs`: the leg's media).
    fn depth_to(&self, leg: &Leg, segs: &[MediumSegment], t: f64) -> [f64; 3] {
        let ray = Ray { origin: leg.origin.to_array(), direction: leg.dir.to_array(), t_min: 0.0, t_max: t };
        let upto: Vec<MediumSegment> = segs
            .iter()
            .filter(|s| s.t0 < t)
            .map(|s| MediumSegment { t0: s.t0, t1: s.t1.min(t), medium: s.medium })
            .collect();
        flight::depth(self.scene, &ray, &upto)
    }

    /// Adds the radiance of the analytic area lights (rect, disk, sphere) whose emitting side `leg`
    /// meets before its end, on a flight no next-event sample can produce (so no MIS partner). The
    /// light's point is a deterministic extension of the path (probability 1 for every tracking
    /// channel), so the hero-channel MIS estimate is `β_c L_c T_c / mean_c' r_c'` with `T_c` the
    /// transmittance to the light, whatever the free flight does (exact on the eye's own ray).
    fn see_area_lights(&self, leg: &Leg, segs: &[MediumSegment], st: &State, out: &mut [f64; 3]) {
        let denom = State::mean(st.r_u);
        if !(denom > 0.0 && denom.is_finite()) {
            return;
        }
        for light in &self.lights {
            let Some(t) = light.hit_distance(leg.origin, leg.dir).filter(|&t| t < leg.t_end) else { continue };
            let trans = if segs.is_empty() { [1.0; 3] } else { self.depth_to(leg, segs, t).map(|x| (-x).exp()) };
            for (c, o) in out.iter_mut().enumerate() {
                let add = st.beta[c] * light.radiance[c] * trans[c] / denom;
                if add > 0.0 {
                    *o += add;
                }
            }
        }
    }

    /// Adds the emission of the emissive-mesh lights on `hit` (front side), MIS-weighted against
    /// next-event estimation of the same light from the previous vertex.
    fn gather_emission(&self, hit: &Hit, dir: DVec3, ng: DVec3, st: &State, r_l: [f64; 3], out: &mut [f64; 3]) {
        let Some(list) = self.emitters.get(hit.mesh) else { return };
        for &li in list {
            let light = &self.lights[li];
            let Some(area) = light.mesh_area() else { continue };
            let cos = dir.dot(ng).abs();
            let pl = hit.t * hit.t / (area * cos);
            let pl = if pl.is_finite() { pl } else { f64::MAX };
            let denom = State::mean([0, 1, 2].map(|c| st.r_u[c] + r_l[c] * pl));
            for (c, o) in out.iter_mut().enumerate() {
                let add = st.beta[c] * light.radiance[c] / denom;
                if add > 0.0 {
                    *o += add;
                }
            }
        }
    }
}
