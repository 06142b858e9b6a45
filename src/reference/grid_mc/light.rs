//! Light tracing with expected-value (uncollided) and track-length (collided) tallies.

use std::time::Instant;

use glam::DVec3;
use rayon::prelude::*;

use super::grid::{Grid, Voxels, rotate};
use super::{LightTraceOptions, RadianceTally, TallySpec, Walk, Welford, light_dir, roulette, seed_hash, walks};
use crate::physics::hg::sample_mu;
use crate::physics::rng::{Draws, StreamKey};
use crate::render::voxel::{DirectionalLight, VoxelMedium};

/// Batches for the standard errors.
const BATCHES: u64 = 64;

/// One batch's sums.
struct Acc {
    fluence: Vec<[f64; 3]>,
    uncollided: Vec<[f64; 3]>,
    radiance: Vec<[f64; 3]>,
    escaped: [f64; 3],
    absorbed: [f64; 3],
    truncated: [f64; 3],
}

impl Acc {
    fn new(cells: usize, bins: usize) -> Self {
        Acc {
            fluence: vec![[0.0; 3]; cells],
            uncollided: vec![[0.0; 3]; cells],
            radiance: vec![[0.0; 3]; cells * bins],
            escaped: [0.0; 3],
            absorbed: [0.0; 3],
            truncated: [0.0; 3],
        }
    }
}

/// Everything a photon needs, shared by all batches.
struct Setup<'a> {
    vox: Voxels<'a>,
    tally: Grid,
    inv_volume: f64,
    bins: usize,
    inv_solid_angle: Vec<f64>,
    axis: DVec3,
    dir: DVec3,
    /// `|dir_i|·area_i` per axis (the front faces' projected areas).
    face_weight: [f64; 3],
    a_perp: f64,
    walks: Vec<Walk>,
    key: u64,
    photons: u64,
    max_events: u32,
}

