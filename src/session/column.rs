//! A recording's long columns (time stamps, gyro and accelerometer outputs): on the heap
//! while the columns read so far fit a budget, beyond it in a memory-mapped spill file.
//!
//! A reader builds each column with a [`ColumnBuilder`]. Its samples go to the heap in
//! steps of [`STEP_BYTES`], each step reserved against one process-wide budget
//! ([`heap_budget_bytes`], 64 MiB unless `CROSSCAL_HEAP_MB` says otherwise). When a step
//! would exceed it, the builder moves what it holds to an unnamed temporary file and goes
//! on writing there; the finished column maps that file read-only. A mapped column reads
//! like any slice (its pages come from the page cache), and a governor thread hands the
//! mapped pages back to the page cache whenever more than [`MAPPED_RESIDENT_BYTES`] of
//! them are resident, looking every [`RELEASE_EVERY`] (`madvise(MADV_DONTNEED)` on the
//! shared mapping: the file's contents do not change, the next touch maps them again), so
//! a session of 10⁷ samples is read with a bounded resident set, the same numbers as on
//! the heap. The bound is the governor's and loose: a pass that streams columns maps them
//! at tens of GB/s (64 KiB of page cache per fault), so between two looks the mapped pages
//! can pass the bound by 50–120 MB (measured at 10⁷ samples; a look every 0.5 ms overshot
//! as much and took 5 % of a core). Once a session is past the budget its heap columns
//! move to spill files too ([`Column::spilled`], `Session::load`), so the heap holds none
//! of a session that is mapped.
//!
//! Why a mapping rather than loading runs on demand: every layer above reads recordings as
//! slices (`&[[f64; 3]]`), so the storage changes and no reader of a recording does.

use std::io::{Read, Seek, Write};
use std::ops::Deref;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::{Arc, Mutex, OnceLock, Weak};
use std::time::Duration;

/// Bytes a heap column reserves from the budget at a time.
pub const STEP_BYTES: usize = 1 << 20;

/// How often the governor looks at the resident pages of the mappings.
pub const RELEASE_EVERY: Duration = Duration::from_millis(2);

/// Resident mapped bytes the governor allows before it hands the pages back.
pub const MAPPED_RESIDENT_BYTES: usize = 32 << 20;

/// Bytes of reader-built columns on the heap now (their reservations).
static HEAP_BYTES: AtomicUsize = AtomicUsize::new(0);

/// The heap budget of reader-built columns, bytes: `CROSSCAL_HEAP_MB` (MiB, fractions
/// allowed; 0 spills everything) or 64 MiB — a session of 10⁶ samples (56 MB) stays on the heap.
pub fn heap_budget_bytes() -> usize {
    static BUDGET: OnceLock<usize> = OnceLock::new();
    *BUDGET.get_or_init(|| {
        let mib = std::env::var("CROSSCAL_HEAP_MB").ok().and_then(|v| v.trim().parse::<f64>().ok());
        (mib.filter(|m| m.is_finite() && *m >= 0.0).unwrap_or(64.0) * (1u64 << 20) as f64) as usize
    })
}

/// Bytes held back from [`HEAP_BYTES`] by one column; given back when dropped.
#[derive(Debug, Default)]
struct Reservation(usize);

impl Reservation {
    /// Reserves `bytes` more when the budget has room for them.
    fn grow(&mut self, bytes: usize, budget: usize) -> bool {
        let before = HEAP_BYTES.fetch_add(bytes, Ordering::Relaxed);
        if before + bytes > budget {
            HEAP_BYTES.fetch_sub(bytes, Ordering::Relaxed);
            return false;
        }
        self.0 += bytes;
        true
    }
}

impl Reservation {
    /// Gives back what is held beyond `bytes`.
    fn shrink_to(&mut self, bytes: usize) {
        if bytes < self.0 {
            HEAP_BYTES.fetch_sub(self.0 - bytes, Ordering::Relaxed);
            self.0 = bytes;
        }
    }
}

impl Drop for Reservation {
    fn drop(&mut self) {
        HEAP_BYTES.fetch_sub(self.0, Ordering::Relaxed);
    }
}

