//! Reading logs and bags (`cargo bench --bench formats`): `crosscal import` against the
//! Python readers users have (rosbags, pyulog, pymavlink) on the same generated files, in
//! one run. Prints a table of wall time and peak resident memory; docs/performance.md
//! ("Reading logs and bags") holds the latest one and how it was made.
//!
//! Files, written in a temporary folder by `formats/writers.rs`: a ROS 1 bag of
//! `CROSSCAL_BENCH_MB` MB (default 1000) with uncompressed 768 KiB chunks, a bz2 bag of a
//! twentieth of that, a PX4 ULog and an ArduPilot DataFlash log of three tenths.
//! `CROSSCAL_BENCH_DIR` chooses where they go (default: the system's temporary folder),
//! `CROSSCAL_BENCH_KEEP=1` keeps them there (to read them with other tools).
//! A filter argument runs only the files whose label contains it
//! (`cargo bench --bench formats -- ulog`).
//!
//! Each reader runs in its own child process, one after another: wall time from spawn to
//! exit, peak RSS from the child's /proc/<pid>/status VmHWM polled every 5 ms (the kernel's
//! high-water mark of the child's own memory since its exec; a peak reached in the last
//! 5 ms of a run would be missed). `getrusage(RUSAGE_CHILDREN).ru_maxrss` was not used: it
//! also counts the memory the child had before its exec, a copy of its parent's (a Python
//! wrapper's 13.5 MiB for `/bin/true`).

#[path = "formats/writers.rs"]
mod writers;

use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Instant;

/// One child's run: wall time, peak RSS, CPU time (user + system, as last polled) and its output.
struct Measured {
    secs: f64,
    peak_mb: f64,
    cpu_secs: f64,
    stdout: String,
}

/// The kernel's clock ticks per second for /proc/<pid>/stat (USER_HZ, 100 on Linux).
const TICKS: f64 = 100.0;

/// Runs `program args`, polling the child's /proc/<pid>/status VmHWM (the high-water mark
/// of its resident set since its exec) and /proc/<pid>/stat CPU times every 5 ms until it
/// exits. The child's output is read by a thread so a full pipe cannot stall it.
fn measure(program: &Path, args: &[&std::ffi::OsStr]) -> Result<Measured, String> {
    let t0 = Instant::now();
    let mut child = Command::new(program)
        .args(args)
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .map_err(|e| format!("{}: {e}", program.display()))?;
    let pipe = |r: Option<Box<dyn std::io::Read + Send>>| {
        std::thread::spawn(move || {
            let mut text = String::new();
            if let Some(mut r) = r {
                let _ = r.read_to_string(&mut text);
            }
            text
        })
    };
    let out = pipe(child.stdout.take().map(|r| Box::new(r) as _));
    let err = pipe(child.stderr.take().map(|r| Box::new(r) as _));
    let proc = format!("/proc/{}", child.id());
    let (mut peak_kb, mut cpu_ticks) = (0.0f64, 0.0f64);
    let code = loop {
        if let Ok(text) = std::fs::read_to_string(format!("{proc}/status")) {
            if let Some(v) = text.lines().find_map(|l| l.strip_prefix("VmHWM:")) {
                peak_kb = peak_kb.max(v.trim().trim_end_matches("kB").trim().parse().unwrap_or(0.0));
            }
        }
        if let Ok(stat) = std::fs::read_to_string(format!("{proc}/stat")) {
            // Fields after the command's closing parenthesis: utime and stime are the 12th and 13th.
            let rest = stat.rsplit_once(')').map_or("", |(_, r)| r);
            let f: Vec<f64> = rest.split_whitespace().skip(11).take(2).filter_map(|x| x.parse().ok()).collect();
            if f.len() == 2 {
                cpu_ticks = f[0] + f[1];
            }
        }
        if let Some(st) = child.try_wait().map_err(|e| e.to_string())? {
            break st;
        }
        std::thread::sleep(std::time::Duration::from_millis(5));
    };
    let secs = t0.elapsed().as_secs_f64();
    let stdout = out.join().unwrap_or_default();
    let stderr = err.join().unwrap_or_default();
    if !code.success() {
        return Err(format!("{code}: {}", stderr.trim().lines().last().unwrap_or("")));
    }
    Ok(Measured { secs, peak_mb: peak_kb / 1024.0, cpu_secs: cpu_ticks / TICKS, stdout })
}

