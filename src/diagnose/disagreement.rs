//! Coefficients that one run alone estimates differently from all runs together: a sign
//! that something depends on rate, direction, cone angle or mount.

use super::refit;
use crate::estimate::{CoefStatus, Fit, FitOptions, FitRun};
use crate::model::Model;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

/// A coefficient whose estimate from one run differs from the all-run estimate.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Disagreement {
    /// Coefficient.
    pub coefficient: String,
    /// Run.
    pub run: String,
    /// Estimate from that run alone (coefficients it cannot identify held at the all-run values).
    pub run_value: f64,
    /// Its standard error.
    pub run_std_error: f64,
    /// All-run estimate.
    pub all_value: f64,
    /// (run − all) / √(run standard error² + all-run standard error²).
    pub z: f64,
}

/// Samples of a run, about, that the first fit of its disagreements (what the run cannot
/// identify) is made on.
const QUICK_SAMPLES: usize = 8192;

/// |z| above which a single-run estimate disagrees (many comparisons are made).
pub const DISAGREEMENT_Z: f64 = 6.0;

/// Refits the model on each run alone and lists coefficients that disagree with the
/// all-run fit by more than [`DISAGREEMENT_Z`] standard errors of their difference.
/// Coefficients a single run cannot identify are held at their all-run values, so the rest
/// stay comparable; with slow noise, each run's errors carry the slow noise the all-run fit
/// measured ([`FitOptions::slow_noise_held`]).
pub fn per_run_disagreements(model: &Model, all: &Fit, runs: &[FitRun<'_>], opts: &FitOptions) -> Vec<Disagreement> {
    // Each run's fits are independent: the runs in parallel, their lists joined in run order.
    let per_run: Vec<Vec<Disagreement>> = runs.par_iter().map(|run| run_disagreements(model, all, run, opts)).collect();
    let mut out: Vec<Disagreement> = per_run.into_iter().flatten().collect();
    out.sort_by(|a, b| b.z.abs().total_cmp(&a.z.abs()));
    out
}

/// One run's disagreements with the all-run fit `all`.
fn run_disagreements(model: &Model, all: &Fit, run: &FitRun<'_>, opts: &FitOptions) -> Vec<Disagreement> {
    let one = std::slice::from_ref(run);
    // The first fit only tells what the run cannot identify; the fit compared carries the
    // slow noise the whole session measured (one run tells its wander poorly).
    let quick = FitOptions { slow_noise: false, ..*opts };
    let session_slow = std::array::from_fn(|c| all.slow_noise(c));
    let opts = &FitOptions { slow_noise_held: Some(session_slow), ..*opts };
    // What a run identifies is a property of its motion, which every k-th sample holds as
    // well (the stand's motion is slow against the sampling): the first fit on those.
    let reduced = super::reduced::Reduced::new(one, super::reduced::step_for(one, QUICK_SAMPLES), |_| false);
    let Ok(first) = refit(model, &reduced.runs(one), &quick) else { return Vec::new() };
    let held: Vec<&String> =
        first.gyro.unidentifiable.iter().chain(&first.accel.unidentifiable).map(|c| &c.held).collect();
    // The fit compared is on every sample; what the run cannot identify is held at the
    // all-run values.
    let f = {
        let mut m = model.clone();
        for name in held {
            if let Some(v) = all.get(name).map(|c| c.value) {
                let _ = m.fix(name, v);
            }
        }
        let Ok(f) = refit(&m, one, opts) else { return Vec::new() };
        f
    };
    let mut out = Vec::new();
    for c in f.gyro.coefficients.iter().chain(&f.accel.coefficients) {
        let (Some(se), Some(a)) = (c.std_error, all.get(&c.name)) else { continue };
        if c.status != CoefStatus::Fitted || a.status != CoefStatus::Fitted || se <= 0.0 {
            continue;
        }
        // The all-run estimate's own error counts too: under slow noise it can be the larger
        // (a wandering bias moves what each run's constant regressors tell the whole fit),
        // and the two are positively correlated, so the sum is an upper bound.
        let z = (c.value - a.value) / se.hypot(a.std_error.unwrap_or(0.0));
        if z.abs() > DISAGREEMENT_Z {
            out.push(Disagreement {
                coefficient: c.name.clone(),
                run: run.name.to_string(),
                run_value: c.value,
                run_std_error: se,
                all_value: a.value,
                z,
            });
        }
    }
    out
}
