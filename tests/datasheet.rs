//! Datasheet quantities, guarded acceptance and lot capability against known truth:
//! simulated units whose true axes, biases and scale factors are drawn from known normals.

use crate::common::{par_map, run_in, run_ok};
use crosscal::app::fit::fit_profile;
use crosscal::check::guarded::Decision;
use crosscal::check::rules::{evaluate, Evidence, Rules};
use crosscal::datasheet::axes::compose;
use crosscal::datasheet::lot::{control_chart, cpk, LotPoint};
use crosscal::datasheet::{build, Datasheet, DEG_H_PER_RAD_S};
use crosscal::estimate::{FitData, FitRequest, ModelChoice};
use crosscal::model::ModelSpec;
use crosscal::profile::Profile;
use crosscal::simulate::{conic_plan, cyclic_mounts, write_session, SimConfig};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};
use std::path::{Path, PathBuf};

const AXES: [char; 3] = ['x', 'y', 'z'];

/// The true datasheet of a simulated unit (what the tests compare with).
#[derive(Debug, Clone, Copy)]
struct Truth {
    /// Gyro non-orthogonality xy, yz, zx, mrad.
    delta_mrad: [f64; 3],
    /// Gyro axes' rotation vector, mrad.
    rot_mrad: [f64; 3],
    /// Gyro scale-factor errors, ppm.
    scale_ppm: [f64; 3],
    /// Gyro biases, °/h.
    bias_deg_h: [f64; 3],
}

/// The lot's distributions: (mean, σ) of misalignment xy (mrad), of every axis's scale
/// error (ppm), of every gyro bias (°/h); the other non-orthogonalities N(0, 0.2 mrad),
/// rotations N(0, 1 mrad).
#[derive(Debug, Clone, Copy)]
struct LotLaw {
    delta_xy: (f64, f64),
    scale: (f64, f64),
    bias: (f64, f64),
}

const LAW: LotLaw = LotLaw { delta_xy: (0.3, 0.2), scale: (200.0, 150.0), bias: (5.0, 3.0) };

fn draw(rng: &mut ChaCha8Rng, law: &LotLaw) -> Truth {
    let n = |m: f64, s: f64, rng: &mut ChaCha8Rng| Normal::new(m, s).unwrap().sample(rng);
    Truth {
        delta_mrad: [n(law.delta_xy.0, law.delta_xy.1, rng), n(0.0, 0.2, rng), n(0.0, 0.2, rng)],
        rot_mrad: [n(0.0, 1.0, rng), n(0.0, 1.0, rng), n(0.0, 1.0, rng)],
        scale_ppm: [0; 3].map(|_| n(law.scale.0, law.scale.1, rng)),
        bias_deg_h: [0; 3].map(|_| n(law.bias.0, law.bias.1, rng)),
    }
}

/// A small conic session of a unit with these true axes, scale and biases.
fn config(serial: &str, seed: u64, t: &Truth, gyro_noise_deg_s: f64) -> SimConfig {
    let mut c = SimConfig::paper();
    c.serial = serial.to_string();
    c.runs = conic_plan(&[10.0, -10.0, 20.0], &[10.0], &cyclic_mounts(3), 10.0);
    c.sample_rate_hz = 25.0;
    c.gyro_noise_deg_s = gyro_noise_deg_s;
    c.accel_noise_g = 2e-5;
    c.seed = seed;
    let m = compose(t.scale_ppm.map(|p| 1.0 + p * 1e-6), t.delta_mrad.map(|d| d * 1e-3), t.rot_mrad.map(|r| r * 1e-3))
        .unwrap();
    for (i, a) in AXES.iter().enumerate() {
        for (j, b) in AXES.iter().enumerate() {
            c.truth.values.insert(format!("gyro.c_{a}{b}"), m[i][j]);
        }
        c.truth.values.insert(format!("gyro.b_{a}"), t.bias_deg_h[i] / DEG_H_PER_RAD_S);
    }
    c
}

