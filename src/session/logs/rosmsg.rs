//! ROS message definitions and a decoder for the `sensor_msgs/Imu` inside a message, in
//! both wire formats: ROS 1 serialisation (little-endian, packed, `Header` with a `seq`,
//! `time` = two `uint32`) and ROS 2 CDR (XCDR1 as the rmw layers write it: a 4-byte
//! encapsulation header, every primitive aligned to its size counted from the end of that
//! header, strings with their NUL counted in the length prefix).
//!
//! A definition is the `.msg` text of the top type followed by its dependencies, each after
//! a `MSG: pkg/Type` line (the layout of a ROS 1 connection header's `message_definition`
//! and of an MCAP `ros2msg` schema). The standard types an IMU message needs are built in,
//! so a custom type that wraps `sensor_msgs/Imu` needs only its own four lines.
//!
//! A definition is compiled once into a flat program ([`Program`]) that skips what is not
//! wanted and reads the stamp, angular velocity, linear acceleration and (where present)
//! a temperature field into fixed slots: no allocation per message.

use super::num::Num as Prim;
use std::collections::HashMap;

/// Wire format of a serialised message.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Wire {
    /// ROS 1: packed little-endian.
    Ros1,
    /// ROS 2: CDR with its encapsulation header (either byte order).
    Cdr,
}

/// A field type.
#[derive(Debug, Clone, PartialEq)]
enum Ty {
    /// A fixed-size primitive of `size` bytes; `kind` says how to read it.
    Prim(Prim),
    /// `string` (or `wstring` refused).
    Str,
    /// ROS 1 `time`/`duration`: two 32-bit integers.
    Time1,
    /// An array of the element type: fixed length, or a `uint32` length prefix.
    Array(Box<Ty>, Option<usize>),
    /// A message type, by full name (`pkg/Type`).
    Msg(String),
}

/// A ROS primitive type name's number type (`bool` and `char` are bytes).
fn prim(s: &str) -> Option<Prim> {
    Some(match s {
        "bool" | "uint8" | "char" => Prim::U8,
        "int8" | "byte" => Prim::I8,
        "int16" => Prim::I16,
        "uint16" => Prim::U16,
        "int32" => Prim::I32,
        "uint32" => Prim::U32,
        "int64" => Prim::I64,
        "uint64" => Prim::U64,
        "float32" => Prim::F32,
        "float64" => Prim::F64,
        _ => return None,
    })
}

/// The standard types an IMU message is made of (ROS 2 spelling; ROS 1 differences are
/// applied by [`Definitions::new`]).
const BUILTIN_ROS2: &[(&str, &str)] = &[
    ("builtin_interfaces/Time", "int32 sec\nuint32 nanosec"),
    ("std_msgs/Header", "builtin_interfaces/Time stamp\nstring frame_id"),
    ("geometry_msgs/Quaternion", "float64 x\nfloat64 y\nfloat64 z\nfloat64 w"),
    ("geometry_msgs/Vector3", "float64 x\nfloat64 y\nfloat64 z"),
    (
        "sensor_msgs/Imu",
        "std_msgs/Header header\ngeometry_msgs/Quaternion orientation\nfloat64[9] orientation_covariance\n\
         geometry_msgs/Vector3 angular_velocity\nfloat64[9] angular_velocity_covariance\n\
         geometry_msgs/Vector3 linear_acceleration\nfloat64[9] linear_acceleration_covariance",
    ),
    (
        "sensor_msgs/MagneticField",
        "std_msgs/Header header\ngeometry_msgs/Vector3 magnetic_field\nfloat64[9] magnetic_field_covariance",
    ),
    ("sensor_msgs/Temperature", "std_msgs/Header header\nfloat64 temperature\nfloat64 variance"),
];

const BUILTIN_ROS1_HEADER: &str = "uint32 seq\ntime stamp\nstring frame_id";

