//! Synthetic stand sessions with known truth: the paper's unit (spec values) on a
//! multi-run conic session, with optional noise, biases and extra effects.
//!
//! The simulator evaluates the same effect regressors as the fit (model forward,
//! `u = f(true)`), so any catalogue effect can be hidden in the data by giving it a value.

pub mod noise;
pub mod protocol;
pub mod realism;
pub mod stand;
pub mod thermal;

use crate::atomic::write_new;
use crate::frames::Mount;
use crate::model::{forward, Model, State};
use crate::motion::{track_for, DerivativeConfig};
use crate::session::{Manifest, MotionSpec, Recording, Run, RunSpec, Session};
use crate::units::SensorKind;
use crate::units::{AccelUnit, GyroUnit, TimeUnit, Units};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// The true unit: a model and the value of each of its coefficients (by name).
#[derive(Debug, Clone)]
pub struct UnitTruth {
    /// Forward model used to generate outputs.
    pub model: Model,
    /// Coefficient values by name (SI); missing coefficients take their nominal value.
    pub values: BTreeMap<String, f64>,
}

impl UnitTruth {
    /// The paper's unit (spec, eqs. 3–4): diagonal 1; c_xy = c_yz = c_zx = 0.01;
    /// e_xz = e_yx = e_zy = 0.001 s; K off-diagonal 0.01; no bias.
    pub fn paper() -> Self {
        let mut values = BTreeMap::new();
        for n in ["gyro.c_xy", "gyro.c_yz", "gyro.c_zx"] {
            values.insert(n.to_string(), 0.01);
        }
        for n in ["gyro.e_xz", "gyro.e_yx", "gyro.e_zy"] {
            values.insert(n.to_string(), 0.001);
        }
        for i in 0..3 {
            for j in 0..3 {
                if i != j {
                    values.insert(crate::model::matrix_name(SensorKind::Accel, "k", i, j), 0.01);
                }
            }
        }
        Self { model: Model::default_model(), values }
    }

    /// True value of a coefficient or nonlinear parameter by name (its nominal value when
    /// not set), or None when the truth model has no such coefficient.
    pub fn value(&self, name: &str) -> Option<f64> {
        let nominal = SensorKind::BOTH
            .iter()
            .flat_map(|s| self.model.terms(*s))
            .find(|t| t.term.name == name)
            .map(|t| t.term.nominal)
            .or_else(|| {
                self.model
                    .nonlinear()
                    .iter()
                    .flat_map(|e| e.effect.params())
                    .find(|d| d.name == name)
                    .map(|d| d.nominal)
            })?;
        Some(self.values.get(name).copied().unwrap_or(nominal))
    }

    /// The true values of each nonlinear entry's parameters (nominal when not set).
    pub fn nonlinear_values(&self) -> Vec<Vec<f64>> {
        self.model
            .nonlinear()
            .iter()
            .map(|e| e.effect.params().iter().map(|d| self.values.get(&d.name).copied().unwrap_or(d.nominal)).collect())
            .collect()
    }

    /// Value of every term of a sensor, in model order.
    pub fn term_values(&self, sensor: SensorKind) -> Vec<f64> {
        self.model
            .terms(sensor)
            .iter()
            .map(|t| self.values.get(&t.term.name).copied().unwrap_or(t.term.nominal))
            .collect()
    }
}

/// One run to simulate.
#[derive(Debug, Clone, PartialEq)]
pub struct RunPlan {
    /// Run name (also the CSV's stem).
    pub name: String,
    /// Motion (conic or static).
    pub motion: MotionSpec,
    /// Mount.
    pub mount: Mount,
    /// Duration, s.
    pub duration_s: f64,
}

/// Samples a simulation may hold in memory (about 8 GB of session and tracks).
pub const MAX_SAMPLES: f64 = 1e8;

