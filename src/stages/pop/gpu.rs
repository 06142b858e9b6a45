//! POP propagation on the GPU (elek2014 Secs. 4.2–4.3, 5.4): the iterations and the accumulation
//! toward the eye as compute passes.
//!
//! **Input → output.** The same inputs as [`propagate::propagate`] with an [`Observer::Eye`] (a
//! [`Grid`] with its link factors, the light, the occluder, the preset's flow table and the
//! iteration settings) → the same [`Propagation`] (`uncollided`, `fluence`, `toward_eye`, the
//! energy of every iterate and the iteration counts), plus the GPU time of each phase.
//!
//! **Split.** The Sec. 4.1 transmittance sweep and first-scattering seed stay on the CPU
//! (`propagate::initialise`: they cast shadow rays through the scene's BVH) and are uploaded once.
//! Each iteration is three passes: `pop_step.wgsl` (gather the six neighbours, Eqs. 2–6, ping-pong
//! buffers, and the iterate's energy per workgroup), `pop_accumulate.wgsl` (Eqs. 7–8) and
//! `pop_energy.wgsl` (sum the energy, append it, and clear `running` once it is below `ε_L` of the
//! seed). All `M` anisotropic and residuum iterations are recorded up front; the passes after the
//! stop see `running = 0` and do nothing, so the host never waits on an iteration and the iteration
//! counts equal the CPU's (up to an energy within f32 rounding of the threshold).
//!
//! **Precision.** The GPU works in f32 where the CPU works in f64; partition look-ups, link factors
//! and sums differ by rounding only, so the fields agree to a relative ~1e-5 per iteration (the
//! tests state their tolerances).

use std::time::Instant;

use super::shaders;
use crate::physics::hg;
use crate::render::color::Rgb;
use crate::render::gpu::context::{Gpu, GpuError, Pass, PassTime, Words};
use crate::render::occluder::Occluder;
use crate::render::voxel::DirectionalLight;
use crate::stages::pop::grid::Grid;
use crate::stages::pop::propagate::{self, FlowTable, Observer, PhaseTimes, Propagation, Settings};

fn vec4s(v: &[Rgb]) -> Vec<[f32; 4]> {
    v.iter().map(|c| [c[0] as f32, c[1] as f32, c[2] as f32, 0.0]).collect()
}

fn links(v: &[[Rgb; 3]]) -> Vec<[f32; 4]> {
    v.iter().flat_map(|axes| axes.iter().map(|c| [c[0] as f32, c[1] as f32, c[2] as f32, 0.0])).collect()
}

fn rgbs(v: &[[f32; 4]]) -> Vec<Rgb> {
    v.iter().map(|c| [c[0] as f64, c[1] as f64, c[2] as f64]).collect()
}

