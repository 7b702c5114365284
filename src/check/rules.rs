//! Acceptance rules (JSON) for a unit's calibration: bounds on coefficients, on their
//! standard errors, on the measured noise, on the corrected residual and reduction factors,
//! on temperature behaviour (bias change over the calibrated range, the range covered, the
//! bias residual after compensation per temperature bin of the checked session) and
//! on model adequacy.
//!
//! ```json
//! { "format": "crosscal-rules/1",
//!   "rules": [
//!     { "kind": "coefficient", "select": "gyro.c_*", "max_abs_deviation": 0.02 },
//!     { "kind": "std_error", "select": "*", "max": 1e-3 },
//!     { "kind": "noise", "sensor": "gyro", "term": "white", "max": 0.2, "unit": "deg/sqrt(h)" },
//!     { "kind": "residual", "sensor": "accel", "max_pct": 0.01 },
//!     { "kind": "reduction", "sensor": "gyro", "min": 10 },
//!     { "kind": "temperature", "sensor": "gyro", "max_bias_change": 1e-3, "covers_c": [-20, 70],
//!       "max_residual": 5e-5 },
//!     { "kind": "adequate" },
//!     { "kind": "datasheet", "quantity": "gyro.misalignment", "max": 1.0, "unit": "mrad" } ],
//!   "decision": "guarded", "k": 2 }
//! ```
//!
//! A `datasheet` rule bounds a quantity of the unit's datasheet ([`crate::datasheet`]) in
//! its datasheet unit and decides with its uncertainty ([`super::guarded`]: `guarded`, the
//! default, or `simple`, per file or per rule, coverage factor `k`).
//!
//! `select` is a coefficient name with `*` wildcards. A deviation is |value − nominal|
//! (nominal 1 for a diagonal scale, 0 otherwise). Noise units: SI by default, or
//! `deg/sqrt(h)`, `deg/s/sqrt(Hz)` (white gyro), `m/s/sqrt(h)`, `ug/sqrt(Hz)` (white
//! accel), `deg/h` (gyro bias instability), `ug` (accel bias instability), `deg/h/sqrt(h)`
//! (gyro random walk). Rules that need a session (residual, reduction, adequate) fail with
//! that reason when none was checked.

use super::guarded::{decide, deciding, AxisDecision, Bounds, Decision, DecisionRule, DEFAULT_K};
pub use super::names::matches;
use super::names::{noise_factor, noise_unit_fits};
use super::CheckReport;
use crate::profile::Profile;
use crate::units::SensorKind;
use serde::{Deserialize, Serialize};
use std::path::Path;

/// The rules format this version reads.
pub const RULES_FORMAT: &str = "crosscal-rules/1";

/// A set of rules.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Rules {
    /// Always [`RULES_FORMAT`].
    pub format: String,
    /// The rules, all of which must pass.
    pub rules: Vec<Rule>,
    /// Decision rule of the `datasheet` rules that do not name one (default `guarded`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub decision: Option<DecisionRule>,
    /// Coverage factor of guarded decisions (default 2).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub k: Option<f64>,
}

