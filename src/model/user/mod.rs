//! User effects: physics the catalogue lacks, written by the user as one expression in an
//! effects file (TOML, see `docs/reference-effects.md`) and then an effect like any other.
//!
//! An output-side effect adds `expr` to one output channel of one sensor:
//! `u_i += f(state; k, p)`, affine in its coefficients `k` (checked at load, symbolically:
//! each ∂f/∂k_j must be free of every coefficient, and f(k = 0) must be 0), so
//! `f = Σ_j k_j ∂f/∂k_j` and each coefficient's regressor is its compiled derivative —
//! the same [`Effect`] the built-in effects implement, through the same Grams, the same
//! streamed fit and the same fixed-point inverse. Its nonlinear parameters `p` (start
//! values in the file) ride on the existing variable projection: a companion
//! [`NonlinearEffect`] holds them, and [`Effect::rebind`] gives the linear part at the
//! values being tried.
//!
//! An input-side effect (`side = "input"`) perturbs the true input of its axis before the
//! coupling, `x_i ← x_i + f(x)`, with every coefficient and parameter refined by the
//! variable projection; it reads the sensor's own input only, so that the correction can
//! invert it per sample (fixed point `x = z − f(x)`, flagged when it does not converge).

pub mod expr;
mod file;

pub(crate) use file::compile;
pub use file::{load_file, load_str, UserEffectError};

use super::nonlinear::{NonlinearEffect, ParamDef};
use super::{Effect, Inputs, Key, Role, SensorKind, Side, State, Term, AXES};
use crate::motion::{SampleMap, SensorKinematics, Track};
use expr::{Program, MAX_SLOTS, VARIABLES};
use serde::{Deserialize, Serialize};
use std::collections::HashSet;
use std::sync::{Arc, Mutex, OnceLock};

/// Where a user effect acts.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum UserSide {
    /// Added to the output channel.
    #[default]
    Output,
    /// Added to the true input of its axis before the coupling.
    Input,
}

/// A nonlinear parameter of a user effect with its start value (SI).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct UserParam {
    /// Name as used in the expression.
    pub name: String,
    /// Start value.
    pub start: f64,
}

/// A user effect's definition, as the effects file gives it and as a profile stores it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct UserEffectDef {
    /// Identifier (command line, profiles, reports, the ladder).
    pub id: String,
    /// The sensor it acts on.
    pub sensor: SensorKind,
    /// The output channel (output side) or input axis (input side): `x`, `y` or `z`.
    pub output: String,
    /// The expression.
    pub expr: String,
    /// Coefficients that enter linearly.
    #[serde(default)]
    pub coefficients: Vec<String>,
    /// Parameters that enter nonlinearly, with start values.
    #[serde(default)]
    pub parameters: Vec<UserParam>,
    /// What it models, for users.
    #[serde(default)]
    pub description: String,
    /// Where it acts.
    #[serde(default)]
    pub side: UserSide,
}

/// Interns a string for the `&'static str` names of the effect traits: each distinct text
/// is kept once for the life of the process (bounded by the definitions loaded).
pub(crate) fn intern(s: &str) -> &'static str {
    static SET: OnceLock<Mutex<HashSet<&'static str>>> = OnceLock::new();
    let mut set = SET.get_or_init(Default::default).lock().unwrap_or_else(|e| e.into_inner());
    if let Some(&k) = set.get(s) {
        return k;
    }
    let k: &'static str = Box::leak(s.to_string().into_boxed_str());
    set.insert(k);
    k
}

/// A compiled user effect (see the module docs).
#[derive(Debug, Clone)]
pub struct UserEffect {
    def: UserEffectDef,
    id: &'static str,
    explain: &'static str,
    axis: usize,
    /// The whole expression.
    value: Program,
    /// ∂f/∂k_j per coefficient (output side).
    regs: Vec<Program>,
    terms: Vec<Term>,
    /// Parameter values the linear part is evaluated at.
    bound: Vec<f64>,
    /// The regressors' slots after the variables: a zero per coefficient (the derivatives
    /// do not read them), then `bound`.
    reg_extra: Vec<f64>,
    inputs: Inputs,
}

