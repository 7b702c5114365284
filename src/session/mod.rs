//! Stand sessions: the manifest (JSON) and its recordings (CSV), as specified in
//! `shared/spec/session-format.md` (format `crosscal-session/1`).
//!
//! Everything is converted on read to SI (rad/s, m/s², s). Sensor outputs stay in the
//! sensor frame; the motion described by the manifest is in the stand frame and is moved to
//! the sensor frame with the run's mount by [`crate::motion`].

pub mod column;
mod csvread;
mod csvwrite;
mod error;
pub mod import;
pub mod import_text;
pub mod logs;
pub mod memory;
mod motions;
mod open;
mod recording;
pub mod sanity;
mod shape;
mod source;

use crate::units::{AccelUnit, GyroUnit, TimeUnit, Units};
pub use column::{Column, ColumnBuilder};
pub use csvread::{
    parse_recording, read_recording, sha256_hex, ReadOptions, Recording, ReferenceColumns, Row, RowReader,
};
pub use csvwrite::{recording_csv, recording_csv_with, recording_header, CsvLine};
pub use error::{Problem, SessionError};
pub use open::{file_kind, open_recording, open_regular};
pub use source::Source;

use crate::frames::Mount;
use serde::{Deserialize, Serialize};
use serde_json::Value;
use std::path::{Path, PathBuf};

/// The stand-session format (conic, static with known up, reference runs).
pub const SESSION_FORMAT: &str = "crosscal-session/1";

/// Version 2 adds, compatibly, what hand-held and multi-position protocols need: `rows`
/// (several runs sharing one CSV), `static` runs with `"up_stand": "unknown"`, `rotation`
/// runs (known total angle about a known axis) and `multi_position` runs (static poses
/// detected automatically). Every version-1 manifest is a valid version-2 manifest.
pub const SESSION_FORMAT_2: &str = "crosscal-session/2";

/// What the stand did during a run, as declared in the manifest (stand frame).
#[derive(Debug, Clone, PartialEq)]
#[non_exhaustive]
pub enum MotionSpec {
    /// Conic motion, paper eqs. 1–2.
    Conic {
        /// Cone half-angle α, degrees.
        cone_angle_deg: f64,
        /// Stand rate ω_s, deg/s; the sign gives the direction.
        rate_deg_s: f64,
        /// Phase φ at t = 0, degrees.
        phase_deg: f64,
    },
    /// At rest.
    Static {
        /// Unit vector pointing up, stand axes (what an ideal accelerometer reads, in g).
        up_stand: [f64; 3],
        /// Earth rate in stand axes, rad/s (zero unless `earth_rate` was requested).
        earth_rate_rad_s: [f64; 3],
    },
    /// True ω, a (and optionally ε) are given per sample in the CSV.
    Reference,
    /// At rest in an unknown orientation (version 2, `"up_stand": "unknown"`): only |a| = g
    /// and ω = 0 are known (Tedaldi multi-position protocol).
    StaticUnknown,
    /// A turn from rest to rest through a known total angle about a known axis (version 2;
    /// Ferraris turns). Only the integral of ω over the run is known.
    Rotation {
        /// Unit rotation axis, stand axes.
        axis_stand: [f64; 3],
        /// Total angle, degrees, right-handed about the axis.
        angle_deg: f64,
    },
    /// Hand-held multi-position recording (version 2): rest at the start, then static poses
    /// joined by free motion; the poses are detected from the accelerometer's moving variance.
    MultiPosition {
        /// Length of the initial rest, s (the gyro bias and the detector's noise level).
        init_rest_s: f64,
        /// Detector window, samples (odd).
        window: usize,
        /// Threshold multiplier on the initial rest's variance; `None` tries 2..=10 and keeps
        /// the one whose accelerometer fit leaves the smallest cost.
        threshold_multiplier: Option<f64>,
        /// Shortest pose used, samples.
        min_pose_samples: usize,
        /// Poses given as sample ranges `[start, end)` within the run (detection skipped);
        /// every pose is used whatever its length.
        poses: Option<Vec<(usize, usize)>>,
    },
}

impl MotionSpec {
    /// True for the kinds whose true state is not known sample by sample (protocol runs).
    pub fn is_protocol(&self) -> bool {
        matches!(self, Self::StaticUnknown | Self::Rotation { .. } | Self::MultiPosition { .. })
    }

