//! Reading one recording CSV into SI arrays, without a `String` per field.

use super::column::ColumnBuilder;
use super::error::{Problem, SessionError};
use super::open::open_recording;
use crate::frames::V3;
use crate::units::{AccelUnit, GyroUnit, Units};
use sha2::{Digest, Sha256};
use std::path::{Path, PathBuf};

pub use super::recording::{Recording, ReferenceColumns};

/// Which optional columns to read.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct ReadOptions {
    /// Require `wx_ref..az_ref` (and read `ex_ref..ez_ref` if present).
    pub reference: bool,
    /// Treat gaps in `t` (more than 5 median sample periods) as errors, not warnings.
    pub strict: bool,
    /// Require this column, the stand's measured angle in degrees (a run's `angle_column`).
    pub angle_column: Option<String>,
}

const REQUIRED: [&str; 7] = ["t", "gx", "gy", "gz", "ax", "ay", "az"];
const REF_REQUIRED: [&str; 6] = ["wx_ref", "wy_ref", "wz_ref", "ax_ref", "ay_ref", "az_ref"];
const REF_EPS: [&str; 3] = ["ex_ref", "ey_ref", "ez_ref"];

/// Hex SHA-256 of bytes.
pub fn sha256_hex(bytes: &[u8]) -> String {
    hex(&Sha256::digest(bytes))
}

pub(super) fn hex(digest: &[u8]) -> String {
    let mut s = String::with_capacity(2 * digest.len());
    for b in digest {
        s.push_str(&format!("{b:02x}"));
    }
    s
}

fn csv_err(
    problem: Problem,
    path: &Path,
    line: u64,
    column: impl Into<String>,
    msg: impl Into<String>,
) -> SessionError {
    SessionError::Csv { problem, path: path.to_path_buf(), line, column: column.into(), msg: msg.into() }
}

/// Reads a recording file (plain or gzip). `g_m_s2` converts `g` to m/s².
pub fn read_recording(path: &Path, units: &Units, g_m_s2: f64, opts: ReadOptions) -> Result<Recording, SessionError> {
    let (file, size) = open_recording(path)?;
    // Streamed (the reader buffers it): never held whole. The first million samples' room
    // is reserved from the file's size; beyond that the arrays grow as samples arrive.
    read_stream(path, file, (size / 64).min(1 << 20) as usize, units, g_m_s2, opts)
}

/// One CSV row converted to SI (stand-frame reference columns when requested).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Row {
    /// Time stamp, s.
    pub t_s: f64,
    /// Gyro output, sensor frame.
    pub gyro: [f64; 3],
    /// Accelerometer output, sensor frame.
    pub accel: [f64; 3],
    /// Temperature, °C (NaN without a `temp` column).
    pub temp_c: f64,
    /// Reference angular rate, rad/s (reference columns only).
    pub w_ref: [f64; 3],
    /// Reference specific force, m/s² (reference columns only).
    pub a_ref: [f64; 3],
    /// Reference angular acceleration, rad/s² (when `ex_ref..ez_ref` are present).
    pub e_ref: [f64; 3],
    /// The stand's logged angle, rad (NaN without an angle column).
    pub angle_rad: f64,
}

/// A reader that hashes (SHA-256) every byte it passes on.
struct Hashing<R> {
    inner: R,
    hash: Sha256,
    /// A byte other than ASCII whitespace has passed.
    nonblank: bool,
    /// Pass bytes on without hashing them.
    skip: bool,
}

impl<R: std::io::Read> std::io::Read for Hashing<R> {
    fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        let n = self.inner.read(buf)?;
        if !self.skip {
            self.hash.update(&buf[..n]);
        }
        if !self.nonblank {
            self.nonblank = buf[..n].iter().any(|b| !b.is_ascii_whitespace());
        }
        Ok(n)
    }
}

/// Bytes read from the input at a time (the buffer grows for longer lines).
const LINE_BUFFER: usize = 1 << 18;

/// The longest line a recording may have, bytes: a row of numbers is a few hundred bytes,
/// so a longer line is not a recording (and memory stays bounded whatever the input).
pub const MAX_LINE: usize = 1 << 20;

/// Why the next line could not be had.
#[derive(Debug)]
enum LineError {
    /// The input failed.
    Io(std::io::Error),
    /// Line `0` is longer than [`MAX_LINE`].
    TooLong(u64),
}

