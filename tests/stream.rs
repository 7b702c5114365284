//! The streamed fit (`fit --stream`: recordings read as streams, memory independent of their
//! length) against the in-memory fit: the same numbers to the last bit.

use crosscal::estimate::stream::{fit_streaming, StreamError};
use crosscal::estimate::{fit, Fit, FitOptions};
use crosscal::model::Model;
use crosscal::pipeline::{fit_runs, tracks};
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
    let in_memory = fit(&model, &fit_runs(&session, &tr), &FitOptions::default()).unwrap();
    let streamed = fit_streaming(&manifest, &model, &FitOptions::default()).unwrap();
    let worst = same(&in_memory, &streamed.fit);
    println!("streamed vs in-memory fit: largest relative difference {worst:e}");
    assert!(worst <= 1e-12, "{worst}");
    // The runs as the profile records them: same hashes and sample counts.
    let used = crosscal::profile::runs_used(&session);
    assert_eq!(used, streamed.runs);
    assert_eq!(streamed.runs.last().map(|r| r.samples), Some(600));
}

#[test]
fn streamed_fit_refuses_what_needs_the_samples_in_memory() {
    let mut c = SimConfig::paper();
    c.runs = conic_plan(&[10.0], &[10.0], &cyclic_mounts(1), 5.0);
    let tmp = tempfile::tempdir().unwrap();
    let manifest = write_session(&c.generate(), tmp.path()).unwrap();
    let robust = FitOptions { robust: true, ..FitOptions::default() };
    let e = fit_streaming(&manifest, &Model::default_model(), &robust).unwrap_err();
    assert!(matches!(e, StreamError::NotStreamable(_)), "{e}");
    let mut m = Model::default_model();
    m.add_effect("time-delay").unwrap();
    assert!(matches!(fit_streaming(&manifest, &m, &FitOptions::default()), Err(StreamError::NotStreamable(_))));
}
