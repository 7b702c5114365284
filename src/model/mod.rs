//! The effects catalogue: each physical effect is one file that says which sensor it acts
//! on, which coefficients it adds (per output channel), the regressor each coefficient
//! multiplies, and a paragraph a user can read.
//!
//! # Forward model and conventions
//! All quantities are in the **sensor frame** and SI units (rad/s, rad/s², m/s², s, °C).
//! For each sensor (gyro, accelerometer) and output channel i ∈ {x, y, z}:
//! ```text
//! u_i = Σ_k θ_ik φ_ik(state)            (forward model, u = f(true))
//! ```
//! where φ are the regressors an effect defines from the true state (ω, ε, a, t, temp and
//! its rate of change).
//! The paper's model (eqs. 3–4) is the special case `u = b + C_ω ω + C_ε ε` (gyro) and
//! `u = b + K a` (accelerometer); matrices are row-major: `C_ω[i][j]` (named `c_ij`) is the
//! weight of true rate j in output i.
//!
//! # Adding an effect
//! Write one file with a type implementing [`Effect`] and add it to [`catalog`].

mod angular_accel;
mod anisoelastic;
mod bias;
mod coupling;
mod cubic;
mod dead_zone;
mod drift;
mod g_sensitivity;
mod hysteresis;
mod lever_arm;
pub mod nonlinear;
mod predict;
mod quadratic;
mod scale_asymmetry;
mod temp_bias;
mod temp_hysteresis;
mod temp_scale;
mod time_delay;
pub mod user;

pub use angular_accel::AngularAcceleration;
pub use anisoelastic::Anisoelastic;
pub use bias::Bias;
pub use coupling::ScaleCoupling;
pub use cubic::Cubic;
pub use dead_zone::DeadZone;
pub use drift::Drift;
pub use g_sensitivity::GSensitivity;
pub use hysteresis::Hysteresis;
pub use lever_arm::LeverArm;
pub use nonlinear::{NonlinearEffect, ParamDef};
pub use predict::{forward, scale_matrix, Predictor};
pub use quadratic::Quadratic;
pub use scale_asymmetry::ScaleAsymmetry;
pub use temp_bias::TempBias;
pub use temp_hysteresis::TempHysteresis;
pub use temp_scale::TempScale;
pub use time_delay::TimeDelay;
pub use user::UserEffectDef;

pub(crate) use crate::units::{SensorKind, AXES};
use serde::{Deserialize, Serialize};
use std::fmt;
use std::sync::Arc;

/// The true state a regressor may depend on (sensor frame, SI).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct State {
    /// Time on the session clock, s: the time stamp as recorded, or the run's declared
    /// `start_s` plus the time since its first sample (what drift is measured against).
    pub t_session_s: f64,
    /// Angular rate, rad/s.
    pub w: [f64; 3],
    /// Angular acceleration, rad/s².
    pub e: [f64; 3],
    /// Specific force, m/s².
    pub a: [f64; 3],
    /// Temperature, °C (NaN when unknown).
    pub temp_c: f64,
    /// The temperature's rate of change, °C/s, smoothed over seconds
    /// ([`crate::stats::temp_rate`]: centred offline, causal when streaming; 0 at a run's
    /// declared constant temperature; NaN when unknown): the thermal branch a sample is on.
    pub temp_rate_c_s: f64,
}

/// How a coefficient enters the correction (lets the shared corrector invert linear parts
/// exactly and treat the rest by fixed-point iteration).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case", tag = "kind", content = "input")]
pub enum Role {
    /// Constant offset of the channel.
    Bias,
    /// Entry (channel, input) of the sensor's scale/coupling matrix: multiplies the
    /// sensor's own true quantity `input` (ω for the gyro, a for the accelerometer).
    Scale(usize),
    /// Entry (channel, input) of the gyro's angular-acceleration matrix C_ε (multiplies ε).
    Epsilon(usize),
    /// Any other regressor (handled by the effect's own regressor in the corrector).
    Other,
}

/// One coefficient an effect adds.
#[derive(Debug, Clone, PartialEq)]
pub struct Term {
    /// Unique coefficient name, e.g. `gyro.c_xy`.
    pub name: String,
    /// Output channel it acts on, 0..3.
    pub channel: usize,
    /// Its regressor (terms with equal keys share a design column).
    pub key: Key,
    /// The regressor in words, for users (`w_x^2`, `(T-20)`, …).
    pub label: String,
    /// Unit of the coefficient (SI; "raw" sessions put the recorded unit in place of SI).
    pub unit: &'static str,
    /// Value assumed when the coefficient is not fitted (1 for diagonal scales, else 0).
    pub nominal: f64,
    /// Which coefficient to drop first when a combination is unidentifiable (higher first).
    pub drop_priority: u8,
    /// How it enters the correction.
    pub role: Role,
}