    /// The manifest's `"motion"` object for this motion.
    pub fn to_json(&self) -> Value {
        match self {
            Self::Conic { cone_angle_deg, rate_deg_s, phase_deg } => serde_json::json!({
                "kind": "conic", "cone_angle_deg": cone_angle_deg, "rate_deg_s": rate_deg_s, "phase_deg": phase_deg
            }),
            Self::Static { up_stand, .. } => serde_json::json!({"kind": "static", "up_stand": up_stand}),
            Self::Reference => serde_json::json!({"kind": "reference"}),
            Self::StaticUnknown => serde_json::json!({"kind": "static", "up_stand": "unknown"}),
            Self::Rotation { axis_stand, angle_deg } => {
                serde_json::json!({"kind": "rotation", "axis_stand": axis_stand, "angle_deg": angle_deg})
            }
            Self::MultiPosition { init_rest_s, window, threshold_multiplier, min_pose_samples, poses } => {
                let mut v = serde_json::json!({
                    "kind": "multi_position", "init_rest_s": init_rest_s, "window": window,
                    "min_pose_samples": min_pose_samples
                });
                if let Some(o) = v.as_object_mut() {
                    if let Some(t) = threshold_multiplier {
                        o.insert("threshold_multiplier".into(), serde_json::json!(t));
                    }
                    if let Some(p) = poses {
                        let list: Vec<[usize; 2]> = p.iter().map(|&(a, b)| [a, b]).collect();
                        o.insert("poses".into(), serde_json::json!(list));
                    }
                }
                v
            }
        }
    }
}

impl RunSpec {
    /// A run of `file` (rows `[start, end)` of it, or all) on the identity mount, without
    /// temperature or note.
    pub fn new(
        name: impl Into<String>,
        file: impl Into<String>,
        motion: MotionSpec,
        rows: Option<(usize, usize)>,
    ) -> Self {
        Self {
            name: name.into(),
            file: file.into(),
            motion,
            mount: Mount::identity(),
            temperature_c: None,
            note: None,
            rows,
            start_s: None,
            duration_s: None,
            angle_column: None,
        }
    }

    /// The manifest's entry for this run.
    pub fn to_json(&self) -> Value {
        let mut v = serde_json::json!({
            "name": self.name, "file": self.file, "motion": self.motion.to_json(), "mount": self.mount.names()
        });
        if let Some(o) = v.as_object_mut() {
            if let Some((a, b)) = self.rows {
                o.insert("rows".into(), serde_json::json!([a, b]));
            }
            if let Some(t) = self.temperature_c {
                o.insert("temperature_c".into(), serde_json::json!(t));
            }
            if let Some(n) = &self.note {
                o.insert("note".into(), serde_json::json!(n));
            }
            if let Some(s) = self.start_s {
                o.insert("start_s".into(), serde_json::json!(s));
            }
            if let Some(d) = self.duration_s {
                o.insert("duration_s".into(), serde_json::json!(d));
            }
            if let Some(c) = &self.angle_column {
                o.insert("angle_column".into(), serde_json::json!(c));
            }
        }
        v
    }
}

impl Manifest {
    /// The manifest as JSON text (version 2 when a run needs it, else version 1).
    pub fn to_json(&self) -> String {
        let v2 = self.runs.iter().any(|r| r.rows.is_some() || r.motion.is_protocol());
        let runs: Vec<Value> = self.runs.iter().map(RunSpec::to_json).collect();
        let mut manifest = serde_json::json!({
            "format": if v2 { SESSION_FORMAT_2 } else { SESSION_FORMAT },
            "serial": self.serial,
            "units": {"gyro": self.units.gyro.to_string(), "accel": self.units.accel.to_string(), "time": self.units.time.to_string()},
            "stand": {"g": self.g_m_s2},
            "runs": runs,
        });
        if let (Some(src), Some(o)) = (&self.source, manifest.as_object_mut()) {
            o.insert("source".into(), src.to_json());
        }
        serde_json::to_string_pretty(&manifest).unwrap_or_default() + "\n"
    }
}

/// Provenance of a run that went into a fit or a validation: which file, its hash, how many
/// samples (what a profile records of the data it came from).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RunUsed {
    /// Run name.
    pub name: String,
    /// CSV file as named in the manifest.
    pub file: String,
    /// SHA-256 of the CSV's bytes.
    pub sha256: String,
    /// Number of samples.
    pub samples: usize,
    /// Lowest and highest temperature of the samples, °C (a `temp` column or the run's
    /// `temperature_c`), when the run has one: the range a profile is calibrated over.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub temp_range_c: Option<[f64; 2]>,
    /// Lowest and highest rate of change of the temperature, °C/s, smoothed over
    /// [`crate::stats::temp_rate::WINDOW_S`] (centred; 0 at a run's constant
    /// `temperature_c`): how fast the calibration data warmed and cooled. None when not
    /// known (no temperature, or a streamed fit, which sees each sample once).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub temp_rate_range_c_s: Option<[f64; 2]>,
}

