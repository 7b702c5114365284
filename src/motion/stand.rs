//! An imperfect conic stand: the motion a stand really makes when it does not move exactly
//! as its manifest says, and the motion of a stand that logs its angle.
//!
//! The attitude of the platform is R(θ, α) = Rz(−θ)·Ry(α)·Rz(θ) (body → base), with a
//! variable stand angle θ(t) and a cone angle α that may wobble with θ. Body-frame rate
//! (Rᵀ Ṙ = [ω]×), angular acceleration and specific force are, with
//! f(α, θ) = (sin α cos θ, −sin α sin θ, 1 − cos α) and g(θ) = (sin θ, cos θ, 0):
//! ```text
//! ω = θ̇ f + α̇ g
//! ε = θ̈ f + θ̇ (f_θ θ̇ + f_α α̇) + α̈ g + α̇ θ̇ g_θ
//! a = |g| · Rᵀ u            (u: the base's up, tilted by the base tilt)
//! ω += Rᵀ Ω_E               (the Earth's rate in base axes, when present)
//! ```
//! At constant θ̇ = ω_s, α fixed, u = e_z and Ω_E = 0 this is paper eq. 1.
//!
//! The stand's imperfections, all small: a cone angle and rate off their labels, a phase
//! offset, a base tilt (two angles), a once- and twice-per-revolution speed ripple (the
//! angle's deviation from uniform turning θ = θ₀ + Σₕ cₕ cos hθ₀ + sₕ sin hθ₀, θ₀ = ω_s t + φ,
//! so the speed's relative ripple is h·√(cₕ² + sₕ²)), a wobble of the cone axis (α = α₀ +
//! w_c cos θ + w_s sin θ), a drift of the rate within a run (θ₀ = ω_s (t + ½ d (t − t_d)²) + φ
//! for t ≥ t_d, the run's first sample: the stand starts at its rate and its speed changes
//! by the share d per second, θ̇₀ = ω_s (1 + d (t − t_d))) and the Earth's rotation.

use super::{Kinematics, SensorKinematics};
use crate::frames::{Mount, Stand, V3};

/// The true motion of an imperfect conic stand (SI; angles in radians).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct StandMotion {
    /// Mean cone half-angle α₀, rad.
    pub cone_angle_rad: f64,
    /// Mean stand rate ω_s, rad/s (signed).
    pub rate_rad_s: f64,
    /// Phase φ at t = 0, rad.
    pub phase_rad: f64,
    /// Base tilt about the base's x and y axes, rad: the base turned right-handed from level
    /// by τ_x about its x axis, then τ_y about its y axis (base → level = Rx(τ_x)·Ry(τ_y)),
    /// so that up in base axes = Ry(τ_y)ᵀ Rx(τ_x)ᵀ e_z = (−sin τ_y cos τ_x, sin τ_x, cos τ_y cos τ_x).
    pub tilt_rad: [f64; 2],
    /// Angle ripple (cos, sin) once and twice per revolution, rad of θ.
    pub ripple_rad: [[f64; 2]; 2],
    /// Cone-axis wobble: α = α₀ + w_c cos θ + w_s sin θ, rad.
    pub wobble_rad: [f64; 2],
    /// The Earth's rate in base axes (x, y horizontal, z up), rad/s.
    pub earth_rad_s: [f64; 3],
    /// Drift of the rate within the run: its relative change per second, 1/s.
    pub rate_drift_per_s: f64,
    /// When the drift starts (the run's first sample), s on the run's clock.
    pub drift_from_s: f64,
}

/// The stand's angle and its first two time derivatives at one instant.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Angle {
    /// θ, rad.
    pub theta: f64,
    /// θ̇, rad/s.
    pub rate: f64,
    /// θ̈, rad/s².
    pub accel: f64,
}

/// How the stand's angle moves with the parameters of its law
/// ([`StandMotion::angle_partials`]): each field the change of θ, θ̇ and θ̈ per unit change
/// of one parameter.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AnglePartials {
    /// Per rad/s of the rate.
    pub rate: Angle,
    /// Per rad of the phase.
    pub phase: Angle,
    /// Per 1/s of the rate's drift.
    pub drift: Angle,
    /// Per rad of each ripple coefficient, `[harmonic − 1][cos, sin]` as in
    /// [`StandMotion::ripple_rad`].
    pub ripple: [[Angle; 2]; 2],
}

impl AnglePartials {
    /// The partials of a logged angle ([`StandMotion::angle_or_logged`]): it moves with
    /// the phase alone (the encoder's offset), one for one.
    pub fn logged() -> Self {
        let zero = Angle { theta: 0.0, rate: 0.0, accel: 0.0 };
        Self { rate: zero, phase: Angle { theta: 1.0, ..zero }, drift: zero, ripple: [[zero; 2]; 2] }
    }
}

