//! Autocovariances of a stream and the long-run variance of a serially correlated series.

/// Newey–West bandwidth ⌊4 (n/100)^{2/9}⌋ for a run of n samples.
pub fn newey_west_lags(n: usize) -> usize {
    ((4.0 * (n as f64 / 100.0).powf(2.0 / 9.0)) as usize).clamp(1, (n / 4).max(1))
}

/// Autocovariance sums Σ r_k r_{k−l} of a residual stream for lags 0..=L+1. Values are
/// gathered in blocks behind the last L + 1 of the previous block and summed a lag at a time
/// over each block (contiguous dot products, four partial sums each): fixed memory, no
/// allocation per sample; [`AutoCov::finish`] sums the last, partial block.
pub struct AutoCov {
    buf: Vec<f64>,
    /// Values in `buf` (history first).
    fill: usize,
    /// How many of them are history already summed.
    hist: usize,
    sums: Vec<f64>,
    n: usize,
}

/// Values per block of [`AutoCov`].
const ACOV_BLOCK: usize = 2048;

impl AutoCov {
    /// Sums for lags 0..=max_lag + 1, empty.
    pub fn new(max_lag: usize) -> Self {
        Self { buf: vec![0.0; max_lag + 1 + ACOV_BLOCK], fill: 0, hist: 0, sums: vec![0.0; max_lag + 1], n: 0 }
    }

    /// Appends values in order, summing each block as it fills.
    pub fn extend(&mut self, mut vals: &[f64]) {
        // Closed: nothing more is summed.
        if self.buf.is_empty() {
            return;
        }
        while !vals.is_empty() {
            let take = (self.buf.len() - self.fill).min(vals.len());
            self.buf[self.fill..self.fill + take].copy_from_slice(&vals[..take]);
            self.fill += take;
            self.n += take;
            vals = &vals[take..];
            if self.fill == self.buf.len() {
                self.finish();
            }
        }
    }

    /// Sums the last, partial block and gives back the block buffer (16 kB): the sums stay
    /// readable, no value may be added after. For statistics kept per run until all runs
    /// are read (10 000 short runs held 1 GB of buffers).
    pub fn close(&mut self) {
        self.finish();
        self.buf = Vec::new();
        self.fill = 0;
        self.hist = 0;
    }

    /// Sums the values gathered since the last block; keeps the last L + 1 as history.
    pub fn finish(&mut self) {
        let (new, fill) = (self.hist, self.fill);
        for (l, s) in self.sums.iter_mut().enumerate() {
            let from = new.max(l);
            if from < fill {
                *s += dot(&self.buf[from..fill], &self.buf[from - l..fill - l]);
            }
        }
        let keep = fill.min(self.sums.len());
        self.buf.copy_within(fill - keep..fill, 0);
        self.fill = keep;
        self.hist = keep;
    }
}

/// Σ a_k b_k for equal lengths, with sixteen partial sums (so that the adds do not wait on
/// each other), added pairwise, then the tail.
#[inline]
pub fn dot(a: &[f64], b: &[f64]) -> f64 {
    let mut s = [0.0; 16];
    let (ac, bc) = (a.chunks_exact(16), b.chunks_exact(16));
    let tail: f64 = ac.remainder().iter().zip(bc.remainder()).map(|(x, y)| x * y).sum();
    for (x, y) in ac.zip(bc) {
        for i in 0..16 {
            s[i] += x[i] * y[i];
        }
    }
    let mut width = 16;
    while width > 1 {
        width /= 2;
        for i in 0..width {
            s[i] += s[i + width];
        }
    }
    s[0] + tail
}

/// Pooled long-run variance of residuals over runs, by AR(1) prewhitening followed by a
/// Bartlett (Newey–West) kernel on the whitened residual (Andrews & Monahan 1992): with
/// ρ = γ₁/γ₀ per run, the whitened autocovariances are γᵉ_l = (1+ρ²)γ_l − ρ(γ_{l−1}+γ_{l+1}),
/// LRV(e) = γᵉ₀ + 2Σ_{l≤L}(1 − l/(L+1))γᵉ_l and LRV(r) = LRV(e)/(1−ρ)². The ratio
/// LRV/γ₀ inflates the white-noise covariance; it is exact for regressors that vary slowly
/// over the noise's correlation time (the cone period is seconds, sensor noise
/// correlation milliseconds).
#[derive(Default)]
pub struct LongRunVariance {
    lrv: f64,
    var: f64,
    lag1: f64,
}

impl LongRunVariance {
    /// Adds one run's autocovariance sums (bandwidth `lags`).
    pub fn add(&mut self, a: &AutoCov, lags: usize) {
        if a.n < 4 || a.sums[0] <= 0.0 {
            return;
        }
        let n = a.n as f64;
        let g = |l: usize| a.sums.get(l).copied().unwrap_or(0.0) / n;
        let rho = (g(1) / g(0)).clamp(-0.995, 0.995);
        let ge = |l: usize| {
            let prev = if l == 0 { g(1) } else { g(l - 1) };
            (1.0 + rho * rho) * g(l) - rho * (prev + g(l + 1))
        };
        let mut le = ge(0);
        for l in 1..lags.min(a.sums.len().saturating_sub(2)) + 1 {
            le += 2.0 * (1.0 - l as f64 / (lags + 1) as f64) * ge(l);
        }
        let lr = (le / (1.0 - rho).powi(2)).max(0.0);
        self.lrv += lr * n;
        self.var += g(0) * n;
        self.lag1 += g(1) * n;
    }

    /// Long-run variance over variance (1 for white noise or no data).
    pub fn inflation(&self) -> f64 {
        if self.var > 0.0 && self.lrv > 0.0 {
            self.lrv / self.var
        } else {
            1.0
        }
    }

    /// Pooled lag-1 autocorrelation.
    pub fn lag1(&self) -> f64 {
        if self.var > 0.0 {
            self.lag1 / self.var
        } else {
            0.0
        }
    }
}

impl AutoCov {
    /// Values summed so far.
    pub fn count(&self) -> usize {
        self.n
    }

    /// Σ r_k r_{k−l} for lag `l` (0 beyond the lags kept).
    pub fn sum(&self, lag: usize) -> f64 {
        self.sums.get(lag).copied().unwrap_or(0.0)
    }
}

#[cfg(test)]
mod tests {
    use super::{AutoCov, ACOV_BLOCK};

    #[test]
    fn blocked_autocovariances_equal_the_direct_sums() {
        // A deterministic, correlated stream; lengths around the block size and shorter
        // than the lags.
        for n in [0, 3, 17, ACOV_BLOCK - 1, ACOV_BLOCK, ACOV_BLOCK + 5, 3 * ACOV_BLOCK + 123] {
            let r: Vec<f64> = (0..n).map(|k| (k as f64 * 0.37).sin() + 0.3 * (k as f64 * 1.91).cos()).collect();
            let lags = 19;
            let mut a = AutoCov::new(lags);
            // In uneven pieces, across block boundaries.
            for piece in r.chunks(97) {
                a.extend(piece);
            }
            a.finish();
            assert_eq!(a.n, n);
            for l in 0..=lags {
                let direct: f64 = (l..n).map(|k| r[k] * r[k - l]).sum();
                let tol = 1e-12 * (1.0 + direct.abs() + n as f64);
                assert!((a.sums[l] - direct).abs() <= tol, "n {n} lag {l}: {} vs {direct}", a.sums[l]);
            }
        }
    }
}
