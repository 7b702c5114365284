//! Checking a calibration against the reference motion: errors before and after
//! correction per run and axis, as the paper states them (max |error| as a percentage of
//! the axis's reference amplitude) and as RMS, reduction factors, and pass/fail against
//! thresholds (paper defaults: gyro ≥ 30×, accelerometer ≥ 40,000×).
//!
//! White noise floors a raw max-error ratio, so each error series is also split into its
//! systematic part: for conic runs a least-squares fit of the first [`HARMONICS`] harmonics
//! of the cone phase θ (plus a constant), for other runs block means. The reduction of the
//! systematic part is what the pass/fail decision uses; on noiseless data it equals the
//! raw reduction. An axis whose corrected error has no systematic part distinguishable
//! from its white noise in any run (χ² test at 0.1 %) is reported as noise-limited and
//! passes: the data cannot show a remaining error.

pub mod harmonics;
pub mod paper;

use crate::correct::Corrected;
use crate::model::{SensorKind, AXES};
use crate::motion::Track;
use crate::session::{MotionSpec, Run};
use serde::{Deserialize, Serialize};

/// Harmonics of the cone phase in the systematic-error fit.
pub const HARMONICS: usize = 4;

/// Pass thresholds.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Thresholds {
    /// Minimum gyro reduction factor (paper: 30).
    pub gyro_min_reduction: f64,
    /// Minimum accelerometer reduction factor (paper: 40,000).
    pub accel_min_reduction: f64,
}

impl Default for Thresholds {
    fn default() -> Self {
        Self { gyro_min_reduction: 30.0, accel_min_reduction: 40_000.0 }
    }
}

impl Thresholds {
    /// Threshold for a sensor.
    pub fn for_sensor(&self, s: SensorKind) -> f64 {
        match s {
            SensorKind::Gyro => self.gyro_min_reduction,
            SensorKind::Accel => self.accel_min_reduction,
        }
    }
}

/// Error statistics of one series (SI units, percentages of the axis amplitude).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct ErrorStats {
    /// max |error|.
    pub max_abs: f64,
    /// RMS error.
    pub rms: f64,
    /// max |systematic error|.
    pub sys_max_abs: f64,
    /// Whether the systematic part is significant against the series' white noise.
    pub sys_significant: bool,
}

/// One axis of one sensor in one run.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct AxisCheck {
    /// Sensor.
    pub sensor: SensorKind,
    /// Axis letter.
    pub axis: char,
    /// Reference amplitude max |true| (SI).
    pub amplitude: f64,
    /// Error of the raw output (None for raw-unit sessions).
    pub before: Option<ErrorStats>,
    /// Error after correction.
    pub after: ErrorStats,
}

impl AxisCheck {
    /// `100 · x / amplitude`, or None when the axis is not excited.
    pub fn pct(&self, x: f64) -> Option<f64> {
        (self.amplitude > 0.0).then(|| 100.0 * x / self.amplitude)
    }
}

/// One run's check.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RunCheck {
    /// Run name.
    pub run: String,
    /// Leading samples left out (streaming warm-up).
    pub skipped: usize,
    /// Six axes: gyro x, y, z then accel x, y, z.
    pub axes: Vec<AxisCheck>,
}

/// Summary of one sensor axis over all runs.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct AxisSummary {
    /// Sensor.
    pub sensor: SensorKind,
    /// Axis letter.
    pub axis: char,
    /// Largest before-correction error over runs, % of amplitude.
    pub before_pct: Option<f64>,
    /// Largest after-correction error over runs, % of amplitude.
    pub after_pct: Option<f64>,
    /// before / after (raw).
    pub reduction: Option<f64>,
    /// Largest systematic error before, % of amplitude.
    pub before_sys_pct: Option<f64>,
    /// Largest systematic error after, % of amplitude.
    pub after_sys_pct: Option<f64>,
    /// before / after (systematic): the pass criterion.
    pub reduction_sys: Option<f64>,
    /// No run's corrected error has a systematic part distinguishable from its noise: the
    /// check cannot resolve any remaining error, so the axis passes whatever the ratio.
    pub noise_limited: bool,
    /// Reduction needed.
    pub threshold: f64,
    /// Whether this axis passes.
    pub pass: bool,
}

