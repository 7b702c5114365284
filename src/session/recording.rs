//! One run's samples in memory, converted to SI, with the optional columns read.

use crate::frames::{Stand, V3};

/// Stand-supplied reference columns (kind `reference`), converted to SI, in stand axes.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct ReferenceColumns {
    /// True angular rate, rad/s.
    pub w_rad_s: Vec<V3<Stand>>,
    /// True specific force, m/s².
    pub a_m_s2: Vec<V3<Stand>>,
    /// True angular acceleration, rad/s², when the CSV has `ex_ref..ez_ref`.
    pub e_rad_s2: Option<Vec<V3<Stand>>>,
}

impl ReferenceColumns {
    /// Samples `[start, end)`.
    pub(super) fn slice(&self, start: usize, end: usize) -> Self {
        Self {
            w_rad_s: self.w_rad_s[start..end].to_vec(),
            a_m_s2: self.a_m_s2[start..end].to_vec(),
            e_rad_s2: self.e_rad_s2.as_ref().map(|e| e[start..end].to_vec()),
        }
    }
}

/// One run's samples, converted to SI (gyro rad/s, accel m/s²; `raw` kept as recorded).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Recording {
    /// Time stamps, s, strictly increasing.
    pub t_s: super::Column<f64>,
    /// Gyro outputs, sensor frame.
    pub gyro: super::Column<[f64; 3]>,
    /// Accelerometer outputs, sensor frame.
    pub accel: super::Column<[f64; 3]>,
    /// Temperature, °C, when the CSV has a `temp` column.
    pub temp_c: Option<Vec<f64>>,
    /// Reference columns, when requested and present.
    pub reference: Option<ReferenceColumns>,
    /// The stand's logged angle, rad (the run's `angle_column`, recorded in degrees), when
    /// the run names one.
    pub angle_rad: Option<Vec<f64>>,
    /// SHA-256 of the file's bytes, hex.
    pub sha256: String,
    /// Non-fatal findings (gaps in `t`), each naming its line.
    pub warnings: Vec<String>,
}

impl Recording {
    /// The long columns (time, gyro, accelerometer) moved to mapped spill files when they
    /// are on the heap ([`super::Column::spilled`]); a column that cannot be moved stays
    /// where it is (only memory is at stake).
    pub fn spill(&mut self) {
        if let Ok(c) = self.t_s.spilled() {
            self.t_s = c;
        }
        if let Ok(c) = self.gyro.spilled() {
            self.gyro = c;
        }
        if let Ok(c) = self.accel.spilled() {
            self.accel = c;
        }
    }

    /// Number of samples.
    pub fn len(&self) -> usize {
        self.t_s.len()
    }

    /// True when there are no samples.
    pub fn is_empty(&self) -> bool {
        self.t_s.is_empty()
    }

    /// Samples `[start, end)` as a recording of their own (same file hash; warnings kept).
    /// Panics if the range is out of bounds; callers check it against [`Self::len`].
    pub fn slice(&self, start: usize, end: usize) -> Self {
        Self {
            t_s: self.t_s.slice(start, end),
            gyro: self.gyro.slice(start, end),
            accel: self.accel.slice(start, end),
            temp_c: self.temp_c.as_ref().map(|t| t[start..end].to_vec()),
            reference: self.reference.as_ref().map(|r| r.slice(start, end)),
            angle_rad: self.angle_rad.as_ref().map(|a| a[start..end].to_vec()),
            sha256: self.sha256.clone(),
            warnings: self.warnings.clone(),
        }
    }
}
