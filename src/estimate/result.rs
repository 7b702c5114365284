//! What a fit returns: every coefficient with its standard error and status, per-channel
//! statistics and covariance, what the runs could not identify.

use super::{Correlation, EstimateError, NonlinearParam, StandParams, Unidentifiable};
use crate::units::SensorKind;
use serde::{Deserialize, Serialize};

/// How a coefficient's value was obtained.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum CoefStatus {
    /// Estimated from the data.
    Fitted,
    /// Held at a value by the model.
    Fixed,
    /// The runs cannot determine it; held at its nominal value.
    Unidentifiable,
}

/// One coefficient of a fitted model.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Coefficient {
    /// Name, e.g. `gyro.c_xy`.
    pub name: String,
    /// Effect id that defines it.
    pub effect: String,
    /// Output channel, 0..3.
    pub channel: usize,
    /// Unit (SI).
    pub unit: String,
    /// Value.
    pub value: f64,
    /// Standard error (fitted coefficients only).
    pub std_error: Option<f64>,
    /// How it was obtained.
    pub status: CoefStatus,
}

/// Fit statistics of one output channel.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ChannelFit {
    /// Axis letter.
    pub axis: char,
    /// Samples used.
    pub n: u64,
    /// Coefficients fitted on this channel.
    pub n_params: usize,
    /// Residual RMS (SI).
    pub residual_rms: f64,
    /// Largest |residual| (SI).
    pub residual_max: f64,
    /// Residual standard deviation with the dof correction, √(RSS/(n − q)).
    pub sigma: f64,
    /// Condition number of the column-scaled design of this channel.
    pub condition_number: f64,
    /// Names of the fitted coefficients, in covariance order.
    pub covariance_names: Vec<String>,
    /// Covariance of the fitted coefficients (row-major).
    pub covariance: Vec<Vec<f64>>,
    /// Samples the robust (Huber) fit gave less than full weight (0 without `--robust`).
    #[serde(default)]
    pub downweighted: u64,
    /// Variance inflation for a coloured (autocorrelated) residual: the residual's long-run
    /// variance over its variance (1 for white noise); the covariance includes it.
    #[serde(default = "one")]
    pub coloured_inflation: f64,
    /// Lag-1 autocorrelation of the residual (pooled over runs).
    #[serde(default)]
    pub residual_lag1: f64,
    /// Slow noise (flicker, bias random walk) read off the residual; the covariance includes
    /// its effect on the coefficients (the bias against its session average).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub slow_noise: Option<super::slow::SlowNoise>,
}

fn one() -> f64 {
    1.0
}

/// The fit of one sensor.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SensorFit {
    /// Which sensor.
    pub sensor: SensorKind,
    /// All coefficients of the model for this sensor, in model order.
    pub coefficients: Vec<Coefficient>,
    /// Per-channel statistics.
    pub channels: Vec<ChannelFit>,
    /// Lost combinations, each with the coefficient held and the run that would fix it.
    pub unidentifiable: Vec<Unidentifiable>,
    /// Pairs of fitted coefficients whose estimates correlate above 0.95.
    pub correlated: Vec<Correlation>,
}

impl SensorFit {
    /// Value of a coefficient by name.
    pub fn value(&self, name: &str) -> Option<f64> {
        self.coefficients.iter().find(|c| c.name == name).map(|c| c.value)
    }

    /// A coefficient by name.
    pub fn get(&self, name: &str) -> Option<&Coefficient> {
        self.coefficients.iter().find(|c| c.name == name)
    }
}

/// Fit of both sensors.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Fit {
    /// Gyro.
    pub gyro: SensorFit,
    /// Accelerometer.
    pub accel: SensorFit,
    /// Parameters of nonlinear effects (time delay, dead zone), if the model has any.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub nonlinear: Vec<NonlinearParam>,
    /// Estimated stand settings (cone angle, rate, phase) per conic run, when fitted.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub stand: Vec<StandParams>,
    /// The stand's imperfections common to its conic runs (tilt, ripple, wobble), when the
    /// stand settings were fitted.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub stand_base: Option<super::StandBase>,
}

impl Fit {
    /// The fit of one sensor.
    pub fn sensor(&self, s: SensorKind) -> &SensorFit {
        match s {
            SensorKind::Gyro => &self.gyro,
            SensorKind::Accel => &self.accel,
        }
    }

    /// The slow noise (flicker and bias random walk) the fit measured or held on channel `c`
    /// (0..6: gyro x..z, accel x..z); None without one.
    pub fn slow_noise(&self, c: usize) -> Option<super::slow::SlowNoise> {
        self.sensor(SensorKind::BOTH[(c / 3).min(1)]).channels.get(c % 3).and_then(|ch| ch.slow_noise)
    }

    /// Fails, naming every lost coefficient and its remedy, when something was unidentifiable.
    pub fn ensure_identifiable(&self) -> Result<(), EstimateError> {
        let lost: Vec<String> = self
            .gyro
            .unidentifiable
            .iter()
            .chain(&self.accel.unidentifiable)
            .map(|u| format!("{} ({}; remedy: {})", u.held, u.reason, u.remedy))
            .collect();
        if lost.is_empty() {
            Ok(())
        } else {
            Err(EstimateError::Unidentifiable(lost.join("; ")))
        }
    }

    /// A coefficient of either sensor by name.
    pub fn get(&self, name: &str) -> Option<&Coefficient> {
        self.gyro.get(name).or_else(|| self.accel.get(name))
    }
}
