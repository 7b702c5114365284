//! The streamed fit (`fit --stream`: recordings read as streams, memory independent of their
//! length) against the in-memory fit: the same numbers to the last bit.

use crosscal::estimate::{fit_runs, tracks};
use crosscal::estimate::{EstimateError, FitData, FitOutcome, FitRequest, ModelChoice, StreamPolicy};
use crosscal::estimate::{Fit, FitOptions};
use crosscal::model::Model;
use crosscal::session::Session;
use crosscal::simulate::{conic_plan, cyclic_mounts, write_session, RunPlan, SimConfig};

/// Relative difference (0 when bit-identical).
fn rel(p: f64, q: f64) -> f64 {
    if p.to_bits() == q.to_bits() {
        0.0
    } else {
        (p - q).abs() / p.abs().max(q.abs())
    }
}

/// The paper's unit with the paper's noise on conic runs at `rates_deg_s` (cone 10°).
fn noisy_cones(rates_deg_s: &[f64], mounts: usize, duration_s: f64) -> SimConfig {
    let mut c = SimConfig::paper();
    c.runs = conic_plan(rates_deg_s, &[10.0], &cyclic_mounts(mounts), duration_s);
    c.gyro_noise_deg_s = 0.002;
    c.accel_noise_g = 2e-5;
    c
}

fn same(a: &Fit, b: &Fit) -> f64 {
    let mut worst: f64 = 0.0;
    for (sa, sb) in [(&a.gyro, &b.gyro), (&a.accel, &b.accel)] {
        assert_eq!(sa.coefficients.len(), sb.coefficients.len());
        for (x, y) in sa.coefficients.iter().zip(&sb.coefficients) {
            assert_eq!((&x.name, x.status), (&y.name, y.status));
            worst = worst.max(rel(x.value, y.value));
            worst = worst.max(rel(x.std_error.unwrap_or(0.0), y.std_error.unwrap_or(0.0)));
        }
        for (x, y) in sa.channels.iter().zip(&sb.channels) {
            for (p, q) in [
                (x.residual_rms, y.residual_rms),
                (x.residual_max, y.residual_max),
                (x.coloured_inflation, y.coloured_inflation),
                (x.condition_number, y.condition_number),
            ] {
                worst = worst.max(rel(p, q));
            }
            assert_eq!(x.n, y.n);
        }
    }
    worst
}

#[test]
fn streamed_fit_equals_the_in_memory_fit() {
    let mut c = SimConfig::paper();
    c.runs = conic_plan(&[10.0, -20.0], &[10.0, 20.0], &cyclic_mounts(2), 12.0);
    let still = crosscal::session::MotionSpec::Static { up_stand: [0.0, 1.0, 0.0], earth_rate_rad_s: [0.0; 3] };
    c.runs.push(RunPlan { name: "static-y".into(), motion: still, mount: cyclic_mounts(1).remove(0), duration_s: 8.0 });
    c.gyro_noise_deg_s = 0.002;
    c.accel_noise_g = 2e-5;
    let tmp = tempfile::tempdir().unwrap();
    let manifest = write_session(&c.generate(), tmp.path()).unwrap();
    // A format-2 run that uses part of another run's file (`rows`).
    let mut m: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&manifest).unwrap()).unwrap();
    m["format"] = "crosscal-session/2".into();
    let mut part = m["runs"][0].clone();
    part["name"] = "part-of-first".into();
    part["rows"] = serde_json::json!([100, 700]);
    m["runs"].as_array_mut().unwrap().push(part);
    std::fs::write(&manifest, serde_json::to_string_pretty(&m).unwrap()).unwrap();
    let mut model = Model::default_model();
    model.add_effect("gyro-g-sensitivity").unwrap();
    let session = Session::load(&manifest).unwrap();
    let tr = tracks(&session, &Default::default());
    let in_memory = crosscal::estimate::fit(&FitRequest::runs(&model, &fit_runs(&session, &tr))).unwrap().fit;
    let streamed = fit_streaming(&manifest, &model, &FitOptions::default()).unwrap();
    let worst = same(&in_memory, &streamed.fit);
    println!("streamed vs in-memory fit: largest relative difference {worst:e}");
    assert!(worst <= 1e-12, "{worst}");
    // The runs as the profile records them: same hashes and sample counts.
    let used = session.runs_used();
    let streamed_runs = &streamed.source.as_ref().unwrap().runs;
    assert_eq!(&used, streamed_runs);
    assert_eq!(streamed_runs.last().map(|r| r.samples), Some(600));
}

