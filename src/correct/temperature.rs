//! The calibrated temperature range and what the correction does outside it (issue #24's
//! requirement: never extrapolate a temperature polynomial silently).
//!
//! A profile with temperature terms records the range of temperatures it was fitted on
//! ([`crate::profile::Profile::temperature_range_c`]). Outside it the correction, by default,
//! holds the temperature at the nearest edge (`clamp`: every temperature term is evaluated
//! at the edge, as ArduPilot and PX4 do with their thermal polynomials), counts the samples
//! and reports the first one; `extrapolate` evaluates the terms as they are (counted too);
//! `error` refuses the record. The guard is a comparison and a clamp per sample: no
//! allocation, the same in offline and streaming correction.

/// What to do with a temperature outside the calibrated range.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum TempPolicy {
    /// Hold the temperature at the nearest edge of the range (default).
    #[default]
    Clamp,
    /// Evaluate the temperature terms outside the range as fitted.
    Extrapolate,
    /// Refuse the record.
    Error,
}

impl TempPolicy {
    /// From `clamp`, `extrapolate` or `error`.
    pub fn parse(s: &str) -> Option<Self> {
        match s {
            "clamp" => Some(Self::Clamp),
            "extrapolate" => Some(Self::Extrapolate),
            "error" => Some(Self::Error),
            _ => None,
        }
    }

    /// The policy's name.
    pub fn name(self) -> &'static str {
        match self {
            Self::Clamp => "clamp",
            Self::Extrapolate => "extrapolate",
            Self::Error => "error",
        }
    }
}

/// The samples a correction met outside the calibrated range.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct TempOutside {
    /// The calibrated range, °C (None: the profile has no temperature terms).
    pub range_c: Option<[f64; 2]>,
    /// Samples outside it.
    pub samples: u64,
    /// The first one: its time, s, and temperature, °C.
    pub first: Option<(f64, f64)>,
    /// The lowest and highest temperature seen outside, °C.
    pub extent_c: Option<[f64; 2]>,
    /// What was done with them.
    pub policy: TempPolicy,
}

impl TempOutside {
    /// The guarded temperature of one sample (clamped under [`TempPolicy::Clamp`]), counted
    /// when outside the range.
    #[inline]
    pub fn guard(&mut self, t_s: f64, temp_c: f64) -> f64 {
        let Some([lo, hi]) = self.range_c else { return temp_c };
        if !(temp_c < lo || temp_c > hi) {
            return temp_c;
        }
        self.samples += 1;
        if self.first.is_none() {
            self.first = Some((t_s, temp_c));
        }
        self.extent_c = crate::stats::widen(self.extent_c, temp_c);
        match self.policy {
            TempPolicy::Clamp => temp_c.clamp(lo, hi),
            TempPolicy::Extrapolate | TempPolicy::Error => temp_c,
        }
    }

    /// The one warning a user reads, when any sample was outside.
    pub fn warning(&self) -> Option<String> {
        let ([lo, hi], (t, temp), [a, b]) = (self.range_c?, self.first?, self.extent_c?);
        let what = match self.policy {
            TempPolicy::Clamp => "the temperature terms were held at the nearest edge (clamp)",
            TempPolicy::Extrapolate => "the temperature terms were extrapolated (--temperature-range extrapolate)",
            TempPolicy::Error => "refused (--temperature-range error)",
        };
        Some(format!(
            "{} samples at {a:.1}..{b:.1} degC lie outside the profile's calibrated range {lo:.1}..{hi:.1} degC (first at t = {t} s, {temp:.2} degC): {what}; --temperature-range clamp|extrapolate|error chooses",
            self.samples
        ))
    }
}

/// The error of `--temperature-range error` when samples were outside.
pub fn refuse_outside(t: &TempOutside) -> Result<(), super::CorrectError> {
    match t.warning() {
        Some(w) if t.policy == TempPolicy::Error => Err(super::CorrectError::OutOfRange(w)),
        _ => Ok(()),
    }
}
