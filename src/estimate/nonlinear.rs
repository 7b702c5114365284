//! Nonlinear parameters by variable projection: for given nonlinear parameters p (time
//! delay, dead-zone widths), the true motion is transformed as the sensor sees it and the
//! linear model is solved exactly (QR); argmin's Nelder–Mead, after a coarse scan, minimises
//! the resulting noise-weighted residual J(p) = Σ_sensors RSS_s(p)/σ_s². A start known to
//! lie near the optimum ([`Model::start_near`]: what the diagnosis's first look fitted on
//! fewer samples, or before a small correction of the motion) takes Newton steps instead,
//! on the same central differences the standard errors use. The standard errors of p come from the numerical Hessian H of J at the
//! optimum, in units of each sensor's noise there: cov(p) = 2 H⁻¹ (for least squares
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

/// Standard errors a near start's step spans ([`near_fit`]).
const NEAR_STEPS: f64 = 3.0;

/// `model` with each fitted nonlinear effect's search started where `fit` put it, within
/// three of its standard errors ([`Model::start_near`]): for a search on more
/// samples of the same runs, or on a motion that moved little. An effect with a parameter
/// without a standard error (at a bound) keeps its start, as does one `fit` does not carry.
pub fn near_fit(model: &Model, fit: &Fit) -> Model {
    let mut m = model.clone();
    for e in model.nonlinear().iter().filter(|e| e.fitted) {
        let mine: Vec<&NonlinearParam> = fit.nonlinear.iter().filter(|p| p.effect == e.effect.id()).collect();
        let steps: Option<Vec<f64>> = mine
            .iter()
            .map(|p| p.std_error.filter(|se| *se > 0.0 && se.is_finite()).map(|se| NEAR_STEPS * se))
            .collect();
        if let Some(steps) = steps.filter(|s| s.len() == e.values.len()) {
            let values: Vec<f64> = mine.iter().map(|p| p.value).collect();
            m.start_near(e.effect.id(), &values, steps);
        }
    }
    m
}

/// The fitted nonlinear parameters' definitions, in order: (effect id, definition).
type Defs = Vec<(String, crate::model::ParamDef)>;

