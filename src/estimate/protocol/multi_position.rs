//! Multi-position sessions (Tedaldi, Pretto & Menegatti, ICRA 2014; imu_tk): static poses
//! in unknown orientations, detected automatically, joined by free motion.

use super::{protocol_error, rms, Detection, PoseResidual, ProtocolOptions, ProtocolReport, TurnResidual};
use crate::estimate::lm::{minimise, numeric_jacobian, LeastSquares};
use crate::estimate::{ChannelFit, CoefStatus, Coefficient, EstimateError, Fit, SensorFit, Unidentifiable};
use crate::model::{Model, TermStatus};
use crate::session::{MotionSpec, Run, Session};
use crate::stats::segment::{mean3, moving_variance_norm, static_intervals, variance_norm};
use crate::units::{SensorKind, AXES};
use nalgebra::{DMatrix, Matrix3, Vector3};

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
    if let Some(Ok(sol)) = crate::stats::svd(a.clone(), true, true).map(|svd| svd.solve(&y, 1e-12)) {
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
    let r =
        means.iter().map(|m| crate::stats::norm3([m[0] - centre[0], m[1] - centre[1], m[2] - centre[2]])).sum::<f64>()
            / n as f64;
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
    let Some(sv) = crate::stats::svd(j, false, false).map(|s| s.singular_values) else { return f64::INFINITY };
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

/// The one multi_position run of a session and its settings.
struct Recording<'a> {
    run: &'a Run,
    init_rest_s: f64,
    window: usize,
    threshold_multiplier: Option<f64>,
    min_pose_samples: usize,
    poses: Option<&'a Vec<(usize, usize)>>,
}

fn the_run(session: &Session) -> Result<Recording<'_>, EstimateError> {
    let mut mp = session.runs.iter().filter(|r| matches!(r.spec.motion, MotionSpec::MultiPosition { .. }));
    let run = mp.next().ok_or_else(|| {
        protocol_error("a multi-position session needs a multi_position run (the whole hand-held recording)")
    })?;
    if mp.next().is_some() {
        return Err(protocol_error("one multi_position run per session: calibrate each recording on its own"));
    }
    match &run.spec.motion {
        MotionSpec::MultiPosition { init_rest_s, window, threshold_multiplier, min_pose_samples, poses } => {
            Ok(Recording {
                run,
                init_rest_s: *init_rest_s,
                window: *window,
                threshold_multiplier: *threshold_multiplier,
                min_pose_samples: *min_pose_samples,
                poses: poses.as_ref(),
            })
        }
        _ => Err(protocol_error("a multi_position run was expected")),
    }
}

/// The declared initial rest checked against its own noise ([`super::rest`]): motion in it
/// stops the fit with the time it starts, or with `trim_rest` shortens the rest to its still
/// part. Returns the rest's samples, the declared samples when shortened, and a note.
fn verified_rest(
    rec: &crate::session::Recording,
    r: &Recording<'_>,
    n_init: usize,
    window: usize,
    opts: &ProtocolOptions,
) -> Result<(usize, Option<usize>, String), EstimateError> {
    let super::rest::RestCheck::Moving { from, still, sensor, size, variance } =
        super::rest::check_rest(&rec.accel, &rec.gyro, n_init, window)
    else {
        return Ok((n_init, None, String::new()));
    };
    let t0 = rec.t_s.first().copied().unwrap_or(0.0);
    let at = rec.t_s.get(from).map_or(0.0, |t| t - t0);
    let what = if variance {
        format!("{sensor} motion from t = {at:.2} s (moving variance {size:.0}× the rest's own)")
    } else {
        format!("the gyro's mean drifts in its second half, from t = {at:.2} s ({size:.1} standard errors)")
    };
    let keep_s = rec.t_s.get(still).map_or(0.0, |t| t - t0);
    if !opts.trim_rest {
        return Err(protocol_error(format!(
            "run '{}': the declared initial rest (init_rest_s = {} s) is not at rest: {what}; the gyro bias and the \
             detector's baseline would come from moving data. Set init_rest_s to {keep_s:.2} s or less, or pass \
             --trim-rest to use the still part",
            r.run.spec.name, r.init_rest_s
        )));
    }
    if still < window.max(10) {
        return Err(protocol_error(format!(
            "run '{}': the declared initial rest is not at rest ({what}) and its still part ({keep_s:.2} s) is \
             shorter than the detector window: record a longer rest",
            r.run.spec.name
        )));
    }
    let note = format!("initial rest shortened from {} s to {keep_s:.2} s: {what}", r.init_rest_s);
    Ok((still, Some(n_init), note))
}

