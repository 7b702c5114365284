//! The inverse of a unit's forward model: per sensor the bias, the scale/coupling matrix and
//! its inverse, the angular-acceleration matrix and the further effect terms, and the
//! nonlinear effects with their parameters.

use super::{mv, solve, CorrectError};
use crate::frames::{Coupling, Output, Sensor};
use crate::model::{Effect, Model, Role, State};
use crate::profile::{CorrectionSettings, Profile};
use crate::units::SensorKind;
use nalgebra::Matrix3;
use std::sync::Arc;

/// A term beyond b, A and E: on the output side its regressor times its value; on the
/// input side (`components` not empty) the channel's row of A applied to its input
/// perturbation, `value · Σ_j A_ij · regressor(component j)`.
#[derive(Debug, Clone)]
struct OtherTerm {
    effect: Arc<dyn Effect>,
    index: usize,
    channel: usize,
    value: f64,
    /// (weight A_ij, term index of component j) for an input-side term.
    components: Vec<(f64, usize)>,
}

/// The inverse of one sensor's model.
#[derive(Debug, Clone)]
pub struct SensorInverse {
    /// Bias b (SI).
    pub bias: [f64; 3],
    /// Scale/coupling matrix A of the forward model: true input (sensor axes) → output.
    pub scale: Coupling<Sensor, Output>,
    /// A⁻¹: output → true input.
    pub scale_inv: Coupling<Output, Sensor>,
    /// Angular-acceleration matrix E of the forward model (gyro; zero for the
    /// accelerometer), s: true ε → output.
    pub eps: Coupling<Sensor, Output>,
    others: Vec<OtherTerm>,
}

impl SensorInverse {
    fn build(model: &Model, sensor: SensorKind) -> Result<Self, CorrectError> {
        let mut bias = [0.0; 3];
        let mut scale = Matrix3::zeros();
        let mut eps = Matrix3::zeros();
        let mut others = Vec::new();
        // Per other term: (input axis, component term) of an input-side term's perturbation.
        let mut axes: Vec<Vec<(usize, usize)>> = Vec::new();
        for e in model.effects() {
            if e.sensor() != sensor {
                continue;
            }
            for t in model.terms(sensor).iter().filter(|t| std::ptr::addr_eq(t.effect, e.as_ref())) {
                let value = match t.status {
                    crate::model::TermStatus::Fixed(v) => v,
                    crate::model::TermStatus::Fitted => t.term.nominal,
                };
                let i = t.term.channel;
                match t.term.role {
                    Role::Bias => bias[i] += value,
                    Role::Scale(j) => scale[(i, j)] += value,
                    Role::Epsilon(j) => eps[(i, j)] += value,
                    Role::Other => {
                        if value != 0.0 {
                            axes.push(t.input_components());
                            let components = Vec::new();
                            others.push(OtherTerm {
                                effect: Arc::clone(e),
                                index: t.index,
                                channel: i,
                                value,
                                components,
                            })
                        }
                    }
                }
            }
        }
        // Input-side terms see the element's row of A: the weights are known now.
        let has_scale = model.terms(sensor).iter().any(|t| matches!(t.term.role, Role::Scale(_)));
        let a = if has_scale { scale } else { Matrix3::identity() };
        for (o, axes) in others.iter_mut().zip(axes) {
            o.components = axes.into_iter().map(|(j, k)| (a[(o.channel, j)], k)).collect();
        }
        let scale = Coupling::new(scale);
        let scale_inv = scale.try_inverse().ok_or(CorrectError::Singular(sensor))?;
        Ok(Self { bias, scale, scale_inv, eps: Coupling::new(eps), others })
    }

    /// Contribution of the non-linear-block terms at a state.
    #[inline]
    pub(super) fn other(&self, s: &State) -> [f64; 3] {
        let mut g = [0.0; 3];
        for o in &self.others {
            if o.components.is_empty() {
                g[o.channel] += o.value * o.effect.regressor(o.index, s);
            } else {
                for &(w, k) in &o.components {
                    g[o.channel] += o.value * w * o.effect.regressor(k, s);
                }
            }
        }
        g
    }

    /// True when the model has terms beyond b, A and E.
    pub fn has_other_terms(&self) -> bool {
        !self.others.is_empty()
    }
}

/// A nonlinear effect of the calibration with its parameter values.
#[derive(Debug, Clone)]
pub struct NonlinearPart {
    /// The effect.
    pub effect: Arc<dyn crate::model::NonlinearEffect>,
    /// Its parameters.
    pub params: Vec<f64>,
}

/// Everything needed to correct a unit.
#[derive(Debug, Clone)]
pub struct Calibration {
    /// Gyro inverse.
    pub gyro: SensorInverse,
    /// Accelerometer inverse.
    pub accel: SensorInverse,
    /// Derivative settings.
    pub settings: CorrectionSettings,
    /// Nonlinear effects (time delay, dead zone).
    pub nonlinear: Vec<NonlinearPart>,
    /// Noise standard deviation per channel (gyro, accel), SI: the dead-band flag threshold.
    pub noise: [[f64; 3]; 2],
    /// The temperature range the profile was calibrated over, °C, when it has temperature
    /// terms (None: no guard).
    pub temp_range_c: Option<[f64; 2]>,
    /// What to do outside that range.
    pub temp_policy: super::TempPolicy,
}

