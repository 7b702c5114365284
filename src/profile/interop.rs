//! Exchange with the tools users already run: imucal's calibration JSON (Ferraris fields)
//! and Kalibr's `imu.yaml`.
//!
//! imucal's Ferraris model (imucal docs, `FerrarisCalibrationInfo`), raw = what the sensor
//! outputs in `from_*_unit`, calibrated in m/s² and deg/s:
//!   accelerometer raw = K_a R_a a + b_a,  gyroscope raw = K_g R_g ω + K_ga a + b_g,
//! K diagonal scales, R misalignment (rows ≈ unit vectors). crosscal's forward model is the
//! same with K = K_a R_a (accelerometer), C_ω = K_g R_g and G = K_ga (gyro g-sensitivity):
//! the export splits each row i as K_a\[i\]\[i\] = |row i| and R_a row i = row i / |row i|.
//! What imucal cannot hold (C_ε, every other effect, standard errors) is listed and left
//! out; the import fills the default model's C_ε with zeros, held.

use super::{Profile, ProfileError, PROFILE_FORMAT};
use crate::estimate::{CoefStatus, Coefficient, SensorFit};
use crate::model::Model;
use crate::units::{AccelUnit, GyroUnit, TimeUnit, Units};
use crate::units::{SensorKind, AXES};
use std::path::Path;

const DEG: f64 = std::f64::consts::PI / 180.0;

/// Effects imucal's Ferraris model can hold.
const IMUCAL_EFFECTS: [&str; 5] =
    ["gyro-bias", "gyro-scale-coupling", "accel-bias", "accel-scale-coupling", "gyro-g-sensitivity"];

/// A 3×3 coefficient matrix of the profile (`letter` c, k, g, e), row-major; entries the
/// model lacks are those of the identity for c and k, 0 otherwise.
pub(super) fn matrix(p: &Profile, sensor: SensorKind, letter: &str) -> [[f64; 3]; 3] {
    let sf = p.sensor(sensor);
    std::array::from_fn(|i| {
        std::array::from_fn(|j| {
            let name = format!("{}.{letter}_{}{}", sensor.as_str(), AXES[i], AXES[j]);
            sf.value(&name).unwrap_or(if letter != "g" && i == j { 1.0 } else { 0.0 })
        })
    })
}

/// A float as YAML 1.1 reads it as a float (PyYAML, which Kalibr and allan_variance_ros
/// use, takes `1e-5` and `1e0` for strings: it needs a point in the mantissa and a signed
/// exponent): shortest round-trip digits, `1.0e-5`, `2.5`, `-3.0e+16`.
pub fn yaml_float(v: f64) -> String {
    if !v.is_finite() {
        return if v.is_nan() {
            ".nan".into()
        } else if v > 0.0 {
            ".inf".into()
        } else {
            "-.inf".into()
        };
    }
    // Debug gives the shortest round-trip digits: `200.0`, `0.001`, `1e-7`, `1.5e16`.
    let s = format!("{v:?}");
    let Some((mant, exp)) = s.split_once('e') else { return s };
    let mant = if mant.contains('.') { mant.to_string() } else { format!("{mant}.0") };
    if exp.starts_with('-') {
        format!("{mant}e{exp}")
    } else {
        format!("{mant}e+{exp}")
    }
}

/// The sensor's bias b (0 where the model has none).
pub(super) fn vector(p: &Profile, sensor: SensorKind) -> [f64; 3] {
    std::array::from_fn(|i| p.sensor(sensor).value(&format!("{}.b_{}", sensor.as_str(), AXES[i])).unwrap_or(0.0))
}

/// Splits M into a diagonal scale and unit rows: M = diag(s) R.
fn split(m: [[f64; 3]; 3]) -> ([f64; 3], [[f64; 3]; 3]) {
    let s: [f64; 3] = std::array::from_fn(|i| m[i].iter().map(|v| v * v).sum::<f64>().sqrt());
    let r = std::array::from_fn(|i| std::array::from_fn(|j| if s[i] > 0.0 { m[i][j] / s[i] } else { 0.0 }));
    (s, r)
}

/// The effects of the profile a target cannot hold, one line each: every effect whose id is
/// not in `held` and whose coefficients (or nonlinear parameters) are not all exactly zero —
/// a term held at 0 loses nothing — named with its largest coefficient and `why`.
pub(crate) fn unheld(p: &Profile, held: &[&str], why: &str) -> Vec<String> {
    p.effects
        .iter()
        .filter(|e| !held.contains(&e.as_str()))
        .filter_map(|e| {
            let linear = p.gyro.coefficients.iter().chain(&p.accel.coefficients).filter(|c| c.effect == **e);
            let nonlinear = p.nonlinear.iter().filter(|q| q.effect == **e);
            let (largest, unit) = linear
                .map(|c| (c.value.abs(), c.unit.as_str()))
                .chain(nonlinear.map(|q| (q.value.abs(), q.unit.as_str())))
                .reduce(|a, b| if b.0 > a.0 { b } else { a })?;
            (largest > 0.0).then(|| format!("effect '{e}' (largest |coefficient| {largest:.3e} {unit}): {why}"))
        })
        .collect()
}

