//! The profile store: `calib-profiles/<serial>/<UTC time>.json`, written atomically and
//! never overwritten; the history of a unit and the profile in force at a time.

use super::{Profile, ProfileError};
use std::path::{Path, PathBuf};

/// A file in the profile store and what reading it gave.
pub type StoredProfile = (PathBuf, Result<Profile, ProfileError>);

/// Every readable profile of unit `serial` in the store `root`, oldest first (by creation
/// time, then file name). Files that are not profiles, or are another unit's, are returned
/// as errors, in order.
pub fn history(root: &Path, serial: &str) -> Result<Vec<StoredProfile>, ProfileError> {
    if !crate::session::valid_serial(serial) {
        return Err(ProfileError::BadSerial(serial.to_string()));
    }
    let dir = root.join(serial);
    let rd = std::fs::read_dir(&dir).map_err(|source| ProfileError::Io { path: dir.clone(), source })?;
    let mut files: Vec<PathBuf> =
        rd.filter_map(|e| e.ok().map(|e| e.path())).filter(|p| p.extension().is_some_and(|x| x == "json")).collect();
    files.sort();
    let read = |path: &Path| -> Result<Profile, ProfileError> {
        let p = Profile::read(path)?;
        if p.serial != serial {
            return Err(ProfileError::WrongFolder {
                path: path.to_path_buf(),
                profile_serial: p.serial,
                folder: serial.to_string(),
            });
        }
        Ok(p)
    };
    let mut out: Vec<StoredProfile> = files.into_iter().map(|p| (p.clone(), read(&p))).collect();
    out.sort_by(|a, b| {
        // By time, not by text: "…:35Z" is earlier than "…:35.1Z" though it sorts after it.
        let key = |x: &StoredProfile| x.1.as_ref().ok().and_then(|p| p.created_utc.parse::<jiff::Timestamp>().ok());
        key(a).cmp(&key(b)).then_with(|| a.0.cmp(&b.0))
    });
    Ok(out)
}

/// The newest readable profile of unit `serial` in `root` created at or before `at` (RFC 3339;
/// None = now: a profile dated in the future is never in force without `at`).
pub fn latest(root: &Path, serial: &str, at: Option<&str>) -> Result<(PathBuf, Profile), ProfileError> {
    if !crate::session::valid_serial(serial) {
        return Err(ProfileError::BadSerial(serial.to_string()));
    }
    let cutoff = match at {
        Some(a) => Some(parse_time(a)?),
        None => Some(jiff::Timestamp::now()),
    };
    let found = history(root, serial)?.into_iter().rev().find_map(|(path, p)| {
        let p = p.ok()?;
        let t = p.created_utc.parse::<jiff::Timestamp>().ok()?;
        cutoff.is_none_or(|c| t <= c).then_some((path, p))
    });
    found.ok_or_else(|| ProfileError::Io {
        path: root.join(serial),
        source: std::io::Error::new(
            std::io::ErrorKind::NotFound,
            match at {
                Some(a) => format!("no profile of unit '{serial}' created at or before {a}"),
                None => format!("no profile of unit '{serial}'"),
            },
        ),
    })
}

/// Parses a UTC time: RFC 3339 (`2026-11-23T12:00:00Z`) or a date (`2026-11-23`, end of day).
pub fn parse_time(s: &str) -> Result<jiff::Timestamp, ProfileError> {
    if let Ok(t) = s.parse::<jiff::Timestamp>() {
        return Ok(t);
    }
    s.parse::<jiff::civil::Date>()
        .ok()
        .and_then(|d| d.at(23, 59, 59, 999_000_000).to_zoned(jiff::tz::TimeZone::UTC).ok())
        .map(|z| z.timestamp())
        .ok_or_else(|| ProfileError::BadTime(s.to_string()))
}

/// Saves a profile under `root/<serial>/<timestamp>.json` atomically, never overwriting:
/// if the name is taken, `-1`, `-2`, … are appended. Returns the path written.
pub fn save(profile: &Profile, root: &Path) -> Result<PathBuf, ProfileError> {
    if !crate::session::valid_serial(&profile.serial) {
        return Err(ProfileError::BadSerial(profile.serial.clone()));
    }
    let dir = root.join(&profile.serial);
    std::fs::create_dir_all(&dir).map_err(|source| ProfileError::Io { path: dir.clone(), source })?;
    let json = profile.to_json();
    let stem = profile.file_stem();
    for k in 0..1000 {
        let name = if k == 0 { format!("{stem}.json") } else { format!("{stem}-{k}.json") };
        let path = dir.join(name);
        match crate::atomic::write_new(&path, json.as_bytes()) {
            Ok(()) => return Ok(path),
            Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => continue,
            Err(source) => return Err(ProfileError::Io { path, source }),
        }
    }
    Err(ProfileError::Io {
        path: dir,
        source: std::io::Error::other("more than 1000 profiles with the same time stamp"),
    })
}

/// Serials with at least one file in the store, sorted.
pub fn serials(root: &Path) -> Result<Vec<String>, ProfileError> {
    let rd = std::fs::read_dir(root).map_err(|source| ProfileError::Io { path: root.to_path_buf(), source })?;
    let mut out: Vec<String> = rd
        .filter_map(|e| e.ok())
        .filter(|e| e.path().is_dir())
        .filter_map(|e| e.file_name().to_str().map(str::to_string))
        .filter(|s| crate::session::valid_serial(s))
        .collect();
    out.sort();
    Ok(out)
}
