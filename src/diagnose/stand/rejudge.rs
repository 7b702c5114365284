//! The stand's groups carried from one diagnosis into the next — from the one without
//! slow noise into the one with it, or from the first look on every k-th sample of a
//! large session into the diagnosis on every sample — and judged again there.

use super::{pinv_sym, reduce, Combo, RunNoiseModel, Suspect, Systems};
use crate::estimate::{Fit, FitRun};
use crate::model::Model;
use nalgebra::DVector;

/// How a suspect's groups were carried from another diagnosis.
#[derive(Debug, Clone, Copy, Default)]
pub(super) struct Carry {
    /// Carried from a diagnosis under another noise model: its groups are judged again
    /// at the first check ([`Suspect::rejudge`]).
    pub(super) carried: bool,
    /// Its groups were found by the first look on every k-th sample of a large session
    /// ([`Suspect::looked_over`]): on every sample they are not picked again.
    pub(super) looked: bool,
    /// Carried from a diagnosis under another noise model ([`Suspect::carried_over`]), not
    /// from the first look.
    pub(super) other_noise: bool,
    /// The diagnosis it was carried from added no sensor effect ([`Suspect::expecting_search`]).
    pub(super) search_expected: bool,
}

impl Suspect {
    /// This suspect, to start a diagnosis from the motion this one corrected: under another
    /// noise model (the slow noise is then measured on a residual without the stand's
    /// error, which it would otherwise absorb), or on every sample after the first look on
    /// every k-th. Its groups are judged again there. A whole diagnosis found them, having
    /// looked for every group at every step of its ladder: so the first check judges them
    /// on their own columns and, when a sensor effect is to be added there, leaves the
    /// search for new groups to the next check, on the model with that effect (a check
    /// with every stand column costs a pass over every sample with each of them).
    pub fn carried_over(self) -> Self {
        Self { carry: Carry { carried: true, other_noise: true, ..self.carry }, ..self }
    }

    /// [`Self::carried_over`] from the first look at the stand on every k-th sample of a
    /// large session: the groups it found are estimated again on every sample at the end
    /// of the diagnosis there, and not picked again ([`Self::pick`]).
    pub fn looked_over(self) -> Self {
        let over = self.carried_over();
        Self { carry: Carry { looked: true, other_noise: false, ..over.carry }, ..over }
    }

    /// Whether the groups were carried from another diagnosis and not yet judged again.
    pub fn carried(&self) -> bool {
        self.carry.carried
    }

    /// The carried groups judged again on `sys` (this diagnosis's noise model): a group
    /// whose departure from the labels v no longer passes what a new group must (Wald
    /// χ² = vᵀC⁻¹v, C its block of the joint solution of every accepted group with the
    /// model's coefficients: p < `P_ACCEPT` and k ln n − χ² < `BIC_EVIDENCE`) goes back to
    /// its labels and is not tried again. Whether any did (the motion changed).
    pub fn rejudge(&mut self, sys: &Systems) -> bool {
        self.carry.carried = false;
        self.judge_carried(sys)
    }

    /// This suspect with the hint that the diagnosis it was carried from added no sensor
    /// effect (`yes`): then none is likely to follow at the first check here either, and
    /// that check looks for new groups on every stand column. The carried groups are then
    /// judged on every column from the start ([`Self::judging_systems`]), so that one pass
    /// over the samples serves both.
    pub fn expecting_search(self, yes: bool) -> Self {
        Self { carry: Carry { search_expected: yes, ..self.carry }, ..self }
    }

    /// The systems to judge the carried groups on around `model` and its fit: every stand
    /// column when a search is expected at the first check ([`Self::expecting_search`]),
    /// else the accepted groups' columns only. Either gives the same judgement (the
    /// accepted groups' entries differ at most in rounding).
    pub fn judging_systems(&self, model: &Model, fit: &Fit, runs: &[FitRun<'_>], noise: &[RunNoiseModel]) -> Systems {
        if self.carry.search_expected {
            self.systems(model, fit, runs, noise)
        } else {
            self.accepted_systems(model, fit, runs, noise)
        }
    }

    /// Whether groups were carried from a diagnosis under another noise model and are yet
    /// to be judged again. Those the first look found on every k-th sample are not asked:
    /// on every sample their evidence grows k-fold, and they are judged at the first check.
    pub fn carries_groups(&self) -> bool {
        self.carry.carried && self.carry.other_noise && !self.accepted.is_empty()
    }

    /// [`Self::rejudge`], with the groups still carried (judged again at the first check)
    /// when none was dropped.
    pub fn judge_carried(&mut self, sys: &Systems) -> bool {
        use statrs::distribution::{ChiSquared, ContinuousCDF};
        let per_run_found =
            |id: &str| self.accepted.iter().any(|(g, _)| self.groups[*g].id.strip_suffix("-per-run") == Some(id));
        let groups: Vec<usize> =
            self.accepted.iter().map(|a| a.0).filter(|&g| !per_run_found(self.groups[g].id)).collect();
        let joint: Vec<Combo> = groups.iter().flat_map(|&g| self.groups[g].params.iter().cloned()).collect();
        let (cov, _) = pinv_sym(&reduce(&sys.total, sys.base, &joint).0);
        let ln_n = (sys.samples.max(2) as f64).ln();
        let (mut start, mut dropped) = (sys.base, Vec::new());
        for &gi in &groups {
            let params = &self.groups[gi].params;
            let idx: Vec<usize> = (start..start + params.len()).collect();
            start += params.len();
            let v = DVector::from_iterator(params.len(), params.iter().map(|c| self.departure(c)));
            let (w, k) = crate::diagnose::algebra::wald(&cov, &idx, &v);
            let p = ChiSquared::new(k.max(1) as f64).map_or(1.0, |d| d.sf(w));
            if !(p < crate::diagnose::select::P_ACCEPT && k as f64 * ln_n - w < crate::diagnose::select::BIC_EVIDENCE) {
                dropped.push(gi);
            }
        }
        for &gi in &dropped {
            let id = self.groups[gi].id;
            for x in self.groups[gi].params.concat().into_iter().map(|p| p.0).collect::<Vec<_>>() {
                self.nudge(x, -self.departure(&vec![(x, 1.0)]));
            }
            let common = id.strip_suffix("-per-run").unwrap_or(id);
            self.accepted.retain(|(g, _)| self.groups[*g].id != id && self.groups[*g].id != common);
            self.refused.push(gi);
        }
        if !dropped.is_empty() {
            self.carry.carried = false;
        }
        !dropped.is_empty()
    }
}
