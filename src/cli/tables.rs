//! Looking at inputs and outputs: `voltab check | plan | scene | inspect | verify | diff | eval | schema`
//! → what a pipeline, a scene or a table holds, printed (or a non-zero exit when it is broken).

use super::*;

/// `voltab check`: validates a pipeline without compiling (or prints its root file as JSON).
pub fn check(a: CheckArgs) -> Result<ExitCode> {
    let CheckArgs { pipeline, dump_json } = a;
    let p = load(&pipeline)?;
    if dump_json {
        let text = if pipeline.exists() { std::fs::read_to_string(&pipeline)? } else { Embedded.read(&pipeline)? };
        let file: voltab::registry::PipelineFile = ron::Options::default()
            .with_default_extension(
                ron::extensions::Extensions::IMPLICIT_SOME | ron::extensions::Extensions::UNWRAP_VARIANT_NEWTYPES,
            )
            .from_str(&text)?;
        println!("{}", serde_json::to_string_pretty(&file)?);
    } else {
        println!("{}: ok ({} tables, {} stages)", pipeline.display(), p.tables().len(), p.stages().len());
        for t in p.tables() {
            println!("  table {:<20} {:<10} key {}", t.id(), t.def().kind(), &voltab::cache::hex(t.key())[..16]);
        }
        for s in p.stages() {
            println!("  stage {:<20} {}", s.id(), s.def().kind());
        }
    }
    Ok(ExitCode::SUCCESS)
}

/// `voltab plan`: which tables and slices the scenes need.
pub fn plan(a: PlanArgs) -> Result<ExitCode> {
    let PlanArgs { pipeline, scene, json } = a;
    let p = load(&pipeline)?;
    let scenes = scene.iter().map(|f| load_scene(f)).collect::<Result<Vec<_>>>()?;
    let plan = voltab::plan::Plan::new(&p, &scenes);
    if json {
        println!("{}", serde_json::to_string_pretty(&plan)?);
    } else {
        print!("{}", plan.text());
    }
    Ok(ExitCode::SUCCESS)
}

/// `voltab scene`: what voltab imported from a scene.
pub fn scene(a: SceneArgs) -> Result<ExitCode> {
    let SceneArgs { file, json } = a;
    let scene = load_scene(&file)?;
    let summary = voltab::scene::summary::SceneSummary::of(&scene);
    if json {
        println!("{}", serde_json::to_string_pretty(&summary)?);
    } else {
        print!("{}", summary.text());
    }
    Ok(ExitCode::SUCCESS)
}

/// `voltab verify`: every table's integrity; a non-zero exit when one fails.
pub fn verify(a: VerifyArgs) -> Result<ExitCode> {
    let VerifyArgs { files } = a;
    let mut bad = 0;
    for f in &files {
        let checked = VtabReader::open(f).map_err(|e| e.to_string()).and_then(|mut r| {
            let rep = r.verify().map_err(|e| e.to_string())?;
            voltab::tables::check_known_kind(r.header()).map_err(|e| e.to_string())?;
            Ok(rep)
        });
        match checked {
            Ok(rep) => println!("ok   {} ({rep})", f.display()),
            Err(e) => {
                bad += 1;
                println!("BAD  {}: {e}", f.display());
            }
        }
    }
    if bad > 0 {
        bail!("{bad} of {} files failed verification", files.len());
    }
    Ok(ExitCode::SUCCESS)
}

