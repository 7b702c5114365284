//! Noise characterisation of static recordings: overlapping Allan deviation per channel
//! ([`allan`]) and the IEEE Std 952-1997 (annex C) noise terms read off it.
//!
//! The Allan variance of the sum of independent noise processes is the sum of theirs
//! (IEEE 952 eq. C.17 and table C.1):
//!
//! σ²(τ) = 3Q²/τ² + N²/τ + (2 ln 2/π) B² + K²τ/3 + R²τ²/2
//!
//! Q quantisation (rate·s), N white-noise density (rate/√Hz: angle or velocity random
//! walk), B bias instability (rate; the flat part of σ is 0.664 B), K rate random walk
//! (rate/√s), R rate ramp (rate/s). The five coefficients are fitted to σ²(τ) by
//! non-negative weighted least squares, each cluster time weighted by its equivalent
//! degrees of freedom (var σ̂² ≈ 2σ⁴/edf). A term is reported only where it is visible: it
//! carries at least half of the fitted σ² at some measured cluster time.
//!
//! Units: SI inside (rad/s for the gyro, m/s² for the accelerometer); [`ChannelNoise`]
//! gives display values in the units engineers quote (°/√h, °/h, µg/√Hz, m/s/√h).

pub mod allan;
pub mod report;

use crate::units::SensorKind;
use allan::NoiseType;
use serde::{Deserialize, Serialize};

/// Names of the six channels, in order gx, gy, gz, ax, ay, az.
pub const CHANNELS: [&str; 6] = ["gx", "gy", "gz", "ax", "ay", "az"];

/// Two-sided confidence level of the reported intervals (1σ).
pub const LEVEL: f64 = 0.683;

/// Settings of an analysis.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct NoiseOptions {
    /// Largest cluster time, s (None: a third of the recording).
    pub max_tau_s: Option<f64>,
}

/// One point of an Allan deviation curve.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct AdevPoint {
    /// Cluster time τ, s.
    pub tau_s: f64,
    /// Overlapping Allan deviation σ(τ), SI rate unit.
    pub adev: f64,
    /// Lower end of the 68.3 % interval.
    pub low: f64,
    /// Upper end of the 68.3 % interval.
    pub high: f64,
    /// Equivalent degrees of freedom.
    pub edf: f64,
}

/// The noise of one channel.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ChannelNoise {
    /// Channel name (gx … az).
    pub channel: String,
    /// SI rate unit of the values ("rad/s" or "m/s^2").
    pub unit: String,
    /// The Allan deviation curve.
    pub points: Vec<AdevPoint>,
    /// White-noise density N, unit/√Hz (angle or velocity random walk), when visible.
    pub white_density: Option<f64>,
    /// Bias instability B, unit (flat minimum of the fitted curve / 0.664), when visible.
    pub bias_instability: Option<f64>,
    /// Cluster time of that minimum, s.
    pub bias_instability_tau_s: Option<f64>,
    /// Rate random walk K, unit/√s, when visible.
    pub random_walk: Option<f64>,
    /// Quantisation Q, unit·s, when visible.
    pub quantization: Option<f64>,
    /// Rate ramp R, unit/s, when visible.
    pub ramp: Option<f64>,
    /// Fitted Allan-variance coefficients [3Q², N², (2 ln2/π) B², K²/3, R²/2] as the
    /// weights of [τ⁻², τ⁻¹, 1, τ, τ²].
    pub coefficients: [f64; 5],
}

/// A noise characterisation of one recording.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct NoiseReport {
    /// What was analysed (file, run).
    pub source: String,
    /// Sample interval τ₀, s (median of the time steps).
    pub sample_interval_s: f64,
    /// Number of samples.
    pub n_samples: usize,
    /// Confidence level of the intervals.
    pub level: f64,
    /// One entry per analysed channel.
    pub channels: Vec<ChannelNoise>,
}

/// Noise analysis errors.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum NoiseError {
    /// Too short to compute even one cluster time.
    #[error("{0} samples are too few for an Allan deviation: at least 7 are needed (a long static recording, ideally hours)")]
    TooShort(usize),
    /// The sample interval is not usable.
    #[error("the sample interval {0} s is not a positive finite number")]
    Interval(f64),
}

