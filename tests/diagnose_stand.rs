//! The stand as a suspect: sessions recorded on an imperfect stand whose manifest declares
//! the nominal motion (the simulator's `StandErrors`, real stand kinematics
//! R(θ) = Rz(−θ)·Ry(α)·Rz(θ) with θ(t) variable and a tilted vertical). `diagnose` must name
//! the stand with the value within 3 standard errors, add no sensor effect for it, still
//! find a sensor effect present alongside, and leave clean sessions alone.

use crate::diagnose::{hidden, run_diagnose};
use crosscal::diagnose::{Diagnosis, StandFinding};
use crosscal::session::Session;
use crosscal::simulate::stand::StandErrors;

/// The paper's session (noise 0.002 °/s, 2e-5 g) with `effect` hidden in the unit and the
/// stand's errors set by `stand` (KEY=VALUE as `simulate --stand`).
fn on_stand(effect: &str, values: &[(&str, f64)], stand: &[&str], seed: u64) -> Session {
    let (mut cfg, _) = hidden(effect, values, seed);
    let mut e = StandErrors::default();
    for s in stand {
        e.set(s).unwrap();
    }
    cfg.stand = e;
    cfg.generate()
}

fn finding<'a>(d: &'a Diagnosis, ids: &[&str]) -> &'a StandFinding {
    d.stand
        .iter()
        .find(|f| ids.contains(&f.id.as_str()))
        .unwrap_or_else(|| panic!("no stand finding {ids:?}: stand {:#?}\nsteps {:?}", d.stand, effects(d)))
}

fn effects(d: &Diagnosis) -> Vec<&str> {
    d.steps.iter().map(|s| s.effect.as_str()).collect()
}

/// Asserts a stand value is within 3 SE of the truth (and prints the measured z).
fn within(f: &StandFinding, name: &str, truth: f64) {
    let v = f.values.iter().find(|v| v.name.starts_with(name)).unwrap_or_else(|| panic!("{name} in {f:#?}"));
    let se = v.std_error.unwrap_or_else(|| panic!("{name} has no standard error: {f:#?}"));
    let z = (v.value - truth) / se;
    println!("{}: {} = {:.5} ± {:.5} {} (truth {truth}, z = {z:.2})", f.id, v.name, v.value, se, v.unit);
    assert!(z.abs() < 3.0, "{}: {} = {} ± {se}, truth {truth}", f.id, v.name, v.value);
}

/// A stand error alone: named as the stand, no sensor effect, residual explained.
fn stand_only(stand: &[&str], seed: u64) -> Diagnosis {
    let d = run_diagnose(&on_stand("", &[], stand, seed));
    assert!(
        d.steps.is_empty(),
        "{stand:?} seed {seed}: sensor effects added: {:?} (stand {:#?})",
        effects(&d),
        d.stand
    );
    assert!(d.unexplained.is_empty(), "{stand:?} seed {seed}: {:?}", d.unexplained);
    for f in &d.stand {
        println!("{}", f.message);
    }
    d
}

#[test]
fn a_cone_angle_off_its_label_is_the_stand() {
    for seed in [1, 2] {
        let d = stand_only(&["cone=0.3"], seed);
        within(finding(&d, &["cone-angle"]), "cone angle offset", 0.3);
        assert!(
            d.stand[0].message.contains("not 10°")
                && d.stand[0].message.contains("--stand")
                && !d.stand[0].message.contains("± 0.000°"),
            "{}",
            d.stand[0].message
        );
    }
}

#[test]
fn a_stand_rate_off_its_label_is_the_stand() {
    for seed in [3, 4] {
        let d = stand_only(&["rate=-0.005"], seed);
        within(finding(&d, &["stand-rate"]), "rate error", -0.5);
    }
}

