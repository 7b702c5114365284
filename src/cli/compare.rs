//! `crosscal compare`: the model ladder.

use super::Outcome;
use anyhow::Context;
use crosscal::diagnose::{compare, plot};
use crosscal::estimate::FitOptions;
use crosscal::motion::DerivativeConfig;
use crosscal::pipeline::{fit_runs, tracks};
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
}

pub fn run(a: Args) -> anyhow::Result<Outcome> {
    let session = Session::load(&a.session).with_context(|| format!("reading session {}", a.session.display()))?;
    let tr = tracks(&session, &DerivativeConfig::default());
    let runs = fit_runs(&session, &tr);
    let motions: Vec<&MotionSpec> = session.runs.iter().map(|r| &r.spec.motion).collect();
    let (rungs, d) = compare(&runs, &motions, &FitOptions::default())?;
    if a.json {
        println!("{}", serde_json::to_string_pretty(&rungs)?);
    } else {
        println!(
            "model ladder for unit {} ({} runs); residual RMS in units of each channel's noise floor",
            session.manifest.serial,
            session.runs.len()
        );
        println!(
            "{:<30} {:>6} {:>7} {:>7} {:>7} {:>7} {:>7} {:>7} {:>14} {:>11} {:>11}",
            "model", "params", "gx", "gy", "gz", "ax", "ay", "az", "BIC", "gyro red.", "accel red."
        );
        for r in &rungs {
            let rel: Vec<String> =
                (0..6).map(|c| format!("{:.2}", r.rms[c] / r.noise_floor[c].max(f64::MIN_POSITIVE))).collect();
            println!(
                "{:<30} {:>6} {:>7} {:>7} {:>7} {:>7} {:>7} {:>7} {:>14.1} {:>10.1}x {:>10.1}x",
                r.model,
                r.params,
                rel[0],
                rel[1],
                rel[2],
                rel[3],
                rel[4],
                rel[5],
                r.bic,
                r.reduction[0],
                r.reduction[1]
            );
        }
        println!(
            "verdict: {:?}{}",
            d.verdict,
            if d.proposal.is_empty() { String::new() } else { format!(": add {}", d.proposal.join(", ")) }
        );
    }
    if let Some(path) = &a.svg {
        let names = ["gyro x", "gyro y", "gyro z", "accel x", "accel y", "accel z"];
        let series: Vec<(String, Vec<(f64, f64)>)> = (0..6)
            .map(|c| {
                let pts = rungs
                    .iter()
                    .enumerate()
                    .map(|(i, r)| (i as f64, r.rms[c] / r.noise_floor[c].max(f64::MIN_POSITIVE)))
                    .collect();
                (names[c].to_string(), pts)
            })
            .collect();
        let svg = plot::lines(
            "residual RMS / noise floor along the ladder (0 = paper model)",
            "ladder step",
            "RMS / noise floor",
            &series,
        );
        crosscal::atomic::write_atomic(path, true, |w| std::io::Write::write_all(w, svg.as_bytes()))
            .with_context(|| format!("writing {}", path.display()))?;
        eprintln!("plot written to {}", path.display());
    }
    Ok(Outcome::Ok)
}
