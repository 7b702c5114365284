//! The linear estimator: each output channel of each sensor is its own problem
//! `y = Φ θ + noise` over all runs. Samples arrive in blocks from any [`Samples`] source
//! (in-memory runs or streamed files); the design is accumulated into an R factor
//! ([`QrAccumulator`]) in one pass per source, each channel is solved from R (so the
//! condition number is never squared), and a second pass gives the residual statistics.

use super::channel::{channel_plan, plan_norm, prediction, reduce, solve_reduced, ChannelPlan, Columns};
pub(crate) use super::channel::{BlockFn, Samples, BLOCK};
use super::robust::robust_refit;
use super::{identify, ChannelFit, CoefStatus, Coefficient, Correlation, EstimateError, Fit, FitOptions};
use super::{FitRun, SensorFit, Unidentifiable};
use crate::model::{Model, State, TermStatus};
use crate::stats::{newey_west_lags, AutoCov, LongRunVariance, QrAccumulator};
use crate::units::{SensorKind, AXES};
use faer::Mat;
use nalgebra::DMatrix;

/// Fits both sensors of a linear model to any [`Samples`] (streamed files or in-memory
/// runs) in one pass per source plus one residual pass; `robust_runs` serve the robust
/// refit, which needs the samples in memory.
pub(crate) fn fit_samples(
    model: &Model,
    sources: &[&dyn Samples],
    robust_runs: &[FitRun<'_>],
    opts: &FitOptions,
) -> Result<Fit, SamplesError> {
    if opts.robust && robust_runs.is_empty() {
        return Err(EstimateError::Request("the robust fit needs the samples in memory".into()).into());
    }
    let mut v = fit_core(model, &SensorKind::BOTH, sources, robust_runs, opts)?;
    let accel = v.pop().ok_or(EstimateError::NoData)?;
    let gyro = v.pop().ok_or(EstimateError::NoData)?;
    Ok(Fit { gyro, accel, nonlinear: Vec::new(), stand: Vec::new(), stand_base: None })
}

/// Failure of a fit over [`Samples`]: reading a streamed file, or the estimate itself.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub(crate) enum SamplesError {
    /// A streamed recording could not be read.
    #[error(transparent)]
    Read(#[from] crate::session::SessionError),
    /// The estimate failed.
    #[error(transparent)]
    Estimate(#[from] EstimateError),
}

impl SamplesError {
    /// The estimate's error of a fit over in-memory runs (which cannot fail to read).
    pub(crate) fn in_memory(self) -> EstimateError {
        match self {
            Self::Estimate(e) => e,
            Self::Read(source) => EstimateError::Read { path: std::path::PathBuf::new(), source },
        }
    }
}

/// One sensor's regressors.
struct SensorDesign<'m> {
    sensor: SensorKind,
    terms: Vec<crate::model::TermRef<'m>>,
    cols: Columns,
}

/// A sensor's solution before the residual pass.
struct Solved {
    values: Vec<f64>,
    std_errors: Vec<Option<f64>>,
    status: Vec<CoefStatus>,
    channels: Vec<ChannelFit>,
    unidentifiable: Vec<Unidentifiable>,
    correlated: Vec<Correlation>,
    fitted_sets: Vec<Vec<usize>>,
}

/// Pass 1 over one source: the R factor of each sensor's design and the sample count.
fn accumulate(
    designs: &[SensorDesign<'_>],
    src: &dyn Samples,
    chunk: usize,
) -> Result<(Vec<QrAccumulator>, usize), SamplesError> {
    let mut accs: Vec<QrAccumulator> = designs.iter().map(|d| QrAccumulator::new(d.cols.len() + 3, chunk)).collect();
    let mut cols: Vec<Vec<f64>> = designs.iter().map(|d| vec![0.0; (d.cols.len() + 3) * BLOCK]).collect();
    let mut n = 0usize;
    let mut bad: Option<(&'static str, State)> = None;
    src.for_each_block(&mut |states, g, a| {
        for ((d, acc), cols) in designs.iter().zip(accs.iter_mut()).zip(cols.iter_mut()) {
            let u = match d.sensor {
                SensorKind::Gyro => g,
                SensorKind::Accel => a,
            };
            d.cols.fill_block(&d.terms, states, u, cols);
            if bad.is_none() {
                bad = d.cols.non_finite_user_column(&d.terms, states, cols);
            }
            acc.push_columns(cols, BLOCK, states.len());
        }
        n += states.len();
    })?;
    if let Some((id, s)) = bad {
        return Err(EstimateError::UserEffect(crate::model::user::UserEffectError::NonFinite {
            id: id.to_string(),
            run: src.run_name().to_string(),
            t_s: s.t_session_s,
            state: format!("w = {:.4?} rad/s, a = {:.4?} m/s^2, T = {} C", s.w, s.a, s.temp_c),
        })
        .into());
    }
    Ok((accs, n))
}

/// Residual statistics of one source for every sensor channel: autocovariance sums and the
/// largest |residual|.
fn residual_pass(
    designs: &[SensorDesign<'_>],
    solved: &[Solved],
    src: &dyn Samples,
    n: usize,
) -> Result<(Vec<AutoCov>, Vec<f64>), crate::session::SessionError> {
    let lags = newey_west_lags(n);
    let mut acov: Vec<AutoCov> = (0..3 * designs.len()).map(|_| AutoCov::new(lags + 1)).collect();
    let mut max = vec![0.0_f64; 3 * designs.len()];
    let mut pred = vec![0.0; 3 * BLOCK];
    let mut resid = vec![0.0; BLOCK];
    // Per sensor: the design's columns once per block, then the fitted coefficients
    // (channel, column, value) in term order.
    let mut blocks: Vec<Vec<f64>> = designs.iter().map(|d| vec![0.0; (d.cols.len() + 3) * BLOCK]).collect();
    let coefs: Vec<Vec<(usize, usize, f64)>> =
        designs.iter().zip(solved).map(|(d, sol)| prediction(&d.terms, &d.cols, &sol.values)).collect();
    src.for_each_block(&mut |states, g, a| {
        let n = states.len();
        for (di, ((d, cols), coefs)) in designs.iter().zip(blocks.iter_mut()).zip(&coefs).enumerate() {
            let u = match d.sensor {
                SensorKind::Gyro => g,
                SensorKind::Accel => a,
            };
            d.cols.fill_block(&d.terms, states, u, cols);
            // Per sample the same sum as term by term over a row: Σ v·x in term order.
            pred.fill(0.0);
            for &(ch, c, v) in coefs {
                for (p, x) in pred[ch * BLOCK..ch * BLOCK + n].iter_mut().zip(&cols[c * BLOCK..c * BLOCK + n]) {
                    *p += v * x;
                }
            }
            for ch in 0..3 {
                let r = &mut resid[..n];
                for ((r, p), u) in r.iter_mut().zip(&pred[ch * BLOCK..ch * BLOCK + n]).zip(u) {
                    *r = u[ch] - p;
                }
                let m = &mut max[3 * di + ch];
                for r in r.iter() {
                    *m = m.max(r.abs());
                }
                acov[3 * di + ch].extend(r);
            }
        }
    })?;
    for a in &mut acov {
        a.close();
    }
    Ok((acov, max))
}

/// The linear fit of `sensors` over `sources` (pass 1 per source in parallel, R factors
/// merged in source order; solve; robust refit when asked, from `robust_runs`; pass 2 per
/// source in parallel for the residual statistics).
fn fit_core(
    model: &Model,
    sensors: &[SensorKind],
    sources: &[&dyn Samples],
    robust_runs: &[FitRun<'_>],
    opts: &FitOptions,
) -> Result<Vec<SensorFit>, SamplesError> {
    use rayon::prelude::*;
    let designs: Vec<SensorDesign<'_>> = sensors
        .iter()
        .map(|&sensor| {
            let terms = model.terms(sensor);
            let cols = Columns::new(&terms);
            SensorDesign { sensor, terms, cols }
        })
        .collect();
    // Sources in groups of a few per thread: each group's accumulators (a chunk of rows
    // each, hundreds of kB) are merged, in source order, before the next group is read, so
    // memory follows the threads, not the number of runs (10 000 short runs used to hold
    // 10 000 accumulators at once).
    let group = rayon::current_num_threads().max(1) * 4;
    let mut counts: Vec<usize> = Vec::with_capacity(sources.len());
    let mut merged: Vec<QrAccumulator> =
        designs.iter().map(|d| QrAccumulator::new(d.cols.len() + 3, opts.chunk)).collect();
    for batch in sources.chunks(group) {
        let parts: Vec<(Vec<QrAccumulator>, usize)> =
            batch.par_iter().map(|src| accumulate(&designs, *src, opts.chunk)).collect::<Result<_, _>>()?;
        for (mut accs, n) in parts {
            counts.push(n);
            for (m, a) in merged.iter_mut().zip(accs.iter_mut()) {
                m.merge(a);
            }
        }
    }
    let mut solved = Vec::with_capacity(designs.len());
    for (d, acc) in designs.iter().zip(merged.iter_mut()) {
        let mut sol = solve(&d.terms, &d.cols, d.sensor, acc, opts)?;
        if opts.robust {
            robust_refit(
                &d.terms,
                &d.cols,
                robust_runs,
                d.sensor,
                opts,
                &sol.fitted_sets,
                &sol.status,
                &mut sol.values,
                &mut sol.std_errors,
                &mut sol.channels,
            );
        }
        solved.push(sol);
    }

    // Second pass: largest residual and residual autocovariances per channel (skipped
    // when only screening candidates by their residual).
    if !opts.screening {
        let stats: Vec<(Vec<AutoCov>, Vec<f64>)> = sources
            .par_iter()
            .zip(counts.par_iter())
            .map(|(src, &n)| residual_pass(&designs, &solved, *src, n))
            .collect::<Result<_, _>>()?;
        for (di, sol) in solved.iter_mut().enumerate() {
            let mut lrv = [LongRunVariance::default(), LongRunVariance::default(), LongRunVariance::default()];
            for ((acov, max), &n) in stats.iter().zip(&counts) {
                let lags = newey_west_lags(n);
                for ch in 0..3 {
                    lrv[ch].add(&acov[3 * di + ch], lags);
                    if max[3 * di + ch] > sol.channels[ch].residual_max {
                        sol.channels[ch].residual_max = max[3 * di + ch];
                    }
                }
            }
            for ch in 0..3 {
                let c = &mut sol.channels[ch];
                c.residual_lag1 = lrv[ch].lag1();
                // With a known σ the covariance is already the Cramér–Rao bound σ²(ΦᵀΦ)⁻¹.
                if opts.known_sigma.is_none() {
                    let f = lrv[ch].inflation();
                    c.coloured_inflation = f;
                    rescale(c, &sol.fitted_sets[ch], &mut sol.std_errors, f);
                }
            }
        }
    }
    if opts.slow_noise && !opts.screening && opts.known_sigma.is_none() {
        slow_noise(&designs, &mut solved, sources, counts.iter().sum(), opts.slow_noise_held.as_ref())?;
    }
    Ok(designs.iter().zip(solved).map(|(d, sol)| finish(&d.terms, d.sensor, sol)).collect())
}

/// Adds the slow noise (flicker, bias random walk) to each channel's covariance
/// ([`super::slow`]): one more pass per source for block sums.
fn slow_noise(
    designs: &[SensorDesign<'_>],
    solved: &mut [Solved],
    sources: &[&dyn Samples],
    total: usize,
    held: Option<&[Option<super::slow::SlowNoise>; 6]>,
) -> Result<(), crate::session::SessionError> {
    use rayon::prelude::*;
    let plans: Vec<Vec<super::slow::ChannelDesign>> = designs
        .iter()
        .zip(solved.iter())
        .map(|(d, s)| super::slow::designs(&d.terms, &d.cols, &s.values, &s.status, &s.fitted_sets))
        .collect();
    let width: Vec<usize> = designs.iter().map(|d| d.cols.len()).collect();
    // Blocks of several integral times of the short-lag colour, where it looks white.
    let integral = solved.iter().flat_map(|s| s.channels.iter()).map(|c| c.coloured_inflation).fold(1.0, f64::max);
    let per_block = super::slow::block_samples(total).max((5.0 * integral).ceil() as usize);
    let fill = |s: usize, states: &[State], g: &[[f64; 3]], a: &[[f64; 3]], cols: &mut [f64]| {
        let u = match designs[s].sensor {
            SensorKind::Gyro => g,
            SensorKind::Accel => a,
        };
        designs[s].cols.fill_block(&designs[s].terms, states, u, cols);
    };
    let blocks: Vec<super::slow::SourceBlocks> = sources
        .par_iter()
        .map(|src| super::slow::pass(*src, &plans, &width, per_block, &fill))
        .collect::<Result<_, _>>()?;
    // Each channel's likelihood climb is its own: the channels in parallel.
    let mut channels: Vec<(usize, &mut ChannelFit)> = solved
        .iter_mut()
        .enumerate()
        .flat_map(|(di, sol)| sol.channels.iter_mut().enumerate().map(move |(ch, c)| (3 * di + ch, c)))
        .collect();
    // A held model is per channel of the whole unit: gyro x..z, then accel x..z.
    let kept = |i: usize| held.map(|h| h[3 * usize::from(designs[i / 3].sensor == SensorKind::Accel) + i % 3]);
    channels.par_iter_mut().for_each(|(i, c)| c.slow_noise = super::slow::inflate(&blocks, *i, c, kept(*i)));
    for sol in solved.iter_mut() {
        for ch in 0..3 {
            rescale(&mut sol.channels[ch], &sol.fitted_sets[ch], &mut sol.std_errors, 1.0);
        }
    }
    Ok(())
}

/// Fits one sensor of a model to in-memory runs.
pub(crate) fn fit_sensor(
    model: &Model,
    sensor: SensorKind,
    runs: &[FitRun<'_>],
    opts: &FitOptions,
) -> Result<SensorFit, EstimateError> {
    let sources: Vec<&dyn Samples> = runs.iter().map(|r| r as &dyn Samples).collect();
    fit_core(model, &[sensor], &sources, runs, opts).map(|mut v| v.remove(0)).map_err(SamplesError::in_memory)
}

/// The identifiability check of one channel: the column-scaled reduced problem is
/// decomposed, and while a singular value falls below `rcond · s_max` the coefficient most
/// likely to be the culprit of the lost combination is held at its nominal value.
struct Identify<'a, 't> {
    terms: &'a [crate::model::TermRef<'t>],
    status: &'a mut Vec<CoefStatus>,
    values: &'a mut Vec<f64>,
    lost: &'a mut Vec<Unidentifiable>,
}

impl Identify<'_, '_> {
    /// The plan, reduced problem and condition number once every kept combination is
    /// identifiable.
    #[allow(clippy::too_many_arguments)]
    fn channel(
        &mut self,
        r: &Mat<f64>,
        norms: &[f64],
        cols: &Columns,
        fitted: &mut Vec<usize>,
        ch: usize,
        p: usize,
        opts: &FitOptions,
        sensor: SensorKind,
    ) -> Result<(ChannelPlan, Mat<f64>, f64), EstimateError> {
        loop {
            let q = fitted.len();
            let plan = channel_plan(self.terms, cols, self.values, self.status, fitted, ch);
            let rs = reduce(r, &plan, p, ch);
            if q == 0 {
                return Ok((plan, rs, 1.0));
            }
            let scale: Vec<f64> = plan.columns.iter().map(|c| plan_norm(r, norms, c)).collect();
            let scaled = DMatrix::from_fn(q, q, |i, j| rs[(i, j)] / scale[j]);
            let svd =
                crate::stats::svd(scaled, false, true).ok_or(EstimateError::NonFinite { sensor, axis: AXES[ch] })?;
            let (mut smin, mut smax, mut imin) = (f64::INFINITY, 0.0_f64, 0);
            for (i, &s) in svd.singular_values.iter().enumerate() {
                if s < smin {
                    smin = s;
                    imin = i;
                }
                smax = smax.max(s);
            }
            if smin > opts.rcond * smax {
                return Ok((plan, rs, smax / smin));
            }
            let Some(vt) = svd.v_t.as_ref() else {
                return Ok((plan, rs, f64::INFINITY));
            };
            let combo: Vec<f64> = (0..q).map(|j| vt[(imin, j)]).collect();
            let (report, drop_at) = identify::lost_combination(self.terms, fitted, &combo, ch);
            let ti = fitted.remove(drop_at);
            self.status[ti] = CoefStatus::Unidentifiable;
            self.values[ti] = self.terms[ti].term.nominal;
            self.lost.push(report);
        }
    }
}

/// Solves one sensor from its accumulated R factor: identifiability, coefficients,
/// covariance (white-noise), per-channel residual RMS.
fn solve(
    terms: &[crate::model::TermRef<'_>],
    cols: &Columns,
    sensor: SensorKind,
    acc: &mut QrAccumulator,
    opts: &FitOptions,
) -> Result<Solved, EstimateError> {
    let p = cols.len();
    let n = acc.rows();
    let r = acc.r();
    let norms = acc.column_norms();
    let max_norm = norms[..p].iter().copied().fold(0.0, f64::max);

    let mut values: Vec<f64> = terms
        .iter()
        .map(|t| match t.status {
            TermStatus::Fixed(v) => v,
            TermStatus::Fitted => t.term.nominal,
        })
        .collect();
    let mut std_errors: Vec<Option<f64>> = vec![None; terms.len()];
    let mut status: Vec<CoefStatus> = terms
        .iter()
        .map(|t| match t.status {
            TermStatus::Fixed(_) => CoefStatus::Fixed,
            TermStatus::Fitted => CoefStatus::Fitted,
        })
        .collect();
    let mut channels = Vec::with_capacity(3);
    let mut unidentifiable = Vec::new();
    let mut correlated = Vec::new();
    let mut fitted_sets: Vec<Vec<usize>> = Vec::with_capacity(3);

    for ch in 0..3 {
        let mut fitted: Vec<usize> =
            (0..terms.len()).filter(|&ti| terms[ti].term.channel == ch && status[ti] == CoefStatus::Fitted).collect();
        // Columns nobody excites cannot be fitted at all.
        let first = channel_plan(terms, cols, &values, &status, &fitted, ch);
        let mut keep = Vec::with_capacity(fitted.len());
        for (&ti, col) in fitted.iter().zip(&first.columns) {
            if plan_norm(&r, &norms, col) <= 1e-12 * max_norm.max(f64::MIN_POSITIVE) {
                unidentifiable.push(identify::zero_column(&terms[ti], ch));
                status[ti] = CoefStatus::Unidentifiable;
            } else {
                keep.push(ti);
            }
        }
        fitted = keep;
        let mut unid = Identify { terms, status: &mut status, values: &mut values, lost: &mut unidentifiable };
        let (mut plan, mut rs, cond) = unid.channel(&r, &norms, cols, &mut fitted, ch, p, opts, sensor)?;
        let q = fitted.len();
        if n <= q as u64 {
            return Err(EstimateError::TooFewSamples { sensor, axis: AXES[ch], n, q });
        }
        let known = opts.known_sigma.map(|k| k[3 * sensor.index() + ch]);
        let (mut theta, mut cov, mut rss, mut sigma2) = solve_reduced(&rs, q, n, known);
        // Input-side coefficients: Gauss–Newton on the bilinear model from R (module
        // `channel`), until the estimates stop moving.
        for _ in 0..50 {
            if !plan.bilinear {
                break;
            }
            let before: Vec<f64> = fitted.iter().map(|&ti| values[ti]).collect();
            for (a, &ti) in fitted.iter().enumerate() {
                values[ti] = theta[a];
            }
            plan = channel_plan(terms, cols, &values, &status, &fitted, ch);
            rs = reduce(&r, &plan, p, ch);
            (theta, cov, rss, sigma2) = solve_reduced(&rs, q, n, known);
            let moved = theta
                .iter()
                .zip(&before)
                .zip(&cov)
                .map(|((t, b), c)| (t - b).abs() / (t.abs() + c[0].abs().sqrt() + f64::MIN_POSITIVE))
                .fold(0.0, f64::max);
            if moved < 1e-13 {
                break;
            }
        }
        // Outputs too large for the arithmetic (squares overflow) leave no usable estimate:
        // refused, not written into a profile.
        if !(rss.is_finite() && theta.iter().all(|v| v.is_finite())) {
            return Err(EstimateError::NonFinite { sensor, axis: AXES[ch] });
        }
        for (a, &ti) in fitted.iter().enumerate() {
            values[ti] = theta[a];
            std_errors[ti] = Some(cov[a][a].sqrt());
        }
        correlated.extend(correlations(terms, &fitted, &cov));
        fitted_sets.push(fitted.clone());
        channels.push(ChannelFit {
            axis: AXES[ch],
            n,
            n_params: q,
            residual_rms: (rss / n as f64).sqrt(),
            residual_max: 0.0,
            sigma: sigma2.sqrt(),
            condition_number: cond,
            covariance_names: fitted.iter().map(|&ti| terms[ti].term.name.clone()).collect(),
            covariance: cov,
            downweighted: 0,
            coloured_inflation: 1.0,
            slow_noise: None,
            residual_lag1: 0.0,
        });
    }

    Ok(Solved { values, std_errors, status, channels, unidentifiable, correlated, fitted_sets })
}

/// Pairs of fitted coefficients whose estimates correlate above 0.95.
fn correlations(terms: &[crate::model::TermRef<'_>], fitted: &[usize], cov: &[Vec<f64>]) -> Vec<Correlation> {
    let mut out = Vec::new();
    for a in 0..fitted.len() {
        for b in a + 1..fitted.len() {
            let c = cov[a][b] / (cov[a][a] * cov[b][b]).sqrt();
            if c.abs() > 0.95 {
                out.push(Correlation {
                    a: terms[fitted[a]].term.name.clone(),
                    b: terms[fitted[b]].term.name.clone(),
                    correlation: c,
                });
            }
        }
    }
    out
}

/// The sensor fit from its solution.
fn finish(terms: &[crate::model::TermRef<'_>], sensor: SensorKind, sol: Solved) -> SensorFit {
    let Solved { values, std_errors, status, channels, unidentifiable, correlated, .. } = sol;
    let coefficients = terms
        .iter()
        .enumerate()
        .map(|(ti, t)| Coefficient {
            name: t.term.name.clone(),
            effect: t.effect.id().to_string(),
            channel: t.term.channel,
            unit: t.term.unit.to_string(),
            value: values[ti],
            std_error: std_errors[ti],
            status: status[ti],
        })
        .collect();
    SensorFit { sensor, coefficients, channels, unidentifiable, correlated }
}

/// Multiplies a channel's covariance by `scale` and updates its standard errors.
fn rescale(c: &mut ChannelFit, fitted: &[usize], std_errors: &mut [Option<f64>], scale: f64) {
    for row in &mut c.covariance {
        for v in row.iter_mut() {
            *v *= scale;
        }
    }
    for (a, &ti) in fitted.iter().enumerate() {
        std_errors[ti] = Some(c.covariance[a][a].max(0.0).sqrt());
    }
}
