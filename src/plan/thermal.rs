//! Planning a thermal calibration: how well a chamber sweep (plateaus, the runs at each, their
//! duration) determines each sensor's bias as a polynomial of degree d in (T − 20 °C), before
//! anything is recorded.
//!
//! The design is simulated noiseless ([`super::predict_config`], the plan's own fit with a
//! known σ), so every coefficient's covariance is the Cramér–Rao bound σ² (ΦᵀΦ)⁻¹ of the
//! white-noise model. The compensated bias of axis i at temperature T is
//! b̂ᵢ(T) = b̂ᵢ + Σₖ t̂bₖᵢ (T − 20)ᵏ, a linear function gᵀθ̂ of the coefficients with
//! g = (1, (T − 20), …, (T − 20)ᵈ), so its variance is gᵀ Σ g with Σ the covariance block of
//! those coefficients (the variance of a linear combination). The plan reports the worst over
//! the calibrated range (401 temperatures) and over the three axes.
//!
//! Lengthening every run by a factor f repeats the static rows of the design f times, so the
//! covariance scales as 1/f (exactly for static faces at settled plateaus, nearly for conic
//! runs): the dwell meeting a target is the current one × (worst std / target)², confirmed by
//! predicting the longer design. The reading noise of the temperature sensor is not in the
//! bound (it adds |db/dT| × σ_T to the output noise, small against a sensor's noise).

use super::{predict_config, PlannedCoefficient};
use crate::estimate::{CoefStatus, EstimateError, Fit};
use crate::model::{Model, T_REF_C};
use crate::simulate::thermal::ThermalSweep;
use crate::simulate::SimConfig;
use crate::units::{SensorKind, AXES};
use serde::Serialize;

/// A thermal design to predict.
#[derive(Debug, Clone)]
pub struct ThermalPlanSpec {
    /// The sweep: plateaus, the runs at each (their durations are the dwell), soak, lag.
    pub sweep: ThermalSweep,
    /// Sample rate, Hz.
    pub sample_rate_hz: f64,
    /// Gyro white-noise density, rad/s/√Hz.
    pub gyro_density: f64,
    /// Accelerometer white-noise density, m/s²/√Hz.
    pub accel_density: f64,
    /// Degree of the bias polynomial in temperature (1 to 3), both sensors.
    pub degree: i32,
    /// Target standard uncertainty of the compensated bias over the range: gyro rad/s,
    /// accelerometer m/s².
    pub target_bias_std: Option<[f64; 2]>,
}

impl ThermalPlanSpec {
    /// Per-sample σ of every channel (gx..az).
    fn sigma(&self) -> [f64; 6] {
        let r = self.sample_rate_hz.sqrt();
        let (g, a) = (self.gyro_density * r, self.accel_density * r);
        [g, g, g, a, a, a]
    }

    /// The same design with every plateau run `factor` times as long (whole samples).
    fn scaled(&self, factor: f64) -> Self {
        let mut s = self.clone();
        for r in &mut s.sweep.runs {
            r.duration_s = (r.duration_s * factor * self.sample_rate_hz).ceil().max(1.0) / self.sample_rate_hz;
        }
        s
    }
}

/// How well one sensor's compensated bias is determined over the range.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct BiasUncertainty {
    /// `gyro` or `accel`.
    pub sensor: SensorKind,
    /// SI unit of the standard uncertainties.
    pub unit: String,
    /// Standard uncertainty of the compensated bias at the worst temperature, per axis (None:
    /// a coefficient it needs is unidentifiable from the design).
    pub worst_std_by_axis: Vec<Option<f64>>,
    /// The worst over axes and temperatures (None: unknown on some axis).
    pub worst_std: Option<f64>,
    /// The axis and temperature, °C, of the worst.
    pub worst_at: Option<(char, f64)>,
    /// The target, when one was given.
    pub target: Option<f64>,
}

/// A run duration (dwell) meeting the target.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct DwellSuggestion {
    /// Duration of a run at a plateau (the first; every run is scaled alike), s.
    pub run_duration_s: f64,
    /// Recorded time per plateau, s.
    pub dwell_s: f64,
    /// The whole sweep's length with it (ramps, soaks and runs), s.
    pub sweep_s: f64,
    /// Predicted worst standard uncertainty (gyro, accel) with it.
    pub worst_std: [Option<f64>; 2],
    /// Whether the prediction meets every target.
    pub meets: bool,
}