impl Calibration {
    /// A fresh guard of the calibrated temperature range (counts nothing yet).
    pub fn temp_guard(&self) -> super::TempOutside {
        super::TempOutside { range_c: self.temp_range_c, policy: self.temp_policy, ..super::TempOutside::default() }
    }

    /// From a model whose coefficients are all fixed at their calibrated values.
    pub fn from_model(model: &Model, settings: CorrectionSettings) -> Result<Self, CorrectError> {
        Ok(Self {
            gyro: SensorInverse::build(model, SensorKind::Gyro)?,
            accel: SensorInverse::build(model, SensorKind::Accel)?,
            settings,
            nonlinear: model
                .nonlinear()
                .iter()
                .map(|e| NonlinearPart { effect: Arc::clone(&e.effect), params: e.values.clone() })
                .collect(),
            noise: [[0.0; 3]; 2],
            temp_range_c: None,
            temp_policy: super::TempPolicy::Clamp,
        })
    }

    /// From a profile (its channel σ set the dead-band flag thresholds).
    pub fn from_profile(p: &Profile) -> Result<Self, CorrectError> {
        let model = p.model()?;
        let mut c = Self::from_model(&model, p.correction)?;
        for (si, sf) in [&p.gyro, &p.accel].iter().enumerate() {
            for (i, ch) in sf.channels.iter().enumerate().take(3) {
                c.noise[si][i] = ch.sigma;
            }
        }
        c.temp_range_c = p.temperature_range_c().filter(|_| p.uses_temperature());
        Ok(c)
    }

    /// Inverts one sample exactly, given the true angular acceleration ε (rad/s²): the
    /// fixed point x = A⁻¹(u − b − E ε − g(x)) iterated from the linear solution, then the
    /// nonlinear inverses. Returns (ω, a, flags) or None if it does not converge in 100
    /// passes (coefficients too large for the effects to be a perturbation). One sample has
    /// no temperature history: a thermal hysteresis term reads no branch (0).
    pub fn invert_state(
        &self,
        gyro: [f64; 3],
        accel: [f64; 3],
        e: [f64; 3],
        t_s: f64,
        temp_c: f64,
    ) -> Option<([f64; 3], [f64; 3], u8)> {
        let (g, a) = (&self.gyro, &self.accel);
        let ee = mv(g.eps.matrix(), e);
        let mut w = solve(g.scale_inv.matrix(), gyro, g.bias, ee, [0.0; 3]);
        let mut acc = solve(a.scale_inv.matrix(), accel, a.bias, [0.0; 3], [0.0; 3]);
        for _ in 0..100 {
            // The effects' regressors see the input as the sensor saw it (before the inverses
            // of the nonlinear effects), exactly as in the forward model.
            let s = State { t_session_s: t_s, w, e, a: acc, temp_c, temp_rate_c_s: f64::NAN };
            let og = g.other(&s);
            let oa = a.other(&s);
            let wn = solve(g.scale_inv.matrix(), gyro, g.bias, ee, og);
            let an = solve(a.scale_inv.matrix(), accel, a.bias, oa, [0.0; 3]);
            let change = (0..3).map(|i| (wn[i] - w[i]).abs().max((an[i] - acc[i]).abs())).fold(0.0, f64::max);
            let size = (0..3).map(|i| wn[i].abs().max(an[i].abs())).fold(f64::MIN_POSITIVE, f64::max);
            w = wn;
            acc = an;
            if change <= 1e-15 * size {
                let flags = self.invert_nonlinear(&mut w, &mut acc);
                return Some((w, acc, flags));
            }
        }
        None
    }

    /// Whether an effect reads the temperature's rate of change (thermal hysteresis).
    pub fn needs_temperature_rate(&self) -> bool {
        self.gyro.others.iter().chain(&self.accel.others).any(|o| o.effect.inputs().temperature_rate)
    }

    /// The first effect that needs a temperature, if any.
    pub fn needs_temperature(&self) -> Option<&'static str> {
        self.gyro.others.iter().chain(&self.accel.others).find(|o| o.effect.needs_temperature()).map(|o| o.effect.id())
    }

    /// Total lag of the sensor's stamps behind the truth, s.
    pub fn lag_s(&self) -> f64 {
        self.nonlinear.iter().map(|n| n.effect.lag_s(&n.params)).sum()
    }

    /// Applies the nonlinear inverses to one sample; returns the flag bits (gyro 0-2, accel 3-5).
    #[inline]
    pub(super) fn invert_nonlinear(&self, w: &mut [f64; 3], a: &mut [f64; 3]) -> u8 {
        let mut flags = 0;
        for n in &self.nonlinear {
            flags |= n.effect.invert_sample(&n.params, SensorKind::Gyro, w, &self.noise[0]);
            flags |= n.effect.invert_sample(&n.params, SensorKind::Accel, a, &self.noise[1]) << 3;
        }
        flags
    }
}
