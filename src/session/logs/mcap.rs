//! MCAP (mcap.dev specification, version 0), read record by record: magic, then records of
//! (u8 opcode, u64 length, content). Only what an IMU import needs is parsed — schemas,
//! channels, messages and chunks (zstd, lz4 or none) — and message index records, to count
//! the messages of a chunk that could not be read.
//!
//! Why not the `mcap` crate's reader: it trusts the lengths in the file. A corrupt length
//! made it panic (`capacity overflow`, index out of range) or abort on a terabyte
//! allocation, and a chunk whose `uncompressed_size` was zeroed vanished without a word.
//! Here every length is checked against what holds it (the file, the record, the chunk)
//! before anything is allocated, a chunk is decompressed to at most the size it declares
//! (and [`MAX_CHUNK`]) and checked against its CRC, and a record whose length does not lead
//! to another record is corruption: said with its byte offset, and reading resumes at the
//! next place where two records in a row make sense. The samples lost are counted from the
//! chunk's message index.

use super::window::Window;
use crate::session::error::{Problem, SessionError};
use std::collections::HashMap;
use std::io::Read;
use std::path::Path;

/// The magic at both ends of the file.
pub const MAGIC: &[u8; 8] = b"\x89MCAP0\r\n";
/// The largest record or uncompressed chunk read into memory (256 MiB).
pub const MAX_CHUNK: u64 = 1 << 28;

const OP_HEADER: u8 = 0x01;
const OP_FOOTER: u8 = 0x02;
const OP_SCHEMA: u8 = 0x03;
const OP_CHANNEL: u8 = 0x04;
const OP_MESSAGE: u8 = 0x05;
const OP_CHUNK: u8 = 0x06;
const OP_MESSAGE_INDEX: u8 = 0x07;
const OP_DATA_END: u8 = 0x0F;

/// What the walk hands on.
#[derive(Debug)]
pub enum Event<'a> {
    /// A schema: id, name, encoding, data.
    Schema {
        /// Schema id.
        id: u16,
        /// Type name.
        name: String,
        /// `ros2msg`, `ros1msg`, …
        encoding: String,
        /// The definition text.
        data: &'a [u8],
    },
    /// A channel: id, schema id, topic, message encoding.
    Channel {
        /// Channel id.
        id: u16,
        /// Its schema.
        schema_id: u16,
        /// Topic name.
        topic: String,
        /// `cdr`, `ros1`, …
        encoding: String,
    },
    /// A message: channel, log time (ns), payload.
    Message {
        /// Channel id.
        channel_id: u16,
        /// Log time, ns.
        log_time: u64,
        /// The serialised message.
        data: &'a [u8],
    },
}

/// Receives each event with the byte offset of its record (of its chunk, for messages in one).
pub type OnEvent<'a> = dyn FnMut(Event<'_>, u64) -> Result<(), SessionError> + 'a;

/// What a walk found wrong: warnings (with offsets) and messages lost per channel.
#[derive(Debug, Default)]
pub struct Damage {
    /// What was skipped and why, with byte offsets.
    pub warnings: Vec<String>,
    /// Messages known lost (from the message index of a chunk that could not be read), per channel.
    pub lost: HashMap<u16, u64>,
}

/// Minimum content length of each record kind.
fn min_len(op: u8) -> Option<u64> {
    Some(match op {
        OP_HEADER => 8,
        OP_FOOTER => 20,
        OP_SCHEMA => 14,
        OP_CHANNEL => 16,
        OP_MESSAGE => 22,
        OP_CHUNK => 40,
        OP_MESSAGE_INDEX => 6,
        0x08 => 48,
        0x09..=0x0E => 4,
        OP_DATA_END => 4,
        0x80..=0xFF => 0,
        _ => return None,
    })
}

/// A little-endian field reader over one record's content, refusing lengths past its end.
struct Fields<'a> {
    b: &'a [u8],
    p: usize,
}

