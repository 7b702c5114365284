//! ROS 1 bags (format 2.0, ROS wiki "Bags/Format/2.0"): `#ROSBAG V2.0\n`, then records of
//! (u32 header length, `len name=value` fields, u32 data length, data). Chunks (op 0x05)
//! hold connection (0x07) and message (0x02) records, stored as is, bz2 or lz4 (the LZ4
//! frame format); the index records (0x04, 0x06) are skipped, so an unindexed bag (a
//! recording that was cut) reads the same. Memory: one chunk, compressed and not.
//!
//! A topic is one stream whatever number of connections it has; a connection whose type
//! holds a `sensor_msgs/Imu` (its `message_definition` is in the bag) is decoded by
//! [`super::rosmsg`], with the sample time from `header.stamp` (the record's receive time
//! when the stamp is zero, which is said).

use super::rosmsg::{Definitions, Program, Wire};
use super::{Contents, LogFormat, LogSample, ReadOptions, Sink, StreamDesc};
use crate::session::error::{Problem, SessionError};
use std::collections::HashMap;
use std::io::Read;
use std::path::Path;

const MAGIC: &[u8] = b"#ROSBAG V2.0\n";
/// The largest record (header or data) read into memory, and the largest chunk unpacked: a
/// bigger claim is corruption (rosbag writes 768 KiB chunks by default).
const MAX_RECORD: usize = 1 << 28;

const OP_MSG: u8 = 0x02;
const OP_CHUNK: u8 = 0x05;
const OP_CONN: u8 = 0x07;

pub(crate) const FRAME_ROS: &str = "as published (REP 145: x forward, y left, z up), rad/s and m/s^2";

/// One record's header fields.
struct Fields<'a>(Vec<(&'a [u8], &'a [u8])>);

impl<'a> Fields<'a> {
    fn parse(buf: &'a [u8]) -> Option<Self> {
        let mut out = Vec::new();
        let mut p = 0;
        while p < buf.len() {
            let len = u32::from_le_bytes(buf.get(p..p + 4)?.try_into().ok()?) as usize;
            let f = buf.get(p + 4..p + 4 + len)?;
            let eq = f.iter().position(|&b| b == b'=')?;
            out.push((&f[..eq], &f[eq + 1..]));
            p += 4 + len;
        }
        Some(Fields(out))
    }

    fn get(&self, name: &str) -> Option<&'a [u8]> {
        self.0.iter().find(|(k, _)| *k == name.as_bytes()).map(|(_, v)| *v)
    }

    fn u32(&self, name: &str) -> Option<u32> {
        Some(u32::from_le_bytes(self.get(name)?.get(..4)?.try_into().ok()?))
    }

    fn text(&self, name: &str) -> Option<String> {
        self.get(name).map(|v| String::from_utf8_lossy(v).into_owned())
    }
}

/// A connection: its stream (when it carries an IMU) and decoder.
struct Conn {
    stream: Option<(usize, Program)>,
}

struct State<'s, 'k> {
    path: &'s Path,
    opts: &'s ReadOptions,
    only: Option<usize>,
    sink: &'s mut Sink<'k>,
    out: Contents,
    conns: HashMap<u32, Conn>,
    topics: HashMap<String, usize>,
    zero_stamps: u64,
}

/// Reads a bag (see the module docs).
pub fn read(
    path: &Path,
    opts: &ReadOptions,
    only: Option<usize>,
    sink: &mut Sink<'_>,
) -> Result<Contents, SessionError> {
    let (file, size) = crate::session::open::open_regular(path)?;
    let mut input = std::io::BufReader::with_capacity(1 << 16, file);
    let io = |source| SessionError::Io { path: path.to_path_buf(), source };
    let mut magic = [0u8; 13];
    let n = super::read_up_to(&mut input, &mut magic).map_err(io)?;
    if &magic[..n] != MAGIC {
        return Err(SessionError::log(
            Problem::Format,
            path,
            0,
            "not a ROS bag 2.0: expected '#ROSBAG V2.0' on the first line",
        ));
    }
    let mut st = State {
        path,
        opts,
        only,
        sink,
        out: Contents::new(LogFormat::Ros1Bag),
        conns: HashMap::new(),
        topics: HashMap::new(),
        zero_stamps: 0,
    };
    let mut pos = MAGIC.len() as u64;
    let mut header = Vec::new();
    let mut data = Vec::new();
    let mut chunk = Vec::new();
    loop {
        let at = pos;
        match next_record(&mut input, &mut header, &mut data, size - pos.min(size)) {
            Ok(None) => break,
            Ok(Some(len)) => pos += len,
            Err(e) => {
                st.out.warnings.push(format!("byte {at}: {e}; the records before it were read"));
                break;
            }
        }
        let fields = Fields::parse(&header).ok_or_else(|| {
            SessionError::log(Problem::Malformed, path, at, "a record header that is not a list of name=value fields")
        })?;
        let op = fields.get("op").and_then(|v| v.first().copied());
        match op {
            Some(OP_CHUNK) => {
                let unpacked = unpack_chunk(&fields, &data, &mut chunk)
                    .map_err(|m| SessionError::log(Problem::Malformed, path, at, m))?;
                let inner = if unpacked { chunk.as_slice() } else { data.as_slice() };
                st.records(inner, at)?;
            }
            Some(OP_CONN) => st.connection(&fields, &data, at)?,
            Some(OP_MSG) => st.message(&fields, &data, at, None)?,
            Some(0x03 | 0x04 | 0x06) => {}
            Some(op) => st.out.refuse(format!("byte {at}: a record of unknown op 0x{op:02x}")),
            None => return Err(SessionError::log(Problem::Malformed, path, at, "a record without an 'op' field")),
        }
    }
    if st.zero_stamps > 0 {
        st.out
            .notes
            .push(format!("{} messages had a zero header.stamp: their time is the bag's receive time", st.zero_stamps));
    }
    Ok(st.out)
}

