//! A run's true motion in sensor axes, one state per recorded sample.
//!
//! A conic or static run's motion is a closed-form function of time (paper eq. 1), so its
//! track stores only the time stamps and evaluates the state when asked: a 1e6-sample
//! session's tracks take 8 MB instead of 80 MB, and a time shift of a conic track is exact
//! (no interpolation). Recorded reference motion is stored sample by sample. Input-side
//! effects (a dead zone) are [`SampleMap`]s applied on the way out, so a transformed track
//! shares its stamps and source with the original instead of copying them. A track also
//! carries its run's smoothed rate of change of temperature (the thermal branch), computed
//! once from the whole `temp` column.

use super::{derivative_offline, ConicAt, DerivativeConfig, Kinematics, EPSILON_CONIC, EPSILON_STATIC};
use crate::frames::{Mount, Sensor, Stand, V3};
use crate::session::{MotionSpec, Run};
use std::fmt;
use std::sync::Arc;

/// True kinematics at one instant in sensor axes (SI units).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SensorKinematics {
    /// Angular rate, rad/s.
    pub w_rad_s: V3<Sensor>,
    /// Angular acceleration, rad/s².
    pub e_rad_s2: V3<Sensor>,
    /// Specific force, m/s².
    pub a_m_s2: V3<Sensor>,
}

/// A sample-by-sample change of the motion as the sensor sees it (an input-side effect such
/// as a dead zone): it may read and change every quantity of one state.
pub trait SampleMap: Send + Sync + fmt::Debug {
    /// Changes one state in place.
    fn apply(&self, k: &mut SensorKinematics);
}

/// Where a track's states come from.
#[derive(Debug, Clone, PartialEq)]
enum Source {
    /// Stored per sample (recorded reference motion, or a materialised track).
    Sampled { w: Arc<[V3<Sensor>]>, e: Arc<[V3<Sensor>]>, a: Arc<[V3<Sensor>]> },
    /// Conic motion evaluated at `t − lag_s` and turned into sensor axes by `mount`.
    Conic { c: ConicAt, mount: Mount, lag_s: f64 },
    /// The same state at every sample (static runs; NaN for protocol runs).
    Constant(SensorKinematics),
    /// An imperfect conic stand ([`super::stand::StandMotion`]) evaluated at `t − lag_s`.
    Stand { s: super::stand::StandAt, mount: Mount, lag_s: f64 },
    /// A conic stand that logs its angle: the stand motion's cone angle, tilt, wobble and
    /// Earth's rate at each sample's logged angle and its derivatives, its phase the
    /// encoder's offset (its own rate, drift and ripple unused).
    Logged { s: super::stand::StandAt, angles: Arc<[super::stand::Angle]>, mount: Mount },
}

/// A track evaluated at many samples in order ([`Track::walk`]): a conic stand's angle's
/// sine and cosine from those of a nearby sample's ([`super::stand::NearTrig`]).
pub struct Walk<'t> {
    track: &'t Track,
    trig: super::stand::NearTrig,
}

impl Walk<'_> {
    /// The state at sample `k` ([`Track::at`], to a unit in the last place of the sines).
    #[inline]
    pub fn at(&mut self, k: usize) -> SensorKinematics {
        let trig = &mut self.trig;
        self.track.at_with(k, |theta| trig.of(theta))
    }
}

/// True motion of one run in sensor axes, one state per recorded sample (SI units).
#[derive(Debug, Clone)]
pub struct Track {
    /// Time stamps, s (shared with the tracks derived from this one).
    pub t_s: crate::session::Column<f64>,
    source: Source,
    maps: Vec<Arc<dyn SampleMap>>,
    /// How ε was obtained (exact, given, or which derivative).
    pub epsilon_source: String,
    /// The rate of change of the run's `temp` column at each stamp, °C/s, smoothed and
    /// centred ([`crate::stats::temp_rate::centred`]; None without a column): the thermal
    /// branch each sample is on, computed once per run from the whole column.
    pub temp_rate_c_s: Option<Arc<[f64]>>,
}

