//! Accumulating a Gram matrix XᵀX from blocks of rows.

use super::ArModel;
use nalgebra::DMatrix;

/// `gram += alpha·Wᵀ·W` for the first `rows` rows of the column-major `block` (W = those
/// rows), Wᵀ copied into `wt` (m × at least `rows`, reused between blocks: no allocation
/// per block). One packed matrix product (nalgebra's `gemm`, which hands dynamic matrices
/// to `matrixmultiply`): `gemm_tr`, its naive counterpart, takes a dot product per element
/// and was the largest single cost of `diagnose` at scale.
pub fn add_block_scaled(gram: &mut DMatrix<f64>, block: &DMatrix<f64>, rows: usize, alpha: f64, wt: &mut DMatrix<f64>) {
    let (ld, m) = block.shape();
    let rows = rows.min(ld).min(wt.ncols());
    if rows == 0 || m == 0 {
        return;
    }
    let w = block.rows(0, rows);
    for j in 0..m {
        for (i, v) in w.column(j).iter().enumerate() {
            wt[(j, i)] = *v;
        }
    }
    gram.gemm(alpha, &wt.columns(0, rows), &w, 1.0);
}

/// The Gram of prewhitened columns, filled a block of samples at a time: the caller writes
/// each column's values for the block ([`Self::column`]), then [`Self::commit`] whitens
/// them with the AR filter — x_i − Σ φ_l x_{i−l}, scaled to unit innovation variance,
/// the last p samples of the previous block as history — and adds the block's Gram. The
/// first p samples of the series (no history) are left out.
pub struct WhitenedGram {
    phi: Vec<f64>,
    scale: f64,
    /// (p + block) × m: p rows of history, then the block's rows.
    raw: DMatrix<f64>,
    white: DMatrix<f64>,
    /// The block's rows transposed, for the product.
    wt: DMatrix<f64>,
    gram: DMatrix<f64>,
    seen: usize,
}

impl WhitenedGram {
    /// `m` columns whitened by `ar`, in blocks of at most `block` samples.
    pub fn new(m: usize, ar: &ArModel, block: usize) -> Self {
        let p = ar.order();
        let scale = if ar.innovation_var > 0.0 { 1.0 / ar.innovation_var.sqrt() } else { 0.0 };
        Self {
            phi: ar.phi.clone(),
            scale,
            raw: DMatrix::zeros(p + block, m),
            white: DMatrix::zeros(if p == 0 { 0 } else { block }, m),
            wt: DMatrix::zeros(m, block),
            gram: DMatrix::zeros(m, m),
            seen: 0,
        }
    }

    /// Column `j`'s values for the next `len` samples (len ≤ the block), to be written.
    pub fn column(&mut self, j: usize, len: usize) -> &mut [f64] {
        let p = self.phi.len();
        let start = j * self.raw.nrows() + p;
        &mut self.raw.as_mut_slice()[start..start + len]
    }

    /// Whitens the `len` samples written and adds their Gram.
    pub fn commit(&mut self, len: usize) {
        let p = self.phi.len();
        if p == 0 {
            // White already: the block's Gram scaled by 1/σ², no filtered copy of the block.
            add_block_scaled(&mut self.gram, &self.raw, len, self.scale * self.scale, &mut self.wt);
            self.seen += len;
            return;
        }
        let skip = p.saturating_sub(self.seen).min(len);
        let rows = len - skip;
        for col in 0..self.raw.ncols() {
            let x = self.raw.column(col);
            let x = x.as_slice();
            let w = &mut self.white.column_mut(col);
            for i in skip..len {
                let mut v = x[p + i];
                for (l, f) in self.phi.iter().enumerate() {
                    v -= f * x[p + i - 1 - l];
                }
                w[i - skip] = v * self.scale;
            }
        }
        add_block_scaled(&mut self.gram, &self.white, rows, 1.0, &mut self.wt);
        // The last p samples (history and block together) are the next block's history.
        for col in 0..self.raw.ncols() {
            self.raw.column_mut(col).as_mut_slice().copy_within(len..len + p, 0);
        }
        self.seen += len;
    }

    /// The Gram of every whitened sample.
    pub fn finish(self) -> DMatrix<f64> {
        self.gram
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn whitened_gram_equals_the_gram_of_the_whole_filtered_series() {
        let x = |i: usize, j: usize| ((i * (j + 3)) as f64 * 0.013).sin() + j as f64 * 0.1;
        let n = 1000;
        for phi in [vec![0.6, -0.2], vec![]] {
            let p = phi.len();
            let ar = ArModel { phi: phi.clone(), innovation_var: 4.0, marginal_var: 9.0 };
            let mut g = WhitenedGram::new(3, &ar, 128);
            let mut k0 = 0;
            while k0 < n {
                let len = (n - k0).min(if k0 == 0 { 1 } else { 128 });
                for j in 0..3 {
                    for (i, v) in g.column(j, len).iter_mut().enumerate() {
                        *v = x(k0 + i, j);
                    }
                }
                g.commit(len);
                k0 += len;
            }
            let w = DMatrix::from_fn(n - p, 3, |i, j| {
                let k = i + p;
                (x(k, j) - phi.iter().enumerate().map(|(l, f)| f * x(k - 1 - l, j)).sum::<f64>()) / 2.0
            });
            let want = w.transpose() * &w;
            assert!((g.finish() - &want).abs().max() < 1e-9 * want.abs().max());
        }
    }

    #[test]
    fn equals_the_plain_product_of_the_leading_rows() {
        for (ld, m, rows) in [(40, 9, 33), (256, 30, 256), (256, 31, 200), (259, 40, 3)] {
            let block = DMatrix::from_fn(ld, m, |i, j| ((i * 7 + j * 3) % 11) as f64 - 5.0 + 0.1 * j as f64);
            let mut gram = DMatrix::from_element(m, m, 1.0);
            add_block_scaled(&mut gram, &block, rows, 1.0, &mut DMatrix::zeros(m, rows));
            let w = block.rows(0, rows);
            let want = w.transpose() * w + DMatrix::from_element(m, m, 1.0);
            assert!((gram - want).abs().max() < 1e-9);
        }
    }
}
