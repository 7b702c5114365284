//! The stand's findings in words: each group's estimate ± standard error in the user's
//! units, what the manifest said, and the fix.

use super::select::Evidence;
use serde::{Deserialize, Serialize};

/// One stand finding: a group of the stand's parameters that explains the residual.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct StandFinding {
    /// Group id (`cone-angle`, `stand-rate-per-run`, `base-tilt`, `earth-rotation`, …).
    pub id: String,
    /// Its parameters: estimated value ± standard error, in the units named.
    pub values: Vec<StandValue>,
    /// The finding and the fix, in words.
    pub message: String,
    /// The evidence when it was accepted (same rules as a catalogue effect).
    pub evidence: Evidence,
}

/// One estimated stand parameter.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct StandValue {
    /// What it is (`cone angle offset`, `rate error of run cone+10`, …).
    pub name: String,
    /// Estimated value (unit below).
    pub value: f64,
    /// Standard error; none when the runs cannot tell it from the unit's model (another
    /// combination of the model's coefficients moves the outputs exactly as it does).
    pub std_error: Option<f64>,
    /// Unit (`deg`, `%`, `deg/h`).
    pub unit: String,
}

/// The fix of a stand finding the manifest can carry.
const FIX: &str = "correct the manifest or fit with --stand";
/// The fix of a rate that drifts within a run (no manifest field carries it).
const DRIFT_FIX: &str = "check the stand's speed control, log its angle (angle_column) or fit with --stand";
/// Relative per second → % per minute.
const PCT_MIN: f64 = 100.0 * 60.0;
const EARTH_RAD_S: f64 = 7.292_115e-5;
/// rad/s → °/h.
const DEG_H: f64 = 180.0 / std::f64::consts::PI * 3600.0;

/// One group parameter's context: the run it belongs to (per-run groups), its name and
/// label (rad or rad/s; NaN for common parameters).
pub struct ParamContext {
    /// Run name, for a per-run parameter.
    pub run: Option<String>,
    /// The manifest's value of the quantity (cone angle, rate or phase), SI.
    pub label: f64,
}

/// A conic run's label, as the words of a finding need it.
pub struct RunLabel {
    /// The declared cone angle, rad.
    pub cone_rad: f64,
    /// The declared rate, rad/s.
    pub rate_rad_s: f64,
    /// Whether the stand logs its angle on the run (its rate, drift and ripple are then the
    /// log's, not the stand groups').
    pub logs: bool,
}

/// The conic runs a group of the stand's angle (rate, drift, ripple) moves, in words.
fn angle_scope(labels: &[RunLabel]) -> &'static str {
    if labels.iter().any(|l| l.logs) {
        "every conic run that does not log its angle"
    } else {
        "every conic run"
    }
}

/// Decimals that show a standard error `se` to one significant digit (two when it starts
/// with 1), at least `min` and at most 8: an estimate is never printed "± 0.000".
fn decimals(se: f64, min: usize) -> usize {
    if !(se > 0.0 && se.is_finite()) {
        return min;
    }
    let mut d = (-se.log10()).ceil().max(0.0) as usize;
    if (se * 10f64.powi(d.min(8) as i32)).round() < 2.0 {
        d += 1;
    }
    d.clamp(min, 8)
}

/// `v ± se` with [`decimals`] (`+` on positive values when `signed`); an infinite `se` (a
/// parameter the runs cannot tell from the unit's model) says so.
fn pm(v: f64, se: f64, min: usize, signed: bool) -> String {
    if se.is_infinite() {
        return format!("{v:.min$} (not separable from the unit's model on these runs)");
    }
    let d = decimals(se, min);
    if signed {
        format!("{v:+.d$} ± {se:.d$}")
    } else {
        format!("{v:.d$} ± {se:.d$}")
    }
}

fn value(name: String, v: f64, se: f64, unit: &str) -> StandValue {
    StandValue { name, value: v, std_error: se.is_finite().then_some(se), unit: unit.to_string() }
}

