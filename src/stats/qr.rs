//! Streaming least squares: the R factor of a tall matrix accumulated block by block.
//!
//! Rows are buffered in chunks; each full chunk is folded into the current R by Householder
//! reflectors that respect R's triangle (see [`QrAccumulator`]'s flush), so memory is
//! O(p · chunk) whatever the number of rows, and no normal equations are formed (the
//! condition number is not squared).
//! Because `RᵀR = XᵀX` and R = QᵀX with Q orthonormal, any least-squares problem on a
//! subset (or linear combination) of X's columns can be solved from R alone.

use faer::Mat;

/// Rows accumulated into an upper-triangular R (p × p).
pub struct QrAccumulator {
    p: usize,
    chunk: usize,
    /// R (first p rows, upper triangular) over the rows not yet folded in.
    buf: Mat<f64>,
    /// The current Householder vector (below its leading 1).
    v: Vec<f64>,
    filled: usize,
    rows: u64,
    col_sq: Vec<f64>,
}

impl std::fmt::Debug for QrAccumulator {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("QrAccumulator")
            .field("p", &self.p)
            .field("chunk", &self.chunk)
            .field("rows", &self.rows)
            .finish()
    }
}

impl Clone for QrAccumulator {
    fn clone(&self) -> Self {
        let mut c = Self::new(self.p, self.chunk);
        c.buf.copy_from(&self.buf);
        c.filled = self.filled;
        c.rows = self.rows;
        c.col_sq.clone_from(&self.col_sq);
        c
    }
}

impl QrAccumulator {
    /// Accumulator for rows of width `p`, re-factoring every `chunk` rows.
    pub fn new(p: usize, chunk: usize) -> Self {
        // The problems solved from R are small (tens of columns): faer's thread pool would only
        // add wake-up latency, and crosscal parallelises across units and runs instead.
        faer::set_global_parallelism(faer::Par::Seq);
        let chunk = chunk.max(p).max(1);
        Self { p, chunk, buf: Mat::zeros(p + chunk, p), v: vec![0.0; chunk], filled: 0, rows: 0, col_sq: vec![0.0; p] }
    }

    /// Row width.
    pub fn width(&self) -> usize {
        self.p
    }

    /// Rows pushed so far.
    pub fn rows(&self) -> u64 {
        self.rows
    }

    /// Adds one row (length must equal the width).
    #[inline]
    pub fn push(&mut self, row: &[f64]) {
        debug_assert_eq!(row.len(), self.p);
        // One row is p columns of one value each.
        self.push_columns(row, 1, 1);
    }

    /// Adds `n` rows given by columns: column j is `cols[j·stride..][..n]` (p columns).
    pub fn push_columns(&mut self, cols: &[f64], stride: usize, n: usize) {
        let mut i0 = 0;
        while i0 < n {
            let take = (self.chunk - self.filled).min(n - i0);
            let r0 = self.p + self.filled;
            for j in 0..self.p {
                let src = &cols[j * stride + i0..j * stride + i0 + take];
                let mut sq = self.col_sq[j];
                for (d, v) in self.buf.col_as_slice_mut(j)[r0..r0 + take].iter_mut().zip(src) {
                    *d = *v;
                    sq += v * v;
                }
                self.col_sq[j] = sq;
            }
            self.filled += take;
            self.rows += take as u64;
            i0 += take;
            if self.filled == self.chunk {
                self.flush();
            }
        }
    }

    /// Folds the buffered rows X into R: `[R; X] = Q [R'; 0]`, one Householder reflector
    /// per column acting on R's diagonal element and X's column only — R is already upper
    /// triangular, so nothing else changes (the structured update of LAPACK's `dtpqrt2`;
    /// Golub & Van Loan, Matrix Computations, §5.2 and §6.5.3). 2·m·p² flops for m rows.
    fn flush(&mut self) {
        let (p, m) = (self.p, self.filled);
        if m == 0 {
            return;
        }
        for j in 0..p {
            let col = self.buf.col_as_slice_mut(j);
            let alpha = col[j];
            let x = &mut col[p..p + m];
            let x_sq = super::dot(x, x);
            if x_sq == 0.0 {
                continue;
            }
            // β = −sign(α)‖(α, x)‖ (no cancellation in α − β); v = (1, x/(α − β)); τ = (β − α)/β.
            let norm = alpha.hypot(x_sq.sqrt());
            let beta = if alpha >= 0.0 { -norm } else { norm };
            let tau = (beta - alpha) / beta;
            let scale = 1.0 / (alpha - beta);
            for v in x.iter_mut() {
                *v *= scale;
            }
            col[j] = beta;
            self.v[..m].copy_from_slice(&col[p..p + m]);
            let v = &self.v[..m];
            for k in j + 1..p {
                let ck = self.buf.col_as_slice_mut(k);
                let tw = tau * (ck[j] + super::dot(v, &ck[p..p + m]));
                ck[j] -= tw;
                for (c, vi) in ck[p..p + m].iter_mut().zip(v) {
                    *c -= tw * vi;
                }
            }
        }
        self.filled = 0;
    }

    /// Adds everything `other` accumulated: its R factor's rows are stacked under this one
    /// (`[R₁; R₂]` has Gram matrix `X₁ᵀX₁ + X₂ᵀX₂`), its row count and column norms added.
    pub fn merge(&mut self, other: &mut QrAccumulator) {
        debug_assert_eq!(self.p, other.p);
        if other.rows == 0 {
            return;
        }
        let r = other.r();
        for i in 0..self.p {
            let row = self.p + self.filled;
            for j in 0..self.p {
                self.buf[(row, j)] = r[(i, j)];
            }
            self.filled += 1;
            if self.filled == self.chunk {
                self.flush();
            }
        }
        self.rows += other.rows;
        for (a, b) in self.col_sq.iter_mut().zip(&other.col_sq) {
            *a += b;
        }
    }

    /// The R factor so far (p × p, upper triangular; `RᵀR = XᵀX`).
    pub fn r(&mut self) -> Mat<f64> {
        self.flush();
        self.buf.as_ref().subrows(0, self.p).to_owned()
    }

    /// Euclidean norm of each column of X (for scaling), computed exactly as rows arrive.
    pub fn column_norms(&self) -> Vec<f64> {
        self.col_sq.iter().map(|s| s.sqrt()).collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn gram_matrix_is_preserved() {
        let n = 1000;
        let p = 4;
        let x: Vec<Vec<f64>> = (0..n)
            .map(|i| {
                let t = i as f64 * 0.01;
                vec![1.0, t.sin(), (3.0 * t).cos(), t * 0.1]
            })
            .collect();
        let mut acc = QrAccumulator::new(p, 64);
        for r in &x {
            acc.push(r);
        }
        let r = acc.r();
        for a in 0..p {
            for b in 0..p {
                let direct: f64 = x.iter().map(|row| row[a] * row[b]).sum();
                let via_r: f64 = (0..p).map(|k| r[(k, a)] * r[(k, b)]).sum();
                assert!((direct - via_r).abs() < 1e-9 * direct.abs().max(1.0), "{a},{b}");
            }
        }
    }
}
