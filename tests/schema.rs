//! The committed `schemas/` must match what the code generates.

#[test]
fn committed_schema_matches_the_code() {
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("schemas");
    let json = format!("{}\n", serde_json::to_string_pretty(&voltab::registry::json_schema()).unwrap());
    let md = voltab::registry::reference_markdown();
    let stale = |name: &str, want: &str| std::fs::read_to_string(root.join(name)).ok().as_deref() != Some(want);
    assert!(
        !stale("pipeline.schema.json", &json) && !stale("reference.md", &md),
        "schemas/ is out of date: run `cargo run -- schema` and commit the result"
    );
}

#[test]
fn schema_documents_every_field_with_default_unit_and_range() {
    let s = voltab::registry::json_schema();
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

/// Issue 29: the schema documented no stage kind but PlotPhase; every kind a pipeline accepts now has
/// each field's default, unit and range in both the JSON Schema and the reference page.
#[test]
fn every_stage_kind_is_documented() {
    use voltab::stages::{bake, god_rays, image_fog, pop, translucent};
    let s = voltab::registry::json_schema();
    let md = voltab::registry::reference_markdown();
    let kinds: [(&str, &[voltab::pipeline::params::FieldDoc]); 5] = [
        (bake::BakeLightmapsRaw::KIND, bake::BakeLightmapsRaw::FIELDS),
        (god_rays::EpipolarShadowsRaw::KIND, god_rays::EpipolarShadowsRaw::FIELDS),
        (image_fog::ImageFogRaw::KIND, image_fog::ImageFogRaw::FIELDS),
        (translucent::TranslucentRenderRaw::KIND, translucent::TranslucentRenderRaw::FIELDS),
        (pop::PopRenderRaw::KIND, pop::PopRenderRaw::FIELDS),
    ];
    for (kind, fields) in kinds {
        assert!(md.contains(&format!("### `{kind}`")), "{kind} missing from reference.md");
        let props = &s["$defs"][format!("{kind}Raw")]["properties"];
        assert!(fields.len() > 3, "{kind}");
        for f in fields {
            let p = &props[f.name];
            assert!(
                p.get("default").is_some() && p.get("x-unit").is_some() && p.get("x-range").is_some(),
                "{kind}.{}: {p}",
                f.name
            );
        }
    }
    // A spot value: the defaults are the declarations' (the god rays' 2048² shadow map).
    assert_eq!(s["$defs"]["EpipolarShadowsRaw"]["properties"]["shadow_map"]["default"], 2048);
}
