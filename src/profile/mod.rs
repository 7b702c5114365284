//! Calibration profiles: one versioned JSON file per unit and calibration, stored as
//! `calib-profiles/<serial>/<UTC timestamp>.json`, written atomically and never overwritten.
//!
//! A profile carries everything needed to correct the unit and to judge the calibration:
//! the model (effects and which coefficients were fitted), every coefficient with its
//! standard error, the covariance of the fitted ones, residual statistics, the runs used
//! (file name and SHA-256) and the conventions of the numbers.
//!
//! Exports to other tools, each a function returning the file's text and what the target
//! cannot hold: [`interop`] (imucal, Kalibr), [`estimators`] (VINS-Fusion, ORB-SLAM3),
//! [`openvins`] (OpenVINS's `kalibr_imu_chain.yaml`), [`autopilot`] (ArduPilot and PX4
//! parameter files); the C header that repeats the correction is
//! [`crate::correct::to_c_header`].

pub mod autopilot;
pub mod estimators;
pub mod interop;
pub mod openvins;
mod store;
mod validate;

use crate::estimate::{CoefStatus, Fit, SensorFit};
use crate::model::{Model, ModelError};
use crate::session::{RunUsed, Session};
use crate::units::SensorKind;
use crate::units::Units;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};
pub use store::{history, latest, parse_time, save, serials, StoredProfile};

/// The profile format this version writes and reads.
pub const PROFILE_FORMAT: &str = "crosscal-profile/1";

/// Conventions of the numbers in a profile (written out so that a reader needs no docs).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Conventions {
    /// Frame of inputs and outputs.
    pub frame: String,
    /// Direction of the model.
    pub forward_model: String,
    /// Matrix layout.
    pub matrices: String,
    /// Units of the coefficients.
    pub coefficient_units: String,
}

impl Default for Conventions {
    fn default() -> Self {
        Self {
            frame: "sensor axes (the unit's own x, y, z), after the mount is applied".into(),
            forward_model: "u = f(true): gyro u = b + C_w w + C_e e [+ effects], accel u = b + K a [+ effects]; correction inverts it".into(),
            matrices: "row-major: coefficient c_ij (k_ij, e_ij) multiplies true input j in output i".into(),
            coefficient_units: "SI: rad/s, rad/s^2, m/s^2, s; scale and coupling dimensionless (recorded unit per SI unit for raw sessions)".into(),
        }
    }
}

/// Validation of a profile on runs the fit never saw.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Validation {
    /// The held-out runs.
    pub runs: Vec<RunUsed>,
    /// Errors before/after and reduction factors on those runs, per sensor axis.
    pub summary: Vec<AxisSummary>,
    /// Whether the held-out check passed.
    pub pass: bool,
}

/// Summary of one sensor axis over the runs of a check (written by `check`, stored in a
/// profile's [`Validation`]).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct AxisSummary {
    /// Sensor.
    pub sensor: SensorKind,
    /// Axis letter.
    pub axis: char,
    /// Largest before-correction error over runs, % of amplitude.
    pub before_pct: Option<f64>,
    /// Largest after-correction error over runs, % of amplitude.
    pub after_pct: Option<f64>,
    /// before / after (raw).
    pub reduction: Option<f64>,
    /// Largest systematic error before, % of amplitude.
    pub before_sys_pct: Option<f64>,
    /// Largest systematic error after, % of amplitude.
    pub after_sys_pct: Option<f64>,
    /// before / after (systematic): the pass criterion.
    pub reduction_sys: Option<f64>,
    /// The corrected error has no systematic part distinguishable from its noise (pooled χ²
    /// over runs): the check cannot resolve any remaining error, so the axis passes.
    pub noise_limited: bool,
    /// Reduction needed.
    pub threshold: f64,
    /// Whether this axis passes.
    pub pass: bool,
}

/// Settings the correction needs besides coefficients.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct CorrectionSettings {
    /// Half-window of the offline (centred) ε derivative, samples.
    pub derivative_half_window: usize,
    /// Polynomial degree of the offline ε derivative.
    pub derivative_degree: usize,
    /// Window length of the streaming (causal) ε derivative, samples.
    pub streaming_window: usize,
    /// Polynomial degree of the streaming ε derivative.
    pub streaming_degree: usize,
}

