//! Discovery: a session with one effect the model lacks; `diagnose` must name it.

use crosscal::diagnose::{channel_reports, diagnose_with_mode, residuals, Diagnosis, SlowNoiseMode, Verdict};
use crosscal::estimate::FitOptions;
use crosscal::estimate::{fit_runs, tracks};
use crosscal::model::Model;
use crosscal::motion::DerivativeConfig;
use crosscal::session::{MotionSpec, Session};
use crosscal::simulate::{conic_plan, cyclic_mounts, SimConfig};
use crosscal::units::SensorKind;

const DEG: f64 = std::f64::consts::PI / 180.0;
const G: f64 = 9.80665;

/// The paper's multi-run session (rates ±10, +20 °/s; cone 10° and 20°; three mounts) with
/// realistic noise and the given hidden effect values.
pub fn hidden(effect: &str, values: &[(&str, f64)], seed: u64) -> (SimConfig, Session) {
    let mut cfg = SimConfig::paper();
    cfg.gyro_noise_deg_s = 0.002;
    cfg.accel_noise_g = 2e-5;
    cfg.seed = seed;
    if !effect.is_empty() {
        cfg.truth.model.add_effect(effect).unwrap();
        if effect.contains("temp") {
            cfg.temperature_c = Some(vec![15.0, 35.0]);
        }
    }
    for (n, v) in values {
        cfg.truth.values.insert(n.to_string(), *v);
    }
    let s = cfg.generate();
    (cfg, s)
}

/// Diagnoses a session from the default model as `crosscal diagnose` does (slow noise
/// `auto`).
pub fn run_diagnose(s: &Session) -> Diagnosis {
    run_diagnose_mode(s, &FitOptions::default(), SlowNoiseMode::Auto)
}

/// Diagnoses a session from the default model with these fit options (slow noise `on`
/// or `off` as `opts.slow_noise` says).
pub fn run_diagnose_with(s: &Session, opts: &FitOptions) -> Diagnosis {
    let mode = if opts.slow_noise { SlowNoiseMode::On } else { SlowNoiseMode::Off };
    run_diagnose_mode(s, opts, mode)
}

/// Diagnoses a session from the default model with these fit options and slow-noise mode.
pub fn run_diagnose_mode(s: &Session, opts: &FitOptions, mode: SlowNoiseMode) -> Diagnosis {
    let tr = tracks(s, &DerivativeConfig::default());
    let runs = fit_runs(s, &tr);
    let motions: Vec<&MotionSpec> = s.runs.iter().map(|r| &r.spec.motion).collect();
    diagnose_with_mode(&Model::default_model(), &runs, &motions, opts, mode).unwrap()
}

