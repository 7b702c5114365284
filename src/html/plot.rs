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
    b.caption(title, ("sans-serif", 15)).margin(8).x_label_area_size(32).y_label_area_size(70);
    b
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
        let _ = chart.configure_mesh().x_desc(x_label).y_desc(y_label).light_line_style(WHITE).draw();
        for (i, (name, pts)) in series.iter().enumerate() {
            let c = COLORS[i % COLORS.len()];
            if let Ok(s) = chart.draw_series(LineSeries::new(pts.iter().copied(), c.stroke_width(1))) {
                s.label(name.as_str()).legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 14, y)], c));
            }
        }
        if series.len() > 1 {
            let _ = chart.configure_series_labels().background_style(WHITE.mix(0.8)).border_style(BLACK).draw();
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
        let _ =
            chart.configure_mesh().x_desc(x_label).y_desc(y_label).y_label_formatter(&|v| format!("{v:.1e}")).draw();
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
        let _ = chart.configure_series_labels().background_style(WHITE.mix(0.8)).border_style(BLACK).draw();
        let _ = root.present();
    }
    buf
}
