//! ArduPilot DataFlash `.bin` logs (AP_Logger `LogStructure.h`): records of `A3 95`, a
//! message type and a packed little-endian payload whose layout the type's FMT record
//! (type 128: type, length, name[4], format[16], columns[64]) gives; there is no length
//! and no checksum, so a byte that is not `A3 95` where a record should start is skipped
//! to the next `A3 95` (and said), and a record cut by the end of the file is a warning.
//!
//! IMU streams: `IMU`, `IMU2`, `IMU3` (older logs, one message name per IMU) or `IMU` with
//! an instance column `I` (newer), each `TimeUS` (or `TimeMS`), `GyrX..Z` rad/s, `AccX..Z`
//! m/s², `T` °C (0 when the sensor reports none); the raw `ACC`/`GYR` messages, paired per
//! instance; and the batch sampler (`ISBH` header + `ISBD` int16 blocks ÷ `mul`), one
//! sensor only, listed but not importable. FMTU multipliers are applied where a log has
//! them (its MULT records give the factors; `-` means none). The `IMU` values are the INS
//! library's output: the `INS_*` offsets, scales and `AHRS_ORIENTATION` of the log's PARM
//! records were applied, and are carried into the session.

use super::{Contents, LogFormat, LogSample, Pairer, Sink, StreamDesc};
use crate::session::error::{Problem, SessionError};
use std::collections::HashMap;
use std::path::Path;

const FRAME_AP: &str = "ArduPilot FRD (x forward, y right, z down), rad/s and m/s^2";
const FMT: u8 = 128;

/// A message type's layout.
#[derive(Debug, Clone, Default)]
struct Fmt {
    name: String,
    len: usize,
    /// Per column: name, offset in the record (after the 3 header bytes), type character.
    cols: Vec<(String, usize, u8)>,
    /// FMTU multipliers per column (1 when absent).
    mult: Vec<f64>,
}

fn char_size(c: u8) -> Option<usize> {
    Some(match c {
        b'b' | b'B' | b'M' => 1,
        b'h' | b'H' | b'c' | b'C' => 2,
        b'i' | b'I' | b'f' | b'e' | b'E' | b'L' | b'n' => 4,
        b'q' | b'Q' | b'd' => 8,
        b'N' => 16,
        b'Z' | b'a' => 64,
        _ => return None,
    })
}

impl Fmt {
    fn col(&self, name: &str) -> Option<usize> {
        self.cols.iter().position(|c| c.0 == name)
    }

    /// Column `i` of a record payload as a number (scaled types applied, then FMTU).
    fn value(&self, b: &[u8], i: usize) -> Option<f64> {
        let (_, off, c) = &self.cols[i];
        let s = b.get(*off..*off + char_size(*c)?)?;
        let le4 = || [s[0], s[1], s[2], s[3]];
        let v = match c {
            b'b' => f64::from(s[0] as i8),
            b'B' | b'M' => f64::from(s[0]),
            b'h' => f64::from(i16::from_le_bytes([s[0], s[1]])),
            b'H' => f64::from(u16::from_le_bytes([s[0], s[1]])),
            b'c' => f64::from(i16::from_le_bytes([s[0], s[1]])) * 0.01,
            b'C' => f64::from(u16::from_le_bytes([s[0], s[1]])) * 0.01,
            b'i' => f64::from(i32::from_le_bytes(le4())),
            b'I' => f64::from(u32::from_le_bytes(le4())),
            b'e' => f64::from(i32::from_le_bytes(le4())) * 0.01,
            b'E' => f64::from(u32::from_le_bytes(le4())) * 0.01,
            b'L' => f64::from(i32::from_le_bytes(le4())) * 1e-7,
            b'f' => f64::from(f32::from_le_bytes(le4())),
            b'd' => f64::from_le_bytes(s.try_into().ok()?),
            b'q' => i64::from_le_bytes(s.try_into().ok()?) as f64,
            b'Q' => u64::from_le_bytes(s.try_into().ok()?) as f64,
            _ => return None,
        };
        // Time columns keep the unit their name gives (µs, ms): FMTU would make them seconds.
        let is_time = matches!(self.cols[i].0.as_str(), "TimeUS" | "TimeMS" | "SampleUS");
        Some(if is_time { v } else { v * self.mult.get(i).copied().unwrap_or(1.0) })
    }

