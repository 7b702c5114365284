//! Text rendering of library results (no numerics beyond unit display).

use crosscal::check::CheckReport;
use crosscal::estimate::{CoefStatus, SensorFit};
use crosscal::units::SensorKind;
use std::fmt::Write;

const RAD2DEG: f64 = 180.0 / std::f64::consts::PI;

/// A coefficient value in the unit users read: gyro biases and residuals in deg/s,
/// accelerometer ones in m/s² (as stored) — scale and coupling dimensionless.
fn display_unit(unit: &str) -> (&str, f64) {
    match unit {
        "rad/s" => ("deg/s", RAD2DEG),
        "1" => ("", 1.0),
        other => (other, 1.0),
    }
}

/// Formats a number with a sensible number of significant digits.
pub fn num(x: f64) -> String {
    if x == 0.0 {
        "0".into()
    } else if x.abs() >= 1e-3 && x.abs() < 1e5 {
        format!("{x:.6}")
    } else {
        format!("{x:.4e}")
    }
}

/// Formats a percentage.
pub fn pct(x: Option<f64>) -> String {
    match x {
        None => "-".into(),
        Some(0.0) => "0 %".into(),
        Some(v) if v.abs() >= 0.01 => format!("{v:.3} %"),
        Some(v) => format!("{v:.2e} %"),
    }
}

/// Formats a ratio.
pub fn ratio(x: Option<f64>) -> String {
    match x {
        None => "-".into(),
        Some(v) if v.is_infinite() => "inf".into(),
        Some(v) if v < 1e5 => format!("{v:.1}x"),
        Some(v) => format!("{v:.2e}x"),
    }
}

/// The coefficient table of one sensor: value ± 2σ.
pub fn sensor_fit(f: &SensorFit, raw: bool, residuals: bool) -> String {
    let mut s = String::new();
    let _ = writeln!(s, "{} coefficients (value ± 2σ):", f.sensor);
    let input = match f.sensor {
        SensorKind::Gyro => "rad/s",
        SensorKind::Accel => "m/s^2",
    };
    for c in &f.coefficients {
        // Raw inputs: coefficients carry the recording's unit ("raw" = counts or volts).
        let raw_unit = match c.unit.as_str() {
            "1" => format!("raw per {input}"),
            "rad/s" | "m/s^2" => "raw".to_string(),
            other => other.replace("rad/s per", "raw per").replace("m/s^2 per", "raw per"),
        };
        let (u, k) = if raw { (raw_unit.as_str(), 1.0) } else { display_unit(&c.unit) };
        let v = match (c.status, c.std_error) {
            (CoefStatus::Fitted, Some(se)) => {
                format!("{:>14} ± {:<11}", num(c.value * k), num(2.0 * se * k))
            }
            (CoefStatus::Fixed, _) => format!("{:>14}   {:<11}", num(c.value * k), "(fixed)"),
            _ => format!("{:>14}   {:<11}", num(c.value * k), "(UNIDENTIFIABLE, held)"),
        };
        let _ = writeln!(s, "  {:<12} {v} {u}", c.name);
    }
    let (ru, rk) = match f.sensor {
        SensorKind::Gyro => ("deg/s", RAD2DEG),
        SensorKind::Accel => ("m/s^2", 1.0),
    };
    for ch in f.channels.iter().filter(|_| residuals) {
        let _ = writeln!(
            s,
            "  residual {}: rms {} max {} {ru} (σ {}; {} samples, {} coefficients, condition {:.3})",
            ch.axis,
            num(ch.residual_rms * rk),
            num(ch.residual_max * rk),
            num(ch.sigma * rk),
            ch.n,
            ch.n_params,
            ch.condition_number
        );
        if ch.coloured_inflation > 1.5 {
            let _ = writeln!(
                s,
                "    coloured residual (lag-1 correlation {:.2}): standard errors widened {:.1}× for it",
                ch.residual_lag1,
                ch.coloured_inflation.sqrt()
            );
        }
    }
    for u in &f.unidentifiable {
        let _ =
            writeln!(s, "  UNIDENTIFIABLE {} (held at {}): {}.\n    remedy: {}", u.held, u.held_at, u.reason, u.remedy);
    }
    for c in &f.correlated {
        let _ = writeln!(s, "  correlated: {} and {} (ρ = {:.3})", c.a, c.b, c.correlation);
    }
    s
}