/// Where a column's samples are.
#[derive(Debug)]
enum Store<T> {
    Heap(Vec<T>, #[allow(dead_code)] Reservation),
    Mapped(memmap2::Mmap),
}

/// An immutable column of samples, cheap to clone and to slice (clones share the samples).
pub struct Column<T: bytemuck::Pod> {
    store: Arc<Store<T>>,
    start: usize,
    len: usize,
}

impl<T: bytemuck::Pod> Column<T> {
    /// Samples `start..end` of this column, sharing its storage. Panics when the range is
    /// out of bounds, as slicing does.
    pub fn slice(&self, start: usize, end: usize) -> Self {
        assert!(start <= end && end <= self.len, "column range {start}..{end} of {}", self.len);
        Self { store: self.store.clone(), start: self.start + start, len: end - start }
    }

    /// True when both are the same samples of the same storage (not merely equal).
    pub fn same_as(&self, other: &Self) -> bool {
        Arc::ptr_eq(&self.store, &other.store) && self.start == other.start && self.len == other.len
    }

    /// True when the samples are in a mapped spill file rather than on the heap.
    pub fn is_mapped(&self) -> bool {
        matches!(*self.store, Store::Mapped(_))
    }

    /// The samples to change in place: this column's own heap copy (copied first when the
    /// samples are shared, mapped or a part of a longer column).
    pub fn make_mut(&mut self) -> &mut [T] {
        let whole = matches!(&*self.store, Store::Heap(v, _) if self.start == 0 && self.len == v.len());
        if !whole || Arc::get_mut(&mut self.store).is_none() {
            *self = self.to_vec().into();
        }
        match Arc::get_mut(&mut self.store) {
            Some(Store::Heap(v, _)) => v,
            // Just made a unique heap store above.
            _ => &mut [],
        }
    }

    /// This column in a mapped spill file of its own (a clone when it is mapped already):
    /// its heap store, once no other column shares it, goes back to the allocator and its
    /// reservation to the budget. Errors when the file cannot be written or mapped.
    pub fn spilled(&self) -> std::io::Result<Self>
    where
        T: Send + Sync + 'static,
    {
        if self.is_mapped() || self.is_empty() {
            return Ok(self.clone());
        }
        mapped(tempfile::tempfile()?, &self[..], self.len)
    }

    fn all(&self) -> &[T] {
        match &*self.store {
            Store::Heap(v, _) => v,
            // The mapping starts on a page boundary and holds whole `T`s written by
            // `ColumnBuilder` (f64 or [f64; 3]), so the cast cannot fail its checks.
            Store::Mapped(m) => bytemuck::cast_slice(&m[..]),
        }
    }
}

impl<T: bytemuck::Pod> Deref for Column<T> {
    type Target = [T];
    fn deref(&self) -> &[T] {
        &self.all()[self.start..self.start + self.len]
    }
}

impl<'a, T: bytemuck::Pod> IntoIterator for &'a Column<T> {
    type Item = &'a T;
    type IntoIter = std::slice::Iter<'a, T>;
    fn into_iter(self) -> Self::IntoIter {
        self.iter()
    }
}

impl<T: bytemuck::Pod> Clone for Column<T> {
    fn clone(&self) -> Self {
        Self { store: self.store.clone(), start: self.start, len: self.len }
    }
}

impl<T: bytemuck::Pod + std::fmt::Debug> std::fmt::Debug for Column<T> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_list().entries(self.iter()).finish()
    }
}

impl<T: bytemuck::Pod + PartialEq> PartialEq for Column<T> {
    fn eq(&self, other: &Self) -> bool {
        self[..] == other[..]
    }
}

impl<T: bytemuck::Pod> Default for Column<T> {
    fn default() -> Self {
        Vec::new().into()
    }
}

impl<T: bytemuck::Pod> From<Vec<T>> for Column<T> {
    /// A heap column outside the readers' budget (built in memory by the caller).
    fn from(v: Vec<T>) -> Self {
        let len = v.len();
        Self { store: Arc::new(Store::Heap(v, Reservation::default())), start: 0, len }
    }
}

