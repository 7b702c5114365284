//! Small writers of the benchmark's input files (`benches/formats.rs`): a ROS 1 bag 2.0
//! (indexed, as `rosbag record` lays it out), a PX4 ULog and an ArduPilot DataFlash `.bin`,
//! each holding one static IMU whose samples are drawn from a seeded generator. Written
//! from the formats' specifications (ROS wiki "Bags/Format/2.0", PX4 "ULog File Format",
//! ArduPilot `LogStructure.h`); bench code only, not part of the library.

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};
use std::fs::File;
use std::io::{BufWriter, Seek, SeekFrom, Write};
use std::path::Path;

/// A static IMU: gravity along z, small biases, white noise, a slow temperature drift.
pub struct Imu {
    rng: ChaCha8Rng,
    k: u64,
    /// The accelerometer's z reading at rest: +g with z up (ROS), -g with z down (FRD).
    gz: f64,
}

/// One sample: (time since the start, µs; rad/s; m/s²; °C).
pub type Sample = (u64, [f64; 3], [f64; 3], f64);

impl Imu {
    /// A generator whose samples depend on `seed` only, z up (ROS) or down (PX4, ArduPilot).
    pub fn new(seed: u64, z_up: bool) -> Self {
        Self { rng: ChaCha8Rng::seed_from_u64(seed), k: 0, gz: if z_up { 9.806 } else { -9.806 } }
    }

    /// The next sample at `rate_hz`.
    pub fn next(&mut self, rate_hz: u64) -> Sample {
        let mut n = || -> f64 { StandardNormal.sample(&mut self.rng) };
        let g = [1e-3 + 2e-3 * n(), -2e-3 + 2e-3 * n(), 5e-4 + 2e-3 * n()];
        let mut a = [0.05 + 0.01 * n(), -0.03 + 0.01 * n(), 0.01 * n()];
        a[2] += self.gz;
        let t_us = self.k * 1_000_000 / rate_hz;
        self.k += 1;
        (t_us, g, a, 40.0 + 1e-6 * t_us as f64 / 3600.0)
    }
}

fn out(path: &Path) -> BufWriter<File> {
    BufWriter::with_capacity(1 << 20, File::create(path).expect("create the bench file"))
}

// ---------------------------------------------------------------------------------------
// ROS 1 bag 2.0

/// How the bag's chunks are stored.
#[derive(Clone, Copy, PartialEq, Eq)]
pub enum Chunks {
    /// As is (`compression=none`).
    Plain,
    /// bzip2 (`compression=bz2`).
    Bz2,
}

/// rosbag's default chunk threshold: a chunk is closed once it holds 768 KiB.
const CHUNK_BYTES: usize = 768 * 1024;
const TOPIC: &str = "/imu/data";
const IMU_TYPE: &str = "sensor_msgs/Imu";
/// The MD5 of sensor_msgs/Imu's definition (as rosbag records it; rosbags computes the same).
const IMU_MD5: &str = "6a62c6daae103f4ff57a132d6f95cec2";
const RULE: &str = "================================================================================";

/// sensor_msgs/Imu's full definition in rosbag's layout: the type, then each type it uses
/// after a line of 80 '=' and `MSG: package/Type`.
fn imu_definition() -> String {
    let header = "# Metadata of stamped data\nuint32 seq\n# stamp.sec, stamp.nsec\ntime stamp\nstring frame_id\n";
    let quaternion = "# An orientation\nfloat64 x\nfloat64 y\nfloat64 z\nfloat64 w\n";
    let vector = "# A direction in space\nfloat64 x\nfloat64 y\nfloat64 z\n";
    format!(
        "# An IMU sample: rates in rad/s, accelerations in m/s^2\n\nHeader header\n\n\
         geometry_msgs/Quaternion orientation\nfloat64[9] orientation_covariance # row major\n\n\
         geometry_msgs/Vector3 angular_velocity\nfloat64[9] angular_velocity_covariance # row major\n\n\
         geometry_msgs/Vector3 linear_acceleration\nfloat64[9] linear_acceleration_covariance # row major\n\n\
         {RULE}\nMSG: std_msgs/Header\n{header}\n{RULE}\nMSG: geometry_msgs/Quaternion\n{quaternion}\n\
         {RULE}\nMSG: geometry_msgs/Vector3\n{vector}"
    )
}

/// Appends one `name=value` header field.
fn field(buf: &mut Vec<u8>, name: &str, value: &[u8]) {
    buf.extend_from_slice(&((name.len() + 1 + value.len()) as u32).to_le_bytes());
    buf.extend_from_slice(name.as_bytes());
    buf.push(b'=');
    buf.extend_from_slice(value);
}

