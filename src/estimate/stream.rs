//! Fitting straight from the recordings, in bounded memory: each run's CSV is parsed row by
//! row (one reused record), the reference motion is evaluated per sample (conic: paper eq. 1
//! with the spec's eq. 2; static: constant) and every design row goes into a QR
//! accumulator; a second read gives the residual statistics, from the rows the first read
//! spilled in binary to a temporary file (64 bytes a sample on disk, none in
//! memory; without a writable temporary directory the text is parsed again). Memory is
//! O(parameters² + chunk) per run in flight, whatever the recordings' length; runs are
//! read in parallel.
//!
//! The arithmetic is that of the in-memory fit ([`super::fit`]): the same rows in the same
//! order through the same accumulators, so the two agree to the last bit.

use super::linear::{fit_samples, BlockFn, Samples, SamplesError, BLOCK};
use super::FitOptions;
use crate::frames::V3;
use crate::model::{Model, State};
use crate::motion::{Conic, Kinematics};
use crate::session::sanity::StreamScan;
use crate::session::RunUsed;
use crate::session::{
    read_manifest, rows_past_end, run_path, Manifest, MotionSpec, ReadOptions, Row, RowReader, RunSpec, SessionError,
};
use std::path::{Path, PathBuf};
use std::sync::Mutex;

/// One run read from its file on demand.
pub struct StreamRun<'a> {
    spec: &'a RunSpec,
    path: PathBuf,
    manifest: &'a Manifest,
    manifest_path: PathBuf,
    /// What the first read saw.
    seen: Mutex<Option<Seen>>,
    /// Gaps in t are errors.
    strict: bool,
    /// The used rows as parsed, in binary (an anonymous temporary file, written by the
    /// first read): later reads take them from here instead of parsing the text again.
    spill: Mutex<Option<Spill>>,
}

/// What the first read of a run's file saw.
#[derive(Debug, Clone, Default)]
struct Seen {
    sha256: String,
    /// Rows used.
    samples: usize,
    /// Gaps, saturation and spikes in the file (as [`crate::session::sanity::StreamScan`]
    /// finds them).
    warnings: Vec<String>,
    /// Temperature range of the rows used, °C.
    temp_range_c: Option<[f64; 2]>,
    /// A conic run's stretches off the stand's speed at its start and end (run index 0).
    off_speed: Option<super::spin::OffSpeed>,
}

/// The rows of a run as parsed, in a closed temporary file (reopened for each later read,
/// so that a session of a thousand runs does not hold a thousand files open). Removed when
/// dropped, and by the binary's signal handler if the process is interrupted.
struct Spill(tempfile::TempPath);

impl Spill {
    fn new(path: tempfile::TempPath) -> Self {
        crate::atomic::register_temporary(&path);
        Self(path)
    }
}

impl Drop for Spill {
    fn drop(&mut self) {
        crate::atomic::forget_temporary(&self.0);
    }
}

/// f64 values per spilled row: t, gyro x y z, accel x y z, temperature.
const SPILL_VALUES: usize = 8;

impl<'a> StreamRun<'a> {
    /// A conic or static run of a manifest; `None` for kinds that need the whole run in
    /// memory (reference motion with a derived ε, protocol runs, a conic run with a logged
    /// stand angle, whose rate and angular acceleration are the angle's derivatives).
    /// `strict`: a gap in t is an error, not a warning.
    pub fn new(
        manifest_path: &Path,
        manifest: &'a Manifest,
        spec: &'a RunSpec,
        strict: bool,
    ) -> Result<Option<Self>, SessionError> {
        if !matches!(spec.motion, MotionSpec::Conic { .. } | MotionSpec::Static { .. }) || spec.angle_column.is_some() {
            return Ok(None);
        }
        let path = run_path(manifest_path, spec)?;
        Ok(Some(Self {
            spec,
            path,
            manifest,
            manifest_path: manifest_path.to_path_buf(),
            seen: Mutex::new(None),
            strict,
            spill: Mutex::new(None),
        }))
    }

    fn seen(&self) -> Seen {
        self.seen.lock().ok().and_then(|s| s.clone()).unwrap_or_default()
    }

    /// What the profile records of this run (after a fit has read it).
    pub fn used(&self) -> RunUsed {
        let Seen { sha256, samples, temp_range_c, .. } = self.seen();
        RunUsed {
            name: self.spec.name.clone(),
            file: self.spec.file.clone(),
            sha256,
            samples,
            temp_range_c,
            temp_rate_range_c_s: None,
        }
    }

