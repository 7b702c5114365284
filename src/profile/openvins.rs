//! OpenVINS's IMU file (`kalibr_imu_chain.yaml`, read by `ov_msckf`'s `VioManagerOptions`):
//! the noise densities and the IMU intrinsics of a profile.
//!
//! OpenVINS's measurement model (OpenVINS documentation, *Propagation* → IMU measurements,
//! and *Analytical Propagation* → IMU intrinsic models), with ᴵa the specific force in the
//! IMU frame {I}, {w} and {a} the gyroscope and accelerometer frames:
//! ```text
//! ʷω_m = T_w ʷ_I R ᴵω + T_g ᴵa + b_g + n_g            ᵃa_m = T_a ᵃ_I R ᴵa + b_a + n_a
//! ᴵω = ᴵ_w R D_w (ʷω_m − T_g ᴵa − b_g − n_g)           ᴵa = ᴵ_a R D_a (ᵃa_m − b_a − n_a)
//! D_w = T_w⁻¹,  D_a = T_a⁻¹
//! ```
//! The file holds the *forward* matrices: `Tw`, `Ta`, `Tg`, and the rotations
//! `R_IMUtoGYRO` = ʷ_I R and `R_IMUtoACC` = ᵃ_I R. OpenVINS inverts `Tw` and `Ta` itself and
//! keeps one triangle of each D: the lower one with `model: kalibr` (or `calibrated`, the
//! same structure with online calibration refused), the upper one with `rpng` (its `State::Dm`).
//! Both rotations are applied whatever the model (`a_hat = R_ACCtoIMU Da (a_m − b_a)`,
//! `w_hat = R_GYROtoIMU Dw (w_m − b_g − Tg a_hat)` in its propagator); the model only chooses
//! which rotation it may refine online (kalibr the gyroscope's, rpng the accelerometer's).
//!
//! crosscal's forward model in the unit's own axes (= {I}) is `u_g = b_g + C_ω ω + G a
//! (+ C_ε ε + …)` and `u_a = b_a + K a`, so the file must satisfy
//! ```text
//! T_w · R_IMUtoGYRO = C_ω,     T_a · R_IMUtoACC = K,     T_g = G.
//! ```
//! Every invertible matrix factors as M = T R with T triangular of either kind and R a proper
//! rotation ([`triangular_rotation`]), so a full, non-triangular C_ω or K is held exactly: its
//! triangular part goes to `Tw`/`Ta`, its rotation part to `R_IMUtoGYRO`/`R_IMUtoACC`. The
//! biases have no field (OpenVINS estimates them online) and are listed as not represented,
//! with their values, as is every effect the model above lacks.

use super::estimators::densities;
use super::interop::yaml_float;
use super::interop::{matrix, unheld, vector};
use super::Profile;
use crate::units::{AccelUnit, GyroUnit, SensorKind};
use std::fmt::Write;

/// OpenVINS's IMU intrinsic model (`imu0: model:`), which fixes the triangle of `Tw`/`Ta`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum OpenVinsModel {
    /// `kalibr`: lower-triangular D (and T); OpenVINS may refine the gyroscope rotation.
    Kalibr,
    /// `rpng`: upper-triangular D (and T); OpenVINS may refine the accelerometer rotation.
    Rpng,
    /// `calibrated`: the kalibr structure, with online intrinsic calibration refused.
    Calibrated,
}

impl OpenVinsModel {
    /// Parses `kalibr`, `rpng` or `calibrated` (OpenVINS's spellings).
    pub fn parse(s: &str) -> Option<Self> {
        match s {
            "kalibr" => Some(Self::Kalibr),
            "rpng" => Some(Self::Rpng),
            "calibrated" => Some(Self::Calibrated),
            _ => None,
        }
    }

    /// The name OpenVINS reads.
    pub fn name(self) -> &'static str {
        match self {
            Self::Kalibr => "kalibr",
            Self::Rpng => "rpng",
            Self::Calibrated => "calibrated",
        }
    }

    /// Whether the model keeps the lower triangle (kalibr, calibrated) or the upper (rpng).
    pub fn lower(self) -> bool {
        self != Self::Rpng
    }
}

type M3 = [[f64; 3]; 3];

fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]
}

