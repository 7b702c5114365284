//! Writing files so that nothing is ever half-written or silently overwritten, and no
//! temporary file outlives its writer.
//!
//! Content goes to a hidden temporary file in the target's folder
//! (`.crosscal-<pid>-<random>.tmp`), is flushed and fsynced, then renamed into place. A
//! failed write removes its temporary file; the binary removes the ones in progress on
//! SIGINT/SIGTERM ([`remove_in_progress`]); and every write first removes the temporary
//! files that a killed process left in that folder (its pid no longer running, or a day
//! old), so a `kill -9` costs at most one stale file until the next write there.

use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};
use std::sync::Mutex;
use std::time::{Duration, SystemTime};

/// Temporary files being written now (removed by [`remove_in_progress`] on a signal).
static IN_PROGRESS: Mutex<Vec<PathBuf>> = Mutex::new(Vec::new());

/// Prefix of crosscal's temporary files.
const PREFIX: &str = ".crosscal-";

/// A temporary file left by a process that is gone (or that is a day old) is stale.
const STALE_AGE: Duration = Duration::from_secs(24 * 3600);

/// Adds a temporary file of the caller's to those [`remove_in_progress`] removes on a
/// signal (a spill file, say); [`forget_temporary`] takes it off again.
pub fn register_temporary(path: &Path) {
    register(path);
}

/// Takes a file registered by [`register_temporary`] off the list.
pub fn forget_temporary(path: &Path) {
    unregister(path);
}

fn register(path: &Path) {
    if let Ok(mut v) = IN_PROGRESS.lock() {
        v.push(path.to_path_buf());
    }
}

fn unregister(path: &Path) {
    if let Ok(mut v) = IN_PROGRESS.lock() {
        v.retain(|p| p != path);
    }
}

/// Removes every temporary file this process is writing (for a signal handler: the process
/// is about to exit without running destructors). Returns how many were removed.
pub fn remove_in_progress() -> usize {
    let paths = match IN_PROGRESS.lock() {
        Ok(mut v) => std::mem::take(&mut *v),
        Err(_) => return 0,
    };
    paths.iter().filter(|p| std::fs::remove_file(p).is_ok()).count()
}

/// The pid in a temporary file's name (`.crosscal-<pid>-…`), if it has one.
fn pid_of(name: &str) -> Option<u32> {
    name.strip_prefix(PREFIX)?.split('-').next()?.parse().ok()
}

/// Whether a process with this pid runs now (unknown on systems without /proc: assume it
/// does, and let the age decide).
fn alive(pid: u32) -> bool {
    if pid == std::process::id() {
        return true;
    }
    let proc = Path::new("/proc");
    !proc.is_dir() || proc.join(pid.to_string()).exists()
}

/// Removes the stale temporary files of crosscal in `dir` (see the module docs); returns
/// their paths.
pub fn clean_stale(dir: &Path) -> Vec<PathBuf> {
    let Ok(rd) = std::fs::read_dir(dir) else { return Vec::new() };
    let now = SystemTime::now();
    let mut removed = Vec::new();
    for e in rd.flatten() {
        let name = e.file_name();
        let Some(name) = name.to_str() else { continue };
        if !name.starts_with(PREFIX) || !name.ends_with(".tmp") {
            continue;
        }
        let old = e
            .metadata()
            .and_then(|m| m.modified())
            .ok()
            .and_then(|t| now.duration_since(t).ok())
            .is_some_and(|age| age > STALE_AGE);
        let orphan = pid_of(name).is_some_and(|pid| !alive(pid));
        if (old || orphan) && std::fs::remove_file(e.path()).is_ok() {
            removed.push(e.path());
        }
    }
    removed
}

/// The output path that means standard output (`-o -`).
pub const STDOUT: &str = "-";

