//! Importers: recordings laid out for other calibration tools, turned into crosscal
//! sessions (a `session.json` manifest, format 2, and one `recording.csv`).
//!
//! | layout | tool | protocol |
//! |---|---|---|
//! | [`imucal_ferraris`] | imucal: CSV `n_samples,gyr_*,acc_*` + section list JSON | Ferraris |
//! | [`imucal_annotated`] | imucal: CSV with a `part` column and `samples` index | Ferraris |
//! | [`imu_tk`] | imu_tk: two whitespace files `t x y z` (accelerometer, gyro) | multi-position |
//! | [`tedaldi_csv`] | `Fs,…` header lines, then `ax,ay,az,gx,gy,gz` (ImuCalibration) | multi-position |
//!
//! Sections named `x_p`/`x_a` (and y, z) are static poses with +axis / −axis up; `x_rot`
//! (and y, z) are turns about +axis through `turn_angle_deg`.

use super::{Manifest, MotionSpec, Problem, RunSpec, SessionError};
use crate::units::{AccelUnit, GyroUnit, TimeUnit, Units};
use std::path::{Path, PathBuf};

/// Settings shared by the importers.
#[derive(Debug, Clone, PartialEq)]
pub struct ImportOptions {
    /// Serial of the unit.
    pub serial: String,
    /// Local gravity, m/s².
    pub g_m_s2: f64,
    /// Sample rate, Hz, for layouts without a time column.
    pub rate_hz: Option<f64>,
    /// Total angle of each Ferraris turn, degrees (imucal's default is −360).
    pub turn_angle_deg: f64,
    /// Initial rest, s (multi-position; from the file when it says).
    pub init_rest_s: Option<f64>,
}

impl Default for ImportOptions {
    fn default() -> Self {
        Self { serial: "imported".into(), g_m_s2: 9.81, rate_hz: None, turn_angle_deg: -360.0, init_rest_s: None }
    }
}

/// What an import wrote.
#[derive(Debug, Clone, PartialEq)]
pub struct Imported {
    /// The manifest written.
    pub manifest_path: PathBuf,
    /// Runs declared.
    pub runs: usize,
    /// Samples written.
    pub samples: usize,
}

/// Samples in the order written: t (s), gyro, accel.
pub(super) struct Table {
    pub(super) t: Vec<f64>,
    pub(super) gyro: Vec<[f64; 3]>,
    pub(super) accel: Vec<[f64; 3]>,
}

/// A reading error at `path:line`, `column` (a number and name, or `-`).
pub(super) fn csv_err(path: &Path, line: usize, column: &str, problem: Problem, msg: String) -> SessionError {
    SessionError::Csv { problem, path: path.to_path_buf(), line: line as u64, column: column.to_string(), msg }
}

fn read(path: &Path) -> Result<String, SessionError> {
    crate::atomic::read_text(path).map_err(|source| SessionError::Io { path: path.to_path_buf(), source })
}

/// Parses field `i` of a split line as a finite number.
fn field(path: &Path, line: usize, fields: &[&str], i: usize, name: &str) -> Result<f64, SessionError> {
    let raw = fields.get(i).ok_or_else(|| {
        csv_err(
            path,
            line,
            &format!("{} ({name})", i + 1),
            Problem::FieldCount,
            format!("the row ends before column '{name}'"),
        )
    })?;
    raw.trim().parse::<f64>().ok().filter(|x| x.is_finite()).ok_or_else(|| {
        csv_err(
            path,
            line,
            &format!("{} ({name})", i + 1),
            Problem::Value,
            format!("'{}' is not a finite number", raw.trim()),
        )
    })
}

/// The remaining comma-separated lines (numbered from 0): of each non-blank one, the six
/// fields at `idx` (named `names`) as numbers, handed to `push` in order.
fn six_columns<'a>(
    path: &Path,
    lines: impl Iterator<Item = (usize, &'a str)>,
    idx: &[usize],
    names: &[&str; 6],
    mut push: impl FnMut([f64; 6]),
) -> Result<(), SessionError> {
    for (i, line) in lines {
        if line.trim().is_empty() {
            continue;
        }
        let f: Vec<&str> = line.split(',').collect();
        let mut v = [0.0; 6];
        for c in 0..6 {
            v[c] = field(path, i + 1, &f, idx[c], names[c])?;
        }
        push(v);
    }
    Ok(())
}

