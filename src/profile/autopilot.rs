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
//!
//! # Thermal compensation
//!
//! A profile with temperature-bias terms (`…-temp-bias`, `…-temp-bias2`, `…-temp-bias3`:
//! u_i += q_i(T) = Σₖ tbₖ_i (T − 20 °C)ᵏ, k = 1…3, see `model::temp_bias`) also gets the
//! autopilot's thermal block, in the same file, because the offsets above and the thermal
//! polynomial are one correction and must be loaded together. Both firmwares hold a cubic per
//! axis in (T − T_ref) and hold T at the edge of [TMIN, TMAX] outside it, as crosscal's
//! default `clamp` does (`correct::temperature`); TMIN/TMAX are the profile's calibrated range
//! (`Profile::temperature_range_c`). crosscal's cubic about 20 °C is re-expanded exactly about
//! the firmware's reference (binomial shift, [`shift_polynomial`]).
//!
//! ArduPilot (`libraries/AP_InertialSensor/AP_InertialSensor_tempcal.cpp`,
//! `AP_InertialSensor::TCal::correct_sensor` and `polynomial_eval`, called from
//! `AP_InertialSensor_Backend::_rotate_and_correct_accel`/`_gyro` after the chip rotation and
//! before `INS_ACCOFFS`/`INS_ACCSCAL`), with `TEMP_REFERENCE` = 35 °C and parameters stored
//! ×10⁶ (`SCALE_FACTOR`):
//! ```text
//! P(T) = 1e-6 (ACC1 d + ACC2 d² + ACC3 d³),   d = T − 35
//! v ← v − P(clamp(T, TMIN, TMAX)) + P(clamp(INS_ACCn_CALTEMP, TMIN, TMAX))
//! ```
//! (`GYR1…3` and `INS_GYRn_CALTEMP` for the gyro), applied only when `INS_TCALn_ENABLE` = 1.
//! The export writes ACCk/GYRk = 10⁶ × the coefficients of q about 35 °C, CALTEMP = c =
//! clamp(20 °C, TMIN, TMAX) and offset = b + q(c) (= b when 20 °C is inside the range), so
//! that P(T) − P(c) + offset = b + q(clamp(T)).
//!
//! PX4 (`src/modules/temperature_compensation/TemperatureCompensation.cpp`,
//! `TemperatureCompensation::calc_thermal_offsets_3D`; the result is `_thermal_offset` in
//! `calibration::Accelerometer::Correct` / `calibration::Gyroscope::Correct` above), used when
//! `TC_A_ENABLE` / `TC_G_ENABLE` = 1 for the sensor whose device id is `TC_An_ID` / `TC_Gn_ID`:
//! ```text
//! b_thermal_i = X0_i + X1_i d + X2_i d² + X3_i d³,   d = clamp(T, TMIN, TMAX) − TREF
//! ```
//! The export writes TREF = the middle of the range (|d| stays small, kind to 32-bit floats),
//! Xk = the coefficients of q about TREF (X0 = q(TREF)), and leaves `CAL_*OFF` = b.
//!
//! A profile without temperature-bias terms writes no thermal block: the vehicle's own
//! `INS_TCALn_*` / `TC_*` stay as they are. Temperature-dependent scale
//! (`…-temp-scale`) has no parameter in either firmware and is listed as lost.

use super::interop::{matrix, unheld, vector};
use super::Profile;
use crate::model::T_REF_C;
use crate::units::{AccelUnit, GyroUnit, SensorKind, AXES};
use std::fmt::Write;

/// ArduPilot's fixed reference temperature, °C (`TEMP_REFERENCE` in `AP_InertialSensor_tempcal.cpp`).
pub const ARDUPILOT_TCAL_REFERENCE_C: f64 = 35.0;

/// ArduPilot's factor between the stored `INS_TCALn_*` coefficients and SI (`SCALE_FACTOR`).
pub const ARDUPILOT_TCAL_SCALE: f64 = 1.0e6;

