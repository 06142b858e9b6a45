//! The translucent stage's measurements (wang2018 Sec. 6): `voltab report --stages` — per material,
//! the noise-corrected MSE against a converged path-traced reference against run time, for the
//! point-based renderer at several qualities and for the reference at increasing paths per pixel —
//! and `voltab bench --suite translucent` (Table 3's frame times, the renderer against the reference).

use super::*;

/// Paths per pixel of the bench's longer reference.
const BENCH_LONG_REFERENCE: u32 = 4096;
/// Width of the bench's frame-time table (wang2018 Table 3 renders 512 × 512).
const BENCH_TABLE3_WIDTH: usize = 512;

/// The bench table's cells of one frame (wang2018 Table 3 columns): pre-processing, single,
/// double + multiple, bounced, rest and total ms, memory MB.
fn table3_cells(frame: &render::Frame, prep: &render::Prepared) -> String {
    let t = frame.times;
    let total = prep.preprocess_ms + t.single_ms + t.double_multiple_ms + t.bounced_ms + t.rest_ms;
    format!(
        "{:.0} | {:.0} | {:.0} | {:.0} | {:.0} | {:.0} | {:.1}",
        prep.preprocess_ms,
        t.single_ms,
        t.double_multiple_ms,
        t.bounced_ms,
        t.rest_ms,
        total,
        prep.memory_bytes as f64 / 1e6
    )
}

impl TranslucentRender {
    /// `voltab report --stages`: per material, MSE against a converged reference (its noise removed)
    /// against run time for the point-based renderer at several qualities and for the reference at
    /// increasing paths per pixel, at `reference_width` pixels wide; a plot per material and Markdown.
    pub fn report(&self, id: &str, ctx: &StageContext, report_dir: &Path) -> Result<String, StageError> {
        let out =
            |path: &Path, message: String| StageError::Output { stage: id.into(), path: path.to_path_buf(), message };
        std::fs::create_dir_all(report_dir).map_err(|e| out(report_dir, e.to_string()))?;
        let loaded = self.load(id, ctx)?;
        let fields = self.fields();
        let cam = fields.camera(id, &loaded.scene, &fields.scene_path(ctx.base_dir), None)?;
        let w = self.reference_width as usize;
        let h = ((w as f64) * cam.height as f64 / cam.width as f64).round().max(1.0) as usize;
        let small = ViewCamera { width: w, height: h, ..cam };
        let tables = self.open_tables(id, ctx, &loaded.scene)?;
        let converged = self.reference_samples.max(256) * 4;
        let ladder = [
            Quality { surface_samples: 1024, k_max: 4, epsilon1: 0.4 },
            Quality { surface_samples: 4096, k_max: 8, epsilon1: 0.2 },
            Quality { surface_samples: 16384, k_max: 16, epsilon1: 0.1 },
            Quality { surface_samples: 65536, k_max: 16, epsilon1: 0.05 },
        ];
        let mut md = format!(
            "## {id}: translucent media (wang2018), {w}×{h}\n\nNormalised MSE over the object's pixels (both images divided by the reference's mean object value) against a {converged}-path reference, with that reference's own noise removed, against run time; \"< X\" where the error is below the smallest MSE that reference resolves. Point-based times include the pre-processing.\n\n| material | method | setting | ms | MSE |\n|---|---|---|---:|---:|\n"
        );
        for name in &self.materials {
            let material = loaded.material(id, name, self.mfp_scale)?;
            let (_, table) = tables.for_material(&material);
            let setup = loaded.setup(material);
            let fail = material_error(id, name);
            let truth = reference::render(
                &setup,
                &small,
                &ReferenceOptions { samples: converged, seed: 0x7e57, ..ReferenceOptions::default() },
                &|_| {},
            );
            let truth_total = truth.total();
            // Normalised MSE with the reference's noise removed, the floor's square when below it, and
            // whether it is.
            let err = |img: &[[f64; 3]]| -> Result<(f64, bool), StageError> {
                let e = NoiseCorrected::of_rgb_masked(img, &truth_total, &truth.variance, &truth.object)
                    .map_err(|e| fail(format!("the {converged}-path reference cannot judge: {e}")))?;
                Ok((e.mse_or_floor(), e.below_floor()))
            };
            let mut curves = Vec::new();
            let mut pts = Vec::new();
            for q in ladder {
                let stage = TranslucentRender {
                    surface_samples: q.surface_samples,
                    k_max: q.k_max,
                    epsilon1: q.epsilon1,
                    epsilon2: self.epsilon2.min(q.epsilon1),
                    ..self.clone()
                };
                let t0 = Instant::now();
                let (frame, _) = stage.render_frame(&setup, table, &small, false).map_err(fail)?;
                let t = ms(t0);
                let label = format!("{} samples, k {}, ε1 {}", q.surface_samples, q.k_max, q.epsilon1);
                let (e, below) = err(&frame.total())?;
                pts.push((label, t, e, below));
            }
            curves.push(compare::Curve { name: format!("{name} point-based"), points: pts });
            let mut pts = Vec::new();
            for spp in [4u32, 16, 64, 256] {
                let t0 = Instant::now();
                let r = reference::render(
                    &setup,
                    &small,
                    &ReferenceOptions { samples: spp, seed: 0x51 + spp as u64, ..ReferenceOptions::default() },
                    &|_| {},
                );
                let (e, below) = err(&r.total())?;
                pts.push((format!("{spp} paths/px"), ms(t0), e, below));
            }
            curves.push(compare::Curve { name: format!("{name} path tracing"), points: pts });
            let series: Vec<Series> = curves
                .iter()
                .map(|c| Series {
                    name: c.name.clone(),
                    points: c.points.iter().filter(|p| p.2 > 0.0).map(|p| (p.1, p.2)).collect(),
                })
                .collect();
            let png = report_dir.join(format!("{id}-{name}-mse-vs-time.png"));
            let plot = Plot {
                title: &format!("{id}: {name}, MSE against run time ({w}×{h})"),
                x_label: "time [ms]",
                y_label: "normalised MSE over the object",
                x_scale: Scale::Log10,
                y_scale: Scale::Log10,
                series: &series,
                width: 1024,
                height: 720,
            };
            write_png(&png, &plot).map_err(|e| out(&png, e.to_string()))?;
            for c in &curves {
                for (label, t, e, below) in &c.points {
                    let lt = if *below { "< " } else { "" };
                    md.push_str(&format!("| {name} | {} | {label} | {t:.0} | {lt}{e:.2e} |\n", c.name));
                }
            }
        }
        let md_path = report_dir.join(format!("{id}-translucent.md"));
        crate::cache::write_atomic(&md_path, md.as_bytes()).map_err(|e| out(&md_path, e.to_string()))?;
        Ok(md)
    }

