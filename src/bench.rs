//! `voltab bench`: timings measured side by side in one process, printed as ratios (absolute
//! times only as context). Tests never assert wall-clock times; this command is where timing
//! claims are checked.
//!
//! Input: a validated pipeline. Output: a text table on stdout (and the same rows as JSON with
//! `--json`): cold compile vs no-op recompile, 1 vs N worker threads, and zstd levels 3/9/19 per table.
//! [`ray_rows`] adds the ray-query benchmark (BVH build and rays/s, 1 vs N threads) on a procedural
//! scene; it needs no pipeline.

use std::time::Instant;

use glam::DVec3;

use crate::compile::{CompileError, CompileOptions, compile, encode_table};
use crate::container::ContainerError;
use crate::pipeline::Limits;
use crate::registry::ValidatedPipeline;
use crate::tables::TableDef;

/// One measured comparison (defined beside the stages, which measure most of them).
pub use crate::stages::BenchRow;

/// Bench failure.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum BenchError {
    /// Compiling failed.
    #[error(transparent)]
    Compile(#[from] CompileError),
    /// Encoding failed.
    #[error(transparent)]
    Container(#[from] ContainerError),
    /// The scratch folder could not be made.
    #[error("cannot create a scratch folder: {0}")]
    Scratch(std::io::Error),
    /// A variant of a table did not validate.
    #[error("{0}")]
    Variant(String),
}

fn ms(t: Instant) -> f64 {
    t.elapsed().as_secs_f64() * 1e3
}

/// Median of `n` timed runs of `f`.
fn median_ms<E>(n: usize, mut f: impl FnMut() -> Result<(), E>) -> Result<f64, E> {
    let mut v = Vec::with_capacity(n);
    for _ in 0..n {
        let t = Instant::now();
        f()?;
        v.push(ms(t));
    }
    v.sort_by(f64::total_cmp);
    Ok(v[n / 2])
}

fn with_level(def: &TableDef, level: i32) -> TableDef {
    match def {
        TableDef::PhaseHg(p) => TableDef::PhaseHg(crate::tables::phase_hg::PhaseHg { zstd_level: level, ..p.clone() }),
        TableDef::ZhResponse(p) => {
            TableDef::ZhResponse(crate::tables::zh_response::ZhResponse { zstd_level: level, ..p.clone() })
        }
        TableDef::MsLobes(p) => TableDef::MsLobes(crate::tables::ms_lobes::MsLobes { zstd_level: level, ..p.clone() }),
        TableDef::PopPreset(p) => {
            TableDef::PopPreset(crate::tables::pop_preset::PopPreset { zstd_level: level, ..p.clone() })
        }
    }
}

/// What to benchmark.
#[derive(Debug, Clone, Default)]
pub struct BenchOptions {
    /// Only these table ids (all when empty).
    pub only: Vec<String>,
    /// Skip the whole-pipeline compile comparisons.
    pub tables_only: bool,
}

/// Runs the benchmarks.
pub fn run(p: &ValidatedPipeline, bench: &BenchOptions) -> Result<Vec<BenchRow>, BenchError> {
    let scratch = tempfile::Builder::new().prefix("voltab-bench-").tempdir().map_err(BenchError::Scratch)?;
    let opts = |dir: &str, jobs| CompileOptions {
        out_dir: scratch.path().join(dir),
        jobs,
        only: bench.only.clone(),
        ..Default::default()
    };
    let mut rows = Vec::new();
    if !bench.tables_only {
        rows.extend(compile_rows(p, &opts)?);
    }
    per_table_rows(p, bench, &mut rows)?;
    Ok(rows)
}

/// Cold vs up-to-date compile, 1 vs N threads.
fn compile_rows(
    p: &ValidatedPipeline,
    opts: &dyn Fn(&str, Option<usize>) -> CompileOptions,
) -> Result<Vec<BenchRow>, BenchError> {
    let mut rows = Vec::new();

    let t = Instant::now();
    compile(p, &opts("cold", None))?;
    let cold = ms(t);
    let noop = median_ms(5, || compile(p, &opts("cold", None)).map(|_| ()))?;
    rows.push(BenchRow {
        what: "compile: cold vs up-to-date rerun".into(),
        baseline_ms: cold,
        candidate_ms: noop,
        speedup: cold / noop,
        note: format!("{} tables", p.tables().len()),
    });

    let threads = rayon::current_num_threads();
    let t = Instant::now();
    compile(p, &opts("j1", Some(1)))?;
    let one = ms(t);
    let t = Instant::now();
    compile(p, &opts("jn", Some(threads)))?;
    let many = ms(t);
    rows.push(BenchRow {
        what: format!("compile: 1 vs {threads} threads (cold)"),
        baseline_ms: one,
        candidate_ms: many,
        speedup: one / many,
        note: String::new(),
    });

    Ok(rows)
}

/// Per table: zstd levels, and query throughput for ZhResponse tables.
fn per_table_rows(p: &ValidatedPipeline, bench: &BenchOptions, rows: &mut Vec<BenchRow>) -> Result<(), BenchError> {
    let limits = Limits::from_machine();
    for table in p.tables().iter().filter(|t| bench.only.is_empty() || bench.only.iter().any(|o| o == t.id())) {
        let t_gen = Instant::now();
        let generated =
            table.def().kind_impl().generate(table.key(), &|_| {}).map_err(|e| BenchError::Variant(e.to_string()))?;
        let generate_ms = ms(t_gen);
        let mut sizes = Vec::new();
        let mut times = Vec::new();
        for level in [3, 9, 19] {
            let v = table.with_def(with_level(table.def(), level), &limits).map_err(BenchError::Variant)?;
            let mut bytes = 0;
            let t = median_ms(3, || {
                encode_table(&v, &generated).map(|e| {
                    bytes = e.bytes.len();
                })
            })?;
            sizes.push(bytes);
            times.push(t);
        }
        if let TableDef::ZhResponse(def) = table.def() {
            rows.extend(zh_query_rows(table.id(), def, &generated)?);
        }
        if let TableDef::MsLobes(def) = table.def() {
            rows.extend(ms_lobes_rows(table.id(), def, &generated, generate_ms)?);
        }
        for (i, level) in [3, 19].into_iter().enumerate() {
            let k = if i == 0 { 0 } else { 2 };
            rows.push(BenchRow {
                what: format!("encode {}: zstd 9 vs {level}", table.id()),
                baseline_ms: times[1],
                candidate_ms: times[k],
                speedup: times[1] / times[k],
                note: format!("size {level}/9 = {:.3}", sizes[k] as f64 / sizes[1] as f64),
            });
        }
    }
    Ok(())
}

/// Queries per configuration set in the ZH query benchmark.
pub const ZH_QUERIES: usize = 200_000;

/// Irradiance queries of a `ZhResponse` table on one thread: the O(N) Appendix A route the baker uses vs
/// the full-SH route (rotate the lobe to world SH, dot with the rotated clamped cosine). Random media
/// (albedo in [0.5, 1], g within the table), distances in [0.01, 10] mfp, normals on the sphere, drawn
/// from counter-based streams (the same set for both routes).
fn zh_query_rows(
    id: &str,
    def: &crate::tables::zh_response::ZhResponse,
    generated: &crate::tables::Generated,
) -> Result<Vec<BenchRow>, BenchError> {
    use crate::physics::medium::HomogeneousMedium;
    use crate::physics::rng::StreamKey;
    use crate::physics::sh;
    use crate::tables::zh_response::{Emitter, QueryOptions, Receiver, ZhResponseTable};
    let table = ZhResponseTable::from_arrays(def, &generated.arrays, &generated.values).map_err(BenchError::Variant)?;
    let (g_lo, g_hi) = (table.g[0], table.g[table.g.len() - 1]);
    let mut rows = Vec::new();
    for &profile in &table.emitters {
        let queries: Vec<(HomogeneousMedium, Emitter, Receiver)> = (0..ZH_QUERIES as u64)
            .map(|i| {
                let k = StreamKey { table: 0x9e37, cell: i };
                let u = |dim| k.uniform(0, dim);
                let sigma_t = 1.0;
                let albedo = 0.5 + 0.5 * u(0);
                let medium = HomogeneousMedium {
                    sigma_s: albedo * sigma_t,
                    sigma_a: (1.0 - albedo) * sigma_t,
                    g: g_lo + (g_hi - g_lo) * u(1),
                };
                let d = 0.01 * 1000f64.powf(u(2));
                let emitter = match profile {
                    crate::tables::zh_response::EmitterProfile::Point => {
                        Emitter::Point { intensity: 1.0, position: [0.0, 0.0, d] }
                    }
                    crate::tables::zh_response::EmitterProfile::Directional => {
                        Emitter::Directional { irradiance: 1.0, toward_light: [0.0, 0.0, 1.0], depth: d }
                    }
                    crate::tables::zh_response::EmitterProfile::Area => {
                        let t = std::f64::consts::PI * u(5);
                        Emitter::Area { intensity: 1.0, position: [0.0, 0.0, d], normal: [t.sin(), 0.0, -t.cos()] }
                    }
                };
                let z = 2.0 * u(3) - 1.0;
                let phi = std::f64::consts::TAU * u(4);
                let s = (1.0 - z * z).sqrt();
                (medium, emitter, Receiver { position: [0.0; 3], normal: [s * phi.cos(), s * phi.sin(), z] })
            })
            .collect();
        let opts = QueryOptions::default();
        let t = Instant::now();
        for (m, e, r) in &queries {
            std::hint::black_box(table.irradiance(m, e, r, &opts).map_err(|x| BenchError::Variant(x.to_string()))?);
        }
        let fast = ms(t);
        let cosine = sh::clamped_cosine_zh(table.order);
        let t = Instant::now();
        for (m, e, r) in &queries {
            let rad = table.radiance(m, e, r, &opts).map_err(|x| BenchError::Variant(x.to_string()))?;
            std::hint::black_box(sh::sh_dot(&rad.sh, &sh::zh_rotate(&cosine, r.normal)));
        }
        let full = ms(t);
        let per_s = ZH_QUERIES as f64 / (fast * 1e-3);
        rows.push(BenchRow {
            what: format!("zh query {id} {profile:?}: full SH vs O(N)"),
            baseline_ms: full,
            candidate_ms: fast,
            speedup: full / fast,
            note: format!("{ZH_QUERIES} queries on 1 thread: {:.2} M/s per core (target >= 5)", per_s / 1e6),
        });
    }
    Ok(rows)
}

/// wang2018 Table 2: the slowest material's precomputation (Milk, 50 M particles), in ms.
pub const PAPER_SLOWEST_MATERIAL_MS: f64 = 212_000.0;

/// `MsLobes` rows: the whole table's generation against the paper's slowest single material; the walk's
/// events per second per core (a 2^16-photon variant on 1 vs N threads); and the symmetric-lobe error
/// (wang2018 Fig. 8) from a full-lobe variant for BumpySphere at g = 0.7 and 0.9.
fn ms_lobes_rows(
    id: &str,
    def: &crate::tables::ms_lobes::MsLobes,
    generated: &crate::tables::Generated,
    generate_ms: f64,
) -> Result<Vec<BenchRow>, BenchError> {
    use crate::tables::ms_lobes::{MsLobes, MsLobesTable, symmetry_error};
    let mut rows = Vec::new();
    let n_g = def.g_values().len();
    rows.push(BenchRow {
        what: format!("lobes {id}: paper's slowest material vs all"),
        baseline_ms: PAPER_SLOWEST_MATERIAL_MS,
        candidate_ms: generate_ms,
        speedup: PAPER_SLOWEST_MATERIAL_MS / generate_ms,
        note: format!(
            "baseline = wang2018 Table 2 (Milk, 50 M particles, published); candidate = {} materials, {n_g} g x {} albedos, {} photons/g, {} events",
            def.materials.len(),
            def.albedo_values().len(),
            def.photons,
            generated.stats.samples
        ),
    });
    let small = MsLobes { photons: 1 << 16, ..def.clone() };
    let key = [0x5a; 32];
    let threads = rayon::current_num_threads();
    let run = |n: usize| -> Result<f64, BenchError> {
        let pool =
            rayon::ThreadPoolBuilder::new().num_threads(n).build().map_err(|e| BenchError::Variant(e.to_string()))?;
        let t = Instant::now();
        pool.install(|| small.generate(&key, &|_| {})).map_err(|e| BenchError::Variant(e.to_string()))?;
        Ok(ms(t))
    };
    let (one, many) = (run(1)?, run(threads)?);
    let events = small.photons as f64 * f64::from(small.max_order) * n_g as f64;
    rows.push(BenchRow {
        what: format!("lobes walk {id}: 1 vs {threads} threads"),
        baseline_ms: one,
        candidate_ms: many,
        speedup: one / many,
        note: format!(
            "{:.1} M scattering events/s per core (1 thread, incl. kernel and closure), {:.1} M/s on {threads}",
            events / one / 1e3,
            events / many / 1e3
        ),
    });
    for g in [0.7, 0.9] {
        let full = MsLobes {
            materials: vec!["BumpySphere".into()],
            g: vec![g],
            albedo_grid: 0,
            albedos: Vec::new(),
            rho_max: 16.0,
            z_min: -8.0,
            z_max: 24.0,
            rho_bins: 48,
            z_bins: 80,
            direction_bins: 32,
            lobe: crate::tables::ms_lobes::LobeKind::Full,
            phi_bins: 13,
            photons: 1 << 18,
            ..def.clone()
        };
        let t = Instant::now();
        let gen_full = full.generate(&key, &|_| {}).map_err(|e| BenchError::Variant(e.to_string()))?;
        let full_ms = ms(t);
        let table =
            MsLobesTable::from_arrays(&full, &gen_full.arrays, &gen_full.values).map_err(BenchError::Variant)?;
        // A second, independent table: its difference from the first measures the Monte-Carlo noise
        // that the symmetric-lobe error includes (for independent noise of σ per node, E|L − L̄| ≈ 0.8σ
        // and E|L_a − L_b| ≈ 1.13σ, so the noise floor of the integrated error is ≈ 0.71 × the latter).
        let full_b = crate::tables::ms_lobes::MsLobes { seed: full.seed + 1, ..full.clone() };
        let gen_b = full_b.generate(&[0x5b; 32], &|_| {}).map_err(|e| BenchError::Variant(e.to_string()))?;
        let table_b = MsLobesTable::from_arrays(&full, &gen_b.arrays, &gen_b.values).map_err(BenchError::Variant)?;
        let mut note = String::new();
        for (rho, z) in [(5.0, 5.0), (10.0, 5.0), (5.0, 10.0)] {
            let (rel, l1, peak) =
                symmetry_error(&table, 0.9545, g, rho, z).map_err(|e| BenchError::Variant(e.to_string()))?;
            let noise = 0.71 * lobe_l1_difference(&table, &table_b, 0.9545, g, rho, z)?;
            note.push_str(&format!(
                "({rho}, {z}): {:.1} % integrated (noise floor {:.1} %), {:.1} % of the peak at worst, peak {peak:.1} deg off axis; ",
                100.0 * l1,
                100.0 * noise,
                100.0 * rel
            ));
        }
        rows.push(BenchRow {
            what: format!("lobes full vs symmetric, g = {g}"),
            baseline_ms: full_ms,
            candidate_ms: full_ms,
            speedup: 1.0,
            note: format!("symmetric-lobe error (BumpySphere R, alpha 0.9545) at (rho, z) = {note}"),
        });
    }
    Ok(rows)
}

/// `∫|L_a − L_b| dω / ∫ L_a dω` over the lobe nodes of two full-lobe tables at canonical `(ρ, z)`.
fn lobe_l1_difference(
    a: &crate::tables::ms_lobes::MsLobesTable,
    b: &crate::tables::ms_lobes::MsLobesTable,
    albedo: f64,
    g: f64,
    rho: f64,
    z: f64,
) -> Result<f64, BenchError> {
    use crate::tables::ms_lobes::{LobeQuery, MsLobesTable};
    let lobe_total =
        |t: &MsLobesTable, q: &LobeQuery| t.lobe(q).map(|v| v.total).map_err(|e| BenchError::Variant(e.to_string()));
    let (nt, np) = a.lobe_nodes();
    let node = |i: usize, n: usize| std::f64::consts::PI * i as f64 / (n.max(2) - 1) as f64;
    let trapezoid = |i: usize, n: usize| if i == 0 || i + 1 == n { 0.5 } else { 1.0 };
    let (mut diff, mut norm) = (0.0, 0.0);
    for i in 0..nt {
        for m in 0..np {
            let q = LobeQuery { albedo, g, rho, z, theta: node(i, nt), phi: node(m, np) };
            let (x, y) = (lobe_total(a, &q)?, lobe_total(b, &q)?);
            let w = trapezoid(i, nt) * trapezoid(m, np) * node(i, nt).sin();
            diff += w * (x - y).abs();
            norm += w * x;
        }
    }
    Ok(if norm > 0.0 { diff / norm } else { 0.0 })
}

/// Default triangle budget of [`ray_rows`] (2²⁰).
pub const RAY_BENCH_TRIANGLES: usize = 1 << 20;

/// Image size (square) of the primary rays in [`ray_rows`]; the incoherent set has as many rays.
pub const RAY_BENCH_IMAGE: usize = 1024;

/// Ray-query benchmark on [`crate::scene::bvh::procedural::sphere_field`] with at least `triangles`
/// triangles: the BVH build, then closest hits for primary-like coherent rays (a pinhole camera's
/// pixels in scan-line order) and incoherent rays (origins uniform in the scene bounds, directions
/// uniform on the sphere), and shadow rays (from the primary hits to a point light above the scene),
/// each on 1 thread vs all threads of the global rayon pool: medians of 3 runs, alternating between
/// the two pools so that both see the same machine load.
pub fn ray_rows(triangles: usize) -> Result<Vec<BenchRow>, BenchError> {
    use crate::scene::bvh::{Ray, SceneBvh, procedural};
    let scene = procedural::sphere_field(triangles);
    let threads = rayon::current_num_threads();
    let pool = |n: usize| {
        rayon::ThreadPoolBuilder::new().num_threads(n).build().map_err(|e| BenchError::Variant(e.to_string()))
    };
    let (one, all) = (pool(1)?, pool(threads)?);
    let mut rows = Vec::new();

    let (build_one, build_all, _) = interleaved(&one, &all, &|| (SceneBvh::build(&scene).stats().build_ms, 0));
    let bvh = all.install(|| SceneBvh::build(&scene));
    let stats = bvh.stats();
    rows.push(BenchRow {
        what: format!("bvh build: 1 vs {threads} threads"),
        baseline_ms: build_one,
        candidate_ms: build_all,
        speedup: build_one / build_all,
        note: format!(
            "{} triangles ({} meshes), {} CWBVH nodes; {:.1} M triangles/s on {threads}",
            stats.triangles,
            scene.meshes.len(),
            stats.nodes,
            stats.triangles as f64 / build_all / 1e3
        ),
    });

    let Some((lo, hi)) = scene.bounds() else { return Ok(rows) };
    let (lo, hi) = (DVec3::from_array(lo), DVec3::from_array(hi));
    let center = 0.5 * (lo + hi);
    let size = hi - lo;
    let n = RAY_BENCH_IMAGE;
    // A camera above one edge of the field looking at its centre, 60° vertical field of view.
    let eye = DVec3::new(center.x, hi.y + 0.35 * size.x, lo.z - 0.15 * size.z);
    let fwd = center - eye;
    let fwd = fwd / fwd.length();
    let right = fwd.cross(DVec3::Y);
    let right = right / right.length();
    let up = right.cross(fwd);
    let tan = (30f64).to_radians().tan();
    let primary: Vec<Ray> = (0..n * n)
        .map(|i| {
            let (x, y) = ((i % n) as f64 + 0.5, (i / n) as f64 + 0.5);
            let (sx, sy) = ((2.0 * x / n as f64 - 1.0) * tan, (1.0 - 2.0 * y / n as f64) * tan);
            Ray::new(eye.to_array(), (fwd + sx * right + sy * up).to_array())
        })
        .collect();
    let key = crate::physics::rng::StreamKey { table: 0x7a7e_5eed, cell: 1 };
    let incoherent: Vec<Ray> = (0..(n * n) as u64)
        .map(|i| {
            let s = key.sample(i);
            let o = lo + size * DVec3::new(s.uniform(0), s.uniform(1), s.uniform(2));
            let z = 2.0 * s.uniform(3) - 1.0;
            let phi = std::f64::consts::TAU * s.uniform(4);
            let r = (1.0 - z * z).max(0.0).sqrt();
            Ray::new(o.to_array(), [r * phi.cos(), z, r * phi.sin()])
        })
        .collect();
    let hits = all.install(|| bvh.closest_hits(&primary));
    let light = DVec3::new(center.x + 0.2 * size.x, hi.y + 0.5 * size.x, center.z - 0.1 * size.z);
    let eps = 1e-4 * 1.0f64.max(size.x).max(size.y).max(size.z);
    let shadow: Vec<Ray> = hits
        .iter()
        .zip(&primary)
        .filter_map(|(h, r)| {
            let h = h.as_ref()?;
            // Offset the start along the normal, on the side the ray came from.
            let side = if h.front_face { 1.0 } else { -1.0 };
            let p = DVec3::from_array(r.origin)
                + h.t * DVec3::from_array(r.direction)
                + side * eps * DVec3::from_array(h.geometric_normal);
            Some(Ray { origin: p.to_array(), direction: (light - p).to_array(), t_min: 0.0, t_max: 1.0 })
        })
        .collect();

    let closest = |rays: &[Ray]| bvh.closest_hits(rays).iter().filter(|h| h.is_some()).count();
    let cases: [(&str, &[Ray], bool); 3] =
        [("primary (coherent)", &primary, false), ("incoherent", &incoherent, false), ("shadow", &shadow, true)];
    for (name, rays, is_shadow) in cases {
        let run = || {
            let t = Instant::now();
            let n = if is_shadow { bvh.occluded_batch(rays).iter().filter(|&&b| b).count() } else { closest(rays) };
            (ms(t), n)
        };
        let (t_one, t_all, count) = interleaved(&one, &all, &run);
        let mrays = |t: f64| rays.len() as f64 / t / 1e3;
        rows.push(BenchRow {
            what: format!("rays {name}: 1 vs {threads} threads"),
            baseline_ms: t_one,
            candidate_ms: t_all,
            speedup: t_one / t_all,
            note: format!(
                "{} rays, {:.1} % {}; {:.2} Mrays/s on 1 thread, {:.2} Mrays/s on {threads}",
                rays.len(),
                100.0 * count as f64 / rays.len().max(1) as f64,
                if is_shadow { "occluded" } else { "hit" },
                mrays(t_one),
                mrays(t_all)
            ),
        });
    }
    Ok(rows)
}

/// Medians of 3 runs of `f` (returning ms and a count) on each pool, alternating between the pools so
/// that both see the same machine load; the count of the last run.
fn interleaved(
    one: &rayon::ThreadPool,
    all: &rayon::ThreadPool,
    f: &(dyn Fn() -> (f64, usize) + Sync),
) -> (f64, f64, usize) {
    let (mut a, mut b, mut count) = (Vec::new(), Vec::new(), 0);
    for _ in 0..3 {
        a.push(one.install(f).0);
        let (t, n) = all.install(f);
        b.push(t);
        count = n;
    }
    a.sort_by(f64::total_cmp);
    b.sort_by(f64::total_cmp);
    (a[1], b[1], count)
}

/// The rows as a text table.
pub fn render(rows: &[BenchRow]) -> String {
    let mut s =
        format!("{:<44} {:>12} {:>12} {:>9}  {}\n", "comparison", "baseline ms", "candidate ms", "speedup", "note");
    for r in rows {
        s.push_str(&format!(
            "{:<44} {:>12.2} {:>12.2} {:>8.2}x  {}\n",
            r.what, r.baseline_ms, r.candidate_ms, r.speedup, r.note
        ));
    }
    s
}