impl StandMotion {
    /// The ideal stand of a conic run (paper eq. 1): every imperfection zero.
    pub fn ideal(cone_angle_rad: f64, rate_rad_s: f64, phase_rad: f64) -> Self {
        Self { cone_angle_rad, rate_rad_s, phase_rad, ..Self::default() }
    }

    /// The stand's angle at time `t_s` (turning at the drifting rate, plus the ripple):
    /// θ = θ₀ + Σₕ cₕ cos hθ₀ + sₕ sin hθ₀, so θ̇ = θ̇₀ θ′ and θ̈ = θ̇₀² θ″ + θ̈₀ θ′ (primes:
    /// derivatives in θ₀).
    #[inline]
    pub fn angle(&self, t_s: f64) -> Angle {
        let w = self.rate_rad_s;
        let d = self.rate_drift_per_s;
        let (th0, w0, e0) = if d == 0.0 {
            (w * t_s + self.phase_rad, w, 0.0)
        } else {
            let tau = t_s - self.drift_from_s;
            (w * (t_s + 0.5 * d * tau * tau) + self.phase_rad, w * (1.0 + d * tau), w * d)
        };
        let (mut theta, mut d1, mut d2) = (th0, 1.0, 0.0);
        for (h, [c, s]) in self.ripple_rad.iter().enumerate() {
            if *c == 0.0 && *s == 0.0 {
                continue;
            }
            let h = (h + 1) as f64;
            let (sn, cs) = libm::sincos(h * th0);
            theta += c * cs + s * sn;
            d1 += h * (-c * sn + s * cs);
            d2 += h * h * (-c * cs - s * sn);
        }
        Angle { theta, rate: w0 * d1, accel: w0 * w0 * d2 + e0 * d1 }
    }

    /// How the angle at `t_s` ([`Self::angle`]) moves with each parameter of its law: per
    /// unit change of the rate (rad/s), the phase (rad), the drift (1/s) and each ripple
    /// coefficient (rad), the change of θ, θ̇ and θ̈. Exact, not a difference: with
    /// θ = θ₀ + R(θ₀), θ̇ = θ̇₀ θ′ and θ̈ = θ̇₀² θ″ + θ̈₀ θ′ (θ′ = 1 + R′, θ″ = R″), a parameter
    /// moving θ₀, θ̇₀, θ̈₀ by δθ₀, δθ̇₀, δθ̈₀ and the ripple R directly by δR moves
    /// θ by θ′ δθ₀ + δR, θ̇ by δθ̇₀ θ′ + θ̇₀ (R″ δθ₀ + δR′) and θ̈ by
    /// 2 θ̇₀ δθ̇₀ θ″ + θ̇₀² (R‴ δθ₀ + δR″) + δθ̈₀ θ′ + θ̈₀ (R″ δθ₀ + δR′).
    pub fn angle_partials(&self, t_s: f64) -> AnglePartials {
        self.angle_partials_with(t_s, libm::sincos)
    }

    /// [`Self::angle_partials`] with the sine and cosine of the angle at `t_s` given
    /// (`theta`, `sc`: [`Self::angle`]'s θ, as a walk along the run has them): the unrippled
    /// angle's are then those (without a ripple they are the same angle) or had from them by
    /// [`sincos_near`], the same to a unit in the last place.
    #[inline]
    pub fn angle_partials_near(&self, t_s: f64, theta: f64, sc: (f64, f64)) -> AnglePartials {
        self.angle_partials_with(
            t_s,
            |th0| if th0.to_bits() == theta.to_bits() { sc } else { sincos_near(th0, theta, sc) },
        )
    }

