//! Accumulating a Gram matrix XᵀX from blocks of rows.

use super::ArModel;
use faer::linalg::matmul::triangular::{matmul, BlockStructure};
use faer::{Accum, Mat, MatRef, Par};
use nalgebra::DMatrix;

/// `gram += alpha·WᵀW` on the lower triangle of `gram` (diagonal included; the strict
/// upper triangle is left alone), for W the first `rows` rows of the column-major `block`
/// of `m = gram.ncols()` columns and leading dimension `ld`. One packed product by faer's
/// triangular matmul: Wᵀ is read as a view of W (no transposed copy) and only the lower
/// half is computed, half the flops of the full product.
pub fn add_block_lower(gram: &mut Mat<f64>, block: &[f64], ld: usize, rows: usize, alpha: f64) {
    let m = gram.ncols();
    let rows = rows.min(ld);
    if rows == 0 || m == 0 || block.len() < ld * (m - 1) + rows {
        return;
    }
    let w = MatRef::from_column_major_slice_with_stride(block, rows, m, ld);
    matmul(
        gram.as_mut(),
        BlockStructure::TriangularLower,
        Accum::Add,
        w.transpose(),
        BlockStructure::Rectangular,
        w,
        BlockStructure::Rectangular,
        alpha,
        Par::Seq,
    );
}

/// `out += alpha·AᵀB` for A and B the first `rows` rows of the column-major blocks `a` and
/// `b` (leading dimension `ld`; `out.nrows()` and `out.ncols()` columns): one product by
/// faer, no transposed copy.
pub fn add_block_cross(out: &mut Mat<f64>, a: &[f64], b: &[f64], ld: usize, rows: usize, alpha: f64) {
    let (ma, mb) = (out.nrows(), out.ncols());
    let rows = rows.min(ld);
    if rows == 0 || ma == 0 || mb == 0 || a.len() < ld * (ma - 1) + rows || b.len() < ld * (mb - 1) + rows {
        return;
    }
    let a = MatRef::from_column_major_slice_with_stride(a, rows, ma, ld);
    let b = MatRef::from_column_major_slice_with_stride(b, rows, mb, ld);
    faer::linalg::matmul::matmul(out.as_mut(), Accum::Add, a.transpose(), b, alpha, Par::Seq);
}

/// `w[i] = scale·(x[p+i] − φ_1 x[p+i−1] − … − φ_p x[i])` for i < w.len(), x holding p
/// samples of history first, the sum in that order. Thirty-two outputs at a time, their sums
/// in registers across the lags (one load of `x` per lag and output, one store of `w`): a
/// pass over the block per lag loads and stores `w` at every lag and took twice the time.
/// Inlined into [`WhitenedGram::commit`]'s vectorised body, where the lanes are four
/// AVX-512 or eight AVX2 registers: independent chains of subtractions, so that the vector
/// unit is not waiting on one chain's latency.
#[inline(always)]
fn ar_filter(w: &mut [f64], x: &[f64], phi: &[f64], scale: f64) {
    const LANES: usize = 32;
    let (p, rows) = (phi.len(), w.len());
    debug_assert!(x.len() >= p + rows, "history and block");
    let whole = rows - rows % LANES;
    for (c, out) in w[..whole].chunks_exact_mut(LANES).enumerate() {
        let i0 = c * LANES;
        let mut acc = [0.0; LANES];
        acc.copy_from_slice(&x[p + i0..p + i0 + LANES]);
        for (l, &f) in phi.iter().enumerate() {
            let xs = &x[p - 1 - l + i0..p - 1 - l + i0 + LANES];
            for (a, &v) in acc.iter_mut().zip(xs) {
                *a -= f * v;
            }
        }
        for (o, a) in out.iter_mut().zip(acc) {
            *o = a * scale;
        }
    }
    for i in whole..rows {
        let mut a = x[p + i];
        for (l, &f) in phi.iter().enumerate() {
            a -= f * x[p - 1 - l + i];
        }
        w[i] = a * scale;
    }
}

