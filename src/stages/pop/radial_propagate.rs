//! Principal-ordinates propagation from a point light on its radial grid (elek2014 Sec. 6, with the
//! scheme of Secs. 4.1–4.3 and the residuum of Sec. 5.4).
//!
//! **Input → output.** A [`RadialGrid`], a [`PointLight`] (isotropic, or a spot's KHR cone profile), the
//! scene's surfaces, the preset's flow table and iteration settings, and an eye → per cell the
//! uncollided and collided fluence and the collided radiance scattered toward the eye per unit `σ_s`
//! (Eqs. 7–8 with the phase convolution of [`super::propagate`]), plus what the ray marcher needs for the
//! uncollided light ([`Initialisation`]: an octahedral shadow map and the optical depth along each
//! angular cell's cone).
//!
//! **Power, not radiance.** Cells of a radial grid differ in size (`∝ r³`). elek2014 propagates radiance
//! and "scales the radiance when propagating along the principal direction in proportion to the radial
//! coordinate spacing". voltab propagates each cell's *power* `P_i` \[W\] — what the Eq. 3 partition
//! moves between cells and what cannot increase — and turns it into the fluence it adds while crossing
//! the cell, `L_i = P_i · Δr_k / V_i` ([`super::radial::fluence_per_power`]; for a cubical cell of side
//! `Δ` this is the rectilinear `P/Δ²`). The lobe is `L_i f_hg(ω·d_i, a_i)` about the cell's radial
//! direction `d_i`.
//!
//! **Initialisation (Sec. 4.1 along the radial direction).** Each angular cell's cone receives
//! `I(ω) Ω` with `Ω = 4π/n²` (exactly, equal-area cells), split into `m × m` sub-rays (the shadow-map
//! texels inside the cone). Along each sub-ray, which ends at the first surface (distance `h`), the
//! sweep outward accumulates the optical depth of the cone's centre ray (`∫ρ ds`, sampled at least every
//! half voxel) and gives, per shell `[r_k, r_{k+1}]` clipped at `h`, the exact uncollided track length
//! `T(r_k)(1 − e^{−σ_t ℓ})/σ_t` and the first-scattered power `P T(r_k)(σ_s/σ_t)(1 − e^{−σ_t ℓ})` (the
//! cell's `σ_t` along the ray). Working with powers, the `1/r²` of the point source never appears: the
//! innermost cells are cones from the light, whose powers and volumes are finite, and their mean
//! uncollided fluence is `3 I T̄ / r_1²`. As in the rectilinear solver the uncollided beam is not
//! propagated (the ray marcher adds its single scattering analytically, [`PointDirect`]); the seeds are
//! the first-scattered powers at the single-scattering anisotropy `a = g`, counted at half weight.
//!
//! **Iterations** are those of [`super::propagate`] on the six links of [`RadialGrid`]: the front part of
//! a source's lobe flows to the next shell out (lost beyond the last shell), the back part to the next
//! shell in (through the light into the antipodal cone for the innermost shell), the side part to each
//! of the four angular neighbours.

use std::time::Instant;

use glam::{DVec2, DVec3};
use rayon::prelude::*;

use crate::render::occluder::Occluder;

use super::octa;
use super::propagate::{self, FlowTable, PhaseTimes, Settings};
use super::radial::{NONE, RadialGrid, cell_solid_angle};
use crate::physics::hg;
use crate::physics::medium::extinguished;
use crate::render::color::Rgb;
use crate::render::spot::SpotCone;

/// A point (or spot) light.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PointLight {
    /// Position \[m\].
    pub position: DVec3,
    /// Radiant intensity per channel \[W/sr\] (on the axis, for a spot).
    pub intensity: Rgb,
    /// The cone of a spot light; `None`: isotropic.
    pub spot: Option<SpotCone>,
    /// The unit normal of a Lambertian emitter (a VPL standing for part of an area light): the intensity
    /// falls off as `max(0, n·w)` (`intensity` is the value along `n`); `None`: no cosine falloff.
    pub normal: Option<DVec3>,
}