/// Refuses runs that cannot be simulated: a duration or sample rate that is not positive
/// and finite, a motion outside the manifest's limits, or more than [`MAX_SAMPLES`] samples
/// in all (the message says how many and the limit).
pub fn check_runs(runs: &[RunPlan], sample_rate_hz: f64) -> Result<(), String> {
    if !(sample_rate_hz.is_finite() && sample_rate_hz > 0.0 && sample_rate_hz <= 1e5) {
        return Err(format!("the sample rate is {sample_rate_hz} Hz: expected more than 0 and at most 100000 Hz"));
    }
    let mut total = 0.0;
    for r in runs {
        if !(r.duration_s.is_finite() && r.duration_s > 0.0) {
            return Err(format!(
                "run '{}': duration {} s: expected a positive number of seconds",
                r.name, r.duration_s
            ));
        }
        if let MotionSpec::Conic { cone_angle_deg, rate_deg_s, .. } = r.motion {
            let lim = crate::session::LIMITS.rate_deg_s;
            if !(-lim..=lim).contains(&rate_deg_s) || !(0.0..=90.0).contains(&cone_angle_deg) {
                return Err(format!(
                    "run '{}': rate {rate_deg_s} deg/s, cone angle {cone_angle_deg} deg: expected |rate| <= {lim} deg/s and a cone angle of 0 to 90 deg",
                    r.name
                ));
            }
        }
        total += r.duration_s * sample_rate_hz;
    }
    if total > MAX_SAMPLES {
        return Err(format!(
            "{} runs at {sample_rate_hz} Hz make {total:.3e} samples: at most {MAX_SAMPLES:e} are simulated (shorten --duration or lower --rate-hz)",
            runs.len()
        ));
    }
    Ok(())
}

/// A simulation.
#[derive(Debug, Clone)]
pub struct SimConfig {
    /// Serial number written to the manifest.
    pub serial: String,
    /// The true unit.
    pub truth: UnitTruth,
    /// Runs.
    pub runs: Vec<RunPlan>,
    /// Sample rate, Hz.
    pub sample_rate_hz: f64,
    /// Gyro white noise standard deviation per sample, deg/s.
    pub gyro_noise_deg_s: f64,
    /// Accelerometer white noise standard deviation per sample, g.
    pub accel_noise_g: f64,
    /// Local gravity, m/s².
    pub g_m_s2: f64,
    /// Random seed.
    pub seed: u64,
    /// Temperature over the whole session, °C: breakpoints evenly spaced in time from its
    /// start to its end, linear between them (`[start, end]` is a ramp; `[10, 40, 10]` warms
    /// then cools; `[t, t]` a plateau); when set, every run gets a `temp` column.
    pub temperature_c: Option<Vec<f64>>,
    /// A chamber program (a thermal sweep, [`thermal::ThermalSweep::apply`]): each run's
    /// temperature from the unit's lag behind the chamber; takes precedence over
    /// `temperature_c`.
    pub chamber: Option<thermal::Chamber>,
    /// How the `temp` column reads the unit's true temperature (noise, step); the sensor
    /// outputs follow the true temperature.
    pub temp_reading: thermal::TempReading,
    /// Coloured noise added to each gyro axis (rad/s), on top of the white per-sample noise.
    pub gyro_process: noise::NoiseProcess,
    /// Coloured noise added to each accelerometer axis (m/s²).
    pub accel_process: noise::NoiseProcess,
    /// Session clock, jitter, quantisation, units and disturbances outside the catalogue.
    pub realism: realism::Realism,
    /// How the stand really moved, unknown to the manifest written (a perfect stand by default).
    pub stand: stand::StandErrors,
    /// The coloured noise (flicker, random walk, Gauss–Markov) runs on over the session
    /// clock from run to run, as a real unit's bias wanders between runs (one generator for
    /// the session, flicker time constants up to the session's length, advanced over the
    /// pauses between runs); false: each run draws its own stationary stretch.
    pub carry_noise: bool,
}

/// The cyclic mounts used for re-mounted runs: nominal, then x→y→z→x twice.
pub fn cyclic_mounts(count: usize) -> Vec<Mount> {
    let all = [["+x", "+y", "+z"], ["+y", "+z", "+x"], ["+z", "+x", "+y"]];
    all.iter().take(count.clamp(1, 3)).filter_map(|m| Mount::parse(m).ok()).collect()
}

