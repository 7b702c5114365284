//! Ferraris sessions (Ferraris et al. 1995; imucal): static faces with a known up and turns
//! through a known angle about a known axis, each one observation of the linear model.

use super::{
    accel_kb, inflate_to_floor, median_dt, pose_mean_noise, protocol_error, rms, state_track, GyroCal, PoseResidual,
    ProtocolOptions, ProtocolReport, TurnResidual,
};
use crate::estimate::memory::fit_in_memory as fit;
use crate::estimate::{EstimateError, Fit, FitOptions, FitRun};
use crate::frames::V3;
use crate::model::{Model, TermRef};
use crate::motion::Track;
use crate::session::{MotionSpec, Run, Session};
use crate::stats::segment::mean3;
use crate::units::{SensorKind, AXES};
use nalgebra::{Matrix3, Vector3};

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
            start_s: None,
        }
    }
}

/// Each run as an observation: a face at its known state, a turn at its mean rate
/// ω̄ = axis·angle/(N·Δt) (its specific force filled in once the accelerometer is known).
fn observations(session: &Session) -> Result<Vec<Obs<'_>>, EstimateError> {
    let g = session.manifest.g_m_s2;
    let mut obs = Vec::with_capacity(session.runs.len());
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
            other => {
                return Err(protocol_error(format!(
                    "run '{}': a Ferraris session has static and rotation runs, not {other:?}",
                    run.spec.name
                )))
            }
        }
    }
    Ok(obs)
}

