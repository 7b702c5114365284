//! The analysis of a session around a fitted model: the noise side (each run's noise
//! statistics, the pooled AR models, the slow noise the fit measured) and the whitened
//! Grams of every run ([`super::space`]), with the noise report drawn from them.

use super::select::Space;
use super::{picture, run_span, space, NoiseReport, RunMotions};
use crate::estimate::{Fit, FitRun};
use crate::model::Model;
use crate::units::{SensorKind, AXES};
use rayon::prelude::*;

/// The analysed session: the base fit, the feature space and the runs' names.
pub(super) struct Analysis {
    pub(super) base_fit: Fit,
    pub(super) space: Space,
    pub(super) names: Vec<String>,
}

/// The noise side of an analysis (module documentation, steps 1–2): each run's noise
/// statistics, the session's pooled AR models, and the slow noise the fit measured
/// (restricted likelihood on the runs' block means, with `FitOptions::slow_noise`: a
/// random effect on each run's slow basis; without it, none) over the session's length.
pub(super) struct NoiseStage {
    pub(super) stats: Vec<space::RunNoiseStats>,
    pub(super) pooled: Vec<crate::stats::ArModel>,
    pub(super) slow: Vec<Option<crate::estimate::slow::SlowNoise>>,
    pub(super) span_s: f64,
}

