//! PNG figures with plotters' pure-Rust bitmap backend and the bundled DejaVu Sans
//! font (tools/assets; no system font or library needed).

use std::path::Path;
use std::sync::Once;

use anyhow::{Result, anyhow};
use plotters::prelude::*;
use plotters::style::{FontStyle, register_font};

static FONT: &[u8] = include_bytes!("../../assets/DejaVuSans.ttf");
static REGISTER: Once = Once::new();

/// Largest number of points drawn per line (longer series are thinned evenly).
pub const MAX_LINE_POINTS: usize = 1500;

/// Line colours, one per joint / final time.
pub const COLORS: [RGBColor; 8] = [
    RGBColor(31, 119, 180),
    RGBColor(255, 127, 14),
    RGBColor(44, 160, 44),
    RGBColor(214, 39, 40),
    RGBColor(148, 103, 189),
    RGBColor(140, 86, 75),
    RGBColor(227, 119, 194),
    RGBColor(23, 190, 207),
];

/// One line (or point cloud) of a panel.
pub struct Series {
    /// Legend text ("" for none).
    pub label: String,
    /// Index into [`COLORS`].
    pub color: usize,
    /// (x, y) points.
    pub points: Vec<(f64, f64)>,
}

/// One chart of a figure.
pub struct Panel {
    /// Title above the chart.
    pub title: String,
    /// x axis label with unit.
    pub x_label: String,
    /// y axis label with unit.
    pub y_label: String,
    /// Lines, or point clouds when `scatter`.
    pub series: Vec<Series>,
    /// Draw points (pixels) instead of lines.
    pub scatter: bool,
    /// Same scale on both axes (workspace projections).
    pub equal_axes: bool,
}

fn err(e: impl std::fmt::Display) -> anyhow::Error {
    anyhow!("plot: {e}")
}

/// Evenly thins `points` to at most [`MAX_LINE_POINTS`], keeping the last one.
pub fn thin(points: Vec<(f64, f64)>) -> Vec<(f64, f64)> {
    let n = points.len();
    if n <= MAX_LINE_POINTS {
        return points;
    }
    let stride = n.div_ceil(MAX_LINE_POINTS);
    let last = points[n - 1];
    let mut out: Vec<(f64, f64)> = points.into_iter().step_by(stride).collect();
    if out.last() != Some(&last) {
        out.push(last);
    }
    out
}

fn range(vals: impl Iterator<Item = f64>) -> (f64, f64) {
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    for v in vals.filter(|v| v.is_finite()) {
        lo = lo.min(v);
        hi = hi.max(v);
    }
    if !lo.is_finite() {
        return (-1.0, 1.0);
    }
    let span = hi - lo;
    let pad = if span > 1e-12 * (lo.abs() + hi.abs()) && span > 1e-12 {
        0.05 * span
    } else {
        0.5 * lo.abs().max(1.0)
    };
    (lo - pad, hi + pad)
}

/// Draws `panels` on a `rows × cols` grid into a `size` PNG with an overall caption.
pub fn draw(
    path: &Path,
    size: (u32, u32),
    grid: (usize, usize),
    caption: &str,
    panels: &[Panel],
) -> Result<()> {
    REGISTER.call_once(|| {
        // The bundled font is valid; if registration ever failed, text would be
        // missing but the figure still drawn.
        let _ = register_font("sans-serif", FontStyle::Normal, FONT);
    });
    let root = BitMapBackend::new(path, size).into_drawing_area();
    root.fill(&WHITE).map_err(err)?;
    let root = root.titled(caption, ("sans-serif", 24)).map_err(err)?;
    let areas = root.split_evenly(grid);
    for (area, panel) in areas.iter().zip(panels) {
        let all = || panel.series.iter().flat_map(|s| s.points.iter());
        let (mut x0, mut x1) = range(all().map(|p| p.0));
        let (mut y0, mut y1) = range(all().map(|p| p.1));
        if panel.equal_axes {
            let (w, h) = area.dim_in_pixel();
            let (sx, sy) = ((x1 - x0) / w.max(1) as f64, (y1 - y0) / h.max(1) as f64);
            let s = sx.max(sy);
            let (cx, cy) = (0.5 * (x0 + x1), 0.5 * (y0 + y1));
            x0 = cx - 0.5 * s * w as f64;
            x1 = cx + 0.5 * s * w as f64;
            y0 = cy - 0.5 * s * h as f64;
            y1 = cy + 0.5 * s * h as f64;
        }
        let mut chart = ChartBuilder::on(area)
            .caption(&panel.title, ("sans-serif", 18))
            .margin(8)
            .x_label_area_size(40)
            .y_label_area_size(70)
            .build_cartesian_2d(x0..x1, y0..y1)
            .map_err(err)?;
        chart
            .configure_mesh()
            .x_desc(panel.x_label.as_str())
            .y_desc(panel.y_label.as_str())
            .label_style(("sans-serif", 13))
            .light_line_style(RGBColor(235, 235, 235))
            .draw()
            .map_err(err)?;
        let mut labelled = false;
        for s in &panel.series {
            let color = COLORS[s.color % COLORS.len()];
            if panel.scatter {
                chart
                    .draw_series(
                        s.points
                            .iter()
                            .map(|&(x, y)| Pixel::new((x, y), color.mix(0.6))),
                    )
                    .map_err(err)?;
            } else {
                let anno = chart
                    .draw_series(LineSeries::new(
                        s.points.iter().copied(),
                        color.stroke_width(2),
                    ))
                    .map_err(err)?;
                if !s.label.is_empty() {
                    labelled = true;
                    anno.label(s.label.as_str()).legend(move |(x, y)| {
                        PathElement::new(vec![(x, y), (x + 18, y)], color.stroke_width(3))
                    });
                }
            }
        }
        if labelled {
            chart
                .configure_series_labels()
                .label_font(("sans-serif", 13))
                .background_style(WHITE.mix(0.8))
                .border_style(BLACK)
                .position(SeriesLabelPosition::UpperRight)
                .draw()
                .map_err(err)?;
        }
    }
    root.present().map_err(err)?;
    Ok(())
}
