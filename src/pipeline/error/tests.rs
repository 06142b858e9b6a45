use super::did_you_mean;

#[test]
fn suggests_for_typos_and_transpositions_but_not_for_unrelated_words() {
    assert_eq!(did_you_mean("mu_bin", ["mu_bins", "xi_bins", "g"]), Some("mu_bins"));
    assert_eq!(did_you_mean("fgo", ["fog", "hg_dubouchet"]), Some("fog"));
    assert_eq!(did_you_mean("PhaseHG", ["PhaseHg"]), Some("PhaseHg"));
    assert_eq!(did_you_mean("albedo", ["mu_bins", "xi_bins", "g", "zh_order"]), None);
}

/// A 20,000-character unknown name took 3.1 s to compare (issue 37): long names are skipped.
#[test]
fn long_names_are_not_compared() {
    let long = "mu_bins".repeat(3000);
    let t = std::time::Instant::now();
    assert_eq!(did_you_mean(&long, ["mu_bins", long.as_str()]), None);
    assert!(t.elapsed().as_millis() < 100, "{:?}", t.elapsed());
}
