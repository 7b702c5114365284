//! Subcommands. Parsing and printing only; every number comes from the library.

mod accept;
mod batch;
mod check;
mod compare;
mod correct;
mod datasheet;
mod demo;
mod diagnose;
mod effects;
mod fit;
mod format;
mod import;
mod import_log;
mod noise;
mod noise_lot;
mod plan;
mod profile;
mod simulate;

use clap::{Parser, Subcommand};
use std::process::ExitCode;

pub use crosscal::app::errors::{EXIT_CHECK_FAILED, EXIT_CODES, EXIT_INPUT};

/// Exit code of an error: the first error in its chain that says (see [`EXIT_CODES`]).
pub fn exit_code(e: &anyhow::Error) -> u8 {
    e.chain().find_map(crosscal::app::errors::code_of).unwrap_or(EXIT_INPUT)
}

/// Cross-coupling calibration of gyro and accelerometer triads on a conic-motion stand.
#[derive(Debug, Parser)]
#[command(
    name = "crosscal",
    version,
    about,
    long_about = None,
    disable_help_subcommand = true,
    after_help = "Example: crosscal simulate --preset paper -o demo/ && crosscal fit demo/session.json --out calib-profiles/\n\
                  More: crosscal help COMMAND, or crosscal help TOPIC for one of: session, formats, profile-format, rules, catalogue, conventions, errors, quantities"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
    /// An effects file (TOML): its user effects join the catalogue for this command, usable
    /// wherever a catalogue effect is (`--effect ID`, `--hidden ID`, diagnose, compare);
    /// repeatable. See `docs/your-own-effect.md`.
    #[arg(long = "effects-file", global = true, value_name = "FILE")]
    effects_file: Vec<std::path::PathBuf>,
}

/// Parsed once per process: the size difference between the commands' arguments does not matter.
#[derive(Debug, Subcommand)]
#[allow(clippy::large_enum_variant)]
enum Command {
    /// Write a synthetic stand session (the paper's unit by default).
    #[command(
        after_help = "Example: crosscal simulate --preset paper -o demo/\nExample: crosscal simulate --thermal-sweep -20,0,20,45,70 --thermal-tau 120 --temp-noise 0.05 -o sweep/"
    )]
    Simulate(simulate::Args),
    /// Fit a calibration profile to a session and store it under calib-profiles/.
    #[command(after_help = "Example: crosscal fit demo/session.json --out calib-profiles/")]
    Fit(fit::Args),
    /// Correct a recording (CSV) with a profile.
    #[command(
        after_help = "Example: crosscal correct --profile calib-profiles/I1426-0042 demo/cone+10.csv -o corrected.csv"
    )]
    Correct(correct::Args),
    /// Compare corrected outputs with a session's reference motion; exit 1 on failure.
    #[command(after_help = "Example: crosscal check --profile calib-profiles/I1426-0042 demo/session.json")]
    Check(check::Args),
    /// Run the whole pipeline on the paper's stand and print the paper comparison.
    #[command(after_help = "Example: crosscal demo")]
    Demo(demo::Args),
    /// Compare model and measurement: where the model fails and which effect is missing.
    #[command(after_help = "Example: crosscal diagnose hidden/session.json --report diagnose.html")]
    Diagnose(diagnose::Args),
    /// The model ladder: paper model, default, then each effect diagnose adds.
    #[command(after_help = "Example: crosscal compare hidden/session.json --svg ladder.svg")]
    Compare(compare::Args),
    /// List the effects catalogue with coefficients, units and physical explanations.
    #[command(after_help = "Example: crosscal effects gyro-dead-zone")]
    Effects(effects::Args),
    /// Allan deviation and noise terms (white noise, bias instability, random walk) of a static recording.
    #[command(after_help = "Example: crosscal noise still/session.json --report noise.html")]
    Noise(noise::Args),
    /// Predicted uncertainty of every coefficient for proposed runs, before recording; suggests a run.
    #[command(
        after_help = "Example: crosscal plan --rates 10 --cone-angles 10 --mounts 1 --arw 0.15 --vrw 0.02\nExample: crosscal plan --thermal -20,0,20,45,70 --degree 3 --target-bias-std 1e-5,1e-3"
    )]
    Plan(plan::Args),
    /// Accept or reject a unit: its profile (and session) against acceptance rules; exit 1 on reject.
    #[command(
        after_help = "Example: crosscal accept calib-profiles/I1426-0042 --rules rules.json --session demo/session.json"
    )]
    Accept(accept::Args),
    /// A unit's datasheet: bias, repeatability, ARW, scale factor, misalignment … in datasheet units with uncertainties.
    #[command(after_help = "Example: crosscal datasheet I1426-0042 --store calib-profiles --report datasheet.html")]
    Datasheet(datasheet::Args),
    /// The profile store: list units and histories, show the profile in force, diff two profiles.
    #[command(after_help = "Example: crosscal profile list")]
    Profile(profile::Args),
    /// Calibrate a production lot in parallel: a profile per unit, acceptance, outliers, reports.
    #[command(after_help = "Example: crosscal batch lot/ --rules rules.json")]
    Batch(batch::Args),
    /// Turn a ROS 1/2 bag, PX4 ULog or ArduPilot DataFlash log, or a recording laid out for
    /// imucal, imu_tk or a Tedaldi script, into a crosscal session.
    #[command(
        after_help = "Example: crosscal import --list flight.ulg\nExample: crosscal import imu.bag --topic /imu/data_raw --out bag-session/\nExample: crosscal import imu-tk acc.mat gyro.mat --init-rest-s 50 --out tk/"
    )]
    Import(import::Args),
    /// List the exit codes and what each means (as the guide's table).
    #[command(after_help = "Example: crosscal exit-codes")]
    ExitCodes,
    /// Help on a command, or a topic: session, formats, profile-format, rules, catalogue, conventions, errors, quantities.
    #[command(after_help = "Example: crosscal help conventions")]
    Help {
        /// A command name or a topic; without one, the list of commands and topics.
        topic: Option<String>,
    },
}

