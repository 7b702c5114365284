//! The shared correction module: inverts a fitted forward model, offline or streaming.
//!
//! For each sensor the profile's coefficients split into a bias b, the scale/coupling
//! matrix A (C_ω or K), the gyro's angular-acceleration matrix E (C_ε) and any further
//! effect terms g(state). The forward model is `u = b + A x + E ε + g(state)`, so
//! ```text
//! x = A⁻¹ (u − b − E ε̂ − g(state))          (paper eqs. 5–8, generalised)
//! ```
//! where ε̂ is estimated from the corrected rate itself with a band-limited derivative
//! ([`crate::motion::derivative`]).
//!
//! * **Offline** ([`correct_offline`]): whole record, centred derivative window, iterated
//!   to a fixed point (each pass re-estimates ε̂ and g from the previous pass).
//! * **Streaming** ([`Streaming`]): causal, one sample at a time, fixed memory, no
//!   allocation per sample. ε̂ at the newest sample is the slope of a local polynomial
//!   through the last N corrected samples *including the current one*; since that slope is
//!   `w₀ x_k + p` (p from past samples), the current sample solves the 3×3 system
//!   `(A + w₀ E) x_k = u − b − E p − g` exactly. On uniform sampling w₀ and the inverse are
//!   computed once. The causal slope lags the centred one by a bias of order (ω·N·dt)²,
//!   which is why offline correction is more accurate on fast motion.
//!
//! A thermal hysteresis term reads the temperature's rate of change
//! ([`crate::stats::temp_rate`]): offline the centred smoothed rate the fit used, streaming a
//! causal one (double exponential smoothing, four numbers of state) that lags it by about
//! ten seconds, so for that long after a sweep turns the streamed branch is the old one.
//!
//! Nonlinear effects carry their own inverse ([`crate::model::NonlinearEffect`]): a dead
//! zone is undone per sample (x = z + d·sign z) and samples inside the band are flagged,
//! not invented; a time delay τ is undone by re-stamping: sample k is the truth at t_k − τ
//! ([`Corrected::time_offset_s`], the same offline and streaming), and offline output can be
//! put back on the input stamps by cubic interpolation ([`resample_to_stamps`]).

use crate::units::SensorKind;
use nalgebra::{Matrix3, Vector3};

mod c_header;
mod csvstream;
mod inverse;
mod offline;
mod streaming;
mod temperature;

pub use c_header::to_c_header;
pub use csvstream::{correct_csv_streaming, OutputScale, StreamCsvError, StreamCsvOptions, StreamedCsv};
pub use inverse::{Calibration, NonlinearPart, SensorInverse};
pub use offline::{correct_offline, resample_to_stamps};
pub use streaming::{correct_streaming, Streaming};
pub use temperature::{refuse_outside, TempOutside, TempPolicy};

/// Correction errors.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum CorrectError {
    /// The scale/coupling matrix cannot be inverted.
    #[error("the {0} scale/coupling matrix of the profile is singular: it cannot be inverted")]
    Singular(SensorKind),
    /// The profile cannot be turned into a model.
    #[error("the profile's model cannot be rebuilt")]
    Model(#[from] crate::model::ModelError),
    /// The profile has an effect the correction cannot invert yet.
    #[error("the profile contains '{0}', whose correction is not implemented yet; refit without it to correct")]
    Unsupported(String),
    /// Samples lie outside the calibrated temperature range and the policy is `error`.
    #[error("{0}")]
    OutOfRange(String),
    /// The profile has a temperature effect but the data have no temperature.
    #[error("the profile's effect '{0}' needs temperatures: the recording has no temp column")]
    MissingTemperature(String),
    /// The session has no per-sample reference (protocol runs).
    #[error("{0} is a protocol session (static poses, turns, multi-position): it has no per-sample reference to check against; `crosscal fit` and `crosscal diagnose` report its pose and turn residuals")]
    ProtocolSession(String),
    /// A sample's correction is not finite: refused rather than returned.
    #[error(
        "sample {sample} (t = {t_s} s): the corrected values are not finite (inputs too large for the calibration?)"
    )]
    NonFinite {
        /// 1-based sample number.
        sample: usize,
        /// Its time stamp, s.
        t_s: f64,
    },
    /// The offline correction's fixed point (ε̂ from the corrected rate) was not reached:
    /// refused rather than returned.
    #[error(
        "the offline correction did not converge ({passes} passes, last change {change:.1e} of the signal): the profile's angular-acceleration terms (C_ε) are too large for the derivative at this sample rate; check the profile (is C_ε plausible?) or use --mode streaming"
    )]
    NotConverged {
        /// Passes made.
        passes: usize,
        /// Largest change of the last pass relative to the signal's largest value.
        change: f64,
    },
    /// A time stamp that does not increase (within a block or from the block before).
    #[error("sample {sample}: t = {t} does not increase (the previous sample is at {previous}): time must increase strictly, block after block (reset() starts a new record)")]
    TimeNotIncreasing {
        /// 1-based sample since the start or the last reset.
        sample: u64,
        /// Its time stamp, input unit.
        t: f64,
        /// The previous one.
        previous: f64,
    },
    /// Input arrays disagree in length.
    #[error("input lengths differ: t has {t}, gyro {g}, accel {a}")]
    Length {
        /// Time stamps.
        t: usize,
        /// Gyro samples.
        g: usize,
        /// Accel samples.
        a: usize,
    },
}

