//! Model versus measurement: where the fitted model fails, and which catalogued physical
//! effect would explain it.
//!
//! 1. Fit the model; per sensor channel compare the residual RMS with the **noise floor**,
//!    estimated from the residual's first differences (σ̂ = 1.4826·MAD(Δr)/√2, blind to
//!    anything smooth), and split the residual into its **systematic** part (per run:
//!    constant + [`HARMONICS`] cone harmonics; one χ² test per channel pooled over runs
//!    against white noise, at the level of [`SIGNIFICANCE_Z`]).
//! 2. For each catalogue effect not in the model, refit with it and score it: residual
//!    reduction, a likelihood-ratio (χ²) p-value and ΔBIC = Σ_s N_s ln(RSS₁/RSS₀) + Δp ln N
//!    over both sensors. Nonlinear effects (time delay, dead zone) are fitted by variable
//!    projection for each try. Candidates that do not reach ΔBIC < [`BIC_EVIDENCE`] are not proposed.
//! 3. Climb greedily: add the best candidate, re-score the rest, until the systematic
//!    residual is at the noise floor or nothing helps. Candidates whose scores are within
//!    [`BIC_TIE`] of the best are reported as indistinguishable on these runs.
//! 4. Verdict: adequate (nothing systematic, nothing proposed), explained (the proposed
//!    effects bring the systematic residual to the noise floor), or unexplained (the channel,
//!    harmonic and runs where the systematic residual stays).

pub mod protocol;
pub mod report;

use crate::estimate::{CoefStatus, EstimateError, Fit, FitOptions, FitRequest, FitRun};
use crate::model::{catalog, forward, Model};
use crate::session::MotionSpec;
use crate::stats::{chi2_upper, systematic, Systematic};
use crate::units::{SensorKind, AXES};
use serde::{Deserialize, Serialize};
use statrs::distribution::{ChiSquared, ContinuousCDF};

/// Fits exactly `model` to prepared runs through the one entry point.
fn refit(model: &Model, runs: &[FitRun<'_>], opts: &FitOptions) -> Result<Fit, EstimateError> {
    Ok(crate::estimate::fit(&FitRequest::runs(model, runs).options(*opts))?.fit)
}

/// Cone harmonics in the systematic-residual fit.
pub const HARMONICS: usize = 6;
/// ΔBIC below which an effect counts as supported (very strong evidence).
pub const BIC_EVIDENCE: f64 = -10.0;
/// Candidates whose ΔBIC differ by less than this are indistinguishable.
pub const BIC_TIE: f64 = 10.0;
/// Normal quantile of the pooled χ² test for a systematic residual (0.001 %).
pub const SIGNIFICANCE_Z: f64 = 4.265;
/// At most this many effects are added by the ladder.
pub const MAX_STEPS: usize = 4;

/// Residual picture of one channel.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ChannelReport {
    /// Sensor.
    pub sensor: SensorKind,
    /// Axis.
    pub axis: char,
    /// Residual RMS (SI).
    pub residual_rms: f64,
    /// Noise floor σ̂ from first differences (SI).
    pub noise_floor: f64,
    /// RMS of the systematic part (SI).
    pub systematic_rms: f64,
    /// Whether the systematic part is significant (pooled χ² over runs).
    pub systematic: bool,
    /// Where the systematic part is largest: (run, harmonic, amplitude SI); harmonic 0 is a
    /// constant, None for non-conic runs.
    pub worst: Option<(String, Option<usize>, f64)>,
}

/// One candidate effect's score.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Candidate {
    /// Effect id.
    pub effect: String,
    /// Sensor whose residual it reduces most.
    pub sensor: SensorKind,
    /// Coefficients it adds that the runs could identify.
    pub added_params: usize,
    /// That sensor's RSS before (SI²).
    pub rss_before: f64,
    /// Sensor RSS with the effect.
    pub rss_after: f64,
    /// Likelihood-ratio p-value of the added coefficients.
    pub p_value: f64,
    /// ΔBIC (negative = supported).
    pub delta_bic: f64,
    /// Physical explanation.
    pub explanation: String,
}

