//! Least squares from Gram matrices: column-scaled symmetric eigen-solves with a rank
//! threshold, so that coefficients the runs cannot identify get no weight instead of
//! exploding (a pseudo-inverse in the scaled metric).

use nalgebra::{DMatrix, DVector};

/// Relative eigenvalue below which a scaled direction counts as unidentified.
pub const RCOND: f64 = 1e-10;

/// Solves A X = B for symmetric positive semi-definite A (pseudo-inverse in the metric of
/// A's diagonal).
pub fn solve_sym(a: &DMatrix<f64>, b: &DMatrix<f64>) -> DMatrix<f64> {
    let (pinv, _) = pinv_sym(a);
    &pinv * b
}

/// The scaled pseudo-inverse of a symmetric PSD matrix and its numerical rank.
pub fn pinv_sym(a: &DMatrix<f64>) -> (DMatrix<f64>, usize) {
    let n = a.nrows();
    if n == 0 {
        return (DMatrix::zeros(0, 0), 0);
    }
    let d: Vec<f64> =
        (0..n).map(|i| if a[(i, i)] > 0.0 && a[(i, i)].is_finite() { 1.0 / a[(i, i)].sqrt() } else { 0.0 }).collect();
    let mut s = a.clone();
    for i in 0..n {
        for j in 0..n {
            s[(i, j)] *= d[i] * d[j];
        }
    }
    if s.iter().any(|v| !v.is_finite()) {
        return (DMatrix::zeros(n, n), 0);
    }
    let eig = s.symmetric_eigen();
    let top = eig.eigenvalues.iter().copied().fold(0.0, f64::max);
    // S⁺ = V Λ⁺ Vᵀ over the eigenvalues kept: V's columns scaled by 1/λ (0 for those
    // dropped), times Vᵀ, one matrix product.
    let mut scaled = eig.eigenvectors.clone();
    let mut rank = 0;
    for (k, &l) in eig.eigenvalues.iter().enumerate() {
        if top > 0.0 && l > RCOND * top {
            rank += 1;
            scaled.column_mut(k).scale_mut(1.0 / l);
        } else {
            scaled.column_mut(k).fill(0.0);
        }
    }
    let mut inv = scaled * eig.eigenvectors.transpose();
    for i in 0..n {
        for j in 0..n {
            inv[(i, j)] *= d[i] * d[j];
        }
    }
    (inv, rank)
}

/// The solution of A β = b for symmetric A when [`pinv_sym`] would keep every direction
/// of it (None otherwise: the caller takes the pseudo-inverse), by a Cholesky factor
/// S = LLᵀ of A scaled to a unit diagonal, at a fifth of an eigen-decomposition's cost.
/// Every direction is kept when λ_min(S) > RCOND·λ_max(S); with λ_max(S) ≤ tr S = n and
/// λ_min(S) = 1/‖S⁻¹‖₂ ≥ 1/‖L⁻¹‖²_F, it is enough that n·‖L⁻¹‖²_F < 1/RCOND, with a
/// thousandfold margin for the rounding of the eigenvalues the pseudo-inverse would see.
pub fn solve_full_rank(a: &DMatrix<f64>, b: &DVector<f64>) -> Option<DVector<f64>> {
    let n = a.nrows();
    if n == 0 || !(0..n).all(|i| a[(i, i)] > 0.0 && a[(i, i)].is_finite()) {
        return None;
    }
    let d: Vec<f64> = (0..n).map(|i| 1.0 / a[(i, i)].sqrt()).collect();
    let s = DMatrix::from_fn(n, n, |i, j| a[(i, j)] * d[i] * d[j]);
    if s.iter().any(|v| !v.is_finite()) {
        return None;
    }
    let chol = nalgebra::linalg::Cholesky::new(s)?;
    let l_inv = chol.l().solve_lower_triangular(&DMatrix::identity(n, n))?;
    // (NaN fails the test too.)
    let bound = n as f64 * l_inv.norm_squared();
    if bound.is_nan() || bound >= 1e-3 / RCOND {
        return None;
    }
    let y = chol.solve(&DVector::from_fn(n, |i, _| b[i] * d[i]));
    Some(DVector::from_fn(n, |i, _| y[i] * d[i]))
}

/// The information on parameter `p` of the Gram matrix `g` that is left after projecting
/// out every other column (the Schur complement g_pp − g_p,r g_rr⁺ g_r,p, at least 0):
/// zero when another combination of columns moves the outputs exactly as `p` does.
pub fn left_information(g: &DMatrix<f64>, p: usize) -> f64 {
    let n = g.nrows();
    if p >= n {
        return 0.0;
    }
    let rest: Vec<usize> = (0..n).filter(|&i| i != p).collect();
    let grr = g.select_rows(&rest).select_columns(&rest);
    let grp = DVector::from_fn(rest.len(), |i, _| g[(rest[i], p)]);
    let (pinv, _) = pinv_sym(&grr);
    (g[(p, p)] - grp.dot(&(&pinv * &grp))).max(0.0)
}

/// The Wald statistic vᵀ C⁻¹ v of the values `v` of parameters `idx` whose joint
/// covariance is the block of `cov` on them (pseudo-inverse: a direction without
/// information adds nothing). Under v = 0 it is χ² with as many degrees of freedom as
/// the block's rank.
pub fn wald(cov: &DMatrix<f64>, idx: &[usize], v: &DVector<f64>) -> (f64, usize) {
    let block = DMatrix::from_fn(idx.len(), idx.len(), |i, j| cov[(idx[i], idx[j])]);
    let (inv, rank) = pinv_sym(&block);
    (v.dot(&(&inv * v)).max(0.0), rank)
}

