//! The stand's findings: each group found, its values ± standard errors from the joint
//! solution of every accepted group with the model's coefficients, in words.

use super::{left_information, pinv_sym, reduce, Combo, Dir, Group, RunStand, StandFinding, Suspect, Systems};
use super::{COMMON, SEPARABLE};
use crate::diagnose::select::Evidence;

impl Suspect {
    /// The findings so far, each group's values ± standard errors from the joint solution
    /// of every accepted group with the model's coefficients on `sys` (around the final
    /// motion: the values are the motion's departures from the labels). `names` are the
    /// runs' names.
    pub fn findings(&self, sys: &Systems, names: &[String]) -> Vec<StandFinding> {
        // A common group whose per-run group was found later is part of it.
        let per_run_found =
            |id: &str| self.accepted.iter().any(|(g, _)| self.groups[*g].id.strip_suffix("-per-run") == Some(id));
        let accepted: Vec<&(usize, Evidence)> =
            self.accepted.iter().filter(|(g, _)| !per_run_found(self.groups[*g].id)).collect();
        let mut joint: Vec<Combo> = Vec::new();
        let mut spans = Vec::new();
        for (gi, _) in &accepted {
            let start = joint.len();
            joint.extend(self.groups[*gi].params.iter().cloned());
            spans.push(start..joint.len());
        }
        let (g, _) = reduce(&sys.total, sys.base, &joint);
        let (pinv, _) = pinv_sym(&g);
        // A parameter another combination of columns (the unit's model, the other groups)
        // moves the outputs as exactly has no standard error: the pseudo-inverse would give
        // it a small one on the arbitrary split (the Earth's vertical rate beside a gyro
        // g-sensitivity's diagonal, on conic runs alone).
        let se_of = |p: usize| {
            if left_information(&g, p) > SEPARABLE * g[(p, p)] {
                pinv[(p, p)].max(0.0).sqrt()
            } else {
                f64::INFINITY
            }
        };
        let labels = self.labels();
        // A group none of whose parameters stands out of its standard error in the joint
        // solution (|v| ≤ 3 SE: a per-run group with no run off its label) is not a finding:
        // the motion it moved is the declared one within the noise.
        let found: Vec<StandFinding> = accepted
            .iter()
            .zip(spans)
            .filter_map(|((gi, ev), span)| {
                let group = &self.groups[*gi];
                let se: Vec<f64> = span.map(|j| se_of(sys.base + j)).collect();
                let values: Vec<f64> = group.params.iter().map(|c| self.departure(c)).collect();
                let stands_out = values.iter().zip(&se).any(|(v, s)| v.abs() > 3.0 * s);
                let ctx = self.context(group, names);
                stands_out
                    .then(|| crate::diagnose::stand_words::finding(group.id, &values, &se, &ctx, &labels, ev.clone()))
            })
            .collect();
        self.mounts.iter().cloned().chain(found).collect()
    }

    /// The runs found on another mount than declared (the findings without a stand group).
    pub fn mounts(&self) -> Vec<StandFinding> {
        self.mounts.clone()
    }

    /// How far the motion now believed is from the labels along one group parameter: on
    /// the first run that has one of its global parameters (a common rate's first run may
    /// log its angle, which the rate does not move).
    pub(super) fn departure(&self, combo: &Combo) -> f64 {
        let found = combo.iter().find_map(|&(gi, _)| {
            self.locals.iter().enumerate().find_map(|(r, l)| l.iter().find(|(g, _)| *g == gi).map(|&(_, dir)| (r, dir)))
        });
        let Some((r, dir)) = found else { return 0.0 };
        match (&self.runs[r], dir) {
            (RunStand::Conic { declared, now, .. }, Dir::Knob(k)) => match k {
                0 => now.cone_angle_rad - declared.cone_angle_rad,
                1 => now.rate_rad_s / declared.rate_rad_s - 1.0,
                2 => now.phase_rad - declared.phase_rad,
                3 => now.rate_drift_per_s - declared.rate_drift_per_s,
                4 | 5 => now.tilt_rad[k - 4],
                6..=9 => now.ripple_rad[(k - 6) / 2][(k - 6) % 2],
                10 | 11 => now.wobble_rad[k - 10],
                _ => now.earth_rad_s[k - 12],
            },
            (RunStand::Static { earth, .. }, Dir::Rate(v)) => earth.iter().zip(v).map(|(a, b)| a * b).sum(),
            _ => 0.0,
        }
    }

    /// Per group parameter: the run it belongs to (per-run groups) and its label.
    pub(super) fn context(&self, group: &Group, names: &[String]) -> Vec<crate::diagnose::stand_words::ParamContext> {
        let per_run = COMMON * self.conic_count();
        group
            .params
            .iter()
            .map(|c| {
                let gi = c.first().map_or(usize::MAX, |x| x.0);
                let run = if c.len() == 1 && gi < per_run {
                    self.locals.iter().position(|l| l.iter().any(|(g, _)| *g == gi))
                } else {
                    None
                };
                let label = run.map_or(f64::NAN, |r| match &self.runs[r] {
                    RunStand::Conic { declared, .. } => match gi % COMMON {
                        0 => declared.cone_angle_rad,
                        1 => declared.rate_rad_s,
                        2 => declared.phase_rad,
                        _ => declared.rate_drift_per_s,
                    },
                    _ => f64::NAN,
                });
                crate::diagnose::stand_words::ParamContext { run: run.and_then(|r| names.get(r).cloned()), label }
            })
            .collect()
    }

    pub(super) fn conic_count(&self) -> usize {
        self.runs.iter().filter(|r| matches!(r, RunStand::Conic { .. })).count()
    }

    /// The declared cone angles and rates of the conic runs (for the words).
    pub fn labels(&self) -> Vec<crate::diagnose::stand_words::RunLabel> {
        self.runs
            .iter()
            .filter_map(|r| match r {
                RunStand::Conic { declared, logs, .. } => Some(crate::diagnose::stand_words::RunLabel {
                    cone_rad: declared.cone_angle_rad,
                    rate_rad_s: declared.rate_rad_s,
                    logs: *logs,
                }),
                _ => None,
            })
            .collect()
    }
}
