//! A unit's datasheet: every IEEE 952 / 1293 quantity a production engineer quotes (bias
//! in °/h and mg, repeatability, in-run stability, ARW/VRW, scale-factor error,
//! nonlinearity and asymmetry in ppm, misalignment in mrad, g-sensitivity, temperature
//! coefficients, long-term trends) in its datasheet unit, with its standard uncertainty
//! propagated from the fit's covariance ([`propagate`]) or the noise reading's interval,
//! the calibrations it comes from and its definition ([`catalogue`]). Quantities the
//! profile cannot give are listed as not measured, with what would measure them.
//!
//! The axes of C_ω and K are split into scale factors, axis-to-axis non-orthogonality and
//! the rotation to the reference frame by a polar decomposition ([`axes`]). Lot statistics
//! over datasheet values — Cpk with its confidence interval and the control chart across
//! lots — are in [`lot`].

pub mod axes;
pub mod catalogue;
mod history;
pub mod lot;
mod propagate;
mod report;

use crate::estimate::SensorFit;
use crate::profile::Profile;
use crate::units::{SensorKind, AXES};
pub use catalogue::{spec, Spec, QUANTITIES};
pub use report::{html, text};
use serde::{Deserialize, Serialize};
use std::path::PathBuf;

/// Degrees per radian × seconds per hour: rad/s → °/h.
pub const DEG_H_PER_RAD_S: f64 = 180.0 / std::f64::consts::PI * 3600.0;

/// One quantity of one axis (or axis pair, or matrix element) of a unit.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Quantity {
    /// Name, as the `datasheet` rule kind names it (`gyro.misalignment`).
    pub name: String,
    /// Sensor.
    pub sensor: SensorKind,
    /// Axis (`x`), axis pair (`xy`: non-orthogonality) or element (`xy`: output x per input
    /// y; `x_yz`: g² term); None for a quantity not measured.
    pub axis: Option<String>,
    /// Value in `unit`; None when not measured.
    pub value: Option<f64>,
    /// Standard uncertainty in `unit` (k = 1).
    pub uncertainty: Option<f64>,
    /// Datasheet unit.
    pub unit: String,
    /// Number of calibrations behind it (repeatability and trends).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub count: Option<usize>,
    /// 90 % interval (repeatability: chi-square on n − 1 degrees of freedom).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub interval90: Option<[f64; 2]>,
    /// The profiles and runs (or noise recording) it comes from.
    pub sources: Vec<String>,
    /// Its definition.
    pub definition: String,
    /// Where the reference defines it.
    pub reference: String,
    /// Why it is not measured and what would measure it.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub not_measured: Option<String>,
}

/// A unit's datasheet.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Datasheet {
    /// Serial.
    pub unit: String,
    /// The profile in force it is built from.
    pub profile: String,
    /// That profile's creation time.
    pub created_utc: String,
    /// Calibrations of the unit in the store (distinct sets of files).
    pub calibrations: usize,
    /// Every quantity: measured ones per axis, then the ones not measured.
    pub quantities: Vec<Quantity>,
}

impl Datasheet {
    /// The measured entries of quantity `name` (every axis).
    pub fn get<'a>(&'a self, name: &'a str) -> impl Iterator<Item = &'a Quantity> + 'a {
        self.quantities.iter().filter(move |q| q.name == name && q.value.is_some())
    }

    /// The entry of `name` on `axis`.
    pub fn value(&self, name: &str, axis: &str) -> Option<&Quantity> {
        self.quantities.iter().find(|q| q.name == name && q.value.is_some() && q.axis.as_deref() == Some(axis))
    }
}

/// What the profile does not say: the calibrated range for nonlinearity in ppm of FS.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct DatasheetOptions {
    /// Gyro full scale (largest |rate| of the calibration), rad/s.
    pub gyro_range_rad_s: Option<f64>,
    /// Accelerometer full scale, m/s² (None: 1 g, the range of a calibration under gravity).
    pub accel_range_m_s2: Option<f64>,
}

