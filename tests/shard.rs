//! Sharded compiles (issue 38): the merge of N shards writes the bytes one machine writes, whatever N;
//! a killed task's finished units are reused; missing, duplicated, stale and corrupt shards are clear
//! errors naming the shard and the units it lacks; concurrent merges into one folder are safe; the
//! no-op check trusts a verified file's fingerprint but never a changed file.

mod common;

use std::path::{Path, PathBuf};

use voltab::compile::{CompileOptions, Status, compile};
use voltab::pipeline::Disk;
use voltab::registry::{ValidatedPipeline, load_and_validate};
use voltab::shard::{ShardError, ShardSpec, compile_shard, merge};

fn fixture() -> PathBuf {
    common::root().join("tests/fixtures/shard/shard.ron")
}

fn pipeline() -> ValidatedPipeline {
    load_and_validate(&fixture(), &Disk).unwrap()
}

fn shards(p: &ValidatedPipeline, root: &Path, n: u32) -> Vec<PathBuf> {
    (0..n)
        .map(|i| {
            let d = root.join(format!("s{i}"));
            compile_shard(p, &[], ShardSpec { index: i, count: n }, &d, None, false).unwrap();
            d
        })
        .collect()
}

fn tables(dir: &Path) -> Vec<(String, Vec<u8>)> {
    let mut v: Vec<(String, Vec<u8>)> = std::fs::read_dir(dir)
        .unwrap()
        .flatten()
        .filter(|e| e.path().extension().is_some_and(|x| x == "vtab"))
        .map(|e| (e.file_name().to_string_lossy().into_owned(), std::fs::read(e.path()).unwrap()))
        .collect();
    v.sort();
    v
}

#[test]
fn merged_shards_are_byte_identical_to_a_local_compile_for_any_shard_count() {
    let p = pipeline();
    let d = common::tempdir();
    let local = d.path().join("local");
    compile(&p, &CompileOptions { out_dir: local.clone(), ..Default::default() }).unwrap();
    let want = tables(&local);
    assert_eq!(want.len(), 4, "one table of each kind");
    for n in [1, 3, 4] {
        let root = d.path().join(format!("n{n}"));
        let dirs = shards(&p, &root, n);
        let out = root.join("merged");
        let m = merge(&p, &dirs, &out).unwrap();
        assert!(m.tables.iter().all(|t| t.status == Status::Compiled));
        assert_eq!(tables(&out), want, "{n} shards");
        // The sidecars agree too, but for wall times.
        for t in p.tables() {
            let strip = |dir: &Path| -> Vec<String> {
                std::fs::read_to_string(dir.join(format!("{}.vtab.json", t.id())))
                    .unwrap()
                    .lines()
                    .filter(|l| !l.contains("_ms"))
                    .map(String::from)
                    .collect()
            };
            assert_eq!(strip(&out), strip(&local), "sidecar of {} with {n} shards", t.id());
        }
        // A second merge finds everything up to date.
        let again = merge(&p, &dirs, &out).unwrap();
        assert!(again.tables.iter().all(|t| t.status == Status::UpToDate));
    }
}

#[test]
fn a_killed_task_reruns_only_its_unfinished_units() {
    let p = pipeline();
    let d = common::tempdir();
    let dirs = shards(&p, d.path(), 2);
    // What a SIGKILL mid-way leaves: some part files, no manifest.
    let m = voltab::shard::read_manifest(&dirs[1]).unwrap();
    assert!(m.parts.len() >= 2, "shard 1 holds several units: {:?}", m.parts.len());
    std::fs::remove_file(dirs[1].join("shard.json")).unwrap();
    std::fs::remove_file(dirs[1].join(&m.parts[0].file)).unwrap();
    let err = merge(&p, &dirs, &d.path().join("out")).unwrap_err().to_string();
    assert!(err.contains("s1") && err.contains("did not finish"), "{err}");
    let s = compile_shard(&p, &[], ShardSpec { index: 1, count: 2 }, &dirs[1], None, false).unwrap();
    assert_eq!(s.computed.len(), 1, "only the lost unit is recomputed: {s:?}");
    assert_eq!(s.computed[0].0, m.parts[0].unit);
    assert_eq!(s.reused.len(), m.parts.len() - 1);
    let out = d.path().join("out");
    merge(&p, &dirs, &out).unwrap();
    let local = d.path().join("local");
    compile(&p, &CompileOptions { out_dir: local.clone(), ..Default::default() }).unwrap();
    assert_eq!(tables(&out), tables(&local));
}

