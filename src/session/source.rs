//! The provenance of a recording imported from a log or bag: the manifest's optional
//! `"source"` object (information for the user; nothing downstream depends on it).

use serde_json::Value;

/// The provenance of an imported recording (the manifest's optional `"source"`).
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Source {
    /// The file's format (`ROS 1 bag`, `PX4 ULog`, …).
    pub format: String,
    /// The file, as given to `import`.
    pub file: String,
    /// The stream (topic, message, instance).
    pub stream: String,
    /// The axis convention and units of the values, in words.
    pub frame: String,
    /// The log's time stamp of the recording's t = 0, ns.
    pub start_ns: i64,
    /// Calibration parameters the log says were applied to the values (name, value).
    pub applied: Vec<(String, f64)>,
    /// What a user should know about the values.
    pub notes: Vec<String>,
}

impl Source {
    /// The `"source"` object.
    pub fn to_json(&self) -> Value {
        let applied: serde_json::Map<String, Value> =
            self.applied.iter().map(|(k, v)| (k.clone(), serde_json::json!(v))).collect();
        serde_json::json!({
            "format": self.format, "file": self.file, "stream": self.stream, "frame": self.frame,
            "start_ns": self.start_ns, "applied_calibration": applied, "notes": self.notes,
        })
    }

    /// The warning a fit on this recording carries when the log says a calibration was
    /// already applied to its values (`None` when none was).
    pub fn applied_warning(&self) -> Option<String> {
        (!self.applied.is_empty()).then(|| {
            format!(
                "the recording ({}, {}) was calibrated by the autopilot before it was logged ({} parameters in the manifest's source, e.g. {}): this calibration is on top of it",
                self.format,
                self.stream,
                self.applied.len(),
                self.applied.iter().take(3).map(|(k, v)| format!("{k}={v}")).collect::<Vec<_>>().join(", ")
            )
        })
    }

    /// Reads a `"source"` object (unknown keys ignored: it is information, not input).
    pub fn from_json(v: &Value) -> Option<Self> {
        let o = v.as_object()?;
        let s = |k: &str| o.get(k).and_then(Value::as_str).unwrap_or_default().to_string();
        let applied = o
            .get("applied_calibration")
            .and_then(Value::as_object)
            .map(|m| m.iter().filter_map(|(k, v)| Some((k.clone(), v.as_f64()?))).collect())
            .unwrap_or_default();
        let notes = o
            .get("notes")
            .and_then(Value::as_array)
            .map(|a| a.iter().filter_map(|n| n.as_str().map(str::to_string)).collect())
            .unwrap_or_default();
        Some(Self {
            format: s("format"),
            file: s("file"),
            stream: s("stream"),
            frame: s("frame"),
            start_ns: o.get("start_ns").and_then(Value::as_i64).unwrap_or(0),
            applied,
            notes,
        })
    }
}
