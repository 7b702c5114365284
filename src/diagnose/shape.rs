//! The shape of what no catalogued effect explains.
//!
//! When a channel's residual stays systematic after the climb, the residual is drawn
//! against what it could depend on — the channel's own true input, its magnitude, the other
//! axes' inputs, the specific force (gyro) or the rates (accelerometer), the temperature,
//! the cone phase and the run — as binned partial residuals: per bin the mean residual and
//! its standard error under the noise model (σ √(τ_int / n), the AR integral time τ_int; the
//! slow noise's offset variance added for the run means). The variable whose bins depart
//! most from a constant (χ² against the weighted mean, as a z-score over its degrees of
//! freedom) carries the shape. On it, shapes are fitted to the bin means by weighted least
//! squares beside the line the fit already absorbs (bias, scale): a knee k·max(x − x₀, 0)
//! (or below −x₀), a symmetric knee k·(max(x − x₀, 0) + min(x + x₀, 0)) (k ≈ −1: the output
//! stops growing — saturation), a square and a cube, and on the own input's rate of change
//! a step at zero (hysteresis: friction or play); the one of least BIC =
//! χ² + p ln(bins) is described in words and, when it is a law of the inputs, written as an
//! effects-file entry ready to paste.

use crate::estimate::slow::SlowNoise;
use crate::estimate::{Fit, FitRun};
use crate::model::{Model, State};
use crate::session::MotionSpec;
use crate::units::{SensorKind, AXES};
use serde::{Deserialize, Serialize};

/// Bins of a continuous variable.
const BINS: usize = 16;
/// Fewest samples a bin needs to be drawn.
const MIN_BIN: u64 = 20;

/// One bin of a partial-residual plot.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Bin {
    /// Bin centre (SI; for the run, its index).
    pub x: f64,
    /// Mean residual (SI).
    pub mean: f64,
    /// Its standard error under the noise model (SI).
    pub se: f64,
    /// Samples.
    pub n: u64,
}

/// The residual of one channel against one variable, binned.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PartialResidual {
    /// The variable as an effects-file expression (`w_x`, `abs(w_x)`, `a_y`, `T`), or
    /// `cone phase`, `run`.
    pub variable: String,
    /// In words.
    pub label: String,
    /// The bins.
    pub bins: Vec<Bin>,
    /// χ² of the bin means against their weighted mean.
    pub chi2: f64,
    /// Its degrees of freedom.
    pub dof: usize,
    /// (χ² − dof)/√(2 dof): how far it departs from flat.
    pub z: f64,
    /// The variable's display unit (`°/s`, `g`, `(°/s)²`, `°C`, `°`; empty for a run index).
    #[serde(default)]
    pub unit: String,
    /// Its SI value (the bins' `x`) times this is in `unit`.
    #[serde(default = "one")]
    pub to_unit: f64,
}

fn one() -> f64 {
    1.0
}

/// What a failing channel's residual looks like.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Shape {
    /// Sensor.
    pub sensor: SensorKind,
    /// Axis.
    pub axis: char,
    /// `knee`, `saturation`, `symmetric knee`, `square law`, `cube law`, `hysteresis`,
    /// `turn-on bias`, `cone-phase pattern` or `unrecognised`.
    pub kind: String,
    /// The best-supported shape in words.
    pub words: String,
    /// The effects-file entry that would model it (None when it is not a law of the inputs).
    pub effect_toml: Option<String>,
    /// The partial-residual plots, the most departing first.
    pub plots: Vec<PartialResidual>,
}

/// A variable a residual may depend on.
#[derive(Clone, Copy)]
enum Var {
    W(usize),
    AbsW(usize),
    E(usize),
    A(usize),
    AbsA(usize),
    RateNorm,
    RateSquared,
    Temp,
    Phase,
}

