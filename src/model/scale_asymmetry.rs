//! Scale asymmetry (catalogue effect).

use super::{input_letter, own_input, per_axis_terms, Effect, Inputs, SensorKind, State, Term, AXES};

/// Scale asymmetry, one coefficient per axis (see `explain`).
#[derive(Debug, Clone)]
pub struct ScaleAsymmetry {
    sensor: SensorKind,
    terms: Vec<Term>,
}

impl ScaleAsymmetry {
    /// The effect's id on a sensor.
    fn id_of(sensor: SensorKind) -> &'static str {
        match sensor {
            SensorKind::Gyro => "gyro-scale-asymmetry",
            SensorKind::Accel => "accel-scale-asymmetry",
        }
    }

    /// The effect on the given sensor.
    pub fn new(sensor: SensorKind) -> Self {
        let terms = per_axis_terms(
            sensor,
            "sa",
            Self::id_of(sensor),
            false,
            |i| format!("|{}_{}|", input_letter(sensor), AXES[i]),
            "1",
        );
        Self { sensor, terms }
    }
}

impl Effect for ScaleAsymmetry {
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
        "Scale asymmetry: the scale factor differs for positive and negative inputs (u_i += sa_i |x_i|, i.e. scale 1+sa for x > 0 and 1-sa for x < 0), from asymmetric pick-offs, torquer magnets or a pendulum that is not centred. It shows as a residual with even harmonics of the cone frequency that does not change sign with the direction of the stand."
    }

    fn terms(&self) -> &[Term] {
        &self.terms
    }

    #[inline]
    fn regressor(&self, k: usize, s: &State) -> f64 {
        let x = own_input(self.sensor, s)[k % 3];
        x.abs()
    }
}
