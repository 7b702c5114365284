//! Profiles: exact JSON round trip, identical correction after reading back, no overwrite.

use crate::common::fit_and_calibrate;
use crosscal::app::validate::{correct_run, Mode};
use crosscal::correct::Calibration;
use crosscal::model::Model;
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

#[test]
fn imucal_export_import_reproduces_the_common_coefficients_and_kalibr_states_what_is_lost() {
    use crate::common::run_in;
    use crosscal::profile::Profile;
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let (code, _, err) = run_in(
        d,
        &["simulate", "-o", "s", "--duration", "12", "--rate-hz", "50", "--gyro-bias", "0.1,-0.2,0.05"]
            .into_iter()
            .chain(["--accel-bias", "0.002,0,-0.001", "--hidden", "gyro-g-sensitivity", "--set", "gyro.g_xy=0.0004"])
            .collect::<Vec<_>>(),
    );
    assert_eq!(code, 0, "{err}");
    let (code, out, err) = run_in(d, &["fit", "s/session.json", "--effect", "gyro-g-sensitivity"]);
    assert_eq!(code, 0, "{err}");
    let path = out.lines().find_map(|l| l.strip_prefix("profile written to ")).unwrap().to_string();
    let (code, _, err) = run_in(d, &["profile", "export", &path, "--to", "imucal", "-o", "cal.json"]);
    assert_eq!(code, 0, "{err}");
    assert!(err.contains("gyro-angular-acceleration"), "C_ε is reported as not representable: {err}");
    let (code, out, err) = run_in(d, &["profile", "import-imucal", "cal.json", "--serial", "IMPORTED-1"]);
    assert_eq!(code, 0, "{err}");
    let back = Profile::read(&d.join(out.trim().rsplit(" as ").next().unwrap())).unwrap();
    let orig = Profile::read(&d.join(&path)).unwrap();
    let mut compared = 0;
    for c in back
        .gyro
        .coefficients
        .iter()
        .chain(&back.accel.coefficients)
        .filter(|c| c.status == crosscal::estimate::CoefStatus::Fitted)
    {
        let o = orig.gyro.get(&c.name).or_else(|| orig.accel.get(&c.name)).unwrap();
        let tol = 4.0 * f64::EPSILON * o.value.abs().max(1e-300);
        assert!((c.value - o.value).abs() <= tol, "{}: {} vs {}", c.name, c.value, o.value);
        compared += 1;
    }
    assert_eq!(compared, 3 + 9 + 9 + 3 + 9, "biases, C, G, accel biases, K");
    // The imported profile corrects data like any other.
    let (code, _, err) =
        run_in(d, &["correct", "--profile", out.trim().rsplit(" as ").next().unwrap(), "s/cone+10.csv", "-o", "c.csv"]);
    assert_eq!(code, 0, "{err}");
    // Kalibr: the YAML carries the intrinsics and says what it leaves out.
    let (code, _, err) = run_in(d, &["profile", "export", &path, "--to", "kalibr", "-o", "imu.yaml"]);
    assert_eq!(code, 0, "{err}");
    let y = std::fs::read_to_string(d.join("imu.yaml")).unwrap();
    for key in [
        "gyroscope_noise_density",
        "accelerometer_random_walk",
        "gyroscope_M",
        "gyroscope_A",
        "accelerometer_M",
        "Not represented",
    ] {
        assert!(y.contains(key), "{key}: {y}");
    }
}

