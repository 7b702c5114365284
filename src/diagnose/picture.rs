//! The residual picture of a fitted model per run and channel, for reports and plots:
//! residuals with the cone phase, and per channel the residual RMS, a white-noise floor
//! from first differences and the systematic part (per run: constant + cone harmonics).
//! The diagnosis itself works on whitened Grams ([`super::space`]); this is what a
//! reader's eye sees.

use crate::estimate::{Fit, FitRun};
use crate::model::{Model, State};
use crate::session::MotionSpec;
use crate::stats::{chi2_upper, systematic, Systematic};
use crate::units::{SensorKind, AXES};

use super::{ChannelReport, HARMONICS, RESOLUTION, SIGNIFICANCE_Z};

/// Motion of each run (for the cone phase).
pub type RunMotions<'a> = [&'a MotionSpec];

fn values_of(f: &Fit, model: &Model, sensor: SensorKind) -> Vec<f64> {
    let sf = f.sensor(sensor);
    model.terms(sensor).iter().map(|t| sf.value(&t.term.name).unwrap_or(t.term.nominal)).collect()
}

/// Residuals (output − model, SI) of a fitted model, one run.
#[derive(Debug, Clone, PartialEq)]
pub struct RunResiduals {
    /// Run name.
    pub run: String,
    /// Time stamps, s.
    pub t_s: Vec<f64>,
    /// Cone phase θ (rad) per sample, for conic runs.
    pub theta: Option<Vec<f64>>,
    /// Six channels: gyro x, y, z, accel x, y, z.
    pub r: Vec<Vec<f64>>,
    /// Sum of squared outputs per channel (for the recording's numerical resolution).
    pub output_ss: [f64; 6],
}

