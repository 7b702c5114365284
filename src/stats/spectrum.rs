//! Power spectral density by Welch's method (Hann window, 50 % overlap) and detection of
//! narrow-band lines standing out of the continuum: each bin against the running median
//! of its neighbours, with the χ² distribution of a Welch estimate (2K degrees of
//! freedom for K segments) and a Bonferroni bound over the bins searched.

use statrs::distribution::{ChiSquared, ContinuousCDF};

/// A one-sided PSD estimate.
#[derive(Debug, Clone, PartialEq)]
pub struct Psd {
    /// Bin width, Hz.
    pub df_hz: f64,
    /// Power per bin, unit²/Hz (bin k at k·df).
    pub power: Vec<f64>,
    /// Segments averaged.
    pub segments: usize,
}

/// Welch PSD of `x` sampled at `fs_hz` with segments of `len` values (a power of two
/// makes no difference; any length ≥ 16), Hann window, half overlap, each segment's mean
/// removed. None when `x` is shorter than one segment.
pub fn welch(x: &[f64], fs_hz: f64, len: usize) -> Option<Psd> {
    if len < 16 || x.len() < len || fs_hz <= 0.0 {
        return None;
    }
    let window: Vec<f64> =
        (0..len).map(|i| 0.5 - 0.5 * (std::f64::consts::TAU * i as f64 / len as f64).cos()).collect();
    let u: f64 = window.iter().map(|w| w * w).sum();
    let mut planner = rustfft::FftPlanner::<f64>::new();
    let fft = planner.plan_fft_forward(len);
    let mut buf = vec![rustfft::num_complex::Complex::new(0.0, 0.0); len];
    let bins = len / 2 + 1;
    let mut power = vec![0.0; bins];
    let step = len / 2;
    let mut segments = 0;
    let mut start = 0;
    while start + len <= x.len() {
        let seg = &x[start..start + len];
        let mean = seg.iter().sum::<f64>() / len as f64;
        for ((b, v), w) in buf.iter_mut().zip(seg).zip(&window) {
            *b = rustfft::num_complex::Complex::new((v - mean) * w, 0.0);
        }
        fft.process(&mut buf);
        for (k, p) in power.iter_mut().enumerate() {
            *p += buf[k].norm_sqr();
        }
        segments += 1;
        start += step;
    }
    // One-sided density: 2|X|²/(fs Σw²), the DC and Nyquist bins not doubled.
    for (k, p) in power.iter_mut().enumerate() {
        let two = if k == 0 || k == bins - 1 { 1.0 } else { 2.0 };
        *p *= two / (fs_hz * u * segments as f64);
    }
    Some(Psd { df_hz: fs_hz / len as f64, power, segments })
}

/// A narrow-band line found by [`lines`].
#[derive(Debug, Clone, PartialEq)]
pub struct SpectralLine {
    /// Bin index of the peak.
    pub bin: usize,
    /// Peak frequency, Hz (parabolic interpolation of the log power).
    pub frequency_hz: f64,
    /// Peak power over the running median of its neighbours.
    pub ratio: f64,
}

