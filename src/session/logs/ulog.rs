//! PX4 ULog (PX4 developer guide, "ULog File Format"): a 16-byte header (`ULog` 01 12 35,
//! version, start time µs), then messages of (u16 size, u8 type, payload). Formats ('F')
//! describe each topic's fields as text; parameters ('P') hold the calibration the
//! autopilot applied (`CAL_ACCn_*`, `CAL_GYROn_*`, `SENS_BOARD_ROT`, `TC_*`);
//! subscriptions ('A') bind a message id to a topic and `multi_id`; data ('D') follows.
//!
//! IMU streams: `sensor_combined` (the voted IMU, FRD body frame, calibrated) and, per
//! `multi_id`, `sensor_accel` + `sensor_gyro` (per-device values with `temperature`, paired
//! on the gyro's clock by [`super::Pairer`]). Fields are found by name, never by offset, so
//! both the 2016 layout (`gyro_integral_dt` float seconds) and later ones read alike; a
//! trailing `_padding` field may be missing from the data (the specification allows it).
//! Dropouts ('O') are counted; data appended after a crash (flag bits 'B', incompatible bit
//! 0) is read from its offsets; a message cut by the end of the file is a warning.

use super::num::Num as Basic;
use super::{Contents, LogFormat, LogSample, Pairer, Sink, StreamDesc};
use crate::session::error::{Problem, SessionError};
use std::collections::HashMap;
use std::path::Path;

const FRAME_PX4: &str = "PX4 FRD (x forward, y right, z down), rad/s and m/s^2";

/// A field's location in a topic's data: byte offset and type.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Field {
    offset: usize,
    ty: Basic,
}

/// A ULog basic type name's number type and size (`bool`, `char` are bytes).
fn basic(s: &str) -> Option<(Basic, usize)> {
    let b = match s {
        "int8_t" => Basic::I8,
        "uint8_t" | "bool" | "char" => Basic::U8,
        "int16_t" => Basic::I16,
        "uint16_t" => Basic::U16,
        "int32_t" => Basic::I32,
        "uint32_t" => Basic::U32,
        "int64_t" => Basic::I64,
        "uint64_t" => Basic::U64,
        "float" => Basic::F32,
        "double" => Basic::F64,
        _ => return None,
    };
    Some((b, b.size()))
}

/// A topic's format: `name:type field;…`, flattened to leaf fields by dotted name.
#[derive(Debug, Clone, Default)]
struct Format {
    text: String,
}

/// Flattens format `name` into `out` (leaf name → field), starting at `base`; returns its size.
fn flatten(
    formats: &HashMap<String, Format>,
    name: &str,
    prefix: &str,
    base: usize,
    out: &mut HashMap<String, Field>,
    depth: usize,
) -> Result<usize, String> {
    if depth > 8 {
        return Err(format!("format '{name}' nests more than 8 deep"));
    }
    let f = formats.get(name).ok_or_else(|| format!("format '{name}' is used but never defined"))?;
    let mut off = base;
    for item in f.text.split(';').filter(|s| !s.trim().is_empty()) {
        let mut w = item.split_whitespace();
        let (Some(ty), Some(field)) = (w.next(), w.next()) else {
            return Err(format!("format '{name}': field '{item}' is not 'type name'"));
        };
        let (base_ty, count) = match ty.find('[') {
            Some(i) => {
                let n = ty[i + 1..]
                    .trim_end_matches(']')
                    .parse::<usize>()
                    .map_err(|_| format!("format '{name}': array '{ty}'"))?;
                (&ty[..i], n)
            }
            None => (ty, 1),
        };
        for k in 0..count.min(1 << 16) {
            let leaf = if count > 1 || ty.contains('[') {
                format!("{prefix}{field}[{k}]")
            } else {
                format!("{prefix}{field}")
            };
            match basic(base_ty) {
                Some((b, size)) => {
                    out.insert(leaf, Field { offset: off, ty: b });
                    off += size;
                }
                None => off = flatten(formats, base_ty, &format!("{leaf}."), off, out, depth + 1)?,
            }
        }
    }
    Ok(off)
}