/// The stand's rate drifting within the runs (from each run's first sample: the stand
/// starts at its rate and slows or speeds up). Before the drift was a stand parameter the
/// diagnosis took a constant rate 0.19 % off, a false once-per-revolution ripple, and left
/// the residual unexplained.
#[test]
fn a_rate_drifting_within_the_runs_is_the_stand() {
    for seed in [12, 13] {
        let d = stand_only(&["drift=-1.4e-4"], seed);
        assert_eq!(d.stand.len(), 1, "{:#?}", d.stand);
        within(finding(&d, &["stand-rate-drift"]), "rate drift", -1.4e-4 * 6000.0);
        assert!(d.stand[0].message.contains("%/min") || d.stand[0].message.contains("per minute"));
    }
    // A different drift in some runs: named per run, the steady ones not listed.
    let drifts = [-1.4e-4, 0.0, 2e-4, 0.0, 8e-5, 0.0];
    let d = stand_only(&["drift=-1.4e-4,0,2e-4,0,8e-5,0"], 14);
    let f = finding(&d, &["stand-rate-drift-per-run"]);
    for (i, v) in f.values.iter().enumerate() {
        within(&StandFinding { values: vec![v.clone()], ..f.clone() }, &v.name, drifts[i % 6] * 6000.0);
    }
    println!("{}", f.message);
    assert!(f.message.contains("9 of 18 runs"), "{}", f.message);
}

/// A stand that logs its angle (an encoder column) is still a suspect for what the log
/// does not hold: its cone angle and base tilt. Its speed ripple and drift are the log's,
/// never reported. Before, such runs had no stand parameters: a cone angle and tilt off
/// their labels ended "unexplained" after 90 s, with accel-cubic and -quadratic tried.
#[test]
fn a_stand_that_logs_its_angle_is_still_the_suspect_for_its_cone_and_tilt() {
    let d = stand_only(&["encoder=0.001", "cone=0.2", "tilt=0.2,-0.1", "ripple1=0.01,30", "drift=1e-4"], 15);
    within(finding(&d, &["cone-angle"]), "cone angle offset", 0.2);
    let f = finding(&d, &["base-tilt"]);
    within(f, "base tilt about x", 0.2);
    within(f, "base tilt about y", -0.1);
    let ids: Vec<&str> = d.stand.iter().map(|f| f.id.as_str()).collect();
    assert_eq!(ids.len(), 2, "{ids:?}");
}

/// Some runs log the stand's angle, the others do not: a drift of the rate is found on those
/// that do not (the others follow their log), and the words say so (before, "within every
/// conic run"), beside the base tilt every run shares.
#[test]
fn a_drift_on_the_runs_that_do_not_log_their_angle_is_said_of_those() {
    let (mut cfg, _) = hidden("", &[], 18);
    let mut e = StandErrors::default();
    for s in ["encoder=0.001", "drift=1e-4", "tilt=0.2,-0.1"] {
        e.set(s).unwrap();
    }
    cfg.stand = e;
    let mut session = cfg.generate();
    for run in session.runs.iter_mut().skip(1).step_by(2) {
        run.rec.angle_rad = None;
        run.spec.angle_column = None;
    }
    let d = run_diagnose(&session);
    assert!(d.steps.is_empty() && d.unexplained.is_empty(), "{:?} {:?}", effects(&d), d.unexplained);
    let f = finding(&d, &["stand-rate-drift"]);
    println!("{}", f.message);
    within(f, "rate drift", 1e-4 * 6000.0);
    assert!(f.message.contains("every conic run that does not log its angle"), "{}", f.message);
    let t = finding(&d, &["base-tilt"]);
    within(t, "base tilt about x", 0.2);
    within(t, "base tilt about y", -0.1);
}