impl PointLight {
    /// Relative intensity toward unit direction `w` (1 for a point light; the squared KHR ramp for a spot;
    /// times `max(0, n·w)` for a Lambertian VPL).
    pub fn profile(&self, w: DVec3) -> f64 {
        let cone = match self.spot {
            None => 1.0,
            Some(s) => s.falloff(w),
        };
        match self.normal {
            None => cone,
            Some(n) => cone * n.dot(w).max(0.0),
        }
    }
}

/// An octahedral depth map around the light: distance to the first surface per texel.
#[derive(Debug, Clone)]
pub struct ShadowMap {
    /// Texels per side.
    pub side: usize,
    /// Distance per texel `x + side·y` \[m\] (`INFINITY`: nothing hit).
    pub depth: Vec<f64>,
}

impl ShadowMap {
    /// Fraction of the four texels around `w` (bilinear, across the folds) that see distance `r`.
    pub fn visibility(&self, w: DVec3, r: f64) -> f64 {
        let x = octa::encode(w) * self.side as f64 - DVec2::splat(0.5);
        let (i0, j0) = (x.x.floor(), x.y.floor());
        let (fx, fy) = (x.x - i0, x.y - j0);
        let mut v = 0.0;
        for (di, wi) in [(0i64, 1.0 - fx), (1, fx)] {
            for (dj, wj) in [(0i64, 1.0 - fy), (1, fy)] {
                let (a, b) = octa::wrap(i0 as i64 + di, j0 as i64 + dj, self.side);
                if r <= self.depth[a + self.side * b] * (1.0 + 1e-3) {
                    v += wi * wj;
                }
            }
        }
        v
    }
}

/// What the initialisation sweep leaves for rendering.
#[derive(Debug, Clone)]
pub struct Initialisation {
    /// The light.
    pub light: PointLight,
    /// Depth map (sub-rays of the sweep).
    pub shadow: ShadowMap,
    /// Per angular cell, `∫ρ ds` along its centre ray at every shell boundary (`S + 1` values).
    pub depth_profile: Vec<Vec<f64>>,
}

/// The propagation on one radial grid.
#[derive(Debug, Clone)]
pub struct RadialPropagation {
    /// Uncollided fluence averaged over each cell \[W/m²\].
    pub uncollided: Vec<Rgb>,
    /// Collided fluence per cell.
    pub fluence: Vec<Rgb>,
    /// Collided radiance scattered toward the eye per unit `σ_s` (`Σ_m L^m f_hg(u, a^m g)`).
    pub toward_eye: Vec<Rgb>,
    /// First-scattered power per cell \[W\] (the seeds).
    pub seed: Vec<Rgb>,
    /// Power the light emits into the grid's sphere, `∫ I(ω) dω` per channel \[W\].
    pub emitted: Rgb,
    /// Anisotropic iterations run.
    pub anisotropic_iterations: usize,
    /// Isotropic residuum iterations run.
    pub isotropic_iterations: usize,
    /// `Σ_cells Σ_channels P` of the seed and every iterate \[W\] (non-increasing).
    pub energy: Vec<f64>,
    /// Phase times (initialisation = shadow map + sweep).
    pub times: PhaseTimes,
    /// The sweep's products for the ray marcher.
    pub init: Initialisation,
}

/// Sub-rays per angular cell and side so that the depth map has at least 256 texels per side.
pub fn sub_rays(n: usize) -> usize {
    256usize.div_ceil(n.max(1)).clamp(1, 64)
}