/// What a coefficient multiplies: a component of the true state, the constant, or a
/// function of the state that only one effect defines. Terms with equal keys share one
/// column of the design.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Key {
    /// The constant 1 (a bias).
    One,
    /// Component `j` of the true angular rate ω.
    Rate(u8),
    /// Component `j` of the true angular acceleration ε.
    AngAccel(u8),
    /// Component `j` of the true specific force a.
    Force(u8),
    /// A regressor of the named effect's own; the code tells its regressors apart (equal
    /// codes are equal functions of the state, shared by the channels that use them).
    Own(&'static str, u8),
}

impl fmt::Display for Key {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match *self {
            Self::One => f.write_str("1"),
            Self::Rate(j) => write!(f, "w_{}", AXES[usize::from(j)]),
            Self::AngAccel(j) => write!(f, "e_{}", AXES[usize::from(j)]),
            Self::Force(j) => write!(f, "a_{}", AXES[usize::from(j)]),
            Self::Own(id, code) => write!(f, "{id}#{code}"),
        }
    }
}

/// The quantities an effect's regressors read from the true state.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Inputs {
    /// Angular rate ω.
    pub rate: bool,
    /// Angular acceleration ε (or a rate of change of the state).
    pub ang_accel: bool,
    /// Specific force a.
    pub force: bool,
    /// Time.
    pub time: bool,
    /// Temperature.
    pub temperature: bool,
    /// The temperature's rate of change (which thermal branch a sample is on).
    pub temperature_rate: bool,
}

impl Inputs {
    /// Nothing: a constant.
    pub const NONE: Self =
        Self { rate: false, ang_accel: false, force: false, time: false, temperature: false, temperature_rate: false };
    /// The angular rate alone.
    pub const RATE: Self = Self { rate: true, ..Self::NONE };
    /// The specific force alone.
    pub const FORCE: Self = Self { force: true, ..Self::NONE };

    /// The sensor's own input: ω for the gyro, a for the accelerometer.
    pub fn own(sensor: SensorKind) -> Self {
        match sensor {
            SensorKind::Gyro => Self::RATE,
            SensorKind::Accel => Self::FORCE,
        }
    }

    /// Also reads `other`.
    pub const fn and(self, other: Self) -> Self {
        Self {
            rate: self.rate || other.rate,
            ang_accel: self.ang_accel || other.ang_accel,
            force: self.force || other.force,
            time: self.time || other.time,
            temperature: self.temperature || other.temperature,
            temperature_rate: self.temperature_rate || other.temperature_rate,
        }
    }
}

/// Where an effect acts: on the sensor's physical input, before the scale/coupling matrix
/// (`u = K (x + Δ) + b`), or on its output, after it (`u = K x + b + g`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Side {
    /// Added to the output.
    Output,
    /// Changes the input the sensing element sees.
    Input,
}

/// A physical effect: a set of coefficients with their regressors.
pub trait Effect: Send + Sync + fmt::Debug {
    /// Identifier used on the command line and in profiles (e.g. `gyro-scale-coupling`).
    fn id(&self) -> &'static str;
    /// The sensor the effect acts on.
    fn sensor(&self) -> SensorKind;
    /// A paragraph explaining the physics, for users.
    fn explain(&self) -> &'static str;
    /// The coefficients, in a fixed order.
    fn terms(&self) -> &[Term];
    /// Regressor of term `k` at a true state.
    fn regressor(&self, k: usize, s: &State) -> f64;
    /// Regressor of term `k` at each of `states`, into `out` (same length): one dynamic
    /// call per block of samples, the per-sample [`Effect::regressor`] inlined in the loop.
    fn regressors(&self, k: usize, states: &[State], out: &mut [f64]) {
        for (o, s) in out.iter_mut().zip(states) {
            *o = self.regressor(k, s);
        }
    }
    /// The quantities the regressors read.
    fn inputs(&self) -> Inputs;
    /// Where the effect acts (output side unless it says otherwise).
    fn side(&self) -> Side {
        Side::Output
    }
    /// For an effect on the input side: how term `k`'s perturbation of the sensing element's
    /// input decomposes over the input axes, as (input axis j, index of the term of this
    /// effect whose regressor is component j). Channel i then sees `Σ_j K_ij · component_j`
    /// (the element's row of the scale/coupling matrix applied to its perturbed input).
    /// Empty for output-side effects.
    fn input_components(&self, _k: usize) -> Vec<(usize, usize)> {
        Vec::new()
    }
    /// Whether the regressors need a temperature (a `temp` column or `temperature_c`).
    fn needs_temperature(&self) -> bool {
        self.inputs().temperature
    }
    /// The effect with its regressors at nonlinear parameter values `p` (a user effect whose
    /// expression also has parameters: see [`user`]); None for effects without parameters.
    fn rebind(&self, _p: &[f64]) -> Option<Arc<dyn Effect>> {
        None
    }
    /// The definition of a user effect (what a profile stores to stay self-contained).
    fn user_definition(&self) -> Option<&user::UserEffectDef> {
        None
    }
}

