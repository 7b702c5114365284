//! The in-memory fit strategy: the runs' checks (samples, temperatures, user effects), then
//! the variable projection when the model has nonlinear parameters, else the linear least
//! squares over the runs as sample sources. A strategy: it calls the solvers
//! ([`super::linear`], [`super::nonlinear`]) and is called by the fit's entry points.

use super::linear::{fit_samples, Samples, SamplesError};
use super::{nonlinear, EstimateError, Fit, FitOptions, FitRun};
use crate::model::Model;

/// Fits both sensors of a model to in-memory runs (nonlinear effects by variable
/// projection).
pub(crate) fn fit_in_memory(model: &Model, runs: &[FitRun<'_>], opts: &FitOptions) -> Result<Fit, EstimateError> {
    if runs.iter().all(|r| r.is_empty()) {
        return Err(EstimateError::NoData);
    }
    for e in model.effects().iter().filter(|e| e.needs_temperature()) {
        if let Some(r) = runs.iter().find(|r| r.temp_c.is_none() && r.temp_const_c.is_none()) {
            return Err(EstimateError::MissingTemperature { effect: e.id().to_string(), run: r.name.to_string() });
        }
    }
    if !model.nonlinear().is_empty() {
        super::runs::check_user_effects(model, runs)?;
        return nonlinear::fit(model, runs, opts);
    }
    let sources: Vec<&dyn Samples> = runs.iter().map(|r| r as &dyn Samples).collect();
    // The linear pass checks the user effects' columns as it fills them (no pass of its own).
    fit_samples(model, &sources, runs, opts).map_err(SamplesError::in_memory)
}
