//! Logs and bags users bring (`../shared/data/formats/`, never copied here): every file is
//! listed and imported, and what crosscal reads is checked against the numbers the
//! folder's README gives (decoded there with pyulog, pymavlink and rosbags). Each test
//! skips with a message when the data are absent. Generated files (`formats_gen`) cover
//! what the samples lack: lz4 chunks, MCAP, a plain `sensor_msgs/msg/Imu` in a sqlite bag,
//! ULog appended data, DataFlash garbage and FMTU multipliers.

use crate::common::{run_in, run_ok};
use crosscal::session::logs::{list, read, LogFormat, LogSample, ReadOptions, StreamStats};
use std::path::{Path, PathBuf};

fn shared(rel: &str) -> Option<PathBuf> {
    let p = Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/data/formats").join(rel);
    if p.exists() {
        Some(p)
    } else {
        eprintln!("skipping: {} is absent", p.display());
        None
    }
}

/// One stream as the README describes it: name, samples, rate (Hz), span (s), temperature
/// range (°C) when reported, and one decoded sample (time ns or the first when None).
struct Expect {
    name: &'static str,
    samples: u64,
    rate_hz: f64,
    span_s: f64,
    temp_c: Option<[f64; 2]>,
    sample: Option<(Option<i64>, [f64; 3], [f64; 3])>,
}

fn close(a: f64, b: f64, tol: f64) -> bool {
    (a - b).abs() <= tol
}

fn check_file(rel: &str, format: LogFormat, expect: &[Expect], applied: &[&str]) {
    let Some(path) = shared(rel) else { return };
    let (contents, stats) = list(&path, &ReadOptions::default()).unwrap_or_else(|e| panic!("{rel}: {e}"));
    assert_eq!(contents.format, format, "{rel}");
    let names: Vec<&str> = contents.streams.iter().map(|s| s.name.as_str()).collect();
    assert_eq!(names.len(), expect.len(), "{rel}: streams {names:?}");
    for e in expect {
        let i = names.iter().position(|n| *n == e.name).unwrap_or_else(|| panic!("{rel}: no {} in {names:?}", e.name));
        let s: &StreamStats = &stats[i];
        assert_eq!(s.samples, e.samples, "{rel} {}: samples", e.name);
        assert!(
            close(s.rate_hz(), e.rate_hz, 0.05 + 0.001 * e.rate_hz),
            "{rel} {}: rate {} vs {}",
            e.name,
            s.rate_hz(),
            e.rate_hz
        );
        assert!(
            close(s.span_s(), e.span_s, 0.01 + 0.001 * e.span_s),
            "{rel} {}: span {} vs {}",
            e.name,
            s.span_s(),
            e.span_s
        );
        match (s.temp_c, e.temp_c) {
            (Some([lo, hi]), Some([elo, ehi])) => {
                assert!(close(lo, elo, 0.06) && close(hi, ehi, 0.06), "{rel} {}: temperature {lo}..{hi}", e.name)
            }
            (None, None) => {}
            (got, want) => panic!("{rel} {}: temperature {got:?}, README {want:?}", e.name),
        }
        if let Some((t, g, a)) = e.sample {
            let found = match t {
                None => s.first,
                Some(t_ns) => {
                    find_sample(&path, i, t_ns).unwrap_or_else(|| panic!("{rel} {}: no sample at {t_ns} ns", e.name))
                }
            };
            for k in 0..3 {
                assert!(
                    close(found.gyro_rad_s[k], g[k], 6e-6),
                    "{rel} {} gyro {k}: {:?} vs README {g:?}",
                    e.name,
                    found.gyro_rad_s
                );
                if !a[k].is_nan() {
                    assert!(
                        close(found.accel_m_s2[k], a[k], 6e-6),
                        "{rel} {} accel {k}: {:?} vs {a:?}",
                        e.name,
                        found.accel_m_s2
                    );
                }
            }
        }
    }
    for p in applied {
        assert!(
            contents.applied.iter().any(|(n, _)| n == p),
            "{rel}: applied calibration lacks {p}: {:?}",
            contents.applied
        );
    }
}

