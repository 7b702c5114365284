//! `crosscal simulate`.

use super::{parse_list, parse_triple, List, Outcome};
use crate::outln;
use anyhow::Context;
use crosscal::simulate::{write_session, SimConfig};
use crosscal::units::{SensorKind, AXES};
use std::path::PathBuf;

/// Options of `simulate`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Preset: `paper` (the paper's unit on its conic session) or `static` (the same unit at
    /// rest for --duration: a recording for `crosscal noise`).
    #[arg(long, default_value = "paper")]
    preset: String,
    /// Output folder (must not already hold a session).
    #[arg(short, long)]
    out: PathBuf,
    /// Gyro white noise per sample, deg/s.
    #[arg(long, default_value_t = 0.0)]
    gyro_noise: f64,
    /// Accelerometer white noise per sample, g.
    #[arg(long, default_value_t = 0.0)]
    accel_noise: f64,
    /// Gyro biases x,y,z in deg/s.
    #[arg(long, value_parser = parse_triple, allow_hyphen_values = true)]
    gyro_bias: Option<[f64; 3]>,
    /// Accelerometer biases x,y,z in g.
    #[arg(long, value_parser = parse_triple, allow_hyphen_values = true)]
    accel_bias: Option<[f64; 3]>,
    /// Random seed of the noise.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// The stand runs.
    #[command(flatten)]
    runs: super::RunSet,
    /// Serial number of the simulated unit.
    #[arg(long, value_parser = super::parse_serial)]
    serial: Option<String>,
    /// Hide a catalogue effect in the unit (repeatable); give its values with --set.
    #[arg(long = "hidden")]
    hidden: Vec<String>,
    /// Set a true coefficient, NAME=VALUE in SI units (repeatable), e.g. gyro.g_xx=1.8e-5.
    #[arg(long = "set", value_parser = parse_set)]
    set: Vec<(String, f64)>,
    /// Temperature over the session, °C: START,END (a ramp) or more breakpoints evenly spaced
    /// in time, linear between them (10,40,10 warms then cools; 20,20,60,60 plateau, ramp,
    /// plateau); adds a temp column.
    #[arg(long, value_parser = parse_list, allow_hyphen_values = true, conflicts_with = "thermal_sweep")]
    temperature: Option<List>,
    /// A production-line chamber sweep through these plateau set points, °C (e.g.
    /// -20,0,20,45,70): at each, after the soak, the static faces (and conic runs) for
    /// --duration each; the runs are named p1-face+z, p1-cone+10, …, their notes give the
    /// plateau and mark runs the unit had not settled for.
    #[arg(long, value_parser = parse_list, allow_hyphen_values = true)]
    thermal_sweep: Option<List>,
    /// How the sweep runs in the chamber.
    #[command(flatten)]
    sweep: super::SweepArgs,
    /// Temperature reading noise (standard deviation), °C, on the temp column; the outputs
    /// follow the true temperature.
    #[arg(long, default_value_t = 0.0)]
    temp_noise: f64,
    /// Temperature reading step, °C (the temp column is rounded to it; 0: no rounding).
    #[arg(long, default_value_t = 0.001)]
    temp_quantum: f64,
    /// Gyro angle random walk (white noise), °/√h.
    #[arg(long, default_value_t = 0.0)]
    arw: f64,
    /// Gyro bias instability (flicker), °/h.
    #[arg(long, default_value_t = 0.0)]
    gyro_bias_instability: f64,
    /// Gyro rate random walk, °/h/√h.
    #[arg(long, default_value_t = 0.0)]
    rrw: f64,
    /// Accelerometer velocity random walk (white noise), m/s/√h.
    #[arg(long, default_value_t = 0.0)]
    vrw: f64,
    /// Accelerometer bias instability (flicker), µg.
    #[arg(long, default_value_t = 0.0)]
    accel_bias_instability: f64,
    /// Accelerometer random walk, m/s²/√s.
    #[arg(long, default_value_t = 0.0)]
    accel_random_walk: f64,
    /// Make the --gyro-noise and --accel-noise first-order Gauss–Markov (AR(1)) with this
    /// correlation per sample, keeping their standard deviation (real sensors are rarely white).
    #[arg(long)]
    ar1: Option<f64>,
    /// Quantise the outputs to GYRO,ACCEL resolution in the file's units (e.g. 0.001,1e-5).
    #[arg(long, value_parser = parse_list)]
    quantize: Option<List>,
    /// Jitter the time stamps by this standard deviation, ms (the samples stay regular).
    #[arg(long, default_value_t = 0.0)]
    jitter_ms: f64,
    /// Let the time run on across the runs (one session clock), with this pause between
    /// runs, s.
    #[arg(long)]
    session_clock: Option<f64>,
    /// Write rad/s and m/s² instead of deg/s and g.
    #[arg(long)]
    si_units: bool,
    /// A disturbance outside the catalogue (repeatable): wobble:CHANNEL:HARMONIC:AMPLITUDE:EVERY,
    /// sine:CHANNEL:FREQ_HZ:AMPLITUDE or saturate:SENSOR:LIMIT (deg/s or g; channels gyro-y …).
    #[arg(long = "disturb", value_parser = crosscal::simulate::realism::Disturbance::parse)]
    disturb: Vec<crosscal::simulate::realism::Disturbance>,
}

fn parse_set(s: &str) -> Result<(String, f64), String> {
    let (name, value) = s.split_once('=').ok_or_else(|| format!("expected NAME=VALUE, found '{s}'"))?;
    let v: f64 = value.trim().parse().map_err(|_| format!("'{value}' is not a number"))?;
    if !v.is_finite() {
        return Err(format!("'{value}' is not finite"));
    }
    Ok((name.trim().to_string(), v))
}

