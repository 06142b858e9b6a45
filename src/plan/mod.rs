//! The scene planner: "leave out what a given scene does not need".
//!
//! **Input → output.** A [`ValidatedPipeline`] and one or more imported [`Scene`]s → a [`Plan`]: per table
//! and per slice (g slice, emitter profile, albedo node, distance range) "compile" or "skip" with the
//! reason, and the pruned table definitions; [`Plan::pruned_pipeline`] turns it into the pipeline
//! `voltab compile --scene` compiles.
//!
//! **What a scene needs** ([`Needs`]):
//! - *fog media* (the global medium and media in index-matched closed meshes) are lit through
//!   volume-to-surface transport: `ZhResponse` (dubouchet2019 Sec. 4–5) with the emitter profiles of the
//!   scene's lights — point tables for point and spot lights, directional tables for distant lights, the
//!   differential-area table for area lights, emissive meshes and indirectly lit surfaces (Sec. 5) — its
//!   g slices bracketing the media's g, and its distance axis up to twice the largest optical extent
//!   (diagonal × max σ_t) plus [`DISTANCE_MARGIN`] mean free paths for the bounce recursion;
//! - *translucent media* (inside refractive closed meshes) use `MsLobes` (wang2018): the g slices and
//!   albedo nodes bracketing their per-channel g and albedo;
//! - every medium samples HG: `PhaseHg` slices bracketing all media's g.
//!
//! A slice "brackets" a range when it is the largest node at or below the range's low end, the smallest
//! at or above its high end, or a node in between, so interpolation inside the range never needs a
//! dropped slice. Slices are computed independently of each other (MsLobes slices draw their random
//! streams from the slice's own parameters), so a pruned table's slices equal the full table's.
//! The ZH distance axis is the exception: bounce `b` is computed from bounce `b − 1` over the whole axis,
//! so trimming it changes the kept distances slightly (2e-8 relative with the margin; see the tests).

use std::borrow::Borrow;

use serde::Serialize;

use crate::pipeline::{Limits, ValidatedTable};
use crate::registry::{ValidatedPipeline, ValidatedStage};
use crate::scene::{Boundary, Density, LightKind, Scene, Surface};
use crate::stages::StageDef;
use crate::stages::planning::{ON_NODE, PlannedScenes, StageDecision};
use crate::stages::pop;
use crate::tables::TableDef;
use crate::tables::ms_lobes::MsLobes;
use crate::tables::phase_hg::{GValues, PhaseHg};
use crate::tables::zh_response::{DistanceSpacing, EmitterProfile, ZhResponse};

/// Whether a table, slice or stage is compiled.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Decision {
    /// Compiled.
    Compile,
    /// Left out.
    Skip,
    /// The scene needs something the pipeline does not declare (the reason says what to add).
    Missing,
}

impl Decision {
    fn word(self) -> &'static str {
        match self {
            Decision::Compile => "compile",
            Decision::Skip => "skip",
            Decision::Missing => "MISSING",
        }
    }
}

/// One slice (or axis range, or emitter profile) of a table.
#[derive(Debug, Clone, Serialize)]
pub struct Item {
    /// What it is, e.g. `g = 0.5` or `emitter Directional`.
    pub what: String,
    /// The decision.
    pub decision: Decision,
    /// Why.
    pub reason: String,
}

/// The plan for one table.
#[derive(Debug, Clone, Serialize)]
pub struct TablePlan {
    /// Table id.
    pub id: String,
    /// Table kind.
    pub kind: &'static str,
    /// Whether any of it is compiled.
    pub decision: Decision,
    /// Why (for the table as a whole).
    pub reason: String,
    /// Per slice.
    pub items: Vec<Item>,
    /// Work units (photons, g slices, …) of the full table.
    pub full_work: u64,
    /// Work units of the pruned table (0 when skipped).
    pub pruned_work: u64,
    /// The pruned definition (None when skipped).
    #[serde(skip)]
    pub def: Option<TableDef>,
}

/// The plan for one stage.
#[derive(Debug, Clone, Serialize)]
pub struct StagePlan {
    /// Stage id.
    pub id: String,
    /// Run or skip.
    pub decision: Decision,
    /// Why.
    pub reason: String,
    /// The adjusted definition (None when skipped).
    #[serde(skip)]
    pub def: Option<StageDef>,
}