/// Conic runs for every combination of mount, cone angle and rate; the first mount's runs
/// are named `cone+10`, others are prefixed by the mount (`yzx-cone+10`), and cone angles
/// after the first get a suffix (`cone+10-a20`).
pub fn conic_plan(rates_deg_s: &[f64], cone_angles_deg: &[f64], mounts: &[Mount], duration_s: f64) -> Vec<RunPlan> {
    let mut runs = Vec::new();
    for (mi, m) in mounts.iter().enumerate() {
        let prefix = if mi == 0 {
            String::new()
        } else {
            let letters: String = m.names().iter().map(|n| n.trim_start_matches(['+', '-'])).collect();
            format!("{letters}-")
        };
        for (ai, &alpha) in cone_angles_deg.iter().enumerate() {
            let suffix = if ai == 0 { String::new() } else { format!("-a{alpha}") };
            for &rate in rates_deg_s {
                runs.push(RunPlan {
                    name: format!("{prefix}cone{rate:+}{suffix}"),
                    motion: MotionSpec::Conic { cone_angle_deg: alpha, rate_deg_s: rate, phase_deg: 0.0 },
                    mount: m.clone(),
                    duration_s,
                });
            }
        }
    }
    runs
}

impl SimConfig {
    /// The paper's unit on the default calibration session: rates +10, −10, +20 °/s, cone
    /// angles 10° and 20°, three cyclic mounts, 36 s each at 100 Hz, noiseless.
    pub fn paper() -> Self {
        Self {
            serial: "I1426-0042".into(),
            truth: UnitTruth::paper(),
            runs: conic_plan(&[10.0, -10.0, 20.0], &[10.0, 20.0], &cyclic_mounts(3), 36.0),
            sample_rate_hz: 100.0,
            gyro_noise_deg_s: 0.0,
            accel_noise_g: 0.0,
            g_m_s2: 9.80665,
            seed: 1,
            temperature_c: None,
            chamber: None,
            temp_reading: Default::default(),
            gyro_process: Default::default(),
            accel_process: Default::default(),
            realism: Default::default(),
            stand: Default::default(),
            carry_noise: false,
        }
    }

    /// The paper's unit at rest (up = +z) for one static run named `static` of
    /// `duration_s`: the recording an engineer characterises noise on.
    pub fn static_recording(duration_s: f64, sample_rate_hz: f64) -> Self {
        let still = MotionSpec::Static { up_stand: [0.0, 0.0, 1.0], earth_rate_rad_s: [0.0; 3] };
        let mount = cyclic_mounts(1).remove(0);
        Self {
            runs: vec![RunPlan { name: "static".into(), motion: still, mount, duration_s }],
            sample_rate_hz,
            ..Self::paper()
        }
    }