/// A measured value of one entry.
struct Entry {
    axis: String,
    value: f64,
    u: f64,
    sources: Vec<String>,
    count: Option<usize>,
    interval90: Option<[f64; 2]>,
}

impl Entry {
    fn new(axis: impl Into<String>, (value, u): (f64, f64), sources: &[String]) -> Self {
        Self { axis: axis.into(), value, u, sources: sources.to_vec(), count: None, interval90: None }
    }
}

/// The entries of one quantity, or why there are none.
type Found = Result<Vec<Entry>, String>;

/// Accumulates the quantities in catalogue order.
struct Sheet {
    out: Vec<Quantity>,
    missing: Vec<Quantity>,
}

impl Sheet {
    fn push(&mut self, name: &str, found: Found) {
        let Some(sp) = spec(name) else { return };
        let base = |axis, value, uncertainty| Quantity {
            name: name.to_string(),
            sensor: if name.starts_with("gyro") { SensorKind::Gyro } else { SensorKind::Accel },
            axis,
            value,
            uncertainty,
            unit: sp.unit.to_string(),
            count: None,
            interval90: None,
            sources: Vec::new(),
            definition: sp.definition.to_string(),
            reference: catalogue::reference(name),
            not_measured: None,
        };
        match found {
            Ok(v) if !v.is_empty() => self.out.extend(v.into_iter().map(|e| Quantity {
                count: e.count,
                interval90: e.interval90,
                sources: e.sources,
                ..base(Some(e.axis), Some(e.value), Some(e.u))
            })),
            Ok(_) => {
                self.missing.push(Quantity { not_measured: Some(sp.remedy.to_string()), ..base(None, None, None) })
            }
            Err(why) => self.missing.push(Quantity {
                not_measured: Some(format!("{why}; would need: {}", sp.remedy)),
                ..base(None, None, None)
            }),
        }
    }
}

/// Display factor of a bias (rad/s → °/h, m/s² → mg).
fn bias_factor(sensor: SensorKind, g: f64) -> f64 {
    match sensor {
        SensorKind::Gyro => DEG_H_PER_RAD_S,
        SensorKind::Accel => 1e3 / g,
    }
}

/// The scale-coupling matrix's coefficient names (c or k), row-major.
fn matrix_names(sensor: SensorKind) -> Vec<String> {
    let (s, m) = match sensor {
        SensorKind::Gyro => ("gyro", "c"),
        SensorKind::Accel => ("accel", "k"),
    };
    AXES.iter().flat_map(|a| AXES.iter().map(move |b| format!("{s}.{m}_{a}{b}"))).collect()
}

fn as_matrix(x: &[f64]) -> [[f64; 3]; 3] {
    [[x[0], x[1], x[2]], [x[3], x[4], x[5]], [x[6], x[7], x[8]]]
}

/// One entry per axis of `sensor.{prefix}_{axis}`, scaled by `k`.
fn per_axis(fit: &SensorFit, prefix: &str, k: f64, src: &[String]) -> Found {
    let s = fit.sensor.as_str();
    AXES.iter()
        .map(|a| {
            let (v, u) = propagate::propagate(fit, &[format!("{s}.{prefix}_{a}")], &|x| x[0] * k)?;
            Ok(Entry::new(a.to_string(), (v, u), src))
        })
        .collect()
}

/// Every element `sensor.{prefix}_{ij}` present in the profile, scaled by `k`.
fn elements(fit: &SensorFit, prefix: &str, k: f64, src: &[String]) -> Found {
    let lead = format!("{}.{prefix}_", fit.sensor.as_str());
    let picked: Vec<_> = fit.coefficients.iter().filter(|c| c.name.starts_with(&lead)).collect();
    if picked.is_empty() {
        return Ok(Vec::new());
    }
    picked
        .iter()
        .map(|c| {
            let (v, u) = propagate::propagate(fit, std::slice::from_ref(&c.name), &|x| x[0] * k)?;
            Ok(Entry::new(&c.name[lead.len()..], (v, u), src))
        })
        .collect()
}