/// The byte size of format `name` and of its trailing `_padding` field (which a data
/// message may leave out), without expanding its arrays; `None` when a type is unknown.
fn format_size(formats: &HashMap<String, Format>, name: &str, depth: usize) -> Option<(usize, usize)> {
    if depth > 8 {
        return None;
    }
    let f = formats.get(name)?;
    let (mut total, mut pad) = (0usize, 0usize);
    for item in f.text.split(';').filter(|s| !s.trim().is_empty()) {
        let mut w = item.split_whitespace();
        let (ty, field) = (w.next()?, w.next()?);
        let (base_ty, count) = match ty.find('[') {
            Some(i) => (&ty[..i], ty[i + 1..].trim_end_matches(']').parse::<usize>().ok()?),
            None => (ty, 1),
        };
        let one = match basic(base_ty) {
            Some((_, size)) => size,
            None => format_size(formats, base_ty, depth + 1)?.0,
        };
        let bytes = one.checked_mul(count)?;
        total = total.checked_add(bytes)?;
        pad = if field.starts_with("_padding") { bytes } else { 0 };
    }
    (total <= 65_535).then_some((total, pad))
}

/// How to read the IMU fields of a subscribed topic.
#[derive(Debug, Clone)]
enum Reader {
    Combined { t: Field, gyro: [Field; 3], accel: [Field; 3], stream: usize },
    Sensor { accel: bool, t: Field, xyz: [Field; 3], temp: Option<Field>, multi: u8 },
}

fn find(fields: &HashMap<String, Field>, names: &[&str]) -> Option<Field> {
    names.iter().find_map(|n| fields.get(*n).copied())
}

fn xyz(fields: &HashMap<String, Field>, arrays: &[&str], scalars: [&str; 3]) -> Option<[Field; 3]> {
    for a in arrays {
        if let (Some(x), Some(y), Some(z)) =
            (fields.get(&format!("{a}[0]")), fields.get(&format!("{a}[1]")), fields.get(&format!("{a}[2]")))
        {
            return Some([*x, *y, *z]);
        }
    }
    Some([*fields.get(scalars[0])?, *fields.get(scalars[1])?, *fields.get(scalars[2])?])
}

struct State<'s, 'k> {
    path: &'s Path,
    only: Option<usize>,
    sink: &'s mut Sink<'k>,
    out: Contents,
    formats: HashMap<String, Format>,
    subs: HashMap<u16, Option<Reader>>,
    /// Stream index and pairer of each `multi_id` of sensor_accel/sensor_gyro.
    pairs: HashMap<u8, (usize, Pairer)>,
    dropouts: (u64, f64),
    params: Vec<(String, f64)>,
    err: Option<SessionError>,
    /// Size range of each subscribed message id's data message (payload bytes, with the
    /// 2-byte id; a trailing `_padding` may be left out); `None` when its format is unknown.
    sizes: HashMap<u16, Option<(usize, usize)>>,
    /// IMU samples lost in corrupt stretches (estimated from the headers found in them).
    lost: u64,
}

