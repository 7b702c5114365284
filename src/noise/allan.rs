//! Overlapping Allan variance from the cumulative sum of the rate samples, O(n) per
//! cluster time (NIST SP 1065, eq. 14), with its equivalent degrees of freedom
//! (SP 1065, Table 5) and chi-squared confidence intervals (SP 1065, eq. 41).
//!
//! With rate samples y_1..y_n at interval τ₀ and phase x_k = τ₀ Σ_{i≤k} (y_i − ȳ), x_0 = 0:
//!
//! σ²(mτ₀) = Σ_{k=0}^{n−2m} (x_{k+2m} − 2x_{k+m} + x_k)² / (2 (mτ₀)² (n − 2m + 1)).
//!
//! Removing the mean ȳ does not change σ² (it cancels in the second difference) and keeps
//! the phase small, so the cumulative sum stays accurate for long recordings.

use statrs::distribution::{ChiSquared, ContinuousCDF};

/// Power-law noise type of the rate, by the exponent α of its spectrum S_y(f) ∝ f^α
/// (SP 1065 Table 1); selects the degrees-of-freedom formula.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum NoiseType {
    /// α = 2, white phase: quantisation noise (σ ∝ τ⁻¹).
    WhitePhase,
    /// α = 0, white rate: angle/velocity random walk (σ ∝ τ^−½).
    WhiteRate,
    /// α = −1, flicker rate: bias instability (σ flat).
    FlickerRate,
    /// α = −2, random walk of the rate (σ ∝ τ^½); also used for a rate ramp.
    RandomWalkRate,
}

/// Log-spaced cluster sizes m (in samples) for `n` rate samples: 1, 2, 3, 4, 6, 8, 12, …
/// (2^j and 3·2^j, about 6.6 per decade) up to ⌊(n − 1)/3⌋, so that the largest cluster
/// time still averages ≥ n/3 terms. Every 2m is itself a cluster size, which lets
/// [`avar_all`] read each offset of the phase once.
pub fn cluster_sizes(n: usize) -> Vec<usize> {
    let max = n.saturating_sub(1) / 3;
    let mut out: Vec<usize> = Vec::new();
    let mut p = 1usize;
    while p <= max {
        out.push(p);
        if p >= 2 && p / 2 * 3 <= max {
            out.push(p / 2 * 3);
        }
        p *= 2;
    }
    out.sort_unstable();
    out.dedup();
    out
}

/// Turns rate samples into the phase x_1..x_n (x_0 = 0 implied) in place: subtracts the
/// mean, then takes the cumulative sum times τ₀. No allocation.
pub fn rate_to_phase(y: &mut [f64], tau0_s: f64) {
    if y.is_empty() {
        return;
    }
    let mean = y.iter().sum::<f64>() / y.len() as f64;
    let mut acc = 0.0;
    for v in y.iter_mut() {
        acc += (*v - mean) * tau0_s;
        *v = acc;
    }
}

/// Overlapping Allan variance at cluster size `m` from the phase written by
/// [`rate_to_phase`] (`x[k-1]` holds x_k). Returns None when fewer than 2m + 1 samples.
pub fn avar_from_phase(x: &[f64], tau0_s: f64, m: usize) -> Option<f64> {
    let n = x.len();
    if m == 0 || n < 2 * m + 1 {
        return None;
    }
    // k = 0 uses x_0 = 0: x_{2m} − 2 x_m.
    let d0 = x[2 * m - 1] - 2.0 * x[m - 1];
    let mut sum = d0 * d0;
    // k = 1..=n−2m: x_{k+2m} − 2x_{k+m} + x_k with x_k = x[k − 1].
    let len = n - 2 * m;
    let (a, b, c) = (&x[..len], &x[m..m + len], &x[2 * m..2 * m + len]);
    const LANES: usize = 8;
    let mut acc = [0.0f64; LANES];
    let (ca, cb, cc) = (a.chunks_exact(LANES), b.chunks_exact(LANES), c.chunks_exact(LANES));
    let (ra, rb, rc) = (ca.remainder(), cb.remainder(), cc.remainder());
    for ((pa, pb), pc) in ca.zip(cb).zip(cc) {
        for i in 0..LANES {
            let d = pc[i] - 2.0 * pb[i] + pa[i];
            acc[i] += d * d;
        }
    }
    for ((va, vb), vc) in ra.iter().zip(rb).zip(rc) {
        let d = vc - 2.0 * vb + va;
        sum += d * d;
    }
    sum += acc.iter().sum::<f64>();
    let tau = m as f64 * tau0_s;
    Some(sum / (2.0 * tau * tau * (len + 1) as f64))
}