/// The lowest and highest finite value of `temps` (None when there is none).
pub fn temp_range(temps: impl IntoIterator<Item = f64>) -> Option<[f64; 2]> {
    temps.into_iter().fold(None, crate::stats::widen)
}

/// One run as declared in the manifest.
#[derive(Debug, Clone, PartialEq)]
pub struct RunSpec {
    /// Run name.
    pub name: String,
    /// CSV file, relative to the manifest's folder.
    pub file: String,
    /// The stand's motion.
    pub motion: MotionSpec,
    /// How the sensor sits on the stand.
    pub mount: Mount,
    /// Constant temperature, °C, when the CSV has no `temp` column.
    pub temperature_c: Option<f64>,
    /// Free text.
    pub note: Option<String>,
    /// Sample range `[start, end)` (0-based data rows) of the CSV this run uses (version 2);
    /// `None` uses the whole file.
    pub rows: Option<(usize, usize)>,
    /// The run's start on the session clock, s (optional `start_s`, any format version):
    /// for sessions whose runs each restart their time stamps; without it the session clock
    /// is `t` as recorded.
    pub start_s: Option<f64>,
    /// Planned duration, s (optional `duration_s`): for `plan --design` on runs not yet
    /// recorded; ignored by every other command (a recorded run's duration is its CSV's).
    pub duration_s: Option<f64>,
    /// A conic run's column holding the stand's measured angle θ in degrees (optional
    /// `angle_column`, e.g. `"theta_deg"`): the kinematics then follow the logged angle
    /// (rate and angular acceleration from its smoothed derivatives) instead of uniform
    /// turning at the declared rate and phase.
    pub angle_column: Option<String>,
}

/// A parsed manifest.
#[derive(Debug, Clone, PartialEq)]
pub struct Manifest {
    /// Unit serial number.
    pub serial: String,
    /// Units of the recordings.
    pub units: Units,
    /// Local gravity, m/s².
    pub g_m_s2: f64,
    /// Runs, in manifest order.
    pub runs: Vec<RunSpec>,
    /// Format version (1 or 2).
    pub version: u8,
    /// Where the recording came from when it was imported from a log or bag (optional
    /// `"source"` object): format, stream, axis convention, the calibration the autopilot
    /// had already applied.
    pub source: Option<Source>,
}

/// One run: its declaration and its samples.
#[derive(Debug, Clone, PartialEq)]
pub struct Run {
    /// The manifest's entry.
    pub spec: RunSpec,
    /// Full path of the CSV.
    pub path: PathBuf,
    /// The samples.
    pub rec: Recording,
}

/// A whole session in memory.
#[derive(Debug, Clone, PartialEq)]
pub struct Session {
    /// Path of the manifest.
    pub manifest_path: PathBuf,
    /// The manifest.
    pub manifest: Manifest,
    /// The runs with their data.
    pub runs: Vec<Run>,
}

impl Session {
    /// Reads a manifest and all its recordings (gaps in `t` are warnings).
    pub fn load(manifest_path: &Path) -> Result<Self, SessionError> {
        Self::load_with(manifest_path, false)
    }

    /// Reads a manifest and all its recordings; with `strict`, gaps in `t` are errors.
    pub fn load_with(manifest_path: &Path, strict: bool) -> Result<Self, SessionError> {
        use rayon::prelude::*;
        let manifest_path = &manifest_in(manifest_path);
        let manifest = read_manifest(manifest_path)?;
        let options = |spec: &RunSpec| ReadOptions {
            reference: matches!(spec.motion, MotionSpec::Reference),
            strict,
            angle_column: spec.angle_column.clone(),
        };
        // Runs with a file of their own are read in parallel; results (and errors) are taken
        // in manifest order below.
        let mut own: Vec<Option<Result<Recording, SessionError>>> = manifest
            .runs
            .par_iter()
            .map(|spec| {
                let path = run_path(manifest_path, spec).ok()?;
                spec.rows.is_none().then(|| read_recording(&path, &manifest.units, manifest.g_m_s2, options(spec)))
            })
            .collect();
        let mut runs = Vec::with_capacity(manifest.runs.len());
        let mut cache: Vec<(PathBuf, Recording)> = Vec::new();
        for (spec, own) in manifest.runs.iter().zip(own.iter_mut()) {
            let path = run_path(manifest_path, spec)?;
            let opts = options(spec);
            let rec = match (spec.rows, own.take()) {
                (None, Some(read)) => read?,
                (None, None) => read_recording(&path, &manifest.units, manifest.g_m_s2, opts)?,
                (Some((start, end)), _) => {
                    // Runs sharing a file read it once.
                    let i = match cache.iter().position(|(p, _)| *p == path) {
                        Some(i) => i,
                        None => {
                            let r = read_recording(&path, &manifest.units, manifest.g_m_s2, opts)?;
                            cache.push((path.clone(), r));
                            cache.len() - 1
                        }
                    };
                    let whole = &cache[i].1;
                    if end > whole.len() {
                        return Err(rows_past_end(manifest_path, spec, whole.len()));
                    }
                    whole.slice(start, end)
                }
            };
            runs.push(Run { spec: spec.clone(), path, rec });
        }
        // A session past the heap budget is mapped whole: the runs read first would
        // otherwise hold the whole budget on the heap for as long as the session lives,
        // beside the mapped pages of the rest (64 MB of the peak at 10⁷ samples).
        if runs.iter().any(|r| r.rec.t_s.is_mapped() || r.rec.gyro.is_mapped() || r.rec.accel.is_mapped()) {
            drop(cache);
            runs.par_iter_mut().for_each(|r| r.rec.spill());
        }
        Ok(Self { manifest_path: manifest_path.to_path_buf(), manifest, runs })
    }

