//! Levenberg–Marquardt for small nonlinear least-squares problems (the multi-position
//! protocol's accelerometer and gyro fits), written as an argmin [`Solver`] so that it runs
//! in argmin's executor with its termination rules and observers.
//!
//! Minimises `F(p) = ½ Σ r_i(p)²`. Each iteration solves Marquardt's damped normal equations
//! `(JᵀJ + λ diag(JᵀJ)) δ = −Jᵀr` (Marquardt 1963, eq. 30; the diagonal scaling makes the
//! step invariant to the parameters' units), accepts the step when the cost falls (λ ← λ/3)
//! and otherwise raises λ (× 4) and tries again.

use argmin::core::{
    CostFunction, Error, Executor, IterState, Jacobian, Operator, Problem, Solver, State, TerminationReason,
    TerminationStatus, KV,
};
use nalgebra::{DMatrix, DVector};

/// The argmin state used by [`LevenbergMarquardt`].
pub type LmState = IterState<Vec<f64>, (), Vec<Vec<f64>>, (), Vec<f64>, f64>;

/// Levenberg–Marquardt solver (see the module documentation).
#[derive(Debug, Clone)]
pub struct LevenbergMarquardt {
    lambda: f64,
    /// Stop when the relative fall of the cost in an accepted step is below this.
    pub ftol: f64,
    converged: bool,
}

impl Default for LevenbergMarquardt {
    fn default() -> Self {
        Self { lambda: 1e-3, ftol: 1e-14, converged: false }
    }
}

fn half_sum_sq(r: &[f64]) -> f64 {
    0.5 * r.iter().map(|x| x * x).sum::<f64>()
}

impl<O> Solver<O, LmState> for LevenbergMarquardt
where
    O: Operator<Param = Vec<f64>, Output = Vec<f64>> + Jacobian<Param = Vec<f64>, Jacobian = Vec<Vec<f64>>>,
{
    fn name(&self) -> &str {
        "Levenberg-Marquardt"
    }

    fn init(&mut self, problem: &mut Problem<O>, state: LmState) -> Result<(LmState, Option<KV>), Error> {
        let p = state.get_param().cloned().ok_or_else(|| Error::msg("no initial parameters"))?;
        let r = problem.apply(&p)?;
        let c = half_sum_sq(&r);
        Ok((state.cost(c).residuals(r), None))
    }

    fn next_iter(&mut self, problem: &mut Problem<O>, state: LmState) -> Result<(LmState, Option<KV>), Error> {
        let p = state.get_param().cloned().ok_or_else(|| Error::msg("no parameters"))?;
        let r0 = match state.get_residuals() {
            Some(r) => r.clone(),
            None => problem.apply(&p)?,
        };
        let c0 = half_sum_sq(&r0);
        let jac = problem.jacobian(&p)?;
        let (m, n) = (r0.len(), p.len());
        let j = DMatrix::from_fn(m, n, |i, k| jac[i][k]);
        let jtj = j.transpose() * &j;
        let g = j.transpose() * DVector::from_vec(r0.clone());
        for _ in 0..30 {
            let mut a = jtj.clone();
            for k in 0..n {
                a[(k, k)] += self.lambda * jtj[(k, k)].max(f64::MIN_POSITIVE);
            }
            let Some(delta) = a.cholesky().map(|ch| ch.solve(&(-&g))) else {
                self.lambda *= 4.0;
                continue;
            };
            let trial: Vec<f64> = p.iter().zip(delta.iter()).map(|(a, d)| a + d).collect();
            let r1 = problem.apply(&trial)?;
            let c1 = half_sum_sq(&r1);
            if c1.is_finite() && c1 <= c0 {
                self.lambda = (self.lambda / 3.0).max(1e-12);
                if c0 - c1 <= self.ftol * c0.max(f64::MIN_POSITIVE) {
                    self.converged = true;
                }
                return Ok((state.param(trial).cost(c1).residuals(r1), None));
            }
            self.lambda *= 4.0;
        }
        // No step lowers the cost: p is a minimum to working precision.
        self.converged = true;
        Ok((state.param(p).cost(c0).residuals(r0), None))
    }

    fn terminate(&mut self, _state: &LmState) -> TerminationStatus {
        if self.converged {
            TerminationStatus::Terminated(TerminationReason::SolverConverged)
        } else {
            TerminationStatus::NotTerminated
        }
    }
}

/// A residual function `r(p)` as an argmin problem: [`Operator`] gives the residuals,
/// [`Jacobian`] central differences with steps `1e-6 · max(|p_k|, scale_k)`, [`CostFunction`]
/// `½ Σ r²`.
#[derive(Clone)]
pub struct LeastSquares<F> {
    residuals: F,
    scale: Vec<f64>,
}

impl<F: Fn(&[f64]) -> Vec<f64>> LeastSquares<F> {
    /// The problem of `residuals`, with a typical magnitude per parameter for the steps.
    pub fn new(residuals: F, scale: Vec<f64>) -> Self {
        Self { residuals, scale }
    }
}

