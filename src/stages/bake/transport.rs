//! Surface-transport path tracing with volume-to-surface transport from the ZH tables
//! (dubouchet2019 Sec. 5, 5.2).
//!
//! **Input → output.** A scene, its BVH, an optional loaded [`ZhResponseTable`] and a [`BakeMode`] → the
//! irradiance \[W/m²\] per RGB channel at a surface point (a lightmap texel or a probe's sample), with an
//! estimate of its noise.
//!
//! **Estimator.** Paths are ordinary surface paths (cosine-sampled bounces off Lambertian surfaces);
//! no vertex is ever placed inside a medium. Every *connection* from a receiver `x` to a source — a
//! delta light (once per receiver, deterministic), a point sampled on an area light, or the next surface
//! vertex `y` of the path — is weighted according to the mode:
//! - [`BakeMode::Surface`]: vacuum (the media are ignored);
//! - [`BakeMode::Shadow`]: the transmittance `exp(−τ)` of the segment (media shadowing only);
//! - [`BakeMode::Full`]: the table's impulse response — the attenuated direct term plus the single- and
//!   multiple-scattered irradiance — queried with the *effective* σ_s, σ_a and g of the segment
//!   (Sec. 4.4: `σ_eff = Σ σ_i d_i / D`; g weighted by scattering), the point/directional responses for
//!   those emitters and the differential-area response for area-light samples and for surface vertices
//!   (a Lambertian surface of outgoing radiance `L_o` seen over `dA` is a patch of intensity `L_o dA`
//!   along its normal). As in the paper (Secs. 4.5, 5.1), the multiple-scattering orders use the similarity
//!   relation (`σ_s* = (1 − g) σ_s`, `g* = 0`), which also halves their cost (one g slice instead of two).
//!   Connections are made only when the straight segment is unoccluded (Sec. 5.2),
//!   and the table's back-scatter compensation (the receiver shifted ε mean free paths along its
//!   normal for the scattered orders) is applied when [`TransportOptions::backscatter`] is on.
//!
//! **Surface vertices.** A bounce sampled with pdf `cos θ_x / π` toward a surface at distance `r` seen at
//! `cos θ_y` is the patch `dA = π r² / (cos θ_x cos θ_y)`. The direct part is exact (`π L_o T`); the scattered
//! part's weight grows like `1/cos θ_y` at grazing angles, so `cos θ_y` is floored at [`GRAZING_FLOOR`] for it
//! (a small downward bias on light scattered from surfaces seen edge-on, in exchange for finite variance).
//!
//! **Singularities.** Receivers closer than [`MIN_DISTANCE`] to a point light or an area-light sample see
//! the source at that distance (the `1/d²` is capped). A directional light enters the media where its ray
//! leaves the scene's bounding box (the global medium is taken to fill the scene's bounds for sunlight).
//!
//! **Randomness.** Texel `t`'s sample `k` draws from [`StreamKey`] `(seed, t)`: the image is the same for any
//! thread count. The first bounce uses a randomly shifted rank-1 lattice (two 2-D point sets, for the
//! area-light point and the bounce direction); deeper bounces use plain counter-based uniforms.

use glam::DVec3;

use super::BakeMode;
use super::lights::{BakeLights, Patch, Source, unit};
use crate::physics::medium::HomogeneousMedium;
use crate::physics::rng::{SampleStream, StreamKey};
use crate::render::frame::frame;
use crate::scene::bvh::{Hit, Ray, SceneBvh, optical_thickness};
use crate::scene::{Boundary, Scene, Surface};
use crate::tables::zh_response::{Emitter, QueryError, QueryOptions, Receiver, ZhResponseTable};

/// Closest a receiver gets to a point source \[m\] (caps the `1/d²`).
pub const MIN_DISTANCE: f64 = 1e-3;

/// Floor on `cos θ_y` in the weight of light scattered from a surface vertex (module doc).
pub const GRAZING_FLOOR: f64 = 0.05;

/// SH coefficients per channel of a light probe (bands `l ≤ 2`).
pub const PROBE_SH: usize = 9;