/// Fits the default model to a session in memory (as `fit` and `batch` do).
fn fit(cfg: &SimConfig) -> Profile {
    let session = cfg.generate();
    let spec = ModelSpec::default();
    let mut req = FitRequest::new(FitData::Session(&session), ModelChoice::Spec(&spec));
    req.strict = true;
    fit_profile(&req, None).expect("fit").profile
}

fn sheet(p: &Profile) -> Datasheet {
    build("unit.json", p, &[], &Default::default())
}

fn value(d: &Datasheet, name: &str, axis: &str) -> (f64, f64) {
    let q = d.value(name, axis).unwrap_or_else(|| panic!("{name} {axis} missing"));
    (q.value.unwrap(), q.uncertainty.unwrap())
}

const LOT_RULES: &str = r#"{"format":"crosscal-rules/1","decision":"guarded","k":2,"rules":[
  {"kind":"datasheet","name":"misalignment xy","quantity":"gyro.misalignment","axis":"xy","max":1.0,"unit":"mrad"},
  {"kind":"datasheet","name":"gyro bias x","quantity":"gyro.bias","axis":"x","max":12,"unit":"deg/h"},
  {"kind":"datasheet","name":"gyro scale x","quantity":"gyro.scale_factor_error","axis":"x","max":600,"unit":"ppm"}]}"#;

/// Population Cpk of a normal (μ, σ) against ±max.
fn population_cpk((m, s): (f64, f64), max: f64) -> f64 {
    (max - m).min(m + max) / (3.0 * s)
}

/// The decomposition recovers a known non-orthogonality and rotation to 1e-6 rad on
/// noise-free data, through the whole pipeline (simulate, fit, datasheet).
#[test]
fn misalignment_and_frame_rotation_come_back_noise_free() {
    let t = Truth {
        delta_mrad: [0.8, -1.5, 0.4],
        rot_mrad: [2.0, -0.7, 1.1],
        scale_ppm: [300.0, -150.0, 80.0],
        bias_deg_h: [10.0, -4.0, 2.0],
    };
    let d = sheet(&fit(&config("AXES-1", 1, &t, 0.0)));
    for (k, pair) in ["xy", "yz", "zx"].iter().enumerate() {
        let (v, _) = value(&d, "gyro.misalignment", pair);
        assert!((v - t.delta_mrad[k]).abs() < 1e-3, "{pair}: {v} mrad, truth {}", t.delta_mrad[k]);
    }
    for (k, a) in ["x", "y", "z"].iter().enumerate() {
        let (v, _) = value(&d, "gyro.frame_alignment", a);
        assert!((v - t.rot_mrad[k]).abs() < 1e-3, "rotation {a}: {v} mrad, truth {}", t.rot_mrad[k]);
        let (s, _) = value(&d, "gyro.scale_factor_error", a);
        assert!((s - t.scale_ppm[k]).abs() < 1e-2, "scale {a}: {s} ppm, truth {}", t.scale_ppm[k]);
        let (b, _) = value(&d, "gyro.bias", a);
        assert!((b - t.bias_deg_h[k]).abs() < 1e-4, "bias {a}: {b} deg/h, truth {}", t.bias_deg_h[k]);
    }
}