    /// Total number of samples over all runs.
    pub fn n_samples(&self) -> usize {
        self.runs.iter().map(|r| r.rec.len()).sum()
    }

    /// True when some run is a protocol run (unknown pose, rotation, multi-position): such
    /// sessions are fitted by [`crate::estimate::protocol`], not sample by sample.
    pub fn is_protocol(&self) -> bool {
        self.runs.iter().any(|r| r.spec.motion.is_protocol())
    }

    /// The session restricted to the runs whose names `keep` accepts (samples copied).
    pub fn subset(&self, keep: impl Fn(&str) -> bool) -> Session {
        let runs: Vec<Run> = self.runs.iter().filter(|r| keep(&r.spec.name)).cloned().collect();
        let mut manifest = self.manifest.clone();
        manifest.runs = runs.iter().map(|r| r.spec.clone()).collect();
        Session { manifest_path: self.manifest_path.clone(), manifest, runs }
    }

    /// What a profile records of each run: name, file, SHA-256 and samples.
    pub fn runs_used(&self) -> Vec<RunUsed> {
        self.runs
            .iter()
            .map(|r| RunUsed {
                name: r.spec.name.clone(),
                file: r.spec.file.clone(),
                sha256: r.rec.sha256.clone(),
                samples: r.rec.len(),
                temp_range_c: match &r.rec.temp_c {
                    Some(t) => temp_range(t.iter().copied()),
                    None => r.spec.temperature_c.map(|t| [t, t]),
                },
                temp_rate_range_c_s: match &r.rec.temp_c {
                    Some(t) => temp_range(crate::stats::temp_rate::centred(&r.rec.t_s, t)),
                    None => r.spec.temperature_c.map(|_| [0.0, 0.0]),
                },
            })
            .collect()
    }

    /// Non-fatal findings of all recordings.
    pub fn warnings(&self) -> Vec<String> {
        let mut w: Vec<String> = self.runs.iter().flat_map(|r| r.rec.warnings.iter().cloned()).collect();
        w.extend(self.manifest.source.as_ref().and_then(Source::applied_warning));
        w
    }
}

/// The error of a run whose `rows` reach past the end of its file of `len` samples (names
/// the manifest's `rows` line).
pub fn rows_past_end(manifest_path: &Path, spec: &RunSpec, len: usize) -> SessionError {
    let (start, end) = spec.rows.unwrap_or((0, len));
    let (line, column) = locate(&crate::atomic::read_text(manifest_path).unwrap_or_default(), "rows");
    SessionError::Manifest {
        problem: Problem::Invalid,
        path: manifest_path.to_path_buf(),
        line,
        column,
        msg: format!("run '{}': rows [{start}, {end}) reach past the end of {} ({len} samples)", spec.name, spec.file),
    }
}

/// The CSV of a run (relative to the manifest's folder; `FILE.gz` when only that exists); an error naming the manifest's
/// line when it does not exist or is not a regular file (a folder, FIFO or device), and the
/// operating system's reason when it cannot be looked at (e.g. a symbolic-link loop).
pub fn run_path(manifest_path: &Path, spec: &RunSpec) -> Result<PathBuf, SessionError> {
    let manifest_path = &manifest_in(manifest_path);
    let dir = manifest_path.parent().unwrap_or(Path::new("."));
    let path = dir.join(&spec.file);
    let refuse = |what: String| {
        let (line, column) = locate(&crate::atomic::read_text(manifest_path).unwrap_or_default(), &spec.file);
        SessionError::Manifest {
            problem: Problem::MissingFile,
            path: manifest_path.to_path_buf(),
            line,
            column,
            msg: format!("run '{}': file '{}' {what} (looked for {})", spec.name, spec.file, path.display()),
        }
    };
    // A recording kept compressed beside its manifest (`static.csv.gz` for `static.csv`) is
    // read as it is.
    let gz = dir.join(format!("{}.gz", spec.file));
    if !path.exists() && gz.is_file() {
        return Ok(gz);
    }
    match std::fs::metadata(&path) {
        Ok(m) if m.is_file() => Ok(path),
        Ok(m) => Err(refuse(format!("is {}: expected the run's CSV recording", file_kind(&m)))),
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => Err(refuse("does not exist".into())),
        Err(source) => Err(SessionError::Io { path, source }),
    }
}