impl Var {
    fn value(self, s: &State, theta: Option<f64>) -> f64 {
        match self {
            Var::W(i) => s.w[i],
            Var::AbsW(i) => s.w[i].abs(),
            Var::E(i) => s.e[i],
            Var::A(i) => s.a[i],
            Var::AbsA(i) => s.a[i].abs(),
            Var::RateNorm => (s.w[0] * s.w[0] + s.w[1] * s.w[1] + s.w[2] * s.w[2]).sqrt(),
            Var::RateSquared => s.w[0] * s.w[0] + s.w[1] * s.w[1] + s.w[2] * s.w[2],
            Var::Temp => s.temp_c,
            Var::Phase => theta.map_or(f64::NAN, |t| t.rem_euclid(std::f64::consts::TAU)),
        }
    }

    /// Effects-file expression (None: not an input law).
    fn expr(self) -> Option<String> {
        Some(match self {
            Var::W(i) => format!("w_{}", AXES[i]),
            Var::AbsW(i) => format!("abs(w_{})", AXES[i]),
            Var::E(i) => format!("e_{}", AXES[i]),
            Var::A(i) => format!("a_{}", AXES[i]),
            Var::AbsA(i) => format!("abs(a_{})", AXES[i]),
            Var::RateNorm => "sqrt(w_x^2 + w_y^2 + w_z^2)".into(),
            Var::RateSquared => "(w_x^2 + w_y^2 + w_z^2)".into(),
            Var::Temp => "T".into(),
            Var::Phase => return None,
        })
    }

    fn label(self, own: bool) -> String {
        let own = if own { "own " } else { "" };
        match self {
            Var::W(i) => format!("{own}rate ω_{}", AXES[i]),
            Var::AbsW(i) => format!("|{own}rate ω_{}|", AXES[i]),
            Var::E(i) => format!("{own}angular acceleration ε_{} (the rate's change)", AXES[i]),
            Var::A(i) => format!("{own}specific force a_{}", AXES[i]),
            Var::AbsA(i) => format!("|{own}specific force a_{}|", AXES[i]),
            Var::RateNorm => "rate magnitude |ω|".into(),
            Var::RateSquared => "squared rate |ω|²".into(),
            Var::Temp => "temperature".into(),
            Var::Phase => "cone phase".into(),
        }
    }

    /// Display unit and SI → display factor.
    fn unit(self) -> (&'static str, f64) {
        let deg = 180.0 / std::f64::consts::PI;
        match self {
            Var::W(_) | Var::AbsW(_) | Var::RateNorm => ("°/s", deg),
            Var::RateSquared => ("(°/s)²", deg * deg),
            Var::E(_) => ("°/s²", deg),
            Var::A(_) | Var::AbsA(_) => ("g", 1.0 / 9.80665),
            Var::Temp => ("°C", 1.0),
            Var::Phase => ("°", deg),
        }
    }

    /// Parameter name of a threshold on it.
    fn threshold_name(self) -> &'static str {
        match self {
            Var::W(_) | Var::AbsW(_) | Var::RateNorm | Var::RateSquared => "w0",
            Var::A(_) | Var::AbsA(_) => "a0",
            Var::E(_) => "e0",
            _ => "x0",
        }
    }
}

/// The variables of channel (sensor, axis), with whether each is the channel's own input.
fn variables(sensor: SensorKind, i: usize, has_temp: bool) -> Vec<(Var, bool)> {
    let own = |v: usize| v == i;
    let mut v: Vec<(Var, bool)> = Vec::new();
    match sensor {
        SensorKind::Gyro => {
            v.push((Var::W(i), true));
            v.push((Var::AbsW(i), true));
            v.push((Var::E(i), true));
            v.extend((0..3).filter(|&j| !own(j)).map(|j| (Var::W(j), false)));
            v.extend((0..3).map(|j| (Var::A(j), false)));
            v.push((Var::RateNorm, false));
        }
        SensorKind::Accel => {
            v.push((Var::A(i), true));
            v.push((Var::AbsA(i), true));
            v.extend((0..3).filter(|&j| !own(j)).map(|j| (Var::A(j), false)));
            v.extend((0..3).map(|j| (Var::W(j), false)));
            v.push((Var::RateSquared, false));
        }
    }
    if has_temp {
        v.push((Var::Temp, false));
    }
    v.push((Var::Phase, false));
    v
}

