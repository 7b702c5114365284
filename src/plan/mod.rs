//! Experiment planning without data: the standard error every coefficient would get from a
//! proposed set of stand runs, from the reference motion alone.
//!
//! For a channel with white noise σ per sample and design Φ (the model's regressors over the
//! simulated true motion of every run), the Cramér–Rao bound of the coefficients is
//! cov = σ² (ΦᵀΦ)⁻¹; it is what [`crate::estimate::fit`] returns with a known σ on
//! noiseless data of the plan, so the identifiability analysis is the fit's own.
//!
//! The "worst" coefficient is the one whose standard error moves the output most: se_j ×
//! RMS over the plan of its regressor, divided by σ of its channel (dimensionless, so gyro,
//! accelerometer and ε terms compare). The suggested extra run is the candidate that leaves
//! fewest coefficients unidentifiable, then the smallest worst error, then the shortest.

use crate::estimate::{fit_runs, tracks, FitRun};
use crate::estimate::{CoefStatus, Correlation, EstimateError, Fit, FitOptions, FitRequest, Unidentifiable};
use crate::model::Model;
use crate::motion::DerivativeConfig;
use crate::session::MotionSpec;
use crate::simulate::{RunPlan, SimConfig};
use crate::units::SensorKind;
use serde::Serialize;

pub mod thermal;

/// How many times the present data (session length, or number of runs of the same design)
/// it takes to bring a standard error from `u_now` down to `u_target`: the Cramér–Rao
/// covariance σ² (ΦᵀΦ)⁻¹ of a fixed design falls as 1/samples, so the factor is
/// (u_now / u_target)². Infinite when the target is 0.
pub fn duration_factor(u_now: f64, u_target: f64) -> f64 {
    if u_target > 0.0 {
        (u_now / u_target).powi(2)
    } else {
        f64::INFINITY
    }
}

/// Fits exactly `model` to prepared runs through the one entry point.
fn refit(model: &Model, runs: &[FitRun<'_>], opts: &FitOptions) -> Result<Fit, EstimateError> {
    Ok(crate::estimate::fit(&FitRequest::runs(model, runs).options(*opts))?.fit)
}

/// A proposed calibration: runs, sample rate and the sensor's white noise.
#[derive(Debug, Clone)]
pub struct PlanSpec {
    /// Runs (motion, mount, duration).
    pub runs: Vec<RunPlan>,
    /// Sample rate, Hz.
    pub sample_rate_hz: f64,
    /// Gyro white-noise density, rad/s/√Hz (per-sample σ = N·√rate).
    pub gyro_density: f64,
    /// Accelerometer white-noise density, m/s²/√Hz.
    pub accel_density: f64,
}

impl PlanSpec {
    /// Per-sample σ of every channel (gx..az).
    pub fn sigma(&self) -> [f64; 6] {
        let r = self.sample_rate_hz.sqrt();
        let (g, a) = (self.gyro_density * r, self.accel_density * r);
        [g, g, g, a, a, a]
    }
}

/// The predicted uncertainty of one coefficient.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct PlannedCoefficient {
    /// Coefficient name.
    pub name: String,
    /// SI unit.
    pub unit: String,
    /// Fitted, fixed by the model, or unidentifiable from these runs.
    pub status: CoefStatus,
    /// Predicted standard error (Cramér–Rao bound), SI.
    pub std_error: Option<f64>,
    /// se × RMS of its regressor / σ of its channel: the output error it leaves, in noise units.
    pub output_error: Option<f64>,
}

/// A run to add.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Suggestion {
    /// The run in words (name, motion, mount, duration).
    pub run: String,
    /// Name of the run.
    pub name: String,
    /// Unidentifiable coefficients without and with it.
    pub unidentifiable: (usize, usize),
    /// Worst coefficient and its output error without the run.
    pub worst_before: Option<(String, f64)>,
    /// The same coefficient's output error with the run, and the new worst.
    pub worst_after: Option<(String, f64)>,
    /// Coefficients it makes identifiable.
    pub resolves: Vec<String>,
}

/// What a plan would determine.
#[derive(Debug, Clone, Serialize)]
pub struct PlanReport {
    /// Total samples.
    pub samples: usize,
    /// Per-sample σ used (gx..az, SI).
    pub sigma: [f64; 6],
    /// Every coefficient of the model.
    pub coefficients: Vec<PlannedCoefficient>,
    /// Lost combinations with the run that would fix each.
    pub unidentifiable: Vec<Unidentifiable>,
    /// Pairs whose estimates would correlate above 0.95.
    pub correlated: Vec<Correlation>,
    /// The coefficient with the largest output error.
    pub worst: Option<(String, f64)>,
    /// The cheapest extra run that most improves the plan, if any candidate does.
    pub suggestion: Option<Suggestion>,
}

/// A run described in words.
pub fn describe(r: &RunPlan) -> String {
    let motion = match &r.motion {
        MotionSpec::Conic { cone_angle_deg, rate_deg_s, .. } => {
            format!("conic α = {cone_angle_deg}°, ω_s = {rate_deg_s:+} °/s")
        }
        MotionSpec::Static { up_stand, .. } => format!("static, up = {up_stand:?}"),
        _ => "reference motion".to_string(),
    };
    format!("{} ({motion}, mount [{}], {} s)", r.name, r.mount.names().join(", "), r.duration_s)
}

