//! Farm bakes: a pipeline's lightmap bakes split into texel tiles over N shards, and a merge that
//! writes the lightmaps one machine writes.
//!
//! Input: a [`ValidatedPipeline`] whose tables are already merged (or compiled) into a folder, and a
//! [`ShardSpec`]. Output of [`bake_shard`] (`voltab run --shard I/N --tables DIR`): a shard folder
//! like a compile shard's (`shard.json` with `job: bake`, one checksummed `.part` per unit), where a
//! unit is [`TILE_TEXELS`] texels of one mode of one `BakeLightmaps` stage (dubouchet2019 Sec. 5–6:
//! every texel is an independent receiver drawing from its own stream, keyed by its atlas pixel).
//! Output of [`merge_bake`] (`voltab merge` given bake shards): every stage of the pipeline run into
//! the output folder as `voltab run` runs them, the bakes finished from the tiles' estimates
//! (dilation, EXR/PNG, reference check, probes, summary) — byte-identical lightmaps and probes
//! (tested in `tests/shard.rs`); the other stages run whole on the merging machine.
//!
//! A bake's content key covers the pipeline's tables, the stage's definition and its imported scene,
//! so tiles of another scene or sample count are refused as stale.

use std::path::{Path, PathBuf};
use std::time::Instant;

use rayon::prelude::*;

use super::{
    Checked, Finished, Job, PartEntry, Payload, ShardError, ShardSpec, ShardSummary, Unit, assign, check_shards,
    encode_part, pipeline_key, reusable,
};
use crate::cache::{OutputDir, write_atomic};
use crate::registry::ValidatedPipeline;
use crate::stages::bake::{BakeLightmaps, TILE_TEXELS, TileBaker};
use crate::stages::{StageContext, StageDef, StageError, StageOutcome};

/// The tile units of every bake stage of `p` (stage order, then mode, then tile) and the job's
/// content key. Imports each bake's scene and builds its atlas (the tile count is the texel count).
pub fn bake_units(p: &ValidatedPipeline, ctx: &StageContext) -> Result<(Vec<Unit>, String), ShardError> {
    let mut h = blake3::Hasher::new();
    h.update(b"voltab bake key v1\0");
    h.update(pipeline_key(p).as_bytes());
    let mut units = Vec::new();
    for (si, s) in p.stages().iter().enumerate() {
        let StageDef::BakeLightmaps(b) = s.def() else { continue };
        let (scene, texels) = b.scene_and_texels(s.id(), ctx).map_err(stage_err)?;
        h.update(s.id().as_bytes());
        h.update(&serde_json::to_vec(s.def()).unwrap_or_default());
        h.update(&bincode::serde::encode_to_vec(scene.as_ref(), bincode::config::standard()).unwrap_or_default());
        let tiles = texels.div_ceil(TILE_TEXELS);
        for (mi, mode) in b.modes.iter().enumerate() {
            for k in 0..tiles {
                let n = (texels - k * TILE_TEXELS).min(TILE_TEXELS) as u64;
                units.push(Unit {
                    name: format!("{}/{}#{k}", s.id(), mode.name()),
                    table: si,
                    part: Some(mi * tiles + k),
                    cost: n * u64::from(b.samples),
                });
            }
        }
    }
    Ok((units, h.finalize().to_hex().to_string()))
}

fn stage_err(e: StageError) -> ShardError {
    ShardError::Spec { message: e.to_string(), help: "fix the stage or its scene".into() }
}

/// Tiles per mode of each bake stage (by stage index), counted once from the unit list.
fn tiles_per_mode(p: &ValidatedPipeline, units: &[Unit]) -> std::collections::BTreeMap<usize, usize> {
    let mut count = std::collections::BTreeMap::new();
    for u in units {
        *count.entry(u.table).or_insert(0) += 1;
    }
    for (si, n) in &mut count {
        if let Some(StageDef::BakeLightmaps(b)) = p.stages().get(*si).map(|s| s.def()) {
            *n /= b.modes.len().max(1);
        }
    }
    count
}

/// The bake stage of unit `u`, its mode and its tile (`tiles`: [`tiles_per_mode`]).
fn locate<'p>(
    p: &'p ValidatedPipeline,
    tiles: &std::collections::BTreeMap<usize, usize>,
    u: &Unit,
) -> Option<(&'p BakeLightmaps, usize, usize)> {
    let StageDef::BakeLightmaps(b) = p.stages().get(u.table)?.def() else { return None };
    let t = tiles.get(&u.table).copied().unwrap_or(1).max(1);
    let k = u.part?;
    Some((b, k / t, k % t))
}

fn part_file(key: &str, u: &Unit) -> String {
    let mut h = blake3::Hasher::new();
    h.update(key.as_bytes());
    h.update(u.name.as_bytes());
    format!("{}.part", &h.finalize().to_hex()[..32])
}

