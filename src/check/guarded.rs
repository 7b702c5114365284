//! The `datasheet` rule kind: a bound on a datasheet quantity ([`crate::datasheet`]) decided
//! with its measurement uncertainty.
//!
//! Decision rules (JCGM 106:2012 §8, ISO 14253-1:2017): with `guarded` (the default) and
//! coverage factor k (2 by default), a value y with standard uncertainty u against an upper
//! limit L
//!
//! * **passes** when y + k·u ≤ L (the whole coverage interval is inside: the guard band
//!   k·u is taken from the tolerance),
//! * **fails** when y − k·u > L (the whole interval is outside),
//! * is **indeterminate** otherwise: the measurement cannot tell, and a better measurement
//!   is needed (mirrored for a lower limit).
//!
//! `simple` compares y with L alone (shared risk). A quantity quoted as ± (bias,
//! misalignment, g-sensitivity …) is bounded in magnitude by default (`"magnitude": true`:
//! |y| against `max`); a rule on several axes takes each axis's decision and the unit's
//! is the worst (fail over indeterminate over pass).

use crate::datasheet::{Datasheet, Quantity};
use serde::{Deserialize, Serialize};

/// How a value is judged against its limit.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "snake_case")]
pub enum DecisionRule {
    /// Guard-banded by k·u (JCGM 106 / ISO 14253-1).
    #[default]
    Guarded,
    /// The value against the limit, uncertainty ignored.
    Simple,
}

/// The outcome of a rule on a unit.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Decision {
    /// Inside the limits (beyond doubt, under `guarded`).
    Pass,
    /// The measurement cannot tell.
    Indeterminate,
    /// Outside the limits.
    Fail,
}

impl Decision {
    /// `pass`, `indeterminate` or `fail`.
    pub fn word(self) -> &'static str {
        match self {
            Decision::Pass => "pass",
            Decision::Indeterminate => "indeterminate",
            Decision::Fail => "fail",
        }
    }
}

/// The coverage factor by default.
pub const DEFAULT_K: f64 = 2.0;

/// One axis of a datasheet rule.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct AxisDecision {
    /// Axis.
    pub axis: String,
    /// Value, datasheet unit (signed).
    pub value: f64,
    /// Standard uncertainty.
    pub uncertainty: f64,
    /// Decision.
    pub decision: Decision,
    /// Distance from the value to the limit it is nearest to (for what would resolve it).
    pub margin: f64,
}

/// The bounds of a datasheet rule.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Bounds {
    /// Lower limit.
    pub min: Option<f64>,
    /// Upper limit.
    pub max: Option<f64>,
    /// Bound |value| rather than value.
    pub magnitude: bool,
    /// Decision rule.
    pub rule: DecisionRule,
    /// Coverage factor.
    pub k: f64,
}

impl Bounds {
    /// The decision on a value y with standard uncertainty u, and its margin to the nearest
    /// limit.
    pub fn decide(&self, y: f64, u: f64) -> (Decision, f64) {
        let y = if self.magnitude { y.abs() } else { y };
        let g = match self.rule {
            DecisionRule::Guarded => self.k * u,
            DecisionRule::Simple => 0.0,
        };
        let mut d = Decision::Pass;
        let mut margin = f64::INFINITY;
        if let Some(hi) = self.max {
            margin = margin.min((hi - y).abs());
            d = d.max(if y - g > hi || (g == 0.0 && y > hi) {
                Decision::Fail
            } else if y + g <= hi {
                Decision::Pass
            } else {
                Decision::Indeterminate
            });
        }
        if let Some(lo) = self.min {
            margin = margin.min((y - lo).abs());
            d = d.max(if y + g < lo || (g == 0.0 && y < lo) {
                Decision::Fail
            } else if y - g >= lo {
                Decision::Pass
            } else {
                Decision::Indeterminate
            });
        }
        (d, margin)
    }

    /// The specification limits of the signed value (a magnitude rule's max is ±max).
    pub fn limits(&self) -> (Option<f64>, Option<f64>) {
        if self.magnitude {
            (self.max.map(|m| -m), self.max)
        } else {
            (self.min, self.max)
        }
    }
}

/// Each measured axis of `quantity` (or only `axis`) in `sheet` decided against `bounds`;
/// Err when the quantity is not measured.
pub fn decide(
    sheet: &Datasheet,
    quantity: &str,
    axis: Option<&str>,
    bounds: &Bounds,
) -> Result<Vec<AxisDecision>, String> {
    let picked: Vec<&Quantity> =
        sheet.get(quantity).filter(|q| axis.is_none_or(|a| q.axis.as_deref() == Some(a))).collect();
    if picked.is_empty() {
        let why = sheet
            .quantities
            .iter()
            .find(|q| q.name == quantity && q.value.is_none())
            .and_then(|q| q.not_measured.clone())
            .unwrap_or_else(|| format!("no axis {}", axis.unwrap_or("-")));
        return Err(format!("{quantity} not measured: {why}"));
    }
    Ok(picked
        .iter()
        .map(|q| {
            let (value, uncertainty) = (q.value.unwrap_or(f64::NAN), q.uncertainty.unwrap_or(0.0));
            let (decision, margin) = bounds.decide(value, uncertainty);
            AxisDecision { axis: q.axis.clone().unwrap_or_default(), value, uncertainty, decision, margin }
        })
        .collect())
}

/// The axis that decides the unit: the worst decision, then the smallest margin in
/// standard uncertainties.
pub fn deciding(axes: &[AxisDecision]) -> Option<&AxisDecision> {
    axes.iter().max_by(|a, b| {
        let m = |x: &AxisDecision| -(x.margin / x.uncertainty.max(f64::MIN_POSITIVE));
        a.decision.cmp(&b.decision).then(m(a).total_cmp(&m(b)))
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn guarded_and_simple_decisions() {
        let b = Bounds { min: None, max: Some(1.0), magnitude: true, rule: DecisionRule::Guarded, k: 2.0 };
        assert_eq!(b.decide(0.5, 0.2).0, Decision::Pass);
        assert_eq!(b.decide(-0.9, 0.1).0, Decision::Indeterminate);
        assert_eq!(b.decide(1.5, 0.2).0, Decision::Fail);
        assert_eq!(b.decide(1.1, 0.1).0, Decision::Indeterminate);
        let s = Bounds { rule: DecisionRule::Simple, ..b };
        assert_eq!(s.decide(0.99, 0.5).0, Decision::Pass);
        assert_eq!(s.decide(1.01, 0.0).0, Decision::Fail);
        let lo = Bounds { min: Some(2.0), max: None, magnitude: false, ..b };
        assert_eq!(lo.decide(3.0, 0.1).0, Decision::Pass);
        assert_eq!(lo.decide(1.0, 0.1).0, Decision::Fail);
        assert_eq!(lo.decide(2.1, 0.1).0, Decision::Indeterminate);
    }
}