/// A medium as the planner sees it.
#[derive(Debug, Clone, Serialize)]
pub struct MediumNeed {
    /// Medium name (and the scene it is from when several scenes are planned together).
    pub name: String,
    /// HG g per channel.
    pub g: [f64; 3],
    /// Single-scattering albedo per channel.
    pub albedo: [f64; 3],
    /// Largest extinction anywhere in the scene bounds \[1/m\] (density included).
    pub sigma_t_max: f64,
    /// `sigma_t_max ×` the scene diagonal: the most mean free paths a query can span.
    pub optical_extent: f64,
    /// Density varies in space.
    pub heterogeneous: bool,
}

/// What the scenes need.
#[derive(Debug, Clone, Default, Serialize)]
pub struct Needs {
    /// Point and spot lights.
    pub point_lights: Vec<String>,
    /// Distant lights.
    pub directional_lights: Vec<String>,
    /// Rect, disk and sphere lights and emissive meshes.
    pub area_lights: Vec<String>,
    /// Media reached by volume-to-surface transport (global, or in index-matched closed meshes).
    pub fog: Vec<MediumNeed>,
    /// Media inside refractive closed meshes.
    pub translucent: Vec<MediumNeed>,
    /// Some opaque surface shares the scene with fog (indirect surface light crosses the medium).
    pub surfaces_in_fog: bool,
}

/// The whole plan.
#[derive(Debug, Clone, Serialize)]
pub struct Plan {
    /// The scene files planned for.
    pub scenes: Vec<String>,
    /// What they need.
    pub needs: Needs,
    /// Per table.
    pub tables: Vec<TablePlan>,
    /// Per stage.
    pub stages: Vec<StagePlan>,
}

impl Needs {
    /// Collects the needs of the scenes (a union: a slice is needed when any scene needs it).
    pub fn of<S: Borrow<Scene>>(scenes: &[S]) -> Needs {
        let mut n = Needs::default();
        let many = scenes.len() > 1;
        for scene in scenes.iter().map(Borrow::borrow) {
            let tag = |name: &str| {
                if many { format!("{} ({})", name, scene.source.display()) } else { name.to_string() }
            };
            for l in &scene.lights {
                match l.kind {
                    LightKind::Point { .. } | LightKind::Spot { .. } => n.point_lights.push(tag(&l.name)),
                    LightKind::Directional { .. } => n.directional_lights.push(tag(&l.name)),
                    _ => n.area_lights.push(tag(&l.name)),
                }
            }
            let diag = scene.diagonal();
            let bounds = scene.bounds();
            let mut has_fog = false;
            for m in &scene.media {
                let refractive = match m.boundary {
                    Boundary::Global => false,
                    Boundary::Mesh(i) => scene.meshes.get(i).and_then(|mesh| mesh.material).is_some_and(|k| {
                        matches!(scene.materials.get(k).map(|mat| mat.surface), Some(Surface::Dielectric { ior }) if ior != 1.0)
                    }),
                };
                let sigma_t_max = m.sigma_t().iter().copied().fold(0.0, f64::max) * m.density.max_over(bounds);
                let need = MediumNeed {
                    name: tag(&m.name),
                    g: m.g,
                    albedo: m.albedo(),
                    sigma_t_max,
                    optical_extent: sigma_t_max * diag,
                    heterogeneous: m.density != Density::Homogeneous,
                };
                if refractive {
                    n.translucent.push(need);
                } else {
                    has_fog = true;
                    n.fog.push(need);
                }
            }
            let opaque = scene.meshes.iter().any(|mesh| {
                mesh.medium.is_none()
                    && !matches!(
                        mesh.material.and_then(|k| scene.materials.get(k)).map(|m| m.surface),
                        Some(Surface::Dielectric { .. })
                    )
            });
            n.surfaces_in_fog |= has_fog && opaque;
        }
        n
    }

    fn all_media(&self) -> impl Iterator<Item = &MediumNeed> {
        self.fog.iter().chain(&self.translucent)
    }
}