impl<T: bytemuck::Pod> From<&[T]> for Column<T> {
    fn from(v: &[T]) -> Self {
        v.to_vec().into()
    }
}

impl<T: bytemuck::Pod> FromIterator<T> for Column<T> {
    fn from_iter<I: IntoIterator<Item = T>>(iter: I) -> Self {
        iter.into_iter().collect::<Vec<T>>().into()
    }
}

/// Builds a column sample by sample, on the heap within the budget, else in a spill file.
#[derive(Debug)]
pub struct ColumnBuilder<T> {
    heap: Vec<T>,
    reserved: Reservation,
    /// The spill file and the samples written to it.
    spill: Option<(std::fs::File, usize)>,
    /// Spilling failed: the samples stay on the heap past the budget.
    no_spill: bool,
    /// Samples written to the spill could not be read back: `finish` fails with this.
    lost: Option<std::io::Error>,
    budget: usize,
}

/// Bytes a spilling builder gathers before writing them.
const CHUNK_BYTES: usize = 1 << 18;

impl<T: bytemuck::Pod + Send + Sync> Default for ColumnBuilder<T> {
    fn default() -> Self {
        Self::with_budget(heap_budget_bytes())
    }
}

impl<T: bytemuck::Pod + Send + Sync> ColumnBuilder<T> {
    /// A builder against the process's heap budget.
    pub fn new() -> Self {
        Self::default()
    }

    /// A builder that spills once the reader-built columns would pass `budget` bytes
    /// (0: from the first sample).
    pub fn with_budget(budget: usize) -> Self {
        Self { heap: Vec::new(), reserved: Reservation::default(), spill: None, no_spill: false, lost: None, budget }
    }

    /// Appends a sample.
    #[inline]
    pub fn push(&mut self, v: T) {
        if self.heap.len() == self.heap.capacity() {
            self.make_room();
        }
        self.heap.push(v);
    }

    /// Samples so far.
    pub fn len(&self) -> usize {
        self.heap.len() + self.spill.as_ref().map_or(0, |s| s.1)
    }

    /// True before the first sample.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Room for at least one more sample: the heap doubled within the budget, or the spill.
    #[cold]
    fn make_room(&mut self) {
        let size = std::mem::size_of::<T>().max(1);
        let cap_bytes = self.heap.capacity() * size;
        if self.spill.is_none() && !self.no_spill {
            let want = (2 * cap_bytes).max(STEP_BYTES);
            if self.reserved.grow(want.saturating_sub(self.reserved.0), self.budget) {
                self.heap.reserve_exact(want / size - self.heap.len());
                return;
            }
            match tempfile::tempfile() {
                Ok(f) => self.spill = Some((f, 0)),
                Err(_) => self.no_spill = true,
            }
        }
        if let Some((file, written)) = &mut self.spill {
            match file.write_all(bytemuck::cast_slice(&self.heap)) {
                Ok(()) => {
                    *written += self.heap.len();
                    self.heap = Vec::with_capacity(CHUNK_BYTES / size);
                    self.reserved = Reservation::default();
                    return;
                }
                Err(_) => self.back_to_heap(),
            }
        }
        // Without a spill file the column grows on the heap past the budget (correct
        // numbers, unbounded memory) rather than failing the read.
        self.heap.reserve(self.heap.len().max(CHUNK_BYTES / size));
    }

    /// A spill that failed: its samples come back to the heap, before the ones held there.
    fn back_to_heap(&mut self) {
        self.no_spill = true;
        let Some((mut file, written)) = self.spill.take() else { return };
        let mut bytes = Vec::new();
        match file.rewind().and_then(|()| file.read_to_end(&mut bytes)) {
            Ok(_) if bytes.len() >= written * std::mem::size_of::<T>() => {
                let mut all: Vec<T> = bytemuck::pod_collect_to_vec(&bytes[..written * std::mem::size_of::<T>()]);
                all.append(&mut self.heap);
                self.heap = all;
            }
            Ok(_) => self.lost = Some(std::io::Error::other("the spill file came back short")),
            Err(e) => self.lost = Some(e),
        }
    }