impl<'a> Fields<'a> {
    fn take(&mut self, n: u64) -> Option<&'a [u8]> {
        let n = usize::try_from(n).ok()?;
        let end = self.p.checked_add(n).filter(|&e| e <= self.b.len())?;
        let s = &self.b[self.p..end];
        self.p = end;
        Some(s)
    }
    fn u16(&mut self) -> Option<u16> {
        self.take(2).map(|s| u16::from_le_bytes([s[0], s[1]]))
    }
    fn u32(&mut self) -> Option<u32> {
        self.take(4).map(|s| u32::from_le_bytes([s[0], s[1], s[2], s[3]]))
    }
    fn u64(&mut self) -> Option<u64> {
        self.take(8).and_then(|s| s.try_into().ok()).map(u64::from_le_bytes)
    }
    fn string(&mut self) -> Option<String> {
        let n = self.u32()?;
        self.take(u64::from(n)).map(|s| String::from_utf8_lossy(s).into_owned())
    }
    fn bytes32(&mut self) -> Option<&'a [u8]> {
        let n = self.u32()?;
        self.take(u64::from(n))
    }
    fn rest(&mut self) -> &'a [u8] {
        let s = &self.b[self.p..];
        self.p = self.b.len();
        s
    }
}

/// Parses one schema, channel or message record into its event (`None`: another kind, or
/// a record whose fields do not fit it).
fn event(op: u8, b: &[u8]) -> Option<Option<Event<'_>>> {
    let mut f = Fields { b, p: 0 };
    Some(Some(match op {
        OP_SCHEMA => Event::Schema { id: f.u16()?, name: f.string()?, encoding: f.string()?, data: f.bytes32()? },
        OP_CHANNEL => Event::Channel { id: f.u16()?, schema_id: f.u16()?, topic: f.string()?, encoding: f.string()? },
        OP_MESSAGE => {
            let channel_id = f.u16()?;
            f.u32()?;
            let log_time = f.u64()?;
            f.u64()?;
            Event::Message { channel_id, log_time, data: f.rest() }
        }
        _ => return Some(None),
    }))
}

/// Walks the MCAP file at `path`, handing schemas, channels and messages to `on`.
pub fn walk(path: &Path, on: &mut OnEvent<'_>) -> Result<Damage, SessionError> {
    let (file, size) = crate::session::open::open_regular(path)?;
    let io = |source| SessionError::Io { path: path.to_path_buf(), source };
    let mut win = Window::new(file);
    if win.get(0, 8).map_err(io)? != MAGIC {
        return Err(SessionError::log(Problem::Format, path, 0, "not an MCAP file: expected its 8-byte magic"));
    }
    let mut dmg = Damage::default();
    summary_first(&mut win, size, on).map_err(io)??;
    let mut chunk = Vec::new();
    // Messages handed on per channel from the last chunk (checked against its message index).
    let mut from_chunk: Option<(u64, bool, HashMap<u16, u64>)> = None;
    let mut pos = 8u64;
    let mut footer = false;
    while pos < size {
        let h = win.get(pos, 9).map_err(io)?;
        if h.len() < 9 {
            dmg.warnings.push(format!("byte {pos}: the file ends inside a record header (cut off)"));
            break;
        }
        let op = h[0];
        let len = u64::from_le_bytes(h[1..9].try_into().unwrap_or([0; 8]));
        let next = (pos + 9).checked_add(len);
        let fits = next.is_some_and(|n| n <= size) && len <= MAX_CHUNK;
        if !fits && min_len(op).is_some_and(|m| len >= m) && len <= MAX_CHUNK && pos + 9 + len > size {
            dmg.warnings.push(format!(
                "byte {pos}: the last record (opcode 0x{op:02x}, {len} bytes) is cut by the end of the file; the records before it were read"
            ));
            break;
        }
        let next = next.unwrap_or(u64::MAX);
        if !fits || !plausible(op, len) || !follows(&mut win, next, size).map_err(io)? {
            pos = resync(&mut win, pos, size, &mut dmg).map_err(io)?;
            continue;
        }
        let content = win.get(pos + 9, len as usize).map_err(io)?;
        match op {
            OP_FOOTER => {
                footer = true;
                break;
            }
            OP_CHUNK => {
                let ok = match unpack(content, &mut chunk) {
                    Ok(()) => true,
                    Err(m) => {
                        dmg.warnings.push(format!("byte {pos}: a chunk of {len} bytes {m}: its messages are lost (counted from its message index)"));
                        false
                    }
                };
                let mut sent = HashMap::new();
                if ok {
                    inner_records(&chunk, pos, on, &mut sent, &mut dmg)?;
                }
                from_chunk = Some((pos, ok, sent));
            }
            OP_MESSAGE_INDEX => {
                let mut f = Fields { b: content, p: 0 };
                if let (Some(ch), Some(n), Some((at, _, sent))) = (f.u16(), f.u32(), from_chunk.as_ref()) {
                    let listed = u64::from(n) / 16;
                    let got = sent.get(&ch).copied().unwrap_or(0);
                    if listed > got {
                        *dmg.lost.entry(ch).or_insert(0) += listed - got;
                        dmg.warnings.push(format!(
                            "byte {at}: the chunk there lists {listed} messages of channel {ch} in its index, {got} were read"
                        ));
                    }
                }
            }
            OP_DATA_END => from_chunk = None,
            _ => {
                from_chunk = from_chunk.filter(|_| op == OP_MESSAGE_INDEX);
                if let Some(Some(ev)) = event(op, content) {
                    on(ev, pos)?;
                } else if event(op, content).is_none() {
                    dmg.warnings.push(format!(
                        "byte {pos}: a record (opcode 0x{op:02x}) whose fields do not fit its length: skipped"
                    ));
                }
            }
        }
        pos = next;
    }
    if !footer && pos >= size {
        dmg.warnings.push(
            "the file has no footer: it was cut (recording stopped?); every record before the end was read".into(),
        );
    }
    Ok(dmg)
}

