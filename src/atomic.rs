//! Writing files so that nothing is ever half-written or overwritten.

use std::io::Write;
use std::path::Path;

/// Writes bytes to a new file atomically: a temporary file in the same folder, fsync, then a
/// no-clobber rename (a hard link, so an existing target is never replaced). Fails with
/// `AlreadyExists` if the target exists; on any failure no target file is left behind.
pub fn write_new(path: &Path, bytes: &[u8]) -> std::io::Result<()> {
    let dir = path
        .parent()
        .filter(|p| !p.as_os_str().is_empty())
        .unwrap_or(Path::new("."));
    let mut tmp = tempfile::Builder::new()
        .prefix(".crosscal-")
        .suffix(".tmp")
        .tempfile_in(dir)?;
    tmp.write_all(bytes)?;
    tmp.as_file().sync_all()?;
    tmp.persist_noclobber(path).map_err(|e| e.error)?;
    if let Ok(d) = std::fs::File::open(dir) {
        let _ = d.sync_all();
    }
    Ok(())
}