impl PartialEq for Track {
    fn eq(&self, other: &Self) -> bool {
        self.t_s == other.t_s
            && self.source == other.source
            && self.epsilon_source == other.epsilon_source
            && self.temp_rate_c_s == other.temp_rate_c_s
            && self.maps.len() == other.maps.len()
            && self.maps.iter().zip(&other.maps).all(|(a, b)| Arc::ptr_eq(a, b))
    }
}

impl Default for Track {
    fn default() -> Self {
        Self::sampled(Vec::new(), Vec::new(), Vec::new(), Vec::new(), String::new())
    }
}

impl Track {
    /// A track stored sample by sample. The four arrays must have the same length.
    pub fn sampled(
        t_s: Vec<f64>,
        w_rad_s: Vec<V3<Sensor>>,
        e_rad_s2: Vec<V3<Sensor>>,
        a_m_s2: Vec<V3<Sensor>>,
        epsilon_source: String,
    ) -> Self {
        Self {
            t_s: t_s.into(),
            source: Source::Sampled { w: w_rad_s.into(), e: e_rad_s2.into(), a: a_m_s2.into() },
            maps: Vec::new(),
            epsilon_source,
            temp_rate_c_s: None,
        }
    }

    /// Number of samples.
    pub fn len(&self) -> usize {
        self.t_s.len()
    }

    /// True when there are no samples.
    pub fn is_empty(&self) -> bool {
        self.t_s.is_empty()
    }

    /// The state at sample `k` (panics when `k` is out of range, like indexing).
    #[inline]
    pub fn at(&self, k: usize) -> SensorKinematics {
        self.at_with(k, libm::sincos)
    }