/// Range `[lo, hi]` of a channel quantity over media.
fn range<'a>(media: impl Iterator<Item = &'a MediumNeed>, f: impl Fn(&MediumNeed) -> [f64; 3]) -> Option<(f64, f64)> {
    let v: Vec<f64> = media.flat_map(f).collect();
    if v.is_empty() {
        return None;
    }
    Some((v.iter().copied().fold(f64::INFINITY, f64::min), v.iter().copied().fold(f64::NEG_INFINITY, f64::max)))
}

/// Mean free paths kept beyond twice the scene's optical extent on a trimmed ZH distance axis. The
/// bounce recursion feeds each distance from all others, so dropping far distances changes the kept
/// ones: measured on the fog-room test scene, 2·extent alone changes the total irradiance by up to 5e-3,
/// 2·extent + 4 by 3e-6, 2·extent + 8 by 2e-8 (below f32 storage precision).
pub const DISTANCE_MARGIN: f64 = 8.0;

/// Which nodes bracket `values`: for each value the node at or just below it and the node at or just
/// above it; `Err(value)` for a value outside the nodes.
fn bracket(nodes: &[f64], values: &[f64]) -> (Vec<bool>, Vec<f64>) {
    let mut keep = vec![false; nodes.len()];
    let mut outside = Vec::new();
    for &v in values {
        if let Some(i) = nodes.iter().position(|&x| (x - v).abs() <= ON_NODE) {
            keep[i] = true;
            continue;
        }
        match nodes.iter().position(|&x| x > v) {
            Some(0) | None => outside.push(v),
            Some(i) => {
                keep[i - 1] = true;
                keep[i] = true;
            }
        }
    }
    (keep, outside)
}

/// Keeps every node between the first and last kept one (a contiguous range: queries inside the range
/// interpolate between neighbours).
fn fill(keep: &mut [bool]) {
    if let (Some(a), Some(b)) = (keep.iter().position(|&k| k), keep.iter().rposition(|&k| k)) {
        keep[a..=b].iter_mut().for_each(|k| *k = true);
    }
}

/// `"= x"` for one value, `"∈ [lo, hi]"` for a range.
fn fmt_range((lo, hi): (f64, f64)) -> String {
    if lo == hi { format!("= {lo}") } else { format!("∈ [{lo}, {hi}]") }
}

fn slice_items(name: &str, nodes: &[f64], keep: &[bool], why_keep: &str, why_skip: &str) -> Vec<Item> {
    nodes
        .iter()
        .zip(keep)
        .map(|(v, &k)| Item {
            what: format!("{name} = {v}"),
            decision: if k { Decision::Compile } else { Decision::Skip },
            reason: if k { why_keep.to_string() } else { why_skip.to_string() },
        })
        .collect()
}

fn missing_items(name: &str, outside: &[f64], nodes: &[f64], field: &str) -> Vec<Item> {
    let (lo, hi) = (nodes.first().copied().unwrap_or(0.0), nodes.last().copied().unwrap_or(0.0));
    let mut outside = outside.to_vec();
    outside.sort_by(f64::total_cmp);
    outside.dedup();
    outside
        .iter()
        .map(|v| Item {
            what: format!("{name} = {v}"),
            decision: Decision::Missing,
            reason: format!("a scene medium has {name} {v}, outside the table's [{lo}, {hi}]: add it to `{field}`"),
        })
        .collect()
}

fn skipped(t: &ValidatedTable, reason: String) -> TablePlan {
    TablePlan {
        id: t.id().to_string(),
        kind: t.def().kind(),
        decision: Decision::Skip,
        reason,
        items: Vec::new(),
        full_work: t.def().kind_impl().work_units(),
        pruned_work: 0,
        def: None,
    }
}

fn compiled(t: &ValidatedTable, reason: String, items: Vec<Item>, def: TableDef) -> TablePlan {
    TablePlan {
        id: t.id().to_string(),
        kind: t.def().kind(),
        decision: Decision::Compile,
        reason,
        items,
        full_work: t.def().kind_impl().work_units(),
        pruned_work: def.kind_impl().work_units(),
        def: Some(def),
    }
}