/// Albedo of surfaces without a material.
pub const DEFAULT_ALBEDO: f64 = 0.8;

/// Switches of the transport.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TransportOptions {
    /// Which media effects are included.
    pub mode: BakeMode,
    /// Samples per receiver (area-light points and bounce paths).
    pub samples: u32,
    /// Surface bounces of indirect light (0: direct light only).
    pub bounces: u32,
    /// dubouchet2019 Sec. 5.2 back-scatter compensation on the scattered orders.
    pub backscatter: bool,
    /// Samples per receiver on which the scattered light is queried (at most `samples`; the others carry
    /// direct light only and the queried ones are weighted up, so the mean is unchanged). Scattered light
    /// is smooth, so a fraction of the samples suffices; this is what keeps Full close to Surface in cost.
    pub scatter_samples: u32,
    /// Seed of the random streams.
    pub seed: u64,
}

/// The irradiance at one receiver.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Estimate {
    /// Irradiance per channel \[W/m²\].
    pub irradiance: [f64; 3],
    /// Standard error of the luminance estimate over its mean (0 when the mean is 0).
    pub rel_stderr: f64,
    /// Rays traced (closest-hit and shadow).
    pub rays: u64,
}

/// What lies along a segment.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Along {
    /// Transmittance per channel.
    transmittance: [f64; 3],
    /// Effective coefficients per channel along the segment (all zero in vacuum).
    channels: [HomogeneousMedium; 3],
}

/// An irradiance estimate split by whether its terms contain scattered-light queries (those are made on
/// a subset of the samples only and already carry that subset's weight `sw` once; a term with several
/// queries must carry it once, not once per query).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
struct Irr {
    /// Terms without table queries.
    plain: [f64; 3],
    /// Terms with at least one query, weighted by `sw` once.
    scat: [f64; 3],
}

impl Irr {
    fn total(&self) -> [f64; 3] {
        [0, 1, 2].map(|c| self.plain[c] + self.scat[c])
    }

    fn add(&mut self, s: &Split) {
        for c in 0..3 {
            self.plain[c] += s.direct[c];
            self.scat[c] += s.scattered[c];
        }
    }
}

/// Irradiance from one connection, split.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
struct Split {
    direct: [f64; 3],
    scattered: [f64; 3],
}

/// The transport of one scene.
pub struct Transport<'a> {
    scene: &'a Scene,
    bvh: &'a SceneBvh,
    table: Option<&'a ZhResponseTable>,
    opts: TransportOptions,
    lights: BakeLights,
    albedo: Vec<[f64; 3]>,
    pass_through: Vec<bool>,
    any_pass_through: bool,
    has_media: bool,
    world: (DVec3, DVec3),
    eps: f64,
    query: QueryOptions,
    key: u64,
}

/// Why a receiver could not be estimated.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum TransportError {
    /// Full mode without a table.
    #[error("mode Full needs a ZhResponse table")]
    NoTable,
    /// The table refused a query (e.g. a medium's g outside its range).
    #[error("{0}")]
    Query(#[from] QueryError),
}

