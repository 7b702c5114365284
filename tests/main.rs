//! crosscal's integration tests: one test binary (links once), modules mirror the product.

mod allan;
mod architecture;
mod bad_input;
mod batch;
mod cli;
mod common;
mod diagnose;
mod diagnose_hard;
mod exit_codes;
mod fixtures;
mod fuzz;
mod fuzz_found;
mod hostile;
mod identify;
mod noise;
mod paper;
mod profile_store;
mod protocol;
mod real;
mod reference;
mod robust;
mod stand;
mod stream;
mod uncertainty;
mod validate;