impl LineError {
    fn into_session(self, path: &Path) -> SessionError {
        match self {
            Self::Io(source) => SessionError::Io { path: path.to_path_buf(), source },
            Self::TooLong(line) => csv_err(
                Problem::Malformed,
                path,
                line,
                "-",
                format!("the line is longer than {MAX_LINE} bytes: expected rows of numbers a few hundred bytes long (is this file a recording?)"),
            ),
        }
    }
}

/// The lines of a text, from one reused buffer: `\n`, `\r\n` and a lone `\r` end a line
/// (as for the csv crate); a UTF-8 byte-order mark at the start is skipped.
struct Lines<R> {
    input: Hashing<R>,
    buf: Vec<u8>,
    /// Unread bytes are `buf[start..end]`.
    start: usize,
    end: usize,
    eof: bool,
    /// 1-based number of the next line.
    next_no: u64,
    /// The byte-order mark has not been looked for yet.
    fresh: bool,
}

impl<R: std::io::Read> Lines<R> {
    fn new(input: Hashing<R>) -> Self {
        Self { input, buf: vec![0; LINE_BUFFER], start: 0, end: 0, eof: false, next_no: 1, fresh: true }
    }

    /// Reads more input behind the unread bytes (moved to the front; the buffer doubles when
    /// they fill it).
    fn fill(&mut self) -> std::io::Result<()> {
        if self.start > 0 {
            self.buf.copy_within(self.start..self.end, 0);
            self.end -= self.start;
            self.start = 0;
        }
        if self.end == self.buf.len() {
            self.buf.resize(2 * self.buf.len(), 0);
        }
        loop {
            match std::io::Read::read(&mut self.input, &mut self.buf[self.end..]) {
                Ok(0) => self.eof = true,
                Ok(n) => self.end += n,
                Err(e) if e.kind() == std::io::ErrorKind::Interrupted => continue,
                Err(e) => return Err(e),
            }
            return Ok(());
        }
    }

    /// The next line as a range of [`Self::buf`] (without its terminator) and its number.
    fn next_line(&mut self) -> Result<Option<(std::ops::Range<usize>, u64)>, LineError> {
        loop {
            if self.fresh && (self.end - self.start >= 3 || self.eof) {
                self.fresh = false;
                if self.buf[self.start..self.end].starts_with(b"\xef\xbb\xbf") {
                    self.start += 3;
                }
            }
            if !self.fresh {
                let hay = &self.buf[self.start..self.end];
                if let Some(p) = memchr::memchr2(b'\n', b'\r', hay) {
                    let after = match (hay[p], hay.get(p + 1)) {
                        (b'\r', Some(b'\n')) => Some(p + 2),
                        (b'\r', None) if !self.eof => None,
                        _ => Some(p + 1),
                    };
                    if let Some(after) = after {
                        let line = self.start..self.start + p;
                        self.start += after;
                        self.next_no += 1;
                        return Ok(Some((line, self.next_no - 1)));
                    }
                } else if self.eof {
                    if self.start == self.end {
                        return Ok(None);
                    }
                    let line = self.start..self.end;
                    self.start = self.end;
                    self.next_no += 1;
                    return Ok(Some((line, self.next_no - 1)));
                } else if self.end - self.start > MAX_LINE {
                    return Err(LineError::TooLong(self.next_no));
                }
            }
            self.fill().map_err(LineError::Io)?;
        }
    }
}

/// Slot of a column that is not read.
const SKIP: u8 = u8::MAX;
/// Values a row can have: t, gyro ×3, accel ×3, temp, reference ω ×3, f ×3, ε ×3, the
/// stand's angle.
const SLOTS: usize = 18;

/// The fields of one data line, parsed straight from its bytes into `vals` by slot (see
/// [`RowReader`]); false when the line needs the general path (anything but finite
/// numbers separated by commas, with optional spaces or tabs around them).
#[inline]
fn fast_row(line: &[u8], slots: &[u8], vals: &mut [f64; SLOTS]) -> bool {
    let n = line.len();
    let blank = |i: &mut usize| {
        while *i < n && matches!(line[*i], b' ' | b'\t') {
            *i += 1;
        }
    };
    let mut i = 0;
    for (j, &slot) in slots.iter().enumerate() {
        if slot == SKIP {
            while i < n && line[i] != b',' {
                if line[i] == b'"' {
                    return false;
                }
                i += 1;
            }
        } else {
            blank(&mut i);
            let Some((v, len)) = fast_float2::parse_partial::<f64, _>(&line[i..]).ok().filter(|(v, _)| v.is_finite())
            else {
                return false;
            };
            vals[slot as usize] = v;
            i += len;
            blank(&mut i);
        }
        if j + 1 < slots.len() {
            if i < n && line[i] == b',' {
                i += 1;
            } else {
                return false;
            }
        } else if i < n {
            // More on the line than the header has columns: the general path names it.
            return false;
        }
    }
    true
}