/// Message definitions by full name (`pkg/Type`, the ROS 2 `pkg/msg/Type` spelling folded).
#[derive(Debug, Clone)]
pub struct Definitions {
    wire: Wire,
    types: HashMap<String, Vec<(Ty, String)>>,
}

/// A problem with a definition: the type and what is wrong.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("message definition of {ty}: {msg}")]
pub struct DefError {
    /// The type being read or compiled.
    pub ty: String,
    /// What is wrong.
    pub msg: String,
}

/// `pkg/msg/Type` → `pkg/Type`.
pub fn short_name(ty: &str) -> String {
    let parts: Vec<&str> = ty.split('/').collect();
    match parts.as_slice() {
        [pkg, "msg", name] => format!("{pkg}/{name}"),
        _ => ty.to_string(),
    }
}

impl Definitions {
    /// The built-in standard types for `wire`.
    pub fn new(wire: Wire) -> Self {
        let mut d = Self { wire, types: HashMap::new() };
        for (name, text) in BUILTIN_ROS2 {
            let text = if wire == Wire::Ros1 && *name == "std_msgs/Header" { BUILTIN_ROS1_HEADER } else { text };
            if wire == Wire::Ros1 && *name == "builtin_interfaces/Time" {
                continue;
            }
            // Built-in texts are well formed; a failure here would be a bug caught by tests.
            if let Ok(fields) = parse_fields(name, text, wire) {
                d.types.insert((*name).to_string(), fields);
            }
        }
        d
    }

    /// Adds a definition text: the top type `top` first, then `MSG: pkg/Type` sections.
    /// Types given here replace the built-in ones of the same name.
    pub fn add_text(&mut self, top: &str, text: &str) -> Result<(), DefError> {
        let mut name = short_name(top);
        let mut body = String::new();
        for line in text.lines() {
            let l = line.trim();
            if l.starts_with("====") {
                continue;
            }
            if let Some(rest) = l.strip_prefix("MSG:") {
                let fields = parse_fields(&name, &body, self.wire)?;
                self.types.insert(name, fields);
                name = short_name(rest.trim());
                body.clear();
                continue;
            }
            body.push_str(line);
            body.push('\n');
        }
        let fields = parse_fields(&name, &body, self.wire)?;
        self.types.insert(name, fields);
        Ok(())
    }

    /// Whether `ty` is known.
    pub fn knows(&self, ty: &str) -> bool {
        self.types.contains_key(&short_name(ty))
    }

    /// Compiles the decoder of the `sensor_msgs/Imu` in `top` (the first one, depth first),
    /// and of a `float64 temperature` beside it when the message has one.
    pub fn compile(&self, top: &str) -> Result<Program, DefError> {
        let top = short_name(top);
        let mut ops = Vec::new();
        let mut found = false;
        self.emit(&Ty::Msg(top.clone()), &mut ops, Target::None, &mut found, 0)?;
        if !found {
            return Err(DefError { ty: top, msg: "holds no sensor_msgs/Imu".into() });
        }
        Ok(Program { ops, wire: self.wire, whole: true })
    }