/// One step of the ladder.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Step {
    /// Effect added.
    pub effect: String,
    /// Its score when added.
    pub score: Candidate,
    /// Other candidates indistinguishable from it at this step.
    pub indistinguishable: Vec<String>,
    /// Channel picture after adding it.
    pub channels: Vec<ChannelReport>,
}

/// Overall verdict.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Verdict {
    /// Residual at the noise floor; nothing to add.
    Adequate,
    /// The proposed effects bring the residual to the noise floor.
    Explained,
    /// A systematic residual remains that no catalogued effect explains.
    Unexplained,
}

/// The full diagnosis.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Diagnosis {
    /// Model diagnosed.
    pub model: String,
    /// Channel picture of the model as given.
    pub channels: Vec<ChannelReport>,
    /// First-round scores of every applicable candidate, best first.
    pub candidates: Vec<Candidate>,
    /// Effects added, in order.
    pub steps: Vec<Step>,
    /// Verdict.
    pub verdict: Verdict,
    /// Effects proposed (empty unless explained).
    pub proposal: Vec<String>,
    /// Where an unexplained systematic residual sits, in words.
    pub unexplained: Vec<String>,
    /// Cautions (aliasing between candidates, missing inputs).
    pub warnings: Vec<String>,
    /// Fit of the model at the end of the ladder (see [`ladder_model`]).
    pub final_fit: Fit,
    /// Coefficients whose single-run estimates disagree with the all-run fit (a sign that
    /// something depends on rate, direction, cone angle or mount).
    pub disagreements: Vec<Disagreement>,
}

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

/// The model at the end of a diagnosis's ladder: the base model plus each added effect.
pub fn ladder_model(base: &Model, d: &Diagnosis) -> Model {
    let mut m = base.clone();
    for s in &d.steps {
        let _ = m.add_effect(&s.effect);
    }
    m
}

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
    let mut out: Vec<RunResiduals> = runs
        .iter()
        .zip(motions.iter())
        .map(|(run, m)| RunResiduals {
            run: run.name.to_string(),
            t_s: run.track.t_s.clone(),
            theta: match m {
                MotionSpec::Conic { cone_angle_deg, rate_deg_s, phase_deg } => {
                    let c = crate::motion::Conic::from_deg(*cone_angle_deg, *rate_deg_s, *phase_deg);
                    Some(run.track.t_s.iter().map(|&t| c.theta(t).rem_euclid(std::f64::consts::TAU)).collect())
                }
                _ => None,
            },
            r: (0..6).map(|_| Vec::with_capacity(run.len())).collect(),
            output_ss: [0.0; 6],
        })
        .collect();
    for (si, sensor) in SensorKind::BOTH.into_iter().enumerate() {
        let terms = model.terms(sensor);
        let values = values_of(f, model, sensor);
        let seen = crate::estimate::seen_tracks(model, f, sensor, runs);
        let moved: Vec<FitRun<'_>> = match &seen {
            Some(tracks) => runs.iter().zip(tracks).map(|(r, t)| FitRun { track: t, ..*r }).collect(),
            None => runs.to_vec(),
        };
        for (run, o) in moved.iter().zip(out.iter_mut()) {
            for k in 0..run.len() {
                let u = forward(&terms, &values, &run.state(k));
                let y = run.output(sensor, k);
                for ch in 0..3 {
                    o.r[3 * si + ch].push(y[ch] - u[ch]);
                    o.output_ss[3 * si + ch] += y[ch] * y[ch];
                }
            }
        }
    }
    out
}

/// Relative numerical resolution below which a residual is rounding, not physics.
const RESOLUTION: f64 = 1e-10;

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

fn sensor_rss(f: &Fit, sensor: SensorKind) -> (f64, u64, usize) {
    let sf = f.sensor(sensor);
    let rss = sf.channels.iter().map(|c| c.residual_rms * c.residual_rms * c.n as f64).sum();
    let n = sf.channels.iter().map(|c| c.n).sum();
    let p = sf.coefficients.iter().filter(|c| c.status == CoefStatus::Fitted).count();
    (rss, n, p)
}

