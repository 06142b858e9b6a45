//! Camera path tracing with next-event estimation toward the directional light or an environment map.

use std::time::Instant;

use glam::DVec3;
use rayon::prelude::*;

use super::grid::{Voxels, rotate};
use super::{CameraOptions, ReferenceImage, Walk, light_dir, roulette, seed_hash, walks};
use crate::physics::hg::{phase, sample_mu};
use crate::physics::rng::{Draws, SampleStream, StreamKey};
use crate::render::ViewCamera;
use crate::render::color::Rgb;
use crate::render::environment::{EnvMap, EnvSampler};
use crate::render::occluder::{NoOccluder, Occluder};
use crate::render::voxel::{DirectionalLight, VoxelMedium};

/// One pixel's result.
struct Pixel {
    radiance: [f64; 3],
    variance: [f64; 3],
    single: [f64; 3],
    single_variance: [f64; 3],
    transmittance: [f64; 3],
    truncated: u64,
}

/// Where next-event estimation connects.
enum Lighting<'a> {
    /// Toward a directional light travelling along this unit direction.
    Directional(DVec3),
    /// Toward a direction drawn from the map's importance sampler.
    Environment(&'a EnvMap, EnvSampler),
}

struct Setup<'a> {
    vox: Voxels<'a>,
    walks: Vec<Walk>,
    sigma_t: [f64; 3],
    lighting: Option<Lighting<'a>>,
    occluder: &'a dyn Occluder,
    key: u64,
    opts: CameraOptions,
}

impl Setup<'_> {
    /// One path of `walk` from `o` along `d`, ending at the first surface (black) or `far` for the
    /// first flight: (radiance per channel per unit `e` of the walk, its once-scattered part, whether
    /// `max_events` cut it with weight left). The caller multiplies by the walk's `e`.
    fn path(
        &self,
        walk: &Walk,
        lighting: &Lighting<'_>,
        o: DVec3,
        d: DVec3,
        far: f64,
        mut dr: Draws,
    ) -> (Rgb, Rgb, bool) {
        let (mut p, mut d, mut far) = (o, d, far);
        let mut beta = 1.0;
        let (mut total, mut single) = ([0.0; 3], [0.0; 3]);
        let mut events = 0u32;
        while let Some((t0, t1)) = self.vox.clip(p, d, 0.0) {
            let t1 = t1.min(far);
            if t1 <= t0 {
                break;
            }
            let xi = dr.draw();
            let target = if events == 0 && matches!(lighting, Lighting::Environment(..)) {
                // Forced first collision: draw the flight inside the segment, weighted by the probability
                // of colliding there at all (1 − T), so thin media are not mostly missed.
                let tau = walk.sigma_t * self.vox.density_integral(p, d, t0, t1);
                let hit = -(-tau).exp_m1();
                if hit <= 0.0 {
                    break;
                }
                beta *= hit;
                -(-xi * hit).ln_1p() / walk.sigma_t
            } else if walk.sigma_t > 0.0 {
                -(-xi).ln_1p() / walk.sigma_t
            } else {
                f64::INFINITY
            };
            let Some(t) = self.vox.invert(p, d, t0, t1, target) else { break };
            p += d * t;
            if events == self.opts.max_events {
                return (total, single, true);
            }
            events += 1;
            let albedo = walk.albedo();
            let nee = match lighting {
                Lighting::Directional(light) => {
                    let shadow = if self.occluder.ray_blocked(p, -*light) {
                        0.0
                    } else {
                        (-walk.sigma_t * self.vox.density_to_exit(p, -*light)).exp()
                    };
                    [beta * albedo * phase(light.dot(-d), walk.g) * shadow; 3]
                }
                Lighting::Environment(env, sampler) => {
                    let (w, pdf) = sampler.sample(dr.draw(), dr.draw(), dr.draw());
                    if pdf > 0.0 && !self.occluder.ray_blocked(p, w) {
                        let shadow = (-walk.sigma_t * self.vox.density_to_exit(p, w)).exp();
                        // Light arrives travelling along −w and leaves toward the eye along −d.
                        let f = beta * albedo * phase(w.dot(d), walk.g) * shadow / pdf;
                        let l = env.lookup(w);
                        l.map(|v| f * v)
                    } else {
                        [0.0; 3]
                    }
                }
            };
            for c in 0..3 {
                total[c] += nee[c];
            }
            if events == 1 {
                single = nee;
            }
            beta *= albedo;
            if beta <= 0.0 {
                break;
            }
            match roulette(beta, 1.0, dr.draw()) {
                Some(b) => beta = b,
                None => break,
            }
            d = rotate(d, sample_mu(dr.draw(), walk.g), dr.draw());
            far = self.occluder.hit_distance(p, d);
        }
        (total, single, false)
    }

    fn pixel(&self, camera: &ViewCamera, surface: Option<&[f64]>, i: usize) -> Pixel {
        let (x, y) = (i % camera.width, i / camera.width);
        let o = camera.position;
        let d = camera.pixel_dir(x, y);
        let far = match surface {
            Some(s) => s.get(i).copied().unwrap_or(f64::INFINITY),
            None if d.is_finite() => self.occluder.hit_distance(o, d),
            None => 0.0,
        };
        let depth = if d.is_finite() {
            self.vox.clip(o, d, 0.0).map_or(0.0, |(t0, t1)| {
                let t1 = t1.min(far);
                if t1 > t0 { self.vox.density_integral(o, d, t0, t1) } else { 0.0 }
            })
        } else {
            0.0
        };
        let transmittance = self.sigma_t.map(|s| (-s * depth).exp());
        let mut px = Pixel {
            radiance: [0.0; 3],
            variance: [0.0; 3],
            single: [0.0; 3],
            single_variance: [0.0; 3],
            transmittance,
            truncated: 0,
        };
        let Some(lighting) = &self.lighting else { return px };
        if !d.is_finite() || self.opts.samples == 0 {
            return px;
        }
        let key = StreamKey { table: self.key, cell: i as u64 };
        let (mut m2, mut m2_single) = ([0.0; 3], [0.0; 3]);
        for s in 0..self.opts.samples {
            let stream: SampleStream = key.sample(u64::from(s));
            let (mut v, mut v1) = ([0.0; 3], [0.0; 3]);
            for walk in &self.walks {
                let (l, l1, cut) = self.path(walk, lighting, o, d, far, Draws::new(stream));
                px.truncated += u64::from(cut);
                for c in 0..3 {
                    v[c] += l[c] * walk.e[c];
                    v1[c] += l1[c] * walk.e[c];
                }
            }
            let n = f64::from(s + 1);
            for c in 0..3 {
                let delta = v[c] - px.radiance[c];
                px.radiance[c] += delta / n;
                m2[c] += delta * (v[c] - px.radiance[c]);
                let delta1 = v1[c] - px.single[c];
                px.single[c] += delta1 / n;
                m2_single[c] += delta1 * (v1[c] - px.single[c]);
            }
        }
        let n = f64::from(self.opts.samples);
        if self.opts.samples > 1 {
            px.variance = m2.map(|q| q.max(0.0) / (n * (n - 1.0)));
            px.single_variance = m2_single.map(|q| q.max(0.0) / (n * (n - 1.0)));
        }
        px
    }
}