impl Default for CorrectionSettings {
    fn default() -> Self {
        Self { derivative_half_window: 5, derivative_degree: 3, streaming_window: 11, streaming_degree: 2 }
    }
}

/// A calibration profile (`crosscal-profile/1`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Profile {
    /// Always [`PROFILE_FORMAT`].
    pub format: String,
    /// Unit serial number.
    pub serial: String,
    /// Creation time, RFC 3339 UTC.
    pub created_utc: String,
    /// Tool name and version that wrote it.
    pub tool: String,
    /// Units of the recordings the profile was fitted on (and that `correct` expects).
    pub input_units: Units,
    /// Local gravity used to convert `g`, m/s².
    pub g_m_s2: f64,
    /// How to read the numbers.
    pub conventions: Conventions,
    /// Model name.
    pub model: String,
    /// Effect ids in the model, in order.
    pub effects: Vec<String>,
    /// Gyro coefficients, covariance and residuals.
    pub gyro: SensorFit,
    /// Accelerometer coefficients, covariance and residuals.
    pub accel: SensorFit,
    /// Parameters of nonlinear effects (time delay, dead zone).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub nonlinear: Vec<crate::estimate::NonlinearParam>,
    /// Definitions of the user effects in `effects` (from an effects file): the profile
    /// corrects without the file.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub user_effects: Vec<crate::model::user::UserEffectDef>,
    /// Estimated stand settings per conic run (`fit --stand`).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub stand: Vec<crate::estimate::StandParams>,
    /// The stand's common imperfections (tilt, speed ripple, wobble) from `fit --stand`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub stand_base: Option<crate::estimate::StandBase>,
    /// Runs used to fit.
    pub runs: Vec<RunUsed>,
    /// Check on runs left out of the fit (`fit --holdout`), if any.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub validation: Option<Validation>,
    /// Correction settings.
    pub correction: CorrectionSettings,
    /// Findings recorded at fit time (unidentifiable terms, gaps, ε source).
    #[serde(default)]
    pub notes: Vec<String>,
    /// Noise characterisation (Allan deviation) of a static recording of the unit.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub noise: Option<crate::noise::NoiseReport>,
    /// Residuals and settings of a protocol fit (Ferraris or multi-position sessions).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub protocol: Option<crate::estimate::protocol::ProtocolReport>,
}

/// What to say about a format this version does not read: another kind of crosscal file
/// is named as such; a newer profile version asks for a newer crosscal.
fn upgrade_hint(found: &str) -> String {
    if found.starts_with("crosscal-session/") {
        ": this is a session manifest, not a profile (a profile comes from `crosscal fit`)".into()
    } else if found.starts_with("crosscal-rules/") {
        ": this is a rules file, not a profile".into()
    } else if found.starts_with("crosscal-profile/") {
        "; upgrade crosscal to read newer profiles".into()
    } else {
        ": not a crosscal profile".into()
    }
}

