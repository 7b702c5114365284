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

/// How a sensor's seen motion follows from a run's states ([`FitRun::seen_from`]).
pub enum SeenFrom<'t> {
    /// The run's own states.
    Same,
    /// The run's states through these maps, in order.
    Maps(&'t [std::sync::Arc<dyn crate::motion::SampleMap>]),
    /// A motion of its own.
    Other(&'t Track),
}

/// `base` with `maps` applied (its stamps, temperature and session time kept): the state
/// of a track that is `base`'s with the maps after it.
pub fn mapped_state(base: &State, maps: &[std::sync::Arc<dyn crate::motion::SampleMap>]) -> State {
    let mut k = crate::motion::SensorKinematics {
        w_rad_s: crate::frames::V3::new(base.w),
        e_rad_s2: crate::frames::V3::new(base.e),
        a_m_s2: crate::frames::V3::new(base.a),
    };
    for m in maps {
        m.apply(&mut k);
    }
    State { w: k.w_rad_s.xyz, e: k.e_rad_s2.xyz, a: k.a_m_s2.xyz, ..*base }
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

impl<'a> FitRun<'a> {
    /// Samples `k0..k1` of the run on `track` (this run's track so cut, [`Track::range`]);
    /// its session clock unchanged (the start moves with the first sample kept).
    pub fn part(&self, track: &'a Track, k0: usize, k1: usize) -> FitRun<'a> {
        let k1 = k1.min(self.len());
        let k0 = k0.min(k1);
        let t = &self.track.t_s;
        let shift = if k0 < k1 { t[k0] - t[0] } else { 0.0 };
        FitRun {
            track,
            gyro: &self.gyro[k0..k1],
            accel: &self.accel[k0..k1],
            temp_c: self.temp_c.and_then(|c| c.get(k0.min(c.len())..k1.min(c.len()))),
            start_s: self.start_s.map(|s| s + shift),
            ..*self
        }
    }

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
        self.state_of(k, self.track.at(k))
    }

    /// The states of samples `ks` (in increasing order, best consecutive) appended to
    /// `out`: [`Self::state`]'s numbers (to a unit in the last place of the stand angle's
    /// sine), its kinematics walked along the track ([`crate::motion::Walk`]).
    pub fn states_into(&self, ks: impl IntoIterator<Item = usize>, out: &mut Vec<State>) {
        let mut walk = self.track.walk();
        out.extend(ks.into_iter().map(|k| self.state_of(k, walk.at(k))));
    }

    /// The state at sample `k` whose kinematics are `s`.
    #[inline(always)]
    fn state_of(&self, k: usize, s: crate::motion::SensorKinematics) -> State {
        let tr = self.track;
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

    /// How the motion `seen` (a sensor's view of this run under nonlinear effects, None: the
    /// run's own track) is had from this run's states: the same states, the states through
    /// the maps `seen` applies beyond the track ([`Track::maps_beyond`]), or its own
    /// kinematics. Worked out once per run, used per block ([`Self::seen_states`]).
    pub fn seen_from<'t>(&self, seen: Option<&'t Track>) -> SeenFrom<'t> {
        match seen {
            None => SeenFrom::Same,
            Some(t) => match t.maps_beyond(self.track) {
                Some([]) => SeenFrom::Same,
                Some(maps) => SeenFrom::Maps(maps),
                None => SeenFrom::Other(t),
            },
        }
    }

    /// The states of samples `k0..k0 + base.len()` on a seen motion into `out` (cleared),
    /// from the run's own states `base` of those samples: the numbers of
    /// `FitRun { track: seen, .. }.state(k)`, without the kinematics worked out again when
    /// the seen motion is the track with maps after it.
    pub fn seen_states(&self, how: &SeenFrom<'_>, base: &[State], k0: usize, out: &mut Vec<State>) {
        out.clear();
        match how {
            SeenFrom::Same => out.extend_from_slice(base),
            SeenFrom::Maps(maps) => out.extend(base.iter().map(|s| mapped_state(s, maps))),
            SeenFrom::Other(t) => {
                FitRun { track: t, ..*self }.states_into(k0..k0 + base.len(), out);
            }
        }
    }

    /// [`Self::seen_states`] of the samples `ks` (not necessarily consecutive), whose own
    /// states are `base`.
    pub fn seen_states_at(&self, how: &SeenFrom<'_>, base: &[State], ks: &[usize], out: &mut Vec<State>) {
        match how {
            SeenFrom::Other(t) => {
                out.clear();
                FitRun { track: t, ..*self }.states_into(ks.iter().copied(), out);
            }
            // The seen states follow from the run's own, whatever their samples.
            _ => self.seen_states(how, base, 0, out),
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::session::{MotionSpec, Recording};

    #[test]
    fn seen_states_are_the_seen_tracks_states_bit_for_bit() {
        let n = 600;
        let rec = Recording {
            t_s: (0..n).map(|k| k as f64 * 0.01).collect(),
            gyro: vec![[0.0; 3]; n].into(),
            accel: vec![[0.0; 3]; n].into(),
            ..Default::default()
        };
        let motion = MotionSpec::Conic { cone_angle_deg: 15.0, rate_deg_s: 40.0, phase_deg: 5.0 };
        let track = crate::motion::track_for(
            &motion,
            &crate::frames::Mount::identity(),
            &rec,
            9.81,
            &DerivativeConfig::default(),
        );
        let run = FitRun {
            name: "r",
            track: &track,
            gyro: &rec.gyro,
            accel: &rec.accel,
            temp_c: None,
            temp_const_c: Some(25.0),
            start_s: Some(100.0),
        };
        let mut dz = crate::model::Model::paper();
        dz.add_effect("gyro-dead-zone").unwrap();
        let entry = &dz.nonlinear()[0];
        let mapped = entry.effect.transform(&[0.05, 0.02, 0.03], &track);
        let delayed = track.delayed(0.013);
        for seen in [None, Some(&mapped), Some(&delayed)] {
            let how = run.seen_from(seen);
            let direct = FitRun { track: seen.unwrap_or(&track), ..run };
            let (k0, k1) = (256, 512);
            let mut base = Vec::new();
            run.states_into(k0..k1, &mut base);
            let mut out = Vec::new();
            run.seen_states(&how, &base, k0, &mut out);
            assert_eq!(out.len(), k1 - k0);
            let mut walked = Vec::new();
            direct.states_into(k0..k1, &mut walked);
            for (i, k) in (k0..k1).enumerate() {
                let want = walked[i];
                assert!(out[i].w.iter().zip(&want.w).all(|(a, b)| a.to_bits() == b.to_bits()), "sample {k}");
                assert!(out[i].e.iter().zip(&want.e).all(|(a, b)| a.to_bits() == b.to_bits()), "sample {k}");
                assert!(out[i].a.iter().zip(&want.a).all(|(a, b)| a.to_bits() == b.to_bits()), "sample {k}");
                assert_eq!(out[i].t_session_s.to_bits(), want.t_session_s.to_bits());
            }
        }
        assert!(matches!(run.seen_from(Some(&mapped)), SeenFrom::Maps(m) if m.len() == 1));
        assert!(matches!(run.seen_from(Some(&delayed)), SeenFrom::Other(_)));
    }

    #[test]
    fn walked_states_are_each_samples_own_to_rounding() {
        let n = 3000;
        let rec = Recording {
            t_s: (0..n).map(|k| k as f64 * 5e-4 + 1e-6 * ((k * 7919) % 13) as f64).collect(),
            gyro: vec![[0.0; 3]; n].into(),
            accel: vec![[0.0; 3]; n].into(),
            ..Default::default()
        };
        let motion = MotionSpec::Conic { cone_angle_deg: 15.0, rate_deg_s: -300.0, phase_deg: 5.0 };
        let mount = crate::frames::Mount::identity();
        let conic = crate::motion::track_for(&motion, &mount, &rec, 9.81, &DerivativeConfig::default());
        let stand = crate::motion::stand::StandMotion {
            tilt_rad: [0.003, -0.002],
            wobble_rad: [0.001, 0.0005],
            ripple_rad: [[0.01, 0.0], [0.0, 0.003]],
            ..crate::motion::stand::StandMotion::ideal(0.26, -5.2, 0.09)
        };
        let stood = conic.on_stand(stand, 9.81, mount.clone());
        for track in [&conic, &stood] {
            let run = FitRun {
                name: "r",
                track,
                gyro: &rec.gyro,
                accel: &rec.accel,
                temp_c: None,
                temp_const_c: None,
                start_s: None,
            };
            let mut walked = Vec::new();
            run.states_into(0..n, &mut walked);
            for (k, got) in walked.iter().enumerate() {
                let want = run.state(k);
                for (g, w) in [(got.w, want.w), (got.e, want.e), (got.a, want.a)] {
                    let scale = w.iter().fold(1.0_f64, |m, v| m.max(v.abs()));
                    assert!(g.iter().zip(&w).all(|(a, b)| (a - b).abs() <= 4e-15 * scale), "sample {k}: {g:?} {w:?}");
                }
            }
        }
    }
}
