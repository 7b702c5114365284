//! Signal sanity, checked as the samples are read (one scanner, [`StreamScan`], for every
//! reader): gaps in t, saturation (flat tops at the channel's extreme) and spikes (isolated
//! samples far from their neighbours), reported with their sample positions and times.

use crate::stats::{median, MAD_TO_SIGMA};
use crate::units::CHANNELS;

/// Consecutive samples at the channel's extreme that count as a flat top.
pub const SATURATION_RUN: usize = 5;
/// Robust z-score above which a sample is a spike.
pub const SPIKE_Z: f64 = 12.0;

/// What the scan found in one channel.
#[derive(Debug, Clone, PartialEq)]
pub enum Finding {
    /// Flat runs at the channel's maximum or minimum.
    Saturation {
        /// Channel name.
        channel: &'static str,
        /// The clipped value (as recorded, SI-converted).
        value: f64,
        /// Samples at that value in flat runs.
        samples: usize,
        /// Index of the first flat sample (0-based).
        first: usize,
    },
    /// Isolated outliers.
    Spikes {
        /// Channel name.
        channel: &'static str,
        /// Indices (0-based) of the first few spikes.
        at: Vec<usize>,
        /// Total number.
        count: usize,
    },
}

/// Human-readable lines for findings, naming sample numbers and the time of sample k
/// (0-based) from `time_of`.
fn describe_with(findings: &[Finding], time_of: &dyn Fn(usize) -> f64, file: &str) -> Vec<String> {
    findings
        .iter()
        .map(|f| match f {
            Finding::Saturation {
                channel,
                value,
                samples,
                first,
            } => format!(
                "{file}: channel {channel} looks saturated: {samples} samples flat at its extreme {value:e} (SI), first at sample {} (t = {} s); the fit will be biased there",
                first + 1,
                time_of(*first)
            ),
            Finding::Spikes { channel, at, count } => format!(
                "{file}: channel {channel} has {count} spike(s) (more than {SPIKE_Z} robust σ from their neighbours), at samples {}; consider --robust",
                at.iter().map(|k| format!("{} (t = {} s)", k + 1, time_of(*k))).collect::<Vec<_>>().join(", ")
            ),
        })
        .collect()
}

/// Samples whose steps and second differences set the reference of a [`StreamScan`].
pub const STREAM_REFERENCE: usize = 4096;

/// Spikes reported by position (as [`scan`]: the first ten).
const SPIKES_LISTED: usize = 10;

/// A gap in t found by a [`StreamScan`].
#[derive(Debug, Clone, PartialEq)]
pub struct StreamGap {
    /// 0-based index of the sample after the gap.
    pub sample: usize,
    /// Its line in the file.
    pub line: u64,
    /// The message.
    pub message: String,
}

impl StreamGap {
    /// The error this gap is in strict mode (`t_column`: 1-based column of t).
    pub fn to_error(&self, path: &std::path::Path, t_column: usize) -> super::SessionError {
        super::SessionError::Csv {
            problem: super::Problem::Gap,
            path: path.to_path_buf(),
            line: self.line,
            column: format!("{t_column} (t)"),
            msg: format!(
                "{}; expected a gap of at most 5 sample periods (strict mode; without --strict gaps are warnings)",
                self.message
            ),
        }
    }
}

/// Flat runs at one running extreme of a channel: exact for the record's final extreme,
/// since its value cannot occur before it is first reached.
#[derive(Debug, Clone, Copy)]
struct Flat {
    value: f64,
    run: usize,
    samples: usize,
    first: Option<usize>,
    /// The stamp of sample `first`.
    first_t: f64,
}

impl Flat {
    fn new(value: f64) -> Self {
        Self { value, run: 0, samples: 0, first: None, first_t: f64::NAN }
    }

    /// Sample k with value v; `beyond` says v is a new extreme.
    #[allow(clippy::float_cmp)]
    #[inline]
    fn push(&mut self, k: usize, v: f64, beyond: bool) {
        if beyond {
            *self = Self::new(v);
        }
        if v == self.value {
            self.run += 1;
            if self.run == SATURATION_RUN {
                self.samples += SATURATION_RUN;
                self.first.get_or_insert(k + 1 - SATURATION_RUN);
            } else if self.run > SATURATION_RUN {
                self.samples += 1;
            }
        } else {
            self.run = 0;
        }
    }
}

