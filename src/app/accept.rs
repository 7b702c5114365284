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
        match &d.proposal {
            Some(p) if d.verdict() == crate::diagnose::Verdict::Explained => why.push(format!("missing effect: {p}")),
            // Beyond the noise: the closest match is no evidence of a unit effect (issue 36).
            Some(p) => {
                why.push(format!("closest catalogued match {p} (not evidence: the residuals are beyond the noise)"))
            }
            None => {}
        }
        Some((why.is_empty(), why))
    } else if diagnose {
        let model = profile.fitted_model().map_err(|e| AppError::Correct { what: what.clone(), source: e.into() })?;
        let tr = tracks(session, &DerivativeConfig::default());
        let runs = fit_runs(session, &tr);
        let motions: Vec<&crate::session::MotionSpec> = session.runs.iter().map(|r| &r.spec.motion).collect();
        let mode = crate::diagnose::SlowNoiseMode::Auto;
        let d = crate::diagnose::diagnose_with_mode(&model, &runs, &motions, &FitOptions::default(), mode)
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

/// Tells every indeterminate datasheet result what measurement would resolve it
/// ([`resolve`]).
pub fn add_resolutions(results: &mut [crate::check::rules::RuleResult], rules: &crate::check::rules::Rules) {
    for (r, rule) in results.iter_mut().zip(&rules.rules) {
        if let crate::check::rules::Rule::Datasheet { quantity, k, .. } = rule {
            let k = k.or(rules.k).unwrap_or(crate::check::guarded::DEFAULT_K);
            r.resolve = resolve(quantity, r, k);
        }
    }
}

/// The measurement that would turn an indeterminate decision into pass or fail: the
/// standard uncertainty must fall below margin / k, margin the distance from the value to
/// the limit. A fitted quantity's variance falls as 1/samples
/// ([`crate::plan::duration_factor`]); so does an Allan-deviation reading's (its degrees of
/// freedom grow with the recording); a repeatability's u = s/√(2(n − 1)) needs n
/// calibrations; a trend's u falls as 1/(span √n).
pub fn resolve(quantity: &str, r: &crate::check::rules::RuleResult, k: f64) -> Option<String> {
    use crate::check::guarded::Decision;
    let ax = r.axes.iter().filter(|a| a.decision == Decision::Indeterminate).max_by(|a, b| {
        let need = |x: &crate::check::guarded::AxisDecision| x.uncertainty * k / x.margin.max(f64::MIN_POSITIVE);
        need(a).total_cmp(&need(b))
    })?;
    let target = ax.margin / k;
    if target.is_nan() || target <= 0.0 {
        return Some(format!(
            "axis {}: the value sits on the limit; no measurement can resolve it (review the limit)",
            ax.axis
        ));
    }
    let f = crate::plan::duration_factor(ax.uncertainty, target);
    let what = if quantity.ends_with("bias_repeatability") {
        let n = 1.0 + (ax.value * ax.value / (2.0 * target * target)).ceil();
        format!("{n:.0} calibrations (power cycles) of the unit instead of its present ones")
    } else if quantity.ends_with("_trend") {
        format!("a calibration history {:.1}× as long (or {f:.1}× the calibrations)", f.sqrt())
    } else if ["bias_instability", "arw", "vrw"].iter().any(|q| quantity.ends_with(q)) {
        format!("a rest recording {f:.1}× as long (crosscal noise)")
    } else {
        format!("a calibration session {f:.1}× as long, or {f:.1}× its runs (the fit's variance falls as 1/samples; `crosscal plan` predicts a design)")
    };
    Some(format!(
        "axis {}: u = {:.3e} must fall below {:.3e} (margin {:.3e} / k = {k}): {what}",
        ax.axis, ax.uncertainty, target, ax.margin
    ))
}
