//! Slow noise in the fit's covariance: flicker (bias instability) and bias random walk.
//!
//! The white-noise covariance σ²(ΦᵀΦ)⁻¹, even inflated by the residual's short-lag long-run
//! variance (Newey–West), misses noise whose correlation time is comparable to a run or to
//! the session: a wandering bias moves every run's offset, and a coefficient whose
//! regressor is nearly constant within a run (the accelerometer's K on gravity, a bias)
//! is estimated from those offsets. This module measures the slow part and adds its
//! contribution to the covariance.
//!
//! 1. **Measure.** The residual of each run is averaged over blocks of L seconds; the
//!    Allan variance of the block means at τ = L, 2L, 4L … (up to a third of a run) is fitted
//!    by non-negative least squares with σ²_A(τ) = N²/τ + B² a_F(τ) + K² τ/3 (IEEE 952
//!    white, flicker, random walk; a_F the Allan variance of the unit flicker model below).
//! 2. **Model.** Flicker is a sum of first-order Gauss–Markov processes with time constants
//!    two per decade from L to the session's span, variances B² ln r/π each (their sum
//!    approximates S(f) = B²/(πf)); the random walk has variogram K²|Δt|. Block means of
//!    these have closed-form covariances: for a Gauss–Markov process of variance σ² and
//!    time constant T, Var = 2σ²(T/L)²(L/T − 1 + e^{−L/T}) within a block and
//!    σ² e^{−Δ/T} Π_b (T/L_b)(e^{L_b/2T} − e^{−L_b/2T}) between blocks Δ apart; for the
//!    random walk −½K²|Δ| (−½K²L/3 within a block), a variogram: the constant it leaves
//!    out is absorbed by the bias, which is judged against the session's average.
//! 3. **Propagate.** With A = (ΦᵀΦ)⁻¹ and S_b the block sums of the regressors, the error
//!    of the estimate is Σ_b d_b s̄_b with d_b = A S_b − e_bias n_b/N (the session-averaged
//!    bias is the target), so the slow part adds Σ_{b,b'} d_b d_bᵀ' C(b, b') to the
//!    covariance (sandwich form, Newey & West 1987 with a parametric kernel). Between
//!    blocks each pole's covariance is a product of a factor of each block's time, so the
//!    double sum is carried forward in time as running sums: linear in the blocks.
//!
//! The pass streams the samples once more in fixed memory (per block: q sums per channel).

use super::channel::channel_plan;
use super::channel::Columns;
use super::channel::{Samples, BLOCK};
use super::{ChannelFit, CoefStatus};
use crate::model::TermRef;
use nalgebra::{DMatrix, DVector};
use serde::{Deserialize, Serialize};

/// The slow noise read off one channel's residual (SI units of the channel).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, Default)]
pub struct SlowNoise {
    /// White density N, unit/√Hz (at the block scale).
    pub white_density: f64,
    /// Bias instability B (flicker), unit.
    pub bias_instability: f64,
    /// Rate random walk K, unit/√s.
    pub random_walk: f64,
    /// Standard-error inflation of the coefficients by the slow part: the largest ratio of
    /// a standard error with it to the same without.
    pub se_inflation: f64,
    /// The block length the residual was averaged over, s (the shortest flicker time
    /// constant modelled: faster noise is in the white and AR part).
    #[serde(default)]
    pub block_s: f64,
    /// Log-likelihood ratio (restricted, on the same block means) of a different constant
    /// offset in each run (a turn-on bias: white within runs, jumps between them) over the
    /// flicker and walk: above [`TURN_ON_EVIDENCE`] the runs' offsets jump rather than
    /// wander, a pattern a wandering bias does not make (it moves within runs too and
    /// carries from one run into the next), and no slow part is modelled (B = K = 0).
    #[serde(default)]
    pub turn_on_log_lr: f64,
}

/// Log-likelihood ratio above which a channel's run offsets are a turn-on bias rather than
/// slow noise (e⁵ ≈ 150 times likelier; the alternatives have two and three variances; clean
/// sessions under MEMS wander read below 2.5).
pub const TURN_ON_EVIDENCE: f64 = 5.0;

impl SlowNoise {
    /// Whether it has a slow part at all.
    pub fn is_slow(&self) -> bool {
        self.bias_instability > 0.0 || self.random_walk > 0.0
    }

    /// Whether the runs' offsets are better told as a turn-on bias than as this wander
    /// ([`SlowNoise::turn_on_log_lr`]).
    pub fn jumps_between_runs(&self) -> bool {
        self.turn_on_log_lr > TURN_ON_EVIDENCE
    }

    /// Its covariance kernel over a session of `span_s`.
    pub fn kernel(&self, span_s: f64) -> SlowKernel {
        self.kernel_down_to(self.block_s, span_s)
    }

