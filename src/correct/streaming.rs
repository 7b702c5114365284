//! Streaming correction: causal, one sample at a time, fixed memory, no allocation per
//! sample (see the module documentation of [`super`]).

use super::{
    check_inputs, ensure_finite, refuse_outside, set_flags, Calibration, CorrectError, Corrected, SensorInverse,
};
use crate::model::State;
use crate::motion::SlopeWeights;
use nalgebra::Matrix3;

/// A 3-vector padded to four lanes (the last is 0) so that the streaming loops vectorize.
type Lanes = [f64; 4];

/// A 3×3 matrix by columns of [`Lanes`]: `M v = c₀v₀ + c₁v₁ + c₂v₂`, lane by lane, as
/// fused multiply-adds in that order (IEEE fma is exactly rounded on every processor, so
/// every path through the corrector gives the same bits).
#[derive(Debug, Clone, Copy, Default)]
struct Cols([Lanes; 3]);

impl Cols {
    fn of(m: &Matrix3<f64>) -> Self {
        Self([0, 1, 2].map(|j| [m[(0, j)], m[(1, j)], m[(2, j)], 0.0]))
    }

    /// `acc + M v` as fused multiply-adds in the order c₀, c₁, c₂.
    #[inline(always)]
    fn apply_from(&self, acc: Lanes, v: &[f64]) -> Lanes {
        let [c0, c1, c2] = &self.0;
        let mut r = acc;
        for i in 0..4 {
            r[i] = c2[i].mul_add(v[2], c1[i].mul_add(v[1], c0[i].mul_add(v[0], r[i])));
        }
        r
    }

    /// `−M v` (the product, then negated): a vector to start [`Self::apply_from`] with.
    fn neg_apply(m: &Matrix3<f64>, v: [f64; 3]) -> Lanes {
        let r = -(m * nalgebra::Vector3::from(v));
        [r[0], r[1], r[2], 0.0]
    }

    /// `acc − M v` as fused multiply-adds with the columns negated (exact): c₀, c₁, c₂ in turn.
    #[inline(always)]
    fn sub_from(&self, acc: Lanes, v: &[f64]) -> Lanes {
        let [c0, c1, c2] = &self.0;
        let mut r = acc;
        for i in 0..4 {
            r[i] = (-c2[i]).mul_add(v[2], (-c1[i]).mul_add(v[1], (-c0[i]).mul_add(v[0], r[i])));
        }
        r
    }
}

/// The gyro's linear inverse for one set of slope weights. With the window's weights h
/// (h₀ on the newest sample, h₁ and h₂ on the two before, the rest on older ones), the
/// estimate ε̂ = h₀ω_k + h₁ω_{k−1} + h₂ω_{k−2} + p, p = Σ_{j≥3} h_j ω_{k−j}, and the model
/// u = Aω + Eε̂ + b + g give ω_k = M(u − g) − Mb − D p − G₂ ω_{k−2} − G₁ ω_{k−1} with
/// M = (A + h₀E)⁻¹, D = M E, G_i = h_i D: the two newest past samples enter through their
/// own 3×3 products, which keeps the chain from one sample to the next three fused
/// multiply-adds long.
#[derive(Debug, Clone, Copy, Default)]
struct GyroStep {
    h: [f64; 3],
    m: Cols,
    d: Cols,
    g1: Cols,
    g2: Cols,
    /// −M b.
    neg_mb: Lanes,
}

impl GyroStep {
    fn new(s: &SensorInverse) -> Self {
        let mut step = Self { h: [f64::NAN; 3], ..Self::default() };
        step.set(s, [0.0; 3]);
        step
    }

    /// Makes the matrices those of weights [h₀, h₁, h₂] (recomputed only when they change).
    #[allow(clippy::float_cmp)]
    #[inline]
    fn set(&mut self, s: &SensorInverse, h: [f64; 3]) {
        if h == self.h {
            return;
        }
        if h[0] != self.h[0] {
            let m = (s.scale.matrix() + s.eps.matrix() * h[0]).try_inverse().unwrap_or(*s.scale_inv.matrix());
            self.m = Cols::of(&m);
            self.d = Cols::of(&(m * s.eps.matrix()));
            self.neg_mb = Cols::neg_apply(&m, s.bias);
        }
        let times = |k: f64| Cols(self.d.0.map(|c| c.map(|x| x * k)));
        self.g1 = times(h[1]);
        self.g2 = times(h[2]);
        self.h = h;
    }

