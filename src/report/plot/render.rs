//! Drawing a plot into memory.
//!
//! Input: a [`Plot`] (the DejaVu Sans font already registered with plotters).
//! Output: a `width × height` RGB8 pixel buffer (row-major, 3 bytes per
//! pixel, white background) holding the title, axes, ticks, one line plus
//! markers per series in its palette colour and marker shape, and the
//! legend; and a [`PlotOutcome`] counting the points drawn and skipped.
//! Axis ranges and ticks come from [`super::axis`].

use plotters::coord::Shift;
use plotters::element::ComposedElement;
use plotters::prelude::*;

use super::axis::{build_axis, to_plot_space};
use super::{Plot, PlotOutcome};

/// Why rendering failed, before a path is attached.
#[derive(Debug)]
pub(super) enum RenderError {
    /// The data cannot be placed on an axis.
    Range(String),
    /// Plotters reported a drawing failure.
    Draw(String),
}

/// Converts a plotters drawing error into a [`RenderError`].
fn draw_err<E: std::error::Error + Send + Sync>(e: DrawingAreaErrorKind<E>) -> RenderError {
    RenderError::Draw(e.to_string())
}

/// Series colours: the Okabe–Ito palette (minus yellow) plus two extras,
/// all readable on white.
const PALETTE: [RGBColor; 8] = [
    RGBColor(0, 114, 178),
    RGBColor(213, 94, 0),
    RGBColor(0, 158, 115),
    RGBColor(204, 121, 167),
    RGBColor(230, 159, 0),
    RGBColor(86, 180, 233),
    RGBColor(40, 40, 40),
    RGBColor(120, 70, 160),
];

/// Marker shapes, cycled at a different period than colours so that
/// colour + shape stays distinct for the first 40 series.
#[derive(Debug, Clone, Copy)]
enum Shape {
    Circle,
    Square,
    TriangleUp,
    Diamond,
    TriangleDown,
}

const SHAPES: [Shape; 5] = [Shape::Circle, Shape::Square, Shape::TriangleUp, Shape::Diamond, Shape::TriangleDown];

/// A marker, optionally with a line through it: a circle or a polygon
/// (whichever is unused is transparent or empty) on a short path, all in
/// pixel offsets from the anchor point. One concrete type serves every
/// shape because plotters' boxed `DynElement` would need a `'static`
/// backend, which one drawing into a borrowed buffer is not.
type Glyph<C, DB> = ComposedElement<
    C,
    DB,
    PathElement<(i32, i32)>,
    ComposedElement<(i32, i32), DB, Circle<(i32, i32), u32>, Polygon<(i32, i32)>>,
>;

/// Builds a marker of `shape` and half-size `r` pixels centred on `at`,
/// optionally with a horizontal line of `(half_length, width)` pixels
/// through it (used for legend entries).
fn glyph<DB: DrawingBackend, C>(
    at: C,
    shape: Shape,
    r: i32,
    colour: RGBColor,
    line: Option<(i32, u32)>,
) -> Glyph<C, DB> {
    let path = match line {
        Some((half, width)) => PathElement::new(vec![(-half, 0), (half, 0)], colour.stroke_width(width)),
        None => PathElement::new(Vec::new(), colour),
    };
    let fill = colour.filled();
    let s = r + 1;
    let (circle_style, vertices) = match shape {
        Shape::Circle => (fill, Vec::new()),
        Shape::Square => (TRANSPARENT.filled(), vec![(-r, -r), (r, -r), (r, r), (-r, r)]),
        Shape::TriangleUp => (TRANSPARENT.filled(), vec![(0, -s), (s, s - 1), (-s, s - 1)]),
        Shape::Diamond => (TRANSPARENT.filled(), vec![(0, -s), (s, 0), (0, s), (-s, 0)]),
        Shape::TriangleDown => (TRANSPARENT.filled(), vec![(0, s), (s, 1 - s), (-s, 1 - s)]),
    };
    EmptyElement::at(at) + path + Circle::new((0, 0), r.max(1) as u32, circle_style) + Polygon::new(vertices, fill)
}

