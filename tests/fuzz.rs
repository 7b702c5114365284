//! Property tests: the readers never panic on arbitrary or mutated input (≥ 100,000 cases
//! per CI run), and simulate → fit recovers random units within their uncertainty.

use crate::common::fit_session;
use crosscal::estimate::FitOptions;
use crosscal::model::Model;
use crosscal::profile::Profile;
use crosscal::session::{parse_manifest, parse_recording, ReadOptions};
use crosscal::simulate::{conic_plan, cyclic_mounts, SimConfig};
use crosscal::units::SensorKind;
use crosscal::units::Units;
use proptest::prelude::*;
use std::path::Path;

const CSV: &str = "# comment\nt,gx,gy,gz,ax,ay,az,temp,wx_ref,wy_ref,wz_ref,ax_ref,ay_ref,az_ref\n\
0,0.1,0.2,0.3,0.01,0.02,0.99,20.5,0.1,0.2,0.3,0.01,0.02,0.99\n\
0.01,0.11,0.21,0.31,0.011,0.021,0.991,20.5,0.11,0.21,0.31,0.011,0.021,0.991\n\
0.02,0.12,0.22,0.32,0.012,0.022,0.992,20.6,0.12,0.22,0.32,0.012,0.022,0.992\n\
\n\
0.03,0.13,0.23,0.33,0.013,0.023,0.993,20.6,0.13,0.23,0.33,0.013,0.023,0.993\n\
0.04,1.3e-1,2.3E-1,-0.33,0.013,0.023,0.993,20.7,0.13,0.23,0.33,0.013,0.023,0.993\n";

const MANIFEST: &str = r#"{
  "format": "crosscal-session/1",
  "serial": "I1426-0042",
  "units": { "gyro": "deg/s", "accel": "g", "time": "s" },
  "stand": { "g": 9.80665 },
  "runs": [
    { "name": "cone+10", "file": "cone+10.csv",
      "motion": { "kind": "conic", "cone_angle_deg": 10.0, "rate_deg_s": 10.0, "phase_deg": 0.0 },
      "mount": ["+x", "+y", "+z"], "temperature_c": 21.0 },
    { "name": "rest", "file": "rest.csv", "motion": { "kind": "static", "up_stand": [0, 0, 1], "earth_rate": true, "latitude_deg": 52.2 } },
    { "name": "ref", "file": "ref.csv", "motion": { "kind": "reference" }, "mount": ["+y", "+z", "+x"] }
  ]
}"#;

/// Applies byte-level edits: (position fraction, byte, 0 = replace / 1 = insert / 2 = delete).
fn mutate(base: &str, edits: &[(f64, u8, u8)]) -> Vec<u8> {
    let mut b = base.as_bytes().to_vec();
    for &(pos, byte, op) in edits {
        let i = ((pos * b.len() as f64) as usize).min(b.len());
        match op % 3 {
            0 if i < b.len() => b[i] = byte,
            1 => b.insert(i, byte),
            _ if i < b.len() => {
                b.remove(i);
            }
            _ => {}
        }
    }
    b
}

/// Bytes that matter to the readers, favoured so mutations hit interesting cases.
fn interesting_byte() -> impl Strategy<Value = u8> {
    prop_oneof![prop::sample::select(b",.-+eE0123456789\n\r#\"{}[]:nNaIifx ".to_vec()), any::<u8>(),]
}

fn edits() -> impl Strategy<Value = Vec<(f64, u8, u8)>> {
    prop::collection::vec((0.0..1.0f64, interesting_byte(), 0u8..3), 1..8)
}