/// Nonlinear parameters (time delay, dead zone), value ± 2σ.
pub fn nonlinear(params: &[crosscal::estimate::NonlinearParam]) -> String {
    let mut s = String::new();
    if params.is_empty() {
        return s;
    }
    let _ = writeln!(s, "nonlinear parameters (value ± 2σ):");
    for p in params {
        let (u, k) = display_unit(&p.unit);
        let se = match (p.fitted, p.std_error) {
            (false, _) => "(fixed)".to_string(),
            (true, Some(se)) => num(2.0 * se * k),
            (true, None) => "(at a bound: no σ)".to_string(),
        };
        let _ = writeln!(s, "  {:<12} {:>14} ± {:<11} {u}", p.name, num(p.value * k), se);
    }
    s
}

/// The check summary table.
pub fn check_summary(r: &CheckReport) -> String {
    let mut s = String::new();
    let _ = writeln!(
        s,
        "{:<6} {:<4} {:>13} {:>13} {:>12} {:>13} {:>12} {:>9}  pass",
        "sensor", "axis", "before max", "after max", "reduction", "after (sys)", "red. (sys)", "needed"
    );
    for a in &r.summary {
        let _ = writeln!(
            s,
            "{:<6} {:<4} {:>13} {:>13} {:>12} {:>13} {:>12} {:>9}  {}",
            a.sensor.as_str(),
            a.axis,
            pct(a.before_pct),
            pct(a.after_pct),
            ratio(a.reduction),
            pct(a.after_sys_pct),
            ratio(a.reduction_sys),
            ratio(Some(a.threshold)),
            match (a.pass, a.noise_limited) {
                (true, true) => "yes (noise-limited)",
                (true, false) => "yes",
                (false, _) => "NO",
            }
        );
    }
    let _ = writeln!(s, "(errors: max |error| over all runs as % of each run's reference amplitude of the axis; sys = systematic part, cone-phase harmonics; pass uses the systematic reduction; noise-limited = no remaining systematic error is distinguishable from noise)");
    for run in &r.runs {
        if let Some(t) = &run.temperature_outside {
            let _ = writeln!(s, "OUTSIDE THE CALIBRATED TEMPERATURE RANGE: run {}: {t}", run.run);
        }
    }
    s
}

/// Estimated stand settings per run, value ± 2σ next to the label, then the stand's common
/// imperfections (tilt, speed ripple, wobble) and what the runs could not identify.
pub fn stand(params: &[crosscal::estimate::StandParams], base: Option<&crosscal::estimate::StandBase>) -> String {
    let mut s = String::new();
    if params.is_empty() {
        return s;
    }
    let _ = writeln!(s, "stand settings (estimated ± 2σ; label in brackets):");
    let _ = writeln!(
        s,
        "  {:<20} {:>26} {:>28} {:>24} {:>24}",
        "run", "cone angle α (deg)", "rate ω_s (deg/s)", "phase φ (deg)", "rate drift (%/min)"
    );
    for p in params {
        let cell =
            |k: usize| format!("{:.5} ± {:.1e} [{}]", p.value.get(k), 2.0 * p.std_error.get(k), p.nominal.get(k));
        // The drift in % of the rate per minute, from the run's first sample.
        let drift = format!("{:+.4} ± {:.1e}", 6000.0 * p.rate_drift_per_s, 12000.0 * p.rate_drift_se_per_s);
        let _ = writeln!(s, "  {:<20} {:>26} {:>28} {:>24} {:>24}", p.run, cell(0), cell(1), cell(2), drift);
        for h in &p.held {
            let _ = writeln!(s, "    held: {h}");
        }
    }
    if let Some(b) = base {
        let _ = writeln!(s, "stand imperfections common to the runs (estimated ± 2σ):");
        for t in b.summary() {
            let (what, v, se, unit) = (&t.what, t.value, t.std_error, t.unit);
            let phase = match t.phase_deg {
                Some(_) if v < 2.0 * se => "  (not distinguishable from none)".to_string(),
                Some([psi, sp]) => format!("  (phase {psi:+.1} ± {:.1}°)", 2.0 * sp),
                None => String::new(),
            };
            let _ = writeln!(s, "  {what:<36} {v:>+9.4} ± {:.2e} {unit}{phase}", 2.0 * se);
        }
        for h in &b.held {
            let _ = writeln!(s, "  held: {h}");
        }
    }
    s
}

