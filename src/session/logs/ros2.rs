//! ROS 2 bags (rosbag2): a folder with `metadata.yaml` and its storage files, sqlite3
//! (`.db3`: tables `topics` and `messages`, CDR payloads) or MCAP (`.mcap`: schemas,
//! channels and chunked messages, read by [`super::mcap`]); a lone `.db3` or `.mcap` file reads the same.
//!
//! sqlite3 bags before ROS 2 Iron store no message definitions. The standard
//! `sensor_msgs/msg/Imu` is built in; a custom type is decoded from the definition the
//! user gives (`--msg-def TYPE=FILE.msg`), from the bag's `message_definitions` table when
//! it has one, or, failing both, recognised from the bytes as a wrapper whose first fields
//! are a `std_msgs/Header` and a `sensor_msgs/Imu` (checked on the first message, and said).
//! MCAP files carry their definitions (`ros2msg` schemas); chunks are decompressed one at
//! a time (zstd, lz4) with every length checked first ([`super::mcap`]).

use super::ros1::{user_program, FRAME_ROS};
use super::rosmsg::{Definitions, Program, Wire};
use super::{Contents, LogFormat, LogSample, ReadOptions, Sink, StreamDesc};
use crate::session::error::{Problem, SessionError};
use std::collections::HashMap;
use std::path::{Path, PathBuf};

/// The storage of a bag folder.
pub fn folder_format(dir: &Path) -> Result<LogFormat, SessionError> {
    let (files, _) = bag_files(dir)?;
    match files.first().and_then(|f| f.extension()).and_then(|e| e.to_str()) {
        Some("mcap") => Ok(LogFormat::Mcap),
        _ => Ok(LogFormat::Ros2Sqlite),
    }
}

/// The storage files of a bag folder, in order (from `metadata.yaml`'s
/// `relative_file_paths`, or every `.db3`/`.mcap` by name), and the metadata's
/// `compression_format` when set.
fn bag_files(dir: &Path) -> Result<(Vec<PathBuf>, Option<String>), SessionError> {
    let meta_path = dir.join("metadata.yaml");
    let mut files = Vec::new();
    let mut compression = None;
    if let Ok(text) = crate::atomic::read_text(&meta_path) {
        let mut in_paths = false;
        for line in text.lines() {
            let t = line.trim();
            if t.starts_with("relative_file_paths:") {
                in_paths = true;
                continue;
            }
            if in_paths {
                match t.strip_prefix("- ") {
                    Some(f) => files.push(dir.join(f.trim().trim_matches('"').trim_matches('\''))),
                    None => in_paths = false,
                }
            }
            if let Some(c) = t.strip_prefix("compression_format:") {
                let c = c.trim().trim_matches('"').trim_matches('\'');
                if !c.is_empty() {
                    compression = Some(c.to_string());
                }
            }
        }
    }
    if files.is_empty() {
        let rd = std::fs::read_dir(dir).map_err(|source| SessionError::Io { path: dir.to_path_buf(), source })?;
        for e in rd.flatten() {
            let p = e.path();
            if matches!(p.extension().and_then(|e| e.to_str()), Some("db3" | "mcap")) {
                files.push(p);
            }
        }
        files.sort();
    }
    if files.is_empty() {
        return Err(SessionError::log(
            Problem::Empty,
            dir,
            0,
            "a folder with no metadata.yaml naming its files and no .db3 or .mcap file: expected a ROS 2 bag folder",
        ));
    }
    Ok((files, compression))
}