/// Reference temperature of the temperature effects, °C.
pub const T_REF_C: f64 = 20.0;

/// The sensor's own true input: ω for the gyro, a for the accelerometer.
#[inline]
pub fn own_input(sensor: SensorKind, s: &State) -> [f64; 3] {
    match sensor {
        SensorKind::Gyro => s.w,
        SensorKind::Accel => s.a,
    }
}

/// Name of the sensor's own input for regressor keys (`w` or `a`).
pub fn input_letter(sensor: SensorKind) -> &'static str {
    match sensor {
        SensorKind::Gyro => "w",
        SensorKind::Accel => "a",
    }
}

/// SI unit of the sensor's output.
pub fn output_unit(sensor: SensorKind) -> &'static str {
    match sensor {
        SensorKind::Gyro => "rad/s",
        SensorKind::Accel => "m/s^2",
    }
}

/// One term per output channel i, named `<sensor>.<letter>_<axis>`, with a regressor of
/// effect `id` (described by `label(i)`): its own per channel (code i), or with `shared`
/// one for all three (code 0).
pub fn per_axis_terms(
    sensor: SensorKind,
    letter: &str,
    id: &'static str,
    shared: bool,
    label: impl Fn(usize) -> String,
    unit: &'static str,
) -> Vec<Term> {
    (0..3)
        .map(|i| Term {
            name: format!("{}.{letter}_{}", sensor.as_str(), AXES[i]),
            channel: i,
            key: Key::Own(id, if shared { 0 } else { i as u8 }),
            label: label(i),
            unit,
            nominal: 0.0,
            drop_priority: 4,
            role: Role::Other,
        })
        .collect()
}

/// A catalogue effect, linear in its coefficients or with nonlinear parameters: the one
/// list callers go through.
#[derive(Debug, Clone)]
pub enum CatalogEffect {
    /// Coefficients that multiply regressors of the true state.
    Linear(Arc<dyn Effect>),
    /// Parameters that change the motion as the sensor sees it.
    Nonlinear(Arc<dyn NonlinearEffect>),
}

impl CatalogEffect {
    /// Identifier (command line, profiles).
    pub fn id(&self) -> &'static str {
        match self {
            Self::Linear(e) => e.id(),
            Self::Nonlinear(e) => e.id(),
        }
    }

    /// The sensor it acts on (None: both).
    pub fn sensor(&self) -> Option<SensorKind> {
        match self {
            Self::Linear(e) => Some(e.sensor()),
            Self::Nonlinear(e) => e.sensor(),
        }
    }

    /// A paragraph explaining the physics.
    pub fn explain(&self) -> &'static str {
        match self {
            Self::Linear(e) => e.explain(),
            Self::Nonlinear(e) => e.explain(),
        }
    }

    /// The quantities of the true state it reads.
    pub fn inputs(&self) -> Inputs {
        match self {
            Self::Linear(e) => e.inputs(),
            Self::Nonlinear(e) => e.inputs(),
        }
    }

    /// Where it acts.
    pub fn side(&self) -> Side {
        match self {
            Self::Linear(e) => e.side(),
            Self::Nonlinear(e) => e.side(),
        }
    }

    /// Whether it needs a temperature.
    pub fn needs_temperature(&self) -> bool {
        self.inputs().temperature
    }

    /// Its coefficients (or nonlinear parameters), for users.
    pub fn coefficients(&self) -> Vec<CoefficientInfo> {
        match self {
            Self::Linear(e) => e
                .terms()
                .iter()
                .map(|t| CoefficientInfo {
                    name: t.name.clone(),
                    unit: t.unit.to_string(),
                    regressor: Some(t.label.clone()),
                    nominal: t.nominal,
                })
                .collect(),
            Self::Nonlinear(e) => e
                .params()
                .into_iter()
                .map(|p| CoefficientInfo {
                    name: p.name,
                    unit: p.unit.to_string(),
                    regressor: None,
                    nominal: p.nominal,
                })
                .collect(),
        }
    }
}

/// A coefficient or parameter of a catalogue effect, as `crosscal effects` lists it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CoefficientInfo {
    /// Name, e.g. `gyro.c_xy`.
    pub name: String,
    /// SI unit.
    pub unit: String,
    /// What it multiplies, in words (linear effects).
    pub regressor: Option<String>,
    /// Value when absent or not fitted.
    pub nominal: f64,
}

