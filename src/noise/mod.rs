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
//! degrees of freedom (var σ̂² ≈ 2σ⁴/edf). A term stays in the model only if it carries at
//! least half of the fitted σ² at a cluster time measured with ≥ 10 degrees of freedom, and
//! the model is held under the measured curve's 99.7 % band everywhere (refitted under
//! that constraint where it would overshoot). Beside the fit, white noise and bias
//! instability are read off the measured curve itself (IEEE 952 C.1.1 and C.1.3: the
//! standard readings), and those are the values quoted.
//!
//! Units: SI inside (rad/s for the gyro, m/s² for the accelerometer); [`ChannelNoise`]
//! gives display values in the units engineers quote (°/√h, °/h, µg/√Hz, m/s/√h).

pub mod allan;
pub mod deviations;
pub mod intervals;
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
    /// A deviation to compute beside the Allan deviation (Allan: none).
    pub deviation: deviations::Deviation,
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
    /// The standard reading of bias instability (IEEE 952 C.1.3 read off the measured curve,
    /// not the fitted one): the smallest measured σ(τ) / 0.664, with its τ and interval.
    /// Present when the curve has a flat part (the fit finds a flicker floor).
    #[serde(default)]
    pub bias_instability_reading: Option<Reading>,
    /// The standard reading of the white-noise density (IEEE 952 C.1.1 read off the measured
    /// curve): σ(τ)·√τ at the well-determined point where the curve's log-log slope is
    /// nearest −½ (within 0.1), with its τ and interval. The fit's `white_density` can sit
    /// below it where the curve's knee is rounder than the five terms allow.
    #[serde(default)]
    pub white_density_reading: Option<Reading>,
    /// Cluster-time ranges where the measured curve leaves the fitted IEEE 952 model by more
    /// than its interval: a bump (a periodic disturbance), a shoulder, a slope the five terms
    /// do not have. Terms are not forced there; these say where and what it looks like.
    #[serde(default)]
    pub departures: Vec<Departure>,
    /// A 68.3 % interval for every reported fitted term ([`intervals`]).
    #[serde(default)]
    pub term_intervals: Vec<intervals::TermInterval>,
    /// The Hadamard or modified Allan deviation when asked for (`NoiseOptions::deviation`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub other: Option<deviations::Curve>,
}

/// A value read off the measured curve, with the interval of the point it comes from.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Reading {
    /// The value (SI).
    pub value: f64,
    /// The cluster time it was read at, s.
    pub tau_s: f64,
    /// Lower end of its 68.3 % interval.
    pub low: f64,
    /// Upper end of its 68.3 % interval.
    pub high: f64,
}

/// A range of cluster times where the measured curve and the fitted model disagree.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Departure {
    /// First cluster time of the range, s.
    pub tau_from_s: f64,
    /// Last cluster time of the range, s.
    pub tau_to_s: f64,
    /// Measured σ over fitted σ where they differ most (> 1: the curve lies above the model).
    pub ratio: f64,
    /// Local log-log slope of the measured curve over the range.
    pub slope: f64,
    /// What it looks like, in words.
    pub looks_like: String,
}

impl Departure {
    /// One line for people.
    pub fn describe(&self) -> String {
        if (self.ratio - 1.0).abs() < 1e-12 {
            return format!("τ {:.3}–{:.3} s: {}", self.tau_from_s, self.tau_to_s, self.looks_like);
        }
        format!(
            "τ {:.3}–{:.3} s: the measured curve lies {} the IEEE 952 model by up to {:.2}× (local slope {:+.2}): {}",
            self.tau_from_s,
            self.tau_to_s,
            if self.ratio > 1.0 { "above" } else { "below" },
            if self.ratio > 1.0 { self.ratio } else { 1.0 / self.ratio },
            self.slope,
            self.looks_like
        )
    }
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

/// The fewest samples an Allan deviation is computed from (two cluster times); a useful
/// one needs hours of a static recording.
pub const MIN_SAMPLES: usize = 7;

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
    /// A sample is NaN or infinite.
    #[error("channel {channel}, sample {sample}: expected a finite number (NaN or infinite values are not accepted)")]
    NotFinite {
        /// The channel (gx … az).
        channel: &'static str,
        /// 1-based sample.
        sample: usize,
    },
}

