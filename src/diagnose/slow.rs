//! Slow noise in the diagnosis: flicker and bias random walk as a random effect on each
//! run's slow basis.
//!
//! The AR model of a run's noise is fitted to what the run's systematic basis leaves
//! ([`super::space`]), so it never sees the noise's power below a few cycles per run. A
//! wandering bias puts exactly there a different offset, slope and curvature in every run:
//! "locked to nothing" (not to the cone phase, the rate, the direction of gravity, nor one
//! law of the session clock or the temperature shared by the runs), it is noise, and the
//! evidence must treat it as such.
//!
//! The fit measures the slow part of each channel's residual (white density, bias
//! instability B, random walk K: [`crate::estimate::slow`]). Projected on a run's basis
//! (ordinary least squares, P = (BᵀB)⁻¹Bᵀ, over pieces of the run), it gives the covariance
//! D = P Σ_slow Pᵀ of the run's basis coefficients that the slow noise alone produces; for
//! the random walk the variogram is centred on the session (the bias is fitted once, so a
//! run's offset is measured against the session's average: + K² span/6).
//!
//! The noise of a run is then AR noise plus B c with c ~ (0, D). The systematic test (is
//! anything left beyond the noise?) measures the basis's cross products z = Bᵀ(r − Xβ)
//! (whitened) in the metric of their covariance G_bb + G_bb D G_bb. The stand's systems
//! carry the random effect in their Grams (generalised least squares, Woodbury:
//! G_xx − G_xb D (I + G_bb D)⁻¹ G_bx), so that a run's wandering offset is not taken for the
//! Earth's rate or a tilt. Catalogue candidates keep the AR Grams: their own rules (gain on
//! left-out runs, one size in every run) already refuse what wanders, and the slow noise is
//! measured on the base model's residual, where a missing effect's per-run offsets would
//! otherwise be taken for noise and hide it; each step's refit measures it again.
//!
//! Only with `FitOptions::slow_noise` (`diagnose --slow-noise`): without it the fit measures
//! no slow noise and D is zero.

use crate::estimate::slow::SlowNoise;
use nalgebra::{DMatrix, DVector};

/// Pieces a run is cut into for the projection (at most; at least 16 per cone cycle of the
/// highest harmonic where the run is long).
const MAX_PIECES: usize = 512;

/// A run's basis functions as this module needs them (the diagnosis's run basis,
/// [`super::space`], passed down).
pub struct Basis<'a> {
    /// Number of basis functions.
    pub size: usize,
    /// The cone frequency, Hz (None without cone harmonics).
    pub cone_hz: Option<f64>,
    /// The basis functions at a time, s.
    pub row: &'a dyn Fn(f64, &mut [f64]),
}

/// Per channel the covariance D of one run's basis coefficients under the slow noise
/// `slow[c]` (None or no slow part: zero). `t` are the run's stamps, `basis_ms` = BᵀB/n,
/// `span_s` the session's length.
pub fn basis_covariances(
    basis: &Basis<'_>,
    t: &[f64],
    basis_ms: &DMatrix<f64>,
    slow: &[Option<SlowNoise>],
    span_s: f64,
) -> Vec<DMatrix<f64>> {
    let nb = basis.size;
    let zero = || DMatrix::<f64>::zeros(nb, nb);
    let n = t.len();
    if n < 2 || slow.iter().all(|s| s.is_none_or(|s| !s.is_slow())) {
        return (0..slow.len()).map(|_| zero()).collect();
    }
    let cycles = basis.cone_hz.map_or(0.0, |f| f * (t[n - 1] - t[0]));
    let pieces = ((16.0 * super::HARMONICS as f64 * cycles) as usize).clamp(32, MAX_PIECES).min(n);
    // Per piece: centre, length, samples, and n_p × the basis at the centre.
    let mut w = DMatrix::<f64>::zeros(nb, pieces);
    let mut at = Vec::with_capacity(pieces);
    let mut row = vec![0.0; nb];
    for p in 0..pieces {
        let (k0, k1) = (p * n / pieces, ((p + 1) * n / pieces).max(p * n / pieces + 1).min(n));
        let m = k1 - k0;
        let (a, b) = (t[k0], t[k1 - 1]);
        let dt = if m > 1 { (b - a) / (m - 1) as f64 } else { (t[n - 1] - t[0]) / (n - 1) as f64 };
        at.push((0.5 * (a + b), dt * m as f64));
        // The basis averaged over the piece (its ends and middle, Simpson's rule).
        for (wt, s) in [(1.0 / 6.0, a), (4.0 / 6.0, 0.5 * (a + b)), (1.0 / 6.0, b)] {
            (basis.row)(s, &mut row);
            for i in 0..nb {
                w[(i, p)] += wt * m as f64 * row[i];
            }
        }
    }
    let btb = basis_ms * n as f64;
    let Some(pinv) = btb.clone().try_inverse().or_else(|| btb.pseudo_inverse(1e-12).ok()) else {
        return (0..slow.len()).map(|_| zero()).collect();
    };
    let proj = &pinv * &w;
    // The flicker down to the pieces: the basis's harmonics sit at frequencies the fit's
    // blocks (longer on a long session) may not resolve.
    let shortest = at.iter().map(|a| a.1).filter(|l| *l > 0.0).fold(f64::INFINITY, f64::min);
    slow.iter()
        .map(|s| {
            let Some(s) = s.filter(SlowNoise::is_slow) else { return zero() };
            let kernel = s.kernel_down_to(shortest, span_s);
            let centre = kernel.walk2() * span_s / 6.0;
            let mut blocks: Vec<(DVector<f64>, (f64, f64))> =
                proj.column_iter().zip(&at).map(|(c, t)| (c.into_owned(), *t)).collect();
            let total: DVector<f64> = proj.column_sum();
            kernel.sandwich(&mut blocks) + centre * &total * total.transpose()
        })
        .collect()
}

/// Replaces the columns' and residual's block of a run's channel Gram
/// `[columns (width) | basis (nb) | r]` by its value under the random effect D on the basis
/// (module documentation); the basis rows and columns are kept as they are.
pub fn adjust_gram(g: &mut DMatrix<f64>, width: usize, nb: usize, d: &DMatrix<f64>) {
    if nb == 0 || d.iter().all(|v| *v == 0.0) {
        return;
    }
    let m = g.nrows();
    let x: Vec<usize> = (0..width).chain(std::iter::once(m - 1)).collect();
    let gbb = g.view((width, width), (nb, nb)).into_owned();
    let Some(inv) = (DMatrix::identity(nb, nb) + &gbb * d).try_inverse() else { return };
    let h = d * inv;
    let gxb = DMatrix::from_fn(x.len(), nb, |i, j| g[(x[i], width + j)]);
    let corr = &gxb * h * gxb.transpose();
    for (i, &xi) in x.iter().enumerate() {
        for (j, &xj) in x.iter().enumerate() {
            g[(xi, xj)] -= corr[(i, j)];
        }
    }
}

/// The metric of a run's basis cross products under AR plus slow noise: G_bb + G_bb D G_bb.
pub fn basis_metric(gbb: &DMatrix<f64>, d: &DMatrix<f64>) -> DMatrix<f64> {
    gbb + gbb * d * gbb
}
