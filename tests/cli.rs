//! The real binary, in fresh temporary folders.

use crate::common::run_in;
use std::path::Path;

fn simulate(dir: &Path, extra: &[&str]) {
    let mut args = vec!["simulate", "--preset", "paper", "-o", "demo", "--duration", "12"];
    args.extend_from_slice(extra);
    let (code, out, err) = run_in(dir, &args);
    assert_eq!(code, 0, "{out}{err}");
    assert!(dir.join("demo/session.json").is_file() && dir.join("demo/cone+10.csv").is_file());
}

fn profiles(dir: &Path) -> Vec<std::path::PathBuf> {
    let mut v: Vec<_> = std::fs::read_dir(dir.join("calib-profiles/I1426-0042"))
        .map(|rd| rd.filter_map(|e| e.ok()).map(|e| e.path()).collect())
        .unwrap_or_default();
    v.sort();
    v
}

#[test]
fn simulate_fit_correct_check() {
    let d = tempfile::tempdir().unwrap();
    let dir = d.path();
    simulate(dir, &["--gyro-noise", "0.002", "--accel-noise", "2e-5"]);
    let snapshot = || {
        let mut v: Vec<(std::path::PathBuf, Vec<u8>)> = std::fs::read_dir(dir.join("demo"))
            .unwrap()
            .map(|e| e.unwrap().path())
            .map(|p| (p.clone(), std::fs::read(&p).unwrap()))
            .collect();
        v.sort();
        v
    };
    let before = snapshot();
    let (code, out, err) = run_in(dir, &["fit", "demo/session.json", "--out", "calib-profiles/"]);
    assert_eq!(code, 0, "{out}{err}");
    assert!(out.contains("gyro.c_xy") && out.contains(" ± "), "{out}");
    assert!(out.contains("profile written to"), "{out}");
    // A stand session with a linear model is fitted from streams; a nonlinear effect needs
    // the samples in memory.
    assert!(out.lines().next().is_some_and(|l| l.contains("(streamed)")), "{out}");
    let (code, out, err) = run_in(dir, &["fit", "demo/session.json", "--dry-run", "--effect", "time-delay"]);
    assert_eq!(code, 0, "{out}{err}");
    assert!(out.lines().next().is_some_and(|l| !l.contains("(streamed)")), "{out}");
    let (code, _, err) = run_in(dir, &["fit", "demo/session.json", "--dry-run", "--stream", "--effect", "time-delay"]);
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("in memory"), "{err}");
    let p = profiles(dir);
    assert_eq!(p.len(), 1);
    let prof = p[0].to_string_lossy().to_string();

    // A second fit keeps the first profile.
    let first = std::fs::read(&p[0]).unwrap();
    let (code, _, _) = run_in(dir, &["fit", "demo/session.json", "--out", "calib-profiles/"]);
    assert_eq!(code, 0);
    assert_eq!(profiles(dir).len(), 2);
    assert_eq!(std::fs::read(&p[0]).unwrap(), first);

    let (code, out, err) = run_in(dir, &["correct", "--profile", &prof, "demo/cone+10.csv", "-o", "corrected.csv"]);
    assert_eq!(code, 0, "{out}{err}");
    let text = std::fs::read_to_string(dir.join("corrected.csv")).unwrap();
    assert!(text.starts_with("t,gx,gy,gz,ax,ay,az\n"));
    assert_eq!(text.lines().count(), 1 + 1200);
    // The corrected z rate of the nominal cone+10 run is ω_s (1 − cos α) = 0.1519 °/s.
    let gz: Vec<f64> = text.lines().skip(1).map(|l| l.split(',').nth(3).unwrap().parse().unwrap()).collect();
    let mean = gz.iter().sum::<f64>() / gz.len() as f64;
    let expect = 10.0 * (1.0 - 10f64.to_radians().cos());
    assert!((mean - expect).abs() < 2e-4, "{mean} vs {expect}");

    // Never overwrite the output unless asked.
    let (code, _, err) = run_in(dir, &["correct", "--profile", &prof, "demo/cone+10.csv", "-o", "corrected.csv"]);
    assert_eq!(code, 24);
    assert!(err.contains("already exists"), "{err}");

    let (code, out, err) = run_in(dir, &["check", "--profile", &prof, "demo/session.json"]);
    assert_eq!(code, 0, "{out}{err}");
    assert!(out.contains("PASS") && out.contains("reduction"), "{out}");
    let (code, out, _) = run_in(dir, &["check", "--profile", &prof, "demo/session.json", "--json"]);
    assert_eq!(code, 0);
    let v: serde_json::Value = serde_json::from_str(&out).unwrap();
    assert_eq!(v["pass"], serde_json::Value::Bool(true));
    assert_eq!(v["summary"].as_array().unwrap().len(), 6);
    // A model that leaves out a real coupling leaves a systematic error: exit code 1.
    let (code, out, err) = run_in(dir, &["fit", "demo/session.json", "--disable", "gyro.c_xy", "--out", "bad"]);
    assert_eq!(code, 0, "{out}{err}");
    assert!(out.contains("gyro.c_xy") && out.contains("(fixed)"), "{out}");
    let bad = std::fs::read_dir(dir.join("bad/I1426-0042")).unwrap().next().unwrap().unwrap().path();
    let (code, out, _) = run_in(dir, &["check", "--profile", bad.to_str().unwrap(), "demo/session.json"]);
    assert_eq!(code, 1, "{out}");
    assert!(out.contains("FAIL") && out.contains("NO"), "{out}");
    // Nothing the user gave was modified.
    assert!(before == snapshot(), "an input file changed");
}

