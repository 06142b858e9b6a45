//! The extreme-input matrix: every row must hold (finite, in range, analytic limits).

#[test]
fn every_formula_survives_extreme_inputs() {
    let rows = voltab::registry::stability_rows();
    let failed: Vec<String> = rows.iter().filter(|r| !r.ok()).map(ToString::to_string).collect();
    assert!(failed.is_empty(), "{} of {} rows failed:\n{}", failed.len(), rows.len(), failed.join("\n"));
    // PhaseHg: 11 g × (5 μ × 2 + 3 + 5 ξ + 4) + 2 whole-table rows. ZhResponse: 3 emitters × (4 media ×
    // 2 g × 5 d × 3 normals + 1 vacuum row) + 1 overflow row. MsLobes: 5 albedos × 4 g × 4 points × 2 θ.
    // ImageFog: 5 density-integral rows + 4 spread rows. Translucent: 5 Fresnel + 4 Eq. 10 weights + 1 oil
    // weight + 3 boundary rows (index-matched grazing Fresnel, grazing emission profile, z_b) + 2 grazing-beam
    // medians + 2 solid angles + 5 object-light rows (coincident photons, 3 glow walks, 1 caustic) + 5 scene-ray
    // rows. PopPreset: 6 a × 4 flow rows + 3 N × 3 ordinate rows + 1 validation row + 5 Eq. 10 rows.
    // PopRadial: 5 shell cases × 2 + 4 centroid/Δr/V + 4 octahedral + 2 ∫ds/r². The matrix must not
    // silently shrink.
    assert_eq!(
        rows.len(),
        11 * (5 * 2 + 3 + 5 + 4)
            + 2
            + 3 * (4 * 2 * 5 * 3 + 1)
            + 1
            + 5 * 4 * 4 * 2
            + 5
            + 4
            + 22
            + 6 * 4
            + 3 * 3
            + 1
            + 5
            + 5 * 2
            + 4
            + 4
            + 2
            + 5
    );
}

#[test]
fn the_harness_catches_a_bad_value() {
    use voltab::stability::{Expect, Row};
    let r = |value, expect| Row { kind: "t", formula: "f", input: String::new(), value, expect };
    assert!(!r(f64::NAN, Expect::Finite).ok());
    assert!(!r(f64::INFINITY, Expect::Positive).ok());
    assert!(!r(0.0, Expect::Positive).ok());
    assert!(!r(1.5, Expect::InRange(-1.0, 1.0)).ok());
    assert!(!r(1.1, Expect::Close { to: 1.0, rel: 0.01 }).ok());
    assert!(r(1.005, Expect::Close { to: 1.0, rel: 0.01 }).ok());
}