    fn emit(&self, ty: &Ty, ops: &mut Vec<Op>, target: Target, found: &mut bool, depth: usize) -> Result<(), DefError> {
        if depth > 16 {
            return Err(DefError {
                ty: format!("{ty:?}"),
                msg: "nested more than 16 deep (a type that contains itself?)".into(),
            });
        }
        match ty {
            Ty::Prim(p) => ops.push(Op::Prim(*p, target.slot())),
            Ty::Str => ops.push(Op::Str),
            Ty::Time1 => {
                let (s, n) = match target {
                    Target::Stamp => (Some(SLOT_SEC), Some(SLOT_NSEC)),
                    _ => (None, None),
                };
                ops.push(Op::Prim(Prim::U32, s));
                ops.push(Op::Prim(Prim::U32, n));
            }
            Ty::Array(elem, len) => {
                let mut body = Vec::new();
                self.emit(elem, &mut body, Target::None, &mut false, depth + 1)?;
                ops.push(Op::Array { len: *len, body });
            }
            Ty::Msg(name) => {
                let fields = self.types.get(name).ok_or_else(|| DefError {
                    ty: name.clone(),
                    msg: "unknown type: give its definition (a .msg file, with MSG: sections for the types it uses)"
                        .into(),
                })?;
                let is_imu = name == "sensor_msgs/Imu" && !*found;
                if is_imu {
                    *found = true;
                }
                for (fty, fname) in fields {
                    let sub = match (is_imu, target, fname.as_str()) {
                        (true, _, "header") => Target::Header,
                        (true, _, "angular_velocity") => Target::Gyro,
                        (true, _, "linear_acceleration") => Target::Accel,
                        (false, Target::Header, "stamp") => Target::Stamp,
                        (false, Target::Stamp, "sec" | "secs") => Target::Sec,
                        (false, Target::Stamp, "nanosec" | "nsecs") => Target::Nsec,
                        (false, Target::Gyro | Target::Accel, "x" | "y" | "z") => target.axis(fname),
                        (false, Target::None, "temperature") if *found && matches!(fty, Ty::Prim(Prim::F64)) => {
                            Target::Temp
                        }
                        _ => Target::None,
                    };
                    self.emit(fty, ops, sub, found, depth + 1)?;
                }
            }
        }
        Ok(())
    }
}

fn parse_fields(name: &str, text: &str, wire: Wire) -> Result<Vec<(Ty, String)>, DefError> {
    let pkg = name.split('/').next().unwrap_or("");
    let err = |msg: String| DefError { ty: name.to_string(), msg };
    let mut out = Vec::new();
    for line in text.lines() {
        let line = line.split('#').next().unwrap_or("").trim();
        if line.is_empty() {
            continue;
        }
        let mut words = line.split_whitespace();
        let (Some(ty), Some(field)) = (words.next(), words.next()) else {
            return Err(err(format!("'{line}': expected 'type name'")));
        };
        // A constant (`uint8 X=1`, or `X = 1` split oddly) takes no room on the wire.
        if field.contains('=') || words.next().is_some_and(|w| w.starts_with('=')) {
            continue;
        }
        out.push((parse_type(ty, pkg, wire).map_err(|m| err(format!("'{line}': {m}")))?, field.to_string()));
    }
    Ok(out)
}

fn parse_type(ty: &str, pkg: &str, wire: Wire) -> Result<Ty, String> {
    if let Some(open) = ty.find('[') {
        let inner = ty[open + 1..].strip_suffix(']').ok_or("an array type must end in ']'")?;
        let elem = parse_type(&ty[..open], pkg, wire)?;
        let len = if inner.is_empty() || inner.starts_with("<=") {
            None
        } else {
            Some(inner.parse::<usize>().map_err(|_| format!("array length '{inner}' is not a number"))?)
        };
        return Ok(Ty::Array(Box::new(elem), len));
    }
    let base = ty.split("<=").next().unwrap_or(ty);
    if let Some(p) = prim(base) {
        return Ok(Ty::Prim(p));
    }
    Ok(match base {
        "string" => Ty::Str,
        "wstring" => return Err("wstring is not supported".into()),
        "time" | "duration" if wire == Wire::Ros1 => Ty::Time1,
        "Header" => Ty::Msg("std_msgs/Header".into()),
        "time" => Ty::Msg("builtin_interfaces/Time".into()),
        "duration" => Ty::Msg("builtin_interfaces/Duration".into()),
        other if other.contains('/') => Ty::Msg(short_name(other)),
        other => Ty::Msg(format!("{pkg}/{other}")),
    })
}

const SLOT_SEC: usize = 0;
const SLOT_NSEC: usize = 1;
const SLOT_GYRO: usize = 2;
const SLOT_ACCEL: usize = 5;
const SLOT_TEMP: usize = 8;

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Target {
    None,
    Header,
    Stamp,
    Sec,
    Nsec,
    Gyro,
    Accel,
    Slot(usize),
    Temp,
}