/// Which legend corner overlaps the fewest points (`pts` in 0..1 plot
/// fractions), preferring upper right, upper left, lower right, lower left.
fn legend_corner(pts: &[(f64, f64)]) -> SeriesLabelPosition {
    let corners = [
        (SeriesLabelPosition::UpperRight, true, true),
        (SeriesLabelPosition::UpperLeft, false, true),
        (SeriesLabelPosition::LowerRight, true, false),
        (SeriesLabelPosition::LowerLeft, false, false),
    ];
    let mut best = (usize::MAX, SeriesLabelPosition::UpperRight);
    for (pos, right, upper) in corners {
        let count = pts
            .iter()
            .filter(|&&(u, v)| {
                let in_x = if right { u >= 0.55 } else { u <= 0.45 };
                let in_y = if upper { v >= 0.6 } else { v <= 0.4 };
                in_x && in_y
            })
            .count();
        if count < best.0 {
            best = (count, pos);
        }
    }
    best.1
}

/// `text` on one line (control characters become spaces), shortened with
/// a trailing `…` until it is at most `max_w` pixels wide in `style`.
fn fit_text<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    text: &str,
    style: &TextStyle,
    max_w: f64,
) -> Result<String, RenderError> {
    let mut chars: Vec<char> = text.chars().take(200).map(|c| if c.is_control() { ' ' } else { c }).collect();
    let mut candidate: String = chars.iter().collect();
    let truncated = chars.len() < text.chars().count();
    if truncated {
        candidate.push('…');
    }
    loop {
        let (w, _) = area.estimate_text_size(&candidate, style).map_err(draw_err)?;
        if f64::from(w) <= max_w || chars.is_empty() {
            return Ok(candidate);
        }
        chars.pop();
        candidate = chars.iter().collect();
        candidate.push('…');
    }
}

