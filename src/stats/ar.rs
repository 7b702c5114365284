//! Autoregressive noise models: an AR(p) fitted to a residual series by Levinson–Durbin on
//! its sample autocovariances (the Yule–Walker equations), the order chosen by BIC, and
//! the prewhitening filter e_t = x_t − Σ φ_i x_{t−i} that turns the series into (nearly)
//! white innovations. Regressions on prewhitened data are generalised least squares:
//! their χ² statistics and standard errors hold under serially correlated noise.

/// An AR(p) noise model: x_t = Σ_{i=1..p} φ_i x_{t−i} + e_t, Var e = `innovation_var`.
#[derive(Debug, Clone, PartialEq)]
pub struct ArModel {
    /// φ_1 … φ_p.
    pub phi: Vec<f64>,
    /// Variance of the innovations e_t.
    pub innovation_var: f64,
    /// Variance of the series itself (γ₀).
    pub marginal_var: f64,
}

/// Largest order tried by [`ArModel::fit`].
pub const MAX_ORDER: usize = 12;

impl ArModel {
    /// White noise of variance `var`.
    pub fn white(var: f64) -> Self {
        Self { phi: Vec::new(), innovation_var: var, marginal_var: var }
    }

    /// Order p.
    pub fn order(&self) -> usize {
        self.phi.len()
    }

    /// Fits orders 0..=`max_order` to `x` (already centred) by Levinson–Durbin and keeps
    /// the one with the lowest BIC = n ln σ²_p + p ln n. Returns white noise of variance 0
    /// for fewer than 8 values.
    pub fn fit(x: &[f64], max_order: usize) -> Self {
        let n = x.len();
        if n < 8 {
            return Self::white(0.0);
        }
        let gamma = autocovariances(x, max_order.min(n / 4));
        Self::from_autocov(&gamma, n)
    }

    /// The BIC-best AR model for autocovariances γ₀…γ_P estimated from `n` values (pooled
    /// over several series of one process, when they are).
    pub fn from_autocov(gamma: &[f64], n: usize) -> Self {
        if gamma.is_empty() || n < 8 {
            return Self::white(gamma.first().copied().unwrap_or(0.0).max(0.0));
        }
        if gamma[0] <= 0.0 || !gamma[0].is_finite() {
            return Self::white(gamma[0].max(0.0));
        }
        let levels = levinson(gamma);
        let nf = n as f64;
        let bic = |p: usize, v: f64| nf * v.max(f64::MIN_POSITIVE).ln() + p as f64 * nf.ln();
        let (mut best, mut best_bic) = (0, bic(0, gamma[0]));
        for (p, (_, v)) in levels.iter().enumerate().skip(1) {
            let b = bic(p, *v);
            if b < best_bic {
                best = p;
                best_bic = b;
            }
        }
        let (phi, v) = levels[best].clone();
        Self { phi, innovation_var: v, marginal_var: gamma[0] }
    }

    /// Variance of the innovations this model's filter leaves in a series with
    /// autocovariances γ: Var(x_t − Σ φ_i x_{t−i}) = Σ_ij a_i a_j γ_|i−j| with a = (1, −φ).
    pub fn innovation_of(&self, gamma: &[f64]) -> f64 {
        let a: Vec<f64> = std::iter::once(1.0).chain(self.phi.iter().map(|p| -p)).collect();
        let g = |l: usize| gamma.get(l).copied().unwrap_or(0.0);
        let mut v = 0.0;
        for (i, ai) in a.iter().enumerate() {
            for (j, aj) in a.iter().enumerate() {
                v += ai * aj * g(i.abs_diff(j));
            }
        }
        v.max(0.0)
    }

    /// The one-sided power spectral density of the model at frequency `f_hz` for a sampling
    /// rate `fs_hz`: 2 σ²_e / (fs |1 − Σ φ_k e^{−i 2π f k / fs}|²).
    pub fn psd(&self, f_hz: f64, fs_hz: f64) -> f64 {
        let w = std::f64::consts::TAU * f_hz / fs_hz;
        let (mut re, mut im) = (1.0, 0.0);
        for (k, p) in self.phi.iter().enumerate() {
            let a = w * (k + 1) as f64;
            re -= p * a.cos();
            im += p * a.sin();
        }
        2.0 * self.innovation_var / (fs_hz * (re * re + im * im))
    }

