//! Noise results as a text table and as a self-contained HTML page with one log-log Allan
//! deviation plot per channel (measured points with intervals, fitted curve, slope lines).

use super::{NoiseReport, FLAT};
use crate::html::plot::loglog;
use crate::html::{esc, page_start, slug, Figure};
use crate::units::SensorKind;
use std::fmt::Write;

fn opt(v: Option<f64>, digits: usize) -> String {
    v.map_or_else(|| "-".to_string(), |v| format!("{v:.digits$e}"))
}

/// One row per channel: the noise terms in engineering units.
pub fn table(r: &NoiseReport, g_m_s2: f64) -> String {
    let mut s = String::new();
    let _ = writeln!(
        s,
        "noise of {} ({} samples at {:.6} s; terms shown where they dominate the Allan deviation somewhere)",
        r.source, r.n_samples, r.sample_interval_s
    );
    let _ = writeln!(
        s,
        "{:<4} {:>13} {:>13} {:>13} {:>10} {:>13} {:>13} {:>13}",
        "chan", "white /√Hz", "ARW/VRW", "BI reading", "at τ (s)", "BI model fit", "random walk", "quantisation"
    );
    for c in &r.channels {
        let (_, k) = c.sensor().display_unit();
        let (w, walk) = match c.white_display(g_m_s2) {
            Some((a, b)) => (format!("{a:.4e}"), format!("{b:.4e}")),
            None => ("-".into(), "-".into()),
        };
        let bi = |b: f64| match c.sensor() {
            SensorKind::Gyro => b * k * 3600.0,
            SensorKind::Accel => b / g_m_s2 * 1e6,
        };
        let bias = c.bias_instability.map(bi);
        let reading = c.bias_instability_reading.map(|r| r.value).map(bi);
        let rw = match c.sensor() {
            SensorKind::Gyro => c.random_walk.map(|v| v * k * 3600.0 * 60.0),
            SensorKind::Accel => c.random_walk,
        };
        let _ = writeln!(
            s,
            "{:<4} {:>13} {:>13} {:>13} {:>10} {:>13} {:>13} {:>13}",
            c.channel,
            w,
            walk,
            opt(reading, 4),
            c.bias_instability_reading.map_or("-".into(), |r| format!("{:.3}", r.tau_s)),
            opt(bias, 4),
            opt(rw, 4),
            opt(c.quantization.map(|q| q * k), 3)
        );
    }
    for c in &r.channels {
        if let Some(rd) = c.bias_instability_reading {
            let (_, k) = c.sensor().display_unit();
            let f = |b: f64| match c.sensor() {
                SensorKind::Gyro => b * k * 3600.0,
                SensorKind::Accel => b / g_m_s2 * 1e6,
            };
            let _ = writeln!(
                s,
                "{}: bias instability reading {:.4e} (68 % interval {:.4e}–{:.4e}) at τ = {:.3} s",
                c.channel,
                f(rd.value),
                f(rd.low),
                f(rd.high),
                rd.tau_s
            );
        }
        if let Some(rd) = c.white_density_reading {
            let (u, f) = match c.sensor() {
                SensorKind::Gyro => ("°/s/√Hz", 1f64.to_degrees()),
                SensorKind::Accel => ("µg/√Hz", 1e6 / g_m_s2),
            };
            let _ = writeln!(
                s,
                "{}: white-noise reading {:.4e} {u} (68 % interval {:.4e}–{:.4e}) at τ = {:.3} s, where the curve runs at slope −½{}",
                c.channel,
                rd.value * f,
                rd.low * f,
                rd.high * f,
                rd.tau_s,
                match c.white_density {
                    Some(n) if n < rd.low || n > rd.high => format!(
                        "; the model's {:.4e} differs from it (the curve's knee is rounder than the five terms)",
                        n * f
                    ),
                    _ => String::new(),
                }
            );
        }
        if let Some(r) = c.ramp {
            let (v, u) = match c.sensor() {
                SensorKind::Gyro => (r.to_degrees() * 3600.0 * 3600.0, "°/h/h"),
                SensorKind::Accel => (r / g_m_s2 * 1e6 * 3600.0, "µg/h"),
            };
            let _ = writeln!(
                s,
                "{}: rate ramp {v:.4e} {u} (the model's slope +1 at long τ: a drift over the recording, to which \
                 --deviation hadamard is blind)",
                c.channel
            );
        }
        if c.bias_instability.is_some() && c.bias_instability_reading.is_none() {
            let last = c.points.iter().filter(|p| p.edf >= super::READING_EDF).map(|p| p.tau_s).fold(0.0, f64::max);
            let _ = writeln!(
                s,
                "{}: no bias instability reading: the measured curve has no minimum among its well-determined points \
                 (≥ 50 degrees of freedom, τ ≤ {last:.3} s); the model fit's value is an extrapolation: record longer",
                c.channel
            );
        }
        for d in &c.departures {
            let _ = writeln!(s, "{}: {}", c.channel, d.describe());
        }
    }
    other_table(&mut s, r);
    let _ = writeln!(
        s,
        "BI reading: the curve's measured minimum / 0.664 (IEEE 952 C.1.3, the standard reading); BI model fit: the flat\n\
         floor of the fitted five-term model (they agree when the model follows the curve)\n\
         units: gyro white °/s/√Hz, ARW °/√h, bias instability °/h, rate random walk °/h/√h, quantisation °;\n       \
         accel white µg/√Hz, VRW m/s/√h, bias instability µg, random walk m/s²/√s, quantisation m/s"
    );
    s
}

