//! Every exit code the guide documents is produced by a real case, and the guide's table
//! is the one the binary prints (`crosscal exit-codes`).

use crate::common::{edit, run_in, small_session};
use std::path::Path;

fn csv(dir: &Path) -> std::path::PathBuf {
    dir.join("s/cone+10.csv")
}

fn manifest(dir: &Path) -> std::path::PathBuf {
    dir.join("s/session.json")
}

fn profile(dir: &Path) -> std::path::PathBuf {
    let unit = std::fs::read_dir(dir.join("store")).unwrap().next().unwrap().unwrap().path();
    std::fs::read_dir(unit).unwrap().next().unwrap().unwrap().path()
}

/// Sets up case `code` in `dir` and returns the command that must exit with it.
fn case(code: u8, dir: &Path) -> Vec<String> {
    let s = |v: &[&str]| v.iter().map(|x| x.to_string()).collect::<Vec<_>>();
    let p = |d: &Path| profile(d).display().to_string();
    let fit = s(&["fit", "s/session.json", "--dry-run"]);
    match code {
        0 => s(&["effects", "gyro-bias"]),
        1 => {
            small_session(dir, true);
            let rules =
                r#"{"format": "crosscal-rules/1", "rules": [{"kind": "std_error", "select": "*", "max": 1e-30}]}"#;
            std::fs::write(dir.join("rules.json"), rules).unwrap();
            s(&["accept", &p(dir), "--rules", "rules.json"])
        }
        2 => {
            small_session(dir, false);
            s(&["fit", "s/session.json", "--effect", "no-such-effect"])
        }
        3 => s(&["fit", "no/such/session.json"]),
        4 => {
            small_session(dir, false);
            edit(&csv(dir), |t| t.lines().next().unwrap().to_string() + "\n");
            fit
        }
        5 => {
            small_session(dir, false);
            edit(&csv(dir), |t| t.replacen("t,gx,gy,gz,ax,ay,az", "t,gx,gy,gz,ax,ay,gx", 1));
            fit
        }
        6 => {
            small_session(dir, false);
            edit(&csv(dir), |t| t.replacen("\n0.1,", "\n1e400,", 1));
            fit
        }
        7 => {
            small_session(dir, false);
            edit(&csv(dir), |t| t.replacen("\n0.1,", "\n0.1,1,", 1));
            fit
        }
        8 => {
            small_session(dir, false);
            edit(&csv(dir), |t| t.replacen("\n0.1,", "\n0.05,", 1));
            fit
        }
        9 => {
            small_session(dir, false);
            // A gap of 5 s before the 21st sample.
            edit(&csv(dir), |t| {
                let mut lines: Vec<String> = t.lines().map(str::to_string).collect();
                for l in lines.iter_mut().skip(21) {
                    let (time, rest) = l.split_once(',').unwrap();
                    *l = format!("{},{rest}", time.parse::<f64>().unwrap() + 5.0);
                }
                lines.join("\n") + "\n"
            });
            s(&["fit", "s/session.json", "--dry-run", "--strict"])
        }
        10 => {
            small_session(dir, false);
            edit(&manifest(dir), |t| t.replace("\"deg/s\"", "\"deg/sec\""));
            fit
        }
        11 => {
            small_session(dir, false);
            edit(&manifest(dir), |t| t.replacen('{', "{\"serial\": \"A\",", 1));
            fit
        }
        12 => {
            small_session(dir, false);
            edit(&manifest(dir), |t| t.replace("crosscal-session/1", "crosscal-session/9"));
            fit
        }
        13 => {
            small_session(dir, false);
            std::fs::remove_file(csv(dir)).unwrap();
            fit
        }
        14 => {
            small_session(dir, false);
            edit(&manifest(dir), |t| t.replacen("\"+y\"", "\"+x\"", 1));
            fit
        }
        15 => {
            small_session(dir, true);
            edit(&profile(dir), |t| t.replace("crosscal-profile/1", "crosscal-profile/9"));
            s(&["check", "s/session.json", "--profile", &p(dir)])
        }
        16 => {
            small_session(dir, true);
            edit(&manifest(dir), |t| t.replacen("\"serial\": \"", "\"serial\": \"OTHER-", 1));
            s(&["check", "s/session.json", "--profile", &p(dir)])
        }
        17 => {
            small_session(dir, false);
            s(&["fit", "s/session.json", "--dry-run", "--strict"])
        }
        18 => {
            small_session(dir, false);
            edit(&manifest(dir), |t| t.replacen("\"rate_deg_s\": 10.0", "\"rate_deg_s\": 1e200", 1));
            fit
        }
        19 => {
            small_session(dir, false);
            edit(&csv(dir), |t| t.replacen("\n0.1,", &format!("\n{}", "9".repeat(2 << 20)), 1));
            fit
        }
        20 => {
            small_session(dir, true);
            std::fs::write(dir.join("rules.json"), r#"{"format": "crosscal-rules/9", "rules": []}"#).unwrap();
            s(&["accept", &p(dir), "--rules", "rules.json"])
        }
        21 => {
            small_session(dir, true);
            let path = profile(dir);
            let mut v: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&path).unwrap()).unwrap();
            v["gyro"]["coefficients"].as_array_mut().unwrap().remove(0);
            std::fs::write(&path, serde_json::to_string_pretty(&v).unwrap()).unwrap();
            s(&["check", "s/session.json", "--profile", &p(dir)])
        }
        22 => {
            small_session(dir, false);
            // Outputs whose squares overflow: no estimate can be made of them.
            edit(&csv(dir), |t| {
                let mut lines: Vec<String> = t.lines().map(str::to_string).collect();
                let f: Vec<&str> = lines[3].split(',').collect();
                lines[3] = format!("{},1e200,{}", f[0], f[2..].join(","));
                lines.join("\n") + "\n"
            });
            fit
        }
        23 => {
            let (c, o, e) = run_in(
                dir,
                &[
                    "simulate",
                    "-o",
                    "s",
                    "--duration",
                    "4",
                    "--rate-hz",
                    "20",
                    "--temperature",
                    "10,40",
                    "--hidden",
                    "gyro-temp-bias",
                    "--set",
                    "gyro.tb_x=1e-4",
                    "--gyro-noise",
                    "0.002",
                ],
            );
            assert_eq!(c, 0, "{o}{e}");
            let (c, o, e) = run_in(dir, &["fit", "s/session.json", "--out", "store", "--effect", "gyro-temp-bias"]);
            assert_eq!(c, 0, "{o}{e}");
            // The recording to correct has no temp column.
            edit(&csv(dir), |t| t.lines().map(|l| l.rsplit_once(',').unwrap().0.to_string() + "\n").collect());
            s(&["correct", "--profile", &p(dir), "s/cone+10.csv", "-o", "out.csv"])
        }
        24 => {
            small_session(dir, true);
            std::fs::write(dir.join("out.csv"), "keep me").unwrap();
            s(&["correct", "--profile", &p(dir), "s/cone+10.csv", "-o", "out.csv"])
        }
        25 => {
            std::fs::write(dir.join("bad.toml"), "[[effect]]\nid = \"x\"\nsensor = \"gyro\"\noutput = \"x\"\nexpr = \"k * w_q\"\ncoefficients = [\"k\"]\n").unwrap();
            s(&["effects", "--effects-file", "bad.toml"])
        }
        _ => panic!("no case for exit code {code}: add one"),
    }
}