/// Lots of 30 units drawn from known normals, 20 seeds: the reported Cpk's 95 % interval
/// holds the Cpk of the lot's true values in ≥ 19 of 20 seeds (for each rule), and holds the
/// population's Cpk about 95 % of the time (≥ 17 of 20: binomial lower tail 1.6 %).
#[test]
fn lot_cpk_interval_holds_the_true_cpk() {
    let rules = Rules::parse(Path::new("rules.json"), LOT_RULES).unwrap();
    let limits = [1.0, 12.0, 600.0];
    let laws = [LAW.delta_xy, LAW.bias, LAW.scale];
    let mut sample_hits = [0usize; 3];
    let mut population_hits = [0usize; 3];
    let mut z2 = Vec::new();
    for seed in 0..20u64 {
        let mut rng = ChaCha8Rng::seed_from_u64(7000 + seed);
        let truths: Vec<Truth> = (0..30).map(|_| draw(&mut rng, &LAW)).collect();
        let items: Vec<(usize, Truth)> = truths.iter().copied().enumerate().collect();
        let results = par_map(&items, |(i, t)| {
            let p = fit(&config(&format!("L{seed}-{i}"), seed * 100 + *i as u64, t, 0.002));
            let d = sheet(&p);
            let ev = Evidence { datasheet: Some(&d), ..Default::default() };
            evaluate(&rules, &p, &ev)
        });
        for r in 0..3 {
            let fitted: Vec<f64> = results.iter().map(|x| x[r].value.unwrap()).collect();
            let truth: Vec<f64> =
                truths.iter().map(|t| [t.delta_mrad[0], t.bias_deg_h[0], t.scale_ppm[0]][r]).collect();
            for (u, (f, t)) in results.iter().zip(fitted.iter().zip(&truth)) {
                z2.push(((f - t) / u[r].uncertainty.unwrap()).powi(2));
            }
            let max = limits[r];
            let (_, _, c) = cpk(&fitted, Some(-max), Some(max)).unwrap();
            let [c, lo, hi] = c.unwrap();
            let (_, _, ct) = cpk(&truth, Some(-max), Some(max)).unwrap();
            let ct = ct.unwrap()[0];
            let cp = population_cpk(laws[r], max);
            sample_hits[r] += usize::from(lo <= ct && ct <= hi);
            population_hits[r] += usize::from(lo <= cp && cp <= hi);
            if seed == 0 {
                println!("rule {r}: Cpk {c:.3} [{lo:.3}, {hi:.3}], true values' {ct:.3}, population {cp:.3}");
            }
        }
    }
    let rms_z = (z2.iter().sum::<f64>() / z2.len() as f64).sqrt();
    println!("sample Cpk inside: {sample_hits:?} of 20; population Cpk inside: {population_hits:?} of 20; RMS z of values {rms_z:.3}");
    assert!(sample_hits.iter().all(|&h| h >= 19), "{sample_hits:?}");
    assert!(population_hits.iter().all(|&h| h >= 17), "{population_hits:?}");
    // The uncertainties the decisions use are honest: fitted − true over u is N(0, 1).
    assert!((0.8..1.25).contains(&rms_z), "RMS z {rms_z}");
}

/// Guarded decisions (k = 2) on units near the limit: no unit whose true value is outside by
/// more than 3u is accepted, none inside by more than 3u rejected; `simple` on the same
/// units leaves no unit indeterminate.
#[test]
fn guarded_acceptance_never_accepts_a_bad_unit_or_rejects_a_good_one() {
    let text = |decision: &str| {
        format!(
            r#"{{"format":"crosscal-rules/1","decision":"{decision}","rules":[
            {{"kind":"datasheet","quantity":"gyro.misalignment","axis":"xy","max":1.0,"unit":"mrad"}}]}}"#
        )
    };
    let guarded = Rules::parse(Path::new("g.json"), &text("guarded")).unwrap();
    let simple = Rules::parse(Path::new("s.json"), &text("simple")).unwrap();
    let mut rng = ChaCha8Rng::seed_from_u64(99);
    let law = LotLaw { delta_xy: (1.0, 0.25), ..LAW };
    let truths: Vec<Truth> = (0..40).map(|_| draw(&mut rng, &law)).collect();
    let items: Vec<(usize, Truth)> = truths.iter().copied().enumerate().collect();
    let out = par_map(&items, |(i, t)| {
        // u ≈ 0.06 mrad: some units are within 2u of the limit.
        let p = fit(&config(&format!("G-{i}"), 500 + *i as u64, t, 0.002));
        let d = sheet(&p);
        let ev = Evidence { datasheet: Some(&d), ..Default::default() };
        (evaluate(&guarded, &p, &ev).remove(0), evaluate(&simple, &p, &ev).remove(0))
    });
    let (mut counts, mut wrong) = ([0usize; 3], Vec::new());
    for ((g, s), t) in out.iter().zip(&truths) {
        let (u, truth) = (g.uncertainty.unwrap(), t.delta_mrad[0].abs());
        let d = g.decided();
        counts[d as usize] += 1;
        if (d == Decision::Pass && truth > 1.0 + 3.0 * u) || (d == Decision::Fail && truth < 1.0 - 3.0 * u) {
            wrong.push(format!("{d:?}: true {truth:.4} value {:.4} u {u:.4}", g.value.unwrap()));
        }
        assert_ne!(s.decided(), Decision::Indeterminate, "simple decides every unit");
    }
    println!("guarded: pass {}, indeterminate {}, fail {}", counts[0], counts[1], counts[2]);
    assert!(wrong.is_empty(), "{wrong:#?}");
    assert!(counts[1] > 0 && counts[0] > 0 && counts[2] > 0, "the lot straddles the limit: {counts:?}");
    let indet = out.iter().find(|(g, _)| g.decided() == Decision::Indeterminate).unwrap();
    let mut with = vec![indet.0.clone()];
    crosscal::app::accept::add_resolutions(&mut with, &guarded);
    let how = with[0].resolve.as_deref().unwrap();
    assert!(how.contains("as long"), "{how}");
}

