//! Model versus measurement: where the fitted model fails, and which catalogued physical
//! effect would explain it — accepted only on evidence the noise cannot fake.
//!
//! 1. Fit the model; per run and channel, model the residual's noise (an AR(p) after the
//!    run's systematic basis, [`space`]) and look for narrow-band lines in its spectrum
//!    ([`lines`]). The noise floor is the noise model's standard deviation.
//! 2. Build the whitened Gram of every catalogue effect's columns beside the model's
//!    ([`space`]): every statistic below is generalised least squares, honest under
//!    serially correlated noise, computed without another pass over the samples.
//! 3. Climb greedily ([`select`]): add the effect with the largest χ² reduction among those
//!    that are supported in-sample (p and ΔBIC), predict left-out runs, and have one size
//!    in every run; two that explain the same residual are one finding. Stop when none
//!    qualifies: there is no cap on the number of steps while the evidence supports one
//!    (each step adds a catalogue effect the model lacks, so the catalogue bounds it). A
//!    temperature polynomial's degree comes with its uncertainty, a thermal hysteresis with
//!    its size ([`temperature`]).
//! 4. Verdict: adequate (nothing systematic, no line off the cone, nothing added),
//!    explained (the added effects leave nothing systematic), or unexplained (where the
//!    residual's systematic part or lines sit: channel, harmonic or frequency, runs, size).

pub mod algebra;
mod analysis;
mod basis;
mod disagreement;
mod knobs;
mod ladder;
pub mod lines;
mod mount;
mod noise_choice;
pub mod picture;
pub mod protocol;
mod reduced;
pub mod report;
mod secants;
pub mod select;
pub mod separate;
pub mod shape;
pub mod slow;
pub mod space;
pub mod stand;
mod stand_words;
mod temperature;
mod with_stand;

pub use disagreement::{per_run_disagreements, Disagreement, DISAGREEMENT_Z};
pub use lines::Line;
pub use picture::{channel_reports, residuals, RunMotions, RunResiduals};
pub use select::{Estimate, Evidence, BIC_EVIDENCE};
pub use space::HARMONICS;
pub use stand::{StandFinding, StandValue};
pub use temperature::{DegreeChoice, DegreeScore};

use crate::estimate::{EstimateError, Fit, FitOptions, FitRequest, FitRun};
use crate::model::{find, Model};
use crate::units::{SensorKind, AXES};
use analysis::{analyse, noise_reports, Analysis};
pub use ladder::{compare, ladder_model, Rung};
pub use noise_choice::{diagnose_with_mode, SlowNoiseMode};
use rayon::prelude::*;
use select::{Leftover, Space};
use serde::{Deserialize, Serialize};

/// Fits exactly `model` to prepared runs through the one entry point.
fn refit(model: &Model, runs: &[FitRun<'_>], opts: &FitOptions) -> Result<Fit, EstimateError> {
    Ok(crate::estimate::fit(&FitRequest::runs(model, runs).options(*opts))?.fit)
}

/// The channel index 0..6 (gyro x..z, accel x..z) of a sensor's axis.
fn channel_of(sensor: SensorKind, axis: char) -> usize {
    3 * usize::from(sensor == SensorKind::Accel) + AXES.iter().position(|&x| x == axis).unwrap_or(0)
}

/// Relative numerical resolution below which a residual is rounding, not physics (no
/// sensor resolves 1e-10 of its signal).
const RESOLUTION: f64 = 1e-10;

/// Per channel: the smallest residual that is not rounding of the recording and the
/// arithmetic (RESOLUTION × output RMS).
fn resolution(space: &Space) -> Vec<f64> {
    (0..6)
        .map(|c| {
            let (mut ms, mut n) = (0.0, 0.0);
            for rg in &space.runs {
                ms += rg.output_ms[c] * rg.noise[c].n as f64;
                n += rg.noise[c].n as f64;
            }
            RESOLUTION * (ms / n.max(1.0)).sqrt()
        })
        .collect()
}

/// Normal quantile of the pooled χ² test for a systematic residual (0.001 %).
pub const SIGNIFICANCE_Z: f64 = 4.265;
/// A candidate whose χ² gain, once the chosen effect is in, keeps less than this share of
/// its own is explained by the same residual feature (indistinguishable on these runs).
const SHARED_FEATURE: f64 = 0.1;

/// Residual picture of one channel.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ChannelReport {
    /// Sensor.
    pub sensor: SensorKind,
    /// Axis.
    pub axis: char,
    /// Residual RMS (SI).
    pub residual_rms: f64,
    /// Noise floor: the standard deviation of the noise model (SI).
    pub noise_floor: f64,
    /// RMS of the systematic part (SI).
    pub systematic_rms: f64,
    /// Whether the systematic part is significant (pooled GLS χ² over runs).
    pub systematic: bool,
    /// Where the systematic part is largest: (run, harmonic, amplitude SI); harmonic 0 is a
    /// constant, None a slow variation (or a run without a cone).
    pub worst: Option<(String, Option<usize>, f64)>,
}

