//! Calibrated uncertainty (issue: trustworthy numbers): interval coverage with white and
//! coloured noise, efficiency against the Cramér–Rao bound, and `plan` against Monte Carlo.

use crate::common::fit_session;
use crosscal::estimate::{CoefStatus, Fit, FitOptions};
use crosscal::model::Model;
use crosscal::plan::{default_candidates, plan, PlanSpec};
use crosscal::simulate::{conic_plan, cyclic_mounts, RunPlan, SimConfig};

const DEG: f64 = std::f64::consts::PI / 180.0;
const G: f64 = 9.80665;
const RATE_HZ: f64 = 25.0;
const GYRO_SD: f64 = 0.002; // deg/s per sample
const ACCEL_SD: f64 = 2e-5; // g per sample

/// Nine runs (rates +10, −10, +20 °/s; cone 10°; three mounts), 20 s at 25 Hz.
fn runs() -> Vec<RunPlan> {
    conic_plan(&[10.0, -10.0, 20.0], &[10.0], &cyclic_mounts(3), 20.0)
}

fn config(seed: u64, ar1: bool) -> SimConfig {
    let mut c = SimConfig::paper();
    c.runs = runs();
    c.sample_rate_hz = RATE_HZ;
    c.seed = seed;
    if ar1 {
        c.gyro_process.ar1 = Some((0.95, GYRO_SD * DEG));
        c.accel_process.ar1 = Some((0.95, ACCEL_SD * G));
    } else {
        c.gyro_noise_deg_s = GYRO_SD;
        c.accel_noise_g = ACCEL_SD;
    }
    c
}

/// Fits of `count` simulations on two threads: (truth config, fit).
fn monte_carlo(count: u64, ar1: bool) -> Vec<(SimConfig, Fit)> {
    let seeds: Vec<u64> = (0..count).map(|s| 50_000 + s).collect();
    let model = Model::default_model();
    crate::common::par_map(&seeds, |&seed| {
        let cfg = config(seed, ar1);
        let f = fit_session(&cfg.generate(), &model, &FitOptions::default()).unwrap();
        (cfg, f)
    })
}

/// Fraction of (simulation, coefficient) pairs whose 95 % interval holds the truth.
fn coverage(fits: &[(SimConfig, Fit)]) -> f64 {
    let (mut inside, mut total) = (0usize, 0usize);
    for (cfg, f) in fits {
        for c in f.gyro.coefficients.iter().chain(&f.accel.coefficients) {
            assert_eq!(c.status, CoefStatus::Fitted, "{}", c.name);
            let truth = cfg.truth.value(&c.name).unwrap();
            total += 1;
            inside += usize::from((c.value - truth).abs() <= 1.959964 * c.std_error.unwrap());
        }
    }
    inside as f64 / total as f64
}

fn spec() -> PlanSpec {
    PlanSpec {
        runs: runs(),
        sample_rate_hz: RATE_HZ,
        gyro_density: GYRO_SD * DEG / RATE_HZ.sqrt(),
        accel_density: ACCEL_SD * G / RATE_HZ.sqrt(),
    }
}

#[test]
fn white_noise_coverage_efficiency_and_plan_agree_with_monte_carlo() {
    let fits = monte_carlo(600, false);
    let cov = coverage(&fits);
    println!("white noise: 95 % interval coverage {cov:.4} over {} fits", fits.len());
    assert!((0.93..=0.97).contains(&cov), "coverage {cov}");

    let predicted = plan(&Model::default_model(), &spec(), &[]).unwrap();
    let n = fits.len() as f64;
    let mut ratios = Vec::new();
    for p in &predicted.coefficients {
        let crb = p.std_error.unwrap();
        let vals: Vec<f64> = fits.iter().map(|(_, f)| f.get(&p.name).unwrap().value).collect();
        let mean = vals.iter().sum::<f64>() / n;
        let var = vals.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (n - 1.0);
        // 600 fits: the sample SD scatters by 2.9 %, so 10 % is a 3.4σ bound.
        assert!((var.sqrt() / crb - 1.0).abs() < 0.10, "{}: Monte Carlo sd {:e}, plan {crb:e}", p.name, var.sqrt());
        ratios.push(var / (crb * crb));
    }
    let pooled = ratios.iter().sum::<f64>() / ratios.len() as f64;
    println!(
        "white noise: Monte Carlo variance / Cramér–Rao bound, pooled over {} coefficients: {pooled:.4}",
        ratios.len()
    );
    assert!((pooled - 1.0).abs() < 0.05, "pooled variance / CRB {pooled}");
}

#[test]
fn coloured_noise_coverage_stays_calibrated() {
    // AR(1) with ρ = 0.95 per sample and the white case's σ: the variance of a mean is
    // (1 + ρ)/(1 − ρ) = 39 times the white value.
    let fits = monte_carlo(400, true);
    let cov = coverage(&fits);
    let infl = fits[0].1.gyro.channels[0].coloured_inflation;
    println!("AR(1) ρ = 0.95: 95 % interval coverage {cov:.4}; variance inflation {infl:.1} (theory 39)");
    // 400 fits × 33 coefficients (correlated within a fit): the Monte Carlo spread of the
    // coverage is about ±1 %.
    assert!((0.93..=0.97).contains(&cov), "coverage {cov}");
    assert!((25.0..=55.0).contains(&infl), "inflation {infl}");
    // Without the inflation the intervals would be √39 ≈ 6 times too narrow.
    assert!(fits[0].1.gyro.channels[0].residual_lag1 > 0.9);
}

#[test]
fn single_run_plan_and_fit_name_c_xz_and_the_suggested_run_fixes_it() {
    let one = conic_plan(&[10.0], &[10.0], &cyclic_mounts(1), 36.0);
    let mut s = PlanSpec { runs: one.clone(), sample_rate_hz: 100.0, ..spec() };
    let model = Model::default_model();
    let p = plan(&model, &s, &default_candidates(&s)).unwrap();
    let names = |u: &[crosscal::estimate::Unidentifiable]| -> Vec<String> {
        u.iter().flat_map(|u| u.combination.iter().map(|c| c.0.clone()).chain([u.held.clone()])).collect()
    };
    assert!(names(&p.unidentifiable).contains(&"gyro.c_xz".to_string()), "{:?}", p.unidentifiable);
    // fit on data of that single run says the same.
    let mut cfg = SimConfig::paper();
    cfg.runs = one;
    cfg.gyro_noise_deg_s = GYRO_SD;
    let f = fit_session(&cfg.generate(), &model, &FitOptions::default()).unwrap();
    let fitted_lost = names(&f.gyro.unidentifiable);
    assert!(fitted_lost.contains(&"gyro.c_xz".to_string()), "{fitted_lost:?}");
    // The suggestion resolves it: with the suggested run added nothing involving c_xz is lost.
    let sug = p.suggestion.expect("a suggestion");
    assert!(sug.unidentifiable.1 < sug.unidentifiable.0, "{sug:?}");
    let extra = default_candidates(&s).into_iter().find(|c| c.name == sug.name).unwrap();
    s.runs.push(extra);
    let p2 = plan(&model, &s, &[]).unwrap();
    assert!(!names(&p2.unidentifiable).contains(&"gyro.c_xz".to_string()), "{:?}", p2.unidentifiable);
    let c = p2.coefficients.iter().find(|c| c.name == "gyro.c_xz").unwrap();
    assert_eq!(c.status, CoefStatus::Fitted);
    let b = p2.coefficients.iter().find(|c| c.name == "gyro.b_x").unwrap();
    assert_eq!(b.status, CoefStatus::Fitted);
}