/// Runs the discovery acceptance for one hidden effect.
fn discovers(effect: &str, values: &[(&str, f64)]) {
    let (cfg, s) = hidden(effect, values, 11);
    let d = run_diagnose(&s);
    let first = d.steps.first().unwrap_or_else(|| panic!("{effect}: nothing proposed: {d:#?}"));
    assert!(
        first.effect == effect || first.indistinguishable.iter().any(|e| e == effect),
        "{effect}: ranked {} first (tied: {:?})",
        first.effect,
        first.indistinguishable
    );
    assert_eq!(d.verdict, Verdict::Explained, "{effect}: {:?} {:?}", d.verdict, d.unexplained);
    let sensor = first.score.sensor;
    let before: Vec<_> = d.channels.iter().filter(|c| c.sensor == sensor).collect();
    let after: Vec<_> = d.steps.last().unwrap().channels.iter().filter(|c| c.sensor == sensor).collect();
    let noise = match sensor {
        SensorKind::Gyro => cfg.gyro_noise_deg_s * DEG,
        SensorKind::Accel => cfg.accel_noise_g * G,
    };
    for a in &after {
        assert!(
            (a.residual_rms / noise - 1.0).abs() < 0.1,
            "{effect} {}: residual {} vs noise {noise}",
            a.axis,
            a.residual_rms
        );
    }
    // Against the paper's own model (eqs. 3-4) on the same runs.
    let paper = Model::paper();
    let tr = tracks(&s, &DerivativeConfig::default());
    let runs = fit_runs(&s, &tr);
    let motions: Vec<&MotionSpec> = s.runs.iter().map(|r| &r.spec.motion).collect();
    let pf = crosscal::estimate::fit(&crosscal::estimate::FitRequest::runs(&paper, &runs)).unwrap().fit;
    let paper_channels = channel_reports(&residuals(&paper, &pf, &runs, &motions), &motions);
    let sys_paper: f64 =
        paper_channels.iter().filter(|c| c.sensor == sensor).map(|c| c.systematic_rms).fold(0.0, f64::max);
    let rms_paper: f64 =
        paper_channels.iter().filter(|c| c.sensor == sensor).map(|c| c.residual_rms).fold(0.0, f64::max);
    let rms_before: f64 = before.iter().map(|c| c.residual_rms).fold(0.0, f64::max);
    assert!(rms_paper >= rms_before * 0.99, "{effect}: the default model should not be worse than the paper's");
    let sys_after: f64 = after.iter().map(|c| c.systematic_rms).fold(0.0, f64::max);
    assert!(sys_after * 10.0 <= sys_paper, "{effect}: systematic {sys_paper} (paper model) -> {sys_after}");
    // Coefficients of the added effect within 4 standard errors of truth.
    let mut m = Model::default_model();
    m.add_effect(effect).unwrap();
    let f = crate::common::fit_session(&s, &m, &FitOptions::default()).unwrap();
    let mut checked = 0;
    for c in f.gyro.coefficients.iter().chain(&f.accel.coefficients).filter(|c| c.effect == effect) {
        let t = cfg.truth.value(&c.name).unwrap();
        if let Some(se) = c.std_error {
            assert!((c.value - t).abs() < 4.0 * se, "{}: {} ± {se}, true {t}", c.name, c.value);
            checked += 1;
        }
    }
    for p in f.nonlinear.iter().filter(|p| p.effect == effect) {
        let t = cfg.truth.value(&p.name).unwrap();
        let se = p.std_error.unwrap_or_else(|| panic!("{}: no standard error", p.name));
        assert!((p.value - t).abs() < 4.0 * se, "{}: {} ± {se}, true {t}", p.name, p.value);
        checked += 1;
    }
    assert!(checked > 0, "{effect}: nothing checked");
}

#[test]
fn discovers_time_delay_of_5_ms() {
    discovers("time-delay", &[("time_delay", 0.005)]);
    // And recovers it within 0.2 ms.
    let (_, s) = hidden("time-delay", &[("time_delay", 0.005)], 3);
    let mut m = Model::default_model();
    m.add_effect("time-delay").unwrap();
    let f = crate::common::fit_session(&s, &m, &FitOptions::default()).unwrap();
    let tau = f.nonlinear[0].value;
    assert!((tau - 0.005).abs() < 2e-4, "τ = {tau}");
}

#[test]
fn discovers_dead_zone() {
    discovers("gyro-dead-zone", &[("gyro.dz_x", 0.0009), ("gyro.dz_y", 0.0005), ("gyro.dz_z", 0.0007)]);
}

