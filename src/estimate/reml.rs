//! Restricted maximum likelihood of variance components (Patterson & Thompson 1971) by
//! average-information Newton steps (Gilmour, Thompson & Cullis 1995): the climb, and the
//! linear algebra of the covariance structures the slow noise uses ([`super::slow`]).
//!
//! The data y = Xβ + e, e ~ N(0, V(θ)) with V = Σ θᵢ Cᵢ. With
//! P = V⁻¹ − V⁻¹X(XᵀV⁻¹X)⁻¹XᵀV⁻¹ the restricted log-likelihood is
//! ℓ = −½(ln|V| + ln|XᵀV⁻¹X| + yᵀPy), its score ½(yᵀPCᵢPy − tr(PCᵢ)) and its average
//! information ½ (CᵢPy)ᵀ P (CⱼPy). A [`Structure`] gives those for its own V:
//! [`Dense`] for any components (a Cholesky inverse per step, cubic in the blocks), and
//! [`RunOffsets`] for white noise plus an offset drawn anew in each run (V block-diagonal,
//! each block a diagonal plus a rank-one part: Sherman–Morrison, linear in the blocks).

use nalgebra::{DMatrix, DVector};

/// The score and average information of ℓ at some θ (every component).
pub(crate) struct Step {
    score: Vec<f64>,
    info: DMatrix<f64>,
}

/// A covariance structure V(θ) = Σ θᵢ Cᵢ of block means with regressors X and data y.
pub(crate) trait Structure {
    /// |tr Cᵢ| per component: each one's share of the variance per unit of it.
    fn traces(&self) -> Vec<f64>;
    /// The score and average information at `theta`; None when V or XᵀV⁻¹X is singular.
    fn step(&self, theta: &[f64]) -> Option<Step>;
    /// ℓ at `theta` (constants dropped); None when V or XᵀV⁻¹X is not positive definite.
    fn loglik(&self, theta: &[f64]) -> Option<f64>;
}

/// One REML climb from `theta` (component 0 the white part, kept positive; the others
/// non-negative): average-information steps until no component moves by 1e-4 of itself or
/// by more than 1e-8 of the total variance (traces; a component heading for its bound).
/// None when the scores stop being finite or a matrix is singular. Returns the components
/// and ℓ there (constants dropped: comparable between models of the same block means and
/// regressors).
pub(crate) fn climb(s: &impl Structure, mut theta: Vec<f64>) -> Option<(Vec<f64>, f64)> {
    let nc = theta.len();
    // Each component's share of the variance, per unit of it: a component heading for its
    // bound (the white part towards zero when flicker takes the shortest scales) has
    // converged once its move is a negligible part of the whole.
    let traces = s.traces();
    for _ in 0..60 {
        let Step { score, info } = s.step(&theta)?;
        if score.iter().any(|v| !v.is_finite()) {
            return None;
        }
        let total: f64 = theta.iter().zip(&traces).map(|(t, c)| t * c).sum();
        // Components at zero whose score points below zero stay at zero.
        let free: Vec<usize> = (0..nc).filter(|&i| i == 0 || theta[i] > 0.0 || score[i] > 0.0).collect();
        let info = DMatrix::from_fn(free.len(), free.len(), |a, b| info[(free[a], free[b])]);
        let step = info.try_inverse()? * DVector::from_iterator(free.len(), free.iter().map(|&i| score[i]));
        let mut moved: f64 = 0.0;
        for (k, &i) in free.iter().enumerate() {
            let new = if i == 0 { (theta[i] + step[k]).max(0.1 * theta[i]) } else { (theta[i] + step[k]).max(0.0) };
            let change = (new - theta[i]).abs();
            if change * traces[i] > 1e-8 * total {
                moved = moved.max(change / (new.abs() + theta[i].abs() + 1e-300));
            }
            theta[i] = new;
        }
        if moved < 1e-4 {
            break;
        }
    }
    let ll = s.loglik(&theta)?;
    Some((theta, ll))
}

/// Any components, dense: V⁻¹ by Cholesky at each step.
pub(crate) struct Dense<'a> {
    /// The components Cᵢ.
    pub comps: &'a [DMatrix<f64>],
    /// Regressors (blocks × q).
    pub x: &'a DMatrix<f64>,
    /// Data (blocks).
    pub y: &'a DVector<f64>,
}

impl Dense<'_> {
    fn at(&self, theta: &[f64]) -> DMatrix<f64> {
        let m = self.x.nrows();
        let mut v = DMatrix::zeros(m, m);
        for (c, t) in self.comps.iter().zip(theta) {
            v.zip_apply(c, |o, ci| *o += ci * *t);
        }
        v
    }
}

