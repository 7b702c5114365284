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

pub mod paper;

use crate::correct::Corrected;
use crate::estimate::QrAccumulator;
use crate::model::{SensorKind, AXES};
use crate::motion::{Conic, Track};
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

/// Upper `q` quantile of χ² with `k` degrees of freedom for q = 0.999 (Wilson–Hilferty:
/// χ² ≈ k (1 − 2/(9k) + z √(2/(9k)))³, z = 3.090).
fn chi2_999(k: usize) -> f64 {
    let k = k.max(1) as f64;
    let c = 2.0 / (9.0 * k);
    k * (1.0 - c + 3.090 * c.sqrt()).powi(3)
}

/// Systematic part of an error series: harmonic fit on the cone phase (conic runs) or
/// block means (others). Returns max |systematic| and whether it is significant, i.e.
/// whether the fitted systematic curve differs from zero beyond what the series' own white
/// noise explains (χ² test of all fitted coefficients at the 0.1 % level).
fn systematic(err: &[f64], t_s: &[f64], motion: &MotionSpec) -> (f64, bool) {
    let n = err.len();
    if n == 0 {
        return (0.0, false);
    }
    if let MotionSpec::Conic { cone_angle_deg, rate_deg_s, phase_deg } = motion {
        let c = Conic::from_deg(*cone_angle_deg, *rate_deg_s, *phase_deg);
        let p = 2 * HARMONICS + 1;
        if n > 4 * p && c.rate_rad_s != 0.0 {
            let basis = |th: f64, row: &mut [f64]| {
                row[0] = 1.0;
                for h in 1..=HARMONICS {
                    let (s, co) = (h as f64 * th).sin_cos();
                    row[2 * h - 1] = co;
                    row[2 * h] = s;
                }
            };
            let mut acc = QrAccumulator::new(p + 1, 4096);
            let mut row = vec![0.0; p + 1];
            for k in 0..n {
                basis(c.theta(t_s[k]), &mut row);
                row[p] = err[k];
                acc.push(&row);
            }
            let r = acc.r();
            let mut coef = vec![0.0; p];
            let mut ok = true;
            for i in (0..p).rev() {
                let mut s = r[(i, p)];
                for j in i + 1..p {
                    s -= r[(i, j)] * coef[j];
                }
                if r[(i, i)].abs() < 1e-300 {
                    ok = false;
                    break;
                }
                coef[i] = s / r[(i, i)];
            }
            if ok {
                let mut worst = 0.0_f64;
                for k in 0..n {
                    basis(c.theta(t_s[k]), &mut row);
                    let v: f64 = (0..p).map(|j| coef[j] * row[j]).sum();
                    worst = worst.max(v.abs());
                }
                // ‖R θ‖² = ‖Qᵀy‖² over the fitted part; residual variance from ρ².
                let explained: f64 = (0..p).map(|i| r[(i, p)] * r[(i, p)]).sum();
                let sigma2 = r[(p, p)] * r[(p, p)] / (n - p) as f64;
                let significant = explained > chi2_999(p) * sigma2;
                return (worst, significant);
            }
        }
    }
    let block = ((n as f64).sqrt().ceil() as usize).max(2);
    let mut worst = 0.0_f64;
    let (mut chi, mut within, mut dof, mut blocks) = (0.0, 0.0, 0usize, 0usize);
    for c in err.chunks(block) {
        let m = c.iter().sum::<f64>() / c.len() as f64;
        worst = worst.max(m.abs());
        chi += m * m * c.len() as f64;
        within += c.iter().map(|e| (e - m) * (e - m)).sum::<f64>();
        dof += c.len() - 1;
        blocks += 1;
    }
    let sigma2 = if dof > 0 { within / dof as f64 } else { 0.0 };
    (worst, chi > chi2_999(blocks) * sigma2)
}

fn stats(err: &[f64], t_s: &[f64], motion: &MotionSpec) -> ErrorStats {
    let n = err.len().max(1) as f64;
    let sys = systematic(err, t_s, motion);
    ErrorStats {
        max_abs: err.iter().map(|e| e.abs()).fold(0.0, f64::max),
        rms: (err.iter().map(|e| e * e).sum::<f64>() / n).sqrt(),
        sys_max_abs: sys.0,
        sys_significant: sys.1,
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
