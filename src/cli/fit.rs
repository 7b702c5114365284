//! `crosscal fit`.

use super::{format, ModelArgs, Outcome};
use crate::errln;
use anyhow::Context;
use crosscal::app::fit::{fit_profile, store, Fitted};
use crosscal::estimate::protocol::ProtocolOptions;
use crosscal::estimate::{FitData, FitRequest, ModelChoice, StreamPolicy};
use std::path::PathBuf;

/// Options of `fit`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// The session manifest (session.json).
    session: PathBuf,
    /// Profile store; the profile goes to <out>/<serial>/<UTC time>.json.
    #[arg(long, default_value = "calib-profiles")]
    out: PathBuf,
    #[command(flatten)]
    model: ModelArgs,
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
    /// Standard errors that cover slow noise (flicker, bias random walk) as well as the
    /// fast noise: the bias wandering over the session widens them (one more pass over the
    /// samples). Use it on MEMS units whose `crosscal noise` shows bias instability or rate
    /// random walk.
    #[arg(long)]
    slow_noise: bool,
    /// Gaps in t and unidentifiable coefficients are errors instead of warnings.
    #[arg(long)]
    strict: bool,
    /// Leave these runs out of the fit and validate the profile on them (repeatable); the
    /// held-out errors and reduction factors are stored in the profile.
    #[arg(long)]
    holdout: Vec<String>,
    /// Estimate each conic run's actual cone angle, rate, phase and rate drift with the coefficients
    /// (for a stand that does not sit exactly at its nominal settings).
    #[arg(long)]
    stand: bool,
    /// Ferraris sessions: biases by the classic six-position formulas (each accelerometer bias
    /// from the two faces along its axis, the gyro bias as the mean of all static samples), as
    /// imucal computes them, instead of least squares over all six faces.
    #[arg(long)]
    classic_six_position: bool,
    /// Multi-position sessions: when the declared initial rest is not at rest (motion or a
    /// drifting gyro in it), use its still part and say so, instead of refusing the fit.
    #[arg(long)]
    trim_rest: bool,
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

pub fn run(a: Args) -> anyhow::Result<Outcome> {
    let spec = a.model.spec(&a.disable);
    let mut req = FitRequest::new(FitData::Manifest(&a.session), ModelChoice::Spec(&spec));
    req.options.robust = a.robust;
    req.options.slow_noise = a.slow_noise;
    req.strict = a.strict;
    req.stand = a.stand;
    req.holdout = a.holdout.clone();
    req.streaming = if a.stream { StreamPolicy::Require } else { StreamPolicy::Auto };
    req.protocol = ProtocolOptions { classic_six_position: a.classic_six_position, trim_rest: a.trim_rest };
    let noise = match &a.noise {
        Some(path) => Some(read_noise(path)?),
        None => None,
    };
    let fitted = fit_profile(&req, noise)?;
    // The profile is saved before anything is printed: a closed stdout never costs it.
    let saved = if a.dry_run { None } else { Some(store(&fitted.profile, &a.out)?) };
    print_fit(&a, &fitted)?;
    if let Some(path) = saved {
        if a.json {
            errln!("profile written to {}", path.display());
        } else {
            super::out(format_args!("profile written to {}\n", path.display()))?;
        }
    }
    Ok(Outcome::Ok)
}

/// What `fit` prints: the validation, then the profile (table or JSON).
fn print_fit(a: &Args, f: &Fitted) -> anyhow::Result<()> {
    let p = &f.profile;
    if a.json {
        return super::out(format_args!("{}", p.to_json()));
    }
    let mut s = String::new();
    if let Some(report) = &f.validation {
        s += &format!("validation on held-out run(s) {}:\n", a.holdout.join(", "));
        s += &format::check_summary(report);
    }
    let how = if f.streamed { " (streamed)" } else { "" };
    s += &format!("unit {}: {} runs, {} samples{how}, model '{}'\n", p.serial, p.runs.len(), f.samples, p.model);
    for w in &f.warnings {
        s += &format!("warning: {w}\n");
    }
    if let Some(r) = &p.protocol {
        s += &format::protocol(r);
    }
    s += &format::profile_fits(p);
    s += &format::nonlinear(&p.nonlinear);
    s += &format::stand(&p.stand, p.stand_base.as_ref());
    super::out(format_args!("{s}"))
}

/// A noise report written by `crosscal noise --save`.
pub fn read_noise(path: &std::path::Path) -> anyhow::Result<crosscal::noise::NoiseReport> {
    let text = crosscal::atomic::read_text(path).with_context(|| format!("reading {}", path.display()))?;
    serde_json::from_str(&text)
        .with_context(|| format!("{}: not a noise report (write one with `crosscal noise --save`)", path.display()))
}