/// Lines of a Welch PSD: bins whose power exceeds the running median of the `half_width`
/// bins either side (the continuum) by more than the χ² quantile of a Welch estimate at
/// family-wise level `alpha` over the bins searched, and by at least `min_ratio`; bins
/// below `min_hz` are skipped (the slow part of a residual is not a line). One line per
/// local maximum.
pub fn lines(psd: &Psd, half_width: usize, alpha: f64, min_ratio: f64, min_hz: f64) -> Vec<SpectralLine> {
    let n = psd.power.len();
    if n < 2 * half_width + 3 || psd.segments == 0 {
        return Vec::new();
    }
    let first = ((min_hz / psd.df_hz).ceil() as usize).max(1);
    let searched = n.saturating_sub(first + 1).max(1);
    // A Hann window with half overlap keeps about 90 % of the 2K degrees of freedom.
    let dof = (1.8 * psd.segments as f64).max(2.0);
    let threshold = ChiSquared::new(dof)
        .map(|d| d.inverse_cdf(1.0 - alpha / searched as f64) / dof)
        .unwrap_or(f64::INFINITY)
        .max(min_ratio);
    let mut baseline = vec![0.0; n];
    let mut window = Vec::with_capacity(2 * half_width + 1);
    for (k, b) in baseline.iter_mut().enumerate() {
        window.clear();
        let lo = k.saturating_sub(half_width);
        let hi = (k + half_width + 1).min(n);
        // The peak's own bin and its two neighbours (window leakage) left out.
        window.extend((lo..hi).filter(|&j| j + 2 < k || j > k + 2).map(|j| psd.power[j]));
        *b = super::median(&mut window).unwrap_or(0.0);
    }
    let mut out = Vec::new();
    for k in first..n - 1 {
        let p = psd.power[k];
        if baseline[k] <= 0.0 || p < psd.power[k - 1] || p < psd.power[k + 1] {
            continue;
        }
        let ratio = p / baseline[k];
        if ratio > threshold {
            let (l, c, r) = (psd.power[k - 1].ln(), p.ln(), psd.power[k + 1].ln());
            let den = l - 2.0 * c + r;
            let shift = if den < 0.0 { (0.5 * (l - r) / den).clamp(-0.5, 0.5) } else { 0.0 };
            out.push(SpectralLine { bin: k, frequency_hz: (k as f64 + shift) * psd.df_hz, ratio });
        }
    }
    out
}

/// Removes the least-squares sinusoid at `f_hz` (phase from the first stamp) from `x`.
pub fn remove_sinusoid(x: &mut [f64], t_s: &[f64], f_hz: f64) {
    let (a, b) = sinusoid_fit(x, t_s, f_hz);
    let w = std::f64::consts::TAU * f_hz;
    let t0 = t_s.first().copied().unwrap_or(0.0);
    for (v, t) in x.iter_mut().zip(t_s) {
        let (s, c) = (w * (t - t0)).sin_cos();
        *v -= a * c + b * s;
    }
}

/// (sin, cos) of θ + φ from those of θ (`sc`) and of φ (`rot`): one step of the rotations
/// that stand in for a sin_cos per sample or cell here.
#[inline(always)]
fn turn((s, c): (f64, f64), (rs, rc): (f64, f64)) -> (f64, f64) {
    (s * rc + c * rs, c * rc - s * rs)
}

/// The least-squares (a, b) of a cos + b sin at `f_hz` (phase from the first stamp),
/// after removing the mean.
fn sinusoid_fit(x: &[f64], t_s: &[f64], f_hz: f64) -> (f64, f64) {
    sinusoid_fits(x, t_s, [f_hz])[0]
}

/// [`sinusoid_fit`] at `K` frequencies in one pass over the data: the K rotations are
/// independent chains the processor overlaps (each gives the numbers it gives alone).
fn sinusoid_fits<const K: usize>(x: &[f64], t_s: &[f64], f_hz: [f64; K]) -> [(f64, f64); K] {
    let w = f_hz.map(|f| std::f64::consts::TAU * f);
    let n = x.len().min(t_s.len());
    if n < 3 {
        return [(0.0, 0.0); K];
    }
    let mean = x[..n].iter().sum::<f64>() / n as f64;
    let (mut cc, mut ss, mut cs, mut xc, mut xs) = ([0.0; K], [0.0; K], [0.0; K], [0.0; K], [0.0; K]);
    // cos/sin by rotation at the mean step, recomputed exactly every 256 samples (stamps
    // that are not quite regular stay exact at those points): one complex product per
    // sample instead of a sin_cos.
    let step = (t_s[n - 1] - t_s[0]) / (n - 1) as f64;
    let rot = w.map(|w| (w * step).sin_cos());
    let (mut s, mut c) = ([0.0; K], [1.0; K]);
    for k0 in (0..n).step_by(256) {
        for j in 0..K {
            (s[j], c[j]) = (w[j] * (t_s[k0] - t_s[0])).sin_cos();
        }
        for &xk in &x[k0..(k0 + 256).min(n)] {
            let v = xk - mean;
            for j in 0..K {
                let (sj, cj) = (s[j], c[j]);
                cc[j] += cj * cj;
                ss[j] += sj * sj;
                cs[j] += cj * sj;
                xc[j] += v * cj;
                xs[j] += v * sj;
                (s[j], c[j]) = turn((sj, cj), rot[j]);
            }
        }
    }
    std::array::from_fn(|j| {
        let det = cc[j] * ss[j] - cs[j] * cs[j];
        if det.abs() < f64::MIN_POSITIVE {
            (0.0, 0.0)
        } else {
            ((xc[j] * ss[j] - xs[j] * cs[j]) / det, (xs[j] * cc[j] - xc[j] * cs[j]) / det)
        }
    })
}

