//! Sessions built from columns in memory (the Python package's numpy arrays and pandas
//! frames), converted and checked exactly as the CSV reader converts and checks a file: the
//! same unit factors (so a session built from arrays fits to the same bits as the same
//! numbers read from a CSV), the same refusals (empty, non-finite, time not increasing), the
//! same findings (gaps, saturation, spikes). Errors name the run and the 1-based row.

use super::{parse_manifest, Manifest, MotionSpec, Problem, Recording, Run, Session, SessionError};
use crate::units::Units;
use std::path::{Path, PathBuf};

/// One run's columns as the recording has them (in the manifest's units).
#[derive(Debug, Clone, Copy)]
pub struct Columns<'a> {
    /// Time stamps (the manifest's time unit).
    pub t: &'a [f64],
    /// Gyro x, y, z per sample (the manifest's gyro unit).
    pub gyro: &'a [[f64; 3]],
    /// Accelerometer x, y, z per sample (the manifest's accelerometer unit).
    pub accel: &'a [[f64; 3]],
    /// Temperature per sample, °C, when there is one.
    pub temp_c: Option<&'a [f64]>,
}

/// The name runs built in memory carry in messages: `<memory>/RUN`.
fn label(run: &str) -> PathBuf {
    Path::new("<memory>").join(run)
}

fn err(problem: Problem, run: &str, row: usize, column: &str, msg: String) -> SessionError {
    SessionError::Csv { problem, path: label(run), line: row as u64, column: column.to_string(), msg }
}

/// Columns converted to SI: t in s, rates in rad/s, specific forces in m/s².
pub type SiColumns = (Vec<f64>, Vec<[f64; 3]>, Vec<[f64; 3]>);

/// Checks run `run`'s columns as the CSV reader checks a file, without copying them:
/// refused when empty, of unequal lengths, with a value that is not finite or time stamps
/// that do not increase (the error names the 1-based row and the column).
pub fn check_columns(run: &str, c: Columns<'_>, units: &Units) -> Result<(), SessionError> {
    let n = c.t.len();
    if n == 0 {
        return Err(err(Problem::Empty, run, 0, "-", "no samples".into()));
    }
    let lengths = [c.gyro.len(), c.accel.len(), c.temp_c.map_or(n, <[f64]>::len)];
    if lengths.iter().any(|&l| l != n) {
        return Err(err(
            Problem::FieldCount,
            run,
            lengths.into_iter().min().unwrap_or(0).min(n) + 1,
            "-",
            format!("columns of unequal length: t {n}, gyro {}, accel {}, temp {}", lengths[0], lengths[1], lengths[2]),
        ));
    }
    const NAMES: [&str; 8] = ["1 (t)", "2 (gx)", "3 (gy)", "4 (gz)", "5 (ax)", "6 (ay)", "7 (az)", "8 (temp)"];
    let kt = units.time.to_s();
    let mut last = f64::NEG_INFINITY;
    for k in 0..n {
        let (g, a) = (c.gyro[k], c.accel[k]);
        let temp = c.temp_c.map_or(0.0, |t| t[k]);
        let values = [c.t[k], g[0], g[1], g[2], a[0], a[1], a[2], temp];
        if let Some(i) = values.iter().position(|v| !v.is_finite()) {
            let msg = format!("expected a finite number, found {}", values[i]);
            return Err(err(Problem::Value, run, k + 1, NAMES[i], msg));
        }
        let t = c.t[k] * kt;
        if t <= last {
            let msg = format!("t = {} does not increase (the previous sample is at {})", c.t[k], last / kt);
            return Err(err(Problem::Time, run, k + 1, NAMES[0], msg));
        }
        last = t;
    }
    Ok(())
}

/// Run `run`'s columns in `units` (gravity `g_m_s2` for g) converted to SI with the CSV
/// reader's factors, once [`check_columns`] accepts them.
pub fn columns_to_si(run: &str, c: Columns<'_>, units: &Units, g_m_s2: f64) -> Result<SiColumns, SessionError> {
    check_columns(run, c, units)?;
    let (kt, kg, ka) = (units.time.to_s(), units.gyro.to_rad_s(), units.accel.to_m_s2(g_m_s2));
    let t_s = c.t.iter().map(|t| t * kt).collect();
    let gyro = c.gyro.iter().map(|g| [g[0] * kg, g[1] * kg, g[2] * kg]).collect();
    let accel = c.accel.iter().map(|a| [a[0] * ka, a[1] * ka, a[2] * ka]).collect();
    Ok((t_s, gyro, accel))
}

/// A recording of run `run` from its columns (see [`columns_to_si`]), with the reader's
/// findings (gaps, saturation, spikes). Its SHA-256 is that of the columns' bytes
/// (little-endian doubles: t, gyro, accel, temp in that order).
pub fn recording_from_columns(
    run: &str,
    c: Columns<'_>,
    units: &Units,
    g_m_s2: f64,
) -> Result<Recording, SessionError> {
    let (t_s, gyro, accel) = columns_to_si(run, c, units, g_m_s2)?;
    let mut hash = sha2::Sha256::default();
    let values = c.t.iter().chain(c.gyro.iter().flatten()).chain(c.accel.iter().flatten());
    for v in values.chain(c.temp_c.into_iter().flatten()) {
        sha2::Digest::update(&mut hash, v.to_le_bytes());
    }
    let warnings = super::sanity::scan_record(&t_s, &gyro, &accel, &label(run).display().to_string());
    Ok(Recording {
        t_s: t_s.into(),
        gyro: gyro.into(),
        accel: accel.into(),
        temp_c: c.temp_c.map(<[f64]>::to_vec),
        reference: None,
        angle_rad: None,
        sha256: super::csvread::hex(&sha2::Digest::finalize(hash)),
        warnings,
    })
}

/// A session from a manifest's JSON text (checked as a manifest file is; its runs' `file`
/// entries name nothing on disk) and each run's columns, in the manifest's run order.
/// Reference runs (whose truth is in extra columns) and `rows` ranges are refused: they
/// describe files.
pub fn session_from_columns(manifest_json: &str, runs: &[Columns<'_>]) -> Result<Session, SessionError> {
    let manifest_path = Path::new("<memory>").join("session.json");
    let manifest: Manifest = parse_manifest(&manifest_path, manifest_json)?;
    let invalid = |msg: String| SessionError::Manifest {
        problem: Problem::Invalid,
        path: manifest_path.clone(),
        line: 0,
        column: 0,
        msg,
    };
    if manifest.runs.len() != runs.len() {
        return Err(invalid(format!("the manifest has {} runs and {} were given", manifest.runs.len(), runs.len())));
    }
    let mut out = Vec::with_capacity(runs.len());
    for (spec, cols) in manifest.runs.iter().zip(runs) {
        if matches!(spec.motion, MotionSpec::Reference) || spec.rows.is_some() {
            return Err(invalid(format!(
                "run '{}': reference runs and row ranges describe files: write the session and read it",
                spec.name
            )));
        }
        let rec = recording_from_columns(&spec.name, *cols, &manifest.units, manifest.g_m_s2)?;
        out.push(Run { spec: spec.clone(), path: label(&spec.name), rec });
    }
    Ok(Session { manifest_path, manifest, runs: out })
}