    /// Column `i` as an exact integer (time stamps: an f64 cannot hold every ns).
    fn int(&self, b: &[u8], i: usize) -> Option<i64> {
        let (_, off, c) = &self.cols[i];
        let s = b.get(*off..*off + char_size(*c)?)?;
        match c {
            // A stamp past i64 (a corrupt one) saturates: the time-stamp checks downstream
            // drop it with a warning instead of the record vanishing here.
            b'Q' => Some(i64::try_from(u64::from_le_bytes(s.try_into().ok()?)).unwrap_or(i64::MAX)),
            b'q' => Some(i64::from_le_bytes(s.try_into().ok()?)),
            b'I' => Some(i64::from(u32::from_le_bytes(s.try_into().ok()?))),
            b'i' => Some(i64::from(i32::from_le_bytes(s.try_into().ok()?))),
            _ => self.value(b, i).map(|v| v as i64),
        }
    }

    fn text(&self, b: &[u8], i: usize) -> String {
        let (_, off, c) = &self.cols[i];
        let n = char_size(*c).unwrap_or(0);
        let s = b.get(*off..*off + n).unwrap_or(&[]);
        String::from_utf8_lossy(s).trim_end_matches('\0').to_string()
    }
}

/// How an IMU-bearing message type is read.
#[derive(Debug, Clone)]
enum Kind {
    /// `IMU`/`IMU2`/`IMU3` (instance from the name or the `I` column).
    Imu {
        time: usize,
        time_scale: i64,
        inst: Option<usize>,
        base: u32,
        gyro: [usize; 3],
        accel: [usize; 3],
        temp: Option<usize>,
    },
    /// Raw `ACC` or `GYR`.
    Raw {
        accel: bool,
        time: usize,
        inst: Option<usize>,
        xyz: [usize; 3],
    },
    /// Batch header and data.
    BatchHead,
    BatchData,
    Param,
}

struct Batch {
    gyro: bool,
    instance: u32,
    mul: f64,
    rate_hz: f64,
    sample_us: f64,
}

struct State<'s, 'k> {
    path: &'s Path,
    only: Option<usize>,
    sink: &'s mut Sink<'k>,
    out: Contents,
    fmts: HashMap<u8, Fmt>,
    kinds: HashMap<u8, Option<Kind>>,
    /// Pending FMTU multiplier strings by type (applied once the MULT table is known).
    mult_chars: HashMap<u8, String>,
    mults: HashMap<u8, f64>,
    streams: HashMap<String, usize>,
    raw_pairs: HashMap<u32, (usize, Pairer)>,
    /// The stream of each `IMU`-like type and instance, once met (no name built per record).
    imu_streams: HashMap<(u8, u32), usize>,
    /// Paired samples waiting to be emitted (reused, so a record allocates nothing).
    paired: Vec<LogSample>,
    batch: Option<Batch>,
    params: Vec<(String, f64)>,
    err: Option<SessionError>,
}

