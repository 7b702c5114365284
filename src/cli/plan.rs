//! `crosscal plan`: predicted uncertainties of a proposed calibration, before recording.

use super::{format, Outcome};
use crate::outln;
use anyhow::Context;
use crosscal::estimate::CoefStatus;
use crosscal::noise::NoiseReport;
use crosscal::plan::thermal::{plan_thermal, ThermalPlanSpec};
use crosscal::plan::{default_candidates, plan, PlanSpec};
use crosscal::units::SensorKind;
use std::path::PathBuf;

/// Options of `plan`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// The stand runs.
    #[command(flatten)]
    runs: super::RunSet,
    /// The model (for `check`: fitted with --holdout / --cross-validate).
    #[command(flatten)]
    model: super::ModelArgs,
    /// Gyro angle random walk (white-noise density), °/√h.
    #[arg(long, default_value_t = 0.15)]
    arw: f64,
    /// Accelerometer velocity random walk (white-noise density), m/s/√h.
    #[arg(long, default_value_t = 0.02)]
    vrw: f64,
    /// Take the white-noise densities (worst axis per sensor) from a profile with a noise
    /// section or from a `crosscal noise --save` file, instead of --arw/--vrw.
    #[arg(long)]
    noise_from: Option<PathBuf>,
    /// Predict the runs a session manifest describes (any subset of conic and static runs, in
    /// their mounts; `duration_s` per run for runs not yet recorded, else the recordings'
    /// spans and sample rate) instead of the factorial --rates × --cone-angles × --mounts.
    #[arg(long)]
    design: Option<PathBuf>,
    /// Plan a thermal calibration instead: a chamber sweep through these plateau set points,
    /// °C (the runs at each from --faces, --plateau-conic and --duration): the predicted
    /// uncertainty of each sensor's temperature-compensated bias across the range.
    #[arg(long = "thermal", alias = "thermal-sweep", value_parser = super::parse_list, allow_hyphen_values = true, conflicts_with = "design")]
    thermal_sweep: Option<super::List>,
    /// How the sweep runs in the chamber.
    #[command(flatten)]
    sweep: super::SweepArgs,
    /// Degree of the bias polynomial in temperature (1 to 3) the thermal plan identifies.
    #[arg(long, default_value_t = 3, value_parser = clap::value_parser!(i32).range(1..=3), requires = "thermal_sweep")]
    degree: i32,
    /// Target standard uncertainty of the compensated bias at the worst temperature of the
    /// range, GYRO,ACCEL in rad/s and m/s² (e.g. 1e-5,1e-3): the thermal plan suggests the run
    /// duration at each plateau meeting both.
    #[arg(long, value_parser = super::parse_list, requires = "thermal_sweep")]
    target_bias_std: Option<super::List>,
    /// Do not search for an extra run (or, with --thermal, an extra plateau).
    #[arg(long)]
    no_suggest: bool,
    /// Print the plan as JSON.
    #[arg(long)]
    json: bool,
}

/// The worst white-noise density of each sensor in a noise report (rad/s/√Hz, m/s²/√Hz).
fn densities(r: &NoiseReport) -> (Option<f64>, Option<f64>) {
    let worst =
        |s: SensorKind| r.channels.iter().filter(|c| c.sensor() == s).filter_map(|c| c.white()).reduce(f64::max);
    (worst(SensorKind::Gyro), worst(SensorKind::Accel))
}

pub fn run(a: Args) -> anyhow::Result<Outcome> {
    if !(a.runs.duration > 0.0 && a.runs.rate_hz > 0.0 && a.arw > 0.0 && a.vrw > 0.0) {
        anyhow::bail!("--duration, --rate-hz, --arw and --vrw must be positive");
    }
    let model = a.model.spec(&[]).build()?;
    let (runs, rate) = match &a.design {
        Some(path) => {
            let (runs, rate) =
                crosscal::plan::design_runs(path).with_context(|| format!("planning the design {}", path.display()))?;
            (runs, rate.unwrap_or(a.runs.rate_hz))
        }
        None => (a.runs.plan(), a.runs.rate_hz),
    };
    let mut spec =
        PlanSpec { runs, sample_rate_hz: rate, gyro_density: a.arw.to_radians() / 60.0, accel_density: a.vrw / 60.0 };
    if let Some(path) = &a.noise_from {
        // A unit's folder of the store: its newest profile.
        let newest;
        let path = if path.is_dir() {
            newest = crosscal::profile::Profile::read_or_latest(path)?.0;
            &newest
        } else {
            path
        };
        let text = crosscal::atomic::read_text(path).with_context(|| format!("reading {}", path.display()))?;
        let report: NoiseReport = match serde_json::from_str::<crosscal::profile::Profile>(&text) {
            Ok(p) => p.noise.ok_or_else(|| {
                anyhow::anyhow!(
                    "{}: the profile has no noise section (add one with `crosscal noise --store`)",
                    path.display()
                )
            })?,
            Err(_) => serde_json::from_str(&text)
                .with_context(|| format!("{}: neither a profile nor a noise report", path.display()))?,
        };
        let (g, acc) = densities(&report);
        spec.gyro_density = g.ok_or_else(|| anyhow::anyhow!("{}: no gyro white noise in it", path.display()))?;
        spec.accel_density =
            acc.ok_or_else(|| anyhow::anyhow!("{}: no accelerometer white noise in it", path.display()))?;
    }
    if let Some(super::List(plateaus)) = &a.thermal_sweep {
        return run_thermal(&a, plateaus, &model, &spec);
    }
    let candidates = if a.no_suggest { Vec::new() } else { default_candidates(&spec) };
    let r = plan(&model, &spec, &candidates)?;
    if a.json {
        outln!("{}", serde_json::to_string_pretty(&r)?);
        return Ok(Outcome::Ok);
    }
    outln!(
        "plan: {} runs, {} samples per channel; gyro σ {:.3e} deg/s, accel σ {:.3e} m/s^2 per sample",
        spec.runs.len(),
        r.samples,
        r.sigma[0].to_degrees(),
        r.sigma[3]
    );
    outln!("{:<22} {:>14} {:>14}  unit", "coefficient", "predicted 2σ", "output err/σ");
    for c in &r.coefficients {
        let (se, out) = match (c.status, c.std_error) {
            (CoefStatus::Fitted, Some(se)) => (format::num(2.0 * se), format!("{:.3e}", c.output_error.unwrap_or(0.0))),
            (CoefStatus::Unidentifiable, _) => ("UNIDENTIFIABLE".to_string(), "-".to_string()),
            _ => ("fixed".to_string(), "-".to_string()),
        };
        outln!("{:<22} {:>14} {:>14}  {}", c.name, se, out, c.unit);
    }
    for u in &r.unidentifiable {
        outln!("UNIDENTIFIABLE {}: {}\n  remedy: {}", u.held, u.reason, u.remedy);
    }
    for c in &r.correlated {
        outln!("correlated: {} and {} (ρ = {:+.3})", c.a, c.b, c.correlation);
    }
    if let Some((name, e)) = &r.worst {
        outln!("worst: {name} (output error {e:.3e} σ)");
    }
    match &r.suggestion {
        Some(s) => {
            outln!("suggested extra run: {}", s.run);
            if !s.resolves.is_empty() {
                outln!("  makes identifiable: {}", s.resolves.join(", "));
            }
            if let (Some(b), Some(a)) = (&s.worst_before, &s.worst_after) {
                outln!("  worst output error {:.3e} σ ({}) → {:.3e} σ ({})", b.1, b.0, a.1, a.0);
            }
        }
        None if !a.no_suggest => outln!("no candidate run improves the plan by 10 % or more"),
        None => {}
    }
    Ok(Outcome::Ok)
}

