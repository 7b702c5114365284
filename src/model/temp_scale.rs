//! Temperature-dependent scale factor (catalogue effect).

use super::{input_letter, own_input, per_axis_terms, Effect, Inputs, SensorKind, State, Term, AXES, T_REF_C};

/// Temperature-dependent scale factor, one coefficient per axis (see `explain`).
#[derive(Debug, Clone)]
pub struct TempScale {
    sensor: SensorKind,
    terms: Vec<Term>,
}

impl TempScale {
    /// The effect's id on a sensor.
    fn id_of(sensor: SensorKind) -> &'static str {
        match sensor {
            SensorKind::Gyro => "gyro-temp-scale",
            SensorKind::Accel => "accel-temp-scale",
        }
    }

    /// The effect on the given sensor.
    pub fn new(sensor: SensorKind) -> Self {
        let terms = per_axis_terms(
            sensor,
            "ts",
            Self::id_of(sensor),
            false,
            |i| format!("(T-20)*{}_{}", input_letter(sensor), AXES[i]),
            "1/degC",
        );
        Self { sensor, terms }
    }
}

impl Effect for TempScale {
    fn id(&self) -> &'static str {
        Self::id_of(self.sensor)
    }

    fn sensor(&self) -> SensorKind {
        self.sensor
    }

    fn inputs(&self) -> Inputs {
        Inputs::own(self.sensor).and(Inputs { temperature: true, ..Inputs::NONE })
    }

    fn explain(&self) -> &'static str {
        "Temperature-dependent scale factor: u_i += ts_i (T - 20 degC) x_i, from the temperature coefficient of magnets, springs and gains. It shows as a residual proportional to the input whose size follows the temperature. Needs a temp column or a run temperature_c."
    }

    fn terms(&self) -> &[Term] {
        &self.terms
    }

    #[inline]
    fn regressor(&self, k: usize, s: &State) -> f64 {
        let x = own_input(self.sensor, s)[k % 3];
        if s.temp_c.is_finite() {
            (s.temp_c - T_REF_C) * x
        } else {
            f64::NAN
        }
    }
}
