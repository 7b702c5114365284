//! The production-line thermal sweep (issue #24, req. 5): `simulate --thermal-sweep`
//! (plateaus, faces and conic runs, the unit's lag behind the chamber, reading noise),
//! `plan --thermal` (the uncertainty of the compensated bias, the dwell meeting a target) and
//! the `temperature` rule's `max_residual`, each against known truth.

use crate::common::{run_in, run_ok};
use crosscal::profile::Profile;
use crosscal::session::Session;

/// A cubic gyro bias and a quadratic accelerometer bias (SI), the issue's unit.
const TRUTH: [(&str, f64); 15] = crate::common::THERMAL_BIASES;

/// The effects fitted (and planned: degree 3 on both sensors; the accelerometer's true cubic
/// term is 0).
const EFFECTS: [&str; 2] =
    ["gyro-temp-bias+gyro-temp-bias2+gyro-temp-bias3", "accel-temp-bias+accel-temp-bias2+accel-temp-bias3"];

/// The sweep design, shared by simulate and plan: five plateaus, six faces and four conic runs
/// at each, the unit lagging the chamber by 60 s and soaked 300 s, 50 Hz.
fn design(duration_s: &str) -> Vec<String> {
    [
        "--thermal-sweep",
        "-20,0,20,45,70",
        "--plateau-conic",
        "--rates",
        "10,-10",
        "--cone-angles",
        "10",
        "--mounts",
        "2",
        "--thermal-tau",
        "60",
        "--rate-hz",
        "50",
        "--duration",
        duration_s,
    ]
    .iter()
    .map(|s| s.to_string())
    .collect()
}

/// Per-sample noise of the simulations: gyro 0.002 °/s, accelerometer 2e-4 g.
const GYRO_NOISE_DEG_S: f64 = 0.002;
const ACCEL_NOISE_G: f64 = 2e-4;

/// Simulates the sweep unit into `dir/out` with reading noise 0.05 °C.
fn simulate(d: &std::path::Path, out: &str, duration_s: &str, seed: u64) {
    let seed = seed.to_string();
    let (gn, an) = (GYRO_NOISE_DEG_S.to_string(), ACCEL_NOISE_G.to_string());
    let mut extra: Vec<String> = design(duration_s);
    extra.extend(
        ["--seed", &seed, "--gyro-noise", &gn, "--accel-noise", &an, "--temp-noise", "0.05"].map(str::to_string),
    );
    let extra: Vec<&str> = extra.iter().map(String::as_str).collect();
    let truth: Vec<(String, f64)> = TRUTH.iter().map(|(n, v)| (n.to_string(), *v)).collect();
    let hidden = ["gyro-temp-bias", "gyro-temp-bias2", "gyro-temp-bias3", "accel-temp-bias", "accel-temp-bias2"];
    crate::common::simulate_hidden(d, out, &hidden, &truth, &extra);
}

/// `plan --thermal` of the same design and noise, as JSON.
fn plan(d: &std::path::Path, duration_s: &str, extra: &[&str]) -> serde_json::Value {
    // Per-sample σ at 50 Hz as densities: ARW (°/√h) = 60 σ/√f, VRW (m/s/√h) = 60 σ/√f.
    let arw = (60.0 * GYRO_NOISE_DEG_S / 50f64.sqrt()).to_string();
    let vrw = (60.0 * ACCEL_NOISE_G * 9.80665 / 50f64.sqrt()).to_string();
    let mut args: Vec<String> = vec!["plan".into()];
    args.extend(design(duration_s).into_iter().map(|a| if a == "--thermal-sweep" { "--thermal".into() } else { a }));
    args.extend(["--degree", "3", "--arw", &arw, "--vrw", &vrw, "--json", "--no-suggest"].map(str::to_string));
    args.extend(extra.iter().map(|s| s.to_string()));
    let args: Vec<&str> = args.iter().map(String::as_str).collect();
    let out = run_ok(d, &args);
    serde_json::from_str(&out).unwrap_or_else(|e| panic!("{e}: {out}"))
}

fn predicted_se(plan: &serde_json::Value, name: &str) -> f64 {
    plan["coefficients"]
        .as_array()
        .and_then(|cs| cs.iter().find(|c| c["name"] == name))
        .and_then(|c| c["std_error"].as_f64())
        .unwrap_or_else(|| panic!("{name} not in the plan: {plan}"))
}

fn truth_of(name: &str) -> f64 {
    TRUTH.iter().find(|t| t.0 == name).map_or(0.0, |t| t.1)
}

