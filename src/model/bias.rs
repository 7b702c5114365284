//! Bias: a constant offset on each output channel.

use super::{Effect, Inputs, Key, Role, SensorKind, State, Term, AXES};

/// Constant zero offset per axis (u_i += b_i).
#[derive(Debug, Clone)]
pub struct Bias {
    sensor: SensorKind,
    terms: Vec<Term>,
}

impl Bias {
    /// Bias of the given sensor.
    pub fn new(sensor: SensorKind) -> Self {
        let unit = match sensor {
            SensorKind::Gyro => "rad/s",
            SensorKind::Accel => "m/s^2",
        };
        let terms = (0..3)
            .map(|i| Term {
                name: format!("{}.b_{}", sensor.as_str(), AXES[i]),
                channel: i,
                key: Key::One,
                label: "1".into(),
                unit,
                nominal: 0.0,
                drop_priority: 2,
                role: Role::Bias,
            })
            .collect();
        Self { sensor, terms }
    }
}

impl Effect for Bias {
    fn id(&self) -> &'static str {
        match self.sensor {
            SensorKind::Gyro => "gyro-bias",
            SensorKind::Accel => "accel-bias",
        }
    }

    fn sensor(&self) -> SensorKind {
        self.sensor
    }

    fn inputs(&self) -> Inputs {
        Inputs::NONE
    }

    fn explain(&self) -> &'static str {
        "Bias (zero offset): the output when the input is zero. It comes from electronics \
         offsets, residual torques in a rate gyro's gimbal or spring, or the pendulum's rest \
         position in an accelerometer. It shows as a constant residual on one channel that does \
         not change with rate, direction or cone phase."
    }

    fn terms(&self) -> &[Term] {
        &self.terms
    }

    fn regressor(&self, _k: usize, _s: &State) -> f64 {
        1.0
    }
}
