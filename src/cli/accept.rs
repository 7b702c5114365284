//! `crosscal accept`: a unit's profile (and session) against acceptance rules.

use super::Outcome;
use crate::outln;
use anyhow::Context;
use crosscal::check::guarded::Decision;
use crosscal::check::rules::{evaluate, Evidence, Rules};
use crosscal::session::Session;
use std::path::PathBuf;

/// Options of `accept`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// The unit's profile.
    profile: PathBuf,
    /// Acceptance rules (JSON, format crosscal-rules/1; see `crosscal help rules`).
    #[arg(long)]
    rules: PathBuf,
    /// The unit's session: checked with the profile for residual and reduction rules.
    #[arg(long)]
    session: Option<PathBuf>,
    /// Also run diagnose on the session (for the `adequate` rule).
    #[arg(long)]
    diagnose: bool,
    /// Print the results as JSON.
    #[arg(long)]
    json: bool,
}

pub fn run(a: Args) -> anyhow::Result<Outcome> {
    let rules = Rules::read(&a.rules)?;
    let (used, profile) = crosscal::profile::Profile::read_or_latest(&a.profile)?;
    if used != a.profile {
        eprintln!("profile: {} (the newest of unit {})", used.display(), profile.serial);
    }
    let acc = match &a.session {
        Some(path) => {
            let s = Session::load(path).with_context(|| format!("reading session {}", path.display()))?;
            profile.ensure_unit(&a.profile, &s.manifest.serial)?;
            Some(crosscal::app::accept::acceptance(&profile, &s, a.diagnose)?)
        }
        None if a.diagnose => anyhow::bail!("--diagnose needs --session"),
        None => None,
    };
    // The unit's other calibrations: the store the profile sits in (STORE/SERIAL/file.json).
    let store = used
        .parent()
        .filter(|d| d.file_name().is_some_and(|n| n == profile.serial.as_str()))
        .and_then(|d| d.parent())
        .unwrap_or(std::path::Path::new(""));
    let sheet = crosscal::app::datasheet::datasheet_of(store, Some(&used), &profile);
    let ev = Evidence {
        datasheet: Some(&sheet),
        check: acc.as_ref().and_then(|x| x.check.as_ref()),
        adequacy: acc.as_ref().and_then(|x| x.adequacy.clone()),
        protocol: acc.as_ref().is_some_and(|x| x.protocol),
    };
    let mut results = evaluate(&rules, &profile, &ev);
    crosscal::app::accept::add_resolutions(&mut results, &rules);
    let worst = results.iter().map(|r| r.decided()).max().unwrap_or(Decision::Pass);
    let pass = worst == Decision::Pass;
    if a.json {
        outln!("{}", serde_json::to_string_pretty(&results)?);
    } else {
        for r in &results {
            let word = match r.decided() {
                Decision::Pass => "pass",
                Decision::Indeterminate => "INDET",
                Decision::Fail => "FAIL",
            };
            outln!("{word:<5} {:<32} {}", r.rule, r.detail);
            if let Some(how) = &r.resolve {
                outln!("      to resolve: {how}");
            }
        }
        let verdict = match worst {
            Decision::Pass => "ACCEPTED",
            Decision::Indeterminate => "INDETERMINATE (neither accepted nor rejected: measure it better, as above)",
            Decision::Fail => "REJECTED",
        };
        outln!("unit {}: {verdict}", profile.serial);
    }
    Ok(if pass { Outcome::Ok } else { Outcome::CheckFailed })
}
