//! `crosscal._crosscal`: the native half of the Python package. Thin: every number comes
//! from the `crosscal` library's use cases (`crosscal::app`), the same functions the
//! command line calls, so a fit or a correction from Python equals the command's bit for
//! bit. Reports cross as JSON text (the library's serde types) and samples as numpy arrays:
//! inputs are read in place (C-contiguous float64 arrays are borrowed, never copied, where
//! the library can use them as they are) and outputs are Rust buffers handed to numpy
//! without a copy. Long calls release the GIL. Errors become the exception class of their
//! exit code (`crosscal.errors`), with the command line's message.

// The library's errors carry their whole cause chain by value (file, line, column); these
// calls run once per user call.
#![allow(clippy::result_large_err)]

use crosscal::app::arrays::{BlockCorrector, BlockOut, IoUnits};
use crosscal::app::diagnose::Diagnosed;
use crosscal::app::validate::Mode;
use crosscal::session::memory::Columns;
use numpy::ndarray::Array2;
use numpy::{IntoPyArray, PyArray1, PyArray2, PyArrayMethods, PyReadonlyArray1, PyReadonlyArray2};
use numpy::{PyReadwriteArray1, PyReadwriteArray2, PyUntypedArrayMethods};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use std::path::{Path, PathBuf};
use std::sync::Arc;

/// The Python exception for an error of exit code `code` (`crosscal.errors.for_code`).
fn raise(py: Python<'_>, code: u8, message: String) -> PyErr {
    let made =
        py.import("crosscal.errors").and_then(|m| m.getattr("for_code")).and_then(|f| f.call1((code, message.clone())));
    match made {
        Ok(e) => PyErr::from_value(e),
        Err(_) => PyValueError::new_err(message),
    }
}

/// Any library error as its exception: the message is the whole cause chain, as the
/// command line prints it after "error: ".
fn err<E: std::error::Error + 'static>(py: Python<'_>, e: E) -> PyErr {
    raise(py, crosscal::app::errors::exit_code(&e), crosscal::app::chain(&e))
}

fn usage(py: Python<'_>, msg: impl Into<String>) -> PyErr {
    raise(py, crosscal::app::errors::EXIT_INPUT, msg.into())
}

/// Bytes per sample a call keeps beside its inputs: time, six axes and a flag in the
/// outputs, and as much again of working buffers (derivatives, a corrected copy).
const WORK_BYTES_PER_SAMPLE: u128 = 2 * (8 + 48 + 1);

/// Checks, before the work starts, that the memory `what` needs for `samples` samples can
/// be had: the allocation is asked for and given back, so a refusal is the package's
/// `OutOfMemoryError` and never an abort of the interpreter (Rust's allocator aborts on a
/// refused allocation in the middle of a computation).
fn probe_memory(py: Python<'_>, samples: usize, what: &str) -> PyResult<()> {
    let bytes = samples as u128 * WORK_BYTES_PER_SAMPLE;
    // More than the machine has (RAM and swap) can never be had, whatever the kernel's
    // overcommit policy would promise first.
    let beyond_machine = machine_bytes().is_some_and(|m| bytes > m);
    let refused = beyond_machine
        || match usize::try_from(bytes) {
            Ok(b) if b <= isize::MAX as usize => Vec::<u8>::new().try_reserve_exact(b).is_err(),
            _ => true,
        };
    if !refused {
        return Ok(());
    }
    let message = format!(
        "{what}: {samples} samples need about {:.3e} bytes of memory beside the inputs, and the allocation was refused: work in blocks (Streaming.push_block with out=) or on fewer samples",
        bytes as f64
    );
    let made = py
        .import("crosscal.errors")
        .and_then(|m| m.getattr("OutOfMemoryError"))
        .and_then(|c| c.call1((message.clone(),)));
    Err(match made {
        Ok(e) => PyErr::from_value(e),
        Err(_) => pyo3::exceptions::PyMemoryError::new_err(message),
    })
}

/// RAM and swap of this machine, bytes (`MemTotal` + `SwapTotal` of /proc/meminfo; `None`
/// where there is no such file).
fn machine_bytes() -> Option<u128> {
    let text = std::fs::read_to_string("/proc/meminfo").ok()?;
    let kib = |key: &str| -> Option<u128> {
        let line = text.lines().find(|l| l.starts_with(key))?;
        line[key.len()..].trim().trim_end_matches("kB").trim().parse().ok()
    };
    Some((kib("MemTotal:")? + kib("SwapTotal:").unwrap_or(0)) * 1024)
}

/// A C-contiguous (n, 3) float64 array as n triples, borrowed.
fn triples<'a>(py: Python<'_>, a: &'a PyReadonlyArray2<'_, f64>, what: &str) -> PyResult<&'a [[f64; 3]]> {
    if a.shape()[1] != 3 {
        return Err(usage(py, format!("{what}: expected an array of shape (n, 3), found {:?}", a.shape())));
    }
    let flat = a.as_slice().map_err(|_| usage(py, format!("{what}: the array is not C-contiguous")))?;
    Ok(flat.as_chunks::<3>().0)
}

fn slice<'a>(py: Python<'_>, a: &'a PyReadonlyArray1<'_, f64>, what: &str) -> PyResult<&'a [f64]> {
    a.as_slice().map_err(|_| usage(py, format!("{what}: the array is not contiguous")))
}

/// A record's columns borrowed from its arrays (`temp` when given).
fn columns<'a>(
    py: Python<'_>,
    t: &'a PyReadonlyArray1<'_, f64>,
    gyro: &'a PyReadonlyArray2<'_, f64>,
    accel: &'a PyReadonlyArray2<'_, f64>,
    temp: Option<&'a PyReadonlyArray1<'_, f64>>,
) -> PyResult<Columns<'a>> {
    let temp_c = match temp {
        Some(x) => Some(slice(py, x, "temp")?),
        None => None,
    };
    Ok(Columns { t: slice(py, t, "t")?, gyro: triples(py, gyro, "gyro")?, accel: triples(py, accel, "accel")?, temp_c })
}

