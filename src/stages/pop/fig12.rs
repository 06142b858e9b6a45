//! elek2014 Fig. 12: POP against Monte-Carlo light tracing on a unit cube.
//!
//! **Input → output.** A phase mean cosine `g` (the paper's 0, 0.7 and 0.96), POP settings and a
//! photon budget → the collided fluence and the incident-radiance distributions (binned by the angle
//! from the light direction, azimuth averaged) in the cells of the cube's middle horizontal slice, from
//! POP ([`super::propagate`], the grid aligned with the cube and the light) and from the independent
//! light tracer ([`crate::reference::grid_mc::light_trace`]), with their errors and run times; and
//! images of the cube from both ([`super::render::march`] against
//! [`crate::reference::grid_mc::render`]).
//!
//! **Setup (Fig. 12 caption).** The unit cube `[0, 1]³`, `σ_s = 4 /m`, albedo 1, a directional light
//! of unit irradiance travelling along `+x` (horizontal), a grid of `n³` cells aligned with the
//! medium (16³ in the paper), the slice of cells whose centres sit just above `y = ½` (cell row
//! `n/2`). Errors are relative RMS differences over the slice, `sqrt(Σ (pop − mc)² / Σ mc²)`, beside
//! the light tracer's own noise in the same units; distributions are compared bin by bin weighted by
//! the bins' solid angles. The images are compared noise-corrected with a floor ([`NoiseCorrected`]).

use std::time::Instant;

use glam::DVec3;
use serde::Serialize;

use super::grid::Grid;

use super::propagate::{self, FlowTable, Observer, Settings};
use super::render::{self, MarchOptions};
use crate::physics::medium::RgbMedium;
use crate::reference::grid_mc::{self, CameraOptions, LightTraceOptions, TallySpec};
use crate::render::ViewCamera;
use crate::render::occluder::NoOccluder;
use crate::render::voxel::{DirectionalLight, VoxelMedium};
use crate::report::noisy::NoiseCorrected;

/// The Fig. 12 scattering coefficient \[1/m\].
pub const SIGMA_S: f64 = 4.0;

/// The Fig. 12 cube with phase mean cosine `g` (albedo 1).
///
/// # Errors
/// `g ∉ [0, 1)`.
pub fn cube(g: f64) -> Result<VoxelMedium, String> {
    VoxelMedium::homogeneous(DVec3::ZERO, DVec3::ONE, RgbMedium::grey(SIGMA_S, 0.0, g)).map_err(|e| e.to_string())
}

/// The Fig. 12 light: unit irradiance along `+x`.
pub fn light() -> DirectionalLight {
    DirectionalLight { direction: DVec3::X, irradiance: [1.0; 3] }
}

/// The comparison's resolution and budget.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SliceOptions {
    /// Cells per axis of the POP grid and of the tally grid.
    pub cells: usize,
    /// Bins of the angle from the light direction.
    pub theta_bins: usize,
    /// Photons of the light tracer.
    pub photons: u64,
    /// Seed of the light tracer.
    pub seed: u64,
}

/// One slice cell (channel 0).
#[derive(Debug, Clone, Serialize)]
pub struct SliceCell {
    /// Cell centre x (along the light) and z \[m\].
    pub x: f64,
    /// Cell centre z \[m\].
    pub z: f64,
    /// POP's collided fluence.
    pub pop: f64,
    /// The light tracer's collided fluence.
    pub mc: f64,
    /// Its standard error.
    pub mc_std_err: f64,
    /// POP's collided radiance per θ bin.
    pub pop_bins: Vec<f64>,
    /// The light tracer's collided radiance per θ bin.
    pub mc_bins: Vec<f64>,
}

/// POP against the light tracer in the mid slice.
#[derive(Debug, Clone, Serialize)]
pub struct SliceComparison {
    /// Phase mean cosine.
    pub g: f64,
    /// Cells per axis.
    pub cells: usize,
    /// θ bins.
    pub theta_bins: usize,
    /// POP's anisotropic and isotropic iterations.
    pub iterations: [usize; 2],
    /// POP time (grid, initialisation, propagation) \[ms\].
    pub pop_ms: f64,
    /// Light-tracing time \[ms\].
    pub mc_ms: f64,
    /// Photons traced.
    pub photons: u64,
    /// Relative RMS error of the total (uncollided + collided) fluence.
    pub fluence_error: f64,
    /// Relative RMS error of the collided fluence.
    pub collided_error: f64,
    /// Relative RMS error of the collided radiance distributions.
    pub distribution_error: f64,
    /// The light tracer's own relative noise on the collided fluence (`sqrt(Σ se²/Σ mc²)`).
    pub mc_noise: f64,
    /// The collided fluence relative to the light tracer's mean, its noise removed, with its floor:
    /// what the report states (the fields above are the paper's RMS-normalised measures, raw).
    pub collided: NoiseCorrected,
    /// The slice's cells.
    pub slice: Vec<SliceCell>,
}

