//! Whether a session's slow variation is noise: the diagnosis with and without slow noise
//! (flicker and bias random walk, [`super::slow`]), and the choice between them.
//!
//! A MEMS unit's bias wanders: every run gets its own offset, slope and curvature, and the
//! diagnosis under an AR noise model calls that a systematic residual ("turn-on bias" on
//! every channel) and may even take it for the Earth's rotation. Treating the wander as
//! noise everywhere has the opposite risk: a missing effect whose misfit differs from run
//! to run (a lever arm, a thermal hysteresis) is then absorbed by a large measured wander.
//! So the automatic mode diagnoses under the AR model first and, only when that leaves the
//! session unexplained, again with the slow noise measured; it takes the second when
//!
//! 1. it keeps every effect the first one added (the wander hid no physics it found),
//! 2. it leaves systematic only channels the first one left systematic, and fewer of them
//!    (or none), and
//! 3. no channel it cleared shows run offsets that jump rather than wander: a constant
//!    offset drawn anew in each run, white within runs, is likelier than flicker and walk
//!    on that channel's block means ([`crate::estimate::slow::SlowNoise::jumps_between_runs`]).
//!    That is a turn-on bias, drawn as a shape. The fit already models no slow noise on
//!    such a channel, so the second diagnosis keeps it systematic while it clears the
//!    channels that wander; this rule guards the choice all the same;
//! 4. it did not clear all three axes of a sensor whose largest systematic parts, under
//!    the AR model, sit on one and the same cone harmonic of [`LOCKED_FROM`] or above: a
//!    residual locked to the motion alike on every axis (the square wave a play-type
//!    hysteresis leaves beyond the catalogue's terms) is physics. A wander, whose power
//!    falls as 1/f or 1/f² and is drawn anew on each channel, puts its largest part on a
//!    high harmonic of one channel now and then (under a strongly coloured model the
//!    basis fit is loose), on the same one of all three almost never.
//! 5. it did not clear a channel of a sensor on which, under the AR model, a catalogued
//!    law of the motion alone (rate, angular acceleration, specific force) that neither
//!    diagnosis added still takes residual that left-out runs confirm (rules 1 and 2
//!    of [`super::select`]): what the other runs' motion predicts in a run is locked to the
//!    motion, whatever its true form (a play-type hysteresis over runs of one or two
//!    revolutions, whose fundamental a wander could also be). A wander predicts nothing
//!    through the motion; through the session clock (a drift from the neighbouring runs)
//!    it may, so laws of time and temperature do not count. When the second diagnosis
//!    adds that law (under the AR model the wander left beside it kept any effect from
//!    reaching the noise floor), the residual is the law's, not absorbed as noise.
//!
//! Otherwise the first diagnosis stands. Both are the one diagnosis ([`super::diagnose`]);
//! this module only chooses, and the one it keeps is finished: its per-run disagreements
//! and the shapes of what no effect explains ([`super::with_stand::finish`]). The second
//! starts from the motion the first corrected (its stand suspect carried over): the slow
//! noise is measured on the residual, and a base tilt's once per revolution on runs of a
//! few revolutions is as slow as a wander, so on the declared motion it would take in the
//! stand's error and let sensor effects explain the rest. The carried groups are judged
//! again under the slow noise (a Wald test of their departure from the labels,
//! [`super::stand::Suspect::rejudge`]); one that no longer passes goes back to its labels.

use super::with_stand::finish;
use super::{channel_of, diagnose, diagnose_from, Candidate, Concluded, Diagnosis, Verdict};
use crate::estimate::{EstimateError, FitOptions, FitRun};
use crate::units::{SensorKind, AXES};
use serde::{Deserialize, Serialize};

/// How the diagnosis treats slow noise.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum SlowNoiseMode {
    /// Decide per session (module documentation).
    #[default]
    Auto,
    /// Always measure slow noise and treat it as noise (`--slow-noise on`).
    On,
    /// Never: the AR noise model only (`--slow-noise off`).
    Off,
}