/// The Sec. 4.1 sweep (module doc): the depth map, the cones' optical-depth profiles, and per cell the
/// uncollided fluence and the first-scattered power.
pub fn initialise(
    grid: &RadialGrid,
    medium: &crate::render::voxel::VoxelMedium,
    light: &PointLight,
    occluder: &dyn Occluder,
) -> (Initialisation, Vec<Rgb>, Vec<Rgb>, Rgb) {
    let n = grid.n;
    let m = sub_rays(n);
    let side = n * m;
    let shells = grid.shells();
    let na = grid.angular();
    let c = grid.centre;
    let depth: Vec<f64> = (0..side * side)
        .into_par_iter()
        .map(|t| {
            let w = octa::decode(DVec2::new(
                ((t % side) as f64 + 0.5) / side as f64,
                ((t / side) as f64 + 0.5) / side as f64,
            ));
            occluder.hit_distance(c, w)
        })
        .collect();
    let step = 0.5 * medium.voxel_size().min_element();
    let depth_profile: Vec<Vec<f64>> = (0..na)
        .into_par_iter()
        .map(|a| {
            let d = grid.dirs[a];
            let mut out = Vec::with_capacity(shells + 1);
            let mut acc = 0.0;
            out.push(0.0);
            for k in 0..shells {
                let (r0, r1) = (grid.radii[k], grid.radii[k + 1]);
                let steps = ((r1 - r0) / step).ceil().clamp(1.0, 4096.0) as usize;
                let dt = (r1 - r0) / steps as f64;
                for s in 0..steps {
                    acc += dt * medium.density_at(c + d * (r0 + (s as f64 + 0.5) * dt));
                }
                out.push(acc);
            }
            out
        })
        .collect();
    let omega_sub = cell_solid_angle(n) / (m * m) as f64;
    let sigma_t: Rgb = medium.coefficients.sigma_t();
    let albedo: Rgb =
        [0, 1, 2].map(|ch| if sigma_t[ch] > 0.0 { medium.coefficients.sigma_s[ch] / sigma_t[ch] } else { 0.0 });
    // Per angular cell: per shell (uncollided track-length power, scattered power), and emitted power.
    let per_cone: Vec<(Vec<(Rgb, Rgb)>, Rgb)> = (0..na)
        .into_par_iter()
        .map(|a| {
            let (i, j) = (a % n, a / n);
            let prof = &depth_profile[a];
            let mut cells = vec![([0.0; 3], [0.0; 3]); shells];
            let mut emitted = [0.0; 3];
            for y in 0..m {
                for x in 0..m {
                    let (tx, ty) = (i * m + x, j * m + y);
                    let w = octa::decode(DVec2::new((tx as f64 + 0.5) / side as f64, (ty as f64 + 0.5) / side as f64));
                    let p = light.profile(w) * omega_sub;
                    if p <= 0.0 {
                        continue;
                    }
                    let h = depth[tx + side * ty];
                    for (e, i) in emitted.iter_mut().zip(light.intensity) {
                        *e += p * i;
                    }
                    for k in 0..shells {
                        let (r0, r1) = (grid.radii[k], grid.radii[k + 1]);
                        if h <= r0 {
                            break;
                        }
                        let len = r1.min(h) - r0;
                        let rho = (prof[k + 1] - prof[k]) / (r1 - r0);
                        for ch in 0..3 {
                            let e = p * light.intensity[ch] * (-sigma_t[ch] * prof[k]).exp();
                            let st = sigma_t[ch] * rho;
                            // (1 − e^{−σ ℓ}) without cancellation for small σ ℓ.
                            let absorbed = extinguished(st, len);
                            cells[k].0[ch] += e * if st > 0.0 { absorbed / st } else { len };
                            cells[k].1[ch] += e * albedo[ch] * absorbed;
                        }
                    }
                }
            }
            (cells, emitted)
        })
        .collect();
    let mut uncollided = vec![[0.0; 3]; grid.len()];
    let mut seed = vec![[0.0; 3]; grid.len()];
    let mut emitted = [0.0; 3];
    for (a, (cells, e)) in per_cone.into_iter().enumerate() {
        for (k, (u, s)) in cells.into_iter().enumerate() {
            // Uncollided fluence = power × track length / volume = (track-length power) · (Δr/V)/Δr.
            let per_len = grid.fluence_per_power(k) / (grid.radii[k + 1] - grid.radii[k]);
            uncollided[a + na * k] = u.map(|v| v * per_len);
            seed[a + na * k] = s;
        }
        for ch in 0..3 {
            emitted[ch] += e[ch];
        }
    }
    (Initialisation { light: *light, shadow: ShadowMap { side, depth }, depth_profile }, uncollided, seed, emitted)
}

