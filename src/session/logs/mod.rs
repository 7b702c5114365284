//! Binary logs and bags as users bring them: ROS 1 bags, ROS 2 bags (sqlite3 and MCAP),
//! PX4 ULog and ArduPilot DataFlash, read as streams of IMU samples.
//!
//! Every reader walks its file once, front to back, in memory bounded by one chunk or
//! record, and hands each IMU sample of each stream to a sink ([`Sink`]). A *stream* is one
//! IMU: a ROS topic (all its connections), a ULog `sensor_combined` or one `multi_id` of
//! `sensor_accel` + `sensor_gyro`, a DataFlash `IMU`/`IMU2`/`IMU3` or one instance `I` of
//! `IMU`. Streams are numbered in the order a reader meets them, which is the same on
//! every pass over the same file.
//!
//! | format | reader | crate |
//! |---|---|---|
//! | ROS 1 bag 2.0 | [`ros1`] (records, chunks) | `bzip2`, `lz4_flex` for compressed chunks |
//! | ROS 2 bag, sqlite3 | [`ros2`] | `rusqlite` (bundled SQLite) |
//! | ROS 2 bag / file, MCAP | [`ros2`], [`mcap`] (records, every length checked) | `zstd`, `lz4_flex` for chunks |
//! | message payloads | [`rosmsg`] (ROS 1 and CDR, definitions compiled once) | — |
//! | PX4 ULog | [`ulog`] | — |
//! | ArduPilot DataFlash | [`dataflash`] | — |
//!
//! Why our own readers for ULog, DataFlash, ROS 1 records and CDR: none of the Rust crates
//! for them streams a file in bounded memory *and* handles what real files hold (ULog's
//! appended data and changing field layouts, DataFlash's FMTU multipliers and truncated
//! last records, a ROS 2 type given only by its `.msg` text), and each format is a few
//! hundred lines against its published specification.
//!
//! Units as each format defines them: ROS `sensor_msgs/Imu` in rad/s and m/s² (REP 145:
//! body axes x forward, y left, z up), PX4 and ArduPilot in rad/s and m/s² in their FRD
//! frames. crosscal takes the axes as the sensor's and converts nothing; the session says
//! which convention the file used.

pub mod dataflash;
pub mod mcap;
mod num;
pub mod ros1;
pub mod ros2;
pub mod rosmsg;
pub mod segment;
pub mod stamps;
pub mod ulog;
mod window;
pub mod write;

use super::error::{Problem, SessionError};
use std::path::{Path, PathBuf};

/// The container formats crosscal reads.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LogFormat {
    /// ROS 1 bag, format 2.0.
    Ros1Bag,
    /// ROS 2 bag with sqlite3 storage (a folder with `metadata.yaml`, or one `.db3`).
    Ros2Sqlite,
    /// MCAP (a ROS 2 bag folder with MCAP storage, or one `.mcap`).
    Mcap,
    /// PX4 ULog.
    ULog,
    /// ArduPilot DataFlash `.bin`.
    DataFlash,
}

impl LogFormat {
    /// The format's name as users know it.
    pub fn name(self) -> &'static str {
        match self {
            LogFormat::Ros1Bag => "ROS 1 bag",
            LogFormat::Ros2Sqlite => "ROS 2 bag (sqlite3)",
            LogFormat::Mcap => "MCAP",
            LogFormat::ULog => "PX4 ULog",
            LogFormat::DataFlash => "ArduPilot DataFlash",
        }
    }
}

/// One IMU stream a file holds.
#[derive(Debug, Clone, PartialEq)]
pub struct StreamDesc {
    /// The name to select it by: a topic, `sensor_combined`, `sensor_accel+gyro[1]`, `IMU2`, `IMU[1]`.
    pub name: String,
    /// Message type or log message names.
    pub message: String,
    /// IMU instance number (PX4 `multi_id`, ArduPilot `IMU2` → 1 or the `I` column), when
    /// the format numbers its IMUs.
    pub instance: Option<u32>,
    /// Axis convention, in words.
    pub frame: &'static str,
    /// Whether the stream carries a temperature.
    pub has_temp: bool,
    /// False for a stream of one sensor only (a gyro batch): listed, not importable.
    pub six_axis: bool,
    /// What the format says about the values (already calibrated, raw, …).
    pub note: Option<String>,
}

