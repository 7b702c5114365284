//! `crosscal fit`.

use super::{format, Outcome};
use anyhow::Context;
use crosscal::estimate::FitOptions;
use crosscal::estimate::{fit_runs, tracks};
use crosscal::model::Model;
use crosscal::motion::DerivativeConfig;
use crosscal::profile::{save, Profile};
use crosscal::session::Session;
use std::path::PathBuf;

/// Options of `fit`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// The session manifest (session.json).
    session: PathBuf,
    /// Profile store; the profile goes to <out>/<serial>/<UTC time>.json.
    #[arg(long, default_value = "calib-profiles")]
    out: PathBuf,
    /// Model preset: `default` (biases, full C_ω, C_ε, K), `paper` (exactly eqs. 3–4),
    /// `ferraris` (biases, C_ω, gyro g-sensitivity, K) or `tedaldi` (biases, C_ω, upper-triangular
    /// K). Protocol sessions (static poses, turns, multi-position) use `ferraris` or `tedaldi`
    /// unless told otherwise.
    #[arg(long, default_value = "default")]
    model: String,
    /// Add a catalogue effect to the model (repeatable).
    #[arg(long = "effect")]
    effects: Vec<String>,
    /// Hold a coefficient at its nominal value instead of fitting it (repeatable), e.g. gyro.e_xx.
    #[arg(long = "disable")]
    disable: Vec<String>,
    /// Print the profile as JSON on stdout instead of the table.
    #[arg(long)]
    json: bool,
    /// Fit and report but do not write a profile.
    #[arg(long)]
    dry_run: bool,
    /// Robust fit (Huber IRLS): spikes and outliers lose weight.
    #[arg(long)]
    robust: bool,
    /// Gaps in t and unidentifiable coefficients are errors instead of warnings.
    #[arg(long)]
    strict: bool,
    /// Leave these runs out of the fit and validate the profile on them (repeatable); the
    /// held-out errors and reduction factors are stored in the profile.
    #[arg(long)]
    holdout: Vec<String>,
    /// Estimate each conic run's actual cone angle, rate and phase with the coefficients
    /// (for a stand that does not sit exactly at its nominal settings).
    #[arg(long)]
    stand: bool,
    /// Ferraris sessions: biases by the classic six-position formulas (each accelerometer bias
    /// from the two faces along its axis, the gyro bias as the mean of all static samples), as
    /// imucal computes them, instead of least squares over all six faces.
    #[arg(long)]
    classic_six_position: bool,
    /// Require the streamed fit (recordings read as streams, memory independent of their
    /// length), which is used anyway whenever the session and model allow it (conic and
    /// static runs, linear models, no --holdout/--stand/--robust): fail instead of reading
    /// the session into memory.
    #[arg(long, conflicts_with_all = ["holdout", "stand", "robust"])]
    stream: bool,
    /// Store this noise characterisation (JSON from `crosscal noise --save`) in the profile.
    #[arg(long)]
    noise: Option<PathBuf>,
}

/// Builds the model from the command line.
pub fn build_model(preset: &str, effects: &[String], disable: &[String]) -> anyhow::Result<Model> {
    let mut m = Model::preset(preset)?;
    for e in effects {
        m.add_effect(e)?;
    }
    for d in disable {
        m.disable(d)?;
    }
    Ok(m)
}

