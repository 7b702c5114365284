//! Production batches: per-unit verdicts with reasons, batch outliers, interruption safety.

use crate::common::run_in;
use crosscal::app::batch::{BatchReport, Verdict};
use crosscal::simulate::{conic_plan, cyclic_mounts, write_session, SimConfig};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use std::path::Path;

const AXES: [char; 3] = ['x', 'y', 'z'];

/// Unit `i` of a lot: C, K, biases drawn around the paper's unit, small session, noise.
fn unit(i: usize) -> SimConfig {
    let mut rng = ChaCha8Rng::seed_from_u64(1000 + i as u64);
    let mut c = SimConfig::paper();
    c.serial = format!("LOT7-{i:03}");
    c.runs = conic_plan(&[10.0, -10.0, 20.0], &[10.0], &cyclic_mounts(3), 10.0);
    c.sample_rate_hz = 25.0;
    c.gyro_noise_deg_s = 0.002;
    c.accel_noise_g = 2e-5;
    c.seed = i as u64;
    for (m, s) in [("c", "gyro"), ("k", "accel")] {
        for a in AXES {
            for b in AXES {
                let v = if a == b {
                    1.0 + 0.002 * (rng.random::<f64>() - 0.5)
                } else {
                    0.01 + 0.002 * (rng.random::<f64>() - 0.5)
                };
                c.truth.values.insert(format!("{s}.{m}_{a}{b}"), v);
            }
            c.truth.values.insert(format!("{s}.b_{a}"), 1e-3 * (rng.random::<f64>() - 0.5));
        }
    }
    c
}

const RULES: &str = r#"{"format":"crosscal-rules/1","rules":[
  {"kind":"coefficient","name":"gyro cross-coupling","select":"gyro.c_*","max_abs_deviation":0.02},
  {"kind":"coefficient","name":"accel cross-coupling","select":"accel.k_*","max_abs_deviation":0.02},
  {"kind":"std_error","name":"calibration precision","select":"*","max":0.01},
  {"kind":"reduction","sensor":"accel","min":10},
  {"kind":"adequate","name":"model adequate"}]}"#;

/// Writes the lot of `n` units; returns the special units' folder names.
fn lot(dir: &Path, n: usize) -> [Vec<String>; 5] {
    let (coupling, gsens, corrupt, missing, outlier) = ([3, 17, 31], [8, 40], 12, 25, 44);
    for i in 0..n {
        let mut c = unit(i);
        if coupling.contains(&i) {
            c.truth.values.insert("gyro.c_xy".into(), 0.035);
        }
        if gsens.contains(&i) {
            c.truth.model.add_effect("gyro-g-sensitivity").unwrap();
            let k = std::f64::consts::PI / 180.0 / 9.80665;
            c.truth.values.insert("gyro.g_xx".into(), 0.05 * k);
            c.truth.values.insert("gyro.g_yz".into(), -0.04 * k);
        }
        if i == outlier {
            // Within the fixed limit (0.02) but far outside the lot's spread (±0.001).
            c.truth.values.insert("accel.k_yz".into(), 0.0185);
        }
        let d = dir.join(format!("unit{i:03}"));
        write_session(&c.generate(), &d).unwrap();
        if i == corrupt {
            let p = d.join("cone-10.csv");
            let text = std::fs::read_to_string(&p).unwrap();
            let mut lines: Vec<String> = text.lines().map(str::to_string).collect();
            let mut fields: Vec<String> = lines[40].split(',').map(str::to_string).collect();
            fields[2] = "zz".into();
            lines[40] = fields.join(",");
            std::fs::write(&p, lines.join("\n")).unwrap();
        }
        if i == missing {
            std::fs::remove_file(d.join("yzx-cone+20.csv")).unwrap();
        }
    }
    let name = |i: usize| format!("unit{i:03}");
    [
        coupling.iter().map(|&i| name(i)).collect(),
        gsens.iter().map(|&i| name(i)).collect(),
        vec![name(corrupt)],
        vec![name(missing)],
        vec![name(outlier)],
    ]
}

