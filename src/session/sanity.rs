//! Signal sanity: saturation (flat tops at the channel's extreme) and spikes (isolated
//! samples far from their neighbours), reported with their sample positions.

/// Channel names in recording order.
const CHANNELS: [&str; 6] = ["gx", "gy", "gz", "ax", "ay", "az"];

/// Consecutive samples at the channel's extreme that count as a flat top.
pub const SATURATION_RUN: usize = 5;
/// Robust z-score above which a sample is a spike.
pub const SPIKE_Z: f64 = 12.0;

/// What the scan found in one channel.
#[derive(Debug, Clone, PartialEq)]
pub enum Finding {
    /// Flat runs at the channel's maximum or minimum.
    Saturation {
        /// Channel name.
        channel: &'static str,
        /// The clipped value (as recorded, SI-converted).
        value: f64,
        /// Samples at that value in flat runs.
        samples: usize,
        /// Index of the first flat sample (0-based).
        first: usize,
    },
    /// Isolated outliers.
    Spikes {
        /// Channel name.
        channel: &'static str,
        /// Indices (0-based) of the first few spikes.
        at: Vec<usize>,
        /// Total number.
        count: usize,
    },
}

/// Scans the six sensor channels of a recording.
pub fn scan(gyro: &[[f64; 3]], accel: &[[f64; 3]]) -> Vec<Finding> {
    let mut out = Vec::new();
    let mut buf = Vec::with_capacity(gyro.len());
    for (c, name) in CHANNELS.iter().enumerate() {
        buf.clear();
        let src = if c < 3 { gyro } else { accel };
        buf.extend(src.iter().map(|v| v[c % 3]));
        if let Some(f) = saturation(&buf, name) {
            out.push(f);
        }
        if let Some(f) = spikes(&buf, name) {
            out.push(f);
        }
    }
    out
}

fn saturation(x: &[f64], channel: &'static str) -> Option<Finding> {
    let (lo, hi) = x.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &v| (a.min(v), b.max(v)));
    if x.len() < SATURATION_RUN || hi <= lo {
        return None;
    }
    for target in [hi, lo] {
        let (mut samples, mut first, mut run) = (0usize, None, 0usize);
        for (k, &v) in x.iter().enumerate() {
            #[allow(clippy::float_cmp)]
            let at = v == target;
            if at {
                run += 1;
                if run == SATURATION_RUN {
                    samples += SATURATION_RUN;
                    first.get_or_insert(k + 1 - SATURATION_RUN);
                } else if run > SATURATION_RUN {
                    samples += 1;
                }
            } else {
                run = 0;
            }
        }
        if let Some(first) = first {
            return Some(Finding::Saturation { channel, value: target, samples, first });
        }
    }
    None
}

/// Median (upper middle for an even count) by selection, reordering `v`; 0 when empty.
pub fn median(v: &mut [f64]) -> f64 {
    if v.is_empty() {
        return 0.0;
    }
    let mid = v.len() / 2;
    *v.select_nth_unstable_by(mid, f64::total_cmp).1
}

fn spikes(x: &[f64], channel: &'static str) -> Option<Finding> {
    let n = x.len();
    if n < 7 {
        return None;
    }
    // Second differences: O(dt² x'') on smooth motion, −2A at a spike of height A.
    let d2: Vec<f64> = (1..n - 1).map(|k| x[k - 1] - 2.0 * x[k] + x[k + 1]).collect();
    let mut tmp = d2.clone();
    let centre = median(&mut tmp);
    let mut abs: Vec<f64> = d2.iter().map(|v| (v - centre).abs()).collect();
    let scale = 1.4826 * median(&mut abs);
    let (lo, hi) = x.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &v| (a.min(v), b.max(v)));
    let floor = 1e-6 * (hi - lo).max(f64::MIN_POSITIVE);
    let limit = (SPIKE_Z * scale).max(floor);
    // A spike at k shows as the largest |d2| at k (twice its neighbours'): report local maxima.
    let mut at = Vec::new();
    for j in 0..d2.len() {
        let v = (d2[j] - centre).abs();
        if v > limit {
            let left = if j > 0 { (d2[j - 1] - centre).abs() } else { 0.0 };
            let right = if j + 1 < d2.len() { (d2[j + 1] - centre).abs() } else { 0.0 };
            if v >= left && v >= right {
                at.push(j + 1);
            }
        }
    }
    if at.is_empty() {
        return None;
    }
    Some(Finding::Spikes { channel, count: at.len(), at: at.into_iter().take(10).collect() })
}

/// Human-readable lines for findings, naming sample numbers and times.
pub fn describe(findings: &[Finding], t_s: &[f64], file: &str) -> Vec<String> {
    findings
        .iter()
        .map(|f| match f {
            Finding::Saturation {
                channel,
                value,
                samples,
                first,
            } => format!(
                "{file}: channel {channel} looks saturated: {samples} samples flat at its extreme {value:e} (SI), first at sample {} (t = {} s); the fit will be biased there",
                first + 1,
                t_s.get(*first).copied().unwrap_or(f64::NAN)
            ),
            Finding::Spikes { channel, at, count } => format!(
                "{file}: channel {channel} has {count} spike(s) (more than {SPIKE_Z} robust σ from their neighbours), at samples {}; consider --robust",
                at.iter()
                    .map(|k| format!("{} (t = {} s)", k + 1, t_s.get(*k).copied().unwrap_or(f64::NAN)))
                    .collect::<Vec<_>>()
                    .join(", ")
            ),
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sine(n: usize, noise: bool) -> Vec<[f64; 3]> {
        (0..n)
            .map(|k| {
                let t = k as f64 * 0.01;
                // Pseudo-random noise (an LCG), uniform in ±0.5e-3.
                let e = if noise {
                    1e-3 * ((((k as u64 + 1) * 6364136223846793005) >> 40) as f64 / (1u64 << 24) as f64 - 0.5)
                } else {
                    0.0
                };
                [t.sin() + e, (0.5 * t).cos() + e, 0.3]
            })
            .collect()
    }

    #[test]
    fn clean_signals_raise_nothing() {
        for noise in [false, true] {
            let g = sine(3000, noise);
            assert!(scan(&g, &g).is_empty(), "{:?}", scan(&g, &g));
        }
    }

    #[test]
    fn finds_clipping_and_spikes() {
        let mut g = sine(3000, true);
        for v in g.iter_mut() {
            v[0] = v[0].min(0.9);
        }
        g[1234][1] += 5.0;
        let f = scan(&g, &sine(3000, true));
        assert!(f.iter().any(|f| matches!(f, Finding::Saturation { channel: "gx", .. })), "{f:?}");
        assert!(
            f.iter().any(|f| matches!(f, Finding::Spikes { channel: "gy", at, .. } if at.contains(&1234))),
            "{f:?}"
        );
    }
}
