//! The fit entry point: [`fit`] of a [`FitRequest`]. Callers say what to fit and how; this
//! module chooses between the streamed, in-memory, stand-settings and protocol fits.

use super::protocol::{self, ProtocolOptions, ProtocolReport};
use super::{fit_runs, memory, stand, stream, tracks, EstimateError, Fit, FitOptions, FitRun};
use crate::model::{Model, ModelSpec, Preset};
use crate::motion::DerivativeConfig;
use crate::session::{Manifest, RunUsed, Session};
use std::path::{Path, PathBuf};

/// What to fit.
#[derive(Debug, Clone, Copy)]
pub enum FitData<'a> {
    /// A session manifest on disk: streamed from its files when the runs and the request
    /// allow it, read whole otherwise.
    Manifest(&'a Path),
    /// A session in memory.
    Session(&'a Session),
    /// Runs already prepared for the estimator (tracks beside outputs): for refits on
    /// subsets and candidates, as `diagnose` makes them.
    Runs(&'a [FitRun<'a>]),
}

/// Which model to fit.
#[derive(Debug, Clone, Copy)]
pub enum ModelChoice<'a> {
    /// As a user names it; its `default` preset stands for a protocol session's own.
    Spec(&'a ModelSpec),
    /// Exactly this model.
    Exact(&'a Model),
}

/// Whether a session on disk is read as a stream.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum StreamPolicy {
    /// Streamed whenever the runs and the request allow it, else read whole.
    #[default]
    Auto,
    /// Streamed, or an error saying why it cannot be.
    Require,
    /// Read whole.
    Never,
}

/// A fit to carry out: the data, the model and how.
#[derive(Debug, Clone)]
pub struct FitRequest<'a> {
    /// What to fit.
    pub data: FitData<'a>,
    /// The model.
    pub model: ModelChoice<'a>,
    /// Numerical settings (robust, known noise, screening, …).
    pub options: FitOptions,
    /// Gaps in t and unidentifiable coefficients are errors, not warnings.
    pub strict: bool,
    /// Estimate each conic run's cone angle, rate and phase with the coefficients.
    pub stand: bool,
    /// Runs left out of the fit (validated by the caller).
    pub holdout: Vec<String>,
    /// Streaming of a session on disk.
    pub streaming: StreamPolicy,
    /// Choices of protocol (Ferraris, multi-position) fits.
    pub protocol: ProtocolOptions,
}

impl<'a> FitRequest<'a> {
    /// A request with default settings.
    pub fn new(data: FitData<'a>, model: ModelChoice<'a>) -> Self {
        Self {
            data,
            model,
            options: FitOptions::default(),
            strict: false,
            stand: false,
            holdout: Vec::new(),
            streaming: StreamPolicy::Auto,
            protocol: ProtocolOptions::default(),
        }
    }

