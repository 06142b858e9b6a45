//! The committed `schemas/` must match what the code generates.

#[test]
fn committed_schema_matches_the_code() {
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("schemas");
    let json = format!("{}\n", serde_json::to_string_pretty(&voltab::pipeline::schema::json_schema()).unwrap());
    let md = voltab::pipeline::schema::reference_markdown();
    let stale = |name: &str, want: &str| std::fs::read_to_string(root.join(name)).ok().as_deref() != Some(want);
    assert!(
        !stale("pipeline.schema.json", &json) && !stale("reference.md", &md),
        "schemas/ is out of date: run `cargo run -- schema` and commit the result"
    );
}

#[test]
fn schema_documents_every_field_with_default_unit_and_range() {
    let s = voltab::pipeline::schema::json_schema();
    let props = &s["$defs"]["PhaseHgRaw"]["properties"];
    for f in voltab::tables::phase_hg::PhaseHgRaw::FIELDS {
        let p = &props[f.name];
        assert!(
            p.get("default").is_some() && p.get("x-unit").is_some() && p.get("x-range").is_some(),
            "{}: {p}",
            f.name
        );
        assert!(p.get("description").is_some(), "{} lacks a description", f.name);
    }
    assert_eq!(props["mu_bins"]["default"], 1024);
    assert_eq!(s["$defs"]["PhaseHgRaw"]["additionalProperties"], false);
}