fn plan_phase_hg(t: &ValidatedTable, d: &PhaseHg, needs: &Needs) -> TablePlan {
    let Some(g_range) = range(needs.all_media(), |m| m.g) else {
        return skipped(t, "the scene has no participating media".into());
    };
    let nodes = d.g.values();
    let gs: Vec<f64> = needs.all_media().flat_map(|m| m.g).collect();
    let (mut keep, outside) = bracket(&nodes, &gs);
    fill(&mut keep);
    let r = fmt_range(g_range);
    let mut items = slice_items(
        "g",
        &nodes,
        &keep,
        &format!("brackets the scene media's g {r}"),
        &format!("unused: scene media have g {r}"),
    );
    items.extend(missing_items("g", &outside, &nodes, "g"));
    let kept: Vec<f64> = nodes.iter().zip(&keep).filter(|(_, k)| **k).map(|(v, _)| *v).collect();
    if kept.is_empty() {
        return TablePlan { items, ..skipped(t, format!("no g slice brackets the scene media's g {r}")) };
    }
    let def = TableDef::PhaseHg(PhaseHg { g: GValues::List(kept.clone()), ..d.clone() });
    compiled(t, format!("{} of {} g slices: scene media have g {r}", kept.len(), nodes.len()), items, def)
}

/// A g (or, for `MsLobes`, an albedo) a table lacks is only missing when no other table of the same
/// kind in the pipeline spans it (tables such as `hg_dubouchet` serve one consumer's narrower range, and
/// a φ-resolved `MsLobes` table may hold one material beside the table that covers them all).
fn covered_elsewhere(p: &ValidatedPipeline, mut tables: Vec<TablePlan>) -> Vec<TablePlan> {
    // (kind, id, axis, lo, hi)
    let mut spans: Vec<(&str, String, &str, f64, f64)> = Vec::new();
    for t in p.tables() {
        let id = t.id().to_string();
        match t.def() {
            TableDef::PhaseHg(d) => {
                let v = d.g.values();
                if let (Some(lo), Some(hi)) = (v.first(), v.last()) {
                    spans.push(("PhaseHg", id, "g", *lo, *hi));
                }
            }
            TableDef::MsLobes(d) => {
                for (axis, v) in [("g", d.g_values()), ("albedo", d.albedo_values())] {
                    let lo = v.iter().copied().fold(f64::INFINITY, f64::min);
                    let hi = v.iter().copied().fold(f64::NEG_INFINITY, f64::max);
                    if lo <= hi {
                        spans.push(("MsLobes", id.clone(), axis, lo, hi));
                    }
                }
            }
            _ => {}
        }
    }
    for t in tables.iter_mut().filter(|t| t.kind == "PhaseHg" || t.kind == "MsLobes") {
        for item in t.items.iter_mut().filter(|i| i.decision == Decision::Missing) {
            let Some((axis, v)) = item.what.split_once(" = ") else { continue };
            let Ok(x) = v.parse::<f64>() else { continue };
            let other = spans
                .iter()
                .find(|(kind, id, ax, lo, hi)| *kind == t.kind && *id != t.id && *ax == axis && *lo <= x && x <= *hi);
            if let Some((_, id, ..)) = other {
                item.decision = Decision::Skip;
                item.reason = format!("outside this table's {axis} range; table {id} covers it");
            }
        }
    }
    tables
}

/// The trimmed distance axis: `(distance_max, distance_bins)` keeping the full axis's nodes up to the
/// first at or beyond `needed` (at least 4 nodes), or None when nothing can be trimmed.
fn trim_distance(d: &ZhResponse, needed: f64) -> Option<(f64, u32)> {
    let nodes = d.distance_axis().values_vec();
    let k = nodes.iter().position(|&x| x >= needed.max(1.0))?.max(3);
    (k + 1 < nodes.len()).then(|| (nodes[k], k as u32 + 1))
}