/// One block's columns through [`ar_filter`], as a `pulp` operation: its body is inlined
/// into the function compiled for the processor's vector unit.
struct Whiten<'a> {
    raw: &'a [f64],
    white: &'a mut [f64],
    ld: usize,
    block: usize,
    start: usize,
    rows: usize,
    phi: &'a [f64],
    scale: f64,
}

impl pulp::WithSimd for Whiten<'_> {
    type Output = ();

    #[inline(always)]
    fn with_simd<S: pulp::Simd>(self, _simd: S) {
        let p = self.phi.len();
        for (x, w) in self.raw.chunks_exact(self.ld).zip(self.white.chunks_exact_mut(self.block)) {
            ar_filter(&mut w[..self.rows], &x[self.start - p..self.start + self.rows], self.phi, self.scale);
        }
    }
}

/// The Gram of prewhitened columns, filled a block of samples at a time: the caller writes
/// each column's values for the block ([`Self::column`]), then [`Self::commit`] whitens
/// them with the AR filter — x_i − Σ φ_l x_{i−l}, scaled to unit innovation variance,
/// the last p samples of the previous block as history — and adds the block's Gram. The
/// first p samples of the series (no history) are left out.
pub struct WhitenedGram {
    phi: Vec<f64>,
    scale: f64,
    /// (p + block) × m column-major: p rows of history, then the block's rows.
    raw: Vec<f64>,
    /// block × m column-major: the block whitened (empty when p = 0: the raw block is white).
    white: Vec<f64>,
    block: usize,
    /// Lower triangle of the Gram.
    gram: Mat<f64>,
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
            raw: vec![0.0; (p + block) * m],
            white: vec![0.0; if p == 0 { 0 } else { block * m }],
            block,
            gram: Mat::zeros(m, m),
            seen: 0,
        }
    }

    /// Column `j`'s values for the next `len` samples (len ≤ the block), to be written.
    pub fn column(&mut self, j: usize, len: usize) -> &mut [f64] {
        let p = self.phi.len();
        let start = j * (p + self.block) + p;
        &mut self.raw[start..start + len.min(self.block)]
    }

    /// Whitens the `len` samples written and adds their Gram.
    pub fn commit(&mut self, len: usize) {
        let (p, m, ld) = (self.phi.len(), self.gram.ncols(), self.phi.len() + self.block);
        let len = len.min(self.block);
        if p == 0 {
            // White already: the block's Gram scaled by 1/σ², no filtered copy of the block.
            add_block_lower(&mut self.gram, &self.raw, ld, len, self.scale * self.scale);
            self.seen += len;
            return;
        }
        let skip = p.saturating_sub(self.seen).min(len);
        let rows = len - skip;
        let start = p + skip;
        // Compiled for the widest vector unit the processor has (pulp's runtime dispatch:
        // AVX-512 or AVX2, else the baseline); the sums are the same, in the same order
        // (no fused multiply-add: Rust does not contract `a - f * v`).
        pulp::Arch::new().dispatch(Whiten {
            raw: &self.raw,
            white: &mut self.white,
            ld,
            block: self.block,
            start,
            rows,
            phi: &self.phi,
            scale: self.scale,
        });
        add_block_lower(&mut self.gram, &self.white, self.block, rows, 1.0);
        // The last p samples (history and block together) are the next block's history.
        for col in 0..m {
            self.raw[col * ld..(col + 1) * ld].copy_within(len..len + p, 0);
        }
        self.seen += len;
    }

    /// The Gram of every whitened sample (symmetric).
    pub fn finish(self) -> DMatrix<f64> {
        let g = &self.gram;
        DMatrix::from_fn(g.nrows(), g.ncols(), |i, j| if i >= j { g[(i, j)] } else { g[(j, i)] })
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
            let mut gram = Mat::from_fn(m, m, |_, _| 1.0);
            add_block_lower(&mut gram, block.as_slice(), ld, rows, 0.5);
            let w = block.rows(0, rows);
            let want = w.transpose() * w * 0.5;
            for i in 0..m {
                for j in 0..m {
                    let expect = if i >= j { want[(i, j)] + 1.0 } else { 1.0 };
                    assert!((gram[(i, j)] - expect).abs() < 1e-9, "({i}, {j})");
                }
            }
        }
    }
}
