//! Nonlinear parameters by variable projection: for given nonlinear parameters p (time
//! delay, dead-zone widths), the true motion is transformed as the sensor sees it and the
//! linear model is solved exactly (QR); argmin's Nelder–Mead minimises the resulting
//! noise-weighted residual J(p) = Σ_sensors RSS_s(p)/σ_s². The standard errors of p come
//! from the numerical Hessian H of J at the optimum: cov(p) = 2 H⁻¹ (for least squares
//! J ≈ J₀ + Δpᵀ (JᵀJ/σ²) Δp). The linear coefficients' standard errors are conditional on
//! p̂.

use super::linear::fit_sensor;
use super::{EstimateError, Fit, FitOptions, FitRun, SensorFit};
use crate::model::Model;
use crate::motion::Track;
use crate::units::SensorKind;
use argmin::core::{CostFunction, Executor, State, TerminationReason};
use argmin::solver::neldermead::NelderMead;
use serde::{Deserialize, Serialize};

/// A fitted nonlinear parameter.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct NonlinearParam {
    /// Effect id.
    pub effect: String,
    /// Parameter name.
    pub name: String,
    /// SI unit.
    pub unit: String,
    /// Value.
    pub value: f64,
    /// Standard error (None when held, or at a bound where it is not defined).
    pub std_error: Option<f64>,
    /// Whether it was estimated.
    pub fitted: bool,
}

/// Maps an optimiser coordinate into a parameter's range: a parameter bounded below by 0
/// (a width) is reflected (|p|), so the objective stays smooth and symmetric through zero;
/// others are clamped.
fn bounded(d: &crate::model::ParamDef, v: f64) -> f64 {
    if d.min == 0.0 && v < 0.0 {
        (-v).min(d.max)
    } else {
        v.clamp(d.min, d.max)
    }
}

/// Per-entry parameter values from the flattened vector of fitted ones (within bounds).
fn expand(model: &Model, p: &[f64]) -> Vec<Vec<f64>> {
    let mut k = 0;
    model
        .nonlinear()
        .iter()
        .map(|e| {
            let defs = e.effect.params();
            if e.fitted {
                defs.iter()
                    .map(|d| {
                        let v = bounded(d, p.get(k).copied().unwrap_or(d.nominal));
                        k += 1;
                        v
                    })
                    .collect()
            } else {
                e.values.clone()
            }
        })
        .collect()
}

