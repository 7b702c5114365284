//! Streaming correction of a recording file: rows are read, corrected with [`Streaming`] and
//! written as they come, a block at a time, so memory stays fixed whatever the length.

use super::{Calibration, CorrectError, Streaming};
use crate::session::sanity::StreamScan;
use crate::session::{recording_header, CsvLine, ReadOptions, Row, RowReader, SessionError};
use crate::units::Units;
use std::io::{Read, Write};
use std::path::Path;

/// Rows corrected per block (the block corrector's batch).
const BLOCK: usize = 1024;

/// Output scales: each value written is the SI value times its factor.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct OutputScale {
    /// Written time per second.
    pub time: f64,
    /// Written rate per rad/s.
    pub gyro: f64,
    /// Written specific force per m/s².
    pub accel: f64,
}

impl OutputScale {
    /// The factors as [time, gyro, accel] (for [`CsvLine::sample`]).
    pub fn factors(&self) -> [f64; 3] {
        [self.time, self.gyro, self.accel]
    }
}

/// Settings of [`correct_csv_streaming`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StreamCsvOptions {
    /// Output scales.
    pub scale: OutputScale,
    /// A gap in t is an error, not a warning.
    pub strict: bool,
}

/// What a streamed correction did.
#[derive(Debug, Clone, PartialEq)]
pub struct StreamedCsv {
    /// Samples corrected.
    pub samples: usize,
    /// Leading samples corrected before the derivative window was full.
    pub warmup: usize,
    /// Samples with a non-zero `flags` column.
    pub flagged: usize,
    /// Whether the output has a `flags` column (the calibration has nonlinear inverses).
    pub has_flags: bool,
    /// The stamps were shifted by −this (the profile's time delay), s.
    pub time_offset_s: f64,
    /// Gaps, saturation and spikes found on the way (see [`StreamScan`]).
    pub warnings: Vec<String>,
    /// Samples outside the profile's calibrated temperature range.
    pub temp_outside: super::TempOutside,
}

/// Errors of [`correct_csv_streaming`].
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum StreamCsvError {
    /// The recording could not be read (names file, line and column).
    #[error(transparent)]
    Read(#[from] SessionError),
    /// The calibration cannot correct this recording.
    #[error(transparent)]
    Correct(#[from] CorrectError),
    /// The output could not be written.
    #[error("writing the output")]
    Write(#[from] std::io::Error),
    /// A row's correction is not finite: refused rather than written.
    #[error("{path}:{line}: the corrected values of this row are not finite (inputs too large for the calibration?); nothing is written")]
    NonFinite {
        /// The recording.
        path: std::path::PathBuf,
        /// Line of the row.
        line: u64,
    },
}

/// Corrects the recording `input` (named `path` in messages) into `out` as CSV, in the
/// same columns as read (`t,gx,gy,gz,ax,ay,az[,temp]`, plus `flags` when the calibration
/// has nonlinear inverses), scaled by `opts.scale`. The values
/// are those of [`super::correct_streaming`] on the whole record, bit for bit.
pub fn correct_csv_streaming(
    path: &Path,
    input: impl Read,
    out: &mut impl Write,
    cal: &Calibration,
    units: &Units,
    g_m_s2: f64,
    opts: StreamCsvOptions,
) -> Result<StreamedCsv, StreamCsvError> {
    let StreamCsvOptions { scale, strict } = opts;
    let mut rdr = RowReader::new(path, input, units, g_m_s2, ReadOptions { strict, ..Default::default() })?;
    rdr.stop_hashing();
    let has_temp = rdr.has_temp();
    if let (false, Some(id)) = (has_temp, cal.needs_temperature()) {
        return Err(CorrectError::MissingTemperature(id.to_string()).into());
    }
    let has_flags = !cal.nonlinear.is_empty();
    let per_sample = has_temp || has_flags;
    let time_offset_s = cal.lag_s();
    let mut corrector = Streaming::new(cal.clone());
    writeln!(out, "{}", recording_header(has_temp, has_flags))?;
    let mut scan = StreamScan::new(units.time.to_s());
    let (mut t, mut gyro, mut accel, mut temp) =
        (Vec::with_capacity(BLOCK), Vec::with_capacity(BLOCK), Vec::with_capacity(BLOCK), Vec::with_capacity(BLOCK));
    let mut lines: Vec<u64> = Vec::with_capacity(BLOCK);
    let (mut w_out, mut a_out, mut flags) = (vec![[0.0; 3]; BLOCK], vec![[0.0; 3]; BLOCK], vec![0u8; BLOCK]);
    let mut line = CsvLine::new();
    let mut row = Row::default();
    let (mut samples, mut flagged) = (0usize, 0usize);
    loop {
        t.clear();
        gyro.clear();
        accel.clear();
        temp.clear();
        lines.clear();
        while t.len() < BLOCK && rdr.read_row(&mut row)? {
            lines.push(rdr.line());
            if let Some(gap) = scan.push(rdr.line(), row.t_s, row.gyro, row.accel).filter(|_| strict) {
                return Err(gap.to_error(path, rdr.t_column()).into());
            }
            t.push(row.t_s);
            gyro.push(row.gyro);
            accel.push(row.accel);
            temp.push(row.temp_c);
        }
        let n = t.len();
        if per_sample {
            for k in 0..n {
                (w_out[k], a_out[k]) = corrector.push(t[k], gyro[k], accel[k], temp[k]);
                flags[k] = corrector.last_flags();
            }
            super::refuse_outside(corrector.temperature_outside())?;
        } else {
            corrector.push_block(&t, &gyro, &accel, &mut w_out, &mut a_out);
        }
        for k in 0..n {
            if !w_out[k].iter().chain(&a_out[k]).all(|v| v.is_finite()) {
                return Err(StreamCsvError::NonFinite { path: path.to_path_buf(), line: lines[k] });
            }
            let (temp, flag) = (has_temp.then_some(temp[k]), has_flags.then_some(flags[k]));
            line.sample(t[k] - time_offset_s, w_out[k], a_out[k], scale.factors(), temp, flag).write_to(out)?;
            flagged += usize::from(flag.unwrap_or(0) != 0);
        }
        samples += n;
        if n < BLOCK {
            break;
        }
    }
    if samples == 0 {
        return Err(rdr.no_samples().into());
    }
    let (gaps, warnings) = scan.finish(&path.display().to_string());
    // A record shorter than the scan's reference has its steps judged only now.
    if let Some(gap) = gaps.first().filter(|_| strict) {
        return Err(gap.to_error(path, rdr.t_column()).into());
    }
    Ok(StreamedCsv {
        samples,
        warmup: corrector.warmup_samples().min(samples),
        flagged,
        has_flags,
        time_offset_s,
        warnings,
        temp_outside: *corrector.temperature_outside(),
    })
}
