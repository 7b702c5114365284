//! Intervals of the fitted noise terms. Each term is read at the measured point where it
//! carries the largest share of the fitted Allan variance (among points with at least
//! [`super::MEASURED_EDF`] degrees of freedom): holding the other terms at their fitted
//! values, the point's χ² interval on σ̂²(τ) (SP 1065 eq. 41) bounds the term's coefficient,
//! c_j ∈ [(σ²_low − others)/f_j(τ), (σ²_high − others)/f_j(τ)], and the coefficient maps to
//! the term as in IEEE 952 table C.1 (Q = √(c/3), N = √c, B = √c / 0.664, K = √(3c),
//! R = √(2c)). The interval reported is the hull of that and of the fitted value widened by
//! the same relative amounts, so it holds the value and shows where fit and point differ.

use super::{allan, AdevPoint, ChannelNoise, BASIS, FLAT, LEVEL, MEASURED_EDF};
use serde::{Deserialize, Serialize};

/// The 68.3 % interval of one fitted term.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TermInterval {
    /// `quantization`, `white`, `bias_instability`, `random_walk` or `ramp`.
    pub term: String,
    /// The fitted value (SI, the term's unit).
    pub value: f64,
    /// Lower end.
    pub low: f64,
    /// Upper end.
    pub high: f64,
    /// The cluster time it was read at, s.
    pub tau_s: f64,
}

const NAMES: [&str; 5] = ["quantization", "white", "bias_instability", "random_walk", "ramp"];

/// The term of coefficient `j` from its coefficient value.
fn term(j: usize, c: f64) -> f64 {
    let c = c.max(0.0);
    match j {
        0 => (c / 3.0).sqrt(),
        1 => c.sqrt(),
        2 => c.sqrt() / FLAT,
        3 => (3.0 * c).sqrt(),
        _ => (2.0 * c).sqrt(),
    }
}

/// An interval for every term the channel reports (a visible, non-zero coefficient).
pub fn term_intervals(ch: &ChannelNoise) -> Vec<TermInterval> {
    let c = ch.coefficients;
    let model = |t: f64| super::model_avar(&c, t);
    let reported = [ch.quantization, ch.white_density, ch.bias_instability, ch.random_walk, ch.ramp];
    let mut out = Vec::new();
    for j in 0..5 {
        if reported[j].is_none() || c[j] <= 0.0 {
            continue;
        }
        let share = |p: &AdevPoint| c[j] * BASIS[j](p.tau_s) / model(p.tau_s);
        let Some(p) = ch
            .points
            .iter()
            .filter(|p| p.edf >= MEASURED_EDF)
            .max_by(|a, b| share(a).total_cmp(&share(b)).then(a.edf.total_cmp(&b.edf)))
        else {
            continue;
        };
        let f = BASIS[j](p.tau_s);
        let others = model(p.tau_s) - c[j] * f;
        let (lo, hi) = allan::interval(p.adev, p.edf, LEVEL);
        let read = |s: f64| term(j, (s * s - others) / f);
        let (value, at) = (term(j, c[j]), read(p.adev));
        // The hull of what the point allows and the fitted value widened by the point's
        // relative interval: it contains the value, and the misfit where they differ.
        let (rl, rh) = if at > 0.0 { (read(lo) / at, read(hi) / at) } else { (1.0, 1.0) };
        out.push(TermInterval {
            term: NAMES[j].to_string(),
            value,
            low: read(lo).min(value * rl),
            high: read(hi).max(value * rh),
            tau_s: p.tau_s,
        });
    }
    out
}
