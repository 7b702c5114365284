//! Spikes and determinism.

use crate::common::fit_session;
use crosscal::estimate::FitOptions;
use crosscal::model::Model;
use crosscal::profile::Profile;
use crosscal::simulate::SimConfig;

#[test]
fn huber_fit_shrugs_off_spikes_that_wreck_least_squares() {
    let mut cfg = SimConfig::paper();
    cfg.gyro_noise_deg_s = 0.002;
    cfg.accel_noise_g = 2e-5;
    cfg.seed = 5;
    let mut s = cfg.generate();
    // 0.5 % of samples get a +5 °/s gyro spike and a +0.05 g accelerometer spike (one-sided,
    // like a glitching converter), rotating over the axes.
    let k = std::f64::consts::PI / 180.0;
    let mut n = 0usize;
    for run in &mut s.runs {
        for i in (37..run.rec.len()).step_by(200) {
            let sign = 1.0;
            run.rec.gyro.make_mut()[i][n % 3] += sign * 5.0 * k;
            run.rec.accel.make_mut()[i][(n + 1) % 3] += sign * 0.05 * 9.80665;
            n += 1;
        }
    }
    let found = s
        .runs
        .iter()
        .flat_map(|r| crosscal::session::sanity::scan_record(&r.rec.t_s, &r.rec.gyro, &r.rec.accel, &r.spec.name));
    assert!(found.filter(|w| w.contains("spike")).count() >= 18, "spikes not reported");

    let m = Model::default_model();
    let ols = fit_session(&s, &m, &FitOptions::default()).unwrap();
    let huber = fit_session(&s, &m, &FitOptions { robust: true, ..FitOptions::default() }).unwrap();
    // Errors in units of the robust standard errors (the least-squares ones are inflated by
    // the spikes, which is itself a symptom).
    let (mut worst_ols, mut worst_huber) = (0.0_f64, 0.0_f64);
    for c in huber.gyro.coefficients.iter().chain(&huber.accel.coefficients) {
        let t = cfg.truth.value(&c.name).unwrap();
        let se = c.std_error.unwrap();
        worst_huber = worst_huber.max((c.value - t).abs() / se);
        worst_ols = worst_ols.max((ols.get(&c.name).unwrap().value - t).abs() / se);
    }
    assert!(worst_huber < 4.0, "robust fit: worst |error|/σ = {worst_huber}");
    assert!(worst_ols > 10.0, "least squares should be visibly hurt: {worst_ols} vs {worst_huber}");
    assert!(huber.gyro.channels.iter().all(|c| c.downweighted > 0));
}

#[test]
fn same_input_gives_bit_identical_profile_apart_from_its_time_stamp() {
    let mut cfg = SimConfig::paper();
    cfg.gyro_noise_deg_s = 0.002;
    cfg.accel_noise_g = 2e-5;
    let m = Model::default_model();
    let json = |robust: bool| {
        let s = cfg.generate();
        let f = fit_session(&s, &m, &FitOptions { robust, ..FitOptions::default() }).unwrap();
        let mut p = Profile::from_fit(&s, &m, f, vec![]);
        p.created_utc = String::new();
        p.to_json()
    };
    for robust in [false, true] {
        assert_eq!(json(robust), json(robust));
    }
}