/// One rule.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
pub enum Rule {
    /// Bounds on coefficient values.
    Coefficient {
        /// Name pattern (`*` wildcard).
        select: String,
        /// Lower bound on the value.
        #[serde(default)]
        min: Option<f64>,
        /// Upper bound on the value.
        #[serde(default)]
        max: Option<f64>,
        /// Bound on |value − nominal|.
        #[serde(default)]
        max_abs_deviation: Option<f64>,
        /// Rule name shown in reports.
        #[serde(default)]
        name: Option<String>,
    },
    /// Bound on standard errors (a too-uncertain calibration fails; unidentifiable fails).
    StdError {
        /// Name pattern.
        select: String,
        /// Largest standard error, SI.
        max: f64,
        /// Rule name.
        #[serde(default)]
        name: Option<String>,
    },
    /// Bound on a measured noise term (needs a noise section in the profile).
    Noise {
        /// `gyro` or `accel`.
        sensor: SensorKind,
        /// `white`, `bias_instability` or `random_walk`.
        term: String,
        /// Upper bound, in `unit`.
        max: f64,
        /// Unit of `max` (SI when absent).
        #[serde(default)]
        unit: Option<String>,
        /// Rule name.
        #[serde(default)]
        name: Option<String>,
    },
    /// Bound on the corrected error of a checked session (largest over runs and axes).
    Residual {
        /// `gyro` or `accel`.
        sensor: SensorKind,
        /// Largest corrected error, % of the run's amplitude.
        max_pct: f64,
        /// Rule name.
        #[serde(default)]
        name: Option<String>,
    },
    /// Lower bound on the (systematic) reduction factor of a checked session.
    Reduction {
        /// `gyro` or `accel`.
        sensor: SensorKind,
        /// Smallest reduction over axes; noise-limited axes pass.
        min: f64,
        /// Rule name.
        #[serde(default)]
        name: Option<String>,
    },
    /// Temperature behaviour from the profile's temperature-bias polynomial: the bias change
    /// over the calibrated range, and the range the calibration covers.
    Temperature {
        /// `gyro` or `accel`.
        sensor: SensorKind,
        /// Largest change of any axis's bias across the calibrated range, SI (rad/s, m/s²).
        #[serde(default)]
        max_bias_change: Option<f64>,
        /// The range, °C, the calibration must cover ([lowest, highest]).
        #[serde(default)]
        covers_c: Option<[f64; 2]>,
        /// Largest bias residual after compensation, SI: the mean corrected error of the
        /// checked session's samples in each temperature bin, worst bin and axis (needs a
        /// session with temperatures).
        #[serde(default)]
        max_residual: Option<f64>,
        /// Width of the temperature bins of `max_residual`, °C (whole degrees, bins centred on
        /// multiples of it; default 1).
        #[serde(default)]
        bin_c: Option<f64>,
        /// Rule name.
        #[serde(default)]
        name: Option<String>,
    },
    /// Bounds on a datasheet quantity, decided with its uncertainty.
    Datasheet {
        /// Quantity name (`gyro.misalignment`; `crosscal help quantities` lists them).
        quantity: String,
        /// Only this axis (default: every axis of the quantity).
        #[serde(default)]
        axis: Option<String>,
        /// Lower limit, datasheet unit.
        #[serde(default)]
        min: Option<f64>,
        /// Upper limit, datasheet unit.
        #[serde(default)]
        max: Option<f64>,
        /// The quantity's datasheet unit (checked: a limit in another unit is refused).
        #[serde(default)]
        unit: Option<String>,
        /// Bound |value| (default true: datasheet limits are ± a number).
        #[serde(default)]
        magnitude: Option<bool>,
        /// Decision rule (default: the file's, else `guarded`).
        #[serde(default)]
        decision: Option<DecisionRule>,
        /// Coverage factor (default: the file's, else 2).
        #[serde(default)]
        k: Option<f64>,
        /// Rule name.
        #[serde(default)]
        name: Option<String>,
    },
    /// `diagnose` finds no unexplained systematic residual.
    Adequate {
        /// Rule name.
        #[serde(default)]
        name: Option<String>,
    },
}

/// Rules errors.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum RulesError {
    /// Cannot read the file (the operating system's reason follows as the cause).
    #[error("{path}")]
    Io {
        /// File.
        path: std::path::PathBuf,
        /// Cause.
        source: std::io::Error,
    },
    /// Not JSON, or a key repeated.
    #[error("{path}:{line}:{column}: not valid JSON: {msg}")]
    Json {
        /// File.
        path: std::path::PathBuf,
        /// Line.
        line: usize,
        /// Column.
        column: usize,
        /// What is wrong.
        msg: String,
    },
    /// Not valid rules (line 0: a problem of the whole file or of a rule, no single place).
    #[error("{}: {msg}", place(path, *line, *column))]
    Parse {
        /// File.
        path: std::path::PathBuf,
        /// Line.
        line: usize,
        /// Column.
        column: usize,
        /// What is wrong.
        msg: String,
    },
    /// Unknown version.
    #[error("{path}: rules format '{found}' is not supported: expected '{RULES_FORMAT}'")]
    UnknownFormat {
        /// File.
        path: std::path::PathBuf,
        /// Found.
        found: String,
    },
}

impl Rules {
    /// Reads and validates a rules file.
    pub fn read(path: &Path) -> Result<Self, RulesError> {
        let text =
            crate::atomic::read_text(path).map_err(|source| RulesError::Io { path: path.to_path_buf(), source })?;
        Self::parse(path, &text)
    }