impl UserEffect {
    /// The definition (what a profile stores).
    pub fn definition(&self) -> &UserEffectDef {
        &self.def
    }

    /// The variable slots (see [`VARIABLES`]) of a state.
    #[inline]
    fn vars(s: &State) -> [f64; VARIABLES.len()] {
        let [wx, wy, wz] = s.w;
        let [ex, ey, ez] = s.e;
        let [ax, ay, az] = s.a;
        [wx, wy, wz, ex, ey, ez, ax, ay, az, s.temp_c, s.temp_rate_c_s, s.t_session_s]
    }

    /// The effect's value at a state for coefficients `coef` and parameters `params`.
    pub fn value_at(&self, s: &State, coef: &[f64], params: &[f64]) -> f64 {
        let mut extra = [0.0; MAX_SLOTS - VARIABLES.len()];
        let nc = self.def.coefficients.len().min(extra.len());
        for (d, c) in extra[..nc].iter_mut().zip(coef) {
            *d = *c;
        }
        for (d, p) in extra[nc..].iter_mut().zip(params) {
            *d = *p;
        }
        self.value.eval_parts(&Self::vars(s), &extra)
    }

    /// Where it acts.
    pub fn user_side(&self) -> UserSide {
        self.def.side
    }

    /// Whether it has linear coefficients fitted by least squares (output side).
    pub fn has_linear(&self) -> bool {
        self.def.side == UserSide::Output && !self.def.coefficients.is_empty()
    }

    /// Whether it has parameters refined by the variable projection.
    pub fn has_nonlinear(&self) -> bool {
        match self.def.side {
            UserSide::Output => !self.def.parameters.is_empty(),
            UserSide::Input => true,
        }
    }

    /// The nonlinear part's parameter definitions: the parameters (output side), or the
    /// coefficients and then the parameters (input side).
    fn param_defs(&self) -> Vec<ParamDef> {
        let coefs = match self.def.side {
            UserSide::Input => self.def.coefficients.iter().map(|c| (c.as_str(), 0.0)).collect(),
            UserSide::Output => Vec::new(),
        };
        coefs
            .into_iter()
            .chain(self.def.parameters.iter().map(|p| (p.name.as_str(), p.start)))
            .map(|(name, start)| ParamDef {
                name: format!("{}.{name}", self.def.id),
                unit: "user",
                nominal: start,
                // A tenth of the start value (the size the user expects), else 0.01.
                scale: if start != 0.0 { 0.1 * start.abs() } else { 0.01 },
                min: f64::NEG_INFINITY,
                max: f64::INFINITY,
            })
            .collect()
    }

    /// The linear part with its parameters at `p`.
    fn bound_to(&self, p: &[f64]) -> Self {
        let mut e = self.clone();
        e.bound = p.to_vec();
        e.reg_extra = regressor_slots(&self.def, p);
        e
    }

    /// The first of `states` where the expression is not finite (start or bound
    /// parameters, every coefficient 1), if any.
    pub fn first_non_finite(&self, states: impl IntoIterator<Item = State>) -> Option<State> {
        let ones = vec![1.0; self.def.coefficients.len()];
        let params: Vec<f64> = if self.bound.is_empty() {
            self.def.parameters.iter().map(|p| p.start).collect()
        } else {
            self.bound.clone()
        };
        states.into_iter().find(|s| !self.value_at(s, &ones, &params).is_finite())
    }
}

impl Effect for UserEffect {
    fn id(&self) -> &'static str {
        self.id
    }

    fn sensor(&self) -> SensorKind {
        self.def.sensor
    }

    fn explain(&self) -> &'static str {
        self.explain
    }

    fn terms(&self) -> &[Term] {
        &self.terms
    }

    #[inline]
    fn regressor(&self, k: usize, s: &State) -> f64 {
        match self.regs.get(k) {
            Some(p) => p.eval_parts(&Self::vars(s), &self.reg_extra),
            None => 0.0,
        }
    }

    fn inputs(&self) -> Inputs {
        self.inputs
    }

    fn rebind(&self, p: &[f64]) -> Option<Arc<dyn Effect>> {
        Some(Arc::new(self.bound_to(p)))
    }

    fn user_definition(&self) -> Option<&UserEffectDef> {
        Some(&self.def)
    }
}

