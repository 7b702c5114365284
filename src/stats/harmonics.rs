//! The systematic part of an error or residual series: a least-squares fit of a constant
//! and the first H harmonics of a phase θ = ω t + φ (the cone phase of a conic run), or
//! block means (runs without a phase), with a χ² test of whether it stands out of the
//! series' white noise.

use super::QrAccumulator;

/// A phase that advances linearly in time: θ(t) = `rate_rad_s` · t + `phase_rad`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PhaseLine {
    /// dθ/dt, rad/s.
    pub rate_rad_s: f64,
    /// θ at t = 0, rad.
    pub phase_rad: f64,
}

impl PhaseLine {
    /// θ at time t, rad.
    #[inline]
    pub fn theta(&self, t_s: f64) -> f64 {
        self.rate_rad_s * t_s + self.phase_rad
    }
}

/// The systematic part of one series.
#[derive(Debug, Clone, PartialEq)]
pub struct Systematic {
    /// Fitted systematic curve, one value per sample.
    pub curve: Vec<f64>,
    /// Amplitude of each harmonic (index 0 = constant, h = |a_h cos hθ + b_h sin hθ|);
    /// empty for non-conic runs.
    pub amplitudes: Vec<f64>,
    /// ‖fitted part‖² (sum of squares explained by the curve).
    pub explained: f64,
    /// White-noise variance of what the curve leaves.
    pub sigma2: f64,
    /// Number of fitted parameters (χ² degrees of freedom).
    pub params: usize,
}

impl Systematic {
    /// max |curve|.
    pub fn max_abs(&self) -> f64 {
        self.curve.iter().map(|v| v.abs()).fold(0.0, f64::max)
    }

    /// Whether the curve differs from zero beyond white noise (χ² at the 0.1 % level).
    pub fn significant(&self) -> bool {
        self.explained > chi2_999(self.params) * self.sigma2
    }
}

/// Upper 0.1 % point of χ² with `k` degrees of freedom.
pub fn chi2_999(k: usize) -> f64 {
    chi2_upper(k, 3.090)
}

/// Upper point of χ² with `k` degrees of freedom at the normal quantile `z` (z = 3.090 for
/// 0.1 %, 4.265 for 0.001 %), by Wilson–Hilferty: χ² ≈ k (1 − 2/(9k) + z √(2/(9k)))³.
pub fn chi2_upper(k: usize, z: f64) -> f64 {
    let k = k.max(1) as f64;
    let c = 2.0 / (9.0 * k);
    k * (1.0 - c + z * c.sqrt()).powi(3)
}

fn basis(th: f64, harmonics: usize, row: &mut [f64]) {
    row[0] = 1.0;
    for h in 1..=harmonics {
        let (s, c) = (h as f64 * th).sin_cos();
        row[2 * h - 1] = c;
        row[2 * h] = s;
    }
}

/// Fits the systematic part of `err` sampled at `t_s`: harmonics of `phase` when given,
/// block means otherwise.
pub fn systematic(err: &[f64], t_s: &[f64], phase: Option<PhaseLine>, harmonics: usize) -> Systematic {
    let n = err.len().min(t_s.len());
    if let Some(c) = phase {
        let p = 2 * harmonics + 1;
        if n > 4 * p && c.rate_rad_s != 0.0 {
            let mut acc = QrAccumulator::new(p + 1, 4096);
            let mut row = vec![0.0; p + 1];
            for k in 0..n {
                basis(c.theta(t_s[k]), harmonics, &mut row);
                row[p] = err[k];
                acc.push(&row);
            }
            let r = acc.r();
            let mut coef = vec![0.0; p];
            let mut ok = true;
            for i in (0..p).rev() {
                let mut s = r[(i, p)];
                for j in i + 1..p {
                    s -= r[(i, j)] * coef[j];
                }
                if r[(i, i)].abs() < 1e-300 {
                    ok = false;
                    break;
                }
                coef[i] = s / r[(i, i)];
            }
            if ok {
                let curve = (0..n)
                    .map(|k| {
                        basis(c.theta(t_s[k]), harmonics, &mut row);
                        (0..p).map(|j| coef[j] * row[j]).sum()
                    })
                    .collect();
                let mut amplitudes = vec![coef[0].abs()];
                for h in 1..=harmonics {
                    amplitudes.push(coef[2 * h - 1].hypot(coef[2 * h]));
                }
                return Systematic {
                    curve,
                    amplitudes,
                    explained: (0..p).map(|i| r[(i, p)] * r[(i, p)]).sum(),
                    sigma2: r[(p, p)] * r[(p, p)] / (n - p) as f64,
                    params: p,
                };
            }
        }
    }
    let block = ((n as f64).sqrt().ceil() as usize).max(2);
    let mut curve = Vec::with_capacity(n);
    let (mut explained, mut within, mut dof, mut blocks) = (0.0, 0.0, 0usize, 0usize);
    for c in err[..n].chunks(block) {
        let m = c.iter().sum::<f64>() / c.len() as f64;
        curve.extend(std::iter::repeat_n(m, c.len()));
        explained += m * m * c.len() as f64;
        within += c.iter().map(|e| (e - m) * (e - m)).sum::<f64>();
        dof += c.len() - 1;
        blocks += 1;
    }
    Systematic {
        curve,
        amplitudes: Vec::new(),
        explained,
        sigma2: if dof > 0 { within / dof as f64 } else { 0.0 },
        params: blocks.max(1),
    }
}
