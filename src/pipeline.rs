//! Glue for the one-way data flow: session → tracks (true motion in sensor axes) → fit.

use crate::check::{check_run, summarize, CheckReport, Thresholds};
use crate::correct::{correct_offline, correct_streaming, Calibration, CorrectError, Corrected};
use crate::estimate::{fit, EstimateError, Fit, FitOptions, FitRun};
use crate::model::Model;
use crate::motion::{track, DerivativeConfig, Track};
use crate::session::{AccelUnit, GyroUnit, Run, Session};

/// The true motion of every run of a session, in sensor axes.
pub fn tracks(session: &Session, deriv: &DerivativeConfig) -> Vec<Track> {
    session.runs.iter().map(|r| track(r, session.manifest.g_m_s2, deriv)).collect()
}

/// Pairs each run's outputs with its track, for the estimator.
pub fn fit_runs<'a>(session: &'a Session, tracks: &'a [Track]) -> Vec<FitRun<'a>> {
    session
        .runs
        .iter()
        .zip(tracks)
        .map(|(r, tr)| FitRun {
            name: &r.spec.name,
            track: tr,
            gyro: &r.rec.gyro,
            accel: &r.rec.accel,
            temp_c: r.rec.temp_c.as_deref(),
            temp_const_c: r.spec.temperature_c,
        })
        .collect()
}

/// Fits a model to all runs of a session.
pub fn fit_session(session: &Session, model: &Model, opts: &FitOptions) -> Result<Fit, EstimateError> {
    let tr = tracks(session, &DerivativeConfig::default());
    fit(model, &fit_runs(session, &tr), opts)
}

/// Correction mode.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Mode {
    /// Whole record, centred derivative, iterated to a fixed point.
    #[default]
    Offline,
    /// Causal, sample by sample.
    Streaming,
}

/// Corrects one run of a session.
pub fn correct_run(cal: &Calibration, run: &Run, mode: Mode) -> Result<Corrected, CorrectError> {
    let temp = run.rec.temp_c.as_deref();
    match mode {
        Mode::Offline => correct_offline(cal, &run.rec.t_s, &run.rec.gyro, &run.rec.accel, temp),
        Mode::Streaming => correct_streaming(cal, &run.rec.t_s, &run.rec.gyro, &run.rec.accel, temp),
    }
}

/// Corrects every run of a session and compares with the reference motion.
pub fn check_session(
    session: &Session,
    cal: &Calibration,
    mode: Mode,
    thresholds: Thresholds,
) -> Result<CheckReport, CorrectError> {
    let tr = tracks(session, &DerivativeConfig::default());
    let raw = [session.manifest.units.gyro == GyroUnit::Raw, session.manifest.units.accel == AccelUnit::Raw];
    let mut runs = Vec::with_capacity(session.runs.len());
    for (run, track) in session.runs.iter().zip(&tr) {
        let corrected = correct_run(cal, run, mode)?;
        runs.push(check_run(run, track, &corrected, raw));
    }
    Ok(summarize(runs, thresholds))
}