/// A field as an error message shows it: the first 40 characters, then an ellipsis.
fn shown(field: &[u8]) -> String {
    let text = String::from_utf8_lossy(field);
    match text.char_indices().nth(40) {
        Some((at, _)) => format!("{}…", &text[..at]),
        None => text.into_owned(),
    }
}

/// A record of a line holding only spaces (one field, blank): skipped like an empty line.
fn blank_record(rec: &csv::ByteRecord) -> bool {
    rec.len() == 1 && rec.get(0).is_some_and(|f| f.trim_ascii().is_empty())
}

/// Parses one line with the csv crate into `rec`: false for a line with no record.
fn csv_line(line: &[u8], rec: &mut csv::ByteRecord) -> Result<bool, csv::Error> {
    let mut rdr = csv::ReaderBuilder::new().has_headers(false).flexible(true).from_reader(line);
    rdr.read_byte_record(rec)
}

/// The columns a recording's header maps: t, gyro, accel; temperature; reference columns.
struct Columns {
    idx: [usize; 7],
    temp_idx: Option<usize>,
    ref_idx: Option<[usize; 6]>,
    eps_idx: Option<[usize; 3]>,
    angle_idx: Option<usize>,
}

/// The header: the first line that is not blank or a comment (its line and column names).
fn read_header<R: std::io::Read>(
    lines: &mut Lines<R>,
    rec: &mut csv::ByteRecord,
    path: &Path,
) -> Result<(u64, Vec<String>), SessionError> {
    let header_line;
    let mut names: Vec<String> = Vec::new();
    loop {
        let Some((range, no)) = lines.next_line().map_err(|e| e.into_session(path))? else {
            if !lines.input.nonblank {
                return Err(csv_err(
                    Problem::Empty,
                    path,
                    1,
                    "-",
                    "the file is empty: expected a header line 't,gx,gy,gz,ax,ay,az[,temp]' and samples",
                ));
            }
            return Err(csv_err(
                Problem::Header,
                path,
                1,
                "-",
                "no header line found: expected 't,gx,gy,gz,ax,ay,az[,temp]'",
            ));
        };
        let line = &lines.buf[range];
        if line.first() == Some(&b'#') {
            continue;
        }
        if !csv_line(line, rec).map_err(|e| csv_error(path, no, &e))? || blank_record(rec) {
            continue;
        }
        header_line = no;
        for f in rec.iter() {
            names.push(String::from_utf8_lossy(f).trim().to_string());
        }
        break;
    }
    Ok((header_line, names))
}