/// Header columns by name: index of each of `names`.
fn columns(path: &Path, header: &str, names: &[&str]) -> Result<Vec<usize>, SessionError> {
    let cols: Vec<&str> = header.split(',').map(str::trim).collect();
    names
        .iter()
        .map(|n| {
            cols.iter().position(|c| c == n).ok_or_else(|| {
                csv_err(
                    path,
                    1,
                    "-",
                    Problem::Header,
                    format!(
                        "column '{n}' is absent: the header has [{}]; expected {}",
                        cols.join(","),
                        names.join(",")
                    ),
                )
            })
        })
        .collect()
}

/// Writes the recording (`recording.csv`) and its manifest (`session.json`) into `out_dir`,
/// neither replacing an existing file.
pub(super) fn write_table(
    out_dir: &Path,
    units: Units,
    opts: &ImportOptions,
    table: &Table,
    runs: Vec<RunSpec>,
) -> Result<Imported, SessionError> {
    let io = |path: &Path| {
        let path = path.to_path_buf();
        move |source| SessionError::Io { path: path.clone(), source }
    };
    std::fs::create_dir_all(out_dir).map_err(io(out_dir))?;
    let csv_path = out_dir.join("recording.csv");
    let text = super::recording_csv(&table.t, &table.gyro, &table.accel, None, [1.0, 1.0]);
    crate::atomic::write_new(&csv_path, &text).map_err(io(&csv_path))?;
    let manifest = Manifest { serial: opts.serial.clone(), units, g_m_s2: opts.g_m_s2, runs, version: 2, source: None };
    let manifest_path = out_dir.join("session.json");
    crate::atomic::write_new(&manifest_path, manifest.to_json().as_bytes()).map_err(io(&manifest_path))?;
    Ok(Imported { manifest_path, runs: manifest.runs.len(), samples: table.t.len() })
}

fn bad_list(path: &Path, msg: String) -> SessionError {
    SessionError::Manifest { problem: Problem::Invalid, path: path.to_path_buf(), line: 0, column: 0, msg }
}

/// A named section: rows `[start, end)`.
type Section = (String, (usize, usize));

/// imucal's section list `{"x_p": {"start": …, "end": …}, …}`: the nine sections in
/// protocol order, each checked against the recording's `n` samples.
fn section_list(path: &Path, n: usize) -> Result<Vec<Section>, SessionError> {
    let json_text = read(path)?;
    let json: serde_json::Value = serde_json::from_str(&json_text).map_err(|e| SessionError::Json {
        path: path.to_path_buf(),
        line: e.line(),
        column: e.column(),
        msg: format!("the section list is not valid JSON: {e}"),
    })?;
    let mut out = Vec::new();
    for name in FERRARIS_SECTIONS {
        let sec = json.get(name).ok_or_else(|| {
            bad_list(path, format!("section '{name}' is missing: expected {}", FERRARIS_SECTIONS.join(", ")))
        })?;
        let get = |k: &str| sec.get(k).and_then(serde_json::Value::as_u64).map(|x| x as usize);
        let (Some(s), Some(e)) = (get("start"), get("end")) else {
            return Err(bad_list(path, format!("section '{name}' needs integer \"start\" and \"end\"")));
        };
        if e <= s || e > n {
            return Err(bad_list(
                path,
                format!("section '{name}' [{s}, {e}) is empty or past the recording's {n} samples"),
            ));
        }
        out.push((name.to_string(), (s, e)));
    }
    Ok(out)
}

/// A run of the imported recording.
pub(super) fn run(name: &str, motion: MotionSpec, rows: Option<(usize, usize)>) -> RunSpec {
    RunSpec::new(name, "recording.csv", motion, rows)
}

/// The motion of an imucal section name (`x_p`, `y_a`, `z_rot`, …).
fn ferraris_motion(name: &str, turn_angle_deg: f64) -> Option<MotionSpec> {
    let axis = match name.as_bytes().first()? {
        b'x' => 0,
        b'y' => 1,
        b'z' => 2,
        _ => return None,
    };
    let mut e = [0.0; 3];
    match &name[1..] {
        "_p" => e[axis] = 1.0,
        "_a" => e[axis] = -1.0,
        "_rot" => {
            e[axis] = 1.0;
            return Some(MotionSpec::Rotation { axis_stand: e, angle_deg: turn_angle_deg });
        }
        _ => return None,
    }
    Some(MotionSpec::Static { up_stand: e, earth_rate_rad_s: [0.0; 3] })
}

const FERRARIS_SECTIONS: [&str; 9] = ["x_p", "x_a", "y_p", "y_a", "z_p", "z_a", "x_rot", "y_rot", "z_rot"];