impl Structure for Dense<'_> {
    fn traces(&self) -> Vec<f64> {
        self.comps.iter().map(|c| c.trace().abs()).collect()
    }

    fn step(&self, theta: &[f64]) -> Option<Step> {
        let (vinv, _) = spd_inverse(self.at(theta))?;
        let vx = &vinv * self.x;
        let xvx = (self.x.transpose() * &vx).try_inverse()?;
        let p = &vinv - &vx * xvx * vx.transpose();
        let py = &p * self.y;
        // Only products with P y, so no m³ product per component.
        let u: Vec<DVector<f64>> = self.comps.iter().map(|c| c * &py).collect();
        let pu: Vec<DVector<f64>> = u.iter().map(|v| &p * v).collect();
        // tr(P Cᵢ) element by element, in the order of Σ over P ∘ Cᵢ.
        let trace = |c: &DMatrix<f64>| p.iter().zip(c.iter()).fold(0.0, |acc, (a, b)| acc + a * b);
        let score = self.comps.iter().zip(&u).map(|(c, ui)| 0.5 * (py.dot(ui) - trace(c))).collect();
        let nc = self.comps.len();
        let info = DMatrix::from_fn(nc, nc, |a, b| 0.5 * u[a].dot(&pu[b]));
        Some(Step { score, info })
    }

    fn loglik(&self, theta: &[f64]) -> Option<f64> {
        let (vinv, ln_det_v) = spd_inverse(self.at(theta))?;
        let vx = &vinv * self.x;
        let xvx = (self.x.transpose() * &vx).cholesky()?;
        let ln_det_xvx = 2.0 * xvx.l().diagonal().iter().map(|d| d.ln()).sum::<f64>();
        let vy = &vinv * self.y;
        let xvy = self.x.transpose() * &vy;
        let ypy = self.y.dot(&vy) - xvy.dot(&xvx.solve(&xvy));
        Some(-0.5 * (ln_det_v + ln_det_xvx + ypy))
    }
}

/// White noise of block means plus an offset drawn anew in each run:
/// V = θ₀ diag(w) + θ₁ J with J_ab = 1 when blocks a and b come from one run. V is
/// block-diagonal; a run's block θ₀D + θ₁11ᵀ has the inverse diag(d) − c·d dᵀ with
/// d_b = 1/(θ₀ w_b), c = θ₁/(1 + θ₁ Σd) and the determinant Π(θ₀ w_b)·(1 + θ₁ Σd)
/// (Sherman–Morrison), so every product with V⁻¹ is linear in the blocks.
pub(crate) struct RunOffsets<'a> {
    /// The white component's diagonal w_b.
    pub white: &'a [f64],
    /// Each block's run.
    pub run: &'a [usize],
    /// Regressors (blocks × q).
    pub x: &'a DMatrix<f64>,
    /// Data (blocks).
    pub y: &'a DVector<f64>,
}

/// [`RunOffsets`]'s V⁻¹ at one θ: per block d_b, per run c and Σd.
struct Offsets {
    d: Vec<f64>,
    c: Vec<f64>,
    sum_d: Vec<f64>,
}

impl RunOffsets<'_> {
    fn runs(&self) -> usize {
        self.run.iter().copied().max().map_or(0, |r| r + 1)
    }

    fn offsets(&self, theta: &[f64]) -> Option<Offsets> {
        let (t0, t1) = (theta[0], theta[1]);
        let d: Vec<f64> = self.white.iter().map(|w| 1.0 / (t0 * w)).collect();
        if t0.is_nan() || t0 <= 0.0 || d.iter().any(|v| !v.is_finite()) {
            return None;
        }
        let mut sum_d = vec![0.0; self.runs()];
        for (db, &r) in d.iter().zip(self.run) {
            sum_d[r] += db;
        }
        let c = sum_d.iter().map(|s| t1 / (1.0 + t1 * s)).collect();
        Some(Offsets { d, c, sum_d })
    }

    /// V⁻¹v.
    fn solve(&self, o: &Offsets, v: &[f64]) -> DVector<f64> {
        let mut per_run = vec![0.0; o.c.len()];
        for ((db, vb), &r) in o.d.iter().zip(v).zip(self.run) {
            per_run[r] += db * vb;
        }
        DVector::from_iterator(
            v.len(),
            (0..v.len()).map(|b| o.d[b] * v[b] - o.c[self.run[b]] * o.d[b] * per_run[self.run[b]]),
        )
    }

    /// V⁻¹X and (XᵀV⁻¹X)⁻¹'s Cholesky factor.
    fn projected(&self, o: &Offsets) -> Option<(DMatrix<f64>, nalgebra::Cholesky<f64, nalgebra::Dyn>)> {
        let (m, q) = self.x.shape();
        let mut z = DMatrix::zeros(m, q);
        for j in 0..q {
            z.set_column(j, &self.solve(o, self.x.column(j).as_slice()));
        }
        let xvx = (self.x.transpose() * &z).cholesky()?;
        Some((z, xvx))
    }

    /// Jv: each block gets the sum of its run's.
    fn runs_sum(&self, v: &DVector<f64>) -> DVector<f64> {
        let mut per_run = vec![0.0; self.runs()];
        for (vb, &r) in v.iter().zip(self.run) {
            per_run[r] += vb;
        }
        DVector::from_iterator(v.len(), self.run.iter().map(|&r| per_run[r]))
    }
}

