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
    let opts = ReadOptions { reference, strict: false };
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
