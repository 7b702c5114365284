//! The stand's own imperfections estimated jointly with the linear coefficients, because a
//! stand never sits exactly at its nominal setting: per conic run the actual cone angle α,
//! rate ω_s, phase φ and the drift of its rate from the run's first sample; common to the runs the base tilt (two angles), the speed ripple
//! once and twice per revolution (cos, sin of the angle's ripple) and the wobble of the cone
//! axis (cos, sin) — the imperfect stand of [`crate::motion::stand`].
//!
//! Gauss–Newton with variable projection (Golub & Pereyra 1973): at stand parameters s the
//! linear coefficients θ are solved exactly; the prediction ŷ = Φ(s)θ is linearised in both,
//! r ≈ Φ Δθ + D Δs with D = ∂(Φ(s)θ)/∂s by central differences of the stand's motion.
//! Per output channel c, a QR of [Φ_c | D_c | r_c] eliminates Δθ:
//! R = [R₁₁ R₁₂ R₁₃; 0 R₂₂ R₂₃; 0 0 ρ], and the step solves
//! (Σ_c R₂₂ᵀR₂₂/σ_c²) Δs = Σ_c R₂₂ᵀR₂₃/σ_c², halved until the weighted residual falls.
//! At convergence M = Σ_c R₂₂ᵀR₂₂/σ_c² is the information of s (cov s = M⁻¹), and each
//! channel's coefficient covariance gains G M⁻¹ Gᵀ with G = R₁₁⁻¹R₁₂ (the part of θ that
//! moves with s), so the standard errors of C and K include the stand's uncertainty.
//!
//! Not every stand parameter can be told from the unit on every session: a base tilt seen
//! on one mount moves the accelerometer's outputs as its bias and cross-coupling do, and a
//! run that logs its angle has no rate or phase to estimate. Before the first step each
//! parameter's information left after projecting out the model's coefficients and the
//! parameters kept before it (the Schur complement of M) is compared with its column's own
//! information Σ_c ‖D_c‖²/σ_c²; below [`HOLD_BELOW`] of it the parameter is held at its
//! label (zero for the common ones) and the fit says so.

mod linearise;

use super::memory::fit_in_memory as fit;
use super::{EstimateError, Fit, FitOptions, FitRun};
use crate::model::Model;
use crate::motion::stand::{StandAt, StandMotion};
use crate::motion::{DerivativeConfig, SensorKinematics, Track};
use crate::session::{MotionSpec, Session};
use crate::units::SensorKind;
use nalgebra::DMatrix;
use serde::{Deserialize, Serialize};

/// The setting of a conic run: cone angle, stand rate and phase (in the manifest's units).
/// Stored in profiles as the array `[cone_angle_deg, rate_deg_s, phase_deg]`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(from = "[f64; 3]", into = "[f64; 3]")]
pub struct ConeSetting {
    /// Cone half-angle α, degrees.
    pub cone_angle_deg: f64,
    /// Stand rate ω_s, deg/s (signed).
    pub rate_deg_s: f64,
    /// Phase φ at t = 0, degrees.
    pub phase_deg: f64,
}

impl From<[f64; 3]> for ConeSetting {
    fn from(a: [f64; 3]) -> Self {
        Self { cone_angle_deg: a[0], rate_deg_s: a[1], phase_deg: a[2] }
    }
}

impl From<ConeSetting> for [f64; 3] {
    fn from(c: ConeSetting) -> Self {
        [c.cone_angle_deg, c.rate_deg_s, c.phase_deg]
    }
}

impl ConeSetting {
    /// The setting's three numbers by index (0 cone angle, 1 rate, 2 phase).
    pub fn get(&self, k: usize) -> f64 {
        <[f64; 3]>::from(*self)[k]
    }
}

/// The estimated setting of one conic run.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct StandParams {
    /// Run name.
    pub run: String,
    /// Nominal (labelled) setting.
    pub nominal: ConeSetting,
    /// Estimated setting.
    pub value: ConeSetting,
    /// Its standard errors (0 for a setting held at its label).
    pub std_error: ConeSetting,
    /// The drift of the run's rate from its first sample: the relative change per second
    /// (0 when held).
    #[serde(default)]
    pub rate_drift_per_s: f64,
    /// Its standard error, per second.
    #[serde(default)]
    pub rate_drift_se_per_s: f64,
    /// Settings held at their labels, with why (a run that logs its angle has no rate or
    /// phase to estimate).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub held: Vec<String>,
}