/// Appends one record: header length, header, data length, data.
fn record(buf: &mut Vec<u8>, header: &[u8], data: &[u8]) {
    buf.extend_from_slice(&(header.len() as u32).to_le_bytes());
    buf.extend_from_slice(header);
    buf.extend_from_slice(&(data.len() as u32).to_le_bytes());
    buf.extend_from_slice(data);
}

/// A ROS time (u32 seconds, u32 nanoseconds) from ns.
fn ros_time(t_ns: u64) -> [u8; 8] {
    let mut b = [0u8; 8];
    b[..4].copy_from_slice(&((t_ns / 1_000_000_000) as u32).to_le_bytes());
    b[4..].copy_from_slice(&((t_ns % 1_000_000_000) as u32).to_le_bytes());
    b
}

/// The bag header record (op 0x03), padded to 4096 bytes as rosbag pads it.
fn bag_header(index_pos: u64, conns: u32, chunks: u32) -> Vec<u8> {
    let mut h = Vec::new();
    field(&mut h, "op", &[0x03]);
    field(&mut h, "index_pos", &index_pos.to_le_bytes());
    field(&mut h, "conn_count", &conns.to_le_bytes());
    field(&mut h, "chunk_count", &chunks.to_le_bytes());
    let mut rec = Vec::new();
    record(&mut rec, &h, &vec![b' '; 4096 - 8 - h.len()]);
    rec
}

/// The connection record of the IMU topic (op 0x07): in the first chunk and in the index.
fn connection() -> Vec<u8> {
    let mut h = Vec::new();
    field(&mut h, "op", &[0x07]);
    field(&mut h, "conn", &0u32.to_le_bytes());
    field(&mut h, "topic", TOPIC.as_bytes());
    let mut d = Vec::new();
    field(&mut d, "topic", TOPIC.as_bytes());
    field(&mut d, "type", IMU_TYPE.as_bytes());
    field(&mut d, "md5sum", IMU_MD5.as_bytes());
    field(&mut d, "message_definition", imu_definition().as_bytes());
    field(&mut d, "callerid", b"/imu_node");
    field(&mut d, "latching", b"0");
    let mut rec = Vec::new();
    record(&mut rec, &h, &d);
    rec
}

/// One sensor_msgs/Imu in ROS 1 serialisation (little endian, packed).
fn imu_message(buf: &mut Vec<u8>, seq: u32, t_ns: u64, g: [f64; 3], a: [f64; 3]) {
    buf.extend_from_slice(&seq.to_le_bytes());
    buf.extend_from_slice(&ros_time(t_ns));
    buf.extend_from_slice(&8u32.to_le_bytes());
    buf.extend_from_slice(b"imu_link");
    let mut f64s = |v: &[f64]| v.iter().for_each(|x| buf.extend_from_slice(&x.to_le_bytes()));
    // Orientation unknown: identity, covariance[0] = -1 (sensor_msgs/Imu's convention).
    f64s(&[0.0, 0.0, 0.0, 1.0]);
    f64s(&[-1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0]);
    f64s(&g);
    f64s(&[4e-6, 0.0, 0.0, 0.0, 4e-6, 0.0, 0.0, 0.0, 4e-6]);
    f64s(&a);
    f64s(&[1e-4, 0.0, 0.0, 0.0, 1e-4, 0.0, 0.0, 0.0, 1e-4]);
}

/// A closed chunk, for the index: position, first and last time, messages.
struct ChunkInfo {
    pos: u64,
    start_ns: u64,
    end_ns: u64,
    count: u32,
}