/// Renders `medium` lit by `light` from `camera`: pixel-centre rays, path tracing with next-event
/// estimation (module doc). Runs in parallel over pixels on the current rayon pool; bit-identical
/// for any pool size. An unusable light direction gives black radiance (transmittance still
/// exact); zero samples give zeros.
pub fn render(
    medium: &VoxelMedium,
    light: &DirectionalLight,
    camera: &ViewCamera,
    opts: &CameraOptions,
) -> ReferenceImage {
    let setup = Setup {
        vox: Voxels::new(medium),
        sigma_t: medium.coefficients.sigma_t(),
        walks: walks(medium, light),
        lighting: light_dir(light).map(Lighting::Directional),
        occluder: &NoOccluder,
        key: seed_hash(opts.seed, 0x6772_6964_5f6d_6332), // "grid_mc2"
        opts: *opts,
    };
    run(&setup, camera, None)
}

/// Renders `medium` lit by the environment map `env` from `camera`, with the opaque, black surfaces
/// of `occluder` (module doc, "Environment"). `surface_distance` (per pixel, `INFINITY` where the ray
/// escapes; `None`: asked of `occluder`) ends the eye ray. Bit-identical for any pool size.
pub fn render_environment(
    medium: &VoxelMedium,
    env: &EnvMap,
    occluder: &dyn Occluder,
    camera: &ViewCamera,
    surface_distance: Option<&[f64]>,
    opts: &CameraOptions,
) -> ReferenceImage {
    let unit = DirectionalLight { direction: DVec3::X, irradiance: [1.0; 3] };
    let setup = Setup {
        vox: Voxels::new(medium),
        sigma_t: medium.coefficients.sigma_t(),
        walks: walks(medium, &unit),
        lighting: Some(Lighting::Environment(env, EnvSampler::new(env))),
        occluder,
        key: seed_hash(opts.seed, 0x6772_6964_5f65_6e76), // "grid_env"
        opts: *opts,
    };
    run(&setup, camera, surface_distance)
}

fn run(setup: &Setup<'_>, camera: &ViewCamera, surface: Option<&[f64]>) -> ReferenceImage {
    let start = Instant::now();
    let n = camera.width.checked_mul(camera.height).unwrap_or(0);
    let pixels: Vec<Pixel> = (0..n).into_par_iter().map(|i| setup.pixel(camera, surface, i)).collect();
    ReferenceImage {
        width: if n == 0 { 0 } else { camera.width },
        height: if n == 0 { 0 } else { camera.height },
        radiance: pixels.iter().map(|p| p.radiance).collect(),
        variance: pixels.iter().map(|p| p.variance).collect(),
        single: pixels.iter().map(|p| p.single).collect(),
        single_variance: pixels.iter().map(|p| p.single_variance).collect(),
        transmittance: pixels.iter().map(|p| p.transmittance).collect(),
        seconds: start.elapsed().as_secs_f64(),
        samples: setup.opts.samples,
        walks: setup.walks.len() as u32,
        truncated_paths: pixels.iter().map(|p| p.truncated).sum(),
    }
}
