//! Flight-controller parameter files: ArduPilot's (Mission Planner / MAVProxy `.param`) and
//! PX4's (QGroundControl `.params`), holding the accelerometer offsets and per-axis scales and
//! the gyro offsets those stacks apply.
//!
//! ArduPilot (`AP_InertialSensor_Backend::_rotate_and_correct_accel` / `_gyro`; parameters
//! `INS_ACCOFFS_*` in m/s², `INS_ACCSCAL_*` dimensionless, `INS_GYROFFS_*` in rad/s, with
//! `INS_ACC2*`/`INS_GYR2*` and `INS_ACC3*`/`INS_GYR3*` for the second and third IMU):
//! ```text
//! a = (u − INS_ACCOFFS) ⊙ INS_ACCSCAL,      ω = u − INS_GYROFFS
//! ```
//! per axis, in the sensor frame: after the driver's fixed rotation of the chip onto the
//! board, before `AHRS_ORIENTATION` rotates into the body frame. PX4
//! (`calibration::Accelerometer::Correct`, `calibration::Gyroscope::Correct`) does the same
//! in its sensor frame before the board rotation `SENS_BOARD_ROT`:
//! ```text
//! a = R_board ((u − b_thermal − CAL_ACCn_OFF) ⊙ CAL_ACCn_SCALE),   ω = R_board (u − b_thermal − CAL_GYROn_OFF)
//! ```
//! on `sensor_accel` (m/s²) and `sensor_gyro` (rad/s) data; current PX4 has no gyro scale.
//!
//! crosscal's correction is `a = K⁻¹ (u − b_a)` and `ω = C_ω⁻¹ (u − b_g − …)`: the
//! accelerometer's is exactly the autopilot's form when K is diagonal (offset b_a, scale
//! 1/k_ii), the gyro's when C_ω = I (offset b_g). What else the profile holds — K's cross-axis
//! terms, the gyro's scale and coupling, C_ε, g-sensitivity, any other effect — has no
//! parameter and is listed, with its size. The profile's x, y, z are taken to be the axes the
//! autopilot calibrates in (its sensor frame above): record the unit in those axes.

use super::interop::{matrix, unheld, vector};
use super::Profile;
use crate::units::{AccelUnit, GyroUnit, SensorKind};
use std::fmt::Write;

/// Which of the autopilot's IMUs the parameters are for: 1, 2 or 3 (ArduPilot `INS_`,
/// `INS_ACC2`/`INS_GYR2`, `INS_ACC3`/`INS_GYR3`; PX4 calibration slots 0, 1, 2).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct AutopilotImu(u8);

impl AutopilotImu {
    /// The first IMU.
    pub const FIRST: Self = Self(1);

    /// IMU `n` (1-based), or None outside 1..=3.
    pub fn new(n: u8) -> Option<Self> {
        (1..=3).contains(&n).then_some(Self(n))
    }

    /// The 1-based number.
    pub fn number(self) -> u8 {
        self.0
    }
}

/// What an autopilot can hold of a profile: accelerometer offsets and per-axis scales, gyro
/// offsets (SI), and the lines saying what it cannot.
struct Diagonal {
    acc_off: [f64; 3],
    acc_scale: [f64; 3],
    gyro_off: [f64; 3],
    lost: Vec<String>,
}

/// Largest |m_ij − δ_ij| over the entries `pick` selects.
fn largest(m: [[f64; 3]; 3], pick: impl Fn(usize, usize) -> bool) -> f64 {
    let mut x = 0.0f64;
    for i in 0..3 {
        for j in 0..3 {
            if pick(i, j) {
                x = x.max((m[i][j] - if i == j { 1.0 } else { 0.0 }).abs());
            }
        }
    }
    x
}

fn diagonal(p: &Profile, stack: &str) -> Diagonal {
    let k = matrix(p, SensorKind::Accel, "k");
    let c = matrix(p, SensorKind::Gyro, "c");
    let mut lost = Vec::new();
    let acc_scale: [f64; 3] = std::array::from_fn(|i| {
        let s = 1.0 / k[i][i];
        if s.is_finite() {
            s
        } else {
            lost.push(format!("accelerometer scale k_{0}{0} = 0 cannot be inverted: written as 1", ['x', 'y', 'z'][i]));
            1.0
        }
    });
    let cross = largest(k, |i, j| i != j);
    if cross > 0.0 {
        lost.push(format!(
            "accelerometer cross-axis coupling (largest |k_ij| = {cross:.3e}): {stack} scales each axis alone (scale = 1/k_ii written)"
        ));
    }
    let gyro = largest(c, |_, _| true);
    if gyro > 0.0 {
        lost.push(format!(
            "gyro scale factors and couplings (largest |c_ij - delta_ij| = {gyro:.3e}): {stack} has no gyro scale"
        ));
    }
    if p.input_units.gyro == GyroUnit::Raw || p.input_units.accel == AccelUnit::Raw {
        lost.push(format!(
            "the profile was fitted on raw counts: {stack}'s offsets are in m/s^2 and rad/s after its driver's scaling, so these values do not apply"
        ));
    }
    let held = ["gyro-bias", "accel-bias", "gyro-scale-coupling", "accel-scale-coupling"];
    lost.extend(unheld(p, &held, &format!("{stack} has no such term")));
    Diagonal { acc_off: vector(p, SensorKind::Accel), acc_scale, gyro_off: vector(p, SensorKind::Gyro), lost }
}

