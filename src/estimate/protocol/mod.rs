//! Calibration from protocol sessions, where the true state is not known sample by sample:
//!
//! * **Ferraris** (Ferraris et al. 1995; imucal): static poses with a known up direction and
//!   turns through a known angle about a known axis. Every pose and every turn is one
//!   observation of the linear model, so the ordinary linear fit ([`super::fit`]) solves it:
//!   a pose is the run's mean output at the known state (ω = Earth rate or 0, a = g·up); a
//!   turn is the run's mean output at the mean state ω̄ = axis·angle/(N·Δt), ε̄ = 0 (rest at
//!   both ends), ā = the calibrated mean specific force. For models linear in the state this
//!   is exact: the mean of `u = Φ(state) θ` is `Φ(mean state) θ`. Poses and turns carry one
//!   row each (equal weights, as imucal): the scatter between hand-placed poses, not the
//!   sensor noise, is what limits them.
//! * **Multi-position** (Tedaldi, Pretto & Menegatti, ICRA 2014; imu_tk): static poses in
//!   unknown orientations, detected automatically, joined by free motion. The accelerometer
//!   `a = M (u − b)` (M upper triangular: the accelerometer's axes define the calibrated
//!   frame, the paper's eq. 10 gauge) is fitted so that every pose measures |a| = g (eq. 14);
//!   the gyro `ω = W (u − b − G a)` (W full) so that integrating it between consecutive poses
//!   turns the first pose's gravity direction onto the next one's (eq. 16). Both are solved
//!   by Levenberg–Marquardt (an argmin solver in `estimate::lm`).
//!
//! Either way the result is an ordinary [`Fit`] in crosscal's forward convention
//! (`u = b + K a`, `u = b + C ω + G a`, sensor frame, row-major, `K = M⁻¹`, `C = W⁻¹`), with
//! a [`ProtocolReport`] of per-pose and per-turn residuals.

mod ferraris;
mod multi_position;
mod rest;

use super::{EstimateError, Fit, FitRun, SensorFit};
use crate::frames::V3;
use crate::model::Model;
use crate::motion::Track;
use crate::session::{MotionSpec, Run, Session};
use crate::stats::segment::mean3;
use crate::units::{SensorKind, AXES};
use nalgebra::{Matrix3, Vector3};
use serde::{Deserialize, Serialize};

/// The effects the multi-position fit supports.
pub const MULTI_POSITION_EFFECTS: [&str; 5] =
    ["gyro-bias", "gyro-scale-coupling", "gyro-g-sensitivity", "accel-bias", "accel-scale-coupling"];

/// True when every regressor of the effect is a constant or a function of the specific
/// force alone, or (with `linear_rate`) a rate entering linearly: what static poses (and,
/// for linear rate terms, turns) identify.
pub fn pose_identifiable(effect: &dyn crate::model::Effect, linear_rate: bool) -> bool {
    use crate::model::Key;
    let inputs = effect.inputs();
    let force_only = !inputs.rate && !inputs.ang_accel && !inputs.time && !inputs.temperature;
    effect.terms().iter().all(|t| match t.key {
        Key::One | Key::Force(_) => true,
        Key::Rate(_) => linear_rate,
        Key::AngAccel(_) => false,
        Key::Own(..) => force_only,
    })
}

/// True when the protocol fit of this kind of session can fit the model.
fn supports(model: &Model, multi_position: bool) -> Result<(), String> {
    for e in model.effects() {
        let ok =
            if multi_position { MULTI_POSITION_EFFECTS.contains(&e.id()) } else { pose_identifiable(e.as_ref(), true) };
        if !ok {
            return Err(if multi_position {
                format!(
                    "effect '{}' cannot be fitted from a multi-position session (it fits {}); record a Ferraris session (six faces, three turns) or stand runs for it",
                    e.id(),
                    MULTI_POSITION_EFFECTS.join(", ")
                )
            } else {
                format!(
                    "effect '{}' cannot be fitted from static faces and turns: they identify constants, functions of the specific force and rates entering linearly (use --model ferraris, optionally with accelerometer effects such as accel-quadratic)",
                    e.id()
                )
            });
        }
    }
    if let Some(e) = model.nonlinear().first() {
        return Err(format!("nonlinear effect '{}' is not supported in protocol sessions", e.effect.id()));
    }
    Ok(())
}

/// True when the session's runs make it a multi-position session.
pub fn is_multi_position(session: &Session) -> bool {
    session.runs.iter().any(|r| matches!(r.spec.motion, MotionSpec::MultiPosition { .. } | MotionSpec::StaticUnknown))
}

