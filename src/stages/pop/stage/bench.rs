//! `voltab bench --suite pop`: the stage's frame → elek2014 Fig. 14's phase times and the isotropic
//! residuum's speed-up of Sec. 5.4 (Fig. 8) on a thick, nearly conservative medium.

use super::*;
use crate::physics::medium::RgbMedium;

/// elek2014 Sec. 5.4 as the paper measures it (Fig. 8): a thick, nearly conservative medium under an
/// environment, every ordinate propagated to convergence against the switch at Eq. 10's `m'` with the
/// ordinates' light merged into one isotropic grid. Grids of 16³ and the preset's ordinates; the
/// difference is the relative RMS of the two images of the scattered light (48 × 48 px).
fn env_residuum_bench(
    id: &str,
    table: &PopPresetTable,
    medium: &crate::render::voxel::VoxelMedium,
) -> Result<(String, crate::stages::BenchRow), String> {
    use crate::render::occluder::NoOccluder;
    let sky = crate::render::environment::bundled_sky();
    let ords = environment::ordinates(&sky, table.def.ordinates as usize, OrdinateSet::Importance);
    let cam = crate::stages::pop::fig12::camera(48, 48).ok_or("the Fig. 12 camera could not be built")?;
    let flow = preset_flow(table);
    let cap = 20_000;
    let mut out = Vec::new();
    for residuum in [false, true] {
        let settings = |grid: &Grid| {
            let (mut s, _) = settings_for(table, grid);
            s.eps_l = s.eps_l.min(1e-3);
            if residuum {
                Settings { iterations: cap, residuum: true, residuum_iterations: cap, ..s }
            } else {
                Settings { iterations: cap, residuum: false, ..s }
            }
        };
        let opts = environment::EnvOptions {
            dims: [16; 3],
            merge_dims: [32; 3],
            flow: &flow,
            settings: &settings,
            eye: cam.position,
        };
        let t0 = Instant::now();
        let run = environment::propagate_environment(medium, &ords, &NoOccluder, &opts)?;
        let t = ms(t0);
        let img = render::march(&run.merged.0, &run.merged.1, medium, &cam, None, &MarchOptions::default()).radiance;
        let aniso: usize = run.ordinates.iter().map(|(_, _, p)| p.anisotropic_iterations).sum();
        let iso = run.residuum.as_ref().map_or(0, |(_, p)| p.isotropic_iterations)
            + run.ordinates.iter().map(|(_, _, p)| p.isotropic_iterations).sum::<usize>();
        out.push((t, img, aniso, iso));
    }
    let (e, d) = out[1].1.iter().zip(&out[0].1).fold((0.0, 0.0), |(e, d), (x, y)| {
        (e + (0..3).map(|c| (x[c] - y[c]).powi(2)).sum::<f64>(), d + (0..3).map(|c| y[c] * y[c]).sum::<f64>())
    });
    let diff = if d > 0.0 { (e / d).sqrt() } else { 0.0 };
    let speedup = out[0].0 / out[1].0.max(1e-9);
    let line = format!(
        "\nMerged isotropic residuum under the bundled sky (same cube, {} ordinates on 16³ grids, Sec. 5.4 / Fig. 8): every ordinate to convergence {} anisotropic iterations in all, {:.0} ms; switch then one merged isotropic grid: {} anisotropic + {} isotropic iterations, {:.0} ms; speed-up {speedup:.2}×, image difference {diff:.4} (rel. RMS)\n",
        ords.len(),
        out[0].2,
        out[0].0,
        out[1].2,
        out[1].3,
        out[1].0
    );
    let row = crate::stages::BenchRow {
        what: format!("{id}: POP merged isotropic residuum vs every ordinate to convergence (environment)"),
        baseline_ms: out[0].0,
        candidate_ms: out[1].0,
        speedup,
        note: format!("images differ by {diff:.4} (rel. RMS); {} ordinates", ords.len()),
    };
    Ok((line, row))
}