/// The schemas and channels of the summary section, handed on before the data are read
/// (so that a chunk lost to corruption does not take its channel with it): from the footer's
/// `summary_start`, when the file ends in a footer and the magic. Anything that does not
/// fit is left to the data section.
fn summary_first<R: Read + std::io::Seek>(
    win: &mut Window<R>,
    size: u64,
    on: &mut OnEvent<'_>,
) -> std::io::Result<Result<(), SessionError>> {
    let Some(footer_at) = size.checked_sub(8 + 9 + 20) else { return Ok(Ok(())) };
    let tail = win.get(footer_at, 9 + 20 + 8)?.to_vec();
    if tail.len() < 37 || tail[0] != OP_FOOTER || &tail[29..37] != MAGIC {
        return Ok(Ok(()));
    }
    let start = u64::from_le_bytes(tail[9..17].try_into().unwrap_or([0; 8]));
    if start < 8 || start >= footer_at {
        return Ok(Ok(()));
    }
    let mut pos = start;
    while pos < footer_at {
        let h = win.get(pos, 9)?;
        if h.len() < 9 {
            break;
        }
        let (op, len) = (h[0], u64::from_le_bytes(h[1..9].try_into().unwrap_or([0; 8])));
        let Some(next) = (pos + 9).checked_add(len).filter(|&n| n <= footer_at && len <= MAX_CHUNK) else { break };
        if !plausible(op, len) {
            break;
        }
        if op == OP_SCHEMA || op == OP_CHANNEL {
            let content = win.get(pos + 9, len as usize)?;
            if let Some(Some(ev)) = event(op, content) {
                if let Err(e) = on(ev, pos) {
                    return Ok(Err(e));
                }
            }
        }
        pos = next;
    }
    Ok(Ok(()))
}

/// Whether a record of `op` may be `len` bytes long.
fn plausible(op: u8, len: u64) -> bool {
    min_len(op).is_some_and(|m| len >= m) && (op != OP_FOOTER || len == 20) && (op != OP_DATA_END || len == 4)
}

/// Whether a record (or the closing magic, or the end) starts at `at`.
fn follows<R: Read + std::io::Seek>(win: &mut Window<R>, at: u64, size: u64) -> std::io::Result<bool> {
    if at == size {
        return Ok(true);
    }
    let h = win.get(at, 9)?;
    if h.len() == 8 && h == MAGIC {
        return Ok(true);
    }
    if h.len() < 9 {
        return Ok(false);
    }
    let len = u64::from_le_bytes(h[1..9].try_into().unwrap_or([0; 8]));
    Ok(plausible(h[0], len) && (at + 9).checked_add(len).is_some_and(|n| n <= size))
}

