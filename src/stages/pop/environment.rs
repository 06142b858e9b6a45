//! Environment lighting for POP (elek2014 Secs. 5.1–5.4): a latitude–longitude HDR map → principal ordinates,
//! each a distant light with its share of the map's energy and a prefiltered initial anisotropy.
//!
//! **Input → output.** An [`EnvMap`] (radiance per texel, read from an EXR or built from a function),
//! an ordinate count `N` and a direction set ([`OrdinateSet`]) → [`EnvOrdinate`]s: the direction the
//! light of ordinate `n` travels, its irradiance `E_n = ∫_{Ω_n} L dω` (per channel) and the initial
//! anisotropy `a_n` of its HG lobe. [`propagate_lobe`] propagates each
//! as a directional light on its own grid, and [`merge`](super::merge) combines the grids (Sec. 5.3).
//!
//! **Map convention and rotation**: [`crate::render::environment`].
//!
//!
//! **Ordinates (Sec. 5.1).** [`OrdinateSet::Importance`] places the `N` directions where the map is
//! bright: the points `((i + ½)/m, frac(i/Φ))` of a two-dimensional Fibonacci lattice pushed through the
//! inverse of the map's texel distribution ([`EnvSampler`], luminance × solid angle with a uniform
//! share so dark regions still get ordinates), one ordinate per texel (lattices of `m = N, 2N, 4N, …`
//! points until `N` distinct texels are found: a sun smaller than `N` texels would otherwise swallow
//! most of the points); [`OrdinateSet::Fibonacci`] uses the preset's
//! well-spread spherical Fibonacci set. Every texel then goes to its nearest ordinate (its Voronoi
//! cell `Ω_n`, at texel resolution), so the ordinates' energies sum to the map's integral exactly.
//! *Departure:* the paper approximates the mean cosine of `Ω_n` from the sampling importance with the
//! heuristic `a_n = (1 − w_n/N)^β`, because it does not know the cells. voltab knows them, so it
//! computes what the heuristic stands for: the radiance-weighted mean direction of the cell,
//! `m_n = Σ_{t∈Ω_n} Y_t ∫_t ω dω / Σ Y_t ΔΩ_t` (`Y` the luminance, the texel integral exact,
//! [`EnvMap::texel_moment`]); the ordinate points along
//! `m_n/|m_n|` and starts with anisotropy `a_n = |m_n|` (the HG lobe with that mean cosine), no tuning
//! of `β`. A cell holding one bright texel (a sun) gets `a_n → 1`, a cell of uniform sky a value near
//! the preset's `ordinate_mean_cosine`. Ordinates whose cell carries no energy are left out.
//!
//! **Importance (Sec. 5.2).** [`importance_map`] propagates importance from the camera and projects it
//! onto the directions; [`ordinates_with_importance`] then places the ordinates by the product of the map
//! and the importance (the energies still partition the whole map).

use std::time::Instant;

use glam::DVec3;
use rayon::prelude::*;

use super::grid::Grid;

use crate::render::occluder::Occluder;

use super::merge::merge_rectilinear;
use super::propagate::{FlowTable, Observer, Propagation, Settings, isotropic_residuum, propagate_lobe};
use crate::render::color::{Rgb, luminance};
use crate::render::environment::direction;
use crate::render::environment::{EnvMap, EnvSampler};
use crate::render::voxel::{DirectionalLight, VoxelMedium};
use crate::tables::pop_preset::ordinates::fibonacci_directions;

/// `1/Φ` (Φ the golden ratio): the second coordinate of the Fibonacci lattice.
const INV_PHI: f64 = 0.618_033_988_749_894_8;

/// How the ordinates' directions are chosen.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub enum OrdinateSet {
    /// Importance-sampled from the map's luminance (elek2014 Sec. 5.1).
    Importance,
    /// The preset's spherical Fibonacci directions (well spread, independent of the map).
    Fibonacci,
}