/// n triples as a numpy (n, 3) array, without a copy.
fn to_numpy<'py>(py: Python<'py>, v: Vec<[f64; 3]>) -> PyResult<Bound<'py, PyArray2<f64>>> {
    let n = v.len();
    let a = Array2::from_shape_vec((n, 3), v.into_flattened()).map_err(|e| PyValueError::new_err(e.to_string()))?;
    Ok(a.into_pyarray(py))
}

/// A session in memory: read from a manifest or built from arrays.
#[pyclass(frozen, module = "crosscal._crosscal")]
struct Session {
    inner: Arc<crosscal::session::Session>,
    /// The manifest it was read from (None: built in memory).
    path: Option<PathBuf>,
}

#[pymethods]
impl Session {
    /// The unit's serial number.
    #[getter]
    fn serial(&self) -> String {
        self.inner.manifest.serial.clone()
    }

    /// The manifest's path (None for a session built in memory).
    #[getter]
    fn path(&self) -> Option<String> {
        self.path.as_ref().map(|p| p.display().to_string())
    }

    /// The manifest as JSON text.
    fn manifest_json(&self) -> String {
        self.inner.manifest.to_json()
    }

    /// Run names, in manifest order.
    #[getter]
    fn run_names(&self) -> Vec<String> {
        self.inner.runs.iter().map(|r| r.spec.name.clone()).collect()
    }

    /// Samples over all runs.
    #[getter]
    fn n_samples(&self) -> usize {
        self.inner.n_samples()
    }

    /// What the reader found (gaps, saturation, spikes, an autopilot's calibration).
    #[getter]
    fn warnings(&self) -> Vec<String> {
        self.inner.warnings()
    }

    /// Run `index`'s samples in the manifest's units: (t, gyro (n, 3), accel (n, 3), temp or None).
    #[allow(clippy::type_complexity)]
    fn run_columns<'py>(
        &self,
        py: Python<'py>,
        index: usize,
    ) -> PyResult<(
        Bound<'py, PyArray1<f64>>,
        Bound<'py, PyArray2<f64>>,
        Bound<'py, PyArray2<f64>>,
        Option<Bound<'py, PyArray1<f64>>>,
    )> {
        let run = self.inner.runs.get(index).ok_or_else(|| usage(py, format!("no run {index}")))?;
        let m = &self.inner.manifest;
        let (kt, kg, ka) = (m.units.time.to_s(), m.units.gyro.to_rad_s(), m.units.accel.to_m_s2(m.g_m_s2));
        let r = &run.rec;
        let t: Vec<f64> = r.t_s.iter().map(|t| t / kt).collect();
        let g = r.gyro.iter().map(|v| [v[0] / kg, v[1] / kg, v[2] / kg]).collect();
        let a = r.accel.iter().map(|v| [v[0] / ka, v[1] / ka, v[2] / ka]).collect();
        let temp = r.temp_c.clone().map(|v| v.into_pyarray(py));
        Ok((t.into_pyarray(py), to_numpy(py, g)?, to_numpy(py, a)?, temp))
    }

    /// Writes the session (manifest and one CSV per run) into `folder`, which must not
    /// hold one already; returns the manifest's path.
    fn save(&self, py: Python<'_>, folder: PathBuf) -> PyResult<String> {
        let s = self.inner.clone();
        let path = py.detach(move || crosscal::simulate::write_session(&s, &folder)).map_err(|e| err(py, e))?;
        Ok(path.display().to_string())
    }
}

/// Reads a session manifest and its recordings.
#[pyfunction]
#[pyo3(signature = (path, strict = false))]
fn read_session(py: Python<'_>, path: PathBuf, strict: bool) -> PyResult<Session> {
    let p = path.clone();
    let s = py.detach(move || crosscal::session::Session::load_with(&p, strict)).map_err(|e| err(py, e))?;
    Ok(Session { inner: Arc::new(s), path: Some(path) })
}

/// One run's arrays as handed over from Python.
type RunArrays<'py> = (
    PyReadonlyArray1<'py, f64>,
    PyReadonlyArray2<'py, f64>,
    PyReadonlyArray2<'py, f64>,
    Option<PyReadonlyArray1<'py, f64>>,
);

/// A session from a manifest (JSON text) and each run's (t, gyro, accel, temp or None) in
/// the manifest's units.
#[pyfunction]
fn session_from_columns(py: Python<'_>, manifest_json: &str, runs: Vec<RunArrays<'_>>) -> PyResult<Session> {
    probe_memory(py, runs.iter().map(|r| r.0.len()).sum(), "Session.from_arrays")?;
    let mut cols = Vec::with_capacity(runs.len());
    for (i, (t, g, a, temp)) in runs.iter().enumerate() {
        let temp_c = match temp {
            Some(x) => Some(slice(py, x, &format!("run {i} temp"))?),
            None => None,
        };
        cols.push(Columns {
            t: slice(py, t, &format!("run {i} t"))?,
            gyro: triples(py, g, &format!("run {i} gyro"))?,
            accel: triples(py, a, &format!("run {i} accel"))?,
            temp_c,
        });
    }
    let s =
        py.detach(|| crosscal::session::memory::session_from_columns(manifest_json, &cols)).map_err(|e| err(py, e))?;
    Ok(Session { inner: Arc::new(s), path: None })
}