/// Scores a refit against the base fit over both sensors: the likelihood-ratio statistic
/// LR = Σ_s N_s ln(RSS₀/RSS₁) (χ² with Δp degrees of freedom under "no effect", giving the
/// p-value) and ΔBIC = −LR + Δp ln N.
fn score(base: &Fit, with: &Fit, effect: &str, explanation: &str) -> Candidate {
    let fitted_nl = |f: &Fit| f.nonlinear.iter().filter(|p| p.fitted).count();
    let mut lr = 0.0;
    let mut dp = fitted_nl(with).saturating_sub(fitted_nl(base));
    let mut n_total = 0.0;
    let (mut best_sensor, mut best_gain) = (SensorKind::Gyro, f64::NEG_INFINITY);
    let (mut rss_before, mut rss_after) = (0.0, 0.0);
    for s in SensorKind::BOTH {
        let (rss0, n, p0) = sensor_rss(base, s);
        let (rss1, _, p1) = sensor_rss(with, s);
        dp += p1.saturating_sub(p0);
        n_total += n as f64;
        let gain = if rss0 > 0.0 && rss1 > 0.0 { n as f64 * (rss0 / rss1).ln() } else { 0.0 };
        lr += gain;
        if gain > best_gain {
            best_gain = gain;
            best_sensor = s;
            rss_before = rss0;
            rss_after = rss1;
        }
    }
    let p_value = if dp == 0 { 1.0 } else { ChiSquared::new(dp as f64).map(|d| d.sf(lr.max(0.0))).unwrap_or(1.0) };
    Candidate {
        effect: effect.to_string(),
        sensor: best_sensor,
        added_params: dp,
        rss_before,
        rss_after,
        p_value,
        delta_bic: -lr + dp as f64 * n_total.max(1.0).ln(),
        explanation: explanation.to_string(),
    }
}