    /// [`Self::angle_partials`] with the unrippled angle's sine and cosine from `trig`.
    #[inline(always)]
    fn angle_partials_with(&self, t_s: f64, trig: impl FnOnce(f64) -> (f64, f64)) -> AnglePartials {
        let w = self.rate_rad_s;
        let d = self.rate_drift_per_s;
        let tau = t_s - self.drift_from_s;
        let (th0, w0, e0) = if d == 0.0 {
            (w * t_s + self.phase_rad, w, 0.0)
        } else {
            (w * (t_s + 0.5 * d * tau * tau) + self.phase_rad, w * (1.0 + d * tau), w * d)
        };
        let (s1, c1) = trig(th0);
        // sin and cos of hθ₀ for h = 1, 2 (the double angle).
        let harm = [(s1, c1), (2.0 * s1 * c1, c1 * c1 - s1 * s1)];
        let (mut r1, mut r2, mut r3) = (0.0, 0.0, 0.0);
        for (h, [c, s]) in self.ripple_rad.iter().enumerate() {
            let (sn, cs) = harm[h];
            let h = (h + 1) as f64;
            r1 += h * (-c * sn + s * cs);
            r2 += h * h * (-c * cs - s * sn);
            r3 += h * h * h * (c * sn - s * cs);
        }
        let d1 = 1.0 + r1;
        // (δθ₀, δθ̇₀, δθ̈₀) and (δR, δR′, δR″) to the change of the angle.
        let moved = |[t0, w0d, e0d]: [f64; 3], [r, rd, rdd]: [f64; 3]| Angle {
            theta: d1 * t0 + r,
            rate: w0d * d1 + w0 * (r2 * t0 + rd),
            accel: 2.0 * w0 * w0d * r2 + w0 * w0 * (r3 * t0 + rdd) + e0d * d1 + e0 * (r2 * t0 + rd),
        };
        let none = [0.0; 3];
        let ripple = |h: usize| {
            let (sn, cs) = harm[h];
            let k = (h + 1) as f64;
            [moved(none, [cs, -k * sn, -k * k * cs]), moved(none, [sn, k * cs, -k * k * sn])]
        };
        AnglePartials {
            rate: moved([t_s + 0.5 * d * tau * tau, 1.0 + d * tau, d], none),
            phase: moved([1.0, 0.0, 0.0], none),
            drift: moved([0.5 * w * tau * tau, w * tau, w], none),
            ripple: [ripple(0), ripple(1)],
        }
    }

    /// The stand's angle at `t_s`, or, for a stand that logs it, the `logged` angle offset
    /// by the motion's phase (the encoder's zero: the angle the log reads when the stand is
    /// at its own zero is −φ).
    #[inline]
    pub fn angle_or_logged(&self, t_s: f64, logged: Option<Angle>) -> Angle {
        match logged {
            Some(a) => Angle { theta: a.theta + self.phase_rad, ..a },
            None => self.angle(t_s),
        }
    }

    /// The base's up direction (unit).
    pub fn up(&self) -> [f64; 3] {
        let [tx, ty] = self.tilt_rad;
        [-ty.sin() * tx.cos(), tx.sin(), ty.cos() * tx.cos()]
    }

    /// Kinematics at time `t_s` in stand (platform) axes, gravity `g_m_s2`.
    #[inline]
    pub fn at(&self, t_s: f64, g_m_s2: f64) -> Kinematics {
        self.fixed(g_m_s2).at(t_s)
    }

    /// Kinematics for a given stand angle and its derivatives (a logged angle).
    pub fn at_angle(&self, an: Angle, g_m_s2: f64) -> Kinematics {
        self.fixed(g_m_s2).at_angle(an)
    }

    /// Kinematics at `t_s` in sensor axes through `mount`.
    #[inline]
    pub fn sensor_at(&self, t_s: f64, g_m_s2: f64, mount: &Mount) -> SensorKinematics {
        to_sensor(self.at(t_s, g_m_s2), mount)
    }

    /// The motion ready to evaluate at many instants under gravity `g_m_s2`: the base's up
    /// and (without a wobble) the cone angle's sine and cosine worked out once.
    pub fn fixed(&self, g_m_s2: f64) -> StandAt {
        let cone = self.wobble_rad.iter().all(|w| *w == 0.0).then(|| {
            let (sa, ca) = libm::sincos(self.cone_angle_rad);
            (self.cone_angle_rad, sa, ca)
        });
        StandAt { motion: *self, up: self.up(), cone, g_m_s2 }
    }
}

/// A [`StandMotion`] ready to evaluate ([`StandMotion::fixed`]): the same numbers as the
/// motion's own methods, without the base's up and a constant cone angle's sine and cosine
/// recomputed at every sample.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StandAt {
    /// The motion.
    pub motion: StandMotion,
    up: [f64; 3],
    /// (α, sin α, cos α) when α does not turn with θ (no wobble).
    cone: Option<(f64, f64, f64)>,
    g_m_s2: f64,
}

/// The farthest θ₀ may be from θ for [`sincos_near`] to take sin θ and cos θ from it, rad.
pub const NEAR_RAD: f64 = 0.05;

/// Sines and cosines of angles that change little from one call to the next (a stand's
/// angle, sample after sample): each from the last angle libm was asked for when within
/// [`NEAR_RAD`] of it ([`sincos_near`]: the same to a unit in the last place), so that a
/// run's samples cost a libm sine per 0.05 rad of the stand's turn instead of one each
/// (every 14 to 28 samples of the paper's runs, 10 and 20 °/s at 100 Hz).
#[derive(Debug, Clone, Copy)]
pub struct NearTrig {
    /// The last angle libm's sine and cosine were taken of (NaN before the first).
    theta: f64,
    sc: (f64, f64),
}

impl Default for NearTrig {
    fn default() -> Self {
        Self { theta: f64::NAN, sc: (0.0, 1.0) }
    }
}