/// `voltab diff`: two tables chunk by chunk; a non-zero exit beyond the tolerances.
pub fn diff(a: DiffArgs) -> Result<ExitCode> {
    let DiffArgs { a, b, abs_tol, rel_tol } = a;
    let mut ra = VtabReader::open(&a).with_context(|| format!("reading {}", a.display()))?;
    let mut rb = VtabReader::open(&b).with_context(|| format!("reading {}", b.display()))?;
    let d = container::diff(&mut ra, &mut rb)?;
    for h in &d.header_differences {
        println!("header: {h}");
    }
    for c in &d.chunks {
        println!(
            "{:<16} slice {:>5}  max abs {:.3e} at {:>7}  max rel {:.3e} at {:>7}",
            c.array, c.slice, c.max_abs, c.max_abs_index, c.max_rel, c.max_rel_index
        );
    }
    if d.identical() {
        println!("identical values");
    } else if d.within(abs_tol, rel_tol) {
        println!("within tolerance (abs {abs_tol:e}, rel {rel_tol:e})");
    } else {
        println!("DIFFERENT beyond tolerance (abs {abs_tol:e}, rel {rel_tol:e})");
        return Ok(ExitCode::FAILURE);
    }
    Ok(ExitCode::SUCCESS)
}

/// `voltab schema`: writes `schemas/` from the code, or checks it is current.
pub fn schema(a: SchemaArgs) -> Result<ExitCode> {
    let SchemaArgs { dir, check } = a;
    let files = [
        ("pipeline.schema.json", format!("{}\n", serde_json::to_string_pretty(&voltab::registry::json_schema())?)),
        ("reference.md", voltab::registry::reference_markdown()),
        (
            "VOLTAB_participating_media.schema.json",
            format!("{}\n", serde_json::to_string_pretty(&voltab::scene::gltf_import::vendor_schema())?),
        ),
    ];
    let mut stale = Vec::new();
    for (name, text) in &files {
        let path = dir.join(name);
        if check {
            if std::fs::read_to_string(&path).ok().as_deref() != Some(text.as_str()) {
                stale.push(path.display().to_string());
            }
        } else {
            std::fs::create_dir_all(&dir)?;
            voltab::cache::write_atomic(&path, text.as_bytes())?;
            println!("wrote {}", path.display());
        }
    }
    if !stale.is_empty() {
        bail!("out of date: {} — run `cargo run -- schema` to regenerate", stale.join(", "));
    }
    Ok(ExitCode::SUCCESS)
}

pub(super) fn inspect(file: &Path, all_chunks: bool) -> Result<()> {
    let r = VtabReader::open(file).with_context(|| format!("reading {}", file.display()))?;
    let h = r.header();
    let (major, minor) = r.version();
    println!("file            {}", file.display());
    println!("format          vtab {major}.{minor}");
    println!("kind            {} (layout v{})", h.kind, h.kind_schema_version);
    if let Err(e) = voltab::tables::check_known_kind(h) {
        println!("warning         {e}");
    }
    println!("generator       {}", h.generator_version);
    println!("content key     {}", voltab::cache::hex(&h.content_key));
    println!("definition      {}", h.definition_ron);
    for (ai, a) in h.arrays.iter().enumerate() {
        let shape: Vec<String> = a.axes.iter().map(|x| x.len.to_string()).collect();
        println!(
            "array {ai}: {} [{}] {:?}, unit {:?} — {}",
            a.name,
            shape.join(" x "),
            a.element,
            a.unit,
            a.description
        );
        if let Some(q) = &a.quantization {
            println!("    quantised to {} mantissa bits: max relative error {:.3e}", q.mantissa_bits, q.max_rel_error);
        }
        for x in &a.axes {
            println!(
                "    axis {:<6} {:>8} values {:?} from {} to {} {}",
                x.name, x.len, x.spacing, x.min, x.max, x.unit
            );
        }
        let chunks: Vec<_> = r.chunks().iter().filter(|c| c.array as usize == ai).collect();
        let raw: u64 = chunks.iter().map(|c| c.raw_len).sum();
        let stored: u64 = chunks.iter().map(|c| c.stored_len).sum();
        println!(
            "    {} chunks, {raw} bytes raw → {stored} stored, ratio {:.2}",
            chunks.len(),
            raw as f64 / stored.max(1) as f64
        );
        for c in chunks.iter().take(if all_chunks { usize::MAX } else { 0 }) {
            println!(
                "      slice {:>5}: {:>9} → {:>9} bytes ({:?}, crc {:08x})",
                c.slice, c.raw_len, c.stored_len, c.transform, c.crc32
            );
        }
    }
    let raw: u64 = r.chunks().iter().map(|c| c.raw_len).sum();
    let stored: u64 = r.chunks().iter().map(|c| c.stored_len).sum();
    println!("total           {raw} bytes raw → {stored} stored, ratio {:.2}", raw as f64 / stored.max(1) as f64);
    Ok(())
}

