//! Temperature-dependent scale factor (catalogue effect): one power of (T − 20 °C) per
//! effect, as for the bias ([`super::TempBias`]), so a scale factor curved in temperature is
//! the effects of degree 1 … d together.

use super::{input_letter, own_input, per_axis_terms, Effect, Inputs, SensorKind, State, Term, AXES, T_REF_C};

/// Temperature-dependent scale factor, one coefficient per axis, the term of one degree
/// (see `explain`).
#[derive(Debug, Clone)]
pub struct TempScale {
    sensor: SensorKind,
    degree: i32,
    terms: Vec<Term>,
}

impl TempScale {
    /// The effect's id on a sensor for a degree (1 `…-temp-scale`, 2 `…-temp-scale2`, 3 `…-temp-scale3`).
    fn id_of(sensor: SensorKind, degree: i32) -> &'static str {
        match (sensor, degree) {
            (SensorKind::Gyro, 2) => "gyro-temp-scale2",
            (SensorKind::Gyro, 3) => "gyro-temp-scale3",
            (SensorKind::Gyro, _) => "gyro-temp-scale",
            (SensorKind::Accel, 2) => "accel-temp-scale2",
            (SensorKind::Accel, 3) => "accel-temp-scale3",
            (SensorKind::Accel, _) => "accel-temp-scale",
        }
    }

    /// The linear term on the given sensor.
    pub fn new(sensor: SensorKind) -> Self {
        Self::with_degree(sensor, 1)
    }

    /// The term of `degree` (1 to 3; others are taken as 1) on the given sensor.
    pub fn with_degree(sensor: SensorKind, degree: i32) -> Self {
        let degree = if (1..=3).contains(&degree) { degree } else { 1 };
        let (letter, power, unit) = match degree {
            2 => ("ts2", "^2", "1/degC^2"),
            3 => ("ts3", "^3", "1/degC^3"),
            _ => ("ts", "", "1/degC"),
        };
        let terms = per_axis_terms(
            sensor,
            letter,
            Self::id_of(sensor, degree),
            false,
            |i| format!("(T-20){power}*{}_{}", input_letter(sensor), AXES[i]),
            unit,
        );
        Self { sensor, degree, terms }
    }
}

impl Effect for TempScale {
    fn id(&self) -> &'static str {
        Self::id_of(self.sensor, self.degree)
    }

    fn sensor(&self) -> SensorKind {
        self.sensor
    }

    fn inputs(&self) -> Inputs {
        Inputs::own(self.sensor).and(Inputs { temperature: true, ..Inputs::NONE })
    }

    fn explain(&self) -> &'static str {
        match self.degree {
            2 => "Temperature-dependent scale factor, quadratic term: u_i += ts2_i (T - 20 degC)^2 x_i. A scale factor that bends over a wide range; add it beside the linear term. Needs a temp column or a run temperature_c.",
            3 => "Temperature-dependent scale factor, cubic term: u_i += ts3_i (T - 20 degC)^3 x_i; add it beside the linear and quadratic terms. Needs a temp column or a run temperature_c.",
            _ => "Temperature-dependent scale factor: u_i += ts_i (T - 20 degC) x_i, from the temperature coefficient of magnets, springs and gains. It shows as a residual proportional to the input whose size follows the temperature. Needs a temp column or a run temperature_c.",
        }
    }

    fn terms(&self) -> &[Term] {
        &self.terms
    }

    #[inline]
    fn regressor(&self, k: usize, s: &State) -> f64 {
        let x = own_input(self.sensor, s)[k % 3];
        if s.temp_c.is_finite() {
            (s.temp_c - T_REF_C).powi(self.degree) * x
        } else {
            f64::NAN
        }
    }
}