/// Factors M = T R with T triangular (lower when `lower`, else upper) and R a proper
/// rotation (R Rᵀ = I, det R = +1); None when M is singular.
///
/// Gram–Schmidt on M's rows mᵢ in the order the triangle fills (lower: x, y, z; upper:
/// z, y, x), with rotation rows rᵢ: the first row gives r = m/|m|, t = |m| on the diagonal;
/// the second r = (m − (m·r₁) r₁)/|…| with t = m·r₁ below (or above) the diagonal and |…| on
/// it; the third rotation row completes a right-handed set (r_z = r_x × r_y, or for the upper
/// order r_x = r_y × r_z) and the third row of T is (m·r_x, m·r_y, m·r_z). Its diagonal entry
/// is negative exactly when det M < 0 (a mirrored axis, which no rotation can hold); the other
/// two diagonal entries are positive. T R reproduces M to rounding, since the rᵢ are an
/// orthonormal basis.
pub fn triangular_rotation(m: M3, lower: bool) -> Option<(M3, M3)> {
    let [a, b, c] = if lower { [0, 1, 2] } else { [2, 1, 0] };
    let (mut t, mut r) = ([[0.0; 3]; 3], [[0.0; 3]; 3]);
    let na = dot(m[a], m[a]).sqrt();
    if !(na > 0.0 && na.is_finite()) {
        return None;
    }
    r[a] = m[a].map(|v| v / na);
    t[a][a] = na;
    let p = dot(m[b], r[a]);
    let v: [f64; 3] = std::array::from_fn(|j| m[b][j] - p * r[a][j]);
    let nb = dot(v, v).sqrt();
    if !(nb > 1e-12 * na.max(dot(m[b], m[b]).sqrt()) && nb.is_finite()) {
        return None;
    }
    r[b] = v.map(|x| x / nb);
    t[b][a] = p;
    t[b][b] = nb;
    r[c] = cross(r[(c + 1) % 3], r[(c + 2) % 3]);
    for j in 0..3 {
        t[c][j] = dot(m[c], r[j]);
    }
    Some((t, r))
}

fn yaml_matrix(s: &mut String, key: &str, m: &[Vec<f64>]) {
    let _ = writeln!(s, "  {key}:");
    for row in m {
        let cells: Vec<String> = row.iter().map(|v| yaml_float(*v)).collect();
        let _ = writeln!(s, "    - [{}]", cells.join(", "));
    }
}

