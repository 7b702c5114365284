//! Synthetic protocol sessions with known truth: a Ferraris session (six faces, three
//! turns) and a hand-held multi-position session (initial rest, random poses joined by
//! smooth turns), both as one recording with runs selecting rows, in raw counts.
//!
//! Forward model (sensor frame): `u_a = b_a + K a + n_a`, `u_g = b_g + C ω + G a + n_g`;
//! the hand is idealised as a pure rotation (no linear acceleration), so `a = Rᵀ g_up`.

use crate::session::{Manifest, MotionSpec, Recording, Run, RunSpec, Session};
use crate::units::{AccelUnit, GyroUnit, TimeUnit, Units};
use nalgebra::{Matrix3, UnitQuaternion, Vector3};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};
use std::path::{Path, PathBuf};

/// The true parameters of a simulated unit (raw counts).
#[derive(Debug, Clone, PartialEq)]
pub struct ProtocolTruth {
    /// Accelerometer scale/coupling, counts per m/s² (row-major, `K[i][j]` = weight of a_j in u_i).
    pub k_accel: Matrix3<f64>,
    /// Accelerometer bias, counts.
    pub b_accel: Vector3<f64>,
    /// Gyro scale/coupling, counts per rad/s.
    pub c_gyro: Matrix3<f64>,
    /// Gyro bias, counts.
    pub b_gyro: Vector3<f64>,
    /// Gyro g-sensitivity, counts per m/s².
    pub g_gyro: Matrix3<f64>,
    /// Accelerometer quadratic nonlinearity `u_i += q_i a_i²`, counts per (m/s²)².
    pub q_accel: Vector3<f64>,
    /// White noise per sample: gyro, accelerometer (counts).
    pub noise: (f64, f64),
    /// Local gravity, m/s².
    pub g_m_s2: f64,
    /// Sample rate, Hz.
    pub rate_hz: f64,
}

impl ProtocolTruth {
    /// A plausible MEMS unit: 16-bit counts, ±4 g and ±500 °/s ranges, percent-level scale
    /// errors and couplings. With `upper_triangular_k`, K has zeros below the diagonal (the
    /// multi-position gauge, so that the truth is the fit's own parametrisation).
    pub fn mems(upper_triangular_k: bool) -> Self {
        let k = Matrix3::new(835.0, 4.2, -6.1, 3.3, 842.0, 2.7, -5.0, 1.9, 828.0);
        let k_accel = if upper_triangular_k { k.upper_triangle() } else { k };
        Self {
            k_accel,
            b_accel: Vector3::new(120.0, -85.0, 240.0),
            c_gyro: Matrix3::new(3760.0, 25.0, -31.0, -18.0, 3702.0, 40.0, 22.0, -36.0, 3731.0),
            b_gyro: Vector3::new(-14.0, 9.5, 3.2),
            g_gyro: Matrix3::new(0.05, -0.02, 0.01, 0.03, 0.04, -0.02, -0.01, 0.02, 0.06),
            q_accel: Vector3::zeros(),
            noise: (2.0, 3.0),
            g_m_s2: 9.80665,
            rate_hz: 100.0,
        }
    }
}

struct Builder<'a> {
    truth: &'a ProtocolTruth,
    rng: ChaCha8Rng,
    /// Outputs so far.
    gyro: Vec<[f64; 3]>,
    accel: Vec<[f64; 3]>,
    /// Stamps so far.
    t: Vec<f64>,
    q: UnitQuaternion<f64>,
}

