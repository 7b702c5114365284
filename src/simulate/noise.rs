//! Coloured sensor noise with known Allan variance: white noise, flicker (bias
//! instability), rate random walk and first-order Gauss–Markov (AR(1)) noise.
//!
//! Flicker noise is the sum of first-order Gauss–Markov processes with time constants two
//! per decade from 3τ₀ to the recording length; a process of variance σ² and time constant
//! T has the one-sided spectrum 4σ²T/(1 + (2πfT)²), and with σ² = B² ln r/π (r the ratio of
//! neighbouring time constants) their sum approximates S(f) = B²/(πf), whose Allan
//! deviation is flat at 0.664 B (IEEE 952 table C.1). [`NoiseProcess::allan_variance`] gives
//! the exact Allan variance of what is generated, so tests compare estimates with truth.

use rand::Rng;
use rand_distr::{Distribution, StandardNormal};

/// Noise added to one channel, SI rate units (rad/s or m/s²).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct NoiseProcess {
    /// White-noise density N, unit/√Hz (per-sample σ = N/√τ₀).
    pub white_density: f64,
    /// Bias instability B, unit (flicker noise).
    pub bias_instability: f64,
    /// Rate random walk K, unit/√s.
    pub random_walk: f64,
    /// First-order Gauss–Markov noise: (correlation per sample ρ, stationary σ), unit.
    pub ar1: Option<(f64, f64)>,
}

/// Ratio of neighbouring flicker time constants (two per decade).
const RATIO: f64 = 3.162_277_660_168_379_5;

impl NoiseProcess {
    /// True when it adds nothing.
    pub fn is_zero(&self) -> bool {
        self.white_density == 0.0
            && self.bias_instability == 0.0
            && self.random_walk == 0.0
            && self.ar1.is_none_or(|(_, s)| s == 0.0)
    }

    /// The Gauss–Markov components (time constant s, stationary σ) of the flicker part for
    /// a recording of `duration_s` at interval `dt_s`.
    fn flicker_poles(&self, dt_s: f64, duration_s: f64) -> Vec<(f64, f64)> {
        if self.bias_instability == 0.0 {
            return Vec::new();
        }
        let sigma = self.bias_instability * (RATIO.ln() / std::f64::consts::PI).sqrt();
        let mut out = Vec::new();
        let mut t = 3.0 * dt_s;
        while t <= duration_s.max(3.0 * dt_s) {
            out.push((t, sigma));
            t *= RATIO;
        }
        out
    }

    /// A generator of this noise at interval `dt_s` for a recording of `duration_s`.
    pub fn generator(&self, dt_s: f64, duration_s: f64) -> NoiseGenerator {
        let poles = self
            .flicker_poles(dt_s, duration_s)
            .into_iter()
            .chain(self.ar1.map(|(rho, s)| (-dt_s / rho.clamp(1e-12, 1.0 - 1e-12).ln(), s)))
            .map(|(t, s)| {
                let phi = (-dt_s / t).exp();
                (phi, s * (1.0 - phi * phi).sqrt(), s)
            })
            .collect();
        NoiseGenerator {
            white_sd: self.white_density / dt_s.sqrt(),
            walk_sd: self.random_walk * dt_s.sqrt(),
            poles,
            state: Vec::new(),
            walk: 0.0,
        }
    }

    /// The exact Allan variance at τ of the continuous-time process generated for a
    /// recording of `duration_s` at interval `dt_s`: N²/τ + K²τ/3 + Σ Gauss–Markov terms
    /// σ²(T/τ)² (2τ/T − 3 + 4e^{−τ/T} − e^{−2τ/T}).
    pub fn allan_variance(&self, tau_s: f64, dt_s: f64, duration_s: f64) -> f64 {
        let gm = |t: f64, s: f64| {
            let x = tau_s / t;
            (s * t / tau_s).powi(2) * (2.0 * x - 3.0 + 4.0 * (-x).exp() - (-2.0 * x).exp())
        };
        let mut v = self.white_density.powi(2) / tau_s + self.random_walk.powi(2) * tau_s / 3.0;
        for (t, s) in self.flicker_poles(dt_s, duration_s) {
            v += gm(t, s);
        }
        if let Some((rho, s)) = self.ar1 {
            v += gm(-dt_s / rho.clamp(1e-12, 1.0 - 1e-12).ln(), s);
        }
        v
    }
}

/// State of a [`NoiseProcess`] being generated.
#[derive(Debug, Clone)]
pub struct NoiseGenerator {
    white_sd: f64,
    walk_sd: f64,
    /// (φ, innovation σ, stationary σ) per Gauss–Markov component.
    poles: Vec<(f64, f64, f64)>,
    state: Vec<f64>,
    walk: f64,
}

impl NoiseGenerator {
    /// Lets `gap_s` pass without samples (a pause between runs on the session clock): each
    /// Gauss–Markov state decays by φ^(gap/dt) and takes the innovation that keeps it
    /// stationary, x ← e^{−g/T} x + σ √(1 − e^{−2g/T}) z; the random walk takes K √g z. The
    /// white part has no memory. A sequence of runs generated with one generator and these
    /// pauses is one continuous process on the session clock.
    pub fn pause<R: Rng>(&mut self, gap_s: f64, dt_s: f64, rng: &mut R) {
        if !(gap_s > 0.0 && dt_s > 0.0) {
            return;
        }
        let steps = gap_s / dt_s;
        if self.walk_sd > 0.0 {
            let z: f64 = StandardNormal.sample(rng);
            self.walk += self.walk_sd * steps.sqrt() * z;
        }
        for (x, p) in self.state.iter_mut().zip(&self.poles) {
            let decay = p.0.powf(steps);
            let z: f64 = StandardNormal.sample(rng);
            *x = decay * *x + p.2 * (1.0 - decay * decay).max(0.0).sqrt() * z;
        }
    }

    /// The next sample.
    pub fn next_sample<R: Rng>(&mut self, rng: &mut R) -> f64 {
        if self.state.is_empty() && !self.poles.is_empty() {
            // Stationary start.
            self.state = self.poles.iter().map(|p| p.2 * Distribution::<f64>::sample(&StandardNormal, rng)).collect();
        }
        let mut v = 0.0;
        if self.white_sd > 0.0 {
            let z: f64 = StandardNormal.sample(rng);
            v += self.white_sd * z;
        }
        if self.walk_sd > 0.0 {
            let z: f64 = StandardNormal.sample(rng);
            self.walk += self.walk_sd * z;
            v += self.walk;
        }
        for (x, p) in self.state.iter_mut().zip(&self.poles) {
            let z: f64 = StandardNormal.sample(rng);
            *x = p.0 * *x + p.1 * z;
            v += *x;
        }
        v
    }
}