/// What the binning needs of the noise: σ, the integral time in samples, and the variance
/// the slow noise adds to a run's mean.
#[derive(Debug, Clone, Copy)]
pub struct NoiseScale {
    /// Noise standard deviation (SI).
    pub sigma: f64,
    /// Integral time of the AR noise, samples (1 for white).
    pub integral: f64,
    /// Variance of a run's mean from the slow noise (SI²).
    pub run_var: f64,
}

impl NoiseScale {
    /// The scale of a channel from its noise report and slow noise over a session of
    /// `span_s` (runs of `run_s`).
    pub fn new(sigma: f64, lag1: f64, slow: Option<SlowNoise>, span_s: f64, run_s: f64) -> Self {
        let rho = lag1.clamp(0.0, 0.999);
        let run_var = slow.filter(SlowNoise::is_slow).map_or(0.0, |s| {
            let k = s.kernel(span_s);
            k.cov((0.0, run_s), (0.0, run_s), true) + k.walk2() * span_s / 6.0
        });
        Self { sigma, integral: (1.0 + rho) / (1.0 - rho), run_var: run_var.max(0.0) }
    }

    /// The same noise seen on every `stride`-th sample: the lag-1 correlation ρ read back
    /// from the integral time (1 + ρ)/(1 − ρ) becomes ρ^stride between the samples kept.
    fn strided(self, stride: usize) -> Self {
        if stride <= 1 {
            return self;
        }
        let rho = ((self.integral - 1.0) / (self.integral + 1.0)).clamp(0.0, 0.999);
        let rs = rho.powi(stride.min(i32::MAX as usize) as i32);
        Self { integral: (1.0 + rs) / (1.0 - rs), ..self }
    }
}

/// Samples a shape is drawn from at most: past it every k-th sample of each run is kept
/// (memory bounded whatever the session's length; the bins' errors follow the stride).
const SHAPE_SAMPLES: usize = 250_000;

