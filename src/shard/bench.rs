//! `voltab bench --suite shards`: what sharding a table's compile costs and buys, measured side by side in
//! one run.
//!
//! Input: a validated pipeline and the ids of tables to measure (default: its `MsLobes` tables).
//! Output: rows ([`crate::stages::BenchRow`]) and a text report: the table compiled whole (as
//! `voltab compile` does), each work unit computed alone one after another (as a shard task does, with
//! every core of this machine), the merge of those units; the sharding overhead (units + merge over the
//! whole compile), the merge's share, and the wall time projected on 1, 8, 64 and 512 nodes.
//!
//! Projection model (stated in the report): a node is this machine; units are spread over K nodes by
//! the same longest-first rule [`super::assign`] uses, so a node's time is the sum of its units'
//! measured times; wall time = the most loaded node + the measured merge + one task start (1 s,
//! Slurm's array dispatch on the test cluster). The wang2018-size line scales the measured walk cost
//! per photon of this table to wang2018's 50 M photons per medium for each of its g slices, in units
//! of [`crate::tables::ms_lobes::MsLobes::unit_photons`] photons, adds each unit's measured part-file
//! cost, and models the merge as the measured read per part times the part count plus the rest of the
//! measured merge scaled by the raw size ratio of their 600 MB table to this one.

use std::time::Instant;

use super::{Payload, Unit, assemble_table, compile_units, decode_part, encode_part};
use crate::compile::build_table;
use crate::registry::ValidatedPipeline;
use crate::stages::BenchRow;
use crate::tables::TableDef;

/// Seconds Slurm takes to dispatch an array task (measured on the test cluster: about 1 s).
const TASK_START_S: f64 = 1.0;
/// wang2018: photons traced per medium and the size of their stored table.
const WANG_PHOTONS: u64 = 50_000_000;
const WANG_TABLE_BYTES: f64 = 600e6;

/// Longest-first makespan of `costs` over `k` nodes.
fn makespan(costs: &[f64], k: usize) -> f64 {
    let mut sorted: Vec<f64> = costs.to_vec();
    sorted.sort_by(|a, b| b.total_cmp(a));
    let mut load = vec![0.0f64; k.max(1)];
    for c in sorted {
        let (i, _) = load.iter().enumerate().min_by(|a, b| a.1.total_cmp(b.1)).unwrap_or((0, &0.0));
        load[i] += c;
    }
    load.into_iter().fold(0.0, f64::max)
}

/// The projected wall time on 1, 8, 64 and 512 nodes: longest-first over the measured `unit_ms`, plus
/// the `fixed_ms` every run pays once (`fixed`: what it is), plus one task start; as text and rows
/// against the whole run's `whole_ms`.
#[allow(clippy::too_many_arguments)]
fn project(
    text: &mut String,
    rows: &mut Vec<BenchRow>,
    id: &str,
    whole: &str,
    whole_ms: f64,
    unit_ms: &[f64],
    fixed_ms: f64,
    fixed: &str,
) {
    text.push_str(&format!(
        "  projected wall time (node = this machine; longest-first; + {fixed} + 1 s task start):\n"
    ));
    for k in [1usize, 8, 64, 512] {
        let wall = makespan(unit_ms, k) + fixed_ms + TASK_START_S * 1e3;
        text.push_str(&format!(
            "    {k:>4} nodes {:>10.1} s  ({:.1}× the whole {whole})\n",
            wall / 1e3,
            whole_ms / wall
        ));
        rows.push(BenchRow {
            what: format!("{id}: projected on {k} nodes"),
            baseline_ms: whole_ms,
            candidate_ms: wall,
            speedup: whole_ms / wall,
            note: format!("model: longest-first over measured unit times + {fixed} + 1 s"),
        });
    }
}