/// The guide's reference pages, built into the binary so `crosscal help TOPIC` and
/// `docs/` are one text.
const TOPICS: &[(&str, &str)] = &[
    ("session", include_str!("../../docs/reference-session.md")),
    ("formats", include_str!("../../docs/reference-session.md")),
    ("profile-format", include_str!("../../docs/reference-profile.md")),
    ("rules", include_str!("../../docs/reference-rules.md")),
    ("quantities", include_str!("../../docs/reference-datasheet.md")),
    ("catalogue", include_str!("../../docs/reference-effects.md")),
    ("conventions", include_str!("../../docs/reference-conventions.md")),
    ("errors", include_str!("../../docs/reference-exit-codes.md")),
];

/// `crosscal help [TOPIC]`.
fn help(topic: Option<&str>) -> anyhow::Result<Outcome> {
    use clap::CommandFactory;
    let mut cmd = Cli::command();
    let Some(topic) = topic else {
        crate::outln!("{}", cmd.render_help());
        crate::outln!("Topics: {}", TOPICS.iter().map(|t| t.0).collect::<Vec<_>>().join(", "));
        return Ok(Outcome::Ok);
    };
    if let Some((_, text)) = TOPICS.iter().find(|t| t.0 == topic) {
        crate::out!("{text}");
        return Ok(Outcome::Ok);
    }
    if let Some(sub) = cmd.find_subcommand_mut(topic) {
        let mut sub = sub.clone().bin_name(format!("crosscal {topic}"));
        crate::outln!("{}", sub.render_long_help());
        return Ok(Outcome::Ok);
    }
    let names: Vec<String> = cmd.get_subcommands().map(|c| c.get_name().to_string()).collect();
    anyhow::bail!(
        "no help on '{topic}': commands are {}; topics are {}",
        names.join(", "),
        TOPICS.iter().map(|t| t.0).collect::<Vec<_>>().join(", ")
    )
}

/// Stdout was closed by its reader (`crosscal … | head -1`): the command stops quietly
/// with exit code 0, as `rg | head` does; whatever it had to save is already saved.
#[derive(Debug, thiserror::Error)]
#[error("stdout was closed")]
pub struct StdoutClosed;

/// Set once stdout's reader has gone: later output is dropped, the command carries on.
static STDOUT_GONE: std::sync::atomic::AtomicBool = std::sync::atomic::AtomicBool::new(false);

/// Writes to stdout, surfacing errors instead of panicking as `print!` does. A closed pipe
/// (`crosscal … | head -3`) is not a failure and does not stop the command: whatever it
/// still has to save (reports, figures, profiles) is saved, the rest of its printing is
/// dropped, and it exits 0 ([`StdoutClosed`] is kept for callers that stop on it). Any
/// other failure (a full disk) is an error naming stdout.
pub fn out(args: std::fmt::Arguments<'_>) -> anyhow::Result<()> {
    use std::io::Write;
    use std::sync::atomic::Ordering;
    if STDOUT_GONE.load(Ordering::Relaxed) {
        return Ok(());
    }
    let mut o = std::io::stdout().lock();
    match o.write_fmt(args).and_then(|()| o.flush()) {
        Ok(()) => Ok(()),
        Err(e) if e.kind() == std::io::ErrorKind::BrokenPipe => {
            STDOUT_GONE.store(true, Ordering::Relaxed);
            Ok(())
        }
        Err(e) => Err(anyhow::Error::new(e).context("writing to stdout")),
    }
}