/// Bias repeatability from 6 calibrations of a unit whose turn-on bias varies with a known
/// σ (2 °/h gyro): the 90 % interval holds σ in about 90 % of 20 trials (≥ 15: binomial
/// lower tail 1.1 %), and the value is the spread of the true turn-on biases.
#[test]
fn bias_repeatability_interval_holds_the_turn_on_sigma() {
    let sigma = 2.0;
    let mut hits = 0;
    for trial in 0..20u64 {
        let mut rng = ChaCha8Rng::seed_from_u64(300 + trial);
        let base = draw(&mut rng, &LAW);
        let turn_on: Vec<f64> = (0..6).map(|_| Normal::new(5.0, sigma).unwrap().sample(&mut rng)).collect();
        let items: Vec<(usize, f64)> = turn_on.iter().copied().enumerate().collect();
        let profiles = par_map(&items, |(k, b)| {
            let t = Truth { bias_deg_h: [*b, base.bias_deg_h[1], base.bias_deg_h[2]], ..base };
            fit(&config("REP-1", trial * 10 + *k as u64, &t, 0.002))
        });
        let history: Vec<(PathBuf, Profile)> =
            profiles.iter().enumerate().map(|(k, p)| (PathBuf::from(format!("cal{k}.json")), p.clone())).collect();
        let d = build("cal5.json", &profiles[5], &history, &Default::default());
        let q = d.value("gyro.bias_repeatability", "x").unwrap();
        assert_eq!(q.count, Some(6));
        let [lo, hi] = q.interval90.unwrap();
        hits += usize::from(lo <= sigma && sigma <= hi);
        let mean = turn_on.iter().sum::<f64>() / 6.0;
        let sd = (turn_on.iter().map(|b| (b - mean).powi(2)).sum::<f64>() / 5.0).sqrt();
        // The fitted biases carry their own estimation error (standard error se): the
        // spread of the fitted biases differs from the true ones' by less than ~3 se.
        let se = profiles.iter().map(|p| p.gyro.get("gyro.b_x").unwrap().std_error.unwrap()).fold(0.0, f64::max);
        let tol = 3.0 * se * DEG_H_PER_RAD_S;
        assert!((q.value.unwrap() - sd).abs() < tol, "{} vs the true biases' {sd} (±{tol})", q.value.unwrap());
    }
    println!("σ inside the 90 % interval in {hits} of 20 trials");
    assert!(hits >= 15, "{hits}");
}

/// Control chart on simulated lot series: a lot whose mean shifted by one within-lot σ is
/// flagged (and only it); unshifted series raise no flag.
#[test]
fn a_shifted_lot_is_flagged_and_an_unshifted_one_not() {
    let mut false_alarms = 0;
    let mut caught = 0;
    for seed in 0..20u64 {
        let mut rng = ChaCha8Rng::seed_from_u64(40 + seed);
        let series = |shift: f64, rng: &mut ChaCha8Rng| -> Vec<LotPoint> {
            (0..6)
                .map(|j| {
                    let m = if j == 5 { 0.3 + shift } else { 0.3 };
                    let v: Vec<f64> = (0..30).map(|_| Normal::new(m, 0.2).unwrap().sample(rng)).collect();
                    let (mean, std, _) = cpk(&v, None, None).unwrap();
                    LotPoint { lot: format!("lot{j}"), created_utc: String::new(), n: 30, mean, std }
                })
                .collect()
        };
        let steady = control_chart(&series(0.0, &mut rng));
        false_alarms += steady.iter().filter(|p| p.shifted).count();
        let moved = control_chart(&series(0.2, &mut rng));
        let flagged: Vec<&str> = moved.iter().filter(|p| p.shifted).map(|p| p.point.lot.as_str()).collect();
        caught += usize::from(flagged.contains(&"lot5"));
        assert!(moved[0].mean_limits.is_none(), "the first lot has no earlier limits");
    }
    println!("shift caught in {caught} of 20 series; {false_alarms} false alarms in 100 steady lots");
    assert!(caught >= 18, "{caught}");
    assert!(false_alarms <= 2, "{false_alarms}");
}