    /// The column: on the heap, or the spill file mapped. Errors when samples written to
    /// the spill could not be read back or the file could not be mapped.
    pub fn finish(mut self) -> std::io::Result<Column<T>> {
        if let Some(e) = self.lost.take() {
            return Err(e);
        }
        match self.spill.take() {
            None => {
                // The heap grew by doubling: give back the room beyond the samples, to the
                // allocator and to the budget (the next columns read may need it).
                self.heap.shrink_to_fit();
                self.reserved.shrink_to(self.heap.capacity() * std::mem::size_of::<T>());
                let len = self.heap.len();
                let store = Store::Heap(std::mem::take(&mut self.heap), std::mem::take(&mut self.reserved));
                Ok(Column { store: Arc::new(store), start: 0, len })
            }
            Some((file, written)) => {
                let len = written + self.heap.len();
                if len == 0 {
                    return Ok(Column::default());
                }
                mapped(file, &self.heap, len)
            }
        }
    }
}

/// The column of a spill file's first `len` samples, `tail` written at its end first: the
/// file mapped read-only and watched by the governor.
fn mapped<T: bytemuck::Pod + Send + Sync + 'static>(
    mut file: std::fs::File,
    tail: &[T],
    len: usize,
) -> std::io::Result<Column<T>> {
    file.write_all(bytemuck::cast_slice(tail))?;
    let store = Arc::new(Store::Mapped(map_file(&file)?));
    governor::watch(&store);
    Ok(Column { store, start: 0, len })
}

/// Maps a finished spill file read-only.
#[allow(unsafe_code)]
fn map_file(file: &std::fs::File) -> std::io::Result<memmap2::Mmap> {
    // SAFETY: the file is this process's own unnamed temporary file (no other process can
    // open it), written completely before this call and never written again: the mapping's
    // bytes cannot change under the slices handed out.
    unsafe { memmap2::Mmap::map(file) }
}

/// The thread that hands mapped pages back to the page cache.
mod governor {
    use super::*;

    /// Something whose resident pages can be handed back.
    pub(super) trait Release: Send + Sync {
        fn release(&self);
    }

    impl<T: Send + Sync> Release for Store<T> {
        #[allow(unsafe_code)]
        fn release(&self) {
            #[cfg(unix)]
            if let Store::Mapped(m) = self {
                // SAFETY: a read-only shared mapping of a file: MADV_DONTNEED drops the
                // page-table entries, not the data; the next read maps the same bytes
                // from the page cache again. A failure leaves the pages resident.
                let _ = unsafe { m.unchecked_advise(memmap2::UncheckedAdvice::DontNeed) };
            }
        }
    }

    /// The mapped stores alive (weakly held: a dropped column is not kept).
    static WATCHED: Mutex<Vec<Weak<dyn Release>>> = Mutex::new(Vec::new());