fn plan_zh(t: &ValidatedTable, d: &ZhResponse, needs: &Needs) -> TablePlan {
    if needs.fog.is_empty() {
        let why = if needs.translucent.is_empty() {
            "the scene has no participating media".to_string()
        } else {
            "no fog media: the scene's media are inside refractive objects (MsLobes renders those)".to_string()
        };
        return skipped(t, why);
    }
    let mut items = Vec::new();
    let mut emitters = Vec::new();
    for profile in EmitterProfile::ALL {
        let (needed, why) = match profile {
            EmitterProfile::Point => (!needs.point_lights.is_empty(), lights_reason("point/spot", &needs.point_lights)),
            EmitterProfile::Directional => {
                (!needs.directional_lights.is_empty(), lights_reason("directional", &needs.directional_lights))
            }
            EmitterProfile::Area => {
                if !needs.area_lights.is_empty() {
                    (true, lights_reason("area/emissive", &needs.area_lights))
                } else if needs.surfaces_in_fog {
                    (true, "indirectly lit surfaces in fog use the differential-area table (Sec. 5)".to_string())
                } else {
                    (false, "no area lights, emissive meshes or surfaces in fog".to_string())
                }
            }
        };
        let declared = d.emitters.contains(&profile);
        let decision = match (needed, declared) {
            (true, true) => Decision::Compile,
            (true, false) => Decision::Missing,
            (false, _) => Decision::Skip,
        };
        if decision == Decision::Compile {
            emitters.push(profile);
        }
        if declared || needed {
            items.push(Item {
                what: format!("emitter {profile:?}"),
                decision,
                reason: if decision == Decision::Missing {
                    format!("{why}: add {profile:?} to `emitters`")
                } else {
                    why
                },
            });
        }
    }
    if emitters.is_empty() {
        return TablePlan { items, ..skipped(t, "the scene has fog but no light the table's emitters cover".into()) };
    }
    let nodes = d.g.values();
    let gs: Vec<f64> = needs.fog.iter().flat_map(|m| m.g).collect();
    let r = fmt_range(range(needs.fog.iter(), |m| m.g).unwrap_or((0.0, 0.0)));
    let (mut keep, outside) = bracket(&nodes, &gs);
    fill(&mut keep);
    items.extend(slice_items(
        "g",
        &nodes,
        &keep,
        &format!("brackets the fog's g {r}"),
        &format!("unused: fog media have g {r}"),
    ));
    items.extend(missing_items("g", &outside, &nodes, "g"));
    let kept: Vec<f64> = nodes.iter().zip(&keep).filter(|(_, k)| **k).map(|(v, _)| *v).collect();
    if kept.is_empty() {
        return TablePlan { items, ..skipped(t, format!("no g slice brackets the fog's g {r}")) };
    }
    let extent = needs.fog.iter().map(|m| m.optical_extent).fold(0.0, f64::max);
    let mut def = ZhResponse { emitters, g: GValues::List(kept.clone()), ..d.clone() };
    let needed = 2.0 * extent + DISTANCE_MARGIN;
    if d.distance_spacing == DistanceSpacing::Log
        && let Some((max, bins)) = trim_distance(d, needed)
    {
        items.push(Item {
            what: format!("distances ({max:.4}, {}] mfp", d.distance_max),
            decision: Decision::Skip,
            reason: format!(
                "distance axis trimmed to {max:.4} mfp ({bins} of {} samples): twice the scene diagonal × max σ_t \
                 (2 × {extent:.4} mfp) + {DISTANCE_MARGIN} mfp for the bounce recursion",
                d.distance_bins
            ),
        });
        def.distance_max = max;
        def.distance_bins = bins;
    } else {
        items.push(Item {
            what: format!("distances [{}, {}] mfp", d.distance_min, d.distance_max),
            decision: Decision::Compile,
            reason: format!("the fog spans up to {extent:.4} mfp: the whole axis is needed"),
        });
    }
    let n_e = def.emitters.len();
    compiled(
        t,
        format!("{n_e} of {} emitters, {} of {} g slices", d.emitters.len(), kept.len(), nodes.len()),
        items,
        TableDef::ZhResponse(def),
    )
}

fn lights_reason(kind: &str, names: &[String]) -> String {
    if names.is_empty() {
        return format!("no {kind} lights");
    }
    let shown: Vec<&str> = names.iter().take(3).map(String::as_str).collect();
    let more = if names.len() > 3 { format!(" and {} more", names.len() - 3) } else { String::new() };
    format!("{kind} lights: {}{more}", shown.join(", "))
}

