//! `crosscal accept`: a unit's profile (and session) against acceptance rules.

use super::Outcome;
use crate::outln;
use anyhow::Context;
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
    let profile = super::read_profile(&a.profile)?;
    let acc = match &a.session {
        Some(path) => {
            let s = Session::load(path).with_context(|| format!("reading session {}", path.display()))?;
            profile.ensure_unit(&a.profile, &s.manifest.serial)?;
            Some(crosscal::app::accept::acceptance(&profile, &s, a.diagnose)?)
        }
        None if a.diagnose => anyhow::bail!("--diagnose needs --session"),
        None => None,
    };
    let ev = Evidence {
        check: acc.as_ref().and_then(|x| x.check.as_ref()),
        adequacy: acc.as_ref().and_then(|x| x.adequacy.clone()),
        protocol: acc.as_ref().is_some_and(|x| x.protocol),
    };
    let results = evaluate(&rules, &profile, &ev);
    let pass = results.iter().all(|r| r.pass);
    if a.json {
        outln!("{}", serde_json::to_string_pretty(&results)?);
    } else {
        for r in &results {
            outln!("{:<5} {:<32} {}", if r.pass { "pass" } else { "FAIL" }, r.rule, r.detail);
        }
        outln!("unit {}: {}", profile.serial, if pass { "ACCEPTED" } else { "REJECTED" });
    }
    Ok(if pass { Outcome::Ok } else { Outcome::CheckFailed })
}