fn report(dir: &Path) -> BatchReport {
    serde_json::from_str(&std::fs::read_to_string(dir.join("batch-report.json")).unwrap()).unwrap()
}

fn folder(u: &crosscal::app::batch::UnitResult) -> String {
    u.dir.file_name().unwrap().to_string_lossy().into_owned()
}

#[test]
fn a_lot_of_50_units_flags_exactly_the_bad_ones_with_their_reasons_and_the_outlier() {
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    let [coupling, gsens, corrupt, missing, outlier] = lot(&d.join("lot"), 50);
    std::fs::write(d.join("rules.json"), RULES).unwrap();
    let (code, out, err) = run_in(d, &["batch", "lot", "--rules", "rules.json"]);
    println!("{out}");
    assert_eq!(code, 1, "{out}{err}");
    let r = report(&d.join("lot"));
    assert_eq!(r.units.len(), 50);
    let mut bad: Vec<String> = r.units.iter().filter(|u| u.verdict != Verdict::Pass).map(folder).collect();
    bad.sort();
    let mut expected: Vec<String> = [&coupling, &gsens, &corrupt, &missing].into_iter().flatten().cloned().collect();
    expected.sort();
    let why: Vec<String> = r
        .units
        .iter()
        .filter(|u| u.verdict != Verdict::Pass)
        .map(|u| format!("{}: {}", folder(u), u.reasons.join(" | ")))
        .collect();
    assert_eq!(bad, expected, "{why:#?}");
    let reasons = |f: &str| r.units.iter().find(|u| folder(u) == f).unwrap().reasons.join(" | ");
    for f in &coupling {
        assert!(reasons(f).contains("gyro cross-coupling") && reasons(f).contains("gyro.c_xy"), "{f}: {}", reasons(f));
    }
    for f in &gsens {
        assert!(
            reasons(f).contains("model adequate") && reasons(f).contains("gyro-g-sensitivity"),
            "{f}: {}",
            reasons(f)
        );
    }
    assert!(
        reasons(&corrupt[0]).contains("cone-10.csv:41") && reasons(&corrupt[0]).contains("'zz'"),
        "{}",
        reasons(&corrupt[0])
    );
    assert!(reasons(&missing[0]).contains("yzx-cone+20.csv"), "{}", reasons(&missing[0]));
    // The outlier passes every rule but is flagged; no other passing unit is.
    let flagged: Vec<String> =
        r.units.iter().filter(|u| u.verdict == Verdict::Pass && !u.outliers.is_empty()).map(folder).collect();
    assert_eq!(flagged, outlier);
    let o = r.units.iter().find(|u| folder(u) == outlier[0]).unwrap();
    assert!(o.outliers.iter().any(|(n, z)| n == "accel.k_yz" && *z > 5.0), "{:?}", o.outliers);
    // Reports: CSV row per unit, HTML with a plot per coefficient, a profile per good unit.
    let csv = std::fs::read_to_string(d.join("lot/batch-report.csv")).unwrap();
    assert_eq!(csv.lines().count(), 51);
    let html = std::fs::read_to_string(d.join("lot/batch-report.html")).unwrap();
    assert!(html.matches("<svg").count() >= 33);
    let profiles = crosscal::profile::serials(&d.join("calib-profiles")).unwrap();
    assert_eq!(profiles.len(), 48, "units with a readable session get a profile");

    // A rerun with --resume fits nothing again and reaches the same verdicts.
    let (code, out, err) = run_in(d, &["batch", "lot", "--rules", "rules.json", "--resume"]);
    assert_eq!(code, 1, "{out}{err}");
    let again = report(&d.join("lot"));
    assert_eq!(again.units.iter().filter(|u| u.reused).count(), 48);
    let verdicts = |r: &BatchReport| r.units.iter().map(|u| u.verdict).collect::<Vec<_>>();
    assert_eq!(verdicts(&again), verdicts(&r));
}