impl Target {
    fn slot(self) -> Option<usize> {
        match self {
            Target::Sec => Some(SLOT_SEC),
            Target::Nsec => Some(SLOT_NSEC),
            Target::Slot(s) => Some(s),
            Target::Temp => Some(SLOT_TEMP),
            _ => None,
        }
    }

    fn axis(self, name: &str) -> Target {
        let base = if self == Target::Gyro { SLOT_GYRO } else { SLOT_ACCEL };
        let k = match name {
            "x" => 0,
            "y" => 1,
            _ => 2,
        };
        Target::Slot(base + k)
    }
}

#[derive(Debug, Clone, PartialEq)]
enum Op {
    Prim(Prim, Option<usize>),
    Str,
    Array { len: Option<usize>, body: Vec<Op> },
}

/// A compiled decoder: skips what is not wanted, reads the IMU's fields into slots.
#[derive(Debug, Clone)]
pub struct Program {
    ops: Vec<Op>,
    wire: Wire,
    /// The definition covers the whole message (it must fill its record); false for a
    /// definition guessed for its first fields only.
    whole: bool,
}

/// The IMU sample of one message (SI, as `sensor_msgs/Imu` defines it).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct ImuFields {
    /// `header.stamp`: seconds and nanoseconds.
    pub stamp: (i64, u32),
    /// `angular_velocity`, rad/s.
    pub gyro_rad_s: [f64; 3],
    /// `linear_acceleration`, m/s².
    pub accel_m_s2: [f64; 3],
    /// A `float64 temperature` field of the wrapping message, °C, when it has one.
    pub temp_c: Option<f64>,
}

/// Why a message could not be decoded: the byte offset in the message and what was read.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct DecodeError {
    /// Offset in the serialised message.
    pub offset: usize,
    /// What went wrong.
    pub msg: String,
}

struct Cursor<'a> {
    buf: &'a [u8],
    pos: usize,
    origin: usize,
    align: bool,
    big: bool,
}

impl Cursor<'_> {
    fn take(&mut self, n: usize, what: &str) -> Result<&[u8], DecodeError> {
        if self.align && n > 1 {
            let a = n.min(8);
            let rel = self.pos - self.origin;
            self.pos += (a - rel % a) % a;
        }
        let end = self.pos.checked_add(n).filter(|&e| e <= self.buf.len()).ok_or_else(|| DecodeError {
            offset: self.pos,
            msg: format!(
                "the message ends before its {what} ({} bytes, {n} needed)",
                self.buf.len().saturating_sub(self.pos)
            ),
        })?;
        let s = &self.buf[self.pos..end];
        self.pos = end;
        Ok(s)
    }

    /// Skips `n` bytes with no alignment (a string's characters).
    fn skip_raw(&mut self, n: usize, what: &str) -> Result<(), DecodeError> {
        let end = self.pos.checked_add(n).filter(|&e| e <= self.buf.len()).ok_or_else(|| DecodeError {
            offset: self.pos,
            msg: format!("the message ends inside a {what} of {n} bytes"),
        })?;
        self.pos = end;
        Ok(())
    }

    fn u32(&mut self, what: &str) -> Result<u32, DecodeError> {
        let b = self.take(4, what)?;
        let a = [b[0], b[1], b[2], b[3]];
        Ok(if self.big { u32::from_be_bytes(a) } else { u32::from_le_bytes(a) })
    }

    fn prim(&mut self, p: Prim) -> Result<f64, DecodeError> {
        let big = self.big;
        let b = self.take(p.size(), "field")?;
        let mut a = [0u8; 8];
        a[..b.len()].copy_from_slice(b);
        if big {
            a[..b.len()].reverse();
        }
        Ok(p.value_le(a))
    }
}

/// The most elements one array may claim (a corrupt length prefix is refused, not looped on).
const MAX_ELEMENTS: usize = 1 << 24;

