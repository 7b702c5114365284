//! Reference kinematics: what the stand did, as true angular rate ω, angular acceleration
//! ε = dω/dt and specific force a, first in stand axes, then in sensor axes via the mount.
//!
//! Conic motion (paper eq. 1, with the spec's physically signed eq. 2), θ = ω_s t + φ:
//! ```text
//! ω = ω_s (sin α cos θ, −sin α sin θ, 1 − cos α)
//! ε = ω_s² (−sin α sin θ, −sin α cos θ, 0)
//! a = g (−sin α cos θ, sin α sin θ, cos α)
//! ```

pub mod derivative;

use crate::frames::{Mount, Sensor, Stand, V3};
pub use derivative::{derivative_offline, DerivativeConfig, SlopeWeights};

use crate::session::{MotionSpec, Run};

/// How ε is known on a conic run.
pub const EPSILON_CONIC: &str = "exact (conic motion, paper eq. 1 differentiated)";
/// How ε is known on a static run.
pub const EPSILON_STATIC: &str = "exact (static: zero)";

/// True kinematics at one instant in stand axes (SI units).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Kinematics {
    /// Angular rate, rad/s.
    pub w_rad_s: V3<Stand>,
    /// Angular acceleration, rad/s².
    pub e_rad_s2: V3<Stand>,
    /// Specific force, m/s².
    pub a_m_s2: V3<Stand>,
}

/// Conic motion of the stand (paper eqs. 1–2).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Conic {
    /// Cone half-angle α, rad.
    pub cone_angle_rad: f64,
    /// Stand rate ω_s, rad/s (signed).
    pub rate_rad_s: f64,
    /// Phase φ at t = 0, rad.
    pub phase_rad: f64,
}

impl Conic {
    /// The conic motion a run declares, if it is one.
    pub fn of(motion: &MotionSpec) -> Option<Self> {
        match motion {
            MotionSpec::Conic { cone_angle_deg, rate_deg_s, phase_deg } => {
                Some(Self::from_deg(*cone_angle_deg, *rate_deg_s, *phase_deg))
            }
            _ => None,
        }
    }

    /// The cone phase θ(t) as a phase line (for harmonic analysis of residuals).
    pub fn phase_line(&self) -> crate::stats::PhaseLine {
        crate::stats::PhaseLine { rate_rad_s: self.rate_rad_s, phase_rad: self.phase_rad }
    }

    /// From the manifest's degrees.
    pub fn from_deg(cone_angle_deg: f64, rate_deg_s: f64, phase_deg: f64) -> Self {
        Self {
            cone_angle_rad: cone_angle_deg.to_radians(),
            rate_rad_s: rate_deg_s.to_radians(),
            phase_rad: phase_deg.to_radians(),
        }
    }

    /// Cone phase θ at time t, rad.
    #[inline]
    pub fn theta(&self, t_s: f64) -> f64 {
        self.rate_rad_s * t_s + self.phase_rad
    }

    /// Kinematics at time t (paper eq. 1; eq. 2 with the spec's sign), g in m/s².
    #[inline]
    pub fn at(&self, t_s: f64, g_m_s2: f64) -> Kinematics {
        self.fixed(g_m_s2).at(t_s)
    }

    /// The motion with the cone angle's sine and cosine and g worked out once, for
    /// evaluating many samples (the same numbers as [`Self::at`]).
    pub fn fixed(&self, g_m_s2: f64) -> ConicAt {
        let (sa, ca) = self.cone_angle_rad.sin_cos();
        ConicAt { conic: *self, sa, ca, g_m_s2 }
    }
}

/// [`Conic`] ready to evaluate: see [`Conic::fixed`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ConicAt {
    conic: Conic,
    sa: f64,
    ca: f64,
    g_m_s2: f64,
}

impl ConicAt {
    /// Kinematics at time t (paper eq. 1; eq. 2 with the spec's sign).
    #[inline]
    pub fn at(&self, t_s: f64) -> Kinematics {
        let (sa, ca, g_m_s2) = (self.sa, self.ca, self.g_m_s2);
        let (st, ct) = libm::sincos(self.conic.theta(t_s));
        let ws = self.conic.rate_rad_s;
        Kinematics {
            w_rad_s: V3::new([ws * sa * ct, -ws * sa * st, ws * (1.0 - ca)]),
            e_rad_s2: V3::new([-ws * ws * sa * st, -ws * ws * sa * ct, 0.0]),
            a_m_s2: V3::new([-g_m_s2 * sa * ct, g_m_s2 * sa * st, g_m_s2 * ca]),
        }
    }
}