    /// Its covariance kernel over a session of `span_s` with the flicker carried down to
    /// time constants of `shortest_s` where that is shorter than the block it was measured
    /// on: the 1/f law B²/(πf) continued to frequencies the fit's blocks do not resolve
    /// (a question about a run's cone harmonics asks about them).
    pub fn kernel_down_to(&self, shortest_s: f64, span_s: f64) -> SlowKernel {
        let t_min = if shortest_s > 0.0 { shortest_s.min(self.block_s) } else { self.block_s };
        SlowKernel {
            poles: poles(t_min.max(f64::MIN_POSITIVE), span_s),
            b2: self.bias_instability.powi(2),
            k2: self.random_walk.powi(2),
        }
    }
}

/// The covariance of block means of a slow noise (module documentation, step 2).
#[derive(Debug, Clone)]
pub struct SlowKernel {
    poles: Vec<(f64, f64)>,
    b2: f64,
    k2: f64,
}

impl SlowKernel {
    /// Covariance of the means over blocks `a` and `b`, each (centre s, length s); `same`
    /// when they are one block. The random walk in variogram form (−½K²|Δ|), to which a
    /// caller adds the constant its question needs.
    pub fn cov(&self, a: (f64, f64), b: (f64, f64), same: bool) -> f64 {
        block_cov(&self.poles, self.b2, self.k2, a, b, same)
    }

    /// Σ_{b,b'} d_b d_bᵀ' C(b, b') over blocks of (d_b, (centre s, length s)): the
    /// covariance of Σ_b d_b m_b, m_b the block means of the noise (the walk in variogram
    /// form, as [`SlowKernel::cov`]), in time linear in the blocks. Sorts `blocks` by centre.
    pub fn sandwich(&self, blocks: &mut [(DVector<f64>, (f64, f64))]) -> DMatrix<f64> {
        propagate(blocks, &self.poles, self.b2, self.k2)
    }

    /// K², unit²/s.
    pub fn walk2(&self) -> f64 {
        self.k2
    }
}

/// Blocks a session is cut into at most (the pass keeps q sums per block and channel).
const MAX_BLOCKS: usize = 1500;
/// Ratio of neighbouring flicker time constants (two per decade).
const RATIO: f64 = 3.162_277_660_168_379_5;

/// One channel's block statistics from a source.
#[derive(Debug, Clone, Default)]
struct ChannelBlocks {
    /// Per block: sums of each fitted coefficient's column.
    sums: Vec<Vec<f64>>,
    /// Per block: mean residual.
    mean: Vec<f64>,
}

/// The blocks of one source (a run): centre times, lengths, and per sensor channel the sums.
#[derive(Debug, Clone, Default)]
pub(crate) struct SourceBlocks {
    centre_s: Vec<f64>,
    length_s: Vec<f64>,
    count: Vec<usize>,
    channels: Vec<ChannelBlocks>,
    /// ΦᵀΦ per channel (plan columns).
    gram: Vec<DMatrix<f64>>,
}

/// A channel's fitted plan as the pass needs it: per fitted coefficient its (design column,
/// weight) pairs; the prediction as (column, weight) pairs.
pub(crate) struct ChannelDesign {
    columns: Vec<Vec<(usize, f64)>>,
    predict: Vec<(usize, f64)>,
}