impl Setup<'_> {
    /// The polar bin of direction `d` and `1/ΔΩ` of it.
    fn bin(&self, d: DVec3) -> Option<(usize, f64)> {
        if self.bins == 0 {
            return None;
        }
        let theta = d.dot(self.axis).clamp(-1.0, 1.0).acos();
        let b = ((theta / std::f64::consts::PI * self.bins as f64) as usize).min(self.bins - 1);
        Some((b, self.inv_solid_angle[b]))
    }

    /// Adds `amount` (\[W·m\] per unit irradiance) of track length in cell `k` with direction bin `bin`.
    fn score(&self, acc: &mut Acc, k: usize, amount: f64, e: &[f64; 3], bin: Option<(usize, f64)>, uncollided: bool) {
        let x = amount * self.inv_volume;
        add_scaled(&mut acc.fluence[k], x, e);
        if uncollided {
            add_scaled(&mut acc.uncollided[k], x, e);
        }
        if let Some((b, inv_sa)) = bin {
            add_scaled(&mut acc.radiance[k * self.bins + b], x * inv_sa, e);
        }
    }

    /// Photon `i`: every walk with the same random numbers.
    fn photon(&self, i: u64, acc: &mut Acc) {
        let stream = StreamKey { table: self.key, cell: i }.sample(0);
        for walk in &self.walks {
            self.walk(walk, Draws::new(stream), acc);
        }
    }

    fn walk(&self, walk: &Walk, mut dr: Draws, acc: &mut Acc) {
        let (min, max) = (self.tally.min, self.tally.max);
        // Start: a front face ∝ its projected area, a point uniform on it.
        let mut u = dr.draw() * self.a_perp;
        let mut face = 0;
        for a in 0..3 {
            if self.face_weight[a] > 0.0 {
                face = a;
                if u < self.face_weight[a] {
                    break;
                }
                u -= self.face_weight[a];
            }
        }
        let (u1, u2) = (dr.draw(), dr.draw());
        let mut p = DVec3::ZERO;
        let (a1, a2) = ((face + 1) % 3, (face + 2) % 3);
        p[face] = if self.dir[face] > 0.0 { min[face] } else { max[face] };
        p[a1] = min[a1] + u1 * (max[a1] - min[a1]);
        p[a2] = min[a2] + u2 * (max[a2] - min[a2]);
        let mut d = self.dir;
        let w0 = self.a_perp / self.photons as f64;
        let mut w = w0;
        let e = &walk.e;
        let add = |v: &mut [f64; 3], w: f64| add_scaled(v, w, e);
        let mut events = 0u32;
        let mut collided = false;
        loop {
            let Some((t0, t1)) = self.vox.clip(p, d, 0.0) else {
                add(&mut acc.escaped, w);
                return;
            };
            let xi = dr.draw();
            let target = if walk.sigma_t > 0.0 { -(-xi).ln_1p() / walk.sigma_t } else { f64::INFINITY };
            let hit = self.vox.invert(p, d, t0, t1, target);
            let bin = self.bin(d);
            if collided {
                let end = hit.unwrap_or(t1);
                self.tally.walk(p, d, t0, end, |k, a, b| {
                    self.score(acc, k, w * (b - a), e, bin, false);
                    true
                });
            } else {
                self.uncollided(walk, p, d, t0, t1, w, bin, acc);
            }
            let Some(t) = hit else {
                add(&mut acc.escaped, w);
                return;
            };
            p += d * t;
            events += 1;
            let albedo = walk.albedo();
            add(&mut acc.absorbed, w * (1.0 - albedo));
            w *= albedo;
            if w <= 0.0 {
                return;
            }
            if events > self.max_events {
                add(&mut acc.truncated, w);
                return;
            }
            match roulette(w, w0, dr.draw()) {
                Some(v) => w = v,
                None => return,
            }
            let mu = sample_mu(dr.draw(), walk.g);
            d = rotate(d, mu, dr.draw());
            collided = true;
        }
    }

    /// Expected track length of the uncollided flight along `p + t d`, `t ∈ [t0, t1]`: per piece
    /// `[u, v]` in one voxel and one tally cell, `w·T(u)·(1 − e^{−σ_t(v − u)})/σ_t`.
    #[allow(clippy::too_many_arguments)]
    fn uncollided(
        &self,
        walk: &Walk,
        p: DVec3,
        d: DVec3,
        t0: f64,
        t1: f64,
        w: f64,
        bin: Option<(usize, f64)>,
        acc: &mut Acc,
    ) {
        let mut depth = 0.0_f64;
        self.vox.grid.walk(p, d, t0, t1, |i, a, b| {
            let sigma = walk.sigma_t * f64::from(self.vox.density[i]);
            let ta = (-depth).exp();
            self.tally.walk(p, d, a, b, |k, u, v| {
                let len = v - u;
                let x = sigma * len;
                let integral =
                    if x > 0.0 { ta * (-sigma * (u - a)).exp() * (-(-x).exp_m1()) / sigma } else { ta * len };
                self.score(acc, k, w * integral, &walk.e, bin, true);
                true
            });
            depth += sigma * (b - a);
            true
        });
    }
}

/// `dst += x·v` per channel.
fn add_scaled(dst: &mut [f64; 3], x: f64, v: &[f64; 3]) {
    for (d, s) in dst.iter_mut().zip(v) {
        *d += x * s;
    }
}

