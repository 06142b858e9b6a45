use std::path::Path;

use super::*;
use crate::pipeline::Disk;
use crate::registry::load_and_validate;
use crate::scene::fixtures::{fog_room, translucent};
use crate::scene::{Density, Light};

fn default_pipeline() -> ValidatedPipeline {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    load_and_validate(&root.join("pipelines/default.ron"), &Disk).unwrap()
}

fn table<'a>(plan: &'a Plan, id: &str) -> &'a TablePlan {
    plan.tables.iter().find(|t| t.id == id).unwrap()
}

fn kept_g(plan: &Plan, id: &str) -> Vec<f64> {
    match &table(plan, id).def {
        Some(TableDef::PhaseHg(d)) => d.g.values(),
        Some(TableDef::ZhResponse(d)) => d.g.values(),
        Some(TableDef::MsLobes(d)) => d.g_values(),
        _ => vec![],
    }
}

fn item<'a>(t: &'a TablePlan, what: &str) -> &'a Item {
    t.items.iter().find(|i| i.what == what).unwrap_or_else(|| panic!("no item {what} in {:#?}", t.items))
}

#[test]
fn the_fog_room_keeps_its_emitters_g_bracket_and_distance_range() {
    let p = default_pipeline();
    let plan = Plan::new(&p, &[fog_room()]);
    // g = 0.3 sits on hg_grid's 0.1-spaced node; hg_extreme brackets it by 0 and 0.9.
    assert_eq!(kept_g(&plan, "hg_grid"), vec![0.3]);
    assert_eq!(kept_g(&plan, "hg_extreme"), vec![0.0, 0.9]);
    assert_eq!(item(table(&plan, "hg_grid"), "g = -0.9").decision, Decision::Skip);

    let zh = table(&plan, "zh_dubouchet");
    assert_eq!(zh.decision, Decision::Compile);
    assert_eq!(item(zh, "emitter Point").decision, Decision::Compile);
    assert_eq!(item(zh, "emitter Area").decision, Decision::Compile);
    let dir = item(zh, "emitter Directional");
    assert_eq!((dir.decision, dir.reason.as_str()), (Decision::Skip, "no directional lights"));
    assert_eq!(kept_g(&plan, "zh_dubouchet"), vec![0.0, 0.5]);
    // Bounds (0, −0.1, 0)..(4, 3, 4): diagonal √41.61 m; σ_t 0.11 /m → 0.7096 mfp; 2 × that + 8 = 9.419.
    // On the log axis 1e-3·64000^(i/255) the first node ≥ 9.419 is i = ⌈255·ln(9419)/ln(64000)⌉ = ⌈210.85⌉.
    let Some(TableDef::ZhResponse(d)) = &zh.def else { panic!() };
    assert_eq!(d.distance_bins, 212);
    let expected_max = 1e-3 * 64000f64.powf(211.0 / 255.0);
    assert!((d.distance_max - expected_max).abs() < 1e-9 * expected_max, "{}", d.distance_max);
    assert_eq!(d.emitters, vec![EmitterProfile::Point, EmitterProfile::Area]);

    let ms = table(&plan, "ms_lobes_table2");
    assert_eq!((ms.decision, ms.reason.as_str()), (Decision::Skip, "no refractive translucent objects in the scene"));
    // Plots: hg_extreme_plot keeps its table's 2 kept slices; hg_grid_plot plots g = ±0.9, ±0.5, 0: none kept.
    let stage = |id: &str| plan.stages.iter().find(|s| s.id == id).unwrap();
    assert_eq!(stage("hg_extreme_plot").decision, Decision::Compile);
    assert_eq!(stage("hg_grid_plot").decision, Decision::Skip);
    assert!(!plan.has_missing());

    let pruned = plan.pruned_pipeline(&p, &crate::pipeline::Limits::from_machine()).unwrap();
    let ids: Vec<&str> = pruned.tables().iter().map(|t| t.id()).collect();
    assert!(!ids.contains(&"ms_lobes_table2"));
    // The fog room's bake runs (its ZH table is kept); the two plots minus the skipped one.
    let bake = stage("fog_room_bake");
    assert_eq!((bake.decision, bake.reason.as_str()), (Decision::Compile, "bakes ../scenes/fog_room.gltf"));
    let kept: Vec<&str> = pruned.stages().iter().map(|s| s.id()).collect();
    assert_eq!(kept, ["fog_room_bake", "hg_extreme_plot"]);
}