impl NearTrig {
    /// (sin θ, cos θ).
    #[inline]
    pub fn of(&mut self, theta: f64) -> (f64, f64) {
        if (theta - self.theta).abs() <= NEAR_RAD {
            return sincos_near(theta, self.theta, self.sc);
        }
        self.sc = libm::sincos(theta);
        self.theta = theta;
        self.sc
    }
}

/// sin θ and cos θ from those of a nearby θ₀ (`sc0`): angle addition with the Taylor
/// series of the difference d = θ − θ₀ (terms to d⁹ and d⁸; the first left out is below 1e-19 for
/// |d| ≤ [`NEAR_RAD`]), or libm's when θ is farther. A stand parameter's nudge (the diagnosis's
/// stand columns) moves the stand's angle and cone angle by far less, so that they cost no
/// sine of their own.
#[inline]
pub fn sincos_near(theta: f64, theta0: f64, (s0, c0): (f64, f64)) -> (f64, f64) {
    let d = theta - theta0;
    if d.abs() > NEAR_RAD {
        return libm::sincos(theta);
    }
    // Products by the reciprocals: a division is ten times a multiplication's latency, and
    // this runs for every nudged sample.
    let d2 = d * d;
    let sd = d
        * (1.0 - d2 * (1.0 / 6.0) * (1.0 - d2 * (1.0 / 20.0) * (1.0 - d2 * (1.0 / 42.0) * (1.0 - d2 * (1.0 / 72.0)))));
    let cd = 1.0 - d2 * 0.5 * (1.0 - d2 * (1.0 / 12.0) * (1.0 - d2 * (1.0 / 30.0) * (1.0 - d2 * (1.0 / 56.0))));
    (s0 * cd + c0 * sd, c0 * cd - s0 * sd)
}

impl StandAt {
    /// Kinematics at time `t_s` in stand (platform) axes.
    #[inline]
    pub fn at(&self, t_s: f64) -> Kinematics {
        self.at_angle(self.motion.angle(t_s))
    }

    /// Kinematics at `t_s` in sensor axes through `mount`.
    #[inline]
    pub fn sensor_at(&self, t_s: f64, mount: &Mount) -> SensorKinematics {
        to_sensor(self.at(t_s), mount)
    }

    /// Kinematics for a given stand angle and its derivatives (a logged angle).
    #[inline]
    pub fn at_angle(&self, an: Angle) -> Kinematics {
        self.at_angle_trig(an, libm::sincos(an.theta), None)
    }

    /// The cone angle at a stand angle with sine and cosine `(st, ct)` (the wobble turns
    /// it once a revolution), with its own sine and cosine: (α, sin α, cos α).
    #[inline]
    pub fn cone_trig(&self, (st, ct): (f64, f64)) -> (f64, f64, f64) {
        let [wc, ws] = self.motion.wobble_rad;
        let alpha = self.motion.cone_angle_rad + wc * ct + ws * st;
        self.cone.filter(|c| c.0.to_bits() == alpha.to_bits()).unwrap_or_else(|| {
            let (sa, ca) = libm::sincos(alpha);
            (alpha, sa, ca)
        })
    }

    /// [`Self::at_angle`] with sin θ and cos θ given, and the cone angle's sine and cosine
    /// reused from `cone` ([`Self::cone_trig`] of a motion at the same θ) when its α is this
    /// motion's, else worked out from them ([`sincos_near`]): many nearby motions at one
    /// sample (a stand parameter nudged at a time) then cost one sine, the numbers of
    /// [`Self::at_angle`] to within a few units in the last place.
    #[inline(always)]
    pub fn at_angle_trig(&self, an: Angle, sc: (f64, f64), cone: Option<(f64, f64, f64)>) -> Kinematics {
        self.kinematics(&self.frame(sc, cone), an.rate, an.accel)
    }

    /// The kinematics at the stand angle with sines `sc` moved by the angle step whose sine
    /// and cosine are `step` (by angle addition), at the rate moved by `h_rate`, and at the
    /// angular acceleration moved by `h_accel`: the three nudged states of the angle's law
    /// (the diagnosis's stand columns), the same numbers as three calls of
    /// [`Self::at_angle_trig`]; the last two share their sines and rotations.
    #[inline(always)]
    pub fn at_angle_nudged(
        &self,
        an: Angle,
        (st, ct): (f64, f64),
        cone: Option<(f64, f64, f64)>,
        (sh, ch): (f64, f64),
        [h_rate, h_accel]: [f64; 2],
    ) -> [Kinematics; 3] {
        let moved = (st * ch + ct * sh, ct * ch - st * sh);
        let here = self.frame((st, ct), cone);
        [
            self.at_angle_trig(an, moved, cone),
            self.kinematics(&here, an.rate + h_rate, an.accel),
            self.kinematics(&here, an.rate, an.accel + h_accel),
        ]
    }

