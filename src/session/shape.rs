//! The keys a manifest may hold, declared once as serde structs with
//! `deny_unknown_fields`: a misspelt field (`"mounting"`, `"serail"`) is an error naming it
//! and the closest known field, never silently ignored (a fit without its run's mount is a
//! wrong fit with exit 0).
//!
//! Values are checked by the manifest parser; these structs only say which keys exist, so a
//! new optional field is one line in the struct here (serde then accepts it). The user's own
//! metadata has an explicit place: an `"extra"` object (anything inside) at the top level
//! and in every run, or any key starting with `x-` in any object.

use serde::de::IgnoredAny;
use serde::Deserialize;
use serde_json::Value;

/// Top level.
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
#[allow(dead_code)]
struct ManifestKeys {
    format: Option<IgnoredAny>,
    serial: Option<IgnoredAny>,
    units: Option<UnitsKeys>,
    stand: Option<StandKeys>,
    runs: Option<Vec<RunKeys>>,
    /// Where an imported recording came from (information: its own keys are free).
    source: Option<IgnoredAny>,
    /// The user's own metadata.
    extra: Option<IgnoredAny>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
#[allow(dead_code)]
struct UnitsKeys {
    gyro: Option<IgnoredAny>,
    accel: Option<IgnoredAny>,
    time: Option<IgnoredAny>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
#[allow(dead_code)]
struct StandKeys {
    g: Option<IgnoredAny>,
}

/// One run; `motion` is checked by its kind (see [`motion_keys`]).
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
#[allow(dead_code)]
struct RunKeys {
    name: Option<IgnoredAny>,
    file: Option<IgnoredAny>,
    motion: Option<IgnoredAny>,
    mount: Option<IgnoredAny>,
    temperature_c: Option<IgnoredAny>,
    start_s: Option<IgnoredAny>,
    duration_s: Option<IgnoredAny>,
    rows: Option<IgnoredAny>,
    note: Option<IgnoredAny>,
    /// A conic run's column of the stand's logged angle, degrees.
    angle_column: Option<IgnoredAny>,
    /// The user's own metadata.
    extra: Option<IgnoredAny>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
#[allow(dead_code)]
struct ConicKeys {
    kind: IgnoredAny,
    cone_angle_deg: Option<IgnoredAny>,
    rate_deg_s: Option<IgnoredAny>,
    phase_deg: Option<IgnoredAny>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
#[allow(dead_code)]
struct StaticKeys {
    kind: IgnoredAny,
    up_stand: Option<IgnoredAny>,
    earth_rate: Option<IgnoredAny>,
    latitude_deg: Option<IgnoredAny>,
    north_stand: Option<IgnoredAny>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
#[allow(dead_code)]
struct ReferenceKeys {
    kind: IgnoredAny,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
#[allow(dead_code)]
struct RotationKeys {
    kind: IgnoredAny,
    axis_stand: Option<IgnoredAny>,
    angle_deg: Option<IgnoredAny>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
#[allow(dead_code)]
struct MultiPositionKeys {
    kind: IgnoredAny,
    init_rest_s: Option<IgnoredAny>,
    window: Option<IgnoredAny>,
    threshold_multiplier: Option<IgnoredAny>,
    min_pose_samples: Option<IgnoredAny>,
    poses: Option<IgnoredAny>,
}

/// An unknown key: where it is (a path like `runs[2].mount`), the key, and the closest
/// known key when one is close enough to be a likely misspelling.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct UnknownKey {
    /// The object holding it, e.g. `runs[1]` or `runs[1].motion` (empty at the top level).
    pub place: String,
    /// The key as written.
    pub key: String,
    /// The known keys of that object.
    pub known: Vec<String>,
}

impl UnknownKey {
    /// The known key nearest `key` by Jaro–Winkler similarity, when it is similar enough.
    pub fn closest(&self) -> Option<&str> {
        self.known
            .iter()
            .map(|k| (strsim::jaro_winkler(&self.key, k), k))
            .filter(|(s, _)| *s >= 0.7)
            .max_by(|a, b| a.0.total_cmp(&b.0))
            .map(|(_, k)| k.as_str())
    }