/// The stand's imperfections common to its conic runs ([`crate::motion::stand::StandMotion`]),
/// as `fit --stand` estimated them, in radians: base tilt about x and y, the angle's
/// ripple (cos, sin) once and twice per revolution, the cone-axis wobble (cos, sin).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct StandBase {
    /// Base tilt about the base's x and y axes, rad.
    pub tilt_rad: [f64; 2],
    /// Their standard errors, rad.
    pub tilt_se_rad: [f64; 2],
    /// Angle ripple (cos, sin) once and twice per revolution, rad of the stand angle.
    pub ripple_rad: [[f64; 2]; 2],
    /// Their standard errors, rad.
    pub ripple_se_rad: [[f64; 2]; 2],
    /// Cone-axis wobble (cos, sin), rad.
    pub wobble_rad: [f64; 2],
    /// Their standard errors, rad.
    pub wobble_se_rad: [f64; 2],
    /// The Earth's rate in the stand's base axes (x, y horizontal, up), rad/s; zero when
    /// held (declared in the manifest, or not identifiable).
    #[serde(default)]
    pub earth_rad_s: [f64; 3],
    /// Its standard errors, rad/s.
    #[serde(default)]
    pub earth_se_rad_s: [f64; 3],
    /// Per static pose the Earth's horizontal rate along the pose's two horizontal
    /// directions (its heading is unknown), rad/s.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub poses: Vec<PoseEarth>,
    /// Parameters the runs cannot identify, held at zero, with why.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub held: Vec<String>,
}

/// The Earth's horizontal rate on one static pose, as `fit --stand` estimated it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PoseEarth {
    /// Run name.
    pub run: String,
    /// Along the pose's two horizontal directions (sensor axes), rad/s.
    pub horizontal_rad_s: [f64; 2],
    /// Their standard errors, rad/s.
    pub horizontal_se_rad_s: [f64; 2],
}

impl StandBase {
    fn from_flat(v: &[f64], se: &[f64], held: Vec<String>) -> Self {
        Self {
            tilt_rad: [v[0], v[1]],
            tilt_se_rad: [se[0], se[1]],
            ripple_rad: [[v[2], v[3]], [v[4], v[5]]],
            ripple_se_rad: [[se[2], se[3]], [se[4], se[5]]],
            wobble_rad: [v[6], v[7]],
            wobble_se_rad: [se[6], se[7]],
            earth_rad_s: [v[EARTH], v[EARTH + 1], v[EARTH + 2]],
            earth_se_rad_s: [se[EARTH], se[EARTH + 1], se[EARTH + 2]],
            poses: Vec::new(),
            held,
        }
    }

    /// In the user's units: the tilt in degrees, each ripple as a percentage of the rate,
    /// the wobble in degrees (the harmonics with their phase). A term held rather than
    /// estimated (value and standard error both zero: the Earth's rate a manifest declares,
    /// one the runs cannot see) is left out; [`Self::held`] says why.
    pub fn summary(&self) -> Vec<StandTerm> {
        let deg = f64::to_degrees;
        let term = |what: &str, value, std_error, unit, phase| StandTerm {
            what: what.to_string(),
            value,
            std_error,
            unit,
            phase_deg: phase,
        };
        let mut out = vec![
            term("base tilt about x", deg(self.tilt_rad[0]), deg(self.tilt_se_rad[0]), "deg", None),
            term("base tilt about y", deg(self.tilt_rad[1]), deg(self.tilt_se_rad[1]), "deg", None),
        ];
        for (h, times) in [(1, "once"), (2, "twice")] {
            let [r, sr, psi, spsi] =
                crate::motion::stand::speed_ripple(h, self.ripple_rad[h - 1], self.ripple_se_rad[h - 1]);
            let what = format!("speed ripple {times} per revolution");
            out.push(term(&what, 100.0 * r, 100.0 * sr, "%", Some([deg(psi), deg(spsi)])));
        }
        let w = &self.wobble_rad;
        let [a, sa, psi, spsi] = crate::motion::stand::polar(w[0], w[1], self.wobble_se_rad[0], self.wobble_se_rad[1]);
        out.push(term("cone-axis wobble", deg(a), deg(sa), "deg", Some([deg(psi), deg(spsi)])));
        // The Earth's rate in °/h.
        let deg_h = |v: f64| deg(v) * 3600.0;
        let (e, se) = (&self.earth_rad_s, &self.earth_se_rad_s);
        out.push(term("Earth's rate, vertical", deg_h(e[2]), deg_h(se[2]), "deg/h", None));
        let [h, sh, psi, spsi] = crate::motion::stand::polar(e[0], e[1], se[0], se[1]);
        let horizontal = Some([deg(psi), deg(spsi)]);
        out.push(term("Earth's rate, horizontal (stand base)", deg_h(h), deg_h(sh), "deg/h", horizontal));
        for p in &self.poses {
            let (v, s) = (p.horizontal_rad_s, p.horizontal_se_rad_s);
            let [h, sh, psi, spsi] = crate::motion::stand::polar(v[0], v[1], s[0], s[1]);
            let what = format!("Earth's rate, horizontal on '{}'", p.run);
            out.push(term(&what, deg_h(h), deg_h(sh), "deg/h", Some([deg(psi), deg(spsi)])));
        }
        out.retain(|t| t.value != 0.0 || t.std_error != 0.0);
        out
    }
}

