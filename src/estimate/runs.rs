//! The runs of a session prepared for the estimator: each run's true motion in sensor axes
//! (its track) beside the sensor's outputs.

use crate::model::State;
use crate::motion::{track, DerivativeConfig, Track};
use crate::session::Session;
use crate::units::SensorKind;

/// Time on the session clock of a sample stamped `t_s` in a run whose first stamp is
/// `t0_s`: the run's declared start plus the time since its first sample, or the stamp as
/// recorded when the run declares no start.
#[inline]
pub fn session_time(start_s: Option<f64>, t_s: f64, t0_s: f64) -> f64 {
    match start_s {
        Some(s) => s + (t_s - t0_s),
        None => t_s,
    }
}

/// One run's data prepared for fitting: its true motion and the sensor outputs.
#[derive(Debug, Clone, Copy)]
pub struct FitRun<'a> {
    /// Run name.
    pub name: &'a str,
    /// True motion in sensor axes.
    pub track: &'a Track,
    /// Gyro outputs (SI or raw).
    pub gyro: &'a [[f64; 3]],
    /// Accelerometer outputs (SI or raw).
    pub accel: &'a [[f64; 3]],
    /// Temperature per sample, °C.
    pub temp_c: Option<&'a [f64]>,
    /// Constant temperature, °C, when there is no per-sample temperature.
    pub temp_const_c: Option<f64>,
    /// The run's start on the session clock, s (manifest `start_s`): session time is then
    /// this plus the time since the run's first sample; `None`: the time as recorded.
    pub start_s: Option<f64>,
}

impl FitRun<'_> {
    /// Number of samples.
    pub fn len(&self) -> usize {
        self.track.t_s.len().min(self.gyro.len()).min(self.accel.len())
    }

    /// True when empty.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The true state at sample k (time on the session clock; the temperature's rate of
    /// change from the track, 0 at a declared constant temperature).
    #[inline]
    pub fn state(&self, k: usize) -> State {
        let tr = self.track;
        let s = tr.at(k);
        State {
            t_session_s: session_time(self.start_s, tr.t_s[k], tr.t_s[0]),
            w: s.w_rad_s.xyz,
            e: s.e_rad_s2.xyz,
            a: s.a_m_s2.xyz,
            temp_c: self.temp_c.map(|t| t[k]).or(self.temp_const_c).unwrap_or(f64::NAN),
            temp_rate_c_s: match (self.temp_c, self.temp_const_c) {
                (Some(_), _) => tr.temp_rate_c_s(k),
                (None, Some(_)) => 0.0,
                (None, None) => f64::NAN,
            },
        }
    }

    /// The sensor output at sample k.
    #[inline]
    pub fn output(&self, sensor: SensorKind, k: usize) -> [f64; 3] {
        match sensor {
            SensorKind::Gyro => self.gyro[k],
            SensorKind::Accel => self.accel[k],
        }
    }
}

/// The true motion of every run of a session, in sensor axes.
pub fn tracks(session: &Session, deriv: &DerivativeConfig) -> Vec<Track> {
    use rayon::prelude::*;
    session.runs.par_iter().map(|r| track(r, session.manifest.g_m_s2, deriv)).collect()
}

/// Pairs each run's outputs with its track, for the estimator.
pub fn fit_runs<'a>(session: &'a Session, tracks: &'a [Track]) -> Vec<FitRun<'a>> {
    session
        .runs
        .iter()
        .zip(tracks)
        .map(|(r, tr)| FitRun {
            name: &r.spec.name,
            track: tr,
            gyro: &r.rec.gyro,
            accel: &r.rec.accel,
            temp_c: r.rec.temp_c.as_deref(),
            temp_const_c: r.spec.temperature_c,
            start_s: r.spec.start_s,
        })
        .collect()
}

/// Refuses a model whose user effects are not finite somewhere on the runs (at their start
/// parameters, every coefficient 1): a clear error naming the effect, run and time instead
/// of a design the solver cannot use.
pub(crate) fn check_user_effects(model: &crate::model::Model, runs: &[FitRun<'_>]) -> Result<(), super::EstimateError> {
    for def in model.user_definitions() {
        let Ok(u) = crate::model::user::compile(&def) else { continue };
        for r in runs {
            let n = r.track.t_s.len();
            if let Some(s) = u.first_non_finite((0..n).map(|k| r.state(k))) {
                return Err(super::EstimateError::UserEffect(crate::model::user::UserEffectError::NonFinite {
                    id: def.id.clone(),
                    run: r.name.to_string(),
                    t_s: s.t_session_s,
                    state: format!("w = {:.4?} rad/s, a = {:.4?} m/s^2, T = {} C", s.w, s.a, s.temp_c),
                }));
            }
        }
    }
    Ok(())
}
