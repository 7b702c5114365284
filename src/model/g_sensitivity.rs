//! Gyro g-sensitivity: rate output caused by specific force.

use super::{matrix_name, Effect, Inputs, Key, Role, SensorKind, State, Term, AXES};

/// u_i += Σ_j g_ij a_j (gyro), a full 3×3 matrix in rad/s per m/s².
#[derive(Debug, Clone)]
pub struct GSensitivity {
    terms: Vec<Term>,
}

impl GSensitivity {
    /// All nine entries.
    pub fn new() -> Self {
        let mut terms = Vec::with_capacity(9);
        for i in 0..3 {
            for j in 0..3 {
                terms.push(Term {
                    name: matrix_name(SensorKind::Gyro, "g", i, j),
                    channel: i,
                    key: Key::Force(j as u8),
                    label: format!("a_{}", AXES[j]),
                    unit: "rad/s per m/s^2",
                    nominal: 0.0,
                    drop_priority: 4,
                    role: Role::Other,
                });
            }
        }
        Self { terms }
    }
}

impl Default for GSensitivity {
    fn default() -> Self {
        Self::new()
    }
}

impl Effect for GSensitivity {
    fn id(&self) -> &'static str {
        "gyro-g-sensitivity"
    }

    fn sensor(&self) -> SensorKind {
        SensorKind::Gyro
    }

    fn inputs(&self) -> Inputs {
        Inputs::FORCE
    }

    fn explain(&self) -> &'static str {
        "Gyro g-sensitivity: a rate gyro's rotor or proof mass is not perfectly balanced, so \
         specific force along any axis produces a torque that reads as rate (u_i += g_ij a_j). \
         On a conic stand it shows as a residual at the cone frequency in phase with the \
         horizontal gravity components, and as a bias that changes with the mount (which axis \
         carries gravity); re-mounts and two cone angles separate it from rate coupling."
    }

    fn terms(&self) -> &[Term] {
        &self.terms
    }

    #[inline]
    fn regressor(&self, k: usize, s: &State) -> f64 {
        s.a[k % 3]
    }
}