    /// Parses rules (the path names the file in messages).
    pub fn parse(path: &Path, text: &str) -> Result<Self, RulesError> {
        let text = text.strip_prefix('\u{feff}').unwrap_or(text);
        let v = crate::json::parse_unique(text).map_err(|e| RulesError::Json {
            path: path.to_path_buf(),
            line: e.line(),
            column: e.column(),
            msg: e.to_string(),
        })?;
        if let Some(found) = v.get("format").and_then(|f| f.as_str()).filter(|f| *f != RULES_FORMAT) {
            return Err(RulesError::UnknownFormat { path: path.to_path_buf(), found: found.to_string() });
        }
        let r: Rules = serde_json::from_str(text).map_err(|e| RulesError::Parse {
            path: path.to_path_buf(),
            line: e.line(),
            column: e.column(),
            msg: format!("{e}; see `crosscal help rules` for the rule kinds"),
        })?;
        if r.format != RULES_FORMAT {
            return Err(RulesError::UnknownFormat { path: path.to_path_buf(), found: r.format });
        }
        let bad = |msg: String| RulesError::Parse { path: path.to_path_buf(), line: 0, column: 0, msg };
        if r.k.is_some_and(|k| !(k.is_finite() && k > 0.0)) {
            return Err(bad("k must be a positive number".into()));
        }
        for rule in &r.rules {
            if let Rule::Datasheet { .. } = rule {
                datasheet_rule_ok(rule).map_err(bad)?;
            }
            if let Rule::Temperature { max_residual, bin_c, .. } = rule {
                let bad = |v: &Option<f64>, min: f64| v.is_some_and(|v| !(v.is_finite() && v >= min));
                if bad(max_residual, 0.0) || bad(bin_c, 1.0) {
                    return Err(RulesError::Parse {
                        path: path.to_path_buf(),
                        line: 0,
                        column: 0,
                        msg: "temperature rule: max_residual must be a non-negative number (SI) and bin_c at least 1 degC".into(),
                    });
                }
            }
            if let Rule::Noise { sensor, term, unit, .. } = rule {
                if !["white", "bias_instability", "random_walk"].contains(&term.as_str()) {
                    return Err(RulesError::Parse {
                        path: path.to_path_buf(),
                        line: 0,
                        column: 0,
                        msg: format!("noise term '{term}': expected white, bias_instability or random_walk"),
                    });
                }
                if let Some(u) = unit {
                    let fits = noise_unit_fits(*sensor, term, u);
                    if noise_factor(u).is_some() && !fits {
                        return Err(RulesError::Parse {
                            path: path.to_path_buf(),
                            line: 0,
                            column: 0,
                            msg: format!(
                                "noise unit '{u}' does not measure the {sensor} {term} term; see `crosscal help rules`"
                            ),
                        });
                    }
                    if noise_factor(u).is_none() {
                        return Err(RulesError::Parse {
                            path: path.to_path_buf(),
                            line: 0,
                            column: 0,
                            msg: format!(
                                "noise unit '{u}' is not known; see `crosscal help rules` for the accepted units"
                            ),
                        });
                    }
                }
            }
        }
        Ok(r)
    }
}

/// Whether a datasheet rule names a known quantity in its unit, with a limit.
fn datasheet_rule_ok(rule: &Rule) -> Result<(), String> {
    let Rule::Datasheet { quantity, min, max, unit, k, .. } = rule else { return Ok(()) };
    let Some(sp) = crate::datasheet::spec(quantity) else {
        let names: Vec<&str> = crate::datasheet::QUANTITIES.iter().map(|q| q.name).collect();
        return Err(format!("datasheet quantity '{quantity}' is not known: expected one of {}", names.join(", ")));
    };
    if let Some(u) = unit.as_deref().filter(|u| *u != sp.unit) {
        return Err(format!("datasheet rule on {quantity}: unit '{u}', but {quantity} is in {}", sp.unit));
    }
    if min.is_none() && max.is_none() {
        return Err(format!("datasheet rule on {quantity}: give min, max or both"));
    }
    if [*min, *max].iter().flatten().any(|v| !v.is_finite()) || k.is_some_and(|k| !(k.is_finite() && k > 0.0)) {
        return Err(format!("datasheet rule on {quantity}: limits must be numbers and k positive"));
    }
    Ok(())
}

/// `file:line:column`, or the file alone when there is no single place (line 0).
fn place(path: &std::path::Path, line: usize, column: usize) -> String {
    if line == 0 {
        path.display().to_string()
    } else {
        format!("{}:{line}:{column}", path.display())
    }
}

/// The outcome of one rule.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RuleResult {
    /// Rule name (given, or generated from the rule).
    pub rule: String,
    /// Passed.
    pub pass: bool,
    /// The numbers behind the verdict, or why it failed.
    pub detail: String,
    /// pass, fail or (a datasheet rule under `guarded`) indeterminate.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub decision: Option<Decision>,
    /// Datasheet rules: the deciding axis's value, datasheet unit.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub value: Option<f64>,
    /// Its standard uncertainty.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub uncertainty: Option<f64>,
    /// The limit it is judged against (the nearest).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub limit: Option<f64>,
    /// The datasheet unit.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub unit: Option<String>,
    /// Every axis's decision.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub axes: Vec<AxisDecision>,
    /// The measurement that would resolve an indeterminate decision.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub resolve: Option<String>,
}

