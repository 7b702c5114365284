//! Temperature calibration (issue #24): the profile records the temperature range it was
//! calibrated over, and the correction outside it clamps (default), extrapolates or refuses,
//! offline and streaming alike, and says how many samples were outside.

use crate::common::{run_in, run_ok};
use crosscal::correct::{correct_offline, correct_streaming, Calibration, CorrectError, TempPolicy};
use crosscal::session::Session;

const SET: [&str; 6] = ["--set", "gyro.tb_x=1e-4", "--set", "gyro.tb_y=-2e-4", "--set", "gyro.tb_z=5e-5"];

fn simulate(d: &std::path::Path, out: &str, temps: &str) {
    let mut args = vec!["simulate", "-o", out, "--temperature", temps, "--hidden", "gyro-temp-bias"];
    args.extend_from_slice(&SET);
    run_ok(d, &args);
}

#[test]
fn a_profile_knows_its_temperature_range_and_correction_clamps_outside_it() {
    let dir = tempfile::tempdir().unwrap_or_else(|e| panic!("{e}"));
    let d = dir.path();
    simulate(d, "cal", "10,40");
    simulate(d, "cold", "-35,0");
    run_ok(d, &["fit", "cal/session.json", "--effect", "gyro-temp-bias", "--out", "store"]);
    let (path, p) = crate::common::only_profile(&d.join("store"));
    let range = p.temperature_range_c().unwrap_or_else(|| panic!("no range in {}", path.display()));
    assert!((range[0] - 10.0).abs() < 1e-9 && (range[1] - 40.0).abs() < 1e-9, "{range:?}");
    assert!(p.uses_temperature());

    let cold = Session::load(&d.join("cold/session.json")).unwrap_or_else(|e| panic!("{e}"));
    let run = &cold.runs[0];
    let (t, g, a) = (&run.rec.t_s, &run.rec.gyro, &run.rec.accel);
    let temps = run.rec.temp_c.clone().unwrap_or_default();
    let n = temps.len();
    let mut cal = Calibration::from_profile(&p).unwrap_or_else(|e| panic!("{e}"));
    // Clamp (default): every sample is outside, and each is corrected as at 10 °C exactly.
    let clamped = correct_offline(&cal, t, g, a, Some(&temps)).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(clamped.temp_outside.samples, n as u64);
    assert_eq!(clamped.temp_outside.first.map(|f| f.1.to_bits()), Some(temps[0].to_bits()));
    let w = clamped.temp_outside.warning().unwrap_or_default();
    assert!(w.contains(&format!("{n} samples")) && w.contains("10.0..40.0"), "{w}");
    let at_edge = vec![10.0; n];
    cal.temp_policy = TempPolicy::Extrapolate;
    let edge = correct_offline(&cal, t, g, a, Some(&at_edge)).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(edge.temp_outside.samples, 0);
    for k in 0..n {
        assert_eq!(clamped.w_rad_s[k].map(f64::to_bits), edge.w_rad_s[k].map(f64::to_bits), "sample {k}");
    }
    // Extrapolate: the linear term evaluated as fitted, counted; the simulated unit's bias is
    // linear in T, so here extrapolation recovers the truth and clamping leaves tb (T − 10).
    let extra = correct_offline(&cal, t, g, a, Some(&temps)).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(extra.temp_outside.samples, n as u64);
    let k = 0;
    let dt = temps[k] - 10.0;
    let diff = extra.w_rad_s[k][1] - clamped.w_rad_s[k][1];
    // u = C ω + tb (T − 20): the two corrections differ by C⁻¹ tb (T − 10), C within 3 % of I.
    let want = -(-2e-4) * dt;
    assert!((diff / want - 1.0).abs() < 0.03, "difference {diff} for ΔT {dt}, expected about {want}");
    // Error: refused, naming the samples.
    cal.temp_policy = TempPolicy::Error;
    match correct_offline(&cal, t, g, a, Some(&temps)) {
        Err(CorrectError::OutOfRange(m)) => assert!(m.contains("refused"), "{m}"),
        other => panic!("expected OutOfRange, got {:?}", other.map(|c| c.temp_outside)),
    }
    assert!(matches!(correct_streaming(&cal, t, g, a, Some(&temps)), Err(CorrectError::OutOfRange(_))));
    // Streaming clamps as offline does: the same count, the same values as at the edge.
    cal.temp_policy = TempPolicy::Clamp;
    let s = correct_streaming(&cal, t, g, a, Some(&temps)).unwrap_or_else(|e| panic!("{e}"));
    cal.temp_policy = TempPolicy::Extrapolate;
    let s_edge = correct_streaming(&cal, t, g, a, Some(&at_edge)).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(s.temp_outside.samples, n as u64);
    assert_eq!(
        s.w_rad_s.iter().map(|v| v.map(f64::to_bits)).collect::<Vec<_>>(),
        s_edge.w_rad_s.iter().map(|v| v.map(f64::to_bits)).collect::<Vec<_>>()
    );
    // Inside the range nothing is counted.
    let cal_in = Calibration::from_profile(&p).unwrap_or_else(|e| panic!("{e}"));
    let warm = Session::load(&d.join("cal/session.json")).unwrap_or_else(|e| panic!("{e}"));
    let r = &warm.runs[3];
    let c = correct_offline(&cal_in, &r.rec.t_s, &r.rec.gyro, &r.rec.accel, r.rec.temp_c.as_deref())
        .unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(c.temp_outside.samples, 0);
    assert!(c.temp_outside.warning().is_none());

    // The command line: a warning by default, exit 23 with --temperature-range error.
    let prof = path.to_string_lossy().to_string();
    let (code, _, err) = run_in(d, &["correct", "--profile", &prof, "cold/cone+10.csv", "-o", "c.csv"]);
    assert_eq!(code, 0, "{err}");
    assert!(err.contains("outside the profile's calibrated range") && err.contains("clamp"), "{err}");
    let (code, _, err) =
        run_in(d, &["correct", "--profile", &prof, "cold/cone+10.csv", "-o", "e.csv", "--temperature-range", "error"]);
    assert_eq!(code, 23, "{err}");
    assert!(!d.join("e.csv").exists(), "a refused correction writes nothing");
    let (code, _, err) = run_in(
        d,
        &[
            "correct",
            "--profile",
            &prof,
            "cold/cone+10.csv",
            "-o",
            "s.csv",
            "--mode",
            "streaming",
            "--temperature-range",
            "error",
        ],
    );
    assert_eq!(code, 23, "{err}");
    // check flags every run outside the range; diagnose --profile names them; a run inside
    // is neither.
    let out = run_in(d, &["check", "cold/session.json", "--profile", &prof]).1;
    assert_eq!(out.matches("OUTSIDE THE CALIBRATED TEMPERATURE RANGE").count(), 18, "{out}");
    let out = run_in(d, &["check", "cal/session.json", "--profile", &prof]).1;
    assert!(!out.contains("OUTSIDE THE CALIBRATED"), "{out}");
    let out = run_ok(d, &["diagnose", "cold/session.json", "--profile", &prof]);
    assert!(out.contains("OUT OF THE CALIBRATED TEMPERATURE RANGE (10.0..40.0 degC): 18 of 18 runs"), "{out}");
    let out = run_ok(d, &["diagnose", "cal/session.json", "--profile", &prof]);
    assert!(!out.contains("OUT OF THE CALIBRATED"), "{out}");
}

