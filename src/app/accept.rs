//! Accept or reject a unit: what its session says about its profile (the check of the
//! session corrected with it and, when asked, whether `diagnose` finds the model adequate),
//! ready for the acceptance rules.

use super::validate::{check_session, Mode};
use super::AppError;
use crate::check::{CheckReport, Thresholds};
use crate::correct::Calibration;
use crate::estimate::{fit_runs, tracks, FitOptions};
use crate::motion::DerivativeConfig;
use crate::session::Session;

/// Everything acceptance can learn about a unit from its session with a profile: the check
/// of the session corrected with it and, when asked, whether `diagnose` finds the model
/// adequate.
#[derive(Debug, Clone)]
pub struct Acceptance {
    /// Check report (offline correction); none for a protocol session, which has no
    /// per-sample reference.
    pub check: Option<CheckReport>,
    /// The session is a protocol session.
    pub protocol: bool,
    /// Diagnose verdict: adequate, and the unexplained findings otherwise.
    pub adequacy: Option<(bool, Vec<String>)>,
}

/// Checks `session` with `profile` and (with `diagnose`) tests the model's adequacy.
pub fn acceptance(
    profile: &crate::profile::Profile,
    session: &Session,
    diagnose: bool,
) -> Result<Acceptance, AppError> {
    let what = session.manifest_path.display().to_string();
    let correct = |source| AppError::Correct { what: what.clone(), source };
    let cal = Calibration::from_profile(profile).map_err(correct)?;
    let protocol = session.is_protocol();
    let check = if protocol {
        None
    } else {
        Some(check_session(session, &cal, Mode::Offline, Thresholds::default()).map_err(correct)?)
    };
    let adequacy = if diagnose && protocol {
        let model = profile.fitted_model().map_err(|e| AppError::Correct { what: what.clone(), source: e.into() })?;
        let d = crate::diagnose::protocol::diagnose_protocol(session, &model)
            .map_err(|source| AppError::Fit { what: what.clone(), source })?;
        let mut why: Vec<String> = d.standing_out().iter().map(|p| format!("{p} stands out")).collect();
        if let Some(p) = &d.proposal {
            why.push(format!("missing effect: {p}"));
        }
        Some((why.is_empty(), why))
    } else if diagnose {
        let model = profile.fitted_model().map_err(|e| AppError::Correct { what: what.clone(), source: e.into() })?;
        let tr = tracks(session, &DerivativeConfig::default());
        let runs = fit_runs(session, &tr);
        let motions: Vec<&crate::session::MotionSpec> = session.runs.iter().map(|r| &r.spec.motion).collect();
        let d = crate::diagnose::diagnose(&model, &runs, &motions, &FitOptions::default())
            .map_err(|source| AppError::Fit { what: what.clone(), source })?;
        let ok = d.verdict == crate::diagnose::Verdict::Adequate;
        let mut why = d.unexplained.clone();
        if !d.proposal.is_empty() {
            why.push(format!("missing effects: {}", d.proposal.join(", ")));
        }
        Some((ok, why))
    } else {
        None
    };
    Ok(Acceptance { check, protocol, adequacy })
}