impl<'a> Transport<'a> {
    /// Prepares the transport. `table` is required for [`BakeMode::Full`] when the scene has media.
    pub fn new(
        scene: &'a Scene,
        bvh: &'a SceneBvh,
        table: Option<&'a ZhResponseTable>,
        opts: TransportOptions,
    ) -> Result<Transport<'a>, TransportError> {
        let has_media = scene.media.iter().any(|m| m.sigma_t().iter().any(|&s| s > 0.0));
        if opts.mode == BakeMode::Full && has_media && table.is_none() {
            return Err(TransportError::NoTable);
        }
        let albedo = scene
            .meshes
            .iter()
            .map(|m| match m.material.and_then(|i| scene.materials.get(i)) {
                Some(mat) => mat.base_color.map(|c| if c.is_finite() { c.clamp(0.0, 1.0) } else { 0.0 }),
                None => [DEFAULT_ALBEDO; 3],
            })
            .collect();
        let pass_through: Vec<bool> = (0..scene.meshes.len())
            .map(|i| {
                let bounds =
                    bvh.medium_bounded_by(i).is_some() || scene.media.iter().any(|m| m.boundary == Boundary::Mesh(i));
                let matched = match scene.meshes[i].material.and_then(|k| scene.materials.get(k)) {
                    Some(mat) => matches!(mat.surface, Surface::Dielectric { ior } if ior == 1.0),
                    None => true,
                };
                bounds && matched
            })
            .collect();
        let world = scene.bounds().map_or((DVec3::ZERO, DVec3::ZERO), |(lo, hi)| (lo.into(), hi.into()));
        let eps = (1e-5 * scene.diagonal()).max(1e-5);
        let key = crate::physics::rng::StreamKey { table: 0x6c69_6768_746d_6170 ^ opts.seed, cell: 0 }.sample(0);
        Ok(Transport {
            scene,
            bvh,
            table,
            opts,
            lights: BakeLights::new(scene),
            albedo,
            any_pass_through: pass_through.iter().any(|&p| p),
            pass_through,
            has_media,
            world,
            eps,
            query: QueryOptions { backscatter: opts.backscatter, tail: true, similarity: true, max_bounce: None },
            key: (key.uniform(0) * 2f64.powi(53)) as u64,
        })
    }

    /// The stream of receiver `cell`.
    pub fn stream(&self, cell: u64) -> StreamKey {
        StreamKey { table: self.key, cell }
    }

    /// Irradiance at the surface point `x` with shading normal `n` and geometric normal `ng` (both unit,
    /// on the side light is gathered from), estimated with the options' samples and bounces.
    pub fn receiver(&self, x: [f64; 3], n: [f64; 3], ng: [f64; 3], cell: u64) -> Result<Estimate, TransportError> {
        let (x, n, ng) = (DVec3::from_array(x), DVec3::from_array(n), DVec3::from_array(ng));
        let mut rays = 0u64;
        let delta = self.delta_irradiance(x, n, ng, 1.0, &mut rays)?.total();
        let samples = self.opts.samples.max(1);
        let stream = self.stream(cell);
        let shift = stream.sample(u64::MAX);
        let shifts = [0, 1, 2, 3, 4].map(|d| shift.uniform(d));
        let (mut sum, mut lum_sum, mut lum_sq) = ([0.0; 3], 0.0, 0.0);
        let n_f = f64::from(samples);
        let stride = samples.div_ceil(self.opts.scatter_samples.clamp(1, samples));
        let queried = samples.div_ceil(stride);
        let sw_on = n_f / f64::from(queried);
        for k in 0..samples {
            let sw = if k % stride == 0 { sw_on } else { 0.0 };
            let s = stream.sample(u64::from(k));
            let kf = f64::from(k);
            // Two shifted rank-1 lattices (generators 1/N and the golden ratio) for the first vertex.
            let lat = |a: usize, b: usize| {
                (((kf + 0.5) / n_f + shifts[a]).fract(), (kf * 0.618_033_988_749_894_9 + shifts[b]).fract())
            };
            let (l1, l2) = lat(1, 2);
            let (d1, d2) = lat(3, 4);
            let u = [(s.uniform(0) + shifts[0]).fract(), l1, l2, d1, d2];
            let v = self.sampled_irradiance(x, n, ng, u, &s, (1, self.opts.bounces), sw, &mut rays)?.total();
            let lum = luminance(v);
            lum_sum += lum;
            lum_sq += lum * lum;
            for c in 0..3 {
                sum[c] += v[c];
            }
        }
        let mean = sum.map(|s| s / n_f);
        let irradiance = [0, 1, 2].map(|c| delta[c] + mean[c]);
        let lum_mean = lum_sum / n_f;
        let var = if samples > 1 { ((lum_sq / n_f - lum_mean * lum_mean) * n_f / (n_f - 1.0)).max(0.0) } else { 0.0 };
        let total = luminance(irradiance);
        let rel_stderr = if total > 0.0 { (var / n_f).sqrt() / total } else { 0.0 };
        Ok(Estimate { irradiance, rel_stderr, rays })
    }

    /// Incident radiance at the free point `x` (a light probe) as real SH of bands `l ≤ 2` per channel
    /// (9 coefficients, `i = l(l+1) + m`, the basis of [`crate::physics::sh`]): delta lights and area-light
    /// samples as weighted deltas in their direction, surfaces reflecting light through uniformly sampled
    /// directions, and in [`BakeMode::Full`] the scattered radiance of every connection (the table's world-SH
    /// lobe, no back-scatter shift: a probe has no surface).
    pub fn probe(&self, x: [f64; 3], cell: u64) -> Result<[[f64; PROBE_SH]; 3], TransportError> {
        let x = DVec3::from_array(x);
        let mut sh = [[0.0; PROBE_SH]; 3];
        let mut y = [0.0; PROBE_SH];
        let mut add = |dir: DVec3, w: [f64; 3], sh: &mut [[f64; PROBE_SH]; 3]| {
            crate::physics::sh::sh_eval_into(3, dir.to_array(), &mut y);
            for c in 0..3 {
                for i in 0..PROBE_SH {
                    sh[c][i] += w[c] * y[i];
                }
            }
        };
        let mut rays = 0;
        let mut sources = Vec::new();
        self.lights.deltas_toward(x, &mut sources);
        for src in &sources {
            let (to, d, strength, unit_radiance, emitter) = match *src {
                Source::Point { position, intensity } => {
                    let (to, d) = direction_to(x, position);
                    let d = d.max(MIN_DISTANCE);
                    let pos = (x + to * d).to_array();
                    (to, d, intensity, 1.0 / (d * d), Emitter::Point { intensity: 1.0, position: pos })
                }
                Source::Directional { toward, irradiance } => {
                    let depth = exit_distance(x, toward, self.world);
                    (
                        toward,
                        depth,
                        irradiance,
                        1.0,
                        Emitter::Directional { irradiance: 1.0, toward_light: toward.to_array(), depth },
                    )
                }
                Source::Patch(_) => continue,
            };
            rays += 1;
            let t_max = if matches!(src, Source::Directional { .. }) { f64::INFINITY } else { d };
            if !self.visible(x, to, t_max) {
                continue;
            }
            self.probe_connection(x, to, d, strength, unit_radiance, 1.0, &emitter, 1.0, &mut sh, &mut add)?;
        }
        let samples = self.opts.samples.max(1);
        let stream = self.stream(cell);
        let w_s = 1.0 / f64::from(samples);
        for k in 0..samples {
            let s = stream.sample(u64::from(k));
            if let Some(p) = self.lights.sample_area([s.uniform(0), s.uniform(1), s.uniform(2)]) {
                let (to, d) = direction_to(x, p.position);
                rays += 1;
                let t_max = d - (1e-4 * d).max(self.eps);
                if t_max <= 0.0 || self.visible(x, to, t_max) {
                    let d = d.max(MIN_DISTANCE);
                    let unit_radiance = (-to.dot(p.normal)).max(0.0) / (d * d);
                    let pos = (x + to * d).to_array();
                    let emitter = Emitter::Area { intensity: 1.0, position: pos, normal: p.normal.to_array() };
                    self.probe_connection(x, to, d, p.intensity, unit_radiance, 1.0, &emitter, w_s, &mut sh, &mut add)?;
                }
            }
            if self.opts.bounces == 0 {
                continue;
            }
            let z = 1.0 - 2.0 * s.uniform(3);
            let r = (1.0 - z * z).max(0.0).sqrt();
            let phi = 2.0 * std::f64::consts::PI * s.uniform(4);
            let dir = DVec3::new(r * phi.cos(), r * phi.sin(), z);
            rays += 1;
            let Some(hit) = self.trace(x, dir) else { continue };
            let rho = self.albedo.get(hit.mesh).copied().unwrap_or([0.0; 3]);
            if rho.iter().all(|&a| a == 0.0) {
                continue;
            }
            let yp = x + hit.t * dir;
            let (ny, nyg) = facing(&hit, dir);
            let uy = [0, 1, 2, 3, 4].map(|d| s.uniform(8 + d));
            let ed = self.delta_irradiance(yp, ny, nyg, 1.0, &mut rays)?;
            let es = self.sampled_irradiance(yp, ny, nyg, uy, &s, (2, self.opts.bounces - 1), 1.0, &mut rays)?;
            let (ed, es) = (ed.total(), es.total());
            let l_o = [0, 1, 2].map(|c| rho[c] / std::f64::consts::PI * (ed[c] + es[c]));
            let four_pi = 4.0 * std::f64::consts::PI;
            let cos_y = (-dir.dot(ny)).max(GRAZING_FLOOR);
            let d = hit.t;
            // Direct: the radiance L_o itself over the sampling pdf 1/(4π); scattered: the patch
            // dA = 4π r² / cos θ_y.
            let emitter = Emitter::Area { intensity: 1.0, position: yp.to_array(), normal: ny.to_array() };
            let scale = four_pi * d * d / cos_y;
            self.probe_connection(x, dir, d, l_o, four_pi, scale, &emitter, w_s, &mut sh, &mut add)?;
        }
        Ok(sh)
    }

    /// Adds one probe connection in direction `to`: radiance `strength · unit_radiance` (times the
    /// transmittance) as a weighted delta, and in Full mode the scattered radiance of the unit emitter times
    /// `strength · scatter_scale`, all times the sample weight `w`.
    #[allow(clippy::too_many_arguments)]
    fn probe_connection(
        &self,
        x: DVec3,
        to: DVec3,
        length: f64,
        strength: [f64; 3],
        unit_radiance: f64,
        scatter_scale: f64,
        emitter: &Emitter,
        w: f64,
        sh: &mut [[f64; PROBE_SH]; 3],
        add: &mut impl FnMut(DVec3, [f64; 3], &mut [[f64; PROBE_SH]; 3]),
    ) -> Result<(), TransportError> {
        let along =
            if self.opts.mode == BakeMode::Surface || !self.has_media { None } else { self.along(x, to, length) };
        let t = along.map_or([1.0; 3], |a| a.transmittance);
        add(to, [0, 1, 2].map(|c| w * strength[c] * unit_radiance * t[c]), sh);
        if self.opts.mode != BakeMode::Full {
            return Ok(());
        }
        let Some(a) = along else { return Ok(()) };
        let table = self.table.ok_or(TransportError::NoTable)?;
        let receiver = Receiver { position: x.to_array(), normal: to.to_array() };
        let query = QueryOptions { backscatter: false, ..self.query };
        for c in 0..3 {
            let ch = a.channels[c];
            if ch.sigma_s <= 0.0 {
                continue;
            }
            let rad = table.radiance(&ch, emitter, &receiver, &query)?;
            for i in 0..PROBE_SH.min(rad.sh.len()) {
                sh[c][i] += w * strength[c] * scatter_scale * rad.sh[i];
            }
        }
        Ok(())
    }

    /// Irradiance from the delta lights (deterministic).
    fn delta_irradiance(&self, x: DVec3, n: DVec3, ng: DVec3, sw: f64, rays: &mut u64) -> Result<Irr, TransportError> {
        let mut sources = Vec::with_capacity(self.lights.delta_count());
        self.lights.deltas_toward(x, &mut sources);
        let mut e = Irr::default();
        for src in &sources {
            e.add(&self.connect_light(x, n, ng, src, sw, rays)?);
        }
        Ok(e)
    }

    /// One sample of the irradiance from area lights and (with `bounces > 0`) from surfaces.
    #[allow(clippy::too_many_arguments)]
    fn sampled_irradiance(
        &self,
        x: DVec3,
        n: DVec3,
        ng: DVec3,
        u: [f64; 5],
        s: &SampleStream,
        (depth, bounces): (u32, u32),
        sw: f64,
        rays: &mut u64,
    ) -> Result<Irr, TransportError> {
        let mut e = Irr::default();
        if let Some(p) = self.lights.sample_area([u[0], u[1], u[2]]) {
            e.add(&self.connect_light(x, n, ng, &Source::Patch(p), sw, rays)?);
        }
        if bounces == 0 {
            return Ok(e);
        }
        // Cosine-weighted bounce direction.
        let (t1, t2) = frame(n);
        let r = u[3].sqrt();
        let phi = 2.0 * std::f64::consts::PI * u[4];
        let z = (1.0 - u[3]).max(0.0).sqrt();
        let dir = r * phi.cos() * t1 + r * phi.sin() * t2 + z * n;
        if dir.dot(ng) <= 0.0 {
            return Ok(e); // below the geometric surface (shading-normal mismatch)
        }
        let origin = offset(x, ng, self.eps);
        *rays += 1;
        let Some(hit) = self.trace(origin, dir) else { return Ok(e) };
        let y = origin + hit.t * dir;
        let rho = self.albedo.get(hit.mesh).copied().unwrap_or([0.0; 3]);
        if rho.iter().all(|&a| a == 0.0) {
            return Ok(e);
        }
        let (ny, nyg) = facing(&hit, dir);
        let base = 8 * depth;
        let uy = [0, 1, 2, 3, 4].map(|d| s.uniform(base + d));
        let ey_delta = self.delta_irradiance(y, ny, nyg, sw, rays)?;
        let ey_s = self.sampled_irradiance(y, ny, nyg, uy, s, (depth + 1, bounces - 1), sw, rays)?;
        let f = rho.map(|r| r / std::f64::consts::PI);
        let l_plain = [0, 1, 2].map(|c| f[c] * (ey_delta.plain[c] + ey_s.plain[c]));
        let l_scat = [0, 1, 2].map(|c| f[c] * (ey_delta.scat[c] + ey_s.scat[c]));
        if l_plain.iter().chain(&l_scat).all(|&l| l == 0.0) {
            return Ok(e);
        }
        let scattered_weight = self.opts.mode == BakeMode::Full && self.has_media && sw > 0.0;
        let along =
            if self.opts.mode == BakeMode::Surface || !self.has_media { None } else { self.along(origin, dir, hit.t) };
        let t = along.map_or([1.0; 3], |a| a.transmittance);
        for c in 0..3 {
            e.plain[c] += std::f64::consts::PI * l_plain[c] * t[c];
            e.scat[c] += std::f64::consts::PI * l_scat[c] * t[c];
        }
        if scattered_weight && let Some(a) = along {
            let cos_x = dir.dot(n).max(1e-6);
            let cos_y = (-dir.dot(ny)).max(GRAZING_FLOOR);
            let r = hit.t * dir.length();
            let w = std::f64::consts::PI * r * r / (cos_x * cos_y);
            let patch = Emitter::Area { intensity: 1.0, position: y.to_array(), normal: ny.to_array() };
            let sc = self.scattered(&a, &patch, x, n)?;
            for c in 0..3 {
                // Plain light from y gets this query's weight; light already queried keeps its own.
                e.scat[c] += sc[c] * w * (sw * l_plain[c] + l_scat[c]);
            }
        }
        Ok(e)
    }

    /// Irradiance at `x` from one light connection (visibility tested), split into direct and scattered.
    fn connect_light(
        &self,
        x: DVec3,
        n: DVec3,
        ng: DVec3,
        src: &Source,
        sw: f64,
        rays: &mut u64,
    ) -> Result<Split, TransportError> {
        let origin = offset(x, ng, self.eps);
        match *src {
            Source::Point { position, intensity } => {
                let (to, d) = direction_to(x, position);
                *rays += 1;
                let (vis_dir, vis_d) = direction_to(origin, position);
                if !self.visible(origin, vis_dir, vis_d) {
                    return Ok(Split::default());
                }
                let d = d.max(MIN_DISTANCE);
                let cos = to.dot(n).max(0.0);
                let direct_unit = cos / (d * d);
                let emitter = Emitter::Point { intensity: 1.0, position: (x + to * d).to_array() };
                self.weigh((origin, to, d), (x, n), direct_unit, intensity, &emitter, sw)
            }
            Source::Directional { toward, irradiance } => {
                *rays += 1;
                if !self.visible(origin, toward, f64::INFINITY) {
                    return Ok(Split::default());
                }
                let depth = exit_distance(origin, toward, self.world);
                let direct_unit = toward.dot(n).max(0.0);
                let emitter = Emitter::Directional { irradiance: 1.0, toward_light: toward.to_array(), depth };
                self.weigh((origin, toward, depth), (x, n), direct_unit, irradiance, &emitter, sw)
            }
            Source::Patch(Patch { position, normal, intensity }) => {
                let (to, d) = direction_to(x, position);
                *rays += 1;
                let (vis_dir, vis_d) = direction_to(origin, position);
                let t_max = vis_d - (1e-4 * vis_d).max(self.eps);
                if t_max > 0.0 && !self.visible(origin, vis_dir, t_max) {
                    return Ok(Split::default());
                }
                let d = d.max(MIN_DISTANCE);
                let direct_unit = to.dot(n).max(0.0) * (-to.dot(normal)).max(0.0) / (d * d);
                let position = (x + to * d).to_array();
                let emitter = Emitter::Area { intensity: 1.0, position, normal: normal.to_array() };
                self.weigh((origin, to, d), (x, n), direct_unit, intensity, &emitter, sw)
            }
        }
    }

    /// Weighs a unit-strength connection of vacuum irradiance `direct_unit` by the mode.
    #[allow(clippy::too_many_arguments)]
    fn weigh(
        &self,
        (origin, to, length): (DVec3, DVec3, f64),
        (x, n): (DVec3, DVec3),
        direct_unit: f64,
        strength: [f64; 3],
        emitter: &Emitter,
        sw: f64,
    ) -> Result<Split, TransportError> {
        let mut out = Split { direct: strength.map(|s| s * direct_unit), scattered: [0.0; 3] };
        if self.opts.mode == BakeMode::Surface || !self.has_media {
            return Ok(out);
        }
        let Some(a) = self.along(origin, to, length) else { return Ok(out) };
        for c in 0..3 {
            out.direct[c] *= a.transmittance[c];
        }
        if self.opts.mode == BakeMode::Full && sw > 0.0 {
            let sc = self.scattered(&a, emitter, x, n)?;
            for c in 0..3 {
                out.scattered[c] = sc[c] * strength[c] * sw;
            }
        }
        Ok(out)
    }

    /// Scattered irradiance (single + multiple) per channel for a unit-strength emitter, querying the table
    /// once per distinct effective medium among the channels.
    fn scattered(&self, a: &Along, emitter: &Emitter, x: DVec3, n: DVec3) -> Result<[f64; 3], TransportError> {
        let table = self.table.ok_or(TransportError::NoTable)?;
        let receiver = Receiver { position: x.to_array(), normal: n.to_array() };
        let mut out = [0.0; 3];
        for c in 0..3 {
            let ch = a.channels[c];
            if let Some(prev) = (0..c).find(|&p| a.channels[p] == ch) {
                out[c] = out[prev];
                continue;
            }
            if ch.sigma_s <= 0.0 {
                continue;
            }
            let irr = table.irradiance(&ch, emitter, &receiver, &self.query)?;
            out[c] = irr.single + irr.multiple;
        }
        Ok(out)
    }

    /// Transmittance and effective coefficients along `origin + t·dir`, `t ∈ [0, length]` (`dir` unit);
    /// `None` when no medium is crossed.
    fn along(&self, origin: DVec3, dir: DVec3, length: f64) -> Option<Along> {
        if length.is_nan() || length <= 0.0 {
            return None;
        }
        let ray = Ray::new(origin.to_array(), dir.to_array());
        let segs = self.bvh.media_segments(self.scene, &ray, length);
        let (mut tau_t, mut tau_s, mut tau_a, mut tau_g) = ([0.0f64; 3], [0.0f64; 3], [0.0f64; 3], [0.0f64; 3]);
        let mut any = false;
        for seg in &segs {
            let Some(m) = seg.medium.and_then(|i| self.scene.media.get(i)) else { continue };
            let t = optical_thickness(self.scene, std::slice::from_ref(seg), &ray);
            let st = m.sigma_t();
            for c in 0..3 {
                if st[c] > 0.0 && t[c] > 0.0 {
                    any = true;
                    tau_t[c] += t[c];
                    let s = t[c] * m.sigma_s[c] / st[c];
                    tau_s[c] += s;
                    tau_a[c] += t[c] * m.sigma_a[c] / st[c];
                    tau_g[c] += s * m.g[c];
                }
            }
        }
        if !any {
            return None;
        }
        let transmittance = tau_t.map(|t| (-t).exp());
        let channels = [0, 1, 2].map(|c| HomogeneousMedium {
            sigma_s: tau_s[c] / length,
            sigma_a: tau_a[c] / length,
            g: if tau_s[c] > 0.0 { (tau_g[c] / tau_s[c]).clamp(-0.999, 0.999) } else { 0.0 },
        });
        Some(Along { transmittance, channels })
    }

    /// Closest opaque hit along `origin + t·dir`, passing through index-matched medium boundaries.
    fn trace(&self, origin: DVec3, dir: DVec3) -> Option<Hit> {
        self.trace_ray(Ray::new(origin.to_array(), dir.to_array()))
    }

    /// Whether `origin + t·dir`, `t ∈ (0, t_max)`, is free of opaque surfaces.
    fn visible(&self, origin: DVec3, dir: DVec3, t_max: f64) -> bool {
        let (origin, dir) = (origin.to_array(), dir.to_array());
        if !self.any_pass_through {
            return !self.bvh.occluded(origin, dir, t_max);
        }
        let mut ray = Ray::new(origin, dir);
        ray.t_max = t_max;
        self.trace_ray(ray).is_none()
    }

    /// [`Self::trace`] within the ray's own range (up to 64 index-matched boundaries are passed).
    fn trace_ray(&self, mut ray: Ray) -> Option<Hit> {
        for _ in 0..64 {
            let hit = self.bvh.closest_hit(&ray)?;
            if !self.pass_through.get(hit.mesh).copied().unwrap_or(false) {
                return Some(hit);
            }
            ray.t_min = hit.t;
        }
        None
    }
}