/// One channel's spike detector: second differences judged against the median and MAD of
/// the first [`STREAM_REFERENCE`] of them, reported at local maxima (one sample later).
#[derive(Debug, Clone)]
struct SpikeWatch {
    /// The first second differences, until the reference is set.
    held: Vec<f64>,
    centre: f64,
    scale: Option<f64>,
    /// |d2 − centre| of the last two second differences seen by the detector.
    prev: [f64; 2],
    /// Values seen (the newest's index + 1; a decided middle value's sample index).
    seen: usize,
    count: usize,
    at: Vec<usize>,
}

impl SpikeWatch {
    fn new() -> Self {
        Self {
            held: Vec::with_capacity(STREAM_REFERENCE),
            centre: 0.0,
            scale: None,
            prev: [0.0; 2],
            seen: 0,
            count: 0,
            at: Vec::new(),
        }
    }

    /// The second difference centred on sample `j + 1`; `range` is the channel's range so far.
    #[inline]
    fn push(&mut self, d2: f64, range: f64) {
        match self.scale {
            Some(_) => self.judge(d2, range),
            None => {
                self.held.push(d2);
                if self.held.len() == STREAM_REFERENCE {
                    self.set_reference(range);
                }
            }
        }
    }

    fn set_reference(&mut self, range: f64) {
        let mut tmp = self.held.clone();
        self.centre = median(&mut tmp).unwrap_or(0.0);
        for v in tmp.iter_mut() {
            *v = (*v - self.centre).abs();
        }
        self.scale = Some(MAD_TO_SIGMA * median(&mut tmp).unwrap_or(0.0));
        for d2 in std::mem::take(&mut self.held) {
            self.judge(d2, range);
        }
    }

    /// Feeds the detector; decides about the previous value now that its right neighbour is
    /// known (`None`: the record ended).
    #[inline]
    fn judge_value(&mut self, v: Option<f64>, range: f64) {
        let limit = (SPIKE_Z * self.scale.unwrap_or(0.0)).max(1e-6 * range.max(f64::MIN_POSITIVE));
        if self.seen > 0 {
            let (left, mid) = (if self.seen > 1 { self.prev[0] } else { 0.0 }, self.prev[1]);
            let right = v.unwrap_or(0.0);
            if mid > limit && mid >= left && mid >= right {
                self.record();
            }
        }
        if let Some(v) = v {
            self.prev = [self.prev[1], v];
            self.seen += 1;
        }
    }

    /// Counts a spike at the detector's middle value (sample `seen`).
    #[cold]
    fn record(&mut self) {
        self.count += 1;
        if self.at.len() < SPIKES_LISTED {
            self.at.push(self.seen);
        }
    }

    #[inline]
    fn judge(&mut self, d2: f64, range: f64) {
        self.judge_value(Some((d2 - self.centre).abs()), range);
    }

    fn finish(&mut self, range: f64) {
        if self.scale.is_none() && !self.held.is_empty() {
            self.set_reference(range);
        }
        self.judge_value(None, range);
    }
}

/// The checks of a recording read as a stream, in fixed memory (what a unit could do as the
/// samples arrive): gaps in t of more than 5 times the median step of the first
/// [`STREAM_REFERENCE`] steps (of all of them in shorter records, as the whole-record
/// reader); saturation (flat runs at the record's extremes); spikes
/// against the median and MAD of the first [`STREAM_REFERENCE`] second differences and the
/// range seen so far.
#[derive(Debug, Clone)]
pub struct StreamScan {
    time_unit_s: f64,
    n: usize,
    /// Stamps of the first samples (those the reference phase may name).
    first_times: Vec<f64>,
    /// The last [`TIME_RING`] samples' stamps (for the times of findings).
    times: Box<[f64; TIME_RING]>,
    /// Samples not yet through the channel checks, by channel.
    cols: Box<[[f64; SCAN_BLOCK]; 6]>,
    /// Samples in `cols`.
    fill: usize,
    /// Samples through the channel checks.
    done: usize,
    /// Times of the spikes listed and of the flat tops found (sample index, t): at most ten
    /// spikes and one flat top per channel.
    named: Vec<(usize, f64)>,
    /// Steps held until the reference step is set: (sample after the step, line, step, t).
    steps: Vec<(usize, u64, f64, f64)>,
    median_step: Option<f64>,
    gaps: Vec<StreamGap>,
    gaps_total: usize,
    last: [[f64; 2]; 6],
    lo: [Flat; 6],
    hi: [Flat; 6],
    spikes: [SpikeWatch; 6],
}

