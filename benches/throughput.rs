//! Throughput benchmarks (`cargo bench`): prints a table of measured rates. Speed claims in
//! the guide (docs/performance.md) come from this, never from timed tests.

use crosscal::noise::{analyse_channel, NoiseOptions};
use crosscal::simulate::noise::NoiseProcess;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use std::time::Instant;

/// The rows of the performance table (docs/performance.md): (what, measured).
type Table = Vec<(String, String)>;

/// Prints a measurement as it is made and keeps it for the table.
fn report(table: &mut Table, what: String, measured: String) {
    println!("{what} | {measured}");
    table.push((what, measured));
}

fn best_of<T>(reps: usize, mut f: impl FnMut() -> T) -> (f64, T) {
    let mut best = f64::INFINITY;
    let mut out = None;
    for _ in 0..reps {
        let t0 = Instant::now();
        let v = f();
        best = best.min(t0.elapsed().as_secs_f64());
        out = Some(v);
    }
    (best, out.expect("at least one repetition"))
}

/// Allan deviation of a 1e7-sample, six-channel static recording on one core.
fn noise(table: &mut Table) {
    let n = 10_000_000usize;
    let p = NoiseProcess { white_density: 1e-3, bias_instability: 1e-4, random_walk: 1e-6, ar1: None };
    let mut rng = ChaCha8Rng::seed_from_u64(1);
    let mut g = p.generator(0.01, n as f64 * 0.01);
    let data: Vec<f64> = (0..n).map(|_| g.next_sample(&mut rng)).collect();
    let (secs, _) = best_of(3, || {
        let mut total = 0;
        for _ in 0..6 {
            // Each channel's column is its own input buffer (the copy is part of the cost).
            let mut col = data.clone();
            let r = analyse_channel("gx", "rad/s", &mut col, 0.01, NoiseOptions::default()).expect("analysis");
            total += r.points.len();
        }
        total
    });
    report(
        table,
        "Allan deviation, 1e7 samples × 6 channels, one core".into(),
        format!("{secs:.2} s ({:.2} s per channel)", secs / 6.0),
    );
}

/// Batch calibration of 16 units with one worker and with two: the parallel speed-up.
fn batch(table: &mut Table) {
    use crosscal::app::batch::{run, unit_dirs, BatchOptions};
    use crosscal::simulate::{conic_plan, cyclic_mounts, write_session, SimConfig};
    let tmp = tempfile::tempdir().expect("temp dir");
    let lot = tmp.path().join("lot");
    for i in 0..16 {
        let mut c = SimConfig::paper();
        c.serial = format!("B-{i:02}");
        c.runs = conic_plan(&[10.0, -10.0, 20.0], &[10.0, 20.0], &cyclic_mounts(3), 12.0);
        c.sample_rate_hz = 50.0;
        c.gyro_noise_deg_s = 0.002;
        c.accel_noise_g = 2e-5;
        c.seed = i;
        write_session(&c.generate(), &lot.join(format!("u{i:02}"))).expect("write unit");
    }
    let dirs = unit_dirs(&lot).expect("units");
    let rules = crosscal::check::rules::Rules::parse(
        std::path::Path::new("bench"),
        r#"{"format":"crosscal-rules/1","rules":[{"kind":"std_error","select":"*","max":1},{"kind":"adequate"}]}"#,
    )
    .expect("rules");
    let mut times = Vec::new();
    for jobs in [1, 2] {
        let opts = BatchOptions {
            model: crosscal::model::ModelSpec::default(),
            store: tmp.path().join(format!("store{jobs}")),
            rules: rules.clone(),
            resume: false,
            jobs,
            lot: format!("bench{jobs}"),
        };
        let t0 = Instant::now();
        let r = run(&dirs, &opts, &|_| {}).expect("batch");
        assert_eq!(r.passed(), 16);
        times.push(t0.elapsed().as_secs_f64());
    }
    report(
        table,
        "`batch`, 16 units (18 runs × 12 s at 50 Hz: fit, check, diagnose), 2 workers vs 1".into(),
        format!("{:.2} s vs {:.2} s: {:.2}×", times[1], times[0], times[0] / times[1]),
    );
}

