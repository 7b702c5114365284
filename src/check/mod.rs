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
//! from its white noise (one χ² test pooled over all runs, at 0.001 %) is reported as
//! noise-limited and passes: the data cannot show a remaining error.

pub mod guarded;
mod names;
pub mod paper;
pub mod rules;

use crate::correct::Corrected;
use crate::motion::Track;
use crate::profile::AxisSummary;
use crate::session::{MotionSpec, Run};
use crate::units::{SensorKind, AXES};
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
    /// χ² statistic of the systematic fit (explained sum of squares / noise variance).
    #[serde(default)]
    pub sys_chi2: f64,
    /// Its degrees of freedom.
    #[serde(default)]
    pub sys_dof: usize,
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
    /// Samples outside the profile's calibrated temperature range, in words (the correction
    /// held the temperature terms at the edge): this run checks the profile where it was
    /// not calibrated.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub temperature_outside: Option<String>,
    /// The corrected error by temperature: one bin per whole degree the run's samples read,
    /// centred on it (empty without temperatures).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub temp_bins: Vec<TempBin>,
}

/// The corrected error of the samples whose temperature reads within half a degree of
/// `centre_c` (in [centre − 0.5, centre + 0.5) °C): what the calibration leaves at that
/// temperature (for `accept`'s `max_residual`). Centred on whole degrees, a plateau at a
/// whole-degree set point falls in one bin whatever its reading noise.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TempBin {
    /// Centre, °C (a whole degree).
    pub centre_c: f64,
    /// Samples per axis (gyro x, y, z, accel x, y, z).
    pub n: [u64; 6],
    /// Mean corrected error per axis, SI.
    pub mean: [f64; 6],
    /// RMS corrected error per axis, SI.
    pub rms: [f64; 6],
}

/// Samples, sums and sums of squares of the corrected error per axis.
#[derive(Default)]
struct Sums {
    n: [u64; 6],
    sum: [f64; 6],
    sq: [f64; 6],
}

/// Accumulates errors by whole degree of temperature.
#[derive(Default)]
struct Bins(std::collections::BTreeMap<i64, Sums>);

impl Bins {
    fn add(&mut self, temp_c: f64, axis: usize, err: f64) {
        if temp_c.is_finite() && err.is_finite() {
            let b = self.0.entry((temp_c + 0.5).floor() as i64).or_default();
            b.n[axis] += 1;
            b.sum[axis] += err;
            b.sq[axis] += err * err;
        }
    }

    fn finish(self) -> Vec<TempBin> {
        self.0
            .into_iter()
            .map(|(centre, b)| {
                let per = |v: [f64; 6]| std::array::from_fn(|i| if b.n[i] > 0 { v[i] / b.n[i] as f64 } else { 0.0 });
                TempBin { centre_c: centre as f64, n: b.n, mean: per(b.sum), rms: per(b.sq).map(f64::sqrt) }
            })
            .collect()
    }
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
    let sys = crate::stats::systematic(err, t_s, crate::motion::cone_phase(motion), HARMONICS);
    ErrorStats {
        max_abs: err.iter().map(|e| e.abs()).fold(0.0, f64::max),
        rms: (err.iter().map(|e| e * e).sum::<f64>() / n).sqrt(),
        sys_max_abs: sys.max_abs(),
        sys_significant: sys.significant(),
        sys_chi2: if sys.sigma2 > 0.0 { sys.explained / sys.sigma2 } else { 0.0 },
        sys_dof: sys.params,
    }
}

/// Checks one run: `corrected` is the correction of `run`'s outputs, `track` its true motion.
/// The corrector's warm-up samples (streaming) and flagged samples (inside a dead band, or
/// beyond the ends after a time-delay shift) are left out of both before and after.
pub fn check_run(run: &Run, track: &Track, corrected: &Corrected, raw_units: [bool; 2]) -> RunCheck {
    let mut axes = Vec::with_capacity(6);
    let skip = corrected.warmup.min(track.t_s.len());
    // Streaming output with a time delay estimates the truth at t − offset.
    let shifted;
    let truth_after = if corrected.time_offset_s != 0.0 {
        use crate::model::NonlinearEffect;
        shifted = crate::model::TimeDelay.transform(&[corrected.time_offset_s], track);
        &shifted
    } else {
        track
    };
    let n = track.t_s.len();
    let constant_c = run.spec.temperature_c.unwrap_or(f64::NAN);
    let temp_c = |k: usize| run.rec.temp_c.as_ref().map_or(constant_c, |t| t.get(k).copied().unwrap_or(f64::NAN));
    let mut bins = Bins::default();
    let mut t_s = Vec::with_capacity(n);
    let mut before = Vec::with_capacity(n);
    let mut after = Vec::with_capacity(n);
    for (si, sensor) in SensorKind::BOTH.iter().enumerate() {
        let (out, corr) = match sensor {
            SensorKind::Gyro => (&run.rec.gyro, &corrected.w_rad_s),
            SensorKind::Accel => (&run.rec.accel, &corrected.a_m_s2),
        };
        let sensed = |s: crate::motion::SensorKinematics| match sensor {
            SensorKind::Gyro => s.w_rad_s,
            SensorKind::Accel => s.a_m_s2,
        };
        for i in 0..3 {
            let bit = 1u8 << (3 * si + i);
            let mut amp = 0.0_f64;
            t_s.clear();
            before.clear();
            after.clear();
            for k in skip..n {
                // Samples the correction flagged (inside a dead band) are unknown, not errors.
                if corrected.flags.get(k).is_some_and(|f| f & bit != 0) {
                    continue;
                }
                let (truth, truth_a) = (sensed(track.at(k)), sensed(truth_after.at(k)));
                amp = amp.max(truth[i].abs());
                t_s.push(track.t_s[k]);
                before.push(out[k][i] - truth[i]);
                after.push(corr[k][i] - truth_a[i]);
                bins.add(temp_c(k), 3 * si + i, corr[k][i] - truth_a[i]);
            }
            axes.push(AxisCheck {
                sensor: *sensor,
                axis: AXES[i],
                amplitude: amp,
                before: (!raw_units[si]).then(|| stats(&before, &t_s, &run.spec.motion)),
                after: stats(&after, &t_s, &run.spec.motion),
            });
        }
    }
    RunCheck {
        run: run.spec.name.clone(),
        skipped: skip,
        axes,
        temperature_outside: corrected.temp_outside.warning(),
        temp_bins: bins.finish(),
    }
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
        // One χ² test pooled over runs (0.001 %), so that many runs do not multiply false alarms.
        let (chi, dof) = runs
            .iter()
            .fold((0.0, 0usize), |(c, d), r| (c + r.axes[idx].after.sys_chi2, d + r.axes[idx].after.sys_dof));
        // A correction that leaves an axis more than twice as wrong as no correction at all
        // is never "noise-limited", whatever the χ² says (the χ² is scaled by the corrected
        // output's own noise, which a diverging correction inflates too).
        let worse = matches!((before_pct, after_pct), (Some(b), Some(a)) if a > 2.0 * b);
        let noise_limited = !worse && dof > 0 && chi <= crate::stats::chi2_upper(dof, 4.265);
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
