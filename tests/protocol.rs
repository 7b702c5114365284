//! Protocol sessions with known truth: simulate a Ferraris and a multi-position session,
//! fit, and check every coefficient against the truth within its reported uncertainty.

use crosscal::estimate::protocol::{fit_protocol, ProtocolOptions};
use crosscal::estimate::{CoefStatus, Fit};
use crosscal::model::{matrix_name, Model};
use crosscal::session::MotionSpec;
use crosscal::simulate::protocol::{ferraris, multi_position, ProtocolTruth};
use crosscal::units::{SensorKind, AXES};

/// Largest |estimate − truth| / σ over the named coefficients, and the worst name.
fn worst_z(fit: &Fit, truth: &[(String, f64)]) -> (f64, String) {
    let mut worst = (0.0, String::new());
    for (name, want) in truth {
        let c = fit.get(name).unwrap_or_else(|| panic!("{name} missing"));
        assert_eq!(c.status, CoefStatus::Fitted, "{name}");
        let se = c.std_error.expect("standard error");
        assert!(se > 0.0 && se.is_finite(), "{name}: σ {se}");
        let z = (c.value - want).abs() / se;
        if z > worst.0 {
            worst = (z, name.clone());
        }
    }
    worst
}

fn matrix_truth(sensor: SensorKind, letter: &str, m: &nalgebra::Matrix3<f64>, upper_only: bool) -> Vec<(String, f64)> {
    let mut v = Vec::new();
    for i in 0..3 {
        for j in 0..3 {
            if !upper_only || j >= i {
                v.push((matrix_name(sensor, letter, i, j), m[(i, j)]));
            }
        }
    }
    v
}

#[test]
fn ferraris_session_recovers_k_c_g_and_biases_within_their_uncertainty() {
    let truth = ProtocolTruth::mems(false);
    let sim = ferraris(&truth, 4.0, -360.0, 11);
    let session = sim.session();
    let (fit, report) = fit_protocol(&session, &Model::ferraris(), &ProtocolOptions::default()).unwrap();
    let mut want = matrix_truth(SensorKind::Accel, "k", &truth.k_accel, false);
    want.extend(matrix_truth(SensorKind::Gyro, "c", &truth.c_gyro, false));
    want.extend(matrix_truth(SensorKind::Gyro, "g", &truth.g_gyro, false));
    for i in 0..3 {
        want.push((format!("accel.b_{}", AXES[i]), truth.b_accel[i]));
        want.push((format!("gyro.b_{}", AXES[i]), truth.b_gyro[i]));
    }
    let (z, name) = worst_z(&fit, &want);
    println!("ferraris: worst |error|/σ {z:.2} ({name}); |a|−g rms {:.2e} m/s²", report.gravity_rms_m_s2);
    // Over 20 seeds the worst of these 42 ratios ranged 1.4–3.5 (σ floored at the noise of
    // a pose mean: six faces alone leave 2 degrees of freedom per channel).
    assert!(z < 4.0, "{name}: {z}");
    // And in absolute terms: scale to 0.05 %, the unit's percent-level couplings to 1e-3.
    let c_xx = fit.get("gyro.c_xx").unwrap().value;
    assert!((c_xx / truth.c_gyro[(0, 0)] - 1.0).abs() < 5e-4, "{c_xx}");
    assert!(report.gravity_rms_m_s2 < 0.01);
    assert_eq!(report.turns.len(), 3);
}

#[test]
fn ferraris_turn_sign_is_checked() {
    let truth = ProtocolTruth::mems(false);
    let mut sim = ferraris(&truth, 2.0, 360.0, 3);
    // Declare the opposite of what was turned: the fit warns, and the scale comes out negative.
    for r in &mut sim.manifest.runs {
        if let crosscal::session::MotionSpec::Rotation { angle_deg, .. } = &mut r.motion {
            *angle_deg = -360.0;
        }
    }
    let (fit, report) = fit_protocol(&sim.session(), &Model::ferraris(), &ProtocolOptions::default()).unwrap();
    assert_eq!(report.warnings.iter().filter(|w| w.contains("opposite sign")).count(), 3, "{:?}", report.warnings);
    assert!(fit.get("gyro.c_xx").unwrap().value < 0.0);
}