/// What a file that is not a regular file is, in words (a FIFO, a device, a folder …).
pub fn file_kind(meta: &std::fs::Metadata) -> &'static str {
    let t = meta.file_type();
    #[cfg(unix)]
    {
        use std::os::unix::fs::FileTypeExt;
        if t.is_fifo() {
            return "a FIFO (named pipe)";
        }
        if t.is_char_device() || t.is_block_device() {
            return "a device";
        }
        if t.is_socket() {
            return "a socket";
        }
    }
    if t.is_dir() {
        "a folder"
    } else if t.is_file() {
        "a regular file"
    } else {
        "not a regular file"
    }
}

/// Refuses an output path that exists and is not a regular file (a device, a FIFO, a
/// folder; a symbolic link is judged by what it points to): crosscal writes regular files
/// only, and `--force` never replaces anything else (as root, `-o /dev/null --force` would
/// otherwise replace /dev/null). `-` is standard output.
pub fn check_target(path: &Path) -> std::io::Result<()> {
    match std::fs::metadata(path) {
        Ok(m) if !m.is_file() => Err(std::io::Error::new(
            std::io::ErrorKind::InvalidInput,
            format!(
                "{} is {}, not a regular file: crosscal writes regular files only (use -o - for standard output)",
                path.display(),
                file_kind(&m)
            ),
        )),
        _ => Ok(()),
    }
}

/// The largest text file (manifest, profile, rules, message definition) read whole.
pub const MAX_TEXT_BYTES: u64 = 1 << 30;

/// Reads a text file that must be a regular file: a FIFO, a device or a link to one is
/// refused before it is opened (opening a FIFO blocks; `/dev/zero` never ends), and a file
/// over [`MAX_TEXT_BYTES`] is refused.
pub fn read_text(path: &Path) -> std::io::Result<String> {
    let m = std::fs::metadata(path)?;
    if !m.is_file() {
        return Err(std::io::Error::new(
            std::io::ErrorKind::InvalidInput,
            format!("{} is {}, not a regular file: skipped", path.display(), file_kind(&m)),
        ));
    }
    if m.len() > MAX_TEXT_BYTES {
        return Err(std::io::Error::new(
            std::io::ErrorKind::InvalidData,
            format!(
                "{} holds {} bytes: more than a text file crosscal reads ({MAX_TEXT_BYTES})",
                path.display(),
                m.len()
            ),
        ));
    }
    let mut s = String::new();
    std::io::Read::read_to_string(&mut std::io::Read::take(File::open(path)?, MAX_TEXT_BYTES), &mut s)?;
    Ok(s)
}

/// Writes `fill`'s output to standard output (for `-o -`).
fn write_stdout<F>(fill: F) -> std::io::Result<()>
where
    F: FnOnce(&mut BufWriter<&File>) -> std::io::Result<()>,
{
    #[cfg(unix)]
    {
        use std::os::fd::AsFd;
        let f = File::from(std::io::stdout().as_fd().try_clone_to_owned()?);
        let mut w = BufWriter::with_capacity(1 << 16, &f);
        fill(&mut w)?;
        w.flush()
    }
    #[cfg(not(unix))]
    {
        let _ = fill;
        Err(std::io::Error::new(std::io::ErrorKind::Unsupported, "-o - (standard output) needs a Unix system"))
    }
}

/// Writes a file atomically: the content goes to a temporary file in the same folder, is
/// flushed and fsynced, then renamed into place. With `replace = false` the rename is a
/// no-clobber link and fails with `AlreadyExists` if the target exists. On any failure no
/// target file is created or changed (the temporary file is removed). A target that is not
/// a regular file is refused ([`check_target`]); the path `-` is standard output.
pub fn write_atomic<F>(path: &Path, replace: bool, fill: F) -> std::io::Result<()>
where
    F: FnOnce(&mut BufWriter<&File>) -> std::io::Result<()>,
{
    if path.as_os_str() == STDOUT {
        return write_stdout(fill);
    }
    check_target(path)?;
    let dir = path.parent().filter(|p| !p.as_os_str().is_empty()).unwrap_or(Path::new("."));
    if !replace && path.exists() {
        return Err(std::io::Error::new(
            std::io::ErrorKind::AlreadyExists,
            format!("{} already exists", path.display()),
        ));
    }
    clean_stale(dir);
    let tmp =
        tempfile::Builder::new().prefix(&format!("{PREFIX}{}-", std::process::id())).suffix(".tmp").tempfile_in(dir)?;
    register(tmp.path());
    let result = write_and_persist(tmp, path, replace, fill);
    if let Err((tmp_path, e)) = result {
        unregister(&tmp_path);
        return Err(e);
    }
    if let Ok(d) = File::open(dir) {
        let _ = d.sync_all();
    }
    Ok(())
}