    /// Exactly `model` on prepared runs.
    pub fn runs(model: &'a Model, runs: &'a [FitRun<'a>]) -> Self {
        Self::new(FitData::Runs(runs), ModelChoice::Exact(model))
    }

    /// Exactly `model` on a session in memory.
    pub fn session(model: &'a Model, session: &'a Session) -> Self {
        Self::new(FitData::Session(session), ModelChoice::Exact(model))
    }

    /// With these numerical settings.
    pub fn options(mut self, options: FitOptions) -> Self {
        self.options = options;
        self
    }
}

/// Where the fitted samples came from (absent for prepared runs).
#[derive(Debug, Clone, PartialEq)]
pub struct FitSource {
    /// The manifest's path.
    pub manifest_path: PathBuf,
    /// The manifest (all runs, held-out ones included).
    pub manifest: Manifest,
    /// The runs fitted, as a profile records them.
    pub runs: Vec<RunUsed>,
    /// Samples fitted.
    pub samples: usize,
}

/// A fit with everything a profile or a report needs about how it was made.
#[derive(Debug, Clone)]
pub struct FitOutcome {
    /// The coefficients and statistics.
    pub fit: Fit,
    /// The model fitted (a protocol session's preset when the request left it to the data).
    pub model: Model,
    /// The data fitted.
    pub source: Option<FitSource>,
    /// Non-fatal findings in the recordings (gaps, saturation, spikes), in run order.
    pub warnings: Vec<String>,
    /// Notes for the profile: the findings, how ε was known per run, protocol warnings and
    /// the coefficients held because the runs cannot identify them.
    pub notes: Vec<String>,
    /// Pose and turn residuals of a protocol fit.
    pub protocol: Option<ProtocolReport>,
    /// Whether the recordings were streamed (never held in memory).
    pub streamed: bool,
}

/// Fits as the request says (see the module documentation).
pub fn fit(req: &FitRequest<'_>) -> Result<FitOutcome, EstimateError> {
    match req.data {
        FitData::Runs(runs) => fit_prepared(req, runs),
        FitData::Session(session) => fit_session(req, session),
        FitData::Manifest(path) => {
            let streamable = req.streaming != StreamPolicy::Never;
            if streamable {
                let why = if req.stand || !req.holdout.is_empty() || req.options.robust {
                    Some("--stand, --holdout and --robust need the samples in memory".to_string())
                } else {
                    None
                };
                match why {
                    Some(why) if req.streaming == StreamPolicy::Require => {
                        return Err(EstimateError::Request(format!("{}: {why}", path.display())))
                    }
                    Some(_) => {}
                    None => {
                        let model = resolve(req, Preset::Default)?;
                        match stream::fit_streaming(path, &model, &req.options, req.strict) {
                            Ok(sf) => return finish_streamed(req, path, model, sf),
                            Err(stream::StreamError::NotStreamable(why)) => {
                                if req.streaming == StreamPolicy::Require {
                                    return Err(EstimateError::Request(format!("{}: {why}", path.display())));
                                }
                            }
                            Err(stream::StreamError::Read(source)) => {
                                return Err(EstimateError::Read { path: path.to_path_buf(), source })
                            }
                            Err(stream::StreamError::Estimate(e)) => return Err(e),
                        }
                    }
                }
            }
            let session = Session::load_with(path, req.strict)
                .map_err(|source| EstimateError::Read { path: path.to_path_buf(), source })?;
            fit_session(req, &session)
        }
    }
}

/// The model of a request, `default` standing for `default_preset`.
fn resolve(req: &FitRequest<'_>, default_preset: Preset) -> Result<Model, EstimateError> {
    Ok(match req.model {
        ModelChoice::Spec(spec) => spec.build_with_default(default_preset)?,
        ModelChoice::Exact(m) => m.clone(),
    })
}

/// Notes naming the coefficients held because the runs cannot identify them.
fn unidentifiable_notes(fit: &Fit) -> Vec<String> {
    fit.gyro
        .unidentifiable
        .iter()
        .chain(&fit.accel.unidentifiable)
        .map(|u| format!("{} unidentifiable, held at {}: {}; remedy: {}", u.held, u.held_at, u.reason, u.remedy))
        .collect()
}

/// Fails in strict mode when the runs could not identify every coefficient.
fn check_strict(req: &FitRequest<'_>, fit: &Fit) -> Result<(), EstimateError> {
    if req.strict {
        fit.ensure_identifiable()?;
    }
    Ok(())
}

fn fit_prepared(req: &FitRequest<'_>, runs: &[FitRun<'_>]) -> Result<FitOutcome, EstimateError> {
    if req.stand || !req.holdout.is_empty() {
        return Err(EstimateError::Request(
            "stand settings and held-out runs need a session, not prepared runs".into(),
        ));
    }
    let model = resolve(req, Preset::Default)?;
    let fit = memory::fit_in_memory(&model, runs, &req.options)?;
    check_strict(req, &fit)?;
    let notes = unidentifiable_notes(&fit);
    Ok(FitOutcome { fit, model, source: None, warnings: Vec::new(), notes, protocol: None, streamed: false })
}

