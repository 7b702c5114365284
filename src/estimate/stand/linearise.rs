//! One Gauss–Newton linearisation of the stand problem: the projected normal equations of
//! the stand parameters (module docs of [`super`]) and, per channel, the gain G = R₁₁⁻¹R₁₂
//! of the coefficients on them.

use super::{Predictor, StandProblem, COMMON, COMMON_STEP, RUN_STEP};
use crate::estimate::{CoefStatus, EstimateError, Fit};
use crate::model::State;
use crate::motion::stand::StandMotion;
use crate::motion::Track;
use crate::stats::QrAccumulator;
use crate::units::SensorKind;
use nalgebra::{DMatrix, DVector};

/// The linearised stand step.
pub(super) struct Linearised {
    /// M = Σ_c R₂₂ᵀR₂₂/σ_c²: the information of the stand parameters beyond the model's.
    pub info: DMatrix<f64>,
    /// Σ_c R₂₂ᵀR₂₃/σ_c².
    pub rhs: DVector<f64>,
    /// Per channel G = R₁₁⁻¹R₁₂ (None when R₁₁ is singular).
    pub gains: Vec<Option<DMatrix<f64>>>,
    /// Each parameter's own information Σ_c ‖D_c‖²/σ_c² (before any projection).
    pub raw: DVector<f64>,
}

impl StandProblem<'_> {
    /// The stand's local parameters of conic run `ci` as (global index, step, motion
    /// above, motion below): its own three, then the common ones.
    fn perturbed(&self, x: &[f64], ci: usize) -> Vec<(usize, f64, StandMotion, StandMotion)> {
        let nc = self.conic.len();
        let own = (0..3).map(|k| (3 * ci + k, RUN_STEP[k]));
        let common = (0..COMMON).map(|k| (3 * nc + k, COMMON_STEP));
        own.chain(common)
            .map(|(p, h)| {
                let (mut hi, mut lo) = (x.to_vec(), x.to_vec());
                hi[p] += h;
                lo[p] -= h;
                (p, h, self.stand_of(&hi, ci), self.stand_of(&lo, ci))
            })
            .collect()
    }

    /// The projected normal equations of the stand step at parameters `x` (tracks and fit
    /// there), channels weighted by 1/σ_c².
    pub(super) fn linearise(
        &self,
        x: &[f64],
        tracks: &[Track],
        f: &Fit,
        sigma2: &[f64; 6],
    ) -> Result<Linearised, EstimateError> {
        let m = self.width();
        let pred = Predictor::new(self.model, f);
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
            (0..6).map(|c| QrAccumulator::new(fitted[c].len() + m + 1, self.opts.chunk)).collect();
        let mut rows: Vec<Vec<f64>> = (0..6).map(|c| vec![0.0; fitted[c].len() + m + 1]).collect();
        let mut raw = DVector::<f64>::zeros(m);
        let runs = crate::estimate::fit_runs(self.session, tracks);
        let mut d: Vec<[f64; 6]> = Vec::new();
        for (ri, run) in runs.iter().enumerate() {
            let ci = self.conic.iter().position(|&i| i == ri);
            let pert = ci.map(|ci| self.perturbed(x, ci)).unwrap_or_default();
            d.resize(pert.len(), [0.0; 6]);
            for k in 0..run.len() {
                let st = run.state(k);
                let y = [run.gyro[k], run.accel[k]];
                let p0 = pred.predict(&st);
                for (j, (_, h, hi, lo)) in pert.iter().enumerate() {
                    let at = |sm: &StandMotion| {
                        let s = self.state_at(ri, sm, k);
                        State { w: s.w_rad_s.xyz, e: s.e_rad_s2.xyz, a: s.a_m_s2.xyz, ..st }
                    };
                    let (ph, pl) = (pred.predict(&at(hi)), pred.predict(&at(lo)));
                    for c in 0..6 {
                        d[j][c] = (ph[c] - pl[c]) / (2.0 * h);
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
                    for (j, (p, ..)) in pert.iter().enumerate() {
                        row[q + p] = d[j][c];
                        raw[*p] += d[j][c] * d[j][c] / sigma2[c];
                    }
                    row[q + m] = y[sk][ch] - p0[c];
                    accs[c].push(row);
                }
            }
        }
        let mut info = DMatrix::<f64>::zeros(m, m);
        let mut rhs = DVector::<f64>::zeros(m);
        let mut gains = Vec::with_capacity(6);
        for c in 0..6 {
            let q = fitted[c].len();
            let r = accs[c].r();
            let w = 1.0 / sigma2[c];
            let r22 =
                DMatrix::from_fn(m, m, |i, j| if i < r.nrows().saturating_sub(q) { r[(q + i, q + j)] } else { 0.0 });
            let r23 = DVector::from_fn(m, |i, _| if i < r.nrows().saturating_sub(q) { r[(q + i, q + m)] } else { 0.0 });
            info += r22.transpose() * &r22 * w;
            rhs += r22.transpose() * &r23 * w;
            let r11 = DMatrix::from_fn(q, q, |i, j| r[(i, j)]);
            let r12 = DMatrix::from_fn(q, m, |i, j| r[(i, q + j)]);
            gains.push(r11.solve_upper_triangular(&r12));
        }
        Ok(Linearised { info, rhs, gains, raw })
    }
}