/// The model named by a preset, effects and held coefficients.
fn model_spec(
    py: Python<'_>,
    preset: &str,
    effects: Vec<String>,
    disable: Vec<String>,
) -> PyResult<crosscal::model::ModelSpec> {
    let preset = preset
        .parse()
        .map_err(|_| usage(py, format!("model '{preset}': expected one of {}", crosscal::model::Preset::NAMES)))?;
    Ok(crosscal::model::ModelSpec { preset, effects, disable })
}

/// What `fit` returns: profile JSON, samples, streamed, warnings, validation JSON or None.
type FitOut = (String, usize, bool, Vec<String>, Option<String>);

/// Fits a profile: (profile JSON, samples, streamed, warnings, validation JSON or None).
#[pyfunction]
#[pyo3(signature = (session, preset, effects, disable, robust, strict, holdout, stand, classic_six_position, trim_rest, stream, noise_json, slow_noise=false))]
#[allow(clippy::too_many_arguments)]
fn fit(
    py: Python<'_>,
    session: &Session,
    preset: &str,
    effects: Vec<String>,
    disable: Vec<String>,
    robust: bool,
    strict: bool,
    holdout: Vec<String>,
    stand: bool,
    classic_six_position: bool,
    trim_rest: bool,
    stream: bool,
    noise_json: Option<String>,
    slow_noise: bool,
) -> PyResult<FitOut> {
    use crosscal::estimate::{FitData, FitRequest, ModelChoice, StreamPolicy};
    let spec = model_spec(py, preset, effects, disable)?;
    let noise: Option<crosscal::noise::NoiseReport> = match noise_json {
        Some(j) => Some(serde_json::from_str(&j).map_err(|e| usage(py, format!("noise: not a noise report: {e}")))?),
        None => None,
    };
    // A session read from disk is fitted from its manifest, exactly as `crosscal fit` does
    // (the streamed fit where it applies).
    let data = match &session.path {
        Some(p) => FitData::Manifest(p),
        None => FitData::Session(&session.inner),
    };
    let mut req = FitRequest::new(data, ModelChoice::Spec(&spec));
    req.options.robust = robust;
    req.options.slow_noise = slow_noise;
    req.strict = strict;
    req.stand = stand;
    req.holdout = holdout;
    req.streaming = if stream { StreamPolicy::Require } else { StreamPolicy::Auto };
    req.protocol = crosscal::estimate::protocol::ProtocolOptions { classic_six_position, trim_rest };
    let fitted = py.detach(|| crosscal::app::fit::fit_profile(&req, noise)).map_err(|e| err(py, e))?;
    let validation = match &fitted.validation {
        Some(v) => Some(serde_json::to_string(v).map_err(|e| PyValueError::new_err(e.to_string()))?),
        None => None,
    };
    Ok((fitted.profile.to_json(), fitted.samples, fitted.streamed, fitted.warnings, validation))
}

/// Loads user effects (an effects file, or TOML text when `is_text`) into the process's
/// catalogue, as `--effects-file` does for a command; returns their ids.
#[pyfunction]
#[pyo3(signature = (source, is_text))]
fn register_effects(py: Python<'_>, source: &str, is_text: bool) -> PyResult<Vec<String>> {
    let loaded = if is_text {
        crosscal::model::user::load_str("<effects>", source)
    } else {
        crosscal::model::user::load_file(std::path::Path::new(source))
    }
    .map_err(|e| err(py, e))?;
    crosscal::model::user::register(&loaded);
    Ok(loaded.iter().map(|e| e.definition().id.clone()).collect())
}

/// A profile from JSON text, checked as a profile file is (`label` names it in messages).
fn profile_of(py: Python<'_>, json: &str, label: &str) -> PyResult<crosscal::profile::Profile> {
    crosscal::profile::Profile::from_json(Path::new(label), json).map_err(|e| err(py, e))
}

/// Checks profile JSON text and returns it as crosscal writes it.
#[pyfunction]
fn profile_normalise(py: Python<'_>, json: &str, label: &str) -> PyResult<String> {
    Ok(profile_of(py, json, label)?.to_json())
}

/// Reads a profile file, or a unit's folder of the store (its newest): (path read, JSON).
#[pyfunction]
fn profile_read(py: Python<'_>, path: PathBuf) -> PyResult<(String, String)> {
    let (used, p) = crosscal::profile::Profile::read_or_latest(&path).map_err(|e| err(py, e))?;
    Ok((used.display().to_string(), p.to_json()))
}

/// A unit's datasheet from a profile store (`crosscal datasheet --json`): its JSON.
#[pyfunction]
#[pyo3(signature = (store, unit, at, gyro_range_deg_s, accel_range_g))]
fn datasheet(
    py: Python<'_>,
    store: PathBuf,
    unit: &str,
    at: Option<String>,
    gyro_range_deg_s: Option<f64>,
    accel_range_g: Option<f64>,
) -> PyResult<String> {
    let opts = crosscal::datasheet::DatasheetOptions {
        gyro_range_rad_s: gyro_range_deg_s.map(f64::to_radians),
        accel_range_m_s2: accel_range_g.map(|g| g * 9.80665),
    };
    let d = py
        .detach(|| crosscal::app::datasheet::datasheet(&store, unit, at.as_deref(), &opts))
        .map_err(|e| err(py, e))?;
    serde_json::to_string(&d).map_err(|e| usage(py, e.to_string()))
}