/// The model preset a protocol session starts from: `tedaldi` when the poses' orientations
/// are unknown, else `ferraris`.
pub fn default_preset(session: &Session) -> crate::model::Preset {
    if is_multi_position(session) {
        crate::model::Preset::Tedaldi
    } else {
        crate::model::Preset::Ferraris
    }
}

/// Whether [`fit_protocol`] can fit `model` on `session`, and why not.
pub fn can_fit(session: &Session, model: &Model) -> Result<(), String> {
    supports(model, is_multi_position(session))
}

/// One static pose used by a protocol fit.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PoseResidual {
    /// Run the pose belongs to.
    pub run: String,
    /// First sample (index within the run).
    pub start: usize,
    /// One past the last sample.
    pub end: usize,
    /// |a| − g of the calibrated mean specific force, m/s².
    pub gravity_error_m_s2: f64,
    /// Calibrated mean rate at rest (should be 0), deg/s.
    pub rate_at_rest_deg_s: [f64; 3],
    /// What shows the pose was not at rest by the noise of the rest (multi-position: the
    /// initial rest; Ferraris: the static runs' median), when something does: a moving
    /// variance above the rest's, or a sensor mean that drifts.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub motion: Option<String>,
    /// Standard error of `rate_at_rest_deg_s` from the noise: the scatter of the pose's block
    /// means through the calibration (and the rest's bias when the bias comes from it).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub rate_se_deg_s: Option<[f64; 3]>,
    /// Standard error of `gravity_error_m_s2` from the noise, along the pose's gravity.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub gravity_se_m_s2: Option<f64>,
}

/// One turn (Ferraris) or one motion between poses (multi-position).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TurnResidual {
    /// Run (Ferraris) or "pose i → i+1" (multi-position).
    pub name: String,
    /// Declared angle (Ferraris) or the angle between the two gravity directions, degrees.
    pub angle_deg: f64,
    /// Misfit: calibrated integrated angle minus declared (Ferraris), or the angle between the
    /// predicted and measured gravity direction after the motion (multi-position), degrees.
    pub error_deg: f64,
}

/// How the static poses of a multi-position run were found.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Detection {
    /// Window of the moving variance, samples.
    pub window: usize,
    /// Samples of the initial rest.
    pub init_rest_samples: usize,
    /// Norm of the accelerometer's per-axis variance over the initial rest (input units²).
    pub baseline_variance_norm: f64,
    /// Chosen threshold multiplier (none when the poses were given).
    pub multiplier: Option<f64>,
    /// Threshold used = multiplier × baseline.
    pub threshold: Option<f64>,
    /// Shortest pose used, samples.
    pub min_pose_samples: usize,
    /// Every multiplier tried: (multiplier, poses found, accelerometer cost or null).
    pub tried: Vec<(f64, usize, Option<f64>)>,
    /// The declared initial rest, samples, when motion was found in it and the rest was
    /// shortened to `init_rest_samples` (with `trim_rest`).
    #[serde(default)]
    pub declared_rest_samples: Option<usize>,
    /// What was found in the declared rest, in words (empty when it was at rest).
    #[serde(default)]
    pub rest_note: String,
}

/// Residuals and settings of a protocol fit.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ProtocolReport {
    /// `ferraris` or `multi-position`.
    pub protocol: String,
    /// Static poses.
    pub poses: Vec<PoseResidual>,
    /// Turns or inter-pose motions.
    pub turns: Vec<TurnResidual>,
    /// Static-pose detection (multi-position only).
    pub detection: Option<Detection>,
    /// RMS over poses of |a| − g, m/s².
    pub gravity_rms_m_s2: f64,
    /// Accelerometer cost ½Σ(g − |a|)² over the fitted samples (multi-position; imu_tk's
    /// definition, m²/s⁴).
    pub accel_cost: Option<f64>,
    /// Gyro cost ½Σ|Rᵀv₀ − v₁|² over the inter-pose motions (multi-position; imu_tk's
    /// definition, dimensionless).
    pub gyro_cost: Option<f64>,
    /// Findings worth a look (e.g. turns whose sign contradicts the declared angle).
    pub warnings: Vec<String>,
    /// Parameters fitted from the poses' (|a| − g, rates at rest): what their residuals lose
    /// in degrees of freedom when compared with the noise.
    #[serde(default)]
    pub pose_params: [usize; 2],
}

fn protocol_error(msg: impl Into<String>) -> EstimateError {
    EstimateError::Protocol(msg.into())
}

/// Median sample interval of a run, s.
fn median_dt(t: &[f64]) -> f64 {
    let mut d: Vec<f64> = t.windows(2).map(|w| w[1] - w[0]).collect();
    if d.is_empty() {
        return f64::NAN;
    }
    crate::stats::median(&mut d).unwrap_or(f64::NAN)
}

