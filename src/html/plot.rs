//! SVG plots (plotters' SVG backend; no fonts or network needed).

use plotters::prelude::*;

const COLORS: [RGBColor; 6] = [
    RGBColor(31, 119, 180),
    RGBColor(255, 127, 14),
    RGBColor(44, 160, 44),
    RGBColor(214, 39, 40),
    RGBColor(148, 103, 189),
    RGBColor(140, 86, 75),
];

fn range(values: impl Iterator<Item = f64>) -> (f64, f64) {
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    for v in values.filter(|v| v.is_finite()) {
        lo = lo.min(v);
        hi = hi.max(v);
    }
    if !lo.is_finite() {
        return (0.0, 1.0);
    }
    if hi - lo <= f64::EPSILON * hi.abs().max(1.0) {
        let pad = hi.abs().max(1e-12) * 0.1;
        return (lo - pad, hi + pad);
    }
    let pad = 0.05 * (hi - lo);
    (lo - pad, hi + pad)
}

/// The project's chart frame on a drawing area: caption, margin and label areas.
fn builder<'a, 'b>(
    root: &'a DrawingArea<SVGBackend<'b>, plotters::coord::Shift>,
    title: &str,
) -> ChartBuilder<'a, 'b, SVGBackend<'b>> {
    let mut b = ChartBuilder::on(root);
    b.caption(title, ("sans-serif", 17)).margin(10).x_label_area_size(44).y_label_area_size(84);
    b
}

/// Axis descriptions and tick labels at a size that reads in a report and in the guide.
const DESC_FONT: (&str, u32) = ("sans-serif", 15);
const TICK_FONT: (&str, u32) = ("sans-serif", 13);

/// The series' legend, boxed, at `pos`, in the tick font.
fn legend<'a, CT: plotters::coord::CoordTranslate>(
    chart: &mut ChartContext<'a, SVGBackend<'a>, CT>,
    pos: SeriesLabelPosition,
) {
    let _ = chart
        .configure_series_labels()
        .position(pos)
        .label_font(TICK_FONT)
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK)
        .draw();
}

/// A line chart of named series of (x, y) points, as an SVG string.
pub fn lines(title: &str, x_label: &str, y_label: &str, series: &[(String, Vec<(f64, f64)>)]) -> String {
    let mut buf = String::new();
    let (x0, x1) = range(series.iter().flat_map(|s| s.1.iter().map(|p| p.0)));
    let (y0, y1) = range(series.iter().flat_map(|s| s.1.iter().map(|p| p.1)));
    {
        let root = SVGBackend::with_string(&mut buf, (720, 260)).into_drawing_area();
        let _ = root.fill(&WHITE);
        let Ok(mut chart) = builder(&root, title).build_cartesian_2d(x0..x1, y0..y1) else {
            return String::new();
        };
        let _ = chart
            .configure_mesh()
            .x_desc(x_label)
            .y_desc(y_label)
            .axis_desc_style(DESC_FONT)
            .label_style(TICK_FONT)
            .light_line_style(WHITE)
            .draw();
        for (i, (name, pts)) in series.iter().enumerate() {
            let c = COLORS[i % COLORS.len()];
            if let Ok(s) = chart.draw_series(LineSeries::new(pts.iter().copied(), c.stroke_width(1))) {
                s.label(name.as_str()).legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 14, y)], c));
            }
        }
        if series.len() > 1 {
            legend(&mut chart, SeriesLabelPosition::MiddleRight);
        }
        let _ = root.present();
    }
    buf
}

/// A bar chart of named values, as an SVG string.
pub fn bars(title: &str, x_label: &str, y_label: &str, values: &[(String, f64)]) -> String {
    let mut buf = String::new();
    let n = values.len().max(1) as f64;
    let (_, y1) = range(values.iter().map(|v| v.1).chain(std::iter::once(0.0)));
    {
        let root = SVGBackend::with_string(&mut buf, (720, 220)).into_drawing_area();
        let _ = root.fill(&WHITE);
        let Ok(mut chart) = builder(&root, title).build_cartesian_2d(-0.5..n - 0.5, 0.0..y1) else {
            return String::new();
        };
        let labels: Vec<String> = values.iter().map(|v| v.0.clone()).collect();
        let _ = chart
            .configure_mesh()
            .x_desc(x_label)
            .y_desc(y_label)
            .axis_desc_style(DESC_FONT)
            .label_style(TICK_FONT)
            .x_labels(values.len().max(1))
            .x_label_formatter(&|x| {
                let i = x.round();
                if (x - i).abs() < 1e-6 && i >= 0.0 {
                    labels.get(i as usize).cloned().unwrap_or_default()
                } else {
                    String::new()
                }
            })
            .light_line_style(WHITE)
            .draw();
        let _ = chart.draw_series(values.iter().enumerate().map(|(i, v)| {
            Rectangle::new([(i as f64 - 0.35, 0.0), (i as f64 + 0.35, v.1.max(0.0))], COLORS[0].filled())
        }));
        let _ = root.present();
    }
    buf
}

