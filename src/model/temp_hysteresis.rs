//! Thermal hysteresis (catalogue effect): a bias that differs between the warming and the
//! cooling branch of a temperature sweep.
//!
//! Packages, adhesives and solder joints relax with a lag behind temperature, so a unit's
//! bias at a given temperature depends on whether it got there warming or cooling (what MEMS
//! IMU datasheets call temperature hysteresis, and why thermal calibrations run a sweep both
//! ways). The simplest model with one number per axis: u_i += h_i·s, s = +1 on the warming
//! branch, −1 on the cooling branch and 0 on a plateau, so the bias on warming minus the
//! bias on cooling is 2h_i, beside any temperature polynomial (the mean curve of the two
//! branches).
//!
//! The branch is read from the state's smoothed rate of change of temperature
//! ([`State::temp_rate_c_s`], smoothed over [`crate::stats::temp_rate::WINDOW_S`]) with a
//! dead band of [`DEAD_BAND_C_S`]: a plateau, the settling tail of a soak, or the flicker of
//! a quantised reading counts as neither branch.

use super::{output_unit, per_axis_terms, Effect, Inputs, SensorKind, State, Term};

/// |dT/dt| at or below which a sample is on no branch (a plateau), °C/s: 0.3 °C/min, a
/// tenth of a slow chamber ramp (1–3 °C/min) and far above the smoothed rate's noise for
/// a reading with 0.05 °C noise at 10 Hz or faster (about 7e-4 °C/s).
pub const DEAD_BAND_C_S: f64 = 0.005;

/// The thermal branch of a rate of change of temperature: +1 warming, −1 cooling, 0 on a
/// plateau (within [`DEAD_BAND_C_S`]) or when the rate is unknown.
#[inline]
pub fn branch(temp_rate_c_s: f64) -> f64 {
    if temp_rate_c_s > DEAD_BAND_C_S {
        1.0
    } else if temp_rate_c_s < -DEAD_BAND_C_S {
        -1.0
    } else {
        0.0
    }
}

/// Thermal hysteresis of one sensor's bias, one coefficient per axis (see `explain`).
#[derive(Debug, Clone)]
pub struct TempHysteresis {
    sensor: SensorKind,
    terms: Vec<Term>,
}

impl TempHysteresis {
    /// The effect's id on a sensor.
    fn id_of(sensor: SensorKind) -> &'static str {
        match sensor {
            SensorKind::Gyro => "gyro-temp-hysteresis",
            SensorKind::Accel => "accel-temp-hysteresis",
        }
    }

    /// The effect on the given sensor.
    pub fn new(sensor: SensorKind) -> Self {
        let terms = per_axis_terms(
            sensor,
            "thy",
            Self::id_of(sensor),
            true,
            |_| "branch(dT/dt): +1 warming, -1 cooling, 0 plateau".to_string(),
            output_unit(sensor),
        );
        Self { sensor, terms }
    }
}

impl Effect for TempHysteresis {
    fn id(&self) -> &'static str {
        Self::id_of(self.sensor)
    }

    fn sensor(&self) -> SensorKind {
        self.sensor
    }

    fn inputs(&self) -> Inputs {
        Inputs { temperature: true, temperature_rate: true, ..Inputs::NONE }
    }

    fn explain(&self) -> &'static str {
        "Thermal hysteresis: the bias differs between the warming and the cooling branch of a temperature sweep, u_i += thy_i s with s = +1 warming, -1 cooling, 0 on a plateau (|dT/dt| <= 0.3 degC/min, dT/dt smoothed over 20 s), so warming minus cooling is 2 thy_i. From packages, adhesives and solder relaxing behind the temperature. It shows on a sweep that warms then cools as a residual of opposite sign on the two branches at the same temperature. Needs a temp column that changes within runs (a run's constant temperature_c is a plateau)."
    }

    fn terms(&self) -> &[Term] {
        &self.terms
    }

    #[inline]
    fn regressor(&self, _k: usize, s: &State) -> f64 {
        if s.temp_c.is_finite() {
            branch(s.temp_rate_c_s)
        } else {
            f64::NAN
        }
    }
}