/// Diagnoses a model on runs. `motions[i]` is run i's declared motion.
pub fn diagnose(
    model: &Model,
    runs: &[FitRun<'_>],
    motions: &RunMotions<'_>,
    opts: &FitOptions,
) -> Result<Diagnosis, EstimateError> {
    let has_temp = runs.iter().all(|r| r.temp_c.is_some() || r.temp_const_c.is_some());
    let mut warnings = Vec::new();
    if !has_temp {
        warnings.push("no temperature in some runs: temperature effects were not tried".to_string());
    }
    let mut current = model.clone();
    let mut current_fit = refit(&current, runs, opts)?;
    let channels = channel_reports(&residuals(&current, &current_fit, runs, motions), motions);
    let disagreements = if current.nonlinear().is_empty() && runs.len() > 1 {
        per_run_disagreements(&current, &current_fit, runs, opts)
    } else {
        Vec::new()
    };
    let mut steps: Vec<Step> = Vec::new();
    let mut first_round: Option<Vec<Candidate>> = None;
    let mut picture = channels.clone();
    while steps.len() < MAX_STEPS && picture.iter().any(|c| c.systematic) {
        let options: Vec<(&'static str, &'static str)> =
            catalog().iter().filter(|e| !e.needs_temperature() || has_temp).map(|e| (e.id(), e.explain())).collect();
        // Candidates are scored with the nonlinear parameters found so far held (a linear
        // refit each); the chosen one is then refitted jointly with everything.
        let mut held = current.clone();
        for e in current.nonlinear() {
            let values = current_fit.nonlinear.iter().filter(|p| p.effect == e.effect.id()).map(|p| p.value).collect();
            let _ = held.fix_nonlinear(e.effect.id(), values);
        }
        let mut scored = Vec::new();
        let screening = FitOptions { screening: true, ..*opts };
        for (id, explain) in options {
            if current.has(id) {
                continue;
            }
            let mut m = held.clone();
            if m.add_effect(id).is_err() {
                continue;
            }
            let Ok(f) = refit(&m, runs, &screening) else { continue };
            scored.push((score(&current_fit, &f, id, explain), id, f));
        }
        scored.sort_by(|a, b| a.0.delta_bic.total_cmp(&b.0.delta_bic));
        if first_round.is_none() {
            first_round = Some(scored.iter().map(|s| s.0.clone()).collect());
        }
        let Some((best, id, _)) = scored.first().cloned() else { break };
        if best.delta_bic >= BIC_EVIDENCE {
            break;
        }
        let mut m = current.clone();
        if m.add_effect(id).is_err() {
            break;
        }
        let f = refit(&m, runs, opts)?;
        let best = score(&current_fit, &f, id, &best.explanation);
        let indistinguishable: Vec<String> = scored[1..]
            .iter()
            .filter(|s| s.0.sensor == best.sensor && s.0.delta_bic - best.delta_bic < BIC_TIE)
            .map(|s| s.0.effect.clone())
            .collect();
        if !indistinguishable.is_empty() {
            warnings.push(format!(
                "{} and {} fit these runs equally well (ΔBIC within {BIC_TIE}): they alias on these runs; add runs at another rate, direction, cone angle or mount to separate them",
                best.effect,
                indistinguishable.join(", ")
            ));
        }
        current = m;
        current_fit = f;
        picture = channel_reports(&residuals(&current, &current_fit, runs, motions), motions);
        steps.push(Step { effect: best.effect.clone(), score: best, indistinguishable, channels: picture.clone() });
    }
    let remaining: Vec<&ChannelReport> = picture.iter().filter(|c| c.systematic).collect();
    let verdict = if steps.is_empty() && remaining.is_empty() {
        Verdict::Adequate
    } else if remaining.is_empty() {
        Verdict::Explained
    } else {
        Verdict::Unexplained
    };
    let unexplained = remaining
        .iter()
        .map(|c| {
            let at = match &c.worst {
                Some((run, Some(0), a)) => format!("a constant offset of {a:.3e} in run {run}"),
                Some((run, Some(h), a)) => {
                    format!("harmonic {h} of the cone frequency, amplitude {a:.3e}, largest in run {run}")
                }
                Some((run, None, a)) => format!("a slow variation of up to {a:.3e} in run {run}"),
                None => "no single place".to_string(),
            };
            format!(
                "{} {}: systematic residual RMS {:.3e} against a noise floor of {:.3e} (SI); it sits at {at}",
                c.sensor, c.axis, c.systematic_rms, c.noise_floor
            )
        })
        .collect();
    let proposal =
        if verdict == Verdict::Explained { steps.iter().map(|s| s.effect.clone()).collect() } else { Vec::new() };
    Ok(Diagnosis {
        disagreements,
        final_fit: current_fit,
        model: model.name.clone(),
        channels,
        candidates: first_round.unwrap_or_default(),
        steps,
        verdict,
        proposal,
        unexplained,
        warnings,
    })
}

/// One rung of the model ladder.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Rung {
    /// Model name.
    pub model: String,
    /// Fitted parameters (linear and nonlinear).
    pub params: usize,
    /// Residual RMS per channel (gyro x, y, z, accel x, y, z), SI.
    pub rms: Vec<f64>,
    /// Largest |residual| per channel, SI.
    pub max: Vec<f64>,
    /// Noise floor per channel, SI.
    pub noise_floor: Vec<f64>,
    /// BIC = Σ_s N_s ln(RSS_s/N_s) + p ln N.
    pub bic: f64,
    /// Worst-channel residual RMS of the paper model over this model's, per sensor (gyro, accel).
    pub reduction: Vec<f64>,
    /// Leave-one-run-out residual RMS per channel, SI: each run predicted by the model
    /// fitted on the others (nonlinear parameters held at their all-run values).
    pub heldout_rms: Vec<f64>,
    /// This rung improves the held-out residual over the previous rung (by more than 0.1 %).
    pub heldout_gain: bool,
}

fn rung(name: &str, f: &Fit, res: &[RunResiduals], motions: &RunMotions<'_>) -> Rung {
    let ch = channel_reports(res, motions);
    let mut bic = 0.0;
    let mut n_total = 0.0;
    let mut params = f.nonlinear.iter().filter(|p| p.fitted).count();
    for s in SensorKind::BOTH {
        let (rss, n, p) = sensor_rss(f, s);
        if n > 0 && rss > 0.0 {
            bic += n as f64 * (rss / n as f64).ln();
        }
        n_total += n as f64;
        params += p;
    }
    bic += params as f64 * n_total.max(1.0).ln();
    let max = (0..6).map(|c| res.iter().flat_map(|r| r.r[c].iter()).fold(0.0_f64, |m, v| m.max(v.abs()))).collect();
    Rung {
        model: name.to_string(),
        params,
        rms: ch.iter().map(|c| c.residual_rms).collect(),
        max,
        noise_floor: ch.iter().map(|c| c.noise_floor).collect(),
        bic,
        reduction: Vec::new(),
        heldout_rms: Vec::new(),
        heldout_gain: true,
    }
}