    /// `voltab bench --suite translucent`: per material, the paper's Table 3 columns at the stage's size and
    /// at 512 × 512 (pre-processing, single, double + multiple, bounced, rest), memory, the naive traversal against
    /// the two-step one, and the speed-up over path tracing at equal MSE at `reference_width` against
    /// the stage's reference and against a 4096-path one.
    pub fn bench(&self, id: &str, ctx: &StageContext) -> Result<(String, Vec<BenchRow>), StageError> {
        let loaded = self.load(id, ctx)?;
        let fields = self.fields();
        let cam = fields.camera(id, &loaded.scene, &fields.scene_path(ctx.base_dir), None)?;
        let tables = self.open_tables(id, ctx, &loaded.scene)?;
        let mut text = format!(
            "{id}: wang2018 point-based rendering at {}×{} ({} threads)\n\n| material | pre-proc ms | single ms | double+multiple ms | bounced ms | rest ms | total ms | memory MB | single naive ms |\n|---|---:|---:|---:|---:|---:|---:|---:|---:|\n",
            cam.width,
            cam.height,
            rayon::current_num_threads()
        );
        let mut rows = Vec::new();
        let stage = TranslucentRender { reference_samples: self.reference_samples.max(64), ..self.clone() };
        // wang2018 Table 3's frame size, at the stage's aspect ratio.
        let big = (
            BENCH_TABLE3_WIDTH,
            ((BENCH_TABLE3_WIDTH as f64) * cam.height as f64 / cam.width as f64).round().max(1.0) as usize,
        );
        let cam_big = fields.camera(id, &loaded.scene, &fields.scene_path(ctx.base_dir), Some(big))?;
        let mut text_big = format!(
            "\n{id}: the same at {}×{} (wang2018 Table 3's size)\n\n| material | pre-proc ms | single ms | double+multiple ms | bounced ms | rest ms | total ms | memory MB |\n|---|---:|---:|---:|---:|---:|---:|---:|\n",
            big.0, big.1
        );
        for name in &self.materials {
            let material = loaded.material(id, name, self.mfp_scale)?;
            let (_, table) = tables.for_material(&material);
            let setup = loaded.setup(material);
            let fail = material_error(id, name);
            let (frame, prep) = self.render_frame(&setup, table, &cam, false).map_err(fail)?;
            let naive = TranslucentRender { two_step: false, ..self.clone() };
            let (frame_naive, _) = naive.render_frame(&setup, table, &cam, false).map_err(fail)?;
            let t = frame.times;
            text.push_str(&format!(
                "| {name} | {} | {:.0} |\n",
                table3_cells(&frame, &prep),
                frame_naive.times.single_ms
            ));
            let (frame_big, prep_big) = self.render_frame(&setup, table, &cam_big, false).map_err(fail)?;
            text_big.push_str(&format!("| {name} | {} |\n", table3_cells(&frame_big, &prep_big)));
            rows.push(BenchRow {
                what: format!("{id} {name}: single scattering, naive vs two-step traversal"),
                baseline_ms: frame_naive.times.single_ms,
                candidate_ms: t.single_ms,
                speedup: frame_naive.times.single_ms / t.single_ms.max(1e-9),
                note: format!("{}×{}", cam.width, cam.height),
            });
            let dir = fields.out_dir(id, ctx)?;
            // The stage's own reference, and a 16× longer one: the reference is heavy-tailed (rare paths
            // through the object's shadow and its internal reflections), so its per-path variance,
            // which sets the equal-MSE time, is better measured over more paths.
            let mut counts = vec![stage.reference_samples];
            if stage.reference_samples < BENCH_LONG_REFERENCE {
                counts.push(BENCH_LONG_REFERENCE);
            }
            for samples in counts {
                let long = TranslucentRender { reference_samples: samples, ..stage.clone() };
                let (c, _) = long.compare(id, &dir, &format!("bench_{name}_{samples}"), &setup, table, &cam)?;
                rows.push(BenchRow {
                    what: format!("{id} {name}: path tracing vs point-based at equal MSE ({samples}-path reference)"),
                    baseline_ms: c.equal_mse_reference_ms,
                    candidate_ms: c.point_ms,
                    speedup: c.speedup,
                    note: format!("{}×{}, {}", c.size[0], c.size[1], c.describe()),
                });
            }
        }
        text.push_str(&text_big);
        Ok((text, rows))
    }
}