/// Binned partial residuals of channel `c` (0..6) and the shape they show.
#[allow(clippy::too_many_arguments)]
pub fn shape_of(
    model: &Model,
    fit: &Fit,
    runs: &[FitRun<'_>],
    motions: &[&MotionSpec],
    c: usize,
    noise: NoiseScale,
) -> Shape {
    let sensor = SensorKind::BOTH[c / 3];
    let i = c % 3;
    let has_temp = runs.iter().all(|r| r.temp_c.is_some() || r.temp_const_c.is_some());
    let vars = variables(sensor, i, has_temp);
    // Values per variable (single precision: what a bin needs, half the memory) and
    // residuals, gathered once (one pass over the runs, the model evaluated only at the
    // samples kept), on every `stride`-th sample of a long session.
    let stride = runs.iter().map(|r| r.len()).sum::<usize>().div_ceil(SHAPE_SAMPLES).max(1);
    let noise = noise.strided(stride);
    let kept: usize = runs.iter().map(|r| r.len().div_ceil(stride)).sum();
    let mut xs: Vec<Vec<f32>> = vec![Vec::with_capacity(kept); vars.len()];
    let mut res = Vec::with_capacity(kept);
    let mut run_of = Vec::with_capacity(kept);
    for (ri, run) in runs.iter().enumerate() {
        let phase = crate::motion::cone_phase(motions[ri]);
        super::picture::visit_residual(model, fit, run, stride, |k, s, _, e| {
            let theta = phase.map(|p| p.theta(run.track.t_s[k]));
            for (vi, (v, _)) in vars.iter().enumerate() {
                xs[vi].push(v.value(s, theta) as f32);
            }
            res.push(e[c]);
            run_of.push(ri);
        });
    }
    let mut plots: Vec<(PartialResidual, Option<usize>)> = vars
        .iter()
        .zip(&xs)
        .enumerate()
        .filter_map(|(vi, (&(v, own), x))| binned(x, &res, noise, BINS).map(|p| (named(p, v, own), Some(vi))))
        .collect();
    plots.push((run_plot(&run_of, &res, runs.len(), noise), None));
    plots.sort_by(|a, b| b.0.z.total_cmp(&a.0.z));
    let (words, kind, toml) = match plots.first() {
        Some((p, Some(vi))) => {
            let x: Vec<f64> = xs[*vi].iter().map(|&v| f64::from(v)).collect();
            describe(p, vars[*vi].0, sensor, i, (x.as_slice(), res.as_slice()))
        }
        Some((p, None)) => {
            let spread = spread(&p.bins);
            let (u, k) = sensor.display_unit();
            (
                format!(
                    "a different offset in each run (spread {:.3e} {u}) — turn-on bias; no expression of the motion \
                     models it (no effects-file entry): count it as noise (`--slow-noise`) or measure each run's \
                     bias at rest before it",
                    spread * k
                ),
                "turn-on bias".into(),
                None,
            )
        }
        None => ("no variable carries it".into(), "unrecognised".into(), None),
    };
    Shape {
        sensor,
        axis: AXES[i],
        kind,
        words: format!("{sensor} {}: {words}", AXES[i]),
        effect_toml: toml.map(|(id, expr, params, what)| toml_entry(&id, sensor, i, &expr, &params, &what)),
        plots: plots.into_iter().map(|p| p.0).collect(),
    }
}

fn named(mut p: PartialResidual, v: Var, own: bool) -> PartialResidual {
    p.variable = v.expr().unwrap_or_else(|| "cone phase".into());
    p.label = v.label(own);
    let (unit, k) = v.unit();
    p.unit = unit.to_string();
    p.to_unit = k;
    p
}

/// Bins of `x` (finite values, equal width from min to max) with the mean residual.
fn binned(x: &[f32], r: &[f64], noise: NoiseScale, bins: usize) -> Option<PartialResidual> {
    let (lo, hi) = x
        .iter()
        .map(|&v| f64::from(v))
        .filter(|v| v.is_finite())
        .fold((f64::INFINITY, f64::NEG_INFINITY), |a, v| (a.0.min(v), a.1.max(v)));
    if hi.partial_cmp(&lo) != Some(std::cmp::Ordering::Greater) {
        return None;
    }
    let w = (hi - lo) / bins as f64;
    let mut sum = vec![0.0; bins];
    let mut n = vec![0u64; bins];
    for (xv, rv) in x.iter().map(|&v| f64::from(v)).zip(r) {
        if xv.is_finite() {
            let b = (((xv - lo) / w) as usize).min(bins - 1);
            sum[b] += rv;
            n[b] += 1;
        }
    }
    let out: Vec<Bin> = (0..bins)
        .filter(|&b| n[b] >= MIN_BIN)
        .map(|b| Bin {
            x: lo + (b as f64 + 0.5) * w,
            mean: sum[b] / n[b] as f64,
            se: noise.sigma * (noise.integral / n[b] as f64).sqrt(),
            n: n[b],
        })
        .collect();
    Some(flatness(String::new(), String::new(), out))
}

fn run_plot(run_of: &[usize], r: &[f64], runs: usize, noise: NoiseScale) -> PartialResidual {
    let mut sum = vec![0.0; runs];
    let mut n = vec![0u64; runs];
    for (&ri, rv) in run_of.iter().zip(r) {
        sum[ri] += rv;
        n[ri] += 1;
    }
    let bins = (0..runs)
        .filter(|&b| n[b] > 0)
        .map(|b| Bin {
            x: b as f64,
            mean: sum[b] / n[b] as f64,
            se: (noise.sigma.powi(2) * noise.integral / n[b] as f64 + noise.run_var).sqrt(),
            n: n[b],
        })
        .collect();
    flatness("run".into(), "run".into(), bins)
}

fn flatness(variable: String, label: String, bins: Vec<Bin>) -> PartialResidual {
    let wsum: f64 = bins.iter().map(|b| 1.0 / b.se.powi(2).max(f64::MIN_POSITIVE)).sum();
    let mean =
        bins.iter().map(|b| b.mean / b.se.powi(2).max(f64::MIN_POSITIVE)).sum::<f64>() / wsum.max(f64::MIN_POSITIVE);
    let chi2: f64 = bins.iter().map(|b| ((b.mean - mean) / b.se.max(f64::MIN_POSITIVE)).powi(2)).sum();
    let dof = bins.len().saturating_sub(1);
    let z = if dof > 0 { (chi2 - dof as f64) / (2.0 * dof as f64).sqrt() } else { 0.0 };
    PartialResidual { variable, label, bins, chi2, dof, z, unit: String::new(), to_unit: 1.0 }
}

fn spread(bins: &[Bin]) -> f64 {
    let n = bins.len().max(1) as f64;
    let m = bins.iter().map(|b| b.mean).sum::<f64>() / n;
    (bins.iter().map(|b| (b.mean - m).powi(2)).sum::<f64>() / n).sqrt()
}

/// Weighted least squares of the bin means on [1, x, extra]: (χ², coefficient of extra).
fn wls(bins: &[Bin], extra: impl Fn(f64) -> f64) -> (f64, f64) {
    let mut m = nalgebra::Matrix3::<f64>::zeros();
    let mut b = nalgebra::Vector3::<f64>::zeros();
    for bin in bins {
        let w = 1.0 / bin.se.powi(2).max(f64::MIN_POSITIVE);
        let row = nalgebra::Vector3::new(1.0, bin.x, extra(bin.x));
        m += w * row * row.transpose();
        b += w * bin.mean * row;
    }
    let Some(beta) = m.try_inverse().map(|inv| inv * b) else { return (f64::INFINITY, 0.0) };
    let chi2 =
        bins.iter().map(|bin| ((bin.mean - beta[0] - beta[1] * bin.x - beta[2] * extra(bin.x)) / bin.se).powi(2)).sum();
    (chi2, beta[2])
}

/// (id suffix, expression, parameters, description) of an effects-file entry.
type Entry = (String, String, Vec<(String, f64)>, String);

/// The best-supported shape on one variable: words, kind and the entry that models it.
fn describe(
    p: &PartialResidual,
    v: Var,
    sensor: SensorKind,
    i: usize,
    raw: (&[f64], &[f64]),
) -> (String, String, Option<Entry>) {
    let bins = &p.bins;
    let nb = bins.len() as f64;
    let (u, k) = v.unit();
    let line = wls(bins, |_| 0.0).0;
    let xs: Vec<f64> = bins.iter().map(|b| b.x).collect();
    let inner = if xs.len() > 4 { &xs[1..xs.len() - 1] } else { &xs[..] };
    // (BIC, kind, x0, coefficient)
    let mut best: (f64, &str, f64, f64) = (line, "line", 0.0, 0.0);
    let mut consider = |bic: f64, kind: &'static str, x0: f64, coef: f64| {
        if bic < best.0 {
            best = (bic, kind, x0, coef);
        }
    };
    let ln = nb.ln();
    for &x0 in inner {
        let (c2, kk) = wls(bins, |x| (x - x0).max(0.0));
        consider(c2 + 2.0 * ln, "knee+", x0, kk);
        let (c2, kk) = wls(bins, |x| (x - x0).min(0.0));
        consider(c2 + 2.0 * ln, "knee-", x0, kk);
        if x0 > 0.0 {
            let (c2, kk) = wls(bins, |x| (x - x0).max(0.0) + (x + x0).min(0.0));
            consider(c2 + 2.0 * ln, "sym", x0, kk);
        }
    }
    let (c2, q) = wls(bins, |x| x * x);
    consider(c2 + ln, "square", 0.0, q);
    let (c2, cu) = wls(bins, |x| x * x * x);
    consider(c2 + ln, "cube", 0.0, cu);
    // On the input's rate of change, a step at zero: one offset while it rises, the
    // opposite while it falls.
    if matches!(v, Var::E(_)) {
        let (c2, h) = wls(bins, f64::signum);
        consider(c2 + ln, "step", 0.0, h);
    }
    let expr = v.expr();
    let ax = AXES[i];
    let id = |s: &str| format!("{}-{ax}-{s}", sensor.as_str());
    let tn = v.threshold_name();
    let show = |x: f64| format!("{:+.1} {u}", x * k);
    let (bic, mut kind, mut x0, mut coef) = best;
    let fit_ok = bic < line - 10.0;
    // The threshold between bin centres, on the samples themselves.
    if matches!(kind, "knee+" | "knee-" | "sym") {
        let width = if xs.len() > 1 { (xs[xs.len() - 1] - xs[0]) / (xs.len() - 1) as f64 } else { 0.0 };
        (x0, coef) = refine(raw, kind, x0, width);
    }
    // Beside the line the fit absorbs, k·max(x − x₀, 0) and −k·min(x − x₀, 0) are one shape
    // (they differ by k(x − x₀)): say it on the side away from zero, where it acts.
    let away = if x0 >= 0.0 { "knee+" } else { "knee-" };
    if matches!(kind, "knee+" | "knee-") && kind != away {
        (kind, coef) = (away, -coef);
    }
    // On the rate's change a symmetric knee beside the line is a ramped step:
    // k·(x − clamp(x, ±x₀)) less its line is −k·clamp(x, ±x₀), ±k·x₀ beyond ±x₀.
    if matches!(v, Var::E(_)) && kind == "sym" {
        (kind, coef) = ("step", -coef * x0);
    }
    match (kind, expr) {
        (_, None) => (format!("follows the {} (see the plot)", v.label(false)), "cone-phase pattern".into(), None),
        (_, Some(_)) if !fit_ok => (
            format!("depends most on {} but no simple shape fits (see the plot)", p.label),
            "unrecognised".into(),
            None,
        ),
        ("knee+" | "knee-", Some(e)) => {
            let above = kind == "knee+";
            let (op, side) = if above { ("max", "above") } else { ("min", "below") };
            let expr = format!("k * {op}({e} - {tn}, 0)");
            let saturates = coef < -0.5;
            let words = if saturates {
                format!("flat {} at {} — saturation", if above { "top" } else { "bottom" }, show(x0))
            } else {
                format!(
                    "zero {} {}, then grows {:.1} % of {} {side} it — a knee",
                    if above { "below" } else { "above" },
                    show(x0),
                    100.0 * coef,
                    p.label
                )
            };
            let kind = if saturates { "saturation" } else { "knee" };
            let what = format!("scale changes by {:.1} % {side} {} (from diagnose)", 100.0 * coef, show(x0));
            (words, kind.into(), Some((id(kind), expr, vec![(tn.to_string(), x0)], what)))
        }
        ("sym", Some(e)) => {
            let expr = format!("k * (max({e} - {tn}, 0) + min({e} + {tn}, 0))");
            let (words, kind) = if coef < -0.5 {
                (format!("flat top at ±{:.1} {u} — saturation", x0 * k), "saturation")
            } else {
                (
                    format!("the scale changes by {:.1} % beyond ±{:.1} {u} — a symmetric knee", 100.0 * coef, x0 * k),
                    "symmetric knee",
                )
            };
            let what = format!("{kind} at ±{:.1} {u} (from diagnose)", x0 * k);
            (words, kind.into(), Some((id(&kind.replace(' ', "-")), expr, vec![(tn.to_string(), x0)], what)))
        }
        ("step", Some(e)) => step_words(p, sensor, &e, (x0, coef), (tn, u, k), &id("hysteresis")),
        ("square" | "cube", Some(e)) => {
            let (pow, kind) = if kind == "square" { (2, "square law") } else { (3, "cube law") };
            let words = format!("grows as the {} of {} — a {kind}", if pow == 2 { "square" } else { "cube" }, p.label);
            let expr = if e.starts_with('(') && pow == 2 { format!("k * {e}") } else { format!("k * ({e})^{pow}") };
            let what = format!("{kind} in {} (from diagnose)", p.label);
            (words, kind.into(), Some((id(&kind.replace(' ', "-")), expr, Vec::new(), what)))
        }
        _ => (format!("depends most on {} (see the plot)", p.label), "unrecognised".into(), None),
    }
}