/// Runs whose value stands out of its error (beyond 3 SE family-wise over the runs), as
/// `run v ± se unit` (the first six).
fn listed(values: &[StandValue], ctx: &[ParamContext], show: impl Fn(&StandValue, &ParamContext) -> String) -> String {
    // A run is listed when its value stands out of its standard error as 3 SE does for one
    // run (two-sided 0.27 %) over all the runs together: with 18 runs at their labels one
    // would pass 3 SE by chance one session in twenty.
    let z = {
        use statrs::distribution::{ContinuousCDF, Normal};
        let tail = 0.00135 / values.len().max(1) as f64;
        Normal::new(0.0, 1.0).map_or(3.0, |n| n.inverse_cdf(1.0 - tail)).max(3.0)
    };
    let off: Vec<String> = values
        .iter()
        .zip(ctx)
        .filter(|(v, _)| v.std_error.is_some_and(|s| v.value.abs() > z * s))
        .map(|(v, c)| show(v, c))
        .collect();
    let more = if off.len() > 6 { format!(" and {} more", off.len() - 6) } else { String::new() };
    format!("{} of {} runs: {}{more}", off.len(), values.len(), off.into_iter().take(6).collect::<Vec<_>>().join("; "))
}

/// The finding of a stand group: `v` and `se` in SI (rad, relative, rad/s), `labels` those
/// of the conic runs.
pub fn finding(
    id: &str,
    v: &[f64],
    se: &[f64],
    ctx: &[ParamContext],
    labels: &[RunLabel],
    evidence: Evidence,
) -> StandFinding {
    let deg = f64::to_degrees;
    let (values, message) = match id {
        "cone-angle" => {
            let (d, s) = (deg(v[0]), deg(se[0]));
            let mut angles: Vec<f64> = labels.iter().map(|l| deg(l.cone_rad)).collect();
            angles.sort_by(f64::total_cmp);
            angles.dedup_by(|a, b| (*a - *b).abs() < 1e-9);
            let each: Vec<String> = angles.iter().map(|a| format!("{}°, not {a}°", pm(a + d, s, 3, false))).collect();
            (
                vec![value("cone angle offset (every conic run)".into(), d, s, "deg")],
                format!("the stand: cone angle {} (every conic run {d:+.3}°): {FIX}", each.join("; ")),
            )
        }
        "stand-rate" => {
            let (d, s) = (100.0 * v[0], 100.0 * se[0]);
            let mut rates: Vec<f64> = labels.iter().filter(|l| !l.logs).map(|l| deg(l.rate_rad_s)).collect();
            rates.sort_by(f64::total_cmp);
            rates.dedup_by(|a, b| (*a - *b).abs() < 1e-9);
            let each: Vec<String> = rates.iter().map(|r| format!("{:.4} °/s, not {r} °/s", r * (1.0 + v[0]))).collect();
            (
                vec![value(format!("rate error ({})", angle_scope(labels)), d, s, "%")],
                format!(
                    "the stand: rate {} % off the manifest ({}){}: {FIX}",
                    pm(d, s, 3, true),
                    each.join("; "),
                    if labels.iter().any(|l| l.logs) { ", on every conic run that does not log its angle" } else { "" }
                ),
            )
        }
        "stand-rate-drift" => {
            let (d, s) = (PCT_MIN * v[0], PCT_MIN * se[0]);
            (
                vec![value(format!("rate drift ({})", angle_scope(labels)), d, s, "%/min")],
                format!(
                    "the stand: its rate drifts {} % of the rate per minute within {} (from the run's first sample): {DRIFT_FIX}",
                    pm(d, s, 3, true),
                    angle_scope(labels)
                ),
            )
        }
        "encoder-offset" => {
            // The model turns the log by φ: the log reads −φ off the stand's angle.
            let (d, s) = (-deg(v[0]), deg(se[0]));
            (
                vec![value("logged angle offset (every run that logs it)".into(), d, s, "deg")],
                format!(
                    "the stand: its logged angle reads {}° off the stand's zero (the encoder's zero; every run that logs it): correct the encoder's zero or fit with --stand",
                    pm(d, s, 3, true)
                ),
            )
        }
        "cone-angle-per-run" | "stand-rate-per-run" | "phase-per-run" | "stand-rate-drift-per-run" => {
            per_run(id, v, se, ctx)
        }
        "base-tilt" => {
            let (x, y) = (deg(v[0]), deg(v[1]));
            let values = vec![
                value("base tilt about x".into(), x, deg(se[0]), "deg"),
                value("base tilt about y".into(), y, deg(se[1]), "deg"),
            ];
            let message = format!(
                "the stand: its base is tilted {}° about x and {}° about y ({:.3}° from level): level the stand or fit with --stand",
                pm(x, deg(se[0]), 3, true),
                pm(y, deg(se[1]), 3, true),
                x.hypot(y)
            );
            (values, message)
        }
        "speed-ripple-1" | "speed-ripple-2" => {
            let h = if id == "speed-ripple-1" { 1 } else { 2 };
            let [r, se_r, psi, se_psi] = crate::motion::stand::speed_ripple(h, [v[0], v[1]], [se[0], se[1]]);
            let (r, se_r, psi, se_psi) = (100.0 * r, 100.0 * se_r, deg(psi), deg(se_psi));
            let times = if h == 1 { "once" } else { "twice" };
            let values = vec![
                value(format!("speed ripple {times} per revolution"), r, se_r, "%"),
                value(format!("speed ripple {times} per revolution, phase"), psi, se_psi, "deg"),
            ];
            let message = format!(
                "the stand: its speed ripples {times} per revolution by {} % of the rate (phase {}°): log the stand's angle (angle_column) or fit with --stand",
                pm(r, se_r, 3, false),
                pm(psi, se_psi, 0, false)
            );
            (values, message)
        }
        "cone-wobble" => {
            let [amp, se_a, psi, se_psi] = crate::motion::stand::polar(v[0], v[1], se[0], se[1]).map(deg);
            let values = vec![
                value("cone-axis wobble".into(), amp, se_a, "deg"),
                value("cone-axis wobble, phase".into(), psi, se_psi, "deg"),
            ];
            let message = format!(
                "the stand: its cone angle wobbles once per revolution by {}° (phase {psi:.0}°): fit with --stand or repair the stand's bearing",
                pm(amp, se_a, 3, false)
            );
            (values, message)
        }
        _ => earth(v, se, !labels.is_empty()),
    };
    StandFinding { id: id.to_string(), values, message, evidence }
}

