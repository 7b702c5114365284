//! The feature space of a diagnosis, built in one pass over the runs.
//!
//! The *universe* is the base model's free coefficients plus every catalogue effect the
//! model lacks: linear effects by their regressors, nonlinear ones (time delay, dead zone)
//! by the secant of the model's output in each parameter (a Gauss–Newton column). For each
//! run and channel the pass:
//!
//! 1. takes the residual r of the base fit and removes its per-run *systematic basis*
//!    (Legendre polynomials P0…P3 of time, and for conic runs cos/sin hθ, h = 1…6 of the
//!    cone phase) to leave the noise;
//! 2. looks for narrow-band lines in its Welch spectrum, removes them and, on a conic run
//!    of [`FOLD_REVOLUTIONS`] or more, the mean per bin of the cone phase ([`FOLD_BINS`]
//!    bins: every harmonic of the cone up to about half of them — a hysteresis's square
//!    wave has them all), and fits what is left an AR(p) model (order by BIC,
//!    [`crate::stats::ArModel`]). The fold's bins sit at
//!    the cone's harmonics, where coloured noise has far less power than at zero frequency:
//!    their share of the noise is added back at the model's spectrum there ([`Fold`]), the
//!    basis's at its long-run variance;
//! 3. prewhitens the universe's columns, the basis and r with that AR filter, scales them
//!    to unit innovation variance, and accumulates their Gram matrix.
//!
//! Every later question — does an effect reduce the residual, does it predict a left-out
//! run, is its size the same in every run, what systematic part is left — is then linear
//! algebra on these Grams (generalised least squares, honest under coloured noise), with
//! no further pass over the samples.

use super::basis::PhaseFold;
pub use super::basis::{RunBasis, FOLD_BINS, FOLD_REVOLUTIONS, HARMONICS};
use super::secants::{Nonlinear, SecantBlock, Secants};
use crate::estimate::slow::SlowNoise;
use crate::estimate::{CoefStatus, Fit, FitRun};
use crate::model::{catalog, scale_matrix, CatalogEffect, Model, Predictor, Role, State, TermRef};
use crate::session::MotionSpec;
use crate::stats::gram::WhitenedGram;
use crate::stats::spectrum::{lines, refine_frequency, welch};
use crate::stats::ArModel;
use crate::units::SensorKind;
use nalgebra::DMatrix;

/// Samples per block of the Gram accumulation.
const BLOCK: usize = 512;

/// A coefficient of the universe.
#[derive(Debug, Clone, PartialEq)]
pub struct Param {
    /// Coefficient name (`gyro.c_xy`, `time_delay`, …).
    pub name: String,
    /// The catalogue effect it belongs to.
    pub effect: &'static str,
    /// Part of the base model (fitted there) rather than a candidate.
    pub base: bool,
    /// The base fit's value (0 or the effect's nominal for candidates).
    pub value: f64,
    /// The value it takes when its effect is absent.
    pub nominal: f64,
}

/// Where a local column comes from.
#[derive(Debug, Clone, Copy)]
enum Source {
    /// Term `k` of the augmented model's terms of the channel's sensor.
    Term(usize),
    /// Parameter `p` of nonlinear candidate `e` (a secant column, precomputed per run).
    Secant(usize, usize),
}

/// The universe: the augmented model (base plus every applicable linear candidate), the
/// nonlinear candidates, and for each channel the global parameters that act on it.
#[derive(Clone)]
pub struct Universe {
    /// Base model plus every applicable linear candidate effect.
    pub augmented: Model,
    /// Global parameters.
    pub params: Vec<Param>,
    /// Nonlinear candidates and the secant step of each of their parameters.
    nonlinear: Vec<Nonlinear>,
    /// Per channel: (global parameter index, source) of each local column.
    columns: [Vec<(usize, Source)>; 6],
    /// Augmented term values per sensor (base fit values, candidates at nominal).
    values: [Vec<f64>; 2],
    /// Candidate effect ids, in catalogue order.
    pub candidates: Vec<&'static str>,
}