/// The static poses and the accelerometer fitted on them: the given poses, or those of the
/// detector's threshold multiplier whose accelerometer fit costs least (imu_tk's rule).
struct Poses {
    poses: Vec<(usize, usize)>,
    acc: AccelSolution,
    detection: Detection,
}

fn detect_poses(session: &Session, r: &Recording<'_>, opts: &ProtocolOptions) -> Result<Poses, EstimateError> {
    let (run, window, min_pose_samples) = (r.run, r.window, r.min_pose_samples);
    let g = session.manifest.g_m_s2;
    let rec = &run.rec;
    let t0 = rec.t_s.first().copied().unwrap_or(0.0);
    let n_init = rec.t_s.iter().take_while(|&&t| t - t0 < r.init_rest_s).count();
    if n_init < window.max(10) || n_init >= rec.len() {
        return Err(protocol_error(format!(
            "run '{}': the initial rest of {} s has {n_init} samples: expected at least the detector window ({window}) and less than the whole recording",
            run.spec.name, r.init_rest_s
        )));
    }
    let (n_init, declared, rest_note) = verified_rest(rec, r, n_init, window, opts)?;
    let baseline = variance_norm(&rec.accel, 0, n_init);
    let norms = moving_variance_norm(&rec.accel, window);
    let extra: Vec<[f64; 3]> = session
        .runs
        .iter()
        .filter(|r| matches!(r.spec.motion, MotionSpec::StaticUnknown))
        .map(|r| mean3(&r.rec.accel))
        .collect();
    if let Some(given) = r.poses {
        if let Some(&(s, e)) = given.iter().find(|&&(_, e)| e > rec.len()) {
            return Err(protocol_error(format!(
                "run '{}': pose [{s}, {e}) reaches past the run's {} samples",
                run.spec.name,
                rec.len()
            )));
        }
    }
    let candidates: Vec<f64> = match (r.poses, r.threshold_multiplier) {
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
        let found: Vec<(usize, usize)> = match r.poses {
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
        if r.poses.is_none() {
            tried.push((m, found.len(), Some(sol.cost)));
        }
        if best.as_ref().is_none_or(|b| sol.cost < b.2.cost) {
            best = Some((m, found, sol));
        }
    }
    let given = r.poses.is_some();
    let Some((multiplier, poses, acc)) = best else {
        let found: Vec<String> = tried.iter().map(|(m, n, _)| format!("{n} at ×{m}")).collect();
        let found = if found.is_empty() { "none".to_string() } else { found.join(", ") };
        return Err(protocol_error(format!(
            "run '{}': too few static poses for the 9 accelerometer parameters: at least 9 poses held still for {min_pose_samples} samples or more are needed. Poses found at each detection threshold tried (×m = m times the initial rest's variance): {found}. Hold 9 or more different orientations still for longer, lower \"min_pose_samples\" in the manifest, or give the poses as sample ranges (\"poses\")",
            run.spec.name
        )));
    };
    let detection = Detection {
        window,
        init_rest_samples: n_init,
        baseline_variance_norm: baseline,
        multiplier: (!given).then_some(multiplier),
        threshold: (!given).then_some(multiplier * baseline),
        min_pose_samples,
        tried,
        declared_rest_samples: declared,
        rest_note,
    };
    Ok(Poses { poses, acc, detection })
}

/// The gyro's bias (and g-sensitivity, when the model has it) with standard errors: from
/// the pose means `u = b + G a`, or the initial rest's mean.
struct GyroRest {
    b: Vector3<f64>,
    g: Matrix3<f64>,
    b_se: [f64; 3],
    g_se: Matrix3<f64>,
}

fn gyro_rest(
    rec: &crate::session::Recording,
    n_init: usize,
    pose_u: &[[f64; 3]],
    pose_a: &[Vector3<f64>],
    with_g: bool,
) -> GyroRest {
    let (b, g, b_se, g_se) = if with_g {
        gyro_bias_and_g(pose_u, pose_a)
    } else {
        let init = &rec.gyro[..n_init];
        let b = mean3(init);
        let se = [0, 1, 2].map(|i| {
            let var = init.iter().map(|u| (u[i] - b[i]).powi(2)).sum::<f64>() / (n_init - 1) as f64;
            (var / n_init as f64).sqrt()
        });
        (Vector3::from(b), Matrix3::zeros(), se, Matrix3::zeros())
    };
    GyroRest { b, g, b_se, g_se }
}

/// The motions between consecutive poses, from the last sample of one to the sample before
/// the next (imu_tk's span), with their names.
fn segments(
    rec: &crate::session::Recording,
    poses: &[(usize, usize)],
    pose_a: &[Vector3<f64>],
    rest: &GyroRest,
    a_cal: &dyn Fn(&[f64; 3]) -> Vector3<f64>,
    with_g: bool,
) -> (Vec<Segment>, Vec<String>) {
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
                let v = Vector3::from(rec.gyro[i]) - rest.b - rest.g * a;
                [v[0], v[1], v[2]]
            })
            .collect();
        let dt: Vec<f64> = (i0..i1).map(|i| rec.t_s[i + 1] - rec.t_s[i]).collect();
        segments.push(Segment { u, dt, v0: pose_a[k].normalize(), v1: pose_a[k + 1].normalize() });
        names.push(format!("pose {} → {}", k + 1, k + 2));
    }
    (segments, names)
}