/// Writes a line to stderr, never panicking as `eprintln!` does when stderr is closed
/// (`2>&1 | head -3`): a message that cannot be shown must not cost an output.
pub fn err_line(args: std::fmt::Arguments<'_>) {
    use std::io::Write;
    let mut e = std::io::stderr().lock();
    let _ = e.write_fmt(args).and_then(|()| e.write_all(b"\n"));
}

/// `eprintln!` that never panics (see [`err_line`]).
#[macro_export]
macro_rules! errln {
    () => { $crate::cli::err_line(format_args!("")) };
    ($($t:tt)*) => { $crate::cli::err_line(format_args!($($t)*)) };
}

/// `print!` that returns the write's error (see [`out`]).
#[macro_export]
macro_rules! out {
    ($($t:tt)*) => { $crate::cli::out(format_args!($($t)*))? };
}

/// `println!` that returns the write's error (see [`out`]).
#[macro_export]
macro_rules! outln {
    () => { $crate::cli::out(format_args!("\n"))? };
    ($($t:tt)*) => { $crate::cli::out(format_args!("{}\n", format_args!($($t)*)))? };
}

/// The model flags shared by the commands that fit.
#[derive(Debug, Clone, clap::Args)]
pub struct ModelArgs {
    /// Model preset: `default` (biases, full C_ω, C_ε, K), `paper` (exactly eqs. 3–4),
    /// `ferraris` (biases, C_ω, gyro g-sensitivity, K) or `tedaldi` (biases, C_ω,
    /// upper-triangular K). Protocol sessions (static poses, turns, multi-position) use
    /// `ferraris` or `tedaldi` unless told otherwise.
    #[arg(long = "model", default_value = "default", value_parser = parse_preset)]
    pub preset: crosscal::model::Preset,
    /// Add a catalogue effect to the model (repeatable; `crosscal effects` lists them).
    #[arg(long = "effect")]
    pub effects: Vec<String>,
}

impl ModelArgs {
    /// The model as named, with `disable` held at their nominal values.
    pub fn spec(&self, disable: &[String]) -> crosscal::model::ModelSpec {
        crosscal::model::ModelSpec { preset: self.preset, effects: self.effects.clone(), disable: disable.to_vec() }
    }
}

/// A unit serial that can name a folder of the profile store (no path separator, no `..`).
pub fn parse_serial(s: &str) -> Result<String, String> {
    if crosscal::session::valid_serial(s) {
        Ok(s.to_string())
    } else {
        Err(format!(
            "'{s}' cannot be a serial: use letters, digits, '-', '_' or '.' (not starting with '.'), at most 128"
        ))
    }
}

fn parse_preset(s: &str) -> Result<crosscal::model::Preset, String> {
    s.parse().map_err(|_| format!("expected one of {}", crosscal::model::Preset::NAMES))
}

/// Reads the profile a `--profile` flag names: a file, or a unit's folder of the store
/// (then its newest profile, named on stderr).
pub fn read_profile(path: &std::path::Path) -> anyhow::Result<crosscal::profile::Profile> {
    let (used, p) = crosscal::profile::Profile::read_or_latest(path)?;
    if used != path {
        errln!("profile: {} (the newest of unit {})", used.display(), p.serial);
    }
    Ok(p)
}

/// Writes one output file by the one rule every output follows: atomically, never over an
/// existing file unless `force` (and never over a device, FIFO or folder, even then), `-`
/// being standard output.
pub fn write_output(path: &std::path::Path, force: bool, bytes: &[u8]) -> anyhow::Result<()> {
    match crosscal::atomic::write_atomic(path, force, |w| std::io::Write::write_all(w, bytes)) {
        Ok(()) => Ok(()),
        Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => Err(anyhow::Error::new(std::io::Error::new(
            std::io::ErrorKind::AlreadyExists,
            format!("{} already exists: choose another name or pass --force to replace it", path.display()),
        ))),
        Err(e) => Err(anyhow::Error::new(e).context(format!("writing {}", path.display()))),
    }
}

