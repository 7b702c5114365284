//! Which run would separate two candidates the recorded runs cannot tell apart.
//!
//! Two candidate effects are one finding when each explains the residual the other does
//! (`aliases` in the climb). Whether a further run would tell them apart is a question of
//! design, not data: the information matrix of the recorded runs plus that of a proposed
//! run (its whitened Gram with zero outputs, [`super::space::design_gram`]) gives the
//! covariance of both effects' coefficients, and the largest canonical correlation ρ
//! between the two blocks says how confounded they remain (1: not separable; 0:
//! independent). Proposals vary one factor of a recorded conic run at a time (cone angle,
//! rate and direction, mount); the one with the smallest ρ is suggested.

use super::select::Space;
use super::space::{design_gram, Universe};
use crate::estimate::{Fit, FitRun};
use crate::frames::Mount;
use crate::model::Model;
use crate::motion::{track_for, DerivativeConfig};
use crate::session::{MotionSpec, Recording};
use nalgebra::DMatrix;
use rayon::prelude::*;

/// Samples of a proposed run's design Gram (its information is scaled to a recorded run's
/// length): enough for every cone harmonic of the basis, cheap enough for dozens of runs.
const DESIGN_SAMPLES: usize = 480;
/// Most proposals tried.
const MAX_PROPOSALS: usize = 48;

/// A proposed conic run, as a manifest would declare it.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ProposedRun {
    /// Cone half-angle, degrees.
    pub cone_angle_deg: f64,
    /// Stand rate, °/s (signed).
    pub rate_deg_s: f64,
    /// Mount (signed axis names).
    pub mount: [String; 3],
    /// Duration, s (a recorded run's).
    pub duration_s: f64,
}

impl std::fmt::Display for ProposedRun {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "a conic run at cone angle {}°, rate {} °/s, mount [{}] ({:.0} s)",
            hundredths(self.cone_angle_deg),
            hundredths(self.rate_deg_s),
            self.mount.join(", "),
            self.duration_s
        )
    }
}

/// `x` rounded to two decimals, for a number a user sets on a stand: a proposal built
/// from a corrected motion (cone 19.74999882…°) reads 19.75, and 20.0 reads 20.
fn hundredths(x: f64) -> f64 {
    let r = (x * 100.0).round() / 100.0;
    if r == 0.0 {
        0.0
    } else {
        r
    }
}

/// Runs that would separate two candidates.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Separation {
    /// The proposed runs, best first (added one at a time until the correlation is below
    /// [`SEPARATED`], at most three).
    pub runs: Vec<ProposedRun>,
    /// Largest canonical correlation between the two candidates' coefficients now.
    pub rho_now: f64,
    /// The same with the proposed runs added.
    pub rho_with: f64,
}

impl std::fmt::Display for Separation {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let runs: Vec<String> = self.runs.iter().map(ToString::to_string).collect();
        write!(
            f,
            "{} (largest correlation of their coefficients {:.3} now, {:.3} with {})",
            runs.join(" and "),
            self.rho_now,
            self.rho_with,
            if self.runs.len() > 1 { "them" } else { "it" }
        )
    }
}

/// Canonical correlation below which two candidates count as separated.
pub const SEPARATED: f64 = 0.9;
/// Most runs proposed.
const MAX_RUNS: usize = 3;

