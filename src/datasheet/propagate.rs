//! A datasheet quantity as a function of fitted coefficients, with its standard uncertainty
//! propagated from the fit's covariance (GUM, JCGM 100 eq. 13: u² = ∇fᵀ Σ ∇f, the gradient
//! by central differences with steps of 1 % of each coefficient's standard error, so a
//! nonlinear f is linearised where the fit is uncertain). Coefficients of different output
//! channels are independent (each channel is its own least-squares problem); within a
//! channel the covariance is the fit's.

use crate::estimate::{CoefStatus, SensorFit};

/// Value and standard uncertainty of `f` at the fitted values of `names` of `fit`; Err
/// says which coefficient is missing or not fitted.
pub fn propagate(fit: &SensorFit, names: &[String], f: &dyn Fn(&[f64]) -> f64) -> Result<(f64, f64), String> {
    let mut x = Vec::with_capacity(names.len());
    let mut se = Vec::with_capacity(names.len());
    for n in names {
        let c = fit.get(n).ok_or_else(|| format!("{n} is not in the profile's model"))?;
        if c.status != CoefStatus::Fitted {
            return Err(format!("{n} was not fitted ({:?})", c.status).to_lowercase());
        }
        x.push(c.value);
        se.push(c.std_error.unwrap_or(0.0));
    }
    let value = f(&x);
    let mut grad = vec![0.0; x.len()];
    let mut y = x.clone();
    for j in 0..x.len() {
        let h = se[j] * 1e-2;
        if h <= 0.0 || !h.is_finite() {
            continue;
        }
        y[j] = x[j] + h;
        let up = f(&y);
        y[j] = x[j] - h;
        let down = f(&y);
        y[j] = x[j];
        grad[j] = (up - down) / (2.0 * h);
    }
    let mut var = 0.0;
    for a in 0..x.len() {
        for b in 0..x.len() {
            if grad[a] != 0.0 && grad[b] != 0.0 {
                var += grad[a] * grad[b] * covariance(fit, &names[a], &names[b], se[a], se[b]);
            }
        }
    }
    Ok((value, var.max(0.0).sqrt()))
}

/// Covariance of two fitted coefficients: the channel's covariance when both are in it, the
/// variance from the standard error on the diagonal, 0 across channels.
fn covariance(fit: &SensorFit, a: &str, b: &str, se_a: f64, se_b: f64) -> f64 {
    for ch in &fit.channels {
        let ia = ch.covariance_names.iter().position(|n| n == a);
        let ib = ch.covariance_names.iter().position(|n| n == b);
        if let (Some(i), Some(j)) = (ia, ib) {
            if let Some(v) = ch.covariance.get(i).and_then(|r| r.get(j)) {
                return *v;
            }
        }
    }
    if a == b {
        se_a * se_b
    } else {
        0.0
    }
}