#[test]
fn streamed_fit_refuses_what_needs_the_samples_in_memory() {
    let mut c = SimConfig::paper();
    c.runs = conic_plan(&[10.0], &[10.0], &cyclic_mounts(1), 5.0);
    let tmp = tempfile::tempdir().unwrap();
    let manifest = write_session(&c.generate(), tmp.path()).unwrap();
    let robust = FitOptions { robust: true, ..FitOptions::default() };
    let e = fit_streaming(&manifest, &Model::default_model(), &robust).unwrap_err();
    assert!(matches!(e, EstimateError::Request(_)), "{e}");
    let mut m = Model::default_model();
    m.add_effect("time-delay").unwrap();
    assert!(matches!(fit_streaming(&manifest, &m, &FitOptions::default()), Err(EstimateError::Request(_))));
}

/// The streamed fit of a session on disk (an error where it cannot be streamed).
fn fit_streaming(manifest: &std::path::Path, model: &Model, opts: &FitOptions) -> Result<FitOutcome, EstimateError> {
    streamed_with(manifest, model, opts, false)
}

fn streamed_with(
    manifest: &std::path::Path,
    model: &Model,
    opts: &FitOptions,
    strict: bool,
) -> Result<FitOutcome, EstimateError> {
    let mut req = FitRequest::new(FitData::Manifest(manifest), ModelChoice::Exact(model)).options(*opts);
    req.streaming = StreamPolicy::Require;
    req.strict = strict;
    let out = crosscal::estimate::fit(&req)?;
    assert!(out.streamed);
    Ok(out)
}

/// A corrected CSV read back: the header and each row's fields.
fn read_back(text: &str) -> (String, Vec<Vec<f64>>) {
    let mut lines = text.lines();
    let header = lines.next().unwrap_or_default().to_string();
    (header, lines.map(|l| l.split(',').map(|f| f.parse().unwrap()).collect()).collect())
}

