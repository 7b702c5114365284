//! Narrow-band lines over a session: the lines each run's noise shows, grouped by channel
//! and frequency, and classified as locked to the cone (the same multiple of each run's
//! cone frequency — something the motion excites) or not (a resonance, vibration or mains
//! pick-up: no effect of the motion explains it).

use super::space::RunGram;
use crate::units::{SensorKind, AXES};
use serde::{Deserialize, Serialize};

/// A line in the residual's spectrum.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Line {
    /// Sensor.
    pub sensor: SensorKind,
    /// Axis.
    pub axis: char,
    /// Frequency, Hz (mean over the runs where it is unlocked; for a locked line the
    /// frequency in the run where it is largest).
    pub frequency_hz: f64,
    /// Largest amplitude over the runs, SI.
    pub amplitude: f64,
    /// Peak power over the continuum of the spectrum, largest over the runs.
    pub ratio: f64,
    /// For a line locked to the cone: the harmonic of the cone frequency.
    pub cone_harmonic: Option<usize>,
    /// The runs that show it.
    pub runs: Vec<String>,
}

impl Line {
    /// The line in words.
    pub fn describe(&self) -> String {
        let (u, k) = self.sensor.display_unit();
        let lock = match self.cone_harmonic {
            Some(h) => format!("locked to the cone (harmonic {h})"),
            None => "not locked to the cone".to_string(),
        };
        format!(
            "{} {}: a narrow line at {:.3} Hz, amplitude {:.3e} {u}, {:.0}× the noise continuum, {lock}, in runs {}",
            self.sensor.as_str(),
            self.axis,
            self.frequency_hz,
            self.amplitude * k,
            self.ratio,
            self.runs.join(", ")
        )
    }
}

/// Highest cone harmonic a line can be locked to.
const MAX_LOCKED_HARMONIC: f64 = 40.0;

/// Groups the runs' lines. Two lines in different runs are one when their frequencies
/// differ by less than `tol_hz` (unlocked) or they sit on the same cone harmonic.
pub fn group(runs: &[RunGram], names: &[&str], tol_hz: f64) -> Vec<Line> {
    let mut out: Vec<(Line, usize)> = Vec::new();
    for (ri, rg) in runs.iter().enumerate() {
        for l in &rg.lines {
            let sensor = if l.channel < 3 { SensorKind::Gyro } else { SensorKind::Accel };
            let axis = AXES[l.channel % 3];
            // Locked when within a quarter of the cone frequency (and the record's
            // resolution) of a low cone harmonic: any frequency is near some high harmonic
            // of a slow cone.
            let harmonic = rg.cone_hz.and_then(|fc| {
                let h = (l.frequency_hz / fc).round();
                let near = (l.frequency_hz - h * fc).abs() < (0.25 * fc).min(tol_hz);
                ((1.0..=MAX_LOCKED_HARMONIC).contains(&h) && near).then_some(h as usize)
            });
            let same = out.iter_mut().find(|(g, _)| {
                g.sensor == sensor
                    && g.axis == axis
                    && match (g.cone_harmonic, harmonic) {
                        (Some(a), Some(b)) => a == b,
                        (None, None) => (g.frequency_hz - l.frequency_hz).abs() < tol_hz,
                        _ => false,
                    }
            });
            match same {
                Some((g, count)) => {
                    if harmonic.is_none() {
                        g.frequency_hz = (g.frequency_hz * *count as f64 + l.frequency_hz) / (*count + 1) as f64;
                    } else if l.amplitude > g.amplitude {
                        g.frequency_hz = l.frequency_hz;
                    }
                    *count += 1;
                    g.amplitude = g.amplitude.max(l.amplitude);
                    g.ratio = g.ratio.max(l.ratio);
                    if !g.runs.iter().any(|r| r == names[ri]) {
                        g.runs.push(names[ri].to_string());
                    }
                }
                None => out.push((
                    Line {
                        sensor,
                        axis,
                        frequency_hz: l.frequency_hz,
                        amplitude: l.amplitude,
                        ratio: l.ratio,
                        cone_harmonic: harmonic,
                        runs: vec![names[ri].to_string()],
                    },
                    1,
                )),
            }
        }
    }
    let mut lines: Vec<Line> = out.into_iter().map(|(l, _)| l).collect();
    lines.sort_by(|a, b| b.ratio.total_cmp(&a.ratio));
    lines
}