/// The codes of the guide's table (docs/reference-exit-codes.md, between its markers).
fn documented() -> (String, Vec<u8>) {
    let readme =
        std::fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join("docs/reference-exit-codes.md")).unwrap();
    let start = readme.find("<!-- exit-codes:begin -->").expect("docs/reference-exit-codes.md marks its table");
    let end = readme.find("<!-- exit-codes:end -->").expect("and its end");
    let table = readme[start..end].lines().skip(1).collect::<Vec<_>>().join("\n") + "\n";
    let codes = table.lines().filter_map(|l| l.strip_prefix("| ")?.split(' ').next()?.parse().ok()).collect();
    (table, codes)
}

#[test]
fn the_guides_table_is_the_binarys() {
    let (table, codes) = documented();
    let d = tempfile::tempdir().unwrap();
    let (code, out, err) = run_in(d.path(), &["exit-codes"]);
    assert_eq!(code, 0, "{err}");
    assert_eq!(
        table.trim(),
        out.trim(),
        "regenerate the table of docs/reference-exit-codes.md with `crosscal exit-codes`"
    );
    assert_eq!(codes, (0..=25).collect::<Vec<u8>>());
}

#[test]
fn every_documented_exit_code_is_produced() {
    let (_, codes) = documented();
    let results = crate::common::par_map(&codes, |&code| {
        let d = tempfile::tempdir().unwrap();
        let args = case(code, d.path());
        let argv: Vec<&str> = args.iter().map(String::as_str).collect();
        let (got, out, err) = run_in(d.path(), &argv);
        (code, got, format!("{argv:?}\nstdout: {}\nstderr: {err}", out.chars().take(2000).collect::<String>()))
    });
    let wrong: Vec<String> = results
        .iter()
        .filter(|(want, got, _)| i32::from(*want) != *got)
        .map(|(want, got, what)| format!("exit code {want} expected, got {got}: {what}"))
        .collect();
    assert!(wrong.is_empty(), "{}", wrong.join("\n\n"));
}