/// Every linear effect, in catalogue order.
fn linear_catalog() -> Vec<Arc<dyn Effect>> {
    vec![
        Arc::new(Bias::new(SensorKind::Gyro)),
        Arc::new(ScaleCoupling::new(SensorKind::Gyro)),
        Arc::new(AngularAcceleration::new()),
        Arc::new(Bias::new(SensorKind::Accel)),
        Arc::new(ScaleCoupling::new(SensorKind::Accel)),
        Arc::new(GSensitivity::new()),
        Arc::new(Anisoelastic::new()),
        Arc::new(Quadratic::new(SensorKind::Gyro)),
        Arc::new(Quadratic::new(SensorKind::Accel)),
        Arc::new(Cubic::new(SensorKind::Gyro)),
        Arc::new(Cubic::new(SensorKind::Accel)),
        Arc::new(ScaleAsymmetry::new(SensorKind::Gyro)),
        Arc::new(ScaleAsymmetry::new(SensorKind::Accel)),
        Arc::new(TempBias::new(SensorKind::Gyro)),
        Arc::new(TempBias::new(SensorKind::Accel)),
        Arc::new(TempBias::with_degree(SensorKind::Gyro, 2)),
        Arc::new(TempBias::with_degree(SensorKind::Accel, 2)),
        Arc::new(TempBias::with_degree(SensorKind::Gyro, 3)),
        Arc::new(TempBias::with_degree(SensorKind::Accel, 3)),
        Arc::new(TempScale::new(SensorKind::Gyro)),
        Arc::new(TempScale::new(SensorKind::Accel)),
        Arc::new(TempScale::with_degree(SensorKind::Gyro, 2)),
        Arc::new(TempScale::with_degree(SensorKind::Accel, 2)),
        Arc::new(TempScale::with_degree(SensorKind::Gyro, 3)),
        Arc::new(TempScale::with_degree(SensorKind::Accel, 3)),
        Arc::new(TempHysteresis::new(SensorKind::Gyro)),
        Arc::new(TempHysteresis::new(SensorKind::Accel)),
        Arc::new(Drift::new(SensorKind::Gyro)),
        Arc::new(Drift::new(SensorKind::Accel)),
        Arc::new(LeverArm::new()),
        Arc::new(Hysteresis::new(SensorKind::Gyro)),
        Arc::new(Hysteresis::new(SensorKind::Accel)),
    ]
}

/// Every effect with nonlinear parameters.
fn nonlinear_catalog() -> Vec<Arc<dyn NonlinearEffect>> {
    vec![Arc::new(TimeDelay), Arc::new(DeadZone::new(SensorKind::Gyro)), Arc::new(DeadZone::new(SensorKind::Accel))]
}

/// Every effect crosscal knows, linear ones first, in catalogue order, then the user
/// effects registered in this process.
pub fn catalog() -> Vec<CatalogEffect> {
    linear_catalog()
        .into_iter()
        .map(CatalogEffect::Linear)
        .chain(nonlinear_catalog().into_iter().map(CatalogEffect::Nonlinear))
        .chain(user_catalog())
        .collect()
}

/// The user effects registered in this process ([`user::register`]), as catalogue
/// entries: linear when they have coefficients on the output side, else nonlinear.
fn user_catalog() -> Vec<CatalogEffect> {
    user::registered()
        .into_iter()
        .map(|u| {
            if u.has_linear() {
                CatalogEffect::Linear(u)
            } else {
                CatalogEffect::Nonlinear(Arc::new(user::UserNonlinear(u)))
            }
        })
        .collect()
}

/// Ids of the built-in effects (user effects may not take them).
pub fn builtin_ids() -> Vec<&'static str> {
    linear_catalog().iter().map(|e| e.id()).chain(nonlinear_catalog().iter().map(|e| e.id())).collect()
}

/// Finds a catalogue effect (built in, or a registered user effect) by id.
pub fn find(id: &str) -> Option<CatalogEffect> {
    catalog().into_iter().find(|e| e.id() == id)
}

/// Finds a linear catalogue effect by id.
fn find_effect(id: &str) -> Option<Arc<dyn Effect>> {
    linear_catalog().into_iter().find(|e| e.id() == id)
}

/// Ids of every catalogue effect, linear and nonlinear.
pub fn all_effect_ids() -> Vec<&'static str> {
    catalog().iter().map(CatalogEffect::id).collect()
}

/// Whether a coefficient is estimated or held at a value.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case", tag = "status", content = "value")]
pub enum TermStatus {
    /// Estimated from the data.
    Fitted,
    /// Held at this value.
    Fixed(f64),
}

