//! `crosscal check`.

use super::correct::ModeArg;
use super::{format, Outcome};
use anyhow::Context;
use crosscal::check::Thresholds;
use crosscal::correct::Calibration;
use crosscal::pipeline::check_session;
use crosscal::profile::Profile;
use crosscal::session::Session;
use std::path::PathBuf;

/// Options of `check`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Calibration profile (JSON).
    #[arg(long)]
    profile: PathBuf,
    /// Session with reference motion (session.json).
    session: PathBuf,
    /// Offline (default) or streaming correction.
    #[arg(long, value_enum, default_value = "offline")]
    mode: ModeArg,
    /// Minimum gyro reduction factor (paper: 30).
    #[arg(long, default_value_t = 30.0)]
    gyro_min_reduction: f64,
    /// Minimum accelerometer reduction factor (paper: 40000).
    #[arg(long, default_value_t = 40000.0)]
    accel_min_reduction: f64,
    /// Print the full report as JSON.
    #[arg(long)]
    json: bool,
    /// Allow a profile whose serial differs from the session's.
    #[arg(long)]
    allow_other_unit: bool,
    /// Gaps in t are errors instead of warnings.
    #[arg(long)]
    strict: bool,
}

pub fn run(a: Args) -> anyhow::Result<Outcome> {
    let profile = Profile::read(&a.profile)?;
    let session =
        Session::load_with(&a.session, a.strict).with_context(|| format!("reading session {}", a.session.display()))?;
    if !a.allow_other_unit {
        profile
            .ensure_unit(&a.profile, &session.manifest.serial)
            .context("checking a unit against another unit's profile (pass --allow-other-unit to do it anyway)")?;
    }
    if profile.input_units != session.manifest.units {
        eprintln!(
            "note: the session's units differ from those the profile was fitted on; values are converted on read"
        );
    }
    let cal = Calibration::from_profile(&profile)?;
    let thresholds =
        Thresholds { gyro_min_reduction: a.gyro_min_reduction, accel_min_reduction: a.accel_min_reduction };
    let report = check_session(&session, &cal, a.mode.into(), thresholds)?;
    if a.json {
        println!("{}", serde_json::to_string_pretty(&report)?);
    } else {
        println!("unit {}: {} runs checked", session.manifest.serial, report.runs.len());
        print!("{}", format::check_summary(&report));
        println!("{}", if report.pass { "PASS" } else { "FAIL" });
    }
    Ok(if report.pass { Outcome::Ok } else { Outcome::CheckFailed })
}
