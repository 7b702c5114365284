//! A sliding window over a file: the bytes from one offset on, read ahead as needed, so a
//! reader can look at a record *and the header after it* before trusting the record's
//! length, and step back to search for the next good record after a corrupt one. Memory:
//! the largest span asked for plus one read block.

use std::io::{Read, Seek, SeekFrom};

/// Bytes read from the file at a time.
const BLOCK: usize = 1 << 16;

/// The window (see the module docs).
#[derive(Debug)]
pub struct Window<R> {
    input: R,
    /// File offset of `data[0]`.
    start: u64,
    data: Vec<u8>,
    /// Where the file's read position is (`start + data.len()` unless a seek is pending).
    eof: bool,
}

impl<R: Read + Seek> Window<R> {
    /// A window at offset 0 of `input`.
    pub fn new(input: R) -> Self {
        Self { input, start: 0, data: Vec::new(), eof: false }
    }

    /// Up to `n` bytes from file offset `at` (fewer at the end of the file).
    pub fn get(&mut self, at: u64, n: usize) -> std::io::Result<&[u8]> {
        let end_in_window = self.start + self.data.len() as u64;
        if at < self.start || at > end_in_window {
            self.input.seek(SeekFrom::Start(at))?;
            self.start = at;
            self.data.clear();
            self.eof = false;
        } else if at > self.start {
            // Keep only what lies from `at` on.
            let drop = (at - self.start) as usize;
            if drop >= BLOCK || drop + n > self.data.capacity() {
                self.data.drain(..drop);
                self.start = at;
            }
        }
        let from = (at - self.start) as usize;
        while self.data.len() < from + n && !self.eof {
            let have = self.data.len();
            let want = (from + n - have).max(BLOCK);
            self.data.resize(have + want, 0);
            let got = super::read_up_to(&mut self.input, &mut self.data[have..])?;
            self.data.truncate(have + got);
            if got < want {
                self.eof = true;
            }
        }
        let to = (from + n).min(self.data.len());
        Ok(&self.data[from.min(to)..to])
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn any_span_reads_as_in_the_file() {
        let bytes: Vec<u8> = (0..300_000u32).map(|i| (i * 7 % 251) as u8).collect();
        let mut w = Window::new(std::io::Cursor::new(bytes.clone()));
        for (at, n) in [(0u64, 3usize), (1, 70_000), (5, 2), (100_000, 65_538), (99_999, 10), (299_990, 100), (3, 4)] {
            let want = &bytes[at as usize..(at as usize + n).min(bytes.len())];
            assert_eq!(w.get(at, n).unwrap(), want, "{at} {n}");
        }
        assert!(w.get(400_000, 5).unwrap().is_empty());
    }
}
