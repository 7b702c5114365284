//! Conic runs recorded while the stand was not at its speed (spinning up from rest at the
//! start, slowing down at the end): the manifest's constant rate is then wrong for those
//! seconds, and no stand parameter of a steady stand (cone angle, rate, phase, ripple)
//! explains a misfit that sits at one end of every run — linearised, they share it out and
//! report errors the stand does not have.
//!
//! On a conic motion the magnitude of the sensor's angular rate is constant (a steady
//! stand) or nearly so (a ripple of a few per cent). Averaged over windows of
//! [`WINDOW_S`], the ratio of the gyro's output magnitude to the declared motion's tells
//! where the stand was off its speed: a stretch at either end of a run whose first (or
//! last) window departs from the run's median ratio by more than [`OFF_SPEED`], extended
//! while the departure stays beyond the windows' own scatter (5 × their robust spread, at
//! least [`SETTLED`]). The diagnosis leaves such stretches out and says so; the fit warns
//! (its coefficients carry the misfit). A stand that logs its angle (`angle_column`) has
//! nothing to leave out: its track follows the stand.

use super::FitRun;
use crate::session::MotionSpec;

/// Relative departure of a window's magnitude ratio from the run's median that marks the
/// stand off its speed at a run's end (10 %: far beyond a ripple or a scale error).
pub const OFF_SPEED: f64 = 0.1;
/// Smallest relative departure that still counts as off speed once a stretch is found.
pub const SETTLED: f64 = 0.002;
/// Averaging window, s.
pub const WINDOW_S: f64 = 0.5;
/// Fewest windows a run needs to be checked.
const MIN_WINDOWS: usize = 8;
/// Largest share of a run left out; beyond it the run is kept whole (something other than
/// a spin-up is wrong with it, and the diagnosis shows it).
const MAX_SHARE: f64 = 0.5;

/// A conic run's stretches off speed at its start and end.
#[derive(Debug, Clone, PartialEq)]
pub struct OffSpeed {
    /// Run index.
    pub run: usize,
    /// Samples left out at the start and at the end.
    pub head: usize,
    /// See `head`.
    pub tail: usize,
    /// Their durations, s.
    pub head_s: f64,
    /// See `head_s`.
    pub tail_s: f64,
}