#[test]
fn multi_position_session_recovers_the_unit_in_the_accelerometer_frame() {
    let truth = ProtocolTruth::mems(true);
    let sim = multi_position(&truth, 20.0, 24, 3.0, 5);
    let t0 = std::time::Instant::now();
    let (fit, report) = fit_protocol(&sim.session(), &Model::tedaldi(), &ProtocolOptions::default()).unwrap();
    let took = t0.elapsed().as_secs_f64();
    let det = report.detection.as_ref().unwrap();
    assert_eq!(report.poses.len(), 25, "initial rest + 24 poses: {det:?}");
    let mut want = matrix_truth(SensorKind::Accel, "k", &truth.k_accel, true);
    want.extend(matrix_truth(SensorKind::Gyro, "c", &truth.c_gyro, false));
    for i in 0..3 {
        want.push((format!("accel.b_{}", AXES[i]), truth.b_accel[i]));
    }
    let (z, name) = worst_z(&fit, &want);
    println!(
        "multi-position: worst |error|/σ {z:.2} ({name}); threshold ×{:?}; |a|−g rms {:.2e} m/s²; {took:.2} s",
        det.multiplier, report.gravity_rms_m_s2
    );
    assert!(z < 4.5, "{name}: {z}");
    // The gyro bias is the initial rest's mean, which includes G·a of that pose.
    for i in 0..3 {
        let b = fit.get(&format!("gyro.b_{}", AXES[i])).unwrap().value;
        let expect = truth.b_gyro[i] + (truth.g_gyro * nalgebra::Vector3::new(0.0, 0.0, truth.g_m_s2))[i];
        assert!((b - expect).abs() < 5.0 * truth.noise.0 / (20.0 * truth.rate_hz).sqrt(), "b_{i}: {b} vs {expect}");
    }
    // Lower entries of K are the gauge, held at zero.
    assert_eq!(fit.get("accel.k_yx").unwrap().status, CoefStatus::Fixed);
}

#[test]
fn multi_position_with_g_sensitivity_fits_it_from_the_poses() {
    let truth = ProtocolTruth::mems(true);
    let sim = multi_position(&truth, 20.0, 24, 3.0, 8);
    let mut model = Model::tedaldi();
    model.add_effect("gyro-g-sensitivity").unwrap();
    let (fit, _) = fit_protocol(&sim.session(), &model, &ProtocolOptions::default()).unwrap();
    let mut want = matrix_truth(SensorKind::Gyro, "g", &truth.g_gyro, false);
    for i in 0..3 {
        want.push((format!("gyro.b_{}", AXES[i]), truth.b_gyro[i]));
    }
    want.extend(matrix_truth(SensorKind::Gyro, "c", &truth.c_gyro, false));
    let (z, name) = worst_z(&fit, &want);
    println!("multi-position + g-sensitivity: worst |error|/σ {z:.2} ({name})");
    assert!(z < 4.5, "{name}: {z}");
}

#[test]
fn protocol_sessions_refuse_what_they_cannot_identify() {
    let truth = ProtocolTruth::mems(false);
    let session = ferraris(&truth, 2.0, -360.0, 1).session();
    let e = fit_protocol(&session, &Model::default_model(), &ProtocolOptions::default()).unwrap_err();
    assert!(e.to_string().contains("gyro-angular-acceleration"), "{e}");
    let e =
        fit_protocol(&multi_position(&truth, 2.0, 3, 1.5, 1).session(), &Model::tedaldi(), &ProtocolOptions::default())
            .unwrap_err();
    assert!(e.to_string().contains("initial rest") || e.to_string().contains("too few"), "{e}");
}