fn check_recording(bytes: &[u8], reference: bool) {
    let opts = ReadOptions { reference, strict: false, angle_column: None };
    if let Ok(r) = parse_recording(Path::new("x.csv"), bytes, &Units::default(), 9.80665, opts) {
        assert!(!r.is_empty());
        assert!(r.t_s.windows(2).all(|w| w[1] > w[0]));
        assert!(r.gyro.iter().chain(&r.accel).all(|v| v.iter().all(|x| x.is_finite())));
        assert_eq!(r.gyro.len(), r.t_s.len());
    }
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 30_000, failure_persistence: None, ..ProptestConfig::default() })]

    #[test]
    fn csv_reader_survives_arbitrary_bytes(bytes in prop::collection::vec(any::<u8>(), 0..300), reference in any::<bool>()) {
        check_recording(&bytes, reference);
    }

    #[test]
    fn csv_reader_survives_mutations(e in edits(), reference in any::<bool>()) {
        check_recording(&mutate(CSV, &e), reference);
    }
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 25_000, failure_persistence: None, ..ProptestConfig::default() })]

    #[test]
    fn manifest_reader_survives_mutations(e in edits()) {
        let bytes = mutate(MANIFEST, &e);
        let text = String::from_utf8_lossy(&bytes);
        if let Ok(m) = parse_manifest(Path::new("s.json"), &text) {
            prop_assert!(!m.runs.is_empty());
            prop_assert!(m.g_m_s2 > 0.0);
        }
    }

    #[test]
    fn manifest_reader_survives_arbitrary_text(text in ".{0,200}") {
        let _ = parse_manifest(Path::new("s.json"), &text);
    }
}

fn small_profile_json() -> String {
    let mut cfg = SimConfig::paper();
    cfg.runs = conic_plan(&[10.0, -10.0, 20.0], &[10.0, 20.0], &cyclic_mounts(3), 2.0);
    cfg.sample_rate_hz = 20.0;
    let s = cfg.generate();
    let m = Model::default_model();
    let f = fit_session(&s, &m, &FitOptions::default()).unwrap();
    Profile::from_fit(&s, &m, f, vec![]).to_json()
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 4_000, failure_persistence: None, ..ProptestConfig::default() })]

    #[test]
    fn profile_reader_survives_mutations(e in edits()) {
        thread_local!(static JSON: String = small_profile_json());
        let bytes = JSON.with(|j| mutate(j, &e));
        let text = String::from_utf8_lossy(&bytes);
        if let Ok(p) = Profile::from_json(Path::new("p.json"), &text) {
            // Whatever parses must also build a calibration or fail cleanly.
            let _ = crosscal::correct::Calibration::from_profile(&p);
        }
    }
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 16, failure_persistence: None, ..ProptestConfig::default() })]

    /// A random unit (couplings, ε terms, scales, biases) is recovered within 5 standard
    /// errors on every coefficient.
    #[test]
    fn random_units_are_recovered_within_their_uncertainty(
        off in prop::collection::vec(-0.02..0.02f64, 12),
        eps in prop::collection::vec(-0.002..0.002f64, 9),
        diag in prop::collection::vec(0.98..1.02f64, 6),
        bias in prop::collection::vec(-0.5..0.5f64, 6),
        seed in any::<u64>(),
    ) {
        let mut cfg = SimConfig::paper();
        cfg.runs = conic_plan(&[10.0, -10.0, 20.0], &[10.0, 20.0], &cyclic_mounts(3), 12.0);
        cfg.gyro_noise_deg_s = 0.002;
        cfg.accel_noise_g = 2e-5;
        cfg.seed = seed;
        let v = &mut cfg.truth.values;
        v.clear();
        let (mut o, mut d) = (0, 0);
        for (sensor, letter) in [(SensorKind::Gyro, "c"), (SensorKind::Accel, "k")] {
            for i in 0..3 {
                for j in 0..3 {
                    let name = crosscal::model::matrix_name(sensor, letter, i, j);
                    if i == j { v.insert(name, diag[d]); d += 1; } else { v.insert(name, off[o]); o += 1; }
                }
            }
        }
        for i in 0..3 {
            for j in 0..3 {
                v.insert(crosscal::model::matrix_name(SensorKind::Gyro, "e", i, j), eps[3 * i + j]);
            }
            v.insert(format!("gyro.b_{}", ['x', 'y', 'z'][i]), bias[i] * 0.01);
            v.insert(format!("accel.b_{}", ['x', 'y', 'z'][i]), bias[3 + i] * 0.1);
        }
        let fit = fit_session(&cfg.generate(), &Model::default_model(), &FitOptions::default()).unwrap();
        for c in fit.gyro.coefficients.iter().chain(&fit.accel.coefficients) {
            let t = cfg.truth.value(&c.name).unwrap();
            let se = c.std_error.unwrap();
            prop_assert!((c.value - t).abs() < 5.0 * se, "{} = {} ± {se}, true {t}", c.name, c.value);
        }
    }
}