/// Words, kind and entry of a step on the own rate's change `e`: ±`h` beyond a ramp of
/// half-width `x0` (0: a sign), `tn` the ramp's parameter, (`u`, `k`) its display unit.
fn step_words(
    p: &PartialResidual,
    sensor: SensorKind,
    e: &str,
    (x0, h): (f64, f64),
    (tn, u, k): (&str, &str, f64),
    id: &str,
) -> (String, String, Option<Entry>) {
    let (ru, rk) = sensor.display_unit();
    let axis = e.trim_start_matches("e_");
    let ramp = if x0 > 0.0 { format!(", changing over |ε_{axis}| < {:.2} {u}", x0 * k) } else { String::new() };
    let words = format!(
        "{:+.3e} {ru} while the own rate rises, {:+.3e} {ru} while it falls{ramp} — hysteresis (friction, or \
         play when the change is gradual: the output holds after each turn of the input before it follows)",
        h * rk,
        -h * rk,
    );
    let what = format!("step of {:+.3e} {ru} with the sign of {} (from diagnose)", h * rk, p.label);
    let (expr, params) = if x0 > 0.0 {
        (format!("k * max(min({e} / {tn}, 1), -1)"), vec![(tn.to_string(), x0)])
    } else {
        (format!("k * sign({e})"), Vec::new())
    };
    (words, "hysteresis".into(), Some((id.to_string(), expr, params, what)))
}