    /// Non-fatal findings in the run's file (after a fit has read it).
    pub fn warnings(&self) -> Vec<String> {
        self.seen().warnings
    }
}

/// The reference state of a conic or static run at each time stamp, in sensor axes.
struct Reference {
    conic: Option<crate::motion::ConicAt>,
    still: ([f64; 3], [f64; 3], [f64; 3]),
    mount: crate::frames::Mount,
}

impl Reference {
    fn of(spec: &RunSpec, g: f64) -> Self {
        let mount = spec.mount.clone();
        let to_sensor = |k: Kinematics| {
            (mount.to_sensor(k.w_rad_s).xyz, mount.to_sensor(k.e_rad_s2).xyz, mount.to_sensor(k.a_m_s2).xyz)
        };
        let conic = Conic::of(&spec.motion).map(|c| c.fixed(g));
        let still = match spec.motion {
            MotionSpec::Static { up_stand, earth_rate_rad_s } => to_sensor(Kinematics {
                w_rad_s: V3::new(earth_rate_rad_s),
                e_rad_s2: V3::new([0.0; 3]),
                a_m_s2: V3::new(up_stand.map(|u| u * g)),
            }),
            _ => ([0.0; 3], [0.0; 3], [0.0; 3]),
        };
        Self { conic, still, mount }
    }

    #[inline]
    fn at(&self, t_s: f64) -> ([f64; 3], [f64; 3], [f64; 3]) {
        match &self.conic {
            Some(c) => {
                let k = c.at(t_s);
                (
                    self.mount.to_sensor(k.w_rad_s).xyz,
                    self.mount.to_sensor(k.e_rad_s2).xyz,
                    self.mount.to_sensor(k.a_m_s2).xyz,
                )
            }
            None => self.still,
        }
    }
}

/// Gathers used rows into blocks of [`BLOCK`] states and outputs for the estimator.
struct Blocks<'f, 'g> {
    reference: Reference,
    f: &'f mut BlockFn<'g>,
    t0: f64,
    start_s: Option<f64>,
    used: usize,
    states: Vec<State>,
    gyro: Vec<[f64; 3]>,
    accel: Vec<[f64; 3]>,
    /// The check for a stand off its speed (a conic run's first read).
    speed: Option<super::spin::SpeedWindows>,
}

impl Blocks<'_, '_> {
    /// One used row (temperature already chosen); the block goes out when full.
    fn push(&mut self, row: &Row) {
        if self.used == 0 {
            self.t0 = row.t_s;
        }
        let (w, e, a) = self.reference.at(row.t_s);
        let t_session_s = crate::estimate::runs::session_time(self.start_s, row.t_s, self.t0);
        // The temperature's rate of change needs the samples after this one: a model that
        // reads it is not streamed (see `fit_streaming`), so it stays unknown here.
        self.states.push(State { t_session_s, w, e, a, temp_c: row.temp_c, temp_rate_c_s: f64::NAN });
        if let Some(s) = &mut self.speed {
            s.push(row.t_s, row.gyro, w);
        }
        self.gyro.push(row.gyro);
        self.accel.push(row.accel);
        self.used += 1;
        if self.states.len() == BLOCK {
            self.flush();
        }
    }

    /// The last, partial block.
    fn flush(&mut self) {
        if !self.states.is_empty() {
            (self.f)(&self.states, &self.gyro, &self.accel);
            self.states.clear();
            self.gyro.clear();
            self.accel.clear();
        }
    }
}

/// A row of the spill file: t, gyro, accel, temperature as little-endian f64.
fn spill_record(row: &Row) -> [u8; 8 * SPILL_VALUES] {
    let mut rec = [0u8; 8 * SPILL_VALUES];
    let values = [row.t_s, row.gyro[0], row.gyro[1], row.gyro[2], row.accel[0], row.accel[1], row.accel[2], row.temp_c];
    for (chunk, v) in rec.chunks_exact_mut(8).zip(values) {
        chunk.copy_from_slice(&v.to_le_bytes());
    }
    rec
}

