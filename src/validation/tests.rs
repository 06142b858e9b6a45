use super::*;

fn method(rel: Option<f64>, floor: f64) -> MethodResult {
    MethodResult {
        name: "full".into(),
        ms: 12.0,
        rel_rmse: rel,
        ci95: rel.map(|e| [e * 0.9, e * 1.1]),
        floor: Some(floor),
        raw_rel_rmse: Some(0.5),
        method_mean: 1.1,
        reference_mean: Some(1.0),
        text: rel.map_or(format!("< floor {floor}"), |e| format!("{e} (floor {floor})")),
    }
}

fn stage(m: MethodResult) -> StageResult {
    StageResult {
        stage: "bake".into(),
        kind: "BakeLightmaps".into(),
        quantity: "irradiance".into(),
        not_compared: None,
        caveats: vec!["a caveat".into()],
        items: 64,
        variant: "scalar_rgb".into(),
        reference_paths: 1024,
        reference_runs: 4,
        reference_s: 3.0,
        methods: vec![m],
        files: Vec::new(),
    }
}

#[test]
fn markdown_states_floor_interval_mean_ratio_and_every_stage() {
    let v = Validation {
        pipeline: "p.ron".into(),
        quality: Quality::Quick,
        stages: vec![stage(method(Some(0.2), 0.03)), not_compared("fog", "ImageFog", "not yet; issue 36")],
    };
    let md = markdown(&v);
    // 20 % with its interval [18, 22], the floor, the raw error, mean ×1.1, paths per item 256 × 4 runs.
    assert!(md.contains("| 20.0 % [18.0, 22.0] | 3.00 % | 50.00 % | 1.100 | 12 ms | scalar_rgb (256×4 runs)"), "{md}");
    assert!(md.contains("| fog | — | not compared | not yet; issue 36 |"), "{md}");
    assert!(md.contains("- **bake**: a caveat"), "{md}");
}

#[test]
fn an_error_below_the_floor_is_never_printed_as_a_number() {
    let v = Validation { pipeline: "p.ron".into(), quality: Quality::Full, stages: vec![stage(method(None, 0.04))] };
    let md = markdown(&v);
    assert!(md.contains("| < floor 4.0 % | 4.00 % |"), "{md}");
}

#[test]
fn results_and_pictures_are_written_atomically() {
    let d = tempfile::tempdir().unwrap();
    let v =
        Validation { pipeline: "p.ron".into(), quality: Quality::Quick, stages: vec![stage(method(Some(0.1), 0.01))] };
    let files = write(&v, d.path()).unwrap();
    assert_eq!(files.len(), 3);
    let back: Validation = serde_json::from_slice(&std::fs::read(&files[0]).unwrap()).unwrap();
    assert_eq!(back.stages[0].methods[0].rel_rmse, Some(0.1));
    let leftovers: Vec<_> = std::fs::read_dir(d.path())
        .unwrap()
        .flatten()
        .filter(|e| e.file_name().to_string_lossy().starts_with('.'))
        .collect();
    assert!(leftovers.is_empty());
}
