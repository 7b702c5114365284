//! Writing recordings: one reused line buffer, each float in its shortest form that reads
//! back to the same bits (`ryu`; integers by `itoa`), so that formatting does not dominate
//! `correct` on CSV.

use std::io::Write;

/// One output line, reused from row to row (no allocation per row once it has grown).
#[derive(Default)]
pub struct CsvLine {
    line: Vec<u8>,
    num: ryu::Buffer,
    int: itoa::Buffer,
}

impl CsvLine {
    /// An empty line.
    pub fn new() -> Self {
        Self::default()
    }

    fn comma(&mut self) {
        if !self.line.is_empty() {
            self.line.push(b',');
        }
    }

    /// Appends a float field: shortest round-trip digits (`1.5`, `2.5e-7`, `NaN`, `inf`).
    pub fn float(&mut self, v: f64) -> &mut Self {
        self.comma();
        self.line.extend_from_slice(self.num.format(v).as_bytes());
        self
    }

    /// Appends an unsigned integer field.
    pub fn uint(&mut self, v: u64) -> &mut Self {
        self.comma();
        self.line.extend_from_slice(self.int.format(v).as_bytes());
        self
    }

    /// Appends one sample's fields: t, gyro x y z, accel x y z, each times its factor in
    /// `scale` = [time, gyro, accel], then the temperature and the flags when given.
    pub fn sample(
        &mut self,
        t: f64,
        gyro: [f64; 3],
        accel: [f64; 3],
        scale: [f64; 3],
        temp: Option<f64>,
        flags: Option<u8>,
    ) -> &mut Self {
        self.float(t * scale[0]);
        for v in gyro {
            self.float(v * scale[1]);
        }
        for v in accel {
            self.float(v * scale[2]);
        }
        if let Some(t) = temp {
            self.float(t);
        }
        if let Some(f) = flags {
            self.uint(f.into());
        }
        self
    }

    /// Writes the line and a `\n`, and empties it for the next row.
    pub fn write_to(&mut self, w: &mut impl Write) -> std::io::Result<()> {
        self.line.push(b'\n');
        let r = w.write_all(&self.line);
        self.line.clear();
        r
    }
}

/// The header of a recording (`t,gx,gy,gz,ax,ay,az`, then `temp` and `flags` when present).
pub fn recording_header(has_temp: bool, has_flags: bool) -> String {
    format!("t,gx,gy,gz,ax,ay,az{}{}", if has_temp { ",temp" } else { "" }, if has_flags { ",flags" } else { "" })
}

/// A recording as CSV text (`t,gx,gy,gz,ax,ay,az[,temp]`), the gyro and accelerometer
/// values multiplied by `scale` = [gyro, accel] (1 for SI).
pub fn recording_csv(
    t_s: &[f64],
    gyro: &[[f64; 3]],
    accel: &[[f64; 3]],
    temp_c: Option<&[f64]>,
    scale: [f64; 2],
) -> Vec<u8> {
    recording_csv_with(t_s, gyro, accel, temp_c, scale, None)
}

/// [`recording_csv`] with one more column at the end, `(name, values)` written as they
/// are (e.g. the stand's logged angle, `theta_deg`).
pub fn recording_csv_with(
    t_s: &[f64],
    gyro: &[[f64; 3]],
    accel: &[[f64; 3]],
    temp_c: Option<&[f64]>,
    scale: [f64; 2],
    extra: Option<(&str, &[f64])>,
) -> Vec<u8> {
    let mut text = Vec::with_capacity(t_s.len() * 128 + 32);
    text.extend_from_slice(recording_header(temp_c.is_some(), false).as_bytes());
    if let Some((name, _)) = extra {
        text.push(b',');
        text.extend_from_slice(name.as_bytes());
    }
    text.push(b'\n');
    let mut line = CsvLine::new();
    for (k, t) in t_s.iter().enumerate() {
        let (g, a) = (gyro.get(k).copied().unwrap_or([f64::NAN; 3]), accel.get(k).copied().unwrap_or([f64::NAN; 3]));
        let temp = temp_c.map(|tc| tc.get(k).copied().unwrap_or(f64::NAN));
        line.sample(*t, g, a, [1.0, scale[0], scale[1]], temp, None);
        if let Some((_, v)) = extra {
            line.float(v.get(k).copied().unwrap_or(f64::NAN));
        }
        // Writing to memory cannot fail.
        let _ = line.write_to(&mut text);
    }
    text
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fields_read_back_to_the_same_bits() {
        let values =
            [0.0, -0.0, 1.0, 0.01, 1.736_052_045_078_272_8, -2.241_774_539_677_791_7e-5, 1e300, 5e-324, f64::NAN];
        let mut line = CsvLine::new();
        for v in values {
            line.float(v);
        }
        line.uint(0).uint(63).uint(u64::MAX);
        let mut out = Vec::new();
        line.write_to(&mut out).unwrap();
        line.float(2.5).write_to(&mut out).unwrap();
        let text = String::from_utf8(out).unwrap();
        let mut lines = text.lines();
        let fields: Vec<&str> = lines.next().unwrap().split(',').collect();
        assert_eq!(fields.len(), values.len() + 3);
        for (f, v) in fields.iter().zip(values) {
            let back: f64 = f.parse().unwrap();
            assert!(back.to_bits() == v.to_bits() || (v.is_nan() && back.is_nan()), "{f} vs {v:e}");
        }
        assert_eq!(&fields[values.len()..], ["0", "63", "18446744073709551615"]);
        assert_eq!(lines.next(), Some("2.5"));
    }
}
