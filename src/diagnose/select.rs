//! Choosing effects on evidence, from the whitened Grams of [`super::space`].
//!
//! A candidate effect E is added to the current set S only when all of these hold:
//!
//! 1. **in-sample support**: the generalised-least-squares χ² reduction ΔQ = Q(S) − Q(S∪E)
//!    has p < [`P_ACCEPT`] against χ²(Δp), and ΔBIC = −ΔQ + Δp ln N < [`BIC_EVIDENCE`];
//! 2. **prediction of left-out runs**: refitted without each run in turn, S∪E predicts that
//!    run better than S, summed over runs, by at least [`HELDOUT_SHARE`] of ΔQ;
//! 3. **one size in every run**: E's coefficients estimated from each run alone (S held)
//!    agree — Cochran's Q = Σ_r (β_r − β̄)ᵀ G_r (β_r − β̄) is not both significant
//!    (p < [`P_HETEROGENEITY`]) and large (excess spread over [`MAX_SPREAD`] of β̄).
//!
//! An effect that only approximates what is really there (a wobble in some runs, a
//! saturation the catalogue models by a cubic) fails 2 or 3; noise that the AR model
//! describes fails 1 and 2.

use super::algebra::{pinv_sym, significant_part, Lsq};
use super::space::{RunGram, Universe};
use nalgebra::{DMatrix, DVector};
use serde::{Deserialize, Serialize};
use statrs::distribution::{ChiSquared, ContinuousCDF};

/// p-value below which the in-sample χ² reduction counts (many candidates are tried).
pub const P_ACCEPT: f64 = 1e-6;
/// ΔBIC below which an effect counts as supported (very strong evidence).
pub const BIC_EVIDENCE: f64 = -10.0;
/// Share of the in-sample χ² reduction the left-out runs must confirm.
pub const HELDOUT_SHARE: f64 = 0.25;
/// Cochran's Q p-value below which the per-run sizes differ.
pub const P_HETEROGENEITY: f64 = 1e-3;
/// Relative spread of the per-run sizes above which an effect is not one physical effect.
pub const MAX_SPREAD: f64 = 0.25;
/// The same for a nonlinear effect screened by its secant column: the column is exact only
/// at the true parameter, so runs that see different ranges of the input see different
/// sizes of it (the refit by variable projection then fits it properly).
pub const MAX_SPREAD_NONLINEAR: f64 = 1.0;

/// Standard errors a term of a run's systematic curve must exceed to count in its size.
const SIZE_Z: f64 = 3.0;

/// One fold (a run, or all runs) as a global Gram system.
#[derive(Debug, Clone)]
pub struct System {
    /// Gram of the global parameters.
    pub g: DMatrix<f64>,
    /// Cross products with the residual.
    pub b: DVector<f64>,
    /// Whitened residual sum of squares.
    pub yy: f64,
    /// Whitened samples.
    pub n: usize,
}

impl System {
    fn zeros(p: usize) -> Self {
        Self { g: DMatrix::zeros(p, p), b: DVector::zeros(p), yy: 0.0, n: 0 }
    }

    fn add(&mut self, other: &System) {
        self.g += &other.g;
        self.b += &other.b;
        self.yy += other.yy;
        self.n += other.n;
    }

    fn minus(&self, other: &System) -> System {
        System { g: &self.g - &other.g, b: &self.b - &other.b, yy: self.yy - other.yy, n: self.n - other.n }
    }
}

/// The evidence for one candidate effect given the current set.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Evidence {
    /// In-sample χ² reduction ΔQ (whitened).
    pub delta_q: f64,
    /// Coefficients the runs identify (rank gained).
    pub added_params: usize,
    /// χ²(Δp) p-value of ΔQ.
    pub p_value: f64,
    /// ΔBIC = −ΔQ + Δp ln N.
    pub delta_bic: f64,
    /// χ² reduction on left-out runs (each predicted from the others).
    pub heldout_gain: f64,
    /// Cochran's Q p-value of the per-run sizes.
    pub heterogeneity_p: f64,
    /// Excess spread of the per-run sizes relative to the pooled size.
    pub spread: f64,
    /// ΔQ per sensor (gyro, accel).
    pub delta_q_sensor: [f64; 2],
    /// Screened by secant columns (a nonlinear effect).
    pub nonlinear: bool,
}

impl Evidence {
    /// In-sample support and prediction of left-out runs (rules 1 and 2): the residual it
    /// takes is locked to the motion, whether or not the effect is its true form.
    pub fn predicts(&self) -> bool {
        self.unsupported().is_none()
    }

