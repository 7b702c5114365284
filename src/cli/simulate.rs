//! `crosscal simulate`.

use super::{parse_list, parse_triple, List, Outcome};
use crate::outln;
use anyhow::Context;
use crosscal::app::simulate::SimulateOptions;
use crosscal::simulate::write_session;
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
    /// Let the flicker and random walk run on from run to run over the session clock (the
    /// bias wanders between runs as a real unit's does) instead of restarting in each run.
    #[arg(long)]
    carry_noise: bool,
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
    /// sine:CHANNEL:FREQ_HZ:AMPLITUDE, saturate:SENSOR:LIMIT, knee:CHANNEL:LEVEL:SLOPE,
    /// clip:CHANNEL:LIMIT or turnon:CHANNEL:SIGMA (a different offset in each run) (deg/s or g;
    /// channels gyro-y …).
    #[arg(long = "disturb", value_parser = crosscal::simulate::realism::Disturbance::parse)]
    disturb: Vec<crosscal::simulate::realism::Disturbance>,
    /// The stand moved otherwise than the manifest says (repeatable, KEY=VALUE): cone=DEG
    /// (added to every cone angle), rate=REL (−0.005: 0.5 % slow), drift=REL_PER_S[,…] (per
    /// conic run, in turn: its rate changes by this share per second from its first sample), phase=DEG[,DEG…] (per
    /// conic run, in turn), tilt=DEG,DEG (base tilt about x, y), ripple1=REL,PHASE_DEG and
    /// ripple2=REL,PHASE_DEG (speed ripple once and twice per revolution), wobble=DEG,PHASE_DEG
    /// (cone-axis wobble), mount=RUN:+y,+x,-z (a run recorded on another mount),
    /// earth=LAT_DEG,HEADING_DEG (the Earth's rotation, undeclared), spinup=S (each conic
    /// run recorded from rest, the stand at speed after S seconds); and encoder=RES_DEG: the
    /// stand logs its angle with this resolution (0: exact) in a `theta_deg` column of each
    /// conic run, named by the run's `angle_column` (the fit then follows it), with
    /// encoder-offset=DEG: the encoder's zero this far off the stand's.
    #[arg(long = "stand", value_name = "KEY=VALUE")]
    stand: Vec<String>,
}

fn parse_set(s: &str) -> Result<(String, f64), String> {
    let (name, value) = s.split_once('=').ok_or_else(|| format!("expected NAME=VALUE, found '{s}'"))?;
    let v: f64 = value.trim().parse().map_err(|_| format!("'{value}' is not a number"))?;
    if !v.is_finite() {
        return Err(format!("'{value}' is not finite"));
    }
    Ok((name.trim().to_string(), v))
}

impl Args {
    /// The flags as the library's simulation settings.
    fn options(&self) -> SimulateOptions {
        SimulateOptions {
            preset: self.preset.clone(),
            gyro_noise_deg_s: self.gyro_noise,
            accel_noise_g: self.accel_noise,
            gyro_bias_deg_s: self.gyro_bias,
            accel_bias_g: self.accel_bias,
            seed: self.seed,
            rates_deg_s: self.runs.rates.0.clone(),
            cone_angles_deg: self.runs.cone_angles.0.clone(),
            mounts: self.runs.mounts as usize,
            duration_s: self.runs.duration,
            rate_hz: self.runs.rate_hz,
            serial: self.serial.clone(),
            hidden: self.hidden.clone(),
            set: self.set.clone(),
            temperature_c: self.temperature.as_ref().map(|l| l.0.clone()),
            arw_deg_rt_h: self.arw,
            gyro_bias_instability_deg_h: self.gyro_bias_instability,
            rrw_deg_h_rt_h: self.rrw,
            vrw_m_s_rt_h: self.vrw,
            accel_bias_instability_ug: self.accel_bias_instability,
            accel_random_walk: self.accel_random_walk,
            carry_noise: self.carry_noise,
            ar1: self.ar1,
            quantize: self.quantize.as_ref().map(|l| match l.0.as_slice() {
                [g, a] => [*g, *a],
                _ => [f64::NAN; 2],
            }),
            jitter_ms: self.jitter_ms,
            session_clock_s: self.session_clock,
            si_units: self.si_units,
            disturb: self.disturb.clone(),
            stand: self.stand.clone(),
            temp_noise_c: self.temp_noise,
            temp_quantum_c: self.temp_quantum,
        }
    }
}

pub fn run(a: Args) -> anyhow::Result<Outcome> {
    let mut cfg = crosscal::app::simulate::config(&a.options())?;
    if let Some(List(plateaus)) = &a.thermal_sweep {
        if a.preset != "paper" {
            anyhow::bail!("--thermal-sweep records its own runs at each plateau: leave out --preset {}", a.preset);
        }
        a.sweep.sweep(plateaus, &a.runs)?.apply(&mut cfg).map_err(anyhow::Error::msg)?;
        crosscal::simulate::check_runs(&cfg.runs, cfg.sample_rate_hz).map_err(anyhow::Error::msg)?;
    }
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
