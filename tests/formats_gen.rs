//! Generated logs with known samples, for what the shared samples lack: a ROS 1 bag with
//! lz4 and uncompressed chunks, a ROS 2 sqlite3 bag holding the plain
//! `sensor_msgs/msg/Imu`, an MCAP file (zstd chunks, `ros2msg` schema), a ULog whose data
//! continue in an appended segment, a DataFlash log with garbage between records and FMTU
//! multipliers. Every sample read back must equal the one written, bit for bit.

use crosscal::session::logs::{list, read, ReadOptions};
use std::path::Path;

/// The sample written at index `i` (deterministic, all different): time ns, gyro, accel.
pub(crate) fn truth(i: usize) -> (i64, [f64; 3], [f64; 3]) {
    let t = 1_700_000_000_000_000_000 + i as i64 * 5_000_000;
    let x = i as f64;
    (t, [0.01 * (x * 0.1).sin(), -0.02 + 1e-5 * x, 0.003 * (x * 0.07).cos()], [0.1 + 1e-4 * x, -0.2, 9.81 - 1e-5 * x])
}

const N: usize = 2500;

fn check_all(path: &Path, opts: &ReadOptions, n: usize) {
    let mut got = Vec::new();
    let c = read(path, opts, None, &mut |_, s| {
        got.push(*s);
        Ok(())
    })
    .unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    assert_eq!(c.streams.len(), 1, "{:?}", c.streams);
    assert_eq!(got.len(), n, "{}", path.display());
    for (i, s) in got.iter().enumerate() {
        let (t, g, a) = truth(i);
        assert_eq!(s.t_ns, t, "sample {i} time");
        assert_eq!(s.gyro_rad_s.map(f64::to_bits), g.map(f64::to_bits), "sample {i} gyro");
        assert_eq!(s.accel_m_s2.map(f64::to_bits), a.map(f64::to_bits), "sample {i} accel");
    }
}

/// The part of a `sensor_msgs/Imu` after its header, little-endian f64s (packed in ROS 1; in
/// CDR the caller has aligned to 8 already): orientation (identity), covariances 0.
pub(crate) fn imu_body(out: &mut Vec<u8>, gyro: [f64; 3], accel: [f64; 3]) {
    let mut f = vec![0.0, 0.0, 0.0, 1.0];
    f.extend([0.0; 9]);
    f.extend(gyro);
    f.extend([0.0; 9]);
    f.extend(accel);
    f.extend([0.0; 9]);
    for v in f {
        out.extend_from_slice(&v.to_le_bytes());
    }
}

pub(crate) fn le32(b: &mut Vec<u8>, v: u32) {
    b.extend_from_slice(&v.to_le_bytes());
}

// ---------------------------------------------------------------- ROS 1

pub(crate) const IMU_DEF_ROS1: &str = "Header header\ngeometry_msgs/Quaternion orientation\nfloat64[9] orientation_covariance\n\
geometry_msgs/Vector3 angular_velocity\nfloat64[9] angular_velocity_covariance\n\
geometry_msgs/Vector3 linear_acceleration\nfloat64[9] linear_acceleration_covariance\n\
================================================================================\nMSG: std_msgs/Header\nuint32 seq\ntime stamp\nstring frame_id\n\
================================================================================\nMSG: geometry_msgs/Quaternion\nfloat64 x\nfloat64 y\nfloat64 z\nfloat64 w\n\
================================================================================\nMSG: geometry_msgs/Vector3\nfloat64 x\nfloat64 y\nfloat64 z\n";

pub(crate) fn fields(pairs: &[(&str, &[u8])]) -> Vec<u8> {
    let mut b = Vec::new();
    for (k, v) in pairs {
        le32(&mut b, (k.len() + 1 + v.len()) as u32);
        b.extend_from_slice(k.as_bytes());
        b.push(b'=');
        b.extend_from_slice(v);
    }
    b
}

pub(crate) fn record(out: &mut Vec<u8>, header: &[u8], data: &[u8]) {
    le32(out, header.len() as u32);
    out.extend_from_slice(header);
    le32(out, data.len() as u32);
    out.extend_from_slice(data);
}