#[test]
fn diagnose_finds_a_hidden_accelerometer_nonlinearity_on_six_faces_and_the_fit_removes_it() {
    use crosscal::diagnose::protocol::diagnose_protocol;
    let mut truth = ProtocolTruth::mems(false);
    truth.q_accel = nalgebra::Vector3::new(0.05, -0.04, 0.06); // counts per (m/s²)²: ~5 counts at 1 g
    let session = ferraris(&truth, 4.0, -360.0, 21).session();
    let d = diagnose_protocol(&session, &Model::ferraris()).unwrap();
    let best = d.proposal.clone().expect("a proposal");
    assert!(best == "accel-quadratic" || best == "accel-scale-asymmetry", "{best}");
    assert!(d.indistinguishable.iter().any(|e| e.starts_with("accel-")), "{:?}", d.indistinguishable);
    assert_eq!(d.candidates[0].fittable, Ok(()));
    let mut model = Model::ferraris();
    model.add_effect("accel-quadratic").unwrap();
    let (fit, after) = fit_protocol(&session, &model, &ProtocolOptions::default()).unwrap();
    println!(
        "hidden accel quadratic: |a|−g rms {:.2e} → {:.2e} m/s²",
        d.report.gravity_rms_m_s2, after.gravity_rms_m_s2
    );
    assert!(after.gravity_rms_m_s2 < d.report.gravity_rms_m_s2 / 10.0);
    for (i, q) in truth.q_accel.iter().enumerate() {
        let c = fit.get(&format!("accel.q_{}", AXES[i])).unwrap();
        assert!(
            (c.value - q).abs() < 4.0 * c.std_error.unwrap(),
            "q_{i}: {} ± {} vs {q}",
            c.value,
            c.std_error.unwrap()
        );
    }
}

#[test]
fn diagnose_finds_hidden_gyro_g_sensitivity_in_a_multi_position_session_and_nothing_in_clean_ones() {
    use crosscal::diagnose::protocol::diagnose_protocol;
    let (clean, hidden) = crate::common::clean_and_g_sensitive();
    for seed in [2, 3, 4] {
        let d = diagnose_protocol(&multi_position(&clean, 20.0, 24, 3.0, seed).session(), &Model::tedaldi()).unwrap();
        assert_eq!(d.proposal, None, "seed {seed}: {:?}", d.candidates.first());
        // Nothing else stands out either: the clean session is adequate.
        assert!(d.adequate(), "seed {seed}: {:?}", d.standing_out());
    }
    let session = multi_position(&hidden, 20.0, 24, 3.0, 2).session();
    let d = diagnose_protocol(&session, &Model::tedaldi()).unwrap();
    assert_eq!(d.proposal.as_deref(), Some("gyro-g-sensitivity"), "{:?}", d.candidates.first());
    let mut model = Model::tedaldi();
    model.add_effect("gyro-g-sensitivity").unwrap();
    let (_, after) = fit_protocol(&session, &model, &ProtocolOptions::default()).unwrap();
    let (before, after) = (d.report.gyro_cost.unwrap(), after.gyro_cost.unwrap());
    println!("hidden gyro g-sensitivity: gyro cost {before:.3e} → {after:.3e}");
    assert!(after < before);
}