fn find_sample(path: &Path, stream: usize, t_ns: i64) -> Option<LogSample> {
    let mut hit = None;
    read(path, &ReadOptions::default(), Some(stream), &mut |_, s| {
        // The README prints stamps to the microsecond.
        if (s.t_ns - t_ns).abs() < 1000 {
            hit = Some(*s);
        }
        Ok(())
    })
    .ok()?;
    hit
}

#[test]
fn px4_ulogs_read_as_their_readme_says() {
    check_file(
        "ulog/px4_auav_x21_sensor_combined.ulg",
        LogFormat::ULog,
        &[Expect {
            name: "sensor_combined",
            samples: 17_070,
            rate_hz: 250.0,
            span_s: 68.88,
            temp_c: None,
            sample: Some((Some(113_048_707_000), [-0.00161, -0.00331, -0.00314], [1.12265, -0.49896, -9.60992])),
        }],
        &["CAL_ACC0_XOFF", "CAL_GYRO0_XOFF", "SENS_BOARD_ROT"],
    );
    let imu = |name: &'static str, t: [f64; 2]| Expect {
        name,
        samples: 6,
        rate_hz: 1.0,
        span_s: 5.0,
        temp_c: Some(t),
        sample: None,
    };
    check_file(
        "ulog/px4_cubeorange_three_imus.ulg",
        LogFormat::ULog,
        &[
            Expect {
                name: "sensor_combined",
                samples: 1298,
                rate_hz: 204.6,
                span_s: 6.50,
                temp_c: None,
                sample: Some((Some(20_971_931_000), [0.00184, -0.00114, -0.00328], [-0.04115, -0.17096, -9.59200])),
            },
            imu("sensor_accel+gyro[0]", [40.0, 40.4]),
            imu("sensor_accel+gyro[1]", [28.2, 28.4]),
            imu("sensor_accel+gyro[2]", [29.4, 29.7]),
        ],
        &["CAL_ACC0_XOFF", "TC_A_ENABLE", "SENS_BOARD_ROT"],
    );
    // The accelerometers' first samples as the README prints them (paired on the gyro's clock,
    // 1 ms apart here, so the interpolated values agree to the README's 5 decimals only when
    // the accelerometer sample itself is taken: compare with a tolerance of the change
    // between neighbouring samples instead).
    let Some(path) = shared("ulog/px4_cubeorange_three_imus.ulg") else { return };
    let (_, stats) = list(&path, &ReadOptions::default()).unwrap_or_else(|e| panic!("{e}"));
    for (i, want) in [(1, [0.68213, 0.24334, -9.69695]), (2, [0.35674, 0.30861, -9.91271])] {
        let a = stats[i].first.accel_m_s2;
        assert!((0..3).all(|k| close(a[k], want[k], 0.02)), "IMU {}: first accel {a:?} vs README {want:?}", i - 1);
    }
}