/// Gaps listed by position.
const GAPS_LISTED: usize = 20;
/// Samples checked a channel at a time (a block's loop keeps its state in registers).
const SCAN_BLOCK: usize = 256;
/// Stamps remembered (a block and the few before it that a finding may name).
const TIME_RING: usize = 512;

impl StreamScan {
    /// A scan before the first sample; `time_unit_s`: seconds per unit of the file's t (gap
    /// messages speak the file's unit).
    pub fn new(time_unit_s: f64) -> Self {
        Self {
            time_unit_s,
            n: 0,
            first_times: Vec::with_capacity(STREAM_REFERENCE + 8),
            times: Box::new([f64::NAN; TIME_RING]),
            cols: Box::new([[0.0; SCAN_BLOCK]; 6]),
            fill: 0,
            done: 0,
            named: Vec::new(),
            steps: Vec::with_capacity(STREAM_REFERENCE),
            median_step: None,
            gaps: Vec::new(),
            gaps_total: 0,
            last: [[0.0; 2]; 6],
            lo: [Flat::new(f64::INFINITY); 6],
            hi: [Flat::new(f64::NEG_INFINITY); 6],
            spikes: std::array::from_fn(|_| SpikeWatch::new()),
        }
    }

    /// The next sample (SI), read from line `line` of the file; returns a gap found now, if
    /// any (listed ones only, in order: the held first steps are judged when the reference is
    /// set).
    pub fn push(&mut self, line: u64, t_s: f64, gyro: [f64; 3], accel: [f64; 3]) -> Option<&StreamGap> {
        let k = self.n;
        let before = self.gaps.len();
        if k > 0 {
            let step = t_s - self.times[(k - 1) % TIME_RING];
            match self.median_step {
                Some(m) => self.judge_step(k, line, step, t_s, m),
                None => {
                    self.steps.push((k, line, step, t_s));
                    if self.steps.len() == STREAM_REFERENCE {
                        self.set_step();
                    }
                }
            }
        }
        self.times[k % TIME_RING] = t_s;
        if self.first_times.len() < self.first_times.capacity() {
            self.first_times.push(t_s);
        }
        for c in 0..3 {
            self.cols[c][self.fill] = gyro[c];
            self.cols[c + 3][self.fill] = accel[c];
        }
        self.fill += 1;
        self.n += 1;
        if self.fill == SCAN_BLOCK {
            self.channels();
        }
        self.gaps[before..].first()
    }

    /// Saturation and spike checks of the samples in `cols`, a channel at a time.
    fn channels(&mut self) {
        let n = self.fill;
        let start = self.done;
        for c in 0..6 {
            let listed = self.spikes[c].at.len();
            let (mut hi, mut lo) = (self.hi[c], self.lo[c]);
            let firsts = (hi.first, lo.first);
            let [mut x0, mut x1] = self.last[c];
            let col = &self.cols[c][..n];
            let w = &mut self.spikes[c];
            match w.scale {
                // The detector's reference is set and it has two values: its state stays in
                // registers for the block.
                Some(scale) if w.seen > 1 && start >= 2 => {
                    let (z, centre) = (SPIKE_Z * scale, w.centre);
                    let ([mut left, mut mid], mut seen) = (w.prev, w.seen);
                    for (i, &v) in col.iter().enumerate() {
                        hi.push(start + i, v, v > hi.value);
                        lo.push(start + i, v, v < lo.value);
                        let value = (x0 - 2.0 * x1 + v - centre).abs();
                        let limit = z.max(1e-6 * (hi.value - lo.value).max(f64::MIN_POSITIVE));
                        if mid > limit && mid >= left && mid >= value {
                            w.seen = seen;
                            w.record();
                        }
                        (left, mid, seen) = (mid, value, seen + 1);
                        (x0, x1) = (x1, v);
                    }
                    (w.prev, w.seen) = ([left, mid], seen);
                }
                _ => {
                    for (i, &v) in col.iter().enumerate() {
                        hi.push(start + i, v, v > hi.value);
                        lo.push(start + i, v, v < lo.value);
                        if start + i >= 2 {
                            w.push(x0 - 2.0 * x1 + v, hi.value - lo.value);
                        }
                        (x0, x1) = (x1, v);
                    }
                }
            }
            // A flat run's first sample is at most four samples before the block.
            for (f, before) in [(&mut hi, firsts.0), (&mut lo, firsts.1)] {
                if let Some(first) = f.first.filter(|_| f.first != before) {
                    f.first_t = self.time_at(first);
                }
            }
            (self.hi[c], self.lo[c], self.last[c]) = (hi, lo, [x0, x1]);
            if self.spikes[c].at.len() > listed {
                self.name_spikes(c, listed);
            }
        }
        self.done += n;
        self.fill = 0;
    }