/// Reads a DataFlash log (see the module docs).
pub fn read(path: &Path, only: Option<usize>, sink: &mut Sink<'_>) -> Result<Contents, SessionError> {
    let (file, _) = crate::session::open::open_regular(path)?;
    let mut input = std::io::BufReader::with_capacity(1 << 16, file);
    let io = |source| SessionError::Io { path: path.to_path_buf(), source };
    let mut st = State {
        path,
        only,
        sink,
        out: Contents::new(LogFormat::DataFlash),
        fmts: HashMap::new(),
        kinds: HashMap::new(),
        mult_chars: HashMap::new(),
        mults: HashMap::new(),
        streams: HashMap::new(),
        raw_pairs: HashMap::new(),
        imu_streams: HashMap::new(),
        paired: Vec::new(),
        batch: None,
        params: Vec::new(),
        err: None,
    };
    // FMT describes itself: 89 bytes with the 3 header bytes.
    st.fmts.insert(FMT, Fmt { name: "FMT".into(), len: 89, cols: Vec::new(), mult: Vec::new() });
    let mut pos = 0u64;
    let mut skipped: (u64, u64) = (0, 0);
    let mut body = Vec::with_capacity(256);
    let mut h = [0u8; 3];
    loop {
        let n = super::read_up_to(&mut input, &mut h[..2]).map_err(io)?;
        if n < 2 {
            if n == 1 {
                st.out.warnings.push(format!("byte {pos}: one stray byte at the end of the file"));
            }
            break;
        }
        let mut eof = false;
        while h[..2] != [0xA3, 0x95] {
            // Garbage: step one byte and look again for A3 95.
            if skipped.1 == 0 {
                skipped.0 = pos;
            }
            skipped.1 += 1;
            pos += 1;
            h[0] = h[1];
            if super::read_up_to(&mut input, &mut h[1..2]).map_err(io)? == 0 {
                eof = true;
                break;
            }
        }
        if eof {
            break;
        }
        if super::read_up_to(&mut input, &mut h[2..3]).map_err(io)? < 1 {
            st.out.warnings.push(format!("byte {pos}: the file ends inside a record header (truncated)"));
            break;
        }
        let ty = h[2];
        let Some(len) = st.fmts.get(&ty).map(|f| f.len) else {
            return Err(SessionError::log(
                Problem::Malformed,
                path,
                pos,
                format!("message type {ty} has no FMT record before it: the log is corrupt or starts mid-way"),
            ));
        };
        let want = len.saturating_sub(3);
        body.resize(want, 0);
        let got = super::read_up_to(&mut input, &mut body).map_err(io)?;
        if got < want {
            let name = st.fmts.get(&ty).map_or(String::new(), |f| f.name.clone());
            st.out.warnings.push(format!(
                "byte {pos}: the last record ({name}, {len} bytes) is cut after {} bytes (truncated file); the records before it were read",
                got + 3
            ));
            break;
        }
        st.record(ty, &body, pos)?;
        if let Some(e) = st.err.take() {
            return Err(e);
        }
        pos += len as u64;
    }
    if skipped.1 > 0 {
        st.out.warnings.push(format!("from byte {}: {} bytes that start no record were skipped", skipped.0, skipped.1));
    }
    st.finish()
}

impl State<'_, '_> {
    fn record(&mut self, ty: u8, b: &[u8], pos: u64) -> Result<(), SessionError> {
        if ty == FMT {
            return self.fmt(b, pos);
        }
        let kind = match self.kinds.get(&ty) {
            Some(k) => k.clone(),
            None => {
                let k = self.kind(ty);
                self.kinds.insert(ty, k.clone());
                k
            }
        };
        match kind {
            Some(k) => self.imu(&k, ty, b),
            None => match self.fmts.get(&ty).map(|f| f.name.as_str()) {
                Some("FMTU") => self.fmtu(ty, b),
                Some("MULT") => self.mult(ty, b),
                _ => {}
            },
        }
        Ok(())
    }

    fn fmt(&mut self, b: &[u8], pos: u64) -> Result<(), SessionError> {
        let (Some(&ty), Some(&len)) = (b.first(), b.get(1)) else { return Ok(()) };
        let text = |r: std::ops::Range<usize>| {
            String::from_utf8_lossy(b.get(r).unwrap_or(&[])).trim_end_matches('\0').to_string()
        };
        let name = text(2..6);
        let format = text(6..22);
        let columns = text(22..86);
        let mut cols = Vec::new();
        let mut off = 0;
        for (c, col) in format.bytes().zip(columns.split(',')) {
            let Some(size) = char_size(c) else {
                return Err(SessionError::log(
                    Problem::Malformed,
                    self.path,
                    pos,
                    format!("FMT of {name}: format character '{}' is unknown", c as char),
                ));
            };
            cols.push((col.to_string(), off, c));
            off += size;
        }
        if ty != FMT {
            let mult = vec![1.0; cols.len()];
            self.fmts.insert(ty, Fmt { name, len: usize::from(len), cols, mult });
            self.kinds.remove(&ty);
            self.imu_streams.retain(|k, _| k.0 != ty);
        }
        Ok(())
    }