#[test]
fn ardupilot_dataflash_logs_read_as_their_readme_says() {
    check_file(
        "dataflash/arducopter_imu_imu2_50s.bin",
        LogFormat::DataFlash,
        &[
            Expect {
                name: "IMU",
                samples: 1258,
                rate_hz: 24.8,
                span_s: 50.86,
                temp_c: Some([27.2, 27.7]),
                sample: Some((Some(402_644_506_000), [-0.07747, -0.09213, 0.01890], [-0.11938, 0.24224, -10.21316])),
            },
            Expect {
                name: "IMU2",
                samples: 1258,
                rate_hz: 24.8,
                span_s: 50.86,
                temp_c: None,
                sample: Some((Some(402_644_506_000), [-0.03300, -0.07381, 0.04374], [-0.27693, 0.14753, -10.39236])),
            },
        ],
        &["INS_ACCOFFS_X", "INS_GYROFFS_Z", "AHRS_ORIENTATION"],
    );
    check_file(
        "dataflash/arducopter_4.6.2_truncated_80k.bin",
        LogFormat::DataFlash,
        &[
            Expect {
                name: "IMU[0]",
                samples: 10,
                rate_hz: 24.6,
                span_s: 0.37,
                temp_c: Some([37.3, 37.3]),
                sample: Some((Some(140_209_868_000), [0.00534, -0.00323, -0.00053], [0.61293, 0.86727, -9.76368])),
            },
            Expect {
                name: "IMU[1]",
                samples: 10,
                rate_hz: 24.6,
                span_s: 0.37,
                temp_c: Some([28.5, 28.5]),
                sample: Some((Some(140_209_868_000), [0.00356, 0.00084, -0.00088], [0.48838, 0.91392, -9.73778])),
            },
            Expect { name: "ISBG[0]", samples: 576, rate_hz: 2000.3, span_s: 0.2875, temp_c: None, sample: None },
        ],
        &["INS_TCAL1_ENABLE", "INS_ACCSCAL_X"],
    );
    // The cut is reported with its byte offset, and the batch's mean matches the README.
    let Some(path) = shared("dataflash/arducopter_4.6.2_truncated_80k.bin") else { return };
    let mut sum = 0.0;
    let mut n = 0.0;
    let c = read(&path, &ReadOptions::default(), None, &mut |i, s| {
        if i == 0 {
            sum += s.gyro_rad_s[0];
            n += 1.0;
        }
        Ok(())
    })
    .unwrap_or_else(|e| panic!("{e}"));
    assert!(c.warnings.iter().any(|w| w.contains("byte 81918") && w.contains("truncated")), "{:?}", c.warnings);
    assert!(close(sum / n, 0.0043, 0.00005), "batch mean gyro x {}", sum / n);
}

#[test]
fn ros_bags_read_as_their_readme_says() {
    check_file(
        "rosbag1/phidgets_imu_upside_down.bag",
        LogFormat::Ros1Bag,
        &[Expect {
            name: "/imu/data_raw",
            samples: 13_964,
            rate_hz: 250.0,
            span_s: 56.24,
            temp_c: None,
            sample: Some((Some(1_360_242_236_215_352_000), [0.00422, 0.0, 0.00187], [-0.20729, -0.10026, -9.86602])),
        }],
        &[],
    );
    check_file(
        "rosbag1/imu_static_1.bag",
        LogFormat::Ros1Bag,
        &[Expect {
            name: "/imu1",
            samples: 1071,
            rate_hz: 10.0,
            span_s: 107.0,
            temp_c: None,
            sample: Some((None, [-0.01171, -0.01490, 0.04257], [0.20111, 0.26336, 9.73961])),
        }],
        &[],
    );
    for (bag, samples, rate, span, gyro, accel) in [
        ("rosbag2/vn100_emulator_40hz", 624, 40.2, 15.58, [-0.00019, 0.00097, -0.00027], [-5.984, -0.164, -7.864]),
        ("rosbag2/vn100_stationary_1hz", 329, 1.0, 328.0, [-0.00130, -0.00035, 0.00052], [0.128, -0.110, -9.673]),
    ] {
        let e = Expect {
            name: "/imu",
            samples,
            rate_hz: rate,
            span_s: span,
            temp_c: None,
            sample: Some((None, gyro, accel)),
        };
        check_file(bag, LogFormat::Ros2Sqlite, &[e], &[]);
    }
}

