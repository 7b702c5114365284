//! Leaf layer: the statistics and numerical kernels every other layer shares — one median,
//! one robust scale, the chi-square quantiles, autocovariances and the long-run variance,
//! harmonic regression on a phase, the streamed QR factor, and the smoothed rate of change
//! of a temperature reading.
//!
//! Nothing here knows about sessions, motions or models: inputs are plain slices.

pub mod ar;
pub mod autocov;
pub mod gram;
pub mod harmonics;
pub mod kernels;
pub mod qr;
pub mod segment;
pub mod spectrum;
pub mod temp_rate;

pub use ar::ArModel;
pub use autocov::{dot, newey_west_lags, AutoCov, LongRunVariance};
pub use harmonics::{chi2_999, chi2_upper, systematic, PhaseLine, Systematic};
pub use qr::QrAccumulator;

/// 1/Φ⁻¹(3/4) = 1.482602…, to the four digits in common use: the factor that turns a
/// median absolute deviation into the standard deviation of Gaussian data.
pub const MAD_TO_SIGMA: f64 = 1.4826;

/// `range` ([lowest, highest]) widened to hold `x`; a non-finite `x` leaves it as it is.
pub fn widen(range: Option<[f64; 2]>, x: f64) -> Option<[f64; 2]> {
    if !x.is_finite() {
        return range;
    }
    Some(range.map_or([x, x], |[lo, hi]| [lo.min(x), hi.max(x)]))
}

/// The median of `v` by selection (O(n), reorders `v`): for an even count the upper of the
/// two middle values (element n/2 of the sorted values), so that every median in crosscal
/// is one of the data and the same whatever the caller. `None` when `v` is empty.
pub fn median(v: &mut [f64]) -> Option<f64> {
    if v.is_empty() {
        return None;
    }
    let mid = v.len() / 2;
    Some(*v.select_nth_unstable_by(mid, f64::total_cmp).1)
}

/// The Euclidean length of a 3-vector.
#[inline]
pub fn norm3(v: [f64; 3]) -> f64 {
    (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt()
}

/// Robust standard deviation of `v` about `centre`: [`MAD_TO_SIGMA`] times the median of
/// |v − centre| (reorders a copy); `None` when `v` is empty.
pub fn robust_sigma(v: &[f64], centre: f64) -> Option<f64> {
    let mut dev: Vec<f64> = v.iter().map(|x| (x - centre).abs()).collect();
    median(&mut dev).map(|m| MAD_TO_SIGMA * m)
}

/// The SVD of `m` when every entry is finite and the iteration converges (nalgebra's
/// `svd` iterates without end on NaN or infinity: a hostile input must not hang a fit).
pub fn svd(
    m: nalgebra::DMatrix<f64>,
    want_u: bool,
    want_v: bool,
) -> Option<nalgebra::SVD<f64, nalgebra::Dyn, nalgebra::Dyn>> {
    if !m.iter().all(|x| x.is_finite()) {
        return None;
    }
    let iterations = 100 * m.nrows().max(m.ncols()).max(1);
    nalgebra::SVD::try_new(m, want_u, want_v, 5.0 * f64::EPSILON, iterations)
}

/// Singular values of a 3×3 matrix (None when it is not finite or does not converge).
pub fn singular_values3(m: &nalgebra::Matrix3<f64>) -> Option<nalgebra::Vector3<f64>> {
    if !m.iter().all(|x| x.is_finite()) {
        return None;
    }
    nalgebra::SVD::try_new(*m, false, false, 5.0 * f64::EPSILON, 300).map(|s| s.singular_values)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn median_is_the_upper_middle_value_and_none_when_empty() {
        assert_eq!(median(&mut []), None);
        assert_eq!(median(&mut [3.0]), Some(3.0));
        assert_eq!(median(&mut [4.0, 1.0, 3.0, 2.0]), Some(3.0));
        assert_eq!(median(&mut [5.0, 1.0, 3.0]), Some(3.0));
        let s = robust_sigma(&[1.0, -1.0, 1.0, -1.0], 0.0).unwrap();
        assert!((s - MAD_TO_SIGMA).abs() < 1e-15);
        assert!((MAD_TO_SIGMA - 1.0 / 0.674_489_750_196_081_7).abs() < 1e-4);
    }
}