fn plan_ms_lobes(t: &ValidatedTable, d: &MsLobes, needs: &Needs) -> TablePlan {
    if needs.translucent.is_empty() {
        return skipped(t, "no refractive translucent objects in the scene".into());
    }
    let mut items = Vec::new();
    let g_nodes = d.g_values();
    let gs: Vec<f64> = needs.translucent.iter().flat_map(|m| m.g).collect();
    let r = fmt_range(range(needs.translucent.iter(), |m| m.g).unwrap_or((0.0, 0.0)));
    let (keep_g, outside_g) = bracket(&g_nodes, &gs);
    items.extend(slice_items(
        "g",
        &g_nodes,
        &keep_g,
        &format!("brackets the translucent media's g {r}"),
        &format!("unused: translucent media have g {r}"),
    ));
    items.extend(missing_items("g", &outside_g, &g_nodes, "g"));
    let a_nodes = d.albedo_values();
    let albedos: Vec<f64> = needs.translucent.iter().flat_map(|m| m.albedo).collect();
    let ra = fmt_range(range(needs.translucent.iter(), |m| m.albedo).unwrap_or((0.0, 0.0)));
    let (keep_a, outside_a) = bracket(&a_nodes, &albedos);
    items.extend(slice_items(
        "albedo",
        &a_nodes,
        &keep_a,
        &format!("brackets a translucent channel albedo ({ra})"),
        &format!("unused: translucent channel albedos {ra}"),
    ));
    items.extend(missing_items("albedo", &outside_a, &a_nodes, "albedos"));
    let kept = |nodes: &[f64], keep: &[bool]| -> Vec<f64> {
        nodes.iter().zip(keep).filter(|(_, k)| **k).map(|(v, _)| *v).collect()
    };
    let (kg, ka) = (kept(&g_nodes, &keep_g), kept(&a_nodes, &keep_a));
    if kg.is_empty() || ka.is_empty() {
        return TablePlan { items, ..skipped(t, "no slice brackets the translucent media".into()) };
    }
    let def = MsLobes { materials: Vec::new(), g: kg.clone(), albedos: ka.clone(), albedo_grid: 0, ..d.clone() };
    compiled(
        t,
        format!("{} of {} g slices, {} of {} albedo nodes", kg.len(), g_nodes.len(), ka.len(), a_nodes.len()),
        items,
        TableDef::MsLobes(def),
    )
}

/// A screen-space effect stage renders its own scene: it runs when that scene is among the planned
/// scenes and has what the effect needs (`lacks` names what is missing).
/// The materials of the stages that read `MsLobes` slices (`TranslucentRender`), on planned scenes: their
/// slices are needs like the scenes' own translucent media.
fn stage_lobe_needs(p: &ValidatedPipeline, scenes: &PlannedScenes) -> Vec<MediumNeed> {
    let mut out = Vec::new();
    for s in p.stages() {
        for name in s.def().stage().lobe_materials(scenes) {
            if let Some(m) = crate::tables::ms_lobes::material(&name) {
                out.push(MediumNeed {
                    name: format!("{name} (stage {})", s.id()),
                    g: [m.g; 3],
                    albedo: m.albedo,
                    sigma_t_max: 0.0,
                    optical_extent: 0.0,
                    heterogeneous: false,
                });
            }
        }
    }
    out
}