impl Structure for RunOffsets<'_> {
    fn traces(&self) -> Vec<f64> {
        vec![self.white.iter().sum::<f64>().abs(), self.white.len() as f64]
    }

    fn step(&self, theta: &[f64]) -> Option<Step> {
        let o = self.offsets(theta)?;
        let (z, xvx) = self.projected(&o)?;
        // Pv = V⁻¹v − Z (XᵀV⁻¹X)⁻¹ Zᵀv.
        let p = |v: &DVector<f64>| self.solve(&o, v.as_slice()) - &z * xvx.solve(&(z.transpose() * v));
        let py = p(self.y);
        let u = [DVector::from_iterator(py.len(), py.iter().zip(self.white).map(|(a, w)| a * w)), self.runs_sum(&py)];
        let pu: Vec<DVector<f64>> = u.iter().map(&p).collect();
        // tr(P Cᵢ) = tr(V⁻¹Cᵢ) − tr((XᵀV⁻¹X)⁻¹ ZᵀCᵢZ).
        let (q, nr) = (z.ncols(), o.c.len());
        let mut zwz = DMatrix::<f64>::zeros(q, q);
        let mut zsum = DMatrix::<f64>::zeros(q, nr);
        let mut tr_vw = 0.0;
        for (b, &r) in self.run.iter().enumerate() {
            let zb = z.row(b).transpose();
            zwz.ger(self.white[b], &zb, &zb, 1.0);
            let mut col = zsum.column_mut(r);
            col += &zb;
            tr_vw += (o.d[b] - o.c[r] * o.d[b] * o.d[b]) * self.white[b];
        }
        let tr_vj: f64 = o.sum_d.iter().zip(&o.c).map(|(s, c)| s - c * s * s).sum();
        let zjz = &zsum * zsum.transpose();
        let tr = [tr_vw - xvx.solve(&zwz).trace(), tr_vj - xvx.solve(&zjz).trace()];
        let score = (0..2).map(|i| 0.5 * (py.dot(&u[i]) - tr[i])).collect();
        let info = DMatrix::from_fn(2, 2, |a, b| 0.5 * u[a].dot(&pu[b]));
        Some(Step { score, info })
    }

    fn loglik(&self, theta: &[f64]) -> Option<f64> {
        let o = self.offsets(theta)?;
        let ln_det_v = self.white.iter().map(|w| (theta[0] * w).ln()).sum::<f64>()
            + o.sum_d.iter().map(|s| (1.0 + theta[1] * s).ln()).sum::<f64>();
        let (z, xvx) = self.projected(&o)?;
        let ln_det_xvx = 2.0 * xvx.l().diagonal().iter().map(|d| d.ln()).sum::<f64>();
        let vy = self.solve(&o, self.y.as_slice());
        let xvy = z.transpose() * self.y;
        let ypy = self.y.dot(&vy) - xvy.dot(&xvx.solve(&xvy));
        Some(-0.5 * (ln_det_v + ln_det_xvx + ypy))
    }
}