/// Mean, standard deviation, Cpk and its 95 % interval (Bissell) of values against limits.
#[pyfunction]
#[pyo3(signature = (values, lsl, usl))]
#[allow(clippy::type_complexity)]
fn cpk(
    py: Python<'_>,
    values: Vec<f64>,
    lsl: Option<f64>,
    usl: Option<f64>,
) -> PyResult<(f64, f64, Option<f64>, Option<f64>, Option<f64>)> {
    if values.iter().any(|v| !v.is_finite()) {
        return Err(usage(py, "values must be finite numbers"));
    }
    let (m, s, c) =
        crosscal::datasheet::lot::cpk(&values, lsl, usl).ok_or_else(|| usage(py, "Cpk needs at least two values"))?;
    Ok((m, s, c.map(|c| c[0]), c.map(|c| c[1]), c.map(|c| c[2])))
}

/// Stores a profile in a store folder (never overwriting; written atomically): its path.
#[pyfunction]
fn profile_save(py: Python<'_>, json: &str, store: PathBuf) -> PyResult<String> {
    let p = profile_of(py, json, "<profile>")?;
    let path = crosscal::app::fit::store(&p, &store).map_err(|e| err(py, e))?;
    Ok(path.display().to_string())
}

/// The calibration of a profile with its temperature policy.
fn calibration(
    py: Python<'_>,
    p: &crosscal::profile::Profile,
    temperature_range: &str,
) -> PyResult<crosscal::correct::Calibration> {
    let mut cal = crosscal::correct::Calibration::from_profile(p).map_err(|e| err(py, e))?;
    cal.temp_policy = crosscal::correct::TempPolicy::parse(temperature_range).ok_or_else(|| {
        usage(py, format!("temperature_range '{temperature_range}': expected clamp, extrapolate or error"))
    })?;
    Ok(cal)
}

/// What `correct` returns: t, gyro, accel, flags (or None), warm-up samples, time offset, warnings.
type CorrectOut<'py> = (
    Bound<'py, PyArray1<f64>>,
    Bound<'py, PyArray2<f64>>,
    Bound<'py, PyArray2<f64>>,
    Option<Bound<'py, PyArray1<u8>>>,
    usize,
    f64,
    Vec<String>,
);

/// Corrects a record with a profile, as `crosscal correct` corrects a file.
#[pyfunction]
#[pyo3(signature = (profile_json, t, gyro, accel, temp, mode, temperature_range, gyro_unit, accel_unit))]
#[allow(clippy::too_many_arguments)]
fn correct<'py>(
    py: Python<'py>,
    profile_json: &str,
    t: PyReadonlyArray1<'py, f64>,
    gyro: PyReadonlyArray2<'py, f64>,
    accel: PyReadonlyArray2<'py, f64>,
    temp: Option<PyReadonlyArray1<'py, f64>>,
    mode: &str,
    temperature_range: &str,
    gyro_unit: Option<&str>,
    accel_unit: Option<&str>,
) -> PyResult<CorrectOut<'py>> {
    let mode = mode_of(py, mode)?;
    let p = profile_of(py, profile_json, "<profile>")?;
    let cal = calibration(py, &p, temperature_range)?;
    let io = IoUnits::for_profile(&p, gyro_unit, accel_unit).map_err(|e| err(py, e))?;
    let c = columns(py, &t, &gyro, &accel, temp.as_ref())?;
    probe_memory(py, c.t.len(), "correct")?;
    let r = py.detach(|| crosscal::app::arrays::correct_arrays(&cal, &io, c, mode)).map_err(|e| err(py, e))?;
    let warnings: Vec<String> = r.temp_outside.warning().into_iter().collect();
    let flags = (!r.flags.is_empty()).then(|| r.flags.into_pyarray(py));
    Ok((
        r.t.into_pyarray(py),
        to_numpy(py, r.gyro)?,
        to_numpy(py, r.accel)?,
        flags,
        r.warmup,
        r.time_offset_s,
        warnings,
    ))
}

/// A causal corrector fed blocks of samples (fixed memory, the unit's own arithmetic).
#[pyclass(module = "crosscal._crosscal")]
struct Streaming {
    inner: BlockCorrector,
}

/// What `push_block` returns: t, gyro, accel, flags.
type BlockResult<'py> =
    (Bound<'py, PyArray1<f64>>, Bound<'py, PyArray2<f64>>, Bound<'py, PyArray2<f64>>, Bound<'py, PyArray1<u8>>);

/// The `out` argument as given: four objects, checked by [`out_arrays`].
type OutArg<'py> = (Bound<'py, PyAny>, Bound<'py, PyAny>, Bound<'py, PyAny>, Bound<'py, PyAny>);

/// `out`'s four arrays, each of the dtype and shape a block of `n` samples needs; anything
/// else is a usage error naming `out` (never a TypeError from the argument parser).
fn out_arrays<'py>(py: Python<'py>, o: OutArg<'py>, n: usize) -> PyResult<BlockResult<'py>> {
    let wrong = |what: &str, want: &str| {
        usage(py, format!("out: the {what} array must be a numpy {want} array (a block of {n} samples)"))
    };
    let t = o.0.cast_into::<PyArray1<f64>>().map_err(|_| wrong("t", "float64 (n,)"))?;
    let g = o.1.cast_into::<PyArray2<f64>>().map_err(|_| wrong("gyro", "float64 (n, 3)"))?;
    let a = o.2.cast_into::<PyArray2<f64>>().map_err(|_| wrong("accel", "float64 (n, 3)"))?;
    let f = o.3.cast_into::<PyArray1<u8>>().map_err(|_| wrong("flags", "uint8 (n,)"))?;
    for (what, shape, want) in [
        ("t", t.shape().to_vec(), vec![n]),
        ("gyro", g.shape().to_vec(), vec![n, 3]),
        ("accel", a.shape().to_vec(), vec![n, 3]),
        ("flags", f.shape().to_vec(), vec![n]),
    ] {
        if shape != want {
            return Err(usage(py, format!("out: the {what} array has shape {shape:?}, the block needs {want:?}")));
        }
    }
    Ok((t, g, a, f))
}