/// One IMU sample: time stamp (ns, the format's clock), rad/s, m/s², °C.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LogSample {
    /// Time stamp, ns.
    pub t_ns: i64,
    /// Angular rate, rad/s (NaN for an accelerometer-only stream).
    pub gyro_rad_s: [f64; 3],
    /// Specific force, m/s² (NaN for a gyro-only stream).
    pub accel_m_s2: [f64; 3],
    /// Temperature, °C, when reported.
    pub temp_c: Option<f64>,
}

/// What a pass over a file found besides the samples.
#[derive(Debug, Clone, PartialEq)]
pub struct Contents {
    /// The format.
    pub format: LogFormat,
    /// The IMU streams, in the order met.
    pub streams: Vec<StreamDesc>,
    /// Calibration parameters the log says were applied to its values (name, value).
    pub applied: Vec<(String, f64)>,
    /// What a user should know (autopilot calibration applied, definitions guessed …).
    pub notes: Vec<String>,
    /// What was tolerated (a truncated last record, skipped garbage, dropouts), with byte offsets.
    pub warnings: Vec<String>,
    /// Messages or records refused as corrupt (each said in `warnings`, the first
    /// [`MAX_REFUSAL_WARNINGS`] with their byte offsets, then a count).
    pub refused: u64,
}

/// Corrupt messages described one by one in [`Contents::warnings`]; the rest are counted.
pub const MAX_REFUSAL_WARNINGS: u64 = 20;

impl Contents {
    fn new(format: LogFormat) -> Self {
        Self { format, streams: Vec::new(), applied: Vec::new(), notes: Vec::new(), warnings: Vec::new(), refused: 0 }
    }

    /// Records a corrupt message or record that was dropped (not read shifted or guessed).
    pub fn refuse(&mut self, what: String) {
        self.refused += 1;
        if self.refused <= MAX_REFUSAL_WARNINGS {
            self.warnings.push(what + ": dropped");
        }
    }

    /// The closing count of refusals beyond those described.
    fn close_refusals(&mut self) {
        if self.refused > MAX_REFUSAL_WARNINGS {
            self.warnings.push(format!(
                "{} corrupt messages or records were dropped in all ({} described above)",
                self.refused, MAX_REFUSAL_WARNINGS
            ));
        }
    }
}

/// Receives each sample with its stream's index in [`Contents::streams`].
pub type Sink<'a> = dyn FnMut(usize, &LogSample) -> Result<(), SessionError> + 'a;

/// How to read a file.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct ReadOptions {
    /// Message definitions for ROS types the file does not describe: (type, path of its
    /// `.msg` text); an empty type applies to any type the file leaves undefined.
    pub msg_defs: Vec<(String, PathBuf)>,
}

/// The format of `path`, from its content (a folder is a ROS 2 bag).
pub fn detect(path: &Path) -> Result<LogFormat, SessionError> {
    let meta = std::fs::metadata(path).map_err(|source| SessionError::Io { path: path.to_path_buf(), source })?;
    if meta.is_dir() {
        return ros2::folder_format(path);
    }
    let (mut file, _) = super::open::open_regular(path)?;
    let mut head = [0u8; 16];
    let n = read_up_to(&mut file, &mut head).map_err(|source| SessionError::Io { path: path.to_path_buf(), source })?;
    format_of(&head[..n]).ok_or_else(|| {
        SessionError::log(
            Problem::Format,
            path,
            0,
            format!(
                "not a log crosscal reads (first bytes {}): expected a ROS 1 bag (#ROSBAG V2.0), a ROS 2 bag folder or .db3/.mcap file, a PX4 ULog or an ArduPilot DataFlash .bin",
                hex(&head[..n.min(8)])
            ),
        )
    })
}

/// The format announced by a file's first bytes.
pub fn format_of(head: &[u8]) -> Option<LogFormat> {
    if head.starts_with(b"#ROSBAG V2.0") {
        Some(LogFormat::Ros1Bag)
    } else if head.starts_with(b"SQLite format 3\0") {
        Some(LogFormat::Ros2Sqlite)
    } else if head.starts_with(b"\x89MCAP0\r\n") {
        Some(LogFormat::Mcap)
    } else if head.starts_with(b"ULog\x01\x12\x35") {
        Some(LogFormat::ULog)
    } else if head.starts_with(&[0xA3, 0x95]) {
        Some(LogFormat::DataFlash)
    } else {
        None
    }
}