    /// Stamp of sample k if it is one of the first or one of the last [`TIME_RING`].
    fn time_at(&self, k: usize) -> f64 {
        match self.first_times.get(k) {
            Some(t) => *t,
            None if k + TIME_RING > self.n => self.times[k % TIME_RING],
            None => f64::NAN,
        }
    }

    /// Records the times of channel c's spikes listed after the first `listed`.
    fn name_spikes(&mut self, c: usize, listed: usize) {
        for i in listed..self.spikes[c].at.len() {
            let j = self.spikes[c].at[i];
            let t = self.time_at(j);
            self.named.push((j, t));
        }
    }

    fn set_step(&mut self) {
        let mut v: Vec<f64> = self.steps.iter().map(|s| s.2).collect();
        let m = median(&mut v).unwrap_or(0.0);
        self.median_step = Some(m);
        for (k, line, step, t) in std::mem::take(&mut self.steps) {
            self.judge_step(k, line, step, t, m);
        }
    }

    fn judge_step(&mut self, k: usize, line: u64, step: f64, t_s: f64, median: f64) {
        if step > 5.0 * median {
            self.gaps_total += 1;
            if self.gaps.len() < GAPS_LISTED {
                self.gaps.push(StreamGap {
                    sample: k,
                    line,
                    message: format!(
                        "gap in t of {} before sample {} (t = {}): {:.1} median sample periods",
                        step / self.time_unit_s,
                        k + 1,
                        t_s / self.time_unit_s,
                        step / median
                    ),
                });
            }
        }
    }

    /// Ends the record: the gaps (in order) and the warnings, each message prefixed with
    /// `file`.
    pub fn finish(mut self, file: &str) -> (Vec<StreamGap>, Vec<String>) {
        self.channels();
        if self.median_step.is_none() && self.steps.len() >= 2 {
            self.set_step();
        }
        let mut findings = Vec::new();
        for c in 0..6 {
            let range = self.hi[c].value - self.lo[c].value;
            if self.n >= 7 {
                let listed = self.spikes[c].at.len();
                self.spikes[c].finish(range);
                self.name_spikes(c, listed);
            }
            let name = CHANNELS[c];
            if self.n >= SATURATION_RUN && range > 0.0 {
                if let Some((f, first)) = [self.hi[c], self.lo[c]].into_iter().find_map(|f| f.first.map(|k| (f, k))) {
                    self.named.push((first, f.first_t));
                    findings.push(Finding::Saturation { channel: name, value: f.value, samples: f.samples, first });
                }
            }
            let w = &self.spikes[c];
            if self.n >= 7 && w.count > 0 {
                findings.push(Finding::Spikes { channel: name, at: w.at.clone(), count: w.count });
            }
        }
        let named = self.named;
        let time_of = |k: usize| named.iter().rev().find(|(j, _)| *j == k).map_or(f64::NAN, |(_, t)| *t);
        let mut warnings: Vec<String> = self.gaps.iter().map(|g| format!("{file}: {}", g.message)).collect();
        if self.gaps_total > self.gaps.len() {
            warnings.push(format!("{file}: further gaps not listed"));
        }
        warnings.extend(describe_with(&findings, &time_of, file));
        (self.gaps, warnings)
    }
}