/// One principal ordinate of an environment: a distant light with a prefiltered lobe.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct EnvOrdinate {
    /// Unit direction the light travels (from the environment into the scene).
    pub direction: [f64; 3],
    /// `∫_{Ω_n} L dω` per channel \[W/m²\].
    pub irradiance: Rgb,
    /// Initial anisotropy `a_n` (radiance-weighted mean cosine of the cell about `direction`).
    pub anisotropy: f64,
    /// Solid angle of the cell \[sr\].
    pub solid_angle: f64,
}

impl EnvOrdinate {
    /// The ordinate as a directional light (its anisotropy goes to `propagate_lobe` separately).
    pub fn light(&self) -> DirectionalLight {
        DirectionalLight { direction: DVec3::from(self.direction), irradiance: self.irradiance }
    }
}

/// The candidate directions (toward the environment) of `set`.
fn candidates(env: &EnvMap, n: usize, set: OrdinateSet, importance: Option<&EnvMap>) -> Vec<DVec3> {
    match set {
        OrdinateSet::Fibonacci => fibonacci_directions(n).into_iter().map(DVec3::from).collect(),
        OrdinateSet::Importance => {
            let sampler = EnvSampler::with_importance(env, importance);
            let mut taken = std::collections::BTreeSet::new();
            let mut out = Vec::with_capacity(n);
            // Lattices of N, 2N, 4N, … points until N distinct texels are found (two points in one
            // texel would split one texel's light), at most 64N points.
            let mut m = n;
            while out.len() < n && m <= 64 * n {
                for i in 0..m {
                    let u1 = (i as f64 + 0.5) / m as f64;
                    let u2 = (i as f64 * INV_PHI).fract();
                    let t = sampler.texel(u1);
                    if out.len() < n && taken.insert(t) {
                        // The lattice's second coordinate places the point inside its texel.
                        let (col, row) = (t % env.width, t / env.width);
                        out.push(env.to_world(direction(col as f64 + u2, row as f64 + 0.5, env.width, env.height)));
                    }
                }
                m *= 2;
            }
            out
        }
    }
}

/// The principal ordinates of `env` (module doc): at most `n`, those with energy, in a fixed order.
pub fn ordinates(env: &EnvMap, n: usize, set: OrdinateSet) -> Vec<EnvOrdinate> {
    ordinates_with_importance(env, n, set, None)
}

/// [`ordinates`] placed by the product of the map and a directional importance map ([`importance_map`],
/// elek2014 Sec. 5.2) when `set` is [`OrdinateSet::Importance`]. The energies still partition the whole
/// map: importance moves the ordinates, it does not weight the light.
pub fn ordinates_with_importance(
    env: &EnvMap,
    n: usize,
    set: OrdinateSet,
    importance: Option<&EnvMap>,
) -> Vec<EnvOrdinate> {
    let dirs = candidates(env, n.max(1), set, importance);
    let w = env.width;
    // Nearest ordinate of every texel (largest cosine; ties to the lower index), per row in parallel.
    let owner: Vec<usize> = (0..w * env.height)
        .into_par_iter()
        .map(|t| {
            let d = env.texel_direction(t % w, t / w);
            let mut best = (0, f64::NEG_INFINITY);
            for (k, o) in dirs.iter().enumerate() {
                let c = o.dot(d);
                if c > best.1 {
                    best = (k, c);
                }
            }
            best.0
        })
        .collect();
    let mut energy = vec![[0.0; 3]; dirs.len()];
    let mut moment = vec![DVec3::ZERO; dirs.len()];
    let mut weight = vec![0.0; dirs.len()];
    let mut omega = vec![0.0; dirs.len()];
    for (t, &k) in owner.iter().enumerate() {
        let (col, row) = (t % w, t / w);
        let dw = env.texel_solid_angle(row);
        let l = env.radiance[t];
        for c in 0..3 {
            energy[k][c] += l[c] * dw;
        }
        let y = luminance(l);
        moment[k] += env.texel_moment(col, row) * y;
        weight[k] += y * dw;
        omega[k] += dw;
    }
    (0..dirs.len())
        .filter(|&k| energy[k].iter().any(|&e| e > 0.0))
        .map(|k| {
            // A cell with energy but no luminance (pure negative-weight colours cannot occur: radiance
            // is non-negative) falls back to its candidate direction and an isotropic start.
            let (dir, a) = if weight[k] > 0.0 && moment[k].length() > 0.0 {
                (moment[k].normalize(), (moment[k].length() / weight[k]).min(1.0))
            } else {
                (dirs[k], 0.0)
            };
            EnvOrdinate { direction: (-dir).to_array(), irradiance: energy[k], anisotropy: a, solid_angle: omega[k] }
        })
        .collect()
}