/// A per-run group's values (one per conic run) and the runs off their labels in words.
fn per_run(id: &str, v: &[f64], se: &[f64], ctx: &[ParamContext]) -> (Vec<StandValue>, String) {
    let deg = f64::to_degrees;
    let (what, unit, k) = match id {
        "cone-angle-per-run" => ("cone angle", "deg", deg(1.0)),
        "stand-rate-per-run" => ("rate error", "%", 100.0),
        "stand-rate-drift-per-run" => ("rate drift", "%/min", PCT_MIN),
        _ => ("starting phase", "deg", deg(1.0)),
    };
    let values: Vec<StandValue> = v
        .iter()
        .zip(se)
        .zip(ctx)
        .map(|((x, s), c)| value(format!("{what} of run {}", c.run.as_deref().unwrap_or("?")), k * x, k * s, unit))
        .collect();
    let words = listed(&values, ctx, |x, c| {
        let run = c.run.as_deref().unwrap_or("?");
        match id {
            "cone-angle-per-run" => {
                format!(
                    "{run} {}°, not {}°",
                    pm(deg(c.label) + x.value, x.std_error.unwrap_or(f64::INFINITY), 3, false),
                    deg(c.label)
                )
            }
            "stand-rate-per-run" => format!(
                "{run} {:.4} °/s ({} %), not {} °/s",
                deg(c.label) * (1.0 + x.value / 100.0),
                pm(x.value, x.std_error.unwrap_or(f64::INFINITY), 3, true),
                deg(c.label)
            ),
            "stand-rate-drift-per-run" => {
                format!("{run} {} %/min", pm(x.value, x.std_error.unwrap_or(f64::INFINITY), 3, true))
            }
            _ => format!("{run} {}°", pm(x.value, x.std_error.unwrap_or(f64::INFINITY), 2, true)),
        }
    });
    let fix = match id {
        "phase-per-run" => "declare phase_deg per run or fit with --stand",
        "stand-rate-drift-per-run" => DRIFT_FIX,
        _ => FIX,
    };
    (values, format!("the stand: {what} off the manifest in {words}: {fix}"))
}