/// Reads a ULog (see the module docs).
pub fn read(path: &Path, only: Option<usize>, sink: &mut Sink<'_>) -> Result<Contents, SessionError> {
    let (file, size) = crate::session::open::open_regular(path)?;
    let mut input = std::io::BufReader::with_capacity(1 << 16, file);
    let io = |source| SessionError::Io { path: path.to_path_buf(), source };
    let mut head = [0u8; 16];
    if super::read_up_to(&mut input, &mut head).map_err(io)? < 16 || !head.starts_with(b"ULog\x01\x12\x35") {
        return Err(SessionError::log(
            Problem::Format,
            path,
            0,
            "not a ULog: expected the 16-byte header 'ULog' 01 12 35",
        ));
    }
    let mut st = State {
        path,
        only,
        sink,
        out: Contents::new(LogFormat::ULog),
        formats: HashMap::new(),
        subs: HashMap::new(),
        pairs: HashMap::new(),
        dropouts: (0, 0.0),
        params: Vec::new(),
        err: None,
        sizes: HashMap::new(),
        lost: 0,
    };
    let mut win = super::window::Window::new(input.into_inner());
    let mut appended: Vec<u64> = Vec::new();
    let mut pos = 16u64;
    let mut end = size;
    let mut segment = 0usize;
    loop {
        if pos >= end {
            // Appended data (after a crash) lives at the offsets the flag bits gave.
            if segment < appended.len() {
                pos = appended[segment];
                end = appended.get(segment + 1).copied().unwrap_or(size);
                segment += 1;
                continue;
            }
            break;
        }
        let h = win.get(pos, 5).map_err(io)?;
        let msg_size = h.get(..2).map_or(0, |s| usize::from(u16::from_le_bytes([s[0], s[1]])));
        let next = pos + 3 + msg_size as u64;
        let ok_here = st.plausible(h, pos == 16);
        let (have, ty) = (h.len(), h.get(2).copied().unwrap_or(0));
        if have >= 3 && ok_here && next > end && end - pos < 3 + 65_535 {
            let what =
                if segment < appended.len() { "the data before the appended segment end" } else { "the file ends" };
            st.out
                .warnings
                .push(format!("byte {pos}: {what} inside a message (cut off); the messages before it were read"));
            pos = end;
            continue;
        }
        if have < 3 {
            st.out.warnings.push(format!("byte {pos}: the file ends inside a message header (cut off)"));
            pos = end;
            continue;
        }
        // A length is trusted only when the header after the message is a header too.
        let sub = subscribed_id(ty, win.get(pos + 3, 3).map_err(io)?);
        let ok_next = next == end || (next < end && st.plausible_after(win.get(next, 5).map_err(io)?, false, sub));
        // A data message whose size is its format's is trusted even when the header after it
        // is not (that header is the corrupt one, and is met next).
        if !(ok_here && (ok_next || ty == b'D')) {
            pos = st.resync(&mut win, pos, end).map_err(io)?;
            continue;
        }
        let buf = win.get(pos + 3, msg_size).map_err(io)?;
        if ty == b'B' && pos == 16 {
            appended = flag_bits(path, buf, size)?;
            if let Some(&first) = appended.first() {
                end = first;
            }
        } else {
            st.message(ty, buf, pos)?;
        }
        if let Some(e) = st.err.take() {
            return Err(e);
        }
        pos = next;
    }
    st.finish()
}

/// The message id an `A` (subscription) message with payload start `p` subscribes.
fn subscribed_id(ty: u8, p: &[u8]) -> Option<u16> {
    (ty == b'A').then(|| p.get(1..3).map(|s| u16::from_le_bytes([s[0], s[1]]))).flatten()
}

/// The appended-data offsets of a flag-bits message (refusing unknown incompatible bits).
fn flag_bits(path: &Path, b: &[u8], size: u64) -> Result<Vec<u64>, SessionError> {
    let incompat = b.get(8..16).unwrap_or(&[]);
    if incompat.first().is_some_and(|&x| x & !1 != 0) || incompat.iter().skip(1).any(|&x| x != 0) {
        return Err(SessionError::log(
            Problem::Format,
            path,
            19,
            "the ULog sets incompatible flag bits this reader does not know: refused, as the specification requires",
        ));
    }
    let mut offs = Vec::new();
    if incompat.first().is_some_and(|&x| x & 1 == 1) {
        for k in 0..3 {
            let o = b.get(16 + 8 * k..24 + 8 * k).map_or(0, |s| u64::from_le_bytes(s.try_into().unwrap_or([0; 8])));
            if o > 0 && o < size {
                offs.push(o);
            }
        }
    }
    Ok(offs)
}

fn key_value(b: &[u8], skip: usize) -> Option<(&str, &[u8])> {
    let kl = usize::from(*b.get(skip)?);
    let key = std::str::from_utf8(b.get(skip + 1..skip + 1 + kl)?).ok()?;
    Some((key, &b[skip + 1 + kl..]))
}

