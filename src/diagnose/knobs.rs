//! The stand's columns of one run ([`super::stand`]): the change of the fitted model's
//! outputs per unit change of each local stand parameter, a forward difference of the true
//! inputs pushed through the model, a block of samples at a time. The knobs of the angle's
//! law share three such differences (in the angle, its rate and its angular acceleration)
//! through the chain rule ([`Shortcut::Angle`]).

use crate::frames::Mount;
use crate::frames::V3;
use crate::model::{Predictor, State};
use crate::motion::stand::{rotate_t, sincos_near, to_sensor, Angle, AnglePartials, NearTrig, StandAt, StandMotion};

/// Motion parameters of a conic run: its own cone, rate (relative), phase and rate drift
/// (relative per second), then the common tilt ×2, ripple ×4, wobble ×2, Earth ×3.
pub(super) const KNOBS: usize = 15;
/// Knobs of one run's own (before the common ones).
pub(super) const PER_RUN: usize = 4;
/// Forward-difference step of each knob (rad, relative, 1/s for the drift, rad/s for the
/// Earth's rate).
pub(super) const STEP: [f64; KNOBS] =
    [1e-6, 1e-6, 1e-6, 1e-7, 1e-6, 1e-6, 1e-6, 1e-6, 1e-6, 1e-6, 1e-6, 1e-6, 1e-8, 1e-8, 1e-8];
/// Samples per whitened block.
pub(super) const BLOCK: usize = 256;
/// Forward-difference steps of the stand's angle, rate and angular acceleration (rad,
/// rad/s, rad/s²) for the knobs that move the angle ([`Shortcut::Angle`]).
const ANGLE_STEP: [f64; 3] = [1e-6, 1e-6, 1e-6];

/// A knob whose nudge moves one quantity of the state by a rotated constant vector: the
/// base's up (a tilt: the specific force) or the Earth's rate (the rate), in stand axes.
/// Its nudged state is the believed one with that quantity worked out again (one rotation
/// instead of the whole kinematics); the other quantities are the believed state's, as the
/// whole kinematics would give them.
#[derive(Debug, Clone, Copy)]
enum Shortcut {
    /// The whole kinematics of the nudged motion.
    None,
    /// The nudged motion's up: the specific force is g·Rᵀ up.
    Up([f64; 3]),
    /// The Earth's rate moved by this vector (the knob's step along an axis): the rate
    /// moves by Rᵀ of it.
    Earth([f64; 3]),
    /// A knob of the angle's law (rate, phase, drift, ripple): the model's outputs move
    /// through the angle, its rate and its angular acceleration alone, so its column is the
    /// chain rule Σ ∂y/∂θ⁽ᵏ⁾ · ∂θ⁽ᵏ⁾/∂knob: three nudged states shared by every such knob
    /// instead of one each, and the angle's exact partials ([`StandMotion::angle_partials`],
    /// times the factor: the declared rate for the relative rate, else 1).
    Angle(fn(&AnglePartials) -> Angle, f64),
}

/// The partial of the angle's law that knob `k` (one that moves the angle) moves.
fn angle_partial(k: usize) -> fn(&AnglePartials) -> Angle {
    match k {
        1 => |p| p.rate,
        2 => |p| p.phase,
        3 => |p| p.drift,
        6 => |p| p.ripple[0][0],
        7 => |p| p.ripple[0][1],
        8 => |p| p.ripple[1][0],
        _ => |p| p.ripple[1][1],
    }
}

/// How a local stand column moves the motion.
#[derive(Debug, Clone, Copy)]
pub(super) enum Dir {
    /// A knob of the run's stand motion.
    Knob(usize),
    /// A rate along a direction (sensor axes) on a static pose.
    Rate([f64; 3]),
}

