//! crosscal: cross-coupling calibration of three-axis gyroscopes and accelerometers on a
//! rotating (conic-motion) stand, in hand-held protocols and from production lots.
//!
//! Layers, lowest first (a module imports only from layers below it; `ARCHITECTURE.md` is
//! the map): leaf maths and helpers ([`units`], [`stats`], [`json`], [`html`], [`atomic`])
//! → [`frames`] → [`session`] (manifests, recordings, importers) → [`motion`] (true ω, ε,
//! a) and [`noise`] → [`model`] (the effects catalogue) → [`estimate`] (the one fit entry
//! point) and [`simulate`] → [`profile`] → [`correct`] → [`check`], [`plan`] →
//! [`diagnose`] → [`app`] (the use cases the command line and batch share).
//!
//! Conventions: sensor frame, SI units inside (rad/s, rad/s², m/s², s); forward models
//! `u = f(true)`; matrices row-major (`C[i][j]` is the weight of input j in output i).

pub mod app;
pub mod atomic;
pub mod check;
pub mod correct;
pub mod datasheet;
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