/// Where the required and optional columns are (errors name the header's line).
fn map_columns(names: &[String], opts: &ReadOptions, path: &Path, header_line: u64) -> Result<Columns, SessionError> {
    let find = |name: &str| names.iter().position(|n| n == name);
    // A column read twice would be ambiguous: which one holds the data?
    for name in REQUIRED.iter().chain(&["temp"]).chain(&REF_REQUIRED).chain(&REF_EPS) {
        let at: Vec<usize> = names.iter().enumerate().filter(|(_, n)| n == name).map(|(i, _)| i + 1).collect();
        if at.len() > 1 {
            let cols: Vec<String> = at.iter().map(|c| c.to_string()).collect();
            return Err(csv_err(
                Problem::Header,
                path,
                header_line,
                format!("{} ({name})", at[1]),
                format!(
                    "column '{name}' appears {} times in the header (columns {}): expected each column once",
                    at.len(),
                    cols.join(", ")
                ),
            ));
        }
    }
    let mut idx = [0usize; 7];
    for (k, name) in REQUIRED.iter().enumerate() {
        idx[k] = find(name).ok_or_else(|| {
                let first_is_number = names.first().is_some_and(|n| n.parse::<f64>().is_ok());
                let one = (names.len() == 1).then(|| names[0].as_str());
                let other = [(';', "semicolons (';')"), ('\t', "tabs"), ('|', "vertical bars ('|')"), (' ', "spaces")]
                    .into_iter()
                    .find(|(c, _)| one.is_some_and(|n| n.contains(*c)));
                let why = if let Some((_, seen)) = other {
                    format!(
                        "required column '{name}' is absent: the header [{}] is separated by {seen}, not commas; crosscal recordings are comma-separated: `crosscal import text {} --out DIR` reads this file (delimiter detected) and writes a session",
                        names.join(","),
                        path.display()
                    )
                } else if first_is_number {
                    format!("the header line is missing (line {header_line} starts with a number); expected a first line 't,gx,gy,gz,ax,ay,az[,temp]'")
                } else {
                    format!(
                        "required column '{name}' is absent: the header has [{}]; expected t,gx,gy,gz,ax,ay,az (any order)",
                        names.join(",")
                    )
                };
                csv_err(Problem::Header, path, header_line, "-", why)
            })?;
    }
    let temp_idx = find("temp");
    let mut ref_idx = None;
    let mut eps_idx: Option<[usize; 3]> = None;
    if opts.reference {
        let mut r = [0usize; 6];
        for (k, name) in REF_REQUIRED.iter().enumerate() {
            r[k] = find(name).ok_or_else(|| {
                    csv_err(Problem::Header,
                        path,
                        header_line,
                        "-",
                        format!(
                            "motion kind 'reference' needs column '{name}': the header has [{}]; expected wx_ref,wy_ref,wz_ref,ax_ref,ay_ref,az_ref",
                            names.join(",")
                        ),
                    )
                })?;
        }
        ref_idx = Some(r);
        let e: Vec<Option<usize>> = REF_EPS.iter().map(|n| find(n)).collect();
        match (e[0], e[1], e[2]) {
            (Some(a), Some(b), Some(c)) => eps_idx = Some([a, b, c]),
            (None, None, None) => {}
            _ => {
                return Err(csv_err(
                    Problem::Header,
                    path,
                    header_line,
                    "-",
                    "give all three of ex_ref,ey_ref,ez_ref or none of them",
                ));
            }
        }
    }
    let angle_idx = match &opts.angle_column {
        Some(name) => Some(find(name).ok_or_else(|| {
            csv_err(
                Problem::Header,
                path,
                header_line,
                "-",
                format!(
                    "the run's angle_column '{name}' (the stand's logged angle, degrees) is absent: the header has [{}]",
                    names.join(",")
                ),
            )
        })?),
        None => None,
    };
    if let Some(k) = angle_idx.filter(|&k| idx.contains(&k) || temp_idx == Some(k)) {
        return Err(csv_err(
            Problem::Header,
            path,
            header_line,
            format!("{} ({})", k + 1, names[k]),
            "the run's angle_column names a column that holds the unit's outputs or temperature: expected a column of its own",
        ));
    }
    Ok(Columns { idx, temp_idx, ref_idx, eps_idx, angle_idx })
}

/// Streams the rows of a recording: one reused buffer, no allocation per row; every row
/// is validated (numbers, finite values, strictly increasing time) with errors naming
/// file, line and column.
///
/// Lines of plain numbers are parsed straight from the buffer, each field by the same
/// correctly rounded parser as the general path (`fast_float2`); any other line (quoted
/// fields, a value that is not a finite number, a short row, time going back) goes through
/// the csv crate and the checks that name the problem, with the same values.
pub struct RowReader<R: std::io::Read> {
    lines: Lines<R>,
    rec: csv::ByteRecord,
    /// A line on the general path, copied out of the buffer.
    scratch: Vec<u8>,
    /// Per column of the header: where its value goes in `vals`, or [`SKIP`].
    slots: Vec<u8>,
    vals: [f64; SLOTS],
    path: PathBuf,
    names: Vec<String>,
    idx: [usize; 7],
    temp_idx: Option<usize>,
    ref_idx: Option<[usize; 6]>,
    eps_idx: Option<[usize; 3]>,
    angle_idx: Option<usize>,
    width: usize,
    header_line: u64,
    factors: [f64; 5],
    last_line: u64,
    last_t: f64,
}