const BASIS: [fn(f64) -> f64; 5] = [|t| 1.0 / (t * t), |t| 1.0 / t, |_| 1.0, |t| t, |t| t * t];
const FLAT: f64 = 0.664_282_4; // sqrt(2 ln 2 / π), IEEE 952 table C.1

impl ChannelNoise {
    /// The fitted Allan deviation at τ.
    pub fn model_adev(&self, tau_s: f64) -> f64 {
        self.coefficients.iter().zip(BASIS).map(|(c, f)| c * f(tau_s)).sum::<f64>().max(0.0).sqrt()
    }

    /// The sensor this channel belongs to.
    pub fn sensor(&self) -> SensorKind {
        if self.channel.starts_with('g') {
            SensorKind::Gyro
        } else {
            SensorKind::Accel
        }
    }

    /// White-noise density in display units: (°/s/√Hz, °/√h) or (µg/√Hz, m/s/√h).
    pub fn white_display(&self, g_m_s2: f64) -> Option<(f64, f64)> {
        self.white_density.map(|n| match self.sensor() {
            SensorKind::Gyro => (n.to_degrees(), n.to_degrees() * 60.0),
            SensorKind::Accel => (n / g_m_s2 * 1e6, n * 60.0),
        })
    }
}

/// Which noise type dominates the fitted σ² at τ (for the degrees of freedom).
fn dominant(c: &[f64; 5], tau: f64) -> NoiseType {
    let parts: Vec<f64> = c.iter().zip(BASIS).map(|(c, f)| c * f(tau)).collect();
    let k = (0..5).max_by(|&a, &b| parts[a].total_cmp(&parts[b])).unwrap_or(1);
    match k {
        0 => NoiseType::WhitePhase,
        1 => NoiseType::WhiteRate,
        2 => NoiseType::FlickerRate,
        _ => NoiseType::RandomWalkRate,
    }
}

/// Non-negative weighted least squares of σ² = Σ c_j f_j(τ) over the 2⁵ subsets of active
/// terms (exact for five terms): the feasible subset with the least weighted residual.
fn fit_terms(tau: &[f64], avar: &[f64], weight: &[f64]) -> [f64; 5] {
    let mut best = ([0.0; 5], f64::INFINITY);
    for mask in 1u32..32 {
        let act: Vec<usize> = (0..5).filter(|j| mask & (1 << j) != 0).collect();
        if act.len() > tau.len() {
            continue;
        }
        let p = act.len();
        let mut a = nalgebra::DMatrix::<f64>::zeros(tau.len(), p);
        let mut b = nalgebra::DVector::<f64>::zeros(tau.len());
        for (i, (&t, (&v, &w))) in tau.iter().zip(avar.iter().zip(weight)).enumerate() {
            let sw = w.sqrt();
            for (col, &j) in act.iter().enumerate() {
                a[(i, col)] = BASIS[j](t) * sw;
            }
            b[i] = v * sw;
        }
        // Columns span many decades: scale them to unit norm before solving.
        let norms: Vec<f64> = (0..p).map(|j| a.column(j).norm().max(f64::MIN_POSITIVE)).collect();
        for j in 0..p {
            let n = norms[j];
            a.column_mut(j).iter_mut().for_each(|v| *v /= n);
        }
        let Some(Ok(x)) = crate::stats::svd(a.clone(), true, true).map(|svd| svd.solve(&b, 1e-12)) else {
            continue;
        };
        if x.iter().any(|v| *v < 0.0 || !v.is_finite()) {
            continue;
        }
        let r = (&a * &x - &b).norm_squared();
        if r < best.1 {
            let mut c = [0.0; 5];
            for (col, &j) in act.iter().enumerate() {
                c[j] = x[col] / norms[col];
            }
            best = (c, r);
        }
    }
    best.0
}