fn hex(b: &[u8]) -> String {
    b.iter().map(|x| format!("{x:02x}")).collect::<Vec<_>>().join(" ")
}

/// Reads until `buf` is full or the input ends; returns the bytes read.
pub(crate) fn read_up_to(r: &mut impl std::io::Read, buf: &mut [u8]) -> std::io::Result<usize> {
    let mut n = 0;
    while n < buf.len() {
        match r.read(&mut buf[n..]) {
            Ok(0) => break,
            Ok(k) => n += k,
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
            Err(e) => return Err(e),
        }
    }
    Ok(n)
}

/// A stream with fewer than 1/this of the samples of the largest one …
const SPORADIC_RATIO: u64 = 100;
/// … and at most this many is called sporadic (a corrupt record, likely).
const SPORADIC_MAX: u64 = 2;

/// Reads every IMU sample of `path` (or of stream `only`) into `sink`.
pub fn read(
    path: &Path,
    opts: &ReadOptions,
    only: Option<usize>,
    sink: &mut Sink<'_>,
) -> Result<Contents, SessionError> {
    let format = detect(path)?;
    let mut deglitch = stamps::Deglitch::default();
    let mut contents = {
        let mut filtered = |i: usize, s: &LogSample| deglitch.push(i, s, sink);
        let filtered: &mut Sink<'_> = &mut filtered;
        match format {
            LogFormat::Ros1Bag => ros1::read(path, opts, only, filtered),
            LogFormat::Ros2Sqlite | LogFormat::Mcap => ros2::read(path, opts, only, filtered),
            LogFormat::ULog => ulog::read(path, only, filtered),
            LogFormat::DataFlash => dataflash::read(path, only, filtered),
        }
    }?;
    deglitch.finish(sink)?;
    contents.close_refusals();
    // A stream of one or two samples beside one of hundreds: a corrupt record (an instance
    // or id field) more likely than a sensor. (Real logs do hold streams of a few samples,
    // logged at a low rate: PX4's sensor_accel/sensor_gyro in some configurations.)
    let seen = deglitch.seen();
    let most = seen.iter().copied().max().unwrap_or(0);
    for (i, &n) in seen.iter().enumerate() {
        if n > 0 && n <= SPORADIC_MAX && most >= 100 && n * SPORADIC_RATIO < most {
            let name = contents.streams.get(i).map_or("?", |s| s.name.as_str());
            contents.warnings.push(format!(
                "{name}: only {n} sample(s) where another stream has {most}: likely a corrupt record (its instance or id field) rather than a sensor"
            ));
        }
    }
    for (i, dropped, seen, first_ns) in deglitch.dropped() {
        let name = contents.streams.get(i).map_or("?", |s| s.name.as_str());
        contents.warnings.push(format!(
            "{name}: {dropped} of {seen} samples had an isolated outlying time stamp (the first {:.3} s) and were dropped; the samples around them were kept",
            first_ns as f64 * 1e-9
        ));
    }
    Ok(contents)
}

/// What `--list` shows of a stream.
#[derive(Debug, Clone, PartialEq)]
pub struct StreamStats {
    /// Samples.
    pub samples: u64,
    /// First and last time stamp, ns.
    pub first_ns: i64,
    /// Last time stamp, ns.
    pub last_ns: i64,
    /// Median sample interval, s (over the first 20 000 intervals).
    pub median_dt_s: f64,
    /// Temperature range, °C, when the stream reports one (all-zero = not reported).
    pub temp_c: Option<[f64; 2]>,
    /// The first sample.
    pub first: LogSample,
    /// Intervals longer than 5 × the median (dropouts), and their total, s.
    pub gaps: (u64, f64),
}

impl StreamStats {
    /// Mean sample rate over the span, Hz.
    pub fn rate_hz(&self) -> f64 {
        if self.median_dt_s > 0.0 {
            1.0 / self.median_dt_s
        } else {
            0.0
        }
    }

    /// Span from the first to the last sample, s.
    pub fn span_s(&self) -> f64 {
        self.last_ns.saturating_sub(self.first_ns) as f64 * 1e-9
    }
}

/// Streams and their statistics (one pass over the file).
pub fn list(path: &Path, opts: &ReadOptions) -> Result<(Contents, Vec<StreamStats>), SessionError> {
    let mut acc: Vec<StatsAcc> = Vec::new();
    let contents = read(path, opts, None, &mut |i, s| {
        if acc.len() <= i {
            acc.resize_with(i + 1, StatsAcc::default);
        }
        acc[i].push(s);
        Ok(())
    })?;
    acc.resize_with(contents.streams.len(), StatsAcc::default);
    let stats = acc.into_iter().map(StatsAcc::finish).collect();
    Ok((contents, stats))
}

