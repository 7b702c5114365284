//! The diagnosis with the stand as a suspect ([`super::stand`]): wrong mounts first, then
//! the climb with a stand check at every step; each time a stand group explains the
//! residual better than any sensor effect, the motion is corrected and the diagnosis
//! starts again on it.

use super::analysis::NoiseStage;
use super::select::Space;
use super::{analyse, conclude, refit, stand, Analysis, ChannelReport, Concluded, Diagnosis, RunMotions, Step};
use crate::estimate::{EstimateError, Fit, FitOptions, FitRun};
use crate::model::Model;
use crate::session::MotionSpec;

/// Stand groups found at most (each restarts the diagnosis on the corrected motion).
const MAX_STAND_FINDINGS: usize = 8;

/// Samples above which the stand is first looked for on every k-th sample (about
/// [`PRE_SAMPLES`] of them): each group found restarts the diagnosis, which on the reduced
/// runs costs a k-th; the diagnosis on every sample then starts from the motion so
/// corrected, with the groups judged again there ([`stand::Suspect::rejudge`]) and
/// estimated again at its end, so that the values and standard errors reported are those
/// of every sample.
const PRE_FROM: usize = 200_000;

/// Samples the reduced runs of the first look at the stand hold, about.
const PRE_SAMPLES: usize = 25_000;

/// The stand check of a climb: the suspect and the runs with their declared motion.
pub(super) struct StandCheck<'s, 'r, 'a> {
    suspect: &'s mut stand::Suspect,
    declared: &'r [FitRun<'a>],
    /// The systems of the last check that found no new group, while the climb is still
    /// around the model and analysis it made them on: the final estimate's first step.
    last: Option<stand::Systems>,
    /// The carried groups' systems, built to judge them before the analysis was drawn
    /// (around the same model, fit and noise models as the first check): that check's.
    judged: Option<stand::Systems>,
    /// The model the first look reached, its nonlinear parameters started near where the
    /// look's fit put them ([`Model::start_near`]): an effect the climb adds that it has
    /// starts its search there.
    near: Option<&'r Model>,
}

/// The runs on the motion a stand suspect now believes: their tracks and motions.
struct Believed {
    tracks: Vec<crate::motion::Track>,
    motions: Vec<MotionSpec>,
}