/// A writable view of an `out` array: a read-only array, or one that shares memory with an
/// input or another `out` array, is a usage error naming it (numpy's borrow checker would
/// otherwise raise a PanicException that `except Exception` does not catch).
fn writable<'py, T: numpy::Element, D: numpy::ndarray::Dimension>(
    py: Python<'py>,
    a: &Bound<'py, numpy::PyArray<T, D>>,
    what: &str,
) -> PyResult<numpy::PyReadwriteArray<'py, T, D>> {
    a.try_readwrite().map_err(|e| {
        usage(py, format!("out: the {what} array cannot be written ({e}): pass a writable array that shares no memory with the inputs or the other out arrays"))
    })
}

#[pymethods]
impl Streaming {
    #[new]
    #[pyo3(signature = (profile_json, temperature_range = "clamp", gyro_unit = None, accel_unit = None))]
    fn new(
        py: Python<'_>,
        profile_json: &str,
        temperature_range: &str,
        gyro_unit: Option<&str>,
        accel_unit: Option<&str>,
    ) -> PyResult<Self> {
        let p = profile_of(py, profile_json, "<profile>")?;
        let cal = calibration(py, &p, temperature_range)?;
        let io = IoUnits::for_profile(&p, gyro_unit, accel_unit).map_err(|e| err(py, e))?;
        Ok(Self { inner: BlockCorrector::new(cal, io) })
    }

    /// Corrects a block: new arrays (t, gyro, accel, flags), or, with `out`, into the
    /// caller's four arrays (returned), which then nothing is allocated for.
    #[pyo3(signature = (t, gyro, accel, temp = None, out = None))]
    #[allow(clippy::type_complexity)]
    fn push_block<'py>(
        &mut self,
        py: Python<'py>,
        t: PyReadonlyArray1<'py, f64>,
        gyro: PyReadonlyArray2<'py, f64>,
        accel: PyReadonlyArray2<'py, f64>,
        temp: Option<PyReadonlyArray1<'py, f64>>,
        out: Option<OutArg<'py>>,
    ) -> PyResult<BlockResult<'py>> {
        let n = t.len();
        let out = match out {
            Some(o) => out_arrays(py, o, n)?,
            None => {
                // numpy's refusal of the new arrays would panic in the binding: ask first.
                probe_memory(py, n, "Streaming.push_block")?;
                (
                    PyArray1::zeros(py, n, false),
                    PyArray2::zeros(py, [n, 3], false),
                    PyArray2::zeros(py, [n, 3], false),
                    PyArray1::zeros(py, n, false),
                )
            }
        };
        {
            let c = columns(py, &t, &gyro, &accel, temp.as_ref())?;
            let (mut ot, mut og, mut oa, mut of): (
                PyReadwriteArray1<f64>,
                PyReadwriteArray2<f64>,
                PyReadwriteArray2<f64>,
                PyReadwriteArray1<u8>,
            ) = (
                writable(py, &out.0, "t")?,
                writable(py, &out.1, "gyro")?,
                writable(py, &out.2, "accel")?,
                writable(py, &out.3, "flags")?,
            );
            let bad = |what: &str| usage(py, format!("out: the {what} array is not C-contiguous"));
            let o = BlockOut {
                t: ot.as_slice_mut().map_err(|_| bad("t"))?,
                gyro: og.as_slice_mut().map_err(|_| bad("gyro"))?.as_chunks_mut::<3>().0,
                accel: oa.as_slice_mut().map_err(|_| bad("accel"))?.as_chunks_mut::<3>().0,
                flags: of.as_slice_mut().map_err(|_| bad("flags"))?,
            };
            let inner = &mut self.inner;
            py.detach(|| inner.push(c, o)).map_err(|e| err(py, e))?;
        }
        Ok(out)
    }

    /// Forgets the history (the start of a new record).
    fn reset(&mut self) {
        self.inner.reset();
    }

    /// Samples after a reset before the derivative window is full.
    #[getter]
    fn warmup_samples(&self) -> usize {
        self.inner.warmup_samples()
    }

    /// Samples corrected since the start or the last reset.
    #[getter]
    fn samples(&self) -> u64 {
        self.inner.samples()
    }

    /// The shift applied to the output stamps, s (the profile's time delay).
    #[getter]
    fn time_offset_s(&self) -> f64 {
        self.inner.time_offset_s()
    }

    /// The warning about samples outside the calibrated temperature range, if any.
    fn temperature_warning(&self) -> Option<String> {
        self.inner.temperature_outside().warning()
    }
}

/// A diagnosis and what it needs to draw its report.
#[pyclass(frozen, module = "crosscal._crosscal")]
struct Diagnosis {
    session: Arc<crosscal::session::Session>,
    model: crosscal::model::Model,
    found: Diagnosed,
    temperature_note: Option<String>,
}