/// Writes an indexed ROS 1 bag of about `bytes` bytes: one connection `/imu/data`
/// (sensor_msgs/Imu at 200 Hz), chunks of 768 KiB uncompressed, each followed by its index
/// data record, then the connection and chunk info records, and the bag header pointing at
/// them. Returns the messages written.
pub fn write_bag(path: &Path, bytes: u64, chunks: Chunks, seed: u64) -> u64 {
    const RATE: u64 = 200;
    const T0_NS: u64 = 1_700_000_000_000_000_000;
    let mut w = out(path);
    w.write_all(b"#ROSBAG V2.0\n").expect("write");
    w.write_all(&bag_header(0, 0, 0)).expect("write");
    let mut pos = 13 + 4096u64;
    let mut imu = Imu::new(seed, true);
    let (mut chunk, mut index, mut msg, mut head) = (Vec::new(), Vec::new(), Vec::new(), Vec::new());
    let mut infos: Vec<ChunkInfo> = Vec::new();
    let mut n = 0u64;
    let mut seq = 0u32;
    while pos < bytes {
        chunk.clear();
        index.clear();
        if infos.is_empty() {
            chunk.extend_from_slice(&connection());
        }
        let mut info = ChunkInfo { pos, start_ns: u64::MAX, end_ns: 0, count: 0 };
        while chunk.len() < CHUNK_BYTES {
            let (t_us, g, a, _) = imu.next(RATE);
            let t_ns = T0_NS + t_us * 1000;
            msg.clear();
            imu_message(&mut msg, seq, t_ns, g, a);
            head.clear();
            field(&mut head, "op", &[0x02]);
            field(&mut head, "conn", &0u32.to_le_bytes());
            field(&mut head, "time", &ros_time(t_ns));
            index.extend_from_slice(&ros_time(t_ns));
            index.extend_from_slice(&(chunk.len() as u32).to_le_bytes());
            record(&mut chunk, &head, &msg);
            info.start_ns = info.start_ns.min(t_ns);
            info.end_ns = t_ns;
            info.count += 1;
            seq = seq.wrapping_add(1);
        }
        let stored = match chunks {
            Chunks::Plain => std::borrow::Cow::Borrowed(&chunk),
            Chunks::Bz2 => {
                let mut z = bzip2::write::BzEncoder::new(Vec::new(), bzip2::Compression::best());
                z.write_all(&chunk).expect("bz2");
                std::borrow::Cow::Owned(z.finish().expect("bz2"))
            }
        };
        let mut rec = Vec::new();
        head.clear();
        field(&mut head, "op", &[0x05]);
        field(&mut head, "compression", if chunks == Chunks::Plain { b"none" } else { b"bz2" });
        field(&mut head, "size", &(chunk.len() as u32).to_le_bytes());
        record(&mut rec, &head, &stored);
        head.clear();
        field(&mut head, "op", &[0x04]);
        field(&mut head, "ver", &1u32.to_le_bytes());
        field(&mut head, "conn", &0u32.to_le_bytes());
        field(&mut head, "count", &info.count.to_le_bytes());
        record(&mut rec, &head, &index);
        w.write_all(&rec).expect("write");
        pos += rec.len() as u64;
        n += u64::from(info.count);
        infos.push(info);
    }
    let index_pos = pos;
    let mut rec = connection();
    for c in &infos {
        head.clear();
        field(&mut head, "op", &[0x06]);
        field(&mut head, "ver", &1u32.to_le_bytes());
        field(&mut head, "chunk_pos", &c.pos.to_le_bytes());
        field(&mut head, "start_time", &ros_time(c.start_ns));
        field(&mut head, "end_time", &ros_time(c.end_ns));
        field(&mut head, "count", &1u32.to_le_bytes());
        let data: Vec<u8> = [0u32.to_le_bytes(), c.count.to_le_bytes()].concat();
        record(&mut rec, &head, &data);
    }
    w.write_all(&rec).expect("write");
    let mut file = w.into_inner().expect("flush");
    file.seek(SeekFrom::Start(13)).expect("seek");
    file.write_all(&bag_header(index_pos, 1, infos.len() as u32)).expect("write");
    n
}

// ---------------------------------------------------------------------------------------
// PX4 ULog

/// `sensor_combined` as PX4 v1.14 logs it (48 bytes).
const SENSOR_COMBINED: &str = "sensor_combined:uint64_t timestamp;float[3] gyro_rad;uint32_t gyro_integral_dt;\
int32_t accelerometer_timestamp_relative;float[3] accelerometer_m_s2;uint32_t accelerometer_integral_dt;\
uint8_t accelerometer_clipping;uint8_t gyro_clipping;uint8_t accel_calibration_count;uint8_t gyro_calibration_count;";

/// One ULog message: u16 payload size, u8 type, payload.
fn ulog_msg(w: &mut impl Write, ty: u8, payload: &[u8]) -> u64 {
    w.write_all(&(payload.len() as u16).to_le_bytes()).expect("write");
    w.write_all(&[ty]).expect("write");
    w.write_all(payload).expect("write");
    3 + payload.len() as u64
}

/// A key-value payload ('I', 'P'): u8 key length, `type name`, value.
fn key_value(key: &str, value: &[u8]) -> Vec<u8> {
    [&[key.len() as u8][..], key.as_bytes(), value].concat()
}