/// An extra plateau and what it would give.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct PlateauSuggestion {
    /// Set point of the extra plateau, °C.
    pub at_c: f64,
    /// Predicted worst standard uncertainty (gyro, accel) with it, at the same dwell.
    pub worst_std: [Option<f64>; 2],
}

/// What a thermal design would determine.
#[derive(Debug, Clone, Serialize)]
pub struct ThermalPlanReport {
    /// Plateau set points, °C.
    pub plateaus_c: Vec<f64>,
    /// Degree of the bias polynomials.
    pub degree: i32,
    /// Range the compensation is judged over (lowest and highest plateau), °C.
    pub range_c: [f64; 2],
    /// Runs per plateau.
    pub runs_per_plateau: usize,
    /// Recorded time per plateau, s.
    pub dwell_s: f64,
    /// The whole sweep's length (ramps, soaks and runs), s.
    pub sweep_s: f64,
    /// Samples per channel.
    pub samples: usize,
    /// Per-sample σ used (gx..az, SI).
    pub sigma: [f64; 6],
    /// The bias and temperature-bias coefficients of both sensors.
    pub coefficients: Vec<PlannedCoefficient>,
    /// Compensated-bias uncertainty, gyro then accelerometer.
    pub bias: Vec<BiasUncertainty>,
    /// The run duration meeting the targets, when targets were given.
    pub dwell: Option<DwellSuggestion>,
    /// The extra plateau (a midpoint between two) that most lowers the worst uncertainty, when
    /// one lowers it by 10 % or more.
    pub extra_plateau: Option<PlateauSuggestion>,
}

/// The model of a thermal plan: `model` with the temperature-bias terms of degree 1 … d of
/// both sensors.
pub fn thermal_model(model: &Model, degree: i32) -> Result<Model, crate::model::ModelError> {
    let mut m = model.clone();
    for sensor in SensorKind::BOTH {
        for d in 1..=degree.clamp(1, 3) {
            let suffix = if d == 1 { String::new() } else { d.to_string() };
            m.add_effect(&format!("{}-temp-bias{suffix}", sensor.as_str()))?;
        }
    }
    Ok(m)
}

/// The coefficient names of axis `ax`'s bias polynomial, degree 0 (the bias) to `degree`.
fn poly_names(sensor: SensorKind, ax: char, degree: i32) -> Vec<String> {
    let s = sensor.as_str();
    (0..=degree)
        .map(|k| match k {
            0 => format!("{s}.b_{ax}"),
            1 => format!("{s}.tb_{ax}"),
            _ => format!("{s}.tb{k}_{ax}"),
        })
        .collect()
}

/// The standard uncertainty of the compensated bias of one axis at `temp_c` (gᵀ Σ g, module
/// doc); None when a coefficient is unidentifiable. Held coefficients add nothing.
fn bias_std(fit: &Fit, sensor: SensorKind, axis: usize, degree: i32, temp_c: f64) -> Option<f64> {
    let sf = fit.sensor(sensor);
    let ch = sf.channels.get(axis)?;
    let names = poly_names(sensor, AXES[axis], degree);
    let mut idx = Vec::with_capacity(names.len());
    for (k, n) in names.iter().enumerate() {
        match sf.coefficients.iter().find(|c| &c.name == n).map(|c| c.status) {
            Some(CoefStatus::Fitted) => idx.push((k, ch.covariance_names.iter().position(|c| c == n)?)),
            Some(CoefStatus::Fixed) => {}
            _ => return None,
        }
    }
    let d = temp_c - T_REF_C;
    let mut var = 0.0;
    for &(ka, ia) in &idx {
        for &(kb, ib) in &idx {
            var += d.powi(ka as i32) * d.powi(kb as i32) * ch.covariance.get(ia)?.get(ib)?;
        }
    }
    Some(var.max(0.0).sqrt())
}

