//! Band-limited derivatives by local polynomial least squares (Savitzky–Golay on the
//! actual time stamps, so non-uniform sampling is handled exactly).
//!
//! For a window of samples `(t_j, y_j)` around an evaluation time `t0`, a polynomial of
//! degree `d` in `τ = (t − t0)/h` is fitted by least squares and its slope at `t0` is
//! returned. The slope is a fixed linear combination `Σ w_j y_j`; the weights solve
//! `G z = e₁`, `G = VᵀV`, `w_j = (V_j · z)/h` with `V_jk = τ_j^k` (normal equations of a
//! ≤ 4×4 system in scaled time, which is well conditioned). On uniform sampling the
//! weights are computed once and reused.
//!
//! The window acts as a low-pass filter: a cubic over 2m+1 samples has a relative slope
//! error of order (ω·m·dt)⁴ for a sinusoid of angular frequency ω, while white noise of
//! standard deviation σ becomes slope noise of order σ/(dt·m^{3/2}).

use nalgebra::{Matrix4, Vector4};

/// Settings of the local polynomial derivative.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DerivativeConfig {
    /// Samples on each side of the evaluation point (window = 2m+1 offline).
    pub half_window: usize,
    /// Polynomial degree, 1..=3.
    pub degree: usize,
}

impl Default for DerivativeConfig {
    fn default() -> Self {
        Self { half_window: 5, degree: 3 }
    }
}

impl DerivativeConfig {
    /// A one-line description of the estimator (recorded in reports and profiles).
    pub fn describe(&self) -> String {
        format!(
            "local degree-{} least-squares (Savitzky-Golay) derivative over {} samples on the recorded time stamps",
            self.degree,
            2 * self.half_window + 1
        )
    }
}

/// Computes slope weights for a window; reuses them when the sampling pattern repeats.
#[derive(Debug, Clone)]
pub struct SlopeWeights {
    degree: usize,
    offsets: Vec<f64>,
    weights: Vec<f64>,
    valid: bool,
}

impl SlopeWeights {
    /// Weight solver for polynomials of `degree` (clamped to 1..=3) and windows of at most
    /// `max_len` samples. Allocates once.
    pub fn new(degree: usize, max_len: usize) -> Self {
        Self {
            degree: degree.clamp(1, 3),
            offsets: Vec::with_capacity(max_len),
            weights: Vec::with_capacity(max_len),
            valid: false,
        }
    }

    /// The weights of the last [`Self::compute`] (empty when it failed).
    pub fn last(&self) -> &[f64] {
        if self.valid {
            &self.weights
        } else {
            &[]
        }
    }

    /// Weights `w` such that `Σ w_j y_j` is the slope at `t0` of the polynomial fitted to
    /// `(times[j], y_j)`. Returns an empty slice when the window has too few distinct times.
    pub fn compute(&mut self, times: &[f64], t0: f64) -> &[f64] {
        let h = times.iter().map(|t| (t - t0).abs()).fold(0.0_f64, f64::max);
        let tol = 1e-9 * h.max(f64::MIN_POSITIVE);
        let same = self.valid
            && self.offsets.len() == times.len()
            && self.offsets.iter().zip(times).all(|(o, t)| ((t - t0) - o).abs() <= tol);
        if same {
            return &self.weights;
        }
        self.offsets.clear();
        self.offsets.extend(times.iter().map(|t| t - t0));
        self.weights.clear();
        self.valid = false;
        let d = self.degree.min(times.len().saturating_sub(1));
        if d == 0 || h <= 0.0 {
            return &self.weights;
        }
        // G = VᵀV padded with identity beyond degree d.
        let mut g = Matrix4::<f64>::zeros();
        for o in &self.offsets {
            let tau = o / h;
            let mut p = [1.0; 7];
            for k in 1..7 {
                p[k] = p[k - 1] * tau;
            }
            for r in 0..=d {
                for c in 0..=d {
                    g[(r, c)] += p[r + c];
                }
            }
        }
        for k in d + 1..4 {
            g[(k, k)] = 1.0;
        }
        let Some(z) = g.lu().solve(&Vector4::new(0.0, 1.0, 0.0, 0.0)) else {
            return &self.weights;
        };
        if !z.iter().all(|v| v.is_finite()) {
            return &self.weights;
        }
        for o in &self.offsets {
            let tau = o / h;
            let mut acc = 0.0;
            let mut p = 1.0;
            for k in 0..=d {
                acc += p * z[k];
                p *= tau;
            }
            self.weights.push(acc / h);
        }
        self.valid = true;
        &self.weights
    }
}

/// Non-causal derivative of a whole record of 3-vectors (centred windows, shifted inward
/// at the ends), in the frame of `x`. `out` must have the same length as `x` and `t`.
pub fn derivative_offline<T>(t: &[f64], x: &[T], cfg: &DerivativeConfig, out: &mut [T])
where
    T: Copy + std::ops::Index<usize, Output = f64> + From<[f64; 3]>,
{
    let n = t.len().min(x.len()).min(out.len());
    if n == 0 {
        return;
    }
    let m = cfg.half_window.max(1);
    let len = (2 * m + 1).min(n);
    let mut sw = SlopeWeights::new(cfg.degree, len);
    for i in 0..n {
        let start = i.saturating_sub(m).min(n - len);
        let w = sw.compute(&t[start..start + len], t[i]);
        let mut s = [0.0; 3];
        for (j, wj) in w.iter().enumerate() {
            let xj = &x[start + j];
            s[0] += wj * xj[0];
            s[1] += wj * xj[1];
            s[2] += wj * xj[2];
        }
        out[i] = T::from(s);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cubic_is_differentiated_exactly_on_irregular_times() {
        let t: Vec<f64> = (0..40).map(|k| k as f64 * 0.01 + 0.003 * ((k * 7 % 5) as f64)).collect();
        let f = |t: f64| 2.0 - 3.0 * t + 0.5 * t * t - 4.0 * t * t * t;
        let df = |t: f64| -3.0 + t - 12.0 * t * t;
        let x: Vec<[f64; 3]> = t.iter().map(|&s| [f(s), 2.0 * f(s), 0.0]).collect();
        let mut out = vec![[0.0; 3]; t.len()];
        derivative_offline(&t, &x, &DerivativeConfig::default(), &mut out);
        for (k, &s) in t.iter().enumerate() {
            assert!((out[k][0] - df(s)).abs() < 1e-9, "k={k}");
            assert!((out[k][1] - 2.0 * df(s)).abs() < 1e-9);
        }
    }

    #[test]
    fn sinusoid_slope_is_accurate() {
        let w = 0.2_f64;
        let t: Vec<f64> = (0..2000).map(|k| k as f64 * 0.01).collect();
        let x: Vec<[f64; 3]> = t.iter().map(|&s| [(w * s).sin(), 0.0, 0.0]).collect();
        let mut out = vec![[0.0; 3]; t.len()];
        derivative_offline(&t, &x, &DerivativeConfig::default(), &mut out);
        let err: Vec<f64> = t.iter().zip(&out).map(|(&s, o)| (o[0] - w * (w * s).cos()).abs()).collect();
        let interior = err[5..err.len() - 5].iter().copied().fold(0.0, f64::max);
        let edges = err.iter().copied().fold(0.0, f64::max);
        assert!(interior < 1e-10 * w, "interior slope error {interior}");
        assert!(edges < 1e-7 * w, "edge slope error {edges}");
    }
}