/// The profile as OpenVINS's `kalibr_imu_chain.yaml` (`%YAML:1.0`, one `imu0` block: `T_i_b`
/// identity, the four noise densities, `rostopic`, `time_offset`, `update_rate`, `model`,
/// `Tw`, `R_IMUtoGYRO`, `Ta`, `R_IMUtoACC`, `Tg`), and what it cannot hold.
///
/// Implements `C_ω = Tw · R_IMUtoGYRO`, `K = Ta · R_IMUtoACC`, `Tg = G` (module docs) with Tw
/// and Ta triangular as `model` requires. The noise densities are those of the VINS-Fusion
/// export (worst axis, continuous-time SI; 0 and listed when the profile has none).
pub fn to_openvins(p: &Profile, model: OpenVinsModel, rate_hz: f64) -> (String, Vec<String>) {
    let d = densities(p);
    let mut lost = d.lost;
    let mut factor = |m: M3, what: &str| match triangular_rotation(m, model.lower()) {
        Some(tr) => tr,
        None => {
            lost.push(format!("the {what} matrix is singular: written untransformed with an identity rotation"));
            (m, [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])
        }
    };
    let (tw, rw) = factor(matrix(p, SensorKind::Gyro, "c"), "gyro scale/coupling");
    let (ta, ra) = factor(matrix(p, SensorKind::Accel, "k"), "accelerometer scale/coupling");
    let tg = matrix(p, SensorKind::Gyro, "g");
    let (bg, ba) = (vector(p, SensorKind::Gyro), vector(p, SensorKind::Accel));
    if bg.iter().chain(&ba).any(|v| *v != 0.0) {
        lost.push(format!(
            "biases b_g = {bg:?} rad/s, b_a = {ba:?} m/s^2 (OpenVINS estimates them online; its file has no field for them)"
        ));
    }
    if p.input_units.gyro == GyroUnit::Raw || p.input_units.accel == AccelUnit::Raw {
        lost.push("raw-unit scales: OpenVINS expects SI measurements (rad/s, m/s^2)".into());
    }
    let held = ["gyro-bias", "accel-bias", "gyro-scale-coupling", "accel-scale-coupling", "gyro-g-sensitivity"];
    lost.extend(unheld(p, &held, "OpenVINS's IMU model has no such term"));
    let tri = if model.lower() { "lower" } else { "upper" };
    let mut s = String::from("%YAML:1.0\n");
    let _ = writeln!(
        s,
        "# OpenVINS kalibr_imu_chain.yaml exported by crosscal from unit {} profile {}",
        p.serial, p.created_utc
    );
    let _ = writeln!(
        s,
        "# w_m = Tw R_IMUtoGYRO w + Tg a + b_g, a_m = Ta R_IMUtoACC a + b_a (SI, the unit's axes); Tw, Ta {tri}-triangular for model {}",
        model.name()
    );
    let _ = writeln!(s, "# Not represented: {}", lost.join("; "));
    let _ = writeln!(s, "imu0:");
    let eye4: Vec<Vec<f64>> = (0..4).map(|i| (0..4).map(|j| if i == j { 1.0 } else { 0.0 }).collect()).collect();
    yaml_matrix(&mut s, "T_i_b", &eye4);
    let _ = writeln!(s, "  accelerometer_noise_density: {}  # m/s^2/sqrt(Hz)", yaml_float(d.accel_white));
    let _ = writeln!(s, "  accelerometer_random_walk: {}  # m/s^3/sqrt(Hz)", yaml_float(d.accel_walk));
    let _ = writeln!(s, "  gyroscope_noise_density: {}  # rad/s/sqrt(Hz)", yaml_float(d.gyro_white));
    let _ = writeln!(s, "  gyroscope_random_walk: {}  # rad/s^2/sqrt(Hz)", yaml_float(d.gyro_walk));
    let _ = writeln!(s, "  rostopic: /imu0");
    let _ = writeln!(s, "  time_offset: 0.0");
    let _ = writeln!(s, "  update_rate: {}", yaml_float(rate_hz));
    let _ = writeln!(s, "  model: \"{}\"", model.name());
    let rows = |m: M3| -> Vec<Vec<f64>> { m.iter().map(|r| r.to_vec()).collect() };
    yaml_matrix(&mut s, "Tw", &rows(tw));
    yaml_matrix(&mut s, "R_IMUtoGYRO", &rows(rw));
    yaml_matrix(&mut s, "Ta", &rows(ta));
    yaml_matrix(&mut s, "R_IMUtoACC", &rows(ra));
    yaml_matrix(&mut s, "Tg", &rows(tg));
    (s, lost)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn product(a: M3, b: M3) -> M3 {
        std::array::from_fn(|i| std::array::from_fn(|j| (0..3).map(|k| a[i][k] * b[k][j]).sum()))
    }

    /// T R = M, T triangular with exact zeros, R a proper rotation, for couplings of both signs,
    /// a mirrored axis (det < 0) and a matrix far from the identity; singular ones refused.
    #[test]
    fn factors_are_triangular_times_rotation() {
        let cases: [M3; 4] = [
            [[1.02, 0.013, -0.007], [-0.011, 0.985, 0.021], [0.004, -0.018, 1.011]],
            [[0.99, 0.02, 0.0], [0.0, -1.01, 0.03], [0.01, 0.0, 1.0]],
            [[0.2, 1.1, -0.3], [0.9, -0.1, 0.4], [0.3, 0.5, 1.7]],
            [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
        ];
        for m in cases {
            for lower in [true, false] {
                let (t, r) = triangular_rotation(m, lower).unwrap();
                for i in 0..3 {
                    for j in 0..3 {
                        let zero = if lower { j > i } else { j < i };
                        if zero {
                            assert_eq!(t[i][j].to_bits(), 0f64.to_bits(), "{m:?} lower={lower}: t[{i}][{j}]");
                        }
                        let rrt: f64 = (0..3).map(|k| r[i][k] * r[j][k]).sum();
                        let eye = if i == j { 1.0 } else { 0.0 };
                        assert!((rrt - eye).abs() < 1e-15, "{m:?}: R Rᵀ[{i}][{j}] = {rrt}");
                        let back = product(t, r)[i][j];
                        assert!((back - m[i][j]).abs() < 2e-15, "{m:?} lower={lower}: {back} vs {}", m[i][j]);
                    }
                }
                assert!((dot(r[0], cross(r[1], r[2])) - 1.0).abs() < 1e-15, "det R = +1");
                let first = if lower { 0 } else { 2 };
                assert!(t[first][first] > 0.0 && t[1][1] > 0.0, "the first two pivots are positive");
            }
        }
        let det_negative = triangular_rotation(cases[1], true).unwrap().0;
        assert!(det_negative[2][2] < 0.0, "the mirrored axis shows as a negative last pivot");
        assert!(triangular_rotation([[1.0, 2.0, 0.0], [2.0, 4.0, 0.0], [0.0, 0.0, 1.0]], true).is_none());
    }
}