#[test]
fn csv_correction_streams_the_same_bits_as_the_in_memory_corrector() {
    use crosscal::correct::{correct_csv_streaming, correct_streaming, Calibration, OutputScale, StreamCsvOptions};
    use crosscal::session::{parse_recording, ReadOptions};
    // 2500 samples a run: two full blocks of the streamed corrector and a partial one.
    let mut c = noisy_cones(&[10.0, -20.0], 2, 25.0);
    let tmp = tempfile::tempdir().unwrap();
    let plain = write_session(&c.generate(), &tmp.path().join("plain")).unwrap();
    c.temperature_c = Some(vec![20.0, 30.0]);
    let warm = write_session(&c.generate(), &tmp.path().join("warm")).unwrap();
    // A fitted linear calibration; and one with a dead zone wide enough to catch the rates'
    // zero crossings (flags), on the recording with a temp column.
    let session = Session::load(&plain).unwrap();
    let f = crate::common::fit_session(&session, &Model::default_model(), &FitOptions::default()).unwrap();
    let fitted = crosscal::app::validate::calibration_of(&Model::default_model(), &f).unwrap();
    let mut dz = Model::default_model();
    dz.fix_nonlinear("gyro-dead-zone", vec![0.002, 0.003, 0.001]).unwrap();
    let mut dead = Calibration::from_model(&dz, Default::default()).unwrap();
    // Outputs within 3 σ of zero are inside the band: flagged, not inverted.
    dead.noise = [[1e-3; 3], [1e-3; 3]];
    for (manifest, cal, flags_expected) in [(&plain, &fitted, false), (&warm, &dead, true)] {
        let session = Session::load(manifest).unwrap();
        let units = session.manifest.units;
        let g = session.manifest.g_m_s2;
        for run in &session.runs {
            let path = manifest.with_file_name(&run.spec.file);
            let bytes = std::fs::read(&path).unwrap();
            let rec = parse_recording(&path, &bytes, &units, g, ReadOptions::default()).unwrap();
            let expected = correct_streaming(cal, &rec.t_s, &rec.gyro, &rec.accel, rec.temp_c.as_deref()).unwrap();
            let mut out = Vec::new();
            let opts = StreamCsvOptions { scale: OutputScale { time: 1.0, gyro: 1.0, accel: 1.0 }, strict: false };
            let s = correct_csv_streaming(&path, bytes.as_slice(), &mut out, cal, &units, g, opts).unwrap();
            let (header, rows) = read_back(std::str::from_utf8(&out).unwrap());
            assert_eq!(s.samples, rec.len());
            assert_eq!(rows.len(), rec.len());
            assert_eq!(s.warmup, expected.warmup);
            assert_eq!(s.has_flags, flags_expected);
            assert_eq!(header.ends_with(",temp,flags"), flags_expected, "{header}");
            let mut flagged = 0;
            for (k, r) in rows.iter().enumerate() {
                let mut want = vec![rec.t_s[k]];
                want.extend(expected.w_rad_s[k]);
                want.extend(expected.a_m_s2[k]);
                if let Some(t) = &rec.temp_c {
                    want.push(t[k]);
                }
                if flags_expected {
                    let f = expected.flags.get(k).copied().unwrap_or(0);
                    flagged += usize::from(f != 0);
                    want.push(f64::from(f));
                }
                assert_eq!(r.len(), want.len());
                for (x, y) in r.iter().zip(&want) {
                    assert_eq!(x.to_bits(), y.to_bits(), "{} sample {k}: {x} vs {y}", run.spec.name);
                }
            }
            assert_eq!(s.flagged, flagged);
            assert_eq!(flagged > 0, flags_expected, "{} flagged", flagged);
            assert!(s.warnings.is_empty(), "{:?}", s.warnings);
        }
    }
}

#[test]
fn csv_correction_reports_gaps_and_refuses_them_in_strict_mode() {
    use crosscal::correct::{correct_csv_streaming, Calibration, OutputScale, StreamCsvError, StreamCsvOptions};
    use crosscal::session::{Problem, SessionError};
    use crosscal::units::Units;
    let cal = Calibration::from_model(&Model::default_model(), Default::default()).unwrap();
    let mut text = String::from("t,gx,gy,gz,ax,ay,az\n");
    for k in 0..200 {
        let t = if k < 120 { k as f64 * 0.01 } else { k as f64 * 0.01 + 1.0 };
        text.push_str(&format!("{t},0.1,0.2,0.3,0,0,1\n"));
    }
    let path = std::path::Path::new("gappy.csv");
    let scale = OutputScale { time: 1.0, gyro: 1.0, accel: 1.0 };
    let run = |text: &str, strict: bool| {
        let opts = StreamCsvOptions { scale, strict };
        correct_csv_streaming(path, text.as_bytes(), &mut Vec::new(), &cal, &Units::default(), 9.80665, opts)
    };
    let s = run(&text, false).unwrap();
    assert_eq!(s.samples, 200);
    assert!(s.warnings.iter().any(|w| w.contains("gap in t") && w.contains("before sample 121")), "{:?}", s.warnings);
    match run(&text, true).unwrap_err() {
        StreamCsvError::Read(SessionError::Csv { problem: Problem::Gap, line, .. }) => assert_eq!(line, 122),
        other => panic!("{other}"),
    }
    let e = run("t,gx,gy,gz,ax,ay,az\n", false).unwrap_err();
    assert!(e.to_string().contains("gappy.csv:1:") && e.to_string().contains("no samples"), "{e}");
}

