//! Every kind of bad input: a clear message naming file, line and column where there is
//! one, the word for the problem, and the kind's own exit code. Nothing is written.

use crate::common::{run_in, small_session};
use std::path::Path;

fn csv_path(dir: &Path) -> std::path::PathBuf {
    dir.join("s/cone+10.csv")
}

/// Replaces field `col` (0-based) of data row `row` (0-based; line row + 2).
fn set_field(dir: &Path, row: usize, col: usize, value: &str) {
    let text = std::fs::read_to_string(csv_path(dir)).unwrap();
    let mut lines: Vec<String> = text.lines().map(str::to_string).collect();
    let mut f: Vec<String> = lines[row + 1].split(',').map(str::to_string).collect();
    f[col] = value.to_string();
    lines[row + 1] = f.join(",");
    std::fs::write(csv_path(dir), lines.join("\n") + "\n").unwrap();
}

fn edit_csv(dir: &Path, f: impl Fn(String) -> String) {
    let text = std::fs::read_to_string(csv_path(dir)).unwrap();
    std::fs::write(csv_path(dir), f(text)).unwrap();
}

fn edit_manifest(dir: &Path, f: impl Fn(String) -> String) {
    let p = dir.join("s/session.json");
    let text = std::fs::read_to_string(&p).unwrap();
    std::fs::write(&p, f(text)).unwrap();
}

/// Runs `fit` and checks exit code and message words; nothing may be written.
fn expect_fit_error(dir: &Path, extra: &[&str], code: i32, words: &[&str]) {
    let mut args = vec!["fit", "s/session.json"];
    args.extend_from_slice(extra);
    let (c, out, err) = run_in(dir, &args);
    assert_eq!(c, code, "stdout: {out}\nstderr: {err}");
    for w in words {
        assert!(err.contains(w), "missing '{w}' in: {err}");
    }
    assert!(!dir.join("calib-profiles").exists(), "a failed fit wrote a profile");
}

macro_rules! bad_csv_case {
    ($name:ident, $setup:expr, $code:expr, $words:expr) => {
        #[test]
        fn $name() {
            let d = tempfile::tempdir().unwrap();
            small_session(d.path(), false);
            let setup: &dyn Fn(&Path) = &$setup;
            setup(d.path());
            expect_fit_error(d.path(), &[], $code, &$words);
        }
    };
}

bad_csv_case!(empty_file, |d| edit_csv(d, |_| String::new()), 4, ["cone+10.csv:1", "empty"]);
bad_csv_case!(
    header_only,
    |d| edit_csv(d, |t| t.lines().next().unwrap_or_default().to_string() + "\n"),
    4,
    ["cone+10.csv:1:", "no samples"]
);
bad_csv_case!(
    header_missing,
    |d| edit_csv(d, |t| t.lines().skip(1).collect::<Vec<_>>().join("\n")),
    5,
    ["cone+10.csv:1", "header line is missing"]
);
bad_csv_case!(
    column_absent,
    |d| edit_csv(d, |t| t.replacen("t,gx,gy,gz,ax,ay,az", "t,gx,gy,gz,ax,ay,ac", 1)),
    5,
    ["cone+10.csv:1", "'az' is absent"]
);
bad_csv_case!(
    non_numeric,
    |d| set_field(d, 6, 2, "1.2.3"),
    6,
    ["cone+10.csv:8:3 (gy)", "expected a number", "'1.2.3'"]
);
bad_csv_case!(nan_value, |d| set_field(d, 9, 5, "NaN"), 6, ["cone+10.csv:11:6 (ay)", "finite"]);
bad_csv_case!(infinite_value, |d| set_field(d, 3, 6, "inf"), 6, ["cone+10.csv:5:7 (az)", "finite"]);
bad_csv_case!(
    truncated_last_row,
    |d| edit_csv(d, |t| {
        let mut s = t.trim_end().to_string();
        let cut = s.rfind(',').unwrap();
        s.truncate(cut - 3);
        s
    }),
    7,
    ["cone+10.csv:41", "truncated"]
);
bad_csv_case!(duplicate_t, |d| set_field(d, 12, 0, "0.55"), 8, ["cone+10.csv:14:1 (t)", "duplicate"]);
bad_csv_case!(decreasing_t, |d| set_field(d, 12, 0, "0.3"), 8, ["cone+10.csv:14:1 (t)", "decreasing"]);

#[test]
fn gap_is_a_warning_or_with_strict_an_error() {
    let d = tempfile::tempdir().unwrap();
    small_session(d.path(), false);
    // Samples 20.. shifted by 1 s: one gap of 21 sample periods before sample 21 (line 22).
    edit_csv(d.path(), |t| {
        let mut lines: Vec<String> = t.lines().map(str::to_string).collect();
        for l in lines.iter_mut().skip(21) {
            let mut f: Vec<String> = l.split(',').map(str::to_string).collect();
            f[0] = format!("{}", f[0].parse::<f64>().unwrap() + 1.0);
            *l = f.join(",");
        }
        lines.join("\n") + "\n"
    });
    let (c, out, _) = run_in(d.path(), &["fit", "s/session.json", "--dry-run"]);
    assert_eq!(c, 0, "{out}");
    assert!(out.contains("warning") && out.contains("gap in t") && out.contains("sample 21"), "{out}");
    expect_fit_error(d.path(), &["--strict"], 9, &["cone+10.csv:22:1 (t)", "gap"]);
    // `correct` says the same, offline and streaming; with --strict it writes nothing.
    let (c, out, err) = run_in(d.path(), &["fit", "s/session.json", "--out", "store"]);
    assert_eq!(c, 0, "{out}{err}");
    let profile = std::fs::read_dir(d.path().join("store")).unwrap().next().unwrap().unwrap().path();
    let profile = std::fs::read_dir(profile).unwrap().next().unwrap().unwrap().path();
    let profile = profile.to_str().unwrap();
    for mode in ["offline", "streaming"] {
        let out_csv = format!("{mode}.csv");
        let args = ["correct", "--profile", profile, "s/cone+10.csv", "-o", &out_csv, "--mode", mode];
        let (c, _, err) = run_in(d.path(), &[&args[..], &["--strict"]].concat());
        assert_eq!(c, 9, "{mode}: {err}");
        assert!(err.contains("cone+10.csv:22:1 (t)") && err.contains("gap"), "{mode}: {err}");
        assert!(!d.path().join(&out_csv).exists(), "{mode}: a refused correction wrote its output");
        let (c, _, err) = run_in(d.path(), &args);
        assert_eq!(c, 0, "{mode}: {err}");
        assert!(err.contains("warning") && err.contains("gap in t") && err.contains("sample 21"), "{mode}: {err}");
    }
}