/// The stand's columns of one run, a block of samples at a time: the change of the fitted
/// model's outputs per unit change of each local stand parameter (a forward difference).
/// Each sample's nudged states are gathered ([`Self::push`]), then the model is evaluated
/// on the whole block, term by term ([`Predictor::block`]).
pub(super) struct Knobs<'m> {
    /// The fitted model's gyro and accel outputs, and what each reads of a state.
    predict: [Predictor<'m>; 2],
    reads: [crate::model::Inputs; 2],
    /// A conic run's motion now believed, each local parameter's nudged motion (ready to
    /// evaluate) and the mount.
    stand: Option<(StandAt, Vec<StandAt>, &'m Mount)>,
    /// Per local parameter: its direction and step.
    dirs: Vec<(Dir, f64)>,
    /// Per local parameter: how its nudged state is worked out.
    short: Vec<Shortcut>,
    g_m_s2: f64,
    /// The block's states as believed, then per local parameter its nudged states.
    base: Vec<State>,
    nudged: Vec<State>,
    /// Per local parameter: whether its nudge moved ω, ε and a in the block.
    moved: Vec<[bool; 3]>,
    /// Whether a local parameter moves the angle; the states with the angle, its rate and
    /// its angular acceleration nudged ([`ANGLE_STEP`]), whether each moved ω, ε and a in
    /// the block, and per local parameter and sample its partials of the three.
    through_angle: bool,
    /// The believed stand angle's sines, sample after sample.
    trig: NearTrig,
    /// The sine and cosine of the angle's step.
    angle_step_trig: (f64, f64),
    angle_nudged: Vec<State>,
    angle_moved: [[bool; 3]; 3],
    partials: Vec<[f64; 3]>,
    /// Scratch: the outputs' forward differences along the three, per unit.
    slopes: Vec<[f64; 3]>,
    /// Scratch: outputs at the base and nudged states, and a regressor block.
    out0: Vec<[f64; 3]>,
    out1: Vec<[f64; 3]>,
    tmp: Vec<f64>,
}

impl<'m> Knobs<'m> {
    /// The columns of a run with local parameters `locals`, the fitted model's predictors
    /// and, for a conic run, its declared rate, motion now believed and mount.
    pub(super) fn new(
        predict: [Predictor<'m>; 2],
        locals: &[(usize, Dir)],
        conic: Option<(f64, StandMotion, &'m Mount)>,
        g_m_s2: f64,
    ) -> Self {
        let dirs: Vec<(Dir, f64)> = locals
            .iter()
            .map(|&(_, d)| match d {
                Dir::Knob(kn) => (d, STEP[kn]),
                Dir::Rate(_) => (d, STEP[KNOBS - 1]),
            })
            .collect();
        let stand: Option<(StandAt, Vec<StandAt>, &Mount)> = conic.map(|(declared_rate, now, mount)| {
            let nudged = dirs
                .iter()
                .map(|&(d, h)| {
                    let mut m = now;
                    if let Dir::Knob(kn) = d {
                        knob(&mut m, declared_rate, kn, h);
                    }
                    m.fixed(g_m_s2)
                })
                .collect();
            (now.fixed(g_m_s2), nudged, mount)
        });
        let short: Vec<Shortcut> = dirs
            .iter()
            .enumerate()
            .map(|(j, &(d, h))| match (d, &stand) {
                (Dir::Knob(4 | 5), Some((_, nudged, _))) => Shortcut::Up(nudged[j].motion.up()),
                (Dir::Knob(kn @ 12..=14), Some(_)) => {
                    let mut v = [0.0; 3];
                    v[kn - 12] = h;
                    Shortcut::Earth(v)
                }
                (Dir::Knob(kn), Some(_)) if moves_angle(kn) => {
                    Shortcut::Angle(angle_partial(kn), if kn == 1 { conic.map_or(1.0, |c| c.0) } else { 1.0 })
                }
                _ => Shortcut::None,
            })
            .collect();
        let nl = dirs.len();
        let through_angle = short.iter().any(|s| matches!(s, Shortcut::Angle(..)));
        Self {
            through_angle,
            angle_step_trig: libm::sincos(ANGLE_STEP[0]),
            trig: NearTrig::default(),
            angle_nudged: vec![State::default(); if through_angle { 3 * BLOCK } else { 0 }],
            angle_moved: [[true; 3]; 3],
            partials: vec![[0.0; 3]; if through_angle { nl * BLOCK } else { 0 }],
            slopes: vec![[0.0; 3]; if through_angle { 3 * BLOCK } else { 0 }],
            short,
            g_m_s2,
            reads: [0, 1].map(|si| predict[si].reads()),
            predict,
            stand,
            dirs,
            base: vec![State::default(); BLOCK],
            nudged: vec![State::default(); nl * BLOCK],
            moved: vec![[true; 3]; nl],
            out0: vec![[0.0; 3]; BLOCK],
            out1: vec![[0.0; 3]; BLOCK],
            tmp: vec![0.0; Predictor::SCRATCH * BLOCK],
        }
    }

    /// Gathers sample `i` of the block: state `st` at `t_s` (at the stand's `logged` angle
    /// when it logs it: of the knobs that move the angle only the phase, the encoder's
    /// offset, is then local) and each local parameter's nudged state. The stand's angle and cone angle are worked out once and their sines
    /// reused by the parameters that leave them alone (the same numbers as the nudged
    /// motion's own [`StandAt::at_angle`]).
    pub(super) fn push(&mut self, i: usize, t_s: f64, logged: Option<Angle>, st: &State) {
        self.base[i] = *st;
        let at = self.stand.as_ref().map(|(now, ..)| {
            let an = now.motion.angle_or_logged(t_s, logged);
            let sc = self.trig.of(an.theta);
            (an, sc, now.cone_trig(sc))
        });
        // A shortcut's vector as the whole kinematics turns it: to the body (then scaled, then
        // to the sensor), from the stand angle's and cone angle's sines and cosines.
        let body = |(s, c): (f64, f64), (_, sa, ca): (f64, f64, f64), v: [f64; 3]| rotate_t([s, c], [sa, ca], v);
        let partials = match (&self.stand, &at) {
            (Some((now, _, mount)), Some((an0, sc0, cone0))) if self.through_angle => {
                // The believed motion with its angle, rate and angular acceleration nudged in
                // turn; the angle's step exactly (its sine by angle addition).
                let nudged =
                    now.at_angle_nudged(*an0, *sc0, Some(*cone0), self.angle_step_trig, [ANGLE_STEP[1], ANGLE_STEP[2]]);
                for (d, x) in nudged.into_iter().enumerate() {
                    let x = to_sensor(x, mount);
                    let s1 = &mut self.angle_nudged[d * BLOCK + i];
                    *s1 = *st;
                    s1.w = x.w_rad_s.xyz;
                    s1.e = x.e_rad_s2.xyz;
                    s1.a = x.a_m_s2.xyz;
                }
                // A logged angle moves with the phase alone (the encoder's offset).
                Some(match logged {
                    Some(_) => AnglePartials::logged(),
                    None => now.motion.angle_partials_near(t_s, an0.theta, *sc0),
                })
            }
            _ => None,
        };
        for (j, &(dir, h)) in self.dirs.iter().enumerate() {
            let mut s1 = *st;
            match (dir, self.short[j], &self.stand, &at) {
                (_, Shortcut::Angle(of, factor), ..) => {
                    let a = partials.as_ref().map_or(Angle { theta: 0.0, rate: 0.0, accel: 0.0 }, of);
                    self.partials[j * BLOCK + i] = [a.theta * factor, a.rate * factor, a.accel * factor];
                    continue;
                }
                (_, Shortcut::Up(up), Some((_, _, mount)), Some((_, sc0, cone0))) => {
                    let g = self.g_m_s2;
                    s1.a = mount.to_sensor(V3::new(body(*sc0, *cone0, up).map(|x| g * x))).xyz;
                }
                (_, Shortcut::Earth(v), Some((_, _, mount)), Some((_, sc0, cone0))) => {
                    let d = mount.to_sensor(V3::new(body(*sc0, *cone0, v))).xyz;
                    for k in 0..3 {
                        s1.w[k] += d[k];
                    }
                }
                (Dir::Knob(kn), _, Some((_, nudged, mount)), Some((an0, sc0, cone0))) => {
                    let m = &nudged[j];
                    let x = if moves_angle(kn) {
                        let an = m.motion.angle_or_logged(t_s, logged);
                        m.at_angle_trig(an, sincos_near(an.theta, an0.theta, *sc0), Some(*cone0))
                    } else {
                        m.at_angle_trig(*an0, *sc0, Some(*cone0))
                    };
                    let x = to_sensor(x, mount);
                    s1.w = x.w_rad_s.xyz;
                    s1.e = x.e_rad_s2.xyz;
                    s1.a = x.a_m_s2.xyz;
                }
                (Dir::Rate(v), ..) => {
                    for k in 0..3 {
                        s1.w[k] += h * v[k];
                    }
                }
                _ => {}
            }
            self.nudged[j * BLOCK + i] = s1;
        }
    }

    /// Whether local parameter `j`'s column can be nonzero for sensor `si` (0 gyro, 1
    /// accel): whether its nudge can move a quantity the sensor's model reads (a tilt moves
    /// only the specific force, the Earth's rate or a static pose's rate only the rate). A
    /// column it cannot move is zero in every block ([`Self::columns`]).
    pub(super) fn felt_by(&self, j: usize, si: usize) -> bool {
        let r = self.reads[si];
        match (self.dirs[j].0, self.short[j]) {
            (_, Shortcut::Up(_)) => r.force,
            (Dir::Rate(_), _) | (_, Shortcut::Earth(_)) => r.rate,
            _ => r.rate || r.ang_accel || r.force,
        }
    }

    /// The residual `resid[channel·BLOCK + i]` = output − the fitted model at each sensor's
    /// `states` of the block (the motion it sees); `output(sensor, i)` is the recorded one.
    pub(super) fn residual(
        &mut self,
        states: &[Vec<State>; 2],
        output: impl Fn(usize, usize) -> [f64; 3],
        resid: &mut [f64],
    ) {
        for (si, p) in self.predict.iter().enumerate() {
            let len = states[si].len();
            p.block(&states[si], &mut self.out0, &mut self.tmp);
            for (i, u) in self.out0[..len].iter().enumerate() {
                let y = output(si, i);
                for ch in 0..3 {
                    resid[(3 * si + ch) * BLOCK + i] = y[ch] - u[ch];
                }
            }
        }
    }

    /// The columns of the first `len` samples gathered: `dcol[(local·6 + channel)·BLOCK + i]`.
    pub(super) fn columns(&mut self, len: usize, dcol: &mut [f64]) {
        // Which of ω, ε and a each knob moved in this block (a tilt moves only a, the
        // Earth's rate only ω): a sensor whose model reads none of them has the outputs of
        // the base states there, so its columns are exactly zero without evaluating it.
        let base = &self.base[..len];
        for (j, m) in self.moved.iter_mut().enumerate() {
            if !matches!(self.short[j], Shortcut::Angle(..)) {
                *m = moved(&self.nudged[j * BLOCK..][..len], base);
            }
        }
        if self.through_angle {
            for (d, m) in self.angle_moved.iter_mut().enumerate() {
                *m = moved(&self.angle_nudged[d * BLOCK..][..len], base);
            }
        }
        for (si, p) in self.predict.iter().enumerate() {
            let reads = self.reads[si];
            let felt = |[w, e, a]: [bool; 3]| (w && reads.rate) || (e && reads.ang_accel) || (a && reads.force);
            p.block(base, &mut self.out0, &mut self.tmp);
            if self.through_angle {
                for (d, h) in ANGLE_STEP.iter().enumerate() {
                    let slopes = &mut self.slopes[d * BLOCK..][..len];
                    if !felt(self.angle_moved[d]) {
                        slopes.fill([0.0; 3]);
                        continue;
                    }
                    p.block(&self.angle_nudged[d * BLOCK..][..len], &mut self.out1, &mut self.tmp);
                    let inv_h = 1.0 / h;
                    for (i, sl) in slopes.iter_mut().enumerate() {
                        *sl = std::array::from_fn(|ch| (self.out1[i][ch] - self.out0[i][ch]) * inv_h);
                    }
                }
            }
            for (j, &(_, h)) in self.dirs.iter().enumerate() {
                if let Shortcut::Angle(..) = self.short[j] {
                    let partials = &self.partials[j * BLOCK..][..len];
                    for ch in 0..3 {
                        let col = &mut dcol[(j * 6 + 3 * si + ch) * BLOCK..][..len];
                        for (i, (d, q)) in col.iter_mut().zip(partials).enumerate() {
                            *d = self.slopes[i][ch] * q[0]
                                + self.slopes[BLOCK + i][ch] * q[1]
                                + self.slopes[2 * BLOCK + i][ch] * q[2];
                        }
                    }
                    continue;
                }
                if !felt(self.moved[j]) {
                    for ch in 0..3 {
                        dcol[(j * 6 + 3 * si + ch) * BLOCK..][..len].fill(0.0);
                    }
                    continue;
                }
                p.block(&self.nudged[j * BLOCK..][..len], &mut self.out1, &mut self.tmp);
                let inv_h = 1.0 / h;
                for ch in 0..3 {
                    let col = &mut dcol[(j * 6 + 3 * si + ch) * BLOCK..][..len];
                    for (i, d) in col.iter_mut().enumerate() {
                        *d = (self.out1[i][ch] - self.out0[i][ch]) * inv_h;
                    }
                }
            }
        }
    }
}

/// Whether the `nudged` states differ from the `base` ones in ω, ε and a.
fn moved(nudged: &[State], base: &[State]) -> [bool; 3] {
    let differs = |f: fn(&State) -> [f64; 3]| {
        nudged.iter().zip(base).any(|(x, y)| f(x).iter().zip(&f(y)).any(|(a, b)| a.to_bits() != b.to_bits()))
    };
    [differs(|s| s.w), differs(|s| s.e), differs(|s| s.a)]
}

/// Whether knob `k` moves the stand's angle (rate, phase, drift, ripple).
pub(super) fn moves_angle(k: usize) -> bool {
    matches!(k, 1..=3 | 6..=9)
}

/// Whether knob `k` belongs to a run whose stand logs its angle (`logs`): the log holds the
/// rate, drift and ripple; the phase is then the encoder's offset.
pub(super) fn follows(k: usize, logs: bool) -> bool {
    !(logs && moves_angle(k) && k != 2)
}

/// Applies a knob of a stand motion (rate relative to the label `declared_rate`).
pub(super) fn knob(m: &mut StandMotion, declared_rate: f64, k: usize, d: f64) {
    match k {
        0 => m.cone_angle_rad += d,
        1 => m.rate_rad_s += d * declared_rate,
        2 => m.phase_rad += d,
        3 => m.rate_drift_per_s += d,
        4 | 5 => m.tilt_rad[k - 4] += d,
        6..=9 => m.ripple_rad[(k - 6) / 2][(k - 6) % 2] += d,
        10 | 11 => m.wobble_rad[k - 10] += d,
        _ => m.earth_rad_s[k - 12] += d,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_nearby_angles_sine_is_libms_to_rounding() {
        for &t0 in &[0.0, 1.0, -3.0, 250.0, 1.0e4] {
            let sc0 = libm::sincos(t0);
            for &d in &[0.0, 1e-9, -3e-6, 2e-3, -0.0099, 0.02, -0.037, 0.0499, 0.07] {
                let (s, c) = sincos_near(t0 + d, t0, sc0);
                let (s1, c1) = libm::sincos(t0 + d);
                assert!((s - s1).abs() < 4e-16 && (c - c1).abs() < 4e-16, "θ₀ {t0}, d {d}: {s} {s1} {c} {c1}");
            }
        }
    }
}