#[test]
fn cli_fits_diagnoses_and_corrects_a_protocol_session_and_refuses_stand_only_commands() {
    use crate::common::run_in;
    let tmp = tempfile::tempdir().unwrap();
    let truth = ProtocolTruth::mems(false);
    ferraris(&truth, 3.0, -360.0, 4).write(&tmp.path().join("s")).unwrap();
    let (code, out, err) = run_in(tmp.path(), &["fit", "s/session.json", "--out", "store"]);
    assert_eq!(code, 0, "{out}{err}");
    assert!(
        out.contains("protocol: ferraris (6 static poses, 3 turns/motions)") && out.contains("raw per rad/s"),
        "{out}"
    );
    let profile = std::fs::read_dir(tmp.path().join("store/SIM-FERRARIS")).unwrap().next().unwrap().unwrap().path();
    let text = std::fs::read_to_string(&profile).unwrap();
    assert!(text.contains("\"protocol\"") && text.contains("\"ferraris\""), "the profile keeps the protocol report");
    let (code, out, err) = run_in(tmp.path(), &["diagnose", "s/session.json"]);
    assert_eq!(code, 0, "{out}{err}");
    assert!(out.contains("verdict: the model is adequate"), "{out}");
    let (code, out, err) = run_in(
        tmp.path(),
        &["correct", "--profile", profile.to_str().unwrap(), "s/recording.csv", "-o", "corrected.csv"],
    );
    assert_eq!(code, 0, "{out}{err}");
    let (code, _, err) = run_in(tmp.path(), &["check", "s/session.json", "--profile", profile.to_str().unwrap()]);
    assert_ne!(code, 0);
    assert!(err.contains("protocol session"), "{err}");
    let (code, _, err) =
        run_in(tmp.path(), &["fit", "s/session.json", "--effect", "gyro-angular-acceleration", "--dry-run"]);
    assert_ne!(code, 0);
    assert!(err.contains("gyro-angular-acceleration"), "{err}");
}

#[test]
fn importers_name_file_line_and_column_of_bad_input() {
    use crate::common::run_in;
    let tmp = tempfile::tempdir().unwrap();
    let csv = "n_samples,gyr_x,gyr_y,gyr_z,acc_x,acc_y,acc_z\n0,0,0,0,9.8,0,0\n1,0,zero,0,9.8,0,0\n";
    std::fs::write(tmp.path().join("f.csv"), csv).unwrap();
    std::fs::write(tmp.path().join("l.json"), "{\"x_p\": {\"start\": 0, \"end\": 1}}").unwrap();
    let (code, _, err) =
        run_in(tmp.path(), &["import", "imucal-ferraris", "f.csv", "l.json", "--rate-hz", "100", "--out", "o"]);
    assert_eq!(code, 6, "{err}");
    assert!(err.contains("f.csv:3:3 (gyr_y)") && err.contains("'zero'"), "{err}");
    std::fs::write(tmp.path().join("f.csv"), csv.replace("zero", "0")).unwrap();
    let (code, _, err) =
        run_in(tmp.path(), &["import", "imucal-ferraris", "f.csv", "l.json", "--rate-hz", "100", "--out", "o"]);
    assert_ne!(code, 0);
    assert!(err.contains("section 'x_a' is missing"), "{err}");
    // imu_tk files that do not share time stamps.
    std::fs::write(tmp.path().join("a.mat"), "0.0 1 2 3\n0.01 1 2 3\n").unwrap();
    std::fs::write(tmp.path().join("g.mat"), "0.0 1 2 3\n0.02 1 2 3\n").unwrap();
    let (code, _, err) = run_in(tmp.path(), &["import", "imu-tk", "a.mat", "g.mat", "--out", "o2"]);
    assert_eq!(code, 8, "{err}");
    assert!(err.contains("g.mat:2:1 (t)"), "{err}");
    assert!(!tmp.path().join("o/session.json").exists() && !tmp.path().join("o2/session.json").exists());
}

#[test]
fn ferraris_sections_are_found_from_the_data() {
    use crosscal::stats::segment::detect_ferraris;
    let truth = ProtocolTruth::mems(false);
    for (turn, sign) in [(-360.0, -1.0), (360.0, 1.0)] {
        let sim = ferraris(&truth, 3.0, turn, 9);
        let r = &sim.recording;
        // The simulated rests around each turn last 1 s (100 samples): a 21-sample window
        // and 50-sample poses see them.
        let found = detect_ferraris(&r.t_s, &r.gyro, &r.accel, 21, 10.0, 50).unwrap();
        assert_eq!(found.len(), 9);
        for sec in &found {
            let declared = sim.manifest.runs.iter().find(|s| s.name == sec.name).unwrap();
            let (s0, e0) = declared.rows.unwrap();
            let overlap = sec.rows.1.min(e0).saturating_sub(sec.rows.0.max(s0));
            assert!(overlap * 2 > e0 - s0, "{}: found {:?}, declared {:?}", sec.name, sec.rows, (s0, e0));
            if sec.name.ends_with("_rot") {
                assert!(sec.sign * sign > 0.0, "{}: sign {}", sec.name, sec.sign);
            }
        }
    }
}

