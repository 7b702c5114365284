//! Shared helpers.

use crosscal::correct::Calibration;
use crosscal::estimate::{EstimateError, Fit, FitOptions, FitRequest};
use crosscal::model::Model;
use crosscal::profile::Profile;
use crosscal::session::Session;

/// Fits exactly `model` to a session in memory through the one fit entry point.
pub fn fit_session(session: &Session, model: &Model, opts: &FitOptions) -> Result<Fit, EstimateError> {
    Ok(crosscal::estimate::fit(&FitRequest::session(model, session).options(*opts))?.fit)
}

/// Fits the default model and builds the calibration (through a profile, like the CLI).
pub fn fit_and_calibrate(session: &Session, model: &Model) -> (Fit, Profile, Calibration) {
    let fit = fit_session(session, model, &FitOptions::default()).expect("fit");
    let profile = Profile::from_fit(session, model, fit.clone(), vec![]);
    let cal = Calibration::from_profile(&profile).expect("calibration");
    (fit, profile, cal)
}

/// Path of the built binary.
pub fn bin() -> std::path::PathBuf {
    std::path::PathBuf::from(env!("CARGO_BIN_EXE_crosscal"))
}

/// Runs the binary in a folder; returns (exit code, stdout, stderr).
pub fn run_in(dir: &std::path::Path, args: &[&str]) -> (i32, String, String) {
    let out = std::process::Command::new(bin()).args(args).current_dir(dir).output().expect("run crosscal");
    (
        out.status.code().unwrap_or(-1),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

/// Runs crosscal in `dir`, asserts it succeeded (naming the arguments and its output
/// otherwise), and returns its stdout.
pub fn run_ok(dir: &std::path::Path, args: &[&str]) -> String {
    let (code, out, err) = run_in(dir, args);
    assert_eq!(code, 0, "{args:?}: {out}{err}");
    out
}

/// A multi-position MEMS unit without gyro g-sensitivity, and the same unit with a large
/// one: the clean/hidden pair of the protocol diagnose and batch tests.
pub fn clean_and_g_sensitive(
) -> (crosscal::simulate::protocol::ProtocolTruth, crosscal::simulate::protocol::ProtocolTruth) {
    let mut clean = crosscal::simulate::protocol::ProtocolTruth::mems(true);
    clean.g_gyro = nalgebra::Matrix3::zeros();
    let mut hidden = clean.clone();
    hidden.g_gyro = nalgebra::Matrix3::new(0.5, -0.2, 0.1, 0.3, 0.4, -0.2, -0.1, 0.2, 0.6);
    (clean, hidden)
}

/// Maps `f` over `items` on two threads, keeping the order.
pub fn par_map<I: Sync, T: Send>(items: &[I], f: impl Fn(&I) -> T + Sync) -> Vec<T> {
    let mut out = Vec::with_capacity(items.len());
    std::thread::scope(|s| {
        let f = &f;
        let handles: Vec<_> = items
            .chunks(items.len().div_ceil(2).max(1))
            .map(|chunk| s.spawn(move || chunk.iter().map(f).collect::<Vec<T>>()))
            .collect();
        for h in handles {
            out.extend(h.join().expect("worker"));
        }
    });
    out
}

/// Runs the binary in a folder with a time limit (a hang is a failure, not a stuck test);
/// returns (exit code, stdout, stderr).
pub fn run_timed(dir: &std::path::Path, args: &[&str], secs: u64) -> (i32, String, String) {
    use std::io::Read;
    let mut child = std::process::Command::new(bin())
        .args(args)
        .current_dir(dir)
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .expect("run crosscal");
    let (mut so, mut se) = (child.stdout.take().expect("stdout"), child.stderr.take().expect("stderr"));
    let out = std::thread::spawn(move || {
        let mut s = String::new();
        let _ = so.read_to_string(&mut s);
        s
    });
    let err = std::thread::spawn(move || {
        let mut s = String::new();
        let _ = se.read_to_string(&mut s);
        s
    });
    let start = std::time::Instant::now();
    let status = loop {
        if let Some(s) = child.try_wait().expect("wait") {
            break s;
        }
        if start.elapsed().as_secs() >= secs {
            let _ = child.kill();
            panic!("crosscal {args:?} did not finish in {secs} s");
        }
        std::thread::sleep(std::time::Duration::from_millis(20));
    };
    (status.code().unwrap_or(-1), out.join().unwrap_or_default(), err.join().unwrap_or_default())
}

/// Runs a shell command line in a folder (for pipes and limits); returns (exit code,
/// stdout, stderr). `$CROSSCAL` names the binary.
pub fn sh_in(dir: &std::path::Path, script: &str) -> (i32, String, String) {
    let out = std::process::Command::new("sh")
        .arg("-c")
        .arg(script)
        .env("CROSSCAL", bin())
        .current_dir(dir)
        .output()
        .expect("run sh");
    (
        out.status.code().unwrap_or(-1),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

/// A one-run, 40-sample session in `dir/s` (conic, 10 °/s, noisy gyro) and, with `fit`, its
/// profile in `dir/store`: the small fixture the refusal and exit-code tests edit.
pub fn small_session(dir: &std::path::Path, fit: bool) {
    let args = [
        "simulate",
        "-o",
        "s",
        "--duration",
        "2",
        "--rate-hz",
        "20",
        "--mounts",
        "1",
        "--rates",
        "10",
        "--cone-angles",
        "10",
        "--gyro-noise",
        "0.002",
    ];
    let (code, out, err) = run_timed(dir, &args, 60);
    assert_eq!(code, 0, "{out}{err}");
    if fit {
        let (code, out, err) = run_timed(dir, &["fit", "s/session.json", "--out", "store"], 60);
        assert_eq!(code, 0, "{out}{err}");
    }
}

/// `crosscal simulate -o out` of the paper's unit with the `hidden` catalogue effects at the
/// `truth` values (NAME, SI value) and `extra` arguments (`--temperature …`, noise, seed).
pub fn simulate_hidden(dir: &std::path::Path, out: &str, hidden: &[&str], truth: &[(String, f64)], extra: &[&str]) {
    let sets: Vec<String> = truth.iter().map(|(n, v)| format!("{n}={v}")).collect();
    let mut args = vec!["simulate", "-o", out];
    args.extend_from_slice(extra);
    for e in hidden {
        args.extend_from_slice(&["--hidden", e]);
    }
    for s in &sets {
        args.extend_from_slice(&["--set", s]);
    }
    run_ok(dir, &args);
}

/// `crosscal fit SESSION --effect …` into `dir/store`; the unit's latest profile (path, profile).
pub fn fit_into_store(dir: &std::path::Path, session: &str, effects: &[&str]) -> (std::path::PathBuf, Profile) {
    let mut args = vec!["fit", session, "--out", "store"];
    for e in effects {
        args.extend_from_slice(&["--effect", e]);
    }
    run_ok(dir, &args);
    only_profile(&dir.join("store"))
}

/// The latest profile of the one unit in the store `store` (its path and contents).
pub fn only_profile(store: &std::path::Path) -> (std::path::PathBuf, Profile) {
    let unit = std::fs::read_dir(store)
        .unwrap_or_else(|e| panic!("{}: {e}", store.display()))
        .flatten()
        .next()
        .map(|e| e.path())
        .unwrap_or_else(|| panic!("{} holds no unit", store.display()));
    Profile::read_or_latest(&unit).unwrap_or_else(|e| panic!("{e}"))
}

/// Rewrites a text file through `f`.
pub fn edit(path: &std::path::Path, f: impl Fn(String) -> String) {
    let text = std::fs::read_to_string(path).unwrap();
    std::fs::write(path, f(text)).unwrap();
}

/// Simulates in `dir/out` a 12 s-per-run stand session of a noisy unit (0.002 °/s, 2e-5 g)
/// with a hidden gyro g-sensitivity g_xz = `g_xz` (rad/s per m/s²) and the given serial and
/// seed; panics with crosscal's message if the simulation fails.
pub fn simulate_g_sensitive(dir: &std::path::Path, out: &str, serial: &str, seed: u64, g_xz: f64) {
    let (seed, set) = (seed.to_string(), format!("gyro.g_xz={g_xz}"));
    let args = [
        "simulate",
        "-o",
        out,
        "--serial",
        serial,
        "--seed",
        &seed,
        "--gyro-noise",
        "0.002",
        "--accel-noise",
        "2e-5",
        "--duration",
        "12",
        "--hidden",
        "gyro-g-sensitivity",
        "--set",
        &set,
    ];
    let (code, stdout, err) = run_in(dir, &args);
    assert_eq!(code, 0, "{stdout}{err}");
}

/// The thermal unit (#24), biases in SI: the gyro's cubic in temperature, the
/// accelerometer's quadratic.
pub const THERMAL_BIASES: [(&str, f64); 15] = [
    ("gyro.tb_x", 2e-5),
    ("gyro.tb2_x", -3e-7),
    ("gyro.tb3_x", 4e-9),
    ("gyro.tb_y", 1e-5),
    ("gyro.tb2_y", 2e-7),
    ("gyro.tb3_y", -3e-9),
    ("gyro.tb_z", -1e-5),
    ("gyro.tb2_z", 1e-7),
    ("gyro.tb3_z", 2e-9),
    ("accel.tb_x", 1e-4),
    ("accel.tb2_x", -2e-6),
    ("accel.tb_y", -1e-4),
    ("accel.tb2_y", 1e-6),
    ("accel.tb_z", 5e-5),
    ("accel.tb2_z", 3e-6),
];