impl Builder<'_> {
    /// The recording built so far, with its stamps.
    fn finish(self) -> Recording {
        Recording { t_s: self.t.into(), gyro: self.gyro.into(), accel: self.accel.into(), ..Default::default() }
    }

    fn sample(&mut self, w_body: Vector3<f64>) {
        let t = self.truth;
        let a = self.q.inverse_transform_vector(&Vector3::new(0.0, 0.0, t.g_m_s2));
        let gn = Normal::new(0.0, t.noise.0.max(0.0)).ok();
        let an = Normal::new(0.0, t.noise.1.max(0.0)).ok();
        let mut ua = t.k_accel * a + t.b_accel + t.q_accel.component_mul(&a.component_mul(&a));
        let mut ug = t.c_gyro * w_body + t.g_gyro * a + t.b_gyro;
        for i in 0..3 {
            ua[i] += an.map_or(0.0, |d| d.sample(&mut self.rng));
            ug[i] += gn.map_or(0.0, |d| d.sample(&mut self.rng));
        }
        self.gyro.push([ug[0], ug[1], ug[2]]);
        self.accel.push([ua[0], ua[1], ua[2]]);
        // One sample at a time while building: the stamps are rebuilt with the sample.
        let n = self.gyro.len();
        self.t.push((n - 1) as f64 / t.rate_hz);
    }

    /// Holds still for `s` seconds; returns the rows `[start, end)`.
    fn hold(&mut self, s: f64) -> (usize, usize) {
        let start = self.t.len();
        for _ in 0..(s * self.truth.rate_hz).round() as usize {
            self.sample(Vector3::zeros());
        }
        (start, self.t.len())
    }

    /// Turns by `angle` (rad) about a body axis in `s` seconds, rate profile 6τ(1−τ) (rest
    /// at both ends); the orientation is propagated exactly.
    fn turn(&mut self, axis_body: Vector3<f64>, angle: f64, s: f64) -> (usize, usize) {
        let start = self.t.len();
        let n = (s * self.truth.rate_hz).round() as usize;
        let q0 = self.q;
        let axis = axis_body.normalize();
        for k in 0..n {
            let tau = k as f64 / n as f64;
            let rate = angle / s * 6.0 * tau * (1.0 - tau);
            let turned = angle * tau * tau * (3.0 - 2.0 * tau);
            self.q = q0 * UnitQuaternion::from_scaled_axis(axis * turned);
            self.sample(axis * rate);
        }
        self.q = q0 * UnitQuaternion::from_scaled_axis(axis * angle);
        (start, self.t.len())
    }
}

/// A simulated protocol session: the manifest (runs select rows of `recording.csv`) and the
/// whole recording.
#[derive(Debug, Clone, PartialEq)]
pub struct ProtocolSession {
    /// The manifest.
    pub manifest: Manifest,
    /// The whole recording (all runs' rows).
    pub recording: Recording,
}

impl ProtocolSession {
    /// The session in memory, as [`Session::load`] would build it from disk.
    pub fn session(&self) -> Session {
        let runs = self
            .manifest
            .runs
            .iter()
            .map(|spec| {
                let rec = match spec.rows {
                    Some((s, e)) => self.recording.slice(s, e),
                    None => self.recording.clone(),
                };
                Run { spec: spec.clone(), path: PathBuf::from(&spec.file), rec }
            })
            .collect();
        Session { manifest_path: PathBuf::from("session.json"), manifest: self.manifest.clone(), runs }
    }

    /// Writes `session.json` and `recording.csv` into `dir` (refusing to overwrite).
    pub fn write(&self, dir: &Path) -> std::io::Result<PathBuf> {
        std::fs::create_dir_all(dir)?;
        let r = &self.recording;
        let text = crate::session::recording_csv(&r.t_s, &r.gyro, &r.accel, None, [1.0, 1.0]);
        crate::atomic::write_new(&dir.join("recording.csv"), &text)?;
        let path = dir.join("session.json");
        crate::atomic::write_new(&path, self.manifest.to_json().as_bytes())?;
        Ok(path)
    }
}

fn spec(name: &str, motion: MotionSpec, rows: Option<(usize, usize)>) -> RunSpec {
    RunSpec::new(name, "recording.csv", motion, rows)
}

fn raw_units() -> Units {
    Units { gyro: GyroUnit::Raw, accel: AccelUnit::Raw, time: TimeUnit::S }
}