    /// What the kinematics at one stand angle take of its sines (`at_angle_trig`'s `cone`).
    #[inline(always)]
    fn frame(&self, (st, ct): (f64, f64), cone: Option<(f64, f64, f64)>) -> Frame {
        let m = &self.motion;
        let [wc, ws] = m.wobble_rad;
        let alpha = m.cone_angle_rad + wc * ct + ws * st;
        let hit = |c: Option<(f64, f64, f64)>| c.filter(|c| c.0.to_bits() == alpha.to_bits()).map(|c| (c.1, c.2));
        // A nearby motion's cone angle (a nudged one) from its sine and cosine.
        let (sa, ca) = hit(self.cone).or_else(|| hit(cone)).unwrap_or_else(|| match cone {
            Some((a0, s0, c0)) => sincos_near(alpha, a0, (s0, c0)),
            None => libm::sincos(alpha),
        });
        let to_body = |v: [f64; 3]| rotate_t([st, ct], [sa, ca], v);
        Frame {
            a1: -wc * st + ws * ct,
            a2: -wc * ct - ws * st,
            f: [sa * ct, -sa * st, 1.0 - ca],
            f_t: [-sa * st, -sa * ct, 0.0],
            f_a: [ca * ct, -ca * st, sa],
            gv: [st, ct, 0.0],
            g_t: [ct, -st, 0.0],
            up: to_body(self.up),
            earth: m.earth_rad_s.iter().any(|&x| x != 0.0).then(|| to_body(m.earth_rad_s)),
        }
    }

    /// The kinematics of the module documentation's equations at rate `td` and angular
    /// acceleration `tdd`, from the frame's sines.
    #[inline(always)]
    fn kinematics(&self, fr: &Frame, td: f64, tdd: f64) -> Kinematics {
        let ad = fr.a1 * td;
        let add = fr.a2 * td * td + fr.a1 * tdd;
        let mut w = [0.0; 3];
        let mut e = [0.0; 3];
        for i in 0..3 {
            w[i] = td * fr.f[i] + ad * fr.gv[i];
            e[i] = tdd * fr.f[i] + td * (fr.f_t[i] * td + fr.f_a[i] * ad) + add * fr.gv[i] + ad * td * fr.g_t[i];
        }
        if let Some(we) = fr.earth {
            for i in 0..3 {
                w[i] += we[i];
            }
        }
        let (g, up) = (self.g_m_s2, fr.up);
        Kinematics { w_rad_s: V3::new(w), e_rad_s2: V3::new(e), a_m_s2: V3::new([g * up[0], g * up[1], g * up[2]]) }
    }
}

/// What the kinematics at one stand angle take of the angle's and the cone angle's sines:
/// f, ∂f/∂θ, ∂f/∂α, g, ∂g/∂θ, dα/dθ and d²α/dθ² (module documentation), the base's up and
/// the Earth's rate in body axes.
struct Frame {
    f: [f64; 3],
    f_t: [f64; 3],
    f_a: [f64; 3],
    gv: [f64; 3],
    g_t: [f64; 3],
    a1: f64,
    a2: f64,
    up: [f64; 3],
    earth: Option<[f64; 3]>,
}

/// A stand state in sensor axes.
#[inline]
pub fn to_sensor(k: Kinematics, mount: &Mount) -> SensorKinematics {
    SensorKinematics {
        w_rad_s: mount.to_sensor(k.w_rad_s),
        e_rad_s2: mount.to_sensor(k.e_rad_s2),
        a_m_s2: mount.to_sensor(k.a_m_s2),
    }
}

/// Rᵀ v with R = Rz(−θ)·Ry(α)·Rz(θ): Rᵀ = Rz(−θ)·Ry(−α)·Rz(θ), from (sin θ, cos θ) and
/// (sin α, cos α).
#[inline]
pub fn rotate_t([s, c]: [f64; 2], [sa, ca]: [f64; 2], v: [f64; 3]) -> [f64; 3] {
    let w = [c * v[0] - s * v[1], s * v[0] + c * v[1], v[2]];
    let x = [ca * w[0] - sa * w[2], w[1], sa * w[0] + ca * w[2]];
    [c * x[0] + s * x[1], -s * x[0] + c * x[1], x[2]]
}

