//! A unit's datasheet from the profile store: the profile in force, the unit's stored
//! calibrations up to it, and the user's calibrated ranges (shared by `crosscal datasheet`,
//! `accept`, `batch` and the Python `datasheet`).

use super::AppError;
use crate::datasheet::{build, Datasheet, DatasheetOptions};
use crate::profile::{history, latest, Profile};
use std::path::{Path, PathBuf};

/// The readable profiles of unit `serial` in `store` created at or before `profile`'s time,
/// oldest first (none when the store has no folder for it).
fn calibrations_up_to(store: &Path, profile: &Profile) -> Vec<(PathBuf, Profile)> {
    let t = profile.created_utc.parse::<jiff::Timestamp>().ok();
    history(store, &profile.serial)
        .map(|h| h.into_iter().filter_map(|(p, r)| r.ok().map(|r| (p, r))).collect::<Vec<_>>())
        .unwrap_or_default()
        .into_iter()
        .filter(|(_, p)| t.is_none_or(|t| p.created_utc.parse::<jiff::Timestamp>().is_ok_and(|x| x <= t)))
        .collect()
}

/// The datasheet of `unit` in `store` as of `at` (RFC 3339 or a date; None: now).
pub fn datasheet(store: &Path, unit: &str, at: Option<&str>, opts: &DatasheetOptions) -> Result<Datasheet, AppError> {
    let (path, profile) = latest(store, unit, at)
        .map_err(|source| AppError::Profile { what: format!("unit {unit} in store {}", store.display()), source })?;
    for (v, what) in [(opts.gyro_range_rad_s, "the gyro range"), (opts.accel_range_m_s2, "the accelerometer range")] {
        if v.is_some_and(|v| !(v.is_finite() && v > 0.0)) {
            return Err(AppError::Invalid(format!("{what} must be a positive number")));
        }
    }
    let history = calibrations_up_to(store, &profile);
    Ok(build(&path.display().to_string(), &profile, &history, opts))
}

/// The datasheet of a profile stored at `path` in `store` (with its unit's calibrations up
/// to it), for acceptance; the profile alone when it is not in a store.
pub fn datasheet_of(store: &Path, path: Option<&Path>, profile: &Profile) -> Datasheet {
    let history = calibrations_up_to(store, profile);
    let shown = path.map_or_else(|| "the profile".to_string(), |p| p.display().to_string());
    build(&shown, profile, &history, &DatasheetOptions::default())
}
