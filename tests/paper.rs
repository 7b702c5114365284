//! The paper's unit on the default calibration session, without noise: the acceptance
//! numbers of the core pipeline.

use crate::common::fit_and_calibrate;
use crosscal::app::validate::{check_session, Mode};
use crosscal::check::paper::paper_rows;
use crosscal::check::Thresholds;
use crosscal::model::{forward, Model, State};
use crosscal::simulate::{SimConfig, UnitTruth};
use crosscal::units::SensorKind;

/// The forward model's regressors reproduce paper eq. 3 and eq. 4 written out by hand.
#[test]
fn forward_model_is_paper_eq3_and_eq4() {
    let truth = UnitTruth::paper();
    let s = State {
        t_session_s: 0.0,
        w: [0.3, -0.7, 0.11],
        e: [1.3, 0.4, -2.1],
        a: [0.5, -9.0, 3.0],
        temp_c: f64::NAN,
        temp_rate_c_s: f64::NAN,
    };
    let gt = truth.model.terms(SensorKind::Gyro);
    let u = forward(&gt, &truth.term_values(SensorKind::Gyro), &s);
    let (w, e) = (s.w, s.e);
    let expect =
        [w[0] + 0.01 * w[1] + 0.001 * e[2], w[1] + 0.01 * w[2] + 0.001 * e[0], w[2] + 0.01 * w[0] + 0.001 * e[1]];
    let at = truth.model.terms(SensorKind::Accel);
    let ua = forward(&at, &truth.term_values(SensorKind::Accel), &s);
    let a = s.a;
    let expect_a = [a[0] + 0.01 * (a[1] + a[2]), a[1] + 0.01 * (a[0] + a[2]), a[2] + 0.01 * (a[0] + a[1])];
    for i in 0..3 {
        assert!((u[i] - expect[i]).abs() < 1e-15, "gyro {i}");
        assert!((ua[i] - expect_a[i]).abs() < 1e-14, "accel {i}");
    }
}

#[test]
fn paper_preset_reproduces_the_paper_and_beats_it() {
    let cfg = SimConfig::paper();
    let session = cfg.generate();
    let model = Model::default_model();
    let (fit, _profile, cal) = fit_and_calibrate(&session, &model);

    // Fitted C_w, C_e, K (and biases) match truth to 1e-9.
    for c in fit.gyro.coefficients.iter().chain(&fit.accel.coefficients) {
        let truth = cfg.truth.value(&c.name).expect("truth");
        assert!((c.value - truth).abs() <= 1e-9, "{} = {} (true {truth})", c.name, c.value);
    }
    assert!(fit.gyro.unidentifiable.is_empty() && fit.accel.unidentifiable.is_empty());

    let th = Thresholds::default();
    let offline = check_session(&session, &cal, Mode::Offline, th).unwrap();
    let streaming = check_session(&session, &cal, Mode::Streaming, th).unwrap();
    assert!(offline.pass && streaming.pass);
    let rows = paper_rows(&offline, &streaming, "cone+10").unwrap();

    // Before correction, from the paper's matrices (α = 10°, ω_s = 10 °/s):
    // gyro z: (c_zx ω_x + e_zy ε_y)/ω_z, max = sin α (0.01 − 0.001 ω_s[rad/s]) / (1 − cos α);
    // accel z: 0.01 (a_x + a_y)/a_z, max = 0.01 √2 sin α / cos α.
    let (sa, ca) = 10f64.to_radians().sin_cos();
    let gyro_z = 100.0 * sa * (0.01 - 0.001 * 10f64.to_radians()) / (1.0 - ca);
    let accel_z = 100.0 * 0.01 * 2f64.sqrt() * sa / ca;
    let gz = rows.iter().find(|r| r.sensor == SensorKind::Gyro && r.axis == 'z').unwrap();
    let az = rows.iter().find(|r| r.sensor == SensorKind::Accel && r.axis == 'z').unwrap();
    let gb = gz.before_pct.unwrap();
    let ab = az.before_pct.unwrap();
    assert!((gb - gyro_z).abs() <= 0.02 * gyro_z, "gyro z before {gb} vs {gyro_z}");
    assert!((ab - accel_z).abs() <= 0.02 * accel_z, "accel z before {ab} vs {accel_z}");
    assert!((gb - 11.0).abs() < 0.5 && (ab - 0.25).abs() < 0.01, "paper: 11 % and 0.25 %");

    for r in &rows {
        let after = r.offline_pct.unwrap();
        let red = r.reduction.unwrap();
        match r.sensor {
            SensorKind::Gyro => {
                assert!(after <= 1e-4, "gyro {} after {after} %", r.axis);
                assert!(red >= 1e5, "gyro {} reduction {red}", r.axis);
                assert!(r.streaming_pct.unwrap() <= 0.4 / 100.0, "gyro {} streaming {:?}", r.axis, r.streaming_pct);
            }
            SensorKind::Accel => {
                assert!(after <= 1e-6, "accel {} after {after} %", r.axis);
                assert!(red >= 1e8, "accel {} reduction {red}", r.axis);
                assert!(r.streaming_pct.unwrap() <= 0.000006 / 100.0);
            }
        }
        assert!(r.pass);
    }
    // Over all 18 runs too.
    for s in &offline.summary {
        let after = s.after_pct.unwrap();
        match s.sensor {
            SensorKind::Gyro => assert!(after <= 1e-4 && s.reduction.unwrap() >= 1e5, "{s:?}"),
            SensorKind::Accel => assert!(after <= 1e-6 && s.reduction.unwrap() >= 1e8, "{s:?}"),
        }
    }
    for s in &streaming.summary {
        if s.sensor == SensorKind::Gyro {
            assert!(s.after_pct.unwrap() <= 0.004, "{s:?}");
        }
    }
}

/// The paper's own model (eq. 3 structure, no biases) fits the paper's unit exactly too.
#[test]
fn paper_model_fits_the_paper_unit() {
    let cfg = SimConfig::paper();
    let session = cfg.generate();
    let model = Model::paper();
    let (fit, _, _) = fit_and_calibrate(&session, &model);
    for c in fit.gyro.coefficients.iter().chain(&fit.accel.coefficients) {
        let truth = cfg.truth.value(&c.name).unwrap();
        assert!((c.value - truth).abs() <= 1e-9, "{} = {}", c.name, c.value);
    }
    assert_eq!(fit.gyro.coefficients.iter().filter(|c| c.status == crosscal::estimate::CoefStatus::Fitted).count(), 9);
}

/// A plain inverse that ignores ε leaves about 0.2 % on the paper unit: the ε estimate
/// is what the correction's accuracy rests on.
#[test]
fn ignoring_epsilon_leaves_the_known_error() {
    let cfg = SimConfig::paper();
    let session = cfg.generate();
    let (_, _, mut cal) = fit_and_calibrate(&session, &Model::default_model());
    cal.gyro.eps = crosscal::frames::Coupling::new(nalgebra::Matrix3::zeros());
    let r = check_session(&session, &cal, Mode::Offline, Thresholds::default()).unwrap();
    let run = r.runs.iter().find(|r| r.run == "cone+10").unwrap();
    let z = &run.axes[2];
    let pct = z.pct(z.after.max_abs).unwrap();
    // e_zy ε_y / ω_z = 0.001 ω_s sin α / (1 − cos α) = 0.2 %.
    let (sa, ca) = 10f64.to_radians().sin_cos();
    let expect = 100.0 * 0.001 * 10f64.to_radians() * sa / (1.0 - ca);
    assert!((pct - expect).abs() < 0.02 * expect, "{pct} vs {expect}");
}
