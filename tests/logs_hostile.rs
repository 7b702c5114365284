//! Issue 38: corrupt logs and bags are refused piece by piece, said with byte offsets and
//! counted, never read shifted and never lost in silence. The real samples in
//! `../shared/data/formats` are mutated in a temporary copy (skipped with a message when
//! absent); the generated files of `tests/formats_gen.rs` cover the same cases everywhere.

use crate::formats_gen::{cdr_imu, ros1_bag_n, truth};
use crosscal::session::logs::{list, read, Contents, LogSample, ReadOptions};
use std::path::{Path, PathBuf};

fn formats() -> Option<PathBuf> {
    let p = Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/data/formats");
    if p.is_dir() {
        Some(p)
    } else {
        eprintln!("skipped: ../shared/data/formats is not beside this checkout");
        None
    }
}

/// Every sample of every stream, and what the pass said.
fn samples(path: &Path) -> (Vec<(usize, LogSample)>, Contents) {
    let mut got = Vec::new();
    let c = read(path, &ReadOptions::default(), None, &mut |i, s| {
        got.push((i, *s));
        Ok(())
    })
    .unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    (got, c)
}

/// A copy of `bytes` in `dir` named `name`, with `edit` applied.
fn mutated(dir: &Path, name: &str, bytes: &[u8], edit: impl FnOnce(&mut Vec<u8>)) -> PathBuf {
    let mut b = bytes.to_vec();
    edit(&mut b);
    let p = dir.join(name);
    std::fs::write(&p, b).unwrap_or_else(|e| panic!("{e}"));
    p
}

fn put_u32(b: &mut [u8], at: usize, v: u32) {
    b[at..at + 4].copy_from_slice(&v.to_le_bytes());
}

/// A corrupt frame_id length in a ROS 1 message: that message is refused (with its offset),
/// every other one reads exactly as in the intact bag (it used to shift every field).
#[test]
fn a_corrupt_string_length_refuses_the_message_never_shifts_it() {
    let dir = tempfile::tempdir().unwrap_or_else(|e| panic!("{e}"));
    // Generated: uncompressed chunk, message 5's frame_id length (after seq, sec, nsec).
    let bag = ros1_bag_n(&["none"], 50);
    let first = ros1_imu_offset(&bag, 5);
    let intact = mutated(dir.path(), "intact.bag", &bag, |_| {});
    let (want, _) = samples(&intact);
    for len in [0u32, 1, 2, 4, 100] {
        let p = mutated(dir.path(), "m.bag", &bag, |b| put_u32(b, first + 12, len));
        let (got, c) = samples(&p);
        let mut expect = want.clone();
        expect.remove(5);
        assert_eq!(got, expect, "frame_id length {len}");
        assert!(c.warnings.iter().any(|w| w.contains("byte ") && w.contains("dropped")), "{:?}", c.warnings);
    }
    let Some(f) = formats() else { return };
    let real = std::fs::read(f.join("rosbag1/imu_static_1.bag")).unwrap_or_else(|e| panic!("{e}"));
    let intact = mutated(dir.path(), "real.bag", &real, |_| {});
    let (want, _) = samples(&intact);
    assert_eq!(want.len(), 1071);
    for len in [0u32, 3] {
        let p = mutated(dir.path(), "real-m.bag", &real, |b| put_u32(b, 14310, len));
        let (got, c) = samples(&p);
        assert_eq!(got.len(), 1070, "length {len}");
        assert_eq!(&got[..], &want[1..], "length {len}: the other messages read as intact");
        assert!(c.warnings.iter().any(|w| w.contains("refused") && w.contains("byte")), "{:?}", c.warnings);
    }
}

/// The byte offset of message `k`'s data in a generated bag (its `seq` field).
fn ros1_imu_offset(bag: &[u8], k: u32) -> usize {
    // Each message starts with seq = k, then the stamp of truth(k).
    let (t, _, _) = truth(k as usize);
    let mut pat = k.to_le_bytes().to_vec();
    pat.extend_from_slice(&((t / 1_000_000_000) as u32).to_le_bytes());
    bag.windows(8).position(|w| w == pat.as_slice()).unwrap_or_else(|| panic!("message {k} not found"))
}

