//! `crosscal import`: recordings laid out for other tools → crosscal sessions.

use super::Outcome;
use crate::outln;
use anyhow::Context;
use crosscal::session::import::{imu_tk, imucal_annotated, imucal_ferraris, tedaldi_csv, ImportOptions, Imported};
use crosscal::session::import_text::{text, Delimiter, TextKind, TextLayout};
use crosscal::units::{AccelUnit, GyroUnit, Units};
use std::path::PathBuf;

/// Options of `import`.
#[derive(Debug, clap::Args)]
#[command(args_conflicts_with_subcommands = true, subcommand_negates_reqs = true)]
pub struct Args {
    #[command(subcommand)]
    layout: Option<Layout>,
    /// A log or bag: ROS 1 bag, ROS 2 bag (its folder, or a .db3/.mcap), PX4 ULog (.ulg) or
    /// ArduPilot DataFlash (.bin); the format is read from the content.
    file: Option<PathBuf>,
    /// List the IMU streams the file holds (samples, rate, span, temperature) and stop.
    #[arg(long)]
    list: bool,
    /// The stream to import: a ROS topic, or a stream name as --list shows it.
    #[arg(long)]
    topic: Option<String>,
    /// The IMU instance to import (PX4 multi_id, ArduPilot IMU number from 0).
    #[arg(long)]
    imu: Option<u32>,
    /// Keep samples from this time on, s after the stream's first sample.
    #[arg(long)]
    from: Option<f64>,
    /// Keep samples up to this time, s after the stream's first sample.
    #[arg(long)]
    to: Option<f64>,
    /// Session kind: auto (static when at rest throughout, else multi-position), static or multi-position.
    #[arg(long, default_value = "auto", value_parser = ["auto", "static", "multi-position"])]
    kind: String,
    /// Definition of a ROS message type the bag does not carry: TYPE=FILE.msg (or FILE.msg
    /// for every undefined type); MSG: sections in the file give the types it uses.
    #[arg(long = "msg-def")]
    msg_def: Vec<String>,
    /// Folder to write session.json and recording.csv into (must not hold them already).
    #[arg(long, global = true, default_value = "imported-session")]
    out: PathBuf,
    /// Serial number of the unit.
    #[arg(long, global = true, default_value = "imported", value_parser = super::parse_serial)]
    serial: String,
    /// Local gravity, m/s² (imucal's default 9.81; imu_tk's example 9.81744).
    #[arg(long, global = true)]
    g: Option<f64>,
}

#[derive(Debug, clap::Subcommand)]
enum Layout {
    /// imucal's example: CSV `n_samples,gyr_*,acc_*` (deg/s, m/s²) and, optionally, its section list.
    #[command(
        after_help = "Example: crosscal import imucal-ferraris session.csv sections.json --rate-hz 102.4 --out ferraris/"
    )]
    ImucalFerraris {
        /// The recording.
        csv: PathBuf,
        /// The section list ({"x_p": {"start":…, "end":…}, …}); without it the faces and
        /// turns are found from the data (each turn's sign from its gyro integral).
        sections: Option<PathBuf>,
        /// Sample rate, Hz.
        #[arg(long)]
        rate_hz: f64,
        /// Total angle of each turn, degrees (negative = clockwise about +axis; imucal's default).
        #[arg(long, default_value_t = -360.0, allow_hyphen_values = true)]
        turn_angle_deg: f64,
    },
    /// imucal's annotated session: CSV with `part`, `samples` and raw `acc_*`, `gyr_*`.
    #[command(
        after_help = "Example: crosscal import imucal-annotated annotated.csv --rate-hz 204.8 --turn-angle-deg 360 --out ann/"
    )]
    ImucalAnnotated {
        /// The recording.
        csv: PathBuf,
        /// Sample rate, Hz.
        #[arg(long)]
        rate_hz: f64,
        /// Total angle of each turn, degrees.
        #[arg(long, default_value_t = -360.0, allow_hyphen_values = true)]
        turn_angle_deg: f64,
    },
    /// imu_tk: accelerometer and gyro files of `t x y z` rows (multi-position protocol).
    #[command(after_help = "Example: crosscal import imu-tk acc.mat gyro.mat --init-rest-s 50 --g 9.81744 --out tk/")]
    ImuTk {
        /// Accelerometer file.
        acc: PathBuf,
        /// Gyro file.
        gyro: PathBuf,
        /// Initial rest, s.
        #[arg(long, default_value_t = 50.0)]
        init_rest_s: f64,
    },
    /// `Fs,…` header lines then `ax,ay,az,gx,gy,gz` raw counts (multi-position protocol).
    #[command(after_help = "Example: crosscal import tedaldi mpu.csv --out mpu/")]
    Tedaldi {
        /// The recording.
        csv: PathBuf,
        /// Static intervals to use instead of detecting them (two rows: starts, ends).
        #[arg(long)]
        intervals: Option<PathBuf>,
    },
    /// Any delimited text: comma, semicolon, tab or spaces (detected), columns by header or
    /// by --columns, units stated; a multi-position or a static recording.
    #[command(
        after_help = "Example: crosscal import text imu.txt --columns t,gx,gy,gz,ax,ay,az --gyro-unit raw --accel-unit raw --init-rest-s 60 --out board/"
    )]
    Text {
        /// The recording.
        file: PathBuf,
        /// Column order when the file has no header (or to override it): names from t, gx, gy,
        /// gz, ax, ay, az, and '-' for a column to skip, comma-separated.
        #[arg(long, value_delimiter = ',')]
        columns: Option<Vec<String>>,
        /// Field separator: ',', ';', tab or space (default: detected from the first lines).
        #[arg(long, value_parser = parse_delimiter)]
        delimiter: Option<Delimiter>,
        /// Unit of the gyro columns: deg/s, rad/s or raw.
        #[arg(long, default_value = "rad/s", value_parser = parse_gyro_unit)]
        gyro_unit: GyroUnit,
        /// Unit of the accelerometer columns: g, m/s^2 or raw.
        #[arg(long, default_value = "m/s^2", value_parser = parse_accel_unit)]
        accel_unit: AccelUnit,
        /// A static recording (for `crosscal noise`) instead of a multi-position one.
        #[arg(long)]
        r#static: bool,
        /// Initial rest of a multi-position recording, s.
        #[arg(long, default_value_t = 30.0)]
        init_rest_s: f64,
        /// Sample rate, Hz, when the file has no time column.
        #[arg(long)]
        rate_hz: Option<f64>,
    },
}