/// Overlapping Allan variance at every cluster size of `ms` in one blocked pass over the
/// phase: within a block of sample indices every offset m and 2m is read while it is still
/// in cache, so memory traffic is one read per distinct offset rather than three per
/// cluster time. Results equal [`avar_from_phase`] (same terms, same order within lanes).
pub fn avar_all(x: &[f64], tau0_s: f64, ms: &[usize]) -> Vec<Option<f64>> {
    const LANES: usize = 8;
    const BLOCK: usize = 2048;
    let n = x.len();
    let mut acc = vec![[0.0f64; LANES]; ms.len()];
    let mut tail = vec![0.0f64; ms.len()];
    // Terms k = 1..=n−2m use x[k−1], x[k+m−1], x[k+2m−1]: index i = k − 1 in 0..n−2m.
    let mut start = 0usize;
    while start < n {
        for (j, &m) in ms.iter().enumerate() {
            if m == 0 || n < 2 * m + 1 {
                continue;
            }
            let len = n - 2 * m;
            if start >= len {
                continue;
            }
            let end = (start + BLOCK).min(len);
            let (a, b, c) = (&x[start..end], &x[start + m..end + m], &x[start + 2 * m..end + 2 * m]);
            let (ca, cb, cc) = (a.chunks_exact(LANES), b.chunks_exact(LANES), c.chunks_exact(LANES));
            let (ra, rb, rc) = (ca.remainder(), cb.remainder(), cc.remainder());
            let mut lanes = acc[j];
            for ((pa, pb), pc) in ca.zip(cb).zip(cc) {
                for i in 0..LANES {
                    let d = pc[i] - 2.0 * pb[i] + pa[i];
                    lanes[i] += d * d;
                }
            }
            acc[j] = lanes;
            for ((va, vb), vc) in ra.iter().zip(rb).zip(rc) {
                let d = vc - 2.0 * vb + va;
                tail[j] += d * d;
            }
        }
        start += BLOCK;
    }
    ms.iter()
        .enumerate()
        .map(|(j, &m)| {
            if m == 0 || n < 2 * m + 1 {
                return None;
            }
            let d0 = x[2 * m - 1] - 2.0 * x[m - 1];
            let sum = d0 * d0 + tail[j] + acc[j].iter().sum::<f64>();
            let tau = m as f64 * tau0_s;
            Some(sum / (2.0 * tau * tau * (n - 2 * m + 1) as f64))
        })
        .collect()
}

/// Equivalent degrees of freedom of the overlapping Allan variance for `n` rate samples at
/// cluster size `m` and noise type `kind` (SP 1065 Table 5, with N = n + 1 phase points),
/// limited to [1, number of terms].
pub fn edf(n: usize, m: usize, kind: NoiseType) -> f64 {
    let big_n = (n + 1) as f64;
    let mf = m as f64;
    let terms = (n + 1).saturating_sub(2 * m).max(1) as f64;
    let v = match kind {
        NoiseType::WhitePhase => (big_n + 1.0) * (big_n - 2.0 * mf) / (2.0 * (big_n - mf)),
        NoiseType::WhiteRate => {
            (3.0 * (big_n - 1.0) / (2.0 * mf) - 2.0 * (big_n - 2.0) / big_n) * 4.0 * mf * mf / (4.0 * mf * mf + 5.0)
        }
        NoiseType::FlickerRate => {
            if m == 1 {
                2.0 * (big_n - 2.0).powi(2) / (2.3 * big_n - 4.9)
            } else {
                5.0 * big_n * big_n / (4.0 * mf * (big_n + 3.0 * mf))
            }
        }
        NoiseType::RandomWalkRate => {
            (big_n - 2.0) / mf * ((big_n - 1.0).powi(2) - 3.0 * mf * (big_n - 1.0) + 4.0 * mf * mf)
                / (big_n - 3.0).powi(2)
        }
    };
    if v.is_finite() {
        v.clamp(1.0, terms)
    } else {
        1.0
    }
}