impl State<'_, '_> {
    fn message(&mut self, ty: u8, b: &[u8], pos: u64) -> Result<(), SessionError> {
        match ty {
            b'F' => {
                let text = String::from_utf8_lossy(b);
                if let Some((name, fields)) = text.split_once(':') {
                    self.formats.insert(name.to_string(), Format { text: fields.to_string() });
                }
            }
            b'P' => {
                if let Some((key, value)) = key_value(b, 0) {
                    self.param(key, value);
                }
            }
            b'A' => self.subscribe(b, pos)?,
            b'D' => {
                let id = b.get(..2).map(|s| u16::from_le_bytes([s[0], s[1]]));
                if let Some(Some(reader)) = id.and_then(|id| self.subs.get(&id)) {
                    let reader = reader.clone();
                    self.data(&reader, &b[2..]);
                }
            }
            b'O' => {
                self.dropouts.0 += 1;
                self.dropouts.1 += f64::from(b.get(..2).map_or(0, |s| u16::from_le_bytes([s[0], s[1]]))) * 1e-3;
            }
            _ => {}
        }
        Ok(())
    }

    fn param(&mut self, key: &str, value: &[u8]) {
        let mut w = key.split_whitespace();
        let (Some(ty), Some(name)) = (w.next(), w.next()) else { return };
        let wanted = name.starts_with("CAL_ACC")
            || name.starts_with("CAL_GYRO")
            || name == "SENS_BOARD_ROT"
            || name.starts_with("TC_A")
            || name.starts_with("TC_G")
            || name.starts_with("SENS_BOARD_");
        if !wanted || name.ends_with("_ID") || name.ends_with("_PRIO") {
            return;
        }
        let v = match (ty, value.get(..4)) {
            ("float", Some(s)) => f64::from(f32::from_le_bytes([s[0], s[1], s[2], s[3]])),
            ("int32_t", Some(s)) => f64::from(i32::from_le_bytes([s[0], s[1], s[2], s[3]])),
            _ => return,
        };
        match self.params.iter_mut().find(|(n, _)| n == name) {
            Some(p) => p.1 = v,
            None => self.params.push((name.to_string(), v)),
        }
    }

    fn subscribe(&mut self, b: &[u8], pos: u64) -> Result<(), SessionError> {
        let (Some(&multi), Some(id)) = (b.first(), b.get(1..3).map(|s| u16::from_le_bytes([s[0], s[1]]))) else {
            return Err(SessionError::log(
                Problem::Malformed,
                self.path,
                pos,
                "a subscription message shorter than 3 bytes",
            ));
        };
        let name = String::from_utf8_lossy(&b[3..]).to_string();
        let size = format_size(&self.formats, &name, 0).map(|(total, pad)| (2 + total - pad, 2 + total));
        if size.is_none() {
            self.out.warnings.push(format!(
                "byte {pos}: message id {id} subscribes '{}', a message the log defines no format for (a corrupt name?): its data is not read",
                name.escape_debug()
            ));
        }
        self.sizes.insert(id, size);
        let mut fields = HashMap::new();
        let reader = match name.as_str() {
            "sensor_combined" | "sensor_accel" | "sensor_gyro" => {
                flatten(&self.formats, &name, "", 0, &mut fields, 0)
                    .map_err(|m| SessionError::log(Problem::Malformed, self.path, pos, m))?;
                let r = self.reader(&name, multi, &fields);
                if r.is_none() {
                    self.out.warnings.push(format!(
                        "byte {pos}: {name} (multi_id {multi}) lacks the fields crosscal reads (timestamp, x/y/z or gyro_rad/accelerometer_m_s2): its samples are not read"
                    ));
                }
                r
            }
            _ => None,
        };
        self.subs.insert(id, reader);
        Ok(())
    }