/// Writes a report's plots as `DIR/<stem>.svg` (the folder is created; an existing plot is
/// replaced only with `force`, as every output).
pub fn write_figures(dir: &std::path::Path, figs: &[crosscal::html::Figure], force: bool) -> anyhow::Result<()> {
    use anyhow::Context;
    std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    let figs: Vec<_> = figs.iter().filter(|f| !f.svg.is_empty()).collect();
    // Refused before any is written, so a refusal leaves the folder as it was.
    if !force {
        if let Some(p) = figs.iter().map(|f| dir.join(format!("{}.svg", f.stem))).find(|p| p.exists()) {
            return write_output(&p, false, b"");
        }
    }
    for f in &figs {
        write_output(&dir.join(format!("{}.svg", f.stem)), force, f.svg.as_bytes())?;
    }
    errln!("{} plots written to {}", figs.len(), dir.display());
    Ok(())
}

/// Prints [`EXIT_CODES`] as a Markdown table.
fn print_exit_codes() -> anyhow::Result<Outcome> {
    let mut s = String::from("| code | meaning |\n|---|---|\n");
    for (code, meaning) in EXIT_CODES {
        s.push_str(&format!("| {code} | {meaning} |\n"));
    }
    out(format_args!("{s}"))?;
    Ok(Outcome::Ok)
}

/// Outcome of a subcommand that succeeded in running.
pub enum Outcome {
    /// Everything passed.
    Ok,
    /// A check failed (exit 1).
    CheckFailed,
}

/// Entry point.
pub fn main() -> ExitCode {
    // Ctrl-C or SIGTERM: remove the temporary files being written, then stop (no output is
    // left half-written, and no hidden temporary file is left behind).
    let _ = ctrlc::set_handler(|| {
        crosscal::atomic::remove_in_progress();
        std::process::exit(130);
    });
    let cli = match Cli::try_parse() {
        Ok(c) => c,
        Err(e) => {
            let _ = e.print();
            return if e.use_stderr() { ExitCode::from(EXIT_INPUT) } else { ExitCode::SUCCESS };
        }
    };
    for f in &cli.effects_file {
        match crosscal::model::user::load_file(f) {
            Ok(v) => crosscal::model::user::register(&v),
            Err(e) => {
                let e = anyhow::Error::new(e);
                eprintln!("error: {e:#}");
                return ExitCode::from(exit_code(&e));
            }
        }
    }
    let result = match cli.command {
        Command::Simulate(a) => simulate::run(a),
        Command::Fit(a) => fit::run(a),
        Command::Correct(a) => correct::run(a),
        Command::Check(a) => check::run(a),
        Command::Demo(a) => demo::run(a),
        Command::Diagnose(a) => diagnose::run(a),
        Command::Compare(a) => compare::run(a),
        Command::Effects(a) => effects::run(a),
        Command::Noise(a) => noise::run(a),
        Command::Plan(a) => plan::run(a),
        Command::Accept(a) => accept::run(a),
        Command::Datasheet(a) => datasheet::run(a),
        Command::Profile(a) => profile::run(a),
        Command::Batch(a) => batch::run(a),
        Command::Import(a) => import::run(a),
        Command::ExitCodes => print_exit_codes(),
        Command::Help { topic } => help(topic.as_deref()),
    };
    match result {
        Ok(Outcome::Ok) => ExitCode::SUCCESS,
        Ok(Outcome::CheckFailed) => ExitCode::from(EXIT_CHECK_FAILED),
        Err(e) if e.chain().any(|c| c.is::<StdoutClosed>()) => ExitCode::SUCCESS,
        Err(e) => {
            errln!("error: {e:#}");
            ExitCode::from(exit_code(&e))
        }
    }
}

/// Parses "x,y,z" into three numbers.
pub fn parse_triple(s: &str) -> Result<[f64; 3], String> {
    let v: Result<Vec<f64>, _> = s.split(',').map(|p| p.trim().parse::<f64>()).collect();
    match v {
        Ok(v) if v.len() == 3 && v.iter().all(|x| x.is_finite()) => Ok([v[0], v[1], v[2]]),
        _ => Err(format!("expected three finite numbers 'x,y,z', found '{s}'")),
    }
}

/// A comma-separated list of numbers on the command line.
#[derive(Debug, Clone)]
pub struct List(pub Vec<f64>);

