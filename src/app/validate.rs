//! Correct a session with a calibration and check it against the reference motion; fit on
//! some runs and check the others (held-out runs, leave-one-run-out).

use super::AppError;
use crate::check::{check_run, summarize, CheckReport, Thresholds};
use crate::correct::{correct_offline, correct_streaming, Calibration, CorrectError, Corrected};
use crate::estimate::{tracks, Fit, FitRequest};
use crate::model::Model;
use crate::motion::DerivativeConfig;
use crate::session::{Run, Session};
use crate::units::{AccelUnit, GyroUnit};

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
    // A run's constant temperature stands in for a missing temp column.
    let constant: Option<Vec<f64>> =
        run.rec.temp_c.is_none().then_some(run.spec.temperature_c).flatten().map(|t| vec![t; run.rec.len()]);
    let temp = run.rec.temp_c.as_deref().or(constant.as_deref());
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
    if session.is_protocol() {
        return Err(CorrectError::ProtocolSession(session.manifest_path.display().to_string()));
    }
    let tr = tracks(session, &DerivativeConfig::default());
    let raw = [session.manifest.units.gyro == GyroUnit::Raw, session.manifest.units.accel == AccelUnit::Raw];
    let mut runs = Vec::with_capacity(session.runs.len());
    for (run, track) in session.runs.iter().zip(&tr) {
        let corrected = correct_run(cal, run, mode)?;
        runs.push(check_run(run, track, &corrected, raw));
    }
    Ok(summarize(runs, thresholds))
}

/// Fits `model` on every run except `holdout` and checks the held-out runs only.
/// Returns the check and the fit.
pub fn holdout_check(
    session: &Session,
    model: &Model,
    holdout: &[String],
    mode: Mode,
    thresholds: Thresholds,
) -> Result<(CheckReport, Fit), AppError> {
    let what = session.manifest_path.display().to_string();
    if holdout.is_empty() {
        return Err(AppError::Invalid("hold out at least one run and keep at least one to fit".into()));
    }
    let mut req = FitRequest::session(model, session);
    req.holdout = holdout.to_vec();
    let fit = crate::estimate::fit(&req).map_err(|source| AppError::Fit { what: what.clone(), source })?.fit;
    let test = session.subset(|n| holdout.iter().any(|h| h == n));
    let correct = |source| AppError::Correct { what: what.clone(), source };
    let cal = calibration_of(model, &fit).map_err(correct)?;
    Ok((check_session(&test, &cal, mode, thresholds).map_err(correct)?, fit))
}

/// The calibration a fit implies (the model with every coefficient held at its estimate).
pub fn calibration_of(model: &Model, fit: &Fit) -> Result<Calibration, CorrectError> {
    let mut m = model.clone();
    for c in fit.gyro.coefficients.iter().chain(&fit.accel.coefficients) {
        m.fix(&c.name, c.value)?;
    }
    for e in model.nonlinear() {
        let values = fit.nonlinear.iter().filter(|p| p.effect == e.effect.id()).map(|p| p.value).collect();
        m.fix_nonlinear(e.effect.id(), values)?;
    }
    let mut cal = Calibration::from_model(&m, Default::default())?;
    for (si, sf) in [&fit.gyro, &fit.accel].iter().enumerate() {
        for (i, ch) in sf.channels.iter().enumerate().take(3) {
            cal.noise[si][i] = ch.sigma;
        }
    }
    Ok(cal)
}

/// Leave-one-run-out: each run is checked with a model fitted on all the others; the
/// per-run checks are summarised together.
pub fn cross_validate(
    session: &Session,
    model: &Model,
    mode: Mode,
    thresholds: Thresholds,
) -> Result<CheckReport, AppError> {
    if session.runs.len() < 2 {
        return Err(AppError::Invalid("cross-validation needs at least two runs".into()));
    }
    let mut runs = Vec::with_capacity(session.runs.len());
    for r in &session.runs {
        let (rep, _) = holdout_check(session, model, std::slice::from_ref(&r.spec.name), mode, thresholds)?;
        runs.extend(rep.runs);
    }
    Ok(summarize(runs, thresholds))
}