#[test]
fn demo_prints_the_paper_table() {
    let d = tempfile::tempdir().unwrap();
    let (code, out, err) = run_in(d.path(), &["demo"]);
    assert_eq!(code, 0, "{out}{err}");
    for word in
        ["axis", "before", "after", "reduction", "paper", "pass", "11 % -> 0.4 %", "0.25 % -> 0.000006 %", "DEMO PASS"]
    {
        assert!(out.contains(word), "missing '{word}' in\n{out}");
    }
    assert_eq!(out.lines().filter(|l| l.starts_with("gyro ") || l.starts_with("accel ")).count(), 12, "{out}");
}

#[test]
fn fit_names_unidentifiable_terms_and_still_writes_a_profile() {
    let d = tempfile::tempdir().unwrap();
    let dir = d.path();
    simulate(dir, &["--mounts", "1"]);
    let (code, out, err) = run_in(dir, &["fit", "demo/session.json"]);
    assert_eq!(code, 0, "{out}{err}");
    assert!(out.contains("UNIDENTIFIABLE gyro.e_xz"), "{out}");
    assert!(out.contains("re-mount"), "{out}");
    assert_eq!(profiles(dir).len(), 1);
    let text = std::fs::read_to_string(&profiles(dir)[0]).unwrap();
    assert!(text.contains("\"status\": \"unidentifiable\""));
}

#[test]
fn bad_input_gives_file_line_column_and_its_exit_code() {
    let d = tempfile::tempdir().unwrap();
    let dir = d.path();
    simulate(dir, &["--mounts", "1", "--rates", "10", "--cone-angles", "10"]);
    let csv = dir.join("demo/cone+10.csv");
    let mut text = std::fs::read_to_string(&csv).unwrap();
    let lines: Vec<&str> = text.lines().collect();
    let mut fields: Vec<String> = lines[5].split(',').map(str::to_string).collect();
    fields[3] = "oops".into();
    let bad = fields.join(",");
    text = text.replacen(lines[5], &bad, 1);
    std::fs::write(&csv, text).unwrap();
    let (code, out, err) = run_in(dir, &["fit", "demo/session.json"]);
    assert_eq!(code, 6, "{out}{err}");
    assert!(err.contains("cone+10.csv:6:4 (gz)") && err.contains("'oops'"), "{err}");
    assert!(!dir.join("calib-profiles").exists(), "a failed fit must not write anything");

    let (code, _, err) = run_in(dir, &["fit", "missing.json"]);
    assert_eq!(code, 3);
    assert!(err.contains("missing.json"), "{err}");
    let (code, _, _) = run_in(dir, &["fit"]);
    assert_eq!(code, 2);
}