impl PopRender {
    /// `voltab bench --suite pop`: the stage's frame split into elek2014 Fig. 14's phases (median of 5 runs on
    /// the current rayon pool) with the time per iteration; and the isotropic residuum's speed-up
    /// (Sec. 5.4, Fig. 8) on a thick, nearly conservative cube (`σ_s = 20 /m`, albedo 0.999, g = 0.95,
    /// the preset's grid): converged anisotropic propagation against the switch at Eq. 10's `m'`, with the
    /// relative RMS difference of their collided fluence.
    pub fn bench(&self, id: &str, ctx: &StageContext) -> Result<(String, Vec<crate::stages::BenchRow>), StageError> {
        use crate::render::occluder::NoOccluder;
        use crate::render::voxel::VoxelMedium;
        let fields = self.fields();
        let table = self.open_table(id, ctx)?;
        let v = fields.load(id, ctx, None)?;
        let media = self.media(id, ctx, &v.scene, &v.bvh)?;
        let distance: Vec<f64> = v.gbuffer.distance.data.iter().map(|&d| f64::from(d)).collect();
        let fail = |message: String| StageError::Input { stage: id.into(), message, help: "check the scene".into() };
        let mut runs = Vec::new();
        for _ in 0..5 {
            runs.push(
                render_frame(&media, &v.bvh, &table, &v.gbuffer.camera, &distance, self.range_sigma, ctx.device)
                    .map_err(fail)?,
            );
        }
        let median = |f: &dyn Fn(&PopFrame) -> f64| {
            let mut x: Vec<f64> = runs.iter().map(f).collect();
            x.sort_by(f64::total_cmp);
            x[x.len() / 2]
        };
        let sum = |f: fn(&LightRun) -> f64| move |fr: &PopFrame| fr.lights.iter().map(f).sum::<f64>();
        let grid_ms = median(&sum(|l| l.grid_ms));
        let init = median(&sum(|l| l.phases_ms.initialisation));
        let prop = median(&sum(|l| l.phases_ms.propagation));
        let res = median(&sum(|l| l.phases_ms.residuum));
        let merge_ms = median(&sum(|l| l.merge_ms));
        let march = median(&|f: &PopFrame| f.march_ms);
        let ordinates_ms = median(&|f: &PopFrame| f.environment.as_ref().map_or(0.0, |e| e.ordinates_ms));
        let importance_ms = median(&|f: &PopFrame| f.environment.as_ref().map_or(0.0, |e| e.importance_ms));
        let merge_ms = merge_ms + median(&|f: &PopFrame| f.environment.as_ref().map_or(0.0, |e| e.merge_ms));
        let l = &runs[0].lights;
        let env_count = l.iter().filter(|r| r.kind == "environment").count();
        let mut names: Vec<String> =
            l.iter().filter(|r| r.kind != "environment").map(|r| format!("{} ({})", r.light, r.kind)).collect();
        if env_count > 0 {
            names.push(format!("{env_count} environment ordinates"));
        }
        let iters: usize = l.iter().map(|r| r.anisotropic_iterations).sum();
        let iso: usize = l.iter().map(|r| r.isotropic_iterations).sum();
        let (w, h) = (v.gbuffer.camera.width, v.gbuffer.camera.height);
        let mut text = format!(
            "{id}: elek2014 POP, preset grid {:?}, {}×{}, {} threads (median of 5)\n\n| phase (Fig. 14) | ms |\n|---|---:|\n| importance propagation + projection (Sec. 5.2) | {importance_ms:.2} |\n| ordinates from the environment map (Sec. 5.1) | {ordinates_ms:.2} |\n| lights | {} |\n| grid + medium downsampling | {grid_ms:.2} |\n| initialisation (point lights: depth map + radial sweep) | {init:.2} |\n| propagation ({iters} iterations, {:.3} ms each) | {prop:.2} |\n| residuum ({iso} iterations) | {res:.2} |\n| merge radial and environment grids into the render grid (Sec. 5.3) | {merge_ms:.2} |\n| upsample + ray march | {march:.1} |\n| frame | {:.1} |\n",
            table.def.grid,
            w,
            h,
            rayon::current_num_threads(),
            names.join(", "),
            prop / iters.max(1) as f64,
            importance_ms + ordinates_ms + grid_ms + init + prop + res + merge_ms + march
        );
        // The residuum on a thick, nearly conservative cube.
        let n = table.def.grid.map(|v| v as usize);
        let medium = VoxelMedium::homogeneous(glam::DVec3::ZERO, glam::DVec3::ONE, RgbMedium::grey(20.0, 0.02, 0.95))
            .map_err(|e| fail(e.to_string()))?;
        let light = crate::stages::pop::fig12::light();
        let grid = Grid::new(&medium, light.direction, n, &NoOccluder).map_err(fail)?;
        let (mut settings, flow) = settings_for(&table, &grid);
        settings.eps_l = settings.eps_l.min(1e-3);
        let cap = 20_000;
        let full = Settings { iterations: cap, residuum: false, ..settings.clone() };
        let switched = Settings { iterations: cap, residuum: true, residuum_iterations: cap, ..settings.clone() };
        let t0 = Instant::now();
        let a = propagate::propagate(&grid, &light, &NoOccluder, &flow, &full, Observer::ThetaBins(1));
        let full_ms = ms(t0);
        let t0 = Instant::now();
        let b = propagate::propagate(&grid, &light, &NoOccluder, &flow, &switched, Observer::ThetaBins(1));
        let switched_ms = ms(t0);
        let (mut e, mut d) = (0.0, 0.0);
        for (x, y) in b.fluence.iter().zip(&a.fluence) {
            e += (x[0] - y[0]).powi(2);
            d += y[0] * y[0];
        }
        let diff = if d > 0.0 { (e / d).sqrt() } else { 0.0 };
        text.push_str(&format!(
            "\nIsotropic residuum (cube σ_s = 20 /m, albedo 0.999, g = 0.95, grid {n:?}, ε_L = {}): anisotropic to convergence {} iterations {full_ms:.1} ms; switch at m' = {} then {} isotropic iterations {switched_ms:.1} ms; speed-up {:.2}×, fluence difference {:.4} (rel. RMS)\n",
            settings.eps_l,
            a.anisotropic_iterations,
            b.anisotropic_iterations,
            b.isotropic_iterations,
            full_ms / switched_ms.max(1e-9),
            diff
        ));
        let mut rows = vec![crate::stages::BenchRow {
            what: format!("{id}: POP isotropic residuum vs anisotropic propagation to convergence"),
            baseline_ms: full_ms,
            candidate_ms: switched_ms,
            speedup: full_ms / switched_ms.max(1e-9),
            note: format!("fluence differs by {diff:.4} (rel. RMS); Eq. 10 m' = {}", settings.switch_iteration),
        }];
        // The same cube under the bundled sky: the residuum merged across the environment's grids (once,
        // for the stages that light with an environment).
        if !self.environment.is_empty() {
            let (line, row) = env_residuum_bench(id, &table, &medium).map_err(fail)?;
            text.push_str(&line);
            rows.push(row);
        }
        Ok((text, rows))
    }
    /// `voltab bench --suite gpu`: the stage's frame with the propagation on the CPU and on `ctx.device`
    /// side by side (median of 3 each), the GPU time of every pass kind, and how far the GPU frame's
    /// scattered light is from the CPU's.
    pub fn bench_gpu(
        &self,
        id: &str,
        ctx: &StageContext,
    ) -> Result<(String, Vec<crate::stages::BenchRow>), StageError> {
        let fields = self.fields();
        let table = self.open_table(id, ctx)?;
        let v = fields.load(id, ctx, None)?;
        let media = self.media(id, ctx, &v.scene, &v.bvh)?;
        let distance: Vec<f64> = v.gbuffer.distance.data.iter().map(|&d| f64::from(d)).collect();
        let fail = |message: String| StageError::Input { stage: id.into(), message, help: "check the scene".into() };
        let cam = &v.gbuffer.camera;
        let frames = |device: &crate::render::gpu::Device| -> Result<Vec<PopFrame>, StageError> {
            (0..3)
                .map(|_| render_frame(&media, &v.bvh, &table, cam, &distance, self.range_sigma, device).map_err(fail))
                .collect()
        };
        let cpu = frames(&crate::render::gpu::Device::Cpu)?;
        let gpu = frames(ctx.device)?;
        let median = |runs: &[PopFrame], f: fn(&LightRun) -> f64| {
            let mut x: Vec<f64> = runs.iter().map(|r| r.lights.iter().map(f).sum::<f64>()).collect();
            x.sort_by(f64::total_cmp);
            x[x.len() / 2]
        };
        let iterate = |l: &LightRun| l.phases_ms.propagation + l.phases_ms.residuum;
        let (cpu_ms, gpu_ms) = (median(&cpu, iterate), median(&gpu, iterate));
        let diff = crate::render::rel_rmse(&gpu[0].scattered, &cpu[0].scattered);
        let mut text = format!(
            "POP on {} ({}×{}, grid {:?}): iterations + accumulation CPU {cpu_ms:.2} ms, {} {gpu_ms:.2} ms ({:.2}×); scattered light differs by {diff:.2e} (rel. RMS)\nGPU passes (median-frame light 0):\n",
            fields.scene_path(ctx.base_dir).display(),
            cam.width,
            cam.height,
            table.def.grid,
            ctx.device.name(),
            cpu_ms / gpu_ms.max(1e-9),
        );
        if let Some(l) = gpu[0].lights.first() {
            for p in &l.gpu_passes {
                text.push_str(&format!("  {:<24} {:>3} passes {:>9.3} ms\n", p.phase, p.passes, 1e3 * p.seconds));
            }
        }
        let rows = vec![crate::stages::BenchRow {
            what: format!("{id}: POP iterations, CPU vs {}", ctx.device.name()),
            baseline_ms: cpu_ms,
            candidate_ms: gpu_ms,
            speedup: cpu_ms / gpu_ms.max(1e-9),
            note: format!("scattered light differs by {diff:.2e} (rel. RMS)"),
        }];
        Ok((text, rows))
    }
}
