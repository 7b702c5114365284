//! A run recorded on another mount than the manifest declares: the run's residual stands
//! far above the other runs', and one of the 24 signed axis permutations (proper
//! rotations) predicts it, from the model fitted on the other runs, at their level.

use super::select::Evidence;
use super::stand::StandFinding;
use crate::estimate::{EstimateError, Fit, FitOptions, FitRequest, FitRun};
use crate::frames::Mount;
use crate::model::{forward, Model};
use crate::motion::stand::StandMotion;
use crate::session::MotionSpec;
use crate::units::SensorKind;

/// A run's mean squared residual (noise units) over the median run's above which its mount
/// is questioned.
const SUSPECT_RATIO: f64 = 25.0;
/// How much better the best mount must predict the run than the declared one.
const BETTER: f64 = 10.0;
/// Samples per run used to compare mounts (evenly thinned).
const SAMPLES: usize = 4000;

/// Every proper rotation that permutes the axes with signs (24).
pub fn signed_permutations() -> Vec<Mount> {
    let names = ["+x", "-x", "+y", "-y", "+z", "-z"];
    let mut out = Vec::new();
    for a in names {
        for b in names {
            for c in names {
                if let Ok(m) = Mount::parse(&[a, b, c]) {
                    out.push(m);
                }
            }
        }
    }
    out
}

/// Mean squared residual per sample of the six channels in noise units (σ² per channel
/// from the fit), over every `step`-th sample of `run` with its track replaced by `track`.
fn run_score(model: &Model, fit: &Fit, run: &FitRun<'_>, track: &crate::motion::Track, step: usize) -> f64 {
    let terms = [model.terms(SensorKind::Gyro), model.terms(SensorKind::Accel)];
    let values: [Vec<f64>; 2] = SensorKind::BOTH.map(|s| {
        let sf = fit.sensor(s);
        model.terms(s).iter().map(|t| sf.value(&t.term.name).unwrap_or(t.term.nominal)).collect()
    });
    let sigma2: Vec<f64> = SensorKind::BOTH
        .iter()
        .flat_map(|s| fit.sensor(*s).channels.iter().map(|c| (c.sigma * c.sigma).max(f64::MIN_POSITIVE)))
        .collect();
    let moved = FitRun { track, ..*run };
    let (mut acc, mut n) = (0.0, 0usize);
    for k in (0..moved.len()).step_by(step.max(1)) {
        let st = moved.state(k);
        for si in 0..2 {
            let u = forward(&terms[si], &values[si], &st);
            let y = moved.output(SensorKind::BOTH[si], k);
            for ch in 0..3 {
                acc += (y[ch] - u[ch]).powi(2) / sigma2[3 * si + ch];
            }
        }
        n += 1;
    }
    acc / (6 * n.max(1)) as f64
}

fn refit(model: &Model, runs: &[FitRun<'_>], opts: &FitOptions) -> Result<Fit, EstimateError> {
    Ok(crate::estimate::fit(&FitRequest::runs(model, runs).options(*opts))?.fit)
}

/// A run recorded on another mount than declared: (run index, the mount that fits, finding).
pub type WrongMount = (usize, Mount, StandFinding);

/// The conic runs whose declared mount is wrong, and the fit on all runs as declared that
/// judged them (none with fewer than three runs): the diagnosis starts from that fit when
/// no mount is wrong.
pub fn wrong_mounts(
    model: &Model,
    runs: &[FitRun<'_>],
    motions: &[&MotionSpec],
    opts: &FitOptions,
) -> Result<(Vec<WrongMount>, Option<Fit>), EstimateError> {
    if runs.len() < 3 {
        return Ok((Vec::new(), None));
    }
    let all = refit(model, runs, opts)?;
    let scores: Vec<f64> = runs.iter().map(|r| run_score(model, &all, r, r.track, r.len().div_ceil(SAMPLES))).collect();
    let mut sorted = scores.clone();
    let median = crate::stats::median(&mut sorted).unwrap_or(0.0);
    let suspects: Vec<usize> = (0..runs.len())
        .filter(|&i| scores[i] > SUSPECT_RATIO * median.max(f64::MIN_POSITIVE) && runs[i].track.mount().is_some())
        .collect();
    if suspects.is_empty() || suspects.len() * 2 > runs.len() {
        return Ok((Vec::new(), Some(all)));
    }
    let others: Vec<FitRun<'_>> = (0..runs.len()).filter(|i| !suspects.contains(i)).map(|i| runs[i]).collect();
    let rest = refit(model, &others, opts)?;
    let rest_scores: Vec<f64> =
        others.iter().map(|r| run_score(model, &rest, r, r.track, r.len().div_ceil(SAMPLES))).collect();
    let mut sorted = rest_scores;
    let level = crate::stats::median(&mut sorted).unwrap_or(1.0).max(f64::MIN_POSITIVE);
    let mut out = Vec::new();
    for &i in &suspects {
        let run = &runs[i];
        let (Some(declared), MotionSpec::Conic { cone_angle_deg, rate_deg_s, phase_deg }) =
            (run.track.mount(), motions[i])
        else {
            continue;
        };
        let g =
            if run.is_empty() { 9.80665 } else { run.track.at(0).a_m_s2.xyz.iter().map(|x| x * x).sum::<f64>().sqrt() };
        let stand = StandMotion::ideal(cone_angle_deg.to_radians(), rate_deg_s.to_radians(), phase_deg.to_radians());
        let step = run.len().div_ceil(SAMPLES);
        let now = run_score(model, &rest, run, run.track, step);
        let best = signed_permutations()
            .into_iter()
            .map(|m| {
                let tr = run.track.on_stand(stand, g, m.clone());
                (run_score(model, &rest, run, &tr, step), m)
            })
            .min_by(|a, b| a.0.total_cmp(&b.0));
        let Some((score, mount)) = best else { continue };
        if &mount != declared && score * BETTER < now && score < 4.0 * level {
            let show = |m: &Mount| m.names().join(", ");
            let message = format!(
                "the stand: run '{}' was recorded on mount [{}], not [{}] as the manifest says (its residual {:.0}× smaller, at the other runs' level): correct the run's mount in the manifest",
                run.name,
                show(&mount),
                show(declared),
                (now / score).sqrt()
            );
            let evidence = Evidence {
                delta_q: (now - score) * (6 * run.len()) as f64,
                added_params: 0,
                p_value: 0.0,
                delta_bic: f64::NEG_INFINITY,
                heldout_gain: (now - score) * (6 * run.len()) as f64,
                heterogeneity_p: 1.0,
                spread: 0.0,
                delta_q_sensor: [0.0; 2],
                nonlinear: false,
            };
            let finding = StandFinding { id: "mount".into(), values: Vec::new(), message, evidence };
            out.push((i, mount, finding));
        }
    }
    Ok((out, Some(all)))
}