impl Universe {
    /// The universe around a fitted base model. Temperature effects only with `has_temp`.
    pub fn new(base: &Model, fit: &Fit, has_temp: bool) -> Self {
        let mut augmented = base.clone();
        let mut nonlinear = Vec::new();
        let mut candidates = Vec::new();
        for e in catalog() {
            if base.has(e.id()) || (e.needs_temperature() && !has_temp) {
                continue;
            }
            match &e {
                CatalogEffect::Linear(_) => {
                    if augmented.add_effect(e.id()).is_ok() {
                        candidates.push(e.id());
                    }
                }
                CatalogEffect::Nonlinear(ne) => {
                    let mut m = Model::from_effects("probe", Vec::new());
                    if m.add_effect(e.id()).is_ok() {
                        if let Some(entry) = m.nonlinear().first().cloned() {
                            let steps = ne.params().iter().map(|d| d.scale).collect();
                            nonlinear.push((entry, steps, false));
                            candidates.push(e.id());
                        }
                    }
                }
            }
        }
        let mut params = Vec::new();
        let mut columns: [Vec<(usize, Source)>; 6] = Default::default();
        let mut values: [Vec<f64>; 2] = Default::default();
        for (si, sensor) in SensorKind::BOTH.into_iter().enumerate() {
            let terms = augmented.terms(sensor);
            let sf = fit.sensor(sensor);
            for (k, t) in terms.iter().enumerate() {
                let in_base = base.has(t.effect.id());
                let fitted = sf.coefficients.iter().find(|c| c.name == t.term.name);
                let value = if in_base {
                    fitted.map_or(
                        match t.status {
                            crate::model::TermStatus::Fixed(v) => v,
                            _ => t.term.nominal,
                        },
                        |c| c.value,
                    )
                } else {
                    t.term.nominal
                };
                values[si].push(value);
                let free = if in_base {
                    fitted.is_some_and(|c| c.status == CoefStatus::Fitted)
                } else {
                    matches!(t.status, crate::model::TermStatus::Fitted)
                };
                if free {
                    columns[3 * si + t.term.channel].push((params.len(), Source::Term(k)));
                    params.push(Param {
                        name: t.term.name.clone(),
                        effect: t.effect.id(),
                        base: in_base,
                        value,
                        nominal: t.term.nominal,
                    });
                }
            }
        }
        // The model's own nonlinear parameters, free around their fitted values: the Grams'
        // solution then carries a Gauss–Newton step on them over all samples (a search on
        // reduced data is refined here).
        for e in base.nonlinear().iter().filter(|e| e.fitted) {
            let mut entry = e.clone();
            let fitted: Vec<f64> =
                fit.nonlinear.iter().filter(|p| p.effect == e.effect.id()).map(|p| p.value).collect();
            if fitted.len() == entry.values.len() {
                entry.values = fitted;
            }
            let steps = e.effect.params().iter().map(|d| 0.01 * d.scale).collect();
            nonlinear.push((entry, steps, true));
        }
        for (ei, (entry, _, in_base)) in nonlinear.iter().enumerate() {
            for (pi, d) in entry.effect.params().iter().enumerate() {
                let g = params.len();
                params.push(Param {
                    name: d.name.clone(),
                    effect: entry.effect.id(),
                    base: *in_base,
                    value: entry.values[pi],
                    nominal: d.nominal,
                });
                for (si, sensor) in SensorKind::BOTH.into_iter().enumerate() {
                    if entry.effect.sensor().is_none_or(|s| s == sensor) {
                        for ch in 0..3 {
                            columns[3 * si + ch].push((g, Source::Secant(ei, pi)));
                        }
                    }
                }
            }
        }
        Self { augmented, params, nonlinear, columns, values, candidates }
    }

    /// Global parameter indices of the local columns of channel `c`.
    pub fn channel_params(&self, c: usize) -> impl Iterator<Item = usize> + '_ {
        self.columns[c].iter().map(|x| x.0)
    }

    /// Whether global parameter `p` is a nonlinear candidate's (secant column).
    pub fn is_secant(&self, p: usize) -> bool {
        self.columns.iter().flatten().any(|&(g, src)| g == p && matches!(src, Source::Secant(..)))
    }

    /// Number of local columns of channel `c`.
    pub fn width(&self, c: usize) -> usize {
        self.columns[c].len()
    }

    /// What the Grams of sensor `si`'s channels are drawn from besides the runs and their
    /// noise models ([`SensorKey`]).
    pub fn sensor_key(&self, si: usize) -> SensorKey {
        let sensor = SensorKind::BOTH[si];
        let acts = |e: &crate::model::NonlinearEntry| e.effect.sensor().is_none_or(|s| s == sensor);
        let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<u64>>();
        SensorKey {
            terms: self
                .augmented
                .terms(sensor)
                .iter()
                .zip(&self.values[si])
                .map(|(t, v)| (t.term.name.clone(), v.to_bits()))
                .collect(),
            columns: std::array::from_fn(|ch| {
                self.columns[3 * si + ch]
                    .iter()
                    .map(|&(g, src)| {
                        (self.params[g].name.clone(), self.params[g].base, matches!(src, Source::Secant(..)))
                    })
                    .collect()
            }),
            nonlinear: self
                .nonlinear
                .iter()
                .filter(|(e, _, _)| acts(e))
                .map(|(e, steps, in_base)| (e.effect.id(), bits(&e.values), bits(steps), *in_base))
                .collect(),
        }
    }
}

