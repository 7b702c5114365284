//! crosscal command-line interface.
fn main() {}