/// Ferraris session: faces x_p, x_a, y_p, y_a, z_p, z_a (`hold_s` each), then one turn of
/// `turn_deg` about each axis (2 s, with 1 s of rest before and after inside the run).
pub fn ferraris(truth: &ProtocolTruth, hold_s: f64, turn_deg: f64, seed: u64) -> ProtocolSession {
    let mut b = Builder {
        truth,
        rng: ChaCha8Rng::seed_from_u64(seed),
        gyro: Vec::new(),
        accel: Vec::new(),
        t: Vec::new(),
        q: UnitQuaternion::identity(),
    };
    // Orientation with body axis e up: rotate body e onto world z.
    let faces: [(&str, Vector3<f64>); 6] = [
        ("x_p", Vector3::x()),
        ("x_a", -Vector3::x()),
        ("y_p", Vector3::y()),
        ("y_a", -Vector3::y()),
        ("z_p", Vector3::z()),
        ("z_a", -Vector3::z()),
    ];
    let mut runs = Vec::new();
    for (name, up) in faces {
        b.q = UnitQuaternion::rotation_between(&up, &Vector3::z())
            .unwrap_or_else(|| UnitQuaternion::from_scaled_axis(Vector3::x() * std::f64::consts::PI));
        b.hold(0.5); // settling, not part of the run
        let rows = b.hold(hold_s);
        runs.push(spec(
            name,
            MotionSpec::Static { up_stand: [up[0], up[1], up[2]], earth_rate_rad_s: [0.0; 3] },
            Some(rows),
        ));
    }
    for (i, name) in ["x_rot", "y_rot", "z_rot"].iter().enumerate() {
        b.q = UnitQuaternion::rotation_between(&Vector3::new(1.0, 1.0, 1.0), &Vector3::z()).unwrap_or_default();
        let mut axis = [0.0; 3];
        axis[i] = 1.0;
        let (start, _) = b.hold(1.0);
        b.turn(Vector3::from(axis), turn_deg.to_radians(), 2.0);
        let (_, end) = b.hold(1.0);
        runs.push(spec(name, MotionSpec::Rotation { axis_stand: axis, angle_deg: turn_deg }, Some((start, end))));
    }
    let manifest = Manifest {
        serial: "SIM-FERRARIS".into(),
        units: raw_units(),
        g_m_s2: truth.g_m_s2,
        runs,
        version: 2,
        source: None,
    };
    ProtocolSession { manifest, recording: b.finish() }
}

/// Hand-held multi-position session: `init_rest_s` of rest, then `poses` random
/// orientations held `hold_s` each, joined by 1.5 s turns.
pub fn multi_position(
    truth: &ProtocolTruth,
    init_rest_s: f64,
    poses: usize,
    hold_s: f64,
    seed: u64,
) -> ProtocolSession {
    let mut b = Builder {
        truth,
        rng: ChaCha8Rng::seed_from_u64(seed),
        gyro: Vec::new(),
        accel: Vec::new(),
        t: Vec::new(),
        q: UnitQuaternion::identity(),
    };
    b.hold(init_rest_s);
    for _ in 0..poses {
        // A random turn of 40–120° about a random axis.
        let axis =
            Vector3::new(b.rng.random_range(-1.0..1.0), b.rng.random_range(-1.0..1.0), b.rng.random_range(-1.0..1.0));
        let angle = b.rng.random_range(40f64..120.0).to_radians();
        b.turn(if axis.norm() > 1e-3 { axis } else { Vector3::x() }, angle, 1.5);
        b.hold(hold_s);
    }
    let motion = MotionSpec::MultiPosition {
        init_rest_s,
        window: 51,
        threshold_multiplier: None,
        min_pose_samples: 100,
        poses: None,
    };
    let manifest = Manifest {
        serial: "SIM-MULTIPOS".into(),
        units: raw_units(),
        g_m_s2: truth.g_m_s2,
        runs: vec![spec("multi-position", motion, None)],
        version: 2,
        source: None,
    };
    ProtocolSession { manifest, recording: b.finish() }
}