#[test]
fn a_translucent_object_needs_lobes_but_no_volume_to_surface_tables() {
    let p = default_pipeline();
    let plan = Plan::new(&p, &[translucent()]);
    let zh = table(&plan, "zh_dubouchet");
    assert_eq!(zh.decision, Decision::Skip);
    assert!(zh.reason.contains("refractive objects"), "{}", zh.reason);
    assert_eq!(kept_g(&plan, "ms_lobes_table2"), vec![0.7]);
    // hg_dubouchet stops at g = 0.5, but hg_grid spans 0.7: not missing.
    let hd = item(table(&plan, "hg_dubouchet"), "g = 0.7");
    assert_eq!(
        (hd.decision, hd.reason.as_str()),
        (Decision::Skip, "outside this table's g range; table hg_grid covers it")
    );
    assert!(!plan.has_missing());
    // The φ-resolved Wax table holds g = 0.8 and Wax's albedos only: this scene's g = 0.7 is covered by
    // ms_lobes_table2, so nothing is missing and the Wax table (no bracketing slice) is skipped.
    let wax = item(table(&plan, "ms_lobes_wax_full"), "g = 0.7");
    assert_eq!(
        (wax.decision, wax.reason.as_str()),
        (Decision::Skip, "outside this table's g range; table ms_lobes_table2 covers it")
    );
    assert_eq!(table(&plan, "ms_lobes_wax_full").decision, Decision::Skip);
    let ms = table(&plan, "ms_lobes_table2");
    let Some(TableDef::MsLobes(d)) = &ms.def else { panic!() };
    // Every channel albedo (0.99, 0.95, 0.9) has its nodes below and above kept, and nothing else is.
    let Some(TableDef::MsLobes(full)) = p.table("ms_lobes_table2").map(|t| t.def().clone()) else { panic!() };
    let nodes = full.albedo_values();
    let mut expected: Vec<f64> = [0.99, 0.95, 0.9]
        .iter()
        .flat_map(|&a| {
            let below = nodes.iter().copied().filter(|&n| n <= a).fold(f64::NEG_INFINITY, f64::max);
            let above = nodes.iter().copied().filter(|&n| n >= a).fold(f64::INFINITY, f64::min);
            [below, above]
        })
        .collect();
    expected.sort_by(f64::total_cmp);
    expected.dedup();
    assert_eq!(d.albedo_values(), expected);
    assert!(d.materials.is_empty());
    // One walk per g slice: 1 of 4.
    assert_eq!(ms.pruned_work * 4, ms.full_work);
}

#[test]
fn two_scenes_give_different_plans_and_their_union_covers_both() {
    let p = default_pipeline();
    let a = Plan::new(&p, &[fog_room()]);
    let b = Plan::new(&p, &[translucent()]);
    let both = Plan::new(&p, &[fog_room(), translucent()]);
    assert_ne!(a.text(), b.text());
    for id in ["hg_grid", "hg_extreme", "zh_dubouchet", "ms_lobes_table2"] {
        let full = kept_g(&both, id);
        for g in kept_g(&a, id).into_iter().chain(kept_g(&b, id)) {
            assert!(full.contains(&g), "{id}: {g} missing from the union {full:?}");
        }
    }
    assert_eq!(kept_g(&both, "hg_grid"), vec![0.3, 0.4, 0.5, 0.6, 0.7]);
}