#[derive(Default)]
struct StatsAcc {
    n: u64,
    first: Option<LogSample>,
    last_ns: i64,
    dts: Vec<f64>,
    temp: Option<[f64; 2]>,
    any_temp_nonzero: bool,
    big_gaps: Vec<f64>,
    median: Option<f64>,
}

const MEDIAN_WINDOW: usize = 20_000;

impl StatsAcc {
    fn push(&mut self, s: &LogSample) {
        if self.first.is_none() {
            self.first = Some(*s);
        } else {
            let dt = s.t_ns.saturating_sub(self.last_ns) as f64 * 1e-9;
            if self.dts.len() < MEDIAN_WINDOW {
                self.dts.push(dt);
            }
            if self.big_gaps.len() < 1_000_000 {
                self.big_gaps.push(dt);
            }
        }
        self.n += 1;
        self.last_ns = s.t_ns;
        if let Some(t) = s.temp_c {
            self.any_temp_nonzero |= t != 0.0;
            self.temp = crate::stats::widen(self.temp, t);
        }
        // Keep only intervals that may be gaps once the median is known (bounded list).
        if self.dts.len() == MEDIAN_WINDOW && self.big_gaps.len() > 4096 {
            let m = *self.median.get_or_insert_with(|| med(&self.dts));
            self.big_gaps.retain(|&d| d > 5.0 * m);
        }
    }

    fn finish(self) -> StreamStats {
        let median_dt_s = if self.dts.is_empty() { 0.0 } else { med(&self.dts) };
        let gaps: Vec<f64> = self.big_gaps.into_iter().filter(|&d| d > 5.0 * median_dt_s).collect();
        let first = self.first.unwrap_or(LogSample {
            t_ns: 0,
            gyro_rad_s: [f64::NAN; 3],
            accel_m_s2: [f64::NAN; 3],
            temp_c: None,
        });
        StreamStats {
            samples: self.n,
            first_ns: first.t_ns,
            last_ns: self.last_ns,
            median_dt_s,
            temp_c: self.temp.filter(|_| self.any_temp_nonzero),
            first,
            gaps: (gaps.len() as u64, gaps.iter().sum::<f64>() - gaps.len() as f64 * median_dt_s),
        }
    }
}

/// The median of `v` (0 when empty).
fn med(v: &[f64]) -> f64 {
    crate::stats::median(&mut v.to_vec()).unwrap_or(0.0)
}

/// Pairs an accelerometer stream and a gyro stream with their own time stamps into six-axis
/// samples on the gyro's clock: the accelerometer linearly interpolated between the two
/// samples around each gyro time, or the nearest one when within half its interval at the
/// ends. Memory: the gyro samples still waiting for a later accelerometer sample.
#[derive(Debug, Default)]
pub struct Pairer {
    accel: std::collections::VecDeque<(i64, [f64; 3], Option<f64>)>,
    gyro: std::collections::VecDeque<(i64, [f64; 3], Option<f64>)>,
    accel_dt: i64,
    accel_seen: u64,
    /// Gyro samples with no accelerometer sample near their time (dropped).
    unpaired: u64,
    gyro_seen: u64,
}

/// Samples one pairer may hold back before the log is called inconsistent.
const PAIR_BACKLOG: usize = 1 << 20;

impl Pairer {
    /// Adds an accelerometer sample (time ns, m/s², °C).
    pub fn accel(&mut self, t_ns: i64, a: [f64; 3], temp: Option<f64>, out: &mut impl FnMut(LogSample)) {
        if let Some(last) = self.accel.back() {
            self.accel_dt = t_ns.saturating_sub(last.0);
        }
        self.accel_seen += 1;
        self.accel.push_back((t_ns, a, temp));
        self.drain(out, false);
    }

    /// Adds a gyro sample (time ns, rad/s, °C); false when too many wait for an accelerometer.
    pub fn gyro(&mut self, t_ns: i64, g: [f64; 3], temp: Option<f64>, out: &mut impl FnMut(LogSample)) -> bool {
        self.gyro_seen += 1;
        self.gyro.push_back((t_ns, g, temp));
        self.drain(out, false);
        self.gyro.len() < PAIR_BACKLOG
    }

