//! Scale factor and cross-axis coupling: the 3×3 matrix C_ω (gyro, paper eq. 3) or K
//! (accelerometer, paper eq. 4) in `u = M x`, row-major, diagonal = scale factors.

use super::{input_letter, matrix_name, Effect, Inputs, Key, Role, SensorKind, State, Term, AXES};

/// Full 3×3 scale/coupling matrix acting on the sensor's own true input.
#[derive(Debug, Clone)]
pub struct ScaleCoupling {
    sensor: SensorKind,
    terms: Vec<Term>,
}

impl ScaleCoupling {
    /// C_ω for the gyro (names `gyro.c_ij`), K for the accelerometer (`accel.k_ij`).
    pub fn new(sensor: SensorKind) -> Self {
        let letter = match sensor {
            SensorKind::Gyro => "c",
            SensorKind::Accel => "k",
        };
        let mut terms = Vec::with_capacity(9);
        for i in 0..3 {
            for j in 0..3 {
                terms.push(Term {
                    name: matrix_name(sensor, letter, i, j),
                    channel: i,
                    key: match sensor {
                        SensorKind::Gyro => Key::Rate(j as u8),
                        SensorKind::Accel => Key::Force(j as u8),
                    },
                    label: format!("{}_{}", input_letter(sensor), AXES[j]),
                    unit: "1",
                    nominal: if i == j { 1.0 } else { 0.0 },
                    drop_priority: if i == j { 0 } else { 1 },
                    role: Role::Scale(j),
                });
            }
        }
        Self { sensor, terms }
    }
}

impl Effect for ScaleCoupling {
    fn id(&self) -> &'static str {
        match self.sensor {
            SensorKind::Gyro => "gyro-scale-coupling",
            SensorKind::Accel => "accel-scale-coupling",
        }
    }

    fn sensor(&self) -> SensorKind {
        self.sensor
    }

    fn inputs(&self) -> Inputs {
        Inputs::own(self.sensor)
    }

    fn explain(&self) -> &'static str {
        "Scale factor and cross-axis coupling (misalignment): each output is a weighted sum of \
         the true inputs along all three axes. The diagonal is each axis's scale factor; the \
         off-diagonal terms come from sensing axes that are not exactly orthogonal or not \
         aligned with the block's reference axes, and from electrical or mechanical cross-talk \
         (paper eqs. 3-4). A single sensor cannot separate them from its scale factor; a \
         triad excited on all axes at once can."
    }

    fn terms(&self) -> &[Term] {
        &self.terms
    }

    #[inline]
    fn regressor(&self, k: usize, s: &State) -> f64 {
        let j = k % 3;
        match self.sensor {
            SensorKind::Gyro => s.w[j],
            SensorKind::Accel => s.a[j],
        }
    }
}
