//! Fit a unit and make its profile: the one fit entry point, then the profile with its
//! provenance and notes, validated on held-out runs when some are named, a noise
//! characterisation attached when given. Storing is a separate step, so that a caller saves
//! the profile before printing anything that might fail.

use super::validate::{check_session, Mode};
use super::AppError;
use crate::check::{CheckReport, Thresholds};
use crate::correct::Calibration;
use crate::estimate::{FitData, FitOutcome, FitRequest};
use crate::noise::NoiseReport;
use crate::profile::{Profile, Validation};
use crate::session::Session;
use std::path::{Path, PathBuf};

/// A fitted profile and what its fit saw.
#[derive(Debug, Clone)]
pub struct Fitted {
    /// The profile (not yet stored).
    pub profile: Profile,
    /// Samples fitted.
    pub samples: usize,
    /// Whether the recordings were streamed.
    pub streamed: bool,
    /// Findings in the recordings (gaps, saturation, spikes).
    pub warnings: Vec<String>,
    /// The check of the held-out runs, when some were held out (also in the profile).
    pub validation: Option<CheckReport>,
}

/// What a request fits, for messages.
pub fn describe(data: &FitData<'_>) -> String {
    match data {
        FitData::Manifest(p) => p.display().to_string(),
        FitData::Session(s) => s.manifest_path.display().to_string(),
        FitData::Runs(r) => format!("{} prepared runs", r.len()),
    }
}

/// Fits as `req` says and makes the profile (validated on `req.holdout`, with `noise`
/// attached).
pub fn fit_profile(req: &FitRequest<'_>, noise: Option<NoiseReport>) -> Result<Fitted, AppError> {
    let what = describe(&req.data);
    // Held-out runs are validated after the fit: read the session once for both.
    let loaded;
    let mut req = req.clone();
    if let (FitData::Manifest(path), false) = (req.data, req.holdout.is_empty()) {
        loaded = Session::load_with(path, req.strict)
            .map_err(|source| AppError::Session { path: path.to_path_buf(), source })?;
        req.data = FitData::Session(&loaded);
    }
    let outcome = crate::estimate::fit(&req).map_err(|source| AppError::Fit { what: what.clone(), source })?;
    let FitOutcome { fit, model, source, warnings, notes, protocol, streamed } = outcome;
    let source = source.ok_or_else(|| AppError::Invalid(format!("{what}: prepared runs cannot make a profile")))?;
    let samples = source.samples;
    let mut profile = Profile::from_fit_of(&source.manifest, source.runs, &model, fit, notes);
    profile.protocol = protocol;
    profile.noise = noise;
    let validation = match (req.data, req.holdout.is_empty()) {
        (FitData::Session(full), false) => {
            let held = full.subset(|n| req.holdout.iter().any(|h| h == n));
            let cal = Calibration::from_profile(&profile)
                .map_err(|source| AppError::Correct { what: what.clone(), source })?;
            let report = check_session(&held, &cal, Mode::Offline, Thresholds::default())
                .map_err(|source| AppError::Correct { what: what.clone(), source })?;
            profile.validation =
                Some(Validation { runs: held.runs_used(), summary: report.summary.clone(), pass: report.pass });
            Some(report)
        }
        _ => None,
    };
    Ok(Fitted { profile, samples, streamed, warnings, validation })
}

/// Stores a profile in the store at `root` (never overwriting); returns its path.
pub fn store(profile: &Profile, root: &Path) -> Result<PathBuf, AppError> {
    crate::profile::save(profile, root)
        .map_err(|source| AppError::Profile { what: format!("saving under {}", root.display()), source })
}
