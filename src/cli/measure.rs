//! Measuring: `voltab report | bench | stability | validate | export` → error against run time,
//! timings side by side, the formulas on extreme inputs, and the judgement of an independent renderer.

use super::*;

/// `voltab report`: error against run time of every table and, with `--stages`, of every stage.
pub fn report(a: ReportArgs) -> Result<ExitCode> {
    let ReportArgs { pipeline, out, stages, tables } = a;
    let progress = progress();
    let cache = SceneCache::default();
    let cpu_device = voltab::render::gpu::Device::Cpu;
    if !stages {
        let p = load(&pipeline)?;
        let r = voltab::report::run(&p, &out, progress)?;
        print!("{}", voltab::report::markdown(&r));
        println!("wrote {}/report.json, report.md and {} plots", out.display(), r.tables.len());
    }
    if let Some(p) = compiled_for_stages(&pipeline, &tables, progress, &cache)? {
        let base = base_dir(&p);
        let ctx = voltab::stages::StageContext {
            out_dir: &tables,
            base_dir: &base,
            progress,
            device: &cpu_device,
            scenes: &cache,
        };
        for s in p.stages() {
            if let Some(md) = s.def().stage().report(s.id(), &ctx, &out)? {
                print!("{md}");
                println!("wrote {}/{}-* (Markdown, JSON where available, error-vs-time plot)", out.display(), s.id());
            }
        }
    }
    Ok(ExitCode::SUCCESS)
}

/// `voltab bench`: timings measured side by side, as ratios (the flags choose which).
pub fn bench(a: BenchArgs) -> Result<ExitCode> {
    use voltab::stages::BenchFocus;
    let BenchArgs { pipeline, suite, json, only, tables_only, rays, tables } = a;
    let progress = progress();
    let cache = SceneCache::default();
    let cpu_device = voltab::render::gpu::Device::Cpu;
    let mut rows = Vec::new();
    let focus = match suite {
        Suite::Tables => {
            let p = load(&pipeline)?;
            rows = voltab::bench::run(&p, &voltab::bench::BenchOptions { only, tables_only })?;
            if let Some(triangles) = rays {
                rows.extend(voltab::bench::ray_rows(triangles)?);
            }
            None
        }
        Suite::Rays => {
            rows = voltab::bench::ray_rows(rays.unwrap_or(voltab::bench::RAY_BENCH_TRIANGLES))?;
            None
        }
        Suite::Shards => {
            let p = load(&pipeline)?;
            let is_stage = |o: &String| p.stages().iter().any(|s| s.id() == o.as_str());
            let (stage_only, table_only): (Vec<String>, Vec<String>) = only.iter().cloned().partition(is_stage);
            let say = |m: &str| {
                if progress {
                    eprintln!("{m}");
                }
            };
            // Prints a measurement's text (unless --json) and keeps its rows.
            let mut keep = |(text, r): (String, Vec<_>)| {
                if !json {
                    print!("{text}");
                }
                rows.extend(r);
            };
            if only.is_empty() || !table_only.is_empty() {
                keep(voltab::shard::bench::run(&p, &table_only, &say).map_err(|e| anyhow::anyhow!(e))?);
            }
            // The lightmap bakes as tiles (their tables compiled into --tables first).
            if (only.is_empty() || !stage_only.is_empty())
                && let Some(p) = compiled_for_stages(&pipeline, &tables, progress, &cache)?
            {
                let base = base_dir(&p);
                let ctx = voltab::stages::StageContext {
                    out_dir: &tables,
                    base_dir: &base,
                    progress: false,
                    device: &cpu_device,
                    scenes: &cache,
                };
                keep(voltab::shard::bench::bake(&p, &ctx, &stage_only, &say).map_err(|e| anyhow::anyhow!(e))?);
            }
            None
        }
        Suite::Bake => Some(Some(BenchFocus::Bake)),
        Suite::Effects => Some(Some(BenchFocus::Effects)),
        Suite::Translucent => Some(Some(BenchFocus::Translucent)),
        Suite::Pop => Some(Some(BenchFocus::Pop)),
        Suite::Gpu => Some(None),
    };
    // The stages' own benchmarks (`None`: their GPU benchmarks); effects need no tables, the others
    // compile theirs into --tables first.
    if let Some(focus) = focus {
        let device = if focus.is_none() {
            let (device, message) =
                voltab::render::gpu::select(voltab::render::gpu::DeviceRequest::Gpu).map_err(|e| anyhow::anyhow!(e))?;
            eprintln!("{message}");
            device
        } else {
            cpu_device
        };
        let p = if focus == Some(BenchFocus::Effects) {
            Some(load(&pipeline)?)
        } else {
            compiled_for_stages(&pipeline, &tables, progress, &cache)?
        };
        if let Some(p) = p {
            let base = base_dir(&p);
            let ctx = voltab::stages::StageContext {
                out_dir: &tables,
                base_dir: &base,
                progress,
                device: &device,
                scenes: &cache,
            };
            for s in p.stages() {
                let measured = match focus {
                    None => s.def().stage().bench_gpu(s.id(), &ctx)?,
                    Some(f) if s.def().stage().bench_focus() == Some(f) => s.def().stage().bench(s.id(), &ctx)?,
                    Some(_) => None,
                };
                if let Some((text, r)) = measured {
                    if !json && !text.is_empty() {
                        println!("{text}");
                    }
                    rows.extend(r);
                }
            }
        }
    }
    if json {
        println!("{}", serde_json::to_string_pretty(&rows)?);
    } else {
        print!("{}", voltab::bench::render(&rows));
    }
    Ok(ExitCode::SUCCESS)
}

