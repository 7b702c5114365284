//! Every input of the coverage-guided fuzzers' corpora (`fuzz/corpus/<reader>`, kept with
//! the fuzz targets in `fuzz/`) replayed through the readers: whatever libFuzzer ever found
//! interesting stays a regression test. Inputs that crashed a reader would be added here
//! under `fuzz/corpus/<reader>` after the fix (none has so far).

use std::path::{Path, PathBuf};

fn corpus(reader: &str) -> Vec<PathBuf> {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("fuzz/corpus").join(reader);
    let mut files: Vec<PathBuf> =
        std::fs::read_dir(&dir).map(|rd| rd.filter_map(|e| e.ok().map(|e| e.path())).collect()).unwrap_or_default();
    files.sort();
    assert!(files.len() >= 10, "{}: the corpus is missing", dir.display());
    files
}

#[test]
fn csv_corpus() {
    for f in corpus("csv") {
        let data = std::fs::read(&f).unwrap();
        for reference in [false, true] {
            let opts = crosscal::session::ReadOptions { reference, strict: false, angle_column: None };
            let units = crosscal::units::Units::default();
            if let Ok(r) = crosscal::session::parse_recording(&f, &data, &units, 9.80665, opts) {
                assert!(r.t_s.windows(2).all(|w| w[1] > w[0]), "{}", f.display());
                assert!(r.gyro.iter().chain(&r.accel).all(|v| v.iter().all(|x| x.is_finite())));
            }
        }
    }
}

#[test]
fn manifest_corpus() {
    for f in corpus("manifest") {
        let text = String::from_utf8_lossy(&std::fs::read(&f).unwrap()).into_owned();
        if let Ok(m) = crosscal::session::parse_manifest(&f, &text) {
            let lim = crosscal::session::LIMITS;
            assert!((lim.g_m_s2.0..=lim.g_m_s2.1).contains(&m.g_m_s2), "{}", f.display());
        }
    }
}

#[test]
fn profile_corpus() {
    for f in corpus("profile") {
        let text = String::from_utf8_lossy(&std::fs::read(&f).unwrap()).into_owned();
        if let Ok(p) = crosscal::profile::Profile::from_json(&f, &text) {
            assert!(crosscal::correct::Calibration::from_profile(&p).is_ok(), "{}", f.display());
        }
    }
}

#[test]
fn rules_corpus() {
    for f in corpus("rules") {
        let text = String::from_utf8_lossy(&std::fs::read(&f).unwrap()).into_owned();
        let _ = crosscal::check::rules::Rules::parse(&f, &text);
    }
}