/// Runs the propagation toward an eye at `eye`.
pub fn propagate(
    grid: &RadialGrid,
    medium: &crate::render::voxel::VoxelMedium,
    light: &PointLight,
    occluder: &dyn Occluder,
    flow: &FlowTable,
    settings: &Settings,
    eye: DVec3,
) -> RadialPropagation {
    let start = Instant::now();
    let (init, uncollided, seed, emitted) = initialise(grid, medium, light, occluder);
    let initialisation = start.elapsed().as_secs_f64();
    let na = grid.angular();
    let kappa: Vec<f64> = (0..grid.len()).map(|c| grid.fluence_per_power(c / na)).collect();
    let u: Vec<f64> =
        (0..grid.len()).map(|c| grid.dirs[c % na].dot((eye - grid.center(c)).normalize_or_zero())).collect();
    let g = grid.g;
    let mut fluence = vec![[0.0; 3]; grid.len()];
    let mut toward_eye = vec![[0.0; 3]; grid.len()];
    let mut acc_seconds = 0.0;
    let mut accumulate = |p: &[Rgb], a: &[Rgb], weight: f64, fluence: &mut Vec<Rgb>, toward_eye: &mut Vec<Rgb>| {
        let t0 = Instant::now();
        fluence.par_iter_mut().zip(toward_eye.par_iter_mut()).enumerate().for_each(|(c, (f, t))| {
            for ch in 0..3 {
                if p[c][ch] > 0.0 {
                    let l = weight * kappa[c] * p[c][ch];
                    f[ch] += l;
                    t[ch] += l * hg::phase(u[c], a[c][ch] * g[ch]);
                }
            }
        });
        acc_seconds += t0.elapsed().as_secs_f64();
    };
    let a0: Vec<Rgb> = vec![g; grid.len()];
    accumulate(&seed, &a0, 0.5, &mut fluence, &mut toward_eye);
    let total = |l: &[Rgb]| l.iter().map(|v| v[0] + v[1] + v[2]).sum::<f64>();
    let seeded = total(&seed);
    let mut energy = vec![seeded];
    let stop = settings.eps_l * seeded;
    let prop_start = Instant::now();
    let mut p = seed.clone();
    let mut a = a0;
    let residuum = settings.residuum && settings.switch_iteration < settings.iterations;
    let cap = if residuum { settings.switch_iteration } else { settings.iterations };
    let mut anisotropic_iterations = 0;
    while anisotropic_iterations < cap && *energy.last().unwrap_or(&0.0) > stop {
        let (np, na_) = step(grid, flow, &p, Some(&a));
        p = np;
        a = na_;
        accumulate(&p, &a, 1.0, &mut fluence, &mut toward_eye);
        energy.push(total(&p));
        anisotropic_iterations += 1;
    }
    let propagation = prop_start.elapsed().as_secs_f64();
    let res_start = Instant::now();
    let mut isotropic_iterations = 0;
    if residuum {
        let zero = vec![[0.0; 3]; grid.len()];
        while isotropic_iterations < settings.residuum_iterations && *energy.last().unwrap_or(&0.0) > stop {
            p = step(grid, flow, &p, None).0;
            accumulate(&p, &zero, 1.0, &mut fluence, &mut toward_eye);
            energy.push(total(&p));
            isotropic_iterations += 1;
        }
    }
    let residuum_seconds = res_start.elapsed().as_secs_f64();
    RadialPropagation {
        uncollided,
        fluence,
        toward_eye,
        seed,
        emitted,
        anisotropic_iterations,
        isotropic_iterations,
        energy,
        times: PhaseTimes { initialisation, propagation, residuum: residuum_seconds, accumulation: acc_seconds },
        init,
    }
}