/// A profile without temperature terms has no range to guard, whatever the data's temperatures.
#[test]
fn a_profile_without_temperature_terms_guards_nothing() {
    let dir = tempfile::tempdir().unwrap_or_else(|e| panic!("{e}"));
    let d = dir.path();
    run_ok(d, &["simulate", "-o", "cal", "--temperature", "10,40"]);
    run_ok(d, &["fit", "cal/session.json", "--out", "store"]);
    let (_, p) = crate::common::only_profile(&d.join("store"));
    assert!(!p.uses_temperature());
    assert!(p.temperature_range_c().is_some(), "the range is still recorded");
    let cal = Calibration::from_profile(&p).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(cal.temp_range_c, None);
}

/// A cubic gyro bias over −20 … +70 °C (the range and degree ArduPilot and PX4 fit) is
/// recovered term by term, each within 3 standard errors of its true value.
#[test]
fn a_cubic_temperature_bias_is_recovered_term_by_term() {
    let dir = tempfile::tempdir().unwrap_or_else(|e| panic!("{e}"));
    let d = dir.path();
    let truth = &crate::common::THERMAL_BIASES[..9];
    let owned: Vec<(String, f64)> = truth.iter().map(|(n, v)| (n.to_string(), *v)).collect();
    let effects = ["gyro-temp-bias", "gyro-temp-bias2", "gyro-temp-bias3"];
    let sweep = ["--temperature", "-20,70", "--gyro-noise", "0.002", "--accel-noise", "0.0002"];
    crate::common::simulate_hidden(d, "sweep", &effects, &owned, &sweep);
    let (_, p) = crate::common::fit_into_store(d, "sweep/session.json", &effects);
    for (name, want) in truth {
        let c = p.gyro.get(name).unwrap_or_else(|| panic!("{name} missing"));
        let se = c.std_error.unwrap_or(f64::INFINITY);
        assert!((c.value - want).abs() < 3.0 * se, "{name}: {} ± {se} vs truth {want}", c.value);
        assert!(se < 0.02 * want.abs(), "{name}: standard error {se} too large for {want}");
    }
    let range = p.temperature_range_c().unwrap_or([0.0, 0.0]);
    assert!((range[0] + 20.0).abs() < 0.01 && (range[1] - 70.0).abs() < 0.01, "{range:?}");
}

