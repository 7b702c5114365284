//! Errors of the session reader. Every variant names the file; CSV errors name the line
//! and column too.

use std::path::PathBuf;

/// The kind of problem, one per distinct exit code of the command-line tool.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[non_exhaustive]
pub enum Problem {
    /// The file is empty or has no samples.
    Empty,
    /// The header line is missing or lacks a required column.
    Header,
    /// A value is not a number, or is NaN or infinite.
    Value,
    /// A row has more or fewer fields than the header (a truncated row, a stray comma).
    FieldCount,
    /// Time stamps repeat or decrease.
    Time,
    /// A gap in time larger than allowed (with `strict`).
    Gap,
    /// The CSV itself is malformed (quoting, encoding).
    Malformed,
    /// A unit is unknown or misspelled.
    Units,
    /// A mount is not a rotation.
    Mount,
    /// A run's file does not exist.
    MissingFile,
    /// The manifest is not JSON.
    Json,
    /// The manifest's format version is unknown.
    Format,
    /// Any other invalid manifest value.
    Invalid,
    /// The file cannot be read.
    Io,
}

/// A session or recording could not be read.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum SessionError {
    /// The file could not be opened or read (the operating system's reason follows as the
    /// cause).
    #[error("{path}: cannot read")]
    Io {
        /// The file.
        path: PathBuf,
        /// The operating-system error.
        source: std::io::Error,
    },
    /// The path names something that is not a regular file (a folder, FIFO or device).
    #[error("{path} is {what}: expected a regular file")]
    NotRegular {
        /// The path.
        path: PathBuf,
        /// What it is.
        what: &'static str,
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
    #[error("{path}: unknown session format '{found}': this crosscal reads 'crosscal-session/1' and 'crosscal-session/2'; upgrade crosscal or convert the session")]
    UnknownFormat {
        /// The manifest.
        path: PathBuf,
        /// The format string found.
        found: String,
    },
    /// A manifest value is invalid (unknown unit, bad mount, ...).
    #[error("{path}:{line}:{column}: {msg}")]
    Manifest {
        /// Kind of problem.
        problem: Problem,
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
        /// Kind of problem.
        problem: Problem,
        /// The recording.
        path: PathBuf,
        /// 1-based line.
        line: u64,
        /// Column, as "N (name)" or "-" when the whole line is at fault.
        column: String,
        /// What was found and what was expected.
        msg: String,
    },
    /// A binary log or bag (ROS bag, ULog, DataFlash) that cannot be read: the byte offset
    /// where reading stopped and what was expected there.
    #[error("{path}: byte {offset}: {msg}")]
    Log {
        /// Kind of problem.
        problem: Problem,
        /// The file.
        path: PathBuf,
        /// Byte offset in the file (or in the decompressed chunk, as the message says).
        offset: u64,
        /// What was found and what was expected.
        msg: String,
    },
}

impl SessionError {
    /// A log or bag that cannot be read at byte `offset`.
    pub fn log(problem: Problem, path: &std::path::Path, offset: u64, msg: impl Into<String>) -> Self {
        Self::Log { problem, path: path.to_path_buf(), offset, msg: msg.into() }
    }

    /// The kind of problem.
    pub fn problem(&self) -> Problem {
        match self {
            Self::Io { .. } => Problem::Io,
            Self::NotRegular { .. } => Problem::MissingFile,
            Self::Json { .. } => Problem::Json,
            Self::UnknownFormat { .. } => Problem::Format,
            Self::Manifest { problem, .. } | Self::Csv { problem, .. } | Self::Log { problem, .. } => *problem,
        }
    }
}
