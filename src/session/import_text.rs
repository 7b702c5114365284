//! Delimited text recordings of any layout: comma, semicolon, tab or space separated, with
//! or without a header, columns named by the header or given in order (`--columns
//! t,gx,gy,gz,ax,ay,az`, `-` for a column to skip), units stated. The delimiter is detected
//! from the first data lines unless given; a header that does not name the needed columns
//! says which delimiter the file seems to use. One run: a multi-position recording (with its
//! initial rest) or a static recording (for `crosscal noise`).

use super::import::{csv_err as err, ImportOptions, Imported};
use super::{MotionSpec, Problem, SessionError};
use crate::units::{TimeUnit, Units};
use std::path::Path;

/// A field separator.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Delimiter {
    /// `,`
    Comma,
    /// `;`
    Semicolon,
    /// A tab.
    Tab,
    /// One or more spaces (and tabs).
    Spaces,
}

impl Delimiter {
    /// Every delimiter, in the order detection prefers them.
    pub const ALL: [Delimiter; 4] = [Delimiter::Tab, Delimiter::Comma, Delimiter::Semicolon, Delimiter::Spaces];

    /// Parses `,`, `;`, `tab`, `space` (or `comma`, `semicolon`, `spaces`).
    pub fn parse(s: &str) -> Option<Self> {
        Some(match s {
            "," | "comma" => Self::Comma,
            ";" | "semicolon" => Self::Semicolon,
            "tab" | "\t" => Self::Tab,
            "space" | "spaces" | " " => Self::Spaces,
            _ => return None,
        })
    }

    /// The fields of a line.
    pub fn split(self, line: &str) -> Vec<&str> {
        match self {
            Self::Comma => line.split(',').map(str::trim).collect(),
            Self::Semicolon => line.split(';').map(str::trim).collect(),
            Self::Tab => line.split('\t').map(str::trim).collect(),
            Self::Spaces => line.split_whitespace().collect(),
        }
    }

    fn name(self) -> &'static str {
        match self {
            Self::Comma => "','",
            Self::Semicolon => "';'",
            Self::Tab => "tab",
            Self::Spaces => "spaces",
        }
    }
}

/// The delimiter that splits every one of `lines` into the same number (≥ 2) of fields,
/// the most fields first; `None` when no delimiter does.
pub fn detect_delimiter(lines: &[&str]) -> Option<(Delimiter, usize)> {
    let mut best: Option<(Delimiter, usize)> = None;
    for d in Delimiter::ALL {
        let counts: Vec<usize> = lines.iter().map(|l| d.split(l).len()).collect();
        let Some(&n) = counts.first() else { continue };
        if n >= 2 && counts.iter().all(|&c| c == n) && best.is_none_or(|(_, m)| n > m) {
            best = Some((d, n));
        }
    }
    best
}

/// What the recording is.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum TextKind {
    /// A hand-held multi-position recording: initial rest, then poses.
    MultiPosition,
    /// A unit at rest throughout (noise characterisation).
    Static,
}

/// How to read a delimited text recording.
#[derive(Debug, Clone, PartialEq)]
pub struct TextLayout {
    /// Column names in file order (`t`, `gx`…`az`, `-` to skip); None: from the header.
    pub columns: Option<Vec<String>>,
    /// Field separator; None: detected.
    pub delimiter: Option<Delimiter>,
    /// Units of the gyro and accelerometer columns (time in seconds).
    pub units: Units,
    /// What the recording is.
    pub kind: TextKind,
}

/// The column names a header may use for each quantity (case-insensitive).
const ALIASES: [(&str, &[&str]); 7] = [
    ("t", &["t", "time", "timestamp", "time_s", "t_s", "sec", "seconds"]),
    ("gx", &["gx", "gyr_x", "gyro_x", "wx", "omega_x", "gyrx", "gyrox"]),
    ("gy", &["gy", "gyr_y", "gyro_y", "wy", "omega_y", "gyry", "gyroy"]),
    ("gz", &["gz", "gyr_z", "gyro_z", "wz", "omega_z", "gyrz", "gyroz"]),
    ("ax", &["ax", "acc_x", "accel_x", "accx", "ax_m_s2"]),
    ("ay", &["ay", "acc_y", "accel_y", "accy", "ay_m_s2"]),
    ("az", &["az", "acc_z", "accel_z", "accz", "az_m_s2"]),
];

fn is_number(s: &str) -> bool {
    s.parse::<f64>().is_ok()
}

/// Index of each of t, gx…az among `names` (t optional).
fn positions(names: &[String]) -> (Option<usize>, Option<[usize; 6]>) {
    let find = |q: &str| {
        let alias = ALIASES.iter().find(|a| a.0 == q).map_or(&[][..], |a| a.1);
        names.iter().position(|n| alias.contains(&n.trim().to_ascii_lowercase().as_str()))
    };
    let six: Vec<Option<usize>> = ["gx", "gy", "gz", "ax", "ay", "az"].iter().map(|q| find(q)).collect();
    let six = six.iter().all(Option::is_some).then(|| {
        let mut a = [0; 6];
        for (k, v) in six.iter().enumerate() {
            a[k] = v.unwrap_or_default();
        }
        a
    });
    (find("t"), six)
}