/// Best-effort 1-based (line, column) of the first occurrence of `"needle"` in `text`.
fn locate(text: &str, needle: &str) -> (usize, usize) {
    let quoted = format!("\"{needle}\"");
    let Some(pos) = text.find(&quoted).or_else(|| text.find(needle)) else {
        return (0, 0);
    };
    let before = &text[..pos];
    let line = before.matches('\n').count() + 1;
    let column = pos - before.rfind('\n').map_or(0, |p| p + 1) + 1;
    (line, column)
}

/// The physical and practical bounds a manifest's numbers must keep, so that a typo (or a
/// hostile file) is refused with the limit in the message instead of hanging a fit or
/// allocating without end.
#[derive(Debug, Clone, Copy)]
pub struct Limits {
    /// Local gravity, m/s².
    pub g_m_s2: (f64, f64),
    /// |stand rate| of a conic run, deg/s (100 revolutions per second).
    pub rate_deg_s: f64,
    /// |phase| of a conic run, degrees.
    pub phase_deg: f64,
    /// |total angle| of a rotation run, degrees (100 turns).
    pub angle_deg: f64,
    /// Run temperature, °C.
    pub temperature_c: (f64, f64),
    /// Runs in one manifest.
    pub runs: usize,
    /// Seconds of an initial rest.
    pub init_rest_s: f64,
    /// Samples of a detector window or a shortest pose.
    pub window: usize,
}

/// The bounds of every manifest.
pub const LIMITS: Limits = Limits {
    g_m_s2: (9.0, 10.5),
    rate_deg_s: 36_000.0,
    phase_deg: 1e6,
    angle_deg: 36_000.0,
    temperature_c: (-100.0, 300.0),
    runs: 100_000,
    init_rest_s: 86_400.0,
    window: 1_000_000,
};

/// A finite number within `[lo, hi]`, or a message naming the key, the value and the limit.
fn within(name: &str, key: &str, x: f64, lo: f64, hi: f64, unit: &str) -> Result<f64, String> {
    if x.is_finite() && (lo..=hi).contains(&x) {
        Ok(x)
    } else {
        Err(format!("run '{name}': {key} is {}: expected {lo} to {hi} {unit}", crate::units::show(x)))
    }
}

/// The manifest a path names: the path itself, or `session.json` in it when it is a folder
/// holding one (what `simulate --out` and `import --out` write).
pub fn manifest_in(path: &Path) -> PathBuf {
    let inside = path.join("session.json");
    if path.is_dir() && inside.is_file() {
        inside
    } else {
        path.to_path_buf()
    }
}

/// Reads and validates a manifest (without reading the recordings); a folder holding a
/// `session.json` reads that.
pub fn read_manifest(path: &Path) -> Result<Manifest, SessionError> {
    let path = &manifest_in(path);
    let text =
        crate::atomic::read_text(path).map_err(|source| SessionError::Io { path: path.to_path_buf(), source })?;
    parse_manifest(path, &text)
}