fn diag(s: [f64; 3]) -> [[f64; 3]; 3] {
    std::array::from_fn(|i| std::array::from_fn(|j| if i == j { s[i] } else { 0.0 }))
}

fn scaled(m: [[f64; 3]; 3], k: f64) -> [[f64; 3]; 3] {
    m.map(|row| row.map(|v| v * k))
}

/// Output units of a profile's inputs for imucal's `from_*_unit`, and the factors that turn
/// crosscal's SI-input coefficients into imucal's (raw per m/s², raw per deg/s).
fn factors(u: &Units, g: f64) -> (&'static str, f64, &'static str, f64) {
    // crosscal: u_recorded = k_rec · (coefficients · SI input); imucal wants recorded units.
    let (acc_unit, ka) = match u.accel {
        AccelUnit::Raw => ("a.u.", 1.0),
        AccelUnit::G => ("g", 1.0 / g),
        AccelUnit::MPerS2 => ("m/s^2", 1.0),
    };
    let (gyr_unit, kg) = match u.gyro {
        GyroUnit::Raw => ("a.u.", 1.0),
        GyroUnit::DegPerS => ("deg/s", 1.0 / DEG),
        GyroUnit::RadPerS => ("rad/s", 1.0),
    };
    (acc_unit, ka, gyr_unit, kg)
}

/// The profile as imucal's Ferraris calibration JSON, and what it cannot represent.
pub fn to_imucal(p: &Profile) -> (serde_json::Value, Vec<String>) {
    let (acc_unit, ka, gyr_unit, kg) = factors(&p.input_units, p.g_m_s2);
    let (k_a, r_a) = split(scaled(matrix(p, SensorKind::Accel, "k"), ka));
    // Gyro input in deg/s: raw = (kg·C)·ω_rad = (kg·C·DEG)·ω_deg.
    let (k_g, r_g) = split(scaled(matrix(p, SensorKind::Gyro, "c"), kg * DEG));
    let k_ga = scaled(matrix(p, SensorKind::Gyro, "g"), kg);
    let b_a = vector(p, SensorKind::Accel).map(|v| v * ka);
    let b_g = vector(p, SensorKind::Gyro).map(|v| v * kg);
    let mut lost: Vec<String> = p
        .effects
        .iter()
        .filter(|e| !IMUCAL_EFFECTS.contains(&e.as_str()))
        .filter(|e| {
            // C_ε that is exactly zero (held) loses nothing.
            e.as_str() != "gyro-angular-acceleration"
                || p.gyro.coefficients.iter().any(|c| c.effect == **e && c.value != 0.0)
        })
        .map(|e| format!("effect '{e}' (imucal's Ferraris model has no such term)"))
        .collect();
    lost.push("standard errors and covariances".into());
    let v = serde_json::json!({
        "acc_unit": "m/s^2",
        "gyr_unit": "deg/s",
        "from_acc_unit": acc_unit,
        "from_gyr_unit": gyr_unit,
        "comment": format!("exported by crosscal from unit {} profile {}; not represented: {}", p.serial, p.created_utc, lost.join("; ")),
        "K_a": diag(k_a),
        "R_a": r_a,
        "b_a": b_a,
        "K_g": diag(k_g),
        "R_g": r_g,
        "K_ga": k_ga,
        "b_g": b_g,
        "cal_type": "Ferraris",
        "_format_version": "2.0",
    });
    (v, lost)
}

fn get_matrix(v: &serde_json::Value, key: &str, path: &Path) -> Result<[[f64; 3]; 3], ProfileError> {
    let bad = || ProfileError::Parse {
        path: path.to_path_buf(),
        line: 1,
        column: 1,
        msg: format!("imucal field '{key}' must be a 3×3 array of numbers"),
    };
    let rows = v.get(key).and_then(|r| r.as_array()).filter(|r| r.len() == 3).ok_or_else(bad)?;
    let mut m = [[0.0; 3]; 3];
    for (i, row) in rows.iter().enumerate() {
        let row = row.as_array().filter(|r| r.len() == 3).ok_or_else(bad)?;
        for (j, x) in row.iter().enumerate() {
            m[i][j] = x.as_f64().filter(|x| x.is_finite()).ok_or_else(bad)?;
        }
    }
    Ok(m)
}