#[test]
fn killing_a_batch_never_leaves_a_partial_profile_and_resume_completes_it() {
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    lot(&d.join("lot"), 16);
    std::fs::write(
        d.join("rules.json"),
        r#"{"format":"crosscal-rules/1","rules":[{"kind":"std_error","select":"*","max":1}]}"#,
    )
    .unwrap();
    for wait_ms in [150u64, 400, 700] {
        let mut child = std::process::Command::new(crate::common::bin())
            .args(["batch", "lot", "--rules", "rules.json", "--resume"])
            .current_dir(d)
            .stdout(std::process::Stdio::null())
            .stderr(std::process::Stdio::null())
            .spawn()
            .unwrap();
        std::thread::sleep(std::time::Duration::from_millis(wait_ms));
        let _ = child.kill(); // SIGKILL
        let _ = child.wait();
        // Every profile file present is complete and valid.
        let store = d.join("calib-profiles");
        if let Ok(serials) = crosscal::profile::serials(&store) {
            for s in serials {
                for (path, p) in crosscal::profile::history(&store, &s).unwrap() {
                    assert!(p.is_ok(), "{} is not a complete profile: {:?}", path.display(), p.err());
                }
            }
        }
    }
    let (code, out, err) = run_in(d, &["batch", "lot", "--rules", "rules.json", "--resume"]);
    assert_eq!(code, 1, "{out}{err}"); // the corrupt unit fails
    let r = report(&d.join("lot"));
    // Units 0..16: only the corrupt unit 12 fails (the missing file is in unit 25).
    assert_eq!(r.units.iter().filter(|u| u.verdict == Verdict::Pass).count(), 15);
    // One profile per unit: interrupted units were either finished or redone, never doubled.
    let store = d.join("calib-profiles");
    for s in crosscal::profile::serials(&store).unwrap() {
        assert_eq!(crosscal::profile::history(&store, &s).unwrap().len(), 1, "{s}");
    }
}

/// `batch` accepts every session `fit` accepts: a lot of multi-position (hand-held) units is
/// fitted and judged like stand units; the clean ones pass an `adequate` rule, the one with
/// a hidden gyro g-sensitivity fails it by name, and rules that need a per-sample reference
/// say that a protocol session has none instead of "could not be processed".
#[test]
fn a_lot_of_protocol_sessions_is_fitted_and_judged() {
    use crosscal::simulate::protocol::multi_position;
    let d = tempfile::tempdir().unwrap();
    let (clean, hidden) = crate::common::clean_and_g_sensitive();
    for (i, truth) in [&clean, &clean, &hidden].into_iter().enumerate() {
        let mut sim = multi_position(truth, 20.0, 24, 3.0, 2 + i as u64);
        sim.manifest.serial = format!("HAND-{i}");
        sim.write(&d.path().join(format!("lot/u{i}"))).unwrap();
    }
    std::fs::write(
        d.path().join("rules.json"),
        r#"{"format":"crosscal-rules/1","rules":[{"kind":"adequate"},{"kind":"std_error","select":"accel.k_xx","max":0.1}]}"#,
    )
    .unwrap();
    let (code, out, err) = run_in(d.path(), &["batch", "lot", "--rules", "rules.json"]);
    assert_eq!(code, 1, "{out}{err}");
    let r = report(&d.path().join("lot"));
    let by = |u: &str| r.units.iter().find(|x| folder(x) == u).unwrap();
    for u in ["u0", "u1"] {
        assert_eq!(by(u).verdict, Verdict::Pass, "{u}: {:?}", by(u).reasons);
    }
    assert_eq!(by("u2").verdict, Verdict::Fail);
    assert!(by("u2").reasons.iter().any(|x| x.contains("gyro-g-sensitivity")), "{:?}", by("u2").reasons);
    std::fs::write(
        d.path().join("rules2.json"),
        r#"{"format":"crosscal-rules/1","rules":[{"kind":"reduction","sensor":"gyro","min":10}]}"#,
    )
    .unwrap();
    let (_, out, err) = run_in(d.path(), &["batch", "lot", "--rules", "rules2.json", "--out", "cp2"]);
    let r = report(&d.path().join("lot"));
    assert!(r.units.iter().all(|u| u.verdict == Verdict::Fail), "{out}{err}");
    assert!(r.units[0].reasons[0].contains("no per-sample reference"), "{:?}", r.units[0].reasons);
}