impl StreamRun<'_> {
    fn io(&self, source: std::io::Error) -> SessionError {
        SessionError::Io { path: self.path.clone(), source }
    }

    /// A later read: the rows from the spill, bit for bit as parsed.
    fn read_spill(&self, path: &Path, blocks: &mut Blocks<'_, '_>) -> Result<(), SessionError> {
        use std::io::Read;
        let file = std::fs::File::open(path).map_err(|e| self.io(e))?;
        let mut input = std::io::BufReader::with_capacity(1 << 18, file);
        let mut rec = [0u8; 8 * SPILL_VALUES];
        let value = |rec: &[u8; 8 * SPILL_VALUES], i: usize| {
            let mut b = [0u8; 8];
            b.copy_from_slice(&rec[8 * i..8 * i + 8]);
            f64::from_le_bytes(b)
        };
        let mut row = Row::default();
        loop {
            match input.read_exact(&mut rec) {
                Ok(()) => {}
                Err(e) if e.kind() == std::io::ErrorKind::UnexpectedEof => break,
                Err(e) => return Err(self.io(e)),
            }
            row.t_s = value(&rec, 0);
            row.gyro = [value(&rec, 1), value(&rec, 2), value(&rec, 3)];
            row.accel = [value(&rec, 4), value(&rec, 5), value(&rec, 6)];
            row.temp_c = value(&rec, 7);
            blocks.push(&row);
        }
        blocks.flush();
        Ok(())
    }

    /// A read of the text: the first checks the whole file as the in-memory reader does,
    /// records what it saw and spills the used rows (if no temporary file can be written,
    /// later reads parse the text again).
    fn read_text(&self, blocks: &mut Blocks<'_, '_>) -> Result<(), SessionError> {
        let (file, _) = crate::session::open_recording(&self.path)?;
        let mut rdr =
            RowReader::new(&self.path, file, &self.manifest.units, self.manifest.g_m_s2, ReadOptions::default())?;
        let has_temp = rdr.has_temp();
        let known = self.seen.lock().ok().and_then(|s| s.clone());
        if known.is_some() {
            rdr.stop_hashing();
        }
        let mut scan = known.is_none().then(|| StreamScan::new(self.manifest.units.time.to_s()));
        if known.is_none() && matches!(self.spec.motion, MotionSpec::Conic { .. }) {
            blocks.speed = Some(super::spin::SpeedWindows::default());
        }
        let mut spill = if known.is_none() {
            tempfile::Builder::new()
                .prefix(&format!(".crosscal-{}-spill-", std::process::id()))
                .tempfile()
                .ok()
                .map(|f| std::io::BufWriter::with_capacity(1 << 18, f))
        } else {
            None
        };
        let (start, end) = self.spec.rows.unwrap_or((0, usize::MAX));
        let mut row = Row::default();
        let mut k = 0usize;
        let mut temps: Option<[f64; 2]> = None;
        while rdr.read_row(&mut row)? {
            if let Some(scan) = &mut scan {
                if let Some(gap) = scan.push(rdr.line(), row.t_s, row.gyro, row.accel).filter(|_| self.strict) {
                    return Err(gap.to_error(&self.path, rdr.t_column()));
                }
            }
            if k >= start && k < end {
                if !has_temp {
                    row.temp_c = self.spec.temperature_c.unwrap_or(f64::NAN);
                }
                temps = crate::stats::widen(temps, row.temp_c);
                if let Some(w) = &mut spill {
                    if std::io::Write::write_all(w, &spill_record(&row)).is_err() {
                        spill = None;
                    }
                }
                blocks.push(&row);
            }
            k += 1;
        }
        blocks.flush();
        if k == 0 {
            return Err(rdr.no_samples());
        }
        if self.spec.rows.is_some_and(|(_, end)| end > k) {
            return Err(rows_past_end(&self.manifest_path, self.spec, k));
        }
        if let Some(scan) = scan {
            let (gaps, warnings) = scan.finish(&self.path.display().to_string());
            if let Some(gap) = gaps.first().filter(|_| self.strict) {
                return Err(gap.to_error(&self.path, rdr.t_column()));
            }
            if let Ok(mut seen) = self.seen.lock() {
                let off_speed = blocks.speed.take().and_then(|s| s.finish(0));
                *seen =
                    Some(Seen { sha256: rdr.sha256(), samples: blocks.used, warnings, temp_range_c: temps, off_speed });
            }
            if let Some(file) = spill.and_then(|w| w.into_inner().ok()) {
                if let Ok(mut s) = self.spill.lock() {
                    *s = Some(Spill::new(file.into_temp_path()));
                }
            }
        }
        Ok(())
    }
}