impl Program {
    /// The same decoder for a definition of the message's first fields only (a wrapper
    /// recognised from its bytes): what follows them is not checked.
    pub fn prefix(mut self) -> Self {
        self.whole = false;
        self
    }

    /// Decodes one serialised message (for CDR, starting with its encapsulation header).
    pub fn decode(&self, msg: &[u8]) -> Result<ImuFields, DecodeError> {
        let (origin, big) = match self.wire {
            Wire::Ros1 => (0, false),
            Wire::Cdr => {
                let head = msg.get(..4).ok_or_else(|| DecodeError {
                    offset: 0,
                    msg: format!("{} bytes: shorter than the 4-byte CDR encapsulation header", msg.len()),
                })?;
                match head[1] {
                    0 | 2 => (4, true),
                    1 | 3 => (4, false),
                    k => {
                        return Err(DecodeError {
                            offset: 1,
                            msg: format!(
                                "CDR encapsulation kind {k}: expected 0 or 1 (plain CDR, big or little endian)"
                            ),
                        })
                    }
                }
            }
        };
        let mut cur = Cursor { buf: msg, pos: origin, origin, align: self.wire == Wire::Cdr, big };
        let mut slots = [f64::NAN; 9];
        run(&self.ops, &mut cur, &mut slots, true)?;
        // The decoded message must fill its record: a corrupt length prefix (a string's, an
        // array's) shifts every later field, so a message that ends elsewhere is refused
        // rather than read shifted. CDR may end in up to 3 bytes of padding (to 4).
        let left = msg.len() - cur.pos.min(msg.len());
        let padding_ok = self.wire == Wire::Cdr && left < 4 && msg[cur.pos..].iter().all(|&b| b == 0);
        if self.whole && left != 0 && !padding_ok {
            return Err(DecodeError {
                offset: cur.pos,
                msg: format!(
                    "the message decodes to {} bytes but its record holds {} (a corrupt length field?): refused, not read shifted",
                    cur.pos,
                    msg.len()
                ),
            });
        }
        Ok(ImuFields {
            stamp: (slots[SLOT_SEC] as i64, slots[SLOT_NSEC] as u32),
            gyro_rad_s: [slots[SLOT_GYRO], slots[SLOT_GYRO + 1], slots[SLOT_GYRO + 2]],
            accel_m_s2: [slots[SLOT_ACCEL], slots[SLOT_ACCEL + 1], slots[SLOT_ACCEL + 2]],
            temp_c: (!slots[SLOT_TEMP].is_nan()).then_some(slots[SLOT_TEMP]),
        })
    }
}

/// Whether the cursor reads CDR (aligned fields, NUL-terminated strings).
fn self_is_cdr(cur: &Cursor<'_>) -> bool {
    cur.align
}