    /// Why rules 1 and 2 fail (None: both hold).
    fn unsupported(&self) -> Option<String> {
        if self.added_params == 0 {
            return Some("these runs cannot identify it".into());
        }
        if !(self.p_value < P_ACCEPT && self.delta_bic < BIC_EVIDENCE) {
            return Some(format!("no in-sample support (p = {:.1e}, ΔBIC = {:.1})", self.p_value, self.delta_bic));
        }
        if !(self.heldout_gain > 0.0 && self.heldout_gain >= HELDOUT_SHARE * self.delta_q) {
            return Some(format!(
                "does not predict left-out runs (χ² gain {:.1} there against {:.1} in the fit)",
                self.heldout_gain, self.delta_q
            ));
        }
        None
    }

    /// Why the effect is not accepted (None: accepted).
    pub fn rejection(&self) -> Option<String> {
        if let Some(why) = self.unsupported() {
            return Some(why);
        }
        let limit = if self.nonlinear { MAX_SPREAD_NONLINEAR } else { MAX_SPREAD };
        if self.heterogeneity_p < P_HETEROGENEITY && self.spread > limit {
            return Some(format!(
                "its size differs between runs by {:.0} % (p = {:.1e}): something else that looks like it",
                100.0 * self.spread,
                self.heterogeneity_p
            ));
        }
        None
    }
}

/// The size of one candidate coefficient from the all-run solution, with its standard error
/// under the noise model.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Estimate {
    /// Coefficient name.
    pub name: String,
    /// Value (SI).
    pub value: f64,
    /// Standard error (SI).
    pub std_error: f64,
}

/// The runs' Grams in the global parameter space.
#[derive(Clone)]
pub struct Space {
    /// The universe.
    pub universe: Universe,
    /// Per run: its Grams and noise.
    pub runs: Vec<RunGram>,
    /// Per run as a global system (the folds of leave-one-run-out).
    folds: Vec<System>,
    /// All runs.
    total: System,
    /// Per channel, all runs.
    channel_total: Vec<System>,
    /// Per channel: the slow noise (flicker, random walk) the runs' Grams carry as a random
    /// effect on their bases ([`super::slow`]).
    pub slow: Vec<Option<crate::estimate::slow::SlowNoise>>,
}

impl Space {
    /// Assembles the global systems from the runs' local Grams.
    pub fn new(universe: Universe, runs: Vec<RunGram>) -> Self {
        let p = universe.params.len();
        let mut total = System::zeros(p);
        let mut channel_total: Vec<System> = (0..6).map(|_| System::zeros(p)).collect();
        let mut folds = Vec::with_capacity(runs.len());
        for rg in &runs {
            let mut fold = System::zeros(p);
            for c in 0..6 {
                let mut one = scatter(&universe, rg, c);
                one.n = rg.noise[c].n;
                fold.add(&one);
                channel_total[c].add(&one);
            }
            total.add(&fold);
            folds.push(fold);
        }
        Self { universe, runs, folds, total, channel_total, slow: Vec::new() }
    }

    /// The same runs around a model whose coefficients `shift` moves ((global index, new
    /// value − fitted value) pairs): the all-run and left-out systems' cross products and χ²
    /// are those of the moved residual r − X·shift (the Grams are unchanged). The per-run
    /// Grams in `runs` (and so [`Self::systematic`], [`Self::heldout_channels`]) are not moved.
    pub fn moved(&self, shift: &[(usize, f64)]) -> Space {
        let mv = |s: &System| {
            let (b, yy) = shifted(s, shift);
            System { g: s.g.clone(), b, yy, n: s.n }
        };
        Space {
            universe: self.universe.clone(),
            runs: self.runs.clone(),
            folds: self.folds.iter().map(mv).collect(),
            total: mv(&self.total),
            channel_total: self.channel_total.iter().map(mv).collect(),
            slow: self.slow.clone(),
        }
    }

    /// The base model's free parameters.
    pub fn base_set(&self) -> Vec<usize> {
        (0..self.universe.params.len()).filter(|&i| self.universe.params[i].base).collect()
    }

    /// The candidate parameters of an effect.
    pub fn effect_params(&self, id: &str) -> Vec<usize> {
        (0..self.universe.params.len())
            .filter(|&i| !self.universe.params[i].base && self.universe.params[i].effect == id)
            .collect()
    }

    /// The information (whitened Gram) of all runs, plus `weight` times a further run's.
    pub fn information_with(&self, extra: Option<(&RunGram, f64)>) -> DMatrix<f64> {
        let mut g = self.total.g.clone();
        if let Some((rg, w)) = extra {
            for c in 0..6 {
                g += scatter(&self.universe, rg, c).g * w;
            }
        }
        g
    }