    /// A walk over this track's samples in order ([`Walk`]).
    pub fn walk(&self) -> Walk<'_> {
        Walk { track: self, trig: super::stand::NearTrig::default() }
    }

    /// [`Self::at`] with a conic stand's angle's sine and cosine from `trig`.
    #[inline(always)]
    fn at_with(&self, k: usize, mut trig: impl FnMut(f64) -> (f64, f64)) -> SensorKinematics {
        let mut s = match &self.source {
            Source::Sampled { w, e, a } => SensorKinematics { w_rad_s: w[k], e_rad_s2: e[k], a_m_s2: a[k] },
            Source::Conic { c, mount, lag_s } => {
                let t = self.t_s[k] - lag_s;
                let st = c.at_trig(trig(c.theta(t)));
                SensorKinematics {
                    w_rad_s: mount.to_sensor(st.w_rad_s),
                    e_rad_s2: mount.to_sensor(st.e_rad_s2),
                    a_m_s2: mount.to_sensor(st.a_m_s2),
                }
            }
            Source::Constant(s) => {
                let _ = self.t_s[k];
                *s
            }
            Source::Stand { s, mount, lag_s } => {
                let an = s.motion.angle(self.t_s[k] - lag_s);
                super::stand::to_sensor(s.at_angle_trig(an, trig(an.theta), None), mount)
            }
            Source::Logged { s, angles, mount } => {
                let an = s.motion.angle_or_logged(0.0, Some(angles[k]));
                super::stand::to_sensor(s.at_angle_trig(an, trig(an.theta), None), mount)
            }
        };
        for m in &self.maps {
            m.apply(&mut s);
        }
        s
    }

    /// The temperature's smoothed rate of change at sample `k`, °C/s (NaN without a `temp`
    /// column).
    #[inline]
    pub fn temp_rate_c_s(&self, k: usize) -> f64 {
        self.temp_rate_c_s.as_ref().and_then(|r| r.get(k).copied()).unwrap_or(f64::NAN)
    }

    /// The mount of a conic track (None for stored or constant motion).
    pub fn mount(&self) -> Option<&Mount> {
        match &self.source {
            Source::Conic { mount, .. } | Source::Stand { mount, .. } | Source::Logged { mount, .. } => Some(mount),
            _ => None,
        }
    }

    /// The stand's logged angle with its derivatives at each sample, for a conic run whose
    /// stand logs it (None otherwise).
    pub fn logged_angles(&self) -> Option<&[super::stand::Angle]> {
        match &self.source {
            Source::Logged { angles, .. } => Some(angles),
            _ => None,
        }
    }

    /// The same stamps (and temperature branch and maps) on an imperfect conic stand's
    /// motion, through `mount` (the stand's own settings replace the declared ones). A run
    /// whose stand logs its angle keeps following it: the motion's cone angle, tilt, wobble
    /// and Earth's rate apply at the logged angles.
    pub fn on_stand(&self, s: super::stand::StandMotion, g_m_s2: f64, mount: Mount) -> Track {
        let source = match &self.source {
            Source::Logged { angles, .. } => Source::Logged { s: s.fixed(g_m_s2), angles: angles.clone(), mount },
            _ => Source::Stand { s: s.fixed(g_m_s2), mount, lag_s: 0.0 },
        };
        let epsilon_source = match &self.source {
            Source::Logged { .. } => self.epsilon_source.clone(),
            _ => "exact (stand motion with its estimated imperfections differentiated)".into(),
        };
        Track { source, epsilon_source, ..self.clone() }
    }

    /// The same stamps (and temperature branch and maps) with states given in stand axes
    /// per sample, turned into sensor axes by `mount` (a stand that logs its angle).
    pub fn on_logged(&self, states: &[Kinematics], mount: &Mount, epsilon_source: String) -> Track {
        let to = |f: fn(&Kinematics) -> V3<Stand>| states.iter().map(|k| mount.to_sensor(f(k))).collect();
        Track {
            source: Source::Sampled { w: to(|k| k.w_rad_s), e: to(|k| k.e_rad_s2), a: to(|k| k.a_m_s2) },
            epsilon_source,
            ..self.clone()
        }
    }

    /// Every state, in order.
    pub fn states(&self) -> impl ExactSizeIterator<Item = SensorKinematics> + '_ {
        (0..self.len()).map(|k| self.at(k))
    }

    /// The same motion with `map` applied after what this track already applies.
    pub fn mapped(&self, map: Arc<dyn SampleMap>) -> Track {
        let mut out = self.clone();
        out.maps.push(map);
        out
    }

    /// The maps `self` applies beyond `base` when it is `base` with more maps (the same
    /// stamps, source and first maps, [`Self::mapped`]): a state of `self` is then `base`'s
    /// with these applied in order, no kinematics recomputed. None otherwise.
    pub fn maps_beyond(&self, base: &Track) -> Option<&[Arc<dyn SampleMap>]> {
        let n = base.maps.len();
        // Identity, not contents: comparing a million stored samples (or temperature rates)
        // per call would cost more than the kinematics it saves.
        let same_temp = match (&self.temp_rate_c_s, &base.temp_rate_c_s) {
            (None, None) => true,
            (Some(a), Some(b)) => Arc::ptr_eq(a, b),
            _ => false,
        };
        let same_source = match (&self.source, &base.source) {
            (Source::Sampled { w, e, a }, Source::Sampled { w: w2, e: e2, a: a2 }) => {
                Arc::ptr_eq(w, w2) && Arc::ptr_eq(e, e2) && Arc::ptr_eq(a, a2)
            }
            (Source::Logged { s, angles, mount }, Source::Logged { s: s2, angles: a2, mount: m2 }) => {
                s == s2 && Arc::ptr_eq(angles, a2) && mount == m2
            }
            (x, y) => x == y,
        };
        let same = self.t_s.same_as(&base.t_s)
            && self.maps.len() >= n
            && self.maps[..n].iter().zip(&base.maps).all(|(a, b)| Arc::ptr_eq(a, b))
            && same_temp
            && same_source;
        same.then(|| &self.maps[n..])
    }

    /// The motion `tau_s` seconds earlier at every stamp (the truth a sensor stamping its
    /// samples `tau_s` late reports). Conic and static tracks shift exactly (their maps,
    /// being pointwise, commute with the shift); stored tracks are interpolated
    /// (Catmull–Rom, held at the ends).
    pub fn delayed(&self, tau_s: f64) -> Track {
        match &self.source {
            // The maps act sample by sample and do not depend on time, so they commute with
            // the shift: the conic source moves, the maps stay.
            Source::Conic { c, mount, lag_s } => {
                Track { source: Source::Conic { c: *c, mount: mount.clone(), lag_s: lag_s + tau_s }, ..self.clone() }
            }
            Source::Stand { s, mount, lag_s } => {
                Track { source: Source::Stand { s: *s, mount: mount.clone(), lag_s: lag_s + tau_s }, ..self.clone() }
            }
            Source::Constant(_) => self.clone(),
            _ => {
                let states: Vec<SensorKinematics> = self.states().collect();
                let t = &self.t_s;
                // One quantity at a time: its samples, interpolated at the earlier times.
                let shift = |of: fn(&SensorKinematics) -> V3<Sensor>| -> Vec<V3<Sensor>> {
                    let x: Vec<V3<Sensor>> = states.iter().map(of).collect();
                    let mut hint = 0;
                    t.iter().map(|&tk| interpolate(t, &x, tk - tau_s, &mut hint)).collect()
                };
                let (w, e, a) = (shift(|s| s.w_rad_s), shift(|s| s.e_rad_s2), shift(|s| s.a_m_s2));
                Track {
                    t_s: self.t_s.clone(),
                    source: Source::Sampled { w: w.into(), e: e.into(), a: a.into() },
                    maps: Vec::new(),
                    epsilon_source: self.epsilon_source.clone(),
                    temp_rate_c_s: self.temp_rate_c_s.clone(),
                }
            }
        }
    }

    /// The same track with its source's states stored sample by sample (its maps kept, to
    /// apply after them): every later evaluation is a lookup, with the numbers the source
    /// gives. For a search that evaluates a short track many times through pointwise maps.
    pub fn materialised(&self) -> Track {
        let plain = Track { maps: Vec::new(), ..self.clone() };
        let states: Vec<SensorKinematics> = plain.states().collect();
        Track {
            source: Source::Sampled {
                w: states.iter().map(|s| s.w_rad_s).collect(),
                e: states.iter().map(|s| s.e_rad_s2).collect(),
                a: states.iter().map(|s| s.a_m_s2).collect(),
            },
            ..self.clone()
        }
    }

    /// Samples `k0..k1` (clamped to the track), with the same source and time stamps: a
    /// run with a stretch left out at either end.
    pub fn range(&self, k0: usize, k1: usize) -> Track {
        let k1 = k1.min(self.len());
        let k0 = k0.min(k1);
        let source = match &self.source {
            Source::Sampled { w, e, a } => {
                Source::Sampled { w: w[k0..k1].into(), e: e[k0..k1].into(), a: a[k0..k1].into() }
            }
            Source::Logged { s, angles, mount } => {
                Source::Logged { s: *s, angles: angles[k0..k1].into(), mount: mount.clone() }
            }
            other => other.clone(),
        };
        Track {
            t_s: self.t_s.slice(k0, k1),
            source,
            maps: self.maps.clone(),
            epsilon_source: self.epsilon_source.clone(),
            temp_rate_c_s: self.temp_rate_c_s.as_ref().map(|r| r[k0..k1].into()),
        }
    }

    /// Every `step`-th sample (from the first), with the same source: for searches on
    /// reduced data.
    pub fn every(&self, step: usize) -> Track {
        let step = step.max(1);
        let t_s: crate::session::Column<f64> = self.t_s.iter().step_by(step).copied().collect();
        let source = match &self.source {
            Source::Sampled { w, e, a } => {
                let pick = |x: &[V3<Sensor>]| x.iter().step_by(step).copied().collect();
                Source::Sampled { w: pick(w), e: pick(e), a: pick(a) }
            }
            Source::Logged { s, angles, mount } => {
                Source::Logged { s: *s, angles: angles.iter().step_by(step).copied().collect(), mount: mount.clone() }
            }
            other => other.clone(),
        };
        let temp_rate_c_s = self.temp_rate_c_s.as_ref().map(|r| r.iter().step_by(step).copied().collect());
        Track { t_s, source, maps: self.maps.clone(), epsilon_source: self.epsilon_source.clone(), temp_rate_c_s }
    }
}