/// Leave-one-run-out residual RMS per channel of a model (nonlinear parameters of `all`
/// held, so each fold is a linear fit).
pub fn heldout_rms(
    model: &Model,
    all: &Fit,
    runs: &[FitRun<'_>],
    motions: &RunMotions<'_>,
    opts: &FitOptions,
) -> Vec<f64> {
    let mut held = model.clone();
    for e in model.nonlinear() {
        let values = all.nonlinear.iter().filter(|p| p.effect == e.effect.id()).map(|p| p.value).collect();
        let _ = held.fix_nonlinear(e.effect.id(), values);
    }
    let mut ss = [0.0; 6];
    let mut n = 0usize;
    for i in 0..runs.len() {
        let train: Vec<FitRun<'_>> = runs.iter().enumerate().filter(|(j, _)| *j != i).map(|(_, r)| *r).collect();
        let Ok(f) = refit(&held, &train, opts) else { continue };
        let res = residuals(&held, &f, std::slice::from_ref(&runs[i]), &motions[i..=i]);
        for c in 0..6 {
            ss[c] += res[0].r[c].iter().map(|v| v * v).sum::<f64>();
        }
        n += runs[i].len();
    }
    ss.iter().map(|s| (s / n.max(1) as f64).sqrt()).collect()
}

/// The model ladder: the paper's model, the default model, then each effect `diagnose` adds
/// (and any `extra` sets of effects), with residuals, BIC, the reduction against the paper's
/// model and the leave-one-run-out residual, so that an effect that only fits noise shows
/// no held-out gain.
pub fn compare(
    runs: &[FitRun<'_>],
    motions: &RunMotions<'_>,
    opts: &FitOptions,
    extra: &[Vec<String>],
) -> Result<(Vec<Rung>, Diagnosis), EstimateError> {
    let paper = Model::paper();
    let base = Model::default_model();
    let d = diagnose(&base, runs, motions, opts)?;
    // The ladder's models, each fitted once.
    let mut models = vec![("paper (eqs. 3-4)".to_string(), paper), ("default".to_string(), base.clone())];
    let mut m = base;
    for st in &d.steps {
        let _ = m.add_effect(&st.effect);
        models.push((format!("+ {}", st.effect), m.clone()));
    }
    for effects in extra {
        for e in effects {
            let _ = m.add_effect(e);
        }
        models.push((format!("+ {}", effects.join(" + ")), m.clone()));
    }
    let mut rungs = Vec::with_capacity(models.len());
    for (name, model) in &models {
        let f = refit(model, runs, opts)?;
        let mut r = rung(name, &f, &residuals(model, &f, runs, motions), motions);
        if runs.len() > 1 {
            r.heldout_rms = heldout_rms(model, &f, runs, motions, opts);
        }
        rungs.push(r);
    }
    if runs.len() > 1 {
        let total = |r: &Rung| -> f64 {
            (0..6).map(|c| (r.heldout_rms[c] / r.noise_floor[c].max(f64::MIN_POSITIVE)).powi(2)).sum()
        };
        for i in 1..rungs.len() {
            rungs[i].heldout_gain = total(&rungs[i]) < total(&rungs[i - 1]) * 0.999;
        }
    }
    let worst = |r: &Rung, s: usize| r.rms[3 * s..3 * s + 3].iter().copied().fold(0.0, f64::max);
    let paper_worst = [worst(&rungs[0], 0), worst(&rungs[0], 1)];
    for r in &mut rungs {
        r.reduction =
            (0..2).map(|s| if worst(r, s) > 0.0 { paper_worst[s] / worst(r, s) } else { f64::INFINITY }).collect();
    }
    Ok((rungs, d))
}
