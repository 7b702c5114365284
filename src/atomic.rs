//! Writing files so that nothing is ever half-written or silently overwritten.

use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::Path;

/// Writes a file atomically: the content goes to a temporary file in the same folder, is
/// flushed and fsynced, then renamed into place. With `replace = false` the rename is a
/// no-clobber link and fails with `AlreadyExists` if the target exists. On any failure no
/// target file is created or changed (the temporary file is removed).
pub fn write_atomic<F>(path: &Path, replace: bool, fill: F) -> std::io::Result<()>
where
    F: FnOnce(&mut BufWriter<&File>) -> std::io::Result<()>,
{
    let dir = path.parent().filter(|p| !p.as_os_str().is_empty()).unwrap_or(Path::new("."));
    if !replace && path.exists() {
        return Err(std::io::Error::new(
            std::io::ErrorKind::AlreadyExists,
            format!("{} already exists", path.display()),
        ));
    }
    let tmp = tempfile::Builder::new().prefix(".crosscal-").suffix(".tmp").tempfile_in(dir)?;
    {
        let mut w = BufWriter::with_capacity(1 << 16, tmp.as_file());
        fill(&mut w)?;
        w.flush()?;
    }
    tmp.as_file().sync_all()?;
    // Temporary files are created 0600; the result is an ordinary file (0644 before umask).
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        std::fs::set_permissions(tmp.path(), std::fs::Permissions::from_mode(0o644))?;
    }
    if replace {
        tmp.persist(path).map_err(|e| e.error)?;
    } else {
        tmp.persist_noclobber(path).map_err(|e| e.error)?;
    }
    if let Ok(d) = File::open(dir) {
        let _ = d.sync_all();
    }
    Ok(())
}

/// Writes bytes to a new file atomically; fails with `AlreadyExists` if the target exists.
pub fn write_new(path: &Path, bytes: &[u8]) -> std::io::Result<()> {
    write_atomic(path, false, |w| w.write_all(bytes))
}