    /// ω_k from the output `u`, the other effects' contribution `other`, the older weights
    /// `h_old` with their samples `old` (oldest first) and the two previous samples `x2`, `x1`.
    /// Lane by lane, as fused multiply-adds in this order: p = Σ h_j x_j (oldest first);
    /// ω = −Mb + M(u − other), then − D p, − G₂x₂, − G₁x₁ (each [`Cols::sub_from`]): the
    /// previous sample enters last. The AVX2 loop of [`Streaming::push_block`] does the same
    /// operations.
    #[inline(always)]
    fn apply(&self, u: &[f64; 3], other: &[f64; 3], h_old: &[f64], old: &[Lanes], x2: &Lanes, x1: &Lanes) -> Lanes {
        let mut p = [0.0; 4];
        for (hj, x) in h_old.iter().zip(old) {
            for i in 0..4 {
                p[i] = hj.mul_add(x[i], p[i]);
            }
        }
        let v = self.m.apply_from(self.neg_mb, &[u[0] - other[0], u[1] - other[1], u[2] - other[2]]);
        let w = self.d.sub_from(v, &p);
        let w = self.g2.sub_from(w, x2);
        self.g1.sub_from(w, x1)
    }
}

/// The constants of [`Streaming::push`] for a calibration whose gyro has no C_ε and no
/// other terms, row-major: the gyro's M = (A + h₀E)⁻¹ with E = 0 (the same matrix for every
/// h₀) and −M b, the accelerometer's A⁻¹ and −A⁻¹ b. Computed by the same code `push` uses,
/// so an export holding them gives the same bits: each output is then
/// `fma(m_i2, u_2, fma(m_i1, u_1, fma(m_i0, u_0, c_i)))` ([`Cols::apply_from`]).
pub(super) fn linear_constants(cal: &super::Calibration) -> [([[f64; 3]; 3], [f64; 3]); 2] {
    let rows = |c: &Cols| -> [[f64; 3]; 3] { std::array::from_fn(|i| std::array::from_fn(|j| c.0[j][i])) };
    let three = |l: Lanes| [l[0], l[1], l[2]];
    let step = GyroStep::new(&cal.gyro);
    let accel = Cols::of(cal.accel.scale_inv.matrix());
    let accel_neg = Cols::neg_apply(cal.accel.scale_inv.matrix(), cal.accel.bias);
    [(rows(&step.m), three(step.neg_mb)), (rows(&accel), three(accel_neg))]
}

/// Stores a time stamp in the doubled ring of stamps (entry `slot` and `slot + window`).
#[inline(always)]
fn stamp(times: &mut [f64], slot: usize, t_s: f64) {
    let n = times.len() / 2;
    times[slot] = t_s;
    times[slot + n] = t_s;
}

/// Stores a rate in the doubled ring of rates (entry `slot` and `slot + window`) and
/// advances the slot (the stamp is already in place: see [`stamp`]).
#[inline(always)]
fn remember(past_w: &mut [Lanes], slot: &mut usize, w: Lanes) {
    let n = past_w.len() / 2;
    past_w[*slot] = w;
    past_w[*slot + n] = w;
    *slot = if *slot + 1 == n { 0 } else { *slot + 1 };
}