pub(crate) fn ros1_imu(i: usize) -> Vec<u8> {
    let (t, g, a) = truth(i);
    let mut m = Vec::new();
    le32(&mut m, i as u32);
    le32(&mut m, (t / 1_000_000_000) as u32);
    le32(&mut m, (t % 1_000_000_000) as u32);
    le32(&mut m, 3);
    m.extend_from_slice(b"imu");
    imu_body(&mut m, g, a);
    m
}

fn ros1_bag(compressions: &[&str]) -> Vec<u8> {
    ros1_bag_n(compressions, N)
}

/// A ROS 1 bag of `n` samples (`truth`) on `/imu`, one chunk per compression.
pub(crate) fn ros1_bag_n(compressions: &[&str], n: usize) -> Vec<u8> {
    let mut out = b"#ROSBAG V2.0\n".to_vec();
    record(
        &mut out,
        &fields(&[
            ("op", &[3]),
            ("index_pos", &[0; 8]),
            ("conn_count", &1u32.to_le_bytes()),
            ("chunk_count", &1u32.to_le_bytes()),
        ]),
        &[],
    );
    let per = n.div_ceil(compressions.len());
    for (c, comp) in compressions.iter().enumerate() {
        let mut inner = Vec::new();
        let conn = fields(&[("op", &[7]), ("conn", &0u32.to_le_bytes()), ("topic", b"/imu")]);
        let info = fields(&[
            ("topic", b"/imu"),
            ("type", b"sensor_msgs/Imu"),
            ("md5sum", b"6a62c6daae103f4ff57a132d6f95cec2"),
            ("message_definition", IMU_DEF_ROS1.as_bytes()),
        ]);
        record(&mut inner, &conn, &info);
        for i in c * per..((c + 1) * per).min(n) {
            let mut time = Vec::new();
            le32(&mut time, 1);
            le32(&mut time, 2);
            record(&mut inner, &fields(&[("op", &[2]), ("conn", &0u32.to_le_bytes()), ("time", &time)]), &ros1_imu(i));
        }
        let packed = match *comp {
            "lz4" => {
                let mut enc = lz4_flex::frame::FrameEncoder::new(Vec::new());
                std::io::Write::write_all(&mut enc, &inner).unwrap_or_else(|e| panic!("{e}"));
                enc.finish().unwrap_or_else(|e| panic!("{e}"))
            }
            "bz2" => {
                let mut enc = bzip2::write::BzEncoder::new(Vec::new(), bzip2::Compression::default());
                std::io::Write::write_all(&mut enc, &inner).unwrap_or_else(|e| panic!("{e}"));
                enc.finish().unwrap_or_else(|e| panic!("{e}"))
            }
            _ => inner.clone(),
        };
        let h =
            fields(&[("op", &[5]), ("compression", comp.as_bytes()), ("size", &(inner.len() as u32).to_le_bytes())]);
        record(&mut out, &h, &packed);
    }
    out
}

#[test]
fn a_ros1_bag_with_lz4_and_plain_chunks_reads_back_bit_for_bit() {
    let dir = tempfile::tempdir().unwrap_or_else(|e| panic!("{e}"));
    let p = dir.path().join("gen.bag");
    std::fs::write(&p, ros1_bag(&["lz4", "none", "lz4"])).unwrap_or_else(|e| panic!("{e}"));
    check_all(&p, &ReadOptions::default(), N);
    // A chunk whose lz4 frame is damaged (its magic number) is refused with its byte offset.
    // (A flipped bit inside an lz4 block without a content checksum cannot be seen by any
    // reader; bz2 chunks carry a CRC.)
    let mut b = ros1_bag(&["lz4"]);
    let at = b.windows(4).position(|w| w == [0x04, 0x22, 0x4d, 0x18]).unwrap_or_else(|| panic!("no lz4 frame"));
    b[at] ^= 0xff;
    std::fs::write(&p, &b).unwrap_or_else(|e| panic!("{e}"));
    let e = list(&p, &ReadOptions::default()).err().map(|e| e.to_string()).unwrap_or_default();
    assert!(e.contains("byte") && e.contains("lz4"), "{e}");
}

// ---------------------------------------------------------------- CDR (ROS 2)