impl RuleResult {
    /// A pass/fail outcome without numbers.
    pub fn plain(rule: String, pass: bool, detail: String) -> Self {
        Self {
            rule,
            pass,
            detail,
            decision: Some(if pass { Decision::Pass } else { Decision::Fail }),
            value: None,
            uncertainty: None,
            limit: None,
            unit: None,
            axes: Vec::new(),
            resolve: None,
        }
    }

    /// The decision (pass/fail from `pass` where none was recorded).
    pub fn decided(&self) -> Decision {
        self.decision.unwrap_or(if self.pass { Decision::Pass } else { Decision::Fail })
    }
}

/// What was learnt from the unit's session besides its profile.
#[derive(Debug, Clone, Default)]
pub struct Evidence<'a> {
    /// Check of the session (or of held-out runs) with the profile.
    pub check: Option<&'a CheckReport>,
    /// Diagnose verdict and its unexplained findings, if it was run.
    pub adequacy: Option<(bool, Vec<String>)>,
    /// The session is a protocol session (poses and turns): it has no per-sample reference,
    /// so rules on the check say that rather than "no session was checked".
    pub protocol: bool,
    /// The unit's datasheet (with its stored calibrations); built from the profile alone
    /// when absent.
    pub datasheet: Option<&'a crate::datasheet::Datasheet>,
}

/// Why a rule that needs the session's check has none.
fn no_check(ev: &Evidence<'_>) -> String {
    if ev.protocol {
        "a protocol session has no per-sample reference to check against (its poses and turns are in the fit)".into()
    } else {
        "no session was checked".into()
    }
}

type Coefs<'a> = [&'a crate::estimate::Coefficient];

/// (label, pass, detail) of one rule.
type Outcome = (String, bool, String);

/// Bounds on coefficients; deviations are from each coefficient's nominal value in the
/// catalogue (1 on a scale diagonal, else 0).
fn coefficient_rule(
    coefs: &Coefs<'_>,
    model: Option<&crate::model::Model>,
    select: &str,
    (min, max, max_abs_deviation): (Option<f64>, Option<f64>, Option<f64>),
    label: String,
) -> Outcome {
    let picked: Vec<_> = coefs.iter().filter(|c| matches(select, &c.name)).collect();
    let bad: Vec<String> = picked
        .iter()
        .filter_map(|c| {
            let nominal = model.and_then(|m| m.nominal(&c.name)).unwrap_or(0.0);
            let dev = (c.value - nominal).abs();
            let out = min.is_some_and(|m| c.value < m)
                || max.is_some_and(|m| c.value > m)
                || max_abs_deviation.is_some_and(|m| dev > m);
            out.then(|| format!("{} = {:.6e}", c.name, c.value))
        })
        .collect();
    if picked.is_empty() {
        (label, false, format!("no coefficient matches '{select}'"))
    } else if bad.is_empty() {
        (label, true, format!("{} coefficients within bounds", picked.len()))
    } else {
        (label, false, format!("out of bounds: {}", bad.join(", ")))
    }
}

fn std_error_rule(coefs: &Coefs<'_>, select: &str, max: f64, label: String) -> Outcome {
    if !coefs.iter().any(|c| matches(select, &c.name)) {
        return (label, false, format!("no coefficient matches '{select}'"));
    }
    let picked: Vec<_> =
        coefs.iter().filter(|c| matches(select, &c.name) && c.status != crate::estimate::CoefStatus::Fixed).collect();
    let bad: Vec<String> = picked
        .iter()
        .filter_map(|c| match c.std_error {
            Some(se) if se <= max => None,
            Some(se) => Some(format!("{} ± {se:.3e}", c.name)),
            None => Some(format!("{} unidentifiable", c.name)),
        })
        .collect();
    if bad.is_empty() {
        (label, true, format!("{} standard errors ≤ {max:e}", picked.len()))
    } else {
        (label, false, format!("too uncertain: {}", bad.join(", ")))
    }
}