    /// Generates the session in memory, exactly as it would read back from disk (outputs
    /// are generated in deg/s and g, then converted like the reader does).
    pub fn generate(&self) -> Session {
        let units = if self.realism.si_units {
            Units { gyro: GyroUnit::RadPerS, accel: AccelUnit::MPerS2, time: TimeUnit::S }
        } else {
            Units { gyro: GyroUnit::DegPerS, accel: AccelUnit::G, time: TimeUnit::S }
        };
        let mut jrng = ChaCha8Rng::seed_from_u64(self.seed ^ 0x0717_7e12);
        let mut clock_s = 0.0;
        let mut conic_index = 0usize;
        let mut rng = ChaCha8Rng::seed_from_u64(self.seed);
        let gn = Normal::new(0.0, self.gyro_noise_deg_s.max(0.0)).ok();
        let an = Normal::new(0.0, self.accel_noise_g.max(0.0)).ok();
        let deriv = DerivativeConfig::default();
        // User effects whose linear part has parameters: at the true parameter values.
        let truth_model = self.truth.model.at_nonlinear_values(&self.truth.nonlinear_values());
        let gterms = truth_model.terms(SensorKind::Gyro);
        let aterms = truth_model.terms(SensorKind::Accel);
        let gvals = self.truth.term_values(SensorKind::Gyro);
        let avals = self.truth.term_values(SensorKind::Accel);
        let to_deg = 180.0 / std::f64::consts::PI;
        let kg = units.gyro.to_rad_s();
        let ka = units.accel.to_m_s2(self.g_m_s2);
        let mut runs = Vec::with_capacity(self.runs.len());
        let total: f64 = self.runs.iter().map(|r| r.duration_s).sum::<f64>().max(f64::MIN_POSITIVE);
        let mut elapsed = 0.0;
        // Slow noise carried over the session: one generator per channel for every run.
        let gap_s = self.realism.session_clock_gap_s.unwrap_or(0.0);
        let session_s = total + gap_s * self.runs.len().saturating_sub(1) as f64;
        let dt = 1.0 / self.sample_rate_hz;
        let mut carried: Vec<noise::NoiseGenerator> = (0..6)
            .map(|c| if c < 3 { &self.gyro_process } else { &self.accel_process })
            .map(|p| p.generator(dt, session_s))
            .collect();
        let mut crng = ChaCha8Rng::seed_from_u64(self.seed ^ 0x05ee_dca7_71ed);
        for (run_index, plan) in self.runs.iter().enumerate() {
            let n = (plan.duration_s * self.sample_rate_hz).round().max(1.0) as usize;
            let t0 = if self.realism.session_clock_gap_s.is_some() { clock_s } else { 0.0 };
            let t_s: Vec<f64> = (0..n).map(|k| t0 + k as f64 / self.sample_rate_hz).collect();
            let mut rec = Recording { t_s: t_s.into(), ..Default::default() };
            let tr = self.true_track(plan, &rec, conic_index, &deriv);
            // Nonlinear effects change the motion as each sensor sees it.
            let (tg, ta) = (self.seen(&tr, SensorKind::Gyro), self.seen(&tr, SensorKind::Accel));
            // Coloured noise draws from its own stream, so sessions without it are unchanged.
            let mut prng = ChaCha8Rng::seed_from_u64(self.seed ^ 0x5eed_c0105 ^ runs.len() as u64);
            let mut own: Vec<noise::NoiseGenerator> = (0..6)
                .map(|c| if c < 3 { &self.gyro_process } else { &self.accel_process })
                .map(|p| p.generator(dt, plan.duration_s))
                .collect();
            if self.carry_noise && !runs.is_empty() {
                for g in &mut carried {
                    g.pause(gap_s, dt, &mut crng);
                }
            }
            let (gens, prng) = if self.carry_noise { (&mut carried, &mut crng) } else { (&mut own, &mut prng) };
            let coloured = !(self.gyro_process.is_zero() && self.accel_process.is_zero());
            let (mut gyro, mut accel) = (Vec::with_capacity(n), Vec::with_capacity(n));
            // The outputs follow the unit's true temperature; the temp column is its reading.
            let true_c = self.true_temperatures_c(runs.len(), &rec.t_s, elapsed, total);
            rec.temp_c = true_c.as_deref().map(|t| self.temp_reading.read(t, self.seed, runs.len()));
            // The thermal branch: the smoothed rate of the true temperature (what the fit reads
            // off the logged column, without the reading's noise).
            let rates = true_c.as_ref().map(|t| crate::stats::temp_rate::centred(&rec.t_s, t));
            for k in 0..n {
                let temp_at = |v: &Option<Vec<f64>>| v.as_ref().map_or(f64::NAN, |t| t[k]);
                let state = |tr: &crate::motion::Track| state_at(tr, k, temp_at(&true_c), temp_at(&rates));
                let ug = forward(&gterms, &gvals, &state(&tg));
                let ua = forward(&aterms, &avals, &state(&ta));
                let mut g = [0.0; 3];
                let mut a = [0.0; 3];
                for i in 0..3 {
                    let ng = gn.map_or(0.0, |d| d.sample(&mut rng));
                    let na = an.map_or(0.0, |d| d.sample(&mut rng));
                    g[i] = (ug[i] * to_deg + ng) * kg;
                    a[i] = (ua[i] / self.g_m_s2 + na) * ka;
                }
                let theta = crate::motion::cone_phase(&plan.motion).map(|p| p.theta(rec.t_s[k]));
                self.realism.disturb(rec.t_s[k], theta, (conic_index, run_index), &mut g, &mut a);
                if coloured {
                    for i in 0..3 {
                        g[i] += gens[i].next_sample(prng);
                        a[i] += gens[3 + i].next_sample(prng);
                    }
                }
                gyro.push(g);
                accel.push(a);
            }
            (rec.gyro, rec.accel) = (gyro.into(), accel.into());
            self.realism.finish(
                &mut rec,
                [1.0 / units.gyro.to_rad_s(), 1.0 / units.accel.to_m_s2(self.g_m_s2)],
                &mut jrng,
            );
            rec.angle_rad = self.logged_angle(plan, conic_index, &rec.t_s);
            conic_index += usize::from(matches!(plan.motion, MotionSpec::Conic { .. }));
            clock_s = t0 + n as f64 / self.sample_rate_hz + self.realism.session_clock_gap_s.unwrap_or(0.0);
            elapsed += plan.duration_s;
            runs.push(Run {
                spec: RunSpec {
                    mount: plan.mount.clone(),
                    note: self.chamber.as_ref().and_then(|c| c.note(runs.len(), plan.duration_s)),
                    angle_column: rec.angle_rad.as_ref().map(|_| ANGLE_COLUMN.to_string()),
                    ..RunSpec::new(plan.name.clone(), format!("{}.csv", plan.name), plan.motion.clone(), None)
                },
                path: PathBuf::from(format!("{}.csv", plan.name)),
                rec,
            });
        }
        Session {
            manifest_path: PathBuf::from("session.json"),
            manifest: Manifest {
                serial: self.serial.clone(),
                units,
                g_m_s2: self.g_m_s2,
                runs: runs.iter().map(|r| r.spec.clone()).collect(),
                version: 1,
                source: None,
            },
            runs,
        }
    }
}