/// Runs a command, polling its peak resident set (VmHWM) until it exits: (seconds, MB).
fn measure(cmd: &mut std::process::Command) -> (f64, f64) {
    let t0 = Instant::now();
    let mut child = cmd.stdout(std::process::Stdio::null()).spawn().expect("spawn");
    let status = format!("/proc/{}/status", child.id());
    let mut peak_kb = 0.0f64;
    loop {
        if let Ok(text) = std::fs::read_to_string(&status) {
            if let Some(v) = text.lines().find_map(|l| l.strip_prefix("VmHWM:")) {
                peak_kb = peak_kb.max(v.trim().trim_end_matches("kB").trim().parse().unwrap_or(0.0));
            }
        }
        if let Ok(Some(st)) = child.try_wait() {
            assert!(st.success(), "{cmd:?} failed");
            break;
        }
        std::thread::sleep(std::time::Duration::from_millis(5));
    }
    (t0.elapsed().as_secs_f64(), peak_kb / 1024.0)
}

/// End-to-end `crosscal fit` against the pandas + numpy peer on the same 10-run sessions.
fn fit_vs_peer(table: &mut Table, sizes: &[usize]) {
    use crosscal::simulate::{conic_plan, cyclic_mounts, write_session, SimConfig};
    let peer = concat!(env!("CARGO_MANIFEST_DIR"), "/benches/peer/fit_numpy.py");
    let tmp = tempfile::tempdir().expect("temp dir");
    for &n in sizes {
        let mut c = SimConfig::paper();
        c.runs = conic_plan(&[10.0, -10.0, 20.0, -20.0, 15.0], &[10.0], &cyclic_mounts(2), n as f64 / 1000.0);
        c.gyro_noise_deg_s = 0.002;
        c.accel_noise_g = 2e-5;
        let dir = tmp.path().join(format!("s{n}"));
        let manifest = write_session(&c.generate(), &dir).expect("write session");
        let crosscal = |extra: &[&str]| {
            measure(
                std::process::Command::new(env!("CARGO_BIN_EXE_crosscal"))
                    .args(["fit", "--dry-run"])
                    .args(extra)
                    .arg(&manifest),
            )
        };
        // `fit` streams these sessions (conic runs, linear model) without being asked.
        let (tc, mc) = crosscal(&[]);
        let (tp, mp) = measure(std::process::Command::new("python3").arg(peer).arg(&manifest));
        report(
            table,
            format!("`fit` vs `benches/peer/fit_numpy.py` (pandas + numpy), 10 runs, {n:.0e} samples"),
            format!(
                "{tc:.2} s / {mc:.0} MB; peer {tp:.2} s / {mp:.0} MB: {:.1}× faster, {:.2}× the memory",
                tp / tc,
                mc / mp
            ),
        );
        let _ = std::fs::remove_dir_all(&dir);
    }
}

/// What troubles the 18-run session of [`diagnose_of`] brings besides a hidden dead zone.
#[derive(Clone, Copy, PartialEq)]
enum Trouble {
    /// White noise on a perfect stand.
    None,
    /// A stand whose cone angle is 0.3° off and whose base is tilted (0.1°, 0.05°): each
    /// stand group found restarts the diagnosis.
    Stand,
    /// A clean unit (no dead zone) whose noise wanders like a MEMS unit's: white + flicker
    /// (10 °/h, 30 µg) + bias random walk (5 °/h/√h, 2e-5 m/s²/√s) carried over the
    /// session clock from run to run. The automatic mode diagnoses it twice (the AR noise
    /// model first, then with the slow noise measured) and keeps the second.
    Wander,
}

/// `diagnose` and `compare` on the issue's 18-run session of `samples` (1e6, and 1e7 with
/// `CROSSCAL_BENCH_1E7`) with a hidden gyro dead zone, beside the plain `fit` of the same
/// session: wall time, peak memory, and diagnose's time over the fit's (issue 36: ≤ 20× and
/// < 100 MB at 1e6, < 300 MB at 1e7). The 1e6 session again with the stand's errors, and
/// once more as a clean unit whose noise wanders ([`Trouble`]).
fn diagnose_at_scale(table: &mut Table) {
    diagnose_of(table, 1e6, Trouble::None);
    diagnose_of(table, 1e6, Trouble::Stand);
    diagnose_of(table, 1e6, Trouble::Wander);
    if std::env::var("CROSSCAL_BENCH_1E7").is_ok() {
        diagnose_of(table, 1e7, Trouble::None);
    }
}

