//! `crosscal import FILE`: a ROS bag, PX4 ULog or ArduPilot DataFlash log listed
//! (`--list`) or written as a session.

use super::Outcome;
use crate::outln;
use anyhow::Context;
use crosscal::session::import::ImportOptions;
use crosscal::session::logs::write::{import_log, Selection, SessionKind};
use crosscal::session::logs::{list, Contents, ReadOptions, StreamStats};
use std::path::{Path, PathBuf};

/// The log options of `import`.
#[derive(Debug, Clone)]
pub struct LogArgs {
    pub list: bool,
    pub topic: Option<String>,
    pub imu: Option<u32>,
    pub from: Option<f64>,
    pub to: Option<f64>,
    pub kind: String,
    pub msg_def: Vec<String>,
}

fn read_options(defs: &[String]) -> ReadOptions {
    let msg_defs = defs
        .iter()
        .map(|d| match d.split_once('=') {
            Some((ty, file)) => (ty.to_string(), PathBuf::from(file)),
            None => (String::new(), PathBuf::from(d)),
        })
        .collect();
    ReadOptions { msg_defs }
}

pub fn run(file: &Option<PathBuf>, out: &Path, serial: &str, g: Option<f64>, a: &LogArgs) -> anyhow::Result<Outcome> {
    let Some(file) = file else {
        anyhow::bail!(
            "import needs a log or bag (crosscal import FILE, or --list FILE) or a layout (imucal-ferraris, imucal-annotated, imu-tk, tedaldi, text); see crosscal import --help"
        );
    };
    let read = read_options(&a.msg_def);
    if a.list {
        let (contents, stats) = list(file, &read).with_context(|| format!("listing {}", file.display()))?;
        print_list(file, &contents, &stats)?;
        return Ok(Outcome::Ok);
    }
    let kind = match a.kind.as_str() {
        "static" => SessionKind::Static,
        "multi-position" => SessionKind::MultiPosition,
        _ => SessionKind::Auto,
    };
    let sel = Selection { topic: a.topic.clone(), imu: a.imu, from_s: a.from, to_s: a.to, kind, read };
    let opts = ImportOptions { serial: serial.to_string(), g_m_s2: g.unwrap_or(9.80665), ..ImportOptions::default() };
    let done = import_log(file, out, &opts, &sel)
        .with_context(|| format!("importing {} into {}", file.display(), out.display()))?;
    outln!("{}: {} {} ({})", file.display(), done.contents.format.name(), done.stream.name, done.stream.message);
    outln!("  axes: {}", done.stream.frame);
    for n in done.contents.notes.iter().chain(done.stream.note.iter()) {
        outln!("  note: {n}");
    }
    if !done.applied.is_empty() {
        let list: Vec<String> = done.applied.iter().map(|(k, v)| format!("{k}={v}")).collect();
        outln!("  already applied by the autopilot: {}", list.join(" "));
    }
    for w in &done.contents.warnings {
        outln!("  warning: {w}");
    }
    if done.dropped_time > 0 {
        outln!("  warning: {} samples whose time stamp did not advance were dropped", done.dropped_time);
    }
    outln!("  {}", done.kind.1);
    let m = done.imported.manifest_path.display();
    let n = done.imported.samples;
    let min = crosscal::noise::MIN_SAMPLES;
    if done.kind.0 == SessionKind::Static && n < min {
        // Suggest only what will work: say why the stream is short and what to do instead.
        let st = &done.stats;
        outln!(
            "wrote {m} ({n} samples): too few for crosscal noise, which needs at least {min} (hours of rest for useful numbers); {} holds {} samples at {:.3} Hz over {:.2} s. Import a longer or faster stream (crosscal import --list {} shows each stream's rate and span) or record longer",
            done.stream.name,
            st.samples,
            st.rate_hz(),
            st.span_s(),
            file.display()
        );
    } else {
        let next = if done.kind.0 == SessionKind::Static { "noise" } else { "fit" };
        outln!("wrote {m} ({n} samples); next: crosscal {next} {m}");
    }
    Ok(Outcome::Ok)
}

fn print_list(file: &Path, c: &Contents, stats: &[StreamStats]) -> anyhow::Result<()> {
    outln!("{}: {}, {} IMU stream(s)", file.display(), c.format.name(), c.streams.len());
    outln!(
        "{:<26} {:<30} {:>9} {:>9} {:>9} {:>16}  first sample: gyro rad/s | accel m/s^2",
        "stream",
        "message",
        "samples",
        "rate Hz",
        "span s",
        "temp degC"
    );
    for (s, st) in c.streams.iter().zip(stats) {
        let temp = st.temp_c.map_or("-".to_string(), |[lo, hi]| format!("{lo:.1}..{hi:.1}"));
        let f = &st.first;
        let v = |x: [f64; 3]| {
            if x.iter().all(|v| v.is_nan()) {
                "-".to_string()
            } else {
                format!("{:+.5} {:+.5} {:+.5}", x[0], x[1], x[2])
            }
        };
        outln!(
            "{:<26} {:<30} {:>9} {:>9.1} {:>9.2} {:>16}  {} | {}",
            s.name,
            s.message,
            st.samples,
            st.rate_hz(),
            st.span_s(),
            temp,
            v(f.gyro_rad_s),
            v(f.accel_m_s2)
        );
        if st.gaps.0 > 0 {
            outln!("{:<26} {} gap(s) over 5 sample intervals, {:.3} s lost", "", st.gaps.0, st.gaps.1);
        }
    }
    if let Some(s) = c.streams.first() {
        outln!("axes: {}", s.frame);
    }
    for s in &c.streams {
        if let Some(n) = &s.note {
            outln!("{}: {n}", s.name);
        }
    }
    for n in &c.notes {
        outln!("note: {n}");
    }
    if !c.applied.is_empty() {
        let list: Vec<String> = c.applied.iter().map(|(k, v)| format!("{k}={v}")).collect();
        outln!("calibration already applied by the autopilot: {}", list.join(" "));
    }
    for w in &c.warnings {
        outln!("warning: {w}");
    }
    Ok(())
}
