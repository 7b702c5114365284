//! Offline correction of a whole record: centred derivative window, iterated to a fixed
//! point (each pass re-estimates ε̂ and the effect terms from the previous pass). The
//! temperature's rate of change (thermal hysteresis) is the centred smoothed one the fit uses.

use super::{check_inputs, ensure_finite, mv, set_flags, solve, Calibration, CorrectError, Corrected};
use crate::model::State;
use crate::motion::{derivative_offline, DerivativeConfig};

/// Offline correction of a whole record (SI inputs; temperature optional).
pub fn correct_offline(
    cal: &Calibration,
    t_s: &[f64],
    gyro: &[[f64; 3]],
    accel: &[[f64; 3]],
    temp_c: Option<&[f64]>,
) -> Result<Corrected, CorrectError> {
    let n = t_s.len();
    check_inputs(cal, n, gyro, accel, temp_c)?;
    // The thermal branch from the column as recorded (a clamped temperature still changes),
    // centred like the fit's.
    let rates: Option<Vec<f64>> =
        temp_c.filter(|_| cal.needs_temperature_rate()).map(|t| crate::stats::temp_rate::centred(t_s, t));
    // Temperatures outside the calibrated range: guarded once (one copy of the column).
    let mut temp_outside = cal.temp_guard();
    let guarded: Option<Vec<f64>> =
        temp_c.map(|t| t.iter().zip(t_s).map(|(&x, &ts)| temp_outside.guard(ts, x)).collect());
    super::refuse_outside(&temp_outside)?;
    let temp_c = guarded.as_deref();
    let g = &cal.gyro;
    let a = &cal.accel;
    const Z: [f64; 3] = [0.0; 3];
    let mut w: Vec<[f64; 3]> = gyro.iter().map(|u| solve(g.scale_inv.matrix(), *u, g.bias, Z, Z)).collect();
    let mut acc: Vec<[f64; 3]> = accel.iter().map(|u| solve(a.scale_inv.matrix(), *u, a.bias, Z, Z)).collect();
    // With nonlinear effects, `seen` keeps the linear inverse's output (the input as the sensor
    // saw it), which is what the other effects' regressors take, as in the forward model;
    // `w`, `acc` hold the true input after the nonlinear inverses.
    let nonlinear = !cal.nonlinear.is_empty();
    let mut seen: Vec<([f64; 3], [f64; 3])> =
        if nonlinear { w.iter().copied().zip(acc.iter().copied()).collect() } else { Vec::new() };
    let mut flags: Vec<u8> = Vec::new();
    if nonlinear {
        for k in 0..n {
            let f = cal.invert_nonlinear(&mut w[k], &mut acc[k]);
            set_flags(&mut flags, n, k, f);
        }
    }
    let needs_eps = g.eps.matrix().iter().any(|v| *v != 0.0) || g.has_other_terms() || a.has_other_terms() || nonlinear;
    let deriv =
        DerivativeConfig { half_window: cal.settings.derivative_half_window, degree: cal.settings.derivative_degree };
    let mut e = vec![[0.0; 3]; n];
    let mut iterations = 0;
    let mut converged = !needs_eps;
    let mut last_change = (0.0_f64, 1.0_f64);
    while needs_eps && iterations < 50 {
        iterations += 1;
        derivative_offline(t_s, &w, &deriv, &mut e);
        let (mut change_w, mut size_w, mut change_a, mut size_a) = (0.0_f64, 0.0_f64, 0.0_f64, 0.0_f64);
        for k in 0..n {
            let (sw, sa) = if nonlinear { seen[k] } else { (w[k], acc[k]) };
            let s = State {
                t_session_s: t_s[k],
                w: sw,
                e: e[k],
                a: sa,
                temp_c: temp_c.map_or(f64::NAN, |t| t[k]),
                temp_rate_c_s: rates.as_ref().map_or(f64::NAN, |r| r[k]),
            };
            let ee = mv(g.eps.matrix(), e[k]);
            let og = g.other(&s);
            let oa = a.other(&s);
            let mut wn = solve(g.scale_inv.matrix(), gyro[k], g.bias, ee, og);
            let mut an = solve(a.scale_inv.matrix(), accel[k], a.bias, oa, Z);
            if nonlinear {
                seen[k] = (wn, an);
                let f = cal.invert_nonlinear(&mut wn, &mut an);
                set_flags(&mut flags, n, k, f);
            }
            for i in 0..3 {
                change_w = change_w.max((wn[i] - w[k][i]).abs());
                size_w = size_w.max(wn[i].abs());
                change_a = change_a.max((an[i] - acc[k][i]).abs());
                size_a = size_a.max(an[i].abs());
            }
            w[k] = wn;
            acc[k] = an;
        }
        last_change = if change_w * size_a.max(f64::MIN_POSITIVE) >= change_a * size_w.max(f64::MIN_POSITIVE) {
            (change_w, size_w.max(f64::MIN_POSITIVE))
        } else {
            (change_a, size_a.max(f64::MIN_POSITIVE))
        };
        if change_w <= 1e-14 * size_w.max(f64::MIN_POSITIVE) && change_a <= 1e-14 * size_a.max(f64::MIN_POSITIVE) {
            converged = true;
            break;
        }
    }
    // Passes that stop changing below 1e-9 of the signal have converged for every practical
    // purpose; anything larger after the last pass is a fixed point that was not reached
    // (the profile's C_ε times the derivative's gain at this sample rate exceeds one).
    if !converged && (last_change.0 > 1e-9 * last_change.1 || last_change.0.is_nan()) {
        return Err(CorrectError::NotConverged { passes: iterations, change: last_change.0 / last_change.1 });
    }
    let out = Corrected {
        w_rad_s: w,
        a_m_s2: acc,
        iterations,
        converged,
        warmup: 0,
        flags,
        time_offset_s: cal.lag_s(),
        temp_outside,
    };
    ensure_finite(out, t_s)
}

/// Resamples a correction with a time offset onto the input stamps (cubic interpolation):
/// sample k then estimates the truth at t_k. Stamps whose source time falls outside the
/// record are flagged (all channels). Interpolation colours the noise (it averages
/// neighbours), so statistics that assume white noise should use the unshifted output.
pub fn resample_to_stamps(c: &Corrected, t_s: &[f64]) -> Corrected {
    let lag = c.time_offset_s;
    if lag == 0.0 || t_s.is_empty() {
        return c.clone();
    }
    let n = t_s.len();
    let mut flags = c.flags.clone();
    let (first, last) = (t_s[0], t_s[n - 1]);
    for (k, &t) in t_s.iter().enumerate() {
        if t + lag < first || t + lag > last {
            set_flags(&mut flags, n, k, 0x3f);
        }
    }
    let (mut h1, mut h2) = (0, 0);
    Corrected {
        w_rad_s: t_s.iter().map(|&t| crate::model::nonlinear::interpolate(t_s, &c.w_rad_s, t + lag, &mut h1)).collect(),
        a_m_s2: t_s.iter().map(|&t| crate::model::nonlinear::interpolate(t_s, &c.a_m_s2, t + lag, &mut h2)).collect(),
        iterations: c.iterations,
        converged: c.converged,
        temp_outside: c.temp_outside,
        warmup: c.warmup,
        flags,
        time_offset_s: 0.0,
    }
}
