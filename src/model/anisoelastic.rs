//! Gyro anisoelasticity: rate output proportional to products of specific-force components.

use super::{Effect, Inputs, Key, Role, SensorKind, State, Term, AXES};

/// The six unique products a_j a_k.
const PAIRS: [(usize, usize); 6] = [(0, 0), (1, 1), (2, 2), (0, 1), (1, 2), (2, 0)];

/// u_i += Σ_{jk} n_ijk a_j a_k (gyro), 18 coefficients in rad/s per (m/s²)².
#[derive(Debug, Clone)]
pub struct Anisoelastic {
    terms: Vec<Term>,
}

impl Anisoelastic {
    /// All 18 coefficients.
    pub fn new() -> Self {
        let mut terms = Vec::with_capacity(18);
        for i in 0..3 {
            for (j, k) in PAIRS {
                terms.push(Term {
                    name: format!("gyro.n_{}_{}{}", AXES[i], AXES[j], AXES[k]),
                    channel: i,
                    key: Key::Own("gyro-anisoelastic", (3 * j + k) as u8),
                    label: format!("a_{}a_{}", AXES[j], AXES[k]),
                    unit: "rad/s per (m/s^2)^2",
                    nominal: 0.0,
                    drop_priority: 4,
                    role: Role::Other,
                });
            }
        }
        Self { terms }
    }
}

impl Default for Anisoelastic {
    fn default() -> Self {
        Self::new()
    }
}

impl Effect for Anisoelastic {
    fn id(&self) -> &'static str {
        "gyro-anisoelastic"
    }

    fn sensor(&self) -> SensorKind {
        SensorKind::Gyro
    }

    fn inputs(&self) -> Inputs {
        Inputs::FORCE
    }

    fn explain(&self) -> &'static str {
        "Gyro anisoelasticity (g² sensitivity): unequal compliance of the rotor suspension along \
         different axes makes the mass centre shift by an amount proportional to the specific \
         force, so the torque and the rate error go with products a_j a_k. It shows as a \
         residual at twice the cone frequency that grows with the square of sin(cone angle)."
    }

    fn terms(&self) -> &[Term] {
        &self.terms
    }

    #[inline]
    fn regressor(&self, k: usize, s: &State) -> f64 {
        let (j, l) = PAIRS[k % 6];
        s.a[j] * s.a[l]
    }
}