/// One of the stand's common imperfections in the user's units.
#[derive(Debug, Clone, PartialEq)]
pub struct StandTerm {
    /// What it is (`base tilt about x`, `speed ripple once per revolution`, …).
    pub what: String,
    /// Its value (an amplitude for a harmonic), in `unit`.
    pub value: f64,
    /// Its standard error, in `unit`.
    pub std_error: f64,
    /// `deg` or `%` (of the stand's rate).
    pub unit: &'static str,
    /// A harmonic's phase and its standard error, degrees.
    pub phase_deg: Option<[f64; 2]>,
}

/// Number of stand parameters common to the runs (tilt ×2, ripple ×4, wobble ×2, the
/// Earth's rate in the stand's base axes ×3).
const COMMON: usize = 11;
/// The first of the Earth's rate's three common parameters (base x, y, up).
const EARTH: usize = 8;
/// The Earth's rotation rate, rad/s.
const EARTH_RAD_S: f64 = 7.292_115e-5;
/// The common parameters' names, for what is held.
const COMMON_NAMES: [&str; COMMON] = [
    "base tilt about x",
    "base tilt about y",
    "speed ripple once per revolution (cos)",
    "speed ripple once per revolution (sin)",
    "speed ripple twice per revolution (cos)",
    "speed ripple twice per revolution (sin)",
    "cone-axis wobble (cos)",
    "cone-axis wobble (sin)",
    "Earth's rate along the stand base's x",
    "Earth's rate along the stand base's y",
    "Earth's rate, vertical",
];
/// Number of a conic run's own parameters: α, ω_s, φ and the rate's drift.
const RUN: usize = 4;
/// A run's own parameters' names.
const RUN_NAMES: [&str; RUN] = ["cone angle", "rate", "phase", "rate drift"];
/// Central-difference steps of a run's α (deg), ω_s (deg/s), φ (deg) and rate drift
/// (relative per second).
const RUN_STEP: [f64; RUN] = [1e-4, 1e-4, 1e-3, 1e-6];
/// How far a run's rate may drift before the estimate is refused, relative per second
/// (0.1 %/s: 6 % in a minute's run).
const DRIFT_LIMIT: f64 = 1e-3;
/// Central-difference step of the common parameters, rad (rad/s for the Earth's rate).
const COMMON_STEP: [f64; COMMON] = [1e-6, 1e-6, 1e-6, 1e-6, 1e-6, 1e-6, 1e-6, 1e-6, 1e-8, 1e-8, 1e-8];
/// Central-difference step of a static pose's horizontal Earth rate, rad/s.
const POSE_STEP: f64 = 1e-8;
/// How far a common parameter may go before the estimate is refused as not a stand's
/// imperfection, rad: tilt 2°, angle ripple 0.1 and 0.05 rad (10 % of the rate), wobble 2°;
/// the Earth's rate 1.5 × its size (rad/s).
const COMMON_LIMIT: [f64; COMMON] =
    [0.035, 0.035, 0.1, 0.1, 0.05, 0.05, 0.035, 0.035, 1.5 * EARTH_RAD_S, 1.5 * EARTH_RAD_S, 1.5 * EARTH_RAD_S];
/// A parameter whose information left after the model's coefficients and the parameters
/// kept before it is below this share of its own is held (not identifiable here).
const HOLD_BELOW: f64 = 1e-6;
const MAX_ITER: usize = 40;

fn conic_of(m: &MotionSpec) -> Option<[f64; 3]> {
    match m {
        MotionSpec::Conic { cone_angle_deg, rate_deg_s, phase_deg } => Some([*cone_angle_deg, *rate_deg_s, *phase_deg]),
        _ => None,
    }
}

