//! One POP frame (elek2014 Secs. 4–5): a preset table and the scene's media → the solver settings
//! (Eq. 10's switch from the medium's mean `σ_s` and `g`), the propagation on each light's grid —
//! directional lights on light-aligned grids, point lights on radial grids merged into a
//! medium-aligned one, an environment through its principal ordinates — and the composed image.

use super::*;

/// The POP settings of a preset table for a grid (Eq. 10's switch from the medium's mean `σ_s` and `g`).
pub fn settings_for(table: &PopPresetTable, grid: &Grid) -> (Settings, FlowTable) {
    let (sigma_s_mean, g) = crate::stages::pop::grid::Cell::means(&grid.cells, grid.g);
    // The seeds start at a = g (propagate's module doc): the largest anisotropy Eq. 10 starts from.
    preset_settings(table, g, sigma_s_mean, grid.size[2], grid.dims[2])
}

/// The iteration settings and flow table of a preset, with Eq. 10's switch `m'` for phase mean cosine
/// `g` (also the seeds' anisotropy), mean `σ_s`, cell size `dx` along the light and `grid_len` cells
/// along it. Uncapped: `propagate` switches only when `m'` is below the iteration budget.
pub(super) fn preset_settings(
    table: &PopPresetTable,
    g: f64,
    sigma_s_mean: f64,
    dx: f64,
    grid_len: usize,
) -> (Settings, FlowTable) {
    let def = &table.def;
    let switch = crate::tables::pop_preset::switch_iteration_raw(def.eps_a, g, g, sigma_s_mean, dx, grid_len)
        .unwrap_or(usize::MAX);
    let flow = preset_flow(table);
    let settings = Settings {
        iterations: def.iterations as usize,
        residuum: def.residuum,
        switch_iteration: switch,
        residuum_iterations: def.residuum_iterations as usize,
        eps_l: def.eps_l,
    };
    (settings, flow)
}

/// The preset's flow table (the exact partition when the stored rows are unusable).
pub(super) fn preset_flow(table: &PopPresetTable) -> FlowTable {
    FlowTable::from_rows(table.flow_rows().to_vec()).unwrap_or_else(|_| FlowTable::exact(table.def.a_bins as usize))
}

/// Runs the propagation on `device`: the CPU solver, or its GPU twin ([`crate::stages::pop::gpu`]) with
/// the GPU's per-pass times.
pub fn propagate_on(
    device: &crate::render::gpu::Device,
    grid: &Grid,
    light: &crate::render::voxel::DirectionalLight,
    occluder: &dyn crate::render::occluder::Occluder,
    flow: &FlowTable,
    settings: &Settings,
    eye: glam::DVec3,
) -> Result<(propagate::Propagation, Vec<crate::render::gpu::PassTime>), String> {
    match device {
        crate::render::gpu::Device::Cpu => {
            Ok((propagate::propagate(grid, light, occluder, flow, settings, Observer::Eye(eye)), Vec::new()))
        }
        #[cfg(feature = "gpu")]
        crate::render::gpu::Device::Gpu(gpu) => {
            crate::stages::pop::gpu::propagate(gpu, grid, light, occluder, flow, settings, Observer::Eye(eye))
                .map_err(|e| e.to_string())
        }
    }
}