/// Builds the true motion of a run in sensor axes from its declared motion and mount.
pub fn track(run: &Run, g_m_s2: f64, deriv: &DerivativeConfig) -> Track {
    track_for(&run.spec.motion, &run.spec.mount, &run.rec, g_m_s2, deriv)
}

/// As [`track`], from the parts.
pub fn track_for(
    motion: &MotionSpec,
    mount: &Mount,
    rec: &crate::session::Recording,
    g_m_s2: f64,
    deriv: &DerivativeConfig,
) -> Track {
    let constant = |k: Kinematics| {
        Source::Constant(SensorKinematics {
            w_rad_s: mount.to_sensor(k.w_rad_s),
            e_rad_s2: mount.to_sensor(k.e_rad_s2),
            a_m_s2: mount.to_sensor(k.a_m_s2),
        })
    };
    let (source, epsilon_source) = match motion {
        MotionSpec::Conic { cone_angle_deg, rate_deg_s, phase_deg } => match rec.angle_rad.as_deref() {
            Some(theta) => logged_source(cone_angle_deg.to_radians(), rec, theta, mount, g_m_s2, deriv),
            None => {
                let c = super::Conic::from_deg(*cone_angle_deg, *rate_deg_s, *phase_deg).fixed(g_m_s2);
                (Source::Conic { c, mount: mount.clone(), lag_s: 0.0 }, EPSILON_CONIC.to_string())
            }
        },
        MotionSpec::Static { up_stand, earth_rate_rad_s } => {
            let k = Kinematics {
                w_rad_s: V3::new(*earth_rate_rad_s),
                e_rad_s2: V3::new([0.0; 3]),
                a_m_s2: V3::new([up_stand[0] * g_m_s2, up_stand[1] * g_m_s2, up_stand[2] * g_m_s2]),
            };
            (constant(k), EPSILON_STATIC.to_string())
        }
        MotionSpec::StaticUnknown | MotionSpec::Rotation { .. } | MotionSpec::MultiPosition { .. } => {
            // Protocol runs have no per-sample truth: the state is unknown (NaN), and the
            // protocol fit (crate::estimate::protocol) uses them instead.
            let nan = V3::new([f64::NAN; 3]);
            (
                constant(Kinematics { w_rad_s: nan, e_rad_s2: nan, a_m_s2: nan }),
                "unknown (protocol run: see `crosscal fit` on protocol sessions)".to_string(),
            )
        }
        MotionSpec::Reference => match rec.reference.as_ref() {
            None => (Source::Sampled { w: Arc::new([]), e: Arc::new([]), a: Arc::new([]) }, String::new()),
            Some(r) => reference_source(rec, r, mount, deriv),
        },
    };
    if let Source::Sampled { w, .. } = &source {
        if w.is_empty() {
            // A reference run without reference columns: no states (the reader refuses such
            // sessions; an empty track keeps callers' lengths honest).
            return Track::default();
        }
    }
    let temp_rate_c_s = rec.temp_c.as_ref().map(|t| crate::stats::temp_rate::centred(&rec.t_s, t).into());
    Track { t_s: rec.t_s.clone(), source, maps: Vec::new(), epsilon_source, temp_rate_c_s }
}

