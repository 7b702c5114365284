//! The forward model compiled for many states ([`Predictor`]).

use super::{weighted_regressors, Effect, State, TermRef};

/// [`super::forward`] worked out once for many states: each nonzero term's channel, weight and
/// regressor (an input-side term's components weighted by the scale matrix's row), so that
/// a state costs only the regressors — no input components looked up or scale matrix built
/// per call. [`Predictor::at`] gives [`super::forward`]'s numbers bit for bit (same terms, same
/// order, the same products).
#[derive(Clone)]
pub struct Predictor<'a> {
    /// (effect, regressor index, output channel, weight) in [`super::forward`]'s order.
    parts: Vec<(&'a dyn Effect, usize, usize, f64)>,
}

impl<'a> Predictor<'a> {
    /// The predictor of one sensor's `terms` at `values`.
    pub fn new(terms: &[TermRef<'a>], values: &[f64]) -> Self {
        let mut parts = Vec::new();
        weighted_regressors(terms, values, |e, k, ch, w| parts.push((e, k, ch, w)));
        Self { parts }
    }

    /// The sensor's three outputs at `s`.
    #[inline]
    pub fn at(&self, s: &State) -> [f64; 3] {
        let mut u = [0.0; 3];
        for &(e, k, ch, w) in &self.parts {
            u[ch] += w * e.regressor(k, s);
        }
        u
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::{forward, Model};
    use crate::units::SensorKind;

    #[test]
    fn predictor_gives_forwards_numbers_bit_for_bit() {
        let mut m = Model::paper();
        m.add_effect("gyro-hysteresis").unwrap();
        m.add_effect("accel-lever-arm").unwrap();
        for sensor in SensorKind::BOTH {
            let terms = m.terms(sensor);
            let values: Vec<f64> =
                (0..terms.len()).map(|i| if i % 5 == 3 { 0.0 } else { 0.01 * (i as f64 + 1.0).sin() }).collect();
            let p = Predictor::new(&terms, &values);
            for k in 0..20 {
                let x = k as f64 * 0.37;
                let s = State {
                    t_session_s: x,
                    w: [x.sin(), x.cos(), 0.3 * x],
                    e: [0.1 * x, -x.sin(), 0.2],
                    a: [9.0 * x.cos(), 1.0, -x],
                    temp_c: 20.0,
                    temp_rate_c_s: 0.0,
                };
                assert_eq!(p.at(&s).map(f64::to_bits), forward(&terms, &values, &s).map(f64::to_bits));
            }
        }
    }
}