/// Scale factor error, non-orthogonality and frame rotation from the decomposition of the
/// scale-coupling matrix ([`axes::decompose`]); `what` 0, 1, 2 picks which.
fn axes_quantity(fit: &SensorFit, what: usize, src: &[String]) -> Found {
    let names = matrix_names(fit.sensor);
    if fit.get(&names[0]).is_none() {
        return Ok(Vec::new());
    }
    let labels: [String; 3] = match what {
        1 => axes::PAIRS.map(|(i, j)| format!("{}{}", AXES[i], AXES[j])),
        _ => AXES.map(|a| a.to_string()),
    };
    (0..3)
        .map(|k| {
            let f = move |x: &[f64]| match axes::decompose(&as_matrix(x)) {
                None => f64::NAN,
                Some(a) => match what {
                    0 => (a.scale[k] - 1.0) * 1e6,
                    1 => a.non_orthogonality_rad[k] * 1e3,
                    _ => a.rotation_rad[k] * 1e3,
                },
            };
            let (v, u) = propagate::propagate(fit, &names, &f)?;
            if !v.is_finite() {
                return Err("the scale-coupling matrix has a zero or degenerate row".into());
            }
            Ok(Entry::new(labels[k].clone(), (v, u), src))
        })
        .collect()
}

/// Nonlinearity in ppm of full scale from the quadratic and cubic terms present.
fn nonlinearity(fit: &SensorFit, fs: Option<f64>, src: &[String]) -> Found {
    let s = fit.sensor.as_str();
    let has = |p: &str| fit.get(&format!("{s}.{p}_x")).is_some();
    if !has("q") && !has("k3") {
        return Ok(Vec::new());
    }
    let Some(fs) = fs else {
        return Err("the calibrated range is not known (give --gyro-range)".into());
    };
    AXES.iter()
        .map(|a| {
            let names: Vec<String> = ["q", "k3"].iter().filter(|p| has(p)).map(|p| format!("{s}.{p}_{a}")).collect();
            let quad = has("q");
            let f = move |x: &[f64]| {
                let (q, k3) = if quad { (x[0], x.get(1).copied().unwrap_or(0.0)) } else { (0.0, x[0]) };
                (q.abs() * fs + k3.abs() * fs * fs) * 1e6
            };
            Ok(Entry::new(a.to_string(), propagate::propagate(fit, &names, &f)?, src))
        })
        .collect()
}

/// End-point slope of the polynomial Σ c_k (T − 20)^k (terms `stems` of degree 1..) over
/// `range`, or its linear term without a range, scaled by `k`.
fn tempco(fit: &SensorFit, stems: [&str; 3], range: Option<[f64; 2]>, k: f64, src: &[String]) -> Found {
    let s = fit.sensor.as_str();
    let present: Vec<usize> = (0..3).filter(|&d| fit.get(&format!("{s}.{}_x", stems[d])).is_some()).collect();
    if present.is_empty() {
        return Ok(Vec::new());
    }
    AXES.iter()
        .map(|a| {
            let names: Vec<String> = present.iter().map(|&d| format!("{s}.{}_{a}", stems[d])).collect();
            let degrees = present.clone();
            let f = move |x: &[f64]| {
                let poly = |t: f64| {
                    let d = t - crate::model::T_REF_C;
                    degrees.iter().zip(x).map(|(&deg, c)| c * d.powi(deg as i32 + 1)).sum::<f64>()
                };
                match range {
                    Some([lo, hi]) if hi > lo => (poly(hi) - poly(lo)) / (hi - lo) * k,
                    _ => degrees.iter().zip(x).find(|(&deg, _)| deg == 0).map_or(0.0, |(_, c)| c * k),
                }
            };
            Ok(Entry::new(a.to_string(), propagate::propagate(fit, &names, &f)?, src))
        })
        .collect()
}