/// After a corrupt record header at `pos`: the next offset where two records in a row make sense.
fn resync<R: Read + std::io::Seek>(win: &mut Window<R>, pos: u64, size: u64, dmg: &mut Damage) -> std::io::Result<u64> {
    let mut q = pos + 1;
    while q < size {
        let h = win.get(q, 9)?;
        if h.len() < 9 {
            q = size;
            break;
        }
        let (op, len) = (h[0], u64::from_le_bytes(h[1..9].try_into().unwrap_or([0; 8])));
        if op != 0 && op < 0x10 && plausible(op, len) {
            if let Some(next) = (q + 9).checked_add(len).filter(|&n| n <= size) {
                if follows(win, next, size)? {
                    break;
                }
            }
        }
        q += 1;
    }
    dmg.warnings.push(format!(
        "byte {pos}: a corrupt record header (its opcode or length does not lead to another record); {} bytes skipped to the next good record at byte {q}",
        q - pos
    ));
    Ok(q)
}

/// Decompresses a chunk record's content into `out`, checked against its declared size and CRC.
fn unpack(content: &[u8], out: &mut Vec<u8>) -> Result<(), String> {
    let mut f = Fields { b: content, p: 0 };
    let bad = || "whose fields do not fit its length".to_string();
    f.u64().ok_or_else(bad)?;
    f.u64().ok_or_else(bad)?;
    let usize_ = f.u64().ok_or_else(bad)?;
    let crc = f.u32().ok_or_else(bad)?;
    let compression = f.string().ok_or_else(bad)?;
    let n = f.u64().ok_or_else(bad)?;
    let data = f.take(n).ok_or_else(|| format!("claims {n} bytes of records, more than it holds"))?;
    if usize_ > MAX_CHUNK {
        return Err(format!("claims {usize_} bytes uncompressed, more than crosscal reads at once"));
    }
    out.clear();
    let got = match compression.as_str() {
        "" => {
            out.extend_from_slice(data);
            Ok(data.len())
        }
        "zstd" => zstd::stream::read::Decoder::new(data)
            .map_err(|e| e.to_string())?
            .take(usize_ + 1)
            .read_to_end(out)
            .map_err(|e| e.to_string()),
        "lz4" => lz4_flex::frame::FrameDecoder::new(data).take(usize_ + 1).read_to_end(out).map_err(|e| e.to_string()),
        other => return Err(format!("is compressed with '{other}', which crosscal does not read (zstd, lz4 or none)")),
    };
    match got {
        Ok(k) if k as u64 == usize_ => {}
        Ok(k) if k as u64 > usize_ => return Err(format!("unpacks to more than the {usize_} bytes its header says")),
        Ok(k) => return Err(format!("unpacks to {k} bytes, its header says {usize_}")),
        Err(e) => return Err(format!("does not decompress ({compression}): {e}")),
    }
    if crc != 0 && crc32fast::hash(out) != crc {
        return Err("fails its CRC check (corrupt bytes)".into());
    }
    Ok(())
}

/// The records inside an unpacked chunk (at byte `at` of the file).
fn inner_records(
    buf: &[u8],
    at: u64,
    on: &mut OnEvent<'_>,
    sent: &mut HashMap<u16, u64>,
    dmg: &mut Damage,
) -> Result<(), SessionError> {
    let mut f = Fields { b: buf, p: 0 };
    while f.p < buf.len() {
        let p = f.p;
        let (Some(op), Some(len)) = (f.take(1).map(|s| s[0]), f.u64()) else {
            dmg.warnings.push(format!("byte {at}: the chunk there is cut inside a record header at offset {p}"));
            return Ok(());
        };
        let Some(content) = f.take(len).filter(|_| plausible(op, len)) else {
            dmg.warnings.push(format!(
                "byte {at}: the chunk there holds a corrupt record at offset {p} (opcode 0x{op:02x}, {len} bytes): the rest of the chunk is skipped"
            ));
            return Ok(());
        };
        match event(op, content) {
            Some(Some(ev)) => {
                if let Event::Message { channel_id, .. } = ev {
                    *sent.entry(channel_id).or_insert(0) += 1;
                }
                on(ev, at)?;
            }
            Some(None) => {}
            None => dmg.warnings.push(format!(
                "byte {at}: the chunk there holds a record at offset {p} (opcode 0x{op:02x}) whose fields do not fit its length: skipped"
            )),
        }
    }
    Ok(())
}
