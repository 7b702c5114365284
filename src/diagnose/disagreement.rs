//! Coefficients that one run alone estimates differently from all runs together: a sign
//! that something depends on rate, direction, cone angle or mount.

use super::refit;
use crate::estimate::{CoefStatus, Fit, FitOptions, FitRun};
use crate::model::Model;
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
    /// (run − all) / run standard error.
    pub z: f64,
}

/// |z| above which a single-run estimate disagrees (many comparisons are made).
pub const DISAGREEMENT_Z: f64 = 6.0;

/// Refits the model on each run alone and lists coefficients that disagree with the
/// all-run fit by more than [`DISAGREEMENT_Z`] standard errors. Coefficients a single run
/// cannot identify are held at their all-run values, so the rest stay comparable.
pub fn per_run_disagreements(model: &Model, all: &Fit, runs: &[FitRun<'_>], opts: &FitOptions) -> Vec<Disagreement> {
    let mut out = Vec::new();
    for run in runs {
        let one = std::slice::from_ref(run);
        let Ok(first) = refit(model, one, opts) else { continue };
        let mut m = model.clone();
        for c in first.gyro.unidentifiable.iter().chain(&first.accel.unidentifiable) {
            if let Some(v) = all.get(&c.held).map(|c| c.value) {
                let _ = m.fix(&c.held, v);
            }
        }
        let Ok(f) = refit(&m, one, opts) else { continue };
        for c in f.gyro.coefficients.iter().chain(&f.accel.coefficients) {
            let (Some(se), Some(a)) = (c.std_error, all.get(&c.name)) else { continue };
            if c.status != CoefStatus::Fitted || a.status != CoefStatus::Fitted || se <= 0.0 {
                continue;
            }
            let z = (c.value - a.value) / se;
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
    }
    out.sort_by(|a, b| b.z.abs().total_cmp(&a.z.abs()));
    out
}
