//! Accelerometer lever arm (size effect): each accelerometer sits at a distance r_i from
//! the rotation centre, so it also senses ε × r_i + ω × (ω × r_i).

use super::{Effect, Inputs, Key, Role, SensorKind, Side, State, Term, AXES};

/// u_i += [ε × r_i + ω × (ω × r_i)]_i with r_i (metres) the position of accelerometer i;
/// linear in r: the regressor of r_ij is (ε × e_j)_i + ω_i ω_j − δ_ij |ω|².
#[derive(Debug, Clone)]
pub struct LeverArm {
    terms: Vec<Term>,
}

impl LeverArm {
    /// Nine coefficients r_ij: component j of accelerometer i's position, metres.
    pub fn new() -> Self {
        let mut terms = Vec::with_capacity(9);
        for i in 0..3 {
            for j in 0..3 {
                terms.push(Term {
                    name: format!("accel.r_{}{}", AXES[i], AXES[j]),
                    channel: i,
                    key: Key::Own("accel-lever-arm", (3 * i + j) as u8),
                    label: format!("(e x e_{j} + w x (w x e_{j}))_{i}", i = AXES[i], j = AXES[j]),
                    unit: "m",
                    nominal: 0.0,
                    drop_priority: 4,
                    role: Role::Other,
                });
            }
        }
        Self { terms }
    }
}

impl Default for LeverArm {
    fn default() -> Self {
        Self::new()
    }
}

impl Effect for LeverArm {
    fn id(&self) -> &'static str {
        "accel-lever-arm"
    }

    fn sensor(&self) -> SensorKind {
        SensorKind::Accel
    }

    fn inputs(&self) -> Inputs {
        Inputs { rate: true, ang_accel: true, ..Inputs::NONE }
    }

    fn side(&self) -> Side {
        Side::Input
    }

    /// Accelerometer i at r_i senses `a + ε×r_i + ω×(ω×r_i)` along its own row of K: the
    /// perturbation of coefficient r_im has component j equal to the regressor of term (j, m).
    fn input_components(&self, k: usize) -> Vec<(usize, usize)> {
        let m = k % 3;
        (0..3).map(|j| (j, 3 * j + m)).collect()
    }

    fn explain(&self) -> &'static str {
        "Lever arm (size effect): the accelerometers are not at the stand's centre of rotation, \
         so each also senses the tangential acceleration ε × r and the centripetal acceleration \
         ω × (ω × r) of its own position r (coefficients in metres). It grows with the square \
         of the stand rate while gravity does not, so runs at two rates separate it from K."
    }

    fn terms(&self) -> &[Term] {
        &self.terms
    }

    #[inline]
    fn regressor(&self, k: usize, s: &State) -> f64 {
        let (i, j) = ((k / 3) % 3, k % 3);
        // (ε × e_j)_i = ε_{i+1} when j = i+2, −ε_{i+2} when j = i+1, else 0 (indices mod 3).
        let cross = if j == (i + 2) % 3 {
            s.e[(i + 1) % 3]
        } else if j == (i + 1) % 3 {
            -s.e[(i + 2) % 3]
        } else {
            0.0
        };
        let w2 = s.w[0] * s.w[0] + s.w[1] * s.w[1] + s.w[2] * s.w[2];
        cross + s.w[i] * s.w[j] - if i == j { w2 } else { 0.0 }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Each regressor is component i of ε × e_j + ω × (ω × e_j) (the acceleration of a point
    /// at unit distance along axis j), written out with the full cross products.
    #[test]
    fn regressors_are_the_rigid_body_acceleration_of_a_unit_arm() {
        let cross = |a: [f64; 3], b: [f64; 3]| {
            [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]
        };
        let s = State { w: [0.3, -1.1, 0.7], e: [2.0, 0.5, -3.0], ..State::default() };
        let e = LeverArm::new();
        for k in 0..27 {
            let (i, j) = ((k / 3) % 3, k % 3);
            let mut ej = [0.0; 3];
            ej[j] = 1.0;
            let want = cross(s.e, ej)[i] + cross(s.w, cross(s.w, ej))[i];
            let got = e.regressor(k, &s);
            assert!((got - want).abs() < 1e-14, "term {k}: {got} vs {want}");
        }
    }
}