/// The nonlinear part of a user effect (its parameters; on the input side the whole effect).
#[derive(Debug, Clone)]
pub struct UserNonlinear(pub Arc<UserEffect>);

impl NonlinearEffect for UserNonlinear {
    fn id(&self) -> &'static str {
        self.0.id
    }

    fn sensor(&self) -> Option<SensorKind> {
        Some(self.0.def.sensor)
    }

    fn explain(&self) -> &'static str {
        self.0.explain
    }

    fn inputs(&self) -> Inputs {
        self.0.inputs
    }

    fn side(&self) -> Side {
        match self.0.def.side {
            UserSide::Output => Side::Output,
            UserSide::Input => Side::Input,
        }
    }

    fn params(&self) -> Vec<ParamDef> {
        self.0.param_defs()
    }

    /// Output side: the motion is unchanged (the parameters act through the bound linear
    /// part). Input side: `x_i ← x_i + f(x)` per sample.
    fn transform(&self, p: &[f64], track: &Track) -> Track {
        match self.0.def.side {
            UserSide::Output => track.clone(),
            UserSide::Input => track.mapped(Arc::new(InputShift { effect: Arc::clone(&self.0), p: p.to_vec() })),
        }
    }

    /// Input side: solves `z = x + f(x)` on the effect's axis by fixed point from `x = z`,
    /// at most 50 passes to a relative change of 1e-12; an axis that does not converge (or
    /// is not finite) is flagged.
    fn invert_sample(&self, p: &[f64], sensor: SensorKind, z: &mut [f64; 3], _noise: &[f64; 3]) -> u8 {
        let e = &self.0;
        if sensor != e.def.sensor || e.def.side != UserSide::Input {
            return 0;
        }
        let (coef, params) = p.split_at(e.def.coefficients.len().min(p.len()));
        let i = e.axis;
        let target = z[i];
        let mut x = *z;
        for _ in 0..50 {
            let s = own_state(sensor, &x);
            let next = target - e.value_at(&s, coef, params);
            if !next.is_finite() {
                break;
            }
            let change = (next - x[i]).abs();
            x[i] = next;
            if change <= 1e-12 * x[i].abs().max(f64::MIN_POSITIVE) {
                *z = x;
                return 0;
            }
        }
        z[i] = 0.0;
        1 << i
    }

    fn user_definition(&self) -> Option<&UserEffectDef> {
        Some(&self.0.def)
    }
}

/// A state whose own input of `sensor` is `x` (the rest zero).
fn own_state(sensor: SensorKind, x: &[f64; 3]) -> State {
    match sensor {
        SensorKind::Gyro => State { w: *x, ..State::default() },
        SensorKind::Accel => State { a: *x, ..State::default() },
    }
}

/// The input-side perturbation as a per-sample change of the motion.
#[derive(Debug)]
struct InputShift {
    effect: Arc<UserEffect>,
    p: Vec<f64>,
}

impl SampleMap for InputShift {
    #[inline]
    fn apply(&self, k: &mut SensorKinematics) {
        let e = &self.effect;
        let s = State { w: k.w_rad_s.xyz, e: k.e_rad_s2.xyz, a: k.a_m_s2.xyz, ..State::default() };
        let (coef, params) = self.p.split_at(e.def.coefficients.len().min(self.p.len()));
        let d = e.value_at(&s, coef, params);
        let x = match e.def.sensor {
            SensorKind::Gyro => &mut k.w_rad_s.xyz,
            SensorKind::Accel => &mut k.a_m_s2.xyz,
        };
        x[e.axis] += d;
    }
}