/// The same in ROS 2 (CDR in a sqlite3 bag): the message is refused, the rest kept.
#[test]
fn a_corrupt_cdr_string_length_refuses_the_message() {
    let dir = tempfile::tempdir().unwrap_or_else(|e| panic!("{e}"));
    let db = dir.path().join("bag.db3");
    let conn = rusqlite::Connection::open(&db).unwrap_or_else(|e| panic!("{e}"));
    conn.execute_batch(
        "CREATE TABLE topics(id INTEGER PRIMARY KEY, name TEXT, type TEXT, serialization_format TEXT, offered_qos_profiles TEXT);
         CREATE TABLE messages(id INTEGER PRIMARY KEY, topic_id INTEGER, timestamp INTEGER, data BLOB);
         INSERT INTO topics VALUES (1, '/imu', 'sensor_msgs/msg/Imu', 'cdr', '');",
    )
    .unwrap_or_else(|e| panic!("{e}"));
    for i in 0..40 {
        let mut m = cdr_imu(i);
        if i == 7 {
            put_u32(&mut m, 12, 1);
        }
        if i == 9 {
            put_u32(&mut m, 12, 17);
        }
        conn.execute(
            "INSERT INTO messages(topic_id, timestamp, data) VALUES (1, ?1, ?2)",
            rusqlite::params![truth(i).0, m],
        )
        .unwrap_or_else(|e| panic!("{e}"));
    }
    drop(conn);
    let (got, c) = samples(&db);
    let times: Vec<i64> = got.iter().map(|(_, s)| s.t_ns).collect();
    let want: Vec<i64> = (0..40).filter(|i| ![7, 9].contains(i)).map(|i| truth(i).0).collect();
    assert_eq!(times, want);
    for (_, s) in &got {
        let i = (0..40).find(|&i| truth(i).0 == s.t_ns).unwrap_or(0);
        assert_eq!(s.gyro_rad_s.map(f64::to_bits), truth(i).1.map(f64::to_bits), "sample {i} read shifted");
    }
    assert_eq!(c.refused, 2, "{:?}", c.warnings);
    assert!(c.warnings.iter().filter(|w| w.contains("message id")).count() == 2, "{:?}", c.warnings);
}

/// One outlying stamp (ROS 1 header.stamp.sec + 100 000) costs one sample, said, not the
/// whole stream; `--list` spans stay sane.
#[test]
fn one_bad_stamp_costs_one_sample_not_the_stream() {
    let dir = tempfile::tempdir().unwrap_or_else(|e| panic!("{e}"));
    let bag = ros1_bag_n(&["none"], 200);
    for (k, delta) in [(0u32, 100_000i64), (1, 100_000), (100, 100_000), (100, -100_000), (199, 100_000), (0, -100_000)]
    {
        let at = ros1_imu_offset(&bag, k);
        let p = mutated(dir.path(), "m.bag", &bag, |b| {
            let sec = u32::from_le_bytes([b[at + 4], b[at + 5], b[at + 6], b[at + 7]]);
            put_u32(b, at + 4, (i64::from(sec) + delta) as u32);
        });
        let (got, c) = samples(&p);
        assert_eq!(got.len(), 199, "message {k} {delta:+}: {:?}", c.warnings);
        assert!(c.warnings.iter().any(|w| w.contains("outlying time stamp")), "{:?}", c.warnings);
        let (_, stats) = list(&p, &ReadOptions::default()).unwrap_or_else(|e| panic!("{e}"));
        assert!((stats[0].span_s() - 199.0 * 0.005).abs() < 0.006, "span {}", stats[0].span_s());
    }
    let Some(f) = formats() else { return };
    let real = std::fs::read(f.join("rosbag1/imu_static_1.bag")).unwrap_or_else(|e| panic!("{e}"));
    // The first message's stamp: sec at 14310 - 8 (after seq).
    let p = mutated(dir.path(), "real.bag", &real, |b| {
        let at = 14310 - 8;
        let sec = u32::from_le_bytes([b[at], b[at + 1], b[at + 2], b[at + 3]]);
        put_u32(b, at, sec + 100_000);
    });
    let (_, stats) = list(&p, &ReadOptions::default()).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(stats[0].samples, 1070);
    assert!(stats[0].span_s() > 100.0 && stats[0].span_s() < 110.0, "span {}", stats[0].span_s());
    // ROS 2: one row's bag time (the vn100 bags' stamps) moved by a day.
    for bag in ["vn100_emulator_40hz", "vn100_stationary_1hz"] {
        let src = f.join("rosbag2").join(bag);
        let copy = dir.path().join(bag);
        std::fs::create_dir_all(&copy).unwrap_or_else(|e| panic!("{e}"));
        for e in std::fs::read_dir(&src).unwrap_or_else(|e| panic!("{e}")).flatten() {
            std::fs::copy(e.path(), copy.join(e.file_name())).unwrap_or_else(|e| panic!("{e}"));
        }
        let (before, _) =
            list(&copy, &ReadOptions::default()).map(|(c, s)| (s[0].samples, c)).unwrap_or_else(|e| panic!("{e}"));
        let db = std::fs::read_dir(&copy)
            .unwrap_or_else(|e| panic!("{e}"))
            .flatten()
            .map(|e| e.path())
            .find(|p| p.extension().is_some_and(|x| x == "db3"))
            .unwrap_or_else(|| panic!("no db3"));
        let conn = rusqlite::Connection::open(&db).unwrap_or_else(|e| panic!("{e}"));
        conn.execute("UPDATE messages SET timestamp = timestamp - 86400000000000 WHERE id = (SELECT id FROM messages ORDER BY id LIMIT 1 OFFSET 100)", [])
            .unwrap_or_else(|e| panic!("{e}"));
        drop(conn);
        let (c, stats) = list(&copy, &ReadOptions::default()).unwrap_or_else(|e| panic!("{e}"));
        assert!(stats[0].samples + 1 >= before, "{bag}: {} of {before} kept: {:?}", stats[0].samples, c.warnings);
        assert!(stats[0].samples == before || !c.warnings.is_empty(), "{bag}: a silent loss");
    }
}