/// V⁻¹ and ln|V| of a symmetric positive-definite V from its Cholesky factor L (faer's
/// blocked factorisation and inverse: V⁻¹ = L⁻ᵀL⁻¹, ln|V| = 2 Σ ln L_ii). None when V is
/// not positive definite.
pub(crate) fn spd_inverse(v: DMatrix<f64>) -> Option<(DMatrix<f64>, f64)> {
    use faer::linalg::solvers::DenseSolveCore;
    let m = v.nrows();
    let llt = faer::MatRef::from_column_major_slice(v.as_slice(), m, m).llt(faer::Side::Lower).ok()?;
    let l = llt.L();
    let ln_det = 2.0 * (0..m).map(|i| l[(i, i)].ln()).sum::<f64>();
    let inv = llt.inverse();
    let mut out = DMatrix::<f64>::zeros(m, m);
    for j in 0..m {
        out.column_mut(j).as_mut_slice().copy_from_slice(inv.col_as_slice(j));
    }
    Some((out, ln_det))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The fast inverse agrees with nalgebra's, and its log-determinant with the factor's.
    #[test]
    fn spd_inverse_matches_the_reference() {
        let m = 37;
        let a = DMatrix::from_fn(m, m, |i, j| ((i * 7 + j * 13) % 11) as f64 - 5.0);
        let v = &a * a.transpose() + DMatrix::identity(m, m) * 3.0;
        let (fast, ln_det) = spd_inverse(v.clone()).expect("positive definite");
        let chol = v.clone().cholesky().expect("positive definite");
        let reference = chol.inverse();
        assert!((&fast - &reference).amax() <= 1e-12 * reference.amax());
        assert!((ln_det - v.determinant().ln()).abs() <= 1e-9 * ln_det.abs());
        assert!(spd_inverse(-v).is_none());
    }

    /// The run-offset structure gives the dense one's steps, likelihood and climb, on runs
    /// of unequal block counts and lengths, with a bias and a slope as regressors: at an
    /// offset variance that is zero, moderate and large.
    #[test]
    fn run_offsets_are_the_dense_structure() {
        let sizes = [7usize, 12, 5, 9];
        let run: Vec<usize> = sizes.iter().enumerate().flat_map(|(r, &n)| std::iter::repeat_n(r, n)).collect();
        let m = run.len();
        let white: Vec<f64> = (0..m).map(|b| 1.0 / (0.5 + 0.1 * ((b * 5) % 7) as f64)).collect();
        let x =
            DMatrix::from_fn(m, 2, |b, j| if j == 0 { 1.0 } else { b as f64 / m as f64 + ((b * 3) % 4) as f64 * 0.1 });
        let offsets = [0.3, -0.5, 0.8, 0.1];
        let y = DVector::from_fn(m, |b, _| offsets[run[b]] + 0.2 * ((b * 17 % 11) as f64 / 11.0 - 0.5));
        let comps = [
            DMatrix::from_fn(m, m, |a, b| if a == b { white[a] } else { 0.0 }),
            DMatrix::from_fn(m, m, |a, b| if run[a] == run[b] { 1.0 } else { 0.0 }),
        ];
        let dense = Dense { comps: &comps, x: &x, y: &y };
        let fast = RunOffsets { white: &white, run: &run, x: &x, y: &y };
        let close = |a: f64, b: f64| (a - b).abs() <= 1e-10 * a.abs().max(b.abs()).max(1e-12);
        assert_eq!(dense.traces(), fast.traces());
        for theta in [[0.01, 0.0], [0.01, 0.05], [0.002, 3.0]] {
            let (sd, sf) = (dense.step(&theta).unwrap(), fast.step(&theta).unwrap());
            for i in 0..2 {
                assert!(close(sd.score[i], sf.score[i]), "θ {theta:?} score {i}: {} {}", sd.score[i], sf.score[i]);
                for j in 0..2 {
                    // An off-diagonal against its natural scale √(I_ii I_jj).
                    let scale = (sd.info[(i, i)] * sd.info[(j, j)]).sqrt();
                    let diff = (sd.info[(i, j)] - sf.info[(i, j)]).abs();
                    assert!(diff <= 1e-10 * scale, "θ {theta:?} info {i}{j}: {} {}", sd.info, sf.info);
                }
            }
            let (ld, lf) = (dense.loglik(&theta).unwrap(), fast.loglik(&theta).unwrap());
            assert!(close(ld, lf), "θ {theta:?} ℓ {ld} {lf}");
        }
        let (td, ld) = climb(&dense, vec![0.01, 0.0]).unwrap();
        let (tf, lf) = climb(&fast, vec![0.01, 0.0]).unwrap();
        assert!(td[1] > 0.01, "the offsets are seen: {td:?}");
        assert!(close(ld, lf) && (td[0] - tf[0]).abs() <= 1e-6 * td[0] && (td[1] - tf[1]).abs() <= 1e-6 * td[1]);
    }
}