/// Causal sample-by-sample corrector with fixed memory.
///
/// The last `window` time stamps and corrected rates live in rings stored twice over (entry
/// at `i` and `i + window`), so the window is always one contiguous slice in time order and
/// nothing is shifted per sample. While the sampling stays uniform (every step within 1e-9
/// of the previous one) the slope weights of the full window are reused without looking at
/// the stamps again, and [`Self::push_block`] runs a loop with nothing else in it.
#[derive(Debug, Clone)]
pub struct Streaming {
    cal: Calibration,
    window: usize,
    times: Vec<f64>,
    past_w: Vec<Lanes>,
    /// Work space of the uniform loop: the window's history, then a block of new rates.
    line: Vec<Lanes>,
    /// Next ring slot.
    head: usize,
    filled: usize,
    weights: SlopeWeights,
    /// Slope weights of a full uniform window with step `dt`, once known.
    uniform_weights: Vec<f64>,
    dt: f64,
    /// Consecutive steps equal to `dt` (within 1e-9 relative).
    steady: usize,
    step: GyroStep,
    accel_inv: Cols,
    /// −A⁻¹ b of the accelerometer.
    accel_neg_ab: Lanes,
    t_last: f64,
    last_flags: u8,
    /// The calibrated temperature range's guard and what it met.
    temp: super::TempOutside,
    /// The temperature's causal smoothed rate of change (the thermal branch).
    temp_rate: crate::stats::temp_rate::Causal,
}

impl Streaming {
    /// A corrector for a calibration (allocates its buffers once).
    pub fn new(cal: Calibration) -> Self {
        let cal_temp_guard = cal.temp_guard();
        let window = cal.settings.streaming_window.max(2);
        let degree = cal.settings.streaming_degree;
        let step = GyroStep::new(&cal.gyro);
        let accel_inv = Cols::of(cal.accel.scale_inv.matrix());
        let accel_neg_ab = Cols::neg_apply(cal.accel.scale_inv.matrix(), cal.accel.bias);
        Self {
            cal,
            window,
            times: vec![0.0; 2 * window],
            past_w: vec![[0.0; 4]; 2 * window],
            line: vec![[0.0; 4]; window + LINE_BLOCK],
            head: 0,
            filled: 0,
            weights: SlopeWeights::new(degree, window),
            uniform_weights: Vec::with_capacity(window),
            dt: f64::NAN,
            steady: 0,
            step,
            accel_inv,
            accel_neg_ab,
            t_last: f64::NAN,
            last_flags: 0,
            temp: cal_temp_guard,
            temp_rate: crate::stats::temp_rate::Causal::new(),
        }
    }

    /// Flag bits of the last sample (see [`Corrected::flags`]).
    pub fn last_flags(&self) -> u8 {
        self.last_flags
    }

    /// Samples after a reset before the derivative window is full.
    pub fn warmup_samples(&self) -> usize {
        self.window - 1
    }

    /// Forgets the history (start of a new record).
    pub fn reset(&mut self) {
        self.filled = 0;
        self.head = 0;
        self.steady = 0;
        self.t_last = f64::NAN;
        self.temp_rate.reset();
    }

    /// The accelerometer's linear inverse `−A⁻¹b + A⁻¹(u − other)`.
    #[inline(always)]
    fn accel(&self, u: &[f64; 3], other: &[f64; 3]) -> [f64; 3] {
        let v = self.accel_inv.apply_from(self.accel_neg_ab, &[u[0] - other[0], u[1] - other[1], u[2] - other[2]]);
        [v[0], v[1], v[2]]
    }

    /// Corrects one sample (SI in, SI out): returns (ω rad/s, a m/s²).
    #[inline]
    pub fn push(&mut self, t_s: f64, gyro: [f64; 3], accel: [f64; 3], temp_c: f64) -> ([f64; 3], [f64; 3]) {
        // With FMA in the processor the fused multiply-adds become single instructions
        // (chosen at run time); without, they are computed exactly in software.
        #[cfg(target_arch = "x86_64")]
        if let Some(simd) = pulp::x86::V3::try_new() {
            return pulp::Simd::vectorize(simd, PushOne { s: self, t_s, gyro, accel, temp_c });
        }
        self.push_one(t_s, gyro, accel, temp_c)
    }

