//! Diagnosis of protocol sessions (Ferraris faces and turns, multi-position poses): which
//! poses and turns the model misfits, and which catalogue effect the static poses call for.
//!
//! The poses of the fitted session become one-row runs at their true specific force (the
//! declared up of a face; the calibrated direction × g for a pose of unknown orientation).
//! Every catalogue effect whose regressors are functions of the specific force alone is
//! added in turn to the pose-level least-squares problem, and scored by the F-test of the
//! residual sum of squares it removes (`F = (ΔRSS/Δp) / (RSS₁/(n − p₁))`). The best effect
//! with p < [`P_PROPOSE`] is proposed, with whether this kind of session can fit it.

use crate::estimate::protocol::{can_fit, pose_identifiable, pose_rows, ProtocolReport};
use crate::estimate::{CoefStatus, EstimateError, Fit, FitOptions, FitRequest, FitRun, SensorFit};
use crate::model::{catalog, Model};
use crate::session::Session;
use crate::units::SensorKind;
use serde::{Deserialize, Serialize};
use statrs::distribution::{ChiSquared, ContinuousCDF, FisherSnedecor};

/// Fits exactly `model` to prepared runs through the one entry point.
fn refit(model: &Model, runs: &[FitRun<'_>], opts: &FitOptions) -> Result<Fit, EstimateError> {
    Ok(crate::estimate::fit(&FitRequest::runs(model, runs).options(*opts))?.fit)
}

/// p-value below which a candidate effect is proposed.
pub const P_PROPOSE: f64 = 1e-3;

/// One candidate effect scored on the static poses.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PoseCandidate {
    /// Effect id.
    pub effect: String,
    /// Sensor it acts on.
    pub sensor: SensorKind,
    /// Coefficients it adds (fitted).
    pub added_params: usize,
    /// Residual sum of squares of that sensor's pose rows without it.
    pub rss_before: f64,
    /// With it.
    pub rss_after: f64,
    /// F-test p-value.
    pub p_value: f64,
    /// Whether `crosscal fit --effect <id>` can fit it on this kind of session (and why not).
    pub fittable: Result<(), String>,
}

/// The diagnosis of a protocol session.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ProtocolDiagnosis {
    /// Model diagnosed.
    pub model: String,
    /// The fit's pose and turn residuals.
    pub report: ProtocolReport,
    /// Poses whose |a| − g stands out (robust z > 5 against the others).
    pub outlier_poses: Vec<String>,
    /// Poses whose calibrated rate at rest stands out (robust z > 5 of its norm).
    #[serde(default)]
    pub outlier_rates: Vec<String>,
    /// Poses that were not at rest by the noise of the rest (see `PoseResidual::motion`).
    #[serde(default)]
    pub moving_poses: Vec<String>,
    /// Pose residuals that, together, are larger than the noise explains (χ² against each
    /// pose's standard errors from its noise), with what would fix them.
    #[serde(default)]
    pub beyond_noise: Vec<String>,
    /// Turns or motions whose misfit stands out (robust z > 5 of |error| against the others).
    #[serde(default)]
    pub outlier_turns: Vec<String>,
    /// Candidates, best first.
    pub candidates: Vec<PoseCandidate>,
    /// The proposed effect, if any candidate is significant.
    pub proposal: Option<String>,
    /// Candidates that remove exactly as much as the proposal: these poses cannot tell them
    /// apart (e.g. quadratic and scale asymmetry on six faces at ±g).
    pub indistinguishable: Vec<String>,
    /// Earth's rotation seen on the poses (its vertical part follows gravity like an
    /// isotropic g-sensitivity), when significant and not declared in the manifest.
    #[serde(default)]
    pub earth_rotation: Option<String>,
}

fn rss(f: &SensorFit) -> (f64, usize, usize) {
    let mut r = 0.0;
    let mut n = 0;
    for ch in &f.channels {
        r += ch.residual_rms * ch.residual_rms * ch.n as f64;
        n += ch.n as usize;
    }
    let p = f.coefficients.iter().filter(|c| c.status == CoefStatus::Fitted).count();
    (r, n, p)
}

/// Diagnoses a protocol session with `model` (see the module documentation).
pub fn diagnose_protocol(session: &Session, model: &Model) -> Result<ProtocolDiagnosis, EstimateError> {
    diagnose_protocol_with(session, model, &crate::estimate::protocol::ProtocolOptions::default())
}

