//! The stand as a suspect: when the stand did not move as the manifest says, the residual
//! it leaves is explained by the stand's own parameters, not by the unit.
//!
//! Each conic run's true motion is an imperfect stand ([`crate::motion::stand`]) around its
//! label: per run a cone angle, a rate (relative), a starting phase and a drift of the rate
//! (relative per second from the run's first sample); common to the runs
//! a base tilt (two angles), a once- and a twice-per-revolution speed ripple (cos, sin),
//! a wobble of the cone axis (cos, sin) and the Earth's rate in base axes (three; its
//! vertical part also turns static poses' gyro outputs along their up, and each static pose
//! has its own horizontal part, the heading being unknown). These parameters are
//! linearised around the current motion: the column of a parameter is the change of the
//! fitted model's prediction per unit change of it (a forward difference of the true
//! inputs pushed through the model). The columns, the model's own free coefficients and
//! the residual are prewhitened with the diagnosis's noise model (the same AR filter per
//! run and channel as [`super::space`]), and the stand's *groups* — cone angle (common or
//! per run), rate (common or per run), rate drift (common or per run), phase per run, base tilt, ripple ×1, ripple ×2,
//! cone wobble, Earth rotation — are judged by the rules of [`super::select`] (χ² gain
//! with p and ΔBIC, gain on left-out runs). A group that passes, is physically plausible,
//! takes a material share of the χ² the noise does not explain (`MIN_SHARE`) and beats
//! the best sensor candidate on BIC is estimated (Gauss–Newton on the whole motion); if the
//! estimate stays plausible the diagnosis starts again on the corrected motion, else the
//! motion is kept and the group not tried again. At the end every group found is reported
//! with its value ± standard error, from the joint generalised least-squares solution of
//! all of them with the model's coefficients; a parameter that solution cannot separate
//! from the model's coefficients (`SEPARABLE`) gets no value.

use super::algebra::{left_information, pinv_sym, Lsq};
use super::knobs::{follows, knob, Dir, Knobs, BLOCK, KNOBS, PER_RUN};
use super::select::Evidence;
use crate::estimate::{CoefStatus, EstimateError, Fit, FitOptions, FitRequest, FitRun};
use crate::frames::Mount;
use crate::model::{Model, Predictor, State, TermRef};
use crate::motion::stand::{AddRate, StandMotion};
use crate::motion::Track;
use crate::session::MotionSpec;
use crate::stats::gram::WhitenedGram;
use crate::stats::ArModel;
use crate::units::SensorKind;
use nalgebra::{DMatrix, DVector};
use rayon::prelude::*;
use std::sync::Arc;

/// The first common knob (tilt); knobs before it belong to one run.
const COMMON: usize = PER_RUN;
/// Gauss–Newton steps on an accepted group.
const MAX_STEPS: usize = 8;
/// Standard errors within which a Gauss–Newton step ends the estimate: the outputs move
/// linearly with a stand parameter over far more than that (its standard error is a tiny
/// share of the scale on which they curve: 1e-6° of a 10° cone), so the point such a step
/// lands on is the solution to far below its standard error, and a step to confirm it
/// (a refit and a pass over every sample) would change nothing reported.
const LINEAR_WITHIN: f64 = 10.0;
/// The Earth's rotation rate, rad/s.
const EARTH_RAD_S: f64 = 7.292_115e-5;
/// Share of the whitened χ² the noise does not explain that a stand group must take to be
/// the explanation ([`Systems::material`]).
const MIN_SHARE: f64 = 0.1;
/// Share of a parameter's own information that must be left beyond every other column for
/// it to be told apart (the fit's `--stand` holds a parameter below the same share).
const SEPARABLE: f64 = 1e-6;

pub use super::stand_words::{StandFinding, StandValue};

mod rejudge;
mod report;

/// A run's noise model as the stand's systems weigh it: the AR filter per channel, and the
/// slow noise's random effect on the run's basis ([`super::slow`]; `slow[c]` empty or zero
/// without one).
#[derive(Clone)]
pub struct RunNoiseModel {
    /// Per channel AR model.
    pub ar: Vec<ArModel>,
    /// The run's basis functions.
    pub basis: super::space::RunBasis,
    /// Per channel the covariance of the basis coefficients under the slow noise.
    pub slow: Vec<DMatrix<f64>>,
    /// Per channel the dispersion φ ≥ 1: the residual's variance over the noise model's
    /// (quasi-likelihood). A channel whose misfit nothing explains yet (a turn-on bias in
    /// each run) is not held to its noise floor: its χ² counts 1/φ, so that a stand term
    /// taking a sliver of a large unexplained misfit is not evidence, while one that
    /// explains the misfit still is (its gain is most of φ·n).
    pub dispersion: [f64; 6],
}

/// What the stand may be doing in one run (a few per session: the size difference between
/// the variants does not matter).
#[derive(Debug, Clone)]
#[allow(clippy::large_enum_variant)]
enum RunStand {
    /// A conic run: its label, the motion now believed, and whether the stand logs its
    /// angle there (its rate, drift and ripple are then the log's).
    Conic { declared: StandMotion, now: StandMotion, mount: Mount, logs: bool },
    /// A static pose: its up in sensor axes and the Earth's rate now believed (sensor axes).
    Static { up: [f64; 3], earth: [f64; 3] },
    /// Anything else (no stand parameters).
    Other,
}