    /// The body of [`Self::push`].
    #[inline(always)]
    fn push_one(&mut self, t_s: f64, gyro: [f64; 3], accel: [f64; 3], temp_c: f64) -> ([f64; 3], [f64; 3]) {
        // The branch from the temperature as recorded, before the range guard clamps it.
        let temp_rate_c_s = self.temp_rate.push(t_s, temp_c);
        let temp_c = self.temp.guard(t_s, temp_c);
        let n = self.window;
        // Uniform sampling: count consecutive steps equal to the last one.
        let step = t_s - self.t_last;
        if (step - self.dt).abs() <= 1e-9 * self.dt.abs() {
            self.steady += 1;
        } else {
            self.dt = step;
            self.steady = 0;
            self.uniform_weights.clear();
        }
        self.t_last = t_s;
        let slot = self.head;
        stamp(&mut self.times, slot, t_s);
        let len = (self.filled + 1).min(n);
        // The window in time order ends at this sample: ring[slot + n - len + 1 ..= slot + n].
        let first = slot + n + 1 - len;
        let weights: &[f64] = if len == n && self.steady + 1 >= n && !self.uniform_weights.is_empty() {
            &self.uniform_weights
        } else {
            let w = self.weights.compute(&self.times[first..first + len], t_s);
            if len == n && self.steady + 1 >= n && w.len() == n {
                self.uniform_weights.extend_from_slice(w);
            }
            self.weights.last()
        };
        // Older weights and samples, the two previous samples' weights and values, the newest's.
        let zero: Lanes = [0.0; 4];
        let ok = weights.len() == len && len >= 2;
        let (h_old, old): (&[f64], &[Lanes]) =
            if ok && len >= 3 { (&weights[..len - 3], &self.past_w[first..first + len - 3]) } else { (&[], &[]) };
        let (h2, x2) = if ok && len >= 3 { (weights[len - 3], &self.past_w[first + len - 3]) } else { (0.0, &zero) };
        let (h1, x1) = if ok { (weights[len - 2], &self.past_w[first + len - 2]) } else { (0.0, &zero) };
        let h0 = if ok { weights[len - 1] } else { 0.0 };
        self.step.set(&self.cal.gyro, [h0, h1, h2]);
        let none = [0.0; 3];
        let mut w4 = self.step.apply(&gyro, &none, h_old, old, x2, x1);
        let mut acc = self.accel(&accel, &none);
        let (g, a) = (&self.cal.gyro, &self.cal.accel);
        if g.has_other_terms() || a.has_other_terms() {
            // ε̂ without the newest sample's share, for the effects' regressors.
            let mut p = [0.0; 3];
            for (hj, x) in h_old.iter().zip(old) {
                for i in 0..3 {
                    p[i] += hj * x[i];
                }
            }
            for i in 0..3 {
                p[i] += h2 * x2[i];
                p[i] += h1 * x1[i];
            }
            // Fixed-point passes for the remaining effects, from the linear solution.
            for _ in 0..4 {
                let s = State {
                    t_session_s: t_s,
                    w: [w4[0], w4[1], w4[2]],
                    e: [p[0] + h0 * w4[0], p[1] + h0 * w4[1], p[2] + h0 * w4[2]],
                    a: acc,
                    temp_c,
                    temp_rate_c_s,
                };
                let og = g.other(&s);
                let oa = a.other(&s);
                w4 = self.step.apply(&gyro, &og, h_old, old, x2, x1);
                acc = self.accel(&accel, &oa);
            }
        }
        let mut w = [w4[0], w4[1], w4[2]];
        if !self.cal.nonlinear.is_empty() {
            self.last_flags = self.cal.invert_nonlinear(&mut w, &mut acc);
        }
        remember(&mut self.past_w, &mut self.head, [w[0], w[1], w[2], 0.0]);
        self.filled = len;
        (w, acc)
    }

    /// The samples met so far outside the profile's calibrated temperature range.
    pub fn temperature_outside(&self) -> &super::TempOutside {
        &self.temp
    }

    /// Corrects a block of samples into caller-owned buffers (no allocation): `w_out[k]`,
    /// `a_out[k]` receive sample k's rate and specific force; stops at the shortest slice.
    /// Returns the number of samples corrected. Results equal those of [`Self::push`]
    /// sample by sample, bit for bit.
    pub fn push_block(
        &mut self,
        t_s: &[f64],
        gyro: &[[f64; 3]],
        accel: &[[f64; 3]],
        w_out: &mut [[f64; 3]],
        a_out: &mut [[f64; 3]],
    ) -> usize {
        let n = t_s.len().min(gyro.len()).min(accel.len()).min(w_out.len()).min(a_out.len());
        let linear =
            !self.cal.gyro.has_other_terms() && !self.cal.accel.has_other_terms() && self.cal.nonlinear.is_empty();
        let mut k = 0;
        while k < n {
            if linear
                && self.window >= 3
                && self.filled == self.window
                && self.steady + 1 >= self.window
                && self.uniform_weights.len() == self.window
            {
                k += self.uniform_run(&t_s[k..n], &gyro[k..n], &accel[k..n], &mut w_out[k..n], &mut a_out[k..n]);
            }
            if k < n {
                let (w, a) = self.push(t_s[k], gyro[k], accel[k], f64::NAN);
                w_out[k] = w;
                a_out[k] = a;
                k += 1;
            }
        }
        n
    }

