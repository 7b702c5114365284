//! crosscal: cross-coupling calibration of three-axis gyroscopes and accelerometers on a
//! rotating (conic-motion) stand.
//!
//! Data flows one way: [`session`] (manifest + CSV) → [`motion`] (true ω, ε, a in sensor
//! axes) → [`model`] (effect regressors) → [`estimate`] (least squares, uncertainty,
//! identifiability) → [`profile`] (versioned JSON per unit) → [`correct`] (shared offline
//! and streaming correction) → [`check`] (errors before/after, reduction factors).
//!
//! Conventions: sensor frame, SI units inside (rad/s, rad/s², m/s², s); forward models
//! `u = f(true)`; matrices row-major (`C[i][j]` is the weight of input j in output i).

pub mod app;
pub mod atomic;
pub mod check;
pub mod correct;
pub mod diagnose;
pub mod estimate;
pub mod frames;
pub mod html;
pub mod json;
pub mod model;
pub mod motion;
pub mod noise;
pub mod plan;
pub mod profile;
pub mod session;
pub mod simulate;
pub mod stats;
pub mod units;