/// The hinge's term at x for a threshold x0.
fn hinge(kind: &str, x: f64, x0: f64) -> f64 {
    match kind {
        "knee+" => (x - x0).max(0.0),
        "knee-" => (x - x0).min(0.0),
        _ => (x - x0).max(0.0) + (x + x0).min(0.0),
    }
}

/// Least squares of r on [1, x, hinge(x; x0)] over the samples: (RSS, hinge coefficient).
fn raw_fit(raw: (&[f64], &[f64]), kind: &str, x0: f64) -> (f64, f64) {
    let mut m = nalgebra::Matrix4::<f64>::zeros();
    for (&x, &r) in raw.0.iter().zip(raw.1) {
        if x.is_finite() {
            let row = nalgebra::Vector4::new(1.0, x, hinge(kind, x, x0), r);
            m += row * row.transpose();
        }
    }
    let a = m.fixed_view::<3, 3>(0, 0).into_owned();
    let b = m.fixed_view::<3, 1>(0, 3).into_owned();
    let Some(beta) = a.try_inverse().map(|inv| inv * b) else { return (f64::INFINITY, 0.0) };
    (m[(3, 3)] - (beta.transpose() * b)[0], beta[2])
}

/// The threshold refined by golden-section search within a bin of the grid's best.
fn refine(raw: (&[f64], &[f64]), kind: &str, x0: f64, width: f64) -> (f64, f64) {
    let g = 0.618_033_988_749_895;
    let (mut a, mut b) = (x0 - width, x0 + width);
    if kind == "sym" {
        a = a.max(0.0);
    }
    for _ in 0..40 {
        let (c, d) = (b - g * (b - a), a + g * (b - a));
        if raw_fit(raw, kind, c).0 < raw_fit(raw, kind, d).0 {
            b = d;
        } else {
            a = c;
        }
    }
    let x = 0.5 * (a + b);
    (x, raw_fit(raw, kind, x).1)
}

/// An effects-file entry (issue 37's format).
fn toml_entry(id: &str, sensor: SensorKind, i: usize, expr: &str, params: &[(String, f64)], what: &str) -> String {
    let params = params.iter().map(|(n, v)| format!("{n} = {}", sig4(*v))).collect::<Vec<_>>().join(", ");
    let params = if params.is_empty() { "{}".to_string() } else { format!("{{ {params} }}") };
    format!(
        "[[effect]]\nid = \"{id}\"\nsensor = \"{}\"\noutput = \"{}\"\nexpr = \"{expr}\"\ncoefficients = [\"k\"]\nparameters = {params}\ndescription = \"{what}\"\n",
        sensor.as_str(),
        AXES[i]
    )
}

/// Four significant digits, plain.
fn sig4(v: f64) -> String {
    if v == 0.0 || !v.is_finite() {
        return "0.0".into();
    }
    let digits = (3 - v.abs().log10().floor() as i32).max(1) as usize;
    let s = format!("{v:.digits$}");
    if s.contains('.') {
        s
    } else {
        format!("{s}.0")
    }
}