    /// The all-run solution on a set.
    pub fn solve(&self, set: &[usize]) -> Lsq {
        Lsq::solve(&self.total.g, &self.total.b, self.total.yy, set)
    }

    /// The all-run solution on a set under the slow noise as well: each run's Grams carry
    /// its random effect on the basis ([`super::slow::adjust_gram`], generalised least
    /// squares), so a wandering bias does not drag coefficients whose regressors are nearly
    /// constant within a run (gravity's share on a cone's axis) and leave their error at
    /// the cone harmonics. Without slow noise, [`Self::solve`].
    pub fn solve_slow(&self, set: &[usize]) -> Lsq {
        let carries = |rg: &RunGram| rg.slow.iter().any(|d| d.iter().any(|v| *v != 0.0));
        if !self.runs.iter().any(carries) {
            return self.solve(set);
        }
        let mut total = System::zeros(self.universe.params.len());
        for rg in &self.runs {
            for c in 0..6 {
                let mut g = rg.gram[c].clone();
                if let Some(d) = rg.slow.get(c) {
                    let width = self.universe.channel_params(c).count();
                    super::slow::adjust_gram(&mut g, width, rg.basis, d);
                }
                total.add(&scatter_gram(&self.universe, &g, c));
            }
        }
        Lsq::solve(&total.g, &total.b, total.yy, set)
    }

    /// Whitened samples over all runs.
    pub fn samples(&self) -> usize {
        self.total.n
    }

    /// The sizes of `cand` fitted with `set` on all runs and their standard errors. The
    /// Gram is whitened to unit innovation variance, so the covariance of the generalised
    /// least-squares solution is its (pseudo-)inverse on `set ∪ cand`.
    pub fn estimates(&self, set: &[usize], cand: &[usize]) -> Vec<Estimate> {
        let mut with: Vec<usize> = set.to_vec();
        with.extend(cand.iter().filter(|c| !set.contains(c)));
        let g = DMatrix::from_fn(with.len(), with.len(), |i, j| self.total.g[(with[i], with[j])]);
        let b = DVector::from_fn(with.len(), |i, _| self.total.b[with[i]]);
        let (pinv, _) = pinv_sym(&g);
        let beta = &pinv * &b;
        cand.iter()
            .filter_map(|&p| {
                let i = with.iter().position(|&w| w == p)?;
                let name = self.universe.params[p].name.clone();
                Some(Estimate { name, value: beta[i], std_error: pinv[(i, i)].max(0.0).sqrt() })
            })
            .collect()
    }

    /// χ² of each left-out run predicted by the set fitted on the other runs.
    pub fn heldout(&self, set: &[usize]) -> Vec<f64> {
        if self.folds.len() < 2 {
            return vec![0.0; self.folds.len()];
        }
        self.folds
            .iter()
            .map(|f| {
                let rest = self.total.minus(f);
                Lsq::solve(&rest.g, &rest.b, rest.yy, set).q_on(&f.g, &f.b, f.yy)
            })
            .collect()
    }

    /// χ² per channel of the all-run solution `l`.
    pub fn channel_q(&self, l: &Lsq) -> Vec<f64> {
        self.channel_total.iter().map(|s| l.q_on(&s.g, &s.b, s.yy)).collect()
    }

    /// χ² per channel of each left-out run, predicted by `set` fitted on the other runs
    /// (with the base coefficients outside `set` moved by `shift`: value − base value).
    pub fn heldout_channels(&self, set: &[usize], shift: &[(usize, f64)]) -> Vec<f64> {
        let mut out = vec![0.0; 6];
        for (ri, f) in self.folds.iter().enumerate() {
            let rest = self.total.minus(f);
            let (b, yy) = shifted(&rest, shift);
            let l = Lsq::solve(&rest.g, &b, yy, set);
            for (c, o) in out.iter_mut().enumerate() {
                let one = self.local_system(ri, c);
                let (b1, yy1) = shifted(&one, shift);
                *o += l.q_on(&one.g, &b1, yy1);
            }
        }
        out
    }

    fn local_system(&self, run: usize, c: usize) -> System {
        scatter(&self.universe, &self.runs[run], c)
    }

