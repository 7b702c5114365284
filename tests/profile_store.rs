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