/// The temperature-bias effects, whose polynomial the autopilots' thermal blocks hold.
const TEMP_BIAS: [&str; 6] =
    ["gyro-temp-bias", "gyro-temp-bias2", "gyro-temp-bias3", "accel-temp-bias", "accel-temp-bias2", "accel-temp-bias3"];

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

fn diagonal(p: &Profile, stack: &str, thermal: bool) -> Diagonal {
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
    let mut held = vec!["gyro-bias", "accel-bias", "gyro-scale-coupling", "accel-scale-coupling"];
    if thermal {
        held.extend(TEMP_BIAS);
    }
    lost.extend(unheld(p, &held, &format!("{stack} has no such term")));
    Diagonal { acc_off: vector(p, SensorKind::Accel), acc_scale, gyro_off: vector(p, SensorKind::Gyro), lost }
}

/// The coefficients, about `to`, of the polynomial Σₖ aₖ (T − from)ᵏ (k = 0…3): with
/// h = to − from, T − from = (T − to) + h and the binomial theorem give
/// bⱼ = Σ_{k ≥ j} C(k, j) aₖ h^(k−j), so Σⱼ bⱼ (T − to)ʲ is the same cubic.
pub fn shift_polynomial(a: [f64; 4], from: f64, to: f64) -> [f64; 4] {
    let h = to - from;
    [a[0] + h * (a[1] + h * (a[2] + h * a[3])), a[1] + h * (2.0 * a[2] + 3.0 * h * a[3]), a[2] + 3.0 * h * a[3], a[3]]
}

/// Σₖ cₖ xᵏ (k = 0…3), Horner.
fn cubic(c: [f64; 4], x: f64) -> f64 {
    c[0] + x * (c[1] + x * (c[2] + x * c[3]))
}

/// The profile's temperature-bias polynomial, what the thermal blocks are written from.
struct Thermal {
    /// TMIN, TMAX: the calibrated range, °C.
    range: [f64; 2],
    /// Per axis, coefficients of (T − 20 °C)^0…3 (the constant is 0), SI.
    gyro: [[f64; 4]; 3],
    accel: [[f64; 4]; 3],
}

impl Thermal {
    fn of(&self, s: SensorKind) -> &[[f64; 4]; 3] {
        match s {
            SensorKind::Gyro => &self.gyro,
            SensorKind::Accel => &self.accel,
        }
    }

    /// Per axis, the coefficients about `t_ref`.
    fn about(&self, s: SensorKind, t_ref: f64) -> [[f64; 4]; 3] {
        self.of(s).map(|c| shift_polynomial(c, T_REF_C, t_ref))
    }

    /// q(t) per axis.
    fn at(&self, s: SensorKind, t: f64) -> [f64; 3] {
        self.of(s).map(|c| cubic(c, t - T_REF_C))
    }
}

/// The temperature-bias polynomial when the profile has one (None otherwise); a profile with
/// temperature-bias terms but no recorded range gets a line in `lost` instead.
fn thermal(p: &Profile, stack: &str, lost: &mut Vec<String>) -> Option<Thermal> {
    if !p.effects.iter().any(|e| TEMP_BIAS.contains(&e.as_str())) {
        return None;
    }
    let Some(range) = p.temperature_range_c() else {
        lost.push(format!(
            "temperature-bias terms: the profile records no calibrated temperature range, so {stack}'s TMIN/TMAX are unknown and no thermal block was written"
        ));
        return None;
    };
    let poly = |s: SensorKind| -> [[f64; 4]; 3] {
        std::array::from_fn(|i| {
            let v = |letter: &str| p.sensor(s).value(&format!("{}.{letter}_{}", s.as_str(), AXES[i])).unwrap_or(0.0);
            [0.0, v("tb"), v("tb2"), v("tb3")]
        })
    };
    Some(Thermal { range, gyro: poly(SensorKind::Gyro), accel: poly(SensorKind::Accel) })
}

