//! Glue for the one-way data flow: session → tracks (true motion in sensor axes) → fit.

use crate::check::{check_run, summarize, CheckReport, Thresholds};
use crate::correct::{correct_offline, correct_streaming, Calibration, CorrectError, Corrected};
use crate::estimate::{fit, fit_runs, tracks, EstimateError, Fit, FitOptions};
use crate::model::Model;
use crate::motion::DerivativeConfig;
use crate::session::{Run, Session};
use crate::units::{AccelUnit, GyroUnit};

/// Fits a model to all runs of a session.
pub fn fit_session(session: &Session, model: &Model, opts: &FitOptions) -> Result<Fit, EstimateError> {
    if session.is_protocol() {
        return Err(EstimateError::Protocol(format!(
            "{} has protocol runs: fit it with `crosscal fit` (estimate::protocol::fit_protocol), not sample by sample",
            session.manifest_path.display()
        )));
    }
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

/// A session restricted to some of its runs (by name).
pub fn subset(session: &Session, keep: impl Fn(&str) -> bool) -> Session {
    let runs: Vec<Run> = session.runs.iter().filter(|r| keep(&r.spec.name)).cloned().collect();
    let mut manifest = session.manifest.clone();
    manifest.runs = runs.iter().map(|r| r.spec.clone()).collect();
    Session { manifest_path: session.manifest_path.clone(), manifest, runs }
}

/// Errors of validation on held-out runs.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum ValidateError {
    /// A named run is not in the session.
    #[error("no run named '{0}' in the session (runs: {1})")]
    UnknownRun(String, String),
    /// Nothing would be left to fit, or nothing to validate.
    #[error("{0}")]
    Empty(String),
    /// Fitting failed.
    #[error(transparent)]
    Fit(#[from] EstimateError),
    /// Correction failed.
    #[error(transparent)]
    Correct(#[from] CorrectError),
}

/// Fits `model` on every run except `holdout` and checks the held-out runs only.
/// Returns the check and the fit.
pub fn holdout_check(
    session: &Session,
    model: &Model,
    holdout: &[String],
    mode: Mode,
    thresholds: Thresholds,
) -> Result<(CheckReport, Fit), ValidateError> {
    for h in holdout {
        if !session.runs.iter().any(|r| &r.spec.name == h) {
            let names: Vec<&str> = session.runs.iter().map(|r| r.spec.name.as_str()).collect();
            return Err(ValidateError::UnknownRun(h.clone(), names.join(", ")));
        }
    }
    let train = subset(session, |n| !holdout.iter().any(|h| h == n));
    let test = subset(session, |n| holdout.iter().any(|h| h == n));
    if train.runs.is_empty() || test.runs.is_empty() {
        return Err(ValidateError::Empty("hold out at least one run and keep at least one to fit".into()));
    }
    let fit = fit_session(&train, model, &FitOptions::default())?;
    let cal = calibration_of(model, &fit)?;
    Ok((check_session(&test, &cal, mode, thresholds)?, fit))
}

/// The calibration a fit implies (the model with every coefficient held at its estimate).
pub fn calibration_of(model: &Model, fit: &Fit) -> Result<Calibration, CorrectError> {
    let mut m = model.clone();
    for c in fit.gyro.coefficients.iter().chain(&fit.accel.coefficients) {
        m.fix(&c.name, c.value).map_err(|e| CorrectError::Model(e.to_string()))?;
    }
    for e in model.nonlinear() {
        let values = fit.nonlinear.iter().filter(|p| p.effect == e.effect.id()).map(|p| p.value).collect();
        m.fix_nonlinear(e.effect.id(), values).map_err(|e| CorrectError::Model(e.to_string()))?;
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
) -> Result<CheckReport, ValidateError> {
    if session.runs.len() < 2 {
        return Err(ValidateError::Empty("cross-validation needs at least two runs".into()));
    }
    let mut runs = Vec::with_capacity(session.runs.len());
    for r in &session.runs {
        let (rep, _) = holdout_check(session, model, std::slice::from_ref(&r.spec.name), mode, thresholds)?;
        runs.extend(rep.runs);
    }
    Ok(summarize(runs, thresholds))
}

/// Everything acceptance can learn about a unit from its session with a profile: the check
/// of the session corrected with it and, when asked, whether `diagnose` finds the model
/// adequate.
#[derive(Debug, Clone)]
pub struct Acceptance {
    /// Check report (offline correction).
    pub check: CheckReport,
    /// Diagnose verdict: adequate, and the unexplained findings otherwise.
    pub adequacy: Option<(bool, Vec<String>)>,
}

/// Errors of [`acceptance`].
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum AcceptanceError {
    /// The profile cannot drive a correction.
    #[error(transparent)]
    Correct(#[from] CorrectError),
    /// The profile's model cannot be rebuilt.
    #[error(transparent)]
    Model(#[from] crate::model::ModelError),
    /// Diagnose failed.
    #[error(transparent)]
    Estimate(#[from] EstimateError),
}

/// Checks `session` with `profile` and (with `diagnose`) tests the model's adequacy.
pub fn acceptance(
    profile: &crate::profile::Profile,
    session: &Session,
    diagnose: bool,
) -> Result<Acceptance, AcceptanceError> {
    let cal = Calibration::from_profile(profile)?;
    let check = check_session(session, &cal, Mode::Offline, Thresholds::default())?;
    let adequacy = if diagnose {
        let model = profile.fitted_model()?;
        let tr = tracks(session, &DerivativeConfig::default());
        let runs = fit_runs(session, &tr);
        let motions: Vec<&crate::session::MotionSpec> = session.runs.iter().map(|r| &r.spec.motion).collect();
        let d = crate::diagnose::diagnose(&model, &runs, &motions, &FitOptions::default())?;
        let ok = d.verdict == crate::diagnose::Verdict::Adequate;
        let mut why = d.unexplained.clone();
        if !d.proposal.is_empty() {
            why.push(format!("missing effects: {}", d.proposal.join(", ")));
        }
        Some((ok, why))
    } else {
        None
    };
    Ok(Acceptance { check, adequacy })
}