/// Allan deviation and noise terms of one channel from its rate samples (SI), which are
/// turned into phase in place (the buffer is the only memory that grows with length).
pub fn analyse_channel(
    name: &str,
    unit: &str,
    samples: &mut [f64],
    tau0_s: f64,
    opts: NoiseOptions,
) -> Result<ChannelNoise, NoiseError> {
    if !(tau0_s.is_finite() && tau0_s > 0.0) {
        return Err(NoiseError::Interval(tau0_s));
    }
    let n = samples.len();
    let mut ms = allan::cluster_sizes(n);
    if let Some(t) = opts.max_tau_s {
        ms.retain(|&m| m as f64 * tau0_s <= t);
    }
    if ms.len() < 2 {
        return Err(NoiseError::TooShort(n));
    }
    allan::rate_to_phase(samples, tau0_s);
    let mut tau = Vec::with_capacity(ms.len());
    let mut avar = Vec::with_capacity(ms.len());
    let mut used = Vec::with_capacity(ms.len());
    for (&m, v) in ms.iter().zip(allan::avar_all(samples, tau0_s, &ms)) {
        if let Some(v) = v {
            tau.push(m as f64 * tau0_s);
            avar.push(v);
            used.push(m);
        }
    }
    // Pass 1: relative errors weighted as white rate noise; pass 2 and 3: degrees of
    // freedom by the dominant fitted term, relative to the fitted variance.
    let mut w: Vec<f64> =
        used.iter().zip(&avar).map(|(&m, v)| allan::edf(n, m, NoiseType::WhiteRate) / (v * v)).collect();
    let mut c = fit_terms(&tau, &avar, &w);
    for _ in 0..2 {
        w = used
            .iter()
            .zip(&tau)
            .zip(&avar)
            .map(|((&m, &t), &v)| {
                let model: f64 = c.iter().zip(BASIS).map(|(c, f)| c * f(t)).sum();
                let s = if model > 0.0 { model } else { v };
                allan::edf(n, m, dominant(&c, t)) / (s * s)
            })
            .collect();
        c = fit_terms(&tau, &avar, &w);
    }
    let points = used
        .iter()
        .zip(&tau)
        .zip(&avar)
        .map(|((&m, &t), &v)| {
            let e = allan::edf(n, m, dominant(&c, t));
            let s = v.sqrt();
            let (low, high) = allan::interval(s, e, LEVEL);
            AdevPoint { tau_s: t, adev: s, low, high, edf: e }
        })
        .collect();
    let visible = |j: usize| {
        tau.iter().any(|&t| {
            let total: f64 = c.iter().zip(BASIS).map(|(c, f)| c * f(t)).sum();
            c[j] * BASIS[j](t) >= 0.5 * total && c[j] > 0.0
        })
    };
    let mut out = ChannelNoise {
        channel: name.to_string(),
        unit: unit.to_string(),
        points,
        white_density: visible(1).then(|| c[1].sqrt()),
        bias_instability: None,
        bias_instability_tau_s: None,
        random_walk: visible(3).then(|| (3.0 * c[3]).sqrt()),
        quantization: visible(0).then(|| (c[0] / 3.0).sqrt()),
        ramp: visible(4).then(|| (2.0 * c[4]).sqrt()),
        coefficients: c,
    };
    if visible(2) {
        // The flat minimum of the fitted curve over the measured range (IEEE 952 C.1.3).
        let (t0, t1) = (tau[0].ln(), tau[tau.len() - 1].ln());
        let grid = (0..=400).map(|i| (t0 + (t1 - t0) * i as f64 / 400.0).exp());
        if let Some((t, s)) = grid.map(|t| (t, out.model_adev(t))).min_by(|a, b| a.1.total_cmp(&b.1)) {
            out.bias_instability = Some(s / FLAT);
            out.bias_instability_tau_s = Some(t);
        }
    }
    Ok(out)
}

/// The chosen channels of a static recording, read as a stream.
#[derive(Debug, Clone)]
pub struct StaticData {
    /// (channel index into [`CHANNELS`], samples in SI).
    pub columns: Vec<(usize, Vec<f64>)>,
    /// Sample interval τ₀, s: the median time step.
    pub tau0_s: f64,
    /// Number of samples.
    pub n: usize,
    /// Findings (irregular time stamps).
    pub warnings: Vec<String>,
}

/// Which part of a recording a noise analysis reads.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Span {
    /// Data rows `[start, end)` (a run's `rows`), or all.
    pub rows: Option<(usize, usize)>,
    /// Only the first this many seconds (a multi-position run's initial rest).
    pub first_s: Option<f64>,
}