/// A scale factor curved in temperature (linear + quadratic tempco on every axis of both
/// sensors) is recovered term by term within 3 standard errors.
#[test]
fn a_curved_scale_factor_tempco_is_recovered_term_by_term() {
    let dir = tempfile::tempdir().unwrap_or_else(|e| panic!("{e}"));
    let d = dir.path();
    let truth: Vec<(String, f64)> = ["gyro", "accel"]
        .iter()
        .flat_map(|s| {
            ["x", "y", "z"].iter().enumerate().flat_map(move |(i, a)| {
                let k = i as f64 + 1.0;
                [(format!("{s}.ts_{a}"), 1e-4 * k), (format!("{s}.ts2_{a}"), -2e-6 * k)]
            })
        })
        .collect();
    let effects = ["gyro-temp-scale", "gyro-temp-scale2", "accel-temp-scale", "accel-temp-scale2"];
    let sweep = ["--temperature", "-20,70", "--gyro-noise", "0.002", "--accel-noise", "0.0002"];
    crate::common::simulate_hidden(d, "sweep", &effects, &truth, &sweep);
    let (_, p) = crate::common::fit_into_store(d, "sweep/session.json", &effects);
    for (name, want) in &truth {
        let sensor = if name.starts_with("gyro") { &p.gyro } else { &p.accel };
        let c = sensor.get(name).unwrap_or_else(|| panic!("{name} missing"));
        let se = c.std_error.unwrap_or(f64::INFINITY);
        assert!((c.value - want).abs() < 3.0 * se, "{name}: {} ± {se} vs truth {want}", c.value);
        assert!(se < 0.05 * want.abs(), "{name}: standard error {se} too large for {want}");
    }
}

/// The unit of the issue: gyro bias cubic, accelerometer bias quadratic
/// ([`crate::common::THERMAL_BIASES`]), gyro scale linear in temperature (these), over a −20 … +70 °C
/// sweep.
const SWEEP_SCALES: [(&str, f64); 3] = [("gyro.ts_x", 1e-4), ("gyro.ts_y", -1e-4), ("gyro.ts_z", 2e-4)];

/// The effects the sweep unit sets.
const SWEEP_EFFECTS: [&str; 6] =
    ["gyro-temp-bias", "gyro-temp-bias2", "gyro-temp-bias3", "accel-temp-bias", "accel-temp-bias2", "gyro-temp-scale"];

/// The sweep unit (or, with `hidden` false, a unit without temperature terms) over `temps`.
fn simulate_sweep(d: &std::path::Path, out: &str, temps: &str, seed: &str, hidden: bool) {
    let extra = ["--temperature", temps, "--seed", seed, "--gyro-noise", "0.002", "--accel-noise", "0.0002"];
    let truth: Vec<(String, f64)> =
        crate::common::THERMAL_BIASES.iter().chain(&SWEEP_SCALES).map(|(n, v)| (n.to_string(), *v)).collect();
    let (hidden, truth): (&[&str], &[(String, f64)]) = if hidden { (&SWEEP_EFFECTS, &truth) } else { (&[], &[]) };
    crate::common::simulate_hidden(d, out, hidden, truth, &extra);
}