/// The fit a plan predicts: noiseless data of the plan fitted with the plan's σ.
pub fn predict(model: &Model, spec: &PlanSpec) -> Result<(Fit, Vec<Vec<f64>>), EstimateError> {
    let cfg = SimConfig { runs: spec.runs.clone(), sample_rate_hz: spec.sample_rate_hz, ..SimConfig::paper() };
    predict_config(model, &cfg, spec.sigma())
}

/// The fit a simulated design predicts (its runs, sample rate and temperatures; the unit and
/// noise of `cfg` are ignored: the paper's unit, noiseless, fitted with the per-sample σ of
/// every channel, gx..az), and the RMS of every regressor over the design per sensor, in
/// model term order.
pub fn predict_config(model: &Model, cfg: &SimConfig, sigma: [f64; 6]) -> Result<(Fit, Vec<Vec<f64>>), EstimateError> {
    crate::simulate::check_runs(&cfg.runs, cfg.sample_rate_hz).map_err(EstimateError::Request)?;
    let noiseless = SimConfig {
        truth: SimConfig::paper().truth,
        gyro_noise_deg_s: 0.0,
        accel_noise_g: 0.0,
        gyro_process: Default::default(),
        accel_process: Default::default(),
        realism: Default::default(),
        stand: Default::default(),
        carry_noise: false,
        temp_reading: Default::default(),
        ..cfg.clone()
    };
    let session = noiseless.generate();
    let tr = tracks(&session, &DerivativeConfig::default());
    let runs = fit_runs(&session, &tr);
    let opts = FitOptions { known_sigma: Some(sigma), ..FitOptions::default() };
    let f = refit(model, &runs, &opts)?;
    // RMS of every regressor over the plan, per sensor, in model term order.
    let mut rms = Vec::new();
    for sensor in SensorKind::BOTH {
        let terms = model.terms(sensor);
        let mut sums = vec![0.0f64; terms.len()];
        let mut n = 0usize;
        for run in &runs {
            for k in 0..run.len() {
                let s = run.state(k);
                for (ti, t) in terms.iter().enumerate() {
                    sums[ti] += t.regressor(&s).powi(2);
                }
                n += 1;
            }
        }
        for v in &mut sums {
            *v = (*v / n.max(1) as f64).sqrt();
        }
        rms.push(sums);
    }
    Ok((f, rms))
}

fn coefficients(f: &Fit, rms: &[Vec<f64>], sigma: &[f64; 6]) -> Vec<PlannedCoefficient> {
    let mut out = Vec::new();
    for sensor in SensorKind::BOTH {
        for (ti, c) in f.sensor(sensor).coefficients.iter().enumerate() {
            let s = sigma[3 * sensor.index() + c.channel];
            let r = rms[sensor.index()].get(ti).copied().unwrap_or(0.0);
            out.push(PlannedCoefficient {
                name: c.name.clone(),
                unit: c.unit.clone(),
                status: c.status,
                std_error: c.std_error,
                output_error: c.std_error.filter(|_| s > 0.0).map(|se| se * r / s),
            });
        }
    }
    out
}

fn worst(c: &[PlannedCoefficient]) -> Option<(String, f64)> {
    c.iter().filter_map(|c| c.output_error.map(|e| (c.name.clone(), e))).max_by(|a, b| a.1.total_cmp(&b.1))
}

fn unidentifiable_names(c: &[PlannedCoefficient]) -> Vec<String> {
    c.iter().filter(|c| c.status == CoefStatus::Unidentifiable).map(|c| c.name.clone()).collect()
}

/// Candidate extra runs: every combination of the plan's rates (and their opposites), its
/// cone angles and the three cyclic mounts, at the plan's longest run duration.
pub fn default_candidates(spec: &PlanSpec) -> Vec<RunPlan> {
    let mut rates: Vec<f64> = Vec::new();
    let mut angles: Vec<f64> = Vec::new();
    for r in &spec.runs {
        if let MotionSpec::Conic { cone_angle_deg, rate_deg_s, .. } = r.motion {
            for v in [rate_deg_s, -rate_deg_s, 2.0 * rate_deg_s] {
                if !rates.iter().any(|x| (x - v).abs() < 1e-9) {
                    rates.push(v);
                }
            }
            if !angles.iter().any(|x| (x - cone_angle_deg).abs() < 1e-9) {
                angles.push(cone_angle_deg);
            }
        }
    }
    if rates.is_empty() {
        rates = vec![10.0, -10.0, 20.0];
    }
    if angles.is_empty() {
        angles = vec![10.0];
    }
    if angles.len() == 1 {
        angles.push(angles[0] * 2.0);
    }
    let duration = spec.runs.iter().map(|r| r.duration_s).fold(0.0, f64::max).max(1.0);
    let mut out = crate::simulate::conic_plan(&rates, &angles, &crate::simulate::cyclic_mounts(3), duration);
    for r in &mut out {
        r.name = format!("extra-{}", r.name);
    }
    out
}

