//! Temperature in the diagnosis.
//!
//! **Polynomials.** The powers of (T − 20 °C) of a sensor's bias or scale are separate
//! catalogue effects, tried here together as one candidate per degree; the degree reported
//! is the lowest that no higher one improves on, chosen on runs the fit did not see, and
//! reported with its uncertainty ([`DegreeChoice`]): each degree's χ² gain on left-out runs,
//! how many left-out runs each degree predicts best (a decisive choice is one most runs
//! agree on), and the size of the highest power (and of the next, not taken) over its
//! standard error. At the end of the climb each degree is checked again with every effect
//! found in the model ([`revisit_degrees`]), and what is reported is that final choice.
//!
//! **Hysteresis.** When the runs hold warming and cooling branches, the thermal hysteresis
//! effects (`…-temp-hysteresis`: a bias offset of opposite sign on the two branches) compete
//! like any other; once sized, their explanation says warming minus cooling per axis with
//! its standard error in the sensor's unit, so a branch-dependent residual is named as what
//! it is rather than absorbed by drift or a lever arm.

use super::algebra::Lsq;
use super::select::{Estimate, Space};
use super::{candidate, Candidate};
use crate::units::{SensorKind, AXES};
use serde::{Deserialize, Serialize};

/// The temperature families whose powers are separate catalogue effects (`…`, `…2`, `…3`).
const TEMPERATURE_FAMILIES: [&str; 4] = ["gyro-temp-bias", "accel-temp-bias", "gyro-temp-scale", "accel-temp-scale"];

/// The evidence for one degree of a temperature polynomial.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct DegreeScore {
    /// Degree (0: no temperature term of this family).
    pub degree: usize,
    /// Coefficients of the polynomial up to this degree.
    pub params: usize,
    /// In-sample χ² reduction against the model without the family.
    pub delta_q: f64,
    /// χ² reduction on left-out runs (each predicted by the fit on the others).
    pub heldout_gain: f64,
    /// Left-out runs this degree predicts best of all degrees tried.
    pub folds_preferring: usize,
}

/// The degree chosen for a temperature polynomial and how sure the choice is.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct DegreeChoice {
    /// The family (`gyro-temp-bias`, …).
    pub family: String,
    /// The degree chosen.
    pub degree: usize,
    /// Every degree tried, 0 first.
    pub scores: Vec<DegreeScore>,
    /// Left-out runs (folds) compared.
    pub folds: usize,
    /// Per axis: the chosen degree's highest-power coefficient over its standard error.
    pub top_power_z: Vec<f64>,
    /// Per axis: the same for the next power up, fitted with it (None when not tried).
    pub next_power_z: Option<Vec<f64>>,
}

impl DegreeChoice {
    /// The choice in words.
    pub fn describe(&self) -> String {
        let by = |f: &dyn Fn(&DegreeScore) -> String| self.scores.iter().map(f).collect::<Vec<_>>().join(", ");
        let gains = by(&|s| format!("{}: {:.1}", s.degree, s.heldout_gain));
        let folds = if self.folds > 1 {
            let agree = self.scores.iter().find(|s| s.degree == self.degree).map_or(0, |s| s.folds_preferring);
            let others = by(&|s| format!("{} at {}", s.folds_preferring, s.degree));
            format!("; {agree} of {} left-out runs are predicted best at degree {} ({others})", self.folds, self.degree)
        } else {
            String::new()
        };
        let z = |v: &[f64]| v.iter().map(|z| format!("{z:.1}")).collect::<Vec<_>>().join(", ");
        let next = self
            .next_power_z
            .as_ref()
            .map_or(String::new(), |v| format!("; the next power, not taken, has z = {} (x, y, z) when fitted", z(v)));
        format!(
            "Degree {} of {} chosen on runs the fit did not see: χ² gain on left-out runs by degree {gains}{folds}; the highest power's size over its standard error z = {} (x, y, z){next}.",
            self.degree,
            self.family,
            z(&self.top_power_z)
        )
    }
}