    fn fmtu(&mut self, ty: u8, b: &[u8]) {
        let Some(f) = self.fmts.get(&ty).cloned() else { return };
        let (Some(ti), Some(mi)) = (f.col("FmtType"), f.col("MultIds")) else { return };
        let Some(target) = f.value(b, ti) else { return };
        self.mult_chars.insert(target as u8, f.text(b, mi));
        self.apply_mults();
    }

    fn mult(&mut self, ty: u8, b: &[u8]) {
        let Some(f) = self.fmts.get(&ty).cloned() else { return };
        let (Some(ii), Some(mi)) = (f.col("Id"), f.col("Mult")) else { return };
        if let (Some(id), Some(m)) = (f.value(b, ii), f.value(b, mi)) {
            self.mults.insert(id as u8, m);
            self.apply_mults();
        }
    }

    /// Sets each FMTU-described type's multipliers (`-` and unknown ids: none; 0 never).
    fn apply_mults(&mut self) {
        for (ty, chars) in &self.mult_chars {
            if let Some(f) = self.fmts.get_mut(ty) {
                f.mult = chars
                    .bytes()
                    .chain(std::iter::repeat(b'-'))
                    .take(f.cols.len())
                    .map(|c| self.mults.get(&c).copied().filter(|m| *m != 0.0 && m.is_finite()).unwrap_or(1.0))
                    .collect();
            }
        }
    }

    fn kind(&self, ty: u8) -> Option<Kind> {
        let f = self.fmts.get(&ty)?;
        let c = |n: &str| f.col(n);
        let time = c("TimeUS").map(|i| (i, 1000)).or_else(|| c("TimeMS").map(|i| (i, 1_000_000)));
        match f.name.as_str() {
            "IMU" | "IMU2" | "IMU3" => {
                let (time, time_scale) = time?;
                let base = match f.name.as_str() {
                    "IMU2" => 1,
                    "IMU3" => 2,
                    _ => 0,
                };
                Some(Kind::Imu {
                    time,
                    time_scale,
                    inst: c("I"),
                    base,
                    gyro: [c("GyrX")?, c("GyrY")?, c("GyrZ")?],
                    accel: [c("AccX")?, c("AccY")?, c("AccZ")?],
                    temp: c("T"),
                })
            }
            "ACC" | "GYR" => {
                let accel = f.name == "ACC";
                let p = if accel { "Acc" } else { "Gyr" };
                let t = c("SampleUS").or(time.map(|t| t.0))?;
                Some(Kind::Raw {
                    accel,
                    time: t,
                    inst: c("I"),
                    xyz: [c(&format!("{p}X"))?, c(&format!("{p}Y"))?, c(&format!("{p}Z"))?],
                })
            }
            "ISBH" => Some(Kind::BatchHead),
            "ISBD" => Some(Kind::BatchData),
            "PARM" => Some(Kind::Param),
            _ => None,
        }
    }

    fn stream(&mut self, name: String, message: &str, instance: u32, has_temp: bool, six: bool) -> usize {
        if let Some(&i) = self.streams.get(&name) {
            return i;
        }
        let note = if six {
            "ArduPilot's calibrated output: the INS_* offsets and scales and AHRS_ORIENTATION in the log were applied; a fit on it calibrates on top of them"
        } else {
            "one sensor only (batch sampler): listed, not importable as a six-axis session"
        };
        self.out.streams.push(StreamDesc {
            name: name.clone(),
            message: message.into(),
            instance: Some(instance),
            frame: FRAME_AP,
            has_temp,
            six_axis: six,
            note: Some(note.into()),
        });
        let i = self.out.streams.len() - 1;
        self.streams.insert(name, i);
        i
    }