/// Runs POP and the light tracer on the Fig. 12 cube.
///
/// # Errors
/// An invalid `g`.
pub fn compare_slice(
    g: f64,
    flow: &FlowTable,
    settings: &Settings,
    opts: &SliceOptions,
) -> Result<SliceComparison, String> {
    let medium = cube(g)?;
    let light = light();
    let n = opts.cells.max(1);
    let nb = opts.theta_bins.max(1);
    let t0 = Instant::now();
    let grid = Grid::new(&medium, light.direction, [n, n, n], &NoOccluder)?;
    let p = propagate::propagate(&grid, &light, &NoOccluder, flow, settings, Observer::ThetaBins(nb));
    let pop_ms = t0.elapsed().as_secs_f64() * 1e3;
    let spec = TallySpec { dims: [n, n, n], theta_bins: nb, axis: light.direction };
    let mc = grid_mc::light_trace(
        &medium,
        &light,
        &spec,
        &LightTraceOptions { photons: opts.photons, seed: opts.seed, max_events: 100_000 },
    );
    let edges: Vec<f64> = (0..=nb).map(|b| (std::f64::consts::PI * b as f64 / nb as f64).cos()).collect();
    let omega: Vec<f64> = (0..nb).map(|b| std::f64::consts::TAU * (edges[b] - edges[b + 1])).collect();
    let row = n / 2;
    let mut slice = Vec::new();
    let (mut e_tot, mut n_tot, mut e_col, mut n_col, mut e_dist, mut n_dist, mut noise) =
        (0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0);
    for cell in 0..grid.len() {
        let centre = grid.center(grid.coords(cell));
        let m = cube_cell(centre, n);
        if (m / n) % n != row {
            continue;
        }
        let mc_unc = mc.uncollided_fluence[m][0];
        let mc_col = mc.fluence[m][0] - mc_unc;
        let pop_col = p.fluence[cell][0];
        let pop_tot = pop_col + p.uncollided[cell][0];
        e_tot += (pop_tot - mc.fluence[m][0]).powi(2);
        n_tot += mc.fluence[m][0].powi(2);
        e_col += (pop_col - mc_col).powi(2);
        n_col += mc_col.powi(2);
        noise += mc.fluence_std_err[m][0].powi(2);
        let pop_bins: Vec<f64> = (0..nb).map(|b| p.bins[cell * nb + b][0]).collect();
        // The tracer's bins hold uncollided light too: all of it in the forward bin.
        let mc_bins: Vec<f64> =
            (0..nb).map(|b| mc.radiance[m * nb + b][0] - if b == 0 { mc_unc / omega[0] } else { 0.0 }).collect();
        for b in 0..nb {
            e_dist += omega[b] * (pop_bins[b] - mc_bins[b]).powi(2);
            n_dist += omega[b] * mc_bins[b].powi(2);
        }
        slice.push(SliceCell {
            x: centre.x,
            z: centre.z,
            pop: pop_col,
            mc: mc_col,
            mc_std_err: mc.fluence_std_err[m][0],
            pop_bins,
            mc_bins,
        });
    }
    slice.sort_by(|a, b| a.z.total_cmp(&b.z).then(a.x.total_cmp(&b.x)));
    let collided = NoiseCorrected::of(
        &slice.iter().map(|c| c.pop).collect::<Vec<_>>(),
        &slice.iter().map(|c| c.mc).collect::<Vec<_>>(),
        &slice.iter().map(|c| c.mc_std_err.powi(2)).collect::<Vec<_>>(),
    )
    .map_err(|e| format!("the light tracer's slice cannot judge POP at g = {g}: {e}"))?;
    let ratio = |e: f64, d: f64| if d > 0.0 { (e / d).sqrt() } else { 0.0 };
    Ok(SliceComparison {
        g,
        cells: n,
        theta_bins: nb,
        iterations: [p.anisotropic_iterations, p.isotropic_iterations],
        pop_ms,
        mc_ms: mc.seconds * 1e3,
        photons: mc.photons,
        fluence_error: ratio(e_tot, n_tot),
        collided_error: ratio(e_col, n_col),
        distribution_error: ratio(e_dist, n_dist),
        mc_noise: ratio(noise, n_col),
        collided,
        slice,
    })
}

/// POP's image of the cube against the path tracer's.
#[derive(Debug, Clone)]
pub struct ImageComparison {
    /// Raster size.
    pub size: [usize; 2],
    /// POP's in-scattered radiance.
    pub pop: Vec<[f64; 3]>,
    /// The path tracer's.
    pub reference: Vec<[f64; 3]>,
    /// POP against it, the reference's noise removed, with its floor.
    pub error: NoiseCorrected,
    /// POP propagation + ray-march time \[ms\].
    pub pop_ms: f64,
    /// Path-tracing time \[ms\].
    pub reference_ms: f64,
}

/// The camera of the cube images: looking at the lit cube from the side (`−z`), perpendicular to the
/// light.
pub fn camera(width: usize, height: usize) -> Option<ViewCamera> {
    ViewCamera::new([0.5, 0.5, 3.2], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0], 0.42, width, height)
}