/// The findings of a [`StreamScan`] over a record in memory (SI stamps), each prefixed
/// with `file`.
pub fn scan_record(t_s: &[f64], gyro: &[[f64; 3]], accel: &[[f64; 3]], file: &str) -> Vec<String> {
    let mut scan = StreamScan::new(1.0);
    for (k, ((&t, g), a)) in t_s.iter().zip(gyro).zip(accel).enumerate() {
        scan.push(k as u64 + 2, t, *g, *a);
    }
    scan.finish(file).1
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sine(n: usize, noise: bool) -> Vec<[f64; 3]> {
        (0..n)
            .map(|k| {
                let t = k as f64 * 0.01;
                // Pseudo-random noise (an LCG), uniform in ±0.5e-3.
                let e = if noise {
                    1e-3 * ((((k as u64 + 1).wrapping_mul(6364136223846793005)) >> 40) as f64 / (1u64 << 24) as f64
                        - 0.5)
                } else {
                    0.0
                };
                [t.sin() + e, (0.5 * t).cos() + e, 0.3]
            })
            .collect()
    }

    fn stream(g: &[[f64; 3]], a: &[[f64; 3]], t: &[f64]) -> (Vec<StreamGap>, Vec<String>) {
        let mut s = StreamScan::new(1.0);
        for k in 0..t.len() {
            s.push(k as u64 + 2, t[k], g[k], a[k]);
        }
        s.finish("f.csv")
    }

    #[test]
    fn clean_signals_raise_nothing() {
        let t: Vec<f64> = (0..3000).map(|k| k as f64 * 0.01).collect();
        for noise in [false, true] {
            let g = sine(3000, noise);
            let (gaps, warnings) = stream(&g, &g, &t);
            assert!(gaps.is_empty() && warnings.is_empty(), "{warnings:?}");
        }
    }

    #[test]
    fn finds_clipping_and_spikes_at_the_ends_of_short_records() {
        let mut g = sine(3000, true);
        for v in g.iter_mut() {
            v[0] = v[0].min(0.9);
            v[2] = v[2].max(0.3);
        }
        g[1234][1] += 5.0;
        g[3][1] -= 4.0;
        g[2998][1] += 3.0;
        let a = sine(3000, true);
        let t: Vec<f64> = (0..3000).map(|k| k as f64 * 0.01).collect();
        let (gaps, warnings) = stream(&g, &a, &t);
        assert!(gaps.is_empty());
        let all = warnings.join("\n");
        assert!(all.contains("channel gx looks saturated"), "{all}");
        assert!(
            all.contains("channel gy has 3 spike(s)")
                && all.contains("at samples 4 (t = 0.03 s), 1235 (t = 12.34 s), 2999 (t = 29.98 s)"),
            "{all}"
        );
    }

    #[test]
    fn the_stream_scan_finds_late_spikes_clipping_and_gaps() {
        let n = 50_000;
        let mut g = sine(n, true);
        let a = sine(n, true);
        let mut t: Vec<f64> = (0..n).map(|k| k as f64 * 0.01).collect();
        // A spike among the reference samples and one long after.
        g[100][1] += 5.0;
        g[30_000][1] += 2.0;
        // Clipping at a new maximum that appears only late.
        for v in g[40_000..40_050].iter_mut() {
            v[0] = 1.5;
        }
        // A gap of 0.5 s before sample 45 000 and one in the reference steps.
        for x in t[45_000..].iter_mut() {
            *x += 0.5;
        }
        for x in t[10..].iter_mut() {
            *x += 0.2;
        }
        let (gaps, warnings) = stream(&g, &a, &t);
        assert_eq!(gaps.iter().map(|g| (g.sample, g.line)).collect::<Vec<_>>(), [(10, 12), (45_000, 45_002)]);
        let all = warnings.join("\n");
        assert!(all.contains("gap in t of 0.5"), "{all}");
        assert!(
            all.contains("channel gx looks saturated: 50 samples") && all.contains("sample 40001 (t = 400.2 s)"),
            "{all}"
        );
        // The plateau's edges are steps, reported as the whole-record scan reports them.
        assert!(all.contains("channel gx has 2 spike(s)"), "{all}");
        assert!(
            all.contains("channel gy has 2 spike(s)") && all.contains("101 (t = 1.2 s), 30001 (t = 300.2 s)"),
            "{all}"
        );
        assert_eq!(warnings.len(), 5, "{all}");
    }

    #[test]
    fn the_stream_scan_keeps_fixed_memory_on_a_rising_staircase() {
        // Every new maximum is held for six samples: a flat top at each step, but only the
        // last is the record's extreme.
        let mut s = StreamScan::new(1.0);
        let n = 120_000;
        for k in 0..n {
            let v = (k / 6) as f64 * 1e-3;
            s.push(k as u64 + 2, k as f64 * 0.01, [v, 0.1 * ((k % 7) as f64), 0.3], [0.0, 0.0, 1.0]);
        }
        assert!(s.named.len() <= 10 * 6, "{}", s.named.len());
        assert!(s.first_times.len() <= STREAM_REFERENCE + 8);
        let (_, warnings) = s.finish("f.csv");
        let top = warnings.iter().find(|w| w.contains("channel gx looks saturated")).expect("flat top");
        assert!(
            top.contains("6 samples")
                && top.contains(&format!("sample {} (t = {} s)", n - 6 + 1, (n - 6) as f64 * 0.01)),
            "{top}"
        );
    }
}