/// A search started near the optimum (Newton steps from `Model::start_near`, as the
/// diagnosis starts one from its first look) lands where the scan and simplex land, with
/// the same standard errors; a start that is not near (half the true widths, tiny steps)
/// still ends there, through the simplex.
#[test]
fn a_near_start_lands_where_the_scan_does() {
    let truth = [0.0009, 0.0005, 0.0007];
    let (_, s) =
        hidden("gyro-dead-zone", &[("gyro.dz_x", truth[0]), ("gyro.dz_y", truth[1]), ("gyro.dz_z", truth[2])], 5);
    let mut m = Model::default_model();
    m.add_effect("gyro-dead-zone").unwrap();
    let opts = FitOptions::default();
    let scanned = crate::common::fit_session(&s, &m, &opts).unwrap();
    let value_se = |f: &crosscal::estimate::Fit| -> Vec<(f64, f64)> {
        f.nonlinear.iter().map(|p| (p.value, p.std_error.expect("a standard error"))).collect()
    };
    let base = value_se(&scanned);
    for (i, (v, se)) in base.iter().enumerate() {
        assert!((v - truth[i]).abs() < 4.0 * se, "scanned {i}: {v} ± {se}, true {}", truth[i]);
    }
    // Near: 2 standard errors off, steps of 3.
    let mut near = m.clone();
    let start: Vec<f64> = base.iter().map(|(v, se)| v + 2.0 * se).collect();
    near.start_near("gyro-dead-zone", &start, base.iter().map(|(_, se)| 3.0 * se).collect());
    // Not near: half the widths, steps of a hundredth of a standard error.
    let mut far = m.clone();
    let start: Vec<f64> = truth.iter().map(|v| 0.5 * v).collect();
    far.start_near("gyro-dead-zone", &start, base.iter().map(|(_, se)| 0.01 * se).collect());
    let near = value_se(&crate::common::fit_session(&s, &near, &opts).unwrap());
    let far = value_se(&crate::common::fit_session(&s, &far, &opts).unwrap());
    for i in 0..3 {
        let ((v0, se0), (v1, se1), (v2, se2)) = (base[i], near[i], far[i]);
        // The simplex stops within a few tenths of a standard error; Newton's steps within
        // a twentieth.
        assert!((v1 - v0).abs() < 0.3 * se0, "near {i}: {v1} against {v0} ± {se0}");
        assert!((v2 - v1).abs() < 0.1 * se1, "far {i}: {v2} against {v1} ± {se1}");
        for (what, se) in [("near", se1), ("far", se2)] {
            assert!((se / se0 - 1.0).abs() < 0.05, "{what} {i}: standard error {se} against {se0}");
        }
    }
}

/// The dead zone's standard errors are those of the noise at the optimum, not of the
/// misfit a search from zero starts with (which made them 14× too large): over 12 seeds
/// the errors' spread matches them.
#[test]
fn dead_zone_standard_errors_match_the_spread_of_the_estimates() {
    let truth = [0.0009, 0.0005, 0.0007];
    let mut m = Model::default_model();
    m.add_effect("gyro-dead-zone").unwrap();
    let (mut z2, mut n) = (0.0, 0.0);
    for seed in 1..=12 {
        let values = [("gyro.dz_x", truth[0]), ("gyro.dz_y", truth[1]), ("gyro.dz_z", truth[2])];
        let (_, s) = hidden("gyro-dead-zone", &values, seed);
        let f = crate::common::fit_session(&s, &m, &FitOptions::default()).unwrap();
        for (p, t) in f.nonlinear.iter().zip(truth) {
            let se = p.std_error.expect("a standard error");
            z2 += ((p.value - t) / se).powi(2);
            n += 1.0;
        }
    }
    // 36 squared z-scores: their mean is 1 ± 0.24 (χ²₃₆/36) when the errors are honest.
    let ratio = z2 / n;
    assert!((0.4..1.8).contains(&ratio), "mean squared z {ratio}");
}

#[test]
fn discovers_gyro_g_sensitivity() {
    let k = DEG / G;
    discovers("gyro-g-sensitivity", &[("gyro.g_xx", 0.02 * k), ("gyro.g_yz", -0.015 * k), ("gyro.g_zy", 0.01 * k)]);
}

#[test]
fn discovers_accel_scale_asymmetry() {
    discovers("accel-scale-asymmetry", &[("accel.sa_x", 1e-3), ("accel.sa_y", -5e-4), ("accel.sa_z", 8e-4)]);
}

