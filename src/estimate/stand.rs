//! The stand's own imperfections: the actual cone angle α, rate ω_s and phase φ of every
//! conic run, estimated jointly with the linear coefficients, because a stand never sits
//! exactly at its nominal setting.
//!
//! Gauss–Newton with variable projection (Golub & Pereyra 1973): at stand parameters s the
//! linear coefficients θ are solved exactly; the prediction ŷ = Φ(s)θ is linearised in both,
//! r ≈ Φ Δθ + D Δs with D = ∂(Φ(s)θ)/∂s by central differences of the conic motion (paper
//! eqs. 1–2). Per output channel c, a QR of [Φ_c | D_c | r_c] eliminates Δθ:
//! R = [R₁₁ R₁₂ R₁₃; 0 R₂₂ R₂₃; 0 0 ρ], and the step solves
//! (Σ_c R₂₂ᵀR₂₂/σ_c²) Δs = Σ_c R₂₂ᵀR₂₃/σ_c², halved until the weighted residual falls.
//! At convergence M = Σ_c R₂₂ᵀR₂₂/σ_c² is the information of s (cov s = M⁻¹), and each
//! channel's coefficient covariance gains G M⁻¹ Gᵀ with G = R₁₁⁻¹R₁₂ (the part of θ that
//! moves with s), so the standard errors of C and K include the stand's uncertainty.

use super::memory::fit_in_memory as fit;
use super::{CoefStatus, EstimateError, Fit, FitOptions, FitRun};
use crate::model::Model;
use crate::motion::{track_for, DerivativeConfig, Track};
use crate::session::{MotionSpec, Session};
use crate::stats::QrAccumulator;
use crate::units::SensorKind;
use nalgebra::{DMatrix, DVector};
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
    /// Its standard errors.
    pub std_error: ConeSetting,
}

/// Central-difference steps for α (deg), ω_s (deg/s), φ (deg).
const STEP: [f64; 3] = [1e-4, 1e-4, 1e-3];
const MAX_ITER: usize = 40;

fn conic_of(m: &MotionSpec) -> Option<[f64; 3]> {
    match m {
        MotionSpec::Conic { cone_angle_deg, rate_deg_s, phase_deg } => Some([*cone_angle_deg, *rate_deg_s, *phase_deg]),
        _ => None,
    }
}

fn motion(p: [f64; 3]) -> MotionSpec {
    MotionSpec::Conic { cone_angle_deg: p[0], rate_deg_s: p[1], phase_deg: p[2] }
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
type Converged = (Vec<[f64; 3]>, Vec<Track>, Fit);

/// The stand problem of a session: which runs are conic, and the tracks and fit at given
/// settings `s` (one `[α, ω_s, φ]` per conic run, degrees and deg/s).
struct StandProblem<'a> {
    model: &'a Model,
    session: &'a Session,
    conic: Vec<usize>,
    deriv: &'a DerivativeConfig,
    opts: &'a FitOptions,
}