/// Coarse start: each parameter without a near start (`near[i]` None) scanned alone over
/// ±{0.5 … 64}× its scale, so that the simplex starts in the right basin without hand
/// tuning.
fn coarse_start(obj: &Objective<'_, '_>, defs: &Defs, near: &[Option<f64>], mut p0: Vec<f64>) -> Vec<f64> {
    if near.iter().all(Option::is_some) {
        return p0;
    }
    let mut j_best = obj.value(&p0);
    for (i, (_, d)) in defs.iter().enumerate().filter(|(i, _)| near[*i].is_none()) {
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

/// Nelder–Mead from `p0` (a simplex of one step per parameter: its near step, else its
/// scale); the best point, within bounds, and the objective back for the Hessian. A search
/// that stops on its iteration budget is an error unless screening.
fn simplex<'a, 'b>(
    obj: Objective<'a, 'b>,
    defs: &Defs,
    near: &[Option<f64>],
    p0: Vec<f64>,
    screening: bool,
) -> Result<(Vec<f64>, Option<Objective<'a, 'b>>), EstimateError> {
    let mut simplex = vec![p0.clone()];
    for (i, (_, d)) in defs.iter().enumerate() {
        let mut v = p0.clone();
        v[i] += near[i].unwrap_or(d.scale);
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

/// J at a point with its central-difference gradient and Hessian over some of the
/// parameters.
struct Local {
    j: f64,
    grad: nalgebra::DVector<f64>,
    hess: nalgebra::DMatrix<f64>,
}

/// The central-difference step of each parameter at `p`: a hundredth of its scale, or a
/// thousandth of its value when that is larger.
fn diff_steps(defs: &Defs, p: &[f64]) -> Vec<f64> {
    defs.iter().zip(p).map(|((_, d), v)| (d.scale * 1e-2).max(v.abs() * 1e-3)).collect()
}

/// J at `p` with its gradient and Hessian over the parameters `free` by central
/// differences of steps `h`: ∂J/∂pᵢ = (J(p + hᵢ) − J(p − hᵢ)) / 2hᵢ, ∂²J/∂pᵢ² =
/// (J(p + hᵢ) − 2J(p) + J(p − hᵢ)) / hᵢ², and the cross terms from the four corners
/// (J(+,+) − J(+,−) − J(−,+) + J(−,−)) / 4hᵢhⱼ.
fn local(obj: &Objective<'_, '_>, p: &[f64], h: &[f64], free: &[usize]) -> Local {
    let j0 = obj.value(p);
    let m = free.len();
    let mut hess = nalgebra::DMatrix::<f64>::zeros(m, m);
    let mut grad = nalgebra::DVector::<f64>::zeros(m);
    let shifted = |i: usize, si: f64, j: usize, sj: f64| {
        let mut q = p.to_vec();
        q[i] += si * h[i];
        q[j] += sj * h[j];
        obj.value(&q)
    };
    for (a, &i) in free.iter().enumerate() {
        let (up, down) = (shifted(i, 1.0, i, 0.0), shifted(i, -1.0, i, 0.0));
        hess[(a, a)] = (up - 2.0 * j0 + down) / (h[i] * h[i]);
        grad[a] = (up - down) / (2.0 * h[i]);
        for (b, &j) in free.iter().enumerate().take(a) {
            let v = (shifted(i, 1.0, j, 1.0) - shifted(i, 1.0, j, -1.0) - shifted(i, -1.0, j, 1.0)
                + shifted(i, -1.0, j, -1.0))
                / (4.0 * h[i] * h[j]);
            hess[(a, b)] = v;
            hess[(b, a)] = v;
        }
    }
    Local { j: j0, grad, hess }
}

/// Standard errors of the parameters from the numerical Hessian H of J at p̂ (central
/// differences, [`local`]): cov(p) = 2 H⁻¹. Parameters at a bound (e.g. a zero dead zone)
/// have none.
fn hessian_std_errors(obj: &Objective<'_, '_>, defs: &Defs, p_hat: &[f64]) -> Vec<Option<f64>> {
    let n = defs.len();
    let mut ses = vec![None; n];
    let h = diff_steps(defs, p_hat);
    let free: Vec<usize> =
        (0..n).filter(|&i| p_hat[i] - h[i] >= defs[i].1.min && p_hat[i] + h[i] <= defs[i].1.max).collect();
    if free.is_empty() {
        return ses;
    }
    if let Some(inv) = local(obj, p_hat, &h, &free).hess.try_inverse() {
        for (a, &i) in free.iter().enumerate() {
            let v = 2.0 * inv[(a, a)];
            ses[i] = (v > 0.0 && v.is_finite()).then(|| v.sqrt());
        }
    }
    ses
}

/// Newton steps at most, from a near start.
const NEWTON_STEPS: usize = 6;
/// A Newton step below this fraction of every standard error ends the search.
const NEWTON_DONE: f64 = 0.05;

/// The search from a start near the optimum (every parameter with a near step): Newton
/// steps p ← p − H⁻¹∇J on J's central-difference gradient and Hessian ([`local`]), the
/// ones the standard errors come from. Near the optimum J of a least-squares fit is
/// quadratic (J ≈ J₀ + Δpᵀ H Δp / 2), so one or two steps land where a simplex needs
/// dozens of evaluations. Done when the next step is below [`NEWTON_DONE`] of every
/// standard error (cov(p) = 2 H⁻¹): the point and its standard errors, exactly those
/// [`hessian_std_errors`] gives there. None (the simplex then searches) when a difference
/// step would leave a parameter's range, H is not positive definite, a step does not
/// lower J, or [`NEWTON_STEPS`] do not settle.
fn newton(obj: &Objective<'_, '_>, defs: &Defs, p0: Vec<f64>) -> Option<(Vec<f64>, Vec<Option<f64>>)> {
    let n = defs.len();
    let all: Vec<usize> = (0..n).collect();
    let mut p = p0;
    let mut j_start = None;
    for _ in 0..NEWTON_STEPS {
        let h = diff_steps(defs, &p);
        if (0..n).any(|i| p[i] - h[i] < defs[i].1.min || p[i] + h[i] > defs[i].1.max) {
            return None;
        }
        let l = local(obj, &p, &h, &all);
        let chol = l.hess.cholesky()?;
        let step = chol.solve(&l.grad);
        let cov = chol.inverse() * 2.0;
        let se: Vec<f64> = (0..n).map(|i| cov[(i, i)].sqrt()).collect();
        if se.iter().any(|v| !v.is_finite()) {
            return None;
        }
        // J is in units of the residual variance at the start, ≈ J(start) per sample: at p
        // the standard errors in the residual's own noise are smaller by √(J(p)/J(start)).
        let shrink = (l.j / *j_start.get_or_insert(l.j)).sqrt();
        if (0..n).all(|i| step[i].abs() <= NEWTON_DONE * se[i] * shrink) {
            return Some((p, se.into_iter().map(Some).collect()));
        }
        let q: Vec<f64> = (0..n).map(|i| bounded(&defs[i].1, p[i] - step[i])).collect();
        if obj.value(&q) >= l.j {
            return None;
        }
        p = q;
    }
    None
}

/// Standard errors `ses` (from J's Hessian at p̂) in the noise of the residual at p̂. J
/// divides each sensor's residual sum of squares by its variance at the start, which a
/// start far from p̂ inflates (a dead zone searched from zero: its whole misfit), while
/// cov(p) = 2 H⁻¹ holds for J in units of the noise at p̂. With one sensor, H scales with
/// 1/σ², so each standard error by σ̂/σ₀; with two, the Hessian is taken again with σ̂².
fn in_noise_at(
    mut obj: Objective<'_, '_>,
    defs: &Defs,
    p_hat: &[f64],
    ses: Vec<Option<f64>>,
    fits: [&SensorFit; 2],
) -> Vec<Option<f64>> {
    let at_p_hat: Vec<(SensorKind, f64)> =
        obj.sensors.iter().map(|&(s, _)| (s, residual_variance(fits[usize::from(s == SensorKind::Accel)]))).collect();
    if let ([(_, before)], [(_, after)]) = (obj.sensors.as_slice(), at_p_hat.as_slice()) {
        let ratio = (after / before).sqrt();
        return ses.into_iter().map(|se| se.map(|v| v * ratio)).collect();
    }
    obj.sensors = at_p_hat;
    hessian_std_errors(&obj, defs, p_hat)
}

/// A sensor fit's residual variance per channel, averaged over its three channels (J's
/// unit for that sensor).
fn residual_variance(f: &SensorFit) -> f64 {
    (f.channels.iter().map(|c| c.sigma * c.sigma).sum::<f64>() / 3.0).max(f64::MIN_POSITIVE)
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
    let near: Vec<Option<f64>> = model
        .nonlinear()
        .iter()
        .filter(|e| e.fitted)
        .flat_map(|e| (0..e.values.len()).map(|i| e.near.as_ref().and_then(|s| s.get(i).copied())))
        // A step that is no step (zero, negative, not finite) is no near start.
        .map(|s| s.filter(|v| *v > 0.0 && v.is_finite()))
        .collect();
    let affected: Vec<SensorKind> = SensorKind::BOTH
        .into_iter()
        .filter(|s| model.nonlinear().iter().any(|e| e.effect.sensor().is_none_or(|x| x == *s)))
        .collect();
    let mut p_hat = p0.clone();
    let mut ses: Vec<Option<f64>> = vec![None; defs.len()];
    let mut searched = None;
    if !defs.is_empty() {
        let mut sensors = Vec::new();
        for &s in &affected {
            let f = sensor_fit_at(model, &start, s, runs, opts)?;
            sensors.push((s, residual_variance(&f)));
        }
        let inner = FitOptions { screening: true, slow_noise: false, ..*opts };
        let obj = Objective { model, runs, opts: inner, sensors };
        let p0 = coarse_start(&obj, &defs, &near, p0);
        let settled = if near.iter().all(Option::is_some) { newton(&obj, &defs, p0.clone()) } else { None };
        searched = match settled {
            Some((best, se)) => {
                p_hat = best;
                ses = se;
                Some(obj)
            }
            None => {
                let (best, obj) = simplex(obj, &defs, &near, p0, opts.screening)?;
                p_hat = best;
                if let Some(obj) = obj.as_ref().filter(|_| !opts.screening) {
                    ses = hessian_std_errors(obj, &defs, &p_hat);
                }
                obj
            }
        };
    }
    let values = expand(model, &p_hat);
    let gyro = sensor_fit_at(model, &values, SensorKind::Gyro, runs, opts)?;
    let accel = sensor_fit_at(model, &values, SensorKind::Accel, runs, opts)?;
    ses = match searched.filter(|_| !opts.screening) {
        Some(obj) => in_noise_at(obj, &defs, &p_hat, ses, [&gyro, &accel]),
        None => vec![None; defs.len()],
    };
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