/// Reads a ROS 2 bag (folder) or one `.db3`/`.mcap` file.
pub fn read(
    path: &Path,
    opts: &ReadOptions,
    only: Option<usize>,
    sink: &mut Sink<'_>,
) -> Result<Contents, SessionError> {
    let (files, compression) = if path.is_dir() { bag_files(path)? } else { (vec![path.to_path_buf()], None) };
    if let Some(c) = compression {
        return Err(SessionError::log(
            Problem::Format,
            path,
            0,
            format!("the bag is {c}-compressed file by file: decompress it first (ros2 bag convert, or zstd -d on each file)"),
        ));
    }
    let mut st = Streams { opts, out: None, topics: HashMap::new() };
    for f in &files {
        match super::detect(f)? {
            LogFormat::Ros2Sqlite => sqlite(f, &mut st, only, sink)?,
            LogFormat::Mcap => mcap_file(f, &mut st, only, sink)?,
            other => {
                return Err(SessionError::log(
                    Problem::Format,
                    f,
                    0,
                    format!("a {} inside a ROS 2 bag: expected .db3 or .mcap", other.name()),
                ))
            }
        }
    }
    st.out.ok_or_else(|| SessionError::log(Problem::Empty, path, 0, "the bag has no storage file"))
}

/// Streams across the files of one bag: topic → (stream index, decoder).
struct Streams<'o> {
    opts: &'o ReadOptions,
    out: Option<Contents>,
    topics: HashMap<String, Option<(usize, Program)>>,
}

impl Streams<'_> {
    fn contents(&mut self, format: LogFormat) -> &mut Contents {
        self.out.get_or_insert_with(|| Contents::new(format))
    }

    /// Registers a topic with its decoder (None: not an IMU topic).
    fn topic(&mut self, format: LogFormat, name: &str, ty: &str, program: Option<Program>, note: Option<String>) {
        if self.topics.contains_key(name) {
            return;
        }
        let entry = program.map(|p| {
            let c = self.contents(format);
            c.streams.push(StreamDesc {
                name: name.into(),
                message: ty.into(),
                instance: None,
                frame: FRAME_ROS,
                has_temp: false,
                six_axis: true,
                note,
            });
            (c.streams.len() - 1, p)
        });
        self.contents(format);
        self.topics.insert(name.into(), entry);
    }
}

/// A wrapper type recognised from the first message's bytes: `Header` + `Imu`, or `Imu`
/// first; the decoded values must be finite and physically plausible.
fn recognise(first: &[u8]) -> Option<(Program, &'static str)> {
    let mut defs = Definitions::new(Wire::Cdr);
    let candidates = [
        (
            "guess/HeaderImu",
            "std_msgs/Header header\nsensor_msgs/Imu imu\n",
            "a std_msgs/Header then a sensor_msgs/Imu",
        ),
        ("guess/ImuFirst", "sensor_msgs/Imu imu\n", "a sensor_msgs/Imu first"),
    ];
    for (name, text, what) in candidates {
        defs.add_text(name, text).ok()?;
        let p = defs.compile(name).ok()?.prefix();
        if let Ok(f) = p.decode(first) {
            let norm = |v: [f64; 3]| v.iter().map(|x| x * x).sum::<f64>().sqrt();
            let ok = f.gyro_rad_s.iter().chain(&f.accel_m_s2).all(|x| x.is_finite())
                && (0.1..1000.0).contains(&norm(f.accel_m_s2))
                && norm(f.gyro_rad_s) < 50.0
                && f.stamp.0 > 0
                && f.stamp.1 < 1_000_000_000;
            if ok {
                return Some((p, what));
            }
        }
    }
    None
}