/// imucal's example layout: `n_samples,gyr_x,gyr_y,gyr_z,acc_x,acc_y,acc_z` (deg/s, m/s²,
/// no time column: `rate_hz` is required) and a section list `{"x_p": {"start": …, "end":
/// …}, …}` (iloc, end exclusive). Without a section list the six faces and three turns are
/// found from the data ([`crate::stats::segment::detect_ferraris`]), each turn's sign from
/// its gyro integral (the magnitude of `turn_angle_deg` is used).
pub fn imucal_ferraris(
    csv: &Path,
    sections: Option<&Path>,
    out_dir: &Path,
    opts: &ImportOptions,
) -> Result<Imported, SessionError> {
    let rate = opts.rate_hz.filter(|r| *r > 0.0).ok_or_else(|| {
        csv_err(
            csv,
            1,
            "-",
            Problem::Header,
            "this layout has no time column: give the sample rate (imucal's example: 102.4 Hz)".into(),
        )
    })?;
    let text = read(csv)?;
    let mut lines = text.lines().enumerate();
    let header = lines.next().map(|(_, l)| l).unwrap_or("");
    let names = ["gyr_x", "gyr_y", "gyr_z", "acc_x", "acc_y", "acc_z"];
    let idx = columns(csv, header, &names)?;
    let mut table = Table { t: Vec::new(), gyro: Vec::new(), accel: Vec::new() };
    six_columns(csv, lines, &idx, &names, |v| {
        table.t.push(table.t.len() as f64 / rate);
        table.gyro.push([v[0], v[1], v[2]]);
        table.accel.push([v[3], v[4], v[5]]);
    })?;
    let mut runs = Vec::new();
    match sections {
        Some(list) => {
            for (name, (s, e)) in section_list(list, table.t.len())? {
                let motion = ferraris_motion(&name, opts.turn_angle_deg)
                    .ok_or_else(|| bad_list(list, format!("unknown section '{name}'")))?;
                runs.push(run(&name, motion, Some((s, e))));
            }
        }
        None => {
            // Sections found from the data; each turn's sense from its gyro integral.
            let window = ((0.5 * rate).round() as usize).max(11) | 1;
            let min_len = (rate.round() as usize).max(window);
            let found = [10.0, 5.0, 20.0]
                .iter()
                .map(|&m| {
                    crate::stats::segment::detect_ferraris(&table.t, &table.gyro, &table.accel, window, m, min_len)
                })
                .find(Result::is_ok)
                .unwrap_or_else(|| {
                    crate::stats::segment::detect_ferraris(&table.t, &table.gyro, &table.accel, window, 10.0, min_len)
                })
                .map_err(|e| csv_err(csv, 1, "-", Problem::Value, format!("finding the Ferraris sections: {e}")))?;
            for sec in found {
                // The face's up is in its name; a turn's sense is the one found.
                let motion = ferraris_motion(&sec.name, sec.sign * opts.turn_angle_deg.abs())
                    .ok_or_else(|| csv_err(csv, 1, "-", Problem::Value, format!("unknown section '{}'", sec.name)))?;
                runs.push(run(&sec.name, motion, Some(sec.rows)));
            }
        }
    }
    let units = Units { gyro: GyroUnit::DegPerS, accel: AccelUnit::MPerS2, time: TimeUnit::S };
    write_table(out_dir, units, opts, &table, runs)
}