/// The light's uncollided single scattering toward an eye at `eye` per unit `σ_s`, per cell: the cell's
/// mean uncollided fluence times `f_hg(d_i·ω_eye, g)` (the uncollided light crosses the cell along its
/// radial direction `d_i`). Cell means keep the power exact and have no `1/r²` singularity: this is how
/// the ray marcher takes the uncollided light of a VPL (elek2014 Sec. 6 clamps VPLs' singularities;
/// this "clamp" is at the grid's resolution and loses no energy), where [`PointDirect`] integrates a
/// true point light's analytically.
pub fn uncollided_toward_eye(grid: &RadialGrid, p: &RadialPropagation, eye: DVec3) -> Vec<Rgb> {
    let na = grid.angular();
    p.uncollided
        .par_iter()
        .enumerate()
        .map(|(c, f)| {
            let u = grid.dirs[c % na].dot((eye - grid.center(c)).normalize_or_zero());
            [0, 1, 2].map(|ch| f[ch] * hg::phase(u, grid.g[ch]))
        })
        .collect()
}

/// One gathering iteration on the radial links (Eqs. 2–6 with powers). `a = None`: isotropic residuum.
pub fn step(grid: &RadialGrid, flow: &FlowTable, p: &[Rgb], a: Option<&[Rgb]>) -> (Vec<Rgb>, Vec<Rgb>) {
    let iso = flow.lookup(0.0);
    let parts = propagate::partitions(flow, a);
    let na = grid.angular();
    let out: Vec<(Rgb, Rgb)> = (0..grid.len())
        .into_par_iter()
        .map(|c| {
            let k = c / na;
            let links = (0..6).filter_map(|slot| {
                let src = grid.neighbours[c][slot];
                (src != NONE).then(|| {
                    (src, RadialGrid::part(slot, k), grid.link_transmittance[c][slot], grid.link_decay[c][slot])
                })
            });
            propagate::gather(links, p, &parts, iso, a)
        })
        .collect();
    out.into_iter().unzip()
}

/// `∫₀ᴸ ds / |a + s u − c|²` along a segment from `a` of length `len` (unit `u`), the distance to `c`
/// floored at `b_min` (> 0): `(atan((L − Δ)/b) + atan(Δ/b))/b` with `Δ` the closest approach's
/// parameter and `b` its distance. Finite for every finite input, exact where `b ≥ b_min`.
pub fn inverse_square_integral(a: DVec3, u: DVec3, len: f64, c: DVec3, b_min: f64) -> f64 {
    let w = c - a;
    let delta = w.dot(u);
    let b = (w - u * delta).length().max(b_min);
    if len.is_nan() || len <= 0.0 || !b.is_finite() {
        return 0.0;
    }
    (((len - delta) / b).atan() + (delta / b).atan()) / b
}

/// The single scattering of a point light's uncollided light toward the eye, evaluated per ray-march
/// step (weighted by the transmittance toward the eye inside the step): the step integral of `I(ω) T V f_hg(ω·ω_eye, g) / r²` per unit `σ_s`. In the equiangular variable
/// `θ` of the step's line (`t = Δ + b tan θ`, `b` the line's distance from the light floored at `1e-4 m`,
/// the reference's clamp) the `1/r²` is exactly `dθ/b` and the scattering cosine is `−sin θ`, so the
/// step is integrated by the midpoint rule in `θ` on panels of at most 0.05 rad (one panel far from the
/// light, up to 64 on the step that passes it): no `1/r²` singularity, and the phase function's flip
/// from forward to backward as the ray passes the light is resolved. `V` comes from the depth map, the
/// transmittance from the light exactly (the box-clipped distance) in a uniform medium, else from the
/// cone's optical-depth profile. ([`inverse_square_integral`] is the closed form of `∫ ds/r²` alone.)
pub struct PointDirect<'a> {
    /// The sweep's products.
    pub init: &'a Initialisation,
    /// The grid (shell radii, for the depth profile).
    pub grid: &'a RadialGrid,
    /// The medium.
    pub medium: &'a crate::render::voxel::VoxelMedium,
    /// True when every voxel has the same density.
    pub uniform: bool,
}