/// Two horizontal unit vectors perpendicular to `up` (right-handed with it): the first is
/// the stand axis least aligned with up, made perpendicular.
pub fn horizontal_basis(up: [f64; 3]) -> [[f64; 3]; 2] {
    let n = (up[0] * up[0] + up[1] * up[1] + up[2] * up[2]).sqrt().max(f64::MIN_POSITIVE);
    let u = up.map(|x| x / n);
    let i = (0..3).min_by(|&a, &b| u[a].abs().total_cmp(&u[b].abs())).unwrap_or(0);
    let mut e1 = [0.0; 3];
    e1[i] = 1.0;
    let d = u[i];
    for k in 0..3 {
        e1[k] -= d * u[k];
    }
    let m = (e1[0] * e1[0] + e1[1] * e1[1] + e1[2] * e1[2]).sqrt().max(f64::MIN_POSITIVE);
    let e1 = e1.map(|x| x / m);
    let e2 = [u[1] * e1[2] - u[2] * e1[1], u[2] * e1[0] - u[0] * e1[2], u[0] * e1[1] - u[1] * e1[0]];
    [e1, e2]
}

/// A constant rate added to a state's true rate (the Earth's on a static pose), sensor axes,
/// rad/s.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AddRate(pub [f64; 3]);

impl super::SampleMap for AddRate {
    fn apply(&self, k: &mut super::SensorKinematics) {
        for i in 0..3 {
            k.w_rad_s[i] += self.0[i];
        }
    }
}

/// Amplitude and phase of a pair of harmonic components: `x` and `y` with standard errors
/// `se_x`, `se_y` → (A, σ_A, ψ, σ_ψ) with A = √(x² + y²), ψ = atan2(y, x) (rad) and the
/// first-order (delta-method) errors σ_A² = (x σ_x)² + (y σ_y)² over A², σ_ψ² = (y σ_x)² +
/// (x σ_y)² over A⁴. At A = 0 the phase is undefined (σ_ψ = π) and σ_A is the mean error.
pub fn polar(x: f64, y: f64, se_x: f64, se_y: f64) -> [f64; 4] {
    let amp = x.hypot(y);
    if amp > 0.0 {
        let se_amp = (x * se_x).hypot(y * se_y) / amp;
        let se_psi = (y * se_x).hypot(x * se_y) / (amp * amp);
        [amp, se_amp, y.atan2(x), se_psi.min(std::f64::consts::PI)]
    } else {
        [0.0, se_x.hypot(se_y) / std::f64::consts::SQRT_2, 0.0, std::f64::consts::PI]
    }
}

/// The relative speed ripple h·A and its phase ψ of the angle ripple `[c, s]` h times per
/// revolution (θ = θ₀ + c cos hθ₀ + s sin hθ₀ = θ₀ + A sin(hθ₀ + ψ), so the speed is
/// ω_s (1 + h·A cos(hθ₀ + ψ))), with standard errors: (h·A, σ, ψ rad, σ_ψ).
pub fn speed_ripple(h: usize, cs: [f64; 2], se: [f64; 2]) -> [f64; 4] {
    let [a, sa, psi, spsi] = polar(cs[1], cs[0], se[1], se[0]);
    let h = h as f64;
    [h * a, h * sa, psi, spsi]
}

/// The stand's angle, rate and angular acceleration from a logged angle θ_k (rad) on the
/// time stamps: θ unwrapped, θ̇ and θ̈ by the local least-squares (Savitzky–Golay)
/// derivative `deriv` applied once and twice ([`super::derivative_offline`]).
pub fn logged_angles(t_s: &[f64], theta_rad: &[f64], deriv: &super::DerivativeConfig) -> Vec<Angle> {
    let n = t_s.len().min(theta_rad.len());
    let mut unwrapped: Vec<V3<Stand>> = Vec::with_capacity(n);
    let mut offset = 0.0;
    for k in 0..n {
        if k > 0 {
            let jump = theta_rad[k] - theta_rad[k - 1];
            offset -= std::f64::consts::TAU * (jump / std::f64::consts::TAU).round();
        }
        unwrapped.push(V3::new([theta_rad[k] + offset, 0.0, 0.0]));
    }
    let mut d1 = vec![V3::new([0.0; 3]); n];
    super::derivative_offline(&t_s[..n], &unwrapped, deriv, &mut d1);
    let mut d2 = vec![V3::new([0.0; 3]); n];
    super::derivative_offline(&t_s[..n], &d1, deriv, &mut d2);
    (0..n).map(|k| Angle { theta: unwrapped[k][0], rate: d1[k][0], accel: d2[k][0] }).collect()
}

/// Share of a revolution a stand log's derivative window spans: the stand's speed varies
/// on the revolution's harmonics (ripple once and twice per turn), which a local cubic over
/// a sixteenth of a turn follows to 5e-5 of the second harmonic's size, while the encoder's
/// resolution, amplified by the derivative, falls with the window's length to the power 3/2.
const LOG_WINDOW_REV: f64 = 1.0 / 16.0;

/// Most samples on each side of a stand log's derivative window (a slow stand sampled fast).
const LOG_HALF_WINDOW_MAX: usize = 200;