/// ArduPilot's `INS_TCALn_*` block and the `INS_ACCn_CALTEMP`/`INS_GYRn_CALTEMP` it is
/// evaluated against (module docs); returns the temperature c written as CALTEMP.
fn ardupilot_tcal(s: &mut String, th: &Thermal, imu: u8, lost: &mut Vec<String>) -> f64 {
    let [lo, hi] = th.range;
    if lo < -70.0 || hi > 80.0 {
        lost.push(format!("INS_TCAL{imu}_TMIN/TMAX = {lo}/{hi} degC lie outside ArduPilot's documented range -70..80"));
    }
    let cal_temp = T_REF_C.clamp(lo, hi);
    let _ = writeln!(s, "INS_TCAL{imu}_ENABLE,1");
    let _ = writeln!(s, "INS_TCAL{imu}_TMIN,{lo}");
    let _ = writeln!(s, "INS_TCAL{imu}_TMAX,{hi}");
    for (sensor, name) in [(SensorKind::Accel, "ACC"), (SensorKind::Gyro, "GYR")] {
        let c = th.about(sensor, ARDUPILOT_TCAL_REFERENCE_C);
        for k in 1..=3 {
            for (i, axis) in ["X", "Y", "Z"].iter().enumerate() {
                let _ = writeln!(s, "INS_TCAL{imu}_{name}{k}_{axis},{}", c[i][k] * ARDUPILOT_TCAL_SCALE);
            }
        }
    }
    let _ = writeln!(s, "INS_ACC{imu}_CALTEMP,{cal_temp}");
    let _ = writeln!(s, "INS_GYR{imu}_CALTEMP,{cal_temp}");
    cal_temp
}

/// PX4's `TC_*` block for slot `n` (module docs).
fn px4_tc(th: &Thermal, n: u8, line: &mut impl FnMut(String, f64, u8)) {
    let [lo, hi] = th.range;
    let t_ref = 0.5 * (lo + hi);
    line("TC_A_ENABLE".into(), 1.0, 6);
    line("TC_G_ENABLE".into(), 1.0, 6);
    for (sensor, letter) in [(SensorKind::Accel, 'A'), (SensorKind::Gyro, 'G')] {
        line(format!("TC_{letter}{n}_TREF"), t_ref, 9);
        line(format!("TC_{letter}{n}_TMIN"), lo, 9);
        line(format!("TC_{letter}{n}_TMAX"), hi, 9);
        let c = th.about(sensor, t_ref);
        for k in 0..=3 {
            for (i, row) in c.iter().enumerate() {
                line(format!("TC_{letter}{n}_X{k}_{i}"), row[k], 9);
            }
        }
    }
}

/// The profile as an ArduPilot parameter file (`NAME,VALUE` lines, `#` comments; read by
/// Mission Planner and MAVProxy/pymavlink `param load`): `INS_ACCOFFS_X/Y/Z` = b_a (m/s²),
/// `INS_ACCSCAL_X/Y/Z` = 1/k_ii, `INS_GYROFFS_X/Y/Z` = b_g (rad/s) — or the `INS_ACC2`/
/// `INS_GYR2`, `INS_ACC3`/`INS_GYR3` names for the second and third IMU — and what it cannot
/// hold. ArduPilot applies them as `a = (u − INS_ACCOFFS) · INS_ACCSCAL`, `ω = u −
/// INS_GYROFFS` per axis (module docs). Values outside ArduPilot's documented ranges
/// (scale 0.8…1.2, offset ±3.5 m/s²) are listed too. A profile with temperature-bias terms
/// also gets `INS_TCALn_ENABLE` = 1, `INS_TCALn_TMIN/TMAX`, `INS_TCALn_ACC1…3_*` and
/// `INS_TCALn_GYR1…3_*` (10⁶ × the cubic's coefficients about 35 °C) and
/// `INS_ACCn_CALTEMP`/`INS_GYRn_CALTEMP` = c, with the offsets b + q(c) (module docs,
/// `AP_InertialSensor::TCal::correct_sensor`).
pub fn to_ardupilot(p: &Profile, imu: AutopilotImu) -> (String, Vec<String>) {
    let mut early = Vec::new();
    let th = thermal(p, "ArduPilot", &mut early);
    let mut d = diagonal(p, "ArduPilot", th.is_some());
    d.lost.extend(early);
    let mut tcal = String::new();
    if let Some(th) = &th {
        let c = ardupilot_tcal(&mut tcal, th, imu.0, &mut d.lost);
        let (qa, qg) = (th.at(SensorKind::Accel, c), th.at(SensorKind::Gyro, c));
        for i in 0..3 {
            d.acc_off[i] += qa[i];
            d.gyro_off[i] += qg[i];
        }
    }
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
    if th.is_some() {
        let n = imu.0;
        let _ = writeln!(
            s,
            "# before them raw -= P(clamp(T, TMIN, TMAX)) - P(clamp(CALTEMP, TMIN, TMAX)), P = 1e-6 (C1 d + C2 d^2 + C3 d^3), d = T - 35 degC (INS_TCAL{n}_*)"
        );
    }
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
    s.push_str(&tcal);
    (s, d.lost)
}