    /// The evidence for adding `cand` to `set` (whose all-run solution and held-out χ² are
    /// given).
    pub fn evidence(&self, set: &[usize], base: &Lsq, base_heldout: &[f64], cand: &[usize]) -> Evidence {
        let mut with: Vec<usize> = set.to_vec();
        with.extend(cand.iter().filter(|c| !set.contains(c)));
        let full = self.solve(&with);
        let delta_q = (base.q - full.q).max(0.0);
        let added = full.rank.saturating_sub(base.rank);
        let p_value =
            if added == 0 { 1.0 } else { ChiSquared::new(added as f64).map(|d| d.sf(delta_q)).unwrap_or(1.0) };
        let n = self.samples().max(2) as f64;
        let heldout: f64 = if self.folds.len() > 1 {
            self.heldout(&with).iter().zip(base_heldout).map(|(h1, h0)| h0 - h1).sum()
        } else {
            delta_q
        };
        let (heterogeneity_p, spread) = self.heterogeneity(&with, &full, cand);
        let q0 = self.channel_q(base);
        let q1 = self.channel_q(&full);
        let dq = |s: usize| (3 * s..3 * s + 3).map(|c| q0[c] - q1[c]).sum::<f64>();
        Evidence {
            delta_q,
            added_params: added,
            p_value,
            delta_bic: -delta_q + added as f64 * n.ln(),
            heldout_gain: heldout,
            heterogeneity_p,
            spread,
            delta_q_sensor: [dq(0), dq(1)],
            nonlinear: cand.iter().any(|&p| self.universe.is_secant(p)),
        }
    }

    /// Cochran's Q of the candidate's per-run coefficients, the rest of the joint solution
    /// `joint` (on `with` = set ∪ candidate) held at its all-run values: its p-value and the
    /// excess spread √(max(0, Q − dof) / β̄ᵀḠβ̄).
    fn heterogeneity(&self, with: &[usize], joint: &Lsq, cand: &[usize]) -> (f64, f64) {
        let k = cand.len();
        let set: Vec<(usize, f64)> =
            with.iter().enumerate().filter(|(_, p)| !cand.contains(p)).map(|(i, &p)| (p, joint.beta[i])).collect();
        let mut gbar = DMatrix::<f64>::zeros(k, k);
        let mut bbar = DVector::<f64>::zeros(k);
        let (mut q, mut dof) = (0.0, 0isize);
        for f in &self.folds {
            let g = DMatrix::from_fn(k, k, |i, j| f.g[(cand[i], cand[j])]);
            let b =
                DVector::from_fn(k, |i, _| f.b[cand[i]] - set.iter().map(|&(s, v)| f.g[(cand[i], s)] * v).sum::<f64>());
            let (pinv, rank) = pinv_sym(&g);
            // Runs that see almost nothing of the effect carry no information on its size.
            if rank == 0 {
                continue;
            }
            q += b.dot(&(&pinv * &b));
            dof += rank as isize;
            gbar += &g;
            bbar += &b;
        }
        let (pinv, rank) = pinv_sym(&gbar);
        let energy = bbar.dot(&(&pinv * &bbar));
        q -= energy;
        dof -= rank as isize;
        if dof <= 0 || energy <= 0.0 {
            return (1.0, 0.0);
        }
        let p = ChiSquared::new(dof as f64).map(|d| d.sf(q.max(0.0))).unwrap_or(1.0);
        (p, ((q - dof as f64).max(0.0) / energy).sqrt())
    }

