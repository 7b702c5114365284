//! A log's IMU stream written as a crosscal session: one pass to list the streams (and
//! learn the chosen one's time base and whether its temperature is real), one pass to
//! write `recording.csv` (streamed, in fixed memory, atomically) while the rests and
//! motions are told apart ([`super::segment`]), then `session.json` with the run kind the
//! recording turned out to be and the log's provenance (`"source"`).

use super::segment::{Blocks, Summary};
use super::{list, read, Contents, LogSample, ReadOptions, StreamDesc, StreamStats};
use crate::session::error::{Problem, SessionError};
use crate::session::import::{ImportOptions, Imported};
use crate::session::{CsvLine, Manifest, MotionSpec, RunSpec, Source};
use crate::units::{AccelUnit, GyroUnit, TimeUnit, Units};
use std::io::Write;
use std::path::Path;

/// What kind of session to write.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum SessionKind {
    /// Decided from the data: static when at rest throughout, else multi-position.
    #[default]
    Auto,
    /// A static recording (for `noise`).
    Static,
    /// A multi-position recording (rests in several orientations).
    MultiPosition,
}

/// Which stream and which part of it.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Selection {
    /// Topic or stream name (`--topic`).
    pub topic: Option<String>,
    /// IMU instance (`--imu`).
    pub imu: Option<u32>,
    /// Keep samples from this time, s after the stream's first sample.
    pub from_s: Option<f64>,
    /// Keep samples up to this time, s after the stream's first sample.
    pub to_s: Option<f64>,
    /// Session kind.
    pub kind: SessionKind,
    /// Reading options (message definitions).
    pub read: ReadOptions,
}

/// What an import from a log did.
#[derive(Debug, Clone, PartialEq)]
pub struct LogImported {
    /// The files written.
    pub imported: Imported,
    /// The stream written.
    pub stream: StreamDesc,
    /// Everything the file held (streams, notes, warnings, applied calibration).
    pub contents: Contents,
    /// The kind written (`static` or `multi-position`) and why.
    pub kind: (SessionKind, String),
    /// Rests and motions found.
    pub summary: Summary,
    /// Samples dropped because their time stamp did not advance.
    pub dropped_time: u64,
    /// The stream's statistics (samples, rate, span) before --from/--to.
    pub stats: StreamStats,
    /// The calibration the log says was applied to this stream (as in the manifest).
    pub applied: Vec<(String, f64)>,
}

/// The stream `sel` names among `streams` (with their statistics).
pub fn choose(path: &Path, contents: &Contents, stats: &[StreamStats], sel: &Selection) -> Result<usize, SessionError> {
    let listing = || {
        contents
            .streams
            .iter()
            .zip(stats)
            .map(|(s, st)| {
                let inst = s.instance.map(|i| format!(", --imu {i}")).unwrap_or_default();
                format!("{} ({} samples{inst})", s.name, st.samples)
            })
            .collect::<Vec<_>>()
            .join("; ")
    };
    let none = |what: String| SessionError::log(Problem::Empty, path, 0, what);
    if contents.streams.is_empty() {
        return Err(none(format!(
            "no IMU stream found in this {} (sensor_msgs/Imu topics, ULog sensor_combined/sensor_accel/sensor_gyro, DataFlash IMU/ACC/GYR)",
            contents.format.name()
        )));
    }
    let idx = if let Some(t) = &sel.topic {
        contents
            .streams
            .iter()
            .position(|s| &s.name == t)
            .ok_or_else(|| none(format!("no IMU stream '{t}': the file holds {}", listing())))?
    } else if let Some(i) = sel.imu {
        let by_instance = contents.streams.iter().position(|s| s.six_axis && s.instance == Some(i));
        let by_order = || {
            let six: Vec<usize> = (0..contents.streams.len()).filter(|&k| contents.streams[k].six_axis).collect();
            six.get(i as usize).copied()
        };
        by_instance.or_else(by_order).ok_or_else(|| none(format!("no IMU {i}: the file holds {}", listing())))?
    } else {
        (0..contents.streams.len())
            .filter(|&k| contents.streams[k].six_axis && stats[k].samples > 0)
            .max_by_key(|&k| stats[k].samples)
            .ok_or_else(|| none(format!("no six-axis IMU stream with samples: the file holds {}", listing())))?
    };
    if !contents.streams[idx].six_axis {
        return Err(SessionError::log(
            Problem::Invalid,
            path,
            0,
            format!(
                "{} holds one sensor only ({}): a session needs gyro and accelerometer together",
                contents.streams[idx].name, contents.streams[idx].message
            ),
        ));
    }
    Ok(idx)
}

