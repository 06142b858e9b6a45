//! Farm bakes (issue 38): a lightmap bake split into texel tiles over N shards and merged writes the
//! lightmaps (EXR and PNG) and probes one machine writes, byte for byte, and the same summary but for
//! wall times; a killed task's finished tiles are reused; bake shards merged before the tables, mixed
//! with compile shards, missing, or computed for another sample count are clear errors.

mod common;

use std::path::{Path, PathBuf};

use voltab::compile::{CompileOptions, compile};
use voltab::pipeline::Disk;
use voltab::registry::{ValidatedPipeline, load_and_validate};
use voltab::render::gpu::Device;
use voltab::shard::bake::{bake_shard, bake_units, merge_bake};
use voltab::shard::{ShardError, ShardSpec, compile_shard, merge};
use voltab::stages::StageContext;

fn fixture() -> PathBuf {
    common::root().join("tests/fixtures/shard/bake.ron")
}

/// The fixture written into `dir` with `samples` per texel (its scene path made absolute).
fn pipeline_in(dir: &Path, samples: u32) -> ValidatedPipeline {
    let scene = common::root().join("scenes/fog_room.gltf");
    let text = std::fs::read_to_string(fixture())
        .unwrap()
        .replace("../../../scenes/fog_room.gltf", &scene.to_string_lossy())
        .replace("samples: 8,", &format!("samples: {samples},"));
    let f = common::write(dir, &format!("bake{samples}.ron"), &text);
    load_and_validate(&f, &Disk).unwrap()
}

static CPU: Device = Device::Cpu;
static SCENES: std::sync::LazyLock<voltab::scene::cache::SceneCache> = std::sync::LazyLock::new(Default::default);

fn ctx<'a>(out: &'a Path, base: &'a Path) -> StageContext<'a> {
    StageContext { out_dir: out, base_dir: base, progress: false, device: &CPU, scenes: &SCENES }
}

fn bake_shards(p: &ValidatedPipeline, tables: &Path, root: &Path, n: u32) -> Vec<PathBuf> {
    let base = p.path().parent().unwrap();
    (0..n)
        .map(|i| {
            let d = root.join(format!("b{i}"));
            bake_shard(p, &[], ShardSpec { index: i, count: n }, &ctx(tables, base), &d).unwrap();
            d
        })
        .collect()
}

/// The files of a stage folder; `summary.json` without its wall times and rates.
fn outputs(dir: &Path) -> Vec<(String, Vec<u8>)> {
    let mut v: Vec<(String, Vec<u8>)> = std::fs::read_dir(dir)
        .unwrap()
        .flatten()
        .map(|e| {
            let name = e.file_name().to_string_lossy().into_owned();
            let bytes = std::fs::read(e.path()).unwrap();
            let bytes = if name == "summary.json" {
                String::from_utf8(bytes)
                    .unwrap()
                    .lines()
                    // Wall times, rates and the output folder differ; everything else is equal.
                    .filter(|l| !["_ms\"", "\"ms\"", "_per_s\"", "\"exr\""].iter().any(|k| l.contains(k)))
                    .collect::<Vec<_>>()
                    .join("\n")
                    .into_bytes()
            } else {
                bytes
            };
            (name, bytes)
        })
        .collect();
    v.sort();
    v
}

/// Tables compiled on a farm too (two compile shards, merged) into `root/farm`.
fn farm_tables(p: &ValidatedPipeline, root: &Path) -> PathBuf {
    let dirs: Vec<PathBuf> = (0..2)
        .map(|i| {
            let d = root.join(format!("c{i}"));
            compile_shard(p, &[], ShardSpec { index: i, count: 2 }, &d, None, false).unwrap();
            d
        })
        .collect();
    let out = root.join("farm");
    merge(p, &dirs, &out).unwrap();
    out
}