/// The Earth's rotation: the conic runs' base-frame (x, y, up) then, per static pose, its
/// two horizontal components (the vertical is shared).
fn earth(v: &[f64], se: &[f64], has_conic: bool) -> (Vec<StandValue>, String) {
    // With conic runs the first three are (x, y, up); on static poses only, the first is up.
    let (up, up_se, horizontal) = if has_conic && v.len() >= 3 {
        (v[2], se[2], Some(((v[0].hypot(v[1])), se[0].hypot(se[1]) / std::f64::consts::SQRT_2)))
    } else {
        (v[0], se[0], None)
    };
    let mut values = vec![value("Earth's rate, vertical".into(), up * DEG_H, up_se * DEG_H, "deg/h")];
    let lat = (up / EARTH_RAD_S).clamp(-1.0, 1.0).asin().to_degrees();
    let lat_se = (up_se / EARTH_RAD_S / (1.0 - (up / EARTH_RAD_S).powi(2)).max(1e-6).sqrt()).to_degrees();
    let vertical = if up_se.is_finite() {
        format!(
            "vertical part {} °/h (latitude {}°)",
            pm(up * DEG_H, up_se * DEG_H, 2, false),
            pm(lat, lat_se, 0, false)
        )
    } else {
        // A gyro g-sensitivity's diagonal follows gravity as the vertical rate does: only
        // the latitude tells them apart.
        "vertical part not separable on these runs from the unit's model (it follows gravity as a gyro g-sensitivity's diagonal does; the latitude, declared as earth_rate, separates them)".to_string()
    };
    let mut message = format!("the environment: the Earth's rotation, not declared in the manifest: {vertical}");
    if let Some((h, hs)) = horizontal {
        values.push(value("Earth's rate, horizontal (stand base)".into(), h * DEG_H, hs * DEG_H, "deg/h"));
        message.push_str(&format!(
            ", horizontal part {} °/h (its direction depends on the heading)",
            pm(h * DEG_H, hs * DEG_H, 2, false)
        ));
    }
    message.push_str(if up_se.is_finite() {
        ": declare earth_rate on the static runs (or fit with --stand); it is not a gyro g-sensitivity"
    } else {
        ": declare earth_rate on the runs (or fit with --stand)"
    });
    (values, message)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_estimate_shows_its_error_to_one_or_two_significant_digits() {
        assert_eq!(pm(10.30021, 0.00037, 3, false), "10.3002 ± 0.0004");
        assert_eq!(pm(0.2, 0.0012, 3, true), "+0.2000 ± 0.0012");
        assert_eq!(pm(-0.1, 0.03, 3, true), "-0.100 ± 0.030");
        assert_eq!(pm(41.7, 12.0, 0, false), "42 ± 12");
        assert_eq!(pm(1.0, 0.0, 3, false), "1.000 ± 0.000");
        assert_eq!(pm(1.0, f64::NAN, 2, false), "1.00 ± NaN");
        assert_eq!(decimals(1e-12, 3), 8);
        assert_eq!(pm(0.5, f64::INFINITY, 3, false), "0.500 (not separable from the unit's model on these runs)");
    }
}
