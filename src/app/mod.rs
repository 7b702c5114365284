//! The use cases shared by the command line, batch runs and the bindings: fit and store,
//! validate on held-out runs, accept, calibrate a lot, write reports.
//!
//! Top layer of the library: it may use every module below it, and nothing below uses it.

pub mod batch;
pub mod pipeline;