fn noise_rule(
    noise: Option<&crate::noise::NoiseReport>,
    sensor: SensorKind,
    term: &str,
    max: f64,
    unit: Option<&str>,
    label: String,
) -> Outcome {
    let k = unit.and_then(noise_factor).unwrap_or(1.0);
    let Some(n) = noise else {
        return (label, false, "the profile has no noise characterisation (crosscal noise --store)".into());
    };
    // Bias instability by the standard reading (the measured curve's minimum / 0.664) where
    // the curve gives one, the model fit's otherwise.
    let vals: Vec<(String, Option<f64>)> = n
        .channels
        .iter()
        .filter(|c| c.sensor() == sensor)
        .map(|c| {
            let v = match term {
                "white" => c.white(),
                "bias_instability" => c.bias(),
                _ => c.random_walk,
            };
            (c.channel.clone(), v)
        })
        .collect();
    let worst = vals.iter().filter_map(|v| v.1).fold(0.0, f64::max) / k;
    let u = unit.unwrap_or("SI");
    if vals.is_empty() {
        (label, false, format!("no {sensor} channel in the noise characterisation"))
    } else {
        (label, worst <= max, format!("worst axis {worst:.4e} {u} (limit {max} {u})"))
    }
}

/// The `noise` rules of `rules` against a noise characterisation alone (a unit of a lot
/// measured at rest, no profile): the other rule kinds need a profile and are left out.
pub fn evaluate_noise(rules: &Rules, noise: &crate::noise::NoiseReport) -> Vec<RuleResult> {
    rules
        .rules
        .iter()
        .filter_map(|rule| match rule {
            Rule::Noise { sensor, term, max, unit, name } => {
                let label = name.clone().unwrap_or_else(|| format!("{sensor} {term} noise"));
                let (rule, pass, detail) = noise_rule(Some(noise), *sensor, term, *max, unit.as_deref(), label);
                Some(RuleResult::plain(rule, pass, detail))
            }
            _ => None,
        })
        .collect()
}

fn residual_rule(ev: &Evidence<'_>, sensor: SensorKind, max_pct: f64, label: String) -> Outcome {
    let Some(r) = ev.check else { return (label, false, no_check(ev)) };
    let worst = r.summary.iter().filter(|a| a.sensor == sensor).filter_map(|a| a.after_pct).fold(0.0, f64::max);
    (label, worst <= max_pct, format!("largest corrected error {worst:.3e} % (limit {max_pct} %)"))
}

fn reduction_rule(ev: &Evidence<'_>, sensor: SensorKind, min: f64, label: String) -> Outcome {
    let Some(r) = ev.check else { return (label, false, no_check(ev)) };
    let bad: Vec<String> = r
        .summary
        .iter()
        .filter(|a| a.sensor == sensor)
        .filter(|a| !a.noise_limited && a.reduction_sys.is_none_or(|v| v < min))
        .map(|a| format!("{} {}: {:.3e}×", a.sensor, a.axis, a.reduction_sys.unwrap_or(0.0)))
        .collect();
    if bad.is_empty() {
        (label, true, format!("every axis ≥ {min}× or at the noise floor"))
    } else {
        (label, false, format!("below {min}×: {}", bad.join(", ")))
    }
}

fn adequate_rule(ev: &Evidence<'_>, label: String) -> Outcome {
    match &ev.adequacy {
        None => (label, false, "diagnose was not run".into()),
        Some((true, _)) => (label, true, "diagnose: adequate (no systematic residual, nothing missing)".into()),
        Some((false, why)) => (label, false, format!("diagnose: not adequate: {}", why.join("; "))),
    }
}

/// The bounds of a `temperature` rule.
#[derive(Debug, Clone, Copy, Default)]
struct TemperatureLimits {
    max_change: Option<f64>,
    covers: Option<[f64; 2]>,
    max_residual: Option<f64>,
    bin_c: Option<f64>,
}

/// Bins with fewer samples than this are too few to judge a residual on and are left out.
pub const MIN_BIN_SAMPLES: u64 = 100;

/// The largest bias residual after compensation in a checked session (see
/// [`worst_temperature_residual`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TemperatureResidual {
    /// |mean corrected error| of the worst bin and axis, SI.
    pub residual: f64,
    /// Its axis.
    pub axis: char,
    /// Its bin, °C ([lo, hi), centred on a multiple of the bin width).
    pub bin_c: [f64; 2],
    /// Samples in it.
    pub samples: u64,
    /// Standard error of its mean (the bin's own spread / √n), SI.
    pub std_error: f64,
}