#[test]
fn missing_duplicated_stale_and_corrupt_shards_are_named() {
    let p = pipeline();
    let d = common::tempdir();
    let dirs = shards(&p, d.path(), 4);
    let out = d.path().join("out");
    let units = voltab::shard::compile_units(&p);
    let owner = voltab::shard::assign(&units, 4);

    // A shard missing: the error names it and every unit it owns.
    let err = merge(&p, &dirs[..3], &out).unwrap_err();
    assert!(matches!(err, ShardError::Coverage { .. }));
    let text = err.to_string();
    assert!(text.contains("shard 3/4 is missing"), "{text}");
    for (u, s) in units.iter().zip(&owner) {
        assert_eq!(text.contains(&format!(" {}", u.name)), *s == 3, "unit {} (shard {s}): {text}", u.name);
    }
    assert!(!out.join("shard_hg.vtab").exists(), "nothing published");

    // The same folder twice.
    let twice = vec![dirs[0].clone(), dirs[1].clone(), dirs[2].clone(), dirs[3].clone(), dirs[2].clone()];
    let text = merge(&p, &twice, &out).unwrap_err().to_string();
    assert!(text.contains("duplicate") && text.contains("shard 2/4"), "{text}");

    // A shard of another version of the pipeline (more photons in the lobe table).
    let other_src = std::fs::read_to_string(fixture()).unwrap().replace("photons: 20000", "photons: 20001");
    let other_file = common::write(d.path(), "other.ron", &other_src);
    let other = load_and_validate(&other_file, &Disk).unwrap();
    let stale = d.path().join("stale");
    compile_shard(&other, &[], ShardSpec { index: 2, count: 4 }, &stale, None, false).unwrap();
    let mixed = vec![dirs[0].clone(), dirs[1].clone(), stale.clone(), dirs[3].clone()];
    let text = merge(&p, &mixed, &out).unwrap_err().to_string();
    assert!(text.contains("stale") && text.contains(&stale.display().to_string()), "{text}");

    // A part corrupted after its shard finished.
    let m = voltab::shard::read_manifest(&dirs[0]).unwrap();
    let part = dirs[0].join(&m.parts[0].file);
    let mut bytes = std::fs::read(&part).unwrap();
    let mid = bytes.len() / 2;
    bytes[mid] ^= 0x5a;
    std::fs::write(&part, &bytes).unwrap();
    let text = merge(&p, &dirs, &out).unwrap_err().to_string();
    assert!(text.contains(&m.parts[0].unit) && text.contains("corrupt"), "{text}");
    assert!(!out.join("shard_hg.vtab").exists(), "nothing published");
    // Rerunning the shard recomputes the corrupt unit; the merge then succeeds.
    let s = compile_shard(&p, &[], ShardSpec { index: 0, count: 4 }, &dirs[0], None, false).unwrap();
    assert_eq!(s.computed.iter().map(|c| c.0.clone()).collect::<Vec<_>>(), vec![m.parts[0].unit.clone()]);
    merge(&p, &dirs, &out).unwrap();

    // Not a shard folder at all.
    let text = merge(&p, &[d.path().join("nowhere")], &out).unwrap_err().to_string();
    assert!(text.contains("no such shard folder"), "{text}");
}