impl<F: Fn(&[f64]) -> Vec<f64>> Operator for LeastSquares<F> {
    type Param = Vec<f64>;
    type Output = Vec<f64>;
    fn apply(&self, p: &Vec<f64>) -> Result<Vec<f64>, Error> {
        Ok((self.residuals)(p))
    }
}

impl<F: Fn(&[f64]) -> Vec<f64>> Jacobian for LeastSquares<F> {
    type Param = Vec<f64>;
    type Jacobian = Vec<Vec<f64>>;
    fn jacobian(&self, p: &Vec<f64>) -> Result<Vec<Vec<f64>>, Error> {
        numeric_jacobian(|q| Ok((self.residuals)(q)), p, &self.scale, 1e-6)
    }
}

impl<F: Fn(&[f64]) -> Vec<f64>> CostFunction for LeastSquares<F> {
    type Param = Vec<f64>;
    type Output = f64;
    fn cost(&self, p: &Vec<f64>) -> Result<f64, Error> {
        Ok(half_sum_sq(&(self.residuals)(p)))
    }
}

/// Result of [`minimise`]: the parameters, the residuals there and the Jacobian there.
#[derive(Debug, Clone)]
pub struct LmResult {
    /// Parameters at the minimum.
    pub param: Vec<f64>,
    /// Residuals at the minimum.
    pub residuals: Vec<f64>,
    /// Jacobian of the residuals at the minimum (rows = residuals).
    pub jacobian: Vec<Vec<f64>>,
}

impl LmResult {
    /// `½ Σ r²`.
    pub fn cost(&self) -> f64 {
        half_sum_sq(&self.residuals)
    }

    /// Parameter covariance `σ² (JᵀJ)⁻¹` with `σ² = Σr²/(m − n)` (pseudo-inverse when
    /// singular).
    pub fn covariance(&self) -> DMatrix<f64> {
        let (m, n) = (self.residuals.len(), self.param.len());
        let j = DMatrix::from_fn(m, n, |i, k| self.jacobian[i][k]);
        let jtj = j.transpose() * &j;
        let s2 = 2.0 * self.cost() / (m.saturating_sub(n).max(1)) as f64;
        let inv = jtj.clone().try_inverse().unwrap_or_else(|| {
            crate::stats::svd(jtj, true, true)
                .and_then(|svd| svd.pseudo_inverse(1e-14).ok())
                .unwrap_or(DMatrix::from_element(n, n, f64::NAN))
        });
        inv * s2
    }
}

/// Minimises `½ Σ r(p)²` from `p0` with [`LevenbergMarquardt`] in argmin's executor.
pub fn minimise<O>(op: O, p0: Vec<f64>, max_iters: u64) -> Result<LmResult, Error>
where
    O: Operator<Param = Vec<f64>, Output = Vec<f64>>
        + Jacobian<Param = Vec<f64>, Jacobian = Vec<Vec<f64>>>
        + CostFunction<Param = Vec<f64>, Output = f64>
        + Clone,
{
    let res = Executor::new(op.clone(), LevenbergMarquardt::default())
        .configure(|s| s.param(p0).max_iters(max_iters))
        .run()?;
    let state = res.state();
    let param = state.get_best_param().or(state.get_param()).cloned().ok_or_else(|| Error::msg("no result"))?;
    let residuals = op.apply(&param)?;
    let jacobian = op.jacobian(&param)?;
    Ok(LmResult { param, residuals, jacobian })
}

/// Central-difference Jacobian of `f` at `p`, with steps `h_k = rel · max(|p_k|, scale_k)`.
pub fn numeric_jacobian<F>(f: F, p: &[f64], scale: &[f64], rel: f64) -> Result<Vec<Vec<f64>>, Error>
where
    F: Fn(&[f64]) -> Result<Vec<f64>, Error>,
{
    let mut cols: Vec<Vec<f64>> = Vec::with_capacity(p.len());
    let mut q = p.to_vec();
    for k in 0..p.len() {
        let h = rel * p[k].abs().max(scale[k]);
        q[k] = p[k] + h;
        let up = f(&q)?;
        q[k] = p[k] - h;
        let down = f(&q)?;
        q[k] = p[k];
        cols.push(up.iter().zip(&down).map(|(a, b)| (a - b) / (2.0 * h)).collect());
    }
    let m = cols.first().map_or(0, Vec::len);
    Ok((0..m).map(|i| cols.iter().map(|c| c[i]).collect()).collect())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn recovers_an_exponential() {
        // y = a·exp(b·x) from exact data: LM must find (a, b) to 1e-9.
        let x: Vec<f64> = (0..30).map(|i| i as f64 * 0.1).collect();
        let y: Vec<f64> = x.iter().map(|x| 2.5 * (-1.3 * x).exp()).collect();
        let f = |p: &[f64]| x.iter().zip(&y).map(|(x, y)| p[0] * (p[1] * x).exp() - y).collect::<Vec<f64>>();
        let r = minimise(LeastSquares::new(f, vec![1.0, 1.0]), vec![1.0, 0.0], 200).unwrap();
        assert!((r.param[0] - 2.5).abs() < 1e-9 && (r.param[1] + 1.3).abs() < 1e-9, "{:?}", r.param);
        assert!(r.cost() < 1e-20);
    }
}