#[test]
fn needs_beyond_the_pipeline_are_reported_missing() {
    let p = default_pipeline();
    let mut s = fog_room();
    s.media[0].g = [0.95; 3]; // zh_dubouchet stops at 0.5, hg_extreme brackets with 0.9 and 0.999
    s.lights.push(Light {
        name: "/Sun".into(),
        kind: crate::scene::LightKind::Directional { direction: [0.0, -1.0, 0.0], angle: 0.0 },
        radiance: [1.0; 3],
    });
    let plan = Plan::new(&p, &[s]);
    assert!(plan.has_missing());
    let zh = table(&plan, "zh_dubouchet");
    let miss = item(zh, "g = 0.95");
    assert_eq!(miss.decision, Decision::Missing);
    assert!(miss.reason.contains("add it to `g`"), "{}", miss.reason);
    assert_eq!(item(zh, "emitter Directional").decision, Decision::Compile);
    assert_eq!(kept_g(&plan, "hg_extreme"), vec![0.9, 0.999]);
    assert!(plan.text().contains("MISSING"));
}

#[test]
fn heterogeneous_fog_is_sized_by_its_densest_corner() {
    let p = default_pipeline();
    let mut s = fog_room();
    // ρ = e^{−(y − 3)}: density e^{3.1} at the floor (y = −0.1), so σ_t,max = 0.11·e^{3.1} = 2.442 /m.
    s.media[0].density =
        Density::ExponentialHeight { rho: 1.0, falloff: 1.0, direction: [0.0, 1.0, 0.0], offset: [0.0, 3.0, 0.0] };
    let needs = Needs::of(&[s.clone()]);
    let m = &needs.fog[0];
    assert!(m.heterogeneous);
    // (The floor's y = −0.1 is an f32 vertex: 1.5e-9 off, hence 1e-8.)
    assert!((m.sigma_t_max - 0.11 * 3.1f64.exp()).abs() < 1e-8 * m.sigma_t_max, "{}", m.sigma_t_max);
    assert!((m.optical_extent - m.sigma_t_max * 41.61f64.sqrt()).abs() < 1e-7 * m.optical_extent);
    let plan = Plan::new(&p, &[s]);
    let Some(TableDef::ZhResponse(d)) = &table(&plan, "zh_dubouchet").def else { panic!() };
    // 2 × 2.4418 × 6.4506 + 8 = 39.502 mfp → node ⌈255·ln(39502)/ln(64000)⌉ = ⌈243.88⌉ = 244.
    assert_eq!(d.distance_bins, 245);
}

#[test]
fn a_scene_without_media_skips_every_table() {
    let p = default_pipeline();
    let mut s = fog_room();
    s.media.clear();
    let plan = Plan::new(&p, &[s]);
    for t in &plan.tables {
        assert_eq!(t.decision, Decision::Skip, "{}", t.id);
        assert_eq!(t.pruned_work, 0);
    }
    assert!(plan.stages.iter().all(|s| s.decision == Decision::Skip));
}

/// A small pipeline with one table of each kind, cheap enough to generate in a test.
fn small_pipeline(dir: &Path) -> ValidatedPipeline {
    let text = r#"(
        tables: [
            PhaseHg(id: "hg", g: (min: -0.9, max: 0.9, count: 7), mu_bins: 64, xi_bins: 64, zh_order: 8),
            ZhResponse(id: "zh", g: [-0.5, 0.0, 0.5], emitters: [Point, Directional], bounces: 3, zh_order: 4,
                distance_bins: 48, quadrature_nodes: 4),
            MsLobes(id: "lobes", materials: [], g: [0.0, 0.7, 0.9], albedo_grid: 5, albedos: [0.95, 0.99],
                rho_bins: 16, z_bins: 24, theta_bins: 9, direction_bins: 16, photons: 4096, max_order: 64),
        ],
    )"#;
    let path = dir.join("small.ron");
    std::fs::write(&path, text).unwrap();
    load_and_validate(&path, &Disk).unwrap()
}

fn generate(def: &TableDef) -> crate::tables::Generated {
    def.kind_impl().generate(&def.content_key(), &|_| {}).unwrap()
}