/// The noise model of one channel, pooled over runs.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct NoiseReport {
    /// Sensor.
    pub sensor: SensorKind,
    /// Axis.
    pub axis: char,
    /// Standard deviation of the noise (SI).
    pub sigma: f64,
    /// Lag-one autocorrelation of the noise model (0 for white noise).
    pub lag1: f64,
    /// Largest AR order chosen over the runs.
    pub ar_order: usize,
    /// Variance of the noise over the variance of its one-step innovations (1 when white).
    pub colour: f64,
    /// Slow wander of the noise (flicker): bias instability B, SI (0: none seen). Read off
    /// the residual less its cone harmonics as `crosscal noise` reads it off a recording at
    /// rest (Allan deviation flat at 0.664 B); a slow variation of this kind is noise.
    #[serde(default)]
    pub bias_instability: f64,
    /// Slow wander of the noise: rate random walk K, SI per √s (0: none seen).
    #[serde(default)]
    pub random_walk: f64,
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
    /// That sensor's whitened residual χ² before (noise units: about one per sample).
    pub rss_before: f64,
    /// The same with the effect.
    pub rss_after: f64,
    /// χ² p-value of the added coefficients (generalised least squares).
    pub p_value: f64,
    /// ΔBIC (negative = supported).
    pub delta_bic: f64,
    /// The evidence in full (held-out gain, per-run consistency).
    pub evidence: Evidence,
    /// Why it is not accepted (None: it qualifies).
    pub rejected: Option<String>,
    /// Physical explanation.
    pub explanation: String,
    /// Its coefficients' sizes fitted on all runs, with standard errors (SI).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub estimates: Vec<Estimate>,
    /// For a temperature polynomial added by the ladder: its degree and how sure that is.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub degree: Option<DegreeChoice>,
}

/// One step of the ladder.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Step {
    /// Effect added.
    pub effect: String,
    /// Its score when added.
    pub score: Candidate,
    /// Other candidates that explain the same residual feature on these runs.
    pub indistinguishable: Vec<String>,
    /// The runs that would separate it from the first of those, with the largest
    /// correlation of their coefficients now and with those runs (design, not data).
    #[serde(default)]
    pub separated_by: Option<separate::Separation>,
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
    /// A systematic residual or a line remains that no catalogued effect explains.
    Unexplained,
}

/// The full diagnosis.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Diagnosis {
    /// Model diagnosed.
    pub model: String,
    /// Channel picture of the model as given.
    pub channels: Vec<ChannelReport>,
    /// The noise model per channel, around the model at the end of the ladder (what the
    /// added effects do not explain).
    pub noise: Vec<NoiseReport>,
    /// Narrow-band lines in the residual's spectrum.
    pub lines: Vec<Line>,
    /// First-round scores of every applicable candidate, best first.
    pub candidates: Vec<Candidate>,
    /// Effects added, in order.
    pub steps: Vec<Step>,
    /// Verdict.
    pub verdict: Verdict,
    /// Effects proposed (empty unless explained).
    pub proposal: Vec<String>,
    /// Where an unexplained systematic residual or line sits, in words.
    pub unexplained: Vec<String>,
    /// What these runs cannot identify, and the run that would.
    pub unidentifiable: Vec<String>,
    /// Cautions (aliasing between candidates, missing inputs).
    pub warnings: Vec<String>,
    /// Fit of the model at the end of the ladder (see [`ladder_model`]).
    pub final_fit: Fit,
    /// Where no catalogued effect brings a channel to the noise floor: the residual's shape
    /// against what it could depend on, in words, plots and an effects-file entry.
    #[serde(default)]
    pub shapes: Vec<shape::Shape>,
    /// Catalogued effects tried on a sensor none of them explains, with the residual each
    /// left (none is reported as an addition).
    #[serde(default)]
    pub tried: Vec<String>,
    /// Coefficients whose single-run estimates disagree with the all-run fit (a sign that
    /// something depends on rate, direction, cone angle or mount).
    pub disagreements: Vec<Disagreement>,
    /// What the stand (or the environment) did that the manifest does not say, with the
    /// estimated values: the rest of the diagnosis is on the motion so corrected.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub stand: Vec<StandFinding>,
}