/// Reads channels `channels` (indices into [`CHANNELS`]) of a recording CSV without holding
/// anything but those columns: rows are streamed and validated like every recording.
pub fn read_channels(
    path: &std::path::Path,
    units: &crate::units::Units,
    g_m_s2: f64,
    channels: &[usize],
    span: Span,
) -> Result<StaticData, crate::session::SessionError> {
    use crate::session::{ReadOptions, Row, RowReader, SessionError};
    let file = std::fs::File::open(path).map_err(|source| SessionError::Io { path: path.to_path_buf(), source })?;
    let mut rows = RowReader::new(path, file, units, g_m_s2, ReadOptions::default())?;
    let mut columns: Vec<(usize, Vec<f64>)> = channels.iter().map(|&c| (c, Vec::new())).collect();
    let mut row = Row::default();
    let mut steps = Vec::with_capacity(100_000);
    let (mut first, mut last, mut n) = (f64::NAN, f64::NAN, 0usize);
    let (start, end) = span.rows.unwrap_or((0, usize::MAX));
    let mut k = 0usize;
    while rows.read_row(&mut row)? {
        k += 1;
        if k <= start {
            continue;
        }
        if k > end || span.first_s.is_some_and(|d| n > 0 && row.t_s - first >= d) {
            break;
        }
        if n == 0 {
            first = row.t_s;
        } else if steps.len() < 100_000 {
            steps.push(row.t_s - last);
        }
        last = row.t_s;
        n += 1;
        for (c, col) in &mut columns {
            col.push(if *c < 3 { row.gyro[*c] } else { row.accel[*c - 3] });
        }
    }
    let tau0_s = crate::stats::median(&mut steps).unwrap_or(f64::NAN);
    let mut warnings = Vec::new();
    let mean = (last - first) / (n.max(2) - 1) as f64;
    if n > 2 && (mean / tau0_s - 1.0).abs() > 0.01 {
        warnings.push(format!(
            "{}: the mean time step {mean:.6} s differs from the median {tau0_s:.6} s by more than 1 %: gaps or an irregular clock bias the Allan deviation",
            path.display()
        ));
    }
    Ok(StaticData { columns, tau0_s, n, warnings })
}

/// Analyses the columns of a static recording (SI) sampled every `tau0_s`. Each column is
/// consumed (turned into phase in place).
pub fn analyse(source: &str, data: StaticData, opts: NoiseOptions) -> Result<NoiseReport, NoiseError> {
    let mut channels = Vec::with_capacity(data.columns.len());
    for (c, mut col) in data.columns {
        let unit = if c < 3 { "rad/s" } else { "m/s^2" };
        channels.push(analyse_channel(CHANNELS[c], unit, &mut col, data.tau0_s, opts)?);
    }
    Ok(NoiseReport {
        source: source.to_string(),
        sample_interval_s: data.tau0_s,
        n_samples: data.n,
        level: LEVEL,
        channels,
    })
}

impl NoiseReport {
    /// The channel named `name` (gx … az).
    pub fn channel(&self, name: &str) -> Option<&ChannelNoise> {
        self.channels.iter().find(|c| c.channel == name)
    }

    /// Per-sample white-noise standard deviation of a sensor at sample interval `dt_s`
    /// (the largest over its axes, N/√dt), SI; None when no axis shows white noise.
    pub fn white_sigma(&self, sensor: SensorKind, dt_s: f64) -> Option<f64> {
        self.channels
            .iter()
            .filter(|c| c.sensor() == sensor)
            .filter_map(|c| c.white_density)
            .map(|n| n / dt_s.sqrt())
            .reduce(f64::max)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_fit_recovers_exact_model_curves() {
        let c = [0.0, 4e-6, 1e-8, 3e-11, 0.0];
        let tau: Vec<f64> = (0..40).map(|i| 0.01 * 10f64.powf(i as f64 / 6.0)).collect();
        let avar: Vec<f64> = tau.iter().map(|&t| c.iter().zip(BASIS).map(|(c, f)| c * f(t)).sum()).collect();
        let w: Vec<f64> = avar.iter().map(|v| 1.0 / (v * v)).collect();
        let f = fit_terms(&tau, &avar, &w);
        for j in 0..5 {
            assert!((f[j] - c[j]).abs() <= 1e-6 * c[j].max(1e-20), "{j}: {} vs {}", f[j], c[j]);
        }
    }
}
