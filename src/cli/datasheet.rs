//! `crosscal datasheet`: a unit's datasheet quantities with their uncertainties.

use super::Outcome;
use crate::{out, outln};
use anyhow::Context;
use std::path::PathBuf;

/// Options of `datasheet`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// The unit's serial.
    unit: String,
    /// Profile store.
    #[arg(long, default_value = "calib-profiles")]
    store: PathBuf,
    /// The profile in force at this time (RFC 3339 or a date; default now).
    #[arg(long)]
    at: Option<String>,
    /// Gyro full scale of the calibration, deg/s (for nonlinearity in ppm of full scale).
    #[arg(long, value_name = "DEG_S")]
    gyro_range: Option<f64>,
    /// Accelerometer full scale of the calibration, g (default 1 g).
    #[arg(long, value_name = "G")]
    accel_range: Option<f64>,
    /// Print the datasheet as JSON.
    #[arg(long)]
    json: bool,
    /// Write the datasheet as an HTML page.
    #[arg(long, value_name = "PAGE.html")]
    report: Option<PathBuf>,
}

pub fn run(a: Args) -> anyhow::Result<Outcome> {
    let opts = crosscal::datasheet::DatasheetOptions {
        gyro_range_rad_s: a.gyro_range.map(f64::to_radians),
        accel_range_m_s2: a.accel_range.map(|g| g * 9.80665),
    };
    let sheet = crosscal::app::datasheet::datasheet(&a.store, &a.unit, a.at.as_deref(), &opts)?;
    if let Some(page) = &a.report {
        let html = crosscal::datasheet::html(&sheet);
        crosscal::atomic::write_atomic(page, true, |w| std::io::Write::write_all(w, html.as_bytes()))
            .with_context(|| format!("writing {}", page.display()))?;
        eprintln!("report: {}", page.display());
    }
    if a.json {
        outln!("{}", serde_json::to_string_pretty(&sheet)?);
    } else {
        out!("{}", crosscal::datasheet::text(&sheet));
    }
    Ok(Outcome::Ok)
}