#[test]
fn a_bake_merged_from_tiles_writes_the_lightmaps_one_machine_writes() {
    let p = load_and_validate(&fixture(), &Disk).unwrap();
    let base = fixture().parent().unwrap().to_path_buf();
    let d = common::tempdir();
    let local = d.path().join("local");
    compile(&p, &CompileOptions { out_dir: local.clone(), ..Default::default() }).unwrap();
    for s in p.stages() {
        s.def().stage().run(s.id(), &ctx(&local, &base)).unwrap();
    }
    let want = outputs(&local.join("farm_bake"));
    let names: Vec<&str> = want.iter().map(|(n, _)| n.as_str()).collect();
    assert_eq!(
        names,
        [
            "lightmap_full.exr",
            "lightmap_full.png",
            "lightmap_shadow.exr",
            "lightmap_shadow.png",
            "lightmap_surface.exr",
            "lightmap_surface.png",
            "probes.vtab",
            "summary.json"
        ]
    );

    let farm = farm_tables(&p, d.path());
    let (units, _) = bake_units(&p, &ctx(&farm, &base)).unwrap();
    assert!(units.len() > 3 * 2, "every mode splits into several tiles: {} units", units.len());
    for n in [1, 3] {
        let dirs = bake_shards(&p, &farm, &d.path().join(format!("n{n}")), n);
        merge_bake(&p, &dirs, &ctx(&farm, &base)).unwrap();
        let got = outputs(&farm.join("farm_bake"));
        assert_eq!(got.len(), want.len());
        for ((name, a), (_, b)) in got.iter().zip(&want) {
            assert!(a == b, "{name} differs with {n} bake shards");
        }
    }

    // A task killed after some tiles: no manifest, one part lost; the rerun computes only that one.
    let root = d.path().join("n3");
    let killed = root.join("b1");
    std::fs::remove_file(killed.join("shard.json")).unwrap();
    let part = std::fs::read_dir(&killed)
        .unwrap()
        .flatten()
        .map(|e| e.path())
        .find(|p| p.extension().is_some_and(|x| x == "part"))
        .unwrap();
    std::fs::remove_file(part).unwrap();
    let s = bake_shard(&p, &[], ShardSpec { index: 1, count: 3 }, &ctx(&farm, &base), &killed).unwrap();
    assert_eq!(s.computed.len(), 1, "{s:?}");
    assert!(!s.reused.is_empty(), "{s:?}");
}

#[test]
fn bake_shards_out_of_order_mixed_missing_or_stale_are_named() {
    let d = common::tempdir();
    let p = pipeline_in(d.path(), 8);
    let base = d.path().to_path_buf();
    let farm = farm_tables(&p, d.path());
    let dirs = bake_shards(&p, &farm, d.path(), 3);
    let text = |e: ShardError| e.to_string();

    // Before the tables are merged into the output folder.
    let empty = d.path().join("empty");
    let e = text(merge_bake(&p, &dirs, &ctx(&empty, &base)).unwrap_err());
    assert!(e.contains("not compiled here: bake_zh") && e.contains("merge the compile shards"), "{e}");
    assert!(!empty.join("farm_bake").exists(), "nothing written");

    // A compile shard among bake shards.
    let mixed = vec![dirs[0].clone(), d.path().join("c1")];
    let e = text(merge_bake(&p, &mixed, &ctx(&farm, &base)).unwrap_err());
    assert!(e.contains("c1") && e.contains("one of the compile shards"), "{e}");

    // A missing shard: named with the tiles it lacks.
    let e = text(merge_bake(&p, &dirs[..2], &ctx(&farm, &base)).unwrap_err());
    assert!(e.contains("shard 2/3 is missing; it lacks: farm_bake/"), "{e}");

    // The same pipeline with another sample count: its bakes' key differs, the old tiles are stale.
    let p9 = pipeline_in(d.path(), 9);
    let e = text(merge_bake(&p9, &dirs, &ctx(&farm, &base)).unwrap_err());
    assert!(e.contains("stale"), "{e}");
}

/// `voltab slurm` on a pipeline that bakes: a second array of bake tiles after the table merge, and
/// its merge; `voltab run --shard` without `--tables` is refused by the command line.
#[test]
fn the_cli_writes_the_bake_phase_and_refuses_a_shard_without_tables() {
    let d = common::tempdir();
    let f = fixture();
    let pipe = f.to_str().unwrap();
    let out = d.path().join("farm");
    let o = common::run(&["slurm", pipe, "--shards", "3", "--out", out.to_str().unwrap()]);
    assert!(o.status.success(), "{}", common::text(&o));
    let bake = std::fs::read_to_string(out.join("slurm/bake.sbatch")).unwrap();
    let merge = std::fs::read_to_string(out.join("slurm/merge-bake.sbatch")).unwrap();
    for want in ["VOLTAB_SHARD_COUNT=3", " run ", "--shard auto", "--tables", "shards/bake-\"$SLURM_ARRAY_TASK_ID\""] {
        assert!(bake.contains(want), "{want} in\n{bake}");
    }
    for i in 0..3 {
        assert!(merge.contains(&format!("shards/bake-{i}'")), "bake shard {i} in\n{merge}");
    }
    let text = common::text(&o);
    assert!(text.contains("bake.sbatch") && text.contains("--dependency=afterok:$mid"), "{text}");
    let o = common::run(&["run", pipe, "--shard", "0/2", "--out", d.path().join("s").to_str().unwrap()]);
    assert!(!o.status.success() && common::text(&o).contains("--tables"), "{}", common::text(&o));
    assert!(!d.path().join("s").exists());
}
