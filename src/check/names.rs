//! Leaf helpers of the rules file: coefficient-name patterns and the units a noise rule may
//! be written in.

use crate::units::SensorKind;

/// Shell-style match with `*` only.
pub fn matches(pattern: &str, name: &str) -> bool {
    let parts: Vec<&str> = pattern.split('*').collect();
    if parts.len() == 1 {
        return pattern == name;
    }
    let mut rest = name;
    for (i, p) in parts.iter().enumerate() {
        if i == 0 {
            match rest.strip_prefix(p) {
                Some(r) => rest = r,
                None => return false,
            }
        } else if i == parts.len() - 1 {
            return rest.ends_with(p);
        } else {
            match rest.find(p) {
                Some(k) => rest = &rest[k + p.len()..],
                None => return false,
            }
        }
    }
    true
}

/// Multiplier from a display unit to SI for noise terms.
/// Whether `unit` measures `term` of `sensor` (an accelerometer bound in deg/h is a mistake,
/// not a number to convert).
pub(super) fn noise_unit_fits(sensor: SensorKind, term: &str, unit: &str) -> bool {
    unit == "SI"
        || match (sensor, term) {
            (SensorKind::Gyro, "white") => ["deg/sqrt(h)", "deg/s/sqrt(Hz)"].contains(&unit),
            (SensorKind::Gyro, "bias_instability") => unit == "deg/h",
            (SensorKind::Gyro, "random_walk") => unit == "deg/h/sqrt(h)",
            (SensorKind::Accel, "white") => ["m/s/sqrt(h)", "ug/sqrt(Hz)"].contains(&unit),
            (SensorKind::Accel, "bias_instability") => unit == "ug",
            _ => false,
        }
}

pub(super) fn noise_factor(unit: &str) -> Option<f64> {
    let deg = std::f64::consts::PI / 180.0;
    let g = 9.80665;
    Some(match unit {
        "deg/sqrt(h)" => deg / 60.0,
        "deg/s/sqrt(Hz)" => deg,
        "m/s/sqrt(h)" => 1.0 / 60.0,
        "ug/sqrt(Hz)" => 1e-6 * g,
        "deg/h" => deg / 3600.0,
        "ug" => 1e-6 * g,
        "deg/h/sqrt(h)" => deg / 3600.0 / 60.0,
        "SI" => 1.0,
        _ => return None,
    })
}
