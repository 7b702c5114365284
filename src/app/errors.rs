//! Exit codes: one number per kind of failure, the same for the command line (its exit
//! status) and the Python package (one exception class per code). The first error in a
//! cause chain that says which kind it is decides.

use crate::check::rules::RulesError;
use crate::correct::{CorrectError, StreamCsvError};
use crate::estimate::EstimateError;
use crate::profile::ProfileError;
use crate::session::{Problem, SessionError};

/// Exit code: a check or acceptance rule failed.
pub const EXIT_CHECK_FAILED: u8 = 1;
/// Exit code: bad usage, or a request these data cannot satisfy.
pub const EXIT_INPUT: u8 = 2;

/// Every exit code and its one meaning, as docs/reference-exit-codes.md lists them (and
/// `tests/exit_codes.rs` produces each one).
pub const EXIT_CODES: &[(u8, &str)] = &[
    (0, "success"),
    (1, "a check or an acceptance rule failed"),
    (2, "usage: a bad flag or value, or a request these data cannot satisfy"),
    (3, "a file cannot be read or written"),
    (4, "empty recording: no samples, or too few to analyse"),
    (5, "header missing, a required column absent or a column repeated"),
    (6, "a value is not a number, or is NaN, infinite or too large for a double"),
    (7, "a row has more or fewer fields than the header"),
    (8, "duplicate or decreasing t (or no usable sample interval)"),
    (9, "gap in t (with --strict)"),
    (10, "unknown or misspelled unit"),
    (11, "a JSON file (manifest, profile, rules) is not valid JSON or repeats a key"),
    (12, "unknown session format version"),
    (13, "a run's file is missing or is not a regular file"),
    (14, "a mount is not a rotation"),
    (15, "profile of an unknown format version"),
    (16, "profile of a different unit"),
    (17, "the runs cannot identify the requested model (with --strict)"),
    (18, "another invalid manifest value (out of its range, missing, of the wrong kind)"),
    (19, "malformed CSV (quoting, encoding, a line over 1 MiB)"),
    (20, "invalid rules file (unknown format version, rule kind, term or unit)"),
    (21, "invalid profile (a coefficient missing, repeated or not finite; g out of range; a scale matrix that cannot be inverted; in another unit's folder)"),
    (22, "the estimate failed (a nonlinear search did not converge, too few samples, values too large to compute with)"),
    (23, "the correction cannot be made (a non-finite result; an offline correction that does not converge; no temperature for a temperature model; temperatures outside the calibrated range with `--temperature-range error`)"),
    (24, "the output already exists (crosscal never overwrites without --force)"),
    (25, "invalid effects file (TOML syntax, an unknown variable or function, a coefficient never used or not linear, an expression not finite on the data)"),
];

/// The exit code of a session reading problem.
pub fn session_code(p: Problem) -> u8 {
    match p {
        Problem::Io => 3,
        Problem::Empty => 4,
        Problem::Header => 5,
        Problem::Value => 6,
        Problem::FieldCount => 7,
        Problem::Time => 8,
        Problem::Gap => 9,
        Problem::Units => 10,
        Problem::Json => 11,
        Problem::Format => 12,
        Problem::MissingFile => 13,
        Problem::Mount => 14,
        Problem::Malformed => 19,
        _ => 18,
    }
}

/// The exit code of one error of a chain, or `None` to look at its cause.
pub fn code_of(cause: &(dyn std::error::Error + 'static)) -> Option<u8> {
    if let Some(s) = cause.downcast_ref::<SessionError>() {
        return Some(session_code(s.problem()));
    }
    if let Some(p) = cause.downcast_ref::<ProfileError>() {
        return Some(match p {
            ProfileError::Io { .. } => 3,
            ProfileError::Json { .. } => 11,
            ProfileError::UnknownFormat { .. } => 15,
            ProfileError::WrongUnit { .. } => 16,
            ProfileError::BadTime(_) | ProfileError::BadSerial(_) => EXIT_INPUT,
            _ => 21,
        });
    }
    if let Some(r) = cause.downcast_ref::<RulesError>() {
        return Some(match r {
            RulesError::Io { .. } => 3,
            RulesError::Json { .. } => 11,
            _ => 20,
        });
    }
    if let Some(u) = cause.downcast_ref::<crate::model::user::UserEffectError>() {
        return Some(match u {
            crate::model::user::UserEffectError::Io { .. } => 3,
            _ => 25,
        });
    }
    if let Some(e) = cause.downcast_ref::<EstimateError>() {
        return match e {
            EstimateError::Read { .. } | EstimateError::UserEffect(_) => None,
            EstimateError::Unidentifiable(_) => Some(17),
            EstimateError::NoData => Some(4),
            EstimateError::NotConverged(_) | EstimateError::NonFinite { .. } | EstimateError::TooFewSamples { .. } => {
                Some(22)
            }
            _ => Some(EXIT_INPUT),
        };
    }
    if let Some(c) = cause.downcast_ref::<CorrectError>() {
        return Some(match c {
            CorrectError::Model(_) | CorrectError::Singular(_) => 21,
            CorrectError::TimeNotIncreasing { .. } => session_code(Problem::Time),
            CorrectError::NonFinite { .. }
            | CorrectError::MissingTemperature(_)
            | CorrectError::OutOfRange(_)
            | CorrectError::NotConverged { .. } => 23,
            _ => EXIT_INPUT,
        });
    }
    if let Some(c) = cause.downcast_ref::<StreamCsvError>() {
        return match c {
            StreamCsvError::NonFinite { .. } | StreamCsvError::Correct(CorrectError::OutOfRange(_)) => Some(23),
            StreamCsvError::Write(_) => Some(3),
            _ => None,
        };
    }
    if let Some(n) = cause.downcast_ref::<crate::noise::NoiseError>() {
        return Some(match n {
            crate::noise::NoiseError::TooShort(_) => 4,
            crate::noise::NoiseError::NotFinite { .. } => 6,
            _ => 8,
        });
    }
    match cause.downcast_ref::<crate::simulate::SimulateError>() {
        Some(crate::simulate::SimulateError::Exists(_)) => return Some(24),
        Some(crate::simulate::SimulateError::FileOutside { .. }) => return Some(EXIT_INPUT),
        _ => {}
    }
    if let Some(io) = cause.downcast_ref::<std::io::Error>() {
        return Some(if io.kind() == std::io::ErrorKind::AlreadyExists { 24 } else { 3 });
    }
    None
}

/// The exit code of an error: the first error of its chain (itself, then its sources) that
/// says; [`EXIT_INPUT`] when none does.
pub fn exit_code(e: &(dyn std::error::Error + 'static)) -> u8 {
    let mut cause = Some(e);
    while let Some(c) = cause {
        if let Some(code) = code_of(c) {
            return code;
        }
        cause = c.source();
    }
    EXIT_INPUT
}