#[test]
fn unknown_unit() {
    let d = tempfile::tempdir().unwrap();
    small_session(d.path(), false);
    edit_manifest(d.path(), |t| t.replace("\"deg/s\"", "\"dps\""));
    expect_fit_error(d.path(), &[], 10, &["session.json:", "'dps'", "deg/s, rad/s, raw"]);
}

#[test]
fn manifest_not_json() {
    let d = tempfile::tempdir().unwrap();
    small_session(d.path(), false);
    edit_manifest(d.path(), |t| t.replacen("{", "{{", 1));
    expect_fit_error(d.path(), &[], 11, &["session.json:1:", "not valid JSON"]);
}

#[test]
fn unknown_session_format() {
    let d = tempfile::tempdir().unwrap();
    small_session(d.path(), false);
    edit_manifest(d.path(), |t| t.replace("crosscal-session/1", "crosscal-session/7"));
    expect_fit_error(d.path(), &[], 12, &["session.json", "crosscal-session/7", "unknown session format"]);
}

#[test]
fn missing_run_file() {
    let d = tempfile::tempdir().unwrap();
    small_session(d.path(), false);
    std::fs::remove_file(csv_path(d.path())).unwrap();
    expect_fit_error(d.path(), &[], 13, &["session.json:", "cone+10.csv", "does not exist"]);
}

#[test]
fn mount_not_a_rotation() {
    let d = tempfile::tempdir().unwrap();
    small_session(d.path(), false);
    edit_manifest(d.path(), |t| t.replacen("\"+y\"", "\"-y\"", 1));
    expect_fit_error(d.path(), &[], 14, &["session.json:", "not a rotation", "mirror"]);
}

#[test]
fn unidentifiable_model_with_strict() {
    let d = tempfile::tempdir().unwrap();
    small_session(d.path(), false);
    expect_fit_error(d.path(), &["--strict"], 17, &["cannot identify", "gyro.e_xz", "re-mount"]);
}

#[test]
fn profile_of_unknown_version_or_other_unit() {
    let d = tempfile::tempdir().unwrap();
    small_session(d.path(), false);
    let (c, out, err) = run_in(d.path(), &["fit", "s/session.json", "--out", "p"]);
    assert_eq!(c, 0, "{out}{err}");
    let prof = std::fs::read_dir(d.path().join("p/I1426-0042")).unwrap().next().unwrap().unwrap().path();
    let text = std::fs::read_to_string(&prof).unwrap();
    std::fs::write(d.path().join("future.json"), text.replace("crosscal-profile/1", "crosscal-profile/2")).unwrap();
    let (c, _, err) = run_in(d.path(), &["check", "--profile", "future.json", "s/session.json"]);
    assert_eq!(c, 15, "{err}");
    assert!(
        err.contains("future.json") && err.contains("crosscal-profile/2") && err.contains("not supported"),
        "{err}"
    );
    let (c, _, err) = run_in(d.path(), &["correct", "--profile", "future.json", "s/cone+10.csv", "-o", "x.csv"]);
    assert_eq!(c, 15, "{err}");
    assert!(!d.path().join("x.csv").exists());
    std::fs::write(d.path().join("other.json"), text.replace("\"serial\": \"I1426-0042\"", "\"serial\": \"OTHER-7\""))
        .unwrap();
    let (c, _, err) = run_in(d.path(), &["check", "--profile", "other.json", "s/session.json"]);
    assert_eq!(c, 16, "{err}");
    assert!(err.contains("other.json") && err.contains("OTHER-7") && err.contains("I1426-0042"), "{err}");
}

#[test]
fn unreadable_file() {
    let d = tempfile::tempdir().unwrap();
    let (c, _, err) = run_in(d.path(), &["fit", "nowhere/session.json"]);
    assert_eq!(c, 3, "{err}");
    assert!(err.contains("nowhere/session.json") && err.contains("cannot read"), "{err}");
}

// Optional manifest fields of the wrong kind are refused, not ignored (a "hot" temperature
// used to fall back to no temperature; a string phase to 0°).
bad_csv_case!(
    temperature_of_the_wrong_kind,
    |d| edit_manifest(d, |t| t.replacen(
        "\"name\": \"cone+10\"",
        "\"name\": \"cone+10\", \"temperature_c\": \"hot\"",
        1
    )),
    18,
    ["temperature_c", "must be a finite number"]
);
bad_csv_case!(
    phase_of_the_wrong_kind,
    |d| edit_manifest(d, |t| t.replacen("\"phase_deg\": 0.0", "\"phase_deg\": \"zero\"", 1)),
    18,
    ["phase_deg", "must be a finite number"]
);
