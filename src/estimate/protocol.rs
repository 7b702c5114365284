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
//!   by Levenberg–Marquardt ([`super::lm`]).
//!
//! Either way the result is an ordinary [`Fit`] in crosscal's forward convention
//! (`u = b + K a`, `u = b + C ω + G a`, sensor frame, row-major, `K = M⁻¹`, `C = W⁻¹`), with
//! a [`ProtocolReport`] of per-pose and per-turn residuals.

use super::linear::fit_in_memory as fit;
use super::lm::{minimise, numeric_jacobian, LeastSquares};
use super::{ChannelFit, CoefStatus, Coefficient, EstimateError, Fit, FitOptions, FitRun, SensorFit};
use crate::frames::V3;
use crate::model::{Model, TermStatus};
use crate::motion::Track;
use crate::session::{MotionSpec, Run, Session};
use crate::stats::segment::{mean3, moving_variance_norm, static_intervals, variance_norm};
use crate::units::{SensorKind, AXES};
use nalgebra::{DMatrix, Matrix3, Vector3};
use serde::{Deserialize, Serialize};

/// The effects the multi-position fit supports.
pub const MULTI_POSITION_EFFECTS: [&str; 5] =
    ["gyro-bias", "gyro-scale-coupling", "gyro-g-sensitivity", "accel-bias", "accel-scale-coupling"];

/// True when every regressor of the effect is a constant or a function of the specific
/// force alone (`1`, `a_x`, `a_x^2`, `|a_x|`, `a_xa_y`, …), or (with `linear_rate`) a rate
/// entering linearly (`w_x`): what static poses (and, for linear rate terms, turns) identify.
pub fn pose_identifiable(effect: &dyn crate::model::Effect, linear_rate: bool) -> bool {
    !effect.needs_temperature()
        && effect.terms().iter().all(|t| {
            let k = t.key.as_str();
            k == "1"
                || (k.starts_with("a_") || k.starts_with("|a_")) && !k.contains('w')
                || linear_rate && matches!(k, "w_x" | "w_y" | "w_z")
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
}

fn norm(v: [f64; 3]) -> f64 {
    (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt()
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
    crate::session::sanity::median(&mut d)
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
        multi_position(session, model)
    } else {
        ferraris(session, model, opts)
    }
}

/// A one-sample track at a mean state.
fn state_track(w: [f64; 3], a: [f64; 3]) -> Track {
    Track {
        t_s: vec![0.0],
        w_rad_s: vec![w],
        e_rad_s2: vec![[0.0; 3]],
        a_m_s2: vec![a],
        epsilon_source: "zero (protocol: rest at both ends)".into(),
    }
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

/// One pose or turn of a Ferraris session as a one-sample run.
struct Obs<'a> {
    run: &'a Run,
    track: Track,
    gyro: [[f64; 3]; 1],
    accel: [[f64; 3]; 1],
    /// Axis (sensor frame) and angle (degrees) of a turn.
    turn: Option<([f64; 3], f64)>,
}

impl Obs<'_> {
    fn as_run(&self) -> FitRun<'_> {
        FitRun {
            name: &self.run.spec.name,
            track: &self.track,
            gyro: &self.gyro,
            accel: &self.accel,
            temp_c: None,
            temp_const_c: self.run.spec.temperature_c,
        }
    }
}

