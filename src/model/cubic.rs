//! Cubic scale nonlinearity (catalogue effect).

use super::{input_letter, own_input, per_axis_terms, Effect, Inputs, SensorKind, State, Term, AXES};

/// Cubic scale nonlinearity, one coefficient per axis (see `explain`).
#[derive(Debug, Clone)]
pub struct Cubic {
    sensor: SensorKind,
    terms: Vec<Term>,
}

impl Cubic {
    /// The effect's id on a sensor.
    fn id_of(sensor: SensorKind) -> &'static str {
        match sensor {
            SensorKind::Gyro => "gyro-cubic",
            SensorKind::Accel => "accel-cubic",
        }
    }

    /// The effect on the given sensor.
    pub fn new(sensor: SensorKind) -> Self {
        let terms = per_axis_terms(
            sensor,
            "k3",
            Self::id_of(sensor),
            false,
            |i| format!("{}_{}^3", input_letter(sensor), AXES[i]),
            match sensor {
                SensorKind::Gyro => "1/(rad/s)^2",
                SensorKind::Accel => "1/(m/s^2)^2",
            },
        );
        Self { sensor, terms }
    }
}

impl Effect for Cubic {
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
        "Cubic scale nonlinearity: u_i += k3_i x_i^3, a symmetric gain compression or expansion at large inputs (spring stiffening, amplifier saturation onset). It shows as a third-harmonic residual that grows with the cube of the rate or cone angle."
    }

    fn terms(&self) -> &[Term] {
        &self.terms
    }

    #[inline]
    fn regressor(&self, k: usize, s: &State) -> f64 {
        let x = own_input(self.sensor, s)[k % 3];
        x * x * x
    }
}