pub use crate::render::color::luminance;

/// `x` moved `eps` along `n`.
fn offset(x: DVec3, n: DVec3, eps: f64) -> DVec3 {
    x + eps * n
}

/// Unit direction and distance from `a` to `b` (`+z`, 0 when they coincide).
fn direction_to(a: DVec3, b: DVec3) -> (DVec3, f64) {
    let v = b - a;
    let d = v.length();
    match unit(v) {
        Some(u) => (u, d),
        None => (DVec3::Z, 0.0),
    }
}

/// Shading and geometric normals of a hit, turned to face against `dir`.
fn facing(hit: &Hit, dir: DVec3) -> (DVec3, DVec3) {
    let ng = unit(DVec3::from_array(hit.geometric_normal)).unwrap_or(DVec3::Z);
    let ng = if ng.dot(dir) > 0.0 { -ng } else { ng };
    let ns = unit(DVec3::from_array(hit.shading_normal)).unwrap_or(ng);
    let ns = if ns.dot(ng) < 0.0 { -ns } else { ns };
    (ns, ng)
}

/// Distance from `o` along unit `d` to where the ray leaves the box `world` (0 when `o` is outside and
/// moving away).
fn exit_distance(o: DVec3, d: DVec3, world: (DVec3, DVec3)) -> f64 {
    let mut t_exit = f64::INFINITY;
    for c in 0..3 {
        if d[c] > 0.0 {
            t_exit = t_exit.min((world.1[c] - o[c]) / d[c]);
        } else if d[c] < 0.0 {
            t_exit = t_exit.min((world.0[c] - o[c]) / d[c]);
        }
    }
    if t_exit.is_finite() { t_exit.max(0.0) } else { 0.0 }
}
