//! A production-line thermal sweep: the unit in a chamber whose set point steps (or ramps)
//! through a list of plateaus; at each plateau, after a soak, the unit is recorded in several
//! orientations (static faces and/or conic runs), and optionally during the ramps between
//! plateaus. The unit's temperature follows the chamber with a first-order lag, and the
//! temperature sensor reads it with white noise and a quantisation step.
//!
//! The lag is the first-order system τ du/dt = c(t) − u. Between knots the chamber set point
//! is linear, c(s) = a + r s, and the response is the closed form of a first-order system to a
//! ramp (a step is r = 0; K. Ogata, *Modern Control Engineering*, 5th ed., §5-3, the unit-ramp
//! response c(t) = t − T + T e^(−t/T)):
//!
//! u(s) = a + r (s − τ) + (u₀ − a + r τ) e^(−s/τ),
//!
//! so the unit temperature at any instant is exact, whatever the sample rate.

use super::{cyclic_mounts, RunPlan, SimConfig};
use crate::session::MotionSpec;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};

/// The six static faces, in recording order: up = +z, −z, +x, −x, +y, −y (stand axes).
pub const FACES: [(&str, [f64; 3]); 6] = [
    ("face+z", [0.0, 0.0, 1.0]),
    ("face-z", [0.0, 0.0, -1.0]),
    ("face+x", [1.0, 0.0, 0.0]),
    ("face-x", [-1.0, 0.0, 0.0]),
    ("face+y", [0.0, 1.0, 0.0]),
    ("face-y", [0.0, -1.0, 0.0]),
];

/// The first `count` (at most six) of [`FACES`] as static runs of `duration_s` each, on the
/// nominal mount, without earth rate.
pub fn faces(count: usize, duration_s: f64) -> Vec<RunPlan> {
    let mount = cyclic_mounts(1).remove(0);
    FACES
        .iter()
        .take(count)
        .map(|(name, up)| RunPlan {
            name: (*name).to_string(),
            motion: MotionSpec::Static { up_stand: *up, earth_rate_rad_s: [0.0; 3] },
            mount: mount.clone(),
            duration_s,
        })
        .collect()
}

/// A chamber sweep as a production line runs it.
#[derive(Debug, Clone, PartialEq)]
pub struct ThermalSweep {
    /// Chamber set points of the plateaus, °C, in the order they are visited.
    pub plateaus_c: Vec<f64>,
    /// The runs recorded at every plateau (each plateau's copies are named `p1-…`, `p2-…`).
    pub runs: Vec<RunPlan>,
    /// Wait from the chamber reaching a set point to the plateau's first run, s (not recorded,
    /// as a line skips the unsettled start).
    pub soak_s: f64,
    /// Time constant of the unit's first-order lag behind the chamber, s (0: no lag).
    pub tau_s: f64,
    /// Chamber and unit temperature when the sweep starts, °C.
    pub start_c: f64,
    /// Chamber ramp rate between set points, °C/min; `None` steps the set point at once.
    pub ramp_c_per_min: Option<f64>,
    /// Record during the ramps too: the plateau's runs in turn, as many as fit in each ramp.
    pub record_ramps: bool,
    /// A run whose unit temperature is farther than this from the set point, °C, is marked
    /// as not settled in its note.
    pub settled_within_c: f64,
}

impl ThermalSweep {
    /// A sweep over `plateaus_c` recording `runs` at each, stepping the set point, with the
    /// unit following the chamber at once (no lag, no soak), starting at 20 °C.
    pub fn new(plateaus_c: Vec<f64>, runs: Vec<RunPlan>) -> Self {
        Self {
            plateaus_c,
            runs,
            soak_s: 0.0,
            tau_s: 0.0,
            start_c: crate::model::T_REF_C,
            ramp_c_per_min: None,
            record_ramps: false,
            settled_within_c: 0.1,
        }
    }