    /// The systematic part each channel keeps under the all-run solution `l`: per run the
    /// GLS fit of the basis to what `l` leaves, pooled as χ² over runs. Its size is that of
    /// the fitted curve's terms that stand out of their noise ([`significant_part`]), and
    /// never more than the run's residual.
    pub fn systematic(&self, l: &Lsq) -> Vec<Leftover> {
        (0..6)
            .map(|c| {
                let idx: Vec<usize> = self.universe.channel_params(c).collect();
                let w = idx.len();
                let beta: Vec<f64> = idx.iter().map(|&p| l.value(p)).collect();
                let mut out = Leftover::default();
                for (ri, rg) in self.runs.iter().enumerate() {
                    let g = &rg.gram[c];
                    let nb = rg.basis;
                    let m = g.nrows();
                    let gbb = g.view((w, w), (nb, nb)).into_owned();
                    let z = DVector::from_fn(nb, |i, _| {
                        g[(w + i, m - 1)] - (0..w).map(|j| g[(w + i, j)] * beta[j]).sum::<f64>()
                    });
                    // The cross products' covariance: AR noise, plus the slow noise's random
                    // effect on the basis (super::slow).
                    let bb = match rg.slow.get(c) {
                        Some(d) => super::slow::basis_metric(&gbb, d),
                        None => gbb.clone(),
                    };
                    let (pinv, rank) = pinv_sym(&bb);
                    let ginv = pinv_sym(&gbb).0;
                    // The fitted curve and its covariance G⁺ Σ G⁺; its size is that of the
                    // terms that stand out of the noise (under near-unit-root noise the
                    // low-order terms alone would be many times the residual).
                    let raw = &ginv * &z;
                    let coef = significant_part(&raw, &(&ginv * &bb * &ginv), SIZE_Z * SIZE_Z);
                    out.chi2 += z.dot(&(&pinv * &z));
                    out.dof += rank;
                    let n = rg.noise[c].n as f64;
                    out.n += n;
                    // Mean square of the fitted curve: cᵀ (BᵀB/n) c (the basis is not orthogonal
                    // over a run of one cone period).
                    // No part of the residual is larger than the residual.
                    let ms = coef.dot(&(&rg.basis_ms * &coef)).clamp(0.0, rg.residual_ms[c]);
                    out.ss += n * ms;
                    out.ss_fitted += n * raw.dot(&(&rg.basis_ms * &raw)).max(0.0);
                    let chi_full = z.dot(&(&pinv * &z));
                    for (feature, cols, amp) in features(&coef, nb, rg.first_harmonic) {
                        // Where it sits: the feature whose removal from the basis loses the
                        // most χ² (the basis is not orthogonal over short runs).
                        let keep: Vec<usize> = (0..nb).filter(|i| !cols.contains(i)).collect();
                        let bk = DMatrix::from_fn(keep.len(), keep.len(), |i, j| bb[(keep[i], keep[j])]);
                        let zk = DVector::from_fn(keep.len(), |i, _| z[keep[i]]);
                        let loss = chi_full - zk.dot(&(pinv_sym(&bk).0 * &zk));
                        if out.worst.as_ref().is_none_or(|w| loss > w.3) {
                            out.worst = Some((ri, feature, amp, loss));
                        }
                    }
                }
                out
            })
            .collect()
    }
}

/// (feature, its basis columns, amplitude) of a run's basis coefficients: Some(0) the
/// constant, Some(h) cone harmonic h, None the slow (P1…P3) part.
fn features(coef: &DVector<f64>, nb: usize, first: usize) -> Vec<(Option<usize>, Vec<usize>, f64)> {
    let mut out =
        vec![(Some(0), vec![0], coef[0].abs()), (None, vec![1, 2, 3], coef[1].abs() + coef[2].abs() + coef[3].abs())];
    let mut i = 4;
    while i + 1 < nb {
        out.push((Some(first + (i - 4) / 2), vec![i, i + 1], coef[i].hypot(coef[i + 1])));
        i += 2;
    }
    out
}

/// What a channel keeps after a set of effects.
#[derive(Debug, Clone, Default)]
pub struct Leftover {
    /// Pooled χ² of the basis fits.
    pub chi2: f64,
    /// Its degrees of freedom.
    pub dof: usize,
    /// Σ n · mean square of the fitted basis curves' significant parts (SI²).
    pub ss: f64,
    /// The same of the whole fitted curves, noise included: above the recording's
    /// resolution or not.
    pub ss_fitted: f64,
    /// Samples.
    pub n: f64,
    /// Largest feature: (run index, feature, amplitude SI, χ² it carries).
    pub worst: Option<(usize, Option<usize>, f64, f64)>,
}

/// One run's channel as a global system: its local Gram scattered onto the global
/// parameters (the basis rows and columns left out).
fn scatter(u: &Universe, rg: &RunGram, c: usize) -> System {
    scatter_gram(u, &rg.gram[c], c)
}

/// A channel's local Gram `[columns | basis | r]` as a global system.
fn scatter_gram(u: &Universe, g: &DMatrix<f64>, c: usize) -> System {
    let idx: Vec<usize> = u.channel_params(c).collect();
    let m = g.nrows();
    let mut one = System::zeros(u.params.len());
    for (i, &gi) in idx.iter().enumerate() {
        for (j, &gj) in idx.iter().enumerate() {
            one.g[(gi, gj)] += g[(i, j)];
        }
        one.b[gi] += g[(i, m - 1)];
    }
    one.yy = g[(m - 1, m - 1)];
    one
}

fn shifted(s: &System, shift: &[(usize, f64)]) -> (DVector<f64>, f64) {
    let mut b = s.b.clone();
    let mut yy = s.yy;
    for &(i, d) in shift {
        yy -= 2.0 * d * s.b[i];
        for &(j, e) in shift {
            yy += d * s.g[(i, j)] * e;
        }
    }
    for r in 0..b.len() {
        b[r] -= shift.iter().map(|&(i, d)| s.g[(r, i)] * d).sum::<f64>();
    }
    (b, yy)
}