/// [`diagnose_protocol`] with the protocol fit's options (e.g. `trim_rest`).
pub fn diagnose_protocol_with(
    session: &Session,
    model: &Model,
    protocol: &crate::estimate::protocol::ProtocolOptions,
) -> Result<ProtocolDiagnosis, EstimateError> {
    let mut req = FitRequest::session(model, session);
    req.protocol = *protocol;
    let outcome = crate::estimate::fit(&req)?;
    let report = outcome.protocol.ok_or_else(|| {
        EstimateError::Request(format!("{} is not a protocol session", session.manifest_path.display()))
    })?;
    let fitted = outcome.fit;
    let rows = pose_rows(session, &fitted, &report);
    let runs: Vec<FitRun<'_>> = rows.iter().map(|r| r.as_run()).collect();
    let opts = FitOptions::default();
    let base = refit(model, &runs, &opts)?;
    let mut candidates = Vec::new();
    for e in catalog() {
        let (crate::model::CatalogEffect::Linear(e), false) = (&e, model.has(e.id())) else { continue };
        if !pose_identifiable(e.as_ref(), false) {
            continue;
        }
        let mut m = model.clone();
        if m.add_effect(e.id()).is_err() {
            continue;
        }
        let Ok(with) = refit(&m, &runs, &opts) else { continue };
        let (r0, _, p0) = rss(base.sensor(e.sensor()));
        let (r1, n, p1) = rss(with.sensor(e.sensor()));
        if p1 <= p0 || n <= p1 {
            continue;
        }
        let (d1, d2) = ((p1 - p0) as f64, (n - p1) as f64);
        let f = ((r0 - r1).max(0.0) / d1) / (r1 / d2).max(f64::MIN_POSITIVE);
        let p_value = FisherSnedecor::new(d1, d2).map_or(1.0, |dist| dist.sf(f));
        candidates.push(PoseCandidate {
            effect: e.id().to_string(),
            sensor: e.sensor(),
            added_params: p1 - p0,
            rss_before: r0,
            rss_after: r1,
            p_value,
            fittable: can_fit(session, &m),
        });
    }
    let earth = earth_rotation(session, model, &base, &runs, &mut candidates, &opts);
    candidates.sort_by(|a, b| a.p_value.total_cmp(&b.p_value));
    let proposal = candidates.first().filter(|c| c.p_value < P_PROPOSE).map(|c| c.effect.clone());
    let indistinguishable = match candidates.first().filter(|_| proposal.is_some()) {
        Some(best) => candidates[1..]
            .iter()
            .filter(|c| {
                c.added_params == best.added_params && (c.rss_after - best.rss_after).abs() <= 1e-9 * best.rss_before
            })
            .map(|c| c.effect.clone())
            .collect(),
        None => Vec::new(),
    };
    // Robust z of each pose's |a| − g against the others (median / MAD).
    let mut errs: Vec<f64> = report.poses.iter().map(|p| p.gravity_error_m_s2).collect();
    let med = crate::stats::median(&mut errs).unwrap_or(0.0);
    let mad = crate::stats::robust_sigma(&errs, med).unwrap_or(0.0);
    let outlier_poses = report
        .poses
        .iter()
        .filter(|p| mad > 0.0 && (p.gravity_error_m_s2 - med).abs() > 5.0 * mad)
        .map(|p| format!("{}[{}..{}]: |a| − g = {:+.4} m/s^2", p.run, p.start, p.end, p.gravity_error_m_s2))
        .collect();
    let norm = |w: &[f64; 3]| (w[0] * w[0] + w[1] * w[1] + w[2] * w[2]).sqrt();
    let rates: Vec<f64> = report.poses.iter().map(|p| norm(&p.rate_at_rest_deg_s)).collect();
    let outlier_rates = stand_out(&rates)
        .into_iter()
        .map(|k| {
            let p = &report.poses[k];
            let w = p.rate_at_rest_deg_s;
            format!("{}[{}..{}]: rate at rest ({:+.4}, {:+.4}, {:+.4}) deg/s", p.run, p.start, p.end, w[0], w[1], w[2])
        })
        .collect();
    let moving_poses = report
        .poses
        .iter()
        .filter_map(|p| p.motion.as_ref().map(|m| format!("{}[{}..{}]: not at rest ({m})", p.run, p.start, p.end)))
        .collect();
    let beyond_noise = beyond_noise(&report);
    let misfits: Vec<f64> = report.turns.iter().map(|t| t.error_deg.abs()).collect();
    let outlier_turns = stand_out(&misfits)
        .into_iter()
        .map(|k| format!("{}: misfit {:+.4} deg", report.turns[k].name, report.turns[k].error_deg))
        .collect();
    Ok(ProtocolDiagnosis {
        model: model.name.clone(),
        report,
        outlier_poses,
        outlier_rates,
        outlier_turns,
        moving_poses,
        beyond_noise,
        candidates,
        proposal,
        indistinguishable,
        earth_rotation: earth,
    })
}

