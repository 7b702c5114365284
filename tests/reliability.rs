//! Issue 38: what used to be silently wrong, lost or crashed on hand-edited inputs (manifests,
//! profiles), special files and closed streams.

use crate::common::{run_timed, small_session};

/// A misspelt manifest field is an error naming it and the closest known field (it used to
/// be ignored: a run's `"mounting"` left the mount at identity and the fit was wrong, exit 0).
#[test]
fn unknown_manifest_fields_are_refused_with_the_closest_known_one() {
    let d = tempfile::tempdir().unwrap();
    small_session(d.path(), false);
    let p = d.path().join("s/session.json");
    let good = std::fs::read_to_string(&p).unwrap();
    for (from, to, key, closest) in [
        ("\"mount\"", "\"mounting\"", "mounting", "mount"),
        ("\"serial\"", "\"serail\"", "serail", "serial"),
        ("\"cone_angle_deg\"", "\"cone_angle\"", "cone_angle", "cone_angle_deg"),
    ] {
        assert!(good.contains(from));
        std::fs::write(&p, good.replacen(from, to, 1)).unwrap();
        for strict in [false, true] {
            let mut args = vec!["fit", "s/session.json"];
            if strict {
                args.push("--strict");
            }
            let (code, out, err) = run_timed(d.path(), &args, 60);
            assert_eq!(code, 18, "{to}: {out}{err}");
            assert!(err.contains(&format!("unknown field \"{key}\"")), "{err}");
            assert!(err.contains(&format!("did you mean \"{closest}\"")), "{err}");
            assert!(err.contains("session.json:"), "no line: {err}");
        }
        assert!(!d.path().join("calib-profiles").exists());
    }
    // The user's own metadata: an `extra` object and `x-` keys anywhere.
    let with_meta = good
        .replacen(
            "\"serial\"",
            "\"extra\": {\"operator\": \"AB\", \"n\": [1, 2]}, \"x-site\": \"lab 2\", \"serial\"",
            1,
        )
        .replacen("\"mount\"", "\"x-take\": 3, \"extra\": {\"note\": 1}, \"mount\"", 1);
    std::fs::write(&p, with_meta).unwrap();
    let (code, out, err) = run_timed(d.path(), &["fit", "s/session.json", "--out", "store"], 60);
    assert_eq!(code, 0, "{out}{err}");
}

/// Correction settings of a hand-edited profile are checked when it is read: a profile error
/// (exit 21) naming the field, never a changed output or a 16 GB allocation.
#[test]
fn hand_edited_correction_settings_are_refused_naming_the_field() {
    let d = tempfile::tempdir().unwrap();
    small_session(d.path(), true);
    let (path, profile) = crate::common::only_profile(&d.path().join("store"));
    let good = std::fs::read_to_string(&path).unwrap();
    let mut v: serde_json::Value = serde_json::from_str(&good).unwrap();
    let channel_of = profile.gyro.coefficients.iter().position(|c| c.channel == 0).unwrap();
    for (field, value, key) in [
        ("derivative_half_window", serde_json::json!(0), "derivative_half_window"),
        ("streaming_window", serde_json::json!(0), "streaming_window"),
        ("streaming_window", serde_json::json!(1), "streaming_window"),
        ("streaming_window", serde_json::json!(1_000_000_000u64), "streaming_window"),
        ("streaming_degree", serde_json::json!(20), "streaming_degree"),
        ("derivative_degree", serde_json::json!(11), "derivative_degree"),
        ("channel", serde_json::json!(7), "channel"),
    ] {
        let mut bad = v.clone();
        if field == "channel" {
            bad["gyro"]["coefficients"][channel_of]["channel"] = value.clone();
        } else {
            bad["correction"][field] = value.clone();
        }
        let p = d.path().join("edited.json");
        std::fs::write(&p, serde_json::to_string_pretty(&bad).unwrap()).unwrap();
        let _ = std::fs::remove_file(d.path().join("out.csv"));
        let args = ["correct", "--profile", "edited.json", "s/cone+10.csv", "-o", "out.csv"];
        let (code, out, err) = run_timed(d.path(), &args, 60);
        assert_eq!(code, 21, "{field}={value}: {out}{err}");
        assert!(err.contains(key), "{field}: {err}");
        assert!(!d.path().join("out.csv").exists());
    }
    // The profile as written still corrects.
    v["correction"]["streaming_window"] = serde_json::json!(11);
    std::fs::write(d.path().join("edited.json"), serde_json::to_string_pretty(&v).unwrap()).unwrap();
    let (code, out, err) =
        run_timed(d.path(), &["correct", "--profile", "edited.json", "s/cone+10.csv", "-o", "out.csv"], 60);
    assert_eq!(code, 0, "{out}{err}");
}

/// Runs a shell script in `dir` with a time limit (`timeout`), so that a hang on a FIFO
/// fails the test instead of stopping it; returns (exit code, stdout, stderr).
fn sh_timed(dir: &std::path::Path, script: &str) -> (i32, String, String) {
    crate::common::sh_in(dir, &format!("timeout -k 5 30 sh -c '{}'", script.replace('\'', "'\\''")))
}