/// Profile errors.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum ProfileError {
    /// File system error (the operating system's reason follows as the cause).
    #[error("{path}")]
    Io {
        /// File.
        path: PathBuf,
        /// Cause.
        source: std::io::Error,
    },
    /// The file is not JSON (or repeats a key).
    #[error("{path}:{line}:{column}: not valid JSON: {msg}")]
    Json {
        /// File.
        path: PathBuf,
        /// Line.
        line: usize,
        /// Column.
        column: usize,
        /// Cause.
        msg: String,
    },
    /// JSON, but not a profile: a field missing or of the wrong type.
    #[error("{path}:{line}:{column}: not a valid crosscal profile: {msg}")]
    Parse {
        /// File.
        path: PathBuf,
        /// Line.
        line: usize,
        /// Column.
        column: usize,
        /// Cause.
        msg: String,
    },
    /// A format this version does not know.
    #[error(
        "{path}: profile format '{found}' is not supported: this crosscal reads '{PROFILE_FORMAT}'{}",
        upgrade_hint(found)
    )]
    UnknownFormat {
        /// File.
        path: PathBuf,
        /// Format found.
        found: String,
    },
    /// A profile whose numbers cannot be used: a coefficient missing, repeated or not finite,
    /// an unusable g, a scale matrix too close to singular to invert.
    #[error("{path}: {msg}")]
    Invalid {
        /// File.
        path: PathBuf,
        /// What is wrong and what was expected.
        msg: String,
    },
    /// A profile in a unit's folder of the store that belongs to another unit.
    #[error("{path}: the profile is of unit '{profile_serial}' but sits in the folder of unit '{folder}': moved or copied by hand?")]
    WrongFolder {
        /// File.
        path: PathBuf,
        /// Serial in the profile.
        profile_serial: String,
        /// The folder's unit.
        folder: String,
    },
    /// The profile names an effect this version does not know.
    #[error("{path}: cannot rebuild the profile's model")]
    Model {
        /// File.
        path: PathBuf,
        /// Cause.
        #[source]
        source: ModelError,
    },
    /// A time that is neither RFC 3339 nor a date.
    #[error("'{0}' is not a time: expected RFC 3339 (2026-11-23T12:00:00Z) or a date (2026-11-23)")]
    BadTime(String),
    /// Serial cannot be used as a folder name.
    #[error("serial '{0}' cannot name a profile folder: use letters, digits, '-', '_' or '.' (not starting with '.')")]
    BadSerial(String),
    /// The profile belongs to another unit.
    #[error("{path}: the profile is for unit '{profile_serial}' but the data are of unit '{data_serial}'; use that unit's profile")]
    WrongUnit {
        /// Profile file.
        path: PathBuf,
        /// Serial in the profile.
        profile_serial: String,
        /// Serial of the data.
        data_serial: String,
    },
}

impl Profile {
    /// Builds a profile from a fit of a session.
    pub fn from_fit(session: &Session, model: &Model, fit: Fit, notes: Vec<String>) -> Self {
        Self::from_fit_of(&session.manifest, session.runs_used(), model, fit, notes)
    }

    /// Builds a profile from a fit of the runs of a manifest (for fits streamed from the
    /// files, which never hold a [`Session`]).
    pub fn from_fit_of(
        manifest: &crate::session::Manifest,
        runs: Vec<RunUsed>,
        model: &Model,
        fit: Fit,
        notes: Vec<String>,
    ) -> Self {
        Self {
            format: PROFILE_FORMAT.into(),
            serial: manifest.serial.clone(),
            created_utc: now_utc(),
            tool: format!("crosscal {}", env!("CARGO_PKG_VERSION")),
            input_units: manifest.units,
            g_m_s2: manifest.g_m_s2,
            conventions: Conventions::default(),
            model: model.name.clone(),
            effects: model.effect_ids().into_iter().map(String::from).collect(),
            gyro: fit.gyro,
            accel: fit.accel,
            nonlinear: fit.nonlinear,
            user_effects: model.user_definitions(),
            stand: fit.stand,
            stand_base: fit.stand_base,
            runs,
            correction: CorrectionSettings::default(),
            validation: None,
            notes,
            noise: None,
            protocol: None,
        }
    }

    /// A profile holding only a noise characterisation (no coefficients: the identity
    /// calibration), so that the estimator and autopilot exports can write the noise
    /// parameters of a unit measured at rest (`crosscal noise --save … --to …`).
    pub fn noise_only(serial: &str, g_m_s2: f64, noise: crate::noise::NoiseReport) -> Self {
        let empty = |sensor| SensorFit {
            sensor,
            coefficients: Vec::new(),
            channels: Vec::new(),
            unidentifiable: Vec::new(),
            correlated: Vec::new(),
        };
        Self {
            format: PROFILE_FORMAT.into(),
            serial: serial.to_string(),
            created_utc: now_utc(),
            tool: format!("crosscal {}", env!("CARGO_PKG_VERSION")),
            input_units: Units::default(),
            g_m_s2,
            conventions: Conventions::default(),
            model: "noise only".into(),
            effects: Vec::new(),
            gyro: empty(SensorKind::Gyro),
            accel: empty(SensorKind::Accel),
            nonlinear: Vec::new(),
            user_effects: Vec::new(),
            stand: Vec::new(),
            stand_base: None,
            runs: Vec::new(),
            correction: CorrectionSettings::default(),
            validation: None,
            notes: vec![format!("noise only, from {}", noise.source)],
            noise: Some(noise),
            protocol: None,
        }
    }