/// The derivative a stand's logged angle θ_k (rad) on the time stamps gets: `deriv` with
/// its window widened to about [`LOG_WINDOW_REV`] of a revolution at the log's mean rate
/// (never narrower than `deriv`'s, at most [`LOG_HALF_WINDOW_MAX`] samples each side). With
/// the default 11 samples, a 0.001° encoder at 100 Hz would add 0.007 °/s of rate noise (its
/// quantisation, σ = q/√12, times the cubic slope's noise gain 25 s⁻¹), more than a good
/// gyro's own; over a sixteenth of a turn at 10 °/s (225 samples) it adds 7e-5 °/s.
pub fn log_derivative(t_s: &[f64], theta_rad: &[f64], deriv: &super::DerivativeConfig) -> super::DerivativeConfig {
    let n = t_s.len().min(theta_rad.len());
    if n < 3 {
        return *deriv;
    }
    let span_s = t_s[n - 1] - t_s[0];
    let turned: f64 = theta_rad[..n]
        .windows(2)
        .map(|w| {
            let d = w[1] - w[0];
            d - std::f64::consts::TAU * (d / std::f64::consts::TAU).round()
        })
        .sum();
    let (rate, dt) = (turned.abs() / span_s, span_s / (n - 1) as f64);
    if !(rate > 0.0 && dt > 0.0 && rate.is_finite() && dt.is_finite()) {
        return *deriv;
    }
    let samples = LOG_WINDOW_REV * std::f64::consts::TAU / rate / dt;
    let half = ((samples / 2.0).floor().min(LOG_HALF_WINDOW_MAX as f64) as usize).max(deriv.half_window);
    super::DerivativeConfig { half_window: half, ..*deriv }
}