#[pymethods]
impl Diagnosis {
    /// "stand" (per-sample residuals) or "protocol" (poses and turns).
    #[getter]
    fn kind(&self) -> &'static str {
        match self.found {
            Diagnosed::Stand(_) => "stand",
            Diagnosed::Protocol(_) => "protocol",
        }
    }

    /// The verdict: stand runs `adequate`, `explained` or `unexplained`; a protocol session
    /// `missing-effect` (a proposal), `adequate`, or `not-adequate` (poses or turns stand out
    /// that no catalogued effect explains), as the command's verdict line says.
    #[getter]
    fn verdict(&self) -> &'static str {
        use crosscal::diagnose::Verdict;
        let verdict = match &self.found {
            Diagnosed::Stand(d) => d.verdict.clone(),
            Diagnosed::Protocol(d) => d.verdict(),
        };
        match verdict {
            Verdict::Adequate => "adequate",
            Verdict::Explained => "explained",
            Verdict::Unexplained => "unexplained",
        }
    }

    /// The diagnosis as JSON text (as `crosscal diagnose --json`).
    fn json(&self) -> PyResult<String> {
        let r = match &self.found {
            Diagnosed::Stand(d) => serde_json::to_string(d),
            Diagnosed::Protocol(d) => serde_json::to_string(d),
        };
        r.map_err(|e| PyValueError::new_err(e.to_string()))
    }

    /// With a profile: the runs outside its calibrated temperature range, named.
    #[getter]
    fn temperature_note(&self) -> Option<String> {
        self.temperature_note.clone()
    }

    /// The self-contained HTML report with its plots (as `crosscal diagnose --report`).
    fn html(&self, py: Python<'_>) -> PyResult<String> {
        let Diagnosed::Stand(d) = &self.found else {
            return Err(usage(py, "the report draws stand-run residuals; a protocol session has its JSON"));
        };
        let (html, _) =
            py.detach(|| crosscal::app::diagnose::report(&self.session, &self.model, d)).map_err(|e| err(py, e))?;
        Ok(html)
    }
}

/// Diagnoses a session from a model (or a profile held as fitted).
#[pyfunction]
#[pyo3(signature = (session, preset, effects, profile_json, trim_rest, slow_noise=None))]
fn diagnose(
    py: Python<'_>,
    session: &Session,
    preset: &str,
    effects: Vec<String>,
    profile_json: Option<&str>,
    trim_rest: bool,
    slow_noise: Option<bool>,
) -> PyResult<Diagnosis> {
    use crosscal::diagnose::SlowNoiseMode;
    let slow_noise = match slow_noise {
        None => SlowNoiseMode::Auto,
        Some(true) => SlowNoiseMode::On,
        Some(false) => SlowNoiseMode::Off,
    };
    let spec = model_spec(py, preset, effects, Vec::new())?;
    let profile = match profile_json {
        Some(j) => Some(profile_of(py, j, "<profile>")?),
        None => None,
    };
    let s = &session.inner;
    let model = crosscal::app::diagnose::start_model(s, &spec, profile.as_ref().map(|p| (Path::new("<profile>"), p)))
        .map_err(|e| err(py, e))?;
    let found = py
        .detach(|| crosscal::app::diagnose::diagnose_session(s, &model, trim_rest, slow_noise))
        .map_err(|e| err(py, e))?;
    let temperature_note = profile.as_ref().and_then(|p| crosscal::app::diagnose::temperature_outside(p, s));
    Ok(Diagnosis { session: s.clone(), model, found, temperature_note })
}

/// Allan deviation and noise terms of columns at rest: the report as JSON text.
#[pyfunction]
#[pyo3(signature = (data, channels, rate_hz, gyro_unit, accel_unit, g_m_s2, max_tau_s, deviation, source))]
#[allow(clippy::too_many_arguments)]
fn noise(
    py: Python<'_>,
    data: PyReadonlyArray2<'_, f64>,
    channels: Vec<String>,
    rate_hz: f64,
    gyro_unit: &str,
    accel_unit: &str,
    g_m_s2: f64,
    max_tau_s: Option<f64>,
    deviation: &str,
    source: &str,
) -> PyResult<String> {
    use crosscal::noise::deviations::Deviation;
    use crosscal::units::{AccelUnit, GyroUnit, Units};
    let shape = data.shape();
    if shape[1] != channels.len() {
        return Err(usage(py, format!("{} channel names for {} columns", channels.len(), shape[1])));
    }
    let units = Units {
        gyro: GyroUnit::parse(gyro_unit)
            .ok_or_else(|| usage(py, format!("gyro unit '{gyro_unit}': expected one of {}", GyroUnit::CHOICES)))?,
        accel: AccelUnit::parse(accel_unit).ok_or_else(|| {
            usage(py, format!("accelerometer unit '{accel_unit}': expected one of {}", AccelUnit::CHOICES))
        })?,
        time: crosscal::units::TimeUnit::S,
    };
    let deviation = match deviation {
        "allan" => Deviation::Allan,
        "hadamard" => Deviation::Hadamard,
        "modified" => Deviation::Modified,
        d => return Err(usage(py, format!("deviation '{d}': expected allan, hadamard or modified"))),
    };
    let view = data.as_array();
    let mut columns = Vec::with_capacity(channels.len());
    for (j, name) in channels.iter().enumerate() {
        let c = crosscal::noise::CHANNELS
            .iter()
            .position(|n| n == name)
            .ok_or_else(|| usage(py, format!("channel '{name}': expected one of gx, gy, gz, ax, ay, az")))?;
        columns.push((c, view.column(j).to_vec()));
    }
    let opts = crosscal::noise::NoiseOptions { max_tau_s, deviation };
    let r = py
        .detach(|| crosscal::app::arrays::noise_of_columns(source, columns, &units, g_m_s2, rate_hz, opts))
        .map_err(|e| err(py, e))?;
    serde_json::to_string(&r).map_err(|e| PyValueError::new_err(e.to_string()))
}

