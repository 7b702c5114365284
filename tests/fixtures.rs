//! The committed fixtures are what `crosscal simulate` makes, and they fit to truth.

use crate::common::fit_session;
use crate::common::run_in;
use crosscal::estimate::FitOptions;
use crosscal::model::Model;
use crosscal::session::Session;
use crosscal::simulate::UnitTruth;
use std::path::Path;

const FIXTURE: &str = "fixtures/paper-short";
const ARGS: [&str; 12] = [
    "--duration",
    "4",
    "--rate-hz",
    "25",
    "--gyro-noise",
    "0.002",
    "--accel-noise",
    "2e-5",
    "--seed",
    "7",
    "--preset",
    "paper",
];

#[test]
fn fixture_is_reproduced_by_the_simulator() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let d = tempfile::tempdir().unwrap();
    let mut args = vec!["simulate", "-o", "gen"];
    args.extend_from_slice(&ARGS);
    let (code, out, err) = run_in(d.path(), &args);
    assert_eq!(code, 0, "{out}{err}");
    for entry in std::fs::read_dir(root.join(FIXTURE)).unwrap() {
        let p = entry.unwrap().path();
        let name = p.file_name().unwrap();
        let generated = std::fs::read(d.path().join("gen").join(name)).unwrap();
        assert!(std::fs::read(&p).unwrap() == generated, "{} differs from the simulator's output", p.display());
    }
}

#[test]
fn fixture_fits_within_four_standard_errors() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let s = Session::load(&root.join(FIXTURE).join("session.json")).unwrap();
    assert_eq!(s.runs.len(), 18);
    let fit = fit_session(&s, &Model::default_model(), &FitOptions::default()).unwrap();
    let truth = UnitTruth::paper();
    for c in fit.gyro.coefficients.iter().chain(&fit.accel.coefficients) {
        let t = truth.value(&c.name).unwrap();
        let se = c.std_error.unwrap();
        assert!((c.value - t).abs() < 4.0 * se, "{} = {} ± {se} (true {t})", c.name, c.value);
    }
}