#[test]
fn streamed_fit_warns_as_the_in_memory_reader_and_refuses_gaps_when_strict() {
    let c = noisy_cones(&[10.0, -20.0], 1, 12.0);
    let tmp = tempfile::tempdir().unwrap();
    let manifest = write_session(&c.generate(), tmp.path()).unwrap();
    // In the first run: a spike in gy (line 402), az clipped at its maximum, stamps shifted
    // by 1 s from sample 900 on (a gap before sample 900, line 901).
    let session = Session::load(&manifest).unwrap();
    let csv = manifest.with_file_name(&session.runs[0].spec.file);
    let az_max = session.runs[0].rec.accel.iter().map(|a| a[2]).fold(f64::MIN, f64::max) / 9.80665;
    let text = std::fs::read_to_string(&csv).unwrap();
    let mut lines: Vec<String> = text.lines().map(str::to_string).collect();
    for (i, l) in lines.iter_mut().enumerate().skip(1) {
        let mut f: Vec<f64> = l.split(',').map(|x| x.parse().unwrap()).collect();
        if i == 402 {
            f[2] += 50.0;
        }
        if (600..620).contains(&i) {
            f[6] = az_max;
        }
        if i >= 901 {
            f[0] += 1.0;
        }
        *l = f.iter().map(|x| x.to_string()).collect::<Vec<_>>().join(",");
    }
    std::fs::write(&csv, lines.join("\n") + "\n").unwrap();
    let session = Session::load(&manifest).unwrap();
    let whole = session.warnings();
    // The gap, the spike, the flat top and its two edges (as steps, spikes).
    assert_eq!(whole.len(), 4, "{whole:?}");
    let streamed = fit_streaming(&manifest, &Model::default_model(), &FitOptions::default()).unwrap();
    assert_eq!(streamed.warnings, whole);
    let strict = streamed_with(&manifest, &Model::default_model(), &FitOptions::default(), true).unwrap_err();
    let strict = std::error::Error::source(&strict).expect("the read error").to_string();
    let in_memory = Session::load_with(&manifest, true).unwrap_err();
    assert_eq!(strict, in_memory.to_string());
    assert!(strict.to_string().contains("cone+10.csv:902:1 (t): gap in t of 1.0"), "{strict}");
}

/// Recordings past the heap budget live in a mapped spill file (`session::column`): with
/// the budget at 0 every column is spilled (with a small one, the runs read first move to the
/// spill once the session is past it), and `diagnose` (its fits, refits and stand
/// systems) and `fit` say the same, to the last digit, as with the recordings on the heap;
/// so does a run where no spill file can be made.
#[test]
fn spilled_recordings_give_the_numbers_of_the_heap() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let sim = [
        "simulate",
        "-o",
        "s",
        "--duration",
        "40",
        "--gyro-noise",
        "0.002",
        "--accel-noise",
        "2e-5",
        "--hidden",
        "gyro-dead-zone",
        "--set",
        "gyro.dz_x=9e-4",
    ];
    crate::common::run_ok(d, &sim);
    let run = |heap_mb: Option<&str>, args: &[&str]| {
        let mut c = std::process::Command::new(crate::common::bin());
        c.args(args).current_dir(d);
        if let Some(mb) = heap_mb {
            c.env("CROSSCAL_HEAP_MB", mb);
        }
        if heap_mb == Some("no-tmp") {
            // No spill file can be made: the columns stay on the heap, past the budget.
            c.env("CROSSCAL_HEAP_MB", "0").env("TMPDIR", d.join("no such folder"));
        }
        let out = c.output().unwrap();
        assert!(out.status.success(), "{args:?}: {}", String::from_utf8_lossy(&out.stderr));
        String::from_utf8_lossy(&out.stdout).into_owned()
    };
    let heap = run(None, &["diagnose", "s"]);
    assert!(heap.contains("gyro-dead-zone"), "{heap}");
    assert_eq!(run(Some("0"), &["diagnose", "s"]), heap);
    assert_eq!(run(Some("no-tmp"), &["diagnose", "s"]), heap);
    // A budget some columns fit in (each reader's three builders take 1 MiB steps): the
    // session passes it, and the columns on the heap move to the spill once all are read.
    assert_eq!(run(Some("2.5"), &["diagnose", "s"]), heap);
    let fit = |mb| run(mb, &["fit", "s", "--dry-run"]);
    assert_eq!(fit(Some("0")), fit(None));
}