/// The largest bias residual after compensation of `sensor` in a checked session: the run
/// checks' whole-degree bins of corrected error merged over runs into `bin_c`-wide bins
/// centred on multiples of `bin_c` (pooled mean and mean square), bins of fewer than
/// [`MIN_BIN_SAMPLES`] left out; the worst |mean| over bins and axes. None when no bin has
/// enough samples.
pub fn worst_temperature_residual(check: &CheckReport, sensor: SensorKind, bin_c: f64) -> Option<TemperatureResidual> {
    let width = bin_c.max(1.0).round();
    // Per merged bin and axis: samples, Σ error, Σ error².
    let mut merged: std::collections::BTreeMap<i64, [(u64, f64, f64); 3]> = Default::default();
    for b in check.runs.iter().flat_map(|r| &r.temp_bins) {
        let m = merged.entry((b.centre_c / width).round() as i64).or_default();
        for (i, acc) in m.iter_mut().enumerate() {
            let j = 3 * sensor.index() + i;
            let n = b.n[j] as f64;
            acc.0 += b.n[j];
            acc.1 += b.mean[j] * n;
            acc.2 += b.rms[j] * b.rms[j] * n;
        }
    }
    let mut worst: Option<TemperatureResidual> = None;
    for (key, axes) in merged {
        for (i, &(n, sum, sq)) in axes.iter().enumerate() {
            if n < MIN_BIN_SAMPLES {
                continue;
            }
            let nf = n as f64;
            let mean = sum / nf;
            if worst.is_none_or(|w| mean.abs() > w.residual) {
                let lo = (key as f64 - 0.5) * width;
                worst = Some(TemperatureResidual {
                    residual: mean.abs(),
                    axis: crate::units::AXES[i],
                    bin_c: [lo, lo + width],
                    samples: n,
                    std_error: ((sq / nf - mean * mean).max(0.0) / nf).sqrt(),
                });
            }
        }
    }
    worst
}

/// `max_residual` of a temperature rule: pass, and the words behind it.
fn temperature_residual(ev: &Evidence<'_>, sensor: SensorKind, max: f64, bin_c: Option<f64>) -> (bool, String) {
    let Some(check) = ev.check else { return (false, format!("bias residual: {}", no_check(ev))) };
    match worst_temperature_residual(check, sensor, bin_c.unwrap_or(1.0)) {
        None => (
            false,
            format!(
                "bias residual: the checked session has no temperature bin of {MIN_BIN_SAMPLES} samples or more (no temperatures?)"
            ),
        ),
        Some(w) => (
            w.residual <= max,
            format!(
                "largest bias residual after compensation {:.4e} (axis {}, {}..{} degC, {} samples, ±{:.1e}) against {max:.4e}",
                w.residual, w.axis, w.bin_c[0], w.bin_c[1], w.samples, w.std_error
            ),
        ),
    }
}

/// The temperature rule: the calibrated range must cover `covers_c`; each axis's bias
/// b(T) = Σₖ tbₖ (T − 20)ᵏ (the profile's temperature-bias terms of degree 1–3) may change by
/// at most `max_change` across the calibrated range (evaluated on 401 points); and the
/// checked session's bias residual per temperature bin may be at most `max_residual`.
fn temperature_rule(
    profile: &Profile,
    ev: &Evidence<'_>,
    sensor: SensorKind,
    limits: TemperatureLimits,
    label: String,
) -> Outcome {
    let TemperatureLimits { max_change, covers, max_residual, bin_c } = limits;
    let mut detail = Vec::new();
    let mut pass = true;
    if let Some(max) = max_residual {
        let (ok, words) = temperature_residual(ev, sensor, max, bin_c);
        pass &= ok;
        detail.push(words);
        if max_change.is_none() && covers.is_none() {
            return (label, pass, detail.join("; "));
        }
    }
    let Some([lo, hi]) = profile.temperature_range_c() else {
        detail.push("the profile records no temperature (its runs had no temp column)".into());
        return (label, false, detail.join("; "));
    };
    detail.insert(0, format!("calibrated over {lo:.1}..{hi:.1} degC"));
    if let Some([a, b]) = covers {
        let ok = lo <= a && hi >= b;
        pass &= ok;
        detail.push(format!("must cover {a:.1}..{b:.1} degC: {}", if ok { "yes" } else { "NO" }));
    }
    if let Some(max) = max_change {
        let fit = profile.sensor(sensor);
        let coef = |k: &str, ax: char| fit.value(&format!("{}.{k}_{ax}", sensor.as_str()));
        let any = crate::units::AXES.iter().any(|&ax| ["tb", "tb2", "tb3"].iter().any(|k| coef(k, ax).is_some()));
        if !any {
            detail.push(format!(
                "the profile has no {sensor} temperature-bias terms: the bias change over the range is unknown"
            ));
            return (label, false, detail.join("; "));
        }
        let (mut worst, mut at) = (0.0_f64, 'x');
        for ax in crate::units::AXES {
            let c = ["tb", "tb2", "tb3"].map(|k| coef(k, ax).unwrap_or(0.0));
            let bias = |t: f64| {
                let d = t - crate::model::T_REF_C;
                ((c[2] * d + c[1]) * d + c[0]) * d
            };
            let (mut min, mut maxv) = (f64::INFINITY, f64::NEG_INFINITY);
            for i in 0..=400 {
                let v = bias(lo + (hi - lo) * f64::from(i) / 400.0);
                min = min.min(v);
                maxv = maxv.max(v);
            }
            if maxv - min > worst {
                worst = maxv - min;
                at = ax;
            }
        }
        let ok = worst <= max;
        pass &= ok;
        detail.push(format!("largest bias change {worst:.4e} (axis {at}) against {max:.4e}"));
    }
    (label, pass, detail.join("; "))
}

