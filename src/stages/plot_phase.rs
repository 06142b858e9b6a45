//! `PlotPhase`: compiled `PhaseHg` table → PNG plot of f(θ) per g on a log scale.
//!
//! A small consumer that proves the consumer side of the container: it opens the table and
//! decompresses only the g slices it plots. Lookups go through [`PhaseHgTable::phase_lerp`], so the
//! plot shows what a renderer sampling the table would see (including interpolation near the peak).

use std::path::Path;

use super::{StageError, StageOutcome, check_output_name};
use crate::report::plot::{Plot, Scale, Series, write_png};
use crate::tables::phase_hg::PhaseHgTable;
use crate::tables::{FieldIssue, TableDef};

crate::declare_params! {
    /// Plot the phase functions of a PhaseHg table.
    raw PlotPhaseRaw => resolved PlotPhase, kind "PlotPhase" {
        /// Id of the PhaseHg table to plot (declared in this pipeline).
        table: String = String::new(), unit = "", range = "id of a PhaseHg table";
        /// g values to plot (each must be one of the table's g); empty plots every g.
        g: Vec<f64> = Vec::new(), unit = "", range = "subset of the table's g values";
        /// Output PNG file name in the output folder; empty means `<stage id>.png`.
        output: String = String::new(), unit = "", range = "plain file name ending in .png";
        /// Angular samples per curve.
        samples: u32 = 721, unit = "samples", range = "2 to 100000";
    }
}

impl PlotPhase {
    /// Range checks.
    pub fn validate(&self) -> Vec<FieldIssue> {
        let mut v: Vec<FieldIssue> = check_output_name("output", &self.output, ".png").into_iter().collect();
        if !(2..=100_000).contains(&self.samples) {
            v.push(FieldIssue {
                field: "samples",
                message: format!("samples = {}", self.samples),
                help: "samples must be between 2 and 100000".into(),
            });
        }
        if self.g.iter().any(|g| !g.is_finite()) {
            v.push(FieldIssue {
                field: "g",
                message: "g contains a non-finite value".into(),
                help: "list g values of the table".into(),
            });
        }
        v
    }

    /// Every plotted g must be a g value of the table (matched within 1e-9, as the table reader
    /// matches them): found at `check`, not only when `run` opens the table (issue 37).
    pub fn check_table(&self, id: &str, table: &TableDef) -> Option<FieldIssue> {
        let TableDef::PhaseHg(t) = table else { return None };
        let have = t.g.values();
        let missing = self.g.iter().find(|g| !have.iter().any(|x| (*x - **g).abs() <= 1e-9))?;
        let list: Vec<String> = have.iter().take(32).map(|g| format!("{g}")).collect();
        Some(FieldIssue {
            field: "g",
            message: format!("stage \"{id}\" plots g = {missing}, which table \"{}\" does not hold", self.table),
            help: format!("use g values of the table: {}", list.join(", ")),
        })
    }

    /// Loads the wanted slices and writes the plot.
    pub fn run(&self, id: &str, out_dir: &Path) -> Result<StageOutcome, StageError> {
        let path = out_dir.join(format!("{}.vtab", self.table));
        let wanted = (!self.g.is_empty()).then_some(self.g.as_slice());
        let table = PhaseHgTable::open(&path, wanted).map_err(|e| StageError::Table {
            stage: id.into(),
            path: path.clone(),
            message: e.to_string(),
        })?;
        let n = self.samples;
        let series: Vec<Series> = table
            .loaded()
            .into_iter()
            .map(|gi| Series {
                name: format!("g = {}", table.g[gi]),
                points: (0..n)
                    .map(|i| {
                        let deg = 180.0 * f64::from(i) / f64::from(n - 1);
                        (deg, table.phase_lerp(gi, deg.to_radians().cos()).unwrap_or(f64::NAN))
                    })
                    .collect(),
            })
            .collect();
        let name = if self.output.is_empty() { format!("{id}.png") } else { self.output.clone() };
        let out = out_dir.join(name);
        let title = format!("Henyey-Greenstein phase, table {}", self.table);
        let plot = Plot {
            title: &title,
            x_label: "scattering angle (degrees)",
            y_label: "phase f (1/sr)",
            x_scale: Scale::Linear,
            y_scale: Scale::Log10,
            series: &series,
            width: 1024,
            height: 720,
        };
        write_png(&out, &plot).map_err(|e| StageError::Output {
            stage: id.into(),
            path: out.clone(),
            message: e.to_string(),
        })?;
        Ok(StageOutcome {
            summary: format!(
                "plotted {} of {} g slices from {}.vtab → {}",
                series.len(),
                table.g.len(),
                self.table,
                out.display()
            ),
            outputs: vec![out],
        })
    }
}

impl super::Stage for PlotPhase {
    fn kind(&self) -> &'static str {
        PlotPhaseRaw::KIND
    }
    fn table_refs(&self) -> Vec<(&'static str, String, &'static str)> {
        vec![("table", self.table.clone(), crate::tables::phase_hg::PhaseHgRaw::KIND)]
    }
    fn validate(&self) -> Vec<FieldIssue> {
        PlotPhase::validate(self)
    }
    fn check_tables(&self, id: &str, table: &dyn Fn(&str) -> Option<TableDef>) -> Vec<FieldIssue> {
        table(&self.table).and_then(|t| self.check_table(id, &t)).into_iter().collect()
    }
    fn plan(
        &self,
        _scenes: &super::planning::PlannedScenes,
        kept: &super::planning::KeptTables,
    ) -> super::planning::StageDecision {
        use super::planning::{ON_NODE, StageDecision, table_skipped};
        let Some(TableDef::PhaseHg(table)) = kept(&self.table) else { return table_skipped(&self.table) };
        let nodes = table.g.values();
        let wanted: Vec<f64> = if self.g.is_empty() {
            nodes
        } else {
            self.g.iter().copied().filter(|g| nodes.iter().any(|k| (k - g).abs() <= ON_NODE)).collect()
        };
        if wanted.is_empty() {
            return StageDecision::Skip { reason: "none of the g values it plots is needed by the scene".into() };
        }
        let reason = format!("plots the {} g values the scene needs", wanted.len());
        StageDecision::Run {
            reason,
            def: Box::new(super::StageDef::PlotPhase(PlotPhase { g: wanted, ..self.clone() })),
        }
    }
    fn run(&self, id: &str, ctx: &super::StageContext) -> Result<StageOutcome, StageError> {
        PlotPhase::run(self, id, ctx.out_dir)
    }
}