/// The custom type given by its definition reads the same as the bytes-recognised guess,
/// and the guess is said.
#[test]
fn a_custom_ros2_type_reads_from_its_definition_as_from_the_guess() {
    let Some(bag) = shared("rosbag2/vn100_emulator_40hz") else { return };
    let dir = tempfile::tempdir().unwrap_or_else(|e| panic!("{e}"));
    let def = dir.path().join("IMUmsg.msg");
    std::fs::write(
        &def,
        "std_msgs/Header header\nsensor_msgs/Imu imu\nsensor_msgs/MagneticField mag_field\nstring raw_imu_string\n",
    )
    .unwrap_or_else(|e| panic!("{e}"));
    let collect = |opts: &ReadOptions| {
        let mut v = Vec::new();
        let c = read(&bag, opts, None, &mut |_, s| {
            v.push(*s);
            Ok(())
        })
        .unwrap_or_else(|e| panic!("{e}"));
        (c, v)
    };
    let (guessed, a) = collect(&ReadOptions::default());
    let opts = ReadOptions { msg_defs: vec![("imu_msg/msg/IMUmsg".into(), def.clone())] };
    let (given, b) = collect(&opts);
    assert_eq!(a.len(), 624);
    assert_eq!(a, b, "definition and guess must decode the same samples");
    assert!(guessed.streams[0].note.as_deref().is_some_and(|n| n.contains("recognised from the bytes")));
    assert!(given.streams[0].note.is_none(), "{:?}", given.streams[0].note);
    // A definition that does not hold an Imu is refused with the type named.
    std::fs::write(&def, "std_msgs/Header header\nstring raw\n").unwrap_or_else(|e| panic!("{e}"));
    let bad = ReadOptions { msg_defs: vec![("imu_msg/msg/IMUmsg".into(), def)] };
    let err = read(&bag, &bad, None, &mut |_, _| Ok(())).err().map(|e| e.to_string()).unwrap_or_default();
    assert!(err.contains("IMUmsg") && err.contains("holds no sensor_msgs/Imu"), "{err}");
}

/// A static bag goes straight to `noise`, the format's provenance in the session.
#[test]
fn a_static_bag_is_imported_as_a_static_session_and_goes_through_noise() {
    let Some(bag) = shared("rosbag1/imu_static_1.bag") else { return };
    let dir = tempfile::tempdir().unwrap_or_else(|e| panic!("{e}"));
    let d = dir.path();
    let bag = bag.to_string_lossy().to_string();
    let out = run_ok(d, &["import", "--list", &bag]);
    assert!(out.contains("/imu1") && out.contains("1071"), "{out}");
    let out = run_ok(d, &["import", &bag, "--out", "s"]);
    assert!(out.contains("at rest throughout") && out.contains("crosscal noise"), "{out}");
    let manifest = std::fs::read_to_string(d.join("s/session.json")).unwrap_or_else(|e| panic!("{e}"));
    assert!(
        manifest.contains("\"static\"") && manifest.contains("\"source\"") && manifest.contains("ROS 1 bag"),
        "{manifest}"
    );
    let noise = run_ok(d, &["noise", "s/session.json", "--json"]);
    let v: serde_json::Value = serde_json::from_str(&noise).unwrap_or_else(|e| panic!("{e}: {noise}"));
    assert!(v["channels"].as_array().is_some_and(|c| c.len() == 6), "{noise}");
    // --from/--to cut a part: 20 s at 10 Hz.
    run_ok(d, &["import", &bag, "--from", "10", "--to", "30", "--out", "cut"]);
    let rows =
        std::fs::read_to_string(d.join("cut/recording.csv")).unwrap_or_else(|e| panic!("{e}")).lines().count() - 1;
    assert!((199..=201).contains(&rows), "{rows} rows between 10 and 30 s");
    // An existing session is never overwritten.
    let (code, _, err) = run_in(d, &["import", &bag, "--out", "s"]);
    assert_ne!(code, 0, "{err}");
}