/// Writes a ULog (version 1) of about `bytes` bytes: header, flag bits, two info messages,
/// the `sensor_combined` format, one parameter, the subscription and 250 Hz data. Returns
/// the samples written.
pub fn write_ulog(path: &Path, bytes: u64, seed: u64) -> u64 {
    const RATE: u64 = 250;
    const T0_US: u64 = 20_000_000;
    let mut w = out(path);
    let mut head = b"ULog\x01\x12\x35\x01".to_vec();
    head.extend_from_slice(&T0_US.to_le_bytes());
    w.write_all(&head).expect("write");
    let mut pos = 16u64;
    pos += ulog_msg(&mut w, b'B', &[0u8; 40]);
    pos += ulog_msg(&mut w, b'I', &key_value("char[3] sys_name", b"PX4"));
    pos += ulog_msg(&mut w, b'I', &key_value("char[5] ver_hw", b"BENCH"));
    pos += ulog_msg(&mut w, b'F', SENSOR_COMBINED.as_bytes());
    pos += ulog_msg(&mut w, b'P', &key_value("int32_t SENS_BOARD_ROT", &0i32.to_le_bytes()));
    pos += ulog_msg(&mut w, b'A', &[&[0u8][..], &0u16.to_le_bytes(), b"sensor_combined"].concat());
    let mut imu = Imu::new(seed, false);
    let mut n = 0u64;
    let mut d = Vec::with_capacity(64);
    while pos < bytes {
        let (t_us, g, a, _) = imu.next(RATE);
        d.clear();
        d.extend_from_slice(&0u16.to_le_bytes());
        d.extend_from_slice(&(T0_US + t_us).to_le_bytes());
        g.iter().for_each(|x| d.extend_from_slice(&(*x as f32).to_le_bytes()));
        d.extend_from_slice(&4000u32.to_le_bytes());
        d.extend_from_slice(&0i32.to_le_bytes());
        a.iter().for_each(|x| d.extend_from_slice(&(*x as f32).to_le_bytes()));
        d.extend_from_slice(&4000u32.to_le_bytes());
        d.extend_from_slice(&[0, 0, 1, 1]);
        pos += ulog_msg(&mut w, b'D', &d);
        n += 1;
    }
    w.flush().expect("flush");
    n
}

// ---------------------------------------------------------------------------------------
// ArduPilot DataFlash

const FMT: u8 = 128;
const PARM: u8 = 64;
const IMU: u8 = 131;

/// An FMT record (89 bytes) describing message `ty`.
fn fmt(ty: u8, len: u8, name: &str, format: &str, columns: &str) -> Vec<u8> {
    let mut r = vec![0xA3, 0x95, FMT, ty, len];
    for (s, n) in [(name, 4), (format, 16), (columns, 64)] {
        let mut b = s.as_bytes().to_vec();
        assert!(b.len() <= n, "{s} does not fit {n} bytes");
        b.resize(n, 0);
        r.extend_from_slice(&b);
    }
    r
}

/// Writes a DataFlash `.bin` of about `bytes` bytes: FMT of FMT, PARM and IMU (`TimeUS`,
/// `GyrX..Z`, `AccX..Z`, `T`), one PARM record, then 400 Hz IMU records. Returns the IMU
/// records written.
pub fn write_dataflash(path: &Path, bytes: u64, seed: u64) -> u64 {
    const RATE: u64 = 400;
    const T0_US: u64 = 5_000_000;
    let mut w = out(path);
    let mut pos = 0u64;
    let imu_len = 3 + 8 + 7 * 4;
    for r in [
        fmt(FMT, 89, "FMT", "BBnNZ", "Type,Length,Name,Format,Columns"),
        fmt(PARM, 3 + 8 + 16 + 4, "PARM", "QNf", "TimeUS,Name,Value"),
        fmt(IMU, imu_len as u8, "IMU", "Qfffffff", "TimeUS,GyrX,GyrY,GyrZ,AccX,AccY,AccZ,T"),
    ] {
        w.write_all(&r).expect("write");
        pos += r.len() as u64;
    }
    let mut parm = vec![0xA3, 0x95, PARM];
    parm.extend_from_slice(&T0_US.to_le_bytes());
    let mut name = b"AHRS_ORIENTATION".to_vec();
    name.resize(16, 0);
    parm.extend_from_slice(&name);
    parm.extend_from_slice(&0f32.to_le_bytes());
    w.write_all(&parm).expect("write");
    pos += parm.len() as u64;
    let mut imu = Imu::new(seed, false);
    let mut n = 0u64;
    let mut r = Vec::with_capacity(imu_len);
    while pos < bytes {
        let (t_us, g, a, temp) = imu.next(RATE);
        r.clear();
        r.extend_from_slice(&[0xA3, 0x95, IMU]);
        r.extend_from_slice(&(T0_US + t_us).to_le_bytes());
        g.iter().chain(&a).chain(&[temp]).for_each(|x| r.extend_from_slice(&(*x as f32).to_le_bytes()));
        w.write_all(&r).expect("write");
        pos += r.len() as u64;
        n += 1;
    }
    w.flush().expect("flush");
    n
}