impl Believed {
    fn new(suspect: &stand::Suspect, runs: &[FitRun<'_>], motions: &RunMotions<'_>) -> Self {
        Self { tracks: suspect.tracks(runs), motions: suspect.motions(motions) }
    }

    /// `runs` on the believed tracks.
    fn runs<'a>(&'a self, runs: &[FitRun<'a>]) -> Vec<FitRun<'a>> {
        runs.iter().zip(&self.tracks).map(|(r, t)| FitRun { track: t, ..*r }).collect()
    }

    /// The believed motions, as the diagnosis takes them.
    fn motions(&self) -> Vec<&MotionSpec> {
        self.motions.iter().collect()
    }
}

/// The diagnosis `c` with its last parts worked out, once it is the answer (the automatic
/// slow-noise mode concludes two and keeps one): the per-run disagreements, on the motion
/// the diagnosis kept, and the shapes of what no effect explains (module `shape`; nothing
/// when no channel is left systematic), on the motion its stand suspect believes at the end
/// (the declared motion without one).
pub(super) fn finish(c: Concluded, model: &Model, runs: &[FitRun<'_>], motions: &RunMotions<'_>) -> Diagnosis {
    let Concluded { mut d, stand, compare } = c;
    if let Some((fit, on, opts)) = compare {
        d.disagreements = match on {
            Some(s) => super::per_run_disagreements(model, &fit, &Believed::new(&s, runs, motions).runs(runs), &opts),
            None => super::per_run_disagreements(model, &fit, runs, &opts),
        };
    }
    let last = d.steps.last().map_or(&d.channels, |s| &s.channels);
    let remaining: Vec<&ChannelReport> = last.iter().filter(|c| c.systematic).collect();
    if remaining.is_empty() {
        return d;
    }
    let shapes = match &stand {
        Some(s) => {
            let now = Believed::new(s, runs, motions);
            super::draw_shapes(model, &d.steps, &d.final_fit, &now.runs(runs), &now.motions(), &remaining, &d.noise)
        }
        None => super::draw_shapes(model, &d.steps, &d.final_fit, runs, motions, &remaining, &d.noise),
    };
    d.shapes = shapes;
    d
}

/// The noise model of every run and channel of an analysis, with each channel's dispersion
/// (its residual's mean square over the noise model's variance, at least 1).
fn noise_models(a: &Analysis) -> Vec<stand::RunNoiseModel> {
    let space: &Space = &a.space;
    let dispersion =
        dispersion(&a.base_fit, |c| super::analysis::floor_sigma(space.runs.iter().map(|rg| rg.noise.as_slice()), c));
    space
        .runs
        .iter()
        .map(|rg| stand::RunNoiseModel {
            ar: rg.noise.iter().map(|n| n.ar.clone()).collect(),
            basis: rg.run_basis,
            slow: rg.slow.clone(),
            dispersion,
        })
        .collect()
}

/// [`noise_models`] of the analysis of `model` fitted as `fit` on `runs`, without its Grams
/// (the noise side only, [`NoiseStage`]): the same numbers, for judging carried stand groups
/// before the whole analysis is drawn, with the stage (the analysis then starts from it).
fn noise_alone(
    model: &Model,
    fit: &Fit,
    runs: &[FitRun<'_>],
    motions: &[&MotionSpec],
) -> (Vec<stand::RunNoiseModel>, NoiseStage) {
    let bound = crate::estimate::bound_at_fit(model, fit);
    let stage = NoiseStage::new(&bound, fit, runs, motions);
    let noises: Vec<Vec<super::space::RunNoise>> =
        stage.stats.iter().map(|s| super::space::run_noises(s, &stage.pooled)).collect();
    let dispersion = dispersion(fit, |c| super::analysis::floor_sigma(noises.iter().map(Vec::as_slice), c));
    let models = runs
        .iter()
        .zip(&stage.stats)
        .zip(noises)
        .map(|((run, st), noise)| stand::RunNoiseModel {
            ar: noise.into_iter().map(|n| n.ar).collect(),
            basis: st.basis,
            slow: super::space::run_slow(run, st, (&stage.slow, stage.span_s)),
            dispersion,
        })
        .collect();
    (models, stage)
}

/// Each channel's dispersion: the fit's residual mean square over the noise floor
/// `sigma(c)` squared, at least 1.
fn dispersion(fit: &Fit, sigma: impl Fn(usize) -> f64) -> [f64; 6] {
    std::array::from_fn(|c| {
        let sensor = crate::units::SensorKind::BOTH[c / 3];
        let rms = fit.sensor(sensor).channels.get(c % 3).map_or(0.0, |ch| ch.residual_rms);
        let sigma = sigma(c);
        if sigma > 0.0 && rms.is_finite() {
            (rms / sigma).powi(2).max(1.0)
        } else {
            1.0
        }
    })
}

impl StandCheck<'_, '_, '_> {
    /// At one step of the climb around `current` (analysed in `a` on `runs`, the corrected
    /// motion): whether a stand group beats every sensor candidate (best ΔBIC
    /// `sensor_bic`); if so it is estimated and the motion corrected (true).
    pub(super) fn check(
        &mut self,
        current: &Model,
        a: &Analysis,
        runs: &[FitRun<'_>],
        sensor_bic: Option<f64>,
        opts: &FitOptions,
    ) -> Result<bool, EstimateError> {
        let noise = noise_models(a);
        // Groups carried from a whole diagnosis, at the first check where a sensor effect
        // follows: judged again on their own columns (`Suspect::carried_over`).
        let judged = self.judged.take();
        if self.suspect.carried() && sensor_bic.is_some() {
            let sys = judged.unwrap_or_else(|| self.suspect.accepted_systems(current, &a.base_fit, runs, &noise));
            let dropped = self.suspect.rejudge(&sys);
            self.last = Some(sys);
            return Ok(dropped);
        }
        // The carried groups' systems serve when they have every column (a search was
        // expected here: `Suspect::expecting_search`); judged again on them, the groups pass.
        let sys = match judged {
            Some(sys) if sys.complete() => sys,
            _ => self.suspect.systems(current, &a.base_fit, runs, &noise),
        };
        if self.suspect.carried() && self.suspect.rejudge(&sys) {
            return Ok(true);
        }
        match self.suspect.pick(&sys, sensor_bic) {
            Some(pick) => {
                // The dispersion decides whether a group is evidence; the estimate weighs each
                // channel by its noise model alone (the misfit it had is what the group removes).
                // The unit's nonlinear parameters are held where the fit put them: the
                // estimate refits the model at each of its steps, and a search on every
                // sample at each (a dead zone's thresholds) would cost far more than the
                // stand's small change of motion moves them.
                let held = crate::estimate::held_at_fit(current, &a.base_fit);
                self.suspect.accept(pick, &held, self.declared, &noise, opts)
            }
            None => {
                self.last = Some(sys);
                Ok(false)
            }
        }
    }

    /// The first look's model, whose near starts an effect the climb adds takes
    /// ([`Model::starts_from`]).
    pub(super) fn near(&self) -> Option<&Model> {
        self.near
    }

    /// The stand as the check now believes it (the motion the climb is on).
    pub(super) fn believed(&self) -> stand::Suspect {
        self.suspect.clone()
    }

    /// The model or its analysis moved on from the last check's (an effect was added, or
    /// the analysis was drawn again): its systems no longer start the final estimate.
    pub(super) fn moved_on(&mut self) {
        self.last = None;
    }
}

/// The stand's findings at the end of a diagnosis (empty without a stand check or when the
/// motion is as declared), around the model at the end of the ladder.
pub(super) fn findings(
    check: Option<StandCheck<'_, '_, '_>>,
    opts: &FitOptions,
    model: &Model,
    steps: &[Step],
    final_fit: &Fit,
    runs: &[FitRun<'_>],
    a: &Analysis,
) -> Vec<stand::StandFinding> {
    match check {
        Some(sc) if sc.suspect.changed() => {
            let mut m = model.clone();
            for s in steps {
                let _ = m.add_effect(&s.effect);
            }
            // Nonlinear parameters held at the final fit's values (as in the check above).
            let m = crate::estimate::held_at_fit(&m, final_fit);
            let noise = noise_models(a);
            // The groups estimated again under the final noise model, so that their values
            // are the estimates whose standard errors the final systems give; if that fails
            // the values of the climb stand (on the final residual's systems).
            match sc.suspect.polish(&m, sc.declared, &noise, opts, sc.last) {
                Ok(Some(sys)) => sc.suspect.findings(&sys, &a.names),
                Ok(None) => sc.suspect.mounts(),
                Err(_) => sc.suspect.findings(&sc.suspect.systems(&m, final_fit, runs, &noise), &a.names),
            }
        }
        _ => Vec::new(),
    }
}

/// The runs of the first look at the stand: every k-th sample, about [`PRE_SAMPLES`].
fn first_look_copy(runs: &[FitRun<'_>]) -> super::reduced::Reduced {
    super::reduced::Reduced::new(runs, super::reduced::step_for(runs, PRE_SAMPLES), |_| false)
}

/// The first look at the stand on reduced runs (every k-th sample of a large session): the
/// mounts, then the stand check on the declared model's residual. When it finds a stand
/// group, the climb runs on the reduced runs with a stand check at every step (each group
/// found restarts it, at a k-th of the cost), and its suspect is the answer: its report is
/// not kept (its numbers are those
/// of a k-th of the samples). When it finds none, the look ends there: a group that shows
/// only beside a sensor effect is found on every sample.
fn first_look(
    mut suspect: stand::Suspect,
    model: &Model,
    runs: &[FitRun<'_>],
    motions: &RunMotions<'_>,
    opts: &FitOptions,
    has_temp: bool,
) -> Result<(stand::Suspect, Option<Model>), EstimateError> {
    let (wrong, fit) = super::mount::wrong_mounts(model, runs, motions, opts)?;
    for (i, mount, finding) in wrong {
        suspect.set_mount(i, mount, finding);
    }
    let now = Believed::new(&suspect, runs, motions);
    let moved = now.runs(runs);
    let fit = match fit {
        Some(f) if !suspect.changed() => f,
        _ => refit(model, &moved, opts)?,
    };
    let a = analyse(model, fit, &moved, &now.motions(), has_temp);
    let (scored, exact) = super::score(&a.space, &a.space.base_set());
    if exact.iter().all(|e| *e) {
        return Ok((suspect, None));
    }
    let sensor_bic = scored.iter().filter(|c| c.0.rejected.is_none()).map(|c| c.0.delta_bic).reduce(f64::min);
    let mut check = StandCheck { suspect: &mut suspect, declared: runs, last: None, judged: None, near: None };
    if !check.check(model, &a, &moved, sensor_bic, opts)? {
        return Ok((suspect, None));
    }
    // The climb on the corrected motion; each group found restarts it from the model it
    // reached (only the suspect is kept: the diagnosis on every sample climbs from the
    // start), whose nonlinear parameters are searched again (held where the fit on the
    // motion before the correction put them, their misfit would be there for a stand
    // group to take).
    let mut reached = model.clone();
    for _ in 0..MAX_STAND_FINDINGS {
        let now = Believed::new(&suspect, runs, motions);
        let moved = now.runs(runs);
        let a = analyse(&reached, refit(&reached, &moved, opts)?, &moved, &now.motions(), has_temp);
        let mut check = StandCheck { suspect: &mut suspect, declared: runs, last: None, judged: None, near: None };
        let (steps, _, a, restart) =
            super::climb(a, &reached, &moved, &now.motions(), opts, has_temp, &mut Vec::new(), Some(&mut check))?;
        let last = check.last.take();
        for st in &steps {
            let _ = reached.add_effect(&st.effect);
        }
        // Searched again on the corrected motion, the nonlinear parameters start near where
        // the fit before the correction put them.
        reached = crate::estimate::near_fit(&reached, &a.base_fit);
        if restart {
            continue;
        }
        // The groups estimated again around the model at the end of the climb, as at the end
        // of a diagnosis (`findings`): the diagnosis on every sample starts from the motion
        // the reduced runs know best.
        let held = crate::estimate::held_at_fit(&reached, &a.base_fit);
        let before = suspect.clone();
        if suspect.polish(&held, runs, &noise_models(&a), opts, last).is_err() {
            suspect = before;
        }
        return Ok((suspect, Some(reached)));
    }
    Err(EstimateError::NotConverged("the stand kept explaining more on the reduced runs".into()))
}

/// Diagnoses `model` on `runs` with the stand as a suspect, with the suspect at the end
/// (None when the diagnosis fell back to the declared motion); [`finish`] completes it.
/// A suspect carried from another diagnosis ([`stand::Suspect::carried_over`]) keeps its
/// mounts and starts from its motion.
pub(super) fn diagnose(
    mut suspect: stand::Suspect,
    model: &Model,
    runs: &[FitRun<'_>],
    motions: &RunMotions<'_>,
    opts: &FitOptions,
    has_temp: bool,
) -> Result<Concluded, EstimateError> {
    let total: usize = runs.iter().map(FitRun::len).sum();
    let mut near = None;
    if !suspect.carried() && total > PRE_FROM {
        let copy = first_look_copy(runs);
        // When the first look cannot be had, the diagnosis on every sample looks for itself.
        if let Ok((found, reached)) = first_look(suspect.clone(), model, &copy.runs(runs), motions, opts, has_temp) {
            suspect = found.looked_over();
            near = reached;
        }
    }
    let mut as_declared = None;
    if !suspect.carried() {
        let (wrong, fit) = super::mount::wrong_mounts(model, runs, motions, opts)?;
        as_declared = fit;
        for (i, mount, finding) in wrong {
            suspect.set_mount(i, mount, finding);
        }
    }
    // Carried groups are first judged again on the first look's every k-th sample: one
    // that fails there goes back to its labels before any work on every sample is done
    // for it (the survivors are judged again there).
    if suspect.carries_groups() && total > PRE_FROM {
        let copy = first_look_copy(runs);
        let reduced = copy.runs(runs);
        let now = Believed::new(&suspect, &reduced, motions);
        let moved = now.runs(&reduced);
        let fit = refit(model, &moved, opts)?;
        let (noise, _) = noise_alone(model, &fit, &moved, &now.motions());
        let sys = suspect.accepted_systems(model, &fit, &moved, &noise);
        if suspect.judge_carried(&sys) {
            suspect = suspect.carried_over();
        }
    }
    for _ in 0..=MAX_STAND_FINDINGS {
        let now = Believed::new(&suspect, runs, motions);
        let moved = now.runs(runs);
        // While the motion is as declared, the mount check's fit is this fit.
        let fit = match as_declared.take() {
            Some(f) if !suspect.changed() => f,
            _ => refit(model, &moved, opts)?,
        };
        // Carried groups are judged again before the analysis is drawn: one that no longer
        // passes goes back to its labels, and the analysis is drawn on the motion without
        // it. The first check judges the groups kept again, on the same numbers.
        let (mut judged, mut stage) = (None, None);
        if suspect.carries_groups() {
            let (noise, drawn) = noise_alone(model, &fit, &moved, &now.motions());
            let sys = suspect.judging_systems(model, &fit, &moved, &noise);
            if suspect.judge_carried(&sys) {
                continue;
            }
            (judged, stage) = (Some(sys), Some(drawn));
        }
        let a = super::analysis::analyse_from(model, fit, &moved, &now.motions(), has_temp, stage, None);
        let check = StandCheck { suspect: &mut suspect, declared: runs, last: None, judged, near: near.as_ref() };
        if let Some(c) = conclude(a, model, &moved, &now.motions(), opts, has_temp, Some(check))? {
            return Ok(Concluded { stand: Some(suspect), ..c });
        }
    }
    // The stand kept explaining more (a residual no stand group removes, e.g. a unit outside
    // its profile's temperature range): the diagnosis of the declared motion, without the
    // stand as a suspect, is the honest answer.
    let a = analyse(model, refit(model, runs, opts)?, runs, motions, has_temp);
    conclude(a, model, runs, motions, opts, has_temp, None)?.ok_or_else(|| {
        EstimateError::NotConverged(format!(
            "the stand kept explaining more after {MAX_STAND_FINDINGS} corrections; check the runs' labels"
        ))
    })
}
