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
        "{:<4} {:>13} {:>13} {:>13} {:>10} {:>13} {:>13}",
        "chan", "white /√Hz", "ARW/VRW", "bias inst.", "at τ (s)", "random walk", "quantisation"
    );
    for c in &r.channels {
        let (_, k) = c.sensor().display_unit();
        let (w, walk) = match c.white_display(g_m_s2) {
            Some((a, b)) => (format!("{a:.4e}"), format!("{b:.4e}")),
            None => ("-".into(), "-".into()),
        };
        let bias = match c.sensor() {
            SensorKind::Gyro => c.bias_instability.map(|b| b * k * 3600.0),
            SensorKind::Accel => c.bias_instability.map(|b| b / g_m_s2 * 1e6),
        };
        let rw = match c.sensor() {
            SensorKind::Gyro => c.random_walk.map(|v| v * k * 3600.0 * 60.0),
            SensorKind::Accel => c.random_walk,
        };
        let _ = writeln!(
            s,
            "{:<4} {:>13} {:>13} {:>13} {:>10} {:>13} {:>13}",
            c.channel,
            w,
            walk,
            opt(bias, 4),
            c.bias_instability_tau_s.map_or("-".into(), |t| format!("{t:.3}")),
            opt(rw, 4),
            opt(c.quantization.map(|q| q * k), 3)
        );
    }
    let _ = writeln!(
        s,
        "units: gyro white °/s/√Hz, ARW °/√h, bias instability °/h, rate random walk °/h/√h, quantisation °;\n       \
         accel white µg/√Hz, VRW m/s/√h, bias instability µg, random walk m/s²/√s, quantisation m/s"
    );
    s
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
            series.push(("bias instability (0.664 B)".into(), curve(&|_| b * FLAT)));
        }
        if let Some(w) = c.random_walk {
            series.push(("random walk (slope +½)".into(), curve(&|t| w * (t / 3.0).sqrt())));
        }
        if let Some(q) = c.quantization {
            series.push(("quantisation (slope −1)".into(), curve(&|t| 3f64.sqrt() * q / t)));
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
