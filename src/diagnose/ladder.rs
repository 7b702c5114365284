//! The model ladder (`crosscal compare`): the paper's model, the default model, then each
//! effect `diagnose` adds, with residuals, BIC, the reduction against the paper's model and
//! the leave-one-run-out residual, so that an effect that only fits noise shows no held-out
//! gain.

use super::select::Space;
use super::{analyse, diagnose_from, refit, refit_reduced, Diagnosis, NoiseReport, RunMotions};
use crate::estimate::{CoefStatus, EstimateError, Fit, FitOptions, FitRun};
use crate::model::Model;
use crate::units::SensorKind;
use serde::{Deserialize, Serialize};

/// The model at the end of a diagnosis's ladder: the base model plus each added effect.
pub fn ladder_model(base: &Model, d: &Diagnosis) -> Model {
    let mut m = base.clone();
    for s in &d.steps {
        let _ = m.add_effect(&s.effect);
    }
    m
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

fn sensor_rss(f: &Fit, sensor: SensorKind) -> (f64, u64, usize) {
    let sf = f.sensor(sensor);
    let rss = sf.channels.iter().map(|c| c.residual_rms * c.residual_rms * c.n as f64).sum();
    let n = sf.channels.iter().map(|c| c.n).sum();
    let p = sf.coefficients.iter().filter(|c| c.status == CoefStatus::Fitted).count();
    (rss, n, p)
}

fn rung(name: &str, f: &Fit, noise: &[NoiseReport]) -> Rung {
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
    let chans = || SensorKind::BOTH.into_iter().flat_map(|s| f.sensor(s).channels.iter());
    Rung {
        model: name.to_string(),
        params,
        rms: chans().map(|c| c.residual_rms).collect(),
        max: chans().map(|c| c.residual_max).collect(),
        noise_floor: noise.iter().map(|n| n.sigma).collect(),
        bic,
        reduction: Vec::new(),
        heldout_rms: Vec::new(),
        heldout_gain: true,
    }
}

/// Leave-one-run-out residual RMS per channel of `model` from the Grams: the model's free
/// coefficients refitted without each run, the run predicted, its whitened χ² turned back
/// into a residual RMS (noise floor × √(χ²/n)). Coefficients the model holds or lacks are
/// moved from the base fit's values to theirs. None when the model has an effect outside
/// the analysed universe.
fn heldout_of(space: &Space, model: &Model, noise: &[NoiseReport]) -> Option<Vec<f64>> {
    let mut set = Vec::new();
    let mut shift = Vec::new();
    for (i, p) in space.universe.params.iter().enumerate() {
        if !model.has(p.effect) {
            if p.base {
                shift.push((i, p.nominal - p.value));
            }
            continue;
        }
        match model.locate_status(&p.name) {
            Some(crate::model::TermStatus::Fixed(v)) => shift.push((i, v - p.value)),
            _ => set.push(i),
        }
    }
    for e in model.effect_ids().into_iter().chain(model.nonlinear().iter().map(|e| e.effect.id())) {
        if !space.universe.params.iter().any(|p| p.effect == e) {
            return None;
        }
    }
    let q = space.heldout_channels(&set, &shift);
    Some(
        (0..6)
            .map(|c| {
                let n: usize = space.runs.iter().map(|r| r.noise[c].n).sum();
                noise[c].sigma * (q[c].max(0.0) / n.max(1) as f64).sqrt()
            })
            .collect(),
    )
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
    let base = Model::default_model();
    let has_temp = runs.iter().all(|r| r.temp_c.is_some() || r.temp_const_c.is_some());
    // The diagnosis with the stand as a suspect, and the ladder on the motion it corrected:
    // a stand that does not move as declared is not a rung of sensor effects.
    let c = diagnose_from(&base, runs, motions, opts, None)?;
    let suspect = c.stand.clone().filter(super::stand::Suspect::changed);
    let d = super::with_stand::finish(c, &base, runs, motions);
    let tracks = suspect.as_ref().map(|s| s.tracks(runs));
    let runs: Vec<FitRun<'_>> = match &tracks {
        Some(t) => runs.iter().zip(t).map(|(r, t)| FitRun { track: t, ..*r }).collect(),
        None => runs.to_vec(),
    };
    let owned = suspect.as_ref().map(|s| s.motions(motions));
    let now: Vec<&crate::session::MotionSpec> = match &owned {
        Some(m) => m.iter().collect(),
        None => motions.to_vec(),
    };
    let runs = runs.as_slice();
    let first = analyse(&base, refit(&base, runs, opts)?, runs, &now, has_temp);
    let (space, base_fit) = (first.space, first.base_fit);
    let mut models = vec![("paper (eqs. 3-4)".to_string(), Model::paper()), ("default".to_string(), base.clone())];
    let mut m = base;
    for st in &d.steps {
        let _ = m.add_effect(&st.effect);
        models.push((format!("+ {}", st.effect), m.clone()));
    }
    for effects in extra {
        // Effects the ladder already has (the diagnosis added them) are not added twice; a
        // rung with nothing new is not repeated.
        let new: Vec<&String> = effects.iter().filter(|e| !m.effect_ids().contains(&e.as_str())).collect();
        if new.is_empty() {
            continue;
        }
        for e in &new {
            let _ = m.add_effect(e);
        }
        models.push((format!("+ {}", new.iter().map(|e| e.as_str()).collect::<Vec<_>>().join(" + ")), m.clone()));
    }
    let mut rungs = Vec::with_capacity(models.len());
    let mut notes = Vec::new();
    // The default model's fit and the diagnosis's final one are already at hand.
    let last_step = 1 + d.steps.len();
    for (i, (name, model)) in models.iter().enumerate() {
        let f = match i {
            1 => base_fit.clone(),
            _ if i == last_step => d.final_fit.clone(),
            _ => refit_reduced(model, runs, opts, &mut notes)?,
        };
        let mut r = rung(name, &f, &d.noise);
        if runs.len() > 1 {
            r.heldout_rms = heldout_of(&space, model, &d.noise).unwrap_or_else(|| r.rms.clone());
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