    /// Refuses a sweep that cannot run: no plateau, a temperature outside −100 … 300 °C, no
    /// run at a plateau, or a soak, time constant, ramp rate or settling tolerance that is not
    /// a finite number of the right sign.
    pub fn check(&self) -> Result<(), String> {
        let in_range = |t: f64| (-100.0..=300.0).contains(&t);
        if self.plateaus_c.is_empty() || !self.plateaus_c.iter().all(|&t| in_range(t)) {
            return Err("a thermal sweep needs at least one plateau set point in °C, each within -100..300".into());
        }
        if !in_range(self.start_c) {
            return Err(format!("the chamber start temperature {} °C is outside -100..300", self.start_c));
        }
        if self.runs.is_empty() {
            return Err("a thermal sweep needs at least one run at each plateau (static faces or conic runs)".into());
        }
        let nonneg = |v: f64| v.is_finite() && v >= 0.0;
        if !(nonneg(self.soak_s) && nonneg(self.tau_s)) {
            return Err(format!(
                "soak {} s, time constant {} s: expected finite, non-negative seconds",
                self.soak_s, self.tau_s
            ));
        }
        if let Some(r) = self.ramp_c_per_min.filter(|r| !(r.is_finite() && *r > 0.0)) {
            return Err(format!("ramp rate {r} °C/min: expected a positive rate"));
        }
        if self.record_ramps && self.ramp_c_per_min.is_none() {
            return Err("recording the ramps needs a ramp rate (the set point otherwise steps)".into());
        }
        if !(self.settled_within_c.is_finite() && self.settled_within_c > 0.0) {
            return Err(format!("settling tolerance {} °C: expected a positive number", self.settled_within_c));
        }
        Ok(())
    }

    /// The runs of the whole sweep, in recording order, and the chamber program that gives
    /// each its start time and note.
    pub fn schedule(&self) -> (Vec<RunPlan>, Chamber) {
        let mut knots = vec![(0.0, self.start_c)];
        let (mut runs, mut starts) = (Vec::new(), Vec::new());
        let (mut t, mut prev) = (0.0, self.start_c);
        let n = self.plateaus_c.len();
        for (p, &sp) in self.plateaus_c.iter().enumerate() {
            let ramp_s = self.ramp_c_per_min.map_or(0.0, |r| (sp - prev).abs() / r * 60.0);
            knots.push((t, prev));
            knots.push((t + ramp_s, sp));
            if self.record_ramps && ramp_s > 0.0 {
                let what = format!("ramp to plateau {}/{n}: chamber {prev} → {sp} °C", p + 1);
                let mut used = 0.0;
                for (j, base) in self.runs.iter().cycle().enumerate() {
                    if used + base.duration_s > ramp_s {
                        break;
                    }
                    runs.push(RunPlan { name: format!("ramp{}-{:02}-{}", p + 1, j + 1, base.name), ..base.clone() });
                    starts.push((t + used, Role::Ramp(what.clone())));
                    used += base.duration_s;
                }
            }
            t += ramp_s + self.soak_s;
            for base in &self.runs {
                runs.push(RunPlan { name: format!("p{}-{}", p + 1, base.name), ..base.clone() });
                starts.push((t, Role::Plateau { index: p + 1, of: n, set_point_c: sp }));
                t += base.duration_s;
            }
            prev = sp;
        }
        let chamber = Chamber::new(knots, self.start_c, self.tau_s, starts, self.settled_within_c);
        (runs, chamber)
    }

    /// Makes `cfg` simulate this sweep: its runs become the sweep's, the chamber program sets
    /// every run's temperature (the breakpoints of `temperature_c` are dropped).
    pub fn apply(&self, cfg: &mut SimConfig) -> Result<(), String> {
        self.check()?;
        let (runs, chamber) = self.schedule();
        cfg.runs = runs;
        cfg.chamber = Some(chamber);
        cfg.temperature_c = None;
        Ok(())
    }
}

/// What a run of a sweep is: a plateau's, or a ramp's (with its description).
#[derive(Debug, Clone, PartialEq)]
enum Role {
    Plateau { index: usize, of: usize, set_point_c: f64 },
    Ramp(String),
}

/// A chamber program and the unit in it: the set point, piecewise linear in time between
/// knots (a step is two knots at one instant), the unit's first-order lag behind it, and the
/// start of every run on the chamber clock.
#[derive(Debug, Clone, PartialEq)]
pub struct Chamber {
    /// Set point knots (t_s, °C), times non-decreasing; constant after the last.
    knots: Vec<(f64, f64)>,
    /// Unit temperature at each knot, °C.
    unit_at_knot_c: Vec<f64>,
    tau_s: f64,
    runs: Vec<(f64, Role)>,
    settled_within_c: f64,
}

