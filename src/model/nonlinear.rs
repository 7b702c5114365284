//! Effects whose parameters enter nonlinearly (time delay, dead zone). Such an effect does
//! not add regressors; it changes the true motion *as the sensor sees it*, and the linear
//! model is then fitted on the transformed motion (variable projection, see
//! `crate::estimate`).

use super::{Inputs, SensorKind, Side};
use crate::motion::Track;
use std::fmt;

/// One nonlinear parameter.
#[derive(Debug, Clone, PartialEq)]
pub struct ParamDef {
    /// Name, e.g. `time_delay` or `gyro.dz_x`.
    pub name: String,
    /// SI unit.
    pub unit: &'static str,
    /// Value when the effect is absent.
    pub nominal: f64,
    /// Typical size, for the optimiser's first simplex and numerical derivatives.
    pub scale: f64,
    /// Smallest physical value.
    pub min: f64,
    /// Largest physical value.
    pub max: f64,
}

/// An effect with nonlinear parameters.
pub trait NonlinearEffect: Send + Sync + fmt::Debug {
    /// Identifier (command line, profiles).
    fn id(&self) -> &'static str;
    /// The sensor whose outputs it affects (None: both).
    fn sensor(&self) -> Option<SensorKind>;
    /// A paragraph explaining the physics.
    fn explain(&self) -> &'static str;
    /// The quantities of the true state it changes or reads.
    fn inputs(&self) -> Inputs;
    /// Where it acts: nonlinear effects change the motion as the sensor sees it (input side).
    fn side(&self) -> Side {
        Side::Input
    }
    /// Its parameters.
    fn params(&self) -> Vec<ParamDef>;
    /// The true motion as the sensor sees it, for parameter values `p`.
    fn transform(&self, p: &[f64], track: &Track) -> Track;
    /// Inverse on one corrected sample of `sensor`: `z` (the linear inverse's output, i.e.
    /// the input as the sensor saw it) is turned into the true input in place. Returns a
    /// bitmask of the axes that cannot be inverted at this sample (their value is then 0 and
    /// must be treated as unknown). `noise` is each axis's noise standard deviation.
    fn invert_sample(&self, _p: &[f64], _sensor: SensorKind, _z: &mut [f64; 3], _noise: &[f64; 3]) -> u8 {
        0
    }
    /// How much later than the truth the sensor's samples are stamped, s (time delay).
    fn lag_s(&self, _p: &[f64]) -> f64 {
        0.0
    }
    /// The definition of a user effect (what a profile stores to stay self-contained).
    fn user_definition(&self) -> Option<&super::UserEffectDef> {
        None
    }
}

pub use crate::motion::interpolate;
