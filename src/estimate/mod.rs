//! Estimation: one entry point, [`fit`], that takes a [`FitRequest`] (a session on disk, a
//! session in memory or prepared runs; a model; settings) and picks the way to fit it:
//!
//! * **streamed** — conic and static runs with a linear model are read row by row from their
//!   files in fixed memory (`stream`);
//! * **in memory** — the linear estimator over whole runs (`linear`), with the robust
//!   refit (`robust`) and nonlinear parameters by variable projection (`nonlinear`);
//! * **stand settings** — each conic run's cone angle, rate and phase fitted with the
//!   coefficients (`stand`);
//! * **protocol** — Ferraris and multi-position sessions ([`protocol`]).
//!
//! Each output channel of each sensor is its own linear problem `y = Φ θ + noise` (the
//! channels share regressor columns). The design over all runs is accumulated into an R
//! factor ([`crate::stats::QrAccumulator`]); each channel's problem is then solved from R,
//! so the condition number is never squared. Standard errors are `σ √diag((R_sᵀR_s)⁻¹)`
//! with `σ² = RSS/(n − q)`, inflated for a coloured residual.
//!
//! Before solving, the column-scaled R of each channel is decomposed (SVD). A singular
//! value below `rcond · s_max` is a lost combination of coefficients: the coefficient most
//! likely to be the culprit (angular-acceleration terms first, then biases, then couplings,
//! never a diagonal scale first) is held at its nominal value and reported by name, with the
//! kind of run that would identify it; the rest of the fit proceeds.

mod channel;
pub mod identify;
mod linear;
mod lm;
mod memory;
mod nonlinear;
pub mod protocol;
mod reml;
mod request;
mod result;
mod robust;
pub(crate) mod runs;
pub mod slow;
pub mod spin;
mod stand;
mod stream;

pub use identify::{Correlation, Unidentifiable};
pub use nonlinear::{bound_at_fit, held_at_fit, near_fit, seen_tracks, NonlinearParam};
pub use request::{fit, FitData, FitOutcome, FitRequest, FitSource, ModelChoice, StreamPolicy};
pub use result::{ChannelFit, CoefStatus, Coefficient, Fit, SensorFit};
pub use runs::{fit_runs, mapped_state, tracks, FitRun, SeenFrom};
pub use stand::{ConeSetting, StandBase, StandParams, StandTerm};

use crate::units::SensorKind;
use std::path::PathBuf;

/// Numerical settings of a fit.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FitOptions {
    /// Rows per QR block (1024: 9 % less CPU time in a streamed fit than 4096, measured).
    pub chunk: usize,
    /// Relative singular-value threshold below which a combination is unidentifiable.
    pub rcond: f64,
    /// Huber IRLS instead of plain least squares (outliers and spikes lose weight).
    pub robust: bool,
    /// Known per-sample noise σ of each channel (gx, gy, gz in rad/s; ax, ay, az in m/s²):
    /// the covariance is then σ²(ΦᵀΦ)⁻¹, the Cramér–Rao bound, instead of using the residual.
    pub known_sigma: Option<[f64; 6]>,
    /// Screening (ranking candidates): nonlinear parameters get a coarse scan and a short
    /// simplex search, and the best point found is returned even if not converged.
    pub screening: bool,
    /// Carry slow noise (flicker, bias random walk) in the covariance ([`slow`]): one more
    /// pass over the samples for block sums; the standard errors then cover a bias that
    /// wanders over the session (`fit --slow-noise`).
    pub slow_noise: bool,
    /// With `slow_noise`: the slow noise of each channel (gyro x..z, accel x..z) as another
    /// fit measured it, carried in the covariance without measuring it again (a run's fit
    /// compared with the session's, whose many runs tell the wander far better than one).
    pub slow_noise_held: Option<[Option<slow::SlowNoise>; 6]>,
}

impl Default for FitOptions {
    fn default() -> Self {
        Self {
            chunk: 1024,
            rcond: 1e-9,
            robust: false,
            known_sigma: None,
            screening: false,
            slow_noise: false,
            slow_noise_held: None,
        }
    }
}

/// Why a fit failed: the data could not be read, the request does not fit the data, or the
/// estimate itself failed. Causes are kept as sources.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum EstimateError {
    /// A manifest or recording could not be read.
    #[error("reading session {path}")]
    Read {
        /// The manifest.
        path: PathBuf,
        /// What went wrong, with file, line and column.
        #[source]
        source: crate::session::SessionError,
    },
    /// The model asked for cannot be built.
    #[error("building the model")]
    Model(#[from] crate::model::ModelError),
    /// The request cannot be carried out on these data (e.g. `stand` on a protocol session,
    /// a held-out run that does not exist, streaming where the runs need memory).
    #[error("{0}")]
    Request(String),
    /// Not enough samples for the number of coefficients.
    #[error("{sensor} channel {axis}: {n} samples cannot determine {q} coefficients")]
    TooFewSamples {
        /// Sensor.
        sensor: SensorKind,
        /// Axis letter.
        axis: char,
        /// Samples.
        n: u64,
        /// Coefficients.
        q: usize,
    },
    /// No runs.
    #[error("no samples to fit")]
    NoData,
    /// A user effect cannot be evaluated on these data (its expression is not finite).
    #[error("user effect on these data")]
    UserEffect(#[source] crate::model::user::UserEffectError),
    /// The design of a channel holds values too large (or not finite) to compute with.
    #[error("{sensor} channel {axis}: the design has values that are not finite (a declared rate, angle or a recorded value too large to compute with)")]
    NonFinite {
        /// Sensor.
        sensor: SensorKind,
        /// Axis letter.
        axis: char,
    },
    /// An effect needs a temperature that a run does not have.
    #[error("effect '{effect}' needs temperatures but run '{run}' has no temp column and no temperature_c")]
    MissingTemperature {
        /// Effect id.
        effect: String,
        /// Run name.
        run: String,
    },
    /// A nonlinear parameter search (time delay, dead zone, stand settings, protocol
    /// Levenberg–Marquardt) did not reach a trustworthy optimum.
    #[error("nonlinear fit failed: {0}")]
    NotConverged(String),
    /// The runs cannot identify the requested model (strict mode).
    #[error("the runs cannot identify the requested model: {0}")]
    Unidentifiable(String),
    /// A protocol session (static poses, turns, multi-position) cannot be fitted as asked.
    #[error("protocol session: {0}")]
    Protocol(String),
}