/// The profile as an ArduPilot parameter file (`NAME,VALUE` lines, `#` comments; read by
/// Mission Planner and MAVProxy/pymavlink `param load`): `INS_ACCOFFS_X/Y/Z` = b_a (m/s²),
/// `INS_ACCSCAL_X/Y/Z` = 1/k_ii, `INS_GYROFFS_X/Y/Z` = b_g (rad/s) — or the `INS_ACC2`/
/// `INS_GYR2`, `INS_ACC3`/`INS_GYR3` names for the second and third IMU — and what it cannot
/// hold. ArduPilot applies them as `a = (u − INS_ACCOFFS) · INS_ACCSCAL`, `ω = u −
/// INS_GYROFFS` per axis (module docs). Values outside ArduPilot's documented ranges
/// (scale 0.8…1.2, offset ±3.5 m/s²) are listed too.
pub fn to_ardupilot(p: &Profile, imu: AutopilotImu) -> (String, Vec<String>) {
    let mut d = diagonal(p, "ArduPilot");
    let (acc, gyr) = match imu.number() {
        1 => ("INS_ACC", "INS_GYR"),
        2 => ("INS_ACC2", "INS_GYR2"),
        _ => ("INS_ACC3", "INS_GYR3"),
    };
    for (i, axis) in ["X", "Y", "Z"].iter().enumerate() {
        if !(0.8..=1.2).contains(&d.acc_scale[i]) {
            d.lost.push(format!(
                "{acc}SCAL_{axis} = {} lies outside ArduPilot's documented range 0.8..1.2",
                d.acc_scale[i]
            ));
        }
        if d.acc_off[i].abs() > 3.5 {
            d.lost.push(format!(
                "{acc}OFFS_{axis} = {} m/s^2 lies outside ArduPilot's documented range -3.5..3.5",
                d.acc_off[i]
            ));
        }
    }
    let mut s = String::new();
    let _ = writeln!(
        s,
        "# ArduPilot IMU {} calibration exported by crosscal from unit {} profile {}",
        imu.0, p.serial, p.created_utc
    );
    let _ = writeln!(
        s,
        "# applied per axis in the sensor frame: a = (raw - {acc}OFFS) * {acc}SCAL (m/s^2), w = raw - {gyr}OFFS (rad/s)"
    );
    let _ = writeln!(
        s,
        "# INS_GYR_CAL 1 (the default) re-measures the gyro offsets at every boot: set it to 0 to keep these"
    );
    let _ = writeln!(s, "# Not represented: {}", d.lost.join("; "));
    for (i, axis) in ["X", "Y", "Z"].iter().enumerate() {
        let _ = writeln!(s, "{acc}OFFS_{axis},{}", d.acc_off[i]);
    }
    for (i, axis) in ["X", "Y", "Z"].iter().enumerate() {
        let _ = writeln!(s, "{acc}SCAL_{axis},{}", d.acc_scale[i]);
    }
    for (i, axis) in ["X", "Y", "Z"].iter().enumerate() {
        let _ = writeln!(s, "{gyr}OFFS_{axis},{}", d.gyro_off[i]);
    }
    (s, d.lost)
}

/// The profile as a QGroundControl parameter file for PX4 (`# Onboard parameters` header,
/// tab-separated `Vehicle-Id Component-Id Name Value Type` lines, vehicle 1, component 1,
/// type 9 = MAV_PARAM_TYPE_REAL32): `CAL_ACCn_XOFF/YOFF/ZOFF` = b_a (m/s²),
/// `CAL_ACCn_XSCALE/YSCALE/ZSCALE` = 1/k_ii, `CAL_GYROn_XOFF/YOFF/ZOFF` = b_g (rad/s) for
/// slot n = IMU − 1, and what it cannot hold. PX4 applies them as `a = (u − OFF) ⊙ SCALE`,
/// `ω = u − OFF` (module docs) to the sensor whose device id is `CAL_ACCn_ID` /
/// `CAL_GYROn_ID`; crosscal does not know those ids, so the file leaves them as the vehicle
/// has them (set by one QGroundControl calibration) and says so.
pub fn to_px4(p: &Profile, imu: AutopilotImu) -> (String, Vec<String>) {
    let mut d = diagonal(p, "PX4");
    let n = imu.0 - 1;
    d.lost.push(format!(
        "CAL_ACC{n}_ID and CAL_GYRO{n}_ID (the device ids PX4 matches a calibration slot by): not written, so the vehicle's must already name this unit's sensors"
    ));
    let mut s = String::from("# Onboard parameters for Vehicle 1\n#\n");
    let _ = writeln!(
        s,
        "# PX4 IMU calibration (slot {n}) exported by crosscal from unit {} profile {}",
        p.serial, p.created_utc
    );
    let _ = writeln!(
        s,
        "# applied per axis in the sensor frame: a = (raw - CAL_ACC{n}_OFF) * CAL_ACC{n}_SCALE (m/s^2), w = raw - CAL_GYRO{n}_OFF (rad/s)"
    );
    let _ = writeln!(s, "# Not represented: {}", d.lost.join("; "));
    let _ = writeln!(s, "#\n# Vehicle-Id Component-Id Name Value Type");
    let mut line = |name: String, v: f64| {
        let _ = writeln!(s, "1\t1\t{name}\t{v}\t9");
    };
    for (i, axis) in ["X", "Y", "Z"].iter().enumerate() {
        line(format!("CAL_ACC{n}_{axis}OFF"), d.acc_off[i]);
    }
    for (i, axis) in ["X", "Y", "Z"].iter().enumerate() {
        line(format!("CAL_ACC{n}_{axis}SCALE"), d.acc_scale[i]);
    }
    for (i, axis) in ["X", "Y", "Z"].iter().enumerate() {
        line(format!("CAL_GYRO{n}_{axis}OFF"), d.gyro_off[i]);
    }
    (s, d.lost)
}