fn get_vector(v: &serde_json::Value, key: &str, path: &Path) -> Result<[f64; 3], ProfileError> {
    let bad = || ProfileError::Parse {
        path: path.to_path_buf(),
        line: 1,
        column: 1,
        msg: format!("imucal field '{key}' must be an array of 3 numbers"),
    };
    let a = v.get(key).and_then(|r| r.as_array()).filter(|r| r.len() == 3).ok_or_else(bad)?;
    let mut out = [0.0; 3];
    for (i, x) in a.iter().enumerate() {
        out[i] = x.as_f64().filter(|x| x.is_finite()).ok_or_else(bad)?;
    }
    Ok(out)
}

fn product(a: [[f64; 3]; 3], b: [[f64; 3]; 3]) -> [[f64; 3]; 3] {
    std::array::from_fn(|i| std::array::from_fn(|j| (0..3).map(|k| a[i][k] * b[k][j]).sum()))
}

/// Reads an imucal Ferraris calibration JSON as a crosscal profile of unit `serial`.
pub fn from_imucal(path: &Path, text: &str, serial: &str, g_m_s2: f64) -> Result<Profile, ProfileError> {
    let v: serde_json::Value = serde_json::from_str(text).map_err(|e| ProfileError::Parse {
        path: path.to_path_buf(),
        line: e.line(),
        column: e.column(),
        msg: e.to_string(),
    })?;
    let field = |k: &str| v.get(k).and_then(|x| x.as_str()).unwrap_or("");
    if field("cal_type") != "Ferraris" {
        return Err(ProfileError::Parse {
            path: path.to_path_buf(),
            line: 1,
            column: 1,
            msg: format!(
                "cal_type '{}' is not supported: crosscal imports imucal's Ferraris calibrations",
                field("cal_type")
            ),
        });
    }
    if field("acc_unit") != "m/s^2" || field("gyr_unit") != "deg/s" {
        return Err(ProfileError::Parse {
            path: path.to_path_buf(),
            line: 1,
            column: 1,
            msg: "expected acc_unit 'm/s^2' and gyr_unit 'deg/s' (imucal's defaults)".into(),
        });
    }
    let accel = match field("from_acc_unit") {
        "m/s^2" => AccelUnit::MPerS2,
        "g" => AccelUnit::G,
        _ => AccelUnit::Raw,
    };
    let gyro = match field("from_gyr_unit") {
        "deg/s" => GyroUnit::DegPerS,
        "rad/s" => GyroUnit::RadPerS,
        _ => GyroUnit::Raw,
    };
    let units = Units { gyro, accel, time: TimeUnit::S };
    let (_, ka, _, kg) = factors(&units, g_m_s2);
    let k = scaled(product(get_matrix(&v, "K_a", path)?, get_matrix(&v, "R_a", path)?), 1.0 / ka);
    let c = scaled(product(get_matrix(&v, "K_g", path)?, get_matrix(&v, "R_g", path)?), 1.0 / (kg * DEG));
    let gs = scaled(get_matrix(&v, "K_ga", path)?, 1.0 / kg);
    let b_a = get_vector(&v, "b_a", path)?.map(|x| x / ka);
    let b_g = get_vector(&v, "b_g", path)?.map(|x| x / kg);
    let mut model = Model::default_model();
    model
        .add_effect("gyro-g-sensitivity")
        .map_err(|source| ProfileError::Model { path: path.to_path_buf(), source })?;
    let value = |name: &str| -> Option<f64> {
        let (sensor, rest) = name.split_once('.')?;
        let (letter, idx) = rest.split_once('_')?;
        let ax = |ch: char| AXES.iter().position(|a| *a == ch);
        let mut chars = idx.chars();
        let i = ax(chars.next()?)?;
        let j = chars.next().and_then(ax);
        match (sensor, letter, j) {
            ("accel", "k", Some(j)) => Some(k[i][j]),
            ("accel", "b", None) => Some(b_a[i]),
            ("gyro", "c", Some(j)) => Some(c[i][j]),
            ("gyro", "g", Some(j)) => Some(gs[i][j]),
            ("gyro", "b", None) => Some(b_g[i]),
            _ => None,
        }
    };
    let sensor_fit = |s: SensorKind| SensorFit {
        sensor: s,
        coefficients: model
            .terms(s)
            .iter()
            .map(|t| {
                let v = value(&t.term.name);
                Coefficient {
                    name: t.term.name.clone(),
                    effect: t.effect.id().to_string(),
                    channel: t.term.channel,
                    unit: t.term.unit.to_string(),
                    value: v.unwrap_or(t.term.nominal),
                    std_error: None,
                    status: if v.is_some() { CoefStatus::Fitted } else { CoefStatus::Fixed },
                }
            })
            .collect(),
        channels: Vec::new(),
        unidentifiable: Vec::new(),
        correlated: Vec::new(),
    };
    Ok(Profile {
        format: PROFILE_FORMAT.into(),
        serial: serial.to_string(),
        created_utc: super::now_utc(),
        tool: format!("crosscal {} (imported from imucal)", env!("CARGO_PKG_VERSION")),
        input_units: units,
        g_m_s2,
        conventions: Default::default(),
        model: "imucal-ferraris".into(),
        effects: model.effects().iter().map(|e| e.id().to_string()).collect(),
        gyro: sensor_fit(SensorKind::Gyro),
        accel: sensor_fit(SensorKind::Accel),
        nonlinear: Vec::new(),
        stand: Vec::new(),
        stand_base: None,
        runs: Vec::new(),
        validation: None,
        correction: Default::default(),
        notes: vec![format!(
            "imported from imucal calibration {} (C_ε held at 0: imucal has no such term)",
            path.display()
        )],
        noise: None,
        protocol: None,
        user_effects: Vec::new(),
    })
}