/// Renders `plot` into a fresh RGB8 buffer of `width × height × 3` bytes.
/// The font must already be registered.
pub(super) fn render_rgb(plot: &Plot) -> Result<(Vec<u8>, PlotOutcome), RenderError> {
    let (width, height) = (plot.width, plot.height);
    let len = (width as usize)
        .checked_mul(height as usize)
        .and_then(|n| n.checked_mul(3))
        .ok_or_else(|| RenderError::Range(format!("image size {width}x{height} too large")))?;
    let mut buf = vec![255u8; len];

    // Map points into plot space; split each series into unbroken runs.
    let mut outcome = PlotOutcome::default();
    let mut runs: Vec<Vec<Vec<(f64, f64)>>> = Vec::with_capacity(plot.series.len());
    let mut x_span: Option<(f64, f64)> = None;
    let mut y_span: Option<(f64, f64)> = None;
    let widen = |span: &mut Option<(f64, f64)>, v: f64| {
        *span = Some(match *span {
            Some((lo, hi)) => (lo.min(v), hi.max(v)),
            None => (v, v),
        });
    };
    for series in plot.series {
        let mut series_runs = vec![Vec::new()];
        for &(x, y) in &series.points {
            match (to_plot_space(plot.x_scale, x), to_plot_space(plot.y_scale, y)) {
                (Some(px), Some(py)) => {
                    outcome.points_drawn += 1;
                    widen(&mut x_span, px);
                    widen(&mut y_span, py);
                    if let Some(run) = series_runs.last_mut() {
                        run.push((px, py));
                    }
                }
                _ => {
                    outcome.points_skipped += 1;
                    if series_runs.last().is_some_and(|r| !r.is_empty()) {
                        series_runs.push(Vec::new());
                    }
                }
            }
        }
        series_runs.retain(|r| !r.is_empty());
        runs.push(series_runs);
    }

    let s = (f64::from(width.min(height)) / 600.0).clamp(0.5, 4.0);
    let px = |v: f64| (v * s).round().max(1.0);
    // Font sizes are even pixel counts: plotters' ab_glyph text path
    // truncates `size / 2 + glyph_top` to whole pixels, which puts glyphs
    // such as `.` and `-` a pixel off the baseline at odd sizes.
    let font_px = |v: f64| ((v * s / 2.0).round() * 2.0).max(8.0);
    let x_target = ((f64::from(width) / (110.0 * s)) as usize).clamp(2, 10);
    let y_target = ((f64::from(height) / (70.0 * s)) as usize).clamp(2, 10);
    let x_axis = build_axis(plot.x_scale, x_span, x_target).map_err(RenderError::Range)?;
    let y_axis = build_axis(plot.y_scale, y_span, y_target).map_err(RenderError::Range)?;

    {
        let root: DrawingArea<BitMapBackend, Shift> =
            BitMapBackend::with_buffer(&mut buf, (width, height)).into_drawing_area();
        root.fill(&WHITE).map_err(draw_err)?;

        let (title_px, desc_px, tick_px) = (font_px(22.0), font_px(16.0), font_px(14.0));
        let title_font = ("sans-serif", title_px).into_font();
        let desc_font = ("sans-serif", desc_px).into_font();
        let tick_font = ("sans-serif", tick_px).into_font();
        let legend_font = ("sans-serif", font_px(14.0)).into_font();

        let tick_style = TextStyle::from(tick_font.clone());
        let mut widest = 0u32;
        for label in &y_axis.labels {
            let (w, _) = root.estimate_text_size(label, &tick_style).map_err(draw_err)?;
            widest = widest.max(w);
        }
        let y_area = f64::from(widest) + desc_px * 1.3 + px(18.0);
        let x_area = tick_px * 1.3 + desc_px * 1.3 + px(18.0);

        let mut builder = ChartBuilder::on(&root);
        builder.margin(px(12.0)).margin_right(px(20.0)).x_label_area_size(x_area).y_label_area_size(y_area);
        if !plot.title.is_empty() {
            builder.caption(plot.title, title_font);
        }
        let mut chart = builder.build_cartesian_2d(x_axis.clone(), y_axis.clone()).map_err(draw_err)?;

        chart
            .configure_mesh()
            .x_desc(plot.x_label)
            .y_desc(plot.y_label)
            .label_style(tick_font)
            .axis_desc_style(desc_font)
            .bold_line_style(BLACK.mix(0.18))
            .light_line_style(BLACK.mix(0.06))
            .axis_style(BLACK.stroke_width(px(1.0) as u32))
            .set_all_tick_mark_size(px(5.0) as u32)
            .draw()
            .map_err(draw_err)?;

        // Legend: as many entries as fit the plot area's height (the rest
        // summarised as "+N more"), names shortened to fit 45% of its width.
        let legend_style = TextStyle::from(legend_font.clone());
        let legend_margin = px(8.0);
        let legend_glyph_area = px(30.0);
        let (area_w, area_h) = chart.plotting_area().dim_in_pixel();
        let entry_h = legend_font.get_size() * 1.25;
        let fit = ((f64::from(area_h) - 2.0 * legend_margin - 4.0) / entry_h).max(0.0) as usize;
        let labelled = if plot.series.len() <= fit { plot.series.len() } else { fit.saturating_sub(1) };
        let max_name_w = (0.45 * f64::from(area_w) - legend_glyph_area - 2.0 * legend_margin).max(0.0);

        let line_width = px(2.0) as u32;
        let marker = px(3.5) as i32;
        let legend_half = px(11.0) as i32;
        for (i, (series, series_runs)) in plot.series.iter().zip(&runs).enumerate() {
            let colour = PALETTE[i % PALETTE.len()];
            let shape = SHAPES[i % SHAPES.len()];
            for run in series_runs {
                chart
                    .draw_series(std::iter::once(PathElement::new(run.clone(), colour.stroke_width(line_width))))
                    .map_err(draw_err)?;
            }
            let points = series_runs.iter().flatten().copied();
            let anno = chart.draw_series(points.map(|p| glyph(p, shape, marker, colour, None))).map_err(draw_err)?;
            if i < labelled {
                let name = fit_text(&root, &series.name, &legend_style, max_name_w)?;
                anno.label(name).legend(move |c| glyph(c, shape, marker, colour, Some((legend_half, line_width))));
            }
        }
        let hidden = plot.series.len() - labelled;
        if hidden > 0 && fit > 0 {
            chart
                .draw_series(std::iter::empty::<PathElement<(f64, f64)>>())
                .map_err(draw_err)?
                .label(format!("+{hidden} more"));
        }

        if fit > 0 && !plot.series.is_empty() {
            let fractions: Vec<(f64, f64)> = runs
                .iter()
                .flatten()
                .flatten()
                .map(|&(x, y)| ((x - x_axis.lo) / (x_axis.hi - x_axis.lo), (y - y_axis.lo) / (y_axis.hi - y_axis.lo)))
                .collect();
            chart
                .configure_series_labels()
                .position(legend_corner(&fractions))
                .margin(legend_margin)
                .legend_area_size(legend_glyph_area)
                .label_font(legend_font)
                .background_style(WHITE.mix(0.9))
                .border_style(BLACK.mix(0.5))
                .draw()
                .map_err(draw_err)?;
        }
        root.present().map_err(draw_err)?;
    }
    Ok((buf, outcome))
}