/// The run names of a profile, as a source line.
fn sources_of(path: &str, p: &Profile) -> Vec<String> {
    let runs: Vec<&str> = p.runs.iter().map(|r| r.name.as_str()).collect();
    vec![format!("{path} (runs {})", runs.join(", "))]
}

/// The coefficient-based quantities of one sensor.
fn coefficient_quantities(sheet: &mut Sheet, p: &Profile, sensor: SensorKind, src: &[String], opts: &DatasheetOptions) {
    let fit = p.sensor(sensor);
    let s = sensor.as_str();
    let bf = bias_factor(sensor, p.g_m_s2);
    let name = |q: &str| format!("{s}.{q}");
    sheet.push(&name("bias"), per_axis(fit, "b", bf, src));
    // Repeatability and noise come after, from the history and the noise reading.
    sheet.push(&name("scale_factor_error"), axes_quantity(fit, 0, src));
    let fs = match sensor {
        SensorKind::Gyro => opts.gyro_range_rad_s,
        SensorKind::Accel => Some(opts.accel_range_m_s2.unwrap_or(p.g_m_s2)),
    };
    sheet.push(&name("nonlinearity"), nonlinearity(fit, fs, src));
    let asym = if fit.get(&format!("{s}.sa_x")).is_some() { per_axis(fit, "sa", 1e6, src) } else { Ok(Vec::new()) };
    sheet.push(&name("asymmetry"), asym);
    sheet.push(&name("misalignment"), axes_quantity(fit, 1, src));
    sheet.push(&name("frame_alignment"), axes_quantity(fit, 2, src));
    if sensor == SensorKind::Gyro {
        let g = p.g_m_s2;
        sheet.push("gyro.g_sensitivity", elements(fit, "g", DEG_H_PER_RAD_S * g, src));
        sheet.push("gyro.g2_sensitivity", elements(fit, "n", DEG_H_PER_RAD_S * g * g, src));
        sheet.push("gyro.angular_accel_sensitivity", elements(fit, "e", 1.0, src));
    }
    let range = p.temperature_range_c();
    sheet.push(&name("bias_tempco"), tempco(fit, ["tb", "tb2", "tb3"], range, bf, src));
    sheet.push(&name("scale_tempco"), tempco(fit, ["ts", "ts2", "ts3"], range, 1e6, src));
    let hyst =
        if fit.get(&format!("{s}.thy_x")).is_some() { per_axis(fit, "thy", 2.0 * bf, src) } else { Ok(Vec::new()) };
    sheet.push(&name("thermal_hysteresis"), hyst);
}

/// The datasheet of the unit whose profile in force is `current` (at `path`), with its
/// stored calibrations `history` (oldest first, the current one among them or not).
pub fn build(path: &str, current: &Profile, history: &[(PathBuf, Profile)], opts: &DatasheetOptions) -> Datasheet {
    let mut sheet = Sheet { out: Vec::new(), missing: Vec::new() };
    let src = sources_of(path, current);
    let calibrations = history::distinct(history, current);
    for sensor in SensorKind::BOTH {
        coefficient_quantities(&mut sheet, current, sensor, &src, opts);
        let s = sensor.as_str();
        sheet.push(&format!("{s}.bias_repeatability"), history::repeatability(&calibrations, sensor));
        let (bi, white) = history::noise(history, current, path, sensor);
        sheet.push(&format!("{s}.bias_instability"), bi);
        sheet.push(if sensor == SensorKind::Gyro { "gyro.arw" } else { "accel.vrw" }, white);
        sheet.push(&format!("{s}.bias_trend"), history::trend(&calibrations, sensor, history::Trend::Bias));
        sheet.push(&format!("{s}.scale_factor_trend"), history::trend(&calibrations, sensor, history::Trend::Scale));
    }
    let mut quantities = sheet.out;
    quantities.extend(sheet.missing);
    Datasheet {
        unit: current.serial.clone(),
        profile: path.to_string(),
        created_utc: current.created_utc.clone(),
        calibrations: calibrations.len(),
        quantities,
    }
}