impl<R: std::io::Read> RowReader<R> {
    /// Reads the header of `input` (named `path` in messages) and maps its columns. The
    /// reader buffers `input` itself.
    pub fn new(path: &Path, input: R, units: &Units, g_m_s2: f64, opts: ReadOptions) -> Result<Self, SessionError> {
        let path: PathBuf = path.to_path_buf();
        let mut lines = Lines::new(Hashing { inner: input, hash: Sha256::new(), nonblank: false, skip: false });
        let mut rec = csv::ByteRecord::new();
        let (header_line, names) = read_header(&mut lines, &mut rec, &path)?;
        let Columns { idx, temp_idx, ref_idx, eps_idx, angle_idx } = map_columns(&names, &opts, &path, header_line)?;
        let width = names.len();
        let mut slots = vec![SKIP; width];
        let used = idx.iter().chain(&temp_idx).chain(ref_idx.iter().flatten()).chain(eps_idx.iter().flatten());
        for (slot, &col) in used.enumerate() {
            slots[col] = slot as u8;
        }
        // The angle has the last slot, whatever else is read.
        if let Some(col) = angle_idx {
            slots[col] = (SLOTS - 1) as u8;
        }
        let kg = units.gyro.to_rad_s();
        let ka = units.accel.to_m_s2(g_m_s2);
        // Reference columns of a raw session are read as deg/s and g.
        let kwr = if units.gyro == GyroUnit::Raw { std::f64::consts::PI / 180.0 } else { kg };
        let kar = if units.accel == AccelUnit::Raw { g_m_s2 } else { ka };
        Ok(Self {
            lines,
            rec,
            scratch: Vec::new(),
            slots,
            vals: [0.0; SLOTS],
            path,
            names,
            idx,
            temp_idx,
            ref_idx,
            eps_idx,
            angle_idx,
            width,
            header_line,
            factors: [units.time.to_s(), kg, ka, kwr, kar],
            last_line: header_line,
            last_t: f64::NEG_INFINITY,
        })
    }

    /// Line of the header.
    pub fn header_line(&self) -> u64 {
        self.header_line
    }

    /// The error of a file with a header and no samples (names the header's line).
    pub fn no_samples(&self) -> SessionError {
        csv_err(Problem::Empty, &self.path, self.header_line, "-", "the file has a header but no samples")
    }

    /// Whether the file has a `temp` column.
    pub fn has_temp(&self) -> bool {
        self.temp_idx.is_some()
    }

    /// Whether the file has `ex_ref..ez_ref` (read only with reference columns).
    pub fn has_eps(&self) -> bool {
        self.eps_idx.is_some()
    }

    /// 1-based column of `t`.
    pub fn t_column(&self) -> usize {
        self.idx[0] + 1
    }

    /// Line of the last row read.
    pub fn line(&self) -> u64 {
        self.last_line
    }

    /// Field `k` of the record on the general path.
    #[inline]
    fn field(&self, k: usize, line: u64) -> Result<f64, SessionError> {
        // Trimmed here, per field parsed: trimming whole records in the reader rewrote them.
        let field = self.rec.get(k).unwrap_or(b"").trim_ascii();
        // Straight from the bytes (Eisel–Lemire, as std's parser, without the UTF-8 pass).
        let parsed = fast_float2::parse::<f64, _>(field).ok();
        let column = || format!("{} ({})", k + 1, self.names[k]);
        match parsed {
            Some(v) if v.is_finite() => Ok(v),
            Some(_) if !field.iter().any(u8::is_ascii_digit) => Err(csv_err(
                Problem::Value,
                &self.path,
                line,
                column(),
                format!("expected a finite number, found '{}' (NaN or infinite values are not accepted)", shown(field)),
            )),
            Some(_) => Err(csv_err(
                Problem::Value,
                &self.path,
                line,
                column(),
                format!("expected a finite number, found '{}', which overflows a double (|x| < 1.8e308)", shown(field)),
            )),
            None => Err(csv_err(
                Problem::Value,
                &self.path,
                line,
                column(),
                format!("expected a number, found '{}'", shown(field)),
            )),
        }
    }

    #[inline]
    fn triple(&self, idx: &[usize], k: f64, line: u64) -> Result<[f64; 3], SessionError> {
        Ok([self.field(idx[0], line)? * k, self.field(idx[1], line)? * k, self.field(idx[2], line)? * k])
    }

    /// Reads the next sample into `row`; false at the end of the file.
    pub fn read_row(&mut self, row: &mut Row) -> Result<bool, SessionError> {
        loop {
            let Some((range, line)) = self.lines.next_line().map_err(|e| e.into_session(&self.path))? else {
                return Ok(false);
            };
            let bytes = &self.lines.buf[range];
            if bytes.first() == Some(&b'#') {
                continue;
            }
            self.last_line = line;
            if fast_row(bytes, &self.slots, &mut self.vals) {
                let [kt, kg, ka, kwr, kar] = self.factors;
                let v = &self.vals;
                let t = v[0] * kt;
                if t > self.last_t {
                    self.last_t = t;
                    row.t_s = t;
                    row.gyro = [v[1] * kg, v[2] * kg, v[3] * kg];
                    row.accel = [v[4] * ka, v[5] * ka, v[6] * ka];
                    let mut s = 7;
                    row.temp_c = if self.temp_idx.is_some() {
                        s += 1;
                        v[7]
                    } else {
                        f64::NAN
                    };
                    if self.ref_idx.is_some() {
                        row.w_ref = [v[s] * kwr, v[s + 1] * kwr, v[s + 2] * kwr];
                        row.a_ref = [v[s + 3] * kar, v[s + 4] * kar, v[s + 5] * kar];
                        if self.eps_idx.is_some() {
                            row.e_ref = [v[s + 6] * kwr, v[s + 7] * kwr, v[s + 8] * kwr];
                        }
                    }
                    row.angle_rad = if self.angle_idx.is_some() { v[SLOTS - 1].to_radians() } else { f64::NAN };
                    return Ok(true);
                }
            }
            // The general path, which also names whatever is wrong with the line.
            self.scratch.clear();
            self.scratch.extend_from_slice(bytes);
            if !csv_line(&self.scratch, &mut self.rec).map_err(|e| csv_error(&self.path, line, &e))? {
                continue;
            }
            if self.general_row(line, row)? {
                return Ok(true);
            }
        }
    }