/// Noise-weighted residual sum of squares of a fit (Σ_c RSS_c/σ_c²).
fn cost(f: &Fit, sigma2: &[f64; 6]) -> f64 {
    let mut j = 0.0;
    for s in SensorKind::BOTH {
        for (c, ch) in f.sensor(s).channels.iter().enumerate() {
            j += ch.residual_rms * ch.residual_rms * ch.n as f64 / sigma2[3 * s.index() + c];
        }
    }
    j
}

/// Per-channel residual variance of a fit (the weights 1/σ_c²).
fn reweight(f: &Fit, sigma2: &mut [f64; 6]) {
    for sk in SensorKind::BOTH {
        for (c, ch) in f.sensor(sk).channels.iter().enumerate() {
            sigma2[3 * sk.index() + c] = (ch.sigma * ch.sigma).max(f64::MIN_POSITIVE);
        }
    }
}

/// Predicted outputs of both sensors at one state with the fit's coefficient values.
struct Predictor<'m> {
    terms: [Vec<crate::model::TermRef<'m>>; 2],
    values: [Vec<f64>; 2],
}

impl<'m> Predictor<'m> {
    fn new(model: &'m Model, f: &Fit) -> Self {
        let terms = [model.terms(SensorKind::Gyro), model.terms(SensorKind::Accel)];
        let values = [
            f.gyro.coefficients.iter().map(|c| c.value).collect(),
            f.accel.coefficients.iter().map(|c| c.value).collect(),
        ];
        Self { terms, values }
    }

    fn predict(&self, s: &crate::model::State) -> [f64; 6] {
        let g = crate::model::forward(&self.terms[0], &self.values[0], s);
        let a = crate::model::forward(&self.terms[1], &self.values[1], s);
        [g[0], g[1], g[2], a[0], a[1], a[2]]
    }
}

/// Settings at convergence with their tracks and fit.
type Converged = (Vec<f64>, Vec<Track>, Fit);

/// The tracks, fit and linearisation at the nominal settings (weights from that fit).
type Start = (Vec<Track>, Fit, linearise::Linearised);

/// The stand problem of a session: which runs are conic, and the tracks and fit at given
/// parameters `x` (per conic run `[α deg, ω_s deg/s, φ deg, drift 1/s]`, then the [`COMMON`] ones, rad
/// and rad/s, then per static pose the Earth's horizontal rate along its two horizontal
/// directions, rad/s — the heading being unknown, each pose has its own).
struct StandProblem<'a> {
    model: &'a Model,
    session: &'a Session,
    conic: Vec<usize>,
    opts: &'a FitOptions,
    g_m_s2: f64,
    /// Each run's track on its declared motion (stamps and temperature branch).
    declared: Vec<Track>,
    /// The static poses whose Earth rate is estimated (none when the manifest declares it).
    poses: Vec<Pose>,
    /// The manifest declares the Earth's rate (its parameters are then held).
    earth_declared: bool,
}

/// A static pose as the Earth's rate sees it: its run, its up and two horizontal directions
/// in sensor axes.
struct Pose {
    run: usize,
    up: [f64; 3],
    horizontal: [[f64; 3]; 2],
}