/// Every temperature coefficient of both sensors (the accelerometer's tb3 is truly 0).
fn temperature_names() -> Vec<String> {
    let mut names = Vec::new();
    for s in ["gyro", "accel"] {
        for ax in ["x", "y", "z"] {
            for k in ["tb", "tb2", "tb3"] {
                names.push(format!("{s}.{k}_{ax}"));
            }
        }
    }
    names
}

fn coefficient(p: &Profile, name: &str) -> (f64, f64) {
    let s = if name.starts_with("gyro") { &p.gyro } else { &p.accel };
    let c = s.get(name).unwrap_or_else(|| panic!("{name} missing from the profile"));
    (c.value, c.std_error.unwrap_or(f64::INFINITY))
}

/// A sweep with a hidden cubic gyro and quadratic accelerometer bias and 0.05 °C reading
/// noise, fitted with cubics: every temperature coefficient within 3 of its standard errors of
/// the truth; each standard error within 15 % of the plan's prediction for the design; and
/// over four seeds the errors scatter as the plan predicts (RMS of error / predicted σ within
/// 0.7 … 1.3).
#[test]
fn a_sweep_recovers_the_temperature_polynomials_as_the_plan_predicts() {
    let dir = tempfile::tempdir().unwrap_or_else(|e| panic!("{e}"));
    let d = dir.path();
    let predicted = plan(d, "10", &[]);
    let names = temperature_names();
    let mut z2 = Vec::new();
    let mut ratio_dev: f64 = 0.0;
    for seed in 1..=4u64 {
        let out = format!("sweep{seed}");
        simulate(d, &out, "10", seed);
        let (_, p) = crate::common::fit_into_store(d, &format!("{out}/session.json"), &EFFECTS);
        std::fs::remove_dir_all(d.join("store")).unwrap_or_else(|e| panic!("{e}"));
        for n in &names {
            let (value, se) = coefficient(&p, n);
            let (want, pse) = (truth_of(n), predicted_se(&predicted, n));
            assert!((value - want).abs() < 3.0 * se, "seed {seed} {n}: {value} ± {se} vs truth {want}");
            assert!((se / pse - 1.0).abs() < 0.15, "seed {seed} {n}: fit's standard error {se} vs predicted {pse}");
            ratio_dev = ratio_dev.max((se / pse - 1.0).abs());
            z2.push(((value - want) / pse).powi(2));
        }
        if seed == 1 {
            let range = p.temperature_range_c().unwrap_or([f64::NAN; 2]);
            assert!((range[0] + 20.0).abs() < 0.3 && (range[1] - 70.0).abs() < 0.3, "{range:?}");
        }
    }
    let rms = (z2.iter().sum::<f64>() / z2.len() as f64).sqrt();
    let zmax = z2.iter().copied().fold(0.0, f64::max).sqrt();
    eprintln!("thermal sweep: RMS error/predicted σ {rms:.3} over {} estimates, largest {zmax:.2}", z2.len());
    eprintln!("thermal sweep: fit's standard errors within {:.1} % of the plan's", 100.0 * ratio_dev);
    assert!((0.7..1.3).contains(&rms), "errors / predicted σ have RMS {rms} over {} estimates", z2.len());
}

