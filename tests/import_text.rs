//! Delimited text recordings (`crosscal import text`): delimiters detected, columns by header
//! aliases or by `--columns`, units stated, errors that name file, line and column and, for
//! a header split by the wrong delimiter, the delimiter the file seems to use; and the real
//! recordings' raw text files give the samples of their converted sessions.

use crate::common::run_in;
use std::path::Path;

/// A small multi-position-like recording: 400 rows at 100 Hz of (t, gyro, accel).
fn rows() -> Vec<[f64; 7]> {
    (0..400)
        .map(|k| {
            let t = k as f64 * 0.01;
            [t, 0.01 * (k % 7) as f64, -0.02, 0.003 * k as f64, 0.1, -0.2, 9.8 + 0.001 * (k % 5) as f64]
        })
        .collect()
}

fn written(dir: &Path) -> Vec<[f64; 7]> {
    let text = std::fs::read_to_string(dir.join("recording.csv")).unwrap();
    text.lines()
        .skip(1)
        .map(|l| {
            let v: Vec<f64> = l.split(',').map(|x| x.parse().unwrap()).collect();
            [v[0], v[1], v[2], v[3], v[4], v[5], v[6]]
        })
        .collect()
}

#[test]
fn delimiters_headers_and_column_orders_are_read() {
    let d = tempfile::tempdir().unwrap();
    let data = rows();
    // Semicolon, a header in another tool's names, accelerometer first.
    let mut semi = String::from("time;acc_x;acc_y;acc_z;gyr_x;gyr_y;gyr_z\n");
    // Tab, no header, an extra column to skip, gyro first.
    let mut tab = String::new();
    // Spaces, no header, no time column.
    let mut spaces = String::from("# a comment line\n");
    for r in &data {
        semi += &format!("{};{};{};{};{};{};{}\n", r[0], r[4], r[5], r[6], r[1], r[2], r[3]);
        tab += &format!("{}\t{}\t{}\t{}\t{}\t{}\t{}\t42\n", r[0], r[1], r[2], r[3], r[4], r[5], r[6]);
        spaces += &format!("  {}   {} {} {} {} {}\n", r[1], r[2], r[3], r[4], r[5], r[6]);
    }
    std::fs::write(d.path().join("semi.txt"), semi).unwrap();
    std::fs::write(d.path().join("tab.txt"), tab).unwrap();
    std::fs::write(d.path().join("spaces.txt"), spaces).unwrap();
    let cases: [(&str, Vec<&str>); 3] = [
        ("semi", vec!["import", "text", "semi.txt", "--out", "semi", "--init-rest-s", "1"]),
        (
            "tab",
            vec![
                "import",
                "text",
                "tab.txt",
                "--columns",
                "t,gx,gy,gz,ax,ay,az,-",
                "--out",
                "tab",
                "--init-rest-s",
                "1",
            ],
        ),
        (
            "spaces",
            vec![
                "import",
                "text",
                "spaces.txt",
                "--columns",
                "gx,gy,gz,ax,ay,az",
                "--rate-hz",
                "100",
                "--out",
                "spaces",
                "--static",
            ],
        ),
    ];
    for (name, args) in cases {
        let (code, out, err) = run_in(d.path(), &args);
        assert_eq!(code, 0, "{name}: {out}{err}");
        let got = written(&d.path().join(name));
        assert_eq!(got.len(), data.len(), "{name}");
        for (g, w) in got.iter().zip(&data) {
            for k in 0..7 {
                assert!((g[k] - w[k]).abs() <= 1e-12 * w[k].abs().max(1.0), "{name}: {g:?} vs {w:?}");
            }
        }
    }
    let manifest = std::fs::read_to_string(d.path().join("spaces/session.json")).unwrap();
    assert!(manifest.contains("\"gyro\": \"rad/s\"") && manifest.contains("\"up_stand\": \"unknown\""), "{manifest}");
    // The static recording goes straight to `noise`.
    let (code, out, err) = run_in(d.path(), &["noise", "spaces/session.json"]);
    assert_eq!(code, 0, "{out}{err}");
}

