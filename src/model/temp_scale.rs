//! Temperature-dependent scale factor (catalogue effect).

use super::{input_letter, own_input, per_axis_terms, Effect, SensorKind, State, Term, T_REF_C};

/// Temperature-dependent scale factor, one coefficient per axis (see `explain`).
#[derive(Debug, Clone)]
pub struct TempScale {
    sensor: SensorKind,
    terms: Vec<Term>,
}

impl TempScale {
    /// The effect on the given sensor.
    pub fn new(sensor: SensorKind) -> Self {
        let inp = input_letter(sensor);
        let terms = per_axis_terms(sensor, "ts", |i| format!("T*{inp}_{}", super::AXES[i]), "1/degC");
        Self { sensor, terms }
    }
}

impl Effect for TempScale {
    fn id(&self) -> &'static str {
        match self.sensor {
            SensorKind::Gyro => "gyro-temp-scale",
            SensorKind::Accel => "accel-temp-scale",
        }
    }

    fn sensor(&self) -> SensorKind {
        self.sensor
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

    fn needs_temperature(&self) -> bool {
        true
    }
}