/// Corrected record.
#[derive(Debug, Clone, PartialEq)]
pub struct Corrected {
    /// Angular rate, rad/s, sensor frame.
    pub w_rad_s: Vec<[f64; 3]>,
    /// Specific force, m/s², sensor frame.
    pub a_m_s2: Vec<[f64; 3]>,
    /// Fixed-point passes made.
    pub iterations: usize,
    /// Whether the last pass changed nothing beyond 1e-14 relative.
    pub converged: bool,
    /// Samples outside the calibrated temperature range, and what was done with them.
    pub temp_outside: TempOutside,
    /// Leading samples corrected before the causal derivative window was full (streaming
    /// warm-up: their ε̂ rests on fewer samples; the first has none). 0 offline.
    pub warmup: usize,
    /// Per sample, channels that could not be inverted (inside a dead band): bits 0-2 gyro
    /// x, y, z, bits 3-5 accel x, y, z. Their values are 0 and unknown. Empty when none.
    pub flags: Vec<u8>,
    /// Sample k estimates the truth at `t_k − time_offset_s` (the profile's time delay; see
    /// [`resample_to_stamps`] to put the output back on the input stamps).
    pub time_offset_s: f64,
}

#[inline]
fn mv(m: &Matrix3<f64>, v: [f64; 3]) -> [f64; 3] {
    let r = m * Vector3::from(v);
    [r[0], r[1], r[2]]
}

/// `M (u − b − p − q)`: the linear inverse of one sample with two known contributions
/// (angular-acceleration and other-effect terms) removed.
#[inline]
fn solve(m: &Matrix3<f64>, u: [f64; 3], b: [f64; 3], p: [f64; 3], q: [f64; 3]) -> [f64; 3] {
    mv(m, [u[0] - b[0] - p[0] - q[0], u[1] - b[1] - p[1] - q[1], u[2] - b[2] - p[2] - q[2]])
}

/// Records sample k's flag bits, allocating the flag vector only when a first flag appears.
#[inline]
fn set_flags(flags: &mut Vec<u8>, n: usize, k: usize, f: u8) {
    if f != 0 {
        flags.resize(n, 0);
    }
    if let Some(x) = flags.get_mut(k) {
        *x = f;
    }
}

/// Refuses a correction with a non-finite value (naming the first such sample).
fn ensure_finite(c: Corrected, t_s: &[f64]) -> Result<Corrected, CorrectError> {
    let bad = c.w_rad_s.iter().zip(&c.a_m_s2).position(|(w, a)| !w.iter().chain(a).all(|v| v.is_finite()));
    match bad {
        Some(k) => Err(CorrectError::NonFinite { sample: k + 1, t_s: t_s.get(k).copied().unwrap_or(f64::NAN) }),
        None => Ok(c),
    }
}

/// Checks that a record can be corrected: equal lengths, temperatures where needed.
fn check_inputs(
    cal: &Calibration,
    n: usize,
    gyro: &[[f64; 3]],
    accel: &[[f64; 3]],
    temp_c: Option<&[f64]>,
) -> Result<(), CorrectError> {
    if gyro.len() != n || accel.len() != n || temp_c.is_some_and(|t| t.len() != n) {
        return Err(CorrectError::Length { t: n, g: gyro.len(), a: accel.len() });
    }
    match (temp_c, cal.needs_temperature()) {
        (None, Some(id)) => Err(CorrectError::MissingTemperature(id.to_string())),
        _ => Ok(()),
    }
}