pub(crate) fn cdr_imu(i: usize) -> Vec<u8> {
    let (t, g, a) = truth(i);
    let mut b = vec![0, 1, 0, 0];
    le32(&mut b, (t / 1_000_000_000) as u32);
    le32(&mut b, (t % 1_000_000_000) as u32);
    le32(&mut b, 9);
    b.extend_from_slice(b"imu_link\0");
    while (b.len() - 4) % 8 != 0 {
        b.push(0);
    }
    imu_body(&mut b, g, a);
    b
}

#[test]
fn a_ros2_sqlite_bag_of_plain_imu_messages_reads_back_bit_for_bit() {
    let dir = tempfile::tempdir().unwrap_or_else(|e| panic!("{e}"));
    let bag = dir.path().join("bag");
    std::fs::create_dir(&bag).unwrap_or_else(|e| panic!("{e}"));
    let db = rusqlite::Connection::open(bag.join("bag_0.db3")).unwrap_or_else(|e| panic!("{e}"));
    db.execute_batch(
        "CREATE TABLE topics(id INTEGER PRIMARY KEY, name TEXT, type TEXT, serialization_format TEXT, offered_qos_profiles TEXT);
         CREATE TABLE messages(id INTEGER PRIMARY KEY, topic_id INTEGER, timestamp INTEGER, data BLOB);
         INSERT INTO topics VALUES (1, '/imu/data', 'sensor_msgs/msg/Imu', 'cdr', '');
         INSERT INTO topics VALUES (2, '/chatter', 'std_msgs/msg/String', 'cdr', '');",
    )
    .unwrap_or_else(|e| panic!("{e}"));
    for i in 0..N {
        let (t, _, _) = truth(i);
        db.execute(
            "INSERT INTO messages(topic_id, timestamp, data) VALUES (1, ?1, ?2)",
            rusqlite::params![t + 1000, cdr_imu(i)],
        )
        .unwrap_or_else(|e| panic!("{e}"));
        db.execute(
            "INSERT INTO messages(topic_id, timestamp, data) VALUES (2, ?1, ?2)",
            rusqlite::params![t + 2000, vec![0u8, 1, 0, 0, 1, 0, 0, 0, 0]],
        )
        .unwrap_or_else(|e| panic!("{e}"));
    }
    drop(db);
    std::fs::write(bag.join("metadata.yaml"), "rosbag2_bagfile_information:\n  version: 5\n  storage_identifier: sqlite3\n  relative_file_paths:\n    - bag_0.db3\n  compression_format: \"\"\n")
        .unwrap_or_else(|e| panic!("{e}"));
    check_all(&bag, &ReadOptions::default(), N);
}

/// Writes `n` IMU messages (`truth`, as `cdr_imu`) on `/imu` as an MCAP file with the given
/// chunk compression and size, with the schema as rosbag2 writes it: the type's own fields,
/// then MSG: sections.
pub(crate) fn mcap_imu<W: std::io::Write + std::io::Seek>(
    out: W,
    n: usize,
    compression: mcap::Compression,
    chunk: u64,
) {
    let mut w = mcap::WriteOptions::new()
        .compression(Some(compression))
        .chunk_size(Some(chunk))
        .create(out)
        .unwrap_or_else(|e| panic!("{e}"));
    let def = "std_msgs/Header header\ngeometry_msgs/Quaternion orientation\nfloat64[9] orientation_covariance\n\
geometry_msgs/Vector3 angular_velocity\nfloat64[9] angular_velocity_covariance\ngeometry_msgs/Vector3 linear_acceleration\n\
float64[9] linear_acceleration_covariance\n================================================================================\n\
MSG: std_msgs/Header\nbuiltin_interfaces/Time stamp\nstring frame_id\n================================================================================\n\
MSG: builtin_interfaces/Time\nint32 sec\nuint32 nanosec\n";
    let schema = w.add_schema("sensor_msgs/msg/Imu", "ros2msg", def.as_bytes()).unwrap_or_else(|e| panic!("{e}"));
    let ch = w.add_channel(schema, "/imu", "cdr", &Default::default()).unwrap_or_else(|e| panic!("{e}"));
    for i in 0..n {
        let (t, _, _) = truth(i);
        let h = mcap::records::MessageHeader {
            channel_id: ch,
            sequence: i as u32,
            log_time: t as u64,
            publish_time: t as u64,
        };
        w.write_to_known_channel(&h, &cdr_imu(i)).unwrap_or_else(|e| panic!("{e}"));
    }
    w.finish().unwrap_or_else(|e| panic!("{e}"));
}

