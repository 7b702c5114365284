//! The use cases shared by the command line, batch runs and the Python bindings: fit a unit
//! and store its profile ([`fit`]), validate a model on held-out runs ([`validate`]), accept
//! a unit against rules ([`accept`]), calibrate a production lot ([`batch`]), diagnose a
//! session ([`diagnose`]), turn simulation settings into a configuration ([`simulate`]),
//! correct and analyse samples held in memory ([`arrays`]), and the exit code of any error
//! ([`errors`]).
//!
//! Top layer of the library: it may use every module below it, and nothing below uses it.
//! Errors are typed ([`AppError`]) with their causes kept as sources; only the binary turns
//! them into messages and exit codes.

// The errors carry their whole cause chain (file, line, column) by value, so that the
// binary can walk it for exit codes; these functions run once per command or unit.
#![allow(clippy::result_large_err)]

pub mod accept;
pub mod arrays;
pub mod batch;
pub mod datasheet;
pub mod diagnose;
pub mod errors;
pub mod fit;
pub mod lots;
pub mod simulate;
pub mod validate;

use std::path::PathBuf;

/// Why a use case failed, with the cause kept as the source.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum AppError {
    /// Fitting failed (reading the session, the request, or the estimate itself).
    #[error("fitting {what}")]
    Fit {
        /// The session or unit.
        what: String,
        /// Why.
        #[source]
        source: crate::estimate::EstimateError,
    },
    /// Correcting with a calibration failed.
    #[error("correcting {what}")]
    Correct {
        /// The session or recording.
        what: String,
        /// Why.
        #[source]
        source: crate::correct::CorrectError,
    },
    /// A profile could not be read, written or rebuilt.
    #[error("profile {what}")]
    Profile {
        /// Which profile, or which store.
        what: String,
        /// Why.
        #[source]
        source: crate::profile::ProfileError,
    },
    /// A session could not be read.
    #[error("reading session {path}")]
    Session {
        /// The manifest.
        path: PathBuf,
        /// Why.
        #[source]
        source: crate::session::SessionError,
    },
    /// The model cannot be built as asked (an unknown effect, a coefficient of another model).
    #[error("the model for {what}")]
    Model {
        /// The session or unit.
        what: String,
        /// Why.
        #[source]
        source: crate::model::ModelError,
    },
    /// The request does not make sense for these data (nothing held out, one run only…).
    #[error("{0}")]
    Invalid(String),
}

/// An error and all its causes on one line, "outer: inner: innermost" (what the binary
/// prints, for places such as batch reports that keep a message instead of the error).
pub fn chain(e: &(dyn std::error::Error + 'static)) -> String {
    let mut s = e.to_string();
    let mut cause = e.source();
    while let Some(c) = cause {
        s.push_str(": ");
        s.push_str(&c.to_string());
        cause = c.source();
    }
    s
}