impl Diagnosis {
    /// The command that fits the proposed effects on the session at `session`, with
    /// `--stand` when the stand moved otherwise than its manifest says (a fit on the
    /// declared motion would put the stand's error into the unit's coefficients); a wrong
    /// mount is corrected in the manifest, which the command then says first.
    pub fn fit_command(&self, session: &str) -> String {
        let mut cmd = format!("crosscal fit {session}");
        for e in &self.proposal {
            cmd.push_str(&format!(" --effect {e}"));
        }
        if self.stand.iter().any(|f| f.id != "mount") {
            cmd.push_str(" --stand");
        }
        if self.stand.iter().any(|f| f.id == "mount") {
            format!("correct the run's mount in the manifest (above), then {cmd}")
        } else {
            cmd
        }
    }
}

/// The channel picture of a set of effects: residual RMS from its fit, the systematic
/// part from the Grams.
fn picture(
    resolution: f64,
    l: &select::Leftover,
    fit: &Fit,
    noise: &[NoiseReport],
    names: &[String],
    c: usize,
) -> ChannelReport {
    let sensor = if c < 3 { SensorKind::Gyro } else { SensorKind::Accel };
    let ch = &fit.sensor(sensor).channels[c % 3];
    let sys_rms = (l.ss / l.n.max(1.0)).sqrt();
    let fitted_rms = (l.ss_fitted / l.n.max(1.0)).sqrt();
    let significant = l.dof > 0 && l.chi2 > crate::stats::chi2_upper(l.dof, SIGNIFICANCE_Z) && fitted_rms > resolution;
    ChannelReport {
        sensor,
        axis: AXES[c % 3],
        residual_rms: ch.residual_rms,
        noise_floor: noise[c].sigma,
        systematic_rms: sys_rms,
        systematic: significant,
        worst: l.worst.map(|(r, f, a, _)| (names[r].clone(), f, a)),
    }
}

fn pictures(a: &Analysis, set: &[usize], fit: &Fit, noise: &[NoiseReport]) -> Vec<ChannelReport> {
    let left: Vec<Leftover> = a.space.systematic(&a.space.solve_slow(set));
    let res = resolution(&a.space);
    (0..6).map(|c| picture(res[c], &left[c], fit, noise, &a.names, c)).collect()
}

fn candidate(id: &str, ev: Evidence, base_q: &[f64]) -> Candidate {
    let s = usize::from(ev.delta_q_sensor[1] > ev.delta_q_sensor[0]);
    let before: f64 = base_q[3 * s..3 * s + 3].iter().sum();
    Candidate {
        effect: id.to_string(),
        sensor: SensorKind::BOTH[s],
        added_params: ev.added_params,
        rss_before: before,
        rss_after: before - ev.delta_q_sensor[s],
        p_value: ev.p_value,
        delta_bic: ev.delta_bic,
        rejected: ev.rejection(),
        evidence: ev,
        explanation: find(id).map_or("", |e| e.explain()).to_string(),
        estimates: Vec::new(),
        degree: None,
    }
}