/// A nonlinear effect in a model, with its parameter values.
#[derive(Debug, Clone)]
pub struct NonlinearEntry {
    /// The effect.
    pub effect: Arc<dyn NonlinearEffect>,
    /// Current (start or fixed) parameter values.
    pub values: Vec<f64>,
    /// Whether the parameters are estimated (false: held at `values`).
    pub fitted: bool,
    /// A start near the optimum ([`Model::start_near`]): the step per parameter within
    /// which `values` are known to lie of it. None: the search scans from `values`.
    pub near: Option<Vec<f64>>,
}

/// A model: effects plus, per coefficient, whether it is fitted.
#[derive(Debug, Clone)]
pub struct Model {
    /// Name of the preset or description.
    pub name: String,
    effects: Vec<Arc<dyn Effect>>,
    status: Vec<Vec<TermStatus>>,
    nonlinear: Vec<NonlinearEntry>,
}

/// Model construction errors.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum ModelError {
    /// Unknown effect id.
    #[error("unknown effect '{0}': known effects are {1}")]
    UnknownEffect(String, String),
    /// Unknown model preset.
    #[error("unknown model '{0}': expected 'default', 'paper', 'ferraris' or 'tedaldi'")]
    UnknownPreset(String),
    /// Unknown coefficient name.
    #[error("unknown coefficient '{0}' in this model")]
    UnknownCoefficient(String),
    /// A stored user effect's definition does not compile.
    #[error("user effect '{0}': {1}")]
    UserEffect(String, String),
}

/// The named starting points of a model.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Preset {
    /// Biases, full C_ω, full C_ε (gyro); bias, full K (accelerometer). On a protocol
    /// session it stands for that protocol's own preset (`ferraris` or `tedaldi`).
    #[default]
    Default,
    /// Exactly the paper's eqs. 3–4.
    Paper,
    /// What a Ferraris session identifies (imucal's model).
    Ferraris,
    /// What a multi-position session identifies (imu_tk's model).
    Tedaldi,
}

impl Preset {
    /// Every preset's name, for messages.
    pub const NAMES: &'static str = "default, paper, ferraris, tedaldi";

    /// The preset's model.
    pub fn model(self) -> Model {
        match self {
            Self::Default => Model::default_model(),
            Self::Paper => Model::paper(),
            Self::Ferraris => Model::ferraris(),
            Self::Tedaldi => Model::tedaldi(),
        }
    }
}

impl std::str::FromStr for Preset {
    type Err = ModelError;

    fn from_str(s: &str) -> Result<Self, ModelError> {
        match s {
            "default" => Ok(Self::Default),
            "paper" => Ok(Self::Paper),
            "ferraris" => Ok(Self::Ferraris),
            "tedaldi" => Ok(Self::Tedaldi),
            other => Err(ModelError::UnknownPreset(other.to_string())),
        }
    }
}

impl fmt::Display for Preset {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Self::Default => "default",
            Self::Paper => "paper",
            Self::Ferraris => "ferraris",
            Self::Tedaldi => "tedaldi",
        })
    }
}

/// A model as a user names it: a preset, catalogue effects added to it, coefficients held
/// at their nominal values. [`ModelSpec::build`] makes the model; the fit entry point
/// resolves [`Preset::Default`] for the kind of session it is given.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct ModelSpec {
    /// The starting point.
    pub preset: Preset,
    /// Catalogue effect ids added to it, in order.
    pub effects: Vec<String>,
    /// Coefficients held at their nominal values.
    pub disable: Vec<String>,
}

impl ModelSpec {
    /// The model, with `default` standing for `default_preset` (the session's own default).
    pub fn build_with_default(&self, default_preset: Preset) -> Result<Model, ModelError> {
        let preset = if self.preset == Preset::Default { default_preset } else { self.preset };
        let mut m = preset.model();
        for e in &self.effects {
            m.add_effect(e)?;
        }
        for d in &self.disable {
            m.disable(d)?;
        }
        Ok(m)
    }

    /// The model for a stand session.
    pub fn build(&self) -> Result<Model, ModelError> {
        self.build_with_default(Preset::Default)
    }
}

/// Paper eq. 3 coefficients (gyro) that the `paper` preset fits.
const PAPER_GYRO: [&str; 9] = [
    "gyro.c_xx",
    "gyro.c_yy",
    "gyro.c_zz",
    "gyro.c_xy",
    "gyro.c_yz",
    "gyro.c_zx",
    "gyro.e_xz",
    "gyro.e_yx",
    "gyro.e_zy",
];

impl Model {
    /// A model of the given effects with every coefficient fitted.
    pub fn from_effects(name: &str, effects: Vec<Arc<dyn Effect>>) -> Self {
        let status = effects.iter().map(|e| vec![TermStatus::Fitted; e.terms().len()]).collect();
        Self { name: name.to_string(), effects, status, nonlinear: Vec::new() }
    }