/// `compare` climbs the ladder on the motion the stand's findings correct: a cone angle off
/// its label and a tilted base are not rungs of sensor effects. Before, its ladder was the
/// diagnosis without the stand (on 1e6 samples: 25 s and 196 MB, sensor effects for the
/// stand's error).
#[test]
fn the_model_ladder_is_on_the_motion_the_stand_corrects() {
    use crosscal::estimate::FitOptions;
    use crosscal::motion::DerivativeConfig;
    let s = on_stand(
        "gyro-g-sensitivity",
        &[("gyro.g_xx", 2e-4), ("gyro.g_zy", -3e-4)],
        &["cone=0.3", "tilt=0.1,0.05"],
        20,
    );
    let tr = crosscal::estimate::tracks(&s, &DerivativeConfig::default());
    let runs = crosscal::estimate::fit_runs(&s, &tr);
    let motions: Vec<&crosscal::session::MotionSpec> = s.runs.iter().map(|r| &r.spec.motion).collect();
    let (rungs, d) = crosscal::diagnose::compare(&runs, &motions, &FitOptions::default(), &[]).unwrap();
    let names: Vec<&str> = rungs.iter().map(|r| r.model.as_str()).collect();
    println!("{names:?}");
    assert_eq!(names, ["paper (eqs. 3-4)", "default", "+ gyro-g-sensitivity"], "{:#?}", d.stand);
    within(finding(&d, &["cone-angle"]), "cone angle offset", 0.3);
    let t = finding(&d, &["base-tilt"]);
    within(t, "base tilt about x", 0.1);
    within(t, "base tilt about y", 0.05);
    // The last rung leaves every channel at its noise floor.
    let last = rungs.last().unwrap();
    for c in 0..6 {
        assert!(last.rms[c] < 1.05 * last.noise_floor[c], "channel {c}: {} vs {}", last.rms[c], last.noise_floor[c]);
    }
}

/// A 0.001° encoder on a stand whose rate is off and whose speed ripples: the runs follow
/// the log, and its resolution, amplified by the derivative, is not the gyro's noise. Before
/// (an 11-sample window), the gyro's noise floor read 0.00226 °/s with an AR(10) model
/// (truth: white, 0.002 °/s); on a rate 0.5 % off, narrow lines at 6 and 12 Hz (the
/// window's side lobes) ended "unexplained".
#[test]
fn an_encoders_resolution_is_not_the_units_noise() {
    for (seed, stand) in [(21, ["rate=0.00123", "ripple2=0.005,40"]), (19, ["rate=0.005", "ripple1=0.002,10"])] {
        let d = stand_only(&["encoder=0.001", stand[0], stand[1]], seed);
        assert!(d.stand.is_empty(), "{:#?}", d.stand);
        for n in d.noise.iter().filter(|n| n.sensor == crosscal::units::SensorKind::Gyro) {
            let sigma_deg_s = n.sigma.to_degrees();
            println!("seed {seed}: gyro {} σ {sigma_deg_s:.6} °/s, lag-1 {:.3}", n.axis, n.lag1);
            assert!((sigma_deg_s / 0.002 - 1.0).abs() < 0.03 && n.lag1.abs() < 0.05, "{n:?}");
        }
    }
}

/// An encoder whose zero is off the stand's: the logged angle is turned by a constant. Before,
/// a 0.5° offset became a base tilt of 0.48° and 0.47°, a cone wobble, and an unexplained
/// residual drawn as hysteresis.
#[test]
fn an_encoder_off_the_stands_zero_is_named_as_its_offset() {
    for (seed, offset) in [(16, 0.5), (17, -2.0)] {
        let d = stand_only(&["encoder=0.001", &format!("encoder-offset={offset}")], seed);
        assert_eq!(d.stand.len(), 1, "{:#?}", d.stand);
        within(finding(&d, &["encoder-offset"]), "logged angle offset", offset);
    }
}

#[test]
fn starting_phases_off_their_labels_are_the_stand() {
    let phases = [1.5, -2.0, 0.7, 3.0, -1.2, 2.2];
    let d = stand_only(&["phase=1.5,-2.0,0.7,3.0,-1.2,2.2"], 5);
    let f = finding(&d, &["phase-per-run"]);
    for (i, v) in f.values.iter().enumerate() {
        within(&crosscal::diagnose::StandFinding { values: vec![v.clone()], ..f.clone() }, &v.name, phases[i % 6]);
    }
}