/// The frequency near `f0_hz` (within ±`half_range_hz`) whose fitted sinusoid in `x` is
/// largest, and that amplitude: a grid at half the record's resolution 1/T, then a search
/// on the best cell to a bracket of 1/(200 T), far below the frequency's own uncertainty.
/// A Welch bin is far wider than 1/T, and a frequency off by more than about 1/(4T) loses
/// the phase over the record.
///
/// The grid is screened on the record demodulated at `f0_hz` and summed over about 2048
/// blocks ([`baseband`]: one pass), the best cell and its neighbours fitted exactly; the
/// search then fits four frequencies per pass ([`sinusoid_fits`]), shrinking the bracket
/// to 2/5 each pass.
pub fn refine_frequency(x: &[f64], t_s: &[f64], f0_hz: f64, half_range_hz: f64) -> (f64, f64) {
    let n = x.len().min(t_s.len());
    if n < 3 {
        return (f0_hz, 0.0);
    }
    let span = (t_s[n - 1] - t_s[0]).max(f64::MIN_POSITIVE);
    let step = 0.5 / span;
    let cells = ((2.0 * half_range_hz / step).ceil() as usize).clamp(1, 400);
    let step = 2.0 * half_range_hz / cells as f64;
    let cell = |i: usize| f0_hz - half_range_hz + i as f64 * step;
    let screen = baseband(&x[..n], &t_s[..n], f0_hz);
    let best_cell = screen
        .amplitudes(cell(0) - f0_hz, step, cells + 1)
        .into_iter()
        .enumerate()
        .fold((0, f64::NEG_INFINITY), |b, (i, a)| if a > b.1 { (i, a) } else { b });
    // The screened cell, its neighbours and f0 itself, fitted exactly.
    let near = [best_cell.0.saturating_sub(1), best_cell.0, (best_cell.0 + 1).min(cells)].map(cell);
    let f = [f0_hz, near[0], near[1], near[2]];
    let (mut best_f, mut best_a) = (f0_hz, f64::NEG_INFINITY);
    for (fj, (a, b)) in f.into_iter().zip(sinusoid_fits(x, t_s, f)) {
        if a.hypot(b) > best_a {
            (best_f, best_a) = (fj, a.hypot(b));
        }
    }
    let (mut lo, mut hi) = (best_f - step, best_f + step);
    for _ in 0..64 {
        if hi - lo <= 0.005 / span {
            break;
        }
        let h = (hi - lo) / 5.0;
        let f: [f64; 4] = std::array::from_fn(|j| lo + (j + 1) as f64 * h);
        for (fj, (a, b)) in f.into_iter().zip(sinusoid_fits(x, t_s, f)) {
            if a.hypot(b) > best_a {
                (best_f, best_a) = (fj, a.hypot(b));
            }
        }
        // The bracket around the best point so far (the previous one when no new point beats it).
        (lo, hi) = (best_f - h, best_f + h);
    }
    (best_f, best_a)
}

/// A record demodulated at one frequency and summed over blocks: the amplitude of a nearby
/// frequency is then a sum over the blocks, not the samples ([`Baseband::amplitudes`]).
struct Baseband {
    /// Per block: the sum of (x − mean)·e^(−iω₀t) and the block's mean time from the first
    /// stamp, s.
    blocks: Vec<([f64; 2], f64)>,
    n: usize,
}