fn diagnose_of(table: &mut Table, samples: f64, trouble: Trouble) {
    use crosscal::simulate::{write_session, SimConfig};
    let tmp = tempfile::tempdir().expect("temp dir");
    let mut c = SimConfig::paper();
    for r in &mut c.runs {
        r.duration_s = samples / 100.0 / 18.0;
    }
    c.gyro_noise_deg_s = 0.002;
    c.accel_noise_g = 2e-5;
    if trouble == Trouble::Wander {
        let deg = std::f64::consts::PI / 180.0;
        c.gyro_process.bias_instability = 10.0 * deg / 3600.0;
        c.gyro_process.random_walk = 5.0 * deg / 3600.0 / 60.0;
        c.accel_process.bias_instability = 30e-6 * c.g_m_s2;
        c.accel_process.random_walk = 2e-5;
        c.carry_noise = true;
    } else {
        c.truth.model.add_effect("gyro-dead-zone").expect("catalogue effect");
        for (n, v) in [("gyro.dz_x", 9e-4), ("gyro.dz_y", 5e-4), ("gyro.dz_z", 7e-4)] {
            c.truth.values.insert(n.into(), v);
        }
    }
    if trouble == Trouble::Stand {
        c.stand.cone_angle_deg = 0.3;
        c.stand.tilt_deg = [0.1, 0.05];
    }
    let manifest = write_session(&c.generate(), &tmp.path().join("s")).expect("write session");
    // Each command three times: the shortest wall time and the largest peak (a shared
    // machine's hiccups make one timing of a few seconds vary by ±10 %).
    let run = |args: &[&str]| {
        (0..3)
            .map(|_| measure(std::process::Command::new(env!("CARGO_BIN_EXE_crosscal")).args(args).arg(&manifest)))
            .fold((f64::INFINITY, 0.0f64), |(t, m), (ti, mi)| (t.min(ti), m.max(mi)))
    };
    let (tf, mf) = run(&["fit", "--dry-run"]);
    let (td, md) = run(&["diagnose"]);
    let (tc, mc) = run(&["compare"]);
    let what = match trouble {
        Trouble::None => "hidden gyro dead zone (found)",
        Trouble::Stand => "hidden gyro dead zone (found), stand cone +0.3° and base tilted (found)",
        Trouble::Wander => {
            "clean unit, flicker + bias random walk carried from run to run (adequate, the wander treated as noise)"
        }
    };
    report(
        table,
        format!("`diagnose` / `compare` / `fit`, 18 runs, {samples:.0e} samples, {what}"),
        format!(
            "{td:.2} s / {md:.0} MB; {tc:.2} s / {mc:.0} MB; fit {tf:.2} s / {mf:.0} MB; diagnose / fit {:.1}×",
            td / tf.max(1e-9)
        ),
    );
}

/// Peak resident set of this process so far, MB.
fn own_peak_mb() -> f64 {
    std::fs::read_to_string("/proc/self/status")
        .ok()
        .and_then(|t| {
            t.lines().find_map(|l| l.strip_prefix("VmHWM:")).map(|v| v.trim().trim_end_matches("kB").trim().to_string())
        })
        .and_then(|v| v.parse::<f64>().ok())
        .map_or(0.0, |kb| kb / 1024.0)
}