/// Reads one top-level record into `header` and `data`; its length in bytes, or `None` at
/// the end of the file. A record that claims more than is left is an error (truncation).
fn next_record(
    input: &mut impl Read,
    header: &mut Vec<u8>,
    data: &mut Vec<u8>,
    left: u64,
) -> Result<Option<u64>, String> {
    let mut len4 = [0u8; 4];
    let n = super::read_up_to(input, &mut len4).map_err(|e| e.to_string())?;
    if n == 0 {
        return Ok(None);
    }
    if n < 4 {
        return Err("the file ends inside a record's length".into());
    }
    let hl = u32::from_le_bytes(len4) as usize;
    if hl as u64 + 8 > left || hl > MAX_RECORD {
        return Err(format!("a record header of {hl} bytes runs past the end of the file (truncated?)"));
    }
    read_exact_into(input, header, hl).map_err(|e| e.to_string())?;
    if super::read_up_to(input, &mut len4).map_err(|e| e.to_string())? < 4 {
        return Err("the file ends inside a record's data length".into());
    }
    let dl = u32::from_le_bytes(len4) as usize;
    if (hl + 8 + dl) as u64 > left || dl > MAX_RECORD {
        return Err(format!("a record of {dl} data bytes runs past the end of the file (truncated?)"));
    }
    read_exact_into(input, data, dl).map_err(|e| e.to_string())?;
    Ok(Some((hl + dl + 8) as u64))
}

fn read_exact_into(input: &mut impl Read, buf: &mut Vec<u8>, n: usize) -> std::io::Result<()> {
    buf.clear();
    buf.resize(n, 0);
    input.read_exact(buf)
}

/// Decompresses a chunk into `out` (true), or says it is stored as is (false).
fn unpack_chunk(fields: &Fields<'_>, data: &[u8], out: &mut Vec<u8>) -> Result<bool, String> {
    let compression = fields.text("compression").unwrap_or_else(|| "none".into());
    let size = fields.u32("size").ok_or("a chunk without its 'size' field")? as usize;
    if size > MAX_RECORD {
        return Err(format!("a chunk claims {size} bytes uncompressed: more than crosscal reads at once"));
    }
    out.clear();
    let got = match compression.as_str() {
        "none" => return Ok(false),
        "bz2" => bzip2::read::BzDecoder::new(data).take(size as u64 + 1).read_to_end(out),
        "lz4" => lz4_flex::frame::FrameDecoder::new(data).take(size as u64 + 1).read_to_end(out),
        other => return Err(format!("chunk compression '{other}': expected none, bz2 or lz4")),
    };
    match got {
        Ok(n) if n == size => Ok(true),
        Ok(n) => Err(format!("a {compression} chunk unpacks to {n} bytes, its header says {size}")),
        Err(e) => Err(format!("a {compression} chunk does not decompress: {e}")),
    }
}

impl State<'_, '_> {
    /// The records inside a chunk.
    fn records(&mut self, buf: &[u8], chunk_at: u64) -> Result<(), SessionError> {
        let mut p = 0usize;
        let bad = |p: usize, m: &str| {
            SessionError::log(
                Problem::Malformed,
                self.path,
                chunk_at,
                format!("inside the chunk at byte {chunk_at}, offset {p}: {m}"),
            )
        };
        while p < buf.len() {
            let hl = buf.get(p..p + 4).map(|b| u32::from_le_bytes([b[0], b[1], b[2], b[3]]) as usize);
            let hl = hl.ok_or_else(|| bad(p, "a record length is cut"))?;
            let h = buf.get(p + 4..p + 4 + hl).ok_or_else(|| bad(p, "a record header runs past the chunk"))?;
            let q = p + 4 + hl;
            let dl = buf.get(q..q + 4).map(|b| u32::from_le_bytes([b[0], b[1], b[2], b[3]]) as usize);
            let dl = dl.ok_or_else(|| bad(q, "a data length is cut"))?;
            let d = buf.get(q + 4..q + 4 + dl).ok_or_else(|| bad(q, "record data runs past the chunk"))?;
            let fields = Fields::parse(h).ok_or_else(|| bad(p, "a record header that is not name=value fields"))?;
            match fields.get("op").and_then(|v| v.first().copied()) {
                Some(OP_CONN) => self.connection(&fields, d, chunk_at)?,
                Some(OP_MSG) => self.message(&fields, d, chunk_at, Some(p))?,
                Some(op) if op != 0x03 && op != 0x04 && op != 0x06 && op != OP_CHUNK => self.out.refuse(format!(
                    "byte {chunk_at} (chunk), record at offset {p} of the chunk: a record of unknown op 0x{op:02x}"
                )),
                _ => {}
            }
            p = q + 4 + dl;
        }
        Ok(())
    }