fn sqlite(path: &Path, st: &mut Streams<'_>, only: Option<usize>, sink: &mut Sink<'_>) -> Result<(), SessionError> {
    use rusqlite::{Connection, OpenFlags};
    let bad = |e: rusqlite::Error| SessionError::log(Problem::Malformed, path, 0, format!("sqlite: {e}"));
    let db = Connection::open_with_flags(path, OpenFlags::SQLITE_OPEN_READ_ONLY | OpenFlags::SQLITE_OPEN_NO_MUTEX)
        .map_err(bad)?;
    // Definitions stored by rosbag2 since Iron (table `message_definitions`).
    let mut stored: HashMap<String, String> = HashMap::new();
    if let Ok(mut q) =
        db.prepare("SELECT topic_type, encoded_message_definition FROM message_definitions WHERE encoding = 'ros2msg'")
    {
        let rows = q.query_map([], |r| Ok((r.get::<_, String>(0)?, r.get::<_, String>(1)?))).map_err(bad)?;
        for r in rows.flatten() {
            stored.insert(r.0, r.1);
        }
    }
    // A damaged file (pages, indexes) is said; what can be read is read.
    if let Ok(check) = db.query_row("PRAGMA quick_check(5)", [], |r| r.get::<_, String>(0)) {
        if check != "ok" {
            st.contents(LogFormat::Ros2Sqlite)
                .warnings
                .push(format!("the sqlite file is damaged (quick_check: {check}): messages may be missing"));
        }
    }
    let mut topics: HashMap<i64, (String, String)> = HashMap::new();
    let mut all_topics = std::collections::HashSet::new();
    {
        let mut q = db.prepare("SELECT id, name, type, serialization_format FROM topics").map_err(bad)?;
        let rows = q
            .query_map([], |r| {
                Ok((r.get::<_, i64>(0)?, r.get::<_, String>(1)?, r.get::<_, String>(2)?, r.get::<_, String>(3)?))
            })
            .map_err(bad)?;
        for r in rows {
            let (id, name, ty, ser) = r.map_err(bad)?;
            all_topics.insert(id);
            if ser == "cdr" {
                topics.insert(id, (name, ty));
            }
        }
    }
    let mut pending: HashMap<i64, ()> = HashMap::new();
    for (id, (name, ty)) in &topics {
        if st.topics.contains_key(name) {
            continue;
        }
        let mut defs = Definitions::new(Wire::Cdr);
        let from_bag = stored.get(ty).and_then(|t| defs.add_text(ty, t).ok()).and_then(|()| defs.compile(ty).ok());
        let user = user_program(st.opts, ty, Wire::Cdr).map_err(|m| SessionError::log(Problem::Invalid, path, 0, m))?;
        let builtin = defs.knows(ty).then(|| defs.compile(ty).ok()).flatten();
        match user.or(from_bag).or(builtin) {
            Some(p) => st.topic(LogFormat::Ros2Sqlite, name, ty, Some(p), None),
            None if defs.knows(ty) => st.topic(LogFormat::Ros2Sqlite, name, ty, None, None),
            None => {
                pending.insert(*id, ());
            }
        }
    }
    st.contents(LogFormat::Ros2Sqlite);
    // In the order written (rosbag2 inserts as it receives): one row with a corrupt bag time
    // is then one outlying stamp, not a row moved to the other end of the recording.
    let mut q = db.prepare("SELECT topic_id, timestamp, data, id FROM messages ORDER BY id").map_err(bad)?;
    let mut rows = q.query([]).map_err(bad)?;
    while let Some(row) = rows.next().map_err(bad)? {
        let id: i64 = row.get(0).map_err(bad)?;
        let Some((name, ty)) = topics.get(&id) else {
            if !all_topics.contains(&id) {
                let row_id: i64 = row.get(3).map_err(bad)?;
                st.contents(LogFormat::Ros2Sqlite)
                    .refuse(format!("message id {row_id}: topic id {id}, which the topics table does not list"));
            }
            continue;
        };
        let data =
            row.get_ref(2).map_err(bad)?.as_blob().map_err(|e| {
                bad(rusqlite::Error::FromSqlConversionFailure(2, rusqlite::types::Type::Blob, Box::new(e)))
            })?;
        if pending.remove(&id).is_some() {
            let guess = recognise(data);
            let note = guess.as_ref().map(|(_, what)| {
                format!("{ty} has no definition in the bag: read as {what} (recognised from the bytes); give --msg-def {ty}=FILE.msg to be sure")
            });
            st.topic(LogFormat::Ros2Sqlite, name, ty, guess.map(|g| g.0), note);
        }
        let Some(Some((idx, program))) = st.topics.get(name) else { continue };
        if only.is_some_and(|o| o != *idx) {
            continue;
        }
        let stamp_ns: i64 = row.get(1).map_err(bad)?;
        if let Err(what) = emit(program, *idx, data, stamp_ns, sink)? {
            let row_id: i64 = row.get(3).map_err(bad)?;
            st.contents(LogFormat::Ros2Sqlite).refuse(format!("message id {row_id}: {what}"));
        }
    }
    Ok(())
}

