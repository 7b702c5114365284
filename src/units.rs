//! Leaf layer: the two sensor triads and the units of their channels, with the conversions
//! to the SI units used inside crosscal (rad/s, rad/s², m/s², s). `raw` channels are kept
//! as recorded: the fitted scale then carries the unit.
//!
//! Nothing here knows about files or models; every other module may use it.

use serde::{Deserialize, Serialize};
use std::fmt;

/// Unit of the gyro columns.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum GyroUnit {
    /// Degrees per second.
    #[serde(rename = "deg/s")]
    DegPerS,
    /// Radians per second.
    #[serde(rename = "rad/s")]
    RadPerS,
    /// Counts or volts; not converted.
    #[serde(rename = "raw")]
    Raw,
}

/// Unit of the accelerometer columns.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum AccelUnit {
    /// Standard gravities, converted with the stand's local `g`.
    #[serde(rename = "g")]
    G,
    /// Metres per second squared.
    #[serde(rename = "m/s^2")]
    MPerS2,
    /// Counts or volts; not converted.
    #[serde(rename = "raw")]
    Raw,
}

/// Unit of the time column.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum TimeUnit {
    /// Seconds.
    #[serde(rename = "s")]
    S,
    /// Milliseconds.
    #[serde(rename = "ms")]
    Ms,
}

/// The units a session (or a CSV to correct) is recorded in.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct Units {
    /// Gyro columns.
    pub gyro: GyroUnit,
    /// Accelerometer columns.
    pub accel: AccelUnit,
    /// Time column.
    pub time: TimeUnit,
}

impl Default for Units {
    fn default() -> Self {
        Self { gyro: GyroUnit::DegPerS, accel: AccelUnit::G, time: TimeUnit::S }
    }
}

impl GyroUnit {
    /// Accepted spellings, for error messages.
    pub const CHOICES: &'static str = "deg/s, rad/s, raw";

    /// Parses a unit name.
    pub fn parse(s: &str) -> Option<Self> {
        match s.trim() {
            "deg/s" => Some(Self::DegPerS),
            "rad/s" => Some(Self::RadPerS),
            "raw" => Some(Self::Raw),
            _ => None,
        }
    }

    /// Multiply a recorded value by this to get rad/s (1 for raw).
    pub fn to_rad_s(self) -> f64 {
        match self {
            Self::DegPerS => std::f64::consts::PI / 180.0,
            Self::RadPerS | Self::Raw => 1.0,
        }
    }
}

impl AccelUnit {
    /// Accepted spellings, for error messages.
    pub const CHOICES: &'static str = "g, m/s^2, raw";

    /// Parses a unit name.
    pub fn parse(s: &str) -> Option<Self> {
        match s.trim() {
            "g" => Some(Self::G),
            "m/s^2" | "m/s2" => Some(Self::MPerS2),
            "raw" => Some(Self::Raw),
            _ => None,
        }
    }

    /// Multiply a recorded value by this to get m/s² (1 for raw).
    pub fn to_m_s2(self, g_m_s2: f64) -> f64 {
        match self {
            Self::G => g_m_s2,
            Self::MPerS2 | Self::Raw => 1.0,
        }
    }
}

impl TimeUnit {
    /// Accepted spellings, for error messages.
    pub const CHOICES: &'static str = "s, ms";

    /// Parses a unit name.
    pub fn parse(s: &str) -> Option<Self> {
        match s.trim() {
            "s" => Some(Self::S),
            "ms" => Some(Self::Ms),
            _ => None,
        }
    }

    /// Multiply a recorded value by this to get seconds.
    pub fn to_s(self) -> f64 {
        match self {
            Self::S => 1.0,
            Self::Ms => 1e-3,
        }
    }
}

impl fmt::Display for GyroUnit {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Self::DegPerS => "deg/s",
            Self::RadPerS => "rad/s",
            Self::Raw => "raw",
        })
    }
}

impl fmt::Display for TimeUnit {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Self::S => "s",
            Self::Ms => "ms",
        })
    }
}

impl fmt::Display for AccelUnit {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Self::G => "g",
            Self::MPerS2 => "m/s^2",
            Self::Raw => "raw",
        })
    }
}

/// Which sensor triad an effect, coefficient or channel belongs to.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum SensorKind {
    /// Three-axis rate gyroscope.
    Gyro,
    /// Three-axis accelerometer.
    Accel,
}

impl SensorKind {
    /// Both sensors, gyro first.
    pub const BOTH: [SensorKind; 2] = [SensorKind::Gyro, SensorKind::Accel];

    /// Lower-case name used in coefficient names.
    pub fn as_str(self) -> &'static str {
        match self {
            Self::Gyro => "gyro",
            Self::Accel => "accel",
        }
    }

    /// Unit shown to users and the factor from SI to it: deg/s for the gyro, m/s² for the
    /// accelerometer.
    pub fn display_unit(self) -> (&'static str, f64) {
        match self {
            Self::Gyro => ("deg/s", DEG_PER_RAD),
            Self::Accel => ("m/s^2", 1.0),
        }
    }

    /// 0 for the gyro, 1 for the accelerometer (channels gx..gz are 0..3, ax..az 3..6).
    pub fn index(self) -> usize {
        match self {
            Self::Gyro => 0,
            Self::Accel => 1,
        }
    }

    /// The sensor of channel `c` in 0..6 (gx, gy, gz, ax, ay, az).
    pub fn of_channel(c: usize) -> Self {
        if c < 3 {
            Self::Gyro
        } else {
            Self::Accel
        }
    }

    /// SI unit of the sensor's output.
    pub fn si_unit(self) -> &'static str {
        match self {
            Self::Gyro => "rad/s",
            Self::Accel => "m/s^2",
        }
    }
}

impl fmt::Display for SensorKind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}

/// Axis letters, index 0..3.
pub const AXES: [char; 3] = ['x', 'y', 'z'];

/// The six channel names of a recording, gyro first.
pub const CHANNELS: [&str; 6] = ["gx", "gy", "gz", "ax", "ay", "az"];

/// Degrees per radian (multiply rad/s by this for deg/s).
pub const DEG_PER_RAD: f64 = 180.0 / std::f64::consts::PI;

/// Radians per degree.
pub const RAD_PER_DEG: f64 = std::f64::consts::PI / 180.0;

/// A number for a message: plain for everyday magnitudes, in scientific notation for very
/// large or very small ones (so that `1e200` is not printed as 201 digits).
pub fn show(x: f64) -> String {
    let a = x.abs();
    if a != 0.0 && !(1e-4..1e7).contains(&a) {
        format!("{x:e}")
    } else {
        format!("{x}")
    }
}
