//! Correction and noise analysis of samples in memory, in the units the user has them (the
//! Python package's numpy arrays), with the same arithmetic as `crosscal correct` and
//! `crosscal noise` on a file: inputs are converted to SI with the CSV reader's factors
//! ([`crate::session::memory::columns_to_si`]), outputs scaled back with the writer's
//! ([`OutputScale`]), so a correction through arrays equals the command's output bit for
//! bit. The block corrector converts a block at a time into fixed buffers (inputs already
//! in SI go straight through), so a stream of any length is corrected in fixed memory.

use super::validate::Mode;
use super::AppError;
use crate::correct::{correct_offline, refuse_outside, Calibration, CorrectError, OutputScale, Streaming, TempOutside};
use crate::noise::{NoiseError, NoiseOptions, NoiseReport, StaticData};
use crate::profile::Profile;
use crate::session::memory::{columns_to_si, Columns};
use crate::units::{AccelUnit, GyroUnit, Units};

/// Units of the samples handed to a correction and of those returned.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct IoUnits {
    /// Units of the inputs.
    pub input: Units,
    /// Units of the outputs: the inputs', except raw, which comes out in deg/s and g (the
    /// calibration supplies the physical unit).
    pub output: Units,
    /// Local gravity, m/s² (for g).
    pub g_m_s2: f64,
}

impl IoUnits {
    /// The units of a profile's sessions, or `gyro_unit` / `accel_unit` when given (their
    /// spellings as in manifests: deg/s, rad/s, raw; g, m/s^2, raw).
    pub fn for_profile(p: &Profile, gyro_unit: Option<&str>, accel_unit: Option<&str>) -> Result<Self, AppError> {
        let mut input = p.input_units;
        if let Some(u) = gyro_unit {
            input.gyro = GyroUnit::parse(u)
                .ok_or_else(|| AppError::Invalid(format!("gyro unit '{u}': expected one of {}", GyroUnit::CHOICES)))?;
        }
        if let Some(u) = accel_unit {
            input.accel = AccelUnit::parse(u).ok_or_else(|| {
                AppError::Invalid(format!("accelerometer unit '{u}': expected one of {}", AccelUnit::CHOICES))
            })?;
        }
        let output = Units {
            gyro: if input.gyro == GyroUnit::Raw { GyroUnit::DegPerS } else { input.gyro },
            accel: if input.accel == AccelUnit::Raw { AccelUnit::G } else { input.accel },
            time: input.time,
        };
        Ok(Self { input, output, g_m_s2: p.g_m_s2 })
    }

    /// SI → output factors.
    pub fn scale(&self) -> OutputScale {
        OutputScale {
            time: 1.0 / self.input.time.to_s(),
            gyro: 1.0 / self.output.gyro.to_rad_s(),
            accel: 1.0 / self.output.accel.to_m_s2(self.g_m_s2),
        }
    }

    /// Input → SI factors [time, gyro, accel].
    fn si_factors(&self) -> [f64; 3] {
        [self.input.time.to_s(), self.input.gyro.to_rad_s(), self.input.accel.to_m_s2(self.g_m_s2)]
    }
}

/// A correction of samples in memory, in the output units.
#[derive(Debug, Clone, PartialEq)]
pub struct CorrectedArrays {
    /// Time stamps, shifted by the profile's time delay (sample k describes `t[k]`).
    pub t: Vec<f64>,
    /// Corrected rates.
    pub gyro: Vec<[f64; 3]>,
    /// Corrected specific forces.
    pub accel: Vec<[f64; 3]>,
    /// Per sample, channels that could not be inverted (bits 0-2 gyro, 3-5 accel); empty
    /// when none.
    pub flags: Vec<u8>,
    /// Leading samples corrected before the streaming derivative window was full.
    pub warmup: usize,
    /// The shift applied to the time stamps, s (the profile's time delay).
    pub time_offset_s: f64,
    /// Samples outside the calibrated temperature range.
    pub temp_outside: TempOutside,
}