/// A set of conic stand runs on the command line (every mount × cone angle × rate).
#[derive(Debug, clap::Args)]
pub struct RunSet {
    /// Stand rates ω_s, deg/s (sign = direction), comma-separated.
    #[arg(long, value_parser = parse_list, allow_hyphen_values = true, default_value = "10,-10,20")]
    pub rates: List,
    /// Cone angles α, degrees, comma-separated.
    #[arg(long, value_parser = parse_list, default_value = "10,20")]
    pub cone_angles: List,
    /// Number of cyclic mounts (1 = nominal only, 2 adds [+y,+z,+x], 3 adds [+z,+x,+y]).
    #[arg(long, default_value_t = 3, value_parser = clap::value_parser!(u8).range(1..=3))]
    pub mounts: u8,
    /// Duration of each run, s.
    #[arg(long, default_value_t = 36.0)]
    pub duration: f64,
    /// Sample rate, Hz.
    #[arg(long, default_value_t = 100.0)]
    pub rate_hz: f64,
}

impl RunSet {
    /// The runs.
    pub fn plan(&self) -> Vec<crosscal::simulate::RunPlan> {
        crosscal::simulate::conic_plan(
            &self.rates.0,
            &self.cone_angles.0,
            &crosscal::simulate::cyclic_mounts(self.mounts as usize),
            self.duration,
        )
    }
}

/// How a thermal sweep (`simulate --thermal-sweep`, `plan --thermal`) runs in the chamber:
/// the runs at each plateau, the soak, the unit's lag, ramps. Each flag needs the sweep.
#[derive(Debug, clap::Args)]
pub struct SweepArgs {
    /// Static faces recorded at each plateau (0 to 6: up = +z, -z, +x, -x, +y, -y), each for
    /// --duration.
    #[arg(long, default_value_t = 6, value_parser = clap::value_parser!(u8).range(0..=6), requires = "thermal_sweep")]
    pub faces: u8,
    /// Also record the conic runs of --rates × --cone-angles × --mounts at each plateau.
    #[arg(long, requires = "thermal_sweep")]
    pub plateau_conic: bool,
    /// Soak at each plateau before its first run, s, not recorded (default 5 × --thermal-tau,
    /// the unit then within 0.7 % of the step).
    #[arg(long, requires = "thermal_sweep")]
    pub soak: Option<f64>,
    /// Time constant of the unit's first-order lag behind the chamber, s (0: none).
    #[arg(long, default_value_t = 0.0, requires = "thermal_sweep")]
    pub thermal_tau: f64,
    /// Chamber ramp rate between set points, °C/min (default: the set point steps).
    #[arg(long, requires = "thermal_sweep")]
    pub ramp_rate: Option<f64>,
    /// Record during the ramps as well (the plateau's runs in turn, as many as fit).
    #[arg(long, requires = "ramp_rate")]
    pub record_ramps: bool,
    /// Chamber and unit temperature when the sweep starts, °C.
    #[arg(long, default_value_t = 20.0, allow_hyphen_values = true, requires = "thermal_sweep")]
    pub chamber_start: f64,
    /// Mark a plateau run NOT SETTLED in its note when the unit is farther than this from the
    /// set point, °C.
    #[arg(long, default_value_t = 0.1, requires = "thermal_sweep")]
    pub settled_within: f64,
}

impl SweepArgs {
    /// The sweep over `plateaus_c`: the faces and (with --plateau-conic) the conic runs of
    /// `runs` at each plateau; refused when it cannot run.
    pub fn sweep(
        &self,
        plateaus_c: &[f64],
        runs: &RunSet,
    ) -> anyhow::Result<crosscal::simulate::thermal::ThermalSweep> {
        let mut at_plateau = crosscal::simulate::thermal::faces(self.faces as usize, runs.duration);
        if self.plateau_conic {
            at_plateau.extend(runs.plan());
        }
        let mut s = crosscal::simulate::thermal::ThermalSweep::new(plateaus_c.to_vec(), at_plateau);
        s.tau_s = self.thermal_tau;
        s.soak_s = self.soak.unwrap_or(5.0 * self.thermal_tau);
        s.ramp_c_per_min = self.ramp_rate;
        s.record_ramps = self.record_ramps;
        s.start_c = self.chamber_start;
        s.settled_within_c = self.settled_within;
        s.check().map_err(anyhow::Error::msg)?;
        Ok(s)
    }
}

/// Parses a comma-separated list of finite numbers.
pub fn parse_list(s: &str) -> Result<List, String> {
    let v: Result<Vec<f64>, _> = s.split(',').map(|p| p.trim().parse::<f64>()).collect();
    match v {
        Ok(v) if !v.is_empty() && v.iter().all(|x| x.is_finite()) => Ok(List(v)),
        _ => Err(format!("expected a comma-separated list of numbers, found '{s}'")),
    }
}
