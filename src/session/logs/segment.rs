//! Rests and motions of a long recording, told apart while it streams past: the samples
//! are cut into blocks (0.5 s and at least 10 samples), each block keeps its mean and
//! scatter, and once the recording has ended the blocks say whether it is at rest
//! throughout (a `static` session for `noise`), a sequence of rests in several
//! orientations (a `multi_position` session, with the initial rest's length) or neither.
//!
//! A block moves when its gyro or accelerometer scatter exceeds 4× the median block's (with
//! floors of 1e-3 rad/s and 1e-2 m/s² for quantised data), or its mean rate differs from
//! the median block's by more than 5× that scatter + 0.01 rad/s (a slow smooth turn has
//! little scatter), or its scatter exceeds what no rest shows (0.05 rad/s, 0.3 m/s²: a
//! flight vibrates throughout). Orientations are the rests' mean gravity directions, merged within 5°.

fn median(v: &[f64]) -> f64 {
    crate::stats::median(&mut v.to_vec()).unwrap_or(0.0)
}

/// One block's moments.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
struct Block {
    t0_s: f64,
    t1_s: f64,
    n: usize,
    g_mean: [f64; 3],
    g_std: f64,
    a_mean: [f64; 3],
    a_std: f64,
}

/// Streamed block moments (memory: one small record per block).
#[derive(Debug, Default)]
pub struct Blocks {
    blocks: Vec<Block>,
    /// Block length, s (0 = not started: [`BLOCK_S`]); doubled each time the list is halved.
    block_s: f64,
    n: usize,
    t0: f64,
    t1: f64,
    sg: [f64; 3],
    sgg: [f64; 3],
    sa: [f64; 3],
    saa: [f64; 3],
}

const BLOCK_S: f64 = 0.5;
/// Blocks kept at most (88 bytes each): past it neighbours are merged.
const MAX_BLOCKS: usize = 1 << 14;

/// Two neighbouring blocks as one: pooled means and scatters (the scatter is the norm of
/// the per-axis standard deviations, so the pooled one is
/// √((n₁(s₁² + |m₁|²) + n₂(s₂² + |m₂|²))/n − |m|²)).
fn merge(a: &Block, b: &Block) -> Block {
    let n = (a.n + b.n) as f64;
    let (wa, wb) = (a.n as f64 / n, b.n as f64 / n);
    let mean = |x: [f64; 3], y: [f64; 3]| std::array::from_fn(|k| wa * x[k] + wb * y[k]);
    let sq = |m: [f64; 3]| m.iter().map(|v| v * v).sum::<f64>();
    let pooled = |sa: f64, ma: [f64; 3], sb: f64, mb: [f64; 3], m: [f64; 3]| {
        (wa * (sa * sa + sq(ma)) + wb * (sb * sb + sq(mb)) - sq(m)).max(0.0).sqrt()
    };
    let g_mean = mean(a.g_mean, b.g_mean);
    let a_mean = mean(a.a_mean, b.a_mean);
    Block {
        t0_s: a.t0_s,
        t1_s: b.t1_s,
        n: a.n + b.n,
        g_mean,
        g_std: pooled(a.g_std, a.g_mean, b.g_std, b.g_mean, g_mean),
        a_mean,
        a_std: pooled(a.a_std, a.a_mean, b.a_std, b.a_mean, a_mean),
    }
}
const BLOCK_MIN: usize = 10;

impl Blocks {
    /// Adds a sample (t s, rad/s, m/s²).
    pub fn push(&mut self, t_s: f64, g: [f64; 3], a: [f64; 3]) {
        if self.n == 0 {
            self.t0 = t_s;
        }
        self.t1 = t_s;
        self.n += 1;
        for k in 0..3 {
            self.sg[k] += g[k];
            self.sgg[k] += g[k] * g[k];
            self.sa[k] += a[k];
            self.saa[k] += a[k] * a[k];
        }
        if self.n >= BLOCK_MIN && t_s - self.t0 >= self.block_s.max(BLOCK_S) {
            self.close();
        }
    }

    /// Halves the list by merging neighbours (memory stays under [`MAX_BLOCKS`] blocks
    /// whatever the recording's length; a long recording is judged in longer blocks).
    fn compact(&mut self) {
        let merged: Vec<Block> =
            self.blocks.chunks(2).map(|p| if p.len() == 2 { merge(&p[0], &p[1]) } else { p[0] }).collect();
        self.blocks = merged;
        self.block_s = 2.0 * self.block_s.max(BLOCK_S);
    }

