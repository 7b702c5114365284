//! The comparison with the paper's published figures (α = 10°, ω_s = 10 °/s, nominal mount).

use super::{AxisCheck, CheckReport};
use crate::units::SensorKind;
use serde::{Deserialize, Serialize};

/// Paper: gyro error before correction, z axis, % (eq. 3 unit on the SRS-1 stand).
pub const PAPER_GYRO_BEFORE_PCT: f64 = 11.0;
/// Paper: gyro error after correction, %.
pub const PAPER_GYRO_AFTER_PCT: f64 = 0.4;
/// Paper: accelerometer error before correction, %.
pub const PAPER_ACCEL_BEFORE_PCT: f64 = 0.25;
/// Paper: accelerometer error after correction, %.
pub const PAPER_ACCEL_AFTER_PCT: f64 = 0.000006;
/// How much better than the paper the streaming corrector must be.
pub const STREAMING_MARGIN: f64 = 100.0;

/// One row of the paper comparison.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PaperRow {
    /// Sensor.
    pub sensor: SensorKind,
    /// Axis.
    pub axis: char,
    /// Error before correction, % of the axis amplitude.
    pub before_pct: Option<f64>,
    /// After offline correction, %.
    pub offline_pct: Option<f64>,
    /// before / offline.
    pub reduction: Option<f64>,
    /// After streaming correction, %.
    pub streaming_pct: Option<f64>,
    /// The paper's before figure for this axis, where it quotes one.
    pub paper_before_pct: Option<f64>,
    /// The paper's after figure.
    pub paper_after_pct: f64,
    /// Reduction the paper reached (threshold).
    pub paper_reduction: f64,
    /// Offline reduction ≥ the paper's, offline error ≤ the paper's and streaming error
    /// ≤ the paper's / [`STREAMING_MARGIN`].
    pub pass: bool,
}

fn pct(a: &AxisCheck, x: f64) -> Option<f64> {
    a.pct(x)
}

/// Rows for one run of an offline and a streaming check.
pub fn paper_rows(offline: &CheckReport, streaming: &CheckReport, run: &str) -> Option<Vec<PaperRow>> {
    let off = offline.runs.iter().find(|r| r.run == run)?;
    let st = streaming.runs.iter().find(|r| r.run == run)?;
    let mut rows = Vec::with_capacity(6);
    for (a, s) in off.axes.iter().zip(&st.axes) {
        let (paper_before, paper_after) = match (a.sensor, a.axis) {
            (SensorKind::Gyro, 'z') => (Some(PAPER_GYRO_BEFORE_PCT), PAPER_GYRO_AFTER_PCT),
            (SensorKind::Gyro, _) => (None, PAPER_GYRO_AFTER_PCT),
            (SensorKind::Accel, 'z') => (Some(PAPER_ACCEL_BEFORE_PCT), PAPER_ACCEL_AFTER_PCT),
            (SensorKind::Accel, _) => (None, PAPER_ACCEL_AFTER_PCT),
        };
        let threshold = offline.thresholds.for_sensor(a.sensor);
        let before = a.before.and_then(|b| pct(a, b.max_abs));
        let offline_pct = pct(a, a.after.max_abs);
        let streaming_pct = pct(s, s.after.max_abs);
        let reduction = match (before, offline_pct) {
            (Some(b), Some(o)) if o > 0.0 => Some(b / o),
            (Some(_), Some(_)) => Some(f64::INFINITY),
            _ => None,
        };
        let pass = reduction.is_some_and(|r| r >= threshold)
            && offline_pct.is_some_and(|o| o <= paper_after)
            && streaming_pct.is_some_and(|v| v <= paper_after / STREAMING_MARGIN);
        rows.push(PaperRow {
            sensor: a.sensor,
            axis: a.axis,
            before_pct: before,
            offline_pct,
            reduction,
            streaming_pct,
            paper_before_pct: paper_before,
            paper_after_pct: paper_after,
            paper_reduction: threshold,
            pass,
        });
    }
    Some(rows)
}
