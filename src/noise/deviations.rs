//! The Hadamard and modified Allan deviations beside the Allan deviation, with equivalent
//! degrees of freedom for any of the three computed one way.
//!
//! With the phase x_0..x_{N−1} (N = n + 1, x_0 = 0; see [`super::allan::rate_to_phase`]) at
//! cluster size m, τ = mτ₀ (NIST SP 1065):
//!
//! - overlapping Hadamard variance (eq. 17), blind to a linear drift of the rate:
//!   Hσ²(τ) = Σ_{k=0}^{N−3m−1} (x_{k+3m} − 3x_{k+2m} + 3x_{k+m} − x_k)² / (6τ²(N − 3m));
//! - modified Allan variance (eq. 15), which separates white from flicker phase noise:
//!   Mod σ²(τ) = Σ_{j=0}^{N−3m} (Σ_{i=j}^{j+m−1} x_{i+2m} − 2x_{i+m} + x_i)² / (2m²τ²(N − 3m + 1)).
//!   The inner sum is a third difference of the running sum P_k = Σ_{i<k} x_i:
//!   P_{j+3m} − 3P_{j+2m} + 3P_{j+m} − P_j, so each τ costs O(N).
//!
//! Degrees of freedom: an estimator V = (1/M) Σ_k z_k² of a Gaussian process has
//! edf = 2E[V]²/var V = M R(0)² / Σ_{|l|<M} (1 − |l|/M) R(l)², R the autocovariance of z
//! (Greenhall & Riley 2003, "Uncertainty of stability variances based on finite
//! differences"). For power-law noise R at lag t (in units of τ) is, up to a factor that
//! cancels, a d-th central difference of the phase's generalized autocovariance (d = 2
//! Allan, 3 Hadamard), itself averaged over τ for the modified variance. The generalized
//! autocovariances used are −|t| (white rate: Brownian phase), t² ln|t| (flicker rate),
//! |t|³ (random-walk rate) and, twice integrated for the averaging, |t|³, t⁴ ln|t|, |t|⁵.
//! White phase (quantisation) without averaging is a discrete white sequence.

use super::allan::NoiseType;
use super::AdevPoint;
use serde::{Deserialize, Serialize};

/// Which two-sample deviation a curve is.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Deviation {
    /// Overlapping Allan deviation (IEEE 952; the noise terms are read off it).
    #[default]
    Allan,
    /// Overlapping Hadamard deviation: a third difference, unchanged by a linear drift.
    Hadamard,
    /// Modified Allan deviation: averages phase over τ, tells white from flicker phase noise.
    Modified,
}

impl Deviation {
    /// Its name in words.
    pub fn label(self) -> &'static str {
        match self {
            Deviation::Allan => "Allan deviation",
            Deviation::Hadamard => "Hadamard deviation",
            Deviation::Modified => "modified Allan deviation",
        }
    }
}

/// Overlapping Hadamard variance at cluster size `m` from the phase written by
/// [`super::allan::rate_to_phase`] (`x[k-1]` holds x_k, x_0 = 0). None when N < 3m + 1.
pub fn hvar_from_phase(x: &[f64], tau0_s: f64, m: usize) -> Option<f64> {
    let big_n = x.len() + 1;
    if m == 0 || big_n < 3 * m + 1 {
        return None;
    }
    let at = |k: usize| if k == 0 { 0.0 } else { x[k - 1] };
    let terms = big_n - 3 * m;
    let mut sum = 0.0;
    for k in 0..terms {
        let d = at(k + 3 * m) - 3.0 * at(k + 2 * m) + 3.0 * at(k + m) - at(k);
        sum += d * d;
    }
    let tau = m as f64 * tau0_s;
    Some(sum / (6.0 * tau * tau * terms as f64))
}