/// Smallest distance at which a point light's `1/r²` is evaluated \[m\] (as the reference's).
pub const R_MIN: f64 = 1e-4;

impl PointDirect<'_> {
    /// `∫ρ ds` from the light to `p` (unit direction `w`, distance `r`).
    fn density_integral(&self, w: DVec3, r: f64) -> f64 {
        let m = self.medium;
        if self.uniform {
            let rho = f64::from(m.density[0]);
            return rho * clipped_length(m.min, m.max, self.grid.centre, w, r);
        }
        let (i, j) = octa::cell_of(w, self.grid.n);
        let prof = &self.init.depth_profile[i + self.grid.n * j];
        let radii = &self.grid.radii;
        let k = radii.partition_point(|&x| x <= r).clamp(1, radii.len() - 1) - 1;
        let f = ((r - radii[k]) / (radii[k + 1] - radii[k])).clamp(0.0, 1.0);
        prof[k] + f * (prof[k + 1] - prof[k])
    }
}

/// Length of `[0, r]` along `o + t w` inside the box.
fn clipped_length(min: DVec3, max: DVec3, o: DVec3, w: DVec3, r: f64) -> f64 {
    let inv = w.recip();
    let t0 = (min - o) * inv;
    let t1 = (max - o) * inv;
    let lo = t0.min(t1);
    let hi = t0.max(t1);
    let enter = lo.x.max(lo.y).max(lo.z).max(0.0);
    let exit = hi.x.min(hi.y).min(hi.z).min(r);
    (exit - enter).max(0.0)
}

impl super::render::StepSource for PointDirect<'_> {
    fn step_integral(&self, a: DVec3, b: DVec3, sigma_t: Rgb) -> Rgb {
        let light = &self.init.light;
        let seg = b - a;
        let len = seg.length();
        if len.is_nan() || len <= 0.0 {
            return [0.0; 3];
        }
        let u = seg / len;
        let w = light.position - a;
        let delta = w.dot(u);
        let dist = (w - u * delta).length().max(R_MIN);
        // Equiangular variable: t = Δ + b tan θ, dt/r² = dθ/b, and μ = −sin θ.
        let (th_a, th_b) = ((-delta / dist).atan(), ((len - delta) / dist).atan());
        let panels = ((th_b - th_a) / 0.05).ceil().clamp(1.0, 64.0) as usize;
        let dth = (th_b - th_a) / panels as f64;
        let m = self.medium;
        let mut out = [0.0; 3];
        for k in 0..panels {
            let th = th_a + (k as f64 + 0.5) * dth;
            let t = delta + dist * th.tan();
            let p = a + u * t;
            let to = p - light.position;
            let r = to.length();
            let dir = if r > 0.0 { to / r } else { -u };
            let weight = light.profile(dir) * dth / dist;
            if weight <= 0.0 {
                continue;
            }
            let vis = self.init.shadow.visibility(dir, r);
            if vis <= 0.0 {
                continue;
            }
            let d = self.density_integral(dir, r);
            let mu = dir.dot(-u);
            for c in 0..3 {
                let tau = (m.coefficients.sigma_s[c] + m.coefficients.sigma_a[c]) * d;
                let eye = (-sigma_t[c] * t.clamp(0.0, len)).exp();
                out[c] += light.intensity[c] * weight * vis * (-tau).exp() * eye * hg::phase(mu, m.coefficients.g[c]);
            }
        }
        out
    }
}