/// The worst compensated-bias uncertainty of each sensor over `range_c`.
fn bias_uncertainty(fit: &Fit, spec: &ThermalPlanSpec, range_c: [f64; 2]) -> Vec<BiasUncertainty> {
    SensorKind::BOTH
        .iter()
        .map(|&sensor| {
            let mut by_axis = Vec::with_capacity(3);
            let mut worst: Option<(f64, char, f64)> = None;
            for (i, &ax) in AXES.iter().enumerate() {
                let mut axis_worst: Option<f64> = Some(0.0);
                for j in 0..=400 {
                    let t = range_c[0] + (range_c[1] - range_c[0]) * f64::from(j) / 400.0;
                    match bias_std(fit, sensor, i, spec.degree, t) {
                        Some(s) => {
                            axis_worst = axis_worst.map(|w| w.max(s));
                            if worst.is_none_or(|w| s > w.0) {
                                worst = Some((s, ax, t));
                            }
                        }
                        None => axis_worst = None,
                    }
                }
                by_axis.push(axis_worst);
            }
            let known = by_axis.iter().all(Option::is_some);
            BiasUncertainty {
                sensor,
                unit: if sensor == SensorKind::Gyro { "rad/s" } else { "m/s^2" }.to_string(),
                worst_std_by_axis: by_axis,
                worst_std: worst.filter(|_| known).map(|w| w.0),
                worst_at: worst.filter(|_| known).map(|w| (w.1, w.2)),
                target: spec.target_bias_std.map(|t| t[sensor.index()]),
            }
        })
        .collect()
}

/// The prediction of one design: the fit, the bias uncertainties, samples per channel.
fn predict_sweep(model: &Model, spec: &ThermalPlanSpec) -> Result<(Fit, Vec<BiasUncertainty>), EstimateError> {
    let mut cfg = SimConfig { sample_rate_hz: spec.sample_rate_hz, ..SimConfig::paper() };
    spec.sweep.apply(&mut cfg).map_err(EstimateError::Request)?;
    let (fit, _) = predict_config(model, &cfg, spec.sigma())?;
    let bias = bias_uncertainty(&fit, spec, range_of(&spec.sweep.plateaus_c));
    Ok((fit, bias))
}

fn range_of(plateaus_c: &[f64]) -> [f64; 2] {
    plateaus_c.iter().fold([f64::INFINITY, f64::NEG_INFINITY], |[lo, hi], &t| [lo.min(t), hi.max(t)])
}

fn worst_pair(bias: &[BiasUncertainty]) -> [Option<f64>; 2] {
    [bias.first().and_then(|b| b.worst_std), bias.get(1).and_then(|b| b.worst_std)]
}

/// The largest (worst std / target)² over the sensors with a target; None when a worst is
/// unknown.
fn shortfall(worst: [Option<f64>; 2], target: [f64; 2]) -> Option<f64> {
    let mut f: f64 = 0.0;
    for i in 0..2 {
        if target[i] > 0.0 {
            f = f.max((worst[i]? / target[i]).powi(2));
        }
    }
    Some(f)
}

/// The sweep's length: ramps, soaks and every run, s.
fn sweep_length_s(sweep: &ThermalSweep) -> f64 {
    let (runs, chamber) = sweep.schedule();
    runs.last().and_then(|r| chamber.run_start_s(runs.len() - 1).map(|s| s + r.duration_s)).unwrap_or(0.0)
}

/// The run durations meeting the targets: every run scaled by the shortfall, confirmed by
/// predicting the longer design (one that does not scale exactly is scaled again, at most
/// four times).
fn suggest_dwell(
    model: &Model,
    spec: &ThermalPlanSpec,
    worst: [Option<f64>; 2],
    target: [f64; 2],
) -> Result<Option<DwellSuggestion>, EstimateError> {
    let Some(mut f) = shortfall(worst, target).filter(|f| *f > 0.0) else { return Ok(None) };
    let mut factor = 1.0;
    let mut last = None;
    for _ in 0..4 {
        factor *= f;
        let s = spec.scaled(factor);
        let (_, bias) = predict_sweep(model, &s)?;
        let w = worst_pair(&bias);
        let Some(nf) = shortfall(w, target) else { return Ok(None) };
        last = Some(DwellSuggestion {
            run_duration_s: s.sweep.runs.first().map_or(0.0, |r| r.duration_s),
            dwell_s: s.sweep.runs.iter().map(|r| r.duration_s).sum(),
            sweep_s: sweep_length_s(&s.sweep),
            worst_std: w,
            meets: nf <= 1.0,
        });
        if nf <= 1.0 {
            break;
        }
        f = nf * 1.02;
    }
    Ok(last)
}

