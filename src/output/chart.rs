//! SVG line charts (convergence, speed against accuracy, error over time).

use std::path::Path;

use plotters::prelude::*;

use super::OutputError;

/// A named series for [`line_chart_svg`].
pub struct Series<'a> {
    pub name: &'a str,
    pub points: Vec<(f64, f64)>,
    /// Draw markers only (measurements) instead of a line (predictions).
    pub markers: bool,
    pub color: RGBColor,
}

/// A chart of several series to an SVG file. Log axes when requested
/// (non-positive values are then skipped). The legend is at the middle of
/// the right side ([`line_chart_svg_legend`] puts it elsewhere).
pub fn line_chart_svg(
    path: &Path,
    title: &str,
    x_label: &str,
    y_label: &str,
    series: &[Series<'_>],
    log_x: bool,
    log_y: bool,
) -> Result<(), OutputError> {
    line_chart_svg_legend(
        path,
        title,
        (x_label, y_label),
        series,
        (log_x, log_y),
        SeriesLabelPosition::MiddleRight,
    )
}

/// [`line_chart_svg`] with its legend at `legend`, for charts whose data
/// lies where the legend would; labels and log axes as (x, y).
pub fn line_chart_svg_legend(
    path: &Path,
    title: &str,
    (x_label, y_label): (&str, &str),
    series: &[Series<'_>],
    (log_x, log_y): (bool, bool),
    legend: SeriesLabelPosition,
) -> Result<(), OutputError> {
    let draw_err = |e: String| OutputError::Draw {
        path: path.display().to_string(),
        reason: e,
    };
    let keep = |(x, y): &(f64, f64)| x.is_finite() && y.is_finite() && (!log_x || *x > 0.0) && (!log_y || *y > 0.0);
    let all: Vec<(f64, f64)> = series
        .iter()
        .flat_map(|s| s.points.iter().copied().filter(keep))
        .collect();
    if all.is_empty() {
        return Err(draw_err("no finite point to plot".into()));
    }
    let range = |v: Vec<f64>, log: bool| {
        let (lo, hi) = v.iter().fold((f64::MAX, f64::MIN), |(a, b), &x| (a.min(x), b.max(x)));
        if log {
            (lo / 1.5, hi * 1.5)
        } else {
            let pad = ((hi - lo) * 0.05).max(1e-12);
            (lo - pad, hi + pad)
        }
    };
    let (x0, x1) = range(all.iter().map(|p| p.0).collect(), log_x);
    let (y0, y1) = range(all.iter().map(|p| p.1).collect(), log_y);
    let root = SVGBackend::new(path, (900, 600)).into_drawing_area();
    root.fill(&WHITE).map_err(|e| draw_err(e.to_string()))?;
    macro_rules! draw {
        ($chart:expr) => {{
            let mut chart = $chart;
            chart
                .configure_mesh()
                .x_desc(x_label)
                .y_desc(y_label)
                .x_label_formatter(&|v| tick(*v))
                .y_label_formatter(&|v| tick(*v))
                .draw()
                .map_err(|e| draw_err(e.to_string()))?;
            for s in series {
                let pts: Vec<(f64, f64)> = s.points.iter().copied().filter(keep).collect();
                let color = s.color;
                if s.markers {
                    chart
                        .draw_series(pts.iter().map(|&p| Circle::new(p, 4, color.filled())))
                        .map_err(|e| draw_err(e.to_string()))?
                        .label(s.name)
                        .legend(move |(x, y)| Circle::new((x + 10, y), 4, color.filled()));
                } else {
                    chart
                        .draw_series(LineSeries::new(pts, color.stroke_width(2)))
                        .map_err(|e| draw_err(e.to_string()))?
                        .label(s.name)
                        .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], color.stroke_width(2)));
                }
            }
            chart
                .configure_series_labels()
                .position(legend.clone())
                .background_style(WHITE.mix(0.8))
                .border_style(BLACK)
                .draw()
                .map_err(|e| draw_err(e.to_string()))?;
        }};
    }
    fn builder<'a, 'b>(
        root: &'a DrawingArea<SVGBackend<'b>, plotters::coord::Shift>,
        title: &str,
    ) -> ChartBuilder<'a, 'b, SVGBackend<'b>> {
        let mut b = ChartBuilder::on(root);
        b.caption(title, ("sans-serif", 22))
            .margin(15)
            .x_label_area_size(50)
            .y_label_area_size(80);
        b
    }
    match (log_x, log_y) {
        (true, true) => draw!(builder(&root, title)
            .build_cartesian_2d((x0..x1).log_scale(), (y0..y1).log_scale())
            .map_err(|e| draw_err(e.to_string()))?),
        (true, false) => draw!(builder(&root, title)
            .build_cartesian_2d((x0..x1).log_scale(), y0..y1)
            .map_err(|e| draw_err(e.to_string()))?),
        (false, true) => draw!(builder(&root, title)
            .build_cartesian_2d(x0..x1, (y0..y1).log_scale())
            .map_err(|e| draw_err(e.to_string()))?),
        (false, false) => draw!(builder(&root, title)
            .build_cartesian_2d(x0..x1, y0..y1)
            .map_err(|e| draw_err(e.to_string()))?),
    }
    root.present().map_err(|e| draw_err(e.to_string()))?;
    Ok(())
}

/// Colours for series, in order: Tableau's ten (matplotlib's `tab10`), so
/// a chart repeats a colour only past ten series (the drape charts draw
/// seven and more).
pub const PALETTE: [RGBColor; 10] = [
    RGBColor(31, 119, 180),
    RGBColor(255, 127, 14),
    RGBColor(44, 160, 44),
    RGBColor(214, 39, 40),
    RGBColor(148, 103, 189),
    RGBColor(140, 86, 75),
    RGBColor(227, 119, 194),
    RGBColor(127, 127, 127),
    RGBColor(188, 189, 34),
    RGBColor(23, 190, 207),
];

/// An axis tick with three significant digits and no trailing zeros (the
/// default printed log-axis ticks as `0.30000000000000004`).
fn tick(v: f64) -> String {
    if v == 0.0 || !v.is_finite() {
        return format!("{v}");
    }
    let decimals = (2 - v.abs().log10().floor() as i32).clamp(0, 12) as usize;
    let s = format!("{v:.decimals$}");
    if s.contains('.') {
        s.trim_end_matches('0').trim_end_matches('.').to_string()
    } else {
        s
    }
}
