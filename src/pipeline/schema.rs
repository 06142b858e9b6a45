//! The pipeline language's schema: a JSON Schema generated from the Rust types (with each field's
//! default, unit and valid range added from its `declare_params!` declaration) and a Markdown
//! reference page for people. Both are committed under `schemas/`; a test fails when they no longer
//! match the code (`voltab schema --write` regenerates them).

use serde_json::{Value, json};

use super::kinds::{KindDoc, StageKinds};
use super::parse::PipelineFile;
use crate::tables::ms_lobes::{MsLobes, MsLobesRaw};
use crate::tables::phase_hg::{PhaseHg, PhaseHgRaw};
use crate::tables::pop_preset::{PopPreset, PopPresetRaw};
use crate::tables::zh_response::{ZhResponse, ZhResponseRaw};

/// Every table kind.
fn table_kinds() -> Vec<KindDoc> {
    vec![
        (
            PhaseHgRaw::KIND,
            "Henyey-Greenstein phase tables: phase value f(mu,g), per-azimuth cumulative F_hg (elek2014), inverse CDF mu(xi,g), ZH and Legendre coefficients; one chunk per g.",
            PhaseHgRaw::FIELDS,
            PhaseHg::defaults_json(),
        ),
        (
            ZhResponseRaw::KIND,
            "ZH impulse-response tables (dubouchet2019 Sec. 4-5): per emitter profile and HG g, the ZH coefficients of the incident radiance after each bounce b = 1..B, their sum and the direct term, over distance in mean free paths; one chunk per g. Convention: canonical medium sigma_s = 1, sigma_a = 0, lengths in mean free paths; a point emitter has intensity 1 W/sr, a directional emitter delivers 1 W/m^2 at the medium boundary (distance = depth below it), a differential-area emitter has intensity max(0, n_e.u) W/sr (axes: distance and the angle theta between n_e and the direction from the patch to the receiver); receiver irradiance E = integral of L(w) max(0, n.w) dw. The direct term of a point emitter is stored as irradiance e^-d/d^2 per unit cosine, never as a lobe. Orders beyond B: the tail arrays (albedo axis).",
            ZhResponseRaw::FIELDS,
            ZhResponse::defaults_json(),
        ),
        (
            MsLobesRaw::KIND,
            "Multiple-scattering lobe tables (wang2018 Sec. 3.5.4, 4.1, 5.2): per HG g slice and albedo node, the radiance scattered at (rho, z) around a pencil beam toward a lobe direction by photons that had scattered at least once before (all orders >= 2, array total_g<i>[albedo, z, rho, theta(, phi)]), its direction integral (density_g<i>), the exactly-two-events part without its albedo^2 (double[g, ...]) and the fraction of each order's collisions inside the grid (inside[g, k]); one chunk per (g, albedo). Convention: unit-power beam from the origin along +z, sigma_t = 1, lengths in mean free paths, values in 1/(mfp sr) per unit beam power; theta is the angle between the outgoing direction and the axis origin -> P, and the symmetric lobe is the average over the azimuth about that axis (Full adds phi in [0, pi] from the plane of the beam). A medium with extinction sigma_t scales positions by sigma_t and values by sigma_t^3. Defaults: the Table 2 materials' g and channel albedos exactly, a 9-node albedo grid uniform in sqrt(1 - albedo), a 32 x [-16, 48] mfp grid (graded: 96 x 160 cells, finest at the beam start), 33 theta nodes (5.6 degrees, finer than the paper's 18), 2^19 photons per g traced to order 512 (orders beyond: central-limit closure), 10 mantissa bits (below the Monte-Carlo noise).",
            MsLobesRaw::FIELDS,
            MsLobes::defaults_json(),
        ),
        (
            PopPresetRaw::KIND,
            "Principal-Ordinates Propagation preset (elek2014 Sec. 4-5): N principal ordinates (spherical Fibonacci unit vectors, array ordinates[n, xyz]), the solid angle of each ordinate's Voronoi cell (ordinate_solid_angle[n], sr, sum 4 pi), the prefiltered initial anisotropy of Sec. 5.1 = mean cosine between the ordinate and its cell (ordinate_mean_cosine[n]), and the flow partition of Eqs. 2-3 (flow[a, side]: fractions of an HG lobe of mean cosine a, uniform in [-1, 1], reaching the front cell, EACH of the four side cells and the back cell). The scalar settings (grids, iterations, thresholds eps_l and eps_a of Eqs. 9-10, beta, importance propagation) are stored in the table's definition for the real-time solver. Defaults: the paper's real-time setting (64 ordinates, 20^3 grid, 15 iterations).",
            PopPresetRaw::FIELDS,
            PopPreset::defaults_json(),
        ),
    ]
}