/// The id of power `d` of a family (`gyro-temp-bias`, `gyro-temp-bias2`, …).
fn power(family: &str, d: usize) -> String {
    if d == 1 {
        family.to_string()
    } else {
        format!("{family}{d}")
    }
}

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
        let powers = [power(family, 1), power(family, 2), power(family, 3)];
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
    let Some(family) = family_of(&best.0.effect) else {
        return best;
    };
    let mut chain: Vec<&(Candidate, Vec<usize>)> =
        passing.iter().copied().filter(|c| c.0.effect.split('+').next() == Some(family)).collect();
    chain.sort_by_key(|c| c.1.len());
    for (i, c) in chain.iter().enumerate() {
        let improved = chain[i + 1..].iter().any(|h| {
            let dq = h.0.evidence.delta_q - c.0.evidence.delta_q;
            let dof = h.0.evidence.added_params.saturating_sub(c.0.evidence.added_params);
            p_gain(dq, dof) < 1e-3 && h.0.evidence.heldout_gain > c.0.evidence.heldout_gain
        });
        if !improved {
            return c;
        }
    }
    best
}

/// The temperature family a candidate starts (its first part is the family's linear term).
fn family_of(effect: &str) -> Option<&'static str> {
    TEMPERATURE_FAMILIES.iter().copied().find(|f| effect.split('+').next() == Some(*f))
}

/// Each candidate's coefficient sizes with their standard errors, and for a thermal
/// hysteresis the size in words: warming minus cooling per axis (2 thy), in the sensor's
/// display unit.
pub(super) fn size_candidates(space: &Space, set: &[usize], scored: &mut [(Candidate, Vec<usize>)]) {
    for (c, params) in scored.iter_mut() {
        c.estimates = space.estimates(set, params);
        if c.effect.ends_with("-temp-hysteresis") && c.estimates.len() == 3 {
            let sensor = if c.effect.starts_with("accel") { SensorKind::Accel } else { SensorKind::Gyro };
            let (unit, k) = sensor.display_unit();
            let axes: Vec<String> = c
                .estimates
                .iter()
                .zip(AXES)
                .map(|(e, a)| format!("{a} {:+.3e} ± {:.1e}", 2.0 * e.value * k, 2.0 * e.std_error * k))
                .collect();
            let generic = crate::model::find(&c.effect).map_or("", |e| e.explain());
            c.explanation = format!(
                "Thermal hysteresis of the {sensor} bias: on the warming branch minus on the cooling branch, at the same temperature, {} {unit} (2 thy, ± one standard error); the temperature dependence differs between the branches by this offset. {generic}",
                axes.join(", ")
            );
        }
    }
}

/// The degree choice of a family's polynomial of `degree` fitted beside `set`: every degree
/// from 0 to the highest whose powers `params_of` finds, fitted on all runs and on each
/// left-out fold.
fn degree_choice(
    space: &Space,
    set: &[usize],
    family: &str,
    degree: usize,
    params_of: &dyn Fn(&str) -> Vec<usize>,
) -> DegreeChoice {
    let base = space.solve(set);
    let base_heldout = space.heldout(set);
    let available = (1..=3).take_while(|&d| !params_of(&power(family, d)).is_empty()).count();
    let params = |d: usize| -> Vec<usize> { (1..=d).flat_map(|p| params_of(&power(family, p))).collect() };
    let mut heldout: Vec<Vec<f64>> = vec![base_heldout.clone()];
    let mut scores = vec![DegreeScore { degree: 0, params: 0, delta_q: 0.0, heldout_gain: 0.0, folds_preferring: 0 }];
    for d in 1..=available {
        let mut with = set.to_vec();
        with.extend(params(d));
        let h = space.heldout(&with);
        let heldout_gain = base_heldout.iter().zip(&h).map(|(a, b)| a - b).sum();
        let delta_q = base.q - space.solve(&with).q;
        scores.push(DegreeScore { degree: d, params: params(d).len(), delta_q, heldout_gain, folds_preferring: 0 });
        heldout.push(h);
    }
    let folds = base_heldout.len();
    for f in 0..folds {
        let best_d = (0..heldout.len()).min_by(|&a, &b| heldout[a][f].total_cmp(&heldout[b][f])).unwrap_or(0);
        scores[best_d].folds_preferring += 1;
    }
    let z_of = |d: usize| -> Vec<f64> {
        let top = params_of(&power(family, d));
        space.estimates(set, &params(d)).iter().filter(|e| top_named(space, &top, e)).map(z).collect()
    };
    DegreeChoice {
        family: family.to_string(),
        degree,
        folds,
        top_power_z: if degree >= 1 { z_of(degree) } else { Vec::new() },
        next_power_z: (degree < available).then(|| z_of(degree + 1)),
        scores,
    }
}