/// Residuals of a fitted model on every run (nonlinear effects applied).
pub fn residuals(model: &Model, f: &Fit, runs: &[FitRun<'_>], motions: &RunMotions<'_>) -> Vec<RunResiduals> {
    runs.iter()
        .zip(motions.iter())
        .map(|(run, m)| {
            let (r, output_ss) = run_residual(model, f, run);
            RunResiduals {
                run: run.name.to_string(),
                t_s: run.track.t_s.to_vec(),
                theta: match m {
                    MotionSpec::Conic { cone_angle_deg, rate_deg_s, phase_deg } => {
                        let c = crate::motion::Conic::from_deg(*cone_angle_deg, *rate_deg_s, *phase_deg);
                        Some(run.track.t_s.iter().map(|&t| c.theta(t).rem_euclid(std::f64::consts::TAU)).collect())
                    }
                    _ => None,
                },
                r,
                output_ss,
            }
        })
        .collect()
}

/// The six residual channels of one run (output − model, SI; gyro x, y, z, accel x, y, z)
/// and each channel's sum of squared outputs. A user effect's linear part is evaluated at
/// the parameters `f` estimated (a knee at its fitted rate, not its start value).
pub fn run_residual(model: &Model, f: &Fit, run: &FitRun<'_>) -> (Vec<Vec<f64>>, [f64; 6]) {
    let n = run.len();
    let mut r: Vec<Vec<f64>> = (0..6).map(|_| vec![0.0; n]).collect();
    let mut output_ss = [0.0; 6];
    visit_residual(model, f, run, 1, |k, _, y, e| {
        for c in 0..6 {
            r[c][k] = e[c];
            output_ss[c] += y[c] * y[c];
        }
    });
    (r, output_ss)
}

/// Visits every `stride`-th sample k of a run (0, stride, …) with its state on the run's
/// own motion, its six outputs and their residuals (output − the fitted model on the
/// motion each sensor sees; SI, gyro x, y, z, accel x, y, z): [`run_residual`]'s numbers
/// at those samples, without the model evaluated at the others.
pub fn visit_residual(
    model: &Model,
    f: &Fit,
    run: &FitRun<'_>,
    stride: usize,
    mut visit: impl FnMut(usize, &State, &[f64; 6], &[f64; 6]),
) {
    let bound;
    let model = if model.has_bound_parameters() {
        bound = crate::estimate::bound_at_fit(model, f);
        &bound
    } else {
        model
    };
    let n = run.len();
    let stride = stride.max(1);
    let terms = SensorKind::BOTH.map(|s| model.terms(s));
    let values = SensorKind::BOTH.map(|s| values_of(f, model, s));
    let predict = [0, 1].map(|si| crate::model::Predictor::new(&terms[si], &values[si]));
    let seen = SensorKind::BOTH
        .map(|s| crate::estimate::seen_tracks(model, f, s, std::slice::from_ref(run)).and_then(|mut v| v.pop()));
    let how = [0, 1].map(|si| run.seen_from(seen[si].as_ref()));
    // A block at a time: the run's states once per block, each sensor's seen states from
    // them ([`FitRun::seen_states_at`]), the model by [`Predictor::block`] (the numbers of
    // `Predictor::at`).
    const BLOCK: usize = 256;
    let mut ks: Vec<usize> = Vec::with_capacity(BLOCK);
    let mut base: Vec<State> = Vec::with_capacity(BLOCK);
    let mut states: [Vec<State>; 2] = [Vec::with_capacity(BLOCK), Vec::with_capacity(BLOCK)];
    let mut u = [vec![[0.0; 3]; BLOCK], vec![[0.0; 3]; BLOCK]];
    let mut tmp = vec![0.0; crate::model::Predictor::SCRATCH * BLOCK];
    let mut next = 0;
    while next < n {
        ks.clear();
        ks.extend((next..n).step_by(stride).take(BLOCK));
        next = ks.last().map_or(n, |k| k + stride);
        base.clear();
        run.states_into(ks.iter().copied(), &mut base);
        for si in 0..2 {
            run.seen_states_at(&how[si], &base, &ks, &mut states[si]);
            predict[si].block(&states[si], &mut u[si], &mut tmp);
        }
        for (i, &k) in ks.iter().enumerate() {
            let (g, a) = (run.output(SensorKind::Gyro, k), run.output(SensorKind::Accel, k));
            let y = [g[0], g[1], g[2], a[0], a[1], a[2]];
            let e: [f64; 6] = std::array::from_fn(|c| y[c] - u[c / 3][i][c % 3]);
            visit(k, &base[i], &y, &e);
        }
    }
}

/// Channel reports (residual RMS, noise floor, systematic part) from residuals.
pub fn channel_reports(res: &[RunResiduals], motions: &RunMotions<'_>) -> Vec<ChannelReport> {
    let mut out = Vec::with_capacity(6);
    for c in 0..6 {
        let sensor = if c < 3 { SensorKind::Gyro } else { SensorKind::Accel };
        let mut diffs = Vec::new();
        let (mut ss, mut n, mut sys_ss) = (0.0, 0usize, 0.0);
        let (mut chi, mut dof) = (0.0, 0usize);
        let mut worst: Option<(String, Option<usize>, f64)> = None;
        for (ri, run) in res.iter().enumerate() {
            let r = &run.r[c];
            diffs.extend(r.windows(2).map(|w| (w[1] - w[0]).abs()));
            ss += r.iter().map(|v| v * v).sum::<f64>();
            n += r.len();
            let sys: Systematic = systematic(r, &run.t_s, crate::motion::cone_phase(motions[ri]), HARMONICS);
            sys_ss += sys.curve.iter().map(|v| v * v).sum::<f64>();
            if sys.sigma2 > 0.0 {
                chi += sys.explained / sys.sigma2;
                dof += sys.params;
            }
            let (h, amp) = if sys.amplitudes.is_empty() {
                (None, sys.max_abs())
            } else {
                let (h, a) = sys
                    .amplitudes
                    .iter()
                    .enumerate()
                    .fold((0, 0.0), |acc, (h, &a)| if a > acc.1 { (h, a) } else { acc });
                (Some(h), a)
            };
            if worst.as_ref().is_none_or(|w| amp > w.2) {
                worst = Some((run.run.clone(), h, amp));
            }
        }
        // One pooled test per channel over all runs, at 0.001 % (few false alarms even
        // over many channels and sessions).
        // Residuals below 1e-10 of the output RMS are rounding of the recording and of the
        // arithmetic (no sensor resolves 1e-10 of its signal): never "systematic".
        let out_ss: f64 = res.iter().map(|r| r.output_ss[c]).sum();
        let resolution = RESOLUTION * (out_ss / n.max(1) as f64).sqrt();
        let sys_rms = (sys_ss / n.max(1) as f64).sqrt();
        let significant = dof > 0 && chi > chi2_upper(dof, SIGNIFICANCE_Z) && sys_rms > resolution;
        let mad = crate::stats::median(&mut diffs).unwrap_or(0.0);
        // For white noise, |Δr| has median 0.6745·√2·σ.
        let noise_floor = mad / (0.674_489_75 * std::f64::consts::SQRT_2);
        out.push(ChannelReport {
            sensor,
            axis: AXES[c % 3],
            residual_rms: (ss / n.max(1) as f64).sqrt(),
            noise_floor,
            systematic_rms: sys_rms,
            systematic: significant,
            worst,
        });
    }
    out
}
