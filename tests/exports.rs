//! Exports to OpenVINS: each file parsed back and checked against the
//! profile, against the simulated truth and against the target's documented equations.

use crate::common::fit_session;
use crosscal::correct::Calibration;
use crosscal::estimate::FitOptions;
use crosscal::model::Model;
use crosscal::profile::openvins::{to_openvins, OpenVinsModel};
use crosscal::profile::Profile;
use crosscal::simulate::{SimConfig, UnitTruth};
use nalgebra::{Matrix3, Vector3};

type M3 = [[f64; 3]; 3];
const AXES: [char; 3] = ['x', 'y', 'z'];

/// A noisy paper session of a unit whose model is `effects` with `values`, fitted with the
/// same effects and `held` coefficients fixed at their values.
fn fitted(effects: &[&str], values: &[(String, f64)], held: &[(String, f64)]) -> Profile {
    let ids: Vec<String> = effects.iter().map(|e| e.to_string()).collect();
    let mut cfg = SimConfig::paper();
    cfg.truth = UnitTruth { model: Model::named("truth", &ids).unwrap(), values: values.iter().cloned().collect() };
    cfg.gyro_noise_deg_s = 0.002;
    cfg.accel_noise_g = 2e-5;
    let session = cfg.generate();
    let mut model = Model::named("export-test", &ids).unwrap();
    for (name, v) in held {
        model.fix(name, *v).unwrap();
    }
    let fit = fit_session(&session, &model, &FitOptions::default()).unwrap();
    Profile::from_fit(&session, &model, fit, vec![])
}

fn name(sensor: &str, letter: &str, i: usize, j: Option<usize>) -> String {
    match j {
        Some(j) => format!("{sensor}.{letter}_{}{}", AXES[i], AXES[j]),
        None => format!("{sensor}.{letter}_{}", AXES[i]),
    }
}

fn mat_values(sensor: &str, letter: &str, m: M3) -> Vec<(String, f64)> {
    (0..9).map(|k| (name(sensor, letter, k / 3, Some(k % 3)), m[k / 3][k % 3])).collect()
}

fn profile_matrix(p: &Profile, sensor: &str, letter: &str) -> Matrix3<f64> {
    let sf = if sensor == "gyro" { &p.gyro } else { &p.accel };
    Matrix3::from_fn(|i, j| sf.value(&name(sensor, letter, i, Some(j))).unwrap())
}

fn profile_bias(p: &Profile, sensor: &str) -> Vector3<f64> {
    let sf = if sensor == "gyro" { &p.gyro } else { &p.accel };
    Vector3::from_fn(|i, _| sf.value(&name(sensor, "b", i, None)).unwrap())
}

/// True inputs spread over a unit's range: rates to ±3 rad/s, specific forces to ±20 m/s².
fn inputs(n: usize) -> Vec<([f64; 3], [f64; 3])> {
    let mut state = 0x9e37_79b9_7f4a_7c15u64;
    let mut next = move || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        (state >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0
    };
    (0..n)
        .map(|_| ([3.0 * next(), 3.0 * next(), 3.0 * next()], [20.0 * next(), 20.0 * next(), 20.0 * next()]))
        .collect()
}

fn yaml_matrix(text: &str, key: &str) -> Matrix3<f64> {
    let lines: Vec<&str> = text.lines().collect();
    let at = lines.iter().position(|l| l.trim() == format!("{key}:")).unwrap_or_else(|| panic!("{key}:\n{text}"));
    let rows: Vec<Vec<f64>> = (1..=3)
        .map(|r| {
            let row = lines[at + r].trim().strip_prefix("- [").and_then(|x| x.strip_suffix(']')).unwrap();
            row.split(',').map(|x| x.trim().parse().unwrap()).collect()
        })
        .collect();
    Matrix3::from_fn(|i, j| rows[i][j])
}

fn yaml_scalar<'a>(text: &'a str, key: &str) -> &'a str {
    let line = text.lines().find(|l| l.trim_start().starts_with(&format!("{key}:"))).unwrap();
    line.split_once(':').unwrap().1.split('#').next().unwrap().trim()
}

