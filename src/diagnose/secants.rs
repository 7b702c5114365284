//! The secant columns of a run's nonlinear candidates (module `space`): per candidate and
//! parameter, the change of each channel's model output per unit step of the parameter,
//! from the motion each sensor sees with that parameter stepped.

use crate::estimate::{seen_tracks, Fit, FitRun};
use crate::model::{Model, Predictor, State};
use crate::motion::Track;
use crate::units::SensorKind;

/// A nonlinear candidate (or a nonlinear effect of the model): its entry, the step of each
/// parameter, and whether it is in the model already.
pub(super) type Nonlinear = (crate::model::NonlinearEntry, Vec<f64>, bool);

/// The secant columns of the nonlinear candidates in one run: per candidate and parameter
/// the change of each channel's model output per unit parameter. The motions are held
/// (lazily evaluated tracks); the columns are worked out a block at a time.
pub(super) struct Secants {
    /// The motion each sensor sees under the model's own nonlinear effects.
    seen: [Option<Track>; 2],
    /// Per candidate, per parameter: the motion per sensor with that parameter stepped
    /// (None: the candidate does not act on that sensor), and the step.
    moved: Vec<Vec<([Option<Track>; 2], f64)>>,
    /// Per candidate, per parameter: whether the accelerometer's stepped states are the
    /// gyro's (the same stepped motion from the same seen one, a time delay on a run
    /// without nonlinear effects): they are then worked out once.
    shared: Vec<Vec<bool>>,
}

/// One block of secant columns: the model's output per sensor, and per candidate and
/// parameter the columns (buffers reused from block to block).
#[derive(Default)]
pub(super) struct SecantBlock {
    /// Per sensor the states of the motion it sees, and the model's output there.
    states: [Vec<State>; 2],
    start: [Vec<[f64; 3]>; 2],
    /// Scratch: a moved motion's states, the output there, a regressor block.
    moved: Vec<State>,
    out: Vec<[f64; 3]>,
    tmp: Vec<f64>,
    /// Per candidate, per parameter, per sample: the column in each of the six channels.
    pub(super) cols: Vec<Vec<Vec<[f64; 6]>>>,
}

impl Secants {
    pub(super) fn new(nonlinear: &[Nonlinear], base: &Model, fit: &Fit, run: &FitRun<'_>) -> Self {
        let seen: [Option<Track>; 2] =
            SensorKind::BOTH.map(|s| seen_tracks(base, fit, s, std::slice::from_ref(run)).and_then(|mut v| v.pop()));
        let moved = nonlinear
            .iter()
            .map(|(entry, steps, in_base)| {
                (0..steps.len())
                    .map(|pi| {
                        let mut p = entry.values.clone();
                        p[pi] += steps[pi];
                        // A base parameter moves inside the model's own chain of nonlinear
                        // effects; a candidate's acts on the motion the model already sees.
                        let shifted = in_base.then(|| {
                            let mut f = fit.clone();
                            for q in f.nonlinear.iter_mut().filter(|q| q.effect == entry.effect.id()) {
                                if let Some(i) = entry.effect.params().iter().position(|d| d.name == q.name) {
                                    q.value = p[i];
                                }
                            }
                            f
                        });
                        let tracks = [0, 1].map(|si| {
                            let sensor = SensorKind::BOTH[si];
                            if entry.effect.sensor().is_some_and(|s| s != sensor) {
                                return None;
                            }
                            let from = seen[si].as_ref().unwrap_or(run.track);
                            Some(match &shifted {
                                Some(f) => seen_tracks(base, f, sensor, std::slice::from_ref(run))
                                    .and_then(|mut v| v.pop())
                                    .unwrap_or_else(|| from.clone()),
                                None => entry.effect.transform(&p, from),
                            })
                        });
                        (tracks, steps[pi])
                    })
                    .collect()
            })
            .collect::<Vec<Vec<([Option<Track>; 2], f64)>>>();
        let shared = moved
            .iter()
            .map(|params| params.iter().map(|(t, _)| t[0].is_some() && t[0] == t[1] && seen[0] == seen[1]).collect())
            .collect();
        Self { seen, moved, shared }
    }

    /// The columns over the samples from `k0` whose run states are `base` into
    /// `out[candidate][parameter][i]` (resized), with `predict` the model's outputs per
    /// sensor; only the channels of the sensors `sensors` marks (the others' stay zero).
    /// The model is evaluated a block at a time ([`Predictor::block`]); every motion's
    /// states come from those it is derived from ([`FitRun::seen_states`]: a stepped motion
    /// that is the seen one with a map more, a dead zone, takes the seen states through it).
    pub(super) fn fill(
        &self,
        predict: &[Predictor<'_>; 2],
        run: &FitRun<'_>,
        k0: usize,
        base: &[State],
        sensors: [bool; 2],
        out: &mut SecantBlock,
    ) {
        let len = base.len();
        let from = |si: usize| self.seen[si].as_ref().unwrap_or(run.track);
        out.tmp.resize(Predictor::SCRATCH * len, 0.0);
        out.out.resize(len, [0.0; 3]);
        // The model's output on the motion it sees, once per sensor (every secant starts
        // there), its states from the run's (`base`).
        for si in (0..2).filter(|&si| sensors[si]) {
            run.seen_states(&run.seen_from(self.seen[si].as_ref()), base, k0, &mut out.states[si]);
            out.start[si].resize(len, [0.0; 3]);
            predict[si].block(&out.states[si], &mut out.start[si], &mut out.tmp);
        }
        out.cols.resize_with(self.moved.len(), Vec::new);
        for (e, params) in self.moved.iter().enumerate() {
            out.cols[e].resize_with(params.len(), Vec::new);
            for (pi, (tracks, step)) in params.iter().enumerate() {
                let col = &mut out.cols[e][pi];
                col.clear();
                col.resize(len, [0.0; 6]);
                for (si, moved) in tracks.iter().enumerate() {
                    let Some(moved) = moved.as_ref().filter(|_| sensors[si]) else { continue };
                    // The gyro's stepped states serve the accelerometer when they are its.
                    if !(si == 1 && sensors[0] && self.shared[e][pi]) {
                        let seen = FitRun { track: from(si), ..*run };
                        seen.seen_states(&seen.seen_from(Some(moved)), &out.states[si], k0, &mut out.moved);
                    }
                    predict[si].block(&out.moved, &mut out.out, &mut out.tmp);
                    for (i, c) in col.iter_mut().enumerate() {
                        let (u0, u1) = (out.start[si][i], out.out[i]);
                        for ch in 0..3 {
                            c[3 * si + ch] = (u1[ch] - u0[ch]) / step;
                        }
                    }
                }
            }
        }
    }
}