#[test]
fn an_mcap_file_with_zstd_chunks_reads_back_bit_for_bit() {
    let dir = tempfile::tempdir().unwrap_or_else(|e| panic!("{e}"));
    let p = dir.path().join("gen.mcap");
    let f = std::io::BufWriter::new(std::fs::File::create(&p).unwrap_or_else(|e| panic!("{e}")));
    mcap_imu(f, N, mcap::Compression::Zstd, 64 * 1024);
    let (c, stats) = list(&p, &ReadOptions::default()).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(c.format, crosscal::session::logs::LogFormat::Mcap);
    assert!((stats[0].rate_hz() - 200.0).abs() < 1e-6, "{}", stats[0].rate_hz());
    check_all(&p, &ReadOptions::default(), N);
}

// ---------------------------------------------------------------- PX4 ULog

pub(crate) fn ulog_msg(out: &mut Vec<u8>, ty: u8, payload: &[u8]) {
    out.extend_from_slice(&(payload.len() as u16).to_le_bytes());
    out.push(ty);
    out.extend_from_slice(payload);
}

/// `sensor_combined` as PX4 ≥ 1.11 logs it (trailing padding not logged), sample `i`.
pub(crate) fn ulog_data(i: usize) -> Vec<u8> {
    let (t, g, a) = truth(i);
    let mut d = 0u16.to_le_bytes().to_vec();
    d.extend_from_slice(&((t / 1000) as u64).to_le_bytes());
    for v in g {
        d.extend_from_slice(&(v as f32).to_le_bytes());
    }
    d.extend_from_slice(&4000u32.to_le_bytes());
    d.extend_from_slice(&0i32.to_le_bytes());
    for v in a {
        d.extend_from_slice(&(v as f32).to_le_bytes());
    }
    d.extend_from_slice(&4000u32.to_le_bytes());
    d.push(0);
    d
}

#[test]
fn a_ulog_with_appended_data_and_a_cut_message_reads_every_whole_sample() {
    let mut b = b"ULog\x01\x12\x35\x01".to_vec();
    b.extend_from_slice(&0u64.to_le_bytes());
    // Flag bits: data appended at an offset filled in below.
    let flags_at = b.len();
    let mut flags = vec![0u8; 40];
    flags[8] = 1;
    ulog_msg(&mut b, b'B', &flags);
    let fmt = "sensor_combined:uint64_t timestamp;float[3] gyro_rad;uint32_t gyro_integral_dt;int32_t accelerometer_timestamp_relative;float[3] accelerometer_m_s2;uint32_t accelerometer_integral_dt;uint8_t accelerometer_clipping;uint8_t[3] _padding0;";
    ulog_msg(&mut b, b'F', fmt.as_bytes());
    let mut p = b"\x05float CAL_ACC0_XOFF".to_vec();
    p[0] = (p.len() - 1) as u8;
    p.extend_from_slice(&0.25f32.to_le_bytes());
    ulog_msg(&mut b, b'P', &p);
    let mut sub = vec![0u8];
    sub.extend_from_slice(&0u16.to_le_bytes());
    sub.extend_from_slice(b"sensor_combined");
    ulog_msg(&mut b, b'A', &sub);
    let half = N / 2;
    for i in 0..half {
        ulog_msg(&mut b, b'D', &ulog_data(i));
    }
    ulog_msg(&mut b, b'O', &40u16.to_le_bytes());
    // A crash: the last message is cut; the rest was appended after it.
    let cut = ulog_data(half);
    b.extend_from_slice(&(cut.len() as u16).to_le_bytes());
    b.push(b'D');
    b.extend_from_slice(&cut[..7]);
    let appended = b.len() as u64;
    b[flags_at + 3 + 16..flags_at + 3 + 24].copy_from_slice(&appended.to_le_bytes());
    for i in half..N {
        ulog_msg(&mut b, b'D', &ulog_data(i));
    }
    let dir = tempfile::tempdir().unwrap_or_else(|e| panic!("{e}"));
    let path = dir.path().join("gen.ulg");
    std::fs::write(&path, &b).unwrap_or_else(|e| panic!("{e}"));
    let mut got = Vec::new();
    let c = read(&path, &ReadOptions::default(), None, &mut |_, s| {
        got.push(*s);
        Ok(())
    })
    .unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(got.len(), N, "every whole sample, from both segments");
    for (i, s) in got.iter().enumerate() {
        let (t, g, a) = truth(i);
        assert_eq!(s.t_ns, t / 1000 * 1000, "sample {i}");
        assert_eq!(s.gyro_rad_s.map(f64::to_bits), g.map(|v| f64::from(v as f32).to_bits()), "sample {i}");
        assert_eq!(s.accel_m_s2.map(f64::to_bits), a.map(|v| f64::from(v as f32).to_bits()), "sample {i}");
    }
    assert!(c.warnings.iter().any(|w| w.contains("dropout")), "{:?}", c.warnings);
    assert_eq!(c.applied, vec![("CAL_ACC0_XOFF".to_string(), 0.25)]);
}