/// Structure-aware mutations of a JSON document: at a chosen place, a huge, negative, zero
/// or overflowing number, a long string, null, an empty list, a deleted key, an unknown
/// field, or a key written twice.
#[derive(Debug, Clone, Copy)]
enum JsonEdit {
    Huge,
    NegativeHuge,
    Zero,
    Overflow,
    LongString,
    Null,
    EmptyList,
    Delete,
    ExtraField,
    DuplicateKey,
}

fn json_edits() -> impl Strategy<Value = Vec<(usize, JsonEdit)>> {
    let edit = prop_oneof![
        Just(JsonEdit::Huge),
        Just(JsonEdit::NegativeHuge),
        Just(JsonEdit::Zero),
        Just(JsonEdit::Overflow),
        Just(JsonEdit::LongString),
        Just(JsonEdit::Null),
        Just(JsonEdit::EmptyList),
        Just(JsonEdit::Delete),
        Just(JsonEdit::ExtraField),
        Just(JsonEdit::DuplicateKey),
    ];
    prop::collection::vec((any::<usize>(), edit), 1..4)
}

/// Paths (object keys and list indices) of every value in `v`, depth first.
fn places(v: &serde_json::Value, here: &mut Vec<serde_json::Value>, out: &mut Vec<Vec<serde_json::Value>>) {
    out.push(here.clone());
    match v {
        serde_json::Value::Object(m) => {
            for (k, x) in m {
                here.push(serde_json::json!(k));
                places(x, here, out);
                here.pop();
            }
        }
        serde_json::Value::Array(a) => {
            for (i, x) in a.iter().enumerate() {
                here.push(serde_json::json!(i));
                places(x, here, out);
                here.pop();
            }
        }
        _ => {}
    }
}

fn at<'a>(v: &'a mut serde_json::Value, path: &[serde_json::Value]) -> Option<&'a mut serde_json::Value> {
    let mut cur = v;
    for p in path {
        cur = match p {
            serde_json::Value::String(k) => cur.get_mut(k.as_str())?,
            serde_json::Value::Number(i) => cur.get_mut(i.as_u64()? as usize)?,
            _ => return None,
        };
    }
    Some(cur)
}

/// `base` with the edits applied, as text (duplicate keys and overflowing numbers are made
/// in the text, which a JSON value cannot hold).
fn mutate_json(base: &str, edits: &[(usize, JsonEdit)]) -> String {
    let mut v: serde_json::Value = serde_json::from_str(base).unwrap();
    let mut text_edits = Vec::new();
    for &(k, e) in edits {
        let mut all = Vec::new();
        places(&v, &mut Vec::new(), &mut all);
        let path = all[k % all.len()].clone();
        let parent_is_object = path.last().is_some_and(|p| p.is_string());
        match e {
            JsonEdit::Delete if parent_is_object => {
                let key = path.last().and_then(|p| p.as_str()).unwrap_or("").to_string();
                if let Some(serde_json::Value::Object(m)) = at(&mut v, &path[..path.len() - 1]) {
                    m.remove(&key);
                }
            }
            JsonEdit::ExtraField => {
                if let Some(serde_json::Value::Object(m)) = at(&mut v, &path) {
                    m.insert("unexpected_field".into(), serde_json::json!([1, "x"]));
                }
            }
            JsonEdit::DuplicateKey | JsonEdit::Overflow => text_edits.push((k, e)),
            _ => {
                if let Some(x) = at(&mut v, &path) {
                    *x = match e {
                        JsonEdit::Huge => serde_json::json!(1e300),
                        JsonEdit::NegativeHuge => serde_json::json!(-1e300),
                        JsonEdit::Zero => serde_json::json!(0),
                        JsonEdit::LongString => serde_json::json!("y".repeat(5000)),
                        JsonEdit::Null => serde_json::Value::Null,
                        _ => serde_json::json!([]),
                    };
                }
            }
        }
    }
    let mut text = serde_json::to_string_pretty(&v).unwrap();
    for (k, e) in text_edits {
        match e {
            // A key written again in its object: `"key": value` becomes `"key": 1, "key": value`.
            JsonEdit::DuplicateKey => {
                let keys: Vec<usize> = text.match_indices("\": ").map(|(i, _)| i).collect();
                if let Some(&end) = keys.get(k % keys.len().max(1)) {
                    if let Some(start) = text[..end].rfind('"') {
                        let key = text[start..=end].to_string();
                        text.insert_str(start, &format!("{key}: 1, "));
                    }
                }
            }
            _ => {
                let nums: Vec<usize> = text
                    .match_indices(": ")
                    .map(|(i, _)| i + 2)
                    .filter(|&i| text[i..].starts_with(|c: char| c.is_ascii_digit()))
                    .collect();
                if let Some(&i) = nums.get(k % nums.len().max(1)) {
                    text.insert_str(i, "9e400+");
                    text = text.replacen("9e400+", "9e400", 1);
                    let end = text[i + 5..]
                        .find(|c: char| !(c.is_ascii_digit() || ".eE+-".contains(c)))
                        .map_or(text.len(), |e| i + 5 + e);
                    text.replace_range(i + 5..end, "");
                }
            }
        }
    }
    text
}