/// Every sample file cut short or with bytes overwritten: an error naming the byte offset
/// (or sqlite's complaint), or the samples before the damage with a warning; never a panic.
#[test]
fn damaged_logs_give_an_error_or_a_warning_never_a_panic() {
    let files = [
        "ulog/px4_auav_x21_sensor_combined.ulg",
        "ulog/px4_cubeorange_three_imus.ulg",
        "dataflash/arducopter_imu_imu2_50s.bin",
        "dataflash/arducopter_4.6.2_truncated_80k.bin",
        "rosbag1/phidgets_imu_upside_down.bag",
        "rosbag1/imu_static_1.bag",
        "rosbag2/vn100_emulator_40hz/rosbag2_2026_03_10-02_31_31_0.db3",
    ];
    let dir = tempfile::tempdir().unwrap_or_else(|e| panic!("{e}"));
    let mut outcomes = (0, 0, 0);
    for rel in files {
        let Some(path) = shared(rel) else { continue };
        let bytes = std::fs::read(&path).unwrap_or_else(|e| panic!("{e}"));
        let n = bytes.len();
        let mut variants: Vec<(String, Vec<u8>)> = [n / 3, 2 * n / 3, n - 1, n - 7]
            .iter()
            .map(|&cut| (format!("cut at {cut}"), bytes[..cut].to_vec()))
            .collect();
        for at in [2 * n / 5, 3 * n / 4] {
            let mut b = bytes.clone();
            for x in &mut b[at..(at + 64).min(n)] {
                *x ^= 0xA5;
            }
            variants.push((format!("64 bytes overwritten at {at}"), b));
        }
        for (what, b) in variants {
            let name = Path::new(rel).file_name().unwrap_or_default();
            let f = dir.path().join(name);
            std::fs::write(&f, &b).unwrap_or_else(|e| panic!("{e}"));
            match list(&f, &ReadOptions::default()) {
                Ok((c, _)) => {
                    outcomes.0 += 1;
                    if what.starts_with("cut") && !rel.ends_with(".db3") && !c.warnings.is_empty() {
                        outcomes.2 += 1;
                        assert!(c.warnings.iter().any(|w| w.contains("byte")), "{rel} {what}: {:?}", c.warnings);
                    }
                }
                Err(e) => {
                    outcomes.1 += 1;
                    let m = e.to_string();
                    assert!(m.contains("byte") || m.contains("sqlite"), "{rel} {what}: {m}");
                }
            }
        }
    }
    eprintln!("damaged files: {} read (of them {} cut with a warning), {} refused", outcomes.0, outcomes.2, outcomes.1);
}

/// A number as YAML 1.1 (PyYAML: Kalibr, allan_variance_ros) resolves a float: digits, a
/// point, optional signed exponent.
fn yaml11_float(s: &str) -> Option<f64> {
    let (mant, exp) = match s.split_once(['e', 'E']) {
        Some((m, e)) => (m, Some(e)),
        None => (s, None),
    };
    let mant_ok =
        mant.contains('.') && mant.trim_start_matches(['-', '+']).chars().all(|c| c.is_ascii_digit() || c == '.');
    let exp_ok =
        exp.is_none_or(|e| (e.starts_with('-') || e.starts_with('+')) && e[1..].chars().all(|c| c.is_ascii_digit()));
    (mant_ok && exp_ok).then(|| s.parse().ok()).flatten()
}

fn value_of(text: &str, key: &str) -> f64 {
    let line =
        text.lines().find(|l| l.trim_start().starts_with(key)).unwrap_or_else(|| panic!("{key} missing:\n{text}"));
    let raw = line.trim_start()[key.len()..].trim_start_matches(':').split_whitespace().next().unwrap_or_default();
    yaml11_float(raw).unwrap_or_else(|| panic!("{key}: '{raw}' is not a YAML 1.1 float"))
}