/// The classic six-position biases (see [`ProtocolOptions::classic_six_position`]): the
/// model with `accel.b_i` and `gyro.b_i` held at them.
fn classic_biases(model: &Model, obs: &[Obs<'_>]) -> Result<Model, EstimateError> {
    let mut m = model.clone();
    let poses: Vec<&Obs<'_>> = obs.iter().filter(|o| o.turn.is_none()).collect();
    for i in 0..3 {
        let face = |sign: f64| {
            poses.iter().find(|o| {
                let a = o.track.at(0).a_m_s2;
                let n = crate::stats::norm3(a.xyz);
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
        m.fix(&format!("accel.b_{}", AXES[i]), b)?;
        let (mut sum, mut n) = (0.0, 0usize);
        for o in &poses {
            sum += o.gyro[0][i] * o.run.rec.len() as f64;
            n += o.run.rec.len();
        }
        m.fix(&format!("gyro.b_{}", AXES[i]), sum / n.max(1) as f64)?;
    }
    Ok(m)
}

/// The accelerometer's inverse: Newton steps with the linear part's Jacobian K on the full
/// forward model (exact for u = b + K a; converges for small nonlinear terms).
struct AccelInverse<'m> {
    k_inv: Matrix3<f64>,
    b: Vector3<f64>,
    terms: Vec<TermRef<'m>>,
    values: Vec<f64>,
}

impl<'m> AccelInverse<'m> {
    fn new(model: &'m Model, fit: &Fit) -> Result<Self, EstimateError> {
        let terms = model.terms(SensorKind::Accel);
        let values = terms.iter().map(|t| fit.accel.value(&t.term.name).unwrap_or(t.term.nominal)).collect();
        let (k, b) = accel_kb(&fit.accel);
        let k_inv = k.try_inverse().ok_or_else(|| protocol_error("the fitted accelerometer matrix K is singular"))?;
        Ok(Self { k_inv, b, terms, values })
    }

    fn apply(&self, u: [f64; 3]) -> [f64; 3] {
        let u = Vector3::from(u);
        let mut a = self.k_inv * (u - self.b);
        for _ in 0..50 {
            let s = crate::model::State { a: [a[0], a[1], a[2]], ..Default::default() };
            let r = u - Vector3::from(crate::model::forward(&self.terms, &self.values, &s));
            let step = self.k_inv * r;
            a += step;
            if step.norm() <= 1e-13 * a.norm() {
                break;
            }
        }
        [a[0], a[1], a[2]]
    }
}

/// Fits a Ferraris session: the accelerometer (and the gyro's bias and g-sensitivity) from
/// the faces, then the gyro from faces and turns, each turn at the calibrated mean specific
/// force.
pub(super) fn ferraris(
    session: &Session,
    model: &Model,
    popts: &ProtocolOptions,
) -> Result<(Fit, ProtocolReport), EstimateError> {
    let mut obs = observations(session)?;
    if obs.iter().all(|o| o.turn.is_some()) {
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
    let calibrate_a = AccelInverse::new(model, &first)?;
    // Turns: the calibrated mean specific force, and a check of the turn's sign.
    let mut warnings = Vec::new();
    let bias_g = mean3(&obs.iter().filter(|o| o.turn.is_none()).map(|o| o.gyro[0]).collect::<Vec<_>>());
    for o in obs.iter_mut() {
        if let Some((axis, angle)) = o.turn {
            o.track = state_track(o.track.at(0).w_rad_s.xyz, calibrate_a.apply(o.accel[0]));
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
    let mut out =
        Fit { gyro: second.gyro, accel: first.accel, nonlinear: Vec::new(), stand: Vec::new(), stand_base: None };
    // Six faces leave few degrees of freedom, so the residual σ can come out far below the
    // sensor's own noise by chance; the noise of a pose mean is a floor under it.
    let statics: Vec<&Run> = obs.iter().filter(|o| o.turn.is_none()).map(|o| o.run).collect();
    inflate_to_floor(&mut out.gyro, pose_mean_noise(&statics, |r| &r.rec.gyro));
    inflate_to_floor(&mut out.accel, pose_mean_noise(&statics, |r| &r.rec.accel));
    let report = report(session.manifest.g_m_s2, &obs, &out, &calibrate_a, warnings);
    Ok((out, report))
}

/// Pose and turn residuals with the final calibration.
fn report(
    g: f64,
    obs: &[Obs<'_>],
    out: &Fit,
    calibrate_a: &AccelInverse<'_>,
    mut warnings: Vec<String>,
) -> ProtocolReport {
    let cal = GyroCal::from_fit(&out.gyro);
    // Each static run judged by the median noise of all of them (a window of 0.5 s).
    let window = |o: &Obs<'_>| ((0.5 / median_dt(&o.run.rec.t_s)).round() as usize).clamp(5, 501);
    let statics: Vec<&Obs<'_>> = obs.iter().filter(|o| o.turn.is_none()).collect();
    let reference = statics.first().and_then(|o| {
        let stretches: Vec<_> = statics.iter().map(|o| (&o.run.rec.accel[..], &o.run.rec.gyro[..])).collect();
        super::rest::rest_noise(&stretches, window(o))
    });
    let motion = |o: &Obs<'_>| {
        let rec = &o.run.rec;
        reference.as_ref().and_then(|n| super::rest::check_span(&rec.accel, &rec.gyro, (0, rec.len()), n))
    };
    let rate_se = |o: &Obs<'_>| {
        let r = super::through(&cal.c_inv, super::mean_se(&o.run.rec.gyro, window(o)));
        Some(r.map(f64::to_degrees)).filter(|v| v.iter().all(|x| x.is_finite()))
    };
    let mut poses = Vec::new();
    let mut turns = Vec::new();
    for o in obs {
        let a = calibrate_a.apply(o.accel[0]);
        match o.turn {
            None => poses.push(PoseResidual {
                run: o.run.spec.name.clone(),
                start: 0,
                end: o.run.rec.len(),
                gravity_error_m_s2: crate::stats::norm3(a) - g,
                rate_at_rest_deg_s: cal.rate(o.gyro[0], a).map(f64::to_degrees),
                motion: motion(o),
                rate_se_deg_s: rate_se(o),
                // The faces fit the accelerometer's 12 parameters exactly or nearly: no
                // degrees of freedom are left to compare |a| − g with the noise.
                gravity_se_m_s2: None,
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
    ProtocolReport {
        protocol: "ferraris".into(),
        gravity_rms_m_s2: rms(poses.iter().map(|p| p.gravity_error_m_s2)),
        poses,
        turns,
        detection: None,
        accel_cost: None,
        gyro_cost: None,
        warnings,
        pose_params: [12, if cal.g.iter().any(|v| *v != 0.0) { 12 } else { 3 }],
    }
}