/// A conic run whose stand logs its angle: paper eq. 1 generalised to a variable stand
/// angle (module [`super::stand`]: ω = θ̇ f, ε = θ̈ f + θ̇² f_θ at the declared cone angle),
/// with θ̇ and θ̈ the logged angle's smoothed derivatives ([`super::stand::logged_angles`]).
fn logged_source(
    cone_angle_rad: f64,
    rec: &crate::session::Recording,
    theta_rad: &[f64],
    mount: &Mount,
    g_m_s2: f64,
    deriv: &DerivativeConfig,
) -> (Source, String) {
    let s = super::stand::StandMotion::ideal(cone_angle_rad, 0.0, 0.0).fixed(g_m_s2);
    let deriv = super::stand::log_derivative(&rec.t_s, theta_rad, deriv);
    let angles = super::stand::logged_angles(&rec.t_s, theta_rad, &deriv).into();
    (Source::Logged { s, angles, mount: mount.clone() }, super::stand::logged_method(&deriv))
}

/// A reference run's stored states, with ε given or derived from the reference rate.
fn reference_source(
    rec: &crate::session::Recording,
    r: &crate::session::ReferenceColumns,
    mount: &Mount,
    deriv: &DerivativeConfig,
) -> (Source, String) {
    let n = rec.len();
    let derived;
    let (e, how): (&[V3<Stand>], String) = match &r.e_rad_s2 {
        Some(e) => (e, "given (ex_ref, ey_ref, ez_ref columns)".into()),
        None => {
            let mut out = vec![V3::new([0.0; 3]); n];
            derivative_offline(&rec.t_s, &r.w_rad_s, deriv, &mut out);
            derived = out;
            (&derived, format!("derived from the reference rate: {}", deriv.describe()))
        }
    };
    let to = |x: &[V3<Stand>]| x.iter().map(|&v| mount.to_sensor(v)).collect();
    (Source::Sampled { w: to(&r.w_rad_s), e: to(e), a: to(&r.a_m_s2) }, how)
}