/// ULog: a corrupt message size is said with its byte offset and the samples lost counted
/// (it used to lose 302 samples, or every stream, without a word).
#[test]
fn ulog_corruption_is_said_with_offsets_and_counted() {
    let Some(f) = formats() else { return };
    let dir = tempfile::tempdir().unwrap_or_else(|e| panic!("{e}"));
    let real = std::fs::read(f.join("ulog/px4_cubeorange_three_imus.ulg")).unwrap_or_else(|e| panic!("{e}"));
    let intact = mutated(dir.path(), "intact.ulg", &real, |_| {});
    let (c0, s0) = list(&intact, &ReadOptions::default()).unwrap_or_else(|e| panic!("{e}"));
    let n0: u64 = s0.iter().map(|s| s.samples).sum();
    assert!(c0.warnings.iter().all(|w| !w.contains("corrupt")), "{:?}", c0.warnings);
    for (at, value) in [(79157usize, 0u16), (63276, 65535), (52446, 32768)] {
        let p = mutated(dir.path(), "m.ulg", &real, |b| b[at..at + 2].copy_from_slice(&value.to_le_bytes()));
        let (c, s) = list(&p, &ReadOptions::default()).unwrap_or_else(|e| panic!("{e}"));
        let n: u64 = s.iter().map(|s| s.samples).sum();
        assert!(!c.streams.is_empty(), "u16 {value} at {at}: no stream left");
        assert!(n + 10 >= n0, "u16 {value} at {at}: {n} of {n0} samples");
        assert!(
            c.warnings.iter().any(|w| w.contains(&format!("byte {at}")) && w.contains("lost")),
            "u16 {value} at {at}: {:?}",
            c.warnings
        );
    }
}