fn steps(d: &std::path::Path, session: &str) -> (Vec<String>, serde_json::Value) {
    let json = run_ok(d, &["diagnose", session, "--json"]);
    let v: serde_json::Value = serde_json::from_str(&json).unwrap_or_else(|e| panic!("{e}: {json}"));
    let names = v["steps"]
        .as_array()
        .map(|s| s.iter().filter_map(|x| x["effect"].as_str().map(str::to_string)).collect())
        .unwrap_or_default();
    (names, v)
}

/// Each temperature step's degree report (diagnose --json): every degree 0 … 3 scored on
/// the 18 left-out runs (each run preferring one degree), the chosen degree the step's, and
/// its highest power significant on every axis (|z| > 5: the true polynomial's top power).
fn assert_degree_reports(v: &serde_json::Value, seed: &str) {
    for st in v["steps"].as_array().into_iter().flatten() {
        let effect = st["effect"].as_str().unwrap_or_default();
        let c = &st["score"]["degree"];
        assert!(c.is_object(), "seed {seed}: {effect} has no degree report");
        assert_eq!(c["degree"].as_u64(), Some(effect.split('+').count() as u64), "seed {seed}: {c}");
        let scores = c["scores"].as_array().cloned().unwrap_or_default();
        assert_eq!(scores.len(), 4, "seed {seed}: degrees 0..3 for {effect}: {c}");
        let folds: u64 = scores.iter().filter_map(|s| s["folds_preferring"].as_u64()).sum();
        assert!(c["folds"].as_u64() == Some(18) && folds == 18, "seed {seed}: {c}");
        let z: Vec<f64> = c["top_power_z"].as_array().into_iter().flatten().filter_map(|z| z.as_f64()).collect();
        assert!(z.len() == 3 && z.iter().all(|z| z.abs() > 5.0), "seed {seed} {effect}: {z:?}");
        let why = st["score"]["explanation"].as_str().unwrap_or_default();
        assert!(why.contains("left-out runs are predicted best at degree"), "{why}");
        eprintln!("seed {seed} {effect}: {}", why.split(". ").next().unwrap_or_default());
    }
}

/// diagnose finds each temperature term at its true degree (cubic, quadratic, linear) and
/// nothing else, on three seeds; a clean sweep gets no temperature effect; the profile
/// fitted with what diagnose found corrects a run at other temperatures to the noise.
#[test]
fn diagnose_finds_each_temperature_term_at_its_true_degree_and_nothing_on_a_clean_sweep() {
    let dir = tempfile::tempdir().unwrap_or_else(|e| panic!("{e}"));
    let d = dir.path();
    let want =
        ["gyro-temp-bias+gyro-temp-bias2+gyro-temp-bias3", "gyro-temp-scale", "accel-temp-bias+accel-temp-bias2"];
    let mut false_discoveries = 0;
    for seed in ["1", "2", "3"] {
        let out = format!("sweep{seed}");
        simulate_sweep(d, &out, "-20,70", seed, true);
        let (mut found, v) = steps(d, &format!("{out}/session.json"));
        assert_degree_reports(&v, seed);
        found.sort();
        let mut expected: Vec<String> = want.iter().map(|s| s.to_string()).collect();
        expected.sort();
        assert_eq!(found, expected, "seed {seed}");
        let clean = format!("clean{seed}");
        simulate_sweep(d, &clean, "-20,70", seed, false);
        false_discoveries += steps(d, &format!("{clean}/session.json")).0.len();
    }
    assert_eq!(false_discoveries, 0, "effects found on clean sweeps");
    // Fit what diagnose found; a run at 0 … 60 °C the fit never saw is corrected to the noise.
    let (path, _) = crate::common::fit_into_store(d, "sweep1/session.json", &want);
    simulate_sweep(d, "held", "0,60", "9", true);
    let out = run_ok(d, &["check", "held/session.json", "--profile", &path.to_string_lossy()]);
    assert!(out.contains("PASS") && out.matches("yes (noise-limited)").count() == 6, "{out}");
}