#[test]
fn a_wrong_delimiter_or_a_short_row_is_named() {
    let d = tempfile::tempdir().unwrap();
    let mut semi = String::from("t;gx;gy;gz;ax;ay;az\n");
    for r in rows() {
        semi += &format!("{};{};{};{};{};{};{}\n", r[0], r[1], r[2], r[3], r[4], r[5], r[6]);
    }
    std::fs::write(d.path().join("semi.csv"), &semi).unwrap();
    let (code, _, err) = run_in(d.path(), &["import", "text", "semi.csv", "--delimiter", ",", "--out", "x"]);
    assert_eq!(code, 5, "{err}");
    assert!(err.contains("semi.csv:1") && err.contains("seems to use ';'"), "{err}");
    let short = semi.replacen("0.03;", "", 1);
    std::fs::write(d.path().join("short.csv"), short).unwrap();
    let (code, _, err) = run_in(d.path(), &["import", "text", "short.csv", "--out", "y"]);
    assert_ne!(code, 0, "{err}");
    assert!(err.contains("short.csv:") && (err.contains("fields") || err.contains("delimiter")), "{err}");
    let (code, _, err) = run_in(d.path(), &["import", "text", "semi.csv", "--gyro-unit", "furlong/s", "--out", "z"]);
    assert_eq!(code, 2, "{err}");
    assert!(!d.path().join("x").join("session.json").exists() && !d.path().join("y").join("session.json").exists());
}

/// The real recordings' raw files (../shared/data/real2) through the importers give the
/// samples of the sessions converted from them, as their README describes: the 7251 board
/// in one gyro-first, space-separated file of raw counts; a ROS 2 unit in imu_tk's two
/// tab-separated files (rad/s, m/s², 100 Hz).
#[test]
fn real_raw_text_files_give_the_converted_sessions() {
    let shared = Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/data/real2");
    if !shared.is_dir() {
        eprintln!("skipped: ../shared/data/real2 is not beside this checkout");
        return;
    }
    let d = tempfile::tempdir().unwrap();
    let raw = shared.join("imu_tk_7251_ouabout/raw/7251imu.txt");
    let (code, out, err) = run_in(
        d.path(),
        &[
            "import",
            "text",
            raw.to_str().unwrap(),
            "--columns",
            "t,gx,gy,gz,ax,ay,az",
            "--gyro-unit",
            "raw",
            "--accel-unit",
            "raw",
            "--init-rest-s",
            "25",
            "--g",
            "9.8",
            "--out",
            "b7",
        ],
    );
    assert_eq!(code, 0, "{out}{err}");
    let ours = std::fs::read_to_string(d.path().join("b7/recording.csv")).unwrap();
    let theirs = std::fs::read_to_string(shared.join("imu_tk_7251_ouabout/session/7251.csv")).unwrap();
    assert_eq!(ours.lines().count(), theirs.lines().count());
    assert_eq!(ours.lines().nth(1), theirs.lines().nth(1));
    assert_eq!(ours.lines().last(), theirs.lines().last());
    // 200 Hz, as the README says.
    let t: Vec<f64> = ours.lines().skip(1).take(1001).map(|l| l.split(',').next().unwrap().parse().unwrap()).collect();
    let rate = 1000.0 / (t[1000] - t[0]);
    assert!((rate - 200.0).abs() < 2.0, "{rate} Hz");
    let (code, out, err) = run_in(d.path(), &["fit", "b7/session.json", "--dry-run"]);
    assert_eq!(code, 0, "a 25 s rest before the first bump fits: {out}{err}");

    let raw = shared.join("imu_tk_ros2_getovermassif/raw/data2");
    let (code, out, err) = run_in(
        d.path(),
        &[
            "import",
            "imu-tk",
            raw.join("acc_data.txt").to_str().unwrap(),
            raw.join("gyro_data.txt").to_str().unwrap(),
            "--init-rest-s",
            "5",
            "--out",
            "r2",
        ],
    );
    assert_eq!(code, 0, "{out}{err}");
    let ours = written(&d.path().join("r2"));
    let theirs: Vec<Vec<f64>> =
        std::fs::read_to_string(shared.join("imu_tk_ros2_getovermassif/session_data2/data2.csv"))
            .unwrap()
            .lines()
            .skip(1)
            .map(|l| l.split(',').map(|x| x.parse().unwrap()).collect())
            .collect();
    assert_eq!(ours.len(), theirs.len());
    for (o, t) in ours.iter().zip(&theirs) {
        for k in 0..7 {
            assert!((o[k] - t[k]).abs() <= 1e-9 * t[k].abs().max(1.0), "{o:?} vs {t:?}");
        }
    }
    // At rest, z down (README): the first second reads about −g on z in m/s².
    let az = ours.iter().take(100).map(|r| r[6]).sum::<f64>() / 100.0;
    assert!((az + 9.8).abs() < 0.3, "az at rest {az}");
}