/// A full check.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CheckReport {
    /// Per run.
    pub runs: Vec<RunCheck>,
    /// Per sensor axis.
    pub summary: Vec<AxisSummary>,
    /// Thresholds used.
    pub thresholds: Thresholds,
    /// All axes pass.
    pub pass: bool,
}

fn stats(err: &[f64], t_s: &[f64], motion: &MotionSpec) -> ErrorStats {
    let n = err.len().max(1) as f64;
    let sys = harmonics::systematic(err, t_s, motion, HARMONICS);
    ErrorStats {
        max_abs: err.iter().map(|e| e.abs()).fold(0.0, f64::max),
        rms: (err.iter().map(|e| e * e).sum::<f64>() / n).sqrt(),
        sys_max_abs: sys.max_abs(),
        sys_significant: sys.significant(),
    }
}

/// Checks one run: `corrected` is the correction of `run`'s outputs, `track` its true motion.
/// The corrector's warm-up samples (streaming) are left out of both before and after.
pub fn check_run(run: &Run, track: &Track, corrected: &Corrected, raw_units: [bool; 2]) -> RunCheck {
    let mut axes = Vec::with_capacity(6);
    let skip = corrected.warmup.min(track.t_s.len());
    let t_s = &track.t_s[skip..];
    let n = t_s.len();
    let mut before = vec![0.0; n];
    let mut after = vec![0.0; n];
    for (si, sensor) in SensorKind::BOTH.iter().enumerate() {
        let (truth, out, corr) = match sensor {
            SensorKind::Gyro => (&track.w_rad_s, &run.rec.gyro, &corrected.w_rad_s),
            SensorKind::Accel => (&track.a_m_s2, &run.rec.accel, &corrected.a_m_s2),
        };
        for i in 0..3 {
            let mut amp = 0.0_f64;
            for k in 0..n {
                let kk = k + skip;
                amp = amp.max(truth[kk][i].abs());
                before[k] = out[kk][i] - truth[kk][i];
                after[k] = corr[kk][i] - truth[kk][i];
            }
            axes.push(AxisCheck {
                sensor: *sensor,
                axis: AXES[i],
                amplitude: amp,
                before: (!raw_units[si]).then(|| stats(&before, t_s, &run.spec.motion)),
                after: stats(&after, t_s, &run.spec.motion),
            });
        }
    }
    RunCheck { run: run.spec.name.clone(), skipped: skip, axes }
}

fn ratio(a: Option<f64>, b: Option<f64>) -> Option<f64> {
    match (a, b) {
        (Some(a), Some(b)) if b > 0.0 => Some(a / b),
        (Some(a), Some(_)) if a > 0.0 => Some(f64::INFINITY),
        _ => None,
    }
}

/// Summarises run checks per sensor axis and applies the thresholds.
pub fn summarize(runs: Vec<RunCheck>, thresholds: Thresholds) -> CheckReport {
    let mut summary = Vec::with_capacity(6);
    for idx in 0..6 {
        let Some(first) = runs.first().map(|r| &r.axes[idx]) else {
            break;
        };
        let (sensor, axis) = (first.sensor, first.axis);
        let maxo = |f: &dyn Fn(&AxisCheck) -> Option<f64>| {
            runs.iter()
                .filter_map(|r| f(&r.axes[idx]))
                .fold(None, |acc: Option<f64>, v| Some(acc.map_or(v, |a| a.max(v))))
        };
        let before_pct = maxo(&|a| a.before.and_then(|b| a.pct(b.max_abs)));
        let after_pct = maxo(&|a| a.pct(a.after.max_abs));
        let before_sys_pct = maxo(&|a| a.before.and_then(|b| a.pct(b.sys_max_abs)));
        let after_sys_pct = maxo(&|a| a.pct(a.after.sys_max_abs));
        let reduction = ratio(before_pct, after_pct);
        let reduction_sys = ratio(before_sys_pct, after_sys_pct);
        let threshold = thresholds.for_sensor(sensor);
        let noise_limited = runs.iter().all(|r| !r.axes[idx].after.sys_significant);
        let pass = noise_limited || reduction_sys.is_none_or(|r| r >= threshold);
        summary.push(AxisSummary {
            sensor,
            axis,
            before_pct,
            after_pct,
            reduction,
            before_sys_pct,
            after_sys_pct,
            reduction_sys,
            noise_limited,
            threshold,
            pass,
        });
    }
    let pass = summary.iter().all(|s| s.pass);
    CheckReport { runs, summary, thresholds, pass }
}