// ---------------------------------------------------------------- DataFlash

pub(crate) fn df_fmt(out: &mut Vec<u8>, ty: u8, len: u8, name: &str, format: &str, cols: &str) {
    out.extend_from_slice(&[0xA3, 0x95, 128, ty, len]);
    let pad = |s: &str, n: usize| {
        let mut v = s.as_bytes().to_vec();
        v.resize(n, 0);
        v
    };
    out.extend(pad(name, 4));
    out.extend(pad(format, 16));
    out.extend(pad(cols, 64));
}

#[test]
fn a_dataflash_log_with_garbage_and_a_cut_record_reads_every_whole_sample() {
    let mut b = Vec::new();
    df_fmt(&mut b, 128, 89, "FMT", "BBnNZ", "Type,Length,Name,Format,Columns");
    // IMU with an instance column: 3 + 8 + 1 + 7 × 4 bytes.
    df_fmt(&mut b, 200, 40, "IMU", "QBfffffff", "TimeUS,I,GyrX,GyrY,GyrZ,AccX,AccY,AccZ,T");
    let rec = |i: usize, inst: u8| {
        let (t, g, a) = truth(i);
        let mut r = vec![0xA3, 0x95, 200];
        r.extend_from_slice(&((t / 1000) as u64).to_le_bytes());
        r.push(inst);
        for v in g.iter().chain(&a) {
            r.extend_from_slice(&(*v as f32).to_le_bytes());
        }
        r.extend_from_slice(&(30.0f32 + inst as f32).to_le_bytes());
        r
    };
    for i in 0..N {
        b.extend(rec(i, 0));
        b.extend(rec(i, 1));
        if i == 100 {
            b.extend_from_slice(&[0x00, 0xA3, 0x17, 0xA3]);
        }
    }
    let last = rec(N, 0);
    b.extend_from_slice(&last[..20]);
    let dir = tempfile::tempdir().unwrap_or_else(|e| panic!("{e}"));
    let path = dir.path().join("gen.bin");
    std::fs::write(&path, &b).unwrap_or_else(|e| panic!("{e}"));
    let (c, stats) = list(&path, &ReadOptions::default()).unwrap_or_else(|e| panic!("{e}"));
    let names: Vec<&str> = c.streams.iter().map(|s| s.name.as_str()).collect();
    assert_eq!(names, ["IMU[0]", "IMU[1]"]);
    assert_eq!((stats[0].samples, stats[1].samples), (N as u64, N as u64));
    assert_eq!(stats[1].temp_c, Some([31.0, 31.0]));
    assert!(c.warnings.iter().any(|w| w.contains("4 bytes") && w.contains("skipped")), "{:?}", c.warnings);
    assert!(
        c.warnings.iter().any(|w| w.contains("cut") && w.contains(&format!("byte {}", b.len() - 20))),
        "{:?}",
        c.warnings
    );
    let mut got = Vec::new();
    read(&path, &ReadOptions::default(), Some(1), &mut |_, s| {
        got.push(*s);
        Ok(())
    })
    .unwrap_or_else(|e| panic!("{e}"));
    for (i, s) in got.iter().enumerate() {
        let (t, g, _) = truth(i);
        assert_eq!(s.t_ns, t / 1000 * 1000);
        assert_eq!(s.gyro_rad_s.map(f64::to_bits), g.map(|v| f64::from(v as f32).to_bits()), "sample {i}");
    }
}