/// The running sum P_0 = 0, P_{k+1} = P_k + (x_k − x̄) of the phase (x_0 = 0 first), for
/// [`mvar_from_sums`]. Removing the phase's mean keeps P small (a constant phase cancels
/// in the inner second difference).
pub fn phase_sums(x: &[f64]) -> Vec<f64> {
    let n = x.len() + 1;
    let mean = x.iter().sum::<f64>() / n as f64;
    let mut p = Vec::with_capacity(n + 1);
    p.push(0.0);
    let mut acc = -mean; // x_0 = 0
    p.push(acc);
    for v in x {
        acc += v - mean;
        p.push(acc);
    }
    p
}

/// Modified Allan variance at cluster size `m` from [`phase_sums`]. None when N < 3m.
pub fn mvar_from_sums(p: &[f64], tau0_s: f64, m: usize) -> Option<f64> {
    let big_n = p.len().saturating_sub(1);
    if m == 0 || big_n < 3 * m {
        return None;
    }
    let terms = big_n - 3 * m + 1;
    let mut sum = 0.0;
    for j in 0..terms {
        let d = p[j + 3 * m] - 3.0 * p[j + 2 * m] + 3.0 * p[j + m] - p[j];
        sum += d * d;
    }
    let (mf, tau) = (m as f64, m as f64 * tau0_s);
    Some(sum / (2.0 * mf * mf * tau * tau * terms as f64))
}

/// A Hadamard or modified Allan deviation curve.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Curve {
    /// Which deviation.
    pub deviation: Deviation,
    /// Its points, with 68.3 % intervals from [`edf`].
    pub points: Vec<AdevPoint>,
}

/// The `dev` curve at cluster sizes `ms` from the phase `x` of `n` rate samples, each point's
/// degrees of freedom for the noise type `kind_at(τ)` dominating there (from the Allan fit).
pub fn curve(dev: Deviation, x: &[f64], tau0_s: f64, ms: &[usize], kind_at: impl Fn(f64) -> NoiseType) -> Curve {
    let n = x.len();
    let sums = (dev == Deviation::Modified).then(|| phase_sums(x));
    let points = ms
        .iter()
        .filter_map(|&m| {
            let var = match (dev, &sums) {
                (Deviation::Modified, Some(p)) => mvar_from_sums(p, tau0_s, m),
                (Deviation::Hadamard, _) => hvar_from_phase(x, tau0_s, m),
                _ => super::allan::avar_from_phase(x, tau0_s, m),
            }?;
            let tau = m as f64 * tau0_s;
            let e = edf(dev, n, m, kind_at(tau));
            let s = var.sqrt();
            let (low, high) = super::allan::interval(s, e, super::LEVEL);
            Some(AdevPoint { tau_s: tau, adev: s, low, high, edf: e })
        })
        .collect();
    Curve { deviation: dev, points }
}

/// Generalized autocovariance kernels, indexed as in Greenhall & Riley: `a` = 2 … −2.
fn sw(t: f64, a: i32) -> f64 {
    let at = t.abs();
    let log = |p: i32| if at == 0.0 { 0.0 } else { t.powi(p) * at.ln() };
    match a {
        2 => -at,
        1 => log(2),
        0 => at.powi(3),
        -1 => log(4),
        _ => at.powi(5),
    }
}

/// The rate exponent α of S_y(f) ∝ f^α for a noise type.
fn alpha(kind: NoiseType) -> i32 {
    match kind {
        NoiseType::WhitePhase => 2,
        NoiseType::WhiteRate => 0,
        NoiseType::FlickerRate => -1,
        NoiseType::RandomWalkRate => -2,
    }
}