/// imucal's annotated layout: `part,samples,acc_x,acc_y,acc_z,gyr_x,gyr_y,gyr_z` in raw
/// units, `part` naming the section and `samples` the original sample index (t =
/// samples / `rate_hz`). Rows are written in sample order; each section must be contiguous.
pub fn imucal_annotated(csv: &Path, out_dir: &Path, opts: &ImportOptions) -> Result<Imported, SessionError> {
    let rate = opts.rate_hz.filter(|r| *r > 0.0).ok_or_else(|| {
        csv_err(csv, 1, "-", Problem::Header, "give the sample rate (imucal's annotated example: 204.8 Hz)".into())
    })?;
    let text = read(csv)?;
    let mut lines = text.lines().enumerate();
    let header = lines.next().map(|(_, l)| l).unwrap_or("");
    let names = ["part", "samples", "acc_x", "acc_y", "acc_z", "gyr_x", "gyr_y", "gyr_z"];
    let idx = columns(csv, header, &names)?;
    let mut rows: Vec<(f64, String, [f64; 6], usize)> = Vec::new();
    for (i, line) in lines {
        if line.trim().is_empty() {
            continue;
        }
        let f: Vec<&str> = line.split(',').collect();
        let part = f.get(idx[0]).map(|s| s.trim().to_string()).unwrap_or_default();
        if ferraris_motion(&part, opts.turn_angle_deg).is_none() {
            return Err(csv_err(
                csv,
                i + 1,
                &format!("{} (part)", idx[0] + 1),
                Problem::Value,
                format!("part '{part}' is not one of {}", FERRARIS_SECTIONS.join(", ")),
            ));
        }
        let sample = field(csv, i + 1, &f, idx[1], "samples")?;
        let mut v = [0.0; 6];
        for c in 0..6 {
            v[c] = field(csv, i + 1, &f, idx[2 + c], names[2 + c])?;
        }
        rows.push((sample, part, v, i + 1));
    }
    rows.sort_by(|a, b| a.0.total_cmp(&b.0));
    if let Some(w) = rows.windows(2).find(|w| w[0].0.total_cmp(&w[1].0).is_eq()) {
        return Err(csv_err(
            csv,
            w[1].3,
            "2 (samples)",
            Problem::Time,
            format!("sample index {} appears twice", w[1].0),
        ));
    }
    let mut runs: Vec<RunSpec> = Vec::new();
    let mut start = 0;
    for k in 1..=rows.len() {
        if k == rows.len() || rows[k].1 != rows[start].1 {
            let name = &rows[start].1;
            if runs.iter().any(|r| &r.name == name) {
                return Err(csv_err(
                    csv,
                    rows[start].3,
                    "1 (part)",
                    Problem::Value,
                    format!(
                        "part '{name}' is split in two by the sample index: each section must be one contiguous block"
                    ),
                ));
            }
            if let Some(m) = ferraris_motion(name, opts.turn_angle_deg) {
                runs.push(run(name, m, Some((start, k))));
            }
            start = k;
        }
    }
    for name in FERRARIS_SECTIONS {
        if !runs.iter().any(|r| r.name == name) {
            return Err(csv_err(csv, 1, "1 (part)", Problem::Value, format!("section '{name}' has no rows")));
        }
    }
    let table = Table {
        t: rows.iter().map(|r| r.0 / rate).collect(),
        gyro: rows.iter().map(|r| [r.2[3], r.2[4], r.2[5]]).collect(),
        accel: rows.iter().map(|r| [r.2[0], r.2[1], r.2[2]]).collect(),
    };
    let units = Units { gyro: GyroUnit::Raw, accel: AccelUnit::Raw, time: TimeUnit::S };
    write_table(out_dir, units, opts, &table, runs)
}

/// Whitespace-separated `t x y z` rows (imu_tk's `.mat` text files).
fn read_triads(path: &Path) -> Result<(Vec<f64>, Vec<[f64; 3]>), SessionError> {
    let text = read(path)?;
    let (mut t, mut v) = (Vec::new(), Vec::new());
    let names = ["t", "x", "y", "z"];
    for (i, line) in text.lines().enumerate() {
        if line.trim().is_empty() || line.trim_start().starts_with('%') || line.trim_start().starts_with('#') {
            continue;
        }
        let f: Vec<&str> = line.split_whitespace().collect();
        let mut x = [0.0; 4];
        for c in 0..4 {
            x[c] = field(path, i + 1, &f, c, names[c])?;
        }
        t.push(x[0]);
        v.push([x[1], x[2], x[3]]);
    }
    if t.is_empty() {
        return Err(csv_err(path, 1, "-", Problem::Empty, "no samples: expected rows 't x y z'".into()));
    }
    Ok((t, v))
}

/// imu_tk's layout: accelerometer and gyro files of `t x y z` rows (raw counts, same time
/// stamps), a multi-position recording with an initial rest (`init_rest_s`, imu_tk's
/// example uses 50 s).
pub fn imu_tk(acc: &Path, gyro: &Path, out_dir: &Path, opts: &ImportOptions) -> Result<Imported, SessionError> {
    let (ta, a) = read_triads(acc)?;
    let (tg, g) = read_triads(gyro)?;
    if ta.len() != tg.len() {
        return Err(csv_err(
            gyro,
            tg.len().min(ta.len()) + 1,
            "1 (t)",
            Problem::FieldCount,
            format!(
                "{} gyro rows but {} accelerometer rows: the files must share their time stamps",
                tg.len(),
                ta.len()
            ),
        ));
    }
    if let Some(k) = (0..ta.len()).find(|&k| (ta[k] - tg[k]).abs() > 1e-6 * ta[k].abs().max(1.0)) {
        return Err(csv_err(
            gyro,
            k + 1,
            "1 (t)",
            Problem::Time,
            format!(
                "time {} differs from the accelerometer's {}: the files must share their time stamps",
                tg[k], ta[k]
            ),
        ));
    }
    let table = Table { t: ta, gyro: g, accel: a };
    let motion = MotionSpec::MultiPosition {
        init_rest_s: opts.init_rest_s.unwrap_or(50.0),
        window: 101,
        threshold_multiplier: None,
        min_pose_samples: 100,
        poses: None,
    };
    let units = Units { gyro: GyroUnit::Raw, accel: AccelUnit::Raw, time: TimeUnit::S };
    write_table(out_dir, units, opts, &table, vec![run("multi-position", motion, None)])
}