/// `voltab stability`: every formula on extreme inputs; a non-zero exit when one fails.
pub fn stability(a: StabilityArgs) -> Result<ExitCode> {
    let StabilityArgs { all } = a;
    let rows = voltab::registry::stability_rows();
    let failed = rows.iter().filter(|r| !r.ok()).count();
    for r in rows.iter().filter(|r| all || !r.ok()) {
        println!("{r}");
    }
    println!("{} passed, {failed} failed", rows.len() - failed);
    if failed > 0 {
        return Ok(ExitCode::FAILURE);
    }
    Ok(ExitCode::SUCCESS)
}

/// `voltab export`: a scene written as another renderer's scene.
pub fn export(what: ExportCommand) -> Result<ExitCode> {
    let ExportCommand::Mitsuba { file, out, camera, width, height, spp, texels } = what;
    let scene = load_scene(&file)?;
    // The bake's own texels (computed first: a scene without lightmap UVs fails before anything is written).
    let texel_set =
        (texels > 0).then(|| voltab::validation::texels::texels(&scene, texels)).transpose().map_err(|e| {
            anyhow::anyhow!(
                "{e}\n  help: give the scene's meshes lightmap UVs (glTF TEXCOORD_1, USD st1) or leave out --texels"
            )
        })?;
    let options = voltab::reference::mitsuba::ExportOptions { camera, width, height, spp };
    let m = voltab::reference::mitsuba::export(&scene, &options, &out).map_err(|e| anyhow::anyhow!("{e}"))?;
    if let Some(set) = texel_set {
        let path = out.join("texels.json");
        let json = serde_json::to_string(&set)?;
        voltab::cache::write_atomic(&path, format!("{json}\n").as_bytes())
            .with_context(|| format!("cannot write {}", path.display()))?;
    }
    println!(
        "wrote {} ({} shapes, {} media, {} lights)",
        out.join(&m.scene_xml).display(),
        m.shapes.len(),
        m.media.len(),
        m.lights.len()
    );
    for w in &m.warnings {
        eprintln!("warning: {}: {}", w.location, w.message);
    }
    Ok(ExitCode::SUCCESS)
}

/// `voltab validate`: each selected stage made comparable, judged by Mitsuba, written as a report.
pub(super) fn validate(
    pipeline: &Path,
    only: &[String],
    quality: voltab::validation::Quality,
    out: &Path,
    tables: &Path,
    progress: bool,
) -> Result<()> {
    use voltab::validation::{self, Validation, cases};
    let cache = SceneCache::default();
    let p = compiled_for_stages(pipeline, tables, progress, &cache)?
        .ok_or_else(|| anyhow::anyhow!("{}: no stage reads a scene; nothing to validate", pipeline.display()))?;
    if let Some(bad) = only.iter().find(|id| !p.stages().iter().any(|s| s.id() == id.as_str())) {
        let ids: Vec<&str> = p.stages().iter().map(|s| s.id()).collect();
        bail!("{}: no stage \"{bad}\" (stages: {})", pipeline.display(), ids.join(", "));
    }
    let base = base_dir(&p);
    let device = voltab::render::gpu::Device::Cpu;
    let ctx =
        voltab::stages::StageContext { out_dir: tables, base_dir: &base, progress, device: &device, scenes: &cache };
    let harness = validation::python::Harness::locate();
    let mut results = Vec::new();
    for s in p.stages().iter().filter(|s| only.is_empty() || only.iter().any(|id| id == s.id())) {
        let dir = out.join(s.id());
        eprintln!("validate   {:<20} {}", s.id(), s.def().kind());
        let rows = match cases::prepare(s.id(), s.def(), &ctx, quality, &dir, &harness)? {
            cases::Prepared::Cases(cases) => {
                let many = cases.len() > 1;
                let mut rows = Vec::new();
                for case in &cases {
                    let sub = if many { dir.join(case.stage.rsplit('/').next().unwrap_or("")) } else { dir.clone() };
                    rows.push(validation::judge(case, &sub, &harness)?);
                }
                rows
            }
            cases::Prepared::NotCompared(why) => vec![validation::not_compared(s.id(), s.def().kind(), &why)],
        };
        for r in rows {
            for m in &r.methods {
                println!(
                    "validate   {:<20} {:<10} {} ({:.0} ms; Mitsuba {:.0} s)",
                    r.stage, m.name, m.text, m.ms, r.reference_s
                );
            }
            if let Some(why) = &r.not_compared {
                println!("validate   {:<20} not compared: {why}", r.stage);
            }
            results.push(r);
        }
    }
    let v = Validation { pipeline: pipeline.to_path_buf(), quality, stages: results };
    let files = validation::write(&v, out)?;
    print!("{}", validation::markdown(&v));
    println!("wrote {}", files.iter().map(|f| f.display().to_string()).collect::<Vec<_>>().join(", "));
    Ok(())
}