/// Predicts the plan's uncertainties and suggests the best extra run among `candidates`.
pub fn plan(model: &Model, spec: &PlanSpec, candidates: &[RunPlan]) -> Result<PlanReport, EstimateError> {
    let sigma = spec.sigma();
    let (f, rms) = predict(model, spec)?;
    let coefs = coefficients(&f, &rms, &sigma);
    let base_worst = worst(&coefs);
    let base_lost = unidentifiable_names(&coefs);
    let mut best: Option<(usize, f64, f64, Suggestion)> = None;
    for cand in candidates {
        let mut s = spec.clone();
        s.runs.push(cand.clone());
        let Ok((cf, crms)) = predict(model, &s) else { continue };
        let cc = coefficients(&cf, &crms, &sigma);
        let lost = unidentifiable_names(&cc);
        let w = worst(&cc);
        let score = w.as_ref().map_or(f64::INFINITY, |x| x.1);
        let same = base_worst
            .as_ref()
            .and_then(|(name, _)| cc.iter().find(|c| &c.name == name).and_then(|c| c.output_error))
            .zip(base_worst.as_ref().map(|b| b.0.clone()))
            .map(|(e, n)| (n, e));
        let better = match &best {
            None => true,
            Some((bl, bs, bd, _)) => {
                (lost.len(), score, cand.duration_s).partial_cmp(&(*bl, *bs, *bd)) == Some(std::cmp::Ordering::Less)
            }
        };
        if better {
            let sug = Suggestion {
                run: describe(cand),
                name: cand.name.clone(),
                unidentifiable: (base_lost.len(), lost.len()),
                worst_before: base_worst.clone(),
                worst_after: same.or(w),
                resolves: base_lost.iter().filter(|n| !lost.contains(n)).cloned().collect(),
            };
            best = Some((lost.len(), score, cand.duration_s, sug));
        }
    }
    // Only suggest a run that helps: fewer unknowns, or a worst error at least 10 % lower.
    let suggestion = best.map(|b| b.3).filter(|s| {
        s.unidentifiable.1 < s.unidentifiable.0
            || matches!((&s.worst_before, &s.worst_after), (Some(a), Some(b)) if b.1 < 0.9 * a.1)
    });
    Ok(PlanReport {
        samples: f.gyro.channels.first().map_or(0, |c| c.n as usize),
        sigma,
        unidentifiable: f.gyro.unidentifiable.iter().chain(&f.accel.unidentifiable).cloned().collect(),
        correlated: f.gyro.correlated.iter().chain(&f.accel.correlated).cloned().collect(),
        coefficients: coefs,
        worst: base_worst,
        suggestion,
    })
}

/// The runs of a session manifest as a design for [`plan`]: its conic runs and its static runs
/// with a known up, in their mounts, each for its `duration_s` (runs not yet recorded) or,
/// when every run is recorded, its recording's span; with the recordings' sample rate (None
/// when a run is not recorded: the caller's rate is used). Protocol runs (rotations,
/// multi-position, poses of unknown orientation) and reference runs have no stand design
/// and are refused by name.
pub fn design_runs(manifest_path: &std::path::Path) -> Result<(Vec<RunPlan>, Option<f64>), EstimateError> {
    let read = |source| EstimateError::Read { path: manifest_path.to_path_buf(), source };
    let manifest = crate::session::read_manifest(manifest_path).map_err(read)?;
    for r in &manifest.runs {
        if !matches!(r.motion, MotionSpec::Conic { .. } | MotionSpec::Static { .. }) {
            return Err(EstimateError::Request(format!(
                "run '{}' of {}: plan predicts conic and static stand runs; protocol runs (rotation, multi_position, poses of unknown up) and reference runs have no stand design",
                r.name,
                manifest_path.display()
            )));
        }
    }
    let plans = |durations: &[f64]| -> Vec<RunPlan> {
        manifest
            .runs
            .iter()
            .zip(durations)
            .map(|(r, &d)| RunPlan {
                name: r.name.clone(),
                motion: r.motion.clone(),
                mount: r.mount.clone(),
                duration_s: d,
            })
            .collect()
    };
    if let Some(d) = manifest.runs.iter().map(|r| r.duration_s).collect::<Option<Vec<f64>>>() {
        return Ok((plans(&d), None));
    }
    // Recorded: the durations and the sample rate from the recordings themselves.
    let session = crate::session::Session::load(manifest_path).map_err(read)?;
    let mut durations = Vec::with_capacity(session.runs.len());
    let (mut samples, mut span) = (0usize, 0.0);
    for run in &session.runs {
        let t = &run.rec.t_s;
        let n = t.len();
        let dt = if n > 1 { (t[n - 1] - t[0]) / (n - 1) as f64 } else { 0.0 };
        if dt.is_nan() || dt <= 0.0 {
            return Err(EstimateError::Request(format!("run '{}' has too few samples to plan from", run.spec.name)));
        }
        durations.push(n as f64 * dt);
        samples += n;
        span += n as f64 * dt;
    }
    Ok((plans(&durations), Some(samples as f64 / span)))
}