/// Choices of a protocol fit.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct ProtocolOptions {
    /// Ferraris biases by the classic six-position formulas (Titterton & Weston §8.5; imucal):
    /// each accelerometer bias from the two faces along its own axis, `b_i = (u_i(+i up) +
    /// u_i(−i up))/2`, and the gyro bias as the mean of all static samples; the other
    /// coefficients are then fitted with the biases held. The default fits the biases by least
    /// squares over all six faces, which uses every face and exposes their disagreement as
    /// residual.
    pub classic_six_position: bool,
    /// When the declared initial rest of a multi-position run is not at rest, use its still
    /// part (and say so) instead of refusing the fit.
    pub trim_rest: bool,
}

/// Fits a protocol session (see the module documentation).
pub fn fit_protocol(
    session: &Session,
    model: &Model,
    opts: &ProtocolOptions,
) -> Result<(Fit, ProtocolReport), EstimateError> {
    supports(model, is_multi_position(session)).map_err(protocol_error)?;
    let has = |f: fn(&MotionSpec) -> bool| session.runs.iter().any(|r| f(&r.spec.motion));
    if has(|m| matches!(m, MotionSpec::Conic { .. } | MotionSpec::Reference)) {
        return Err(protocol_error(
            "this session mixes stand runs (conic/reference) with protocol runs: fit them as separate sessions",
        ));
    }
    if has(|m| matches!(m, MotionSpec::MultiPosition { .. } | MotionSpec::StaticUnknown)) {
        if has(|m| matches!(m, MotionSpec::Rotation { .. } | MotionSpec::Static { .. })) {
            return Err(protocol_error(
                "a session is either Ferraris (static runs with up_stand + rotation runs) or multi-position (multi_position / unknown-pose runs), not both",
            ));
        }
        multi_position::multi_position(session, model, opts)
    } else {
        ferraris::ferraris(session, model, opts)
    }
}

/// A one-sample track at a mean state.
fn state_track(w: [f64; 3], a: [f64; 3]) -> Track {
    Track::sampled(
        vec![0.0],
        vec![V3::new(w)],
        vec![V3::new([0.0; 3])],
        vec![V3::new(a)],
        "zero (protocol: rest at both ends)".into(),
    )
}

/// Accelerometer forward model `u = b + K a` from a sensor fit: (K, b).
fn accel_kb(f: &SensorFit) -> (Matrix3<f64>, Vector3<f64>) {
    let v = |n: String, d: f64| f.value(&n).unwrap_or(d);
    let k = Matrix3::from_fn(|i, j| {
        v(crate::model::matrix_name(SensorKind::Accel, "k", i, j), f64::from(u8::from(i == j)))
    });
    let b = Vector3::from_fn(|i, _| v(format!("accel.b_{}", AXES[i]), 0.0));
    (k, b)
}

/// Per channel, the standard deviation of a pose's mean output from the scatter within the
/// poses: `s² · mean(1/N)` with `s²` the pooled within-pose variance.
fn pose_mean_noise(runs: &[&Run], data: impl Fn(&Run) -> &[[f64; 3]]) -> [f64; 3] {
    let mut out = [0.0; 3];
    for i in 0..3 {
        let (mut ss, mut dof, mut inv_n) = (0.0, 0usize, 0.0);
        for r in runs {
            let x = data(r);
            if x.len() < 2 {
                continue;
            }
            let m = x.iter().map(|v| v[i]).sum::<f64>() / x.len() as f64;
            ss += x.iter().map(|v| (v[i] - m).powi(2)).sum::<f64>();
            dof += x.len() - 1;
            inv_n += 1.0 / x.len() as f64;
        }
        if dof > 0 {
            out[i] = (ss / dof as f64 * inv_n / runs.len() as f64).sqrt();
        }
    }
    out
}

/// Per channel, the standard error of a stretch's mean: the scatter of its block means
/// (blocks of `w` samples, which keeps the noise correlated within a window) / √blocks when
/// there are at least four blocks, else the sample scatter / √n (white noise).
fn mean_se(x: &[[f64; 3]], w: usize) -> [f64; 3] {
    let w = w.max(1);
    let k = x.len() / w;
    let blocks;
    let rows = if k >= 4 {
        blocks = rest::block_means(x, w);
        &blocks[..]
    } else {
        x
    };
    if rows.len() < 2 {
        return [f64::NAN; 3];
    }
    crate::stats::segment::var3(rows).map(|v| (v / rows.len() as f64).sqrt())
}

/// Standard errors of `m·x` for independent channels of `x` with standard errors `se`.
fn through(m: &Matrix3<f64>, se: [f64; 3]) -> [f64; 3] {
    [0, 1, 2].map(|i| (0..3).map(|j| (m[(i, j)] * se[j]).powi(2)).sum::<f64>().sqrt())
}

