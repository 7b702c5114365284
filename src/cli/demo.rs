//! `crosscal demo`: the whole pipeline on the paper's stand, ending in one table.

use super::{format, Outcome};
use crate::{out, outln};
use anyhow::Context;
use crosscal::app::validate::{check_session, Mode};
use crosscal::check::paper::paper_rows;
use crosscal::check::Thresholds;
use crosscal::correct::Calibration;
use crosscal::model::Model;
use crosscal::profile::{save, Profile};
use crosscal::session::Session;
use crosscal::simulate::{write_session, SimConfig};
use std::path::PathBuf;

/// Options of `demo`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Keep the generated session and profile in this folder (default: a temporary folder).
    #[arg(long)]
    keep: Option<PathBuf>,
}

pub fn run(a: Args) -> anyhow::Result<Outcome> {
    let tmp;
    let dir = match &a.keep {
        Some(d) => d.clone(),
        None => {
            tmp = tempfile::tempdir().context("creating a temporary folder")?;
            tmp.path().to_path_buf()
        }
    };
    let cfg = SimConfig::paper();
    outln!(
        "1. simulate: the paper's unit (C_w off-diagonal 0.01, C_e 0.001 s, K off-diagonal 0.01) on {} conic runs",
        cfg.runs.len()
    );
    let manifest = write_session(&cfg.generate(), &dir.join("session")).context("writing the demo session")?;
    let session = Session::load(&manifest)?;
    outln!("   {} ({} samples)", manifest.display(), session.n_samples());
    let model = Model::default_model();
    let fit = crosscal::estimate::fit(&crosscal::estimate::FitRequest::session(&model, &session))?.fit;
    let profile = Profile::from_fit(&session, &model, fit, session.warnings());
    let path = save(&profile, &dir.join("calib-profiles"))?;
    outln!("2. fit: model '{}' -> {}", profile.model, path.display());
    let worst = profile
        .gyro
        .coefficients
        .iter()
        .chain(&profile.accel.coefficients)
        .filter_map(|c| cfg.truth.value(&c.name).map(|truth| (c.value - truth).abs()))
        .fold(0.0, f64::max);
    outln!("   largest |fitted - true| coefficient error: {worst:.2e}");
    let profile = Profile::read(&path)?;
    let cal = Calibration::from_profile(&profile)?;
    let thresholds = Thresholds::default();
    let offline = check_session(&session, &cal, Mode::Offline, thresholds)?;
    let streaming = check_session(&session, &cal, Mode::Streaming, thresholds)?;
    outln!("3. correct + check, all {} runs (offline):", offline.runs.len());
    out!("{}", format::check_summary(&offline));
    let run = "cone+10";
    let rows = paper_rows(&offline, &streaming, run).context("the paper's run is missing from the demo session")?;
    outln!("\n4. the paper's configuration (run {run}: α = 10°, ω_s = 10 °/s, nominal mount):");
    outln!(
        "{:<6} {:<4} {:>12} {:>14} {:>12} {:>14} {:>22}  pass",
        "sensor",
        "axis",
        "before",
        "after",
        "reduction",
        "streaming",
        "paper before -> after"
    );
    for r in &rows {
        let before = r.paper_before_pct.map_or("-".to_string(), |p| format!("{p} %"));
        let paper = format!("{before} -> {} %", r.paper_after_pct);
        outln!(
            "{:<6} {:<4} {:>12} {:>14} {:>12} {:>14} {:>22}  {}",
            r.sensor.as_str(),
            r.axis,
            format::pct(r.before_pct),
            format::pct(r.offline_pct),
            format::ratio(r.reduction),
            format::pct(r.streaming_pct),
            paper,
            if r.pass { "yes" } else { "NO" }
        );
    }
    outln!("(pass: reduction >= the paper's (gyro 30x, accel 40000x), after <= the paper's, streaming <= the paper's / 100)");
    let pass = offline.pass && rows.iter().all(|r| r.pass);
    outln!("{}", if pass { "DEMO PASS" } else { "DEMO FAIL" });
    Ok(if pass { Outcome::Ok } else { Outcome::CheckFailed })
}
