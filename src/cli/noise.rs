//! `crosscal noise`: Allan deviation and noise terms of a static recording.

use super::Outcome;
use crate::errln;
use crate::{out, outln};
use anyhow::Context;
use crosscal::noise::deviations::Deviation;
use crosscal::noise::{analyse, read_channels, report, NoiseOptions, NoiseReport, Span, CHANNELS};
use crosscal::profile::{latest, save};
use crosscal::session::{read_manifest, MotionSpec};
use crosscal::units::{AccelUnit, GyroUnit, Units};
use std::path::PathBuf;

/// Options of `noise`.
#[derive(Debug, Clone, clap::Args)]
pub struct Args {
    /// A session manifest (its static run, or the run given by --run) or a plain CSV
    /// (t,gx,gy,gz,ax,ay,az); with --lot, a folder of units (`DIR/<unit>/session.json`).
    pub(super) recording: PathBuf,
    /// The recording is a lot: every sub-folder holding a session.json is a unit; prints each
    /// unit's terms, their spread over the lot and (with --rules) each unit's verdict.
    #[arg(long)]
    pub(super) lot: bool,
    /// Acceptance rules whose `noise` rules are applied to each unit of --lot (exit 1 when a
    /// unit fails).
    #[arg(long, requires = "lot")]
    pub(super) rules: Option<PathBuf>,
    /// Run of the session to analyse (default: its first static run).
    #[arg(long)]
    run: Option<String>,
    /// Channels to analyse, comma-separated (default: all six).
    #[arg(long, value_delimiter = ',', default_value = "gx,gy,gz,ax,ay,az")]
    channels: Vec<String>,
    /// Gyro unit of a plain CSV: deg/s, rad/s.
    #[arg(long, default_value = "deg/s")]
    gyro_unit: String,
    /// Accelerometer unit of a plain CSV: g, m/s^2.
    #[arg(long, default_value = "g")]
    accel_unit: String,
    /// Local gravity of a plain CSV, m/s².
    #[arg(long, default_value_t = 9.80665)]
    g: f64,
    /// Largest cluster time, s (default: a third of the recording).
    #[arg(long)]
    max_tau: Option<f64>,
    /// Also compute this deviation, with its 68 % intervals: `hadamard` (blind to a linear
    /// drift of the rate) or `modified` (modified Allan: tells white from flicker phase
    /// noise). The noise terms are still read off the Allan deviation.
    #[arg(long, value_enum, default_value = "allan")]
    deviation: DeviationArg,
    /// Print the result as JSON.
    #[arg(long)]
    json: bool,
    /// Write a self-contained HTML report with the Allan deviation plots.
    #[arg(long)]
    report: Option<PathBuf>,
    /// Write the Allan deviation plots as SVG files into this folder (`gx-adev.svg`, …).
    #[arg(long)]
    figures: Option<PathBuf>,
    /// Write the result to this file: crosscal's JSON (for `fit --noise`), or with --to the
    /// noise parameters an estimator reads.
    #[arg(long)]
    save: Option<PathBuf>,
    /// Replace output files (--report, --figures, --save) that already exist (never a
    /// device, FIFO or folder).
    #[arg(long)]
    force: bool,
    /// Format of --save: crosscal (JSON), kalibr (imu.yaml), openvins (kalibr_imu_chain.yaml),
    /// vins-fusion or orb-slam3; continuous-time SI densities, worst axis.
    #[arg(long, default_value = "crosscal", requires = "save")]
    to: String,
    /// The IMU rate written into kalibr, openvins and orb-slam3 files, Hz (default: the recording's).
    #[arg(long)]
    rate_hz: Option<f64>,
    /// Add the result to the unit's latest profile in this store as a new revision.
    #[arg(long)]
    store: Option<PathBuf>,
    /// Characterise the noise of the corrected outputs: the profile (a file or a unit's folder
    /// of the store) is applied to the recording first, and the report says so.
    #[arg(long, conflicts_with = "lot")]
    profile: Option<PathBuf>,
    /// Serial of the unit (a plain CSV has none; a session's manifest gives it).
    #[arg(long)]
    serial: Option<String>,
}