/// After a step of the set point the temp column follows u = T_set + (T₀ − T_set) e^(−t/τ)
/// (to its 1 mK step), and the unsettled run's note says so; during a recorded ramp it
/// follows the ramp response T₀ + r (t − τ) + r τ e^(−t/τ).
#[test]
fn the_unit_temperature_lags_the_chamber_with_its_time_constant() {
    let dir = tempfile::tempdir().unwrap_or_else(|e| panic!("{e}"));
    let d = dir.path();
    let common = ["--faces", "1", "--thermal-tau", "30", "--soak", "0", "--rate-hz", "10", "--duration", "60"];
    let mut args = vec!["simulate", "-o", "step", "--thermal-sweep", "60", "--chamber-start", "20"];
    args.extend_from_slice(&common);
    run_ok(d, &args);
    let s = Session::load(&d.join("step/session.json")).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(s.runs.len(), 1);
    let run = &s.runs[0];
    assert_eq!(run.spec.name, "p1-face+z");
    let temps = run.rec.temp_c.as_deref().unwrap_or_default();
    assert_eq!(temps.len(), 600);
    let mut worst: f64 = 0.0;
    for (k, &t) in temps.iter().enumerate() {
        let want = 60.0 - 40.0 * (-(k as f64 / 10.0) / 30.0).exp();
        worst = worst.max((t - want).abs());
    }
    assert!(worst <= 5.0e-4 + 1e-12, "the temp column strays {worst} °C from the closed form");
    eprintln!("settling: step response within {worst:.2e} °C of the closed form");
    let note = run.spec.note.clone().unwrap_or_default();
    assert!(note.contains("plateau 1/1: set point 60 °C; NOT SETTLED: the unit is up to 40.000 °C"), "{note}");

    // A ramp from 20 to 50 °C at 6 °C/min (300 s), recorded: five 60 s runs of the face.
    let mut args = vec!["simulate", "-o", "ramp", "--thermal-sweep", "20,50", "--ramp-rate", "6", "--record-ramps"];
    args.extend_from_slice(&common);
    run_ok(d, &args);
    let s = Session::load(&d.join("ramp/session.json")).unwrap_or_else(|e| panic!("{e}"));
    let names: Vec<&str> = s.runs.iter().map(|r| r.spec.name.as_str()).collect();
    assert_eq!(
        names,
        [
            "p1-face+z",
            "ramp2-01-face+z",
            "ramp2-02-face+z",
            "ramp2-03-face+z",
            "ramp2-04-face+z",
            "ramp2-05-face+z",
            "p2-face+z"
        ]
    );
    // The ramp starts at 60 s, the unit settled at 20 °C; run j starts (j − 1) 60 s into it.
    let mut worst: f64 = 0.0;
    for (j, run) in s.runs[1..6].iter().enumerate() {
        assert!(run.spec.note.as_deref().unwrap_or_default().contains("ramp to plateau 2/2: chamber 20 → 50 °C"));
        for (k, &t) in run.rec.temp_c.as_deref().unwrap_or_default().iter().enumerate() {
            let s = 60.0 * j as f64 + k as f64 / 10.0;
            let want = 20.0 + 0.1 * (s - 30.0) + 0.1 * 30.0 * (-s / 30.0).exp();
            worst = worst.max((t - want).abs());
        }
    }
    assert!(worst <= 5.0e-4 + 1e-12, "the ramp's temp column strays {worst} °C from the closed form");
    eprintln!("settling: ramp response within {worst:.2e} °C of the closed form");
    // At the plateau the unit still lags: 50 − 3 e^(−10) … at once, then settles.
    let p2 = s.runs[6].rec.temp_c.as_deref().unwrap_or_default();
    assert!((p2[0] - (50.0 - 3.0 * (1.0 - (-10f64).exp()))).abs() < 1e-3, "{}", p2[0]);
}

/// The reading noise and step as given: on a settled 45 °C plateau the temp column's standard
/// deviation is within 10 % of √(σ² + q²/12), its mean within 3 standard errors of 45 °C, and
/// every reading a multiple of the step.
#[test]
fn the_temperature_reading_has_the_given_noise_and_step() {
    let dir = tempfile::tempdir().unwrap_or_else(|e| panic!("{e}"));
    let d = dir.path();
    let args = [
        "simulate",
        "-o",
        "read",
        "--thermal-sweep",
        "45",
        "--faces",
        "1",
        "--duration",
        "100",
        "--rate-hz",
        "50",
        "--temp-noise",
        "0.05",
        "--temp-quantum",
        "0.01",
    ];
    run_ok(d, &args);
    let s = Session::load(&d.join("read/session.json")).unwrap_or_else(|e| panic!("{e}"));
    let t = s.runs[0].rec.temp_c.clone().unwrap_or_default();
    let n = t.len() as f64;
    let mean = t.iter().sum::<f64>() / n;
    let sd = (t.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (n - 1.0)).sqrt();
    let want = (0.05f64.powi(2) + 0.01f64.powi(2) / 12.0).sqrt();
    eprintln!("reading: σ {sd:.5} °C (expected {want:.5}), mean {mean:.5} °C");
    assert!((sd / want - 1.0).abs() < 0.10, "reading σ {sd} °C, expected {want}");
    assert!((mean - 45.0).abs() < 3.0 * want / n.sqrt(), "mean {mean}");
    assert!(t.iter().all(|v| ((v * 100.0).round() - v * 100.0).abs() < 1e-6), "readings on the 0.01 °C step");
    // Flags that need a sweep are refused without one; the breakpoints and the sweep exclude
    // each other.
    let (code, _, err) = run_in(d, &["simulate", "-o", "x", "--faces", "3"]);
    assert_ne!(code, 0, "{err}");
    assert!(err.contains("--thermal-sweep"), "{err}");
    let (code, _, err) = run_in(d, &["simulate", "-o", "x", "--thermal-sweep", "10", "--temperature", "1,2"]);
    assert_ne!(code, 0, "{err}");
    let (code, _, err) = run_in(d, &["simulate", "-o", "x", "--thermal-sweep", "10", "--faces", "0"]);
    assert_ne!(code, 0, "{err}");
    assert!(err.contains("at least one run at each plateau"), "{err}");
    let (code, _, err) = run_in(d, &["simulate", "-o", "x", "--thermal-sweep", "10", "--thermal-tau=-1"]);
    assert_ne!(code, 0, "{err}");
    assert!(err.contains("non-negative"), "{err}");
}

