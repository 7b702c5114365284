//! A seeded mutation fuzz of every log reader (ULog, DataFlash, ROS 1, ROS 2 sqlite3,
//! MCAP), in process, from the committed corpus of generated seed files in
//! `fuzz/corpus/logs/` (written by [`write_corpus`], never the shared real recordings).
//!
//! Each seed is read intact, then [`MUTANTS`] mutants of it (byte flips, random bytes,
//! truncations, inserted and deleted bytes, and length fields set to huge or small values)
//! are read by `crosscal::session::logs::list`, and counted:
//!
//! - **crash**: a panic (caught), or — not catchable — an abort, which fails the test;
//! - **hang**: a mutant that takes longer than [`HANG_S`] (a watchdog aborts the process);
//! - **silent loss**: read without error, fewer samples than the intact seed, and no warning
//!   the intact seed does not print (the ULog seed has a logged dropout). A ULog or DataFlash
//!   cut exactly between two records is a valid shorter log (neither format has an end
//!   marker or an index to tell), so it is not a loss.
//!
//! All three must be 0. Decoding errors that stop the reader are fine: they say why.

use crate::formats_gen::{cdr_imu, df_fmt, mcap_imu, ros1_bag_n, truth, ulog_data, ulog_msg};
use crosscal::session::logs::{list, ReadOptions};
use rand::{Rng, SeedableRng};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::{Duration, Instant};

/// Mutants per format.
const MUTANTS: usize = 300;
/// Samples in each generated seed (small: the corpus is committed).
const SAMPLES: usize = 300;
/// A mutant read for longer than this is a hang.
const HANG_S: u64 = 20;

/// The committed corpus folder.
fn corpus_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("fuzz/corpus/logs")
}

/// Seed files by name (as committed) from the generators of `tests/formats_gen.rs`.
fn seeds(dir: &Path) -> Vec<(&'static str, Vec<u8>)> {
    let sqlite = dir.join("seed.db3");
    let _ = std::fs::remove_file(&sqlite);
    write_sqlite(&sqlite, SAMPLES);
    let db3 = std::fs::read(&sqlite).unwrap_or_else(|e| panic!("{e}"));
    vec![
        ("seed.ulg", ulog(SAMPLES)),
        ("seed.bin", dataflash(SAMPLES)),
        ("seed.bag", ros1_bag_n(&["lz4", "none", "bz2"], SAMPLES)),
        ("seed.db3", db3),
        ("seed.mcap", mcap_file(SAMPLES)),
    ]
}

/// A ULog: `sensor_combined` plus `sensor_accel`/`sensor_gyro` of one device, a parameter,
/// a dropout and a text message between the data.
fn ulog(n: usize) -> Vec<u8> {
    let mut b = b"ULog\x01\x12\x35\x01".to_vec();
    b.extend_from_slice(&0u64.to_le_bytes());
    ulog_msg(&mut b, b'B', &[0u8; 40]);
    let fmt = "sensor_combined:uint64_t timestamp;float[3] gyro_rad;uint32_t gyro_integral_dt;int32_t accelerometer_timestamp_relative;float[3] accelerometer_m_s2;uint32_t accelerometer_integral_dt;uint8_t accelerometer_clipping;uint8_t[3] _padding0;";
    ulog_msg(&mut b, b'F', fmt.as_bytes());
    ulog_msg(
        &mut b,
        b'F',
        b"sensor_gyro:uint64_t timestamp;uint64_t timestamp_sample;float x;float y;float z;float temperature;",
    );
    ulog_msg(
        &mut b,
        b'F',
        b"sensor_accel:uint64_t timestamp;uint64_t timestamp_sample;float x;float y;float z;float temperature;",
    );
    let mut p = b"\x05float CAL_ACC0_XOFF".to_vec();
    p[0] = (p.len() - 1) as u8;
    p.extend_from_slice(&0.25f32.to_le_bytes());
    ulog_msg(&mut b, b'P', &p);
    for (id, name) in [(0u16, "sensor_combined"), (1, "sensor_gyro"), (2, "sensor_accel")] {
        let mut sub = vec![0u8];
        sub.extend_from_slice(&id.to_le_bytes());
        sub.extend_from_slice(name.as_bytes());
        ulog_msg(&mut b, b'A', &sub);
    }
    for i in 0..n {
        ulog_msg(&mut b, b'D', &ulog_data(i));
        let (t, g, a) = truth(i);
        for (id, v) in [(2u16, a), (1, g)] {
            let mut d = id.to_le_bytes().to_vec();
            d.extend_from_slice(&((t / 1000) as u64).to_le_bytes());
            d.extend_from_slice(&((t / 1000) as u64).to_le_bytes());
            for x in v {
                d.extend_from_slice(&(x as f32).to_le_bytes());
            }
            d.extend_from_slice(&31.5f32.to_le_bytes());
            ulog_msg(&mut b, b'D', &d);
        }
        if i == n / 2 {
            ulog_msg(&mut b, b'O', &40u16.to_le_bytes());
            let mut l = vec![6u8];
            l.extend_from_slice(&((t / 1000) as u64).to_le_bytes());
            l.extend_from_slice(b"a log line");
            ulog_msg(&mut b, b'L', &l);
        }
    }
    b
}