    fn close(&mut self) {
        if self.n < 2 {
            return;
        }
        let n = self.n as f64;
        let mean = |s: [f64; 3]| s.map(|x| x / n);
        let std =
            |s: [f64; 3], ss: [f64; 3]| (0..3).map(|k| (ss[k] / n - (s[k] / n).powi(2)).max(0.0)).sum::<f64>().sqrt();
        self.blocks.push(Block {
            t0_s: self.t0,
            t1_s: self.t1,
            n: self.n,
            g_mean: mean(self.sg),
            g_std: std(self.sg, self.sgg),
            a_mean: mean(self.sa),
            a_std: std(self.sa, self.saa),
        });
        *self = Blocks { blocks: std::mem::take(&mut self.blocks), block_s: self.block_s, ..Blocks::default() };
        if self.blocks.len() >= MAX_BLOCKS {
            self.compact();
        }
    }

    /// Classifies the recording (the last partial block included when long enough).
    pub fn finish(mut self) -> Summary {
        self.close();
        summarise(&self.blocks)
    }
}

/// What the blocks say about a recording.
#[derive(Debug, Clone, PartialEq)]
pub struct Summary {
    /// Blocks, and of them moving.
    pub blocks: usize,
    /// Moving blocks.
    pub moving: usize,
    /// Rests `[start, end]`, s.
    pub rests: Vec<(f64, f64)>,
    /// Distinct orientations among the rests.
    pub orientations: usize,
    /// Largest angle between a block's mean gravity direction and the median one, degrees.
    pub tilt_spread_deg: f64,
}

impl Summary {
    /// At rest throughout, in one orientation.
    pub fn is_static(&self) -> bool {
        self.blocks > 0 && self.moving == 0 && self.tilt_spread_deg < 2.0
    }

    /// The initial rest's length, s, when the recording starts at rest.
    pub fn initial_rest_s(&self) -> Option<f64> {
        self.rests.first().filter(|r| r.0 <= 1.0).map(|r| r.1 - r.0)
    }
}

/// Block scatter no rest shows whatever the unit (rad/s, m/s²): a recording that vibrates
/// throughout (a flight) has a median block as busy as its others.
const GYRO_STD_REST: f64 = 0.05;
const ACCEL_STD_REST: f64 = 0.3;

fn unit(v: [f64; 3]) -> [f64; 3] {
    let n = v.iter().map(|x| x * x).sum::<f64>().sqrt();
    if n > 0.0 {
        v.map(|x| x / n)
    } else {
        v
    }
}

fn angle_deg(a: [f64; 3], b: [f64; 3]) -> f64 {
    let (a, b) = (unit(a), unit(b));
    (a[0] * b[0] + a[1] * b[1] + a[2] * b[2]).clamp(-1.0, 1.0).acos().to_degrees()
}