/// The upper-tail χ²(dof) probability of a χ² gain `dq` (1 when dof is 0).
fn p_gain(dq: f64, dof: usize) -> f64 {
    if dof == 0 {
        return 1.0;
    }
    statrs::distribution::ChiSquared::new(dof as f64).map_or(1.0, |d| {
        use statrs::distribution::ContinuousCDF;
        d.sf(dq.max(0.0))
    })
}

/// The lowest degree from 1 to `max` that no higher one up to `max` improves on (the rule
/// of [`lowest_sufficient_degree`] on the scores of a [`DegreeChoice`]).
fn lowest_sufficient(c: &DegreeChoice, max: usize) -> usize {
    let at = |d: usize| c.scores.iter().find(|s| s.degree == d);
    (1..=max)
        .find(|&d| {
            let Some(lo) = at(d) else { return true };
            !(d + 1..=max).filter_map(at).any(|h| {
                p_gain(h.delta_q - lo.delta_q, h.params.saturating_sub(lo.params)) < 1e-3
                    && h.heldout_gain > lo.heldout_gain
            })
        })
        .unwrap_or(max)
}

/// The explanation of a family's polynomial of `degree`.
fn polynomial_explanation(family: &str, degree: usize) -> String {
    if degree <= 1 {
        return crate::model::find(family).map_or("", |e| e.explain()).to_string();
    }
    let ids: Vec<String> = (1..=degree).map(|d| power(family, d)).collect();
    format!(
        "Temperature polynomial of degree {degree} in (T - 20 degC) ({}): the residual follows the temp column along a curve no single power explains. Needs a temp column or a run temperature_c.",
        ids.join(", ")
    )
}

/// After the climb, each temperature polynomial's degree again with every effect found in
/// the model: a polynomial added early can take a higher degree to absorb part of an effect
/// found later (a thermal hysteresis reaches a scale polynomial through the runs' mean
/// rate). Its top powers are dropped while they fail the rule that chose them, and the
/// step's degree, uncertainty ([`DegreeChoice`]), sizes and explanation are those of the
/// final model. Returns whether a step's effect changed (the caller refits).
pub(super) fn revisit_degrees(space: &Space, steps: &mut [super::Step], warnings: &mut Vec<String>) -> bool {
    let all_of = |id: &str| -> Vec<usize> {
        (0..space.universe.params.len()).filter(|&i| space.universe.params[i].effect == id).collect()
    };
    let mut changed = false;
    for st in steps.iter_mut() {
        let Some(family) = family_of(&st.effect) else { continue };
        let degree = st.effect.split('+').count();
        let family_params: Vec<usize> = (1..=3).flat_map(|d| all_of(&power(family, d))).collect();
        let set: Vec<usize> = space.base_set().into_iter().filter(|p| !family_params.contains(p)).collect();
        // The family's fitted powers moved back to nominal (absent), so that each degree is
        // fitted from nothing beside everything else found.
        let shift: Vec<(usize, f64)> = family_params
            .iter()
            .map(|&i| (i, space.universe.params[i].nominal - space.universe.params[i].value))
            .collect();
        let space = &space.moved(&shift);
        let mut choice = degree_choice(space, &set, family, degree, &all_of);
        let lowered = if choice.folds > 1 { lowest_sufficient(&choice, degree) } else { degree };
        if lowered < degree {
            choice = degree_choice(space, &set, family, lowered, &all_of);
            warnings.push(format!(
                "{family}: degree {degree} when it was added, {lowered} once every effect found is in the model (the higher powers no longer predict left-out runs better)"
            ));
            st.effect = (1..=lowered).map(|d| power(family, d)).collect::<Vec<_>>().join("+");
            st.score.effect = st.effect.clone();
            changed = true;
        }
        let params: Vec<usize> = (1..=lowered).flat_map(|d| all_of(&power(family, d))).collect();
        st.score.estimates = space.estimates(&set, &params);
        st.score.explanation = format!("{} {}", choice.describe(), polynomial_explanation(family, lowered));
        st.score.degree = Some(choice);
    }
    changed
}

fn top_named(space: &Space, top: &[usize], e: &Estimate) -> bool {
    top.iter().any(|&p| space.universe.params[p].name == e.name)
}

fn z(e: &Estimate) -> f64 {
    if e.std_error > 0.0 {
        e.value / e.std_error
    } else {
        0.0
    }
}