/// `--deviation`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
enum DeviationArg {
    /// The Allan deviation only.
    Allan,
    /// The overlapping Hadamard deviation beside it.
    Hadamard,
    /// The modified Allan deviation beside it.
    Modified,
}

impl Args {
    fn options(&self) -> NoiseOptions {
        let deviation = match self.deviation {
            DeviationArg::Allan => Deviation::Allan,
            DeviationArg::Hadamard => Deviation::Hadamard,
            DeviationArg::Modified => Deviation::Modified,
        };
        NoiseOptions { max_tau_s: self.max_tau, deviation }
    }
}

/// What `noise` analyses: the CSV and its part, units, gravity, serial and a label.
struct Source {
    csv: PathBuf,
    span: Span,
    units: Units,
    g: f64,
    serial: Option<String>,
    label: String,
}

/// Reads and analyses the recording `a` names (a session's static run or a plain CSV):
/// the report, the local gravity of its units and the unit's serial when known.
pub(super) fn analyse_one(a: &Args, chans: &[usize]) -> anyhow::Result<(NoiseReport, f64, Option<String>)> {
    let Source { csv, span, units, g, serial, label } = locate(a)?;
    if units.gyro == GyroUnit::Raw || units.accel == AccelUnit::Raw {
        anyhow::bail!("{label}: raw (uncalibrated) units have no physical noise density; record in deg/s and g");
    }
    let Some(path) = &a.profile else {
        let data = read_channels(&csv, &units, g, chans, span).with_context(|| format!("reading {}", csv.display()))?;
        for w in &data.warnings {
            errln!("warning: {w}");
        }
        return Ok((analyse(&label, data, a.options())?, g, serial));
    };
    // Corrected outputs: all six channels are read (the correction couples them), corrected
    // offline on the recording's own sample interval, then the chosen ones analysed.
    let profile = super::read_profile(path)?;
    let cal = crosscal::correct::Calibration::from_profile(&profile)?;
    let mut data = read_channels(&csv, &units, g, &[0, 1, 2, 3, 4, 5], span)
        .with_context(|| format!("reading {}", csv.display()))?;
    for w in &data.warnings {
        errln!("warning: {w}");
    }
    let col = |c: usize| &data.columns[c].1;
    let triad =
        |o: usize| -> Vec<[f64; 3]> { (0..data.n).map(|k| [col(o)[k], col(o + 1)[k], col(o + 2)[k]]).collect() };
    let (gyro, accel) = (triad(0), triad(3));
    let t: Vec<f64> = (0..data.n).map(|k| k as f64 * data.tau0_s).collect();
    let corrected = crosscal::correct::correct_offline(&cal, &t, &gyro, &accel, None)?;
    data.columns = chans
        .iter()
        .map(|&c| {
            let v = if c < 3 { &corrected.w_rad_s } else { &corrected.a_m_s2 };
            (c, v.iter().map(|x| x[c % 3]).collect())
        })
        .collect();
    let label = format!("{label}, corrected with the profile of unit {} ({})", profile.serial, profile.created_utc);
    Ok((analyse(&label, data, a.options())?, g, serial))
}