/// Fills, syncs and renames the temporary file (unregistered once renamed); on failure the
/// temporary file is dropped (removed) and its path returned with the error.
fn write_and_persist<F>(
    tmp: tempfile::NamedTempFile,
    path: &Path,
    replace: bool,
    fill: F,
) -> Result<(), (PathBuf, std::io::Error)>
where
    F: FnOnce(&mut BufWriter<&File>) -> std::io::Result<()>,
{
    let tmp_path = tmp.path().to_path_buf();
    let fail = |e| (tmp_path.clone(), e);
    {
        let mut w = BufWriter::with_capacity(1 << 16, tmp.as_file());
        fill(&mut w).map_err(fail)?;
        w.flush().map_err(fail)?;
    }
    tmp.as_file().sync_all().map_err(fail)?;
    // Temporary files are created 0600; the result is an ordinary file (0644 before umask).
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        std::fs::set_permissions(tmp.path(), std::fs::Permissions::from_mode(0o644)).map_err(fail)?;
    }
    let persisted = if replace { tmp.persist(path) } else { tmp.persist_noclobber(path) };
    unregister(&tmp_path);
    persisted.map(|_| ()).map_err(|e| (tmp_path.clone(), e.error))
}

/// Writes bytes to a new file atomically; fails with `AlreadyExists` if the target exists.
pub fn write_new(path: &Path, bytes: &[u8]) -> std::io::Result<()> {
    write_atomic(path, false, |w| w.write_all(bytes))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The in-progress registry is global: tests that write must not run at once, or one's
    /// `remove_in_progress` removes the other's temporary file.
    static SERIAL: std::sync::Mutex<()> = std::sync::Mutex::new(());

    #[test]
    fn stale_temporaries_of_dead_processes_are_removed_and_live_ones_kept() {
        let _one = SERIAL.lock().unwrap_or_else(std::sync::PoisonError::into_inner);
        let dir = tempfile::tempdir().unwrap();
        // A pid that cannot run (above the kernel's maximum), and this process's.
        let dead = dir.path().join(".crosscal-4194305-abc.tmp");
        let mine = dir.path().join(format!(".crosscal-{}-abc.tmp", std::process::id()));
        let other = dir.path().join("data.tmp");
        for p in [&dead, &mine, &other] {
            std::fs::write(p, b"x").unwrap();
        }
        write_new(&dir.path().join("out.json"), b"{}").unwrap();
        assert!(!dead.exists() && mine.exists() && other.exists());
        assert_eq!(std::fs::read(dir.path().join("out.json")).unwrap(), b"{}");
    }

    #[test]
    fn a_failed_write_leaves_nothing_and_remove_in_progress_forgets_it() {
        let _one = SERIAL.lock().unwrap_or_else(std::sync::PoisonError::into_inner);
        let dir = tempfile::tempdir().unwrap();
        let target = dir.path().join("out.csv");
        let e = write_atomic(&target, false, |_| Err(std::io::Error::other("disk full"))).unwrap_err();
        assert!(e.to_string().contains("disk full"));
        let left: Vec<_> = std::fs::read_dir(dir.path()).unwrap().collect();
        assert!(left.is_empty() && !target.exists());
        assert_eq!(remove_in_progress(), 0);
    }
}
