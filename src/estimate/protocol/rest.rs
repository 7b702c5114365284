//! Is a declared rest at rest? A multi-position recording's initial rest gives the gyro bias
//! and the detector's noise baseline; if the unit was already moving in it, both are wrong
//! and nothing downstream can tell. The rest is checked against its own noise: the moving
//! variance of both sensors (window = the detector's) against the median over the rest's
//! first half, and the drift of the gyro's block means between the rest's two halves.

use crate::stats::segment::{mean3, moving_variance_norm, var3};

/// A gyro moving variance this many times the rest's own median is motion (for a window of
/// ~50 samples or more the variance estimate scatters by ~20 %: 4× is a > 10σ event).
const GYRO_RATIO: f64 = 4.0;
/// The accelerometer's threshold is higher: a knock on the table or a vibration raises its
/// variance ten-fold without turning the unit (seen in a real board's rest, gyro unmoved);
/// a hand that starts to move raises both.
const ACCEL_RATIO: f64 = 25.0;
/// Block means that differ between the rest's halves by more than this many standard errors
/// are a drift (a slow turn, a bias still settling).
const DRIFT_Z: f64 = 6.0;

/// What was found in a declared rest.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) enum RestCheck {
    /// At rest throughout.
    Still,
    /// Motion from sample `from` on: the rest's still part is `[0, still)`.
    Moving {
        /// First sample of the window that showed the motion.
        from: usize,
        /// Samples before it that are at rest.
        still: usize,
        /// `accelerometer` or `gyro`.
        sensor: &'static str,
        /// The moving variance over the rest's median there (variance), or the drift in
        /// standard errors (drift).
        size: f64,
        /// A change of variance (true) or a drift of the mean (false).
        variance: bool,
    },
}