#[test]
fn two_merges_into_one_folder_at_once_publish_one_consistent_result() {
    let p = pipeline();
    let d = common::tempdir();
    let dirs = shards(&p, d.path(), 2);
    let out = d.path().join("out");
    let (a, b) = std::thread::scope(|s| {
        let a = s.spawn(|| merge(&p, &dirs, &out).map(|m| m.tables.len()));
        let b = s.spawn(|| merge(&p, &dirs, &out).map(|m| m.tables.len()));
        (a.join().unwrap(), b.join().unwrap())
    });
    assert_eq!((a.unwrap(), b.unwrap()), (4, 4));
    let local = d.path().join("local");
    compile(&p, &CompileOptions { out_dir: local.clone(), ..Default::default() }).unwrap();
    assert_eq!(tables(&out), tables(&local));
    let leftovers: Vec<_> = std::fs::read_dir(&out)
        .unwrap()
        .flatten()
        .filter(|e| e.file_name().to_string_lossy().starts_with(".tmp-"))
        .collect();
    assert!(leftovers.is_empty(), "{leftovers:?}");
}

#[test]
fn shard_specs_from_the_command_line_slurm_and_kubernetes() {
    let none = |_: &str| None;
    assert_eq!(ShardSpec::parse("2/4", &none).unwrap(), ShardSpec { index: 2, count: 4 });
    let slurm = |k: &str| match k {
        "SLURM_ARRAY_TASK_ID" => Some("3".to_string()),
        "SLURM_ARRAY_TASK_COUNT" => Some("8".to_string()),
        _ => None,
    };
    assert_eq!(ShardSpec::parse("auto", &slurm).unwrap(), ShardSpec { index: 3, count: 8 });
    // A resubmitted single task (`--array=3`) has SLURM_ARRAY_TASK_COUNT=1: the script's count wins.
    let resubmitted = |k: &str| match k {
        "SLURM_ARRAY_TASK_ID" => Some("3".to_string()),
        "SLURM_ARRAY_TASK_COUNT" => Some("1".to_string()),
        "VOLTAB_SHARD_COUNT" => Some("4".to_string()),
        _ => None,
    };
    assert_eq!(ShardSpec::parse("auto", &resubmitted).unwrap(), ShardSpec { index: 3, count: 4 });
    let k8s = |k: &str| (k == "JOB_COMPLETION_INDEX").then(|| "5".to_string());
    assert_eq!(ShardSpec::parse("auto/6", &k8s).unwrap(), ShardSpec { index: 5, count: 6 });
    for (bad, env, says) in [
        ("4/4", &none as &dyn Fn(&str) -> Option<String>, "does not exist"),
        ("0/0", &none, "does not exist"),
        ("x/2", &none, "not a whole number"),
        ("3", &none, "write --shard I/N"),
        ("auto", &none, "neither SLURM_ARRAY_TASK_ID nor JOB_COMPLETION_INDEX"),
        ("auto", &k8s, "JOB_COMPLETION_INDEX is set but not the shard count"),
        ("auto/6", &|k: &str| (k == "JOB_COMPLETION_INDEX").then(|| "6".to_string()), "does not exist"),
    ] {
        let e = ShardSpec::parse(bad, env).unwrap_err().to_string();
        assert!(e.contains(says), "{bad}: {e}");
        assert!(e.contains("help:"), "{bad}: {e}");
    }
}