    /// The record in `rec` (line `line`) as a sample; false for a blank line.
    fn general_row(&mut self, line: u64, row: &mut Row) -> Result<bool, SessionError> {
        if blank_record(&self.rec) {
            return Ok(false);
        }
        if self.rec.len() > self.width {
            let n = self.rec.len();
            return Err(csv_err(
                Problem::FieldCount,
                &self.path,
                line,
                format!("{}", self.width + 1),
                format!(
                    "the row has {n} fields, the header has {}: a field too many (a stray comma, or a row of another layout)",
                    self.width
                ),
            ));
        }
        if self.rec.len() < self.width {
            let n = self.rec.len();
            return Err(csv_err(
                Problem::FieldCount,
                &self.path,
                line,
                format!("{} ({})", n + 1, self.names[n]),
                format!("the row has {n} fields, the header has {}: a truncated or incomplete row", self.width),
            ));
        }
        let [kt, kg, ka, kwr, kar] = self.factors;
        let t = self.field(self.idx[0], line)? * kt;
        if t <= self.last_t {
            let what = if t >= self.last_t { "duplicate" } else { "decreasing" };
            return Err(csv_err(
                Problem::Time,
                &self.path,
                line,
                format!("{} (t)", self.idx[0] + 1),
                format!(
                    "{what} time stamp {}: t must be strictly increasing (previous sample had {})",
                    t / kt,
                    self.last_t / kt
                ),
            ));
        }
        self.last_t = t;
        row.t_s = t;
        row.gyro = self.triple(&self.idx[1..4], kg, line)?;
        row.accel = self.triple(&self.idx[4..7], ka, line)?;
        row.temp_c = match self.temp_idx {
            Some(k) => self.field(k, line)?,
            None => f64::NAN,
        };
        if let Some(r) = self.ref_idx {
            row.w_ref = self.triple(&r[0..3], kwr, line)?;
            row.a_ref = self.triple(&r[3..6], kar, line)?;
            if let Some(e) = self.eps_idx {
                row.e_ref = self.triple(&e, kwr, line)?;
            }
        }
        row.angle_rad = match self.angle_idx {
            Some(k) => self.field(k, line)?.to_radians(),
            None => f64::NAN,
        };
        Ok(true)
    }

    /// Stops hashing the bytes still to come (a re-read whose hash is already known).
    pub fn stop_hashing(&mut self) {
        self.lines.input.skip = true;
    }

    /// The SHA-256 (hex) of every byte read so far; of the whole file once it is read.
    pub fn sha256(&self) -> String {
        hex(&self.lines.input.hash.clone().finalize())
    }
}

/// Parses recording bytes (the file name is used in messages only).
pub fn parse_recording(
    path: &Path,
    bytes: &[u8],
    units: &Units,
    g_m_s2: f64,
    opts: ReadOptions,
) -> Result<Recording, SessionError> {
    read_stream(path, bytes, bytes.len() / 64, units, g_m_s2, opts)
}