impl SimConfig {
    /// The motion as `sensor` sees it: the unit's nonlinear effects (at their true
    /// parameters) applied to the true motion `tr`.
    fn seen(&self, tr: &crate::motion::Track, sensor: SensorKind) -> crate::motion::Track {
        let mut t = tr.clone();
        for e in self.truth.model.nonlinear() {
            if e.effect.sensor().is_none_or(|s| s == sensor) {
                let p: Vec<f64> = e
                    .effect
                    .params()
                    .iter()
                    .map(|d| self.truth.values.get(&d.name).copied().unwrap_or(d.nominal))
                    .collect();
                t = e.effect.transform(&p, &t);
            }
        }
        t
    }

    /// A stand that logs its angle ([`stand::StandErrors::encoder_deg`]): the encoder's
    /// reading of conic run `plan`'s true angle at each stamp, rad (None otherwise).
    fn logged_angle(&self, plan: &RunPlan, conic_index: usize, t_s: &[f64]) -> Option<Vec<f64>> {
        let t0 = t_s.first().copied().unwrap_or(0.0);
        let m = self.stand.encoder_deg.and(self.stand.conic_motion(&plan.motion, conic_index, t0))?;
        Some(
            t_s.iter()
                .map(|&t| self.stand.logged_deg(self.stand.angle_at(&m, t, t0).theta).unwrap_or(f64::NAN).to_radians())
                .collect(),
        )
    }

    /// The true motion of a run: the stand's real motion and mount (the manifest keeps the
    /// declared ones).
    fn true_track(
        &self,
        plan: &RunPlan,
        rec: &Recording,
        conic_index: usize,
        deriv: &DerivativeConfig,
    ) -> crate::motion::Track {
        let mount = self.stand.mount_of(&plan.name, &plan.mount).clone();
        let truth = self.stand.static_motion(&plan.motion);
        let tr = track_for(&truth, &mount, rec, self.g_m_s2, deriv);
        let t0 = rec.t_s.first().copied().unwrap_or(0.0);
        match self.stand.conic_motion(&plan.motion, conic_index, t0).filter(|_| !self.stand.is_zero()) {
            Some(m) if self.stand.spin_up_s > 0.0 => {
                // The stand's angle law is not one a stand motion holds: its states per sample.
                let fixed = m.fixed(self.g_m_s2);
                let states: Vec<crate::motion::Kinematics> =
                    rec.t_s.iter().map(|&t| fixed.at_angle(self.stand.angle_at(&m, t, t0))).collect();
                tr.on_logged(&states, &mount, "exact (stand spinning up)".into())
            }
            Some(m) => tr.on_stand(m, self.g_m_s2, mount),
            None => tr,
        }
    }
}