/// Parses manifest text (the path is used in messages only).
pub fn parse_manifest(path: &Path, text: &str) -> Result<Manifest, SessionError> {
    // A UTF-8 byte-order mark is accepted, as in recordings.
    let text = text.strip_prefix('\u{feff}').unwrap_or(text);
    let json: Value = crate::json::parse_unique(text).map_err(|e| SessionError::Json {
        path: path.to_path_buf(),
        line: e.line(),
        column: e.column(),
        msg: format!("the manifest is not valid JSON: {e}"),
    })?;
    let bad_kind = |problem: Problem, needle: &str, msg: String| {
        let (line, column) = locate(text, needle);
        SessionError::Manifest { problem, path: path.to_path_buf(), line, column, msg }
    };
    let bad = |needle: &str, msg: String| bad_kind(Problem::Invalid, needle, msg);
    let units_err = |needle: &str, msg: String| bad_kind(Problem::Units, needle, msg);
    let obj = json.as_object().ok_or_else(|| bad("", "the manifest must be a JSON object".into()))?;
    let version = match obj.get("format") {
        Some(Value::String(f)) if f == SESSION_FORMAT => 1,
        Some(Value::String(f)) if f == SESSION_FORMAT_2 => 2,
        Some(Value::String(f)) => {
            return Err(SessionError::UnknownFormat { path: path.to_path_buf(), found: f.clone() })
        }
        _ => return Err(bad("format", format!("missing \"format\": expected \"format\": \"{SESSION_FORMAT}\""))),
    };
    if let Some(u) = shape::unknown_key(&json) {
        return Err(bad(&u.key, u.message()));
    }
    let serial = match obj.get("serial") {
        Some(Value::String(s)) if valid_serial(s) => s.clone(),
        Some(Value::String(s)) => {
            return Err(bad(
                s,
                format!("serial '{s}' cannot name a profile folder: use letters, digits, '-', '_' or '.' (not starting with '.')"),
            ))
        }
        _ => return Err(bad("serial", "missing \"serial\": expected the unit's serial number as a string".into())),
    };
    let units_obj = obj.get("units").and_then(Value::as_object).ok_or_else(|| {
        bad("units", "missing \"units\": expected {\"gyro\": ..., \"accel\": ..., \"time\": ...}".into())
    })?;
    let unit_str = |key: &str| -> Result<Option<&str>, SessionError> {
        match units_obj.get(key) {
            None => Ok(None),
            Some(Value::String(s)) => Ok(Some(s.as_str())),
            Some(_) => Err(units_err(key, format!("units.{key} must be a string"))),
        }
    };
    let gyro = match unit_str("gyro")? {
        Some(s) => GyroUnit::parse(s)
            .ok_or_else(|| units_err(s, format!("units.gyro is '{s}': expected one of {}", GyroUnit::CHOICES)))?,
        None => return Err(units_err("units", format!("missing units.gyro: expected one of {}", GyroUnit::CHOICES))),
    };
    let accel = match unit_str("accel")? {
        Some(s) => AccelUnit::parse(s)
            .ok_or_else(|| units_err(s, format!("units.accel is '{s}': expected one of {}", AccelUnit::CHOICES)))?,
        None => return Err(units_err("units", format!("missing units.accel: expected one of {}", AccelUnit::CHOICES))),
    };
    let time = match unit_str("time")? {
        Some(s) => TimeUnit::parse(s)
            .ok_or_else(|| units_err(s, format!("units.time is '{s}': expected one of {}", TimeUnit::CHOICES)))?,
        None => TimeUnit::S,
    };
    let g_m_s2 = match obj.get("stand").and_then(|s| s.get("g")) {
        None => 9.80665,
        Some(v) => match v.as_f64() {
            Some(g) if (LIMITS.g_m_s2.0..=LIMITS.g_m_s2.1).contains(&g) => g,
            _ => {
                let (lo, hi) = LIMITS.g_m_s2;
                return Err(bad(
                    "\"g\"",
                    format!("stand.g is {v}: expected local gravity in m/s^2, between {lo} and {hi}"),
                ));
            }
        },
    };
    let runs_json = obj
        .get("runs")
        .and_then(Value::as_array)
        .ok_or_else(|| bad("runs", "missing \"runs\": expected a list of runs".into()))?;
    if runs_json.len() > LIMITS.runs {
        return Err(bad(
            "runs",
            format!("the manifest has {} runs: at most {} are read (split the session)", runs_json.len(), LIMITS.runs),
        ));
    }
    if runs_json.is_empty() {
        return Err(bad("runs", "\"runs\" is empty: a session needs at least one run".into()));
    }
    let mut runs = Vec::with_capacity(runs_json.len());
    for (i, r) in runs_json.iter().enumerate() {
        let run = parse_run(i, r, &bad_kind)?;
        if version < 2 && (run.rows.is_some() || run.motion.is_protocol()) {
            return Err(bad(
                &run.name,
                format!(
                    "run '{}' uses a version-2 feature (rows, unknown up_stand, rotation or multi_position): declare \"format\": \"{SESSION_FORMAT_2}\"",
                    run.name
                ),
            ));
        }
        runs.push(run);
    }
    let mut names: Vec<&str> = runs.iter().map(|r: &RunSpec| r.name.as_str()).collect();
    names.sort_unstable();
    if let Some(w) = names.windows(2).find(|w| w[0] == w[1]) {
        return Err(bad(w[0], format!("two runs are named '{}': run names must be unique", w[0])));
    }
    let source = obj.get("source").and_then(Source::from_json);
    Ok(Manifest { serial, units: Units { gyro, accel, time }, g_m_s2, runs, version, source })
}

