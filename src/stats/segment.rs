//! Static-interval detection for hand-held multi-position recordings (Tedaldi et al. 2014,
//! §IV-A): a sample is static when the norm of the accelerometer's per-axis variance over a
//! centred window is below a threshold, the threshold being a multiple of the same norm over
//! the initial rest.

/// Per-axis mean of a run of triads (zeros when empty).
pub fn mean3(x: &[[f64; 3]]) -> [f64; 3] {
    let mut m = [0.0; 3];
    for v in x {
        for i in 0..3 {
            m[i] += v[i];
        }
    }
    let n = x.len().max(1) as f64;
    m.map(|s| s / n)
}

/// Per-axis unbiased variance of a run of triads (zeros with fewer than two).
pub fn var3(x: &[[f64; 3]]) -> [f64; 3] {
    let n = x.len();
    if n < 2 {
        return [0.0; 3];
    }
    let m = mean3(x);
    [0, 1, 2].map(|i| x.iter().map(|v| (v[i] - m[i]).powi(2)).sum::<f64>() / (n - 1) as f64)
}

/// Norm of the per-axis unbiased variance of `x[start..end]`.
pub fn variance_norm(x: &[[f64; 3]], start: usize, end: usize) -> f64 {
    let var = var3(&x[start..end.max(start)]);
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

/// A section of a Ferraris recording found by [`detect_ferraris`].
#[derive(Debug, Clone, PartialEq)]
pub struct FerrarisSection {
    /// imucal's name: `x_p`, `x_a`, …, `x_rot`, ….
    pub name: String,
    /// Rows `[start, end)`.
    pub rows: (usize, usize),
    /// Axis index (0..3) of the face's up or the turn.
    pub axis: usize,
    /// +1 or −1: the face's up direction, or the turn's sense (from the gyro's integral).
    pub sign: f64,
}

/// Finds the six faces and three turns of a Ferraris recording without annotations: static
/// intervals where the accelerometer's moving-variance norm (window `window`) stays below
/// `multiplier` × its 10th percentile, at least `min_len` samples long; each interval on a
/// face when one axis carries at least 90 % of the mean specific force (the longest per
/// face is kept); for each axis, the motion between consecutive static intervals whose gyro
/// integral (bias from the faces removed) is largest along that axis and at least 80 % along
/// it is the turn, its sense the integral's sign.
pub fn detect_ferraris(
    t_s: &[f64],
    gyro: &[[f64; 3]],
    accel: &[[f64; 3]],
    window: usize,
    multiplier: f64,
    min_len: usize,
) -> Result<Vec<FerrarisSection>, String> {
    let norms = moving_variance_norm(accel, window);
    let mut finite: Vec<f64> = norms.iter().copied().filter(|x| x.is_finite()).collect();
    if finite.is_empty() {
        return Err(format!("the recording is shorter than the detector window ({window} samples)"));
    }
    let baseline = super::median(&mut finite[..]).unwrap_or(0.0).max(0.0);
    finite.sort_by(f64::total_cmp);
    let quiet = finite[finite.len() / 10].max(baseline * 1e-6).max(f64::MIN_POSITIVE);
    let intervals: Vec<(usize, usize)> =
        static_intervals(&norms, multiplier * quiet).into_iter().filter(|(s, e)| e - s >= min_len).collect();
    let mean = |x: &[[f64; 3]], s: usize, e: usize| mean3(&x[s..e]);
    let mut faces: [[Option<(usize, usize)>; 2]; 3] = [[None; 2]; 3];
    for &(s, e) in &intervals {
        let m = mean(accel, s, e);
        let n = (m[0] * m[0] + m[1] * m[1] + m[2] * m[2]).sqrt();
        let (i, v) = (0..3).map(|i| (i, m[i])).max_by(|a, b| a.1.abs().total_cmp(&b.1.abs())).unwrap_or((0, 0.0));
        if n > 0.0 && v.abs() >= 0.9 * n {
            let slot = &mut faces[i][usize::from(v < 0.0)];
            if slot.is_none_or(|(s0, e0)| e - s > e0 - s0) {
                *slot = Some((s, e));
            }
        }
    }
    let mut out = Vec::new();
    let mut bias = [0.0; 3];
    let mut count = 0usize;
    for (i, pair) in faces.iter().enumerate() {
        for (k, face) in pair.iter().enumerate() {
            let (s, e) = face.ok_or_else(|| {
                format!(
                    "no static interval with {}{} up (found {} static intervals of at least {min_len} samples): hold each face still longer, or give the section list",
                    if k == 0 { "+" } else { "-" },
                    ['x', 'y', 'z'][i],
                    intervals.len()
                )
            })?;
            let g = mean(gyro, s, e);
            for j in 0..3 {
                bias[j] += g[j] * (e - s) as f64;
            }
            count += e - s;
            out.push(FerrarisSection {
                name: format!("{}_{}", ['x', 'y', 'z'][i], if k == 0 { "p" } else { "a" }),
                rows: (s, e),
                axis: i,
                sign: if k == 0 { 1.0 } else { -1.0 },
            });
        }
    }
    let bias = bias.map(|b| b / count.max(1) as f64);
    let mut best: [Option<(f64, (usize, usize))>; 3] = [None; 3];
    for w in intervals.windows(2) {
        let (s, e) = (w[0].1, w[1].0);
        if e <= s + 1 {
            continue;
        }
        let mut integral = [0.0; 3];
        for k in s..e {
            let dt = t_s[k + 1] - t_s[k];
            for j in 0..3 {
                integral[j] += (gyro[k][j] - bias[j]) * dt;
            }
        }
        let n = (integral[0] * integral[0] + integral[1] * integral[1] + integral[2] * integral[2]).sqrt();
        for i in 0..3 {
            if integral[i].abs() >= 0.8 * n && best[i].is_none_or(|(b, _)| integral[i].abs() > b.abs()) {
                best[i] = Some((integral[i], (s, e)));
            }
        }
    }
    for (i, b) in best.iter().enumerate() {
        let (integral, rows) = b.ok_or_else(|| {
            format!("no turn about {} found between the static intervals: give the section list", ['x', 'y', 'z'][i])
        })?;
        out.push(FerrarisSection {
            name: format!("{}_rot", ['x', 'y', 'z'][i]),
            rows,
            axis: i,
            sign: integral.signum(),
        });
    }
    Ok(out)
}