/// [`Baseband`] of `x` at `f0_hz`, in blocks of ⌈n/2048⌉ samples: a frequency δ away turns
/// by at most 2π·δ·(block span)/2 inside a block, 0.025 rad for δ within 16/T.
/// Within a block the demodulating sines turn by rotation at the mean step, exact at its
/// first sample (as in [`sinusoid_fits`]).
fn baseband(x: &[f64], t_s: &[f64], f0_hz: f64) -> Baseband {
    let n = x.len().min(t_s.len());
    let mean = x[..n].iter().sum::<f64>() / n.max(1) as f64;
    let w = std::f64::consts::TAU * f0_hz;
    let size = n.div_ceil(2048).max(1);
    let rot = libm::sincos(w * (t_s[n.max(2) - 1] - t_s[0]) / (n.max(2) - 1) as f64);
    let blocks = (0..n)
        .step_by(size)
        .map(|k0| {
            let k1 = (k0 + size).min(n);
            let (mut re, mut im, mut tm) = (0.0, 0.0, 0.0);
            // cos/sin by rotation at the mean step, exact every 256 samples.
            let mut sc = (0.0, 1.0);
            for k in k0..k1 {
                let dt = t_s[k] - t_s[0];
                if (k - k0) % 256 == 0 {
                    sc = libm::sincos(w * dt);
                }
                let (s, c) = sc;
                re += (x[k] - mean) * c;
                im -= (x[k] - mean) * s;
                tm += dt;
                sc = turn(sc, rot);
            }
            ([re, im], tm / (k1 - k0) as f64)
        })
        .collect();
    Baseband { blocks, n }
}