/// Decodes one message and hands it on (the bag's receive time when the stamp is zero);
/// `Ok(Err(what))` for a message that does not decode (to be refused by the caller).
fn emit(
    program: &Program,
    idx: usize,
    data: &[u8],
    recv_ns: i64,
    sink: &mut Sink<'_>,
) -> Result<Result<(), String>, SessionError> {
    let f = match program.decode(data) {
        Ok(f) => f,
        Err(e) => return Ok(Err(format!("a message received at {recv_ns} ns, offset {} in it: {}", e.offset, e.msg))),
    };
    let mut t_ns = f.stamp.0.saturating_mul(1_000_000_000).saturating_add(i64::from(f.stamp.1));
    if t_ns == 0 {
        t_ns = recv_ns;
    }
    sink(idx, &LogSample { t_ns, gyro_rad_s: f.gyro_rad_s, accel_m_s2: f.accel_m_s2, temp_c: f.temp_c }).map(Ok)
}

fn mcap_file(path: &Path, st: &mut Streams<'_>, only: Option<usize>, sink: &mut Sink<'_>) -> Result<(), SessionError> {
    use super::mcap::Event;
    let mut schemas: HashMap<u16, (String, String, Vec<u8>)> = HashMap::new();
    let mut channels: HashMap<u16, String> = HashMap::new();
    st.contents(LogFormat::Mcap);
    let dmg = super::mcap::walk(path, &mut |ev, at| {
        match ev {
            Event::Schema { id, name, encoding, data } => {
                schemas.insert(id, (name, encoding, data.to_vec()));
            }
            Event::Channel { id, schema_id, topic, encoding } => {
                if let std::collections::hash_map::Entry::Vacant(e) = channels.entry(id) {
                    mcap_channel(path, st, &schemas, schema_id, &topic, &encoding)?;
                    e.insert(topic);
                }
            }
            Event::Message { channel_id, log_time, data } => {
                let Some(topic) = channels.get(&channel_id) else {
                    st.contents(LogFormat::Mcap).refuse(format!(
                        "byte {at}: a message on channel {channel_id}, which no channel record declares"
                    ));
                    return Ok(());
                };
                let Some(Some((idx, program))) = st.topics.get(topic) else { return Ok(()) };
                if only.is_some_and(|o| o != *idx) {
                    return Ok(());
                }
                if let Err(what) = emit(program, *idx, data, i64::try_from(log_time).unwrap_or(i64::MAX), sink)? {
                    st.contents(LogFormat::Mcap).refuse(format!("byte {at}: {what}"));
                }
            }
        }
        Ok(())
    })?;
    let c = st.contents(LogFormat::Mcap);
    c.warnings.extend(dmg.warnings);
    for (ch, n) in dmg.lost {
        if let Some(topic) = channels.get(&ch).filter(|t| st.topics.get(*t).is_some_and(Option::is_some)) {
            st.contents(LogFormat::Mcap)
                .warnings
                .push(format!("{topic}: {n} messages lost in chunks that could not be read"));
        }
    }
    Ok(())
}

fn mcap_channel(
    path: &Path,
    st: &mut Streams<'_>,
    schemas: &HashMap<u16, (String, String, Vec<u8>)>,
    schema_id: u16,
    topic: &str,
    message_encoding: &str,
) -> Result<(), SessionError> {
    let wire = match message_encoding {
        "cdr" => Wire::Cdr,
        "ros1" => Wire::Ros1,
        _ => return Ok(()),
    };
    let Some((ty, encoding, def)) = schemas.get(&schema_id) else { return Ok(()) };
    let mut defs = Definitions::new(wire);
    let from_file = (encoding == "ros2msg" || encoding == "ros1msg")
        .then(|| defs.add_text(ty, &String::from_utf8_lossy(def)).ok().and_then(|()| defs.compile(ty).ok()))
        .flatten();
    let user = user_program(st.opts, ty, wire).map_err(|m| SessionError::log(Problem::Invalid, path, 0, m))?;
    st.topic(LogFormat::Mcap, topic, ty, user.or(from_file), None);
    Ok(())
}