/// A serial usable as a folder name.
pub fn valid_serial(s: &str) -> bool {
    !s.is_empty()
        && !s.starts_with('.')
        && s.len() <= 128
        && s.chars().all(|c| c.is_ascii_alphanumeric() || matches!(c, '-' | '_' | '.'))
}

fn num(v: &Value, key: &str) -> Option<f64> {
    v.get(key).and_then(Value::as_f64).filter(|x| x.is_finite())
}

/// Refuses optional fields that are present with a value of the wrong kind (a string where a
/// number belongs, a fraction where a count belongs) instead of ignoring them: `numbers` must
/// be finite numbers, `counts` non-negative integers.
fn kinds_ok(name: &str, v: &Value, numbers: &[&str], counts: &[&str], bad: &BadValue<'_>) -> Result<(), SessionError> {
    for key in numbers {
        if v.get(*key).is_some_and(|x| !x.is_null() && !x.as_f64().is_some_and(f64::is_finite)) {
            return Err(bad(key, format!("run '{name}': \"{key}\" must be a finite number")));
        }
    }
    for key in counts {
        if v.get(*key).is_some_and(|x| !x.is_null() && x.as_u64().is_none()) {
            return Err(bad(key, format!("run '{name}': \"{key}\" must be a whole number")));
        }
    }
    Ok(())
}

fn vec3(v: &Value, key: &str) -> Option<[f64; 3]> {
    let a = v.get(key)?.as_array().filter(|a| a.len() == 3)?;
    let x: Vec<f64> = a.iter().filter_map(Value::as_f64).filter(|x| x.is_finite()).collect();
    (x.len() == 3).then(|| [x[0], x[1], x[2]])
}

/// A manifest error at the first place `needle` appears (best effort).
type Bad<'a> = dyn Fn(Problem, &str, String) -> SessionError + 'a;

fn parse_run(i: usize, r: &Value, bad_kind: &Bad<'_>) -> Result<RunSpec, SessionError> {
    let bad = |needle: &str, msg: String| bad_kind(Problem::Invalid, needle, msg);
    let name = r.get("name").and_then(Value::as_str).map(str::to_string).unwrap_or_else(|| format!("run{}", i + 1));
    let file = r
        .get("file")
        .and_then(Value::as_str)
        .ok_or_else(|| {
            bad(&name, format!("run '{name}' has no \"file\": expected the CSV's path relative to the manifest"))
        })?
        .to_string();
    let m = r.get("motion").ok_or_else(|| {
        bad(
            &name,
            format!(
                "run '{name}' has no \"motion\": expected {{\"kind\": \"conic\" | \"static\" | \"reference\" | \"rotation\" | \"multi_position\", ...}}"
            ),
        )
    })?;
    let kind = m.get("kind").and_then(Value::as_str).unwrap_or("");
    let motion = match kind {
        "conic" => motions::conic_motion(&name, m, &bad)?,
        "static" if m.get("up_stand").and_then(Value::as_str) == Some("unknown") => MotionSpec::StaticUnknown,
        "static" => motions::static_motion(&name, m, &bad)?,
        "reference" => MotionSpec::Reference,
        "rotation" => motions::rotation_motion(&name, m, &bad)?,
        "multi_position" => motions::multi_position_motion(&name, m, &bad)?,
        other => {
            return Err(bad(
                if other.is_empty() { &name } else { other },
                format!("run '{name}': motion kind '{other}' is unknown: expected conic, static, reference, rotation or multi_position"),
            ))
        }
    };
    kinds_ok(&name, r, &["temperature_c", "duration_s"], &[], &bad)?;
    let duration_s = match num(r, "duration_s") {
        Some(d) if d > 0.0 && d <= 1e7 => Some(d),
        Some(d) => return Err(bad("duration_s", format!("run '{name}': duration_s is {d}: expected 0 < s ≤ 1e7"))),
        None => None,
    };
    let temperature_c = match num(r, "temperature_c") {
        Some(t) => Some(
            within(&name, "temperature_c", t, LIMITS.temperature_c.0, LIMITS.temperature_c.1, "degC")
                .map_err(|m| bad("temperature_c", m))?,
        ),
        None => None,
    };
    let start_s = match num(r, "start_s") {
        Some(s) => Some(within(&name, "start_s", s, -1e9, 1e9, "s").map_err(|m| bad("start_s", m))?),
        None if r.get("start_s").is_some() => {
            return Err(bad("start_s", format!("run '{name}': start_s must be a finite number of seconds")))
        }
        None => None,
    };
    let angle_column = match r.get("angle_column") {
        None => None,
        Some(Value::String(c)) if matches!(motion, MotionSpec::Conic { .. }) && !c.trim().is_empty() => Some(c.clone()),
        Some(Value::String(_)) if matches!(motion, MotionSpec::Conic { .. }) => {
            return Err(bad("angle_column", format!("run '{name}': angle_column is empty: expected the name of the column holding the stand's angle in degrees")))
        }
        Some(Value::String(_)) => {
            return Err(bad("angle_column", format!("run '{name}': angle_column (the stand's logged angle) is for conic runs: this run's motion is not conic")))
        }
        Some(_) => {
            return Err(bad("angle_column", format!("run '{name}': angle_column must be a column name (a string), e.g. \"theta_deg\"")))
        }
    };
    Ok(RunSpec {
        angle_column,
        duration_s,
        start_s,
        rows: run_rows(&name, r, &bad)?,
        mount: run_mount(&name, r, bad_kind)?,
        name,
        file,
        motion,
        temperature_c,
        note: r.get("note").and_then(Value::as_str).map(str::to_string),
    })
}

