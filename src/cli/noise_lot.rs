//! `crosscal noise --lot DIR`: the noise of every unit of a lot recorded at rest, the spread
//! of each term over the lot, and each unit against the `noise` acceptance rules.

use super::noise::{analyse_one, Args};
use super::Outcome;
use crate::{out, outln};
use crosscal::check::rules::{evaluate_noise, Rules};
use crosscal::noise::{ChannelNoise, NoiseReport};
use crosscal::units::SensorKind;

/// A term of a channel in display units: white noise as ARW (°/√h) or VRW (m/s/√h), bias
/// instability (reading, else model fit) in °/h or µg, rate random walk in °/h/√h or
/// m/s²/√s.
fn terms(c: &ChannelNoise, g: f64) -> [Option<f64>; 3] {
    let (_, k) = c.sensor().display_unit();
    let walk = c.white_display(g).map(|w| w.1);
    let bi = c.bias();
    match c.sensor() {
        SensorKind::Gyro => [walk, bi.map(|b| b * k * 3600.0), c.random_walk.map(|v| v * k * 3600.0 * 60.0)],
        SensorKind::Accel => [walk, bi.map(|b| b / g * 1e6), c.random_walk],
    }
}

const TERMS: [(&str, &str, &str); 3] =
    [("ARW/VRW", "°/√h", "m/s/√h"), ("bias instability", "°/h", "µg"), ("random walk", "°/h/√h", "m/s²/√s")];

pub(super) fn run(a: &Args, chans: &[usize]) -> anyhow::Result<Outcome> {
    let rules = a.rules.as_ref().map(|p| Rules::read(p)).transpose()?;
    let mut dirs: Vec<_> = std::fs::read_dir(&a.recording)
        .map_err(|e| anyhow::anyhow!("reading the lot folder {}: {e}", a.recording.display()))?
        .flatten()
        .map(|e| e.path())
        .filter(|p| p.join("session.json").is_file())
        .collect();
    dirs.sort();
    if dirs.is_empty() {
        anyhow::bail!("{}: no unit folder with a session.json", a.recording.display());
    }
    let mut units: Vec<(String, NoiseReport, f64)> = Vec::with_capacity(dirs.len());
    for d in &dirs {
        let mut one = a.clone();
        (one.recording, one.lot, one.rules) = (d.join("session.json"), false, None);
        let name = d.file_name().map_or_else(|| d.display().to_string(), |n| n.to_string_lossy().into_owned());
        let (r, g, _) = analyse_one(&one, chans).map_err(|e| e.context(format!("unit {name}")))?;
        units.push((name, r, g));
    }
    outln!(
        "noise of a lot of {} units ({}); bias instability by the standard reading (measured minimum / 0.664) where the curve gives one",
        units.len(),
        a.recording.display()
    );
    outln!("{:<12} {:<4} {:>13} {:>17} {:>13}", "unit", "chan", TERMS[0].0, TERMS[1].0, TERMS[2].0);
    let fmt = |v: Option<f64>| v.map_or_else(|| "-".to_string(), |v| format!("{v:.4e}"));
    for (name, r, g) in &units {
        for c in &r.channels {
            let t = terms(c, *g);
            outln!("{:<12} {:<4} {:>13} {:>17} {:>13}", name, c.channel, fmt(t[0]), fmt(t[1]), fmt(t[2]));
        }
    }
    outln!("spread over the lot (median, robust σ = 1.4826·MAD, range; units with the term):");
    let channels: Vec<String> = units[0].1.channels.iter().map(|c| c.channel.clone()).collect();
    for ch in &channels {
        for (i, (term, gyro_unit, accel_unit)) in TERMS.iter().enumerate() {
            let mut v: Vec<f64> = units
                .iter()
                .filter_map(|(_, r, g)| r.channels.iter().find(|c| &c.channel == ch).and_then(|c| terms(c, *g)[i]))
                .collect();
            let Some(med) = crosscal::stats::median(&mut v) else { continue };
            let sigma = crosscal::stats::robust_sigma(&v, med).unwrap_or(0.0);
            let (lo, hi) = v.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |a, &x| (a.0.min(x), a.1.max(x)));
            let unit = if ch.starts_with('g') { gyro_unit } else { accel_unit };
            outln!(
                "  {ch} {term}: {med:.4e} ± {sigma:.2e} {unit} (range {lo:.4e}–{hi:.4e}; {} of {} units)",
                v.len(),
                units.len()
            );
        }
    }
    let Some(rules) = rules else { return Ok(Outcome::Ok) };
    let mut failed = 0;
    for (name, r, _) in &units {
        let results = evaluate_noise(&rules, r);
        let pass = results.iter().all(|x| x.pass);
        failed += usize::from(!pass);
        out!("{name}: {}", if pass { "pass" } else { "FAIL" });
        for x in results.iter().filter(|x| !x.pass) {
            out!(" — {}: {}", x.rule, x.detail);
        }
        outln!();
    }
    outln!("{} of {} units pass the noise rules", units.len() - failed, units.len());
    Ok(if failed == 0 { Outcome::Ok } else { Outcome::CheckFailed })
}