/// The effects registered in this process (from `--effects-file`, Python's `effects=`):
/// found by id beside the catalogue by [`super::find`] and listed by [`super::catalog`].
fn registry() -> &'static Mutex<Vec<Arc<UserEffect>>> {
    static R: OnceLock<Mutex<Vec<Arc<UserEffect>>>> = OnceLock::new();
    R.get_or_init(Default::default)
}

/// Registers user effects; one with the id of a registered one replaces it.
pub fn register(effects: &[Arc<UserEffect>]) {
    let mut r = registry().lock().unwrap_or_else(|e| e.into_inner());
    for e in effects {
        r.retain(|x| x.id != e.id);
        r.push(Arc::clone(e));
    }
}

/// The registered user effects, in registration order.
pub fn registered() -> Vec<Arc<UserEffect>> {
    registry().lock().unwrap_or_else(|e| e.into_inner()).clone()
}

/// A registered user effect by id.
pub fn find_registered(id: &str) -> Option<Arc<UserEffect>> {
    registry().lock().unwrap_or_else(|e| e.into_inner()).iter().find(|e| e.id == id).cloned()
}

/// The slots after the variables for the regressors at parameters `bound`.
fn regressor_slots(def: &UserEffectDef, bound: &[f64]) -> Vec<f64> {
    std::iter::repeat_n(0.0, def.coefficients.len()).chain(bound.iter().copied()).collect()
}

/// The term of coefficient `j` of an output-side effect.
fn term(def: &UserEffectDef, id: &'static str, axis: usize, j: usize, coef: &str) -> Term {
    Term {
        name: format!("{}.{coef}", def.id),
        channel: axis,
        key: Key::Own(id, j as u8),
        label: format!("d({})/d{coef}", def.expr),
        unit: "user",
        nominal: 0.0,
        drop_priority: 4,
        role: Role::Other,
    }
}

/// Which quantities an expression reads.
fn inputs_of(node: &expr::Node) -> Inputs {
    let reads = |r: std::ops::Range<usize>| node.uses_any(r);
    Inputs {
        rate: reads(0..3),
        ang_accel: reads(3..6),
        force: reads(6..9),
        temperature: reads(9..10),
        temperature_rate: reads(10..11),
        time: reads(11..12),
    }
}

/// Axis index of `x`, `y` or `z`.
fn axis_of(s: &str) -> Option<usize> {
    AXES.iter().position(|a| a.to_string() == s)
}

#[cfg(test)]
mod tests {
    use super::*;

    const INPUT: &str = "[[effect]]\nid = \"in-x\"\nsensor = \"gyro\"\noutput = \"x\"\nside = \"input\"\nexpr = \"s * w_x\"\nparameters = { s = 0.5 }\n";

    /// The input side's inverse solves z = x + s·x by fixed point: it converges for
    /// |s| < 1 (x = z / (1 + s), no flag) and is flagged (bit of its axis, value zeroed)
    /// where the iteration diverges.
    #[test]
    #[allow(clippy::float_cmp)] // untouched values are compared bit for bit on purpose
    fn the_input_side_inverse_converges_or_flags_the_sample() {
        let e = load_str("t.toml", INPUT).unwrap().remove(0);
        let nl = UserNonlinear(e);
        let mut z = [0.3, -0.2, 0.1];
        assert_eq!(nl.invert_sample(&[0.5], SensorKind::Gyro, &mut z, &[0.0; 3]), 0);
        assert!((z[0] - 0.3 / 1.5).abs() < 1e-12 && z[1] == -0.2 && z[2] == 0.1, "{z:?}");
        // The accelerometer is not its sensor: untouched.
        let mut a = [1.0, 2.0, 3.0];
        assert_eq!(nl.invert_sample(&[0.5], SensorKind::Accel, &mut a, &[0.0; 3]), 0);
        assert_eq!(a, [1.0, 2.0, 3.0]);
        // s = 2: x ← z − 2x diverges; the sample is flagged on x.
        let mut z = [0.3, -0.2, 0.1];
        assert_eq!(nl.invert_sample(&[2.0], SensorKind::Gyro, &mut z, &[0.0; 3]), 1);
        assert_eq!(z[0], 0.0);
    }
}
