//! Temperature-dependent bias (catalogue effect).

use super::{per_axis_terms, Effect, Inputs, SensorKind, State, Term, T_REF_C};

/// Temperature-dependent bias, one coefficient per axis (see `explain`).
#[derive(Debug, Clone)]
pub struct TempBias {
    sensor: SensorKind,
    terms: Vec<Term>,
}

impl TempBias {
    /// The effect's id on a sensor.
    fn id_of(sensor: SensorKind) -> &'static str {
        match sensor {
            SensorKind::Gyro => "gyro-temp-bias",
            SensorKind::Accel => "accel-temp-bias",
        }
    }

    /// The effect on the given sensor.
    pub fn new(sensor: SensorKind) -> Self {
        let terms = per_axis_terms(
            sensor,
            "tb",
            Self::id_of(sensor),
            true,
            |_| "(T-20)".to_string(),
            match sensor {
                SensorKind::Gyro => "rad/s/degC",
                SensorKind::Accel => "m/s^2/degC",
            },
        );
        Self { sensor, terms }
    }
}

impl Effect for TempBias {
    fn id(&self) -> &'static str {
        Self::id_of(self.sensor)
    }

    fn sensor(&self) -> SensorKind {
        self.sensor
    }

    fn inputs(&self) -> Inputs {
        Inputs { temperature: true, ..Inputs::NONE }
    }

    fn explain(&self) -> &'static str {
        "Temperature-dependent bias: u_i += tb_i (T - 20 degC), from thermal expansion of the suspension and electronics drift (the paper quotes ~1e-5 deg/s per degC for its gyros, ~1e-4 g per degC for its accelerometers). It shows as a residual that follows the temp column across runs. Needs a temp column or a run temperature_c."
    }

    fn terms(&self) -> &[Term] {
        &self.terms
    }

    #[inline]
    fn regressor(&self, _k: usize, s: &State) -> f64 {
        if s.temp_c.is_finite() {
            s.temp_c - T_REF_C
        } else {
            f64::NAN
        }
    }
}