/// Corrects one record held in memory (inputs in `io.input`, outputs in `io.output`), as
/// `crosscal correct` corrects a file in `mode`.
pub fn correct_arrays(
    cal: &Calibration,
    io: &IoUnits,
    c: Columns<'_>,
    mode: Mode,
) -> Result<CorrectedArrays, AppError> {
    let what = "the arrays".to_string();
    if mode == Mode::Streaming {
        return streamed(cal, io, c, what);
    }
    let (t_s, gyro, accel) = columns_to_si("arrays", c, &io.input, io.g_m_s2)
        .map_err(|source| AppError::Session { path: "<memory>".into(), source })?;
    let n = t_s.len();
    let corrected =
        correct_offline(cal, &t_s, &gyro, &accel, c.temp_c).map_err(|source| AppError::Correct { what, source })?;
    let s = io.scale();
    let scale3 = |v: [f64; 3], k: f64| [v[0] * k, v[1] * k, v[2] * k];
    let offset = corrected.time_offset_s;
    Ok(CorrectedArrays {
        t: t_s.iter().map(|t| (t - offset) * s.time).collect(),
        gyro: corrected.w_rad_s.iter().map(|&w| scale3(w, s.gyro)).collect(),
        accel: corrected.a_m_s2.iter().map(|&a| scale3(a, s.accel)).collect(),
        flags: corrected.flags,
        warmup: corrected.warmup.min(n),
        time_offset_s: offset,
        temp_outside: corrected.temp_outside,
    })
}

/// Streaming mode of [`correct_arrays`]: the block corrector straight into the output
/// buffers (no SI copy of the inputs), after the inputs are checked as the reader checks a
/// file.
fn streamed(cal: &Calibration, io: &IoUnits, c: Columns<'_>, what: String) -> Result<CorrectedArrays, AppError> {
    crate::session::memory::check_columns("arrays", c, &io.input)
        .map_err(|source| AppError::Session { path: "<memory>".into(), source })?;
    let n = c.t.len();
    let mut b = BlockCorrector::new(cal.clone(), *io);
    let (mut t, mut gyro, mut accel, mut flags) = (vec![0.0; n], vec![[0.0; 3]; n], vec![[0.0; 3]; n], vec![0u8; n]);
    b.push(c, BlockOut { t: &mut t, gyro: &mut gyro, accel: &mut accel, flags: &mut flags })
        .map_err(|source| AppError::Correct { what, source })?;
    if flags.iter().all(|&f| f == 0) {
        flags = Vec::new();
    }
    Ok(CorrectedArrays {
        t,
        gyro,
        accel,
        flags,
        warmup: b.warmup_samples().min(n),
        time_offset_s: b.time_offset_s(),
        temp_outside: *b.temperature_outside(),
    })
}

/// Samples converted per block by [`BlockCorrector`].
const BLOCK: usize = 4096;

/// A streaming corrector fed blocks of samples in the user's units, writing corrected
/// samples into the caller's buffers: the [`Streaming`] corrector (bit for bit the same
/// numbers as `crosscal correct --mode streaming`) behind a conversion through fixed
/// buffers. Memory is fixed; nothing is allocated per block.
#[derive(Debug, Clone)]
pub struct BlockCorrector {
    s: Streaming,
    io: IoUnits,
    /// Input factors are all 1 and outputs are SI: the caller's slices are used directly.
    si: bool,
    /// Per-sample pushes (temperatures, nonlinear inverses).
    nonlinear: bool,
    needs_temp: Option<&'static str>,
    buf: Box<Buffers>,
    samples: u64,
    lag_s: f64,
    /// The last time stamp corrected (input unit), so the next block must start after it.
    last_t: f64,
}

#[derive(Debug, Clone)]
struct Buffers {
    t: [f64; BLOCK],
    g: [[f64; 3]; BLOCK],
    a: [[f64; 3]; BLOCK],
    w_out: [[f64; 3]; BLOCK],
    a_out: [[f64; 3]; BLOCK],
}

