//! Angular-acceleration sensitivity of the gyro: the matrix C_ε in `u = … + C_ε ε`
//! (the paper's c_xz, c_yx, c_zy of eq. 3 are its entries e_xz, e_yx, e_zy), in seconds.

use super::{matrix_name, Effect, Inputs, Key, Role, SensorKind, State, Term, AXES};

/// Full 3×3 angular-acceleration sensitivity C_ε (names `gyro.e_ij`, unit s).
#[derive(Debug, Clone)]
pub struct AngularAcceleration {
    terms: Vec<Term>,
}

impl AngularAcceleration {
    /// All nine entries.
    pub fn new() -> Self {
        let mut terms = Vec::with_capacity(9);
        for i in 0..3 {
            for j in 0..3 {
                terms.push(Term {
                    name: matrix_name(SensorKind::Gyro, "e", i, j),
                    channel: i,
                    key: Key::AngAccel(j as u8),
                    label: format!("e_{}", AXES[j]),
                    unit: "s",
                    nominal: 0.0,
                    drop_priority: 3,
                    role: Role::Epsilon(j),
                });
            }
        }
        Self { terms }
    }
}

impl Default for AngularAcceleration {
    fn default() -> Self {
        Self::new()
    }
}

impl Effect for AngularAcceleration {
    fn id(&self) -> &'static str {
        "gyro-angular-acceleration"
    }

    fn sensor(&self) -> SensorKind {
        SensorKind::Gyro
    }

    fn inputs(&self) -> Inputs {
        Inputs { ang_accel: true, ..Inputs::NONE }
    }

    fn explain(&self) -> &'static str {
        "Angular-acceleration sensitivity: an electromechanical rate gyro's rotor and gimbal \
         have inertia, so an angular acceleration about another axis produces a torque that \
         the restraining spring reads as rate (the paper's eq. 3 terms multiplying dω/dt). The \
         coefficient is in seconds: output error = e_ij · ε_j. It shows as a residual in \
         quadrature with the rate coupling that grows with the square of the stand rate."
    }

    fn terms(&self) -> &[Term] {
        &self.terms
    }

    #[inline]
    fn regressor(&self, k: usize, s: &State) -> f64 {
        s.e[k % 3]
    }
}
