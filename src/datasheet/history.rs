//! Quantities from a unit's stored calibrations (repeatability, long-term trends) and from
//! its noise reading.

use super::{bias_factor, Entry, Found};
use crate::profile::Profile;
use crate::units::{SensorKind, AXES};
use statrs::distribution::{ChiSquared, ContinuousCDF};
use std::path::PathBuf;

/// A calibration: the newest profile of each distinct set of fitted files (a profile
/// revised to add a noise reading is the same calibration, not another power cycle).
pub(super) struct Calibration<'a> {
    path: String,
    profile: &'a Profile,
}

/// The distinct calibrations of `history`, oldest first; the current profile alone when the
/// history is empty. Profiles of sessions without file hashes (built in memory) are each
/// their own calibration.
pub(super) fn distinct<'a>(history: &'a [(PathBuf, Profile)], current: &'a Profile) -> Vec<Calibration<'a>> {
    let key = |path: &str, p: &Profile| {
        let mut k: Vec<String> = p.runs.iter().map(|r| r.sha256.clone()).collect();
        if k.is_empty() || k.iter().any(String::is_empty) {
            k.push(path.to_string());
        }
        k
    };
    let mut out: Vec<Calibration<'a>> = Vec::new();
    for (path, p) in history {
        let path = path.display().to_string();
        let k = key(&path, p);
        out.retain(|c| key(&c.path, c.profile) != k);
        out.push(Calibration { path, profile: p });
    }
    if out.is_empty() {
        out.push(Calibration { path: "the profile".into(), profile: current });
    }
    out
}

/// Biases (display unit) and their standard errors of one axis over the calibrations that
/// fitted it, with the calibrations' paths and times.
fn biases<'a>(cals: &'a [Calibration<'_>], sensor: SensorKind, axis: char) -> Vec<(f64, f64, &'a str, &'a str)> {
    cals.iter()
        .filter_map(|c| {
            let co = c.profile.sensor(sensor).get(&format!("{}.b_{axis}", sensor.as_str()))?;
            (co.status == crate::estimate::CoefStatus::Fitted).then_some(())?;
            let k = bias_factor(sensor, c.profile.g_m_s2);
            Some((co.value * k, co.std_error.unwrap_or(0.0) * k, c.path.as_str(), c.profile.created_utc.as_str()))
        })
        .collect()
}

/// Turn-on to turn-on repeatability: the sample standard deviation s of the biases over
/// n ≥ 2 calibrations; its standard uncertainty s/√(2(n − 1)) and 90 % interval
/// s·√((n − 1)/χ²₀.₉₅), s·√((n − 1)/χ²₀.₀₅) (normal turn-on biases).
pub(super) fn repeatability(cals: &[Calibration<'_>], sensor: SensorKind) -> Found {
    AXES.iter()
        .map(|&a| {
            let b = biases(cals, sensor, a);
            let n = b.len();
            if n < 2 {
                return Err(format!("{n} calibration(s) of the unit stored with a fitted bias"));
            }
            let mean = b.iter().map(|x| x.0).sum::<f64>() / n as f64;
            let sd = (b.iter().map(|x| (x.0 - mean).powi(2)).sum::<f64>() / (n - 1) as f64).sqrt();
            let dof: f64 = (n - 1) as f64;
            let interval = ChiSquared::new(dof)
                .ok()
                .map(|c| [sd * (dof / c.inverse_cdf(0.95)).sqrt(), sd * (dof / c.inverse_cdf(0.05)).sqrt()]);
            let sources = b.iter().map(|x| x.2.to_string()).collect::<Vec<_>>();
            let mut e = Entry::new(a.to_string(), (sd, sd / (2.0 * dof).sqrt()), &sources);
            e.count = Some(n);
            e.interval90 = interval;
            Ok(e)
        })
        .collect()
}

/// Which long-term trend.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Trend {
    /// Of the bias.
    Bias,
    /// Of the scale-factor error.
    Scale,
}

/// The scale-factor error (ppm) and its standard error of one axis of a calibration, from
/// the diagonal of C_ω or K (to first order |row| − 1).
fn scale(p: &Profile, sensor: SensorKind, axis: char) -> Option<(f64, f64)> {
    let m = if sensor == SensorKind::Gyro { "c" } else { "k" };
    let c = p.sensor(sensor).get(&format!("{}.{m}_{axis}{axis}", sensor.as_str()))?;
    (c.status == crate::estimate::CoefStatus::Fitted)
        .then_some(((c.value - 1.0) * 1e6, c.std_error.unwrap_or(0.0) * 1e6))
}