/// Predicted uncertainties of a proposed set of conic runs: the plan as JSON text.
#[pyfunction]
#[pyo3(signature = (rates_deg_s, cone_angles_deg, mounts, duration_s, rate_hz, preset, effects, arw_deg_rt_h, vrw_m_s_rt_h, suggest))]
#[allow(clippy::too_many_arguments)]
fn plan(
    py: Python<'_>,
    rates_deg_s: Vec<f64>,
    cone_angles_deg: Vec<f64>,
    mounts: usize,
    duration_s: f64,
    rate_hz: f64,
    preset: &str,
    effects: Vec<String>,
    arw_deg_rt_h: f64,
    vrw_m_s_rt_h: f64,
    suggest: bool,
) -> PyResult<String> {
    if !(duration_s > 0.0 && rate_hz > 0.0 && arw_deg_rt_h > 0.0 && vrw_m_s_rt_h > 0.0 && (1..=3).contains(&mounts)) {
        return Err(usage(py, "duration_s, rate_hz, arw and vrw must be positive and mounts 1, 2 or 3"));
    }
    let model = model_spec(py, preset, effects, Vec::new())?.build().map_err(|e| err(py, e))?;
    let runs = crosscal::simulate::conic_plan(
        &rates_deg_s,
        &cone_angles_deg,
        &crosscal::simulate::cyclic_mounts(mounts),
        duration_s,
    );
    let spec = crosscal::plan::PlanSpec {
        runs,
        sample_rate_hz: rate_hz,
        gyro_density: arw_deg_rt_h.to_radians() / 60.0,
        accel_density: vrw_m_s_rt_h / 60.0,
    };
    let candidates = if suggest { crosscal::plan::default_candidates(&spec) } else { Vec::new() };
    let r = py.detach(|| crosscal::plan::plan(&model, &spec, &candidates)).map_err(|e| err(py, e))?;
    serde_json::to_string(&r).map_err(|e| PyValueError::new_err(e.to_string()))
}

/// Simulates a unit on a stand (settings as a dict whose keys are the fields of
/// `crosscal::app::simulate::SimulateOptions`): the session in memory.
#[pyfunction]
fn simulate(py: Python<'_>, options: Bound<'_, pyo3::types::PyDict>) -> PyResult<Session> {
    use crosscal::app::simulate::SimulateOptions;
    let mut o = SimulateOptions::default();
    for (k, v) in options.iter() {
        let key: String = k.extract()?;
        match key.as_str() {
            "preset" => o.preset = v.extract()?,
            "gyro_noise_deg_s" => o.gyro_noise_deg_s = v.extract()?,
            "accel_noise_g" => o.accel_noise_g = v.extract()?,
            "gyro_bias_deg_s" => o.gyro_bias_deg_s = v.extract()?,
            "accel_bias_g" => o.accel_bias_g = v.extract()?,
            "seed" => o.seed = v.extract()?,
            "rates_deg_s" => o.rates_deg_s = v.extract()?,
            "cone_angles_deg" => o.cone_angles_deg = v.extract()?,
            "mounts" => o.mounts = v.extract()?,
            "duration_s" => o.duration_s = v.extract()?,
            "rate_hz" => o.rate_hz = v.extract()?,
            "serial" => o.serial = v.extract()?,
            "hidden" => o.hidden = v.extract()?,
            "set" => o.set = v.extract()?,
            "temperature_c" => o.temperature_c = v.extract()?,
            "arw_deg_rt_h" => o.arw_deg_rt_h = v.extract()?,
            "gyro_bias_instability_deg_h" => o.gyro_bias_instability_deg_h = v.extract()?,
            "rrw_deg_h_rt_h" => o.rrw_deg_h_rt_h = v.extract()?,
            "vrw_m_s_rt_h" => o.vrw_m_s_rt_h = v.extract()?,
            "accel_bias_instability_ug" => o.accel_bias_instability_ug = v.extract()?,
            "accel_random_walk" => o.accel_random_walk = v.extract()?,
            "carry_noise" => o.carry_noise = v.extract()?,
            "ar1" => o.ar1 = v.extract()?,
            "quantize" => o.quantize = v.extract()?,
            "jitter_ms" => o.jitter_ms = v.extract()?,
            "session_clock_s" => o.session_clock_s = v.extract()?,
            "si_units" => o.si_units = v.extract()?,
            "temp_noise_c" => o.temp_noise_c = v.extract()?,
            "temp_quantum_c" => o.temp_quantum_c = v.extract()?,
            "disturb" => {
                let specs: Vec<String> = v.extract()?;
                o.disturb = specs
                    .iter()
                    .map(|s| {
                        crosscal::simulate::realism::Disturbance::parse(s)
                            .map_err(|e| usage(py, format!("disturb '{s}': {e}")))
                    })
                    .collect::<PyResult<_>>()?;
            }
            other => return Err(usage(py, format!("simulate: unknown setting '{other}'"))),
        }
    }
    let cfg = crosscal::app::simulate::config(&o).map_err(|e| err(py, e))?;
    let s = py.detach(|| cfg.generate());
    Ok(Session { inner: Arc::new(s), path: None })
}

/// Corrects every run of a session with a profile and compares with the reference motion
/// (as `crosscal check`): the check report as JSON text.
#[pyfunction]
#[pyo3(signature = (session, profile_json, mode, allow_other_unit = false))]
fn check(
    py: Python<'_>,
    session: &Session,
    profile_json: &str,
    mode: &str,
    allow_other_unit: bool,
) -> PyResult<String> {
    let p = profile_of(py, profile_json, "<profile>")?;
    if !allow_other_unit {
        // As `crosscal check` (exit 16): one unit's profile says nothing about another unit.
        p.ensure_unit(Path::new("<profile>"), &session.inner.manifest.serial).map_err(|e| err(py, e))?;
    }
    let cal = crosscal::correct::Calibration::from_profile(&p).map_err(|e| err(py, e))?;
    let mode = mode_of(py, mode)?;
    let s = &session.inner;
    let thresholds = crosscal::check::Thresholds::default();
    let r = py.detach(|| crosscal::app::validate::check_session(s, &cal, mode, thresholds)).map_err(|e| err(py, e))?;
    serde_json::to_string(&r).map_err(|e| PyValueError::new_err(e.to_string()))
}