/// Where a block's corrected samples go (each slice as long as the block's inputs).
#[derive(Debug)]
pub struct BlockOut<'a> {
    /// Time stamps shifted by the profile's time delay, output time unit.
    pub t: &'a mut [f64],
    /// Corrected rates, output unit.
    pub gyro: &'a mut [[f64; 3]],
    /// Corrected specific forces, output unit.
    pub accel: &'a mut [[f64; 3]],
    /// Flag bits per sample (see [`CorrectedArrays::flags`]).
    pub flags: &'a mut [u8],
}

impl BlockCorrector {
    /// A corrector for `cal` with inputs and outputs in `io`.
    pub fn new(cal: Calibration, io: IoUnits) -> Self {
        let k = io.si_factors();
        let s = io.scale();
        // Exact ones only: then converting is the identity and can be skipped.
        let one = |x: f64| x.to_bits() == 1.0f64.to_bits();
        let si = k.iter().chain(&[s.time, s.gyro, s.accel]).all(|&x| one(x));
        let nonlinear = !cal.nonlinear.is_empty();
        let needs_temp = cal.needs_temperature();
        let zero = [[0.0; 3]; BLOCK];
        let buf = Box::new(Buffers { t: [0.0; BLOCK], g: zero, a: zero, w_out: zero, a_out: zero });
        let lag_s = cal.lag_s();
        Self {
            s: Streaming::new(cal),
            io,
            si,
            nonlinear,
            needs_temp,
            buf,
            samples: 0,
            lag_s,
            last_t: f64::NEG_INFINITY,
        }
    }

    /// Samples after a reset before the derivative window is full.
    pub fn warmup_samples(&self) -> usize {
        self.s.warmup_samples()
    }

    /// Samples corrected since the start or the last reset.
    pub fn samples(&self) -> u64 {
        self.samples
    }

    /// The samples met so far outside the calibrated temperature range.
    pub fn temperature_outside(&self) -> &TempOutside {
        self.s.temperature_outside()
    }

    /// The shift applied to the output stamps, s (the profile's time delay).
    pub fn time_offset_s(&self) -> f64 {
        self.lag_s
    }

    /// Forgets the history (the start of a new record).
    pub fn reset(&mut self) {
        self.s.reset();
        self.samples = 0;
        self.last_t = f64::NEG_INFINITY;
    }