/// Both sensors' coefficients of a profile, in the units of its recordings (protocol
/// profiles show their residuals in the protocol report instead of per channel).
pub fn profile_fits(p: &crosscal::profile::Profile) -> String {
    use crosscal::units::{AccelUnit, GyroUnit};
    let per_channel = p.protocol.is_none();
    sensor_fit(&p.gyro, p.input_units.gyro == GyroUnit::Raw, per_channel)
        + &sensor_fit(&p.accel, p.input_units.accel == AccelUnit::Raw, per_channel)
}

/// The residuals of a protocol fit: poses, turns, pose detection.
pub fn protocol(r: &crosscal::estimate::protocol::ProtocolReport) -> String {
    let mut s = String::new();
    let _ = writeln!(s, "protocol: {} ({} static poses, {} turns/motions)", r.protocol, r.poses.len(), r.turns.len());
    if let Some(d) = &r.detection {
        if !d.rest_note.is_empty() {
            let _ = writeln!(s, "  note: {} (--trim-rest)", d.rest_note);
        }
        match (d.multiplier, d.threshold) {
            (Some(m), Some(t)) => {
                let _ = writeln!(
                    s,
                    "  static poses detected: moving variance over {} samples below {} (= {m} × the initial rest's {}), poses ≥ {} samples",
                    d.window,
                    num(t),
                    num(d.baseline_variance_norm),
                    d.min_pose_samples
                );
                let tried: Vec<String> = d
                    .tried
                    .iter()
                    .map(|(m, n, c)| {
                        format!("×{m}: {n} poses{}", c.map_or(String::new(), |c| format!(", cost {}", num(c))))
                    })
                    .collect();
                let _ = writeln!(s, "  thresholds tried: {}", tried.join("; "));
            }
            _ => {
                let _ = writeln!(s, "  static poses as given in the manifest");
            }
        }
    }
    let worst = r.poses.iter().map(|p| p.gravity_error_m_s2.abs()).fold(0.0, f64::max);
    let _ = writeln!(s, "  |a| − g over the poses: rms {} max {} m/s^2", num(r.gravity_rms_m_s2), num(worst));
    if let Some(c) = r.accel_cost {
        let _ = writeln!(s, "  accelerometer cost ½Σ(g − |a|)²: {}", num(c));
    }
    if let Some(c) = r.gyro_cost {
        let _ = writeln!(s, "  gyro cost ½Σ|Rᵀv₀ − v₁|²: {}", num(c));
    }
    let moving: Vec<&crosscal::estimate::protocol::PoseResidual> =
        r.poses.iter().filter(|p| p.motion.is_some()).collect();
    if !moving.is_empty() {
        let _ = writeln!(
            s,
            "  NOT AT REST: {} of {} poses by the noise of the rest (their means carry motion into the fit):",
            moving.len(),
            r.poses.len()
        );
        for p in moving {
            let _ = writeln!(s, "    {}[{}..{}]: {}", p.run, p.start, p.end, p.motion.as_deref().unwrap_or(""));
        }
    }
    let worst_turn = r.turns.iter().map(|t| t.error_deg.abs()).fold(0.0, f64::max);
    if !r.turns.is_empty() {
        let _ = writeln!(s, "  worst turn/motion misfit: {} deg", num(worst_turn));
    }
    for w in &r.warnings {
        let _ = writeln!(s, "  note: {w}");
    }
    s
}
