//! A profile is checked when it is read, so that no correction starts from numbers it
//! cannot use: every coefficient of its model present exactly once and finite, a sane g,
//! scale/coupling matrices that can be inverted without amplifying rounding beyond reason.

use super::Profile;
use crate::model::{Model, Role};
use crate::units::SensorKind;
use nalgebra::Matrix3;

/// Local gravity crosscal accepts, m/s² (Earth's ranges from 9.76 at the equator's
/// mountains to 9.84 at the poles; the margin allows a hand-typed value, not a typo).
pub const G_RANGE_M_S2: (f64, f64) = (9.0, 10.5);

/// Largest condition number of a scale/coupling matrix: beyond it the inverse turns the
/// output's last digits into errors larger than any sensor's noise.
pub const MAX_CONDITION: f64 = 1e6;

/// Why `p` cannot be used, or `Ok` (see the module documentation).
pub fn validate(p: &Profile, model: &Model) -> Result<(), String> {
    let (lo, hi) = G_RANGE_M_S2;
    if !(p.g_m_s2.is_finite() && (lo..=hi).contains(&p.g_m_s2)) {
        return Err(format!("g_m_s2 is {}: expected local gravity in m/s^2 between {lo} and {hi}", p.g_m_s2));
    }
    correction(&p.correction)?;
    for sensor in SensorKind::BOTH {
        coefficients(p, model, sensor)?;
        condition(p, model, sensor)?;
    }
    for n in &p.nonlinear {
        if !n.value.is_finite() || n.std_error.is_some_and(|s| !s.is_finite()) {
            return Err(format!("nonlinear parameter {} is {}: expected a finite number", n.name, n.value));
        }
    }
    for e in model.nonlinear() {
        for d in e.effect.params() {
            let k = p.nonlinear.iter().filter(|n| n.name == d.name).count();
            if k != 1 {
                return Err(format!(
                    "nonlinear parameter {} of effect '{}' appears {k} times: expected exactly once",
                    d.name,
                    e.effect.id()
                ));
            }
        }
    }
    Ok(())
}

/// Bounds of the correction settings (a hand-edited profile must not change the output or
/// exhaust memory): the offline derivative's half-window and degree, the streaming window
/// and degree. A local polynomial of degree d needs more than d points (Savitzky–Golay),
/// and a degree above [`MAX_DEGREE`] turns rounding into noise.
pub const HALF_WINDOW: (usize, usize) = (1, 1000);
/// Streaming window length, samples.
pub const STREAMING_WINDOW: (usize, usize) = (2, 10_000);
/// Highest polynomial degree of either derivative.
pub const MAX_DEGREE: usize = 6;

fn correction(c: &super::CorrectionSettings) -> Result<(), String> {
    let (hl, hh) = HALF_WINDOW;
    if !(hl..=hh).contains(&c.derivative_half_window) {
        return Err(format!(
            "correction.derivative_half_window is {}: expected {hl} to {hh} samples (default 5)",
            c.derivative_half_window
        ));
    }
    if !(1..=MAX_DEGREE.min(2 * c.derivative_half_window)).contains(&c.derivative_degree) {
        return Err(format!(
            "correction.derivative_degree is {}: expected 1 to {} (at most {MAX_DEGREE}, below the window's {} samples; default 3)",
            c.derivative_degree,
            MAX_DEGREE.min(2 * c.derivative_half_window),
            2 * c.derivative_half_window + 1
        ));
    }
    let (wl, wh) = STREAMING_WINDOW;
    if !(wl..=wh).contains(&c.streaming_window) {
        return Err(format!(
            "correction.streaming_window is {}: expected {wl} to {wh} samples (default 11)",
            c.streaming_window
        ));
    }
    if !(1..=MAX_DEGREE.min(c.streaming_window - 1)).contains(&c.streaming_degree) {
        return Err(format!(
            "correction.streaming_degree is {}: expected 1 to {} (at most {MAX_DEGREE}, below the window's {} samples; default 2)",
            c.streaming_degree,
            MAX_DEGREE.min(c.streaming_window - 1),
            c.streaming_window
        ));
    }
    Ok(())
}

/// Every coefficient of the model for `sensor` exactly once, finite, nothing else.
fn coefficients(p: &Profile, model: &Model, sensor: SensorKind) -> Result<(), String> {
    let listed = &p.sensor(sensor).coefficients;
    for t in model.terms(sensor) {
        let k = listed.iter().filter(|c| c.name == t.term.name).count();
        if k != 1 {
            let how = if k == 0 { "is missing".to_string() } else { format!("appears {k} times") };
            return Err(format!(
                "coefficient {} of effect '{}' {how}: a profile lists every coefficient of its model exactly once",
                t.term.name,
                t.effect.id()
            ));
        }
    }
    let terms = model.terms(sensor);
    for c in listed {
        if model.nominal(&c.name).is_none() {
            return Err(format!("coefficient {} is not part of the profile's model '{}'", c.name, p.model));
        }
        if let Some(t) = terms.iter().find(|t| t.term.name == c.name) {
            if c.channel != t.term.channel {
                return Err(format!(
                    "coefficient {}: channel is {}, expected {} (the output axis its effect acts on, 0..2)",
                    c.name, c.channel, t.term.channel
                ));
            }
        }
        if !c.value.is_finite() || c.std_error.is_some_and(|s| !s.is_finite() || s < 0.0) {
            return Err(format!(
                "coefficient {} is {} ± {:?}: expected a finite value and standard error",
                c.name, c.value, c.std_error
            ));
        }
    }
    Ok(())
}

/// The sensor's scale/coupling matrix from the profile's values can be inverted well.
fn condition(p: &Profile, model: &Model, sensor: SensorKind) -> Result<(), String> {
    let sf = p.sensor(sensor);
    let mut m = Matrix3::<f64>::zeros();
    for t in model.terms(sensor) {
        if let Role::Scale(j) = t.term.role {
            m[(t.term.channel, j)] += sf.value(&t.term.name).unwrap_or(t.term.nominal);
        }
    }
    let (max, min) = crate::stats::singular_values3(&m).map_or((f64::NAN, f64::NAN), |sv| (sv.max(), sv.min()));
    let cond = if min > 0.0 { max / min } else { f64::INFINITY };
    if cond.is_nan() || cond > MAX_CONDITION {
        return Err(format!(
            "the {sensor} scale/coupling matrix has condition number {cond:.3e} (singular values {max:.3e} … {min:.3e}): above {MAX_CONDITION:e}, its inverse would blow the outputs' rounding up into errors; refit the unit"
        ));
    }
    Ok(())
}