/// Autocovariance (up to a constant) of the estimator's summands at lag `t` (units of τ):
/// the d-th central difference, Σ_k (−1)^k C(2d, d+k) s(t + k), of the phase covariance
/// s — sampled (`averaged` false) or averaged over τ (true).
fn lag_cov(t: f64, kind: NoiseType, d: usize, averaged: bool) -> f64 {
    let a = alpha(kind);
    let s = |u: f64| {
        if averaged {
            2.0 * sw(u, a) - sw(u - 1.0, a) - sw(u + 1.0, a)
        } else if kind == NoiseType::WhitePhase {
            // Sampled white phase: uncorrelated between distinct samples.
            f64::from(u8::from(u.abs() < 1e-9))
        } else {
            sw(u, a + 2)
        }
    };
    let binom = |n: usize, k: usize| (0..k).fold(1.0, |c, i| c * (n - i) as f64 / (i + 1) as f64);
    (-(d as i64)..=d as i64)
        .map(|k| {
            let sign = if k % 2 == 0 { 1.0 } else { -1.0 };
            sign * binom(2 * d, (d as i64 + k) as usize) * s(t + k as f64)
        })
        .sum()
}

/// Equivalent degrees of freedom of the overlapping estimator `dev` at cluster size `m` for
/// `n` rate samples dominated by `kind` (module docs), limited to [1, number of summands].
pub fn edf(dev: Deviation, n: usize, m: usize, kind: NoiseType) -> f64 {
    // Modified at m = 1 is the Allan variance.
    let (d, averaged) = match dev {
        Deviation::Allan => (2usize, false),
        Deviation::Hadamard => (3, false),
        Deviation::Modified => (2, m > 1),
    };
    let big_n = n + 1;
    let span = if averaged { (d + 1) * m } else { d * m };
    if m == 0 || big_n <= span {
        return 1.0;
    }
    let terms = (big_n - span + usize::from(averaged)) as f64;
    let mf = m as f64;
    let r0 = lag_cov(0.0, kind, d, averaged);
    let sum = if kind == NoiseType::WhitePhase && !averaged {
        // A discrete white phase: the summands correlate only at multiples of m.
        (-(d as i64)..=d as i64)
            .map(|q| (q as f64, lag_cov(q as f64, kind, d, false)))
            .filter(|(q, _)| q.abs() * mf < terms)
            .map(|(q, r)| (1.0 - q.abs() * mf / terms) * r * r)
            .sum::<f64>()
    } else {
        // Lags j (samples) = t·m; the summands decorrelate beyond t = d + 1.
        let reach = (d + 1) as f64;
        let lags = ((reach * mf).ceil()).min(terms - 1.0);
        let weight = |t: f64| (1.0 - t.abs() * mf / terms).max(0.0);
        if lags <= 2000.0 {
            let j_max = lags as i64;
            (-j_max..=j_max)
                .map(|j| {
                    let t = j as f64 / mf;
                    weight(t) * lag_cov(t, kind, d, averaged).powi(2)
                })
                .sum::<f64>()
        } else {
            // A Riemann sum over t with 2000 steps, each standing for h·m integer lags.
            let t_max = lags / mf;
            let h = t_max / 1000.0;
            (-1000..=1000)
                .map(|i| {
                    let t = i as f64 * h;
                    weight(t) * lag_cov(t, kind, d, averaged).powi(2)
                })
                .sum::<f64>()
                * h
                * mf
        }
    };
    let v = terms * r0 * r0 / sum;
    if v.is_finite() {
        v.clamp(1.0, terms)
    } else {
        1.0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_generic_allan_edf_agrees_with_sp1065_table_5() {
        for (n, m) in [(10_000usize, 1usize), (10_000, 10), (10_000, 300), (1_000_000, 5000), (100_000, 20_000)] {
            for kind in [NoiseType::WhiteRate, NoiseType::FlickerRate, NoiseType::RandomWalkRate, NoiseType::WhitePhase]
            {
                let a = edf(Deviation::Allan, n, m, kind);
                let b = crate::noise::allan::edf(n, m, kind);
                assert!((a / b - 1.0).abs() < 0.13, "n {n} m {m} {kind:?}: {a} vs table {b}");
            }
        }
    }
}
