//! Hysteresis (catalogue effect).

use super::{input_letter, output_unit, per_axis_terms, Effect, Inputs, SensorKind, Side, State, Term, AXES};

/// Hysteresis, one coefficient per axis (see `explain`).
#[derive(Debug, Clone)]
pub struct Hysteresis {
    sensor: SensorKind,
    terms: Vec<Term>,
}

impl Hysteresis {
    /// The effect's id on a sensor.
    fn id_of(sensor: SensorKind) -> &'static str {
        match sensor {
            SensorKind::Gyro => "gyro-hysteresis",
            SensorKind::Accel => "accel-hysteresis",
        }
    }

    /// The effect on the given sensor.
    pub fn new(sensor: SensorKind) -> Self {
        let terms = per_axis_terms(
            sensor,
            "h",
            Self::id_of(sensor),
            false,
            |i| format!("sgn(d{}_{}/dt)", input_letter(sensor), AXES[i]),
            output_unit(sensor),
        );
        Self { sensor, terms }
    }
}

impl Effect for Hysteresis {
    fn id(&self) -> &'static str {
        Self::id_of(self.sensor)
    }

    fn sensor(&self) -> SensorKind {
        self.sensor
    }

    fn inputs(&self) -> Inputs {
        match self.sensor {
            SensorKind::Gyro => Inputs { ang_accel: true, ..Inputs::NONE },
            SensorKind::Accel => Inputs { rate: true, force: true, ..Inputs::NONE },
        }
    }

    fn side(&self) -> Side {
        Side::Input
    }

    /// The element's own input is shifted by h_i·sign(ẋ_i).
    fn input_components(&self, k: usize) -> Vec<(usize, usize)> {
        vec![(k % 3, k % 3)]
    }

    fn explain(&self) -> &'static str {
        "Hysteresis: the output depends on whether the input is rising or falling (u_i += h_i sign(dx_i/dt)), from friction in gimbal bearings or magnetic hysteresis. It shows as a residual square wave locked to the cone phase, switching where the input on that axis turns. For the accelerometer dx/dt is taken as the gravity rotation rate -(w x a); a rate of change below 1e-6 of its scale counts as none. The friction acts on the sensing element's input, before its scale and coupling."
    }

    fn terms(&self) -> &[Term] {
        &self.terms
    }

    #[inline]
    fn regressor(&self, k: usize, s: &State) -> f64 {
        // The rate of change of the input and a scale it is measured against: a component
        // below 1e-6 of it is zero (no direction), not a sign drawn from rounding (the z
        // axis of a conic stand sees ω×a = 0 up to rounding).
        let (d, scale) = match self.sensor {
            SensorKind::Gyro => (s.e[k % 3], crate::stats::norm3(s.e)),
            SensorKind::Accel => {
                let (w, a) = (s.w, s.a);
                let c = [w[1] * a[2] - w[2] * a[1], w[2] * a[0] - w[0] * a[2], w[0] * a[1] - w[1] * a[0]];
                (-c[k % 3], crate::stats::norm3(w) * crate::stats::norm3(a))
            }
        };
        let tol = 1e-6 * scale;
        if d > tol {
            1.0
        } else if d < -tol {
            -1.0
        } else {
            0.0
        }
    }
}