/// Renders the cube with POP and with the path tracer (`samples` paths per pixel).
///
/// # Errors
/// An invalid `g` or raster.
pub fn compare_image(
    g: f64,
    flow: &FlowTable,
    settings: &Settings,
    cells: usize,
    size: [usize; 2],
    samples: u32,
) -> Result<ImageComparison, String> {
    let medium = cube(g)?;
    let light = light();
    let cam = camera(size[0], size[1]).ok_or("the image raster is empty")?;
    let t0 = Instant::now();
    let grid = Grid::new(&medium, light.direction, [cells; 3], &NoOccluder)?;
    let p = propagate::propagate(&grid, &light, &NoOccluder, flow, settings, Observer::Eye(cam.position));
    let frame = render::march(&grid, &p.toward_eye, &medium, &cam, None, &MarchOptions::default());
    let pop_ms = t0.elapsed().as_secs_f64() * 1e3;
    let r = grid_mc::render(&medium, &light, &cam, &CameraOptions { samples, seed: 0xf1612, max_events: 100_000 });
    let error = NoiseCorrected::of_rgb(&frame.radiance, &r.radiance, &r.variance)
        .map_err(|e| format!("the path-traced cube image cannot judge POP: {e}"))?;
    Ok(ImageComparison {
        size,
        pop: frame.radiance,
        reference: r.radiance,
        error,
        pop_ms,
        reference_ms: r.seconds * 1e3,
    })
}

/// Collided fluence (channel 0) on the `n³` cells of the cube (index `x + n(y + n z)`, cells of the
/// medium box) and the time it took.
#[derive(Debug, Clone)]
pub struct FluenceRun {
    /// Collided fluence per cell.
    pub collided: Vec<f64>,
    /// Variance of each cell's value (0 for POP, which is deterministic).
    pub variance: Vec<f64>,
    /// Run time \[ms\].
    pub ms: f64,
    /// Iterations run (POP; 0 for the light tracer).
    pub iterations: usize,
}

/// The cube cell containing `p`.
fn cube_cell(p: DVec3, n: usize) -> usize {
    let t = [p.x, p.y, p.z].map(|v| ((v * n as f64).max(0.0) as usize).min(n - 1));
    t[0] + n * (t[1] + n * t[2])
}

/// POP's collided fluence on the Fig. 12 cube with an `n³` grid.
///
/// # Errors
/// An invalid `g`.
pub fn pop_fluence(g: f64, n: usize, flow: &FlowTable, settings: &Settings) -> Result<FluenceRun, String> {
    let n = n.max(1);
    let medium = cube(g)?;
    let t0 = Instant::now();
    let grid = Grid::new(&medium, light().direction, [n, n, n], &NoOccluder)?;
    let p = propagate::propagate(&grid, &light(), &NoOccluder, flow, settings, Observer::ThetaBins(1));
    let ms = t0.elapsed().as_secs_f64() * 1e3;
    let mut collided = vec![0.0; n * n * n];
    for (cell, f) in p.fluence.iter().enumerate() {
        collided[cube_cell(grid.center(grid.coords(cell)), n)] = f[0];
    }
    let variance = vec![0.0; collided.len()];
    Ok(FluenceRun { collided, variance, ms, iterations: p.anisotropic_iterations + p.isotropic_iterations })
}

/// The light tracer's collided fluence on the cube's `n³` cells.
pub fn reference_fluence(g: f64, n: usize, photons: u64, seed: u64) -> FluenceRun {
    let n = n.max(1);
    let Ok(medium) = cube(g) else {
        return FluenceRun { collided: vec![0.0; n * n * n], variance: vec![0.0; n * n * n], ms: 0.0, iterations: 0 };
    };
    let spec = TallySpec { dims: [n, n, n], theta_bins: 1, axis: light().direction };
    let mc = grid_mc::light_trace(&medium, &light(), &spec, &LightTraceOptions { photons, seed, max_events: 100_000 });
    // The uncollided fluence is tallied analytically: the standard error is the collided part's.
    let collided = mc.fluence.iter().zip(&mc.uncollided_fluence).map(|(f, u)| f[0] - u[0]).collect();
    let variance = mc.fluence_std_err.iter().map(|s| s[0] * s[0]).collect();
    FluenceRun { collided, variance, ms: mc.seconds * 1e3, iterations: 0 }
}

/// `a`'s collided fluence against the light tracer's `reference` over the mid slice (cell row `n/2` in
/// y), relative to the reference's mean there, its noise removed, with its floor.
///
/// # Errors
/// The runs' sizes differ from `n³`, or the reference's slice is black.
pub fn slice_error(a: &FluenceRun, reference: &FluenceRun, n: usize) -> Result<NoiseCorrected, String> {
    let cells = n * n * n;
    if a.collided.len() != cells || reference.collided.len() != cells || reference.variance.len() != cells {
        return Err(format!("the fluence runs do not hold {n}³ cells"));
    }
    let row = n / 2;
    let idx: Vec<usize> = (0..n).flat_map(|z| (0..n).map(move |x| x + n * (row + n * z))).collect();
    let pick = |v: &[f64]| idx.iter().map(|&i| v[i]).collect::<Vec<f64>>();
    NoiseCorrected::of(&pick(&a.collided), &pick(&reference.collided), &pick(&reference.variance))
}
