//! Dead zone: no output until the input on an axis exceeds a threshold.

use super::nonlinear::{NonlinearEffect, ParamDef};
use super::{output_unit, Inputs, SensorKind, AXES};
use crate::motion::Track;

/// The sensor sees x_i − clamp(x_i, −d_i, d_i) on its own axis i (d_i ≥ 0).
#[derive(Debug, Clone)]
pub struct DeadZone {
    sensor: SensorKind,
}

impl DeadZone {
    /// Dead zone of a sensor's three axes.
    pub fn new(sensor: SensorKind) -> Self {
        Self { sensor }
    }
}

impl NonlinearEffect for DeadZone {
    fn id(&self) -> &'static str {
        match self.sensor {
            SensorKind::Gyro => "gyro-dead-zone",
            SensorKind::Accel => "accel-dead-zone",
        }
    }

    fn sensor(&self) -> Option<SensorKind> {
        Some(self.sensor)
    }

    fn inputs(&self) -> Inputs {
        Inputs::own(self.sensor)
    }

    fn explain(&self) -> &'static str {
        "Dead zone (threshold): below a minimum input the sensor does not respond at all, from \
         static friction in a gimbal or pivot or a comparator threshold; above it the output \
         follows the input less the threshold. On a conic stand it shows where an axis's input \
         crosses zero, as odd harmonics of the cone frequency (a square wave of height d) and \
         as a direction-dependent offset on an axis with a constant input. Inside the band the \
         input cannot be recovered: corrected samples there are flagged, not invented."
    }

    fn params(&self) -> Vec<ParamDef> {
        let scale = match self.sensor {
            SensorKind::Gyro => 1e-4,
            SensorKind::Accel => 1e-3,
        };
        (0..3)
            .map(|i| ParamDef {
                name: format!("{}.dz_{}", self.sensor.as_str(), AXES[i]),
                unit: output_unit(self.sensor),
                nominal: 0.0,
                scale,
                min: 0.0,
                max: f64::INFINITY,
            })
            .collect()
    }

    /// x = z + d·sign(z) outside the band; inside it (|z| ≤ 3σ of the noise, or exactly 0)
    /// the input is anywhere in [−d, d]: flagged, returned as 0.
    fn invert_sample(&self, p: &[f64], sensor: SensorKind, z: &mut [f64; 3], noise: &[f64; 3]) -> u8 {
        if sensor != self.sensor {
            return 0;
        }
        let mut flags = 0;
        for i in 0..3 {
            let d = p.get(i).copied().unwrap_or(0.0).abs();
            if d == 0.0 {
                continue;
            }
            if z[i].abs() <= 3.0 * noise[i] || z[i] == 0.0 {
                z[i] = 0.0;
                flags |= 1 << i;
            } else {
                z[i] += d * z[i].signum();
            }
        }
        flags
    }

    fn transform(&self, p: &[f64], tr: &Track) -> Track {
        let half_width = std::array::from_fn(|i| p.get(i).copied().unwrap_or(0.0).abs());
        tr.mapped(std::sync::Arc::new(DeadBand { sensor: self.sensor, half_width }))
    }
}

/// The dead zone as a per-sample change of the input: `x − clamp(x, −d, d)` per axis on the
/// quantity the sensor senses.
#[derive(Debug)]
struct DeadBand {
    sensor: SensorKind,
    half_width: [f64; 3],
}

impl crate::motion::SampleMap for DeadBand {
    #[inline]
    fn apply(&self, k: &mut crate::motion::SensorKinematics) {
        let x = match self.sensor {
            SensorKind::Gyro => &mut k.w_rad_s,
            SensorKind::Accel => &mut k.a_m_s2,
        };
        for i in 0..3 {
            let d = self.half_width[i];
            x[i] -= x[i].clamp(-d, d);
        }
    }
}