/// A manifest error of the invalid-value kind at `needle`.
type BadValue<'a> = dyn Fn(&str, String) -> SessionError + 'a;

fn run_rows(name: &str, r: &Value, bad: &BadValue<'_>) -> Result<Option<(usize, usize)>, SessionError> {
    let Some(v) = r.get("rows") else { return Ok(None) };
    let pair = v.as_array().filter(|a| a.len() == 2).and_then(|a| Some((a[0].as_u64()?, a[1].as_u64()?)));
    match pair {
        Some((s, e)) if e > s => Ok(Some((s as usize, e as usize))),
        _ => Err(bad(
            name,
            format!("run '{name}': rows must be [start, end] with 0 <= start < end (data rows, end exclusive)"),
        )),
    }
}

fn run_mount(name: &str, r: &Value, bad_kind: &Bad<'_>) -> Result<Mount, SessionError> {
    let Some(v) = r.get("mount") else { return Ok(Mount::identity()) };
    let names: Option<Vec<&str>> = v.as_array().map(|a| a.iter().filter_map(Value::as_str).collect());
    let names = names.ok_or_else(|| {
        bad_kind(Problem::Mount, name, format!("run '{name}': mount must be a list like [\"+x\", \"+y\", \"+z\"]"))
    })?;
    Mount::parse(&names)
        .map_err(|e| bad_kind(Problem::Mount, names.first().copied().unwrap_or(name), format!("run '{name}': {e}")))
}

#[cfg(test)]
mod tests {
    use super::*;

    const GOOD: &str = r#"{
  "format": "crosscal-session/1",
  "serial": "I1426-0042",
  "units": { "gyro": "deg/s", "accel": "g", "time": "s" },
  "stand": { "g": 9.80665 },
  "runs": [
    { "name": "cone+10", "file": "cone+10.csv",
      "motion": { "kind": "conic", "cone_angle_deg": 10.0, "rate_deg_s": 10.0, "phase_deg": 0.0 },
      "mount": ["+x", "+y", "+z"] }
  ]
}"#;

    #[test]
    fn parses_the_spec_example() {
        let m = parse_manifest(Path::new("s.json"), GOOD).unwrap();
        assert_eq!(m.serial, "I1426-0042");
        assert_eq!(m.runs.len(), 1);
        assert!(
            matches!(m.runs[0].motion, MotionSpec::Conic { cone_angle_deg, .. } if (cone_angle_deg - 10.0).abs() < 1e-12)
        );
    }

    #[test]
    fn rejects_unknown_format_and_units_with_position() {
        let e =
            parse_manifest(Path::new("s.json"), &GOOD.replace("crosscal-session/1", "crosscal-session/3")).unwrap_err();
        assert!(matches!(e, SessionError::UnknownFormat { .. }));
        assert!(e.to_string().contains("crosscal-session/3"));
        let e = parse_manifest(Path::new("s.json"), &GOOD.replace("\"deg/s\"", "\"deg/sec\"")).unwrap_err();
        let m = e.to_string();
        assert!(m.starts_with("s.json:4:") && m.contains("deg/sec") && m.contains("deg/s, rad/s, raw"), "{m}");
        let e =
            parse_manifest(Path::new("s.json"), &GOOD.replace("[\"+x\", \"+y\", \"+z\"]", "[\"+y\", \"+x\", \"+z\"]"))
                .unwrap_err();
        assert!(e.to_string().contains("not a rotation"), "{e}");
        let e = parse_manifest(Path::new("s.json"), "{ \"format\": ").unwrap_err();
        assert!(matches!(e, SessionError::Json { line: 1, .. }), "{e}");
    }
}