/// One channel of 1e8 samples: time and peak memory (the 800 MB input buffer dominates).
fn noise_1e8(table: &mut Table) {
    let n = 100_000_000usize;
    let p = NoiseProcess { white_density: 1e-3, ..Default::default() };
    let mut rng = ChaCha8Rng::seed_from_u64(2);
    let mut g = p.generator(0.01, n as f64 * 0.01);
    let mut data: Vec<f64> = (0..n).map(|_| g.next_sample(&mut rng)).collect();
    let before = own_peak_mb();
    let t0 = Instant::now();
    let r = analyse_channel("gx", "rad/s", &mut data, 0.01, NoiseOptions::default()).expect("analysis");
    report(
        table,
        "Allan deviation, 1e8 samples, one channel".into(),
        format!(
            "{:.2} s; peak RSS {:.0} MB with an {:.0} MB input buffer ({:.0} MB before analysis); N = {:.4e}",
            t0.elapsed().as_secs_f64(),
            own_peak_mb(),
            n as f64 * 8.0 / 1048576.0,
            before,
            r.white_density.unwrap_or(f64::NAN)
        ),
    );
}

/// CSV parsing (one core, in memory) and streaming correction (gyro + accelerometer with
/// ε estimation, in memory) of the paper's session.
fn parse_and_correct(table: &mut Table) {
    use crosscal::session::{parse_recording, ReadOptions};
    use crosscal::units::Units;
    let mut c = crosscal::simulate::SimConfig::paper();
    c.gyro_noise_deg_s = 0.002;
    c.accel_noise_g = 2e-5;
    let session = c.generate();
    let tmp = tempfile::tempdir().expect("temp dir");
    crosscal::simulate::write_session(&session, tmp.path()).expect("write");
    let bytes: Vec<u8> =
        session.runs.iter().flat_map(|r| std::fs::read(tmp.path().join(&r.spec.file)).expect("csv")).collect();
    let one = std::fs::read(tmp.path().join(&session.runs[0].spec.file)).expect("csv");
    let reps = bytes.len() / one.len();
    let (secs, n) = best_of(10, || {
        let mut n = 0;
        for _ in 0..reps {
            n += parse_recording(
                std::path::Path::new("x.csv"),
                &one,
                &Units::default(),
                9.80665,
                ReadOptions::default(),
            )
            .expect("parse")
            .len();
        }
        n
    });
    report(
        table,
        format!(
            "CSV parsing (`parse_recording`: SHA-256, gap and sanity scans included), {} MB, one core, in memory",
            (reps * one.len()) / 1_000_000
        ),
        format!("{:.0} MB/s ({:.1} M rows/s)", (reps * one.len()) as f64 / secs / 1e6, n as f64 / secs / 1e6),
    );
    let f = crosscal::estimate::fit(&crosscal::estimate::FitRequest::session(
        &crosscal::model::Model::default_model(),
        &session,
    ))
    .map(|o| o.fit)
    .expect("fit");
    let cal =
        crosscal::app::validate::calibration_of(&crosscal::model::Model::default_model(), &f).expect("calibration");
    // The corrector as a streaming user drives it: caller-owned buffers, no allocation.
    let longest = session.runs.iter().map(|r| r.rec.len()).max().unwrap_or(0);
    let (mut w_out, mut a_out) = (vec![[0.0; 3]; longest], vec![[0.0; 3]; longest]);
    let mut corrector = crosscal::correct::Streaming::new(cal.clone());
    let (secs, n) = best_of(10, || {
        let mut n = 0;
        for r in session.runs.iter().cycle().take(50 * session.runs.len()) {
            corrector.reset();
            n += corrector.push_block(&r.rec.t_s, &r.rec.gyro, &r.rec.accel, &mut w_out, &mut a_out);
        }
        std::hint::black_box((&w_out, &a_out));
        n
    });
    let runs_rate = n as f64 / secs / 1e6;
    // One long record on one uniform clock (a unit streaming for hours), corrected in blocks
    // of 4096 samples that stay in cache: the first run's samples over and over, with the
    // stamps running on.
    let block = 4096.min(session.runs[0].rec.len());
    let dt = 1.0 / c.sample_rate_hz;
    let (gyro, accel) = (&session.runs[0].rec.gyro[..block], &session.runs[0].rec.accel[..block]);
    let mut t = vec![0.0; block];
    let (mut w_out, mut a_out) = (vec![[0.0; 3]; block], vec![[0.0; 3]; block]);
    let (secs, n) = best_of(10, || {
        corrector.reset();
        let mut n = 0;
        for b in 0..1000 {
            for (k, t) in t.iter_mut().enumerate() {
                *t = (b * block + k) as f64 * dt;
            }
            n += corrector.push_block(&t, gyro, accel, &mut w_out, &mut a_out);
            std::hint::black_box((&w_out, &a_out));
        }
        n
    });
    report(
        table,
        format!("streaming correction, gyro + accel with ε estimation, one core, caller's buffers: runs of {longest} samples (reset and warm-up each) / one long record in blocks of {block}"),
        format!("{runs_rate:.1} / {:.1} M samples/s", n as f64 / secs / 1e6),
    );
}