/// Light tracing through `medium` from `light` into the tally `spec` (module doc for the
/// estimators, standard errors, channel walks and determinism). Runs in parallel on the current
/// rayon pool; results are bit-identical for any pool size. Degenerate inputs give zeros (module
/// doc, "Robustness").
pub fn light_trace(
    medium: &VoxelMedium,
    light: &DirectionalLight,
    spec: &TallySpec,
    opts: &LightTraceOptions,
) -> RadianceTally {
    let start = Instant::now();
    let cells = spec.dims.iter().try_fold(1usize, |n, &d| n.checked_mul(d)).unwrap_or(0);
    let bins = spec.theta_bins;
    let rad_len = cells.checked_mul(bins).unwrap_or(0);
    let mut out = RadianceTally {
        dims: spec.dims,
        theta_bins: bins,
        fluence: vec![[0.0; 3]; cells],
        fluence_std_err: vec![[0.0; 3]; cells],
        uncollided_fluence: vec![[0.0; 3]; cells],
        radiance: vec![[0.0; 3]; rad_len],
        radiance_std_err: vec![[0.0; 3]; rad_len],
        photons: opts.photons,
        walks: 0,
        seconds: 0.0,
        truncated_fraction: 0.0,
        injected: [0.0; 3],
        escaped: [0.0; 3],
        escaped_std_err: [0.0; 3],
        absorbed: [0.0; 3],
        absorbed_std_err: [0.0; 3],
    };
    let walks = walks(medium, light);
    out.walks = walks.len() as u32;
    let Some(dir) = light_dir(light) else {
        out.seconds = start.elapsed().as_secs_f64();
        return out;
    };
    if opts.photons == 0 || cells == 0 || (bins > 0 && rad_len == 0) {
        out.seconds = start.elapsed().as_secs_f64();
        return out;
    }
    let ext = medium.max - medium.min;
    let face_weight = [dir.x.abs() * ext.y * ext.z, dir.y.abs() * ext.x * ext.z, dir.z.abs() * ext.x * ext.y];
    let a_perp: f64 = face_weight.iter().sum();
    let axis = if spec.axis.is_finite() { spec.axis.try_normalize().unwrap_or(dir) } else { dir };
    let pi = std::f64::consts::PI;
    let inv_solid_angle = (0..bins)
        .map(|b| {
            let (t0, t1) = (b as f64 * pi / bins as f64, (b + 1) as f64 * pi / bins as f64);
            1.0 / (std::f64::consts::TAU * (t0.cos() - t1.cos()))
        })
        .collect();
    let tally = Grid::new(medium.min, medium.max, spec.dims);
    let setup = Setup {
        vox: Voxels::new(medium),
        tally,
        inv_volume: 1.0 / tally.cell_volume(),
        bins,
        inv_solid_angle,
        axis,
        dir,
        face_weight,
        a_perp,
        walks,
        key: seed_hash(opts.seed, 0x6772_6964_5f6d_6331), // "grid_mc1"
        photons: opts.photons,
        max_events: opts.max_events,
    };
    for w in &setup.walks {
        add_scaled(&mut out.injected, a_perp, &w.e);
    }

    let n = opts.photons;
    let batches = BATCHES.min(n);
    let range = |b: u64| {
        let lo = (u128::from(b) * u128::from(n) / u128::from(batches)) as u64;
        let hi = (u128::from(b + 1) * u128::from(n) / u128::from(batches)) as u64;
        (lo, hi)
    };
    let mut w_fluence = Welford::new(cells);
    let mut w_radiance = Welford::new(rad_len);
    let mut w_escaped = Welford::new(1);
    let mut w_absorbed = Welford::new(1);
    let mut truncated = [0.0; 3];
    let chunk = rayon::current_num_threads().clamp(1, batches as usize) as u64;
    let mut b0 = 0;
    while b0 < batches {
        let b1 = (b0 + chunk).min(batches);
        let results: Vec<Acc> = (b0..b1)
            .into_par_iter()
            .map(|b| {
                let mut acc = Acc::new(cells, bins);
                let (lo, hi) = range(b);
                for i in lo..hi {
                    setup.photon(i, &mut acc);
                }
                acc
            })
            .collect();
        for (b, acc) in (b0..b1).zip(results) {
            let (lo, hi) = range(b);
            let scale = n as f64 / (hi - lo) as f64;
            let sum = |dst: &mut [[f64; 3]], src: &[[f64; 3]]| {
                for (d, s) in dst.iter_mut().zip(src) {
                    add_scaled(d, 1.0, s);
                }
            };
            sum(&mut out.fluence, &acc.fluence);
            sum(&mut out.uncollided_fluence, &acc.uncollided);
            sum(&mut out.radiance, &acc.radiance);
            sum(std::slice::from_mut(&mut out.escaped), &[acc.escaped]);
            sum(std::slice::from_mut(&mut out.absorbed), &[acc.absorbed]);
            sum(std::slice::from_mut(&mut truncated), &[acc.truncated]);
            w_fluence.push(&acc.fluence, scale);
            w_radiance.push(&acc.radiance, scale);
            w_escaped.push(&[acc.escaped], scale);
            w_absorbed.push(&[acc.absorbed], scale);
        }
        b0 = b1;
    }
    out.fluence_std_err = w_fluence.std_err();
    out.radiance_std_err = w_radiance.std_err();
    out.escaped_std_err = w_escaped.std_err()[0];
    out.absorbed_std_err = w_absorbed.std_err()[0];
    let injected: f64 = out.injected.iter().sum();
    out.truncated_fraction = if injected > 0.0 { truncated.iter().sum::<f64>() / injected } else { 0.0 };
    out.seconds = start.elapsed().as_secs_f64();
    out
}
