//! The robust linear fit: iteratively reweighted least squares with Huber weights, so that
//! spikes and outliers lose weight.

use super::channel::{reduce, solve_reduced, Columns};
use super::{ChannelFit, CoefStatus, FitOptions, FitRun};
use crate::stats::QrAccumulator;
use crate::units::SensorKind;

/// Huber tuning constant (95 % efficiency under Gaussian noise).
const HUBER_K: f64 = 1.345;

/// Iteratively reweighted least squares with Huber weights `w = min(1, k·s/|r|)`, the
/// scale s = 1.4826·median|r| ([`crate::stats::MAD_TO_SIGMA`]) re-estimated each pass. Starts from the ordinary fit, keeps
/// its identifiability decisions, stops when no coefficient moves by more than 1e-10 of
/// its standard error (at most 30 passes). Standard errors are those of the final weighted
/// problem.
#[allow(clippy::too_many_arguments)]
pub(crate) fn robust_refit(
    terms: &[crate::model::TermRef<'_>],
    cols: &Columns,
    runs: &[FitRun<'_>],
    sensor: SensorKind,
    opts: &FitOptions,
    fitted_sets: &[Vec<usize>],
    status: &[CoefStatus],
    values: &mut [f64],
    std_errors: &mut [Option<f64>],
    channels: &mut [ChannelFit],
) {
    let p = cols.len();
    let n: usize = runs.iter().map(|r| r.len()).sum();
    let mut resid: Vec<[f64; 3]> = Vec::with_capacity(n);
    let mut abs_r: Vec<f64> = Vec::with_capacity(n);
    let mut row = vec![0.0; p + 3];
    let mut weighted = vec![0.0; p + 3];
    for _pass in 0..30 {
        resid.clear();
        for run in runs {
            for k in 0..run.len() {
                let u = crate::model::forward(terms, values, &run.state(k));
                let y = run.output(sensor, k);
                resid.push([y[0] - u[0], y[1] - u[1], y[2] - u[2]]);
            }
        }
        let mut scale = [0.0; 3];
        for ch in 0..3 {
            abs_r.clear();
            abs_r.extend(resid.iter().map(|r| r[ch].abs()));
            scale[ch] = crate::stats::MAD_TO_SIGMA * crate::stats::median(&mut abs_r).unwrap_or(0.0);
        }
        let mut accs: Vec<QrAccumulator> = (0..3).map(|_| QrAccumulator::new(p + 3, opts.chunk)).collect();
        let mut down = [0u64; 3];
        let mut idx = 0;
        for run in runs {
            for k in 0..run.len() {
                cols.fill_row(terms, run, sensor, k, &mut row);
                for ch in 0..3 {
                    let r = resid[idx][ch].abs();
                    let cut = HUBER_K * scale[ch];
                    let w = if r > cut && r > 0.0 { cut / r } else { 1.0 };
                    if w < 1.0 {
                        down[ch] += 1;
                    }
                    let sw = w.sqrt();
                    for (o, v) in weighted.iter_mut().zip(&row) {
                        *o = v * sw;
                    }
                    accs[ch].push(&weighted);
                }
                idx += 1;
            }
        }
        let mut moved = 0.0_f64;
        for ch in 0..3 {
            let fitted = &fitted_sets[ch];
            let q = fitted.len();
            let r = accs[ch].r();
            let plan = super::channel::channel_plan(terms, cols, values, status, fitted, ch);
            let rs = reduce(&r, &plan, p, ch);
            let known = opts.known_sigma.map(|k| k[3 * sensor.index() + ch]);
            let (theta, cov, rss, sigma2) = solve_reduced(&rs, q, n as u64, known);
            for (a, &ti) in fitted.iter().enumerate() {
                let se = cov[a][a].sqrt();
                if se > 0.0 {
                    moved = moved.max((theta[a] - values[ti]).abs() / se);
                }
                values[ti] = theta[a];
                std_errors[ti] = Some(se);
            }
            let c = &mut channels[ch];
            c.residual_rms = (rss / n.max(1) as f64).sqrt();
            c.sigma = sigma2.sqrt();
            c.covariance = cov;
            c.downweighted = down[ch];
        }
        if moved < 1e-10 {
            break;
        }
    }
}