/// MCAP: a chunk whose uncompressed_size is zeroed is said, with the messages it held
/// counted from its index; huge lengths neither panic nor allocate.
#[test]
fn mcap_corruption_is_said_and_counted_and_huge_lengths_are_safe() {
    let dir = tempfile::tempdir().unwrap_or_else(|e| panic!("{e}"));
    let bytes = std::fs::read(Path::new(env!("CARGO_MANIFEST_DIR")).join("fuzz/corpus/logs/seed.mcap"))
        .unwrap_or_else(|e| panic!("{e}"));
    let intact = mutated(dir.path(), "intact.mcap", &bytes, |_| {});
    let (want, _) = samples(&intact);
    // The first chunk record: opcode 0x06, then its length, start, end, uncompressed_size.
    let mut chunk = 8;
    while bytes[chunk] != 0x06 {
        let len = u64::from_le_bytes(bytes[chunk + 1..chunk + 9].try_into().unwrap_or([0; 8]));
        chunk += 9 + len as usize;
    }
    let p = mutated(dir.path(), "m.mcap", &bytes, |b| b[chunk + 25..chunk + 33].copy_from_slice(&0u64.to_le_bytes()));
    let (got, c) = samples(&p);
    assert!(got.len() < want.len());
    let lost = (want.len() - got.len()).to_string();
    assert!(c.warnings.iter().any(|w| w.contains(&format!("byte {chunk}"))), "{:?}", c.warnings);
    assert!(c.warnings.iter().any(|w| w.contains(&format!("{lost} messages lost"))), "{lost}: {:?}", c.warnings);
    for (off, value) in [(1usize, i64::MAX as u64), (1, u64::MAX), (1, 1 << 40), (25, 1 << 40), (25, u64::MAX)] {
        let p = mutated(dir.path(), "h.mcap", &bytes, |b| {
            b[chunk + off..chunk + off + 8].copy_from_slice(&value.to_le_bytes())
        });
        let r =
            std::panic::catch_unwind(|| list(&p, &ReadOptions::default()).map(|(c, s)| (c.warnings.len(), s.len())));
        match r {
            Ok(Ok((w, _))) => assert!(w > 0, "length {value:#x} at {off}: no warning"),
            Ok(Err(_)) => {}
            Err(_) => panic!("length {value:#x} at +{off}: panic"),
        }
    }
}

/// Issue 38 item 12: a stream too short for `noise` is imported with the reason (its rate and
/// span) and the way out, and nothing suggests a command that will fail.
#[test]
fn a_short_stream_suggests_only_what_works() {
    let Some(f) = formats() else { return };
    let dir = tempfile::tempdir().unwrap_or_else(|e| panic!("{e}"));
    let log = f.join("ulog/px4_cubeorange_three_imus.ulg");
    let log = log.to_string_lossy();
    let out = crate::common::run_ok(dir.path(), &["import", &log, "--imu", "1", "--out", "short"]);
    assert!(out.contains("too few for crosscal noise, which needs at least 7"), "{out}");
    assert!(out.contains("1.000 Hz over 5.00 s"), "{out}");
    assert!(!out.contains("ready for") && !out.contains("next: crosscal noise"), "{out}");
    // The session folder itself is a session argument (as `simulate --out` writes it).
    crate::common::run_ok(dir.path(), &["simulate", "--out", "sim", "--duration", "4"]);
    let fit = crate::common::run_ok(dir.path(), &["fit", "sim", "--out", "store"]);
    assert!(fit.contains("profile written"), "{fit}");
}

/// Issue 38 item 12: a recording separated by semicolons or tabs is named as such, with the
/// command that reads it, instead of "column 't' is absent".
#[test]
fn a_semicolon_or_tab_recording_names_its_delimiter_and_the_importer() {
    let dir = tempfile::tempdir().unwrap_or_else(|e| panic!("{e}"));
    crate::common::run_ok(dir.path(), &["simulate", "--out", "s", "--duration", "4"]);
    for (sep, name) in [(";", "semicolons (';')"), ("\t", "tabs")] {
        let csv = dir.path().join("s/cone+10.csv");
        let text = std::fs::read_to_string(&csv).unwrap_or_else(|e| panic!("{e}"));
        std::fs::write(&csv, text.replace([',', ';', '\t'], sep)).unwrap_or_else(|e| panic!("{e}"));
        let (code, out, err) = crate::common::run_in(dir.path(), &["fit", "s", "--dry-run"]);
        assert_eq!(code, 5, "{out}{err}");
        assert!(err.contains("s/cone+10.csv:1:"), "{err}");
        assert!(err.contains(&format!("separated by {name}")), "{err}");
        assert!(err.contains("crosscal import text s/cone+10.csv"), "{err}");
    }
}
