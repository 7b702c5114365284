//! Accumulating a Gram matrix XᵀX from blocks of rows.

use nalgebra::DMatrix;

/// `gram += Wᵀ·W` for the first `rows` rows of the column-major `block` (W = those rows).
///
/// One packed matrix product (nalgebra's `gemm`, which hands dynamic matrices to
/// `matrixmultiply`) with a transposed copy of the rows: `gemm_tr`, its naive counterpart,
/// takes a dot product per element and was the largest single cost of `diagnose` at scale.
pub fn add_block(gram: &mut DMatrix<f64>, block: &DMatrix<f64>, rows: usize) {
    let (ld, m) = block.shape();
    let rows = rows.min(ld);
    if rows == 0 || m == 0 {
        return;
    }
    let w = block.rows(0, rows);
    let wt = w.transpose();
    gram.gemm(1.0, &wt, &w, 1.0);
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn equals_the_plain_product_of_the_leading_rows() {
        for (ld, m, rows) in [(40, 9, 33), (256, 30, 256), (256, 31, 200), (259, 40, 3)] {
            let block = DMatrix::from_fn(ld, m, |i, j| ((i * 7 + j * 3) % 11) as f64 - 5.0 + 0.1 * j as f64);
            let mut gram = DMatrix::from_element(m, m, 1.0);
            add_block(&mut gram, &block, rows);
            let w = block.rows(0, rows);
            let want = w.transpose() * w + DMatrix::from_element(m, m, 1.0);
            assert!((gram - want).abs().max() < 1e-9);
        }
    }
}