impl NoiseStage {
    /// The stage around `model` (its user effects bound at the fit's parameters) and its
    /// fit (in parallel over the runs; each run's residual lives only while its
    /// statistics are drawn).
    pub(super) fn new(model: &Model, base_fit: &Fit, runs: &[FitRun<'_>], motions: &RunMotions<'_>) -> Self {
        let stats: Vec<space::RunNoiseStats> = (0..runs.len())
            .into_par_iter()
            .map(|i| space::run_noise(&runs[i], motions[i], picture::run_residual(model, base_fit, &runs[i])))
            .collect();
        let pooled = space::pooled_noise(&stats);
        let span_s: f64 = runs.iter().map(run_span).sum();
        let slow = (0..6).map(|c| base_fit.slow_noise(c)).collect();
        Self { stats, pooled, slow, span_s }
    }
}

/// Analyses each run around a fitted model (in parallel; each run's residual lives only
/// while its Grams are built).
pub(super) fn analyse(
    model: &Model,
    base_fit: Fit,
    runs: &[FitRun<'_>],
    motions: &RunMotions<'_>,
    has_temp: bool,
) -> Analysis {
    analyse_from(model, base_fit, runs, motions, has_temp, None, None)
}

/// [`analyse`], with the noise side already drawn (`stage`: [`NoiseStage::new`] of the same
/// model, fit, runs and motions) or drawn here (None), and after `previous`, an analysis of
/// the same runs and motions around another model (the climb's step before): a sensor whose
/// part of the model, fit and candidates is unchanged ([`space::SensorKey`]: an effect of
/// the other sensor was added) keeps its Grams in every run whose noise models for it are
/// unchanged, instead of drawing them again (the same numbers).
pub(super) fn analyse_from(
    model: &Model,
    base_fit: Fit,
    runs: &[FitRun<'_>],
    motions: &RunMotions<'_>,
    has_temp: bool,
    stage: Option<NoiseStage>,
    previous: Option<&Analysis>,
) -> Analysis {
    // A user effect's linear part at the parameters the fit estimated (a knee at its fitted
    // rate): the residual and the Grams are then those of the fitted model.
    let bound = crate::estimate::bound_at_fit(model, &base_fit);
    let model = &bound;
    let universe = space::Universe::new(model, &base_fit, has_temp);
    let NoiseStage { stats, pooled, slow, span_s } =
        stage.unwrap_or_else(|| NoiseStage::new(model, &base_fit, runs, motions));
    let previous = previous.filter(|p| p.space.runs.len() == runs.len());
    let same = [0, 1].map(|si| previous.filter(|p| p.space.universe.sensor_key(si) == universe.sensor_key(si)));
    let gram_of = |i: usize, st| {
        let r = picture::run_residual(model, &base_fit, &runs[i]).0;
        let kept = same.map(|p| p.map(|p| &p.space.runs[i]));
        space::run_gram(&universe, model, &base_fit, &runs[i], st, &pooled, &r, (slow.as_slice(), span_s), kept)
    };
    let grams: Vec<space::RunGram> = stats.into_par_iter().enumerate().map(|(i, st)| gram_of(i, st)).collect();
    let names = runs.iter().map(|r| r.name.to_string()).collect();
    let mut space = Space::new(universe, grams);
    space.slow = slow;
    Analysis { base_fit, space, names }
}

/// The noise floor σ of channel `c` over runs whose noise models are `runs`: the root of
/// the sample-weighted mean of their marginal variances.
pub(super) fn floor_sigma<'a>(runs: impl Iterator<Item = &'a [space::RunNoise]>, c: usize) -> f64 {
    let (mut n, mut var) = (0.0, 0.0);
    for rn in runs {
        let w = rn[c].n as f64;
        n += w;
        var += w * rn[c].ar.marginal_var;
    }
    (var / f64::max(n, 1.0)).sqrt()
}

/// The noise model per channel, pooled over runs.
pub(super) fn noise_reports(space: &Space) -> Vec<NoiseReport> {
    (0..6)
        .map(|c| {
            let (mut n, mut var, mut innov, mut lag1, mut order) = (0.0, 0.0, 0.0, 0.0, 0);
            for rg in &space.runs {
                let rn = &rg.noise[c];
                let w = rn.n as f64;
                n += w;
                var += w * rn.ar.marginal_var;
                innov += w * rn.ar.innovation_var;
                lag1 += w * lag_one(&rn.ar);
                order = order.max(rn.ar.order());
            }
            let n = n.max(1.0);
            NoiseReport {
                sensor: if c < 3 { SensorKind::Gyro } else { SensorKind::Accel },
                axis: AXES[c % 3],
                sigma: floor_sigma(space.runs.iter().map(|rg| rg.noise.as_slice()), c),
                lag1: lag1 / n,
                ar_order: order,
                colour: if innov > 0.0 { var / innov } else { 1.0 },
                bias_instability: space.slow.get(c).copied().flatten().map_or(0.0, |s| s.bias_instability),
                random_walk: space.slow.get(c).copied().flatten().map_or(0.0, |s| s.random_walk),
            }
        })
        .collect()
}

/// Lag-one autocorrelation of an AR model by simulating its impulse response (exact to
/// 1e-6 for stable models): ρ₁ = Σ ψ_k ψ_{k+1} / Σ ψ_k².
fn lag_one(ar: &crate::stats::ArModel) -> f64 {
    if ar.phi.is_empty() {
        return 0.0;
    }
    let mut psi = vec![1.0];
    for k in 1..4096 {
        let v: f64 = ar.phi.iter().enumerate().filter(|(i, _)| *i < k).map(|(i, p)| p * psi[k - 1 - i]).sum();
        psi.push(v);
        if k > 64 && v.abs() < 1e-9 {
            break;
        }
    }
    let num: f64 = psi.windows(2).map(|w| w[0] * w[1]).sum();
    let den: f64 = psi.iter().map(|v| v * v).sum();
    num / den
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::estimate::{fit_runs, tracks, FitOptions};
    use crate::session::MotionSpec;

    /// After an effect of one sensor is added, the analysis keeps the other sensor's Grams
    /// (a mark set in the earlier analysis's shows through) and draws its own again; every
    /// Gram equals the one a fresh analysis draws.
    #[test]
    fn an_analysis_after_an_effect_keeps_the_other_sensors_grams() {
        let mut cfg = crate::simulate::SimConfig::paper();
        cfg.gyro_noise_deg_s = 0.002;
        cfg.accel_noise_g = 2e-5;
        let s = cfg.generate();
        let tr = tracks(&s, &crate::motion::DerivativeConfig::default());
        let runs = fit_runs(&s, &tr);
        let motions: Vec<&MotionSpec> = s.runs.iter().map(|r| &r.spec.motion).collect();
        let opts = FitOptions::default();
        let base = Model::default_model();
        let fitted = |m: &Model| crate::diagnose::refit(m, &runs, &opts).expect("fit");
        for (effect, kept) in [("gyro-cubic", 3..6), ("accel-cubic", 0..3)] {
            let mut before = analyse(&base, fitted(&base), &runs, &motions, false);
            let mark = 1e300;
            before.space.runs[0].gram[kept.start][(0, 0)] = mark;
            let mut m = base.clone();
            m.add_effect(effect).expect("a catalogue effect");
            let fresh = analyse(&m, fitted(&m), &runs, &motions, false);
            let after = analyse_from(&m, fitted(&m), &runs, &motions, false, None, Some(&before));
            assert_eq!(after.space.runs[0].gram[kept.start][(0, 0)].to_bits(), mark.to_bits(), "{effect}: not kept");
            for (i, (a, f)) in after.space.runs.iter().zip(&fresh.space.runs).enumerate() {
                for c in 0..6 {
                    if i == 0 && c == kept.start {
                        continue;
                    }
                    assert_eq!(a.gram[c], f.gram[c], "{effect}: run {i} channel {c}");
                    if !kept.contains(&c) {
                        assert_ne!(a.gram[c], before.space.runs[i].gram[c], "{effect}: channel {c} kept");
                    }
                }
            }
        }
    }
}
