//! The production-line thermal sweep (issue #24, req. 5): `simulate --thermal-sweep`
//! (plateaus, faces and conic runs, the unit's lag behind the chamber, reading noise),
//! `plan --thermal` (the uncertainty of the compensated bias, the dwell meeting a target) and
//! the `temperature` rule's `max_residual`, each against known truth.

use crate::common::{run_in, run_ok};
use crosscal::session::Session;

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
