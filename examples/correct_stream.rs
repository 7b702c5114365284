//! Correct a unit's outputs in your own program: the stored profile, a streaming corrector,
//! blocks of samples in and out of buffers you own (no allocation per block).
//!
//! Run: `cargo run --release --example correct_stream -- calib-profiles/<serial>`
//! (a unit's folder means its newest profile).

use crosscal::correct::{Calibration, Streaming};
use crosscal::profile::Profile;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let arg = std::env::args().nth(1).ok_or("usage: correct_stream PROFILE-OR-UNIT-FOLDER")?;
    let (path, profile) = Profile::read_or_latest(std::path::Path::new(&arg))?;
    let mut corrector = Streaming::new(Calibration::from_profile(&profile)?);

    // One block of 100 samples at 100 Hz, SI units (rad/s, m/s²): here a unit at rest, level.
    let t_s: Vec<f64> = (0..100).map(|k| k as f64 * 0.01).collect();
    let gyro = vec![[0.0; 3]; 100];
    let accel = vec![[0.0, 0.0, 9.80665]; 100];
    let (mut w_rad_s, mut a_m_s2) = (vec![[0.0; 3]; 100], vec![[0.0; 3]; 100]);
    let n = corrector.push_block(&t_s, &gyro, &accel, &mut w_rad_s, &mut a_m_s2);

    println!("profile {} of unit {}: corrected {n} samples", path.display(), profile.serial);
    println!("last sample: rate {:?} rad/s, specific force {:?} m/s²", w_rad_s[n - 1], a_m_s2[n - 1]);
    Ok(())
}