pub fn run(a: Args) -> anyhow::Result<Outcome> {
    // Stand sessions with a linear model are fitted from streams (memory independent of the
    // recordings' length, the same numbers to the last bit); what needs the samples in
    // memory reads the session whole.
    if a.stream || (a.holdout.is_empty() && !a.stand && !a.robust) {
        use crosscal::estimate::stream::{fit_streaming_with, StreamError};
        let model = build_model(&a.model, &a.effects, &a.disable)?;
        match fit_streaming_with(&a.session, &model, &FitOptions::default(), a.strict) {
            Ok(sf) => return run_streamed(&a, &model, sf),
            Err(StreamError::NotStreamable(why)) if a.stream => anyhow::bail!("{}: {why}", a.session.display()),
            Err(StreamError::NotStreamable(_)) => {}
            // Typed causes keep their exit codes.
            Err(StreamError::Read(e)) => {
                return Err(anyhow::Error::from(e).context(format!("reading session {}", a.session.display())))
            }
            Err(StreamError::Estimate(e)) => {
                return Err(anyhow::Error::from(e).context(format!("fitting {}", a.session.display())))
            }
            Err(e) => return Err(e.into()),
        }
    }
    let full =
        Session::load_with(&a.session, a.strict).with_context(|| format!("reading session {}", a.session.display()))?;
    if full.is_protocol() {
        return run_protocol(&a, &full);
    }
    let model = build_model(&a.model, &a.effects, &a.disable)?;
    for h in &a.holdout {
        if !full.runs.iter().any(|r| &r.spec.name == h) {
            anyhow::bail!("--holdout {h}: no such run in {}", a.session.display());
        }
    }
    // Without held-out runs the fit uses the session as read (no copy of its samples).
    let session = if a.holdout.is_empty() {
        std::borrow::Cow::Borrowed(&full)
    } else {
        std::borrow::Cow::Owned(crosscal::app::pipeline::subset(&full, |n| !a.holdout.iter().any(|h| h == n)))
    };
    let deriv = DerivativeConfig::default();
    let tr = tracks(&session, &deriv);
    let opts = FitOptions { robust: a.robust, ..FitOptions::default() };
    let fit = if a.stand {
        crosscal::estimate::fit_with_stand(&model, &session, &deriv, &opts)
    } else {
        crosscal::estimate::fit(&model, &fit_runs(&session, &tr), &opts)
    }
    .with_context(|| format!("fitting {}", a.session.display()))?;
    if a.strict {
        fit.ensure_identifiable().with_context(|| format!("fitting {} (--strict)", a.session.display()))?;
    }
    let mut notes = session.warnings();
    for (run, t) in session.runs.iter().zip(&tr) {
        notes.push(format!("run {}: ε reference {}", run.spec.name, t.epsilon_source));
    }
    notes.extend(unidentifiable_notes(&fit));
    let mut profile = Profile::from_fit(&session, &model, fit, notes);
    attach_noise(&a, &mut profile)?;
    if !a.holdout.is_empty() {
        let held = crosscal::app::pipeline::subset(&full, |n| a.holdout.iter().any(|h| h == n));
        let cal = crosscal::correct::Calibration::from_profile(&profile)?;
        let report = crosscal::app::pipeline::check_session(
            &held,
            &cal,
            crosscal::app::pipeline::Mode::Offline,
            crosscal::check::Thresholds::default(),
        )?;
        profile.validation = Some(crosscal::profile::Validation {
            runs: crosscal::profile::runs_used(&held),
            summary: report.summary.clone(),
            pass: report.pass,
        });
        if !a.json {
            println!("validation on held-out run(s) {}:", a.holdout.join(", "));
            print!("{}", format::check_summary(&report));
        }
    }
    if a.json {
        print!("{}", profile.to_json());
    } else {
        println!("{}", headline(&profile, session.n_samples(), ""));
        for w in session.warnings() {
            println!("warning: {w}");
        }
        print!("{}", format::profile_fits(&profile));
        print!("{}", format::nonlinear(&profile.nonlinear));
        print!("{}", format::stand(&profile.stand));
    }
    save_unless_dry(&a, &profile)?;
    Ok(Outcome::Ok)
}