impl Samples for StreamRun<'_> {
    fn run_name(&self) -> &str {
        &self.spec.name
    }

    fn for_each_block(&self, f: &mut BlockFn<'_>) -> Result<(), SessionError> {
        let mut blocks = Blocks {
            reference: Reference::of(self.spec, self.manifest.g_m_s2),
            f,
            t0: f64::NAN,
            start_s: self.spec.start_s,
            used: 0,
            states: Vec::with_capacity(BLOCK),
            gyro: Vec::with_capacity(BLOCK),
            accel: Vec::with_capacity(BLOCK),
            speed: None,
        };
        let spilled = self.spill.lock().ok().and_then(|s| s.as_ref().map(|f| f.0.to_path_buf()));
        match spilled {
            Some(path) => self.read_spill(&path, &mut blocks),
            None => self.read_text(&mut blocks),
        }
    }
}

/// A fit streamed from the files of a session.
#[derive(Debug, Clone)]
pub struct StreamedFit {
    /// The manifest.
    pub manifest: Manifest,
    /// The fit.
    pub fit: super::Fit,
    /// The runs as the profile records them.
    pub runs: Vec<RunUsed>,
    /// Non-fatal findings in the recordings (gaps, saturation, spikes), in run order.
    pub warnings: Vec<String>,
}

/// Errors of the streamed fit.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum StreamError {
    /// Reading the manifest or a recording failed.
    #[error(transparent)]
    Read(#[from] SessionError),
    /// The estimate failed.
    #[error(transparent)]
    Estimate(#[from] super::EstimateError),
    /// A run or the model needs the samples in memory.
    #[error("{0}")]
    NotStreamable(String),
}

/// Fits a linear model to a session read straight from its files (see the module docs);
/// with `strict`, a gap in t is an error naming its line.
pub(crate) fn fit_streaming(
    manifest_path: &Path,
    model: &Model,
    opts: &FitOptions,
    strict: bool,
) -> Result<StreamedFit, StreamError> {
    if !model.nonlinear().is_empty() || opts.robust {
        return Err(StreamError::NotStreamable(
            "nonlinear effects and the robust fit need the samples in memory: fit without --stream".into(),
        ));
    }
    let manifest = read_manifest(manifest_path)?;
    let mut runs = Vec::with_capacity(manifest.runs.len());
    for spec in &manifest.runs {
        match StreamRun::new(manifest_path, &manifest, spec, strict)? {
            Some(r) => runs.push(r),
            None => {
                return Err(StreamError::NotStreamable(format!(
                    "run '{}' is not conic or static: its reference must be held in memory; fit without --stream",
                    spec.name
                )))
            }
        }
    }
    if let Some(e) = model.effects().iter().find(|e| e.inputs().temperature_rate) {
        return Err(StreamError::NotStreamable(format!(
            "effect '{}' reads the temperature's rate of change, smoothed over the samples around each one: fit without --stream",
            e.id()
        )));
    }
    if let Some(e) = model.effects().iter().find(|e| e.needs_temperature()) {
        if manifest.runs.iter().any(|r| r.temperature_c.is_none()) {
            return Err(StreamError::NotStreamable(format!(
                "effect '{}' needs temperatures: fit without --stream to use a temp column",
                e.id()
            )));
        }
    }
    let sources: Vec<&dyn Samples> = runs.iter().map(|r| r as &dyn Samples).collect();
    let fit = fit_samples(model, &sources, &[], opts).map_err(|e| match e {
        SamplesError::Read(e) => StreamError::Read(e),
        SamplesError::Estimate(e) => StreamError::Estimate(e),
    })?;
    let used = runs.iter().map(StreamRun::used).collect();
    let mut warnings: Vec<String> = runs.iter().flat_map(StreamRun::warnings).collect();
    // Runs recorded while the stand was not at its speed, as the in-memory fit warns.
    let off: Vec<super::spin::OffSpeed> = runs
        .iter()
        .enumerate()
        .filter_map(|(i, r)| r.seen().off_speed.map(|o| super::spin::OffSpeed { run: i, ..o }))
        .collect();
    if !off.is_empty() {
        let names: Vec<&str> = manifest.runs.iter().map(|r| r.name.as_str()).collect();
        warnings.push(super::spin::warning(&off, &names, super::spin::FIT_KEEPS));
    }
    drop(sources);
    drop(runs);
    Ok(StreamedFit { manifest, fit, runs: used, warnings })
}