    /// The message: the field, its place, the closest known one, and where user metadata goes.
    pub fn message(&self) -> String {
        let at = if self.place.is_empty() { String::new() } else { format!(" in {}", self.place) };
        let hint = match self.closest() {
            Some(k) => format!("did you mean \"{k}\"?"),
            None => format!("known fields: {}", self.known.join(", ")),
        };
        format!(
            "unknown field \"{}\"{at}: {hint} (put your own metadata in an \"extra\" object or under a key starting with \"x-\")",
            self.key
        )
    }
}

/// The first unknown key of a manifest (objects in document order), if any.
pub(crate) fn unknown_key(json: &Value) -> Option<UnknownKey> {
    let Value::Object(top) = json else { return None };
    if let Some(u) = check::<ManifestKeys>(json, "") {
        return Some(u);
    }
    for (name, keys) in [("units", check::<UnitsKeys> as Check), ("stand", check::<StandKeys>)] {
        if let Some(v) = top.get(name).filter(|v| v.is_object()) {
            if let Some(u) = keys(v, name) {
                return Some(u);
            }
        }
    }
    let runs = top.get("runs").and_then(Value::as_array)?;
    for (i, run) in runs.iter().enumerate() {
        if !run.is_object() {
            continue;
        }
        let place = format!("runs[{i}]");
        if let Some(u) = check::<RunKeys>(run, &place) {
            return Some(u);
        }
        if let Some(u) = run.get("motion").and_then(|m| motion_keys(m, &format!("{place}.motion"))) {
            return Some(u);
        }
    }
    None
}

type Check = fn(&Value, &str) -> Option<UnknownKey>;

/// The motion object's keys by its kind (an unknown kind is the parser's error).
fn motion_keys(m: &Value, place: &str) -> Option<UnknownKey> {
    let check: Check = match m.get("kind").and_then(Value::as_str)? {
        "conic" => check::<ConicKeys>,
        "static" => check::<StaticKeys>,
        "reference" => check::<ReferenceKeys>,
        "rotation" => check::<RotationKeys>,
        "multi_position" => check::<MultiPositionKeys>,
        _ => return None,
    };
    check(m, place)
}

/// Deserialises the object's keys (without its `x-` keys) into `T`, returning the unknown
/// key serde reports. Only unknown-field errors are reported here; every other problem is
/// the parser's.
fn check<T: serde::de::DeserializeOwned>(v: &Value, place: &str) -> Option<UnknownKey> {
    let Value::Object(o) = v else { return None };
    let keys: serde_json::Map<String, Value> =
        o.keys().filter(|k| !k.starts_with("x-")).map(|k| (k.clone(), Value::Null)).collect();
    let err = serde_json::from_value::<T>(Value::Object(keys)).err()?;
    parse_serde_unknown(&err.to_string(), place)
}

/// Reads serde's "unknown field `k`, expected one of `a`, `b`" (or "expected `a`").
fn parse_serde_unknown(msg: &str, place: &str) -> Option<UnknownKey> {
    let rest = msg.strip_prefix("unknown field `")?;
    let (key, rest) = rest.split_once('`')?;
    let known = rest.split('`').skip(1).step_by(2).map(str::to_string).collect();
    Some(UnknownKey { place: place.to_string(), key: key.to_string(), known })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn misspellings_name_the_closest_field_and_user_keys_pass() {
        let m: Value = serde_json::json!({
            "format": "crosscal-session/1", "serial": "A", "units": {"gyro": "deg/s"},
            "runs": [{"name": "a", "file": "a.csv", "motion": {"kind": "conic"}, "mounting": ["+x", "+y", "+z"]}]
        });
        let u = unknown_key(&m).unwrap();
        assert_eq!((u.place.as_str(), u.key.as_str(), u.closest()), ("runs[0]", "mounting", Some("mount")));
        let m = serde_json::json!({"format": "f", "serail": "A", "runs": []});
        assert_eq!(unknown_key(&m).unwrap().closest(), Some("serial"));
        let m = serde_json::json!({"runs": [{"motion": {"kind": "conic", "cone_angle": 1}}]});
        let u = unknown_key(&m).unwrap();
        assert_eq!((u.place.as_str(), u.closest()), ("runs[0].motion", Some("cone_angle_deg")));
        let m = serde_json::json!({"units": {"gyr": "deg/s"}});
        assert_eq!(unknown_key(&m).unwrap().closest(), Some("gyro"));
        let m = serde_json::json!({"x-lab": 1, "extra": {"anything": [1]}, "stand": {"g": 9.8, "x-site": "B"},
            "runs": [{"extra": {"operator": "me"}, "x-take": 3, "motion": {"kind": "static", "x-k": 1}}]});
        assert_eq!(unknown_key(&m), None);
        let m = serde_json::json!({"zzzz": 1});
        assert!(unknown_key(&m).unwrap().message().contains("known fields: format, serial"));
    }
}