#[test]
fn a_tilted_base_is_the_stand() {
    for seed in [6, 7] {
        let d = stand_only(&["tilt=0.2,-0.1"], seed);
        let f = finding(&d, &["base-tilt"]);
        within(f, "base tilt about x", 0.2);
        within(f, "base tilt about y", -0.1);
    }
}

/// A tilted base under MEMS-like slow noise (flicker 5 °/h and 50 µg, rate random walk
/// 2 °/h/√h, carried from run to run over one session clock). The tilt's once per
/// revolution is as slow as the wander on these runs: measured on the residual of the
/// declared motion, the slow noise took it in, and the diagnosis added accel-drift,
/// -quadratic, -cubic and -scale-asymmetry instead (4 of 5 seeds before the slow-noise
/// diagnosis started from the motion the first one corrected).
#[test]
fn a_tilted_base_under_flicker_and_random_walk_is_the_stand() {
    const DEG: f64 = std::f64::consts::PI / 180.0;
    for seed in [3, 5, 6] {
        let (mut cfg, _) = hidden("", &[], seed);
        cfg.stand.set("tilt=0.15,0.1").unwrap();
        cfg.gyro_process.bias_instability = 5.0 * DEG / 3600.0;
        cfg.gyro_process.random_walk = 2.0 * DEG / 3600.0 / 60.0;
        cfg.accel_process.bias_instability = 50e-6 * cfg.g_m_s2;
        cfg.carry_noise = true;
        cfg.realism.session_clock_gap_s = Some(10.0);
        let d = run_diagnose(&cfg.generate());
        assert!(d.steps.is_empty(), "seed {seed}: sensor effects added: {:?} (stand {:#?})", effects(&d), d.stand);
        assert!(d.unexplained.is_empty(), "seed {seed}: {:?}", d.unexplained);
        let f = finding(&d, &["base-tilt"]);
        within(f, "base tilt about x", 0.15);
        within(f, "base tilt about y", 0.1);
    }
}

#[test]
fn a_speed_ripple_once_and_twice_per_revolution_is_the_stand() {
    let d = stand_only(&["ripple1=0.005,30"], 8);
    let f = finding(&d, &["speed-ripple-1"]);
    within(f, "speed ripple once per revolution", 0.5);
    within(f, "speed ripple once per revolution, phase", 30.0);
    let d = stand_only(&["ripple2=0.004,-60"], 9);
    let f = finding(&d, &["speed-ripple-2"]);
    within(f, "speed ripple twice per revolution", 0.4);
}

#[test]
fn the_earths_rotation_undeclared_is_the_environment() {
    let d = stand_only(&["earth=48,30"], 10);
    let f = finding(&d, &["earth-rotation"]);
    let omega = 7.292_115e-5_f64.to_degrees() * 3600.0;
    within(f, "Earth's rate, vertical", omega * 48f64.to_radians().sin());
    within(f, "Earth's rate, horizontal", omega * 48f64.to_radians().cos());
}

/// The Earth's rotation undeclared beside a gyro g-sensitivity, on conic runs alone: the
/// vertical rate follows gravity as the g-sensitivity's diagonal does, so no value of it is
/// printed (no standard error on the arbitrary split); the horizontal part still is.
#[test]
fn the_earths_vertical_rate_beside_a_g_sensitivity_is_not_given_a_value() {
    let s = on_stand("gyro-g-sensitivity", &[("gyro.g_zz", 3e-5)], &["earth=52,30"], 9);
    let d = run_diagnose(&s);
    assert_eq!(effects(&d), ["gyro-g-sensitivity"], "stand {:#?}", d.stand);
    let f = finding(&d, &["earth-rotation"]);
    println!("{}", f.message);
    let vertical = f.values.iter().find(|v| v.name.starts_with("Earth's rate, vertical")).expect("vertical");
    assert_eq!(vertical.std_error, None, "{f:#?}");
    assert!(f.message.contains("vertical part not separable") && !f.message.contains("latitude 1"), "{}", f.message);
    let omega = 7.292_115e-5_f64.to_degrees() * 3600.0;
    within(f, "Earth's rate, horizontal", omega * 52f64.to_radians().cos());
}