/// Runs the benchmark; `say` reports progress.
pub fn run(p: &ValidatedPipeline, only: &[String], say: &dyn Fn(&str)) -> Result<(String, Vec<BenchRow>), String> {
    let ids: Vec<String> = if only.is_empty() {
        p.tables().iter().filter(|t| matches!(t.def(), TableDef::MsLobes(_))).map(|t| t.id().to_string()).collect()
    } else {
        only.to_vec()
    };
    let mut text = String::new();
    let mut rows = Vec::new();
    let all_units = compile_units(p);
    for id in &ids {
        let Some((ti, t)) = p.tables().iter().enumerate().find(|(_, t)| t.id() == id) else {
            return Err(format!("--only {id}: no such table"));
        };
        say(&format!("{id}: the whole table, as voltab compile builds it"));
        let t0 = Instant::now();
        let (whole, sidecar) = build_table(t, &|_| {}).map_err(|e| e.to_string())?;
        let local_ms = t0.elapsed().as_secs_f64() * 1e3;
        // Each unit alone, one after another, as a shard task computes it (encoded as a part file).
        let units: Vec<&Unit> = all_units.iter().filter(|u| u.table == ti).collect();
        let n = units.len();
        let mut unit_ms = Vec::with_capacity(n);
        let mut part_io_ms = 0.0;
        let mut part_bytes = 0usize;
        let mut encoded = Vec::with_capacity(n);
        for (i, u) in units.iter().enumerate() {
            say(&format!("{id}: unit {} of {n}", i + 1));
            let t1 = Instant::now();
            let payload = match u.part {
                None => {
                    let (vtab, sc) = build_table(t, &|_| {}).map_err(|e| e.to_string())?;
                    Payload::Table { vtab, sidecar: serde_json::to_vec(&sc).unwrap_or_default() }
                }
                Some(k) => Payload::Unit {
                    part: t.def().kind_impl().generate_unit(t.key(), k, &|_| {}).map_err(|e| e.to_string())?,
                    ms: 0.0,
                },
            };
            let t_io = Instant::now();
            encoded.push(encode_part(&payload));
            part_io_ms += t_io.elapsed().as_secs_f64() * 1e3;
            part_bytes += encoded.last().map_or(0, Vec::len);
            unit_ms.push(t1.elapsed().as_secs_f64() * 1e3);
        }
        say(&format!("{id}: merge"));
        let t2 = Instant::now();
        let mut read_ms = 0.0;
        let merged = if n == 1 {
            match decode_part(&encoded[0])? {
                Payload::Table { vtab, .. } => vtab,
                Payload::Unit { .. } | Payload::Texels { .. } => {
                    return Err("a whole table's unit holds a part".into());
                }
            }
        } else {
            let mut parts = Vec::new();
            for bytes in &encoded {
                match decode_part(bytes)? {
                    Payload::Unit { part, .. } => crate::tables::UnitPart::absorb(&mut parts, part),
                    Payload::Table { .. } | Payload::Texels { .. } => {
                        return Err("a split table's unit holds no table part".into());
                    }
                }
            }
            read_ms = t2.elapsed().as_secs_f64() * 1e3;
            assemble_table(t, parts, 0.0, 0.0).map_err(|e| e.to_string())?.0
        };
        let merge_ms = t2.elapsed().as_secs_f64() * 1e3;
        let identical = merged == whole;
        let units_ms: f64 = unit_ms.iter().sum();
        let overhead = (units_ms + merge_ms) / local_ms - 1.0;
        let max_unit = unit_ms.iter().copied().fold(0.0, f64::max);
        text.push_str(&format!(
            "{id} ({}): {n} work units\n  whole table            {:>10.0} ms (generate + check + encode, every core)\n  units one by one       {:>10.0} ms (sum; largest {:.0} ms, mean {:.0} ms)\n  merge                  {:>10.0} ms ({:.2} % of the whole compile)\n  sharding overhead      {:>+10.2} % of the whole compile (units + merge − whole: setup repeated per unit; no unit computes another's work)\n  merged bytes           {}\n",
            t.def().kind(),
            local_ms,
            units_ms,
            max_unit,
            units_ms / n as f64,
            merge_ms,
            100.0 * merge_ms / local_ms,
            100.0 * overhead,
            if identical { "identical to the whole table" } else { "DIFFER from the whole table" },
        ));
        text.push_str(&format!(
            "    of which part files  {part_io_ms:>10.0} ms writing {:.1} MB in the units, {read_ms:.0} ms reading and summing them in the merge; the merge's rest ({:.0} ms) finishes, checks and encodes the table as the whole compile does\n",
            part_bytes as f64 / 1e6,
            merge_ms - read_ms,
        ));
        rows.push(BenchRow {
            what: format!("{id}: whole vs {n} units + merge"),
            baseline_ms: local_ms,
            candidate_ms: units_ms + merge_ms,
            speedup: local_ms / (units_ms + merge_ms),
            note: format!(
                "merge {:.2} % of whole; bytes {}",
                100.0 * merge_ms / local_ms,
                if identical { "identical" } else { "DIFFER" }
            ),
        });
        project(&mut text, &mut rows, id, "compile", local_ms, &unit_ms, merge_ms, "merge");
        if let TableDef::MsLobes(def) = t.def() {
            let slices = def.g_values().len();
            let walk_units = unit_ms.len().saturating_sub(1).max(1);
            let walk_ms: f64 = unit_ms[..unit_ms.len() - 1].iter().sum();
            // Part files cost per file, whatever its photon count; the walk per photon.
            let io_per_part = part_io_ms / n as f64;
            let read_per_part = read_ms / walk_units as f64;
            let photons_here = def.photons as f64 * slices as f64;
            let ms_per_photon = (walk_ms - io_per_part * walk_units as f64).max(0.0) / photons_here;
            let unit_photons = def.unit_photons();
            let per_unit = ms_per_photon * unit_photons as f64 + io_per_part;
            let wang_units = WANG_PHOTONS.div_ceil(unit_photons) as usize * slices;
            let raw = sidecar.raw_bytes.max(1) as f64;
            let wang_merge =
                read_per_part * wang_units as f64 + (merge_ms - read_ms) * (WANG_TABLE_BYTES / raw).max(1.0);
            let check = unit_ms.last().copied().unwrap_or(0.0);
            let mut costs = vec![per_unit; wang_units];
            costs.push(check);
            text.push_str(&format!(
                "  wang2018 size ({} photons per g slice × {slices} slices = {wang_units} units of {unit_photons} photons, {:.1} s each; merge = {:.2} s per part read × {wang_units} + the rest scaled ×{:.1} by table size = {:.0} s):\n",
                WANG_PHOTONS,
                per_unit / 1e3,
                read_per_part / 1e3,
                WANG_TABLE_BYTES / raw,
                wang_merge / 1e3
            ));
            for k in [1usize, 8, 64, 512] {
                let wall = makespan(&costs, k) + wang_merge + TASK_START_S * 1e3;
                text.push_str(&format!("    {k:>4} nodes {:>10.1} min\n", wall / 6e4));
                rows.push(BenchRow {
                    what: format!("{id} at wang2018 size: projected on {k} nodes"),
                    baseline_ms: makespan(&costs, 1) + wang_merge,
                    candidate_ms: wall,
                    speedup: (makespan(&costs, 1) + wang_merge) / wall,
                    note: format!("{wang_units} units; measured {:.3} µs per photon", ms_per_photon * 1e3),
                });
            }
        }
    }
    Ok((text, rows))
}

