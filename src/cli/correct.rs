//! `crosscal correct`.

use super::Outcome;
use crate::errln;
use anyhow::Context;
use crosscal::app::arrays::IoUnits;
use crosscal::app::validate::{correct_run, Mode};
use crosscal::correct::{correct_csv_streaming, Calibration, OutputScale, StreamCsvError, StreamCsvOptions};
use crosscal::profile::Profile;
use crosscal::session::{read_recording, recording_header, CsvLine, MotionSpec, ReadOptions, Run, RunSpec};
use crosscal::units::Units;
use std::io::Write;
use std::path::PathBuf;

/// Correction mode on the command line.
#[derive(Debug, Clone, Copy, clap::ValueEnum)]
pub enum ModeArg {
    /// Whole record, centred ε derivative, iterated to convergence.
    Offline,
    /// Causal, sample by sample (what runs on the unit).
    Streaming,
}

impl From<ModeArg> for Mode {
    fn from(m: ModeArg) -> Self {
        match m {
            ModeArg::Offline => Mode::Offline,
            ModeArg::Streaming => Mode::Streaming,
        }
    }
}

/// Options of `correct`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Calibration profile (JSON).
    #[arg(long)]
    profile: PathBuf,
    /// Recording to correct (CSV with t,gx,gy,gz,ax,ay,az[,temp]).
    input: PathBuf,
    /// Output CSV (same columns and units as the input).
    #[arg(short, long)]
    output: PathBuf,
    /// Offline (default) or streaming correction.
    #[arg(long, value_enum, default_value = "offline")]
    mode: ModeArg,
    /// Gyro unit of the input when it differs from the profile's sessions: deg/s, rad/s, raw.
    #[arg(long)]
    gyro_unit: Option<String>,
    /// Accelerometer unit of the input: g, m/s^2, raw.
    #[arg(long)]
    accel_unit: Option<String>,
    /// Replace the output file if it exists (atomically).
    #[arg(long)]
    force: bool,
    /// Gaps in t are errors instead of warnings.
    #[arg(long)]
    strict: bool,
    /// With a time delay in the profile: interpolate the output back onto the input's time
    /// stamps (offline only) instead of re-stamping it.
    #[arg(long)]
    resample: bool,
    /// Outside the temperature range the profile was calibrated over: clamp (hold the
    /// temperature terms at the nearest edge; default), extrapolate, or error.
    #[arg(long, default_value = "clamp", value_parser = ["clamp", "extrapolate", "error"])]
    temperature_range: String,
    /// Warn when the profile is older than this many days.
    #[arg(long, default_value_t = 365.0)]
    max_age_days: f64,
}

