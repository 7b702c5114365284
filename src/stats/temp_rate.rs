//! The rate of change of a temperature reading, °C/s: which thermal branch (warming,
//! cooling, plateau) each sample is on.
//!
//! A logged temperature is noisy and quantised (0.0625 °C steps are common), so the
//! difference of neighbouring samples flickers in sign on a plateau and says nothing on a
//! slow ramp. Both estimators here smooth over [`WINDOW_S`] seconds:
//!
//! - [`centred`] (offline: the fit, the offline correction, the simulator, a profile's
//!   record): the ordinary least-squares slope of temperature against time over the samples
//!   within ±[`WINDOW_S`]/2 of each one, S_tT / S_tt with S the centred sums of products —
//!   exact on a ramp, 0 on a constant plateau whatever the quantisation, and computed in
//!   O(1) per sample from prefix sums of t, t², T and tT (t taken from the run's first stamp
//!   to keep the sums small). At a run's ends the window is what exists on that side (a
//!   one-sided slope over half a window, not a slope from a single sample).
//! - [`Causal`] (streaming correction): Brown's double exponential smoothing (Brown 1963,
//!   *Smoothing, Forecasting and Prediction*, ch. 7) with time constant τ = [`WINDOW_S`]/4:
//!   m₁ ← m₁ + α(T − m₁), m₂ ← m₂ + α(m₁ − m₂), α = 1 − e^(−Δt/τ), rate = (m₁ − m₂)/τ.
//!   On a steady ramp r, m₁ lags T by rτ and m₂ lags m₁ by rτ, so the rate is r; it lags
//!   the centred estimate by about 2τ (half a window) and needs no memory beyond four
//!   numbers (no allocation per sample).

/// Length of the smoothing window, s: long against the temperature reading's noise and
/// quantisation, short against a chamber's ramps and plateaus (minutes).
pub const WINDOW_S: f64 = 20.0;

/// The centred smoothed rate of change of `temp_c` (°C) at each stamp of `t_s` (s), °C/s
/// (module documentation). Non-finite temperatures are left out of the means; a sample
/// whose window holds no two distinct times gets NaN (unknown). `t_s` must be
/// non-decreasing; the output has the length of the shorter input.
pub fn centred(t_s: &[f64], temp_c: &[f64]) -> Vec<f64> {
    let n = t_s.len().min(temp_c.len());
    if n == 0 {
        return Vec::new();
    }
    let t0 = t_s[0];
    // Prefix sums over the finite samples: count, Σt, Σt², ΣT, ΣtT (t from t0).
    let mut sums = vec![[0.0; 5]; n + 1];
    for k in 0..n {
        let (t, x) = (t_s[k] - t0, temp_c[k]);
        let add = if x.is_finite() && t.is_finite() { [1.0, t, t * t, x, t * x] } else { [0.0; 5] };
        sums[k + 1] = std::array::from_fn(|i| sums[k][i] + add[i]);
    }
    let half = 0.5 * WINDOW_S;
    let (mut lo, mut hi) = (0usize, 0usize);
    let mut out = Vec::with_capacity(n);
    for k in 0..n {
        // lo: the first sample at or after t_k − half; hi: one past the last at or before t_k + half.
        while lo < k && t_s[lo] < t_s[k] - half {
            lo += 1;
        }
        hi = hi.max(k + 1);
        while hi < n && t_s[hi] <= t_s[k] + half {
            hi += 1;
        }
        let [c, st, stt, sx, stx]: [f64; 5] = std::array::from_fn(|i| sums[hi][i] - sums[lo][i]);
        let s_tt = stt - st * st / c.max(1.0);
        let s_tx = stx - st * sx / c.max(1.0);
        // Two distinct times at least (S_tt of two samples dt apart is dt²/2).
        let spread = (t_s[hi - 1] - t_s[lo]).abs();
        out.push(if c >= 2.0 && s_tt > 1e-6 * spread * spread { s_tx / s_tt } else { f64::NAN });
    }
    out
}

/// The causal smoothed rate of change of a temperature stream (module documentation): four
/// numbers of state, updated per sample.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Causal {
    m1: f64,
    m2: f64,
    t_last_s: f64,
}

impl Default for Causal {
    fn default() -> Self {
        Self::new()
    }
}

impl Causal {
    /// Time constant of the two exponential smoothers, s.
    pub const TAU_S: f64 = WINDOW_S / 4.0;

    /// A filter that has seen nothing.
    pub const fn new() -> Self {
        Self { m1: f64::NAN, m2: f64::NAN, t_last_s: f64::NAN }
    }

    /// Forgets the history (start of a new record).
    pub fn reset(&mut self) {
        *self = Self::new();
    }

    /// Takes the temperature `temp_c` stamped `t_s` and returns the rate estimate, °C/s
    /// (0 at the first sample: no change seen yet; NaN until a finite temperature arrives).
    /// A non-finite temperature or a stamp that does not advance leaves the state as it is.
    #[inline]
    pub fn push(&mut self, t_s: f64, temp_c: f64) -> f64 {
        if temp_c.is_finite() && t_s.is_finite() {
            if !self.m1.is_finite() {
                (self.m1, self.m2, self.t_last_s) = (temp_c, temp_c, t_s);
            } else if t_s > self.t_last_s {
                let alpha = -(-(t_s - self.t_last_s) / Self::TAU_S).exp_m1();
                self.m1 += alpha * (temp_c - self.m1);
                self.m2 += alpha * (self.m1 - self.m2);
                self.t_last_s = t_s;
            }
        }
        self.rate()
    }

    /// The current estimate, °C/s (NaN before the first finite temperature).
    #[inline]
    pub fn rate(&self) -> f64 {
        (self.m1 - self.m2) / Self::TAU_S
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A 0.05 °C/s ramp read through 0.0625 °C quantisation: the centred estimate is the
    /// slope within 2 % away from the ends; a quantised plateau that flickers between two
    /// levels reads within 1e-3 °C/s of 0; the causal estimate reaches the slope within 2 %
    /// after five time constants.
    #[test]
    fn ramp_and_plateau_through_quantisation() {
        let t: Vec<f64> = (0..20_000).map(|k| k as f64 * 0.01).collect();
        let q = |x: f64| (x / 0.0625).round() * 0.0625;
        let ramp: Vec<f64> = t.iter().map(|&s| q(10.0 + 0.05 * s)).collect();
        let r = centred(&t, &ramp);
        for k in (1500..18_500).step_by(500) {
            assert!((r[k] / 0.05 - 1.0).abs() < 0.02, "sample {k}: {}", r[k]);
        }
        let flicker: Vec<f64> = (0..20_000).map(|k| q(20.03 + 0.01 * ((k * 7919) % 13) as f64 / 13.0)).collect();
        let p = centred(&t, &flicker);
        assert!(p.iter().all(|x| x.abs() < 1e-3), "{:?}", p.iter().fold(0.0_f64, |m, x| m.max(x.abs())));
        let mut c = Causal::new();
        let mut last = 0.0;
        for (s, x) in t.iter().zip(&ramp) {
            last = c.push(*s, *x);
        }
        assert!((last / 0.05 - 1.0).abs() < 0.02, "{last}");
        assert!(centred(&[1.0], &[20.0])[0].is_nan());
    }
}