/// The recording (or the part of a session's run) to analyse.
fn locate(a: &Args) -> anyhow::Result<Source> {
    if a.recording.extension().is_some_and(|x| x == "json") {
        let m = read_manifest(&a.recording)?;
        let run = match &a.run {
            Some(name) => m
                .runs
                .iter()
                .find(|r| &r.name == name)
                .ok_or_else(|| anyhow::anyhow!("--run {name}: no such run in {}", a.recording.display()))?,
            None => m
                .runs
                .iter()
                .find(|r| matches!(r.motion, MotionSpec::Static { .. } | MotionSpec::StaticUnknown))
                .or_else(|| m.runs.iter().find(|r| matches!(r.motion, MotionSpec::MultiPosition { .. })))
                .ok_or_else(|| {
                    anyhow::anyhow!(
                        "{} has no static run: record the unit at rest, or name a run with --run",
                        a.recording.display()
                    )
                })?,
        };
        // A multi-position run is at rest only during its initial rest.
        let first_s = match run.motion {
            MotionSpec::MultiPosition { init_rest_s, .. } => Some(init_rest_s),
            _ => None,
        };
        let what = if first_s.is_some() { " (initial rest)" } else { "" };
        Ok(Source {
            csv: crosscal::session::run_path(&a.recording, run)?,
            span: Span { rows: run.rows, first_s },
            units: m.units,
            g: m.g_m_s2,
            serial: a.serial.clone().or(Some(m.serial)),
            label: format!("{} run {}{what}", a.recording.display(), run.name),
        })
    } else {
        let gyro = GyroUnit::parse(&a.gyro_unit)
            .filter(|u| *u != GyroUnit::Raw)
            .ok_or_else(|| anyhow::anyhow!("--gyro-unit '{}': expected deg/s or rad/s", a.gyro_unit))?;
        let accel = AccelUnit::parse(&a.accel_unit)
            .filter(|u| *u != AccelUnit::Raw)
            .ok_or_else(|| anyhow::anyhow!("--accel-unit '{}': expected g or m/s^2", a.accel_unit))?;
        let units = Units { gyro, accel, ..Units::default() };
        Ok(Source {
            csv: a.recording.clone(),
            span: Span::default(),
            units,
            g: a.g,
            serial: a.serial.clone(),
            label: a.recording.display().to_string(),
        })
    }
}

pub fn run(a: Args) -> anyhow::Result<Outcome> {
    let mut chans = Vec::new();
    for c in &a.channels {
        let k = CHANNELS.iter().position(|n| n == c).ok_or_else(|| {
            anyhow::anyhow!("--channels: unknown channel '{c}'; expected some of {}", CHANNELS.join(","))
        })?;
        chans.push(k);
    }
    if a.lot {
        return super::noise_lot::run(&a, &chans);
    }
    let (r, g, serial) = analyse_one(&a, &chans)?;
    let label = r.source.clone();
    if a.json {
        outln!("{}", serde_json::to_string_pretty(&r)?);
    } else {
        out!("{}", report::table(&r, g));
    }
    if let Some(path) = &a.report {
        let html = report::html(&r, g);
        super::write_output(path, a.force, html.as_bytes())?;
        errln!("report: {}", path.display());
    }
    if let Some(dir) = &a.figures {
        super::write_figures(dir, &report::figures(&r), a.force)?;
    }
    if let Some(path) = &a.save {
        let (text, lost) = if a.to == "crosscal" {
            (serde_json::to_string_pretty(&r)? + "\n", Vec::new())
        } else {
            let rate_hz = a.rate_hz.unwrap_or(1.0 / r.sample_interval_s);
            let p = crosscal::profile::Profile::noise_only(serial.as_deref().unwrap_or("unknown"), g, r.clone());
            let t = super::profile::Target { rate_hz, openvins_model: "kalibr", imu: 1 };
            match a.to.as_str() {
                "kalibr" | "openvins" | "vins-fusion" | "orb-slam3" => super::profile::export_text(&p, &a.to, t)?,
                other => anyhow::bail!("--to {other}: expected crosscal, kalibr, openvins, vins-fusion or orb-slam3"),
            }
        };
        super::write_output(path, a.force, text.as_bytes())?;
        errln!("saved: {} ({})", path.display(), a.to);
        for l in lost {
            errln!("not represented: {l}");
        }
    }
    if let Some(root) = &a.store {
        let serial = serial.ok_or_else(|| anyhow::anyhow!("--store needs --serial for a plain CSV"))?;
        let (from, p) = latest(root, &serial, None)?;
        let mut next = p.revised(format!("noise from {label} added to {}", from.display()));
        next.noise = Some(r);
        let path = save(&next, root)?;
        errln!("profile: {} (previous revision kept: {})", path.display(), from.display());
    }
    Ok(Outcome::Ok)
}