/// `accept` judges temperature behaviour: the bias change the fitted polynomial makes over
/// the calibrated range, and the range the calibration covers.
#[test]
fn accept_rules_on_temperature_behaviour() {
    let dir = tempfile::tempdir().unwrap_or_else(|e| panic!("{e}"));
    let d = dir.path();
    simulate(d, "cal", "10,40");
    run_ok(d, &["fit", "cal/session.json", "--effect", "gyro-temp-bias", "--out", "store"]);
    let (path, _) = crate::common::only_profile(&d.join("store"));
    let prof = path.to_string_lossy().to_string();
    // The y axis: |tb_y| = 2e-4 rad/s/°C over 30 °C is a change of 6e-3 rad/s, the largest.
    let judge = |rule: &str| {
        std::fs::write(d.join("rules.json"), format!(r#"{{"format":"crosscal-rules/1","rules":[{rule}]}}"#))
            .unwrap_or_else(|e| panic!("{e}"));
        let (code, out, err) = run_in(d, &["accept", &prof, "--rules", "rules.json"]);
        (code, format!("{out}{err}"))
    };
    let (code, out) = judge(r#"{"kind":"temperature","sensor":"gyro","max_bias_change":7e-3}"#);
    assert_eq!(code, 0, "{out}");
    assert!(out.contains("6.0000e-3 (axis y)"), "{out}");
    let (code, out) = judge(r#"{"kind":"temperature","sensor":"gyro","max_bias_change":5e-3}"#);
    assert_eq!(code, 1, "a 6e-3 change must fail a 5e-3 limit: {out}");
    let (code, out) = judge(r#"{"kind":"temperature","sensor":"gyro","covers_c":[15,35]}"#);
    assert_eq!(code, 0, "{out}");
    let (code, out) = judge(r#"{"kind":"temperature","sensor":"gyro","covers_c":[-20,70]}"#);
    assert_eq!(code, 1, "10..40 does not cover -20..70: {out}");
    let (code, out) = judge(r#"{"kind":"temperature","sensor":"accel","max_bias_change":1}"#);
    assert_eq!(code, 1, "no accelerometer temperature terms: unknown, not passed: {out}");
    let (code, out) = judge(r#"{"kind":"temperature","sensor":"gyro","max_bias_chnge":1}"#);
    assert_eq!(code, 20, "a misspelt field is refused: {out}");
}

/// `simulate --temperature` takes breakpoints: a sweep that warms then cools, and plateaus.
#[test]
fn simulated_temperature_follows_its_breakpoints() {
    let dir = tempfile::tempdir().unwrap_or_else(|e| panic!("{e}"));
    let d = dir.path();
    run_ok(d, &["simulate", "-o", "wc", "--temperature", "10,40,10"]);
    let s = Session::load(&d.join("wc/session.json")).unwrap_or_else(|e| panic!("{e}"));
    let temps: Vec<f64> = s.runs.iter().flat_map(|r| r.rec.temp_c.clone().unwrap_or_default()).collect();
    let (first, last) = (temps[0], temps[temps.len() - 1]);
    let peak = temps.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    let at_peak = temps.iter().position(|&t| t >= peak).unwrap_or(0);
    assert!(
        (first - 10.0).abs() < 1e-9 && (last - 10.0).abs() < 0.01 && (peak - 40.0).abs() < 0.01,
        "{first} {peak} {last}"
    );
    assert!(
        (at_peak as f64 / temps.len() as f64 - 0.5).abs() < 0.01,
        "the peak is half-way: sample {at_peak} of {}",
        temps.len()
    );
    assert!(temps[..at_peak].windows(2).all(|w| w[1] >= w[0]) && temps[at_peak..].windows(2).all(|w| w[1] <= w[0]));
    run_ok(d, &["simulate", "-o", "plateau", "--temperature", "20,20,60,60"]);
    let s = Session::load(&d.join("plateau/session.json")).unwrap_or_else(|e| panic!("{e}"));
    let temps: Vec<f64> = s.runs.iter().flat_map(|r| r.rec.temp_c.clone().unwrap_or_default()).collect();
    let n = temps.len();
    assert!(temps[..n / 3 - 1].iter().all(|&t| (t - 20.0).abs() < 1e-9), "first third at 20 °C");
    assert!(temps[2 * n / 3 + 1..].iter().all(|&t| (t - 60.0).abs() < 1e-9), "last third at 60 °C");
    let (code, _, err) = run_in(d, &["simulate", "-o", "bad", "--temperature", "25"]);
    assert_ne!(code, 0, "{err}");
    assert!(err.contains("(--temperature) expects START,END"), "{err}");
}