/// The profile as Kalibr's `imu.yaml` (noise densities and random walks from the noise
/// section, update rate) with the scale-misalignment intrinsics (M_gyro = C_ω, A = G,
/// M_accel = K, in SI-input form), and what it cannot represent.
pub fn to_kalibr(p: &Profile, update_rate_hz: f64) -> (String, Vec<String>) {
    use std::fmt::Write;
    let mut lost = Vec::new();
    let density = |s: SensorKind, f: fn(&crate::noise::ChannelNoise) -> Option<f64>| {
        p.noise.as_ref().and_then(|n| n.channels.iter().filter(|c| c.sensor() == s).filter_map(f).reduce(f64::max))
    };
    let mut noise = |name: &str, v: Option<f64>| match v {
        Some(v) => yaml_float(v),
        None => {
            lost.push(format!(
                "{name}: the profile has no noise characterisation (crosscal noise --store); written as 0"
            ));
            "0.0".to_string()
        }
    };
    let gn = noise("gyroscope_noise_density", density(SensorKind::Gyro, |c| c.white()));
    let gw = noise("gyroscope_random_walk", density(SensorKind::Gyro, |c| c.random_walk));
    let an = noise("accelerometer_noise_density", density(SensorKind::Accel, |c| c.white()));
    let aw = noise("accelerometer_random_walk", density(SensorKind::Accel, |c| c.random_walk));
    let m = |x: [[f64; 3]; 3]| {
        let rows: Vec<String> = x
            .iter()
            .map(|r| format!("[{}]", r.iter().map(|v| yaml_float(*v)).collect::<Vec<_>>().join(", ")))
            .collect();
        format!("[{}]", rows.join(", "))
    };
    if p.input_units.gyro == GyroUnit::Raw || p.input_units.accel == AccelUnit::Raw {
        lost.push("raw-unit scales: Kalibr expects SI measurements".into());
    }
    for e in &p.effects {
        if !IMUCAL_EFFECTS.contains(&e.as_str()) {
            lost.push(format!("effect '{e}' (Kalibr's scale-misalignment model has no such term)"));
        }
    }
    lost.push("biases (Kalibr estimates them online as random-walk states)".into());
    let mut s = String::new();
    let _ =
        writeln!(s, "# Kalibr IMU configuration exported by crosscal from unit {} profile {}", p.serial, p.created_utc);
    let _ = writeln!(s, "# Not represented: {}", lost.join("; "));
    let _ = writeln!(s, "imu0:");
    let _ = writeln!(s, "  rostopic: /imu0");
    let _ = writeln!(s, "  update_rate: {}", yaml_float(update_rate_hz));
    let _ = writeln!(s, "  accelerometer_noise_density: {an}");
    let _ = writeln!(s, "  accelerometer_random_walk: {aw}");
    let _ = writeln!(s, "  gyroscope_noise_density: {gn}");
    let _ = writeln!(s, "  gyroscope_random_walk: {gw}");
    let _ = writeln!(s, "  model: scale-misalignment");
    let _ = writeln!(s, "  gyroscope_M: {}", m(matrix(p, SensorKind::Gyro, "c")));
    let _ = writeln!(s, "  gyroscope_A: {}", m(matrix(p, SensorKind::Gyro, "g")));
    let _ = writeln!(s, "  accelerometer_M: {}", m(matrix(p, SensorKind::Accel, "k")));
    (s, lost)
}