/// The issue's acceptance test: what a consumer computes from the pruned tables equals what it computes
/// from the full ones — exactly for slices (phase values, lobes), and for the trimmed ZH distance axis to
/// the difference the bounce recursion leaves (orders ≥ 2 see the dropped far distances): 1.9e-8 measured.
#[test]
fn consumers_get_the_same_answers_from_pruned_tables() {
    use crate::physics::medium::HomogeneousMedium;
    use crate::tables::ms_lobes::{LobeQuery, MsLobesTable};
    use crate::tables::phase_hg::PhaseHgTable;
    use crate::tables::zh_response::{Emitter, QueryOptions, Receiver, ZhResponseTable};

    let dir = tempfile::tempdir().unwrap();
    let p = small_pipeline(dir.path());
    let mut scene = fog_room();
    let wax = translucent();
    scene.materials.extend(wax.materials.clone());
    let mut body = wax.meshes[0].clone();
    body.material = Some(1);
    body.medium = Some(1);
    scene.meshes.push(body);
    scene.media.push(crate::scene::Medium { boundary: Boundary::Mesh(2), ..wax.media[0].clone() });
    let plan = Plan::new(&p, &[scene]);
    let full = |id: &str| p.table(id).unwrap().def().clone();
    let pruned = |id: &str| table(&plan, id).def.clone().unwrap();

    // PhaseHg: g 0.3 and 0.7 bracket to 0.3 (node) … 0.9: slices 0.3, 0.6, 0.9 of the 0.3-spaced grid.
    let (hf, hp) = (generate(&full("hg")), generate(&pruned("hg")));
    let (tf, tp) = (
        PhaseHgTable::from_arrays(&hf.arrays, &hf.values).unwrap(),
        PhaseHgTable::from_arrays(&hp.arrays, &hp.values).unwrap(),
    );
    assert_eq!(tp.g, vec![0.3, 0.6, 0.9]);
    for (pi, g) in tp.g.iter().enumerate() {
        let fi = tf.g.iter().position(|x| x == g).unwrap();
        for mu in [-1.0, -0.3, 0.0, 0.41, 0.99, 1.0] {
            assert_eq!(tf.phase_lerp(fi, mu), tp.phase_lerp(pi, mu), "g {g} mu {mu}");
        }
        assert_eq!(tf.zh(fi), tp.zh(pi));
    }

    // MsLobes: the g 0.7 slice and the albedo nodes around 0.9, 0.95, 0.99 are bit-identical.
    let (lf, lp) = (generate(&full("lobes")), generate(&pruned("lobes")));
    let (TableDef::MsLobes(df), TableDef::MsLobes(dp)) = (full("lobes"), pruned("lobes")) else { panic!() };
    assert_eq!(dp.g_values(), vec![0.7]);
    let (mf, mp) = (
        MsLobesTable::from_arrays(&df, &lf.arrays, &lf.values).unwrap(),
        MsLobesTable::from_arrays(&dp, &lp.arrays, &lp.values).unwrap(),
    );
    for albedo in [0.9, 0.93, 0.95, 0.99] {
        for (rho, z, theta) in [(0.5, 1.0, 0.3), (2.0, 4.0, 1.2), (5.0, -1.0, 3.0)] {
            let q = LobeQuery { albedo, g: 0.7, rho, z, theta, phi: 0.0 };
            let (a, b) = (mf.lobe(&q).unwrap(), mp.lobe(&q).unwrap());
            assert_eq!((a.total, a.double), (b.total, b.double), "{q:?}");
            assert!(a.total > 0.0);
        }
    }

    // ZhResponse: g slices 0 and 0.5, Point only, distances trimmed to twice the room's 0.71 mfp.
    let (zf, zp) = (generate(&full("zh")), generate(&pruned("zh")));
    let (TableDef::ZhResponse(df), TableDef::ZhResponse(dp)) = (full("zh"), pruned("zh")) else { panic!() };
    assert_eq!(dp.emitters, vec![crate::tables::zh_response::EmitterProfile::Point]);
    assert!(dp.distance_bins < df.distance_bins, "{} of {}", dp.distance_bins, df.distance_bins);
    let (qf, qp) = (
        ZhResponseTable::from_arrays(&df, &zf.arrays, &zf.values).unwrap(),
        ZhResponseTable::from_arrays(&dp, &zp.arrays, &zp.values).unwrap(),
    );
    let medium = HomogeneousMedium { sigma_s: 0.1, sigma_a: 0.01, g: 0.3 };
    let opts = QueryOptions { backscatter: true, tail: true, similarity: false, max_bounce: None };
    let receiver = Receiver { position: [0.0; 3], normal: [0.0, 0.0, 1.0] };
    let mut worst = 0.0f64;
    for d in [0.05, 0.5, 2.0, 4.0, 6.4] {
        let e = Emitter::Point { intensity: 1.0, position: [0.0, 0.0, d] };
        let (a, b) = (
            qf.irradiance(&medium, &e, &receiver, &opts).unwrap(),
            qp.irradiance(&medium, &e, &receiver, &opts).unwrap(),
        );
        // The trimmed axis's nodes are recomputed from its new end: equal to the full axis's up to rounding.
        assert!((a.direct - b.direct).abs() <= 1e-12 * a.direct, "d {d}: {a:?} {b:?}");
        println!("d {d}: single {:.3e}, total {:.3e}", (a.single - b.single) / a.single, (a.total - b.total) / a.total);
        worst = worst.max((a.total - b.total).abs() / a.total);
    }
    println!("worst relative difference of the total irradiance, pruned vs full ZH: {worst:.3e}");
    assert!(worst < 1e-6, "{worst}");
}