impl Args {
    fn log_args(&self) -> super::import_log::LogArgs {
        super::import_log::LogArgs {
            list: self.list,
            topic: self.topic.clone(),
            imu: self.imu,
            from: self.from,
            to: self.to,
            kind: self.kind.clone(),
            msg_def: self.msg_def.clone(),
        }
    }
}

fn parse_delimiter(s: &str) -> Result<Delimiter, String> {
    Delimiter::parse(s).ok_or_else(|| format!("'{s}': expected ',', ';', tab or space"))
}

fn parse_gyro_unit(s: &str) -> Result<GyroUnit, String> {
    GyroUnit::parse(s).ok_or_else(|| format!("'{s}': expected deg/s, rad/s or raw"))
}

fn parse_accel_unit(s: &str) -> Result<AccelUnit, String> {
    AccelUnit::parse(s).ok_or_else(|| format!("'{s}': expected g, m/s^2 or raw"))
}

pub fn run(a: Args) -> anyhow::Result<Outcome> {
    let Some(layout) = &a.layout else {
        return super::import_log::run(&a.file, &a.out, &a.serial, a.g, &a.log_args());
    };
    let mut opts = ImportOptions { serial: a.serial.clone(), ..ImportOptions::default() };
    let done: Imported = match layout {
        Layout::ImucalFerraris { csv, sections, rate_hz, turn_angle_deg } => {
            opts.rate_hz = Some(*rate_hz);
            opts.turn_angle_deg = *turn_angle_deg;
            opts.g_m_s2 = a.g.unwrap_or(9.81);
            imucal_ferraris(csv, sections.as_deref(), &a.out, &opts)
        }
        Layout::ImucalAnnotated { csv, rate_hz, turn_angle_deg } => {
            opts.rate_hz = Some(*rate_hz);
            opts.turn_angle_deg = *turn_angle_deg;
            opts.g_m_s2 = a.g.unwrap_or(9.81);
            imucal_annotated(csv, &a.out, &opts)
        }
        Layout::ImuTk { acc, gyro, init_rest_s } => {
            opts.init_rest_s = Some(*init_rest_s);
            opts.g_m_s2 = a.g.unwrap_or(9.81744);
            imu_tk(acc, gyro, &a.out, &opts)
        }
        Layout::Tedaldi { csv, intervals } => {
            opts.g_m_s2 = a.g.unwrap_or(9.80665);
            tedaldi_csv(csv, intervals.as_deref(), &a.out, &opts)
        }
        Layout::Text { file, columns, delimiter, gyro_unit, accel_unit, r#static, init_rest_s, rate_hz } => {
            opts.g_m_s2 = a.g.unwrap_or(9.80665);
            opts.init_rest_s = Some(*init_rest_s);
            opts.rate_hz = *rate_hz;
            let layout = TextLayout {
                columns: columns.clone(),
                delimiter: *delimiter,
                units: Units { gyro: *gyro_unit, accel: *accel_unit, ..Units::default() },
                kind: if *r#static { TextKind::Static } else { TextKind::MultiPosition },
            };
            text(file, &a.out, &opts, &layout)
        }
    }
    .with_context(|| format!("importing into {}", a.out.display()))?;
    outln!(
        "wrote {} ({} runs, {} samples); fit it with: crosscal fit {}",
        done.manifest_path.display(),
        done.runs,
        done.samples,
        done.manifest_path.display()
    );
    Ok(Outcome::Ok)
}