/// A declared initial rest that runs into the first turn (declared 26 s, the unit moves at
/// 20 s): the fit stops and names the time the motion starts, within one detector window;
/// with `trim_rest` it uses the still part and says so, and recovers the unit as a clean
/// session does. Clean sessions (several seeds) pass the check.
#[test]
fn motion_inside_the_declared_rest_is_found_and_reported_or_trimmed() {
    let truth = ProtocolTruth::mems(true);
    for seed in [5, 6, 7] {
        let sim = multi_position(&truth, 20.0, 24, 3.0, seed);
        assert!(fit_protocol(&sim.session(), &Model::tedaldi(), &ProtocolOptions::default()).is_ok(), "seed {seed}");
    }
    let mut sim = multi_position(&truth, 20.0, 24, 3.0, 5);
    for run in &mut sim.manifest.runs {
        if let MotionSpec::MultiPosition { init_rest_s, .. } = &mut run.motion {
            *init_rest_s = 26.0;
        }
    }
    let err = fit_protocol(&sim.session(), &Model::tedaldi(), &ProtocolOptions::default()).unwrap_err().to_string();
    assert!(err.contains("not at rest") && err.contains("--trim-rest"), "{err}");
    let at: f64 = err.split("motion from t = ").nth(1).and_then(|s| s.split(' ').next()).unwrap().parse().unwrap();
    // The window is 51 samples (0.51 s at 100 Hz): the motion starts at 20 s.
    let window_s = 51.0 / truth.rate_hz;
    assert!((at - 20.0).abs() <= window_s, "motion reported at {at} s, starts at 20 s");
    let opts = ProtocolOptions { trim_rest: true, ..Default::default() };
    let (fit, report) = fit_protocol(&sim.session(), &Model::tedaldi(), &opts).unwrap();
    let det = report.detection.unwrap();
    assert!(det.rest_note.contains("shortened from 26 s"), "{}", det.rest_note);
    assert_eq!(det.declared_rest_samples, Some((26.0 * truth.rate_hz) as usize));
    assert!(det.init_rest_samples as f64 <= 20.0 * truth.rate_hz, "{}", det.init_rest_samples);
    for i in 0..3 {
        let b = fit.get(&format!("gyro.b_{}", AXES[i])).unwrap().value;
        let expect = truth.b_gyro[i] + (truth.g_gyro * nalgebra::Vector3::new(0.0, 0.0, truth.g_m_s2))[i];
        assert!((b - expect).abs() < 5.0 * truth.noise.0 / (19.0 * truth.rate_hz).sqrt(), "b_{i}: {b} vs {expect}");
    }
}

/// Protocol diagnose is "adequate" only when no pose or turn stands out beyond the noise and
/// the pose-to-pose scatter (clean sessions are adequate: the g-sensitivity test above): a
/// motion recorded with a 10 % gyro glitch (one turn integrates wrong) is "not adequate" and
/// the turn is named.
#[test]
fn protocol_diagnose_names_a_turn_that_stands_out_and_is_not_adequate_then() {
    use crosscal::diagnose::protocol::diagnose_protocol;
    // Clean seeds are adequate: checked in the g-sensitivity test above.
    let (clean, _) = crate::common::clean_and_g_sensitive();
    let mut sim = multi_position(&clean, 20.0, 24, 3.0, 2);
    // The first turn runs from 20 s to 21.5 s at 100 Hz.
    for w in &mut sim.recording.gyro.make_mut()[2000..2150] {
        for v in w.iter_mut() {
            *v *= 1.1;
        }
    }
    let d = diagnose_protocol(&sim.session(), &Model::tedaldi()).unwrap();
    assert!(!d.adequate(), "a glitched turn passed");
    assert!(
        d.outlier_turns.iter().any(|t| t.starts_with("pose 0 → 1") || t.starts_with("pose 1 → 2")),
        "{:?}",
        d.standing_out()
    );
}