/// Propagates every directional light of `media` on `device` and ray-marches the camera view.
pub fn render_frame(
    media: &SceneMedia,
    bvh: &SceneBvh,
    table: &PopPresetTable,
    cam: &ViewCamera,
    distance: &[f64],
    range_sigma: f64,
    device: &crate::render::gpu::Device,
) -> Result<PopFrame, String> {
    let occluder = BvhOccluder(bvh);
    let dims = table.def.grid.map(|v| v as usize);
    let (w, h) = (cam.width, cam.height);
    let mut scattered = vec![[0.0f64; 3]; w * h];
    let mut transmittance = vec![[1.0f64; 3]; w * h];
    let mut lights = Vec::new();
    let mut march_ms = 0.0;
    let opts =
        MarchOptions { range_sigma: if range_sigma > 0.0 { range_sigma } else { f64::INFINITY }, ..Default::default() };
    for (light, name) in media.lights.iter().zip(&media.light_names) {
        let t0 = Instant::now();
        let grid = Grid::new(&media.medium, light.direction, dims, &occluder)?;
        let grid_ms = ms(t0);
        let (settings, flow) = settings_for(table, &grid);
        let (p, gpu_passes) = propagate_on(device, &grid, light, &occluder, &flow, &settings, cam.position)?;
        let t0 = Instant::now();
        let f = render::march(&grid, &p.toward_eye, &media.medium, cam, Some(distance), &opts);
        march_ms += ms(t0);
        for (s, r) in scattered.iter_mut().zip(&f.radiance) {
            for c in 0..3 {
                s[c] += r[c];
            }
        }
        transmittance = f.transmittance;
        let seeded = p.energy.first().copied().unwrap_or(0.0);
        lights.push(LightRun {
            light: name.clone(),
            kind: "directional",
            merge_ms: 0.0,
            grid: grid.dims,
            cell: grid.size,
            switch_iteration: settings.switch_iteration,
            anisotropic_iterations: p.anisotropic_iterations,
            isotropic_iterations: p.isotropic_iterations,
            residual_energy: if seeded > 0.0 { p.energy.last().copied().unwrap_or(0.0) / seeded } else { 0.0 },
            grid_ms,
            phases_ms: p.times.into(),
            device: device.name(),
            gpu_passes,
        });
    }
    let mut env_summary = None;
    if let Some(env) = &media.environment {
        let (f, summary) = render_environment(media, env, &occluder, table, cam, distance, &opts, &mut lights)?;
        march_ms += f.march_ms;
        for (s, r) in scattered.iter_mut().zip(&f.frame.radiance) {
            for c in 0..3 {
                s[c] += r[c];
            }
        }
        transmittance = f.frame.transmittance;
        env_summary = Some(summary);
    }
    if !media.points.is_empty() {
        let f = render_points(media, &occluder, table, cam, distance, &opts, &mut lights)?;
        march_ms += f.march_ms;
        for (s, r) in scattered.iter_mut().zip(&f.frame.radiance) {
            for c in 0..3 {
                s[c] += r[c];
            }
        }
        transmittance = f.frame.transmittance;
    }
    let to_img =
        |v: Vec<[f64; 3]>| Image { width: w, height: h, data: v.into_iter().map(|c| c.map(|x| x as f32)).collect() };
    Ok(PopFrame {
        scattered: to_img(scattered),
        transmittance: to_img(transmittance),
        lights,
        march_ms,
        environment: env_summary,
    })
}

/// The point lights' part of a frame.
struct PointFrame {
    frame: render::Frame,
    march_ms: f64,
}

/// The merge grid's resolution: double the preset's rectilinear grid (elek2014 Sec. 5.3), at most 128.
pub fn merge_dims(table: &PopPresetTable) -> [usize; 3] {
    table.def.grid.map(|v| (2 * v as usize).clamp(1, 128))
}

/// The iteration settings of a radial grid: Eq. 10 with the mean `σ_s` of its occupied cells and the mean
/// shell spacing `r_far/S`, at least `S` iterations before the switch.
pub fn radial_settings(table: &PopPresetTable, grid: &RadialGrid) -> (Settings, FlowTable) {
    let (sigma_s_mean, g) = crate::stages::pop::grid::Cell::means(&grid.cells, grid.g);
    let s = grid.shells();
    preset_settings(table, g, sigma_s_mean, grid.radii[s] / s as f64, s)
}