/// The worst compensated-bias uncertainty a profile's covariance gives over −20 … 70 °C.
fn worst_bias_std(p: &Profile, sensor: &str) -> f64 {
    let fit = if sensor == "gyro" { &p.gyro } else { &p.accel };
    let mut worst: f64 = 0.0;
    for (i, ax) in ["x", "y", "z"].iter().enumerate() {
        let ch = &fit.channels[i];
        let names = [
            format!("{sensor}.b_{ax}"),
            format!("{sensor}.tb_{ax}"),
            format!("{sensor}.tb2_{ax}"),
            format!("{sensor}.tb3_{ax}"),
        ];
        let idx: Vec<usize> = names
            .iter()
            .map(|n| ch.covariance_names.iter().position(|c| c == n).unwrap_or_else(|| panic!("{n}")))
            .collect();
        for j in 0..=90 {
            let dt = -40.0 + f64::from(j);
            let g = [1.0, dt, dt * dt, dt * dt * dt];
            let mut var = 0.0;
            for a in 0..4 {
                for b in 0..4 {
                    var += g[a] * g[b] * ch.covariance[idx[a]][idx[b]];
                }
            }
            worst = worst.max(var.sqrt());
        }
    }
    worst
}

/// `plan --thermal --target-bias-std`: the suggested run duration meets the target, and a
/// sweep simulated with it and fitted does too (the fit's own covariance, within 10 %).
#[test]
fn the_suggested_dwell_meets_the_target_when_simulated() {
    let dir = tempfile::tempdir().unwrap_or_else(|e| panic!("{e}"));
    let d = dir.path();
    let short = plan(d, "4", &[]);
    let worst = |p: &serde_json::Value, i: usize| p["bias"][i]["worst_std"].as_f64().unwrap_or(f64::NAN);
    let (g4, a4) = (worst(&short, 0), worst(&short, 1));
    // Targets a third of the 4 s design's worst: about nine times the dwell.
    let target = format!("{},{}", g4 / 3.0, a4 / 3.0);
    let p = plan(d, "4", &["--target-bias-std", &target]);
    let dwell = &p["dwell"];
    assert_eq!(dwell["meets"], true, "{p}");
    let dur = dwell["run_duration_s"].as_f64().unwrap_or(f64::NAN);
    assert!((30.0..45.0).contains(&dur), "suggested {dur} s for a third of the uncertainty of 4 s runs");
    let dur_arg = format!("{dur}");
    simulate(d, "long", &dur_arg, 7);
    let (_, prof) = crate::common::fit_into_store(d, "long/session.json", &EFFECTS);
    let (tg, ta) = (g4 / 3.0, a4 / 3.0);
    let (fg, fa) = (worst_bias_std(&prof, "gyro"), worst_bias_std(&prof, "accel"));
    eprintln!(
        "dwell: 4 s runs give worst σ gyro {g4:.3e}, accel {a4:.3e}; suggested {dur} s; fitted worst σ / target gyro {:.3}, accel {:.3}",
        fg / tg,
        fa / ta
    );
    assert!(fg <= 1.1 * tg && fa <= 1.1 * ta, "fitted worst σ gyro {fg} (target {tg}), accel {fa} (target {ta})");
    // Three plateaus cannot fix a cubic: the text says so, and suggests the fourth.
    let text = run_ok(d, &["plan", "--thermal", "-20,20,70", "--degree", "3", "--duration", "2", "--rate-hz", "20"]);
    assert!(text.contains("gyro compensated bias: UNKNOWN"), "{text}");
    assert!(
        text.contains("suggested extra plateau: 0 degC") || text.contains("suggested extra plateau: 45 degC"),
        "{text}"
    );
    let (code, _, err) = run_in(d, &["plan", "--thermal", "0,40", "--target-bias-std", "1e-5"]);
    assert_ne!(code, 0);
    assert!(err.contains("GYRO,ACCEL"), "{err}");
}

