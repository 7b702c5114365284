//! Shared helpers.

use crosscal::correct::Calibration;
use crosscal::estimate::{EstimateError, Fit, FitOptions, FitRequest};
use crosscal::model::Model;
use crosscal::profile::Profile;
use crosscal::session::Session;

/// Fits exactly `model` to a session in memory through the one fit entry point.
pub fn fit_session(session: &Session, model: &Model, opts: &FitOptions) -> Result<Fit, EstimateError> {
    Ok(crosscal::estimate::fit(&FitRequest::session(model, session).options(*opts))?.fit)
}

/// Fits the default model and builds the calibration (through a profile, like the CLI).
pub fn fit_and_calibrate(session: &Session, model: &Model) -> (Fit, Profile, Calibration) {
    let fit = fit_session(session, model, &FitOptions::default()).expect("fit");
    let profile = Profile::from_fit(session, model, fit.clone(), vec![]);
    let cal = Calibration::from_profile(&profile).expect("calibration");
    (fit, profile, cal)
}

/// Path of the built binary.
pub fn bin() -> std::path::PathBuf {
    std::path::PathBuf::from(env!("CARGO_BIN_EXE_crosscal"))
}

/// Runs the binary in a folder; returns (exit code, stdout, stderr).
pub fn run_in(dir: &std::path::Path, args: &[&str]) -> (i32, String, String) {
    let out = std::process::Command::new(bin()).args(args).current_dir(dir).output().expect("run crosscal");
    (
        out.status.code().unwrap_or(-1),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

/// Maps `f` over `items` on two threads, keeping the order.
pub fn par_map<I: Sync, T: Send>(items: &[I], f: impl Fn(&I) -> T + Sync) -> Vec<T> {
    let mut out = Vec::with_capacity(items.len());
    std::thread::scope(|s| {
        let f = &f;
        let handles: Vec<_> = items
            .chunks(items.len().div_ceil(2).max(1))
            .map(|chunk| s.spawn(move || chunk.iter().map(f).collect::<Vec<T>>()))
            .collect();
        for h in handles {
            out.extend(h.join().expect("worker"));
        }
    });
    out
}