pub(crate) const BASIS: [fn(f64) -> f64; 5] = [|t| 1.0 / (t * t), |t| 1.0 / t, |_| 1.0, |t| t, |t| t * t];
pub(crate) const FLAT: f64 = 0.664_282_4; // sqrt(2 ln 2 / π), IEEE 952 table C.1
/// Degrees of freedom a point needs to be read as the curve's minimum (±10 % at 68 %).
pub const READING_EDF: f64 = 50.0;
/// Degrees of freedom of the points where a term must dominate to be in the model.
pub(crate) const MEASURED_EDF: f64 = 10.0;
/// The band a fitted model must stay inside at every measured point (99.7 %: with tens of
/// correlated points a 68 % band is left by chance).
const WIDE: f64 = 0.997;

impl ChannelNoise {
    /// The fitted Allan deviation at τ.
    pub fn model_adev(&self, tau_s: f64) -> f64 {
        model_avar(&self.coefficients, tau_s).max(0.0).sqrt()
    }

    /// The white-noise density to quote: the standard reading off the curve where there is
    /// one, else the fitted term.
    pub fn white(&self) -> Option<f64> {
        self.white_density_reading.map(|r| r.value).or(self.white_density)
    }

    /// The bias instability to quote: the standard reading where there is one, else the
    /// fitted model's floor.
    pub fn bias(&self) -> Option<f64> {
        self.bias_instability_reading.map(|r| r.value).or(self.bias_instability)
    }

    /// The sensor this channel belongs to.
    pub fn sensor(&self) -> SensorKind {
        if self.channel.starts_with('g') {
            SensorKind::Gyro
        } else {
            SensorKind::Accel
        }
    }

