//! Noise parameters for visual-inertial estimators, from a profile's noise section: the
//! IMU block of a VINS-Fusion configuration and of an ORB-SLAM3 settings file. Both want
//! continuous-time densities in SI units, as Kalibr does: white noise in rad/s/√Hz and
//! m/s²/√Hz (the Allan deviation's N), bias random walk in rad/s²/√Hz and m/s³/√Hz (its rate
//! random walk K, the same unit as rad/s/√s). Each value is the worst axis of the sensor's
//! standard reading ([`crate::noise::ChannelNoise::white`]) or fitted term; a value the
//! profile does not have is written as 0 and listed as not represented, as the Kalibr export
//! does. What these estimators cannot hold of the calibration (scale factors, couplings,
//! g-sensitivity) is listed too: apply the profile to the data first (`crosscal correct`).

use super::Profile;
use crate::noise::ChannelNoise;
use crate::units::SensorKind;
use std::fmt::Write;

/// White density and bias random walk of both sensors (gyro, accel), SI, and what is missing.
pub(super) struct Densities {
    /// Gyro white noise, rad/s/√Hz.
    pub gyro_white: f64,
    /// Gyro bias random walk, rad/s²/√Hz.
    pub gyro_walk: f64,
    /// Accelerometer white noise, m/s²/√Hz.
    pub accel_white: f64,
    /// Accelerometer bias random walk, m/s³/√Hz.
    pub accel_walk: f64,
    /// The terms the noise section lacks (written as 0).
    pub lost: Vec<String>,
}

/// The worst axis of each sensor's white noise (standard reading) and bias random walk
/// (fitted K) from the profile's noise section; a missing term is 0 and listed.
pub(super) fn densities(p: &Profile) -> Densities {
    let mut lost = Vec::new();
    let mut worst = |name: &str, s: SensorKind, f: fn(&ChannelNoise) -> Option<f64>| {
        let v =
            p.noise.as_ref().and_then(|n| n.channels.iter().filter(|c| c.sensor() == s).filter_map(f).reduce(f64::max));
        v.unwrap_or_else(|| {
            lost.push(format!(
                "{name}: the profile's noise section has no such term (crosscal noise --store); written as 0"
            ));
            0.0
        })
    };
    let gyro_white = worst("gyro white noise", SensorKind::Gyro, |c| c.white());
    let gyro_walk = worst("gyro bias random walk", SensorKind::Gyro, |c| c.random_walk);
    let accel_white = worst("accelerometer white noise", SensorKind::Accel, |c| c.white());
    let accel_walk = worst("accelerometer bias random walk", SensorKind::Accel, |c| c.random_walk);
    Densities { gyro_white, gyro_walk, accel_white, accel_walk, lost }
}

/// [`densities`] and what a noise-only block cannot hold of the calibration.
fn noise_block(p: &Profile) -> Densities {
    let mut d = densities(p);
    d.lost.push(
        "scale factors, couplings and the other effects of the profile (correct the data with crosscal correct first)"
            .into(),
    );
    d
}

/// The IMU block of a VINS-Fusion configuration (`acc_n`, `gyr_n`, `acc_w`, `gyr_w`,
/// `g_norm`), to paste into the estimator's YAML, and what it cannot hold.
pub fn to_vins_fusion(p: &Profile, g_m_s2: f64) -> (String, Vec<String>) {
    let d = noise_block(p);
    let mut s = String::new();
    let _ = writeln!(
        s,
        "# VINS-Fusion IMU parameters exported by crosscal from unit {} profile {}",
        p.serial, p.created_utc
    );
    let _ = writeln!(s, "# continuous-time densities, SI; not represented: {}", d.lost.join("; "));
    let _ = writeln!(s, "acc_n: {:e}          # accelerometer white noise, m/s^2/sqrt(Hz)", d.accel_white);
    let _ = writeln!(s, "gyr_n: {:e}          # gyroscope white noise, rad/s/sqrt(Hz)", d.gyro_white);
    let _ = writeln!(s, "acc_w: {:e}          # accelerometer bias random walk, m/s^3/sqrt(Hz)", d.accel_walk);
    let _ = writeln!(s, "gyr_w: {:e}          # gyroscope bias random walk, rad/s^2/sqrt(Hz)", d.gyro_walk);
    let _ = writeln!(s, "g_norm: {g_m_s2}      # gravity magnitude, m/s^2");
    (s, d.lost)
}

/// The IMU noise block of an ORB-SLAM3 settings file (OpenCV `%YAML:1.0`; `IMU.NoiseGyro`,
/// `IMU.NoiseAcc`, `IMU.GyroWalk`, `IMU.AccWalk`, `IMU.Frequency`), and what it cannot hold.
pub fn to_orb_slam3(p: &Profile, rate_hz: f64) -> (String, Vec<String>) {
    let d = noise_block(p);
    let mut s = String::from("%YAML:1.0\n");
    let _ = writeln!(s, "# ORB-SLAM3 IMU noise exported by crosscal from unit {} profile {}", p.serial, p.created_utc);
    let _ = writeln!(s, "# continuous-time densities, SI; not represented: {}", d.lost.join("; "));
    let _ = writeln!(s, "IMU.NoiseGyro: {:e}", d.gyro_white);
    let _ = writeln!(s, "IMU.NoiseAcc: {:e}", d.accel_white);
    let _ = writeln!(s, "IMU.GyroWalk: {:e}", d.gyro_walk);
    let _ = writeln!(s, "IMU.AccWalk: {:e}", d.accel_walk);
    let _ = writeln!(s, "IMU.Frequency: {rate_hz:?}");
    (s, d.lost)
}
