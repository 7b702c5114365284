//! Diagnose a session: the model to start from (a preset with effects, or a unit's profile
//! held as fitted), the diagnosis of stand runs or of a protocol session, the HTML report
//! with its residual plots, and the runs a profile's temperature terms never saw.

use super::AppError;
use crate::diagnose::protocol::ProtocolDiagnosis;
use crate::diagnose::Diagnosis;
use crate::estimate::protocol::ProtocolOptions;
use crate::estimate::{fit_runs, tracks, FitOptions, FitRequest};
use crate::model::{Model, ModelSpec, Preset};
use crate::motion::DerivativeConfig;
use crate::profile::Profile;
use crate::session::{MotionSpec, Session};

/// What a diagnosis found: on stand runs (per-sample residuals) or on a protocol session
/// (pose and turn residuals).
#[derive(Debug, Clone)]
pub enum Diagnosed {
    /// Conic, static or reference runs.
    Stand(Box<Diagnosis>),
    /// Static poses, turns, multi-position.
    Protocol(Box<ProtocolDiagnosis>),
}

/// The model a diagnosis starts from: the profile's (read from `path`; coefficients held,
/// `spec.effects` added) when one is given, else `spec`; protocol sessions default to their protocol's
/// preset unless `spec` names another.
pub fn start_model(
    session: &Session,
    spec: &ModelSpec,
    profile: Option<(&std::path::Path, &Profile)>,
) -> Result<Model, AppError> {
    let what = session.manifest_path.display().to_string();
    let model_err = |source| AppError::Model { what: what.clone(), source };
    match profile {
        Some((path, p)) => {
            p.ensure_unit(path, &session.manifest.serial)
                .map_err(|source| AppError::Profile { what: format!("of unit {}", p.serial), source })?;
            let mut m = p.model().map_err(model_err)?;
            for e in &spec.effects {
                m.add_effect(e).map_err(model_err)?;
            }
            Ok(m)
        }
        None => {
            let default = if session.is_protocol() {
                crate::estimate::protocol::default_preset(session)
            } else {
                Preset::Default
            };
            spec.build_with_default(default).map_err(model_err)
        }
    }
}

/// Diagnoses `session` from `model` (`trim_rest`: a multi-position session's initial rest
/// is cut to its still part, as `fit --trim-rest`; `slow_noise`: whether the fits measure
/// each channel's flicker and bias random walk and the evidence treats them as noise, as
/// `fit --slow-noise` — always, never, or when the session's slow variation wanders like
/// noise, [`crate::diagnose::SlowNoiseMode`]; stand sessions).
pub fn diagnose_session(
    session: &Session,
    model: &Model,
    trim_rest: bool,
    slow_noise: crate::diagnose::SlowNoiseMode,
) -> Result<Diagnosed, AppError> {
    let what = session.manifest_path.display().to_string();
    let fit_err = |source| AppError::Fit { what: what.clone(), source };
    if session.is_protocol() {
        let protocol = ProtocolOptions { trim_rest, ..Default::default() };
        let d = crate::diagnose::protocol::diagnose_protocol_with(session, model, &protocol).map_err(fit_err)?;
        return Ok(Diagnosed::Protocol(Box::new(d)));
    }
    let tr = tracks(session, &DerivativeConfig::default());
    let runs = fit_runs(session, &tr);
    let motions: Vec<&MotionSpec> = session.runs.iter().map(|r| &r.spec.motion).collect();
    let d = crate::diagnose::diagnose_with_mode(model, &runs, &motions, &FitOptions::default(), slow_noise)
        .map_err(fit_err)?;
    Ok(Diagnosed::Stand(Box::new(d)))
}

/// The report of a stand diagnosis: the self-contained HTML page and its figures (residual
/// against time and cone phase, spectrum and harmonics per channel, before and after the
/// effects the diagnosis adds).
pub fn report(session: &Session, model: &Model, d: &Diagnosis) -> Result<(String, Vec<crate::html::Figure>), AppError> {
    let what = session.manifest_path.display().to_string();
    let tr = tracks(session, &DerivativeConfig::default());
    let runs = fit_runs(session, &tr);
    let motions: Vec<&MotionSpec> = session.runs.iter().map(|r| &r.spec.motion).collect();
    let base_fit =
        crate::estimate::fit(&FitRequest::runs(model, &runs)).map_err(|source| AppError::Fit { what, source })?.fit;
    let before = crate::diagnose::residuals(model, &base_fit, &runs, &motions);
    let after = (!d.steps.is_empty()).then(|| {
        let m = crate::diagnose::ladder_model(model, d);
        crate::diagnose::residuals(&m, &d.final_fit, &runs, &motions)
    });
    let title = format!("crosscal diagnose: unit {}", session.manifest.serial);
    let path = session.manifest_path.display().to_string();
    let html = crate::diagnose::report::html(&title, &path, d, &before, after.as_deref(), &motions);
    let mut figures = crate::diagnose::report::figures(&before, after.as_deref(), &motions);
    figures.extend(d.shapes.iter().flat_map(crate::diagnose::report::shape_figures));
    Ok((html, figures))
}

/// The runs of `session` whose temperatures lie outside the range `profile`'s temperature
/// terms were calibrated over, named in one sentence (None when all lie inside, or the
/// profile has no temperature terms): the model is extrapolated there.
pub fn temperature_outside(profile: &Profile, session: &Session) -> Option<String> {
    let [lo, hi] = profile.temperature_range_c().filter(|_| profile.uses_temperature())?;
    let outside: Vec<String> = session
        .runs_used()
        .iter()
        .filter_map(|r| {
            let [a, b] = r.temp_range_c?;
            (a < lo || b > hi).then(|| format!("{} ({a:.1}..{b:.1} degC)", r.name))
        })
        .collect();
    (!outside.is_empty()).then(|| {
        format!(
            "OUT OF THE CALIBRATED TEMPERATURE RANGE ({lo:.1}..{hi:.1} degC): {} of {} runs: {}; the profile's temperature terms are extrapolated there, so a misfit may be the range, not a missing effect: recalibrate over these temperatures",
            outside.len(),
            session.runs.len(),
            outside.join(", ")
        )
    })
}