/// Every ordinate of an environment propagated on its own grid, the merged isotropic residuum when it
/// applies, and their accumulations merged into one medium-aligned grid (Secs. 5.3, 5.4).
pub struct EnvPropagation {
    /// Per ordinate: its grid, its iteration settings and its propagation.
    pub ordinates: Vec<(Grid, Settings, Propagation)>,
    /// The merged isotropic residuum: its grid and its iterations (when Eq. 10's switch falls inside
    /// the iteration budget of every ordinate).
    pub residuum: Option<(Grid, Propagation)>,
    /// The medium-aligned render grid and its accumulated radiance toward the eye per unit `σ_s`.
    pub merged: (Grid, Vec<Rgb>),
    /// Building each ordinate's grid (medium downsampling, links) \[s\].
    pub grid_seconds: Vec<f64>,
    /// Resampling the ordinates' last iterates onto the residuum grid \[s\].
    pub handover_seconds: f64,
    /// Merging the accumulations into the render grid \[s\].
    pub merge_seconds: f64,
}

/// How [`propagate_environment`] runs.
pub struct EnvOptions<'a> {
    /// Cells of every ordinate's grid and of the residuum grid.
    pub dims: [usize; 3],
    /// Cells of the medium-aligned render grid (elek2014: double the propagation grids).
    pub merge_dims: [usize; 3],
    /// The flow table of Eqs. 2–3.
    pub flow: &'a FlowTable,
    /// The iteration settings of a grid (Eq. 10's `m'` depends on its cell size along the ordinate).
    pub settings: &'a (dyn Fn(&Grid) -> Settings + Sync),
    /// The eye the accumulation looks from.
    pub eye: DVec3,
}

