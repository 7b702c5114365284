//! A lot's capability on a datasheet quantity (mean, standard deviation, Cpk with its 95 %
//! confidence interval) and the control chart of a quantity across lots.
//!
//! Cpk = min(USL − x̄, x̄ − LSL) / (3 s) over the lot's values (one limit: that side only).
//! Its 95 % interval is Bissell's normal approximation (Bissell 1990, "How reliable is
//! your capability index?", Appl. Statist. 39:331): Ĉpk ± 1.96 √(1/(9n) + Ĉpk²/(2(n − 1))),
//! for normal values.
//!
//! Control chart (Shewhart X̄ and s charts, Montgomery, *Introduction to Statistical Quality
//! Control*, 6.2–6.3) with limits from the earlier lots only: centre x̿ = the earlier lots'
//! pooled mean, σ̂ = their pooled within-lot standard deviation; lot j's mean is out of
//! control outside x̿ ± 3 σ̂ √(1/n_j + 1/N) (N the earlier lots' units: the centre's own
//! uncertainty), its spread when s_j > σ̂ √(χ²₀.₉₉₈₆₅(n_j − 1)/(n_j − 1)) — the two
//! false-alarm rates of a 3σ chart (0.27 %, 0.135 % one-sided).

use serde::{Deserialize, Serialize};
use statrs::distribution::{ChiSquared, ContinuousCDF};

/// The lot's capability on one datasheet rule (and axis).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Capability {
    /// Rule name.
    pub rule: String,
    /// Datasheet quantity.
    pub quantity: String,
    /// Axis.
    pub axis: String,
    /// Datasheet unit.
    pub unit: String,
    /// Units with a value.
    pub n: usize,
    /// Lot mean.
    pub mean: f64,
    /// Lot standard deviation (n − 1).
    pub std: f64,
    /// Lower specification limit (a magnitude rule's −max).
    pub lsl: Option<f64>,
    /// Upper specification limit.
    pub usl: Option<f64>,
    /// Cpk (None with fewer than 2 units or no spread).
    pub cpk: Option<f64>,
    /// Lower end of its 95 % interval.
    pub cpk_low: Option<f64>,
    /// Upper end.
    pub cpk_high: Option<f64>,
    /// Units that pass on this axis.
    pub pass: usize,
    /// Units that fail.
    pub fail: usize,
    /// Units whose decision is indeterminate.
    pub indeterminate: usize,
}

/// Mean, standard deviation (n − 1), Cpk and its 95 % Bissell interval of `values` against
/// the limits; None with fewer than 2 values.
pub fn cpk(values: &[f64], lsl: Option<f64>, usl: Option<f64>) -> Option<(f64, f64, Option<[f64; 3]>)> {
    let n = values.len();
    if n < 2 {
        return None;
    }
    let mean = values.iter().sum::<f64>() / n as f64;
    let sd = (values.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (n - 1) as f64).sqrt();
    let sides = [usl.map(|u| u - mean), lsl.map(|l| mean - l)];
    let nearest = sides.iter().flatten().copied().reduce(f64::min);
    let c = match nearest {
        Some(d) if sd > 0.0 => {
            let c = d / (3.0 * sd);
            let se = (1.0 / (9.0 * n as f64) + c * c / (2.0 * (n - 1) as f64)).sqrt();
            Some([c, c - 1.96 * se, c + 1.96 * se])
        }
        _ => None,
    };
    Some((mean, sd, c))
}

/// One lot's statistics of one quantity and axis, as stored for the control chart.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct LotPoint {
    /// Lot name.
    pub lot: String,
    /// When the lot was processed, RFC 3339.
    pub created_utc: String,
    /// Units.
    pub n: usize,
    /// Mean.
    pub mean: f64,
    /// Standard deviation.
    pub std: f64,
}

/// A lot on the control chart, judged against the limits of the lots before it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ChartPoint {
    /// The lot.
    #[serde(flatten)]
    pub point: LotPoint,
    /// Limits from the earlier lots: [lower, centre, upper] of the mean; None for the first.
    pub mean_limits: Option<[f64; 3]>,
    /// Upper limit of the standard deviation.
    pub std_upper: Option<f64>,
    /// The mean is outside its limits: a process shift at this lot.
    pub shifted: bool,
    /// The spread is above its limit.
    pub spread_up: bool,
}

/// The control chart of a series of lots (oldest first).
pub fn control_chart(series: &[LotPoint]) -> Vec<ChartPoint> {
    series
        .iter()
        .enumerate()
        .map(|(j, p)| {
            let before: Vec<&LotPoint> = series[..j].iter().filter(|q| q.n >= 2).collect();
            let units: usize = before.iter().map(|q| q.n).sum();
            let dof: usize = before.iter().map(|q| q.n - 1).sum();
            if before.is_empty() || dof == 0 || p.n < 2 {
                return ChartPoint {
                    point: p.clone(),
                    mean_limits: None,
                    std_upper: None,
                    shifted: false,
                    spread_up: false,
                };
            }
            let centre = before.iter().map(|q| q.n as f64 * q.mean).sum::<f64>() / units as f64;
            let sigma = (before.iter().map(|q| (q.n - 1) as f64 * q.std * q.std).sum::<f64>() / dof as f64).sqrt();
            let half = 3.0 * sigma * (1.0 / p.n as f64 + 1.0 / units as f64).sqrt();
            let k = (p.n - 1) as f64;
            let std_upper = ChiSquared::new(k).ok().map(|c| sigma * (c.inverse_cdf(0.99865) / k).sqrt());
            ChartPoint {
                point: p.clone(),
                mean_limits: Some([centre - half, centre, centre + half]),
                std_upper,
                shifted: (p.mean - centre).abs() > half,
                spread_up: std_upper.is_some_and(|u| p.std > u),
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cpk_of_a_centred_lot() {
        // Values ±1 around 0: s = √(n/(n−1)); limits ±3 → Cpk = 3/(3s).
        let v: Vec<f64> = (0..40).map(|i| if i % 2 == 0 { 1.0 } else { -1.0 }).collect();
        let (m, s, c) = cpk(&v, Some(-3.0), Some(3.0)).unwrap();
        let [c, lo, hi] = c.unwrap();
        assert!(m.abs() < 1e-12 && (s - (40.0f64 / 39.0).sqrt()).abs() < 1e-12);
        assert!((c - 1.0 / s).abs() < 1e-12 && lo < c && hi > c);
    }
}