    /// Corrects one block (inputs in the input units; `temp_c` per sample when the record
    /// has temperatures) into `out`. Refuses lengths that differ, a missing temperature the
    /// profile needs, samples outside the calibrated range under the `error` policy, and
    /// non-finite results (naming the sample, counted from the start or last reset).
    pub fn push(&mut self, c: Columns<'_>, out: BlockOut<'_>) -> Result<(), CorrectError> {
        let n = c.t.len();
        let lens = [c.gyro.len(), c.accel.len(), out.t.len(), out.gyro.len(), out.accel.len(), out.flags.len()];
        if lens.iter().any(|&l| l != n) || c.temp_c.is_some_and(|t| t.len() != n) {
            return Err(CorrectError::Length { t: n, g: c.gyro.len(), a: c.accel.len() });
        }
        if let (None, Some(id)) = (c.temp_c, self.needs_temp) {
            return Err(CorrectError::MissingTemperature(id.to_string()));
        }
        // Time increases strictly within the block and from the last block (as the
        // offline and streaming corrections of a whole record require): checked before
        // anything is corrected, so a refused block changes nothing.
        let mut previous = self.last_t;
        for (k, &t) in c.t.iter().enumerate() {
            if !t.is_finite() || t <= previous {
                return Err(CorrectError::TimeNotIncreasing { sample: self.samples + k as u64 + 1, t, previous });
            }
            previous = t;
        }
        if let Some(&t) = c.t.last() {
            self.last_t = t;
        }
        let per_sample = self.nonlinear || c.temp_c.is_some();
        let [kt, kg, ka] = self.io.si_factors();
        let scale = self.io.scale();
        let lag = self.lag_s;
        for start in (0..n).step_by(BLOCK) {
            let end = (start + BLOCK).min(n);
            let m = end - start;
            let b = &mut *self.buf;
            let (t, g, a): (&[f64], &[[f64; 3]], &[[f64; 3]]) = if self.si {
                (&c.t[start..end], &c.gyro[start..end], &c.accel[start..end])
            } else {
                for k in 0..m {
                    let (gi, ai) = (c.gyro[start + k], c.accel[start + k]);
                    b.t[k] = c.t[start + k] * kt;
                    b.g[k] = [gi[0] * kg, gi[1] * kg, gi[2] * kg];
                    b.a[k] = [ai[0] * ka, ai[1] * ka, ai[2] * ka];
                }
                (&b.t[..m], &b.g[..m], &b.a[..m])
            };
            let (w_out, a_out) = if self.si {
                (&mut out.gyro[start..end], &mut out.accel[start..end])
            } else {
                (&mut b.w_out[..m], &mut b.a_out[..m])
            };
            if per_sample {
                for k in 0..m {
                    let temp = c.temp_c.map_or(f64::NAN, |tc| tc[start + k]);
                    (w_out[k], a_out[k]) = self.s.push(t[k], g[k], a[k], temp);
                    out.flags[start + k] = self.s.last_flags();
                }
                refuse_outside(self.s.temperature_outside())?;
            } else {
                self.s.push_block(t, g, a, w_out, a_out);
                out.flags[start..end].fill(0);
            }
            if let Some(k) = w_out.iter().zip(a_out.iter()).position(|(w, a)| !w.iter().chain(a).all(|v| v.is_finite()))
            {
                let sample = self.samples as usize + start + k + 1;
                return Err(CorrectError::NonFinite { sample, t_s: t[k] });
            }
            for k in 0..m {
                out.t[start + k] = (t[k] - lag) * scale.time;
            }
            if !self.si {
                for k in 0..m {
                    let (w, acc) = (b.w_out[k], b.a_out[k]);
                    out.gyro[start + k] = [w[0] * scale.gyro, w[1] * scale.gyro, w[2] * scale.gyro];
                    out.accel[start + k] = [acc[0] * scale.accel, acc[1] * scale.accel, acc[2] * scale.accel];
                }
            }
        }
        self.samples += n as u64;
        Ok(())
    }
}

/// Allan deviation and noise terms of columns at rest sampled at `rate_hz`: `columns` are
/// (channel index into [`crate::noise::CHANNELS`], samples in `units`), analysed as
/// `crosscal noise` analyses a recording's channels (`source` names them in the report).
pub fn noise_of_columns(
    source: &str,
    columns: Vec<(usize, Vec<f64>)>,
    units: &Units,
    g_m_s2: f64,
    rate_hz: f64,
    opts: NoiseOptions,
) -> Result<NoiseReport, NoiseError> {
    if !(rate_hz.is_finite() && rate_hz > 0.0) {
        return Err(NoiseError::Interval(1.0 / rate_hz));
    }
    let n = columns.iter().map(|c| c.1.len()).max().unwrap_or(0);
    for (c, v) in &columns {
        if let Some(k) = v.iter().position(|x| !x.is_finite()) {
            return Err(NoiseError::NotFinite { channel: crate::noise::CHANNELS[*c % 6], sample: k + 1 });
        }
    }
    let (kg, ka) = (units.gyro.to_rad_s(), units.accel.to_m_s2(g_m_s2));
    let columns = columns
        .into_iter()
        .map(|(c, mut v)| {
            let k = if c < 3 { kg } else { ka };
            v.iter_mut().for_each(|x| *x *= k);
            (c, v)
        })
        .collect();
    crate::noise::analyse(source, StaticData { columns, tau0_s: 1.0 / rate_hz, n, warnings: Vec::new() }, opts)
}