/// Value at time `t` of a sampled series by Catmull–Rom cubic interpolation on the
/// (possibly non-uniform) time stamps, clamped at the ends.
pub fn interpolate<T>(t_s: &[f64], x: &[T], t: f64, hint: &mut usize) -> T
where
    T: Copy + std::ops::Index<usize, Output = f64> + From<[f64; 3]>,
{
    let n = t_s.len();
    if n == 0 {
        return T::from([0.0; 3]);
    }
    if n == 1 || t <= t_s[0] {
        return x[0];
    }
    if t >= t_s[n - 1] {
        return x[n - 1];
    }
    let mut i = (*hint).min(n - 2);
    while i + 1 < n - 1 && t_s[i + 1] <= t {
        i += 1;
    }
    while i > 0 && t_s[i] > t {
        i -= 1;
    }
    *hint = i;
    let (t0, t1) = (t_s[i], t_s[i + 1]);
    let h = t1 - t0;
    let u = (t - t0) / h;
    let slope = |j: usize, c: usize| -> f64 {
        let a = j.saturating_sub(1);
        let b = (j + 1).min(n - 1);
        (x[b][c] - x[a][c]) / (t_s[b] - t_s[a]) * h
    };
    let (h00, h10, h01, h11) = (
        2.0 * u * u * u - 3.0 * u * u + 1.0,
        u * u * u - 2.0 * u * u + u,
        -2.0 * u * u * u + 3.0 * u * u,
        u * u * u - u * u,
    );
    let mut out = [0.0; 3];
    for c in 0..3 {
        out[c] = h00 * x[i][c] + h10 * slope(i, c) + h01 * x[i + 1][c] + h11 * slope(i + 1, c);
    }
    T::from(out)
}

#[cfg(test)]
// Exact equality is the point: the lazy state must be the same arithmetic as the closed form.
#[allow(clippy::float_cmp)]
mod tests {
    use super::*;
    use crate::session::Recording;

    fn conic_track(mount: &Mount, n: usize) -> (Track, ConicAt) {
        let rec = Recording { t_s: (0..n).map(|k| k as f64 * 0.01).collect(), ..Default::default() };
        let motion = MotionSpec::Conic { cone_angle_deg: 20.0, rate_deg_s: -30.0, phase_deg: 15.0 };
        let tr = track_for(&motion, mount, &rec, 9.81, &DerivativeConfig::default());
        (tr, crate::motion::Conic::from_deg(20.0, -30.0, 15.0).fixed(9.81))
    }