/// Diagnoses a model on runs. `motions[i]` is run i's declared motion.
pub fn diagnose(
    model: &Model,
    runs: &[FitRun<'_>],
    motions: &RunMotions<'_>,
    opts: &FitOptions,
) -> Result<Diagnosis, EstimateError> {
    Ok(with_stand::finish(diagnose_from(model, runs, motions, opts, None)?, model, runs, motions))
}

/// A diagnosis concluded, with what its last and costly parts need: they are worked out
/// ([`with_stand::finish`]) only for the diagnosis that is the answer (the automatic
/// slow-noise mode concludes two and keeps one).
pub(super) struct Concluded {
    /// The diagnosis, without its shapes and per-run disagreements.
    pub(super) d: Diagnosis,
    /// The stand suspect at the end (None: the declared motion); the shapes are drawn on
    /// the motion it believes.
    pub(super) stand: Option<stand::Suspect>,
    /// The default model's fit the single-run fits are compared with (None: no comparison,
    /// [`per_run_disagreements`]), on the motion the stand suspect believed when the
    /// diagnosis kept it (None: the declared one), and the fit's options.
    pub(super) compare: Option<(Fit, Option<stand::Suspect>, FitOptions)>,
}

/// [`diagnose`], with the stand starting from `start` (a suspect carried from a diagnosis
/// under another noise model) and the stand suspect at the end.
fn diagnose_from(
    model: &Model,
    runs: &[FitRun<'_>],
    motions: &RunMotions<'_>,
    opts: &FitOptions,
    start: Option<stand::Suspect>,
) -> Result<Concluded, EstimateError> {
    let has_temp = runs.iter().all(|r| r.temp_c.is_some() || r.temp_const_c.is_some());
    let Some(suspect) = start.or_else(|| stand::Suspect::new(runs, motions)) else {
        let a = analyse(model, refit(model, runs, opts)?, runs, motions, has_temp);
        return conclude(a, model, runs, motions, opts, has_temp, None)?
            .ok_or_else(|| EstimateError::NotConverged("the diagnosis did not settle".into()));
    };
    with_stand::diagnose(suspect, model, runs, motions, opts, has_temp)
}

/// The shape of what no effect explains on each channel still systematic (module `shape`),
/// around the model at the end of the ladder (`steps` added, fitted as `fit` on `runs`),
/// each channel's noise as `noise` reports it and the slow noise the fit measured.
fn draw_shapes(
    model: &Model,
    steps: &[Step],
    fit: &Fit,
    runs: &[FitRun<'_>],
    motions: &RunMotions<'_>,
    remaining: &[&ChannelReport],
    noise: &[NoiseReport],
) -> Vec<shape::Shape> {
    if remaining.is_empty() {
        return Vec::new();
    }
    let mut m = model.clone();
    for st in steps {
        let _ = m.add_effect(&st.effect);
    }
    let span_s: f64 = runs.iter().map(run_span).sum();
    let run_s = span_s / runs.len().max(1) as f64;
    remaining
        .iter()
        .map(|ch| {
            let c = channel_of(ch.sensor, ch.axis);
            let n = &noise[c];
            let scale = shape::NoiseScale::new(n.sigma, n.lag1, fit.slow_noise(c), span_s, run_s);
            shape::shape_of(&m, fit, runs, motions, c, scale)
        })
        .collect()
}

/// The diagnosis of an analysed session, its stand suspect left for the caller to set
/// (None: the stand check corrected the motion and the diagnosis starts again).
fn conclude(
    a: Analysis,
    model: &Model,
    runs: &[FitRun<'_>],
    motions: &RunMotions<'_>,
    opts: &FitOptions,
    has_temp: bool,
    mut stand_check: Option<with_stand::StandCheck<'_, '_, '_>>,
) -> Result<Option<Concluded>, EstimateError> {
    let mut warnings = Vec::new();
    if !has_temp {
        warnings.push("no temperature in some runs: temperature effects were not tried".to_string());
    }
    let noise = noise_reports(&a.space);
    let base_set = a.space.base_set();
    let channels = pictures(&a, &base_set, &a.base_fit, &noise);
    warnings.extend(absorbed(&channels, &noise));
    // The per-run refits compare with the base model's fit, on the motion the climb keeps
    // (a stand group found starts the diagnosis again); they are made for the answer.
    let disagree = model.nonlinear().is_empty() && runs.len() > 1;
    let base_fit = if disagree { Some(a.base_fit.clone()) } else { None };
    let (mut steps, mut first_round, mut a, restart) =
        climb(a, model, runs, motions, opts, has_temp, &mut warnings, stand_check.as_mut())?;
    if restart {
        return Ok(None);
    }
    let compare = base_fit.map(|f| (f, stand_check.as_ref().map(|sc| sc.believed()), *opts));
    // Each temperature polynomial's degree, again with every effect found in the model.
    let mut changed = temperature::revisit_degrees(&a.space, &mut steps, &mut warnings);
    // A sensor still systematic after its effects: no catalogued effect brings it to the
    // noise floor, so none is reported as an addition; they are listed as tried, with the
    // residual each leaves, and the residual's shape is drawn instead (module `shape`).
    let (tried, set_aside) = set_aside(&channels, &mut steps, &mut first_round);
    changed |= set_aside;
    let mut m = model.clone();
    for st in &steps {
        let _ = m.add_effect(&st.effect);
    }
    // A user effect whose linear part moves with its parameters (a knee's rate): the climb's
    // pictures are linearised around the model before it, which cannot follow the kink to
    // its estimate; the last picture is drawn again around the final fit.
    changed |= !steps.is_empty() && m.has_bound_parameters();
    if changed {
        if let Some(sc) = stand_check.as_mut() {
            sc.moved_on();
        }
        a = analyse(&m, refit(&m, runs, opts)?, runs, motions, has_temp);
        let noise = noise_reports(&a.space);
        if let Some(st) = steps.last_mut() {
            st.channels = pictures(&a, &a.space.base_set(), &a.base_fit, &noise);
        }
    }
    let final_fit = a.base_fit.clone();
    let picture_now = steps.last().map_or_else(|| channels.clone(), |s| s.channels.clone());
    let names: Vec<&str> = a.names.iter().map(String::as_str).collect();
    let tol = runs.iter().map(|r| run_span(r)).fold(0.0, f64::max);
    // A line within ten times the recording's numerical resolution is its rounding (a
    // noiseless recording), not a disturbance.
    let res = resolution(&a.space);
    let channel = |l: &Line| channel_of(l.sensor, l.axis);
    let found: Vec<Line> = lines::group(&a.space.runs, &names, if tol > 0.0 { 4.0 / tol } else { 0.05 })
        .into_iter()
        .filter(|l| l.amplitude > 10.0 * res[channel(l)])
        .collect();
    let remaining: Vec<&ChannelReport> = picture_now.iter().filter(|c| c.systematic).collect();
    // A line no effect of the model holds: off the cone (a resonance, vibration, pick-up),
    // or on a cone harmonic above those the runs' bases fit (a shape locked to the motion
    // with edges sharper than the basis, e.g. the rest of a play's square wave).
    let unheld: Vec<&Line> = found.iter().filter(|l| l.cone_harmonic.is_none_or(|h| h > space::HARMONICS)).collect();
    let verdict = if !remaining.is_empty() || !unheld.is_empty() {
        Verdict::Unexplained
    } else if steps.is_empty() {
        Verdict::Adequate
    } else {
        Verdict::Explained
    };
    let mut unexplained: Vec<String> = remaining.iter().map(|c| describe_leftover(c)).collect();
    unexplained.extend(unheld.iter().map(|l| match l.cone_harmonic {
        Some(_) => format!(
            "{}: locked to the motion, beyond what the model holds (edges sharper than a smooth \
             shape follows, or the stand's speed rippling at that harmonic)",
            l.describe()
        ),
        None => l.describe(),
    }));
    let final_noise = noise_reports(&a.space);
    let unidentifiable = unidentifiable(&final_fit, &first_round);
    let stand = with_stand::findings(stand_check, opts, model, &steps, &final_fit, runs, &a);
    // The stand explains what the unit does not need to: nothing left is "explained".
    let verdict = if verdict == Verdict::Adequate && !stand.is_empty() { Verdict::Explained } else { verdict };
    let proposal =
        if verdict == Verdict::Explained { steps.iter().map(|s| s.effect.clone()).collect() } else { Vec::new() };
    let d = Diagnosis {
        model: model.name.clone(),
        channels,
        noise: final_noise,
        // Drawn, with the disagreements, once this diagnosis is the answer (`with_stand::finish`).
        shapes: Vec::new(),
        tried,
        lines: found,
        candidates: first_round,
        steps,
        verdict,
        proposal,
        unexplained,
        unidentifiable,
        warnings,
        final_fit,
        disagreements: Vec::new(),
        stand,
    };
    Ok(Some(Concluded { d, stand: None, compare }))
}

fn run_span(r: &FitRun<'_>) -> f64 {
    let t = &r.track.t_s;
    t.last().copied().unwrap_or(0.0) - t.first().copied().unwrap_or(0.0)
}

/// Samples above which a nonlinear search runs on every k-th sample.
const REDUCED_SAMPLES: usize = 100_000;

/// Fits `model`; with nonlinear effects on a large session, their parameters are searched
/// on every k-th sample (the motion is slow against the sampling) and then held while the
/// linear coefficients are fitted on all samples.
fn refit_reduced(
    model: &Model,
    runs: &[FitRun<'_>],
    opts: &FitOptions,
    warnings: &mut Vec<String>,
) -> Result<Fit, EstimateError> {
    if model.nonlinear().is_empty() {
        return refit(model, runs, opts);
    }
    // Nonlinear effects that are pointwise maps of the motion (a dead zone) search on a
    // stored copy of the motion: the same numbers, without the kinematics worked out again
    // at each of the search's evaluations.
    let pointwise = |t: &crate::motion::Track| {
        model.nonlinear().iter().all(|e| e.effect.transform(&e.values, t).maps_beyond(t).is_some())
    };
    let total: usize = runs.iter().map(FitRun::len).sum();
    if total <= REDUCED_SAMPLES {
        return refit(model, runs, opts);
    }
    let k = reduced::step_for(runs, REDUCED_SAMPLES);
    // The reduced copies live only for the search (memory: the fit on all samples follows).
    let searched = {
        let copy = reduced::Reduced::new(runs, k, pointwise);
        let reduced = copy.runs(runs);
        refit(model, &reduced, opts)?
    };
    let mut f = refit(&crate::estimate::held_at_fit(model, &searched), runs, opts)?;
    f.nonlinear = searched.nonlinear;
    warnings.push(format!(
        "nonlinear parameters searched on every {k}th sample ({} of {total}), then held while the rest was fitted on all; `crosscal fit` refines them on all samples",
        total.div_ceil(k)
    ));
    Ok(f)
}

/// Every candidate effect scored around the base set `set` of `space`, best ΔBIC first
/// (each with its columns), and per sensor whether its residual is at the recording's
/// numerical resolution (a noiseless recording: its candidates are then rejected, as
/// there is nothing to explain).
pub(super) fn score(space: &Space, set: &[usize]) -> (Vec<(Candidate, Vec<usize>)>, [bool; 2]) {
    let base = space.solve(set);
    let base_heldout = space.heldout(set);
    let base_q = space.channel_q(&base);
    let mut scored: Vec<(Candidate, Vec<usize>)> = space
        .universe
        .candidates
        .par_iter()
        .map(|&id| {
            let cand = space.effect_params(id);
            (candidate(id, space.evidence(set, &base, &base_heldout, &cand), &base_q), cand)
        })
        .collect();
    scored.extend(temperature::polynomial_candidates(space, set, &base, &base_heldout, &base_q));
    temperature::size_candidates(space, set, &mut scored);
    scored.sort_by(|x, y| x.0.delta_bic.total_cmp(&y.0.delta_bic));
    let res = resolution(space);
    let sigma = noise_reports(space);
    let exact: [bool; 2] = std::array::from_fn(|s| (3 * s..3 * s + 3).all(|c| sigma[c].sigma <= 10.0 * res[c]));
    for (c, _) in &mut scored {
        if c.rejected.is_none() && exact[usize::from(c.sensor == SensorKind::Accel)] {
            c.rejected = Some("the residual is at the recording's numerical resolution".into());
        }
    }
    (scored, exact)
}

/// Steps, first-round candidates, the last analysis, and whether the stand check changed
/// the motion (the climb then stops: the diagnosis starts again on the corrected motion).
type Climb = (Vec<Step>, Vec<Candidate>, Analysis, bool);

/// The greedy climb over candidate effects (module documentation, step 3). After each
/// effect is added the model is refitted (nonlinear parameters by variable projection on
/// all samples) and the runs analysed again around it, so that the noise model, the
/// columns of nonlinear effects and the systematic part follow the model.
#[allow(clippy::too_many_arguments)]
fn climb(
    mut a: Analysis,
    model: &Model,
    runs: &[FitRun<'_>],
    motions: &RunMotions<'_>,
    opts: &FitOptions,
    has_temp: bool,
    warnings: &mut Vec<String>,
    mut stand_check: Option<&mut with_stand::StandCheck<'_, '_, '_>>,
) -> Result<Climb, EstimateError> {
    let mut current = model.clone();
    let mut steps: Vec<Step> = Vec::new();
    let mut first_round: Option<Vec<Candidate>> = None;
    // No step cap: the loop ends when no candidate passes; each step adds an effect the
    // model lacks, so there can be no more steps than candidates (a safety bound only).
    let bound = a.space.universe.candidates.len();
    while steps.len() < bound {
        let space = &a.space;
        let set = space.base_set();
        let (scored, exact) = score(space, &set);
        if steps.is_empty() {
            first_round = Some(scored.iter().map(|s| s.0.clone()).collect());
        }
        let passing: Vec<&(Candidate, Vec<usize>)> = scored.iter().filter(|s| s.0.rejected.is_none()).collect();
        // A recording at its numerical resolution (noiseless) has nothing for the stand to explain.
        if let Some(sc) = stand_check.as_deref_mut().filter(|_| !exact.iter().all(|e| *e)) {
            let sensor_bic = passing.iter().map(|c| c.0.delta_bic).reduce(f64::min);
            if sc.check(&current, &a, runs, sensor_bic, opts)? {
                return Ok((steps, first_round.unwrap_or_default(), a, true));
            }
        }
        let Some(best) = passing.iter().max_by(|x, y| x.0.evidence.delta_q.total_cmp(&y.0.evidence.delta_q)) else {
            break;
        };
        let mut best = temperature::lowest_sufficient_degree(best, &passing);
        let mut indistinguishable = aliases(space, &set, best, &passing);
        // Of effects that explain the same residual, the one the evidence prefers for its
        // number of parameters (the lowest ΔBIC) is named: a weak g-sensitivity, whose
        // pattern anisoelasticity's 15 coefficients also reach, is not anisoelasticity.
        let simpler = passing
            .iter()
            .filter(|o| indistinguishable.contains(&o.0.effect) && o.0.delta_bic < best.0.delta_bic)
            .min_by(|x, y| x.0.delta_bic.total_cmp(&y.0.delta_bic));
        if let Some(simpler) = simpler {
            best = simpler;
            indistinguishable = aliases(space, &set, best, &passing);
        }
        let separated_by = indistinguishable.first().and_then(|other| {
            let b = space.effect_params(other);
            separate::separating_run(space, &current, &a.base_fit, &set, &best.1, &b, runs, motions)
        });
        if !indistinguishable.is_empty() {
            let how = separated_by
                .as_ref()
                .map_or_else(|| "runs at another rate, direction, cone angle or mount".into(), ToString::to_string);
            warnings.push(format!(
                "{} or {}: they explain the same residual on these runs (one finding, not two); {how} would separate them",
                best.0.effect,
                indistinguishable.join(" or ")
            ));
        }
        let mut m = current.clone();
        if m.add_effect(&best.0.effect).is_err() {
            break;
        }
        if let Some(near) = stand_check.as_deref().and_then(with_stand::StandCheck::near) {
            m.starts_from(near);
        }
        let f = refit_reduced(&m, runs, opts, warnings)?;
        let next = analysis::analyse_from(&m, f, runs, motions, has_temp, None, Some(&a));
        let noise = noise_reports(&next.space);
        let channels = pictures(&next, &next.space.base_set(), &next.base_fit, &noise);
        if let Some(sc) = stand_check.as_deref_mut() {
            sc.moved_on();
        }
        steps.push(Step {
            effect: best.0.effect.clone(),
            score: best.0.clone(),
            indistinguishable,
            separated_by,
            channels,
        });
        current = m;
        a = next;
    }
    Ok((steps, first_round.unwrap_or_default(), a, false))
}

/// The passing candidates that explain the same residual feature as `best`: each adds less
/// than [`SHARED_FEATURE`] of its own gain once `best` is in, and `best` adds as little
/// once it is in.
fn aliases(
    space: &Space,
    set: &[usize],
    best: &(Candidate, Vec<usize>),
    passing: &[&(Candidate, Vec<usize>)],
) -> Vec<String> {
    let gain_after = |first: &[usize], then: &[usize]| {
        let mut with = set.to_vec();
        with.extend(first);
        let l = space.solve(&with);
        let h = space.heldout(&with);
        space.evidence(&with, &l, &h, then).delta_q
    };
    passing
        .iter()
        .filter(|o| o.0.effect != best.0.effect && o.0.evidence.delta_q >= 0.5 * best.0.evidence.delta_q)
        // A polynomial and its own lower degree are one family, not two explanations.
        .filter(|o| !o.1.iter().all(|p| best.1.contains(p)) && !best.1.iter().all(|p| o.1.contains(p)))
        .filter(|o| gain_after(&best.1, &o.1) < SHARED_FEATURE * o.0.evidence.delta_q)
        .filter(|o| gain_after(&o.1, &best.1) < SHARED_FEATURE * best.0.evidence.delta_q)
        .map(|o| o.0.effect.clone())
        .collect()
}

/// A candidate that met the evidence rules on a sensor no catalogued effect brings to the
/// noise floor (`chasing[sensor]`) is not proposed either: its row says why.
fn not_proposed(candidates: &mut [Candidate], chasing: &[bool]) {
    for c in
        candidates.iter_mut().filter(|c| c.rejected.is_none() && chasing[usize::from(c.sensor == SensorKind::Accel)])
    {
        c.rejected = Some(format!(
            "meets the evidence rules, but no catalogued effect brings the {} residual to the noise floor: tried, not proposed",
            c.sensor
        ));
    }
}

/// Sets aside the steps of a sensor still systematic after them (none is reported as an
/// addition) and lists them as tried, with the residual each leaves, beside the
/// candidates that take residual the left-out runs confirm but not in one size in every
/// run (the nearest catalogued forms of what is there). Returns the list and whether a
/// step was set aside.
fn set_aside(channels: &[ChannelReport], steps: &mut Vec<Step>, first_round: &mut [Candidate]) -> (Vec<String>, bool) {
    let mut tried = Vec::new();
    let last = steps.last().map_or(channels, |st| &st.channels);
    let chasing: Vec<bool> = (0..2).map(|s| last[3 * s..3 * s + 3].iter().any(|c| c.systematic)).collect();
    let mut listed = Vec::new();
    steps.retain(|st| {
        let s = usize::from(st.score.sensor == SensorKind::Accel);
        if chasing[s] {
            tried.push(tried_line(&st.score));
            listed.push(st.score.effect.clone());
        }
        !chasing[s]
    });
    not_proposed(first_round, &chasing);
    let set_aside = !listed.is_empty();
    for c in first_round.iter().filter(|c| {
        chasing[usize::from(c.sensor == SensorKind::Accel)] && noise_choice::confirmed(c) && !listed.contains(&c.effect)
    }) {
        tried.push(format!(
            "{}: would take {:.1} % of the {} residual's whitened χ² and predicts left-out runs, but {}",
            c.effect,
            100.0 * (1.0 - c.rss_after / c.rss_before.max(f64::MIN_POSITIVE)),
            c.sensor,
            c.rejected.as_deref().unwrap_or("is not proposed"),
        ));
    }
    (tried, set_aside)
}

/// Channels whose noise model reaches the whole residual (its σ is bounded there) while a
/// systematic part shows: the model took part of that systematic residual for coloured
/// noise, and every test against it understates the evidence.
fn absorbed(channels: &[ChannelReport], noise: &[NoiseReport]) -> Option<String> {
    let hit: Vec<String> = channels
        .iter()
        .zip(noise)
        .filter(|(c, n)| c.systematic && n.sigma >= 0.98 * c.residual_rms)
        .map(|(c, _)| format!("{} {}", c.sensor, c.axis))
        .collect();
    (!hit.is_empty()).then(|| {
        format!(
            "the noise model of {} takes the whole residual although a systematic part shows: it took part of that \
             residual (a shape locked to the motion beyond the cone harmonics the runs resolve) for coloured noise, \
             so the noise floor shown is an upper bound and every p-value against it understates the evidence; \
             runs of three or more revolutions let the noise be told from what follows the cone",
            hit.join(", ")
        )
    })
}

/// A catalogued effect tried on a sensor it does not explain, with what it left.
fn tried_line(c: &Candidate) -> String {
    format!(
        "{}: left the {} residual's whitened χ² at {:.0} (from {:.0}), still systematic",
        c.effect, c.sensor, c.rss_after, c.rss_before
    )
}

fn describe_leftover(c: &ChannelReport) -> String {
    let (u, k) = c.sensor.display_unit();
    let show = |v: f64| format!("{:.3e}", v * k);
    let at = match &c.worst {
        Some((run, Some(0), a)) => format!("a constant offset of {} {u} in run {run}", show(*a)),
        Some((run, Some(h), a)) => {
            format!("harmonic {h} of the cone frequency, amplitude {} {u}, largest in run {run}", show(*a))
        }
        Some((run, None, a)) => format!("a slow variation of about {} {u} in run {run}", show(*a)),
        None => "no single place".to_string(),
    };
    format!(
        "{} {}: systematic residual RMS {} {u} against a noise floor of {} {u}; it sits at {at}",
        c.sensor,
        c.axis,
        show(c.systematic_rms),
        show(c.noise_floor)
    )
}

/// What the runs cannot identify: the final fit's lost combinations (with the run that
/// would identify each) and candidate effects the runs see only in part.
fn unidentifiable(f: &Fit, candidates: &[Candidate]) -> Vec<String> {
    let mut out: Vec<String> = f
        .gyro
        .unidentifiable
        .iter()
        .chain(&f.accel.unidentifiable)
        .map(|u| {
            format!("{} ({}): {}; held at {}; {}", u.held, u.axis, u.reason, crate::units::show(u.held_at), u.remedy)
        })
        .collect();
    let none: Vec<&str> = candidates.iter().filter(|c| c.added_params == 0).map(|c| c.effect.as_str()).collect();
    if !none.is_empty() {
        out.push(format!("not seen at all by these runs (tried, nothing to estimate): {}", none.join(", ")));
    }
    for c in candidates.iter().filter(|c| c.added_params > 0) {
        let total = find(&c.effect).map_or(0, |e| e.coefficients().len());
        if c.added_params < total {
            out.push(format!(
                "{}: these runs identify {} of its {} coefficients; runs at other rates, cone angles or mounts would identify the rest",
                c.effect, c.added_params, total
            ));
        }
    }
    out
}
