//! Temperature-dependent bias (catalogue effect): one power of (T − 20 °C) per effect, so a
//! polynomial bias of degree d is the effects of degree 1 … d together and each degree is
//! found, or not, on its own evidence.

use super::{per_axis_terms, Effect, Inputs, SensorKind, State, Term, T_REF_C};

/// Temperature-dependent bias, one coefficient per axis, the term of one degree (see `explain`).
#[derive(Debug, Clone)]
pub struct TempBias {
    sensor: SensorKind,
    degree: i32,
    terms: Vec<Term>,
}

impl TempBias {
    /// The effect's id on a sensor for a degree (1 `…-temp-bias`, 2 `…-temp-bias2`, 3 `…-temp-bias3`).
    fn id_of(sensor: SensorKind, degree: i32) -> &'static str {
        match (sensor, degree) {
            (SensorKind::Gyro, 2) => "gyro-temp-bias2",
            (SensorKind::Gyro, 3) => "gyro-temp-bias3",
            (SensorKind::Gyro, _) => "gyro-temp-bias",
            (SensorKind::Accel, 2) => "accel-temp-bias2",
            (SensorKind::Accel, 3) => "accel-temp-bias3",
            (SensorKind::Accel, _) => "accel-temp-bias",
        }
    }

    /// The linear term on the given sensor.
    pub fn new(sensor: SensorKind) -> Self {
        Self::with_degree(sensor, 1)
    }

    /// The term of `degree` (1 to 3; others are taken as 1) on the given sensor.
    pub fn with_degree(sensor: SensorKind, degree: i32) -> Self {
        let degree = if (1..=3).contains(&degree) { degree } else { 1 };
        let (letter, label, unit) = match (sensor, degree) {
            (SensorKind::Gyro, 2) => ("tb2", "(T-20)^2", "rad/s/degC^2"),
            (SensorKind::Gyro, 3) => ("tb3", "(T-20)^3", "rad/s/degC^3"),
            (SensorKind::Gyro, _) => ("tb", "(T-20)", "rad/s/degC"),
            (SensorKind::Accel, 2) => ("tb2", "(T-20)^2", "m/s^2/degC^2"),
            (SensorKind::Accel, 3) => ("tb3", "(T-20)^3", "m/s^2/degC^3"),
            (SensorKind::Accel, _) => ("tb", "(T-20)", "m/s^2/degC"),
        };
        let terms = per_axis_terms(sensor, letter, Self::id_of(sensor, degree), true, |_| label.to_string(), unit);
        Self { sensor, degree, terms }
    }
}

impl Effect for TempBias {
    fn id(&self) -> &'static str {
        Self::id_of(self.sensor, self.degree)
    }

    fn sensor(&self) -> SensorKind {
        self.sensor
    }

    fn inputs(&self) -> Inputs {
        Inputs { temperature: true, ..Inputs::NONE }
    }

    fn explain(&self) -> &'static str {
        match self.degree {
            2 => "Temperature-dependent bias, quadratic term: u_i += tb2_i (T - 20 degC)^2. Bias curves over a wide range bend (accelerometers are typically quadratic in T); add it beside the linear term when the residual after that term still follows T. Needs a temp column or a run temperature_c.",
            3 => "Temperature-dependent bias, cubic term: u_i += tb3_i (T - 20 degC)^3 (ArduPilot and PX4 fit cubics per axis over a thermal sweep; MEMS gyros are often cubic over -20..+70 degC). Add it beside the linear and quadratic terms. Needs a temp column or a run temperature_c.",
            _ => "Temperature-dependent bias: u_i += tb_i (T - 20 degC), from thermal expansion of the suspension and electronics drift (the paper quotes ~1e-5 deg/s per degC for its gyros, ~1e-4 g per degC for its accelerometers). It shows as a residual that follows the temp column across runs. Needs a temp column or a run temperature_c.",
        }
    }

    fn terms(&self) -> &[Term] {
        &self.terms
    }

    #[inline]
    fn regressor(&self, _k: usize, s: &State) -> f64 {
        if s.temp_c.is_finite() {
            (s.temp_c - T_REF_C).powi(self.degree)
        } else {
            f64::NAN
        }
    }
}