/// A DataFlash log: FMT, an `IMU` with instances 0 and 1 and a `PARM`.
fn dataflash(n: usize) -> Vec<u8> {
    let mut b = Vec::new();
    df_fmt(&mut b, 128, 89, "FMT", "BBnNZ", "Type,Length,Name,Format,Columns");
    df_fmt(&mut b, 200, 40, "IMU", "QBfffffff", "TimeUS,I,GyrX,GyrY,GyrZ,AccX,AccY,AccZ,T");
    df_fmt(&mut b, 64, 31, "PARM", "QNf", "TimeUS,Name,Value");
    let mut parm = vec![0xA3, 0x95, 64];
    parm.extend_from_slice(&0u64.to_le_bytes());
    let mut name = b"INS_ACCOFFS_X".to_vec();
    name.resize(16, 0);
    parm.extend(name);
    parm.extend_from_slice(&0.125f32.to_le_bytes());
    b.extend(parm);
    for i in 0..n {
        for inst in 0..2u8 {
            let (t, g, a) = truth(i);
            let mut r = vec![0xA3, 0x95, 200];
            r.extend_from_slice(&((t / 1000) as u64).to_le_bytes());
            r.push(inst);
            for v in g.iter().chain(&a) {
                r.extend_from_slice(&(*v as f32).to_le_bytes());
            }
            r.extend_from_slice(&(30.0f32 + f32::from(inst)).to_le_bytes());
            b.extend(r);
        }
    }
    b
}

/// A ROS 2 sqlite3 bag (one `.db3`) of `n` plain `sensor_msgs/msg/Imu` and a chatter topic.
fn write_sqlite(path: &Path, n: usize) {
    let db = rusqlite::Connection::open(path).unwrap_or_else(|e| panic!("{e}"));
    db.execute_batch(
        "PRAGMA page_size = 1024;
         CREATE TABLE topics(id INTEGER PRIMARY KEY, name TEXT, type TEXT, serialization_format TEXT, offered_qos_profiles TEXT);
         CREATE TABLE messages(id INTEGER PRIMARY KEY, topic_id INTEGER, timestamp INTEGER, data BLOB);
         INSERT INTO topics VALUES (1, '/imu/data', 'sensor_msgs/msg/Imu', 'cdr', '');
         INSERT INTO topics VALUES (2, '/chatter', 'std_msgs/msg/String', 'cdr', '');",
    )
    .unwrap_or_else(|e| panic!("{e}"));
    for i in 0..n {
        let (t, _, _) = truth(i);
        db.execute(
            "INSERT INTO messages(topic_id, timestamp, data) VALUES (1, ?1, ?2)",
            rusqlite::params![t + 1000, cdr_imu(i)],
        )
        .unwrap_or_else(|e| panic!("{e}"));
        if i % 10 == 0 {
            db.execute(
                "INSERT INTO messages(topic_id, timestamp, data) VALUES (2, ?1, ?2)",
                rusqlite::params![t + 2000, vec![0u8, 1, 0, 0, 1, 0, 0, 0, 0]],
            )
            .unwrap_or_else(|e| panic!("{e}"));
        }
    }
}

/// An MCAP file (written by the `mcap` crate): lz4 chunks of 8 KiB, a `ros2msg` schema.
fn mcap_file(n: usize) -> Vec<u8> {
    let mut out = std::io::Cursor::new(Vec::new());
    mcap_imu(&mut out, n, mcap::Compression::Lz4, 8 * 1024);
    out.into_inner()
}