/// Propagates every point light on its radial grid (CPU), merges the grids into one medium-aligned grid
/// and ray-marches it with the lights' single scattering.
fn render_points(
    media: &SceneMedia,
    occluder: &BvhOccluder<'_>,
    table: &PopPresetTable,
    cam: &ViewCamera,
    distance: &[f64],
    opts: &MarchOptions,
    runs: &mut Vec<LightRun>,
) -> Result<PointFrame, String> {
    let [n, shells] = table.def.radial_grid.map(|v| v as usize);
    let mut grids = Vec::new();
    for (light, name) in media.points.iter().zip(&media.point_names) {
        let t0 = Instant::now();
        let grid = RadialGrid::new(&media.medium, light.position, n, shells, occluder)?;
        let grid_ms = ms(t0);
        let (settings, flow) = radial_settings(table, &grid);
        let p = radial_propagate::propagate(&grid, &media.medium, light, occluder, &flow, &settings, cam.position);
        let seeded = p.energy.first().copied().unwrap_or(0.0);
        runs.push(LightRun {
            light: name.clone(),
            kind: "point",
            grid: [n, n, grid.shells()],
            cell: [grid.radii[1], grid.radii[grid.shells()], (4.0 * std::f64::consts::PI).sqrt() / n as f64],
            switch_iteration: settings.switch_iteration,
            anisotropic_iterations: p.anisotropic_iterations,
            isotropic_iterations: p.isotropic_iterations,
            residual_energy: if seeded > 0.0 { p.energy.last().copied().unwrap_or(0.0) / seeded } else { 0.0 },
            grid_ms,
            phases_ms: p.times.into(),
            merge_ms: 0.0,
            device: "cpu",
            gpu_passes: Vec::new(),
        });
        grids.push((grid, p));
    }
    let t0 = Instant::now();
    let merged = Grid::medium_aligned(&media.medium, merge_dims(table))?;
    // The VPLs of reflected light bring their uncollided light through the grid too.
    let reflected = media.first_reflection_vpl();
    let fields: Vec<std::borrow::Cow<'_, [[f64; 3]]>> = grids
        .iter()
        .enumerate()
        .map(|(i, (g, p))| {
            if i < reflected {
                return std::borrow::Cow::Borrowed(p.toward_eye.as_slice());
            }
            let direct = radial_propagate::uncollided_toward_eye(g, p, cam.position);
            std::borrow::Cow::Owned(
                p.toward_eye.iter().zip(direct).map(|(a, b)| [0, 1, 2].map(|c| a[c] + b[c])).collect(),
            )
        })
        .collect();
    let sources: Vec<(&RadialGrid, &[[f64; 3]])> =
        grids.iter().zip(&fields).map(|((g, _), f)| (g, f.as_ref())).collect();
    let merged_field = merge::merge(&merged, &sources);
    let merge_ms = ms(t0);
    // The merge is shared; each light is charged its share.
    let first = runs.len() - grids.len();
    for r in &mut runs[first..] {
        r.merge_ms = merge_ms / grids.len() as f64;
    }
    let t0 = Instant::now();
    let lights: Vec<(&RadialGrid, &radial_propagate::RadialPropagation)> =
        grids.iter().take(reflected).map(|(g, p)| (g, p)).collect();
    let frame = merge::march_points(&merged, &merged_field, &lights, &media.medium, cam, Some(distance), opts);
    Ok(PointFrame { frame, march_ms: ms(t0) })
}