    fn emit(&mut self, stream: usize, s: &LogSample) {
        if self.only.is_some_and(|o| o != stream) {
            return;
        }
        if let Err(e) = (self.sink)(stream, s) {
            self.err.get_or_insert(e);
        }
    }

    fn imu(&mut self, k: &Kind, ty: u8, b: &[u8]) {
        // The layout is moved out for the record and put back (a clone per record had cost
        // a quarter of the import's time in allocations); nothing below looks it up.
        let Some(f) = self.fmts.get_mut(&ty).map(std::mem::take) else { return };
        self.imu_with(k, &f, ty, b);
        if let Some(slot) = self.fmts.get_mut(&ty) {
            *slot = f;
        }
    }

    fn imu_with(&mut self, k: &Kind, f: &Fmt, ty: u8, b: &[u8]) {
        let v = |i: usize| f.value(b, i);
        let v3 = |c: &[usize; 3]| Some([v(c[0])?, v(c[1])?, v(c[2])?]);
        match k {
            Kind::Imu { time, time_scale, inst, base, gyro, accel, temp } => {
                let instance = inst.and_then(v).map_or(*base, |i| i as u32);
                let stream = match self.imu_streams.get(&(ty, instance)) {
                    Some(&s) => s,
                    None => {
                        let name = if inst.is_some() { format!("IMU[{instance}]") } else { f.name.clone() };
                        let s = self.stream(name, "IMU", instance, temp.is_some(), true);
                        self.imu_streams.insert((ty, instance), s);
                        s
                    }
                };
                let (Some(t), Some(g), Some(a)) = (f.int(b, *time), v3(gyro), v3(accel)) else { return };
                let t_ns = t.saturating_mul(*time_scale);
                let temp_c = temp.and_then(v);
                self.emit(stream, &LogSample { t_ns, gyro_rad_s: g, accel_m_s2: a, temp_c });
            }
            Kind::Raw { accel, time, inst, xyz } => {
                let instance = inst.and_then(v).map_or(0, |i| i as u32);
                let stream = match self.raw_pairs.get(&instance) {
                    Some(p) => p.0,
                    None => {
                        let s = self.stream(format!("ACC+GYR[{instance}]"), "ACC + GYR", instance, false, true);
                        self.raw_pairs.insert(instance, (s, Pairer::default()));
                        s
                    }
                };
                if self.only.is_some_and(|o| o != stream) {
                    return;
                }
                let (Some(t), Some(x)) = (f.int(b, *time), v3(xyz)) else { return };
                let t_ns = t.saturating_mul(1000);
                let mut out = std::mem::take(&mut self.paired);
                if let Some((_, p)) = self.raw_pairs.get_mut(&instance) {
                    if *accel {
                        p.accel(t_ns, x, None, &mut |s| out.push(s));
                    } else {
                        p.gyro(t_ns, x, None, &mut |s| out.push(s));
                    }
                }
                for s in out.drain(..) {
                    self.emit(stream, &s);
                }
                self.paired = out;
            }
            Kind::BatchHead => {
                let g = |n: &str| f.col(n).and_then(v);
                let (Some(kind), Some(mul), Some(rate)) = (g("type"), g("mul"), g("smp_rate")) else { return };
                self.batch = Some(Batch {
                    gyro: kind.round() as i64 == 1,
                    instance: g("instance").unwrap_or(0.0) as u32,
                    mul: if mul != 0.0 { mul } else { 1.0 },
                    rate_hz: rate,
                    sample_us: g("SampleUS").unwrap_or(0.0),
                });
            }
            Kind::BatchData => self.batch_data(f, b),
            Kind::Param => {
                let (Some(ni), Some(vi)) = (f.col("Name"), f.col("Value")) else { return };
                let name = f.text(b, ni);
                let wanted = [
                    "INS_ACCOFFS",
                    "INS_ACCSCAL",
                    "INS_GYROFFS",
                    "INS_ACC2OFFS",
                    "INS_ACC2SCAL",
                    "INS_GYR2OFFS",
                    "INS_ACC3OFFS",
                    "INS_ACC3SCAL",
                    "INS_GYR3OFFS",
                    "INS_TCAL",
                    "AHRS_ORIENTATION",
                ];
                if wanted.iter().any(|w| name.starts_with(w)) {
                    if let Some(val) = v(vi) {
                        match self.params.iter_mut().find(|p| p.0 == name) {
                            Some(p) => p.1 = val,
                            None => self.params.push((name, val)),
                        }
                    }
                }
            }
        }
    }
}

