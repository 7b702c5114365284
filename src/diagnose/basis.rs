//! The per-run systematic basis of a diagnosis ([`super::space`], step 1): Legendre
//! polynomials P0…P3 of the run's time and, for a conic run, the cone harmonics it turns
//! through; and the phase fold that takes every harmonic of the cone beyond them from the
//! noise (step 2).

use crate::motion::cone_phase;
use crate::motion::stand::NearTrig;
use crate::session::MotionSpec;
use crate::stats::PhaseLine;

/// Cone harmonics in the per-run systematic basis.
pub const HARMONICS: usize = 6;
/// Legendre polynomials (degree 0…3) in the per-run systematic basis.
const LEGENDRE: usize = 4;

/// The basis functions at one sample: Legendre P0…P3 of s ∈ [−1, 1], then cos hθ, sin hθ.
/// `trig`: sin θ and cos θ of the cone phase (None: no harmonics).
#[inline(always)]
fn basis_row(s: f64, trig: Option<(f64, f64)>, first: usize, out: &mut [f64]) {
    out[0] = 1.0;
    out[1] = s;
    out[2] = 0.5 * (3.0 * s * s - 1.0);
    out[3] = 0.5 * (5.0 * s * s * s - 3.0 * s);
    if let Some((s1, c1)) = trig {
        // cos hθ, sin hθ by the angle-addition recurrence from the first harmonic's (the
        // recurrence's rounding stays near 1e-15 at these h).
        let (mut sn, mut cs) = (0.0, 1.0);
        for h in 1..=HARMONICS {
            (sn, cs) = (sn * c1 + cs * s1, cs * c1 - sn * s1);
            if h >= first {
                out[LEGENDRE + 2 * (h - first)] = cs;
                out[LEGENDRE + 2 * (h - first) + 1] = sn;
            }
        }
    }
}

/// The systematic basis of one run: Legendre P0…P3 of time scaled to [−1, 1], and for a
/// conic run the cone harmonics that complete at least 0.9 cycles over it (fewer are slow
/// variations there, which the Legendre part holds; keeping them would make the basis
/// nearly singular).
#[derive(Debug, Clone, Copy)]
pub struct RunBasis {
    t0: f64,
    half: f64,
    pub(super) phase: Option<PhaseLine>,
    /// Lowest harmonic.
    pub first: usize,
    /// Number of basis functions.
    pub size: usize,
}

impl RunBasis {
    /// The basis of a run with stamps `t` and declared motion.
    pub fn new(t: &[f64], motion: &MotionSpec) -> Self {
        let phase = cone_phase(motion);
        let (t0, t1) = (t.first().copied().unwrap_or(0.0), t.last().copied().unwrap_or(0.0));
        let revolutions = phase.map_or(0.0, |p| p.rate_rad_s.abs() * (t1 - t0) / std::f64::consts::TAU);
        let first = (1..=HARMONICS).find(|&h| h as f64 * revolutions >= 0.9).unwrap_or(HARMONICS + 1);
        let phase = phase.filter(|_| first <= HARMONICS);
        let size = if phase.is_some() { LEGENDRE + 2 * (HARMONICS + 1 - first) } else { LEGENDRE };
        Self { t0, half: 0.5 * (t1 - t0).max(f64::MIN_POSITIVE), phase, first, size }
    }

    /// The basis functions at time `t_s`.
    #[inline]
    pub fn row(&self, t_s: f64, out: &mut [f64]) {
        basis_row((t_s - self.t0) / self.half - 1.0, self.phase.map(|p| libm::sincos(p.theta(t_s))), self.first, out);
    }

    /// The rows at stamps `t` into the column-major block `out` (leading dimension `ld`:
    /// function b of sample i at `out[b·ld + i]`), a function at a time over the samples;
    /// `scratch` holds the phase's sines and the harmonics' recurrence. [`Self::row`]'s
    /// numbers to a unit in the last place: the phase's sines are walked from sample to
    /// sample ([`NearTrig`], a libm sine every 0.05 rad of the phase), the rest is the same
    /// arithmetic.
    pub fn rows_into(&self, t: &[f64], scratch: &mut Vec<f64>, out: &mut [f64], ld: usize) {
        let len = t.len().min(ld);
        if out.len() < (self.size.max(1) - 1) * ld + len {
            return;
        }
        let (t0, half) = (self.t0, self.half);
        for (o, &ti) in out[ld..ld + len].iter_mut().zip(t) {
            *o = (ti - t0) / half - 1.0;
        }
        out[..len].fill(1.0);
        let (low, high) = out.split_at_mut(2 * ld);
        let s_col = &low[ld..ld + len];
        for (o, &s) in high[..len].iter_mut().zip(s_col) {
            *o = 0.5 * (3.0 * s * s - 1.0);
        }
        for (o, &s) in high[ld..ld + len].iter_mut().zip(s_col) {
            *o = 0.5 * (5.0 * s * s * s - 3.0 * s);
        }
        let Some(phase) = self.phase else { return };
        // sin θ, cos θ of the first harmonic, then sin hθ, cos hθ by the angle-addition
        // recurrence (basis_row's), harmonic after harmonic over the block.
        scratch.clear();
        scratch.resize(4 * len, 0.0);
        let (first, running) = scratch.split_at_mut(2 * len);
        let (s1, c1) = first.split_at_mut(len);
        let mut trig = NearTrig::default();
        for ((s, c), &ti) in s1.iter_mut().zip(c1.iter_mut()).zip(t) {
            (*s, *c) = trig.of(phase.theta(ti));
        }
        let (sn, cs) = running.split_at_mut(len);
        cs.fill(1.0);
        for h in 1..=HARMONICS {
            for i in 0..len {
                (sn[i], cs[i]) = (sn[i] * c1[i] + cs[i] * s1[i], cs[i] * c1[i] - sn[i] * s1[i]);
            }
            if h >= self.first {
                let col = LEGENDRE + 2 * (h - self.first);
                out[col * ld..col * ld + len].copy_from_slice(cs);
                out[(col + 1) * ld..(col + 1) * ld + len].copy_from_slice(sn);
            }
        }
    }