#[test]
fn a_sensor_effect_beside_a_stand_error_is_still_found() {
    let s = on_stand("accel-quadratic", &[("accel.q_x", 0.02), ("accel.q_y", -0.01)], &["cone=0.3"], 11);
    let d = run_diagnose(&s);
    assert_eq!(effects(&d), ["accel-quadratic"], "stand {:#?}", d.stand);
    within(finding(&d, &["cone-angle"]), "cone angle offset", 0.3);
    // The fit the verdict proposes follows the stand, not the manifest's cone angle.
    assert_eq!(d.fit_command("s/session.json"), "crosscal fit s/session.json --effect accel-quadratic --stand");
    assert!(d.unexplained.is_empty(), "{:?}", d.unexplained);
}

/// A session above the size from which the stand is looked for first on every k-th sample
/// (250k samples): the groups that look finds are carried into the diagnosis on every
/// sample, judged again there and estimated again at its end. The cone angle off and the
/// tilted base are the stand, with values within 3 SE of every sample's standard errors
/// (not the reduced runs'), the hidden dead zone is the unit, and nothing else is added.
#[test]
fn a_large_session_looks_for_the_stand_on_every_kth_sample_first() {
    let dz = [("gyro.dz_x", 9e-4), ("gyro.dz_y", 5e-4), ("gyro.dz_z", 7e-4)];
    let (mut cfg, _) = hidden("gyro-dead-zone", &dz, 31);
    for r in &mut cfg.runs {
        r.duration_s = 250_000.0 / 100.0 / 18.0;
    }
    let mut e = StandErrors::default();
    e.set("cone=0.3").unwrap();
    e.set("tilt=0.1,0.05").unwrap();
    cfg.stand = e;
    let d = run_diagnose(&cfg.generate());
    assert_eq!(effects(&d), ["gyro-dead-zone"], "stand {:#?}", d.stand);
    within(finding(&d, &["cone-angle"]), "cone angle offset", 0.3);
    let f = finding(&d, &["base-tilt"]);
    within(f, "base tilt about x", 0.1);
    within(f, "base tilt about y", 0.05);
    assert_eq!(d.stand.len(), 2, "{:#?}", d.stand);
    assert!(d.unexplained.is_empty(), "{:?}", d.unexplained);
}

#[test]
fn clean_stands_bring_no_stand_finding() {
    let mut false_findings = 0;
    for seed in 0..6 {
        let d = run_diagnose(&on_stand("", &[], &[], 900 + seed));
        false_findings += d.stand.len() + d.steps.len();
        // A steady stand is never taken for one spinning up (no run is cut).
        false_findings += d.warnings.iter().filter(|w| w.contains("not at its speed")).count();
    }
    println!("false discoveries on 6 clean sessions: {false_findings}");
    assert_eq!(false_findings, 0);
}

/// Runs recorded from rest: the stand spins up over the first 2 s of each (raised-cosine
/// rate), then runs at speed ω·1 s behind the manifest's phase. The first seconds are left
/// out with a warning, and what stays is a starting phase per run of −ω·1 s. Before, the
/// steady stand's parameters shared the spin-up's misfit out: a 2 % and a 6 % speed ripple,
/// a cone angle and a rate 5 % off, none of which the stand had.
#[test]
fn runs_recorded_while_the_stand_spins_up_are_cut_and_the_lag_is_the_phase() {
    for seed in [21, 22] {
        let d = stand_only(&["spinup=2"], seed);
        let cut = d.warnings.iter().find(|w| w.contains("not at its speed")).expect("a warning on the spin-up");
        assert!(cut.contains("18 conic run"), "{cut}");
        assert!(d.stand.iter().all(|f| f.id == "phase-per-run"), "{:#?}", d.stand);
        let f = finding(&d, &["phase-per-run"]);
        // The paper's runs in order: rates 10, −10, 20 °/s at each cone angle and mount.
        let rates = [10.0, -10.0, 20.0];
        for (i, v) in f.values.iter().enumerate() {
            let truth = -rates[i % 3] * 1.0;
            let se = v.std_error.expect("a standard error");
            assert!((v.value - truth).abs() < 3.0 * se, "{}: {} ± {se}, truth {truth}", v.name, v.value);
        }
    }
}

