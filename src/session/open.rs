//! Opening the files a session names: regular files only (a folder, FIFO or device is
//! refused before it can block), gzip decompressed on the fly.

use super::error::SessionError;
use std::path::Path;

/// Opens a recording for reading as a stream: a regular file, decompressed on the fly when
/// it is gzip (by its first two bytes, 1f 8b, whatever its name), with an estimate of its
/// uncompressed size (for reserving room; eight times the compressed size for gzip).
pub fn open_recording(path: &Path) -> Result<(Box<dyn std::io::Read + Send>, u64), SessionError> {
    use std::io::{BufRead, BufReader};
    let (file, size) = open_regular(path)?;
    let mut input = BufReader::with_capacity(1 << 16, file);
    let head = input.fill_buf().map_err(|source| SessionError::Io { path: path.to_path_buf(), source })?;
    if head.starts_with(&[0x1f, 0x8b]) {
        Ok((Box::new(flate2::bufread::MultiGzDecoder::new(input)), size.saturating_mul(8)))
    } else {
        Ok((Box::new(input), size))
    }
}

/// Opens a file that must be a regular file (not a folder, FIFO or device, which would be
/// refused late or block), with its size.
pub fn open_regular(path: &Path) -> Result<(std::fs::File, u64), SessionError> {
    let io = |source| SessionError::Io { path: path.to_path_buf(), source };
    let meta = std::fs::metadata(path).map_err(io)?;
    if !meta.is_file() {
        return Err(SessionError::NotRegular { path: path.to_path_buf(), what: file_kind(&meta) });
    }
    let file = std::fs::File::open(path).map_err(io)?;
    Ok((file, meta.len()))
}

/// What a file that is not a regular file is, in words.
pub fn file_kind(meta: &std::fs::Metadata) -> &'static str {
    crate::atomic::file_kind(meta)
}