/// A bag at rest → `noise` → the files Kalibr, OpenVINS, VINS-Fusion and ORB-SLAM3 read,
/// each with the recording's white-noise readings (worst axis, SI) and its rate.
#[test]
fn a_bag_at_rest_goes_out_to_every_estimators_noise_file() {
    let Some(bag) = shared("rosbag1/imu_static_1.bag") else { return };
    let dir = tempfile::tempdir().unwrap_or_else(|e| panic!("{e}"));
    let d = dir.path();
    run_ok(d, &["import", &bag.to_string_lossy(), "--out", "s"]);
    let json = run_ok(d, &["noise", "s/session.json", "--json"]);
    let r: crosscal::noise::NoiseReport = serde_json::from_str(&json).unwrap_or_else(|e| panic!("{e}"));
    let worst = |s: crosscal::units::SensorKind| {
        r.channels.iter().filter(|c| c.sensor() == s).filter_map(|c| c.white()).fold(0.0, f64::max)
    };
    let (gn, an) = (worst(crosscal::units::SensorKind::Gyro), worst(crosscal::units::SensorKind::Accel));
    // The README's bag: ~0.05 °/s/√Hz gyro white noise at 10 Hz.
    assert!(gn > 1e-4 && gn < 1e-2 && an > 1e-3 && an < 1.0, "gyro {gn} rad/s/√Hz, accel {an} m/s²/√Hz");
    for (to, file, gkey, akey) in [
        ("kalibr", "imu.yaml", "gyroscope_noise_density", "accelerometer_noise_density"),
        ("openvins", "kalibr_imu_chain.yaml", "gyroscope_noise_density", "accelerometer_noise_density"),
        ("vins-fusion", "vins.yaml", "gyr_n", "acc_n"),
        ("orb-slam3", "orb.yaml", "IMU.NoiseGyro", "IMU.NoiseAcc"),
    ] {
        let (code, _, err) = run_in(d, &["noise", "s/session.json", "--save", file, "--to", to]);
        assert_eq!(code, 0, "{to}: {err}");
        let text = std::fs::read_to_string(d.join(file)).unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(value_of(&text, gkey).to_bits(), gn.to_bits(), "{to} {gkey}:\n{text}");
        assert_eq!(value_of(&text, akey).to_bits(), an.to_bits(), "{to} {akey}");
        if to == "kalibr" || to == "openvins" {
            assert!((value_of(&text, "update_rate") - 10.0).abs() < 0.01, "{to} update_rate");
        }
        if to == "kalibr" {
            // PyYAML (Kalibr's reader), where installed, reads every number as a number.
            let check = "import sys,yaml; d=yaml.safe_load(open(sys.argv[1]))['imu0']; \
                         assert all(isinstance(d[k], float) for k in ['gyroscope_noise_density','accelerometer_noise_density','update_rate']), d; \
                         assert all(isinstance(x, float) for r in d['gyroscope_M'] for x in r), d['gyroscope_M']";
            match std::process::Command::new("python3").args(["-c", "import yaml"]).status() {
                Ok(s) if s.success() => {
                    let ok = std::process::Command::new("python3").args(["-c", check]).arg(d.join(file)).status();
                    assert!(ok.is_ok_and(|s| s.success()), "PyYAML does not read {file} as numbers:\n{text}");
                }
                _ => eprintln!("skipping the PyYAML check: python3 with yaml is absent"),
            }
        }
    }
}

/// A session whose manifest says the autopilot had calibrated the values: the fit says it
/// calibrates on top of that calibration, and the profile keeps the note.
#[test]
fn a_fit_on_autopilot_calibrated_data_says_so() {
    let dir = tempfile::tempdir().unwrap_or_else(|e| panic!("{e}"));
    let d = dir.path();
    run_ok(d, &["simulate", "-o", "s", "--duration", "5"]);
    let path = d.join("s/session.json");
    let mut m: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&path).unwrap_or_default()).unwrap_or_else(|e| panic!("{e}"));
    m["source"] = serde_json::json!({"format": "PX4 ULog", "file": "f.ulg", "stream": "sensor_combined", "frame": "FRD",
        "start_ns": 0, "applied_calibration": {"CAL_ACC0_XOFF": 0.125, "CAL_GYRO0_XOFF": -0.01}, "notes": []});
    std::fs::write(&path, m.to_string()).unwrap_or_else(|e| panic!("{e}"));
    let (code, out, err) = run_in(d, &["fit", "s/session.json", "--out", "store"]);
    assert_eq!(code, 0, "{out}{err}");
    let all = format!("{out}{err}");
    assert!(all.contains("calibrated by the autopilot") && all.contains("CAL_ACC0_XOFF=0.125"), "{all}");
    let (_, p) = crate::common::only_profile(&d.join("store"));
    assert!(p.notes.iter().any(|n| n.contains("calibrated by the autopilot")), "{:?}", p.notes);
}