/// The response at `s` of the first-order lag of time constant `tau` (from `u0`) to the input
/// a + r s (the module's closed form; no lag when τ = 0).
fn lag(u0: f64, a: f64, r: f64, tau: f64, s: f64) -> f64 {
    if tau > 0.0 {
        a + r * (s - tau) + (u0 - a + r * tau) * (-s / tau).exp()
    } else {
        a + r * s
    }
}

impl Chamber {
    fn new(knots: Vec<(f64, f64)>, start_c: f64, tau_s: f64, runs: Vec<(f64, Role)>, settled_within_c: f64) -> Self {
        let mut unit_at_knot_c = vec![start_c];
        for w in knots.windows(2) {
            let (((t0, c0), (t1, c1)), u0) = ((w[0], w[1]), unit_at_knot_c[unit_at_knot_c.len() - 1]);
            let d = t1 - t0;
            let u1 = if d > 0.0 { lag(u0, c0, (c1 - c0) / d, tau_s, d) } else { u0 };
            unit_at_knot_c.push(u1);
        }
        Self { knots, unit_at_knot_c, tau_s, runs, settled_within_c }
    }

    /// The segment holding `t_s`: its knot index, start time, set point and rate (°C/s).
    fn segment(&self, t_s: f64) -> (usize, f64, f64, f64) {
        let j = self.knots.partition_point(|k| k.0 <= t_s).saturating_sub(1);
        let (t0, c0) = self.knots[j];
        let rate = match self.knots.get(j + 1) {
            Some(&(t1, c1)) if t1 > t0 => (c1 - c0) / (t1 - t0),
            _ => 0.0,
        };
        (j, t0, c0, rate)
    }

    /// The chamber set point at `t_s` on the chamber clock, °C.
    pub fn set_point_c(&self, t_s: f64) -> f64 {
        let (_, t0, c0, r) = self.segment(t_s);
        c0 + r * (t_s - t0).max(0.0)
    }

    /// The unit's true temperature at `t_s` on the chamber clock, °C.
    pub fn unit_c(&self, t_s: f64) -> f64 {
        let (j, t0, c0, r) = self.segment(t_s);
        lag(self.unit_at_knot_c[j], c0, r, self.tau_s, (t_s - t0).max(0.0))
    }

    /// Start of run `index` on the chamber clock, s.
    pub fn run_start_s(&self, index: usize) -> Option<f64> {
        self.runs.get(index).map(|r| r.0)
    }

    /// The manifest note of run `index` lasting `duration_s`: its plateau and set point (or
    /// its ramp) and, when the unit is farther from the set point than the settling tolerance
    /// at the run's start or end, `NOT SETTLED` with the distance.
    pub fn note(&self, index: usize, duration_s: f64) -> Option<String> {
        let (start, role) = self.runs.get(index)?;
        Some(match role {
            Role::Ramp(what) => what.clone(),
            Role::Plateau { index, of, set_point_c } => {
                let off = [*start, start + duration_s]
                    .map(|t| (self.unit_c(t) - set_point_c).abs())
                    .into_iter()
                    .fold(0.0, f64::max);
                let mut s = format!("plateau {index}/{of}: set point {set_point_c} °C");
                if off > self.settled_within_c {
                    s.push_str(&format!(
                        "; NOT SETTLED: the unit is up to {off:.3} °C from the set point (tolerance {} °C)",
                        self.settled_within_c
                    ));
                }
                s
            }
        })
    }
}

/// How the temperature sensor reads the unit's temperature: white noise, then rounding to a
/// step.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TempReading {
    /// Standard deviation of the reading noise, °C.
    pub noise_c: f64,
    /// Quantisation step, °C (0: none).
    pub quantum_c: f64,
}

impl Default for TempReading {
    /// Noiseless, logged to 1 mK.
    fn default() -> Self {
        Self { noise_c: 0.0, quantum_c: 1e-3 }
    }
}

impl TempReading {
    /// Refuses a negative or non-finite noise or step.
    pub fn check(&self) -> Result<(), String> {
        if [self.noise_c, self.quantum_c].iter().all(|v| v.is_finite() && *v >= 0.0) {
            Ok(())
        } else {
            Err(format!(
                "temperature reading noise {} °C, step {} °C: expected finite, non-negative values",
                self.noise_c, self.quantum_c
            ))
        }
    }