/// The command: text, JSON with the interface's fields, the HTML page; quantities the
/// profile cannot give are listed with what would give them; repeatability over stored
/// calibrations.
#[test]
fn datasheet_command_prints_every_quantity_with_its_unit_and_uncertainty() {
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    for (k, b) in ["0.001,0,0", "0.0015,0,0", "0.0005,0,0"].iter().enumerate() {
        let out = format!("s{k}");
        run_ok(
            d,
            &[
                "simulate",
                "-o",
                &out,
                "--duration",
                "6",
                "--gyro-noise",
                "0.002",
                "--accel-noise",
                "2e-5",
                "--seed",
                &k.to_string(),
                "--gyro-bias",
                b,
            ],
        );
        run_ok(d, &["fit", &format!("{out}/session.json"), "--out", "store"]);
    }
    let text = run_ok(d, &["datasheet", "I1426-0042", "--store", "store", "--report", "ds.html"]);
    for needle in [
        "gyro.bias ",
        "deg/h",
        "gyro.misalignment",
        "mrad",
        "gyro.bias_repeatability",
        "3 calibrations",
        "not measured:",
        "gyro.arw",
        "crosscal noise",
    ] {
        assert!(text.contains(needle), "{needle}:\n{text}");
    }
    let json = run_ok(d, &["datasheet", "I1426-0042", "--store", "store", "--json"]);
    let v: serde_json::Value = serde_json::from_str(&json).unwrap();
    assert_eq!(v["unit"], "I1426-0042");
    let qs = v["quantities"].as_array().unwrap();
    let mis: Vec<_> = qs.iter().filter(|q| q["name"] == "gyro.misalignment").collect();
    assert_eq!(mis.len(), 3);
    for q in &mis {
        assert_eq!(q["unit"], "mrad");
        assert!(q["value"].is_f64() && q["uncertainty"].as_f64().unwrap() > 0.0, "{q}");
        assert!(q["axis"].is_string() && q["definition"].is_string() && q["sources"].is_array());
    }
    // Repeatability: the 1σ of the three stored biases (0.001, 0.0015, 0.0005 deg/s).
    let rep = qs.iter().find(|q| q["name"] == "gyro.bias_repeatability" && q["axis"] == "x").unwrap();
    assert!((rep["value"].as_f64().unwrap() - 1.8).abs() < 0.3, "{rep}");
    let arw = qs.iter().find(|q| q["name"] == "gyro.arw").unwrap();
    assert!(arw["value"].is_null() && arw["not_measured"].as_str().unwrap().contains("crosscal noise"), "{arw}");
    let html = std::fs::read_to_string(d.join("ds.html")).unwrap();
    assert!(html.contains("gyro.misalignment") && html.contains("not measured"));
    // A rule on an unknown quantity or in the wrong unit is refused (exit 20).
    std::fs::write(d.join("bad.json"), r#"{"format":"crosscal-rules/1","rules":[{"kind":"datasheet","quantity":"gyro.misalignment","max":1,"unit":"deg"}]}"#).unwrap();
    let (code, _, err) = run_in(d, &["accept", "store/I1426-0042", "--rules", "bad.json"]);
    assert_eq!(code, 20, "{err}");
    assert!(err.contains("mrad"), "{err}");
}

/// Every quantity has its definition in the reference page (a heading per quantity) and in
/// the JSON.
#[test]
fn every_quantity_is_defined_in_the_reference() {
    let page =
        std::fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join("docs/reference-datasheet.md")).unwrap();
    for q in crosscal::datasheet::QUANTITIES {
        assert!(
            page.contains(&format!("### {}\n\nUnit: `{}`.", q.name, q.unit)),
            "{} missing from the reference",
            q.name
        );
    }
    let rules = std::fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join("docs/reference-rules.md")).unwrap();
    assert!(rules.contains("\"kind\": \"datasheet\"") && rules.contains("indeterminate"));
}