    #[test]
    fn a_conic_track_is_the_closed_form_in_sensor_axes() {
        let mount = Mount::parse(&["+y", "-x", "+z"]).unwrap();
        let (tr, c) = conic_track(&mount, 500);
        assert_eq!(tr.len(), 500);
        for k in [0, 17, 499] {
            let want = c.at(tr.t_s[k]);
            let got = tr.at(k);
            assert_eq!(got.w_rad_s, mount.to_sensor(want.w_rad_s));
            assert_eq!(got.e_rad_s2, mount.to_sensor(want.e_rad_s2));
            assert_eq!(got.a_m_s2, mount.to_sensor(want.a_m_s2));
        }
    }

    #[derive(Debug)]
    struct Halve;
    impl SampleMap for Halve {
        fn apply(&self, k: &mut SensorKinematics) {
            for i in 0..3 {
                k.w_rad_s[i] *= 0.5;
            }
        }
    }

    #[test]
    fn a_delay_is_exact_on_a_conic_and_commutes_with_pointwise_maps() {
        let (tr, c) = conic_track(&Mount::identity(), 300);
        let tau = 0.0123;
        let mapped_then_delayed = tr.mapped(Arc::new(Halve)).delayed(tau);
        let delayed_then_mapped = tr.delayed(tau).mapped(Arc::new(Halve));
        for k in [0, 150, 299] {
            let want = c.at(tr.t_s[k] - tau);
            let a = mapped_then_delayed.at(k);
            assert_eq!(a.a_m_s2.xyz, want.a_m_s2.xyz);
            for i in 0..3 {
                assert_eq!(a.w_rad_s[i], 0.5 * want.w_rad_s[i]);
            }
            assert_eq!(a, delayed_then_mapped.at(k));
        }
    }

    #[test]
    fn a_stored_track_is_delayed_by_interpolation_and_thinned_sample_by_sample() {
        // A stored track of a smooth motion: the interpolated delay matches the closed form.
        let (conic, c) = conic_track(&Mount::identity(), 1000);
        let states: Vec<SensorKinematics> = conic.states().collect();
        let stored = Track::sampled(
            conic.t_s.to_vec(),
            states.iter().map(|s| s.w_rad_s).collect(),
            states.iter().map(|s| s.e_rad_s2).collect(),
            states.iter().map(|s| s.a_m_s2).collect(),
            "test".into(),
        );
        let tau = 0.004;
        let d = stored.delayed(tau);
        for k in [10, 500, 990] {
            let want = c.at(stored.t_s[k] - tau);
            for i in 0..3 {
                assert!((d.at(k).a_m_s2[i] - want.a_m_s2.xyz[i]).abs() < 1e-6, "k {k} axis {i}");
            }
        }
        let thin = stored.every(7);
        assert_eq!(thin.len(), 1000_usize.div_ceil(7));
        assert_eq!(thin.at(3), stored.at(21));
        assert_eq!(conic.every(7).at(3), conic.at(21));
    }

    #[test]
    fn the_maps_beyond_a_track_are_found_by_identity_not_by_comparing_samples() {
        let (conic, _) = conic_track(&Mount::identity(), 200);
        let halved = conic.mapped(Arc::new(Halve));
        assert_eq!(halved.maps_beyond(&conic).map(<[_]>::len), Some(1));
        assert_eq!(conic.maps_beyond(&conic).map(<[_]>::len), Some(0));
        assert!(conic.maps_beyond(&halved).is_none());
        assert!(conic.delayed(0.01).mapped(Arc::new(Halve)).maps_beyond(&conic).is_none());
        // A stored track's copies share its samples (identity holds through `mapped`); a
        // stored copy of a track gives its states and keeps its maps.
        let stored = conic.materialised();
        assert!((0..200).all(|k| stored.at(k) == conic.at(k)));
        assert!((0..200).all(|k| halved.materialised().at(k) == halved.at(k)));
        assert_eq!(stored.maps_beyond(&stored).map(<[_]>::len), Some(0));
        assert_eq!(stored.mapped(Arc::new(Halve)).maps_beyond(&stored).map(<[_]>::len), Some(1));
        assert!(stored.every(2).mapped(Arc::new(Halve)).maps_beyond(&stored).is_none());
    }
}
