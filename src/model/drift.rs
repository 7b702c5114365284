//! Bias drift with time (catalogue effect).

use super::{per_axis_terms, Effect, Inputs, SensorKind, State, Term};

/// Bias drift with time, one coefficient per axis (see `explain`).
#[derive(Debug, Clone)]
pub struct Drift {
    sensor: SensorKind,
    terms: Vec<Term>,
}

impl Drift {
    /// The effect's id on a sensor.
    fn id_of(sensor: SensorKind) -> &'static str {
        match sensor {
            SensorKind::Gyro => "gyro-drift",
            SensorKind::Accel => "accel-drift",
        }
    }

    /// The effect on the given sensor.
    pub fn new(sensor: SensorKind) -> Self {
        let terms = per_axis_terms(
            sensor,
            "d",
            Self::id_of(sensor),
            true,
            |_| "t".to_string(),
            match sensor {
                SensorKind::Gyro => "rad/s^2",
                SensorKind::Accel => "m/s^3",
            },
        );
        Self { sensor, terms }
    }
}

impl Effect for Drift {
    fn id(&self) -> &'static str {
        Self::id_of(self.sensor)
    }

    fn sensor(&self) -> SensorKind {
        self.sensor
    }

    fn inputs(&self) -> Inputs {
        Inputs { time: true, ..Inputs::NONE }
    }

    fn explain(&self) -> &'static str {
        "Bias drift with time: u_i += d_i t on the session clock (t as recorded, or each run's start_s plus the time since its first sample), from warm-up or slow relaxation. Over a session recorded run after run it shows as offsets between runs that grow with their start time and as a trend within each run, the same sign whatever the motion."
    }

    fn terms(&self) -> &[Term] {
        &self.terms
    }

    #[inline]
    fn regressor(&self, _k: usize, s: &State) -> f64 {
        s.t_session_s
    }
}