#[test]
fn imucal_reference_calibration_imports_and_exports_to_the_same_matrices() {
    let file = std::path::Path::new("../shared/data/real/imucal_annotated_session/reference_example_cal.json");
    let Ok(text) = std::fs::read_to_string(file) else {
        eprintln!("skipped: {} not present", file.display());
        return;
    };
    let p = crosscal::profile::interop::from_imucal(file, &text, "IMUCAL-REF", 9.81).unwrap();
    assert_eq!(p.input_units.gyro, crosscal::units::GyroUnit::Raw);
    let (v, _) = crosscal::profile::interop::to_imucal(&p);
    let orig: serde_json::Value = serde_json::from_str(&text).unwrap();
    let m = |v: &serde_json::Value, k: &str| -> Vec<Vec<f64>> {
        v[k].as_array()
            .unwrap()
            .iter()
            .map(|r| r.as_array().unwrap().iter().map(|x| x.as_f64().unwrap()).collect())
            .collect()
    };
    let prod = |a: Vec<Vec<f64>>, b: Vec<Vec<f64>>| -> Vec<Vec<f64>> {
        (0..3).map(|i| (0..3).map(|j| (0..3).map(|k| a[i][k] * b[k][j]).sum()).collect()).collect()
    };
    for (k, r) in [("K_a", "R_a"), ("K_g", "R_g")] {
        let (a, b) = (prod(m(&orig, k), m(&orig, r)), prod(m(&v, k), m(&v, r)));
        for i in 0..3 {
            for j in 0..3 {
                assert!(
                    (a[i][j] - b[i][j]).abs() <= 1e-12 * a[i][i].abs(),
                    "{k}{r}[{i}][{j}]: {} vs {}",
                    a[i][j],
                    b[i][j]
                );
            }
        }
    }
    for k in ["b_a", "b_g"] {
        for i in 0..3 {
            let (a, b) = (orig[k][i].as_f64().unwrap(), v[k][i].as_f64().unwrap());
            assert!((a - b).abs() <= 1e-12 * a.abs().max(1.0), "{k}[{i}]");
        }
    }
}

#[test]
fn history_orders_profiles_by_time_not_by_text() {
    // Creation times are written to the millisecond without trailing zeros, so as text
    // "…:34.9Z" sorts after "…:34.95Z" and "…:35Z" after "…:35.1Z", though each is earlier.
    let session = SimConfig::paper().generate();
    let (_, mut profile, _) = fit_and_calibrate(&session, &Model::default_model());
    let dir = tempfile::tempdir().unwrap();
    for t in ["2026-11-23T20:31:35.1Z", "2026-11-23T20:31:34.95Z", "2026-11-23T20:31:35Z", "2026-11-23T20:31:34.9Z"] {
        profile.created_utc = t.to_string();
        save(&profile, dir.path()).unwrap();
    }
    let order: Vec<String> = crosscal::profile::history(dir.path(), "I1426-0042")
        .unwrap()
        .into_iter()
        .map(|(_, p)| p.unwrap().created_utc)
        .collect();
    assert_eq!(
        order,
        ["2026-11-23T20:31:34.9Z", "2026-11-23T20:31:34.95Z", "2026-11-23T20:31:35Z", "2026-11-23T20:31:35.1Z"]
    );
    let (_, at) = crosscal::profile::latest(dir.path(), "I1426-0042", Some("2026-11-23T20:31:35.05Z")).unwrap();
    assert_eq!(at.created_utc, "2026-11-23T20:31:35Z");
}