impl Baseband {
    /// About the amplitudes of the sinusoids δ_i = `first_hz` + i·`step_hz` (i < `cells`)
    /// from the demodulation frequency: 2/n·|Σ_b z_b·e^(−i2πδ_i t_b)| (the fit's amplitude
    /// for a record of many cycles). Per block, e^(−i2πδ_i t_b) turns from one cell to the
    /// next by e^(−i2π·step·t_b): a complex product per block and cell, not a sin_cos.
    fn amplitudes(&self, first_hz: f64, step_hz: f64, cells: usize) -> Vec<f64> {
        let mut sums = vec![[0.0f64; 2]; cells];
        for ([zr, zi], t) in &self.blocks {
            let mut sc = libm::sincos(std::f64::consts::TAU * first_hz * t);
            let rot = libm::sincos(std::f64::consts::TAU * step_hz * t);
            for sum in sums.iter_mut() {
                let (s, c) = sc;
                sum[0] += zr * c + zi * s;
                sum[1] += zi * c - zr * s;
                sc = turn(sc, rot);
            }
        }
        sums.iter().map(|[re, im]| 2.0 * re.hypot(*im) / self.n.max(1) as f64).collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_distr::{Distribution, StandardNormal};
    use std::f64::consts::TAU;

    #[test]
    fn fits_at_several_frequencies_in_one_pass_equal_the_fits_one_at_a_time() {
        let t: Vec<f64> = (0..1000).map(|k| k as f64 * 0.01 + if k % 7 == 0 { 1e-4 } else { 0.0 }).collect();
        let x: Vec<f64> = t.iter().map(|t| (3.1 * t).sin() + 0.3 * (17.0 * t).cos() + 0.01 * t).collect();
        let f = [0.4, 0.5, 2.7, 11.0];
        let one: Vec<(f64, f64)> = f.iter().map(|&f| sinusoid_fit(&x, &t, f)).collect();
        let four = sinusoid_fits(&x, &t, f);
        for (a, b) in one.iter().zip(&four) {
            assert_eq!((a.0.to_bits(), a.1.to_bits()), (b.0.to_bits(), b.1.to_bits()));
        }
        assert!(four[1].0.hypot(four[1].1) > 0.8, "the 0.49 Hz line is seen at 0.5 Hz: {four:?}");
    }

    #[test]
    fn finds_a_line_in_coloured_noise_and_nothing_in_noise_alone() {
        let fs = 200.0;
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(9);
        let n = 60_000;
        let t: Vec<f64> = (0..n).map(|k| k as f64 / fs).collect();
        let mut x = vec![0.0; n];
        for k in 1..n {
            let z: f64 = StandardNormal.sample(&mut rng);
            x[k] = 0.9 * x[k - 1] + z;
        }
        for seed in 0..20 {
            let mut r2 = rand_chacha::ChaCha8Rng::seed_from_u64(100 + seed);
            let mut y = vec![0.0; n];
            for k in 1..n {
                let z: f64 = StandardNormal.sample(&mut r2);
                y[k] = 0.9 * y[k - 1] + z;
            }
            let p = welch(&y, fs, 2048).unwrap();
            assert!(lines(&p, 24, 1e-3, 2.0, 0.5).is_empty(), "seed {seed}");
        }
        // Total variance of the AR(1) is 1/(1 − 0.81) ≈ 5.3; a line of amplitude 0.5 is far below it.
        for (k, v) in x.iter_mut().enumerate() {
            *v += 0.5 * (std::f64::consts::TAU * 7.3 * t[k] + 0.3).sin();
        }
        let p = welch(&x, fs, 2048).unwrap();
        let found = lines(&p, 24, 1e-3, 2.0, 0.5);
        assert_eq!(found.len(), 1, "{found:?}");
        assert!((found[0].frequency_hz - 7.3).abs() < p.df_hz, "{found:?}");
        let (f, a) = refine_frequency(&x, &t, found[0].frequency_hz, p.df_hz);
        assert!((a - 0.5).abs() < 0.05 && (f - 7.3).abs() < 1e-3, "{f} {a}");
    }

    /// The screen's sines turned by rotation are those worked out one by one: from cell to
    /// cell to rounding on any stamps, and within the baseband's blocks to rounding on
    /// regular ones (on stamps that jitter, the blocks are off by the jitter's phase, as the
    /// fits' own rotation is between its exact points).
    #[test]
    fn the_screens_rotated_sines_are_each_ones_own() {
        let n: usize = 20_000;
        let (f0, first, step, cells) = (4.0, -0.05, 1e-3, 101);
        for jitter in [0.0, 2e-6] {
            let t: Vec<f64> = (0..n).map(|k| 3.0 + k as f64 * 0.005 + if k % 11 == 0 { jitter } else { 0.0 }).collect();
            let x: Vec<f64> =
                t.iter().map(|t| 0.7 * (TAU * 4.1 * t).cos() + 0.2 * (TAU * 13.0 * t).sin() + 0.05).collect();
            let screen = baseband(&x, &t, f0);
            let fast = screen.amplitudes(first, step, cells);
            // The cells from the same blocks, each with its own sin_cos.
            for (i, a) in fast.iter().enumerate() {
                let w = TAU * (first + i as f64 * step);
                let (mut re, mut im) = (0.0, 0.0);
                for ([zr, zi], tb) in &screen.blocks {
                    let (s, c) = (w * tb).sin_cos();
                    re += zr * c + zi * s;
                    im += zi * c - zr * s;
                }
                let slow = 2.0 * f64::hypot(re, im) / n as f64;
                assert!((a - slow).abs() <= 1e-12 * fast.iter().copied().fold(0.0, f64::max), "cell {i}: {a} {slow}");
            }
            if jitter > 0.0 {
                continue;
            }
            // The blocks, each sample with its own sin_cos.
            let mean = x.iter().sum::<f64>() / n as f64;
            let size = n.div_ceil(2048);
            for (b, k0) in (0..n).step_by(size).enumerate() {
                let (mut zr, mut zi) = (0.0, 0.0);
                for k in k0..(k0 + size).min(n) {
                    let (s, c) = (TAU * f0 * (t[k] - t[0])).sin_cos();
                    zr += (x[k] - mean) * c;
                    zi -= (x[k] - mean) * s;
                }
                let [fr, fi] = screen.blocks[b].0;
                // The phases reach 2500 rad here: their own rounding is about 5e-13.
                let tol = 1e-11 * zr.hypot(zi).max(1.0);
                assert!((fr - zr).abs() <= tol && (fi - zi).abs() <= tol, "block {b}: {fr} {zr} {fi} {zi}");
            }
        }
    }
}