    /// A model named `name` of the catalogue effects `ids`, in that order, every
    /// coefficient fitted (as a profile records its model).
    pub fn named(name: &str, ids: &[String]) -> Result<Self, ModelError> {
        let mut m = Self::from_effects(name, Vec::new());
        for id in ids {
            m.add_effect(id)?;
        }
        m.name = name.to_string();
        Ok(m)
    }

    /// As [`Model::named`], the user effects among `ids` built from their stored
    /// definitions `users` (a profile's own, whatever is registered in the process).
    pub fn named_with_users(name: &str, ids: &[String], users: &[user::UserEffectDef]) -> Result<Self, ModelError> {
        let mut m = Self::from_effects(name, Vec::new());
        for id in ids {
            match users.iter().find(|d| d.id == *id) {
                Some(d) => {
                    let u = user::compile(d).map_err(|(_, msg)| ModelError::UserEffect(id.clone(), msg))?;
                    m.add_user(Arc::new(u));
                }
                None => m.add_effect(id)?,
            }
        }
        m.name = name.to_string();
        Ok(m)
    }

    /// The nonlinear effects.
    pub fn nonlinear(&self) -> &[NonlinearEntry] {
        &self.nonlinear
    }

    /// Starts the search for the parameters of the fitted nonlinear effect `id` at `values`,
    /// known to lie within about `steps` of the optimum (a fit of the same runs on fewer
    /// samples, or on a motion that has moved little since): the search then skips its
    /// coarse scan and takes Newton steps from there (a simplex of those steps when they
    /// fail). No-op when the model lacks the effect, holds its parameters, or the lengths
    /// do not match its parameters.
    pub fn start_near(&mut self, id: &str, values: &[f64], steps: Vec<f64>) {
        let Some(e) = self.nonlinear.iter_mut().find(|e| e.effect.id() == id && e.fitted) else {
            return;
        };
        if values.len() != e.values.len() || steps.len() != values.len() {
            return;
        }
        e.values = values.to_vec();
        e.near = Some(steps);
        self.rebind(id, values);
    }

    /// Takes `other`'s near starts ([`Model::start_near`]) for the fitted nonlinear effects
    /// this model shares with it and would search from their start values.
    pub fn starts_from(&mut self, other: &Model) {
        for o in &other.nonlinear {
            let Some(steps) = &o.near else { continue };
            if self.nonlinear.iter().any(|e| e.effect.id() == o.effect.id() && e.fitted && e.near.is_none()) {
                self.start_near(o.effect.id(), &o.values, steps.clone());
            }
        }
    }

    /// Holds a nonlinear effect's parameters at given values (adds it if absent).
    pub fn fix_nonlinear(&mut self, id: &str, values: Vec<f64>) -> Result<(), ModelError> {
        self.add_effect(id)?;
        if let Some(e) = self.nonlinear.iter_mut().find(|e| e.effect.id() == id) {
            e.values.clone_from(&values);
            e.fitted = false;
        }
        self.rebind(id, &values);
        Ok(())
    }

    /// Adds a user effect (no-op when one of its id is present): its linear part (output
    /// side, coefficients fitted) and its nonlinear part (parameters at their start values).
    pub fn add_user(&mut self, u: Arc<user::UserEffect>) {
        if self.has(u.id()) {
            return;
        }
        let id = u.id();
        if u.has_linear() {
            self.status.push(vec![TermStatus::Fitted; u.terms().len()]);
            self.effects.push(Arc::clone(&u) as Arc<dyn Effect>);
        }
        if u.has_nonlinear() {
            let effect: Arc<dyn NonlinearEffect> = Arc::new(user::UserNonlinear(u));
            let values = effect.params().iter().map(|p| p.nominal).collect();
            self.nonlinear.push(NonlinearEntry { effect, values, fitted: true, near: None });
        }
        self.name = format!("{}+{id}", self.name);
    }

    /// The linear part of effect `id` evaluated at nonlinear parameters `p` (user effects
    /// whose expressions have parameters; others are left as they are).
    fn rebind(&mut self, id: &str, p: &[f64]) {
        for e in self.effects.iter_mut().filter(|e| e.id() == id) {
            if let Some(b) = e.rebind(p) {
                *e = b;
            }
        }
    }

    /// The model with its linear parts at the nonlinear parameter values `values` (one
    /// vector per nonlinear entry): what the variable projection fits at each trial.
    pub fn at_nonlinear_values(&self, values: &[Vec<f64>]) -> Model {
        let mut m = self.clone();
        for (e, v) in self.nonlinear.iter().zip(values) {
            m.rebind(e.effect.id(), v);
        }
        m
    }