/// Rewrites the committed corpus: `cargo test --test main write_corpus -- --ignored`.
#[test]
#[ignore = "rewrites fuzz/corpus/logs; run by hand after changing a generator"]
fn write_corpus() {
    let dir = corpus_dir();
    std::fs::create_dir_all(&dir).unwrap_or_else(|e| panic!("{e}"));
    for (name, bytes) in seeds(&dir) {
        std::fs::write(dir.join(name), bytes).unwrap_or_else(|e| panic!("{e}"));
    }
}

/// One mutation of `b` (see the module docs), from `rng`.
fn mutate(b: &mut Vec<u8>, rng: &mut impl Rng) -> String {
    let n = b.len().max(1);
    match rng.random_range(0..6) {
        0 => {
            let k = rng.random_range(1..=4);
            for _ in 0..k {
                let i = rng.random_range(0..n).min(b.len().saturating_sub(1));
                b[i] ^= 1 << rng.random_range(0..8);
            }
            format!("{k} bit flips")
        }
        1 => {
            let i = rng.random_range(0..n).min(b.len().saturating_sub(1));
            b[i] = rng.random();
            format!("byte {i} random")
        }
        2 => {
            let i = rng.random_range(0..n);
            b.truncate(i);
            format!("truncated at {i}")
        }
        3 => {
            let i = rng.random_range(0..n);
            let k = rng.random_range(1..=16).min(b.len() - i.min(b.len()));
            b.drain(i..i + k);
            format!("{k} bytes deleted at {i}")
        }
        4 => {
            let i = rng.random_range(0..n).min(b.len());
            let k = rng.random_range(1..=16);
            for _ in 0..k {
                b.insert(i, rng.random());
            }
            format!("{k} bytes inserted at {i}")
        }
        _ => {
            // A length field: u16, u32 or u64 set to a huge or tiny value.
            let width = [2usize, 4, 8][rng.random_range(0..3)];
            let value: u64 = match rng.random_range(0..6) {
                0 => 0,
                1 => u64::MAX,
                2 => i64::MAX as u64,
                3 => 1 << 40,
                4 => 32_768,
                _ => 65_535,
            };
            let i = rng.random_range(0..n).min(b.len().saturating_sub(width));
            let bytes = value.to_le_bytes();
            for k in 0..width.min(b.len() - i) {
                b[i + k] = if width < 8 && value > u64::from(u32::MAX) { 0xFF } else { bytes[k] };
            }
            format!("{width}-byte length {value:#x} at {i}")
        }
    }
}

/// Whether `b` is `seed` cut exactly at a record boundary of a format with no end marker
/// (ULog, DataFlash): a valid shorter log that no reader can tell from a shorter recording,
/// so not a loss.
fn whole_records_of(name: &str, seed: &[u8], b: &[u8]) -> bool {
    if b.len() >= seed.len() || !seed.starts_with(b) {
        return false;
    }
    let mut pos = match name {
        "seed.ulg" => 16,
        "seed.bin" => 0,
        _ => return false,
    };
    // DataFlash record lengths by type, from the FMT records met (FMT itself is 89 bytes).
    let mut lengths = std::collections::HashMap::from([(0x80u8, 89usize)]);
    while pos < b.len() {
        let step = if name == "seed.ulg" {
            3 + usize::from(u16::from_le_bytes([seed[pos], seed[pos + 1]]))
        } else {
            let ty = seed[pos + 2];
            if ty == 0x80 {
                lengths.insert(seed[pos + 3], usize::from(seed[pos + 4]));
            }
            lengths[&ty]
        };
        pos += step;
    }
    pos == b.len()
}

/// Samples and warnings of a pass over `path` (all streams).
fn read_all(path: &Path) -> Result<(u64, Vec<String>), String> {
    list(path, &ReadOptions::default())
        .map(|(c, stats)| (stats.iter().map(|s| s.samples).sum(), c.warnings))
        .map_err(|e| e.to_string())
}

#[derive(Debug, Default)]
struct Tally {
    crashes: Vec<String>,
    silent: Vec<String>,
    errors: usize,
    warned: usize,
    /// Cuts between two records (valid shorter logs).
    cuts: usize,
    slowest_s: f64,
}