/// Reads a delimited text recording and writes it as a session (see the module docs).
pub fn text(path: &Path, out_dir: &Path, opts: &ImportOptions, layout: &TextLayout) -> Result<Imported, SessionError> {
    let body =
        crate::atomic::read_text(path).map_err(|source| SessionError::Io { path: path.to_path_buf(), source })?;
    let lines: Vec<(usize, &str)> = body
        .lines()
        .enumerate()
        .map(|(i, l)| (i + 1, l.trim_end_matches('\r')))
        .filter(|(_, l)| !l.trim().is_empty() && !l.trim_start().starts_with('#'))
        .collect();
    let Some(&(first_no, first)) = lines.first() else {
        return Err(err(path, 1, "-", Problem::Empty, "no lines: expected a delimited text recording".into()));
    };
    // Header: a first line with a field that is not a number.
    let detect_on: Vec<&str> = lines.iter().skip(1).take(20).map(|l| l.1).collect();
    let detected = detect_delimiter(if detect_on.is_empty() { std::slice::from_ref(&first) } else { &detect_on });
    let delimiter =
        match (layout.delimiter, detected) {
            (Some(d), _) => d,
            (None, Some((d, _))) => d,
            (None, None) => return Err(err(
                path,
                lines.get(1).map_or(first_no, |l| l.0),
                "-",
                Problem::FieldCount,
                "no delimiter (comma, semicolon, tab, spaces) splits the first lines into the same number of fields"
                    .into(),
            )),
        };
    let first_fields = delimiter.split(first);
    let has_header = first_fields.iter().any(|f| !is_number(f));
    let names: Vec<String> =
        match &layout.columns {
            Some(c) => c.clone(),
            None if has_header => first_fields.iter().map(|s| s.to_string()).collect(),
            None => return Err(err(
                path,
                first_no,
                "-",
                Problem::Header,
                "no header line: give the column order with --columns (e.g. t,gx,gy,gz,ax,ay,az; '-' skips a column)"
                    .into(),
            )),
        };
    let (t_col, six) = positions(&names);
    let Some(six) = six else {
        let hint = detected
            .filter(|(d, n)| *d != delimiter && *n >= 6)
            .map(|(d, n)| format!("; the file seems to use {} as delimiter ({n} fields a line)", d.name()))
            .unwrap_or_default();
        return Err(err(
            path,
            first_no,
            "-",
            Problem::Header,
            format!(
                "the columns [{}] (split by {}) do not name gx, gy, gz, ax, ay, az{hint}",
                names.join(", "),
                delimiter.name()
            ),
        ));
    };
    if t_col.is_none() && opts.rate_hz.is_none_or(|r| !(r > 0.0 && r.is_finite())) {
        return Err(err(path, first_no, "-", Problem::Header, "no time column: give --rate-hz".into()));
    }
    let data = if has_header { &lines[1..] } else { &lines[..] };
    let mut table = super::import::Table { t: Vec::new(), gyro: Vec::new(), accel: Vec::new() };
    for &(no, line) in data {
        let f = delimiter.split(line);
        if f.len() < names.len() {
            return Err(err(
                path,
                no,
                &format!("{}", f.len() + 1),
                Problem::FieldCount,
                format!("{} fields, expected {} ({})", f.len(), names.len(), names.join(",")),
            ));
        }
        let value = |i: usize| -> Result<f64, SessionError> {
            f[i].parse::<f64>().ok().filter(|x| x.is_finite()).ok_or_else(|| {
                err(
                    path,
                    no,
                    &format!("{} ({})", i + 1, names[i]),
                    Problem::Value,
                    format!("'{}' is not a finite number", f[i]),
                )
            })
        };
        let mut v = [0.0; 6];
        for k in 0..6 {
            v[k] = value(six[k])?;
        }
        let t = match t_col {
            Some(c) => value(c)?,
            None => table.t.len() as f64 / opts.rate_hz.unwrap_or(1.0),
        };
        table.t.push(t);
        table.gyro.push([v[0], v[1], v[2]]);
        table.accel.push([v[3], v[4], v[5]]);
    }
    if table.t.is_empty() {
        return Err(err(path, first_no, "-", Problem::Empty, "no samples after the header".into()));
    }
    let motion = match layout.kind {
        TextKind::MultiPosition => MotionSpec::MultiPosition {
            init_rest_s: opts.init_rest_s.unwrap_or(30.0),
            window: 101,
            threshold_multiplier: None,
            min_pose_samples: 100,
            poses: None,
        },
        TextKind::Static => MotionSpec::StaticUnknown,
    };
    let name = match layout.kind {
        TextKind::MultiPosition => "multi-position",
        TextKind::Static => "static",
    };
    let units = Units { time: TimeUnit::S, ..layout.units };
    super::import::write_table(out_dir, units, opts, &table, vec![super::import::run(name, motion, None)])
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn delimiters_are_detected() {
        assert_eq!(detect_delimiter(&["1,2,3", "4,5,6"]), Some((Delimiter::Comma, 3)));
        assert_eq!(detect_delimiter(&["1;2,5;3", "4;5,1;6"]), Some((Delimiter::Semicolon, 3)));
        assert_eq!(detect_delimiter(&["1\t2\t3", "4\t5\t6"]), Some((Delimiter::Tab, 3)));
        assert_eq!(detect_delimiter(&["1  2 3", " 4 5   6"]), Some((Delimiter::Spaces, 3)));
        assert_eq!(detect_delimiter(&["1,2", "1,2,3"]), None);
    }
}