fn summarise(blocks: &[Block]) -> Summary {
    if blocks.is_empty() {
        return Summary { blocks: 0, moving: 0, rests: Vec::new(), orientations: 0, tilt_spread_deg: 0.0 };
    }
    let gs: Vec<f64> = blocks.iter().map(|b| b.g_std).collect();
    let as_: Vec<f64> = blocks.iter().map(|b| b.a_std).collect();
    let sg = median(&gs).max(1e-3);
    let sa = median(&as_).max(1e-2);
    let bias: [f64; 3] = std::array::from_fn(|k| median(&blocks.iter().map(|b| b.g_mean[k]).collect::<Vec<_>>()));
    let up: [f64; 3] = std::array::from_fn(|k| median(&blocks.iter().map(|b| unit(b.a_mean)[k]).collect::<Vec<_>>()));
    let moving: Vec<bool> = blocks
        .iter()
        .map(|b| {
            let dg = (0..3).map(|k| (b.g_mean[k] - bias[k]).powi(2)).sum::<f64>().sqrt();
            let shaking = b.g_std > GYRO_STD_REST || b.a_std > ACCEL_STD_REST;
            shaking || b.g_std > 4.0 * sg || b.a_std > 4.0 * sa || dg > 5.0 * sg + 0.01
        })
        .collect();
    let mut rests = Vec::new();
    let mut dirs: Vec<[f64; 3]> = Vec::new();
    let mut i = 0;
    while i < blocks.len() {
        if moving[i] {
            i += 1;
            continue;
        }
        let j = (i..blocks.len()).find(|&j| moving[j]).unwrap_or(blocks.len());
        rests.push((blocks[i].t0_s, blocks[j - 1].t1_s));
        let mut d = [0.0; 3];
        for b in &blocks[i..j] {
            for k in 0..3 {
                d[k] += b.a_mean[k] * b.n as f64;
            }
        }
        if !dirs.iter().any(|e| angle_deg(*e, d) < 5.0) {
            dirs.push(d);
        }
        i = j;
    }
    let tilt = blocks.iter().map(|b| angle_deg(b.a_mean, up)).fold(0.0, f64::max);
    Summary {
        blocks: blocks.len(),
        moving: moving.iter().filter(|&&m| m).count(),
        rests,
        orientations: dirs.len(),
        tilt_spread_deg: tilt,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn feed(b: &mut Blocks, t0: f64, n: usize, rate: f64, g: [f64; 3], a: [f64; 3], seed: &mut u64) {
        for i in 0..n {
            *seed = seed.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            let u = (*seed >> 11) as f64 / (1u64 << 53) as f64 - 0.5;
            b.push(t0 + i as f64 / rate, g.map(|x| x + 1e-3 * u), a.map(|x| x + 2e-2 * u));
        }
    }

    #[test]
    fn rests_and_poses_are_told_from_a_static_recording() {
        let mut seed = 1;
        let mut s = Blocks::default();
        feed(&mut s, 0.0, 6000, 100.0, [0.01, 0.0, 0.0], [0.0, 0.0, 9.8], &mut seed);
        let sum = s.finish();
        assert!(sum.is_static(), "{sum:?}");
        assert_eq!(sum.rests.len(), 1);

        let mut m = Blocks::default();
        feed(&mut m, 0.0, 3000, 100.0, [0.0; 3], [0.0, 0.0, 9.8], &mut seed);
        feed(&mut m, 30.0, 200, 100.0, [0.8, 0.0, 0.0], [0.0, 5.0, 5.0], &mut seed);
        feed(&mut m, 32.0, 1000, 100.0, [0.0; 3], [0.0, 9.8, 0.0], &mut seed);
        feed(&mut m, 42.0, 200, 100.0, [0.0, 0.8, 0.0], [5.0, 5.0, 0.0], &mut seed);
        feed(&mut m, 44.0, 1000, 100.0, [0.0; 3], [9.8, 0.0, 0.0], &mut seed);
        let sum = m.finish();
        assert!(!sum.is_static());
        assert_eq!(sum.orientations, 3, "{sum:?}");
        let init = sum.initial_rest_s().unwrap_or(0.0);
        assert!((init - 30.0).abs() < 1.0, "initial rest {init}");
    }

    #[test]
    fn a_long_recording_keeps_few_blocks_and_the_same_verdict() {
        let mut seed = 3;
        let mut b = Blocks::default();
        // 3 h at 100 Hz: 21 600 half-second blocks, so the list is halved once.
        feed(&mut b, 0.0, 1_080_000, 100.0, [0.01, 0.0, 0.0], [0.0, 0.0, 9.8], &mut seed);
        assert!(b.blocks.len() < MAX_BLOCKS && b.block_s > BLOCK_S, "{} blocks of {} s", b.blocks.len(), b.block_s);
        let sum = b.finish();
        assert!(sum.is_static(), "{sum:?}");
        // Pooling two blocks gives the moments of their samples taken together.
        let x = Block { t0_s: 0.0, t1_s: 1.0, n: 2, g_mean: [1.0, 0.0, 0.0], g_std: 1.0, a_mean: [0.0; 3], a_std: 0.0 };
        let y = Block { t0_s: 1.0, t1_s: 2.0, n: 2, g_mean: [3.0, 0.0, 0.0], g_std: 1.0, a_mean: [0.0; 3], a_std: 0.0 };
        // Samples 0, 2, 2, 4 on x: mean 2, variance 2.
        let m = merge(&x, &y);
        assert!((m.g_mean[0] - 2.0).abs() < 1e-12 && (m.g_std - 2f64.sqrt()).abs() < 1e-12, "{m:?}");
    }
}