fn finish_streamed(
    req: &FitRequest<'_>,
    path: &Path,
    model: Model,
    mut sf: stream::StreamedFit,
) -> Result<FitOutcome, EstimateError> {
    check_strict(req, &sf.fit)?;
    sf.warnings.extend(sf.manifest.source.as_ref().and_then(crate::session::Source::applied_warning));
    let mut notes = sf.warnings.clone();
    for run in &sf.manifest.runs {
        let eps = match run.motion {
            crate::session::MotionSpec::Conic { .. } => crate::motion::EPSILON_CONIC,
            _ => crate::motion::EPSILON_STATIC,
        };
        notes.push(format!("run {}: ε reference {eps}", run.name));
    }
    notes.extend(unidentifiable_notes(&sf.fit));
    let samples = sf.runs.iter().map(|r| r.samples).sum();
    Ok(FitOutcome {
        fit: sf.fit,
        model,
        source: Some(FitSource { manifest_path: path.to_path_buf(), manifest: sf.manifest, runs: sf.runs, samples }),
        warnings: sf.warnings,
        notes,
        protocol: None,
        streamed: true,
    })
}

fn source_of(session: &Session) -> FitSource {
    FitSource {
        manifest_path: session.manifest_path.clone(),
        manifest: session.manifest.clone(),
        runs: session.runs_used(),
        samples: session.n_samples(),
    }
}

fn fit_session(req: &FitRequest<'_>, full: &Session) -> Result<FitOutcome, EstimateError> {
    if full.is_protocol() {
        return fit_protocol_session(req, full);
    }
    let model = resolve(req, Preset::Default)?;
    for h in &req.holdout {
        if !full.runs.iter().any(|r| &r.spec.name == h) {
            let names: Vec<&str> = full.runs.iter().map(|r| r.spec.name.as_str()).collect();
            return Err(EstimateError::Request(format!(
                "held-out run '{h}': no such run in {} (runs: {})",
                full.manifest_path.display(),
                names.join(", ")
            )));
        }
    }
    // Without held-out runs the fit uses the session as given (no copy of its samples).
    let session = if req.holdout.is_empty() {
        std::borrow::Cow::Borrowed(full)
    } else {
        let kept = full.subset(|n| !req.holdout.iter().any(|h| h == n));
        if kept.runs.is_empty() {
            return Err(EstimateError::Request("every run is held out: keep at least one to fit".into()));
        }
        std::borrow::Cow::Owned(kept)
    };
    let deriv = DerivativeConfig::default();
    let tr = tracks(&session, &deriv);
    let fit = if req.stand {
        stand::fit_with_stand(&model, &session, &deriv, &req.options)?
    } else {
        memory::fit_in_memory(&model, &fit_runs(&session, &tr), &req.options)?
    };
    check_strict(req, &fit)?;
    let mut warnings = session.warnings();
    let motions: Vec<&crate::session::MotionSpec> = session.runs.iter().map(|r| &r.spec.motion).collect();
    let off = super::spin::off_speed(&fit_runs(&session, &tr), &motions);
    if !off.is_empty() {
        let names: Vec<&str> = session.runs.iter().map(|r| r.spec.name.as_str()).collect();
        warnings.push(super::spin::warning(&off, &names, super::spin::FIT_KEEPS));
    }
    let mut notes = warnings.clone();
    for (run, t) in session.runs.iter().zip(&tr) {
        notes.push(format!("run {}: ε reference {}", run.spec.name, t.epsilon_source));
    }
    notes.extend(unidentifiable_notes(&fit));
    let mut source = source_of(&session);
    source.manifest = full.manifest.clone();
    Ok(FitOutcome { fit, model, source: Some(source), warnings, notes, protocol: None, streamed: false })
}

fn fit_protocol_session(req: &FitRequest<'_>, session: &Session) -> Result<FitOutcome, EstimateError> {
    if req.stand || !req.holdout.is_empty() || req.options.robust {
        return Err(EstimateError::Request(format!(
            "--stand, --holdout and --robust apply to stand sessions; {} is a protocol session",
            session.manifest_path.display()
        )));
    }
    let model = resolve(req, protocol::default_preset(session))?;
    let (fit, report) = protocol::fit_protocol(session, &model, &req.protocol)?;
    check_strict(req, &fit)?;
    let warnings = session.warnings();
    let mut notes = warnings.clone();
    notes.extend(report.warnings.iter().cloned());
    notes.extend(unidentifiable_notes(&fit));
    Ok(FitOutcome {
        fit,
        model,
        source: Some(source_of(session)),
        warnings,
        notes,
        protocol: Some(report),
        streamed: false,
    })
}