impl Plan {
    /// Plans a pipeline for scenes (their union of needs): `Scene`s, or scenes shared from a
    /// [`crate::scene::cache::SceneCache`].
    pub fn new<S: Borrow<Scene>>(p: &ValidatedPipeline, scenes: &[S]) -> Plan {
        let scenes: Vec<&Scene> = scenes.iter().map(Borrow::borrow).collect();
        let scenes = scenes.as_slice();
        let base = p.path().parent().unwrap_or(std::path::Path::new(""));
        let planned = PlannedScenes { base, scenes };
        let mut needs = Needs::of(scenes);
        needs.translucent.extend(stage_lobe_needs(p, &planned));
        let tables: Vec<TablePlan> = p
            .tables()
            .iter()
            .map(|t| match t.def() {
                TableDef::PhaseHg(d) => plan_phase_hg(t, d, &needs),
                TableDef::ZhResponse(d) => plan_zh(t, d, &needs),
                TableDef::MsLobes(d) => plan_ms_lobes(t, d, &needs),
                // A POP preset has no scene slices: it is small and kept whole when a scene has what POP
                // propagates.
                TableDef::PopPreset(_) => match scenes.iter().find(|sc| pop::scene::lacks(sc).is_none()) {
                    Some(sc) => compiled(
                        t,
                        format!(
                            "POP preset (kept whole): {} has a global medium and a light POP propagates",
                            sc.source.display()
                        ),
                        Vec::new(),
                        t.def().clone(),
                    ),
                    None => skipped(
                        t,
                        "no scene has a global medium lit by a directional, point, spot, sphere or dome light (what POP propagates)"
                            .into(),
                    ),
                },
            })
            .collect();
        let tables = covered_elsewhere(p, tables);
        let kept = |id: &str| tables.iter().find(|t| t.id == id).and_then(|t| t.def.as_ref());
        let stages = p
            .stages()
            .iter()
            .map(|s| {
                let (decision, reason, def) = match s.def().stage().plan(&planned, &kept) {
                    StageDecision::Run { reason, def } => (Decision::Compile, reason, Some(*def)),
                    StageDecision::Skip { reason } => (Decision::Skip, reason, None),
                };
                StagePlan { id: s.id().to_string(), decision, reason, def }
            })
            .collect();
        Plan { scenes: scenes.iter().map(|s| s.source.display().to_string()).collect(), needs, tables, stages }
    }

    /// The pipeline of the compiled tables with their pruned definitions and the kept stages.
    pub fn pruned_pipeline(&self, p: &ValidatedPipeline, limits: &Limits) -> Result<ValidatedPipeline, String> {
        let mut tables = Vec::new();
        for tp in &self.tables {
            let (Some(def), Some(t)) = (&tp.def, p.table(&tp.id)) else { continue };
            tables.push(
                t.with_def(def.clone(), limits).map_err(|e| format!("table \"{}\": pruned definition: {e}", tp.id))?,
            );
        }
        let mut stages: Vec<ValidatedStage> = Vec::new();
        for sp in &self.stages {
            let (Some(def), Some(s)) = (&sp.def, p.stages().iter().find(|s| s.id() == sp.id)) else { continue };
            stages.push(s.with_def(def.clone()).map_err(|e| format!("stage \"{}\": {e}", sp.id))?);
        }
        Ok(p.with_parts(tables, stages))
    }

    /// True when the scene needs something the pipeline does not declare.
    pub fn has_missing(&self) -> bool {
        self.tables.iter().flat_map(|t| &t.items).any(|i| i.decision == Decision::Missing)
    }

    /// The human-readable plan.
    pub fn text(&self) -> String {
        use std::fmt::Write as _;
        let mut s = String::new();
        let n = &self.needs;
        let _ = writeln!(s, "plan for {}", self.scenes.join(", "));
        let _ = writeln!(
            s,
            "  lights: {} point/spot, {} directional, {} area/emissive; media: {} fog ({} heterogeneous), {} translucent",
            n.point_lights.len(),
            n.directional_lights.len(),
            n.area_lights.len(),
            n.fog.len(),
            n.fog.iter().filter(|m| m.heterogeneous).count(),
            n.translucent.len()
        );
        for t in &self.tables {
            let work = if t.decision == Decision::Compile {
                format!(" (work {} of {})", t.pruned_work, t.full_work)
            } else {
                String::new()
            };
            let _ = writeln!(s, "{:<8} table {} [{}]: {}{work}", t.decision.word(), t.id, t.kind, t.reason);
            for i in &t.items {
                let _ = writeln!(s, "  {:<8} {:<28} {}", i.decision.word(), i.what, i.reason);
            }
        }
        for st in &self.stages {
            let _ = writeln!(s, "{:<8} stage {}: {}", st.decision.word(), st.id, st.reason);
        }
        s
    }
}

#[cfg(test)]
mod tests;