    /// The temperature range the profile was calibrated over, °C: the union of its runs'
    /// ranges (None when no run had a temperature).
    pub fn temperature_range_c(&self) -> Option<[f64; 2]> {
        crate::session::temp_range(self.runs.iter().filter_map(|r| r.temp_range_c).flatten())
    }

    /// The range of the temperature's rate of change in the calibration data, °C/s: the
    /// union of its runs' (None when no run recorded one).
    pub fn temperature_rate_range_c_s(&self) -> Option<[f64; 2]> {
        crate::session::temp_range(self.runs.iter().filter_map(|r| r.temp_rate_range_c_s).flatten())
    }

    /// Whether the profile's model has temperature terms (its correction reads temperatures).
    pub fn uses_temperature(&self) -> bool {
        self.effects.iter().any(|e| e.contains("temp"))
    }

    /// The fit of one sensor.
    pub fn sensor(&self, s: SensorKind) -> &SensorFit {
        match s {
            SensorKind::Gyro => &self.gyro,
            SensorKind::Accel => &self.accel,
        }
    }

    /// Rebuilds the model with every coefficient held at its stored value (for correction).
    pub fn model(&self) -> Result<Model, ModelError> {
        self.rebuild(true)
    }

    /// Rebuilds the model as it was fitted: the same effects, free coefficients (those the
    /// fit held stay held), nonlinear parameters free (for re-fitting and `diagnose`).
    pub fn fitted_model(&self) -> Result<Model, ModelError> {
        self.rebuild(false)
    }

    fn rebuild(&self, fix_all: bool) -> Result<Model, ModelError> {
        let mut m = Model::named_with_users(&self.model, &self.effects, &self.user_effects)?;
        for c in self.gyro.coefficients.iter().chain(&self.accel.coefficients) {
            if fix_all || c.status == crate::estimate::CoefStatus::Fixed {
                m.fix(&c.name, c.value)?;
            }
        }
        if fix_all {
            let ids: Vec<&'static str> = m.nonlinear().iter().map(|e| e.effect.id()).collect();
            for id in ids {
                let values = self.nonlinear.iter().filter(|p| p.effect == id).map(|p| p.value).collect();
                m.fix_nonlinear(id, values)?;
            }
        }
        Ok(m)
    }

    /// Refuses a profile that belongs to another unit.
    pub fn ensure_unit(&self, path: &Path, serial: &str) -> Result<(), ProfileError> {
        if self.serial == serial {
            Ok(())
        } else {
            Err(ProfileError::WrongUnit {
                path: path.to_path_buf(),
                profile_serial: self.serial.clone(),
                data_serial: serial.to_string(),
            })
        }
    }

    /// Names of coefficients the fit could not identify.
    pub fn unidentifiable(&self) -> Vec<&str> {
        self.gyro
            .coefficients
            .iter()
            .chain(&self.accel.coefficients)
            .filter(|c| c.status == CoefStatus::Unidentifiable)
            .map(|c| c.name.as_str())
            .collect()
    }

    /// Serialises to pretty JSON.
    pub fn to_json(&self) -> String {
        serde_json::to_string_pretty(self).unwrap_or_default() + "\n"
    }

    /// Parses a profile, refusing unknown formats with a clear message.
    pub fn from_json(path: &Path, text: &str) -> Result<Self, ProfileError> {
        let text = text.strip_prefix('\u{feff}').unwrap_or(text);
        let at = |e: &serde_json::Error| (path.to_path_buf(), e.line(), e.column(), e.to_string());
        let v = crate::json::parse_unique(text).map_err(|e| {
            let (path, line, column, msg) = at(&e);
            ProfileError::Json { path, line, column, msg }
        })?;
        match v.get("format").and_then(|f| f.as_str()) {
            Some(PROFILE_FORMAT) => {}
            Some(other) => {
                return Err(ProfileError::UnknownFormat { path: path.to_path_buf(), found: other.to_string() })
            }
            None => {
                return Err(ProfileError::Parse {
                    path: path.to_path_buf(),
                    line: 1,
                    column: 1,
                    msg: format!("no \"format\" field: expected \"format\": \"{PROFILE_FORMAT}\""),
                })
            }
        }
        let p: Profile = serde_json::from_str(text).map_err(|e| {
            let (path, line, column, msg) = at(&e);
            ProfileError::Parse { path, line, column, msg }
        })?;
        let model = p.model().map_err(|source| ProfileError::Model { path: path.to_path_buf(), source })?;
        validate::validate(&p, &model).map_err(|msg| ProfileError::Invalid { path: path.to_path_buf(), msg })?;
        Ok(p)
    }