    /// A linear calibration, full window, uniform sampling: corrects samples from the start
    /// of the slices until a step breaks the uniform sampling (that sample is left to
    /// [`Self::push`]); returns how many it did.
    fn uniform_run(
        &mut self,
        t_s: &[f64],
        gyro: &[[f64; 3]],
        accel: &[[f64; 3]],
        w_out: &mut [[f64; 3]],
        a_out: &mut [[f64; 3]],
    ) -> usize {
        let n = self.window;
        // Weights run oldest → newest over the window.
        let u = &self.uniform_weights;
        self.step.set(&self.cal.gyro, [u[n - 1], u[n - 2], u[n - 3]]);
        let (dt, tol) = (self.dt, 1e-9 * self.dt.abs());
        // How many samples keep the uniform step.
        let mut len = 0;
        let mut last = self.t_last;
        while len < t_s.len() && ((t_s[len] - last) - dt).abs() <= tol {
            last = t_s[len];
            len += 1;
        }
        // The history in time order (oldest first) opens the line; each block of new rates
        // follows it, and the last n − 1 rates move to the front before the next block.
        let h = n - 1;
        let head = self.head;
        self.line[..h].copy_from_slice(&self.past_w[head + 1..head + n]);
        let kernel = Kernel {
            step: &self.step,
            accel_inv: &self.accel_inv,
            accel_neg_ab: &self.accel_neg_ab,
            h_old: &self.uniform_weights[..n - 3],
        };
        let mut done = 0;
        while done < len {
            let m = (len - done).min(LINE_BLOCK);
            let r = done..done + m;
            let (line, gyro, accel) = (&mut self.line, &gyro[r.clone()], &accel[r.clone()]);
            let (w, a) = (&mut w_out[r.clone()], &mut a_out[r]);
            #[cfg(target_arch = "x86_64")]
            if let Some(simd) = pulp::x86::V4::try_new() {
                // The same AVX2 code with AVX-512's 32 vector registers (the loop's
                // constants then stay in registers).
                kernel.block_v3(simd, *simd, line, gyro, accel, w, a);
            } else if let Some(simd) = pulp::x86::V3::try_new() {
                kernel.block_v3(simd, simd, line, gyro, accel, w, a);
            } else {
                kernel.block(line, gyro, accel, w, a);
            }
            #[cfg(not(target_arch = "x86_64"))]
            kernel.block(line, gyro, accel, w, a);
            self.line.copy_within(m..m + h, 0);
            done += m;
        }
        // The rings as `push` would have left them: the last n samples (fewer if fewer).
        let first = len.saturating_sub(n);
        for k in first..len {
            let w = [w_out[k][0], w_out[k][1], w_out[k][2], 0.0];
            stamp(&mut self.times, self.head, t_s[k]);
            remember(&mut self.past_w, &mut self.head, w);
        }
        self.t_last = last;
        self.steady += len;
        self.last_flags = 0;
        len
    }
}

/// [`Streaming::push_one`] as a `pulp` operation: its body is inlined into the function
/// compiled for the processor's features (a closure as large is not, and its fused
/// multiply-adds then become calls to the software `fma`).
struct PushOne<'a> {
    s: &'a mut Streaming,
    t_s: f64,
    gyro: [f64; 3],
    accel: [f64; 3],
    temp_c: f64,
}