/// Weighted least-squares slope per year of bias or scale against the calibrations' times,
/// when they span more than one date; its standard uncertainty √(1/Σw(t − t̄)²), inflated by
/// √(χ²/(n − 2)) when the points scatter more than their standard errors say.
pub(super) fn trend(cals: &[Calibration<'_>], sensor: SensorKind, which: Trend) -> Found {
    const YEAR_S: f64 = 365.25 * 86400.0;
    AXES.iter()
        .map(|&a| {
            let mut pts = Vec::new();
            let mut dates = std::collections::BTreeSet::new();
            let mut sources = Vec::new();
            for c in cals {
                let Ok(t) = c.profile.created_utc.parse::<jiff::Timestamp>() else { continue };
                let v = match which {
                    Trend::Bias => biases(std::slice::from_ref(c), sensor, a).first().map(|b| (b.0, b.1)),
                    Trend::Scale => scale(c.profile, sensor, a),
                };
                if let Some((v, se)) = v {
                    dates.insert(t.to_zoned(jiff::tz::TimeZone::UTC).date());
                    pts.push((t.as_second() as f64 / YEAR_S, v, se));
                    sources.push(c.path.clone());
                }
            }
            if dates.len() < 2 {
                return Err(format!("the calibrations span {} date(s)", dates.len()));
            }
            let floor = pts.iter().map(|p| p.2).fold(0.0, f64::max).max(1e-300);
            let w: Vec<f64> = pts.iter().map(|p| 1.0 / p.2.max(floor * 1e-3).powi(2)).collect();
            let sw: f64 = w.iter().sum();
            let tm = pts.iter().zip(&w).map(|(p, w)| w * p.0).sum::<f64>() / sw;
            let vm = pts.iter().zip(&w).map(|(p, w)| w * p.1).sum::<f64>() / sw;
            let sxx: f64 = pts.iter().zip(&w).map(|(p, w)| w * (p.0 - tm).powi(2)).sum();
            let sxy: f64 = pts.iter().zip(&w).map(|(p, w)| w * (p.0 - tm) * (p.1 - vm)).sum();
            let slope = sxy / sxx;
            let n = pts.len();
            let chi2: f64 = pts.iter().zip(&w).map(|(p, w)| w * (p.1 - vm - slope * (p.0 - tm)).powi(2)).sum();
            let inflate = if n > 2 { (chi2 / (n - 2) as f64).max(1.0).sqrt() } else { 1.0 };
            let mut e = Entry::new(a.to_string(), (slope, inflate / sxx.sqrt()), &sources);
            e.count = Some(n);
            Ok(e)
        })
        .collect()
}

/// In-run bias stability and ARW/VRW per axis from the newest noise reading (the current
/// profile's, else the newest stored one's).
pub(super) fn noise(
    history: &[(PathBuf, Profile)],
    current: &Profile,
    path: &str,
    sensor: SensorKind,
) -> (Found, Found) {
    let found =
        current.noise.as_ref().map(|n| (path.to_string(), n)).or_else(|| {
            history.iter().rev().find_map(|(p, pr)| pr.noise.as_ref().map(|n| (p.display().to_string(), n)))
        });
    let Some((from, report)) = found else {
        return (Err("the profile has no noise reading".into()), Err("the profile has no noise reading".into()));
    };
    let g = current.g_m_s2;
    let (bi_k, white_k) = match sensor {
        SensorKind::Gyro => (DEG_H, 180.0 / std::f64::consts::PI * 60.0),
        SensorKind::Accel => (1e6 / g, 60.0),
    };
    let src = vec![format!("noise of {} (stored in {from})", report.source)];
    let half = |lo: f64, hi: f64| (hi - lo).abs() / 2.0;
    let interval = |c: &crate::noise::ChannelNoise, term: &str| {
        c.term_intervals.iter().find(|t| t.term == term).map_or(0.0, |t| half(t.low, t.high))
    };
    let mut bi = Vec::new();
    let mut white = Vec::new();
    for c in report.channels.iter().filter(|c| c.sensor() == sensor) {
        let axis = c.channel.chars().last().map(String::from).unwrap_or_default();
        if let Some(v) = c.bias() {
            let u = c.bias_instability_reading.map_or_else(|| interval(c, "bias_instability"), |r| half(r.low, r.high));
            bi.push(Entry::new(axis.clone(), (v * bi_k, u * bi_k), &src));
        }
        if let Some(v) = c.white() {
            let u = c.white_density_reading.map_or_else(|| interval(c, "white"), |r| half(r.low, r.high));
            white.push(Entry::new(axis, (v * white_k, u * white_k), &src));
        }
    }
    let none = |what: &str| Err(format!("the noise reading shows no {what} on the {sensor} channels"));
    (
        if bi.is_empty() { none("bias instability floor") } else { Ok(bi) },
        if white.is_empty() { none("white noise") } else { Ok(white) },
    )
}

const DEG_H: f64 = super::DEG_H_PER_RAD_S;