    fn reader(&mut self, name: &str, multi: u8, f: &HashMap<String, Field>) -> Option<Reader> {
        let t = find(f, &["timestamp_sample", "timestamp"])?;
        if name == "sensor_combined" {
            let gyro = xyz(f, &["gyro_rad", "gyro_rad_s"], ["gyro_x", "gyro_y", "gyro_z"])?;
            let accel = xyz(f, &["accelerometer_m_s2"], ["acc_x", "acc_y", "acc_z"])?;
            let stream = self.stream(
                "sensor_combined".into(),
                "sensor_combined".into(),
                None,
                false,
                "the voted IMU, calibrated by PX4 with the log's CAL_* offsets and scales, SENS_BOARD_ROT and, if TC_*_ENABLE, thermal compensation; a fit on it calibrates on top of them",
            );
            return Some(Reader::Combined { t: find(f, &["timestamp"])?, gyro, accel, stream });
        }
        let xyz = xyz(f, &[], ["x", "y", "z"])?;
        let temp = find(f, &["temperature"]);
        if !self.pairs.contains_key(&multi) {
            let stream = self.stream(
                format!("sensor_accel+gyro[{multi}]"),
                "sensor_accel + sensor_gyro".into(),
                Some(u32::from(multi)),
                temp.is_some(),
                "per-device values in the board frame; PX4 applies CAL_* after these (in vehicle_imu)",
            );
            self.pairs.insert(multi, (stream, Pairer::default()));
        }
        Some(Reader::Sensor { accel: name == "sensor_accel", t, xyz, temp, multi })
    }

    fn stream(&mut self, name: String, message: String, instance: Option<u32>, has_temp: bool, note: &str) -> usize {
        if let Some(i) = self.out.streams.iter().position(|s| s.name == name) {
            return i;
        }
        self.out.streams.push(StreamDesc {
            name,
            message,
            instance,
            frame: FRAME_PX4,
            has_temp,
            six_axis: true,
            note: Some(note.into()),
        });
        self.out.streams.len() - 1
    }

    fn data(&mut self, r: &Reader, b: &[u8]) {
        let get = |f: Field| f.ty.read_le(b, f.offset);
        match r {
            Reader::Combined { t, gyro, accel, stream } => {
                if self.only.is_some_and(|o| o != *stream) {
                    return;
                }
                let (Some(t), Some(g), Some(a)) = (get(*t), three(gyro, &get), three(accel, &get)) else { return };
                let s = LogSample { t_ns: (t as i64).saturating_mul(1000), gyro_rad_s: g, accel_m_s2: a, temp_c: None };
                if let Err(e) = (self.sink)(*stream, &s) {
                    self.err.get_or_insert(e);
                }
            }
            Reader::Sensor { accel, t, xyz, temp, multi } => {
                let Some((stream, pairer)) = self.pairs.get_mut(multi) else { return };
                let stream = *stream;
                if self.only.is_some_and(|o| o != stream) {
                    return;
                }
                let (Some(t), Some(v)) = (get(*t), three(xyz, &get)) else { return };
                let temp = temp.and_then(get);
                let sink = &mut *self.sink;
                let err = &mut self.err;
                let mut emit = |s: LogSample| {
                    if let Err(e) = sink(stream, &s) {
                        err.get_or_insert(e);
                    }
                };
                if *accel {
                    pairer.accel((t as i64).saturating_mul(1000), v, temp, &mut emit);
                } else if !pairer.gyro((t as i64).saturating_mul(1000), v, temp, &mut emit) {
                    err.get_or_insert(SessionError::log(
                        Problem::Malformed,
                        self.path,
                        0,
                        format!("sensor_gyro[{multi}]: over a million samples with no sensor_accel[{multi}] to pair them with"),
                    ));
                }
            }
        }
    }

    /// Whether `h` (at least 3 bytes: size, type, then a data message's id) can start a
    /// message here: a known type with a size its kind allows; a data message of a
    /// subscribed id, of its format's size.
    fn plausible(&self, h: &[u8], first: bool) -> bool {
        self.plausible_after(h, first, None)
    }