/// A generated file and the peer that reads it.
struct Case {
    label: String,
    path: PathBuf,
    samples: u64,
    /// The peer's name, the `read_logs.py` mode and the modules it imports.
    peer: (&'static str, &'static str, &'static str),
}

/// Why a peer cannot run (its Python module missing), if it cannot.
fn peer_missing(modules: &str) -> Option<String> {
    let o = match Command::new("python3").args(["-c", &format!("import {modules}")]).output() {
        Ok(o) => o,
        Err(e) => return Some(format!("python3 not found ({e})")),
    };
    (!o.status.success()).then(|| {
        let err = String::from_utf8_lossy(&o.stderr);
        err.trim().lines().last().unwrap_or("import failed").to_string()
    })
}

/// Writes the bench's files into `dir` (the bag sized `mb` MB), keeping those `only` names.
fn generate(dir: &Path, mb: f64, only: Option<&str>) -> Vec<Case> {
    let bytes = |f: f64| (mb * f * 1e6) as u64;
    let wanted = |label: &str| only.is_none_or(|o| label.contains(o));
    let mut cases = Vec::new();
    let mut add = |label: &str, file: &str, peer, write: &dyn Fn(&Path) -> u64| {
        if !wanted(label) {
            return;
        }
        let path = dir.join(file);
        let t0 = Instant::now();
        let samples = write(&path);
        let size = std::fs::metadata(&path).map_or(0, |m| m.len());
        println!(
            "wrote {file}: {:.1} MB, {samples} IMU samples, {:.1} s",
            size as f64 / 1e6,
            t0.elapsed().as_secs_f64()
        );
        cases.push(Case { label: label.into(), path, samples, peer });
    };
    let rosbags = ("rosbags", "rosbag1", "rosbags.rosbag1, rosbags.typesys");
    add("ROS 1 bag, uncompressed chunks", "imu.bag", rosbags, &|p| {
        writers::write_bag(p, bytes(1.0), writers::Chunks::Plain, 1)
    });
    add("ROS 1 bag, bz2 chunks", "imu_bz2.bag", rosbags, &|p| {
        writers::write_bag(p, bytes(0.05), writers::Chunks::Bz2, 2)
    });
    add("PX4 ULog, sensor_combined", "imu.ulg", ("pyulog", "ulog", "pyulog"), &|p| {
        writers::write_ulog(p, bytes(0.3), 3)
    });
    add("ArduPilot DataFlash, IMU", "imu.bin", ("pymavlink", "dataflash", "pymavlink.DFReader"), &|p| {
        writers::write_dataflash(p, bytes(0.3), 4)
    });
    cases
}

/// The number in `(N samples)` of crosscal's last line, or in a peer's `samples N`.
fn samples_in(stdout: &str) -> Option<u64> {
    if let Some(rest) = stdout.lines().find_map(|l| l.strip_prefix("samples ")) {
        return rest.split_whitespace().next()?.parse().ok();
    }
    let l = stdout.lines().find(|l| l.starts_with("wrote "))?;
    let (_, after) = l.rsplit_once('(')?;
    after.split_whitespace().next()?.parse().ok()
}

/// A table row: crosscal's and the peer's measurements of one file.
fn row(case: &Case, dir: &Path) -> String {
    let size = std::fs::metadata(&case.path).map_or(0, |m| m.len()) as f64 / 1e6;
    let out = dir.join("session");
    let _ = std::fs::remove_dir_all(&out);
    let args = [case.path.as_os_str(), "--out".as_ref(), out.as_os_str(), "--kind".as_ref(), "static".as_ref()];
    let mut import = vec!["import".as_ref()];
    import.extend_from_slice(&args);
    let c = measure(Path::new(env!("CARGO_BIN_EXE_crosscal")), &import).expect("crosscal import");
    let csv_mb = std::fs::metadata(out.join("recording.csv")).map_or(0.0, |m| m.len() as f64 / 1e6);
    let _ = std::fs::remove_dir_all(&out);
    let got = samples_in(&c.stdout);
    assert_eq!(got, Some(case.samples), "crosscal imported another number of samples than were written");
    println!(
        "  crosscal import: {:.2} s, {:.1} MiB peak, CPU ≥ {:.2} s (last poll); {} samples, recording.csv {csv_mb:.0} MB",
        c.secs, c.peak_mb, c.cpu_secs, case.samples
    );
    let (name, mode, modules) = case.peer;
    let cross = format!("{:.2} | {:.1}", c.secs, c.peak_mb);
    let head = format!("| {} | {size:.1} MB, {} samples | {cross}", case.label, case.samples);
    if let Some(why) = peer_missing(modules) {
        println!("  {name}: skipped ({why})");
        return format!("{head} | {name}: skipped ({why}) | – | – | – |");
    }
    let script = Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/benches/peer/read_logs.py"));
    let p = measure(Path::new("python3"), &[script.as_os_str(), mode.as_ref(), case.path.as_os_str()]);
    match p {
        Ok(p) => {
            let n = samples_in(&p.stdout);
            println!(
                "  {name}: {:.2} s, {:.1} MiB peak, CPU ≥ {:.2} s (last poll); {} samples",
                p.secs,
                p.peak_mb,
                p.cpu_secs,
                n.map_or("?".into(), |n| n.to_string())
            );
            assert_eq!(n, Some(case.samples), "{name} read another number of samples than were written");
            format!("{head} | {name} | {:.2} | {:.1} | {:.1}× |", p.secs, p.peak_mb, p.secs / c.secs)
        }
        Err(e) => {
            println!("  {name}: failed ({e})");
            format!("{head} | {name}: failed ({e}) | – | – | – |")
        }
    }
}

fn main() {
    let only = std::env::args().skip(1).find(|a| !a.starts_with('-'));
    let mb: f64 = std::env::var("CROSSCAL_BENCH_MB").ok().and_then(|v| v.parse().ok()).unwrap_or(1000.0);
    let tmp = match std::env::var_os("CROSSCAL_BENCH_DIR") {
        Some(d) => tempfile::tempdir_in(d),
        None => tempfile::tempdir(),
    }
    .expect("temp dir");
    let cases = generate(tmp.path(), mb, only.as_deref());
    println!(
        "each reader in its own child process, one after another (wall time; peak RSS = VmHWM of \
         /proc/<pid>/status, polled every 5 ms); the files are in the page cache"
    );
    let mut rows = Vec::new();
    for case in &cases {
        println!("{}:", case.label);
        rows.push(row(case, tmp.path()));
    }
    println!();
    println!("| file | size | crosscal s | crosscal peak MiB | peer | peer s | peer peak MiB | peer / crosscal time |");
    println!("|---|---|---|---|---|---|---|---|");
    for r in &rows {
        println!("{r}");
    }
    if std::env::var_os("CROSSCAL_BENCH_KEEP").is_some() {
        println!("files kept in {}", tmp.keep().display());
    }
    println!();
    println!(
        "crosscal does more than the peers: `import --kind static` reads the file twice (a listing pass, then \
         the chosen stream) and writes recording.csv and session.json; the peers only decode every IMU message \
         to numbers."
    );
}
