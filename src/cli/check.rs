//! `crosscal check`.

use super::correct::ModeArg;
use super::{format, Outcome};
use crate::errln;
use crate::{out, outln};
use anyhow::Context;
use crosscal::app::validate::{check_session, cross_validate, holdout_check};
use crosscal::check::{CheckReport, Thresholds};
use crosscal::correct::Calibration;
use crosscal::session::Session;
use std::path::PathBuf;

/// Options of `check`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Calibration profile (JSON). Without it, use --holdout or --cross-validate, which fit
    /// the model on the session's other runs.
    #[arg(long, required_unless_present_any = ["holdout", "cross_validate"])]
    profile: Option<PathBuf>,
    /// Session with reference motion (session.json).
    session: PathBuf,
    /// Fit on all runs but these and check only these (repeatable).
    #[arg(long, conflicts_with_all = ["profile", "cross_validate"])]
    holdout: Vec<String>,
    /// Leave-one-run-out: check each run with a model fitted on all the others.
    #[arg(long, conflicts_with = "profile")]
    cross_validate: bool,
    /// The model (for `check`: fitted with --holdout / --cross-validate).
    #[command(flatten)]
    model: super::ModelArgs,
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
    let thresholds =
        Thresholds { gyro_min_reduction: a.gyro_min_reduction, accel_min_reduction: a.accel_min_reduction };
    let session =
        Session::load_with(&a.session, a.strict).with_context(|| format!("reading session {}", a.session.display()))?;
    let Some(profile_path) = &a.profile else {
        let model = a.model.spec(&[]).build()?;
        let (report, what) = if a.cross_validate {
            let r = cross_validate(&session, &model, a.mode.into(), thresholds)?;
            (r, "leave-one-run-out: each run checked with a model fitted on the others".to_string())
        } else {
            let (r, _) = holdout_check(&session, &model, &a.holdout, a.mode.into(), thresholds)?;
            (r, format!("model fitted on the other runs, checked on {}", a.holdout.join(", ")))
        };
        return print_report(&session, &report, &what, a.json);
    };
    let profile = super::read_profile(profile_path)?;
    if !a.allow_other_unit {
        profile
            .ensure_unit(profile_path, &session.manifest.serial)
            .context("checking a unit against another unit's profile (pass --allow-other-unit to do it anyway)")?;
    }
    if profile.input_units != session.manifest.units {
        errln!("note: the session's units differ from those the profile was fitted on; values are converted on read");
    }
    let cal = Calibration::from_profile(&profile)?;
    let report = check_session(&session, &cal, a.mode.into(), thresholds)?;
    print_report(&session, &report, &format!("profile {}", profile_path.display()), a.json)
}

fn print_report(session: &Session, report: &CheckReport, what: &str, json: bool) -> anyhow::Result<Outcome> {
    if json {
        outln!("{}", serde_json::to_string_pretty(report)?);
    } else {
        outln!("unit {}: {} runs checked ({what})", session.manifest.serial, report.runs.len());
        out!("{}", format::check_summary(report));
        outln!("{}", if report.pass { "PASS" } else { "FAIL" });
    }
    Ok(if report.pass { Outcome::Ok } else { Outcome::CheckFailed })
}