/// The `Fs,…` layout (e.g. tomisuarez2/ImuCalibration): header lines `Fs,<Hz>`,
/// `Initialization time,<s>` (and others), then `ax,ay,az,gx,gy,gz` raw counts. With
/// `intervals` (a CSV of two rows, start and end sample indices), those static poses are
/// used instead of detecting them.
pub fn tedaldi_csv(
    csv: &Path,
    intervals: Option<&Path>,
    out_dir: &Path,
    opts: &ImportOptions,
) -> Result<Imported, SessionError> {
    let text = read(csv)?;
    let mut rate = opts.rate_hz;
    let mut init = opts.init_rest_s;
    let mut lines = text.lines().enumerate();
    let mut idx = None;
    let names = ["ax", "ay", "az", "gx", "gy", "gz"];
    for (i, line) in lines.by_ref() {
        let f: Vec<&str> = line.split(',').map(str::trim).collect();
        match f.first().copied() {
            Some("Fs") => rate = rate.or(f.get(1).and_then(|x| x.parse().ok())),
            Some("Initialization time") => {
                init = init.or(f.get(1).and_then(|x| x.parse().ok()).filter(|x: &f64| *x > 0.0))
            }
            Some("ax") => {
                idx = Some(columns(csv, line, &names)?);
                break;
            }
            _ if i > 20 => break,
            _ => {}
        }
    }
    let idx = idx.ok_or_else(|| {
        csv_err(csv, 1, "-", Problem::Header, "no header line 'ax,ay,az,gx,gy,gz' in the first lines".into())
    })?;
    let rate = rate
        .filter(|r| *r > 0.0)
        .ok_or_else(|| csv_err(csv, 1, "-", Problem::Header, "no 'Fs,<Hz>' line: give the sample rate".into()))?;
    let mut table = Table { t: Vec::new(), gyro: Vec::new(), accel: Vec::new() };
    six_columns(csv, lines, &idx, &names, |v| {
        table.t.push(table.t.len() as f64 / rate);
        table.accel.push([v[0], v[1], v[2]]);
        table.gyro.push([v[3], v[4], v[5]]);
    })?;
    let poses = match intervals {
        None => None,
        Some(p) => Some(read_intervals(p, table.t.len())?),
    };
    let motion = MotionSpec::MultiPosition {
        init_rest_s: init.unwrap_or(30.0),
        window: 101,
        threshold_multiplier: None,
        min_pose_samples: 100,
        poses,
    };
    let units = Units { gyro: GyroUnit::Raw, accel: AccelUnit::Raw, time: TimeUnit::S };
    write_table(out_dir, units, opts, &table, vec![run("multi-position", motion, None)])
}

/// Two CSV rows of sample indices: starts, then ends (inclusive).
fn read_intervals(path: &Path, n: usize) -> Result<Vec<(usize, usize)>, SessionError> {
    let text = read(path)?;
    let rows: Vec<(usize, Vec<&str>)> = text
        .lines()
        .enumerate()
        .filter(|(_, l)| !l.trim().is_empty())
        .map(|(i, l)| (i + 1, l.split(',').collect()))
        .collect();
    if rows.len() != 2 || rows[0].1.len() != rows[1].1.len() {
        return Err(csv_err(
            path,
            1,
            "-",
            Problem::FieldCount,
            "expected two rows of equal length: start indices, then end indices".into(),
        ));
    }
    let mut out = Vec::new();
    for c in 0..rows[0].1.len() {
        let s = field(path, rows[0].0, &rows[0].1, c, "start")?;
        let e = field(path, rows[1].0, &rows[1].1, c, "end")?;
        let (s, e) = (s.round() as usize, e.round() as usize + 1);
        if s >= e || e > n {
            return Err(csv_err(
                path,
                rows[1].0,
                &(c + 1).to_string(),
                Problem::Value,
                format!("interval [{s}, {e}) is empty or past the {n} samples"),
            ));
        }
        out.push((s, e));
    }
    Ok(out)
}