/// The Hadamard or modified Allan deviation, when computed: one row per fourfold cluster
/// time, one column per channel (display units, ± the 68 % interval's half-width in %).
fn other_table(s: &mut String, r: &NoiseReport) {
    let Some(first) = r.channels.iter().find_map(|c| c.other.as_ref()) else { return };
    let _ = writeln!(
        s,
        "{} (gyro °/s, accel m/s²; ± half the 68 % interval, from its equivalent degrees of freedom):",
        first.deviation.label()
    );
    let _ = write!(s, "{:>10}", "τ (s)");
    for c in &r.channels {
        let _ = write!(s, " {:>18}", c.channel);
    }
    s.push('\n');
    let tau0 = r.sample_interval_s;
    for (k, p) in first.points.iter().enumerate() {
        let m = (p.tau_s / tau0).round() as u64;
        if !(m.is_power_of_two() && m.trailing_zeros() % 2 == 0) && k + 1 != first.points.len() {
            continue;
        }
        let _ = write!(s, "{:>10.3}", p.tau_s);
        for c in &r.channels {
            let (_, f) = c.sensor().display_unit();
            let cell =
                c.other.as_ref().and_then(|o| o.points.get(k)).map_or("-".to_string(), |q| {
                    format!("{:.4e} ±{:.1}%", q.adev * f, 50.0 * (q.high - q.low) / q.adev)
                });
            let _ = write!(s, " {cell:>18}");
        }
        s.push('\n');
    }
}

/// The HTML page: the table, then one Allan deviation plot per channel.
pub fn html(r: &NoiseReport, g_m_s2: f64) -> String {
    let mut s = page_start(&format!("crosscal noise: {}", r.source));
    let _ = write!(s, "<pre>{}</pre>", esc(&table(r, g_m_s2)));
    for (c, f) in r.channels.iter().zip(figures(r)) {
        let _ = write!(s, "<h2>{}</h2>", esc(&c.channel));
        s.push_str(&f.svg);
    }
    s.push_str("</body></html>\n");
    s
}

/// One log-log Allan deviation plot per channel: measured points with their intervals, the
/// fitted curve and the slope line of each term found.
pub fn figures(r: &NoiseReport) -> Vec<Figure> {
    let mut out = Vec::with_capacity(r.channels.len());
    for c in &r.channels {
        let (u, k) = c.sensor().display_unit();
        let measured: Vec<(f64, f64, f64, f64)> =
            c.points.iter().map(|p| (p.tau_s, p.low * k, p.adev * k, p.high * k)).collect();
        let taus: Vec<f64> = c.points.iter().map(|p| p.tau_s).collect();
        let curve = |f: &dyn Fn(f64) -> f64| -> Vec<(f64, f64)> {
            let (a, b) = (taus.first().copied().unwrap_or(1.0).ln(), taus.last().copied().unwrap_or(1.0).ln());
            (0..=100).map(|i| (a + (b - a) * i as f64 / 100.0).exp()).map(|t| (t, f(t) * k)).collect()
        };
        let mut series = vec![("fitted".to_string(), curve(&|t| c.model_adev(t)))];
        if let Some(n) = c.white_density {
            series.push(("white noise (slope −½)".into(), curve(&|t| n / t.sqrt())));
        }
        if let Some(b) = c.bias_instability {
            series.push(("bias instability, model fit (0.664 B)".into(), curve(&|_| b * FLAT)));
        }
        if let Some(r) = c.bias_instability_reading {
            series.push(("bias instability, reading (measured minimum)".into(), curve(&|_| r.value * FLAT)));
        }
        if let Some(w) = c.random_walk {
            series.push(("random walk (slope +½)".into(), curve(&|t| w * (t / 3.0).sqrt())));
        }
        if let Some(q) = c.quantization {
            series.push(("quantisation (slope −1)".into(), curve(&|t| 3f64.sqrt() * q / t)));
        }
        if let Some(o) = &c.other {
            let points: Vec<(f64, f64, f64, f64)> =
                o.points.iter().map(|p| (p.tau_s, p.low * k, p.adev * k, p.high * k)).collect();
            let allan: Vec<(f64, f64)> = c.points.iter().map(|p| (p.tau_s, p.adev * k)).collect();
            let stem = match o.deviation {
                super::deviations::Deviation::Hadamard => "hdev",
                _ => "mdev",
            };
            out.push(Figure {
                stem: format!("{}-{stem}", slug(&c.channel)),
                svg: loglog(
                    &format!("{}: {}", c.channel, o.deviation.label()),
                    "cluster time τ (s)",
                    &format!("{} ({u})", o.deviation.label()),
                    &points,
                    &[("Allan deviation (measured)".to_string(), allan)],
                ),
            });
        }
        out.push(Figure {
            stem: format!("{}-adev", slug(&c.channel)),
            svg: loglog(
                &format!("{}: overlapping Allan deviation", c.channel),
                "cluster time τ (s)",
                &format!("Allan deviation ({u})"),
                &measured,
                &series,
            ),
        });
    }
    out
}