/// Chi-squared confidence interval of a deviation σ estimated with `edf` degrees of
/// freedom at two-sided level `level` (e.g. 0.683): (low, high) (SP 1065 eq. 41).
pub fn interval(sigma: f64, edf: f64, level: f64) -> (f64, f64) {
    // Below one degree of freedom the χ² quantiles underflow and the interval means nothing;
    // such points (the last cluster time of a short record) get the interval of one.
    let edf = edf.max(1.0);
    let p = (1.0 - level) / 2.0;
    let (lo_q, hi_q) = chi2_quantiles(edf, p);
    let var = sigma * sigma;
    let low = (var * edf / hi_q).sqrt();
    // The upper end is finite for every edf > 0; a quantile that underflows to 0 at tiny edf
    // is held at the smallest positive double so the bound stays a number (JSON has no ∞).
    let high = (var * edf / lo_q.max(f64::MIN_POSITIVE)).sqrt().min(f64::MAX);
    (low, high)
}

/// The p and 1 − p quantiles of χ²(k). statrs' inverse fails (NaN) at the edf of long
/// recordings (≳ 3e5); there, and wherever it does not return a finite number, the
/// Wilson–Hilferty approximation k(1 − 2/(9k) + z√(2/(9k)))³ is used (relative error < 1e-6
/// for k > 1e3).
fn chi2_quantiles(k: f64, p: f64) -> (f64, f64) {
    let wilson_hilferty = |z: f64| {
        let c = 2.0 / (9.0 * k);
        k * (1.0 - c + z * c.sqrt()).powi(3).max(0.0)
    };
    let z = statrs::distribution::Normal::standard().inverse_cdf(1.0 - p);
    let exact =
        if k <= 1e4 { ChiSquared::new(k).ok().map(|c| (c.inverse_cdf(p), c.inverse_cdf(1.0 - p))) } else { None };
    match exact {
        Some((lo, hi)) if lo.is_finite() && hi.is_finite() && hi > 0.0 => (lo, hi),
        _ => (wilson_hilferty(-z), wilson_hilferty(z)),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cluster_sizes_are_increasing_and_bounded() {
        let m = cluster_sizes(1000);
        assert_eq!(&m[..6], &[1, 2, 3, 4, 6, 8]);
        assert!(m.windows(2).all(|w| w[1] > w[0]));
        assert!(*m.last().unwrap() <= 333);
        assert!(cluster_sizes(3).is_empty());
        assert_eq!(cluster_sizes(10), vec![1, 2, 3]);
    }

    #[test]
    fn interval_brackets_the_estimate() {
        let (lo, hi) = interval(2.0, 10.0, 0.683);
        assert!(lo < 2.0 && hi > 2.0, "{lo} {hi}");
        let (lo2, hi2) = interval(2.0, 1000.0, 0.683);
        assert!(hi2 - lo2 < hi - lo);
    }

    /// Long recordings (edf ~ 1e5–1e7) used to give NaN bounds, saved as JSON nulls that
    /// nothing could read back; the bounds are now finite and match the normal limit
    /// σ(1 ± z/√(2·edf)).
    #[test]
    fn intervals_stay_finite_at_the_edf_of_long_recordings() {
        for edf in [3e3, 1e4, 1e4 + 1.0, 3e5, 7e5, 1e7] {
            let (lo, hi) = interval(1.0, edf, 0.683);
            assert!(lo.is_finite() && hi.is_finite() && lo < 1.0 && hi > 1.0, "{edf}: {lo} {hi}");
            let half = 1.0 / (2.0 * edf).sqrt();
            assert!(
                ((1.0 - lo) / half - 1.0).abs() < 0.05 && ((hi - 1.0) / half - 1.0).abs() < 0.05,
                "{edf}: {lo} {hi}"
            );
        }
        let (a, b) = interval(1.0, 1e4, 0.683);
        let (c, d) = interval(1.0, 1e4 + 1.0, 0.683);
        assert!((a - c).abs() < 1e-6 && (b - d).abs() < 1e-6, "exact and approximate agree at the switch");
        let (lo, hi) = interval(1.0, 1e-3, 0.683);
        assert!(lo.is_finite() && hi.is_finite() && lo < 1.0 && hi > 1.0, "{lo} {hi}");
    }
}
