//! Static-interval detection for hand-held multi-position recordings (Tedaldi et al. 2014,
//! §IV-A): a sample is static when the norm of the accelerometer's per-axis variance over a
//! centred window is below a threshold, the threshold being a multiple of the same norm over
//! the initial rest.

/// Norm of the per-axis unbiased variance of `x[start..end]`.
pub fn variance_norm(x: &[[f64; 3]], start: usize, end: usize) -> f64 {
    let n = end.saturating_sub(start);
    if n < 2 {
        return 0.0;
    }
    let mut var = [0.0; 3];
    for i in 0..3 {
        let mean = x[start..end].iter().map(|v| v[i]).sum::<f64>() / n as f64;
        var[i] = x[start..end].iter().map(|v| (v[i] - mean).powi(2)).sum::<f64>() / (n - 1) as f64;
    }
    (var[0] * var[0] + var[1] * var[1] + var[2] * var[2]).sqrt()
}

/// For every centre `i` in `h..n-h` (`h = window/2`), the norm of the per-axis variance over
/// `[i-h, i+h]`; `NaN` near the ends. Running sums of the data minus its first sample keep
/// the cost O(n) and the cancellation small.
pub fn moving_variance_norm(x: &[[f64; 3]], window: usize) -> Vec<f64> {
    let n = x.len();
    let w = window | 1;
    let h = w / 2;
    let mut out = vec![f64::NAN; n];
    if n < w || w < 3 {
        return out;
    }
    let x0 = x[0];
    let mut s = [0.0; 3];
    let mut s2 = [0.0; 3];
    let add = |s: &mut [f64; 3], s2: &mut [f64; 3], v: &[f64; 3], sign: f64| {
        for i in 0..3 {
            let d = v[i] - x0[i];
            s[i] += sign * d;
            s2[i] += sign * d * d;
        }
    };
    for v in &x[..w] {
        add(&mut s, &mut s2, v, 1.0);
    }
    let wf = w as f64;
    for c in h..n - h {
        if c > h {
            add(&mut s, &mut s2, &x[c + h], 1.0);
            add(&mut s, &mut s2, &x[c - h - 1], -1.0);
        }
        let mut q = 0.0;
        for i in 0..3 {
            let var = ((s2[i] - s[i] * s[i] / wf) / (wf - 1.0)).max(0.0);
            q += var * var;
        }
        out[c] = q.sqrt();
    }
    out
}

/// Maximal runs `[start, end)` where `norms < threshold` (NaN counts as moving).
pub fn static_intervals(norms: &[f64], threshold: f64) -> Vec<(usize, usize)> {
    let mut out = Vec::new();
    let mut start = None;
    for (i, &q) in norms.iter().enumerate() {
        let still = q < threshold;
        match (still, start) {
            (true, None) => start = Some(i),
            (false, Some(s)) => {
                out.push((s, i));
                start = None;
            }
            _ => {}
        }
    }
    if let Some(s) = start {
        let end = norms.iter().rposition(|q| !q.is_nan()).map_or(norms.len(), |e| e + 1);
        if end > s {
            out.push((s, end));
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn moving_variance_matches_direct_and_finds_the_still_parts() {
        // Still, moving (a ramp with wiggle), still.
        let mut x = Vec::new();
        for k in 0..600 {
            let v = match k {
                0..200 => [1000.0, 2.0, -5.0],
                200..300 => [1000.0 + (k as f64 * 0.7).sin() * 50.0, k as f64, -5.0],
                _ => [900.0, 300.0, 10.0],
            };
            x.push([v[0] + (k % 3) as f64 * 0.1, v[1], v[2]]);
        }
        let q = moving_variance_norm(&x, 21);
        for c in [10, 150, 250, 400, 589] {
            let d = variance_norm(&x, c - 10, c + 11);
            assert!((q[c] - d).abs() <= 1e-9 * d.max(1.0), "{c}: {} vs {d}", q[c]);
        }
        let iv = static_intervals(&q, 0.1);
        assert_eq!(iv.len(), 2, "{iv:?}");
        assert_eq!(iv[0], (10, 190));
        assert_eq!(iv[1], (310, 590));
    }
}
