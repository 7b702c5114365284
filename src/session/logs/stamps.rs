//! Isolated outlying time stamps, found and dropped between a reader and its sink.
//!
//! One corrupt stamp (a `header.stamp.sec` off by 100 000 s, a bag time from another day)
//! used to take the whole stream with it: every later sample lay before the outlier and
//! "did not advance". Each stream's samples pass through a short look-ahead ([`AHEAD`]
//! samples, fixed memory); a sample is an *isolated outlier*, dropped and counted, when
//!
//! - it lies after most of the samples that follow it, while those follow the last sample
//!   kept (a jump forward and back), or
//! - it lies before the last sample kept while most of the samples that follow it lie after
//!   that one (a jump back and forward), or
//! - at either end of the stream, where there is no neighbour on one side, it is separated
//!   from its neighbours by more than [`END_GAP_FACTOR`] × their spacing and at least
//!   [`END_GAP_MIN_NS`].
//!
//! A lasting change (a clock that restarts) is not isolated: those samples pass, and the
//! session writer drops what does not advance, as before. Every drop is counted per stream
//! and reported in [`super::Contents::warnings`].

use super::LogSample;
use std::collections::VecDeque;

/// Samples looked at after the one being judged.
pub const AHEAD: usize = 4;
/// An end sample this many spacings from its neighbours is an outlier …
pub const END_GAP_FACTOR: i64 = 1000;
/// … when that is also at least this far (10 s).
pub const END_GAP_MIN_NS: i64 = 10_000_000_000;

/// Where the samples judged good go.
pub type Out<'a, E> = dyn FnMut(usize, &LogSample) -> Result<(), E> + 'a;

/// One stream's look-ahead.
#[derive(Debug, Default)]
struct Lane {
    q: VecDeque<LogSample>,
    last_kept: Option<i64>,
    /// Last spacing between two kept samples, ns (for the end rule).
    spacing: i64,
    dropped: u64,
    first_dropped: Option<i64>,
    seen: u64,
}

/// The look-ahead of every stream of a pass.
#[derive(Debug, Default)]
pub struct Deglitch {
    lanes: Vec<Lane>,
}

impl Deglitch {
    /// Takes a sample of stream `idx`; hands on (to `out`) the samples now judged good.
    pub fn push<E>(&mut self, idx: usize, s: &LogSample, out: &mut Out<'_, E>) -> Result<(), E> {
        if self.lanes.len() <= idx {
            self.lanes.resize_with(idx + 1, Lane::default);
        }
        let lane = &mut self.lanes[idx];
        lane.seen += 1;
        lane.q.push_back(*s);
        while lane.q.len() > AHEAD {
            lane.judge_front(false, idx, out)?;
        }
        Ok(())
    }

    /// Judges what is left at the end of the pass.
    pub fn finish<E>(&mut self, out: &mut Out<'_, E>) -> Result<(), E> {
        for (idx, lane) in self.lanes.iter_mut().enumerate() {
            while !lane.q.is_empty() {
                lane.judge_front(true, idx, out)?;
            }
        }
        Ok(())
    }

    /// Samples met per stream (before any drop), by stream index.
    pub fn seen(&self) -> Vec<u64> {
        self.lanes.iter().map(|l| l.seen).collect()
    }

    /// Per stream: (samples dropped, the time of the first one, ns), for streams with drops.
    pub fn dropped(&self) -> impl Iterator<Item = (usize, u64, u64, i64)> + '_ {
        self.lanes
            .iter()
            .enumerate()
            .filter(|(_, l)| l.dropped > 0)
            .map(|(i, l)| (i, l.dropped, l.seen, l.first_dropped.unwrap_or(0)))
    }
}

impl Lane {
    fn judge_front<E>(&mut self, end: bool, idx: usize, out: &mut Out<'_, E>) -> Result<(), E> {
        let Some(s) = self.q.pop_front() else { return Ok(()) };
        if self.is_outlier(s.t_ns, end) {
            self.dropped += 1;
            self.first_dropped.get_or_insert(s.t_ns);
            return Ok(());
        }
        if let Some(p) = self.last_kept {
            if s.t_ns > p {
                self.spacing = s.t_ns.saturating_sub(p);
            }
        }
        self.last_kept = Some(self.last_kept.map_or(s.t_ns, |p| p.max(s.t_ns)));
        out(idx, &s)
    }

    fn is_outlier(&self, t: i64, end: bool) -> bool {
        let ahead: Vec<i64> = self.q.iter().map(|s| s.t_ns).collect();
        let after_prev = |n: i64| self.last_kept.is_none_or(|p| n > p);
        if !ahead.is_empty() {
            let behind = ahead.iter().filter(|&&n| n < t && after_prev(n)).count();
            if 2 * behind > ahead.len() {
                return true;
            }
            if let Some(p) = self.last_kept {
                let past = ahead.iter().filter(|&&n| n > p).count();
                if t < p && 2 * past > ahead.len() {
                    return true;
                }
            }
        }
        let far = |gap: i64, spacing: i64| spacing > 0 && gap > END_GAP_MIN_NS && gap / spacing.max(1) > END_GAP_FACTOR;
        // The first sample: far before the ones that follow (which are close together).
        if self.last_kept.is_none() && self.dropped == 0 && ahead.len() >= 2 {
            return far(ahead[0].saturating_sub(t), ahead[1].saturating_sub(ahead[0]));
        }
        // The last sample: far from the last one kept.
        if end && ahead.is_empty() {
            if let Some(p) = self.last_kept {
                return far(t.saturating_sub(p).saturating_abs(), self.spacing);
            }
        }
        false
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn run(ts: &[i64]) -> (Vec<i64>, u64) {
        let mut d = Deglitch::default();
        let mut kept = Vec::new();
        let mut out = |_: usize, s: &LogSample| -> Result<(), ()> {
            kept.push(s.t_ns);
            Ok(())
        };
        for &t in ts {
            let s = LogSample { t_ns: t, gyro_rad_s: [0.0; 3], accel_m_s2: [0.0; 3], temp_c: None };
            d.push(0, &s, &mut out).unwrap();
        }
        d.finish(&mut out).unwrap();
        let dropped = d.dropped().map(|x| x.1).sum();
        (kept, dropped)
    }

    const S: i64 = 100_000_000; // 10 Hz

    #[test]
    fn isolated_outliers_go_and_the_rest_stays() {
        let base: Vec<i64> = (0..50).map(|i| 1_600_000_000_000_000_000 + i * S).collect();
        for at in [0, 1, 25, 48, 49] {
            for jump in [100_000 * 1_000_000_000i64, -100_000 * 1_000_000_000] {
                let mut ts = base.clone();
                ts[at] += jump;
                let (kept, dropped) = run(&ts);
                assert_eq!(dropped, 1, "at {at}, jump {jump}");
                let mut want = base.clone();
                want.remove(at);
                assert_eq!(kept, want, "at {at}, jump {jump}");
            }
        }
        // Intact, with a real 5 s gap and a duplicate: nothing dropped here.
        let mut ts = base.clone();
        for t in &mut ts[30..] {
            *t += 5_000_000_000;
        }
        ts[10] = ts[9];
        assert_eq!(run(&ts), (ts.clone(), 0));
        // A clock that restarts is not isolated: every sample is handed on.
        let ts: Vec<i64> = (0..20).map(|i| (i % 10) * S).collect();
        assert_eq!(run(&ts).1, 0);
    }
}