/// Fits a multi-position session (Tedaldi et al. 2014): the accelerometer so that every
/// pose measures |a| = g, then the gyro so that the motions between poses turn one pose's
/// gravity direction onto the next.
pub(super) fn multi_position(
    session: &Session,
    model: &Model,
    opts: &ProtocolOptions,
) -> Result<(Fit, ProtocolReport), EstimateError> {
    let g = session.manifest.g_m_s2;
    let r = the_run(session)?;
    let (run, rec) = (r.run, &r.run.rec);
    let Poses { poses, acc, detection } = detect_poses(session, &r, opts)?;
    let m_acc = upper(&acc.p);
    let b_acc = Vector3::new(acc.p[6], acc.p[7], acc.p[8]);
    let a_cal = |u: &[f64; 3]| -> Vector3<f64> { m_acc * (Vector3::from(*u) - b_acc) };

    let with_g = model.effects().iter().any(|e| e.id() == "gyro-g-sensitivity");
    let pose_a: Vec<Vector3<f64>> = poses.iter().map(|&(s, e)| a_cal(&mean3(&rec.accel[s..e]))).collect();
    let pose_u: Vec<[f64; 3]> = poses.iter().map(|&(s, e)| mean3(&rec.gyro[s..e])).collect();
    let rest = gyro_rest(rec, detection.init_rest_samples, &pose_u, &pose_a, with_g);
    let (segments, names) = segments(rec, &poses, &pose_a, &rest, &a_cal, with_g);
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

    // Report.
    let rate_at = |u: [f64; 3], a: &Vector3<f64>| -> [f64; 3] {
        let rate = w * (Vector3::from(u) - rest.b - rest.g * a);
        [rate[0].to_degrees(), rate[1].to_degrees(), rate[2].to_degrees()]
    };
    let n_rest = detection.init_rest_samples;
    let reference = super::rest::rest_noise(&[(&rec.accel[..n_rest], &rec.gyro[..n_rest])], detection.window);
    let motion = |x: &crate::session::Recording, span: (usize, usize)| {
        reference.as_ref().and_then(|n| super::rest::check_span(&x.accel, &x.gyro, span, n))
    };
    // Noise of a pose's rate at rest and |a| − g: its block means through the calibration,
    // with the rest's bias error when the bias comes from the rest.
    let bias_se = if with_g { [0.0; 3] } else { super::through(&w, rest.b_se) };
    let noise = |x: &crate::session::Recording, (s, e): (usize, usize), a: &Vector3<f64>| {
        let r = super::through(&w, super::mean_se(&x.gyro[s..e], detection.window));
        let rate = [0, 1, 2].map(|i| r[i].hypot(bias_se[i]).to_degrees());
        let dir = a.normalize().transpose() * m_acc;
        let sa = super::mean_se(&x.accel[s..e], detection.window);
        let grav = (0..3).map(|j| (dir[j] * sa[j]).powi(2)).sum::<f64>().sqrt();
        (Some(rate).filter(|v| v.iter().all(|x| x.is_finite())), Some(grav).filter(|v| v.is_finite()))
    };
    let mut pose_rows = Vec::new();
    for (k, &(s, e)) in poses.iter().enumerate() {
        let (rate_se_deg_s, gravity_se_m_s2) = noise(rec, (s, e), &pose_a[k]);
        pose_rows.push(PoseResidual {
            run: run.spec.name.clone(),
            start: s,
            end: e,
            gravity_error_m_s2: pose_a[k].norm() - g,
            rate_at_rest_deg_s: rate_at(pose_u[k], &pose_a[k]),
            motion: motion(rec, (s, e)),
            rate_se_deg_s,
            gravity_se_m_s2,
        });
    }
    for r in session.runs.iter().filter(|r| matches!(r.spec.motion, MotionSpec::StaticUnknown)) {
        let a = a_cal(&mean3(&r.rec.accel));
        let (rate_se_deg_s, gravity_se_m_s2) = noise(&r.rec, (0, r.rec.len()), &a);
        pose_rows.push(PoseResidual {
            run: r.spec.name.clone(),
            start: 0,
            end: r.rec.len(),
            gravity_error_m_s2: a.norm() - g,
            rate_at_rest_deg_s: rate_at(mean3(&r.rec.gyro), &a),
            motion: motion(&r.rec, (0, r.rec.len())),
            rate_se_deg_s,
            gravity_se_m_s2,
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
    let report = ProtocolReport {
        protocol: "multi-position".into(),
        gravity_rms_m_s2: rms(pose_rows.iter().map(|p| p.gravity_error_m_s2)),
        poses: pose_rows,
        turns,
        detection: Some(detection),
        accel_cost: Some(acc.cost),
        gyro_cost: Some(gyro.cost()),
        warnings: Vec::new(),
        pose_params: [9, if with_g { 12 } else { 0 }],
    };
    let fit = forward_fit(model, &acc, &gyro, &rest, s0, with_g);
    Ok((fit, report))
}

/// The fit in crosscal's forward convention: K = M⁻¹ (upper triangular), C = W⁻¹, with
/// their covariances propagated to first order.
fn forward_fit(
    model: &Model,
    acc: &AccelSolution,
    gyro: &crate::estimate::lm::LmResult,
    rest: &GyroRest,
    s0: f64,
    with_g: bool,
) -> Fit {
    let w_cov = gyro.covariance();
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
                    (rest.g[(i, j)], Some(rest.g_se[(i, j)]), usize::MAX),
                );
            }
        }
        values.insert(format!("gyro.b_{}", AXES[i]), (rest.b[i], Some(rest.b_se[i]), usize::MAX));
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
            cond: condition(&gyro.jacobian, &[s0; 9]),
        },
        "",
    );
    Fit { gyro: gyro_fit, accel: accel_fit, nonlinear: Vec::new(), stand: Vec::new(), stand_base: None }
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
                    unidentifiable.push(Unidentifiable {
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
                slow_noise: None,
                residual_lag1: 0.0,
            }
        })
        .collect();
    SensorFit { sensor, coefficients, channels, unidentifiable, correlated: Vec::new() }
}