pub fn run(a: Args) -> anyhow::Result<Outcome> {
    let profile = super::read_profile(&a.profile)?;
    if let Some(age) = profile.age_days(jiff::Timestamp::now()).filter(|d| *d > a.max_age_days) {
        errln!(
            "warning: profile {} is {age:.0} days old (limit {} days): the unit may have drifted; recalibrate or check it with `crosscal profile diff`",
            a.profile.display(),
            a.max_age_days
        );
    }
    let mut cal =
        Calibration::from_profile(&profile).with_context(|| format!("using profile {}", a.profile.display()))?;
    cal.temp_policy = crosscal::correct::TempPolicy::parse(&a.temperature_range).unwrap_or_default();
    let io = IoUnits::for_profile(&profile, a.gyro_unit.as_deref(), a.accel_unit.as_deref())?;
    let (units, out_units, scale) = (io.input, io.output, io.scale());
    if a.output.exists() && !a.force {
        return Err(anyhow::Error::new(std::io::Error::new(
            std::io::ErrorKind::AlreadyExists,
            format!("{} already exists: choose another output or pass --force to replace it", a.output.display()),
        )));
    }
    if a.output.canonicalize().ok().is_some_and(|o| a.input.canonicalize().ok().is_some_and(|i| i == o)) {
        anyhow::bail!("the output {} is the input: crosscal never modifies the data it is given", a.output.display());
    }
    if matches!(a.mode, ModeArg::Streaming) {
        if a.resample {
            anyhow::bail!("--resample needs the whole record: use it with --mode offline");
        }
        return run_streaming(&a, &profile, &cal, &units, out_units, scale);
    }
    let rec =
        read_recording(&a.input, &units, profile.g_m_s2, ReadOptions { strict: a.strict, ..ReadOptions::default() })?;
    for w in &rec.warnings {
        errln!("warning: {w}");
    }
    let run = Run {
        spec: RunSpec::new(a.input.display().to_string(), a.input.display().to_string(), MotionSpec::Reference, None),
        path: a.input.clone(),
        rec,
    };
    let mut corrected = correct_run(&cal, &run, a.mode.into())?;
    if a.resample {
        corrected = crosscal::correct::resample_to_stamps(&corrected, &run.rec.t_s);
    }
    let has_temp = run.rec.temp_c.is_some();
    let has_flags = !corrected.flags.is_empty();
    let offset = corrected.time_offset_s;
    crosscal::atomic::write_atomic(&a.output, a.force, |w| {
        writeln!(w, "{}", recording_header(has_temp, has_flags))?;
        let mut line = CsvLine::new();
        for k in 0..run.rec.len() {
            let temp = run.rec.temp_c.as_ref().map(|t| t[k]);
            let flag = has_flags.then(|| corrected.flags[k]);
            let (t, g, ac) = (run.rec.t_s[k], corrected.w_rad_s[k], corrected.a_m_s2[k]);
            line.sample(t - offset, g, ac, scale.factors(), temp, flag).write_to(w)?;
        }
        Ok(())
    })
    .with_context(|| format!("writing {}", a.output.display()))?;
    if let Some(w) = corrected.temp_outside.warning() {
        errln!("warning: {w}");
    }
    if has_flags {
        let n = corrected.flags.iter().filter(|f| **f != 0).count();
        errln!("note: {n} samples could not be inverted (inside a dead band or past the record's ends after a delay shift): their 'flags' column is non-zero (bits 0-2 gyro x,y,z; 3-5 accel x,y,z) and their values are 0, not estimates");
    }
    if offset != 0.0 {
        errln!(
            "note: the profile has a time delay: the t column is shifted by -{offset} s to the time each sample describes (--resample puts it back on the input stamps)"
        );
    }
    errln!(
        "corrected {} samples ({} mode{}) with profile of unit {} -> {} (gyro {}, accel {})",
        run.rec.len(),
        match a.mode {
            ModeArg::Offline => "offline",
            ModeArg::Streaming => "streaming",
        },
        if corrected.warmup > 0 {
            format!(", first {} samples are derivative warm-up", corrected.warmup)
        } else {
            String::new()
        },
        profile.serial,
        a.output.display(),
        out_units.gyro,
        out_units.accel
    );
    Ok(Outcome::Ok)
}

/// `--mode streaming`: read, correct and write row by row (fixed memory).
fn run_streaming(
    a: &Args,
    profile: &Profile,
    cal: &Calibration,
    units: &Units,
    out_units: Units,
    scale: OutputScale,
) -> anyhow::Result<Outcome> {
    let (input, _) = crosscal::session::open_recording(&a.input)?;
    let opts = StreamCsvOptions { scale, strict: a.strict };
    let mut failed = None;
    let mut done = None;
    let written = crosscal::atomic::write_atomic(&a.output, a.force, |w| {
        match correct_csv_streaming(&a.input, input, w, cal, units, profile.g_m_s2, opts) {
            Ok(s) => {
                done = Some(s);
                Ok(())
            }
            Err(StreamCsvError::Write(e)) => Err(e),
            Err(e) => {
                failed = Some(e);
                Err(std::io::Error::other("the input could not be corrected"))
            }
        }
    });
    // Errors of the input keep their type (exit codes); nothing was written.
    match failed {
        Some(StreamCsvError::Read(e)) => return Err(e.into()),
        Some(StreamCsvError::Correct(e)) => return Err(e.into()),
        Some(e) => return Err(e.into()),
        None => written.with_context(|| format!("writing {}", a.output.display()))?,
    }
    let s = done.ok_or_else(|| anyhow::anyhow!("writing {}: nothing was corrected", a.output.display()))?;
    for w in s.warnings.iter().cloned().chain(s.temp_outside.warning()) {
        errln!("warning: {w}");
    }
    if s.flagged > 0 {
        errln!("note: {} samples could not be inverted (inside a dead band): their 'flags' column is non-zero (bits 0-2 gyro x,y,z; 3-5 accel x,y,z) and their values are 0, not estimates", s.flagged);
    }
    if s.time_offset_s != 0.0 {
        errln!(
            "note: the profile has a time delay: the t column is shifted by -{} s to the time each sample describes",
            s.time_offset_s
        );
    }
    errln!(
        "corrected {} samples (streaming mode, read and written as a stream{}) with profile of unit {} -> {} (gyro {}, accel {})",
        s.samples,
        if s.warmup > 0 { format!(", first {} samples are derivative warm-up", s.warmup) } else { String::new() },
        profile.serial,
        a.output.display(),
        out_units.gyro,
        out_units.accel
    );
    Ok(Outcome::Ok)
}
