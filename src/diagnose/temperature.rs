//! Temperature polynomials in the diagnosis: the powers of (T − 20 °C) of a sensor's bias or
//! scale are separate catalogue effects, tried here together as one candidate per degree,
//! and the degree reported is the lowest that no higher one improves on.

use super::algebra::Lsq;
use super::select::Space;
use super::{candidate, Candidate};

/// The temperature families whose powers are separate catalogue effects (`…`, `…2`, `…3`).
const TEMPERATURE_FAMILIES: [&str; 4] = ["gyro-temp-bias", "accel-temp-bias", "gyro-temp-scale", "accel-temp-scale"];

/// Temperature polynomials as single candidates: for each family, the powers 1 … d (d = 2,
/// 3) not yet in the model, added together (`gyro-temp-bias+gyro-temp-bias2+…`). A curve in
/// T is explained by no one power alone — each alone leaves a residual whose size differs
/// between runs and is rejected — so the degree is chosen by the same evidence as any
/// effect: the χ² gain on the runs left out, the BIC and one size across runs.
pub(super) fn polynomial_candidates(
    space: &Space,
    set: &[usize],
    base: &Lsq,
    base_heldout: &[f64],
    base_q: &[f64],
) -> Vec<(Candidate, Vec<usize>)> {
    let mut out = Vec::new();
    for family in TEMPERATURE_FAMILIES {
        let powers = [family.to_string(), format!("{family}2"), format!("{family}3")];
        for degree in 2..=3 {
            let group: Vec<&str> =
                powers[..degree].iter().map(String::as_str).filter(|p| space.universe.candidates.contains(p)).collect();
            if group.len() < 2 {
                continue;
            }
            let params: Vec<usize> = group.iter().flat_map(|p| space.effect_params(p)).collect();
            let mut c = candidate(&group.join("+"), space.evidence(set, base, base_heldout, &params), base_q);
            c.explanation = format!(
                "Temperature polynomial of degree {degree} in (T - 20 degC) ({}): the residual follows the temp column along a curve no single power explains. Needs a temp column or a run temperature_c.",
                group.join(", ")
            );
            out.push((c, params));
        }
    }
    out
}

/// Of a temperature family's passing polynomials (the power 1 alone, then 1 … 2, then
/// 1 … 3), the lowest degree no higher one improves on: a higher degree must add a χ² gain
/// significant at p < 1e-3 on its extra parameters *and* predict the left-out runs better.
/// Any other candidate is returned as it is.
pub(super) fn lowest_sufficient_degree<'a>(
    best: &'a (Candidate, Vec<usize>),
    passing: &[&'a (Candidate, Vec<usize>)],
) -> &'a (Candidate, Vec<usize>) {
    let Some(family) = TEMPERATURE_FAMILIES.iter().find(|f| best.0.effect.split('+').next() == Some(**f)) else {
        return best;
    };
    let mut chain: Vec<&(Candidate, Vec<usize>)> =
        passing.iter().copied().filter(|c| c.0.effect.split('+').next() == Some(*family)).collect();
    chain.sort_by_key(|c| c.1.len());
    for (i, c) in chain.iter().enumerate() {
        let improved = chain[i + 1..].iter().any(|h| {
            let dq = h.0.evidence.delta_q - c.0.evidence.delta_q;
            let dof = h.0.evidence.added_params.saturating_sub(c.0.evidence.added_params);
            let p = if dof == 0 {
                1.0
            } else {
                statrs::distribution::ChiSquared::new(dof as f64).map_or(1.0, |d| {
                    use statrs::distribution::ContinuousCDF;
                    d.sf(dq.max(0.0))
                })
            };
            p < 1e-3 && h.0.evidence.heldout_gain > c.0.evidence.heldout_gain
        });
        if !improved {
            return c;
        }
    }
    best
}
