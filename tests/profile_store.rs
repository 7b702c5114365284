//! Profiles: exact JSON round trip, identical correction after reading back, no overwrite.

use crate::common::fit_and_calibrate;
use crosscal::correct::Calibration;
use crosscal::model::Model;
use crosscal::pipeline::{correct_run, Mode};
use crosscal::profile::{save, Profile};
use crosscal::simulate::SimConfig;

#[test]
fn write_read_correct_is_identical_and_never_overwrites() {
    let mut cfg = SimConfig::paper();
    cfg.gyro_noise_deg_s = 0.002;
    cfg.accel_noise_g = 2e-5;
    let session = cfg.generate();
    let (_, profile, cal) = fit_and_calibrate(&session, &Model::default_model());
    let dir = tempfile::tempdir().unwrap();
    let p1 = save(&profile, dir.path()).unwrap();
    let p2 = save(&profile, dir.path()).unwrap();
    assert_ne!(p1, p2, "a second save must not reuse the file");
    assert!(p1.starts_with(dir.path().join("I1426-0042")));
    let back = Profile::read(&p1).unwrap();
    assert_eq!(back, profile, "JSON round trip must be exact");
    assert_eq!(std::fs::read(&p1).unwrap(), std::fs::read(&p2).unwrap());
    let cal2 = Calibration::from_profile(&back).unwrap();
    for mode in [Mode::Offline, Mode::Streaming] {
        for run in session.runs.iter().take(3) {
            let a = correct_run(&cal, run, mode).unwrap();
            let b = correct_run(&cal2, run, mode).unwrap();
            assert_eq!(a, b, "run {} {mode:?}", run.spec.name);
        }
    }
    // No temporary files are left behind.
    let leftovers: Vec<_> = std::fs::read_dir(dir.path().join("I1426-0042"))
        .unwrap()
        .filter_map(|e| e.ok())
        .filter(|e| e.file_name().to_string_lossy().ends_with(".tmp"))
        .collect();
    assert!(leftovers.is_empty());
}

#[test]
fn unknown_profile_format_is_refused() {
    let session = SimConfig::paper().generate();
    let (_, profile, _) = fit_and_calibrate(&session, &Model::default_model());
    let text = profile.to_json().replace("crosscal-profile/1", "crosscal-profile/9");
    let e = Profile::from_json(std::path::Path::new("p.json"), &text).unwrap_err();
    let m = e.to_string();
    assert!(m.contains("crosscal-profile/9") && m.contains("p.json"), "{m}");
    let e = Profile::from_json(std::path::Path::new("p.json"), "{\"format\": 3").unwrap_err();
    assert!(e.to_string().starts_with("p.json:1:"), "{e}");
}

#[test]
fn profile_list_show_at_and_diff_find_a_drifted_coefficient() {
    use crate::common::run_in;
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let sim = |out: &str, seed: &str, extra: &[&str]| {
        let mut args = vec!["simulate", "-o", out, "--duration", "12", "--rate-hz", "50", "--seed", seed];
        args.extend(["--gyro-noise", "0.002", "--accel-noise", "2e-5"]);
        args.extend(extra);
        let (code, _, err) = run_in(d, &args);
        assert_eq!(code, 0, "{err}");
    };
    sim("jan", "1", &[]);
    sim("feb", "2", &[]);
    sim("mar", "3", &["--set", "gyro.c_xy=0.0105"]);
    let mut files = Vec::new();
    for s in ["jan", "feb", "mar"] {
        let (code, out, err) = run_in(d, &["fit", &format!("{s}/session.json")]);
        assert_eq!(code, 0, "{err}");
        let path = out.lines().find_map(|l| l.strip_prefix("profile written to ")).unwrap().to_string();
        files.push(path);
        std::thread::sleep(std::time::Duration::from_millis(20));
    }
    let (code, out, _) = run_in(d, &["profile", "list"]);
    assert_eq!(code, 0);
    assert!(out.contains("I1426-0042: 3 profile(s)"), "{out}");
    // show --at the second profile's time gives the second, not the newest.
    let second = crosscal::profile::Profile::read(&d.join(&files[1])).unwrap();
    let (code, out, err) = run_in(d, &["profile", "show", "I1426-0042", "--at", &second.created_utc, "--json"]);
    assert_eq!(code, 0, "{err}");
    assert_eq!(crosscal::profile::Profile::from_json(std::path::Path::new("x"), &out).unwrap(), second);
    let (code, _, err) = run_in(d, &["profile", "show", "I1426-0042", "--at", "2001-01-01"]);
    assert_ne!(code, 0);
    assert!(err.contains("no profile of unit 'I1426-0042' created at or before 2001-01-01"), "{err}");
    // Two calibrations of an unchanged unit agree within noise; the changed c_xy is drift.
    let (code, out, _) = run_in(d, &["profile", "diff", &files[0], &files[1]]);
    assert_eq!(code, 0, "{out}");
    let (code, out, _) = run_in(d, &["profile", "diff", &files[1], &files[2]]);
    assert_eq!(code, 1, "{out}");
    assert!(out.contains("DRIFTED (|z| > 3): gyro.c_xy"), "{out}");
    // An old profile draws a warning when used.
    let (code, _, err) =
        run_in(d, &["correct", "--profile", &files[0], "jan/cone+10.csv", "-o", "c.csv", "--max-age-days", "0"]);
    assert_eq!(code, 0, "{err}");
    assert!(err.contains("days old"), "{err}");
}