/// The plans of the three channels of a sensor at its solution.
pub(crate) fn designs(
    terms: &[TermRef<'_>],
    cols: &Columns,
    values: &[f64],
    status: &[CoefStatus],
    fitted: &[Vec<usize>],
) -> Vec<ChannelDesign> {
    let pred = super::channel::prediction(terms, cols, values);
    (0..3)
        .map(|ch| {
            let plan = channel_plan(terms, cols, values, status, &fitted[ch], ch);
            ChannelDesign {
                columns: plan.columns,
                predict: pred.iter().filter(|p| p.0 == ch).map(|p| (p.1, p.2)).collect(),
            }
        })
        .collect()
}

/// Samples per block for a session of `total` samples.
pub(crate) fn block_samples(total: usize) -> usize {
    total.div_ceil(MAX_BLOCKS).max(8)
}

/// A block being filled.
struct Open {
    t0: f64,
    t1: f64,
    n: usize,
    sums: Vec<Vec<f64>>,
    rsum: Vec<f64>,
}

impl SourceBlocks {
    fn close(&mut self, o: &mut Open) {
        if o.n == 0 {
            return;
        }
        let dt = if o.n > 1 { (o.t1 - o.t0) / (o.n - 1) as f64 } else { 0.0 };
        self.centre_s.push(0.5 * (o.t0 + o.t1));
        self.length_s.push(dt * o.n as f64);
        self.count.push(o.n);
        for (c, cb) in self.channels.iter_mut().enumerate() {
            cb.sums.push(std::mem::take(&mut o.sums[c]));
            cb.mean.push(o.rsum[c] / o.n as f64);
            o.sums[c] = vec![0.0; cb.sums.last().map_or(0, Vec::len)];
            o.rsum[c] = 0.0;
        }
        o.n = 0;
    }
}

/// Fills a sensor's design columns of a block: (sensor index, states, gyro, accel, columns).
pub(crate) type FillFn<'f> = dyn Fn(usize, &[crate::model::State], &[[f64; 3]], &[[f64; 3]], &mut [f64]) + Sync + 'f;

/// The block pass over one source for every sensor: `fill(sensor index, states, gyro,
/// accel, cols)` fills the sensor's design columns of a block (stride [`BLOCK`]);
/// `designs[s]` are its channels' plans, `width[s]` its number of design columns. Blocks
/// hold `per_block` consecutive samples (the last of a source fewer).
pub(crate) fn pass(
    src: &dyn Samples,
    designs: &[Vec<ChannelDesign>],
    width: &[usize],
    per_block: usize,
    fill: &FillFn<'_>,
) -> Result<SourceBlocks, crate::session::SessionError> {
    use crate::stats::kernels::axpy;
    let sensors = designs.len();
    let q = |c: usize| designs[c / 3][c % 3].columns.len();
    let mut out = SourceBlocks { channels: vec![ChannelBlocks::default(); 3 * sensors], ..Default::default() };
    // ΦᵀΦ's lower triangle per channel, a stretch of samples at a time (faer's product).
    let mut lower: Vec<faer::Mat<f64>> = (0..3 * sensors).map(|c| faer::Mat::zeros(q(c), q(c))).collect();
    let mut open = Open {
        t0: 0.0,
        t1: 0.0,
        n: 0,
        sums: (0..3 * sensors).map(|c| vec![0.0; q(c)]).collect(),
        rsum: vec![0.0; 3 * sensors],
    };
    let mut cols: Vec<Vec<f64>> = width.iter().map(|w| vec![0.0; (w + 3) * BLOCK]).collect();
    // A stretch's plan columns (column-major, stride BLOCK) and prediction.
    let qmax = (0..3 * sensors).map(q).max().unwrap_or(0);
    let mut x = vec![0.0; qmax * BLOCK];
    let mut pred = vec![0.0; BLOCK];
    // Each plan column (and the prediction) as its weighted design columns summed in their
    // order, a stretch of samples at once: element by element the sums of one sample.
    let combine = |to: &mut [f64], parts: &[(usize, f64)], c: &[f64], k: usize| {
        to.fill(-0.0);
        for &(j, wt) in parts {
            axpy(to, wt, &c[j * BLOCK + k..][..to.len()]);
        }
    };
    src.for_each_block(&mut |states, g, a| {
        for (s, c) in cols.iter_mut().enumerate() {
            fill(s, states, g, a, c);
        }
        // Stretches of the block that fall in one block of means.
        let mut k = 0;
        while k < states.len() {
            let take = (per_block - open.n).min(states.len() - k);
            if open.n == 0 {
                open.t0 = states[k].t_session_s;
            }
            open.t1 = states[k + take - 1].t_session_s;
            for s in 0..sensors {
                let c = &cols[s];
                for (ch, d) in designs[s].iter().enumerate() {
                    let i = 3 * s + ch;
                    for (col, (xa, acc)) in d.columns.iter().zip(x.chunks_exact_mut(BLOCK).zip(&mut open.sums[i])) {
                        let xa = &mut xa[..take];
                        combine(xa, col, c, k);
                        for v in xa.iter() {
                            *acc += v;
                        }
                    }
                    combine(&mut pred[..take], &d.predict, c, k);
                    let y = &c[(width[s] + ch) * BLOCK + k..][..take];
                    for (y, p) in y.iter().zip(&pred[..take]) {
                        open.rsum[i] += y - p;
                    }
                    crate::stats::gram::add_block_lower(&mut lower[i], &x, BLOCK, take, 1.0);
                }
            }
            open.n += take;
            k += take;
            if open.n == per_block {
                out.close(&mut open);
            }
        }
    })?;
    out.close(&mut open);
    out.gram = lower
        .iter()
        .map(|l| DMatrix::from_fn(l.nrows(), l.ncols(), |i, j| if i >= j { l[(i, j)] } else { l[(j, i)] }))
        .collect();
    Ok(out)
}

/// Allan variance of a series of equal block means (overlapping estimator) at cluster size
/// m: (value, terms averaged).
fn allan(means: &[f64], m: usize) -> Option<(f64, usize)> {
    if means.len() < 2 * m {
        return None;
    }
    let mut prefix = vec![0.0; means.len() + 1];
    for (i, v) in means.iter().enumerate() {
        prefix[i + 1] = prefix[i] + v;
    }
    let avg = |i: usize| (prefix[i + m] - prefix[i]) / m as f64;
    let terms = means.len() + 1 - 2 * m;
    let s: f64 = (0..terms).map(|i| (avg(i + m) - avg(i)).powi(2)).sum();
    Some((0.5 * s / terms as f64, terms))
}

/// The flicker poles (time constant, variance per unit B²) from `t_min` to `span`.
fn poles(t_min: f64, span: f64) -> Vec<(f64, f64)> {
    let var = RATIO.ln() / std::f64::consts::PI;
    let mut out = Vec::new();
    let mut t = t_min.max(f64::MIN_POSITIVE);
    while t <= span.max(t_min) * RATIO {
        out.push((t, var));
        t *= RATIO;
    }
    out
}

/// Allan variance of a Gauss–Markov process (σ², T) at τ.
fn gm_allan(var: f64, t: f64, tau: f64) -> f64 {
    let x = tau / t;
    var * (t / tau).powi(2) * (2.0 * x - 3.0 + 4.0 * (-x).exp() - (-2.0 * x).exp())
}

/// Non-negative least squares of a tiny problem (≤ 3 unknowns) by trying every active set.
fn nnls(a: &[[f64; 3]], y: &[f64], w: &[f64]) -> [f64; 3] {
    let mut best = ([0.0; 3], f64::INFINITY);
    for mask in 1u8..8 {
        let idx: Vec<usize> = (0..3).filter(|i| mask & (1 << i) != 0).collect();
        let k = idx.len();
        let m = DMatrix::from_fn(k, k, |i, j| (0..y.len()).map(|r| w[r] * a[r][idx[i]] * a[r][idx[j]]).sum::<f64>());
        let b = DVector::from_fn(k, |i, _| (0..y.len()).map(|r| w[r] * a[r][idx[i]] * y[r]).sum::<f64>());
        let Some(sol) = m.lu().solve(&b) else { continue };
        if sol.iter().any(|v| *v < 0.0 || !v.is_finite()) {
            continue;
        }
        let mut x = [0.0; 3];
        for (i, &j) in idx.iter().enumerate() {
            x[j] = sol[i];
        }
        let cost: f64 = (0..y.len()).map(|r| w[r] * (y[r] - (0..3).map(|j| a[r][j] * x[j]).sum::<f64>()).powi(2)).sum();
        if cost < best.1 {
            best = (x, cost);
        }
    }
    best.0
}

/// One Allan variance of block means: (τ s, value, weight = terms/m/value²).
pub type AllanPoint = (f64, f64, f64);

/// The Allan variances of one run's block means (blocks of `block_s`) at τ = L, 2L, 4L, …
/// while at least three differences remain.
pub fn allan_points(means: &[f64], block_s: f64) -> Vec<AllanPoint> {
    let mut out = Vec::new();
    let mut m = 1;
    while let Some((v, terms)) = allan(means, m) {
        if terms < 3 || block_s.partial_cmp(&0.0) != Some(std::cmp::Ordering::Greater) {
            break;
        }
        // Each Allan variance is known to about 1/√(terms/m) of itself.
        out.push((block_s * m as f64, v, terms as f64 / m as f64 / v.max(f64::MIN_POSITIVE).powi(2)));
        m *= 2;
    }
    out
}

/// White density, bias instability and random walk fitted (non-negative least squares) to
/// Allan variances: σ²_A(τ) = N²/τ + B² a_F(τ) + K² τ/3, the flicker modelled from
/// `block_s` to `span_s`.
pub fn fit_allan(points: &[AllanPoint], block_s: f64, span_s: f64) -> SlowNoise {
    let flick = poles(block_s, span_s);
    let rows: Vec<[f64; 3]> = points
        .iter()
        .map(|&(tau, _, _)| [1.0 / tau, flick.iter().map(|&(t, var)| gm_allan(var, t, tau)).sum(), tau / 3.0])
        .collect();
    let ys: Vec<f64> = points.iter().map(|p| p.1).collect();
    let ws: Vec<f64> = points.iter().map(|p| p.2).collect();
    let distinct = {
        let mut t: Vec<f64> = points.iter().map(|p| p.0).collect();
        t.sort_by(f64::total_cmp);
        t.dedup_by(|a, b| (*a - *b).abs() <= 1e-9 * b.abs());
        t.len()
    };
    let [n2, b2, k2] = if distinct < 3 { [0.0; 3] } else { nnls(&rows, &ys, &ws) };
    SlowNoise {
        white_density: n2.sqrt(),
        bias_instability: b2.sqrt(),
        random_walk: k2.sqrt(),
        se_inflation: 1.0,
        block_s,
        turn_on_log_lr: 0.0,
    }
}

/// Fits (N², B², K²) to the Allan variances of one channel's block means over its runs.
fn measure(sources: &[SourceBlocks], c: usize, t_min: f64, span: f64) -> [f64; 3] {
    let mut points = Vec::new();
    for s in sources {
        let means = &s.channels[c].mean;
        // Blocks of one length only (a run's last, shorter block is left out).
        let full = s.count.iter().take_while(|&&n| n == s.count[0]).count().min(means.len());
        if let Some(&l) = s.length_s.first() {
            points.extend(allan_points(&means[..full], l));
        }
    }
    let f = fit_allan(&points, t_min, span);
    [f.white_density.powi(2), f.bias_instability.powi(2), f.random_walk.powi(2)]
}

/// A Gauss–Markov pole's factor of a block of length L between blocks:
/// f = (T/L)(1 − e^(−L/T)), 1 for a block of no length ([`block_cov`], [`propagate`]).
fn gm_factor(t: f64, l: f64) -> f64 {
    if l > 0.0 {
        (t / l) * (1.0 - (-l / t).exp())
    } else {
        1.0
    }
}

/// Covariance of the block means b, b' of the slow part (flicker poles at B² = `b2`, random
/// walk K² = `k2`), in variogram form for the walk.
fn block_cov(flick: &[(f64, f64)], b2: f64, k2: f64, tb: (f64, f64), tc: (f64, f64), same: bool) -> f64 {
    let mut v = 0.0;
    if same {
        let l = tb.1.max(f64::MIN_POSITIVE);
        for &(t, var) in flick {
            let x = l / t;
            v += b2 * var * 2.0 * (t / l).powi(2) * (x - 1.0 + (-x).exp());
        }
        v -= 0.5 * k2 * l / 3.0;
    } else {
        let d = (tb.0 - tc.0).abs();
        for &(t, var) in flick {
            let e = -(d - 0.5 * tb.1 - 0.5 * tc.1) / t;
            v += b2 * var * e.exp() * gm_factor(t, tb.1) * gm_factor(t, tc.1);
        }
        v -= 0.5 * k2 * d;
    }
    v
}

/// Coarse blocks a channel's REML fit aims at over the session (its cost is cubic in them;
/// each run keeps at least [`REML_PER_RUN`]).
const REML_BLOCKS: usize = 144;
/// Coarse blocks per run at least (the runs' own curvature tells flicker from walk).
const REML_PER_RUN: usize = 16;

/// One coarse block of a channel: session-clock centre and length (s), samples, the
/// block-level design row (block sums of the regressors over the count) and mean residual.
struct Coarse {
    source: usize,
    centre: f64,
    len: f64,
    x: DVector<f64>,
    r: f64,
}

/// The channel's fine blocks merged to about [`REML_BLOCKS`] over the session, on the
/// session clock (`offsets` per source; times from the session's start `t0`).
fn coarse_blocks(sources: &[SourceBlocks], c: usize, offsets: &[f64], t0: f64, q: usize) -> Vec<Coarse> {
    let per_run = (REML_BLOCKS / sources.len().max(1)).max(REML_PER_RUN);
    let mut out = Vec::new();
    for (si, s) in sources.iter().enumerate() {
        let nb = s.count.len();
        let group = nb.div_ceil(per_run).max(1);
        for g in (0..nb).step_by(group) {
            let idx = g..(g + group).min(nb);
            let n: f64 = idx.clone().map(|b| s.count[b] as f64).sum();
            let a = s.centre_s[idx.start] - 0.5 * s.length_s[idx.start];
            let b = s.centre_s[idx.end - 1] + 0.5 * s.length_s[idx.end - 1];
            let mut x = DVector::<f64>::zeros(q);
            let mut r = 0.0;
            for k in idx {
                x += DVector::from_column_slice(&s.channels[c].sums[k]);
                r += s.channels[c].mean[k] * s.count[k] as f64;
            }
            if n > 0.0 {
                out.push(Coarse {
                    source: si,
                    centre: 0.5 * (a + b) + offsets[si] - t0,
                    len: b - a,
                    x: x / n,
                    r: r / n,
                });
            }
        }
    }
    out
}

/// White density², B² and K² of a channel by restricted maximum likelihood on its coarse
/// block means (Patterson & Thompson 1971), by average-information Newton steps.
///
/// Block means of the data follow the block-level regression ȳ_b = x_bᵀβ + ε̄_b exactly
/// (x_b the block's mean regressors), so the residual's projection P r̄ = P ε̄ with
/// P = V⁻¹ − V⁻¹X(XᵀV⁻¹X)⁻¹XᵀV⁻¹ does not depend on β. V = N² V_w + B² V_F + K² V_K: white
/// (diag 1/L_b), the flicker poles, and the random walk W(t) from the session's start
/// (block means: min of the centres between blocks, start + L/3 within one). Unlike an
/// Allan fit inside runs, the likelihood weighs the runs' offsets against each other, which
/// is where a session shows its flicker and walk. Components are kept non-negative (a
/// component with a negative step at zero stays there). `start` seeds the iteration.
fn reml(blocks: &[Coarse], flick: &[(f64, f64)], start: [f64; 3]) -> Option<([f64; 3], f64)> {
    let (x, y) = block_regression(blocks)?;
    let m = blocks.len();
    let comps = [
        white_component(blocks),
        flicker_component(blocks, flick),
        DMatrix::from_fn(m, m, |a, b| {
            let (ba, bb) = (&blocks[a], &blocks[b]);
            if a == b {
                ba.centre - ba.len / 6.0
            } else {
                ba.centre.min(bb.centre)
            }
        }),
    ];
    let mut first = start;
    first[0] = white_start(blocks, first[0]);
    let (theta, ll) = super::reml::climb(&super::reml::Dense { comps: &comps, x: &x, y: &y }, first.to_vec())?;
    let theta = [theta[0], theta[1], theta[2]];
    theta.iter().all(|v| v.is_finite()).then_some((theta, ll))
}

/// The flicker poles' covariance of block means per unit B² ([`block_cov`] with B² = 1 and
/// no walk), worked out on the lower triangle and mirrored, with each block's factor
/// f = (T/L)(1 − e^(−L/T)) per pole worked out once: one exponential per pair and pole
/// instead of three on both triangles. The lower triangle has [`block_cov`]'s numbers.
fn flicker_component(blocks: &[Coarse], flick: &[(f64, f64)]) -> DMatrix<f64> {
    let m = blocks.len();
    let np = flick.len();
    let factors: Vec<f64> = blocks.iter().flat_map(|b| flick.iter().map(move |&(t, _)| gm_factor(t, b.len))).collect();
    let mut out = DMatrix::<f64>::zeros(m, m);
    for b in 0..m {
        let bb = &blocks[b];
        out[(b, b)] = block_cov(flick, 1.0, 0.0, (bb.centre, bb.len), (bb.centre, bb.len), true);
        for a in b + 1..m {
            let ba = &blocks[a];
            let d = (ba.centre - bb.centre).abs();
            let mut v = 0.0;
            for (p, &(t, var)) in flick.iter().enumerate() {
                let e = -(d - 0.5 * ba.len - 0.5 * bb.len) / t;
                v += var * e.exp() * factors[a * np + p] * factors[b * np + p];
            }
            out[(a, b)] = v;
            out[(b, a)] = v;
        }
    }
    out
}

/// The block-level regression of the block means (regressors X, means y); None when there
/// are too few blocks beside the regressors to measure variances (fewer than q + 6).
fn block_regression(blocks: &[Coarse]) -> Option<(DMatrix<f64>, DVector<f64>)> {
    let m = blocks.len();
    let q = blocks.first()?.x.len();
    if m < q + 6 {
        return None;
    }
    Some((DMatrix::from_fn(m, q, |b, j| blocks[b].x[j]), DVector::from_fn(m, |b, _| blocks[b].r)))
}

/// The white level a climb starts from: `given` when positive, else the block means' own
/// (mean of r² L).
fn white_start(blocks: &[Coarse], given: f64) -> f64 {
    if given > 0.0 {
        return given;
    }
    let v = blocks.iter().map(|b| b.r * b.r * b.len).sum::<f64>() / blocks.len().max(1) as f64;
    v.max(f64::MIN_POSITIVE)
}

/// White noise of block means: diag 1/L_b.
fn white_component(blocks: &[Coarse]) -> DMatrix<f64> {
    DMatrix::from_diagonal(&DVector::from_vec(white_weights(blocks)))
}

/// The white component's diagonal: 1/L_b per block.
fn white_weights(blocks: &[Coarse]) -> Vec<f64> {
    blocks.iter().map(|b| 1.0 / b.len.max(f64::MIN_POSITIVE)).collect()
}

/// The restricted log-likelihood of white noise plus a constant offset drawn anew in each
/// run (a turn-on bias, variance τ² shared by the runs) on the same block means, at its
/// REML estimate; `white_level` seeds the white level. None when it does not converge or the
/// blocks come from one run.
fn turn_on_likelihood(blocks: &[Coarse], white_level: f64) -> Option<f64> {
    // An offset drawn anew in each run needs two runs (in one it is that run's bias).
    if blocks.iter().all(|b| b.source == blocks[0].source) {
        return None;
    }
    let (x, y) = block_regression(blocks)?;
    let white = white_weights(blocks);
    let run: Vec<usize> = blocks.iter().map(|b| b.source).collect();
    let structure = super::reml::RunOffsets { white: &white, run: &run, x: &x, y: &y };
    let (_, ll) = super::reml::climb(&structure, vec![white_start(blocks, white_level), 0.0])?;
    ll.is_finite().then_some(ll)
}

/// Σ_{b,b'} d_b d_bᵀ' C(b, b') over blocks `d` of (d_b, (centre s, length s)), C from
/// [`block_cov`], in O(n · poles · q) rather than O(n² · poles · q): between blocks the
/// kernel separates. A pole's covariance σ² e^{−(s_b − e_c)/T} f_b f_c (s_b the later
/// block's start, e_c the earlier's end, f = (T/L)(1 − e^{−L/T})) is carried forward in
/// time as a running sum rescaled at each block, every exponent ≤ 0 for blocks that do
/// not overlap; the walk's −½K²(t_b − t_c) as Σ_c (t_b − t_c) d_c, grown by the step
/// times the sum of the blocks passed. Sorts `d` by centre.
fn propagate(d: &mut [(DVector<f64>, (f64, f64))], flick: &[(f64, f64)], b2: f64, k2: f64) -> DMatrix<f64> {
    let q = d.first().map_or(0, |v| v.0.len());
    d.sort_by(|a, b| a.1 .0.total_cmp(&b.1 .0));
    // Per pole: the running sum and the time it refers to (the end of the last block).
    let mut sums: Vec<(DVector<f64>, f64)> = flick.iter().map(|_| (DVector::zeros(q), f64::NEG_INFINITY)).collect();
    let (mut passed, mut walk) = (DVector::<f64>::zeros(q), DVector::<f64>::zeros(q));
    let mut h = DVector::<f64>::zeros(q);
    let mut add = DMatrix::<f64>::zeros(q, q);
    let mut prev = None;
    for (v, (t, l)) in d.iter() {
        let (start, end) = (t - 0.5 * l, t + 0.5 * l);
        if let Some(p) = prev {
            walk.axpy(t - p, &passed, 1.0);
        }
        h.copy_from(&walk);
        h *= -0.5 * k2;
        for ((pole, var), (s, at)) in flick.iter().zip(&mut sums) {
            let fb = gm_factor(*pole, *l);
            if at.is_finite() {
                h.axpy(b2 * var * fb * (-(start - *at) / pole).exp(), s, 1.0);
                *s *= (-(end - *at) / pole).exp();
            }
            s.axpy(fb, v, 1.0);
            *at = end;
        }
        add.ger(block_cov(flick, b2, k2, (*t, *l), (*t, *l), true), v, v, 1.0);
        add.ger(1.0, v, &h, 1.0);
        add.ger(1.0, &h, v, 1.0);
        passed += v;
        prev = Some(*t);
    }
    add
}

/// Adds the slow part to channel `c`'s covariance (module documentation) and returns what
/// was measured, or carries `held` (Some(None): no slow noise on the channel) without
/// measuring it; the caller updates the standard errors from the covariance.
pub(crate) fn inflate(
    sources: &[SourceBlocks],
    c: usize,
    ch: &mut ChannelFit,
    held: Option<Option<SlowNoise>>,
) -> Option<SlowNoise> {
    let q = ch.covariance.len();
    if q == 0 || sources.is_empty() {
        return None;
    }
    let t_min = sources.iter().flat_map(|s| s.length_s.first()).copied().fold(f64::INFINITY, f64::min);
    if !(t_min.is_finite() && t_min > 0.0) {
        return None;
    }
    let mut gram = DMatrix::<f64>::zeros(q, q);
    let mut total = 0usize;
    for s in sources {
        gram += &s.gram[c];
        total += s.count.iter().sum::<usize>();
    }
    let ainv = gram.clone().try_inverse().or_else(|| gram.clone().pseudo_inverse(1e-12).ok())?;
    // Runs whose clocks restart (each from 0) are laid end to end on one session clock.
    let mut offsets = Vec::with_capacity(sources.len());
    let mut end = f64::NEG_INFINITY;
    for s in sources {
        let (a, b) = (s.centre_s.first().copied().unwrap_or(0.0), s.centre_s.last().copied().unwrap_or(0.0));
        let off = if a < end { end - a + s.length_s.first().copied().unwrap_or(0.0) } else { 0.0 };
        offsets.push(off);
        end = b + off;
    }
    // The constant column (the bias), if fitted: its block sums are the block counts.
    let bias = (0..q).find(|&a| {
        sources
            .iter()
            .all(|s| s.channels[c].sums.iter().zip(&s.count).all(|(v, &n)| (v[a] - n as f64).abs() <= 1e-9 * n as f64))
    });
    let t0 = sources.first().and_then(|s| s.centre_s.first()).copied().unwrap_or(0.0);
    let span = (end - t0).max(t_min);
    let flick = poles(t_min, span);
    let ([n2, b2, k2], turn_on_log_lr) = match held {
        Some(h) => {
            let h = h?;
            ([h.white_density.powi(2), h.bias_instability.powi(2), h.random_walk.powi(2)], h.turn_on_log_lr)
        }
        None => {
            let start = measure(sources, c, t_min, span);
            let t_first = sources
                .iter()
                .zip(&offsets)
                .flat_map(|(s, o)| s.centre_s.first().zip(s.length_s.first()).map(|(c, l)| c - 0.5 * l + o))
                .fold(f64::INFINITY, f64::min);
            let blocks = coarse_blocks(sources, c, &offsets, t_first, q);
            let (theta, ll) = reml(&blocks, &flick, start).map_or((start, None), |(t, ll)| (t, Some(ll)));
            // The turn-on alternative on the same block means ([`SlowNoise::turn_on_log_lr`]).
            (theta, ll.zip(turn_on_likelihood(&blocks, theta[0])).map_or(0.0, |(a, b)| b - a))
        }
    };
    // Offsets that jump between runs are not wander: none is modelled (the diagnosis draws
    // them as a turn-on bias).
    if (b2 == 0.0 && k2 == 0.0) || turn_on_log_lr > TURN_ON_EVIDENCE {
        return Some(SlowNoise {
            white_density: n2.sqrt(),
            se_inflation: 1.0,
            block_s: t_min,
            turn_on_log_lr,
            ..Default::default()
        });
    }
    // d_b per block, with the session's time of each block.
    let mut d: Vec<(DVector<f64>, (f64, f64))> = Vec::new();
    for (si, s) in sources.iter().enumerate() {
        for (b, sums) in s.channels[c].sums.iter().enumerate() {
            let mut v = &ainv * DVector::from_column_slice(sums);
            if let Some(i) = bias {
                v[i] -= s.count[b] as f64 / total.max(1) as f64;
            }
            d.push((v, (s.centre_s[b] + offsets[si], s.length_s[b])));
        }
    }
    let add = propagate(&mut d, &flick, b2, k2);
    let mut worst: f64 = 1.0;
    for a in 0..q {
        let before = ch.covariance[a][a];
        for b in 0..q {
            ch.covariance[a][b] += add[(a, b)];
        }
        if before > 0.0 {
            worst = worst.max((ch.covariance[a][a].max(0.0) / before).sqrt());
        }
    }
    Some(SlowNoise {
        white_density: n2.sqrt(),
        bias_instability: b2.sqrt(),
        random_walk: k2.sqrt(),
        se_inflation: worst,
        block_s: t_min,
        turn_on_log_lr,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The running-sum propagation equals the double sum over every pair of blocks,
    /// on blocks of unequal lengths, a gap and runs laid end to end out of order.
    #[test]
    fn propagation_equals_the_double_sum() {
        let q = 3;
        let mut d: Vec<(DVector<f64>, (f64, f64))> = Vec::new();
        let mut state = 12345u64;
        let mut next = || {
            state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            ((state >> 11) as f64 / (1u64 << 53) as f64) - 0.5
        };
        for (start, len, n) in [(300.0, 0.7, 40), (0.0, 0.5, 60), (120.0, 1.3, 25)] {
            for k in 0..n {
                let l = len * (1.0 + 0.2 * next());
                let v = DVector::from_fn(q, |_, _| next());
                d.push((v, (start + len * k as f64 + 0.5 * l, l)));
            }
        }
        let flick = poles(0.4, 500.0);
        let (b2, k2) = (2.5, 0.3);
        let mut brute = DMatrix::<f64>::zeros(q, q);
        for (i, (vi, ti)) in d.iter().enumerate() {
            for (j, (vj, tj)) in d.iter().enumerate() {
                brute += vi * vj.transpose() * block_cov(&flick, b2, k2, *ti, *tj, i == j);
            }
        }
        let fast = propagate(&mut d, &flick, b2, k2);
        let scale = brute.amax();
        assert!(scale > 0.0);
        assert!((&fast - &brute).amax() <= 1e-10 * scale, "fast {fast} brute {brute}");
    }
}