/// Propagates every ordinate of the environment on its own grid (CPU), merges the accumulation grids into
/// one medium-aligned grid (Sec. 5.3) and ray-marches it.
#[allow(clippy::too_many_arguments)]
fn render_environment(
    media: &SceneMedia,
    env: &Environment,
    occluder: &BvhOccluder<'_>,
    table: &PopPresetTable,
    cam: &ViewCamera,
    distance: &[f64],
    opts: &MarchOptions,
    runs: &mut Vec<LightRun>,
) -> Result<(PointFrame, EnvSummary), String> {
    let n = if env.ordinates == 0 { table.def.ordinates as usize } else { env.ordinates };
    let flow = preset_flow(table);
    let t0 = Instant::now();
    let importance = if table.def.importance && env.set == OrdinateSet::Importance {
        let settings = Settings {
            iterations: table.def.iterations as usize,
            residuum: false,
            switch_iteration: usize::MAX,
            residuum_iterations: 0,
            eps_l: table.def.eps_l,
        };
        let size = table.def.importance_map.map(|v| v as usize);
        let n = table.def.importance_grid as usize;
        Some(environment::importance_map(&media.medium, occluder, cam, &flow, &settings, n, size)?)
    } else {
        None
    };
    let importance_ms = ms(t0);
    let t0 = Instant::now();
    let ords = environment::ordinates_with_importance(&env.map, n, env.set, importance.as_ref());
    let ordinates_ms = ms(t0);
    let settings = |grid: &Grid| settings_for(table, grid).0;
    let env_opts = environment::EnvOptions {
        dims: table.def.grid.map(|v| v as usize),
        merge_dims: merge_dims(table),
        flow: &flow,
        settings: &settings,
        eye: cam.position,
    };
    let run = environment::propagate_environment(&media.medium, &ords, occluder, &env_opts)?;
    for (k, ((grid, settings, p), grid_s)) in run.ordinates.iter().zip(&run.grid_seconds).enumerate() {
        let seeded = p.energy.first().copied().unwrap_or(0.0);
        runs.push(LightRun {
            light: format!("{} ordinate {k}", env.name),
            kind: "environment",
            grid: grid.dims,
            cell: grid.size,
            switch_iteration: settings.switch_iteration,
            anisotropic_iterations: p.anisotropic_iterations,
            isotropic_iterations: p.isotropic_iterations,
            residual_energy: if seeded > 0.0 { p.energy.last().copied().unwrap_or(0.0) / seeded } else { 0.0 },
            grid_ms: grid_s * 1e3,
            phases_ms: p.times.into(),
            merge_ms: 0.0,
            device: "cpu",
            gpu_passes: Vec::new(),
        });
    }
    if let Some((grid, p)) = &run.residuum {
        runs.push(LightRun {
            light: format!("{} isotropic residuum", env.name),
            kind: "environment residuum",
            grid: grid.dims,
            cell: grid.size,
            switch_iteration: 0,
            anisotropic_iterations: 0,
            isotropic_iterations: p.isotropic_iterations,
            residual_energy: {
                let first = p.energy.first().copied().unwrap_or(0.0);
                if first > 0.0 { p.energy.last().copied().unwrap_or(0.0) / first } else { 0.0 }
            },
            grid_ms: run.handover_seconds * 1e3,
            phases_ms: p.times.into(),
            merge_ms: 0.0,
            device: "cpu",
            gpu_passes: Vec::new(),
        });
    }
    let merge_ms = run.merge_seconds * 1e3;
    let (merged, merged_field) = (&run.merged.0, &run.merged.1);
    let t0 = Instant::now();
    let frame = render::march(merged, merged_field, &media.medium, cam, Some(distance), opts);
    let summary = EnvSummary {
        map: env.name.clone(),
        size: [env.map.width, env.map.height],
        integral: env.map.integral(),
        ordinates: ords,
        importance: importance.is_some(),
        importance_ms,
        ordinates_ms,
        merge_ms,
    };
    Ok((PointFrame { frame, march_ms: ms(t0) }, summary))
}

/// The environment map of the scene's dome light ([`env_map::dome_map`]); a texture that cannot be
/// read is an input error naming the scene file, the prim and the texture, with the fix.
pub(super) fn dome_environment(id: &str, scene: &Scene, dome: &EnvironmentLight) -> Result<EnvMap, StageError> {
    env_map::dome_map(dome).map_err(|e| {
        let texture = dome.texture.as_ref().map_or("(none)".to_string(), |t| t.display().to_string());
        StageError::Input {
            stage: id.into(),
            message: format!(
                "{}: DomeLight {}: cannot light the medium with its texture {texture}: {e}",
                scene.source.display(),
                dome.name
            ),
            help: "fix the DomeLight's inputs:texture:file: it must name a latitude-longitude RGB OpenEXR file \
                   (convert others, e.g. `oiiotool sky.hdr -o sky.exr`), and a relative asset path is relative to \
                   the layer that authors it; or give the stage's environment field, which overrides the dome"
                .into(),
        }
    })
}

/// `colour · transmittance (+ scattered)`.
pub fn compose(colour: &RgbImage, frame: &PopFrame, with_scattered: bool) -> RgbImage {
    let data = colour
        .data
        .iter()
        .zip(&frame.transmittance.data)
        .zip(&frame.scattered.data)
        .map(|((c, t), s)| [0, 1, 2].map(|k| c[k] * t[k] + if with_scattered { s[k] } else { 0.0 }))
        .collect();
    Image { width: colour.width, height: colour.height, data }
}