    /// Pairs what is left at the end of the log.
    pub fn finish(&mut self, out: &mut impl FnMut(LogSample)) {
        // At the end every gyro sample is paired or counted as unpaired.
        self.drain(out, true);
    }

    /// Gyro samples dropped so far for want of an accelerometer sample near their time
    /// (a corrupt or missing accelerometer message, or a stamp far off).
    pub fn unpaired(&self) -> u64 {
        self.unpaired
    }

    /// The warning for the samples [`Self::unpaired`] counts, or for accelerometer samples
    /// with no gyro sample at all, if any, for stream `name`.
    pub fn unpaired_warning(&self, name: &str) -> Option<String> {
        if self.gyro_seen == 0 && self.accel_seen > 0 {
            return Some(format!(
                "{name}: {} accelerometer sample(s) and no gyro sample to pair them with (a missing or corrupt gyro message): the stream is empty",
                self.accel_seen
            ));
        }
        (self.unpaired > 0).then(|| {
            format!(
                "{name}: {} gyro sample(s) had no accelerometer sample near their time (a missing or corrupt accelerometer message or time stamp) and are dropped",
                self.unpaired
            )
        })
    }

    fn drain(&mut self, out: &mut impl FnMut(LogSample), end: bool) {
        while let Some(&(t, g, gt)) = self.gyro.front() {
            // Drop accelerometer samples no longer needed (keep the last one at or before t).
            while self.accel.len() >= 2 && self.accel[1].0 <= t {
                self.accel.pop_front();
            }
            let near = |a: i64| a.saturating_sub(t).saturating_abs().saturating_mul(2) <= self.accel_dt.max(0);
            let paired = match (self.accel.front(), self.accel.get(1)) {
                (Some(a0), Some(a1)) if a0.0 <= t => {
                    let w = if a1.0 > a0.0 {
                        t.saturating_sub(a0.0) as f64 / a1.0.saturating_sub(a0.0) as f64
                    } else {
                        0.0
                    };
                    Some((std::array::from_fn(|k| a0.1[k] + w * (a1.1[k] - a0.1[k])), a0.2))
                }
                (Some(a0), _) if t == a0.0 => Some((a0.1, a0.2)),
                (Some(_), _) if self.accel_seen < 2 && !end => return,
                (Some(a0), _) if t < a0.0 => near(a0.0).then_some((a0.1, a0.2)),
                (Some(_), None) if !end => return,
                (Some(a0), None) => near(a0.0).then_some((a0.1, a0.2)),
                (None, _) if !end => return,
                _ => None,
            };
            self.gyro.pop_front();
            match paired {
                Some((acc, at)) => out(LogSample { t_ns: t, gyro_rad_s: g, accel_m_s2: acc, temp_c: gt.or(at) }),
                None => self.unpaired += 1,
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Gyro samples the pairer cannot pair are counted and named, never dropped silently.
    #[test]
    fn unpaired_samples_are_counted() {
        let mut kept = 0usize;
        let mut p = Pairer::default();
        for k in 0..10i64 {
            // Accelerometer samples stop after the fifth; gyro samples go on.
            if k < 5 {
                p.accel(k * 10, [0.0; 3], None, &mut |_| kept += 1);
            }
            p.gyro(k * 10, [0.0; 3], None, &mut |_| kept += 1);
        }
        p.finish(&mut |_| kept += 1);
        assert_eq!(kept as u64 + p.unpaired(), 10);
        assert!(p.unpaired() >= 4, "{}", p.unpaired());
        assert!(p.unpaired_warning("s").is_some_and(|w| w.contains("no accelerometer sample")));
        // Accelerometer samples and no gyro: the stream is empty, and it says so.
        let mut q = Pairer::default();
        q.accel(0, [0.0; 3], None, &mut |_| {});
        q.finish(&mut |_| {});
        assert!(q.unpaired_warning("s").is_some_and(|w| w.contains("no gyro sample")));
        // Intact pairs: nothing to say.
        let mut r = Pairer::default();
        for k in 0..10i64 {
            r.accel(k * 10, [0.0; 3], None, &mut |_| {});
            r.gyro(k * 10, [0.0; 3], None, &mut |_| {});
        }
        r.finish(&mut |_| {});
        assert_eq!(r.unpaired_warning("s"), None);
    }
}