/// JSON Schema of a pipeline file whose stage entries are `S`.
pub fn json_schema<S: StageKinds>() -> Value {
    let mut schema = serde_json::to_value(schemars::schema_for!(PipelineFile<S>)).unwrap_or(Value::Null);
    schema["title"] = json!("voltab pipeline");
    schema["description"] =
        json!("A voltab pipeline file (RON). Generated from the Rust types by `voltab schema --write`; do not edit.");
    for (kind, _, fields, defaults) in table_kinds().into_iter().chain(S::docs()) {
        let def_name = format!("{kind}Raw");
        let Some(props) =
            schema.get_mut("$defs").and_then(|d| d.get_mut(&def_name)).and_then(|d| d.get_mut("properties"))
        else {
            continue;
        };
        for f in fields {
            if let Some(p) = props.get_mut(f.name) {
                if let Some((_, d)) = defaults.iter().find(|(n, _)| *n == f.name) {
                    p["default"] = d.clone();
                }
                p["x-unit"] = json!(f.unit);
                p["x-range"] = json!(f.range);
            }
        }
    }
    schema
}

/// The human reference page of a pipeline file whose stage entries are `S`.
pub fn reference_markdown<S: StageKinds>() -> String {
    let mut s = String::new();
    s.push_str("# voltab pipeline reference\n\n");
    s.push_str("Generated from the code by `voltab schema --write`; a test fails when it is out of date. ");
    s.push_str("Machine-readable form: `pipeline.schema.json` (JSON Schema) beside this file.\n\n");
    s.push_str("## File layout\n\n```ron\n(\n    include: [\"studio-base.ron\"],              // optional: loaded first (paths relative to this file)\n    presets: { \"fine\": PhaseHg(mu_bins: 4096) }, // optional: partial definitions\n    tables: [\n        PhaseHg(id: \"hg\", preset: \"fine\", g: [-0.5, 0.0, 0.5]),\n    ],\n    overrides: { \"hg_dubouchet\": PhaseHg(zh_order: 16) }, // optional: change fields of included tables\n    stages: [ PlotPhase(id: \"hg_plot\", table: \"hg\") ],\n)\n```\n\n");
    s.push_str("- Every field of a table or stage may be omitted: it then takes the value of its `preset` (presets may chain), else the default below.\n");
    s.push_str("- `id` is required in `tables` and `stages`, unique, and used as the output file name (letters, digits, `_`, `-`, `.`).\n");
    s.push_str("- Unknown fields, unknown kinds, wrong types, out-of-range values, duplicate ids and dangling preset/override/table references are errors with `file:line:column` and a hint.\n\n");
    s.push_str("## Physical conventions\n\n");
    s.push_str("- Phase functions are normalised over the sphere: the integral of f over all directions is 1 (unit 1/sr). mu = cos(theta) is the cosine between the incident propagation direction and the scattered direction; g is the mean cosine.\n");
    s.push_str("- F_hg(mu, g) (elek2014) is the cumulative per unit azimuth, 1/rad: 2 pi F_hg(mu, g) is the probability that the scattering cosine is at most mu.\n");
    s.push_str("- ZH coefficients use real-SH normalisation y_l^0 = sqrt((2l+1)/(4 pi)) P_l: the HG lobe's coefficients are sqrt((2l+1)/(4 pi)) g^l.\n\n");
    for (title, kinds) in [("Table kinds", table_kinds()), ("Stage kinds", S::docs())] {
        s.push_str(&format!("## {title}\n\n"));
        for (kind, about, fields, defaults) in kinds {
            let about = about.split_whitespace().collect::<Vec<_>>().join(" ");
            s.push_str(&format!("### `{kind}`\n\n{about}\n\n| field | type | default | unit | valid range | meaning |\n|---|---|---|---|---|---|\n"));
            for f in fields {
                let d = defaults.iter().find(|(n, _)| *n == f.name).map_or_else(String::new, |(_, v)| v.to_string());
                let doc = f.doc.split_whitespace().collect::<Vec<_>>().join(" ");
                s.push_str(&format!(
                    "| `{}` | `{}` | `{}` | {} | {} | {} |\n",
                    f.name,
                    f.ty.replace(' ', ""),
                    d,
                    f.unit,
                    f.range.replace('|', "\\|"),
                    doc.replace('|', "\\|")
                ));
            }
            s.push('\n');
        }
    }
    s
}
