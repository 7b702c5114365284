//! Simulate a unit on a stand: the settings a user gives (the command's flags, the Python
//! package's keywords) checked and turned into a [`SimConfig`], in display units (deg/s,
//! g, °/√h …) converted to SI here, once for every caller.

use super::AppError;
use crate::simulate::realism::Disturbance;
use crate::simulate::SimConfig;
use crate::units::{SensorKind, AXES};

/// What to simulate, in the units users give it (the defaults are the command's).
#[derive(Debug, Clone, PartialEq)]
pub struct SimulateOptions {
    /// `paper` (the paper's unit on its conic session) or `static` (at rest for `duration_s`).
    pub preset: String,
    /// Gyro white noise per sample, deg/s.
    pub gyro_noise_deg_s: f64,
    /// Accelerometer white noise per sample, g.
    pub accel_noise_g: f64,
    /// Gyro biases, deg/s.
    pub gyro_bias_deg_s: Option<[f64; 3]>,
    /// Accelerometer biases, g.
    pub accel_bias_g: Option<[f64; 3]>,
    /// Random seed of the noise.
    pub seed: u64,
    /// Stand rates, deg/s (sign = direction).
    pub rates_deg_s: Vec<f64>,
    /// Cone angles, degrees.
    pub cone_angles_deg: Vec<f64>,
    /// Cyclic mounts, 1 to 3.
    pub mounts: usize,
    /// Duration of each run, s.
    pub duration_s: f64,
    /// Sample rate, Hz.
    pub rate_hz: f64,
    /// Serial number of the unit.
    pub serial: Option<String>,
    /// Catalogue effects hidden in the unit.
    pub hidden: Vec<String>,
    /// True coefficients, NAME = VALUE in SI.
    pub set: Vec<(String, f64)>,
    /// Temperature breakpoints over the session, °C (evenly spaced in time, linear between).
    pub temperature_c: Option<Vec<f64>>,
    /// Gyro angle random walk, °/√h.
    pub arw_deg_rt_h: f64,
    /// Gyro bias instability, °/h.
    pub gyro_bias_instability_deg_h: f64,
    /// Gyro rate random walk, °/h/√h.
    pub rrw_deg_h_rt_h: f64,
    /// Accelerometer velocity random walk, m/s/√h.
    pub vrw_m_s_rt_h: f64,
    /// Accelerometer bias instability, µg.
    pub accel_bias_instability_ug: f64,
    /// Accelerometer random walk, m/s²/√s.
    pub accel_random_walk: f64,
    /// The flicker and random walk run on over the session clock from run to run (a real
    /// unit's bias wanders between runs) instead of restarting in each run.
    pub carry_noise: bool,
    /// First-order Gauss–Markov correlation per sample of the white noises.
    pub ar1: Option<f64>,
    /// Output resolutions [gyro, accel] in the file's units.
    pub quantize: Option<[f64; 2]>,
    /// Time-stamp jitter, ms.
    pub jitter_ms: f64,
    /// One session clock with this pause between runs, s.
    pub session_clock_s: Option<f64>,
    /// Write rad/s and m/s² instead of deg/s and g.
    pub si_units: bool,
    /// Disturbances outside the catalogue.
    pub disturb: Vec<Disturbance>,
    /// How the stand really moved, unknown to the manifest (`KEY=VALUE` each, see
    /// [`crate::simulate::stand::StandErrors::set`]).
    pub stand: Vec<String>,
    /// Temperature reading noise (standard deviation), °C.
    pub temp_noise_c: f64,
    /// Temperature reading step, °C (0: no rounding).
    pub temp_quantum_c: f64,
}

impl Default for SimulateOptions {
    fn default() -> Self {
        Self {
            preset: "paper".into(),
            gyro_noise_deg_s: 0.0,
            accel_noise_g: 0.0,
            gyro_bias_deg_s: None,
            accel_bias_g: None,
            seed: 1,
            rates_deg_s: vec![10.0, -10.0, 20.0],
            cone_angles_deg: vec![10.0, 20.0],
            mounts: 3,
            duration_s: 36.0,
            rate_hz: 100.0,
            serial: None,
            hidden: Vec::new(),
            set: Vec::new(),
            temperature_c: None,
            arw_deg_rt_h: 0.0,
            gyro_bias_instability_deg_h: 0.0,
            rrw_deg_h_rt_h: 0.0,
            vrw_m_s_rt_h: 0.0,
            accel_bias_instability_ug: 0.0,
            accel_random_walk: 0.0,
            carry_noise: false,
            ar1: None,
            quantize: None,
            jitter_ms: 0.0,
            session_clock_s: None,
            si_units: false,
            disturb: Vec::new(),
            stand: Vec::new(),
            temp_noise_c: 0.0,
            temp_quantum_c: 0.001,
        }
    }
}

fn invalid(msg: &str) -> AppError {
    AppError::Invalid(msg.to_string())
}

