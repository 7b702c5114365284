//! Quadratic scale nonlinearity (catalogue effect).

use super::{input_letter, own_input, per_axis_terms, Effect, Inputs, SensorKind, State, Term, AXES};

/// Quadratic scale nonlinearity, one coefficient per axis (see `explain`).
#[derive(Debug, Clone)]
pub struct Quadratic {
    sensor: SensorKind,
    terms: Vec<Term>,
}

impl Quadratic {
    /// The effect's id on a sensor.
    fn id_of(sensor: SensorKind) -> &'static str {
        match sensor {
            SensorKind::Gyro => "gyro-quadratic",
            SensorKind::Accel => "accel-quadratic",
        }
    }

    /// The effect on the given sensor.
    pub fn new(sensor: SensorKind) -> Self {
        let terms = per_axis_terms(
            sensor,
            "q",
            Self::id_of(sensor),
            false,
            |i| format!("{}_{}^2", input_letter(sensor), AXES[i]),
            match sensor {
                SensorKind::Gyro => "1/(rad/s)",
                SensorKind::Accel => "1/(m/s^2)",
            },
        );
        Self { sensor, terms }
    }
}

impl Effect for Quadratic {
    fn id(&self) -> &'static str {
        Self::id_of(self.sensor)
    }

    fn sensor(&self) -> SensorKind {
        self.sensor
    }

    fn inputs(&self) -> Inputs {
        Inputs::own(self.sensor)
    }

    fn explain(&self) -> &'static str {
        "Quadratic scale nonlinearity: the output grows with the square of the input on its own axis (u_i += q_i x_i^2), from a pick-off or spring whose gain changes with deflection. It shows as a residual at twice the cone frequency on axes with a varying input and as a rate- or g-dependent bias; runs at two rates or cone angles separate it from the bias."
    }

    fn terms(&self) -> &[Term] {
        &self.terms
    }

    #[inline]
    fn regressor(&self, k: usize, s: &State) -> f64 {
        let x = own_input(self.sensor, s)[k % 3];
        x * x
    }
}