/// Runs `ops`; `store` is false inside arrays (nothing there is wanted).
fn run(ops: &[Op], cur: &mut Cursor<'_>, slots: &mut [f64; 9], store: bool) -> Result<(), DecodeError> {
    for op in ops {
        match op {
            Op::Prim(p, slot) => {
                let v = cur.prim(*p)?;
                if let (Some(s), true) = (slot, store) {
                    slots[*s] = v;
                }
            }
            Op::Str => {
                let at = cur.pos;
                let n = cur.u32("string length")? as usize;
                if n > cur.buf.len() {
                    return Err(DecodeError {
                        offset: at,
                        msg: format!("a string claims {n} bytes, more than the message holds"),
                    });
                }
                cur.skip_raw(n, "string")?;
                // A CDR string counts its terminating NUL: a length that does not end on one
                // is corrupt.
                if self_is_cdr(cur) && n > 0 && cur.buf[cur.pos - 1] != 0 {
                    return Err(DecodeError {
                        offset: at,
                        msg: format!("a CDR string of {n} bytes does not end in its NUL (a corrupt length?)"),
                    });
                }
            }
            Op::Array { len, body } => {
                let at = cur.pos;
                let n = match len {
                    Some(n) => *n,
                    None => cur.u32("array length")? as usize,
                };
                if n > MAX_ELEMENTS || n > cur.buf.len().saturating_mul(8) {
                    return Err(DecodeError {
                        offset: at,
                        msg: format!("an array claims {n} elements, more than the message can hold"),
                    });
                }
                // Fixed-size primitive elements: one bounds check, no loop.
                if let [Op::Prim(p, _)] = body.as_slice() {
                    if n > 0 {
                        cur.take(p.size(), "array")?;
                        let rest = (n - 1) * p.size();
                        let end =
                            cur.pos.checked_add(rest).filter(|&e| e <= cur.buf.len()).ok_or_else(|| DecodeError {
                                offset: cur.pos,
                                msg: format!("the message ends inside an array of {n} elements"),
                            })?;
                        cur.pos = end;
                    }
                    continue;
                }
                for _ in 0..n {
                    run(body, cur, slots, false)?;
                }
            }
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A CDR writer for the tests: aligned little-endian fields after a 4-byte header.
    struct W(Vec<u8>);

    impl W {
        fn new() -> Self {
            W(vec![0, 1, 0, 0])
        }
        fn align(&mut self, a: usize) {
            while (self.0.len() - 4) % a != 0 {
                self.0.push(0);
            }
        }
        fn u32(&mut self, v: u32) {
            self.align(4);
            self.0.extend_from_slice(&v.to_le_bytes());
        }
        fn f64(&mut self, v: f64) {
            self.align(8);
            self.0.extend_from_slice(&v.to_le_bytes());
        }
        fn string(&mut self, s: &str) {
            self.u32(s.len() as u32 + 1);
            self.0.extend_from_slice(s.as_bytes());
            self.0.push(0);
        }
        fn header(&mut self, sec: u32, nsec: u32, frame: &str) {
            self.u32(sec);
            self.u32(nsec);
            self.string(frame);
        }
        fn f64s(&mut self, v: &[f64]) {
            for &x in v {
                self.f64(x);
            }
        }
        fn imu(&mut self, sec: u32, frame: &str, gyro: [f64; 3], accel: [f64; 3]) {
            self.header(sec, 500, frame);
            self.f64s(&[0.0, 0.0, 0.0, 1.0]);
            self.f64s(&[0.0; 9]);
            self.f64s(&gyro);
            self.f64s(&[0.0; 9]);
            self.f64s(&accel);
            self.f64s(&[0.0; 9]);
        }
    }

    #[test]
    fn a_cdr_imu_decodes_whatever_the_frame_ids_length() {
        let d = Definitions::new(Wire::Cdr);
        let p = d.compile("sensor_msgs/msg/Imu").unwrap_or_else(|e| panic!("{e}"));
        for frame in ["", "a", "imu_link", "abcdefg"] {
            let mut w = W::new();
            w.imu(7, frame, [0.1, -0.2, 0.3], [1.0, 2.0, -9.8]);
            let f = p.decode(&w.0).unwrap_or_else(|e| panic!("{e:?}"));
            assert_eq!(f.stamp, (7, 500));
            assert_eq!(f.gyro_rad_s.map(f64::to_bits), [0.1, -0.2, 0.3].map(f64::to_bits));
            assert_eq!(f.accel_m_s2.map(f64::to_bits), [1.0, 2.0, -9.8].map(f64::to_bits));
            let cut = p.decode(&w.0[..w.0.len() - 1]).err().map(|e| e.offset);
            assert!(cut.is_some_and(|o| o > 4), "a cut message must be refused with its offset");
            // Padding to 4 is accepted; a corrupt frame_id length is refused (not shifted)
            // unless the alignment after it absorbs the change (then nothing moved).
            let mut padded = w.0.clone();
            padded.extend_from_slice(&[0, 0, 0]);
            assert!(p.decode(&padded).is_ok());
            for len in [0u32, 1, 9, 17, 200] {
                let mut bad = w.0.clone();
                bad[12..16].copy_from_slice(&len.to_le_bytes());
                if let Ok(g) = p.decode(&bad) {
                    assert_eq!((g.gyro_rad_s, g.accel_m_s2), (f.gyro_rad_s, f.accel_m_s2), "{frame:?} {len}");
                }
            }
        }
    }

    #[test]
    fn a_wrapper_type_is_compiled_from_its_own_lines() {
        let mut d = Definitions::new(Wire::Cdr);
        assert!(d.compile("my/Wrapped").is_err(), "an unknown type must be refused");
        let text = "std_msgs/Header header\nsensor_msgs/Imu imu\nsensor_msgs/MagneticField mag_field\nstring raw\n";
        d.add_text("my/msg/Wrapped", text).unwrap_or_else(|e| panic!("{e}"));
        let p = d.compile("my/msg/Wrapped").unwrap_or_else(|e| panic!("{e}"));
        for outer_frame in ["x", "longer_frame"] {
            let mut w = W::new();
            w.header(1, 0, outer_frame);
            w.imu(7, "imu", [0.5, 0.25, -0.125], [0.0, 0.0, 9.0]);
            w.header(1, 0, "mag");
            w.f64s(&[0.0; 12]);
            w.string("$VNYMR,...");
            let f = p.decode(&w.0).unwrap_or_else(|e| panic!("{e:?}"));
            assert_eq!(f.stamp, (7, 500), "the Imu's own stamp, not the wrapper's");
            assert_eq!(f.gyro_rad_s.map(f64::to_bits), [0.5, 0.25, -0.125].map(f64::to_bits));
            assert_eq!(f.accel_m_s2[2].to_bits(), 9.0f64.to_bits());
        }
    }

    #[test]
    fn ros1_definitions_read_the_seq_and_time_header() {
        let mut d = Definitions::new(Wire::Ros1);
        let def = "Header header\ngeometry_msgs/Quaternion orientation\nfloat64[9] orientation_covariance\n\
                   geometry_msgs/Vector3 angular_velocity\nfloat64[9] angular_velocity_covariance\n\
                   geometry_msgs/Vector3 linear_acceleration\nfloat64[9] linear_acceleration_covariance\n\
                   ================\nMSG: std_msgs/Header\nuint32 seq\ntime stamp\nstring frame_id\n";
        d.add_text("sensor_msgs/Imu", def).unwrap_or_else(|e| panic!("{e}"));
        let p = d.compile("sensor_msgs/Imu").unwrap_or_else(|e| panic!("{e}"));
        let mut m = Vec::new();
        m.extend_from_slice(&3u32.to_le_bytes());
        m.extend_from_slice(&100u32.to_le_bytes());
        m.extend_from_slice(&9u32.to_le_bytes());
        m.extend_from_slice(&3u32.to_le_bytes());
        m.extend_from_slice(b"imu");
        let vals: Vec<f64> = (0..37).map(f64::from).collect();
        for v in &vals {
            m.extend_from_slice(&v.to_le_bytes());
        }
        let f = p.decode(&m).unwrap_or_else(|e| panic!("{e:?}"));
        assert_eq!(f.stamp, (100, 9));
        // A corrupt frame_id length shifts every later field: refused, never read shifted.
        for len in [0u32, 1, 2, 4, 11] {
            let mut bad = m.clone();
            bad[12..16].copy_from_slice(&len.to_le_bytes());
            let e = p.decode(&bad).err().unwrap_or_else(|| panic!("length {len} was read shifted"));
            assert!(e.msg.contains("refused") || e.msg.contains("ends"), "{e:?}");
        }
        assert_eq!(f.gyro_rad_s.map(f64::to_bits), [13.0, 14.0, 15.0].map(f64::to_bits));
        assert_eq!(f.accel_m_s2.map(f64::to_bits), [25.0, 26.0, 27.0].map(f64::to_bits));
    }
}