/// The effect stages run on their own scenes when those are planned and have what the effect needs.
#[test]
fn effect_stages_follow_their_scenes() {
    let p = default_pipeline();
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let load = |n: &str| Scene::load(&root.join("scenes").join(n)).unwrap();
    let stage = |plan: &Plan, id: &str| {
        let s = plan.stages.iter().find(|s| s.id == id).unwrap();
        (s.decision, s.reason.clone())
    };
    let plan = Plan::new(&p, &[load("window_room.gltf"), load("outdoor.gltf")]);
    assert_eq!(
        stage(&plan, "window_room_god_rays"),
        (Decision::Compile, "renders god rays of ../scenes/window_room.gltf".to_string())
    );
    assert_eq!(stage(&plan, "outdoor_fog").0, Decision::Compile);
    // Without fog the god rays have nothing to scatter in; the fog stage is not planned for this scene set.
    let mut room = load("window_room.gltf");
    room.media.clear();
    let plan = Plan::new(&p, &[room]);
    assert_eq!(
        stage(&plan, "window_room_god_rays"),
        (Decision::Skip, "../scenes/window_room.gltf has no homogeneous global medium".to_string())
    );
    assert_eq!(
        stage(&plan, "outdoor_fog"),
        (Decision::Skip, "its scene ../scenes/outdoor.gltf is not among the planned scenes".to_string())
    );
}

#[test]
fn a_dome_alone_lights_a_scene_for_pop() {
    // The fog room without its bulb has only an emissive panel: nothing POP propagates on a grid of its
    // own; a dome light (environment ordinates) is enough.
    let mut s = fog_room();
    s.lights.retain(|l| matches!(l.kind, crate::scene::LightKind::EmissiveMesh { .. }));
    assert_eq!(pop::scene::lacks(&s), Some("directional, point, spot, sphere or dome light"));
    s.environment = Some(crate::scene::EnvironmentLight {
        name: "/Sky".into(),
        texture: None,
        scale: 1.0 / crate::scene::LUMENS_PER_WATT,
        color: [1.0; 3],
        rotation: [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
    });
    assert_eq!(pop::scene::lacks(&s), None);
}