/// The parameters of `applied` that act on IMU `instance` (ArduPilot numbers the second
/// IMU's `INS_ACC2OFFS_*`, `INS_GYR2OFFS_*` and `INS_TCAL2_*`), with `AHRS_ORIENTATION`.
pub fn applied_to(applied: &[(String, f64)], instance: u32) -> Vec<(String, f64)> {
    let (acc, gyr) = match instance {
        0 => ("INS_ACC".to_string(), "INS_GYR".to_string()),
        n => (format!("INS_ACC{}", n + 1), format!("INS_GYR{}", n + 1)),
    };
    let tcal = format!("INS_TCAL{}_", instance + 1);
    applied
        .iter()
        .filter(|(n, _)| {
            let rest = |p: &str| n.strip_prefix(p).is_some_and(|r| r.starts_with("OFFS") || r.starts_with("SCAL"));
            n == "AHRS_ORIENTATION" || n.starts_with(&tcal) || n == "INS_TCAL_OPTIONS" || rest(&acc) || rest(&gyr)
        })
        .cloned()
        .collect()
}

impl State<'_, '_> {
    /// One `ISBD` block: `x`, `y`, `z` int16[32] ÷ `mul`, at the header's rate from its
    /// `SampleUS`, block `seqno` × 32 samples in.
    fn batch_data(&mut self, f: &Fmt, b: &[u8]) {
        let Some(h) = &self.batch else { return };
        let (gyro, instance, mul, rate, t0) = (h.gyro, h.instance, h.mul, h.rate_hz, h.sample_us);
        let which = if gyro { "gyro" } else { "accel" };
        let stream = self.stream(
            format!("ISB{}[{instance}]", if gyro { "G" } else { "A" }),
            &format!("ISBH + ISBD ({which} batch)"),
            instance,
            false,
            false,
        );
        let (Some(xi), Some(yi), Some(zi)) = (f.col("x"), f.col("y"), f.col("z")) else { return };
        let seq = f.col("seqno").and_then(|i| f.value(b, i)).unwrap_or(0.0);
        let arr = |i: usize, k: usize| {
            let off = f.cols[i].1 + 2 * k;
            b.get(off..off + 2).map(|s| f64::from(i16::from_le_bytes([s[0], s[1]])) / mul)
        };
        for k in 0..32 {
            let (Some(x), Some(y), Some(z)) = (arr(xi, k), arr(yi, k), arr(zi, k)) else { return };
            let t_us = t0 + (seq * 32.0 + k as f64) * 1e6 / rate.max(1e-9);
            let (g, a) = if gyro { ([x, y, z], [f64::NAN; 3]) } else { ([f64::NAN; 3], [x, y, z]) };
            self.emit(stream, &LogSample { t_ns: (t_us * 1000.0) as i64, gyro_rad_s: g, accel_m_s2: a, temp_c: None });
        }
    }

    fn finish(mut self) -> Result<Contents, SessionError> {
        self.out.applied = std::mem::take(&mut self.params);
        let mut pairs: Vec<(usize, Pairer)> = self.raw_pairs.drain().map(|(_, v)| v).collect();
        pairs.sort_by_key(|p| p.0);
        for (stream, mut p) in pairs {
            let mut out = Vec::new();
            p.finish(&mut |s| out.push(s));
            for s in out {
                self.emit(stream, &s);
            }
            if let Some(w) = p.unpaired_warning(&self.out.streams[stream].name) {
                self.out.warnings.push(w);
            }
        }
        if let Some(e) = self.err {
            return Err(e);
        }
        Ok(self.out)
    }
}
