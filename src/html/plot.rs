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

/// A tick label: up to four significant digits, never "-0" (a zero that rounding signed).
pub fn tick(v: f64) -> String {
    if v == 0.0 || !v.is_finite() {
        return "0".into();
    }
    let mag = v.abs().log10().floor() as i32;
    if !(-3..5).contains(&mag) {
        return format!("{v:.1e}");
    }
    let digits = (3 - mag).clamp(0, 6) as usize;
    let s = format!("{v:.digits$}");
    let s = if s.contains('.') { s.trim_end_matches('0').trim_end_matches('.').to_string() } else { s };
    if s.trim_start_matches('-').chars().all(|c| c == '0' || c == '.') {
        "0".into()
    } else {
        s
    }
}

/// A linear range with headroom above the data for the legend (share of the span).
fn with_headroom((lo, hi): (f64, f64), share: f64) -> (f64, f64) {
    (lo, hi + share * (hi - lo))
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
    // Room above the traces for the legend (a row per series), so that it hides none of them.
    let drawn = series.iter().filter(|s| !s.1.is_empty()).count();
    let (y0, y1) = if drawn > 1 { with_headroom((y0, y1), 0.2 + 0.17 * drawn as f64) } else { (y0, y1) };
    // A tick a rounding error away from zero is zero (not "6.9e-18").
    let snap = |v: f64, span: f64| if v.abs() < 1e-9 * span.abs() { 0.0 } else { v };
    let (xspan, yspan) = (x1 - x0, y1 - y0);
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
            .x_label_formatter(&|v| tick(snap(*v, xspan)))
            .y_label_formatter(&|v| tick(snap(*v, yspan)))
            .light_line_style(WHITE)
            .draw();
        for (i, (name, pts)) in series.iter().enumerate() {
            let c = COLORS[i % COLORS.len()];
            if pts.is_empty() {
                continue;
            }
            if let Ok(s) = chart.draw_series(LineSeries::new(pts.iter().copied(), c.stroke_width(1))) {
                s.label(name.as_str()).legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 14, y)], c));
            }
        }
        if drawn > 1 {
            legend(&mut chart, SeriesLabelPosition::UpperRight);
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
            .y_label_formatter(&|v| tick(*v))
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
    // Whole decades (every axis then carries labelled ticks), and a decade of headroom
    // above the traces for the legend.
    let (y0, y1) = (y0.floor(), y1.ceil() + 1.0);
    let (x0, x1, y0, y1) = (10f64.powf(x0), 10f64.powf(x1), 10f64.powf(y0), 10f64.powf(y1));
    {
        let root = SVGBackend::with_string(&mut buf, (720, 420)).into_drawing_area();
        let _ = root.fill(&WHITE);
        let Ok(mut chart) = builder(&root, title).build_cartesian_2d((x0..x1).log_scale(), (y0..y1).log_scale()) else {
            return String::new();
        };
        // plotters' log axis repeats the key point where two decades meet (a "10" drawn
        // twice on itself): a label equal to the one before it is left blank.
        let (last_x, last_y) = (std::cell::RefCell::new(String::new()), std::cell::RefCell::new(String::new()));
        let once = |last: &std::cell::RefCell<String>, t: String| {
            let mut l = last.borrow_mut();
            if *l == t {
                String::new()
            } else {
                l.clone_from(&t);
                t
            }
        };
        let _ = chart
            .configure_mesh()
            .x_desc(x_label)
            .y_desc(y_label)
            .axis_desc_style(DESC_FONT)
            .label_style(TICK_FONT)
            .y_labels(10)
            .y_label_formatter(&|v| once(&last_y, format!("{v:.0e}")))
            .x_label_formatter(&|v| once(&last_x, tick(*v)))
            .draw();
        let c0 = COLORS[0];
        let inside = |y: f64| y.clamp(y0, y1);
        if measured.is_empty() {
            // No legend entry for a trace that is not drawn.
        } else if let Ok(s) = chart.draw_series(
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
            if pts.is_empty() {
                continue;
            }
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
    // Headroom above for the legend (it then hides no marker).
    let (y0, y1) = (10f64.powf(y0.min(-0.35)), 10f64.powf(y1.max(0.35) + 0.25 * (y1.max(0.35) - y0.min(-0.35))));
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
        // Each channel a little to the side of the rung, so that channels at the same value
        // (all at the noise floor) stay visible side by side.
        let m = series.len().max(1) as f64;
        for (i, (name, ys)) in series.iter().enumerate() {
            let c = COLORS[i % COLORS.len()];
            let dx = (i as f64 - 0.5 * (m - 1.0)) * (0.5 / m).min(0.08);
            let pts: Vec<(f64, f64)> =
                ys.iter().enumerate().filter(|p| positive(p.1)).map(|(k, &y)| (k as f64 + dx, y)).collect();
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

/// A tick label of `v` on an axis whose ticks are `step` apart: as many decimals as the
/// step needs and no more (`0.25`, `12`, `-0.004`), exponent form outside 1e-3..1e5, so
/// neighbouring labels differ and stay short.
pub fn tick_label(v: f64, step: f64) -> String {
    let mag = v.abs().max(step.abs());
    if v == 0.0 {
        return "0".into();
    }
    if !(1e-3..1e5).contains(&mag) {
        let digits = ((mag / step.abs().max(f64::MIN_POSITIVE)).log10().ceil().max(0.0) as usize).min(6);
        return format!("{v:.digits$e}");
    }
    let decimals = (-(step.abs().log10().floor())).max(0.0) as usize;
    format!("{v:.decimals$}")
}

/// A round step (1, 2 or 5 × 10ⁿ) giving at most `max_ticks` ticks over `span`.
fn nice_step(span: f64, max_ticks: usize) -> f64 {
    let raw = span / max_ticks.max(1) as f64;
    let p = 10f64.powf(raw.log10().floor());
    [1.0, 2.0, 5.0, 10.0].iter().map(|m| m * p).find(|s| *s >= raw).unwrap_or(10.0 * p)
}

/// A histogram of `values` (x in the quantity's unit, named in `x_label`) with vertical
/// lines at named `limits`, as an SVG string: at most 7 x ticks at round values labelled
/// with the decimals their step needs, counts on an integer axis.
pub fn histogram(title: &str, x_label: &str, values: &[f64], limits: &[(String, f64)]) -> String {
    let mut buf = String::new();
    let finite: Vec<f64> = values.iter().copied().filter(|v| v.is_finite()).collect();
    let (vlo, vhi) = range(finite.iter().copied());
    let bins = ((finite.len() as f64).log2().ceil() as usize + 1).clamp(5, 20);
    let width = (vhi - vlo) / bins as f64;
    let mut counts = vec![0i32; bins];
    for v in &finite {
        counts[(((v - vlo) / width) as usize).min(bins - 1)] += 1;
    }
    let (x0, x1) = range(finite.iter().copied().chain(limits.iter().map(|l| l.1)));
    let step = nice_step(x1 - x0, 6);
    let ymax = counts.iter().copied().max().unwrap_or(1).max(1) + 1;
    {
        let root = SVGBackend::with_string(&mut buf, (720, 260)).into_drawing_area();
        let _ = root.fill(&WHITE);
        let Ok(mut chart) = builder(&root, title).build_cartesian_2d(x0..x1, 0..ymax) else {
            return String::new();
        };
        let ticks = ((x1 - x0) / step).floor() as usize + 1;
        let _ = chart
            .configure_mesh()
            .x_desc(x_label)
            .y_desc("number of units (count)")
            .axis_desc_style(DESC_FONT)
            .label_style(TICK_FONT)
            .x_labels(ticks.min(7))
            .x_label_formatter(&|x| tick_label(*x, step))
            .y_labels((ymax as usize + 1).min(6))
            .y_label_formatter(&|y| y.to_string())
            .light_line_style(WHITE)
            .draw();
        let _ = chart.draw_series(counts.iter().enumerate().filter(|(_, &c)| c > 0).map(|(i, &c)| {
            let a = vlo + i as f64 * width;
            Rectangle::new([(a + 0.04 * width, 0), (a + 0.96 * width, c)], COLORS[0].filled())
        }));
        for (i, (name, x)) in limits.iter().enumerate() {
            let c = COLORS[(3 + i) % COLORS.len()];
            let line = PathElement::new(vec![(*x, 0), (*x, ymax)], c.stroke_width(2));
            if let Ok(s) = chart.draw_series(std::iter::once(line)) {
                s.label(name.as_str()).legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 14, y)], c));
            }
        }
        if !limits.is_empty() {
            legend(&mut chart, SeriesLabelPosition::UpperRight);
        }
        let _ = root.present();
    }
    buf
}