/// Imports stream `sel` of the log at `path` into `out_dir` (see the module docs).
pub fn import_log(
    path: &Path,
    out_dir: &Path,
    opts: &ImportOptions,
    sel: &Selection,
) -> Result<LogImported, SessionError> {
    let (contents, stats) = list(path, &sel.read)?;
    let idx = choose(path, &contents, &stats, sel)?;
    let st = &stats[idx];
    if st.samples == 0 {
        return Err(SessionError::log(
            Problem::Empty,
            path,
            0,
            format!("{} has no samples", contents.streams[idx].name),
        ));
    }
    let io = |p: &Path| {
        let p = p.to_path_buf();
        move |source| SessionError::Io { path: p.clone(), source }
    };
    std::fs::create_dir_all(out_dir).map_err(io(out_dir))?;
    let csv_path = out_dir.join("recording.csv");
    let (written, dropped, blocks) = write_recording(path, sel, idx, st, &csv_path)?;
    if written == 0 {
        let _ = std::fs::remove_file(&csv_path);
        return Err(SessionError::log(
            Problem::Empty,
            path,
            0,
            format!("no sample of {} lies between --from and --to", contents.streams[idx].name),
        ));
    }
    let summary = blocks.finish();
    let rate = st.rate_hz();
    let (kind, why) = decide(sel.kind, &summary);
    let motion = match kind {
        SessionKind::Static => MotionSpec::StaticUnknown,
        _ => {
            let window = (((rate.max(10.0)).round() as usize) | 1).clamp(11, 1001);
            MotionSpec::MultiPosition {
                init_rest_s: summary.initial_rest_s().map_or(30.0, |r| (r * 0.9).max(1.0)),
                window,
                threshold_multiplier: None,
                min_pose_samples: window.max(20),
                poses: None,
            }
        }
    };
    let name = if kind == SessionKind::Static { "static" } else { "multi-position" };
    let stream = contents.streams[idx].clone();
    let mut notes = contents.notes.clone();
    notes.extend(stream.note.iter().cloned());
    notes.extend(contents.warnings.iter().cloned());
    let source = Source {
        format: contents.format.name().into(),
        file: path.display().to_string(),
        stream: format!("{} ({})", stream.name, stream.message),
        frame: stream.frame.into(),
        start_ns: st.first_ns,
        applied: match (contents.format, stream.instance) {
            (super::LogFormat::DataFlash, Some(i)) => super::dataflash::applied_to(&contents.applied, i),
            _ => contents.applied.clone(),
        },
        notes,
    };
    let units = Units { gyro: GyroUnit::RadPerS, accel: AccelUnit::MPerS2, time: TimeUnit::S };
    let manifest = Manifest {
        serial: opts.serial.clone(),
        units,
        g_m_s2: opts.g_m_s2,
        runs: vec![RunSpec::new(name, "recording.csv", motion, None)],
        version: 2,
        source: Some(source),
    };
    let manifest_path = out_dir.join("session.json");
    crate::atomic::write_new(&manifest_path, manifest.to_json().as_bytes()).map_err(io(&manifest_path))?;
    Ok(LogImported {
        imported: Imported { manifest_path, runs: 1, samples: written },
        stream,
        contents,
        kind: (kind, why),
        summary,
        dropped_time: dropped,
        stats: st.clone(),
        applied: manifest.source.map(|s| s.applied).unwrap_or_default(),
    })
}

/// Writes stream `idx` (statistics `st`) to `csv_path`, new and atomically: samples kept,
/// samples dropped because their time did not advance, and the rest/motion blocks.
fn write_recording(
    path: &Path,
    sel: &Selection,
    idx: usize,
    st: &StreamStats,
    csv_path: &Path,
) -> Result<(usize, u64, Blocks), SessionError> {
    let has_temp = st.temp_c.is_some();
    let (from, to) = (sel.from_s.unwrap_or(f64::NEG_INFINITY), sel.to_s.unwrap_or(f64::INFINITY));
    let mut blocks = Blocks::default();
    let mut written = 0usize;
    let mut dropped = 0u64;
    let mut failure: Option<SessionError> = None;
    let write = crate::atomic::write_atomic(csv_path, false, |w| {
        writeln!(w, "{}", crate::session::recording_header(has_temp, false))?;
        let mut line = CsvLine::new();
        let mut last_t = f64::NEG_INFINITY;
        let mut last_temp = st.temp_c.map_or(0.0, |r| r[0]);
        let mut sink = |i: usize, s: &LogSample| -> Result<(), SessionError> {
            if i != idx {
                return Ok(());
            }
            let t = s.t_ns.saturating_sub(st.first_ns) as f64 * 1e-9;
            if t < from || t > to {
                return Ok(());
            }
            if t <= last_t {
                dropped += 1;
                return Ok(());
            }
            last_t = t;
            if let Some(c) = s.temp_c {
                last_temp = c;
            }
            blocks.push(t, s.gyro_rad_s, s.accel_m_s2);
            line.sample(t, s.gyro_rad_s, s.accel_m_s2, [1.0; 3], has_temp.then_some(last_temp), None);
            written += 1;
            line.write_to(w).map_err(|source| SessionError::Io { path: csv_path.to_path_buf(), source })
        };
        match read(path, &sel.read, Some(idx), &mut sink) {
            Ok(_) => Ok(()),
            Err(e) => {
                failure = Some(e);
                Err(std::io::Error::other("reading the log failed"))
            }
        }
    });
    if let Some(e) = failure {
        return Err(e);
    }
    write.map_err(|source| SessionError::Io { path: csv_path.to_path_buf(), source })?;
    Ok((written, dropped, blocks))
}

/// The session kind for `asked` given what the blocks say, and why in words.
fn decide(asked: SessionKind, s: &Summary) -> (SessionKind, String) {
    let seen = format!(
        "{} rest(s) in {} orientation(s), {} of {} half-second blocks moving",
        s.rests.len(),
        s.orientations,
        s.moving,
        s.blocks
    );
    match asked {
        SessionKind::Static if !s.is_static() => (SessionKind::Static, format!("static as asked, though the data move: {seen}")),
        SessionKind::Static => (SessionKind::Static, format!("static as asked: {seen}")),
        SessionKind::MultiPosition => (SessionKind::MultiPosition, format!("multi-position as asked: {seen}")),
        SessionKind::Auto if s.is_static() => (SessionKind::Static, format!("at rest throughout ({seen}): static")),
        SessionKind::Auto if s.orientations >= 2 && s.initial_rest_s().is_some() => {
            (SessionKind::MultiPosition, format!("rests and motions ({seen}): multi-position"))
        }
        SessionKind::Auto => (
            SessionKind::MultiPosition,
            format!("neither at rest nor rests in several orientations from an initial rest ({seen}): written as multi-position, which a fit may refuse; cut a rest with --from/--to for noise"),
        ),
    }
}