impl StandProblem<'_> {
    fn tracks(&self, s: &[[f64; 3]]) -> Vec<Track> {
        let g = self.session.manifest.g_m_s2;
        let mut k = 0;
        self.session
            .runs
            .iter()
            .map(|r| match conic_of(&r.spec.motion) {
                Some(_) => {
                    let t = track_for(&motion(s[k]), &r.spec.mount, &r.rec, g, self.deriv);
                    k += 1;
                    t
                }
                None => crate::motion::track(r, g, self.deriv),
            })
            .collect()
    }

    fn fit_at(&self, tracks: &[Track]) -> Result<Fit, EstimateError> {
        let runs: Vec<FitRun<'_>> = crate::estimate::fit_runs(self.session, tracks);
        fit(self.model, &runs, self.opts)
    }

    fn linearise(
        &self,
        s: &[[f64; 3]],
        tracks: &[Track],
        f: &Fit,
        sigma2: &[f64; 6],
    ) -> Result<Linearised, EstimateError> {
        linearise(self.model, self.session, &self.conic, s, tracks, f, sigma2, self.deriv, self.opts)
    }

    /// Gauss–Newton from `s` with a halving line search; the settings, their tracks and fit
    /// at convergence.
    fn gauss_newton(&self, mut s: Vec<[f64; 3]>) -> Result<Converged, EstimateError> {
        let m = 3 * self.conic.len();
        let mut tracks = self.tracks(&s);
        let mut f = self.fit_at(&tracks)?;
        let mut sigma2 = [1.0; 6];
        for _ in 0..MAX_ITER {
            // Channel weights from the current residual, held through the step's line search
            // (the nominal fit's residual holds the mislabelling; later ones only the noise).
            reweight(&f, &mut sigma2);
            let mut j = cost(&f, &sigma2);
            let (info, rhs, _) = self.linearise(&s, &tracks, &f, &sigma2)?;
            let Some(chol) = info.cholesky() else {
                return Err(EstimateError::NotConverged(
                    "the stand parameters are not identifiable from these runs (their information matrix is singular)"
                        .into(),
                ));
            };
            let step = chol.solve(&rhs);
            let mut lambda = 1.0;
            for _ in 0..12 {
                let trial: Vec<[f64; 3]> = s
                    .iter()
                    .enumerate()
                    .map(|(r, p)| std::array::from_fn(|i| p[i] + lambda * step[3 * r + i]))
                    .collect();
                let tt = self.tracks(&trial);
                if let Ok(ft) = self.fit_at(&tt) {
                    let jt = cost(&ft, &sigma2);
                    if jt <= j {
                        s = trial;
                        tracks = tt;
                        f = ft;
                        let gain = j - jt;
                        j = jt;
                        // Converged when the step is tiny against the parameters' own uncertainty.
                        let inv = chol.inverse();
                        let rel = (0..m)
                            .map(|i| (lambda * step[i]).abs() / inv[(i, i)].sqrt().max(1e-300))
                            .fold(0.0, f64::max);
                        if rel < 1e-3 || gain <= 1e-10 * j.max(1.0) {
                            return Ok((s, tracks, f));
                        }
                        break;
                    }
                }
                lambda *= 0.5;
                if lambda < 0.5f64.powi(11) {
                    // No descent along the Gauss–Newton direction: at the minimum to rounding.
                    return Ok((s, tracks, f));
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
    fn refuse_mislabelled(
        &self,
        s: &[[f64; 3]],
        nominal: &[[f64; 3]],
        tracks: &[Track],
        f: &Fit,
    ) -> Result<(), EstimateError> {
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
        for (r, (&i, p)) in self.conic.iter().zip(s).enumerate() {
            let n = nominal[r];
            let limit = [2.0, 0.05 * n[1].abs().max(1.0), 30.0];
            if let Some(k) = (0..3).find(|&k| (p[k] - n[k]).abs() > limit[k] || !p[k].is_finite()) {
                let what = ["cone angle", "rate", "phase"][k];
                return Err(EstimateError::NotConverged(format!(
                    "run '{}': the estimated {what} {:.4} is implausibly far from its label {} (limit ±{}); check the run's label (cone angle, rate and direction)",
                    self.session.runs[i].spec.name, p[k], n[k], limit[k]
                )));
            }
        }
        Ok(())
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

/// Fits the model with every conic run's α, ω_s and φ free. Fails with
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
    let nominal: Vec<[f64; 3]> = conic.iter().filter_map(|&i| conic_of(&session.runs[i].spec.motion)).collect();
    let problem = StandProblem { model, session, conic, deriv, opts };
    let (s, tracks, mut f) = problem.gauss_newton(nominal.clone())?;
    problem.refuse_mislabelled(&s, &nominal, &tracks, &f)?;
    // Final linearisation at the optimum for the covariance, weighted by the final noise.
    let mut sigma2 = [1.0; 6];
    reweight(&f, &mut sigma2);
    let (info, _, gains) = problem.linearise(&s, &tracks, &f, &sigma2)?;
    let cov_s = info.clone().try_inverse().ok_or_else(|| {
        EstimateError::NotConverged("the stand parameters' information matrix is singular at the optimum".into())
    })?;
    add_stand_covariance(&mut f, &gains, &cov_s);
    f.stand = problem
        .conic
        .iter()
        .enumerate()
        .map(|(r, &i)| StandParams {
            run: session.runs[i].spec.name.clone(),
            nominal: nominal[r].into(),
            value: s[r].into(),
            std_error: ConeSetting::from(std::array::from_fn(|k| cov_s[(3 * r + k, 3 * r + k)].max(0.0).sqrt())),
        })
        .collect();
    Ok(f)
}

type Linearised = (DMatrix<f64>, DVector<f64>, Vec<Option<DMatrix<f64>>>);

/// The projected normal equations of the stand step and, per channel, G = R₁₁⁻¹R₁₂.
#[allow(clippy::too_many_arguments)]
fn linearise(
    model: &Model,
    session: &Session,
    conic: &[usize],
    s: &[[f64; 3]],
    tracks: &[Track],
    f: &Fit,
    sigma2: &[f64; 6],
    deriv: &DerivativeConfig,
    opts: &FitOptions,
) -> Result<Linearised, EstimateError> {
    let g = session.manifest.g_m_s2;
    let m = 3 * conic.len();
    let pred = Predictor::new(model, f);
    // Fitted columns of each channel, in covariance order.
    let mut fitted: Vec<Vec<usize>> = Vec::with_capacity(6);
    for sk in SensorKind::BOTH {
        let sf = f.sensor(sk);
        for c in 0..3 {
            fitted.push(
                sf.coefficients
                    .iter()
                    .enumerate()
                    .filter(|(_, k)| k.channel == c && k.status == CoefStatus::Fitted)
                    .map(|(i, _)| i)
                    .collect(),
            );
        }
    }
    let mut accs: Vec<QrAccumulator> =
        (0..6).map(|c| QrAccumulator::new(fitted[c].len() + m + 1, opts.chunk)).collect();
    let mut rows: Vec<Vec<f64>> = (0..6).map(|c| vec![0.0; fitted[c].len() + m + 1]).collect();
    let runs = crate::estimate::fit_runs(session, tracks);
    let mut ci = 0usize;
    for (ri, run) in runs.iter().enumerate() {
        let rs = session.runs[ri].spec.motion.clone();
        // Perturbed tracks for this run's three parameters (central differences).
        let pert: Option<Vec<(Track, Track)>> = conic_of(&rs).map(|_| {
            (0..3)
                .map(|k| {
                    let mut hi = s[ci];
                    let mut lo = s[ci];
                    hi[k] += STEP[k];
                    lo[k] -= STEP[k];
                    let r = &session.runs[ri];
                    (
                        track_for(&motion(hi), &r.spec.mount, &r.rec, g, deriv),
                        track_for(&motion(lo), &r.spec.mount, &r.rec, g, deriv),
                    )
                })
                .collect()
        });
        for k in 0..run.len() {
            let st = run.state(k);
            let y = [run.gyro[k], run.accel[k]];
            let p0 = pred.predict(&st);
            let mut d = [[0.0f64; 6]; 3];
            if let Some(pt) = &pert {
                for (j, (hi, lo)) in pt.iter().enumerate() {
                    let at = |tr: &Track| {
                        let x = tr.at(k);
                        crate::model::State {
                            t_session_s: st.t_session_s,
                            w: x.w_rad_s.xyz,
                            e: x.e_rad_s2.xyz,
                            a: x.a_m_s2.xyz,
                            temp_c: st.temp_c,
                            temp_rate_c_s: st.temp_rate_c_s,
                        }
                    };
                    let (ph, pl) = (pred.predict(&at(hi)), pred.predict(&at(lo)));
                    for c in 0..6 {
                        d[j][c] = (ph[c] - pl[c]) / (2.0 * STEP[j]);
                    }
                }
            }
            for c in 0..6 {
                let (sk, ch) = (c / 3, c % 3);
                let terms = &pred.terms[sk];
                let row = &mut rows[c];
                row.fill(0.0);
                let q = fitted[c].len();
                for (a, &ti) in fitted[c].iter().enumerate() {
                    row[a] = terms[ti].regressor(&st);
                }
                if pert.is_some() {
                    for j in 0..3 {
                        row[q + 3 * ci + j] = d[j][c];
                    }
                }
                row[q + m] = y[sk][ch] - p0[c];
                accs[c].push(row);
            }
        }
        if pert.is_some() {
            ci += 1;
        }
    }
    let mut info = DMatrix::<f64>::zeros(m, m);
    let mut rhs = DVector::<f64>::zeros(m);
    let mut gains = Vec::with_capacity(6);
    for c in 0..6 {
        let q = fitted[c].len();
        let r = accs[c].r();
        let w = 1.0 / sigma2[c];
        let r22 = DMatrix::from_fn(m, m, |i, j| if i < r.nrows().saturating_sub(q) { r[(q + i, q + j)] } else { 0.0 });
        let r23 = DVector::from_fn(m, |i, _| if i < r.nrows().saturating_sub(q) { r[(q + i, q + m)] } else { 0.0 });
        info += r22.transpose() * &r22 * w;
        rhs += r22.transpose() * &r23 * w;
        let r11 = DMatrix::from_fn(q, q, |i, j| r[(i, j)]);
        let r12 = DMatrix::from_fn(q, m, |i, j| r[(i, q + j)]);
        gains.push(r11.solve_upper_triangular(&r12));
    }
    Ok((info, rhs, gains))
}
