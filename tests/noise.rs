//! Noisy sessions: fitted coefficients lie within their predicted uncertainty, and the
//! predicted standard errors match the Monte Carlo spread.

use crate::common::fit_session;
use crosscal::estimate::{CoefStatus, Fit, FitOptions};
use crosscal::model::Model;
use crosscal::simulate::SimConfig;

/// Paper preset with gyro noise 0.002 °/s and accelerometer noise 2e-5 g per sample.
fn noisy(seed: u64) -> SimConfig {
    let mut c = SimConfig::paper();
    c.gyro_noise_deg_s = 0.002;
    c.accel_noise_g = 2e-5;
    c.seed = seed;
    c
}

fn fits(seeds: std::ops::Range<u64>) -> Vec<(SimConfig, Fit)> {
    let seeds: Vec<u64> = seeds.collect();
    let model = Model::default_model();
    crate::common::par_map(&seeds, |&seed| {
        let cfg = noisy(seed);
        let f = fit_session(&cfg.generate(), &model, &FitOptions::default()).unwrap();
        (cfg, f)
    })
}

#[test]
fn every_coefficient_within_four_standard_errors_over_20_seeds() {
    for (cfg, fit) in fits(100..120) {
        for c in fit.gyro.coefficients.iter().chain(&fit.accel.coefficients) {
            assert_eq!(c.status, CoefStatus::Fitted, "{}", c.name);
            let se = c.std_error.unwrap();
            let truth = cfg.truth.value(&c.name).unwrap();
            assert!(
                (c.value - truth).abs() <= 4.0 * se,
                "seed {}: {} = {} ± {se}, true {truth}",
                cfg.seed,
                c.name,
                c.value
            );
        }
    }
}

#[test]
fn standard_errors_match_monte_carlo_spread() {
    let runs = fits(1000..1200);
    let names: Vec<String> =
        runs[0].1.gyro.coefficients.iter().chain(&runs[0].1.accel.coefficients).map(|c| c.name.clone()).collect();
    let n = runs.len() as f64;
    let mut pooled = Vec::new();
    for name in &names {
        let vals: Vec<f64> = runs.iter().map(|(_, f)| f.get(name).unwrap().value).collect();
        let ses: Vec<f64> = runs.iter().map(|(_, f)| f.get(name).unwrap().std_error.unwrap()).collect();
        let truth = runs[0].0.truth.value(name).unwrap();
        let mean = vals.iter().sum::<f64>() / n;
        let sd = (vals.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (n - 1.0)).sqrt();
        let se = ses.iter().sum::<f64>() / n;
        // 200 seeds: the sample SD has ~5 % relative scatter, so 20 % is a 4σ bound.
        assert!((sd / se - 1.0).abs() < 0.2, "{name}: Monte Carlo sd {sd:e}, predicted {se:e}");
        // Unbiased: the mean is within 4 standard errors of the mean of truth.
        assert!((mean - truth).abs() < 4.0 * sd / n.sqrt(), "{name}: mean {mean} truth {truth}");
        pooled.push(sd / se);
    }
    let avg = pooled.iter().sum::<f64>() / pooled.len() as f64;
    assert!((avg - 1.0).abs() < 0.05, "pooled sd/se ratio {avg}");
}