/// Checks the first `n_rest` samples of a recording (accelerometer and gyro, any units) with
/// the detector's `window`.
pub(super) fn check_rest(accel: &[[f64; 3]], gyro: &[[f64; 3]], n_rest: usize, window: usize) -> RestCheck {
    let w = window | 1;
    let h = w / 2;
    let n_rest = n_rest.min(accel.len()).min(gyro.len());
    if n_rest < 2 * w {
        return RestCheck::Still; // too short to tell its own noise from motion
    }
    // Only the rest and one window beyond it are needed.
    let span = (n_rest + h).min(accel.len());
    let mut first: Option<(usize, &'static str, f64)> = None;
    for (sensor, x, ratio) in [("accelerometer", &accel[..span], ACCEL_RATIO), ("gyro", &gyro[..span], GYRO_RATIO)] {
        let norms = moving_variance_norm(x, w);
        let mut first_half: Vec<f64> =
            norms[h..(n_rest / 2).max(h + 1)].iter().copied().filter(|v| v.is_finite()).collect();
        let Some(reference) = crate::stats::median(&mut first_half) else { continue };
        if reference <= 0.0 {
            continue;
        }
        let hit = (h..n_rest.saturating_sub(h)).find(|&c| norms[c] > ratio * reference);
        if let Some(c) = hit {
            let from = c + h - 1;
            if first.is_none_or(|(f, ..)| from < f) {
                first = Some((from, sensor, norms[c] / reference));
            }
        }
    }
    if let Some((from, sensor, size)) = first {
        return RestCheck::Moving { from, still: from.saturating_sub(w), sensor, size, variance: true };
    }
    drift(gyro, n_rest, w)
}

/// The gyro's mean in the rest's first and second half, in standard errors from the scatter
/// of block means (blocks of one window, so serial correlation within a window is allowed for).
fn drift(gyro: &[[f64; 3]], n_rest: usize, w: usize) -> RestCheck {
    let blocks = block_means(&gyro[..n_rest], w);
    let k = blocks.len();
    if k < 8 {
        return RestCheck::Still;
    }
    let (a, b) = blocks.split_at(k / 2);
    let mut worst = 0.0_f64;
    for i in 0..3 {
        let mean = |s: &[[f64; 3]]| s.iter().map(|v| v[i]).sum::<f64>() / s.len() as f64;
        let (ma, mb) = (mean(a), mean(b));
        let all = mean(&blocks);
        let var = blocks.iter().map(|v| (v[i] - all).powi(2)).sum::<f64>() / (k - 1) as f64;
        // Scatter of block means after the step between the halves is taken out.
        let step = (mb - ma).powi(2) * (a.len() * b.len()) as f64 / (k * (k - 1)) as f64;
        let se = ((var - step).max(var * 0.05) * (1.0 / a.len() as f64 + 1.0 / b.len() as f64)).sqrt();
        if se > 0.0 {
            worst = worst.max((mb - ma).abs() / se);
        }
    }
    if worst > DRIFT_Z {
        RestCheck::Moving { from: (k / 2) * w, still: (k / 2) * w, sensor: "gyro", size: worst, variance: false }
    } else {
        RestCheck::Still
    }
}

/// The noise of a stretch known to be at rest, to judge other stretches (poses, static
/// runs) by: per sensor (accelerometer, gyro) the median moving-variance norm and the
/// scatter of block means (blocks of one window).
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct RestNoise {
    window: usize,
    var: [f64; 2],
    block_sd: [[f64; 3]; 2],
}

/// Median moving-variance norm and per-axis scatter of block means of `x` (one sensor).
fn stretch_noise(x: &[[f64; 3]], w: usize) -> Option<(f64, [f64; 3])> {
    let h = w / 2;
    if x.len() < 4 * w {
        return None;
    }
    let norms = moving_variance_norm(x, w);
    let mut inner: Vec<f64> = norms[h..x.len() - h].iter().copied().filter(|v| v.is_finite()).collect();
    let var = crate::stats::median(&mut inner)?;
    Some((var, var3(&block_means(x, w)).map(f64::sqrt)))
}

/// Means of consecutive blocks of `w` samples (a partial last block is dropped).
pub(super) fn block_means(x: &[[f64; 3]], w: usize) -> Vec<[f64; 3]> {
    x.chunks_exact(w).map(mean3).collect()
}

/// One stretch of samples: (accelerometer, gyro).
pub(super) type Stretch<'a> = (&'a [[f64; 3]], &'a [[f64; 3]]);

/// The noise of each stretch (accelerometer, gyro samples), combined by the median over the
/// stretches that are long enough: a stretch that moves does not set the reference the
/// others are judged by. None when none is long enough.
pub(super) fn rest_noise(stretches: &[Stretch<'_>], window: usize) -> Option<RestNoise> {
    let w = window | 1;
    let mut each: Vec<[f64; 8]> = Vec::new();
    for &(accel, gyro) in stretches {
        let (Some((va, sa)), Some((vg, sg))) = (stretch_noise(accel, w), stretch_noise(gyro, w)) else {
            continue;
        };
        each.push([va, vg, sa[0], sa[1], sa[2], sg[0], sg[1], sg[2]]);
    }
    let med = |j: usize| {
        let mut v: Vec<f64> = each.iter().map(|r| r[j]).collect();
        crate::stats::median(&mut v)
    };
    Some(RestNoise {
        window: w,
        var: [med(0)?, med(1)?],
        block_sd: [[med(2)?, med(3)?, med(4)?], [med(5)?, med(6)?, med(7)?]],
    })
}

/// Whether the interior of `span` (one window in from each end) is at rest by the reference
/// noise: no moving variance above the ratios
/// the declared rest is held to, and no drift of either sensor's mean between the stretch's
/// halves beyond [`DRIFT_Z`] standard errors of the reference's block means. What was found,
/// in words, when it is not.
pub(super) fn check_span(
    accel: &[[f64; 3]],
    gyro: &[[f64; 3]],
    span: (usize, usize),
    noise: &RestNoise,
) -> Option<String> {
    // A detected pose's edges are uncertain by the detector's window (a turn's slow tail
    // looks static to the accelerometer's variance): its interior is judged.
    let w = noise.window;
    let h = w / 2;
    let (s, e) = (span.0 + w, span.1.saturating_sub(w));
    if e <= s + 2 * w {
        return None;
    }
    let sensors = [("accelerometer", &accel[s..e], ACCEL_RATIO), ("gyro", &gyro[s..e], GYRO_RATIO)];
    for (j, (sensor, x, ratio)) in sensors.into_iter().enumerate() {
        let reference = noise.var[j];
        if reference > 0.0 {
            let norms = moving_variance_norm(x, w);
            let worst = norms[h..x.len() - h].iter().copied().filter(|v| v.is_finite()).fold(0.0, f64::max);
            if worst > ratio * reference {
                return Some(format!("{sensor} moving variance {:.0}× the rest's", worst / reference));
            }
        }
        let blocks = block_means(x, w);
        let k = blocks.len();
        if k < 2 {
            continue;
        }
        let (a, b) = blocks.split_at(k / 2);
        for i in 0..3 {
            let mean = |v: &[[f64; 3]]| v.iter().map(|q| q[i]).sum::<f64>() / v.len() as f64;
            let se = noise.block_sd[j][i] * (1.0 / a.len() as f64 + 1.0 / b.len() as f64).sqrt();
            let z = (mean(b) - mean(a)).abs() / se;
            if se > 0.0 && z > DRIFT_Z {
                return Some(format!(
                    "{sensor} mean drifts between its halves ({z:.1} standard errors of the rest's noise)"
                ));
            }
        }
    }
    None
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};

    fn noise(n: usize, seed: u64, s: f64) -> Vec<[f64; 3]> {
        let mut r = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
        (0..n).map(|_| [r.random_range(-s..s), r.random_range(-s..s), r.random_range(-s..s)]).collect()
    }

    #[test]
    fn still_rests_pass_and_motion_is_found_within_a_window() {
        for seed in 0..20 {
            let (a, g) = (noise(3000, seed, 0.01), noise(3000, seed + 100, 0.002));
            assert_eq!(check_rest(&a, &g, 3000, 51), RestCheck::Still, "seed {seed}");
        }
        let (mut a, g) = (noise(3000, 1, 0.01), noise(3000, 2, 0.002));
        for (k, v) in a.iter_mut().enumerate().skip(2000) {
            v[0] += 0.5 * ((k - 2000) as f64 * 0.02).sin();
        }
        match check_rest(&a, &g, 3000, 51) {
            RestCheck::Moving { from, still, sensor, variance, .. } => {
                assert!((1950..=2051).contains(&from), "{from}");
                assert!(still <= 2000 && sensor == "accelerometer" && variance, "{still} {sensor}");
            }
            other => panic!("{other:?}"),
        }
    }

    #[test]
    fn a_slow_gyro_drift_is_found() {
        let a = noise(3000, 3, 0.01);
        let mut g = noise(3000, 4, 0.002);
        for (k, v) in g.iter_mut().enumerate() {
            v[2] += 2e-6 * k as f64; // a slow turn: 0.006 over the rest, noise 0.002
        }
        assert!(matches!(check_rest(&a, &g, 3000, 51), RestCheck::Moving { variance: false, .. }));
    }
}
