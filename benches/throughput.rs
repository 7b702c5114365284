//! Throughput benchmarks (`cargo bench`): prints a table of measured rates. Speed claims in
//! the README come from this, never from timed tests.

use crosscal::noise::{analyse_channel, NoiseOptions};
use crosscal::simulate::noise::NoiseProcess;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use std::time::Instant;

fn best_of<T>(reps: usize, mut f: impl FnMut() -> T) -> (f64, T) {
    let mut best = f64::INFINITY;
    let mut out = None;
    for _ in 0..reps {
        let t0 = Instant::now();
        let v = f();
        best = best.min(t0.elapsed().as_secs_f64());
        out = Some(v);
    }
    (best, out.expect("at least one repetition"))
}

/// Allan deviation of a 1e7-sample, six-channel static recording on one core.
fn noise() {
    let n = 10_000_000usize;
    let p = NoiseProcess { white_density: 1e-3, bias_instability: 1e-4, random_walk: 1e-6, ar1: None };
    let mut rng = ChaCha8Rng::seed_from_u64(1);
    let mut g = p.generator(0.01, n as f64 * 0.01);
    let data: Vec<f64> = (0..n).map(|_| g.next_sample(&mut rng)).collect();
    let (secs, _) = best_of(3, || {
        let mut total = 0;
        for _ in 0..6 {
            // Each channel's column is its own input buffer (the copy is part of the cost).
            let mut col = data.clone();
            let r = analyse_channel("gx", "rad/s", &mut col, 0.01, NoiseOptions::default()).expect("analysis");
            total += r.points.len();
        }
        total
    });
    println!(
        "noise   | Allan deviation, 1e7 samples × 6 channels, one core | {secs:.3} s ({:.3} s per channel)",
        secs / 6.0
    );
}

fn main() {
    let only = std::env::args().skip(1).find(|a| !a.starts_with('-'));
    if only.as_deref().is_none_or(|o| "noise".contains(o)) {
        noise();
    }
}