/// The extra plateau, among the midpoints of neighbouring plateaus, that most lowers the
/// worst uncertainty relative to the current design (10 % at least).
fn suggest_plateau(
    model: &Model,
    spec: &ThermalPlanSpec,
    worst: [Option<f64>; 2],
) -> Result<Option<PlateauSuggestion>, EstimateError> {
    let mut sorted = spec.sweep.plateaus_c.clone();
    sorted.sort_by(f64::total_cmp);
    sorted.dedup();
    let mut best: Option<(f64, PlateauSuggestion)> = None;
    for w in sorted.windows(2) {
        let at_c = 0.5 * (w[0] + w[1]);
        let mut s = spec.clone();
        let pos = s.sweep.plateaus_c.iter().position(|&p| p > at_c).unwrap_or(s.sweep.plateaus_c.len());
        s.sweep.plateaus_c.insert(pos, at_c);
        let (_, bias) = predict_sweep(model, &s)?;
        let new = worst_pair(&bias);
        // The larger relative worst of the two sensors (unknown before: any known is better).
        let ratio = (0..2)
            .map(|i| match (worst[i], new[i]) {
                (Some(a), Some(b)) if a > 0.0 => b / a,
                (None, Some(_)) => 0.0,
                (_, None) => f64::INFINITY,
                _ => 1.0,
            })
            .fold(0.0, f64::max);
        if ratio < 0.9 && best.as_ref().is_none_or(|b| ratio < b.0) {
            best = Some((ratio, PlateauSuggestion { at_c, worst_std: new }));
        }
    }
    Ok(best.map(|b| b.1))
}

/// Predicts a thermal design: the uncertainty of the compensated bias across the range, the
/// run duration meeting the targets (when given) and, with `suggest`, the best extra plateau.
pub fn plan_thermal(model: &Model, spec: &ThermalPlanSpec, suggest: bool) -> Result<ThermalPlanReport, EstimateError> {
    spec.sweep.check().map_err(EstimateError::Request)?;
    if !(1..=3).contains(&spec.degree) {
        return Err(EstimateError::Request(format!("degree {}: expected 1, 2 or 3", spec.degree)));
    }
    if let Some(t) = spec.target_bias_std.filter(|t| !t.iter().all(|v| v.is_finite() && *v >= 0.0)) {
        return Err(EstimateError::Request(format!("target bias std {t:?}: expected non-negative SI values")));
    }
    let model = thermal_model(model, spec.degree).map_err(|e| EstimateError::Request(e.to_string()))?;
    let (fit, bias) = predict_sweep(&model, spec)?;
    let worst = worst_pair(&bias);
    let sigma = spec.sigma();
    let coefficients = SensorKind::BOTH
        .iter()
        .flat_map(|&s| AXES.iter().flat_map(move |&ax| poly_names(s, ax, spec.degree)))
        .filter_map(|n| {
            let c = fit.gyro.coefficients.iter().chain(&fit.accel.coefficients).find(|c| c.name == n)?;
            Some(PlannedCoefficient {
                name: c.name.clone(),
                unit: c.unit.clone(),
                status: c.status,
                std_error: c.std_error,
                output_error: None,
            })
        })
        .collect();
    let dwell = match spec.target_bias_std {
        Some(t) => suggest_dwell(&model, spec, worst, t)?,
        None => None,
    };
    let extra_plateau = if suggest { suggest_plateau(&model, spec, worst)? } else { None };
    let runs = spec.sweep.runs.len();
    Ok(ThermalPlanReport {
        plateaus_c: spec.sweep.plateaus_c.clone(),
        degree: spec.degree,
        range_c: range_of(&spec.sweep.plateaus_c),
        runs_per_plateau: runs,
        dwell_s: spec.sweep.runs.iter().map(|r| r.duration_s).sum(),
        sweep_s: sweep_length_s(&spec.sweep),
        samples: fit.gyro.channels.first().map_or(0, |c| c.n as usize),
        sigma,
        coefficients,
        bias,
        dwell,
        extra_plateau,
    })
}