    /// Bins of the phase fold of a run of `n` samples: at least 16 samples a bin, and none
    /// unless the run turns [`FOLD_REVOLUTIONS`] times (a bin seen once is a stretch of the
    /// run, and its mean the slow noise there, not what follows the phase).
    pub fn fold_bins(&self, n: usize) -> usize {
        let revolutions = self.phase.map_or(0.0, |p| p.rate_rad_s.abs() * 2.0 * self.half / std::f64::consts::TAU);
        let bins = if revolutions >= FOLD_REVOLUTIONS { FOLD_BINS.min(n / 16) } else { 0 };
        if bins > 2 * HARMONICS + 1 {
            bins
        } else {
            0
        }
    }

    /// The cone frequency, Hz (None unless the basis has harmonics).
    pub fn cone_hz(&self) -> Option<f64> {
        self.phase.map(|p| p.rate_rad_s.abs() / std::f64::consts::TAU)
    }
}

/// Phase bins of the fold of a conic run's noise (module documentation, step 2).
pub const FOLD_BINS: usize = 64;
// A sample's bin is kept in a byte.
const _: () = assert!(FOLD_BINS <= 256);
/// Revolutions a run needs for its fold: each bin's mean then averages that many passes.
pub const FOLD_REVOLUTIONS: f64 = 3.0;

/// The mean of a series per bin of the cone phase, removed: every harmonic of the cone up
/// to about half the bins at once.
pub(super) struct PhaseFold {
    sum: Vec<f64>,
    count: Vec<f64>,
}

impl PhaseFold {
    pub(super) fn new(bins: usize) -> Self {
        Self { sum: vec![0.0; bins], count: vec![0.0; bins] }
    }

    fn bin(&self, theta: f64) -> usize {
        let b = self.sum.len();
        ((theta.rem_euclid(std::f64::consts::TAU) / std::f64::consts::TAU * b as f64) as usize).min(b - 1)
    }

    /// The bin of each stamp of `t` (none without bins).
    pub(super) fn bins(&self, t: &[f64], phase: PhaseLine) -> Vec<u8> {
        if self.sum.is_empty() {
            return Vec::new();
        }
        t.iter().map(|&tk| self.bin(phase.theta(tk)) as u8).collect()
    }

    /// Removes each bin's mean from `x`, whose samples fall in bins `bins` ([`Self::bins`];
    /// nothing when empty).
    pub(super) fn remove(&mut self, x: &mut [f64], bins: &[u8]) {
        if self.sum.is_empty() || bins.len() < x.len() {
            return;
        }
        self.sum.iter_mut().for_each(|v| *v = 0.0);
        self.count.iter_mut().for_each(|v| *v = 0.0);
        for (v, &b) in x.iter().zip(bins) {
            self.sum[b as usize] += v;
            self.count[b as usize] += 1.0;
        }
        for (s, c) in self.sum.iter_mut().zip(&self.count) {
            *s /= c.max(1.0);
        }
        for (v, &b) in x.iter_mut().zip(bins) {
            *v -= self.sum[b as usize];
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_blocks_rows_are_each_samples_row() {
        let t: Vec<f64> = (0..700).map(|k| 3.0 + 0.1 * k as f64 + 1e-3 * (k as f64 * 0.3).sin()).collect();
        let conic = |rate_deg_s| MotionSpec::Conic { cone_angle_deg: 10.0, rate_deg_s, phase_deg: 30.0 };
        let rest = MotionSpec::Static { up_stand: [0.0, 0.0, 1.0], earth_rate_rad_s: [0.0; 3] };
        // No harmonics; all six (20 °/s over 70 s); the fifth and sixth (1 °/s).
        for (motion, first) in [(rest, HARMONICS + 1), (conic(20.0), 1), (conic(-1.0), 5)] {
            let b = RunBasis::new(&t, &motion);
            assert_eq!(b.first, first);
            let ld = 300;
            let (mut out, mut scratch, mut row) = (vec![f64::NAN; b.size * ld], Vec::new(), vec![0.0; b.size]);
            for k0 in (0..t.len()).step_by(ld) {
                let block = &t[k0..(k0 + ld).min(t.len())];
                b.rows_into(block, &mut scratch, &mut out, ld);
                for (i, &ti) in block.iter().enumerate() {
                    b.row(ti, &mut row);
                    for (f, v) in row.iter().enumerate() {
                        assert!((out[f * ld + i] - v).abs() <= 1e-14, "function {f} at {ti}: {} {v}", out[f * ld + i]);
                    }
                }
            }
        }
    }
}