#[test]
fn diagnose_names_a_hidden_lever_arm_and_fit_then_corrects_with_it() {
    let d = tempfile::tempdir().unwrap();
    let dir = d.path();
    simulate(
        dir,
        &[
            "--gyro-noise",
            "0.002",
            "--accel-noise",
            "2e-5",
            "--hidden",
            "accel-lever-arm",
            "--set",
            "accel.r_xx=0.03",
            "--set",
            "accel.r_yy=0.04",
        ],
    );
    let (code, out, err) = run_in(dir, &["diagnose", "demo/session.json"]);
    assert_eq!(code, 0, "{out}{err}");
    assert!(out.contains("SYSTEMATIC"), "{out}");
    assert!(out.contains("step 1: add accel-lever-arm"), "{out}");
    assert!(out.contains("verdict: add accel-lever-arm"), "{out}");
    let (code, out, _) = run_in(dir, &["diagnose", "demo/session.json", "--json"]);
    assert_eq!(code, 0);
    let v: serde_json::Value = serde_json::from_str(&out).unwrap();
    assert_eq!(v["verdict"], "explained");
    assert_eq!(v["proposal"][0], "accel-lever-arm");

    let (code, out, err) = run_in(dir, &["fit", "demo/session.json", "--effect", "accel-lever-arm"]);
    assert_eq!(code, 0, "{out}{err}");
    assert!(out.contains("accel.r_xx"), "{out}");
    let prof = profiles(dir)[0].to_string_lossy().to_string();
    // The lever arm is in the profile, so the correction removes it: accelerometer passes.
    let (code, out, err) = run_in(dir, &["check", "--profile", &prof, "demo/session.json", "--json"]);
    assert_eq!(code, 0, "{out}{err}");
    let v: serde_json::Value = serde_json::from_str(&out).unwrap();
    assert_eq!(v["pass"], serde_json::Value::Bool(true), "{out}");
    let (code, _, err) = run_in(dir, &["diagnose", "demo/session.json", "--report", "report.html"]);
    assert_eq!(code, 0, "{err}");
    let html = std::fs::read_to_string(dir.join("report.html")).unwrap();
    assert!(html.starts_with("<!DOCTYPE html>") && html.matches("<svg").count() == 24, "6 channels × 4 plots");
    assert!(html.contains("residual vs cone phase") && html.contains("accel-lever-arm"));
    assert!(html.matches("residual spectrum").count() == 6 && html.contains("PSD"), "a spectrum per channel");
    assert!(!html.contains("<script") && !html.contains("src=\"http"), "self-contained");
    let (code, out, err) = run_in(dir, &["compare", "demo/session.json", "--svg", "ladder.svg"]);
    assert_eq!(code, 0, "{out}{err}");
    assert!(out.contains("paper (eqs. 3-4)") && out.contains("default") && out.contains("+ accel-lever-arm"), "{out}");
    assert!(std::fs::read_to_string(dir.join("ladder.svg")).unwrap().starts_with("<svg"));
    let (code, out, _) = run_in(dir, &["compare", "demo/session.json", "--json"]);
    assert_eq!(code, 0);
    let v: serde_json::Value = serde_json::from_str(&out).unwrap();
    let rungs = v.as_array().unwrap();
    assert_eq!(rungs.len(), 3);
    let last = &rungs[2];
    assert!(last["reduction"][1].as_f64().unwrap() > 1.1, "the lever arm reduces the accelerometer residual: {last}");
    let (code, out, err) = run_in(dir, &["diagnose", "demo/session.json", "--effect", "accel-lever-arm"]);
    assert_eq!(code, 0, "{out}{err}");
    assert!(out.contains("verdict: the model is adequate"), "{out}");
}
