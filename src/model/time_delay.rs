//! Time delay between the sensor's clock and the stand's.

use super::nonlinear::{NonlinearEffect, ParamDef};
use super::{Inputs, SensorKind};
use crate::motion::Track;

/// The outputs stamped t show the motion at t − τ (τ > 0: the sensor lags the stand).
#[derive(Debug, Clone, Default)]
pub struct TimeDelay;

impl NonlinearEffect for TimeDelay {
    fn id(&self) -> &'static str {
        "time-delay"
    }

    fn sensor(&self) -> Option<SensorKind> {
        None
    }

    fn inputs(&self) -> Inputs {
        Inputs { rate: true, ang_accel: true, force: true, ..Inputs::NONE }
    }

    fn explain(&self) -> &'static str {
        "Time delay: the unit's samples are stamped later (or earlier) than the stand's motion \
         they measure, from filter group delay, transmission latency or an offset between the \
         two clocks. Output at t shows the truth at t − τ. On a gyro it looks exactly like the \
         diagonal angular-acceleration terms (e_ii = −τ); on the accelerometer it looks like \
         τ (ω × a), which grows with the stand rate. Runs at several rates separate it from \
         cross-coupling."
    }

    fn params(&self) -> Vec<ParamDef> {
        vec![ParamDef { name: "time_delay".into(), unit: "s", nominal: 0.0, scale: 1e-3, min: -1.0, max: 1.0 }]
    }

    fn lag_s(&self, p: &[f64]) -> f64 {
        p.first().copied().unwrap_or(0.0)
    }

    fn transform(&self, p: &[f64], tr: &Track) -> Track {
        tr.delayed(p.first().copied().unwrap_or(0.0))
    }
}