/// The conic runs (`motions[i]` run i's declared motion) with a stretch off speed.
pub fn off_speed(runs: &[FitRun<'_>], motions: &[&MotionSpec]) -> Vec<OffSpeed> {
    runs.iter()
        .zip(motions)
        .enumerate()
        .filter(|(_, (r, m))| matches!(m, MotionSpec::Conic { .. }) && r.track.mount().is_some())
        .filter_map(|(i, (r, _))| run_off_speed(i, r))
        .collect()
}

fn run_off_speed(i: usize, r: &FitRun<'_>) -> Option<OffSpeed> {
    let n = r.len();
    let t = &r.track.t_s;
    if n < 2 {
        return None;
    }
    let dt = (t[n - 1] - t[0]) / (n - 1) as f64;
    let w = if dt > 0.0 { ((WINDOW_S / dt).round() as usize).max(1) } else { return None };
    let windows = n / w;
    if windows < MIN_WINDOWS {
        return None;
    }
    // Per window: mean |gyro| over mean |ω| of the declared motion (the last takes the rest).
    let ratio: Vec<f64> = (0..windows)
        .map(|j| {
            let (k0, k1) = (j * w, if j + 1 == windows { n } else { (j + 1) * w });
            let (mut meas, mut truth) = (0.0, 0.0);
            for k in k0..k1 {
                meas += crate::stats::norm3(r.gyro[k]);
                truth += crate::stats::norm3(r.track.at(k).w_rad_s.xyz);
            }
            if truth > 0.0 {
                meas / truth
            } else {
                f64::NAN
            }
        })
        .collect();
    let (head_w, tail_w) = stretches(&ratio)?;
    // One window more each side: the last one off settles within the next.
    let head = if head_w > 0 { ((head_w + 1) * w).min(n) } else { 0 };
    let tail = if tail_w > 0 { (n - ((windows - tail_w - 1) * w)).min(n - head) } else { 0 };
    let span = |k0: usize, k1: usize| if k1 > k0 { t[k1.min(n - 1)] - t[k0] } else { 0.0 };
    Some(OffSpeed { run: i, head, tail, head_s: span(0, head), tail_s: span(n - tail, n - 1) })
}

/// What the fit does with the seconds off speed (its warning's `done`).
pub const FIT_KEEPS: &str = "the fit uses those seconds as declared, and its coefficients carry their misfit";

/// The windows off speed at a run's start and end, from the windows' ratios of the gyro's
/// magnitude to the declared motion's: (head, tail) counts, None when there are none or
/// too many (module docs).
fn stretches(ratio: &[f64]) -> Option<(usize, usize)> {
    if ratio.len() < MIN_WINDOWS || ratio.iter().any(|x| !x.is_finite()) {
        return None;
    }
    let med = crate::stats::median(&mut ratio.to_vec())?;
    let spread = crate::stats::robust_sigma(ratio, med)?;
    if med <= 0.0 {
        return None;
    }
    let off = |x: f64, share: f64| (x - med).abs() > (share * med).max(5.0 * spread);
    // A stretch starts at a window off by OFF_SPEED and runs on while still unsettled.
    let stretch = |order: &mut dyn Iterator<Item = &f64>| -> usize {
        let mut it = order.peekable();
        if !it.peek().is_some_and(|&&x| off(x, OFF_SPEED)) {
            return 0;
        }
        it.take_while(|&&x| off(x, SETTLED)).count()
    };
    let head_w = stretch(&mut ratio.iter());
    let tail_w = stretch(&mut ratio.iter().rev());
    if head_w + tail_w == 0 || (head_w + tail_w) as f64 > MAX_SHARE * ratio.len() as f64 {
        return None;
    }
    Some((head_w, tail_w))
}

/// The same check fed one sample at a time (a fit that streams its runs): windows of
/// [`WINDOW_S`] on the run's clock, a few numbers per window.
#[derive(Debug, Clone, Default)]
pub struct SpeedWindows {
    t0_s: Option<f64>,
    /// The current window's index and sums of |gyro|, |ω| declared, and samples.
    current: usize,
    meas: f64,
    truth: f64,
    count: usize,
    /// Per finished window: its ratio and samples.
    done: Vec<(f64, usize)>,
}

impl SpeedWindows {
    /// One sample: its stamp, the gyro's output and the declared motion's rate (same units).
    pub fn push(&mut self, t_s: f64, gyro: [f64; 3], declared: [f64; 3]) {
        let t0 = *self.t0_s.get_or_insert(t_s);
        let j = ((t_s - t0) / WINDOW_S).floor();
        let j = if j.is_finite() && j >= 0.0 { j as usize } else { self.current };
        if j != self.current && self.count > 0 {
            self.close();
        }
        self.current = j;
        self.meas += crate::stats::norm3(gyro);
        self.truth += crate::stats::norm3(declared);
        self.count += 1;
    }

    fn close(&mut self) {
        let ratio = if self.truth > 0.0 { self.meas / self.truth } else { f64::NAN };
        self.done.push((ratio, self.count));
        (self.meas, self.truth, self.count) = (0.0, 0.0, 0);
    }

    /// Run `run`'s stretches off speed, when it has some.
    pub fn finish(mut self, run: usize) -> Option<OffSpeed> {
        if self.count > 0 {
            self.close();
        }
        let ratio: Vec<f64> = self.done.iter().map(|d| d.0).collect();
        let (head_w, tail_w) = stretches(&ratio)?;
        // One window more each side, as the in-memory check leaves out.
        let samples = |ws: &[(f64, usize)]| ws.iter().map(|d| d.1).sum::<usize>();
        let n = self.done.len();
        let head = if head_w > 0 { samples(&self.done[..(head_w + 1).min(n)]) } else { 0 };
        let tail = if tail_w > 0 { samples(&self.done[n.saturating_sub(tail_w + 1)..]) } else { 0 };
        let secs = |w: usize| if w > 0 { ((w + 1) as f64 * WINDOW_S).min(n as f64 * WINDOW_S) } else { 0.0 };
        Some(OffSpeed { run, head, tail, head_s: secs(head_w), tail_s: secs(tail_w) })
    }
}

/// The warning that says which runs were off speed, by how much, what was done about it
/// (`done`, e.g. "the diagnosis leaves those seconds out") and what to do.
pub fn warning(off: &[OffSpeed], names: &[&str], done: &str) -> String {
    let ends = |o: &OffSpeed| match (o.head > 0, o.tail > 0) {
        (true, true) => format!("first {:.1} s, last {:.1} s", o.head_s, o.tail_s),
        (true, false) => format!("first {:.1} s", o.head_s),
        _ => format!("last {:.1} s", o.tail_s),
    };
    // Runs cut alike are said once.
    let said: Vec<String> = match off.first().map(ends) {
        Some(first) if off.len() > 3 && off.iter().all(|o| ends(o) == first) => vec![format!("{first} of each")],
        _ => off.iter().map(|o| format!("{} ({})", names.get(o.run).copied().unwrap_or("?"), ends(o))).collect(),
    };
    format!(
        "the stand was not at its speed at the start or end of {} conic run(s): {} — the gyro's rate magnitude is more than {:.0} % off the declared motion's there (spinning up or slowing down); {done}: trim the runs to the steady motion, or log the stand's angle (angle_column)",
        off.len(),
        said.join(", "),
        100.0 * OFF_SPEED
    )
}