pub(super) fn eval_zh(a: &EvalZh) -> Result<()> {
    use voltab::physics::medium::HomogeneousMedium;
    use voltab::tables::zh_response::{Emitter, EmitterProfile, QueryOptions, Receiver, ZhResponseTable};
    let profile = match a.emitter {
        EvalEmitter::Point => EmitterProfile::Point,
        EvalEmitter::Directional => EmitterProfile::Directional,
        EvalEmitter::Area => EmitterProfile::Area,
    };
    let table = ZhResponseTable::open(&a.table, Some(&[profile]), Some(&[a.g])).map_err(|e| anyhow::anyhow!("{e}"))?;
    let theta = a.normal_angle.to_radians();
    let receiver = Receiver { position: [0.0; 3], normal: [theta.sin(), 0.0, theta.cos()] };
    let emitter = match a.emitter {
        EvalEmitter::Point => Emitter::Point { intensity: a.intensity, position: [0.0, 0.0, a.distance] },
        EvalEmitter::Directional => {
            Emitter::Directional { irradiance: a.intensity, toward_light: [0.0, 0.0, 1.0], depth: a.distance }
        }
        EvalEmitter::Area => {
            let t = a.patch_angle.to_radians();
            Emitter::Area { intensity: a.intensity, position: [0.0, 0.0, a.distance], normal: [t.sin(), 0.0, -t.cos()] }
        }
    };
    if !(a.distance.is_finite() && a.distance >= 0.0) {
        bail!("--distance {} must be finite and >= 0 (metres)", a.distance);
    }
    let medium = HomogeneousMedium { sigma_s: a.sigma_s, sigma_a: a.sigma_a, g: a.g };
    let opts = QueryOptions {
        backscatter: a.backscatter,
        tail: !a.no_tail,
        similarity: a.similarity,
        max_bounce: a.max_bounce,
    };
    let r = table
        .irradiance(&medium, &emitter, &receiver, &opts)
        .map_err(|e| anyhow::anyhow!("{}: {e}", a.table.display()))?;
    if a.json {
        println!("{}", serde_json::to_string_pretty(&r)?);
    } else {
        println!("direct    {:.6e} W/m^2", r.direct);
        println!("single    {:.6e} W/m^2", r.single);
        println!("multiple  {:.6e} W/m^2  (b >= 2, of which tail b > {}: {:.6e})", r.multiple, table.bounces, r.tail);
        println!("total     {:.6e} W/m^2", r.total);
    }
    Ok(())
}

pub(super) fn eval_lobes(a: &EvalLobes) -> Result<()> {
    use voltab::tables::ms_lobes::{LobeQuery, MsLobesTable};
    let table = MsLobesTable::open(&a.table, Some(&[(a.albedo, a.g)])).map_err(|e| anyhow::anyhow!("{e}"))?;
    let q = LobeQuery {
        albedo: a.albedo,
        g: a.g,
        rho: a.rho,
        z: a.z,
        theta: a.theta.to_radians(),
        phi: a.phi.to_radians(),
    };
    let v = table.lobe(&q).map_err(|e| anyhow::anyhow!("{}: {e}", a.table.display()))?;
    if a.json {
        println!("{}", serde_json::json!({ "total": v.total, "double": v.double }));
    } else {
        println!("total   {:.6e} 1/(mfp sr)  (all paths with >= 2 scattering events)", v.total);
        println!("double  {:.6e} 1/(mfp sr)  (exactly 2 scattering events)", v.double);
    }
    Ok(())
}