#[test]
fn discovers_quadratic_nonlinearity() {
    discovers("gyro-quadratic", &[("gyro.q_x", 0.02), ("gyro.q_y", -0.01), ("gyro.q_z", 0.015)]);
}

#[test]
fn discovers_lever_arm() {
    discovers(
        "accel-lever-arm",
        &[("accel.r_xx", 0.03), ("accel.r_yy", 0.04), ("accel.r_zz", -0.02), ("accel.r_xy", 0.01)],
    );
}

#[test]
fn discovers_temperature_bias() {
    discovers("gyro-temp-bias", &[("gyro.tb_x", 1e-3 * DEG), ("gyro.tb_y", -5e-4 * DEG), ("gyro.tb_z", 8e-4 * DEG)]);
}

#[test]
fn clean_sessions_are_adequate_over_20_seeds() {
    for seed in 0..20 {
        let (_, s) = hidden("", &[], 500 + seed);
        let d = run_diagnose(&s);
        assert_eq!(d.verdict, Verdict::Adequate, "seed {seed}: {:#?}", d.steps);
        assert!(d.proposal.is_empty());
        assert!(d.disagreements.is_empty(), "seed {seed}: {:?}", d.disagreements);
    }
}

/// Adds `amp_rad_s`·sin(h·θ + phase) to gyro axis `axis` of every conic run (θ the cone
/// angle at each sample): a residual locked to the cone's harmonic h.
fn add_cone_harmonic(s: &mut Session, axis: usize, h: f64, amp_rad_s: f64, phase: f64) {
    for run in &mut s.runs {
        if let MotionSpec::Conic { cone_angle_deg, rate_deg_s, phase_deg } = run.spec.motion {
            let c = crosscal::motion::Conic::from_deg(cone_angle_deg, rate_deg_s, phase_deg);
            let t_s = run.rec.t_s.clone();
            for (k, g) in run.rec.gyro.make_mut().iter_mut().enumerate() {
                g[axis] += amp_rad_s * (h * c.theta(t_s[k]) + phase).sin();
            }
        }
    }
}

#[test]
fn an_uncatalogued_wobble_is_reported_as_unexplained() {
    let (_, mut s) = hidden("", &[], 77);
    // A 3rd-harmonic wobble of 0.01 °/s on gyro y only, phase 40°, in every conic run.
    add_cone_harmonic(&mut s, 1, 3.0, 0.01 * DEG, 0.7);
    let d = run_diagnose(&s);
    assert_eq!(d.verdict, Verdict::Unexplained, "{:#?}", d.steps);
    assert!(d.proposal.is_empty());
    assert!(d.unexplained.iter().any(|u| u.starts_with("gyro y") && u.contains("harmonic 3")), "{:?}", d.unexplained);
}

/// A shape locked to the cone above the harmonics a run's basis fits (here harmonic 23,
/// 0.004 °/s on gyro y: the sharp edges of a play or a stand's gear ripple) is held by
/// nothing in the model: the verdict is unexplained and names the harmonic, not adequate.
#[test]
fn a_cone_harmonic_above_the_basis_is_unexplained_not_adequate() {
    let (_, mut s) = hidden("", &[], 78);
    add_cone_harmonic(&mut s, 1, 23.0, 0.004 * DEG, 0.3);
    let d = run_diagnose(&s);
    assert_eq!(d.verdict, Verdict::Unexplained, "{:#?} {:?}", d.steps, d.lines);
    assert!(d.proposal.is_empty() && d.steps.is_empty(), "{:?}", d.steps);
    let said = d.unexplained.iter().find(|u| u.starts_with("gyro y") && u.contains("harmonic 23"));
    assert!(said.is_some_and(|u| u.contains("beyond what the model holds")), "{:?}", d.unexplained);
    assert!(d.unexplained.iter().all(|u| u.starts_with("gyro y")), "{:?}", d.unexplained);
}