/// Earth's rotation, 15.04 °/h, on static poses: its vertical part Ω_v (Ω_E sin latitude)
/// adds Ω_v a/|a| to the rates at rest — it follows gravity exactly like an isotropic
/// g-sensitivity — and its horizontal part depends on the heading of each pose. Unless the
/// manifest declares it, the vertical part is estimated on the poses (one coefficient
/// shared by the three gyro channels, beside the fitted biases), and every gyro candidate
/// is scored against the model *with* it: ΔRSS over the residual of candidate + Earth
/// (`F = ((RSS_E − RSS_{c+E})/Δp) / (RSS_{c+E}/(n − p_c − 1))`), so that no unit effect is
/// named for what the Earth does. Returns the finding in words when Ω_v is significant.
fn earth_rotation(
    session: &Session,
    model: &Model,
    base: &Fit,
    runs: &[FitRun<'_>],
    candidates: &mut [PoseCandidate],
    opts: &FitOptions,
) -> Option<String> {
    let declared = session.runs.iter().any(|r| {
        matches!(r.spec.motion, crate::session::MotionSpec::Static { earth_rate_rad_s, .. } if earth_rate_rad_s.iter().any(|&x| x != 0.0))
    });
    if declared || runs.len() < 4 {
        return None;
    }
    let up: Vec<[f64; 3]> = runs
        .iter()
        .map(|r| {
            let a = r.state(0).a;
            let n = (a[0] * a[0] + a[1] * a[1] + a[2] * a[2]).sqrt().max(f64::MIN_POSITIVE);
            a.map(|v| v / n)
        })
        .collect();
    // The regressor with each channel's mean over the poses removed (the biases are fitted).
    let mean: Vec<f64> = (0..3).map(|i| up.iter().map(|u| u[i]).sum::<f64>() / up.len() as f64).collect();
    let x: Vec<[f64; 3]> = up.iter().map(|u| [u[0] - mean[0], u[1] - mean[1], u[2] - mean[2]]).collect();
    let sxx: f64 = x.iter().flat_map(|v| v.iter()).map(|v| v * v).sum();
    if sxx <= 0.0 {
        return None;
    }
    let reduction = |m: &Model, f: &Fit| -> (f64, f64) {
        let sxe: f64 = runs
            .iter()
            .zip(&x)
            .map(|(r, xv)| {
                let res = super::picture::run_residual(m, f, r).0;
                (0..3).map(|i| xv[i] * res[i].first().copied().unwrap_or(0.0)).sum::<f64>()
            })
            .sum();
        (sxe * sxe / sxx, sxe / sxx)
    };
    let (r0, n, p0) = rss(base.sensor(SensorKind::Gyro));
    let (red0, omega) = reduction(model, base);
    let r0e = (r0 - red0).max(f64::MIN_POSITIVE);
    if n <= p0 + 1 {
        return None;
    }
    let s2 = r0e / (n - p0 - 1) as f64;
    let se = (s2 / sxx).sqrt();
    let f = red0 / s2;
    let p = FisherSnedecor::new(1.0, (n - p0 - 1) as f64).map_or(1.0, |d| d.sf(f));
    for c in candidates.iter_mut().filter(|c| c.sensor == SensorKind::Gyro) {
        let mut m = model.clone();
        if m.add_effect(&c.effect).is_err() {
            continue;
        }
        let Ok(with) = refit(&m, runs, opts) else { continue };
        let (red1, _) = reduction(&m, &with);
        let r1e = (c.rss_after - red1).max(f64::MIN_POSITIVE);
        let p1 = p0 + c.added_params;
        if n <= p1 + 1 {
            continue;
        }
        let (d1, d2) = (c.added_params as f64, (n - p1 - 1) as f64);
        let fc = ((r0e - r1e).max(0.0) / d1) / (r1e / d2);
        c.p_value = c.p_value.max(FisherSnedecor::new(d1, d2).map_or(1.0, |d| d.sf(fc)));
    }
    if p >= P_PROPOSE {
        return None;
    }
    let deg_h = 180.0 / std::f64::consts::PI * 3600.0;
    let earth = 15.041;
    let (w, e) = (omega * deg_h, se * deg_h);
    let lat = if w.abs() <= earth {
        format!(", latitude ≈ {:.0}°", (w / earth).asin().to_degrees())
    } else {
        String::new()
    };
    let verdict = if w.abs() <= earth + 3.0 * e {
        "Earth's rotation, not the unit: declare it in the manifest (earth_rate) or keep it out of the gyro model"
    } else {
        "larger than Earth's rotation can be (15.04 °/h): a g-sensitivity of the unit, or poses that were not still"
    };
    Some(format!(
        "the rates at rest follow gravity with a vertical rate of {w:+.1} ± {e:.1} °/h (p = {p:.1e}; Earth: 15.04 °/h × sin latitude{lat}): {verdict}; gyro candidates are scored with it in the model"
    ))
}

/// Residuals larger than the noise explains, as a whole: the rates at rest and |a| − g of
/// all poses against their standard errors from the noise, χ² = Σ (r/σ)² on (values −
/// parameters fitted from them) degrees of freedom. Reported when p < 1e-3 and the residuals
/// are more than twice the noise (χ²/dof > 4): a bias that wanders between the rest and the
/// poses, or a systematic effect every pose shares, which no single outlier shows.
fn beyond_noise(report: &ProtocolReport) -> Vec<String> {
    let mut out = Vec::new();
    let rates: Vec<f64> = report
        .poses
        .iter()
        .filter_map(|p| p.rate_se_deg_s.map(|se| (p.rate_at_rest_deg_s, se)))
        .flat_map(|(r, se)| (0..3).map(move |i| r[i] / se[i]))
        .collect();
    let gravity: Vec<f64> =
        report.poses.iter().filter_map(|p| p.gravity_se_m_s2.map(|se| p.gravity_error_m_s2 / se)).collect();
    for (what, z, params, fix) in [
        (
            "calibrated rates at rest",
            rates,
            report.pose_params[1],
            "the gyro bias is not the same in the rest and in the poses (warm-up, bias instability, a rest that was not still): a longer warm-up before recording, a repeated orientation late in the recording, or gyro-g-sensitivity if the rates follow the pose",
        ),
        (
            "pose |a| − g",
            gravity,
            report.pose_params[0],
            "the accelerometer model misses something every pose shares, or the poses were not still: more poses held longer, or an accelerometer effect from the catalogue",
        ),
    ] {
        let dof = z.len().saturating_sub(params);
        if dof < 3 || z.iter().any(|v| !v.is_finite()) {
            continue;
        }
        let chi2 = z.iter().map(|v| v * v).sum::<f64>();
        let p = ChiSquared::new(dof as f64).map_or(1.0, |d| d.sf(chi2));
        if p < P_PROPOSE && chi2 / dof as f64 > 4.0 {
            out.push(format!(
                "{what} are {:.1}× what the noise explains (χ² = {chi2:.0} on {dof} degrees of freedom, p = {p:.1e}): {fix}",
                (chi2 / dof as f64).sqrt()
            ));
        }
    }
    out
}

/// Indices of the non-negative sizes (rates at rest, misfits) that stand out of the others:
/// above their median by more than 5 robust σ (1.4826·MAD) and twice the median; none with
/// fewer than five values (no scatter to compare with).
fn stand_out(v: &[f64]) -> Vec<usize> {
    if v.len() < 5 {
        return Vec::new();
    }
    let mut c = v.to_vec();
    let med = crate::stats::median(&mut c).unwrap_or(0.0);
    let sigma = crate::stats::robust_sigma(v, med).unwrap_or(0.0);
    (0..v.len()).filter(|&k| v[k] > med + 5.0 * sigma && v[k] > 2.0 * med && v[k] > 0.0).collect()
}

impl ProtocolDiagnosis {
    /// The verdict in a stand diagnosis's terms: `Explained` when the proposal explains pose
    /// residuals that are otherwise within the noise model, `Adequate` when nothing stands
    /// out, else `Unexplained` (a proposal on residuals beyond the noise is no evidence).
    pub fn verdict(&self) -> super::Verdict {
        if self.proposal.is_some() && self.beyond_noise.is_empty() {
            super::Verdict::Explained
        } else if self.adequate() {
            super::Verdict::Adequate
        } else {
            super::Verdict::Unexplained
        }
    }

    /// Adequate: no missing effect, and no pose or turn the noise and the pose-to-pose
    /// scatter do not explain.
    pub fn adequate(&self) -> bool {
        self.proposal.is_none()
            && self.outlier_poses.is_empty()
            && self.outlier_rates.is_empty()
            && self.outlier_turns.is_empty()
            && self.moving_poses.is_empty()
            && self.beyond_noise.is_empty()
    }

    /// What stands out, one line each (poses, rates at rest, turns).
    pub fn standing_out(&self) -> Vec<String> {
        self.outlier_poses
            .iter()
            .chain(&self.outlier_rates)
            .chain(&self.outlier_turns)
            .chain(&self.moving_poses)
            .chain(&self.beyond_noise)
            .cloned()
            .collect()
    }
}