/// The recorded conic runs' declarations: (cone angle °, rate °/s, mount, duration s, samples).
fn recorded(runs: &[FitRun<'_>], motions: &[&MotionSpec]) -> Vec<(f64, f64, Mount, f64, usize)> {
    runs.iter()
        .zip(motions)
        .filter_map(|(r, m)| match (m, r.track.mount()) {
            (MotionSpec::Conic { cone_angle_deg, rate_deg_s, .. }, Some(mount)) if r.len() > 1 => {
                let t = &r.track.t_s;
                Some((*cone_angle_deg, *rate_deg_s, mount.clone(), t[r.len() - 1] - t[0], r.len()))
            }
            _ => None,
        })
        .collect()
}

/// Proposals: each recorded run with one factor changed (the angle to one not recorded,
/// the rate reversed or doubled, the mount to one not recorded).
fn proposals(rec: &[(f64, f64, Mount, f64, usize)]) -> Vec<(f64, f64, Mount)> {
    let angles: Vec<f64> = rec.iter().map(|r| r.0).collect();
    let max_angle = angles.iter().copied().fold(0.0, f64::max);
    let new_angles = [(max_angle + 15.0).min(60.0), (max_angle * 0.5).max(2.0)];
    let mounts: Vec<Mount> = [["+y", "+z", "+x"], ["+z", "+x", "+y"], ["+x", "-y", "-z"], ["+y", "+x", "-z"]]
        .iter()
        .filter_map(|n| Mount::parse(n).ok())
        .collect();
    let mut out: Vec<(f64, f64, Mount)> = Vec::new();
    // Declared angles and rates are the manifest's numbers: equal to 1e-9 is the same run.
    let same = |a: (f64, f64, &Mount), b: (f64, f64, &Mount)| {
        (a.0 - b.0).abs() < 1e-9 && (a.1 - b.1).abs() < 1e-9 && a.2.names() == b.2.names()
    };
    let mut push = |p: (f64, f64, Mount)| {
        let key = (p.0, p.1, &p.2);
        if !rec.iter().any(|r| same((r.0, r.1, &r.2), key)) && !out.iter().any(|q| same((q.0, q.1, &q.2), key)) {
            out.push(p);
        }
    };
    for (a, w, m, _, _) in rec {
        for &na in &new_angles {
            push((na, *w, m.clone()));
        }
        push((*a, -w, m.clone()));
        push((*a, 2.0 * w, m.clone()));
        for nm in &mounts {
            push((*a, *w, nm.clone()));
        }
    }
    out.truncate(MAX_PROPOSALS);
    out
}

/// The largest canonical correlation between the coefficients `a` and `b` given `set`
/// (all global indices) under information `g`: with P = (G_SS)⁻¹ on S = set ∪ a ∪ b,
/// ρ² = λ_max(P_aa^{-1/2} P_ab P_bb⁻¹ P_ba P_aa^{-1/2}). A tiny ridge (1e-10 of each
/// diagonal) makes an exactly aliased pair come out as ρ ≈ 1 rather than undefined.
pub fn canonical_correlation(g: &DMatrix<f64>, set: &[usize], a: &[usize], b: &[usize]) -> f64 {
    let mut s: Vec<usize> = set.to_vec();
    for &i in a.iter().chain(b) {
        if !s.contains(&i) {
            s.push(i);
        }
    }
    let mut gs = DMatrix::from_fn(s.len(), s.len(), |i, j| g[(s[i], s[j])]);
    for i in 0..s.len() {
        gs[(i, i)] += 1e-10 * gs[(i, i)].abs().max(f64::MIN_POSITIVE);
    }
    let (p, _) = super::algebra::pinv_sym(&gs);
    let pos = |x: &[usize]| -> Vec<usize> { x.iter().filter_map(|i| s.iter().position(|j| j == i)).collect() };
    let (ia, ib) = (pos(a), pos(b));
    let block = |r: &[usize], c: &[usize]| DMatrix::from_fn(r.len(), c.len(), |i, j| p[(r[i], c[j])]);
    let (paa, pbb, pab) = (block(&ia, &ia), block(&ib, &ib), block(&ia, &ib));
    let e = paa.symmetric_eigen();
    let top = e.eigenvalues.iter().copied().fold(0.0, f64::max);
    let inv_sqrt = DMatrix::from_diagonal(&e.eigenvalues.map(|v| if v > 1e-14 * top { 1.0 / v.sqrt() } else { 0.0 }));
    let half = &e.eigenvectors * inv_sqrt * e.eigenvectors.transpose();
    let (pbb_inv, _) = super::algebra::pinv_sym(&pbb);
    let m = &half * &pab * pbb_inv * pab.transpose() * &half;
    let m = (&m + m.transpose()) * 0.5;
    m.symmetric_eigen().eigenvalues.iter().copied().fold(0.0, f64::max).clamp(0.0, 1.0).sqrt()
}

/// The proposed runs that separate candidates `a` and `b` (global parameter indices of
/// `space`, around `base` fitted as `fit`): the best single run, then the best run added
/// to it, until their correlation falls below [`SEPARATED`] (at most three runs). None
/// when no proposal lowers the correlation.
#[allow(clippy::too_many_arguments)]
pub fn separating_run(
    space: &Space,
    base: &Model,
    fit: &Fit,
    set: &[usize],
    a: &[usize],
    b: &[usize],
    runs: &[FitRun<'_>],
    motions: &[&MotionSpec],
) -> Option<Separation> {
    let rec = recorded(runs, motions);
    let first = rec.first()?;
    let noise = &space.runs.first()?.noise;
    let mut g = space.information_with(None);
    let rho_now = canonical_correlation(&g, set, a, b);
    let duration = first.3.max(f64::MIN_POSITIVE);
    let weight = first.4 as f64 / DESIGN_SAMPLES as f64;
    let u: &Universe = &space.universe;
    // The recorded conic's specific force has the session's g as its norm.
    let a0 = runs.iter().find(|r| r.track.mount().is_some())?.track.at(0).a_m_s2.xyz;
    let g_m_s2 = (a0[0] * a0[0] + a0[1] * a0[1] + a0[2] * a0[2]).sqrt();
    let temp = runs[0].temp_c.map(|t| t[0]).or(runs[0].temp_const_c);
    // Each proposal's information, once.
    let infos: Vec<((f64, f64, Mount), DMatrix<f64>)> = proposals(&rec)
        .into_par_iter()
        .map(|(angle, rate, mount)| {
            let n = DESIGN_SAMPLES;
            // At least one revolution, so that every harmonic of the basis is there.
            let span = duration.max(360.0 / rate.abs().max(f64::MIN_POSITIVE));
            let rec_t =
                Recording { t_s: (0..n).map(|k| k as f64 * span / (n - 1) as f64).collect(), ..Default::default() };
            let motion = MotionSpec::Conic { cone_angle_deg: angle, rate_deg_s: rate, phase_deg: 0.0 };
            let track = track_for(&motion, &mount, &rec_t, g_m_s2, &DerivativeConfig::default());
            let zeros = vec![[0.0; 3]; n];
            let run = FitRun {
                name: "proposed",
                track: &track,
                gyro: &zeros,
                accel: &zeros,
                temp_c: None,
                temp_const_c: temp,
                start_s: None,
            };
            let rg = design_gram(u, base, fit, &run, &motion, noise);
            let info = space.information_with(Some((&rg, weight))) - &g;
            ((angle, rate, mount), info)
        })
        .collect();
    let mut chosen: Vec<ProposedRun> = Vec::new();
    let mut rho = rho_now;
    while chosen.len() < MAX_RUNS && rho >= SEPARATED {
        let Some((i, r)) = infos
            .iter()
            .enumerate()
            .map(|(i, (_, info))| (i, canonical_correlation(&(&g + info), set, a, b)))
            .filter(|(_, r)| r.is_finite())
            .min_by(|x, y| x.1.total_cmp(&y.1))
        else {
            break;
        };
        if r >= rho - 0.01 {
            break;
        }
        let ((angle, rate, mount), info) = &infos[i];
        g += info;
        rho = r;
        chosen.push(ProposedRun {
            cone_angle_deg: *angle,
            rate_deg_s: *rate,
            mount: mount.names().clone(),
            duration_s: duration,
        });
    }
    (!chosen.is_empty()).then_some(Separation { runs: chosen, rho_now, rho_with: rho })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_proposed_run_prints_numbers_a_user_can_set() {
        let run = ProposedRun {
            cone_angle_deg: 19.74999882553065,
            rate_deg_s: -0.0000001,
            mount: ["+x".into(), "+y".into(), "+z".into()],
            duration_s: 60.2,
        };
        assert_eq!(run.to_string(), "a conic run at cone angle 19.75°, rate 0 °/s, mount [+x, +y, +z] (60 s)");
        let run = ProposedRun { cone_angle_deg: 20.0, rate_deg_s: 10.0, ..run };
        assert!(run.to_string().starts_with("a conic run at cone angle 20°, rate 10 °/s"), "{run}");
    }

    #[test]
    fn canonical_correlation_of_two_coefficients_is_their_correlation() {
        // Two parameters with information [[1, c], [c, 1]]: their estimates correlate −c.
        for c in [0.0, 0.5, 0.9, 0.999] {
            let g = DMatrix::from_row_slice(2, 2, &[1.0, c, c, 1.0]);
            let rho = canonical_correlation(&g, &[], &[0], &[1]);
            assert!((rho - c).abs() < 1e-6, "c {c}: rho {rho}");
        }
        // Exactly aliased: ρ ≈ 1.
        let g = DMatrix::from_row_slice(2, 2, &[1.0, 1.0, 1.0, 1.0]);
        assert!(canonical_correlation(&g, &[], &[0], &[1]) > 0.999);
        // Given a third coefficient: P = G⁻¹ has P₁₂ = 0.5, P₁₁ = P₂₂ = 1.5, so ρ = 1/3.
        let g = DMatrix::from_row_slice(3, 3, &[1.0, 0.5, 0.5, 0.5, 1.0, 0.0, 0.5, 0.0, 1.0]);
        let rho = canonical_correlation(&g, &[0], &[1], &[2]);
        assert!((rho - 1.0 / 3.0).abs() < 1e-6, "rho {rho}");
    }
}