impl pulp::WithSimd for PushOne<'_> {
    type Output = ([f64; 3], [f64; 3]);

    #[inline(always)]
    fn with_simd<S: pulp::Simd>(self, _simd: S) -> Self::Output {
        self.s.push_one(self.t_s, self.gyro, self.accel, self.temp_c)
    }
}

/// Samples per block of the uniform loop.
const LINE_BLOCK: usize = 256;

/// The loop of [`Streaming::uniform_run`]: a linear calibration on uniform sampling.
struct Kernel<'a> {
    step: &'a GyroStep,
    accel_inv: &'a Cols,
    accel_neg_ab: &'a Lanes,
    /// Weights of the window's samples older than the two newest, oldest first.
    h_old: &'a [f64],
}

impl Kernel<'_> {
    /// One block: `line` holds the window's history (oldest first) and receives the block's
    /// rates after it (one slot per sample of `gyro`); `accel` is corrected alongside.
    #[inline(always)]
    fn block(
        &self,
        line: &mut [Lanes],
        gyro: &[[f64; 3]],
        accel: &[[f64; 3]],
        w_out: &mut [[f64; 3]],
        a_out: &mut [[f64; 3]],
    ) {
        let h = self.h_old.len() + 2;
        let none = [0.0; 3];
        let (ai, ab) = (self.accel_inv, *self.accel_neg_ab);
        for (i, (((u, f), o), q)) in gyro.iter().zip(accel).zip(w_out.iter_mut()).zip(a_out.iter_mut()).enumerate() {
            let (past, new) = line[i..].split_at_mut(h);
            let w = self.step.apply(u, &none, self.h_old, &past[..h - 2], &past[h - 2], &past[h - 1]);
            *o = [w[0], w[1], w[2]];
            new[0] = w;
            let a = ai.apply_from(ab, f);
            *q = [a[0], a[1], a[2]];
        }
    }

    /// [`Self::block`] four lanes per instruction (AVX2 and FMA: the same fused operations
    /// in the same order as [`GyroStep::apply`] and [`Cols::apply_from`], so the bits are
    /// the same). Each new rate is spread over the lanes once by shuffles and kept so for
    /// the next two samples (the loop's critical path), as is the older samples' sum p;
    /// the raw sensor outputs are broadcast straight from memory, which keeps the shuffle
    /// port free.
    #[cfg(target_arch = "x86_64")]
    #[allow(clippy::too_many_arguments)]
    fn block_v3(
        &self,
        arch: impl pulp::Simd,
        simd: pulp::x86::V3,
        line: &mut [Lanes],
        gyro: &[[f64; 3]],
        accel: &[[f64; 3]],
        w_out: &mut [[f64; 3]],
        a_out: &mut [[f64; 3]],
    ) {
        // Windows of up to 17 samples get a loop with the window's length fixed at compile
        // time (the sum over the older samples unrolled, no inner loop); longer ones the same
        // loop with the length read at run time.
        macro_rules! fixed {
            ($($n:literal)*) => {$(
                if let Ok(h_old) = <&[f64; $n]>::try_from(self.h_old) {
                    return arch.vectorize(|| {
                        // The weights spread over the lanes once, held in registers.
                        let h = h_old.map(|h| pulp::Simd::splat_f64s(simd, h));
                        self.block_v3_with(simd, $n, |j| h[j], line, gyro, accel, w_out, a_out)
                    });
                }
            )*};
        }
        fixed!(0 1 2 3 4 5 6 7 8 9 10 11 12 13 14);
        let h_old = self.h_old;
        arch.vectorize(|| {
            self.block_v3_with(
                simd,
                h_old.len(),
                |j| pulp::Simd::splat_f64s(simd, h_old[j]),
                line,
                gyro,
                accel,
                w_out,
                a_out,
            )
        });
    }

    /// The body of [`Self::block_v3`] for `n_old` older samples, whose weights `h_old(j)`
    /// gives spread over the lanes.
    #[cfg(target_arch = "x86_64")]
    #[allow(clippy::too_many_arguments)]
    #[inline(always)]
    fn block_v3_with(
        &self,
        simd: pulp::x86::V3,
        n_old: usize,
        h_old: impl Fn(usize) -> pulp::f64x4,
        line: &mut [Lanes],
        gyro: &[[f64; 3]],
        accel: &[[f64; 3]],
        w_out: &mut [[f64; 3]],
        a_out: &mut [[f64; 3]],
    ) {
        use pulp::{f64x4, Simd};
        let v4 = |x: &Lanes| -> f64x4 { pulp::bytemuck::cast(*x) };
        let neg = |c: &Cols| c.0.map(|c| v4(&c.map(|x| -x)));
        let step = self.step;
        let [m0, m1, m2] = step.m.0.map(|c| v4(&c));
        let [d0, d1, d2] = neg(&step.d);
        let [e0, e1, e2] = neg(&step.g1);
        let [k0, k1, k2] = self.accel_inv.0.map(|c| v4(&c));
        let (fma, splat) = (|a, b, c| simd.mul_add_f64s(a, b, c), |x| simd.splat_f64s(x));
        let [f0, f1, f2] = neg(&step.g2);
        let (nmb, nab) = (v4(&step.neg_mb), v4(self.accel_neg_ab));
        let h = n_old + 2;
        // The two previous rates, each spread over the lanes (x₁'s become x₂'s).
        let spread = |x: f64x4| [splat(x.0), splat(x.1), splat(x.2)];
        let mut x2 = spread(v4(&line[h - 2]));
        let mut x1 = spread(v4(&line[h - 1]));
        for (i, (((u, f), o), q)) in gyro.iter().zip(accel).zip(w_out.iter_mut()).zip(a_out.iter_mut()).enumerate() {
            let (past, new) = line[i..].split_at_mut(h);
            let mut p = splat(0.0);
            for (j, x) in past[..n_old].iter().enumerate() {
                p = fma(h_old(j), v4(x), p);
            }
            let v = fma(m2, splat(u[2]), fma(m1, splat(u[1]), fma(m0, splat(u[0]), nmb)));
            let w = fma(d2, splat(p.2), fma(d1, splat(p.1), fma(d0, splat(p.0), v)));
            let w = fma(f2, x2[2], fma(f1, x2[1], fma(f0, x2[0], w)));
            let w = fma(e2, x1[2], fma(e1, x1[1], fma(e0, x1[0], w)));
            *o = [w.0, w.1, w.2];
            new[0] = pulp::bytemuck::cast(w);
            x2 = x1;
            x1 = spread(w);
            let a = fma(k2, splat(f[2]), fma(k1, splat(f[1]), fma(k0, splat(f[0]), nab)));
            *q = [a.0, a.1, a.2];
        }
    }
}