/// Reads a recording from a stream, checked as it is read (gaps, saturation, spikes: the
/// same [`super::sanity::StreamScan`] as the streamed readers, so that every reader says
/// the same of the same file).
fn read_stream<R: std::io::Read>(
    path: &Path,
    input: R,
    cap: usize,
    units: &Units,
    g_m_s2: f64,
    opts: ReadOptions,
) -> Result<Recording, SessionError> {
    let mut rows = RowReader::new(path, input, units, g_m_s2, opts.clone())?;
    // The long columns go to the heap within the readers' budget, beyond it to a mapped
    // spill file (`super::column`); the optional ones are reserved from the file's size.
    let (mut t_s, mut gyro, mut accel) = (ColumnBuilder::new(), ColumnBuilder::new(), ColumnBuilder::new());
    let mut temp_c = rows.has_temp().then(|| Vec::with_capacity(cap));
    let mut refc =
        opts.reference.then(|| ReferenceColumns { e_rad_s2: rows.has_eps().then(Vec::new), ..Default::default() });
    let mut angle = opts.angle_column.is_some().then(|| Vec::with_capacity(cap));
    let mut scan = super::sanity::StreamScan::new(units.time.to_s());
    let mut row = Row::default();
    while rows.read_row(&mut row)? {
        if let Some(gap) = scan.push(rows.line(), row.t_s, row.gyro, row.accel).filter(|_| opts.strict) {
            return Err(gap.to_error(path, rows.t_column()));
        }
        t_s.push(row.t_s);
        gyro.push(row.gyro);
        accel.push(row.accel);
        if let Some(v) = temp_c.as_mut() {
            v.push(row.temp_c);
        }
        if let Some(v) = angle.as_mut() {
            v.push(row.angle_rad);
        }
        if let Some(r) = refc.as_mut() {
            r.w_rad_s.push(V3::new(row.w_ref));
            r.a_m_s2.push(V3::new(row.a_ref));
            if let Some(ev) = r.e_rad_s2.as_mut() {
                ev.push(V3::new(row.e_ref));
            }
        }
    }
    if t_s.is_empty() {
        return Err(rows.no_samples());
    }
    let spill_err = |e: std::io::Error| SessionError::Io {
        path: path.to_path_buf(),
        source: std::io::Error::new(e.kind(), format!("keeping its samples in a temporary spill file: {e}")),
    };
    let mut out = Recording {
        t_s: t_s.finish().map_err(spill_err)?,
        gyro: gyro.finish().map_err(spill_err)?,
        accel: accel.finish().map_err(spill_err)?,
        // Reserved from the file's size (an over-estimate): give back the rest.
        temp_c: temp_c.map(|mut v| {
            v.shrink_to_fit();
            v
        }),
        ..Default::default()
    };
    out.reference = refc;
    out.angle_rad = angle.map(|mut v| {
        v.shrink_to_fit();
        v
    });
    out.sha256 = rows.sha256();
    let (gaps, warnings) = scan.finish(&path.display().to_string());
    if let Some(gap) = gaps.first().filter(|_| opts.strict) {
        return Err(gap.to_error(path, rows.t_column()));
    }
    out.warnings = warnings;
    Ok(out)
}