/// Every detected pose and every static run is checked against the noise of the rest: a
/// slow drift inside one pose (the gyro turning by 0.05 °/s, the accelerometer tilting) and
/// a knock inside one Ferraris face are named — in the report, in `diagnose` (not adequate)
/// — while the clean seeds' poses and faces all pass (no false alarm over 5 × 24 poses).
#[test]
fn every_pose_and_static_run_is_checked_against_the_rest() {
    use crosscal::diagnose::protocol::diagnose_protocol;
    let truth = ProtocolTruth::mems(true);
    let model = Model::tedaldi();
    for seed in 20..25 {
        let sim = multi_position(&truth, 20.0, 24, 3.0, seed);
        let (_, report) = fit_protocol(&sim.session(), &model, &ProtocolOptions::default()).unwrap();
        let moving: Vec<_> = report.poses.iter().filter(|p| p.motion.is_some()).collect();
        assert!(moving.is_empty(), "seed {seed}: clean poses flagged {moving:?}");
        let sim = ferraris(&truth, 3.0, 360.0, seed);
        let (_, report) = fit_protocol(&sim.session(), &Model::ferraris(), &ProtocolOptions::default()).unwrap();
        assert!(report.poses.iter().all(|p| p.motion.is_none()), "seed {seed}: {:?}", report.poses);
    }
    // A drift inside the 6th pose.
    let mut sim = multi_position(&truth, 20.0, 24, 3.0, 20);
    let (_, report) = fit_protocol(&sim.session(), &model, &ProtocolOptions::default()).unwrap();
    let run_start = sim.manifest.runs[0].rows.map_or(0, |r| r.0);
    let p = report.poses[5].clone();
    let (s, e) = (run_start + p.start, run_start + p.end);
    let scale = truth.c_gyro[(2, 2)];
    for k in s + (e - s) / 2..e {
        sim.recording.gyro.make_mut()[k][2] += 0.05f64.to_radians() * scale;
    }
    let (_, report) = fit_protocol(&sim.session(), &model, &ProtocolOptions::default()).unwrap();
    let flagged: Vec<_> = report.poses.iter().filter(|q| q.motion.is_some()).collect();
    assert_eq!(flagged.len(), 1, "{flagged:?}");
    assert_eq!((flagged[0].start, flagged[0].end), (p.start, p.end));
    assert!(flagged[0].motion.as_deref().unwrap().contains("gyro mean drifts"), "{flagged:?}");
    let d = diagnose_protocol(&sim.session(), &model).unwrap();
    assert!(!d.adequate() && d.moving_poses.len() == 1, "{:?}", d.moving_poses);

    // A knock (a 0.3 s burst on the accelerometer) in the middle of Ferraris face y_p.
    let mut sim = ferraris(&truth, 3.0, 360.0, 20);
    let face = sim.manifest.runs.iter().find(|r| r.name == "y_p").unwrap().rows.unwrap();
    let mid = (face.0 + face.1) / 2;
    for k in mid..mid + 30 {
        sim.recording.accel.make_mut()[k][0] += 2000.0 * ((k - mid) as f64 * 1.3).sin();
    }
    let (_, report) = fit_protocol(&sim.session(), &Model::ferraris(), &ProtocolOptions::default()).unwrap();
    let flagged: Vec<&str> = report.poses.iter().filter(|q| q.motion.is_some()).map(|q| q.run.as_str()).collect();
    assert_eq!(flagged, ["y_p"], "{:?}", report.poses);
}