/// The profile as a QGroundControl parameter file for PX4 (`# Onboard parameters` header,
/// tab-separated `Vehicle-Id Component-Id Name Value Type` lines, vehicle 1, component 1,
/// type 9 = MAV_PARAM_TYPE_REAL32): `CAL_ACCn_XOFF/YOFF/ZOFF` = b_a (m/s²),
/// `CAL_ACCn_XSCALE/YSCALE/ZSCALE` = 1/k_ii, `CAL_GYROn_XOFF/YOFF/ZOFF` = b_g (rad/s) for
/// slot n = IMU − 1, and what it cannot hold. PX4 applies them as `a = (u − OFF) ⊙ SCALE`,
/// `ω = u − OFF` (module docs) to the sensor whose device id is `CAL_ACCn_ID` /
/// `CAL_GYROn_ID`; crosscal does not know those ids, so the file leaves them as the vehicle
/// has them (set by one QGroundControl calibration) and says so. A profile with
/// temperature-bias terms also gets `TC_A_ENABLE`/`TC_G_ENABLE` = 1 (type 6, INT32) and slot
/// n's `TC_An_*`/`TC_Gn_*`: TREF (the range's middle), TMIN, TMAX and `X0_i…X3_i`, the cubic's
/// coefficients about TREF (module docs, `TemperatureCompensation::calc_thermal_offsets_3D`);
/// `TC_An_ID`/`TC_Gn_ID` are left as the vehicle has them, like the `CAL_*_ID`.
pub fn to_px4(p: &Profile, imu: AutopilotImu) -> (String, Vec<String>) {
    let mut early = Vec::new();
    let th = thermal(p, "PX4", &mut early);
    let mut d = diagonal(p, "PX4", th.is_some());
    d.lost.extend(early);
    let n = imu.0 - 1;
    d.lost.push(format!(
        "CAL_ACC{n}_ID and CAL_GYRO{n}_ID (the device ids PX4 matches a calibration slot by): not written, so the vehicle's must already name this unit's sensors"
    ));
    if th.is_some() {
        d.lost.push(format!(
            "TC_A{n}_ID and TC_G{n}_ID (the device ids PX4 matches a thermal slot by): not written, so the vehicle's must already name this unit's sensors"
        ));
    }
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
    if th.is_some() {
        let _ = writeln!(
            s,
            "# before them raw -= X0 + X1 d + X2 d^2 + X3 d^3, d = clamp(T, TMIN, TMAX) - TREF (TC_A{n}_*, TC_G{n}_*)"
        );
    }
    let _ = writeln!(s, "# Not represented: {}", d.lost.join("; "));
    let _ = writeln!(s, "#\n# Vehicle-Id Component-Id Name Value Type");
    let mut typed = |name: String, v: f64, ty: u8| {
        let _ = writeln!(s, "1\t1\t{name}\t{v}\t{ty}");
    };
    if let Some(th) = &th {
        px4_tc(th, n, &mut typed);
    }
    let mut line = |name: String, v: f64| typed(name, v, 9);
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