/// A control chart as an SVG string: each lot's mean (points, lots numbered 1, 2, … in
/// time order) with ±1 standard deviation bars, and the lower and upper limits each lot is
/// judged against (from the lots before it); a lot out of control is drawn in red.
pub fn control_chart(title: &str, y_label: &str, lots: &[(f64, f64, Option<[f64; 2]>, bool)]) -> String {
    let mut buf = String::new();
    let n = lots.len().max(1);
    let ys =
        lots.iter().flat_map(|l| [l.0 - l.1, l.0 + l.1]).chain(lots.iter().flat_map(|l| l.2.into_iter().flatten()));
    let (y0, y1) = range(ys);
    let step = nice_step(y1 - y0, 6);
    {
        let root = SVGBackend::with_string(&mut buf, (720, 260)).into_drawing_area();
        let _ = root.fill(&WHITE);
        let Ok(mut chart) = builder(&root, title).build_cartesian_2d(0.5..n as f64 + 0.5, y0..y1) else {
            return String::new();
        };
        let _ = chart
            .configure_mesh()
            .x_desc("lot (in time order)")
            .y_desc(y_label)
            .axis_desc_style(DESC_FONT)
            .label_style(TICK_FONT)
            .x_labels(n.min(8))
            .x_label_formatter(&|x| if (x - x.round()).abs() < 1e-6 { format!("{}", x.round()) } else { String::new() })
            .y_labels(7)
            .y_label_formatter(&|y| tick_label(*y, step))
            .light_line_style(WHITE)
            .draw();
        let grey = RGBColor(90, 90, 90);
        for side in 0..2 {
            let pts: Vec<(f64, f64)> = lots
                .iter()
                .enumerate()
                .filter_map(|(i, l)| l.2.map(|b| (i as f64 + 1.0, b[side])))
                .flat_map(|(x, y)| [(x - 0.4, y), (x + 0.4, y), (f64::NAN, f64::NAN)])
                .collect();
            let segs: Vec<Vec<(f64, f64)>> =
                pts.split(|p| p.0.is_nan()).filter(|s| !s.is_empty()).map(<[_]>::to_vec).collect();
            let drawn = chart.draw_series(segs.into_iter().map(|s| PathElement::new(s, grey.stroke_width(2))));
            if side == 0 {
                if let Ok(s) = drawn {
                    s.label("limits from the earlier lots")
                        .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 14, y)], grey));
                }
            }
        }
        let _ = chart.draw_series(lots.iter().enumerate().map(|(i, l)| {
            let c = if l.3 { COLORS[3] } else { COLORS[0] };
            ErrorBar::new_vertical(i as f64 + 1.0, l.0 - l.1, l.0, l.0 + l.1, c.filled(), 8)
        }));
        legend(&mut chart, SeriesLabelPosition::UpperLeft);
        let _ = root.present();
    }
    buf
}

#[cfg(test)]
mod tests {
    use super::tick;

    #[test]
    fn ticks_never_show_a_signed_zero_and_keep_four_digits() {
        assert_eq!(tick(-0.0), "0");
        assert_eq!(tick(-1e-12), "-1.0e-12");
        assert_eq!(tick(-0.00004), "-4.0e-5");
        assert_eq!(tick(0.25), "0.25");
        assert_eq!(tick(-2.5), "-2.5");
        assert_eq!(tick(123.456), "123.5");
        assert_eq!(tick(12345.0), "12345");
        assert_eq!(tick(2.0e6), "2.0e6");
        assert_eq!(tick(f64::NAN), "0");
    }
}