/// Streaming correction of a whole record (convenience; same results as pushing samples).
pub fn correct_streaming(
    cal: &Calibration,
    t_s: &[f64],
    gyro: &[[f64; 3]],
    accel: &[[f64; 3]],
    temp_c: Option<&[f64]>,
) -> Result<Corrected, CorrectError> {
    let n = t_s.len();
    check_inputs(cal, n, gyro, accel, temp_c)?;
    let mut s = Streaming::new(cal.clone());
    let mut out = Corrected {
        w_rad_s: Vec::with_capacity(n),
        a_m_s2: Vec::with_capacity(n),
        iterations: 1,
        converged: true,
        warmup: s.warmup_samples().min(n),
        flags: Vec::new(),
        time_offset_s: cal.lag_s(),
        temp_outside: cal.temp_guard(),
    };
    if temp_c.is_none() && cal.nonlinear.is_empty() {
        // Nothing per sample but the samples: the block corrector (same bits as `push`).
        out.w_rad_s.resize(n, [0.0; 3]);
        out.a_m_s2.resize(n, [0.0; 3]);
        s.push_block(t_s, gyro, accel, &mut out.w_rad_s, &mut out.a_m_s2);
        return ensure_finite(out, t_s);
    }
    for k in 0..n {
        let (w, a) = s.push(t_s[k], gyro[k], accel[k], temp_c.map_or(f64::NAN, |t| t[k]));
        out.w_rad_s.push(w);
        out.a_m_s2.push(a);
        set_flags(&mut out.flags, n, k, s.last_flags());
    }
    out.temp_outside = *s.temperature_outside();
    refuse_outside(&out.temp_outside)?;
    ensure_finite(out, t_s)
}