/// `fit` on a protocol session (Ferraris or multi-position).
fn run_protocol(a: &Args, session: &Session) -> anyhow::Result<Outcome> {
    if a.stand || !a.holdout.is_empty() || a.robust {
        anyhow::bail!(
            "--stand, --holdout and --robust apply to stand sessions; {} is a protocol session",
            a.session.display()
        );
    }
    let preset = match a.model.as_str() {
        "default" => crosscal::estimate::protocol::default_preset(session),
        other => other,
    };
    let model = build_model(preset, &a.effects, &a.disable)?;
    let popts = crosscal::estimate::protocol::ProtocolOptions { classic_six_position: a.classic_six_position };
    let (fit, report) = crosscal::estimate::protocol::fit_protocol(session, &model, &popts)
        .with_context(|| format!("fitting {}", a.session.display()))?;
    if a.strict {
        fit.ensure_identifiable().with_context(|| format!("fitting {} (--strict)", a.session.display()))?;
    }
    let mut notes = session.warnings();
    notes.extend(report.warnings.iter().cloned());
    notes.extend(unidentifiable_notes(&fit));
    let mut profile = Profile::from_fit(session, &model, fit, notes);
    profile.protocol = Some(report);
    if a.json {
        print!("{}", profile.to_json());
    } else {
        println!("{}", headline(&profile, session.n_samples(), ""));
        if let Some(r) = &profile.protocol {
            print!("{}", format::protocol(r));
        }
        print!("{}", format::profile_fits(&profile));
    }
    save_unless_dry(a, &profile)?;
    Ok(Outcome::Ok)
}

/// Stores `--noise`'s report in the profile.
fn attach_noise(a: &Args, profile: &mut Profile) -> anyhow::Result<()> {
    if let Some(path) = &a.noise {
        let text = std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
        let r: crosscal::noise::NoiseReport = serde_json::from_str(&text).with_context(|| {
            format!("{}: not a noise report (write one with `crosscal noise --save`)", path.display())
        })?;
        profile.noise = Some(r);
    }
    Ok(())
}

/// A streamed fit's report and profile (the recordings were never held in memory).
fn run_streamed(a: &Args, model: &Model, sf: crosscal::estimate::stream::StreamedFit) -> anyhow::Result<Outcome> {
    if a.strict {
        sf.fit.ensure_identifiable().with_context(|| format!("fitting {} (--strict)", a.session.display()))?;
    }
    let mut notes = sf.warnings.clone();
    for run in &sf.manifest.runs {
        let eps = match run.motion {
            crosscal::session::MotionSpec::Conic { .. } => crosscal::motion::EPSILON_CONIC,
            _ => crosscal::motion::EPSILON_STATIC,
        };
        notes.push(format!("run {}: ε reference {eps}", run.name));
    }
    notes.extend(unidentifiable_notes(&sf.fit));
    let samples: usize = sf.runs.iter().map(|r| r.samples).sum();
    let mut profile = Profile::from_fit_of(&sf.manifest, sf.runs, model, sf.fit, notes);
    attach_noise(a, &mut profile)?;
    if a.json {
        print!("{}", profile.to_json());
    } else {
        println!("{}", headline(&profile, samples, " (streamed)"));
        for w in &sf.warnings {
            println!("warning: {w}");
        }
        print!("{}", format::profile_fits(&profile));
    }
    save_unless_dry(a, &profile)?;
    Ok(Outcome::Ok)
}

/// Saves the profile in the store unless `--dry-run`; says where.
fn save_unless_dry(a: &Args, profile: &Profile) -> anyhow::Result<()> {
    if !a.dry_run {
        let path = save(profile, &a.out).with_context(|| format!("saving the profile under {}", a.out.display()))?;
        if a.json {
            eprintln!("profile written to {}", path.display());
        } else {
            println!("profile written to {}", path.display());
        }
    }
    Ok(())
}

/// Notes for the profile on the coefficients held because the runs cannot identify them.
fn unidentifiable_notes(fit: &crosscal::estimate::Fit) -> Vec<String> {
    fit.gyro
        .unidentifiable
        .iter()
        .chain(&fit.accel.unidentifiable)
        .map(|u| format!("{} unidentifiable, held at {}: {}; remedy: {}", u.held, u.held_at, u.reason, u.remedy))
        .collect()
}

/// The first line `fit` prints: unit, runs, samples, model.
fn headline(profile: &Profile, samples: usize, how: &str) -> String {
    format!("unit {}: {} runs, {samples} samples{how}, model '{}'", profile.serial, profile.runs.len(), profile.model)
}
