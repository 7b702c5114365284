//! Exports to OpenVINS, ArduPilot, PX4 and C: each file parsed back and checked against the
//! profile, against the simulated truth and against the target's documented equations.

use crate::common::{fit_session, run_in, run_ok};
use crosscal::correct::{correct_offline, Calibration, Streaming};
use crosscal::estimate::FitOptions;
use crosscal::model::Model;
use crosscal::profile::autopilot::{to_ardupilot, to_px4, AutopilotImu};
use crosscal::profile::openvins::{to_openvins, OpenVinsModel};
use crosscal::profile::Profile;
use crosscal::simulate::{SimConfig, UnitTruth};
use nalgebra::{Matrix3, Vector3};
use std::collections::BTreeMap;

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

/// ArduPilot (`NAME,VALUE`) and PX4 (QGroundControl, tab-separated) files of a unit with
/// biases and diagonal accelerometer scales only: the values are the profile's offsets and
/// 1/k_ii bit for bit, nothing is lost (besides PX4's device ids), and the autopilots' own
/// arithmetic — a = (u − OFFS)·SCAL, ω = u − OFFS — on simulated raw outputs gives crosscal's
/// correction to 1e-12 and the true inputs to the fit's accuracy. A unit with couplings names
/// them, with their size, as not represented.
#[test]
fn ardupilot_and_px4_parameters_reproduce_crosscal_correction() {
    let (bg, ba, ks) = ([0.01, -0.02, 0.005], [0.15, -0.08, 0.2], [1.02, 0.985, 1.01]);
    let mut values = Vec::new();
    let mut held = Vec::new();
    for i in 0..3 {
        values.push((name("gyro", "b", i, None), bg[i]));
        values.push((name("accel", "b", i, None), ba[i]));
        values.push((name("accel", "k", i, Some(i)), ks[i]));
        for j in 0..3 {
            held.push((name("gyro", "c", i, Some(j)), if i == j { 1.0 } else { 0.0 }));
            if i != j {
                held.push((name("accel", "k", i, Some(j)), 0.0));
            }
        }
    }
    let effects = ["gyro-bias", "gyro-scale-coupling", "accel-bias", "accel-scale-coupling"];
    let p = fitted(&effects, &values, &held);
    let (pk, pba, pbg) = (profile_matrix(&p, "accel", "k"), profile_bias(&p, "accel"), profile_bias(&p, "gyro"));
    for i in 0..3 {
        assert!((pk[(i, i)] - ks[i]).abs() < 1e-4, "k_{i}{i} {} vs truth {}", pk[(i, i)], ks[i]);
        assert!((pba[i] - ba[i]).abs() < 2e-3, "accel bias {i}: {} vs truth {}", pba[i], ba[i]);
        assert!((pbg[i] - bg[i]).abs() < 1e-4, "gyro bias {i}: {} vs truth {}", pbg[i], bg[i]);
    }

    let (ap, ap_lost) = to_ardupilot(&p, AutopilotImu::new(2).unwrap());
    assert!(ap_lost.is_empty(), "a diagonal unit loses nothing in ArduPilot: {ap_lost:?}");
    let ap_params: BTreeMap<String, f64> = ap
        .lines()
        .filter(|l| !l.starts_with('#'))
        .map(|l| {
            let (k, v) = l.split_once(',').unwrap_or_else(|| panic!("not NAME,VALUE: {l}"));
            (k.to_string(), v.parse().unwrap())
        })
        .collect();
    let (px, px_lost) = to_px4(&p, AutopilotImu::FIRST);
    assert_eq!(px_lost.len(), 1, "PX4 loses only the device ids: {px_lost:?}");
    assert!(px.starts_with("# Onboard parameters for Vehicle 1\n"), "{px}");
    assert!(px.contains("\n# Vehicle-Id Component-Id Name Value Type\n"), "{px}");
    let px_params: BTreeMap<String, f64> = px
        .lines()
        .filter(|l| !l.starts_with('#'))
        .map(|l| {
            let f: Vec<&str> = l.split('\t').collect();
            assert_eq!((f.len(), f[0], f[1], f[4]), (5, "1", "1", "9"), "{l}");
            (f[2].to_string(), f[3].parse().unwrap())
        })
        .collect();
    assert_eq!(ap_params.len(), 9);
    assert_eq!(px_params.len(), 9);
    for (i, ax) in ["X", "Y", "Z"].iter().enumerate() {
        for (params, off, scale, goff) in [
            (&ap_params, format!("INS_ACC2OFFS_{ax}"), format!("INS_ACC2SCAL_{ax}"), format!("INS_GYR2OFFS_{ax}")),
            (&px_params, format!("CAL_ACC0_{ax}OFF"), format!("CAL_ACC0_{ax}SCALE"), format!("CAL_GYRO0_{ax}OFF")),
        ] {
            assert_eq!(params[&off].to_bits(), pba[i].to_bits(), "{off}");
            assert_eq!(params[&scale].to_bits(), (1.0 / pk[(i, i)]).to_bits(), "{scale}");
            assert_eq!(params[&goff].to_bits(), pbg[i].to_bits(), "{goff}");
        }
    }
    // The autopilots' arithmetic on the simulated unit's raw outputs.
    let cal = Calibration::from_profile(&p).unwrap();
    let mut worst = [0.0f64; 2];
    for (w, a) in inputs(500) {
        let ua: [f64; 3] = std::array::from_fn(|i| ba[i] + ks[i] * a[i]);
        let ug: [f64; 3] = std::array::from_fn(|i| bg[i] + w[i]);
        let (wc, ac, _) = cal.invert_state(ug, ua, [0.0; 3], 0.0, f64::NAN).unwrap();
        for (params, acc, gyr) in [(&ap_params, "INS_ACC2", "INS_GYR2"), (&px_params, "CAL_ACC0_", "CAL_GYRO0_")] {
            for (i, ax) in ["X", "Y", "Z"].iter().enumerate() {
                let (off, scale, goff) = if acc.starts_with("INS") {
                    (format!("{acc}OFFS_{ax}"), format!("{acc}SCAL_{ax}"), format!("{gyr}OFFS_{ax}"))
                } else {
                    (format!("{acc}{ax}OFF"), format!("{acc}{ax}SCALE"), format!("{gyr}{ax}OFF"))
                };
                let a_ap = (ua[i] - params[&off]) * params[&scale];
                let w_ap = ug[i] - params[&goff];
                assert!(
                    (a_ap - ac[i]).abs() <= 1e-12 * ac[i].abs().max(1.0),
                    "{acc} {ax}: {a_ap} vs crosscal {}",
                    ac[i]
                );
                assert!(
                    (w_ap - wc[i]).abs() <= 1e-12 * wc[i].abs().max(1.0),
                    "{gyr} {ax}: {w_ap} vs crosscal {}",
                    wc[i]
                );
                worst[0] = worst[0].max((a_ap - a[i]).abs());
                worst[1] = worst[1].max((w_ap - w[i]).abs());
            }
        }
    }
    assert!(
        worst[0] < 5e-3 && worst[1] < 1e-4,
        "against the truth: accel {:.2e} m/s², gyro {:.2e} rad/s",
        worst[0],
        worst[1]
    );

    // The paper's unit has couplings (0.01) and C_ε: each is named with its size.
    let coupled = crate::common::fit_and_calibrate(&SimConfig::paper().generate(), &Model::default_model()).1;
    let (_, lost) = to_ardupilot(&coupled, AutopilotImu::FIRST);
    let size = |key: &str| -> f64 {
        let l = lost.iter().find(|l| l.contains(key)).unwrap_or_else(|| panic!("{key} not listed: {lost:?}"));
        l.split("= ").nth(1).and_then(|r| r.split(')').next()).unwrap().parse().unwrap()
    };
    assert!((size("cross-axis") - 0.01).abs() < 1e-6, "{lost:?}");
    assert!((size("gyro scale factors") - 0.01).abs() < 1e-6, "{lost:?}");
    let eps = lost.iter().find(|l| l.contains("'gyro-angular-acceleration'")).unwrap();
    assert!(eps.contains("1.000e-3 s"), "C_ε's largest term (e_xz = 0.001 s): {eps}");
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

/// The C header of a linear profile, compiled with the system's C compiler (skipped without
/// one) and run on 1000 samples, gives crosscal's streaming correction bit for bit; a profile
/// with C_ε is exported with `CROSSCAL_CORRECT_EXACT 0` and C_ε listed as not applied.
#[test]
fn c_header_corrects_like_streaming_bit_for_bit() {
    let mut values = vec![];
    for i in 0..3 {
        values.push((name("gyro", "b", i, None), [0.01, -0.02, 0.005][i]));
        values.push((name("accel", "b", i, None), [0.15, -0.08, 0.2][i]));
        values.push((name("gyro", "c", i, Some((i + 1) % 3)), 0.01));
        values.push((name("accel", "k", i, Some((i + 2) % 3)), -0.012));
        values.push((name("accel", "k", i, Some(i)), [1.02, 0.985, 1.01][i]));
    }
    let p = fitted(&["gyro-bias", "gyro-scale-coupling", "accel-bias", "accel-scale-coupling"], &values, &[]);
    let (h, lost) = crosscal::correct::to_c_header(&p).unwrap();
    assert!(lost.is_empty(), "{lost:?}");
    assert!(h.contains("#define CROSSCAL_CORRECT_EXACT 1"), "{h}");
    assert!(h.contains(&format!("unit {}", p.serial)), "the serial is named");
    let (_, with_eps) = crosscal::correct::to_c_header(
        &crate::common::fit_and_calibrate(&SimConfig::paper().generate(), &Model::default_model()).1,
    )
    .unwrap();
    assert!(
        with_eps.iter().any(|l| l.contains("'gyro-angular-acceleration'") && l.contains("derivative")),
        "{with_eps:?}"
    );

    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    std::fs::write(d.join("crosscal_correct.h"), &h).unwrap();
    std::fs::write(
        d.join("driver.c"),
        r#"#include <stdio.h>
#include <string.h>
#include "crosscal_correct.h"
static double from_bits(unsigned long long u) { double x; memcpy(&x, &u, sizeof x); return x; }
static unsigned long long to_bits(double x) { unsigned long long u; memcpy(&u, &x, sizeof u); return u; }
int main(void) {
    unsigned long long v[6];
    while (scanf("%llx %llx %llx %llx %llx %llx", &v[0], &v[1], &v[2], &v[3], &v[4], &v[5]) == 6) {
        double g[3], a[3];
        int i;
        for (i = 0; i < 3; i++) { g[i] = from_bits(v[i]); a[i] = from_bits(v[3 + i]); }
        crosscal_correct(g, a, g, a); /* in place: the outputs may alias the inputs */
        printf("%016llx %016llx %016llx %016llx %016llx %016llx\n", to_bits(g[0]), to_bits(g[1]), to_bits(g[2]),
               to_bits(a[0]), to_bits(a[1]), to_bits(a[2]));
    }
    return 0;
}
"#,
    )
    .unwrap();
    let cc = std::process::Command::new("cc")
        .args(["-O2", "-std=c99", "-ffp-contract=off", "-Wall", "-Wextra", "-pedantic", "-Werror"])
        .args(["driver.c", "-o", "driver", "-lm"])
        .current_dir(d)
        .output();
    let Ok(cc) = cc else {
        eprintln!("skipped: no C compiler (cc) on PATH");
        return;
    };
    assert!(cc.status.success(), "the header does not compile cleanly: {}", String::from_utf8_lossy(&cc.stderr));
    let samples = inputs(1000);
    let mut stdin = String::new();
    for (w, a) in &samples {
        let bits: Vec<String> = w.iter().chain(a).map(|x| format!("{:016x}", x.to_bits())).collect();
        stdin.push_str(&(bits.join(" ") + "\n"));
    }
    let mut child = std::process::Command::new(d.join("driver"))
        .stdin(std::process::Stdio::piped())
        .stdout(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    use std::io::Write;
    child.stdin.take().unwrap().write_all(stdin.as_bytes()).unwrap();
    let out = child.wait_with_output().unwrap();
    let lines: Vec<&str> = std::str::from_utf8(&out.stdout).unwrap().lines().collect();
    assert_eq!(lines.len(), samples.len());
    let mut streaming = Streaming::new(Calibration::from_profile(&p).unwrap());
    for (k, ((w, a), line)) in samples.iter().zip(&lines).enumerate() {
        let (wc, ac) = streaming.push(k as f64 * 0.01, *w, *a, f64::NAN);
        let c: Vec<u64> = line.split(' ').map(|x| u64::from_str_radix(x, 16).unwrap()).collect();
        for i in 0..3 {
            assert_eq!(c[i], wc[i].to_bits(), "sample {k} gyro {i}: C {} vs crosscal {}", f64::from_bits(c[i]), wc[i]);
            assert_eq!(
                c[3 + i],
                ac[i].to_bits(),
                "sample {k} accel {i}: C {} vs crosscal {}",
                f64::from_bits(c[3 + i]),
                ac[i]
            );
        }
    }
}

/// `crosscal profile export` writes each new target, prints what it leaves out and names the
/// targets and models it knows when given another.
#[test]
fn export_command_writes_openvins_autopilot_and_c_files() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let p = crate::common::fit_and_calibrate(&SimConfig::paper().generate(), &Model::default_model()).1;
    let path = crosscal::profile::save(&p, d).unwrap();
    let path = path.to_str().unwrap();
    for (to, file, key) in [
        ("openvins", "kalibr_imu_chain.yaml", "R_IMUtoGYRO:"),
        ("ardupilot", "imu.param", "INS_ACCSCAL_X,"),
        ("px4", "imu.params", "\tCAL_ACC0_XSCALE\t"),
        ("c-header", "crosscal_correct.h", "static inline void crosscal_correct("),
    ] {
        let (code, out, err) = run_in(d, &["profile", "export", path, "--to", to, "-o", file]);
        assert_eq!(code, 0, "{to}: {out}{err}");
        assert!(err.contains("not represented: "), "{to}: {err}");
        let text = std::fs::read_to_string(d.join(file)).unwrap();
        assert!(text.contains(key), "{to}: {text}");
    }
    run_ok(d, &["profile", "export", path, "--to", "openvins", "--openvins-model", "rpng", "-o", "rpng.yaml"]);
    assert!(std::fs::read_to_string(d.join("rpng.yaml")).unwrap().contains("model: \"rpng\""));
    let (code, _, err) = run_in(d, &["profile", "export", path, "--to", "betaflight", "-o", "x"]);
    assert_ne!(code, 0);
    assert!(err.contains("openvins, ardupilot, px4 or c-header"), "{err}");
    let (code, _, err) =
        run_in(d, &["profile", "export", path, "--to", "openvins", "--openvins-model", "x", "-o", "y"]);
    assert_ne!(code, 0);
    assert!(err.contains("expected kalibr, rpng or calibrated"), "{err}");
    let (code, _, _) = run_in(d, &["profile", "export", path, "--to", "ardupilot", "--imu", "4", "-o", "z"]);
    assert_ne!(code, 0, "there is no fourth ArduPilot IMU in the INS_ names");
}

/// `NAME,VALUE` lines of an ArduPilot parameter file.
fn ardupilot_params(text: &str) -> BTreeMap<String, f64> {
    text.lines()
        .filter(|l| !l.starts_with('#'))
        .map(|l| {
            let (k, v) = l.split_once(',').unwrap_or_else(|| panic!("not NAME,VALUE: {l}"));
            (k.to_string(), v.parse().unwrap_or_else(|e| panic!("{l}: {e}")))
        })
        .collect()
}

/// `1 1 NAME VALUE TYPE` lines of a QGroundControl parameter file (type 6 INT32, 9 REAL32).
fn px4_params(text: &str) -> BTreeMap<String, f64> {
    text.lines()
        .filter(|l| !l.starts_with('#'))
        .map(|l| {
            let f: Vec<&str> = l.split('\t').collect();
            assert_eq!((f.len(), f[0], f[1]), (5, "1", "1"), "{l}");
            let ty = if f[2].ends_with("_ENABLE") { "6" } else { "9" };
            assert_eq!(f[4], ty, "{l}");
            (f[2].to_string(), f[3].parse().unwrap_or_else(|e| panic!("{l}: {e}")))
        })
        .collect()
}

/// ArduPilot's thermal correction as `AP_InertialSensor::TCal::correct_sensor` evaluates it,
/// plus the offset: the total subtracted from raw axis `i` of `sensor` ("ACC"/"GYR") at `t`,
/// P(x) = 1e-6 (C1 d + C2 d² + C3 d³), d = x − 35, x clamped to [TMIN, TMAX], and the
/// calibration temperature (`INS_ACC1_CALTEMP`) clamped the same way.
fn ardupilot_offset(p: &BTreeMap<String, f64>, sensor: &str, i: usize, t: f64) -> f64 {
    let ax = ["X", "Y", "Z"][i];
    let (lo, hi) = (p["INS_TCAL1_TMIN"], p["INS_TCAL1_TMAX"]);
    assert_eq!(p["INS_TCAL1_ENABLE"].to_bits(), 1f64.to_bits());
    let poly = |x: f64| {
        let d = x.clamp(lo, hi) - 35.0;
        let c = |k: u8| p[&format!("INS_TCAL1_{sensor}{k}_{ax}")];
        (c(1) + (c(2) + c(3) * d) * d) * d * 1e-6
    };
    let (offs, cal) = if sensor == "ACC" {
        (p[&format!("INS_ACCOFFS_{ax}")], p["INS_ACC1_CALTEMP"])
    } else {
        (p[&format!("INS_GYROFFS_{ax}")], p["INS_GYR1_CALTEMP"])
    };
    poly(t) - poly(cal) + offs
}

/// PX4's `TemperatureCompensation::calc_thermal_offsets_3D` plus the calibration offset: the
/// total subtracted from raw axis `i` of `sensor` ('A'/'G') at `t`.
fn px4_offset(p: &BTreeMap<String, f64>, sensor: char, i: usize, t: f64) -> f64 {
    let g = |k: &str| p[&format!("TC_{sensor}0_{k}")];
    assert_eq!(p[&format!("TC_{sensor}_ENABLE")].to_bits(), 1f64.to_bits());
    let d = if t > g("TMAX") {
        g("TMAX") - g("TREF")
    } else if t < g("TMIN") {
        g("TMIN") - g("TREF")
    } else {
        t - g("TREF")
    };
    let x = |k: u8| g(&format!("X{k}_{i}"));
    let cal = if sensor == 'A' {
        format!("CAL_ACC0_{}OFF", AXES[i].to_ascii_uppercase())
    } else {
        format!("CAL_GYRO0_{}OFF", AXES[i].to_ascii_uppercase())
    };
    x(0) + x(1) * d + x(2) * d * d + x(3) * d * d * d + p[&cal]
}

/// A unit with a hidden cubic gyro and quadratic accelerometer temperature bias, swept over
/// −20 … +70 °C and fitted with those terms, exported to ArduPilot and PX4: each file's thermal
/// block, evaluated as the firmware does (`ardupilot_offset`, `px4_offset`) at 487 temperatures
/// from 25 °C below the calibrated range to 25 °C above it, subtracts from raw samples exactly
/// what crosscal's correction (`correct_offline`, default clamp) does — the firmware's output
/// equals crosscal's with the scale the firmware lacks re-applied (C ω̂, diag(1/k_ii) K â) to
/// 1e-9 of the output — inside the range and, both clamping at TMIN/TMAX, outside it. The same
/// holds for the profile narrowed to 25 … 70 °C, where 20 °C (crosscal's reference) is outside
/// and ArduPilot's CALTEMP and offsets move.
#[test]
fn thermal_blocks_reproduce_crosscal_temperature_correction() {
    let dir = tempfile::tempdir().unwrap_or_else(|e| panic!("{e}"));
    let d = dir.path();
    // The issue's gyro biases, larger accelerometer ones (the exports' thermal units).
    let accel = [
        ("accel.tb_x", 1e-3),
        ("accel.tb2_x", -2e-5),
        ("accel.tb_y", -5e-4),
        ("accel.tb2_y", 1e-5),
        ("accel.tb_z", 8e-4),
        ("accel.tb2_z", 5e-6),
    ];
    let truth: Vec<(&str, f64)> = crate::common::THERMAL_BIASES[..9].iter().chain(&accel).copied().collect();
    let effects = ["gyro-temp-bias", "gyro-temp-bias2", "gyro-temp-bias3", "accel-temp-bias", "accel-temp-bias2"];
    let owned: Vec<(String, f64)> = truth.iter().map(|(n, v)| (n.to_string(), *v)).collect();
    crate::common::simulate_hidden(d, "sweep", &effects, &owned, &["--temperature", "-20,70"]);
    let (_, p) = crate::common::fit_into_store(d, "sweep/session.json", &effects);
    let coef = |name: &str| if name.starts_with("gyro") { p.gyro.value(name) } else { p.accel.value(name) };
    for (name, want) in truth {
        let got = coef(name).unwrap_or(f64::NAN);
        assert!((got - want).abs() < 0.05 * want.abs(), "{name}: {got} vs truth {want}");
    }
    let [lo, hi] = p.temperature_range_c().unwrap_or([f64::NAN; 2]);
    assert!((lo + 20.0).abs() < 0.01 && (hi - 70.0).abs() < 0.01, "{lo}..{hi}");

    let worst = firmware_matches_crosscal(&p);
    eprintln!("firmware vs crosscal, -20..70 degC: {:?}", worst.map(|w| format!("{w:.1e}")));
    // Calibrated over 25 … 70 °C only: 20 °C is outside, so ArduPilot's CALTEMP is 25 °C and
    // its offsets carry q(25 °C); PX4's TREF moves to 47.5 °C.
    let mut warm = p.clone();
    for r in &mut warm.runs {
        r.temp_range_c = r.temp_range_c.map(|_| [25.0, 70.0]);
    }
    let ap = ardupilot_params(&to_ardupilot(&warm, AutopilotImu::FIRST).0);
    assert_eq!(ap["INS_GYR1_CALTEMP"].to_bits(), 25f64.to_bits());
    assert!((ap["INS_GYROFFS_X"] - profile_bias(&p, "gyro")[0]).abs() > 1e-5, "q(25 degC) is in the offset");
    let worst = firmware_matches_crosscal(&warm);
    eprintln!("firmware vs crosscal, 25..70 degC: {:?}", worst.map(|w| format!("{w:.1e}")));
}

/// Both exports of `p` evaluated as the firmware does, against crosscal's correction of the
/// same raw samples at 487 temperatures 25 °C beyond the calibrated range on either side;
/// returns the worst gyro and accelerometer output differences and the worst relative
/// differences of the offsets from b + q(clamp(T)).
fn firmware_matches_crosscal(p: &Profile) -> [f64; 4] {
    let coef = |name: &str| if name.starts_with("gyro") { p.gyro.value(name) } else { p.accel.value(name) };
    let [lo, hi] = p.temperature_range_c().unwrap_or([f64::NAN; 2]);
    let (ap_text, ap_lost) = to_ardupilot(p, AutopilotImu::FIRST);
    let (px_text, px_lost) = to_px4(p, AutopilotImu::FIRST);
    for lost in [&ap_lost, &px_lost] {
        assert!(!lost.iter().any(|l| l.contains("temp-bias")), "the thermal polynomial is held: {lost:?}");
    }
    assert!(px_lost.iter().any(|l| l.contains("TC_A0_ID")), "{px_lost:?}");
    let ap = ardupilot_params(&ap_text);
    let px = px4_params(&px_text);
    assert_eq!(ap.len(), 9 + 3 + 18 + 2, "{ap_text}");
    assert_eq!(px.len(), 9 + 2 + 2 * (3 + 12), "{px_text}");
    assert_eq!((ap["INS_TCAL1_TMIN"].to_bits(), ap["INS_TCAL1_TMAX"].to_bits()), (lo.to_bits(), hi.to_bits()));
    assert_eq!((px["TC_G0_TMIN"].to_bits(), px["TC_A0_TMAX"].to_bits()), (lo.to_bits(), hi.to_bits()));
    // A quadratic accelerometer bias has no cubic term about any reference.
    assert!(ap["INS_TCAL1_ACC3_X"].abs() < 1e-9 && px["TC_A0_X3_0"].abs() < 1e-18);

    // Raw samples the firmware's offsets map to fixed outputs: crosscal must find the same.
    let pc = profile_matrix(p, "gyro", "c");
    let pk = profile_matrix(p, "accel", "k");
    let (s_w, s_a) = (Vector3::new(0.3, -0.2, 0.5), Vector3::new(0.4, -0.3, 9.8));
    let temps: Vec<f64> = (0..487).map(|k| lo - 25.0 + (hi - lo + 50.0) * k as f64 / 486.0).collect();
    let cal = Calibration::from_profile(p).unwrap_or_else(|e| panic!("{e}"));
    let t_s: Vec<f64> = (0..temps.len()).map(|k| k as f64 * 0.01).collect();
    let mut worst = [0.0f64; 4];
    for stack in ["ArduPilot", "PX4"] {
        let off = |acc: bool, i: usize, t: f64| match (stack, acc) {
            ("ArduPilot", true) => ardupilot_offset(&ap, "ACC", i, t),
            ("ArduPilot", false) => ardupilot_offset(&ap, "GYR", i, t),
            (_, true) => px4_offset(&px, 'A', i, t),
            (_, false) => px4_offset(&px, 'G', i, t),
        };
        let (cw, ka) = (pc * s_w, pk * s_a);
        let scale: [f64; 3] = std::array::from_fn(|i| match stack {
            "ArduPilot" => ap[&format!("INS_ACCSCAL_{}", AXES[i].to_ascii_uppercase())],
            _ => px[&format!("CAL_ACC0_{}SCALE", AXES[i].to_ascii_uppercase())],
        });
        let gyro: Vec<[f64; 3]> = temps.iter().map(|&t| std::array::from_fn(|i| off(false, i, t) + cw[i])).collect();
        let accel: Vec<[f64; 3]> = temps.iter().map(|&t| std::array::from_fn(|i| off(true, i, t) + ka[i])).collect();
        let c = correct_offline(&cal, &t_s, &gyro, &accel, Some(&temps)).unwrap_or_else(|e| panic!("{e}"));
        let outside = temps.iter().filter(|&&t| t < lo || t > hi).count() as u64;
        assert_eq!(c.temp_outside.samples, outside);
        for (k, &t) in temps.iter().enumerate() {
            let (w, a) = (Vector3::from(c.w_rad_s[k]), Vector3::from(c.a_m_s2[k]));
            let (cw_cc, ka_cc) = (pc * w, pk * a);
            for i in 0..3 {
                // The firmware's own output, ω = raw − offset, a = (raw − offset)·(1/k_ii).
                let w_fw = gyro[k][i] - off(false, i, t);
                let a_fw = (accel[k][i] - off(true, i, t)) * scale[i];
                let (ew, ea) = ((w_fw - cw_cc[i]).abs(), (a_fw - ka_cc[i] * scale[i]).abs());
                assert!(ew <= 1e-9 * s_w.norm(), "{stack} gyro {i} at {t:.2} degC: {w_fw} vs crosscal {}", cw_cc[i]);
                assert!(ea <= 1e-9 * s_a.norm(), "{stack} accel {i} at {t:.2} degC: {a_fw} vs crosscal {}", ka_cc[i]);
                worst[0] = worst[0].max(ew);
                worst[1] = worst[1].max(ea);
            }
        }
        // The thermal part alone against the profile's polynomial about 20 °C, clamped.
        for &t in &temps {
            let tc = t.clamp(lo, hi) - 20.0;
            for (i, ax) in AXES.iter().enumerate() {
                let q = |s: &str, b: f64| {
                    let v = |l: &str| coef(&format!("{s}.{l}_{ax}")).unwrap_or(0.0);
                    b + v("tb") * tc + v("tb2") * tc * tc + v("tb3") * tc * tc * tc
                };
                let (qg, qa) = (q("gyro", profile_bias(p, "gyro")[i]), q("accel", profile_bias(p, "accel")[i]));
                worst[2] = worst[2].max((off(false, i, t) - qg).abs() / qg.abs().max(1e-3));
                worst[3] = worst[3].max((off(true, i, t) - qa).abs() / qa.abs().max(1e-3));
            }
        }
        // Outside the range the firmware holds the edge: its offset there is the edge's.
        for i in 0..3 {
            assert_eq!(off(false, i, hi + 20.0).to_bits(), off(false, i, hi).to_bits(), "{stack}");
            assert_eq!(off(true, i, lo - 20.0).to_bits(), off(true, i, lo).to_bits(), "{stack}");
        }
    }
    assert!(worst[2] < 1e-9 && worst[3] < 1e-9, "thermal offsets vs the profile's polynomial: {worst:?}");
    worst
}