/// The paper's comparison (errors before and after correction, reduction factors, the
/// paper's figures) on one run of a session: the rows as JSON text (as `crosscal demo`).
#[pyfunction]
fn paper_table(py: Python<'_>, session: &Session, profile_json: &str, run: &str) -> PyResult<String> {
    use crosscal::app::validate::check_session;
    let p = profile_of(py, profile_json, "<profile>")?;
    let cal = crosscal::correct::Calibration::from_profile(&p).map_err(|e| err(py, e))?;
    let s = session.inner.subset(|n| n == run);
    if s.runs.is_empty() {
        return Err(usage(py, format!("no run '{run}' in the session")));
    }
    let t = crosscal::check::Thresholds::default();
    let (offline, streaming) = py
        .detach(|| {
            Ok::<_, crosscal::correct::CorrectError>((
                check_session(&s, &cal, Mode::Offline, t)?,
                check_session(&s, &cal, Mode::Streaming, t)?,
            ))
        })
        .map_err(|e| err(py, e))?;
    let rows = crosscal::check::paper::paper_rows(&offline, &streaming, run)
        .ok_or_else(|| usage(py, format!("no run '{run}' in the check")))?;
    serde_json::to_string(&rows).map_err(|e| PyValueError::new_err(e.to_string()))
}

fn mode_of(py: Python<'_>, mode: &str) -> PyResult<Mode> {
    match mode {
        "offline" => Ok(Mode::Offline),
        "streaming" => Ok(Mode::Streaming),
        m => Err(usage(py, format!("mode '{m}': expected 'offline' or 'streaming'"))),
    }
}

/// The benchmark's peer: the Rust library's own streaming corrector
/// (`crosscal::correct::Streaming::push_block`) on SI arrays, in blocks of `block`
/// samples into preallocated buffers, as a Rust program would call it. Returns the
/// seconds it took (GIL released); `block` 0: the whole record at once with
/// `crosscal::correct::correct_streaming` (outputs allocated). For
/// `benches/python_streaming.py`.
#[pyfunction]
fn bench_rust_streaming(
    py: Python<'_>,
    profile_json: &str,
    t_s: PyReadonlyArray1<'_, f64>,
    gyro_rad_s: PyReadonlyArray2<'_, f64>,
    accel_m_s2: PyReadonlyArray2<'_, f64>,
    block: usize,
) -> PyResult<f64> {
    let p = profile_of(py, profile_json, "<profile>")?;
    let cal = crosscal::correct::Calibration::from_profile(&p).map_err(|e| err(py, e))?;
    let (t, g, a) = (slice(py, &t_s, "t")?, triples(py, &gyro_rad_s, "gyro")?, triples(py, &accel_m_s2, "accel")?);
    let n = t.len().min(g.len()).min(a.len());
    if block == 0 {
        // The whole record at once: the library's `correct_streaming`, outputs allocated.
        return py
            .detach(|| {
                let start = std::time::Instant::now();
                let r = crosscal::correct::correct_streaming(&cal, &t[..n], &g[..n], &a[..n], None);
                let took = start.elapsed().as_secs_f64();
                std::hint::black_box(&r);
                r.map(|_| took)
            })
            .map_err(|e| err(py, e));
    }
    Ok(py.detach(|| {
        let mut s = crosscal::correct::Streaming::new(cal);
        let (mut w, mut f) = (vec![[0.0; 3]; block], vec![[0.0; 3]; block]);
        let start = std::time::Instant::now();
        for k in (0..n).step_by(block) {
            let e = (k + block).min(n);
            s.push_block(&t[k..e], &g[k..e], &a[k..e], &mut w[..e - k], &mut f[..e - k]);
        }
        let took = start.elapsed().as_secs_f64();
        std::hint::black_box((&w, &f));
        took
    }))
}

/// Every exit code and its meaning (the exception classes' codes).
#[pyfunction]
fn exit_codes() -> Vec<(u8, &'static str)> {
    crosscal::app::errors::EXIT_CODES.to_vec()
}

/// The crosscal library's version.
#[pyfunction]
fn version() -> &'static str {
    env!("CARGO_PKG_VERSION")
}

#[pymodule]
fn _crosscal(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<Session>()?;
    m.add_class::<Streaming>()?;
    m.add_class::<Diagnosis>()?;
    m.add_function(wrap_pyfunction!(read_session, m)?)?;
    m.add_function(wrap_pyfunction!(session_from_columns, m)?)?;
    m.add_function(wrap_pyfunction!(fit, m)?)?;
    m.add_function(wrap_pyfunction!(register_effects, m)?)?;
    m.add_function(wrap_pyfunction!(profile_normalise, m)?)?;
    m.add_function(wrap_pyfunction!(profile_read, m)?)?;
    m.add_function(wrap_pyfunction!(profile_save, m)?)?;
    m.add_function(wrap_pyfunction!(datasheet, m)?)?;
    m.add_function(wrap_pyfunction!(cpk, m)?)?;
    m.add_function(wrap_pyfunction!(correct, m)?)?;
    m.add_function(wrap_pyfunction!(diagnose, m)?)?;
    m.add_function(wrap_pyfunction!(noise, m)?)?;
    m.add_function(wrap_pyfunction!(plan, m)?)?;
    m.add_function(wrap_pyfunction!(simulate, m)?)?;
    m.add_function(wrap_pyfunction!(check, m)?)?;
    m.add_function(wrap_pyfunction!(paper_table, m)?)?;
    m.add_function(wrap_pyfunction!(bench_rust_streaming, m)?)?;
    m.add_function(wrap_pyfunction!(exit_codes, m)?)?;
    m.add_function(wrap_pyfunction!(version, m)?)?;
    Ok(())
}
