//! Subcommands. Parsing and printing only; every number comes from the library.

mod check;
mod correct;
mod demo;
mod fit;
mod format;
mod simulate;

use clap::{Parser, Subcommand};
use std::process::ExitCode;

/// Exit code: a check or acceptance rule failed.
pub const EXIT_CHECK_FAILED: u8 = 1;
/// Exit code: bad input, bad usage, or an error while processing.
pub const EXIT_INPUT: u8 = 2;

/// Cross-coupling calibration of gyro and accelerometer triads on a conic-motion stand.
#[derive(Debug, Parser)]
#[command(name = "crosscal", version, about, long_about = None)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Debug, Subcommand)]
enum Command {
    /// Write a synthetic stand session (the paper's unit by default).
    Simulate(simulate::Args),
    /// Fit a calibration profile to a session and store it under calib-profiles/.
    Fit(fit::Args),
    /// Correct a recording (CSV) with a profile.
    Correct(correct::Args),
    /// Compare corrected outputs with a session's reference motion; exit 1 on failure.
    Check(check::Args),
    /// Run the whole pipeline on the paper's stand and print the paper comparison.
    Demo(demo::Args),
}

/// Outcome of a subcommand that succeeded in running.
pub enum Outcome {
    /// Everything passed.
    Ok,
    /// A check failed (exit 1).
    CheckFailed,
}

/// Entry point.
pub fn main() -> ExitCode {
    let cli = match Cli::try_parse() {
        Ok(c) => c,
        Err(e) => {
            let _ = e.print();
            return if e.use_stderr() {
                ExitCode::from(EXIT_INPUT)
            } else {
                ExitCode::SUCCESS
            };
        }
    };
    let result = match cli.command {
        Command::Simulate(a) => simulate::run(a),
        Command::Fit(a) => fit::run(a),
        Command::Correct(a) => correct::run(a),
        Command::Check(a) => check::run(a),
        Command::Demo(a) => demo::run(a),
    };
    match result {
        Ok(Outcome::Ok) => ExitCode::SUCCESS,
        Ok(Outcome::CheckFailed) => ExitCode::from(EXIT_CHECK_FAILED),
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::from(EXIT_INPUT)
        }
    }
}

/// Parses "x,y,z" into three numbers.
pub fn parse_triple(s: &str) -> Result<[f64; 3], String> {
    let v: Result<Vec<f64>, _> = s.split(',').map(|p| p.trim().parse::<f64>()).collect();
    match v {
        Ok(v) if v.len() == 3 && v.iter().all(|x| x.is_finite()) => Ok([v[0], v[1], v[2]]),
        _ => Err(format!(
            "expected three finite numbers 'x,y,z', found '{s}'"
        )),
    }
}

/// A comma-separated list of numbers on the command line.
#[derive(Debug, Clone)]
pub struct List(pub Vec<f64>);

/// Parses a comma-separated list of finite numbers.
pub fn parse_list(s: &str) -> Result<List, String> {
    let v: Result<Vec<f64>, _> = s.split(',').map(|p| p.trim().parse::<f64>()).collect();
    match v {
        Ok(v) if !v.is_empty() && v.iter().all(|x| x.is_finite()) => Ok(List(v)),
        _ => Err(format!(
            "expected a comma-separated list of numbers, found '{s}'"
        )),
    }
}
