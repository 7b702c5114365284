//! `crosscal compare`: the model ladder.

use super::Outcome;
use crate::errln;
use crate::outln;
use anyhow::Context;
use crosscal::diagnose::compare;
use crosscal::estimate::FitOptions;
use crosscal::estimate::{fit_runs, tracks};
use crosscal::html::plot;
use crosscal::motion::DerivativeConfig;
use crosscal::session::{MotionSpec, Session};
use std::path::PathBuf;

/// Options of `compare`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// The session manifest (session.json).
    session: PathBuf,
    /// Write an SVG plot of the residual falling along the ladder.
    #[arg(long)]
    svg: Option<PathBuf>,
    /// Print the ladder as JSON.
    #[arg(long)]
    json: bool,
    /// Add a rung with these effects (comma-separated ids, or `all` for the whole catalogue);
    /// repeatable.
    #[arg(long = "with")]
    with: Vec<String>,
    /// Replace output files that already exist (never a device, FIFO or folder).
    #[arg(long)]
    force: bool,
}

pub fn run(a: Args) -> anyhow::Result<Outcome> {
    let session = Session::load(&a.session).with_context(|| format!("reading session {}", a.session.display()))?;
    if session.is_protocol() {
        anyhow::bail!(
            "{} is a protocol session: `compare` ranks models on stand runs; use `crosscal diagnose` for its candidate effects",
            a.session.display()
        );
    }
    let tr = tracks(&session, &DerivativeConfig::default());
    let runs = fit_runs(&session, &tr);
    let motions: Vec<&MotionSpec> = session.runs.iter().map(|r| &r.spec.motion).collect();
    let extra: Vec<Vec<String>> = a
        .with
        .iter()
        .map(|w| {
            if w == "all" {
                let has_temp = session.runs.iter().all(|r| r.rec.temp_c.is_some() || r.spec.temperature_c.is_some());
                let needs_temp: Vec<&str> =
                    crosscal::model::catalog().iter().filter(|e| e.needs_temperature()).map(|e| e.id()).collect();
                crosscal::model::all_effect_ids()
                    .into_iter()
                    .filter(|id| has_temp || !needs_temp.contains(id))
                    .map(str::to_string)
                    .collect()
            } else {
                w.split(',').map(|s| s.trim().to_string()).collect()
            }
        })
        .collect();
    for e in extra.iter().flatten() {
        if !crosscal::model::all_effect_ids().contains(&e.as_str()) {
            anyhow::bail!("--with {e}: unknown effect (see `crosscal effects`)");
        }
    }
    let (rungs, d) = compare(&runs, &motions, &FitOptions::default(), &extra)?;
    if a.json {
        outln!("{}", serde_json::to_string_pretty(&rungs)?);
    } else {
        outln!(
            "model ladder for unit {} ({} runs); residual RMS in units of each channel's noise floor",
            session.manifest.serial,
            session.runs.len()
        );
        outln!(
            "{:<30} {:>6} {:>7} {:>7} {:>7} {:>7} {:>7} {:>7} {:>14} {:>11} {:>11} {:>9}",
            "model",
            "params",
            "gx",
            "gy",
            "gz",
            "ax",
            "ay",
            "az",
            "BIC",
            "gyro red.",
            "accel red.",
            "held-out"
        );
        for r in &rungs {
            let rel: Vec<String> =
                (0..6).map(|c| format!("{:.2}", r.rms[c] / r.noise_floor[c].max(f64::MIN_POSITIVE))).collect();
            let held = if r.heldout_rms.is_empty() {
                "-".to_string()
            } else {
                let worst =
                    (0..6).map(|c| r.heldout_rms[c] / r.noise_floor[c].max(f64::MIN_POSITIVE)).fold(0.0, f64::max);
                format!("{worst:.4}")
            };
            let name = if r.model.len() > 30 { format!("{}…", &r.model[..29]) } else { r.model.clone() };
            outln!(
                "{:<30} {:>6} {:>7} {:>7} {:>7} {:>7} {:>7} {:>7} {:>14.1} {:>10.1}x {:>10.1}x {:>9}",
                name,
                r.params,
                rel[0],
                rel[1],
                rel[2],
                rel[3],
                rel[4],
                rel[5],
                r.bic,
                r.reduction[0],
                r.reduction[1],
                held
            );
        }
        outln!("(channels: in-sample residual RMS / noise floor; held-out: worst channel's leave-one-run-out RMS / noise floor)");
        for r in rungs.iter().skip(1).filter(|r| !r.heldout_gain) {
            outln!("no held-out gain: '{}' does not predict left-out runs better than the rung before it: its extra terms fit noise", r.model);
        }
        conclusion(&d)?;
    }
    if let Some(path) = &a.svg {
        let names = ["gyro x", "gyro y", "gyro z", "accel x", "accel y", "accel z"];
        let series: Vec<(String, Vec<f64>)> = (0..6)
            .map(|c| {
                let ys = rungs.iter().map(|r| r.rms[c] / r.noise_floor[c].max(f64::MIN_POSITIVE)).collect();
                (names[c].to_string(), ys)
            })
            .collect();
        let labels: Vec<String> = rungs.iter().map(|r| r.model.clone()).collect();
        let svg = plot::ladder(
            &format!("Model ladder of unit {}: residual RMS per channel, in noise floors", session.manifest.serial),
            "residual RMS / noise floor (log)",
            &labels,
            &series,
        );
        super::write_output(path, a.force, svg.as_bytes())?;
        errln!("plot written to {}", path.display());
    }
    Ok(Outcome::Ok)
}

/// The stand's findings the ladder's motion carries, and the verdict.
fn conclusion(d: &crosscal::diagnose::Diagnosis) -> anyhow::Result<()> {
    if !d.stand.is_empty() {
        outln!("the ladder is on the motion the stand's findings correct (`diagnose` says more):");
        for f in &d.stand {
            outln!("  {}", f.message);
        }
    }
    outln!(
        "verdict: {:?}{}",
        d.verdict,
        if d.proposal.is_empty() { String::new() } else { format!(": add {}", d.proposal.join(", ")) }
    );
    Ok(())
}