const RULES: &str = r#"{ "format": "crosscal-rules/1",
  "rules": [
    { "kind": "coefficient", "select": "gyro.c_*", "max_abs_deviation": 0.02 },
    { "kind": "std_error", "select": "*", "max": 1e-3 },
    { "kind": "noise", "sensor": "gyro", "term": "white", "max": 0.2, "unit": "deg/sqrt(h)" },
    { "kind": "residual", "sensor": "accel", "max_pct": 0.01 },
    { "kind": "reduction", "sensor": "gyro", "min": 10 },
    { "kind": "adequate" } ] }"#;

proptest! {
    #![proptest_config(ProptestConfig { cases: 6_000, failure_persistence: None, ..ProptestConfig::default() })]

    /// A manifest read after structure-aware damage either is refused or keeps every
    /// number within the manifest's limits.
    #[test]
    fn manifest_reader_survives_structured_damage(e in json_edits()) {
        let text = mutate_json(MANIFEST, &e);
        if let Ok(m) = parse_manifest(Path::new("s.json"), &text) {
            let lim = crosscal::session::LIMITS;
            prop_assert!((lim.g_m_s2.0..=lim.g_m_s2.1).contains(&m.g_m_s2));
            prop_assert!(!m.runs.is_empty() && m.runs.len() <= lim.runs);
            for r in &m.runs {
                if let crosscal::session::MotionSpec::Conic { cone_angle_deg, rate_deg_s, phase_deg } = r.motion {
                    prop_assert!(rate_deg_s.abs() <= lim.rate_deg_s && phase_deg.is_finite());
                    prop_assert!((0.0..=90.0).contains(&cone_angle_deg));
                }
                prop_assert!(r.temperature_c.is_none_or(|t| t.is_finite()));
            }
        }
    }

    /// Rules read after damage are refused or parse; evaluating them never panics.
    #[test]
    fn rules_reader_survives_structured_damage(e in json_edits()) {
        let text = mutate_json(RULES, &e);
        let _ = crosscal::check::rules::Rules::parse(Path::new("r.json"), &text);
    }
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 1_500, failure_persistence: None, ..ProptestConfig::default() })]

    /// A profile that survives structure-aware damage and still loads can correct: its
    /// matrices invert and a sample comes out finite.
    #[test]
    fn profile_reader_survives_structured_damage(e in json_edits()) {
        thread_local!(static JSON: String = small_profile_json());
        let text = JSON.with(|j| mutate_json(j, &e));
        if let Ok(p) = Profile::from_json(Path::new("p.json"), &text) {
            let cal = crosscal::correct::Calibration::from_profile(&p);
            prop_assert!(cal.is_ok(), "{:?}", cal.err());
            let cal = cal.unwrap();
            let r = crosscal::correct::correct_offline(&cal, &[0.0, 0.01, 0.02], &[[0.1, 0.2, 0.3]; 3], &[[0.0, 0.0, 9.8]; 3], Some(&[20.0; 3]));
            if let Ok(c) = r {
                prop_assert!(c.w_rad_s.iter().chain(&c.a_m_s2).all(|v| v.iter().all(|x| x.is_finite())));
            }
        }
    }
}