#[test]
fn the_cli_shards_merges_and_writes_slurm_scripts() {
    let d = common::tempdir();
    let f = fixture();
    let pipe = f.to_str().unwrap();
    let s0 = d.path().join("s0");
    // --shard with --only is refused.
    let o = common::run(&["compile", pipe, "--shard", "0/2", "--only", "shard_hg", "--out", s0.to_str().unwrap()]);
    assert!(!o.status.success() && common::text(&o).contains("--only and --shard"), "{}", common::text(&o));
    // A bad spec: clear message, exit 1, nothing written.
    let o = common::run(&["compile", pipe, "--shard", "2/2", "--out", s0.to_str().unwrap()]);
    assert_eq!(o.status.code(), Some(1), "{}", common::text(&o));
    assert!(common::text(&o).contains("shard 2 of 2 does not exist"));
    assert!(!s0.exists());
    // Merge of a folder that is no shard.
    let o = common::run(&["merge", d.path().to_str().unwrap(), "--out", d.path().join("o").to_str().unwrap()]);
    assert_eq!(o.status.code(), Some(1));
    assert!(common::text(&o).contains("no shard.json"), "{}", common::text(&o));
    // The Slurm scripts (not submitted).
    let out = d.path().join("farm");
    let o = common::run(&[
        "slurm",
        pipe,
        "--shards",
        "4",
        "--partition",
        "render",
        "--time",
        "0:30:00",
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", common::text(&o));
    let array = std::fs::read_to_string(out.join("slurm/compile.sbatch")).unwrap();
    let merge = std::fs::read_to_string(out.join("slurm/merge.sbatch")).unwrap();
    for want in ["#SBATCH --partition=render", "#SBATCH --time=0:30:00", "VOLTAB_SHARD_COUNT=4", "--shard auto"] {
        assert!(array.contains(want), "{want} in\n{array}");
    }
    for i in 0..4 {
        assert!(merge.contains(&format!("shards/compile-{i}'")), "shard {i} in\n{merge}");
    }
    assert!(common::text(&o).contains("--dependency=afterok"), "{}", common::text(&o));
}

#[test]
fn a_no_op_compile_trusts_a_fingerprint_but_never_a_changed_file() {
    let p = pipeline();
    let d = common::tempdir();
    let out = d.path().join("out");
    let opts = CompileOptions { out_dir: out.clone(), only: vec!["shard_hg".into()], ..Default::default() };
    compile(&p, &opts).unwrap();
    let cache = out.join(".voltab-cache");
    let fp_path = || {
        std::fs::read_dir(&cache)
            .unwrap()
            .flatten()
            .map(|e| e.path())
            .find(|p| p.extension().is_some_and(|x| x == "fp"))
            .expect("a fingerprint beside the cached table")
    };
    let fp = || std::fs::read_to_string(fp_path()).unwrap();
    // The writer records the fingerprint of what it published: the next no-op reads no chunk (a
    // verification would rewrite the record as "verified").
    let written = fp();
    assert!(written.trim_end().ends_with(" written"), "{written}");
    for _ in 0..2 {
        assert_eq!(compile(&p, &opts).unwrap().tables[0].status, Status::UpToDate);
        assert_eq!(fp(), written, "trusted without verifying");
    }
    // Without a record, a no-op verifies completely; a verification within the racy window of the
    // file's last change is repeated next time, one past it is trusted.
    std::fs::remove_file(fp_path()).unwrap();
    assert_eq!(compile(&p, &opts).unwrap().tables[0].status, Status::UpToDate);
    let racy = fp();
    assert!(racy.trim_end().ends_with(" verified"), "{racy}");
    std::thread::sleep(std::time::Duration::from_nanos(voltab::cache::RACY_NS as u64 + 100_000_000));
    assert_eq!(compile(&p, &opts).unwrap().tables[0].status, Status::UpToDate);
    let settled = fp();
    assert_ne!(settled, racy, "a racy verification is repeated");
    assert_eq!(compile(&p, &opts).unwrap().tables[0].status, Status::UpToDate);
    assert_eq!(fp(), settled, "a verification past the racy window is trusted");
    // Any write changes the status-change time: the file is verified again and rebuilt.
    let t = out.join("shard_hg.vtab");
    let mut bytes = std::fs::read(&t).unwrap();
    let n = bytes.len();
    bytes[n - 40] ^= 0xff;
    std::fs::write(&t, &bytes).unwrap();
    let s = compile(&p, &opts).unwrap();
    assert_eq!(s.tables[0].status, Status::Compiled, "a corrupted table is never trusted");
    voltab::container::VtabReader::open(&t).unwrap().verify().unwrap();
}

#[test]
fn a_slice_split_into_photon_batches_is_the_slice_walked_whole() {
    // Two batches: MIN_UNIT_PHOTONS (a coarse grid's unit) and a short remainder, merged from
    // separate work units.
    let photons = voltab::tables::ms_lobes::MIN_UNIT_PHOTONS + 3000;
    let d = common::tempdir();
    let f = common::write(
        d.path(),
        "lobes.ron",
        &format!(
            "(tables: [MsLobes(id: \"two_batches\", materials: [], g: [0.8], albedo_grid: 0, albedos: [0.5], \
             rho_bins: 4, z_bins: 4, theta_bins: 3, direction_bins: 4, photons: {photons}, max_order: 16)])"
        ),
    );
    let p = load_and_validate(&f, &Disk).unwrap();
    let local = d.path().join("local");
    compile(&p, &CompileOptions { out_dir: local.clone(), ..Default::default() }).unwrap();
    let t = &p.tables()[0];
    assert_eq!(t.def().kind_impl().units(), 3, "two photon batches and the check");
    let dirs = shards(&p, d.path(), 3);
    let units = voltab::shard::compile_units(&p);
    assert_eq!(voltab::shard::assign(&units, 3).iter().collect::<std::collections::BTreeSet<_>>().len(), 3);
    let out = d.path().join("merged");
    merge(&p, &dirs, &out).unwrap();
    assert_eq!(tables(&out), tables(&local));
}

/// A unit's part file holds its slice's whole tally, so fine grids get bigger units: at most
/// `TALLY_BYTES_PER_PHOTON` tally bytes per photon (the size of the walk's real tally, from its
/// configuration), the smallest such power of two, never below `MIN_UNIT_PHOTONS`.
#[test]
fn fine_grids_get_units_big_enough_to_carry_their_tally() {
    use voltab::tables::ms_lobes::{MIN_UNIT_PHOTONS, TALLY_BYTES_PER_PHOTON};
    let d = common::tempdir();
    let f = common::write(
        d.path(),
        "units.ron",
        "(tables: [MsLobes(id: \"table2\"), MsLobes(id: \"wax\", materials: [\"Wax\"], albedo_grid: 0, lobe: Full), \
         MsLobes(id: \"coarse\", materials: [], g: [0.8], albedo_grid: 0, albedos: [0.5], rho_bins: 4, z_bins: 4, \
         theta_bins: 3, direction_bins: 4, photons: 5000, max_order: 16)])",
    );
    let p = load_and_validate(&f, &Disk).unwrap();
    let mut fine = 0;
    for t in p.tables() {
        let voltab::tables::TableDef::MsLobes(def) = t.def() else { panic!("an MsLobes table") };
        let cfg = def.lobe_config(0, 0.5, t.key());
        let tally_bytes = 8 * (cfg.cells() * cfg.bins() * (1 + cfg.albedos.len())) as u64;
        let unit = def.unit_photons();
        assert!(unit.is_power_of_two() && unit >= MIN_UNIT_PHOTONS, "{}: {unit}", t.id());
        assert!(unit * TALLY_BYTES_PER_PHOTON >= tally_bytes, "{}: {unit} photons for {tally_bytes} B", t.id());
        if unit > MIN_UNIT_PHOTONS {
            fine += 1;
            assert!(unit / 2 * TALLY_BYTES_PER_PHOTON < tally_bytes, "{}: {unit} is not the smallest", t.id());
        }
        assert_eq!(def.photon_units() as u64, def.photons.div_ceil(unit).max(1), "{}", t.id());
    }
    assert_eq!(fine, 2, "the Table 2 and Wax grids are fine, the 4 x 4 one coarse");
}