/// Evaluates every rule on a profile and what was checked on its session.
pub fn evaluate(rules: &Rules, profile: &Profile, ev: &Evidence<'_>) -> Vec<RuleResult> {
    let coefs: Vec<&crate::estimate::Coefficient> =
        profile.gyro.coefficients.iter().chain(&profile.accel.coefficients).collect();
    let model = profile.model().ok();
    let own;
    let sheet = match ev.datasheet {
        Some(d) => d,
        None => {
            own = crate::datasheet::build("the profile", profile, &[], &Default::default());
            &own
        }
    };
    rules
        .rules
        .iter()
        .map(|rule| {
            let (rule, pass, detail) = match rule {
                Rule::Datasheet { .. } => return datasheet_rule(rules, rule, sheet),
                Rule::Coefficient { select, min, max, max_abs_deviation, name } => coefficient_rule(
                    &coefs,
                    model.as_ref(),
                    select,
                    (*min, *max, *max_abs_deviation),
                    name.clone().unwrap_or_else(|| format!("coefficient {select}")),
                ),
                Rule::StdError { select, max, name } => std_error_rule(
                    &coefs,
                    select,
                    *max,
                    name.clone().unwrap_or_else(|| format!("standard error {select}")),
                ),
                Rule::Noise { sensor, term, max, unit, name } => noise_rule(
                    profile.noise.as_ref(),
                    *sensor,
                    term,
                    *max,
                    unit.as_deref(),
                    name.clone().unwrap_or_else(|| format!("{sensor} {term} noise")),
                ),
                Rule::Residual { sensor, max_pct, name } => {
                    residual_rule(ev, *sensor, *max_pct, name.clone().unwrap_or_else(|| format!("{sensor} residual")))
                }
                Rule::Reduction { sensor, min, name } => {
                    reduction_rule(ev, *sensor, *min, name.clone().unwrap_or_else(|| format!("{sensor} reduction")))
                }
                Rule::Adequate { name } => adequate_rule(ev, name.clone().unwrap_or_else(|| "model adequate".into())),
                Rule::Temperature { sensor, max_bias_change, covers_c, max_residual, bin_c, name } => temperature_rule(
                    profile,
                    ev,
                    *sensor,
                    TemperatureLimits {
                        max_change: *max_bias_change,
                        covers: *covers_c,
                        max_residual: *max_residual,
                        bin_c: *bin_c,
                    },
                    name.clone().unwrap_or_else(|| format!("{sensor} temperature")),
                ),
            };
            RuleResult::plain(rule, pass, detail)
        })
        .collect()
}

