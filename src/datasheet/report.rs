//! The datasheet as a text table and as a self-contained HTML page.

use super::Datasheet;
use crate::html::{esc, page_start};
use std::fmt::Write;

/// A number in 5 significant digits, plain where it reads, exponent otherwise.
pub fn num(v: f64) -> String {
    let a = v.abs();
    if a == 0.0 || (1e-3..1e6).contains(&a) {
        let digits = (4 - a.log10().floor().max(-3.0) as i32).clamp(0, 7) as usize;
        format!("{v:.digits$}")
    } else {
        format!("{v:.4e}")
    }
}

/// The measured quantities (one line per axis: value ± standard uncertainty, unit,
/// calibrations), then what is not measured and why, then where the definitions are.
pub fn text(d: &Datasheet) -> String {
    let mut s = String::new();
    let _ = writeln!(
        s,
        "datasheet of unit {} — profile {} ({}), {} calibration(s) stored",
        d.unit, d.profile, d.created_utc, d.calibrations
    );
    let _ = writeln!(s, "{:<32} {:<5} {:>14} {:>12}  {:<12} notes", "quantity", "axis", "value", "± u (1σ)", "unit");
    for q in d.quantities.iter().filter(|q| q.value.is_some()) {
        let mut notes = Vec::new();
        if let Some(n) = q.count {
            notes.push(format!("{n} calibrations"));
        }
        if let Some([lo, hi]) = q.interval90 {
            notes.push(format!("90 % interval {}..{}", num(lo), num(hi)));
        }
        let _ = writeln!(
            s,
            "{:<32} {:<5} {:>14} {:>12}  {:<12} {}",
            q.name,
            q.axis.as_deref().unwrap_or("-"),
            num(q.value.unwrap_or(f64::NAN)),
            q.uncertainty.map_or("-".into(), num),
            q.unit,
            notes.join("; ")
        );
    }
    let missing: Vec<_> = d.quantities.iter().filter(|q| q.value.is_none()).collect();
    if !missing.is_empty() {
        let _ = writeln!(s, "not measured:");
        for q in missing {
            let _ = writeln!(s, "  {:<30} {}", q.name, q.not_measured.as_deref().unwrap_or(""));
        }
    }
    let _ = writeln!(
        s,
        "from: {}\ndefinitions: `crosscal help quantities` (docs/reference-datasheet.md); uncertainties are standard (k = 1), from the fit's covariance or the noise reading's 68 % interval",
        d.quantities.iter().find_map(|q| q.sources.first()).map_or("-", String::as_str)
    );
    s
}

/// The datasheet as an HTML page: one table of the measured quantities with their
/// definitions, one of the quantities not measured.
pub fn html(d: &Datasheet) -> String {
    let mut s = page_start(&format!("crosscal datasheet: {}", d.unit));
    let _ = write!(
        s,
        "<p>Profile {} ({}), {} calibration(s) stored. Uncertainties are standard (k = 1).</p>",
        esc(&d.profile),
        esc(&d.created_utc),
        d.calibrations
    );
    s.push_str("<table><tr><th>quantity</th><th>axis</th><th>value</th><th>± u</th><th>unit</th><th>definition</th><th>from</th></tr>");
    for q in d.quantities.iter().filter(|q| q.value.is_some()) {
        let _ = write!(
            s,
            "<tr><td style=\"text-align:left\">{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td style=\"text-align:left\">{}</td><td style=\"text-align:left\">{}</td></tr>",
            esc(&q.name),
            esc(q.axis.as_deref().unwrap_or("-")),
            num(q.value.unwrap_or(f64::NAN)),
            q.uncertainty.map_or("-".into(), num),
            esc(&q.unit),
            esc(&q.definition),
            esc(&q.sources.join("; "))
        );
    }
    s.push_str("</table><h2>not measured</h2><table><tr><th>quantity</th><th>what would measure it</th></tr>");
    for q in d.quantities.iter().filter(|q| q.value.is_none()) {
        let _ = write!(
            s,
            "<tr><td style=\"text-align:left\">{}</td><td style=\"text-align:left\">{}</td></tr>",
            esc(&q.name),
            esc(q.not_measured.as_deref().unwrap_or(""))
        );
    }
    s.push_str("</table></body></html>\n");
    s
}