/// True motion of one run in sensor axes, one entry per recorded sample (SI units).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Track {
    /// Time stamps, s.
    pub t_s: Vec<f64>,
    /// Angular rate, rad/s.
    pub w_rad_s: Vec<V3<Sensor>>,
    /// Angular acceleration, rad/s².
    pub e_rad_s2: Vec<V3<Sensor>>,
    /// Specific force, m/s².
    pub a_m_s2: Vec<V3<Sensor>>,
    /// How ε was obtained (exact, given, or which derivative).
    pub epsilon_source: String,
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
    let n = rec.len();
    let mut tr = Track {
        t_s: rec.t_s.clone(),
        w_rad_s: Vec::with_capacity(n),
        e_rad_s2: Vec::with_capacity(n),
        a_m_s2: Vec::with_capacity(n),
        epsilon_source: String::new(),
    };
    let push = |tr: &mut Track, k: Kinematics| {
        tr.w_rad_s.push(mount.to_sensor(k.w_rad_s));
        tr.e_rad_s2.push(mount.to_sensor(k.e_rad_s2));
        tr.a_m_s2.push(mount.to_sensor(k.a_m_s2));
    };
    match motion {
        MotionSpec::Conic { cone_angle_deg, rate_deg_s, phase_deg } => {
            let c = Conic::from_deg(*cone_angle_deg, *rate_deg_s, *phase_deg).fixed(g_m_s2);
            for &t in &rec.t_s {
                push(&mut tr, c.at(t));
            }
            tr.epsilon_source = EPSILON_CONIC.into();
        }
        MotionSpec::Static { up_stand, earth_rate_rad_s } => {
            let k = Kinematics {
                w_rad_s: V3::new(*earth_rate_rad_s),
                e_rad_s2: V3::new([0.0; 3]),
                a_m_s2: V3::new([up_stand[0] * g_m_s2, up_stand[1] * g_m_s2, up_stand[2] * g_m_s2]),
            };
            for _ in 0..n {
                push(&mut tr, k);
            }
            tr.epsilon_source = EPSILON_STATIC.into();
        }
        MotionSpec::StaticUnknown | MotionSpec::Rotation { .. } | MotionSpec::MultiPosition { .. } => {
            // Protocol runs have no per-sample truth: the state is unknown (NaN), and the
            // protocol fit (crate::estimate::protocol) uses them instead.
            let nan = Kinematics {
                w_rad_s: V3::new([f64::NAN; 3]),
                e_rad_s2: V3::new([f64::NAN; 3]),
                a_m_s2: V3::new([f64::NAN; 3]),
            };
            for _ in 0..n {
                push(&mut tr, nan);
            }
            tr.epsilon_source = "unknown (protocol run: see `crosscal fit` on protocol sessions)".into();
        }
        MotionSpec::Reference => {
            let Some(r) = rec.reference.as_ref() else {
                return tr;
            };
            let derived;
            let e: &[V3<Stand>] = match &r.e_rad_s2 {
                Some(e) => {
                    tr.epsilon_source = "given (ex_ref, ey_ref, ez_ref columns)".into();
                    e
                }
                None => {
                    let mut out = vec![V3::new([0.0; 3]); n];
                    derivative_offline(&rec.t_s, &r.w_rad_s, deriv, &mut out);
                    derived = out;
                    tr.epsilon_source = format!("derived from the reference rate: {}", deriv.describe());
                    &derived
                }
            };
            for k in 0..n {
                push(&mut tr, Kinematics { w_rad_s: r.w_rad_s[k], e_rad_s2: e[k], a_m_s2: r.a_m_s2[k] });
            }
        }
    }
    tr
}

/// The cone phase of a run's declared motion (None unless conic).
pub fn cone_phase(motion: &MotionSpec) -> Option<crate::stats::PhaseLine> {
    Conic::of(motion).map(|c| c.phase_line())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn conic_epsilon_is_derivative_of_omega() {
        let c = Conic::from_deg(10.0, -20.0, 33.0);
        let h = 1e-5;
        for k in 0..20 {
            let t = k as f64 * 0.7;
            let d = |i: usize| (c.at(t + h, 9.8).w_rad_s.xyz[i] - c.at(t - h, 9.8).w_rad_s.xyz[i]) / (2.0 * h);
            let e = c.at(t, 9.8).e_rad_s2.xyz;
            for i in 0..3 {
                assert!((d(i) - e[i]).abs() < 1e-9, "axis {i}");
            }
        }
    }

    #[test]
    fn conic_specific_force_obeys_body_frame_kinematics() {
        // A fixed gravity vector seen from the rotating body: ḟ = −ω × f.
        let c = Conic::from_deg(15.0, 12.0, 5.0);
        let h = 1e-5;
        for k in 0..20 {
            let t = k as f64 * 1.3;
            let f = c.at(t, 9.8).a_m_s2.xyz;
            let w = c.at(t, 9.8).w_rad_s.xyz;
            let cross = [w[1] * f[2] - w[2] * f[1], w[2] * f[0] - w[0] * f[2], w[0] * f[1] - w[1] * f[0]];
            for i in 0..3 {
                let fd = (c.at(t + h, 9.8).a_m_s2.xyz[i] - c.at(t - h, 9.8).a_m_s2.xyz[i]) / (2.0 * h);
                assert!((fd + cross[i]).abs() < 1e-7, "axis {i}: {fd} vs {}", -cross[i]);
            }
            let norm = (f[0] * f[0] + f[1] * f[1] + f[2] * f[2]).sqrt();
            assert!((norm - 9.8).abs() < 1e-12);
        }
    }
}