/// FIFOs and devices are never opened as data: a FIFO profile in a store, a FIFO manifest,
/// a link to /dev/zero are skipped or refused naming them, in bounded time.
#[test]
fn fifos_and_devices_are_skipped_or_refused_naming_them() {
    let d = tempfile::tempdir().unwrap();
    small_session(d.path(), true);
    let unit = std::fs::read_dir(d.path().join("store")).unwrap().flatten().next().unwrap().path();
    let unit_name = unit.file_name().unwrap().to_string_lossy().to_string();
    let (c, o, e) =
        sh_timed(d.path(), &format!("mkfifo store/{unit_name}/x.json && ln -s /dev/zero store/{unit_name}/z.json"));
    assert_eq!(c, 0, "{o}{e}");
    let (c, o, e) = sh_timed(d.path(), "\"$CROSSCAL\" profile list --store store");
    assert_eq!(c, 0, "profile list with a FIFO in the store (124 = hung): {o}{e}");
    assert!(format!("{o}{e}").contains("x.json") && format!("{o}{e}").contains("FIFO"), "{o}{e}");
    assert!(format!("{o}{e}").contains("z.json") && format!("{o}{e}").contains("device"), "{o}{e}");
    let (c, o, e) =
        sh_timed(d.path(), &format!("\"$CROSSCAL\" correct --profile store/{unit_name} s/cone+10.csv -o out.csv"));
    assert_eq!(c, 0, "correct --profile STORE/UNIT with a FIFO in it: {o}{e}");
    // A FIFO manifest: refused, naming it, not read forever.
    let (c, o, e) = sh_timed(d.path(), "mkdir lot && mkfifo lot/session.json && \"$CROSSCAL\" fit lot/session.json");
    assert!(c != 0 && c != 124, "{c}: {o}{e}");
    assert!(e.contains("lot/session.json") && e.contains("FIFO"), "{e}");
}

/// `--force` never replaces what is not a regular file, and `-o -` is standard output.
#[test]
fn force_never_replaces_a_special_file_and_dash_is_stdout() {
    let d = tempfile::tempdir().unwrap();
    small_session(d.path(), true);
    let (_, o, e) = sh_timed(d.path(), "mkfifo target.csv");
    let (path, _) = crate::common::only_profile(&d.path().join("store"));
    let profile = path.to_string_lossy().to_string();
    for mode in ["offline", "streaming"] {
        let (c, o2, e2) = sh_timed(
            d.path(),
            &format!("\"$CROSSCAL\" correct --profile {profile} s/cone+10.csv -o target.csv --force --mode {mode}"),
        );
        assert!(c != 0 && c != 124, "{mode}: {c} {o}{e}{o2}{e2}");
        assert!(e2.contains("FIFO") && e2.contains("not a regular file"), "{e2}");
        let (c, _, _) = sh_timed(d.path(), "test -p target.csv");
        assert_eq!(c, 0, "the FIFO was replaced");
        let (c, out, err) =
            sh_timed(d.path(), &format!("\"$CROSSCAL\" correct --profile {profile} s/cone+10.csv -o - --mode {mode}"));
        assert_eq!(c, 0, "{err}");
        assert!(out.starts_with("t,gx,gy,gz,ax,ay,az") && out.lines().count() == 41, "{out}");
        assert!(!d.path().join("-").exists());
    }
}

/// A closed stderr (or stdout) is not a crash, and every output is still written.
#[test]
fn a_closed_stderr_loses_no_output() {
    let d = tempfile::tempdir().unwrap();
    let (c, o, e) = run_timed(d.path(), &["simulate", "--preset", "static", "--duration", "200", "-o", "still"], 60);
    assert_eq!(c, 0, "{o}{e}");
    let script = "(\"$CROSSCAL\" noise still/session.json --report n.html --figures figs/ --save n.json; echo \"code $?\" > code.txt) 2>&1 | head -c 1 >/dev/null";
    let (_, o, e) = sh_timed(d.path(), script);
    let code = std::fs::read_to_string(d.path().join("code.txt")).unwrap_or_default();
    assert_eq!(code.trim(), "code 0", "{o}{e}");
    for f in ["n.html", "n.json"] {
        assert!(d.path().join(f).is_file(), "{f} not written");
    }
    assert!(std::fs::read_dir(d.path().join("figs")).map(|r| r.count()).unwrap_or(0) > 0, "no figures");
    // Stderr alone closed (exec 2>&-).
    let script =
        "\"$CROSSCAL\" noise still/session.json --report m.html --figures figs2/ --save m.json 2>&- >/dev/null; echo \"code $?\"";
    let (_, o, _) = sh_timed(d.path(), script);
    assert_eq!(o.trim(), "code 0");
    assert!(d.path().join("m.html").is_file() && d.path().join("m.json").is_file());
}

/// One rule for every output: an existing file is refused unless --force (compare --svg and
/// diagnose --report used to replace it silently).
#[test]
fn every_output_refuses_to_replace_a_file_unless_forced() {
    let d = tempfile::tempdir().unwrap();
    small_session(d.path(), false);
    for (args, file) in [
        (vec!["compare", "s/session.json", "--svg", "ladder.svg"], "ladder.svg"),
        (vec!["diagnose", "s/session.json", "--report", "d.html"], "d.html"),
        (vec!["diagnose", "s/session.json", "--figures", "figs"], "figs/gyro-x-time.svg"),
    ] {
        std::fs::create_dir_all(d.path().join("figs")).unwrap();
        std::fs::write(d.path().join(file), "keep me").unwrap();
        let (code, out, err) = run_timed(d.path(), &args, 120);
        assert_eq!(code, 24, "{args:?}: {out}{err}");
        assert!(err.contains("already exists") && err.contains("--force"), "{err}");
        assert_eq!(std::fs::read_to_string(d.path().join(file)).unwrap(), "keep me");
        let mut forced = args.clone();
        forced.push("--force");
        let (code, out, err) = run_timed(d.path(), &forced, 120);
        assert_eq!(code, 0, "{forced:?}: {out}{err}");
        assert_ne!(std::fs::read_to_string(d.path().join(file)).unwrap(), "keep me");
    }
}