/// Propagates `ordinates` through `medium` (elek2014 Sec. 5). Each runs on its own grid aligned with it
/// ([`propagate_lobe`] with its prefiltered anisotropy). *Residuum (Sec. 5.4):* the paper switches when
/// every grid's anisotropy is below `ε_a`, merges the propagation grids into one medium-aligned grid and
/// continues isotropically there. voltab takes the largest Eq. 10 switch `m'` over the ordinates; when
/// it is below the iteration budget `M` (and the preset enables the residuum), every ordinate runs `m'`
/// anisotropic iterations, their last iterates are resampled onto one grid of the same resolution
/// aligned with the medium (as power per volume, `L/Δ` with `Δ` the cube root of the cell volume, then
/// back to `L` with the new cells, so the light's power carries over) and the isotropic iterations run
/// there until `ε_L` of the seeded energy is left or `residuum_iterations` run out. Otherwise every
/// ordinate runs as a lone light would.
pub fn propagate_environment(
    medium: &VoxelMedium,
    ordinates: &[EnvOrdinate],
    occluder: &dyn Occluder,
    opts: &EnvOptions<'_>,
) -> Result<EnvPropagation, String> {
    let mut grids = Vec::with_capacity(ordinates.len());
    let mut grid_seconds = Vec::with_capacity(ordinates.len());
    for o in ordinates {
        let t0 = Instant::now();
        let grid = Grid::new(medium, DVec3::from(o.direction), opts.dims, occluder)?;
        grid_seconds.push(t0.elapsed().as_secs_f64());
        let settings = (opts.settings)(&grid);
        grids.push((grid, settings));
    }
    let switch = grids.iter().map(|(_, s)| s.switch_iteration).max().unwrap_or(usize::MAX);
    let merged_residuum = !grids.is_empty() && grids.iter().all(|(_, s)| s.residuum && switch < s.iterations);
    let mut runs = Vec::with_capacity(grids.len());
    for ((grid, settings), o) in grids.into_iter().zip(ordinates) {
        let run_settings = if merged_residuum {
            Settings { iterations: switch, residuum: false, ..settings.clone() }
        } else {
            settings.clone()
        };
        let p = propagate_lobe(
            &grid,
            &o.light(),
            o.anisotropy,
            occluder,
            opts.flow,
            &run_settings,
            Observer::Eye(opts.eye),
        );
        runs.push((grid, settings, p));
    }
    let mut handover_seconds = 0.0;
    let residuum = if merged_residuum {
        let t0 = Instant::now();
        let target = Grid::new(medium, DVec3::Z, opts.dims, occluder)?;
        let cell = |g: &Grid| (g.size[0] * g.size[1] * g.size[2]).cbrt();
        let scaled: Vec<Vec<Rgb>> =
            runs.iter().map(|(g, _, p)| p.last.iter().map(|v| v.map(|x| x / cell(g))).collect()).collect();
        let sources: Vec<(&Grid, &[Rgb])> = runs.iter().zip(&scaled).map(|((g, _, _), f)| (g, f.as_slice())).collect();
        let dt = cell(&target);
        let l0: Vec<Rgb> = merge_rectilinear(&target, &sources).into_iter().map(|v| v.map(|x| x * dt)).collect();
        handover_seconds = t0.elapsed().as_secs_f64();
        let seeded: f64 = runs.iter().map(|(_, _, p)| p.energy.first().copied().unwrap_or(0.0)).sum();
        let (max_iterations, eps_l) = runs.first().map_or((0, 0.0), |(_, s, _)| (s.residuum_iterations, s.eps_l));
        let p = isotropic_residuum(&target, opts.flow, l0, max_iterations, eps_l * seeded, opts.eye);
        Some((target, p))
    } else {
        None
    };
    let t0 = Instant::now();
    let merged = Grid::medium_aligned(medium, opts.merge_dims)?;
    let mut sources: Vec<(&Grid, &[Rgb])> = runs.iter().map(|(g, _, p)| (g, p.toward_eye.as_slice())).collect();
    if let Some((g, p)) = &residuum {
        sources.push((g, p.toward_eye.as_slice()));
    }
    let field = merge_rectilinear(&merged, &sources);
    Ok(EnvPropagation {
        ordinates: runs,
        residuum,
        merged: (merged, field),
        grid_seconds,
        handover_seconds,
        merge_seconds: t0.elapsed().as_secs_f64(),
    })
}