/// Diagnoses `model` on `runs` with slow noise treated as `mode` says (`opts.slow_noise`
/// is set by the mode). Conic runs recorded while the stand was not at its speed are
/// diagnosed without those seconds, and a warning says so ([`crate::estimate::spin`]).
pub fn diagnose_with_mode(
    model: &crate::model::Model,
    runs: &[FitRun<'_>],
    motions: &super::RunMotions<'_>,
    opts: &FitOptions,
    mode: SlowNoiseMode,
) -> Result<Diagnosis, EstimateError> {
    let off = crate::estimate::spin::off_speed(runs, motions);
    if off.is_empty() {
        return by_mode(model, runs, motions, opts, mode);
    }
    let tracks: Vec<crate::motion::Track> = runs
        .iter()
        .enumerate()
        .map(|(i, r)| match off.iter().find(|o| o.run == i) {
            Some(o) => r.track.range(o.head, r.len() - o.tail),
            None => r.track.clone(),
        })
        .collect();
    let steady: Vec<FitRun<'_>> = runs
        .iter()
        .zip(&tracks)
        .enumerate()
        .map(|(i, (r, t))| match off.iter().find(|o| o.run == i) {
            Some(o) => r.part(t, o.head, r.len() - o.tail),
            None => *r,
        })
        .collect();
    let mut d = by_mode(model, &steady, motions, opts, mode)?;
    let names: Vec<&str> = runs.iter().map(|r| r.name).collect();
    d.warnings.insert(0, crate::estimate::spin::warning(&off, &names, "the diagnosis leaves those seconds out"));
    Ok(d)
}

/// [`diagnose_with_mode`] on runs as given.
fn by_mode(
    model: &crate::model::Model,
    runs: &[FitRun<'_>],
    motions: &super::RunMotions<'_>,
    opts: &FitOptions,
    mode: SlowNoiseMode,
) -> Result<Diagnosis, EstimateError> {
    let with = |slow_noise| FitOptions { slow_noise, ..*opts };
    match mode {
        SlowNoiseMode::On => diagnose(model, runs, motions, &with(true)),
        SlowNoiseMode::Off => diagnose(model, runs, motions, &with(false)),
        SlowNoiseMode::Auto => {
            let first = diagnose_from(model, runs, motions, &with(false), None)?;
            let finished = |c| finish(c, model, runs, motions);
            if first.d.verdict != Verdict::Unexplained {
                return Ok(finished(first));
            }
            // The second starts from the motion the first corrected, its stand groups
            // judged again under the slow noise: measured on the residual of the declared
            // motion, the slow noise would take in the stand's error (a base tilt's once per
            // revolution is as slow as a wander on runs of a few revolutions) and hide it.
            // The first answer stands when the second cannot be had, and says so. Only the
            // answer is finished (its disagreements and shapes).
            // Where the first added no sensor effect, the second's first check likely looks
            // for new stand groups: its carried groups are judged on every column at once.
            let searching = first.d.steps.is_empty();
            let carried = first.stand.clone().map(|s| s.carried_over().expecting_search(searching));
            match diagnose_from(model, runs, motions, &with(true), carried) {
                Ok(second) => Ok(finished(choose(first, second))),
                Err(e) => {
                    let mut first = first;
                    first.d.warnings.push(format!("slow noise was not tried: {e}"));
                    Ok(finished(first))
                }
            }
        }
    }
}

/// Share of a sensor's whitened χ² the left-out runs must confirm for rule 5: a residual
/// mostly locked to the motion, not a few hundred of χ² that a many-coefficient effect
/// picks out of a wander the AR model underrates.
pub const PREDICTED_SHARE: f64 = 0.02;

/// The lowest cone harmonic whose systematic part counts as locked to the motion (rule 4).
pub const LOCKED_FROM: usize = 3;

/// The channels (0..6: gyro x..z, accel x..z) still systematic at the end of the ladder.
fn systematic(d: &Diagnosis) -> Vec<usize> {
    last_channels(d).iter().filter(|c| c.systematic).map(|c| channel_of(c.sensor, c.axis)).collect()
}

/// The channel reports at the end of the ladder.
fn last_channels(d: &Diagnosis) -> &[super::ChannelReport] {
    d.steps.last().map_or(&d.channels, |s| &s.channels)
}

/// The channels of the sensors whose three axes all have their largest systematic part
/// on one cone harmonic of [`LOCKED_FROM`] or above, with that harmonic.
fn locked(d: &Diagnosis) -> Vec<(usize, usize)> {
    let harmonic = |c: usize| {
        last_channels(d).iter().find(|r| r.systematic && channel_of(r.sensor, r.axis) == c).and_then(|r| {
            match r.worst {
                Some((_, Some(h), _)) if h >= LOCKED_FROM => Some(h),
                _ => None,
            }
        })
    };
    [0usize, 3]
        .into_iter()
        .filter_map(|first| {
            let h = harmonic(first)?;
            (1..3).all(|i| harmonic(first + i) == Some(h)).then(|| (first..first + 3).map(move |c| (c, h)))
        })
        .flatten()
        .collect()
}

/// Whether left-out runs confirm at least [`PREDICTED_SHARE`] of the sensor's χ² for
/// candidate `k` (rules 1 and 2 of [`super::select`] on a residual mostly its own).
pub(super) fn confirmed(k: &Candidate) -> bool {
    k.evidence.predicts() && k.evidence.heldout_gain >= PREDICTED_SHARE * k.rss_before
}

/// The catalogued effect, added by neither `d` nor `second`, that best predicts left-out
/// runs on the sensor of channel `c` in `d` (rule 5), with its χ² gain there as a share of
/// the sensor's χ². One the second diagnosis adds (or one it names as the same finding as
/// a step) takes the motion-locked residual itself: it is not absorbed as noise there.
fn predicted_by(d: &Diagnosis, second: &Diagnosis, c: usize) -> Option<(String, f64)> {
    let sensor = if c < 3 { SensorKind::Gyro } else { SensorKind::Accel };
    let added = |id: &str| {
        d.steps.iter().chain(&second.steps).any(|s| s.effect == id || s.indistinguishable.iter().any(|e| e == id))
    };
    d.candidates
        .iter()
        .filter(|k| k.sensor == sensor && motion_law(&k.effect) && confirmed(k) && !added(&k.effect))
        .max_by(|a, b| a.evidence.heldout_gain.total_cmp(&b.evidence.heldout_gain))
        .map(|k| (k.effect.clone(), k.evidence.heldout_gain / k.rss_before))
}

/// An effect that is a law of the motion alone (rate, angular acceleration, specific
/// force), not of the session clock or the temperature: a wander carried from run to run
/// is predicted in a left-out run by a drift from its neighbours, never by the motion.
fn motion_law(id: &str) -> bool {
    crate::model::find(id).is_some_and(|e| {
        let i = e.inputs();
        (i.rate || i.ang_accel || i.force) && !(i.time || i.temperature || i.temperature_rate)
    })
}

/// The choice (module documentation): the diagnosis with slow noise when it keeps the
/// first one's effects, clears channels without clearing a turn-on bias or a residual
/// locked to the cone, and leaves nothing new; else the first. The chosen one says why in its warnings.
fn choose(mut first_c: Concluded, mut second_c: Concluded) -> Concluded {
    let (first, second) = (&mut first_c.d, &mut second_c.d);
    let keeps = first.steps.iter().all(|s| second.steps.iter().any(|t| t.effect == s.effect));
    let (before, after) = (systematic(first), systematic(second));
    let fewer = after.iter().all(|c| before.contains(c)) && after.len() < before.len();
    let cleared: Vec<usize> = before.iter().copied().filter(|c| !after.contains(c)).collect();
    let jumps: Vec<usize> = cleared
        .iter()
        .copied()
        .filter(|&c| second.final_fit.slow_noise(c).is_some_and(|s| s.jumps_between_runs()))
        .collect();
    let name = |c: usize| format!("{} {}", if c < 3 { "gyro" } else { "accel" }, AXES[c % 3]);
    let names = |cs: &[usize]| cs.iter().map(|&c| name(c)).collect::<Vec<_>>().join(", ");
    if !(keeps && fewer) {
        return first_c;
    }
    let locked: Vec<(usize, usize)> = locked(first).into_iter().filter(|(c, _)| cleared.contains(c)).collect();
    if !locked.is_empty() {
        let said: Vec<String> = locked.iter().map(|&(c, h)| format!("{} (harmonic {h})", name(c))).collect();
        first.warnings.push(format!(
            "the systematic residual on {} sits on a harmonic of the cone: locked to the motion, it is not treated as slow noise (--slow-noise on would)",
            said.join(", ")
        ));
        return first_c;
    }
    let predicted: Vec<(usize, (String, f64))> =
        cleared.iter().filter_map(|&c| predicted_by(first, second, c).map(|p| (c, p))).collect();
    if let Some((_, (effect, gain))) = predicted.first() {
        let predicted: Vec<usize> = predicted.iter().map(|p| p.0).collect();
        first.warnings.push(format!(
            "the systematic residual on {} is predicted in left-out runs from the others' motion ({effect} predicts {:.1} % of its whitened χ² on left-out runs): locked to the motion, it is not treated as slow noise (--slow-noise on would)",
            names(&predicted),
            100.0 * gain
        ));
        return first_c;
    }
    if jumps.is_empty() {
        second.warnings.push(format!(
            "the slow variation on {} wanders like flicker and bias random walk (different in every run, carried from one run into the next, locked to nothing): it is treated as noise, as --slow-noise on does (--slow-noise off shows it as a systematic residual)",
            names(&cleared)
        ));
        return second_c;
    }
    first.warnings.push(format!(
        "the run offsets on {} jump between runs and stay flat within them (a turn-on bias is likelier than flicker and walk there): not treated as noise",
        names(&jumps)
    ));
    first_c
}