fn tracks_for(model: &Model, values: &[Vec<f64>], sensor: SensorKind, runs: &[FitRun<'_>]) -> Option<Vec<Track>> {
    let applies: Vec<usize> = (0..model.nonlinear().len())
        .filter(|&i| model.nonlinear()[i].effect.sensor().is_none_or(|s| s == sensor))
        .collect();
    if applies.is_empty() {
        return None;
    }
    Some(
        runs.iter()
            .map(|r| {
                let first = applies[0];
                let mut tr = model.nonlinear()[first].effect.transform(&values[first], r.track);
                for &i in &applies[1..] {
                    tr = model.nonlinear()[i].effect.transform(&values[i], &tr);
                }
                tr
            })
            .collect(),
    )
}

fn sensor_fit_at(
    model: &Model,
    values: &[Vec<f64>],
    sensor: SensorKind,
    runs: &[FitRun<'_>],
    opts: &FitOptions,
) -> Result<SensorFit, EstimateError> {
    // A user effect's linear part at the parameters being tried (no-op for the catalogue's).
    let bound;
    let model = if model.has_bound_parameters() {
        bound = model.at_nonlinear_values(values);
        &bound
    } else {
        model
    };
    match tracks_for(model, values, sensor, runs) {
        None => fit_sensor(model, sensor, runs, opts),
        Some(tracks) => {
            let moved: Vec<FitRun<'_>> = runs.iter().zip(&tracks).map(|(r, t)| FitRun { track: t, ..*r }).collect();
            fit_sensor(model, sensor, &moved, opts)
        }
    }
}

fn rss(f: &SensorFit) -> f64 {
    f.channels.iter().map(|c| c.residual_rms * c.residual_rms * c.n as f64).sum()
}

struct Objective<'a, 'b> {
    model: &'a Model,
    runs: &'a [FitRun<'b>],
    /// The fit's options for J's evaluations: screening (J needs each sensor's residual
    /// sum of squares, which the solve gives; the second pass over the samples, for the
    /// residual's statistics, is skipped), without the slow-noise pass.
    opts: FitOptions,
    sensors: Vec<(SensorKind, f64)>,
}

impl Objective<'_, '_> {
    fn value(&self, p: &[f64]) -> f64 {
        let values = expand(self.model, p);
        let mut j = 0.0;
        for &(s, sigma2) in &self.sensors {
            match sensor_fit_at(self.model, &values, s, self.runs, &self.opts) {
                Ok(f) => j += rss(&f) / sigma2,
                Err(_) => return f64::INFINITY,
            }
        }
        j
    }
}

impl CostFunction for Objective<'_, '_> {
    type Param = Vec<f64>;
    type Output = f64;

    fn cost(&self, p: &Self::Param) -> Result<f64, argmin::core::Error> {
        Ok(self.value(p))
    }
}

/// The motion each run shows `sensor` under a fitted model's nonlinear parameters (None
/// when no nonlinear effect touches that sensor).
pub fn seen_tracks(model: &Model, fit: &Fit, sensor: SensorKind, runs: &[FitRun<'_>]) -> Option<Vec<Track>> {
    tracks_for(model, &fitted_values(model, fit), sensor, runs)
}

/// The nonlinear parameters of each of `model`'s nonlinear entries as `fit` estimated them
/// (an entry the fit does not carry keeps the model's values).
pub fn fitted_values(model: &Model, fit: &Fit) -> Vec<Vec<f64>> {
    model
        .nonlinear()
        .iter()
        .map(|e| {
            let mine: Vec<f64> = fit.nonlinear.iter().filter(|p| p.effect == e.effect.id()).map(|p| p.value).collect();
            if mine.len() == e.values.len() {
                mine
            } else {
                e.values.clone()
            }
        })
        .collect()
}

/// `model` with every nonlinear parameter held at the value `fit` estimated (the model's
/// own where the fit carries none): a fit of it solves only the linear coefficients, one
/// pass over the samples instead of a search, for re-solving around a motion that moved
/// little (the stand's corrections) once the nonlinear parameters are known.
pub fn held_at_fit(model: &Model, fit: &Fit) -> Model {
    let mut m = model.clone();
    for (e, values) in model.nonlinear().iter().zip(fitted_values(model, fit)) {
        // The entry is the model's own, so holding it cannot fail.
        let _ = m.fix_nonlinear(e.effect.id(), values);
    }
    m
}

/// `model` with the linear parts of its user effects at the parameters `fit` estimated
/// (a knee's coefficient column at the fitted knee rate), for evaluating the fit's residual;
/// a plain clone when no linear part depends on a parameter.
pub fn bound_at_fit(model: &Model, fit: &Fit) -> Model {
    if model.has_bound_parameters() {
        model.at_nonlinear_values(&fitted_values(model, fit))
    } else {
        model.clone()
    }
}

/// The fitted nonlinear parameters' definitions, in order: (effect id, definition).
type Defs = Vec<(String, crate::model::ParamDef)>;

/// Coarse start: each parameter scanned alone over ±{0.5 … 64}× its scale, so that the
/// simplex starts in the right basin without hand tuning.
fn coarse_start(obj: &Objective<'_, '_>, defs: &Defs, mut p0: Vec<f64>) -> Vec<f64> {
    let mut j_best = obj.value(&p0);
    for (i, (_, d)) in defs.iter().enumerate() {
        let base = p0[i];
        for m in [0.5, 1.0, 2.0, 4.0, 8.0, 16.0, 32.0, 64.0] {
            for sign in [1.0, -1.0] {
                if sign < 0.0 && d.min == 0.0 {
                    continue;
                }
                let mut q = p0.clone();
                q[i] = base + sign * m * d.scale;
                let j = obj.value(&q);
                if j < j_best {
                    j_best = j;
                    p0 = q;
                }
            }
        }
    }
    p0
}

/// Nelder–Mead from `p0` (a simplex of one scale step per parameter); the best point, within
/// bounds, and the objective back for the Hessian. A search that stops on its iteration
/// budget is an error unless screening.
fn simplex<'a, 'b>(
    obj: Objective<'a, 'b>,
    defs: &Defs,
    p0: Vec<f64>,
    screening: bool,
) -> Result<(Vec<f64>, Option<Objective<'a, 'b>>), EstimateError> {
    let mut simplex = vec![p0.clone()];
    for (i, (_, d)) in defs.iter().enumerate() {
        let mut v = p0.clone();
        v[i] += d.scale;
        simplex.push(v);
    }
    let solver = NelderMead::new(simplex)
        // J is in χ² units: a spread of 1e-4 across the simplex is far below 1σ.
        .with_sd_tolerance(1e-4)
        .map_err(|e| EstimateError::NotConverged(e.to_string()))?;
    let budget = if screening { 30 } else { 400 } * defs.len() as u64;
    let res = Executor::new(obj, solver)
        .configure(|s| s.max_iters(budget))
        .run()
        .map_err(|e| EstimateError::NotConverged(e.to_string()))?;
    let state = res.state();
    if !screening && matches!(state.get_termination_reason(), Some(TerminationReason::MaxItersReached)) {
        return Err(EstimateError::NotConverged(format!(
            "{} did not converge from the nominal start in {} iterations",
            defs.iter().map(|d| d.1.name.as_str()).collect::<Vec<_>>().join(", "),
            state.get_iter()
        )));
    }
    let mut p_hat = state.get_best_param().cloned().unwrap_or(p0);
    for (i, (_, d)) in defs.iter().enumerate() {
        p_hat[i] = bounded(d, p_hat[i]);
    }
    Ok((p_hat, res.problem.problem))
}

/// Standard errors of the parameters from the numerical Hessian H of J at p̂ (central
/// differences): cov(p) = 2 H⁻¹. Parameters at a bound (e.g. a zero dead zone) have none.
fn hessian_std_errors(obj: &Objective<'_, '_>, defs: &Defs, p_hat: &[f64]) -> Vec<Option<f64>> {
    let n = defs.len();
    let mut ses = vec![None; n];
    let h: Vec<f64> = defs.iter().zip(p_hat).map(|((_, d), v)| (d.scale * 1e-2).max(v.abs() * 1e-3)).collect();
    let free: Vec<usize> =
        (0..n).filter(|&i| p_hat[i] - h[i] >= defs[i].1.min && p_hat[i] + h[i] <= defs[i].1.max).collect();
    if free.is_empty() {
        return ses;
    }
    let j0 = obj.value(p_hat);
    let m = free.len();
    let mut hess = nalgebra::DMatrix::<f64>::zeros(m, m);
    let shifted = |i: usize, si: f64, j: usize, sj: f64| {
        let mut q = p_hat.to_vec();
        q[i] += si * h[i];
        q[j] += sj * h[j];
        obj.value(&q)
    };
    for (a, &i) in free.iter().enumerate() {
        hess[(a, a)] = (shifted(i, 1.0, i, 0.0) - 2.0 * j0 + shifted(i, -1.0, i, 0.0)) / (h[i] * h[i]);
        for (b, &j) in free.iter().enumerate().take(a) {
            let v = (shifted(i, 1.0, j, 1.0) - shifted(i, 1.0, j, -1.0) - shifted(i, -1.0, j, 1.0)
                + shifted(i, -1.0, j, -1.0))
                / (4.0 * h[i] * h[j]);
            hess[(a, b)] = v;
            hess[(b, a)] = v;
        }
    }
    if let Some(inv) = hess.try_inverse() {
        for (a, &i) in free.iter().enumerate() {
            let v = 2.0 * inv[(a, a)];
            ses[i] = (v > 0.0 && v.is_finite()).then(|| v.sqrt());
        }
    }
    ses
}

/// Fits a model with nonlinear effects.
pub(crate) fn fit(model: &Model, runs: &[FitRun<'_>], opts: &FitOptions) -> Result<Fit, EstimateError> {
    let start: Vec<Vec<f64>> = model.nonlinear().iter().map(|e| e.values.clone()).collect();
    let defs: Defs = model
        .nonlinear()
        .iter()
        .filter(|e| e.fitted)
        .flat_map(|e| e.effect.params().into_iter().map(|d| (e.effect.id().to_string(), d)).collect::<Vec<_>>())
        .collect();
    let p0: Vec<f64> = model.nonlinear().iter().filter(|e| e.fitted).flat_map(|e| e.values.clone()).collect();
    let affected: Vec<SensorKind> = SensorKind::BOTH
        .into_iter()
        .filter(|s| model.nonlinear().iter().any(|e| e.effect.sensor().is_none_or(|x| x == *s)))
        .collect();
    let mut p_hat = p0.clone();
    let mut ses: Vec<Option<f64>> = vec![None; defs.len()];
    if !defs.is_empty() {
        let mut sensors = Vec::new();
        for &s in &affected {
            let f = sensor_fit_at(model, &start, s, runs, opts)?;
            let s2 = f.channels.iter().map(|c| c.sigma * c.sigma).sum::<f64>() / 3.0;
            sensors.push((s, s2.max(f64::MIN_POSITIVE)));
        }
        let inner = FitOptions { screening: true, slow_noise: false, ..*opts };
        let obj = Objective { model, runs, opts: inner, sensors };
        let p0 = coarse_start(&obj, &defs, p0);
        let (best, obj) = simplex(obj, &defs, p0, opts.screening)?;
        p_hat = best;
        if let Some(obj) = obj.as_ref().filter(|_| !opts.screening) {
            ses = hessian_std_errors(obj, &defs, &p_hat);
        }
    }
    let values = expand(model, &p_hat);
    let gyro = sensor_fit_at(model, &values, SensorKind::Gyro, runs, opts)?;
    let accel = sensor_fit_at(model, &values, SensorKind::Accel, runs, opts)?;
    let mut params = Vec::new();
    let mut k = 0;
    for (e, v) in model.nonlinear().iter().zip(&values) {
        for (d, x) in e.effect.params().iter().zip(v) {
            params.push(NonlinearParam {
                effect: e.effect.id().to_string(),
                name: d.name.clone(),
                unit: d.unit.to_string(),
                value: *x,
                std_error: if e.fitted { ses.get(k).copied().flatten() } else { None },
                fitted: e.fitted,
            });
            if e.fitted {
                k += 1;
            }
        }
    }
    Ok(Fit { gyro, accel, nonlinear: params, stand: Vec::new(), stand_base: None })
}