/// Widens each channel's standard errors and covariance so that its σ is at least `floor`.
fn inflate_to_floor(f: &mut SensorFit, floor: [f64; 3]) {
    for (ch, fl) in f.channels.iter_mut().zip(floor) {
        if ch.sigma >= fl || ch.sigma <= 0.0 {
            if ch.sigma <= 0.0 && fl > 0.0 {
                ch.sigma = fl;
            }
            continue;
        }
        let r = fl / ch.sigma;
        ch.sigma = fl;
        for row in &mut ch.covariance {
            for v in row.iter_mut() {
                *v *= r * r;
            }
        }
        for c in f.coefficients.iter_mut().filter(|c| ch.covariance_names.contains(&c.name)) {
            c.std_error = c.std_error.map(|s| s * r);
        }
    }
}

fn rms(x: impl Iterator<Item = f64>) -> f64 {
    let (mut s, mut n) = (0.0, 0usize);
    for v in x {
        s += v * v;
        n += 1;
    }
    if n == 0 {
        0.0
    } else {
        (s / n as f64).sqrt()
    }
}

/// The gyro's inverse model `ω = C⁻¹ (u − b − G a)` from a sensor fit.
struct GyroCal {
    c_inv: Matrix3<f64>,
    b: Vector3<f64>,
    g: Matrix3<f64>,
}

impl GyroCal {
    fn from_fit(f: &SensorFit) -> Self {
        let v = |n: String, d: f64| f.value(&n).unwrap_or(d);
        let c = Matrix3::from_fn(|i, j| {
            v(crate::model::matrix_name(SensorKind::Gyro, "c", i, j), f64::from(u8::from(i == j)))
        });
        let g = Matrix3::from_fn(|i, j| v(crate::model::matrix_name(SensorKind::Gyro, "g", i, j), 0.0));
        let b = Vector3::from_fn(|i, _| v(format!("gyro.b_{}", AXES[i]), 0.0));
        Self { c_inv: c.try_inverse().unwrap_or(Matrix3::from_element(f64::NAN)), b, g }
    }

    fn rate(&self, u: [f64; 3], a: [f64; 3]) -> [f64; 3] {
        let w = self.c_inv * (Vector3::from(u) - self.b - self.g * Vector3::from(a));
        [w[0], w[1], w[2]]
    }
}

/// One static pose as a one-sample run for linear refits ([`crate::diagnose::protocol`]):
/// its true specific force (the declared up for a face, the calibrated direction × g for a
/// pose of unknown orientation) and its mean outputs.
#[derive(Debug, Clone)]
pub struct PoseRow {
    /// "run" or "run[start..end]".
    pub name: String,
    /// The pose's state (ω = 0).
    pub track: Track,
    /// Mean gyro output.
    pub gyro: [[f64; 3]; 1],
    /// Mean accelerometer output.
    pub accel: [[f64; 3]; 1],
}

impl PoseRow {
    /// The row as a run for a fit ([`crate::estimate::FitRequest::runs`]).
    pub fn as_run(&self) -> FitRun<'_> {
        FitRun {
            name: &self.name,
            track: &self.track,
            gyro: &self.gyro,
            accel: &self.accel,
            temp_c: None,
            temp_const_c: None,
            start_s: None,
        }
    }
}

/// The static poses of a fitted protocol session as rows (see [`PoseRow`]).
pub fn pose_rows(session: &Session, fit: &Fit, report: &ProtocolReport) -> Vec<PoseRow> {
    let g = session.manifest.g_m_s2;
    let (k, b) = accel_kb(&fit.accel);
    let k_inv = k.try_inverse().unwrap_or(Matrix3::from_element(f64::NAN));
    let mut rows = Vec::with_capacity(report.poses.len());
    for p in &report.poses {
        let Some(run) = session.runs.iter().find(|r| r.spec.name == p.run) else { continue };
        let (s, e) = (p.start.min(run.rec.len()), p.end.min(run.rec.len()));
        if e <= s {
            continue;
        }
        let gyro = [mean3(&run.rec.gyro[s..e])];
        let accel = [mean3(&run.rec.accel[s..e])];
        let a = match &run.spec.motion {
            MotionSpec::Static { up_stand, .. } => run.spec.mount.to_sensor(V3::new(*up_stand)).xyz.map(|x| x * g),
            _ => {
                let d = (k_inv * (Vector3::from(accel[0]) - b)).normalize() * g;
                [d[0], d[1], d[2]]
            }
        };
        let name = if s == 0 && e == run.rec.len() { p.run.clone() } else { format!("{}[{s}..{e}]", p.run) };
        rows.push(PoseRow { name, track: state_track([0.0; 3], a), gyro, accel });
    }
    rows
}