/// elek2014 Sec. 5.2: how much light arriving from each direction reaches the camera through the medium,
/// as a latitude–longitude map of `size` texels (grey, normalised to a largest value of 1).
///
/// *Importance propagation.* By duality the camera is a light: voltab propagates a unit spot light at
/// the eye, its cone the view frustum, through `medium` on a radial grid of `n × n` directions and `n`
/// shells ([`super::radial_propagate::propagate`], the same solver as point lights), which gives the
/// importance fluence `φ_I(x)` of the camera, uncollided and collided. A point `x` passes light arriving
/// from `ω` on to the camera in proportion to `W(x) = σ_s(x) φ_I(x)`. *Projection:* on a medium-aligned
/// grid of `n³` cells, `I(ω) = Σ_x W(x) V(x, ω) T(x, ω)` with `V` the occluder's visibility toward `ω` and
/// `T` the medium's transmittance to its box (marched in steps of half a cell); texels are their centre
/// directions. Cells with `W` below 10⁻³ of the largest are skipped. The paper ray-marches its
/// importance grid the same way; the map is smooth, so a small one suffices (its defaults: 16³ and
/// 32 × 16).
pub fn importance_map(
    medium: &VoxelMedium,
    occluder: &dyn Occluder,
    camera: &crate::render::ViewCamera,
    flow: &FlowTable,
    settings: &Settings,
    n: usize,
    size: [usize; 2],
) -> Result<EnvMap, String> {
    use super::radial::RadialGrid;
    use super::radial_propagate::{PointLight, propagate};
    use crate::render::spot::SpotCone;
    let n = n.clamp(2, 64);
    let (w, h) = (size[0].max(1), size[1].max(1));
    // The frustum's half-diagonal: the smallest cosine between the axis and a corner ray.
    let corners = [(0, 0), (camera.width - 1, 0), (0, camera.height - 1), (camera.width - 1, camera.height - 1)];
    let cos_outer = corners.iter().map(|&(x, y)| camera.pixel_dir(x, y).dot(camera.forward)).fold(1.0, f64::min);
    let eye = PointLight {
        position: camera.position,
        intensity: [1.0; 3],
        spot: Some(SpotCone { axis: camera.forward, cos_outer: (cos_outer - 1e-3).max(-1.0), inv_range: 1e3 }),
        normal: None,
    };
    let grid = RadialGrid::new(medium, camera.position, n, n, occluder)?;
    let p = propagate(&grid, medium, &eye, occluder, flow, settings, camera.position);
    let cells = Grid::medium_aligned(medium, [n; 3])?;
    let weight: Vec<f64> = (0..cells.len())
        .map(|i| {
            let x = cells.center(cells.coords(i));
            let phi = grid.sample(&p.fluence, x)[1] + grid.sample(&p.uncollided, x)[1];
            cells.cells[i].sigma_s[1] * phi.max(0.0)
        })
        .collect();
    let top = weight.iter().copied().fold(0.0, f64::max);
    let used: Vec<(DVec3, f64)> = (0..cells.len())
        .filter(|&i| weight[i] > 1e-3 * top)
        .map(|i| (cells.center(cells.coords(i)), weight[i]))
        .collect();
    let step = 0.5 * cells.size.iter().copied().fold(f64::INFINITY, f64::min);
    let sigma_t = medium.coefficients.sigma_s[1] + medium.coefficients.sigma_a[1];
    let map = EnvMap::from_fn(w, h, |dir| {
        let mut sum = 0.0;
        for &(x, wt) in &used {
            if occluder.ray_blocked(x, dir) {
                continue;
            }
            // Optical depth to the box along `dir` (midpoint steps).
            let exit = box_exit(medium.min, medium.max, x, dir);
            let steps = (exit / step).ceil().max(1.0) as usize;
            let dt = exit / steps as f64;
            let tau: f64 =
                (0..steps).map(|k| medium.density_at(x + dir * ((k as f64 + 0.5) * dt))).sum::<f64>() * dt * sigma_t;
            sum += wt * (-tau).exp();
        }
        [sum; 3]
    })
    .map_err(|e| e.to_string())?;
    let top = map.radiance.iter().map(|v| v[0]).fold(0.0, f64::max);
    let scale = if top > 0.0 { 1.0 / top } else { 0.0 };
    EnvMap::new(w, h, map.radiance.iter().map(|v| v.map(|c| c * scale)).collect()).map_err(|e| e.to_string())
}

/// Distance from `p` inside the box along unit `d` to where it leaves (0 outside).
fn box_exit(min: DVec3, max: DVec3, p: DVec3, d: DVec3) -> f64 {
    let mut t = f64::INFINITY;
    for a in 0..3 {
        if d[a] > 0.0 {
            t = t.min((max[a] - p[a]) / d[a]);
        } else if d[a] < 0.0 {
            t = t.min((min[a] - p[a]) / d[a]);
        }
    }
    if t.is_finite() { t.max(0.0) } else { 0.0 }
}