    /// [`Self::plausible`], with `sub` a message id the message before subscribes (its data
    /// may follow at once).
    fn plausible_after(&self, h: &[u8], first: bool, sub: Option<u16>) -> bool {
        let (Some(s), Some(&ty)) = (h.get(..2), h.get(2)) else { return false };
        let size = usize::from(u16::from_le_bytes([s[0], s[1]]));
        match ty {
            b'B' => first && size >= 40,
            b'F' | b'I' | b'M' | b'P' | b'Q' => size >= 2,
            b'A' => size >= 4,
            b'L' => size >= 9,
            b'C' => size >= 11,
            b'R' | b'O' => size == 2,
            b'S' => size == 8,
            b'D' => {
                let Some(id) = h.get(3..5).map(|s| u16::from_le_bytes([s[0], s[1]])) else { return false };
                if sub == Some(id) {
                    return size >= 2;
                }
                match self.sizes.get(&id) {
                    Some(Some((lo, hi))) => (*lo..=*hi).contains(&size),
                    Some(None) => size >= 2,
                    None => false,
                }
            }
            _ => false,
        }
    }

    /// After a corrupt message at `pos`: the next offset where two messages in a row are
    /// plausible, with a warning giving both offsets and the IMU samples lost between.
    fn resync<R: std::io::Read + std::io::Seek>(
        &mut self,
        win: &mut super::window::Window<R>,
        pos: u64,
        end: u64,
    ) -> std::io::Result<u64> {
        let imu_ids: Vec<(u16, (usize, usize))> = self
            .subs
            .iter()
            .filter(|(_, r)| r.is_some())
            .filter_map(|(id, _)| self.sizes.get(id).copied().flatten().map(|range| (*id, range)))
            .collect();
        let mut q = pos + 1;
        let mut lost = 0u64;
        // The corrupt message itself, when its header still names an IMU topic.
        let h0 = win.get(pos, 5)?;
        if h0.get(2) == Some(&b'D') && h0.len() == 5 && imu_ids.iter().any(|(id, _)| id.to_le_bytes() == h0[3..5]) {
            lost += 1;
        }
        while q < end {
            let h = win.get(q, 5)?;
            if h.len() < 3 {
                q = end;
                break;
            }
            let size = u64::from(u16::from_le_bytes([h[0], h[1]]));
            if self.plausible(h, false) {
                // An IMU data message's header inside the skipped bytes: a sample lost.
                let next = q + 3 + size;
                let imu = h[2] == b'D'
                    && imu_ids
                        .iter()
                        .any(|(id, (lo, hi))| id.to_le_bytes() == h[3..5] && (*lo..=*hi).contains(&(size as usize)));
                let ty = h[2];
                let sub = subscribed_id(ty, win.get(q + 3, 3)?);
                let ok = next == end || (next < end && self.plausible_after(win.get(next, 5)?, false, sub));
                if ok {
                    break;
                }
                lost += u64::from(imu);
            }
            q += 1;
        }
        self.lost += lost;
        self.out.refuse(format!(
            "byte {pos}: a corrupt message header (not a message of a known type and size, or not followed by one); {} bytes skipped to the next good message at byte {q}, {lost} IMU sample(s) lost there",
            q - pos
        ));
        Ok(q)
    }

    fn finish(mut self) -> Result<Contents, SessionError> {
        let mut pairs: Vec<(usize, Pairer)> = self.pairs.drain().map(|(_, v)| v).collect();
        pairs.sort_by_key(|p| p.0);
        for (stream, mut p) in pairs {
            let sink = &mut *self.sink;
            let err = &mut self.err;
            p.finish(&mut |s| {
                if let Err(e) = sink(stream, &s) {
                    err.get_or_insert(e);
                }
            });
            if let Some(w) = p.unpaired_warning(&self.out.streams[stream].name) {
                self.out.warnings.push(w);
            }
        }
        if let Some(e) = self.err {
            return Err(e);
        }
        if self.dropouts.0 > 0 {
            self.out.warnings.push(format!(
                "{} logging dropouts, {:.3} s in all (samples lost there)",
                self.dropouts.0, self.dropouts.1
            ));
        }
        if self.lost > 0 {
            self.out.warnings.push(format!("{} IMU samples lost in corrupt stretches of the log in all", self.lost));
        }
        self.out.applied = self.params;
        Ok(self.out)
    }
}

fn three(f: &[Field; 3], get: &impl Fn(Field) -> Option<f64>) -> Option<[f64; 3]> {
    Some([get(f[0])?, get(f[1])?, get(f[2])?])
}