/// The real batch: a lot of 30 units with datasheet rules reports every unit's value,
/// uncertainty, limit and decision and the lot's capability; a second lot whose
/// misalignment shifted is flagged on the control chart; the HTML histograms have limits
/// drawn and tick labels that do not overlap (checked in headless Chromium where present).
#[test]
fn batch_reports_capability_and_flags_a_shifted_lot() {
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    std::fs::write(d.join("rules.json"), LOT_RULES).unwrap();
    let mut rng = ChaCha8Rng::seed_from_u64(2024);
    let mut truths = Vec::new();
    for (lot, n, shift) in [("lotA", 30, 0.0), ("lotB", 12, 0.5)] {
        for i in 0..n {
            let mut t = draw(&mut rng, &LAW);
            t.delta_mrad[0] += shift;
            write_session(
                &config(&format!("{lot}-{i:02}"), i as u64, &t, 0.002).generate(),
                &d.join(lot).join(format!("u{i:02}")),
            )
            .unwrap();
            if lot == "lotA" {
                truths.push(t);
            }
        }
    }
    let (_, out_a, err_a) = run_in(d, &["batch", "lotA", "--rules", "rules.json", "--out", "store", "--jobs", "2"]);
    println!("{out_a}");
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(d.join("lotA/batch-report.json")).unwrap()).unwrap();
    let units = report["units"].as_array().unwrap();
    assert_eq!(units.len(), 30, "{err_a}");
    for u in units {
        for r in u["rules"].as_array().unwrap() {
            assert!(r["value"].is_f64() && r["uncertainty"].is_f64() && r["limit"].is_f64(), "{r}");
            assert!(["pass", "fail", "indeterminate"].contains(&r["decision"].as_str().unwrap()), "{r}");
        }
    }
    let cap = report["capability"].as_array().unwrap();
    assert_eq!(cap.len(), 3);
    let mis = cap.iter().find(|c| c["rule"] == "misalignment xy").unwrap();
    let truth: Vec<f64> = truths.iter().map(|t| t.delta_mrad[0]).collect();
    let ct = cpk(&truth, Some(-1.0), Some(1.0)).unwrap().2.unwrap()[0];
    let (lo, hi) = (mis["cpk_low"].as_f64().unwrap(), mis["cpk_high"].as_f64().unwrap());
    assert!(lo <= ct && ct <= hi, "true values' Cpk {ct} outside [{lo}, {hi}]");
    let counted: u64 = ["pass", "fail", "indeterminate"].iter().map(|k| mis[k].as_u64().unwrap()).sum();
    assert_eq!(counted, 30);
    assert!(out_a.contains("capability misalignment xy"), "{out_a}");
    assert!(!out_a.contains("process shift"), "the first lot has nothing to shift from: {out_a}");
    let (_, out_b, _) = run_in(d, &["batch", "lotB", "--rules", "rules.json", "--out", "store", "--jobs", "2"]);
    println!("{out_b}");
    assert!(out_b.contains("process shift: gyro.misalignment xy at lot lotB"), "{out_b}");
    assert!(!out_b.contains("process shift: gyro.bias"), "{out_b}");
    let html = std::fs::read_to_string(d.join("lotB/batch-report.html")).unwrap();
    assert!(html.contains("upper limit 1") && html.contains("lower limit -1"), "limits drawn");
    assert!(html.contains("Cpk") && html.contains("(mrad)") && html.contains("across lots: shift at lotB"));
    crate::reports::no_overlapping_text(&d.join("lotB/batch-report.html"), "batch capability");
}