    /// Watches a newly mapped store, starting the governor if it is not running.
    pub(super) fn watch<T: Send + Sync + 'static>(store: &Arc<Store<T>>) {
        let weak: Weak<dyn Release> = Arc::downgrade(store) as Weak<dyn Release>;
        let Ok(mut w) = WATCHED.lock() else { return };
        let start = w.is_empty();
        w.push(weak);
        if start {
            // When the thread cannot be started the pages stay resident (as on the heap).
            let _ = std::thread::Builder::new().name("crosscal-spill".into()).spawn(run);
        }
    }

    /// The process's file-backed resident bytes (the third field of `/proc/self/statm`, in
    /// pages), read from a handle kept open: a look is one `pread`, no allocation.
    struct Statm {
        file: Option<std::fs::File>,
        page: usize,
        buf: [u8; 128],
    }

    impl Statm {
        fn open() -> Self {
            Statm {
                file: std::fs::File::open("/proc/self/statm").ok(),
                page: rustix::param::page_size(),
                buf: [0; 128],
            }
        }

        fn shared_bytes(&mut self) -> Option<usize> {
            #[cfg(unix)]
            {
                use std::os::unix::fs::FileExt;
                let len = self.file.as_ref()?.read_at(&mut self.buf, 0).ok()?;
                let text = std::str::from_utf8(&self.buf[..len]).ok()?;
                text.split_whitespace().nth(2)?.parse::<usize>().ok().map(|pages| pages * self.page)
            }
            #[cfg(not(unix))]
            {
                None
            }
        }
    }

    /// Every [`RELEASE_EVERY`], hands back the pages of every mapped store alive when the
    /// process's file-backed resident pages have grown more than [`MAPPED_RESIDENT_BYTES`]
    /// past what they were when it started (the binary's and libraries' pages); stops when
    /// no store is left (the next mapping starts it again).
    fn run() {
        let mut statm = Statm::open();
        let base = statm.shared_bytes();
        loop {
            std::thread::sleep(RELEASE_EVERY);
            // Without /proc the pages are handed back at every tick.
            let over = match (base, statm.shared_bytes()) {
                (Some(b), Some(now)) => now > b + MAPPED_RESIDENT_BYTES,
                _ => true,
            };
            let alive: Vec<Arc<dyn Release>> = {
                let Ok(mut w) = WATCHED.lock() else { return };
                w.retain(|s| s.strong_count() > 0);
                if w.is_empty() {
                    return;
                }
                if !over {
                    continue;
                }
                w.iter().filter_map(Weak::upgrade).collect()
            };
            for s in &alive {
                s.release();
            }
        }
    }
}

#[cfg(test)]
// Bit-for-bit equality is what these tests check.
#[allow(clippy::float_cmp)]
mod tests {
    use super::*;

    fn built(budget: usize, n: usize) -> Column<[f64; 3]> {
        let mut b = ColumnBuilder::with_budget(budget);
        for k in 0..n {
            b.push([k as f64, -(k as f64), 0.5 * k as f64]);
        }
        b.finish().unwrap()
    }

    #[test]
    fn a_spilled_column_reads_back_bit_for_bit_and_slices_share_it() {
        let n = 200_000;
        let mapped = built(0, n);
        let heap = built(usize::MAX, n);
        assert!(mapped.is_mapped() && !heap.is_mapped());
        assert_eq!(mapped.len(), n);
        assert_eq!(mapped, heap);
        assert_eq!(mapped[123_456], [123_456.0, -123_456.0, 61_728.0]);
        let part = mapped.slice(10, 20);
        assert_eq!(part.len(), 10);
        assert_eq!(part[0], mapped[10]);
        assert!(part.same_as(&mapped.slice(10, 20)) && !part.same_as(&mapped.slice(10, 21)));
        // The governor's release leaves the samples as they were.
        mapped.store.release_now();
        assert_eq!(mapped, heap);
        // A heap column (or a part of one) moved to a spill file reads the same.
        let moved = heap.spilled().unwrap();
        assert!(moved.is_mapped() && moved == heap && !moved.same_as(&heap));
        let part = heap.slice(1000, 1010).spilled().unwrap();
        assert!(part.is_mapped() && part.len() == 10 && part[0] == heap[1000]);
        assert!(mapped.spilled().unwrap().same_as(&mapped));
    }

    #[test]
    fn a_builder_spills_when_the_budget_is_spent_and_returns_its_reservation() {
        let before = HEAP_BYTES.load(Ordering::Relaxed);
        // Within two steps of budget above what other tests hold now: the first step fits.
        let small = built(before + STEP_BYTES, 1000);
        assert!(!small.is_mapped());
        // A finished heap column holds the budget for its samples only.
        assert!(matches!(&*small.store, Store::Heap(v, r) if v.capacity() == 1000 && r.0 == 1000 * 24));
        let big = built(before + STEP_BYTES, 2 * STEP_BYTES / 24);
        assert!(big.is_mapped());
        assert_eq!(big[big.len() - 1][0], (big.len() - 1) as f64);
        assert!(ColumnBuilder::<f64>::with_budget(0).finish().unwrap().is_empty());
        drop(small);
    }

    impl<T: Send + Sync> Store<T> {
        fn release_now(&self) {
            governor::Release::release(self);
        }
    }
}