/// VINS-Fusion and ORB-SLAM3 noise blocks (and OpenVINS's noise keys): the continuous-time densities of the profile's
/// noise section (white noise from the standard reading, bias random walk from the fitted
/// term; worst axis, SI), under the keys each estimator's configuration uses, the simulated
/// ARW and rate random walk recovered, and what the estimator cannot hold listed.
#[test]
fn vins_fusion_and_orb_slam3_noise_blocks_carry_the_profiles_densities() {
    use crate::common::run_ok;
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    run_ok(d, &["simulate", "-o", "s", "--duration", "12", "--rate-hz", "50"]);
    // ARW 0.3 °/√h, rate random walk 20 °/h/√h; VRW 0.05 m/s/√h.
    run_ok(
        d,
        &[
            "simulate",
            "--preset",
            "static",
            "--duration",
            "3600",
            "--arw",
            "0.3",
            "--rrw",
            "20",
            "--vrw",
            "0.05",
            "-o",
            "still",
        ],
    );
    run_ok(d, &["noise", "still/session.json", "--save", "n.json"]);
    run_ok(d, &["fit", "s/session.json", "--noise", "n.json", "--out", "store"]);
    let unit = std::fs::read_dir(d.join("store")).unwrap().next().unwrap().unwrap().path();
    let (_, p) = crosscal::profile::Profile::read_or_latest(&unit).unwrap();
    let worst = |s: crosscal::units::SensorKind, f: fn(&crosscal::noise::ChannelNoise) -> Option<f64>| {
        p.noise.as_ref().unwrap().channels.iter().filter(|c| c.sensor() == s).filter_map(f).fold(0.0, f64::max)
    };
    use crosscal::units::SensorKind::{Accel, Gyro};
    let (gn, gw, an) = (worst(Gyro, |c| c.white()), worst(Gyro, |c| c.random_walk), worst(Accel, |c| c.white()));
    // The simulated unit, in SI: ARW 0.3 °/√h = 0.3/60 °/s/√Hz; RRW 20 °/h/√h.
    let arw_si = (0.3f64 / 60.0).to_radians();
    let rrw_si = (20.0f64 / 3600.0 / 60.0).to_radians();
    assert!((gn / arw_si - 1.0).abs() < 0.05, "gyro white {gn} vs {arw_si}");
    assert!((gw / rrw_si - 1.0).abs() < 0.35, "gyro walk {gw} vs {rrw_si}");
    let unit_s = unit.to_str().unwrap();
    let value = |text: &str, key: &str| -> f64 {
        let line = text.lines().find(|l| l.starts_with(key)).unwrap_or_else(|| panic!("{key} missing:\n{text}"));
        line[key.len()..].trim_start_matches(':').split_whitespace().next().unwrap().parse().unwrap()
    };
    let out = run_ok(d, &["profile", "export", unit_s, "--to", "vins-fusion", "-o", "vins.yaml"]);
    assert!(out.contains("exported"), "{out}");
    let v = std::fs::read_to_string(d.join("vins.yaml")).unwrap();
    assert_eq!(value(&v, "gyr_n").to_bits(), gn.to_bits(), "gyr_n");
    assert_eq!(value(&v, "gyr_w").to_bits(), gw.to_bits(), "gyr_w");
    assert_eq!(value(&v, "acc_n").to_bits(), an.to_bits(), "acc_n");
    assert_eq!(value(&v, "g_norm").to_bits(), p.g_m_s2.to_bits(), "g_norm");
    assert!(v.contains("not represented: ") && v.contains("scale factors"), "{v}");
    run_ok(d, &["profile", "export", unit_s, "--to", "orb-slam3", "--rate-hz", "200", "-o", "orb.yaml"]);
    let o = std::fs::read_to_string(d.join("orb.yaml")).unwrap();
    assert!(o.starts_with("%YAML:1.0\n"), "OpenCV FileStorage needs its header first: {o}");
    assert_eq!(value(&o, "IMU.NoiseGyro").to_bits(), gn.to_bits(), "IMU.NoiseGyro");
    assert_eq!(value(&o, "IMU.GyroWalk").to_bits(), gw.to_bits(), "IMU.GyroWalk");
    assert_eq!(value(&o, "IMU.NoiseAcc").to_bits(), an.to_bits(), "IMU.NoiseAcc");
    assert_eq!(value(&o, "IMU.Frequency").to_bits(), 200f64.to_bits(), "IMU.Frequency");
    // OpenVINS reads the same densities under Kalibr's names.
    run_ok(d, &["profile", "export", unit_s, "--to", "openvins", "-o", "ov.yaml"]);
    let ov = std::fs::read_to_string(d.join("ov.yaml")).unwrap();
    assert_eq!(value(&ov, "  gyroscope_noise_density").to_bits(), gn.to_bits(), "gyroscope_noise_density");
    assert_eq!(value(&ov, "  gyroscope_random_walk").to_bits(), gw.to_bits(), "gyroscope_random_walk");
    assert_eq!(value(&ov, "  accelerometer_noise_density").to_bits(), an.to_bits(), "accelerometer_noise_density");
}