    fn connection(&mut self, fields: &Fields<'_>, data: &[u8], at: u64) -> Result<(), SessionError> {
        let id = fields.u32("conn").ok_or_else(|| {
            SessionError::log(Problem::Malformed, self.path, at, "a connection record without 'conn'")
        })?;
        if self.conns.contains_key(&id) {
            return Ok(());
        }
        let topic = fields.text("topic").unwrap_or_default();
        let info = Fields::parse(data).ok_or_else(|| {
            SessionError::log(
                Problem::Malformed,
                self.path,
                at,
                format!("connection {id} ({topic}): its header is not name=value fields"),
            )
        })?;
        let ty = info.text("type").unwrap_or_default();
        let def = info.text("message_definition").unwrap_or_default();
        let mut defs = Definitions::new(Wire::Ros1);
        let mut program = defs.add_text(&ty, &def).ok().and_then(|()| defs.compile(&ty).ok());
        if program.is_none() {
            // A definition the user gave for this type (or for any undefined type).
            if let Some(p) = user_program(self.opts, &ty, Wire::Ros1)
                .map_err(|m| SessionError::log(Problem::Invalid, self.path, at, m))?
            {
                program = Some(p);
            }
        }
        let stream = program.map(|p| {
            let next = self.topics.len();
            let idx = *self.topics.entry(topic.clone()).or_insert(next);
            if idx == self.out.streams.len() {
                self.out.streams.push(StreamDesc {
                    name: topic.clone(),
                    message: ty.clone(),
                    instance: None,
                    frame: FRAME_ROS,
                    has_temp: false,
                    six_axis: true,
                    note: None,
                });
            }
            (idx, p)
        });
        self.conns.insert(id, Conn { stream });
        Ok(())
    }

    /// A message record (at byte `at`, or at offset `inner` of the chunk at byte `at`).
    fn message(&mut self, fields: &Fields<'_>, data: &[u8], at: u64, inner: Option<usize>) -> Result<(), SessionError> {
        let place = || match inner {
            Some(p) => format!("byte {at} (chunk), record at offset {p} of the chunk"),
            None => format!("byte {at}"),
        };
        let Some(id) = fields.u32("conn") else {
            self.out.refuse(format!("{}: a message record without its 'conn' field", place()));
            return Ok(());
        };
        let Some(conn) = self.conns.get(&id) else {
            self.out.refuse(format!("{}: a message on connection {id}, which no connection record declares", place()));
            return Ok(());
        };
        let Conn { stream: Some((idx, program)) } = conn else { return Ok(()) };
        if self.only.is_some_and(|o| o != *idx) {
            return Ok(());
        }
        let f = match program.decode(data) {
            Ok(f) => f,
            Err(e) => {
                let msg = format!("{}: a message on connection {id}, offset {} in it: {}", place(), e.offset, e.msg);
                self.out.refuse(msg);
                return Ok(());
            }
        };
        let mut t_ns = f.stamp.0 * 1_000_000_000 + i64::from(f.stamp.1);
        if t_ns == 0 {
            self.zero_stamps += 1;
            let time = fields.get("time").and_then(|b| b.get(..8)).map(|b| {
                let s = u32::from_le_bytes([b[0], b[1], b[2], b[3]]);
                let n = u32::from_le_bytes([b[4], b[5], b[6], b[7]]);
                i64::from(s) * 1_000_000_000 + i64::from(n)
            });
            t_ns = time.unwrap_or(0);
        }
        let idx = *idx;
        (self.sink)(idx, &LogSample { t_ns, gyro_rad_s: f.gyro_rad_s, accel_m_s2: f.accel_m_s2, temp_c: f.temp_c })
    }
}

/// The decoder from a definition the user gave (`--msg-def TYPE=FILE`, or `FILE` for any
/// undefined type), if one applies to `ty`.
pub(crate) fn user_program(opts: &ReadOptions, ty: &str, wire: Wire) -> Result<Option<Program>, String> {
    let short = super::rosmsg::short_name(ty);
    let Some((_, file)) = opts
        .msg_defs
        .iter()
        .find(|(t, _)| super::rosmsg::short_name(t) == short)
        .or_else(|| opts.msg_defs.iter().find(|(t, _)| t.is_empty()))
    else {
        return Ok(None);
    };
    let text = crate::atomic::read_text(file)
        .map_err(|e| format!("{}: cannot read the definition of {ty}: {e}", file.display()))?;
    let mut defs = Definitions::new(wire);
    defs.add_text(ty, &text).map_err(|e| format!("{}: {e}", file.display()))?;
    defs.compile(ty).map(Some).map_err(|e| format!("{}: {e}", file.display()))
}
