//! Errors of the session reader. Every variant names the file; CSV errors name the line
//! and column too.

use std::path::PathBuf;

/// A session or recording could not be read.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum SessionError {
    /// The file could not be opened or read.
    #[error("{path}: cannot read: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The operating-system error.
        source: std::io::Error,
    },
    /// The manifest is not valid JSON or does not have the expected shape.
    #[error("{path}:{line}:{column}: {msg}")]
    Json {
        /// The manifest.
        path: PathBuf,
        /// 1-based line.
        line: usize,
        /// 1-based column.
        column: usize,
        /// What was wrong.
        msg: String,
    },
    /// The manifest's `format` is not one this reader knows.
    #[error("{path}: unknown session format '{found}': this crosscal reads 'crosscal-session/1'; upgrade crosscal or convert the session")]
    UnknownFormat {
        /// The manifest.
        path: PathBuf,
        /// The format string found.
        found: String,
    },
    /// A manifest value is invalid (unknown unit, bad mount, ...).
    #[error("{path}:{line}:{column}: {msg}")]
    Manifest {
        /// The manifest.
        path: PathBuf,
        /// 1-based line of the offending value (best effort; 0 if unknown).
        line: usize,
        /// 1-based column of the offending value (best effort; 0 if unknown).
        column: usize,
        /// What was found and what was expected.
        msg: String,
    },
    /// A CSV recording has a problem at a position.
    #[error("{path}:{line}:{column}: {msg}")]
    Csv {
        /// The recording.
        path: PathBuf,
        /// 1-based line.
        line: u64,
        /// Column, as "N (name)" or "-" when the whole line is at fault.
        column: String,
        /// What was found and what was expected.
        msg: String,
    },
}

impl SessionError {
    /// A short word for the kind of problem (used for exit codes and tests).
    pub fn kind(&self) -> &'static str {
        match self {
            Self::Io { .. } => "io",
            Self::Json { .. } => "json",
            Self::UnknownFormat { .. } => "format",
            Self::Manifest { .. } => "manifest",
            Self::Csv { .. } => "csv",
        }
    }
}
