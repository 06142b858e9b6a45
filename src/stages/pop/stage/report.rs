//! `voltab report --stages` for POP: grid resolution, iteration cap and isotropic residuum → the
//! collided-fluence error on elek2014's Fig. 12 cube against light tracing, against run time
//! ([`LadderPoint`], the error-against-time ladder and its plot).

use super::*;

/// One point of the error-against-time ladder.
#[derive(Debug, Clone, Serialize)]
pub struct LadderPoint {
    /// Grid cells per axis.
    pub grid: usize,
    /// Anisotropic iteration cap `M`.
    pub iterations: usize,
    /// Isotropic residuum on.
    pub residuum: bool,
    /// Propagation time (initialisation, anisotropic and residuum iterations) \[ms\].
    pub propagation_ms: f64,
    /// Iterations run (anisotropic + isotropic).
    pub iterations_run: usize,
    /// The collided fluence of the mid slice against the light tracer (relative to its mean, noise
    /// removed), or the floor when below it.
    pub error: f64,
    /// `error` is the floor (an upper bound).
    pub below_floor: bool,
}

impl PopRender {
    /// `voltab report --stages`: on the Fig. 12 cube with `g = 0.7`, POP's collided-fluence error in the
    /// mid slice against a light-tracing reference of `max(fig12_photons, 400 000)` photons, against
    /// POP's run time, over grid resolutions, iteration caps and with and without the isotropic residuum;
    /// and the light tracer's own error (against the same reference) at increasing photon counts
    /// (`<id>-pop.md`, `<id>-pop-error-vs-time.png`).
    pub fn report(&self, id: &str, ctx: &StageContext, report_dir: &Path) -> Result<String, StageError> {
        use crate::stages::pop::fig12;
        let out =
            |path: &Path, message: String| StageError::Output { stage: id.into(), path: path.to_path_buf(), message };
        let fail = |message: String| StageError::Input { stage: id.into(), message, help: "check the preset".into() };
        let table = self.open_table(id, ctx)?;
        let g = 0.7;
        let photons = u64::from(self.fig12_photons).max(400_000);
        let mut points = Vec::new();
        let mut floors = Vec::new();
        for grid in [8usize, 16, 32] {
            let reference = fig12::reference_fluence(g, grid, photons, 99);
            for iterations in [4usize, 8, 16, 32, 64, 128] {
                for residuum in [false, true] {
                    let (mut settings, flow) = cube_settings(&table, g, grid);
                    settings.iterations = iterations;
                    settings.residuum = residuum;
                    let r = fig12::pop_fluence(g, grid, &flow, &settings).map_err(fail)?;
                    let e = fig12::slice_error(&r, &reference, grid).map_err(fail)?;
                    floors.push((grid, e.floor));
                    points.push(LadderPoint {
                        grid,
                        iterations,
                        residuum,
                        propagation_ms: r.ms,
                        iterations_run: r.iterations,
                        error: e.rel_or_floor(),
                        below_floor: e.below_floor(),
                    });
                }
            }
        }
        // The light tracer's own convergence on the 16³ tally.
        let reference = fig12::reference_fluence(g, 16, photons, 99);
        let mut mc_points = Vec::new();
        for n in [1_000u64, 4_000, 16_000, 64_000] {
            let r = fig12::reference_fluence(g, 16, n, 7);
            let e = fig12::slice_error(&r, &reference, 16).map_err(fail)?;
            mc_points.push((r.ms, e.rel_or_floor(), e.below_floor()));
        }
        std::fs::create_dir_all(report_dir).map_err(|e| out(report_dir, e.to_string()))?;
        let mut series = Vec::new();
        for grid in [8usize, 16, 32] {
            for residuum in [false, true] {
                let pts: Vec<(f64, f64)> = points
                    .iter()
                    .filter(|p| p.grid == grid && p.residuum == residuum)
                    .map(|p| (p.propagation_ms.max(1e-3), p.error.max(1e-6)))
                    .collect();
                let name = format!("POP {grid}³{}", if residuum { " + residuum" } else { "" });
                series.push(crate::report::plot::Series { name, points: pts });
            }
        }
        series.push(crate::report::plot::Series {
            name: "light tracing".into(),
            points: mc_points.iter().map(|&(t, e, _)| (t.max(1e-3), e.max(1e-6))).collect(),
        });
        let png = report_dir.join(format!("{id}-pop-error-vs-time.png"));
        let plot = crate::report::plot::Plot {
            title: &format!("{id}: POP on the elek2014 Fig. 12 cube (g = {g}), error against time"),
            x_label: "run time [ms]",
            y_label: "collided fluence, mid slice: rel. RMSE (noise removed)",
            x_scale: crate::report::plot::Scale::Log10,
            y_scale: crate::report::plot::Scale::Log10,
            series: &series,
            width: 1024,
            height: 720,
        };
        crate::report::plot::write_png(&png, &plot).map_err(|e| out(&png, e.to_string()))?;
        floors.dedup();
        let floors: Vec<String> = floors.iter().map(|(n, f)| format!("{n}³: {:.2} %", 100.0 * f)).collect();
        let mut md = format!(
            "## {id}: Principal-Ordinates Propagation (elek2014) on the Fig. 12 cube, g = {g}\n\nRelative RMSE of the collided fluence in the middle slice against light tracing ({photons} photons per grid), relative to the tracer's mean with its noise removed (\"< X\": below the floor X it resolves; floors {}), against run time, per grid and iteration cap, with and without the isotropic residuum.\n\n| grid | M | residuum | iterations run | ms | rel. error |\n|---:|---:|---|---:|---:|---:|\n",
            floors.join(", ")
        );
        let lt = |below: bool| if below { "< " } else { "" };
        for p in &points {
            md.push_str(&format!(
                "| {}³ | {} | {} | {} | {:.2} | {}{:.4} |\n",
                p.grid,
                p.iterations,
                if p.residuum { "on" } else { "off" },
                p.iterations_run,
                p.propagation_ms,
                lt(p.below_floor),
                p.error
            ));
        }
        md.push_str("\nLight tracing against the reference (16³ tally):\n\n| ms | rel. error |\n|---:|---:|\n");
        for (t, e, below) in &mc_points {
            md.push_str(&format!("| {t:.1} | {}{e:.4} |\n", lt(*below)));
        }
        let md_path = report_dir.join(format!("{id}-pop.md"));
        crate::cache::write_atomic(&md_path, md.as_bytes()).map_err(|e| out(&md_path, e.to_string()))?;
        Ok(md)
    }
}
