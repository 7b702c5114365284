//! One Gauss–Newton linearisation of the stand problem: the projected normal equations of
//! the stand parameters (module docs of [`super`]) and, per channel, the gain G = R₁₁⁻¹R₁₂
//! of the coefficients on them.

use super::{Predictor, StandProblem, COMMON, COMMON_STEP, EARTH, POSE_STEP, RUN, RUN_STEP};
use crate::estimate::{CoefStatus, EstimateError, Fit};
use crate::model::State;
use crate::motion::stand::StandAt;
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

/// How one parameter moves a run's motion, for its central difference.
// A few per run, built once: the size difference between the variants does not matter.
#[allow(clippy::large_enum_variant)]
enum Move {
    /// A conic run's stand motion above and below (prepared once for the run's samples).
    Stand(StandAt, StandAt),
    /// A rate added along a direction (sensor axes) on a static pose.
    Rate([f64; 3]),
}

impl StandProblem<'_> {
    /// The parameters that move run `ri` as (global index, step, how): a conic run's own
    /// four and the common ones; a static pose's vertical and horizontal Earth rate.
    fn perturbed(&self, x: &[f64], ri: usize) -> Vec<(usize, f64, Move)> {
        let c0 = self.common();
        if let Some(ci) = self.conic.iter().position(|&i| i == ri) {
            let own = (0..RUN).map(|k| (RUN * ci + k, RUN_STEP[k]));
            let common = (0..COMMON).map(|k| (c0 + k, COMMON_STEP[k]));
            return own
                .chain(common)
                .map(|(p, h)| {
                    let (mut hi, mut lo) = (x.to_vec(), x.to_vec());
                    hi[p] += h;
                    lo[p] -= h;
                    let g = self.g_m_s2;
                    (p, h, Move::Stand(self.stand_of(&hi, ci).fixed(g), self.stand_of(&lo, ci).fixed(g)))
                })
                .collect();
        }
        match self.poses.iter().position(|p| p.run == ri) {
            Some(pi) => {
                let pose = &self.poses[pi];
                let h0 = c0 + COMMON + 2 * pi;
                vec![
                    (c0 + EARTH + 2, POSE_STEP, Move::Rate(pose.up)),
                    (h0, POSE_STEP, Move::Rate(pose.horizontal[0])),
                    (h0 + 1, POSE_STEP, Move::Rate(pose.horizontal[1])),
                ]
            }
            None => Vec::new(),
        }
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
            let pert = self.perturbed(x, ri);
            d.resize(pert.len(), [0.0; 6]);
            for k in 0..run.len() {
                let st = run.state(k);
                let y = [run.gyro[k], run.accel[k]];
                let p0 = pred.predict(&st);
                for (j, (_, h, how)) in pert.iter().enumerate() {
                    let at = |sm: &StandAt| {
                        let s = self.state_at(ri, sm, k);
                        State { w: s.w_rad_s.xyz, e: s.e_rad_s2.xyz, a: s.a_m_s2.xyz, ..st }
                    };
                    let turned = |sign: f64, v: &[f64; 3]| {
                        let mut s = st;
                        for i in 0..3 {
                            s.w[i] += sign * h * v[i];
                        }
                        s
                    };
                    let (sh, sl) = match how {
                        Move::Stand(hi, lo) => (at(hi), at(lo)),
                        Move::Rate(v) => (turned(1.0, v), turned(-1.0, v)),
                    };
                    let (ph, pl) = (pred.predict(&sh), pred.predict(&sl));
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