/// One parameter of a group: a combination of global stand parameters.
type Combo = Vec<(usize, f64)>;

/// A stand group.
#[derive(Debug, Clone)]
struct Group {
    id: &'static str,
    params: Vec<Combo>,
}

/// The stand's parameters in a session and what has been found so far.
#[derive(Debug, Clone)]
pub struct Suspect {
    runs: Vec<RunStand>,
    g_m_s2: f64,
    /// Per run: (global stand index, direction) of its local stand columns.
    locals: Vec<Vec<(usize, Dir)>>,
    /// Number of global stand parameters.
    width: usize,
    groups: Vec<Group>,
    accepted: Vec<(usize, Evidence)>,
    /// Groups whose estimate on the whole motion left what a stand does (picked on the
    /// linearisation around the labels, then run off to an implausible value): not tried again.
    refused: Vec<usize>,
    mounts: Vec<StandFinding>,
    /// How its groups were carried from another diagnosis ([`rejudge::Carry`]).
    carry: rejudge::Carry,
}

/// The whitened system of one run (global stand parameters after the model's).
#[derive(Clone)]
struct Fold {
    g: DMatrix<f64>,
    b: DVector<f64>,
    yy: f64,
}

/// The systems of every run around one model and fit.
pub struct Systems {
    folds: Vec<Fold>,
    total: Fold,
    /// The total without the channels' dispersion: the scale the sensor candidates' ΔBIC
    /// is on, for ranking a stand group against them.
    raw: Fold,
    base: usize,
    samples: usize,
    /// Every stand parameter has its columns (not only the accepted groups').
    complete: bool,
}