/// The classic six-position biases (see [`ProtocolOptions::classic_six_position`]): the
/// model with `accel.b_i` and `gyro.b_i` held at them.
fn classic_biases(model: &Model, obs: &[Obs<'_>]) -> Result<Model, EstimateError> {
    let mut m = model.clone();
    let poses: Vec<&Obs<'_>> = obs.iter().filter(|o| o.turn.is_none()).collect();
    for i in 0..3 {
        let face = |sign: f64| {
            poses.iter().find(|o| {
                let a = o.track.a_m_s2[0];
                let n = norm(a);
                n > 0.0 && (a[i] / n - sign).abs() < 1e-6
            })
        };
        let (Some(up), Some(down)) = (face(1.0), face(-1.0)) else {
            return Err(protocol_error(format!(
                "the classic six-position biases need the faces with +{0} and −{0} up",
                AXES[i]
            )));
        };
        let b = 0.5 * (up.accel[0][i] + down.accel[0][i]);
        m.fix(&format!("accel.b_{}", AXES[i]), b).map_err(|e| protocol_error(e.to_string()))?;
        let (mut sum, mut n) = (0.0, 0usize);
        for o in &poses {
            sum += o.gyro[0][i] * o.run.rec.len() as f64;
            n += o.run.rec.len();
        }
        m.fix(&format!("gyro.b_{}", AXES[i]), sum / n.max(1) as f64).map_err(|e| protocol_error(e.to_string()))?;
    }
    Ok(m)
}

fn ferraris(session: &Session, model: &Model, popts: &ProtocolOptions) -> Result<(Fit, ProtocolReport), EstimateError> {
    let g = session.manifest.g_m_s2;
    let mut obs: Vec<Obs<'_>> = Vec::new();
    let mut warnings = Vec::new();
    for run in &session.runs {
        if run.rec.is_empty() {
            return Err(protocol_error(format!("run '{}' has no samples", run.spec.name)));
        }
        let gyro = [mean3(&run.rec.gyro)];
        let accel = [mean3(&run.rec.accel)];
        let mount = &run.spec.mount;
        match &run.spec.motion {
            MotionSpec::Static { up_stand, earth_rate_rad_s } => {
                let up = mount.to_sensor(V3::new(*up_stand)).xyz;
                let w = mount.to_sensor(V3::new(*earth_rate_rad_s)).xyz;
                obs.push(Obs { run, track: state_track(w, up.map(|u| u * g)), gyro, accel, turn: None });
            }
            MotionSpec::Rotation { axis_stand, angle_deg } => {
                let axis = mount.to_sensor(V3::new(*axis_stand)).xyz;
                let dt = median_dt(&run.rec.t_s);
                if !(dt.is_finite() && dt > 0.0) {
                    return Err(protocol_error(format!("rotation run '{}' needs at least two samples", run.spec.name)));
                }
                let span = run.rec.len() as f64 * dt;
                let w = axis.map(|x| x * angle_deg.to_radians() / span);
                obs.push(Obs {
                    run,
                    track: state_track(w, [f64::NAN; 3]),
                    gyro,
                    accel,
                    turn: Some((axis, *angle_deg)),
                });
            }
            _ => unreachable!("dispatch sends only static and rotation runs here"),
        }
    }
    let n_poses = obs.iter().filter(|o| o.turn.is_none()).count();
    if n_poses == 0 {
        return Err(protocol_error("a Ferraris session needs static runs with up_stand (six faces)"));
    }
    let opts = FitOptions::default();
    let classic;
    let model = if popts.classic_six_position {
        classic = classic_biases(model, &obs)?;
        &classic
    } else {
        model
    };
    let pose_runs: Vec<FitRun<'_>> = obs.iter().filter(|o| o.turn.is_none()).map(Obs::as_run).collect();
    let first = fit(model, &pose_runs, &opts)?;
    let accel_terms = model.terms(SensorKind::Accel);
    let accel_values: Vec<f64> =
        accel_terms.iter().map(|t| first.accel.value(&t.term.name).unwrap_or(t.term.nominal)).collect();
    let (k, b) = accel_kb(&first.accel);
    let k_inv = k.try_inverse().ok_or_else(|| protocol_error("the fitted accelerometer matrix K is singular"))?;
    // The accelerometer's inverse: Newton steps with the linear part's Jacobian K on the full
    // forward model (exact for u = b + K a; converges for small nonlinear terms).
    let calibrate_a = |u: [f64; 3]| -> [f64; 3] {
        let u = Vector3::from(u);
        let mut a = k_inv * (u - b);
        for _ in 0..50 {
            let s = crate::model::State { a: [a[0], a[1], a[2]], ..Default::default() };
            let r = u - Vector3::from(crate::model::forward(&accel_terms, &accel_values, &s));
            let step = k_inv * r;
            a += step;
            if step.norm() <= 1e-13 * a.norm() {
                break;
            }
        }
        [a[0], a[1], a[2]]
    };
    // Turns: the calibrated mean specific force, and a check of the turn's sign.
    let bias_g = mean3(&obs.iter().filter(|o| o.turn.is_none()).map(|o| o.gyro[0]).collect::<Vec<_>>());
    for o in obs.iter_mut() {
        if let Some((axis, angle)) = o.turn {
            o.track.a_m_s2[0] = calibrate_a(o.accel[0]);
            let raw: f64 = (0..3).map(|i| (o.gyro[0][i] - bias_g[i]) * axis[i]).sum();
            if raw * angle < 0.0 {
                warnings.push(format!(
                    "run '{}': the gyro integrates to the opposite sign of the declared {angle}° (raw rate along the axis {raw:+.4}): the turn's sign is probably reversed, and the fitted scale will be negative",
                    o.run.spec.name
                ));
            }
        }
    }
    let all_runs: Vec<FitRun<'_>> = obs.iter().map(Obs::as_run).collect();
    let second = fit(model, &all_runs, &opts)?;
    let mut out = Fit { gyro: second.gyro, accel: first.accel, nonlinear: Vec::new(), stand: Vec::new() };
    // Six faces leave few degrees of freedom, so the residual σ can come out far below the
    // sensor's own noise by chance; the noise of a pose mean is a floor under it.
    let statics: Vec<&Run> = obs.iter().filter(|o| o.turn.is_none()).map(|o| o.run).collect();
    inflate_to_floor(&mut out.gyro, pose_mean_noise(&statics, |r| &r.rec.gyro));
    inflate_to_floor(&mut out.accel, pose_mean_noise(&statics, |r| &r.rec.accel));

    // Residuals with the final calibration.
    let cal = GyroCal::from_fit(&out.gyro);
    let mut poses = Vec::new();
    let mut turns = Vec::new();
    for o in &obs {
        let a = calibrate_a(o.accel[0]);
        match o.turn {
            None => poses.push(PoseResidual {
                run: o.run.spec.name.clone(),
                start: 0,
                end: o.run.rec.len(),
                gravity_error_m_s2: norm(a) - g,
                rate_at_rest_deg_s: cal.rate(o.gyro[0], a).map(f64::to_degrees),
            }),
            Some((axis, angle)) => {
                let w = cal.rate(o.gyro[0], a);
                let span = o.run.rec.len() as f64 * median_dt(&o.run.rec.t_s);
                let along: f64 = (0..3).map(|i| w[i] * axis[i]).sum::<f64>() * span;
                turns.push(TurnResidual {
                    name: o.run.spec.name.clone(),
                    angle_deg: angle,
                    error_deg: along.to_degrees() - angle,
                });
            }
        }
    }
    if turns.len() == 3 {
        warnings.push(
            "one turn per axis determines C exactly: the turn residuals are zero by construction and C's standard errors reflect only the static scatter; repeat the turns to see the turn-angle error".into(),
        );
    }
    let report = ProtocolReport {
        protocol: "ferraris".into(),
        gravity_rms_m_s2: rms(poses.iter().map(|p| p.gravity_error_m_s2)),
        poses,
        turns,
        detection: None,
        accel_cost: None,
        gyro_cost: None,
        warnings,
    };
    Ok((out, report))
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

// ---------------------------------------------------------------------------------------
// Multi-position (Tedaldi)
// ---------------------------------------------------------------------------------------

/// Accelerometer residuals `g − |M (u − b)|` over pose samples; p = [m00, m01, m02, m11,
/// m12, m22, b0, b1, b2] (M upper triangular).
fn accel_residuals(samples: &[[f64; 3]], g: f64, p: &[f64]) -> Vec<f64> {
    let m = upper(p);
    let b = Vector3::new(p[6], p[7], p[8]);
    samples.iter().map(|u| g - (m * (Vector3::from(*u) - b)).norm()).collect()
}

fn upper(p: &[f64]) -> Matrix3<f64> {
    Matrix3::new(p[0], p[1], p[2], 0.0, p[3], p[4], 0.0, 0.0, p[5])
}

/// A motion between two poses: the unbiased gyro samples `u − b − G a`, their time steps,
/// and the gravity directions before and after.
struct Segment {
    u: Vec<[f64; 3]>,
    dt: Vec<f64>,
    v0: Vector3<f64>,
    v1: Vector3<f64>,
}

/// Rotation (body at the end relative to the start) from rates `ω_k = W u_k`: each step
/// turns by the mean of its two end rates (exact for a rate constant over the step, second
/// order otherwise): `q ← q ⊗ exp(½ ω̄ Δt)`.
fn integrate(w: &Matrix3<f64>, seg: &Segment) -> nalgebra::UnitQuaternion<f64> {
    let mut q = nalgebra::UnitQuaternion::identity();
    let mut prev = w * Vector3::from(seg.u[0]);
    for k in 1..seg.u.len() {
        let cur = w * Vector3::from(seg.u[k]);
        let mid = (prev + cur) * (0.5 * seg.dt[k - 1]);
        q *= nalgebra::UnitQuaternion::from_scaled_axis(mid);
        prev = cur;
    }
    q
}

/// Gyro residuals `Rᵀv₀ − v₁` of every motion for `ω = W u` (W row-major in p).
fn gyro_residuals(segments: &[Segment], w: &Matrix3<f64>) -> Vec<f64> {
    let mut r = Vec::with_capacity(3 * segments.len());
    for s in segments {
        let q = integrate(w, s);
        let d = q.inverse_transform_vector(&s.v0) - s.v1;
        r.extend_from_slice(&[d[0], d[1], d[2]]);
    }
    r
}

/// Initial accelerometer guess: the axis-aligned ellipsoid through the pose means
/// (`Σ c_i x_i² + d_i x_i = 1`, linear least squares), else the sphere.
fn ellipsoid_guess(means: &[[f64; 3]], g: f64) -> [f64; 9] {
    let n = means.len();
    let a = DMatrix::from_fn(n, 6, |r, c| if c < 3 { means[r][c] * means[r][c] } else { means[r][c - 3] });
    let y = nalgebra::DVector::from_element(n, 1.0);
    if let Ok(sol) = a.clone().svd(true, true).solve(&y, 1e-12) {
        let c = [sol[0], sol[1], sol[2]];
        if c.iter().all(|&x| x > 0.0) {
            let centre: Vec<f64> = (0..3).map(|i| -sol[3 + i] / (2.0 * c[i])).collect();
            let rhs = 1.0 + (0..3).map(|i| c[i] * centre[i] * centre[i]).sum::<f64>();
            if rhs > 0.0 {
                let s: Vec<f64> = (0..3).map(|i| g * (c[i] / rhs).sqrt()).collect();
                return [s[0], 0.0, 0.0, s[1], 0.0, s[2], centre[0], centre[1], centre[2]];
            }
        }
    }
    let centre = mean3(means);
    let r = means.iter().map(|m| norm([m[0] - centre[0], m[1] - centre[1], m[2] - centre[2]])).sum::<f64>() / n as f64;
    let s = g / r.max(f64::MIN_POSITIVE);
    [s, 0.0, 0.0, s, 0.0, s, centre[0], centre[1], centre[2]]
}

struct AccelSolution {
    p: Vec<f64>,
    cov: DMatrix<f64>,
    cost: f64,
    residuals: Vec<f64>,
    cond: f64,
}

fn fit_accel(samples: &[[f64; 3]], means: &[[f64; 3]], g: f64) -> Result<AccelSolution, EstimateError> {
    let p0 = ellipsoid_guess(means, g);
    let s = p0[0].abs().max(p0[3].abs()).max(p0[5].abs());
    let range = g / s;
    let scale = [s, s, s, s, s, s, range, range, range];
    let prob = LeastSquares::new(|p: &[f64]| accel_residuals(samples, g, p), scale.to_vec());
    let r = minimise(prob, p0.to_vec(), 200).map_err(|e| EstimateError::NotConverged(e.to_string()))?;
    let cov = r.covariance();
    Ok(AccelSolution {
        cost: r.cost(),
        cond: condition(&r.jacobian, &scale),
        residuals: r.residuals.clone(),
        cov,
        p: r.param,
    })
}

/// Condition number of the column-scaled Jacobian.
fn condition(jac: &[Vec<f64>], scale: &[f64]) -> f64 {
    let m = jac.len();
    let n = scale.len();
    let j = DMatrix::from_fn(m, n, |i, k| jac[i][k] * scale[k]);
    let sv = j.singular_values();
    let max = sv.iter().copied().fold(0.0, f64::max);
    let min = sv.iter().copied().fold(f64::INFINITY, f64::min);
    max / min
}

/// Samples of a pose used by the accelerometer fit: its first `take` samples (imu_tk).
fn pose_samples(accel: &[[f64; 3]], poses: &[(usize, usize)], take: usize, out: &mut Vec<[f64; 3]>) {
    out.clear();
    for &(s, e) in poses {
        out.extend_from_slice(&accel[s..e.min(s + take)]);
    }
}

fn multi_position(session: &Session, model: &Model) -> Result<(Fit, ProtocolReport), EstimateError> {
    let g = session.manifest.g_m_s2;
    let mut mp = session.runs.iter().filter(|r| matches!(r.spec.motion, MotionSpec::MultiPosition { .. }));
    let run = mp.next().ok_or_else(|| {
        protocol_error("a multi-position session needs a multi_position run (the whole hand-held recording)")
    })?;
    if mp.next().is_some() {
        return Err(protocol_error("one multi_position run per session: calibrate each recording on its own"));
    }
    let MotionSpec::MultiPosition { init_rest_s, window, threshold_multiplier, min_pose_samples, ref poses } =
        run.spec.motion
    else {
        unreachable!("filtered above")
    };
    let rec = &run.rec;
    let t0 = rec.t_s.first().copied().unwrap_or(0.0);
    let n_init = rec.t_s.iter().take_while(|&&t| t - t0 < init_rest_s).count();
    if n_init < window.max(10) || n_init >= rec.len() {
        return Err(protocol_error(format!(
            "run '{}': the initial rest of {init_rest_s} s has {n_init} samples: expected at least the detector window ({window}) and less than the whole recording",
            run.spec.name
        )));
    }
    let baseline = variance_norm(&rec.accel, 0, n_init);
    let norms = moving_variance_norm(&rec.accel, window);
    let extra: Vec<[f64; 3]> = session
        .runs
        .iter()
        .filter(|r| matches!(r.spec.motion, MotionSpec::StaticUnknown))
        .map(|r| mean3(&r.rec.accel))
        .collect();
    if let Some(given) = poses {
        if let Some(&(s, e)) = given.iter().find(|&&(_, e)| e > rec.len()) {
            return Err(protocol_error(format!(
                "run '{}': pose [{s}, {e}) reaches past the run's {} samples",
                run.spec.name,
                rec.len()
            )));
        }
    }
    let candidates: Vec<f64> = match (poses, threshold_multiplier) {
        (Some(_), _) => vec![0.0],
        (None, Some(m)) => vec![m],
        (None, None) => (2..=10).map(f64::from).collect(),
    };
    let mut tried = Vec::new();
    // (multiplier, poses, solution) of the lowest cost so far.
    type Best = (f64, Vec<(usize, usize)>, AccelSolution);
    let mut best: Option<Best> = None;
    let mut buf = Vec::new();
    for &m in &candidates {
        let found: Vec<(usize, usize)> = match poses {
            Some(given) => given.clone(),
            None => {
                static_intervals(&norms, m * baseline).into_iter().filter(|(s, e)| e - s >= min_pose_samples).collect()
            }
        };
        if found.len() + extra.len() < 9 {
            tried.push((m, found.len(), None));
            continue;
        }
        pose_samples(&rec.accel, &found, min_pose_samples, &mut buf);
        buf.extend_from_slice(&extra);
        let means: Vec<[f64; 3]> =
            found.iter().map(|&(s, e)| mean3(&rec.accel[s..e])).chain(extra.iter().copied()).collect();
        let sol = fit_accel(&buf, &means, g)?;
        if poses.is_none() {
            tried.push((m, found.len(), Some(sol.cost)));
        }
        if best.as_ref().is_none_or(|b| sol.cost < b.2.cost) {
            best = Some((m, found, sol));
        }
    }
    let given = poses.is_some();
    let Some((multiplier, poses, acc)) = best else {
        let found: Vec<String> = tried.iter().map(|(m, n, _)| format!("×{m}: {n}")).collect();
        return Err(protocol_error(format!(
            "run '{}': too few static poses of at least {min_pose_samples} samples for the 9 accelerometer parameters (found {}); hold more poses longer, or lower min_pose_samples",
            run.spec.name,
            found.join(", ")
        )));
    };
    let m_acc = upper(&acc.p);
    let b_acc = Vector3::new(acc.p[6], acc.p[7], acc.p[8]);
    let a_cal = |u: &[f64; 3]| -> Vector3<f64> { m_acc * (Vector3::from(*u) - b_acc) };

    // Gyro bias (and g-sensitivity) from rest.
    let with_g = model.effects().iter().any(|e| e.id() == "gyro-g-sensitivity");
    let pose_a: Vec<Vector3<f64>> = poses.iter().map(|&(s, e)| a_cal(&mean3(&rec.accel[s..e]))).collect();
    let pose_u: Vec<[f64; 3]> = poses.iter().map(|&(s, e)| mean3(&rec.gyro[s..e])).collect();
    let (b_g, g_mat, b_se, g_se) = if with_g {
        gyro_bias_and_g(&pose_u, &pose_a)
    } else {
        let init = &rec.gyro[..n_init];
        let b = mean3(init);
        let se = [0, 1, 2].map(|i| {
            let var = init.iter().map(|u| (u[i] - b[i]).powi(2)).sum::<f64>() / (n_init - 1) as f64;
            (var / n_init as f64).sqrt()
        });
        (Vector3::from(b), Matrix3::zeros(), se, Matrix3::zeros())
    };

    // Motions between consecutive poses: from the last sample of one to the sample before
    // the next (imu_tk's span).
    let mut segments = Vec::new();
    let mut names = Vec::new();
    for k in 0..poses.len().saturating_sub(1) {
        let i0 = poses[k].1 - 1;
        let i1 = poses[k + 1].0 - 1;
        if i1 <= i0 {
            continue;
        }
        let u: Vec<[f64; 3]> = (i0..=i1)
            .map(|i| {
                let a = if with_g { a_cal(&rec.accel[i]) } else { Vector3::zeros() };
                let v = Vector3::from(rec.gyro[i]) - b_g - g_mat * a;
                [v[0], v[1], v[2]]
            })
            .collect();
        let dt: Vec<f64> = (i0..i1).map(|i| rec.t_s[i + 1] - rec.t_s[i]).collect();
        segments.push(Segment { u, dt, v0: pose_a[k].normalize(), v1: pose_a[k + 1].normalize() });
        names.push(format!("pose {} → {}", k + 1, k + 2));
    }
    if segments.len() < 4 {
        return Err(protocol_error(format!(
            "run '{}': {} motions between poses cannot determine the 9 gyro parameters (need at least 4, better 10+)",
            run.spec.name,
            segments.len()
        )));
    }
    let s0 = gyro_scale_guess(&segments);
    let scale = [s0; 9];
    let prob = LeastSquares::new(|p: &[f64]| gyro_residuals(&segments, &Matrix3::from_row_slice(p)), scale.to_vec());
    let p0 = vec![s0, 0.0, 0.0, 0.0, s0, 0.0, 0.0, 0.0, s0];
    let gyro = minimise(prob, p0, 100).map_err(|e| EstimateError::NotConverged(e.to_string()))?;
    let w = Matrix3::from_row_slice(&gyro.param);
    let w_cov = gyro.covariance();

    // Report.
    let mut pose_rows = Vec::new();
    for (k, &(s, e)) in poses.iter().enumerate() {
        let rate = w * (Vector3::from(pose_u[k]) - b_g - g_mat * pose_a[k]);
        pose_rows.push(PoseResidual {
            run: run.spec.name.clone(),
            start: s,
            end: e,
            gravity_error_m_s2: pose_a[k].norm() - g,
            rate_at_rest_deg_s: [rate[0].to_degrees(), rate[1].to_degrees(), rate[2].to_degrees()],
        });
    }
    for r in session.runs.iter().filter(|r| matches!(r.spec.motion, MotionSpec::StaticUnknown)) {
        let a = a_cal(&mean3(&r.rec.accel));
        let rate = w * (Vector3::from(mean3(&r.rec.gyro)) - b_g - g_mat * a);
        pose_rows.push(PoseResidual {
            run: r.spec.name.clone(),
            start: 0,
            end: r.rec.len(),
            gravity_error_m_s2: a.norm() - g,
            rate_at_rest_deg_s: [rate[0].to_degrees(), rate[1].to_degrees(), rate[2].to_degrees()],
        });
    }
    let turns: Vec<TurnResidual> = segments
        .iter()
        .zip(&names)
        .enumerate()
        .map(|(k, (s, name))| {
            let d = Vector3::new(gyro.residuals[3 * k], gyro.residuals[3 * k + 1], gyro.residuals[3 * k + 2]);
            let predicted = s.v1 + d;
            TurnResidual {
                name: name.clone(),
                angle_deg: s.v0.dot(&s.v1).clamp(-1.0, 1.0).acos().to_degrees(),
                error_deg: predicted.normalize().dot(&s.v1).clamp(-1.0, 1.0).acos().to_degrees(),
            }
        })
        .collect();
    let detection = Detection {
        window,
        init_rest_samples: n_init,
        baseline_variance_norm: baseline,
        multiplier: (!given).then_some(multiplier),
        threshold: (!given).then_some(multiplier * baseline),
        min_pose_samples,
        tried,
    };
    let report = ProtocolReport {
        protocol: "multi-position".into(),
        gravity_rms_m_s2: rms(pose_rows.iter().map(|p| p.gravity_error_m_s2)),
        poses: pose_rows,
        turns,
        detection: Some(detection),
        accel_cost: Some(acc.cost),
        gyro_cost: Some(gyro.cost()),
        warnings: Vec::new(),
    };

    // Forward-convention coefficients: K = M⁻¹ (upper triangular), C = W⁻¹.
    let acc_map = |p: &[f64]| -> Vec<f64> {
        let k = upper(p).try_inverse().unwrap_or(Matrix3::from_element(f64::NAN));
        vec![k[(0, 0)], k[(0, 1)], k[(0, 2)], k[(1, 1)], k[(1, 2)], k[(2, 2)], p[6], p[7], p[8]]
    };
    let (acc_vals, acc_cov) = propagate(&acc.p, &acc.cov, &acc_map, &[acc.p[0]; 9]);
    let gyr_map = |p: &[f64]| -> Vec<f64> {
        let c = Matrix3::from_row_slice(p).try_inverse().unwrap_or(Matrix3::from_element(f64::NAN));
        c.transpose().as_slice().to_vec()
    };
    let (gyr_vals, gyr_cov) = propagate(&gyro.param, &w_cov, &gyr_map, &[s0; 9]);

    let n_acc = acc.residuals.len() as u64;
    let acc_rms = rms(acc.residuals.iter().copied());
    let acc_max = acc.residuals.iter().fold(0.0_f64, |m, r| m.max(r.abs()));
    let gyr_rms = rms(gyro.residuals.iter().copied());
    let gyr_max = gyro.residuals.iter().fold(0.0_f64, |m, r| m.max(r.abs()));
    let mut values = std::collections::HashMap::new();
    let upper_idx = [(0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2)];
    for (k, &(i, j)) in upper_idx.iter().enumerate() {
        values.insert(
            crate::model::matrix_name(SensorKind::Accel, "k", i, j),
            (acc_vals[k], Some(acc_cov[(k, k)].sqrt()), k),
        );
    }
    for i in 0..3 {
        values.insert(format!("accel.b_{}", AXES[i]), (acc_vals[6 + i], Some(acc_cov[(6 + i, 6 + i)].sqrt()), 6 + i));
        for j in 0..3 {
            let k = 3 * i + j;
            values.insert(
                crate::model::matrix_name(SensorKind::Gyro, "c", i, j),
                (gyr_vals[k], Some(gyr_cov[(k, k)].sqrt()), k),
            );
            if with_g {
                values.insert(
                    crate::model::matrix_name(SensorKind::Gyro, "g", i, j),
                    (g_mat[(i, j)], Some(g_se[(i, j)]), usize::MAX),
                );
            }
        }
        values.insert(format!("gyro.b_{}", AXES[i]), (b_g[i], Some(b_se[i]), usize::MAX));
    }
    let accel_fit = sensor_fit(
        model,
        SensorKind::Accel,
        &values,
        &acc_cov,
        ChannelStats { n: n_acc, rms: acc_rms, max: acc_max, cond: acc.cond },
        "the accelerometer's axes define the calibrated frame (x along the accelerometer's x, y in its x-y plane): K is upper triangular",
    );
    let gyro_fit = sensor_fit(
        model,
        SensorKind::Gyro,
        &values,
        &gyr_cov,
        ChannelStats {
            n: gyro.residuals.len() as u64,
            rms: gyr_rms,
            max: gyr_max,
            cond: condition(&gyro.jacobian, &scale),
        },
        "",
    );
    Ok((Fit { gyro: gyro_fit, accel: accel_fit, nonlinear: Vec::new(), stand: Vec::new() }, report))
}

/// Bias and g-sensitivity of the gyro from pose means: `u = b + G a` per channel, linear
/// least squares over poses; returns values and standard errors.
fn gyro_bias_and_g(u: &[[f64; 3]], a: &[Vector3<f64>]) -> (Vector3<f64>, Matrix3<f64>, [f64; 3], Matrix3<f64>) {
    let n = u.len();
    let x = DMatrix::from_fn(n, 4, |r, c| if c == 0 { 1.0 } else { a[r][c - 1] });
    let xtx_inv = (x.transpose() * &x).try_inverse().unwrap_or(DMatrix::zeros(4, 4));
    let mut b = Vector3::zeros();
    let mut g = Matrix3::zeros();
    let mut b_se = [0.0; 3];
    let mut g_se = Matrix3::zeros();
    for i in 0..3 {
        let y = nalgebra::DVector::from_fn(n, |r, _| u[r][i]);
        let th = &xtx_inv * (x.transpose() * &y);
        let res = &y - &x * &th;
        let s2 = res.norm_squared() / (n.saturating_sub(4).max(1)) as f64;
        b[i] = th[0];
        b_se[i] = (s2 * xtx_inv[(0, 0)]).sqrt();
        for j in 0..3 {
            g[(i, j)] = th[1 + j];
            g_se[(i, j)] = (s2 * xtx_inv[(1 + j, 1 + j)]).sqrt();
        }
    }
    (b, g, b_se, g_se)
}

/// First guess of the gyro's scale (ω per input unit): the median over motions of the angle
/// between the two gravity directions over the integrated input's magnitude (a lower bound
/// for each motion), refined along `W = s·I` by a golden-section search.
fn gyro_scale_guess(segments: &[Segment]) -> f64 {
    let mut ratios: Vec<f64> = segments
        .iter()
        .filter_map(|s| {
            let angle = s.v0.dot(&s.v1).clamp(-1.0, 1.0).acos();
            let mut sum = Vector3::zeros();
            for (k, u) in s.u.iter().enumerate().skip(1) {
                sum += Vector3::from(*u) * s.dt[k - 1];
            }
            (angle > 0.2 && sum.norm() > 0.0).then(|| angle / sum.norm())
        })
        .collect();
    if ratios.is_empty() {
        return 1.0;
    }
    ratios.sort_by(f64::total_cmp);
    let s0 = ratios[ratios.len() / 2];
    let cost = |ls: f64| -> f64 {
        let s = ls.exp();
        let r = gyro_residuals(segments, &Matrix3::from_diagonal_element(s));
        r.iter().map(|x| x * x).sum()
    };
    let (mut lo, mut hi) = ((s0 / 1.5).ln(), (s0 * 3.0).ln());
    let phi = 0.5 * (5f64.sqrt() - 1.0);
    let (mut x1, mut x2) = (hi - phi * (hi - lo), lo + phi * (hi - lo));
    let (mut f1, mut f2) = (cost(x1), cost(x2));
    for _ in 0..40 {
        if f1 < f2 {
            hi = x2;
            x2 = x1;
            f2 = f1;
            x1 = hi - phi * (hi - lo);
            f1 = cost(x1);
        } else {
            lo = x1;
            x1 = x2;
            f1 = f2;
            x2 = lo + phi * (hi - lo);
            f2 = cost(x2);
        }
    }
    (0.5 * (lo + hi)).exp()
}

/// Values and covariance of `f(p)` by first-order propagation (central differences).
fn propagate(p: &[f64], cov: &DMatrix<f64>, f: &dyn Fn(&[f64]) -> Vec<f64>, scale: &[f64]) -> (Vec<f64>, DMatrix<f64>) {
    let vals = f(p);
    let jac = numeric_jacobian(|q| Ok(f(q)), p, scale, 1e-7).unwrap_or_default();
    let m = vals.len();
    let j = DMatrix::from_fn(m, p.len(), |i, k| jac.get(i).and_then(|r| r.get(k)).copied().unwrap_or(0.0));
    (vals, &j * cov * j.transpose())
}

struct ChannelStats {
    n: u64,
    rms: f64,
    max: f64,
    cond: f64,
}

/// Builds a [`SensorFit`] over the model's terms from named values
/// (`name → (value, std error, index into cov or usize::MAX)`); terms without a value are
/// held at their nominal value (`gauge` says why, when non-empty).
fn sensor_fit(
    model: &Model,
    sensor: SensorKind,
    values: &std::collections::HashMap<String, (f64, Option<f64>, usize)>,
    cov: &DMatrix<f64>,
    stats: ChannelStats,
    gauge: &str,
) -> SensorFit {
    let terms = model.terms(sensor);
    let mut coefficients = Vec::with_capacity(terms.len());
    let mut unidentifiable = Vec::new();
    for t in &terms {
        let (value, se, status) = match (values.get(&t.term.name), t.status) {
            (_, TermStatus::Fixed(v)) => (v, None, CoefStatus::Fixed),
            (Some(&(v, se, _)), TermStatus::Fitted) => (v, se, CoefStatus::Fitted),
            (None, TermStatus::Fitted) => {
                if gauge.is_empty() {
                    unidentifiable.push(super::Unidentifiable {
                        axis: AXES[t.term.channel],
                        held: t.term.name.clone(),
                        held_at: t.term.nominal,
                        combination: vec![(t.term.name.clone(), 1.0)],
                        reason: "not identifiable from static poses and inter-pose motions".into(),
                        remedy: "a stand run (conic or reference motion)".into(),
                    });
                }
                (t.term.nominal, None, CoefStatus::Fixed)
            }
        };
        coefficients.push(Coefficient {
            name: t.term.name.clone(),
            effect: t.effect.id().to_string(),
            channel: t.term.channel,
            unit: t.term.unit.to_string(),
            value,
            std_error: se,
            status,
        });
    }
    let channels = (0..3)
        .map(|ch| {
            let names: Vec<&Coefficient> =
                coefficients.iter().filter(|c| c.channel == ch && c.status == CoefStatus::Fitted).collect();
            let idx: Vec<usize> = names.iter().map(|c| values.get(&c.name).map_or(usize::MAX, |v| v.2)).collect();
            let covariance = idx
                .iter()
                .zip(&names)
                .map(|(&a, ca)| {
                    idx.iter()
                        .zip(&names)
                        .map(|(&b, cb)| {
                            if a != usize::MAX && b != usize::MAX {
                                cov[(a, b)]
                            } else if ca.name == cb.name {
                                ca.std_error.unwrap_or(0.0).powi(2)
                            } else {
                                0.0
                            }
                        })
                        .collect()
                })
                .collect();
            ChannelFit {
                axis: AXES[ch],
                n: stats.n,
                n_params: names.len(),
                residual_rms: stats.rms,
                residual_max: stats.max,
                sigma: stats.rms,
                condition_number: stats.cond,
                covariance_names: names.iter().map(|c| c.name.clone()).collect(),
                covariance,
                downweighted: 0,
                coloured_inflation: 1.0,
                residual_lag1: 0.0,
            }
        })
        .collect();
    SensorFit { sensor, coefficients, channels, unidentifiable, correlated: Vec::new() }
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
    /// The row as a run for [`fit`].
    pub fn as_run(&self) -> FitRun<'_> {
        FitRun {
            name: &self.name,
            track: &self.track,
            gyro: &self.gyro,
            accel: &self.accel,
            temp_c: None,
            temp_const_c: None,
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