    /// Prewhitens `x` into `out` (same length): out_t = x_t − Σ φ_i x_{t−i}, with the
    /// first p values (no full history) set to NaN so callers skip them.
    pub fn whiten(&self, x: &[f64], out: &mut [f64]) {
        let p = self.phi.len();
        for t in 0..x.len().min(out.len()) {
            if t < p {
                out[t] = f64::NAN;
                continue;
            }
            let mut v = x[t];
            for (i, ph) in self.phi.iter().enumerate() {
                v -= ph * x[t - 1 - i];
            }
            out[t] = v;
        }
    }
}

/// Sample autocovariances γ₀…γ_P (divisor n) of a centred series.
pub fn autocovariances(x: &[f64], max_lag: usize) -> Vec<f64> {
    let n = x.len();
    (0..=max_lag.min(n.saturating_sub(1))).map(|l| super::dot(&x[l..], &x[..n - l]) / n.max(1) as f64).collect()
}

/// Levinson–Durbin recursion on autocovariances γ₀…γ_P: for each order p the AR
/// coefficients and the innovation variance (Yule–Walker solution, Brockwell & Davis §8.2).
fn levinson(gamma: &[f64]) -> Vec<(Vec<f64>, f64)> {
    let mut out = vec![(Vec::new(), gamma[0])];
    let mut phi: Vec<f64> = Vec::new();
    let mut v = gamma[0];
    for p in 1..gamma.len() {
        let acc: f64 = phi.iter().enumerate().map(|(i, f)| f * gamma[p - 1 - i]).sum();
        let k = ((gamma[p] - acc) / v).clamp(-0.9999, 0.9999);
        let mut next = phi.clone();
        for i in 0..phi.len() {
            next[i] = phi[i] - k * phi[phi.len() - 1 - i];
        }
        next.push(k);
        v *= 1.0 - k * k;
        phi = next;
        out.push((phi.clone(), v));
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_distr::{Distribution, StandardNormal};

    #[test]
    fn recovers_ar1_and_white_noise_orders() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
        let mut x = vec![0.0; 50_000];
        for t in 1..x.len() {
            let z: f64 = StandardNormal.sample(&mut rng);
            x[t] = 0.95 * x[t - 1] + z;
        }
        let m = ArModel::fit(&x, MAX_ORDER);
        assert_eq!(m.order(), 1, "{m:?}");
        assert!((m.phi[0] - 0.95).abs() < 0.01);
        assert!((m.innovation_var - 1.0).abs() < 0.03);
        let w: Vec<f64> = (0..50_000).map(|_| StandardNormal.sample(&mut rng)).collect();
        assert_eq!(ArModel::fit(&w, MAX_ORDER).order(), 0);
        // The whitened AR(1) series is white with the innovations' variance.
        let mut e = vec![0.0; x.len()];
        m.whiten(&x, &mut e);
        let v = e[1..].iter().map(|v| v * v).sum::<f64>() / (e.len() - 1) as f64;
        let l1 = e[2..].iter().zip(&e[1..]).map(|(a, b)| a * b).sum::<f64>() / (e.len() - 2) as f64;
        assert!((v - 1.0).abs() < 0.03 && (l1 / v).abs() < 0.02, "{v} {l1}");
        // Integral of the one-sided PSD over 0..fs/2 is the marginal variance.
        let fs = 100.0;
        let k = 20_000;
        let area: f64 =
            (0..k).map(|i| m.psd((i as f64 + 0.5) * fs / 2.0 / k as f64, fs)).sum::<f64>() * fs / 2.0 / k as f64;
        assert!((area / m.marginal_var - 1.0).abs() < 0.05, "{area} {}", m.marginal_var);
    }
}