/// Computes shard `spec`'s bake tiles of `p` into the shard folder `dir`, reading the tables from
/// `ctx.out_dir`. Tiles finished by an earlier attempt are reused; the manifest is written last.
pub fn bake_shard(
    p: &ValidatedPipeline,
    scenes: &[PathBuf],
    spec: ShardSpec,
    ctx: &StageContext,
    dir: &Path,
) -> Result<ShardSummary, ShardError> {
    let t0 = Instant::now();
    let (units, key) = bake_units(p, ctx)?;
    let out = OutputDir::open(dir, || {
        eprintln!("waiting for another voltab run that is using {}", dir.display());
    })?;
    let owner = assign(&units, spec.count);
    let tiles = tiles_per_mode(p, &units);
    let mine: Vec<&Unit> = units.iter().zip(&owner).filter(|(_, s)| **s == spec.index).map(|(u, _)| u).collect();
    let bar = crate::compile::progress_bar(
        ctx.progress,
        mine.iter().map(|u| u.cost).sum(),
        format!("bake shard {}/{}: texels", spec.index, spec.count),
    );
    let mut parts = Vec::with_capacity(mine.len());
    let (mut computed, mut reused) = (Vec::new(), Vec::new());
    // One stage prepared at a time (scene, BVH, table, atlas), for all of its tiles in this shard.
    let mut baker: Option<(usize, TileBaker<'_>)> = None;
    for u in &mine {
        let file = part_file(&key, u);
        let path = dir.join(&file);
        let entry = |bytes: &[u8], ms: f64| PartEntry::of(&u.name, &file, bytes, ms);
        // A tile's part: its estimates (40 B a texel), bounded with slack.
        if let Some(bytes) = reusable(&path, (TILE_TEXELS as u64) * 64 + (1 << 20)) {
            bar.inc(u.cost);
            reused.push(u.name.clone());
            parts.push(entry(&bytes, 0.0));
            continue;
        }
        let Some((b, mode, tile)) = locate(p, &tiles, u) else {
            return Err(ShardError::Spec {
                message: format!("unit {} names no bake", u.name),
                help: "report this bug".into(),
            });
        };
        if baker.as_ref().is_none_or(|(si, _)| *si != u.table) {
            let id = p.stages()[u.table].id();
            baker = Some((u.table, b.tile_baker(id, ctx).map_err(stage_err)?));
        }
        let Some((_, tb)) = baker.as_ref() else { continue };
        let t1 = Instant::now();
        let estimates = tb.bake(mode, tile).map_err(stage_err)?;
        let ms = t1.elapsed().as_secs_f64() * 1e3;
        let bytes = encode_part(&Payload::Texels { estimates, ms });
        write_atomic(&path, &bytes)?;
        bar.inc(u.cost);
        computed.push((u.name.clone(), ms));
        parts.push(entry(&bytes, ms));
    }
    bar.finish_and_clear();
    Finished { job: Job::Bake, key, units: &units, parts, computed, reused }.write(p, scenes, spec, out.path(), t0)
}

/// Checks the bake shard folders `dirs` of `p` (as [`super::merge`] checks compile shards), then runs
/// every stage of `p` into `ctx.out_dir` as `voltab run` does: bakes finished from their tiles, the
/// other stages whole. The tables must already be up to date in `ctx.out_dir`.
pub fn merge_bake(
    p: &ValidatedPipeline,
    dirs: &[PathBuf],
    ctx: &StageContext,
) -> Result<Vec<(String, StageOutcome)>, ShardError> {
    let (units, key) = bake_units(p, ctx)?;
    let checked: Checked = check_shards(Job::Bake, &key, &units, dirs)?;
    {
        let out = OutputDir::open(ctx.out_dir, || {
            eprintln!("waiting for another voltab run that is using {}", ctx.out_dir.display());
        })?;
        let stale: Vec<&str> =
            p.tables().iter().filter(|t| !out.is_up_to_date(t.id(), t.key())).map(|t| t.id()).collect();
        if !stale.is_empty() {
            return Err(ShardError::Shard {
                path: ctx.out_dir.to_path_buf(),
                message: format!("the tables the stages read are not compiled here: {}", stale.join(", ")),
                help: format!(
                    "merge the compile shards into this folder first (`voltab merge <compile shard folders…> --out {}`), then the bake shards",
                    ctx.out_dir.display()
                ),
            });
        }
    }
    let mut results = Vec::new();
    for (si, s) in p.stages().iter().enumerate() {
        let outcome = match s.def() {
            StageDef::BakeLightmaps(b) => {
                let mine: Vec<&Unit> = units.iter().filter(|u| u.table == si).collect();
                let tiles = mine.len() / b.modes.len().max(1);
                let given = (0..b.modes.len())
                    .into_par_iter()
                    .map(|m| {
                        let mut est = Vec::new();
                        let mut ms = 0.0;
                        for u in &mine[m * tiles..(m + 1) * tiles] {
                            match checked.read(u)? {
                                Payload::Texels { estimates, ms: t } => {
                                    est.extend(estimates);
                                    ms += t;
                                }
                                _ => {
                                    return Err(ShardError::Coverage {
                                        message: format!("unit {} holds no texels", u.name),
                                        help: "rerun the bake shards with the same voltab as the merge".into(),
                                    });
                                }
                            }
                        }
                        Ok((est, ms))
                    })
                    .collect::<Result<Vec<_>, ShardError>>()?;
                b.run_with(s.id(), ctx, Some(&given)).map_err(stage_err)?
            }
            def => def.stage().run(s.id(), ctx).map_err(stage_err)?,
        };
        results.push((s.id().to_string(), outcome));
    }
    Ok(results)
}
