//! Identifiability: what a session cannot determine is named, with the run that fixes it.

use crate::common::fit_session;
use crosscal::estimate::{CoefStatus, FitOptions};
use crosscal::model::Model;
use crosscal::simulate::{conic_plan, cyclic_mounts, SimConfig};

#[test]
fn without_remounts_e_xz_is_unidentifiable_and_the_rest_fits() {
    let mut cfg = SimConfig::paper();
    cfg.runs = conic_plan(&[10.0, -10.0, 20.0], &[10.0, 20.0], &cyclic_mounts(1), 36.0);
    let session = cfg.generate();
    let fit = fit_session(&session, &Model::default_model(), &FitOptions::default()).unwrap();
    let held: Vec<&str> = fit.gyro.unidentifiable.iter().map(|u| u.held.as_str()).collect();
    for name in ["gyro.e_xz", "gyro.e_yz", "gyro.e_zz"] {
        assert!(held.contains(&name), "{name} not reported: {held:?}");
        assert_eq!(fit.gyro.get(name).unwrap().status, CoefStatus::Unidentifiable);
        let u = fit.gyro.unidentifiable.iter().find(|u| u.held == name).unwrap();
        assert!(u.remedy.contains("re-mount"), "{}", u.remedy);
    }
    assert_eq!(held.len(), 3, "{held:?}");
    // Everything else is still recovered. The true e_xz = 0.001 s cannot be seen (ε_z ≡ 0), so
    // holding it at 0 costs nothing on these runs.
    for c in fit.gyro.coefficients.iter().chain(&fit.accel.coefficients) {
        if c.status == CoefStatus::Fitted {
            let truth = cfg.truth.value(&c.name).unwrap();
            assert!((c.value - truth).abs() < 1e-9, "{} = {} (true {truth})", c.name, c.value);
        }
    }
}

#[test]
fn single_run_names_every_lost_term_with_a_remedy() {
    let mut cfg = SimConfig::paper();
    cfg.runs.truncate(1);
    let session = cfg.generate();
    let fit = fit_session(&session, &Model::default_model(), &FitOptions::default()).unwrap();
    let held: Vec<&str> = fit.gyro.unidentifiable.iter().map(|u| u.held.as_str()).collect();
    assert!(held.contains(&"gyro.e_xz"), "{held:?}");
    // One run: ε is a fixed multiple of ω and ω_z, a_z are constant, so biases and ε terms
    // blur with the rate couplings; each lost combination is named with a remedy.
    assert!(fit.gyro.unidentifiable.len() >= 6, "{:?}", fit.gyro.unidentifiable);
    assert!(!fit.accel.unidentifiable.is_empty());
    for u in fit.gyro.unidentifiable.iter().chain(&fit.accel.unidentifiable) {
        assert!(!u.remedy.is_empty() && !u.reason.is_empty());
    }
    // The fit still returns finite values and standard errors for what it did fit.
    for c in fit.gyro.coefficients.iter().chain(&fit.accel.coefficients) {
        assert!(c.value.is_finite());
        if c.status == CoefStatus::Fitted {
            assert!(c.std_error.unwrap().is_finite());
        }
    }
}

#[test]
fn a_second_rate_or_direction_separates_epsilon_from_rate_coupling() {
    // One mount, one rate: ε_x = ω_s ω_y and ε_y = −ω_s ω_x in every run, so the ε terms
    // alias with the rate couplings (and ε_z ≡ 0).
    let mut cfg = SimConfig::paper();
    cfg.runs = conic_plan(&[10.0], &[10.0, 20.0], &cyclic_mounts(1), 36.0);
    let fit = fit_session(&cfg.generate(), &Model::default_model(), &FitOptions::default()).unwrap();
    assert!(
        fit.gyro.unidentifiable.iter().any(|u| u.remedy.contains("another stand rate")),
        "{:?}",
        fit.gyro.unidentifiable
    );
    // The opposite direction breaks the tie; only the ε_z terms remain (no re-mount).
    cfg.runs = conic_plan(&[10.0, -10.0], &[10.0, 20.0], &cyclic_mounts(1), 36.0);
    let fit = fit_session(&cfg.generate(), &Model::default_model(), &FitOptions::default()).unwrap();
    let held: Vec<&str> = fit.gyro.unidentifiable.iter().map(|u| u.held.as_str()).collect();
    assert_eq!(held.len(), 3, "{held:?}");
    assert!(held.iter().all(|h| h.ends_with('z') && h.starts_with("gyro.e_")), "{held:?}");
}

/// `plan --design`: the runs a manifest describes. A recorded session predicts exactly what
/// the factorial flags that made it predict; a design of two planned runs (`duration_s`, no
/// recordings) names what those runs cannot identify; a protocol run is refused by name.
#[test]
fn plan_predicts_the_design_a_manifest_describes() {
    let d = tempfile::tempdir().unwrap();
    let run = |args: &[&str]| crate::common::run_ok(d.path(), args);
    run(&["simulate", "-o", "s", "--gyro-noise", "0.002"]);
    let noise = ["--arw", "0.012", "--vrw", "0.0011768", "--json"];
    let factorial = run(&[&["plan"][..], &noise].concat());
    let designed = run(&[&["plan", "--design", "s/session.json"][..], &noise].concat());
    assert_eq!(factorial, designed, "the recorded session is the factorial plan");
    let mut m: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(d.path().join("s/session.json")).unwrap()).unwrap();
    let runs: Vec<serde_json::Value> = m["runs"].as_array().unwrap()[..2]
        .iter()
        .map(|r| {
            let mut r = r.clone();
            r["duration_s"] = serde_json::json!(36.0);
            r["file"] = serde_json::json!("not-yet-recorded.csv");
            r
        })
        .collect();
    m["runs"] = serde_json::Value::Array(runs);
    std::fs::write(d.path().join("two.json"), m.to_string()).unwrap();
    let out = run(&["plan", "--design", "two.json", "--arw", "0.012", "--vrw", "0.0011768"]);
    assert!(out.contains("plan: 2 runs, 7200 samples"), "{out}");
    assert!(out.contains("UNIDENTIFIABLE gyro.e_xz"), "two runs in one mount cannot see ε_z:\n{out}");
    m["runs"][0]["motion"] = serde_json::json!({"kind": "rotation", "axis_stand": [0, 0, 1], "angle_deg": 360});
    m["format"] = serde_json::json!("crosscal-session/2");
    std::fs::write(d.path().join("prot.json"), m.to_string()).unwrap();
    let (code, _, err) = crate::common::run_in(d.path(), &["plan", "--design", "prot.json"]);
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("plan predicts conic and static stand runs"), "{err}");
}