pub fn run(a: Args) -> anyhow::Result<Outcome> {
    if a.preset != "paper" && a.preset != "static" {
        anyhow::bail!("unknown preset '{}': expected 'paper' or 'static'", a.preset);
    }
    if !(a.runs.duration > 0.0 && a.runs.rate_hz > 0.0 && a.gyro_noise >= 0.0 && a.accel_noise >= 0.0) {
        anyhow::bail!("--duration and --rate-hz must be positive and noise levels non-negative");
    }
    let mut cfg = SimConfig::paper();
    cfg.gyro_noise_deg_s = a.gyro_noise;
    cfg.accel_noise_g = a.accel_noise;
    if let Some(rho) = a.ar1 {
        if !(0.0..1.0).contains(&rho) {
            anyhow::bail!("--ar1 must be in [0, 1)");
        }
        cfg.gyro_process.ar1 = Some((rho, a.gyro_noise.to_radians()));
        cfg.accel_process.ar1 = Some((rho, a.accel_noise * cfg.g_m_s2));
        cfg.gyro_noise_deg_s = 0.0;
        cfg.accel_noise_g = 0.0;
    }
    if let Some(List(q)) = &a.quantize {
        match q.as_slice() {
            [g, acc] if *g >= 0.0 && *acc >= 0.0 => cfg.realism.quantum = [*g, *acc],
            _ => anyhow::bail!("--quantize expects GYRO,ACCEL resolutions (non-negative)"),
        }
    }
    if !(a.jitter_ms.is_finite() && a.jitter_ms >= 0.0) {
        anyhow::bail!("--jitter-ms must be finite and non-negative");
    }
    cfg.realism.jitter_s = a.jitter_ms * 1e-3;
    if let Some(gap) = a.session_clock {
        if !(gap.is_finite() && gap >= 0.0) {
            anyhow::bail!("--session-clock expects a pause between runs in s (finite, non-negative)");
        }
        cfg.realism.session_clock_gap_s = Some(gap);
    }
    cfg.realism.si_units = a.si_units;
    cfg.realism.disturbances = a.disturb.clone();
    cfg.seed = a.seed;
    cfg.sample_rate_hz = a.runs.rate_hz;
    cfg.runs = a.runs.plan();
    if a.preset == "static" {
        cfg.runs = SimConfig::static_recording(a.runs.duration, a.runs.rate_hz).runs;
    }
    let deg = std::f64::consts::PI / 180.0;
    let coloured = [a.arw, a.gyro_bias_instability, a.rrw, a.vrw, a.accel_bias_instability, a.accel_random_walk];
    if coloured.iter().any(|v| !(v.is_finite() && *v >= 0.0)) {
        anyhow::bail!("noise densities must be finite and non-negative");
    }
    // Display units to SI: °/√h → rad/s/√Hz; °/h → rad/s; °/h/√h → rad/s/√s; m/s/√h →
    // m/s²/√Hz; µg → m/s²; m/s²/√s stays.
    cfg.gyro_process.white_density = a.arw * deg / 60.0;
    cfg.gyro_process.bias_instability = a.gyro_bias_instability * deg / 3600.0;
    cfg.gyro_process.random_walk = a.rrw * deg / 3600.0 / 60.0;
    cfg.accel_process.white_density = a.vrw / 60.0;
    cfg.accel_process.bias_instability = a.accel_bias_instability * 1e-6 * cfg.g_m_s2;
    cfg.accel_process.random_walk = a.accel_random_walk;
    if let Some(s) = a.serial {
        cfg.serial = s;
    }
    for (sensor, bias, k) in
        [(SensorKind::Gyro, a.gyro_bias, std::f64::consts::PI / 180.0), (SensorKind::Accel, a.accel_bias, cfg.g_m_s2)]
    {
        if let Some(b) = bias {
            for i in 0..3 {
                cfg.truth.values.insert(format!("{}.b_{}", sensor.as_str(), AXES[i]), b[i] * k);
            }
        }
    }
    for h in &a.hidden {
        cfg.truth.model.add_effect(h)?;
    }
    for (name, v) in &a.set {
        if cfg.truth.value(name).is_none() {
            anyhow::bail!(
                "--set {name}: no such coefficient in the simulated unit's model (add its effect with --hidden)"
            );
        }
        cfg.truth.values.insert(name.clone(), *v);
    }
    if let Some(List(t)) = &a.temperature {
        if t.len() < 2 || t.iter().any(|v| !(-100.0..=300.0).contains(v)) {
            anyhow::bail!("--temperature expects START,END (or more breakpoints) in °C, each within -100..300");
        }
        cfg.temperature_c = Some(t.clone());
    }
    if let Some(List(plateaus)) = &a.thermal_sweep {
        if a.preset != "paper" {
            anyhow::bail!("--thermal-sweep records its own runs at each plateau: leave out --preset {}", a.preset);
        }
        a.sweep.sweep(plateaus, &a.runs)?.apply(&mut cfg).map_err(anyhow::Error::msg)?;
    }
    cfg.temp_reading = crosscal::simulate::thermal::TempReading { noise_c: a.temp_noise, quantum_c: a.temp_quantum };
    cfg.temp_reading.check().map_err(anyhow::Error::msg)?;
    crosscal::simulate::check_runs(&cfg.runs, cfg.sample_rate_hz).map_err(anyhow::Error::msg)?;
    let session = cfg.generate();
    let path =
        write_session(&session, &a.out).with_context(|| format!("writing the session to {}", a.out.display()))?;
    outln!(
        "wrote {} ({} runs, {} samples, serial {})",
        path.display(),
        session.runs.len(),
        session.n_samples(),
        session.manifest.serial
    );
    Ok(Outcome::Ok)
}