/// A datasheet rule on a unit's datasheet: every axis decided, the unit's decision the
/// worst, reported with the deciding axis's value, uncertainty and nearest limit.
fn datasheet_rule(rules: &Rules, rule: &Rule, sheet: &crate::datasheet::Datasheet) -> RuleResult {
    let Rule::Datasheet { quantity, axis, min, max, unit, magnitude, decision, k, name } = rule else {
        return RuleResult::plain("?".into(), false, "not a datasheet rule".into());
    };
    let label = name.clone().unwrap_or_else(|| format!("datasheet {quantity}"));
    let bounds = Bounds {
        min: *min,
        max: *max,
        magnitude: magnitude.unwrap_or(true),
        rule: decision.or(rules.decision).unwrap_or_default(),
        k: k.or(rules.k).unwrap_or(DEFAULT_K),
    };
    let unit = unit.clone().or_else(|| crate::datasheet::spec(quantity).map(|s| s.unit.to_string()));
    let axes = match decide(sheet, quantity, axis.as_deref(), &bounds) {
        Ok(a) => a,
        Err(why) => {
            let mut r = RuleResult::plain(label, false, why);
            r.unit = unit;
            return r;
        }
    };
    let Some(worst) = deciding(&axes).cloned() else {
        return RuleResult::plain(label, false, format!("{quantity}: nothing to decide"));
    };
    let shown = if bounds.magnitude { worst.value.abs() } else { worst.value };
    let limit = match (bounds.min, bounds.max) {
        (Some(lo), Some(hi)) => Some(if (shown - lo).abs() < (hi - shown).abs() { lo } else { hi }),
        (lo, hi) => hi.or(lo),
    };
    let u_name = unit.clone().unwrap_or_default();
    let how = match bounds.rule {
        DecisionRule::Guarded => format!("guarded, k = {}", bounds.k),
        DecisionRule::Simple => "simple".into(),
    };
    let detail = format!(
        "{}{} = {:.4e} ± {:.2e} {u_name} against {} {:.4e} ({how}): {}",
        if bounds.magnitude { "|" } else { "" },
        format_args!("{quantity} {}{}", worst.axis, if bounds.magnitude { "|" } else { "" }),
        shown,
        worst.uncertainty,
        if limit == bounds.max { "max" } else { "min" },
        limit.unwrap_or(f64::NAN),
        worst.decision.word()
    );
    RuleResult {
        rule: label,
        pass: worst.decision == Decision::Pass,
        detail,
        decision: Some(worst.decision),
        value: Some(worst.value),
        uncertainty: Some(worst.uncertainty),
        limit,
        unit,
        axes,
        resolve: None,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    #[allow(clippy::float_cmp)]
    fn wildcards() {
        assert!(matches("gyro.c_*", "gyro.c_xy"));
        assert!(!matches("gyro.c_*", "gyro.e_xy"));
        assert!(matches("*", "accel.b_x"));
        assert!(matches("*.b_*", "accel.b_x"));
        assert!(matches("accel.k_xx", "accel.k_xx"));
        assert!(!matches("accel.k_x", "accel.k_xx"));
        let m = crate::model::Model::default_model();
        assert_eq!(m.nominal("gyro.c_yy"), Some(1.0));
        assert_eq!(m.nominal("gyro.c_xy"), Some(0.0));
        assert_eq!(m.nominal("gyro.e_xx"), Some(0.0));
        assert_eq!(m.nominal("gyro.nothing"), None);
    }

    #[test]
    fn unknown_fields_and_versions_are_refused() {
        let p = Path::new("r.json");
        assert!(Rules::parse(p, r#"{"format":"crosscal-rules/1","rules":[{"kind":"adequate"}]}"#).is_ok());
        let e = Rules::parse(p, r#"{"format":"crosscal-rules/9","rules":[]}"#).unwrap_err();
        assert!(e.to_string().contains("not supported"), "{e}");
        let e = Rules::parse(p, r#"{"format":"crosscal-rules/1","rules":[{"kind":"coefficient","selct":"*"}]}"#)
            .unwrap_err();
        assert!(e.to_string().contains("r.json:1:"), "{e}");
        let e = Rules::parse(
            p,
            r#"{"format":"crosscal-rules/1","rules":[{"kind":"noise","sensor":"gyro","term":"white","max":1,"unit":"furlong"}]}"#,
        )
        .unwrap_err();
        assert!(e.to_string().contains("furlong"), "{e}");
        // A known unit of another sensor or term is a mistake, not a number to convert.
        let e = Rules::parse(
            p,
            r#"{"format":"crosscal-rules/1","rules":[{"kind":"noise","sensor":"accel","term":"bias_instability","max":1,"unit":"deg/h"}]}"#,
        )
        .unwrap_err();
        assert!(e.to_string().contains("does not measure the accel bias_instability"), "{e}");
        for (sensor, term, unit) in
            [("gyro", "white", "deg/sqrt(h)"), ("accel", "bias_instability", "ug"), ("gyro", "random_walk", "SI")]
        {
            let text = format!(
                r#"{{"format":"crosscal-rules/1","rules":[{{"kind":"noise","sensor":"{sensor}","term":"{term}","max":1,"unit":"{unit}"}}]}}"#
            );
            assert!(Rules::parse(p, &text).is_ok(), "{sensor} {term} in {unit}");
        }
    }

    /// A `std_error` rule whose `select` matches nothing is a typo, and fails (it passed).
    #[test]
    fn a_std_error_rule_selecting_nothing_fails() {
        let c = crate::estimate::Coefficient {
            name: "gyro.b_x".into(),
            effect: "gyro-bias".into(),
            channel: 0,
            unit: "rad/s".into(),
            value: 0.0,
            std_error: Some(1e-6),
            status: crate::estimate::CoefStatus::Fitted,
        };
        let coefs = [&c];
        assert!(std_error_rule(&coefs, "gyro.b_*", 1e-5, "r".into()).1);
        let (_, pass, detail) = std_error_rule(&coefs, "gyro.bx*", 1e-5, "r".into());
        assert!(!pass && detail.contains("no coefficient matches"), "{detail}");
    }
}