/// Runs [`propagate::propagate`]'s scheme on the GPU for an eye observer. Returns the propagation
/// (its `times` hold the GPU phase times, with initialisation measured on the CPU) and the per-pass
/// GPU times.
///
/// # Errors
/// [`GpuError::Limit`] for a grid too large for the adapter's buffers, [`GpuError::Runtime`] when a
/// pass fails; [`GpuError::Limit`] also for an observer other than an eye (θ bins are CPU-only).
pub fn propagate(
    gpu: &Gpu,
    grid: &Grid,
    light: &DirectionalLight,
    occluder: &dyn Occluder,
    flow: &FlowTable,
    settings: &Settings,
    observer: Observer,
) -> Result<(Propagation, Vec<PassTime>), GpuError> {
    let Observer::Eye(eye) = observer else {
        return Err(GpuError::Limit("the GPU POP path accumulates toward an eye only; θ bins run on the CPU".into()));
    };
    let start = Instant::now();
    let n = grid.len();
    let cells = u32::try_from(n).map_err(|_| GpuError::Limit(format!("{n} cells exceed the GPU path's 2³² limit")))?;
    let (uncollided, seed) = propagate::initialise(grid, light, occluder);
    let d = grid.axes[2];
    let g = grid.g;
    let u: Vec<f64> = (0..n).map(|i| (eye - grid.center(grid.coords(i))).normalize_or_zero().dot(d)).collect();
    // The uncollided Dirac lobe and the half-weighted seed (a = g) are accumulated on the host in
    // f64, exactly as the CPU path does, then the GPU adds the iterates.
    let mut toward_eye = vec![[0.0; 3]; n];
    let mut fluence = vec![[0.0; 3]; n];
    for i in 0..n {
        for c in 0..3 {
            toward_eye[i][c] = uncollided[i][c] * hg::phase(u[i], g[c]);
            if seed[i][c] > 0.0 {
                toward_eye[i][c] += 0.5 * seed[i][c] * hg::phase(u[i], g[c] * g[c]);
            }
            fluence[i][c] = 0.5 * seed[i][c];
        }
    }
    let seeded: f64 = seed.iter().map(|v| v[0] + v[1] + v[2]).sum();
    let initialisation = start.elapsed().as_secs_f64();

    let residuum = settings.residuum && settings.switch_iteration < settings.iterations;
    let aniso_cap = if residuum { settings.switch_iteration } else { settings.iterations };
    let iso_cap = if residuum { settings.residuum_iterations } else { 0 };
    let total_iterations = aniso_cap + iso_cap;

    let step_k = gpu.kernel(&shaders::POP_STEP, "main")?;
    let acc_k = gpu.kernel(&shaders::POP_ACCUMULATE, "main")?;
    let energy_k = gpu.kernel(&shaders::POP_ENERGY, "main")?;

    let flow_rows: Vec<[f32; 4]> = (0..flow.len())
        .map(|j| {
            let r = flow.row(j);
            [r[0] as f32, r[1] as f32, r[2] as f32, 0.0]
        })
        .collect();
    let zeros = vec![[0.0f32; 4]; n];
    let a0 = vec4s(&vec![g; n]);
    let l = [gpu.buffer_from("pop L 0", &vec4s(&seed))?, gpu.buffer_from("pop L 1", &zeros)?];
    let a = [gpu.buffer_from("pop a 0", &a0)?, gpu.buffer_from("pop a 1", &zeros)?];
    let link_t = gpu.buffer_from("pop link T", &links(&grid.link_transmittance))?;
    let link_decay = gpu.buffer_from("pop link decay", &links(&grid.link_decay))?;
    let flow_buf = gpu.buffer_from("pop flow", &flow_rows)?;
    let (gx, gy) = gpu.groups(cells);
    let groups = gx * gy;
    let partial = gpu.buffer_zeroed("pop partial energy", groups as u64 * 4)?;
    let mut state_init = vec![1u32, 0, 0, 0];
    state_init.push((seeded as f32).to_bits());
    state_init.resize(4 + total_iterations + 1, 0);
    // A seed with no energy stops before the first iteration, as on the CPU.
    let stop = settings.eps_l * seeded;
    if seeded <= stop {
        state_init[0] = 0;
    }
    let state = gpu.buffer_from("pop state", &state_init)?;
    let u_buf = gpu.buffer_from("pop u", &u.iter().map(|&v| v as f32).collect::<Vec<f32>>())?;
    let eye_buf = gpu.buffer_from("pop toward eye", &vec4s(&toward_eye))?;
    let fluence_buf = gpu.buffer_from("pop fluence", &vec4s(&fluence))?;

    let dims = grid.dims.map(|v| v as u32);
    let step_params = |iso: u32| {
        gpu.uniform(
            "pop step",
            &Words::default().u(dims[0]).u(dims[1]).u(dims[2]).u(cells).u(flow.len() as u32).u(iso).pad().0,
        )
    };
    let acc_params = |iso: u32| {
        gpu.uniform(
            "pop accumulate",
            &Words::default().u(cells).u(iso).f(1.0).u(0).f(g[0] as f32).f(g[1] as f32).f(g[2] as f32).f(0.0).0,
        )
    };
    let energy_params = |iso: u32| gpu.uniform("pop energy", &Words::default().u(groups).u(iso).f(stop as f32).pad().0);
    let modes: Vec<u32> = if iso_cap > 0 { vec![0, 1] } else { vec![0] };
    // Bind groups per (mode, ping-pong parity).
    let mut binds = Vec::new();
    for &iso in &modes {
        let (sp, ap, ep) = (step_params(iso), acc_params(iso), energy_params(iso));
        for parity in 0..2 {
            let (src, dst) = (parity, 1 - parity);
            let step = gpu.bind(
                &step_k,
                &[&sp, &l[src], &a[src], &link_t, &link_decay, &flow_buf, &l[dst], &a[dst], &partial, &state],
            );
            let acc = gpu.bind(&acc_k, &[&ap, &l[dst], &a[dst], &u_buf, &eye_buf, &fluence_buf, &state]);
            let energy = gpu.bind(&energy_k, &[&ep, &partial, &state]);
            binds.push((step, acc, energy));
        }
    }
    let mut passes = Vec::with_capacity(3 * total_iterations);
    for it in 0..total_iterations {
        let iso = it >= aniso_cap;
        let (step, acc, energy) = &binds[(iso as usize) * 2 + it % 2];
        let phase = if iso { "residuum" } else { "propagation" };
        passes.push(Pass { phase, kernel: &step_k, bind: step, items: cells });
        passes.push(Pass {
            phase: if iso { "residuum accumulation" } else { "accumulation" },
            kernel: &acc_k,
            bind: acc,
            items: cells,
        });
        passes.push(Pass { phase: "stopping rule", kernel: &energy_k, bind: energy, items: 64 });
    }
    let pass_times = gpu.run(&passes)?;

    let st: Vec<u32> = gpu.read(&state, 4 + total_iterations + 1)?;
    let iterations = st[1] as usize;
    let energy: Vec<f64> = st[4..4 + iterations + 1].iter().map(|&b| f32::from_bits(b) as f64).collect();
    let toward_eye = rgbs(&gpu.read::<[f32; 4]>(&eye_buf, n)?);
    let fluence = rgbs(&gpu.read::<[f32; 4]>(&fluence_buf, n)?);
    let sum = |phases: &[&str]| {
        pass_times.iter().filter(|t| phases.contains(&t.phase.as_str())).map(|t| t.seconds).sum::<f64>()
    };
    let times = PhaseTimes {
        initialisation,
        propagation: sum(&["propagation", "accumulation", "stopping rule"]),
        residuum: sum(&["residuum", "residuum accumulation"]),
        accumulation: sum(&["accumulation", "residuum accumulation"]),
    };
    Ok((
        Propagation {
            uncollided,
            fluence,
            toward_eye,
            bins: Vec::new(),
            theta_bins: 0,
            anisotropic_iterations: st[2] as usize,
            isotropic_iterations: st[3] as usize,
            energy,
            times,
            last: Vec::new(),
        },
        pass_times,
    ))
}

#[cfg(test)]
mod tests;