/// `voltab bench --suite shards` for the lightmap bakes of `p` (tables read from `ctx.out_dir`; outputs
/// written there): each bake run whole as `voltab run` runs it, then as its tiles one by one (one
/// preparation — scene, BVH, table, atlas — as a bake task does once) plus the merge that finishes it
/// (reads the tiles, dilates, writes, checks against path tracing, bakes the probes), with the
/// lightmaps of both compared byte for byte and the wall time projected as for tables (every node
/// prepares once).
pub fn bake(
    p: &ValidatedPipeline,
    ctx: &crate::stages::StageContext,
    only: &[String],
    say: &dyn Fn(&str),
) -> Result<(String, Vec<BenchRow>), String> {
    use crate::stages::StageDef;
    let (units, _) = super::bake::bake_units(p, ctx).map_err(|e| e.to_string())?;
    let mut text = String::new();
    let mut rows = Vec::new();
    for (si, s) in p.stages().iter().enumerate() {
        let StageDef::BakeLightmaps(b) = s.def() else { continue };
        if !only.is_empty() && !only.iter().any(|o| o == s.id()) {
            continue;
        }
        let id = s.id();
        let dir = ctx.out_dir.join(if b.output.is_empty() { id } else { &b.output });
        let lightmaps = || -> Vec<(String, Vec<u8>)> {
            let mut v: Vec<(String, Vec<u8>)> = b
                .modes
                .iter()
                .flat_map(|m| ["exr", "png"].map(|x| format!("lightmap_{}.{x}", m.name())))
                .chain(std::iter::once("probes.vtab".to_string()))
                .filter_map(|n| std::fs::read(dir.join(&n)).ok().map(|bytes| (n, bytes)))
                .collect();
            v.sort();
            v
        };
        say(&format!("{id}: the whole bake, as voltab run runs it"));
        let t0 = Instant::now();
        b.run(id, ctx).map_err(|e| e.to_string())?;
        let whole_ms = t0.elapsed().as_secs_f64() * 1e3;
        let want = lightmaps();
        say(&format!("{id}: its tiles one by one"));
        let t1 = Instant::now();
        let tb = b.tile_baker(id, ctx).map_err(|e| e.to_string())?;
        let prepare_ms = t1.elapsed().as_secs_f64() * 1e3;
        let texels = tb.texels();
        let mine: Vec<&Unit> = units.iter().filter(|u| u.table == si).collect();
        let tiles = mine.len() / b.modes.len().max(1);
        let mut unit_ms = Vec::with_capacity(mine.len());
        let mut encoded = Vec::with_capacity(mine.len());
        for u in &mine {
            let k = u.part.unwrap_or(0);
            let t = Instant::now();
            let estimates = tb.bake(k / tiles.max(1), k % tiles.max(1)).map_err(|e| e.to_string())?;
            encoded.push(encode_part(&Payload::Texels { estimates, ms: 0.0 }));
            unit_ms.push(t.elapsed().as_secs_f64() * 1e3);
        }
        drop(tb);
        say(&format!("{id}: the merge"));
        let t2 = Instant::now();
        let mut given = vec![(Vec::new(), 0.0); b.modes.len()];
        for (u, bytes) in mine.iter().zip(&encoded) {
            let k = u.part.unwrap_or(0);
            match decode_part(bytes)? {
                Payload::Texels { estimates, .. } => given[k / tiles.max(1)].0.extend(estimates),
                _ => return Err(format!("unit {} holds no texels", u.name)),
            }
        }
        let read_ms = t2.elapsed().as_secs_f64() * 1e3;
        b.run_with(id, ctx, Some(&given)).map_err(|e| e.to_string())?;
        let merge_ms = t2.elapsed().as_secs_f64() * 1e3;
        let identical = lightmaps() == want;
        let units_ms: f64 = unit_ms.iter().sum();
        let overhead = (prepare_ms + units_ms + merge_ms) / whole_ms - 1.0;
        let n = unit_ms.len();
        text.push_str(&format!(
            "{id} (BakeLightmaps, {} texels × {} modes): {n} tiles of {} texels\n  whole bake             {whole_ms:>10.0} ms (trace every mode, write, check against path tracing, probes)\n  preparation            {prepare_ms:>10.0} ms (scene, BVH, table slices, atlas: once per bake task)\n  tiles one by one       {units_ms:>10.0} ms (sum; largest {:.0} ms, mean {:.0} ms)\n  merge                  {merge_ms:>10.0} ms ({:.2} % of the whole bake; {read_ms:.0} ms reading the tiles, the rest finishes the bake as the whole run does)\n  sharding overhead      {:>+10.2} % of the whole bake (preparation + tiles + merge − whole)\n  lightmaps and probes   {}\n",
            texels,
            b.modes.len(),
            crate::stages::bake::TILE_TEXELS,
            unit_ms.iter().copied().fold(0.0, f64::max),
            units_ms / n.max(1) as f64,
            100.0 * merge_ms / whole_ms,
            100.0 * overhead,
            if identical { "identical to the whole bake" } else { "DIFFER from the whole bake" },
        ));
        rows.push(BenchRow {
            what: format!("{id}: whole vs {n} tiles + merge"),
            baseline_ms: whole_ms,
            candidate_ms: prepare_ms + units_ms + merge_ms,
            speedup: whole_ms / (prepare_ms + units_ms + merge_ms),
            note: format!(
                "merge {:.2} % of whole; lightmaps {}",
                100.0 * merge_ms / whole_ms,
                if identical { "identical" } else { "DIFFER" }
            ),
        });
        project(&mut text, &mut rows, id, "bake", whole_ms, &unit_ms, prepare_ms + merge_ms, "preparation + merge");
    }
    Ok((text, rows))
}
