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
pub mod stand;
mod track;

use crate::frames::{Stand, V3};
pub use derivative::{derivative_offline, DerivativeConfig, SlopeWeights};
pub use track::{interpolate, track, track_for, SampleMap, SensorKinematics, Track, Walk};

use crate::session::MotionSpec;

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
        self.at_trig(libm::sincos(self.conic.theta(t_s)))
    }

    /// Cone phase θ at time t, rad.
    #[inline]
    pub fn theta(&self, t_s: f64) -> f64 {
        self.conic.theta(t_s)
    }

    /// [`Self::at`] with sin θ and cos θ given.
    #[inline]
    pub fn at_trig(&self, (st, ct): (f64, f64)) -> Kinematics {
        let (sa, ca, g_m_s2) = (self.sa, self.ca, self.g_m_s2);
        let ws = self.conic.rate_rad_s;
        Kinematics {
            w_rad_s: V3::new([ws * sa * ct, -ws * sa * st, ws * (1.0 - ca)]),
            e_rad_s2: V3::new([-ws * ws * sa * st, -ws * ws * sa * ct, 0.0]),
            a_m_s2: V3::new([-g_m_s2 * sa * ct, g_m_s2 * sa * st, g_m_s2 * ca]),
        }
    }
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
