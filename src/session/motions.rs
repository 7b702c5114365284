//! The manifest's motion kinds parsed and checked (`conic`, `static`, `rotation`,
//! `multi_position`): each returns the [`MotionSpec`] or an error naming the key.

use super::{kinds_ok, num, vec3, within, BadValue, MotionSpec, SessionError, LIMITS};
use serde_json::Value;

/// A `conic` motion: cone angle, rate and phase within their limits.
pub(super) fn conic_motion(name: &str, m: &Value, bad: &BadValue<'_>) -> Result<MotionSpec, SessionError> {
    let need = |key: &str| {
        num(m, key).ok_or_else(|| bad(name, format!("run '{name}': conic motion needs a finite number \"{key}\"")))
    };
    let check =
        |key: &str, x: f64, lim: f64, unit: &str| within(name, key, x, -lim, lim, unit).map_err(|m| bad(key, m));
    kinds_ok(name, m, &["cone_angle_deg", "rate_deg_s", "phase_deg"], &[], bad)?;
    let cone_angle_deg = need("cone_angle_deg")?;
    let rate_deg_s = check("rate_deg_s", need("rate_deg_s")?, LIMITS.rate_deg_s, "deg/s")?;
    let phase_deg = check("phase_deg", num(m, "phase_deg").unwrap_or(0.0), LIMITS.phase_deg, "degrees")?;
    if !(0.0..=90.0).contains(&cone_angle_deg) {
        return Err(bad(name, format!("run '{name}': cone_angle_deg is {cone_angle_deg}: expected 0..90 degrees")));
    }
    Ok(MotionSpec::Conic { cone_angle_deg, rate_deg_s, phase_deg })
}

/// A `static` motion: `up_stand` (or `"unknown"`), with the Earth's rate when declared.
pub(super) fn static_motion(name: &str, m: &Value, bad: &BadValue<'_>) -> Result<MotionSpec, SessionError> {
    let up = m
        .get("up_stand")
        .and_then(Value::as_array)
        .filter(|a| a.len() == 3)
        .and_then(|a| {
            let v: Vec<f64> = a.iter().filter_map(Value::as_f64).collect();
            (v.len() == 3).then(|| [v[0], v[1], v[2]])
        })
        .ok_or_else(|| {
            bad(
                name,
                format!("run '{name}': static motion needs \"up_stand\": [x, y, z], the up unit vector in stand axes"),
            )
        })?;
    let norm = (up[0] * up[0] + up[1] * up[1] + up[2] * up[2]).sqrt();
    if (norm - 1.0).abs() > 1e-3 {
        return Err(bad(name, format!("run '{name}': up_stand has length {norm}: expected a unit vector")));
    }
    let up = [up[0] / norm, up[1] / norm, up[2] / norm];
    let mut earth = [0.0; 3];
    kinds_ok(name, m, &["latitude_deg"], &[], bad)?;
    if m.get("earth_rate").and_then(Value::as_bool).unwrap_or(false) {
        let lat = num(m, "latitude_deg")
            .ok_or_else(|| bad(name, format!("run '{name}': earth_rate needs \"latitude_deg\"")))?
            .to_radians();
        const OMEGA_E: f64 = 7.292_115e-5;
        // Vertical component along up; horizontal along north when given.
        for k in 0..3 {
            earth[k] = OMEGA_E * lat.sin() * up[k];
        }
        if let Some(n) = m.get("north_stand").and_then(Value::as_array) {
            let v: Vec<f64> = n.iter().filter_map(Value::as_f64).collect();
            if v.len() == 3 {
                for k in 0..3 {
                    earth[k] += OMEGA_E * lat.cos() * v[k];
                }
            }
        }
    }
    Ok(MotionSpec::Static { up_stand: up, earth_rate_rad_s: earth })
}

/// A `rotation` motion (a protocol turn): its axis and angle.
pub(super) fn rotation_motion(name: &str, m: &Value, bad: &BadValue<'_>) -> Result<MotionSpec, SessionError> {
    let axis = vec3(m, "axis_stand").ok_or_else(|| {
        bad(name, format!("run '{name}': rotation needs \"axis_stand\": [x, y, z], the turn axis in stand axes"))
    })?;
    let norm = (axis[0] * axis[0] + axis[1] * axis[1] + axis[2] * axis[2]).sqrt();
    if (norm - 1.0).abs() > 1e-3 {
        return Err(bad(name, format!("run '{name}': axis_stand has length {norm}: expected a unit vector")));
    }
    let angle_deg = num(m, "angle_deg").ok_or_else(|| {
        bad(name, format!("run '{name}': rotation needs a finite \"angle_deg\" (the total turn, e.g. -360)"))
    })?;
    if angle_deg == 0.0 {
        return Err(bad(name, format!("run '{name}': angle_deg is 0: a rotation run must turn")));
    }
    within(name, "angle_deg", angle_deg, -LIMITS.angle_deg, LIMITS.angle_deg, "degrees").map_err(|m| bad(name, m))?;
    Ok(MotionSpec::Rotation { axis_stand: [axis[0] / norm, axis[1] / norm, axis[2] / norm], angle_deg })
}

/// A `multi_position` motion (a protocol run): rest, detector and poses.
pub(super) fn multi_position_motion(name: &str, m: &Value, bad: &BadValue<'_>) -> Result<MotionSpec, SessionError> {
    kinds_ok(name, m, &["init_rest_s", "threshold_multiplier"], &["window", "min_pose_samples"], bad)?;
    let init_rest_s = num(m, "init_rest_s").unwrap_or(30.0);
    let window = m.get("window").and_then(Value::as_u64).unwrap_or(101) as usize;
    let threshold_multiplier = num(m, "threshold_multiplier");
    let min_pose_samples = m.get("min_pose_samples").and_then(Value::as_u64).unwrap_or(100) as usize;
    if init_rest_s <= 0.0
        || init_rest_s > LIMITS.init_rest_s
        || !(3..=LIMITS.window).contains(&window)
        || !(2..=LIMITS.window).contains(&min_pose_samples)
        || threshold_multiplier.is_some_and(|t| t <= 0.0 || t > 1e6)
    {
        return Err(bad(
            name,
            format!(
                "run '{name}': multi_position needs 0 < init_rest_s <= {}, 3 <= window <= {w}, 2 <= min_pose_samples <= {w} and 0 < threshold_multiplier <= 1e6",
                LIMITS.init_rest_s,
                w = LIMITS.window
            ),
        ));
    }
    let poses = match m.get("poses") {
        None => None,
        Some(v) => {
            let list: Option<Vec<(usize, usize)>> = v.as_array().and_then(|a| {
                a.iter()
                    .map(|p| {
                        let p = p.as_array().filter(|p| p.len() == 2)?;
                        let (s, e) = (p[0].as_u64()? as usize, p[1].as_u64()? as usize);
                        (e > s).then_some((s, e))
                    })
                    .collect()
            });
            Some(list.ok_or_else(|| {
                bad(name, format!("run '{name}': poses must be a list of [start, end] sample ranges with start < end"))
            })?)
        }
    };
    Ok(MotionSpec::MultiPosition { init_rest_s, window: window | 1, threshold_multiplier, min_pose_samples, poses })
}