/// The column a simulated stand that logs its angle writes it to, degrees.
pub const ANGLE_COLUMN: &str = "theta_deg";

/// Errors writing a simulated session.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum SimulateError {
    /// File system error.
    #[error("{path}: {source}")]
    Io {
        /// File or folder.
        path: PathBuf,
        /// Cause.
        source: std::io::Error,
    },
    /// The output folder already holds a session.
    #[error("{0}: already exists; choose another output folder or remove it (crosscal never overwrites data)")]
    Exists(PathBuf),
    /// A run's file name would be written outside the session's folder.
    #[error("run '{run}': file '{file}' is not a plain file name (no folder, '..' or absolute path): a saved session's files stay in its folder")]
    FileOutside {
        /// Run name.
        run: String,
        /// Its file as named.
        file: String,
    },
}

/// Writes a session (deg/s, g, s) as `session.json` plus one CSV per run into `dir`.
/// Refuses to overwrite an existing manifest or recording. Returns the manifest path.
pub fn write_session(session: &Session, dir: &Path) -> Result<PathBuf, SimulateError> {
    let io = |path: &Path| {
        let path = path.to_path_buf();
        move |source| SimulateError::Io { path, source }
    };
    for r in &session.runs {
        let mut parts = Path::new(&r.spec.file).components();
        let plain = matches!((parts.next(), parts.next()), (Some(std::path::Component::Normal(_)), None))
            && !r.spec.file.contains(['/', '\\']);
        if !plain {
            return Err(SimulateError::FileOutside { run: r.spec.name.clone(), file: r.spec.file.clone() });
        }
    }
    std::fs::create_dir_all(dir).map_err(io(dir))?;
    let manifest_path = dir.join("session.json");
    let mut targets = vec![manifest_path.clone()];
    targets.extend(session.runs.iter().map(|r| dir.join(&r.spec.file)));
    if let Some(existing) = targets.iter().find(|p| p.exists()) {
        return Err(SimulateError::Exists(existing.clone()));
    }
    let kg = 1.0 / session.manifest.units.gyro.to_rad_s();
    let ka = 1.0 / session.manifest.units.accel.to_m_s2(session.manifest.g_m_s2);
    for run in &session.runs {
        let path = dir.join(&run.spec.file);
        let r = &run.rec;
        let angle_deg: Option<Vec<f64>> = r.angle_rad.as_ref().map(|a| a.iter().map(|x| x.to_degrees()).collect());
        let column = run.spec.angle_column.as_deref().unwrap_or(ANGLE_COLUMN);
        let extra = angle_deg.as_deref().map(|a| (column, a));
        let text = crate::session::recording_csv_with(&r.t_s, &r.gyro, &r.accel, r.temp_c.as_deref(), [kg, ka], extra);
        write_new(&path, &text).map_err(io(&path))?;
    }
    let text = session.manifest.to_json();
    write_new(&manifest_path, text.as_bytes()).map_err(io(&manifest_path))?;
    Ok(manifest_path)
}

/// The true state at sample `k` of a track, the time as stamped (the simulator's clock).
fn state_at(tr: &crate::motion::Track, k: usize, temp_c: f64, temp_rate_c_s: f64) -> State {
    let x = tr.at(k);
    State { t_session_s: tr.t_s[k], w: x.w_rad_s.xyz, e: x.e_rad_s2.xyz, a: x.a_m_s2.xyz, temp_c, temp_rate_c_s }
}

/// The piecewise-linear value at `pos` (0 … 1 over the whole) of breakpoints evenly spaced
/// from 0 to 1 (one breakpoint: a constant).
fn piecewise(points: &[f64], pos: f64) -> f64 {
    let m = points.len().saturating_sub(1);
    if m == 0 {
        return points.first().copied().unwrap_or(f64::NAN);
    }
    let x = pos.clamp(0.0, 1.0) * m as f64;
    let i = (x.floor() as usize).min(m - 1);
    points[i] + (points[i + 1] - points[i]) * (x - i as f64)
}