/// `crosscal correct` on a CSV of 1e6 samples (one run), streaming and offline, against its
/// parts on one core in memory: parsing, the streaming corrector's maths, formatting.
fn correct_csv(table: &mut Table) {
    use crosscal::session::{parse_recording, CsvLine, ReadOptions};
    use crosscal::simulate::{conic_plan, cyclic_mounts, write_session, SimConfig};
    let tmp = tempfile::tempdir().expect("temp dir");
    let mut c = SimConfig::paper();
    c.runs = conic_plan(&[10.0], &[10.0], &cyclic_mounts(1), 10_000.0);
    c.gyro_noise_deg_s = 0.002;
    c.accel_noise_g = 2e-5;
    let session = c.generate();
    let manifest = write_session(&session, &tmp.path().join("s")).expect("write session");
    let model = crosscal::model::Model::default_model();
    let fit = crosscal::estimate::fit(&crosscal::estimate::FitRequest::session(&model, &session))
        .map(|o| o.fit)
        .expect("fit");
    let cal = crosscal::app::validate::calibration_of(&model, &fit).expect("calibration");
    let profile = crosscal::profile::Profile::from_fit(&session, &model, fit, Vec::new());
    let profile_path = tmp.path().join("profile.json");
    std::fs::write(&profile_path, profile.to_json()).expect("profile");
    let csv = manifest.with_file_name(&session.runs[0].spec.file);
    let bytes = std::fs::read(&csv).expect("csv");
    let cli = |mode: &str| {
        measure(
            std::process::Command::new(env!("CARGO_BIN_EXE_crosscal"))
                .args(["correct", "--force", "--mode", mode, "--profile"])
                .arg(&profile_path)
                .arg(&csv)
                .arg("-o")
                .arg(tmp.path().join("out.csv"))
                .stderr(std::process::Stdio::null()),
        )
    };
    let (ts, ms) = cli("streaming");
    let (to, mo) = cli("offline");
    let units = session.manifest.units;
    let (parse, rec) =
        best_of(3, || parse_recording(&csv, &bytes, &units, 9.80665, ReadOptions::default()).expect("parse"));
    let (maths, out) = best_of(3, || {
        crosscal::correct::correct_streaming(&cal, &rec.t_s, &rec.gyro, &rec.accel, None).expect("correct")
    });
    let (format, _) = best_of(3, || {
        let mut sink = std::io::sink();
        let mut line = CsvLine::new();
        for k in 0..rec.len() {
            line.float(rec.t_s[k]);
            for v in out.w_rad_s[k].iter().chain(&out.a_m_s2[k]) {
                line.float(*v);
            }
            line.write_to(&mut sink).expect("sink");
        }
    });
    report(
        table,
        format!(
            "`correct` on a CSV of {} samples ({:.0} MB): `--mode streaming` / offline (whole record); one core in memory: parsing, streaming maths, formatting",
            rec.len(),
            bytes.len() as f64 / 1e6
        ),
        format!(
            "{ts:.2} s / {ms:.0} MB; {to:.2} s / {mo:.0} MB; {parse:.3} s, {maths:.3} s, {format:.3} s (maths {:.0} % of the three)",
            100.0 * maths / (parse + maths + format)
        ),
    );
}