/// OpenVINS: for a unit with full, non-triangular C_ω and K and a g-sensitivity, `Tw`/`Ta` are
/// triangular as each model requires (kalibr lower, rpng upper; exact zeros), the rotations
/// proper, `Tw·R_IMUtoGYRO` and `Ta·R_IMUtoACC` the profile's C_ω and K to 1e-15 and `Tg` its G
/// bit for bit; OpenVINS's own correction (`a = R_ACCtoIMU·Da·(a_m − b_a)`, `ω = R_GYROtoIMU·
/// Dw·(ω_m − b_g − Tg·a)`, D the kept triangle of T⁻¹) recovers the true inputs to 1e-12 and
/// agrees with crosscal's; the biases are listed with their values.
#[test]
fn openvins_intrinsics_rebuild_the_profiles_forward_model() {
    let c: M3 = [[1.01, 0.012, -0.008], [-0.015, 0.992, 0.011], [0.007, -0.013, 1.004]];
    let k: M3 = [[0.995, 0.009, -0.011], [0.014, 1.012, -0.006], [-0.01, 0.008, 0.988]];
    let g: M3 = [[4e-4, -2e-4, 1e-4], [3e-4, 5e-4, -2e-4], [-1e-4, 2e-4, 6e-4]];
    let mut values = [mat_values("gyro", "c", c), mat_values("accel", "k", k), mat_values("gyro", "g", g)].concat();
    for i in 0..3 {
        values.push((name("gyro", "b", i, None), [0.01, -0.02, 0.005][i]));
        values.push((name("accel", "b", i, None), [0.15, -0.08, 0.2][i]));
    }
    let effects = ["gyro-bias", "gyro-scale-coupling", "accel-bias", "accel-scale-coupling", "gyro-g-sensitivity"];
    let p = fitted(&effects, &values, &[]);
    let (pc, pk, pg) =
        (profile_matrix(&p, "gyro", "c"), profile_matrix(&p, "accel", "k"), profile_matrix(&p, "gyro", "g"));
    let (pbg, pba) = (profile_bias(&p, "gyro"), profile_bias(&p, "accel"));
    for i in 0..3 {
        for j in 0..3 {
            assert!((pc[(i, j)] - c[i][j]).abs() < 1e-4, "C[{i}][{j}] {} vs truth {}", pc[(i, j)], c[i][j]);
            assert!((pk[(i, j)] - k[i][j]).abs() < 1e-4, "K[{i}][{j}] {} vs truth {}", pk[(i, j)], k[i][j]);
            assert!((pg[(i, j)] - g[i][j]).abs() < 2e-5, "G[{i}][{j}] {} vs truth {}", pg[(i, j)], g[i][j]);
        }
    }
    let cal = Calibration::from_profile(&p).unwrap();
    for model in [OpenVinsModel::Kalibr, OpenVinsModel::Rpng] {
        let (y, lost) = to_openvins(&p, model, 200.0);
        assert!(y.starts_with("%YAML:1.0\n"), "OpenCV's FileStorage needs its header first");
        assert_eq!(yaml_scalar(&y, "model"), format!("\"{}\"", model.name()));
        assert_eq!(yaml_scalar(&y, "update_rate"), "200.0");
        for key in ["accelerometer_noise_density", "gyroscope_random_walk", "rostopic", "time_offset"] {
            assert!(!yaml_scalar(&y, key).is_empty(), "{key}");
        }
        let (tw, rw, ta, ra, tg) = (
            yaml_matrix(&y, "Tw"),
            yaml_matrix(&y, "R_IMUtoGYRO"),
            yaml_matrix(&y, "Ta"),
            yaml_matrix(&y, "R_IMUtoACC"),
            yaml_matrix(&y, "Tg"),
        );
        let outside = |i: usize, j: usize| if model.lower() { j > i } else { j < i };
        // OpenVINS keeps one triangle of D = T⁻¹ (State::Dm); the other is dropped.
        let kept = |t: Matrix3<f64>| {
            let d = t.try_inverse().unwrap();
            Matrix3::from_fn(|i, j| if outside(i, j) { 0.0 } else { d[(i, j)] })
        };
        for (t, r, m, what) in [(tw, rw, pc, "gyro"), (ta, ra, pk, "accel")] {
            for i in 0..3 {
                for j in 0..3 {
                    if outside(i, j) {
                        assert_eq!(t[(i, j)].to_bits(), 0f64.to_bits(), "{what} {model:?}: T[{i}][{j}]");
                    }
                }
            }
            assert!((r * r.transpose() - Matrix3::identity()).amax() < 1e-15, "{what}: R is orthonormal");
            assert!((r.determinant() - 1.0).abs() < 1e-15, "{what}: R is a proper rotation");
            assert!((t * r - m).amax() < 1e-15, "{what} {model:?}: T R = {} vs {m}", t * r);
        }
        for i in 0..3 {
            for j in 0..3 {
                assert_eq!(tg[(i, j)].to_bits(), pg[(i, j)].to_bits(), "Tg[{i}][{j}]");
            }
        }
        let (dw, da) = (kept(tw), kept(ta));
        for (w, a) in inputs(200) {
            let (w, a) = (Vector3::from(w), Vector3::from(a));
            let ug = pbg + pc * w + pg * a;
            let ua = pba + pk * a;
            let a_ov = ra.transpose() * da * (ua - pba);
            let w_ov = rw.transpose() * dw * (ug - pbg - tg * a_ov);
            assert!((a_ov - a).amax() < 1e-12 * 20.0, "{model:?}: OpenVINS's accel {a_ov} vs {a}");
            assert!((w_ov - w).amax() < 1e-12 * 3.0, "{model:?}: OpenVINS's rate {w_ov} vs {w}");
            let (wc, ac, _) = cal.invert_state(ug.into(), ua.into(), [0.0; 3], 0.0, f64::NAN).unwrap();
            assert!((w_ov - Vector3::from(wc)).amax() < 1e-12 * 3.0, "OpenVINS vs crosscal rate");
            assert!((a_ov - Vector3::from(ac)).amax() < 1e-12 * 20.0, "OpenVINS vs crosscal accel");
        }
        let biases = lost.iter().find(|l| l.starts_with("biases")).unwrap_or_else(|| panic!("{lost:?}"));
        assert!(biases.contains(&format!("{:?}", pbg[0])) && biases.contains(&format!("{:?}", pba[2])), "{biases}");
        assert!(!lost.iter().any(|l| l.contains("g-sensitivity") || l.contains("scale-coupling")), "{lost:?}");
        assert!(lost.iter().any(|l| l.contains("noise")), "no noise section: the densities are listed as 0");
    }
}