    /// Whether any linear part depends on nonlinear parameters (user effects with both).
    pub fn has_bound_parameters(&self) -> bool {
        self.nonlinear.iter().any(|n| self.effects.iter().any(|e| e.id() == n.effect.id()))
    }

    /// Definitions of the user effects in the model, in model order, each once.
    pub fn user_definitions(&self) -> Vec<user::UserEffectDef> {
        let mut out: Vec<user::UserEffectDef> = Vec::new();
        let defs = self
            .effects
            .iter()
            .filter_map(|e| e.user_definition().cloned())
            .chain(self.nonlinear.iter().filter_map(|e| e.effect.user_definition().cloned()));
        for d in defs {
            if !out.iter().any(|o| o.id == d.id) {
                out.push(d);
            }
        }
        out
    }

    /// The default model: biases, full C_ω, full C_ε (gyro); bias, full K (accelerometer).
    pub fn default_model() -> Self {
        let ids =
            ["gyro-bias", "gyro-scale-coupling", "gyro-angular-acceleration", "accel-bias", "accel-scale-coupling"];
        let effects = ids.iter().filter_map(|id| find_effect(id)).collect();
        Self::from_effects("default", effects)
    }

    /// Exactly the paper's structure: eq. 3 (diagonal, c_xy, c_yz, c_zx, e_xz, e_yx, e_zy;
    /// no bias) and eq. 4 (full K, no bias).
    pub fn paper() -> Self {
        let effects: Vec<Arc<dyn Effect>> =
            ["gyro-scale-coupling", "gyro-angular-acceleration", "accel-scale-coupling"]
                .iter()
                .filter_map(|id| find_effect(id))
                .collect();
        let mut m = Self::from_effects("paper", effects);
        for (ei, e) in m.effects.iter().enumerate() {
            if e.sensor() == SensorKind::Gyro {
                for (k, t) in e.terms().iter().enumerate() {
                    if !PAPER_GYRO.contains(&t.name.as_str()) {
                        m.status[ei][k] = TermStatus::Fixed(t.nominal);
                    }
                }
            }
        }
        m
    }

    /// What a Ferraris session (six faces and three turns) identifies: biases, full C_ω,
    /// gyro g-sensitivity, full K (imucal's model).
    pub fn ferraris() -> Self {
        let ids = ["gyro-bias", "gyro-scale-coupling", "gyro-g-sensitivity", "accel-bias", "accel-scale-coupling"];
        Self::from_effects("ferraris", ids.iter().filter_map(|id| find_effect(id)).collect())
    }

    /// What a multi-position session identifies as imu_tk does: biases, full C_ω, K (upper
    /// triangular: the accelerometer's axes define the frame). Add `gyro-g-sensitivity` to
    /// fit it from the poses.
    pub fn tedaldi() -> Self {
        let ids = ["gyro-bias", "gyro-scale-coupling", "accel-bias", "accel-scale-coupling"];
        Self::from_effects("tedaldi", ids.iter().filter_map(|id| find_effect(id)).collect())
    }

    /// A preset by name (`default`, `paper`, `ferraris`, `tedaldi`).
    pub fn preset(name: &str) -> Result<Self, ModelError> {
        Ok(name.parse::<Preset>()?.model())
    }

    /// Adds a catalogue effect (no-op when already present).
    pub fn add_effect(&mut self, id: &str) -> Result<(), ModelError> {
        // A composite (`gyro-temp-bias+gyro-temp-bias2`: a polynomial diagnose adds as one
        // finding) is its parts.
        if id.contains('+') {
            return id.split('+').try_for_each(|part| self.add_effect(part));
        }
        if self.has(id) {
            return Ok(());
        }
        if let Some(u) = user::find_registered(id) {
            self.add_user(u);
            return Ok(());
        }
        match find(id).ok_or_else(|| ModelError::UnknownEffect(id.to_string(), all_effect_ids().join(", ")))? {
            CatalogEffect::Nonlinear(e) => {
                let values = e.params().iter().map(|p| p.nominal).collect();
                self.nonlinear.push(NonlinearEntry { effect: e, values, fitted: true, near: None });
            }
            CatalogEffect::Linear(e) => {
                self.status.push(vec![TermStatus::Fitted; e.terms().len()]);
                self.effects.push(e);
            }
        }
        self.name = format!("{}+{id}", self.name);
        Ok(())
    }

    /// Holds a coefficient at a value instead of fitting it.
    pub fn fix(&mut self, name: &str, value: f64) -> Result<(), ModelError> {
        let (ei, k) = self.locate(name).ok_or_else(|| ModelError::UnknownCoefficient(name.to_string()))?;
        self.status[ei][k] = TermStatus::Fixed(value);
        Ok(())
    }