/// A log-log chart as an SVG string: `measured` points with vertical interval bars
/// (x, low, y, high) and named line series (e.g. a fitted curve and slope lines).
pub fn loglog(
    title: &str,
    x_label: &str,
    y_label: &str,
    measured: &[(f64, f64, f64, f64)],
    series: &[(String, Vec<(f64, f64)>)],
) -> String {
    let mut buf = String::new();
    let positive = |v: &f64| v.is_finite() && *v > 0.0;
    let xs = measured.iter().map(|p| p.0).chain(series.iter().flat_map(|s| s.1.iter().map(|p| p.0)));
    let ys = measured.iter().flat_map(|p| [p.1, p.2, p.3]).chain(series.iter().flat_map(|s| s.1.iter().map(|p| p.1)));
    let (x0, x1) = range(xs.filter(positive).map(f64::log10));
    let (y0, y1) = range(ys.filter(positive).map(f64::log10));
    let (x0, x1, y0, y1) = (10f64.powf(x0), 10f64.powf(x1), 10f64.powf(y0), 10f64.powf(y1));
    {
        let root = SVGBackend::with_string(&mut buf, (720, 420)).into_drawing_area();
        let _ = root.fill(&WHITE);
        let Ok(mut chart) = builder(&root, title).build_cartesian_2d((x0..x1).log_scale(), (y0..y1).log_scale()) else {
            return String::new();
        };
        let _ = chart
            .configure_mesh()
            .x_desc(x_label)
            .y_desc(y_label)
            .axis_desc_style(DESC_FONT)
            .label_style(TICK_FONT)
            .y_label_formatter(&|v| format!("{v:.1e}"))
            .draw();
        let c0 = COLORS[0];
        let inside = |y: f64| y.clamp(y0, y1);
        if let Ok(s) = chart.draw_series(
            measured
                .iter()
                .filter(|p| positive(&p.0) && positive(&p.2))
                .map(|p| ErrorBar::new_vertical(p.0, inside(p.1.max(y0)), p.2, inside(p.3), c0.filled(), 4)),
        ) {
            s.label("measured (68 % interval)").legend(move |(x, y)| Circle::new((x + 7, y), 3, c0.filled()));
        }
        for (i, (name, pts)) in series.iter().enumerate() {
            let c = COLORS[(i + 1) % COLORS.len()];
            let pts: Vec<(f64, f64)> =
                pts.iter().copied().filter(|p| positive(&p.0) && p.1 >= y0 && p.1 <= y1).collect();
            if let Ok(s) = chart.draw_series(LineSeries::new(pts, c.stroke_width(1))) {
                s.label(name.as_str()).legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 14, y)], c));
            }
        }
        legend(&mut chart, SeriesLabelPosition::UpperRight);
        let _ = root.present();
    }
    buf
}

/// The model ladder as an SVG string: one rung per model on a categorical x axis (labelled
/// by `rungs`), each channel's residual RMS / noise floor on a logarithmic y axis, and the
/// noise floor (1) drawn as a dashed line.
pub fn ladder(title: &str, y_label: &str, rungs: &[String], series: &[(String, Vec<f64>)]) -> String {
    let mut buf = String::new();
    let n = rungs.len().max(1);
    let positive = |v: &f64| v.is_finite() && *v > 0.0;
    let ys = series.iter().flat_map(|s| s.1.iter().copied()).chain([1.0]);
    let (y0, y1) = range(ys.filter(positive).map(f64::log10));
    let (y0, y1) = (10f64.powf(y0.min(-0.35)), 10f64.powf(y1.max(0.35)));
    let vertical = rungs.iter().map(String::len).sum::<usize>() > 70 || n > 7;
    let width = 760u32.max(90 * n as u32);
    let label_area = if vertical { 14 + 8 * rungs.iter().map(String::len).max().unwrap_or(4) as u32 } else { 44 };
    {
        let root = SVGBackend::with_string(&mut buf, (width, 340 + label_area)).into_drawing_area();
        let _ = root.fill(&WHITE);
        let mut b = builder(&root, title);
        b.x_label_area_size(label_area);
        let Ok(mut chart) = b.build_cartesian_2d(-0.5..n as f64 - 0.5, (y0..y1).log_scale()) else {
            return String::new();
        };
        let tick =
            if vertical { TICK_FONT.into_font().transform(FontTransform::Rotate90) } else { TICK_FONT.into_font() };
        let _ = chart
            .configure_mesh()
            .y_desc(y_label)
            .axis_desc_style(DESC_FONT)
            .y_label_style(TICK_FONT)
            .x_label_style(tick)
            .x_labels(n)
            .x_label_formatter(&|x| {
                let i = x.round();
                if (x - i).abs() < 1e-6 && i >= 0.0 {
                    rungs.get(i as usize).cloned().unwrap_or_default()
                } else {
                    String::new()
                }
            })
            .y_labels(12)
            .y_label_formatter(&|v| format!("{}", (v * 1000.0).round() / 1000.0))
            .light_line_style(WHITE)
            .draw();
        let grey = RGBColor(90, 90, 90);
        let dashes = (0..2 * n).map(|i| {
            let a = -0.5 + i as f64 * 0.5;
            PathElement::new(vec![(a, 1.0), (a + 0.3, 1.0)], grey.stroke_width(2))
        });
        if let Ok(s) = chart.draw_series(dashes) {
            s.label("noise floor (1)").legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 14, y)], grey));
        }
        for (i, (name, ys)) in series.iter().enumerate() {
            let c = COLORS[i % COLORS.len()];
            let pts: Vec<(f64, f64)> =
                ys.iter().enumerate().filter(|p| positive(p.1)).map(|(k, &y)| (k as f64, y)).collect();
            let _ = chart.draw_series(pts.iter().map(|&p| Circle::new(p, 3, c.filled())));
            if let Ok(s) = chart.draw_series(LineSeries::new(pts, c.stroke_width(2))) {
                s.label(name.as_str()).legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 14, y)], c));
            }
        }
        legend(&mut chart, SeriesLabelPosition::UpperRight);
        let _ = root.present();
    }
    buf
}