/// The simulator's configuration for `o`, or why `o` is not a simulation.
pub fn config(o: &SimulateOptions) -> Result<SimConfig, AppError> {
    if o.preset != "paper" && o.preset != "static" {
        return Err(AppError::Invalid(format!("unknown preset '{}': expected 'paper' or 'static'", o.preset)));
    }
    if !(o.duration_s > 0.0 && o.rate_hz > 0.0 && o.gyro_noise_deg_s >= 0.0 && o.accel_noise_g >= 0.0) {
        return Err(invalid("the duration and the sample rate must be positive and noise levels non-negative"));
    }
    if !(1..=3).contains(&o.mounts) {
        return Err(invalid("mounts must be 1, 2 or 3"));
    }
    let mut cfg = SimConfig::paper();
    cfg.gyro_noise_deg_s = o.gyro_noise_deg_s;
    cfg.accel_noise_g = o.accel_noise_g;
    if let Some(rho) = o.ar1 {
        if !(0.0..1.0).contains(&rho) {
            return Err(invalid("ar1 must be in [0, 1)"));
        }
        cfg.gyro_process.ar1 = Some((rho, o.gyro_noise_deg_s.to_radians()));
        cfg.accel_process.ar1 = Some((rho, o.accel_noise_g * cfg.g_m_s2));
        cfg.gyro_noise_deg_s = 0.0;
        cfg.accel_noise_g = 0.0;
    }
    if let Some([g, acc]) = o.quantize {
        if !(g >= 0.0 && acc >= 0.0) {
            return Err(invalid("quantize expects GYRO,ACCEL resolutions (non-negative)"));
        }
        cfg.realism.quantum = [g, acc];
    }
    if !(o.jitter_ms.is_finite() && o.jitter_ms >= 0.0) {
        return Err(invalid("the jitter must be finite and non-negative"));
    }
    cfg.realism.jitter_s = o.jitter_ms * 1e-3;
    if let Some(gap) = o.session_clock_s {
        if !(gap.is_finite() && gap >= 0.0) {
            return Err(invalid("the session clock expects a pause between runs in s (finite, non-negative)"));
        }
        cfg.realism.session_clock_gap_s = Some(gap);
    }
    cfg.realism.si_units = o.si_units;
    cfg.realism.disturbances = o.disturb.clone();
    for spec in &o.stand {
        cfg.stand.set(spec).map_err(|e| AppError::Invalid(format!("--stand {e}")))?;
    }
    cfg.seed = o.seed;
    cfg.sample_rate_hz = o.rate_hz;
    let mounts = crate::simulate::cyclic_mounts(o.mounts);
    cfg.runs = crate::simulate::conic_plan(&o.rates_deg_s, &o.cone_angles_deg, &mounts, o.duration_s);
    if o.preset == "static" {
        cfg.runs = SimConfig::static_recording(o.duration_s, o.rate_hz).runs;
    }
    noise_processes(o, &mut cfg)?;
    if let Some(s) = &o.serial {
        if !crate::session::valid_serial(s) {
            return Err(AppError::Invalid(format!(
                "'{s}' cannot be a serial: use letters, digits, '-', '_' or '.' (not starting with '.'), at most 128"
            )));
        }
        cfg.serial = s.clone();
    }
    truth(o, &mut cfg)?;
    if let Some(t) = &o.temperature_c {
        if t.len() < 2 || t.iter().any(|v| !(-100.0..=300.0).contains(v)) {
            return Err(invalid(
                "temperature_c (--temperature) expects START,END (or more breakpoints) in °C, each within -100..300",
            ));
        }
        cfg.temperature_c = Some(t.clone());
    }
    cfg.temp_reading = crate::simulate::thermal::TempReading { noise_c: o.temp_noise_c, quantum_c: o.temp_quantum_c };
    cfg.temp_reading.check().map_err(AppError::Invalid)?;
    crate::simulate::check_runs(&cfg.runs, cfg.sample_rate_hz).map_err(AppError::Invalid)?;
    Ok(cfg)
}

/// Coloured noise densities, display units to SI: °/√h → rad/s/√Hz; °/h → rad/s;
/// °/h/√h → rad/s/√s; m/s/√h → m/s²/√Hz; µg → m/s²; m/s²/√s stays.
fn noise_processes(o: &SimulateOptions, cfg: &mut SimConfig) -> Result<(), AppError> {
    let deg = std::f64::consts::PI / 180.0;
    let coloured = [
        o.arw_deg_rt_h,
        o.gyro_bias_instability_deg_h,
        o.rrw_deg_h_rt_h,
        o.vrw_m_s_rt_h,
        o.accel_bias_instability_ug,
        o.accel_random_walk,
    ];
    if coloured.iter().any(|v| !(v.is_finite() && *v >= 0.0)) {
        return Err(invalid("noise densities must be finite and non-negative"));
    }
    cfg.gyro_process.white_density = o.arw_deg_rt_h * deg / 60.0;
    cfg.gyro_process.bias_instability = o.gyro_bias_instability_deg_h * deg / 3600.0;
    cfg.gyro_process.random_walk = o.rrw_deg_h_rt_h * deg / 3600.0 / 60.0;
    cfg.accel_process.white_density = o.vrw_m_s_rt_h / 60.0;
    cfg.accel_process.bias_instability = o.accel_bias_instability_ug * 1e-6 * cfg.g_m_s2;
    cfg.accel_process.random_walk = o.accel_random_walk;
    cfg.carry_noise = o.carry_noise;
    Ok(())
}

/// The unit's true biases, hidden effects and coefficients.
fn truth(o: &SimulateOptions, cfg: &mut SimConfig) -> Result<(), AppError> {
    for (sensor, bias, k) in [
        (SensorKind::Gyro, o.gyro_bias_deg_s, std::f64::consts::PI / 180.0),
        (SensorKind::Accel, o.accel_bias_g, cfg.g_m_s2),
    ] {
        if let Some(b) = bias {
            for i in 0..3 {
                cfg.truth.values.insert(format!("{}.b_{}", sensor.as_str(), AXES[i]), b[i] * k);
            }
        }
    }
    for h in &o.hidden {
        cfg.truth
            .model
            .add_effect(h)
            .map_err(|source| AppError::Model { what: format!("the hidden effect '{h}'"), source })?;
    }
    for (name, v) in &o.set {
        if cfg.truth.value(name).is_none() {
            return Err(AppError::Invalid(format!(
                "set {name}: no such coefficient in the simulated unit's model (add its effect with --hidden)"
            )));
        }
        cfg.truth.values.insert(name.clone(), *v);
    }
    Ok(())
}
