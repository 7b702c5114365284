//! crosscal command-line interface: a thin layer over the library.
//!
//! Exit codes: 0 success; 1 a check or acceptance failed; 2 bad input or usage.

use std::process::ExitCode;

mod cli;

fn main() -> ExitCode {
    cli::main()
}