/// The fuzz (see the module docs): 0 crashes, 0 hangs, 0 silent losses over every format.
#[test]
fn mutated_logs_never_crash_hang_or_lose_samples_silently() {
    let dir = corpus_dir();
    let tmp = tempfile::tempdir().unwrap_or_else(|e| panic!("{e}"));
    // The watchdog: the start of the mutant being read; one read past HANG_S aborts.
    static STARTED_MS: AtomicU64 = AtomicU64::new(0);
    let t0 = Instant::now();
    let stop = std::sync::Arc::new(std::sync::atomic::AtomicBool::new(false));
    let watchdog = {
        let stop = stop.clone();
        std::thread::spawn(move || {
            while !stop.load(Ordering::Relaxed) {
                let s = STARTED_MS.load(Ordering::Relaxed);
                if s > 0 && t0.elapsed().as_millis() as u64 > s + HANG_S * 1000 {
                    eprintln!("log fuzz: a mutant hung for more than {HANG_S} s");
                    std::process::abort();
                }
                std::thread::sleep(Duration::from_millis(100));
            }
        })
    };
    let mut report = Vec::new();
    let mut failures: Vec<String> = Vec::new();
    for name in ["seed.ulg", "seed.bin", "seed.bag", "seed.db3", "seed.mcap"] {
        let seed = std::fs::read(dir.join(name)).unwrap_or_else(|e| panic!("{name}: {e} (run write_corpus)"));
        let ext = name.rsplit('.').next().unwrap_or("x");
        let intact = tmp.path().join(format!("intact.{ext}"));
        std::fs::write(&intact, &seed).unwrap_or_else(|e| panic!("{e}"));
        let (n0, w0) = read_all(&intact).unwrap_or_else(|e| panic!("{name}: {e}"));
        assert!(n0 > 0, "{name}: the intact seed reads no sample");
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(38);
        let mut t = Tally::default();
        for k in 0..MUTANTS {
            let mut b = seed.clone();
            let what = mutate(&mut b, &mut rng);
            let path = tmp.path().join(format!("m{k}.{ext}"));
            std::fs::write(&path, &b).unwrap_or_else(|e| panic!("{e}"));
            let start = Instant::now();
            STARTED_MS.store(t0.elapsed().as_millis() as u64 + 1, Ordering::Relaxed);
            let got = std::panic::catch_unwind(|| read_all(&path));
            STARTED_MS.store(0, Ordering::Relaxed);
            t.slowest_s = t.slowest_s.max(start.elapsed().as_secs_f64());
            match got {
                Err(_) => t.crashes.push(format!("{name} mutant {k} ({what}): panic")),
                Ok(Err(_)) => t.errors += 1,
                Ok(Ok((n, w))) => {
                    // A new warning is one the intact seed does not print (a cut can remove
                    // the seed's own warning, so counts do not compare).
                    let new = w.iter().any(|x| !w0.contains(x));
                    let cut = whole_records_of(name, &seed, &b);
                    t.cuts += usize::from(cut);
                    if n < n0 && !new && !cut {
                        // LOG_FUZZ_KEEP=DIR keeps the silent mutants to look at.
                        if let Some(keep) = std::env::var_os("LOG_FUZZ_KEEP") {
                            let _ = std::fs::copy(&path, Path::new(&keep).join(format!("m{k}.{ext}")));
                        }
                        t.silent.push(format!("{name} mutant {k} ({what}): {n} of {n0} samples, no new warning"))
                    }
                    t.warned += usize::from(new);
                }
            }
            let _ = std::fs::remove_file(&path);
        }
        report.push(format!(
            "{name}: {MUTANTS} mutants, {} crashes, {} silent losses, {} refused with an error, {} read with warnings, {} cut between records, slowest {:.3} s",
            t.crashes.len(),
            t.silent.len(),
            t.errors,
            t.warned,
            t.cuts,
            t.slowest_s
        ));
        failures.extend(t.crashes.iter().cloned());
        failures.extend(t.silent.iter().take(10).cloned());
    }
    stop.store(true, Ordering::Relaxed);
    let _ = watchdog.join();
    eprintln!("log fuzz:\n{}", report.join("\n"));
    assert!(failures.is_empty(), "{}\n{failures:#?}", report.join("\n"));
}