    /// Reads a profile file.
    pub fn read(path: &Path) -> Result<Self, ProfileError> {
        let text =
            crate::atomic::read_text(path).map_err(|source| ProfileError::Io { path: path.to_path_buf(), source })?;
        Self::from_json(path, &text)
    }

    /// Reads a profile given as a file, or as a unit's folder of the store
    /// (`calib-profiles/<serial>`): then the newest profile in force now, whose path is
    /// returned beside it so the caller can say which revision it used.
    pub fn read_or_latest(path: &Path) -> Result<(PathBuf, Self), ProfileError> {
        if !path.is_dir() {
            return Self::read(path).map(|p| (path.to_path_buf(), p));
        }
        let serial = path.file_name().and_then(|s| s.to_str()).unwrap_or_default();
        let root = path.parent().unwrap_or(Path::new("."));
        store::latest(root, serial, None)
    }

    /// The same profile as a new revision created now (for `save`, which never overwrites).
    pub fn revised(&self, note: impl Into<String>) -> Self {
        let mut p = self.clone();
        p.created_utc = now_utc();
        p.tool = format!("crosscal {}", env!("CARGO_PKG_VERSION"));
        p.notes.push(note.into());
        p
    }

    /// File name for this profile: the creation time with `:` replaced by `-`.
    pub fn file_stem(&self) -> String {
        self.created_utc.replace(':', "-")
    }
}

/// The current UTC time, RFC 3339 to the millisecond.
pub(crate) fn now_utc() -> String {
    // Always three decimals, so the store's file names sort in time order as text too.
    let now = jiff::Timestamp::now();
    now.round(jiff::Unit::Millisecond).unwrap_or(now).strftime("%Y-%m-%dT%H:%M:%S%.3fZ").to_string()
}

/// How one coefficient changed between two profiles of a unit.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CoefChange {
    /// Coefficient name.
    pub name: String,
    /// SI unit.
    pub unit: String,
    /// Value in the older profile.
    pub before: f64,
    /// Value in the newer profile.
    pub after: f64,
    /// (after − before) / √(se_before² + se_after²), when both have standard errors.
    pub z: Option<f64>,
}

/// Coefficient changes from `a` to `b` (coefficients present in both), in units of their
/// combined standard error: |z| > 3 means the unit has drifted beyond what the two
/// calibrations' noise explains.
pub fn diff(a: &Profile, b: &Profile) -> Vec<CoefChange> {
    let before: Vec<&crate::estimate::Coefficient> = a.gyro.coefficients.iter().chain(&a.accel.coefficients).collect();
    b.gyro
        .coefficients
        .iter()
        .chain(&b.accel.coefficients)
        .filter_map(|cb| {
            let ca = before.iter().find(|c| c.name == cb.name)?;
            let z = match (ca.std_error, cb.std_error) {
                (Some(x), Some(y)) if x > 0.0 || y > 0.0 => Some((cb.value - ca.value) / (x * x + y * y).sqrt()),
                _ => None,
            };
            Some(CoefChange { name: cb.name.clone(), unit: cb.unit.clone(), before: ca.value, after: cb.value, z })
        })
        .collect()
}

impl Profile {
    /// Age of the profile at `now`, days (None if its time stamp does not parse).
    pub fn age_days(&self, now: jiff::Timestamp) -> Option<f64> {
        let t = self.created_utc.parse::<jiff::Timestamp>().ok()?;
        Some((now.as_millisecond() - t.as_millisecond()) as f64 / 86_400_000.0)
    }
}