/// Two candidates the runs cannot tell apart are one finding, with the runs that would
/// separate them; recording those runs separates them.
#[test]
fn aliased_candidates_come_with_the_runs_that_separate_them() {
    use crosscal::frames::Mount;
    use crosscal::simulate::RunPlan;
    // One mount, one direction: accelerometer quadratic and scale asymmetry look alike.
    let narrow = |c: &mut SimConfig| c.runs.retain(|r| r.mount == Mount::identity() && !r.name.contains('-'));
    let (mut cfg, _) = hidden("accel-quadratic", &[("accel.q_x", 0.02), ("accel.q_y", -0.01)], 3);
    narrow(&mut cfg);
    let d = run_diagnose(&cfg.generate());
    let first = d.steps.first().expect("a step");
    let named: Vec<&str> =
        std::iter::once(first.effect.as_str()).chain(first.indistinguishable.iter().map(String::as_str)).collect();
    assert!(named.contains(&"accel-quadratic") && named.contains(&"accel-scale-asymmetry"), "{named:?}");
    let sep = first.separated_by.as_ref().expect("a separating run");
    assert!(sep.rho_now > 0.99 && sep.rho_with < sep.rho_now - 0.03, "{sep}");
    // Record the proposed runs as well: the two are told apart and the right one is named.
    for (i, p) in sep.runs.iter().enumerate() {
        cfg.runs.push(RunPlan {
            name: format!("proposed-{i}"),
            motion: MotionSpec::Conic { cone_angle_deg: p.cone_angle_deg, rate_deg_s: p.rate_deg_s, phase_deg: 0.0 },
            mount: Mount::parse(&p.mount).unwrap(),
            duration_s: p.duration_s,
        });
    }
    let d = run_diagnose(&cfg.generate());
    let first = d.steps.first().expect("a step");
    // The pair the runs were proposed for is told apart (other pairs may still need theirs).
    assert_eq!(first.effect, "accel-quadratic", "{:?}", first.indistinguishable);
    assert!(!first.indistinguishable.iter().any(|e| e == "accel-scale-asymmetry"), "{:?}", first.indistinguishable);
    assert_eq!(d.verdict, Verdict::Explained, "{:?}", d.unexplained);
}

/// Issue 36: a weak gyro g-sensitivity (a few standard errors of its coefficients on these
/// runs) is named as g-sensitivity when it is named at all, never as anisoelasticity,
/// whose 15 products of specific force reach the same residual with more parameters.
#[test]
fn a_weak_gyro_g_sensitivity_is_not_named_anisoelasticity() {
    let (_, clean) = hidden("", &[], 5);
    let mut m = Model::default_model();
    m.add_effect("gyro-g-sensitivity").unwrap();
    let f = crate::common::fit_session(&clean, &m, &FitOptions::default()).unwrap();
    let se = |name: &str| f.gyro.coefficients.iter().find(|c| c.name == name).and_then(|c| c.std_error).unwrap();
    let values = [("gyro.g_xx", 4.0 * se("gyro.g_xx")), ("gyro.g_yz", -3.0 * se("gyro.g_yz"))];
    for seed in [1, 2, 3, 4, 5, 6] {
        let (_, s) = hidden("gyro-g-sensitivity", &values, seed);
        let d = run_diagnose(&s);
        let named: Vec<&str> = d.steps.iter().map(|st| st.effect.as_str()).collect();
        assert!(named.iter().all(|e| *e == "gyro-g-sensitivity"), "seed {seed}: {values:?} named {named:?}");
    }
}

/// Adds a play (backlash) of `half_play` rad/s to every gyro axis: the output holds after
/// each turn of the input until the input has moved by twice the play.
fn add_play(s: &mut Session, half_play: f64) {
    let tr = tracks(s, &DerivativeConfig::default());
    for (run, track) in s.runs.iter_mut().zip(&tr) {
        let mut held: Option<[f64; 3]> = None;
        for (k, g) in run.rec.gyro.make_mut().iter_mut().enumerate() {
            let w = track.at(k).w_rad_s.xyz;
            let y = held.map_or(w, |h| std::array::from_fn(|i| h[i].clamp(w[i] - half_play, w[i] + half_play)));
            for i in 0..3 {
                g[i] += y[i] - w[i];
            }
            held = Some(y);
        }
    }
}