/// What the Grams of one sensor's channels are drawn from, besides the runs and their noise
/// models: the augmented terms of the sensor with their values (the base fit's, or the
/// nominal of a candidate), each channel's columns (parameter name, whether the base
/// model's, whether a secant), and the nonlinear entries acting on the sensor (id, values,
/// secant steps, whether the base model's: its parameters at the fit's values). The
/// residual follows from the same terms, values and nonlinear parameters; so two universes
/// with equal keys draw the same Grams for that sensor's channels on the same runs under
/// the same noise models, and an analysis after an effect of the other sensor was added
/// keeps them ([`run_gram`]'s `kept`).
#[derive(Debug, Clone, PartialEq)]
pub struct SensorKey {
    terms: Vec<(String, u64)>,
    columns: [Vec<(String, bool, bool)>; 3],
    nonlinear: Vec<(&'static str, Vec<u64>, Vec<u64>, bool)>,
}

/// The noise of one channel in one run.
#[derive(Debug, Clone, PartialEq)]
pub struct RunNoise {
    /// AR model of the residual after its systematic basis.
    pub ar: ArModel,
    /// Samples.
    pub n: usize,
}

/// A narrow-band line found in one run and channel.
#[derive(Debug, Clone, PartialEq)]
pub struct RunLine {
    /// Channel 0..6.
    pub channel: usize,
    /// Frequency, Hz.
    pub frequency_hz: f64,
    /// Amplitude of the fitted sinusoid, SI.
    pub amplitude: f64,
    /// Peak power over the continuum.
    pub ratio: f64,
    /// Peak power spectral density, unit²/Hz.
    pub power: f64,
    /// Sampling rate of the run, Hz.
    pub fs_hz: f64,
}

/// One run's contribution: per channel the whitened Gram of [local columns | basis | r].
#[derive(Debug, Clone)]
pub struct RunGram {
    /// Per channel: the Gram (width + basis + 1 square).
    pub gram: Vec<DMatrix<f64>>,
    /// Basis size of this run.
    pub basis: usize,
    /// Lowest cone harmonic in the basis (harmonics first..=6 follow the Legendre part).
    pub first_harmonic: usize,
    /// Per channel noise model.
    pub noise: Vec<RunNoise>,
    /// Lines found.
    pub lines: Vec<RunLine>,
    /// The run's cone frequency, Hz (None unless conic).
    pub cone_hz: Option<f64>,
    /// Mean square of each channel's recorded output (for the recording's resolution).
    pub output_ms: [f64; 6],
    /// Mean square of each channel's base residual: no noise or systematic part of it is
    /// larger.
    pub residual_ms: [f64; 6],
    /// BᵀB / n of the basis over the run (unwhitened): the mean square of a fitted curve
    /// with coefficients c is cᵀ (BᵀB/n) c.
    pub basis_ms: DMatrix<f64>,
    /// Per channel: the covariance of the basis coefficients the slow noise makes (empty or
    /// zero without slow noise, [`super::slow`]).
    pub slow: Vec<DMatrix<f64>>,
    /// The run's basis functions (for other Grams that carry the same random effect).
    pub run_basis: RunBasis,
}

/// What the first look at one run's residual finds: per channel the autocovariances of
/// its noise (the residual less its basis fit), the lines in its spectrum.
#[derive(Debug, Clone)]
pub struct RunNoiseStats {
    /// The run's basis.
    pub basis: RunBasis,
    /// BᵀB / n.
    pub basis_ms: DMatrix<f64>,
    /// Per channel γ₀…γ_P of the noise.
    pub acov: Vec<Vec<f64>>,
    /// Samples.
    pub n: usize,
    /// Lines found.
    pub lines: Vec<RunLine>,
    /// Mean square of each channel's recorded output.
    pub output_ms: [f64; 6],
    /// Mean square of each channel's base residual.
    pub residual_ms: [f64; 6],
    /// What the phase fold removed (None: no fold).
    pub fold: Option<Fold>,
}

/// The first look at one run (module documentation, steps 1–2): `r` is the base residual
/// per channel (cleaned in place: at 10⁷ samples a run's six channels are 27 MB, and a
/// copy of them per worker was the diagnosis's largest transient) and `output_ss` each
/// channel's sum of squared recorded outputs, as [`super::picture::run_residual`] returns
/// them.
pub fn run_noise(
    run: &FitRun<'_>,
    motion: &MotionSpec,
    (mut r, output_ss): (Vec<Vec<f64>>, [f64; 6]),
) -> RunNoiseStats {
    let n = run.len().min(r.iter().map(Vec::len).min().unwrap_or(0));
    let t = &run.track.t_s[..n];
    let basis = RunBasis::new(t, motion);
    let nb = basis.size;
    // BᵀB and BᵀR a block of rows at a time (one product each, by faer), then the
    // residual less its basis fit, each channel's column less one basis column at a time.
    const ROWS: usize = 256;
    let mut rows = vec![0.0; ROWS * nb];
    let mut row = Vec::new();
    let mut bb = faer::Mat::<f64>::zeros(nb, nb);
    let mut br = faer::Mat::<f64>::zeros(nb, 6);
    let mut rr = vec![0.0; ROWS * 6];
    for k0 in (0..n).step_by(ROWS) {
        let len = (n - k0).min(ROWS);
        basis.rows_into(&t[k0..k0 + len], &mut row, &mut rows, ROWS);
        for (c, rc) in r.iter().enumerate() {
            rr[c * ROWS..][..len].copy_from_slice(&rc[k0..k0 + len]);
        }
        crate::stats::gram::add_block_lower(&mut bb, &rows, ROWS, len, 1.0);
        crate::stats::gram::add_block_cross(&mut br, &rows, &rr, ROWS, len, 1.0);
    }
    let bb = DMatrix::from_fn(nb, nb, |i, j| if i >= j { bb[(i, j)] } else { bb[(j, i)] });
    let br = DMatrix::from_fn(nb, 6, |i, c| br[(i, c)]);
    let basis_ms = &bb / n.max(1) as f64;
    let coef = crate::diagnose::algebra::solve_sym(&bb, &br);
    let span = t.last().copied().unwrap_or(0.0) - t.first().copied().unwrap_or(0.0);
    let fs_hz = if n > 1 { (n - 1) as f64 / span.max(f64::MIN_POSITIVE) } else { 1.0 };
    let mut acov = Vec::with_capacity(6);
    let mut found = Vec::new();
    let residual_ms = std::array::from_fn(|c| {
        r.get(c).map_or(0.0, |rc| rc[..n].iter().map(|v| v * v).sum::<f64>()) / n.max(1) as f64
    });
    for cl in r.iter_mut() {
        cl.truncate(n);
    }
    for k0 in (0..n).step_by(ROWS) {
        let len = (n - k0).min(ROWS);
        basis.rows_into(&t[k0..k0 + len], &mut row, &mut rows, ROWS);
        for (c, cl) in r.iter_mut().enumerate() {
            for b in 0..nb {
                let w = coef[(b, c)];
                for (o, v) in cl[k0..k0 + len].iter_mut().zip(&rows[b * ROWS..][..len]) {
                    *o -= w * v;
                }
            }
        }
    }
    let bins = basis.fold_bins(n);
    let mut fold = PhaseFold::new(bins);
    // Each sample's phase bin, worked out once for the six channels.
    let sample_bins = basis.phase.map(|phase| fold.bins(t, phase)).unwrap_or_default();
    for (c, mut clean) in r.into_iter().enumerate() {
        // Lines are not noise: their sinusoids leave before the noise is modelled.
        let here = run_lines(c, &clean, t, fs_hz);
        for l in &here {
            crate::stats::spectrum::remove_sinusoid(&mut clean, t, l.frequency_hz);
        }
        // Nor is what follows the cone phase beyond the basis's harmonics (the square wave
        // of a hysteresis has them all): modelled as noise it would make the AR model
        // resonate at low frequency and hide the very effect that leaves it.
        fold.remove(&mut clean, &sample_bins);
        acov.push(crate::stats::ar::autocovariances(&clean, crate::stats::ar::MAX_ORDER));
        found.extend(here);
    }
    let output_ms = output_ss.map(|s| s / n.max(1) as f64);
    let fold = (bins > 0).then(|| Fold {
        cone_hz: basis.cone_hz().unwrap_or(0.0),
        fs_hz,
        harmonics: (HARMONICS + 1, bins / 2),
    });
    RunNoiseStats { basis, basis_ms, acov, n, lines: found, output_ms, residual_ms, fold }
}

/// The cone harmonics a run's phase fold took from its noise beyond the basis's.
#[derive(Debug, Clone, Copy)]
pub struct Fold {
    cone_hz: f64,
    fs_hz: f64,
    /// First and last harmonic removed.
    harmonics: (usize, usize),
}

impl Fold {
    /// What the fold took from the autocovariances γ̂₀…γ̂_{lags−1} of a run of `n` samples
    /// under noise `ar`: each harmonic h a pair of sinusoids, (2/n)·S(f_h)·cos(2π f_h l / fs)
    /// with S(f) = psd(f)·fs/2 the variance per degree of freedom at f.
    fn bias(&self, ar: &ArModel, n: usize, lags: usize) -> Vec<f64> {
        let mut out = vec![0.0; lags];
        for h in self.harmonics.0..=self.harmonics.1 {
            let f = h as f64 * self.cone_hz;
            let s = ar.psd(f, self.fs_hz) * self.fs_hz / 2.0;
            for (l, o) in out.iter_mut().enumerate() {
                *o += 2.0 / n.max(1) as f64 * s * (std::f64::consts::TAU * f * l as f64 / self.fs_hz).cos();
            }
        }
        out
    }
}

/// One AR model per channel for the whole session (the noise of a channel is one process
/// in every run): orders by BIC on the autocovariances pooled over runs, so that short runs
/// do not pick orders from the few samples they have.
///
/// Removing a run's basis (m smooth functions of n samples) takes about m/n of the noise's
/// low-frequency power from every short-lag autocovariance: E γ̂_l ≈ γ_l − (m/n)·LRV, with
/// LRV = σ²_e/(1 − Σφ)² the long-run variance. Uncorrected, that dip at low frequency makes
/// BIC choose a long AR filter that amplifies exactly the slow variations the systematic
/// test looks for; the bias is added back, the LRV taken from the model, three times.
pub fn pooled_noise(stats: &[RunNoiseStats]) -> Vec<ArModel> {
    (0..6)
        .map(|c| {
            let lags = stats.iter().map(|s| s.acov[c].len()).min().unwrap_or(0);
            let n: usize = stats.iter().map(|s| s.n).sum();
            let removed: usize = stats.iter().map(|s| s.basis.size).sum();
            let gamma: Vec<f64> = (0..lags)
                .map(|l| stats.iter().map(|s| s.acov[c][l] * s.n as f64).sum::<f64>() / n.max(1) as f64)
                .collect();
            let share = removed as f64 / n.max(1) as f64;
            let mut ar = ArModel::from_autocov(&gamma, n);
            for _ in 0..3 {
                let lrv = long_run_variance(&ar).min(1e3 * ar.marginal_var.max(f64::MIN_POSITIVE));
                let mut corrected: Vec<f64> = gamma.iter().map(|g| g + share * lrv).collect();
                for st in stats {
                    if let Some(f) = st.fold {
                        let w = st.n as f64 / n.max(1) as f64;
                        for (g, b) in corrected.iter_mut().zip(f.bias(&ar, st.n, lags)) {
                            *g += w * b;
                        }
                    }
                }
                ar = ArModel::from_autocov(&corrected, n);
            }
            ar
        })
        .collect()
}

/// σ²_e / (1 − Σ φ)²: the spectral density at zero frequency times 2π (the variance of a
/// mean scales as LRV/n).
fn long_run_variance(ar: &ArModel) -> f64 {
    let s = 1.0 - ar.phi.iter().sum::<f64>();
    if s.abs() < 1e-6 {
        ar.marginal_var
    } else {
        ar.innovation_var / (s * s)
    }
}

/// A run's noise per channel: the session's pooled AR model (`pooled`) with the run's
/// own innovation variance, from its autocovariances with what its basis took from the
/// noise added back.
pub fn run_noises(stats: &RunNoiseStats, pooled: &[ArModel]) -> Vec<RunNoise> {
    let n = stats.n;
    let b = stats.basis;
    (0..6)
        .map(|c| {
            // The run's own autocovariances, with its basis's share of the bias added back.
            let share = b.size as f64 / n.max(1) as f64;
            let lrv = long_run_variance(&pooled[c]);
            let mut g: Vec<f64> = stats.acov[c].iter().map(|g| g + share * lrv).collect();
            if let Some(f) = stats.fold {
                for (g, b) in g.iter_mut().zip(f.bias(&pooled[c], n, stats.acov[c].len())) {
                    *g += b;
                }
            }
            // The bias added back estimates what the basis took from the noise; under a
            // near-unit-root model it can exceed the whole residual, which holds the noise.
            let ar = ArModel {
                phi: pooled[c].phi.clone(),
                innovation_var: pooled[c].innovation_of(&g),
                marginal_var: g.first().copied().unwrap_or(0.0).min(stats.residual_ms[c]),
            };
            RunNoise { ar, n }
        })
        .collect()
}

/// Per channel the covariance of a run's basis coefficients under the slow noise
/// (`slow`: per channel, over a session of that many seconds; [`super::slow`]).
pub fn run_slow(run: &FitRun<'_>, stats: &RunNoiseStats, slow: (&[Option<SlowNoise>], f64)) -> Vec<DMatrix<f64>> {
    let b = stats.basis;
    let basis = super::slow::Basis { size: b.size, cone_hz: b.cone_hz(), row: &|t, out: &mut [f64]| b.row(t, out) };
    super::slow::basis_covariances(&basis, &run.track.t_s[..run.len()], &stats.basis_ms, slow.0, slow.1)
}

/// The whitened Grams of one run (module documentation, step 3) with the session's noise
/// models; each run keeps its own innovation variance. With slow noise (`slow`, per
/// channel, over a session of `span_s`), the run keeps the covariance of its basis
/// coefficients under it, for the systematic test ([`super::slow`]).
#[allow(clippy::too_many_arguments)]
pub fn run_gram(
    u: &Universe,
    base: &Model,
    fit: &Fit,
    run: &FitRun<'_>,
    stats: RunNoiseStats,
    pooled: &[ArModel],
    r: &[Vec<f64>],
    slow: (&[Option<SlowNoise>], f64),
    kept: [Option<&RunGram>; 2],
) -> RunGram {
    let b = stats.basis;
    let noise = run_noises(&stats, pooled);
    let secants = Secants::new(&u.nonlinear, base, fit, run);
    // A sensor's Grams from an earlier analysis of this run serve when its noise models
    // are those it was drawn under (the caller vouches for the rest: equal sensor keys).
    let kept = [0, 1].map(|si| {
        kept[si]
            .filter(|k| k.noise.get(3 * si..3 * si + 3) == noise.get(3 * si..3 * si + 3))
            .and_then(|k| k.gram.get(3 * si..3 * si + 3))
    });
    let gram = channel_grams(u, run, &noise, &b, r, &secants, kept);
    let slow_cov = run_slow(run, &stats, slow);
    RunGram {
        gram,
        basis: b.size,
        first_harmonic: b.first,
        noise,
        slow: slow_cov,
        output_ms: stats.output_ms,
        residual_ms: stats.residual_ms,
        // A line must also stand out of the noise model's spectrum: a steep continuum (AR
        // noise at low frequency) fools a running median, not the model.
        lines: stats
            .lines
            .into_iter()
            .filter_map(|mut l| {
                let model = pooled[l.channel].psd(l.frequency_hz, l.fs_hz);
                let ratio = if model > 0.0 { l.power / model } else { f64::INFINITY };
                l.ratio = l.ratio.min(ratio);
                (ratio >= LINE_RATIO).then_some(l)
            })
            .collect(),
        cone_hz: b.cone_hz(),
        basis_ms: stats.basis_ms,
        run_basis: b,
    }
}

/// The whitened Gram of a run that has not been recorded (outputs and residual zero):
/// what it would add to the information on every parameter, with the session's noise
/// models (`noise`, per channel) scaled to the run's length. For planning a run that
/// separates candidates the recorded runs cannot tell apart.
pub fn design_gram(
    u: &Universe,
    base: &Model,
    fit: &Fit,
    run: &FitRun<'_>,
    motion: &MotionSpec,
    noise: &[RunNoise],
) -> RunGram {
    let n = run.len();
    let t = &run.track.t_s[..n];
    let b = RunBasis::new(t, motion);
    let noise: Vec<RunNoise> = noise.iter().map(|x| RunNoise { ar: x.ar.clone(), n }).collect();
    let secants = Secants::new(&u.nonlinear, base, fit, run);
    let zero: Vec<Vec<f64>> = (0..6).map(|_| vec![0.0; n]).collect();
    let gram = channel_grams(u, run, &noise, &b, &zero, &secants, [None, None]);
    RunGram {
        gram,
        basis: b.size,
        first_harmonic: b.first,
        noise,
        slow: Vec::new(),
        output_ms: [0.0; 6],
        residual_ms: [0.0; 6],
        lines: Vec::new(),
        cone_hz: b.cone_hz(),
        run_basis: b,
        basis_ms: DMatrix::zeros(b.size, b.size),
    }
}

/// Peak power over the continuum a line must reach (against the running median of its
/// neighbours and against the session's noise model).
const LINE_RATIO: f64 = 4.0;
/// Family-wise false-line probability per channel and run (a lot of 50 units has ~3000).
const LINE_ALPHA: f64 = 1e-6;

/// Lines in one channel's noise: Welch segments of about an eighth of the run (at most
/// 8192 samples), continuum from ±8 bins, family-wise level [`LINE_ALPHA`] per channel and run.
fn run_lines(channel: usize, clean: &[f64], t: &[f64], fs_hz: f64) -> Vec<RunLine> {
    let len = (clean.len() / 8).clamp(64, 8192);
    let Some(psd) = welch(clean, fs_hz, len) else { return Vec::new() };
    let span = t.last().copied().unwrap_or(0.0) - t.first().copied().unwrap_or(0.0);
    // Below a few cycles per run a "line" is the slow part of the residual.
    let min_hz = (8.0 / span.max(f64::MIN_POSITIVE)).max(3.0 * psd.df_hz);
    let mut found = lines(&psd, 8, LINE_ALPHA, LINE_RATIO, min_hz);
    found.sort_by(|a, b| b.ratio.total_cmp(&a.ratio));
    found
        .into_iter()
        .take(4)
        .map(|l| {
            let (f, a) = refine_frequency(clean, t, l.frequency_hz, psd.df_hz);
            RunLine { channel, frequency_hz: f, amplitude: a, ratio: l.ratio, power: psd.power[l.bin], fs_hz }
        })
        .collect()
}

/// The whitened Grams of the six channels of one run, built block by block: the states
/// and the basis rows of a block are evaluated once for all channels; each channel's block
/// of unwhitened columns is prewhitened and its Gram updated ([`WhitenedGram`]). A
/// sensor's three Grams in `kept` are taken as they are (nothing of that sensor is
/// evaluated).
fn channel_grams(
    u: &Universe,
    run: &FitRun<'_>,
    noise: &[RunNoise],
    basis: &RunBasis,
    r: &[Vec<f64>],
    secants: &Secants,
    kept: [Option<&[DMatrix<f64>]>; 2],
) -> Vec<DMatrix<f64>> {
    let drawn = kept.map(|k| k.is_none());
    if drawn == [false, false] {
        return kept.iter().flatten().flat_map(|k| k.iter().cloned()).collect();
    }
    let n = run.len();
    let nb = basis.size;
    let terms: [Vec<TermRef<'_>>; 2] = SensorKind::BOTH.map(|s| u.augmented.terms(s));
    let k_matrix: [[[f64; 3]; 3]; 2] = [0, 1].map(|si| scale_matrix(&terms[si], &u.values[si]));
    // The model's outputs, for the secant columns (built once per run, not per block).
    let predict = [0, 1].map(|si| Predictor::new(&terms[si], &u.values[si]));
    let mut chans: Vec<WhitenedGram> =
        (0..6).map(|c| WhitenedGram::new(u.width(c) + nb + 1, &noise[c].ar, BLOCK)).collect();
    // Each term column as a weighted sum of the block's regressors (worked out once per
    // run); each regressor a column needs, evaluated once per block for all channels.
    let recipes: Vec<Vec<Vec<(usize, f64)>>> = (0..6)
        .map(|c| {
            let (si, ch) = (c / 3, c % 3);
            let recipe = |src: &Source| match *src {
                Source::Term(k) => term_recipe(&terms[si], &u.values[si], &k_matrix[si], ch, k),
                Source::Secant(..) => Vec::new(),
            };
            u.columns[c].iter().map(|(_, src)| recipe(src)).collect()
        })
        .collect();
    let needed: [Vec<usize>; 2] = [0, 1].map(|si| {
        if !drawn[si] {
            return Vec::new();
        }
        let mut v: Vec<usize> = recipes[3 * si..3 * si + 3].iter().flatten().flatten().map(|p| p.0).collect();
        v.sort_unstable();
        v.dedup();
        v
    });
    let mut regs: [Vec<f64>; 2] = [0, 1].map(|si| vec![0.0; terms[si].len() * BLOCK]);
    let mut states: Vec<State> = Vec::with_capacity(BLOCK);
    let mut basis_rows = DMatrix::<f64>::zeros(BLOCK, nb);
    let mut row = Vec::new();
    let mut secant_block = SecantBlock::default();
    let t = &run.track.t_s;
    let mut k0 = 0;
    while k0 < n {
        let k1 = (k0 + BLOCK).min(n);
        let len = k1 - k0;
        states.clear();
        run.states_into(k0..k1, &mut states);
        if !u.nonlinear.is_empty() {
            secants.fill(&predict, run, k0, &states, drawn, &mut secant_block);
        }
        basis.rows_into(&t[k0..k1], &mut row, basis_rows.as_mut_slice(), BLOCK);
        for si in 0..2 {
            for &ti in &needed[si] {
                terms[si][ti].regressors(&states, &mut regs[si][ti * BLOCK..][..len]);
            }
        }
        for (c, chn) in chans.iter_mut().enumerate().filter(|(c, _)| drawn[c / 3]) {
            let si = c / 3;
            let width = u.width(c);
            for (j, &(_, src)) in u.columns[c].iter().enumerate() {
                match src {
                    Source::Term(_) => {
                        let recipe = &recipes[c][j];
                        let out = chn.column(j, len);
                        if let [(ti, 1.0)] = recipe.as_slice() {
                            out.copy_from_slice(&regs[si][ti * BLOCK..][..len]);
                            continue;
                        }
                        out.fill(0.0);
                        for &(ti, w) in recipe {
                            for (o, v) in out.iter_mut().zip(&regs[si][ti * BLOCK..][..len]) {
                                *o += w * v;
                            }
                        }
                    }
                    Source::Secant(e, pi) => {
                        for (o, s) in chn.column(j, len).iter_mut().zip(&secant_block.cols[e][pi]) {
                            *o = s[c];
                        }
                    }
                }
            }
            for b in 0..nb {
                chn.column(width + b, len).copy_from_slice(&basis_rows.as_slice()[b * BLOCK..b * BLOCK + len]);
            }
            chn.column(width + nb, len).copy_from_slice(&r[c][k0..k1]);
            chn.commit(len);
        }
        k0 = k1;
    }
    chans
        .into_iter()
        .enumerate()
        .map(|(c, g)| match kept[c / 3] {
            Some(k) => k[c % 3].clone(),
            None => g.finish(),
        })
        .collect()
}

/// The Gauss–Newton column of term `ti` (of `terms`) in output channel `ch`, as a weighted
/// sum Σ w·regressor(term) over `terms`: its regressor for an output-side term; K_i·(its
/// input perturbation) for an input-side term (eq. u = K(x+Δ)); for an entry K_ij of the
/// scale matrix, x_j plus the input perturbation Δ_j the model's input-side terms (fitted
/// `values`) put on axis j. An effect's terms are consecutive in `terms`.
fn term_recipe(terms: &[TermRef<'_>], values: &[f64], k: &[[f64; 3]; 3], ch: usize, ti: usize) -> Vec<(usize, f64)> {
    let t = &terms[ti];
    let comps = t.input_components();
    let mut out: Vec<(usize, f64)> = if comps.is_empty() {
        vec![(ti, 1.0)]
    } else {
        comps.iter().map(|&(j, kj)| (ti - t.index + kj, k[ch][j])).collect()
    };
    if let Role::Scale(j) = t.term.role {
        for (oi, (o_t, v)) in terms.iter().zip(values).enumerate() {
            if *v == 0.0 || o_t.term.channel != ch {
                continue;
            }
            out.extend(
                o_t.input_components().into_iter().filter(|c| c.0 == j).map(|(_, kj)| (oi - o_t.index + kj, *v)),
            );
        }
    }
    out
}