impl StandProblem<'_> {
    fn width(&self) -> usize {
        RUN * self.conic.len() + COMMON + 2 * self.poses.len()
    }

    /// Index of the first common parameter.
    fn common(&self) -> usize {
        RUN * self.conic.len()
    }

    /// The Earth's rate on static pose `pi` at parameters `x`, sensor axes, rad/s: the
    /// vertical shared with the conic runs along its up, its own horizontal part.
    fn pose_rate(&self, x: &[f64], pi: usize) -> [f64; 3] {
        let pose = &self.poses[pi];
        let up = x[self.common() + EARTH + 2];
        let h = &x[self.common() + COMMON + 2 * pi..];
        std::array::from_fn(|i| up * pose.up[i] + h[0] * pose.horizontal[0][i] + h[1] * pose.horizontal[1][i])
    }

    /// The stand motion of conic run number `ci` at parameters `x`.
    fn stand_of(&self, x: &[f64], ci: usize) -> StandMotion {
        let p = &x[RUN * ci..RUN * ci + RUN];
        let c = &x[self.common()..];
        StandMotion {
            cone_angle_rad: p[0].to_radians(),
            rate_rad_s: p[1].to_radians(),
            phase_rad: p[2].to_radians(),
            tilt_rad: [c[0], c[1]],
            ripple_rad: [[c[2], c[3]], [c[4], c[5]]],
            wobble_rad: [c[6], c[7]],
            earth_rad_s: [c[EARTH], c[EARTH + 1], c[EARTH + 2]],
            rate_drift_per_s: p[3],
            drift_from_s: self.declared[self.conic[ci]].t_s.first().copied().unwrap_or(0.0),
        }
    }

    /// Run `ri`'s state at sample `k` on stand `sm`, sensor axes (for the derivatives,
    /// without building a track).
    fn state_at(&self, ri: usize, sm: &StandAt, k: usize) -> SensorKinematics {
        let mount = &self.session.runs[ri].spec.mount;
        match self.declared[ri].logged_angles() {
            Some(angles) => {
                crate::motion::stand::to_sensor(sm.at_angle(sm.motion.angle_or_logged(0.0, Some(angles[k]))), mount)
            }
            None => sm.sensor_at(self.declared[ri].t_s[k], mount),
        }
    }

    fn tracks(&self, x: &[f64]) -> Vec<Track> {
        let mut ci = 0;
        (0..self.session.runs.len())
            .map(|ri| {
                if self.conic.get(ci) != Some(&ri) {
                    return match self.poses.iter().position(|p| p.run == ri) {
                        Some(pi) => {
                            let w = self.pose_rate(x, pi);
                            if w.iter().all(|v| *v == 0.0) {
                                self.declared[ri].clone()
                            } else {
                                let add = crate::motion::stand::AddRate(w);
                                self.declared[ri].mapped(std::sync::Arc::new(add))
                            }
                        }
                        None => self.declared[ri].clone(),
                    };
                }
                let sm = self.stand_of(x, ci);
                ci += 1;
                let mount = &self.session.runs[ri].spec.mount;
                // A run that logs its angle keeps following it (the phase turns the log: the
                // encoder's offset).
                self.declared[ri].on_stand(sm, self.g_m_s2, mount.clone())
            })
            .collect()
    }

    fn fit_at(&self, tracks: &[Track]) -> Result<Fit, EstimateError> {
        let runs: Vec<FitRun<'_>> = crate::estimate::fit_runs(self.session, tracks);
        fit(self.model, &runs, self.opts)
    }

    /// The parameters this session identifies, in order (a run's own first, then the
    /// common ones), each kept when the information it has beyond the model's coefficients
    /// and the parameters kept before it is at least [`HOLD_BELOW`] of its own.
    /// Also returns the tracks, fit and linearisation at `x`: the Gauss–Newton's first step
    /// starts from them instead of working them out again.
    fn identifiable(&self, x: &[f64]) -> Result<(Vec<usize>, Start), EstimateError> {
        let tracks = self.tracks(x);
        let f = self.fit_at(&tracks)?;
        let mut sigma2 = [1.0; 6];
        reweight(&f, &mut sigma2);
        let lin = self.linearise(x, &tracks, &f, &sigma2)?;
        let mut free: Vec<usize> = Vec::new();
        for j in 0..self.width() {
            let own = lin.raw[j];
            if own.is_nan() || own <= 0.0 || self.is_declared(j) {
                continue;
            }
            let mff = lin.info.select_rows(&free).select_columns(&free);
            let mfj = DMatrix::from_fn(free.len(), 1, |i, _| lin.info[(free[i], j)]);
            let left = match mff.cholesky() {
                Some(ch) => lin.info[(j, j)] - (mfj.transpose() * ch.solve(&mfj))[(0, 0)],
                None => lin.info[(j, j)],
            };
            if left > HOLD_BELOW * own {
                free.push(j);
            }
        }
        Ok((free, (tracks, f, lin)))
    }

    /// Gauss–Newton over the parameters `free` from `x` (its tracks, fit and linearisation
    /// with channel weights from that fit: `start`) with a halving line search; the
    /// parameters, their tracks and fit at convergence.
    fn gauss_newton(&self, mut x: Vec<f64>, free: &[usize], start: Start) -> Result<Converged, EstimateError> {
        let (mut tracks, mut f, first) = start;
        let mut first = Some(first);
        let mut sigma2 = [1.0; 6];
        for _ in 0..MAX_ITER {
            // Channel weights from the current residual, held through the step's line search
            // (the nominal fit's residual holds the mislabelling; later ones only the noise).
            reweight(&f, &mut sigma2);
            let mut j = cost(&f, &sigma2);
            let lin = match first.take() {
                Some(lin) => lin,
                None => self.linearise(&x, &tracks, &f, &sigma2)?,
            };
            let info = lin.info.select_rows(free).select_columns(free);
            let rhs = lin.rhs.select_rows(free);
            let Some(chol) = info.cholesky() else {
                return Err(EstimateError::NotConverged(
                    "the stand parameters are not identifiable from these runs (their information matrix is singular)"
                        .into(),
                ));
            };
            let step = chol.solve(&rhs);
            let inv = chol.inverse();
            let mut lambda = 1.0;
            for _ in 0..12 {
                let mut trial = x.clone();
                for (i, &p) in free.iter().enumerate() {
                    trial[p] += lambda * step[i];
                }
                let tt = self.tracks(&trial);
                if let Ok(ft) = self.fit_at(&tt) {
                    let jt = cost(&ft, &sigma2);
                    if jt <= j {
                        x = trial;
                        tracks = tt;
                        f = ft;
                        let gain = j - jt;
                        j = jt;
                        // Converged when the step is tiny against the parameters' own uncertainty.
                        let rel = (0..free.len())
                            .map(|i| (lambda * step[i]).abs() / inv[(i, i)].sqrt().max(1e-300))
                            .fold(0.0, f64::max);
                        if rel < 1e-3 || gain <= 1e-10 * j.max(1.0) {
                            return Ok((x, tracks, f));
                        }
                        break;
                    }
                }
                lambda *= 0.5;
                if lambda < 0.5f64.powi(11) {
                    // No descent along the Gauss–Newton direction: at the minimum to rounding.
                    return Ok((x, tracks, f));
                }
            }
        }
        Err(EstimateError::NotConverged(format!(
            "stand parameters did not converge in {MAX_ITER} Gauss–Newton steps; check the runs' labels (cone angle, rate, direction)"
        )))
    }

    /// Refuses what is not a stand slightly off its label: a run whose residual stays far
    /// above the others' (a wrong label or a local minimum), or a setting implausibly far
    /// from its label.
    fn refuse_mislabelled(&self, x: &[f64], nominal: &[f64], tracks: &[Track], f: &Fit) -> Result<(), EstimateError> {
        let mut sigma2 = [1.0; 6];
        reweight(f, &mut sigma2);
        let pred = Predictor::new(self.model, f);
        let runs = crate::estimate::fit_runs(self.session, tracks);
        let per_run: Vec<f64> = runs
            .iter()
            .map(|run| {
                let mut acc = 0.0;
                for k in 0..run.len() {
                    let p = pred.predict(&run.state(k));
                    let y = [run.gyro[k], run.accel[k]];
                    for c in 0..6 {
                        acc += (y[c / 3][c % 3] - p[c]).powi(2) / sigma2[c];
                    }
                }
                acc / (6 * run.len().max(1)) as f64
            })
            .collect();
        let mut sorted = per_run.clone();
        let median = crate::stats::median(&mut sorted).unwrap_or(0.0);
        if let Some((i, v)) = per_run.iter().enumerate().find(|(_, v)| **v > 25.0 * median) {
            return Err(EstimateError::NotConverged(format!(
                "run '{}': its residual stays {:.0}× the other runs' (RMS) after estimating the stand settings; check the run's label (cone angle, rate and direction)",
                self.session.runs[i].spec.name,
                (v / median).sqrt()
            )));
        }
        for (r, &i) in self.conic.iter().enumerate() {
            let (p, n) = (&x[RUN * r..RUN * r + RUN], &nominal[RUN * r..RUN * r + RUN]);
            let limit = [2.0, 0.05 * n[1].abs().max(1.0), 30.0, DRIFT_LIMIT];
            if let Some(k) = (0..RUN).find(|&k| (p[k] - n[k]).abs() > limit[k] || !p[k].is_finite()) {
                return Err(EstimateError::NotConverged(format!(
                    "run '{}': the estimated {} {:.4} is implausibly far from its label {} (limit ±{}); check the run's label (cone angle, rate and direction)",
                    self.session.runs[i].spec.name, RUN_NAMES[k], p[k], n[k], limit[k]
                )));
            }
        }
        let common = &x[self.common()..];
        let limit = |k: usize| if k < COMMON { COMMON_LIMIT[k] } else { COMMON_LIMIT[EARTH] };
        if let Some(k) = (0..common.len()).find(|&k| common[k].abs() > limit(k) || !common[k].is_finite()) {
            let what = match k {
                k if k < COMMON => COMMON_NAMES[k].to_string(),
                k => format!(
                    "Earth's horizontal rate on static run '{}'",
                    self.session.runs[self.poses[(k - COMMON) / 2].run].spec.name
                ),
            };
            return Err(EstimateError::NotConverged(format!(
                "the estimated {what} {:.4e} is implausibly large for a stand or the Earth (limit ±{:.1e}): the runs do not pin it down, the labels are wrong, or the unit has an effect the model lacks",
                common[k],
                limit(k)
            )));
        }
        Ok(())
    }

    /// Whether parameter `j` is the Earth's rate the manifest declares.
    fn is_declared(&self, j: usize) -> bool {
        self.earth_declared && (self.common() + EARTH..self.common() + COMMON).contains(&j)
    }

    /// Why a parameter is held, in words.
    fn held_reason(&self, j: usize, raw: f64) -> String {
        let logs = j < self.common() && self.declared[self.conic[j / RUN]].logged_angles().is_some();
        if self.is_declared(j) {
            "declared in the manifest (earth_rate on the static runs); not estimated".to_string()
        } else if logs {
            "followed from the run's logged angle".to_string()
        } else if raw > 0.0 {
            "not identifiable from these runs (it moves the outputs as the model's coefficients or the other stand settings do); held at its label".to_string()
        } else {
            "these runs do not depend on it; held at its label".to_string()
        }
    }
}