    /// Holds a coefficient at its nominal value (1 for diagonal scales, else 0).
    pub fn disable(&mut self, name: &str) -> Result<(), ModelError> {
        let (ei, k) = self.locate(name).ok_or_else(|| ModelError::UnknownCoefficient(name.to_string()))?;
        self.status[ei][k] = TermStatus::Fixed(self.effects[ei].terms()[k].nominal);
        Ok(())
    }

    /// The catalogue's nominal value of a coefficient of this model (1 on a scale diagonal,
    /// else 0), or `None` when the model has no such coefficient.
    pub fn nominal(&self, name: &str) -> Option<f64> {
        self.locate(name).map(|(ei, k)| self.effects[ei].terms()[k].nominal)
    }

    fn locate(&self, name: &str) -> Option<(usize, usize)> {
        self.effects
            .iter()
            .enumerate()
            .find_map(|(ei, e)| e.terms().iter().position(|t| t.name == name).map(|k| (ei, k)))
    }

    /// How the model treats a coefficient (None when it has no such coefficient).
    pub fn locate_status(&self, name: &str) -> Option<TermStatus> {
        self.locate(name).map(|(ei, k)| self.status[ei][k])
    }

    /// Whether the model has the effect (linear or nonlinear).
    pub fn has(&self, id: &str) -> bool {
        self.effects.iter().any(|e| e.id() == id) || self.nonlinear.iter().any(|e| e.effect.id() == id)
    }

    /// Ids of every effect in the model, linear ones first, in the order they were added
    /// (a user effect with both coefficients and parameters once).
    pub fn effect_ids(&self) -> Vec<&'static str> {
        let mut ids: Vec<&'static str> = self.effects.iter().map(|e| e.id()).collect();
        for n in &self.nonlinear {
            if !ids.contains(&n.effect.id()) {
                ids.push(n.effect.id());
            }
        }
        ids
    }

    /// The linear effects in the model.
    pub fn effects(&self) -> &[Arc<dyn Effect>] {
        &self.effects
    }

    /// Every coefficient of one sensor, in model order.
    pub fn terms(&self, sensor: SensorKind) -> Vec<TermRef<'_>> {
        let mut out = Vec::new();
        for (ei, e) in self.effects.iter().enumerate() {
            if e.sensor() != sensor {
                continue;
            }
            for (k, t) in e.terms().iter().enumerate() {
                out.push(TermRef { effect: e.as_ref(), index: k, term: t, status: self.status[ei][k] });
            }
        }
        out
    }
}

/// A coefficient of a model, with its effect.
#[derive(Debug, Clone, Copy)]
pub struct TermRef<'a> {
    /// The effect that defines it.
    pub effect: &'a dyn Effect,
    /// Index within the effect's terms.
    pub index: usize,
    /// The definition.
    pub term: &'a Term,
    /// Fitted or fixed.
    pub status: TermStatus,
}

impl TermRef<'_> {
    /// Regressor value at a state.
    #[inline]
    pub fn regressor(&self, s: &State) -> f64 {
        self.effect.regressor(self.index, s)
    }

    /// Regressor values at each of `states`, into `out` (same length).
    #[inline]
    pub fn regressors(&self, states: &[State], out: &mut [f64]) {
        self.effect.regressors(self.index, states, out);
    }

    /// For an input-side term: (input axis, term index of the effect) of each component of
    /// its input perturbation (see [`Effect::input_components`]); empty otherwise.
    pub fn input_components(&self) -> Vec<(usize, usize)> {
        self.effect.input_components(self.index)
    }
}

/// Name of a matrix coefficient, e.g. `matrix_name(Gyro, "c", 0, 1)` = `gyro.c_xy`.
pub fn matrix_name(sensor: SensorKind, letter: &str, i: usize, j: usize) -> String {
    format!("{}.{letter}_{}{}", sensor.as_str(), AXES[i], AXES[j])
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_are_unique_across_catalogue() {
        let mut names: Vec<String> = catalog().iter().flat_map(|e| e.coefficients()).map(|c| c.name).collect();
        let n = names.len();
        names.sort();
        names.dedup();
        assert_eq!(names.len(), n);
    }

    #[test]
    fn paper_model_fits_exactly_eq3_and_eq4() {
        let m = Model::paper();
        let fitted: Vec<String> = m
            .terms(SensorKind::Gyro)
            .iter()
            .filter(|t| t.status == TermStatus::Fitted)
            .map(|t| t.term.name.clone())
            .collect();
        assert_eq!(fitted.len(), 9);
        for n in PAPER_GYRO {
            assert!(fitted.iter().any(|f| f == n), "{n}");
        }
        assert_eq!(m.terms(SensorKind::Accel).len(), 9);
    }
}
