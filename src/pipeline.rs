//! Glue for the one-way data flow: session → tracks (true motion in sensor axes) → fit.

use crate::estimate::{fit, EstimateError, Fit, FitOptions, FitRun};
use crate::model::Model;
use crate::motion::{track, DerivativeConfig, Track};
use crate::session::Session;

/// The true motion of every run of a session, in sensor axes.
pub fn tracks(session: &Session, deriv: &DerivativeConfig) -> Vec<Track> {
    session
        .runs
        .iter()
        .map(|r| track(r, session.manifest.g_m_s2, deriv))
        .collect()
}

/// Pairs each run's outputs with its track, for the estimator.
pub fn fit_runs<'a>(session: &'a Session, tracks: &'a [Track]) -> Vec<FitRun<'a>> {
    session
        .runs
        .iter()
        .zip(tracks)
        .map(|(r, tr)| FitRun {
            name: &r.spec.name,
            track: tr,
            gyro: &r.rec.gyro,
            accel: &r.rec.accel,
            temp_c: r.rec.temp_c.as_deref(),
            temp_const_c: r.spec.temperature_c,
        })
        .collect()
}

/// Fits a model to all runs of a session.
pub fn fit_session(
    session: &Session,
    model: &Model,
    opts: &FitOptions,
) -> Result<Fit, EstimateError> {
    let tr = tracks(session, &DerivativeConfig::default());
    fit(model, &fit_runs(session, &tr), opts)
}
