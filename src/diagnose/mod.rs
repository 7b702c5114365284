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

use crate::check::harmonics::{chi2_upper, systematic, Systematic};
use crate::estimate::{fit, CoefStatus, EstimateError, Fit, FitOptions, FitRun};
use crate::model::{catalog, forward, nonlinear_catalog, Model, SensorKind, AXES};
use crate::session::MotionSpec;
use serde::{Deserialize, Serialize};
use statrs::distribution::{ChiSquared, ContinuousCDF};

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
}

/// Motion of each run (for the cone phase).
pub type RunMotions<'a> = [&'a MotionSpec];

fn values_of(f: &Fit, model: &Model, sensor: SensorKind) -> Vec<f64> {
    let sf = f.sensor(sensor);
    model.terms(sensor).iter().map(|t| sf.value(&t.term.name).unwrap_or(t.term.nominal)).collect()
}

/// Channel reports of a fitted model.
fn channel_reports(model: &Model, f: &Fit, runs: &[FitRun<'_>], motions: &RunMotions<'_>) -> Vec<ChannelReport> {
    let mut out = Vec::with_capacity(6);
    for sensor in SensorKind::BOTH {
        let terms = model.terms(sensor);
        let values = values_of(f, model, sensor);
        let seen = crate::estimate::nonlinear::seen_tracks(model, f, sensor, runs);
        let moved: Vec<FitRun<'_>> = match &seen {
            Some(tracks) => runs.iter().zip(tracks).map(|(r, t)| FitRun { track: t, ..*r }).collect(),
            None => runs.to_vec(),
        };
        let mut res: Vec<Vec<Vec<f64>>> = vec![Vec::new(); 3];
        for run in &moved {
            let mut r: Vec<Vec<f64>> = (0..3).map(|_| Vec::with_capacity(run.len())).collect();
            for k in 0..run.len() {
                let u = forward(&terms, &values, &run.state(k));
                let y = run.output(sensor, k);
                for ch in 0..3 {
                    r[ch].push(y[ch] - u[ch]);
                }
            }
            for ch in 0..3 {
                res[ch].push(std::mem::take(&mut r[ch]));
            }
        }
        for ch in 0..3 {
            let mut diffs = Vec::new();
            let (mut ss, mut n, mut sys_ss) = (0.0, 0usize, 0.0);
            let (mut chi, mut dof) = (0.0, 0usize);
            let mut worst: Option<(String, Option<usize>, f64)> = None;
            for (ri, r) in res[ch].iter().enumerate() {
                diffs.extend(r.windows(2).map(|w| (w[1] - w[0]).abs()));
                ss += r.iter().map(|v| v * v).sum::<f64>();
                n += r.len();
                let sys: Systematic = systematic(r, &runs[ri].track.t_s, motions[ri], HARMONICS);
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
                    worst = Some((runs[ri].name.to_string(), h, amp));
                }
            }
            // One pooled test per channel over all runs, at 0.001 % (few false alarms even
            // over many channels and sessions).
            let significant = dof > 0 && chi > chi2_upper(dof, SIGNIFICANCE_Z);
            let mid = diffs.len() / 2;
            let mad = if diffs.is_empty() { 0.0 } else { *diffs.select_nth_unstable_by(mid, f64::total_cmp).1 };
            // For white noise, |Δr| has median 0.6745·√2·σ.
            let noise_floor = mad / (0.674_489_75 * std::f64::consts::SQRT_2);
            out.push(ChannelReport {
                sensor,
                axis: AXES[ch],
                residual_rms: (ss / n.max(1) as f64).sqrt(),
                noise_floor,
                systematic_rms: (sys_ss / n.max(1) as f64).sqrt(),
                systematic: significant,
                worst,
            });
        }
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
    let mut current_fit = fit(&current, runs, opts)?;
    let channels = channel_reports(&current, &current_fit, runs, motions);
    let mut steps: Vec<Step> = Vec::new();
    let mut first_round: Option<Vec<Candidate>> = None;
    let mut picture = channels.clone();
    while steps.len() < MAX_STEPS && picture.iter().any(|c| c.systematic) {
        let mut options: Vec<(&'static str, &'static str)> =
            catalog().iter().filter(|e| !e.needs_temperature() || has_temp).map(|e| (e.id(), e.explain())).collect();
        options.extend(nonlinear_catalog().iter().map(|e| (e.id(), e.explain())));
        // Candidates are scored with the nonlinear parameters found so far held (a linear
        // refit each); the chosen one is then refitted jointly with everything.
        let mut held = current.clone();
        for e in current.nonlinear() {
            let values = current_fit.nonlinear.iter().filter(|p| p.effect == e.effect.id()).map(|p| p.value).collect();
            let _ = held.fix_nonlinear(e.effect.id(), values);
        }
        let mut scored = Vec::new();
        for (id, explain) in options {
            let present = current.effects().iter().any(|m| m.id() == id)
                || current.nonlinear().iter().any(|m| m.effect.id() == id);
            if present {
                continue;
            }
            let mut m = held.clone();
            if m.add_effect(id).is_err() {
                continue;
            }
            let Ok(f) = fit(&m, runs, opts) else { continue };
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
        let f = fit(&m, runs, opts)?;
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
        picture = channel_reports(&current, &current_fit, runs, motions);
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