    /// White-noise density ([`Self::white`]) in display units: (°/s/√Hz, °/√h) or
    /// (µg/√Hz, m/s/√h).
    pub fn white_display(&self, g_m_s2: f64) -> Option<(f64, f64)> {
        self.white().map(|n| match self.sensor() {
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
/// terms within `allowed` (a bit per term; exact for five terms): the feasible subset with the
/// least weighted residual.
fn fit_terms(tau: &[f64], avar: &[f64], weight: &[f64], allowed: u32) -> [f64; 5] {
    let mut best = ([0.0; 5], f64::INFINITY);
    for mask in (1u32..32).filter(|m| m & !allowed == 0) {
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

/// A channel whose output never changes (stuck, or a resolution coarser than its noise): a
/// zero curve, no term, and a departure that says so, rather than terms fitted to rounding.
fn constant_channel(name: &str, unit: &str, ms: &[usize], tau0_s: f64) -> ChannelNoise {
    let points: Vec<AdevPoint> =
        ms.iter().map(|&m| AdevPoint { tau_s: m as f64 * tau0_s, adev: 0.0, low: 0.0, high: 0.0, edf: 1.0 }).collect();
    let departures = vec![Departure {
        tau_from_s: points.first().map_or(0.0, |p| p.tau_s),
        tau_to_s: points.last().map_or(0.0, |p| p.tau_s),
        ratio: 1.0,
        slope: 0.0,
        looks_like: "the output is constant: a stuck channel, or a resolution coarser than the noise; no noise \
                     term can be read"
            .to_string(),
    }];
    ChannelNoise {
        channel: name.to_string(),
        unit: unit.to_string(),
        points,
        white_density: None,
        bias_instability: None,
        bias_instability_tau_s: None,
        random_walk: None,
        quantization: None,
        ramp: None,
        coefficients: [0.0; 5],
        bias_instability_reading: None,
        white_density_reading: None,
        departures,
        term_intervals: Vec::new(),
        other: None,
    }
}

/// The terms of `c` (a bit each) that dominate the model nowhere the curve is measured with
/// at least [`MEASURED_EDF`] degrees of freedom.
fn unmeasured(c: &[f64; 5], tau: &[f64], used: &[usize], n: usize) -> u32 {
    let well = |j: usize| {
        used.iter().zip(tau).any(|(&m, &t)| {
            c[j] * BASIS[j](t) >= 0.5 * model_avar(c, t) && allan::edf(n, m, dominant(c, t)) >= MEASURED_EDF
        })
    };
    (0..5).filter(|&j| c[j] > 0.0 && !well(j)).fold(0, |a, j| a | 1 << j)
}

/// The fitted variance Σ c_j f_j(τ).
pub(crate) fn model_avar(c: &[f64; 5], tau_s: f64) -> f64 {
    c.iter().zip(BASIS).map(|(c, f)| c * f(tau_s)).sum()
}

/// Refits `c` so that the model variance stays at or below `upper` (the squared upper end of
/// each point's 99.7 % band) everywhere: points the model overshoots get the bound, slightly
/// inside, as their target and a hundredfold weight, and the fit is repeated until none
/// overshoots (an active-set iteration for the inequality-constrained least squares). If
/// that has not converged after 40 rounds the coefficients are scaled down by the largest
/// overshoot, which satisfies every bound at once.
fn fit_below(tau: &[f64], avar: &[f64], weight: &[f64], upper: &[f64], mut c: [f64; 5], allowed: u32) -> [f64; 5] {
    let over = |c: &[f64; 5]| tau.iter().zip(upper).map(|(&t, &u)| model_avar(c, t) / u).fold(0.0, f64::max);
    if over(&c) <= 1.0 {
        return c;
    }
    let (mut target, mut w) = (avar.to_vec(), weight.to_vec());
    for _ in 0..40 {
        for (k, (&t, &u)) in tau.iter().zip(upper).enumerate() {
            if model_avar(&c, t) > u {
                target[k] = 0.97 * u;
                w[k] *= 100.0;
            }
        }
        c = fit_terms(tau, &target, &w, allowed);
        if over(&c) <= 1.0 {
            return c;
        }
    }
    let s = over(&c);
    c.map(|v| v / s)
}

/// The five IEEE 952 terms fitted to a measured curve (cluster sizes `used`, times `tau`,
/// variances `avar` of `n` samples), held under the curve's band and without terms nothing
/// measures.
fn fit_model(n: usize, used: &[usize], tau: &[f64], avar: &[f64]) -> [f64; 5] {
    // Pass 1: relative errors weighted as white rate noise; pass 2 and 3: degrees of
    // freedom by the dominant fitted term, relative to the fitted variance. Where the five
    // terms cannot follow the measured curve the misfit is reported (`departures`), and the
    // bias instability is also read off the measured curve (`bias_instability_reading`).
    let mut w: Vec<f64> =
        used.iter().zip(avar).map(|(&m, v)| allan::edf(n, m, NoiseType::WhiteRate) / (v * v)).collect();
    let mut allowed = 0b11111;
    let mut c = fit_terms(tau, avar, &w, allowed);
    for pass in 0..4 {
        w = used
            .iter()
            .zip(tau)
            .zip(avar)
            .map(|((&m, &t), &v)| {
                let model = model_avar(&c, t);
                let s = if model > 0.0 { model } else { v };
                allan::edf(n, m, dominant(&c, t)) / (s * s)
            })
            .collect();
        // A term that dominates only where the curve has a few degrees of freedom (its last
        // points) is not measured, and left in it would bend the model away from the curve
        // there: the terms are refitted without it.
        if pass >= 1 {
            allowed &= !unmeasured(&c, tau, used, n);
        }
        c = fit_terms(tau, avar, &w, allowed);
    }
    // Requirement: the model never lies above the measured curve by more than the curve's
    // band. Where the free fit does (a curve whose knees are rounder than the five terms
    // allow, as on real units), it is refitted under that constraint.
    let upper: Vec<f64> = used
        .iter()
        .zip(tau)
        .zip(avar)
        .map(|((&m, &t), &v)| allan::interval(v.sqrt(), allan::edf(n, m, dominant(&c, t)), WIDE).1.powi(2))
        .collect();
    c = fit_below(tau, avar, &w, &upper, c, allowed);
    // The constrained refit may bring in a term only the last points carry: out with it too.
    for _ in 0..3 {
        let drop = unmeasured(&c, tau, used, n);
        if drop == 0 {
            break;
        }
        allowed &= !drop;
        c = fit_below(tau, avar, &w, &upper, fit_terms(tau, avar, &w, allowed), allowed);
    }
    c
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
    let (lo, hi) = samples.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &v| (a.min(v), b.max(v)));
    if hi - lo <= 0.0 {
        return Ok(constant_channel(name, unit, &ms, tau0_s));
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
    let c = fit_model(n, &used, &tau, &avar);
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
            let total = model_avar(&c, t);
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
        bias_instability_reading: None,
        white_density_reading: None,
        departures: Vec::new(),
        term_intervals: Vec::new(),
        other: (opts.deviation != deviations::Deviation::Allan)
            .then(|| deviations::curve(opts.deviation, samples, tau0_s, &used, |t| dominant(&c, t))),
    };
    out.departures = departures(&out);
    out.white_density_reading = white_reading(&out.points);
    if visible(2) {
        // The flat minimum of the fitted curve over the measured range (IEEE 952 C.1.3).
        let (t0, t1) = (tau[0].ln(), tau[tau.len() - 1].ln());
        let grid = (0..=400).map(|i| (t0 + (t1 - t0) * i as f64 / 400.0).exp());
        if let Some((t, s)) = grid.map(|t| (t, out.model_adev(t))).min_by(|a, b| a.1.total_cmp(&b.1)) {
            out.bias_instability = Some(s / FLAT);
            out.bias_instability_tau_s = Some(t);
        }
    }
    // The reading belongs to the curve, not the model: wherever the model has a flicker floor,
    // or the measured curve is flat around its minimum (within 1.2× over a factor of three of
    // τ each side; white noise meeting a random walk makes a valley 1.29× deep there).
    out.bias_instability_reading =
        bias_reading(&out.points).filter(|r| visible(2) || flat_around(&out.points, r.tau_s, r.value * FLAT));
    out.term_intervals = intervals::term_intervals(&out);
    Ok(out)
}

/// Whether the measured points (≥ [`MEASURED_EDF`]) within a factor of three of `tau_s` stay
/// within 1.2× of `at`, the curve's value there, with points on both sides.
fn flat_around(pts: &[AdevPoint], tau_s: f64, at: f64) -> bool {
    let near: Vec<&AdevPoint> =
        pts.iter().filter(|p| p.edf >= MEASURED_EDF && p.tau_s >= tau_s / 3.0 && p.tau_s <= tau_s * 3.0).collect();
    let below = near.iter().any(|p| p.tau_s <= tau_s / 2.5);
    let above = near.iter().any(|p| p.tau_s >= tau_s * 2.5);
    below && above && near.iter().all(|p| p.adev <= 1.2 * at)
}

/// The standard bias-instability reading: the smallest well-determined measured point / 0.664
/// (IEEE 952 C.1.3), when it is an interior minimum of the curve.
fn bias_reading(pts: &[AdevPoint]) -> Option<Reading> {
    // The standard reading: the smallest well-determined measured point (≥ READING_EDF
    // degrees of freedom: the minimum of scattered long-τ points is biased low) / 0.664.
    let eligible: Vec<usize> = (0..pts.len()).filter(|&k| pts[k].edf >= READING_EDF).collect();
    let k = eligible.iter().copied().min_by(|&a, &b| pts[a].adev.total_cmp(&pts[b].adev));
    // At the last of them the minimum counts only where the curve has flattened: a
    // log-log slope above −0.2 over the factor of three of τ before it.
    let flat_end = |k: usize| {
        let t = pts[k].tau_s / 3.0;
        let j = eligible
            .iter()
            .copied()
            .filter(|&j| pts[j].tau_s <= t)
            .max_by(|&a, &b| pts[a].tau_s.total_cmp(&pts[b].tau_s));
        j.is_some_and(|j| {
            let (a, b) = (pts[j], pts[k]);
            (b.adev.ln() - a.adev.ln()) / (b.tau_s.ln() - a.tau_s.ln()) > -0.2
        })
    };
    let interior = |k: usize| Some(&k) != eligible.first() && (Some(&k) != eligible.last() || flat_end(k));
    let p = pts[k.filter(|&k| interior(k))?];
    Some(Reading { value: p.adev / FLAT, tau_s: p.tau_s, low: p.low / FLAT, high: p.high / FLAT })
}

/// σ(τ)√τ at the well-determined point (≥ [`READING_EDF`]) whose local log-log slope (to
/// its neighbours) is nearest −½, when within 0.1 of it (IEEE 952 C.1.1: the slope −½ line
/// read at τ = 1 s is σ(τ)√τ anywhere on it).
fn white_reading(pts: &[AdevPoint]) -> Option<Reading> {
    let slope = |k: usize| {
        let (a, b) = (pts[k - 1], pts[k + 1]);
        (b.adev.ln() - a.adev.ln()) / (b.tau_s.ln() - a.tau_s.ln())
    };
    let k = (1..pts.len().saturating_sub(1))
        .filter(|&k| pts[k + 1].edf >= READING_EDF && (slope(k) + 0.5).abs() < 0.1)
        .min_by(|&a, &b| (slope(a) + 0.5).abs().total_cmp(&(slope(b) + 0.5).abs()))?;
    let (p, r) = (pts[k], pts[k].tau_s.sqrt());
    Some(Reading { value: p.adev * r, tau_s: p.tau_s, low: p.low * r, high: p.high * r })
}

/// Ranges of consecutive points where the fitted model leaves the measured point's 99.7 %
/// interval, with what the measured curve does there.
fn departures(c: &ChannelNoise) -> Vec<Departure> {
    let pts = &c.points;
    let off = |p: &AdevPoint| {
        let m = c.model_adev(p.tau_s);
        let (lo, hi) = allan::interval(p.adev, p.edf, WIDE);
        m > hi || m < lo
    };
    let mut out = Vec::new();
    let mut k = 0;
    while k < pts.len() {
        if !off(&pts[k]) {
            k += 1;
            continue;
        }
        let start = k;
        while k < pts.len() && off(&pts[k]) {
            k += 1;
        }
        let (a, b) = (start, k - 1);
        let ratio = pts[a..=b]
            .iter()
            .map(|p| p.adev / c.model_adev(p.tau_s).max(f64::MIN_POSITIVE))
            .max_by(|x, y| x.ln().abs().total_cmp(&y.ln().abs()))
            .unwrap_or(1.0);
        let (lo, hi) = (a.saturating_sub(1), (b + 1).min(pts.len() - 1));
        let slope = if hi > lo {
            (pts[hi].adev.ln() - pts[lo].adev.ln()) / (pts[hi].tau_s.ln() - pts[lo].tau_s.ln())
        } else {
            0.0
        };
        // A local maximum of the measured curve that rises significantly (its 99.7 % interval
        // above that of the lowest point before it in the range) is a bump: a sinusoid of
        // period T peaks near τ = 0.37 T whatever the model does around it.
        let peak = (lo.max(1)..=hi.min(pts.len().saturating_sub(2))).find(|&k| {
            let Some(j) = (lo..k).min_by(|&x, &y| pts[x].adev.total_cmp(&pts[y].adev)) else { return false };
            let (k_low, _) = allan::interval(pts[k].adev, pts[k].edf, WIDE);
            let (_, j_high) = allan::interval(pts[j].adev, pts[j].edf, WIDE);
            pts[k].adev > pts[k + 1].adev && k_low > j_high
        });
        let looks_like = if let Some(k) = peak {
            format!(
                "a bump peaking at τ = {:.3} s: a periodic disturbance of period near {:.3} s (vibration, a \
                 temperature or supply cycle) adds variance there",
                pts[k].tau_s,
                pts[k].tau_s / 0.371
            )
        } else if ratio > 1.0 && b + 1 == pts.len() {
            "more variance than the five terms allow at the end of the curve (a trend, a drift, or a \
             random walk steeper than +1/2)"
                .to_string()
        } else if ratio > 1.0 {
            "more variance than the model here: correlated noise (an output filter, a resonance) the \
             five terms do not have"
                .to_string()
        } else if slope < -0.75 {
            "a slope near −1: quantisation or correlated high-frequency noise the model does not fit here".to_string()
        } else {
            "less variance than the model: the terms overshoot here, read the curve rather than the fit".to_string()
        };
        out.push(Departure { tau_from_s: pts[a].tau_s, tau_to_s: pts[b].tau_s, ratio, slope, looks_like });
    }
    out
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
    use crate::session::{ReadOptions, Row, RowReader};
    let (file, _) = crate::session::open_recording(path)?;
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
            .filter_map(|c| c.white())
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
        let avar: Vec<f64> = tau.iter().map(|&t| model_avar(&c, t)).collect();
        let w: Vec<f64> = avar.iter().map(|v| 1.0 / (v * v)).collect();
        let f = fit_terms(&tau, &avar, &w, 0b11111);
        for j in 0..5 {
            assert!((f[j] - c[j]).abs() <= 1e-6 * c[j].max(1e-20), "{j}: {} vs {}", f[j], c[j]);
        }
    }
}