/// `max_residual`: a profile without temperature terms on a sweep whose gyro x bias is linear
/// in T (1e-4 rad/s/°C, plateaus −20, 0, 20, 45, 70 °C, equal dwell) leaves tb (T − T̄) at each
/// plateau, T̄ = 23 °C: 4.7e-3 rad/s at 70 °C, the worst; the profile with the term leaves noise.
#[test]
fn max_residual_measures_what_the_compensation_leaves_per_plateau() {
    let dir = tempfile::tempdir().unwrap_or_else(|e| panic!("{e}"));
    let d = dir.path();
    let args = [
        "--thermal-sweep",
        "-20,0,20,45,70",
        "--plateau-conic",
        "--rates",
        "10,-10",
        "--cone-angles",
        "10",
        "--mounts",
        "2",
        "--duration",
        "6",
        "--rate-hz",
        "50",
        "--gyro-noise",
        "0.002",
        "--accel-noise",
        "0.0002",
    ];
    let truth = [("gyro.tb_x".to_string(), 1e-4)];
    crate::common::simulate_hidden(d, "sweep", &["gyro-temp-bias"], &truth, &args);
    run_ok(d, &["fit", "sweep/session.json", "--out", "plain"]);
    run_ok(d, &["fit", "sweep/session.json", "--effect", "gyro-temp-bias", "--out", "comp"]);
    let judge = |store: &str, rule: &str| {
        std::fs::write(d.join("rules.json"), format!(r#"{{"format":"crosscal-rules/1","rules":[{rule}]}}"#))
            .unwrap_or_else(|e| panic!("{e}"));
        let (path, _) = crate::common::only_profile(&d.join(store));
        let prof = path.to_string_lossy().to_string();
        let (code, out, err) =
            run_in(d, &["accept", &prof, "--rules", "rules.json", "--session", "sweep/session.json"]);
        (code, format!("{out}{err}"))
    };
    let residual = |out: &str| -> f64 {
        out.split("largest bias residual after compensation ")
            .nth(1)
            .and_then(|s| s.split_whitespace().next())
            .and_then(|v| v.parse().ok())
            .unwrap_or_else(|| panic!("no residual in {out}"))
    };
    let (code, out) = judge("plain", r#"{"kind":"temperature","sensor":"gyro","max_residual":5e-3}"#);
    assert_eq!(code, 0, "{out}");
    let r = residual(&out);
    eprintln!("max_residual: uncompensated {r:.4e} rad/s (expected 4.7e-3)");
    assert!((r / 4.7e-3 - 1.0).abs() < 0.02, "residual {r}, expected 4.7e-3: {out}");
    assert!(out.contains("axis x, 69.5..70.5 degC"), "{out}");
    let (code, out) = judge("plain", r#"{"kind":"temperature","sensor":"gyro","max_residual":4.5e-3}"#);
    assert_eq!(code, 1, "4.7e-3 must fail a 4.5e-3 limit: {out}");
    // Compensated: what is left is the noise of a plateau's mean (σ/√1500 ≈ 1e-6 rad/s).
    let (code, out) = judge("comp", r#"{"kind":"temperature","sensor":"gyro","max_residual":1e-5}"#);
    assert_eq!(code, 0, "{out}");
    assert!(residual(&out) < 1e-5, "{out}");
    eprintln!("max_residual: compensated {:.3e} rad/s", residual(&out));
    // Wider bins, centred on multiples of 10 °C: 65..75 holds the 70 °C plateau; no session: fails.
    let (code, out) = judge("plain", r#"{"kind":"temperature","sensor":"gyro","max_residual":5e-3,"bin_c":10}"#);
    assert_eq!(code, 0, "{out}");
    assert!(out.contains("axis x, 65..75 degC"), "{out}");
    let (path, _) = crate::common::only_profile(&d.join("comp"));
    let (code, out, _) = run_in(d, &["accept", &path.to_string_lossy(), "--rules", "rules.json"]);
    assert_eq!(code, 1, "no session checked: {out}");
    assert!(out.contains("no session was checked"), "{out}");
    let (code, out) = judge("plain", r#"{"kind":"temperature","sensor":"gyro","max_residual":-1}"#);
    assert_eq!(code, 20, "{out}");
}