    /// The readings of the true temperatures `true_c`; the noise of run `index` draws from its
    /// own stream of `seed` (a session without reading noise draws nothing).
    pub fn read(&self, true_c: &[f64], seed: u64, index: usize) -> Vec<f64> {
        let mut rng = ChaCha8Rng::seed_from_u64(seed ^ 0x7e3d_5a17 ^ ((index as u64) << 20));
        let noise = Normal::new(0.0, self.noise_c).ok().filter(|_| self.noise_c > 0.0);
        let steps = if self.quantum_c > 0.0 { 1.0 / self.quantum_c } else { 0.0 };
        true_c
            .iter()
            .map(|&t| {
                let v = t + noise.map_or(0.0, |d| d.sample(&mut rng));
                if steps > 0.0 {
                    (v * steps).round() / steps
                } else {
                    v
                }
            })
            .collect()
    }
}

impl SimConfig {
    /// The unit's true temperature at every stamp `t_s` of run `index` (which starts `elapsed_s`
    /// into a session of `total_s`): from the chamber program when there is one, else from
    /// the breakpoints of `temperature_c`; None when the session has no temperature.
    pub(super) fn true_temperatures_c(
        &self,
        index: usize,
        t_s: &[f64],
        elapsed_s: f64,
        total_s: f64,
    ) -> Option<Vec<f64>> {
        if let Some(ch) = &self.chamber {
            let start = ch.run_start_s(index)?;
            let t0 = t_s.first().copied().unwrap_or(0.0);
            return Some(t_s.iter().map(|&t| ch.unit_c(start + (t - t0))).collect());
        }
        let points = self.temperature_c.as_deref().filter(|p| !p.is_empty())?;
        Some(t_s.iter().map(|&t| super::piecewise(points, (elapsed_s + t) / total_s)).collect())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A step from 20 to 70 °C with τ = 100 s: the unit is at 70 − 50 e^(−t/τ); a ramp at
    /// 6 °C/min lags by r τ once settled into it.
    #[test]
    fn the_unit_follows_the_chamber_with_a_first_order_lag() {
        let mut s = ThermalSweep::new(vec![70.0], faces(1, 10.0));
        s.tau_s = 100.0;
        let (_, ch) = s.schedule();
        for t in [0.0, 1.0, 50.0, 100.0, 400.0] {
            let want = 70.0 - 50.0 * (-t / 100.0_f64).exp();
            assert!((ch.unit_c(t) - want).abs() < 1e-12, "{t}: {} vs {want}", ch.unit_c(t));
            assert!((ch.set_point_c(t) - 70.0).abs() < 1e-12);
        }
        s.ramp_c_per_min = Some(6.0);
        let (_, ch) = s.schedule();
        // 50 °C at 0.1 °C/s takes 500 s; at 450 s the unit lags by r τ (1 − e^(−4.5)).
        let want = 20.0 + 0.1 * 450.0 - 0.1 * 100.0 * (1.0 - (-4.5_f64).exp());
        assert!((ch.unit_c(450.0) - want).abs() < 1e-9, "{} vs {want}", ch.unit_c(450.0));
        assert!((ch.set_point_c(450.0) - 65.0).abs() < 1e-12);
        assert!((ch.set_point_c(900.0) - 70.0).abs() < 1e-12);
    }

    #[test]
    fn a_plateau_run_is_marked_when_the_unit_has_not_settled() {
        let mut s = ThermalSweep::new(vec![-20.0, 40.0], faces(2, 30.0));
        s.tau_s = 60.0;
        let (runs, ch) = s.schedule();
        let names: Vec<&str> = runs.iter().map(|r| r.name.as_str()).collect();
        assert_eq!(names, ["p1-face+z", "p1-face-z", "p2-face+z", "p2-face-z"]);
        let note = ch.note(0, 30.0).unwrap_or_default();
        assert!(note.contains("plateau 1/2: set point -20 °C; NOT SETTLED: the unit is up to 40.000"), "{note}");
        s.soak_s = 600.0;
        let (_, ch) = s.schedule();
        let note = ch.note(2, 30.0).unwrap_or_default();
        assert_eq!(note, "plateau 2/2: set point 40 °C");
        assert_eq!(ch.run_start_s(2), Some(1260.0));
    }

    #[test]
    fn readings_are_quantised() {
        let r = TempReading { noise_c: 0.0, quantum_c: 0.25 };
        assert_eq!(r.read(&[20.1, 20.2, -3.3], 1, 0), vec![20.0, 20.25, -3.25]);
    }
}