/// Issue 36: a play-type hysteresis of 0.02 °/s on every gyro axis (white noise
/// 0.002 °/s) does not bring a time delay with it: the delay is never added, nor any effect
/// but the catalogue's hysteresis; where nothing explains it the shape says hysteresis with
/// the play's size. No systematic part or noise floor is sized above the residual that
/// holds it. On the paper's runs (one or two revolutions) the square wave's high harmonics
/// cannot be told from coloured noise within a run, and the report says so; on runs of
/// three or more revolutions the noise model is the simulated one (its floor within 2× of
/// 0.002 °/s, not the play's 0.014 °/s).
#[test]
fn a_play_type_hysteresis_brings_no_time_delay() {
    let half_play = 0.02 * DEG;
    for (seed, long) in [(1, false), (2, false), (3, true), (4, true)] {
        let mut cfg = SimConfig::paper();
        cfg.gyro_noise_deg_s = 0.002;
        cfg.accel_noise_g = 2e-5;
        cfg.seed = seed;
        if long {
            cfg.runs = conic_plan(&[10.0, -10.0, 20.0], &[10.0, 20.0], &cyclic_mounts(3), 120.0);
        }
        let mut s = cfg.generate();
        add_play(&mut s, half_play);
        let d = run_diagnose(&s);
        let named: Vec<&str> = d.steps.iter().map(|st| st.effect.as_str()).collect();
        let sigma: Vec<String> = d.noise.iter().take(3).map(|n| format!("{:.4}", n.sigma / DEG)).collect();
        let shapes: Vec<&str> = d.shapes.iter().map(|s| s.words.as_str()).collect();
        println!(
            "seed {seed} long {long}: {:?} {named:?} gyro σ {sigma:?} deg/s\n  {shapes:#?}\n  tried {:#?}",
            d.verdict, d.tried
        );
        assert!(!named.contains(&"time-delay"), "seed {seed}: named {named:?}");
        assert!(
            d.verdict != Verdict::Adequate && (named.contains(&"gyro-hysteresis") || !d.unexplained.is_empty()),
            "seed {seed}: {:?} {named:?} {:?}",
            d.verdict,
            d.unexplained
        );
        assert!(named.iter().all(|e| *e == "gyro-hysteresis"), "seed {seed}: named {named:?}");
        let last = d.steps.last().map_or(&d.channels, |st| &st.channels);
        for c in last.iter().chain(&d.channels) {
            assert!(c.systematic_rms <= 1.0001 * c.residual_rms, "seed {seed}: {c:?}");
            assert!(c.noise_floor <= 1.0001 * c.residual_rms, "seed {seed}: {c:?}");
        }
        if long {
            for n in d.noise.iter().filter(|n| n.sensor == SensorKind::Gyro) {
                assert!(n.sigma < 2.0 * 0.002 * DEG, "seed {seed}: noise floor {} deg/s", n.sigma / DEG);
            }
        } else {
            assert!(
                d.warnings.iter().any(|w| w.contains("takes the whole residual")),
                "seed {seed}: {:#?}",
                d.warnings
            );
        }
        if named.is_empty() {
            let gyro = || d.shapes.iter().filter(|s| s.sensor == SensorKind::Gyro);
            assert_eq!(gyro().map(|s| s.kind.as_str()).collect::<Vec<_>>(), ["hysteresis"; 3], "seed {seed}");
            for sh in gyro() {
                let size: f64 = sh
                    .words
                    .split(": ")
                    .nth(1)
                    .and_then(|w| w.split(' ').next())
                    .and_then(|v| v.parse().ok())
                    .unwrap_or(0.0);
                assert!((size.abs() - 0.02).abs() < 0.005, "seed {seed}: {}", sh.words);
            }
        }
    }
}