/// Rates at rest judged against the noise, not only against each other: a gyro bias that
/// warms up after the rest (a ramp of 4 counts, 0.06 °/s, over the recording) gives every
/// pose a rate at rest none of them stands out from; diagnose says the rates are beyond the
/// noise (χ²) and is not adequate. Clean seeds stay near χ²/dof = 1 on both tests.
#[test]
fn rates_at_rest_beyond_the_noise_are_not_adequate_even_when_none_stands_out() {
    use crosscal::diagnose::protocol::diagnose_protocol;
    let (clean, _) = crate::common::clean_and_g_sensitive();
    let ratio = |r: &crosscal::estimate::protocol::ProtocolReport| {
        let z: Vec<f64> = r
            .poses
            .iter()
            .flat_map(|p| {
                let se = p.rate_se_deg_s.unwrap();
                (0..3).map(move |i| p.rate_at_rest_deg_s[i] / se[i])
            })
            .collect();
        z.iter().map(|v| v * v).sum::<f64>() / z.len() as f64
    };
    for seed in [2, 3, 4] {
        let d = diagnose_protocol(&multi_position(&clean, 20.0, 24, 3.0, seed).session(), &Model::tedaldi()).unwrap();
        assert!(d.beyond_noise.is_empty(), "seed {seed}: {:?}", d.beyond_noise);
        let r = ratio(&d.report);
        assert!(r < 2.0, "seed {seed}: clean rates at rest χ²/n = {r}");
    }
    let mut sim = multi_position(&clean, 20.0, 24, 3.0, 2);
    let n = sim.recording.gyro.len() as f64;
    for (k, w) in sim.recording.gyro.make_mut().iter_mut().enumerate().skip(2000) {
        w[1] += 4.0 * (k as f64 - 2000.0) / (n - 2000.0);
    }
    let d = diagnose_protocol(&sim.session(), &Model::tedaldi()).unwrap();
    assert!(d.outlier_rates.is_empty(), "a ramp makes no single outlier: {:?}", d.outlier_rates);
    assert!(!d.adequate(), "a warming bias passed as adequate");
    assert!(d.beyond_noise.iter().any(|b| b.starts_with("calibrated rates at rest are")), "{:?}", d.standing_out());
}

/// Issue 36: on the real hand-held sessions of ../shared/data/real2 (data2–data4), whose rates
/// at rest are many times what the noise explains, no unit effect is named on a p-value the
/// data reject: the verdict says the residual is beyond the noise and lists the suspects
/// before a unit effect, in the same words as a stand session's verdict.
#[test]
fn hand_held_sessions_beyond_the_noise_name_no_unit_effect() {
    let shared =
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/data/real2/imu_tk_ros2_getovermassif");
    if !shared.is_dir() {
        eprintln!("skipped: ../shared/data/real2 is not beside this checkout");
        return;
    }
    let tmp = tempfile::tempdir().unwrap();
    for k in 2..=4 {
        let session = shared.join(format!("session_data{k}/session.json"));
        let (code, out, err) = crate::common::run_in(tmp.path(), &["diagnose", session.to_str().unwrap()]);
        assert_eq!(code, 0, "{out}{err}");
        let verdict = out.lines().find(|l| l.starts_with("verdict:")).unwrap_or_else(|| panic!("{out}"));
        assert!(out.contains("BEYOND NOISE"), "data{k}: {out}");
        assert!(!verdict.starts_with("verdict: add"), "data{k}: {verdict}");
        assert!(verdict.starts_with("verdict: a systematic residual remains"), "data{k}: {verdict}");
        assert!(verdict.contains("not evidence on its own") && verdict.contains("Earth's rotation"), "{verdict}");
        assert!(!out.contains("Fit it with:"), "data{k}: {out}");
    }
}

/// Issue 38 item 12: too few poses says what the counts per threshold mean and what to do.
#[test]
fn too_few_poses_explains_its_counts_and_the_way_out() {
    let truth = ProtocolTruth::mems(false);
    let e = fit_protocol(
        &multi_position(&truth, 20.0, 5, 3.0, 4).session(),
        &Model::tedaldi(),
        &ProtocolOptions::default(),
    )
    .unwrap_err()
    .to_string();
    assert!(e.contains("too few static poses for the 9 accelerometer parameters"), "{e}");
    assert!(e.contains("×m = m times the initial rest's variance"), "{e}");
    assert!(e.contains("Hold 9 or more different orientations still"), "{e}");
}