impl Suspect {
    /// The stand of the runs (`motions[i]` is run i's declared motion). None when no run
    /// has stand parameters.
    pub fn new(runs: &[FitRun<'_>], motions: &[&MotionSpec]) -> Option<Self> {
        let mut out = Vec::with_capacity(runs.len());
        let mut g_m_s2 = 0.0;
        let mut earth_declared = false;
        for (run, m) in runs.iter().zip(motions) {
            let a = if run.is_empty() { [f64::NAN; 3] } else { run.track.at(0).a_m_s2.xyz };
            let norm = (a[0] * a[0] + a[1] * a[1] + a[2] * a[2]).sqrt();
            let kind = match (m, run.track.mount()) {
                (MotionSpec::Conic { cone_angle_deg, rate_deg_s, phase_deg }, Some(mount)) if norm.is_finite() => {
                    g_m_s2 = norm;
                    // A stand that logs its angle starts from the log (its phase is the
                    // encoder's offset, none declared).
                    let phase_deg = if run.track.logged_angles().is_some() { 0.0 } else { *phase_deg };
                    let d = StandMotion {
                        // A drift of the rate counts from the run's first sample.
                        drift_from_s: run.track.t_s.first().copied().unwrap_or(0.0),
                        ..StandMotion::ideal(
                            cone_angle_deg.to_radians(),
                            rate_deg_s.to_radians(),
                            phase_deg.to_radians(),
                        )
                    };
                    RunStand::Conic {
                        declared: d,
                        now: d,
                        mount: mount.clone(),
                        logs: run.track.logged_angles().is_some(),
                    }
                }
                (MotionSpec::Static { earth_rate_rad_s, .. }, _) if norm > 0.0 && norm.is_finite() => {
                    earth_declared |= earth_rate_rad_s.iter().any(|&x| x != 0.0);
                    RunStand::Static { up: a.map(|x| x / norm), earth: [0.0; 3] }
                }
                _ => RunStand::Other,
            };
            out.push(kind);
        }
        let conic: Vec<usize> = (0..out.len()).filter(|&i| matches!(out[i], RunStand::Conic { .. })).collect();
        let statics: Vec<usize> = (0..out.len()).filter(|&i| matches!(out[i], RunStand::Static { .. })).collect();
        if conic.is_empty() && (statics.is_empty() || earth_declared) {
            return None;
        }
        let nc = conic.len();
        let common = COMMON * nc;
        let earth_z = common + KNOBS - 1 - COMMON;
        let mut locals = vec![Vec::new(); out.len()];
        let logs = |r: usize| runs[r].track.logged_angles().is_some();
        for (ci, &r) in conic.iter().enumerate() {
            // A stand that logs its angle: the run's rate, drift and ripple are the log's.
            let own = |k: &usize| follows(*k, logs(r));
            let mut l: Vec<(usize, Dir)> = (0..COMMON).filter(own).map(|k| (COMMON * ci + k, Dir::Knob(k))).collect();
            let last = if earth_declared { KNOBS - 3 } else { KNOBS };
            l.extend((COMMON..last).filter(own).map(|k| (common + k - COMMON, Dir::Knob(k))));
            locals[r] = l;
        }
        let free_angle = conic.iter().any(|&r| !logs(r));
        let mut width = common + KNOBS - COMMON;
        let mut horizontals = Vec::new();
        if !earth_declared {
            for &r in &statics {
                if let RunStand::Static { up, .. } = out[r] {
                    let [e1, e2] = crate::motion::stand::horizontal_basis(up);
                    locals[r] = vec![(earth_z, Dir::Rate(up)), (width, Dir::Rate(e1)), (width + 1, Dir::Rate(e2))];
                    horizontals.push(vec![(width, 1.0)]);
                    horizontals.push(vec![(width + 1, 1.0)]);
                    width += 2;
                }
            }
        }
        let per_run = |k: usize| -> Vec<Combo> { (0..nc).map(|ci| vec![(COMMON * ci + k, 1.0)]).collect() };
        let all = |k: usize| -> Vec<Combo> { vec![(0..nc).map(|ci| (COMMON * ci + k, 1.0)).collect()] };
        let pair = |k: usize| -> Vec<Combo> { vec![vec![(common + k, 1.0)], vec![(common + k + 1, 1.0)]] };
        let mut groups = Vec::new();
        if nc > 0 {
            groups.push(Group { id: "cone-angle", params: all(0) });
            if nc > 1 {
                groups.push(Group { id: "cone-angle-per-run", params: per_run(0) });
            }
            // Groups of the stand's angle, unless every conic run logs it.
            if free_angle {
                groups.push(Group { id: "stand-rate", params: all(1) });
                groups.push(Group { id: "stand-rate-drift", params: all(3) });
                if nc > 1 {
                    groups.push(Group { id: "stand-rate-per-run", params: per_run(1) });
                    groups.push(Group { id: "stand-rate-drift-per-run", params: per_run(3) });
                }
                groups.push(Group { id: "speed-ripple-1", params: pair(2) });
                groups.push(Group { id: "speed-ripple-2", params: pair(4) });
            }
            // The encoder's zero, common to the runs that log the angle.
            let logged: Combo =
                conic.iter().enumerate().filter(|(_, &r)| logs(r)).map(|(ci, _)| (COMMON * ci + 2, 1.0)).collect();
            if !logged.is_empty() {
                groups.push(Group { id: "encoder-offset", params: vec![logged] });
            }
            // A starting phase per run; on a run that logs its angle, its encoder's offset.
            groups.push(Group { id: "phase-per-run", params: per_run(2) });
            groups.push(Group { id: "base-tilt", params: pair(0) });
            groups.push(Group { id: "cone-wobble", params: pair(6) });
        }
        if !earth_declared {
            let mut p = if nc > 0 { vec![vec![(common + 8, 1.0)], vec![(common + 9, 1.0)]] } else { Vec::new() };
            p.push(vec![(earth_z, 1.0)]);
            p.extend(horizontals);
            groups.push(Group { id: "earth-rotation", params: p });
        }
        Some(Self {
            runs: out,
            g_m_s2,
            locals,
            width,
            groups,
            accepted: Vec::new(),
            refused: Vec::new(),
            mounts: Vec::new(),
            carry: rejudge::Carry::default(),
        })
    }

    /// Whether any stand parameter or mount has been changed from the labels.
    pub fn changed(&self) -> bool {
        !self.accepted.is_empty() || !self.mounts.is_empty()
    }

    /// Run `run` was recorded on `mount` (a conic run; the finding says so).
    pub fn set_mount(&mut self, run: usize, mount: Mount, finding: StandFinding) {
        if let Some(RunStand::Conic { mount: m, .. }) = self.runs.get_mut(run) {
            *m = mount;
            self.mounts.push(finding);
        }
    }

    /// The runs' tracks on the motion now believed.
    pub fn tracks(&self, runs: &[FitRun<'_>]) -> Vec<Track> {
        runs.iter()
            .zip(&self.runs)
            .map(|(r, s)| match s {
                RunStand::Conic { now, mount, .. } => r.track.on_stand(*now, self.g_m_s2, mount.clone()),
                RunStand::Static { earth, .. } if earth.iter().any(|&x| x != 0.0) => {
                    r.track.mapped(Arc::new(AddRate(*earth)))
                }
                _ => r.track.clone(),
            })
            .collect()
    }

    /// The declared motions with each conic run's cone angle, rate and phase now believed.
    pub fn motions(&self, motions: &[&MotionSpec]) -> Vec<MotionSpec> {
        motions
            .iter()
            .zip(&self.runs)
            .map(|(m, s)| match s {
                RunStand::Conic { now, .. } => MotionSpec::Conic {
                    cone_angle_deg: now.cone_angle_rad.to_degrees(),
                    rate_deg_s: now.rate_rad_s.to_degrees(),
                    phase_deg: now.phase_rad.to_degrees(),
                },
                _ => (*m).clone(),
            })
            .collect()
    }

    /// Moves global stand parameter `p` by `d`.
    fn nudge(&mut self, p: usize, d: f64) {
        for (r, locals) in self.locals.iter().enumerate() {
            for &(gi, dir) in locals.iter().filter(|(gi, _)| *gi == p) {
                let _ = gi;
                match (&mut self.runs[r], dir) {
                    (RunStand::Conic { declared, now, .. }, Dir::Knob(k)) => knob(now, declared.rate_rad_s, k, d),
                    (RunStand::Static { earth, .. }, Dir::Rate(v)) => {
                        for i in 0..3 {
                            earth[i] += d * v[i];
                        }
                    }
                    _ => {}
                }
            }
        }
    }

    /// The whitened systems of every run around `model` and its fit, with the noise models
    /// `noise[run][channel]`.
    pub fn systems(&self, model: &Model, fit: &Fit, runs: &[FitRun<'_>], noise: &[RunNoiseModel]) -> Systems {
        self.systems_of(model, fit, runs, noise, None)
    }

    /// [`Self::systems`] with the columns of the accepted groups' parameters only (the
    /// others' rows and columns zero): enough to judge them again ([`Self::rejudge`]) or
    /// to estimate them, not to look for new ones.
    pub fn accepted_systems(&self, model: &Model, fit: &Fit, runs: &[FitRun<'_>], noise: &[RunNoiseModel]) -> Systems {
        let used = self.accepted_params();
        self.systems_of(model, fit, runs, noise, Some(&used))
    }

    /// The global stand parameters of the accepted groups, sorted.
    fn accepted_params(&self) -> Vec<usize> {
        let mut used: Vec<usize> =
            self.accepted.iter().flat_map(|a| self.groups[a.0].params.iter().flatten().map(|&(gi, _)| gi)).collect();
        used.sort_unstable();
        used.dedup();
        used
    }

    /// [`Self::systems`] with the columns of only the global stand parameters `only`
    /// (every one when None): the others' rows and columns stay zero, so a solution on the
    /// parameters kept is the same, for a fraction of the nudged evaluations.
    fn systems_of(
        &self,
        model: &Model,
        fit: &Fit,
        runs: &[FitRun<'_>],
        noise: &[RunNoiseModel],
        only: Option<&[usize]>,
    ) -> Systems {
        // The base model's columns at the parameters the fit estimated (a knee at its
        // fitted rate): at their start values the residual would carry the knee's misfit,
        // which a stand term (the Earth's vertical rate) could take.
        let bound = crate::estimate::bound_at_fit(model, fit);
        let model = &bound;
        let layout = BaseLayout::new(model, fit);
        let (folds, raws): (Vec<Fold>, Vec<Fold>) = (0..runs.len())
            .into_par_iter()
            .map(|r| {
                let locals: Vec<(usize, Dir)> =
                    self.locals[r].iter().filter(|l| only.is_none_or(|o| o.contains(&l.0))).copied().collect();
                self.run_system(r, &locals, model, fit, &layout, &runs[r], &noise[r])
            })
            .unzip();
        let p = layout.count + self.width;
        let sum = |fs: &[Fold]| {
            let mut total = Fold { g: DMatrix::zeros(p, p), b: DVector::zeros(p), yy: 0.0 };
            for f in fs {
                total.g += &f.g;
                total.b += &f.b;
                total.yy += f.yy;
            }
            total
        };
        let (total, raw) = (sum(&folds), sum(&raws));
        let samples = runs.iter().map(|r| 6 * r.len()).sum();
        Systems { folds, total, raw, base: layout.count, samples, complete: only.is_none() }
    }

    #[allow(clippy::too_many_arguments)]
    fn run_system(
        &self,
        r: usize,
        locals: &[(usize, Dir)],
        model: &Model,
        fit: &Fit,
        layout: &BaseLayout,
        run: &FitRun<'_>,
        noise: &RunNoiseModel,
    ) -> (Fold, Fold) {
        let n = run.len();
        let nl = locals.len();
        let terms: [Vec<TermRef<'_>>; 2] = SensorKind::BOTH.map(|s| model.terms(s));
        let values: [Vec<f64>; 2] = SensorKind::BOTH.map(|s| {
            let sf = fit.sensor(s);
            model.terms(s).iter().map(|t| sf.value(&t.term.name).unwrap_or(t.term.nominal)).collect()
        });
        let seen: [Option<Track>; 2] = SensorKind::BOTH
            .map(|s| crate::estimate::seen_tracks(model, fit, s, std::slice::from_ref(run)).and_then(|mut v| v.pop()));
        let predict = [0, 1].map(|si| Predictor::new(&terms[si], &values[si]));
        let conic = match &self.runs[r] {
            RunStand::Conic { declared, now, mount, .. } => Some((declared.rate_rad_s, *now, mount)),
            _ => None,
        };
        let mut knobs = Knobs::new(predict, locals, conic, self.g_m_s2);
        // Per channel: its stand columns that can be nonzero (local indices), and the global
        // indices of its columns (model coefficients, then those stand columns; the others'
        // rows and columns stay zero).
        let felt: [Vec<usize>; 2] = [0, 1].map(|si| (0..nl).filter(|&j| knobs.felt_by(j, si)).collect());
        let index: Vec<Vec<usize>> = (0..6)
            .map(|c| {
                let mut v: Vec<usize> = layout.channel[c].iter().map(|x| x.0).collect();
                v.extend(felt[c / 3].iter().map(|&j| layout.count + locals[j].0));
                v
            })
            .collect();
        // The slow noise as a random effect on the run's basis (super::slow), where it has one.
        let slow = |c: usize| noise.slow.get(c).filter(|d| d.iter().any(|v| *v != 0.0));
        let nb = |c: usize| if slow(c).is_some() { noise.basis.size } else { 0 };
        let any_slow = (0..6).any(|c| nb(c) > 0);
        let mut chans: Vec<WhitenedGram> =
            (0..6).map(|c| WhitenedGram::new(index[c].len() + nb(c) + 1, &noise.ar[c], BLOCK)).collect();
        // A block's knob columns ([local][channel][sample]), states per sensor and basis rows.
        let mut dcol = vec![0.0; nl * 6 * BLOCK];
        let mut states: [Vec<State>; 2] = [Vec::with_capacity(BLOCK), Vec::with_capacity(BLOCK)];
        let mut base: Vec<State> = Vec::with_capacity(BLOCK);
        let how = [0, 1].map(|si| run.seen_from(seen[si].as_ref()));
        let logged = run.track.logged_angles();
        let mut basis = vec![0.0; noise.basis.size * BLOCK];
        let mut brow = Vec::new();
        // The residual (output − the fitted model on the motion each sensor sees).
        let mut resid = vec![0.0; 6 * BLOCK];
        let mut k0 = 0;
        while k0 < n {
            let k1 = (k0 + BLOCK).min(n);
            let len = k1 - k0;
            base.clear();
            run.states_into(k0..k1, &mut base);
            for (si, s) in states.iter_mut().enumerate() {
                run.seen_states(&how[si], &base, k0, s);
            }
            for (i, k) in (k0..k1).enumerate() {
                knobs.push(i, run.track.t_s[k], logged.map(|a| a[k]), &base[i]);
            }
            if any_slow {
                noise.basis.rows_into(&run.track.t_s[k0..k1], &mut brow, &mut basis, BLOCK);
            }
            knobs.columns(len, &mut dcol);
            knobs.residual(&states, |si, i| run.output(SensorKind::BOTH[si], k0 + i), &mut resid);
            for (c, w) in chans.iter_mut().enumerate() {
                let (si, nbase) = (c / 3, layout.channel[c].len());
                let nf = felt[si].len();
                for (col, &(_, ti)) in layout.channel[c].iter().enumerate() {
                    terms[si][ti].regressors(&states[si], w.column(col, len));
                }
                for (col, &j) in felt[si].iter().enumerate() {
                    w.column(nbase + col, len).copy_from_slice(&dcol[(j * 6 + c) * BLOCK..][..len]);
                }
                for b in 0..nb(c) {
                    w.column(nbase + nf + b, len).copy_from_slice(&basis[b * BLOCK..][..len]);
                }
                w.column(nbase + nf + nb(c), len).copy_from_slice(&resid[c * BLOCK..][..len]);
                w.commit(len);
            }
            k0 = k1;
        }
        let p_all = layout.count + self.width;
        let mut fold = Fold { g: DMatrix::zeros(p_all, p_all), b: DVector::zeros(p_all), yy: 0.0 };
        let mut raw = fold.clone();
        for (c, w) in chans.into_iter().enumerate() {
            let mut gm = w.finish();
            if let Some(d) = slow(c) {
                super::slow::adjust_gram(&mut gm, index[c].len(), nb(c), d);
            }
            let phi = noise.dispersion[c].max(1.0);
            let m = gm.nrows();
            for (f, scale) in [(&mut raw, 1.0), (&mut fold, 1.0 / phi)] {
                for (i, &gi) in index[c].iter().enumerate() {
                    for (j, &gj) in index[c].iter().enumerate() {
                        f.g[(gi, gj)] += scale * gm[(i, j)];
                    }
                    f.b[gi] += scale * gm[(i, m - 1)];
                }
                f.yy += scale * gm[(m - 1, m - 1)];
            }
        }
        (fold, raw)
    }
}

/// The model's free coefficients as global parameters: per channel (global index, term index).
struct BaseLayout {
    channel: [Vec<(usize, usize)>; 6],
    count: usize,
}

impl BaseLayout {
    fn new(model: &Model, fit: &Fit) -> Self {
        let mut channel: [Vec<(usize, usize)>; 6] = Default::default();
        let mut count = 0;
        for (si, s) in SensorKind::BOTH.into_iter().enumerate() {
            let sf = fit.sensor(s);
            for (ti, t) in model.terms(s).iter().enumerate() {
                let free = sf.coefficients.iter().any(|c| c.name == t.term.name && c.status == CoefStatus::Fitted);
                if free {
                    channel[3 * si + t.term.channel].push((count, ti));
                    count += 1;
                }
            }
        }
        Self { channel, count }
    }
}

/// A group's solution on a system: the model's coefficients plus the group's parameters.
fn reduce(s: &Fold, base: usize, group: &[Combo]) -> (DMatrix<f64>, DVector<f64>) {
    let p = s.g.nrows();
    let q = base + group.len();
    let mut t = DMatrix::<f64>::zeros(p, q);
    for i in 0..base {
        t[(i, i)] = 1.0;
    }
    for (j, combo) in group.iter().enumerate() {
        for &(gi, w) in combo {
            t[(base + gi, base + j)] += w;
        }
    }
    (t.transpose() * &s.g * &t, t.transpose() * &s.b)
}

impl Systems {
    /// Whether every stand parameter has its columns ([`Suspect::systems`], not
    /// [`Suspect::accepted_systems`]): enough to look for new groups.
    pub fn complete(&self) -> bool {
        self.complete
    }

    /// Whether a group with evidence `ev` and raw ΔBIC `raw_bic` takes a material share
    /// (`MIN_SHARE`) of what the noise model does not explain: the whitened χ² in excess
    /// of the sample count, less twice its spread under the noise alone (√(2n)). A residual
    /// no effect explains (a gyro that clips) leaves a few χ² on the cone's harmonics that a
    /// stand group takes with a p-value far below the rule's, without explaining it.
    fn material(&self, ev: &Evidence, raw_bic: f64) -> bool {
        let n = self.samples.max(2) as f64;
        let delta_q = -(raw_bic - ev.added_params as f64 * n.ln());
        let excess = self.raw.yy - n - 2.0 * (2.0 * n).sqrt();
        excess <= 0.0 || delta_q >= MIN_SHARE * excess
    }

    /// What every group's evidence on this system shares ([`Shared`]).
    fn shared(&self) -> Shared {
        let base_set: Vec<usize> = (0..self.base).collect();
        let l0 = Lsq::solve(&self.total.g, &self.total.b, self.total.yy, &base_set);
        let raw_q0 = Lsq::solve(&self.raw.g, &self.raw.b, self.raw.yy, &base_set).q;
        let rest = if self.folds.len() > 1 {
            self.folds
                .par_iter()
                .map(|f| {
                    let rest = Fold { g: &self.total.g - &f.g, b: &self.total.b - &f.b, yy: self.total.yy - f.yy };
                    let q0 = Lsq::solve(&rest.g, &rest.b, rest.yy, &base_set).q_on(&f.g, &f.b, f.yy);
                    (rest, q0)
                })
                .collect()
        } else {
            Vec::new()
        };
        Shared { q0: l0.q, rank0: l0.rank, raw_q0, rest }
    }

    /// The evidence for a group (channels weighed by their dispersion), its values and
    /// standard errors (all-run GLS), and its ΔBIC without the dispersion (the sensor
    /// candidates' scale, for ranking against them); `shared` is [`Self::shared`].
    fn evidence(&self, group: &[Combo], shared: &Shared) -> Judged {
        let (g, b) = reduce(&self.total, self.base, group);
        // The solution on every column: G⁺b, whose pseudo-inverse also gives the standard errors.
        let (pinv, rank1) = pinv_sym(&g);
        let q1 = self.total.yy - b.dot(&(&pinv * &b));
        let added = rank1.saturating_sub(shared.rank0);
        let n = self.samples.max(2) as f64;
        let raw_bic = {
            let (g, b) = reduce(&self.raw, self.base, group);
            let q1 = self.raw.yy - b.dot(&(pinv_sym(&g).0 * &b));
            -(shared.raw_q0 - q1).max(0.0) + added as f64 * n.ln()
        };
        let delta_q = (shared.q0 - q1).max(0.0);
        let p_value = if added == 0 {
            1.0
        } else {
            use statrs::distribution::{ChiSquared, ContinuousCDF};
            ChiSquared::new(added as f64).map(|d| d.sf(delta_q)).unwrap_or(1.0)
        };
        let heldout = if self.folds.len() > 1 { self.heldout_gain(group, shared) } else { delta_q };
        let beta = &pinv * &b;
        let values = (0..group.len())
            .map(|j| (beta[self.base + j], pinv[(self.base + j, self.base + j)].max(0.0).sqrt()))
            .collect();
        let ev = Evidence {
            delta_q,
            added_params: added,
            p_value,
            delta_bic: -delta_q + added as f64 * n.ln(),
            heldout_gain: heldout,
            heterogeneity_p: 1.0,
            spread: 0.0,
            delta_q_sensor: [0.0; 2],
            nonlinear: false,
        };
        (ev, values, raw_bic)
    }

    /// A group's values and standard errors solved on the system without the channels'
    /// dispersion (each channel weighed by its noise model alone).
    fn raw_values(&self, group: &[Combo]) -> Vec<(f64, f64)> {
        let (g, b) = reduce(&self.raw, self.base, group);
        let all: Vec<usize> = (0..g.nrows()).collect();
        let l = Lsq::solve(&g, &b, self.raw.yy, &all);
        let (pinv, _) = pinv_sym(&g);
        (0..group.len())
            .map(|j| (l.beta[self.base + j], pinv[(self.base + j, self.base + j)].max(0.0).sqrt()))
            .collect()
    }

    /// Σ over left-out runs of the χ² reduction: the model's coefficients and the group's
    /// common parameters from the other runs; the left-out run's own parameters (a per-run
    /// group's) refitted on that run alone with the rest held.
    fn heldout_gain(&self, group: &[Combo], shared: &Shared) -> f64 {
        let mut gain = 0.0;
        for (f, (rest, q0)) in self.folds.iter().zip(&shared.rest) {
            let (g, b) = reduce(rest, self.base, group);
            let (gf, bf) = reduce(f, self.base, group);
            let all: Vec<usize> = (0..g.nrows()).collect();
            let l1 = Lsq::solve(&g, &b, rest.yy, &all);
            // The run's own parameters: those the other runs do not see at all.
            let own: Vec<usize> =
                (self.base..g.nrows()).filter(|&i| g[(i, i)] <= 1e-12 * gf[(i, i)] && gf[(i, i)] > 0.0).collect();
            let mut beta = DVector::from_fn(g.nrows(), |i, _| l1.value(i));
            if !own.is_empty() {
                let go = DMatrix::from_fn(own.len(), own.len(), |i, j| gf[(own[i], own[j])]);
                let rhs = DVector::from_fn(own.len(), |i, _| {
                    bf[own[i]]
                        - (0..g.nrows()).filter(|j| !own.contains(j)).map(|j| gf[(own[i], j)] * beta[j]).sum::<f64>()
                });
                let sol = pinv_sym(&go).0 * rhs;
                for (i, &o) in own.iter().enumerate() {
                    beta[o] = sol[i];
                }
            }
            let q1 = f.yy - 2.0 * beta.dot(&bf) + beta.dot(&(&gf * &beta));
            gain += q0 - q1;
        }
        gain
    }
}

/// What every group's evidence on one system shares: the χ² and rank of the model's
/// coefficients alone on the system and on its raw twin, and per left-out run the rest of
/// the runs with the χ² the run has around the rest's solution.
struct Shared {
    q0: f64,
    rank0: usize,
    raw_q0: f64,
    rest: Vec<(Fold, f64)>,
}

/// A group's evidence, its values with their standard errors, and its raw ΔBIC
/// ([`Systems::evidence`]).
type Judged = (Evidence, Vec<(f64, f64)>, f64);

/// What the stand check decided at one step of the climb.
pub struct Pick {
    group: usize,
    evidence: Evidence,
    /// ΔBIC without the channels' dispersion (ranked against the sensor candidates).
    raw_bic: f64,
}

impl Suspect {
    /// The best stand group on `sys` that passes the rules, is plausible, and beats
    /// `sensor_bic` (the best sensor candidate's ΔBIC, if any passes).
    pub fn pick(&self, sys: &Systems, sensor_bic: Option<f64>) -> Option<Pick> {
        let mut best: Option<Pick> = None;
        let mut passed: Vec<&str> = Vec::new();
        // After a first look on every k-th sample, a group it found is estimated again on
        // every sample at the end (`polish`), not picked again: its estimate on the reduced
        // runs is about one of their standard errors from every sample's, so that its
        // refinement would take about k χ² per parameter there — near the rules' threshold,
        // and each such pick would start the diagnosis again.
        let again = |gi: &usize| !(self.carry.looked && self.accepted.iter().any(|a| a.0 == *gi));
        let shared = sys.shared();
        let judged: Vec<(usize, Judged)> = (0..self.groups.len())
            .into_par_iter()
            .filter(|gi| !self.refused.contains(gi) && again(gi))
            .map(|gi| (gi, sys.evidence(&self.groups[gi].params, &shared)))
            .collect();
        for (gi, (ev, values, raw_bic)) in judged {
            let g = &self.groups[gi];
            if ev.rejection().is_some() || !self.plausible(g.id, &values) || !sys.material(&ev, raw_bic) {
                continue;
            }
            passed.push(g.id);
            if best.as_ref().is_none_or(|b| raw_bic < b.raw_bic) {
                best = Some(Pick { group: gi, evidence: ev, raw_bic });
            }
        }
        // One value for every run before one per run: the common group first when it passes
        // (its linearisation around the labels leaves a little that per-run values absorb);
        // the per-run group comes next, around the corrected motion, only if the runs differ.
        if let Some(b) = best.as_mut() {
            if let Some(common) = self.groups[b.group].id.strip_suffix("-per-run") {
                if passed.contains(&common) {
                    if let Some(ci) = self.groups.iter().position(|g| g.id == common) {
                        let (ev, _, raw_bic) = sys.evidence(&self.groups[ci].params, &shared);
                        *b = Pick { group: ci, evidence: ev, raw_bic };
                    }
                }
            }
        }
        best.filter(|b| sensor_bic.is_none_or(|s| b.raw_bic < s))
    }

    /// Whether a group's estimate is something a stand does (within its limits).
    fn plausible(&self, id: &str, values: &[(f64, f64)]) -> bool {
        let within = |limit: f64| values.iter().all(|(v, _)| v.abs() <= limit);
        match id {
            "cone-angle" | "cone-angle-per-run" => within(2f64.to_radians()),
            "stand-rate" | "stand-rate-per-run" => within(0.05),
            "phase-per-run" | "encoder-offset" => within(30f64.to_radians()),
            // 0.1 % of the rate per second: 6 % in a minute's run.
            "stand-rate-drift" | "stand-rate-drift-per-run" => within(1e-3),
            "base-tilt" | "cone-wobble" => within(2f64.to_radians()),
            "speed-ripple-1" | "speed-ripple-2" => within(0.1),
            "earth-rotation" => {
                // Every component at most the Earth's rate (3 SE of slack): a larger rate is not it.
                values.iter().all(|(v, se)| v.abs() <= EARTH_RAD_S * 1.1 + 3.0 * se)
                    && values.iter().any(|(v, se)| v.abs() > 3.0 * se)
            }
            _ => true,
        }
    }

    /// Estimates the picked group by Gauss–Newton on the whole motion (the model refitted
    /// at every step) and records it (true). `runs` are the runs with their declared
    /// tracks. When the estimate leaves what a stand or the Earth does (a residual the
    /// linearisation around the labels took for the stand, e.g. a gyro that clips), the
    /// motion is left as it was, the group is not tried again, and the answer is false.
    pub fn accept(
        &mut self,
        pick: Pick,
        model: &Model,
        runs: &[FitRun<'_>],
        noise: &[RunNoiseModel],
        opts: &FitOptions,
    ) -> Result<bool, EstimateError> {
        // Every group found so far moves with the new one (joint Gauss–Newton): one at a
        // time would leave each biased by what the others still hold.
        let mut groups: Vec<usize> = self.accepted.iter().map(|a| a.0).collect();
        if !groups.contains(&pick.group) {
            groups.push(pick.group);
        }
        let before = self.runs.clone();
        let (se, _) = self.estimate(&groups, model, runs, noise, opts, None)?;
        if !self.all_plausible(&groups, &se) {
            self.runs = before;
            self.refused.push(pick.group);
            return Ok(false);
        }
        if !self.accepted.iter().any(|a| a.0 == pick.group) {
            self.accepted.push((pick.group, pick.evidence));
        }
        Ok(true)
    }

    /// Estimates every group found again, jointly, under `model` (the end of the ladder)
    /// and `noise` (the final residual's noise models): a group accepted early was
    /// estimated under the noise model of a residual that still held its misfit, which
    /// weighs the samples inefficiently — unbiased, but scattered far beyond the standard
    /// error the final systems report. An estimate that leaves what a stand does (a
    /// residual no effect explains pulls it) is an error, and the motion stays as it was.
    /// The systems of the estimate's last step (on the groups' parameters, the channels
    /// weighed by their dispersion too), for the findings' standard errors; None with no
    /// group found.
    /// `first`, when given, are the systems around `model`'s fit on the motion now believed
    /// under `noise` (the last stand check's, at the end of the ladder): the first step's,
    /// without a fit and a pass of its own.
    pub fn polish(
        &mut self,
        model: &Model,
        runs: &[FitRun<'_>],
        noise: &[RunNoiseModel],
        opts: &FitOptions,
        first: Option<Systems>,
    ) -> Result<Option<Systems>, EstimateError> {
        let groups: Vec<usize> = self.accepted.iter().map(|a| a.0).collect();
        if groups.is_empty() {
            return Ok(None);
        }
        let before = self.runs.clone();
        let (se, sys) = self.estimate(&groups, model, runs, noise, opts, first)?;
        if !self.all_plausible(&groups, &se) {
            self.runs = before;
            return Err(EstimateError::NotConverged(
                "the stand's groups estimated again under the final model left what a stand does".into(),
            ));
        }
        Ok(Some(sys))
    }

    /// Whether every group's departure from the labels is something a stand does, with the
    /// standard errors `se` of their parameters in order.
    fn all_plausible(&self, groups: &[usize], se: &[f64]) -> bool {
        let mut se = se.iter();
        groups.iter().all(|&g| {
            let group = &self.groups[g];
            let values: Vec<(f64, f64)> =
                group.params.iter().map(|c| (self.departure(c), se.next().copied().unwrap_or(0.0))).collect();
            self.plausible(group.id, &values)
        })
    }

    /// Gauss–Newton on the groups' parameters, the model refitted at every step, each
    /// channel weighed by its noise model alone (not its dispersion: the misfit it had is
    /// what the groups remove); the standard error of each parameter (in the groups' order)
    /// and the systems (on the groups' parameters) of the last step. `first`: the first
    /// step's systems when they are already at hand ([`Self::polish`]).
    fn estimate(
        &mut self,
        groups: &[usize],
        model: &Model,
        runs: &[FitRun<'_>],
        noise: &[RunNoiseModel],
        opts: &FitOptions,
        mut first: Option<Systems>,
    ) -> Result<(Vec<f64>, Systems), EstimateError> {
        let params: Vec<Combo> = groups.iter().flat_map(|&g| self.groups[g].params.iter().cloned()).collect();
        let mut used: Vec<usize> = params.iter().flatten().map(|&(gi, _)| gi).collect();
        used.sort_unstable();
        used.dedup();
        let mut last = None;
        for _ in 0..MAX_STEPS {
            let sys = match first.take() {
                Some(sys) => sys,
                None => {
                    let tracks = self.tracks(runs);
                    let moved: Vec<FitRun<'_>> =
                        runs.iter().zip(&tracks).map(|(r, t)| FitRun { track: t, ..*r }).collect();
                    let fit = crate::estimate::fit(&FitRequest::runs(model, &moved).options(*opts))?.fit;
                    self.systems_of(model, &fit, &moved, noise, Some(&used))
                }
            };
            let values = sys.raw_values(&params);
            let mut worst = 0.0f64;
            for (combo, (v, se)) in params.iter().zip(&values) {
                for &(gi, w) in combo {
                    self.nudge(gi, w * v);
                }
                if *se > 0.0 {
                    worst = worst.max(v.abs() / se);
                }
            }
            last = Some((values.iter().map(|v| v.1).collect(), sys));
            if worst < LINEAR_WITHIN {
                break;
            }
        }
        last.ok_or_else(|| EstimateError::NotConverged("no Gauss–Newton step on the stand's groups".into()))
    }
}