/// A csv crate error on line `line` (parsed on its own).
fn csv_error(path: &Path, line: u64, e: &csv::Error) -> SessionError {
    csv_err(Problem::Malformed, path, line, "-", format!("malformed CSV: {e}"))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(text: &str) -> Result<Recording, SessionError> {
        parse_recording(Path::new("run.csv"), text.as_bytes(), &Units::default(), 9.80665, ReadOptions::default())
    }

    #[test]
    fn spaces_around_fields_and_blank_lines_are_accepted() {
        let r = parse(" t , gx,gy ,gz,ax,ay,az\n\n 0 , 1,2 ,3,0,0,1\n   \n0.5,\t4,5,6,0,0,1 \n").unwrap();
        assert_eq!(r.len(), 2);
        assert!((r.gyro[1][0] - 4f64.to_radians()).abs() < 1e-15 && (r.t_s[1] - 0.5).abs() < 1e-15);
        let e = parse("t,gx,gy,gz,ax,ay,az\n0,1, x ,3,0,0,1\n").unwrap_err();
        assert!(e.to_string().contains("found 'x'"), "{e}");
    }

    #[test]
    fn reads_any_column_order_comments_and_blank_lines() {
        let r = parse("# c\ngz,t,gx,gy,ax,ay,az,extra\n\n3,0,1,2,0,0,1,x\n# mid\n6,0.5,4,5,0,0,1,y\n").unwrap();
        assert_eq!(r.len(), 2);
        let k = std::f64::consts::PI / 180.0;
        assert!((r.gyro[1][2] - 6.0 * k).abs() < 1e-15);
        assert!((r.accel[0][2] - 9.80665).abs() < 1e-12);
        assert!((r.t_s[1] - 0.5).abs() < 1e-15);
    }

    #[test]
    fn errors_name_line_and_column() {
        let e = parse("t,gx,gy,gz,ax,ay,az\n0,1,2,3,0,0,1\n0.1,1,abc,3,0,0,1\n").unwrap_err();
        let m = e.to_string();
        assert!(m.contains("run.csv:3:3 (gy)"), "{m}");
        assert!(m.contains("'abc'"), "{m}");
        let e = parse("t,gx,gy,gz,ax,ay,az\n0,1,2,3,0,0,1\n0.1,1,1.5abc,3,0,0,1\n").unwrap_err();
        assert!(e.to_string().contains("'1.5abc'"), "{e}");
        let e = parse("t,gx,gy,gz,ax,ay,az\n0,1,2,3,0,0,1\n0.1,1,NaN,3,0,0,1\n").unwrap_err();
        assert!(e.to_string().contains("finite"), "{e}");
        let e = parse("t,gx,gy,gz,ax,ay,az\n0,1,2,3,0,0,1\n0,1,2,3,0,0,1\n").unwrap_err();
        assert!(e.to_string().contains(":3:1 (t)") && e.to_string().contains("duplicate"), "{e}");
        let e = parse("t,gx,gy,gz,ax,ay\n0,1,2,3,0,0\n").unwrap_err();
        assert!(e.to_string().contains("'az' is absent"), "{e}");
        let e = parse("t,gx,gy,gz,ax,ay,az\n0,1,2,3,0,0,1\n0.1,1,2,3\n").unwrap_err();
        assert!(e.to_string().contains(":3:5 (ax)") && e.to_string().contains("truncated"), "{e}");
        let e = parse("").unwrap_err();
        assert!(e.to_string().contains("empty"), "{e}");
        let e = parse("0,1,2,3,0,0,1\n").unwrap_err();
        assert!(e.to_string().contains("header line is missing"), "{e}");
    }

    #[test]
    fn line_endings_bom_and_quotes_read_like_plain_lines() {
        let plain = parse("t,gx,gy,gz,ax,ay,az\n0,1.25,2,3,0,0,1\n0.5,4,5,6,0,0,1\n").unwrap();
        for text in [
            "\u{feff}t,gx,gy,gz,ax,ay,az\r\n0,1.25,2,3,0,0,1\r\n0.5,4,5,6,0,0,1\r\n",
            "t,gx,gy,gz,ax,ay,az\r0,1.25,2,3,0,0,1\r0.5,4,5,6,0,0,1",
            "\"t\",gx,gy,gz,ax,ay,az\n\"0\",\"1.25\",2,3,0,0,1\n0.5,4,5,6,0,0,\"1\"\n",
        ] {
            let r = parse(text).unwrap();
            assert_eq!((&r.t_s, &r.gyro, &r.accel), (&plain.t_s, &plain.gyro, &plain.accel), "{text:?}");
        }
        // A skipped column may hold quoted text with commas; the line number stays right.
        let r = parse("t,note,gx,gy,gz,ax,ay,az\n0,\"a, b\",1,2,3,0,0,1\n0.5,x,1,2,3,0,0,1\n0.25,y,1,2,3,0,0,1\n");
        let e = r.unwrap_err().to_string();
        assert!(e.contains("run.csv:4:1 (t)") && e.contains("decreasing"), "{e}");
    }

    #[test]
    fn lines_longer_than_the_buffer_and_many_rows_are_read() {
        let pad = "9".repeat(3 * LINE_BUFFER);
        let mut s = format!("t,gx,gy,gz,ax,ay,az,pad\n0,1,2,3,0,0,1,{pad}\n");
        for k in 1..20_000 {
            s.push_str(&format!("{},{},-2.5e-3,3,0,0,1,x\n", k as f64 * 0.01, k as f64 / 7.0));
        }
        let r = parse(&s).unwrap();
        assert_eq!(r.len(), 20_000);
        assert_eq!(
            r.gyro[19_999][0].to_bits(),
            (19_999.0f64 / 7.0).to_string().parse::<f64>().unwrap().to_radians().to_bits()
        );
        assert_eq!(r.gyro[5][1].to_bits(), (-2.5e-3f64).to_radians().to_bits());
        assert_eq!(r.sha256, sha256_hex(s.as_bytes()));
    }

    #[test]
    fn gaps_are_warned() {
        let mut s = String::from("t,gx,gy,gz,ax,ay,az\n");
        for k in 0..20 {
            let t = if k < 10 { k as f64 * 0.01 } else { k as f64 * 0.01 + 1.0 };
            s.push_str(&format!("{t},0,0,0,0,0,1\n"));
        }
        let r = parse(&s).unwrap();
        assert_eq!(r.warnings.len(), 1, "{:?}", r.warnings);
        assert!(r.warnings[0].contains("sample 11"));
    }
}