/// `plan --thermal`: the thermal design's prediction, in text or JSON.
fn run_thermal(a: &Args, plateaus: &[f64], model: &crosscal::model::Model, spec: &PlanSpec) -> anyhow::Result<Outcome> {
    let target = match a.target_bias_std.as_ref().map(|l| l.0.as_slice()) {
        None => None,
        Some(&[g, acc]) if g > 0.0 && acc > 0.0 => Some([g, acc]),
        Some(_) => anyhow::bail!("--target-bias-std expects GYRO,ACCEL: two positive values, rad/s and m/s^2"),
    };
    let t = ThermalPlanSpec {
        sweep: a.sweep.sweep(plateaus, &a.runs)?,
        sample_rate_hz: spec.sample_rate_hz,
        gyro_density: spec.gyro_density,
        accel_density: spec.accel_density,
        degree: a.degree,
        target_bias_std: target,
    };
    let r = plan_thermal(model, &t, !a.no_suggest)?;
    if a.json {
        outln!("{}", serde_json::to_string_pretty(&r)?);
        return Ok(Outcome::Ok);
    }
    let plateaus: Vec<String> = r.plateaus_c.iter().map(|p| format!("{p}")).collect();
    outln!(
        "thermal plan: plateaus {} degC, {} runs of {:.2} s per plateau ({:.1} s recorded each, sweep {:.0} s), degree {}",
        plateaus.join(", "),
        r.runs_per_plateau,
        t.sweep.runs.first().map_or(0.0, |x| x.duration_s),
        r.dwell_s,
        r.sweep_s,
        r.degree
    );
    outln!("{:<22} {:>14}  unit", "coefficient", "predicted 1σ");
    for c in &r.coefficients {
        let se = match (c.status, c.std_error) {
            (CoefStatus::Fitted, Some(se)) => format::num(se),
            (CoefStatus::Unidentifiable, _) => "UNIDENTIFIABLE".to_string(),
            _ => "fixed".to_string(),
        };
        outln!("{:<22} {:>14}  {}", c.name, se, c.unit);
    }
    for b in &r.bias {
        let target = b.target.map(|t| format!(" (target {t:.3e})")).unwrap_or_default();
        match (b.worst_std, b.worst_at) {
            (Some(s), Some((ax, at))) => outln!(
                "{} compensated bias: worst 1σ {s:.3e} {} at {at:.1} degC, axis {ax}{target}",
                b.sensor,
                b.unit
            ),
            _ => outln!(
                "{} compensated bias: UNKNOWN (a coefficient is unidentifiable: a degree-{} polynomial needs at least {} plateaus){target}",
                b.sensor,
                r.degree,
                r.degree + 1
            ),
        }
    }
    if let Some(d) = &r.dwell {
        let [g, acc] = d.worst_std.map(|v| v.map_or("unknown".to_string(), |v| format!("{v:.3e}")));
        outln!(
            "suggested run duration: {:.2} s ({:.1} s recorded per plateau, sweep {:.0} s): worst 1σ gyro {g} rad/s, accel {acc} m/s^2{}",
            d.run_duration_s,
            d.dwell_s,
            d.sweep_s,
            if d.meets { "" } else { " — still short of the target" }
        );
    }
    match &r.extra_plateau {
        Some(p) => {
            let [g, acc] = p.worst_std.map(|v| v.map_or("unknown".to_string(), |v| format!("{v:.3e}")));
            outln!("suggested extra plateau: {} degC: worst 1σ gyro {g} rad/s, accel {acc} m/s^2", p.at_c);
        }
        None if !a.no_suggest => outln!("no extra plateau lowers the worst uncertainty by 10 % or more"),
        None => {}
    }
    Ok(Outcome::Ok)
}