/// A least-squares solution on a subset of the columns of a Gram system.
#[derive(Debug, Clone)]
pub struct Lsq {
    /// The subset (global indices).
    pub set: Vec<usize>,
    /// Coefficients on the subset.
    pub beta: DVector<f64>,
    /// Residual sum of squares yᵀy − bᵀβ (whitened: χ² units).
    pub q: f64,
    /// Numerical rank.
    pub rank: usize,
}

impl Lsq {
    /// Solves G_SS β = b_S on the subset `set` of the system (G, b, yᵀy).
    pub fn solve(g: &DMatrix<f64>, b: &DVector<f64>, yy: f64, set: &[usize]) -> Self {
        let gs = DMatrix::from_fn(set.len(), set.len(), |i, j| g[(set[i], set[j])]);
        let bs = DVector::from_fn(set.len(), |i, _| b[set[i]]);
        let (beta, rank) = solve_full_rank(&gs, &bs).map_or_else(
            || {
                let (pinv, rank) = pinv_sym(&gs);
                (&pinv * &bs, rank)
            },
            |beta| (beta, set.len()),
        );
        let q = yy - bs.dot(&beta);
        Self { set: set.to_vec(), beta, q, rank }
    }

    /// χ² of data (G, b, yᵀy) around this solution: yᵀy − 2βᵀb + βᵀGβ.
    pub fn q_on(&self, g: &DMatrix<f64>, b: &DVector<f64>, yy: f64) -> f64 {
        let mut q = yy;
        for (i, &gi) in self.set.iter().enumerate() {
            q -= 2.0 * self.beta[i] * b[gi];
            for (j, &gj) in self.set.iter().enumerate() {
                q += self.beta[i] * g[(gi, gj)] * self.beta[j];
            }
        }
        q
    }

    /// The coefficient of global parameter `p` (0 when not in the subset).
    pub fn value(&self, p: usize) -> f64 {
        self.set.iter().position(|&s| s == p).map_or(0.0, |i| self.beta[i])
    }
}

/// The part of an estimate `c` (covariance `cov`) that stands out of its own noise: in the
/// eigenbasis of `cov`, a component a_k of variance λ_k is kept only when a_k² > `z2`·λ_k,
/// and then shrunk to √(a_k² − λ_k) (an unbiased square). A curve fitted under strongly
/// coloured noise carries large, insignificant low-order terms; its size is that of what
/// survives, not of the noise.
pub fn significant_part(c: &DVector<f64>, cov: &DMatrix<f64>, z2: f64) -> DVector<f64> {
    if c.is_empty() || cov.iter().any(|v| !v.is_finite()) {
        return c.clone();
    }
    let eig = cov.clone().symmetric_eigen();
    let mut out = DVector::<f64>::zeros(c.len());
    for (k, &l) in eig.eigenvalues.iter().enumerate() {
        let v = eig.eigenvectors.column(k);
        let a = v.dot(c);
        let l = l.max(0.0);
        if a * a > z2 * l {
            out += v * (a.signum() * (a * a - l).sqrt());
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A Gram matrix of `n` columns over 200 rows, the last one `last` times the first plus
    /// a share `apart` of its own (0: exactly collinear).
    fn gram(n: usize, apart: f64) -> DMatrix<f64> {
        let x = DMatrix::from_fn(200, n, |i, j| {
            let own = ((i * (j + 2)) as f64 * 0.173).sin() * 10f64.powi(j as i32 % 4 - 2);
            if j + 1 == n {
                3.0 * ((i * 2) as f64 * 0.173).sin() * 0.01 + apart * own
            } else {
                own
            }
        });
        x.transpose() * x
    }

    #[test]
    fn a_full_rank_solve_is_the_pseudo_inverses_and_a_deficient_one_is_left_to_it() {
        let b = DVector::from_fn(6, |i, _| (i as f64 * 0.7).cos());
        // Well conditioned (columns of very different scales): the Cholesky solution is the
        // pseudo-inverse's to rounding.
        let g = gram(6, 1.0);
        let fast = solve_full_rank(&g, &b).expect("full rank");
        let (pinv, rank) = pinv_sym(&g);
        assert_eq!(rank, 6);
        let slow = &pinv * &b;
        assert!((&fast - &slow).norm() <= 1e-9 * slow.norm(), "{fast} {slow}");
        // Collinear, or so nearly that the pseudo-inverse drops a direction: no answer, and
        // Lsq takes the pseudo-inverse's with its rank.
        for apart in [0.0, 1e-9] {
            let g = gram(6, apart);
            assert!(solve_full_rank(&g, &b).is_none(), "apart {apart}");
            let all: Vec<usize> = (0..6).collect();
            let l = Lsq::solve(&g, &b, 1.0, &all);
            let (pinv, rank) = pinv_sym(&g);
            assert_eq!((l.rank, rank), (5, 5), "apart {apart}");
            assert!((&l.beta - &pinv * &b).norm() <= 1e-12 * l.beta.norm().max(1.0));
        }
        // A zero column: no answer either.
        let mut g = gram(6, 1.0);
        g.row_mut(2).fill(0.0);
        g.column_mut(2).fill(0.0);
        assert!(solve_full_rank(&g, &b).is_none());
    }
}