/// How the kinematics of a run with a logged angle are derived (for reports).
pub fn logged_method(deriv: &super::DerivativeConfig) -> String {
    format!("from the stand's logged angle: rate and angular acceleration by {} (applied twice)", deriv.describe())
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Matrix3, Rotation3, Vector3};

    fn attitude(theta: f64, alpha: f64) -> Matrix3<f64> {
        let rz = |a: f64| *Rotation3::from_axis_angle(&Vector3::z_axis(), a).matrix();
        let ry = |a: f64| *Rotation3::from_axis_angle(&Vector3::y_axis(), a).matrix();
        rz(-theta) * ry(alpha) * rz(theta)
    }

    #[test]
    fn the_angles_partials_are_its_central_differences() {
        let s = StandMotion {
            rate_rad_s: -0.7,
            phase_rad: 0.3,
            ripple_rad: [[0.02, -0.01], [0.005, 0.01]],
            rate_drift_per_s: -3e-3,
            drift_from_s: 1.5,
            ..StandMotion::default()
        };
        // Each parameter by name, with the partial that claims to be its derivative.
        type Knob = (&'static str, fn(&mut StandMotion) -> &mut f64, fn(&AnglePartials) -> Angle);
        let knobs: [Knob; 7] = [
            ("rate", |m| &mut m.rate_rad_s, |p| p.rate),
            ("phase", |m| &mut m.phase_rad, |p| p.phase),
            ("drift", |m| &mut m.rate_drift_per_s, |p| p.drift),
            ("c1", |m| &mut m.ripple_rad[0][0], |p| p.ripple[0][0]),
            ("s1", |m| &mut m.ripple_rad[0][1], |p| p.ripple[0][1]),
            ("c2", |m| &mut m.ripple_rad[1][0], |p| p.ripple[1][0]),
            ("s2", |m| &mut m.ripple_rad[1][1], |p| p.ripple[1][1]),
        ];
        for base in [s, StandMotion { ripple_rad: [[0.0; 2]; 2], rate_drift_per_s: 0.0, ..s }] {
            for k in 0..12 {
                let t = 0.83 * k as f64 + 0.1;
                let p = base.angle_partials(t);
                for (name, field, partial) in knobs {
                    let h = 1e-6;
                    let at = |d: f64| {
                        let mut m = base;
                        *field(&mut m) += d;
                        m.angle(t)
                    };
                    let (hi, lo) = (at(h), at(-h));
                    let num = [hi.theta - lo.theta, hi.rate - lo.rate, hi.accel - lo.accel].map(|x| x / (2.0 * h));
                    let a = partial(&p);
                    for (x, y) in num.iter().zip([a.theta, a.rate, a.accel]) {
                        assert!((x - y).abs() < 1e-6 * (1.0 + y.abs()), "{name} at t {t}: {num:?} against {a:?}");
                    }
                }
            }
        }
    }

    #[test]
    fn the_closed_form_is_the_attitude_differentiated() {
        let s = StandMotion {
            cone_angle_rad: 0.2,
            rate_rad_s: -0.5,
            phase_rad: 0.3,
            tilt_rad: [0.01, -0.02],
            ripple_rad: [[0.02, -0.01], [0.005, 0.01]],
            wobble_rad: [0.003, -0.002],
            earth_rad_s: [0.0; 3],
            rate_drift_per_s: -3e-3,
            drift_from_s: 1.5,
        };
        let rot = |t: f64| {
            let a = s.angle(t);
            let (st, ct) = a.theta.sin_cos();
            attitude(a.theta, s.cone_angle_rad + s.wobble_rad[0] * ct + s.wobble_rad[1] * st)
        };
        let h = 1e-5;
        for k in 0..15 {
            let t = 0.37 * k as f64;
            let w_of = |t: f64| {
                let d = (rot(t + h) - rot(t - h)) / (2.0 * h);
                let m = rot(t).transpose() * d;
                [m[(2, 1)], m[(0, 2)], m[(1, 0)]]
            };
            let got = s.at(t, 9.8);
            let w = w_of(t);
            for i in 0..3 {
                assert!((got.w_rad_s[i] - w[i]).abs() < 1e-8, "ω {i}: {} vs {}", got.w_rad_s[i], w[i]);
                let e = (w_of(t + 1e-3)[i] - w_of(t - 1e-3)[i]) / 2e-3;
                assert!((got.e_rad_s2[i] - e).abs() < 1e-5, "ε {i}: {} vs {e}", got.e_rad_s2[i]);
            }
            let up = Vector3::from(s.up());
            let a = rot(t).transpose() * up * 9.8;
            for i in 0..3 {
                assert!((got.a_m_s2[i] - a[i]).abs() < 1e-12);
            }
        }
    }

    #[test]
    fn the_ideal_stand_is_paper_eq_1() {
        let c = crate::motion::Conic::from_deg(10.0, 20.0, 5.0);
        let s = StandMotion::ideal(c.cone_angle_rad, c.rate_rad_s, c.phase_rad);
        for k in 0..10 {
            let t = 0.9 * k as f64;
            let (a, b) = (s.at(t, 9.8), c.at(t, 9.8));
            for i in 0..3 {
                assert!((a.w_rad_s[i] - b.w_rad_s[i]).abs() < 1e-14);
                assert!((a.e_rad_s2[i] - b.e_rad_s2[i]).abs() < 1e-14);
                assert!((a.a_m_s2[i] - b.a_m_s2[i]).abs() < 1e-12);
            }
        }
    }

    /// A 0.001° encoder at 100 Hz on a 10 °/s stand: through the default 11-sample window
    /// its quantisation is several times a good gyro's noise (0.002 °/s); over the log's
    /// window (a sixteenth of a turn) it is a small share of it, and the speed's ripple is
    /// still followed.
    #[test]
    fn an_encoders_resolution_is_not_the_rate_noise() {
        let q = 0.001f64.to_radians();
        let s = StandMotion {
            rate_rad_s: 10.0f64.to_radians() * (1.0 + 3e-7),
            ripple_rad: [[0.002, 0.0], [0.0, 0.001]],
            ..StandMotion::default()
        };
        let t: Vec<f64> = (0..7200).map(|k| k as f64 * 0.01).collect();
        let th: Vec<f64> = t.iter().map(|&t| (s.angle(t).theta / q).round() * q).collect();
        let rms_deg_s = |cfg: &crate::motion::DerivativeConfig| {
            let got = logged_angles(&t, &th, cfg);
            let sq: f64 = (400..6800).map(|k| (got[k].rate - s.angle(t[k]).rate).powi(2)).sum();
            (sq / 6400.0).sqrt().to_degrees()
        };
        let default = crate::motion::DerivativeConfig::default();
        let wide = log_derivative(&t, &th, &default);
        assert_eq!(wide.half_window, 112, "{wide:?}");
        let (narrow, log) = (rms_deg_s(&default), rms_deg_s(&wide));
        assert!(narrow > 3e-3, "{narrow}");
        assert!(log < 2e-4, "{log}");
    }

    #[test]
    fn a_logged_angle_gives_the_rate_and_acceleration() {
        let s = StandMotion { rate_rad_s: 0.3, ripple_rad: [[0.01, 0.0], [0.0, 0.004]], ..StandMotion::default() };
        let t: Vec<f64> = (0..4000).map(|k| k as f64 * 0.01).collect();
        let th: Vec<f64> = t.iter().map(|&t| s.angle(t).theta.rem_euclid(std::f64::consts::TAU)).collect();
        let got = logged_angles(&t, &th, &crate::motion::DerivativeConfig::default());
        for k in [100, 2000, 3900] {
            let want = s.angle(t[k]);
            assert!((got[k].rate - want.rate).abs() < 1e-7, "{:?} {want:?}", got[k]);
            assert!((got[k].accel - want.accel).abs() < 1e-5, "{:?} {want:?}", got[k]);
        }
    }
}