/// The machine and tools the table was measured with.
fn machine() -> String {
    let cpuinfo = std::fs::read_to_string("/proc/cpuinfo").unwrap_or_default();
    let model = cpuinfo
        .lines()
        .find_map(|l| l.strip_prefix("model name").and_then(|v| v.split_once(':')).map(|(_, v)| v.trim().to_string()))
        .unwrap_or_else(|| "unknown processor".into());
    let flags: Vec<&str> = cpuinfo
        .lines()
        .find_map(|l| l.strip_prefix("flags"))
        .map(|f| f.split_whitespace().collect())
        .unwrap_or_default();
    let has = |f: &str| flags.contains(&f);
    let features: Vec<&str> = [("avx2", "AVX2"), ("fma", "FMA"), ("avx512f", "AVX-512F"), ("sha_ni", "SHA extensions")]
        .iter()
        .filter(|(f, _)| has(f))
        .map(|(_, n)| *n)
        .collect();
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    let output = |cmd: &str, args: &[&str]| {
        std::process::Command::new(cmd)
            .args(args)
            .output()
            .ok()
            .map(|o| String::from_utf8_lossy(&o.stdout).trim().to_string())
            .filter(|s| !s.is_empty())
            .unwrap_or_else(|| format!("{cmd}: not found"))
    };
    let rustc = output("rustc", &["--version"]);
    let peer = output(
        "python3",
        &["-c", "import sys, numpy, pandas; print(f'Python {sys.version.split()[0]}, pandas {pandas.__version__}, numpy {numpy.__version__}')"],
    );
    let date = jiff::Zoned::now().strftime("%Y-%m-%d").to_string();
    format!(
        "{model}, {cores} logical cores ({}); {rustc}; peer: {peer}. Measured {date}, release build.",
        features.join(", ")
    )
}

/// Replaces the table of docs/performance.md (between the bench markers) with this run's.
fn write_readme(table: &Table) -> std::io::Result<()> {
    const BEGIN: &str = "<!-- bench:begin";
    const END: &str = "<!-- bench:end -->";
    let path = std::path::Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/docs/performance.md"));
    let text = std::fs::read_to_string(path)?;
    let (Some(a), Some(b)) = (text.find(BEGIN), text.find(END)) else {
        return Err(std::io::Error::other("docs/performance.md has no bench markers"));
    };
    let mut block = String::from(
        "<!-- bench:begin: generated by `CROSSCAL_BENCH_WRITE=1 cargo bench --bench throughput`; edits here are overwritten -->\n",
    );
    block.push_str(&format!("{}\n\n| what | measured (one run) |\n|---|---|\n", machine()));
    for (what, measured) in table {
        block.push_str(&format!("| {what} | {measured} |\n"));
    }
    let new = format!("{}{block}{}", &text[..a], &text[b..]);
    crosscal::atomic::write_atomic(path, true, |w| std::io::Write::write_all(w, new.as_bytes()))
}

fn main() {
    let only = std::env::args().skip(1).find(|a| !a.starts_with('-'));
    let readme = std::env::var("CROSSCAL_BENCH_WRITE").is_ok();
    let mut table = Table::new();
    if only.as_deref().is_none_or(|o| "noise".contains(o)) {
        noise(&mut table);
        if std::env::var("CROSSCAL_BENCH_1E8").is_ok() {
            noise_1e8(&mut table);
        }
    }
    if only.as_deref().is_none_or(|o| "batch".contains(o)) {
        batch(&mut table);
    }
    if only.as_deref().is_none_or(|o| "csv correct".contains(o)) {
        parse_and_correct(&mut table);
        correct_csv(&mut table);
    }
    if only.as_deref().is_none_or(|o| "diagnose compare".contains(o)) {
        diagnose_at_scale(&mut table);
    }
    if only.as_deref().is_none_or(|o| "fit".contains(o)) {
        let big = readme || std::env::var("CROSSCAL_BENCH_1E7").is_ok();
        fit_vs_peer(&mut table, if big { &[100_000, 1_000_000, 10_000_000] } else { &[100_000, 1_000_000] });
    }
    if readme {
        if only.is_some() {
            eprintln!("docs/performance.md not rewritten: its table needs the whole bench (no filter)");
        } else {
            match write_readme(&table) {
                Ok(()) => println!("docs/performance.md: table rewritten"),
                Err(e) => eprintln!("docs/performance.md not rewritten: {e}"),
            }
        }
    }
}