/// Adds each channel's share of the stand settings' uncertainty to its coefficients'
/// covariance: conditional + G cov(s) Gᵀ, on the σ scale of the fit.
fn add_stand_covariance(f: &mut Fit, gains: &[Option<DMatrix<f64>>], cov_s: &DMatrix<f64>) {
    for sk in SensorKind::BOTH {
        let sf = match sk {
            SensorKind::Gyro => &mut f.gyro,
            SensorKind::Accel => &mut f.accel,
        };
        for c in 0..3 {
            let Some(gm) = &gains[3 * sk.index() + c] else { continue };
            let extra = gm * cov_s * gm.transpose();
            let ch = &mut sf.channels[c];
            for a in 0..ch.covariance.len().min(extra.nrows()) {
                for b in 0..ch.covariance.len().min(extra.ncols()) {
                    ch.covariance[a][b] += extra[(a, b)];
                }
            }
            let names = ch.covariance_names.clone();
            for (a, name) in names.iter().enumerate() {
                if let Some(coef) = sf.coefficients.iter_mut().find(|k| &k.name == name) {
                    coef.std_error = Some(sf.channels[c].covariance[a][a].max(0.0).sqrt());
                }
            }
        }
    }
}

/// Fits the model with every conic run's α, ω_s and φ free and the stand's common
/// imperfections (tilt, ripple, wobble) where the session identifies them. Fails with
/// [`EstimateError::NotConverged`] rather than return a wrong answer.
pub(crate) fn fit_with_stand(
    model: &Model,
    session: &Session,
    deriv: &DerivativeConfig,
    opts: &FitOptions,
) -> Result<Fit, EstimateError> {
    if !model.nonlinear().is_empty() {
        return Err(EstimateError::Request(
            "stand-parameter estimation cannot be combined with nonlinear effects (time delay, dead zone) yet; fit them in two steps".into(),
        ));
    }
    let conic: Vec<usize> =
        (0..session.runs.len()).filter(|&i| conic_of(&session.runs[i].spec.motion).is_some()).collect();
    if conic.is_empty() {
        return Err(EstimateError::Request("stand parameters need conic runs; the session has none".into()));
    }
    let g_m_s2 = session.manifest.g_m_s2;
    let declared: Vec<Track> = session.runs.iter().map(|r| crate::motion::track(r, g_m_s2, deriv)).collect();
    // Per conic run its label's α, ω_s, φ and no drift.
    let mut nominal: Vec<f64> = conic
        .iter()
        .filter_map(|&i| conic_of(&session.runs[i].spec.motion))
        .zip(&conic)
        // A run that logs its angle has no declared phase: its phase is the encoder's offset.
        .flat_map(|([a, w, p], &i)| [a, w, if session.runs[i].rec.angle_rad.is_some() { 0.0 } else { p }, 0.0])
        .collect();
    let earth_declared = session.runs.iter().any(|r| {
        matches!(r.spec.motion, MotionSpec::Static { earth_rate_rad_s, .. } if earth_rate_rad_s.iter().any(|v| *v != 0.0))
    });
    let poses: Vec<Pose> = if earth_declared {
        Vec::new()
    } else {
        (0..session.runs.len())
            .filter(|&i| matches!(session.runs[i].spec.motion, MotionSpec::Static { .. }) && !declared[i].is_empty())
            .filter_map(|i| {
                let a = declared[i].at(0).a_m_s2.xyz;
                let n = (a[0] * a[0] + a[1] * a[1] + a[2] * a[2]).sqrt();
                (n > 0.0 && n.is_finite()).then(|| {
                    let up = a.map(|v| v / n);
                    Pose { run: i, up, horizontal: crate::motion::stand::horizontal_basis(up) }
                })
            })
            .collect()
    };
    nominal.extend(vec![0.0; COMMON + 2 * poses.len()]);
    let problem = StandProblem { model, session, conic, opts, g_m_s2, declared, poses, earth_declared };
    let (free, start) = problem.identifiable(&nominal)?;
    let (x, tracks, mut f) = problem.gauss_newton(nominal.clone(), &free, start)?;
    problem.refuse_mislabelled(&x, &nominal, &tracks, &f)?;
    // Final linearisation at the optimum for the covariance, weighted by the final noise.
    let mut sigma2 = [1.0; 6];
    reweight(&f, &mut sigma2);
    let lin = problem.linearise(&x, &tracks, &f, &sigma2)?;
    let cov_free = lin.info.select_rows(&free).select_columns(&free).try_inverse().ok_or_else(|| {
        EstimateError::NotConverged("the stand parameters' information matrix is singular at the optimum".into())
    })?;
    let m = problem.width();
    let mut cov = DMatrix::<f64>::zeros(m, m);
    for (a, &i) in free.iter().enumerate() {
        for (b, &j) in free.iter().enumerate() {
            cov[(i, j)] = cov_free[(a, b)];
        }
    }
    add_stand_covariance(&mut f, &lin.gains, &cov);
    let se = |j: usize| cov[(j, j)].max(0.0).sqrt();
    let held = |j: usize| !free.contains(&j);
    f.stand = problem
        .conic
        .iter()
        .enumerate()
        .map(|(r, &i)| StandParams {
            run: session.runs[i].spec.name.clone(),
            nominal: ConeSetting::from(std::array::from_fn(|k| nominal[RUN * r + k])),
            value: ConeSetting::from(std::array::from_fn(|k| x[RUN * r + k])),
            std_error: ConeSetting::from(std::array::from_fn(|k| se(RUN * r + k))),
            rate_drift_per_s: x[RUN * r + 3],
            rate_drift_se_per_s: se(RUN * r + 3),
            held: (0..RUN)
                .filter(|&k| held(RUN * r + k))
                .map(|k| format!("{}: {}", RUN_NAMES[k], problem.held_reason(RUN * r + k, lin.raw[RUN * r + k])))
                .collect(),
        })
        .collect();
    let c0 = problem.common();
    let held_common: Vec<String> = (0..COMMON)
        .filter(|&k| held(c0 + k))
        .map(|k| format!("{}: {}", COMMON_NAMES[k], problem.held_reason(c0 + k, lin.raw[c0 + k])))
        .collect();
    let mut held_common = held_common;
    let mut poses = Vec::with_capacity(problem.poses.len());
    for (pi, pose) in problem.poses.iter().enumerate() {
        let j = c0 + COMMON + 2 * pi;
        let run = session.runs[pose.run].spec.name.clone();
        if held(j) || held(j + 1) {
            let why = problem.held_reason(j, lin.raw[j]);
            held_common.push(format!("Earth's horizontal rate on static run '{run}': {why}"));
        }
        poses.push(PoseEarth { run, horizontal_rad_s: [x[j], x[j + 1]], horizontal_se_rad_s: [se(j), se(j + 1)] });
    }
    let se_common: Vec<f64> = (0..COMMON).map(|k| se(c0 + k)).collect();
    let mut base = StandBase::from_flat(&x[c0..], &se_common, held_common);
    base.poses = poses;
    f.stand_base = Some(base);
    Ok(f)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_summary_leaves_out_what_was_held_and_keeps_what_was_estimated() {
        let base = StandBase {
            tilt_rad: [1e-3, 0.0],
            tilt_se_rad: [1e-5, 1e-5],
            ripple_rad: [[0.0; 2]; 2],
            ripple_se_rad: [[1e-6; 2]; 2],
            wobble_rad: [0.0; 2],
            wobble_se_rad: [1e-6; 2],
            earth_rad_s: [0.0; 3],
            earth_se_rad_s: [0.0; 3],
            poses: Vec::new(),
            held: vec!["the Earth's rate: declared in the manifest".into()],
        };
        let what: Vec<String> = base.summary().into_iter().map(|t| t.what).collect();
        assert!(!what.iter().any(|w| w.contains("Earth")), "{what:?}");
        // An estimate that happens to be zero keeps its line: its standard error is not.
        assert!(what.contains(&"base tilt about y".to_string()), "{what:?}");
        assert_eq!(what.len(), 5, "{what:?}");
    }
}