/// A unit whose bias differs in each run on one channel (a turn-on bias, 0.01 °/s or
/// 1 mg between runs) is a misfit nothing in the motion explains: no stand term is named
/// for it (per-run cone angles and rates once took slivers of it, because the evidence
/// held the channel to its noise floor), no sensor effect is added, and the shape says
/// "turn-on bias" on that channel.
#[test]
fn a_turn_on_bias_is_not_the_stand() {
    use crosscal::simulate::realism::Disturbance;
    let mut wrong = Vec::new();
    for (seed, spec) in [(1, "turnon:gyro-x:0.01"), (2, "turnon:gyro-y:0.003"), (3, "turnon:accel-z:0.001")] {
        let (mut cfg, _) = hidden("", &[], 40 + seed);
        cfg.realism.disturbances = vec![Disturbance::parse(spec).unwrap()];
        let d = run_diagnose(&cfg.generate());
        let shapes: Vec<(String, &str)> =
            d.shapes.iter().map(|s| (format!("{} {}", s.sensor, s.axis), s.kind.as_str())).collect();
        println!(
            "{spec}: stand {:?}, steps {:?}, shapes {shapes:?}",
            d.stand.iter().map(|f| &f.id).collect::<Vec<_>>(),
            effects(&d)
        );
        let channel = spec.split(':').nth(1).unwrap().replace('-', " ");
        if !d.stand.is_empty() || !d.steps.is_empty() || !shapes.contains(&(channel.clone(), "turn-on bias")) {
            wrong.push(format!(
                "{spec}: stand {:?}, steps {:?}, shapes {shapes:?}",
                d.stand.iter().map(|f| &f.id).collect::<Vec<_>>(),
                effects(&d)
            ));
        }
    }
    assert!(wrong.is_empty(), "{}", wrong.join("\n"));
}

/// A gyro that saturates near the paper plan's largest rates leaves a residual no
/// catalogued effect explains; stand groups that take a few χ² of it on the cone's
/// harmonics (an Earth's rate of 145 °/h, a speed ripple of 0.0007 %) are not the stand.
#[test]
fn a_gyro_that_saturates_is_not_the_stand() {
    use crosscal::simulate::realism::Disturbance;
    let mut wrong = Vec::new();
    for (seed, spec) in [(16, "saturate:gyro:25"), (17, "saturate:gyro:22"), (18, "saturate:gyro:28")] {
        let (mut cfg, _) = hidden("", &[], seed);
        cfg.realism.disturbances = vec![Disturbance::parse(spec).unwrap()];
        let d = run_diagnose(&cfg.generate());
        let stand: Vec<&str> = d.stand.iter().map(|f| f.message.as_str()).collect();
        println!("{spec}: verdict {:?}, stand {stand:?}, steps {:?}", d.verdict, effects(&d));
        if !d.stand.is_empty() || !d.proposal.is_empty() {
            wrong.push(format!("{spec}: stand {stand:?}, proposal {:?}", d.proposal));
        }
    }
    assert!(wrong.is_empty(), "{}", wrong.join("\n"));
}

#[test]
fn a_run_on_another_mount_is_named_with_the_mount_that_fits() {
    // Declared [+y, +z, +x]; recorded on [+z, +x, +y].
    let d = stand_only(&["mount=yzx-cone+10:+z,+x,+y"], 12);
    let f = finding(&d, &["mount"]);
    assert!(f.message.contains("'yzx-cone+10'") && f.message.contains("[+z, +x, +y]"), "{}", f.message);
    assert_eq!(d.stand.iter().filter(|f| f.id == "mount").count(), 1, "{:#?}", d.stand);
    // A fit cannot follow a wrong mount: the manifest is corrected first.
    assert!(d.fit_command("s/session.json").starts_with("correct the run's mount in the manifest"));
}
